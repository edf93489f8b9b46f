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
) -> TrackResult:
    """Run the estimator called ``name`` (one of :data:`ESTIMATORS`)."""
    from fgdoppler.estimators.batch import run_batch
    from fgdoppler.estimators.ekf import run_ekf
    from fgdoppler.estimators.fixed_lag import run_fixed_lag
    from fgdoppler.estimators.isam2 import run_isam2

    runners = {"ekf": run_ekf, "isam2": run_isam2, "fixed-lag": run_fixed_lag, "batch": run_batch}
    if name not in runners:
        raise ValueError(f"unknown estimator {name!r}: expected one of {', '.join(ESTIMATORS)}")
    return runners[name](measurements, model, init, settings)
