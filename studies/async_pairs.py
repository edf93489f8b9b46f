r"""Pairs that report milliseconds apart: does every estimator track as well as on synchronous pairs?

Receivers with their own clocks sample at the same rate but not at the same
instants.  Each such measurement is its own scan, so the trackers that keep a
state per scan (iSAM2, the fixed-lag and offline smoothers) get two states a
few milliseconds apart, tied by a constant-velocity factor whose noise
:math:`\mathbf Q(\delta)` (position variance :math:`q\delta^3/3`) pins their
difference to micrometres while the track itself is known to hundreds of
metres or kilometres: an ill-conditioned graph.  The Doppler data carry the
same information as the synchronous recording's (the target moves a metre in
10 ms), so every estimator should track as well as there.

For each paper scenario and run (the accuracy benchmark's recordings,
``SeedSequence([seed, s, r])``) the recording is simulated as the paper's
(case a: both pairs at the same instants; case b: pair 2 0.25 s after pair
1) and with pair 2 :data:`DELAYS` after pair 1 (``Scenario.time_offsets``),
each initiated on its first 10 measurements per pair and tracked by every
estimator (``fd.run_estimators``).  Printed per scenario, delay and
estimator: the position RMSE over t >= 5 s and the NEES over t >= 10 s (the
accuracy benchmark's measures) and how many runs were judged ``ok``.

Run: python studies/async_pairs.py [--runs 10] [--seed 2026] [--estimators isam2 ...] [--out DIR]
(about 6 min on 2 cores at 10 runs, every estimator)
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import _common  # the repository root on the path
import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import T_NEES, T_RMSE, _on_grid, mean_after
from fgdoppler.analysis.metrics import time_averaged_rmse
from fgdoppler.analysis.workers import one_blas_thread

#: Pair 2's sampling instants after pair 1's (s); ``None``: the paper's scenario as it is.
DELAYS: tuple[float | None, ...] = (None, 0.001, 0.01)


@one_blas_thread
def one(task: tuple[int, int, int, float | None, tuple[str, ...]]) -> dict[str, Any]:
    """Run ``r`` of scenario ``s`` with pair 2 ``delay`` after pair 1: each estimator's errors on the truth grid."""
    s, r, seed, delay, names = task
    scen = fd.paper_scenarios()[s]
    if delay is not None:
        scen = dataclasses.replace(scen, time_offsets=(0.0, delay))
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    results = fd.run_estimators(names, sim.measurements, model, init)
    out: dict[str, Any] = {"s": s, "r": r, "delay": delay, "t": sim.truth.times}
    for name, res in results.items():
        e = res.primary
        se, ne = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
        out[name] = {"se": se, "nees": ne, "ok": res.status == "ok"}
    return out


def main() -> None:
    p = argparse.ArgumentParser(prog="python studies/async_pairs.py", description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--estimators", nargs="+", default=list(fd.ESTIMATORS))
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    names = tuple(a.estimators)
    tasks = [(s, r, a.seed, d, names) for s in range(len(fd.paper_scenarios())) for d in DELAYS
             for r in range(a.runs)]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one, tasks, chunksize=2))
    table = []
    lines = [f"Pair 2 sampled after pair 1 ({a.runs} runs per cell, seed {a.seed}): position RMSE over "
             f"t >= {T_RMSE:g} s (m) / NEES over t >= {T_NEES:g} s / runs judged ok", "",
             "| scenario | pair 2 after pair 1 | " + " | ".join(names) + " |",
             "|---|---|" + "---|" * len(names)]
    for s, scen in enumerate(fd.paper_scenarios()):
        for d in DELAYS:
            cell = [x for x in rows if x["s"] == s and x["delay"] == d]
            t = np.asarray(cell[0]["t"])
            row: dict[str, Any] = {"scenario": scen.name, "delay": d}
            cells = []
            for name in names:
                se = np.array([x[name]["se"] for x in cell])
                ne = np.array([x[name]["nees"] for x in cell])
                rmse = time_averaged_rmse(se, t, t0=T_RMSE)
                with warnings.catch_warnings():  # all-NaN columns are expected: no state before the window ends
                    warnings.simplefilter("ignore", RuntimeWarning)
                    nees = mean_after(np.nanmean(ne, axis=0), t, T_NEES)
                ok = sum(x[name]["ok"] for x in cell)
                row[name] = {"rmse": rmse, "nees": nees, "ok": ok}
                cells.append(f"{rmse:,.0f} / {nees:.3g} / {ok}")
            label = "as in the paper" if d is None else f"{1e3 * d:g} ms"
            lines.append(f"| {scen.name} | {label} | " + " | ".join(cells) + " |")
            table.append(row)
    _common.save_table(a.out, "async_pairs", "\n".join(lines) + "\n", table)


if __name__ == "__main__":
    main()
