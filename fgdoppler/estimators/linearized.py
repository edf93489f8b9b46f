r"""Linearising the tracking graph in numpy, for graphs too long for ``CustomFactor`` callbacks.

GTSAM passes a ``CustomFactor`` callback a copy of the *whole* ``Values``, so
a callback costs O(number of states) and long graphs cost O(N²) per
linearisation.  The long-running estimators (iSAM2, offline batch) therefore
linearise the measurement model themselves, vectorised over all rows at
once, and hand GTSAM native linear factors:

* measurement rows, whitened and Huber-reweighted:
  :math:`\sqrt{w_j}\,\mathbf H_j/\sigma_j` with right-hand side
  :math:`\sqrt{w_j}\,(z_j - h_j(\bar{\mathbf x}))/\sigma_j`;
* motion rows :math:`\mathbf L^{-1}[-\mathbf F,\ \mathbf I]` with
  :math:`\mathbf Q = \mathbf L\mathbf L'` (exact: the model is linear).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import MeasurementModel
from fgdoppler.models.robust import huber_weights

__all__ = ["LinearRows", "MotionBlocks", "linearize_rows"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class LinearRows:
    """Whitened measurement rows at a linearisation point."""

    A: FloatArray  # (m, n)
    b: FloatArray  # (m,) whitened residual z - h at the point (Huber weighted)
    scale: FloatArray  # (m,) each row's whitening sqrt(w_j) / sigma_j: the rows of anything added to h


def linearize_rows(
    model: MeasurementModel,
    states: FloatArray,
    channels: NDArray[np.intp],
    z: FloatArray,
    sigma: FloatArray,
    huber_k: float | None = None,
) -> LinearRows:
    """Whitened Jacobian rows and residuals of every measurement at ``states`` (one row each)."""
    h, H = model.predict_and_jacobian(states, channels)
    r = (z - h) / sigma
    s = np.sqrt(huber_weights(r, huber_k)) / sigma
    return LinearRows(A=H * s[:, None], b=(z - h) * s, scale=s)


class MotionBlocks:
    """Whitened motion blocks ``(-R F, R)`` per time step, cached by step length."""

    def __init__(self, motion: ConstantVelocity) -> None:
        self.motion = motion
        self._cache: dict[float, tuple[FloatArray, FloatArray]] = {}

    def __call__(self, dt: float) -> tuple[FloatArray, FloatArray]:
        """``(A_prev, A_next)`` with residual ``A_prev x_prev + A_next x_next``."""
        key = round(float(dt), 12)
        blk = self._cache.get(key)
        if blk is None:
            R = self.motion.sqrt_information(dt)
            blk = (-R @ self.motion.F(dt), R)
            self._cache[key] = blk
        return blk

    def residuals(self, states: FloatArray, times: FloatArray) -> FloatArray:
        """Whitened motion residuals ``(n-1, 2d)`` of a trajectory."""
        out = np.empty((max(states.shape[0] - 1, 0), self.motion.n))
        dts = np.diff(times)
        # steps are few distinct lengths (one per sampling pattern): vectorise per length
        for dt in np.unique(np.round(dts, 12)):
            idx = np.flatnonzero(np.round(dts, 12) == dt)
            Ap, An = self(float(dts[idx[0]]))
            out[idx] = states[idx] @ Ap.T + states[idx + 1] @ An.T
        return out
