r"""The tracking graphs, built in one place.

Two shapes of graph describe a recording (or a window of it):

``chain_graph``
    One state per scan, joined by constant-velocity motion factors: a
    measurement factor per scan (all of that scan's measurements, one Python
    callback), a motion factor per step and, optionally, a Gaussian prior on
    the first state,

    .. math::

        \sum_k \lVert \mathbf h(\mathbf x_k) - \mathbf z_k \rVert^2_{\mathbf R_k}
        + \sum_k \lVert \mathbf x_{k+1} - \mathbf F\mathbf x_k \rVert^2_{\mathbf Q}
        + \lVert \mathbf x_0 - \bar{\mathbf x} \rVert^2_{\mathbf P_0}.

``cv_graph``
    The paper's exactly-constant-velocity window: one state
    :math:`\mathbf x_0` and the map :math:`\mathbf g(\mathbf x_0)` of every
    measurement (Eq. 11–15), plus the optional prior.

The data factors come first, so the first ``n_data`` factors' error is the
data cost (the χ² statistic) and regularisers appended after them can be
told apart.
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.factors import X, cv_factor, measurement_factor, motion_factor, prior_factor
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import StackedTimes
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import MeasurementModel

__all__ = ["chain_graph", "chain_values", "cv_graph"]

FloatArray = NDArray[np.float64]
Prior = tuple[ArrayLike, ArrayLike]


def chain_graph(
    measurements: Measurements,
    observation: MeasurementModel,
    motion: ConstantVelocity,
    *,
    prior: Prior | None = None,
    huber_k: float | None = None,
) -> tuple[gtsam.NonlinearFactorGraph, int]:
    """A state per scan of ``measurements`` with measurement, motion and (optional) prior factors.

    State ``k`` has key ``X(k)`` and the time of scan ``k``
    (:meth:`~fgdoppler.measurements.Measurements.scans`).

    Returns
    -------
    graph, n_data
        The graph and the number of its data factors (measurement and
        motion), which come before the prior.
    """
    scans = measurements.scans()
    graph = gtsam.NonlinearFactorGraph()
    for k in range(len(scans)):
        rows = scans.rows(k)
        graph.add(measurement_factor(X(k), observation, measurements.pair[rows], measurements.doppler[rows],
                                     measurements.sigma[rows], huber_k=huber_k))
        if k:
            graph.add(motion_factor(X(k - 1), X(k), scans.times[k] - scans.times[k - 1], motion))
    n_data = int(graph.size())
    if prior is not None:
        graph.add(prior_factor(X(0), *prior))
    return graph, n_data


def chain_values(states: ArrayLike) -> gtsam.Values:
    """``Values`` with ``X(k) = states[k]``."""
    values = gtsam.Values()
    for k, s in enumerate(np.asarray(states, dtype=float)):
        values.insert(X(k), s)
    return values


def cv_graph(
    geometry: Geometry,
    times: StackedTimes,
    doppler: ArrayLike,
    sigma: ArrayLike,
    *,
    prior: Prior | None = None,
    huber_k: float | None = None,
) -> tuple[gtsam.NonlinearFactorGraph, int]:
    """The exactly-constant-velocity window on one key ``X(0)`` (``times`` relative to it), and the prior.

    Returns
    -------
    graph, n_data
        The graph and its number of data factors (1).
    """
    graph = gtsam.NonlinearFactorGraph()
    graph.add(cv_factor(X(0), geometry, times, doppler, sigma, huber_k=huber_k))
    if prior is not None:
        graph.add(prior_factor(X(0), *prior))
    return graph, 1
