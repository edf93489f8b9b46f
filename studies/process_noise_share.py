"""Where the process noise, not the data, sets the smoother's spread: precise Doppler and long recordings.

The smoother's posterior samples (``fgdoppler.estimators.spread``) move at
exactly constant velocity; along the curvature probe's axis the share of the
smoother's variance that such a track accounts for (``spread._information``)
decides whether they are drawn (``spread.DETERMINISTIC_MIN``).  This study
runs the cells of docs/concepts.md, "Precise Doppler": case a 45 km with
σ = 0.05 m/s (every estimator; recordings from ``SeedSequence(11)``), with
0.1, 0.2 and 0.3 m/s and case b 5 km with 0.2 m/s (the EKF and the smoother), and the
poorly observed scenarios flown for 40 and 120 s with the paper's σ (the
smoother; ``SeedSequence(5)``), and four pairs in 3-D on masts
(``studies/geometries/four_pairs_on_masts.toml``) watching an aircraft for
60 s (the EKF and the smoother; its start drawn 50-70 km out at 1-6 km,
``SeedSequence(9)``; docs/concepts.md, "A bend beyond trust where nothing is
sampled").  Printed per cell and estimator: position RMSE and run-averaged
NEES over t ≥ 10 s, runs beyond the χ² 99.9 % quantile of the state's
dimension, ``ok`` verdicts, how many runs report a ``nonlinear`` finding
(sampled, posterior mean, or a bend beyond trust) and the range of the
smoother's share.

Run it at a commit and at the one before it to compare.
Run: ``python studies/process_noise_share.py [--runs 20] [--workers 2]`` (about 4 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import dataclasses
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import _common  # noqa: F401  (the repository root on the path)
import numpy as np
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.metrics import nees
from fgdoppler.analysis.workers import one_blas_thread

#: The 3-D cell's geometry: four pairs on masts.
MASTS = Path(__file__).resolve().parent / "geometries" / "four_pairs_on_masts.toml"
#: (label, case (or a geometry file), start x (m), duration (s), sigma (m/s), estimators, seed of the recordings)
CELLS = [
    ("a-45, 30 s, sigma 0.05", "a", 45e3, 30.0, 0.05, tuple(fd.ESTIMATORS), 11),
    *[(f"a-45, 30 s, sigma {s:g}", "a", 45e3, 30.0, s, ("ekf", "smoother"), 11) for s in (0.1, 0.2, 0.3)],
    ("b-5, 30 s, sigma 0.2", "b", 5e3, 30.0, 0.2, ("ekf", "smoother"), 11),
    *[(f"{c}-{x / 1e3:.0f}, {d:.0f} s", c, x, d, 1.0, ("smoother",), 5)
      for d in (40.0, 120.0) for c, x in (("a", 5e3), ("b", 45e3), ("a", 25e3), ("b", 25e3))],
    ("four pairs on masts, 3-D, 60 s", str(MASTS), float("nan"), 60.0, 1.0, ("ekf", "smoother"), 9),
]
#: Start of the time averages (s).
T_AVERAGE = 10.0
#: A run is inconsistent beyond this χ² quantile (of the state's dimension) of its run-averaged NEES.
LEVEL = 0.999


def _share(m: fd.Measurements, model: fd.TrackingModel, init: fd.Initiation) -> float:
    """The constant-velocity cost's share of the smoother's Laplace variance along the probe's axis."""
    from fgdoppler.estimators import curvature, spread

    if not hasattr(spread, "_information"):  # a commit before the share was introduced
        return float("nan")
    lap = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(sampled_covariance=False),
                           verify=False).primary
    x0, P0 = lap.states[0], lap.covariances[0]
    _, data = spread._posterior(m, model, float(lap.times[0]), None, 0, 64)
    axis = curvature.probe_axis(P0)[0]
    return 1.0 / float(axis @ spread._information(model, data, x0, None, P0) @ axis)


@one_blas_thread
def one_run(task: tuple[int, np.random.SeedSequence]) -> dict[str, Any]:
    c, seq = task
    _, case, x, duration, sigma, names, _ = CELLS[c]
    rng = np.random.default_rng(seq)
    if case in ("a", "b"):
        scen = dataclasses.replace(fd.paper_scenario(case, x), duration=duration, sigma=sigma)
    else:  # an aircraft 50-70 km out at 1-6 km, level at 224 m/s
        start = (60e3 + rng.uniform(-10e3, 10e3), -20e3 + rng.uniform(-10e3, 10e3), rng.uniform(1e3, 6e3))
        scen = fd.Scenario(geometry=fd.resolve_geometry(case), x0=(*start, -200.0, 100.0, 0.0), duration=duration,
                           dt=0.5, sigma=sigma)
    sim = fd.simulate(scen, rng)
    m, model = sim.measurements, fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(m.first_per_pair(10), model)
    out: dict[str, Any] = {"cell": c, "share": _share(m, model, init), "results": {}}
    for name, res in fd.run_estimators(list(names), m, model, init).items():
        e = res.primary
        late = (e.times >= T_AVERAGE) & e.cov_ok
        truth = sim.truth.at(e.times[late])
        out["results"][name] = {
            "dim": e.states.shape[1],
            "se": float(np.mean(np.sum((e.states[late, :model.dim] - truth[:, :model.dim]) ** 2, axis=1))),
            "nees": float(np.mean(nees(truth, e.covariances[late], e.states[late]))),
            "ok": res.status == "ok", "nonlinear": any(r.code == "nonlinear" for r in res.reasons)}
    return out


def main() -> None:
    p = argparse.ArgumentParser(prog="process_noise_share.py", description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=20)
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args()
    tasks = [(c, seq) for c, cell in enumerate(CELLS) for seq in np.random.SeedSequence(cell[6]).spawn(args.runs)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(one_run, tasks, chunksize=2))
    print(f"{args.runs} runs per cell; averages over t >= {T_AVERAGE:g} s")
    print("| cell | estimator | RMSE (m) | NEES | beyond 99.9 % | ok | nonlinear finding | share along the axis |")
    print("|---|---|---|---|---|---|---|---|")
    for c, (label, *_, names, _) in enumerate(CELLS):
        mine = [r for r in rows if r["cell"] == c]
        shares = [r["share"] for r in mine]
        for name in names:
            v = [r["results"][name] for r in mine]
            ne = np.array([x["nees"] for x in v])
            limit = float(chi2.ppf(LEVEL, v[0]["dim"]))
            print(f"| {label} | {name} | {np.sqrt(np.mean([x['se'] for x in v])):,.1f} | {ne.mean():.2f} | "
                  f"{int(np.sum(ne > limit))} | {sum(x['ok'] for x in v)} | {sum(x['nonlinear'] for x in v)} | "
                  f"{min(shares):.3f}-{max(shares):.3f} |")


if __name__ == "__main__":
    main()
