r"""How exact are the values that iSAM2's relinearisation checks read?

iSAM2 relinearises a Doppler factor when its state has moved beyond
``relinearize_position`` / ``relinearize_velocity`` from the factor's
linearisation point (:mod:`fgdoppler.estimators.isam2`).  The recent
states' values come from their joint marginal (:meth:`ISAM2Tracker._means`,
one ``jointBayesNet`` per check; until 2026-12-06 one ``marginalFactor`` per
state), not from iSAM2's own estimate, which stops back-substituting at the
wildfire threshold.  (The history check, every tenth update, reads iSAM2's
full back-substitution itself since later that day,
:meth:`ISAM2Tracker._solved`: it is compared with that by construction, and
this study compares the recent checks.)  In exact arithmetic a Gaussian marginal's mean is the
MAP of the linear system; in floating point the marginal is assembled from
the Bayes tree's cliques and shortcuts, which can lose digits in the
ill-conditioned chain of a poorly observed track.

This study runs iSAM2 (the mixture, as ``fgdoppler track`` does, without
the verdict) on the long benchmark's slow three-pair recording
(``benchmarks.bench_long``, cut to ``--duration`` seconds) and, at every
``--every``-th check, compares the values the check read with iSAM2's full
back-substitution (``calculateBestEstimate``), in metres and in each
component's marginal standard deviation.  It also counts the factors
relinearised with those values and, re-run with the full back-substitution's
values in their place (exact, O(N) per check), how many and how accurate the
filtered track is then.

Run: python studies/isam2_check_values.py [--duration 300] [--every 1]
(about 25 s at the defaults, 2026-12-06)
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import _common  # noqa: F401  (the benchmarks importable)
import numpy as np
from numpy.typing import NDArray

import fgdoppler as fd
from benchmarks.bench_long import recording
from fgdoppler.estimators.isam2 import ISAM2Tracker
from fgdoppler.factors import X


def _run(sim: fd.Simulation, means: Callable[[ISAM2Tracker, list[int]], NDArray[np.float64]]) -> dict[str, Any]:
    """iSAM2 on ``sim`` with ``means`` as the checks' values: relinearised factors and filtered position RMSE."""
    g = sim.scenario.geometry
    init = fd.initiate(sim.measurements.first_per_pair(10), g)
    original = ISAM2Tracker._means
    ISAM2Tracker._means = means  # type: ignore[method-assign,assignment]
    try:
        result = fd.run_estimator("isam2", sim.measurements, g, init, verify=False)
    finally:
        ISAM2Tracker._means = original  # type: ignore[method-assign]
    f = result.estimates[0]
    err = f.states[:, :2] - sim.truth.at(f.times)[:, :2]
    return {"relinearised": int(result.relinearizations.sum()),
            "filtered_rmse_m": float(np.sqrt(np.mean(np.sum(err**2, axis=1))))}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=300.0)
    p.add_argument("--every", type=int, default=1, help="compare at every n-th check")
    args = p.parse_args()
    sim = fd.simulate(replace(recording("slow"), duration=args.duration), np.random.default_rng(0))
    worst = {"checks": 0, "compared": 0, "m": 0.0, "m_per_s": 0.0, "sd": 0.0}
    original = ISAM2Tracker._means

    def compared(tracker: ISAM2Tracker, ks: list[int]) -> np.ndarray:
        xs = original(tracker, ks)
        worst["checks"] += 1
        if worst["checks"] % args.every == 0:
            best = tracker.isam.calculateBestEstimate()
            full = np.array([best.atVector(X(k)) for k in ks])
            sd = np.array([np.sqrt(np.diag(tracker.isam.marginalCovariance(X(k)))) for k in ks])
            d = np.abs(xs - full)
            worst["compared"] += 1
            worst["m"] = max(worst["m"], float(d[:, :2].max()))
            worst["m_per_s"] = max(worst["m_per_s"], float(d[:, 2:].max()))
            worst["sd"] = max(worst["sd"], float((d / sd).max()))
        return xs

    def exact(tracker: ISAM2Tracker, ks: list[int]) -> np.ndarray:
        best = tracker.isam.calculateBestEstimate()
        return np.array([best.atVector(X(k)) for k in ks])

    out = {"duration_s": args.duration, "largest_difference": worst,
           "with_marginals": _run(sim, compared), "with_full_back_substitution": _run(sim, exact)}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
