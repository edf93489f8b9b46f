"""The measurement and motion models: one numpy implementation used everywhere."""

from fgdoppler.models.doppler import (
    StackedTimes,
    bistatic_doppler,
    bistatic_doppler_and_jacobian,
    bistatic_doppler_jacobian,
    cv_doppler,
    cv_doppler_and_jacobian,
    cv_doppler_jacobian,
    cv_information,
)
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import DopplerModel, MeasurementModel
from fgdoppler.models.tracking import TrackingModel, as_tracking_model

__all__ = [
    "ConstantVelocity",
    "DopplerModel",
    "MeasurementModel",
    "StackedTimes",
    "TrackingModel",
    "as_tracking_model",
    "bistatic_doppler",
    "bistatic_doppler_and_jacobian",
    "bistatic_doppler_jacobian",
    "cv_doppler",
    "cv_doppler_and_jacobian",
    "cv_doppler_jacobian",
    "cv_information",
]
