"""Estimators: initiation, EKF, iSAM2, fixed-lag and offline (batch) smoothers.

All trackers share one signature,
``run_*(measurements, model, init, settings) -> TrackResult``; use
:func:`run_estimator` to pick one by name.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fgdoppler.estimators.common import TrackerSettings
    from fgdoppler.estimators.initiation import Initiation
    from fgdoppler.estimators.results import TrackResult
    from fgdoppler.measurements import Measurements
    from fgdoppler.models.measurement import MeasurementModel

__all__ = ["ESTIMATORS", "run_estimator"]

#: Names accepted by :func:`run_estimator`.
ESTIMATORS = ("ekf", "isam2", "fixed-lag", "batch")


def run_estimator(
    name: str,
    measurements: Measurements,
    model: MeasurementModel,
    init: Initiation,
    settings: TrackerSettings | None = None,
    *,
    resolve_ambiguity: bool = True,
) -> TrackResult:
    """Run the estimator called ``name`` (one of :data:`ESTIMATORS`).

    If the initiation is ambiguous (other solutions pass its χ² test, e.g. a
    mirror image) and ``resolve_ambiguity`` is set, the estimator is run from
    every hypothesis (:func:`~fgdoppler.estimators.initiation.hypotheses`) and
    the later data decide:

    * EKF, iSAM2, fixed-lag: an EKF per hypothesis accumulates the predictive
      log-likelihood of the measurements; each *filtered* estimate comes from
      the hypothesis leading at that time (causal), the smoothed/lagged
      estimates from the hypothesis leading at the end;
    * batch: the hypothesis with the lowest final cost.

    ``TrackResult.hypothesis`` records which one was reported when.
    """
    import time

    import numpy as np

    from fgdoppler.estimators.batch import run_batch
    from fgdoppler.estimators.ekf import run_ekf
    from fgdoppler.estimators.fixed_lag import run_fixed_lag
    from fgdoppler.estimators.initiation import hypotheses
    from fgdoppler.estimators.isam2 import run_isam2

    runners = {"ekf": run_ekf, "isam2": run_isam2, "fixed-lag": run_fixed_lag, "batch": run_batch}
    if name not in runners:
        raise ValueError(f"unknown estimator {name!r}: expected one of {', '.join(ESTIMATORS)}")
    runner = runners[name]
    hyps = hypotheses(init) if (resolve_ambiguity and init.ambiguous) else [init]
    if len(hyps) == 1:
        return runner(measurements, model, hyps[0], settings)
    t_begin = time.perf_counter()
    results = [runner(measurements, model, h, settings) for h in hyps]
    note = f"ambiguous initiation: {len(hyps)} hypotheses run"
    if name == "batch":
        costs = [np.inf if r.cost is None else r.cost for r in results]
        best = int(np.argmin(costs))
        r = results[best]
        return _with(r, {k: v for k, v in r.estimates.items()}, np.full(len(r.main), best),
                     (*r.warnings, (float(r.main.times[-1]), f"{note}; hypothesis {best} has the lowest cost")),
                     time.perf_counter() - t_begin)
    ekfs = results if name == "ekf" else [run_ekf(measurements, model, h, settings) for h in hyps]
    L = np.array([e.log_likelihood for e in ekfs])
    t_ekf = ekfs[0].main.times

    def leaders(times: np.ndarray) -> np.ndarray:
        idx = np.clip(np.searchsorted(t_ekf, times, side="right") - 1, 0, t_ekf.size - 1)
        return np.argmax(L[:, idx], axis=0)

    final = int(np.argmax(L[:, -1]))
    stitched = {}
    for key, est in results[0].estimates.items():
        choice = leaders(est.times) if key == "filtered" else np.full(len(est), final)
        stitched[key] = type(est)(
            times=est.times,
            states=np.array([results[h].estimates[key].states[i] for i, h in enumerate(choice)]),
            covariances=np.array([results[h].estimates[key].covariances[i] for i, h in enumerate(choice)]),
            cov_ok=np.array([results[h].estimates[key].cov_ok[i] for i, h in enumerate(choice)], dtype=bool),
        )
    primary = results[0].primary
    hyp = leaders(stitched[primary].times) if primary == "filtered" else np.full(len(stitched[primary]), final)
    warnings = (*results[final].warnings, (float(t_ekf[-1]), f"{note}; hypothesis {final} leads at the end"))
    return _with(results[final], stitched, hyp, warnings, time.perf_counter() - t_begin)


def _with(r: TrackResult, estimates: dict, hypothesis: object, warnings: tuple, wall: float) -> TrackResult:
    from dataclasses import replace

    import numpy as np

    return replace(r, estimates=estimates, hypothesis=np.asarray(hypothesis, dtype=np.int64), warnings=warnings,
                   wall_time=wall)
