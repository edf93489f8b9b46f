r"""Sensor sites: what a transmitter or receiver that is not quite where the geometry says does to a track.

Every estimator takes the sensors to be exactly where the geometry puts
them.  A surveyed site is known to metres, one read off a map to tens of
metres; on the paper's closely spaced pairs the difference between the
pairs' Doppler carries the position, and a site error changes that
difference as another track would, with residuals as good.  What the user
can say is how well each site is known: its true position is
:math:`\mathbf s + \boldsymbol\delta_s`, :math:`\boldsymbol\delta_s \sim
N(\mathbf 0, \sigma_s^2\mathbf I)`, independent per site and coordinate
(``site_sigma`` of every estimator's settings).

A *site* is a distinct sensor position: a transmitter shared by two pairs is
one site (its error moves both pairs' Doppler), and so is a monostatic
radar.  Sites are numbered in the order the pairs first name them: pair 0's
transmitter, its receiver, pair 1's transmitter, its receiver, … skipping a
position already named (:meth:`~fgdoppler.geometry.Geometry.sites`); in the
paper's case (a) the sites are Tx1, Rx and Tx2.

As for calibration and clock offsets (:mod:`~fgdoppler.estimators.calibration`,
:mod:`~fgdoppler.estimators.clock_offsets`) the track is not changed and
its covariances grow by the mean square of what the site errors do to it —
a *consider* covariance, by the five-point Gauss–Hermite rule over each
site coordinate in turn
(:func:`~fgdoppler.estimators.calibration.offset_shares` with one direction
:math:`\sigma_s\mathbf e_{s,c}` per site :math:`s` and coordinate :math:`c`).
The data as they would read with the sites displaced by
:math:`\boldsymbol\delta` are made along the estimated track
:math:`\hat{\mathbf x}`,

.. math:: y_{p,k} \;\to\; y_{p,k}
          + h_p\big(\hat{\mathbf x}(t_k);\,\mathbf s + \boldsymbol\delta\big)
          - h_p\big(\hat{\mathbf x}(t_k);\,\mathbf s\big)

(:func:`displaced_by`), which keeps the geometry the estimators solve with,
and is exact where the track is the truth.  Each quadrature point is one
more run of the estimator on such data: four per site coordinate, so
``4 · dim`` per site.  The rotation of the problem into the sensors' own
frame does not change the share (the site errors are isotropic).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.calibration import offset_shares, smoother_response
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.geometry import Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.observation import DopplerModel
from fgdoppler.models.tracking import TrackingModel

__all__ = ["displaced_by", "site_directions", "site_shares", "site_sigmas", "with_site_uncertainty"]

FloatArray = NDArray[np.float64]


def site_sigmas(site_sigma: float | tuple[float, ...], geometry: Geometry | TrackingModel) -> FloatArray:
    """``site_sigma`` (m) for each of the sites (:meth:`~fgdoppler.geometry.Geometry.sites`) of ``geometry`` (or of a
    Doppler model's).

    Raises
    ------
    ValueError
        If it has neither one value nor one per site, or a value is negative or not finite; or the model is not
        a Doppler model.
    """
    n = (geometry if isinstance(geometry, Geometry) else _doppler_geometry(geometry)).sites()[0].shape[0]
    s = np.asarray(site_sigma, dtype=float).reshape(-1)
    if s.size not in (1, n) or not np.all(np.isfinite(s) & (s >= 0)):
        raise ValueError(f"site_sigma must be one value >= 0 (m) or one per site ({n}: in the order the pairs first "
                         f"name them, pair 0's transmitter, its receiver, pair 1's transmitter, ...), got {site_sigma}")
    return np.broadcast_to(s, (n,)).copy()


def site_directions(sigmas: ArrayLike, dim: int) -> FloatArray:
    r"""One row per site :math:`s` with :math:`\sigma_s > 0` and coordinate :math:`c`: :math:`\sigma_s\mathbf e_{s,c}`,
    a displacement of every site's coordinates ``(n_directions, n_sites * dim)`` (site-major)."""
    scale = np.repeat(np.asarray(sigmas, dtype=float).reshape(-1), dim)
    return np.diag(scale)[scale > 0]


def _doppler_geometry(model: TrackingModel) -> Geometry:
    if not isinstance(model.observation, DopplerModel):
        raise ValueError(f"site_sigma needs a Doppler model, whose sensors have sites; got a "
                         f"{type(model.observation).__name__}")
    return model.observation.geometry


def displaced_by(measurements: Measurements, model: TrackingModel, times: ArrayLike, states: ArrayLike,
                 displacement: ArrayLike) -> Measurements:
    r"""``measurements`` as they would read with the sites displaced, along a track.

    :math:`y_{p,k} + h_p(\hat{\mathbf x}(t_k); \mathbf s + \boldsymbol\delta) - h_p(\hat{\mathbf x}(t_k); \mathbf s)`
    (module docstring), with :math:`\hat{\mathbf x}(t_k)` the track's state at the last of its ``times`` not
    after :math:`t_k` (its first before them) carried to :math:`t_k` by the motion model.  The measurement
    times, pairs and sigmas stay.

    Parameters
    ----------
    measurements
        The recording.
    model
        Its Doppler model (the sites are its geometry's, in its coordinates).
    times, states
        The track: ``(n,)`` increasing times and ``(n, 2d)`` states, ``d`` the geometry's dimension.
    displacement
        Each site's displacement (m): ``(n_sites, d)``, or flat, site-major.

    Raises
    ------
    ValueError
        If the model is not a Doppler model, the track is empty, its shapes disagree or its states are not of
        the geometry's dimension, or ``displacement`` has not ``d`` numbers per site.
    """
    geometry = _doppler_geometry(model)
    t = np.asarray(times, dtype=float).reshape(-1)
    x = np.asarray(states, dtype=float)
    if t.size == 0 or x.ndim != 2 or x.shape[0] != t.size:
        raise ValueError(f"a track of {t.size} times needs as many states, got shape {x.shape}")
    if x.shape[1] != geometry.state_dim:
        raise ValueError(f"a {geometry.dim}-D geometry's track has states of {geometry.state_dim} numbers, got "
                         f"{x.shape[1]}")
    n_sites = geometry.sites()[0].shape[0]
    delta = np.asarray(displacement, dtype=float)
    if delta.size != n_sites * geometry.dim:
        raise ValueError(f"one displacement of {geometry.dim} numbers per site ({n_sites}), got shape {delta.shape}")
    if len(measurements) == 0:
        return measurements
    moved = DopplerModel(geometry=geometry.with_sites_moved(delta))
    now = model.motion.along(t, x, measurements.time)
    change = moved.predict(now, measurements.pair) - model.observation.predict(now, measurements.pair)
    return replace(measurements, doppler=measurements.doppler + change)


def site_shares(measurements: Measurements, model: TrackingModel, site_sigma: ArrayLike, times: ArrayLike,
                states: ArrayLike, baseline: Sequence[ArrayLike],
                respond: Callable[[Measurements], Sequence[ArrayLike]]) -> list[FloatArray]:
    r"""The site errors' share of the covariances of tracks that respond to the data by ``respond``.

    :math:`\sum_{s,c} \sum_i w_i\,\mathbf f_{s,c}(u_i\sigma_s)\,\mathbf f_{s,c}(u_i\sigma_s)^\top` with
    :math:`\mathbf f_{s,c}(\delta)` = ``respond`` (the data with site :math:`s` moved by :math:`\delta` along
    coordinate :math:`c`, along the track ``times``, ``states``; :func:`displaced_by`) less ``baseline``
    (:func:`~fgdoppler.estimators.calibration.offset_shares`).

    Parameters
    ----------
    measurements
        The recording.
    model
        Its Doppler model.
    site_sigma
        One :math:`\sigma_s` per site (m), as :func:`site_sigmas` gives it.
    times, states
        The track along which the data are displaced.
    baseline
        The tracks ``respond`` gives on ``measurements`` itself.
    respond
        The estimator as a function of the data.

    Returns
    -------
    list of ndarray
        One ``(n_k, 2d, 2d)`` share per track.
    """
    x = np.asarray(states, dtype=float)

    def displaced(data: Measurements, delta: FloatArray) -> Measurements:
        return displaced_by(data, model, times, x, delta)

    return offset_shares(measurements, site_sigma, baseline, respond,
                         directions=site_directions(site_sigma, x.shape[-1] // 2), shift=displaced)


def with_site_uncertainty(measurements: Measurements, model: TrackingModel, times: ArrayLike, states: ArrayLike,
                          covariances: ArrayLike, site_sigma: float | tuple[float, ...],
                          settings: SmootherSettings | None = None) -> FloatArray:
    r"""The smoothed track's covariances ``(n, 2d, 2d)`` with the site errors' share added (module docstring).

    Parameters
    ----------
    measurements, model
        The recording and the Doppler model the track was smoothed with.
    times, states
        The smoothed track (the minimum of the smoother's objective):
        ``(n,)`` and ``(n, 2d)``.  The data are displaced along it and
        re-solved from it.
    covariances
        Its covariances ``(n, 2d, 2d)``.
    site_sigma
        :math:`\sigma_s` in m, one value for every site or one per site
        (:meth:`~fgdoppler.geometry.Geometry.sites`).
    settings
        The smoother's (its loss, iteration cap and zone wall are used for
        the solves of the displaced data).

    Raises
    ------
    ValueError
        For a ``site_sigma`` of the wrong length or with a negative value, or a model that is not a Doppler model.
    """
    sigmas = site_sigmas(site_sigma, model)
    x = np.asarray(states, dtype=float)
    if not np.any(sigmas > 0):
        return np.asarray(covariances, dtype=float)
    respond = smoother_response(model, times, x, settings)
    return np.asarray(covariances, dtype=float) + site_shares(measurements, model, sigmas, times, x, [x], respond)[0]
