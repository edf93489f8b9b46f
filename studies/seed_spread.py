"""How much the estimators' answers move with the seed of their random numbers (``TrackerSettings.seed``).

On the accuracy benchmark's recordings (``benchmarks/bench_accuracy.py``:
run ``r`` of scenario ``s`` draws from ``SeedSequence([seed, s, r])``) every
estimator runs with sampler seeds ``0 .. --seeds - 1`` (the reference
smoother that judges the filters with the same seed, as ``run_estimator``
runs it).  Per scenario and estimator:

- the share of runs whose position error moved by more than 10 cm at some time
  with the seed;
- the benchmark's number, the time-averaged position RMSE over t ≥ 5 s,
  for each seed (its range is the Monte Carlo error of that number that no
  more recordings remove: the recordings are the same);
- the median over runs of the standard deviation over seeds of each run's
  own time-averaged RMS error, against the median of that error;
- the run-averaged NEES over t ≥ 10 s for each seed, as the benchmark averages it.

Run: ``python studies/seed_spread.py [--runs 20] [--seeds 4] [--seed 2026] [--out DIR]``
(15 minutes on 2 cores with the defaults).
"""

from __future__ import annotations

import argparse
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import _common  # noqa: F401  (the repository root on the path, for the benchmarks)
import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import T_NEES, T_RMSE, _on_grid, mean_after
from fgdoppler.analysis.metrics import time_averaged_rmse
from fgdoppler.analysis.workers import one_blas_thread

NAMES: tuple[str, ...] = tuple(fd.ESTIMATORS)
#: A run's track "moved" when its position error changed by more than this (m) at some time.
MOVED = 0.1


@one_blas_thread
def _run(args: tuple[int, int, int, int]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Squared position errors and NEES on the truth's grid of every estimator, sampler seed ``k``."""
    s, r, seed, k = args
    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), model)
    reference = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(seed=k))
    out = {}
    for name in NAMES:
        res = reference if name == "smoother" else fd.run_estimator(
            name, m, model, init, fd.ESTIMATORS[name].settings(seed=k), reference=reference)
        e = res.primary
        out[name] = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
    return out


def summarise(se: np.ndarray, ne: np.ndarray, times: np.ndarray) -> dict[str, object]:
    """``se``, ``ne``: (seeds, runs, T) of one estimator in one scenario."""
    k = se.shape[0]
    moved = np.any(np.abs(np.sqrt(se) - np.sqrt(se[:1])) > MOVED, axis=(0, 2))
    per_run = np.sqrt(np.nanmean(se[..., times >= T_RMSE], axis=-1))  # (seeds, runs): each run's time-averaged error
    return {
        "moved": f"{int(moved.sum())}/{moved.size}",
        "rmse per seed": [round(float(time_averaged_rmse(se[i], times, t0=T_RMSE)), 1) for i in range(k)],
        "median run error": round(float(np.median(per_run)), 1),
        "median run sd over seeds": round(float(np.median(np.std(per_run, axis=0, ddof=1))), 2),
        "largest run sd over seeds": round(float(np.max(np.std(per_run, axis=0, ddof=1))), 1),
        "nees per seed": [round(mean_after(np.nanmean(ne[i], axis=0), times, T_NEES), 2) for i in range(k)],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=2026, help="root seed of the recordings (default 2026)")
    p.add_argument("--runs", type=int, default=20, help="recordings per scenario (default 20)")
    p.add_argument("--seeds", type=int, default=4, help="sampler seeds 0 .. N-1 (default 4)")
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    scenarios = fd.paper_scenarios()
    jobs = [(s, r, a.seed, k) for s in range(len(scenarios)) for r in range(a.runs) for k in range(a.seeds)]
    with ProcessPoolExecutor(max(1, min(2, os.cpu_count() or 1))) as ex:
        results = list(ex.map(_run, jobs, chunksize=1))
    out: dict[str, object] = {"seed": a.seed, "runs": a.runs, "sampler seeds": a.seeds}
    for s, scen in enumerate(scenarios):
        label = scen.name
        times = fd.simulate(scen, np.random.default_rng(0)).truth.times  # the truth's grid: the same in every run
        mine = [res for (js, _, _, _), res in zip(jobs, results, strict=True) if js == s]
        rows = {}
        for name in NAMES:
            se = np.array([res[name][0] for res in mine]).reshape(a.runs, a.seeds, -1).transpose(1, 0, 2)
            ne = np.array([res[name][1] for res in mine]).reshape(a.runs, a.seeds, -1).transpose(1, 0, 2)
            rows[name] = summarise(se, ne, times)
            print(f"{label} {name}: {rows[name]}", flush=True)
        out[label] = rows
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "seed_spread.json").write_text(json.dumps(out, indent=1))
    print(f"wrote {a.out / 'seed_spread.json'}")


if __name__ == "__main__":
    main()
