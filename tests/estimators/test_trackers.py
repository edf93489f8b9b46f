"""Trackers: cross-estimator equalities, a linear-Gaussian surrogate, bad conditions."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import gtsam
import numpy as np
import pytest
from scipy.stats import chi2, poisson

import fgdoppler as fd
from fgdoppler.csvfile import CSVError
from fgdoppler.estimators import run_estimator
from fgdoppler.estimators.ekf import ExtendedKalmanFilter, run_ekf
from fgdoppler.estimators.fixed_lag import FixedLagTracker, run_fixed_lag
from fgdoppler.estimators.initiation import initiate, lm_params
from fgdoppler.estimators.isam2 import ISAM2Tracker, run_isam2
from fgdoppler.estimators.results import Estimates, TrackResult, states_csv
from fgdoppler.estimators.settings import (
    EKFSettings,
    FixedLagSettings,
    ISAM2Settings,
    SmootherSettings,
)
from fgdoppler.estimators.smoother import run_smoother
from fgdoppler.factors import X, measurement_factor, motion_factor, prior_factor


def _setup(case: str = "a", x: float = 45e3, seed: int = 1):
    sc = fd.paper_scenario(case, x)
    sim = fd.simulate(sc, np.random.default_rng(seed))
    model = fd.TrackingModel.of(sc.geometry)
    init = initiate(sim.measurements.first_per_pair(10), model)
    return sc, sim, model, init


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference relative to each state component's scale over the trajectory."""
    scale = np.maximum(np.abs(b).max(axis=0), 1e-12)
    return float(np.max(np.abs(a - b) / scale))


def _gtsam_lm(sim: fd.Simulation, model: fd.TrackingModel, start: np.ndarray):
    """The same graph built from CustomFactors one by one here and solved by GTSAM's own LM."""
    m = sim.measurements
    sc = m.scans()
    g = gtsam.NonlinearFactorGraph()
    v = gtsam.Values()
    g.add(prior_factor(X(0), *model.prior()))
    for k in range(len(sc)):
        sl = sc.rows(k)
        g.add(measurement_factor(X(k), model.observation, m.pair[sl], m.doppler[sl], m.sigma[sl]))
        if k:
            g.add(motion_factor(X(k - 1), X(k), sc.times[k] - sc.times[k - 1], model.motion))
        v.insert(X(k), start[k])
    res = gtsam.LevenbergMarquardtOptimizer(g, v, lm_params(200)).optimize()
    keys = [X(k) for k in range(len(sc))]
    # Reference marginals independent of every GTSAM/fgdoppler elimination path: the SVD of the
    # whitened Jacobian of the linearised graph, C = V S^-2 V' (columns in key order x0, x1, ...).
    gfg = g.linearize(res)
    assert sorted(gfg.keyVector()) == keys
    A, _ = gfg.jacobian()
    _, sv, Vt = np.linalg.svd(A, full_matrices=False)
    C = (Vt.T / sv**2) @ Vt
    covs = np.array([C[4 * k:4 * k + 4, 4 * k:4 * k + 4] for k in range(len(keys))])
    return np.array([res.atVector(k) for k in keys]), covs


@pytest.mark.parametrize(("case", "x"), [("a", 45e3), ("b", 5e3)])
def test_isam2_and_batch_equal_gtsam_lm_on_the_same_graph(case: str, x: float) -> None:
    _, sim, model, init = _setup(case, x)
    isam = run_isam2(sim.measurements, model, init).estimate("smoothed")
    batch = run_smoother(sim.measurements, model, init).primary
    # GTSAM LM started away from both answers
    lm, lm_cov = _gtsam_lm(sim, model, sim.truth.states + np.array([50.0, -30.0, 1.0, -0.5]))
    assert _rel(isam.states, lm) <= 1e-6
    assert _rel(batch.states, lm) <= 1e-6
    for covs in (isam.covariances, batch.covariances):
        scale = np.abs(lm_cov).max(axis=(1, 2))[:, None, None]
        assert np.max(np.abs(covs - lm_cov) / scale) <= 1e-5


def test_fixed_lag_longer_than_track_equals_batch() -> None:
    _, sim, model, init = _setup("a", 45e3)
    batch = run_smoother(sim.measurements, model, init).primary
    fl = run_fixed_lag(sim.measurements, model, init, FixedLagSettings(lag=1e3)).primary
    np.testing.assert_array_equal(fl.times, batch.times)
    assert _rel(fl.states, batch.states) <= 1e-6
    scale = np.abs(batch.covariances).max(axis=(1, 2))[:, None, None]
    assert np.max(np.abs(fl.covariances - batch.covariances) / scale) <= 1e-5


def test_fixed_lag_marginalises_and_stays_close_to_batch() -> None:
    _, sim, model, init = _setup("b", 5e3)
    fl = run_fixed_lag(sim.measurements, model, init, FixedLagSettings(lag=3.0))
    assert not fl.events and fl.status == "ok"
    lag = fl.estimate("lagged")
    assert len(lag) == sim.truth.times.size
    batch = run_smoother(sim.measurements, model, init).primary
    # With marginalisation, old information is frozen at old linearisation points, so the
    # last state differs from the full batch only by that linearisation loss: small against
    # the posterior standard deviation.
    sd = np.sqrt(np.diag(batch.covariances[-1]))
    assert np.all(np.abs(lag.states[-1] - batch.states[-1]) < 0.1 * sd)


# -- a linear-Gaussian surrogate: position measurements through the same machinery --------
@dataclass(frozen=True)
class PositionModel:
    """Channel 0 measures x, channel 1 measures y (linear)."""

    @property
    def n_channels(self) -> int:
        return 2

    def predict(self, states: np.ndarray, channels: np.ndarray) -> np.ndarray:
        x = np.asarray(states, dtype=float).reshape(-1, 4)
        return x[np.arange(x.shape[0]), np.asarray(channels, dtype=int)]

    def predict_and_jacobian(self, states: np.ndarray, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = np.asarray(channels, dtype=int)
        H = np.zeros((c.size, 4))
        H[np.arange(c.size), c] = 1.0
        return self.predict(states, c), H


def _kalman(x0, P0, t0, scans, motion):
    """A textbook Kalman filter (joint update per scan), written independently here."""
    x, P, t = x0.copy(), P0.copy(), t0
    out = []
    for ts, ch, z, s in scans:
        dt = ts - t
        if dt > 0:
            F = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1.0]])
            q = motion.q
            Q = q * np.array([[dt**3 / 3, 0, dt**2 / 2, 0], [0, dt**3 / 3, 0, dt**2 / 2],
                              [dt**2 / 2, 0, dt, 0], [0, dt**2 / 2, 0, dt]])
            x, P = F @ x, F @ P @ F.T + Q
        H = np.zeros((len(ch), 4))
        H[np.arange(len(ch)), ch] = 1.0
        S = H @ P @ H.T + np.diag(np.asarray(s) ** 2)
        K = np.linalg.solve(S, H @ P).T
        x = x + K @ (z - H @ x)
        P = (np.eye(4) - K @ H) @ P
        out.append((x.copy(), P.copy()))
        t = ts
    return out


def test_linear_gaussian_surrogate_ekf_isam2_fixed_lag_agree_with_kalman() -> None:
    rng = np.random.default_rng(4)
    motion = fd.ConstantVelocity(q=0.5)
    tm = fd.TrackingModel(observation=PositionModel(), motion=motion)
    x0 = np.array([100.0, -50.0, 3.0, 1.0])
    P0 = np.diag([25.0, 25.0, 4.0, 4.0])
    times = np.cumsum(rng.uniform(0.2, 1.0, 40))
    scans = []
    for k, t in enumerate(times):
        ch = [0, 1] if k % 3 else [1]  # asynchronous-looking: sometimes only y
        truth = x0 + np.array([t * 3.0, t * 1.0, 0, 0])
        scans.append((t, ch, truth[ch] + rng.normal(0, 2.0, len(ch)), [2.0] * len(ch)))
    ref = _kalman(x0, P0, 0.0, scans, motion)
    ekf = ExtendedKalmanFilter(tm, x0, P0, 0.0, EKFSettings(gate_probability=None))
    vec = ExtendedKalmanFilter(tm, x0, P0, 0.0, EKFSettings(gate_probability=None, update="scan"))
    # an exact prior: every scan is one update from the first (no warm-up)
    cold = {"warmup_seconds": 0.0, "warmup_per_pair": 0}
    isam = ISAM2Tracker(tm, ISAM2Settings(gate_probability=None, **cold), prior=None)
    fl = FixedLagTracker(tm, FixedLagSettings(gate_probability=None, lag=2.5, **cold), prior=None)
    # iSAM2/fixed-lag: a state at t = 0 with the prior and no measurement, then the scans
    isam.prior = (x0, P0)
    isam.add_scan(0.0, [], [], [], x0)
    fl.prior = (x0, P0)
    fl.add_scans([0.0], [[]], [[]], [[]], [x0])
    for (t, ch, z, sig), (xr, Pr) in zip(scans, ref, strict=True):
        for c, zz, ss in zip(ch, z, sig, strict=True):
            ekf.update(t, c, zz, ss)
        vec.update_scan(t, np.array(ch), np.array(z), np.array(sig))  # the vector update of a linear model too
        xi, Pi = isam.add_scan(t, ch, z, sig)
        xf, Pf = fl.add_scans([t], [ch], [z], [sig])
        for x, P in ((ekf.x, ekf.P), (vec.x, vec.P), (xi, Pi), (xf, Pf)):
            np.testing.assert_allclose(x, xr, rtol=1e-8, atol=1e-8 * np.abs(xr).max())
            np.testing.assert_allclose(P, Pr, rtol=1e-8, atol=1e-8 * np.abs(Pr).max())


def test_ekf_takes_a_scan_in_the_sensors_order_whatever_the_rows_or_the_numbering() -> None:
    # Sequential scalar updates of a nonlinear model do not commute, so the EKF fixes the order of a scan's
    # updates by the sensors (Geometry.scan_rank): the rows' order and the numbering of the pairs after the
    # first must not change a bit of the answer.  Three pairs measuring at once, a broad start (where the
    # order matters most).
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(40e3, 0.0), rx=(0.0, 0.0)),
                           fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3)),
                           fd.BistaticPair(tx=(5e3, 30e3), rx=(0.0, 0.0))))
    truth = np.array([20e3, 10e3, -60.0, 70.0])
    x0, P0 = truth + np.array([3e3, -2e3, 40.0, -30.0]), np.diag([4e6, 4e6, 2.5e3, 2.5e3])
    at_1s = truth + np.array([-60.0, 70.0, 0.0, 0.0])  # the truth at the scan's time, t = 1 s
    z = fd.DopplerModel(geometry=g).predict(np.tile(at_1s, (3, 1)), [0, 1, 2]) + np.random.default_rng(5).normal(0, 1, 3)

    def scan(geometry: fd.Geometry, channels: list[int], doppler: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ekf = ExtendedKalmanFilter(fd.TrackingModel.of(geometry), x0, P0, 0.0, EKFSettings(gate_probability=None))
        ekf.add_scan(1.0, channels, doppler, 1.0)
        return ekf.x, ekf.P

    x_ref, P_ref = scan(g, [0, 1, 2], z)
    for rows in ([0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]):
        x, P = scan(g, rows, z[rows])
        np.testing.assert_array_equal(x, x_ref)
        np.testing.assert_array_equal(P, P_ref)
    perm = [0, 2, 1]  # pairs 1 and 2 swapped: old pair i is new pair new_of[i]
    new_of = np.argsort(perm)
    x, P = scan(fd.Geometry(pairs=tuple(g.pairs[i] for i in perm)), new_of.tolist(), z)
    np.testing.assert_array_equal(x, x_ref)
    np.testing.assert_array_equal(P, P_ref)
    # the order does matter here: the same updates one by one in the pairs' numbering differ
    ekf = ExtendedKalmanFilter(fd.TrackingModel.of(g), x0, P0, 0.0, EKFSettings(gate_probability=None))
    for c in (0, 1, 2):
        ekf.update(1.0, c, float(z[c]), 1.0)
    assert list(np.argsort(g.scan_rank)) != [0, 1, 2]
    assert np.max(np.abs(ekf.x - x_ref)) > 1e-6 * np.max(np.abs(x_ref))


# -- bad conditions ------------------------------------------------------------------------
def _paper_at_20_hz(duration: float):
    """Paper geometry (a), a well-observed track (the scaling benchmark's), 20 scans/s, seed 0."""
    sc = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=duration, dt=0.05)
    return sc, fd.simulate(sc, np.random.default_rng(0))


def test_isam2_holds_a_well_observed_track_at_20_hz() -> None:
    # At 20 scans/s the 10 most recent states are half a second: a tracker that checked only
    # those left the factors of states it had long moved away from linearised where the
    # states were while it converged from the prior, and lost the target (measured without
    # the history check, 1,200 scans: 0.6 % of the measurements accepted, end error 11.7 km
    # at a stated sd of 55 m; on 2026-12-04, with the gate and restarts of today, 4 of 2,360
    # rejected but the end error 5.1 km at a stated sd of 90 m, squared Mahalanobis distance
    # 35,925: the last assertion's failure).  With it the track holds: once it has converged from the prior,
    # the 0.9999 gate rejects no more genuine measurements than a consistent filter's would,
    # and the end state is consistent with its covariance.  Streamed from the first scan (the
    # warm-up off), as the check has to hold the track from there.  While it converges the gate
    # does reject some: measured 2026-12-04, 11 of 2,360 with OpenBLAS's Haswell kernels and 26
    # with those it picks on an AMD EPYC (the same code; iSAM2 amplifies the arithmetic's last
    # bits there), all before 5.2 s.  So the count is taken from 10 s on, where a consistent
    # filter rejects each of ~2,000 measurements with probability 1e-4: a Poisson count of mean
    # 0.2, whose 1 - 1e-6 quantile is the bound.
    sc, sim = _paper_at_20_hz(59.95)
    model = fd.TrackingModel.of(sc.geometry)
    settings = ISAM2Settings(warmup_seconds=0.0, warmup_per_pair=0)
    tracker = ISAM2Tracker(model, settings, model.prior())
    m = sim.measurements
    scans = m.scans()
    x0 = sim.truth.states[0]
    for k in range(len(scans)):
        r = scans.rows(k)
        x, P = tracker.add_scan(scans.times[k], m.pair[r], m.doppler[r], m.sigma[r], x0 if k == 0 else None,
                                gate=k >= 20)
    assert P is not None and settings.gate_probability == 0.9999
    gate = tracker.gate.as_array()
    later = gate[gate[:, 0] >= 10.0]
    assert later.shape[0] > 1900
    assert np.sum(later[:, 3] == 0) <= poisson.isf(1e-6, later.shape[0] * (1.0 - settings.gate_probability))
    d = x - sim.truth.states[-1]
    assert float(d @ np.linalg.solve(P, d)) <= chi2.ppf(0.9999, 4)


def test_ekf_from_a_window_in_time_is_consistent_at_20_hz() -> None:
    # fd.track's window spans 4.5 s (initiation_window): at 20 Hz, 91 scans rather than the
    # 10 (0.45 s) that 10 per pair would give.  Measured on this recording, NEES averaged over
    # 5-20 s: 119 from the short window (init_seconds=0), 10.7 from the 4.5 s one; the bound
    # is the single-time 0.9999 quantile, 23.5.
    sc, sim = _paper_at_20_hz(19.95)
    r = fd.track(sim.measurements, sc.geometry, "ekf")
    e = r.primary
    d = e.states - sim.truth.at(e.times)
    later = np.flatnonzero((e.times >= 5.0) & e.cov_ok)
    nees = np.array([d[k] @ np.linalg.solve(e.covariances[k], d[k]) for k in later])
    assert later.size > 200
    assert np.mean(nees) <= chi2.ppf(0.9999, 4)


@pytest.mark.parametrize("bad", [{"relinearize_history": -1}, {"relinearize_history": 2.5},
                                 {"relinearize_every": 0}, {"relinearize_window": 0},
                                 {"relinearize_position": 0.0}, {"wildfire_threshold": float("nan")},
                                 {"sampling_interval": 0.0}, {"sampling_interval": float("inf")},
                                 {"sampled_covariance": 1}, {"keep_states": -1}, {"keep_states": 500.0},
                                 {"keep_states": True}])
def test_isam2_settings_reject_bad_values(bad: dict) -> None:
    name = next(iter(bad))
    with pytest.raises(ValueError, match=name):
        ISAM2Settings(**bad)
    ISAM2Settings(relinearize_history=0)  # 0 switches the history check off
    ISAM2Settings(keep_states=0)  # 0 keeps every state


@pytest.mark.parametrize("bad", [{"sampling_interval": -1.0}, {"sampling_interval": float("nan")},
                                 {"sampled_covariance": "yes"}, {"update": "iterated"},
                                 {"gaussian_gate_probability": 1.0}, {"gaussian_gate_probability": True},
                                 {"gaussian_gate_probability": 0.99}])  # the last: narrower than the gate
def test_ekf_settings_reject_bad_values(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        EKFSettings(**bad)


@pytest.mark.parametrize("bad", [{"sampling_interval": 0.0}, {"sampling_interval": float("inf")},
                                 {"sampled_covariance": None}, {"lag": -5.0}])
def test_fixed_lag_settings_reject_bad_values(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        FixedLagSettings(**bad)


@pytest.mark.parametrize("bad", [{"sampled_covariance": 1}, {"posterior_mean": "yes"}, {"posterior_mean": None}])
def test_smoother_settings_reject_bad_values(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        SmootherSettings(**bad)


def test_outlier_is_gated_by_nis_and_downweighted_by_huber() -> None:
    _, sim, model, init = _setup("a", 45e3)
    m = sim.measurements
    bad = m.doppler.copy()
    j = int(np.flatnonzero(m.time == 20.0)[0])
    bad[j] += 60.0  # 60 sigma
    mo = fd.Measurements(time=m.time, pair=m.pair, doppler=bad, sigma=m.sigma)
    clean = run_ekf(m, model, init).primary
    for name in ("ekf", "isam2", "fixed-lag"):
        r = run_estimator(name, mo, model, init)
        rejected = r.nis[r.nis[:, 3] == 0]
        assert rejected.shape[0] >= 1 and np.any(rejected[:, 0] == 20.0), name
        assert any("rejected" in e.message for e in r.events), name
    ekf_out = run_ekf(mo, model, init).primary
    # rejecting the outlier costs one measurement's information: a small fraction of sigma
    sd = np.sqrt(np.diag(clean.covariances[-1]))
    assert np.all(np.abs(ekf_out.states[-1] - clean.states[-1]) < 0.25 * sd)
    # batch: Huber limits the damage of the outlier compared with a plain Gaussian loss
    truth_end = sim.truth.states[-1]
    plain = run_smoother(mo, model, init).primary
    robust = run_smoother(mo, model, init, SmootherSettings(huber_k=1.345)).primary
    assert np.linalg.norm(robust.states[-1, :2] - truth_end[:2]) < np.linalg.norm(plain.states[-1, :2] - truth_end[:2])


def test_gap_in_the_data_is_bridged() -> None:
    _, sim, model, init = _setup("a", 45e3)
    m = sim.measurements
    gapped = m.subset((m.time <= 10.0) | (m.time >= 20.0))
    gapped_results, full_results = (fd.run_estimators(fd.ESTIMATORS, d, model, init) for d in (gapped, m))
    for name in fd.ESTIMATORS:
        r = gapped_results[name]
        full = full_results[name].primary
        e = r.primary
        assert np.all(np.isfinite(e.states)) and np.all(e.cov_ok), name
        assert not any("failed" in ev.message for ev in r.events), name
        assert not np.any((e.times > 10.0) & (e.times < 20.0)), name
        # ten seconds without data leave the estimate at t = 20 s less certain than with them
        i, j = np.searchsorted(e.times, 20.0), np.searchsorted(full.times, 20.0)
        assert np.trace(e.covariances[i][:2, :2]) > np.trace(full.covariances[j][:2, :2]), name


def test_out_of_order_is_rejected_in_streaming_and_batch_input() -> None:
    model = fd.TrackingModel.of(fd.paper_geometry("a"))
    x0 = np.array([45e3, 2e3, 10.0, -100.0])
    ekf = ExtendedKalmanFilter(model, x0, np.eye(4), 1.0)
    with pytest.raises(ValueError, match="out of order"):
        ekf.update(0.5, 0, 1.0, 1.0)
    for bad in (np.nan, np.inf):  # NaN compares false both ways: it once propagated the state to NaN silently
        with pytest.raises(ValueError, match="not a finite number"):
            ekf.add_scan(bad, [0], [1.0], [1.0])
    assert np.all(np.isfinite(ekf.x))
    cold = {"warmup_seconds": 0.0, "warmup_per_pair": 0}  # the warm-up's own check: test_warmup.py
    tr = ISAM2Tracker(model, ISAM2Settings(**cold), prior=(x0, np.eye(4)))
    tr.add_scan(1.0, [0, 1], [0.0, 0.0], [1.0, 1.0], x0)
    with pytest.raises(ValueError, match="out of order"):
        tr.add_scan(1.0, [0], [0.0], [1.0])
    with pytest.raises(ValueError, match="scan time nan is not a finite number"):
        tr.add_scan(np.nan, [0], [0.0], [1.0])
    fl = FixedLagTracker(model, FixedLagSettings(**cold), prior=(x0, np.eye(4)))
    fl.add_scans([1.0], [[0]], [[0.0]], [[1.0]], [x0])
    with pytest.raises(ValueError, match="out of order"):
        fl.add_scans([0.5], [[0]], [[0.0]], [[1.0]])
    with pytest.raises(ValueError, match="scan time inf is not a finite number"):
        fl.add_scans([np.inf], [[0]], [[0.0]], [[1.0]])
    with pytest.raises(fd.MeasurementError, match="time order"):
        fd.Measurements.from_arrays([1.0, 0.5], [0, 0], [1.0, 1.0], 1.0)


def test_ill_conditioned_steps_do_not_crash() -> None:
    # moving along the Tx1-Rx1 baseline: pair 1 is blind, the problem is near-singular
    g = fd.paper_geometry("a")
    sc = fd.Scenario(geometry=g, x0=(20e3, 0.0, 100.0, 0.0), duration=20.0)
    sim = fd.simulate(sc, np.random.default_rng(0))
    model = fd.TrackingModel.of(g)
    init = initiate(sim.measurements.first_per_pair(10), model)
    for name, r in fd.run_estimators(fd.ESTIMATORS, sim.measurements, model, init).items():
        assert np.all(np.isfinite(r.primary.states)), name
        # indeterminate covariances are flagged, never NaN
        assert np.all(np.isfinite(r.primary.covariances)), name


def test_ekf_skips_update_on_bad_innovation_variance() -> None:
    @dataclass(frozen=True)
    class Broken:
        n_channels: int = 1

        def predict(self, states, channels):
            return np.zeros(len(np.atleast_2d(states)))

        def predict_and_jacobian(self, states, channels):
            return np.zeros(1), np.full((1, 4), np.nan)

    ekf = ExtendedKalmanFilter(fd.TrackingModel(observation=Broken()), np.zeros(4), np.eye(4), 0.0)
    x_before = ekf.x.copy()
    assert np.isnan(ekf.update(1.0, 0, 1.0, 1.0))
    assert ekf.events and "skipped" in ekf.events[0].message
    assert np.all(np.isfinite(ekf.x))
    np.testing.assert_allclose(ekf.x[:2], x_before[:2])


@pytest.mark.parametrize(("edit", "match"), [
    (lambda rows: [*rows[:-1], rows[-1][:7]], r"t\.csv:8: expected 15 fields, got 2"),
    (lambda rows: [r for r in rows if not r.startswith(("#", "time"))], r"t\.csv:1: bad header '0\.0,.*no column 'time'"),
    (lambda rows: [*rows[:-1], ",".join(["5.0", "", *rows[-1].split(",")[2:]])], r"t\.csv:8: x is empty"),
    (lambda rows: [*rows[:-1], ",".join(rows[-1].split(",")[:6] + [""] * 9)], r"t\.csv:8: the covariance is given in part"),
    (lambda rows: [*rows[:-1], rows[-1].replace(",", ",nan", 1)], r"t\.csv:8: x is not a number"),
    (lambda rows: [r for r in rows if not r[:1].isdigit()], r"t\.csv: no data rows after the header"),
])
def test_a_malformed_track_csv_is_refused_with_its_line(tmp_path: Path, edit: object, match: str) -> None:
    """A track file read back (``TrackResult.read_csv``) is checked as every CSV is: a short row, a missing header, an
    empty state cell, a covariance given in part or a non-number is refused naming the line (it used to raise an
    IndexError, or read the first data row as the header and lose it)."""
    times = np.arange(5.0)
    states = np.column_stack([times, 2 * times, np.ones(5), np.zeros(5)])
    est = Estimates(kind="filtered", times=times, states=states, covariances=np.tile(np.eye(4), (5, 1, 1)),
                    cov_ok=np.array([False, True, True, True, True]))
    text = states_csv(est.times, est.states, est.covariances, est.cov_ok, ["fgdoppler ekf: filtered estimates"])
    (tmp_path / "t.csv").write_text(text)
    back = TrackResult.read_csv(tmp_path / "t.csv", kind="filtered")
    np.testing.assert_array_equal(back.states, states)
    assert list(back.cov_ok) == [False, True, True, True, True]
    np.testing.assert_array_equal(back.covariances[1:], est.covariances[1:])
    rows = text.splitlines()
    assert rows[1] == "time,x,y,vx,vy,P00,P01,P02,P03,P11,P12,P13,P22,P23,P33" and len(rows) == 7
    rows.append(rows[-1].replace("4.0,", "5.0,", 1))  # line 8: the row every edit below breaks
    (tmp_path / "t.csv").write_text("\n".join(edit(rows)) + "\n")  # type: ignore[operator]
    with pytest.raises(CSVError, match=match):
        TrackResult.read_csv(tmp_path / "t.csv")


def test_result_csv_json_round_trip(tmp_path) -> None:
    _, sim, model, init = _setup("b", 5e3)
    r = run_smoother(sim.measurements, model, init)
    r.to_csv(tmp_path / "t.csv")
    back = TrackResult.read_csv(tmp_path / "t.csv")
    np.testing.assert_array_equal(back.states, r.primary.states)
    np.testing.assert_allclose(back.covariances, r.primary.covariances, rtol=1e-15)
    r.to_json(tmp_path / "t.json")
    import json

    d = json.loads((tmp_path / "t.json").read_text())
    assert d["estimator"] == "smoother" and d["kind"] == "smoothed" and len(d["states"]) == len(r.primary)
    assert d["status"] == r.status and d["settings"]["type"] == "SmootherSettings"
    assert len(d["covariances"][0]) == 4


def test_unknown_estimator() -> None:
    _, sim, model, init = _setup("a", 45e3)
    with pytest.raises(ValueError, match="unknown estimator"):
        run_estimator("ukf", sim.measurements, model, init)


def test_window_start_is_the_initiation_solution_where_the_wall_is_inactive() -> None:
    # Same window graph built two ways (initiation: Doppler factors; trackers: generic
    # measurement factors): where the region wall is inactive both optima coincide.
    from fgdoppler.estimators.window import split_window, window_start

    _, sim, model, init = _setup("a", 45e3, seed=1)
    assert not any(r.code == "boundary" for r in init.reasons)
    window = split_window(sim.measurements, init.t_end)[0]
    states, note = window_start(model, window, init)
    assert note is None
    assert np.linalg.norm(states[0, :2] - init.x_start[:2]) < 1e-2
    assert np.linalg.norm(states[-1, :2] - init.x_end[:2]) < 1e-2


def test_wall_held_initiation_does_not_throw_isam2_off() -> None:
    # A noise-free target beyond Tx: the initiation's start is held on the region's
    # boundary.  The trackers' window graph has no wall, so its optimum is elsewhere;
    # iSAM2 and the fixed-lag smoother start there (found by damped LM), so iSAM2's first
    # update (one undamped Gauss-Newton step in this very ill-conditioned window, sd of
    # kilometres) moves the window end by well under one standard deviation.  Started on
    # the wall-held track instead, it moved about 6 km (Mahalanobis^2 5-10, seeds 0-2).
    from fgdoppler.estimators.window import split_window, window_start

    g = fd.paper_geometry("a")
    sc = fd.Scenario(geometry=g, x0=(55e3, 3e3, -50.0, -20.0), duration=15.0, dt=0.5, sigma=1.0)
    sim = fd.simulate(sc, np.random.default_rng(2))
    model = fd.TrackingModel.of(g)
    init = initiate(sim.measurements.first_per_pair(10), model)
    assert any(r.code == "boundary" for r in init.reasons)
    window = split_window(sim.measurements, init.t_end)[0]
    start, note = window_start(model, window, init)
    assert note is None
    assert np.linalg.norm(start[0, :2] - init.x_start[:2]) > 100.0  # it left the wall
    r = run_isam2(sim.measurements, model, init)
    first, P = r.estimate("filtered").states[0], r.estimate("filtered").covariances[0]
    d = first - start[-1]
    assert float(d @ np.linalg.solve(P, d)) < 1.0
    # the track is kept: the gate accepts nearly all later measurements
    assert np.mean(r.nis[:, 3]) >= 0.9


def _isam2_feed(model, m, init, settings: ISAM2Settings, check=None, n_scans: int | None = None) -> ISAM2Tracker:
    """Initiation window in one update, then the later scans (all, or ``n_scans``).

    ``check(tracker, k)`` is called before scan ``k``; what it returns (if not
    ``None``) is called after it with the filtered ``(x, P)`` that the scan returned.
    """
    tracker = ISAM2Tracker(model, settings, model.prior())
    sc = m.scans()
    start, _ = fd.estimators.window.window_start(model, m.between(0, init.t_end), init)
    n_win = int(np.searchsorted(sc.times, init.t_end, side="right"))
    rows = [sc.rows(k) for k in range(len(sc))]
    tracker.add_window(sc.times[:n_win], [m.pair[r] for r in rows[:n_win]], [m.doppler[r] for r in rows[:n_win]],
                       [m.sigma[r] for r in rows[:n_win]], start)
    for k in range(n_win, len(sc) if n_scans is None else n_win + n_scans):
        after = check(tracker, k) if check is not None else None
        x, P = tracker.add_scan(sc.times[k], m.pair[rows[k]], m.doppler[rows[k]], m.sigma[rows[k]])
        if after is not None:
            after(x, P)
    return tracker


def test_isam2_marginal_equals_its_full_estimate_and_covariance() -> None:
    # The online estimate is read from the newest state's marginal factor; it must be the
    # exact MAP and marginal covariance of the current linear system, as iSAM2's full
    # back-substitution and its own marginalCovariance give them.
    _, sim, model, init = _setup("b", 5e3)

    def compare(tracker: ISAM2Tracker, k: int):
        def after(x: np.ndarray, P: np.ndarray | None) -> None:
            assert P is not None
            best = tracker.isam.calculateBestEstimate().atVector(X(k))
            full_P = tracker.isam.marginalCovariance(X(k))
            sd = np.sqrt(np.diag(full_P))
            # Both by QR (the condition number of the information matrix reaches ~1e13 here, so a
            # Cholesky path would lose about six digits; measured agreement is ~1e-10).
            assert np.all(np.abs(x - best) <= 1e-7 * sd)
            assert np.max(np.abs(P - full_P)) <= 1e-7 * np.abs(full_P).max()
            checked.append(k)
        return after

    checked: list[int] = []
    _isam2_feed(model, sim.measurements, init, ISAM2Settings(), compare, n_scans=40)
    assert len(checked) == 40


def test_isam2_marginalising_old_states_changes_no_filtered_estimate() -> None:
    # States beyond the relinearisation's reach keep their linear factors for good, so marginalising them out
    # of iSAM2 (keep_states) leaves the Gaussian marginal of every later state what it was: the filtered
    # estimates and covariances agree to rounding (measured 6e-8 sd and 3e-10).  The final smoothing starts the
    # marginalised states from their estimates when they left and converges to the same optimum (3e-7 sd).
    # Case b 25 km at 5 scans/s (300 scans), a short relinearisation reach (10 + 40 states) and 60 states kept:
    # poorly observed, so old states move and are relinearised a lot, and two batches leave, the second
    # through the rows the first left on its first kept state.
    sc = dataclasses.replace(fd.paper_scenario("b", 25e3), dt=0.2)
    sim = fd.simulate(sc, np.random.default_rng(3))
    model = fd.TrackingModel.of(sc.geometry)
    init = initiate(sim.measurements.first_per_pair(10), model)
    every, some = (run_isam2(sim.measurements, model, init, ISAM2Settings(keep_states=k, relinearize_history=40))
                   for k in (0, 60))
    f0, f1 = every.estimates[0], some.estimates[0]
    assert len(f0) == len(f1) > 250
    sd = np.sqrt(np.einsum("kii->ki", f0.covariances))
    assert np.max(np.abs(f1.states - f0.states) / sd) <= 1e-6
    assert np.max(np.abs(f1.covariances - f0.covariances)) <= 1e-6 * np.abs(f0.covariances).max()
    np.testing.assert_array_equal(some.relinearizations, every.relinearizations)
    assert some.relinearizations.sum() > 1000
    s0, s1 = every.estimates[1], some.estimates[1]
    assert np.max(np.abs(s1.states - s0.states) / np.sqrt(np.einsum("kii->ki", s0.covariances))) <= 1e-4

    # iSAM2 then holds at most keep_states + one batch of states, and never fewer than the relinearisation reaches
    for keep, held in ((60, 60), (1, 10 + 40 + 1)):
        tracker = _isam2_feed(model, sim.measurements, init, ISAM2Settings(keep_states=keep, relinearize_history=40))
        n = len(tracker.times)
        assert tracker.isam.getLinearizationPoint().size() == n - tracker._oldest
        assert held <= n - tracker._oldest <= held + 100
        assert tracker._oldest >= 100

    # with no Doppler factor at all the graph is linear and finish() reads every state's covariance from
    # iSAM2: nothing leaves
    empty = ISAM2Tracker(model, ISAM2Settings(warmup_seconds=0.0, warmup_per_pair=0, keep_states=1), model.prior())
    for k in range(300):
        empty.add_scan(0.2 * k, [], [], [], sim.truth.states[0] if k == 0 else None)
    states, covs = empty.finish()
    assert empty._oldest == 0 and states.shape == (300, 4) and covs is not None and np.all(np.isfinite(covs))


def _stale(tracker: ISAM2Tracker, ks: list[int], xs: np.ndarray) -> np.ndarray:
    """Which of states ``ks`` have a factor linearised beyond the thresholds from their value ``xs``."""
    st = tracker.settings
    lin = np.array([tracker.scans[j].lin for j in ks])
    d = np.abs(xs - lin)
    return np.any(d[:, :2] > st.relinearize_position, axis=1) | np.any(d[:, 2:] > st.relinearize_velocity, axis=1)


def test_isam2_history_check_leaves_no_stale_factor() -> None:
    # Every relinearize_every updates the states before the recent window are checked too:
    # right after such an update, every checked state's factor is linearised within the
    # thresholds of the value the state had when it was checked (its marginal mean, the MAP
    # of the linear system before the update).  Case b 25 km is poorly observed: old states
    # keep moving, and without the check (the control) many factors are left far from them.
    _, sim, model, init = _setup("b", 25e3, seed=3)
    m = sim.measurements
    every = 5

    def run(history: int) -> list[int]:
        st = ISAM2Settings(relinearize_history=history, relinearize_every=every)
        stale: list[int] = []

        def check(tracker: ISAM2Tracker, k: int):
            if tracker._n_updates % every:
                return None
            ks = [j for j in range(k) if tracker.scans[j].lin is not None]
            xs = tracker._means(ks)
            return lambda _x, _P: stale.append(int(np.sum(_stale(tracker, ks, xs))))

        _isam2_feed(model, m, init, st, check)
        return stale

    with_check, without = run(10_000), run(0)
    assert len(with_check) == len(without) >= 10
    assert sum(with_check) == 0
    assert sum(without) >= 10 * len(without)


def test_smoother_state_without_measurements_changes_nothing_else() -> None:
    # Constant velocity with white acceleration composes exactly over a step
    # (F(a+b) = F(b)F(a), Q(a+b) = F(b)Q(a)F(b)' + Q(b)), so a state at a time without
    # measurements leaves every other state's solution as it was and itself lies on the
    # smoothed CV interpolation.
    _, sim, model, init = _setup("a", 45e3)
    m = sim.measurements
    times = m.scans().times
    x0 = fd.estimators.smoother.initial_trajectory(m, model, init, SmootherSettings())
    plain = fd.estimators.smoother.solve_smoother(m, model, x0, prior=model.prior())
    extra_t = 0.5 * (times[30] + times[31])
    t_ext = np.insert(times, 31, extra_t)
    x_ext = np.insert(x0, 31, model.motion.propagate(x0[30], extra_t - times[30]), axis=0)
    ext = fd.estimators.smoother.solve_smoother(m, model, x_ext, prior=model.prior(), times=t_ext)
    others = np.delete(ext.states, 31, axis=0)
    assert _rel(others, plain.states) <= 1e-7
    assert plain.covariances is not None and ext.covariances is not None
    np.testing.assert_allclose(np.delete(ext.covariances, 31, axis=0), plain.covariances, rtol=1e-5,
                               atol=1e-8 * np.abs(plain.covariances).max())
    assert abs(ext.cost - plain.cost) <= 1e-8 * plain.cost
    with pytest.raises(ValueError, match="every measurement time"):
        fd.estimators.smoother.solve_smoother(m, model, x0[1:], times=times[1:])


def _paper_a45_with_pair_2_late(seed: int) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation]:
    """Case a 45 km with pair 2 sampling 10 ms after pair 1: every measurement its own scan, 10 ms or 490 ms
    after the one before."""
    sc = dataclasses.replace(fd.paper_scenario("a", 45e3), time_offsets=(0.0, 0.01))
    sim = fd.simulate(sc, np.random.default_rng(seed))
    model = fd.TrackingModel.of(sc.geometry)
    return sim, model, initiate(sim.measurements.first_per_pair(10), model)


def test_isam2_old_states_means_are_the_full_back_substitution_when_pairs_report_10_ms_apart() -> None:
    # Two states 10 ms apart are tied by a motion factor whose noise pins their difference to about
    # 20 micrometres while the track is known to ~100 m: the information matrix spans some 16 orders.
    # The relinearisation check's values (_means) must still be the MAP of the linear system, as
    # iSAM2's full back-substitution gives it.  GTSAM's default elimination of the marginals (Cholesky)
    # squares the condition number: on this run's graphs its means were up to 1.0 standard deviation
    # off where it did not call the marginal indeterminate, and a tracker that relinearised its
    # measurements at them drifted until they were 52 standard deviations off (its track kilometres
    # off the truth: the next test).  By QR the per-state marginals agreed to ~2e-8; the joint marginal
    # of the checked states, read since 2026-12-06, agrees to 3e-12 (this run) and 5e-12 (seed 2).
    sim, model, init = _paper_a45_with_pair_2_late(1)
    worst: list[float] = []

    def check(tracker: ISAM2Tracker, k: int):
        if k % 10:
            return None

        def after(_x: np.ndarray, _P: np.ndarray | None) -> None:
            ks = list(range(k + 1))
            est = tracker.isam.calculateEstimate()
            full = np.array([est.atVector(X(j)) for j in ks])
            sd = np.array([np.sqrt(np.diag(tracker.isam.marginalCovariance(X(j)))) for j in ks])
            worst.append(float(np.max(np.abs(tracker._means(ks) - full) / sd)))
        return after

    _isam2_feed(model, sim.measurements, init, ISAM2Settings(), check)
    assert len(worst) >= 10
    assert max(worst) <= 1e-9


def test_isam2_tracks_pairs_that_report_10_ms_apart_as_well_as_synchronous_ones() -> None:
    # The target moves 1 m in 10 ms: the two recordings carry the same information, and the filtered
    # track must be as accurate (measured 140.2 against 140.8 m; with the Cholesky check values it
    # diverged, 35 km and a NEES of 9e8) and its end consistent.
    sim, model, init = _paper_a45_with_pair_2_late(1)
    sync = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(1))
    rmse = []
    for s, i in ((sim, init), (sync, initiate(sync.measurements.first_per_pair(10), model))):
        e = run_isam2(s.measurements, model, i).primary
        truth = s.truth.at(e.times)
        err2 = np.sum((e.states[:, :2] - truth[:, :2]) ** 2, axis=1)
        rmse.append(float(np.sqrt(np.mean(err2[e.times >= 5.0]))))
        d = e.states[-1] - truth[-1]
        assert float(d @ np.linalg.solve(e.covariances[-1], d)) <= chi2.ppf(0.9999, 4)
    assert rmse[0] <= 1.25 * rmse[1]


def test_isam2_survives_a_marginal_that_cholesky_calls_indeterminate(monkeypatch: pytest.MonkeyPatch) -> None:
    # Case b 5 km with 5 % of the measurements replaced by +-100 m/s, no robust loss: the 13th run of
    # seed 3 drives one of the relinearisation checks into a marginal that GTSAM's Cholesky calls
    # indeterminate (it raised out of the tracker once, when the check eliminated by Cholesky first).
    # The check eliminates by QR, which solves it.
    sc = fd.paper_scenario("b", 5e3)
    rng = np.random.default_rng(np.random.SeedSequence(3).spawn(20)[12])
    sim = fd.simulate(sc, rng)
    m = sim.measurements
    z = m.doppler.copy()
    idx = rng.choice(len(m), round(0.05 * len(m)), replace=False)
    z[idx] += rng.choice([-100.0, 100.0], idx.size)
    m = fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)
    model = fd.TrackingModel.of(sc.geometry)
    init = initiate(m.first_per_pair(10), model)
    failures = []
    original = ISAM2Tracker._means

    def counting(self: ISAM2Tracker, ks: list[int]) -> np.ndarray:
        try:
            [self.isam.marginalFactor(X(k)) for k in ks]
        except RuntimeError:
            failures.append(ks)
        return original(self, ks)

    monkeypatch.setattr(ISAM2Tracker, "_means", counting)
    result = run_isam2(m, model, init)
    assert failures, "the data no longer reach the Cholesky failure: this test needs a new case"
    assert np.all(np.isfinite(result.primary.states))


def _read_through(tracker: ISAM2Tracker, wrapper: type, read: Callable[[ISAM2Tracker, list[int]], np.ndarray],
                  ks: list[int]) -> np.ndarray:
    """``read(tracker, ks)`` with the tracker's iSAM2 wrapped in ``wrapper`` for that call only."""
    tracker.isam, real = wrapper(tracker.isam), tracker.isam
    try:
        return read(tracker, ks)
    finally:
        tracker.isam = real


class _WrappedISAM2:
    """An iSAM2 with some methods replaced by a subclass; everything else is the wrapped one's."""

    def __init__(self, isam: object) -> None:
        self._isam = isam

    def __getattr__(self, name: str) -> object:
        return getattr(self._isam, name)


class _JointRefused(_WrappedISAM2):
    """An iSAM2 whose joint marginal is refused as indeterminate."""

    def jointBayesNet(self, *args: object) -> None:
        raise RuntimeError("indeterminant linear system (refused by the test)")


def test_isam2_check_reads_its_own_estimate_where_the_joint_marginal_is_indeterminate() -> None:
    # Where QR calls the checked states' joint marginal indeterminate, the check reads iSAM2's own
    # estimate of them instead of raising out of the tracker: the same values as the joint marginal's
    # up to iSAM2's wildfire threshold (its estimate stops back-substituting where the solution moved
    # less; GTSAM's default 1e-3 in the state's units).  Measured on this well-observed track: 6e-14.
    _, sim, model, init = _setup("a", 45e3)
    seen: list[float] = []

    def check(tracker: ISAM2Tracker, k: int):
        if k % 5:
            return None

        def after(_x: np.ndarray, _P: np.ndarray | None) -> None:
            ks = list(range(max(0, k - 10), k + 1))
            joint = tracker._means(ks)
            fallback = _read_through(tracker, _JointRefused, ISAM2Tracker._means, ks)
            seen.append(float(np.max(np.abs(fallback - joint))))
        return after

    tracker = _isam2_feed(model, sim.measurements, init, ISAM2Settings(), check)
    assert len(seen) >= 5
    assert max(seen) <= 1e-3
    assert np.all(np.isfinite(tracker.finish(covariances=False)[0]))


@pytest.mark.parametrize("recording", ["b 25 km", "pairs 10 ms apart"])
def test_isam2_history_check_reads_the_full_solution_and_it_is_the_joint_marginals(
        recording: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # The history check (every relinearize_every updates, the states before the recent window too) reads
    # iSAM2's full back-substitution (_solved), which on 130 states costs less than their joint marginal;
    # the recent window alone reads the joint marginal (_means).  Both are the MAP of the same linear
    # system: on a poorly observed track (case b 25 km) and where the information matrix spans some 16
    # orders (pairs 10 ms apart) they must agree to 1e-9 of the states' marginal standard deviations
    # (the joint marginal's own distance from the full back-substitution, measured: 3e-12 / 5e-12).
    if recording == "b 25 km":
        _, sim, model, init = _setup("b", 25e3, seed=3)
    else:
        sim, model, init = _paper_a45_with_pair_2_late(1)
    every = 5
    st = ISAM2Settings(relinearize_every=every)
    calls: list[tuple[int, str, int]] = []
    worst: list[float] = []
    solved, joint = ISAM2Tracker._solved, ISAM2Tracker._means

    def solved_and_compared(self: ISAM2Tracker, ks: list[int]) -> np.ndarray:
        calls.append((self._n_updates, "solved", len(ks)))
        full = solved(self, ks)
        sd = np.array([np.sqrt(np.diag(self.isam.marginalCovariance(X(k)))) for k in ks])
        worst.append(float(np.max(np.abs(joint(self, ks) - full) / sd)))
        return full

    def counted(self: ISAM2Tracker, ks: list[int]) -> np.ndarray:
        calls.append((self._n_updates, "joint", len(ks)))
        return joint(self, ks)

    monkeypatch.setattr(ISAM2Tracker, "_solved", solved_and_compared)
    monkeypatch.setattr(ISAM2Tracker, "_means", counted)
    _isam2_feed(model, sim.measurements, init, st)
    assert len(worst) >= 5
    assert max(worst) <= 1e-9
    # each update's check reads one way: the full solution exactly on the history updates
    assert calls and all((n % every == 0) == (way == "solved") for n, way, _ in calls)
    assert all(size <= st.relinearize_window for _, way, size in calls if way == "joint")
    assert any(size > st.relinearize_window for _, way, size in calls if way == "solved")


class _NaNSolution(_WrappedISAM2):
    """An iSAM2 whose full back-substitution is not finite (a singular factor)."""

    def calculateBestEstimate(self) -> object:
        best = self._isam.calculateBestEstimate()  # type: ignore[attr-defined]
        out = gtsam.Values()
        for key in best.keys():
            out.insert(key, np.full(4, np.nan))
        return out


class _RefusedSolution(_WrappedISAM2):
    """An iSAM2 whose full back-substitution GTSAM refuses as indeterminate."""

    def calculateBestEstimate(self) -> object:
        raise RuntimeError("indeterminant linear system (refused by the test)")


def test_isam2_history_check_reads_the_joint_marginal_where_the_full_solution_is_refused() -> None:
    # GTSAM reports an indeterminate system as a plain RuntimeError: the history check must not crash the
    # tracker but read the joint marginal, as it does where the back-substitution is not finite.
    _, sim, model, init = _setup("b", 25e3, seed=3)
    tracker = _isam2_feed(model, sim.measurements, init, ISAM2Settings(), n_scans=15)
    ks = list(range(len(tracker.times)))
    np.testing.assert_array_equal(_read_through(tracker, _RefusedSolution, ISAM2Tracker._solved, ks),
                                  tracker._means(ks))


def test_isam2_history_check_reads_the_joint_marginal_where_the_full_solution_is_not_finite() -> None:
    # Back-substitution through a singular factor gives infinities or NaN rather than an error: the history
    # check then reads the joint marginal, which eliminates again by QR (and falls back further itself).
    _, sim, model, init = _setup("b", 25e3, seed=3)
    tracker = _isam2_feed(model, sim.measurements, init, ISAM2Settings(), n_scans=15)
    ks = list(range(len(tracker.times)))
    joint = tracker._means(ks)
    fallback = _read_through(tracker, _NaNSolution, ISAM2Tracker._solved, ks)
    np.testing.assert_array_equal(fallback, joint)
    assert np.max(np.abs(tracker._solved(ks) - joint)) <= 1e-6 * np.max(np.abs(joint))
