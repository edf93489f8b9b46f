r"""The offline smoother's searches for other modes of the whole recording, and the ``competing`` rule.

The initiation sees a few seconds of data; the whole recording can hold
narrow modes its window could not separate.  Offline, every measurement is
available: the recording is initiated again where the track cannot explain
the data (:func:`_reinitiate`), searched for other modes in 2-D
(:func:`_modes_2d`) and restarted at every altitude level in 3-D
(:func:`_restarts_3d`); another mode that explains the data about as well
is a ``competing`` finding (:func:`_rival_reason`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np
from scipy.stats import chi2

from fgdoppler._text import distance_text
from fgdoppler.estimators.search_memo import SearchMemo
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.smoother_solve import FloatArray, SmootherSolution, solve_smoother
from fgdoppler.estimators.spread import MAX_SPAN
from fgdoppler.estimators.verdict import Reason
from fgdoppler.geometry import MIRROR_ADVICE, is_mirror_image
from fgdoppler.measurements import Measurements
from fgdoppler.models.observation import DopplerModel
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance, prefixed, start_task
from fgdoppler.zone import Zone

if TYPE_CHECKING:
    from fgdoppler.estimators.grid import HalfPlane
    from fgdoppler.geometry import Geometry

__all__ = ["MODES_PER_PAIR", "REINITIATE_PER_PAIR"]

REINITIATE_PER_PAIR = 64
"""Measurements per pair the re-initiation's grid scores (evenly spread over the recording)."""
#: Measurements per pair the grid of the 2-D whole-recording mode search scores (:func:`_modes_2d`), as the
#: trackers' restart checks (:data:`fgdoppler.estimators.restart.PER_PAIR`).
MODES_PER_PAIR = 16


class _Mode(Protocol):
    """A solution the mode rules compare: a smoother's, or a joint one of track and offsets."""

    @property
    def states(self) -> FloatArray: ...

    @property
    def covariances(self) -> FloatArray | None: ...

    @property
    def cost(self) -> float: ...


def _reinitiate(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                progress: Progress | None = None, per_pair: int = REINITIATE_PER_PAIR,
                memo: SearchMemo | None = None, half_plane: HalfPlane | None = None) -> SmootherSolution | None:
    """Multi-start deterministic-CV ML over the whole recording, then the full smoother from its best solution.

    The grid scores ``per_pair`` measurements of each pair, evenly spread over the recording, on the side of
    ``half_plane`` (the initiation's) where one is given.  ``None`` where no start can be found — also when the
    recording needs a speed above the zone's bound, which the grid refuses to search (the verdict's ``zone``
    finding says so, :mod:`fgdoppler.estimators.judge`).
    """
    try:
        starts = _recording_starts(measurements, model, settings, progress, per_pair=per_pair,
                                   half_plane=half_plane, memo=memo)
    except ValueError:
        return None
    found = _smooth_from(measurements, model, settings, starts[:1], progress, memo)
    return found[0] if found else None


def _recording_starts(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                      progress: Progress | None = None, *, per_pair: int,
                      half_plane: HalfPlane | None = None, k_best: int = 5,
                      memo: SearchMemo | None = None) -> list[FloatArray]:
    """Start trajectories of the multi-start initiation of the whole recording: its best solution first, then
    its alternatives, each the constant-velocity track of the solution at every scan time.

    The grid scores ``per_pair`` measurements of each pair, evenly spread over
    the recording; Levenberg–Marquardt refines its ``k_best`` best distinct
    candidates on every measurement (deterministic constant velocity).
    ``half_plane`` (the initiation's) binds them to the side the user gave.
    A ``memo`` runs each search once for all of a call's hypotheses.
    """
    if memo is not None:
        zone = model.zone
        key = ("starts", per_pair, k_best, half_plane, settings.huber_k,
               None if zone is None else (zone.along, zone.across, zone.altitude, zone.speed_max))
        return list(memo.starts(measurements, key, lambda: _recording_starts(
            measurements, model, settings, progress, per_pair=per_pair, half_plane=half_plane, k_best=k_best)))
    from fgdoppler.estimators.initiation import InitiationSettings, initiate, window_grid

    init_settings = InitiationSettings(window="cv", huber_k=settings.huber_k, half_plane=half_plane, k_best=k_best,
                                       mistake_check=False)
    # The grid only has to find the basins, and its cost grows with the measurements it
    # scores: search a bounded, evenly spread subset, then let LM refine each candidate
    # against every measurement.
    scans = measurements.scans()
    start_task(progress, "re-initiation", 1)
    grid = window_grid(measurements.spread(per_pair), model, init_settings)
    full = initiate(measurements, model, init_settings, grid_result=grid)
    advance(progress)
    return [model.motion.propagate(x, scans.times - full.t_start)
            for x in (full.x_start, *(a.state for a in full.alternatives))]


def _smooth_from(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                 starts: list[FloatArray], progress: Progress | None = None, memo: SearchMemo | None = None
                 ) -> list[SmootherSolution]:
    """The smoother from each start trajectory (those it cannot start from are left out).

    A ``memo`` solves from each start once for all of a call's hypotheses.
    """
    out = []
    for i, x0 in enumerate(starts):
        name = "re-initiated" if len(starts) == 1 else f"re-initiated {i + 1}/{len(starts)}"

        def solve(x0: FloatArray = x0, name: str = name) -> SmootherSolution | None:
            try:
                return solve_smoother(measurements, model, x0, settings, prior=model.prior(),
                                      progress=prefixed(progress, name))
            except ValueError:
                return None

        x0 = np.asarray(x0, dtype=float)
        sol = solve() if memo is None else memo.solution(measurements, ("solution", x0.shape, x0.tobytes(), settings),
                                                          solve)
        if sol is not None:
            out.append(sol)
    return out


def _searchable_2d(model: TrackingModel, sol: SmootherSolution) -> bool:
    """Whether the 2-D whole-recording searches apply: a 2-D Doppler model with a zone, a recording no longer
    than :data:`~fgdoppler.estimators.spread.MAX_SPAN` (:func:`_modes_2d` says why)."""
    return model.dim == 2 and model.zone is not None and isinstance(model.observation, DopplerModel) \
        and float(sol.times[-1] - sol.times[0]) <= MAX_SPAN


def _modes_2d(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
              sol: SmootherSolution, progress: Progress | None = None, *, half_plane: HalfPlane | None = None,
              memo: SearchMemo | None = None) -> tuple[SmootherSolution, list[str], list[Reason]]:
    r"""2-D: smooth again from each other mode of a multi-start over the whole recording; report rivals.

    The initiation sees a few seconds of data, whose likelihood can hold
    several basins that the whole recording separates into narrow modes;
    Levenberg–Marquardt keeps the one its start lies in, and the χ² test of
    the residuals cannot tell it from another that fits as well.  Measured
    on random layouts of two to four pairs (docs/concepts.md, "Modes of the
    whole recording"): tracks 0.5-24 km from the truth with a reported
    sigma of 4-270 m were judged ``ok`` while a multi-start over the whole
    recording finds the truth's mode within 1.3 in cost.  So the whole
    recording is initiated again (:func:`_recording_starts`,
    :data:`MODES_PER_PAIR` measurements of each pair scored by the grid);
    the smoother runs from each solution whose start lies outside the
    current solution's 99.9 % region (the others are its own mode); a
    distinct solution whose cost is lower by more than
    :data:`~fgdoppler.estimators.ambiguity.COMPETING` replaces it (between
    modes the data cannot tell apart the initiation's stays, and the
    verdict says so); and another solution is a rival — a ``competing``
    finding, ``doubtful`` — by the rule of :func:`_restarts_3d`.  A half
    plane given to the initiation binds the search too.  Recordings longer
    than :data:`~fgdoppler.estimators.spread.MAX_SPAN` are not searched:
    the search fits deterministic constant-velocity tracks, which a track
    with process noise leaves over a long recording (and each fit would
    cost a pass over every measurement).
    """
    zone = model.zone
    if zone is None or not _searchable_2d(model, sol):
        return sol, [], []
    try:
        starts = _recording_starts(measurements, model, settings, progress, per_pair=MODES_PER_PAIR,
                                   half_plane=half_plane, k_best=settings.mode_candidates, memo=memo)
    except ValueError:  # the recording needs a speed above the zone's bound: the verdict's `zone` finding
        return sol, [], []
    if sol.covariances is not None and np.all(np.isfinite(sol.covariances[0])):
        limit = float(chi2.ppf(0.999, model.n))
        P0 = sol.covariances[0]
        try:
            starts = [x for x in starts if float((x[0] - sol.states[0]) @ np.linalg.solve(P0, x[0] - sol.states[0]))
                      > limit]
        except np.linalg.LinAlgError:
            pass
    found = [sol, *_smooth_from(measurements, model, settings, starts, progress, memo)]
    from fgdoppler.estimators.ambiguity import COMPETING

    return _best_and_rival(found, sol, zone, margin=COMPETING, geometry=getattr(model.observation, "geometry", None))


def _best_and_rival(found: list[SmootherSolution], sol: SmootherSolution, zone: Zone, *,
                    margin: float | None = None, geometry: Geometry | None = None
                    ) -> tuple[SmootherSolution, list[str], list[Reason]]:
    """The lowest-cost solution, a note if it moved the track, and its findings (floor and rival).

    With a ``margin``, ``sol`` stays unless another *mode* (ending farther
    than 50 m and three of ``sol``'s standard deviations from it) costs
    less by more than ``margin``: the same mode found again, or one the data
    cannot tell from it, does not replace it.
    """
    k = sol.states.shape[1] // 2
    if margin is not None:
        found = [sol, *(s for s in found if s is not sol and _apart(sol, s))]
        better = [s for s in found if s.cost < sol.cost - margin]
        best = min(better, key=lambda s: s.cost) if better else sol
    else:
        best = min(found, key=lambda s: s.cost)
    end = best.states[-1, :k]
    moved = float(np.linalg.norm(sol.states[-1, :k] - end))
    notes = []
    if moved > 50.0 and moved > 3.0 * _sigma_along(best, (sol.states[-1, :k] - end) / moved):
        notes.append(f"a restart lowered the cost from {sol.cost:.2f} to {best.cost:.2f} (the track's end moved "
                     f"{distance_text(moved)})")
    floor = _floor_reason(best, zone) if zone.altitude is not None and k == 3 else None
    reasons = [r for r in (floor, _rival_reason(found, best, zone, geometry)) if r is not None]
    return best, notes, reasons


def _apart(a: _Mode, b: _Mode) -> bool:
    """``b`` ends farther from ``a`` than 50 m and three of ``a``'s standard deviations in that direction."""
    k = a.states.shape[1] // 2
    d_vec = b.states[-1, :k] - a.states[-1, :k]
    d = float(np.linalg.norm(d_vec))
    return d > 50.0 and d > 3.0 * (_sigma_along(a, d_vec / d) if d > 0 else 0.0)


def _restarts_3d(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                 sol: SmootherSolution, progress: Progress | None = None, memo: SearchMemo | None = None
                 ) -> tuple[SmootherSolution, list[str], list[Reason]]:
    r"""3-D only: smooth again from other starts, keep the lowest cost, and report rival solutions.

    Ground sensors measure height only through :math:`z/r` and are blind to
    its sign, and over nearly collinear sensors a target rotated about their
    line gives almost the same Doppler: distinct tracks can explain the data
    about as well, and Levenberg–Marquardt keeps whichever basin its start
    lies in.  So the solution is restarted (a) from its horizontal track at
    each altitude level of the initiation grid (:meth:`GridSpec.levels`),
    level in the zone's frame, and (b) from a multi-start initiation over the
    whole recording (as the χ²-triggered re-initiation); the lowest cost wins.

    Another solution :math:`s` ending :math:`d` from the best one, farther
    than 50 m and 3σ along that direction (σ from the best's covariance), is a
    rival — a ``competing`` finding, ``doubtful`` — when the data cannot tell
    them apart (cost difference :math:`\Delta` below χ²₁ at 95 %) or when its
    posterior weight :math:`w = e^{-\Delta/2}` is large enough for its share
    of the mean-square error, :math:`\tfrac{w}{1+w}d^2`, to exceed
    :math:`(3\sigma)^2`: then the reported covariance, a Gaussian about the
    best solution, understates the error.  (Measured on the paper's case a
    at 5 km flown at 0 km: a track 41 km from the truth was 3.9 *lower* in
    cost than the truth's basin, with σ = 1.4 km; the χ² rule alone called it
    ``ok``.)  A solution that sinks below the altitude band's floor by more
    than 50 m and 3σ somewhere along the track is not a rival: for ground
    sensors the floor is the ground, and a best track that sinks below it that
    far is an ``altitude`` finding, ``doubtful``.
    """
    zone = model.zone
    if model.dim != 3 or zone is None or zone.altitude is None:
        return sol, [], []
    return _best_and_rival(_restart_solutions(measurements, model, settings, sol, zone, progress, memo), sol, zone)


def _restart_solutions(measurements: Measurements, model: TrackingModel, settings: SmootherSettings,
                       sol: SmootherSolution, zone: Zone, progress: Progress | None,
                       memo: SearchMemo | None = None) -> list[SmootherSolution]:
    """``sol`` and the smoother's solutions from level flight at each grid altitude and from a global multi-start."""
    from fgdoppler.estimators.grid import GridSpec

    local = zone.frame.states_to_local(sol.states)
    found = [sol]
    for level in GridSpec().levels(zone):
        start = local.copy()
        start[:, 2] = level
        start[:, 5] = 0.0
        try:
            found.append(solve_smoother(measurements, model, zone.frame.states_to_world(start), settings,
                                        prior=model.prior(), progress=prefixed(progress, f"altitude {level:.0f} m")))
        except ValueError:
            continue
    if isinstance(model.observation, DopplerModel):
        # the grid only has to find the basins: a quarter of the 2-D re-initiation's measurements keeps the
        # 3-D grid (four altitude levels) at the 2-D one's cost
        again = _reinitiate(measurements, model, settings, progress, per_pair=REINITIATE_PER_PAIR // 4, memo=memo)
        if again is not None:
            found.append(again)
    return found


def _sigma_along(sol: _Mode, u: FloatArray) -> float:
    """Standard deviation of the solution's end position along the unit vector ``u`` (0 without a covariance)."""
    if sol.covariances is None or not np.all(np.isfinite(sol.covariances[-1])):
        return 0.0
    k = u.size
    return float(np.sqrt(max(u @ sol.covariances[-1][:k, :k] @ u, 0.0)))


def _floor_reason(best: SmootherSolution, zone: Zone) -> Reason | None:
    """An ``altitude`` finding when the track sinks below the band's floor by more than 50 m and 3σ."""
    assert zone.altitude is not None
    heights = zone.frame.states_to_local(best.states)[:, 2]
    k = int(np.argmin(heights))
    sd_z = 0.0 if best.covariances is None else float(np.sqrt(max(best.covariances[k][2, 2], 0.0)))
    if float(heights[k]) >= zone.altitude[0] - max(50.0, 3.0 * sd_z):
        return None
    return Reason(code="altitude", status="doubtful", message=(
        f"the track sinks to {heights[k]:.0f} m, below the altitude band's floor ({zone.altitude[0]:g} m) by "
        f"more than 3 sigma (sigma {sd_z:.0f} m): for sensors on the ground that is underground — the data "
        "do not fix the height"))


def _rival_reason(found: Sequence[_Mode], best: _Mode, zone: Zone, geometry: Geometry | None = None
                  ) -> Reason | None:
    """A ``competing`` finding for the rival with the largest share of the mean-square error (rule: :func:`_restarts_3d`).

    In 3-D a rival that sinks below the altitude band's floor is not one
    (:func:`_floor_reason` speaks of the best track's floor).  In 2-D, given
    the ``geometry``, a rival that ends nearer the mirror image of the
    reported track's end across the sensors' line than a quarter of the two
    ends' distance is called the mirror image, and the finding names the
    option that settles it (``--half-plane``: a side the data cannot tell).
    """
    from fgdoppler.estimators.ambiguity import COMPETING

    k = best.states.shape[1] // 2
    floor = zone.altitude[0] if k == 3 and zone.altitude is not None else None
    end = best.states[-1, :k]
    has_cov = _sigma_along(best, np.eye(k)[0]) > 0.0
    rivals = []
    for s in found:
        if not _apart(best, s):
            continue
        d_vec = s.states[-1, :k] - end
        d = float(np.linalg.norm(d_vec))
        sd = _sigma_along(best, d_vec / d)
        if floor is not None and float(np.min(zone.frame.states_to_local(s.states)[:, 2])) < floor - max(50.0, 3.0 * sd):
            continue
        delta = s.cost - best.cost
        w = float(np.exp(-0.5 * delta))
        share = w / (1.0 + w) * d * d
        if delta < COMPETING or (has_cov and share > 9.0 * sd * sd):
            rivals.append((share, s, d, sd, delta))
    if not rivals:
        return None
    _, rival, apart, sd, delta = max(rivals, key=lambda r: r[0])
    head = (f"another track explains the data nearly as well (cost {rival.cost:.2f} vs {best.cost:.2f}, posterior "
            f"weight {np.exp(-0.5 * delta):.2g} of the reported one's) and ends {distance_text(apart)} away")
    if floor is not None:
        return Reason(code="competing", status="doubtful", message=(
            f"{head} (height {zone.frame.points_to_local(rival.states[-1, :3])[2]:.0f} m vs "
            f"{zone.frame.points_to_local(end)[2]:.0f} m; reported sigma in that direction {sd:.0f} m): the data do "
            "not fix the track in 3-D"))
    mirror = geometry is not None and k == 2 and is_mirror_image(end, rival.states[-1], geometry)
    return Reason(code="competing", status="doubtful", message=(
        f"{head} (reported sigma in that direction {sd:.0f} m): the data do not tell the two apart, and the "
        "reported covariance, about one of them, understates the error"
        + (f"; the other track is the reported one's {MIRROR_ADVICE}" if mirror else "")),
        mirror="sensors" if mirror else None)
