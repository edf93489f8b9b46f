r"""Cramér–Rao bounds for Doppler-only tracking.

Deterministic constant velocity (the paper's truth): the whole trajectory is
a function of :math:`\mathbf x_0`, whose Fisher information from the
measurements up to time :math:`t` is
:math:`\mathbf J_0(t) = \sum_{t_j \le t} \mathbf g_j'\mathbf g_j / \sigma_j^2`
(rows of the paper's batch Jacobian).  The bound on the state at time
:math:`t` is :math:`\mathbf F(t)\mathbf J_0^{-1}\mathbf F(t)'` — *filtering*
with the data up to :math:`t`, *smoothing* with all data.

With process noise, the posterior CRLB for filtering follows Tichavský,
Muravchik & Nehorai (1998):

.. math::

    \mathbf J_{k+1} = \mathbf D^{22}_k - \mathbf D^{21}_k(\mathbf J_k + \mathbf D^{11}_k)^{-1}\mathbf D^{12}_k,

    \mathbf D^{11} = \mathbf F'\mathbf Q^{-1}\mathbf F,\quad
    \mathbf D^{12} = -\mathbf F'\mathbf Q^{-1},\quad
    \mathbf D^{22} = \mathbf Q^{-1} + \mathbf H_{k+1}'\mathbf R^{-1}\mathbf H_{k+1},

with the Jacobians evaluated on the true trajectory; the smoothing PCRLB is
the marginal covariance of the graph linearised at the truth
(:func:`fgdoppler.analysis.observability.observability_report`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import StackedTimes, cv_doppler_jacobian
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import MeasurementModel
from fgdoppler.simulation import Trajectory

__all__ = ["crlb_deterministic", "pcrlb_filter"]

FloatArray = NDArray[np.float64]


def _inv_or_nan(info: FloatArray) -> FloatArray:
    out = np.full_like(info, np.nan)
    for i, A in enumerate(info):
        s = np.linalg.svd(A, compute_uv=False)
        if s[-1] > s[0] * 1e-15:
            out[i] = np.linalg.inv(A)
    return out


def crlb_deterministic(
    geometry: Geometry,
    x0: ArrayLike,
    measurements: Measurements,
    times: ArrayLike,
    *,
    t0: float = 0.0,
    smoothing: bool = False,
    prior_information: ArrayLike | None = None,
) -> FloatArray:
    """CRLB ``(n, 2d, 2d)`` of the state at ``times`` for a constant-velocity target starting at ``x0``.

    Parameters
    ----------
    geometry, x0
        Sensors and the true initial state (at ``t0``).
    measurements
        Times, pairs and sigmas of the data (values unused).
    times
        Where to evaluate the bound.
    smoothing
        Use all measurements (smoothing) instead of those up to each time.
    prior_information
        Optional information matrix on ``x0`` added to the data's.

    Returns
    -------
    ndarray
        NaN where the information is still singular (too few measurements).
    """
    t = np.asarray(times, dtype=float)
    bt = StackedTimes(pair=measurements.pair, t=measurements.time - t0)
    J = cv_doppler_jacobian(np.asarray(x0, dtype=float), geometry, bt) / measurements.sigma[:, None]
    outer = np.einsum("ji,jk->jik", J, J)
    cum = np.cumsum(outer, axis=0)
    if smoothing:
        info = np.broadcast_to(cum[-1], (t.size, *cum.shape[1:])).copy()
    else:
        idx = np.searchsorted(measurements.time, t, side="right") - 1
        info = np.where(idx[:, None, None] >= 0, cum[np.clip(idx, 0, None)], 0.0)
    if prior_information is not None:
        info = info + np.asarray(prior_information, dtype=float)
    P0 = _inv_or_nan(info)
    F = ConstantVelocity(dim=J.shape[-1] // 2).F(t - t0)
    return F @ P0 @ np.swapaxes(F, -1, -2)


def pcrlb_filter(
    model: MeasurementModel,
    truth: Trajectory,
    measurements: Measurements,
    motion: ConstantVelocity,
    J0: ArrayLike,
    t0: float,
) -> tuple[FloatArray, FloatArray]:
    """Filtering posterior CRLB by Tichavský's recursion, from information ``J0`` at ``t0``.

    Returns the scan times after ``t0`` and the bound ``(n, 2d, 2d)`` after
    each scan (all measurements of a scan together).
    """
    m = measurements.subset(measurements.time > t0)
    times, scan = m.scans().times, m.scans().scan_of
    J = np.asarray(J0, dtype=float)
    t_prev = t0
    out = np.empty((times.size, *J.shape))
    states = truth.at(times)
    _, H_all = model.predict_and_jacobian(states[scan], m.pair)
    Rinv = 1.0 / m.sigma**2
    for k, t in enumerate(times):
        dt = t - t_prev
        F = motion.F(dt)
        Qi = np.linalg.inv(motion.Q(dt))
        D11 = F.T @ Qi @ F
        D12 = -F.T @ Qi
        rows = scan == k
        Hk = H_all[rows]
        D22 = Qi + Hk.T @ (Hk * Rinv[rows, None])
        J = D22 - D12.T @ np.linalg.solve(J + D11, D12)
        out[k] = np.linalg.inv(J)
        t_prev = t
    return times, out
