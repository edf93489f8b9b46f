r"""Clock offsets: what a receiver's clock that is off by a constant does to a track.

Every measurement is taken to carry the time of one common clock
(docs/data-formats.md).  A receiver whose clock runs :math:`\tau_p` late —
or whose software stamps a Doppler value with the end of its coherent
interval where another stamps its middle — reports pair :math:`p`'s value
of time :math:`t - \tau_p` at time :math:`t`:

.. math:: y_{p}(t) = h_p\big(\mathbf x(t - \tau_p)\big) + w.

On the paper's closely spaced pairs the difference between the pairs'
Doppler carries the position, and a time offset of one pair changes that
difference as another track would: with pair 1's clock 0.5 s late the
offline smoother said ``ok`` on 55 of 60 paper recordings, 36 of them
0.3–6 km off at 3.2–7.1 of its own σ (``python studies/data_mistakes.py
--runs 10``, seed 2026), and no residual test can see it.  What the user
can say is how well each receiver's clock is known:
:math:`\tau_p \sim N(0, \sigma_{\tau,p}^2)`, independent per pair
(``clock_sigma`` of the smoother's, the filters' and the particle estimators'
settings).

As for calibration offsets (:mod:`~fgdoppler.estimators.calibration`) the
track is not changed and its covariances grow by the mean square of what
the offsets do to it — a *consider* covariance, by the same five-point
Gauss–Hermite rule over each pair's :math:`\tau_p` in turn
(:func:`~fgdoppler.estimators.calibration.offset_shares`).  The data as
they would read with pair :math:`p`'s clock :math:`\tau` late are made
along the estimated track :math:`\hat{\mathbf x}`,

.. math:: y_{p,k} \;\to\; y_{p,k}
          + h_p\big(\mathbf F(-\tau)\,\hat{\mathbf x}(t_k)\big)
          - h_p\big(\hat{\mathbf x}(t_k)\big)

(:func:`delayed_by`; :math:`\mathbf F` the constant-velocity transition),
which keeps the measurement times — the estimators' graphs and scans do not
change — and is exact where the track is the truth: the change a clock
offset makes to the data is the change of the predicted Doppler along the
track, and a track that fits the data has their rate of change.  Each
quadrature point is one more run of the estimator on such data, four per
pair.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.calibration import offset_shares, per_pair_sigmas, smoother_response
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel

__all__ = ["clock_shares", "clock_sigmas", "delayed_by", "with_clock_uncertainty"]

FloatArray = NDArray[np.float64]


def clock_sigmas(clock_sigma: float | tuple[float, ...], n_pairs: int) -> FloatArray:
    """``clock_sigma`` (s) for each of ``n_pairs`` pairs.

    Raises
    ------
    ValueError
        If it has neither one value nor one per pair, or a value is negative or not finite.
    """
    return per_pair_sigmas(clock_sigma, n_pairs, "clock_sigma", "s")


def delayed_by(measurements: Measurements, model: TrackingModel, times: ArrayLike, states: ArrayLike,
               delays: ArrayLike) -> Measurements:
    r"""``measurements`` as they would read with each pair's clock ``delays`` seconds late, along a track.

    :math:`y_{p,k} + h_p(\mathbf F(-\tau_p)\hat{\mathbf x}(t_k)) - h_p(\hat{\mathbf x}(t_k))`
    (module docstring), with :math:`\hat{\mathbf x}(t_k)` the track's state at the last of its ``times``
    not after :math:`t_k` (its first before them) carried to :math:`t_k` by the motion model.  The
    measurement times, pairs and sigmas stay.

    Parameters
    ----------
    measurements
        The recording.
    model
        Its observation and motion model.
    times, states
        The track: ``(n,)`` increasing times and ``(n, 2d)`` states.
    delays
        One :math:`\tau_p` per pair (s; negative: early).

    Raises
    ------
    ValueError
        If the track is empty or its shapes disagree, or ``delays`` has not one value per pair.
    """
    t = np.asarray(times, dtype=float).reshape(-1)
    x = np.asarray(states, dtype=float)
    tau = np.asarray(delays, dtype=float).reshape(-1)
    if t.size == 0 or x.ndim != 2 or x.shape[0] != t.size:
        raise ValueError(f"a track of {t.size} times needs as many states, got shape {x.shape}")
    if tau.size != model.observation.n_channels:
        raise ValueError(f"one delay per pair ({model.observation.n_channels}), got {tau.size}")
    if len(measurements) == 0:
        return measurements
    now = model.motion.along(t, x, measurements.time)
    then = model.motion.propagate(now, -tau[measurements.pair])
    change = model.observation.predict(then, measurements.pair) - model.observation.predict(now, measurements.pair)
    return replace(measurements, doppler=measurements.doppler + change)


def clock_shares(measurements: Measurements, model: TrackingModel, clock_sigma: ArrayLike, times: ArrayLike,
                 states: ArrayLike, baseline: Sequence[ArrayLike],
                 respond: Callable[[Measurements], Sequence[ArrayLike]]) -> list[FloatArray]:
    r"""The clock offsets' share of the covariances of tracks that respond to the data by ``respond``.

    :math:`\sum_p \sum_i w_i\,\mathbf f_p(u_i\sigma_{\tau,p})\,\mathbf f_p(u_i\sigma_{\tau,p})^\top`
    with :math:`\mathbf f_p(\tau)` = ``respond`` (the data with pair :math:`p`'s clock :math:`\tau` late
    along the track ``times``, ``states``; :func:`delayed_by`) less ``baseline``
    (:func:`~fgdoppler.estimators.calibration.offset_shares`).

    Parameters
    ----------
    measurements
        The recording.
    model
        Its model.
    clock_sigma
        One :math:`\sigma_{\tau,p}` per pair (s), as :func:`clock_sigmas` gives it.
    times, states
        The track along which the data are delayed.
    baseline
        The tracks ``respond`` gives on ``measurements`` itself.
    respond
        The estimator as a function of the data.

    Returns
    -------
    list of ndarray
        One ``(n_k, 2d, 2d)`` share per track.
    """
    def delayed(data: Measurements, delays: FloatArray) -> Measurements:
        return delayed_by(data, model, times, states, delays)

    return offset_shares(measurements, clock_sigma, baseline, respond, shift=delayed)


def with_clock_uncertainty(measurements: Measurements, model: TrackingModel, times: ArrayLike, states: ArrayLike,
                           covariances: ArrayLike, clock_sigma: float | tuple[float, ...],
                           settings: SmootherSettings | None = None) -> FloatArray:
    r"""The smoothed track's covariances ``(n, 2d, 2d)`` with the clock offsets' share added (module docstring).

    Parameters
    ----------
    measurements, model
        The recording and the model the track was smoothed with.
    times, states
        The smoothed track (the minimum of the smoother's objective):
        ``(n,)`` and ``(n, 2d)``.  The data are delayed along it and
        re-solved from it.
    covariances
        Its covariances ``(n, 2d, 2d)``.
    clock_sigma
        :math:`\sigma_{\tau,p}` in s, one value for every pair or one per pair.
    settings
        The smoother's (its loss, iteration cap and zone wall are used for
        the solves of the delayed data).

    Raises
    ------
    ValueError
        For a ``clock_sigma`` of the wrong length or with a negative value.
    """
    sigmas = clock_sigmas(clock_sigma, model.observation.n_channels)
    x = np.asarray(states, dtype=float)
    respond = smoother_response(model, times, x, settings)
    return np.asarray(covariances, dtype=float) + clock_shares(measurements, model, sigmas, times, x, [x], respond)[0]
