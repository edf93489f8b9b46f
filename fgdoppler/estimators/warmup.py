r"""Warm-up of a streaming tracker fed scan by scan from its first scan.

An iSAM2 update is one undamped Gauss–Newton step on a linearisation.  A
tracker fed one scan at a time from a broad prior solves, at its first
updates, a system of two Doppler values per scan for four unknowns: the
linear solution moves the unobserved directions to the prior's mean, tens
of kilometres away, every later factor is linearised there, and the
tracker never comes back.  Measured (paper geometry (a), a well-observed
target, 50 scans/s, streamed from the true state with the model's weak
prior): 45 km off at 0.5 s with a stated standard deviation of 58 m, 6.8 km
off at 5 s; at 20 scans/s the same stream needs the iSAM2 history check to
hold at all.

So a tracker whose first update is a single scan *warms up*: it holds the
scans back, untouched, until ``warmup_seconds`` have passed since the first
and they hold ``warmup_per_pair`` measurements per pair on average (the
initiation window's span and count,
:meth:`~fgdoppler.measurements.Measurements.initiation_window`); then it
solves them together and adds them as one window, as
:func:`~fgdoppler.estimators.window.feed_from_window_start` does after an
initiation.  The window's states are the Levenberg–Marquardt optimum of the
window graph with the tracker's prior (:func:`~fgdoppler.estimators.window.solve_window`),
started from

- the caller's guess of the first state, moved along a constant-velocity
  track, when one was given; or
- the best solution of a multi-start initiation of the window
  (:func:`~fgdoppler.estimators.initiation.initiate`) otherwise, so that a
  tracker fed no guess at all starts like :func:`fgdoppler.track` (but on
  one hypothesis: an ambiguous initiation is logged as an event).

Until then the tracker has no estimate: it returns a state of NaN and no
covariance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.initiation import initiate
from fgdoppler.estimators.settings import StreamingSettings
from fgdoppler.estimators.verdict import Event
from fgdoppler.estimators.window import solve_window
from fgdoppler.measurements import Measurements, scan_time
from fgdoppler.models.observation import MeasurementModel, check_channels
from fgdoppler.models.tracking import TrackingModel

__all__ = ["WarmUp"]

FloatArray = NDArray[np.float64]


@dataclass
class WarmUp:
    """Scans held back until a streaming tracker can start from them together.

    Parameters
    ----------
    seconds
        Span from the first scan the buffer must cover (with the relative
        tolerance of :meth:`~fgdoppler.measurements.Measurements.initiation_window`).
    per_pair
        Measurements per pair on average it must hold
        (``per_pair * n_channels`` in all).
    n_channels
        Number of pairs of the model.
    """

    seconds: float
    per_pair: int
    n_channels: int
    times: list[float] = field(default_factory=list)
    channels: list[NDArray[np.intp]] = field(default_factory=list)
    z: list[FloatArray] = field(default_factory=list)
    sigma: list[FloatArray] = field(default_factory=list)
    guess: FloatArray | None = None

    @classmethod
    def of(cls, settings: StreamingSettings, n_channels: int) -> WarmUp | None:
        """The warm-up ``settings`` ask for, or ``None`` when they switch it off."""
        if not settings.warms_up:
            return None
        return cls(seconds=settings.warmup_seconds, per_pair=settings.warmup_per_pair, n_channels=n_channels)

    def refuse_window(self) -> None:
        """Raise if scans are held: a window must come before any scan.

        Raises
        ------
        ValueError
            If a scan is held.
        """
        if self.times:
            raise ValueError("scans are held in the warm-up: add the window before any scan, or switch the "
                             "warm-up off (warmup_seconds=0, warmup_per_pair=0)")

    def hold(self, model: MeasurementModel, t: float, channels: ArrayLike, z: ArrayLike, sigma: ArrayLike,
             guess: ArrayLike | None) -> bool:
        """Hold one scan; whether the warm-up is complete with it.

        Raises
        ------
        ValueError
            If ``t`` is not after the previous held scan, or a channel is
            outside ``model``.
        """
        t = scan_time(t, self.times[-1] if self.times else None)
        c = np.asarray(channels, dtype=np.intp).reshape(-1)
        zz = np.asarray(z, dtype=float).reshape(-1)
        ss = np.broadcast_to(np.asarray(sigma, dtype=float), zz.shape).copy()
        check_channels(model, Measurements.from_scans([t], [c], [zz], [ss]))
        if not self.times and guess is not None:
            self.guess = np.asarray(guess, dtype=float).copy()
        self.times.append(float(t))
        self.channels.append(c)
        self.z.append(zz)
        self.sigma.append(ss)
        return self.complete

    @property
    def complete(self) -> bool:
        """Whether the held scans span ``seconds`` and hold ``per_pair * n_channels`` measurements."""
        if not self.times:
            return False
        span = self.times[-1] - self.times[0]
        count = sum(c.size for c in self.channels)
        return span >= self.seconds * (1.0 - 1e-9) and count >= self.per_pair * self.n_channels

    def measurements(self) -> Measurements:
        """The held measurements (scans without any are left out)."""
        return Measurements.from_scans(self.times, self.channels, self.z, self.sigma)

    def start(self, model: TrackingModel, prior: tuple[ArrayLike, ArrayLike] | None, *,
              huber_k: float | None, events: list[Event]) -> FloatArray:
        r"""States at every held scan's time from which the tracker adds them as its window.

        The measured scans' states are the window graph's optimum
        (:func:`~fgdoppler.estimators.window.solve_window`); a held scan
        without measurements takes the state of the nearest earlier measured
        scan (the first measured one before that), moved by
        :math:`\mathbf F(\Delta t)`.  Notes (an initiation that is not
        ``"ok"``, a failed LM) go to ``events``.

        Raises
        ------
        ValueError
            If there is neither a guess nor a measurement to start from.
        """
        ts = np.asarray(self.times)
        n_meas = sum(c.size for c in self.channels)
        if n_meas == 0:
            if self.guess is None:
                raise ValueError("the warm-up holds no measurement and the first scan gave no guess: "
                                 "nothing to start from")
            return model.motion.propagate(self.guess, ts - ts[0])
        window = self.measurements()
        scan_times = window.scans().times
        if self.guess is not None:
            guesses = model.motion.propagate(self.guess, scan_times - ts[0])
        else:
            init = initiate(window, model)
            if init.status != "ok":
                events.append(Event(time=float(ts[0]), message=(
                    f"warm-up: the initiation of the first {ts[-1] - ts[0]:g} s is {init.status} ({init.message}); "
                    "the tracker follows its best solution")))
            guesses = model.motion.propagate(init.x_start, scan_times - init.t_start)
        states, note = solve_window(model, window, guesses, prior=prior, huber_k=huber_k)
        if note:
            events.append(Event(time=float(ts[0]), message=f"warm-up: {note}"))
        return model.motion.along(scan_times, states, ts)

