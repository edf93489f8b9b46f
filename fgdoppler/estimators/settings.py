"""Settings of the trackers: a shared base and one class per estimator with only its options.

The model every estimator shares (observation, motion, zone, weak prior) is
a :class:`~fgdoppler.models.tracking.TrackingModel`; the classes here hold
how each estimator works on it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from scipy.stats import chi2

__all__ = ["EKFSettings", "FixedLagSettings", "ISAM2Settings", "SmootherSettings", "TrackerSettings"]


def _positive(value: float, name: str) -> None:
    if isinstance(value, bool) or not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number, got {value!r}")


def _count(value: int, name: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a whole number >= 1, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class TrackerSettings:
    """Base of every tracker's settings: the measurement gate and the robust loss.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate: a measurement whose normalised innovation against the
        prediction exceeds the χ²₁ quantile at this probability is rejected
        and reported.  ``None`` disables gating.  (The offline smoother gates
        only the EKF pass that starts it.)
    huber_k : float or None, default None
        Huber loss with this threshold (whitened units; 1.345 gives 95 %
        efficiency on Gaussian data) on every Doppler residual: quadratic up
        to ``k``, linear beyond, so a few gross outliers cannot drag the
        estimate.  ``None`` for the Gaussian loss.
    """

    gate_probability: float | None = 0.9999
    huber_k: float | None = None

    def __post_init__(self) -> None:
        p = self.gate_probability
        if p is not None and (isinstance(p, bool) or not 0 < p < 1):
            raise ValueError(f"gate_probability must be in (0, 1) or None, got {p!r}")
        if self.huber_k is not None:
            _positive(self.huber_k, "huber_k")

    @property
    def gate(self) -> float:
        """NIS threshold (``inf`` when gating is off)."""
        return float(chi2.ppf(self.gate_probability, 1)) if self.gate_probability is not None else math.inf

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, with the class name under ``"type"``."""
        return {"type": type(self).__name__, **dataclasses.asdict(self)}


@dataclass(frozen=True, kw_only=True)
class EKFSettings(TrackerSettings):
    """Extended Kalman filter.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate probability (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold on the normalised innovation: a measurement beyond it
        updates with its variance inflated by ``|ν|/(k√S)`` (see
        :class:`TrackerSettings`).
    """


@dataclass(frozen=True, kw_only=True)
class ISAM2Settings(TrackerSettings):
    """iSAM2 tracker.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate probability (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold (whitened units, e.g. 1.345) on every Doppler
        residual; ``None`` for the Gaussian loss.
    relinearize_position : float, default 10.0
        A Doppler factor is relinearised when its state has moved more than
        this (m) from the linearisation point.  With the Doppler curvature of
        these geometries (|∂²h/∂p²| ≲ v/r² ≈ 3e-5 s⁻¹ m⁻¹ at 2 km) a 10 m move
        changes the linearisation by ~1e-3 m/s, far below σ.
    relinearize_velocity : float, default 0.1
        The same for velocity (m/s).
    relinearize_window : int, default 10
        How many of the most recent scans are checked for relinearisation at
        every update (older states barely move); the whole graph is solved to
        convergence at the end.
    wildfire_threshold : float, default 0.01
        Back-substitution threshold (m and m/s): changes smaller than this are
        not propagated to older states until the end (GTSAM's default 0.001
        made the per-scan cost grow with the track length).
    final_passes : int, default 100
        Cap on the Levenberg–Marquardt iterations of the final smoothing
        (:meth:`~fgdoppler.estimators.isam2.ISAM2Tracker.finish`).
    smoothed_covariances : bool, default True
        Compute the marginal covariance of every smoothed state at the end.
    """

    relinearize_position: float = 10.0
    relinearize_velocity: float = 0.1
    relinearize_window: int = 10
    wildfire_threshold: float = 0.01
    final_passes: int = 100
    smoothed_covariances: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive(self.relinearize_position, "relinearize_position")
        _positive(self.relinearize_velocity, "relinearize_velocity")
        _positive(self.wildfire_threshold, "wildfire_threshold")
        _count(self.relinearize_window, "relinearize_window")
        _count(self.final_passes, "final_passes")


@dataclass(frozen=True, kw_only=True)
class FixedLagSettings(TrackerSettings):
    """Fixed-lag smoother.

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate probability (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold on every Doppler residual; ``None`` for Gaussian.
    lag : float, default 5.0
        Lag in seconds: states older than this are marginalised out.
    final_iterations : int, default 100
        Cap on the smoother iterations that bring the last window to its
        optimum at the end.
    """

    lag: float = 5.0
    final_iterations: int = 100

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive(self.lag, "lag")
        _count(self.final_iterations, "final_iterations")


@dataclass(frozen=True, kw_only=True)
class SmootherSettings(TrackerSettings):
    """Offline smoother (the whole recording by Levenberg–Marquardt).

    Parameters
    ----------
    gate_probability : float or None, default 0.9999
        NIS gate of the EKF pass that gives the smoother its starting
        trajectory (see :class:`TrackerSettings`).
    huber_k : float or None, default None
        Huber threshold on every Doppler residual; ``None`` for Gaussian.
    max_iterations : int, default 100
        Cap on the Levenberg–Marquardt iterations.
    covariances : bool, default True
        Compute the marginal covariance of every state.
    reinitiate : bool, default True
        If the solution cannot explain the data (its cost fails a 99.9 % χ²
        check), initiate again from the whole recording and keep the better.
    """

    max_iterations: int = 100
    covariances: bool = True
    reinitiate: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _count(self.max_iterations, "max_iterations")

    def start(self) -> EKFSettings:
        """Settings of the EKF pass that starts the smoother."""
        return EKFSettings(gate_probability=self.gate_probability, huber_k=self.huber_k)
