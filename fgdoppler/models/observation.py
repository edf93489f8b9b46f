r"""Observation models: the scalar measurement models the estimators consume.

Every estimator (EKF, iSAM2, fixed-lag, batch) consumes a
:class:`MeasurementModel`: for states ``(n, 4)`` and one channel index per
state (the bistatic pair for Doppler), it returns the predicted measurement
``(n,)`` and, on request, its Jacobian ``(n, 2d)`` (states of ``2d`` numbers,
``d`` = 2 or 3).  :class:`DopplerModel` is
the bistatic Doppler of :mod:`fgdoppler.models.doppler`; other models (e.g. a
linear-Gaussian surrogate in tests) plug into the same machinery.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.geometry import SENSOR_EPS, Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import _along, _as_states, _terms

#: Up to this many rows the model is evaluated in plain floats (less overhead than numpy).
_SMALL = 4

__all__ = ["DopplerModel", "MeasurementModel", "check_channels", "predict_along"]

FloatArray = NDArray[np.float64]


@runtime_checkable
class MeasurementModel(Protocol):
    """A scalar measurement per (state, channel).

    A model may also have a ``state_dim`` attribute (the length of its states,
    6 for a 3-D one); without it the states are 2-D ``[x, y, vx, vy]``.
    """

    @property
    def n_channels(self) -> int:
        """Number of channels (valid channel indices are ``0 .. n_channels - 1``)."""
        ...

    def predict(self, states: ArrayLike, channels: ArrayLike) -> FloatArray:
        """Predicted measurements ``(n,)`` for states ``(n, state_dim)`` and channels ``(n,)``."""
        ...

    def predict_and_jacobian(self, states: ArrayLike, channels: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Predictions ``(n,)`` and Jacobians ``(n, state_dim)``."""
        ...


@dataclass(frozen=True, kw_only=True)
class DopplerModel:
    """Bistatic Doppler of pair ``channels[j]`` at ``states[j]`` (one pair per row, no waste).

    States have ``2 * geometry.dim`` numbers: ``[x, y, vx, vy]`` or ``[x, y, z, vx, vy, vz]``.
    """

    geometry: Geometry

    @property
    def n_channels(self) -> int:
        """Number of pairs."""
        return self.geometry.n_pairs

    @property
    def state_dim(self) -> int:
        """``2 * geometry.dim``."""
        return self.geometry.state_dim

    def _check(self, states: ArrayLike, channels: ArrayLike) -> tuple[FloatArray, NDArray[np.intp]]:
        n = self.geometry.state_dim
        if isinstance(states, np.ndarray) and states.shape == (1, n) and isinstance(channels, list) \
                and len(channels) == 1:
            # the filters' one-state, one-channel call: validate cheaply
            k = channels[0]
            if not 0 <= k < self.geometry.n_pairs:
                raise ValueError(f"pair index out of range for a geometry of {self.geometry.n_pairs} pair(s)")
            return states.astype(float, copy=False), np.array([k], dtype=np.intp)
        x = _as_states(states)
        if x.shape[-1] != n:
            raise ValueError(f"a {self.geometry.dim}-D geometry takes states of {n} numbers, got {x.shape[-1]}")
        x = x.reshape(-1, n)
        c = np.asarray(channels, dtype=np.intp).reshape(-1)
        if c.shape[0] != x.shape[0]:
            raise ValueError(f"{x.shape[0]} states but {c.shape[0]} channels")
        if c.size and (c.min() < 0 or c.max() >= self.geometry.n_pairs):
            raise ValueError(f"pair index out of range for a geometry of {self.geometry.n_pairs} pair(s)")
        return x, c

    def predict(self, states: ArrayLike, channels: ArrayLike) -> FloatArray:
        """Doppler ``(n,)``; raises :class:`ValueError` at a sensor position."""
        x, c = self._check(states, channels)
        if c.size <= _SMALL:
            return self._small(x, c, jacobian=False)[0]
        return self._vectorised(x, c, jacobian=False)[0]

    def predict_and_jacobian(self, states: ArrayLike, channels: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Doppler ``(n,)`` and Jacobian ``(n, state_dim)``."""
        x, c = self._check(states, channels)
        if c.size <= _SMALL:
            h, H = self._small(x, c, jacobian=True)
            assert H is not None
            return h, H
        h, H = self._vectorised(x, c, jacobian=True)
        assert H is not None
        return h, H

    def _vectorised(self, x: FloatArray, c: NDArray[np.intp], *, jacobian: bool
                    ) -> tuple[FloatArray, FloatArray | None]:
        """Doppler of the rows ``x`` on the pairs ``c`` (and their Jacobian) in numpy: many rows."""
        d = self.geometry.dim
        h, dp, dv, _ = _terms(x[:, :d], x[:, d:], self.geometry.tx[c], self.geometry.rx[c], jacobian=jacobian)
        if not jacobian:
            return h, None
        assert dp is not None and dv is not None
        return h, np.concatenate([dp, dv], axis=-1)

    def at_state(self, state: FloatArray, channels: NDArray[np.intp], *, jacobian: bool
                 ) -> tuple[FloatArray, FloatArray | None]:
        """Doppler ``(n,)`` of the pairs ``channels`` at one ``state`` ``(state_dim,)``, and with ``jacobian`` its
        Jacobian ``(n, state_dim)``: :meth:`predict` and :meth:`predict_and_jacobian` of ``state`` repeated, to
        the bit, without their checks of ``channels``.

        For the graphs' measurement factors, which check their channels once
        when built and are then called at every linearisation and every
        trial step: the checks and the repeated state cost more than the
        arithmetic of a scan's few pairs.
        """
        if state.shape != (self.geometry.state_dim,):
            raise ValueError(f"a {self.geometry.dim}-D geometry takes states of {self.geometry.state_dim} numbers, "
                             f"got shape {state.shape}")
        if channels.size <= _SMALL:
            row = state.tolist()
            return self._plain([(row, k) for k in channels.tolist()], jacobian=jacobian)
        return self._vectorised(np.broadcast_to(state, (channels.size, state.size)), channels, jacobian=jacobian)

    def predict_along(self, x0: ArrayLike, times: ArrayLike, channels: ArrayLike) -> FloatArray:
        r"""Doppler ``(n, m)`` of constant-velocity tracks from states ``x0`` ``(n, state_dim)`` at ``times`` ``(m,)``.

        Row ``i`` is track ``i`` (position :math:`\mathbf p_0 + t\mathbf v`)
        seen by pair ``channels[j]`` at ``times[j]``; NaN where a track passes
        through a sensor (no exception: a particle or grid node there is
        simply impossible).
        """
        d = self.geometry.dim
        x = np.asarray(x0, dtype=float).reshape(-1, 2 * d)
        t = np.asarray(times, dtype=float).reshape(-1)
        c = np.asarray(channels, dtype=np.intp).reshape(-1)
        if c.size and (c.min() < 0 or c.max() >= self.geometry.n_pairs):
            raise ValueError(f"pair index out of range for a geometry of {self.geometry.n_pairs} pair(s)")
        h, mask = _along(x, t, self.geometry.tx[c], self.geometry.rx[c], singular="mask")
        if mask is not None:
            h = np.where(mask, np.nan, h)
        return h

    @property
    def scan_rank(self) -> NDArray[np.intp]:
        """Each pair's place in a scan's update order (:attr:`fgdoppler.geometry.Geometry.scan_rank`)."""
        return self.geometry.scan_rank

    @cached_property
    def scalar(self) -> Callable[[list[float], int], tuple[float, list[float]]]:
        """``scalar(state, channel)``: Doppler of one pair at one state and its Jacobian row, in plain floats.

        No checks on ``channel``.  The same formulas as
        :func:`fgdoppler.models.doppler.bistatic_doppler_and_jacobian`; the
        filters call this for their one-state, one-pair updates, where numpy's
        per-call overhead would cost several times the arithmetic.  (The
        function for the geometry's dimension, chosen once.)
        """
        return self._scalar2 if self.geometry.dim == 2 else self._scalar3

    @cached_property
    def _sensor_floats(self) -> tuple[tuple[tuple[float, ...], tuple[float, ...]], ...]:
        """Each pair's transmitter and receiver coordinates as plain floats, for :meth:`scalar`.

        Converted once: reading them from the geometry's arrays at every call
        cost more than the arithmetic they enter.
        """
        return tuple((tuple(float(v) for v in tx), tuple(float(v) for v in rx))
                     for tx, rx in zip(self.geometry.tx, self.geometry.rx, strict=True))

    def _scalar3(self, state: list[float], channel: int) -> tuple[float, list[float]]:
        pos, vel = state[:3], state[3:]
        hv = 0.0
        dp = [0.0, 0.0, 0.0]
        dv = [0.0, 0.0, 0.0]
        for sensor in self._sensor_floats[channel]:
            delta = [pos[i] - sensor[i] for i in range(3)]
            r = math.sqrt(delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2])
            if r <= SENSOR_EPS:
                raise ValueError(
                    f"1 target position(s) coincide with a sensor (distance <= {SENSOR_EPS} m): "
                    "the bistatic Doppler is undefined there"
                )
            u = [c / r for c in delta]
            rd = u[0] * vel[0] + u[1] * vel[1] + u[2] * vel[2]
            hv += rd
            for i in range(3):
                dp[i] += (vel[i] - rd * u[i]) / r
                dv[i] += u[i]
        return hv, dp + dv

    def _scalar2(self, state: list[float], channel: int) -> tuple[float, list[float]]:
        px, py, vx, vy = state
        dpx = dpy = dvx = dvy = hv = 0.0
        for sx, sy in self._sensor_floats[channel]:
            dx = px - sx
            dy = py - sy
            r = math.sqrt(dx * dx + dy * dy)
            if r <= SENSOR_EPS:
                raise ValueError(
                    f"1 target position(s) coincide with a sensor (distance <= {SENSOR_EPS} m): "
                    "the bistatic Doppler is undefined there"
                )
            ux = dx / r
            uy = dy / r
            rd = ux * vx + uy * vy
            hv += rd
            dpx += (vx - rd * ux) / r
            dpy += (vy - rd * uy) / r
            dvx += ux
            dvy += uy
        return hv, [dpx, dpy, dvx, dvy]

    def _small(self, x: FloatArray, c: NDArray[np.intp], *, jacobian: bool) -> tuple[FloatArray, FloatArray | None]:
        # Few rows: plain floats beat numpy's per-call overhead (see :meth:`scalar`).
        return self._plain(list(zip(x.tolist(), c.tolist(), strict=True)), jacobian=jacobian)

    def _plain(self, rows: list[tuple[list[float], int]], *, jacobian: bool) -> tuple[FloatArray, FloatArray | None]:
        """:meth:`scalar` of each (state, channel) in ``rows``, made arrays once: for a few rows numpy's per-row
        assignments would cost more than the arithmetic."""
        scalar = self.scalar
        values = [scalar(row, k) for row, k in rows]
        h = np.array([v[0] for v in values], dtype=float)
        if not jacobian:
            return h, None
        return h, np.array([v[1] for v in values], dtype=float).reshape(len(values), self.geometry.state_dim)


def check_channels(model: MeasurementModel, measurements: Measurements) -> None:
    """Raise :class:`ValueError` if a measurement's channel (pair) is outside ``model``."""
    if len(measurements) and int(measurements.pair.max()) >= model.n_channels:
        raise ValueError(f"pair index {int(measurements.pair.max())} outside a model of {model.n_channels} channel(s)")


def predict_along(model: MeasurementModel, x0: FloatArray, times: FloatArray,
                  channels: NDArray[np.intp]) -> FloatArray:
    r"""Predictions ``(n, m)`` of any measurement model along constant-velocity tracks.

    Row ``i`` is the track :math:`\mathbf p_0 + t\mathbf v` from state
    ``x0[i]``, seen on ``channels[j]`` at ``times[j]``.  A model with its own
    vectorised ``predict_along`` (:meth:`DopplerModel.predict_along`: NaN
    where a track passes through a sensor) is called directly; any other
    :class:`MeasurementModel` is evaluated at the propagated states.
    """
    along = getattr(model, "predict_along", None)
    if along is not None:
        return np.asarray(along(x0, times, channels), dtype=float)
    d = x0.shape[1] // 2
    states = x0[:, None, :] + np.concatenate([times[None, :, None] * x0[:, None, d:],
                                              np.zeros((1, times.size, d))], -1)
    return np.asarray(model.predict(states.reshape(-1, 2 * d), np.tile(channels, x0.shape[0])),
                      dtype=float).reshape(x0.shape[0], times.size)
