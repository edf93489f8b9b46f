r"""How much of a filter's sampled widening is the process noise added unconditioned?

A filter's sampled check (:func:`fgdoppler.estimators.spread.filtered_spread`)
compares its covariance :math:`\mathbf P` at time :math:`t` with posterior samples
of the data so far, drawn for the first state and carried at constant
velocity, plus the whole span's process noise unconditioned:
:math:`\mathbf S = \mathbf F\mathbf\Sigma_0\mathbf F^\top + \mathbf Q(t - t_0)`;
it widens :math:`\mathbf P` where a whitened eigenvalue of :math:`\mathbf S`
exceeds :data:`~fgdoppler.estimators.spread.FILTER_WIDEN_MIN`.  The offline
smoother no longer adds :math:`\mathbf Q` so (docs/concepts.md, "The samples
on the smoother's marginals"); a filter has no smoothed marginals to carry
the samples on.  This study measures what the :math:`\mathbf Q` term does to
the filters' checks on the paper's six scenarios: at every check, the largest
whitened eigenvalue of :math:`\mathbf S` with and without it, and how many
checks widen either way.

Run: python studies/filter_check_noise.py [--runs 10] [--seed 2026] [--estimator ekf]
(about 1 min per estimator on 2 cores at the defaults)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from _common import each_run, paper_run

import fgdoppler as fd
from fgdoppler.estimators import spread


def one_run(task: tuple[int, int, int], estimator: str) -> tuple[int, list[tuple[float, float]]]:
    """(scenario, [(largest whitened eigenvalue with Q, without Q)] at each of the run's sampled checks)."""
    s, r, seed = task
    rows: list[tuple[float, float]] = []
    noise: list[np.ndarray] = []
    widening, whitened = spread._widening, spread._whitened_widening

    def with_noise(measurements: fd.Measurements, model: fd.TrackingModel, t0: float, t: float, x: np.ndarray,
                   P: np.ndarray, huber_k: float | None, rng: np.random.Generator) -> np.ndarray | None:
        noise.append(model.motion.Q(t - t0))
        try:
            return widening(measurements, model, t0, t, x, P, huber_k, rng)
        finally:
            noise.clear()

    def measured(P: np.ndarray, S: np.ndarray, min_ratio: float) -> Any:
        if noise:
            Li = np.linalg.inv(np.linalg.cholesky(P))
            rows.append((float(np.linalg.eigvalsh(Li @ S @ Li.T).max()),
                         float(np.linalg.eigvalsh(Li @ (S - noise[0]) @ Li.T).max())))
        return whitened(P, S, min_ratio)

    spread._widening, spread._whitened_widening = with_noise, measured
    try:
        sim, model, init = paper_run(s, r, seed)
        fd.run_estimator(estimator, sim.measurements, model, init, verify=False)
    finally:
        spread._widening, spread._whitened_widening = widening, whitened
    return s, rows


def main() -> None:
    args, results = each_run(one_run, "filter_check_noise.py", "filter_check_noise", chunksize=2,
                             options={"--estimator": {"default": "ekf", "choices": ("ekf", "isam2", "fixed-lag")}})
    limit = spread.FILTER_WIDEN_MIN
    print(f"{args.estimator}, {args.runs} runs per scenario, seed {args.seed}: largest whitened eigenvalue of the "
          f"checks' target with Q(t - t0) -> without it; a check widens above {limit:g}")
    for s, scenario in enumerate(fd.paper_scenarios()):
        lam = np.array([row for ss, rows in results if ss == s for row in rows]).reshape(-1, 2)
        if lam.size == 0:
            print(f"{scenario.name:22s} no checks")
            continue
        wide = lam[:, 0] > limit
        ratio = np.median(lam[wide, 0] / lam[wide, 1]) if np.any(wide) else float("nan")
        print(f"{scenario.name:22s} checks {len(lam):4d}, widening {int(wide.sum()):4d} -> "
              f"{int(np.sum(lam[:, 1] > limit)):4d}; median {np.median(lam[:, 0]):.2f} -> {np.median(lam[:, 1]):.2f}, "
              f"largest {lam[:, 0].max():.1f} -> {lam[:, 1].max():.1f}; median ratio where widening {ratio:.3f}")


if __name__ == "__main__":
    main()
