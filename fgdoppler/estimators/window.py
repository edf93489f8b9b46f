"""Where trackers that re-solve the initiation window start its states.

iSAM2 and the fixed-lag smoother take the initiation window into their own
graph — measurement and motion factors and the weak search-region prior, but
not the initiation's region wall (:func:`fgdoppler.factors.region_factor`).
An iSAM2 update is a single undamped Gauss–Newton step.  Where the wall held
the initiation's start on the region's boundary, the tracker's graph is not
at its optimum there, and that one step can overshoot by tens of kilometres
(measured: 98 km in case a at 5 km); the gate then rejects every later
measurement.  So the window's states start at the optimum of the tracker's
own window graph, reached by damped Levenberg–Marquardt (QR) from the
initiation's constant-velocity track.  Where the wall was not active that
optimum is the initiation's own solution and LM stops at once.
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.common import (
    Scans,
    StreamingTracker,
    TrackerSettings,
    feed,
    region_prior,
    split_window,
)
from fgdoppler.estimators.initiation import Initiation, lm_params
from fgdoppler.factors import X, measurement_factor, motion_factor, prior_factor
from fgdoppler.measurements import Measurements
from fgdoppler.models.measurement import MeasurementModel

__all__ = ["feed_from_window_start", "window_start"]

FloatArray = NDArray[np.float64]


def window_start(
    model: MeasurementModel, window: Measurements, init: Initiation, settings: TrackerSettings
) -> tuple[FloatArray, str | None]:
    r"""States at the window's scan times from which a tracker re-solves the window.

    Minimises, by Levenberg–Marquardt from :math:`\mathbf F(t_k - t_0)\,\hat{\mathbf x}_0`,

    .. math::

        \sum_k \lVert \mathbf h(\mathbf x_k) - \mathbf z_k \rVert^2_{\mathbf R_k}
        + \sum_k \lVert \mathbf x_{k+1} - \mathbf F\mathbf x_k \rVert^2_{\mathbf Q}
        + \lVert \mathbf x_0 - \bar{\mathbf x} \rVert^2_{\mathbf P_0}

    (the last term with ``settings.weak_prior``), the window graph of
    :func:`~fgdoppler.estimators.isam2.run_isam2` and
    :func:`~fgdoppler.estimators.fixed_lag.run_fixed_lag`.

    Returns
    -------
    states, note
        ``(n_scans, 4)`` states, and ``None`` or the reason LM failed (the
        constant-velocity track of ``init.x_start`` is returned then).
    """
    scans = Scans.of(window)
    guesses = settings.motion.propagate(init.x_start, scans.times - init.t_start)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for k in range(len(scans)):
        rows = scans.rows(k)
        graph.add(measurement_factor(X(k), model, window.pair[rows], window.doppler[rows], window.sigma[rows],
                                     huber_k=settings.huber_k))
        if k:
            graph.add(motion_factor(X(k - 1), X(k), scans.times[k] - scans.times[k - 1], settings.motion))
        values.insert(X(k), guesses[k])
    if settings.weak_prior:
        graph.add(prior_factor(X(0), *region_prior(settings.grid)))
    try:
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(settings.max_iterations)).optimize()
    except (RuntimeError, ValueError) as exc:  # ValueError: a state on a sensor
        return guesses, f"window start: LM failed ({str(exc).strip().splitlines()[0]}); starting on the CV track"
    states = np.array([result.atVector(X(k)) for k in range(len(scans))])
    if not np.all(np.isfinite(states)):
        return guesses, "window start: LM gave non-finite states; starting on the CV track"
    return states, None


def feed_from_window_start(
    tracker: StreamingTracker, model: MeasurementModel, measurements: Measurements, init: Initiation,
    settings: TrackerSettings, warnings: list[tuple[float, str]],
) -> tuple[list[float], list[FloatArray], list[FloatArray | None]]:
    """:func:`~fgdoppler.estimators.common.feed` with the window's states started at :func:`window_start`.

    A failed LM start is recorded in ``warnings`` (the tracker's list).
    """
    start, note = window_start(model, split_window(measurements, init.t_end)[0], init, settings)
    if note:
        warnings.append((init.t_start, note))
    return feed(tracker, measurements, init, settings, guesses=start)
