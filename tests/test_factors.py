"""GTSAM factors equal the numpy models they wrap."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler import factors
from fgdoppler.factors import X
from fgdoppler.models.doppler_kernels import Along
from fgdoppler.models.observation import DopplerModel
from tests.conftest import random_states


def _values(**states: np.ndarray) -> gtsam.Values:
    v = gtsam.Values()
    for k, x in states.items():
        v.insert(X(int(k[1:])), np.asarray(x, dtype=float))
    return v


def test_doppler_factor_linearize_equals_model(rng: np.random.Generator, paper_geom: fd.Geometry) -> None:
    for x in random_states(rng, paper_geom, 20):
        pairs = np.array([1, 0])
        z = rng.normal(0, 50, 2)
        sigma = np.array([0.5, 2.0])
        f = factors.doppler_factor(X(3), paper_geom, pairs, z, sigma)
        lin = f.linearize(_values(x3=x))
        A, b = lin.jacobian()
        h, H = fd.bistatic_doppler_and_jacobian(x, paper_geom)
        np.testing.assert_allclose(A, H[pairs] / sigma[:, None], rtol=1e-12)
        np.testing.assert_allclose(b, -(h[pairs] - z) / sigma, rtol=1e-12, atol=1e-12)
        assert f.error(_values(x3=x)) == pytest.approx(0.5 * np.sum(((h[pairs] - z) / sigma) ** 2), rel=1e-12)


def test_error_only_call_computes_no_jacobian(monkeypatch: pytest.MonkeyPatch) -> None:
    g = fd.paper_geometry("a")
    f = factors.doppler_factor(X(0), g, [0, 1], [1.0, 2.0], 1.0)
    bf = factors.cv_factor(X(0), g, [[0.0, 0.5], [0.0, 0.5]], [1.0, 2.0, 3.0, 4.0], 1.0)
    v = _values(x0=[25e3, 2e3, 10.0, -100.0])

    real_at_state = DopplerModel.at_state
    asked: list[bool] = []  # the measurement factor's calls: whether each computed a Jacobian

    def spy(self: DopplerModel, *args: object, jacobian: bool, **kwargs: object):
        asked.append(jacobian)
        return real_at_state(self, *args, jacobian=jacobian, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(DopplerModel, "at_state", spy)
    assert np.isfinite(f.error(v))
    assert asked == [False]
    real_along = Along.__call__
    window_asked: list[bool] = []  # the window factor's calls of its laid-out evaluator

    def window_spy(self: Along, *args: object, jacobian: bool):
        window_asked.append(jacobian)
        return real_along(self, *args, jacobian=jacobian)  # type: ignore[arg-type]

    monkeypatch.setattr(Along, "__call__", window_spy)
    assert np.isfinite(bf.error(v))
    assert window_asked == [False]
    # and the linearising calls do use the Jacobian path, once
    asked.clear()
    window_asked.clear()
    f.linearize(v)
    bf.linearize(v)
    assert asked == [True] and window_asked == [True]
    # a state in space on the ground layout's window factor: the sensors looked up at each call, by _cv
    real_cv = factors._cv
    cv_asked: list[bool] = []

    def cv_spy(*args: object, jacobian: bool, **kwargs: object):
        cv_asked.append(jacobian)
        return real_cv(*args, jacobian=jacobian, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(factors, "_cv", cv_spy)
    in_space = _values(x0=[25e3, 2e3, 1e3, 10.0, -100.0, 0.0])
    assert np.isfinite(bf.error(in_space))
    bf.linearize(in_space)
    assert cv_asked == [False, True] and window_asked == [True]


def test_cv_factor_equals_g_and_J(rng: np.random.Generator, paper_geom: fd.Geometry) -> None:
    times = [np.arange(10) * 0.5, 0.25 + np.arange(10) * 0.5]
    for x0 in random_states(rng, paper_geom, 10, min_dist=3e3):
        Z = rng.normal(0, 30, 20)
        f = factors.cv_factor(X(0), paper_geom, times, Z, 1.5)
        A, b = f.linearize(_values(x0=x0)).jacobian()
        g, J = fd.cv_doppler_and_jacobian(x0, paper_geom, times)
        np.testing.assert_allclose(A, J / 1.5, rtol=1e-12)
        np.testing.assert_allclose(b, -(g - Z) / 1.5, rtol=1e-12, atol=1e-12)


def test_cv_factor_refuses_a_track_through_a_sensor(paper_geom: fd.Geometry) -> None:
    """A start whose track meets a sensor at a measurement's time has no Doppler there: the window factor raises
    the model's error (Levenberg-Marquardt reports the step as failed), with and without the Jacobian."""
    times = [np.array([0.0, 1.0]), np.array([0.0, 1.0])]
    f = factors.cv_factor(X(0), paper_geom, times, np.zeros(4), 1.0)
    through_rx = np.r_[paper_geom.rx[0] - np.array([100.0, -50.0]), 100.0, -50.0]  # at receiver 0 at t = 1 s
    sharing = int(np.sum(np.all(paper_geom.rx == paper_geom.rx[0], axis=1)))  # case a's pairs share it
    for call in (f.error, f.linearize):
        with pytest.raises(ValueError, match=f"^{sharing} target position"):
            call(_values(x0=through_rx))


def test_cv_factor_of_a_ground_layout_serves_states_in_space(rng: np.random.Generator,
                                                               paper_geom: fd.Geometry) -> None:
    """A 2-D geometry serves 3-D states with its sensors at z = 0: its window factor at a state in space (the
    sensors looked up at each call) is the factor of the same sensors given in 3-D (looked up once), exactly."""
    lifted = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=(*p.tx, 0.0), rx=(*p.rx, 0.0)) for p in paper_geom.pairs))
    times = [np.arange(10) * 0.5, 0.25 + np.arange(10) * 0.5]
    for x2 in random_states(rng, paper_geom, 5, min_dist=3e3):
        x0 = np.r_[x2[:2], rng.uniform(500.0, 3e3), x2[2:], rng.uniform(-20.0, 20.0)]
        Z = rng.normal(0, 30, 20)
        flat, space = (factors.cv_factor(X(0), g, times, Z, 1.5) for g in (paper_geom, lifted))
        v = _values(x0=x0)
        assert flat.error(v) == space.error(v)
        for a, b in zip(flat.linearize(v).jacobian(), space.linearize(v).jacobian(), strict=True):
            np.testing.assert_array_equal(a, b)


def test_motion_factor_is_exact_and_finite(rng: np.random.Generator) -> None:
    m = fd.ConstantVelocity(q=0.01)
    for dt in (0.01, 0.5, 7.0):
        x1, x2 = rng.normal(0, 1e3, 4), rng.normal(0, 1e3, 4)
        f = factors.motion_factor(X(0), X(1), dt, m)
        v = _values(x0=x1, x1=x2)
        r = x2 - m.F(dt) @ x1
        assert f.error(v) == pytest.approx(0.5 * r @ np.linalg.solve(m.Q(dt), r), rel=1e-9)
        lin = f.linearize(v)
        A, b = lin.jacobian()
        assert np.all(np.isfinite(A)) and np.all(np.isfinite(b))
        # Information of the factor equals [F' ; -I] Q^{-1} [F, -I]
        G = np.hstack([-m.F(dt), np.eye(4)])
        np.testing.assert_allclose(A.T @ A, G.T @ np.linalg.solve(m.Q(dt), G), rtol=1e-8, atol=1e-8 * np.abs(A.T @ A).max())


def test_motion_factor_rejects_singular_Q() -> None:
    # The paper's rank-2 Q would give NaN in a Gaussian noise model: refuse it clearly.
    with pytest.raises(ValueError, match="full-rank"):
        factors.motion_factor(X(0), X(1), 0.5, fd.ConstantVelocity(q=0.01, form="discrete"))


def test_numpy_linearised_rows_match_the_custom_factor_at_the_point(rng: np.random.Generator) -> None:
    # iSAM2 and the offline smoother linearise in numpy (linearize_rows) and hand GTSAM an
    # absolute linear factor; at the linearisation point it must equal the CustomFactor's.
    from fgdoppler.estimators.linearized import linearize_rows

    g = fd.paper_geometry("b")
    x = random_states(rng, g, 1)[0]
    z, s = np.array([3.0, -4.0]), np.array([1.0, 0.7])
    rows = linearize_rows(DopplerModel(geometry=g), np.broadcast_to(x, (2, 4)), np.array([0, 1]), z, s)
    lf = factors.absolute_linear_factor([X(0)], [rows.A], rows.b + rows.A @ x)
    cf = factors.doppler_factor(X(0), g, [0, 1], z, s)
    v = _values(x0=x)
    A1, b1 = lf.linearize(v).jacobian()
    A2, b2 = cf.linearize(v).jacobian()
    np.testing.assert_allclose(A1, A2, rtol=1e-12)
    np.testing.assert_allclose(b1, b2, rtol=1e-8, atol=1e-9)
    assert lf.error(v) == pytest.approx(cf.error(v), rel=1e-8)


def test_factor_input_validation() -> None:
    g = fd.paper_geometry("a")
    with pytest.raises(ValueError, match="out of range"):
        factors.doppler_factor(X(0), g, [2], [1.0], 1.0)
    with pytest.raises(ValueError):
        factors.doppler_factor(X(0), g, [0], [1.0], 0.0)
    with pytest.raises(ValueError, match="measurements for"):
        factors.cv_factor(X(0), g, [[0.0], [0.0]], [1.0], 1.0)
    with pytest.raises(ValueError, match="positive definite"):
        factors.prior_factor(X(0), np.zeros(4), np.diag([1.0, 1.0, 0.0, 1.0]))


def test_huber_noise_model_downweights_outliers() -> None:
    g = fd.paper_geometry("a")
    x = np.array([25e3, 2e3, 10.0, -100.0])
    h = fd.bistatic_doppler(x, g)
    v = _values(x0=x)
    robust = factors.doppler_factor(X(0), g, [0], [h[0] + 50.0], 1.0, huber_k=1.345)
    plain = factors.doppler_factor(X(0), g, [0], [h[0] + 50.0], 1.0)
    # Huber loss for |r| = 50 > k: k |r| - k^2 / 2
    assert robust.error(v) == pytest.approx(1.345 * 50 - 1.345**2 / 2, rel=1e-9)
    assert plain.error(v) == pytest.approx(0.5 * 50**2, rel=1e-12)


ZONE = fd.Zone(along=(2e3, 48e3), across=(-5e3, 5e3), speed_max=200.0)


@pytest.mark.parametrize(
    "state",
    [
        [49.3e3, 1.9e3, -80.0, 9.0],  # beyond along_hi
        [1.0e3, -6.0e3, 30.0, 40.0],  # below along_lo and across_lo
        [10e3, 7e3, 180.0, 150.0],  # above across_hi and too fast
    ],
)
def test_region_factor_linearises_to_the_zone_excess(state: list[float]) -> None:
    x = np.asarray(state)
    e, J = ZONE.excess(x)
    assert np.any(e != 0)
    f = factors.region_factor(X(0), ZONE, wall_sigma=(10.0, 0.1))
    A, b = f.linearize(_values(x0=x)).jacobian()
    W = np.diag([1 / 10.0, 1 / 10.0, 1 / 0.1])
    np.testing.assert_allclose(A, W @ J, atol=1e-12)
    np.testing.assert_allclose(b, -W @ e, atol=1e-12)
    assert f.error(_values(x0=x)) == pytest.approx(0.5 * float(np.sum((W @ e) ** 2)), rel=1e-12)


def test_region_factor_is_zero_inside(rng: np.random.Generator) -> None:
    f = factors.region_factor(X(0), ZONE)
    for _ in range(50):
        x = np.array([rng.uniform(2e3, 48e3), rng.uniform(-5e3, 5e3), *rng.uniform(-140.0, 140.0, 2)])
        assert f.error(_values(x0=x)) == 0.0


def test_region_factor_validation() -> None:
    with pytest.raises(ValueError, match="wall_sigma"):
        factors.region_factor(X(0), ZONE, wall_sigma=(0.0, 1.0))


class _GivenJacobian:
    """A one-channel measurement model whose Jacobian is given: what does a factor make of it?"""

    n_channels = 1

    def __init__(self, jacobian: np.ndarray) -> None:
        self.jacobian = jacobian

    def predict(self, states: object, channels: object) -> np.ndarray:
        return np.zeros(len(self.jacobian))

    def predict_and_jacobian(self, states: object, channels: object) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(len(self.jacobian)), self.jacobian


@pytest.mark.parametrize(("jacobian", "refused"), [
    (np.array([[1e308, 1e308, 1e308, 0.0]]), None),  # every entry finite, though their sum overflows
    (np.array([[0.0, np.nan, 0.0, 0.0]]), "non-finite Jacobian"),
    (np.array([[np.inf, -np.inf, 0.0, 0.0]]), "non-finite Jacobian"),  # sums to NaN
    (np.array([[0.0, 0.0, -np.inf, 1.0]]), "non-finite Jacobian"),
    (np.zeros((1, 3)), "Jacobian shape"),  # handed to GTSAM it would crash the interpreter
], ids=["large-finite", "nan", "inf-minus-inf", "minus-inf", "shape"])
@pytest.mark.parametrize("rows", [1, 20])  # a scan's few rows and a window's many are tested apart
def test_a_factor_refuses_a_non_finite_or_misshapen_jacobian(jacobian: np.ndarray, refused: str | None,
                                                              rows: int) -> None:
    J = np.repeat(jacobian, rows, axis=0)
    f = factors.measurement_factor(X(0), _GivenJacobian(J), [0] * rows, [0.0] * rows, [1.0] * rows)
    v = _values(x0=np.zeros(4))
    if refused is None:
        np.testing.assert_array_equal(f.linearize(v).jacobian()[0], J)
    else:
        with pytest.raises(RuntimeError, match=refused):
            f.linearize(v)
