"""Where the process noise keeps the smoother's spread from being sampled: the profile of the whole track's valley.

Below ``spread.DETERMINISTIC_MIN`` (the constant-velocity track accounts for
less than a quarter of the smoother's variance along the probe's axis) no
posterior samples are drawn.  Since 2026-12-07 the smoother's own cost is
profiled there along the valley wherever the probe of the whole track strays
beyond ``spread.SAMPLING_LIMIT`` (``fgdoppler.estimators.trajectory_bend``), as
beyond ``spread.MAX_SPAN``; before, only a constant-velocity probe beyond
``CURVATURE_LIMIT`` led to it.  The recordings: case a from (25, 3) km at
(20, −60) m/s, truth and model with q = 0.05 m²/s³, seeds 1-16, and case b
from (25, 2) km at (50, −50) m/s, q = 0.01, seeds 1-8; 150, 225 and 300 s
every 0.5 s (``simulate`` with ``default_rng(seed)``; the initiation from the
first 10 measurements per pair).  Printed per cell: the run-averaged NEES of
the 4-D state over t ≥ 10 s with the Laplace covariances (``sampled_covariance
=False``) and as reported, the runs whose final NEES exceeds the χ²₄ 99.9 %
point, the reported ``nonlinear`` findings by status, the runs below
``DETERMINISTIC_MIN`` and the CPU of the smoother as reported.

Run it at a commit and at the one before it to compare.
Run: ``python studies/unsampled_profiles.py [--workers 2]`` (about 5 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import _common  # noqa: F401  (the repository root on the path)
import numpy as np
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.metrics import nees
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.spread import DETERMINISTIC_MIN

#: case -> (start (x, y, vx, vy), process noise q (m²/s³), seeds)
CASES = {"a": ((25e3, 3e3, 20.0, -60.0), 0.05, range(1, 17)), "b": ((25e3, 2e3, 50.0, -50.0), 0.01, range(1, 9))}
DURATIONS = (150.0, 225.0, 300.0)
#: Start of the time averages (s).
T_AVERAGE = 10.0
#: A final NEES beyond this χ²₄ quantile is counted.
LEVEL = 0.999


def _share(m: fd.Measurements, model: fd.TrackingModel, laplace: fd.Estimates) -> float:
    """The constant-velocity cost's share of the smoother's Laplace variance along the probe's axis."""
    from fgdoppler.estimators import curvature, spread

    x0, P0 = laplace.states[0], laplace.covariances[0]
    _, data = spread._posterior(m, model, float(laplace.times[0]), None, 0, 64)
    axis = curvature.probe_axis(P0)[0]
    return 1.0 / float(axis @ spread._information(model, data, x0, None, P0) @ axis)


@one_blas_thread
def one_run(task: tuple[str, float, int]) -> dict[str, Any]:
    case, duration, seed = task
    x0, q, _ = CASES[case]
    motion = fd.ConstantVelocity(q=q)
    g = fd.paper_geometry(case)
    scen = fd.Scenario(geometry=g, x0=x0, duration=duration, dt=0.5, time_offsets=(0.0, 0.0), process_noise=motion)
    model = fd.TrackingModel.of(g, motion=motion)
    sim = fd.simulate(scen, np.random.default_rng(seed))
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), model)
    laplace = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(sampled_covariance=False))
    cpu = time.process_time()
    reported = fd.run_estimator("smoother", m, model, init)
    cpu = time.process_time() - cpu
    out: dict[str, Any] = {"case": case, "duration": duration, "seed": seed, "cpu": cpu,
                           "share": _share(m, model, laplace.primary),
                           "findings": [r.status for r in reported.reasons if r.code == "nonlinear"]}
    for name, res in (("laplace", laplace), ("reported", reported)):
        e = res.primary
        late = e.times >= T_AVERAGE
        values = nees(e.states[late], e.covariances[late], sim.truth.at(e.times[late]))
        out[name] = (float(np.mean(values)), float(values[-1]))
    return out


def main() -> None:
    p = argparse.ArgumentParser(prog="unsampled_profiles.py", description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args()
    tasks = [(c, d, s) for d in DURATIONS for c, (_, _, seeds) in CASES.items() for s in seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(one_run, tasks))
    limit = float(chi2.ppf(LEVEL, 4))
    print(f"run-averaged NEES over t >= {T_AVERAGE:g} s (mean over runs, range); final NEES beyond {limit:.1f}")
    print("| cell | runs | below DETERMINISTIC_MIN | NEES Laplace | NEES reported | final beyond, Laplace -> reported "
          "| findings ok / doubtful | smoother CPU (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for d in DURATIONS:
        for c in CASES:
            mine = [r for r in rows if r["case"] == c and r["duration"] == d]
            lap, rep = (np.array([r[k] for r in mine]) for k in ("laplace", "reported"))
            found = [f for r in mine for f in r["findings"]]
            cpu = [r["cpu"] for r in mine]
            print(f"| {c}, {d:.0f} s | {len(mine)} | {sum(r['share'] < DETERMINISTIC_MIN for r in mine)} | "
                  f"{lap[:, 0].mean():.2f} ({lap[:, 0].min():.2f}-{lap[:, 0].max():.2f}) | "
                  f"{rep[:, 0].mean():.2f} ({rep[:, 0].min():.2f}-{rep[:, 0].max():.2f}) | "
                  f"{int(np.sum(lap[:, 1] > limit))} -> {int(np.sum(rep[:, 1] > limit))} | "
                  f"{found.count('ok')} / {found.count('doubtful')} | {min(cpu):.1f}-{max(cpu):.1f} |")


if __name__ == "__main__":
    main()
