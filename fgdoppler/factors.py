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
``cv_factor``
    The paper's window map on one initial-state key (exactly constant
    velocity), :math:`\mathbf e = \mathbf g(\mathbf x_0) - \mathbf Z` with
    Jacobian :math:`\mathbf J(\mathbf x_0)`.
``region_factor``
    The zone as the support of the initial state: zero inside the box and
    below the speed limit, a steep quadratic wall outside.
``absolute_linear_factor``
    A native linear factor in absolute coordinates.  Long-running graphs
    (iSAM2, the offline smoother) linearise the Doppler model in numpy and use
    it, because GTSAM copies the whole ``Values`` into Python for every
    ``CustomFactor`` callback, which makes callbacks cost O(number of states).

Keys are GTSAM's standard ``x0, x1, ...`` (:data:`gtsam.symbol_shorthand.X`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial
from typing import TYPE_CHECKING

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X
from numpy.typing import ArrayLike, NDArray

from fgdoppler.geometry import Geometry
from fgdoppler.models.doppler import StackedTimes, _cv, _kernels, _singular_error
from fgdoppler.models.motion import ConstantVelocity
from fgdoppler.models.observation import DopplerModel, MeasurementModel
from fgdoppler.models.robust import huber_residuals
from fgdoppler.zone import Zone

if TYPE_CHECKING:
    from fgdoppler.models.doppler_kernels import Along

__all__ = [
    "X",
    "absolute_linear_factor",
    "cv_factor",
    "doppler_factor",
    "measurement_factor",
    "motion_factor",
    "noise_model",
    "prior_factor",
    "region_factor",
]

FloatArray = NDArray[np.float64]


def noise_model(sigma: ArrayLike) -> gtsam.noiseModel.Base:
    """Diagonal Gaussian noise model with the given standard deviations (one per error component)."""
    s = np.asarray(sigma, dtype=float).reshape(-1)
    if not np.all(np.isfinite(s) & (s > 0)):
        raise ValueError(f"sigmas must be finite and > 0, got {s}")
    return gtsam.noiseModel.Diagonal.Sigmas(s)


def _robust(residual: FloatArray, jacobian: FloatArray | None, sigma: FloatArray, huber_k: float | None
            ) -> tuple[FloatArray, FloatArray | None]:
    """Residuals (and Jacobian rows) transformed so their whitened squares are the Huber loss, per row."""
    if huber_k is None:
        return residual, jacobian
    e, d = huber_residuals(residual / sigma, huber_k)
    return e * sigma, None if jacobian is None else jacobian * d[:, None]


def _check_huber(huber_k: float | None) -> None:
    if huber_k is not None and not (np.isfinite(huber_k) and huber_k > 0):
        raise ValueError(f"huber_k must be > 0, got {huber_k}")


def _checked(jac: FloatArray, rows: int, cols: int, what: str) -> FloatArray:
    # A wrong-shaped Jacobian handed to GTSAM crashes the interpreter; fail in Python.
    out = np.ascontiguousarray(jac, dtype=float)
    if out.shape != (rows, cols):
        raise RuntimeError(f"{what}: Jacobian shape {out.shape}, expected {(rows, cols)}")
    # For a scan's few rows: the entries' sum as plain floats, finite exactly when every entry is unless it
    # overflows, where the entry-wise test rules (numpy's per-call overhead is most of the cost there).  For a
    # window's rows numpy's entry-wise test costs less than the sum under np.errstate (1.4 against 2.4 us for
    # 20 to 100 rows).
    few = out.size <= 64
    if not (few and math.isfinite(sum(out.ravel().tolist()))) and not np.isfinite(out).all():
        raise RuntimeError(f"{what}: non-finite Jacobian")
    return out


def _measurement_error(
    model: MeasurementModel,
    channels: NDArray[np.intp],
    z: FloatArray,
    sigma: FloatArray,
    huber_k: float | None,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[FloatArray] | None,
) -> FloatArray:
    state = values.atVector(this.keys()[0])
    at_state = getattr(model, "at_state", None)
    if at_state is not None:  # the channels were checked when the factor was built
        h, H = at_state(state, channels, jacobian=jacobians is not None)
    else:
        x = np.broadcast_to(state, (channels.size, state.size))
        h, H = (model.predict(x, channels), None) if jacobians is None else model.predict_and_jacobian(x, channels)
    if jacobians is None:
        return _robust(h - z, None, sigma, huber_k)[0]
    e, J = _robust(h - z, H, sigma, huber_k)
    assert J is not None
    jacobians[0] = _checked(J, channels.size, state.size, "measurement factor")
    return e


def measurement_factor(
    key: int,
    model: MeasurementModel,
    channels: ArrayLike,
    values: ArrayLike,
    sigma: ArrayLike,
    *,
    huber_k: float | None = None,
) -> gtsam.CustomFactor:
    """All scalar measurements of any :class:`~fgdoppler.models.observation.MeasurementModel` at one state.

    Error ``h(x)[channels] - z``; one Python callback per state.  With
    ``huber_k`` each row is robust on its own
    (:func:`~fgdoppler.models.robust.huber_residuals`).
    """
    c = np.asarray(channels, dtype=np.intp).reshape(-1)
    z = np.asarray(values, dtype=float).reshape(-1)
    if c.size == 0 or c.size != z.size:
        raise ValueError(f"need one or more measurements with matching channels, got {c.size} and {z.size}")
    if c.max() >= model.n_channels or c.min() < 0:
        raise ValueError(f"pair index out of range for a model of {model.n_channels} channel(s)")
    _check_huber(huber_k)
    s = np.broadcast_to(np.asarray(sigma, dtype=float), z.shape).copy()
    return gtsam.CustomFactor(noise_model(s), [int(key)], partial(_measurement_error, model, c, z.copy(), s, huber_k))


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
        Optional Huber threshold, per measurement (robust to outliers).
    """
    return measurement_factor(key, DopplerModel(geometry=geometry), pairs, doppler, sigma, huber_k=huber_k)


def motion_factor(key1: int, key2: int, dt: float, model: ConstantVelocity) -> gtsam.LinearContainerFactor:
    r"""Constant-velocity factor :math:`\mathbf x_2 - \mathbf F(dt)\mathbf x_1 \sim \mathcal N(0, \mathbf Q(dt))`.

    Native and exact (the model is linear).  Raises :class:`ValueError` if
    ``Q(dt)`` is singular (``dt <= 0``, ``q = 0`` or the paper's rank-2 form).
    """
    R = model.sqrt_information(dt)
    return absolute_linear_factor((key1, key2), (-R @ model.F(dt), R), np.zeros(model.n))


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
    for k, a in zip(keys, A, strict=True):
        lin.insert(int(k), np.zeros(a.shape[1]))
    return gtsam.LinearContainerFactor(jf, lin)


def prior_factor(key: int, mean: ArrayLike, covariance: ArrayLike) -> gtsam.PriorFactorVector:
    """Gaussian prior on one state."""
    mean = np.asarray(mean, dtype=float).reshape(-1)
    cov = np.asarray(covariance, dtype=float)
    if cov.shape != (mean.size, mean.size) or not np.all(np.isfinite(cov)):
        raise ValueError(f"prior covariance must be a finite {mean.size}x{mean.size} matrix, got shape {cov.shape}")
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise ValueError("prior covariance must be positive definite") from None
    return gtsam.PriorFactorVector(int(key), mean, gtsam.noiseModel.Gaussian.Covariance(cov))


def _region_error(
    zone: Zone,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[FloatArray] | None,
) -> FloatArray:
    e, J = zone.excess(values.atVector(this.keys()[0]))
    if jacobians is not None:
        jacobians[0] = J
    return e


def region_factor(key: int, zone: Zone, *, wall_sigma: tuple[float, float] = (10.0, 0.1)) -> gtsam.CustomFactor:
    r"""The zone as the support of a state: a steep wall outside, nothing inside.

    Error :meth:`fgdoppler.zone.Zone.excess` whitened by ``wall_sigma``
    (position m, speed m/s): a state ``d`` metres outside the box costs
    :math:`(d/\sigma_w)^2`, so a solution can cross the boundary only by a few
    :math:`\sigma_w`.  This is the hard (uniform) prior of the paper's
    detectable zone in a form Levenberg–Marquardt can use.
    """
    sp, sv = wall_sigma
    if not (sp > 0 and sv > 0):
        raise ValueError(f"wall_sigma must be positive, got {wall_sigma}")
    return gtsam.CustomFactor(noise_model([sp] * zone.dim + [sv]), [int(key)], partial(_region_error, zone))


def _cv_error(
    geometry: Geometry,
    times: StackedTimes,
    along: Along,
    z: FloatArray,
    sigma: FloatArray,
    huber_k: float | None,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[FloatArray] | None,
) -> FloatArray:
    x0 = values.atVector(this.keys()[0])
    if x0.size == along.state_size:  # the window's sensors, picked, checked and laid out when the factor was built
        g, J, singular = along(x0, jacobian=jacobians is not None)
        if singular is not None:
            raise _singular_error(singular)
    else:
        g, J, _ = _cv(x0, geometry, times, jacobian=jacobians is not None)
    e, J = _robust(g - z, J, sigma, huber_k)
    if jacobians is not None:
        assert J is not None
        jacobians[0] = _checked(J, z.size, x0.size, "cv_factor")
    return e


def cv_factor(
    key: int,
    geometry: Geometry,
    times: Sequence[ArrayLike] | StackedTimes,
    doppler: ArrayLike,
    sigma: ArrayLike,
    *,
    huber_k: float | None = None,
) -> gtsam.CustomFactor:
    r"""The paper's window factor :math:`\mathbf g(\mathbf x_0) - \mathbf Z` on one initial-state key.

    ``times`` are relative to the time of :math:`\mathbf x_0`, one array per pair
    (or a :class:`~fgdoppler.models.StackedTimes`); ``doppler`` and ``sigma`` are
    stacked in the same order.  ``huber_k`` makes every row robust on its own.
    """
    bt = times if isinstance(times, StackedTimes) else StackedTimes.from_per_pair(times)
    bt.check(geometry)
    z = np.asarray(doppler, dtype=float).reshape(-1)
    if z.size != bt.size or z.size == 0:
        raise ValueError(f"{z.size} measurements for {bt.size} batch times")
    _check_huber(huber_k)
    s = np.broadcast_to(np.asarray(sigma, dtype=float), z.shape).copy()
    tx, rx = geometry.positions(geometry.dim)
    along = _kernels().Along(bt.t, tx[bt.pair], rx[bt.pair])
    return gtsam.CustomFactor(noise_model(s), [int(key)], partial(_cv_error, geometry, bt, along, z.copy(), s, huber_k))
