"""Warm-up of the streaming trackers fed scan by scan from their first scan (fgdoppler.estimators.warmup)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.estimators.fixed_lag import FixedLagTracker, run_fixed_lag
from fgdoppler.estimators.initiation import initiate
from fgdoppler.estimators.isam2 import ISAM2Tracker, run_isam2
from fgdoppler.estimators.settings import FixedLagSettings, ISAM2Settings

COLD = {"warmup_seconds": 0.0, "warmup_per_pair": 0}
WARM = {"warmup_seconds": 4.5, "warmup_per_pair": 10}  # iSAM2's default; the fixed-lag smoother's is off


def _paper(seed: int = 1):
    sc = fd.paper_scenario("a", 45e3)
    sim = fd.simulate(sc, np.random.default_rng(seed))
    return sim, fd.TrackingModel.of(sc.geometry)


def _stream(tracker, m: fd.Measurements, guess: np.ndarray | None = None, until: float = np.inf):
    """Every scan of ``m`` up to ``until``, one update each; the returned ``(time, x, P, warming_up)``."""
    sc = m.scans()
    out = []
    for k in range(len(sc)):
        if sc.times[k] > until:
            break
        r = sc.rows(k)
        g = guess if k == 0 else None
        x, P = tracker.add_scan(sc.times[k], m.pair[r], m.doppler[r], m.sigma[r], g)
        out.append((float(sc.times[k]), x, P, tracker.warming_up))
    return out


@pytest.mark.parametrize("name", ["isam2", "fixed-lag"])
def test_a_tracker_fed_no_guess_starts_as_the_registry_runner_does(name: str) -> None:
    # Fed scan by scan with no guess, the tracker holds the first 4.5 s (20 measurements at
    # 2 scans/s), initiates them by multi-start and adds them as one window from the window
    # graph's optimum: exactly what run_isam2 / run_fixed_lag do after fd.initiate on
    # first_per_pair(10), the same window at this rate.  So every later estimate is theirs.
    sim, model = _paper()
    m = sim.measurements
    init = initiate(m.first_per_pair(10), model)
    if name == "isam2":
        ref = run_isam2(m, model, init).estimate("filtered")
        tracker: ISAM2Tracker | FixedLagTracker = ISAM2Tracker(model, ISAM2Settings(), model.prior())
    else:
        ref = run_fixed_lag(m, model, init).estimate("filtered")
        tracker = FixedLagTracker(model, FixedLagSettings(**WARM), model.prior())
    out = _stream(tracker, m)
    held = [o for o in out if o[0] < init.t_end]
    assert held and all(np.all(np.isnan(x)) and P is None and w for _, x, P, w in held)
    live = [o for o in out if o[0] >= init.t_end]
    assert not any(w for *_, w in live)
    times = np.array([o[0] for o in live])
    np.testing.assert_array_equal(times, ref.times)
    np.testing.assert_allclose(np.array([o[1] for o in live]), ref.states, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(np.array([o[2] for o in live]), np.array(ref.covariances), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 6])
def test_a_guess_and_the_initiation_reach_the_same_window_optimum_at_50_hz(seed: int) -> None:
    # 50 scans/s from the model's broad prior.  With the warm-up the first 4.5 s are solved
    # together; from the true state (LM) and from nothing (multi-start initiation, then LM) the
    # tracker reaches the same optimum of the window graph, two independent starts (measured
    # 1.4e-5 and 3.9e-4 standard deviations apart on these two recordings).
    #
    # The control: streamed one scan per update from the true state with the warm-up off,
    # iSAM2's first Gauss-Newton steps throw the unobserved directions to the prior's mean, and
    # on recording 6 the tracker ends 14.6 km off at a stated 485 m (NEES 6e6) where the
    # warm-up's estimate is 712 m off and within the chi-square 99.99 % quantile (NEES 1.5).
    # Over recordings 0-29 (2026-12-06) the cold stream ends more than 5 km off in 3 and beyond
    # the quantile in 27, the warm-up in none and 19 (at 4.5 s the window's Gaussian is itself
    # often over-confident at this rate; the registry's sampled checks are not run here); RMS
    # error 3,827 m against 1,668 m.  Until 2026-12-06 the control read recording 0, where the
    # cold outcome is chaotic: kilometres off at a stated sd of metres while the check read
    # Cholesky marginals, 1.5 km off at NEES 59.7 with per-state QR marginals (2026-12-05), and
    # 407 m off at NEES 9.7 with the joint marginal of the checked states.  Recording 6's
    # divergence is the same with both QR check values (14.5 and 14.6 km, NEES 6.1e6 and 6.0e6).
    sc = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=4.6, dt=0.02)
    sim = fd.simulate(sc, np.random.default_rng(seed))
    model = fd.TrackingModel.of(sc.geometry)
    m, x0 = sim.measurements, sim.truth.states[0]
    ends = []
    for settings, guess in ((ISAM2Settings(), x0), (ISAM2Settings(), None), (ISAM2Settings(**COLD), x0)):
        out = _stream(ISAM2Tracker(model, settings, model.prior()), m, guess, until=4.5 + 1e-9)
        t, x, P, warming = out[-1]
        assert not warming and P is not None
        k = int(np.argmin(np.abs(sim.truth.times - t)))
        d = x - sim.truth.states[k]
        ends.append((x, P, float(d @ np.linalg.solve(P, d)), float(np.hypot(d[0], d[1]))))
    (xg, Pg, nees_warm, _), (xn, _, _, _), (_, _, nees_cold, miss_cold) = ends
    sd = np.sqrt(np.diag(Pg))
    assert np.all(np.abs(xg - xn) <= 1e-3 * sd)
    if seed == 6:  # the control: the scenario does exercise the failure the warm-up removes
        assert nees_warm <= chi2.ppf(0.9999, 4) and nees_cold > 1e4 and miss_cold > 5e3


def test_warm_up_edges() -> None:
    sim, model = _paper()
    m = sim.measurements
    short = m.subset(m.time <= 3.0)  # shorter than the warm-up
    for tracker in (ISAM2Tracker(model, ISAM2Settings(), model.prior()),
                    FixedLagTracker(model, FixedLagSettings(**WARM), model.prior())):
        out = _stream(tracker, short)
        assert all(w for *_, w in out)
        # out of order, a pair the model does not have, a window after held scans: refused
        with pytest.raises(ValueError, match="out of order"):
            _stream(tracker, m.subset(m.time == 1.0))
        with pytest.raises(ValueError, match="outside a model"):
            _stream(tracker, fd.Measurements.from_arrays([3.5], [5], [1.0], 1.0))
        held = len(tracker._warmup.times)
        for z, sigma, what in ((np.nan, 1.0, "not finite"), (1.0, 0.0, "sigma")):
            with pytest.raises(fd.MeasurementError, match=what):
                tracker.add_scan(3.6, [0], [z], [sigma])
        assert len(tracker._warmup.times) == held  # a refused scan is not held
        with pytest.raises(ValueError, match="held in the warm-up"):
            tracker.add_window([4.0], [[0]], [[0.0]], [[1.0]], sim.truth.states[:1])
        tracker.finish()  # a track shorter than the warm-up: finish starts from the held scans
        assert not tracker.warming_up
        assert len(tracker.times) == len(short.scans())
    # the warm-up off: one update per scan from the first, which needs a guess (both trackers alike)
    for cold in (ISAM2Tracker(model, ISAM2Settings(**COLD), model.prior()),
                 FixedLagTracker(model, FixedLagSettings(), model.prior())):
        assert not cold.warming_up
        r = m.scans().rows(0)
        with pytest.raises(ValueError, match="initial guess"):
            cold.add_scan(0.0, m.pair[r], m.doppler[r], m.sigma[r])
        x, _ = cold.add_scan(0.0, m.pair[r], m.doppler[r], m.sigma[r], sim.truth.states[0])
        assert np.all(np.isfinite(x))
    # a window first: no warm-up at all
    tr = ISAM2Tracker(model, ISAM2Settings(), model.prior())
    first = m.scans()
    r = first.rows(0)
    x, _ = tr.add_window([first.times[0]], [m.pair[r]], [m.doppler[r]], [m.sigma[r]], sim.truth.states[:1])
    assert not tr.warming_up and np.all(np.isfinite(x))


@pytest.mark.parametrize("bad", [{"warmup_seconds": -1.0}, {"warmup_seconds": float("nan")},
                                 {"warmup_seconds": True}, {"warmup_per_pair": -1}, {"warmup_per_pair": 2.5}])
def test_warm_up_settings_reject_bad_values(bad: dict) -> None:
    name = next(iter(bad))
    for cls in (ISAM2Settings, FixedLagSettings):
        with pytest.raises(ValueError, match=name):
            cls(**bad)
    assert not ISAM2Settings(**COLD).warms_up and ISAM2Settings(warmup_seconds=0.0).warms_up
    assert ISAM2Settings().warms_up and not FixedLagSettings().warms_up
