"""The linearised widening of a filter's covariances: one stacked factorisation against one matrix at a time.

:class:`fgdoppler.estimators.spread._Linearised` widens every usable
covariance of the EKF, iSAM2 and the fixed-lag smoother towards the
posterior mean-square error of its estimate (by default at every estimate,
``SampledCovarianceSettings.linearised_everywhere``): a 2-hour recording at
2 scans/s holds 14,400 of them.  ``N`` pairs of 4 × 4 covariances with
variances of 10⁶ m² and 10² m²/s² (the scales of the paper's tracks), about
three in four of them wider than the threshold in some direction, widened by
:func:`~fgdoppler.estimators.spread._widened_stack` as one stack and one
matrix at a time (each a stack of one, as the per-estimate loop before it
did), the two interleaved ``REPEATS`` times so that load affects both
alike.  The two must agree bit for bit.

Run alone: ``python -m benchmarks --only widening`` (a few seconds).
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks._common import Row
from fgdoppler.estimators.spread import FILTER_WIDEN_MIN, _widened_stack

N = 2000
REPEATS = 5


def pairs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` positive definite covariances ``P`` and mean-square errors ``S`` near ``c P``, ``c`` in 0.2-2.5."""
    rng = np.random.default_rng(seed)
    A, B = rng.standard_normal((2, n, 4, 4))
    scale = np.array([1e3, 1e3, 10.0, 10.0])[:, None]
    P = (scale * A) @ (scale * A).transpose(0, 2, 1) + 1e-3 * np.eye(4)
    S = rng.uniform(0.2, 2.5, (n, 1, 1)) * (P + 0.05 * (scale * B) @ (scale * B).transpose(0, 2, 1))
    return P, S


def run() -> list[Row]:
    P, S = pairs(N)
    stacked, single = [], []
    for _ in range(REPEATS):
        t = time.perf_counter()
        wide, grew = _widened_stack(P, S, FILTER_WIDEN_MIN)
        stacked.append(time.perf_counter() - t)
        t = time.perf_counter()
        each = [_widened_stack(P[k:k + 1], S[k:k + 1], FILTER_WIDEN_MIN) for k in range(N)]
        single.append(time.perf_counter() - t)
    same = (np.array_equal(wide, np.concatenate([w for w, _ in each]))
            and np.array_equal(grew, np.concatenate([g for _, g in each])))
    a, b = float(np.median(stacked)) / N * 1e6, float(np.median(single)) / N * 1e6
    return [Row(name=f"linearised widening of {N} covariances ({int(np.count_nonzero(grew))} widened), per "
                     f"covariance: one stack vs one matrix at a time; bit-identical: {'yes' if same else 'NO'}",
                value=f"{a:.1f} vs {b:.1f} µs", ratio=b / a, target="— (speed-up of the stack)",
                met=None if same else False)]
