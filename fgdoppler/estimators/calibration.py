r"""Doppler calibration offsets: what a constant offset per pair does to a track.

A pair whose transmitter and receiver oscillators are not locked, or whose
processing assumes a slightly wrong carrier, measures every Doppler value
shifted by one constant :math:`b_p`.  The data hardly tell such an offset
from a shift of the track: in the paper's well-observed case a 45 km an
offset of 1 m/s (one σ of the noise) on one pair moves the smoother's
answer 430–480 m (6–8 of its own σ), and one of 2 m/s 0.8–1.0 km while its
cost changes by −4 to +5 — no residual test can see it.  What the user can
say is how well each pair is calibrated: :math:`b_p \sim N(0, \sigma_{b,p}^2)`,
independent per pair (``SmootherSettings(bias_sigma=...)``).

The track is not changed (the offsets are not estimated); its covariances
grow by the mean square of what the offsets do to it — a *consider*
covariance.  With :math:`\mathbf f_p(b)` the change of the smoothed
trajectory when pair :math:`p`'s measurements are all shifted by :math:`b`,

.. math:: \mathbf P_k \;\to\; \mathbf P_k + \sum_p
          \mathrm E\big[\mathbf f_{p,k}(b_p)\,\mathbf f_{p,k}(b_p)^\top\big],
          \qquad
          \mathrm E[\mathbf f\mathbf f^\top] \approx \sum_i w_i\,
          \mathbf f(u_i\sigma_{b,p})\,\mathbf f(u_i\sigma_{b,p})^\top,

with the five-point Gauss–Hermite rule :math:`(u_i, w_i)`
(:data:`QUADRATURE`; its middle point, :math:`u = 0`, adds nothing): exact
where :math:`\mathbf f` is a polynomial of degree four or less in
:math:`b`.  Each :math:`\mathbf f_p(u_i\sigma_{b,p})` is a
Levenberg–Marquardt solve of the shifted data from the track, four per
pair.  Not the first-order response (the tangent, one linear solve): on
case a 45 km the track moves 7 % more or less than the tangent says at
1 m/s and 13 % at 2 m/s, enough to leave the first-order covariance 25 %
short in NEES (60 runs with offsets of σ 1 m/s: mean final NEES 5.0 for 4
dimensions).  Nor the three-point rule (points at :math:`\pm\sqrt3`
σ): where the data observe the track poorly, an offset of two or three σ
moves it much further than one of one σ, and with offsets of σ 1 m/s the
three-point rule left 24 of 240 answers of case a 5 and 25 km and case b
25 and 45 km ``ok`` with a final NEES beyond the χ²₄ 99.9 % level, the
five-point rule 17 (``python studies/doppler_offsets.py``, seed 2026, 60
runs per scenario).  Offsets of different pairs are taken one at a time
and their effects added (no cross terms).

The filters (EKF, iSAM2, fixed-lag; ``bias_sigma`` of their settings)
take the same share of what the offsets do to them, by
:func:`offset_shares` with the tracker itself as the response: run again
on the shifted data from starts moved as the initiation window's solution
moves (:func:`moved_starts`), by
:func:`~fgdoppler.estimators.registry.run_estimator`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from numpy.polynomial.hermite_e import hermegauss
from numpy.typing import ArrayLike, NDArray

from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.settings import SmootherSettings
from fgdoppler.measurements import Measurements
from fgdoppler.models.tracking import TrackingModel

__all__ = ["QUADRATURE", "SAME_MINIMUM", "bias_sigmas", "moved_starts", "offset_shares", "per_pair_sigmas", "shifted_by",
           "smoother_response", "with_bias_uncertainty"]

FloatArray = NDArray[np.float64]


def _rule(points: int) -> tuple[tuple[float, float], ...]:
    """The ``points``-point Gauss–Hermite rule for N(0, 1) as (offset in sigma, weight), without the point 0."""
    u, w = hermegauss(points)
    return tuple((float(a), float(b)) for a, b in zip(u, w / w.sum(), strict=True) if abs(a) > 1e-12)


#: The five-point Gauss–Hermite rule's offsets in units of sigma and their weights (the middle point, 0, adds
#: nothing): +-1.36 and +-2.86 sigma, weights 0.222 and 0.0113.
QUADRATURE: tuple[tuple[float, float], ...] = _rule(5)


def per_pair_sigmas(value: float | tuple[float, ...], n_pairs: int, name: str = "bias_sigma",
                    unit: str = "m/s") -> FloatArray:
    """``value`` — one standard deviation for every pair or one per pair — for each of ``n_pairs`` pairs.

    Raises
    ------
    ValueError
        If it has neither one value nor one per pair, or a value is negative or not finite (naming ``name``).
    """
    sb = np.asarray(value, dtype=float).reshape(-1)
    if sb.size not in (1, n_pairs) or not np.all(np.isfinite(sb) & (sb >= 0)):
        raise ValueError(f"{name} must be one value >= 0 ({unit}) or one per pair ({n_pairs}), got {value}")
    return np.broadcast_to(sb, (n_pairs,)).copy()


def bias_sigmas(bias_sigma: float | tuple[float, ...], n_pairs: int) -> FloatArray:
    """``bias_sigma`` for each of ``n_pairs`` pairs.

    Raises
    ------
    ValueError
        If it has neither one value nor one per pair, or a value is negative or not finite.
    """
    return per_pair_sigmas(bias_sigma, n_pairs)


def shifted_by(measurements: Measurements, offsets: ArrayLike) -> Measurements:
    """``measurements`` with every pair's Doppler values shifted by its own offset (``offsets``: one per pair, m/s)."""
    return replace(measurements, doppler=measurements.doppler + np.asarray(offsets, dtype=float)[measurements.pair])


def offset_shares(measurements: Measurements, bias_sigma: ArrayLike, baseline: Sequence[ArrayLike],
                  respond: Callable[[Measurements], Sequence[ArrayLike]], *,
                  directions: ArrayLike | None = None,
                  shift: Callable[[Measurements, FloatArray], Measurements] = shifted_by) -> list[FloatArray]:
    r"""The calibration offsets' share of the covariances of tracks that respond to the data by ``respond``.

    :math:`\sum_p \sum_i w_i\,\mathbf f_p(u_i\sigma_{b,p})\,\mathbf f_p(u_i\sigma_{b,p})^\top`
    for each track, with :math:`\mathbf f_p(b)` = ``respond(data with pair p shifted by b)`` less
    ``baseline`` (the module docstring; :data:`QUADRATURE`).  With ``directions`` (rows
    :math:`\mathbf d_j`, one offset per pair each) the data are shifted along each row instead,
    :math:`\mathbf f_j(u) = ` ``respond(data shifted by u d_j)`` less ``baseline``: the share of offsets
    :math:`\sum_j \xi_j\mathbf d_j`, :math:`\xi_j \sim N(0, 1)` independent (the rows of a square
    root of their covariance).

    Parameters
    ----------
    measurements
        The recording.
    bias_sigma
        One :math:`\sigma_{b,p}` per pair (m/s), as :func:`bias_sigmas` gives it (unused with ``directions``).
    baseline
        The tracks ``respond`` gives on ``measurements`` itself: state arrays ``(n_k, 2d)``.
    respond
        The estimator, as a function of the data: one state array per track, shaped as ``baseline``'s.
    directions
        ``(n_directions, n_pairs)`` offset vectors (m/s) to shift the data along, or ``None``: each pair by its
        own :math:`\sigma_{b,p}`.
    shift
        ``shift(measurements, v)``: the data with each pair ``p`` offset by ``v[p]``.

    Returns
    -------
    list of ndarray
        One ``(n_k, 2d, 2d)`` share per track.

    Raises
    ------
    ValueError
        If ``respond`` returns tracks shaped unlike ``baseline``.
    """
    base = [np.asarray(b, dtype=float) for b in baseline]
    shares = [np.zeros((*b.shape, b.shape[-1])) for b in base]
    if directions is None:
        sb = np.asarray(bias_sigma, dtype=float).reshape(-1)
        rows = [np.where(np.arange(sb.size) == p, sb[p], 0.0) for p in np.flatnonzero(sb > 0)
                if np.any(measurements.pair == p)]
    else:
        rows = list(np.atleast_2d(np.asarray(directions, dtype=float)))
    for d in rows:
        for step, weight in QUADRATURE:
            moved = [np.asarray(m, dtype=float) for m in respond(shift(measurements, step * d))]
            if [m.shape for m in moved] != [b.shape for b in base]:
                raise ValueError(f"the tracks of the shifted data are shaped {[m.shape for m in moved]}, "
                                 f"not as the recording's {[b.shape for b in base]}")
            for share, m, b in zip(shares, moved, base, strict=True):
                f = m - b
                share += weight * np.einsum("ki,kj->kij", f, f)
    return shares


def with_bias_uncertainty(measurements: Measurements, model: TrackingModel, times: ArrayLike, states: ArrayLike,
                          covariances: ArrayLike, bias_sigma: float | tuple[float, ...],
                          settings: SmootherSettings | None = None, *, directions: ArrayLike | None = None
                          ) -> FloatArray:
    r"""The smoothed track's covariances ``(n, 2d, 2d)`` with the calibration offsets' share added (module docstring).

    Parameters
    ----------
    measurements, model
        The recording and the model the track was smoothed with.
    times, states
        The smoothed track (the minimum of the smoother's objective): one
        state per time, ``(n,)`` and ``(n, 2d)``.
    covariances
        Its covariances ``(n, 2d, 2d)``.
    bias_sigma
        :math:`\sigma_{b,p}` in m/s, one value for every pair or one per pair.
    settings
        The smoother's (its loss, iteration cap and zone wall are used for
        the shifted solves).
    directions
        Offset vectors to shift the data along instead of each pair by its
        ``bias_sigma`` (:func:`offset_shares`).

    Raises
    ------
    ValueError
        For a ``bias_sigma`` of the wrong length or with a negative value.
    """
    sb = bias_sigmas(bias_sigma, model.observation.n_channels)
    x = np.asarray(states, dtype=float)
    respond = smoother_response(model, times, x, settings)
    return np.asarray(covariances, dtype=float) + offset_shares(measurements, sb, [x], respond, directions=directions)[0]


def smoother_response(model: TrackingModel, times: ArrayLike, states: ArrayLike,
                      settings: SmootherSettings | None = None) -> Callable[[Measurements], list[FloatArray]]:
    """The smoothed track as a function of the data: Levenberg–Marquardt from ``states`` at ``times`` with the
    smoother's ``settings`` (loss, iteration cap, zone wall; no covariances), one state array in a list (the
    ``respond`` of :func:`offset_shares`)."""
    from fgdoppler.estimators.smoother import solve_smoother

    x = np.asarray(states, dtype=float)
    solve = replace(settings or SmootherSettings(), covariances=False)

    def respond(data: Measurements) -> list[FloatArray]:
        return [solve_smoother(data, model, x, solve, prior=model.prior(), times=times).states]

    return respond


#: Two window solutions whose last states lie closer than this (squared distance in the hypothesis's own ``P_end``)
#: are one minimum, reached from two starts (:func:`moved_starts` re-solves the window once for both): a hundredth
#: of a standard deviation, far below what a share resolves and above where Levenberg–Marquardt stops along a flat
#: valley (the terms of a restart's Gaussian sum: within a metre of one another where σ is kilometres).
SAME_MINIMUM = 1e-4


def _same_minimum(h: Initiation, mine: tuple[FloatArray, FloatArray | None],
                  other: tuple[FloatArray, FloatArray | None]) -> bool:
    """Whether hypothesis ``h``'s window solution ``mine`` and ``other`` (``(times, states)``) are one minimum."""
    (t_a, a), (t_b, b) = mine, other
    if a is None or b is None or h.P_end is None or not np.array_equal(t_a, t_b):
        return False
    d = a[-1] - b[-1]
    try:
        return bool(float(d @ np.linalg.solve(h.P_end, d)) < SAME_MINIMUM)
    except np.linalg.LinAlgError:
        return False


def moved_starts(hyps: Sequence[Initiation], measurements: Measurements, model: TrackingModel, *,
                 huber_k: float | None = None) -> Callable[[Measurements], list[Initiation]]:
    r"""The trackers' starts as they move with the data of the initiation window.

    A tracker starts from an initiation of the window's data; shift the data
    and the start moves too.  For each hypothesis the window's
    :func:`~fgdoppler.estimators.window.window_start` solution is found once
    for ``measurements``; the function returned re-solves the window of
    other data from it and moves the hypothesis's ``x_start`` and ``x_end``
    by the solution's change (carried from the window's first and last scan
    to ``t_start`` and ``t_end`` by the motion model; no change where either
    solve fails or the window is empty).  The covariances stay.  Hypotheses
    whose window solutions are one minimum (:data:`SAME_MINIMUM`) share one
    re-solve: the terms of a Gaussian sum mostly converge there, and a
    restart's window is all the data so far.
    """
    from fgdoppler.estimators.window import solve_window, split_window, window_start

    solved = []
    same: list[int] = []  # for each hypothesis, the first one whose window solution is the same minimum
    for i, h in enumerate(hyps):
        window, _ = split_window(measurements, h.t_end)
        times = window.scans().times
        s0, note = window_start(model, window, h, huber_k=huber_k) if times.size else (None, "empty")
        solved.append((times, None if note else s0))
        same.append(next((j for j in range(i) if _same_minimum(h, solved[i], solved[j])), i))

    def moved(data: Measurements) -> list[Initiation]:
        changes: dict[int, tuple[FloatArray, FloatArray] | None] = {}
        out = []
        for h, (times, s0), j in zip(hyps, solved, same, strict=True):
            if s0 is None:
                out.append(h)
                continue
            if j not in changes:  # one solve per minimum: started from the same one, the data move it alike
                window, _ = split_window(data, hyps[j].t_end)
                sj = solved[j][1]
                assert sj is not None
                s1, note = solve_window(model, window, sj, prior=model.prior(), huber_k=huber_k)
                changes[j] = None if note else (s1[0] - sj[0], s1[-1] - sj[-1])
            change = changes[j]
            if change is None:
                out.append(h)
                continue
            d0 = model.motion.F(h.t_start - times[0]) @ change[0]
            d1 = model.motion.F(h.t_end - times[-1]) @ change[1]
            out.append(replace(h, x_start=h.x_start + d0, x_end=h.x_end + d1))
        return out

    return moved
