r"""Pairs a few milliseconds apart against synchronous ones, run by run, with a shift that changes nothing.

``studies/async_pairs.py`` compares whole cells of 10 runs.  Here each
recording of the 25 km scenarios (the accuracy benchmark's draws,
``SeedSequence([seed, s, r])``) is simulated three ways with the same noise:
both pairs at the same instants (``Scenario.time_offsets`` ``(0, 0)``, case b
too, so that the windows are alike), pair 2 :data:`DELAYS` after pair 1.  A
microsecond changes nothing a Doppler tracker can see (the target moves
0.1 mm, its Doppler by about 10⁻⁷ m/s); it still makes every measurement a
scan of its own, as a millisecond does.  So the microsecond's paired
difference is what any change of the data does to an estimator's answer, and
a loss to pairs a millisecond apart is one beyond it.

Every recording is initiated on its first 10 measurements per pair and run by
each estimator (``fd.run_estimator``, no verdict: it does not change the
track).  Errors are read at pair 1's instants, the synchronous recording's
truth grid.  Printed per scenario and estimator: the time-averaged position
RMSE over t >= 5 s of each timing, the paired difference of each later timing
against the synchronous one with its 95 % bootstrap interval, and the NEES.

Run: python studies/async_pairs_paired.py [--runs 600] [--seed 2026] [--estimators ekf fixed-lag]
(40 min on 2 cores at 600 runs with the EKF and the fixed-lag smoother, 2026-12-07)
"""

from __future__ import annotations

import argparse
import dataclasses
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import _common  # the repository root on the path
import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import _on_grid
from fgdoppler.analysis.workers import one_blas_thread

#: Pair 2's sampling instants after pair 1's (s), each against both at the same instants.
DELAYS: tuple[float, ...] = (1e-6, 1e-3)
#: The paper's 25 km scenarios (indices into ``fd.paper_scenarios()``).
SCENARIOS: tuple[int, ...] = (1, 4)


@one_blas_thread
def one(task: tuple[int, int, int, tuple[str, ...]]) -> dict[str, Any]:
    """Run ``r`` of scenario ``s`` at every timing: each estimator's errors at pair 1's instants."""
    s, r, seed, names = task
    out: dict[str, Any] = {"s": s, "r": r}
    for delay in (0.0, *DELAYS):
        scen = dataclasses.replace(fd.paper_scenarios()[s], time_offsets=(0.0, delay))
        sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, s, r])))
        model = fd.TrackingModel.of(scen.geometry)
        init = fd.initiate(sim.measurements.first_per_pair(10), model)
        if delay == 0.0:
            out["t"] = sim.truth.times
        on_grid = np.isin(sim.truth.times, out["t"])
        if np.count_nonzero(on_grid) != out["t"].size:  # pair 1's instants must be the same numbers every time
            raise RuntimeError(f"run {r} of scenario {s}: pair 1's instants moved with pair 2's delay {delay:g} s")
        for name in names:
            e = fd.run_estimator(name, sim.measurements, model, init, verify=False).primary
            se, ne = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
            out[f"{name} {delay:g}"] = {"se": se[on_grid], "nees": ne[on_grid]}
    return out


def main() -> None:
    p = argparse.ArgumentParser(prog="python studies/async_pairs_paired.py", description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=600)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--estimators", nargs="+", default=["ekf", "fixed-lag"])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    names = tuple(a.estimators)
    tasks = [(s, r, a.seed, names) for s in SCENARIOS for r in range(a.runs)]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one, tasks, chunksize=4))
    timings = " / ".join(["same instants", *(f"{1e3 * d:g} ms" for d in DELAYS)])
    lines = [f"Pair 2 after pair 1, paired on the same recordings ({a.runs} runs per scenario, seed {a.seed}): "
             f"position RMSE over t >= 5 s (m) for {timings}; paired difference against the same instants "
             "(m, 95 % bootstrap interval); NEES", "",
             "| scenario | estimator | RMSE | " + " | ".join(f"{1e3 * d:g} ms − same" for d in DELAYS) + " | NEES |",
             "|---|---|---|" + "---|" * len(DELAYS) + "---|"]
    table = []
    for s in SCENARIOS:
        cell = [row for row in rows if row["s"] == s]
        for name in names:
            rmse, paired, nees = _common.paired_cells(cell, [f"{name} {d:g}" for d in (0.0, *DELAYS)])
            scenario = fd.paper_scenarios()[s].name
            lines.append(f"| {scenario} | {name} | {rmse} | {paired} | {nees} |")
            table.append({"scenario": scenario, "estimator": name, "rmse": rmse, "paired": paired, "nees": nees})
    _common.save_table(a.out, "async_pairs_paired", "\n".join(lines) + "\n", table)


if __name__ == "__main__":
    main()
