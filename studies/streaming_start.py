"""A tracker fed scan by scan from its first scan: with and without the warm-up (docs/concepts.md, "High scan rates").

The scaling benchmark's track (paper geometry (a), from 45 km, 4.5 km at
-100, -20 m/s), seeded recordings at several scan rates, streamed into an
``ISAM2Tracker`` (and the fixed-lag smoother, lag 5 s) with the model's weak
prior, the gate from the 20th scan: from the first scan with the true state
as the guess (warm-up off), with the warm-up from the true state, with
the warm-up and no guess, and as a Gaussian sum
(:class:`~fgdoppler.estimators.gaussian_sum.GaussianSumTracker`: the
registry's hypotheses from the first 4.5 s, no guess, no prior).  Per variant: median end position error, the
smallest share of measurements a run accepted, and how many runs have a
filtered NEES averaged over t >= 10 s below 20.  Then the paper's six
scenarios at 2 scans/s (``PAPER_RUNS`` runs each), streamed with no guess
into one warmed-up iSAM2 and into the Gaussian sum; and the scaling track
for an hour into the Gaussian sum, to time each update.

Run: python studies/streaming_start.py [--out DIR]   (about 10 minutes)
"""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
from _common import out_dir
from scipy.stats import chi2
from threadpoolctl import threadpool_limits

import fgdoppler as fd
from fgdoppler.estimators.fixed_lag import FixedLagTracker
from fgdoppler.estimators.gaussian_sum import GaussianSumTracker
from fgdoppler.estimators.isam2 import ISAM2Tracker

#: A run is inconsistent when its NEES averaged over t >= 10 s exceeds the chi-square(4) 99.9 % quantile.
RUN_LIMIT = float(chi2.ppf(0.999, 4))
COLD = {"warmup_seconds": 0.0, "warmup_per_pair": 0}
WARM = {"warmup_seconds": 4.5, "warmup_per_pair": 10}
CASES = (("isam2", 0.5, 60.0, 10), ("isam2", 0.05, 30.0, 10), ("isam2", 0.02, 30.0, 10),
         ("fixed-lag", 0.5, 60.0, 10), ("fixed-lag", 0.05, 30.0, 6))
VARIANTS = {"from the first scan": (COLD, True, False), "warm-up, true guess": (WARM, True, False),
            "warm-up, no guess": (WARM, False, False), "Gaussian sum, no guess": (WARM, False, True)}


def one_run(name: str, dt: float, duration: float, seed: int, warmup: dict[str, Any], guess: bool,
            gaussian_sum: bool = False) -> tuple[float, float, float]:
    """End position error (m), share of gated measurements accepted, filtered NEES averaged over t >= 10 s.

    With ``gaussian_sum``, a :class:`~fgdoppler.estimators.gaussian_sum.GaussianSumTracker` of ``name``
    (its own 4.5 s warm-up, no guess, no prior); the share accepted is its heaviest hypothesis's.
    """
    sc = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=duration - dt, dt=dt)
    sim = fd.simulate(sc, np.random.default_rng(seed))
    model = fd.TrackingModel.of(sc.geometry)
    tracker: ISAM2Tracker | FixedLagTracker | GaussianSumTracker
    if gaussian_sum:
        tracker = GaussianSumTracker(model, "isam2" if name == "isam2" else "fixed-lag",
                                     fd.ISAM2Settings() if name == "isam2" else fd.FixedLagSettings(lag=5.0))
    elif name == "isam2":
        tracker = ISAM2Tracker(model, fd.ISAM2Settings(**warmup), model.prior())
    else:
        tracker = FixedLagTracker(model, fd.FixedLagSettings(lag=5.0, **warmup), model.prior())
    m, s = sim.measurements, sim.measurements.scans()
    x0 = sim.truth.states[0]
    nees = []
    x: np.ndarray = x0
    for k in range(len(s)):
        r = s.rows(k)
        g = x0 if (k == 0 and guess) else None
        if isinstance(tracker, GaussianSumTracker):
            x, P = tracker.add_scan(s.times[k], m.pair[r], m.doppler[r], m.sigma[r])
        else:
            x, P = tracker.add_scan(s.times[k], m.pair[r], m.doppler[r], m.sigma[r], g, gate=k >= 20)
        if P is not None and s.times[k] >= 10.0:
            d = x - sim.truth.states[k]
            nees.append(float(d @ np.linalg.solve(P, d)))
    nis = tracker.nis if isinstance(tracker, GaussianSumTracker) else tracker.gate.as_array()
    accepted = float(nis[:, 3].mean()) if nis.size else 1.0
    return float(np.hypot(*(x - sim.truth.states[-1])[:2])), accepted, float(np.mean(nees)) if nees else np.nan


#: The paper's six scenarios streamed at their 2 scans/s: runs per scenario and the seed (the accuracy benchmark's
#: recordings, ``SeedSequence([seed, scenario, run])``).
PAPER_RUNS, PAPER_SEED = 30, 2026


def paper_run(s: int, r: int, gaussian_sum: bool) -> tuple[float, float, float, float]:
    """Run ``r`` of paper scenario ``s`` streamed with no guess into a warmed-up ``ISAM2Tracker`` (weak prior)
    or a ``GaussianSumTracker``: mean squared position error and mean NEES over t >= 10 s, seconds, and the
    median seconds of one scan's update after the warm-up (the scan that ends it excluded)."""
    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([PAPER_SEED, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    tracker = GaussianSumTracker(model, "isam2") if gaussian_sum else ISAM2Tracker(model, fd.ISAM2Settings(),
                                                                                   model.prior())
    m, sc = sim.measurements, sim.measurements.scans()
    se, ne, per_scan = [], [], []
    t0 = time.perf_counter()
    for k in range(len(sc)):
        rows = sc.rows(k)
        was_warming = tracker.warming_up
        t_scan = time.perf_counter()
        x, P = tracker.add_scan(sc.times[k], m.pair[rows], m.doppler[rows], m.sigma[rows])
        if not was_warming:
            per_scan.append(time.perf_counter() - t_scan)
        if sc.times[k] >= 10.0 and P is not None:
            d = x - sim.truth.at(sc.times[k:k + 1])[0]
            se.append(float(d[0] ** 2 + d[1] ** 2))
            ne.append(float(d @ np.linalg.solve(P, d)))
    return float(np.mean(se)), float(np.mean(ne)), time.perf_counter() - t0, float(np.median(per_scan))


def paper_table() -> list[dict[str, object]]:
    """One warmed-up Gaussian against the Gaussian sum on the paper's scenarios (printed as a Markdown table)."""
    rows: list[dict[str, Any]] = []
    print(f"\n{PAPER_RUNS} runs per scenario, seed {PAPER_SEED}, iSAM2 fed scan by scan with no guess; position RMSE and "
          f"NEES averaged over runs and t >= 10 s; runs whose own NEES average exceeds {RUN_LIMIT:.1f}; seconds per run; "
          "median time of one scan's update after the warm-up\n")
    print("| scenario | one Gaussian (warm-up) | Gaussian sum |\n|---|---|---|")
    for s, scen in enumerate(fd.paper_scenarios()):
        cells = []
        for gaussian_sum in (False, True):
            res = np.array([paper_run(s, r, gaussian_sum) for r in range(PAPER_RUNS)])
            row = {"scenario": scen.name, "gaussian_sum": gaussian_sum, "rmse_m": float(np.sqrt(res[:, 0].mean())),
                   "nees": float(res[:, 1].mean()), "inconsistent_runs": int(np.sum(res[:, 1] > RUN_LIMIT)),
                   "seconds": float(res[:, 2].mean()), "ms_per_scan": float(1e3 * np.median(res[:, 3]))}
            rows.append(row)
            cells.append(f"{row['rmse_m']:,.0f} m, NEES {row['nees']:.3g}, {row['inconsistent_runs']} runs, "
                         f"{row['seconds']:.2f} s, {row['ms_per_scan']:.2f} ms/scan")
        print(f"| {scen.name} | " + " | ".join(cells) + " |", flush=True)
    return rows


def long_feed(duration: float = 3600.0) -> dict[str, object]:
    """The scaling track for ``duration`` s at 2 scans/s into a ``GaussianSumTracker``: the latency of each update.

    Printed: median and slowest updates (the warm-up's end and the restart checkpoints' refits of all the data
    so far are the slow ones) and the end position error.
    """
    dt = 0.5
    sc = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=duration - dt, dt=dt)
    sim = fd.simulate(sc, np.random.default_rng(0))
    tracker = GaussianSumTracker(fd.TrackingModel.of(sc.geometry), "isam2")
    m, scans = sim.measurements, sim.measurements.scans()
    latency = np.zeros(len(scans))
    x = np.full(4, np.nan)
    for k in range(len(scans)):
        rows = scans.rows(k)
        t0 = time.perf_counter()
        x, _ = tracker.add_scan(scans.times[k], m.pair[rows], m.doppler[rows], m.sigma[rows])
        latency[k] = time.perf_counter() - t0
    slow = np.argsort(latency)[::-1][:5]
    out: dict[str, Any] = {"scans": len(scans), "hypotheses": len(tracker.weights), "median_ms": float(1e3 * np.median(latency)),
           "slowest": [(float(scans.times[i]), float(1e3 * latency[i])) for i in slow],
           "end_error_m": float(np.hypot(*(x - sim.truth.states[-1])[:2]))}
    print(f"\n{duration:g} s at 2 scans/s into a GaussianSumTracker (isam2): {out['scans']} scans, "
          f"{out['hypotheses']} hypotheses, median update {out['median_ms']:.2f} ms, slowest (t, ms) "
          + ", ".join(f"({t:g} s, {ms:.0f})" for t, ms in out["slowest"])
          + f"; end error {out['end_error_m']:.0f} m", flush=True)
    return out


def main() -> None:
    out = out_dir("studies")
    rows = []
    with threadpool_limits(1):
        for name, dt, duration, runs in CASES:
            for label, (warmup, guess, gaussian_sum) in VARIANTS.items():
                if name == "fixed-lag" and label == "warm-up, no guess":
                    continue
                res = np.array([one_run(name, dt, duration, seed, warmup, guess, gaussian_sum)
                                for seed in range(runs)])
                row = {"tracker": name, "scans_per_s": round(1 / dt), "seconds": duration, "variant": label,
                       "runs": runs, "median_end_error_m": float(np.nanmedian(res[:, 0])),
                       "min_accepted": float(np.nanmin(res[:, 1])), "nees_below_20": int(np.sum(res[:, 2] < 20))}
                rows.append(row)
                print(f"| {name} | {row['scans_per_s']}/s, {duration:g} s | {label} | "
                      f"{row['median_end_error_m']:,.0f} m | {row['min_accepted']:.1%} | "
                      f"{row['nees_below_20']}/{runs} |", flush=True)
        paper = paper_table()
        long = long_feed()
    out.mkdir(parents=True, exist_ok=True)
    (out / "streaming_start.json").write_text(json.dumps({"scaling_track": rows, "paper": paper, "long_feed": long},
                                                         indent=1))


if __name__ == "__main__":
    main()
