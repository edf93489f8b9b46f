"""The estimator registry: every tracker by name, and the functions that run one.

:data:`ESTIMATORS` maps a name to an :class:`EstimatorInfo` (the runner, its
settings class, how an ambiguous initiation is resolved, a one-line
summary).  Monte Carlo studies and the paper reproduction read it; the
names, summaries and aliases are those of :mod:`fgdoppler.estimators.names`,
which the command line's choices read without loading an estimator.  Every
runner has the signature
``run(measurements, model, init, settings, *, progress=None) -> TrackResult``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.ambiguity import (
    CostStages,
    Resolution,
    hypotheses,
    hypothesis_weights,
    posterior_hypotheses,
    resolve,
    resolve_staged,
)
from fgdoppler.estimators.basin_screen import basin_screen
from fgdoppler.estimators.calibration import bias_sigmas, moved_starts, offset_shares
from fgdoppler.estimators.clock_offsets import clock_shares, clock_sigmas
from fgdoppler.estimators.ekf import run_ekf
from fgdoppler.estimators.fixed_lag import run_fixed_lag
from fgdoppler.estimators.initiation import Initiation, InitiationSettings, initiate
from fgdoppler.estimators.isam2 import run_isam2
from fgdoppler.estimators.judge import covariance_reference, judge, track_reference
from fgdoppler.estimators.later_mistakes import later_mistakes
from fgdoppler.estimators.names import ALIASES, SUMMARIES
from fgdoppler.estimators.particle import rescued, run_map, run_particle
from fgdoppler.estimators.restart import (
    MODE_MARGIN,
    FreshFits,
    splice_estimates,
    surprise_check,
    with_restarts,
)
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.search_memo import SearchMemo
from fgdoppler.estimators.settings import (
    EKFSettings,
    FixedLagSettings,
    GaussianSumSettings,
    ISAM2Settings,
    MapSettings,
    ParticleSettings,
    SampledCovarianceSettings,
    SmootherSettings,
    TrackerSettings,
)
from fgdoppler.estimators.site_offsets import site_shares, site_sigmas
from fgdoppler.estimators.smoother import (
    SmootherDraft,
    draft_smoother,
    finish_smoother,
    run_smoother,
    with_offset_findings,
)
from fgdoppler.estimators.spread import filtered_spread
from fgdoppler.estimators.verdict import Reason
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel, as_tracking_model
from fgdoppler.progress import Progress, prefixed

__all__ = ["ALIASES", "ESTIMATORS", "EstimatorInfo", "estimator_info", "hypotheses_of", "run_estimator", "run_estimators",
           "track"]


@dataclass(frozen=True, kw_only=True)
class EstimatorInfo:
    """One registered tracker.

    Attributes
    ----------
    name
        Registry name.
    run
        ``run(measurements, model, init, settings, *, progress=None) -> TrackResult``
        (``progress``: :mod:`fgdoppler.progress`).
    settings
        Its settings class (``settings()`` gives the defaults).
    resolution
        How an ambiguous initiation is resolved
        (:mod:`fgdoppler.estimators.ambiguity`).
    online
        True if its primary estimate at a time uses only the data up to then.
    summary
        One line for help texts.
    stages
        For resolution ``"cost"``: ``run`` in two stages, so that only the
        hypothesis of lowest cost is finished
        (:func:`~fgdoppler.estimators.ambiguity.resolve_staged`); ``None``:
        every hypothesis runs whole.
    """

    name: str
    run: Callable[..., TrackResult]
    settings: type[TrackerSettings]
    resolution: Resolution
    online: bool
    summary: str
    stages: CostStages[Any] | None = None


ESTIMATORS: Mapping[str, EstimatorInfo] = MappingProxyType({
    "ekf": EstimatorInfo(name="ekf", run=run_ekf, settings=EKFSettings, resolution="likelihood", online=True,
                         summary=SUMMARIES["ekf"]),
    "isam2": EstimatorInfo(name="isam2", run=run_isam2, settings=ISAM2Settings, resolution="likelihood",
                           online=True, summary=SUMMARIES["isam2"]),
    "fixed-lag": EstimatorInfo(name="fixed-lag", run=run_fixed_lag, settings=FixedLagSettings,
                               resolution="likelihood", online=False,
                               summary=SUMMARIES["fixed-lag"]),
    "smoother": EstimatorInfo(name="smoother", run=run_smoother, settings=SmootherSettings, resolution="cost",
                              online=False, summary=SUMMARIES["smoother"],
                              stages=CostStages(draft=draft_smoother, finish=finish_smoother,
                                                join=SmootherDraft.joined)),
    "particle": EstimatorInfo(name="particle", run=run_particle, settings=ParticleSettings, resolution="native",
                              online=True,
                              summary=SUMMARIES["particle"]),
    "map": EstimatorInfo(name="map", run=run_map, settings=MapSettings, resolution="native", online=True,
                         summary=SUMMARIES["map"]),
})


def estimator_info(name: str) -> EstimatorInfo:
    """The registry entry of ``name`` (or of a deprecated alias).

    Raises
    ------
    ValueError
        If no estimator has that name.
    """
    if name in ALIASES:
        warnings.warn(f"estimator {name!r} is now called {ALIASES[name]!r}", DeprecationWarning, stacklevel=3)
        name = ALIASES[name]
    if name not in ESTIMATORS:
        raise ValueError(f"unknown estimator {name!r}: expected one of {', '.join(ESTIMATORS)}")
    return ESTIMATORS[name]


def run_estimator(
    name: str,
    measurements: Measurements,
    model: TrackingModel | Geometry,
    init: Initiation,
    settings: TrackerSettings | None = None,
    *,
    resolve_ambiguity: bool = True,
    verify: bool = True,
    reference: TrackResult | None = None,
    progress: Progress | None = None,
) -> TrackResult:
    """Run the estimator called ``name`` (a key of :data:`ESTIMATORS`).

    If the initiation is ambiguous (other solutions pass its χ² test, e.g. a
    mirror image) and ``resolve_ambiguity`` is set, the estimator is run from
    every hypothesis and the later data decide
    (:mod:`fgdoppler.estimators.ambiguity`); with it and
    ``settings.restarts`` (the default of every estimator but the offline
    smoother) the run is started again where all the data so far point
    elsewhere (:mod:`fgdoppler.estimators.restart`).

    The estimator runs in the model's computation frame (the geometry's own,
    :attr:`~fgdoppler.models.tracking.TrackingModel.frame`) and the result is
    reported in the user's coordinates, with its verdict
    (:func:`~fgdoppler.estimators.judge.judge` and the initiation's findings;
    on a track that misfits, :mod:`~fgdoppler.estimators.later_mistakes`).
    With ``verify`` (default) a filter's final state is checked against the
    offline smoother's, which costs a smoother run unless ``reference`` — the
    result of ``run_estimator("smoother", ...)`` on the same data and
    initiation, with ``SmootherSettings.reference_for(settings)`` — is given
    (one run without the declared calibration offsets has only its findings
    about the motion model and the mirror image read with them; without
    ``verify`` a given ``reference`` serves only the later windows' check,
    whose answer it may already hold).
    With ``settings.bias_sigma`` a filter's covariances include what
    calibration offsets of that size would do to it (:func:`~fgdoppler.estimators.calibration.offset_shares`, added last;
    the smoother adds its own; the particle estimators integrate the
    offsets out of their likelihood, :mod:`~fgdoppler.estimators.offset_posterior`),
    and with ``settings.clock_sigma`` a filter's or particle estimator's what
    clock offsets would (:func:`~fgdoppler.estimators.clock_offsets.clock_shares`),
    with ``settings.site_sigma`` what errors of the sensor sites would
    (:func:`~fgdoppler.estimators.site_offsets.site_shares`).
    ``progress`` (:mod:`fgdoppler.progress`) is told of every task: each
    hypothesis's run, the reference smoother's, the runs on offset (or delayed) data.

    Raises
    ------
    ValueError
        For an unknown name.
    TypeError
        If ``settings`` belong to another estimator.
    """
    return _run_estimator(name, measurements, model, init, settings, resolve_ambiguity=resolve_ambiguity,
                          verify=verify, reference=reference, progress=progress, fits=None)


def _run_estimator(name: str, measurements: Measurements, model: TrackingModel | Geometry, init: Initiation,
                   settings: TrackerSettings | None, *, resolve_ambiguity: bool, verify: bool,
                   reference: TrackResult | None, progress: Progress | None, fits: FreshFits | None
                   ) -> TrackResult:
    """:func:`run_estimator`, the restart checks' fresh fits shared through ``fits`` (:func:`run_estimators`)."""
    info = estimator_info(name)
    model = as_tracking_model(model)
    settings = settings if settings is not None else info.settings()
    if type(settings) is not info.settings:
        raise TypeError(f"{info.name} takes {info.settings.__name__}, got {type(settings).__name__}")
    frame = model.computation_frame
    if not model.canonical:  # solve in the geometry's own frame, answer in the user's
        local_ref = None if reference is None else reference.transformed(frame, to_world=False)
        local_model = model.in_frame(frame) if fits is None else fits.local_model(model)
        local = _run_estimator(info.name, measurements, local_model, init.in_frame_of(frame), settings,
                               resolve_ambiguity=resolve_ambiguity, verify=verify, reference=local_ref,
                               progress=progress, fits=fits)
        return local.transformed(frame, to_world=True)
    per_pair, offsets, clocks, site_errors = _declared_offsets(settings, model)
    hyps, weights = _hypotheses(info, measurements, model, init, settings) if resolve_ambiguity else ([init], None)
    result = _solve(info, measurements, model, hyps, settings, progress, weights)
    segments = [_Segment(t_from=-np.inf, hyps=hyps, weights=weights)]
    if resolve_ambiguity and getattr(settings, "restarts", False) and model.zone is not None:
        def again(new: Initiation, tc: float) -> TrackResult:
            h, w = _hypotheses(info, measurements, model, new, settings)
            segments.append(_Segment(t_from=tc, hyps=h, weights=w))
            return _solve(info, measurements, model, h, settings, prefixed(progress, "restart"), w)
        result = with_restarts(measurements, model, init, settings, result, again, fits=fits,
                               only_if=surprise_check(init.t_start, settings.max_span,
                                                      basin_screen(measurements, model, init, MODE_MARGIN),
                                                      armed=rescued, every=settings.checks_every(model.dim))
                               if isinstance(settings, ParticleSettings) else None)
    held = (_reference(measurements, model, init, settings, reference, per_pair, resolve_ambiguity, progress)
            if verify and result.primary.kind != "smoothed" else None)
    judged = judge(result, measurements, model, settings, held, half_plane=init.half_plane is not None)
    own = judged.primary  # the tracker's own Gaussian covariances
    checked = None  # the primary covariances without the enclosure built from the reference's track
    if isinstance(settings, SampledCovarianceSettings) and settings.sampled_covariance:
        judged, checked = _with_sampled_covariances(judged, measurements, model, settings, held)
    if held is not None:  # on the covariances reported, before the offsets' share (the reference has none)
        judged = replace(judged, reasons=(*judged.reasons, *covariance_reference(judged.primary, own, held.primary)))
    if any(v is not None and np.any(v > 0) for v in (offsets, clocks, site_errors)):
        judged, checked = _with_offsets(judged, result, segments, info, measurements, model, settings, offsets,
                                        clocks, prefixed(progress, "calibration, clock and site offsets"),
                                        checked=checked, sites=site_errors)
    if held is not None:
        judged = _with_track_reference(judged, checked, held)
    judged = _with_initiation_reasons(judged, hyps[0], native=info.resolution == "native")
    return _with_later_mistakes(judged, measurements, model, init, settings,
                                held if held is not None else reference)


def _with_later_mistakes(result: TrackResult, measurements: Measurements, model: TrackingModel, init: Initiation,
                         settings: TrackerSettings, reference: TrackResult | None) -> TrackResult:
    """The result with a ``sign``, ``swapped``, ``radial`` or ``outliers`` finding from later in the recording where
    the track does not fit and the initiation named no mistake
    (:func:`~fgdoppler.estimators.later_mistakes.later_mistakes`; taken from the reference smoother where it made the
    same check)."""
    found = later_mistakes(measurements, model, init, result.reasons, huber_k=settings.huber_k, reference=reference)
    return replace(result, reasons=(*result.reasons, *found)) if found else result


def _declared_offsets(settings: TrackerSettings, model: TrackingModel
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64] | None,
                                 NDArray[np.float64] | None]:
    """The calibration uncertainty per pair, and those of it, of the clocks (per pair) and of the sites (per site)
    whose share the registry adds (a filter's all three; the particle estimators' clocks and sites, since they
    integrate calibration offsets out themselves; the smoother accounts for all itself).  Their counts are said
    here, before any work."""
    n_pairs = model.observation.n_channels
    per_pair = bias_sigmas(settings.bias_sigma, n_pairs)
    if not isinstance(settings, (ParticleSettings, SampledCovarianceSettings)):
        return per_pair, None, None, None
    site_errors = site_sigmas(settings.site_sigma, model) if np.any(np.asarray(settings.site_sigma) > 0) else None
    clocks = clock_sigmas(settings.clock_sigma, n_pairs)
    return per_pair, None if isinstance(settings, ParticleSettings) else per_pair, clocks, site_errors


def _reference(measurements: Measurements, model: TrackingModel, init: Initiation, settings: TrackerSettings,
               given: TrackResult | None, per_pair: NDArray[np.float64], resolve_ambiguity: bool,
               progress: Progress | None) -> TrackResult:
    """The offline smoother a tracker is held against: ``given``, or run here with the tracker's gate, loss, seed and
    calibration offsets (``SmootherSettings.reference_for``: its findings read the offsets, its covariances
    leave out their share).  A ``given`` smoother run without the declared offsets (``per_pair``) has its
    motion-model and mirror-image findings read with them in the model
    (:func:`~fgdoppler.estimators.smoother.with_offset_findings`; its zone-wall findings stay those without)."""
    if given is None:
        return run_estimator("smoother", measurements, model, init, SmootherSettings.reference_for(settings),
                             resolve_ambiguity=resolve_ambiguity, progress=prefixed(progress, "reference"))
    declared = isinstance(given.settings, SmootherSettings) and np.array_equal(
        bias_sigmas(given.settings.bias_sigma, model.observation.n_channels), per_pair)
    return given if declared else with_offset_findings(given, measurements, model, tuple(float(v) for v in per_pair),
                                                       half_plane=init.half_plane is not None)


def run_estimators(
    names: Iterable[str],
    measurements: Measurements,
    model: TrackingModel | Geometry,
    init: Initiation,
    settings: Mapping[str, TrackerSettings] | None = None,
    *,
    resolve_ambiguity: bool = True,
    verify: bool = True,
    progress: Progress | None = None,
) -> dict[str, TrackResult]:
    """Run several estimators on the same data and initiation, each as :func:`run_estimator` would.

    The filters' ``reference`` check needs the offline smoother with the
    filter's gate, loss and seed (``SmootherSettings.reference_for``);
    :func:`run_estimator` runs it once per filter.  Here it
    runs once per distinct gate, loss and seed and is shared — the smoother's own
    result where its settings are those — so comparing every estimator costs
    one smoother run, not one per filter, with the same results.  The
    filters' restart checks share their fits of the data so far
    (:class:`~fgdoppler.estimators.restart.FreshFits`) the same way.
    ``settings`` maps a name to its settings (default: the estimator's
    defaults); ``names`` may be aliases, and the result is keyed by the
    canonical names, in the order given.

    Raises
    ------
    ValueError
        For an unknown name, or a key of ``settings`` not among ``names``.
    TypeError
        If a name's settings belong to another estimator.
    """
    infos = [estimator_info(n) for n in names]
    given = {estimator_info(k).name: v for k, v in (settings or {}).items()}
    if set(given) - {i.name for i in infos}:
        raise ValueError(f"settings for {sorted(set(given) - {i.name for i in infos})}, which are not run")
    chosen = {i.name: given.get(i.name, i.settings()) for i in infos}
    model = as_tracking_model(model)
    references: dict[SmootherSettings, TrackResult] = {}
    fits = FreshFits(measurements)

    def reference(s: TrackerSettings) -> TrackResult:
        key = SmootherSettings.reference_for(s)
        if key not in references:
            references[key] = _run_estimator("smoother", measurements, model, init, key,
                                             resolve_ambiguity=resolve_ambiguity, verify=True, reference=None,
                                             progress=prefixed(progress, "reference"), fits=fits)
        return references[key]

    out: dict[str, TrackResult] = {}
    if "smoother" in chosen:  # first: it may be the filters' reference
        out["smoother"] = _run_estimator("smoother", measurements, model, init, chosen["smoother"],
                                         resolve_ambiguity=resolve_ambiguity, verify=verify, reference=None,
                                         progress=progress, fits=fits)
        own = chosen["smoother"]
        if own == SmootherSettings.reference_for(own):
            references[own] = out["smoother"]
    for name, s in chosen.items():
        if name not in out:  # a filter: its primary estimate is not the smoothed one
            ref = reference(s) if verify else out.get("smoother")  # without verify: for the later windows alone
            out[name] = _run_estimator(name, measurements, model, init, s, resolve_ambiguity=resolve_ambiguity,
                                       verify=verify, reference=ref, progress=progress, fits=fits)
    return {n: out[n] for n in chosen}

def hypotheses_of(name: str, measurements: Measurements, model: TrackingModel, init: Initiation,
                  settings: TrackerSettings) -> tuple[list[Initiation], NDArray[np.float64] | None]:
    """The hypotheses ``run_estimator(name, ...)`` starts from, and their prior weights (``None``: from the costs).

    The terms of the window posterior's Gaussian sum where the initiation is
    ``nonlinear`` or its curvature probe lies beyond ``settings.split_ratio``
    (at most ``settings.components``), its distinct solutions
    where it is ``ambiguous``, else the initiation alone; ``measurements``
    need only hold the initiation window.
    """
    return _hypotheses(estimator_info(name), measurements, model, init, settings)


def _split(init: Initiation, settings: TrackerSettings) -> bool:
    """Whether a Gaussian tracker's start from ``init`` is split: its ``nonlinear`` finding, or a curvature beyond
    ``settings.split_ratio``."""
    return (any(r.code == "nonlinear" and r.status != "ok" for r in init.reasons)
            or (isinstance(settings, GaussianSumSettings) and settings.splits(init.curvature)))


def _hypotheses(info: EstimatorInfo, measurements: Measurements, model: TrackingModel, init: Initiation,
                settings: TrackerSettings) -> tuple[list[Initiation], NDArray[np.float64] | None]:
    """Where to start from: the initiation, its distinct solutions, or the terms of its posterior's Gaussian sum."""
    if info.resolution == "native":  # the estimator carries every solution itself
        return [init], None
    k = getattr(settings, "components", 1)
    if info.resolution == "likelihood" and k > 1 and _split(init, settings) and model.zone is not None:
        try:
            return posterior_hypotheses(init, measurements, model, k, huber_k=settings.huber_k, seed=settings.seed)
        except ValueError:  # nothing in the zone explains the window: keep the initiation's own answer
            pass
    return (hypotheses(init), hypothesis_weights(init)) if init.ambiguous else ([init], None)


def _solve(info: EstimatorInfo, measurements: Measurements, model: TrackingModel, hyps: list[Initiation],
           settings: TrackerSettings, progress: Progress | None = None,
           weights: NDArray[np.float64] | None = None) -> TrackResult:
    if len(hyps) == 1:
        return info.run(measurements, model, hyps[0], settings, progress=progress)
    if info.stages is not None:  # the smoother: its whole-recording searches are the same for every hypothesis
        return resolve_staged(info.stages, measurements, model, hyps, settings, progress, SearchMemo(measurements))
    return resolve(info.run, info.resolution, measurements, model, hyps, settings, progress, weights)


def _with_sampled_covariances(result: TrackResult, measurements: Measurements, model: TrackingModel,
                              settings: SampledCovarianceSettings, reference: TrackResult | None = None
                              ) -> tuple[TrackResult, NDArray[np.float64] | None]:
    """The primary covariances widened to posterior samples of the data the estimates have read (:func:`~fgdoppler.estimators.spread.filtered_spread`).

    A filter's estimates have read the data so far; a fixed-lag smoother's
    lagged ones the data up to its lag after their time.  The samples see
    the measurements the tracker kept: those its gate rejected
    (``result.nis``) are left out, as the tracker left them out.
    It runs after the verdict: the ``reference`` test compares the
    tracker's own Gaussian covariance with the offline smoother's, a
    witness of poor observability that a widened covariance would hide
    (paper's case a 5 km, seed 2026, run 79: ``doubtful`` on the Gaussian
    covariance, ``ok`` on the widened one, 2.4 km off with a position
    sigma of 0.6 km).  Where the samples cannot describe the posterior (the
    process noise) — and with ``settings.linearised_everywhere`` (default) at
    every estimate, after the checks — the covariances are widened towards
    the posterior of the data the estimates have read linearised about
    ``reference``'s track, the offline smoother's (``filtered_spread``'s
    ``reference``).  Returns the result and, where that enclosure widened
    any, the primary covariances of the sampled checks alone (``None``
    otherwise), which the whole-track ``reference`` finding reads.
    """
    e = result.primary
    rejected = result.nis[result.nis[:, 3] == 0] if result.nis.size else np.zeros((0, 4))
    kept = measurements
    if rejected.shape[0]:
        out = {(float(t), int(c)) for t, c in rejected[:, :2]}
        drop = np.fromiter(((float(t), int(c)) in out for t, c in zip(measurements.time, measurements.pair,
                                                                      strict=True)), dtype=bool, count=len(measurements))
        kept = measurements.subset(~drop)
    widened = filtered_spread(kept, model, e.times, e.states, e.covariances, e.cov_ok,
                              interval=settings.sampling_interval, lag=settings.look_ahead,
                              huber_k=settings.huber_k, seed=settings.seed,
                              linearised_everywhere=settings.linearised_everywhere,
                              reference=None if reference is None or not len(reference.primary)
                              else (reference.primary.times, reference.primary.states))
    if widened is None:
        return result, None
    primary = replace(e, covariances=widened.covariances)
    return (replace(result, estimates=(primary, *result.estimates[1:]), reasons=(*result.reasons, widened.reason)),
            widened.checked)


@dataclass(frozen=True, kw_only=True)
class _Segment:
    """A stretch of the reported track: the tracker's run from ``hyps`` (weighted by ``weights``) from ``t_from`` on
    (the first run from the start; each restart's from its checkpoint)."""

    t_from: float
    hyps: list[Initiation]
    weights: NDArray[np.float64] | None


def _with_offsets(result: TrackResult, tracked: TrackResult, segments: list[_Segment], info: EstimatorInfo,
                  measurements: Measurements, model: TrackingModel, settings: TrackerSettings,
                  offsets: NDArray[np.float64] | None, clocks: NDArray[np.float64] | None = None,
                  progress: Progress | None = None, *, checked: NDArray[np.float64] | None = None,
                  sites: NDArray[np.float64] | None = None) -> tuple[TrackResult, NDArray[np.float64] | None]:
    """Every estimate's covariances with the calibration offsets' share (``offsets``: σ per pair, m/s), the
    clock offsets' (``clocks``: σ per pair, s) and the site errors' (``sites``: σ per site, m) added; and
    ``checked`` (other primary covariances, or ``None``) with the primary's share added too.

    The share is what the offsets do to ``tracked`` — the tracker's
    reported track, its run from the first hypotheses spliced with those of
    its restarts (``segments``) — with each run made again on the data with
    one pair shifted at a time, from starts moved as its window's solution
    moves (:func:`~fgdoppler.estimators.calibration.moved_starts`,
    :func:`~fgdoppler.estimators.calibration.offset_shares`), and spliced at
    the same checkpoints: the restart decisions held, as a linearisation
    holds the track's mode.  A clock offset shifts the data along
    ``tracked``'s primary track
    (:func:`~fgdoppler.estimators.clock_offsets.clock_shares`), and so does
    a site error (:func:`~fgdoppler.estimators.site_offsets.site_shares`).
    """
    kinds = [e.kind for e in tracked.estimates]
    moved = [moved_starts(s.hyps, measurements, model, huber_k=settings.huber_k) for s in segments]

    def respond(data: Measurements) -> list[NDArray[np.float64]]:
        spliced: dict[str, Estimates] = {}
        for s, move in zip(segments, moved, strict=True):
            again = _solve(info, data, model, move(data), settings, progress, s.weights)
            for e in again.estimates:
                spliced[e.kind] = e if e.kind not in spliced else splice_estimates(spliced[e.kind], e, s.t_from)
        return [spliced[k].states for k in kinds]

    baseline = [e.states for e in tracked.estimates]
    shares = [np.zeros((*b.shape, b.shape[-1])) for b in baseline]
    if offsets is not None and np.any(offsets > 0):
        shares = [a + b for a, b in zip(shares, offset_shares(measurements, offsets, baseline, respond), strict=True)]
    along = tracked.primary
    if clocks is not None and np.any(clocks > 0):
        shares = [a + b for a, b in zip(shares, clock_shares(measurements, model, clocks, along.times, along.states,
                                                              baseline, respond), strict=True)]
    if sites is not None and np.any(sites > 0):
        shares = [a + b for a, b in zip(shares, site_shares(measurements, model, sites, along.times, along.states,
                                                             baseline, respond), strict=True)]
    by_kind = dict(zip(kinds, shares, strict=True))
    estimates = []
    for e in result.estimates:
        if e.kind in by_kind:
            if not np.array_equal(e.times, tracked.estimate(e.kind).times):
                raise RuntimeError(f"{info.name}: the {e.kind} estimates' times changed after the run")
            e = replace(e, covariances=e.covariances + by_kind[e.kind])
        estimates.append(e)
    share = by_kind.get(result.primary.kind)
    return (replace(result, estimates=tuple(estimates)),
            checked if checked is None or share is None else checked + share)


def _with_track_reference(result: TrackResult, checked: NDArray[np.float64] | None,
                          reference: TrackResult) -> TrackResult:
    """``result`` with the whole-track ``reference`` finding (:func:`~fgdoppler.estimators.judge.track_reference`)
    read on the primary covariances ``checked`` where given: those after the sampled checks and the offsets but
    not widened towards the reference's own track, which could not disagree with it (where the reference is
    wrong, the disagreement is the evidence)."""
    own = result.primary if checked is None else replace(result.primary, covariances=checked)
    return replace(result, reasons=(*result.reasons, *track_reference(own, reference.primary)))


#: Initiation findings about its covariance only, which an offline smoother does not use: informational there.
START_COVARIANCE_FINDINGS = frozenset({"nonlinear"})


def _with_initiation_reasons(result: TrackResult, init: Initiation, *, native: bool = False) -> TrackResult:
    """The track's reasons with those of the initiation it started from.

    An ambiguity resolved by the track is not one; a finding about the
    start covariance (:data:`START_COVARIANCE_FINDINGS`) stays doubtful for a
    filter that carries that covariance on, and is informational for the
    offline smoother, which re-solves from all the data, and for a tracker
    that started from the Gaussian sum of the window's posterior instead, or
    carries the posterior itself (``native``: the particle estimator).
    """
    informational = native or result.primary.kind == "smoothed" or init.window_summarised
    inherited = tuple(
        Reason(code=f"initiation-{r.code}",
               status="ok" if (informational and r.code in START_COVARIANCE_FINDINGS) else r.status,
               message=f"initiation: {r.message}", zone=r.zone, mirror=r.mirror,
               pairs=r.pairs)
        for r in init.reasons if r.code != "ambiguous")
    return replace(result, reasons=inherited + result.reasons) if inherited else result


def track(
    measurements: Measurements,
    model: TrackingModel | Geometry,
    estimator: str = "smoother",
    *,
    settings: TrackerSettings | None = None,
    initiation: InitiationSettings | None = None,
    init_per_pair: int = 10,
    init_seconds: float = 4.5,
    progress: Progress | None = None,
) -> TrackResult:
    """Initiate from the first ``init_per_pair`` measurements of each pair and the first ``init_seconds``, then run ``estimator``.

    The one-call form of :func:`~fgdoppler.estimators.initiation.initiate`
    followed by :func:`run_estimator` (``progress``: :mod:`fgdoppler.progress`);
    the window is :meth:`~fgdoppler.measurements.Measurements.initiation_window`.
    """
    model = as_tracking_model(model)
    init = initiate(measurements.initiation_window(init_per_pair, init_seconds), model, initiation)
    return run_estimator(estimator, measurements, model, init, settings, progress=progress)
