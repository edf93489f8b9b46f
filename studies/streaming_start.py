"""A tracker fed scan by scan from its first scan: with and without the warm-up (docs/concepts.md, "High scan rates").

The scaling benchmark's track (paper geometry (a), from 45 km, 4.5 km at
-100, -20 m/s), seeded recordings at several scan rates, streamed into an
``ISAM2Tracker`` (and the fixed-lag smoother, lag 5 s) with the model's weak
prior, the gate from the 20th scan: from the first scan with the true state
as the guess (warm-up off), with the warm-up from the true state, and with
the warm-up and no guess.  Per variant: median end position error, the
smallest share of measurements a run accepted, and how many runs have a
filtered NEES averaged over t >= 10 s below 20.

Run: python studies/streaming_start.py [--out DIR]   (about 2-3 minutes)
"""

from __future__ import annotations

import json

import numpy as np
from _common import out_dir
from threadpoolctl import threadpool_limits

import fgdoppler as fd
from fgdoppler.estimators.fixed_lag import FixedLagTracker
from fgdoppler.estimators.isam2 import ISAM2Tracker

COLD = {"warmup_seconds": 0.0, "warmup_per_pair": 0}
WARM = {"warmup_seconds": 4.5, "warmup_per_pair": 10}
CASES = (("isam2", 0.5, 60.0, 10), ("isam2", 0.05, 30.0, 10), ("isam2", 0.02, 30.0, 10),
         ("fixed-lag", 0.5, 60.0, 10), ("fixed-lag", 0.05, 30.0, 6))
VARIANTS = {"from the first scan": (COLD, True), "warm-up, true guess": (WARM, True),
            "warm-up, no guess": (WARM, False)}


def one_run(name: str, dt: float, duration: float, seed: int, warmup: dict[str, float], guess: bool
            ) -> tuple[float, float, float]:
    """End position error (m), share of gated measurements accepted, filtered NEES averaged over t >= 10 s."""
    sc = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(45e3, 4.5e3, -100.0, -20.0), duration=duration - dt, dt=dt)
    sim = fd.simulate(sc, np.random.default_rng(seed))
    model = fd.TrackingModel.of(sc.geometry)
    tracker: ISAM2Tracker | FixedLagTracker
    if name == "isam2":
        tracker = ISAM2Tracker(model, fd.ISAM2Settings(**warmup), model.prior())
    else:
        tracker = FixedLagTracker(model, fd.FixedLagSettings(lag=5.0, **warmup), model.prior())
    m, s = sim.measurements, sim.measurements.scans()
    x0 = sim.truth.states[0]
    nees = []
    x: np.ndarray = x0
    for k in range(len(s)):
        r = s.rows(k)
        g = x0 if (k == 0 and guess) else None
        x, P = tracker.add_scan(s.times[k], m.pair[r], m.doppler[r], m.sigma[r], g, gate=k >= 20)
        if P is not None and s.times[k] >= 10.0:
            d = x - sim.truth.states[k]
            nees.append(float(d @ np.linalg.solve(P, d)))
    nis = tracker.gate.as_array()
    accepted = float(nis[:, 3].mean()) if nis.size else 1.0
    return float(np.hypot(*(x - sim.truth.states[-1])[:2])), accepted, float(np.mean(nees)) if nees else np.nan


def main() -> None:
    out = out_dir("studies")
    rows = []
    with threadpool_limits(1):
        for name, dt, duration, runs in CASES:
            for label, (warmup, guess) in VARIANTS.items():
                if name == "fixed-lag" and label == "warm-up, no guess":
                    continue
                res = np.array([one_run(name, dt, duration, seed, warmup, guess) for seed in range(runs)])
                row = {"tracker": name, "scans_per_s": round(1 / dt), "seconds": duration, "variant": label,
                       "runs": runs, "median_end_error_m": float(np.nanmedian(res[:, 0])),
                       "min_accepted": float(np.nanmin(res[:, 1])), "nees_below_20": int(np.sum(res[:, 2] < 20))}
                rows.append(row)
                print(f"| {name} | {row['scans_per_s']}/s, {duration:g} s | {label} | "
                      f"{row['median_end_error_m']:,.0f} m | {row['min_accepted']:.1%} | "
                      f"{row['nees_below_20']}/{runs} |", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / "streaming_start.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
