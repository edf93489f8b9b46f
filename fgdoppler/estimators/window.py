"""The initiation window inside the trackers: where it ends, and where trackers that re-solve it start.

Every tracker starts from an :class:`~fgdoppler.estimators.initiation.Initiation`
of the same recording.  The *window* is every measurement at or before the
initiation's ``t_end``; the *stream* is everything after it.  The EKF starts
from the initiation's end state and covariance and processes the stream;
iSAM2 and the fixed-lag smoother take the window into their own graph.

Their graph has the window's measurement and motion factors and the weak
prior, but not the initiation's zone wall
(:func:`fgdoppler.factors.region_factor`).  An iSAM2 update is a single
undamped Gauss–Newton step.  Where the wall held the initiation's start on
the zone's boundary, the tracker's graph is not at its optimum there, and
that one step can overshoot by tens of kilometres (measured: 98 km in case a
at 5 km); the gate then rejects every later measurement.  So the window's
states start at the optimum of the tracker's own window graph, reached by
damped Levenberg–Marquardt (QR) from the initiation's constant-velocity
track (:func:`window_start`).  Where the wall was not active that optimum is
the initiation's own solution and LM stops at once.
"""

from __future__ import annotations

from typing import Protocol

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._text import first_line
from fgdoppler.estimators.initiation import Initiation, lm_params
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.smoother_solve import solve_smoother
from fgdoppler.estimators.verdict import Event
from fgdoppler.factors import X
from fgdoppler.graphs import chain_graph, chain_values
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance, start_task

__all__ = ["StreamingTracker", "feed_from_window_start", "solve_window", "split_window", "window_start"]

FloatArray = NDArray[np.float64]


def split_window(meas: Measurements, t_end: float) -> tuple[Measurements, Measurements]:
    """(window, stream): measurements at or before ``t_end`` and after it."""
    return meas.subset(meas.time <= t_end), meas.subset(meas.time > t_end)


def window_start(model: TrackingModel, window: Measurements, init: Initiation, *, huber_k: float | None = None,
                 max_iterations: int = 100) -> tuple[FloatArray, str | None]:
    r"""States at the window's scan times from which a tracker re-solves the window.

    Minimises the window's chain graph (:func:`solve_window`, with the
    model's weak prior) by Levenberg–Marquardt from
    :math:`\mathbf F(t_k - t_0)\,\hat{\mathbf x}_0`.

    Returns
    -------
    states, note
        ``(n_scans, 4)`` states, and ``None`` or the reason LM failed (the
        constant-velocity track of ``init.x_start`` is returned then).
    """
    guesses = model.motion.propagate(init.x_start, window.scans().times - init.t_start)
    return solve_window(model, window, guesses, prior=model.prior(), huber_k=huber_k, max_iterations=max_iterations)


#: Windows of more scans than this are re-solved by the offline smoother's O(N) solver, smaller ones by GTSAM's LM.
LARGE_WINDOW = 256


def solve_window(model: TrackingModel, window: Measurements, guesses: ArrayLike, *,
                 prior: tuple[ArrayLike, ArrayLike] | None, huber_k: float | None = None,
                 max_iterations: int = 100) -> tuple[FloatArray, str | None]:
    r"""Levenberg–Marquardt (QR) on the window's chain graph with ``prior`` on its first state.

    Minimises the offline smoother's objective over the window alone,

    .. math::

        \sum_k \rho\big(\|\mathbf z_k - \mathbf h(\mathbf x_k)\|^2_{\mathbf R_k}\big)
        + \sum_k \|\mathbf x_{k+1} - \mathbf F_k \mathbf x_k\|^2_{\mathbf Q_k}
        + \|\mathbf x_0 - \bar{\mathbf x}\|^2_{\bar{\mathbf P}}.

    Up to :data:`LARGE_WINDOW` scans (every initiation window, every
    recording of the paper) by GTSAM's optimiser over the graph's
    ``CustomFactor`` s (:func:`~fgdoppler.graphs.chain_graph`).  GTSAM
    copies the whole ``Values`` into Python at every factor's callback, so
    an iteration costs O(N²) in the window's N scans (measured by
    ``python -m benchmarks --only scaling``: 64–76 µs per scan and iteration
    at 60 scans, 308–478 at 600, two runs); a larger window — a restart's, which holds
    everything up to its checkpoint — is solved by the offline smoother's
    O(N) solver instead (:func:`~fgdoppler.estimators.smoother_solve.solve_smoother`,
    no zone wall, no covariances; 16.6 instead of 33.9 s for the fixed-lag
    smoother on a 600 s recording restarted at 288 and 432 s).  The two
    minimise the same objective but count iterations differently (an
    iteration of GTSAM's holds all its damping trials, the smoother's
    counts each), so in a long flat valley that neither finishes in
    ``max_iterations`` they stop at different points.

    ``guesses`` holds one state per scan of ``window``.  Returns the states
    and ``None``, or the guesses and the reason LM failed.
    """
    g = np.asarray(guesses, dtype=float).reshape(-1, model.n)
    try:
        if len(g) > LARGE_WINDOW:
            settings = SmootherSettings(huber_k=huber_k, max_iterations=max_iterations, covariances=False,
                                        region_bound=False, sampled_covariance=False)
            states = solve_smoother(window, model, g, settings, prior=prior).states
        else:
            graph, _ = chain_graph(window, model.observation, model.motion, prior=prior, huber_k=huber_k)
            result = gtsam.LevenbergMarquardtOptimizer(graph, chain_values(g), lm_params(max_iterations)).optimize()
            states = np.array([result.atVector(X(k)) for k in range(len(g))])
    except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:  # ValueError: a state on a sensor
        return g, f"window start: LM failed ({first_line(exc)}); starting on the CV track"
    if not np.all(np.isfinite(states)):
        return g, "window start: LM gave non-finite states; starting on the CV track"
    return states, None


def start_prior(model: TrackingModel, init: Initiation) -> tuple[FloatArray, FloatArray] | None:
    """The prior of a streaming tracker's first state: the summarised window, or the model's weak prior."""
    if init.window_summarised:
        if init.P_end is None:
            raise ValueError("a summarised window needs its covariance P_end")
        return np.asarray(init.x_end, dtype=float), np.asarray(init.P_end, dtype=float)
    return model.prior()


class StreamingTracker(Protocol):
    """What :func:`feed_from_window_start` needs from a tracker (iSAM2 and fixed-lag implement it)."""

    def add_window(self, times: ArrayLike, channels: list[ArrayLike], z: list[ArrayLike], sigma: list[ArrayLike],
                   guesses: ArrayLike) -> tuple[FloatArray, FloatArray | None]: ...

    def add_scan(self, t: float, channels: ArrayLike, z: ArrayLike,
                 sigma: ArrayLike) -> tuple[FloatArray, FloatArray | None]: ...


def feed_from_window_start(
    tracker: StreamingTracker, model: TrackingModel, measurements: Measurements, init: Initiation,
    events: list[Event], *, huber_k: float | None = None, max_iterations: int = 100,
    progress: Progress | None = None, name: str = "tracking",
) -> tuple[list[float], list[FloatArray], list[FloatArray | None]]:
    """Feed the initiation window (one call, states from :func:`window_start`), then every later scan.

    A failed LM start is recorded in ``events`` (the tracker's list).
    ``progress`` gets a task ``name`` with one step for the window and one
    per later scan.  A term of a Gaussian sum (``init.window_summarised``)
    starts with one state at ``t_end`` instead, with no measurements: the
    tracker holds that term as the prior of its first state
    (:func:`start_prior`).
    Returns the filtered ``(times, states, covariances)`` from the window's end on.
    """
    window, stream = split_window(measurements, init.t_end)
    times: list[float] = []
    states: list[FloatArray] = []
    covs: list[FloatArray | None] = []
    ws = window.scans()
    ss = stream.scans()
    start_task(progress, name, len(ss) + (1 if len(ws) else 0))
    if init.window_summarised:
        x, P = tracker.add_window(np.array([init.t_end]), [np.empty(0, dtype=np.intp)], [np.empty(0)],
                                  [np.empty(0)], np.asarray(init.x_end, dtype=float)[None])
        times.append(float(init.t_end))
        states.append(x)
        covs.append(P)
        advance(progress)
    elif len(ws):
        start, note = window_start(model, window, init, huber_k=huber_k, max_iterations=max_iterations)
        if note:
            events.append(Event(time=init.t_start, message=note))
        rows = [ws.rows(k) for k in range(len(ws))]
        x, P = tracker.add_window(ws.times, [window.pair[r] for r in rows], [window.doppler[r] for r in rows],
                                  [window.sigma[r] for r in rows], start)
        times.append(float(ws.times[-1]))
        states.append(x)
        covs.append(P)
        advance(progress)
    for k in range(len(ss)):
        sl = ss.rows(k)
        x, P = tracker.add_scan(ss.times[k], stream.pair[sl], stream.doppler[sl], stream.sigma[sl])
        times.append(float(ss.times[k]))
        states.append(x)
        covs.append(P)
        advance(progress)
    return times, states, covs
