"""The offline smoother with the Huber loss on the paper's recordings, with and without gross outliers.

Each paper scenario, ``--runs`` recordings drawn from
``SeedSequence([seed, scenario, run])``; with ``--fraction F`` that share of
the measurements is replaced by ±100 m/s (100 σ) outliers, drawn after the
recording from the same generator, as in ``tests/estimators/test_robust.py``
(``--fraction 0``: clean data).  The window is initiated with the Huber loss
and ``fd.run_estimator("smoother", ...)`` runs with it (``--huber K``;
``--huber none``: the Gaussian loss on both), verdict included.  Printed per
scenario: the position RMSE over t ≥ 5 s (m), the verdicts, how many runs
re-initiated from the whole recording, how many are wrong and ``ok``
(final position error beyond χ²₂ 99.9 % of its own covariance), and the mean
CPU time per run (s).

Written for the Levenberg–Marquardt fix of 2026-11-26 (docs/concepts.md,
"Outliers: the Huber loss"): run it at the commit before it (1d60947) and
after to compare.

Run: ``python studies/robust_smoother.py [--runs 20] [--seed 3] [--fraction 0.05] [--huber 1.345]`` (about
3 minutes for 20 runs on 2 cores).
"""

from __future__ import annotations

import time
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: Start of the time average of the position error (s), as in the accuracy benchmark.
T_RMSE = 5.0
#: Size of an outlier (m/s): 100 σ of the paper's 1 m/s.
OUTLIER = 100.0
#: A run is wrong when its final position error lies beyond this χ²₂ quantile of its own covariance.
WRONG = float(chi2.ppf(0.999, 2))


def _huber(text: str) -> float | None:
    return None if text == "none" else float(text)


def _with_outliers(m: fd.Measurements, rng: np.random.Generator, fraction: float) -> fd.Measurements:
    """``m`` with ``fraction`` of its values replaced by ±:data:`OUTLIER` added to them."""
    z = m.doppler.copy()
    idx = rng.choice(len(m), round(fraction * len(m)), replace=False)
    z[idx] += rng.choice([-OUTLIER, OUTLIER], idx.size)
    return fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)


@one_blas_thread
def one_run(task: tuple[int, int, int], *, fraction: float, huber: float | None) -> dict[str, Any]:
    s, r, seed = task
    scen = fd.paper_scenarios()[s]
    rng = np.random.default_rng(np.random.SeedSequence([seed, s, r]))
    sim = fd.simulate(scen, rng)
    m = _with_outliers(sim.measurements, rng, fraction) if fraction > 0 else sim.measurements
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(m.first_per_pair(10), model, fd.InitiationSettings(huber_k=huber))
    t = time.process_time()
    res = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(huber_k=huber))
    cpu = time.process_time() - t
    e = res.primary
    err = e.states[:, :2] - sim.truth.at(e.times)[:, :2]
    late = e.times >= T_RMSE
    d = err[-1]
    wrong = bool(e.cov_ok[-1]) and float(d @ np.linalg.solve(e.covariances[-1, :2, :2], d)) > WRONG
    return {"scenario": s, "se": float(np.mean(np.sum(err[late] ** 2, axis=1))), "status": res.status,
            "reinitiated": any("re-initiated" in ev.message for ev in res.events), "wrong_ok": wrong and res.status == "ok",
            "cpu": cpu}


def main() -> None:
    options = {"--fraction": {"type": float, "default": 0.05},
               "--huber": {"type": _huber, "default": 1.345}}
    args, rows = _common.each_run(one_run, "robust_smoother.py", "robust_smoother", options=options)
    print(f"{args.runs} runs per scenario, seed {args.seed}, outliers {args.fraction:.0%}, Huber k {args.huber}")
    print("| scenario | RMSE (m) | ok / doubtful / failed | re-initiated | wrong and ok | CPU per run (s) |")
    print("|---|---|---|---|---|---|")
    for s, scen in enumerate(fd.paper_scenarios()):
        mine = [x for x in rows if x["scenario"] == s]
        counts = " / ".join(str(sum(x["status"] == k for x in mine)) for k in ("ok", "doubtful", "failed"))
        print(f"| {scen.name} | {np.sqrt(np.mean([x['se'] for x in mine])):,.1f} | {counts} | "
              f"{sum(x['reinitiated'] for x in mine)} | {sum(x['wrong_ok'] for x in mine)} | "
              f"{np.mean([x['cpu'] for x in mine]):.2f} |")


if __name__ == "__main__":
    main()
