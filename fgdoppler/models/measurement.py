"""Deprecated location of :mod:`fgdoppler.models.observation` (the documentation used to import from here)."""

import warnings

from fgdoppler.models.observation import DopplerModel, MeasurementModel

warnings.warn("fgdoppler.models.measurement is now fgdoppler.models.observation (or use fgdoppler.DopplerModel)",
              DeprecationWarning, stacklevel=2)

__all__ = ["DopplerModel", "MeasurementModel"]
