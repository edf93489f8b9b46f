"""Sensors on one line and a pair off it that reports little: does a wrong side come back ``ok``?

Pairs whose Tx and Rx lie on one line see a track and its mirror image
across it with the same Doppler; only the pairs off the line tell the two
apart.  Each draw (seeded, ``--draws`` of them) puts one or two bistatic
pairs on a random line in an 80 km square (each baseline longer than 8 km)
and one pair anywhere in the square, starts a target uniformly inside the
geometry's default zone (at least 2 km from every sensor) at 50–200 m/s in a
uniform heading, records 30 s at 2 scans/s, and tracks it with the offline
smoother (``fgdoppler.track``, the command line's default), the pair off the
line keeping:

* ``all``: every measurement;
* ``3``, ``1``: only its 3 or 1 middle measurements;
* ``1 wrong``, ``3, 1 wrong``: the same with the middle one set to 0 m/s
  (a dead receiver's value, or an outlier).

An answer is *wrong* as in ``studies/random_layouts.py``: its final position
is farther from the truth than three standard deviations along its
covariance's major axis.  Printed per version: how many tracks are ``ok``,
wrong and ``ok``, carry the ``competing`` finding of
:mod:`fgdoppler.estimators.mirror_side` (``mirror="pairs"``), would be ``ok``
without it, and would be wrong and ``ok`` without it.  With ``--random``
N the same smoother also runs on the first N (at most ``--draws``) draws of
``studies/random_layouts.py`` as recorded (two to four pairs anywhere, every
pair reporting throughout), to count the finding where nothing is missing.

Run: ``python studies/few_off_line.py [--draws 60] [--random 0] [--out DIR]``.
"""

from __future__ import annotations

from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from random_layouts import MIN_BASELINE, MIN_SENSOR_DISTANCE, SPEED_MIN, SQUARE, random_pairs, row
from random_layouts import draw as random_draw

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

VERSIONS = ("all", "3", "1", "1 wrong", "3, 1 wrong")


def layout(i: int) -> tuple[fd.Geometry, tuple[float, float, float, float], np.random.Generator]:
    """Draw ``i``'s pairs (one or two on a line, the last off it), start state, and the generator that then
    simulates it."""
    rng = np.random.default_rng([91, i])
    n_on = int(rng.integers(1, 3))
    while True:
        c, angle = rng.uniform(-SQUARE / 2, SQUARE / 2, 2), rng.uniform(0.0, np.pi)
        u = np.array([np.cos(angle), np.sin(angle)])
        pairs = []
        for _ in range(n_on):
            a, b = np.sort(rng.uniform(-SQUARE, SQUARE, 2))
            if b - a > MIN_BASELINE:
                pairs.append(fd.BistaticPair(tx=tuple(c + a * u), rx=tuple(c + b * u)))
        if len(pairs) < n_on:
            continue
        g = fd.Geometry(pairs=(*pairs, *random_pairs(rng, 1)), name=f"few off line {i}")
        z = g.zone
        p = z.frame.points_to_world(np.array([[rng.uniform(*z.along), rng.uniform(*z.across)]]))[0]
        sensors = np.vstack([g.tx, g.rx])
        if np.min(np.hypot(*(sensors - p).T)) < MIN_SENSOR_DISTANCE:
            continue
        speed, heading = rng.uniform(SPEED_MIN, 200.0), rng.uniform(0.0, 2.0 * np.pi)
        return g, (float(p[0]), float(p[1]), speed * np.sin(heading), speed * np.cos(heading)), rng


def version(m: fd.Measurements, off: int, name: str) -> fd.Measurements:
    """``m`` with pair ``off`` keeping what version ``name`` says (module docstring)."""
    if name == "all":
        return m
    rows = np.flatnonzero(m.pair == off)
    keep = 3 if name.startswith("3") else 1
    kept = rows[len(rows) // 2 - keep // 2:][:keep]
    doppler = m.doppler.copy()
    if name.endswith("wrong"):
        doppler[rows[len(rows) // 2]] = 0.0
    chosen = (m.pair != off) | np.isin(np.arange(len(m)), kept)
    return fd.Measurements.from_arrays(m.time, m.pair, doppler, m.sigma).subset(chosen)


def judged(m: fd.Measurements, g: fd.Geometry, truth: fd.Trajectory) -> list[Any]:
    """:func:`random_layouts.row` of the smoother, then [the finding is there, ok without it]."""
    try:
        r = fd.track(m, g, "smoother")
    except ValueError as exc:  # the initiation refuses a target faster than the zone's bound
        return ["refused", str(exc)]
    found = any(x.mirror == "pairs" for x in r.reasons)
    others = [x for x in r.reasons if x.mirror != "pairs" and x.status != "ok"]
    return [*row(r, truth), found, not others]


@one_blas_thread
def one(i: int, random: float = 0.0) -> dict[str, Any]:
    g, x0, rng = layout(i)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=30.0, dt=0.5), rng)
    off = len(g.pairs) - 1
    out: dict[str, Any] = {"draw": i, "pairs": len(g.pairs), "x0": [round(v, 1) for v in x0]}
    for name in VERSIONS:
        out[name] = judged(version(sim.measurements, off, name), g, sim.truth)
    if i < int(random):  # draw i of studies/random_layouts.py too, every pair reporting throughout
        g, x0, rng = random_draw(i)
        sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=30.0, dt=0.5), rng)
        out["random layout"] = judged(sim.measurements, g, sim.truth)
    return out


def main() -> None:
    a, rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 60, {"random": 0.0})
    lines = ["| version | tracks | ok | wrong and ok | finding | ok without it | wrong and ok without it |",
             "|---|---|---|---|---|---|---|"]
    for name, part in [(v, [r[v] for r in rows if v in r]) for v in (*VERSIONS, "random layout")]:
        ran = [v for v in part if v[0] != "refused"]
        if not ran:
            continue
        wrong_ok = sum(v[3] for v in ran)
        alone = [v for v in ran if v[4] and v[5]]  # the finding alone makes it not ok
        lines.append(f"| {name} | {len(ran)} | {sum(v[0] == 'ok' for v in ran)} | {wrong_ok} | "
                     f"{sum(v[4] for v in ran)} | {sum(v[0] == 'ok' for v in ran) + len(alone)} | "
                     f"{wrong_ok + sum(v[1] > 3.0 * v[2] for v in alone)} |")
    _common.save_table(a.out, "few_off_line", "\n".join(lines) + "\n", rows)


if __name__ == "__main__":
    main()
