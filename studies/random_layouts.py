"""Random sensor layouts: how often does an estimator end kilometres off and call it ``ok``?

Each draw (seeded, ``--draws`` of them) places two to four bistatic pairs
anywhere in an 80 km square (each baseline longer than 8 km), starts a
target uniformly inside the geometry's default zone (at least 2 km from
every sensor), at 50 m/s to ``--speed-max`` (default the zone's bound of
200 m/s; faster targets the initiation refuses, and they are counted as
refused) in a uniform heading,
and records 30 s at 2 scans/s.  Every estimator runs from the default
initiation; the smoother also with ``SmootherSettings(mode_search=False)``
(the whole recording's mode search off), and the filters' verdict then uses
that smoother as its reference, so both columns are what a user got with
and without the search.  An answer is *wrong* as in the verdict tests
(``tests/estimators/test_verdict.py``): its final position is farther from
the truth than three standard deviations along its covariance's major
axis.  Printed: per estimator, the wrong-and-``ok`` count and the ``ok``
count, with and without the search, and every draw that is wrong and
``ok`` either way.

Run: ``python studies/random_layouts.py [--draws 60] [--first 0] [--speed-max 200] [--out DIR]`` (draws
``first`` to ``first + draws - 1``; about 20 minutes per 60 draws on 2 cores).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

#: Slowest start speed (m/s); the fastest is ``--speed-max`` (default the zone's bound, 200 m/s).
SPEED_MIN = 50.0
SQUARE = 40e3
MIN_BASELINE = 8e3
MIN_SENSOR_DISTANCE = 2e3


def random_pairs(rng: np.random.Generator, n: int, *, ground: bool = False, square: float = SQUARE
                 ) -> tuple[fd.BistaticPair, ...]:
    """``n`` pairs anywhere in the square of half-side ``square`` (m), each baseline longer than
    :data:`MIN_BASELINE`; with ``ground`` 3-D sensors at ``z = 0``."""
    pairs = []
    for _ in range(n):
        while True:
            tx, rx = rng.uniform(-square, square, 2), rng.uniform(-square, square, 2)
            if np.hypot(*(tx - rx)) > MIN_BASELINE:
                break
        z = (0.0,) if ground else ()
        pairs.append(fd.BistaticPair(tx=(float(tx[0]), float(tx[1]), *z), rx=(float(rx[0]), float(rx[1]), *z)))
    return tuple(pairs)


def draw(i: int, speed_max: float = 200.0
         ) -> tuple[fd.Geometry, tuple[float, float, float, float], np.random.Generator]:
    """Layout, start state and the generator that then simulates draw ``i``."""
    rng = np.random.default_rng([77, i])
    n = int(rng.integers(2, 5))
    while True:
        pairs = random_pairs(rng, n)
        g = fd.Geometry(pairs=pairs, name=f"random {i}")
        z = g.zone
        p = z.frame.points_to_world(np.array([[rng.uniform(*z.along), rng.uniform(*z.across)]]))[0]
        sensors = np.array([s for pair in pairs for s in (pair.tx, pair.rx)])
        if np.min(np.hypot(*(sensors - p).T)) < MIN_SENSOR_DISTANCE:
            continue
        speed, heading = rng.uniform(SPEED_MIN, speed_max), rng.uniform(0.0, 2.0 * np.pi)
        return g, (float(p[0]), float(p[1]), speed * np.sin(heading), speed * np.cos(heading)), rng


def row(r: fd.TrackResult, truth: fd.Trajectory) -> list[Any]:
    """[status, final position error (m), sigma along the major axis (m), wrong and ok], in 2-D or 3-D."""
    e = r.primary
    k = e.states.shape[1] // 2
    err = float(np.linalg.norm(e.states[-1, :k] - truth.at(e.times[-1:])[0][:k]))
    sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:k, :k])))) if e.cov_ok[-1] else float("nan")
    return [str(r.status), round(err, 1), round(sd, 1), bool(r.status == "ok" and err > 3.0 * sd)]


def every_estimator(m: fd.Measurements, g: fd.Geometry, init: fd.Initiation, truth: fd.Trajectory,
                    settings: fd.SmootherSettings | None = None) -> dict[str, list[Any]]:
    """:func:`row` of every estimator; the smoother (with ``settings``) is the others' verdict reference."""
    reference = fd.run_estimator("smoother", m, g, init, settings)
    rows = {"smoother": row(reference, truth)}
    for name in fd.ESTIMATORS:
        if name != "smoother":
            rows[name] = row(fd.run_estimator(name, m, g, init, reference=reference), truth)
    return rows


def recorded(i: int, g: fd.Geometry, x0: tuple[float, ...], rng: np.random.Generator, *, duration: float = 30.0
             ) -> tuple[dict[str, Any], fd.Simulation, fd.Initiation | None]:
    """Draw ``i``'s record (its number, pairs and start), its recording (``duration`` s) and the default
    initiation (``None`` when the initiation refuses it — a target faster than the zone's bound —, said in the
    record)."""
    sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=duration, dt=0.5), rng)
    out: dict[str, Any] = {"draw": i, "pairs": len(g.pairs), "x0": [round(v, 1) for v in x0]}
    try:
        return out, sim, fd.initiate(sim.measurements.first_per_pair(10), g)
    except ValueError as exc:
        return {**out, "refused": str(exc)}, sim, None


@one_blas_thread
def one(k: int, speed_max: float = 200.0, first: float = 0.0) -> dict[str, Any]:
    i = k + int(first)
    out, sim, init = recorded(i, *draw(i, speed_max))
    if init is None:
        return out
    for label, search in (("search", True), ("no search", False)):
        out[label] = every_estimator(sim.measurements, sim.scenario.geometry, init, sim.truth,
                                     fd.SmootherSettings(mode_search=search))
    return out


def saved(all_rows: list[dict[str, Any]], out: Path, name: str, columns: str) -> list[dict[str, Any]]:
    """Write every draw's record to ``out/name``, say how many were refused and what the ``columns`` are,
    and return the records of the draws that ran."""
    rows = [r for r in all_rows if "refused" not in r]
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text(json.dumps(all_rows, indent=1))
    print(f"{len(all_rows)} draws, {len(all_rows) - len(rows)} refused (a target faster than the zone's bound); "
          f"per estimator: {columns}")
    return rows


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 60, {"speed_max": 200.0, "first": 0.0})
    rows = saved(all_rows, a.out, "random_layouts.json", "wrong and ok / ok, with the mode search and without")
    for name in fd.ESTIMATORS:
        counts = {label: (sum(r[label][name][3] for r in rows), sum(r[label][name][0] == "ok" for r in rows))
                  for label in ("search", "no search")}
        print(f"  {name:10s} " + "   ".join(f"{label}: {w} / {ok}" for label, (w, ok) in counts.items()))
    for r in rows:
        bad = {label: [n for n, v in r[label].items() if v[3]] for label in ("search", "no search")}
        if any(bad.values()):
            print(f"  draw {r['draw']} ({r['pairs']} pairs, start {r['x0']}): wrong and ok {bad}")
    print(f"  wrote {a.out / 'random_layouts.json'}")


if __name__ == "__main__":
    main()
