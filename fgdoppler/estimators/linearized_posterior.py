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

A fixed-lag smoother's estimate of the state at :math:`t` has read the
data up to :math:`t + \ell`; its posterior is the Rauch–Tung–Striebel
smoother of the same linearised model run back from the last scan at or
before :math:`t + \ell` (:meth:`LinearizedPosterior.at` with
``horizons``): with the filtered :math:`(\mathbf x_i, \mathbf P_i)` and
predicted :math:`(\mathbf x^-_{i+1}, \mathbf P^-_{i+1})` moments,

.. math::

    \mathbf G_i = \mathbf P_i\mathbf F_{i+1}^\top(\mathbf P^-_{i+1})^{-1},\quad
    \mathbf x^s_i = \mathbf x_i + \mathbf G_i(\mathbf x^s_{i+1} - \mathbf x^-_{i+1}),\quad
    \mathbf P^s_i = \mathbf P_i + \mathbf G_i(\mathbf P^s_{i+1} - \mathbf P^-_{i+1})\mathbf G_i^\top,

the last step to a time between two scans taken the same way from the
prediction to it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._text import time_text
from fgdoppler.estimators.linearized import linearize_rows
from fgdoppler.measurements import Measurements
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.tracking import TrackingModel

__all__ = ["LinearizedPosterior", "linearized_filter", "mean_square_errors"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class LinearizedPosterior:
    r"""The linearised Kalman filter's moments at its start and after each later scan (:func:`linearized_filter`).

    Parameters
    ----------
    times
        ``(n + 1,)``: the start, then every later scan.
    means, covariances
        ``(n + 1, 2d)``, ``(n + 1, 2d, 2d)``: the filtered moments (at the start, the starting ones).
    predicted_means, predicted_covariances
        The same before each scan's update (at the start, the starting ones).
    gains
        ``(n + 1, 2d, 2d)``: the smoother gains :math:`\mathbf G_i` from each entry back from the next (the
        last: zero).
    motion
        The motion model of the prediction.
    """

    times: FloatArray
    means: FloatArray
    covariances: FloatArray
    predicted_means: FloatArray
    predicted_covariances: FloatArray
    gains: FloatArray
    motion: ConstantVelocity

    def at(self, times: ArrayLike, horizons: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        r"""The posterior of the state at each of ``times`` given the scans up to its horizon.

        Parameters
        ----------
        times
            ``(m,)``, none before the start.
        horizons
            ``(m,)``, each at or after its time (``None``: the times themselves, the filter's posterior of
            the data so far): the scans read are those at or before it.

        Returns
        -------
        means, covariances
            ``(m, 2d)``, ``(m, 2d, 2d)``: the filtered moments carried to each time where no scan falls
            between it and its horizon, the smoothed ones (module docstring) elsewhere.

        Raises
        ------
        ValueError
            For a time before the start or a horizon before its time.
        """
        t = np.atleast_1d(np.asarray(times, dtype=float))
        h = t if horizons is None else np.broadcast_to(np.asarray(horizons, dtype=float), t.shape)
        if np.any(~(t >= self.times[0])):
            raise ValueError(f"times must not be before the start {time_text(self.times[0])} s")
        if np.any(~(h >= t)):
            raise ValueError("each horizon must be at or after its time")
        j = np.searchsorted(self.times, t, side="right") - 1  # the last entry at or before each time
        e = np.searchsorted(self.times, h, side="right") - 1  # the last scan read
        xs, Ps = self.means[e].copy(), self.covariances[e].copy()
        cur = e.copy()
        while np.any(back := cur > j + 1):  # smoothed back to the first scan after each time
            i = cur[back] - 1
            xs[back], Ps[back] = _rts_step(self.means[i], self.covariances[i], self.gains[i], xs[back], Ps[back],
                                           self.predicted_means[i + 1], self.predicted_covariances[i + 1])
            cur[back] -= 1
        dt = t - self.times[j]
        F = self.motion.F(dt)
        means = np.einsum("kab,kb->ka", F, self.means[j])
        covs = F @ self.covariances[j] @ np.swapaxes(F, 1, 2) + self.motion.Q(dt)
        later = e > j
        if np.any(later):  # the last step, from the first scan after the time back to it
            F2 = self.motion.F(self.times[j[later] + 1] - t[later])
            x_pred = np.einsum("kab,kb->ka", F2, means[later])
            P_pred = F2 @ covs[later] @ np.swapaxes(F2, 1, 2) + self.motion.Q(self.times[j[later] + 1] - t[later])
            G = _rts_gains(covs[later], F2, P_pred)
            means[later], covs[later] = _rts_step(means[later], covs[later], G, xs[later], Ps[later], x_pred, P_pred)
        return means, 0.5 * (covs + np.swapaxes(covs, 1, 2))


def linearized_filter(measurements: Measurements, model: TrackingModel, ref_times: FloatArray,
                      ref_states: FloatArray, t_start: float, x: FloatArray, P: FloatArray,
                      huber_k: float | None = None) -> LinearizedPosterior:
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
    LinearizedPosterior
        The moments at ``t_start`` and after each later scan, with the smoother gains.

    Raises
    ------
    ValueError
        From the measurement model, for a reference state on a sensor.
    numpy.linalg.LinAlgError
        Where a predicted covariance is singular (no smoother gain).
    """
    later = measurements.subset(measurements.time > t_start)
    scans = later.scans()
    n = scans.times.size
    d = model.n
    x, P = np.array(x, dtype=float), np.array(P, dtype=float)
    means, covs = np.empty((n + 1, d)), np.empty((n + 1, d, d))
    pred_means, pred_covs = np.empty((n + 1, d)), np.empty((n + 1, d, d))
    means[0], covs[0], pred_means[0], pred_covs[0] = x, P, x, P
    times = np.concatenate([[float(t_start)], scans.times.astype(float)])
    at = model.motion.along(ref_times, ref_states, later.time)
    rows = linearize_rows(model.observation, at, later.pair, later.doppler, later.sigma, huber_k)
    eye = np.eye(d)
    for k in range(1, n + 1):
        dt = times[k] - times[k - 1]
        F = model.motion.F(dt)
        x = F @ x
        P = F @ P @ F.T + model.motion.Q(dt)
        pred_means[k], pred_covs[k] = x, P
        a, b = scans.bounds[k - 1], scans.bounds[k]
        A = rows.A[a:b]
        innovation = rows.b[a:b] + A @ (at[a] - x)
        S = A @ P @ A.T + np.eye(b - a)
        K = np.linalg.solve(S, A @ P).T
        x = x + K @ innovation
        IKA = eye - K @ A
        P = IKA @ P @ IKA.T + K @ K.T
        P = 0.5 * (P + P.T)
        means[k], covs[k] = x, P
    gains = np.zeros((n + 1, d, d))
    if n:
        gains[:-1] = _rts_gains(covs[:-1], model.motion.F(np.diff(times)), pred_covs[1:])
    return LinearizedPosterior(times=times, means=means, covariances=covs, predicted_means=pred_means,
                               predicted_covariances=pred_covs, gains=gains, motion=model.motion)


def _rts_gains(P: FloatArray, F: FloatArray, P_pred: FloatArray) -> FloatArray:
    r"""Smoother gains :math:`\mathbf G = \mathbf P\mathbf F^\top(\mathbf P^-)^{-1}`, stacked ``(k, 2d, 2d)``
    (as :math:`((\mathbf P^-)^{-1}\mathbf F\mathbf P)^\top`, both covariances symmetric)."""
    return np.asarray(np.swapaxes(np.linalg.solve(P_pred, F @ P), 1, 2), dtype=float)


def _rts_step(x: FloatArray, P: FloatArray, G: FloatArray, x_next: FloatArray, P_next: FloatArray,
              x_pred: FloatArray, P_pred: FloatArray) -> tuple[FloatArray, FloatArray]:
    r"""One stacked Rauch–Tung–Striebel step back: :math:`\mathbf x + \mathbf G(\mathbf x^s - \mathbf x^-)`,
    :math:`\mathbf P + \mathbf G(\mathbf P^s - \mathbf P^-)\mathbf G^\top`."""
    return (x + np.einsum("kab,kb->ka", G, x_next - x_pred),
            P + G @ (P_next - P_pred) @ np.swapaxes(G, 1, 2))


def mean_square_errors(estimates: FloatArray, means: FloatArray, covariances: FloatArray) -> FloatArray:
    r""":math:`\mathbf P_k + \mathbf d_k\mathbf d_k^\top`, :math:`\mathbf d_k = \hat{\mathbf x}_k - \mathbf x_k`:
    the posterior mean-square error of estimates ``(n, 2d)`` under Gaussian posteriors ``(means, covariances)``."""
    diff = np.asarray(estimates, dtype=float) - means
    return np.asarray(covariances + diff[:, :, None] * diff[:, None, :], dtype=float)
