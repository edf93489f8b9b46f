r"""How often does the test for repeated values (:mod:`fgdoppler.repeats`) fire on right data, and how often on a
receiver that holds its last value?

Each recording is one of the paper's two geometries with a target drawn anywhere in the default zone (speed up to
150 m/s in each axis, 30 s at 2 Hz, sigma 1 m/s).  Its Doppler is written rounded to a grid of step ``q`` (none,
0.05, 0.1, 0.3, 0.7 and 1 sigma) with the sigma stated as they are or 2 or 5 times too large, and each version is
tested as it is (right data: a finding is a false alarm, at most one in a thousand at the verdict's level), with
pair 1 holding its last value at 10 % of its measurements (drawn at random) and at every third, and with pair 1
reading 0 at 10 % of its measurements (drawn at random: a fixed value written without a detection).

Run: python studies/repeats_test.py [--recordings 500] [--out DIR]   (about 1 min on 2 cores at the default)
"""

from __future__ import annotations

import _common
import numpy as np

import fgdoppler as fd
from fgdoppler.estimators.judge import LEVEL
from fgdoppler.repeats import find_repeats

STEPS = (0.0, 0.05, 0.1, 0.3, 0.7, 1.0)
SIGMA_FACTORS = (1.0, 2.0, 5.0)
HOLDS = ("none", "10 % at random", "every third", "0 at 10 % at random")


def _held(m: fd.Measurements, how: str, rng: np.random.Generator) -> fd.Measurements:
    if how == "none":
        return m
    z = m.doppler.copy()
    rows = np.flatnonzero(m.pair == 1)
    if how.startswith("0 at"):  # a fixed value written where the receiver has no detection
        z[rows[rng.random(rows.size) < 0.1]] = 0.0
        return fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)
    pos = np.arange(rows.size)
    held = (rng.random(rows.size) < 0.1) if how == "10 % at random" else (pos % 3 == 0)
    held[0] = False
    # each held measurement repeats the last one measured before it, so successive holds make one run
    z[rows] = z[rows[np.maximum.accumulate(np.where(held, 0, pos))]]
    return fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)


def one(k: int) -> dict[str, bool]:
    rng = np.random.default_rng(np.random.SeedSequence([2026, k]))
    g = fd.paper_geometry("ab"[k % 2])
    x0 = (rng.uniform(3e3, 47e3), rng.uniform(-4e3, 4e3), *rng.uniform(-150.0, 150.0, 2))
    m = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=30.0, dt=0.5, sigma=1.0), rng).measurements
    out = {}
    for how in HOLDS:
        h = _held(m, how, rng)
        for step in STEPS:
            z = h.doppler if step == 0.0 else np.round(h.doppler / step) * step
            for f in SIGMA_FACTORS:
                found = find_repeats(fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=f * m.sigma),
                                     level=LEVEL)
                out[f"{how}|{step:g}|{f:g}"] = any(r.pair == 1 for r in found) if how != "none" else bool(found)
    return out


def main() -> None:
    args, rows = _common.each_count(one, __doc__.splitlines()[0], "recordings", 500)
    lines = [f"{len(rows)} recordings; found repeating (of {len(rows)}), pair 1 holding its last value or writing 0:",
             "",
             "| grid step (sigma) | sigma stated | " + " | ".join(HOLDS) + " |", "|---|---|" + "---|" * len(HOLDS)]
    for step in STEPS:
        for f in SIGMA_FACTORS:
            cells = [sum(r[f"{how}|{step:g}|{f:g}"] for r in rows) for how in HOLDS]
            lines.append(f"| {step:g} | x{f:g} | " + " | ".join(map(str, cells)) + " |")
    _common.save_table(args.out, "repeats_test", "\n".join(lines), rows)


if __name__ == "__main__":
    main()
