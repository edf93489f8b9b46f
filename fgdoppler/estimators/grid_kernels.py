r"""The grid search's compiled inner loop (numba): every candidate's cost on a window.

For a candidate start position :math:`\mathbf p_0` and velocity
:math:`\mathbf v`, and a sensor :math:`\mathbf s`, with
:math:`\mathbf a = \mathbf p_0 - \mathbf s`, :math:`U = \mathbf a\cdot\mathbf v`,
:math:`c = \lVert\mathbf a\rVert^2` and :math:`s^2 = \lVert\mathbf v\rVert^2`
(:func:`fgdoppler.estimators.grid._product_costs` forms :math:`U` and
:math:`c` as outer products), the range rate at time :math:`t` is

.. math:: \dot r(t) = \frac{U + t s^2}{\sqrt{c + 2tU + t^2 s^2}},

and the cost of the candidate is

.. math:: e = \sum_j \rho\Big(\big(Z_j - \dot r_{T_j}(t_j) - \dot r_{R_j}(t_j)\big)\,w_j\Big),

:math:`\rho(r) = r^2`, or the Huber loss
(:func:`fgdoppler.models.robust.huber_rho`) with a threshold.  Each distinct
(sensor, time) term is computed once per candidate and read by every
measurement that needs it (a transmitter seen by several receivers at one
instant).  The operations are numpy's in the same order (the terms, then the
sum over measurements in window order), and numba compiles without
fast-math, so the costs are those of the numpy loop this replaced to the bit
(``tests/estimators/test_grid.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["window_costs"]

FloatArray = NDArray[np.float64]
#: Velocities whose terms are held at once per position: bounds the loop's scratch to
#: ``TERM_BLOCK`` × (distinct terms) numbers, in the processor's cache for the windows the library scores.
TERM_BLOCK = 64


@njit(cache=True, error_model="numpy")
def _costs_loop(U: FloatArray, c: FloatArray, s2: FloatArray, per_position: bool, term_sensor: NDArray[np.intp],
                term_time: FloatArray, tx_term: NDArray[np.intp], rx_term: NDArray[np.intp], z: FloatArray,
                w: FloatArray, huber_k: float, out: FloatArray) -> None:  # pragma: no cover - compiled
    n_pos, _, n_vel = U.shape
    robust = huber_k > 0.0
    two_k = 2.0 * huber_k
    k_squared = huber_k * huber_k
    block = min(n_vel, TERM_BLOCK)
    terms = np.empty((term_sensor.size, block))
    for p in range(n_pos):
        for v0 in range(0, n_vel, block):
            nv = min(block, n_vel - v0)
            for q in range(term_sensor.size):
                si = term_sensor[q]
                t = term_time[q]
                t2 = 2.0 * t
                cp = c[p, si]
                for b in range(nv):
                    sv = s2[p] if per_position else s2[v0 + b]
                    us = U[p, si, v0 + b]
                    ts2 = t * sv
                    d2 = us * t2
                    d2 += cp
                    d2 += t * ts2
                    terms[q, b] = (us + ts2) / np.sqrt(d2)
            for b in range(nv):
                out[p, v0 + b] = 0.0
            for j in range(z.size):
                a = tx_term[j]
                r_ = rx_term[j]
                zj = z[j]
                wj = w[j]
                for b in range(nv):
                    h = 0.0
                    h += terms[a, b]
                    h += terms[r_, b]
                    r = (zj - h) * wj
                    if robust and abs(r) > huber_k:
                        out[p, v0 + b] += abs(r) * two_k - k_squared
                    else:
                        out[p, v0 + b] += r * r


def window_costs(U: FloatArray, c: FloatArray, s2: FloatArray, term_sensor: NDArray[np.intp],
                 term_time: FloatArray, tx_term: NDArray[np.intp], rx_term: NDArray[np.intp], z: FloatArray,
                 w: FloatArray, huber_k: float | None) -> FloatArray:
    r"""Costs ``(P, V)`` of ``P`` positions × ``V`` velocities (or ``(n, 1)`` of ``n`` pairs of them).

    Parameters
    ----------
    U : ndarray, shape ``(P, S, V)``
        :math:`U` of each position, sensor and velocity.
    c : ndarray, shape ``(P, S)``
        :math:`c` of each position and sensor.
    s2 : ndarray, shape ``(V,)`` or ``(P, 1)``
        :math:`s^2` of each velocity, or of each position's own velocity (then ``V`` is 1).
    term_sensor, term_time : ndarray, shape ``(T,)``
        The distinct (sensor, time) terms.
    tx_term, rx_term : ndarray, shape ``(m,)``
        Each measurement's transmitter and receiver term.
    z, w : ndarray, shape ``(m,)``
        The measurements and their weights :math:`1/\sigma_j`.
    huber_k : float or None
        The Huber threshold (``None``: squares).

    Returns
    -------
    ndarray, shape ``(P, V)``
        The costs; ``inf`` or NaN where a trajectory passes through a sensor.
    """
    n_pos, _, n_vel = U.shape
    out = np.empty((n_pos, n_vel))
    _costs_loop(np.ascontiguousarray(U), np.ascontiguousarray(c), np.ascontiguousarray(s2, dtype=np.float64).reshape(-1),
                s2.ndim == 2, np.ascontiguousarray(term_sensor, dtype=np.intp), np.ascontiguousarray(term_time),
                np.ascontiguousarray(tx_term, dtype=np.intp), np.ascontiguousarray(rx_term, dtype=np.intp),
                np.ascontiguousarray(z, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64),
                0.0 if huber_k is None else float(huber_k), out)
    return out
