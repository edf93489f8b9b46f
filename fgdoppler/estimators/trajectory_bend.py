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
straight line leaves the valley within three standard deviations.

Until 2026-12-07 (second change of the day) a ratio beyond
:data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` only made the
answer ``"doubtful"``, its Laplace covariances unchanged.  Now the valley
is followed instead (:func:`valley_profile`): at each probed state whose
ratio lies beyond the limit the caller gives
(:data:`~fgdoppler.estimators.spread.SAMPLING_LIMIT`, 3, as for a sampled
recording) the cost is profiled along the axis — the state's position
held at :data:`NODES` Gauss–Hermite points along it, the rest of the track
at its minimum (Gauss–Newton from the conditional step, one chain solve
per iteration) — and the points' spread about the estimate, weighted by
the profile's own likelihood, gives each state's second moment,

.. math::

    \mathbf M_j = \mathbf P_j - \boldsymbol\Delta_j\boldsymbol\Delta_j^\top
        + \sum_i w_i\,(\mathbf X_{i,j} - \hat{\mathbf x}_j)(\mathbf X_{i,j} - \hat{\mathbf x}_j)^\top,

which is :math:`\mathbf P_j` where the floor is straight and adds the
bend's own variance and offset where it is not.  The reported covariances
are the Laplace ones widened, in every whitened direction, to enclose the
profiles' :math:`\mathbf M` (:func:`~fgdoppler.estimators.spread._widened_stack`;
never narrower).  The finding stays, informational (``"ok"``), where every
profile is trusted — each point found, and the floor's cost rising within
:data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` times the
Gaussian's :math:`\xi^2` at every point — and the state is 2-D.  Otherwise
it is ``"doubtful"``, and the covariances are still widened by what the
profile found (:class:`TrackBend`).  In 3-D one axis profiled does not
follow the second poorly observed direction, the target's rotation about
the sensors' near-collinear line: on the 3-D cell of
``studies/process_noise_share.py`` (four pairs on masts, 60 s, 20 runs)
profiles whose every check passed left run-averaged NEES of 68, 73 and 100
in three runs.  Since 2026-12-07 (evening) the 3-D position is also held on
the product grid of the rule along its two major axes at the farthest
probe's state (:func:`valley_profile` with ``across``, 24 points): on that
cell the smoother's run-averaged NEES went from 35.09 to 19.18 and its
runs beyond the χ²₆ 99.9 % point from 4 to 2, for 1.4 times the CPU
(median 2.6 → 3.6 s a run; docs/concepts.md, "Two axes in 3-D").  The
finding stays ``"doubtful"`` in 3-D.  The same profile, with the same finding, serves a shorter
recording that the process noise keeps from being sampled
(:func:`~fgdoppler.estimators.spread._unsampled_bend`), and widens the
covariances of one sampled beyond trust
(:func:`~fgdoppler.estimators.spread._curved`).

Measured (the smoother from its default initiation, each recording's
truth with the process noise the model is told; the run-averaged NEES of
the 4-D state over t ≥ 10 s, Laplace → widened; a script, not kept:
docs/concepts.md, "The valley followed", says how to rebuild
it):

- the 600 s recordings above, seeds 1–16: mean 12.8 → 4.0 (per
  recording 1.8–54.5 → 1.3–9.3), final NEES 2.4–214 → 0.4–8.8 (beyond the
  χ²₄ 99.9 % point, 18.5: 7 of 16 → none); the last state's root-mean-square
  error across the axis 46–67 m against a Laplace σ of 6.9–7.4 m; the
  finding ``"ok"`` in all sixteen (it was ``"doubtful"``), each profile's
  floor rising 0.78–1.26 times :math:`\xi^2`;
- case b from (25, 2) km at (50, −50) m/s for 400 s, q = 0.01, seeds 1–8:
  mean 3.9 → 3.2, final NEES 0.5–14.9 → 0.4–6.0, the finding ``"ok"`` in
  all eight (floors 0.93–1.07 times :math:`\xi^2`; across 14–16 m
  against 6.2–6.5 m);
- well-observed long tracks (case a 45 km and case b 5 km flown 400 s,
  case a from (25, 3) km at (20, −20) m/s for 600 s, q = 10⁻³, four seeds
  each): ratios within 3, nothing profiled, covariances unchanged;
- the paper's case a 45 km flown 400 s at 5 km altitude (3-D, the zone
  wall holding the start), seeds 1–4: points not found and floors rising
  26–420 times the Gaussian's, so ``"doubtful"`` as before, with the NEES
  577–781 → 4.3–8.4 (7–9 s of CPU, most of it Levenberg–Marquardt on the
  points not found); the same sensors with a target from (25, 3) km at
  3 km altitude, (20, −60, 0) m/s, q = 0.01, seeds 1–4: floors rising
  −23 to 13 times (the profile finds lower costs than the estimate's, which
  the zone wall holds), ``"doubtful"`` as before, NEES 478–982 → 1.9–14.3,
  the widening there tens of kilometres across.

The 5-point rule's second moments equal a 7-point rule's to 0.3 % on the
curved recordings, and on a well-observed track the profile gives the
Laplace covariance back to 0.5–6 % (tests).  Each profile costs four
points of 3–4 Gauss–Newton steps: 0.5 s of CPU for the two or three
profiles of a 1,201-state track.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.polynomial.hermite_e import hermegauss
from numpy.typing import NDArray

from fgdoppler._text import distance_text, time_text
from fgdoppler.estimators.curvature import CURVATURE_LIMIT, PROBE_SIGMAS, probe_axis, rises_along
from fgdoppler.estimators.marginals import chain_solve
from fgdoppler.estimators.smoother_solve import _levenberg_marquardt, _Problem
from fgdoppler.estimators.verdict import Reason, Status
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel

__all__ = ["HELD", "NODES", "PROBED", "PROFILE_ITERATIONS", "PROFILE_TOLERANCE", "TrackBend", "TrackProbe",
           "ValleyProfile", "conditional_step", "probe_state", "track_bend", "valley_profile"]

FloatArray = NDArray[np.float64]

#: The states probed, as fractions of the track's length: the first, the middle and the last.
PROBED: tuple[float, ...] = (0.0, 0.5, 1.0)
#: How many times the data's own information about the held state the hold weighs (its square):
#: the step reaches :math:`(1 + 10^{-8})^{-1}` of the one asked.
HELD = 1e4
#: Gauss–Hermite points of the profile: the rule is exact for a second moment of a floor that departs from
#: the straight axis by a polynomial of degree up to 4 in the along coordinate (the bend measured is quadratic).
NODES = 5
#: Gauss–Newton steps of a profile point stop once the linear model predicts a smaller decrease of the cost
#: (a sum of squared whitened residuals): below it the point moves by about a metre on the 600 s recordings
#: of the module docstring, against a widened σ of tens of metres.
PROFILE_TOLERANCE = 1e-4
#: Gauss–Newton steps of a profile point before Levenberg–Marquardt takes over (3-4 were needed on those
#: recordings).
PROFILE_ITERATIONS = 10
_LM_ITERATIONS = 100


class _HeldProblem(_Problem):
    """The smoother's cost without the zone wall, and the same with one state's position held along axes.

    :meth:`hold` sets the held state, axes and values; :meth:`cost` and
    :meth:`system` then carry the hold's residuals, :meth:`data_cost` never.
    """

    _held: tuple[int, FloatArray, FloatArray] | None = None

    def hold(self, k: int, rows: FloatArray, targets: FloatArray) -> None:
        """Hold ``rows @ x_k[:dim]`` (``rows`` ``(m, dim)``: the axes, each weighted by :data:`HELD` over its σ)
        at ``targets`` ``(m,)``."""
        self._held = (k, np.atleast_2d(np.asarray(rows, dtype=float)), np.atleast_1d(np.asarray(targets, dtype=float)))

    def release(self) -> None:
        """Back to the smoother's cost."""
        self._held = None

    def _hold_residual(self, states: FloatArray) -> FloatArray:
        if self._held is None:
            return np.zeros(0)
        k, rows, targets = self._held
        return np.asarray(targets - rows @ states[k, :rows.shape[1]], dtype=float)

    def cost(self, states: FloatArray) -> float:
        r = self._hold_residual(states)
        return self.data_cost(states) + float(r @ r)

    def system(self, states: FloatArray, lam: float, *, wall: bool = True) -> gtsam.GaussianFactorGraph:
        gfg = super().system(states, lam, wall=False)
        if self._held is not None:
            k, rows, _ = self._held
            full = np.zeros((rows.shape[0], self.nx))
            full[:, :rows.shape[1]] = rows
            gfg.add(gtsam.JacobianFactor(self.keys[k], full, self._hold_residual(states),
                                         gtsam.noiseModel.Unit.Create(rows.shape[0])))
        return gfg


def _problem(measurements: Measurements, model: TrackingModel, times: FloatArray, huber_k: float | None
             ) -> _HeldProblem:
    """The smoother's cost without the zone wall (as its covariances), with the zone's weak prior."""
    return _HeldProblem(model, measurements, huber_k, model.prior(), np.asarray(times, dtype=float))


def conditional_step(prob: _Problem, states: FloatArray, covariance: FloatArray, k: int, *, order: int = 0
                     ) -> tuple[FloatArray, float, float]:
    r"""The whole track's step when state ``k`` moves one standard deviation along its position's major axis
    (``order`` 1: along the next axis, :func:`~fgdoppler.estimators.curvature.probe_axis`).

    The linearised system at ``states`` with a zero right-hand side and
    state ``k`` held at :math:`\boldsymbol\delta_k`
    (:func:`~fgdoppler.estimators.curvature.probe_axis` of ``covariance``,
    its Laplace marginal) by a factor :data:`HELD` times the data's own
    information about it: every other state at its conditional mean.  Since
    :math:`\boldsymbol\delta_k` is itself the conditional mean of
    :math:`\mathbf x_k` given its position's coordinate
    :math:`s = \mathbf v^\top\mathbf p_k` along the axis at one standard
    deviation, the step is the regression of the whole track on that
    coordinate, :math:`\boldsymbol\Delta_j = \mathrm{Cov}(\mathbf x_j, s)/\sigma_s`.

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
    delta, sd = probe_axis(covariance, order)
    hold = HELD * np.linalg.inv(np.linalg.cholesky(covariance))
    gfg.add(gtsam.JacobianFactor(prob.keys[k], hold, hold @ delta, gtsam.noiseModel.Unit.Create(delta.size)))
    step, _ = chain_solve(gfg, prob.keys, covariances=False)
    rows = np.einsum("kij,kj->ki", A_prev[1:], step[:-1]) + np.einsum("kij,kj->ki", A_next[1:], step[1:])
    first = A0 @ step[0]
    return step, float(first @ first + np.sum(rows**2)), sd


@dataclass(frozen=True, kw_only=True)
class TrackProbe:
    r"""The probe at one state (module docstring).

    Attributes
    ----------
    index
        The state probed.
    ratio
        The smaller of the two rises over the quadratic model's.
    rises
        The cost's rises at :math:`\mp 3\boldsymbol\Delta` (linear term removed).
    predicted
        The quadratic model's rise, :math:`9\lVert\mathbf A\boldsymbol\Delta\rVert^2`.
    sd
        The position σ along the axis (m).
    axis
        The position's major axis :math:`\mathbf v` (unit vector).
    step
        :math:`\boldsymbol\Delta` ``(n, 2d)`` (:func:`conditional_step`).
    """

    index: int
    ratio: float
    rises: tuple[float, float]
    predicted: float
    sd: float
    axis: FloatArray
    step: FloatArray


def probe_state(prob: _Problem, states: FloatArray, covariance: FloatArray, k: int, *, order: int = 0
                ) -> TrackProbe:
    """The probe at state ``k`` of ``states`` (the optimum), ``covariance`` its Laplace marginal, along the
    position's major axis (``order`` 1: the next one, :func:`~fgdoppler.estimators.curvature.probe_axis`)."""
    step, quad, sd = conditional_step(prob, states, covariance, k, order=order)
    lo, hi = rises_along(prob.data_cost, np.asarray(states, dtype=float), step)
    predicted = PROBE_SIGMAS**2 * quad
    dim = covariance.shape[0] // 2
    position = probe_axis(covariance, order)[0][:dim]  # the axis times its variance over σ
    axis = position / np.linalg.norm(position)
    return TrackProbe(index=k, ratio=min(lo, hi) / predicted, rises=(lo, hi), predicted=predicted, sd=sd,
                      axis=axis, step=step)


@dataclass(frozen=True, kw_only=True)
class ValleyProfile:
    r"""The cost profiled along one state's major axis, and the second moments it gives (module docstring).

    Attributes
    ----------
    index
        The state whose position was held.
    nodes
        The rule's Gauss–Hermite nodes :math:`\xi_i` (standard deviations along an axis).
    points
        ``(p, a)`` the points held, in standard deviations along each of the ``a`` axes (1 or 2): the nodes, or
        their product grid.
    weights
        The points' normalised weights :math:`w_i`.
    rises
        The cost's rise :math:`c(\mathbf X_i) - c(\hat{\mathbf X})` at each point (0 at the estimate).
    moments
        ``(n, 2d, 2d)`` the second moments :math:`\mathbf M_j` about the estimate.
    failure
        Why the profile is not to be trusted (``None``: it is): a point not
        found, or a floor that rises beyond
        :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` times the
        Gaussian's, either way.
    """

    index: int
    nodes: FloatArray
    points: FloatArray
    weights: FloatArray
    rises: FloatArray
    moments: FloatArray
    failure: str | None


def _profile_point(prob: _HeldProblem, start: FloatArray) -> tuple[FloatArray, str | None]:
    """The held cost's minimum from ``start``: Gauss–Newton to :data:`PROFILE_TOLERANCE`, and
    Levenberg–Marquardt where a step fails to lower the cost or the steps run out; why it failed, or ``None``."""
    x = np.asarray(start, dtype=float)
    cost = prob.cost(x)
    for _ in range(PROFILE_ITERATIONS):
        try:
            gfg = prob.system(x, 0.0)
            dx, _ = prob.solve(gfg)
            new = prob.cost(x + dx)
        except (RuntimeError, ValueError):  # an indeterminate system, or a step onto a sensor
            break
        predicted = cost - prob.model_gap(x) - prob.model_cost(gfg, dx, 0.0)
        if not new < cost:
            break
        x, cost = x + dx, new
        if predicted < PROFILE_TOLERANCE:
            return x, None
    x, _, _, why, _ = _levenberg_marquardt(prob, x, _LM_ITERATIONS)
    return x, why


def valley_profile(prob: _HeldProblem, states: FloatArray, covariances: FloatArray, probe: TrackProbe, *,
                   nodes: int = NODES, across: TrackProbe | None = None) -> ValleyProfile:
    r"""The cost profiled along the probe's axis at :attr:`TrackProbe.index`, and its second moments.

    At each Gauss–Hermite point :math:`\xi_i` the position of state
    :math:`k` is held at :math:`\mathbf v^\top\hat{\mathbf p}_k + \xi_i\sigma`
    along the axis :math:`\mathbf v` (σ its Laplace standard deviation) and
    the rest of the track minimises the cost (:func:`_profile_point`, from
    :math:`\hat{\mathbf X} + \xi_i\boldsymbol\Delta`): the floor of the
    valley, :math:`\mathbf X_i`, at cost rise :math:`r_i`.  Weighted by the
    profile's own likelihood against the rule's Gaussian,
    :math:`w_i \propto \omega_i\,e^{\xi_i^2/2 - r_i/2}`, the second moment of
    state :math:`j` about the estimate is

    .. math::

        \mathbf M_j = \mathbf P_j - \boldsymbol\Delta_j\boldsymbol\Delta_j^\top
            + \sum_i w_i\,(\mathbf X_{i,j} - \hat{\mathbf x}_j)(\mathbf X_{i,j} - \hat{\mathbf x}_j)^\top:

    the Laplace covariance given the along coordinate, plus the spread of the
    floor.  Where the floor is the straight axis,
    :math:`\mathbf X_i = \hat{\mathbf X} + \xi_i\boldsymbol\Delta` and
    :math:`r_i = \xi_i^2`, so :math:`\mathbf M_j = \mathbf P_j` (the rule
    integrates :math:`\xi^2` exactly); where it bends, the bend adds its
    own variance and the offset of its mean from the estimate.  The
    conditional covariance and the volume of the valley's cross-section are
    taken as the estimate's all along it.

    With ``across`` (the probe of the same state along the next axis of its
    position, :func:`probe_state` with ``order=1``) the position is held on
    the product grid of the two rules, :math:`(\xi_{i_1}, \xi_{i_2})`, the
    start :math:`\hat{\mathbf X} + \xi_{i_1}\boldsymbol\Delta_1 + \xi_{i_2}\boldsymbol\Delta_2`,
    the weights :math:`\omega_{i_1}\omega_{i_2}e^{\lVert\boldsymbol\xi\rVert^2/2 - r/2}` and
    :math:`\mathbf P_j - \boldsymbol\Delta_{1,j}\boldsymbol\Delta_{1,j}^\top - \boldsymbol\Delta_{2,j}
    \boldsymbol\Delta_{2,j}^\top` in place of the first term (the two coordinates are uncorrelated under the
    Laplace approximation): the floor of a valley that is poorly observed in two directions.
    """
    x = np.asarray(states, dtype=float)
    P = np.asarray(covariances, dtype=float)
    axes = (probe,) if across is None else (probe, across)
    k = probe.index
    xi, omega = hermegauss(nodes)
    points = np.stack(np.meshgrid(*([xi] * len(axes)), indexing="ij"), axis=-1).reshape(-1, len(axes))
    point_weights = np.prod(np.stack(np.meshgrid(*([omega] * len(axes)), indexing="ij"), axis=-1), axis=-1).ravel()
    rows = np.array([a.axis * (HELD / a.sd) for a in axes])
    centres = np.array([float(a.axis @ x[k, :a.axis.size]) for a in axes])
    sds = np.array([a.sd for a in axes])
    steps = np.array([a.step for a in axes])
    c0 = prob.data_cost(x)
    offsets = np.zeros((len(points), *x.shape))
    rises = np.zeros(len(points))
    missed: list[str] = []
    for i, s in enumerate(points):
        if not np.any(s):
            continue
        prob.hold(k, rows, HELD / sds * (centres + s * sds))
        try:
            found, why = _profile_point(prob, x + np.tensordot(s, steps, axes=1))
        finally:
            prob.release()
        offsets[i] = found - x
        rises[i] = prob.data_cost(found) - c0
        if why is not None:
            missed.append(why)
    squared = np.sum(points**2, axis=1)
    off = squared != 0.0
    failures = [f"{len(missed)} of {int(np.sum(off))} points not found ({missed[0]})"] if missed else []
    log_w = np.log(point_weights) + 0.5 * squared - 0.5 * rises
    weights = np.exp(log_w - np.max(log_w))
    weights /= np.sum(weights)
    steep = _steep_floor(points[off], rises[off])
    if steep is not None:
        failures.append(steep)
    moments = (P - np.einsum("ani,anj->nij", steps, steps)
               + np.einsum("q,qni,qnj->nij", weights, offsets, offsets))
    if not np.all(np.isfinite(moments)):
        failures.append("its second moments are not finite")
    return ValleyProfile(index=k, nodes=xi, points=points, weights=weights, rises=rises, moments=moments,
                         failure="; ".join(failures) if failures else None)


def _steep_floor(points: FloatArray, rises: FloatArray) -> str | None:
    r"""Where the floor's rise at a point other than the estimate strays beyond
    :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` times the Gaussian's :math:`\lVert\xi\rVert^2`
    (either way, or below the estimate's cost), the farthest such point in words; ``None`` where none does."""
    rate = rises / np.sum(points**2, axis=1)
    far = ~((1.0 / CURVATURE_LIMIT <= rate) & (rate <= CURVATURE_LIMIT))
    if not np.any(far):
        return None
    worst = int(np.argmax(np.where(rate > 0.0, np.abs(np.log(np.where(rate > 0.0, rate, 1.0))), np.inf)))
    where = points[worst]
    at = (f"at {where[0]:+.2f} standard deviations" if where.size == 1 else
          f"at ({', '.join(f'{c:+.2f}' for c in where)}) standard deviations along the two axes")
    return (f"the floor rises {rate[worst]:.3g} times the Gaussian's {at}" if rate[worst] > 0.0 else
            f"the floor lies {-rises[worst]:.3g} below the estimate's cost {at}")


@dataclass(frozen=True, kw_only=True)
class TrackBend:
    """What the probe and the profiles of a track found (:func:`track_bend`).

    Attributes
    ----------
    profiles
        The profiles taken: one along the axis per probed state whose ratio is beyond the limit, and in 3-D one
        more on the grid of the position's two major axes at the farthest probe's state (``points`` of two
        columns).
    reason
        The ``nonlinear`` finding of a recording that is not sampled (beyond
        the sampled span, or where the process noise sets the variance):
        ``"ok"`` where every profile is trusted in 2-D, ``"doubtful"``
        otherwise.
    widening
        What widened the covariances, in words (for a caller's own finding).
    untrusted
        Why the profiles are not to be trusted, in words: each failed profile's time and
        :attr:`ValleyProfile.failure` (``""`` where every profile is trusted; for a caller's own finding too).
    """

    profiles: tuple[ValleyProfile, ...]
    reason: Reason
    widening: str
    untrusted: str


def track_bend(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
               covariances: FloatArray, *, limit: float, huber_k: float | None = None,
               unsampled: str = "over a recording this long") -> TrackBend | None:
    """The profiles where the probe at one of :data:`PROBED` strays beyond ``limit`` (either way), and their
    finding; ``None`` where none does (also where every probe's linear solve fails: nothing is said then).
    ``unsampled`` says in the finding why no posterior samples are drawn (it is followed by "no posterior
    samples are drawn").

    The finding names the farthest probe.  It is ``"ok"`` (informational)
    where every profile is trusted (:attr:`ValleyProfile.failure`) and the
    state is 2-D; ``"doubtful"`` where one is not, and in 3-D, where the one
    axis profiled does not follow the second poorly observed direction (the
    target's rotation about the sensors' line; module docstring).  The
    caller widens the covariances to the profiles' second moments either
    way, never narrowing them.
    """
    prob = _problem(measurements, model, times, huber_k)
    x = np.asarray(states, dtype=float)
    P = np.asarray(covariances, dtype=float)
    probes: list[TrackProbe] = []
    for f in PROBED:
        k = round(f * (prob.n - 1))
        try:
            probe = probe_state(prob, x, P[k], k)
        except (RuntimeError, ValueError, np.linalg.LinAlgError):
            continue
        if np.isfinite(probe.ratio) and probe.ratio > 0.0:
            probes.append(probe)
    bent = [p for p in probes if not 1.0 / limit <= p.ratio <= limit]
    if not bent:
        return None
    worst = max(bent, key=lambda p: abs(np.log(p.ratio)))
    lines = tuple(valley_profile(prob, x, P, p) for p in bent)
    # in 3-D the grid along both axes follows the rotation about the sensors' line.  The lines are kept, as a line's
    # floor may reach farther along the second axis than the grid's nodes at the Laplace σ (one of 16 random
    # layouts: NEES 2.9 with the lines, 105 with grids alone).  One grid, at the farthest probe, did as well as one
    # at every bent probe on the masts cell (runs beyond the chi-square point 2 either way; the smoother's median
    # CPU 3.6 s against 4.8 s); a grid only where the second axis' own probe is bent missed two of the runs it
    # mends (docs/concepts.md, "Two axes in 3-D").
    grids = tuple(valley_profile(prob, x, P, p, across=a) for p in (worst,)
                  if model.dim == 3 and (a := _next_axis(prob, x, P, p)) is not None)
    profiles = lines + grids
    failed = tuple(f"t = {time_text(float(prob.times[pr.index]))} s{' (grid)' if pr.points.shape[1] == 2 else ''}: "
                   f"{pr.failure}" for pr in profiles if pr.failure)
    shape = ("a curved valley, not the straight ellipsoid of the smoother's Laplace covariance" if worst.ratio > 1.0
             else "flatter than the smoother's Laplace covariance says")
    found = (f"the likelihood is {shape}: at t = {time_text(float(prob.times[worst.index]))} s, {PROBE_SIGMAS:g} "
             f"standard deviations ({distance_text(PROBE_SIGMAS * worst.sd, km_decimals=2)}) along the position's "
             f"major axis, the rest of the track following, raise the cost by {worst.rises[0]:.3g} and "
             f"{worst.rises[1]:.3g} where its quadratic model predicts {worst.predicted:.3g}")
    widening = (f"the cost profiled along the valley's floor at {NODES} Gauss-Hermite points along the axis at "
                f"t = {_times_text(lines, prob.times)} s{_grid_text(grids, prob.times)} "
                f"({_across_text(profiles, worst, P)})")
    if failed:
        message = (f"{found}; {unsampled} no posterior samples are drawn, and {widening} is not to "
                   f"be trusted ({'; '.join(failed)}): the covariances are widened by what it found and may still "
                   "misstate the uncertainty (poor observability)")
    elif model.dim == 3:
        message = (f"{found}; {unsampled} no posterior samples are drawn: the covariances are "
                   f"widened to the second moment about the estimate along the valley's floor, {widening}, but in "
                   "3-D the target's rotation about the sensors' line bends the valley too, and held on two axes its "
                   "floor has left the truth outside such covariances on some recordings: they may still misstate "
                   "the uncertainty (poor observability)")
    else:
        message = (f"{found}; {unsampled} no posterior samples are drawn: the covariances are widened to the "
                   f"second moment about the estimate along the valley's floor, {widening}")
    status: Status = "ok" if not failed and model.dim == 2 else "doubtful"
    return TrackBend(profiles=profiles, reason=Reason(code="nonlinear", status=status, message=message),
                     widening=widening, untrusted="; ".join(failed))


def _times_text(profiles: tuple[ValleyProfile, ...], times: FloatArray) -> str:
    """The times of the profiles' states, in words."""
    return ", ".join(time_text(float(times[pr.index])) for pr in profiles)


def _grid_text(grids: tuple[ValleyProfile, ...], times: FloatArray) -> str:
    """The grids' clause of the widening's words ("" where none was taken)."""
    if not grids:
        return ""
    return (f", and on a grid of {NODES} x {NODES} points along the position's two major axes at "
            f"t = {_times_text(grids, times)} s")


def _next_axis(prob: _HeldProblem, states: FloatArray, covariances: FloatArray, probe: TrackProbe
               ) -> TrackProbe | None:
    """The probe of ``probe``'s state along its position's next axis (:func:`probe_state`, ``order=1``); ``None``
    where its linear solve fails."""
    try:
        return probe_state(prob, states, covariances[probe.index], probe.index, order=1)
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        return None


def _across_text(profiles: tuple[ValleyProfile, ...], worst: TrackProbe, laplace: FloatArray) -> str:
    """The position σ across the major axis at the farthest probe's state, its profiles' (the larger, where a grid
    was taken there too) against the Laplace one (2-D: the one direction across; 3-D: the larger of the two)."""
    own = [pr for pr in profiles if pr.index == worst.index]
    k, v = worst.index, worst.axis
    dim = v.size
    across = np.eye(dim) - np.outer(v, v)

    def sd(M: FloatArray) -> float:
        return float(np.sqrt(max(np.linalg.eigvalsh(across @ M[:dim, :dim] @ across)[-1], 0.0)))

    return (f"root-mean-square position error across that axis {distance_text(max(sd(pr.moments[k]) for pr in own))}, "
            f"Laplace σ "
            f"{distance_text(sd(laplace[k]))}")
