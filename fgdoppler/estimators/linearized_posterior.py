r"""The posterior of the data so far, linearised about a whole-recording track: a filter's covariance where sampling cannot go.

A filter linearises each measurement once, at its own prediction.  On a
poorly observed track that prediction can be kilometres off, and the
information the update adds points the wrong way: over minutes the filter's
covariance shrinks below what the data allow (on the paper's pairs, 600 s
from (20 km, 3 km) at (30, −40) m/s, 12 recordings per case with the
model's own process noise: the EKF's run-averaged NEES 9.2 and 9.0 in
4 dimensions, iSAM2's 6.0 and 6.5, while the offline smoother's is 4.7
and 3.1; ``docs/concepts.md``, "Long recordings").  The posterior samples of
:mod:`fgdoppler.estimators.spread` correct this over the first minutes, but
they move the state deterministically and stop where the process noise
matters.

Beyond that point this module gives the Gaussian posterior of the state at
each time given the measurements up to it, linearised about a reference
track :math:`\bar{\mathbf x}(t)` — the offline smoother's, which uses the
whole recording and lies closer to the truth than any filter's estimate —
instead of about the filter's own predictions.  It is the Kalman filter of
the linearised model

.. math::

    z_j = h(\bar{\mathbf x}_j) + \mathbf H(\bar{\mathbf x}_j)(\mathbf x_j - \bar{\mathbf x}_j) + e_j,
    \qquad e_j \sim \mathcal N(0, \sigma_j^2/w_j),

with the constant-velocity prediction
:math:`\mathbf x^- = \mathbf F\mathbf x`, :math:`\mathbf P^- = \mathbf F\mathbf P\mathbf F^\top + \mathbf Q`,
one vector update per scan,

.. math::

    \mathbf S = \mathbf A\mathbf P^-\mathbf A^\top + \mathbf I,\quad
    \mathbf K = \mathbf P^-\mathbf A^\top\mathbf S^{-1},\quad
    \mathbf x = \mathbf x^- + \mathbf K\big(\mathbf b + \mathbf A(\bar{\mathbf x} - \mathbf x^-)\big),

in whitened rows :math:`\mathbf A = \sqrt{w}\,\mathbf H/\sigma`,
:math:`\mathbf b = \sqrt{w}\,(z - h(\bar{\mathbf x}))/\sigma`
(:func:`~fgdoppler.estimators.linearized.linearize_rows`; :math:`w` the
Huber weight of the residual at the reference, 1 for the Gaussian loss) and
the Joseph form for :math:`\mathbf P`.  Its mean and covariance at
:math:`t_k` read only the measurements up to :math:`t_k`; the reference
track only sets where the measurement model is linearised — a Gauss–Newton
information evaluated near the truth rather than at the filter's guess.
The posterior mean-square error of a filter's estimate
:math:`\hat{\mathbf x}_k` is then
:math:`\mathbf S_k = \mathbf P_k + (\hat{\mathbf x}_k - \mathbf x_k)(\hat{\mathbf x}_k - \mathbf x_k)^\top`
(:func:`mean_square_errors`), which
:func:`~fgdoppler.estimators.spread.filtered_spread` encloses where its
samples cannot reach.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.linearized import linearize_rows
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel

__all__ = ["linearized_filter", "mean_square_errors"]

FloatArray = NDArray[np.float64]


def linearized_filter(measurements: Measurements, model: TrackingModel, ref_times: FloatArray,
                      ref_states: FloatArray, t_start: float, x: FloatArray, P: FloatArray,
                      huber_k: float | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
    r"""The Kalman filter of the module docstring from ``(x, P)`` at ``t_start`` over the later scans.

    Parameters
    ----------
    measurements
        The measurements to read (those at or before ``t_start`` are not).
    model
        Observation and motion model.
    ref_times, ref_states
        The reference track ``(r,)``, ``(r, 2d)`` (time-ordered) the measurements are linearised about.
    t_start, x, P
        The starting time, mean ``(2d,)`` and covariance ``(2d, 2d)``.
    huber_k
        Huber threshold of the likelihood (``None``: Gaussian).

    Returns
    -------
    times, means, covariances
        ``(n,)``, ``(n, 2d)``, ``(n, 2d, 2d)``: after each scan later than ``t_start``.

    Raises
    ------
    ValueError
        From the measurement model, for a reference state on a sensor.
    """
    later = measurements.subset(measurements.time > t_start)
    scans = later.scans()
    n = scans.times.size
    d = model.n
    means, covs = np.empty((n, d)), np.empty((n, d, d))
    if n == 0:
        return scans.times.astype(float), means, covs
    at = model.motion.along(ref_times, ref_states, later.time)
    rows = linearize_rows(model.observation, at, later.pair, later.doppler, later.sigma, huber_k)
    x, P = np.array(x, dtype=float), np.array(P, dtype=float)
    eye = np.eye(d)
    t_prev = float(t_start)
    for k, t in enumerate(scans.times):
        dt = float(t) - t_prev
        F = model.motion.F(dt)
        x = F @ x
        P = F @ P @ F.T + model.motion.Q(dt)
        t_prev = float(t)
        a, b = scans.bounds[k], scans.bounds[k + 1]
        A = rows.A[a:b]
        innovation = rows.b[a:b] + A @ (at[a] - x)
        S = A @ P @ A.T + np.eye(b - a)
        K = np.linalg.solve(S, A @ P).T
        x = x + K @ innovation
        IKA = eye - K @ A
        P = IKA @ P @ IKA.T + K @ K.T
        P = 0.5 * (P + P.T)
        means[k], covs[k] = x, P
    return scans.times.astype(float), means, covs


def mean_square_errors(estimates: FloatArray, means: FloatArray, covariances: FloatArray) -> FloatArray:
    r""":math:`\mathbf P_k + \mathbf d_k\mathbf d_k^\top`, :math:`\mathbf d_k = \hat{\mathbf x}_k - \mathbf x_k`:
    the posterior mean-square error of estimates ``(n, 2d)`` under Gaussian posteriors ``(means, covariances)``."""
    diff = np.asarray(estimates, dtype=float) - means
    return np.asarray(covariances + diff[:, :, None] * diff[:, None, :], dtype=float)
