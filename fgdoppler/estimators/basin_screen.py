r"""The particle estimators' cheap screen for a wrong basin: the start's solutions refined on the data so far.

The particle estimators test themselves for a restart
(:mod:`fgdoppler.estimators.restart`) at the checkpoints where the data
since the last one surprise them (:func:`~fgdoppler.estimators.restart.surprised`).
A wrong basin that the data leave *slowly* never surprises them: on the
random 3-D layouts of ``studies/filters_3d.py`` (draw 9) the particles sat
in basins 62 km from the truth, and between the checkpoints at 16.5 and
25 s their normalised innovations summed to 80.4 against a quantile of
88.0, while the truth's basin already fitted the data better by a cost of
34.5 (:math:`e^{17}` in likelihood).  Testing at every checkpoint finds
such runs but makes the test's grid and factor-graph fits at every one,
which costs six times the time.

The screen looks for the mistake itself.  At a checkpoint :math:`t_c`
every measurement so far, :math:`z_j` at :math:`t_j` on pair :math:`p_j`
with :math:`\sigma_j`, is fitted by constant-velocity tracks from the
initiation's start time,

.. math::

    c(\mathbf x_0) = \sum_j \big((z_j - h_{p_j}(\mathbf F(t_j)\mathbf x_0))/\sigma_j\big)^2,

the paper's batch map :math:`\mathbf g(\mathbf x_0)` (Eq. 11).  Each of the
initiation's solutions (its estimate, alternatives and grid candidates)
and the running estimate carried back to the start,
:math:`\mathbf F(t_0 - t_c)\hat{\mathbf x}(t_c)`, climbs to the least
:math:`c` of its basin (:func:`refined_costs`).  The screen fires where a
start's basin costs less than the running estimate's by more than
:data:`~fgdoppler.estimators.restart.MODE_MARGIN`, the margin the full test
asks of a fresh solution; the full test then decides as before.  All the
climbs of a checkpoint are one Levenberg–Marquardt on the stacked starts:
each iteration is one call of the vectorised model.

On the accuracy benchmark's recordings the screen never fired
(``python studies/restart_screen.py``: 720 screens per estimator, every
track the same to the bit, 1.4–3.9 % more CPU; ``python -m
benchmarks.same_as_records``: all 600 runs of both seeds the same to the
bit); on 40 random 3-D draws it fired at 5 and 3 of 236 screens and brought
the RMS error over the draws from 18.7 to 17.5 km (``particle``, 5 draws
closer, none farther) and 18.5 to 17.6 km (``map``, 3 closer, none
farther) (docs/concepts.md, "The basin screen, built in").
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.initiation import Initiation
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import StackedTimes, _cv
from fgdoppler.models.tracking import TrackingModel

__all__ = ["DECREMENT", "ITERATIONS", "basin_screen", "refined_costs"]

FloatArray = NDArray[np.float64]

#: Levenberg–Marquardt iterations of :func:`refined_costs` at most (measured: 100 reach SciPy's minima to 0.02
#: in cost on the 3-D draws, where 40 left a basin 12 short).
ITERATIONS = 100
#: A start of :func:`refined_costs` has settled where the local quadratic model of its cost falls by no more.
DECREMENT = 1e-6


def refined_costs(geometry: Geometry, starts: FloatArray, times: StackedTimes, z: FloatArray, sigma: FloatArray,
                  *, iterations: int = ITERATIONS) -> FloatArray:
    r"""The least data cost in the basin of each start: all starts climbed at once.

    Levenberg–Marquardt on :math:`c(\mathbf x_0) = \lVert\mathbf r\rVert^2`,
    :math:`\mathbf r = (\mathbf z - \mathbf g(\mathbf x_0))/\boldsymbol\sigma`,
    each start with its own damping :math:`\lambda`: the step solves
    :math:`(\mathbf A + \lambda\mathbf D)\,\boldsymbol\delta = \mathbf J_w'\mathbf r`,
    :math:`\mathbf D` the largest diagonal of :math:`\mathbf A` met so far (MINPACK's scaling),
    :math:`\mathbf A = \mathbf J_w'\mathbf J_w`, :math:`\mathbf J_w` the whitened Jacobian of
    :math:`\mathbf g`; a step that lowers the cost is taken and :math:`\lambda`
    divided by 3, otherwise :math:`\lambda` is multiplied by 4.  A start stops
    where its Gauss–Newton decrement :math:`\mathbf b'\mathbf A^{-1}\mathbf b`,
    :math:`\mathbf b = \mathbf J_w'\mathbf r` (what the local quadratic model
    of the cost still falls by), is at most :data:`DECREMENT`, or where its
    :math:`\lambda` passes :math:`10^{10}` (no step lowers the cost).

    Parameters
    ----------
    geometry
        The sensor pairs.
    starts
        Start states ``(K, 2d)`` at the time the ``times`` are counted from.
    times
        Time and pair of every measurement.
    z, sigma
        Measurements and their standard deviations ``(m,)``.
    iterations
        Iterations at most.

    Returns
    -------
    ndarray, shape ``(K,)``
        The least cost found from each start; ``inf`` where the start's track meets a sensor.
    """
    sig = np.asarray(sigma, dtype=float)[None, :]
    zz = np.asarray(z, dtype=float)[None, :]

    def evaluate(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        g, J, mask = _cv(x, geometry, times, jacobian=True, singular="mask")
        assert J is not None
        r = (zz - g) / sig
        cost = np.sum(r * r, axis=1)
        if mask is not None:  # a track through a sensor: the model is undefined there
            cost[np.any(mask, axis=1)] = np.inf
        return r, J / sig[..., None], cost

    x = np.array(starts, dtype=float)
    r, J, cost = evaluate(x)
    lam = np.full(x.shape[0], 1e-3)
    live = np.isfinite(cost)
    eye = np.eye(x.shape[1])
    diag = np.zeros_like(x)
    for _ in range(iterations):
        rows = np.flatnonzero(live)
        if rows.size == 0:
            break
        A = np.einsum("kmi,kmj->kij", J[rows], J[rows])
        b = np.einsum("kmi,km->ki", J[rows], r[rows])
        # MINPACK's scaling: the largest diagonal so far, so a direction whose derivative vanishes on the way
        # (the height above ground sensors, where the Doppler is even in it) stays damped
        diag[rows] = np.maximum(diag[rows], np.einsum("kii->ki", A))
        # floored: a start exactly on the ground has no derivative in height or climb rate at all, and its
        # singular normal matrix must not stop the others' climbs
        floor = 1e-12 * diag[rows].max(axis=1, keepdims=True) + np.finfo(float).tiny
        scale = np.maximum(diag[rows], floor)[:, :, None] * eye
        # the Gauss-Newton decrement b'A^-1 b: how far the local quadratic model still falls
        decrement = np.einsum("ki,ki->k", b, np.linalg.solve(A + 1e-12 * scale, b[..., None])[..., 0])
        step = np.linalg.solve(A + lam[rows, None, None] * scale, b[..., None])[..., 0]
        settled = decrement <= DECREMENT
        live[rows[settled]] = False
        rows, step = rows[~settled], step[~settled]
        trial = x[rows] + step
        rn, Jn, cn = evaluate(trial)
        better = cn < cost[rows]
        took = rows[better]
        x[took], r[took], J[took], cost[took] = trial[better], rn[better], Jn[better], cn[better]
        lam[rows] = np.where(better, lam[rows] / 3.0, lam[rows] * 4.0)
        live &= lam <= 1e10
    return cost


def basin_screen(measurements: Measurements, model: TrackingModel, init: Initiation, margin: float
                 ) -> Callable[[FloatArray, float], bool] | None:
    """``fires(state, t_c)``: whether a start's basin fits the data up to ``t_c`` better than that of ``state``.

    ``state`` is the running (filtered) estimate at ``t_c``; better by more
    than ``margin`` in data cost (module docstring).  ``None`` where the
    observation model is not a geometry's Doppler (no vectorised
    constant-velocity map to climb on).
    """
    geometry = getattr(model.observation, "geometry", None)
    if not isinstance(geometry, Geometry):
        return None
    starts = [init.x_start, *(a.state for a in init.alternatives), *(c.state for c in init.candidates)]

    def fires(state: FloatArray, tc: float) -> bool:
        sel = measurements.time <= tc + 1e-9
        times = StackedTimes(pair=measurements.pair[sel], t=measurements.time[sel] - init.t_start)
        own = model.motion.F(init.t_start - tc) @ state
        costs = refined_costs(geometry, np.array([own, *starts]), times, measurements.doppler[sel],
                              measurements.sigma[sel])
        return bool(np.min(costs[1:]) < costs[0] - margin)

    return fires
