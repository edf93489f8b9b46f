"""The measurement and motion models: one numpy implementation used everywhere."""

from fgdoppler.models.doppler import (
    BatchTimes,
    batch_doppler,
    batch_doppler_and_jacobian,
    batch_doppler_jacobian,
    bistatic_doppler,
    bistatic_doppler_and_jacobian,
    bistatic_doppler_jacobian,
)
from fgdoppler.models.motion import ConstantVelocity

__all__ = [
    "BatchTimes",
    "ConstantVelocity",
    "batch_doppler",
    "batch_doppler_and_jacobian",
    "batch_doppler_jacobian",
    "bistatic_doppler",
    "bistatic_doppler_and_jacobian",
    "bistatic_doppler_jacobian",
]
