r"""Online re-initiation of the trackers: when all the data so far point elsewhere, start again there.

A Gaussian tracker (EKF, iSAM2, fixed-lag; one Gaussian or a Gaussian sum)
carries what its start told it.  Where the start's posterior is a long
curved valley, every term of the sum can sit in the wrong part of it, each
too confident for the later data to pull it out: on the paper's case a
5 km, run 32 of the accuracy benchmark's seed 2026, all eight EKF terms
end 3.7–8.7 km from the truth with a NEES of 500–6,000, while a
multi-start initiation over the first 10 s of data alone is 188 m off.

So at checkpoints :math:`t_c` — when the number of measurements since the
start has grown by :data:`GROWTH` since the last one (the window's count
× 1.5, × 2.25, …; a handful for a short recording, a logarithmic number
for a long one) — the tracker's online estimate is tested against a fresh
initiation over *all* data up to :math:`t_c`:

1. the grid of :func:`~fgdoppler.estimators.initiation.initiate` scores at
   most :data:`PER_PAIR` measurements of each pair, evenly spread, and
   Levenberg–Marquardt refines its best candidates on the deterministic-CV
   window (``window="cv"``) against every measurement up to :math:`t_c`;
2. the running estimate's own basin is found by the same
   Levenberg–Marquardt from the running estimate :math:`\mathbf x_o`
   (propagated back to the start).  The best fit of all the data so far,
   :math:`\mathbf x_b` with its Laplace covariance :math:`\mathbf P_b`, is
   that basin — unless the fresh solution is another mode whose data cost
   (:math:`\sum r^2`, −2 log likelihood; the Huber loss's sum where the
   check is robust, "A few outliers" below) is lower by more than
   :data:`MODE_MARGIN` (a likelihood ratio of 1,000 to 1): a mode barely
   better than the tracker's own is no reason to jump;
3. the tracker restarts from it when the two disagree by *both*
   covariances, :math:`\min(\mathbf d'\mathbf P_o^{-1}\mathbf d,\;
   \mathbf d'\mathbf P_b^{-1}\mathbf d)` above the χ² quantile at
   :data:`DISAGREEMENT` (state-dimension degrees of freedom),
   :math:`\mathbf d = \mathbf x_b - \mathbf x_o`: the fit lies outside the
   tracker's confidence region and the tracker outside the fit's.  A fit less
   certain than the tracker cannot overrule it.  On run 32 above the EKF's
   basin *is* the fresh solution's: the filter had not got stuck in another
   mode, it lagged 4 km behind the maximum of its own posterior, 4–13 σ by
   its own covariance (squared distances 19–181 at the four checkpoints)
   and 8–17 σ by the fit's;
4. the restart starts from the fit *and* from the running estimate: the
   latter, :math:`\mathbf x_o` and :math:`\mathbf P_o` carried back to the
   fit's window start, joins the fit's solutions as one more alternative
   with its data cost over the same measurements.  A long, flat valley of
   the likelihood can put the fit far from the truth while the data favour
   it over the running estimate by little (on the slow three-pair track of
   :mod:`benchmarks.bench_long`, sampler seed 6 of recording 3: a fit at
   25 s 17.8 km from the truth, the EKF 0.9 km from it, data costs 168.2
   and 174.0; the Laplace covariance of the fit put the EKF 25 sigma off).
   So neither is dropped: the restarted tracker's Gaussian sum
   (:mod:`fgdoppler.estimators.ambiguity`) weighs both by the data — by
   their window costs, or by the sampled window posterior, which the
   running estimate now also proposes from, where the fit's window is
   non-Gaussian — and the later measurements decide.  Measured with
   ``python studies/slow_track_check.py`` and the accuracy benchmark
   (docs/concepts.md, "Online re-initiation").

A half plane the user gave the first initiation
(:attr:`~fgdoppler.estimators.initiation.Initiation.half_plane`) binds both
fits of step 1 and 2: with sensors on one line the mirror image of the track
fits the data exactly as well, so without it a tracker drifted onto the
mirror side would stand, and a fresh fit could land there.

**A few outliers.**  The trackers reject gross outliers by their gate (the
particle estimators by their likelihood); a squared-loss fit follows
them.  So under the squared loss, where a check calls for a restart, the
data so far are fitted under the Huber loss at
:data:`~fgdoppler.models.robust.EFFICIENT_K` as well, and where that fit
lies outside the squared-loss fit's region (χ² quantile at
:data:`DISAGREEMENT`: a few measurements pull the latter away) the check
is decided again with the fits and data costs under the Huber loss
(:func:`_pulled`).  With 5 % of the measurements moved by ±100 σ (the
verdict cases of ``tests/estimators/test_verdict.py``, seed 3) the
squared-loss check alone put the EKF, iSAM2 and the fixed-lag smoother
239, 252 and 1,102 m from the truth at the end after four restarts each,
against 4, 3 and 17 m without one: the two fits were 29–182 sigma apart,
the Huber check finds the running estimates in agreement, and nothing
restarts.  On Gaussian data the two fits lie within about a sigma of each
other and the squared-loss check stands.  Off the model (truths with
process noise) the two losses can also find two modes of the data so far,
and the Huber check then decides though no outlier pulls anything;
restricting it to squared-loss fits that fail their χ² test undid those
decisions and was worse in four of five such recordings
(docs/concepts.md, "Recorded off the recipe").  The Huber check as a veto on
every restart, and checks and restarts under the Huber loss alone, were
tried and not kept: on such data the Huber fit is the less efficient one,
and they vetoed or added restarts near the threshold, mostly to the
tracks' cost (case a 5 km, run 36 of the accuracy benchmark's seed 2026:
the EKF's RMSE over 5–30 s 1,063 m → 1,288 m under the veto;
docs/concepts.md, "A few outliers do not restart a tracker").

Both guards were measured on a two-hour recording of a slow target seen by
three pairs (:mod:`benchmarks.bench_long`): with the fit's estimate tested
against the tracker's covariance alone and the lowest cost always winning,
the EKF jumped four times — to a mode 23 km off whose cost was 1.7 lower
than its own basin's, and to a fit over 192 s that was itself uncertain to
4.9 km — and its RMSE went from 454 m to 1,306 m; with them it does not jump.

A restart runs the tracker again from the new initiation (its Gaussian sum
when the new window is itself non-Gaussian, :mod:`fgdoppler.estimators.ambiguity`):
the EKF from the initiation's state at :math:`t_c`, iSAM2 and the
fixed-lag smoother by re-solving its window — every measurement up to
:math:`t_c`, with their process noise — as their first update
(:func:`~fgdoppler.estimators.window.solve_window`, O(N) in the window's
scans), then the measurements after :math:`t_c`.  The estimates before
:math:`t_c` stay as they were (they were the online answer then), those
from :math:`t_c` on are the new run's.  Everything uses only data up to
:math:`t_c`: the tracker stays online.  ``restarts=False`` in the
settings turns this off.

**The particle estimators** (``particle``, ``map``) carry the posterior
of all the data since their start, not a Gaussian that can lag behind it,
so the test above would only cost them time — but their start is the
window's posterior sampled from the initiation's solutions
(:mod:`fgdoppler.estimators.window_posterior`), and where the first data
favour a wrong basin every particle can settle there and stay, confident.
On two pairs in general position recorded with gaps (the layout and
target of draw 23 of ``studies/random_layouts.py``, 60 s at 2 Hz, 30 % of
the measurements dropped, one pair silent for 10 s; one of 16 noise
draws, ``tests/estimators/test_restart.py``) both ended 12.6 km from the
truth with a position sigma of 53 m, and the verdict said ``failed``.  So
they are tested as well, at a checkpoint where the measurements since the
last one *surprise* them — their normalised innovations sum beyond the χ²
quantile at :data:`SURPRISE` (:func:`surprised`), or where their
particles were sampled again about a posterior peak they had missed since
the last one (:func:`~fgdoppler.estimators.particle.rescued`: that peak,
the best fit of the data so far, can lie in a wrong basin), or where the data do
not surprise them but one of the initiation's solutions, refined on every
measurement so far, fits them better than the running estimate's basin by
:data:`MODE_MARGIN` (:mod:`fgdoppler.estimators.basin_screen`: a wrong basin
the data leave slowly) — and no later than ``max_span`` after the start:
a restart samples the posterior of every measurement so far, which past
``max_span`` costs more than the moves the estimators themselves bound to
that span.  A wrong basin that neither the data nor the screen flag, one the
initiation never proposed, is found only by the test itself; so in space
``map`` makes it at every checkpoint (``ParticleSettings.check_every``,
docs/concepts.md, "Every checkpoint in space").  The test and the restart are
the ones above: with the outliers above (seeds 0 and 2) the NIS sum fires,
the Huber check finds the running estimate in agreement and nothing
restarts, where the squared-loss check alone sent ``particle`` 829 m and
1,042 m from the truth (58 m and 88 m without a restart).  The estimator
runs again from the fresh initiation, its window every measurement up to
:math:`t_c`, sampled from the fit's solutions and the running estimate.
On the gapped recording the check at 20 s put the running estimate 950-960
sigma from the best fit, and both ended 23–25 m from the truth
(``doubtful``: the rejections before the restart).  On the accuracy
benchmark (100 runs of each scenario, seeds 2026 and 7) the data surprised
them at 10 of the 9,600 checkpoints of both estimators and both seeds, and
none restarted; every track is the one of the median rule before, to the
bit (docs/concepts.md, "The particle estimators restart too").

Step 1 depends on the recording, the model, the loss and the half plane,
never on the tracker or its estimate: the EKF, iSAM2 and the fixed-lag
smoother run on one recording would each compute the same fits.
:func:`~fgdoppler.estimators.registry.run_estimators` shares them through
a :class:`FreshFits` (each fit once; the tracks the same to the bit).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fgdoppler._text import time_text
from fgdoppler.estimators.grid import GridResult, HalfPlane
from fgdoppler.estimators.initiation import (
    Candidate,
    Initiation,
    InitiationSettings,
    initiate,
    window_grid,
)
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.search_memo import RecordingMemo
from fgdoppler.estimators.settings import TrackerSettings
from fgdoppler.estimators.verdict import Event
from fgdoppler.measurements import Measurements
from fgdoppler.models.observation import predict_along
from fgdoppler.models.robust import EFFICIENT_K, huber_rho
from fgdoppler.models.tracking import TrackingModel

__all__ = ["DISAGREEMENT", "GROWTH", "MODE_MARGIN", "PER_PAIR", "SURPRISE", "FreshFits", "checkpoint_counts",
           "checkpoints", "fresh_start", "splice_estimates", "surprise_check", "surprised",
           "with_restarts"]

FloatArray = NDArray[np.float64]
#: A checkpoint each time the number of measurements since the start has grown by this factor.
GROWTH = 1.5
#: Measurements per pair the checkpoint's grid scores (LM then uses all of them).
PER_PAIR = 16
#: χ² probability (state-dimension dof) beyond which the best fit of all data so far lies outside the tracker's region.
DISAGREEMENT = 0.999
#: Data-cost margin (Σr², i.e. −2 log-likelihood) by which another mode must beat the running estimate's own basin:
#: a likelihood ratio of 1/(1 − DISAGREEMENT), 1,000 to 1.
MODE_MARGIN = float(2.0 * np.log(1.0 / (1.0 - DISAGREEMENT)))
#: χ²ₙ probability beyond which the NIS sum of the n measurements since the last checkpoint surprises a particle
#: estimator (:func:`surprised`).
SURPRISE = 0.999

#: Runs a tracker from an initiation over the measurements after its window (the registry's solve step); the second
#: argument is the checkpoint the run takes over from (s).
Solver = Callable[[Initiation, float], TrackResult]


def checkpoint_counts(n0: int) -> Iterator[int]:
    """The measurement counts ``ceil(n0 × GROWTH^k)``, k = 1, 2, …, at which checkpoints fall (``n0``: the window's)."""
    target = float(max(n0, 1))
    while True:
        target *= GROWTH
        yield int(np.ceil(target))


def checkpoints(measurements: Measurements, init: Initiation) -> list[float]:
    """Scan times after the window at which the measurement count reaches ``n0 × GROWTH^k``.

    ``n0`` is the number of measurements up to the window's end; the last
    scan is never a checkpoint (no data would follow it).
    """
    t = np.sort(measurements.time)
    n0 = int(np.searchsorted(t, init.t_end, side="right"))
    scan_times = measurements.scans().times
    out: list[float] = []
    for count in checkpoint_counts(n0):
        k = count - 1
        if k >= t.size:
            break
        tc = float(t[k])
        if tc >= scan_times[-1] or (out and tc <= out[-1]) or tc <= init.t_end:
            continue
        out.append(tc)
    return out


def _cost(model: TrackingModel, x_start: FloatArray, t_start: float, data: Measurements,
          huber_k: float | None) -> float:
    """Data cost :math:`\\sum\\rho(r)` of the constant-velocity track from ``x_start`` at ``t_start``."""
    h = predict_along(model.observation, x_start[None], data.time - t_start, data.pair.astype(np.intp))[0]
    r = (data.doppler - h) / data.sigma
    return float(np.sum(huber_rho(r, huber_k))) if np.all(np.isfinite(r)) else float("inf")


def _state_at(result: TrackResult, t: float) -> tuple[FloatArray, FloatArray] | None:
    """The *filtered* estimate at ``t`` (a lagged or smoothed one has seen data after ``t``)."""
    e = next((x for x in result.estimates if x.kind == "filtered"), None)
    if e is None:
        return None
    i = int(np.searchsorted(e.times, t))
    if i >= len(e) or abs(e.times[i] - t) > 1e-9 or not e.cov_ok[i]:
        return None
    return e.states[i], e.covariances[i]


#: Step 1 of a check: the data up to the checkpoint, the initiation settings, the grid and the fresh initiation.
_Fit = tuple[Measurements, InitiationSettings, GridResult, Initiation]


def _fresh_fit(measurements: Measurements, model: TrackingModel, huber_k: float | None,
               half_plane: HalfPlane | None, tc: float) -> _Fit | None:
    """Step 1 of the check at ``tc`` (module docstring); ``None`` where there is nothing to restart from."""
    data = measurements.subset(measurements.time <= tc)
    if len(data) < model.n + 1:
        return None
    isets = InitiationSettings(window="cv", huber_k=huber_k, half_plane=half_plane, mistake_check=False)
    try:
        grid = window_grid(data.spread(PER_PAIR), model, isets)
    except ValueError:  # the data so far need a speed above the zone's bound: nothing in the zone to restart from
        return None
    new = initiate(data, model, isets, grid_result=grid)
    if new.P_end is None or abs(new.t_end - tc) > 1e-9:
        return None
    return data, isets, grid, new


class FreshFits(RecordingMemo):
    """The restart checks' fits of all the data up to each checkpoint (step 1), for the trackers of one call.

    A fit depends on the recording, the model, the loss (``huber_k``), the
    half plane and the checkpoint, and nothing else (module docstring); the
    keys name those.  Models are told apart by identity (the memo keeps a
    reference to each, so an identity is never reused), and
    :meth:`local_model` gives every tracker of one model the same model in
    its computation frame, so that trackers of a model that is moved into
    its own frame share their fits too.  The fits are the ones each
    tracker would compute alone, to the bit.

    Parameters
    ----------
    measurements
        The recording the trackers share; a check on another is refused.
    """

    def __init__(self, measurements: Measurements) -> None:
        super().__init__(measurements)
        self._models: dict[int, TrackingModel] = {}
        self._local: dict[int, TrackingModel] = {}
        self._fits: dict[Hashable, _Fit | None] = {}
        self.computed = 0  # fits computed, not taken from the memo (how much was shared)

    def local_model(self, model: TrackingModel) -> TrackingModel:
        """``model.in_frame(model.computation_frame)``, the same object for every call with ``model``."""
        key = id(model)
        if key not in self._local:
            self._models[key] = model
            self._local[key] = model.in_frame(model.computation_frame)
        return self._local[key]

    def fit(self, measurements: Measurements, model: TrackingModel, huber_k: float | None,
            half_plane: HalfPlane | None, tc: float) -> _Fit | None:
        """Step 1 of the check at ``tc``: computed the first time, then the same objects.

        Raises
        ------
        ValueError
            If ``measurements`` is not the recording the memo was made for.
        """
        self._models.setdefault(id(model), model)
        side = None if half_plane is None else (tuple(map(float, half_plane.point)),
                                                tuple(map(float, half_plane.normal)))

        def compute() -> _Fit | None:
            self.computed += 1
            return _fresh_fit(measurements, model, huber_k, half_plane, tc)

        return self._once(self._fits, measurements, (id(model), huber_k, side, tc), compute)


def _shared_fit(measurements: Measurements, model: TrackingModel, huber_k: float | None,
                half_plane: HalfPlane | None, tc: float, fits: FreshFits | None) -> _Fit | None:
    """Step 1 of the check at ``tc`` under the loss ``huber_k``, from ``fits`` where the trackers share them."""
    return (_fresh_fit(measurements, model, huber_k, half_plane, tc) if fits is None
            else fits.fit(measurements, model, huber_k, half_plane, tc))


@dataclass(frozen=True, kw_only=True)
class _Disagreement:
    """Steps 1-3 of a check that called for a restart: the fits, the chosen one and how far the tracker lies."""

    data: Measurements
    new: Initiation  # the fresh fit (step 1)
    basin: Initiation  # the running estimate's own basin (step 2)
    best: Initiation  # the one of them restarted from
    x_back: FloatArray  # the running estimate carried back to the fit's window start
    cost: float  # its data cost there
    m2: float  # the smaller of the two squared distances (step 3)


def _disagreement(measurements: Measurements, model: TrackingModel, huber_k: float | None,
                  old: tuple[FloatArray, FloatArray], tc: float, half_plane: HalfPlane | None,
                  fits: FreshFits | None) -> _Disagreement | None:
    """Steps 1-3 of the check at ``tc`` under the loss ``huber_k``; ``None`` where the running estimate stands."""
    fit = _shared_fit(measurements, model, huber_k, half_plane, tc, fits)
    if fit is None:
        return None
    data, isets, grid, new = fit
    x_old, P_old = old
    # the running estimate's own basin on the same data, by the same solver
    x_back = model.motion.propagate(x_old, new.t_start - tc)
    cost = _cost(model, x_back, new.t_start, data, huber_k)
    own = GridResult(states=x_back[None], costs=np.array([cost]), n_candidates=1, speed_min=grid.speed_min)
    basin = initiate(data, model, isets, grid_result=own)
    best = new if basin.P_end is None or new.cost < basin.cost - MODE_MARGIN else basin
    P_best = best.P_end
    assert P_best is not None  # new's was checked above, basin is chosen only with one
    d = best.x_end - x_old
    try:
        # each must lie outside the other's region: a fit less certain than the tracker cannot overrule it
        m2 = min(float(d @ np.linalg.solve(P_old, d)), float(d @ np.linalg.solve(P_best, d)))
    except np.linalg.LinAlgError:
        return None
    if not m2 > chi2.ppf(DISAGREEMENT, model.n):
        return None
    return _Disagreement(data=data, new=new, basin=basin, best=best, x_back=x_back, cost=cost, m2=m2)


def _pulled(fit: Initiation, measurements: Measurements, model: TrackingModel, half_plane: HalfPlane | None,
            tc: float, fits: FreshFits | None) -> bool:
    r"""Whether a few measurements pull the squared-loss fresh fit ``fit`` away (module docstring, "A few outliers").

    True where the fit under the Huber loss at :data:`~fgdoppler.models.robust.EFFICIENT_K`,
    :math:`\mathbf x_h`, lies outside the squared-loss fit's region:
    :math:`(\mathbf x_h - \mathbf x_s)'\mathbf P_s^{-1}(\mathbf x_h - \mathbf x_s)` beyond the χ² quantile at
    :data:`DISAGREEMENT`.
    """
    robust = _shared_fit(measurements, model, EFFICIENT_K, half_plane, tc, fits)
    if robust is None or fit.P_end is None:
        return False
    d = robust[3].x_end - fit.x_end
    try:
        return bool(float(d @ np.linalg.solve(fit.P_end, d)) > chi2.ppf(DISAGREEMENT, model.n))
    except np.linalg.LinAlgError:
        return False


def fresh_start(measurements: Measurements, model: TrackingModel, settings: TrackerSettings,
                old: tuple[FloatArray, FloatArray] | None, tc: float, *,
                half_plane: HalfPlane | None = None, fits: FreshFits | None = None) -> tuple[Initiation, str] | None:
    """The initiation to restart from at checkpoint ``tc``, and why; ``None`` when the running estimate stands.

    ``old`` is the tracker's filtered ``(x, P)`` at ``tc`` (``None``: nothing
    to test); only the measurements up to ``tc`` are used (module docstring,
    steps 1-3).  ``half_plane`` (the first initiation's, in the model's
    coordinates) holds the fresh start and the running estimate's basin to
    the side the user gave: a restart never jumps to the mirror image.
    ``fits`` shares step 1 with the other trackers of a call.  Under the
    squared loss, where a check calls for a restart but a few measurements
    pull its fit away (:func:`_pulled`), the check under the Huber loss at
    :data:`~fgdoppler.models.robust.EFFICIENT_K` decides instead (module
    docstring, "A few outliers").
    """
    if old is None:
        return None
    found = _disagreement(measurements, model, settings.huber_k, old, tc, half_plane, fits)
    if found is None:
        return None
    if settings.huber_k is None and _pulled(found.new, measurements, model, half_plane, tc, fits):
        found = _disagreement(measurements, model, EFFICIENT_K, old, tc, half_plane, fits)
        if found is None:
            return None
    best, new, basin = found.best, found.new, found.basin
    where = "in its own basin" if best is basin else f"of lower cost ({new.cost:.1f} vs {basin.cost:.1f})"
    kept = _running_estimate(model, best, found.x_back, old[1], found.cost, tc, half_plane)
    also = "" if kept is None else (f", carrying its running estimate along (data cost {kept.cost:.1f} against "
                                    f"{best.cost:.1f})")
    return (best if kept is None else replace(best, alternatives=(*best.alternatives, kept))), (
        f"online re-initiation over the {len(found.data)} measurements up to t = {time_text(tc)} s: the running "
        f"estimate is {np.sqrt(found.m2):.1f} sigma from the best fit of all the data so far, {where}; "
        f"the tracker restarts there{also}")


def _running_estimate(model: TrackingModel, best: Initiation, x_back: FloatArray, P_old: FloatArray, cost: float,
                      tc: float, half_plane: HalfPlane | None) -> Candidate | None:
    r"""The running estimate as one more solution of the restart's start (step 4 of the module docstring).

    Its state and covariance at the fit's window start, :math:`\mathbf F^{-1}\mathbf x_o` and
    :math:`\mathbf F^{-1}\mathbf P_o\mathbf F^{-\top}` (:math:`\mathbf F` the constant-velocity transition
    from there to :math:`t_c`), with its data cost :math:`c_o` over the same data and, where the fit's
    solutions have their shares of the window's posterior
    (:meth:`~fgdoppler.estimators.initiation.Initiation.posterior_shares`), a log evidence
    :math:`\log Z_b - (c_o - c_b)/2` beside them.  ``None`` when it lies outside the user's half plane
    (the half plane is the only thing that can send a tracker back from the mirror side) or its
    covariance is not finite.
    """
    if half_plane is not None and not bool(half_plane.contains(x_back)):
        return None
    F_back = model.motion.F(best.t_start - tc)  # the constant-velocity transition run backwards: F(-dt) = F(dt)^-1
    P_back = F_back @ P_old @ F_back.T
    if not (np.isfinite(cost) and np.all(np.isfinite(P_back))):
        return None
    # Weighed against the fit by the likelihood ratio of the data alone, as if its basin held as much of the
    # posterior as the fit's; the fit's own solutions keep their shares of the window's posterior.
    evidence = None if best.log_evidence is None else best.log_evidence - 0.5 * (float(cost) - best.cost)
    return Candidate(state=x_back, cost=float(cost), passes_chi2=bool(cost <= best.chi2_threshold), covariance=P_back,
                     log_evidence=evidence)


def splice_estimates(old: Estimates, new: Estimates, tc: float) -> Estimates:
    """``old`` before ``tc`` and ``new`` from ``tc`` on (a restart's track: :func:`with_restarts`)."""
    keep = old.times < tc - 1e-9
    take = new.times >= tc - 1e-9
    return Estimates(kind=old.kind, times=np.concatenate([old.times[keep], new.times[take]]),
                     states=np.concatenate([old.states[keep], new.states[take]]),
                     covariances=np.concatenate([old.covariances[keep], new.covariances[take]]),
                     cov_ok=np.concatenate([old.cov_ok[keep], new.cov_ok[take]]))


def _splice(old: TrackResult, new: TrackResult, tc: float, message: str) -> TrackResult:
    """``old`` before ``tc`` and ``new`` from ``tc`` on, in every estimate set and record."""
    kinds = {e.kind: e for e in new.estimates}
    estimates = tuple(splice_estimates(e, kinds[e.kind], tc) if e.kind in kinds else e for e in old.estimates)
    keep = old.primary.times < tc - 1e-9
    take = new.primary.times >= tc - 1e-9
    loglik = old.log_likelihood
    if old.log_likelihood.size == len(old.primary) and new.log_likelihood.size == len(new.primary):
        base = old.log_likelihood[keep][-1] if np.any(keep) else 0.0
        loglik = np.concatenate([old.log_likelihood[keep], base + new.log_likelihood[take]])
    nis = np.concatenate([old.nis[old.nis[:, 0] <= tc + 1e-9], new.nis[new.nis[:, 0] > tc + 1e-9]])
    return replace(
        new, estimates=estimates, nis=nis, log_likelihood=loglik,
        hypothesis=np.concatenate([old.hypothesis[keep], new.hypothesis[take]]),
        events=(*(e for e in old.events if e.time < tc), Event(time=tc, message=message), *new.events),
        relinearizations=np.concatenate([old.relinearizations, new.relinearizations]),
        iterations=old.iterations + new.iterations)


def surprised(result: TrackResult, t_from: float, t_to: float) -> bool:
    r"""Whether the measurements gated in :math:`(t_\mathrm{from}, t_\mathrm{to}]` surprise the tracker.

    Surprised when the sum of their :math:`n` normalised innovations
    :math:`\nu_j` (``result.nis``, kept or rejected) exceeds the
    :math:`\chi^2_n` quantile at :data:`SURPRISE`: under a right predictive
    distribution the :math:`\nu_j` are :math:`\chi^2_1` and nearly
    independent, so one checkpoint in a thousand is tested for nothing.
    An estimator drifting away from the target first misses every
    measurement by a little rather than a few by much: on the layouts of
    ``studies/noisy_truth_layouts.py`` where it went 17-67 km astray the
    NIS summed to 1.1-2.7 times the quantile, with a median of 0.9-2.7:
    most of them inside the :math:`\chi^2_1` quantile (10.8).  The median,
    tried next, never fired there; the sum restarts them and they end
    0.1-1.3 km off (3-D draws 2 and 9, 3-D-noisy draw 2, 2-D-noisy draw 3).
    A few outliers set the sum off too; the check that follows then fits
    the data under the Huber loss as well (module docstring, "A few
    outliers"), which they do not pull away from the running estimate, and
    nothing restarts.
    """
    if result.nis.size == 0:
        return False
    t = result.nis[:, 0]
    nu = result.nis[(t > t_from + 1e-9) & (t <= t_to + 1e-9), 2]
    nu = nu[np.isfinite(nu)]
    return bool(nu.size and float(np.sum(nu)) > chi2.ppf(SURPRISE, nu.size))


def surprise_check(t_start: float, max_span: float, screen: Callable[[FloatArray, float], bool] | None = None,
                   *, armed: Callable[[TrackResult, float, float], bool] | None = None, every: bool = False
                   ) -> Callable[[TrackResult, float, float], bool]:
    """The particle estimators' ``only_if`` of :func:`with_restarts` (module docstring, "The particle estimators").

    True at a checkpoint no more than ``max_span`` seconds after ``t_start``
    (the recording's start) where the data since the last one surprise the
    estimator (:func:`surprised`), where ``armed(result, t_last, t_c)`` holds
    (the particles were sampled again about a mode they had missed since the
    last checkpoint, :func:`~fgdoppler.estimators.particle.rescued`) or, where
    neither, ``screen(state, t_c)`` holds of its filtered estimate there
    (:func:`~fgdoppler.estimators.basin_screen.basin_screen`: a start's basin
    fits all the data so far better).  ``every``: true at every checkpoint
    within ``max_span`` (``ParticleSettings.check_every``).
    """
    def check(result: TrackResult, t_last: float, tc: float) -> bool:
        if tc - t_start > max_span:
            return False
        if every:
            return True
        if surprised(result, t_last, tc) or (armed is not None and armed(result, t_last, tc)):
            return True
        if screen is None:
            return False
        state = _state_at(result, tc)
        return state is not None and screen(state[0], tc)
    return check


def with_restarts(measurements: Measurements, model: TrackingModel, init: Initiation, settings: TrackerSettings,
                  first: TrackResult, solve: Solver, *, fits: FreshFits | None = None,
                  only_if: Callable[[TrackResult, float, float], bool] | None = None) -> TrackResult:
    """Test ``first`` (the tracker run from ``init``) at every checkpoint and restart where it fails (module doc).

    ``solve(init, tc)`` runs the tracker from an initiation (with its
    hypotheses) to take the track over from checkpoint ``tc``;
    the returned result's ``wall_time`` covers the checks and the restarts.
    ``fits`` shares the checks' fresh fits with the other trackers of a call.
    ``only_if(result, t_last, t_c)``: test only at the checkpoints ``t_c``
    where it holds of the track so far, the previous checkpoint (or the
    window's end) at ``t_last``; the particle estimators test only where
    the data since surprise them (:func:`surprised`, module docstring).
    """
    t_begin = time.perf_counter()
    result = first
    last = init.t_end
    for tc in checkpoints(measurements, init):
        since, last = last, tc
        if only_if is not None and not only_if(result, since, tc):
            continue
        fresh = fresh_start(measurements, model, settings, _state_at(result, tc), tc, half_plane=init.half_plane,
                            fits=fits)
        if fresh is None:
            continue
        new_init, message = fresh
        result = _splice(result, solve(new_init, tc), tc, message)
    return replace(result, wall_time=first.wall_time + time.perf_counter() - t_begin)
