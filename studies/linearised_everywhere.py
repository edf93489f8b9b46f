r"""Would the linearised enclosure at every estimate, not only beyond the samples' reach, make the filters honest?

The registry widens a filter's (and the fixed-lag smoother's lagged)
covariances to posterior samples of the data they have read, and only
where those samples lose reach (the process noise) towards the posterior
of the same data linearised about the offline smoother's track
(:mod:`fgdoppler.estimators.linearized_posterior`).  Between two sample
checks the widening of the last one is carried, and a covariance that
changes shape there can be overconfident (docs/concepts.md, "The filters'
covariances on long recordings").  This study applies the linearised
enclosure (horizon: the estimate's time plus its look-ahead) at *every*
estimate, on top of the covariances the registry reports (reading every
measurement, where the registry leaves out those the gate rejected), on the accuracy
benchmark's recordings (the paper's six scenarios, ``--runs`` per scenario,
``--seed``), and prints per scenario and estimator the run-averaged NEES
(t >= 10 s) and the inconsistent runs (run NEES above the chi-square(4)
99.9 % point, as ``benchmarks.bench_accuracy`` counts them) and of those
the ones judged ``ok``, reported → always enclosed.  Not adopted: it would
make every covariance depend on the whole recording (note on issue 14,
stop 63).

Run: python studies/linearised_everywhere.py [--runs 100] [--seed 2026]   (7 min per seed on 2 cores)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from _common import each_run, paper_run

import fgdoppler as fd
from benchmarks.bench_accuracy import T_NEES, _on_grid, run_inconsistent
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.spread import _Linearised

ESTIMATORS = ("ekf", "isam2", "fixed-lag")


@one_blas_thread
def one_run(task: tuple[int, int, int]) -> tuple[int, Any, dict[str, tuple[Any, Any, str]]]:
    """(scenario, truth times, per estimator: NEES on the truth grid reported and always enclosed, status)."""
    s, r, seed = task
    sim, model, init = paper_run(s, r, seed)
    m = sim.measurements
    reference = fd.run_estimator("smoother", m, model, init)
    tt, truth = sim.truth.times, sim.truth.states
    out: dict[str, tuple[Any, Any, str]] = {}
    for name in ESTIMATORS:
        result = fd.run_estimator(name, m, model, init, reference=reference)
        e = result.primary
        P = e.covariances.copy()
        usable = np.flatnonzero(e.cov_ok)
        if usable.size:
            _Linearised(m, model, (reference.primary.times, reference.primary.states), result.settings.huber_k,
                        result.settings.look_ahead).widen(P, e.times, e.states, usable, int(usable[0]))
        out[name] = (_on_grid(tt, e.times, e.states, e.covariances, truth, e.cov_ok)[1],
                     _on_grid(tt, e.times, e.states, P, truth, e.cov_ok)[1], str(result.status))
    return s, tt, out


def main() -> None:
    args, rows = each_run(one_run, "linearised_everywhere.py", "studies")
    print(f"{args.runs} runs per scenario, seed {args.seed}: NEES (t >= {T_NEES:g} s) and inconsistent runs "
          "(of them ok), reported -> enclosed at every estimate")
    for s, scenario in enumerate(fd.paper_scenarios()):
        mine = [row for row in rows if row[0] == s]
        tt = mine[0][1]
        late = tt >= T_NEES
        parts = []
        for name in ESTIMATORS:
            before, after = (np.array([row[2][name][i] for row in mine]) for i in (0, 1))
            ok = np.array([row[2][name][2] == "ok" for row in mine])
            bad = [run_inconsistent(v, tt) for v in (before, after)]
            parts.append(f"{name} {np.nanmean(before[:, late]):.2f} -> {np.nanmean(after[:, late]):.2f}, "
                         f"{bad[0].sum()} ({(bad[0] & ok).sum()} ok) -> {bad[1].sum()} ({(bad[1] & ok).sum()} ok)")
        print(f"{scenario.name}: " + " | ".join(parts))


if __name__ == "__main__":
    main()
