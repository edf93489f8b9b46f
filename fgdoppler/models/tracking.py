"""The tracking model: what every estimator of one recording shares.

A :class:`TrackingModel` bundles the observation model (how the target is
measured), the motion model (how it moves) and the prior knowledge of where
it starts (the zone and its weak prior).  The initiation, the EKF, iSAM2, the
fixed-lag smoother and the offline smoother all take one, so the model is
stated once; each estimator's own options live in its settings class.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgdoppler.frames import Frame
from fgdoppler.geometry import Geometry
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import DopplerModel, MeasurementModel
from fgdoppler.zone import Zone

__all__ = ["TrackingModel", "as_tracking_model", "default_motion"]

FloatArray = NDArray[np.float64]


def default_motion() -> ConstantVelocity:
    """The estimators' motion model unless told otherwise: white-noise acceleration with ``q = 1e-3`` m²/s³."""
    return ConstantVelocity(q=1e-3)


@dataclass(frozen=True, kw_only=True)
class TrackingModel:
    """Observation, motion and start-zone model shared by every estimator.

    Parameters
    ----------
    observation
        The measurement model, e.g. :class:`~fgdoppler.models.observation.DopplerModel`.
    motion
        Nearly-constant-velocity model with a full-rank process noise
        (continuous white-noise acceleration, PSD ``q = 1e-3`` m²/s³ by default).
    zone
        Where a track may start: the initiation lays its candidate grid out in
        it and bounds the start state by it; the weak prior spans it.
        ``None``: the geometry's zone (:attr:`fgdoppler.geometry.Geometry.zone`,
        the default rule with the geometry file's ``[zone]`` overrides) for a
        Doppler model, no zone for other models.
    weak_prior
        Put the zone's weak Gaussian prior (:meth:`fgdoppler.zone.Zone.prior`)
        on the first state of every graph.  It regularises near-singular
        windows — without it Levenberg–Marquardt can run off to non-physical
        speeds along the flat valleys of a poorly observed window — and
        barely moves a well-posed one.
    frame
        Where the estimators compute (``None``: the geometry's own frame,
        :attr:`fgdoppler.geometry.Geometry.frame`; world coordinates for other
        models).  :func:`~fgdoppler.estimators.initiation.initiate` and
        :func:`~fgdoppler.estimators.registry.run_estimator` move the problem
        into it and the answer back, so a rigid motion of the whole problem
        moves the answer with it and coordinates stay small (a recording
        1,000 km from the origin is solved as well as one at it).
    """

    observation: MeasurementModel
    motion: ConstantVelocity = field(default_factory=default_motion)
    zone: Zone | None = None
    weak_prior: bool = True
    frame: Frame | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.observation, MeasurementModel):
            raise TypeError(f"observation must be a MeasurementModel, got {type(self.observation).__name__}")
        if not isinstance(self.motion, ConstantVelocity):
            raise TypeError(f"motion must be a ConstantVelocity model, got {type(self.motion).__name__}")
        geometry = self.observation.geometry if isinstance(self.observation, DopplerModel) else None
        dim = getattr(self.observation, "state_dim", 4) // 2
        if self.motion.dim != dim:  # one motion model for any dimension: follow the observation's states
            object.__setattr__(self, "motion", replace(self.motion, dim=dim))
        if self.zone is None and geometry is not None:
            object.__setattr__(self, "zone", geometry.zone)
        if self.frame is None:
            object.__setattr__(self, "frame", Frame.identity(dim) if geometry is None else geometry.frame)
        if self.zone is not None and self.zone.dim != dim:
            raise ValueError(f"a {self.zone.dim}-D zone for {dim}-D states: give the zone an altitude band exactly "
                             "when the problem is 3-D")

    @classmethod
    def of(cls, geometry: Geometry, **kwargs: Any) -> TrackingModel:
        """The bistatic Doppler model of ``geometry`` with the given motion, zone and prior."""
        return cls(observation=DopplerModel(geometry=geometry), **kwargs)

    @property
    def dim(self) -> int:
        """Spatial dimension of the states (2 or 3)."""
        return self.motion.dim

    @property
    def n(self) -> int:
        """State length, ``2 * dim``."""
        return self.motion.n

    @property
    def geometry(self) -> Geometry:
        """The sensor geometry (Doppler models only).

        Raises
        ------
        TypeError
            If the observation model has no geometry.
        """
        if not isinstance(self.observation, DopplerModel):
            raise TypeError(f"a {type(self.observation).__name__} has no sensor geometry")
        return self.observation.geometry

    def prior(self) -> tuple[FloatArray, FloatArray] | None:
        """``(mean, covariance)`` of the weak prior on the first state, or ``None`` when it is off."""
        if not self.weak_prior or self.zone is None:
            return None
        return self.zone.prior()

    def with_zone(self, zone: Zone) -> TrackingModel:
        """The same model with another zone."""
        return replace(self, zone=zone)

    @property
    def computation_frame(self) -> Frame:
        """:attr:`frame`, resolved (never ``None`` after construction)."""
        assert self.frame is not None
        return self.frame

    @property
    def canonical(self) -> bool:
        """True if the model already computes in place: identity frame and sensors on the snap lattice."""
        if not self.computation_frame.is_identity:
            return False
        return not isinstance(self.observation, DopplerModel) or self.observation.geometry.on_lattice

    def in_frame(self, frame: Frame) -> TrackingModel:
        """The same model with positions in ``frame``'s local coordinates, computing there (frame identity).

        The sensors are snapped to the 1 mm lattice of
        :meth:`~fgdoppler.geometry.Geometry.in_frame`.  Only Doppler models can
        move (their geometry does); the motion model is the same in any
        Cartesian frame (its Q is isotropic).
        """
        if not isinstance(self.observation, DopplerModel):
            if frame.is_identity:
                return self
            raise TypeError(f"a {type(self.observation).__name__} cannot be moved into another frame")
        geometry = self.observation.geometry
        local = geometry.in_frame(frame)
        if self.zone is None:
            zone = None
        elif self.zone == geometry.zone:  # the geometry's own zone: rebuilt from the snapped sensors
            zone = local.zone
        else:
            zone = self.zone.relative_to(frame)
        return replace(self, observation=DopplerModel(geometry=local), zone=zone, frame=Frame.identity())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (motion, zone, prior)."""
        return {"motion": {"q": self.motion.q, "form": self.motion.form},
                "zone": None if self.zone is None else self.zone.to_dict(), "weak_prior": self.weak_prior,
                "frame": self.computation_frame.to_dict()}


def as_tracking_model(model: TrackingModel | Geometry | MeasurementModel) -> TrackingModel:
    """A :class:`TrackingModel` from itself, a geometry or an observation model (every other default)."""
    if isinstance(model, TrackingModel):
        return model
    if isinstance(model, Geometry):
        return TrackingModel.of(model)
    if isinstance(model, MeasurementModel):
        return TrackingModel(observation=model)
    raise TypeError(f"expected a TrackingModel, a Geometry or a MeasurementModel, got {type(model).__name__}")
