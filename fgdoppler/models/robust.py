r"""The Huber loss, in the three forms the estimators use.

.. math::

    \rho(r) = \begin{cases} r^2 & |r| \le k \\ 2k|r| - k^2 & |r| > k \end{cases}

on whitened residuals :math:`r` (twice GTSAM's convention, so that it is the
squared residual inside ``k``): quadratic for small residuals, linear for
large ones, so that a few gross outliers cannot drag an estimate.  ``k =
1.345`` keeps 95 % efficiency on Gaussian data.

* :func:`huber_rho` — the loss itself (grid costs, smoother costs);
* :func:`huber_weights` — IRLS weights :math:`w = \min(1, k/|r|)` (estimators
  that linearise in numpy);
* :func:`huber_residuals` — residuals whose squares are the loss (GTSAM
  factors, robust per row).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["EFFICIENT_K", "huber_residuals", "huber_rho", "huber_weights"]

FloatArray = NDArray[np.float64]
#: The threshold (whitened units) at which the Huber estimate of a mean keeps 95 % efficiency on Gaussian data.
EFFICIENT_K = 1.345


def huber_rho(r: ArrayLike, k: float | None, *, out: FloatArray | None = None) -> FloatArray:
    r"""The Huber loss of whitened residuals: :math:`\rho(r) = r^2` for :math:`|r| \le k`, else
    :math:`2k|r| - k^2` (the squares without ``k``).

    ``out`` (which may be ``r`` itself) receives the loss, as numpy's own
    ``out``: the grid's hot loop takes it without allocating the loss anew.
    """
    r = np.asarray(r, dtype=float)
    if k is None:
        return np.multiply(r, r, out=out)
    linear = np.abs(r)
    beyond = linear > k
    rho = np.asarray(np.multiply(r, r, out=out))  # a 0-d input gives a scalar, which copyto cannot fill
    linear *= 2.0 * k
    linear -= k * k
    np.copyto(rho, linear, where=beyond)
    return rho


def huber_weights(whitened: ArrayLike, k: float | None) -> FloatArray:
    r"""IRLS weights of the Huber loss: :math:`w = \min(1, k/|r|)` for whitened residuals ``r``."""
    r = np.abs(np.asarray(whitened, dtype=float))
    if k is None:
        return np.ones_like(r)
    return np.minimum(1.0, k / np.maximum(r, 1e-300))


def huber_residuals(r: ArrayLike, k: float) -> tuple[FloatArray, FloatArray]:
    r"""Residuals whose squares are the loss, and their derivative: :math:`\tilde r = \mathrm{sign}(r)\sqrt{\rho(r)}`.

    :math:`\sum_j \tilde r_j^2 = \sum_j \rho(r_j)` exactly, and
    :math:`d\tilde r/dr = k/\sqrt{2k|r| - k^2}` beyond ``k`` (1 inside,
    continuous at ``k``).  A factor that returns :math:`\tilde r` under a
    Gaussian noise model is robust per measurement, with an error GTSAM's step
    acceptance sees exactly (GTSAM's own robust noise models weigh a multi-row
    factor by the norm of its whole error).
    """
    r = np.asarray(r, dtype=float)
    a = np.abs(r)
    big = a > k
    e = r.copy()
    d = np.ones_like(r)
    if np.any(big):
        root = np.sqrt(2.0 * k * a[big] - k * k)
        e[big] = np.sign(r[big]) * root
        d[big] = k / root
    return e, d
