r"""Would a whole-track check against the reference smoother flag the inconsistent runs the verdict calls ok?

The verdict compares a filter with the offline smoother of the same data at
the last time only (:func:`fgdoppler.estimators.judge.judge`).  This study
measures a check over every time instead, on the accuracy benchmark's
recordings (the paper's six scenarios, ``--runs`` per scenario, ``--seed``):
with :math:`\mathbf d_k = \hat{\mathbf x}_{f,k} - \hat{\mathbf x}_{s,k}` the
filtered minus the smoothed state at the common time :math:`t_k`,

.. math::

    m^2_k = \mathbf d_k^\top \mathbf P_{f,k}^{-1} \mathbf d_k,

which in a linear-Gaussian model is at most :math:`\chi^2_4` distributed
(:math:`\mathrm{Cov}\,\mathbf d_k = \mathbf P_{f,k} - \mathbf P_{s,k}
\preceq \mathbf P_{f,k}`).  Two tests: the maximum over the track against
the :math:`\chi^2_4` quantile at :math:`1 - 0.001/K` (Bonferroni over the
:math:`K` times), and the time average against the 99.9 % quantile.  A run
is inconsistent, as in ``benchmarks.bench_accuracy``, when its NEES
against the truth averaged over t >= 10 s exceeds the :math:`\chi^2_4`
99.9 % quantile.  Printed per seed, over the EKF, iSAM2, fixed-lag and
particle estimators: the inconsistent runs judged ``ok`` and how many of
them each test would flag, and the consistent ``ok`` runs each test would
flag.  The check was not adopted (docs/concepts.md, "How sure is each
comparison?").

Run: python studies/whole_track_check.py [--out DIR] [--runs 100] [--seed 2026]   (9 min per seed on 2 cores)
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from _common import each_run, paper_run
from numpy.typing import NDArray
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.metrics import nees
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.results import Estimates

FILTERS = ("ekf", "isam2", "fixed-lag", "particle")
LEVEL = 0.999
T_NEES = 10.0


def whole_track_statistic(est: Estimates, ref: Estimates) -> NDArray[np.float64]:
    r""":math:`m^2_k` at the times both ``est`` and ``ref`` have a determinate covariance."""
    _, ie, ir = np.intersect1d(np.round(est.times, 9), np.round(ref.times, 9), return_indices=True)
    keep = est.cov_ok[ie] & ref.cov_ok[ir]
    # the filtered state's NEES with the smoothed state standing in for the truth
    return nees(est.states[ie[keep]], est.covariances[ie[keep]], ref.states[ir[keep]])


def _run_nees(est: Estimates, times: NDArray[np.float64], truth: NDArray[np.float64]) -> float:
    """NEES against the truth averaged over the truth times t >= T_NEES where ``est`` has a state."""
    _, ie, it = np.intersect1d(np.round(est.times, 9), np.round(times, 9), return_indices=True)
    keep = est.cov_ok[ie] & (times[it] >= T_NEES)
    if not np.any(keep):
        return float("nan")
    return float(np.mean(nees(est.states[ie[keep]], est.covariances[ie[keep]], truth[it[keep]])))


@one_blas_thread
def one_run(args: tuple[int, int, int]) -> list[dict[str, Any]]:
    """Per filter of run ``r`` of scenario ``s``: run NEES, status and the two statistics of the check."""
    s, r, seed = args
    sim, model, init = paper_run(s, r, seed)
    m = sim.measurements
    ref = fd.run_estimator("smoother", m, model, init)
    out = []
    for name in FILTERS:
        res = fd.run_estimator(name, m, model, init, reference=ref)
        stat = whole_track_statistic(res.primary, ref.primary)
        out.append({"s": s, "r": r, "estimator": name, "status": str(res.status),
                    "run_nees": _run_nees(res.primary, sim.truth.times, sim.truth.states),
                    "max": float(np.max(stat)) if stat.size else float("nan"),
                    "mean": float(np.mean(stat)) if stat.size else float("nan"), "times": int(stat.size)})
    return out


def tally(rows: list[dict[str, Any]]) -> dict[str, int]:
    """Inconsistent ``ok`` runs and consistent ``ok`` runs, and how many of each the two tests flag."""
    q = float(chi2.ppf(LEVEL, 4))
    out = dict.fromkeys(("missed", "missed_max", "missed_mean", "consistent_ok", "flag_max", "flag_mean"), 0)
    for row in rows:
        if row["status"] != "ok" or not np.isfinite(row["run_nees"]) or not row["times"]:
            continue
        by_max = row["max"] > chi2.ppf(1 - (1 - LEVEL) / row["times"], 4)
        by_mean = row["mean"] > q
        key = "missed" if row["run_nees"] > q else "consistent_ok"
        prefix = "missed_" if key == "missed" else "flag_"
        out[key] += 1
        out[prefix + "max"] += int(by_max)
        out[prefix + "mean"] += int(by_mean)
    return out


def main() -> None:
    args, parts = each_run(one_run, "whole_track_check.py", "studies", chunksize=2)
    rows = [row for part in parts for row in part]
    t = tally(rows)
    print(f"seed {args.seed}, {args.runs} runs per scenario, filters {', '.join(FILTERS)}:")
    print(f"  inconsistent runs judged ok: {t['missed']}; the maximum test flags {t['missed_max']}, "
          f"the mean test {t['missed_mean']}")
    print(f"  consistent runs judged ok: {t['consistent_ok']}; the maximum test flags {t['flag_max']}, "
          f"the mean test {t['flag_mean']}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"whole_track_check_seed{args.seed}.json").write_text(json.dumps({"tally": t, "runs": rows}, indent=1))


if __name__ == "__main__":
    main()
