"""fgdoppler: Doppler-only multistatic tracking near the Tx–Rx baseline.

Bistatic Doppler models and their GTSAM factors, multi-start track initiation,
EKF / iSAM2 / fixed-lag / batch estimators, observability analysis and Monte
Carlo studies reproducing Yang, Leung & Bar-Shalom (FUSION 2026).
"""

from importlib.metadata import PackageNotFoundError, version

from fgdoppler.analysis.observability import observability_measure
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
    BatchTimes,
    ConstantVelocity,
    batch_doppler,
    batch_doppler_and_jacobian,
    batch_doppler_jacobian,
    bistatic_doppler,
    bistatic_doppler_and_jacobian,
    bistatic_doppler_jacobian,
)
from fgdoppler.simulation import (
    Scenario,
    Simulation,
    Trajectory,
    paper_scenario,
    paper_scenarios,
    simulate,
)

try:
    __version__ = version("fgdoppler")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = [
    "BatchTimes",
    "BistaticPair",
    "ConstantVelocity",
    "Geometry",
    "MeasurementError",
    "Measurements",
    "Scenario",
    "Simulation",
    "Trajectory",
    "__version__",
    "batch_doppler",
    "batch_doppler_and_jacobian",
    "batch_doppler_jacobian",
    "bistatic_doppler",
    "bistatic_doppler_and_jacobian",
    "bistatic_doppler_jacobian",
    "bistatic_range",
    "ellipse_tangent",
    "observability_measure",
    "paper_geometry",
    "paper_scenario",
    "paper_scenarios",
    "resolve_geometry",
    "simulate",
]
