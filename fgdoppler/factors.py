r"""GTSAM factors for Doppler-only tracking: thin wrappers over :mod:`fgdoppler.models`.

Every factor's error is the *unwhitened* residual; GTSAM whitens it with the
factor's noise model.

``doppler_factor``
    :class:`gtsam.CustomFactor` on one state key holding *all* measurements
    taken at that state (one Python callback per state, not per measurement):
    :math:`\mathbf e = \mathbf h_{\mathcal P}(\mathbf x_k) - \mathbf z_k`.
``motion_factor``
    Native linear factor between consecutive states,
    :math:`\mathbf e = \mathbf x_{k+1} - \mathbf F(dt)\,\mathbf x_k`, whitened by the
    full-rank continuous-white-noise :math:`\mathbf Q(dt)` (see
    :mod:`fgdoppler.models.motion`).  The model is linear, so a
    :class:`gtsam.JacobianFactor` wrapped in a :class:`gtsam.LinearContainerFactor`
    linearised at zero is exact and costs no Python callback.
``batch_factor``
    The paper's window map on one initial-state key,
    :math:`\mathbf e = \mathbf g(\mathbf x_0) - \mathbf Z` with Jacobian :math:`\mathbf J(\mathbf x_0)`.
``region_factor``
    The search region as the support of the initial state: zero inside the
    position box and below the speed limit, a steep quadratic wall outside.
``linear_doppler_factor``
    A Doppler factor linearised in numpy at a given point, as a native
    linear factor.  Long-running graphs (iSAM2, offline reconstruction) use it
    because GTSAM copies the whole ``Values`` into Python for every
    ``CustomFactor`` callback, which makes callbacks cost O(number of states).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.geometry import Geometry
from fgdoppler.models.doppler import BatchTimes, _batch
from fgdoppler.models.measurement import DopplerModel, MeasurementModel
from fgdoppler.models.motion import ConstantVelocity

__all__ = [
    "X",
    "absolute_linear_factor",
    "batch_factor",
    "doppler_factor",
    "linear_doppler_factor",
    "measurement_factor",
    "motion_factor",
    "noise_model",
    "prior_factor",
    "region_excess",
    "region_factor",
]

FloatArray = NDArray[np.float64]


def X(k: int) -> int:
    """GTSAM key of the ``k``-th state (symbol ``x``)."""
    return int(gtsam.symbol("x", int(k)))


def noise_model(sigma: ArrayLike, huber_k: float | None = None) -> gtsam.noiseModel.Base:
    """Diagonal noise model, optionally wrapped in a Huber robust estimator.

    Parameters
    ----------
    sigma
        Standard deviations, one per error component.
    huber_k
        Huber threshold in whitened units (e.g. 1.345); ``None`` for Gaussian.
    """
    s = np.asarray(sigma, dtype=float).reshape(-1)
    if not np.all(np.isfinite(s) & (s > 0)):
        raise ValueError(f"sigmas must be finite and > 0, got {s}")
    base = gtsam.noiseModel.Diagonal.Sigmas(s)
    if huber_k is None:
        return base
    if not huber_k > 0:
        raise ValueError(f"huber_k must be > 0, got {huber_k}")
    return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k), base)


def _checked(jac: FloatArray, rows: int, cols: int, what: str) -> FloatArray:
    # A wrong-shaped Jacobian handed to GTSAM crashes the interpreter; fail in Python.
    out = np.ascontiguousarray(jac, dtype=float)
    if out.shape != (rows, cols):
        raise RuntimeError(f"{what}: Jacobian shape {out.shape}, expected {(rows, cols)}")
    if not np.all(np.isfinite(out)):
        raise RuntimeError(f"{what}: non-finite Jacobian")
    return out


def _measurement_error(
    model: MeasurementModel,
    channels: NDArray[np.intp],
    z: FloatArray,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[FloatArray] | None,
) -> FloatArray:
    x = np.broadcast_to(values.atVector(this.keys()[0]), (channels.size, 4))
    if jacobians is None:
        return model.predict(x, channels) - z
    h, H = model.predict_and_jacobian(x, channels)
    jacobians[0] = _checked(H, channels.size, 4, "measurement factor")
    return h - z


def measurement_factor(
    key: int,
    model: MeasurementModel,
    channels: ArrayLike,
    values: ArrayLike,
    sigma: ArrayLike,
    *,
    huber_k: float | None = None,
) -> gtsam.CustomFactor:
    """All scalar measurements of any :class:`~fgdoppler.models.measurement.MeasurementModel` at one state.

    Error ``h(x)[channels] - z``; one Python callback per state.
    """
    c = np.asarray(channels, dtype=np.intp).reshape(-1)
    z = np.asarray(values, dtype=float).reshape(-1)
    if c.size == 0 or c.size != z.size:
        raise ValueError(f"need one or more measurements with matching channels, got {c.size} and {z.size}")
    if c.max() >= model.n_channels or c.min() < 0:
        raise ValueError(f"pair index out of range for a model of {model.n_channels} channel(s)")
    return gtsam.CustomFactor(
        noise_model(np.broadcast_to(sigma, z.shape), huber_k),
        [int(key)],
        partial(_measurement_error, model, c, z.copy()),
    )


def doppler_factor(
    key: int,
    geometry: Geometry,
    pairs: ArrayLike,
    doppler: ArrayLike,
    sigma: ArrayLike,
    *,
    huber_k: float | None = None,
) -> gtsam.CustomFactor:
    """All Doppler measurements taken at one state, as one factor.

    Parameters
    ----------
    key
        The state key.
    geometry
        Sensor pairs.
    pairs, doppler, sigma
        Pair index, measured Doppler (m/s) and its standard deviation, one
        entry per measurement at this state.
    huber_k
        Optional Huber threshold (robust to outliers).
    """
    return measurement_factor(key, DopplerModel(geometry=geometry), pairs, doppler, sigma, huber_k=huber_k)


def motion_factor(key1: int, key2: int, dt: float, model: ConstantVelocity) -> gtsam.LinearContainerFactor:
    r"""Constant-velocity factor :math:`\mathbf x_2 - \mathbf F(dt)\mathbf x_1 \sim \mathcal N(0, \mathbf Q(dt))`.

    Native and exact (the model is linear).  Raises :class:`ValueError` if
    ``Q(dt)`` is singular (``dt <= 0``, ``q = 0`` or the paper's rank-2 form).
    """
    R = model.sqrt_information(dt)
    return absolute_linear_factor((key1, key2), (-R @ model.F(dt), R), np.zeros(4))


def absolute_linear_factor(
    keys: Sequence[int], blocks: Sequence[ArrayLike], b: ArrayLike
) -> gtsam.LinearContainerFactor:
    r"""Native linear factor :math:`\sum_i \mathbf A_i\mathbf x_i - \mathbf b` (whitened, 1 or 2 keys).

    Wrapped in a :class:`gtsam.LinearContainerFactor` linearised at zero, so its
    error is the linear residual in absolute coordinates and any optimiser
    (LM, iSAM2, fixed-lag) can use it exactly, without a Python callback.
    """
    rhs = np.asarray(b, dtype=float).reshape(-1)
    unit = gtsam.noiseModel.Unit.Create(rhs.size)
    A = [np.ascontiguousarray(a, dtype=float) for a in blocks]
    if len(keys) == 1:
        jf = gtsam.JacobianFactor(int(keys[0]), A[0], rhs, unit)
    elif len(keys) == 2:
        jf = gtsam.JacobianFactor(int(keys[0]), A[0], int(keys[1]), A[1], rhs, unit)
    else:
        raise ValueError(f"absolute_linear_factor takes 1 or 2 keys, got {len(keys)}")
    lin = gtsam.Values()
    for k in keys:
        lin.insert(int(k), np.zeros(4))
    return gtsam.LinearContainerFactor(jf, lin)


def prior_factor(key: int, mean: ArrayLike, covariance: ArrayLike) -> gtsam.PriorFactorVector:
    """Gaussian prior on one state."""
    cov = np.asarray(covariance, dtype=float)
    if cov.shape != (4, 4) or not np.all(np.isfinite(cov)):
        raise ValueError(f"prior covariance must be a finite 4x4 matrix, got shape {cov.shape}")
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise ValueError("prior covariance must be positive definite") from None
    return gtsam.PriorFactorVector(int(key), np.asarray(mean, dtype=float), gtsam.noiseModel.Gaussian.Covariance(cov))


def region_excess(
    x: FloatArray, x_range: tuple[float, float], y_range: tuple[float, float], speed_max: float
) -> tuple[FloatArray, FloatArray]:
    r"""How far a state lies outside a search region, and the Jacobian of that.

    .. math::

        \mathbf e(\mathbf x) = \begin{bmatrix}
            \min(0, x - x_{lo}) + \max(0, x - x_{hi}) \\
            \min(0, y - y_{lo}) + \max(0, y - y_{hi}) \\
            \max(0, \lVert \mathbf v \rVert - s_{max})
        \end{bmatrix}

    zero inside the region; continuous, piecewise linear in position.
    """
    # plain floats: this runs once per LM iteration as a Python callback, where numpy's
    # per-call overhead would be most of the cost
    px, py, vx, vy = (float(v) for v in np.asarray(x, dtype=float).reshape(4))
    e = [0.0, 0.0, 0.0]
    J = [[0.0] * 4 for _ in range(3)]
    for i, (v, (lo, hi)) in enumerate(((px, x_range), (py, y_range))):
        if v < lo:
            e[i], J[i][i] = v - lo, 1.0
        elif v > hi:
            e[i], J[i][i] = v - hi, 1.0
    speed = math.hypot(vx, vy)
    if speed > speed_max:
        e[2] = speed - speed_max
        J[2][2], J[2][3] = vx / speed, vy / speed
    return np.array(e), np.array(J)


def _region_error(
    bounds: tuple[tuple[float, float], tuple[float, float], float],
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[FloatArray] | None,
) -> FloatArray:
    e, J = region_excess(values.atVector(this.keys()[0]), *bounds)
    if jacobians is not None:
        jacobians[0] = J
    return e


def region_factor(
    key: int,
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    speed_max: float,
    *,
    wall_sigma: tuple[float, float] = (10.0, 0.1),
) -> gtsam.CustomFactor:
    r"""The search region as the support of a state: a steep wall outside, nothing inside.

    Error :func:`region_excess` whitened by ``wall_sigma`` (position m, speed
    m/s): a state ``d`` metres outside the box costs :math:`(d/\sigma_w)^2`, so
    a solution can cross the boundary only by a few :math:`\sigma_w`.  This is
    the hard (uniform) prior of the paper's detectable zone in a form
    Levenberg–Marquardt can use.
    """
    for lo, hi in (x_range, y_range):
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ValueError(f"region bounds must be finite with lo < hi, got ({lo}, {hi})")
    if not (np.isfinite(speed_max) and speed_max > 0):
        raise ValueError(f"speed_max must be > 0, got {speed_max}")
    sp, sv = wall_sigma
    if not (sp > 0 and sv > 0):
        raise ValueError(f"wall_sigma must be positive, got {wall_sigma}")
    bounds = ((float(x_range[0]), float(x_range[1])), (float(y_range[0]), float(y_range[1])), float(speed_max))
    return gtsam.CustomFactor(noise_model([sp, sp, sv]), [int(key)], partial(_region_error, bounds))


def _batch_error(
    geometry: Geometry,
    times: BatchTimes,
    z: FloatArray,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[FloatArray] | None,
) -> FloatArray:
    x0 = values.atVector(this.keys()[0])
    g, J, _ = _batch(x0, geometry, times, jacobian=jacobians is not None)
    if jacobians is not None:
        assert J is not None
        jacobians[0] = _checked(J, z.size, 4, "batch_factor")
    return g - z


def batch_factor(
    key: int,
    geometry: Geometry,
    times: Sequence[ArrayLike] | BatchTimes,
    doppler: ArrayLike,
    sigma: ArrayLike,
) -> gtsam.CustomFactor:
    r"""The paper's window factor :math:`\mathbf g(\mathbf x_0) - \mathbf Z` on one initial-state key.

    ``times`` are relative to the time of :math:`\mathbf x_0`, one array per pair
    (or a :class:`~fgdoppler.models.BatchTimes`); ``doppler`` and ``sigma`` are
    stacked in the same order.
    """
    bt = times if isinstance(times, BatchTimes) else BatchTimes.from_per_pair(times)
    bt.check(geometry)
    z = np.asarray(doppler, dtype=float).reshape(-1)
    if z.size != bt.size or z.size == 0:
        raise ValueError(f"{z.size} measurements for {bt.size} batch times")
    return gtsam.CustomFactor(
        noise_model(np.broadcast_to(sigma, z.shape)), [int(key)], partial(_batch_error, geometry, bt, z.copy())
    )


def linear_doppler_factor(
    key: int,
    H: ArrayLike,
    residual: ArrayLike,
    x_lin: ArrayLike,
    sigma: ArrayLike,
) -> gtsam.LinearContainerFactor:
    r"""A Doppler factor linearised at ``x_lin``, as a native linear factor.

    With :math:`\mathbf r = \mathbf z - \mathbf h(\bar{\mathbf x})` and
    :math:`\mathbf H = \partial\mathbf h/\partial\mathbf x|_{\bar{\mathbf x}}`, the
    linearised error :math:`\mathbf H(\mathbf x-\bar{\mathbf x}) - \mathbf r` is
    stored in absolute coordinates as
    :math:`\mathbf H\mathbf x - (\mathbf r + \mathbf H\bar{\mathbf x})`, whitened by ``sigma``.
    Use :func:`fgdoppler.models.bistatic_doppler_and_jacobian` to compute
    ``H`` and the prediction for many states at once.
    """
    H = np.atleast_2d(np.asarray(H, dtype=float))
    r = np.asarray(residual, dtype=float).reshape(-1)
    s = np.broadcast_to(np.asarray(sigma, dtype=float), r.shape)
    H = _checked(H, r.size, 4, "linear_doppler_factor")
    W = 1.0 / s
    return absolute_linear_factor((key,), (H * W[:, None],), (r + H @ np.asarray(x_lin, dtype=float)) * W)
