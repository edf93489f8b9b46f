"""The particle estimator's start: tempered against one-step importance sampling, on case a 25 km.

Two parts, on the accuracy benchmark's recordings of case a 25 km
(``benchmarks/bench_accuracy.py``: run ``r`` of scenario 1 draws from
``SeedSequence([seed, 1, r])``):

1. Windows: for the first ``--windows`` recordings whose initiation has a
   single solution, the window posterior's mean at the window's end from
   two independent large samples (tempered, 32,768 particles; one step,
   65,536 particles and 60 moves) and from the estimator's own 4,096 with
   either start: squared Mahalanobis distances to the reference (in its
   covariance), the spread ``trace(Σ_ref⁻¹ Σ)`` (4 for a faithful sample)
   and each mean's position error against the truth.
2. Tracks (``--runs``, 0 to skip): the benchmark's time-averaged position
   RMSE (t ≥ 5 s) of the particle estimator with either start at 4,096 and
   16,384 particles, and paired differences with 95 % bootstrap intervals.

Run: ``python studies/particle_start_check.py [--runs 100] [--seed 2026] [--out DIR]``
(7 minutes on 2 cores, most of it part 2).
"""

from __future__ import annotations

import argparse
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import _common  # noqa: F401  (the repository root on the path, for the benchmarks)
import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import _on_grid
from fgdoppler.analysis.metrics import compare_rmse, errors, time_averaged_rmse
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.window_posterior import WindowPosterior, window_posterior

SCENARIO = 1  # case a, start 25 km, in fd.paper_scenarios()
VARIANTS = {"tempered 4096": (True, 4096), "one-step 4096": (False, 4096),
            "tempered 16384": (True, 16384), "one-step 16384": (False, 16384)}


def _recording(seed: int, r: int) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation]:
    scen = fd.paper_scenarios()[SCENARIO]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([seed, SCENARIO, r])))
    model = fd.TrackingModel.of(scen.geometry)
    return sim, model, fd.initiate(sim.measurements.first_per_pair(10), model)


def _mean_cov(post: WindowPosterior, model: fd.TrackingModel) -> tuple[np.ndarray, np.ndarray]:
    x = post.at(post.t_end, model)
    return post.weights @ x, np.cov(x.T, aweights=post.weights)


def _maha(a: np.ndarray, ref: np.ndarray, cov: np.ndarray) -> float:
    return float((a - ref) @ np.linalg.solve(cov, a - ref))


def windows(seed: int, count: int) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    r = 0
    while len(rows) < count:
        sim, model, init = _recording(seed, r)
        r += 1
        if init.alternatives:
            continue
        m = sim.measurements
        ref_t, cov = _mean_cov(window_posterior(m, model, init, fd.ParticleSettings(
            n_particles=32768, start_move_steps=60)), model)
        ref_o, _ = _mean_cov(window_posterior(m, model, init, fd.ParticleSettings(
            n_particles=65536, start_move_steps=60, seed=1, tempered_start=False)), model)
        truth = sim.truth.at(np.array([init.t_end]))[0]
        row: dict[str, object] = {"run": r - 1}
        row["references apart"] = _maha(ref_o, ref_t, cov)
        row["position error, references"] = [float(np.sqrt(errors(a[None], truth[None])[0][0])) for a in (ref_t, ref_o)]
        for name, tempered in (("tempered", True), ("one-step", False)):
            mean, c = _mean_cov(window_posterior(m, model, init, fd.ParticleSettings(tempered_start=tempered)), model)
            row[f"{name}: distance"] = _maha(mean, ref_t, cov)
            row[f"{name}: spread"] = float(np.trace(np.linalg.solve(cov, c)))
            row[f"{name}: position error"] = float(np.sqrt(errors(mean[None], truth[None])[0][0]))
        rows.append(row)
        print(f"run {row['run']}: references {row['references apart']:.1e} apart; distance tempered "
              f"{row['tempered: distance']:.1e}, one-step {row['one-step: distance']:.1e}; spread "
              f"{row['tempered: spread']:.2f}, {row['one-step: spread']:.2f}; position error (m) references "
              + ", ".join(f"{v:.0f}" for v in row["position error, references"])  # type: ignore[attr-defined]
              + f", tempered {row['tempered: position error']:.0f}, one-step {row['one-step: position error']:.0f}",
              flush=True)
    return rows


@one_blas_thread
def _track(args: tuple[int, int, bool, int]) -> np.ndarray:
    seed, r, tempered, n = args
    sim, model, init = _recording(seed, r)
    e = fd.run_estimator("particle", sim.measurements, model, init,
                         fd.ParticleSettings(n_particles=n, tempered_start=tempered), verify=False).primary
    return _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)[0]


def tracks(seed: int, runs: int) -> dict[str, object]:
    times = _recording(seed, 0)[0].truth.times
    se: dict[str, np.ndarray] = {}
    with ProcessPoolExecutor(max(1, min(2, os.cpu_count() or 1))) as ex:
        for name, (tempered, n) in VARIANTS.items():
            se[name] = np.array(list(ex.map(_track, [(seed, r, tempered, n) for r in range(runs)])))
            print(f"{name}: RMSE {time_averaged_rmse(se[name], times, t0=5.0):.0f} m", flush=True)
    out: dict[str, object] = {name: float(time_averaged_rmse(v, times, t0=5.0)) for name, v in se.items()}
    for a, b in (("one-step 4096", "tempered 4096"), ("one-step 4096", "one-step 16384"),
                 ("one-step 16384", "tempered 16384")):
        c = compare_rmse(se[b], se[a], times, t0=5.0)
        out[f"{b} - {a}"] = str(c)
        print(f"{b} - {a}: {c}", flush=True)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--windows", type=int, default=8)
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--out", type=Path, default=Path("output") / "studies")
    a = p.parse_args()
    result: dict[str, object] = {"seed": a.seed, "windows": windows(a.seed, a.windows)}
    if a.runs > 0:
        result["tracks"] = tracks(a.seed, a.runs)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "particle_start_check.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {a.out / 'particle_start_check.json'}")


if __name__ == "__main__":
    main()
