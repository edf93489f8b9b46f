"""Faster scan rates, one recording: what the initiation window's span does to every estimator (docs/concepts.md,
"High scan rates").

The scaling benchmark's track (paper geometry (a), from 45 km, 4.5 km at
-100, -20 m/s; seed 0; 60 s) recorded at several scan rates and tracked by
the EKF, iSAM2, the fixed-lag smoother and the offline smoother through the
registry (``fd.run_estimators``, no reference run), each initiated on

* the first 10 measurements per pair (``first_per_pair(10)``, what Monte Carlo
  and the benchmarks use at the paper's 2 scans/s: 0.45 s of data at 20 scans/s),
* the first 10 per pair and every measurement of the first 4.5 s
  (``initiation_window(10, 4.5)``, what ``fgdoppler track`` and ``fd.track`` use).

Printed per rate, window and estimator: the position RMSE over t >= 5 s, the
NEES averaged over t >= 10 s (the accuracy benchmark's measures), the verdict
and the CPU seconds.  At the fastest rate only the EKF runs (the graph
trackers keep a state per scan).

Run: python studies/high_rate.py [--out DIR]   (about 10 minutes)
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path
from typing import Any

import _common  # the repository root on the path
import numpy as np
from threadpoolctl import threadpool_limits

import fgdoppler as fd
from benchmarks.bench_accuracy import T_NEES, T_RMSE, _on_grid, mean_after
from fgdoppler.analysis.metrics import time_averaged_rmse

#: Scan rates (scans/s) and the estimators run at each.
RATES: tuple[tuple[float, tuple[str, ...]], ...] = (
    (20.0, ("ekf", "isam2", "fixed-lag", "smoother")),
    (50.0, ("ekf", "isam2", "fixed-lag", "smoother")),
    (100.0, ("ekf",)),
)
WINDOWS = {"first 10 per pair": lambda m: m.first_per_pair(10),
           "first 10 per pair and 4.5 s": lambda m: m.initiation_window(10, 4.5)}


def one(rate: float, names: tuple[str, ...], window: str) -> list[dict[str, Any]]:
    """Every estimator of ``names`` on the recording at ``rate`` scans/s, initiated on ``window``."""
    dt = 1.0 / rate
    sc = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=60.0 - dt, dt=dt)
    sim = fd.simulate(sc, np.random.default_rng(0))
    model = fd.TrackingModel.of(sc.geometry)
    init = fd.initiate(WINDOWS[window](sim.measurements), model)
    rows = []
    for name in names:
        t0 = time.process_time()
        res = fd.run_estimator(name, sim.measurements, model, init, verify=False)
        cpu = time.process_time() - t0
        e = res.primary
        se, ne = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
        t = sim.truth.times
        with warnings.catch_warnings():  # NaN before the window ends is expected
            warnings.simplefilter("ignore", RuntimeWarning)
            nees = mean_after(ne, t, T_NEES)
        rows.append({"rate": rate, "window": window, "estimator": name, "window_s": float(np.ptp(
            WINDOWS[window](sim.measurements).time)), "rmse": float(time_averaged_rmse(se[None], t, t0=T_RMSE)),
            "nees": nees, "status": res.status, "cpu_s": cpu})
        print(f"{rate:g}/s, {window}: {name} {rows[-1]['rmse']:,.0f} m, NEES {nees:.3g}, {res.status}, "
              f"{cpu:.1f} s", flush=True)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(prog="python studies/high_rate.py", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    rows: list[dict[str, Any]] = []
    with threadpool_limits(1):
        for rate, names in RATES:
            for window in WINDOWS:
                rows += one(rate, names, window)
    lines = [f"One 60 s recording (paper geometry a, from 45 km; seed 0): position RMSE over t >= {T_RMSE:g} s (m) "
             f"/ NEES over t >= {T_NEES:g} s / verdict / CPU s", "",
             "| scans/s | initiation window | " + " | ".join(RATES[0][1]) + " |",
             "|---|---|" + "---|" * len(RATES[0][1])]
    for rate, _names in RATES:
        for window in WINDOWS:
            cells = []
            for name in RATES[0][1]:
                r = [x for x in rows if x["rate"] == rate and x["window"] == window and x["estimator"] == name]
                cells.append(f"{r[0]['rmse']:,.0f} / {r[0]['nees']:.3g} / {r[0]['status']} / {r[0]['cpu_s']:.1f}"
                             if r else "—")
            span = next(x["window_s"] for x in rows if x["rate"] == rate and x["window"] == window)
            lines.append(f"| {rate:g} | {window} ({span:.2f} s) | " + " | ".join(cells) + " |")
    _common.save_table(a.out, "high_rate", "\n".join(lines) + "\n", rows)


if __name__ == "__main__":
    main()
