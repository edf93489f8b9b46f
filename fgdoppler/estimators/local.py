r"""The frame a streaming tracker computes in: its model's computation frame, as in the registry.

:func:`~fgdoppler.estimators.registry.run_estimator` solves every problem in
the geometry's own frame (:attr:`~fgdoppler.models.tracking.TrackingModel.computation_frame`,
sensors snapped to a millimetre lattice) and answers in the user's, so a
rigidly moved recording gives the moved answer to rounding.  A tracker fed
by hand (:class:`~fgdoppler.estimators.isam2.ISAM2Tracker`,
:class:`~fgdoppler.estimators.fixed_lag.FixedLagTracker`) does the same
through :class:`LocalFrame`: its model is moved into that frame once, and
states cross at its public boundary — guesses and priors in, estimates out
(:math:`\mathbf x_\mathrm{local} = \mathbf T(\mathbf x - \mathbf o)`,
:math:`\mathbf P_\mathrm{local} = \mathbf T\mathbf P\mathbf T'`,
:mod:`fgdoppler.frames`).

Measured, streaming one recording and the same recording rigidly moved
(rotations, reflections, translations up to 1,000 km; the three motions of
``tests/test_invariance.py``), largest difference of the filtered iSAM2
states after moving back.  In the user's coordinates: with the model's weak
prior, case a 45 km 6 cm and case b 25 km 54 m (its relinearisation
decisions fell differently); case b without a prior, 744 km to 172,000 km
(the stream went astray in every moved frame).  In the computation frame:
0.15 mm, and without a prior 1e-10 m.  A prior given in
the user's coordinates arrives rounded (6e-13 m in the weak prior's mean),
and a poorly observed stream is sensitive enough to carry that to tens of
metres (case b 25 km: 42–55 m, well inside its kilometre standard
deviation).

Every runner (``run_ekf``, ``run_isam2``, ``run_fixed_lag``,
``run_smoother``, ``run_particle``) called directly, not through the
registry, moves its problem the same way (:func:`in_computation_frame`):
the initiation it is given keeps the copy computed in that frame, so the
answer moves with the problem to rounding.  Called in the user's
coordinates instead, case b 25 km in a rotated frame 830 km from the origin
gave iSAM2 states 46 m and particle states 152 m from the moved answer
(the EKF, the fixed-lag smoother and the smoother within 5 mm).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.frames import Frame
from fgdoppler.models.tracking import TrackingModel

if TYPE_CHECKING:
    from fgdoppler.estimators.initiation import Initiation
    from fgdoppler.estimators.results import TrackResult
    from fgdoppler.measurements import Measurements

__all__ = ["LocalFrame", "in_computation_frame"]

FloatArray = NDArray[np.float64]
Run = TypeVar("Run", bound=Callable[..., "TrackResult"])


@dataclass(frozen=True)
class LocalFrame:
    """Conversions between the user's coordinates and a tracker's computation frame.

    Parameters
    ----------
    frame
        The computation frame, or ``None`` when the model computes in place
        (:attr:`~fgdoppler.models.tracking.TrackingModel.canonical`): then
        every conversion returns its input unchanged.
    """

    frame: Frame | None

    @classmethod
    def of(cls, model: TrackingModel) -> tuple[LocalFrame, TrackingModel]:
        """The frame of ``model`` and the model moved into it."""
        if model.canonical:
            return cls(None), model
        frame = model.computation_frame
        return cls(frame), model.in_frame(frame)

    def state_in(self, x: ArrayLike) -> FloatArray:
        """A state ``(n,)`` or states ``(..., n)`` from the user's coordinates into the frame."""
        x = np.asarray(x, dtype=float)
        return x if self.frame is None else self.frame.states_to_local(x)

    def prior_in(self, prior: tuple[ArrayLike, ArrayLike] | None) -> tuple[FloatArray, FloatArray] | None:
        """A ``(mean, covariance)`` into the frame."""
        if prior is None:
            return None
        mean, cov = np.asarray(prior[0], dtype=float), np.asarray(prior[1], dtype=float)
        if self.frame is None:
            return mean, cov
        return self.frame.states_to_local(mean), self.frame.covariances_to_local(cov)

    def out(self, x: FloatArray, P: FloatArray | None) -> tuple[FloatArray, FloatArray | None]:
        """Estimates (and covariances, or ``None``) from the frame into the user's coordinates."""
        if self.frame is None:
            return x, P
        return self.frame.states_to_world(x), None if P is None else self.frame.covariances_to_world(P)


def in_computation_frame(run: Run) -> Run:
    """Make ``run(measurements, model, init, settings, **options)`` solve in ``model``'s computation frame.

    A canonical model runs as it is.  Otherwise the model and the
    initiation move into the frame, the run's result moves back
    (:meth:`~fgdoppler.estimators.results.TrackResult.transformed`); a
    ``fallback_covariance`` option (the EKF's) moves in with them.
    """
    @functools.wraps(run)
    def framed(measurements: Measurements, model: TrackingModel, init: Initiation, *args: Any,
               **options: Any) -> TrackResult:
        if model.canonical:
            return run(measurements, model, init, *args, **options)
        frame = model.computation_frame
        if options.get("fallback_covariance") is not None:
            options["fallback_covariance"] = frame.covariances_to_local(options["fallback_covariance"])
        local = run(measurements, model.in_frame(frame), init.in_frame_of(frame), *args, **options)
        return local.transformed(frame, to_world=True)

    return cast(Run, framed)
