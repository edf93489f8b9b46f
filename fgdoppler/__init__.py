"""fgdoppler: Doppler-only multistatic tracking near the Tx–Rx baseline.

Bistatic Doppler models and their GTSAM factors, multi-start track initiation,
EKF / iSAM2 / fixed-lag / offline smoothers, observability analysis and Monte
Carlo studies reproducing Yang, Leung & Bar-Shalom (FUSION 2026).

The names here are what a first track needs::

    import fgdoppler as fd
    geometry = fd.paper_geometry("b")
    sim = fd.simulate(fd.paper_scenario("b", 5e3), rng)
    result = fd.track(sim.measurements, geometry, "smoother")
    result.status, result.primary.states
"""

from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING

from fgdoppler._lazy import attach

#: Where each public name lives: its module is imported on first use (:mod:`fgdoppler._lazy`), so that
#: ``fgdoppler --help`` loads no estimator.  Type checkers read the same names from the imports below.
_HOMES: dict[str, tuple[str, ...]] = {
    "fgdoppler.analysis.observability": ("observability_measure",),
    "fgdoppler.error_draws": ("ErrorDraws",),
    "fgdoppler.estimators": (
        "ESTIMATORS", "METHODS", "STATUSES", "EKFSettings", "Estimates", "Event", "FixedLagSettings",
        "Initiation", "InitiationSettings", "ISAM2Settings", "MapSettings", "OffsetEstimate",
        "ParticleSettings", "Reason", "SmootherSettings", "TrackerSettings", "TrackResult", "initiate",
        "run_estimator", "run_estimators", "track",
    ),
    "fgdoppler.estimators.grid": ("GridSpec", "HalfPlane"),
    "fgdoppler.frames": ("Frame",),
    "fgdoppler.geodetic": ("GeodeticOrigin",),
    "fgdoppler.geometry": (
        "BistaticPair", "Geometry", "bistatic_range", "ellipse_tangent", "paper_geometry",
        "resolve_geometry",
    ),
    "fgdoppler.measurements": ("MeasurementError", "Measurements"),
    "fgdoppler.models": (
        "ConstantVelocity", "DopplerModel", "MeasurementModel", "StackedTimes", "TrackingModel",
        "bistatic_doppler", "bistatic_doppler_and_jacobian", "bistatic_doppler_jacobian", "cv_doppler",
        "cv_doppler_and_jacobian", "cv_doppler_jacobian", "cv_information",
    ),
    "fgdoppler.progress": ("Progress", "TqdmProgress"),
    "fgdoppler.simulation": (
        "Manoeuvre", "Scenario", "Simulation", "Trajectory", "paper_scenario", "paper_scenarios",
        "simulate",
    ),
    "fgdoppler.zone": ("Zone", "ZoneBox"),
}

if TYPE_CHECKING:
    from fgdoppler.analysis.observability import observability_measure
    from fgdoppler.error_draws import ErrorDraws
    from fgdoppler.estimators import (
        ESTIMATORS,
        METHODS,
        STATUSES,
        EKFSettings,
        Estimates,
        Event,
        FixedLagSettings,
        Initiation,
        InitiationSettings,
        ISAM2Settings,
        MapSettings,
        OffsetEstimate,
        ParticleSettings,
        Reason,
        SmootherSettings,
        TrackerSettings,
        TrackResult,
        initiate,
        run_estimator,
        run_estimators,
        track,
    )
    from fgdoppler.estimators.grid import GridSpec, HalfPlane
    from fgdoppler.frames import Frame
    from fgdoppler.geodetic import GeodeticOrigin
    from fgdoppler.geometry import (
        BistaticPair,
        Geometry,
        bistatic_range,
        ellipse_tangent,
        paper_geometry,
        resolve_geometry,
    )
    from fgdoppler.measurements import MeasurementError, Measurements
    from fgdoppler.models import (
        ConstantVelocity,
        DopplerModel,
        MeasurementModel,
        StackedTimes,
        TrackingModel,
        bistatic_doppler,
        bistatic_doppler_and_jacobian,
        bistatic_doppler_jacobian,
        cv_doppler,
        cv_doppler_and_jacobian,
        cv_doppler_jacobian,
        cv_information,
    )
    from fgdoppler.progress import Progress, TqdmProgress
    from fgdoppler.simulation import (
        Manoeuvre,
        Scenario,
        Simulation,
        Trajectory,
        paper_scenario,
        paper_scenarios,
        simulate,
    )
    from fgdoppler.zone import Zone, ZoneBox
else:
    __getattr__, __dir__ = attach(__name__, _HOMES)

try:
    __version__ = version("fgdoppler")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = [
    "ESTIMATORS",
    "METHODS",
    "STATUSES",
    "BistaticPair",
    "ConstantVelocity",
    "DopplerModel",
    "EKFSettings",
    "ErrorDraws",
    "Estimates",
    "Event",
    "FixedLagSettings",
    "Frame",
    "GeodeticOrigin",
    "Geometry",
    "GridSpec",
    "HalfPlane",
    "ISAM2Settings",
    "Initiation",
    "InitiationSettings",
    "Manoeuvre",
    "MapSettings",
    "MeasurementError",
    "MeasurementModel",
    "Measurements",
    "OffsetEstimate",
    "ParticleSettings",
    "Progress",
    "Reason",
    "Scenario",
    "Simulation",
    "SmootherSettings",
    "StackedTimes",
    "TqdmProgress",
    "TrackResult",
    "TrackerSettings",
    "TrackingModel",
    "Trajectory",
    "Zone",
    "ZoneBox",
    "__version__",
    "bistatic_doppler",
    "bistatic_doppler_and_jacobian",
    "bistatic_doppler_jacobian",
    "bistatic_range",
    "cv_doppler",
    "cv_doppler_and_jacobian",
    "cv_doppler_jacobian",
    "cv_information",
    "ellipse_tangent",
    "initiate",
    "observability_measure",
    "paper_geometry",
    "paper_scenario",
    "paper_scenarios",
    "resolve_geometry",
    "run_estimator",
    "run_estimators",
    "simulate",
    "track",
]
