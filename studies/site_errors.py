r"""Sensor sites off their declared positions: how far off the trackers go, and what ``site_sigma`` makes of it.

Each recording of the paper's six scenarios is simulated with its three
sites moved by draws of :math:`N(0, \sigma^2)` per coordinate (``--site-error-sigma``,
m) and tracked with the sites where the paper puts them, once as it is and
once with ``site_sigma`` = the same σ declared (docs/concepts.md, "Sensor
sites").  For each estimator and scenario the table gives the verdicts
``ok`` / all, the ``ok`` answers whose final position lies beyond
χ²₂'s 99.73 % level (3 σ) under their own covariance, the final position's
NEES averaged over the runs (2 dimensions), and the mean CPU time per run
with the verdict (the filters' reference smoother included).  The tracks are
checked to be the same with and without (the share changes covariances only).

Run: python studies/site_errors.py [--runs 10] [--seed 2026] [--site-error-sigma 30] [--estimators smoother ekf]
[--workers 2] (about 5 minutes on 2 cores with the defaults)
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from _common import each_run, save_table
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.registry import estimator_info

#: The final position's NEES beyond which an answer is more than 3 sigma off (chi-square with 2 dof, 99.73 %).
BEYOND_3_SIGMA = float(chi2.ppf(0.9973, 2))


@one_blas_thread
def one_run(args: tuple[int, int, int], site_error_sigma: float, estimators: list[str]) -> dict[str, Any]:
    """Run ``r`` of scenario ``s``: each estimator's status, final NEES and CPU without and with ``site_sigma``."""
    s, r, seed = args
    scen = fd.paper_scenarios()[s]
    moved = fd.ErrorDraws(site_sigma=site_error_sigma).applied(
        scen, np.random.default_rng(np.random.SeedSequence([seed, s, r, 1])))
    sim = fd.simulate(moved, np.random.default_rng(np.random.SeedSequence([seed, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    row: dict[str, Any] = {"s": s}
    for name in estimators:
        states = []
        for declared in (0.0, site_error_sigma):
            t0 = time.process_time()
            result = fd.run_estimator(name, sim.measurements, model, init,
                                      estimator_info(name).settings(site_sigma=declared))
            e = result.primary
            j = np.flatnonzero(np.isin(e.times, sim.truth.times))[-1]
            err = e.states[j, :2] - sim.truth.at(e.times[j:j + 1])[0, :2]
            key = f"{name}_{declared > 0}"
            row[key] = {"cpu": time.process_time() - t0, "status": result.status,
                        "nees": float(err @ np.linalg.solve(e.covariances[j][:2, :2], err))}
            states.append(e.states)
        if not np.array_equal(states[0], states[1]):
            raise RuntimeError(f"{name}: the track changed with site_sigma in scenario {s}, run {r}")
    return row


def main() -> None:
    args, rows = each_run(one_run, "site_errors.py", "studies", chunksize=1,
                          options={"--site-error-sigma": {"type": float, "default": 30.0},
                                   "--estimators": {"nargs": "+", "default": ["smoother", "ekf"]}})
    names = [sc.name for sc in fd.paper_scenarios()]
    lines = [f"{args.runs} runs of each paper scenario, seed {args.seed}, sites off by N(0, {args.site_error_sigma:g}^2) m "
             "per coordinate; ok / runs, ok beyond 3 sigma, final position NEES (2-D, mean), CPU s per run", "",
             "| scenario | estimator | site_sigma | ok | ok beyond 3 sigma | mean NEES | CPU s |", "|---|---|---|---|---|---|---|"]
    table = []
    for s, scenario in enumerate(names):
        for name in args.estimators:
            for declared in (False, True):
                cells = [row[f"{name}_{declared}"] for row in rows if row["s"] == s]
                ok = [c for c in cells if c["status"] == "ok"]
                beyond = sum(c["nees"] > BEYOND_3_SIGMA for c in ok)
                mean_nees = float(np.mean([c["nees"] for c in cells]))
                cpu = float(np.mean([c["cpu"] for c in cells]))
                sigma = args.site_error_sigma if declared else 0.0
                lines.append(f"| {scenario} | {name} | {sigma:g} | {len(ok)} / {len(cells)} | {beyond} | "
                             f"{mean_nees:.2f} | {cpu:.2f} |")
                table.append({"scenario": scenario, "estimator": name, "site_sigma": sigma, "ok": len(ok),
                              "runs": len(cells), "ok_beyond_3_sigma": beyond, "mean_nees": mean_nees, "cpu": cpu})
    save_table(args.out, "site_errors", "\n".join(lines) + "\n", table)


if __name__ == "__main__":
    main()
