r"""Does the smoother's Laplace covariance describe a long recording's likelihood?  A probe of the whole track.

The smoother's covariance is the Laplace approximation: the marginals of the
inverse Hessian of its cost at the optimum.  Where the likelihood of the
track is a thin curved valley, the marginal of a state is a straight, thin
ellipse tangent to it, and the truth, somewhere along the curve, lies many
of its standard deviations across it.  On recordings up to
:data:`~fgdoppler.estimators.spread.MAX_SPAN` the first state's posterior is
sampled under constant velocity (:mod:`~fgdoppler.estimators.spread`), and a
bend the samples find is carried along the track; on longer ones the process
noise moves the track too far for a constant-velocity posterior to be the
smoother's, and nothing examined the Laplace covariance there.

Measured on the paper's case a geometry (a target from (25, 3) km at
(20, −60) m/s for 600 s, sampled every 0.5 s, the truth drawn with process
noise :math:`q = 0.05` m²/s³ and the smoother told so; eight recordings):
the smoother was ``ok`` in all eight, 140–1,763 m off (RMSE), and its
run-averaged NEES was 18–37 in three (final NEES 30–119).  At the last
state its position σ was 1.7–1.9 km along the major axis and 7 m across it,
and the truth lay off that axis on a parabola: 36, 53 and 76 m across at
1.9, 1.9 and 2.8 km along (5–10 σ across, 1–1.5 σ along), the same side on
both sides — a valley of curvature radius 35–52 km, about the target's
distance from the sensors.

The probe of :mod:`~fgdoppler.estimators.curvature` reads that bend on the
whole track.  At state :math:`k` it takes the step of one standard
deviation along the major axis of the position's marginal,
:math:`\boldsymbol\delta_k` (:func:`~fgdoppler.estimators.curvature.probe_axis`),
and moves every other state to its conditional mean given it under the
Laplace approximation: the solution :math:`\boldsymbol\Delta` of the
linearised system at the optimum with a zero right-hand side and
:math:`\mathbf x_k` held at :math:`\boldsymbol\delta_k`
(:func:`conditional_step`; one chain solve).  Under the quadratic model the
cost then rises by :math:`\lVert\mathbf A\boldsymbol\Delta\rVert^2 = 1`
(computed, not assumed), by 9 at :math:`\pm 3\boldsymbol\Delta`; the
probe's ratio is the smaller of the two rises over that
(:func:`trajectory_ratio`).  On those eight recordings it was 1.5–2.4 at
the first state, 88–142 at the middle one and 265–395 at the last: the
straight line leaves the valley within three standard deviations.  Beyond
:data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` (either way) at the
first, middle or last state (:data:`PROBED`) the smoother reports its
Laplace track and covariances unchanged with a ``"doubtful"``
``nonlinear`` finding (:func:`long_track_reason`), as it does where the
process noise forbids sampling a shorter recording
(:func:`~fgdoppler.estimators.spread._untrusted_laplace`).  Like that
finding it is the probe's, not the NEES's: the five of the eight whose
truth happened to lie near the axis (NEES 1.8–7.2) are flagged too,
because their covariance misstates the valley as much.  Each probe costs
one chain solve and five evaluations of the cost (0.02–0.03 s on 1,201
states).
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from fgdoppler._text import distance_text, time_text
from fgdoppler.estimators.curvature import CURVATURE_LIMIT, PROBE_SIGMAS, probe_axis, rises_along
from fgdoppler.estimators.marginals import chain_solve
from fgdoppler.estimators.smoother_solve import _Problem
from fgdoppler.estimators.verdict import Reason
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel

__all__ = ["HELD", "PROBED", "conditional_step", "long_track_reason", "trajectory_ratio"]

FloatArray = NDArray[np.float64]

#: The states probed, as fractions of the track's length: the first, the middle and the last.
PROBED: tuple[float, ...] = (0.0, 0.5, 1.0)
#: How many times the data's own information about the held state the hold weighs (its square):
#: the step reaches :math:`(1 + 10^{-8})^{-1}` of the one asked.
HELD = 1e4


def _problem(measurements: Measurements, model: TrackingModel, times: FloatArray, huber_k: float | None
             ) -> _Problem:
    """The smoother's cost without the zone wall (as its covariances), with the zone's weak prior."""
    return _Problem(model, measurements, huber_k, model.prior(), np.asarray(times, dtype=float))


def conditional_step(prob: _Problem, states: FloatArray, covariance: FloatArray, k: int
                     ) -> tuple[FloatArray, float, float]:
    r"""The whole track's step when state ``k`` moves one standard deviation along its position's major axis.

    The linearised system at ``states`` with a zero right-hand side and
    state ``k`` held at :math:`\boldsymbol\delta_k`
    (:func:`~fgdoppler.estimators.curvature.probe_axis` of ``covariance``,
    its Laplace marginal) by a factor :data:`HELD` times the data's own
    information about it: every other state at its conditional mean.

    Returns
    -------
    tuple
        The step ``(n, 2d)``, the quadratic model's rise
        :math:`\lVert\mathbf A\boldsymbol\Delta\rVert^2` (1 where
        ``covariance`` is the system's marginal) and the position σ along the
        axis.
    """
    A_prev, A_next, b, A0, b0, _ = prob._blocks(states, 0.0, False, prob.meas.doppler)
    gfg = prob._factors(A_prev, A_next, np.zeros_like(b), A0, np.zeros_like(b0))
    delta, sd = probe_axis(covariance)
    hold = HELD * np.linalg.inv(np.linalg.cholesky(covariance))
    gfg.add(gtsam.JacobianFactor(prob.keys[k], hold, hold @ delta, gtsam.noiseModel.Unit.Create(delta.size)))
    step, _ = chain_solve(gfg, prob.keys, covariances=False)
    rows = np.einsum("kij,kj->ki", A_prev[1:], step[:-1]) + np.einsum("kij,kj->ki", A_next[1:], step[1:])
    first = A0 @ step[0]
    return step, float(first @ first + np.sum(rows**2)), sd


def trajectory_ratio(prob: _Problem, states: FloatArray, covariance: FloatArray, k: int
                     ) -> tuple[float, float, float, float, float]:
    """The probe's ratio at state ``k`` (module docstring), the two rises, the quadratic model's rise at three
    standard deviations and the position σ along the axis."""
    step, quad, sd = conditional_step(prob, states, covariance, k)
    lo, hi = rises_along(prob.data_cost, np.asarray(states, dtype=float), step)
    predicted = PROBE_SIGMAS**2 * quad
    return min(lo, hi) / predicted, lo, hi, predicted, sd


def long_track_reason(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                      covariances: FloatArray, *, huber_k: float | None = None) -> Reason | None:
    """A ``"doubtful"`` ``nonlinear`` finding where the probe at one of :data:`PROBED` strays beyond
    :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` (either way; the farthest is named), else ``None``
    (also where a linear solve fails: nothing is said then)."""
    prob = _problem(measurements, model, times, huber_k)
    x = np.asarray(states, dtype=float)
    found: list[tuple[float, int, float, float, float, float]] = []
    for f in PROBED:
        k = round(f * (prob.n - 1))
        try:
            ratio, lo, hi, predicted, sd = trajectory_ratio(prob, x, np.asarray(covariances[k], dtype=float), k)
        except (RuntimeError, ValueError, np.linalg.LinAlgError):
            continue
        if np.isfinite(ratio) and ratio > 0.0:
            found.append((ratio, k, lo, hi, predicted, sd))
    if not found:
        return None
    ratio, k, lo, hi, predicted, sd = max(found, key=lambda r: abs(np.log(r[0])))
    if 1.0 / CURVATURE_LIMIT <= ratio <= CURVATURE_LIMIT:
        return None
    shape = ("a curved valley, not the straight ellipsoid of the smoother's covariance" if ratio > 1.0 else
             "flatter than the smoother's covariance says")
    return Reason(code="nonlinear", status="doubtful", message=(
        f"the likelihood is {shape}: at t = {time_text(float(prob.times[k]))} s, {PROBE_SIGMAS:g} standard "
        f"deviations ({distance_text(PROBE_SIGMAS * sd, km_decimals=2)}) along the position's major axis, the rest "
        f"of the track following, raise the cost by {lo:.3g} and {hi:.3g} where its quadratic model predicts "
        f"{predicted:.3g}; over a recording this long no posterior samples are drawn, so the Laplace covariance is "
        "reported, and it misstates the uncertainty (poor observability)"))
