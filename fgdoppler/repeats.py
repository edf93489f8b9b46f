r"""Repeated values in a pair's Doppler: a receiver that holds its last value, or writes a fixed one, when it has
no detection.

A Doppler measurement carries noise of standard deviation :math:`\sigma`, so two successive measurements of a
pair are equal only where the file rounds them to a coarse resolution :math:`q`.  For two values each the truth
plus :math:`\mathcal N(0, \sigma^2)` noise, rounded to a grid of step :math:`q` whose offset is arbitrary, the
chance that both fall in one cell is, with :math:`D` their difference (:math:`\mathcal N(0, 2\sigma^2)`) and
:math:`a = q / (\sigma\sqrt 2)`,

.. math::

    p(a) = \mathrm E\left[\max\left(0, 1 - \frac{|D|}{q}\right)\right]
         = \operatorname{erf}\frac{a}{\sqrt 2} - \frac{2\,\varphi(0)}{a}\left(1 - e^{-a^2/2}\right),

:math:`a\,\varphi(0) = q / (2\sigma\sqrt\pi)` for a fine grid.  The truth's own change between the two
measurements only lowers it, so :math:`p` bounds the chance from above.  Of a pair's :math:`n` measurements in
time order, the number :math:`m` equal to the one before is then at most Binomial(:math:`n - 1, p`) by chance,
and the pair is *found repeating* where :math:`P(M \ge m)` is below :math:`(1 - \text{level}) / 2P` for the
:math:`P` pairs tested (:func:`find_repeats`).

A receiver that writes a fixed value (say 0) in its gaps between real measurements repeats it, not always in a
row.  Any one measurement takes a given value of the grid with chance at most
:math:`c = 2\Phi(q / 2\sigma) - 1`, that of the cell about its mean whatever the truth, so the chance that some
value comes :math:`k` or more times among :math:`n` is at most
:math:`n\,P(\text{Binomial}(n - 1, c) \ge k - 1)` (the union over which measurement first takes it); counted
as the runs of one value it starts (a held run once), the bound holds all the more.  Where that is below the same
bound the value is *fixed*, no measurement wherever it stands; so is the value of a pair that gives one value
throughout.

Neither :math:`q` nor the noise is taken on trust, so that right data are not called repeating:

- :math:`q` is the step of the grid the pair's values lie on (:func:`grid_step`: the smallest gap between its
  distinct values divided by the smallest whole number that puts the gaps on the grid), or, for values
  written to full precision, that gap over :data:`GRID_DIVISORS`: coarser than their true resolution, which
  only makes the test conservative; a pair with one value throughout takes :math:`q = \sigma` (the
  coarsest resolution tested);
- :math:`\sigma` is the smaller of the stated sigma (root mean square over the pair) and the scatter of the
  pair's steps, :math:`\sqrt{(\overline{\Delta z^2} - q^2/6)/2}` (a step of two rounded values has variance
  :math:`2\sigma^2 + q^2/6`; the truth's own change only adds to it, and lowers the chance of a repeat more
  than that raises :math:`\sigma`): stated sigma too large would otherwise make a coarse grid's repeats look
  unlikely.  Where every step is zero the stated sigma stands;
- a pair whose resolution is coarser than that :math:`\sigma` (:math:`q > \sigma`) is not tested: its values
  repeat whenever the truth moves less than a grid step.

The same grid tells how much noise the file's rounding adds: a value rounded to a step :math:`q` carries an
error uniform over :math:`\pm q/2`, of variance :math:`q^2/12`, that a sigma stated for the receiver alone leaves
out (:func:`coarse_rounding`).

Under continuous noise written to full precision equal successive values do not occur; on the paper's six
scenarios no pair is found repeating.  ``python studies/repeats_test.py`` measures the false alarms on right data
rounded to grids of up to one sigma and the power against held and fixed values (docs/concepts.md, the verdict
table's ``data`` row).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import erf
from scipy.stats import binom, norm

from fgdoppler.measurements import Measurements

__all__ = ["GRID_DIVISORS", "GRID_GAPS", "GRID_TOLERANCE", "Repeats", "Rounding", "coarse_rounding", "drop_repeats",
           "find_repeats", "grid_step", "repeat_probability"]

FloatArray = NDArray[np.float64]

_PHI0 = 1.0 / np.sqrt(2.0 * np.pi)

#: The finest grid :func:`grid_step` looks for: a pair's smallest gap divided by up to this.
GRID_DIVISORS = 1000
#: How near a whole number each gap over a grid step must be for the values to lie on that grid.
GRID_TOLERANCE = 1e-6
#: How many of the smallest gaps :func:`grid_step` checks.
GRID_GAPS = 256


@dataclass(frozen=True, kw_only=True)
class Repeats:
    """A pair found repeating its values (:func:`find_repeats`).

    Attributes
    ----------
    pair
        The pair's index.
    measurements
        Its measurements.
    repeats
        How many of them equal the one before (the pair's, in time order).
    chance
        The chance of at least that many by noise, :math:`P(M \\ge m)` (module docstring).
    resolution
        The resolution :math:`q` the test took (m/s); ``None`` where the pair has one value throughout
        (then :math:`q = \\sigma`).
    sigma
        The noise :math:`\\sigma` the test took (m/s).
    longest, value, start, end
        The longest run of one value: its measurements, the value (m/s), its first and last time (s).
    fixed, fixed_count, fixed_chance
        The value that starts more of the pair's runs than noise allows, or the pair's one value throughout (a
        fixed value written without a detection; ``None`` where neither), how many runs its most frequent value
        starts, and the chance of that by noise (bounded above, module docstring).
    rows
        The indices in the measurements of what :func:`drop_repeats` leaves out: the repeats (each a
        measurement equal to the one before) and every measurement of the fixed value.
    """

    pair: int
    measurements: int
    repeats: int
    chance: float
    resolution: float | None
    sigma: float
    longest: int
    value: float
    start: float
    end: float
    fixed: float | None
    fixed_count: int
    fixed_chance: float
    rows: NDArray[np.intp] = field(repr=False, compare=False)


def repeat_probability(a: ArrayLike) -> FloatArray:
    r"""The chance :math:`p(a)` that two noisy values fall in one cell of a grid (module docstring), for
    :math:`a = q / (\sigma\sqrt 2) > 0`.

    Examples
    --------
    >>> round(float(repeat_probability(1e-6) / (1e-6 / np.sqrt(2 * np.pi))), 9)  # a phi(0) for a fine grid
    1.0
    """
    a = np.asarray(a, dtype=float)
    # expm1 keeps the second term accurate for a fine grid, where it is -a phi(0) against erf's 2 a phi(0)
    return np.asarray(erf(a / np.sqrt(2.0)) + 2.0 * _PHI0 * np.expm1(-0.5 * a * a) / a, dtype=float)


def find_repeats(measurements: Measurements, *, level: float = 0.999) -> tuple[Repeats, ...]:
    """The pairs of ``measurements`` that repeat their values more often than noise on their resolution allows
    (module docstring: in a row, or one value anywhere), in the order of their indices.

    Parameters
    ----------
    measurements
        Any measurements.
    level
        The tests' level for the whole recording (Bonferroni over the pairs tested and the two tests): right data
        are found repeating at most ``1 - level`` of the time.
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level:g}")
    m = measurements
    if len(m) < 2:
        return ()
    pairs, idx, counts = np.unique(m.pair, return_inverse=True, return_counts=True)
    order = np.lexsort((m.time, idx))  # each pair's measurements together, in time order
    i, z = idx[order], m.doppler[order]
    same = i[1:] == i[:-1]
    step = np.diff(z)
    equal = same & (step == 0.0)
    k = pairs.size
    repeats = np.bincount(i[1:][equal], minlength=k)
    resolution = _resolution(idx, m.doppler, k)
    q, sigma = _grid_and_noise(m, i, step, same, resolution)
    tested = (q <= sigma) & (counts > 1)
    bound = (1.0 - level) / (2 * max(int(tested.sum()), 1))
    chance = np.where(repeats > 0, binom.sf(repeats - 1, counts - 1, repeat_probability(q / (sigma * np.sqrt(2.0)))),
                      1.0)
    modal, value = _modal(i, z, k)
    # any one measurement takes a given value of the grid with chance at most that of the cell about its mean; the
    # union over which measurement first takes the value bounds the chance that some value starts that many runs
    cell = 2.0 * norm.cdf(q / (2.0 * sigma)) - 1.0
    recurs = np.minimum(counts * binom.sf(modal - 2, counts - 1, cell), 1.0)
    constant = ~np.isfinite(resolution)
    out = []
    for j in np.flatnonzero(tested & ((chance < bound) | (recurs < bound))):
        # a pair with one value throughout has no measurement to tell from that value either
        fixed = recurs[j] < bound or constant[j]
        rows = order[1:][equal & (i[1:] == j)]
        if fixed:  # a fixed value written without a detection is no measurement wherever it stands
            rows = np.union1d(rows, np.flatnonzero((m.pair == pairs[j]) & (m.doppler == value[j])))
        longest, run_value, start, end = _longest_run(m, order[i == j])
        out.append(Repeats(pair=int(pairs[j]), measurements=int(counts[j]), repeats=int(repeats[j]),
                           chance=float(chance[j]),
                           resolution=float(resolution[j]) if np.isfinite(resolution[j]) else None,
                           sigma=float(sigma[j]), longest=longest, value=run_value, start=start, end=end,
                           fixed=float(value[j]) if fixed else None, fixed_count=int(modal[j]),
                           fixed_chance=float(recurs[j]), rows=np.sort(rows)))
    return tuple(out)


def _grid_and_noise(m: Measurements, i: NDArray[np.intp], step: FloatArray, same: NDArray[np.bool_],
                    resolution: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each pair's grid step :math:`q` and noise :math:`\\sigma` as the tests take them (module docstring)."""
    k = resolution.size
    stated = m.rms_per_pair(m.sigma)[1]
    # each step is the difference of two rounded noisy values: variance 2 sigma^2 + q^2 / 6 (Sheppard)
    n_steps = np.bincount(i[1:][same], minlength=k)
    step_ms = np.bincount(i[1:][same], weights=step[same] ** 2, minlength=k) / np.maximum(n_steps, 1)
    finite_q = np.where(np.isfinite(resolution), resolution, 0.0)
    scatter = np.sqrt(np.maximum(step_ms - finite_q ** 2 / 6.0, 0.0) / 2.0)
    sigma = np.where(scatter > 0.0, np.minimum(stated, scatter), stated)
    return np.where(np.isfinite(resolution), resolution, sigma), sigma


def _modal(i: NDArray[np.intp], z: FloatArray, k: int) -> tuple[NDArray[np.intp], FloatArray]:
    """Each of ``k`` pairs' value that starts the most runs (``i``, ``z``: the pairs' measurements each in time
    order) and how many it starts (the largest value among equals): a held run counts once."""
    first = np.r_[True, (i[1:] != i[:-1]) | (z[1:] != z[:-1])]
    ir, zr = i[first], z[first]
    order = np.lexsort((zr, ir))
    ir, zr = ir[order], zr[order]
    starts = np.flatnonzero(np.r_[True, (ir[1:] != ir[:-1]) | (zr[1:] != zr[:-1])])
    runs = np.diff(np.r_[starts, zr.size])
    count = np.zeros(k, dtype=np.intp)
    np.maximum.at(count, ir[starts], runs)
    best = runs == count[ir[starts]]
    value = np.full(k, np.nan)
    value[ir[starts][best]] = zr[starts][best]
    return count, value


@dataclass(frozen=True, kw_only=True)
class Rounding:
    """A pair whose values lie on a grid coarse against its sigma (:func:`coarse_rounding`).

    Attributes
    ----------
    pair
        The pair's index.
    step
        The grid's step :math:`q` (m/s, :func:`grid_step`).
    sigma
        The pair's stated sigma (root mean square, m/s).
    with_rounding
        :math:`\\sqrt{\\sigma^2 + q^2/12}`: the sigma with the rounding's noise in it (m/s).
    """

    pair: int
    step: float
    sigma: float
    with_rounding: float


def coarse_rounding(measurements: Measurements, *, share: float = 0.05) -> tuple[Rounding, ...]:
    r"""The pairs whose values lie on a grid so coarse that rounding adds at least ``share`` of the stated
    variance: a value rounded to a step :math:`q` carries a rounding error uniform over :math:`\pm q/2`, of
    variance :math:`q^2/12`, which a sigma stated for the receiver's noise alone leaves out (a grid of two sigma
    adds a third to the variance, and the whole-track χ² test of a long recording fails by that).

    Values written to full precision lie on no grid (:func:`grid_step` then bounds the step far below sigma).
    """
    m = measurements
    pairs, idx = np.unique(m.pair, return_inverse=True)
    q = _resolution(idx, m.doppler, pairs.size)
    sigma = m.rms_per_pair(m.sigma)[1]
    coarse = np.isfinite(q) & (q ** 2 / 12.0 >= share * sigma ** 2)
    return tuple(Rounding(pair=int(pairs[j]), step=float(q[j]), sigma=float(sigma[j]),
                          with_rounding=float(np.sqrt(sigma[j] ** 2 + q[j] ** 2 / 12.0)))
                 for j in np.flatnonzero(coarse))


def _resolution(idx: NDArray[np.intp], z: FloatArray, k: int) -> FloatArray:
    """Each of ``k`` pairs' resolution (:func:`grid_step` of the gaps between its distinct values; ``inf`` for one
    value throughout)."""
    order = np.lexsort((z, idx))
    i, zs = idx[order], z[order]
    gap = np.diff(zs)
    ok = (i[1:] == i[:-1]) & (gap > 0.0)
    out = np.full(k, np.inf)
    scale = float(np.max(np.abs(z))) if z.size else 0.0
    for j in np.unique(i[1:][ok]):
        out[j] = grid_step(gap[ok & (i[1:] == j)], scale)
    return out


def grid_step(gaps: ArrayLike, scale: float = 0.0) -> float:
    r"""The step of the grid that values with these ``gaps`` between them (sorted distinct values, all > 0) were
    rounded to: the largest :math:`g_{\min}/j`, :math:`j \le` :data:`GRID_DIVISORS`, that every gap (the
    :data:`GRID_GAPS` smallest) is a whole multiple of (to :data:`GRID_TOLERANCE`, and the float rounding of values
    up to ``scale``); where there is none,
    :math:`g_{\min}/` :data:`GRID_DIVISORS`, no finer than any grid the values may lie on.

    Every gap of values on a grid is a whole multiple of its step, the smallest too, so the step is
    :math:`g_{\min}/j` for a whole :math:`j`.  Values written to full precision lie on no grid, and the bound
    only makes the test conservative.

    Examples
    --------
    >>> grid_step(np.array([0.3, 0.1, 1.2])), grid_step(np.array([0.2, 0.3]))
    (0.1, 0.1)
    """
    # A grid puts every gap on it, so any of them may be checked; the smallest few hundred settle it (values on no
    # grid pass by chance with odds of GRID_TOLERANCE to that power) at a fixed cost on long recordings.
    g = np.sort(np.asarray(gaps, dtype=float).reshape(-1))[:GRID_GAPS]
    g0 = float(g[0])
    j = np.arange(1, GRID_DIVISORS + 1)
    # a gap of two values each rounded once is off its multiple by a few units in the last place of the values
    tol = GRID_TOLERANCE + 8.0 * np.finfo(float).eps * scale * j / g0

    def on_grid(part: FloatArray, js: NDArray[np.int64], tols: FloatArray) -> NDArray[np.bool_]:
        ratio = part[:, None] * js[None, :] / g0
        return np.asarray(np.all(np.abs(ratio - np.rint(ratio)) <= tols[None, :], axis=0))

    # the few smallest gaps leave almost no divisor standing on values that lie on no grid; the rest confirm
    candidates = np.flatnonzero(on_grid(g[:8], j, tol))
    for c in candidates:
        if on_grid(g, j[c:c + 1], tol[c:c + 1])[0]:
            return g0 / float(j[c])
    return g0 / GRID_DIVISORS


def _longest_run(m: Measurements, rows: NDArray[np.intp]) -> tuple[int, float, float, float]:
    """The longest run of one value among a pair's ``rows`` (in time order): its length, value, first and last
    time."""
    z = m.doppler[rows]
    starts = np.flatnonzero(np.r_[True, z[1:] != z[:-1]])
    lengths = np.diff(np.r_[starts, z.size])
    j = int(np.argmax(lengths))
    first, last = rows[starts[j]], rows[starts[j] + lengths[j] - 1]
    return int(lengths[j]), float(z[starts[j]]), float(m.time[first]), float(m.time[last])


def drop_repeats(measurements: Measurements, found: tuple[Repeats, ...] | None = None) -> Measurements:
    """``measurements`` without the repeats of the pairs found repeating (``found``, else :func:`find_repeats`
    at its default level): of each run of one value the first measurement stays (the value a receiver holds was
    measured once), and every measurement of a value found fixed goes (a dead receiver's value throughout, or
    one written in many of the gaps).

    A fixed value that comes too seldom to be found stays: a gross outlier, for the gate or the Huber loss
    (``--huber``).
    """
    found = find_repeats(measurements) if found is None else found
    keep = np.ones(len(measurements), dtype=bool)
    for r in found:
        keep[r.rows] = False
    return measurements.subset(keep)
