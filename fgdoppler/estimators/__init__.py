"""Estimators: initiation, EKF, iSAM2, fixed-lag and offline smoothers, a particle filter.

All trackers share one signature, ``run(measurements, model, init, settings)
-> TrackResult``; :data:`ESTIMATORS` lists them and :func:`run_estimator`
picks one by name.
"""

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
