"""Random 3-D layouts: how often does an estimator end kilometres off in space and call it ``ok``?

The 3-D counterpart of ``random_layouts.py``.  Each draw (seeded,
``--draws`` of them) places two to four bistatic pairs on the ground
(``z = 0``) anywhere in a square (``--square``: half its side in km, default
40, an 80 km square; each baseline longer than 8 km),
and starts an aircraft uniformly inside the geometry's default zone —
horizontally in its box, at 500 m to ``--ceiling`` (default 4,500 m) above
the ground and inside the default altitude band (0 to a quarter of the
layout's extent along its first baseline), at least 2 km from
every sensor — at 50 m/s to ``--speed-max`` (default the zone's bound of
200 m/s; faster targets the initiation refuses, counted as refused) in a
uniform heading, climbing or descending by up to 3 degrees; it records 30 s
(``--duration``) at 2 scans/s.  Every estimator runs from the default initiation (the 3-D
smoother always searches its altitude levels and the whole recording; the
filters' verdict uses it as the reference).  An answer is *wrong* as in the
2-D study: its final position is farther from the truth than three standard
deviations along its covariance's major axis (3-D: the position's 3×3
block).  Printed: per estimator, the wrong-and-``ok`` count and the ``ok``
count, and every draw that is wrong and ``ok``.

``--sites H`` raises every sensor to a height drawn uniformly in 0..H m (masts and hills; the target's
start height stays above the ground): the frame's third axis is then the sensors' plane's normal on
the sky's side (:func:`fgdoppler.frames.sensor_frame`).

Run: ``python studies/random_layouts_3d.py [--draws 60] [--first 0] [--speed-max 200] [--ceiling 4500]
[--square 40] [--sites 0] [--duration 30] [--out DIR]`` (draws ``first`` to ``first + draws - 1``; a smaller square brings the
sensors closer to the aircraft, which sees its height better).
"""

from __future__ import annotations

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

#: Lowest start height above the ground (m); the highest is ``--ceiling``.
FLOOR = 500.0
#: Steepest climb or descent (degrees).
CLIMB = 3.0


def draw(i: int, speed_max: float = 200.0, ceiling: float = 4500.0, square: float = SQUARE, sites: float = 0.0
         ) -> tuple[fd.Geometry, tuple[float, ...], np.random.Generator]:
    """Layout, start state ``(x, y, z, vx, vy, vz)`` and the generator that then simulates draw ``i``; with
    ``sites`` > 0 every sensor stands at a height drawn uniformly in 0..``sites`` m (its own generator: the
    layouts' horizontal positions and the targets are those of ``sites = 0``)."""
    rng = np.random.default_rng([77, 3, i])
    raised = np.random.default_rng([77, 3, i, 1])
    n = int(rng.integers(2, 5))
    while True:
        pairs = random_pairs(rng, n, ground=True, square=square)
        if sites > 0:
            pairs = tuple(fd.BistaticPair(tx=(*p.tx[:2], raised.uniform(0, sites)), rx=(*p.rx[:2], raised.uniform(0, sites)))
                          for p in pairs)
        g = fd.Geometry(pairs=pairs, name=f"random 3-D {i}")
        z = g.zone
        assert z.altitude is not None
        height = rng.uniform(FLOOR, min(ceiling, z.altitude[1]))
        # the height above the ground (world z), whatever the tilt of the sensors' plane
        p = z.frame.points_to_world(np.array([[rng.uniform(*z.along), rng.uniform(*z.across), 0.0]]))[0]
        p[2] = height
        sensors = np.array([s for pair in pairs for s in (pair.tx, pair.rx)])
        if np.min(np.linalg.norm(sensors - p, axis=1)) < MIN_SENSOR_DISTANCE:
            continue
        speed, heading = rng.uniform(SPEED_MIN, speed_max), rng.uniform(0.0, 2.0 * np.pi)
        climb = np.radians(rng.uniform(-CLIMB, CLIMB))
        level = speed * np.cos(climb)
        x0 = (*(float(v) for v in p), level * np.sin(heading), level * np.cos(heading), speed * np.sin(climb))
        return g, x0, rng


@one_blas_thread
def one(k: int, speed_max: float = 200.0, first: float = 0.0, ceiling: float = 4500.0,
        square: float = SQUARE / 1e3, sites: float = 0.0, duration: float = 30.0) -> dict[str, Any]:
    i = k + int(first)
    out, sim, init = recorded(i, *draw(i, speed_max, ceiling, square * 1e3, sites), duration=duration)
    if init is None:
        return out
    out["initiation"] = str(init.status)
    out["rows"] = every_estimator(sim.measurements, sim.scenario.geometry, init, sim.truth)
    # the heights at the end: ground sensors see height only through z/r
    out["height"] = round(float(sim.truth.states[-1, 2]), 1)
    return out


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 60,
                                     {"speed_max": 200.0, "first": 0.0, "ceiling": 4500.0, "square": SQUARE / 1e3,
                                      "sites": 0.0, "duration": 30.0})
    rows = saved(all_rows, a.out, "random_layouts_3d.json", "wrong and ok / ok / all")
    for name in fd.ESTIMATORS:
        wrong = sum(r["rows"][name][3] for r in rows)
        ok = sum(r["rows"][name][0] == "ok" for r in rows)
        print(f"  {name:10s} {wrong} / {ok} / {len(rows)}")
    for r in rows:
        bad = [n for n, v in r["rows"].items() if v[3]]
        if bad:
            print(f"  draw {r['draw']} ({r['pairs']} pairs, start {r['x0']}): wrong and ok "
                  + ", ".join(f"{n} {r['rows'][n][1] / 1e3:.1f} km off (sigma {r['rows'][n][2]:.0f} m)" for n in bad))
    print(f"  wrote {a.out / 'random_layouts_3d.json'}")


if __name__ == "__main__":
    main()
