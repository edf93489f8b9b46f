"""Monte Carlo throughput with 1 and 2 worker processes (six paper scenarios)."""

from __future__ import annotations

import time

import fgdoppler as fd
from benchmarks._common import Row
from fgdoppler.analysis.montecarlo import MonteCarloSpec, run_monte_carlo


def run(runs: int = 10) -> list[Row]:
    spec = MonteCarloSpec(scenarios=tuple(fd.paper_scenarios()), runs=runs)
    times = {}
    for w in (1, 2):
        t = time.perf_counter()
        run_monte_carlo(spec, workers=w, progress=False)
        times[w] = time.perf_counter() - t
    n = runs * len(spec.scenarios)
    speedup = times[1] / times[2]
    return [Row(name=f"Monte Carlo, {n} scenario-runs x 7 estimators",
                value=f"1 worker {n / times[1]:.2f} runs/s, 2 workers {n / times[2]:.2f} runs/s",
                ratio=speedup, target="2 workers >= 1.8x", met=speedup >= 1.8)]
