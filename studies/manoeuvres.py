"""Manoeuvring targets on random layouts: how often is an answer kilometres off and ``ok``?

Every estimator assumes a nearly constant velocity (process noise
``q = 1e-3`` m²/s³ by default).  This study breaks that assumption gently:
each draw is the layout, start and noise of draw ``i`` of
``random_layouts.py`` (two to four pairs anywhere in an 80 km square, a
target in the default zone at 50–200 m/s, 30 s at 2 scans/s), and from an
onset uniform in 0–``--onset-max`` s (default 20) the target turns at a
rate uniform in ±``--turn-max`` deg/s (default 0.6) and changes speed at a
rate uniform in ±``--accel-max`` m/s² (default 1.0)
(:class:`fgdoppler.Manoeuvre`).  Every estimator runs from the default
initiation, with the smoother's split test of the motion model
(``SmootherSettings(motion_check=True)``, the default; the ``manoeuvre``
finding) and without it; the filters' verdicts use that smoother as their
reference, so both columns are what a user got with and without the test.
With ``--bias-sigma S`` every pair also carries a calibration offset drawn
from :math:`N(0, S^2)` (a stream of its own, so the recordings are
otherwise the same) and the smoother is told so and estimates the offsets
(``bias_sigma=S, estimate_offsets=True``): its split test then re-fits the
offsets with each part's track.
An answer is *wrong* as in the other layout studies: its final position is
farther from the truth than three standard deviations along its
covariance's major axis.  Printed: per estimator, the wrong-and-``ok``
count and the ``ok`` count with the test and without, and every draw that
is wrong and ``ok`` either way.

Run: ``python studies/manoeuvres.py [--draws 120] [--first 0] [--turn-max 0.6] [--accel-max 1.0]
[--onset-max 20] [--bias-sigma 0] [--out DIR]`` (draws ``first`` to ``first + draws - 1``; about 10 minutes per 60
draws on 2 cores).
"""

from __future__ import annotations

from typing import Any

import _common  # the repository root on the path, and the runner
import numpy as np
from random_layouts import draw, every_estimator, saved

import fgdoppler as fd
from fgdoppler.analysis.workers import one_blas_thread

LABELS = ("test", "no test")


def drawn_manoeuvre(pick: np.random.Generator, turn_max: float = 0.6, accel_max: float = 1.0,
                    onset_max: float = 20.0) -> fd.Manoeuvre:
    """The study's rule: a turn rate uniform in ±``turn_max`` deg/s, a speed change uniform in ±``accel_max``
    m/s² and an onset uniform in 0–``onset_max`` s, drawn from ``pick`` in that order."""
    return fd.Manoeuvre(turn_rate_deg=float(pick.uniform(-turn_max, turn_max)),
                        acceleration=float(pick.uniform(-accel_max, accel_max)),
                        onset=float(pick.uniform(0.0, onset_max)))


@one_blas_thread
def one(k: int, first: float = 0.0, turn_max: float = 0.6, accel_max: float = 1.0,
        onset_max: float = 20.0, bias_sigma: float = 0.0) -> dict[str, Any]:
    i = k + int(first)
    g, x0, rng = draw(i)
    pick = np.random.default_rng([91, i])  # the manoeuvre from a stream of its own: the noise is draw i's
    manoeuvre = drawn_manoeuvre(pick, turn_max, accel_max, onset_max)
    out: dict[str, Any] = {"draw": i, "pairs": len(g.pairs), "x0": [round(v, 1) for v in x0],
                           "turn_rate_deg": round(manoeuvre.turn_rate_deg, 3),
                           "acceleration": round(manoeuvre.acceleration, 3), "onset": round(manoeuvre.onset, 1)}
    # offsets from a stream of their own too: with --bias-sigma 0 the recordings are the same as without
    bias = np.random.default_rng([92, i]).normal(0.0, bias_sigma, g.n_pairs) if bias_sigma > 0 else np.zeros(0)
    told: dict[str, Any] = {"bias_sigma": bias_sigma, "estimate_offsets": True} if bias_sigma > 0 else {}
    if bias.size:
        out["bias"] = bias.round(3).tolist()
    try:
        sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=30.0, dt=0.5, manoeuvre=manoeuvre,
                                      bias=tuple(bias) if bias.size else 0.0), rng)
    except ValueError as exc:  # a deceleration that would stop the target
        return {**out, "refused": str(exc)}
    try:
        init = fd.initiate(sim.measurements.first_per_pair(10), g)
    except ValueError as exc:
        return {**out, "refused": str(exc)}
    for label, check in zip(LABELS, (True, False), strict=True):
        out[label] = every_estimator(sim.measurements, g, init, sim.truth,
                                     fd.SmootherSettings(motion_check=check, **told))
    return out


def main() -> None:
    a, all_rows = _common.each_count(one, __doc__.splitlines()[0], "draws", 120,
                                     {"first": 0.0, "turn_max": 0.6, "accel_max": 1.0, "onset_max": 20.0,
                                      "bias_sigma": 0.0})
    rows = saved(all_rows, a.out, "manoeuvres.json", "wrong and ok / ok, with the split test and without")
    for name in fd.ESTIMATORS:
        counts = {label: (sum(r[label][name][3] for r in rows), sum(r[label][name][0] == "ok" for r in rows))
                  for label in LABELS}
        print(f"  {name:10s} " + "   ".join(f"{label}: {w} / {ok}" for label, (w, ok) in counts.items()))
    for r in rows:
        bad = {label: [n for n, v in r[label].items() if v[3]] for label in LABELS}
        if any(bad.values()):
            print(f"  draw {r['draw']} ({r['pairs']} pairs, turn {r['turn_rate_deg']} deg/s, "
                  f"{r['acceleration']} m/s^2 from {r['onset']} s): wrong and ok {bad}")
    print(f"  wrote {a.out / 'manoeuvres.json'}")


if __name__ == "__main__":
    main()
