r"""Doppler measurements: a validated, time-ordered columnar container and its CSV form.

CSV format (one row per measurement)::

    time,pair,doppler,sigma
    0.0,0,-12.25,1.0
    0.0,1,-11.80,1.0

``time`` in seconds, ``pair`` the 0-based index into the geometry, ``doppler``
the bistatic range rate in m/s, ``sigma`` its standard deviation in m/s.  The
``sigma`` column is optional when a default is supplied.  Rows must be in
non-decreasing time order; every problem is reported with the file and line.

A file may instead give the Doppler shift in Hz, ``doppler_hz`` and
``sigma_hz`` (:data:`HZ_HEADER`), when the geometry gives each pair's carrier
wavelength :math:`\lambda`: it is read as ``doppler`` :math:`= -\lambda f_D`
and ``sigma`` :math:`= \lambda \sigma_f`.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._io import atomic_write_text
from fgdoppler.geometry import Geometry

if TYPE_CHECKING:
    from fgdoppler.csvfile import Table

__all__ = ["HEADER", "HZ_HEADER", "MeasurementError", "Measurements", "Scans", "scan_time"]

HEADER = ("time", "pair", "doppler", "sigma")
#: The columns of a file giving the Doppler as a frequency shift in Hz (the geometry gives the wavelengths).
HZ_HEADER = ("time", "pair", "doppler_hz", "sigma_hz")


class MeasurementError(ValueError):
    """Invalid measurement data; the message names the source and the line."""


@dataclass(frozen=True, kw_only=True)
class Scans:
    """Measurements grouped by time: the one scan index every estimator uses.

    A *scan* is the set of measurements that share one time stamp (both pairs
    of the paper's synchronous case (a); a single pair of its staggered
    case (b)).  Rows of scan ``k`` are ``bounds[k]:bounds[k + 1]`` of the
    (time-ordered) measurements.
    """

    times: NDArray[np.float64]
    bounds: NDArray[np.intp]

    def __len__(self) -> int:
        return int(self.times.size)

    def rows(self, k: int) -> slice:
        """Rows of scan ``k``."""
        return slice(int(self.bounds[k]), int(self.bounds[k + 1]))

    @cached_property
    def scan_of(self) -> NDArray[np.intp]:
        """Scan index of every measurement row."""
        return np.repeat(np.arange(len(self), dtype=np.intp), np.diff(self.bounds))

    @cached_property
    def counts(self) -> NDArray[np.intp]:
        """Measurements per scan."""
        return np.diff(self.bounds).astype(np.intp)


@dataclass(frozen=True, kw_only=True)
class Measurements:
    """Time-ordered Doppler measurements, one entry per (time, pair).

    Parameters
    ----------
    time, pair, doppler, sigma
        Equal-length 1-D arrays.  ``time`` must be non-decreasing; entries
        with equal time are ordered by pair.  ``sigma`` must be > 0 and
        every value finite; a (time, pair) combination may occur only once.

    Raises
    ------
    MeasurementError
        On any violation, naming the offending entry.
    """

    time: NDArray[np.float64]
    pair: NDArray[np.intp]
    doppler: NDArray[np.float64]
    sigma: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.asarray(self.time, dtype=float).reshape(-1)
        p_raw = np.asarray(self.pair).reshape(-1)
        z = np.asarray(self.doppler, dtype=float).reshape(-1)
        s = np.asarray(self.sigma, dtype=float).reshape(-1)
        if not (t.size == p_raw.size == z.size == s.size):
            raise MeasurementError(
                f"columns differ in length: time {t.size}, pair {p_raw.size}, "
                f"doppler {z.size}, sigma {s.size}"
            )
        if p_raw.size and not np.all(np.asarray(p_raw, dtype=float) == np.round(np.asarray(p_raw, dtype=float))):
            raise MeasurementError("pair indices must be integers")
        p = np.asarray(p_raw, dtype=np.intp)
        for name, col in (("time", t), ("doppler", z), ("sigma", s)):
            bad = np.flatnonzero(~np.isfinite(col))
            if bad.size:
                raise MeasurementError(f"entry {bad[0]}: {name} is not finite ({col[bad[0]]})")
        bad = np.flatnonzero(s <= 0)
        if bad.size:
            raise MeasurementError(f"entry {bad[0]}: sigma must be > 0, got {s[bad[0]]}")
        for name, col in (("time", t), ("doppler", z), ("sigma", s)):
            lo, hi = LIMITS[name]
            bad = np.flatnonzero((col < lo) | (col > hi))
            if bad.size:
                raise MeasurementError(f"entry {bad[0]}: {name} {col[bad[0]]:g} is outside [{lo:g}, {hi:g}]: "
                                       f"{_limit_text(name, float(col[bad[0]]))}")
        bad = np.flatnonzero(p < 0)
        if bad.size:
            raise MeasurementError(f"entry {bad[0]}: pair index must be >= 0, got {p[bad[0]]}")
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            i = int(back[0]) + 1
            raise MeasurementError(
                f"entry {i}: time {t[i]} is earlier than the previous entry's {t[i - 1]}; "
                "measurements must be in time order"
            )
        order = np.lexsort((p, t))
        t, p, z, s = t[order], p[order], z[order], s[order]
        dup = np.flatnonzero((np.diff(t) == 0) & (np.diff(p) == 0))
        if dup.size:
            i = int(order[dup[0] + 1])
            raise MeasurementError(f"entry {i}: duplicate measurement for time {t[dup[0]]}, pair {p[dup[0]]}")
        for name, col in (("time", t), ("pair", p), ("doppler", z), ("sigma", s)):
            col.setflags(write=False)
            object.__setattr__(self, name, col)

    # -- construction -----------------------------------------------------------
    @classmethod
    def from_arrays(
        cls,
        time: ArrayLike,
        pair: ArrayLike,
        doppler: ArrayLike,
        sigma: ArrayLike | float,
        *,
        sort: bool = False,
    ) -> Measurements:
        """Build from columns; a scalar ``sigma`` applies to all; ``sort=True`` time-sorts first."""
        t = np.asarray(time, dtype=float).reshape(-1)
        s = np.broadcast_to(np.asarray(sigma, dtype=float), t.shape).copy()
        p = np.asarray(pair).reshape(-1)
        z = np.asarray(doppler, dtype=float).reshape(-1)
        if sort and t.size == p.size == z.size:
            order = np.argsort(t, kind="stable")
            t, p, z, s = t[order], p[order], z[order], s[order]
        return cls(time=t, pair=p, doppler=z, sigma=s)

    @classmethod
    def from_scans(cls, times: Sequence[float], pairs: Sequence[ArrayLike], doppler: Sequence[ArrayLike],
                   sigma: Sequence[ArrayLike]) -> Measurements:
        """Build from scans: scan ``k`` at ``times[k]`` holds the measurements ``pairs[k]``, ``doppler[k]``, ``sigma[k]``.

        Scans without measurements add nothing; within a scan the rows are
        put in pair order, as everywhere.
        """
        def column(cols: Sequence[ArrayLike], dtype: type) -> NDArray:
            return np.concatenate([np.asarray(c, dtype=dtype).reshape(-1) for c in cols]) if len(cols) else \
                np.zeros(0, dtype=dtype)

        counts = [np.asarray(p).size for p in pairs]
        return cls(time=np.repeat(np.asarray(times, dtype=float), counts), pair=column(pairs, np.intp),
                   doppler=column(doppler, float), sigma=column(sigma, float))

    def __len__(self) -> int:
        return int(self.time.size)

    def check(self, geometry: Geometry, source: str = "measurements") -> None:
        """Raise :class:`MeasurementError` if a pair index is not in ``geometry``."""
        bad = np.flatnonzero(self.pair >= geometry.n_pairs)
        if bad.size:
            raise MeasurementError(
                f"{source}: entry {bad[0]}: pair index {self.pair[bad[0]]} is not in the geometry "
                f"({geometry.n_pairs} pair(s), indices 0..{geometry.n_pairs - 1})"
            )

    def rms_per_pair(self, values: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        r"""The pairs that reported (ascending) and the root mean square of ``values`` (one per entry) over each
        pair's entries, :math:`\sqrt{\sum_{i \in k} v_i^2 / n_k}`."""
        pairs, at, counts = np.unique(self.pair, return_inverse=True, return_counts=True)
        v = np.asarray(values, dtype=float)
        return pairs, np.sqrt(np.bincount(at, weights=v * v, minlength=pairs.size) / counts)

    def subset(self, mask: ArrayLike) -> Measurements:
        """The entries selected by a boolean mask or index array (order kept)."""
        idx = np.asarray(mask)
        return Measurements(
            time=self.time[idx], pair=self.pair[idx], doppler=self.doppler[idx], sigma=self.sigma[idx]
        )

    def between(self, t_start: float, t_end: float) -> Measurements:
        """Entries with ``t_start <= time <= t_end``."""
        return self.subset((self.time >= t_start) & (self.time <= t_end))

    def first_per_pair(self, n: int) -> Measurements:
        """The first ``n`` measurements of every pair (the paper's initiation batch)."""
        return self.subset(self._first_mask(n, "n"))

    def _first_mask(self, n: int, name: str) -> NDArray[np.bool_]:
        """Which rows are among the first ``n`` of their pair."""
        if n < 1:
            raise ValueError(f"{name} must be >= 1, got {n}")
        keep = np.zeros(len(self), dtype=bool)
        for k in np.unique(self.pair):
            keep[np.flatnonzero(self.pair == k)[:n]] = True
        return keep

    def initiation_window(self, per_pair: int = 10, seconds: float = 4.5) -> Measurements:
        r"""The first ``per_pair`` measurements of every pair and every measurement of the first ``seconds``.

        At the paper's 2 scans/s both give the same window, 10 scans over
        4.5 s.  At faster rates the span in time, not the count, decides how
        well the start is observed: at 20 scans/s, from the first 10
        measurements per pair (0.45 s) the EKF's NEES over t >= 10 s was 17.5
        and its RMSE over t >= 5 s 555 m; from this window (10 per pair and 4.5 s)
        3.6 and 404 m, and the fixed-lag smoother's 2.1 and 335 m against 39.8
        and 500 m (``python studies/high_rate.py``; docs/concepts.md, "High
        scan rates").

        Parameters
        ----------
        per_pair
            Measurements per pair kept at least (>= 1).
        seconds
            Every measurement with :math:`t - t_0 \le` ``seconds`` is kept
            too (:math:`t_0`: the first time); 0 keeps only ``per_pair``.
        """
        if not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"seconds must be a finite number >= 0, got {seconds!r}")
        keep = self._first_mask(per_pair, "per_pair")
        if len(self) and seconds > 0:
            # a relative tolerance so that 0.1-s steps summing to 4.5 s still include the scan at 4.5 s
            keep |= self.time - self.time.min() <= seconds * (1.0 + 1e-9)
        return self.subset(keep)

    def spread(self, per_pair: int) -> Measurements:
        """At most ``per_pair`` measurements of every pair, evenly spread over its record.

        Each pair keeps its first and last measurement and, between them,
        the ones nearest to evenly spaced positions in its own sequence, so a
        staggered schedule still gives every pair its share (taking every
        k-th scan would not).
        """
        if per_pair < 2:
            raise ValueError(f"per_pair must be >= 2, got {per_pair}")
        keep = np.zeros(len(self), dtype=bool)
        for k in np.unique(self.pair):
            rows = np.flatnonzero(self.pair == k)
            pick = np.unique(np.round(np.linspace(0, rows.size - 1, min(per_pair, rows.size))).astype(np.intp))
            keep[rows[pick]] = True
        return self.subset(keep)

    def scans(self) -> Scans:
        """The measurements grouped by time (:class:`Scans`; computed once)."""
        return self._scans

    @cached_property
    def _scans(self) -> Scans:
        times, inverse = np.unique(self.time, return_inverse=True)
        bounds = np.searchsorted(inverse, np.arange(times.size + 1)).astype(np.intp)
        times.setflags(write=False)
        bounds.setflags(write=False)
        return Scans(times=times, bounds=bounds)

    def stacked_order(self) -> NDArray[np.intp]:
        """Permutation that stacks pair 0's entries first, then pair 1's, ... (paper Eq. 11)."""
        return np.lexsort((self.time, self.pair)).astype(np.intp)

    # -- CSV --------------------------------------------------------------------
    def csv_text(self, *, wavelengths: Sequence[float] | None = None) -> str:
        r"""The ``time,pair,doppler,sigma`` CSV as text; values round-trip exactly.

        With ``wavelengths`` (metres, one per pair index, e.g.
        :attr:`Geometry.wavelengths <fgdoppler.geometry.Geometry.wavelengths>`)
        the columns are :data:`HZ_HEADER` instead: the Doppler shift
        :math:`f_D = -\dot r / \lambda` and its sigma :math:`\sigma / \lambda`
        in Hz, which :meth:`from_csv` reads back to within rounding.
        """
        if wavelengths is None:
            header, doppler, sigma = HEADER, self.doppler, self.sigma
        else:
            lam = np.asarray(wavelengths, dtype=float)
            if lam.ndim != 1 or lam.size <= int(self.pair.max(initial=-1)) or not np.all(lam > 0):
                raise ValueError(f"wavelengths must be positive numbers, one for each pair 0..{int(self.pair.max())}, "
                                 f"got {wavelengths!r}")
            header, doppler, sigma = HZ_HEADER, -self.doppler / lam[self.pair], self.sigma / lam[self.pair]
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(header)
        for t, p, z, s in zip(self.time, self.pair, doppler, sigma, strict=True):
            w.writerow((repr(float(t)), int(p), repr(float(z)), repr(float(s))))
        return buf.getvalue()

    def to_csv(self, path: str | Path, *, wavelengths: Sequence[float] | None = None) -> None:
        """Write :meth:`csv_text` atomically."""
        atomic_write_text(Path(path), self.csv_text(wavelengths=wavelengths))

    @classmethod
    def from_csv(
        cls,
        path: str | Path,
        *,
        geometry: Geometry | None = None,
        default_sigma: float | None = None,
        ignore_columns: Sequence[str] = (),
    ) -> Measurements:
        r"""Read and validate a measurement CSV (:mod:`fgdoppler.csvfile` reads it strictly and boundedly).

        Parameters
        ----------
        path
            The file: columns :data:`HEADER` (``sigma`` optional), or
            :data:`HZ_HEADER` (``sigma_hz`` optional) for a Doppler shift in Hz.
        geometry
            If given, pair indices are checked against it, and a pair may be
            given by its name (:attr:`~fgdoppler.geometry.Geometry.pair_names`)
            instead of its index.  A file in Hz needs it, with every pair's
            :attr:`~fgdoppler.geometry.Geometry.wavelengths`.
        default_sigma
            Used when the file has no ``sigma`` (or ``sigma_hz``) column
            (required then), in the unit of its Doppler column: m/s, or Hz
            for ``doppler_hz``.
        ignore_columns
            Columns to skip where the file has them (another tool's extras,
            e.g. ``("snr",)``); any other column not above is refused, so
            that a misspelt ``sigma`` is never dropped unseen.

        Raises
        ------
        ValueError
            If ``ignore_columns`` names a column read here (``time``, ``pair``,
            ``doppler``, ``sigma`` or their Hz names).
        MeasurementError
            Naming the file, the line and the problem: unreadable or not text,
            missing or bad header, wrong number of fields, an empty or
            non-numeric field, a value outside :data:`LIMITS`, a non-integer
            or unknown pair index, a time earlier than the previous row *of the
            same pair*, a duplicated (time, pair), or no data rows; a file in
            Hz without the wavelengths to read it.

        Notes
        -----
        Each pair's rows must be in time order, but the pairs may interleave
        in any way: a file of one receiver's rows after another's, or rows
        appended as each sensor reports, is read as the same measurements,
        sorted by (time, pair).  A time that goes back within one pair is a
        clock jump or two recordings run together, and is refused.

        A Doppler shift :math:`f_D` (Hz, positive for a target closing on
        the pair) of a carrier of wavelength :math:`\lambda` is the bistatic
        range rate :math:`\dot r_T + \dot r_R = -\lambda f_D`, and its
        standard deviation :math:`\sigma_f` is :math:`\lambda \sigma_f` in m/s.
        """
        from fgdoppler.csvfile import CSVError, read_table

        path = Path(path)
        try:
            names = {} if geometry is None else {v: float(i) for i, v in enumerate(geometry.pair_names)}
            table = read_table(path, header=HEADER[:3], optional=HEADER[3:], what="measurement file",
                               labels={"pair": names} if names else None, layout=_layout,
                               ignore=_ignored(ignore_columns))
        except CSVError as exc:
            raise MeasurementError(str(exc)) from None
        hz = "doppler_hz" in table.header
        columns = HZ_HEADER if hz else HEADER
        if hz:
            _check_wavelengths(path, geometry)
        if table.values.shape[1] == 3:
            if default_sigma is None:
                raise MeasurementError(f"{path}: no {columns[3]} column and no default sigma given "
                                       f"(pass --sigma or add a {columns[3]} column)")
            _check_value(default_sigma, "sigma", f"{path}: default sigma")
        n = table.values.shape[0]
        t, z = table.values[:, 0], table.values[:, 2]
        s = table.values[:, 3] if table.values.shape[1] == 4 else np.full(n, float(default_sigma))  # type: ignore[arg-type]
        p = _checked_rows(table, t, z, s, geometry, hz)
        return cls.from_arrays(t, p, z, s, sort=True)


def _ignored(columns: Sequence[str]) -> tuple[str, ...]:
    """The column names to skip (one name may be given as a string), none of them a column a measurement file is
    read by in either layout (:func:`~fgdoppler.csvfile.skipped_columns`; :class:`ValueError` otherwise)."""
    from fgdoppler.csvfile import skipped_columns

    return skipped_columns((columns,) if isinstance(columns, str) else tuple(columns), (*HEADER, *HZ_HEADER),
                           "measurement file")


#: How a value read from a file in Hz is named in a message: what it was converted from.
_FROM_HZ = {"doppler": "doppler (-wavelength * doppler_hz)", "sigma": "sigma (wavelength * sigma_hz)"}

#: Physical bounds of every value (inclusive): a time beyond 30,000 years, a bistatic range rate
#: above twice the speed of light or a sigma outside 1 µm/s .. 1,000 km/s is a corrupt or mis-scaled file.
LIMITS: dict[str, tuple[float, float]] = {"time": (-1e12, 1e12), "doppler": (-6e8, 6e8), "sigma": (1e-6, 1e6)}

#: Units of a time beyond :data:`LIMITS`, each with the factor to seconds, from the largest: a Unix time now
#: (1.8e9 s) is 1.8e12 in milliseconds, 1.8e15 in microseconds and 1.8e18 in nanoseconds.
_SUBSECOND = (("nanoseconds", 1e9), ("microseconds", 1e6), ("milliseconds", 1e3))


def scan_time(t: float, previous: float | None) -> float:
    """``t`` as a float, checked as the time of a live feed's next scan after one at ``previous`` (``None``:
    the first).

    Raises
    ------
    ValueError
        If ``t`` is not a finite number, or not after ``previous`` (out of order).
    """
    t = float(t)
    if not math.isfinite(t):
        raise ValueError(f"scan time {t} is not a finite number")
    if previous is not None and not t > previous:
        raise ValueError(f"scan at t = {t} is not after the previous scan at t = {previous}: out of order")
    return t


def _limit_text(name: str, value: float) -> str:
    """Why ``value`` of column ``name`` is beyond :data:`LIMITS`: for a time that is a Unix time in a finer unit
    than seconds, which unit and what to divide by; else a corrupt or mis-scaled value."""
    if name == "time":
        for unit, factor in _SUBSECOND:
            if 1e8 < value / factor < 1e10:  # 1973 to 2286 in that unit
                return (f"likely a Unix time in {unit} where fgdoppler reads seconds: divide the time column "
                        f"by {factor:,.0f}")
    return "a corrupt or mis-scaled value"


def _check_value(value: float, name: str, where: str, shown: str | None = None) -> None:
    lo, hi = LIMITS[name]
    if not (math.isfinite(value) and lo <= value <= hi):
        if name == "sigma" and value <= 0:
            raise MeasurementError(f"{where}: sigma must be > 0, got {value}")
        raise MeasurementError(f"{where}: {shown or name} {value:g} is outside [{lo:g}, {hi:g}]: "
                               f"{_limit_text(name, value)}")


def _pair(value: float, where: str, geometry: Geometry | None, one_based: bool = False) -> int:
    if value != int(value) or value < 0:
        raise MeasurementError(f"{where}: pair must be a non-negative integer, got {value:g}")
    k = int(value)
    if geometry is not None and k >= geometry.n_pairs:
        hint = (f"; the file numbers its pairs 1..{geometry.n_pairs}: fgdoppler numbers them from 0 in the "
                "geometry's order, so subtract 1 if that is what they mean") if one_based else ""
        raise MeasurementError(f"{where}: unknown pair index {k}: the geometry has {geometry.n_pairs} "
                               f"pair(s), indices 0..{geometry.n_pairs - 1}{hint}")
    return k


def _numbered_from_one(column: NDArray[np.float64], geometry: Geometry | None) -> bool:
    """Whether a file's pair column holds whole numbers 1..P exactly, for the P pairs of ``geometry``, each at least
    once: likely numbered from 1 where fgdoppler numbers from 0."""
    if geometry is None or not bool(np.all(np.isfinite(column) & (column == np.floor(column)))):
        return False
    return set(np.unique(column).astype(int).tolist()) == set(range(1, geometry.n_pairs + 1))


def _checked_rows(table: Table, t: NDArray[np.float64], z: NDArray[np.float64], s: NDArray[np.float64],
                  geometry: Geometry | None, hz: bool) -> NDArray[np.intp]:
    """Each row's pair index, every value checked (a file in Hz converted in ``z`` and ``s`` in place)."""
    p = _valid_pairs(table, t, z, s, geometry, hz)
    if p is not None:
        return p
    n = t.size
    p = np.empty(n, dtype=np.intp)
    seen: dict[tuple[float, int], int] = {}
    last: dict[int, int] = {}  # pair -> its latest row
    one_based = _numbered_from_one(table.values[:, 1], geometry)
    for j in range(n):
        where = table.where(j)
        p[j] = _pair(table.values[j, 1], where, geometry, one_based)
        if hz:
            z[j], s[j] = _from_hz(z[j], s[j], geometry.wavelengths[p[j]], where)  # type: ignore[union-attr]
        for name, value in (("time", t[j]), ("doppler", z[j]), ("sigma", s[j])):
            _check_value(value, name, where, _FROM_HZ.get(name) if hz else None)
        prev = last.get(int(p[j]))
        if prev is not None and t[j] < t[prev]:
            raise MeasurementError(f"{where}: time {t[j]} is earlier than pair {p[j]}'s previous row's "
                                   f"{t[prev]} (line {table.lines[prev]}); each pair's rows must be "
                                   "in time order")
        last[int(p[j])] = j
        key = (float(t[j]), int(p[j]))
        if key in seen:
            raise MeasurementError(f"{where}: duplicate measurement for time {t[j]}, pair {p[j]} "
                                   f"(first at line {seen[key]})")
        seen[key] = int(table.lines[j])
    return p


def _valid_pairs(table: Table, t: NDArray[np.float64], z: NDArray[np.float64], s: NDArray[np.float64],
                 geometry: Geometry | None, hz: bool) -> NDArray[np.intp] | None:
    """:func:`_checked_rows` for the whole file at once where it finds nothing wrong; ``None`` (``z`` and ``s``
    untouched) where any row fails a check, so that the row-by-row loop names the first one."""
    v = table.values[:, 1]
    top = geometry.n_pairs if geometry is not None else 2**31
    if not bool(np.all((v >= 0) & (v < top) & (v == np.floor(v)))):
        return None
    p = v.astype(np.intp)
    zc, sc = z, s
    if hz:
        if not bool(np.all(s > 0)):
            return None
        wavelength = np.asarray(geometry.wavelengths, dtype=float)[p]  # type: ignore[union-attr]
        zc, sc = -wavelength * z, wavelength * s
    for name, value in (("time", t), ("doppler", zc), ("sigma", sc)):
        lo, hi = LIMITS[name]
        if not bool(np.all(np.isfinite(value) & (value >= lo) & (value <= hi))):
            return None
    # each pair's rows in file order: its times must not go back, and an equal time is a duplicate
    order = np.lexsort((np.arange(t.size), p))
    same = p[order][1:] == p[order][:-1]
    if bool(np.any(same & (np.diff(t[order]) <= 0.0))):
        return None
    if hz:
        z[:], s[:] = zc, sc
    return p


def _layout(names: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The columns of a measurement file whose header holds ``names``: in Hz where they hold ``doppler_hz``."""
    columns = HZ_HEADER if "doppler_hz" in names else HEADER
    return columns[:3], columns[3:]


def _check_wavelengths(path: Path, geometry: Geometry | None) -> None:
    """Refuse a file in Hz that its geometry gives no wavelengths to read."""
    if geometry is None or not geometry.wavelengths:
        raise MeasurementError(
            f"{path}: the doppler_hz column is a Doppler shift in Hz, and reading it as the bistatic range rate "
            "(doppler = -wavelength * doppler_hz) needs each pair's carrier wavelength: "
            + ("pass the geometry, with its wavelengths" if geometry is None else
               "give `wavelength` (metres, c / f_c) in every [[pair]] table of the geometry file"))


def _from_hz(shift: float, sigma: float, wavelength: float, where: str) -> tuple[float, float]:
    """A Doppler shift and its sigma (Hz; finite, as the CSV reader returns them) as the bistatic range rate and its
    sigma (m/s)."""
    if sigma <= 0:
        raise MeasurementError(f"{where}: sigma_hz must be > 0, got {sigma:g}")
    return -wavelength * shift, wavelength * sigma
