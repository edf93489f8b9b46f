"""Estimators: initiation, EKF, iSAM2, fixed-lag and offline smoothers, a particle filter.

All trackers share one signature, ``run(measurements, model, init, settings)
-> TrackResult``; :data:`ESTIMATORS` lists them and :func:`run_estimator`
picks one by name.
"""

from typing import TYPE_CHECKING

from fgdoppler._lazy import attach

#: Where each public name lives: its module is imported on first use (:mod:`fgdoppler._lazy`), so that
#: ``fgdoppler --help`` loads no estimator.  Type checkers read the same names from the imports below.
_HOMES: dict[str, tuple[str, ...]] = {
    "fgdoppler.estimators.initiation": ("METHODS", "Initiation", "InitiationSettings", "initiate"),
    "fgdoppler.estimators.registry": (
        "ALIASES", "ESTIMATORS", "EstimatorInfo", "estimator_info", "run_estimator", "run_estimators",
        "track",
    ),
    "fgdoppler.estimators.results": ("Estimates", "OffsetEstimate", "TrackResult"),
    "fgdoppler.estimators.settings": (
        "EKFSettings", "FixedLagSettings", "GaussianSumSettings", "ISAM2Settings", "MapSettings",
        "ParticleSettings", "SampledCovarianceSettings", "SmootherSettings", "StreamingSettings",
        "TrackerSettings",
    ),
    "fgdoppler.estimators.verdict": ("STATUSES", "Event", "Reason"),
}

if TYPE_CHECKING:
    from fgdoppler.estimators.initiation import METHODS, Initiation, InitiationSettings, initiate
    from fgdoppler.estimators.registry import (
        ALIASES,
        ESTIMATORS,
        EstimatorInfo,
        estimator_info,
        run_estimator,
        run_estimators,
        track,
    )
    from fgdoppler.estimators.results import Estimates, OffsetEstimate, TrackResult
    from fgdoppler.estimators.settings import (
        EKFSettings,
        FixedLagSettings,
        GaussianSumSettings,
        ISAM2Settings,
        MapSettings,
        ParticleSettings,
        SampledCovarianceSettings,
        SmootherSettings,
        StreamingSettings,
        TrackerSettings,
    )
    from fgdoppler.estimators.verdict import STATUSES, Event, Reason
else:
    __getattr__, __dir__ = attach(__name__, _HOMES)

__all__ = [
    "ALIASES",
    "ESTIMATORS",
    "METHODS",
    "STATUSES",
    "EKFSettings",
    "Estimates",
    "EstimatorInfo",
    "Event",
    "FixedLagSettings",
    "GaussianSumSettings",
    "ISAM2Settings",
    "Initiation",
    "InitiationSettings",
    "MapSettings",
    "OffsetEstimate",
    "ParticleSettings",
    "Reason",
    "SampledCovarianceSettings",
    "SmootherSettings",
    "StreamingSettings",
    "TrackResult",
    "TrackerSettings",
    "estimator_info",
    "initiate",
    "run_estimator",
    "run_estimators",
    "track",
]
