r"""The grid search's compiled inner loop (numba): every candidate's cost on a window.

For a candidate start position :math:`\mathbf p_0` and velocity
:math:`\mathbf v`, and a sensor :math:`\mathbf s`, with
:math:`\mathbf a = \mathbf p_0 - \mathbf s`, :math:`U = \mathbf a\cdot\mathbf v`,
:math:`c = \lVert\mathbf a\rVert^2` and :math:`s^2 = \lVert\mathbf v\rVert^2`
the range rate at time :math:`t` is

.. math:: \dot r(t) = \frac{U + t s^2}{\sqrt{c + 2tU + t^2 s^2}},

and the cost of the candidate is

.. math:: e = \sum_j \rho\Big(\big(Z_j - \dot r_{T_j}(t_j) - \dot r_{R_j}(t_j)\big)\,w_j\Big),

:math:`\rho(r) = r^2`, or the Huber loss
(:func:`fgdoppler.models.robust.huber_rho`) with a threshold.  Each distinct
(sensor, time) term is computed once per candidate and read by every
measurement that needs it (a transmitter seen by several receivers at one
instant).  The operations are numpy's in the same order (:math:`\mathbf a`,
:math:`c` and :math:`U` coordinate by coordinate, the terms, then the sum over
measurements in window order), and numba compiles without fast-math, so the
costs are those of the numpy loop this replaced to the bit
(``tests/estimators/test_grid.py``).  Until 2026-12-06 numpy formed
:math:`\mathbf a`, :math:`c` and :math:`U` as arrays of positions × sensors
(× velocities) before this loop; forming them here, per position, spares that
memory traffic (``benchmarks/bench_grid.py``).

:func:`minima_among` tells which of some candidates are local minima of the
grid, looking at their neighbours only: the pruned search scores a few per
cent of the grid, and a filter over the whole grid (mostly infinite) cost
about as much as scoring them.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["minima_among", "window_costs"]

FloatArray = NDArray[np.float64]
#: Velocities whose terms are held at once per position: bounds the loop's scratch to
#: ``TERM_BLOCK`` × (distinct terms + sensors) numbers, in the processor's cache for the windows the library scores.
TERM_BLOCK = 64


@njit(cache=True, error_model="numpy")
def _costs_loop(pos: FloatArray, sensors: FloatArray, vel: FloatArray, s2: FloatArray, per_position: bool,
                term_sensor: NDArray[np.intp], term_time: FloatArray, tx_term: NDArray[np.intp],
                rx_term: NDArray[np.intp], z: FloatArray, w: FloatArray, huber_k: float,
                out: FloatArray) -> None:  # pragma: no cover - compiled
    n_pos, dim = pos.shape
    n_sensors = sensors.shape[0]
    n_vel = out.shape[1]
    robust = huber_k > 0.0
    two_k = 2.0 * huber_k
    k_squared = huber_k * huber_k
    block = min(n_vel, TERM_BLOCK)
    terms = np.empty((term_sensor.size, block))
    u = np.empty((n_sensors, block))
    a = np.empty((n_sensors, 3))
    c = np.empty(n_sensors)
    for p in range(n_pos):
        for si in range(n_sensors):
            for k in range(dim):
                a[si, k] = pos[p, k] - sensors[si, k]
            cs = a[si, 0] * a[si, 0] + a[si, 1] * a[si, 1]
            if dim == 3:
                cs += a[si, 2] * a[si, 2]
            c[si] = cs
        for v0 in range(0, n_vel, block):
            nv = min(block, n_vel - v0)
            for si in range(n_sensors):
                for b in range(nv):
                    vi = p if per_position else v0 + b
                    us = a[si, 0] * vel[vi, 0] + a[si, 1] * vel[vi, 1]
                    if dim == 3:
                        us += a[si, 2] * vel[vi, 2]
                    u[si, b] = us
            for q in range(term_sensor.size):
                si = term_sensor[q]
                t = term_time[q]
                t2 = 2.0 * t
                cp = c[si]
                for b in range(nv):
                    sv = s2[p] if per_position else s2[v0 + b]
                    us = u[si, b]
                    ts2 = t * sv
                    d2 = us * t2
                    d2 += cp
                    d2 += t * ts2
                    terms[q, b] = (us + ts2) / np.sqrt(d2)
            for b in range(nv):
                out[p, v0 + b] = 0.0
            for j in range(z.size):
                ta = tx_term[j]
                r_ = rx_term[j]
                zj = z[j]
                wj = w[j]
                for b in range(nv):
                    h = 0.0
                    h += terms[ta, b]
                    h += terms[r_, b]
                    r = (zj - h) * wj
                    if robust and abs(r) > huber_k:
                        out[p, v0 + b] += abs(r) * two_k - k_squared
                    else:
                        out[p, v0 + b] += r * r


def window_costs(pos: FloatArray, sensors: FloatArray, vel: FloatArray, s2: FloatArray, per_position: bool,
                 term_sensor: NDArray[np.intp], term_time: FloatArray, tx_term: NDArray[np.intp],
                 rx_term: NDArray[np.intp], z: FloatArray, w: FloatArray, huber_k: float | None) -> FloatArray:
    r"""Costs ``(P, V)`` of ``P`` positions × ``V`` velocities (or ``(n, 1)`` of ``n`` pairs of them).

    Parameters
    ----------
    pos : ndarray, shape ``(P, d)``
        Start positions (``d`` = 2 or 3).
    sensors : ndarray, shape ``(S, d)``
        The distinct sensor positions.
    vel : ndarray, shape ``(V, d)``, or ``(P, d)`` with ``per_position``
        Velocities.
    s2 : ndarray, shape ``(V,)``, or ``(P,)`` with ``per_position``
        :math:`s^2` of each velocity.
    per_position : bool
        Each position with its own velocity (the result is ``(P, 1)``) instead of with every velocity.
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
    out = np.empty((pos.shape[0], 1 if per_position else vel.shape[0]))
    _costs_loop(np.ascontiguousarray(pos, dtype=np.float64), np.ascontiguousarray(sensors, dtype=np.float64),
                np.ascontiguousarray(vel, dtype=np.float64), np.ascontiguousarray(s2, dtype=np.float64).reshape(-1),
                per_position, np.ascontiguousarray(term_sensor, dtype=np.intp), np.ascontiguousarray(term_time),
                np.ascontiguousarray(tx_term, dtype=np.intp), np.ascontiguousarray(rx_term, dtype=np.intp),
                np.ascontiguousarray(z, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64),
                0.0 if huber_k is None else float(huber_k), out)
    return out


@njit(cache=True)
def _minima_loop(cost: FloatArray, shape: NDArray[np.intp], wrap_last: bool, flat: NDArray[np.intp],
                 out: NDArray[np.bool_]) -> None:  # pragma: no cover - compiled
    d = shape.size
    strides = np.empty(d, dtype=np.intp)
    stride = 1
    for k in range(d - 1, -1, -1):
        strides[k] = stride
        stride *= shape[k]
    index = np.empty(d, dtype=np.intp)
    for i in range(flat.size):
        f = flat[i]
        here = cost[f]
        rest = f
        for k in range(d):
            index[k] = rest // strides[k]
            rest -= index[k] * strides[k]
        lowest = True
        for code in range(3 ** d):
            g = 0
            inside = True
            c = code
            for k in range(d - 1, -1, -1):
                j = index[k] + c % 3 - 1
                c //= 3
                if j < 0 or j >= shape[k]:
                    if k == d - 1 and wrap_last:
                        j %= shape[k]
                    else:
                        # clamped to the edge, the neighbour is another member of the box: nothing to compare
                        inside = False
                        break
                g += j * strides[k]
            if inside and cost[g] < here:
                lowest = False
                break
        out[i] = lowest


def minima_among(cost: FloatArray, shape: tuple[int, ...], wrap_last: bool,
                 flat: NDArray[np.intp]) -> NDArray[np.bool_]:
    r"""Which of the candidates ``flat`` are no worse than any grid neighbour.

    A candidate :math:`i` of the grid ``cost.reshape(shape)`` is a local
    minimum when :math:`e_i \le e_j` for every :math:`j` in the
    :math:`3^d` box around it: ``cube == minimum_filter(cube, size=3)`` with
    the mode ``"nearest"`` on every axis (a neighbour beyond the edge is
    another member of the box) and ``"wrap"`` on the last where
    ``wrap_last`` (headings over the full circle).

    Parameters
    ----------
    cost : ndarray, shape ``(prod(shape),)``
        The grid's costs, flat; no NaN (the scorers map it to ``inf``).
    shape : tuple of int
        The grid's axes.
    wrap_last : bool
        Whether the last axis wraps around.
    flat : ndarray of int
        The candidates to test.

    Returns
    -------
    ndarray of bool, shape ``flat.shape``
    """
    out = np.empty(flat.size, dtype=np.bool_)
    _minima_loop(np.ascontiguousarray(cost, dtype=np.float64), np.asarray(shape, dtype=np.intp), bool(wrap_last),
                 np.ascontiguousarray(flat, dtype=np.intp), out)
    return out
