r"""The log of a sum of exponentials, for the particle estimators' weights.

:func:`log_sum_exp` computes what :func:`scipy.special.logsumexp` computes
(without its ``b``, ``return_sign`` and complex input), with the same
arithmetic as the SciPy this was measured with (1.17), so the same numbers
to the bit (test: ``tests/estimators/test_log_sum_exp.py``).  It exists for speed
alone: SciPy's function dispatches through its array-API layer on every
call, about 100 µs for 4,096 weights against about 30 µs here, and the
particle estimators normalise their weights some 500 times per 30 s
recording: 5 to 9 % of their CPU time (``python -m benchmarks --only
particle``, each variant in a fresh process: 0.95×; case b 25 and 45 km
alternated in one process beside other jobs: 0.91–0.93×).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["log_sum_exp"]

FloatArray = NDArray[np.float64]


def log_sum_exp(a: ArrayLike, axis: int | None = None, *, keepdims: bool = False) -> FloatArray:
    r""":math:`\log\sum_i e^{a_i}` over ``axis`` (all of ``a`` if ``None``), without overflow.

    With :math:`a^* = \max_i a_i` attained by :math:`m` of the entries,

    .. math::

        \log\sum_i e^{a_i} = a^* + \log m + \operatorname{log1p}\Big(\frac1m
        \sum_{i:\,a_i < a^*} e^{a_i - a^*}\Big),

    the maxima kept out of the sum so that a dominant term loses no
    precision (Blanchard, Higham & Higham 2021, "Accurately computing the
    log-sum-exp and softmax functions").  Where that is not finite (an
    entry ``+inf`` or NaN, or every entry ``-inf``) the direct
    :math:`\log\sum_i e^{a_i}` is returned: ``inf``, NaN or ``-inf``;
    over no entries, ``-inf``.

    Parameters
    ----------
    a
        Real values (converted to float).
    axis
        The axis to sum over, or ``None`` for every entry.
    keepdims
        Keep the summed axis with length one.

    Returns
    -------
    ndarray
        ``a``'s shape without ``axis`` (a 0-d array for ``axis=None``), or
        with it of length one.
    """
    x = np.asarray(a, dtype=float)
    if x.size == 0:
        return np.full(np.sum(x, axis=axis, keepdims=keepdims).shape, -np.inf)
    x_max = np.max(x, axis=axis, keepdims=True)
    top = x == x_max
    m = np.sum(top, axis=axis, keepdims=True, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        rest = np.sum(np.exp(np.where(top, -np.inf, x) - x_max), axis=axis, keepdims=True)
        rest = np.where(rest == 0, rest, rest / m)
        out = np.log1p(rest) + np.log(m) + x_max
        finite = np.isfinite(out)
        if not np.all(finite):
            out = np.where(finite, out, np.log(np.sum(np.exp(x), axis=axis, keepdims=True)))
    if not keepdims:
        out = out.reshape(()) if axis is None else np.squeeze(out, axis=axis)
    return out
