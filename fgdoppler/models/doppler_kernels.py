r"""Compiled loops of the bistatic Doppler along constant-velocity tracks (numba).

The hot paths of the library — the particles' likelihoods, the restart and
mistake checks' predictions, the initiation's window factor — evaluate

.. math::

    h_{ij} = \frac{\Delta\mathbf p_{T,ij}\cdot\mathbf v_i}{r_{T,ij}}
           + \frac{\Delta\mathbf p_{R,ij}\cdot\mathbf v_i}{r_{R,ij}},
    \qquad \Delta\mathbf p_{S,ij} = \mathbf p_{0,i} + t_j\mathbf v_i - \mathbf s_j,

for many tracks :math:`i` and measurements :math:`j`, and the window factor
also its Jacobian with respect to the start state,

.. math::

    \frac{\partial h_{ij}}{\partial\mathbf p_0} = \mathbf a_{ij} = \sum_{S}
        \frac{\mathbf v_i - \dot r^S_{ij}\,\mathbf u_{S,ij}}{r_{S,ij}},
    \qquad
    \frac{\partial h_{ij}}{\partial\mathbf v} = t_j\,\mathbf a_{ij} + \sum_S \mathbf u_{S,ij},

with :math:`\mathbf u_S = \Delta\mathbf p_S / r_S` and
:math:`\dot r^S = \Delta\mathbf p_S\cdot\mathbf v / r_S`.  In numpy each of
the dozen operations is a pass over a temporary array, and for the small
windows of the factors the per-call overhead is several times the
arithmetic; here every entry is computed in one pass.

The operations are those of :func:`fgdoppler.models.doppler._terms` in the
same order (component sums :math:`x` first, the placeholder distance 1 on a
sensor), and numba compiles without fast-math (no reassociation, no fused
multiply-add), so the numbers are the numpy model's to the bit
(``tests/models/test_doppler.py``).  Compiled code is cached on disk
beside this module (numba's ``cache=True``), so only the first process after
an install pays the compilation.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from fgdoppler.geometry import SENSOR_EPS

__all__ = ["Along", "along", "along_and_jacobian"]

FloatArray = NDArray[np.float64]


# The two loops below are written out per dimension, with the sensors' coordinates as contiguous rows and the
# singular entries only counted: so written, the compiler turns them into vector instructions (about twice as
# fast as one loop over the coordinates); the rare singular entries are then flagged by a second pass.
@njit(cache=True, error_model="numpy")
def _along_plane(x: FloatArray, t: FloatArray, s: FloatArray, h: FloatArray) -> int:  # pragma: no cover - compiled
    tx0, tx1, rx0, rx1 = s[0], s[1], s[2], s[3]
    singular = 0
    for i in range(x.shape[0]):
        px, py, vx, vy = x[i, 0], x[i, 1], x[i, 2], x[i, 3]
        hi = h[i]
        for j in range(t.size):
            qx = t[j] * vx + px
            qy = t[j] * vy + py
            ax, ay = qx - tx0[j], qy - tx1[j]
            bx, by = qx - rx0[j], qy - rx1[j]
            rT = np.sqrt(ax * ax + ay * ay)
            rR = np.sqrt(bx * bx + by * by)
            singular += (rT <= SENSOR_EPS) | (rR <= SENSOR_EPS)
            rT = 1.0 if rT <= SENSOR_EPS else rT
            rR = 1.0 if rR <= SENSOR_EPS else rR
            hi[j] = (ax * vx + ay * vy) / rT + (bx * vx + by * vy) / rR
    return singular


@njit(cache=True, error_model="numpy")
def _along_space(x: FloatArray, t: FloatArray, s: FloatArray, h: FloatArray) -> int:  # pragma: no cover - compiled
    tx0, tx1, tx2, rx0, rx1, rx2 = s[0], s[1], s[2], s[3], s[4], s[5]
    singular = 0
    for i in range(x.shape[0]):
        px, py, pz, vx, vy, vz = x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5]
        hi = h[i]
        for j in range(t.size):
            qx = t[j] * vx + px
            qy = t[j] * vy + py
            qz = t[j] * vz + pz
            ax, ay, az = qx - tx0[j], qy - tx1[j], qz - tx2[j]
            bx, by, bz = qx - rx0[j], qy - rx1[j], qz - rx2[j]
            rT = np.sqrt(ax * ax + ay * ay + az * az)
            rR = np.sqrt(bx * bx + by * by + bz * bz)
            singular += (rT <= SENSOR_EPS) | (rR <= SENSOR_EPS)
            rT = 1.0 if rT <= SENSOR_EPS else rT
            rR = 1.0 if rR <= SENSOR_EPS else rR
            hi[j] = (ax * vx + ay * vy + az * vz) / rT + (bx * vx + by * vy + bz * vz) / rR
    return singular


@njit(cache=True, error_model="numpy")
def _singular_flags(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray,
                    bad: NDArray[np.bool_]) -> None:  # pragma: no cover - compiled
    # the distances of the loops above, in the same order (a sum of squares from 0.0 is exact)
    d = x.shape[1] // 2
    for i in range(x.shape[0]):
        for j in range(t.size):
            rT2 = 0.0
            rR2 = 0.0
            for k in range(d):
                p = t[j] * x[i, d + k] + x[i, k]
                a = p - tx[j, k]
                b = p - rx[j, k]
                rT2 += a * a
                rR2 += b * b
            bad[i, j] = (np.sqrt(rT2) <= SENSOR_EPS) | (np.sqrt(rR2) <= SENSOR_EPS)


@njit(cache=True, error_model="numpy")
def _jacobian_loop(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray, h: FloatArray,
                   jac: FloatArray, bad: NDArray[np.bool_]) -> None:  # pragma: no cover - compiled
    d = x.shape[1] // 2
    a = np.empty(d)
    b = np.empty(d)
    for i in range(x.shape[0]):
        for j in range(t.shape[0]):
            rT2 = 0.0
            rR2 = 0.0
            pT = 0.0
            pR = 0.0
            for k in range(d):
                v = x[i, d + k]
                p = x[i, k] + t[j] * v
                a[k] = p - tx[j, k]
                b[k] = p - rx[j, k]
                if k == 0:
                    rT2 = a[k] * a[k]
                    rR2 = b[k] * b[k]
                    pT = a[k] * v
                    pR = b[k] * v
                else:
                    rT2 += a[k] * a[k]
                    rR2 += b[k] * b[k]
                    pT += a[k] * v
                    pR += b[k] * v
            rT = np.sqrt(rT2)
            rR = np.sqrt(rR2)
            if rT <= SENSOR_EPS or rR <= SENSOR_EPS:
                bad[i, j] = True
                if rT <= SENSOR_EPS:
                    rT = 1.0
                if rR <= SENSOR_EPS:
                    rR = 1.0
            rdT = pT / rT
            rdR = pR / rR
            h[i, j] = rdT + rdR
            for k in range(d):
                v = x[i, d + k]
                uT = a[k] / rT
                uR = b[k] / rR
                dp = (v - rdT * uT) / rT + (v - rdR * uR) / rR
                jac[i, j, k] = dp
                jac[i, j, d + k] = t[j] * dp + (uT + uR)


def _sensors(t: FloatArray, tx: FloatArray, rx: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The times and each measurement's sensors, checked and contiguous."""
    # the loops do not check their indices: sensors of another dimension, or fewer of them than times, would be
    # read out of bounds
    if rx.shape[-1] != tx.shape[-1]:
        raise ValueError(f"transmitters of {tx.shape[-1]} coordinates need receivers of as many, got {rx.shape[-1]}")
    if not len(tx) == len(rx) == np.size(t):
        raise ValueError(f"{np.size(t)} times need as many transmitters and receivers, got {len(tx)} and {len(rx)}")
    return (np.ascontiguousarray(t, dtype=np.float64), np.ascontiguousarray(tx, dtype=np.float64),
            np.ascontiguousarray(rx, dtype=np.float64))


def _rows(tx: FloatArray, rx: FloatArray) -> FloatArray:
    """The sensors' coordinates as contiguous rows ``(2d, m)``, as the Doppler loops read them."""
    d = tx.shape[1]
    rows = np.empty((2 * d, tx.shape[0]))
    rows[:d], rows[d:] = tx.T, rx.T
    return rows


def _tracks(x: FloatArray, n: int) -> FloatArray:
    """Start states ``(..., n)`` as contiguous rows ``(k, n)``; ``n`` is twice the sensors' dimension."""
    if x.shape[-1] != n:
        raise ValueError(f"states of {x.shape[-1]} numbers need sensors of {x.shape[-1] // 2} coordinates, "
                         f"got {n // 2}")
    return np.ascontiguousarray(x, dtype=np.float64).reshape(-1, n)


def _doppler(flat: FloatArray, t: FloatArray, rows: FloatArray, tx: FloatArray, rx: FloatArray
             ) -> tuple[FloatArray, NDArray[np.bool_], bool]:
    """Doppler ``(k, m)`` of the tracks ``flat``, where a track meets a sensor, and whether any does."""
    h = np.empty((flat.shape[0], t.size))
    bad = np.zeros(h.shape, dtype=np.bool_)
    singular = bool((_along_plane if flat.shape[1] == 4 else _along_space)(flat, t, rows, h))
    if singular:
        _singular_flags(flat, t, tx, rx, bad)
    return h, bad, singular


def _doppler_and_jacobian(flat: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray
                          ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """:func:`_doppler` and the Jacobian ``(k, m, 2d)`` with respect to each start state."""
    h = np.empty((flat.shape[0], t.size))
    jac = np.empty((flat.shape[0], t.size, flat.shape[1]))
    bad = np.zeros(h.shape, dtype=np.bool_)
    _jacobian_loop(flat, t, tx, rx, h, jac, bad)
    return h, jac, bad


def along(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray
          ) -> tuple[FloatArray, NDArray[np.bool_]]:
    r"""Doppler of constant-velocity tracks at the measurements' times.

    Parameters
    ----------
    x : ndarray, shape ``(..., 2d)``
        Start states :math:`[\mathbf p_0', \mathbf v']'` of the tracks (``d`` = 2 or 3).
    t : ndarray, shape ``(m,)``
        Times relative to the start.
    tx, rx : ndarray, shape ``(m, d)``
        The transmitter and receiver of each measurement.

    Returns
    -------
    h : ndarray, shape ``(..., m)``
        :math:`h_{ij}`; where a track meets a sensor, the value with the placeholder distance 1.
    singular : ndarray of bool, shape ``(..., m)``
        Where a track meets a sensor (within :data:`fgdoppler.geometry.SENSOR_EPS`).
    """
    t, tx, rx = _sensors(t, tx, rx)
    h, bad, _ = _doppler(_tracks(x, 2 * tx.shape[1]), t, _rows(tx, rx), tx, rx)
    lead = x.shape[:-1]
    return h.reshape(*lead, t.size), bad.reshape(*lead, t.size)


def along_and_jacobian(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray
                       ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    r""":func:`along` and the Jacobian of each Doppler with respect to its track's start state.

    Returns
    -------
    h : ndarray, shape ``(..., m)``
    jacobian : ndarray, shape ``(..., m, 2d)``
        :math:`[\partial h_{ij}/\partial\mathbf p_0, \partial h_{ij}/\partial\mathbf v]`.
    singular : ndarray of bool, shape ``(..., m)``
    """
    t, tx, rx = _sensors(t, tx, rx)
    n = 2 * tx.shape[1]
    h, jac, bad = _doppler_and_jacobian(_tracks(x, n), t, tx, rx)
    lead = x.shape[:-1]
    return h.reshape(*lead, t.size), jac.reshape(*lead, t.size, n), bad.reshape(*lead, t.size)


class Along:
    r""":func:`along` and :func:`along_and_jacobian` of one start state at fixed times and sensors.

    For the window factor, which evaluates the same window at every step of
    Levenberg–Marquardt: the times and sensors are checked and laid out once
    here, where :func:`along` does so at every call (for a window of 20
    measurements that took most of its time).  The same loops on the same
    arrays: their numbers to the bit.

    Parameters
    ----------
    t : ndarray, shape ``(m,)``
        Times relative to the start.
    tx, rx : ndarray, shape ``(m, d)``
        The transmitter and receiver of each measurement.
    """

    __slots__ = ("_rows", "_rx", "_t", "_tx")

    def __init__(self, t: FloatArray, tx: FloatArray, rx: FloatArray) -> None:
        self._t, self._tx, self._rx = _sensors(t, tx, rx)
        self._rows = _rows(self._tx, self._rx)

    @property
    def state_size(self) -> int:
        """``2d``: the length of the start states it takes."""
        return self._rows.shape[0]

    def __call__(self, x: FloatArray, *, jacobian: bool
                 ) -> tuple[FloatArray, FloatArray | None, NDArray[np.bool_] | None]:
        """Doppler ``(m,)`` of the track from ``x`` ``(2d,)``, with ``jacobian`` its Jacobian ``(m, 2d)``, and
        where the track meets a sensor (``None`` where it meets none)."""
        n = self._rows.shape[0]
        if x.shape != (n,):
            raise ValueError(f"a window of {n // 2}-D sensors takes a start state of {n} numbers, got {x.shape}")
        flat = np.ascontiguousarray(x, dtype=np.float64).reshape(1, n)
        if jacobian:
            h, jac, bad = _doppler_and_jacobian(flat, self._t, self._tx, self._rx)
            return h[0], jac[0], bad[0] if bad.any() else None
        h, bad, singular = _doppler(flat, self._t, self._rows, self._tx, self._rx)
        return h[0], None, bad[0] if singular else None
