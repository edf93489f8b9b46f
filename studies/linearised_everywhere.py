r"""What the linearised enclosure at every estimate (``linearised_everywhere``, the default) does on the
accuracy benchmark's recordings.

The registry widens a filter's (and the fixed-lag smoother's lagged)
covariances to posterior samples of the data they have read, and towards
the posterior of the same data linearised about the offline smoother's
track (:mod:`fgdoppler.estimators.linearized_posterior`): beyond the
samples' reach only with ``linearised_everywhere=False``, at every
estimate by default (docs/concepts.md, "The linearised enclosure at every
estimate").  This study runs the EKF, iSAM2 and the fixed-lag smoother
both ways through the registry, with the same reference smoother, on the
paper's six scenarios (``--runs`` per scenario, ``--seed``, the recordings
and initiations of ``benchmarks.bench_accuracy``), and prints per scenario
and estimator the run-averaged NEES (t >= 10 s), the inconsistent runs
(run NEES above the chi-square(4) 99.9 % point, as the benchmark counts
them), of those the ones judged ``ok``, and the runs whose status differs,
beyond reach only -> everywhere.

Run: python studies/linearised_everywhere.py [--runs 100] [--seed 2026]   (about 10 min per seed on 2 cores)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from _common import each_run, paper_run

import fgdoppler as fd
from benchmarks.bench_accuracy import T_NEES, _on_grid, run_inconsistent
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.registry import estimator_info

ESTIMATORS = ("ekf", "isam2", "fixed-lag")


@one_blas_thread
def one_run(task: tuple[int, int, int]) -> tuple[int, Any, dict[str, tuple[Any, Any, str, str]]]:
    """(scenario, truth times, per estimator: NEES on the truth grid and status beyond reach only and everywhere)."""
    s, r, seed = task
    sim, model, init = paper_run(s, r, seed)
    m = sim.measurements
    reference = fd.run_estimator("smoother", m, model, init)
    tt, truth = sim.truth.times, sim.truth.states
    out: dict[str, tuple[Any, Any, str, str]] = {}
    for name in ESTIMATORS:
        settings_of: Callable[..., fd.TrackerSettings] = estimator_info(name).settings
        both = [fd.run_estimator(name, m, model, init, settings_of(linearised_everywhere=flag),
                                 reference=reference) for flag in (False, True)]
        nees = [_on_grid(tt, x.primary.times, x.primary.states, x.primary.covariances, truth, x.primary.cov_ok)[1]
                for x in both]
        out[name] = (nees[0], nees[1], str(both[0].status), str(both[1].status))
    return s, tt, out


def main() -> None:
    args, rows = each_run(one_run, "linearised_everywhere.py", "studies")
    print(f"{args.runs} runs per scenario, seed {args.seed}: NEES (t >= {T_NEES:g} s) and inconsistent runs "
          "(of them ok), the linearised enclosure beyond the samples' reach only -> at every estimate")
    for s, scenario in enumerate(fd.paper_scenarios()):
        mine = [row for row in rows if row[0] == s]
        tt = mine[0][1]
        late = tt >= T_NEES
        parts = []
        for name in ESTIMATORS:
            before, after = (np.array([row[2][name][i] for row in mine]) for i in (0, 1))
            ok = [np.array([row[2][name][i] == "ok" for row in mine]) for i in (2, 3)]
            bad = [run_inconsistent(v, tt) for v in (before, after)]
            parts.append(f"{name} {np.nanmean(before[:, late]):.2f} -> {np.nanmean(after[:, late]):.2f}, "
                         f"{bad[0].sum()} ({(bad[0] & ok[0]).sum()} ok) -> {bad[1].sum()} ({(bad[1] & ok[1]).sum()} ok), "
                         f"{(ok[0] != ok[1]).sum()} statuses differ")
        print(f"{scenario.name}: " + " | ".join(parts))


if __name__ == "__main__":
    main()
