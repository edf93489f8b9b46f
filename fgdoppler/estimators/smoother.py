r"""Offline smoother: the whole recording's graph solved by Levenberg–Marquardt.

The graph has one state per distinct measurement time, a measurement factor
per state, a constant-velocity motion factor per step and (optionally) the
zone's weak prior.  It is started from the initiation (window) and an
EKF pass (the rest), then solved by LM with Marquardt's diagonal scaling.

The run is in four modules: the graph and its solve
(:mod:`fgdoppler.estimators.smoother_solve`: O(N) per iteration, one native
factor per scan, the marginals by an O(N) recursion), the searches for other
modes of the whole recording (:mod:`fgdoppler.estimators.smoother_modes`),
the findings about the zone (:mod:`fgdoppler.estimators.smoother_zone`), and
here the run itself — start, re-initiation, searches, final findings and the
reported states and covariances — in two stages (:func:`draft_smoother`,
:func:`finish_smoother`) so that the hypotheses of an ambiguous initiation
finish only the one of lowest cost.

The reported track is the maximum a posteriori one, except where the
posterior is skewed about it while the cost stays near-quadratic (the
paper's 25 km scenarios): there it is the posterior mean, with the
samples' covariance (:mod:`fgdoppler.estimators.spread`, "Skewed valleys";
``SmootherSettings.posterior_mean``).  ``TrackResult.cost`` is the cost at
the maximum a posteriori track either way.

Verdict reasons: ``not-converged`` (LM hit its iteration cap or found no
step that reduces the cost), ``covariance`` (indeterminate marginals),
``competing`` (another mode explains the data about as well), ``altitude``
(3-D: the track sinks below the altitude band's floor), ``boundary`` and
``zone`` (the data prefer a start outside the zone; a ``boundary``
finding is informational where they do not), ``manoeuvre`` (the
recording's parts disagree about the track:
:mod:`fgdoppler.estimators.manoeuvre`), each ``"doubtful"``; the χ² test of
the solution is the judge's (:mod:`fgdoppler.estimators.judge`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.stats import chi2

from fgdoppler.estimators.calibration import bias_sigmas, shifted_by, with_bias_uncertainty
from fgdoppler.estimators.clock_offsets import clock_sigmas, with_clock_uncertainty
from fgdoppler.estimators.ekf import run_ekf
from fgdoppler.estimators.initiation import Initiation, inlier_statistic
from fgdoppler.estimators.judge import REJECT_ROBUST
from fgdoppler.estimators.local import in_computation_frame
from fgdoppler.estimators.manoeuvre import manoeuvre_reason
from fgdoppler.estimators.results import Estimates, OffsetEstimate, TrackResult
from fgdoppler.estimators.search_memo import SearchMemo
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.site_offsets import site_sigmas, with_site_uncertainty
from fgdoppler.estimators.smoother_modes import _modes_2d, _reinitiate, _restarts_3d, _rival_reason
from fgdoppler.estimators.smoother_solve import FloatArray, SmootherSolution, solve_smoother
from fgdoppler.estimators.smoother_zone import (
    _held_with_offsets,
    _outside_findings,
    _released_reason,
)
from fgdoppler.estimators.spread import posterior_spread
from fgdoppler.estimators.verdict import Event, Reason
from fgdoppler.geometry import pair_labels
from fgdoppler.measurements import Measurements
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import DopplerModel
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, prefixed

if TYPE_CHECKING:
    from fgdoppler.estimators.smoother_offsets import JointSolution

__all__ = ["SmootherDraft", "SmootherSolution", "draft_smoother", "finish_smoother", "initial_trajectory", "rts_smooth",
           "run_smoother", "solve_smoother"]


def rts_smooth(times: FloatArray, states: FloatArray, covs: FloatArray, motion: ConstantVelocity) -> FloatArray:
    r"""Rauch–Tung–Striebel backward pass over filtered estimates at consecutive scans.

    Between scans there are no measurements, so the prediction of scan
    :math:`k+1` from scan :math:`k` is :math:`\mathbf F\mathbf x_k` with
    :math:`\mathbf P^- = \mathbf F\mathbf P_k\mathbf F' + \mathbf Q`, and
    :math:`\mathbf x^s_k = \mathbf x_k + \mathbf P_k\mathbf F'(\mathbf P^-)^{-1}(\mathbf x^s_{k+1} - \mathbf F\mathbf x_k)`.
    """
    out = states.copy()
    for k in range(times.size - 2, -1, -1):
        dt = times[k + 1] - times[k]
        F = motion.F(dt)
        P_pred = motion.predict_covariance(covs[k], dt)
        G = np.linalg.solve(P_pred, F @ covs[k]).T
        out[k] = states[k] + G @ (out[k + 1] - F @ states[k])
    return out


def initial_trajectory(measurements: Measurements, model: TrackingModel, init: Initiation,
                       settings: SmootherSettings, progress: Progress | None = None) -> FloatArray:
    """Starting trajectory: EKF after the window, RTS-smoothed, and its CV extrapolation back over the window.

    Raw EKF states violate a small process noise badly between scans (the
    cost of such a start can exceed 1e15); the RTS pass makes the start
    consistent with the motion model so LM begins near the optimum.
    """
    times = measurements.scans().times
    ekf = run_ekf(measurements, model, init, settings.start(), progress=prefixed(progress, "start")).primary
    smoothed = rts_smooth(ekf.times, ekf.states, ekf.covariances, model.motion) if np.all(ekf.cov_ok) else ekf.states
    out = np.empty((times.size, model.n))
    in_window = times <= init.t_end
    out[in_window] = model.motion.propagate(smoothed[0], times[in_window] - ekf.times[0])
    idx = np.searchsorted(ekf.times, times[~in_window])
    out[~in_window] = smoothed[np.clip(idx, 0, len(ekf) - 1)]
    return out


def _final_findings(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                    sol: SmootherSolution, init: Initiation, reasons: list[Reason], progress: Progress | None,
                    memo: SearchMemo | None, joint: JointSolution | str | None = None,
                    walls: Callable[[FloatArray, FloatArray], float] | None = None,
                    reported: Callable[[], FloatArray | None] | None = None) -> list[Reason]:
    """``reasons`` with what the searches outside the zone (2-D, ``mode_search``:
    :func:`~fgdoppler.estimators.smoother_zone._outside_findings`) and the split test of the motion model
    (``motion_check``: :mod:`fgdoppler.estimators.manoeuvre`) find about the final solution — with the offsets
    in the model where they were estimated with the track (``joint``,
    :func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`); the zone wall's tests with them in
    the model where ``walls`` (:func:`~fgdoppler.estimators.smoother_offsets.joint_wall_gain`) is given, and the
    mirror image's rule with the ``reported`` covariances (:func:`_mirror_reason`)."""
    if settings.mode_search:
        reasons = _outside_findings(measurements, model, settings, sol, init, reasons, progress, memo, walls)
    reasons = _held_with_offsets(measurements, model, settings, sol, reasons, walls)
    return [*reasons, *_model_findings(measurements, model, settings, sol.times, sol.states, joint,
                                       half_plane=init.half_plane is not None, reported=reported,
                                       progress=progress)]


def _model_findings(measurements: Measurements, model: TrackingModel, settings: SmootherSettings, times: FloatArray,
                    states: FloatArray, joint: JointSolution | str | None, *, half_plane: bool,
                    reported: Callable[[], FloatArray | None] | None = None, progress: Progress | None = None
                    ) -> list[Reason]:
    """The findings about the model of the track ``states``: the mirror image that free offsets can make a rival
    (``mode_search``, a ``joint`` solution, no ``half_plane``: :func:`_mirror_reason`, with the ``reported``
    covariances where given) and the split test of the
    motion model (``motion_check``), re-fitting the offsets where there is a joint solution
    (:func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`); ``progress`` is told of the split
    test's fits (:func:`~fgdoppler.estimators.manoeuvre.manoeuvre_reason`)."""
    from fgdoppler.estimators.smoother_offsets import JointSolution

    solved = joint if isinstance(joint, JointSolution) else None
    out: list[Reason] = []
    if settings.mode_search and solved is not None and not half_plane:
        mirror = _mirror_reason(measurements, model, settings, solved, reported)
        out += [mirror] if mirror is not None else []
    if settings.motion_check:
        manoeuvre = manoeuvre_reason(measurements, model, times, states, settings, joint=solved, progress=progress)
        out += [manoeuvre] if manoeuvre is not None else []
    return out


def _mirror_reason(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                   joint: JointSolution, reported: Callable[[], FloatArray | None] | None = None) -> Reason | None:
    """A ``competing`` finding when the joint mode from the mirror image of the track is a rival by the rule of
    :func:`~fgdoppler.estimators.smoother_modes._restarts_3d`
    (:func:`~fgdoppler.estimators.smoother_offsets.mirror_solution`; 2-D, with offsets declared).  The reported
    track stays: the finding says what the other mode is.

    The rule weighs the rival against the covariance the user receives, ``reported()`` — with the offsets'
    share (:func:`_rule_covariances`) — where given, else the joint mode's Laplace covariance.  Those differ
    where the offsets are only considered: the track responds to them far from linearly where the data
    observe it poorly, and the five-point share is kilometres wide where the Laplace one is a few hundred
    metres.  Measured on the paper's case a 5 km and case b 45 km (offsets drawn with σ 1 m/s and declared,
    seed 2026; runs 53 and 4, 8, 40, 58): the smoother ended 2.2–2.7 km from the truth with a reported σ of
    1.5–3.1 km along the error (final NEES 2.0–14.3), yet the mirror mode, 1.6–2.2 km away, was called a rival
    against a Laplace σ of 112–587 m along the way to it.  With the offsets estimated the reported covariance
    is the joint mode's, and the rule reads that."""
    from fgdoppler.estimators.smoother_offsets import mirror_solution

    if model.zone is None or not isinstance(model.observation, DopplerModel):
        return None
    mirror = mirror_solution(measurements, model, settings, joint)
    if mirror is None:
        return None
    covariances = None if reported is None else reported()
    best = joint if covariances is None else replace(joint, covariances=covariances)
    found = _rival_reason([best, mirror], best, model.zone)
    if found is None:
        return None
    label = pair_labels(model.observation)
    return replace(found, message=(
        f"{found.message} — the mirror image of the track across the sensors' line, with the offsets "
        f"{mirror.offsets.describe(label)} (the reported track's: {joint.offsets.describe(label)})"), mirror="sensors")


def with_offset_findings(reference: TrackResult, measurements: Measurements, model: TrackingModel,
                         bias_sigma: float | tuple[float, ...], *, half_plane: bool = False) -> TrackResult:
    """The verdict of a smoother run without offsets as it reads with the calibration offsets ``bias_sigma`` in the
    model: the split test of the motion model re-fitting them
    (:func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`) in place of the one without, and in 2-D
    the mirror image that free offsets can make a rival (:func:`_mirror_reason`; not with a ``half_plane``).
    Not the zone wall's test, which needs the tracks the smoother released from the wall: a smoother run with
    the offsets declared (``SmootherSettings.reference_for``) reads that one too.

    For a tracker told of offsets and held against an offline smoother given without them (the ``reference``
    finding; :func:`~fgdoppler.estimators.registry.run_estimator`'s ``reference``): the
    comparison of track and covariance stays like with like — both without the offsets' share, which the
    tracker adds last — but the smoother's own findings about the model must be those of the model the
    user declared.  Without this, offsets pass for a manoeuvre: the paper's case b 45 km, offsets of σ 1 m/s
    (seed 2026), 5 of 30 EKF runs told of them were `doubtful` for the smoother's ``manoeuvre`` finding,
    three of them consistent.  (Referring the tracker to a smoother that considers or estimates the offsets
    itself, covariances included, was tried: the tracker, its covariance with its own share, was then
    called over-confident in up to 8 and 11 of 30 consistent runs of case a 5 km and case b 45 km, against
    1 and 2 this way.)  ``reference`` itself where no offset is declared or the joint solve fails.
    """
    from fgdoppler.estimators.smoother_offsets import solve_with_offsets

    if not np.any(np.asarray(bias_sigma) > 0):
        return reference
    base = reference.settings if isinstance(reference.settings, SmootherSettings) else SmootherSettings()
    settings = replace(base, bias_sigma=bias_sigma, estimate_offsets=True)
    e = reference.primary
    joint = solve_with_offsets(measurements, model, settings, e.times, e.states)
    if isinstance(joint, str):
        return reference
    reasons = [r for r in reference.reasons if r.code != "manoeuvre"]
    reasons += _model_findings(measurements, model, settings, e.times, e.states, joint, half_plane=half_plane)
    return replace(reference, reasons=tuple(reasons))


def _joint(measurements: Measurements, model: TrackingModel, settings: SmootherSettings, sol: SmootherSolution
           ) -> JointSolution | str | None:
    """With calibration offsets declared (``settings.bias_sigma``) the joint solution of track and offsets from
    ``sol`` (:func:`~fgdoppler.estimators.smoother_offsets.solve_with_offsets`; a string says why there is none),
    else ``None``.  The verdict's split test and mirror-image search use it whenever offsets are declared (they
    test the model the user declared); the report only with ``settings.estimate_offsets``."""
    if not np.any(np.asarray(settings.bias_sigma) > 0):
        return None
    from fgdoppler.estimators.smoother_offsets import solve_with_offsets

    return solve_with_offsets(measurements, model, settings, sol.times, sol.states)


def _reported(measurements: Measurements, model: TrackingModel, settings: SmootherSettings, sol: SmootherSolution,
              reasons: list[Reason], notes: list[str], joint: JointSolution | str | None = None
              ) -> tuple[list[FloatArray], list[FloatArray | None], OffsetEstimate | None]:
    """The states and covariances to report: the sampled spread where the posterior is skewed (its reason joins
    ``reasons``), with the calibration offsets' share (``settings.bias_sigma``; not without
    ``settings.offset_share``) added — a consider covariance
    (:func:`~fgdoppler.estimators.calibration.with_bias_uncertainty`) or, with ``settings.estimate_offsets``, the
    joint solution's (``joint``, :func:`_joint`) shift and share (:mod:`~fgdoppler.estimators.smoother_offsets`;
    its offsets are returned, what happened joins ``notes``), the clock offsets' share (``settings.clock_sigma``,
    :func:`~fgdoppler.estimators.clock_offsets.with_clock_uncertainty`, from the solution itself) and the site
    errors' (``settings.site_sigma``, :func:`~fgdoppler.estimators.site_offsets.with_site_uncertainty`, so too)."""
    states = list(sol.states)
    covs: list[FloatArray | None] = list(sol.covariances) if sol.covariances is not None else [None] * sol.times.size
    has_covs = sol.covariances is not None and bool(np.all(np.isfinite(sol.covariances[0])))
    if has_covs and settings.sampled_covariance:
        assert sol.covariances is not None
        sampled = posterior_spread(measurements, model, sol.times, sol.states, sol.covariances,
                                   huber_k=settings.huber_k, mean=settings.posterior_mean, seed=settings.seed)
        if sampled is not None:
            states, covs = list(sampled.states), list(sampled.covariances)
            reasons.append(sampled.reason)
    off = None
    if settings.offset_share and np.any(np.asarray(settings.bias_sigma) > 0):  # its count was checked at the start
        states, covs, off = _with_bias(measurements, model, settings, sol, states, covs, has_covs, notes, joint)
    if has_covs and np.any(np.asarray(settings.clock_sigma) > 0):
        covs = list(with_clock_uncertainty(measurements, model, sol.times, sol.states, np.array(covs),
                                           settings.clock_sigma, settings))
    if has_covs and np.any(np.asarray(settings.site_sigma) > 0):
        covs = list(with_site_uncertainty(measurements, model, sol.times, sol.states, np.array(covs),
                                          settings.site_sigma, settings))
    return states, covs, off


def _with_bias(measurements: Measurements, model: TrackingModel, settings: SmootherSettings, sol: SmootherSolution,
               states: list[FloatArray], covs: list[FloatArray | None], has_covs: bool, notes: list[str],
               joint: JointSolution | str | None) -> tuple[list[FloatArray], list[FloatArray | None],
                                                            OffsetEstimate | None]:
    """:func:`_reported`'s states and covariances with the calibration offsets' share, and the offsets estimated."""
    n_pairs = model.observation.n_channels
    if joint is not None:
        if not isinstance(joint, str):
            notes += [*joint.notes, "calibration offsets estimated with the track: "
                      + joint.offsets.describe(pair_labels(model.observation))]
            off = joint.offsets
            if has_covs:
                covs = list(with_bias_uncertainty(shifted_by(measurements, -off.full(n_pairs)), model, sol.times,
                                                  joint.states, np.array(covs), settings.bias_sigma, settings,
                                                  directions=off.square_root(n_pairs)))
            return list(np.array(states) + joint.states - sol.states), covs, off
        notes.append(f"{joint}: the offsets' consider covariance instead")
    if has_covs:
        covs = list(with_bias_uncertainty(measurements, model, sol.times, sol.states, np.array(covs),
                                          settings.bias_sigma, settings))
    return states, covs, None


@dataclass(frozen=True, kw_only=True)
class SmootherDraft:
    """The smoother's solution from one initiation before its final findings and reported covariances.

    :func:`draft_smoother` makes it, :func:`finish_smoother` completes it;
    :func:`run_smoother` does both.  The two stages let the runs from the
    hypotheses of an ambiguous initiation (resolution ``"cost"``,
    :func:`~fgdoppler.estimators.ambiguity.resolve_staged`) finish only the
    one of lowest cost: the findings about the final solution — the
    searches outside the zone, the split test of the motion model — and the
    posterior samples of the reported covariances are about the track
    reported, and cost as much as the solve itself.

    Attributes
    ----------
    init
        The initiation it started from.
    settings
        The smoother's settings.
    solution
        The maximum a posteriori track after the re-initiation and the
        whole-recording searches.
    notes
        What happened so far.
    reasons
        The findings so far (the solve's and the searches').
    started
        ``time.perf_counter()`` when the run began.
    released
        The tracks (states, cost) reached without the zone wall from the
        solutions it held — those replaced on the way and the final one —,
        and after :meth:`joined` those of the other hypotheses' drafts: the
        final findings test the solution against them
        (:func:`~fgdoppler.estimators.smoother_zone._released_reason`).
    """

    init: Initiation
    settings: SmootherSettings
    solution: SmootherSolution
    notes: tuple[str, ...]
    reasons: tuple[Reason, ...]
    started: float
    released: tuple[tuple[FloatArray, float], ...] = ()

    def joined(self, drafts: Sequence[SmootherDraft]) -> SmootherDraft:
        """This draft, chosen among ``drafts`` (the hypotheses' of an ambiguous initiation, this one included),
        with their released tracks: a hypothesis held at the zone's wall that lost by cost still says where
        the data lead without the wall."""
        return replace(self, released=tuple(r for d in drafts for r in d.released))

    @property
    def cost(self) -> float:
        """The solution's cost (:attr:`SmootherSolution.cost`)."""
        return self.solution.cost

    def result(self) -> TrackResult:
        """The draft as a track: the maximum a posteriori states, their Laplace covariances, the findings so far."""
        sol = self.solution
        covs: list[FloatArray | None] = (list(sol.covariances) if sol.covariances is not None
                                         else [None] * sol.times.size)
        return _track(self, list(sol.states), covs, self.reasons, self.notes, None)


def _track(draft: SmootherDraft, states: list[FloatArray], covs: list[FloatArray | None], reasons: Sequence[Reason],
           notes: Sequence[str], offsets: OffsetEstimate | None) -> TrackResult:
    """The track result of ``draft``'s solution reporting ``states`` and ``covs``."""
    sol = draft.solution
    t_last = float(sol.times[-1])
    return TrackResult(
        estimator="smoother",
        settings=draft.settings,
        estimates=(Estimates.from_lists("smoothed", list(sol.times), states, covs),),
        reasons=tuple(reasons),
        events=tuple(Event(time=t_last, message=n) for n in notes),
        iterations=sol.iterations,
        cost=sol.cost,
        wall_time=time.perf_counter() - draft.started,
        offsets=offsets,
    )


def _misfit(measurements: Measurements, model: TrackingModel, settings: SmootherSettings, sol: SmootherSolution
            ) -> str | None:
    r"""Why ``sol`` cannot explain the data, or ``None``: the judge's ``fit`` and ``rejections`` tests at 99.9 %.

    With the Gaussian loss the cost is a χ² statistic on
    :math:`n - n_x` degrees of freedom.  The Huber cost is not: every gross
    outlier adds about :math:`2k|r|` to it, so 5 % outliers of 100 σ fail
    the χ² check whatever the track.  There, as in the judge
    (:mod:`fgdoppler.estimators.judge`), the misfit is the inliers' χ²
    statistic (:func:`~fgdoppler.estimators.initiation.inlier_statistic`)
    on as many fewer degrees of freedom as outliers, and more than
    :data:`~fgdoppler.estimators.judge.REJECT_ROBUST` of the measurements
    beyond the outlier cut is a misfit too: a track from a wrong basin
    leaves most residuals beyond it.
    """
    n = len(measurements)
    if settings.huber_k is None:
        threshold = float(chi2.ppf(0.999, max(n - model.n, 1)))
        return (f"cost {sol.cost:.1f} fails the 99.9 % chi-square check ({threshold:.1f})"
                if sol.cost > threshold else None)
    statistic, outliers = inlier_statistic(model, measurements, sol.states, sol.times)
    if outliers > REJECT_ROBUST * n:
        return f"{outliers} of {n} residuals are beyond the outlier cut (more than {REJECT_ROBUST:.0%})"
    threshold = float(chi2.ppf(0.999, max(n - outliers - model.n, 1)))
    return (f"the inliers' chi-square {statistic:.1f} fails the 99.9 % check ({threshold:.1f}, {outliers} "
            "outliers left out)" if statistic > threshold else None)


def draft_smoother(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: SmootherSettings | None = None,
    *,
    progress: Progress | None = None,
    memo: SearchMemo | None = None,
) -> SmootherDraft:
    """The first stage of :func:`run_smoother`: initiation → EKF start → LM, the re-initiation and the searches.

    Computes in ``model``'s coordinates as given (:func:`run_smoother` moves
    the problem into its computation frame first); ``progress`` and ``memo``
    as there.
    """
    settings = settings or SmootherSettings()
    bias_sigmas(settings.bias_sigma, model.observation.n_channels)  # a wrong count is said before any work
    clock_sigmas(settings.clock_sigma, model.observation.n_channels)
    if np.any(np.asarray(settings.site_sigma) > 0):
        site_sigmas(settings.site_sigma, model)
    t_begin = time.perf_counter()
    progress = prefixed(progress, "smoother")
    x_init = initial_trajectory(measurements, model, init, settings, progress)
    sol = solve_smoother(measurements, model, x_init, settings, prior=model.prior(), progress=progress)
    notes = list(sol.notes)
    searchable = settings.reinitiate and isinstance(model.observation, DopplerModel)
    misfit = _misfit(measurements, model, settings, sol) if searchable else None
    discarded: list[SmootherSolution] = []
    if misfit is not None:
        # The solution cannot explain the data (a wrong basin inherited from the window):
        # offline, every measurement is available, so initiate again from all of them.
        notes.append(f"{misfit}: re-initiated from the whole recording")
        again = _reinitiate(measurements, model, settings, progress, memo=memo, half_plane=init.half_plane)
        if again is not None and again.cost < sol.cost:
            discarded.append(sol)
            sol = again
            notes += list(again.notes)
    searched = sol
    if model.dim == 3:
        sol, more_notes, mode_reasons = _restarts_3d(measurements, model, settings, sol, progress, memo)
    elif settings.mode_search:
        sol, more_notes, mode_reasons = _modes_2d(measurements, model, settings, sol, progress,
                                                  half_plane=init.half_plane, memo=memo)
    else:
        more_notes, mode_reasons = [], []
    if sol is not searched:
        discarded.append(searched)
    return SmootherDraft(init=init, settings=settings, solution=sol, notes=(*notes, *more_notes),
                         reasons=(*sol.reasons, *mode_reasons), started=t_begin,
                         released=tuple(d.released for d in (*discarded, sol) if d.released is not None))


def finish_smoother(measurements: Measurements, model: TrackingModel, draft: SmootherDraft, *,
                    progress: Progress | None = None, memo: SearchMemo | None = None) -> TrackResult:
    """The second stage of :func:`run_smoother`: the final findings and the reported states and covariances.

    ``model`` is the one ``draft`` was made with (:func:`draft_smoother`).
    """
    from fgdoppler.estimators.smoother_offsets import joint_wall_gain

    settings, sol = draft.settings, draft.solution
    progress = prefixed(progress, "smoother")
    notes = list(draft.notes)
    joint = _joint(measurements, model, settings, sol)
    # With offsets declared the zone wall's tests read them too: a pair's constant error can make a start
    # outside the zone fit better, which the model the user declared explains inside it.
    walls = None if joint is None else joint_wall_gain(measurements, model, settings, sol.times)
    released = _released_reason(measurements, model, settings, sol, draft.released, offsets=walls)
    sampled: list[Reason] = []
    states, covs, offsets = _reported(measurements, model, settings, sol, sampled, notes,
                                      joint if settings.estimate_offsets else None)
    reasons = _final_findings(measurements, model, settings, sol, draft.init, [*draft.reasons, *released],
                              progress, memo, joint, walls, _rule_covariances(measurements, model, settings, sol, covs))
    return _track(draft, states, covs, [*reasons, *sampled], notes, offsets)


def _rule_covariances(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                      sol: SmootherSolution, covs: list[FloatArray | None]) -> Callable[[], FloatArray | None]:
    """The covariances the mirror image's rule reads (:func:`_mirror_reason`), when asked: those reported
    (``covs``), with the calibration offsets' share — added here where the settings leave it out of the report
    (``offset_share=False``, the reference a tracker told of offsets is held against, whose tracker reports
    its own share); ``None`` without covariances."""
    def covariances() -> FloatArray | None:
        if any(c is None for c in covs):
            return None
        reported = np.array(covs)
        if settings.offset_share or not np.any(np.asarray(settings.bias_sigma) > 0):
            return reported
        return with_bias_uncertainty(measurements, model, sol.times, sol.states, reported, settings.bias_sigma,
                                     settings)

    return covariances


@in_computation_frame
def run_smoother(
    measurements: Measurements,
    model: TrackingModel,
    init: Initiation,
    settings: SmootherSettings | None = None,
    *,
    progress: Progress | None = None,
    memo: SearchMemo | None = None,
) -> TrackResult:
    """Offline reconstruction of a whole recording (initiation → EKF start → LM) with marginals.

    If the solution's cost fails a 99.9 % χ² check (it cannot explain the data: the window's
    initiation led to a wrong basin) and ``settings.reinitiate`` is set, the whole recording is
    initiated again (multi-start, deterministic constant velocity) and smoothed from there; the
    lower cost wins and an event says so.  In 2-D with ``settings.mode_search`` the whole recording
    is searched for other modes in any case
    (:func:`~fgdoppler.estimators.smoother_modes._modes_2d`): a distinct mode of lower cost replaces
    the track, and one that explains the data about as well is a ``competing`` finding; where the
    zone wall holds the track, the ``boundary`` test also looks beyond the wall
    (:func:`~fgdoppler.estimators.smoother_zone._beyond_wall_2d`); where the wall held a track that
    gave way to the reported one, that track released from the wall is tested against it
    (:func:`~fgdoppler.estimators.smoother_zone._released_reason`, a ``boundary`` finding; with an
    ambiguous initiation the held tracks of every hypothesis, :meth:`SmootherDraft.joined`); and
    without a ``boundary`` finding, where the track fits poorly (cost, or under the Huber loss the
    inliers' χ² statistic, above the :data:`~fgdoppler.estimators.smoother_zone.OUTSIDE_LEVEL` χ²
    level), the smoother looks outside the zone on every side
    (:func:`~fgdoppler.estimators.smoother_zone._outside_zone_2d`, a ``zone`` finding).  With
    ``settings.motion_check`` the recording's parts are fitted on their own and compared with the
    track (a ``manoeuvre`` finding where they disagree: :mod:`fgdoppler.estimators.manoeuvre`).  In
    3-D the altitude levels and the whole recording are searched
    (:func:`~fgdoppler.estimators.smoother_modes._restarts_3d`).  The runs from the hypotheses of an
    ambiguous initiation share a ``memo`` (:class:`~fgdoppler.estimators.search_memo.SearchMemo`,
    made by :func:`~fgdoppler.estimators.registry.run_estimator`): each of those searches then runs
    once, not once per hypothesis, with the same results.  The run is :func:`draft_smoother` then
    :func:`finish_smoother`.
    """
    draft = draft_smoother(measurements, model, init, settings, progress=progress, memo=memo)
    return finish_smoother(measurements, model, draft, progress=progress, memo=memo)
