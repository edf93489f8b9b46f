r"""What a declared clock uncertainty costs: CPU per run of every estimator with and without ``clock_sigma``.

A ``clock_sigma`` makes every estimator add the consider covariance of
:func:`fgdoppler.estimators.clock_offsets.clock_shares` (the smoother its own,
:func:`~fgdoppler.estimators.clock_offsets.with_clock_uncertainty`): four more
runs per pair on the data as a clock that far off would give them
(docs/concepts.md, "Clock offsets").  This study runs each estimator through
the registry, with its verdict (the filters' and the particle estimators'
reference smoother included), on the accuracy benchmark's recordings (the
paper's six scenarios, ``--runs`` per scenario, ``--seed``) once without and
once with ``--clock-sigma`` (s, every pair), and prints the mean CPU time per
run of each and their ratio.  The CPU time is each worker process's own
(BLAS on one thread), so it does not depend on ``--workers``; the tracks are
checked to be the same with and without (the share changes covariances only).

Run: python studies/clock_share_cost.py [--runs 3] [--seed 2026] [--clock-sigma 0.1] [--workers 2]
(about 4 minutes on 2 cores with the defaults)
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from _common import each_run, paper_run

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.registry import estimator_info


@one_blas_thread
def one_run(args: tuple[int, int, int], clock_sigma: float) -> dict[str, Any]:
    """CPU seconds of every estimator on run ``r`` of scenario ``s`` without and with ``clock_sigma``."""
    s, r, seed = args
    sim, model, init = paper_run(s, r, seed)
    row: dict[str, Any] = {"s": s}
    for name in fd.ESTIMATORS:
        states = []
        for declared in (0.0, clock_sigma):
            t0 = time.process_time()
            result = fd.run_estimator(name, sim.measurements, model, init,
                                      estimator_info(name).settings(clock_sigma=declared))
            row[f"{name}_{declared > 0}"] = time.process_time() - t0
            states.append(result.primary.states)
        if not np.array_equal(states[0], states[1]):
            raise RuntimeError(f"{name}: the track changed with clock_sigma in scenario {s}, run {r}")
    return row


def main() -> None:
    args, rows = each_run(one_run, "clock_share_cost.py", "studies", chunksize=1,
                          options={"--clock-sigma": {"type": float, "default": 0.1}})
    lines = [f"{args.runs} runs of each paper scenario, seed {args.seed}, clock_sigma {args.clock_sigma:g} s: "
             "mean CPU time per run (s), with the verdict", "",
             "| estimator | without | with | ratio |", "|---|---|---|---|"]
    for name in fd.ESTIMATORS:
        without = float(np.mean([row[f"{name}_False"] for row in rows]))
        with_ = float(np.mean([row[f"{name}_True"] for row in rows]))
        lines.append(f"| {name} | {without:.2f} | {with_:.2f} | {with_ / without:.2f} |")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
