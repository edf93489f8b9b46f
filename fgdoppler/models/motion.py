r"""Nearly constant velocity (NCV) motion model, paper Eq. 2–6.

.. math::

    \mathbf x_{k} = \mathbf F(T)\,\mathbf x_{k-1} + \mathbf w_{k-1},\qquad
    \mathbf F(T) = \begin{bmatrix} \mathbf I & T\mathbf I\\ \mathbf 0 & \mathbf I\end{bmatrix}.

Two process-noise forms are provided (per axis, ``q`` the noise level):

``"discrete"`` — the paper's discrete white-noise acceleration,
:math:`\mathbf Q = \boldsymbol\Gamma\mathbf q\boldsymbol\Gamma'` with
:math:`\boldsymbol\Gamma = [T^2/2,\; T]'` per axis and ``q`` the acceleration
variance (m²/s⁴).  It has rank 2, so it cannot be the covariance of a
4-dimensional Gaussian factor: whitening by its inverse square root gives NaN.

``"continuous"`` — continuous white-noise acceleration with power spectral
density ``q`` (m²/s³),

.. math::

    \mathbf Q(T) = q \begin{bmatrix} T^3/3 & T^2/2\\ T^2/2 & T\end{bmatrix}\otimes\mathbf I_d,

which has full rank for :math:`T > 0`.  The factor graph, the EKF and the
simulator all use this form by default, so every estimator shares one
well-posed model; the discrete form is kept for comparison with the paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ConstantVelocity"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class ConstantVelocity:
    """Nearly constant velocity model with state ``[p, v]``: ``[x, y, vx, vy]`` (``dim=2``) or
    ``[x, y, z, vx, vy, vz]`` (``dim=3``), the same isotropic noise on every axis.

    Parameters
    ----------
    q
        Process-noise level: power spectral density in m²/s³ for
        ``form="continuous"``, acceleration variance in m²/s⁴ for
        ``form="discrete"``.  Zero gives a deterministic model (allowed for
        simulation, rejected by :meth:`sqrt_information`).
    form
        ``"continuous"`` (full rank, default) or ``"discrete"`` (the paper's
        rank-2 :math:`\\Gamma q \\Gamma'`).
    dim
        Spatial dimension, 2 or 3 (:class:`~fgdoppler.models.tracking.TrackingModel`
        sets it from the geometry).
    """

    q: float = 1e-2
    form: Literal["continuous", "discrete"] = "continuous"
    dim: int = 2

    def __post_init__(self) -> None:
        if self.dim not in (2, 3) or isinstance(self.dim, bool):
            raise ValueError(f"dim must be 2 or 3, got {self.dim!r}")
        if not np.isfinite(self.q) or self.q < 0:
            raise ValueError(f"process noise q must be finite and >= 0, got {self.q}")
        if self.form not in ("continuous", "discrete"):
            raise ValueError(f"form must be 'continuous' or 'discrete', got {self.form!r}")

    @property
    def n(self) -> int:
        """State length ``2 * dim``."""
        return 2 * self.dim

    def F(self, dt: ArrayLike) -> FloatArray:
        """State transition matrix, shape ``(..., 2d, 2d)`` for ``dt`` of shape ``(...)``."""
        d = self.dim
        dt = np.asarray(dt, dtype=float)
        out = np.broadcast_to(np.eye(2 * d), (*dt.shape, 2 * d, 2 * d)).copy()
        for i in range(d):
            out[..., i, i + d] = dt
        return out

    def Q(self, dt: ArrayLike) -> FloatArray:
        """Process-noise covariance, shape ``(..., 2d, 2d)`` for ``dt`` of shape ``(...)``."""
        dt = np.asarray(dt, dtype=float)
        if self.form == "continuous":
            a, b, c = dt**3 / 3.0, dt**2 / 2.0, dt
        else:
            a, b, c = dt**4 / 4.0, dt**3 / 2.0, dt**2
        d = self.dim
        out = np.zeros((*dt.shape, 2 * d, 2 * d))
        for i in range(d):
            out[..., i, i] = a
            out[..., i, i + d] = b
            out[..., i + d, i] = b
            out[..., i + d, i + d] = c
        return self.q * out

    def propagate(self, states: ArrayLike, dt: ArrayLike) -> FloatArray:
        """Noise-free prediction ``F(dt) x``; ``states (..., 2d)`` and ``dt`` broadcast."""
        x = np.asarray(states, dtype=float)
        d = self.dim
        if x.shape[-1] != 2 * d:
            raise ValueError(f"a {d}-D motion model takes states of {2 * d} numbers, got shape {x.shape}")
        dt = np.asarray(dt, dtype=float)[..., None]
        pos = x[..., :d] + dt * x[..., d:]
        return np.concatenate([pos, np.broadcast_to(x[..., d:], pos.shape)], axis=-1)

    def along(self, times: ArrayLike, states: ArrayLike, at: ArrayLike) -> FloatArray:
        r"""A track ``(times, states)`` (time-ordered) read at times ``at`` ``(m,)``: each from the track's last
        state at or before it (the first where none is), carried noise-free, :math:`\mathbf F(t - t_j)\mathbf x_j`."""
        t = np.asarray(times, dtype=float)
        when = np.asarray(at, dtype=float)
        j = np.clip(np.searchsorted(t, when, side="right") - 1, 0, t.size - 1)
        return self.propagate(np.asarray(states, dtype=float)[j], when - t[j])

    def predict_covariance(self, P: ArrayLike, dt: float) -> FloatArray:
        r"""Covariance of the prediction over ``dt``: :math:`\mathbf F\mathbf P\mathbf F' + \mathbf Q(dt)`."""
        F = self.F(dt)
        return F @ np.asarray(P, dtype=float) @ F.T + self.Q(dt)

    def sqrt_information(self, dt: float) -> FloatArray:
        r"""Square-root information :math:`\mathbf R = \mathbf L^{-1}` (:math:`\mathbf Q = \mathbf L\mathbf L'`), so :math:`\mathbf R'\mathbf R = \mathbf Q(dt)^{-1}`.

        Raises
        ------
        ValueError
            If ``Q(dt)`` is singular (the discrete form, ``q = 0`` or ``dt <= 0``).
        """
        if self.form != "continuous" or self.q <= 0 or not dt > 0:
            raise ValueError(
                "a motion factor needs a full-rank Q: use form='continuous' with q > 0 and dt > 0 "
                f"(got form={self.form!r}, q={self.q}, dt={dt})"
            )
        L = np.linalg.cholesky(self.Q(dt))
        return np.linalg.inv(L)

    def sample_track(self, x0: ArrayLike, times: ArrayLike, rng: np.random.Generator) -> FloatArray:
        r"""A track of this model from ``x0`` at time 0, read at ``times`` (increasing), ``(m, 2d)``.

        From :math:`t = 0` on, :math:`\mathbf x_{k+1} = \mathbf F(\Delta t_k)\mathbf x_k + \mathbf w_k`,
        :math:`\mathbf w_k \sim \mathcal N(0, \mathbf Q(\Delta t_k))` (one draw of :meth:`sample_noise` per
        step, in time order; a repeated time repeats the state); before it, :math:`\mathbf F(t)\mathbf x_0`
        without noise (a clock running early reads the track before its start).
        """
        x0 = np.asarray(x0, dtype=float)
        t_all = np.asarray(times, dtype=float)
        states = np.empty((t_all.size, x0.size))
        x = x0.copy()
        t_prev = 0.0
        for k, t in enumerate(t_all):
            if t < 0:
                states[k] = self.propagate(x0, t)
                continue
            dt = t - t_prev
            if dt > 0:
                x = self.propagate(x, dt) + self.sample_noise(dt, rng)
            states[k] = x
            t_prev = t
        return states

    def sample_noise(self, dt: float, rng: np.random.Generator, size: int | None = None) -> FloatArray:
        """Draw process noise ``w ~ N(0, Q(dt))`` (works for the rank-2 form too)."""
        Q = self.Q(dt)
        w, V = np.linalg.eigh(Q)
        A = V * np.sqrt(np.clip(w, 0.0, None))
        n = 1 if size is None else size
        out = rng.standard_normal((n, 2 * self.dim)) @ A.T
        return out[0] if size is None else out
