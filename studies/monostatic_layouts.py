"""Random layouts with monostatic radars: how often does an estimator end kilometres off and call it ``ok``?

As ``studies/random_layouts.py`` (an 80 km square, a target uniformly in
the default zone at least 2 km from every sensor, 50-200 m/s in a uniform
heading, 30 s at 2 scans/s, every estimator from the default initiation,
*wrong* = a final position farther from the truth than three standard
deviations along the covariance's major axis), but the first pair of each
draw is a radar: monostatic (transmitter and receiver at one place) or,
with ``--quasi M``, quasi-monostatic (the transmitter ``M`` metres from
the receiver in a random direction); one to three bistatic pairs follow
(baselines longer than 8 km), and with probability one half a second
radar replaces the last of them.  With ``--spread F`` the target starts
in the zone's box scaled by ``F`` about its centre (``F`` > 1: often
outside the zone, where a user's target may well be); with ``--zone-scale
F`` the geometry's zone is its default scaled so (``[zone]`` limits: the
user who says where the target may be).  Only the default smoother (with its
whole-recording searches) is run as the reference, so each estimator's
row is what a user gets.

Run: ``python studies/monostatic_layouts.py [--draws 60] [--first 0] [--quasi 0] [--spread 1] [--zone-scale 1] [--out DIR]``
(about 10 minutes per 60 draws on 2 cores).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from random_layouts import (
    MIN_SENSOR_DISTANCE,
    SPEED_MIN,
    SQUARE,
    every_estimator,
    random_pairs,
    recorded,
    saved,
)

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.zone import ZoneLimits


def _radar(rng: np.random.Generator, quasi: float) -> fd.BistaticPair:
    rx = rng.uniform(-SQUARE, SQUARE, 2)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    tx = rx + quasi * np.array([np.cos(angle), np.sin(angle)])
    return fd.BistaticPair(tx=(float(tx[0]), float(tx[1])), rx=(float(rx[0]), float(rx[1])))


def _scaled(interval: tuple[float, float], factor: float) -> tuple[float, float]:
    mid, half = (interval[0] + interval[1]) / 2, factor * (interval[1] - interval[0]) / 2
    return mid - half, mid + half


def draw(i: int, quasi: float = 0.0, spread: float = 1.0, zone_scale: float = 1.0
         ) -> tuple[fd.Geometry, tuple[float, float, float, float], np.random.Generator]:
    """Layout, start state and the generator that then simulates draw ``i`` (rule: module docstring)."""
    rng = np.random.default_rng([79, i])
    n = int(rng.integers(1, 4))
    while True:
        pairs = [_radar(rng, quasi), *random_pairs(rng, n)]
        if rng.uniform() < 0.5:
            pairs[-1] = _radar(rng, quasi)
        g = fd.Geometry(pairs=tuple(pairs), name=f"radar layout {i}")
        z = g.zone
        if zone_scale != 1.0:
            g = replace(g, zone_limits=ZoneLimits(along=_scaled(z.along, zone_scale),
                                                     across=_scaled(z.across, zone_scale)))
        p = z.frame.points_to_world(np.array([[rng.uniform(*_scaled(z.along, spread)),
                                                rng.uniform(*_scaled(z.across, spread))]]))[0]
        sensors = np.array([s for pair in pairs for s in (pair.tx, pair.rx)])
        if np.min(np.hypot(*(sensors - p).T)) < MIN_SENSOR_DISTANCE:
            continue
        speed, heading = rng.uniform(SPEED_MIN, 200.0), rng.uniform(0.0, 2.0 * np.pi)
        return g, (float(p[0]), float(p[1]), float(speed * np.sin(heading)), float(speed * np.cos(heading))), rng


@one_blas_thread
def one(k: int, quasi: float = 0.0, first: float = 0.0, spread: float = 1.0, zone_scale: float = 1.0
        ) -> dict[str, Any]:
    i = k + int(first)
    g, x0, rng = draw(i, quasi, spread, zone_scale)
    out, sim, init = recorded(i, g, x0, rng)
    out["radars"] = sum(p.baseline < 1e3 for p in g.pairs)
    out["outside"] = not bool(g.zone.contains(np.array(x0)))
    if init is not None:
        out["search"] = every_estimator(sim.measurements, g, init, sim.truth)
    return out


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 60, {"quasi": 0.0, "first": 0.0,
                                                                                         "spread": 1.0,
                                                                                         "zone_scale": 1.0})
    rows = saved(all_rows, a.out, f"monostatic_layouts_quasi{a.quasi:g}_spread{a.spread:g}_zone{a.zone_scale:g}.json",
                 "wrong and ok / ok")
    print(f"  {sum(r['outside'] for r in rows)} of {len(rows)} targets start outside the zone")
    for name in fd.ESTIMATORS:
        print(f"  {name:10s} {sum(r['search'][name][3] for r in rows)} / "
              f"{sum(r['search'][name][0] == 'ok' for r in rows)}")
    for r in rows:
        bad = [n for n, v in r["search"].items() if v[3]]
        if bad:
            print(f"  draw {r['draw']} ({r['pairs']} pairs, {r['radars']} radar(s), start {r['x0']}"
                  f"{', outside the zone' if r['outside'] else ''}): wrong and ok "
                  + ", ".join(f"{n} {r['search'][n][1]:.0f} m at sigma {r['search'][n][2]:.0f} m" for n in bad))


if __name__ == "__main__":
    main()
