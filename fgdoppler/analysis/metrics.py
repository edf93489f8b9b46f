r"""Accuracy and consistency metrics over Monte Carlo runs.

Errors are stored per run and time with NaN where an estimator has no
estimate at that time (e.g. a filter before the end of the initiation window).

.. math::

    \mathrm{RMSE}_\text{pos}(t) = \sqrt{\tfrac1M\textstyle\sum_m \lVert\hat{\mathbf p}_m(t) - \mathbf p_m(t)\rVert^2},\qquad
    \mathrm{NEES}_m(t) = \mathbf e_m(t)'\mathbf P_m(t)^{-1}\mathbf e_m(t).

Under consistency the average NEES over :math:`M` runs satisfies
:math:`M\,\overline{\mathrm{NEES}} \sim \chi^2_{4M}`, giving the two-sided band
of :func:`nees_band`.

Comparisons of two estimators on the same runs use the time-averaged RMSE
:math:`\bar R = \frac1{|T|}\sum_{t\in T}\mathrm{RMSE}_\text{pos}(t)` and a
*paired* bootstrap over runs (:func:`compare_rmse`): both estimators see the
same resampled runs, so the run-to-run spread common to both cancels and a
difference far below either RMSE's own sampling error is still resolved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

__all__ = ["RmseComparison", "compare_rmse", "errors", "nees", "nees_band", "rmse", "time_averaged_rmse"]

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


def time_averaged_rmse(squared_errors: ArrayLike, times: ArrayLike, *, t0: float = 0.0,
                       counts: ArrayLike | None = None) -> FloatArray:
    r"""Position RMSE over runs at each time, averaged over the times :math:`t \ge t_0`.

    Parameters
    ----------
    squared_errors : array_like, shape (runs, T)
        Squared position errors per run and time; NaN where a run has no
        estimate (that run does not count at that time).
    times : array_like, shape (T,)
        The times of the columns.
    t0 : float
        First time of the average (s).
    counts : array_like, shape (B, runs), optional
        Run multiplicities of ``B`` resamples (bootstrap counts, or 0/1
        for subsets).  With :math:`c_{bm}` the count of run :math:`m` in
        resample :math:`b`,
        :math:`\mathrm{RMSE}_b(t) = \sqrt{\sum_m c_{bm} e^2_m(t) / \sum_m c_{bm}}`
        over the runs with a value at :math:`t`.

    Returns
    -------
    ndarray
        A 0-d array, or ``(B,)`` with ``counts``; NaN where no time has a value.
    """
    se = np.asarray(squared_errors, dtype=float)
    t = np.asarray(times, dtype=float)
    if se.ndim != 2 or t.shape != (se.shape[1],):
        raise ValueError(f"squared errors (runs, T) and times (T,) expected, got {se.shape} and {t.shape}")
    c = np.ones((1, se.shape[0])) if counts is None else np.asarray(counts, dtype=float)
    if c.ndim != 2 or c.shape[1] != se.shape[0]:
        raise ValueError(f"counts must be (B, {se.shape[0]}), got {c.shape}")
    sel = t >= t0 - 1e-9
    finite = np.isfinite(se[:, sel])
    total = c @ np.where(finite, se[:, sel], 0.0)
    n = c @ finite
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(n > 0, np.sqrt(total / np.where(n > 0, n, 1.0)), np.nan)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r)
        out = np.where(valid.any(axis=1), np.nansum(r, axis=1) / np.maximum(valid.sum(axis=1), 1), np.nan)
    return out[0] if counts is None else out


@dataclass(frozen=True, kw_only=True)
class RmseComparison:
    """Time-averaged RMSE of estimator A minus that of B, with its paired-bootstrap interval.

    Parameters
    ----------
    difference : float
        :math:`\bar R_A - \bar R_B` on all runs (m); negative: A more accurate.
    low, high : float
        Percentile interval of the difference over the bootstrap resamples.
    probability : float
        The interval's coverage.
    resamples : int
        Number of bootstrap resamples.
    """

    difference: float
    low: float
    high: float
    probability: float
    resamples: int

    @property
    def resolved(self) -> bool:
        """Whether the interval excludes zero (the data tell the two apart)."""
        return bool(self.low > 0 or self.high < 0)

    def __str__(self) -> str:
        pct = f"{100 * self.probability:g} %"
        return f"{self.difference:+,.1f} m ({pct} {self.low:+,.1f} to {self.high:+,.1f})"


def compare_rmse(squared_errors_a: ArrayLike, squared_errors_b: ArrayLike, times: ArrayLike, *,
                 t0: float = 0.0, probability: float = 0.95, resamples: int = 2000,
                 seed: int = 0) -> RmseComparison:
    r"""Paired bootstrap of the difference of two estimators' time-averaged RMSE on the same runs.

    Runs are resampled with replacement (``resamples`` times, from
    ``numpy.random.default_rng(seed)``), the *same* runs for both
    estimators; the interval is the central ``probability`` percentile
    interval of :math:`\bar R_A^{(b)} - \bar R_B^{(b)}`
    (:func:`time_averaged_rmse`).

    Raises
    ------
    ValueError
        If the two arrays differ in shape or ``probability`` is not in (0, 1).
    """
    a = np.asarray(squared_errors_a, dtype=float)
    b = np.asarray(squared_errors_b, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"both estimators need the same runs and times, got {a.shape} and {b.shape}")
    if not 0 < probability < 1:
        raise ValueError(f"probability must be in (0, 1), got {probability}")
    if resamples < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    rng = np.random.default_rng(seed)
    counts = rng.multinomial(a.shape[0], np.full(a.shape[0], 1.0 / a.shape[0]), size=resamples)
    d = time_averaged_rmse(a, times, t0=t0, counts=counts) - time_averaged_rmse(b, times, t0=t0, counts=counts)
    lo, hi = np.nanpercentile(d, [50 * (1 - probability), 50 * (1 + probability)])
    diff = float(time_averaged_rmse(a, times, t0=t0) - time_averaged_rmse(b, times, t0=t0))
    return RmseComparison(difference=diff, low=float(lo), high=float(hi), probability=probability,
                          resamples=resamples)
