r"""Fixed-lag smoother: ``gtsam.IncrementalFixedLagSmoother`` over the tracking graph.

States older than ``lag`` seconds are marginalised out, so the graph (and
every ``CustomFactor`` callback's copy of ``Values``) stays bounded and the
cost per scan is flat.  After each scan the estimate and marginal covariance
of the newest state (``"filtered"``) are recorded, together with the
estimate of the oldest state still in the window — the state about ``lag``
seconds back, as smoothed by everything up to now (``"lagged"``, the
fixed-lag smoothed track).  States that leave the window before the end are
reported from the last scan at which they were in it; at the end the whole
remaining window is reported.

Through :func:`~fgdoppler.estimators.registry.run_estimator` the lagged
covariances are then checked against posterior samples of the data up to
``lag`` seconds after each estimate's time, the data it has read, and
widened where those spread further (``FixedLagSettings.sampled_covariance``,
:func:`~fgdoppler.estimators.spread.filtered_spread` with ``lag``), and
where the process noise puts those samples out of reach (long recordings)
towards the posterior of the same data linearised about the verdict's
offline smoother's track (:mod:`~fgdoppler.estimators.linearized_posterior`);
:func:`run_fixed_lag` and :class:`FixedLagTracker` report the smoother's own
marginals.

Known marginalisation failures of GTSAM's fixed-lag smoothers (an
"indeterminant linear system" during marginalisation, or a key that is
requested after it was marginalised) surface as :class:`RuntimeError`.  They
are caught: the smoother is rebuilt from the last good estimate and
covariance of the newest state as a Gaussian prior, the event is logged,
and processing continues.

Verdict reasons: ``rebuilt`` (the smoother had to be rebuilt),
``covariance`` (some covariances indeterminate), ``not-converged`` (the
final iterations hit their cap), each ``"doubtful"``.
"""

from __future__ import annotations

import time
from typing import Any

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._text import first_line
from fgdoppler.estimators.gating import NISGate
from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.local import LocalFrame, in_computation_frame
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.settings import FixedLagSettings
from fgdoppler.estimators.verdict import NOT_CONVERGED, Event, Reason
from fgdoppler.estimators.warmup import WarmUp
from fgdoppler.estimators.window import feed_from_window_start, start_prior
from fgdoppler.factors import X, measurement_factor, motion_factor, prior_factor
from fgdoppler.geometry import pair_labels
from fgdoppler.measurements import Measurements, scan_time
from fgdoppler.models.observation import check_channels
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress

__all__ = ["FixedLagTracker", "run_fixed_lag"]

FloatArray = NDArray[np.float64]


def values_keys(values: gtsam.Values) -> set[int]:
    """Keys present in a ``Values``."""
    return {int(k) for k in values.keys()}


def _params() -> gtsam.ISAM2Params:
    # relinearise every 10th update (GTSAM's default) when the delta exceeds 1e-3: far fewer
    # Python callbacks than every update, and :meth:`FixedLagTracker.finish` converges at the end
    p = gtsam.ISAM2Params()
    p.setFactorization("QR")
    p.setRelinearizeThreshold(1e-3)
    p.relinearizeSkip = 10
    return p


class FixedLagTracker:
    """Streaming fixed-lag smoother.

    Guesses, the prior and every estimate (the returned ones and
    :attr:`lagged`) are in the model's coordinates; the smoother computes in
    its computation frame (:mod:`fgdoppler.estimators.local`).

    Parameters
    ----------
    model
        Observation and motion model.
    settings
        Lag, gate, Huber threshold.
    prior
        Optional ``(mean, covariance)`` on the first state.
    """

    def __init__(self, model: TrackingModel, settings: FixedLagSettings | None = None,
                 prior: tuple[ArrayLike, ArrayLike] | None = None) -> None:
        # computed in the model's computation frame; states cross at the public methods
        self.local, self.tracking_model = LocalFrame.of(model)
        self.model = self.tracking_model.observation
        self.motion = self.tracking_model.motion
        self.settings = settings or FixedLagSettings()
        self.smoother = gtsam.IncrementalFixedLagSmoother(self.settings.lag, _params())
        self.prior = self.local.prior_in(prior)  # in the computation frame
        self.times: list[float] = []
        self.events: list[Event] = []
        self.gate = NISGate(self.settings.gate_probability, self.events, label=pair_labels(self.model))
        self.lagged: dict[int, tuple[FloatArray, FloatArray | None]] = {}
        self.rebuilds = 0
        self.iterations = 0
        self.converged = True
        self._first_live = 0
        self._last: tuple[FloatArray, FloatArray | None] | None = None
        self._warmup = WarmUp.of(self.settings, self.model.n_channels)

    @property
    def warming_up(self) -> bool:
        """Whether the tracker still holds its first scans back (:mod:`fgdoppler.estimators.warmup`)."""
        return self._warmup is not None

    def add_window(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                   guesses: ArrayLike) -> tuple[FloatArray, FloatArray | None]:
        """Add the initiation window, ungated; returns the newest ``(x, P)``.

        The scans within one lag of the start go in together (jointly
        determined); later window scans one by one, so every state is
        recorded before it is marginalised.
        """
        g = self.local.state_in(np.asarray(guesses, dtype=float).reshape(-1, self.motion.n))
        return self.local.out(*self._add_window(times, channels, z, sigma, g))

    def _add_window(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                    g: FloatArray) -> tuple[FloatArray, FloatArray | None]:
        """:meth:`add_window` in the computation frame."""
        ts = np.asarray(times, dtype=float).reshape(-1)
        if self._warmup is not None:
            self._warmup.refuse_window()
        self._warmup = None  # a window is the start the warm-up would build
        first = max(1, int(np.searchsorted(ts, ts[0] + 0.999 * self.settings.lag, side="right")))
        x, P = self._add_scans(ts[:first], channels[:first], z[:first], sigma[:first], g[:first], gate=False)
        for k in range(first, ts.size):
            x, P = self._add_scans(ts[k:k + 1], channels[k:k + 1], z[k:k + 1], sigma[k:k + 1], g[k:k + 1],
                                   gate=False)
        return x, P

    def add_scan(self, t: float, channels: ArrayLike, z: ArrayLike, sigma: ArrayLike,
                 x_guess: ArrayLike | None = None, *, gate: bool = True) -> tuple[FloatArray, FloatArray | None]:
        """Add one scan; returns the newest ``(x, P)`` (as :meth:`add_scans` with one scan).

        ``x_guess`` is the new state's initial value (default: the previous
        estimate moved by the motion model; needed for the first scan unless
        the warm-up is on), ``gate`` whether the NIS gate applies, as in
        :meth:`ISAM2Tracker.add_scan <fgdoppler.estimators.isam2.ISAM2Tracker.add_scan>`.
        """
        guesses = None if x_guess is None else np.asarray(x_guess, dtype=float)[None]
        return self.add_scans([t], [channels], [z], [sigma], guesses, gate=gate)

    def _factors(self, k: int, t: float, c: NDArray[np.intp], z: FloatArray, s: FloatArray,
                 graph: gtsam.NonlinearFactorGraph) -> None:
        if c.size:
            graph.add(measurement_factor(X(k), self.model, c, z, s, huber_k=self.settings.huber_k))
        if k > self._first_live:
            graph.add(motion_factor(X(k - 1), X(k), t - self.times[k - 1], self.motion))

    def add_scans(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                  guesses: ArrayLike | None = None, *, gate: bool = True) -> tuple[FloatArray, FloatArray | None]:
        """Add one or more scans in one smoother update; returns the newest ``(x, P)``.

        A tracker whose first update is this one warms up
        (:mod:`fgdoppler.estimators.warmup`): it holds the scans back,
        ungated, returns a state of NaN and no covariance, and at the scan
        that completes the warm-up adds them all as one window (from
        ``guesses[0]``, or without guesses from a multi-start initiation of
        them); scans after that one in the same call follow as one update.

        Raises
        ------
        ValueError
            If a scan is not after the previous one (out of order).
        """
        ts = np.asarray(times, dtype=float).reshape(-1)
        g = None if guesses is None else self.local.state_in(np.asarray(guesses, dtype=float).reshape(-1, self.motion.n))
        if self._warmup is not None:
            return self.local.out(*self._hold(ts, channels, z, sigma, g, gate))
        return self.local.out(*self._add_scans(ts, channels, z, sigma, g, gate=gate))

    def _add_scans(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                   g: FloatArray | None, *, gate: bool) -> tuple[FloatArray, FloatArray | None]:
        """:meth:`add_scans` in the computation frame, after the warm-up."""
        ts = np.asarray(times, dtype=float).reshape(-1)
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        stamps: dict[Any, Any] = {}  # key -> time (gtsam's stub wants SupportsInt keys)
        m = self.motion
        for j, t in enumerate(ts):
            t = scan_time(t, self.times[-1] if self.times else None)
            k = len(self.times)
            cc = np.asarray(channels[j], dtype=np.intp).reshape(-1)
            zz = np.asarray(z[j], dtype=float).reshape(-1)
            ss = np.broadcast_to(np.asarray(sigma[j], dtype=float), zz.shape).copy()
            if g is not None:
                x_pred = g[j]
            elif self._last is not None:
                x_pred = m.propagate(self._last[0], t - self.times[-1])
            else:
                raise ValueError("the first scan needs an initial guess "
                                 "(or the warm-up on, warmup_seconds > 0, to start without one)")
            if gate and self._last is not None and self._last[1] is not None and cc.size:
                P_pred = m.predict_covariance(self._last[1], t - self.times[-1])
                keep = self.gate.scan(self.model, x_pred, P_pred, t, cc, zz, ss)
                cc, zz, ss = cc[keep], zz[keep], ss[keep]
            self.times.append(t)
            if k == 0 and self.prior is not None:
                graph.add(prior_factor(X(0), *self.prior))
            self._factors(k, t, cc, zz, ss, graph)
            values.insert(X(k), np.asarray(x_pred, dtype=float))
            stamps[X(k)] = t
            self._last = (np.asarray(x_pred, dtype=float), None if self._last is None else self._last[1])
        return self._update(graph, values, stamps)

    def _hold(self, ts: FloatArray, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
              g: FloatArray | None, gate: bool) -> tuple[FloatArray, FloatArray | None]:
        """The warm-up part of :meth:`add_scans`."""
        w = self._warmup
        assert w is not None
        for j, t in enumerate(ts):
            if w.hold(self.model, float(t), channels[j], z[j], sigma[j], None if g is None else g[j]):
                x, P = self._start_warmed_up()
                if j + 1 < ts.size:
                    x, P = self._add_scans(ts[j + 1:], channels[j + 1:], z[j + 1:], sigma[j + 1:],
                                           None if g is None else g[j + 1:], gate=gate)
                return x, P
        return np.full(self.motion.n, np.nan), None

    def _start_warmed_up(self) -> tuple[FloatArray, FloatArray | None]:
        w, self._warmup = self._warmup, None
        assert w is not None
        states = w.start(self.tracking_model, self.prior, huber_k=self.settings.huber_k, events=self.events)
        return self._add_window(w.times, list(w.channels), list(w.z), list(w.sigma), states)

    def _update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                stamps: dict[Any, Any]) -> tuple[FloatArray, FloatArray | None]:
        k = len(self.times) - 1
        t = self.times[-1]
        # States older than the lag are marginalised by this update: record them now, as
        # estimated by everything up to the previous scan (~lag seconds after their time).
        leaving = [j for j in range(self._first_live, k) if self.times[j] < t - self.settings.lag
                   and j not in values_keys(values)]
        if leaving:
            self._record(self.smoother.calculateEstimate(), leaving)
        try:
            self.smoother.update(graph, values, stamps)
            est = self.smoother.calculateEstimate()
            x = np.asarray(est.atVector(X(k)), dtype=float)
            P = np.asarray(self.smoother.marginalCovariance(X(k)), dtype=float)
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
                raise RuntimeError("non-finite estimate")
        except (RuntimeError, ValueError) as exc:  # ValueError: the model at a sensor position
            self.rebuilds += 1
            self.events.append(Event(time=t, message=(
                f"fixed-lag update failed ({first_line(exc)}); smoother rebuilt from the last good estimate")))
            return self._rebuild(k, t, graph)
        self._last = (x, P)
        return x, P

    def finish(self, *, tol: float = 1e-10) -> None:
        """Iterate the smoother (empty updates: relinearise + Gauss–Newton) until the window converges.

        iSAM2 takes one Gauss–Newton step per update, so the last window is
        not at its optimum after the last scan; this brings it there (with a
        lag longer than the track, to the batch solution).  A tracker still
        warming up starts from the scans it holds first.
        """
        if self._warmup is not None and self._warmup.times:
            self._start_warmed_up()
        if not self.times:
            return
        prev = self._live_estimates()
        skip = max(1, int(self.smoother.params().relinearizeSkip))
        for _ in range(self.settings.final_iterations):
            try:
                # iSAM2 relinearises every ``skip`` updates: compare across a full cycle
                for _ in range(skip):
                    self.smoother.update()
            except RuntimeError as exc:
                self.converged = False
                self.events.append(Event(time=self.times[-1], message=f"final fixed-lag iteration failed: {first_line(exc)}"))
                return
            self.iterations += 1
            cur = self._live_estimates()
            diff = max((float(np.max(np.abs(cur[j] - prev[j]) / (1.0 + np.abs(prev[j])))) for j in cur if j in prev),
                       default=0.0)
            prev = cur
            if diff < tol:
                break
        else:
            self.converged = False
            self.events.append(Event(time=self.times[-1], message="final fixed-lag iterations did not converge"))
        self._record(self.smoother.calculateEstimate())

    def _live_estimates(self) -> dict[int, FloatArray]:
        try:
            est = self.smoother.calculateEstimate()
        except RuntimeError:
            return {}
        return {j: np.asarray(est.atVector(X(j))) for j in range(self._first_live, len(self.times)) if est.exists(X(j))}

    def _record(self, est: gtsam.Values, which: list[int] | None = None) -> None:
        # Record estimate and marginal covariance of the given live states (default: all).
        live = [j for j in range(self._first_live, len(self.times)) if est.exists(X(j))]
        if which is not None:
            live = [j for j in live if j in set(which)]
        for j in live:
            try:
                P = np.asarray(self.smoother.marginalCovariance(X(j)), dtype=float)
            except RuntimeError:
                P = None
            self.lagged[j] = self.local.out(np.asarray(est.atVector(X(j)), dtype=float), P)
        if which is not None and live:
            self._first_live = max(live) + 1
        elif live:
            self._first_live = live[0]

    def _rebuild(self, k: int, t: float, graph: gtsam.NonlinearFactorGraph) -> tuple[FloatArray, FloatArray | None]:
        # Restart from the newest good estimate as a prior; the current scan's measurement
        # factors are re-added on top of it (motion factors to dead keys are dropped).
        if self._last is None or self._last[1] is None:
            raise RuntimeError(f"fixed-lag smoother failed at t = {t} before any good estimate") from None
        x_prev, P_prev = self._last
        assert P_prev is not None  # checked just above
        t_prev = self.times[-2] if len(self.times) > 1 else t
        m = self.motion
        dt = t - t_prev
        x0 = m.propagate(x_prev, dt) if dt > 0 else x_prev
        P0 = m.predict_covariance(P_prev, dt) if dt > 0 else P_prev
        self.smoother = gtsam.IncrementalFixedLagSmoother(self.settings.lag, _params())
        self._first_live = k
        g2 = gtsam.NonlinearFactorGraph()
        g2.add(prior_factor(X(k), x0, 0.5 * (P0 + P0.T)))
        for i in range(graph.size()):
            f = graph.at(i)
            if all(int(key) == X(k) for key in f.keys()) and not isinstance(f, gtsam.PriorFactorVector):
                g2.add(f)
        v2 = gtsam.Values()
        v2.insert(X(k), x0)
        self.smoother.update(g2, v2, {X(k): t})
        est = self.smoother.calculateEstimate()
        x = np.asarray(est.atVector(X(k)), dtype=float)
        P = np.asarray(self.smoother.marginalCovariance(X(k)), dtype=float)
        self._record(est)
        self._last = (x, P)
        return x, P


@in_computation_frame
def run_fixed_lag(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: FixedLagSettings | None = None,
    *,
    progress: Progress | None = None,
) -> TrackResult:
    """Fixed-lag smoothing of a recording: the initiation window in one update, then one update per scan.

    The window's states start at the optimum of this tracker's window graph
    (:func:`~fgdoppler.estimators.window.window_start`).

    ``lagged`` (primary): every state as estimated when it was ``lag`` seconds
    old (or at the end of the recording).  ``filtered``: the newest state
    after each update (from the window's end on).
    """
    settings = settings or FixedLagSettings()
    check_channels(model.observation, measurements)
    t_begin = time.perf_counter()
    tr = FixedLagTracker(model, settings, start_prior(model, init))
    times, states, covs = feed_from_window_start(tr, model, measurements, init, tr.events, huber_k=settings.huber_k,
                                                 progress=progress, name="fixed-lag")
    tr.finish()
    idx = sorted(tr.lagged)
    lagged = Estimates.from_lists("lagged", [tr.times[j] for j in idx], [tr.lagged[j][0] for j in idx],
                                  [tr.lagged[j][1] for j in idx])
    reasons = [r for r in (lagged.covariance_reason(),) if r is not None]
    if tr.rebuilds:
        reasons.insert(0, Reason(code="rebuilt", status="doubtful", message=(
            f"the smoother failed and was rebuilt from its last good estimate {tr.rebuilds} time(s)")))
    if not tr.converged:
        reasons.append(NOT_CONVERGED)
    return TrackResult(
        estimator="fixed-lag",
        settings=settings,
        estimates=(lagged, Estimates.from_lists("filtered", times, states, covs)),
        reasons=tuple(reasons),
        events=tuple(tr.events),
        nis=tr.gate.as_array(),
        iterations=tr.iterations,
        wall_time=time.perf_counter() - t_begin,
    )
