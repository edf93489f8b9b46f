"""Two-hour recordings (14,400 scans): every estimator's wall time and peak memory, with and without the verdict.

Recordings: the paper's case (a) from 45 km (2 pairs, its target and
sampling, 7,200 s instead of 30 s) and a slow 7 m/s target on a 3-pair
geometry (poorly observed: the regime that once made the smoother and
iSAM2 explode).  Each run is initiation plus
:func:`~fgdoppler.estimators.registry.run_estimator`, in its own process so
its peak resident memory is its own.  ``verify`` on is what ``fgdoppler
track`` does (the verdict's reference smoother runs too).

Run alone: ``python -m benchmarks.bench_long`` (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row

N_SCANS = 14_400
DT = 0.5
LIMIT_S = 60.0
LIMIT_MB = 2048.0

THREE_PAIRS = fd.Geometry(pairs=(
    fd.BistaticPair(tx=(40e3, 0.0), rx=(0.0, 0.0)),
    fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3)),
    fd.BistaticPair(tx=(5e3, 30e3), rx=(0.0, 0.0)),
), name="three")


def recording(kind: str) -> fd.Scenario:
    """The 2-hour scenario ``"paper"`` or ``"slow"``."""
    duration = (N_SCANS - 1) * DT
    if kind == "paper":
        return replace(fd.paper_scenario("a", 45e3), duration=duration, name="paper (a) 45 km, 2 h")
    if kind == "slow":
        return fd.Scenario(geometry=THREE_PAIRS, x0=(15e3, 8e3, 5.0, 5.0), duration=duration, dt=DT,
                           name="slow 7 m/s, 3 pairs, 2 h")
    raise ValueError(f"unknown recording {kind!r}")


def one(kind: str, name: str, verify: bool) -> dict[str, float | str]:
    """Time and peak memory of one run in this process (call in a fresh process)."""
    sim = fd.simulate(recording(kind), np.random.default_rng(0))
    geometry = sim.scenario.geometry
    t = time.perf_counter()
    init = fd.initiate(sim.measurements.first_per_pair(10), geometry)
    result = fd.run_estimator(name, sim.measurements, geometry, init, verify=verify)
    seconds = time.perf_counter() - t
    err = result.primary.states - sim.truth.at(result.primary.times)
    rmse = float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))))
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    return {"seconds": seconds, "peak_mb": peak_mb, "status": str(result.status), "rmse": rmse,
            "scans": len(sim.measurements.scans())}


def _in_subprocess(kind: str, name: str, verify: bool) -> dict[str, float | str]:
    code = ("import json, sys; from benchmarks.bench_long import one; "
            f"print(json.dumps(one({kind!r}, {name!r}, {verify!r})))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run() -> list[Row]:
    rows = []
    for kind in ("paper", "slow"):
        for name in fd.ESTIMATORS:
            for verify in (False, True):
                r = _in_subprocess(kind, name, verify)
                sec, mb = float(r["seconds"]), float(r["peak_mb"])
                label = f"2-hour recording, {recording(kind).name}: {name}{' + verdict' if verify else ''}"
                value = (f"{sec:.1f} s, peak {mb:.0f} MB ({r['scans']} scans; status {r['status']}, "
                         f"position RMSE {float(r['rmse']):.0f} m)")
                rows.append(Row(name=label, value=value, ratio=sec / LIMIT_S,
                                target=f"<= {LIMIT_S:.0f} s and <= {LIMIT_MB / 1024:.0f} GB",
                                met=sec <= LIMIT_S and mb <= LIMIT_MB))
    return rows


if __name__ == "__main__":
    for row in run():
        print(f"{row.name}: {row.value} -> {'met' if row.met else 'NOT MET'}", flush=True)
