r"""Mistakes in a measurement file that the initiation window did not show, looked for later in the recording.

The initiation names common mistakes where its window fails the χ²
test and fits with the data changed (:func:`~fgdoppler.estimators.window_mistakes.with_mistake`):
the opposite sign convention (the Doppler of every pair, or of one pair,
negated: a ``sign`` finding), two pairs' labels exchanged (``swapped``)
and a radar's radial velocity given for its bistatic range rate
(``radial``).
A short window can fit a wrong track with the wrong data as well — near
the paper's baseline the likelihood has long valleys — and then the
initiation says nothing; the whole track fails its residual test later
(the verdict's ``fit`` finding), which says that the data and the model
disagree but not why, and a mistaken sign can read as a manoeuvre.

So where a track's ``fit`` finding is not ``ok`` and the initiation named
no mistake, :func:`later_mistakes` initiates :data:`LATER_WINDOWS` windows
of the initiation window's span spread over the rest of the recording
(:func:`~fgdoppler.estimators.initiation.initiate`, which tries the
changes itself where a window fails), and turns the change that makes the
most of them pass into a ``doubtful`` finding of the track — if
:data:`WHOLE_PER_PAIR` measurements of every pair spread evenly over the
whole recording, which fail the verdict's χ² test as given, pass it with
that change too (a window holding a manoeuvre fits no constant-velocity
track, and one of the changes sometimes makes it fit; over the whole
recording it does not).  Not the change
each window finds likeliest: a short window often passes under two changes
(on radar layouts, a radar's Doppler negated as well as halved back), while
the right change passes in every window that needs one.  A window that fits
as given, or fails for another reason (an outlier, a manoeuvre inside it,
a target that has left the zone, which bounds each window's start), names
nothing.  The track's status does not change (the ``fit`` finding is
already ``doubtful``); the finding says what to check.

Where no window names a change and the geometry has radars, the last check
takes :data:`WHOLE_PER_PAIR` measurements of every pair spread evenly over
the whole recording: a radar's halved Doppler fits another track in a
short window (its direction to the target barely turns in 4.5 s), but not
over the whole recording, where the positions that a track's velocity
carries it through no longer match.  If they fail the χ² test as given and
pass with a radar's Doppler doubled, or doubled and negated, that change is
named.  (The sign and swapped labels, which windows mostly name, are not
tried there: that would cost :math:`1 + P + P(P-1)/2` more initiations on
every track that misfits, a manoeuvring one included.)

Where no change is named, a few gross errors may explain the misfit: the
initiation window names them only where they are a few of *its*
measurements, and several in one window drag a least-squares track off the
rest of the recording.  The whole recording (:data:`OUTLIERS_PER_PAIR`
measurements a pair spread over it) is then fitted with one
constant-velocity track as given, with the Huber loss and without the
measurements that fit leaves far off; where the last passes the χ² test and
those left out are at most a tenth, an ``outliers`` finding names them and
advises the Huber loss.

The geometry in kilometres
(:func:`~fgdoppler.estimators.window_mistakes.units_reason`) and times in
milliseconds or microseconds
(:func:`~fgdoppler.estimators.window_mistakes.time_units_reason`): where the
initiation named either, nothing more is searched (every window would fail
with the units mistaken); where the initiation named nothing, the
:data:`WHOLE_PER_PAIR` measurements a pair spread over the whole recording
are first tried in kilometres (on a layout at most
:data:`~fgdoppler.estimators.window_mistakes.KILOMETRE_EXTENT` across) and
then with their times divided (where the recording's own sampling
interval allows it), one initiation each and one more for the spread
measurements as given, and a ``units`` finding then replaces the windows'
search.

Where the initiation window did name a change, a short window often fits
under several (on radar layouts with a radar's radial velocity positive
for an approaching target, the right change came first in 12 of 36 such
windows and among the others in 20: a negation or a swap fits as well
there).  The same spread measurements then rank the window's changes: the
one under which they pass with the least cost, where as given they fail,
is named as the track's finding, which says whether the window's likeliest
change is that one.

Where the window named a change and the track nevertheless fits its data
as given, the same spread measurements are initiated as given; where they
pass the verdict's χ² test, an ``unconfirmed`` finding says so: the data
do not need the change, and the window's misfit may have another cause.  A
receiver 5 km from where a three-pair layout's geometry puts it made the
window fit only with that pair's Doppler negated (a ``sign`` finding), while
the smoother's track fitted the whole recording as given, 94–117 m from the
truth.

Cost, on a track that misfits only: with a change the window named, one
initiation of the spread measurements and one per change the window
passes with; else :math:`n` initiations of later windows and, for each
window that fails, :math:`1 + P + P(P-1)/2` more with :math:`P` pairs (and
more with radars, :func:`~fgdoppler.estimators.window_mistakes.with_mistake`),
then one initiation of the spread measurements and one more per change
asked to confirm, or with radars where the windows name nothing, if they
fail, :math:`2(1 + R)` more with :math:`R \ge 2` radars (one radar: 2).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from fgdoppler._text import time_text
from fgdoppler.estimators.initiation import VERDICT_LEVEL, Initiation, InitiationSettings, initiate
from fgdoppler.estimators.results import TrackResult
from fgdoppler.estimators.verdict import Reason
from fgdoppler.estimators.window_mistakes import (
    IN_KILOMETRES,
    IN_SECONDS,
    Mistake,
    MistakeCode,
    find_mistake,
    fits,
    kilometre_extent,
    median_interval,
    mistake_reason,
    outliers_reason,
    radar_pairs,
    time_units_reason,
    tries_time_units,
    units_reason,
)
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.repeats import find_repeats

__all__ = ["CONFIRMED_AT_MOST", "LATER_WINDOWS", "MISTAKE_CODES", "OUTLIERS_PER_PAIR", "UNCONFIRMED", "WHOLE_CODES",
           "WHOLE_PER_PAIR", "is_later_finding", "is_mistake_finding", "later_mistakes"]

#: Windows initiated after the initiation window where a track fails its residual test.
LATER_WINDOWS = 3
#: The code of the finding that the whole recording fits as given where the initiation window named a change.
UNCONFIRMED = "unconfirmed"

#: Measurements per pair, spread evenly over the whole recording, of the last check (:func:`later_mistakes`).
WHOLE_PER_PAIR = 20

#: The changes the later windows name that the whole recording is asked to confirm, at most.
CONFIRMED_AT_MOST = 3

#: The changes the last check tries: a radar's Doppler, which a short window rarely tells (its halved data fit
#: another track there); the sign and swapped pairs, which windows mostly name, would cost 1 + P + P(P-1)/2
#: initiations more on every track that misfits.
WHOLE_CODES: tuple[MistakeCode, ...] = ("radial",)

#: The findings of a mistake in the measurement file (:func:`~fgdoppler.estimators.window_mistakes.with_mistake`).
MISTAKE_CODES = ("sign", "swapped", "radial")

#: Measurements per pair, spread evenly over the recording, that the outliers check fits in one constant-velocity
#: track (every measurement of a recording of up to that many a pair: the paper's 30 s hold 61).
OUTLIERS_PER_PAIR = 100


def later_mistakes(measurements: Measurements, model: TrackingModel, init: Initiation, reasons: tuple[Reason, ...],
                   *, huber_k: float | None = None, windows: int = LATER_WINDOWS,
                   reference: TrackResult | None = None) -> list[Reason]:
    r"""A ``sign``, ``swapped``, ``radial``, ``units`` or ``outliers`` finding from later in the recording, where
    the track does not fit (``reasons``, the track's, hold a ``fit`` finding that is not ``ok``) and ``init`` did
    not find the geometry in kilometres or the times in other units (the module docstring: those are tried first);
    no change of the data where a pair repeats its values (:func:`_changes`).

    Where the track fits but ``init`` named a change, an ``unconfirmed`` finding where the data do not need it
    (:func:`_unconfirmed`).  Where ``init`` names a change (:attr:`~.initiation.Initiation.mistake`), the
    :data:`WHOLE_PER_PAIR` measurements a pair spread over the whole
    recording are initiated as given and, where they fail the verdict's χ²
    test, with each of the window's changes; the one under which they pass
    the χ² test at 95 % with the least cost is named (one initiation and one
    per change the window passes with); none passing, nothing is.  Where
    ``init`` names none, :math:`n` = ``windows`` later windows are
    initiated: window :math:`i` of :math:`n` holds every measurement in
    :math:`[s_i, s_i + \Delta]`, :math:`\Delta` the initiation window's span
    and :math:`s_i` evenly spaced from the initiation window's end to
    :math:`t_\mathrm{last} - \Delta`; each is initiated with the model's zone
    and ``init``'s half plane, and every change under which a window that
    fails passes the χ² test at 95 % counts as its vote.  The change with
    the most votes (among equals, the least total cost in the windows that
    pass with it) is reported, with the first window it makes pass, the
    count and the other changes under which that window passes — where the
    :data:`WHOLE_PER_PAIR` measurements a pair spread over the whole
    recording fail the verdict's χ² test as given and pass it with that
    change (else the next, up to :data:`CONFIRMED_AT_MOST` changes).  Where no
    window names one and the geometry has radars, those spread measurements
    are tried with the changes of :data:`WHOLE_CODES` (a radar's Doppler
    doubled, or doubled and negated); then a few outliers
    (:func:`_outliers_on_whole`).  Nothing more where ``reference``, a
    track on the same data and initiation with the same ``huber_k`` that
    misfits too, made the same check: its finding (or none) is the answer.

    Parameters
    ----------
    measurements, model
        The recording and model the track was estimated with.
    init
        The initiation the track started from: its window's span, findings and
        ``mistake`` (a mistake finding without it, as made elsewhere than by
        :func:`~fgdoppler.estimators.initiation.initiate`: nothing more).
    reasons
        The track's findings so far.
    huber_k
        Huber threshold of the windows' fits (``None``: Gaussian), as the track's.
    windows
        Windows to initiate (>= 1).
    reference
        A track on the same ``measurements``, ``model`` and ``init`` that has
        been through this check with :data:`LATER_WINDOWS` windows (the
        registry's result for the offline smoother a filter is held
        against), or ``None``.

    Returns
    -------
    list of Reason
        At most one ``doubtful`` finding.

    Raises
    ------
    ValueError
        If ``windows`` < 1.
    """
    if windows < 1:
        raise ValueError(f"windows must be >= 1, got {windows}")
    if len(measurements) == 0 or not _misfits(reasons):
        return [] if len(measurements) == 0 or init.mistake is None \
            else _unconfirmed(measurements, model, init, huber_k, reference)
    if init.mistake is None and any(is_mistake_finding(r) for r in init.reasons):
        return []  # a units finding explains the misfit
    if reference is not None and windows == LATER_WINDOWS and _misfits(reference.reasons) \
            and reference.settings.huber_k == huber_k:
        # the same windows, fits and votes: the answer depends on nothing else
        return [r for r in reference.reasons if is_later_finding(r)]
    whole = _Whole(measurements, model, init, huber_k)
    if init.mistake is not None:
        return _ranked_on_whole(model, whole, init.mistake)
    return _units_on_whole(model, whole) or _changes(measurements, model, init, windows, whole)


def _changes(measurements: Measurements, model: TrackingModel, init: Initiation, windows: int, whole: _Whole
             ) -> list[Reason]:
    """The change of the data from later windows, or else from the whole recording's spread measurements
    (:func:`later_mistakes`); none where a pair repeats its values (:func:`~fgdoppler.repeats.find_repeats`): a
    held or dead receiver misfits every track, which the track's ``data`` finding names."""
    if find_repeats(measurements, level=VERDICT_LEVEL):
        return []
    return (_from_windows(measurements, model, init, windows, whole) or _from_whole(model, whole, WHOLE_CODES)
            or _outliers_on_whole(measurements, model, init, whole))


def _outliers_on_whole(measurements: Measurements, model: TrackingModel, init: Initiation, whole: _Whole
                       ) -> list[Reason]:
    r"""An ``outliers`` finding of the track where the recording fits one constant-velocity track without a few
    of its measurements, which lie far from it
    (:func:`~fgdoppler.estimators.window_mistakes.outliers_reason` on the whole recording), else none.

    The initiation window names a few outliers only where they are at most a
    tenth of *its* measurements; several in one window (four of its twenty)
    are not, and a least-squares track dragged by them misfits the rest of
    the recording too, so that its rejections and its halves' misfit read as
    sigma too small or a manoeuvre.  Fitted over the whole recording, the
    same outliers are a few again.  :data:`OUTLIERS_PER_PAIR` measurements a
    pair spread over the recording are fitted (all of a short one): as
    given, with the Huber loss, and without the measurements that fit leaves
    beyond the cut; the finding is made where the last passes the verdict's
    χ² test (99.9 %) and those left out are at most a tenth.  A manoeuvre or
    a wrong sigma leaves more than a tenth beyond the cut, and no finding.  Not where the
    track used the Huber loss, nor where the initiation window already named
    its outliers.  Three initiations of the sample, only for a track that
    misfits and that no change of the data explains; where the sample is
    ``whole``'s spread measurements (a recording of at most
    :data:`WHOLE_PER_PAIR` a pair), their fit as given is ``whole``'s.
    """
    settings = whole.settings
    if settings.huber_k is not None or any(r.code == "outliers" and r.status != "ok" for r in init.reasons):
        return []
    sample = measurements.spread(OUTLIERS_PER_PAIR)
    if len(sample) <= init.n_measurements:
        return []  # nothing beyond the window, whose own check has run
    quiet = replace(settings, mistake_check=False)
    if len(sample) == len(whole.spread):
        given = whole.given()
    else:
        try:
            given = initiate(sample, model, quiet)
        except ValueError:  # no start in the zone explains them
            given = None
    if given is None:
        return []
    every = len(sample) == len(measurements)
    found = outliers_reason(sample, model, quiet, given, level=VERDICT_LEVEL,
                            what="the recording" if every else "the sample spread over the recording")
    if found is None:
        return []
    unsampled = "" if every else " (the measurements between the sample's may hold more)"
    return [replace(found, message=(
        "the track fails its residual test and no window named a mistake in the file; fitted with one "
        f"constant-velocity track, {found.message}{unsampled}"))]


def is_mistake_finding(reason: Reason) -> bool:
    """Whether ``reason`` names a mistake in the measurement file or the geometry: a ``sign``, ``swapped`` or
    ``radial`` finding, or a ``units`` finding of the geometry in kilometres or of the times in another unit
    than seconds (not the verdict's own ``units`` findings of speed and distance)."""
    return reason.code in MISTAKE_CODES or (reason.code == "units" and (
        IN_KILOMETRES in reason.message or IN_SECONDS in reason.message))


def is_later_finding(reason: Reason) -> bool:
    """Whether :func:`later_mistakes` may have made ``reason``: a finding of :func:`is_mistake_finding`, or a
    track's ``outliers`` finding (an initiation's carries the ``initiation-`` prefix on a track)."""
    return is_mistake_finding(reason) or reason.code == "outliers"


def _misfits(reasons: tuple[Reason, ...]) -> bool:
    """Whether a track's findings say its residuals fail the whole-track test."""
    return any(r.code == "fit" and r.status != "ok" for r in reasons)


def _from_windows(measurements: Measurements, model: TrackingModel, init: Initiation, windows: int, whole: _Whole
                  ) -> list[Reason]:
    """The change most of ``windows`` later windows need to fit and the whole recording fits with, as a finding
    (:func:`later_mistakes`)."""
    span = init.t_end - init.t_start
    last = float(np.max(measurements.time))
    if not (span > 0 and last - span > init.t_end):
        return []
    settings = whole.settings
    quiet = replace(settings, mistake_check=False)
    # for each change, the windows it makes pass, in order: (the change there, every change that passes there,
    # the window's cost as given, its start)
    passed: dict[tuple[str, str, float], list[tuple[Mistake, tuple[Mistake, ...], float, float]]] = {}
    for start in np.unique(np.linspace(init.t_end, last - span, windows)):
        window = measurements.between(float(start), float(start) + span)
        try:
            given = initiate(window, model, quiet)
        except ValueError:  # too few measurements, or no start in the zone explains them
            continue
        found = find_mistake(window, model, settings, given)
        if found is None:
            continue
        there = (found, *found.others)
        for m in there:
            passed.setdefault((m.code, m.which, m.factor), []).append((m, there, given.cost, float(start)))
    # the most windows first, among equals the least total cost there (then the order first seen); the first
    # that the whole recording's spread measurements confirm is named
    ranked = sorted(passed.values(), key=lambda v: (-len(v), sum(m.cost for m, *_ in v)))
    for votes in ranked[:CONFIRMED_AT_MOST]:
        chosen, there, cost, start = votes[0]
        confirmed = whole.confirms(chosen)
        if confirmed is None:
            continue
        named = mistake_reason(replace(chosen, others=tuple(m for m in there if m is not chosen)), cost,
                               settings.confidence)
        return [replace(named, message=(
            f"the track fails its residual test and the initiation window named no mistake, but later in the "
            f"recording {len(votes)} of {windows} windows of {span:g} s fit with a change of the data (first at "
            f"t = {start:.1f}-{start + span:.1f} s), and so do the {whole.describe()} ({confirmed}): "
            f"{named.message}"))]
    return []


class _Whole:
    """The :data:`WHOLE_PER_PAIR` measurements a pair spread over the whole recording and their fit as given,
    initiated once, where first asked for."""

    def __init__(self, measurements: Measurements, model: TrackingModel, init: Initiation, huber_k: float | None
                 ) -> None:
        self.model = model
        self.settings = InitiationSettings(half_plane=init.half_plane, huber_k=huber_k)
        self.spread = measurements.spread(WHOLE_PER_PAIR)
        self.interval = median_interval(measurements)
        # no more than the initiation window saw: nothing to learn from them
        self._usable = len(self.spread) > init.n_measurements
        self._given: Initiation | None = None
        self._tried = False

    def given(self) -> Initiation | None:
        """Their fit as given (``None``: too few of them, or no start in the zone explains them)."""
        if self._usable and not self._tried:
            self._tried = True
            try:
                self._given = initiate(self.spread, self.model, replace(self.settings, mistake_check=False))
            except ValueError:
                self._given = None
        return self._given

    def confirms(self, change: Mistake) -> str | None:
        """Where they fail the verdict's χ² test (:data:`~fgdoppler.estimators.initiation.VERDICT_LEVEL`) as
        given and pass it with ``change``: the two costs in words (``None``: they do not)."""
        given = self.given()
        if given is None or fits(given, VERDICT_LEVEL):
            return None
        changed = change.applied(self.spread)
        try:
            again = initiate(changed, self.model, replace(self.settings, mistake_check=False))
        except ValueError:  # no start in the zone explains them
            return None
        if not fits(again, VERDICT_LEVEL):
            return None
        return f"cost {again.cost:.2f} with it, {given.cost:.2f} as given, {_level(given.dof):.2f} the 99.9 % level"

    def describe(self) -> str:
        """``"60 measurements spread over the whole recording (t = 0-30 s)"``."""
        t = self.spread.time
        return (f"{len(self.spread)} measurements spread over the whole recording (t = {time_text(float(t.min()))}-"
                f"{time_text(float(t.max()))} s)")


def _level(dof: int) -> float:
    """The verdict's χ² level for ``dof`` degrees of freedom."""
    return float(chi2.ppf(VERDICT_LEVEL, max(dof, 1)))


def _ranked_on_whole(model: TrackingModel, whole: _Whole, found: Mistake) -> list[Reason]:
    """Of the changes under which the initiation window fits (``found`` and its ``others``), the one under
    which the whole recording's spread measurements fit with the least cost where as given they fail, as a
    finding (:func:`later_mistakes`)."""
    given = whole.given()
    if given is None:
        return []
    window = (found, *found.others)
    best = find_mistake(whole.spread, model, whole.settings, given, changes=window)
    if best is None:
        return []
    named = mistake_reason(best, given.cost, whole.settings.confidence, what="they")
    if len(window) == 1:
        head = f"the {whole.describe()} confirm the initiation window's finding"
    else:
        first = "its likeliest too" if best.same_change(found) else f"another than its likeliest ({found.change()})"
        head = (f"of the {len(window)} changes of the data under which the initiation window fits, the "
                f"{whole.describe()} fit best with {first}")
    return [replace(named, message=f"the track fails its residual test; {head}: {named.message}")]


def _unconfirmed(measurements: Measurements, model: TrackingModel, init: Initiation, huber_k: float | None,
                 reference: TrackResult | None) -> list[Reason]:
    """Where the track fits its data as given although ``init`` named a change (its ``mistake``), and the
    :data:`WHOLE_PER_PAIR` measurements a pair spread over the whole recording, initiated as given, pass the
    verdict's χ² test too, an ``unconfirmed`` finding: the data do not need the window's change (one
    initiation; the answer of ``reference`` where it fits too with the same ``huber_k``)."""
    assert init.mistake is not None
    if reference is not None and not _misfits(reference.reasons) and reference.settings.huber_k == huber_k:
        return [r for r in reference.reasons if r.code == UNCONFIRMED]
    whole = _Whole(measurements, model, init, huber_k)
    found = init.mistake
    given = whole.given()
    if given is None or not fits(given, VERDICT_LEVEL):
        return []
    return [Reason(code=UNCONFIRMED, status="doubtful", message=(
        f"the track fits its data as given, and so do the {whole.describe()}, cost {given.cost:.2f} against "
        f"{_level(given.dof):.2f} at the 99.9 % level: they do not confirm the initiation window's {found.code} "
        f"finding ({found.change()}); the window's misfit may have another cause (a sensor's position in the "
        "geometry, outliers, a manoeuvre early in the recording): check those as well as the file before changing "
        "the data"))]


def _units_on_whole(model: TrackingModel, whole: _Whole) -> list[Reason]:
    """Where the whole recording's spread measurements fail the verdict's χ² test as given and fit with every
    length multiplied by 1000 (on a layout small enough to be in kilometres,
    :func:`~fgdoppler.estimators.window_mistakes.kilometre_extent`) or with the times in milliseconds or
    microseconds (:func:`~fgdoppler.estimators.window_mistakes.time_units_reason`, judged by the recording's
    own sampling interval), that as a ``units`` finding (:func:`later_mistakes`)."""
    in_km = kilometre_extent(model) is not None
    in_ms = tries_time_units(whole.interval)
    given = whole.given() if in_km or in_ms else None
    if given is None:
        return []
    found = units_reason(whole.spread, model, whole.settings, given, what="they") if in_km else None
    unit = "in kilometres"
    if found is None:
        found = time_units_reason(whole.spread, model, whole.settings, given, what="they",
                                  interval=whole.interval)
        unit = "with other time units"
    if found is None:
        return []
    return [replace(found, message=(
        f"the track fails its residual test and the initiation window named nothing, but the {whole.describe()} "
        f"fail the chi-square test as given and fit {unit}: {found.message}"))]


def _from_whole(model: TrackingModel, whole: _Whole, codes: tuple[MistakeCode, ...]) -> list[Reason]:
    """The change of ``codes`` under which the whole recording's spread measurements fit where as given they
    do not, as a finding (:func:`later_mistakes`)."""
    if not codes or (set(codes) <= {"radial"} and not radar_pairs(model)):
        return []  # nothing to try
    given = whole.given()
    if given is None:
        return []
    found = find_mistake(whole.spread, model, whole.settings, given, codes=codes)
    if found is None:
        return []
    named = mistake_reason(found, given.cost, whole.settings.confidence, what="they")
    return [replace(named, message=(
        f"the track fails its residual test and no window named a mistake, but the {whole.describe()} fail the "
        f"chi-square test as given and fit with a change of the data: {named.message}"))]
