"""The online restarts on the slow three-pair track: EKF RMSE with and without them, over many recordings.

The slow 7 m/s target of :mod:`benchmarks.bench_long` on its three pairs,
120 s per recording (``--recordings`` of them, seeds 0, 1, ...): poorly
observed, its initiation windows non-Gaussian, so the EKF starts from the
Gaussian sum of the window's posterior
(:func:`~fgdoppler.estimators.ambiguity.posterior_hypotheses`), and the
online restarts (:mod:`fgdoppler.estimators.restart`) fire in some
recordings.  Per recording: the position RMSE over the whole track with
``restarts=False`` and with the default, how many restarts fired, and
whether the run is inconsistent as the accuracy benchmark calls a run
(its NEES averaged over t ≥ 10 s above the χ²₄ 99.9 % quantile,
:func:`benchmarks.bench_accuracy.run_inconsistent`); then the RMS over
runs, the median, and how many runs are inconsistent.  ``--samplers K`` runs every
recording with sampler seeds ``0 .. K - 1`` (``TrackerSettings.seed``: the
EKF's sampled start, and with it the restarts, move with it) and
summarises over all of them.  Run it at two commits to measure a change to
the start or to the restart rule.

Run: ``python studies/slow_track_check.py [--recordings 30] [--samplers 1] [--out DIR]``
(about 1 minute on 2 cores per sampler seed).
"""

from __future__ import annotations

import json
from dataclasses import replace

import _common  # the repository root on the path, and the runner
import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import T_NEES, mean_after, run_inconsistent
from benchmarks.bench_long import recording
from fgdoppler.analysis.metrics import errors, nees
from fgdoppler.analysis.workers import one_blas_thread

#: The two-hour slow recording of the long-run benchmark, cut to its first 120 s.
SCENARIO = replace(recording("slow"), duration=120.0, name="slow 7 m/s, 3 pairs, 120 s")


@one_blas_thread
def one(seed: int, samplers: float = 1.0) -> list[dict[str, float]]:
    """The recording drawn with ``seed``, tracked with sampler seeds ``0 .. samplers - 1``."""
    sim = fd.simulate(SCENARIO, np.random.default_rng(seed))
    m = sim.measurements
    model = fd.TrackingModel.of(SCENARIO.geometry)
    init = fd.initiate(m.first_per_pair(10), model)

    def rmse(r: fd.TrackResult) -> float:
        e = r.primary
        return float(np.sqrt(np.mean(errors(e.states, sim.truth.at(e.times))[0])))

    def run_nees(r: fd.TrackResult) -> tuple[float, bool]:
        """The run's NEES averaged over t >= T_NEES, and whether the accuracy benchmark calls it inconsistent."""
        e = r.primary
        ok = e.cov_ok
        ne, t = nees(e.states[ok], e.covariances[ok], sim.truth.at(e.times[ok])), e.times[ok]
        return mean_after(ne, t, T_NEES), bool(run_inconsistent(ne[None], t)[0])

    rows = []
    for k in range(int(samplers)):
        plain = fd.run_estimator("ekf", m, model, init, fd.EKFSettings(restarts=False, seed=k), verify=False)
        full = fd.run_estimator("ekf", m, model, init, fd.EKFSettings(seed=k), verify=False)
        restarts = sum("online re-initiation" in ev.message for ev in full.events)
        (n_plain, bad_plain), (n_full, bad_full) = run_nees(plain), run_nees(full)
        rows.append({"seed": seed, "sampler": k, "no restarts": rmse(plain), "restarts": rmse(full),
                     "fired": restarts, "nees no restarts": n_plain, "nees restarts": n_full,
                     "inconsistent no restarts": bad_plain, "inconsistent restarts": bad_full})
    return rows


def main() -> None:
    a, per_recording = _common.each_count(one, __doc__.splitlines()[0], "recordings", 30, {"samplers": 1.0})
    rows = [r for rs in per_recording for r in rs]
    for r in rows:
        print(f"recording {r['seed']:3d}, sampler seed {r['sampler']}: RMSE {r['no restarts']:8.0f} m without "
              f"restarts, {r['restarts']:8.0f} m with ({r['fired']} fired)")
    summary = {}
    for key in ("no restarts", "restarts"):
        v = np.array([r[key] for r in rows])
        summary[key] = {"rms": float(np.sqrt(np.mean(v ** 2))), "median": float(np.median(v))}
        print(f"{key}: RMS over runs {summary[key]['rms']:.0f} m, median {summary[key]['median']:.0f} m")
    for label in ("no restarts", "restarts"):
        key = f"nees {label}"
        v = np.array([r[key] for r in rows])
        summary[key] = {"median": float(np.median(v)),
                        "inconsistent": int(sum(r[f"inconsistent {label}"] for r in rows))}
        print(f"{key}: median over runs of each run's time-averaged NEES {summary[key]['median']:.1f}, "
              f"inconsistent (the accuracy benchmark's rule) in {summary[key]['inconsistent']} of {len(v)} runs")
    fired = sum(1 for r in rows if r["fired"])
    print(f"restarts fired in {fired} of {len(rows)} runs")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "slow_track_check.json").write_text(json.dumps({"rows": rows, "summary": summary}, indent=1))
    print(f"wrote {a.out / 'slow_track_check.json'}")


if __name__ == "__main__":
    main()
