"""Stone Soup interoperability: the model equals fgdoppler's, Stone Soup's EKF equals ours, exact round trips."""

from __future__ import annotations

import datetime as dt
import subprocess
import sys

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.ekf import run_ekf
from fgdoppler.models.doppler import bistatic_doppler_and_jacobian

ss = pytest.importorskip("stonesoup", reason="extra 'stonesoup' not installed")

from stonesoup.models.transition.linear import (  # noqa: E402
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.predictor.kalman import ExtendedKalmanPredictor  # noqa: E402
from stonesoup.types.array import StateVectors  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import ParticleState, State  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402
from stonesoup.updater.kalman import ExtendedKalmanUpdater  # noqa: E402

from fgdoppler.interop.stonesoup import (  # noqa: E402
    TO_STONESOUP,
    TO_STONESOUP_3D,
    detections,
    from_track,
    measurements_from,
    models,
    prior,
    to_track,
)

EPOCH = dt.datetime(2026, 1, 1, 12, 0, 0)


def _random_states(rng: np.random.Generator, n: int) -> np.ndarray:
    pos = rng.uniform([-20e3, -30e3], [70e3, 30e3], (n, 2))
    vel = rng.uniform(-300, 300, (n, 2))
    return np.column_stack([pos, vel])


@pytest.mark.parametrize("case", ["a", "b"])
def test_model_equals_fgdoppler_and_its_jacobian_equals_finite_differences(case: str) -> None:
    """h and ∂h/∂x of the Stone Soup model equal fgdoppler's to 1e-12 (relative), per state and vectorised."""
    geom = fd.paper_geometry(case)  # type: ignore[arg-type]
    rng = np.random.default_rng(7)
    xs = _random_states(rng, 200)
    h_ref, J_ref = bistatic_doppler_and_jacobian(xs, geom)
    for i, mdl in enumerate(models(geom, 0.5)):
        assert mdl.ndim_meas == 1 and mdl.covar()[0, 0] == pytest.approx(0.25)
        # all 200 states at once, as a particle filter calls it
        h_all = np.asarray(mdl.function(State(StateVectors(xs[:, TO_STONESOUP].T))), dtype=float).reshape(-1)
        np.testing.assert_allclose(h_all, h_ref[:, i], rtol=1e-12, atol=1e-12)
        for k in range(0, 200, 20):
            st = State(xs[k, TO_STONESOUP].reshape(4, 1))
            J = mdl.jacobian(st)
            np.testing.assert_allclose(J[0], J_ref[k, i][TO_STONESOUP], rtol=1e-12, atol=1e-15)
            # central differences of Stone Soup's own function, in Stone Soup's order
            step = np.array([1.0, 1e-3, 1.0, 1e-3])
            fd_J = np.empty(4)
            for j in range(4):
                e = np.zeros((4, 1))
                e[j] = step[j]
                up = float(mdl.function(State(st.state_vector + e))[0, 0])
                down = float(mdl.function(State(st.state_vector - e))[0, 0])
                fd_J[j] = (up - down) / (2 * step[j])
            np.testing.assert_allclose(J[0], fd_J, rtol=1e-5, atol=1e-9)


def test_noise_is_drawn_with_the_models_covariance() -> None:
    """``function(noise=True)`` adds N(0, σ²): sample variance within a χ² 99.9 % band (fixed seed)."""
    mdl = models(fd.paper_geometry("a"), 2.0)[0]
    x = np.tile(np.array([[20e3], [-50.0], [1e3], [10.0]]), (1, 4000))
    np.random.seed(3)  # noqa: NPY002 -- Stone Soup draws from numpy's global generator
    z = np.asarray(mdl.function(State(StateVectors(x)), noise=True), dtype=float).reshape(-1)
    z0 = np.asarray(mdl.function(State(StateVectors(x))), dtype=float).reshape(-1)
    var = np.var(z - z0, ddof=1)
    from scipy.stats import chi2

    lo, hi = chi2.ppf([0.0005, 0.9995], 3999) / 3999 * 4.0
    assert lo < var < hi


def _scenario(index: int = 2, seed: int = 1) -> tuple[fd.Scenario, fd.Measurements, fd.TrackingModel, fd.Initiation]:
    scen = fd.paper_scenarios()[index]
    sim = fd.simulate(scen, np.random.default_rng(seed))
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    return scen, sim.measurements, model, init


@pytest.mark.parametrize("index", [0, 2, 3])
def test_stonesoup_ekf_equals_fgdoppler_ekf(index: int) -> None:
    """Stone Soup's EKF with this model, from fgdoppler's initiation, equals fgdoppler's EKF (gate off) to 1e-9.

    fgdoppler's EKF updates one measurement at a time, relinearising after
    each; Stone Soup does the same when every detection is its own update
    (prediction over zero time between the pairs of one scan is exact:
    F = I, Q = 0).
    """
    scen, m, model, init = _scenario(index)
    ours = run_ekf(m, model, init, fd.EKFSettings(gate_probability=None, components=1)).primary
    _assert_same_track(_stonesoup_ekf(scen, m, model, init, per_scan=False), ours)


def _stonesoup_ekf(scen: fd.Scenario, m: fd.Measurements, model: fd.TrackingModel, init: fd.Initiation, *,
                   per_scan: bool) -> fd.Estimates:
    """Stone Soup's EKF from fgdoppler's initiation over the data after the window, one state per scan."""
    q = model.motion.q
    predictor = ExtendedKalmanPredictor(CombinedLinearGaussianTransitionModel([ConstantVelocity(q),
                                                                                ConstantVelocity(q)]))
    updater = ExtendedKalmanUpdater(measurement_model=None)
    state = prior(init, EPOCH)
    track = Track([state])
    dets = [d for d in detections(m, scen.geometry, EPOCH, per_scan=per_scan) if d.metadata["time"] > init.t_end + 1e-9]
    for k, d in enumerate(dets):
        state = updater.update(SingleHypothesis(predictor.predict(state, timestamp=d.timestamp), d))
        if k + 1 == len(dets) or dets[k + 1].timestamp != d.timestamp:
            track.append(state)
    return from_track(track, EPOCH).primary


def _assert_same_track(theirs: fd.Estimates, ours: fd.Estimates) -> None:
    """Times to 1 µs, states to 1e-9 of their scale, covariances to 1e-9 of σσ'."""
    np.testing.assert_allclose(theirs.times, ours.times, rtol=0, atol=1e-6)
    scale_x = np.abs(ours.states).max(axis=0)
    np.testing.assert_allclose(theirs.states / scale_x, ours.states / scale_x, rtol=0, atol=1e-9)
    scale_p = np.sqrt(np.einsum("kii->ki", ours.covariances))
    norm = scale_p[:, :, None] * scale_p[:, None, :]
    np.testing.assert_allclose(theirs.covariances / norm, ours.covariances / norm, rtol=0, atol=1e-9)


@pytest.mark.parametrize("index", [0, 2, 4])
def test_stonesoup_ekf_per_scan_equals_fgdoppler_vector_update(index: int) -> None:
    """One Detection per scan (all pairs at one time) against ``EKFSettings(update="scan")``: the same vector
    update, linearised once at the prediction, to 1e-9 (case b's pairs are asynchronous: scans of one)."""
    scen, m, model, init = _scenario(index)
    ours = run_ekf(m, model, init, fd.EKFSettings(gate_probability=None, components=1, update="scan")).primary
    _assert_same_track(_stonesoup_ekf(scen, m, model, init, per_scan=True), ours)
    scale_x = np.abs(ours.states).max(axis=0)
    if scen.geometry.name == "a":  # synchronous pairs: the vector update is not the sequential one
        seq = run_ekf(m, model, init, fd.EKFSettings(gate_probability=None, components=1)).primary
        assert np.max(np.abs(seq.states - ours.states) / scale_x) > 1e-9


def test_detections_keep_every_measurement_time_and_pair() -> None:
    """CSV → Measurements → Detections → Measurements is exact, and each detection has its pair's model."""
    scen, m, _, _ = _scenario(3)
    dets = detections(m, scen.geometry, EPOCH)
    assert len(dets) == len(m)
    back = measurements_from(dets)
    for field in ("time", "pair", "doppler", "sigma"):
        np.testing.assert_array_equal(getattr(back, field), getattr(m, field))
    for d, p, t in zip(dets, m.pair, m.time, strict=True):
        np.testing.assert_array_equal(np.asarray(d.measurement_model.tx, dtype=float).reshape(-1),
                                      scen.geometry.tx[p])
        np.testing.assert_array_equal(np.asarray(d.measurement_model.rx, dtype=float).reshape(-1),
                                      scen.geometry.rx[p])
        assert abs((d.timestamp - EPOCH).total_seconds() - t) < 1e-6


def test_detections_from_a_csv_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A measurement CSV written by fgdoppler becomes the same detections as its in-memory source."""
    scen, m, _, _ = _scenario(0)
    path = tmp_path / "m.csv"
    m.to_csv(path)
    dets = detections(fd.Measurements.from_csv(path), scen.geometry, EPOCH)
    back = measurements_from(dets)
    np.testing.assert_array_equal(back.pair, m.pair)
    np.testing.assert_allclose(back.time, m.time, rtol=1e-15)
    np.testing.assert_allclose(back.doppler, m.doppler, rtol=1e-15)


@pytest.mark.parametrize("name", ["ekf", "smoother"])
def test_track_round_trip_is_exact(name: str) -> None:
    """fgdoppler result → Stone Soup track → fgdoppler result: times, states, covariances bit for bit."""
    _, m, model, init = _scenario(2)
    res = fd.run_estimator(name, m, model, init)
    track = to_track(res, EPOCH)
    assert len(track) == len(res.primary)
    first = track.states[0]
    np.testing.assert_array_equal(np.asarray(first.state_vector, dtype=float).reshape(-1),
                                  res.primary.states[0][TO_STONESOUP])
    back = from_track(track, EPOCH)
    assert back.estimator == res.estimator and back.primary.kind == res.primary.kind
    np.testing.assert_array_equal(back.primary.times, res.primary.times)
    np.testing.assert_array_equal(back.primary.states, res.primary.states)
    np.testing.assert_array_equal(back.primary.cov_ok, res.primary.cov_ok)
    ok = res.primary.cov_ok
    np.testing.assert_array_equal(back.primary.covariances[ok], res.primary.covariances[ok])


def test_3d_model_equals_fgdoppler_and_3d_tracks_round_trip() -> None:
    """The 3-D layout ([x, vx, y, vy, z, vz]): h and J equal fgdoppler's, J equals central differences,
    and a 3-D track goes to Stone Soup and back bit for bit."""
    geom = fd.Geometry(pairs=(fd.BistaticPair(tx=(0, 0, 0), rx=(20e3, 0, 0)),
                              fd.BistaticPair(tx=(0, 0, 0), rx=(0, 20e3, 300.0))))
    rng = np.random.default_rng(8)
    xs = np.column_stack([rng.uniform(1e3, 19e3, (50, 2)), rng.uniform(500, 9e3, 50), rng.uniform(-200, 200, (50, 3))])
    h_ref, J_ref = bistatic_doppler_and_jacobian(xs, geom)
    perm = TO_STONESOUP_3D
    for i, mdl in enumerate(models(geom, 1.0)):
        assert mdl.ndim_state == 6
        h_all = np.asarray(mdl.function(State(StateVectors(xs[:, perm].T))), dtype=float).reshape(-1)
        np.testing.assert_allclose(h_all, h_ref[:, i], rtol=1e-12, atol=1e-12)
        for k in range(0, 50, 10):
            st = State(xs[k, perm].reshape(6, 1))
            J = mdl.jacobian(st)
            np.testing.assert_allclose(J[0], J_ref[k, i][perm], rtol=1e-12, atol=1e-15)
            fd_J = np.empty(6)
            for j in range(6):
                e = np.zeros((6, 1))
                e[j] = 1.0 if j % 2 == 0 else 1e-3
                fd_J[j] = (float(mdl.function(State(st.state_vector + e))[0, 0])
                           - float(mdl.function(State(st.state_vector - e))[0, 0])) / (2 * e[j, 0])
            np.testing.assert_allclose(J[0], fd_J, rtol=1e-5, atol=1e-9)
    scen = fd.Scenario(geometry=geom, x0=(5e3, 8e3, 3e3, 100.0, 40.0, 0.0), duration=10.0, dt=0.5)
    sim = fd.simulate(scen, np.random.default_rng(3))
    res = fd.run_estimator("ekf", sim.measurements, geom, fd.initiate(sim.measurements.first_per_pair(10), geom))
    back = from_track(to_track(res, EPOCH), EPOCH)
    np.testing.assert_array_equal(back.primary.states, res.primary.states)
    ok = res.primary.cov_ok
    np.testing.assert_array_equal(back.primary.covariances[ok], res.primary.covariances[ok])
    dets = detections(sim.measurements, geom, EPOCH, per_scan=True)
    assert dets[0].measurement_model.ndim_state == 6
    back_m = measurements_from(dets)
    np.testing.assert_array_equal(back_m.doppler, sim.measurements.doppler)


def test_prior_is_the_initiation_at_its_window_end() -> None:
    _, _, _, init = _scenario(2)
    p = prior(init, EPOCH)
    assert p.timestamp == EPOCH + dt.timedelta(seconds=init.t_end)
    np.testing.assert_array_equal(np.asarray(p.state_vector, dtype=float).reshape(-1), init.x_end[TO_STONESOUP])
    assert init.P_end is not None
    np.testing.assert_array_equal(np.asarray(p.covar), init.P_end[np.ix_(TO_STONESOUP, TO_STONESOUP)])


def test_particle_track_becomes_weighted_mean_and_covariance() -> None:
    """A track of particle states converts to their weighted mean and covariance (analytic for 2 particles)."""
    a = np.array([1.0, 2.0, 3.0, 4.0])
    b = np.array([3.0, 6.0, 7.0, 0.0])
    particles = ParticleState(StateVectors(np.column_stack([a, b])[TO_STONESOUP]), weight=np.array([0.5, 0.5]), timestamp=EPOCH)
    res = from_track(Track([particles]), EPOCH)
    np.testing.assert_allclose(res.primary.states[0], (a + b) / 2)
    d = (a - b) / 2
    # Σ w (x - m)(x - m)ᵀ with deviations ±d of weight ½ each
    np.testing.assert_allclose(res.primary.covariances[0], np.outer(d, d), rtol=1e-12)


def test_missing_extra_names_it() -> None:
    """Without Stone Soup, importing the bridge raises an ImportError that names the extra."""
    code = ("import sys; sys.modules['stonesoup'] = None\n"
            "try:\n    import fgdoppler.interop.stonesoup\nexcept ImportError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "pip install 'fgdoppler[stonesoup]'" in out
    # fgdoppler itself never imports Stone Soup
    code = "import sys, fgdoppler; print('stonesoup' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"
