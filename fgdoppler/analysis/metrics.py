r"""Accuracy and consistency metrics over Monte Carlo runs.

Errors are stored per run and time with NaN where an estimator has no
estimate at that time (e.g. a filter before the end of the initiation window).

.. math::

    \mathrm{RMSE}_\text{pos}(t) = \sqrt{\tfrac1M\textstyle\sum_m \lVert\hat{\mathbf p}_m(t) - \mathbf p_m(t)\rVert^2},\qquad
    \mathrm{NEES}_m(t) = \mathbf e_m(t)'\mathbf P_m(t)^{-1}\mathbf e_m(t).

Under consistency the average NEES over :math:`M` runs satisfies
:math:`M\,\overline{\mathrm{NEES}} \sim \chi^2_{4M}`, giving the two-sided band
of :func:`nees_band`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

__all__ = ["errors", "nees", "nees_band", "rmse"]

FloatArray = NDArray[np.float64]


def errors(estimates: ArrayLike, truth: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Squared position and velocity errors ``(..., )`` of states ``(..., 2d)`` (``d`` = 2 or 3)."""
    e = np.asarray(estimates, dtype=float) - np.asarray(truth, dtype=float)
    d = e.shape[-1] // 2
    pos, vel = e[..., 0] ** 2, e[..., d] ** 2
    for i in range(1, d):
        pos = pos + e[..., i] ** 2
        vel = vel + e[..., d + i] ** 2
    return pos, vel


def nees(estimates: ArrayLike, covariances: ArrayLike, truth: ArrayLike) -> FloatArray:
    """NEES of each state: ``e' P^-1 e`` for ``(..., n)`` states and ``(..., n, n)`` covariances."""
    e = np.asarray(estimates, dtype=float) - np.asarray(truth, dtype=float)
    P = np.asarray(covariances, dtype=float)
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def rmse(squared_errors: ArrayLike, axis: int = 0) -> FloatArray:
    """Root mean of squared errors over ``axis`` (runs), ignoring NaN; NaN where no run has a value."""
    se = np.asarray(squared_errors, dtype=float)
    n = np.sum(np.isfinite(se), axis=axis)
    total = np.nansum(se, axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sqrt(total / np.maximum(n, 1)), np.nan)


def nees_band(n_runs: int, dim: int = 4, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` band of the run-averaged NEES of ``dim``-dimensional states."""
    lo, hi = chi2.ppf([(1 - probability) / 2, (1 + probability) / 2], dim * n_runs)
    return float(lo / n_runs), float(hi / n_runs)
