r"""Mistakes in a measurement file that the initiation window did not show, looked for later in the recording.

The initiation names common mistakes where its window fails the χ²
test and fits with the data changed (:func:`~fgdoppler.estimators.window_mistakes.mistake_reasons`):
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
most of them pass into a ``doubtful`` finding of the track.  Not the change
each window finds likeliest: a short window often passes under two changes
(on radar layouts, a radar's Doppler negated as well as halved back), while
the right change passes in every window that needs one.  A window that fits
as given, or fails for another reason (an outlier, a manoeuvre inside it,
a target that has left the zone, which bounds each window's start), names
nothing.  The track's status does not change (the ``fit`` finding is
already ``doubtful``); the finding says what to check.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fgdoppler.estimators.initiation import Initiation, InitiationSettings, initiate
from fgdoppler.estimators.results import TrackResult
from fgdoppler.estimators.verdict import Reason
from fgdoppler.estimators.window_mistakes import Mistake, find_mistake, mistake_reason
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel

__all__ = ["LATER_WINDOWS", "MISTAKE_CODES", "later_mistakes"]

#: Windows initiated after the initiation window where a track fails its residual test.
LATER_WINDOWS = 3

#: The findings of a mistake in the measurement file (:func:`~fgdoppler.estimators.window_mistakes.mistake_reasons`).
MISTAKE_CODES = ("sign", "swapped", "radial")


def later_mistakes(measurements: Measurements, model: TrackingModel, init: Initiation, reasons: tuple[Reason, ...],
                   *, huber_k: float | None = None, windows: int = LATER_WINDOWS,
                   reference: TrackResult | None = None) -> list[Reason]:
    r"""A ``sign``, ``swapped`` or ``radial`` finding from windows later in the recording, where the track does
    not fit.

    Only where ``reasons`` (the track's) hold a ``fit`` finding that is not
    ``ok`` and ``init`` has none of :data:`MISTAKE_CODES`.  Window
    :math:`i` of :math:`n` holds every measurement in
    :math:`[s_i, s_i + \Delta]`, :math:`\Delta` the initiation window's span
    and :math:`s_i` evenly spaced from the initiation window's end to
    :math:`t_\mathrm{last} - \Delta`; each is initiated with the model's zone
    and ``init``'s half plane, and every change under which a window that
    fails passes the χ² test at 95 % counts as its vote.  The change with
    the most votes (among equals, the least total cost in the windows that
    pass with it) is reported, with the first window it makes pass, the
    count and the other changes under which that window passes.  Costs
    nothing on a track that fits; on one that does not, :math:`n`
    initiations and, for each window that fails,
    :math:`1 + P + P(P-1)/2` more with :math:`P` pairs (and more with radars,
    :func:`~fgdoppler.estimators.window_mistakes.mistake_reasons`) — unless
    ``reference``, a track on the same data and initiation whose own
    ``fit`` finding is not ``ok`` either and whose settings have the same
    ``huber_k``, made the same check already: its mistake
    finding (or its lack of one) is then the answer.

    Parameters
    ----------
    measurements, model
        The recording and model the track was estimated with.
    init
        The initiation the track started from (its window's span and findings).
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
    if not _misfits(reasons) or any(r.code in MISTAKE_CODES for r in init.reasons) or len(measurements) == 0:
        return []
    if reference is not None and windows == LATER_WINDOWS and _misfits(reference.reasons) \
            and reference.settings.huber_k == huber_k:
        # the same windows, fits and votes: the answer depends on nothing else
        return [r for r in reference.reasons if r.code in MISTAKE_CODES]
    return _from_windows(measurements, model, init, huber_k, windows)


def _misfits(reasons: tuple[Reason, ...]) -> bool:
    """Whether a track's findings say its residuals fail the whole-track test."""
    return any(r.code == "fit" and r.status != "ok" for r in reasons)


def _from_windows(measurements: Measurements, model: TrackingModel, init: Initiation, huber_k: float | None,
                  windows: int) -> list[Reason]:
    """The change most of ``windows`` later windows need to fit, as a finding (:func:`later_mistakes`)."""
    span = init.t_end - init.t_start
    last = float(np.max(measurements.time))
    if not (span > 0 and last - span > init.t_end):
        return []
    settings = InitiationSettings(half_plane=init.half_plane, huber_k=huber_k)
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
    if not passed:
        return []
    best = max(len(v) for v in passed.values())
    # among the changes that pass in the most windows, the least total cost there (dict order: first seen)
    votes = min((v for v in passed.values() if len(v) == best), key=lambda v: sum(m.cost for m, *_ in v))
    chosen, there, cost, start = votes[0]
    named = mistake_reason(replace(chosen, others=tuple(m for m in there if m is not chosen)), cost,
                           settings.confidence)
    return [replace(named, message=(
        f"the track fails its residual test and the initiation window named no mistake, but later in the "
        f"recording {best} of {windows} windows of {span:g} s fit with a change of the data (first at t = "
        f"{start:.1f}-{start + span:.1f} s): {named.message}"))]
