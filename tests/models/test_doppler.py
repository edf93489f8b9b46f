"""The Doppler model: analytic Jacobians vs central differences, invariances, references."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.models.observation import DopplerModel
from tests.conftest import random_geometry, random_states


def _central_diff(fun, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of fun: (..., 4) -> (..., m) at many states at once."""
    cols = []
    for j in range(4):
        e = np.zeros(4)
        e[j] = steps[j]
        cols.append((fun(x + e) - fun(x - e)) / (2 * steps[j]))
    return np.stack(cols, axis=-1)


def _rel_err(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    num = np.linalg.norm(a - b, axis=(-2, -1))
    den = np.linalg.norm(b, axis=(-2, -1))
    return num / den


STEPS = np.array([1e-2, 1e-2, 1e-4, 1e-4])


def _geometries(rng: np.random.Generator) -> list[fd.Geometry]:
    # and a monostatic radar (tx = rx) beside a bistatic pair
    monostatic = fd.Geometry(pairs=(fd.BistaticPair(tx=(-5e3, 2e3), rx=(-5e3, 2e3)),
                                    fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3))))
    return [fd.paper_geometry("a"), fd.paper_geometry("b")] + [random_geometry(rng) for _ in range(4)] + [monostatic]


def test_single_state_jacobian_matches_central_differences(rng: np.random.Generator) -> None:
    n_total = 0
    for g in _geometries(rng):
        x = random_states(rng, g, 250)
        J = fd.bistatic_doppler_jacobian(x, g)
        Jfd = _central_diff(lambda s, g=g: fd.bistatic_doppler(s, g), x, STEPS)
        assert J.shape == (250, g.n_pairs, 4)
        assert np.max(_rel_err(J, Jfd)) <= 1e-6
        n_total += x.shape[0]
    assert n_total >= 1000


def test_batch_jacobian_matches_central_differences(rng: np.random.Generator) -> None:
    n_total = 0
    for g in _geometries(rng):
        times = [np.arange(10) * 0.5 + 0.1 * i for i in range(g.n_pairs)]
        # keep the whole 5 s trajectory away from the sensors
        x = random_states(rng, g, 250, min_dist=3e3)
        J = fd.cv_doppler_jacobian(x, g, times)
        Jfd = _central_diff(lambda s, g=g, times=times: fd.cv_doppler(s, g, times), x, STEPS)
        assert J.shape == (250, 10 * g.n_pairs, 4)
        assert np.max(_rel_err(J, Jfd)) <= 1e-6
        n_total += x.shape[0]
    assert n_total >= 1000


def test_paper_appendix_formula_for_batch_jacobian(rng: np.random.Generator) -> None:
    """The Appendix A expressions, written out term by term, equal J(x0)."""
    g = fd.paper_geometry("a")
    x0 = random_states(rng, g, 50, min_dist=3e3)
    times = [np.arange(10) * 0.5, np.arange(10) * 0.5]
    J = fd.cv_doppler_jacobian(x0, g, times)
    col = 0
    for i in range(2):
        for t in times[i]:
            x, y, vx, vy = x0.T
            rows = np.zeros((x0.shape[0], 4))
            for s in (g.tx[i], g.rx[i]):
                dx, dy = x + t * vx - s[0], y + t * vy - s[1]
                r = np.hypot(dx, dy)
                rd = (dx * vx + dy * vy) / r
                rows[:, 0] += (r * vx - rd * dx) / r**2
                rows[:, 1] += (r * vy - rd * dy) / r**2
                rows[:, 2] += (r * (dx + t * vx) - t * dx * rd) / r**2
                rows[:, 3] += (r * (dy + t * vy) - t * dy * rd) / r**2
            np.testing.assert_allclose(J[:, col], rows, rtol=1e-12, atol=1e-15)
            col += 1


def test_doppler_is_time_derivative_of_bistatic_range(rng: np.random.Generator) -> None:
    """Independent reference: d/dt (r_T + r_R) along the velocity, by central difference."""
    g = random_geometry(rng, 3)
    x = random_states(rng, g, 300)
    eps = 1e-3
    plus = fd.bistatic_range(x[:, :2] + eps * x[:, 2:], g)
    minus = fd.bistatic_range(x[:, :2] - eps * x[:, 2:], g)
    np.testing.assert_allclose(fd.bistatic_doppler(x, g), (plus - minus) / (2 * eps), rtol=1e-6, atol=1e-6)


def test_hand_computed_value() -> None:
    # Target straight above Rx at 3 km moving north at 100 m/s: Rx range rate 100,
    # Tx range rate 100 * 3 / sqrt(50^2 + 3^2).
    g = fd.paper_geometry("a")
    h = fd.bistatic_doppler([0.0, 3e3, 0.0, 100.0], g)
    assert h[0] == pytest.approx(100 + 100 * 3 / np.hypot(50, 3), rel=1e-14)


def test_swapping_tx_and_rx_leaves_doppler_unchanged(rng: np.random.Generator) -> None:
    g = random_geometry(rng, 3)
    swapped = fd.Geometry(pairs=tuple(p.swapped() for p in g.pairs))
    x = random_states(rng, g, 500)
    np.testing.assert_allclose(fd.bistatic_doppler(x, swapped), fd.bistatic_doppler(x, g), rtol=1e-13, atol=1e-12)


def test_mirror_of_case_a_is_case_b(rng: np.random.Generator) -> None:
    # Reflecting case (a) about x = 25 km maps Tx1, Tx2, Rx to (0,0), (0,1km), (50km,0):
    # pairs (Tx=(0,0), Rx=(50km,0)) and (Tx=(0,1km), Rx=(50km,0)), which are case (b)'s
    # pairs with Tx and Rx swapped. Doppler is swap-invariant, so
    # h_a(x, y, vx, vy) = h_b(50km - x, y, -vx, vy).
    a, b = fd.paper_geometry("a"), fd.paper_geometry("b")
    x = random_states(rng, a, 500)
    xm = x * [-1, 1, -1, 1] + [50e3, 0, 0, 0]
    np.testing.assert_allclose(fd.bistatic_doppler(x, a), fd.bistatic_doppler(xm, b), rtol=1e-12, atol=1e-10)
    mirrored = a.mirrored_x(25e3)
    np.testing.assert_allclose(fd.bistatic_doppler(xm, mirrored), fd.bistatic_doppler(xm, b), rtol=1e-12, atol=1e-10)


def test_motion_along_baseline_gives_zero_doppler_for_that_pair() -> None:
    g = fd.paper_geometry("a")
    xs = np.linspace(1e3, 49e3, 30)
    states = np.stack([xs, np.zeros_like(xs), np.full_like(xs, 100.0), np.zeros_like(xs)], axis=1)
    h = fd.bistatic_doppler(states, g)
    np.testing.assert_allclose(h[:, 0], 0.0, atol=1e-12)
    assert np.all(np.abs(h[:, 1]) > 0)


def test_any_leading_shape(rng: np.random.Generator) -> None:
    g = fd.paper_geometry("b")
    x = random_states(rng, g, 24).reshape(2, 3, 4, 4)
    h, J = fd.bistatic_doppler_and_jacobian(x, g)
    assert h.shape == (2, 3, 4, 2) and J.shape == (2, 3, 4, 2, 4)
    np.testing.assert_allclose(h.reshape(-1, 2), fd.bistatic_doppler(x.reshape(-1, 4), g))


def test_batch_map_equals_doppler_along_cv_trajectory(rng: np.random.Generator) -> None:
    g = fd.paper_geometry("b")
    x0 = random_states(rng, g, 20, min_dist=3e3)
    times = [np.arange(10) * 0.5, 0.25 + np.arange(10) * 0.5]
    gx = fd.cv_doppler(x0, g, times)
    for i, ts in enumerate(times):
        for j, t in enumerate(ts):
            xt = x0 + t * np.concatenate([x0[:, 2:], np.zeros((20, 2))], axis=1)
            np.testing.assert_allclose(gx[:, 10 * i + j], fd.bistatic_doppler(xt, g)[:, i], rtol=1e-13)


def test_sensor_singularity_raises() -> None:
    g = fd.paper_geometry("a")
    with pytest.raises(ValueError, match="coincide with a sensor"):
        fd.bistatic_doppler([0.0, 0.0, 1.0, 1.0], g)
    with pytest.raises(ValueError, match="coincide with a sensor"):
        fd.bistatic_doppler_jacobian([50e3, 1e3, 1.0, 1.0], g)
    # a trajectory that reaches the receiver at t = 1 s
    with pytest.raises(ValueError, match="coincide with a sensor"):
        fd.cv_doppler([-100.0, 0.0, 100.0, 0.0], g, [[0.0, 1.0], [0.0]])


def test_bad_inputs() -> None:
    g = fd.paper_geometry("a")
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        fd.bistatic_doppler([1.0, 2.0, 3.0], g)
    with pytest.raises(ValueError, match="out of range"):
        fd.cv_doppler([1e3, 2e3, 1.0, 1.0], g, [[0.0], [0.0], [0.0]])


def test_measurement_model_small_and_vectorised_paths_agree(rng: np.random.Generator) -> None:
    g = random_geometry(rng, 3)
    model = DopplerModel(geometry=g)
    x = random_states(rng, g, 200)
    c = rng.integers(0, 3, 200)
    h_vec, H_vec = model.predict_and_jacobian(x, c)  # 200 rows: vectorised path
    for i in range(0, 200, 2):  # 2 rows at a time: the plain-float path
        h, H = model.predict_and_jacobian(x[i:i + 2], c[i:i + 2])
        np.testing.assert_allclose(h, h_vec[i:i + 2], rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(H, H_vec[i:i + 2], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(model.predict(x[i:i + 2], c[i:i + 2]), h, rtol=1e-15)
    with pytest.raises(ValueError, match="coincide with a sensor"):
        model.predict(np.array([[*g.rx[0], 1.0, 1.0]]), [0])


def _model_and_states(rng: np.random.Generator, dim: int, pairs: int, n: int
                      ) -> tuple[fd.Geometry, DopplerModel, np.ndarray]:
    """A random geometry of ``pairs`` pairs (3-D: transmitters 0-50 m up, receivers on the ground), its model,
    and ``n`` states 3 km or more from every sensor (3-D: 0.5-3 km up, climbing or sinking at up to 20 m/s)."""
    g2 = random_geometry(rng, pairs)
    g = g2 if dim == 2 else fd.Geometry(pairs=tuple(
        fd.BistaticPair(tx=(*p.tx, float(rng.uniform(0, 50))), rx=(*p.rx, 0.0)) for p in g2.pairs))
    x2 = random_states(rng, g2, n, min_dist=3e3)
    x = x2 if dim == 2 else np.c_[x2[:, :2], rng.uniform(500, 3e3, n), x2[:, 2:], rng.uniform(-20, 20, n)]
    return g, DopplerModel(geometry=g), x


@pytest.mark.parametrize("dim", [2, 3])
def test_doppler_along_tracks_is_the_per_state_model_to_the_bit(rng: np.random.Generator, dim: int) -> None:
    """``predict_along`` and ``cv_doppler`` evaluate coordinate by coordinate; the per-state model, on the
    propagated states, does the same arithmetic in another layout: the numbers must agree exactly."""
    g, model, x = _model_and_states(rng, dim, 3, 40)
    t = np.sort(rng.uniform(0.0, 30.0, 25))
    c = rng.integers(0, 3, 25)
    along = model.predict_along(x, t, c)
    assert along.shape == (40, 25)
    for i in range(40):
        xt = x[i] + t[:, None] * np.concatenate([x[i, dim:], np.zeros(dim)])
        np.testing.assert_array_equal(along[i], model.predict(xt, c))  # 25 rows: the vectorised path
    np.testing.assert_array_equal(fd.cv_doppler(x, g, fd.StackedTimes(pair=c, t=t)), along)
    # a track that reaches receiver 0 at t = 1 s: NaN there, numbers elsewhere
    v = np.ones(dim) * 100.0
    start = np.concatenate([g.rx[0] - v, v])
    h = model.predict_along(start[None], np.array([0.0, 1.0, 2.0]), np.array([0, 0, 0]))
    assert np.isnan(h[0, 1]) and np.all(np.isfinite(h[0, [0, 2]]))


@pytest.mark.parametrize("dim", [2, 3])
def test_one_states_pairs_are_the_checked_model_to_the_bit(rng: np.random.Generator, dim: int) -> None:
    """``at_state`` (the graphs' measurement factors, which check their pairs once) is ``predict`` and
    ``predict_and_jacobian`` of the state repeated, exactly — with a scan's few pairs (plain floats) and with
    more than four (the vectorised path) — and refuses a state of the wrong length or at a sensor as they do."""
    g, model, states = _model_and_states(rng, dim, 6, 20)
    for x in states:
        for n in (1, 2, 4, 5, 9):
            c = rng.integers(0, 6, n).astype(np.intp)
            xs = np.broadcast_to(x, (n, x.size))
            h, H = model.at_state(x, c, jacobian=True)
            h_ref, H_ref = model.predict_and_jacobian(xs, c)
            np.testing.assert_array_equal(h, h_ref)
            np.testing.assert_array_equal(H, H_ref)
            h_only, none = model.at_state(x, c, jacobian=False)
            np.testing.assert_array_equal(h_only, model.predict(xs, c))
            assert none is None
    with pytest.raises(ValueError, match="states of"):
        model.at_state(states[0][:-1], np.array([0], dtype=np.intp), jacobian=False)
    at_rx = np.concatenate([g.rx[1], np.ones(dim)])
    for n in (1, 5):
        with pytest.raises(ValueError, match="coincide with a sensor"):
            model.at_state(at_rx, np.ones(n, dtype=np.intp), jacobian=True)


@pytest.mark.parametrize("dim", [2, 3])
def test_window_jacobian_is_the_per_state_models_chain_rule_to_the_bit(rng: np.random.Generator, dim: int) -> None:
    r"""The window's compiled Jacobian is the per-state model's (numpy, another layout) through the chain rule
    :math:`\partial g/\partial\mathbf v = t\,\partial h/\partial\mathbf p + \partial h/\partial\mathbf v`, exactly;
    any leading shape and memory layout of the states gives the same numbers."""
    g, model, x = _model_and_states(rng, dim, 3, 30)
    t = np.sort(rng.uniform(0.0, 30.0, 20))
    c = rng.integers(0, 3, 20)
    times = fd.StackedTimes(pair=c, t=t)
    h, J = fd.cv_doppler_and_jacobian(x, g, times)
    assert J.shape == (30, 20, 2 * dim)
    for i in range(30):
        xt = x[i] + t[:, None] * np.concatenate([x[i, dim:], np.zeros(dim)])
        h_ref, H = model.predict_and_jacobian(xt, c)
        np.testing.assert_array_equal(h[i], h_ref)
        np.testing.assert_array_equal(J[i], np.concatenate([H[:, :dim], t[:, None] * H[:, :dim] + H[:, dim:]], 1))
    h6, J6 = fd.cv_doppler_and_jacobian(x.reshape(5, 6, 2 * dim), g, times)
    np.testing.assert_array_equal(h6.reshape(30, 20), h)
    np.testing.assert_array_equal(J6.reshape(30, 20, 2 * dim), J)
    strided = np.zeros((30, 4 * dim))
    strided[:, ::2] = x
    h_s, J_s = fd.cv_doppler_and_jacobian(strided[:, ::2], g, times)  # a view with gaps between its entries
    np.testing.assert_array_equal(h_s, h)
    np.testing.assert_array_equal(J_s, J)
    h1, J1 = fd.cv_doppler_and_jacobian(x[7], g, times)
    np.testing.assert_array_equal(h1, h[7])
    np.testing.assert_array_equal(J1, J[7])


@pytest.mark.parametrize("dim", [2, 3])
def test_a_window_laid_out_once_is_the_compiled_loops_to_the_bit(rng: np.random.Generator, dim: int) -> None:
    """The window factor's evaluator (times and sensors checked and laid out once) gives the numbers, the
    Jacobian and the singular entries of :func:`~fgdoppler.models.doppler_kernels.along` and
    ``along_and_jacobian`` exactly, and refuses what they refuse."""
    from fgdoppler.models import doppler_kernels

    g, _, x = _model_and_states(rng, dim, 3, 20)
    t = np.sort(rng.uniform(0.0, 30.0, 24))
    c = rng.integers(0, 3, 24)
    tx, rx = g.positions(dim)
    along = doppler_kernels.Along(t, tx[c], rx[c])
    assert along.state_size == 2 * dim
    for xi in x:
        h, none, clear = along(xi, jacobian=False)
        h_ref, bad_ref = doppler_kernels.along(xi, t, tx[c], rx[c])
        np.testing.assert_array_equal(h, h_ref)
        assert none is None and clear is None and not bad_ref.any()
        hj, J, clear = along(xi, jacobian=True)
        hj_ref, J_ref, _ = doppler_kernels.along_and_jacobian(xi, t, tx[c], rx[c])
        np.testing.assert_array_equal(hj, hj_ref)
        np.testing.assert_array_equal(J, J_ref)
        assert clear is None
    # a track that reaches pair 0's receiver at t = 1 s: that entry flagged, by both paths
    v = np.ones(dim) * 100.0
    on = doppler_kernels.Along(np.array([0.0, 1.0, 2.0]), tx[[0, 0, 0]], rx[[0, 0, 0]])
    start = np.concatenate([g.rx[0] - v, v])
    for jacobian in (False, True):
        h, _, bad = on(start, jacobian=jacobian)
        assert bad is not None and bad.tolist() == [False, True, False]
        np.testing.assert_array_equal(h, doppler_kernels.along(start, np.array([0.0, 1.0, 2.0]),
                                                                tx[[0, 0, 0]], rx[[0, 0, 0]])[0])
    with pytest.raises(ValueError, match="start state of"):
        along(x[0][:-1], jacobian=False)
    with pytest.raises(ValueError, match="as many transmitters"):
        doppler_kernels.Along(t[:-1], tx[c], rx[c])
    with pytest.raises(ValueError, match="coordinates"):
        doppler_kernels.Along(t, tx[c], rx[c][:, :1])
