"""Where a Gaussian tracker's start is split: the curvature probe's ratio, and what the split buys below the finding.

The EKF, iSAM2 and the fixed-lag smoother start from a Gaussian sum of the
window's posterior where their start is split
(:attr:`~fgdoppler.estimators.settings.GaussianSumSettings.split_ratio`):
on the initiation's ``nonlinear`` finding (its curvature probe beyond
:data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT`, 10) and, by
default, wherever the probe's ratio
(:attr:`Initiation.curvature <fgdoppler.estimators.initiation.Initiation>`)
lies beyond 2.5 or below 1/2.5.  This study runs each of the three on the
accuracy benchmark's recordings (``SeedSequence([seed, s, r])``) with the
default settings and with ``split_ratio=inf`` (the split on the finding
alone) wherever the two start differently, and prints per scenario: the
range of the probe's ratio on the windows without the finding, how many
windows the default splits beyond the finding, and on those the position
RMSE over t >= 5 s of both, the paired difference (default minus
finding alone, with its 95 % bootstrap interval), the NEES over t >= 10 s
(the accuracy benchmark's measures) and the median CPU time per run.
``--ratio R`` measures another default (``inf`` forces nothing: every
window is run both ways with its finding alone).  ``--force`` splits
every window without the finding instead (``split_ratio=1``), which is
what the well-observed scenarios would pay.

Run: ``python studies/start_split.py [--runs 60] [--seed 2026] [--workers 2] [--ratio 2.5] [--force] [--out DIR]``
(3 min on 2 cores at 60 runs; every run's errors to ``DIR/start_split.json``, default
``output/start_split``).  Results: docs/concepts.md, "Where a Gaussian start is split".
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import _common
import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import _on_grid
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.settings import EKFSettings, FixedLagSettings, ISAM2Settings

#: The trackers whose start is split, with their settings classes.
TRACKERS: dict[str, type[EKFSettings | ISAM2Settings | FixedLagSettings]] = {
    "ekf": EKFSettings, "isam2": ISAM2Settings, "fixed-lag": FixedLagSettings}


@one_blas_thread
def one(task: tuple[int, int, int], *, ratio: float, force: bool) -> dict[str, Any]:
    """Run ``r`` of scenario ``s``: the window's probe ratio and, where the split differs, each tracker both ways."""
    s, r, seed = task
    sim, model, init = _common.paper_run(s, r, seed)
    finding = any(x.code == "nonlinear" and x.status != "ok" for x in init.reasons)
    split = 1.0 if force else ratio
    out: dict[str, Any] = {"s": s, "r": r, "t": sim.truth.times.tolist(), "curvature": init.curvature,
                           "finding": finding}
    out["differs"] = not finding and EKFSettings(split_ratio=split).splits(init.curvature)
    if not out["differs"]:
        return out
    for name, kind in TRACKERS.items():
        default = kind(split_ratio=split)
        for key, settings in (("alone", dataclasses.replace(default, split_ratio=float("inf"))), ("split", default)):
            t0 = time.process_time()
            res = fd.run_estimator(name, sim.measurements, model, init, settings, verify=False)
            e = res.primary
            se, ne = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
            out[f"{name}/{key}"] = {"se": se.tolist(), "nees": ne.tolist(), "cpu": time.process_time() - t0}
    return out


def main() -> None:
    args, rows = _common.each_run(one, "start_split.py", "start_split", chunksize=1, options={
        "--ratio": {"type": float, "default": 2.5, "help": "the split_ratio measured (default 2.5)"},
        "--force": {"action": "store_true", "help": "split every window without the finding (split_ratio=1)"}})
    lines = [f"The start split beyond the finding ({args.runs} runs per scenario, seed {args.seed}, "
             f"split_ratio {1.0 if args.force else args.ratio:g}): RMSE over t >= 5 s (m) finding alone / split, "
             "paired difference, NEES over t >= 10 s, median CPU s per run", "",
             "| scenario | probe ratio without the finding | split beyond the finding | tracker | RMSE | "
             "paired difference (m) | NEES | CPU (s) |", "|---|---|---|---|---|---|---|---|"]
    for s, scen in enumerate(fd.paper_scenarios()):
        runs = [x for x in rows if x["s"] == s]
        ratios = [x["curvature"] for x in runs if not x["finding"] and x["curvature"] is not None]
        span = f"{min(ratios):.2f}–{max(ratios):.2f} ({len(ratios)})" if ratios else "—"
        split = [x for x in runs if x["differs"]]
        if not split:
            lines.append(f"| {scen.name} | {span} | 0 of {len(runs)} | — | — | — | — | — |")
            continue
        for name in TRACKERS:
            keyed = [{k: x[f"{name}/{k}"] for k in ("alone", "split")} | {"t": x["t"]} for x in split]
            rmse, diff, nees = _common.paired_cells(keyed, ["alone", "split"])
            cpu = " / ".join(f"{np.median([x[f'{name}/{k}']['cpu'] for x in split]):.2f}" for k in ("alone", "split"))
            lines.append(f"| {scen.name} | {span} | {len(split)} of {len(runs)} | {name} | {rmse} | {diff} | "
                         f"{nees} | {cpu} |")
    _common.save_table(args.out, "start_split", "\n".join(lines) + "\n", rows)


if __name__ == "__main__":
    main()
