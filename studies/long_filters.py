"""The filters' and the fixed-lag smoother's covariances on 600 s recordings: their own (and the samples') against
the linearised posterior.

A filter linearises each measurement at its own prediction; over minutes of
a poorly observed track its covariance shrinks below what the data allow.
The sampled check (:func:`fgdoppler.estimators.spread.filtered_spread`)
stops where the process noise matters; beyond, the registry now widens the
filtered covariances towards the posterior of the data so far linearised
about the offline smoother's track
(:mod:`fgdoppler.estimators.linearized_posterior`), and the fixed-lag
smoother's lagged covariances towards that posterior given the data up to
its lag after their time.

Recordings: those of ``studies/long_particles.py`` (the paper's pairs, a
target from (20 km, 3 km) at (30, -40) m/s for 600 s, its truth at constant
velocity or with the model's process noise, ``--truth-q``).  Per case and
estimator (EKF, iSAM2, fixed-lag smoother), over ``--recordings`` recordings (seeds 0, 1, ...):
position RMSE over t >= 30 s, run-averaged NEES over t >= 30 s (4 state
dimensions: 4 if consistent) without the reference smoother (``verify=False``:
the covariances as before the linearised check) and with it (the default),
the runs whose own average NEES exceeds the chi-square(4) 99.9 % point
(18.5) and how many of those were judged ``ok``; each run above that point
(seed, NEES own -> reported, verdict), and every run in the JSON file.

Run: ``python studies/long_filters.py [--recordings 12] [--truth-q 0]``
(30 CPU minutes per ``--truth-q``: 15 minutes on 2 free cores).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from long_particles import CASES, by_variant, recording, run_recordings, save
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.metrics import errors, nees
from fgdoppler.analysis.workers import one_blas_thread

FILTERS = ("ekf", "isam2", "fixed-lag")
#: Run-averaged NEES beyond which a run is called inconsistent (as the accuracy benchmark does).
RUN_LIMIT = float(chi2.ppf(0.999, 4))


@one_blas_thread
def one(seed: int, truth_q: float) -> dict[str, dict[str, list[float | str]]]:
    out: dict[str, dict[str, list[float | str]]] = {}
    for case in CASES:
        sim, m, model, init, smoother = recording(case, truth_q, seed)
        for name in FILTERS:
            own = fd.run_estimator(name, m, model, init, verify=False).primary
            result = fd.run_estimator(name, m, model, init, reference=smoother)
            e = result.primary
            truth = sim.truth.at(e.times)
            late = e.times >= 30.0
            out.setdefault(case, {})[name] = [float(np.mean(errors(e.states, truth)[0][late])),
                                              float(np.mean(nees(own.states, own.covariances, truth)[late])),
                                              float(np.mean(nees(e.states, e.covariances, truth)[late])),
                                              str(result.status)]
    return out


def main() -> None:
    args, rows = run_recordings(one, __doc__)
    summary: dict[str, dict[str, Any]] = {}
    for case, name, runs in by_variant(rows, FILTERS):
        squared, before, after = (np.array([float(v[i]) for v in runs]) for i in range(3))
        ok = np.array([v[3] == "ok" for v in runs])
        summary[f"{case} {name}"] = {
            "rmse": float(np.sqrt(squared.mean())), "nees_own": float(before.mean()),
            "nees_reported": float(after.mean()), "inconsistent_own": int(np.sum(before > RUN_LIMIT)),
            "inconsistent_own_ok": int(np.sum((before > RUN_LIMIT) & ok)),
            "inconsistent_reported": int(np.sum(after > RUN_LIMIT)),
            "inconsistent_reported_ok": int(np.sum((after > RUN_LIMIT) & ok)), "not_ok": int(np.sum(~ok)),
            "runs": [{"seed": seed, "mean_square_error": float(squared[seed]), "nees_own": float(before[seed]),
                      "nees_reported": float(after[seed]), "status": str(runs[seed][3])} for seed in range(len(runs))]}
        s = summary[f"{case} {name}"]
        above = ", ".join(f"seed {r['seed']} {r['nees_own']:.0f} -> {r['nees_reported']:.0f} {r['status']}"
                          for r in s["runs"] if max(r["nees_own"], r["nees_reported"]) > RUN_LIMIT)
        print(f"case {case} {name:9s} RMSE {s['rmse']:6.0f} m, NEES own {s['nees_own']:6.2f} "
              f"(runs > {RUN_LIMIT:.1f}: {s['inconsistent_own']}, {s['inconsistent_own_ok']} ok), "
              f"reported {s['nees_reported']:6.2f} (runs > {RUN_LIMIT:.1f}: {s['inconsistent_reported']}, "
              f"{s['inconsistent_reported_ok']} ok), not ok {s['not_ok']} of {len(runs)}"
              + (f"\n    above {RUN_LIMIT:.1f}: {above}" if above else ""))
    save(args.out, f"long_filters_q{args.truth_q:g}.json", summary)


if __name__ == "__main__":
    main()
