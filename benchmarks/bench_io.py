"""Reading long files: a 200,000-row measurement CSV and a 50,000-row track CSV, against ``numpy.loadtxt``.

``Measurements.from_csv`` and ``TrackResult.read_csv`` check every value (ASCII decimals, physical bounds,
pairs, each pair's time order, duplicates, the covariance whole or empty) and name the line of any problem;
``numpy.loadtxt`` of the same file checks none of that.  Both are timed alternately in one process, so the
ratio holds on a shared machine.  Run alone: ``python -m benchmarks --only io``.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row
from fgdoppler.estimators.results import states_csv

MEASUREMENT_ROWS = 200_000
TRACK_ROWS = 50_000
LIMIT = 6.0


def _alternate(ours: Callable[[], object], numpy_read: Callable[[], object], repeat: int = 5) -> tuple[float, float]:
    """Median times of the two readers, called alternately."""
    a: list[float] = []
    b: list[float] = []
    for _ in range(repeat):
        for fn, out in ((ours, a), (numpy_read, b)):
            t = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t)
    return float(np.median(a)), float(np.median(b))


def _row(what: str, ours: float, plain: float) -> Row:
    ratio = ours / plain
    return Row(name=f"reading {what}", value=f"{ours:.3f} s (numpy.loadtxt of the same file: {plain:.3f} s)",
               ratio=ratio, target=f"<= {LIMIT:g}x numpy.loadtxt", met=ratio <= LIMIT)


def run() -> list[Row]:
    rng = np.random.default_rng(0)
    geometry = fd.paper_geometry("a")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.csv"
        n = MEASUREMENT_ROWS // 2
        m = fd.Measurements.from_arrays(np.repeat(np.arange(n) * 0.05, 2), np.tile([0, 1], n),
                                        rng.normal(0.0, 50.0, 2 * n), np.ones(2 * n))
        m.to_csv(path)
        rows = [_row(f"a measurement CSV of {MEASUREMENT_ROWS:,} rows (Measurements.from_csv)",
                     *_alternate(lambda: fd.Measurements.from_csv(path, geometry=geometry),
                                 lambda: np.loadtxt(path, delimiter=",", skiprows=1)))]
        track = Path(tmp) / "t.csv"
        t = np.asarray(np.arange(TRACK_ROWS) * 0.05, dtype=np.float64)
        states = np.column_stack([25e3 + 10 * t, 2e3 - 100 * t, np.full_like(t, 10.0), np.full_like(t, -100.0)])
        cov = np.tile(np.diag([1e4, 4e4, 1.0, 4.0]), (TRACK_ROWS, 1, 1))
        track.write_text(states_csv(t, states, cov, np.ones(TRACK_ROWS, dtype=bool), ["fgdoppler smoother"]))
        rows.append(_row(f"a track CSV of {TRACK_ROWS:,} rows (TrackResult.read_csv)",
                         *_alternate(lambda: fd.TrackResult.read_csv(track),
                                     lambda: np.loadtxt(track, delimiter=",", skiprows=2))))
    return rows


if __name__ == "__main__":
    for r in run():
        print(r)
