r"""Mistakes in a measurement file that the initiation window names: a sign, two pairs' labels, a radar's Doppler.

Where the window fails the verdict's χ² test, it is initiated again with its
data changed as each such mistake would have changed them
(:func:`find_mistake`); a change under which it fits is a ``sign``,
``swapped`` or ``radial`` finding (:func:`with_mistake`) that names the
change and the others that pass the same test.  The same test on later
windows of a track that fits poorly is
:mod:`fgdoppler.estimators.later_mistakes`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fgdoppler._text import distance_text, pairs_text, time_text
from fgdoppler.estimators.initiation import (
    OUTLIER_CUT,
    VERDICT_LEVEL,
    Initiation,
    InitiationSettings,
    initiate,
    whitened_residuals,
)
from fgdoppler.estimators.judge import REJECT_ROBUST
from fgdoppler.estimators.verdict import Reason
from fgdoppler.geometry import Geometry, pair_labels
from fgdoppler.measurements import Measurements
from fgdoppler.models.robust import EFFICIENT_K
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.repeats import find_repeats

__all__ = [
    "HUBER_TRIED",
    "IN_KILOMETRES",
    "IN_SECONDS",
    "KILOMETRE_EXTENT",
    "OR_OUTSIDE_THE_ZONE",
    "OTHERS_NAMED",
    "SHORTEST_INTERVAL",
    "SIGN_CONVENTION",
    "TIME_UNITS",
    "WITH_OUTLIERS",
    "Mistake",
    "few_outliers",
    "find_mistake",
    "fits_beyond_the_zone",
    "kilometre_extent",
    "median_interval",
    "mistake_reason",
    "outliers_reason",
    "radar_pairs",
    "time_units_reason",
    "tries_time_units",
    "units_reason",
    "with_mistake",
]

FloatArray = NDArray[np.float64]

#: The data's sign convention, as a ``sign`` finding states it (docs/data-formats.md says the same).
SIGN_CONVENTION = ("fgdoppler's doppler is the bistatic range rate, negative for a target closing on the pair; "
                   "from a Doppler shift f_D in Hz, doppler = -wavelength * f_D (f_D positive for a closing target)")


#: Other changes under which a window fits that a mistake finding names (the rest it counts).
OTHERS_NAMED = 2

#: Largest distance (m) between two sensors of a geometry that :func:`units_reason` also tries in kilometres: a
#: layout 1,000 km across at most, read as metres.
KILOMETRE_EXTENT = 1000.0

#: What a ``units`` finding of :func:`units_reason` says (and only it: the verdict's own ``units`` findings do not).
IN_KILOMETRES = "the geometry likely gives kilometres where fgdoppler reads metres"

#: What every ``units`` finding of :func:`time_units_reason` says, after the unit it names.
IN_SECONDS = "where fgdoppler reads seconds"

#: What a mistake finding adds where the window also fits as given with its start outside the zone.
OR_OUTSIDE_THE_ZONE = ("but the window also fits as given with its start outside the zone (the boundary finding): the "
                       "target may start there instead, and then the data need no change")

#: The time units :func:`time_units_reason` tries, each with what a time in it is divided by to give seconds.
TIME_UNITS: tuple[tuple[str, float], ...] = (("milliseconds", 1e3), ("microseconds", 1e6))

#: Shortest interval (s) between a pair's measurements that :func:`time_units_reason` takes for real: a unit is
#: tried only where the median interval, divided as it says, is at least this (200 measurements a second).
SHORTEST_INTERVAL = 5e-3

#: The Huber threshold (whitened residuals) :func:`outliers_reason` fits a failing window with: ``--huber``'s default.
HUBER_TRIED = EFFICIENT_K

#: What an ``outliers`` finding of :func:`outliers_reason` says (and only it).
WITH_OUTLIERS = "the data likely hold outliers"

#: The mistakes in a measurement file that :func:`find_mistake` tries.
MistakeCode = Literal["sign", "swapped", "radial"]


@dataclass(frozen=True, kw_only=True)
class Mistake:
    """A change of a window's data, as a common mistake in writing a measurement file makes, under which it fits.

    Parameters
    ----------
    code
        ``"sign"`` (Doppler negated), ``"swapped"`` (two pairs' labels exchanged) or ``"radial"`` (radars'
        Doppler doubled, or doubled and negated: a radial velocity given for twice it).
    which
        What was changed: ``"every pair"``, ``"pair 1"``, ``"pairs 0 and 1"``.
    cost
        The changed window's cost (it passes the χ² test at the settings' confidence).
    factor
        What the named pairs' Doppler was multiplied by: −1 (``sign``), 1 (``swapped``), 2 or −2
        (``radial``).
    others
        The other changes under which the window passes the same test, by increasing cost.
    pairs
        The pairs changed (``swapped``: the two exchanged), as :meth:`applied` changes them.
    """

    code: MistakeCode
    which: str
    cost: float
    factor: float
    others: tuple[Mistake, ...] = ()
    pairs: tuple[int, ...] = ()

    def applied(self, measurements: Measurements) -> Measurements:
        """``measurements`` changed as this mistake undone: the Doppler of :attr:`pairs` times :attr:`factor`,
        or (``swapped``) the labels of the two :attr:`pairs` exchanged."""
        if self.code == "swapped":
            a, b = self.pairs
            p = measurements.pair
            label = np.where(p == a, b, np.where(p == b, a, p))
            return Measurements.from_arrays(measurements.time, label, measurements.doppler, measurements.sigma,
                                            sort=True)
        gain = np.where(np.isin(measurements.pair, self.pairs), self.factor, 1.0)
        return replace(measurements, doppler=gain * measurements.doppler)

    def same_change(self, other: Mistake) -> bool:
        """Whether ``other`` changes the data as this does (whatever the costs)."""
        return (self.code, self.pairs, self.factor) == (other.code, other.pairs, other.factor)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form (:attr:`others` each without their own ``others``)."""
        return {"code": self.code, "which": self.which, "change": self.change(), "cost": self.cost,
                "factor": self.factor, "pairs": list(self.pairs),
                "others": [{k: v for k, v in m.to_dict().items() if k != "others"} for m in self.others]}

    def change(self) -> str:
        """The change in words: ``"the Doppler of pair 1 negated"``."""
        if self.code == "swapped":
            return f"the labels of {self.which} exchanged"
        verb = {"sign": "negated", "radial": "doubled" if self.factor > 0 else "doubled and negated"}[self.code]
        return f"the Doppler of {self.which} {verb}"


def with_mistake(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                 result: Initiation) -> Initiation:
    r"""``result`` with a ``sign``, ``swapped`` or ``radial`` finding and its
    :attr:`~fgdoppler.estimators.initiation.Initiation.mistake` where the window fits only with its data
    changed as a common mistake in writing a measurement file would have changed them (else ``result``).
    No change is looked for where a pair repeats its values (:func:`~fgdoppler.repeats.find_repeats`): a held
    or dead receiver misfits every track, and the track's ``data`` finding names it.

    * **Sign.**  Negating a pair's Doppler is not a change of the target's
      state: the bistatic range rate :math:`\dot r = \mathbf v \cdot
      (\mathbf u_T + \mathbf u_R)` changes sign with :math:`\mathbf v`,
      but a track flown backwards visits its positions in the reverse
      order, so a window with the opposite sign convention fits no
      constant-velocity track (on the paper's six scenarios, 20 windows
      each, the negated windows cost 48–442 at the median against the
      99.9 % level 39.3, and a single pair negated 81–3,120).  Tried: every
      pair's Doppler negated and, with more than one pair, each pair's
      alone.
    * **Swapped.**  Two pairs' labels exchanged (a geometry file listing the
      receivers in another order than the recording).  Tried: each pair of
      pairs.  Where the exchanged data fit another track, no window can
      tell (the paper's closely spaced pairs: ``studies/data_mistakes.py``);
      pair names in the geometry and the file rule that mistake out.
    * **Radial.**  A radar's (a pair whose Tx and Rx are at one place or
      nearly so, :attr:`~fgdoppler.geometry.Geometry.radars`) radial
      velocity :math:`\dot r` given where fgdoppler reads its bistatic
      range rate :math:`2\dot r` — or the radial velocity positive for an
      approaching target, :math:`\lambda f_D / 2`, the radar formula
      without the minus sign.  Tried: the Doppler of every radar, and with
      more than one radar each radar's alone, multiplied by 2 and by −2.
      Halved data are not those of a slower target (the positions would
      follow the halved velocity, and the directions to the sensors would
      change otherwise), yet a short window often fits them with another
      track.

    Only where ``result`` fails the verdict's χ² test
    (:data:`~fgdoppler.estimators.initiation.VERDICT_LEVEL`); the change whose window passes the χ² test at
    ``settings.confidence`` with the least cost is reported as a
    ``doubtful`` finding, which also names the other changes that pass
    (on radar layouts a short window often fits two of them:
    ``studies/data_mistakes.py``).  A window that fails for another reason
    (outliers, a manoeuvre, a wrong sigma) is mended by none of these and
    gets none of these findings; where it fits without a few measurements
    that the Huber loss picks out, an ``outliers`` finding names them
    instead (:func:`outliers_reason`, two initiations more).  With
    :math:`P \ge 2` pairs that is :math:`1 + P + P(P-1)/2`
    more initiations of the window (two pairs: 4; four: 11; one pair: 1),
    and :math:`2(1 + R)` more with :math:`R \ge 2` radars among them (one
    radar: 2), made only for a window that fails.  Before them, on a
    layout at most :data:`KILOMETRE_EXTENT` across, a geometry in
    kilometres is tried (:func:`units_reason`: a ``units`` finding instead,
    one initiation more), then times in milliseconds or microseconds
    (:func:`time_units_reason`, likewise).  Where the window's start is held
    at the zone's boundary and the window also passes the test as given with
    the bound lifted (:func:`fits_beyond_the_zone`), the finding says so
    (:data:`OR_OUTSIDE_THE_ZONE`): a target outside the zone explains the
    misfit as well as the change does (a target 10 km off a radar's
    baseline, outside a zone 2 km across, fits with the two pairs' labels
    exchanged; a paper recording with pair 0's Doppler negated fits as
    given with a start outside the zone in 6 of 60 windows).
    """
    units = units_reason(measurements, model, settings, result) \
        or time_units_reason(measurements, model, settings, result)
    if units is not None:
        return replace(result, reasons=(*result.reasons, units))
    # a pair repeating its values (a held or dead receiver) misfits any track: that, which the track's data finding
    # names, comes before any change of the data (a dead pair's window fitted with two other pairs exchanged)
    found = None if find_repeats(measurements, level=VERDICT_LEVEL) else \
        find_mistake(measurements, model, settings, result)
    named = outliers_reason(measurements, model, settings, result) if found is None \
        else mistake_reason(found, result.cost, settings.confidence)
    if named is None:
        return result
    if fits_beyond_the_zone(measurements, model, settings, result):
        named = replace(named, message=f"{named.message}; {OR_OUTSIDE_THE_ZONE}")
    return replace(result, reasons=(*result.reasons, named), mistake=found)


def fits_beyond_the_zone(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                         result: Initiation) -> bool:
    """Whether ``result`` — ``measurements``' fit, failing its χ² test with a ``doubtful`` ``boundary`` finding
    (the data prefer a start outside the zone) — passes the test at ``settings.confidence`` when initiated again
    without the zone's bound (``region_bound=False``): one initiation more, only for such a window."""
    held = any(r.code == "boundary" and r.status == "doubtful" for r in result.reasons)
    if not held or not settings.region_bound or result.passes_chi2:
        return False
    try:
        free = initiate(measurements, model, replace(settings, mistake_check=False, region_bound=False))
    except ValueError:
        return False
    return fits(free)


def outliers_reason(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                    result: Initiation, *, what: str = "the window", level: float | None = None
                    ) -> Reason | None:
    r"""An ``outliers`` finding where ``measurements`` (``result`` their fit, with the Gaussian loss) fail the
    verdict's χ² test and fit without a few of them, which the Huber loss picks out, else ``None``.

    A gross error in one measurement of the window drags a least-squares
    start far from the rest: its whitened residual :math:`r_i` enters the
    cost as :math:`r_i^2`, and a 40σ outlier outweighs the other nineteen
    measurements' χ² a hundredfold, so the start moves (even to the zone's
    edge, with advice to widen it) to shrink that one residual.  The window
    is initiated again with the Huber loss (:data:`HUBER_TRIED`,
    ``--huber``'s default), whose bounded pull leaves the outliers beyond
    :data:`~fgdoppler.estimators.initiation.OUTLIER_CUT`; then without them,
    with the Gaussian loss, and the finding is made where that fit passes
    the χ² test at ``settings.confidence``.  The Huber fit's own test (of
    its inliers' χ²) would be biased: each outlier still pulls with the
    force :math:`K`, and two of 20–50σ in the paper's windows left the
    inliers' χ² at 25.7–29.5 against the 95 % level of 23.7, where the
    window without them passes.  The finding names each outlier (pair,
    time, :math:`r_i` at that fit's start carried by the constant-velocity
    model) and is made only where they are at most
    :data:`~fgdoppler.estimators.judge.REJECT_ROBUST` of the window (at
    least one): more than a robust track's verdict allows are a misfit of
    the model (a manoeuvre, a wrong sigma), not outliers.  Not tried where
    ``settings`` already use the Huber loss.  Two initiations more, only for
    a window that fails and that no change of :func:`find_mistake` mends.
    ``what`` names ``measurements`` in the message and ``level`` is the χ²
    test's level for the fit without the outliers (``None``: the settings'
    confidence); the track's check of the whole recording
    (:func:`~fgdoppler.estimators.later_mistakes.later_mistakes`) passes
    ``"the recording"`` and the verdict's 99.9 %, as its other checks of the
    whole recording do: a recording's one constant-velocity fit fails the
    95 % test on one recording in twenty as simulated.
    """
    if settings.huber_k is not None or fits(result, VERDICT_LEVEL):
        return None
    quiet = replace(settings, mistake_check=False)
    n = len(measurements)
    try:
        robust = initiate(measurements, model, replace(quiet, huber_k=HUBER_TRIED))
        out = few_outliers(_residuals(measurements, model, robust))
        if out is None:
            return None
        kept = initiate(measurements.subset(~out), model, quiet)
    except ValueError:
        return None
    if not fits(kept, level):
        return None
    r = _residuals(measurements, model, kept)
    label = pair_labels(model.observation)
    named = np.flatnonzero(out)
    which = "; ".join(f"pair {label(int(measurements.pair[i]))} at t = {time_text(float(measurements.time[i]))} s: "
                      f"{r[i]:+.1f} sigma" for i in named[np.argsort(-np.abs(r[named]))])
    return Reason(code="outliers", status="doubtful", message=(
        f"without {named.size} of its {n} measurements {what} fits (cost {kept.cost:.2f}, passing the "
        f"{100 * (settings.confidence if level is None else level):g}% chi-square test, against {result.cost:.2f} "
        "as given), and "
        f"{'it lies' if named.size == 1 else 'they lie'} beyond "
        f"{OUTLIER_CUT:.2f} sigma of that fit ({which}): {WITH_OUTLIERS}; if so, track with the Huber loss "
        "(--huber), which down-weights them"))


def _residuals(measurements: Measurements, model: TrackingModel, fit: Initiation) -> FloatArray:
    """Whitened residuals of ``measurements`` at ``fit``'s start carried by the constant-velocity model."""
    return whitened_residuals(model, measurements, model.motion.propagate(fit.x_start, measurements.time - fit.t_start))


def fits(fit: Initiation, level: float | None = None) -> bool:
    """Whether ``fit`` passes its χ² test — at ``level`` (the verdict's 99.9 % where asked) or else its own
    settings' (:attr:`~fgdoppler.estimators.initiation.Initiation.passes_chi2`) — leaving out at most a few of
    its measurements as outliers (at most :data:`~fgdoppler.estimators.judge.REJECT_ROBUST` of them, at least
    one), as :func:`few_outliers` counts a few.  A robust fit that leaves out more passes on what is left: with
    the Huber loss and every sigma a fifth of the truth's, the spread measurements of a case-a recording passed
    with pair 0's Doppler negated (cost 8.79 against 119.25 as given), most of that pair left out, and the track
    was told to negate correct data."""
    passes = fit.passes_chi2 if level is None else fit.cost <= float(chi2.ppf(level, max(fit.dof, 1)))
    return passes and _a_few(fit.n_outliers, fit.n_measurements)


def few_outliers(r: FloatArray) -> NDArray[np.bool_] | None:
    """Which whitened residuals ``r`` lie beyond :data:`~fgdoppler.estimators.initiation.OUTLIER_CUT`, where
    some do and they are at most :data:`~fgdoppler.estimators.judge.REJECT_ROBUST` of them (at least one): a few
    outliers, not a misfit of the model; ``None`` otherwise."""
    out = np.abs(r) > OUTLIER_CUT
    return out if out.any() and _a_few(int(out.sum()), r.size) else None


def _a_few(count: int, n: int) -> bool:
    """Whether ``count`` of ``n`` measurements are a few: at most :data:`~fgdoppler.estimators.judge.REJECT_ROBUST`
    of them, and one always is."""
    return count <= max(1, int(REJECT_ROBUST * n))


def find_mistake(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                 result: Initiation, *, codes: tuple[MistakeCode, ...] = ("sign", "radial", "swapped"),
                 changes: tuple[Mistake, ...] | None = None) -> Mistake | None:
    """The change of :func:`with_mistake` whose window passes with the least cost (``None``: none, or
    ``result`` passes the verdict's χ² test), with the others that pass in its ``others``; only the changes
    of ``codes`` are tried, or only ``changes`` (their costs and ``others`` are ignored) where given."""
    if fits(result, VERDICT_LEVEL):
        return None
    if changes is not None:
        return _least_cost(measurements, model, settings,
                           [replace(c, cost=np.nan, others=()) for c in changes])
    pairs = [int(k) for k in np.unique(measurements.pair)]
    tried: list[Mistake] = []  # cost filled in by the fit
    label = pair_labels(model.observation)

    def scaled(code: MistakeCode, which: list[int], factor: float) -> None:
        tried.append(Mistake(code=code, which=pairs_text(which, label, every=which == pairs), cost=np.nan,
                             factor=factor, pairs=tuple(which)))

    for flipped in [pairs] + ([[k] for k in pairs] if len(pairs) > 1 else []) if "sign" in codes else []:
        scaled("sign", flipped, -1.0)
    radars = [k for k in radar_pairs(model) if k in pairs] if "radial" in codes else []
    for group in [radars] + ([[k] for k in radars] if len(radars) > 1 else []) if radars else []:
        for factor in (2.0, -2.0):
            scaled("radial", group, factor)
    for i, a in enumerate(pairs if "swapped" in codes else []):
        for b in pairs[i + 1:]:
            tried.append(Mistake(code="swapped", which=pairs_text([a, b], label), cost=np.nan, factor=1.0,
                                 pairs=(a, b)))
    return _least_cost(measurements, model, settings, tried)


def _least_cost(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                changes: list[Mistake]) -> Mistake | None:
    """Of ``changes``, the one under which ``measurements`` pass the χ² test at ``settings.confidence`` with
    the least cost (among equals the first), the others that pass in its ``others``; ``None``: none passes."""
    quiet = replace(settings, mistake_check=False)
    passing = []
    for k, change in enumerate(changes):
        try:
            again = initiate(change.applied(measurements), model, quiet)
        except ValueError:  # doubled data may need a speed the zone does not allow: no fit in it
            continue
        if fits(again):
            passing.append((again.cost, k, replace(change, cost=float(again.cost))))
    if not passing:
        return None
    ranked = [m for *_, m in sorted(passing, key=lambda p: (p[0], p[1]))]
    return replace(ranked[0], others=tuple(ranked[1:]))


def kilometre_extent(model: TrackingModel) -> float | None:
    """The largest distance (m) between two sensors of ``model``'s geometry where it is at most
    :data:`KILOMETRE_EXTENT` — a layout :func:`units_reason` tries in kilometres — else ``None``."""
    geometry = getattr(model.observation, "geometry", None)
    if not isinstance(geometry, Geometry):
        return None
    return geometry.extent if geometry.extent <= KILOMETRE_EXTENT else None


def units_reason(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                 result: Initiation, *, what: str = "the window") -> Reason | None:
    r"""A ``units`` finding where ``measurements`` (``result`` their fit) fail the verdict's χ² test and fit
    with every length of the geometry multiplied by 1000 — sensor positions given in kilometres where
    fgdoppler reads metres — else ``None``; ``what`` says what was fitted (:func:`mistake_reason`).

    Read as metres, a layout given in kilometres puts the sensors a thousand
    times too close together: the bistatic Doppler
    :math:`\dot r = \mathbf v\cdot(\mathbf u_T + \mathbf u_R)` depends on
    the directions :math:`\mathbf u` from the target to the sensors, which
    then barely differ between pairs nor change while the target moves
    (its metres per second against sensors metres apart), so no track fits
    pairs whose Doppler differ.  Tried only where the sensors lie at most
    :data:`KILOMETRE_EXTENT` apart (:func:`kilometre_extent`: a layout up to
    1,000 km across read as metres), in the scaled geometry's own zone
    (:meth:`~fgdoppler.geometry.Geometry.scaled`: the zone's limits scaled
    too, its speed bound kept) with ``settings``' half plane scaled: one
    initiation more, only where they fail.  The scaled fit must pass the χ²
    test at ``settings.confidence``, as a change of the data must: a short
    window of a slow target on a small layout often fits about as well
    with the sensors a thousand times farther apart, and at the verdict's
    99.9 % that named kilometres for one of 180 manoeuvring windows on
    layouts 440 m-1 km across (``studies/data_mistakes.py``).
    """
    extent = kilometre_extent(model)
    if extent is None or fits(result, VERDICT_LEVEL):
        return None
    geometry = model.geometry
    factor = 1000.0
    plane = settings.half_plane
    quiet = replace(settings, mistake_check=False, half_plane=None if plane is None else replace(
        plane, point=(plane.point[0] * factor, plane.point[1] * factor)))
    scaled = TrackingModel.of(geometry.scaled(factor), motion=model.motion, weak_prior=model.weak_prior)
    try:
        again = initiate(measurements, scaled, quiet)
    except ValueError:  # the data need a speed the scaled zone does not allow: no fit in it
        return None
    if not fits(again):
        return None
    zone = "" if geometry.zone_limits.along is None and geometry.zone_limits.across is None \
        and geometry.zone_limits.altitude is None else " and the zone's limits"
    return Reason(code="units", status="doubtful", message=(
        f"with every sensor position{zone} multiplied by 1000 {what} fit{'s' if what == 'the window' else ''} "
        f"(cost {again.cost:.2f}, passing the {settings.confidence:.0%} chi-square test, against {result.cost:.2f} "
        f"as given): {IN_KILOMETRES} (its sensors lie within "
        f"{distance_text(extent)} of each other); if so, multiply every sensor coordinate{zone} by 1000"))


def median_interval(measurements: Measurements) -> float | None:
    """The median of the positive intervals between consecutive measurements of one pair (``None``: none)."""
    order = np.lexsort((measurements.time, measurements.pair))
    t, p = measurements.time[order], measurements.pair[order]
    step = np.diff(t)[np.diff(p) == 0]
    step = step[step > 0]
    return float(np.median(step)) if step.size else None


def tries_time_units(interval: float | None) -> bool:
    """Whether :func:`time_units_reason` tries any unit for a recording whose median interval between a pair's
    measurements is ``interval`` (``None``: none): where it divided by 1000 is at least :data:`SHORTEST_INTERVAL`."""
    return interval is not None and interval / TIME_UNITS[0][1] >= SHORTEST_INTERVAL


def time_units_reason(measurements: Measurements, model: TrackingModel, settings: InitiationSettings,
                      result: Initiation, *, what: str = "the window", interval: float | None = None
                      ) -> Reason | None:
    r"""A ``units`` finding where ``measurements`` (``result`` their fit) fail the verdict's χ² test and fit
    with every time divided by 1000 or by a million — times in milliseconds or microseconds where fgdoppler
    reads seconds, as many loggers write them — else ``None``; ``what`` says what was fitted.

    Read as seconds, times in milliseconds slow the target's clock a
    thousandfold: the Doppler :math:`\dot r = \mathbf v\cdot(\mathbf u_T +
    \mathbf u_R)` still gives its speed in metres per *second*, so between
    two measurements half a "second" apart (500 s) it would move 50 km at
    100 m/s, and no constant-velocity track fits Doppler that barely change
    over such distances.  A unit of :data:`TIME_UNITS` is tried only where
    the median interval between a pair's consecutive measurements, divided
    as the unit says, is at least :data:`SHORTEST_INTERVAL` (a 0.5 s
    sampling written in milliseconds, 500, tries milliseconds alone; data
    sampled every 0.5 s as given try nothing), in the model's own zone and
    with ``settings``' half plane; the divided fit must pass the χ² test at
    ``settings.confidence``, as a change of the data must.  One initiation
    more per unit tried, only where they fail; the first unit that passes
    is named.  ``interval``: the median interval to judge by where ``measurements`` are a selection of a
    recording (measurements spread over it lie farther apart than its sampling), else theirs.
    """
    interval = median_interval(measurements) if interval is None else interval
    if not tries_time_units(interval) or fits(result, VERDICT_LEVEL):
        return None
    assert interval is not None
    quiet = replace(settings, mistake_check=False)
    for unit, divisor in TIME_UNITS:
        if interval / divisor < SHORTEST_INTERVAL:
            break  # the units are tried from the smaller divisor up
        try:
            again = initiate(replace(measurements, time=measurements.time / divisor), model, quiet)
        except ValueError:  # the data need a speed the zone does not allow: no fit in it
            continue
        if fits(again):
            return Reason(code="units", status="doubtful", message=(
                f"with every time divided by {divisor:,.0f} {what} fit{'s' if what == 'the window' else ''} "
                f"(cost {again.cost:.2f}, passing the {settings.confidence:.0%} chi-square test, against "
                f"{result.cost:.2f} as given): the times are likely in {unit} {IN_SECONDS} (the median interval "
                f"between a pair's measurements is {interval:g} in the file); if so, divide the time column, and a truth "
                f"file's, by {divisor:,.0f}"))
    return None


def radar_pairs(model: TrackingModel) -> tuple[int, ...]:
    """The pairs of ``model``'s geometry that are radars (:attr:`~fgdoppler.geometry.Geometry.radars`; none
    for a model without a geometry)."""
    geometry = getattr(model.observation, "geometry", None)
    return tuple(int(k) for k in geometry.radars) if isinstance(geometry, Geometry) else ()


def mistake_reason(found: Mistake, cost: float, confidence: float, *, what: str = "the window") -> Reason:
    """The ``doubtful`` finding that names ``found``, against the window's ``cost`` as given, and the other
    changes under which the window passes the same test (at most :data:`OTHERS_NAMED` of them by name, with
    their costs: the least cost is the likeliest change, not the only one the data allow); ``what`` says
    what was fitted ("the window", "they")."""
    fits = (f"with {found.change()} {what} fit{'s' if what == 'the window' else ''} (cost {found.cost:.2f}, "
            f"passing the {confidence:.0%} chi-square test, against {cost:.2f} as given)")
    column = "" if found.which == "every pair" else f" of {found.which}"
    if found.code == "swapped":
        advice = ("the measurement file and the geometry may list those pairs in different orders; if so, exchange "
                  "them in one of the two, or name the pairs in the geometry (name = ...) and give the names in the "
                  "file's pair column")
    elif found.code == "radial" and found.factor > 0:
        advice = ("the file likely gives the radar's radial velocity (the rate of change of its range) where "
                  "fgdoppler reads the bistatic range rate, for a radar the rate of change of twice its range; if "
                  f"so, double the doppler column{column}")
    elif found.code == "radial":
        advice = ("the file likely gives the radar's radial velocity positive for an approaching target (from a "
                  "Doppler shift f_D in Hz, wavelength * f_D / 2) where fgdoppler reads the bistatic range rate, for "
                  "a radar the rate of change of twice its range, negative for a closing target (doppler = "
                  f"-wavelength * f_D); if so, multiply the doppler column{column} by -2")
    else:
        advice = (f"the data likely follow the opposite sign convention ({SIGN_CONVENTION}); if so, negate the "
                  f"doppler column{column}")
    named = [f"{m.change()} (cost {m.cost:.2f})" for m in found.others[:OTHERS_NAMED]]
    more = len(found.others) - len(named)
    also = "" if not named else (
        f"; {what} pass{'es' if what == 'the window' else ''} the same test with "
        f"{', '.join(named[:-1]) + ' or ' if len(named) > 1 else ''}"
        f"{named[-1]}" + (f" and {more} more such change{'s' if more > 1 else ''}" if more else "")
        + " too: check " + ("that change" if len(found.others) == 1 else "those changes") + " as well")
    return Reason(code=found.code, status="doubtful", message=f"{fits}: {advice}{also}")
