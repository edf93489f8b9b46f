"""Doppler measurements: a validated, time-ordered columnar container and its CSV form.

CSV format (one row per measurement)::

    time,pair,doppler,sigma
    0.0,0,-12.25,1.0
    0.0,1,-11.80,1.0

``time`` in seconds, ``pair`` the 0-based index into the geometry, ``doppler``
the bistatic range rate in m/s, ``sigma`` its standard deviation in m/s.  The
``sigma`` column is optional when a default is supplied.  Rows must be in
non-decreasing time order; every problem is reported with the file and line.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler._io import atomic_open
from fgdoppler.geometry import Geometry

__all__ = ["MeasurementError", "Measurements", "Scans"]

HEADER = ("time", "pair", "doppler", "sigma")


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
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        keep = np.zeros(len(self), dtype=bool)
        for k in np.unique(self.pair):
            keep[np.flatnonzero(self.pair == k)[:n]] = True
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
    def to_csv(self, path: str | Path) -> None:
        """Write ``time,pair,doppler,sigma`` atomically; values round-trip exactly."""
        with atomic_open(Path(path)) as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(HEADER)
            for t, p, z, s in zip(self.time, self.pair, self.doppler, self.sigma, strict=True):
                w.writerow((repr(float(t)), int(p), repr(float(z)), repr(float(s))))

    @classmethod
    def from_csv(
        cls,
        path: str | Path,
        *,
        geometry: Geometry | None = None,
        default_sigma: float | None = None,
    ) -> Measurements:
        """Read and validate a measurement CSV.

        Parameters
        ----------
        path
            The file.
        geometry
            If given, pair indices are checked against it.
        default_sigma
            Used when the file has no ``sigma`` column (required then).

        Raises
        ------
        MeasurementError
            Naming the file, the line and the problem: missing or bad header,
            wrong number of fields, a non-numeric or non-finite value, a
            non-integer or unknown pair index, sigma <= 0, a time earlier than
            the previous row's, a duplicated (time, pair), or no data rows.
        """
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise MeasurementError(f"{path}: cannot read: {exc.strerror or exc}") from exc
        rows = list(csv.reader(text.splitlines()))
        # Blank lines are tolerated (e.g. a trailing newline); line numbers stay 1-based.
        numbered = [(i + 1, r) for i, r in enumerate(rows) if r and any(c.strip() for c in r)]
        if not numbered:
            raise MeasurementError(f"{path}: empty file: expected the header {','.join(HEADER)}")
        has_sigma = _header(path, *numbered[0], default_sigma)
        data = numbered[1:]
        if not data:
            raise MeasurementError(f"{path}: no measurement rows after the header")
        n = len(data)
        t = np.empty(n)
        p = np.empty(n, dtype=np.intp)
        z = np.empty(n)
        s = np.empty(n)
        seen: dict[tuple[float, int], int] = {}
        for j, (line, row) in enumerate(data):
            where = f"{path}:{line}"
            tv, pv, zv, sv = _row(where, row, has_sigma, default_sigma, geometry)
            if j and tv < t[j - 1]:
                raise MeasurementError(
                    f"{where}: time {tv} is earlier than the previous row's {t[j - 1]}; "
                    "rows must be in time order"
                )
            if (tv, pv) in seen:
                raise MeasurementError(
                    f"{where}: duplicate measurement for time {tv}, pair {pv} (first at line {seen[(tv, pv)]})"
                )
            seen[(tv, pv)] = line
            t[j], p[j], z[j], s[j] = tv, pv, zv, sv
        return cls(time=t, pair=p, doppler=z, sigma=s)


def _header(path: Path, line: int, header: list[str], default_sigma: float | None) -> bool:
    """Check the header row; True if it has a sigma column."""
    names = [h.strip().lower() for h in header]
    if names == list(HEADER):
        return True
    if names != list(HEADER[:3]):
        raise MeasurementError(
            f"{path}:{line}: bad header {','.join(names)!r}: expected {','.join(HEADER)!r} (sigma optional)"
        )
    if default_sigma is None:
        raise MeasurementError(
            f"{path}:{line}: no sigma column and no default sigma given (pass --sigma or add a sigma column)"
        )
    if not (math.isfinite(default_sigma) and default_sigma > 0):
        raise MeasurementError(f"{path}: default sigma must be finite and > 0, got {default_sigma}")
    return False


def _row(where: str, row: list[str], has_sigma: bool, default_sigma: float | None,
         geometry: Geometry | None) -> tuple[float, int, float, float]:
    """One data row as ``(time, pair, doppler, sigma)``, checked on its own."""
    ncol = 4 if has_sigma else 3
    if len(row) != ncol:
        raise MeasurementError(f"{where}: expected {ncol} fields, got {len(row)}")
    vals = []
    for name, cell in zip(HEADER, row, strict=False):
        try:
            v = float(cell)
        except ValueError:
            raise MeasurementError(f"{where}: {name} is not a number: {cell.strip()!r}") from None
        if not math.isfinite(v):
            raise MeasurementError(f"{where}: {name} is not finite: {cell.strip()!r}")
        vals.append(v)
    tv, pv, zv = vals[0], vals[1], vals[2]
    sv = vals[3] if has_sigma else float(default_sigma)  # type: ignore[arg-type]
    if pv != int(pv) or pv < 0:
        raise MeasurementError(f"{where}: pair must be a non-negative integer, got {row[1].strip()!r}")
    if geometry is not None and int(pv) >= geometry.n_pairs:
        raise MeasurementError(
            f"{where}: unknown pair index {int(pv)}: the geometry has {geometry.n_pairs} "
            f"pair(s), indices 0..{geometry.n_pairs - 1}"
        )
    if sv <= 0:
        raise MeasurementError(f"{where}: sigma must be > 0, got {sv}")
    return tv, int(pv), zv, sv
