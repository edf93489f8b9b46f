r"""Extended Kalman filter: the paper's dynamic estimator and the baseline of the smoothers.

Prediction with the shared NCV model,
:math:`\mathbf x^- = \mathbf F\mathbf x`, :math:`\mathbf P^- = \mathbf F\mathbf P\mathbf F' + \mathbf Q`;
then one *scalar* update per measurement in time order (so asynchronous pairs
need nothing special; simultaneous ones in the sensors' own order,
:attr:`~fgdoppler.geometry.Geometry.scan_rank`, whatever the pairs' numbering):

.. math::

    S = \mathbf H\mathbf P^-\mathbf H' + \sigma^2,\quad
    \mathbf K = \mathbf P^-\mathbf H'/S,\quad
    \mathbf x = \mathbf x^- + \mathbf K\,(z - h(\mathbf x^-)),

    \mathbf P = (\mathbf I - \mathbf K\mathbf H)\mathbf P^-(\mathbf I - \mathbf K\mathbf H)' + \mathbf K\sigma^2\mathbf K'
    \quad\text{(Joseph form)}.

The normalised innovation :math:`\mathrm{NIS} = (z - h)^2/S` is recorded for
every measurement; above the gate the measurement is rejected and reported —
unless the filter's position Gaussian fits its posterior there (sag ratio
below :data:`~fgdoppler.estimators.gating.SAG_LIMIT`), where the wider
``gaussian_gate_probability`` applies (:mod:`fgdoppler.estimators.gating`).
With a Huber threshold :math:`k` a measurement with :math:`|r| = \sqrt{\mathrm{NIS}} > k`
updates with weight :math:`w = k/|r|`: its variance grows until
:math:`S_w = S/w` (an M-estimate of the update, which bounds any one
measurement's pull).
A non-finite or non-positive :math:`S`, or a covariance that stops being
positive definite, skips the update with a warning instead of propagating
garbage.

With ``EKFSettings(update="scan")`` the measurements of one scan (all pairs
at one time) update together, linearised once at the prediction:
:math:`\mathbf S = \mathbf H\mathbf P^-\mathbf H' + \mathbf R`,
:math:`\mathbf K = \mathbf P^-\mathbf H'\mathbf S^{-1}`, Joseph form with
:math:`\mathbf R = \mathrm{diag}(\sigma_j^2)` — the textbook vector update
(and Stone Soup's with one Detection per scan).  Each measurement is gated
by its own χ²₁ test against the prediction; a Huber weight inflates its
:math:`\sigma_j^2` as above, from its own :math:`S_{jj}`.

Through :func:`~fgdoppler.estimators.registry.run_estimator` the filtered
covariances are then checked against posterior samples of the data so far
and widened where those spread further
(``EKFSettings.sampled_covariance``,
:func:`~fgdoppler.estimators.spread.filtered_spread`), as iSAM2's are;
:func:`run_ekf` and :class:`ExtendedKalmanFilter` report the filter's own
covariances.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.gating import NISGate, sag_ratio
from fgdoppler.estimators.initiation import OUTLIER_CUT, Initiation
from fgdoppler.estimators.local import in_computation_frame
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.settings import EKFSettings
from fgdoppler.estimators.verdict import Event, Reason
from fgdoppler.estimators.window import split_window
from fgdoppler.geometry import pair_labels
from fgdoppler.measurements import Measurements
from fgdoppler.models.observation import check_channels
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance, start_task

__all__ = ["ExtendedKalmanFilter", "run_ekf"]

FloatArray = NDArray[np.float64]
#: Largest contribution of one measurement to a robust filter's log-likelihood (χ²₁ at 0.9999).
OUTLIER_CUT2 = OUTLIER_CUT**2


def _dot4(a: list[float], b: list[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


def _dot6(a: list[float], b: list[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]


#: ``a . b`` in plain floats, summed left to right, per state length: written out, because in this hot
#: loop a generic loop or ``sum(map(...))`` costs twice the arithmetic.  (Zero terms of a 3-D state at
#: z = 0 add exactly 0, so the 3-D filter on the ground is the 2-D one to the bit.)
_DOT = {4: _dot4, 6: _dot6}


class ExtendedKalmanFilter:
    r"""Streaming EKF.

    Parameters
    ----------
    model
        Observation and motion model.
    x0, P0, t0
        Initial state, covariance and time.
    settings
        The gate.

    Notes
    -----
    The state arithmetic (4 or 6 numbers) runs in plain Python floats: for matrices this small
    numpy's per-call overhead is several times the arithmetic.  The Joseph
    update for a scalar measurement is evaluated exactly in O(n^2) as
    :math:`\mathbf A = \mathbf P - \mathbf K(\mathbf P\mathbf H')'`,
    :math:`\mathbf P^+ = \mathbf A - (\mathbf A\mathbf H')\mathbf K' + \sigma^2\mathbf K\mathbf K'`,
    which equals :math:`(\mathbf I-\mathbf K\mathbf H)\mathbf P(\mathbf I-\mathbf K\mathbf H)' + \mathbf K\sigma^2\mathbf K'`
    term by term; the prediction uses the block structure of the
    constant-velocity :math:`\mathbf F`.  ``x`` and ``P`` are numpy arrays.
    """

    def __init__(self, model: TrackingModel, x0: ArrayLike, P0: ArrayLike, t0: float,
                 settings: EKFSettings | None = None) -> None:
        self.model = model.observation
        self.motion = model.motion
        self.settings = settings or EKFSettings()
        self.n = n = model.n
        x = np.array(x0, dtype=float).reshape(-1)
        P = np.array(P0, dtype=float)
        if x.shape != (n,) or P.shape != (n, n):
            raise ValueError(f"a {n // 2}-D model needs a state of {n} numbers and a {n}x{n} covariance, "
                             f"got {x.shape} and {P.shape}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            raise ValueError("initial state and covariance must be finite")
        self._x = x.tolist()
        self._P = (0.5 * (P + P.T)).tolist()
        self.t = float(t0)
        # plain-float fast path of models that offer one (DopplerModel.scalar)
        self._scalar = getattr(self.model, "scalar", None)
        # the sensors' own order of a scan's pairs (DopplerModel.scan_rank; None: by channel)
        rank = getattr(self.model, "scan_rank", None)
        self._rank: list[int] | None = None if rank is None else [int(r) for r in rank]
        self._Q: dict[float, list[list[float]]] = {}
        self.events: list[Event] = []
        self.gate = NISGate(self.settings.gate_probability, self.events, self.settings.gaussian_gate_probability,
                            label=pair_labels(self.model))
        self._sensors = self._pair_sensors(n // 2)
        self._huber = self.settings.huber_k
        #: Cumulative predictive log-likelihood of all measurements (gated ones
        #: included), sum of -0.5 (log(2 pi S) + NIS); with a Huber threshold each
        #: NIS is capped at the outlier cut (χ²₁ at 0.9999).
        self.log_likelihood = 0.0

    @property
    def x(self) -> FloatArray:
        """Current state estimate ``(n,)``."""
        return np.array(self._x)

    @property
    def P(self) -> FloatArray:
        """Current covariance ``(n, n)``."""
        return np.array(self._P)

    def predict(self, t: float) -> None:
        """Propagate to time ``t`` (no-op if ``t`` equals the current time).

        Raises
        ------
        ValueError
            If ``t`` is earlier than the filter's time (out-of-order data) or not a finite number.
        """
        dt = float(t) - self.t
        if not math.isfinite(dt):
            raise ValueError(f"measurement time {t} is not a finite number")
        if dt < 0:
            raise ValueError(f"measurement at t = {t} is earlier than the filter time {self.t}: out of order")
        if dt == 0:
            return
        Q = self._Q.get(dt)
        if Q is None:  # few distinct step lengths: build Q once each
            Q = self._Q[dt] = self.motion.Q(dt).tolist()
        x = self._x
        d = self.n // 2
        self._x = [x[i] + dt * x[i + d] for i in range(d)] + x[d:]
        P = self._P
        # F P F' for F = [[I, dt I], [0, I]], by blocks (P symmetric)
        n = [[0.0] * self.n for _ in range(self.n)]
        for i in range(d):
            for j in range(d):
                p11, p12, p21, p22 = P[i][j], P[i][j + d], P[i + d][j], P[i + d][j + d]
                n[i][j] = p11 + dt * (p12 + p21) + dt * dt * p22 + Q[i][j]
                n[i][j + d] = p12 + dt * p22 + Q[i][j + d]
                n[i + d][j] = p21 + dt * p22 + Q[i + d][j]
                n[i + d][j + d] = p22 + Q[i + d][j + d]
        self._P = n
        self.t = float(t)

    def add_scan(self, t: float, channels: ArrayLike, z: ArrayLike, sigma: ArrayLike) -> None:
        """Predict to ``t`` and apply one scan as ``settings.update`` says (a scan without measurements only predicts).

        ``"sequential"``: one :meth:`update` per measurement, in the sensors'
        order — by the pairs' :attr:`~fgdoppler.geometry.Geometry.scan_rank`
        (by channel for a model without one), then by sigma and Doppler —
        whatever the order given or the pairs' numbering; ``"scan"``: one
        :meth:`update_scan`.
        """
        c = np.asarray(channels, dtype=np.intp).reshape(-1)
        zz = np.asarray(z, dtype=float).reshape(-1)
        ss = np.broadcast_to(np.asarray(sigma, dtype=float), zz.shape)
        if self.settings.update == "scan":
            self.update_scan(t, c, zz, ss)
            return
        if not c.size:
            self.predict(t)
        elif c.size > 1:
            order = self._scan_order(c, zz, ss)
            if order is not None:
                c, zz, ss = c[order], zz[order], ss[order]
        for p, zi, si in zip(c, zz, ss, strict=True):
            self.update(t, int(p), float(zi), float(si))

    def _scan_order(self, c: NDArray[np.intp], z: FloatArray, sigma: FloatArray) -> list[int] | None:
        """The permutation that puts a scan's rows in the sensors' order (``None``: they are in it already).

        Sequential updates of a nonlinear model do not commute (a linearisation effect, of the order of the
        noise: docs/concepts.md), so the order is the sensors' — not the rows' or the pairs' numbering.
        """
        channels = c.tolist()
        rank = self._rank
        if rank is None or min(channels) < 0 or max(channels) >= len(rank):
            ranks = channels  # by channel (a bad one is refused by the update)
        else:
            ranks = [rank[i] for i in channels]
        if all(a < b for a, b in pairwise(ranks)):
            return None  # the common case, a scan fed in pair order: no work
        s, v = sigma.tolist(), z.tolist()
        return sorted(range(len(channels)), key=lambda j: (ranks[j], s[j], v[j]))

    def update_scan(self, t: float, channels: NDArray[np.intp], z: FloatArray, sigma: FloatArray) -> FloatArray:
        """Predict to ``t`` and apply the scan's measurements in one vector update; returns each one's NIS.

        The NIS of measurement ``j`` is :math:`(z_j - h_j)^2 / S_{jj}` against the prediction (``nan``
        for all of them if the update is skipped).
        """
        self.predict(t)
        ch = np.asarray(channels, dtype=np.intp).reshape(-1)
        zv = np.asarray(z, dtype=float).reshape(-1)
        s2 = np.asarray(sigma, dtype=float).reshape(-1) ** 2
        x, P = np.array(self._x), np.array(self._P)
        try:
            h, H = self.model.predict_and_jacobian(np.broadcast_to(x, (ch.size, x.size)), ch)
        except ValueError as exc:
            self.events.append(Event(time=self.t, message=f"update skipped: {exc}"))
            return np.full(ch.size, np.nan)
        r = zv - h
        PH = P @ H.T
        S = H @ PH + np.diag(s2)
        Sd = np.diag(S)
        if not (np.all(np.isfinite(S)) and np.all(Sd > 0)):
            self.events.append(Event(time=self.t, message="update skipped: innovation covariance not finite"))
            return np.full(ch.size, np.nan)
        nis = r * r / Sd
        try:
            L = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            self.events.append(Event(time=self.t, message="update skipped: innovation covariance not positive"))
            return np.full(ch.size, np.nan)
        w = np.linalg.solve(L, r)
        joint = float(w @ w)
        if self._huber is not None:  # each term capped at the outlier cut, as in the scalar update
            joint = min(joint, OUTLIER_CUT2 * ch.size)
        self.log_likelihood -= 0.5 * (ch.size * math.log(2 * math.pi) + 2.0 * float(np.sum(np.log(np.diag(L))))
                                      + joint)
        narrow = self.gate.threshold  # the sag ratio is asked only beyond it
        keep = np.array([self.gate.accept(self.t, int(c), float(v), self._sag(int(c), x, P) if v > narrow else None)
                         for c, v in zip(ch, nis, strict=True)], dtype=bool)
        if not np.any(keep):
            return nis
        k = self._huber
        if k is not None:  # Huber: inflate the variance of a measurement beyond k normalised units
            big = nis > k * k
            s2 = np.where(big, s2 + Sd * (np.sqrt(nis) / k - 1.0), s2)
        Hk, rk, Rk = H[keep], r[keep], np.diag(s2[keep])
        Sk = Hk @ P @ Hk.T + Rk
        K = np.linalg.solve(Sk, Hk @ P).T
        A = np.eye(x.size) - K @ Hk
        Pn = A @ P @ A.T + K @ Rk @ K.T
        Pn = 0.5 * (Pn + Pn.T)
        xn = x + K @ rk
        if not (np.all(np.isfinite(xn)) and np.all(np.isfinite(Pn))):
            self.events.append(Event(time=self.t, message="update skipped: non-finite result"))
            return nis
        self._x, self._P = xn.tolist(), Pn.tolist()
        return nis

    def _pair_sensors(self, d: int) -> list[FloatArray] | None:
        """Each pair's Tx and Rx with the states' ``d`` coordinates, for the wider gate's sag ratio.

        ``None`` (one gate) for a model without a geometry, or one whose sensors its states cannot place.
        """
        geometry = getattr(self.model, "geometry", None)
        if geometry is None:
            return None
        try:
            tx, rx = geometry.positions(d)
        except ValueError:
            return None
        return [np.vstack([a, b]) for a, b in zip(tx, rx, strict=True)]

    def _sag(self, channel: int, x: ArrayLike, P: ArrayLike) -> Callable[[], float] | None:
        """The sag ratio of the prediction ``x, P`` for pair ``channel``, as a call the gate makes only if it needs it."""
        sensors = self._sensors
        if sensors is None:
            return None
        d = self.n // 2

        def ratio() -> float:
            xs, Ps = np.asarray(x, dtype=float), np.asarray(P, dtype=float)
            return sag_ratio(xs[:d], Ps[:d, :d], sensors[channel])
        return ratio

    def update(self, t: float, channel: int, z: float, sigma: float) -> float:
        """Predict to ``t`` and apply one scalar measurement; returns its NIS (``nan`` if skipped)."""
        self.predict(t)
        try:
            if self._scalar is not None:
                if not 0 <= channel < self.model.n_channels:
                    raise ValueError(f"pair index {channel} out of range")
                hv, H = self._scalar(self._x, int(channel))
            else:
                h, Hm = self.model.predict_and_jacobian(np.array([self._x]), [channel])
                hv, H = float(h[0]), Hm[0].tolist()
        except ValueError as exc:
            self.events.append(Event(time=self.t, message=f"update skipped: {exc}"))
            return float("nan")
        r = float(z) - hv
        P = self._P
        n = self.n
        dot = _DOT[n]
        PH = [dot(row, H) for row in P]
        s2 = float(sigma) * float(sigma)
        S = dot(H, PH) + s2
        if not (math.isfinite(S) and S > 0):
            self.events.append(Event(time=self.t, message=f"update skipped: innovation variance {S}"))
            return float("nan")
        nis = r * r / S
        # Every measurement counts in the likelihood, gated or not: a hypothesis must not
        # gain by rejecting the data that contradict it.  Robust filters cap each term at the
        # outlier cut, so that a gross outlier costs every hypothesis the same.
        self.log_likelihood -= 0.5 * (math.log(2 * math.pi * S) + (nis if self._huber is None else
                                                                   min(nis, OUTLIER_CUT2)))
        sag = self._sag(int(channel), self._x, P) if nis > self.gate.threshold else None
        if not self.gate.accept(self.t, int(channel), nis, sag):
            return nis
        k = self._huber
        if k is not None and nis > k * k:
            # Huber M-estimate: a measurement beyond k normalised units counts with weight
            # w = k / |r|, i.e. its variance is inflated so that S grows by 1 / w
            s2 += (S * (math.sqrt(nis) / k - 1.0))
            S = dot(H, PH) + s2
        K = [v / S for v in PH]
        # Joseph form, exactly: A = (I - K H) P = P - K (P H')', then A (I - K H)' + s2 K K'
        A = [[P[i][j] - K[i] * PH[j] for j in range(n)] for i in range(n)]
        AH = [dot(row, H) for row in A]
        Pn = [[A[i][j] - AH[i] * K[j] + s2 * K[i] * K[j] for j in range(n)] for i in range(n)]
        Pn = [[0.5 * (Pn[i][j] + Pn[j][i]) for j in range(n)] for i in range(n)]
        x = [self._x[i] + K[i] * r for i in range(n)]
        if not math.isfinite(sum(x) + sum(sum(row) for row in Pn)):
            self.events.append(Event(time=self.t, message="update skipped: non-finite result"))
            return nis
        self._x, self._P = x, Pn
        return nis


@in_computation_frame
def run_ekf(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: EKFSettings | None = None,
    *,
    fallback_covariance: ArrayLike | None = None,
    progress: Progress | None = None,
) -> TrackResult:
    """Run the EKF over every measurement after the initiation window.

    Starts from ``init.x_end`` / ``init.P_end`` at ``init.t_end``.  If the
    initiation covariance is indeterminate, ``fallback_covariance`` (default:
    the zone's weak-prior covariance) is used and the verdict says so.
    Reports the filtered estimate after each scan, including the start;
    ``progress`` (:mod:`fgdoppler.progress`) is advanced scan by scan.
    """
    settings = settings or EKFSettings()
    check_channels(model.observation, measurements)
    t_begin = time.perf_counter()
    reasons: list[Reason] = []
    P0 = init.P_end
    if P0 is None:
        if fallback_covariance is not None:
            P0 = np.asarray(fallback_covariance)
        elif model.zone is not None:
            P0 = model.zone.prior()[1]
        else:
            raise ValueError("the initiation covariance is indeterminate and the model has no zone to fall back on")
        reasons.append(Reason(code="start", status="doubtful", message=(
            "the initiation covariance is indeterminate: the EKF started from a broad covariance")))
    ekf = ExtendedKalmanFilter(model, init.x_end, P0, init.t_end, settings)
    _, stream = split_window(measurements, init.t_end)
    start_task(progress, "ekf", len(stream.scans()))
    times, states, covs, loglik = [init.t_end], [ekf.x.copy()], [ekf.P.copy()], [0.0]
    scans = stream.scans()
    for k in range(len(scans)):
        rows = scans.rows(k)
        ekf.add_scan(float(scans.times[k]), stream.pair[rows], stream.doppler[rows], stream.sigma[rows])
        times.append(float(scans.times[k]))
        states.append(ekf.x.copy())
        covs.append(ekf.P.copy())
        loglik.append(ekf.log_likelihood)
        advance(progress)
    return TrackResult(
        estimator="ekf",
        settings=settings,
        estimates=(Estimates.from_lists("filtered", times, states, covs),),
        reasons=tuple(reasons),
        events=tuple(ekf.events),
        nis=ekf.gate.as_array(),
        log_likelihood=np.array(loglik),
        wall_time=time.perf_counter() - t_begin,
    )
