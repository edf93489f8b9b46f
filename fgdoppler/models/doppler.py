r"""Bistatic Doppler (range-rate) model and its analytic Jacobians.

For a target state :math:`\mathbf x = [\mathbf p', \mathbf v']'` — 2-D
:math:`[x, y, \dot x, \dot y]'` or 3-D :math:`[x, y, z, \dot x, \dot y, \dot z]'`,
the same formulas in either dimension — and a pair with
transmitter :math:`\mathbf t` and receiver :math:`\mathbf r`, the bistatic
Doppler in m/s is the sum of the range rates to Tx and to Rx (paper Eq. 8–10):

.. math::

    h(\mathbf x) = \dot r^T + \dot r^R, \qquad
    \dot r^S = \frac{\Delta\mathbf p_S \cdot \mathbf v}{r_S}, \qquad
    \Delta\mathbf p_S = \mathbf p - \mathbf s,\; r_S = \lVert\Delta\mathbf p_S\rVert .

Its Jacobian (paper Appendix A with :math:`t = 0`):

.. math::

    \frac{\partial h}{\partial \mathbf p} = \sum_{S\in\{T,R\}}
        \frac{r_S\,\mathbf v - \dot r^S\,\Delta\mathbf p_S}{r_S^2},
    \qquad
    \frac{\partial h}{\partial \mathbf v} = \sum_{S\in\{T,R\}} \frac{\Delta\mathbf p_S}{r_S}.

The paper's *batch map* (Section 3; called the constant-velocity map here,
``cv_doppler``) evaluates :math:`h` along a constant-velocity trajectory from
an initial state :math:`\mathbf x_0`:
:math:`g_j(\mathbf x_0) = h_{i_j}(\mathbf p_0 + t_j \mathbf v, \mathbf v)`, with
Jacobian :math:`\partial g/\partial\mathbf p_0 = \partial h/\partial\mathbf p`
and :math:`\partial g/\partial\mathbf v = t_j\,\partial h/\partial\mathbf p + \partial h/\partial\mathbf v`.

A target at a sensor position is a singularity of the model; every public
function raises :class:`ValueError` there rather than return NaN or inf.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.geometry import SENSOR_EPS, Geometry

__all__ = [
    "StackedTimes",
    "bistatic_doppler",
    "bistatic_doppler_and_jacobian",
    "bistatic_doppler_jacobian",
    "cv_doppler",
    "cv_doppler_and_jacobian",
    "cv_doppler_jacobian",
    "cv_information",
]

FloatArray = NDArray[np.float64]


def _as_states(states: ArrayLike) -> FloatArray:
    x = np.asarray(states, dtype=float)
    if x.ndim == 0 or x.shape[-1] not in (4, 6):
        raise ValueError(f"states must have shape (..., 4) = [x, y, vx, vy] or (..., 6) = [x, y, z, vx, vy, vz], "
                         f"got {x.shape}")
    return x


def _singular_error(mask: NDArray[np.bool_]) -> ValueError:
    n = int(np.count_nonzero(mask))
    return ValueError(
        f"{n} target position(s) coincide with a sensor (distance <= {SENSOR_EPS} m): "
        "the bistatic Doppler is undefined there"
    )


def _terms(
    pos: FloatArray,
    vel: FloatArray,
    tx: FloatArray,
    rx: FloatArray,
    *,
    jacobian: bool,
    singular: str = "raise",
) -> tuple[FloatArray, FloatArray | None, FloatArray | None, NDArray[np.bool_] | None]:
    """Doppler and its partial derivatives for broadcastable pos/vel/tx/rx (..., d), d = 2 or 3.

    Returns ``(h, dh_dp, dh_dv, singular_mask)``.  With ``singular="mask"``
    singular entries are evaluated at a harmless placeholder distance and
    reported in the mask instead of raising (used by the grid search, which
    gives such candidates infinite cost).
    """
    dT = pos - tx
    dR = pos - rx
    d = pos.shape[-1]
    rT, rR, pT, pR, bad = _ranges([dT[..., k] for k in range(d)], [dR[..., k] for k in range(d)],
                                  [vel[..., k] for k in range(d)])
    mask = _singular_mask(bad, singular)
    rdT = pT / rT
    rdR = pR / rR
    h = rdT + rdR
    if not jacobian:
        return h, None, None, mask
    uT = dT / rT[..., None]
    uR = dR / rR[..., None]
    # (r v - rdot d) / r^2 = (v - rdot u) / r
    dh_dp = (vel - rdT[..., None] * uT) / rT[..., None] + (vel - rdR[..., None] * uR) / rR[..., None]
    dh_dv = uT + uR
    return h, dh_dp, dh_dv, mask


def _ranges(dT: Sequence[FloatArray], dR: Sequence[FloatArray], v: Sequence[FloatArray]
            ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    r"""The pieces of :math:`h = \Delta\mathbf p_T\cdot\mathbf v/r_T + \Delta\mathbf p_R\cdot\mathbf v/r_R`.

    ``dT``, ``dR`` and ``v`` hold the coordinates of :math:`\Delta\mathbf p_T`,
    :math:`\Delta\mathbf p_R` and :math:`\mathbf v` (broadcastable arrays).
    Returns ``(r_T, r_R, Δp_T·v, Δp_R·v, singular)``, with the distance 1 as
    a placeholder where a target sits on a sensor (``singular``; the caller
    raises or masks).  Explicit component sums in a fixed order: the 3-D model
    at z = 0 is then the 2-D model to the bit, and the compiled loops of
    :mod:`fgdoppler.models.doppler_kernels`, which follow the same order,
    give the same numbers.
    """
    # the sums are this function's own arrays (or scalars, for 0-d input), accumulated in place
    rT2, rR2 = dT[0] * dT[0], dR[0] * dR[0]
    pT, pR = dT[0] * v[0], dR[0] * v[0]
    for a, b, w in zip(dT[1:], dR[1:], v[1:], strict=True):
        rT2 += a * a
        rR2 += b * b
        pT += a * w
        pR += b * w
    rT = np.sqrt(rT2)
    rR = np.sqrt(rR2)
    bad = (rT <= SENSOR_EPS) | (rR <= SENSOR_EPS)
    if np.any(bad):
        rT = np.where(rT <= SENSOR_EPS, 1.0, rT)
        rR = np.where(rR <= SENSOR_EPS, 1.0, rR)
    return rT, rR, pT, pR, bad


def _kernels() -> ModuleType:
    """The compiled loops, imported on first use: numba (and the SciPy it loads) stays out of the command line's
    parser, which reads this module's neighbours for its defaults."""
    from fgdoppler.models import doppler_kernels

    return doppler_kernels


def _along(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray, *, singular: str = "raise"
           ) -> tuple[FloatArray, NDArray[np.bool_] | None]:
    r"""Doppler ``(..., m)`` along constant-velocity tracks: :math:`h(\mathbf p_0 + t_j\mathbf v, \mathbf v)`.

    ``x`` holds the start states ``(..., 2d)``, ``t`` the times ``(m,)``,
    ``tx`` and ``rx`` the sensors of each time ``(m, d)``.  The arithmetic of
    :func:`_terms` (without the Jacobian), compiled
    (:func:`fgdoppler.models.doppler_kernels.along`): the same numbers to the
    bit, several times faster than numpy's pass per operation.
    ``singular`` as in :func:`_terms`; returns ``(h, mask)``.
    """
    h, bad = _kernels().along(x, t, tx, rx)
    return h, _singular_mask(bad, singular)


def _singular_mask(bad: NDArray[np.bool_], singular: str) -> NDArray[np.bool_] | None:
    """``None`` where no track meets a sensor; else the mask, or the error when ``singular`` is ``"raise"``."""
    if not np.any(bad):
        return None
    if singular == "raise":
        raise _singular_error(bad)
    return bad


def bistatic_doppler(states: ArrayLike, geometry: Geometry) -> FloatArray:
    """Bistatic Doppler (m/s) of every state for every pair.

    Parameters
    ----------
    states
        Target states ``[x, y, vx, vy]`` ``(..., 4)`` or ``[x, y, z, vx, vy, vz]`` ``(..., 6)``.
    geometry
        The sensor pairs.

    Returns
    -------
    ndarray, shape ``(..., n_pairs)``

    Raises
    ------
    ValueError
        If a state's position coincides with a sensor.
    """
    x = _as_states(states)[..., None, :]
    d = x.shape[-1] // 2
    h, _, _, _ = _terms(x[..., :d], x[..., d:], *geometry.positions(d), jacobian=False)
    return h


def bistatic_doppler_and_jacobian(
    states: ArrayLike, geometry: Geometry
) -> tuple[FloatArray, FloatArray]:
    """Doppler ``(..., n_pairs)`` and its Jacobian ``(..., n_pairs, 2d)`` in one pass."""
    x = _as_states(states)[..., None, :]
    d = x.shape[-1] // 2
    h, dp, dv, _ = _terms(x[..., :d], x[..., d:], *geometry.positions(d), jacobian=True)
    assert dp is not None and dv is not None
    return h, np.concatenate([dp, dv], axis=-1)


def bistatic_doppler_jacobian(states: ArrayLike, geometry: Geometry) -> FloatArray:
    r"""Analytic Jacobian :math:`\partial h_i/\partial\mathbf x`, shape ``(..., n_pairs, 2d)``."""
    return bistatic_doppler_and_jacobian(states, geometry)[1]


@dataclass(frozen=True, kw_only=True)
class StackedTimes:
    """Times of a stacked measurement vector :math:`\\mathbf Z`, in the paper's order (Eq. 11).

    The paper stacks all of pair 1's measurements, then all of pair 2's
    (Eq. 11).  ``pair[j]`` and ``t[j]`` give the pair index and the time
    (relative to the time of :math:`\\mathbf x_0`) of the ``j``-th entry.
    """

    pair: NDArray[np.intp]
    t: FloatArray

    def __post_init__(self) -> None:
        pair = np.asarray(self.pair, dtype=np.intp).reshape(-1)
        t = np.asarray(self.t, dtype=float).reshape(-1)
        if pair.shape != t.shape:
            raise ValueError(f"pair and t must have the same length, got {pair.size} and {t.size}")
        if not np.all(np.isfinite(t)):
            raise ValueError("measurement times must be finite")
        if np.any(pair < 0):
            raise ValueError("pair indices must be non-negative")
        object.__setattr__(self, "pair", pair)
        object.__setattr__(self, "t", t)

    @classmethod
    def from_per_pair(cls, times: Sequence[ArrayLike]) -> StackedTimes:
        """From one array of times per pair (pair ``i`` gets ``times[i]``)."""
        ts = [np.atleast_1d(np.asarray(t, dtype=float)).reshape(-1) for t in times]
        pair = np.concatenate([np.full(t.size, i, dtype=np.intp) for i, t in enumerate(ts)])
        return cls(pair=pair, t=np.concatenate(ts) if ts else np.zeros(0))

    @property
    def size(self) -> int:
        """Number of measurements :math:`n_Z`."""
        return int(self.t.size)

    def check(self, geometry: Geometry) -> None:
        """Raise if a pair index is out of range for ``geometry``."""
        if self.size and int(self.pair.max()) >= geometry.n_pairs:
            raise ValueError(
                f"pair index {int(self.pair.max())} out of range for a geometry of "
                f"{geometry.n_pairs} pair(s)"
            )


def _stacked_times(times: Sequence[ArrayLike] | StackedTimes, geometry: Geometry) -> StackedTimes:
    bt = times if isinstance(times, StackedTimes) else StackedTimes.from_per_pair(times)
    bt.check(geometry)
    return bt


def _cv(
    x0: ArrayLike,
    geometry: Geometry,
    times: Sequence[ArrayLike] | StackedTimes,
    *,
    jacobian: bool,
    singular: str = "raise",
) -> tuple[FloatArray, FloatArray | None, NDArray[np.bool_] | None]:
    x = _as_states(x0)
    d = x.shape[-1] // 2
    bt = _stacked_times(times, geometry)
    tx, rx = geometry.positions(d)
    return _cv_along(x, bt.t, tx[bt.pair], rx[bt.pair], jacobian=jacobian, singular=singular)


def _cv_along(x: FloatArray, t: FloatArray, tx: FloatArray, rx: FloatArray, *, jacobian: bool,
              singular: str = "raise") -> tuple[FloatArray, FloatArray | None, NDArray[np.bool_] | None]:
    """:func:`_cv` with each measurement's sensors given ``(m, d)``, laid out at every call (the window factor,
    which evaluates one window many times, lays them out once: :class:`~fgdoppler.models.doppler_kernels.Along`)."""
    if not jacobian:
        h, mask = _along(x, t, tx, rx, singular=singular)
        return h, None, mask
    h, jac, bad = _kernels().along_and_jacobian(x, t, tx, rx)
    return h, jac, _singular_mask(bad, singular)


def cv_doppler(
    x0: ArrayLike, geometry: Geometry, times: Sequence[ArrayLike] | StackedTimes
) -> FloatArray:
    r"""The paper's batch map :math:`\mathbf g(\mathbf x_0)`: Doppler along a constant-velocity trajectory.

    Parameters
    ----------
    x0
        Initial states, shape ``(..., 4)`` or ``(..., 6)``; any leading shape is evaluated at once.
    geometry
        The sensor pairs.
    times
        One array of measurement times per pair, relative to the time of
        ``x0`` (pair ``i`` gets ``times[i]``), or a :class:`StackedTimes`.

    Returns
    -------
    ndarray, shape ``(..., n_Z)``
        Predicted Doppler, pair 0's times first (the paper's Eq. 11 order).
    """
    return _cv(x0, geometry, times, jacobian=False)[0]


def cv_doppler_and_jacobian(
    x0: ArrayLike, geometry: Geometry, times: Sequence[ArrayLike] | StackedTimes
) -> tuple[FloatArray, FloatArray]:
    r""":math:`\mathbf g(\mathbf x_0)` ``(..., n_Z)`` and :math:`\mathbf J(\mathbf x_0)` ``(..., n_Z, 2d)``."""
    g, jac, _ = _cv(x0, geometry, times, jacobian=True)
    assert jac is not None
    return g, jac


def cv_doppler_jacobian(
    x0: ArrayLike, geometry: Geometry, times: Sequence[ArrayLike] | StackedTimes
) -> FloatArray:
    r"""The paper's Jacobian :math:`\mathbf J(\mathbf x_0) = \partial\mathbf g/\partial\mathbf x_0` (Eq. 15, Appendix A).

    Returns
    -------
    ndarray, shape ``(..., n_Z, 2d)``
    """
    return cv_doppler_and_jacobian(x0, geometry, times)[1]


def cv_information(
    x0: ArrayLike, geometry: Geometry, times: Sequence[ArrayLike] | StackedTimes, sigma: ArrayLike
) -> FloatArray:
    r"""Fisher information of :math:`\mathbf x_0` from a stacked window: :math:`\mathbf J'\mathbf R^{-1}\mathbf J`.

    :math:`\mathbf R = \mathrm{diag}(\sigma_j^2)`, :math:`\mathbf J` the constant-velocity map's
    Jacobian (:func:`cv_doppler_jacobian`).

    Returns
    -------
    ndarray, shape ``(..., 2d, 2d)``
    """
    Jw = cv_doppler_jacobian(x0, geometry, times) / np.asarray(sigma, dtype=float)[:, None]
    return np.swapaxes(Jw, -1, -2) @ Jw
