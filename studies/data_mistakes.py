r"""Mistakes a user makes writing a measurement file: does the verdict say so, and only then?

Three mistakes, each checked on the same recordings:

* **The opposite sign convention.**  A Doppler shift in Hz is positive for a closing target;
  fgdoppler's ``doppler`` column is the bistatic range rate, negative for one
  (docs/data-formats.md).  A file converted without the minus sign — for every pair, or for one
  receiver whose software differs.  The initiation's ``sign`` finding should name the negated
  pairs.
* **Pairs swapped.**  The file's pair 0 is the geometry's pair 1 and the other way round (a
  geometry file listing the receivers in another order than the recording's software).  Data
  cannot always tell: the swapped data may fit another track as well as the right data fit the
  truth's; where the window fails, the initiation's ``swapped`` finding should name the pairs.
  Pair names (``name`` in the geometry's ``[[pair]]`` tables, used in the file's ``pair`` column)
  rule the mistake out.
* **A radar's radial velocity.**  For a radar (Tx and Rx at one place) fgdoppler's ``doppler`` is
  the rate of change of twice its range; a file may give its radial velocity (half of it), or the
  radial velocity positive for an approaching target (minus half of it: ``wavelength * f_D / 2``).
  The initiation's ``radial`` finding should name the radars.  Checked on the radar layouts alone
  (the others have no radar).
* **Sensors in kilometres.**  The geometry's positions (and its zone's limits) in kilometres where
  fgdoppler reads metres.  The initiation's ``units`` finding should say so
  (:func:`fgdoppler.estimators.window_mistakes.units_reason`, tried where the sensors lie within
  1,000 m of each other as read).  Its check for false alarms: the manoeuvring recording below on the
  layout a hundred times smaller (lengths, speeds, sigma scaled: layouts 44-100 km across become
  440 m-1 km, the paper's 50 km 500 m), whose windows fail for a manoeuvre and are tried in kilometres
  too where they lie within those 1,000 m.
* **Times in milliseconds.**  The time column in milliseconds where fgdoppler reads seconds (as many
  loggers write it).  The initiation's ``units`` finding should say so
  (:func:`fgdoppler.estimators.window_mistakes.time_units_reason`, tried where a pair's median interval
  divided by 1000 is at least 5 ms).  Its check for false alarms: the manoeuvring recording below
  twenty times slower (times 20 times later, Doppler, sigma and speeds a twentieth, the process noise
  density 1/8000: the same whitened problem sampled every 10 s), whose windows fail for a manoeuvre and
  are tried in milliseconds.
* **Two outliers in the window.**  Two of the initiation window's measurements moved by 20-50 sigma, each
  of a random sign (``two outliers in the window``).  Not a file mistake: the initiation's ``outliers``
  finding (:func:`fgdoppler.estimators.window_mistakes.outliers_reason`) should name exactly those two, and
  nothing on the other versions (the table's outliers column).
* **The Doppler's scale.**  Every Doppler and its sigma times 0.5, 0.8, 1.25 or 2 (``Doppler scaled by F``):
  a Doppler shift in Hz converted with a wrong wavelength, or a range rate in another unit.  Not looked
  for: where the scaled data fit another track, no finding can tell (the table's smoother columns say how
  often a confident answer is wrong).
* **A receiver misplaced.**  The geometry puts pair 1's receiver 5 km east of where it is (the data as
  simulated; ``pair 1's receiver 5 km off``).  Not a mistake in the file: where the window names a change
  anyway and the track fits as given, the track's ``unconfirmed`` finding
  (:mod:`fgdoppler.estimators.later_mistakes`) should say that the whole recording does not need it.
* **Sigma too small.**  Every sigma times 0.2 or 0.5, the Doppler as measured (``sigma times F``): sigma in
  another unit, or estimated for another integration time.  Every cost then grows about ``1/F**2``-fold and the
  smoother's split test of the motion model fires on targets that fly straight; its ``manoeuvre`` finding should
  say that the sigma are more likely too small (:func:`fgdoppler.estimators.manoeuvre._sigma_instead`), and
  nothing of the kind on the manoeuvring recordings or with a receiver misplaced (the table's last column).
* **A receiver that holds or writes a fixed value.**  Every third of pair 1's measurements the one before it
  (``pair 1 holds a third of its values``: a receiver holding its last value without a detection), or pair 1
  reading 0 throughout (``pair 1 reads 0 throughout``: a dead one), or 0 at every tenth of its measurements
  (``pair 1 reads 0 at a tenth of its scans``: one that writes 0 without a detection); each also with the repeats the verdict finds
  left out (``... (repeats dropped)``, as ``track --drop-repeats`` does: :mod:`fgdoppler.repeats`).  The
  smoother's ``data`` finding should name the repeats (the table's repeats column) and nothing on the other
  versions.
* **Values rounded coarsely.**  Every Doppler rounded to twice its sigma (``Doppler rounded to twice sigma``: a
  receiver's coarse output), its sigma as stated, and with sigma that include the rounding's noise (``... (sigma
  with the rounding)``).  Where the track's fit test fails, its ``data`` finding should say the rounding adds
  noise (the table's last column).
* **A receiver's clock off.**  Pair 1's times ``--late`` seconds late (default 0.5; one clock for
  every pair is assumed).  Not looked for: where such data fit another track, no finding can tell.
  With ``--clock-sigma S`` the estimator is told each pair's clock may be off by S (1 sigma;
  ``clock_sigma=S`` of its settings, a consider covariance), on every version of the data.

Per recording, up to twenty versions of the data: as simulated, every pair's Doppler negated, pair 0's
alone negated, pairs 0 and 1 swapped, pair 1's clock late, where the geometry has radars their
Doppler halved and halved and negated, every Doppler scaled by 0.5, 0.8, 1.25 and 2, every sigma times 0.2
and 0.5, the recording simulated anew with its target manoeuvring
(``target manoeuvres``: turning by up to 0.6 deg/s and changing speed by up to 1 m/s^2 from a time in
0-20 s, drawn per recording; right data, so no mistake should be named), the geometry in kilometres
and that manoeuvring recording on the layout a hundred times smaller (nothing to name), the times in milliseconds
and the manoeuvring recording twenty times slower (nothing to name), two outliers in the window, and pair 1's receiver misplaced.  ``--only`` runs the versions
it lists (comma-separated names, as the tables give them).  For each: whether the initiation has a ``sign``,
``swapped``, ``radial`` or ``units`` finding (:func:`fgdoppler.estimators.window_mistakes.with_mistake`) and
what it names, and (``--track 1``, the default) the verdict of ``--estimator`` (default the
offline smoother) from that initiation, with its position error at the last time of the truth
against its own sigma along the major axis (wrong: beyond 3 sigma), and the mistake finding it
adds where the track fails its residual test (:mod:`fgdoppler.estimators.later_mistakes`): where
the initiation named nothing, from windows later in the recording, or on radar layouts from
measurements spread over the whole recording; where it named a change, the change of those the
window fits with that the measurements spread over the whole recording fit with best.
``--late-only 1`` runs the late clock's version alone (the check of ``--clock-sigma`` for an
estimator whose every run is slow).

Recordings: the accuracy benchmark's runs of the paper's six scenarios (``--runs`` each, ``--seed``),
as many random layouts of ``studies/random_layouts.py`` (draw ``100 s + r``: two to four
pairs anywhere, the target anywhere in the default zone) and as many radar layouts of
``studies/monostatic_layouts.py`` (draw ``100 s + r``: a radar and one to three pairs, the last a
second radar in half of them).

Run: python studies/data_mistakes.py [--runs 10] [--seed 2026] [--track 1] [--late 0.5] [--clock-sigma 0]
[--estimator smoother] [--late-only 0] [--only VERSION,...] [--workers 2] [--out DIR]
(with the radar layouts, 2026-11-27, on 2 cores shared with other work: ``--runs 10`` 43 min; ``--track 0``,
the initiations alone, 15 min for ``--runs 20``; 2026-11-29, with the whole recording's check of
:mod:`fgdoppler.estimators.later_mistakes`, on 2 idle cores: ``--runs 10`` 34 min; with the window's
changes ranked there too, on 2 cores beside other work: 56 min; ``--only "sensors in kilometres,target manoeuvres on
a layout 1/100 the size"``, 23 min; 2026-11-30, ``--only "times in milliseconds,target manoeuvres 20 times slower"``,
13 min on 2 cores; ``--only "as given,target manoeuvres,two outliers in the window,pair 1's clock late"``, 18 min
on 2 cores; the four ``Doppler scaled by`` versions, 10 min on 2 cores; ``--only "as given,target manoeuvres,pair 1's
receiver 5 km off,sigma times 0.2,sigma times 0.5"``, 31 min on 2 cores; ``--only "as given,every pair negated,pair 0
negated,pairs 0 and 1 swapped,radars' radial velocity,radars' approach speed,pair 1's receiver 5 km off"``, 34 min on
2 cores; the seven versions of "as given" and the held, dead and gapped receivers, 27 min on 2 cores; "as given" and the
two rounded versions, 9 min on 2 cores)
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from _common import each_run, paper_run, save_table
from manoeuvres import drawn_manoeuvre
from monostatic_layouts import draw as radar_draw
from random_layouts import draw, one_blas_thread, recorded

import fgdoppler as fd
from fgdoppler.estimators.judge import LEVEL, REPEATS_ADVICE, ROUNDING_ADVICE
from fgdoppler.estimators.later_mistakes import MISTAKE_CODES, UNCONFIRMED, is_mistake_finding
from fgdoppler.estimators.manoeuvre import SIGMA_ADVICE
from fgdoppler.estimators.registry import estimator_info
from fgdoppler.estimators.verdict import status_of
from fgdoppler.repeats import drop_repeats, find_repeats


def _negated(m: fd.Measurements, pairs: list[int] | None) -> fd.Measurements:
    """``m`` with the Doppler of ``pairs`` (``None``: every pair) negated."""
    sign = -np.ones(len(m)) if pairs is None else np.where(np.isin(m.pair, pairs), -1.0, 1.0)
    return fd.Measurements(time=m.time, pair=m.pair, doppler=sign * m.doppler, sigma=m.sigma)


def _swapped(m: fd.Measurements) -> fd.Measurements:
    """``m`` with pairs 0 and 1 exchanged."""
    pair = np.where(m.pair == 0, 1, np.where(m.pair == 1, 0, m.pair))
    return fd.Measurements.from_arrays(m.time, pair, m.doppler, m.sigma, sort=True)


def _radial(m: fd.Measurements, g: fd.Geometry, factor: float) -> fd.Measurements:
    """``m`` with the Doppler of ``g``'s radars multiplied by ``factor``."""
    return fd.Measurements(time=m.time, pair=m.pair, doppler=np.where(np.isin(m.pair, g.radars), factor, 1.0) * m.doppler,
                           sigma=m.sigma)


def _radars(g: fd.Geometry) -> str:
    """How a mistake finding names ``g``'s radars (``find_mistake``'s wording)."""
    r = list(g.radars)
    if len(r) == g.n_pairs:
        return "every pair"
    return f"pair {r[0]}" if len(r) == 1 else f"pairs {', '.join(map(str, r[:-1]))} and {r[-1]}"


def _scaled(m: fd.Measurements, g: fd.Geometry, late: float, *, factor: float) -> fd.Measurements:
    """``m`` with every Doppler and sigma times ``factor``: a Doppler shift in Hz converted with a wavelength
    ``factor`` times the carrier's, or a range rate in another unit."""
    return fd.Measurements(time=m.time, pair=m.pair, doppler=factor * m.doppler, sigma=factor * m.sigma)


def _sigma_scaled(m: fd.Measurements, g: fd.Geometry, late: float, *, factor: float) -> fd.Measurements:
    """``m`` with every sigma times ``factor`` (the Doppler as measured): sigma in another unit, or estimated for
    another integration time."""
    return fd.Measurements(time=m.time, pair=m.pair, doppler=m.doppler, sigma=factor * m.sigma)


def _dropped(m: fd.Measurements) -> fd.Measurements:
    """``m`` without what the verdict finds repeated (``track --drop-repeats``)."""
    return drop_repeats(m, find_repeats(m, level=LEVEL))


def _held(m: fd.Measurements, g: fd.Geometry, late: float, *, dropped: bool) -> fd.Measurements:
    """``m`` with every third measurement of pair 1 the one before it (a receiver holding its last value where it
    has no detection); ``dropped``: then without the repeats the verdict finds (``track --drop-repeats``)."""
    z = m.doppler.copy()
    rows = np.flatnonzero(m.pair == 1)
    z[rows[3::3]] = z[rows[2::3][:rows[3::3].size]]
    out = fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)
    return _dropped(out) if dropped else out


def _dead(m: fd.Measurements, g: fd.Geometry, late: float, *, dropped: bool) -> fd.Measurements:
    """``m`` with pair 1 reading 0 throughout (a dead receiver whose software writes 0 without a detection);
    ``dropped``: then without the repeats the verdict finds (``track --drop-repeats``: all of pair 1)."""
    out = fd.Measurements(time=m.time, pair=m.pair, doppler=np.where(m.pair == 1, 0.0, m.doppler), sigma=m.sigma)
    return _dropped(out) if dropped else out


def _gaps(m: fd.Measurements, g: fd.Geometry, late: float, *, dropped: bool) -> fd.Measurements:
    """``m`` with 0 in every tenth of pair 1's measurements, from its third (a receiver writing 0 where it has no
    detection); ``dropped``: then without what the verdict finds (``track --drop-repeats``)."""
    rows = np.flatnonzero(m.pair == 1)[2::10]
    z = m.doppler.copy()
    z[rows] = 0.0
    out = fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)
    return _dropped(out) if dropped else out


def _rounded(m: fd.Measurements, g: fd.Geometry, late: float, *, with_rounding: bool) -> fd.Measurements:
    """``m`` with every Doppler rounded to twice its sigma (a receiver's coarse output); ``with_rounding``: with
    sigma that include the rounding's noise, sqrt(sigma^2 + q^2 / 12)."""
    q = 2.0 * m.sigma
    sigma = np.sqrt(m.sigma ** 2 + q ** 2 / 12.0) if with_rounding else m.sigma
    return fd.Measurements(time=m.time, pair=m.pair, doppler=np.round(m.doppler / q) * q, sigma=sigma)


def _late(m: fd.Measurements, seconds: float) -> fd.Measurements:
    """``m`` with pair 1's times ``seconds`` late (its receiver's clock off)."""
    return fd.Measurements.from_arrays(np.where(m.pair == 1, m.time + seconds, m.time), m.pair, m.doppler, m.sigma,
                                       sort=True)


#: The late clock's version (``--late-only``).
LATE = "pair 1's clock late"
#: The version whose data are right but whose target manoeuvres (a recording simulated anew): nothing to name.
MANOEUVRE = "target manoeuvres"
#: A receiver holding its last value (every third of pair 1's measurements the one before), and a dead one.
HELD = "pair 1 holds a third of its values"
DEAD = "pair 1 reads 0 throughout"
GAPS = "pair 1 reads 0 at a tenth of its scans"
ROUNDED = "Doppler rounded to twice sigma"

#: The versions of each recording: name -> (the data given the geometry and the clock's lateness in s, the change
#: of the data that a mistake finding should name given the geometry, as it words it — "" for none —, whether the
#: version needs radars).
VERSIONS: dict[str, tuple[Callable[[fd.Measurements, fd.Geometry, float], fd.Measurements],
                          Callable[[fd.Geometry], str], bool]] = {
    "as given": (lambda m, g, _: m, lambda g: "", False),
    "every pair negated": (lambda m, g, _: _negated(m, None), lambda g: "the Doppler of every pair negated", False),
    "pair 0 negated": (lambda m, g, _: _negated(m, [0]), lambda g: "the Doppler of pair 0 negated", False),
    "pairs 0 and 1 swapped": (lambda m, g, _: _swapped(m), lambda g: "the labels of pairs 0 and 1 exchanged", False),
    LATE: (lambda m, g, late: _late(m, late), lambda g: "", False),
    "radars' radial velocity": (lambda m, g, _: _radial(m, g, 0.5), lambda g: f"the Doppler of {_radars(g)} doubled",
                                True),
    "radars' approach speed": (lambda m, g, _: _radial(m, g, -0.5),
                               lambda g: f"the Doppler of {_radars(g)} doubled and negated", True),
    **{f"Doppler scaled by {f:g}": (functools.partial(_scaled, factor=f), lambda g: "", False)
       for f in (0.5, 0.8, 1.25, 2.0)},
    **{f"sigma times {f:g}": (functools.partial(_sigma_scaled, factor=f), lambda g: "", False) for f in (0.2, 0.5)},
    HELD: (functools.partial(_held, dropped=False), lambda g: "", False),
    f"{HELD} (repeats dropped)": (functools.partial(_held, dropped=True), lambda g: "", False),
    DEAD: (functools.partial(_dead, dropped=False), lambda g: "", False),
    f"{DEAD} (repeats dropped)": (functools.partial(_dead, dropped=True), lambda g: "", False),
    GAPS: (functools.partial(_gaps, dropped=False), lambda g: "", False),
    f"{GAPS} (repeats dropped)": (functools.partial(_gaps, dropped=True), lambda g: "", False),
    ROUNDED: (functools.partial(_rounded, with_rounding=False), lambda g: "", False),
    f"{ROUNDED} (sigma with the rounding)": (functools.partial(_rounded, with_rounding=True), lambda g: "", False),
}

#: The version whose geometry gives the sensors in kilometres (the data as simulated): a ``units`` finding is right.
KILOMETRES = "sensors in kilometres"
#: The manoeuvring version on the layout a hundred times smaller (lengths, speeds, sigma and the process noise's
#: accelerations scaled with it: the same whitened problem), whose failing windows are tried in kilometres too.
SMALL = "target manoeuvres on a layout 1/100 the size"
#: What a ``units`` finding names, as :func:`_changes` reads it.
IN_KILOMETRES = "every sensor position multiplied by 1000"
#: The version with the times in milliseconds (the data as simulated otherwise): a ``units`` finding is right.
MILLISECONDS = "times in milliseconds"
#: What its ``units`` finding names, as :func:`_changes` reads it.
IN_MILLISECONDS = "every time divided by 1,000"
#: The manoeuvring version twenty times slower (sampled every 10 s), whose failing windows are tried in
#: milliseconds.
SLOW = "target manoeuvres 20 times slower"
#: The version with two gross outliers in the initiation window (the data as simulated otherwise): an ``outliers``
#: finding naming them is right.
OUTLIERS = "two outliers in the window"
#: The version whose geometry puts pair 1's receiver 5 km east of where it is (the data as simulated): nothing to
#: name in the file; an ``unconfirmed`` finding where the window names a change is right.
MISPLACED = "pair 1's receiver 5 km off"
#: The findings the tables count.
FINDINGS = (*MISTAKE_CODES, "units")

#: Every version, in the tables' order.
ALL_VERSIONS = [*VERSIONS, MANOEUVRE, KILOMETRES, SMALL, MILLISECONDS, SLOW, OUTLIERS, MISPLACED]
#: A named outlier in an ``outliers`` finding's words: its pair and time.
_OUTLIER = re.compile(r"pair (\d+)(?: \([^)]*\))? at t = ([\d.]+) s: ")


def _with_outliers(m: fd.Measurements, key: int) -> tuple[fd.Measurements, list[tuple[int, float]]]:
    """``m`` with two of its first ten measurements per pair (the initiation window) moved by 20-50 sigma, each
    of a random sign, drawn from ``key``; and those two as (pair, time)."""
    rng = np.random.default_rng(9000 + key)
    w = m.first_per_pair(10)
    hit = [int(np.flatnonzero((m.pair == w.pair[i]) & (m.time == w.time[i]))[0])
           for i in rng.choice(len(w), size=2, replace=False)]
    jump = np.zeros(len(m))
    jump[hit] = rng.choice([-1.0, 1.0], size=2) * rng.uniform(20.0, 50.0, size=2) * m.sigma[hit]
    return (fd.Measurements(time=m.time, pair=m.pair, doppler=m.doppler + jump, sigma=m.sigma),
            sorted((int(m.pair[i]), float(m.time[i])) for i in hit))


def misplaced(g: fd.Geometry, metres: float = 5e3) -> fd.Geometry:
    """``g`` with pair 1's receiver ``metres`` farther along x (east) than it is; its zone, names and
    wavelengths kept."""
    p = g.pairs[1]
    moved = fd.BistaticPair(tx=p.tx, rx=np.asarray(p.rx, dtype=float) + np.eye(len(p.rx))[0] * metres)
    return replace(g, pairs=(g.pairs[0], moved, *g.pairs[2:]))


def manoeuvring(sim: fd.Simulation, key: int) -> fd.Simulation:
    """``sim``'s recording simulated anew with its target turning by up to 0.6 deg/s and changing speed by up to
    1 m/s^2 from a time in 0-20 s (``studies/manoeuvres.py``'s default rule), drawn from ``key``."""
    man = drawn_manoeuvre(np.random.default_rng(7000 + key))
    return fd.simulate(replace(sim.scenario, manoeuvre=man), np.random.default_rng(8000 + key))


def _shrunk(m: fd.Measurements, truth: fd.Trajectory, model: fd.TrackingModel, s: float
            ) -> tuple[fd.Measurements, fd.Trajectory, fd.TrackingModel]:
    """The recording of a layout ``s`` times the size, its target's positions and speeds ``s`` times too: the
    bistatic Doppler depends on positions only through directions, so it and its sigma scale by ``s``, and
    the process noise's density by ``s**2`` (the same problem, whitened)."""
    g = model.geometry.scaled(s)
    return (fd.Measurements(time=m.time, pair=m.pair, doppler=s * m.doppler, sigma=s * m.sigma),
            replace(truth, states=s * truth.states),
            fd.TrackingModel.of(g, motion=replace(model.motion, q=model.motion.q * s**2)))


def _slowed(m: fd.Measurements, truth: fd.Trajectory, model: fd.TrackingModel, s: float
            ) -> tuple[fd.Measurements, fd.Trajectory, fd.TrackingModel]:
    """The recording of a target ``s`` times slower on the same layout, sampled ``s`` times less often: its
    positions at times ``s`` times later, so the Doppler and its sigma scale by ``1/s`` and the process noise's
    density, an acceleration's (``1/s**2``) white noise in time stretched ``s``-fold, by ``1/s**3`` (the same
    problem, whitened)."""
    k = truth.states.shape[1] // 2
    slow = truth.states.copy()
    slow[:, k:] /= s
    return (fd.Measurements(time=s * m.time, pair=m.pair, doppler=m.doppler / s, sigma=m.sigma / s),
            fd.Trajectory(times=s * truth.times, states=slow),
            fd.TrackingModel.of(model.geometry, motion=replace(model.motion, q=model.motion.q / s**3)))


#: The change a mistake finding names first, and the other changes it names (``mistake_reason``'s wording).
_FIRST = re.compile(r"^(?:.*: )?with (the (?:Doppler|labels) of .+?|every sensor position(?: and the zone's limits)? "
                    r"multiplied by 1000|every time divided by [\d,]+) (?:the window fits|they fit)")
_OTHERS = re.compile(r"(?:passes|pass) the same test with (.+?) too: check")
_CHANGE = re.compile(r"(the (?:Doppler|labels) of .+?) \(cost ")


def _changes(reason: fd.Reason | None) -> tuple[str, list[str]]:
    """The change a mistake finding names first and the others it names ("" and [] without a finding)."""
    if reason is None:
        return "", []
    first, others = _FIRST.search(reason.message), _OTHERS.search(reason.message)
    return (first.group(1) if first else "?"), (_CHANGE.findall(others.group(1)) if others else [])


def _judged(sim: fd.Simulation, model: fd.TrackingModel, track: int, late: float, clock_sigma: float,
            estimator: str, versions: list[str], key: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    g = sim.scenario.geometry
    for name in versions:
        corrupted: list[tuple[int, float]] = []
        truth, used = sim.truth, model
        if name in (MANOEUVRE, SMALL, SLOW):
            moved = manoeuvring(sim, key)
            m, truth, want = moved.measurements, moved.truth, (lambda g: "")
            if name == SMALL:
                m, truth, used = _shrunk(m, truth, model, 0.01)
            elif name == SLOW:
                m, truth, used = _slowed(m, truth, model, 20.0)
        elif name == MILLISECONDS:
            m = fd.Measurements(time=1e3 * sim.measurements.time, pair=sim.measurements.pair,
                                doppler=sim.measurements.doppler, sigma=sim.measurements.sigma)
            truth, want = fd.Trajectory(times=1e3 * sim.truth.times, states=sim.truth.states), (lambda g: IN_MILLISECONDS)
        elif name == KILOMETRES:
            m, want, used = sim.measurements, (lambda g: IN_KILOMETRES), fd.TrackingModel.of(g.scaled(1e-3))
        elif name == MISPLACED:
            m, want, used = sim.measurements, (lambda g: ""), fd.TrackingModel.of(misplaced(g))
        elif name == OUTLIERS:
            (m, corrupted), want = _with_outliers(sim.measurements, key), (lambda g: "")
        else:
            version, want, radars = VERSIONS[name]
            if radars and not g.radars:
                continue
            m = version(sim.measurements, g, late)
        try:
            init = fd.initiate(m.first_per_pair(10), used)
        except ValueError as exc:  # a manoeuvre can take the target beyond the zone's speed bound
            out[name] = {"refused": str(exc)}
            continue
        found = [r for r in init.reasons if is_mistake_finding(r)]
        first, others = _changes(found[0] if found else None)
        outliers = [r for r in init.reasons if r.code == "outliers" and r.status != "ok"]
        row: dict[str, Any] = {"finding": found[0].code if found else "", "names": first, "others": others,
                               "right": want(g),
                               "outliers": sorted((int(p), float(t)) for p, t in _OUTLIER.findall(outliers[0].message))
                               if outliers else None,
                               "corrupted": corrupted if name == OUTLIERS else None}
        if track:
            r = fd.run_estimator(estimator, m, used, init, estimator_info(estimator).settings(clock_sigma=clock_sigma))
            e = r.primary
            k = e.states.shape[1] // 2
            j = int(np.flatnonzero(e.times <= truth.times[-1])[-1])  # a late clock's last times are not truth's
            err = float(np.linalg.norm(e.states[j, :k] - truth.at(e.times[j:j + 1])[0][:k]))
            sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[j][:k, :k])))) if e.cov_ok[j] else np.nan
            later = [x for x in r.reasons if is_mistake_finding(x)]
            row.update(status=str(r.status), error=round(err, 1), sigma=round(sd, 1),
                       later=_changes(later[0] if later else None)[0],
                       unconfirmed=any(x.code == UNCONFIRMED for x in r.reasons),
                       manoeuvre=any(x.code == "manoeuvre" for x in r.reasons),
                       sigma_small=any(x.code == "manoeuvre" and SIGMA_ADVICE in x.message for x in r.reasons),
                       repeats=any(x.code == "data" and REPEATS_ADVICE in x.message for x in r.reasons),
                       but_repeats=status_of(x for x in r.reasons
                                             if not (x.code == "data" and REPEATS_ADVICE in x.message)),
                       rounding=any(x.code == "data" and ROUNDING_ADVICE in x.message for x in r.reasons))
        out[name] = row
    return out


@one_blas_thread
def one(task: tuple[int, int, int], track: int = 1, late: float = 0.5, clock_sigma: float = 0.0,
        estimator: str = "smoother", late_only: int = 0, only: str = "") -> dict[str, Any]:
    s, r, seed = task
    sim, model, _ = paper_run(s, r, seed)
    versions = [LATE] if late_only else [v for v in ALL_VERSIONS if not only or v in only.split(",")]
    i = 100 * s + r
    out: dict[str, Any] = {"scenario": s, "run": r,
                           "paper": _judged(sim, model, track, late, clock_sigma, estimator, versions, i)}
    for where, drawn in (("layout", draw(i)), ("radar layout", radar_draw(i))):
        record, layout_sim, init = recorded(i, *drawn)
        if init is not None:
            out[where] = _judged(layout_sim, fd.TrackingModel.of(layout_sim.scenario.geometry), track, late,
                                 clock_sigma, estimator, versions, i)
        else:
            out[f"{where} refused"] = record.get("refused", "")
    return out


def _repeats_cell(got: list[dict[str, Any]]) -> str:
    """The repeats column: tracks with the finding (of them, ``ok`` but for it, and of those, beyond 3 sigma)."""
    found = [g for g in got if g.get("repeats")]
    but = [g for g in found if g.get("but_repeats") == "ok"]
    return f"{len(found)} ({len(but)}, {sum(g['error'] > 3.0 * g['sigma'] for g in but)})"


def _table(rows: list[dict[str, Any]], where: str, track: bool, estimator: str) -> list[str]:
    lines = [f"### {where}", "", "| data | recordings | sign / swapped / radial / units finding | names the change made "
             "(first / among the others) | outliers finding (names exactly the two made) | " + (f"{estimator} ok | ok and beyond 3 sigma | named later by the "
                                                 f"{estimator} where the window named nothing (rightly) | the "
                                                 f"window's finding ranked by the {estimator} (the change made "
                                                 f"first) | the window's finding unconfirmed by the {estimator} | "
                                                 f"the {estimator}'s manoeuvre finding (saying the sigma are too "
                                                 f"small) | the {estimator}'s repeats finding (ok but for it, beyond 3 sigma) | its rounding finding |"
                                                 if track else ""),
             "|---|---|---|---|---|" + ("---|---|---|---|---|---|---|---|" if track else "")]
    for name in ALL_VERSIONS:
        got = [r[where][name] for r in rows if where in r and name in r[where] and "refused" not in r[where][name]]
        if not got:
            continue
        wanted = any(g["right"] for g in got)
        right = f"{sum(g['names'] == g['right'] for g in got)} / {sum(g['right'] in g['others'] for g in got)}" \
            if wanted else "—"
        said = [g["finding"] for g in got if g["finding"]]
        flagged = [g for g in got if g.get("outliers") is not None]
        exact = f" ({sum(g['outliers'] == g['corrupted'] for g in flagged)})" if name == OUTLIERS else ""
        line = (f"| {name} | {len(got)} | {' / '.join(str(said.count(c)) for c in FINDINGS)} | {right} | "
                f"{len(flagged)}{exact} |")
        if track:
            ok = [g for g in got if g["status"] == "ok"]
            wrong = sum(g["error"] > 3.0 * g["sigma"] for g in ok)
            later = [(g["later"], g["right"]) for g in got if g.get("later") and not g["finding"]]
            ranked = [(g["later"], g["right"]) for g in got if g.get("later") and g["finding"]]
            line += (f" {len(ok)} | {wrong} | {len(later)} ({sum(x == w for x, w in later) if wanted else '—'}) | "
                     f"{len(ranked)} ({sum(x == w for x, w in ranked) if wanted else '—'}) | "
                     f"{sum(bool(g.get('unconfirmed')) for g in got)} | {sum(bool(g.get('manoeuvre')) for g in got)} "
                     f"({sum(bool(g.get('sigma_small')) for g in got)}) | {_repeats_cell(got)} | "
                     f"{sum(bool(g.get('rounding')) for g in got)} |")
        lines.append(line)
    return [*lines, ""]


def main() -> None:
    args, rows = each_run(one, "data_mistakes.py", "studies",
                          options={"--track": {"type": int, "default": 1},
                                   "--late": {"type": float, "default": 0.5},
                                   "--clock-sigma": {"type": float, "default": 0.0},
                                   "--estimator": {"choices": list(fd.ESTIMATORS), "default": "smoother"},
                                   "--late-only": {"type": int, "default": 0},
                                   "--only": {"default": "", "help": "comma-separated versions to run (default: "
                                              "all of them)"}})
    track = bool(args.track)
    text = "\n".join([f"{args.runs} runs per paper scenario and as many random layouts and radar layouts, seed "
                       f"{args.seed}; a late clock {args.late:g} s; the {args.estimator}'s clock_sigma "
                       f"{args.clock_sigma:g} s", "",
                      *(line for where in ("paper", "layout", "radar layout")
                        for line in _table(rows, where, track, args.estimator))])
    save_table(args.out, "data_mistakes", text, rows)


if __name__ == "__main__":
    main()
