"""Per-scan cost of iSAM2, the fixed-lag smoother and offline reconstruction at 60, 600 and 7,200 scans.

The trackers' latency is the median over the last quarter of each run's
scans (at least the 30th on), pooled over three repeats: the cost at the
end of a track of that length.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row, long_scenario
from fgdoppler.estimators.fixed_lag import FixedLagTracker
from fgdoppler.estimators.initiation import initiate
from fgdoppler.estimators.isam2 import ISAM2Tracker
from fgdoppler.estimators.smoother import initial_trajectory, solve_smoother

SIZES = (60, 600, 7200)
REPEATS = 3


def _stream(tracker: ISAM2Tracker | FixedLagTracker, sim: fd.Simulation, n_window: int) -> tuple[np.ndarray, float, float, float]:
    """Per-scan latencies, the share of gated measurements accepted, and the end error and its sd (m).

    A tracker that lost the track rejects nearly everything and costs almost
    nothing per scan: its latency says nothing, so the row reports the
    acceptance and the end position error beside it.
    """
    m = sim.measurements
    sc = m.scans()
    lat = []
    x0 = sim.truth.states[0]
    x, P = x0, None
    for k in range(len(sc)):
        sl = sc.rows(k)
        t = time.perf_counter()
        x, P = tracker.add_scan(sc.times[k], m.pair[sl], m.doppler[sl], m.sigma[sl], x0 if k == 0 else None,
                                gate=k >= n_window)
        lat.append(time.perf_counter() - t)
    nis = tracker.gate.as_array()
    accepted = float(np.mean(nis[:, 3])) if nis.size else 1.0
    error = float(np.hypot(*(np.asarray(x) - sim.truth.states[-1])[:2]))
    sd = float(np.sqrt(P[0, 0] + P[1, 1])) if P is not None else float("nan")
    return np.array(lat), accepted, error, sd


def _native_isam2(n: int) -> float:
    """Median per-update time of GTSAM's own iSAM2 on the same chain with native factors only (the floor), over
    the last quarter of the updates."""
    import gtsam

    from fgdoppler.factors import X, motion_factor

    motion = fd.TrackingModel.of(fd.paper_geometry('a')).motion
    p = gtsam.ISAM2Params()
    p.setFactorization("QR")
    isam = gtsam.ISAM2(p)
    lat = []
    noise = gtsam.noiseModel.Isotropic.Sigma(4, 1.0)
    for k in range(n):
        g = gtsam.NonlinearFactorGraph()
        v = gtsam.Values()
        v.insert(X(k), np.zeros(4))
        g.add(gtsam.PriorFactorVector(X(k), np.zeros(4), noise))
        if k:
            g.add(motion_factor(X(k - 1), X(k), 0.05, motion))
        t = time.perf_counter()
        isam.update(g, v)
        isam.calculateEstimate([X(k)])
        isam.marginalCovariance(X(k))
        lat.append(time.perf_counter() - t)
    return float(np.median(lat[max(min(20, n // 2), n - n // 4):]))


def _gtsam_lm_per_iteration(sim: fd.Simulation, model: fd.TrackingModel) -> float:
    """Seconds per scan and iteration of GTSAM's LM over the chain of ``CustomFactor`` s (the window re-solve's
    solver before it took the smoother's): every callback copies the whole ``Values`` into Python."""
    import gtsam

    from fgdoppler.estimators.initiation import lm_params
    from fgdoppler.graphs import chain_graph, chain_values

    m = sim.measurements
    graph, _ = chain_graph(m, model.observation, model.motion, prior=model.prior())
    guesses = model.motion.propagate(sim.truth.states[0], m.scans().times - m.scans().times[0])
    opt = gtsam.LevenbergMarquardtOptimizer(graph, chain_values(guesses), lm_params(3))
    t = time.perf_counter()
    opt.optimize()
    return (time.perf_counter() - t) / len(guesses) / max(opt.iterations(), 1)


def run() -> list[Row]:
    rows = []
    # lag 1 s = 20 states at dt = 0.05 s, so even the 60-scan run reaches steady state.  Streamed
    # from the true state, one update per scan from the first (no warm-up): the 60-scan run is
    # shorter than iSAM2's default 4.5-s warm-up, and a 1-s one started it at the 1-s window's
    # optimum, 9 km off, from which it lost the track (measured: 8.8 km off at 600 scans, sd 11 m).
    # The trackers get a prior about the true first state (a track handed over with 500 m and 20 m/s):
    # with the model's weak prior one scan at a time collapses the start (iSAM2 2.9 km off at 60 scans,
    # 71 % accepted, on 2026-12-06), and a latency of a tracker that lost the track says nothing
    isam2_settings = fd.ISAM2Settings(warmup_seconds=0.0, warmup_per_pair=0)
    lag_settings = fd.FixedLagSettings(lag=1.0)
    results: dict[str, dict[int, float]] = {"isam2": {}, "fixed-lag": {}, "smoother": {}}
    detail: dict[str, dict[int, str]] = {"isam2": {}, "fixed-lag": {}, "smoother": {}}
    tracking: dict[str, float] = {}  # the lowest share of measurements accepted over the sizes
    for n in SIZES:
        sim = fd.simulate(long_scenario(n), np.random.default_rng(0))
        model = fd.TrackingModel.of(sim.scenario.geometry)
        handed_over = (sim.truth.states[0], np.diag([500.0**2, 500.0**2, 20.0**2, 20.0**2]))
        prior = model.prior()
        trackers: tuple[tuple[str, Callable[[], ISAM2Tracker | FixedLagTracker]], ...] = (
            ("isam2", partial(ISAM2Tracker, model, isam2_settings, handed_over)),
            ("fixed-lag", partial(FixedLagTracker, model, lag_settings, handed_over)))
        for name, make in trackers:
            # sub-millisecond medians are noisy on a shared machine: pool three repeats.  The last quarter of
            # the scans: a cost that grows with the track shows there (a whole-run median hid a 3x growth)
            runs = [_stream(make(), sim, 20) for _ in range(REPEATS)]
            steady = np.concatenate([r[0][max(30, n - n // 4):] for r in runs])
            results[name][n] = float(np.median(steady))
            _, accepted, error, sd = runs[-1]
            tracking[name] = min(tracking.get(name, 1.0), accepted)
            detail[name][n] = (f"median {np.median(steady) * 1e3:.2f} ms, p99 {np.percentile(steady, 99) * 1e3:.2f} ms, "
                               f"mean {np.mean(steady) * 1e3:.2f} ms (accepted {accepted:.1%}, "
                               f"end error {error:.0f} m, sd {sd:.0f} m)")
        init = initiate(sim.measurements.first_per_pair(min(100, n // 2)), model)
        smoother = fd.SmootherSettings()
        x_init = initial_trajectory(sim.measurements, model, init, smoother)
        t = time.perf_counter()
        sol = solve_smoother(sim.measurements, model, x_init, smoother, prior=prior)
        dt = time.perf_counter() - t
        per_it = dt / n / max(sol.iterations, 1)
        results["smoother"][n] = per_it
        detail["smoother"][n] = (f"{dt / n * 1e3:.2f} ms/scan total ({sol.iterations} LM iterations), "
                                 f"{per_it * 1e6:.1f} us/scan/iteration")
    # not at 7,200 scans: quadratic, it would take minutes there
    gtsam_lm = {n: _gtsam_lm_per_iteration(fd.simulate(long_scenario(n), np.random.default_rng(0)),
                                           fd.TrackingModel.of(fd.paper_geometry("a"))) for n in SIZES[:2]}
    rows.append(Row(name="reference: GTSAM LM over the chain's CustomFactors, cost per scan and iteration",
                    value="; ".join(f"{n}: {gtsam_lm[n] * 1e6:.1f} us/scan/iteration" for n in gtsam_lm),
                    ratio=gtsam_lm[SIZES[1]] / gtsam_lm[SIZES[0]],
                    target="(why the smoother and the trackers' window re-solve use their own LM; 600 vs 60 scans)",
                    met=None))
    native = {n: _native_isam2(n) for n in SIZES}
    ratio = native[SIZES[-1]] / native[SIZES[0]]
    rows.append(Row(name="reference: GTSAM iSAM2 alone, native factors only, same chain",
                    value="; ".join(f"{n}: median {native[n] * 1e3:.2f} ms" for n in SIZES), ratio=ratio,
                    target="(floor for iSAM2)", met=None))
    for name, label in (("isam2", "iSAM2 per-scan latency"), ("fixed-lag", "fixed-lag (1 s) per-scan latency"),
                        ("smoother", "offline smoother cost per scan and LM iteration")):
        ratio = results[name][SIZES[-1]] / results[name][SIZES[0]]
        value = "; ".join(f"{n}: {detail[name][n]}" for n in SIZES)
        # a tracker that lost the track (rejecting nearly all measurements) is fast for nothing
        target = "7200 vs 60 scans <= 1.5x" + (", >= 90 % of measurements accepted" if name in tracking else "")
        holds = tracking.get(name, 1.0) >= 0.9
        rows.append(Row(name=label, value=value, ratio=ratio, target=target, met=ratio <= 1.5 and holds))
    return rows
