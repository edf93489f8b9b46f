r"""Does the target move as the motion model says?  A split test of the whole recording.

Doppler-only tracking places a target through its motion: with two pairs a
scan gives two numbers for four unknowns, and the position comes from how
the Doppler changes over time under the nearly-constant-velocity model.  A
target that turns or changes speed breaks that link, and the smoother's
track — the constant-velocity track that best explains the data — can then
lie kilometres from the target while fitting the data as well as a true
track would: its residuals pass the χ² test, and the filters, run on the
same assumption, agree with it.  Measured on random layouts with gentle
manoeuvres (``python studies/manoeuvres.py``, docs/concepts.md
"Manoeuvring targets"): answers 1.6–22 km off with σ of 0.1–0.2 km were
``ok``.

What the data do show is that their parts disagree about the track.  For a
split time :math:`t_c`, let :math:`C` be the least cost of the whole
recording (whitened residuals and motion terms, as the smoother minimises
it, without the zone's prior and wall) and :math:`C_1`, :math:`C_2` the
least costs of the data up to :math:`t_c` and after it, each fitted on its
own: the motion link across :math:`t_c` removed.  The statistic

.. math:: D(t_c) = C - C_1 - C_2 \ \ge 0

is the likelihood ratio of "one track" against "two independent tracks".
Under the model the parts gain the :math:`n` degrees of freedom of the
removed link (4 in 2-D, 6 in 3-D), so :math:`D \sim \chi^2_n`
asymptotically.  A manoeuvre makes the later part's track differ from the
earlier one's, and :math:`D` grows with it.  The recording is split at the
middle of its span (:data:`SPLITS`), where both parts are longest and best
observed, and a :math:`D` above the :math:`\chi^2_n` quantile at
:data:`LEVEL` is the ``manoeuvre`` finding.  Several split times would share
the level (Bonferroni: the largest :math:`D` against the quantile at
:math:`1 - (1 - \text{LEVEL}) / k` for :math:`k` of them).

Measured under the model (constant-velocity truths; docs/concepts.md,
"Manoeuvring targets"): on the accuracy benchmark's 1,200 recordings of
the paper's six scenarios the mean of :math:`D` at the middle is 4.11 and
one recording exceeds the 99.9 % level (0.08 %); on 180 random layouts none
does.  Splitting at a third, half and two thirds, the level shared, caught
one more of four confidently wrong answers to manoeuvres but raised the
false alarms to 3 in 1,200 (short parts are poorly observed, and there
:math:`D`'s tail is heavier than the χ² law's) and doubled the test's cost.

Each part is fitted by the smoother's Levenberg–Marquardt started from the
whole track's states there, so it finds the part's optimum nearest that
track: where a part has a better, distant optimum in another basin,
:math:`D` is smaller than the global ratio, and the test errs towards
silence.  A split is skipped where a part would hold fewer than
:data:`MIN_PART` × ``n`` measurements.

**Poorly observed parts.**  The :math:`\chi^2_n` law is asymptotic: it
holds where each part's fit stays where the part's cost is near-quadratic.
A part observed poorly on its own has a long, flat valley instead, and its
fit slides along it to a lower cost with no manoeuvre at all.  Measured on
the paper's case a geometry (a target from (25, 3) km at (20, −60) m/s for
600 s sampled every 0.5 s, the truth drawn with process noise
:math:`q = 0.05` m²/s³ and the tracker told so; eight recordings): the
second part, 15–33 km off the sensors' line, slid 5–51 km, and :math:`D`
was 9–53 (mean 25), above the level in four — each called a manoeuvre of
a target that follows the model.  So where :math:`D` exceeds the level,
recordings of the null hypothesis are simulated from the track's start
(:func:`simulated_scale`) and the level is scaled by how far their
statistic's mean exceeds :math:`n` (a bootstrap Bartlett correction, by its
lower bound: only as far as the simulation shows for certain).  Those four
gave means of 18–35 and are informational findings now; the manoeuvring
random layouts of ``studies/manoeuvres.py`` (draws 0–119, 110 above the
level) keep all 110 findings, 4 of them with a scaled level still exceeded,
and ``studies/data_mistakes.py`` (as given, manoeuvring, a receiver
misplaced, the Doppler 1.25 times too large; 720 recordings) all 238 of its
own, 7 with a scaled level.
The simulation costs 4–16 fits of the split, and only where the level is
exceeded: 0.2–1.1 s on those 30 s recordings, 6–7 s on the 600 s ones
sampled every 0.5 s, 31 s on one sampled every 0.1 s (12,000 measurements).
With calibration offsets declared the parts re-fit them
(:func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`),
which frees them to slide further: on those eight recordings with offsets of
σ 0.5 m/s declared (none in the data) :math:`D` was 22–54, above the level
in all eight.  The simulated recordings then carry the joint mode's offsets
and re-fit them as the data's parts did (means 18–36); all eight are within
their scaled level, and on ``studies/manoeuvres.py``'s draws 0–119 with
offsets (``--bias-sigma 0.5``) all 108 findings stay, 41 with a scaled level
still exceeded, at 9–13 s a recording and 7 % more time respectively.

**Not only a manoeuvre.**  Any misfit that grows over the recording makes
the parts disagree: a receiver 5 km from where the geometry puts it, or one
pair's Doppler 1.25 times what it should be (a wrong wavelength), on the
83 random and radar layouts of three or four pairs of
``studies/data_mistakes.py`` (draws 100 s + r, s 0–5, r 0–9) misfitted on
34 and 54 tracks, and 32 and 51 of those had this finding.  So it names
those causes too (:data:`NOT_ONLY_A_MANOEUVRE`).  Leaving one pair out does
not tell them apart: of the spread measurements of
:mod:`~fgdoppler.estimators.later_mistakes` that fail as given, those
without exactly one pair passed the χ² test at 95 % on 13 of 82 manoeuvring
recordings against 5 of 34 with the misplaced receiver, and the best
pair's margin over the next was larger on the manoeuvring ones
(``python studies/one_pair_out.py --runs 10``).

**Sigma too small.**  With every stated sigma :math:`1/s` of the truth's,
every cost grows about :math:`s^2`-fold, :math:`D` with it, and the test
fires on a target flying straight; but then each part misfits its own track
as much, while a manoeuvre leaves the parts fitting theirs.  Where the parts'
cost :math:`C_1 + C_2` exceeds its χ² :data:`LEVEL` quantile on
:math:`\nu = N - 2n` degrees of freedom and
:math:`F = (D / n) / ((C_1 + C_2) / \nu)` — the split statistic against the
scatter the parts show, the F test of a likelihood ratio whose noise scale is
estimated — lies within the :math:`F(n, \nu)` quantile at
:data:`SCALE_AGREE_LEVEL`, the finding says the sigma are more likely
:math:`\sqrt{(C_1 + C_2)/\nu}` times too small (:data:`SIGMA_ADVICE`).
``python studies/data_mistakes.py --runs 10 --only "as given,target
manoeuvres,pair 1's receiver 5 km off,sigma times 0.2,sigma times 0.5"``
(seed 2026, 31 min on 2 cores, 2026-11-30; 60 paper recordings, 60 random
and 60 radar layouts each): with every sigma a fifth of the truth's the
finding fired on 159 of 180 recordings and said so on 158; with half, on 49
and said so on 48; it said so on none of the 126 findings on manoeuvring
recordings and on 1 of the 52 with a receiver misplaced (a radar layout,
whose parts misfit their own tracks too).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2
from scipy.stats import f as f_distribution

from fgdoppler._text import time_text
from fgdoppler.estimators.calibration import bias_sigmas, shifted_by
from fgdoppler.estimators.results import OffsetEstimate
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.estimators.verdict import Reason
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel
from fgdoppler.progress import Progress, advance, start_task

if TYPE_CHECKING:
    from fgdoppler.estimators.smoother_offsets import JointSolution

__all__ = ["AGREE_LEVEL", "LEVEL", "MIN_PART", "MIN_REPLICATES", "NOT_ONLY_A_MANOEUVRE", "REPLICATES", "SCALE_AGREE_LEVEL",
           "SIGMA_ADVICE", "SIMULATION_STREAM", "SPLITS", "Split", "manoeuvre_reason", "simulated_scale",
           "split_statistics", "splits"]

FloatArray = NDArray[np.float64]

#: Where the recording is split, as fractions of its span: the middle (module docstring).
SPLITS: tuple[float, ...] = (0.5,)
#: Level of the test (over all split times together): a recording that follows the model is flagged
#: one time in a thousand.
LEVEL = 0.999
#: Level within which the split statistic without a few outliers says the parts agree (:func:`manoeuvre_reason`).
AGREE_LEVEL = 0.90
#: A part must hold at least this many measurements per state component.
MIN_PART = 2
#: Recordings simulated from the track where the statistic exceeds the chi-square level, at most and at least
#: (:func:`simulated_scale`).
REPLICATES = 16
MIN_REPLICATES = 4
#: The stream of ``settings.seed`` those recordings draw from (:func:`simulated_scale`).
SIMULATION_STREAM = 7
#: Level within which the split statistic, against the parts' own scatter, says the parts agree (:func:`_sigma_instead`).
SCALE_AGREE_LEVEL = 0.99
#: What the finding advises where the sigma look too small (:func:`_sigma_instead`).
SIGMA_ADVICE = ("if so, give the measurements' right sigma (check their unit and what they were estimated from): "
                "the gates, the rejections and the fit test read them as given")
#: What the finding says misfits like a manoeuvre (module docstring, "Not only a manoeuvre").
NOT_ONLY_A_MANOEUVRE = ("or the geometry or one pair's data are off in a way no other finding names (a sensor's "
                        "position, a pair's wavelength or clock), which makes the parts disagree the same way: if the "
                        "target cannot manoeuvre, check those")


def _fit_cost(measurements: Measurements, model: TrackingModel, states: FloatArray,
              settings: SmootherSettings, progress: Progress | None = None) -> float:
    """Least cost of ``measurements`` under ``model`` from ``states`` (one per scan), without prior or wall; one
    step of ``progress``."""
    from fgdoppler.estimators.smoother import solve_smoother

    try:
        return solve_smoother(measurements, model, states, settings).cost
    finally:
        advance(progress)


@dataclass(frozen=True, kw_only=True)
class Split:
    """One split of the recording (:func:`splits`).

    Attributes
    ----------
    time
        The split time :math:`t_c`: the last scan of the first part.
    statistic
        :math:`D(t_c) = C - C_1 - C_2`.
    parts_cost
        :math:`C_1 + C_2`, the two parts' least costs.
    measurements
        The measurements of both parts, :math:`N`.
    """

    time: float
    statistic: float
    parts_cost: float
    measurements: int


def splits(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
           settings: SmootherSettings | None = None, *, progress: Progress | None = None) -> list[Split]:
    """The split test's fits at each of :data:`SPLITS` (:func:`split_statistics`, whose parameters these are),
    with the parts' own cost; ``progress`` advances once per fit."""
    base = replace(settings or SmootherSettings(), covariances=False, region_bound=False)
    scan_times = measurements.scans().times
    if scan_times.size != np.asarray(times).size:
        raise ValueError(f"{np.asarray(times).size} states for {scan_times.size} scans")
    need = MIN_PART * model.n
    try:
        whole = _fit_cost(measurements, model, states, base, progress)
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        return []
    t0, t1 = float(scan_times[0]), float(scan_times[-1])
    out: list[Split] = []
    for f in SPLITS:
        k = int(np.searchsorted(scan_times, t0 + f * (t1 - t0), side="right")) - 1
        tc = float(scan_times[max(k, 0)])
        first = measurements.time <= tc
        if min(int(first.sum()), int((~first).sum())) < need or (out and out[-1].time == tc):
            continue
        try:
            parts = sum(_fit_cost(measurements.subset(mask), model, states[sel], base, progress)
                        for mask, sel in ((first, scan_times <= tc), (~first, scan_times > tc)))
        except (RuntimeError, ValueError, np.linalg.LinAlgError):
            continue
        out.append(Split(time=tc, statistic=max(whole - parts, 0.0), parts_cost=float(parts),
                         measurements=len(measurements)))
    return out


def split_statistics(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                     settings: SmootherSettings | None = None) -> list[tuple[float, float]]:
    """:math:`D(t_c)` of the module docstring at each of :data:`SPLITS`, as ``(t_c, D)``.

    Parameters
    ----------
    measurements
        The whole recording.
    model
        Its observation and motion model.
    times, states
        The smoother's track, one state per scan of ``measurements``: every
        fit starts there.
    settings
        The smoother's (its loss and iteration cap are used; covariances,
        the zone's prior and wall are not).

    Returns
    -------
    list of (float, float)
        Split time (the last scan of the first part) and statistic, for each
        split whose parts hold enough measurements; a split whose fit fails
        (an indeterminate linear system) is left out.
    """
    return [(x.time, x.statistic) for x in splits(measurements, model, times, states, settings)]


def simulated_scale(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                    settings: SmootherSettings | None = None, *, statistic: float, level: float,
                    offsets: OffsetEstimate | None = None, progress: Progress | None = None
                    ) -> tuple[float, float, float, int]:
    r"""The split statistic's law under the model at this track, read from recordings simulated from it.

    Each replicate is a recording of the null hypothesis, drawn as the
    model says the data arise: a track from the fitted first state with the
    motion model's process noise, and its Doppler at the recording's times
    and pairs with Gaussian noise of their sigma; :func:`splits` runs on it
    from that track, as on the data from the fitted one.  (Not the fitted
    track itself: fitted to a manoeuvre, it bends more than the process
    noise allows, and data drawn about it make the parts disagree as the
    manoeuvre did.)  With :math:`\bar D` and :math:`s` the mean
    and standard deviation of the largest statistic over :math:`B`
    replicates, the scale is the lower two-standard-error bound of the
    Bartlett factor (Rocke 1989, the bootstrap Bartlett correction),

    .. math:: c = \max\Bigl(1,\ \bigl(\bar D - 2 s / \sqrt{B}\bigr) / n\Bigr),

    what the simulation shows for certain of how far the statistic's mean
    exceeds the :math:`\chi^2_n` law's :math:`n`; :math:`D / c` then follows
    :math:`\chi^2_n` more closely (module docstring, "Poorly observed
    parts").  Replicates are drawn until ``statistic`` lies beyond the
    ``level`` scaled by the upper bound (:math:`\bar D + 2 s / \sqrt{B}`)
    or within it scaled by the lower one, from :data:`MIN_REPLICATES` to
    :data:`REPLICATES` of them: a clear answer costs few fits.  Random
    numbers from ``settings.seed``; ``progress`` advances once per fit.

    With ``offsets`` — the calibration offsets at the joint mode of track and
    offsets, of the pairs ``settings.bias_sigma`` declares uncertain — each
    replicate's Doppler carries them, and its statistic is the
    joint one that re-fits them with the parts
    (:func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`), as
    the data's was; ``states`` is then the joint mode's track.

    Returns
    -------
    tuple
        :math:`c`, :math:`\bar D`, its standard error :math:`s / \sqrt{B}`
        and :math:`B` (``(1, nan, nan, B)`` where fewer than two replicates
        could be split).
    """
    settings = settings or SmootherSettings()
    rng = np.random.default_rng([settings.seed, SIMULATION_STREAM])
    t = np.asarray(times, dtype=float)
    x0 = np.asarray(states, dtype=float)[0]
    scan_of = measurements.scans().scan_of
    n_pairs = model.observation.n_channels
    if offsets is not None:
        declared = np.flatnonzero(bias_sigmas(settings.bias_sigma, n_pairs) > 0)
        if not np.array_equal(offsets.pairs, declared):
            raise ValueError(f"offsets of pairs {offsets.pairs.tolist()} where the settings declare pairs "
                             f"{declared.tolist()} uncertain")
    values: list[float] = []
    scale, mean, se = 1.0, float("nan"), float("nan")
    for b in range(1, REPLICATES + 1):
        track = model.motion.sample_track(x0, t - t[0], rng)
        drawn = replace(measurements, doppler=model.observation.predict(track[scan_of], measurements.pair)
                        + measurements.sigma * rng.standard_normal(len(measurements)))
        drawn = drawn if offsets is None else shifted_by(drawn, offsets.full(n_pairs))
        try:
            found = _statistics(drawn, model, t, track, settings, offsets, progress)
        except ValueError:  # a drawn track onto a sensor
            found = []
        if found:
            values.append(max(d for _, d in found))
        if len(values) < 2:
            continue
        mean = float(np.mean(values))
        se = float(np.std(values, ddof=1) / np.sqrt(len(values)))
        scale = max(1.0, (mean - 2.0 * se) / model.n)
        upper = max(1.0, (mean + 2.0 * se) / model.n)
        if b >= MIN_REPLICATES and (statistic > upper * level or statistic <= scale * level):
            return scale, mean, se, b
    return scale, mean, se, REPLICATES


def _statistics(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                settings: SmootherSettings, offsets: OffsetEstimate | None, progress: Progress | None
                ) -> list[tuple[float, float]]:
    """The split statistics ``(t_c, D)`` from the track ``states``: :func:`split_statistics`'s, or with ``offsets``
    the joint ones that re-fit them (:func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`)."""
    if offsets is None:
        return [(x.time, x.statistic) for x in splits(measurements, model, times, states, settings, progress=progress)]
    from fgdoppler.estimators.smoother_offsets import joint_split_statistics

    return joint_split_statistics(measurements, model, settings, times, states, offsets.values, progress=progress)


def manoeuvre_reason(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                     settings: SmootherSettings | None = None, *,
                     joint: JointSolution | None = None, progress: Progress | None = None
                     ) -> Reason | None:
    r"""The ``manoeuvre`` finding (``doubtful``) when the largest :func:`split_statistics` exceeds its level.

    ``None`` when the recording's parts agree with one track (or cannot be
    tested).  Where the statistic exceeds the :math:`\chi^2_n` level, the
    level is scaled by the statistic's law simulated at this track
    (:func:`simulated_scale`); a statistic within the scaled level is an
    ``ok`` finding that says so.  ``states`` should be the most likely track
    (the smoother's optimum), not a posterior mean: the fits start there.
    ``joint``: with calibration offsets declared (``settings.bias_sigma``),
    the joint mode of track and offsets, from which the statistics re-fit the
    offsets with the parts
    (:func:`~fgdoppler.estimators.smoother_offsets.joint_split_statistics`) and
    the simulated recordings carry them; its track then takes the place of
    ``times`` and ``states``.  ``progress`` is told of a task,
    "split test of the motion model", advanced once per fit.
    """
    if joint is not None and settings is None:
        raise ValueError("the split test with offsets needs the settings that declare them (bias_sigma)")
    settings = settings or SmootherSettings()
    offsets = None if joint is None else joint.offsets
    if joint is not None:
        times, states = joint.times, joint.states
    start_task(progress, "split test of the motion model", None)
    if joint is None:
        found = splits(measurements, model, times, states, settings, progress=progress)
        stats = [(x.time, x.statistic) for x in found]
    else:
        found, stats = [], _statistics(measurements, model, times, states, settings, offsets, progress)
    if not stats:
        return None
    tc, d = max(stats, key=lambda s: s[1])
    threshold = float(chi2.ppf(1.0 - (1.0 - LEVEL) / len(SPLITS), model.n))
    if d <= threshold:
        return None
    scaled = ""
    factor, mean, se, drawn = simulated_scale(measurements, model, times, states, settings, statistic=d,
                                             level=threshold, offsets=offsets, progress=progress)
    if factor > 1.0:
        law = (f"{drawn} recordings simulated under the model from the track's start give a split statistic "
               f"of mean {mean:.1f} ± {se:.1f}, not the chi-square law's {model.n}: the parts are observed too "
               "poorly for that law")
        if d <= factor * threshold:
            return Reason(code="manoeuvre", status="ok", message=(
                f"the data up to t = {time_text(tc)} s and after it, each fitted with a track of its own, "
                f"explain the data better than one track by {d:.1f}, beyond the chi-square level "
                f"{threshold:.1f}, but {law}; scaled by {factor:.2f}, the level is {factor * threshold:.1f}, "
                "and the parts agree within it"))
        scaled = f"; and beyond that level scaled by {factor:.2f} to {factor * threshold:.1f}, as {law}"
    q = getattr(model.motion, "q", None)
    shared = f" over {len(SPLITS)} split times" if len(SPLITS) > 1 else ""
    robust = settings.huber_k is not None
    outliers = scale = None
    if not (joint is not None or robust):
        from fgdoppler.estimators.initiation import whitened_residuals

        r = whitened_residuals(model, measurements, states[measurements.scans().scan_of])
        outliers = _outliers_instead(measurements, model, times, states, settings, r)
        scale = _sigma_instead(max(found, key=lambda x: x.statistic), model.n, measurements, model, r)
    return Reason(code="manoeuvre", status="doubtful", message=(
        f"the target does not move as the motion model says: the data up to t = {time_text(tc)} s and after it, "
        f"each fitted with a track of its own, explain the data better than one track by {d:.1f} "
        f"(> {threshold:.1f}, the chi-square level for {model.n} degrees of freedom at "
        f"{LEVEL:.1%}{shared}{scaled}): the target may manoeuvre, and a track that "
        "assumes it does not can lie far from it while fitting its data"
        + (f" (motion model: nearly constant velocity, process noise q = {q:g} m^2/s^3)" if q is not None else "")
        + f"; {NOT_ONLY_A_MANOEUVRE}" + (outliers or "") + (scale or "")))


def _scatter_per_pair(measurements: Measurements, model: TrackingModel, r: FloatArray) -> str:
    r"""Each pair's root-mean-square whitened residual ``r`` (one per measurement), in words: where one pair's
    sigma alone are too small, its scatter stands out (case a 25 km with pair 1's sigma a fifth of the truth's,
    ``tests/estimators/test_manoeuvre.py``: 4.4 against 0.9 for pair 0, where the parts' scatter gives 3.2 for
    both)."""
    from fgdoppler.geometry import pair_labels

    label = pair_labels(model.observation)
    pairs, rms = measurements.rms_per_pair(r)
    return ", ".join(f"pair {label(int(p))} {v:.1f}" for p, v in zip(pairs, rms, strict=True))


def _sigma_instead(split: Split, n: int, measurements: Measurements, model: TrackingModel, r: FloatArray
                   ) -> str | None:
    r"""What the manoeuvre finding adds where stated sigma too small explain the split statistic instead: ``None``
    unless the parts themselves misfit — :math:`C_1 + C_2` above its χ² :data:`LEVEL` quantile on
    :math:`\nu = N - 2n` degrees of freedom — and, against the scatter they show, the split is an ordinary
    draw: :math:`F = (D / n) / ((C_1 + C_2) / \nu)` within the :math:`F(n, \nu)` quantile at
    :data:`SCALE_AGREE_LEVEL`.

    With every sigma :math:`1/s` of the truth, every cost grows about
    :math:`s^2`-fold, :math:`D` with it, and the test fires on a target that
    flies straight; :math:`F` divides the scale out (the F test of a
    likelihood ratio whose noise scale is estimated), and the parts' scatter
    :math:`\sqrt{(C_1 + C_2) / \nu}` estimates :math:`s`.  A manoeuvre
    leaves the parts fitting their own tracks, so :math:`F` stays about
    :math:`D / n` (module docstring, "Sigma too small").  The clause also gives each pair's scatter of the
    track's whitened residuals ``r`` (:func:`_scatter_per_pair`)."""
    dof = split.measurements - 2 * n
    if dof < 1 or split.parts_cost <= float(chi2.ppf(LEVEL, dof)):
        return None
    ratio = split.parts_cost / dof
    f = split.statistic / n / ratio
    agree = float(f_distribution.ppf(SCALE_AGREE_LEVEL, n, dof))
    if f > agree:
        return None
    return (f"; but each part fits its own track only to within about {np.sqrt(ratio):.1f} times the stated sigma "
            f"(the parts' cost {split.parts_cost:.1f} on {dof} degrees of freedom), and against that scatter the parts "
            f"agree (F = {f:.2f}, within the {SCALE_AGREE_LEVEL:.0%} level {agree:.2f} of F({n}, {dof})): the "
            f"measurements' sigma are more likely about {np.sqrt(ratio):.1f} times too small than the target "
            "manoeuvring (the track's residuals, root mean square per pair in sigma: "
            f"{_scatter_per_pair(measurements, model, r)}); {SIGMA_ADVICE}")


def _outliers_instead(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                      settings: SmootherSettings | None, r: FloatArray) -> str | None:
    r"""What the manoeuvre finding adds where a few outliers explain the split statistic instead: ``None`` unless
    the recording has measurements beyond :data:`~fgdoppler.estimators.initiation.OUTLIER_CUT` of the track —
    at most :data:`~fgdoppler.estimators.judge.REJECT_ROBUST` of them — without which the largest :math:`D`
    is an ordinary draw of its law under the model, within the :math:`\chi^2_n` quantile at
    :data:`AGREE_LEVEL` (the alarm's is :data:`LEVEL`).  ``r``: the track's whitened residuals, one per
    measurement.

    A gross error at :math:`r_i` whitened adds up to :math:`r_i^2` to
    :math:`C` and less to :math:`C_1 + C_2`, whose two tracks bend to it
    more freely than one: three 40σ outliers in a recording of case b raise
    :math:`D` to 39.  The statistic is computed again without them (the
    track's states at the scans left); the finding stays ``doubtful``, for
    the data misfit either way, but says which explanation they favour.
    Merely falling below the alarm's level is not enough: on manoeuvring
    random layouts (``studies/manoeuvres.py``'s rule, draws 0–119) the one
    residual of a genuine manoeuvre just beyond the cut (4.0σ, 4.2σ) took
    :math:`D` from above 18.5 to 15 in two of 110 findings."""
    from fgdoppler.estimators.initiation import OUTLIER_CUT
    from fgdoppler.estimators.window_mistakes import few_outliers

    out = few_outliers(r)
    if out is None:
        return None
    kept = measurements.subset(~out)
    left = np.isin(times, kept.scans().times)
    stats = split_statistics(kept, model, times[left], states[left], settings)
    agree = float(chi2.ppf(AGREE_LEVEL, model.n))
    if not stats or max(s[1] for s in stats) > agree:
        return None
    return (f"; but without the {int(out.sum())} measurement{'s' if out.sum() > 1 else ''} beyond "
            f"{OUTLIER_CUT:.2f} sigma of the track the two parts agree ({max(s[1] for s in stats):.1f}, within the "
            f"{AGREE_LEVEL:.0%} level {agree:.1f}): the data more likely hold outliers; if so, track with the Huber "
            "loss (--huber), which down-weights them")
