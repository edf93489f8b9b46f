r"""Extended Kalman filter: the paper's dynamic estimator and the baseline of the smoothers.

Prediction with the shared NCV model,
:math:`\mathbf x^- = \mathbf F\mathbf x`, :math:`\mathbf P^- = \mathbf F\mathbf P\mathbf F' + \mathbf Q`;
then one *scalar* update per measurement in time order (so asynchronous pairs
need nothing special):

.. math::

    S = \mathbf H\mathbf P^-\mathbf H' + \sigma^2,\quad
    \mathbf K = \mathbf P^-\mathbf H'/S,\quad
    \mathbf x = \mathbf x^- + \mathbf K\,(z - h(\mathbf x^-)),

    \mathbf P = (\mathbf I - \mathbf K\mathbf H)\mathbf P^-(\mathbf I - \mathbf K\mathbf H)' + \mathbf K\sigma^2\mathbf K'
    \quad\text{(Joseph form)}.

The normalised innovation :math:`\mathrm{NIS} = (z - h)^2/S` is recorded for
every measurement; above the gate the measurement is rejected and reported.
A non-finite or non-positive :math:`S`, or a covariance that stops being
positive definite, skips the update with a warning instead of propagating
garbage.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.common import TrackerSettings, check_model, split_window
from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.measurements import Measurements
from fgdoppler.models.measurement import MeasurementModel

__all__ = ["ExtendedKalmanFilter", "run_ekf"]

FloatArray = NDArray[np.float64]
_EYE4 = np.eye(4)
_EYE4.setflags(write=False)


class ExtendedKalmanFilter:
    """Streaming EKF.

    Parameters
    ----------
    model
        Measurement model (e.g. :class:`~fgdoppler.models.measurement.DopplerModel`).
    x0, P0, t0
        Initial state, covariance and time.
    settings
        Motion model and gate.
    """

    def __init__(self, model: MeasurementModel, x0: ArrayLike, P0: ArrayLike, t0: float,
                 settings: TrackerSettings | None = None) -> None:
        self.model = model
        self.settings = settings or TrackerSettings()
        self.x = np.array(x0, dtype=float).reshape(4)
        self.P = np.array(P0, dtype=float).reshape(4, 4)
        if not (np.all(np.isfinite(self.x)) and np.all(np.isfinite(self.P))):
            raise ValueError("initial state and covariance must be finite")
        self.t = float(t0)
        self._gate = self.settings.gate
        self._FQ: dict[float, tuple[FloatArray, FloatArray]] = {}
        self.nis: list[tuple[float, int, float, bool]] = []
        self.warnings: list[tuple[float, str]] = []
        #: Cumulative predictive log-likelihood of all measurements (gated ones
        #: included), sum of -0.5 (log(2 pi S) + NIS).
        self.log_likelihood = 0.0

    def predict(self, t: float) -> None:
        """Propagate to time ``t`` (no-op if ``t`` equals the current time).

        Raises
        ------
        ValueError
            If ``t`` is earlier than the filter's time (out-of-order data).
        """
        dt = float(t) - self.t
        if dt < 0:
            raise ValueError(f"measurement at t = {t} is earlier than the filter time {self.t}: out of order")
        if dt == 0:
            return
        FQ = self._FQ.get(dt)
        if FQ is None:  # few distinct step lengths: build F and Q once each
            m = self.settings.motion
            FQ = self._FQ[dt] = (m.F(dt), m.Q(dt))
        F, Q = FQ
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + Q
        self.t = float(t)

    def update(self, t: float, channel: int, z: float, sigma: float) -> float:
        """Predict to ``t`` and apply one scalar measurement; returns its NIS (``nan`` if skipped)."""
        self.predict(t)
        try:
            h, H = self.model.predict_and_jacobian(self.x[None], [channel])
        except ValueError as exc:
            self.warnings.append((self.t, f"update skipped: {exc}"))
            return float("nan")
        H = H[0]
        r = float(z - h[0])
        PH = self.P @ H
        S = float(H @ PH) + sigma * sigma
        if not (math.isfinite(S) and S > 0):
            self.warnings.append((self.t, f"update skipped: innovation variance {S}"))
            return float("nan")
        nis = r * r / S
        # Every measurement counts in the likelihood, gated or not: a hypothesis must not
        # gain by rejecting the data that contradict it.
        self.log_likelihood -= 0.5 * (math.log(2 * math.pi * S) + nis)
        accepted = nis <= self._gate
        self.nis.append((self.t, int(channel), nis, bool(accepted)))
        if not accepted:
            self.warnings.append((self.t, f"pair {channel}: NIS {nis:.1f} > gate {self._gate:.1f}, measurement rejected"))
            return nis
        K = PH / S
        IKH = _EYE4 - K[:, None] * H[None, :]
        P = IKH @ self.P @ IKH.T + (sigma * sigma) * (K[:, None] * K[None, :])
        P = 0.5 * (P + P.T)
        x = self.x + K * r
        # one scalar check: inf and NaN propagate into the sum
        if not math.isfinite(float(P.sum()) + float(x.sum())):
            self.warnings.append((self.t, "update skipped: non-finite result"))
            return nis
        self.x, self.P = x, P
        return nis


def run_ekf(
    measurements: Measurements,
    model: MeasurementModel,
    init: Initiation,
    settings: TrackerSettings | None = None,
    *,
    fallback_covariance: ArrayLike | None = None,
) -> TrackResult:
    """Run the EKF over every measurement after the initiation window.

    Starts from ``init.x_end`` / ``init.P_end`` at ``init.t_end``.  If the
    initiation covariance is indeterminate, ``fallback_covariance`` (default:
    the weak search-region prior's covariance) is used and a warning recorded.
    Reports the filtered estimate after each scan, including the start.
    """
    from fgdoppler.estimators.common import region_prior

    settings = settings or TrackerSettings()
    check_model(model, measurements)
    t_begin = time.perf_counter()
    warnings: list[tuple[float, str]] = []
    P0 = init.P_end
    if P0 is None:
        P0 = np.asarray(fallback_covariance) if fallback_covariance is not None else region_prior(settings.grid)[1]
        warnings.append((init.t_end, f"initiation covariance indeterminate ({init.covariance_message}); EKF starts "
                                     "from a broad covariance"))
    ekf = ExtendedKalmanFilter(model, init.x_end, P0, init.t_end, settings)
    _, stream = split_window(measurements, init.t_end)
    times, states, covs, loglik = [init.t_end], [ekf.x.copy()], [ekf.P.copy()], [0.0]
    t_prev = None
    for t, p, z, s in zip(stream.time, stream.pair, stream.doppler, stream.sigma, strict=True):
        if t_prev is not None and t != t_prev:
            times.append(t_prev)
            states.append(ekf.x.copy())
            covs.append(ekf.P.copy())
            loglik.append(ekf.log_likelihood)
        ekf.update(float(t), int(p), float(z), float(s))
        t_prev = t
    if t_prev is not None:
        times.append(t_prev)
        states.append(ekf.x.copy())
        covs.append(ekf.P.copy())
        loglik.append(ekf.log_likelihood)
    return TrackResult(
        estimator="ekf",
        settings=settings.to_dict(),
        estimates={"filtered": Estimates.from_lists(times, states, covs)},
        primary="filtered",
        nis=np.array(ekf.nis, dtype=float).reshape(-1, 4),
        log_likelihood=np.array(loglik),
        warnings=tuple(warnings + ekf.warnings),
        wall_time=time.perf_counter() - t_begin,
    )
