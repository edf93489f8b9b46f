r"""A Gaussian-sum tracker fed scan by scan: the registry's hypotheses, online.

:func:`fgdoppler.track` and :func:`~fgdoppler.estimators.registry.run_estimator`
carry a non-Gaussian start as a Gaussian sum (:mod:`fgdoppler.estimators.ambiguity`):
one tracker per term of the initiation window's posterior, weighted by how
well each predicts the later data.  A single tracker fed by hand
(:class:`~fgdoppler.estimators.isam2.ISAM2Tracker`,
:class:`~fgdoppler.estimators.fixed_lag.FixedLagTracker`,
:class:`~fgdoppler.estimators.ekf.ExtendedKalmanFilter`) follows one
Gaussian, and where the window's posterior is a curved valley that Gaussian
is over-confident (docs/concepts.md, "Feeding a tracker yourself").
:class:`GaussianSumTracker` does what the registry does, one scan at a time:

1. **Warm-up** — scans are held (:class:`~fgdoppler.estimators.warmup.WarmUp`)
   until they span ``warmup_seconds`` and hold ``warmup_per_pair``
   measurements per pair; until then :meth:`GaussianSumTracker.add_scan`
   returns a state of NaN and no covariance.
2. **Hypotheses** — the held scans are initiated
   (:func:`~fgdoppler.estimators.initiation.initiate`) and split into the
   registry's hypotheses: the terms of the window posterior's Gaussian sum
   (at most ``components``) where the initiation is ``nonlinear`` or its
   curvature probe lies beyond ``split_ratio``, its distinct solutions
   where it is ``ambiguous``, else the initiation alone.
   Each gets a tracker started from the window exactly as the registry's
   runner starts it, and an EKF whose predictive likelihood weighs it (the
   EKF is the tracker itself for ``"ekf"``).
3. **Each later scan** — every live hypothesis takes the scan; hypothesis
   :math:`h` weighs

   .. math::

       w_h \propto w_{h,0}\, \prod_{j} p(z_j \mid z_{1:j-1}, h),

   with :math:`w_{h,0}` its prior weight (its term's weight, or
   :math:`e^{-c_h/2}` of its window cost) and the product the EKF's
   predictive likelihood of the measurements since the window; the
   estimate is the mixture

   .. math::

       \bar{\mathbf x} = \sum_h w_h \mathbf x_h, \qquad
       \mathbf P = \sum_h w_h\big(\mathbf P_h + (\mathbf x_h - \bar{\mathbf x})(\mathbf x_h - \bar{\mathbf x})^\top\big).

   A hypothesis whose weight falls below
   :data:`~fgdoppler.estimators.ambiguity.NEGLIGIBLE` stops: it takes no
   further scans and weighs nothing from then on.  (The registry, with all
   the data at hand, stops a hypothesis only where its weight stays below
   that for good; the two agree unless a weight of :math:`10^{-12}`
   recovers.)

4. **Restarts** (``settings.restarts``, on by default, with a zone) — at
   the registry's checkpoints (each time the number of measurements since
   the start has grown by :data:`~fgdoppler.estimators.restart.GROWTH`,
   :func:`~fgdoppler.estimators.restart.checkpoint_counts`)
   the mixture is tested against the best fit of all the data so far
   (:func:`~fgdoppler.estimators.restart.fresh_start`); where each lies
   outside the other's 99.9 % region, the hypotheses are replaced by those
   of the new initiation, started on all the data up to the checkpoint.
   For this the tracker keeps every measurement (without restarts it keeps
   none beyond the warm-up).

Fed the same scans, the filtered estimates equal ``run_estimator``'s from the
same initiation (tests: ``tests/estimators/test_gaussian_sum.py``).  After
a restart a graph tracker agrees with the registry only roughly — 3 mm on
case a 5 km run 32, 1.0 m (its error: 315 m) on the three-pair scenario of
``tests/test_invariance.py`` — because the two mixtures at the checkpoint
differ by rounding and hypotheses weighing < 1e-12, and the restart's
window split (sampled) and iSAM2's relinearisation thresholds are not
continuous in their inputs; the EKF agrees to 5e-9 m on run 32 (to the bit
before restarts carried the running estimate along, which adds the
mixture's rounding to the restart's start).

With the fixed-lag smoother, :meth:`GaussianSumTracker.lagged` gives each
state once it is ``lag`` old, mixed with the weights of the data it has
read (the scans up to one lag after its time), as the registry mixes it:
without restarts, the two agree.  :meth:`GaussianSumTracker.finish` solves the whole trajectory;
after a restart the times before it come from the hypotheses it replaced,
solved on the data up to the restart (the registry's trajectory there has
seen the whole recording).  What this tracker does not give is the verdict,
which needs the whole recording: call :func:`fgdoppler.track` on it
afterwards.  Like the trackers it holds, it computes in the model's
computation frame (:mod:`fgdoppler.estimators.local`) and answers in the
user's coordinates.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import logsumexp

from fgdoppler.estimators.ambiguity import NEGLIGIBLE, mixture_moments
from fgdoppler.estimators.ekf import ExtendedKalmanFilter
from fgdoppler.estimators.fixed_lag import FixedLagTracker
from fgdoppler.estimators.initiation import Initiation, InitiationSettings, initiate
from fgdoppler.estimators.isam2 import ISAM2Tracker
from fgdoppler.estimators.local import LocalFrame
from fgdoppler.estimators.registry import hypotheses_of
from fgdoppler.estimators.restart import checkpoint_counts, fresh_start
from fgdoppler.estimators.settings import (
    EKFSettings,
    FixedLagSettings,
    GaussianSumSettings,
    ISAM2Settings,
)
from fgdoppler.estimators.verdict import Event
from fgdoppler.estimators.warmup import WarmUp
from fgdoppler.estimators.window import feed_from_window_start, start_prior
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements, scan_time
from fgdoppler.models.observation import check_channels
from fgdoppler.models.tracking import TrackingModel, as_tracking_model

__all__ = ["GaussianSumTracker"]

FloatArray = NDArray[np.float64]
Name = Literal["ekf", "isam2", "fixed-lag"]

_SETTINGS: dict[str, type[GaussianSumSettings]] = {
    "ekf": EKFSettings, "isam2": ISAM2Settings, "fixed-lag": FixedLagSettings}


@dataclass
class _Hypothesis:
    """One term: its weighting EKF, its tracker (``None`` for the EKF itself), its prior log-weight."""

    init: Initiation
    ekf: ExtendedKalmanFilter
    tracker: ISAM2Tracker | FixedLagTracker | None
    logw0: float
    x: FloatArray
    P: FloatArray | None
    alive: bool = True


class GaussianSumTracker:
    """The registry's Gaussian sum of ``estimator``, fed scan by scan (module docstring).

    Parameters
    ----------
    model
        Observation and motion model (or a geometry, with the default models).
    estimator
        ``"isam2"`` (default), ``"fixed-lag"`` or ``"ekf"``: the tracker run
        from each hypothesis.
    settings
        That estimator's settings (:class:`~fgdoppler.estimators.settings.ISAM2Settings`,
        :class:`~fgdoppler.estimators.settings.FixedLagSettings`,
        :class:`~fgdoppler.estimators.settings.EKFSettings`); their
        ``components`` bounds the Gaussian sum, their gate and Huber loss
        apply to every hypothesis and its weighting EKF, and ``restarts``
        to the online re-initiation (step 4).  The trackers' own warm-up is
        not used: each starts from a window.
    initiation
        How the held window is initiated (:class:`~fgdoppler.estimators.initiation.InitiationSettings`,
        in the model's coordinates: a half plane for sensors on one line, the
        Huber loss for data with outliers), as ``fd.track(initiation=...)``.
    warmup_seconds, warmup_per_pair
        The window to initiate from: held scans spanning this long and
        holding this many measurements per pair (defaults: the initiation
        window of :func:`fgdoppler.track`).

    Raises
    ------
    ValueError
        For an unknown ``estimator`` or a warm-up that holds nothing.
    TypeError
        If ``settings`` belong to another estimator.
    """

    def __init__(self, model: TrackingModel | Geometry, estimator: Name = "isam2",
                 settings: GaussianSumSettings | None = None, *, initiation: InitiationSettings | None = None,
                 warmup_seconds: float = 4.5, warmup_per_pair: int = 10) -> None:
        if estimator not in _SETTINGS:
            raise ValueError(f"estimator must be one of {', '.join(_SETTINGS)}, got {estimator!r}")
        cls = _SETTINGS[estimator]
        settings = settings if settings is not None else cls()
        if type(settings) is not cls:
            raise TypeError(f"{estimator} takes {cls.__name__}, got {type(settings).__name__}")
        if not (np.isfinite(warmup_seconds) and warmup_seconds >= 0) or isinstance(warmup_per_pair, bool) \
                or not isinstance(warmup_per_pair, int) or warmup_per_pair < 0:
            raise ValueError("warmup_seconds must be a finite number >= 0 and warmup_per_pair a whole number >= 0")
        if warmup_seconds == 0 and warmup_per_pair == 0:
            raise ValueError("the Gaussian sum is built from a window: warmup_seconds or warmup_per_pair must be > 0")
        self.estimator: Name = estimator
        self.settings = settings
        self.local, self.tracking_model = LocalFrame.of(as_tracking_model(model))
        initiation = initiation or InitiationSettings()
        self._initiation_settings = initiation if self.local.frame is None else initiation.in_frame(self.local.frame)
        self.warmup = WarmUp(seconds=float(warmup_seconds), per_pair=warmup_per_pair,
                             n_channels=self.tracking_model.observation.n_channels)
        self.events: list[Event] = []
        self._init: Initiation | None = None  # the held window's initiation, in the computation frame
        self._hyps: list[_Hypothesis] = []
        # hypothesis sets replaced by a restart, with the time each stopped (their trajectories end there)
        self._retired: list[tuple[float, list[_Hypothesis]]] = []
        self.t: float | None = None
        self._restarts = bool(settings.restarts) and self.tracking_model.zone is not None
        # every scan since the first, for the restarts' refits (none kept without restarts)
        self._kept: list[tuple[float, NDArray[np.intp], FloatArray, FloatArray]] = []
        self._count = 0
        self._next_checkpoint: Iterator[int] = iter(())
        self._checkpoint_at = 0
        # fixed-lag: lagged mixtures emitted so far, and the next state index of the current set to emit
        self._lagged: list[tuple[float, FloatArray, FloatArray | None]] = []
        self._lagged_next = 0

    # -- public -------------------------------------------------------------------
    @property
    def warming_up(self) -> bool:
        """Whether scans are still held (no estimate yet)."""
        return self._init is None

    @property
    def initiation(self) -> Initiation | None:
        """The initiation of the held window (``None`` while warming up), in the model's coordinates.

        It keeps the exact copy computed in the computation frame, so
        ``run_estimator(name, recording, model, tracker.initiation)`` starts
        where this tracker started.
        """
        if self._init is None or self.local.frame is None:
            return self._init
        frame = self.local.frame
        return replace(self._init.transformed(frame, to_world=True), computed_in=(frame, self._init))

    @property
    def weights(self) -> FloatArray:
        """Current weight of every hypothesis (0 for a stopped one; empty while warming up)."""
        if not self._hyps:
            return np.zeros(0)
        return self._weights()

    @property
    def mode(self) -> tuple[FloatArray, FloatArray | None]:
        """The newest estimate of the heaviest hypothesis alone (the mixture's most likely term).

        Raises
        ------
        ValueError
            While warming up.
        """
        h = self._heaviest()
        return self.local.out(h.x, h.P)

    @property
    def nis(self) -> FloatArray:
        """The gate's log of the heaviest hypothesis's tracker: ``(m, 4)``, time, pair, NIS, accepted (1/0).

        Raises
        ------
        ValueError
            While warming up.
        """
        h = self._heaviest()
        return (h.ekf if h.tracker is None else h.tracker).gate.as_array()

    def lagged(self) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """``"fixed-lag"`` only: every state that has left the lag window so far, as ``(times, states, covariances)``.

        Each state is the mixture of the live hypotheses' lagged estimates
        (:attr:`FixedLagTracker.lagged <fgdoppler.estimators.fixed_lag.FixedLagTracker>`:
        the state as estimated when it was ``lag`` old, at the last scan
        before it left the window), weighted by the same data: the scans up
        to one lag after its time, as the registry weighs its lagged
        mixture.  Covariances are ``None`` if any is indeterminate.

        Raises
        ------
        TypeError
            For ``"isam2"`` and ``"ekf"``.
        """
        if self.estimator != "fixed-lag":
            raise TypeError(f"{self.estimator} has no lag: its filtered estimates are what add_scan returns")
        n = self.tracking_model.n
        if not self._lagged:
            return np.zeros(0), np.zeros((0, n)), np.zeros((0, n, n))
        times = np.array([t for t, _, _ in self._lagged])
        states = np.array([x for _, x, _ in self._lagged])
        covs = None if any(P is None for _, _, P in self._lagged) else np.array([P for _, _, P in self._lagged])
        x_out, P_out = self.local.out(states, covs)
        return times, x_out, P_out

    def add_scan(self, t: float, channels: ArrayLike, z: ArrayLike,
                 sigma: ArrayLike) -> tuple[FloatArray, FloatArray | None]:
        """Add the measurements of one time; returns the mixture's filtered ``(x, P)``.

        While warming up, a state of NaN and no covariance; the scan that
        completes the warm-up returns the mixture at the window's end.

        Raises
        ------
        ValueError
            If ``t`` is not after the previous scan, a channel is not one of
            the model's pairs, or a Doppler or sigma is not a finite number
            (sigma > 0).
        """
        t = scan_time(t, self.t)
        if self._init is None:
            if self.warmup.hold(self.tracking_model.observation, t, channels, z, sigma, None):
                self._start()
                return self._mixture()
            return np.full(self.tracking_model.n, np.nan), None
        zz = np.asarray(z, dtype=float).reshape(-1)
        # refused before any hypothesis sees it (a bad value would stop them all at once), and in
        # pair order, the order in which the registry's runners take a scan
        scan = Measurements.from_scans([t], [channels], [zz], [np.broadcast_to(sigma, zz.shape)])
        check_channels(self.tracking_model.observation, scan)
        c, zz, ss = scan.pair, scan.doppler, scan.sigma
        self.t = t
        # the states this scan pushes out of a fixed-lag window were last smoothed without it:
        # they are mixed with the weights of the data up to the scan before
        before = _live(self._hyps) if self.estimator == "fixed-lag" else None
        for h in self._hyps:
            if not h.alive:
                continue
            h.ekf.add_scan(self.t, c, zz, ss)
            if h.tracker is None:
                h.x, h.P = h.ekf.x.copy(), h.ekf.P.copy()
            else:
                # the trackers hold the model already moved into its frame: their answers are local
                h.x, h.P = h.tracker.add_scan(self.t, c, zz, ss)
        self._stop_negligible()
        if before is not None:
            self._emit_lagged(*before)
        if self._restarts:
            self._kept.append((self.t, c, zz, ss))
            self._count += c.size
            if c.size and self._count >= self._checkpoint_at:
                while self._count >= self._checkpoint_at:  # several counts in one scan: one check
                    self._checkpoint_at = next(self._next_checkpoint)
                self._checkpoint()
        return self._mixture()

    def finish(self) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """The whole trajectory ``(times, states, covariances)``: the live trackers' mixture.

        Each live hypothesis's tracker is solved to convergence — iSAM2's
        smoothed trajectory (:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker.finish`),
        the fixed-lag smoother's lagged one (every state as estimated when
        it was ``lag`` old, :meth:`~fgdoppler.estimators.fixed_lag.FixedLagTracker.finish`) —
        and the trajectories are mixed, on the times all of them hold, as
        the registry mixes them: iSAM2's with the final weights; the
        fixed-lag smoother's states already given by :meth:`lagged` as they
        were given there (weighted by the data up to one lag after them),
        the rest, still in the window, with the final weights.

        Raises
        ------
        TypeError
            For ``"ekf"``, which keeps no trajectory.
        ValueError
            While warming up with nothing to start from.
        """
        if self.estimator == "ekf":
            raise TypeError("the EKF keeps no trajectory: its filtered estimates are what add_scan returned")
        if self._init is None:
            if not self.warmup.times:
                raise ValueError("no scan was added")
            self._start()
        times, mean, cov = _set_trajectory(self._hyps)
        # after a restart the new hypotheses' graphs may start later (a posterior term starts at its
        # checkpoint): the earlier times come from the set it replaced, solved on the data it had
        for _, hyps in reversed(self._retired):
            t_old, m_old, c_old = _set_trajectory(hyps)
            keep = t_old < times[0] - 1e-9
            if np.any(keep):
                times, mean = np.concatenate([t_old[keep], times]), np.concatenate([m_old[keep], mean])
                cov = None if cov is None or c_old is None else np.concatenate([c_old[keep], cov])
        if self._lagged:  # fixed-lag: the states already given keep the weights they were given with
            given = {t: (x, P) for t, x, P in self._lagged}
            at = [i for i, t in enumerate(times.tolist()) if t in given]
            mean = mean.copy()
            mean[at] = [given[times[i]][0] for i in at]
            if cov is not None and all(given[times[i]][1] is not None for i in at):
                cov = cov.copy()
                cov[at] = [given[times[i]][1] for i in at]
            else:
                cov = None
        x_out, P_out = self.local.out(mean, cov)
        return times, x_out, P_out

    # -- internals ------------------------------------------------------------------
    def _start(self) -> None:
        """Initiate the held scans and start the hypotheses from them."""
        window = self.warmup.measurements()
        if not len(window.time):
            raise ValueError("the warm-up holds no measurement: nothing to initiate from")
        init = initiate(window, self.tracking_model, self._initiation_settings)
        self._hyps = self._hypotheses(window, init)
        self._init = init
        self.t = self.warmup.times[-1]
        if self._restarts:
            self._kept = [(t, c, z, s) for t, c, z, s in zip(self.warmup.times, self.warmup.channels, self.warmup.z,
                                                             self.warmup.sigma, strict=True)]
            # the registry's checkpoints: each time the count since the start has grown by GROWTH
            self._count = len(window.time)
            self._next_checkpoint = checkpoint_counts(self._count)
            self._checkpoint_at = next(self._next_checkpoint)
        if len(self._hyps) > 1:
            self.events.append(Event(time=self.t, message=(
                f"{len(self._hyps)} hypotheses from the initiation of the first {self.t - self.warmup.times[0]:g} s")))

    def _hypotheses(self, window: Measurements, init: Initiation) -> list[_Hypothesis]:
        """One tracker and one weighting EKF per hypothesis of ``init`` (whose window ``window`` holds)."""
        model, st = self.tracking_model, self.settings
        hyps, prior_w = hypotheses_of(self.estimator, window, model, init, st)
        logw0 = np.log(prior_w) if prior_w is not None else -0.5 * np.array([h.cost for h in hyps])
        ekf_settings = st if isinstance(st, EKFSettings) else EKFSettings.gating_as(st)
        fallback = model.zone.prior()[1] if model.zone is not None else None
        out = []
        for h, lw in zip(hyps, logw0, strict=True):
            P0 = h.P_end if h.P_end is not None else fallback
            if P0 is None:
                raise ValueError("the initiation covariance is indeterminate and the model has no zone to fall back on")
            ekf = ExtendedKalmanFilter(model, h.x_end, P0, h.t_end, ekf_settings)
            tracker: ISAM2Tracker | FixedLagTracker | None = None
            x, P = ekf.x.copy(), ekf.P.copy()
            if isinstance(st, ISAM2Settings | FixedLagSettings):
                if isinstance(st, ISAM2Settings):
                    tracker = ISAM2Tracker(model, st, start_prior(model, h))
                else:
                    tracker = FixedLagTracker(model, st, start_prior(model, h))
                _, xs, Ps = feed_from_window_start(tracker, model, window, h, tracker.events, huber_k=st.huber_k)
                x, P = xs[-1], Ps[-1]
            out.append(_Hypothesis(init=h, ekf=ekf, tracker=tracker, logw0=float(lw), x=x, P=P))
        return out

    def _checkpoint(self) -> None:
        """Test the mixture against the best fit of all the data so far; restart there if they disagree."""
        assert self.t is not None
        old = self._mixture_local()
        if old[1] is None:
            return
        times, pairs, doppler, sigma = zip(*self._kept, strict=True)
        data = Measurements.from_scans(times, pairs, doppler, sigma)
        fresh = fresh_start(data, self.tracking_model, self.settings, (old[0], old[1]), self.t,
                            half_plane=self._initiation_settings.half_plane)
        if fresh is None:
            return
        new_init, message = fresh
        self._retired.append((self.t, self._hyps))
        self._hyps = self._hypotheses(data, new_init)
        self._lagged_next = 0
        self.events.append(Event(time=self.t, message=message))

    def _emit_lagged(self, idx: list[int], w: FloatArray) -> None:
        """Mix the states that every fixed-lag tracker of hypotheses ``idx`` has now let go of (in order, each
        once), with their weights ``w``."""
        live = [tr for i in idx if isinstance(tr := self._hyps[i].tracker, FixedLagTracker)]
        j = self._lagged_next
        while all(j in tr.lagged for tr in live):
            t_j = float(live[0].times[j])
            j += 1
            if self._lagged and t_j <= self._lagged[-1][0] + 1e-9:
                continue  # a restarted set's window repeats times already given
            terms = [tr.lagged[j - 1] for tr in live]
            self._lagged.append((t_j, *_mixed(w, [x for x, _ in terms], [P for _, P in terms])))
        self._lagged_next = j

    def _heaviest(self) -> _Hypothesis:
        if not self._hyps:
            raise ValueError("no estimate yet: the tracker is warming up")
        return self._hyps[int(np.argmax(self._weights()))]

    def _weights(self) -> FloatArray:
        return _weights_of(self._hyps)

    def _stop_negligible(self) -> None:
        w = self._weights()
        for i, h in enumerate(self._hyps):
            if h.alive and w[i] < NEGLIGIBLE:
                h.alive = False
                self.events.append(Event(time=float(self.t or 0.0), message=(
                    f"hypothesis {i} stopped: weight {w[i]:.1e} below {NEGLIGIBLE:.0e}")))

    def _mixture_local(self) -> tuple[FloatArray, FloatArray | None]:
        """The live hypotheses' mixture in the computation frame."""
        idx, w = _live(self._hyps)
        return _mixed(w, [self._hyps[i].x for i in idx], [self._hyps[i].P for i in idx])

    def _mixture(self) -> tuple[FloatArray, FloatArray | None]:
        return self.local.out(*self._mixture_local())


def _live(hyps: list[_Hypothesis]) -> tuple[list[int], FloatArray]:
    """The live hypotheses' indices and their weights, renormalised over them."""
    idx = [i for i, h in enumerate(hyps) if h.alive]
    w = _weights_of(hyps)[idx]
    return idx, w / w.sum()


def _mixed(w: FloatArray, states: list[FloatArray], covs: list[FloatArray | None]
           ) -> tuple[FloatArray, FloatArray | None]:
    """The mixture of the terms (:func:`~fgdoppler.estimators.ambiguity.mixture_moments`); no covariance if any is
    indeterminate."""
    if any(P is None for P in covs):
        return mixture_moments(w, np.array(states))
    return mixture_moments(w, np.array(states), np.array(covs))


def _weights_of(hyps: list[_Hypothesis]) -> FloatArray:
    r"""Each hypothesis's weight, :math:`\propto w_{h,0}` times its EKF's predictive likelihood (0 once stopped)."""
    lw = np.array([h.logw0 + h.ekf.log_likelihood if h.alive else -np.inf for h in hyps])
    return np.exp(lw - logsumexp(lw))


def _set_trajectory(hyps: list[_Hypothesis]) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """The live hypotheses' trajectories mixed with their current weights, on the times all of them hold."""
    idx, w = _live(hyps)
    parts = [_trajectory(hyps[i].tracker) for i in idx]  # type: ignore[arg-type]
    n = min(p[0].size for p in parts)
    return (parts[0][0][-n:],
            *_mixed(np.repeat(w[:, None], n, axis=1), [p[1][-n:] for p in parts],
                    [None if p[2] is None else p[2][-n:] for p in parts]))


def _trajectory(tracker: ISAM2Tracker | FixedLagTracker) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """A tracker's whole trajectory ``(times, states, covariances)``: iSAM2's smoothed, fixed-lag's lagged."""
    if isinstance(tracker, ISAM2Tracker):
        xs, Ps = tracker.finish()
        return np.asarray(tracker.times, dtype=float), xs, Ps
    tracker.finish()
    idx = sorted(tracker.lagged)
    covs = [tracker.lagged[j][1] for j in idx]
    return (np.array([tracker.times[j] for j in idx]), np.array([tracker.lagged[j][0] for j in idx]),
            None if any(c is None for c in covs) else np.array(covs))
