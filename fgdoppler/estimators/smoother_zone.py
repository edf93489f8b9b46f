r"""The offline smoother's findings about the zone: whether the data prefer a start outside it.

Every verdict assumes that the zone holds the target's start.  Where the
zone visibly constrains the answer, the 2-D smoother looks beyond it: behind
a wall that holds the track (:func:`_beyond_wall_2d`), outside the zone on
every side where the track fits poorly (:func:`_outside_zone_2d`), and at
the tracks the wall held that gave way to the reported one
(:func:`_released_reason`).  The track itself stays — the zone is the
user's — and a ``doubtful`` finding advises the zone to try
(:func:`_zone_advice`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from scipy.stats import chi2

from fgdoppler._text import distance_text
from fgdoppler.estimators.initiation import Initiation, inlier_statistic
from fgdoppler.estimators.search_memo import SearchMemo
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.smoother_modes import (
    MODES_PER_PAIR,
    _apart,
    _recording_starts,
    _searchable_2d,
    _smooth_from,
)
from fgdoppler.estimators.smoother_solve import (
    WALL_GAIN,
    FloatArray,
    SmootherSolution,
    _data_cost,
    _held_start,
    _offsets_gain,
    _offsets_text,
    _wall_reason,
)
from fgdoppler.estimators.verdict import Reason
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress
from fgdoppler.zone import Zone

if TYPE_CHECKING:
    from fgdoppler.estimators.grid import HalfPlane

__all__ = ["EDGE_SHARE", "OUTSIDE_GAIN", "OUTSIDE_LEVEL", "WIDEN"]

#: How far the search behind a zone wall that holds the track (:func:`_beyond_wall_2d`) widens the bound.
WIDEN = 1.5
#: χ² level of the track's cost above which the 2-D smoother also searches outside the zone
#: (:func:`_outside_zone_2d`).
OUTSIDE_LEVEL = 0.90
#: How much lower the cost of a track starting outside the zone must be for the ``zone`` finding of
#: :func:`_outside_zone_2d`: χ²₁ at 99.9 %, the verdict's level.
OUTSIDE_GAIN = float(chi2.ppf(0.999, 1))
#: A start found by the searches outside the zone nearer a bound of the searched box than this share of that
#: side (or of the speed bound), or past it, is said to lie at the search's edge.
EDGE_SHARE = 0.01


def _widened(zone: Zone, x0: FloatArray | None) -> Zone:
    """``zone`` with each bound that holds ``x0`` moved out (``None``: every bound): :data:`WIDEN` times the
    speed bound, a box side by ``WIDEN - 1`` times the box's extent on its axis."""
    e = np.ones(zone.dim + 1) if x0 is None else zone.excess(x0)[0]
    intervals = []
    for (lo, hi), ext, ei in zip(zone.intervals, zone.extents, e[:-1], strict=True):
        grow = (WIDEN - 1.0) * ext
        intervals.append((lo - grow if ei < 0 or x0 is None else lo, hi + grow if ei > 0 else hi))
    return replace(zone, along=intervals[0], across=intervals[1],
                   speed_max=zone.speed_max * WIDEN if e[-1] > 0 else zone.speed_max)


def _beyond_wall_2d(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                    sol: SmootherSolution, window: Measurements, progress: Progress | None = None, *,
                    half_plane: HalfPlane | None = None, memo: SearchMemo | None = None,
                    offsets: Callable[[FloatArray, FloatArray], float] | None = None) -> Reason | None:
    r"""2-D: the ``boundary`` test of a track held by the zone wall, against the data's modes beyond the wall.

    The test in :func:`~fgdoppler.estimators.smoother_solve.solve_smoother` releases the wall from where the
    track stopped, and so finds only the basin it is in.  Measured on a
    random layout (``studies/random_layouts.py --speed-max 250``, draw 57:
    a target at 229 m/s, the zone's bound 200 m/s): the track held at the
    bound ended 6.9 km from the truth with a sigma of 254 m; released
    there it gained 3.4 in cost (``ok``), while the truth's mode, which
    starts outside the bound, fits the data better by 19.  So both
    initiations are run again over the zone widened where the wall holds
    (:func:`_widened`) — the initiation window's (``window``: what the user
    would get with the wider zone; it finds that mode on the study's draw)
    and the whole recording's (:func:`~fgdoppler.estimators.smoother_modes._recording_starts`; it finds it on
    another seed of that layout, where the window's does not) — the smoother runs without the
    wall from each of their solutions (their constant-velocity tracks) and
    from the held track, and the lowest cost :math:`c_f` found is tested
    against the held track's cost without the wall :math:`c_h`:
    ``"doubtful"`` when :math:`c_h - c_f > \chi^2_{1,0.95}`.  The track
    itself stays: the zone is the user's, and the finding tells them to
    widen it.  ``None`` where the wall does not hold or the search does
    not apply (as :func:`~fgdoppler.estimators.smoother_modes._modes_2d`).  A ``memo`` runs each search once for
    all of a call's hypotheses.  With calibration offsets declared, ``offsets`` tests the lowest-cost track
    found in the model with them (:func:`~fgdoppler.estimators.smoother_solve._wall_reason`).
    """
    zone = model.zone
    if zone is None or not settings.region_bound or not _searchable_2d(model, sol) \
            or not any(r.code == "boundary" for r in sol.reasons):
        return None
    found = _best_outside_2d(measurements, model, settings, sol, window, _widened(zone, sol.states[0]), progress,
                             half_plane=half_plane, memo=memo)
    if found is None:
        return None
    best, inside, searched, advise = found
    return _wall_reason(zone, sol.states, inside, best.states, best.cost, searched, advise, offsets)


def _best_outside_2d(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                     sol: SmootherSolution, window: Measurements, wide_zone: Zone, progress: Progress | None, *,
                     half_plane: HalfPlane | None, memo: SearchMemo | None
                     ) -> tuple[SmootherSolution, float, str, Callable[[], tuple[str, Zone]]] | None:
    """The lowest-cost track without the zone wall from ``sol`` and from both initiations over ``wide_zone``
    (:func:`_beyond_wall_2d` says which), ``sol``'s own data cost, where it was searched, and what gives the
    zone to advise (:func:`_zone_advice`, which costs a smoother run: asked only for a ``doubtful`` finding;
    ``None``: the smoother could start from none of them)."""
    from fgdoppler.estimators.initiation import InitiationSettings, initiate

    wide = model.with_zone(wide_zone)
    assert wide.zone is not None

    def window_starts() -> list[FloatArray]:
        try:
            again = initiate(window, wide, InitiationSettings(huber_k=settings.huber_k, half_plane=half_plane,
                                                               mistake_check=False))
        except ValueError:
            return []
        return [model.motion.propagate(x, sol.times - again.t_start)
                for x in (again.x_start, *(a.state for a in again.alternatives))]

    w = wide.zone
    key = ("window", window.time.tobytes(), window.pair.tobytes(), half_plane, settings.huber_k,
           (w.along, w.across, w.altitude, w.speed_max))
    starts = [sol.states, *(window_starts() if memo is None else memo.starts(measurements, key, window_starts))]
    try:
        starts += _recording_starts(measurements, wide, settings, progress, per_pair=MODES_PER_PAIR,
                                    half_plane=half_plane, k_best=settings.mode_candidates, memo=memo)
    except ValueError:
        pass
    free = _smooth_from(measurements, model, replace(settings, region_bound=False, covariances=False), starts,
                        progress, memo)
    if not free:
        return None
    best = min(free, key=lambda s: s.cost)
    inside = _data_cost(measurements, model, settings, sol)
    w = wide.zone
    # a start on the searched box's edge (or past it) was found only as far as the search reached
    edge = "; the start found lies at the edge of the search: the target may start farther out still" \
        if _at_edge(w, best.states[0]) else ""
    searched = (f" (searched to {w.speed_max:.0f} m/s, along {distance_text(w.along[0])} to "
                f"{distance_text(w.along[1])}, across {distance_text(w.across[0])} to {distance_text(w.across[1])}"
                f"{edge})")
    return best, inside, searched, partial(_zone_advice, measurements, model, settings, best, progress,
                                           half_plane=half_plane, memo=memo)


def _zone_advice(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                 best: SmootherSolution, progress: Progress | None, *, half_plane: HalfPlane | None,
                 memo: SearchMemo | None) -> tuple[str, Zone]:
    """The zone a search outside it advises, and its words: one that holds ``best``'s start — and its mirror
    image's where that is a mode the data cannot tell from it.

    Sensors near one line give a track and its mirror image across that
    line nearly the same Doppler.  Measured on a quasi-monostatic radar
    with a bistatic receiver 30 km away (antennas 20 m apart, the three
    sensors within 3.3 m of one line; a target 9.4 km off it, outside the
    default zone; seeds 0–7): the search found the mirror image's start in
    7 of 8 recordings, and with a zone advised to hold only that start the
    smoother reported the mirror track, 14–15 km from the truth, ``ok`` in
    4 of them (the final position's squared Mahalanobis distance
    1,200–2,800).  With the twin in the advised zone all 8 runs that follow
    it are ``doubtful`` by the ``competing`` finding, 6 on the truth's
    track (75–1,213 m from it at the end, within 3 σ), 2 on the mirror's
    (``python studies/zone_advice.py``, and ``--no-twin 1`` for the
    advice without it).  So the smoother is run once more,
    without the wall, from the mirror image of ``best``
    (:func:`~fgdoppler.estimators.smoother_offsets.mirrored`); a solution
    apart from ``best`` (:func:`~fgdoppler.estimators.smoother_modes._apart`) costing less than
    :data:`~fgdoppler.estimators.ambiguity.COMPETING` more is a twin, and
    the advised zone holds both starts, so that the modes search of the
    next run sees both and says whether the data tell them apart.  Not
    where the user's half plane rules the mirror out.
    """
    from fgdoppler.estimators.ambiguity import COMPETING
    from fgdoppler.estimators.smoother_offsets import mirrored

    zone = model.zone
    assert zone is not None
    advised = zone.reaching(best.states[0])
    geometry = getattr(model.observation, "geometry", None)
    if geometry is None or half_plane is not None:
        return _held_start(advised)
    twins = [s for s in _smooth_from(measurements, model, replace(settings, region_bound=False, covariances=False),
                                     [mirrored(best.states, geometry)], progress, memo)
             if _apart(best, s) and s.cost < best.cost + COMPETING]
    if not twins:
        return _held_start(advised)
    twin = min(twins, key=lambda s: s.cost)
    both = advised.reaching(twin.states[0])
    return (f"and its mirror image across the sensors' line, whose track fits the data nearly as well (cost "
            f"{twin.cost:.2f}), e.g. {both.options()}", both)


def _at_edge(zone: Zone, x0: FloatArray) -> bool:
    """Whether the start ``x0`` lies within :data:`EDGE_SHARE` of a side (or of the speed bound) of ``zone``'s
    box from inside, or outside it."""
    d = zone.dim
    u = zone.frame.points_to_local(x0[:d])
    near = [not (lo + EDGE_SHARE * (hi - lo) < ui < hi - EDGE_SHARE * (hi - lo))
            for ui, (lo, hi) in zip(u, zone.intervals, strict=True)]
    return any(near) or float(np.linalg.norm(x0[d:])) >= (1.0 - EDGE_SHARE) * zone.speed_max


def _outside_zone_2d(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                     sol: SmootherSolution, window: Measurements, progress: Progress | None = None, *,
                     half_plane: HalfPlane | None = None,
                     memo: SearchMemo | None = None) -> Reason | None:
    r"""2-D: a track that fails the χ² check, no wall holding it, against the data's modes outside the zone.

    Measured on a random layout (``studies/random_layouts.py --first 180
    --speed-max 250``, draw 231: two pairs, a target at 248 m/s, the zone's
    bound 200 m/s): the only mode that fits the data starts outside the
    zone, so the smoother settled in a mode inside it, 52.6 km from the
    truth with a sigma of 58 m; its cost (179.7) failed the smoother's own
    99.9 % χ² check (171.2) but not the verdict's, which leaves out one
    residual as an outlier, the wall did not hold it and the re-initiation
    inside the zone found nothing better: ``ok``.  Started from the truth
    without the wall the smoother reaches a cost of 112.8.  On that layout
    over 8 seeds the wrong mode's cost lies at χ² p-values of 0.05 to
    1e-5: a 99.9 % level would have searched in 5 of them, 95 % in all but
    one (p = 0.0500), 90 % (:data:`OUTSIDE_LEVEL`) in all.  With 5 % gross
    outliers and the Huber loss the same layout gave a wrong ``ok`` in 6 of
    8 seeds; the robust cost is not a χ² statistic, so there the misfit is
    the inliers' (:func:`~fgdoppler.estimators.initiation.inlier_statistic`,
    on as many fewer degrees of freedom as outliers left out), above the
    level in all 8.  So where the misfit exceeds that level, both
    initiations are run again
    over the zone widened on every side and in speed (:func:`_widened`) and
    the smoother without the wall from each of their solutions, as in
    :func:`_beyond_wall_2d`; a track starting outside the zone whose cost
    is lower than the track's by more than :data:`OUTSIDE_GAIN`
    (:math:`\chi^2_{1,0.999}` = 10.8) is a ``zone`` finding, ``doubtful``.
    Not :math:`\chi^2_{1,0.95}` as behind a wall: a track inside the zone
    is the user's assumption, not a sign of trouble, and on the accuracy
    benchmark's recordings (1,200, both seeds) the 90 % level searched in
    three well-observed runs (a-45, b-5) whose answers are right (73–96 m)
    and found a mode starting 7 km outside the zone lower by 4.8–6.8; on
    draw 231 the found mode is lower by 31–72 (16 runs, both losses).
    The track itself stays: the zone is the user's, and the finding tells
    them to widen it.
    """
    zone = model.zone
    if zone is None or not _searchable_2d(model, sol):
        return None
    misfit, outliers = (sol.cost, 0) if settings.huber_k is None else \
        inlier_statistic(model, measurements, sol.states, sol.times)
    threshold = float(chi2.ppf(OUTSIDE_LEVEL, max(len(measurements) - outliers - model.n, 1)))
    if misfit <= threshold:
        return None
    found = _best_outside_2d(measurements, model, settings, sol, window, _widened(zone, None), progress,
                             half_plane=half_plane, memo=memo)
    if found is None:
        return None
    best, inside, searched, advise = found
    excess, _ = zone.excess(best.states[0])
    gain = inside - best.cost
    if gain <= OUTSIDE_GAIN or not np.any(excess != 0.0):
        return None
    d = zone.dim
    text, advised = advise()
    return Reason(code="zone", status="doubtful", zone=advised.box(), message=(
        f"the track fits the data poorly ({'cost' if settings.huber_k is None else 'inlier chi-square'} "
        f"{misfit:.1f} above the {OUTSIDE_LEVEL:.0%} chi-square level {threshold:.1f}) and a track starting outside the zone fits them better{searched}: cost {best.cost:.2f} instead of "
        f"{inside:.2f}, lower by {gain:.1f} > {OUTSIDE_GAIN:.2f}, starting "
        f"{distance_text(np.linalg.norm(best.states[0, :d] - sol.states[0, :d]))} away at "
        f"{np.linalg.norm(best.states[0, d:]):.0f} m/s ({zone.excess_text(best.states[0])}): the target may be outside the zone; widen it to hold that "
        f"start, {text}"))


def _outside_findings(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                      sol: SmootherSolution, init: Initiation, reasons: list[Reason], progress: Progress | None,
                      memo: SearchMemo | None, offsets: Callable[[FloatArray, FloatArray], float] | None = None
                      ) -> list[Reason]:
    """``reasons`` after the 2-D searches outside the zone: beyond a wall that holds the track (its
    ``boundary`` finding replaced, :func:`_beyond_wall_2d`, with the declared calibration offsets in the model
    where ``offsets`` is given), else where the track fits poorly (a ``zone`` finding added,
    :func:`_outside_zone_2d`)."""
    window = measurements.between(init.t_start, init.t_end)
    beyond = _beyond_wall_2d(measurements, model, settings, sol, window, progress, half_plane=init.half_plane,
                             memo=memo, offsets=offsets)
    if beyond is not None:
        return [beyond if r.code == "boundary" else r for r in reasons]
    if any(r.code == "boundary" for r in reasons):
        return reasons
    outside = _outside_zone_2d(measurements, model, settings, sol, window, progress, half_plane=init.half_plane,
                               memo=memo)
    return reasons if outside is None else [*reasons, outside]


def _held_with_offsets(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                       sol: SmootherSolution, reasons: list[Reason],
                       offsets: Callable[[FloatArray, FloatArray], float] | None) -> list[Reason]:
    """``reasons`` with the solve's own ``boundary`` finding — the held track released from where it stopped
    (:func:`~fgdoppler.estimators.smoother_solve.solve_smoother`) — tested again with the declared calibration
    offsets in the model (``offsets``), where it is ``doubtful`` and no search beyond the wall replaced it (3-D,
    or nothing found there: :func:`_beyond_wall_2d`)."""
    own = [r for r in sol.reasons if r.code == "boundary" and r.status == "doubtful"]
    if offsets is None or sol.released is None or model.zone is None or not own:
        return reasons
    free, free_cost = sol.released
    again = _wall_reason(model.zone, sol.states, _data_cost(measurements, model, settings, sol), free, free_cost,
                         offsets=offsets)
    return [again if any(r is o for o in own) else r for r in reasons]


def _released_reason(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                     sol: SmootherSolution, released: Sequence[tuple[FloatArray, float]], *,
                     offsets: Callable[[FloatArray, FloatArray], float] | None = None) -> list[Reason]:
    r"""A ``boundary`` finding, ``doubtful``, where a track the zone wall held gave way to ``sol`` and,
    released from the wall, fits the data better than ``sol`` from a start outside the zone (with calibration
    offsets declared, in the model with them: ``offsets``, :func:`~fgdoppler.estimators.smoother_solve._wall_reason`).

    The ``boundary`` test (:func:`~fgdoppler.estimators.smoother_solve._boundary_test`) is a likelihood-ratio
    test of the wall for the track it holds.  When the re-initiation or the
    mode search replaces that track by one of lower cost inside the zone,
    or the hypothesis it came from loses to another of an ambiguous
    initiation (:meth:`SmootherDraft.joined`), its finding went with it,
    though the constrained optimum is now ``sol`` and the unconstrained one
    may still be the released track.  Measured on a random layout
    (``studies/random_layouts.py --first 300 --speed-max 250``, draw 317:
    two pairs, a target at 212 m/s, the zone's bound 200 m/s): the first
    track was held at the bound 1.9 km from the truth's start (cost 520.1;
    released, 127.5 at 213 m/s), failed the χ² check and was replaced by
    the re-initiation's track inside the zone, 33.8 km from the truth with
    σ 182 m and cost 132.1, which the wall does not hold and which fits
    below the 90 % level of the search outside the zone
    (:func:`_outside_zone_2d`): ``ok``.  On the same layout with seeds 0–7
    an initiation hypothesis sits at the bound in 7; its track, held and
    released, fits better than the reported one in 6 (by 4.1–11.7), while
    the lowest-cost hypothesis, the same 33.5 km wrong track, was reported
    ``ok`` in all 8.  So the released tracks are tested against ``sol`` at
    the ``boundary`` test's level, :data:`~fgdoppler.estimators.smoother_solve.WALL_GAIN`: a released
    track lies in a basin the wall cut (reached from the bound by descent),
    not in a mode found by a search beyond the zone, whose threshold is
    :data:`OUTSIDE_GAIN`.  Nothing where ``sol`` holds a ``boundary``
    finding of its own or no track was held.
    """
    zone = model.zone
    if zone is None or any(r.code == "boundary" for r in sol.reasons):
        return []
    outside = [r for r in released if np.any(zone.excess(r[0][0])[0] != 0.0)]
    if not outside:
        return []
    free, free_cost = min(outside, key=lambda r: r[1])
    inside = _data_cost(measurements, model, settings, sol)
    gain = inside - free_cost
    joint = _offsets_gain(offsets, sol.states, free, gain, WALL_GAIN)
    said = _offsets_text(joint, gain)
    gain = gain if joint is None else joint
    if gain <= WALL_GAIN:
        return []
    d = zone.dim
    text, advised = _held_start(zone.reaching(free[0]))
    return [Reason(code="boundary", status="doubtful", zone=advised.box(), message=(
        f"a track held at the zone's boundary was replaced by this one (cost {inside:.2f}), but released from the "
        f"bound it fits the data better: cost {free_cost:.2f}, lower by {gain:.1f}{said} > {WALL_GAIN:.2f}, starting "
        f"{distance_text(np.linalg.norm(free[0, :d] - sol.states[0, :d]))} away at "
        f"{np.linalg.norm(free[0, d:]):.0f} m/s ({zone.excess_text(free[0])}): the data prefer a start outside "
        f"the zone; widen the zone to hold that start, {text}"))]
