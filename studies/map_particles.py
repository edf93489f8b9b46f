r"""How many particles does ``map`` need?  Its accuracy, consistency and CPU time against the particle count.

``map`` (:func:`fgdoppler.estimators.particle.run_map`) reads the particle
posterior at its mode: its particles serve only its covariance (their second
moment about the mode), where a second climb starts and the skew test of its
read-out, so it may need fewer of them than the posterior mean does.  On the
accuracy benchmark's recordings (the paper's six scenarios, ``--runs`` per
scenario, ``--seed``), each run is tracked by ``MapSettings(n_particles=n)``
for every ``n`` of ``--particles`` (the first is the one the others are
compared with), in one process per run, in turn (the order reversed on odd
runs), each with its verdict against one shared reference smoother as
``python -m benchmarks.bench_accuracy`` runs it.  Per scenario:

* the position RMSE over t >= 5 s (the benchmark's measure,
  :func:`~fgdoppler.analysis.metrics.time_averaged_rmse`) and the paired
  difference against the first count with its 95 % bootstrap interval
  (:func:`~fgdoppler.analysis.metrics.compare_rmse`);
* the NEES averaged over runs, then over t >= 10 s (the benchmark's);
* the median CPU time per run, and the median over runs of each run's CPU
  time over the first count's (the ratio goal 2's time budget sees);
* the runs not judged ``ok``.

Run: python studies/map_particles.py [--particles 4096 2048] [--runs 100] [--seed 2026] [--workers 2] [--out DIR]
(about 10 min per seed on 2 cores)
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from _common import each_run, paired_cells, paper_run, save_table

import fgdoppler as fd
from benchmarks.bench_accuracy import _on_grid
from fgdoppler.analysis.workers import one_blas_thread


@one_blas_thread
def one_run(args: tuple[int, int, int], *, particles: list[int]) -> dict[str, Any]:
    """Squared errors, NEES, CPU time and status of ``map`` with each particle count on one run."""
    s, r, seed = args
    sim, model, init = paper_run(s, r, seed)
    m = sim.measurements
    reference = fd.run_estimator("smoother", m, model, init)
    out: dict[str, Any] = {"s": s, "r": r, "t": sim.truth.times.tolist()}
    for n in (particles if r % 2 == 0 else particles[::-1]):
        cpu = time.process_time()
        res = fd.run_estimator("map", m, model, init, fd.MapSettings(n_particles=n), reference=reference)
        cpu = time.process_time() - cpu
        e = res.primary
        se, ne = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
        out[str(n)] = {"se": se.tolist(), "nees": ne.tolist(), "seconds": cpu, "status": str(res.status)}
    return out


def summary(rows: list[dict[str, Any]], particles: list[int]) -> str:
    """One Markdown table line per scenario."""
    first, others = str(particles[0]), [str(n) for n in particles[1:]]
    counts = " / ".join(f"{n:,}" for n in particles)
    lines = [f"| scenario | RMSE (m), {counts} | " + " | ".join(f"{int(n):,} − {int(first):,} (m, 95 %)"
                                                                 for n in others)
             + f" | NEES, {counts} | median CPU (s), {counts} | CPU ratio to {int(first):,} (median of runs) "
             f"| not ok, {counts} |",
             "|---|---|" + "---|" * len(others) + "---|---|---|---|"]
    for s, scen in enumerate(fd.paper_scenarios()):
        rs = [row for row in rows if row["s"] == s]
        if not rs:
            continue
        keys = [first, *others]
        rmse, diffs, nees = paired_cells(rs, keys)
        cpu = {k: np.array([row[k]["seconds"] for row in rs]) for k in keys}
        lines.append(
            f"| {scen.name} | {rmse} | {diffs} | {nees} | "
            + " / ".join(f"{np.median(cpu[k]):.3f}" for k in keys) + " | "
            + " / ".join(f"{np.median(cpu[k] / cpu[first]):.2f}" for k in others) + " | "
            + " / ".join(str(sum(row[k]["status"] != "ok" for row in rs)) for k in keys) + " |")
    return "\n".join(lines)


def main() -> None:
    args, rows = each_run(one_run, "map_particles.py", "map_particles", chunksize=1, options={
        "--particles": {"type": int, "nargs": "+", "default": [4096, 2048],
                        "help": "particle counts; the first is the one the others are compared with"}})
    text = (f"{args.runs} runs per scenario, seed {args.seed}; `map` with "
            + ", ".join(f"{n:,}" for n in args.particles) + " particles\n\n"
            + summary(rows, args.particles) + "\n")
    save_table(args.out, f"map_particles_seed{args.seed}", text, rows)


if __name__ == "__main__":
    main()
