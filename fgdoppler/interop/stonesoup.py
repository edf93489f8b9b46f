r"""Stone Soup interoperability: the bistatic Doppler model, detections, priors and tracks.

Optional extra ``fgdoppler[stonesoup]``; importing this module imports
Stone Soup, nothing else in fgdoppler does.

Stone Soup orders a 2-D constant-velocity state as :math:`[x, \dot x, y, \dot y]`,
fgdoppler as :math:`[x, y, \dot x, \dot y]`; :data:`TO_STONESOUP` is the
permutation between them (its own inverse), applied to every state vector
and both sides of every covariance.  In 3-D Stone Soup's order is
:math:`[x, \dot x, y, \dot y, z, \dot z]` and fgdoppler's
:math:`[x, y, z, \dot x, \dot y, \dot z]` (:data:`TO_STONESOUP_3D`); every
function here takes either, by the state's length.

* :class:`BistaticDoppler` — a Stone Soup measurement model for one Tx–Rx
  pair: :math:`h` and its analytic Jacobian are fgdoppler's
  (:mod:`fgdoppler.models.doppler`), vectorised over particle states.
* :func:`detections` — a fgdoppler :class:`~fgdoppler.measurements.Measurements`
  as Stone Soup :class:`~stonesoup.types.detection.Detection` s, each with
  its pair's model and a datetime timestamp from an epoch.
* :func:`prior` — a fgdoppler initiation as a Stone Soup
  :class:`~stonesoup.types.state.GaussianState` at the end of its window.
* :func:`to_track` / :func:`from_track` — a fgdoppler
  :class:`~fgdoppler.estimators.results.TrackResult` estimate as a Stone Soup
  :class:`~stonesoup.types.track.Track` of Gaussian states and back, so that
  either side's metrics and plots apply to the other's output.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

try:
    from stonesoup.base import Property
    from stonesoup.models.measurement.nonlinear import NonLinearGaussianMeasurement
    from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "fgdoppler.interop.stonesoup needs Stone Soup: pip install 'fgdoppler[stonesoup]'") from exc

from fgdoppler.estimators.initiation import Initiation
from fgdoppler.estimators.results import Estimates, TrackResult
from fgdoppler.estimators.settings import TrackerSettings
from fgdoppler.geometry import BistaticPair, Geometry
from fgdoppler.measurements import Measurements
from fgdoppler.models.doppler import bistatic_doppler_and_jacobian

__all__ = ["TO_STONESOUP", "TO_STONESOUP_3D", "BistaticDoppler", "detections", "from_track", "measurements_from",
           "models", "prior", "to_track"]

FloatArray = NDArray[np.float64]

#: fgdoppler state index of each Stone Soup state component, and vice versa (a permutation that is its
#: own inverse): Stone Soup ``[x, vx, y, vy]`` = fgdoppler ``[x, y, vx, vy]``\ ``[TO_STONESOUP]``.
TO_STONESOUP = np.array([0, 2, 1, 3])
#: The 3-D permutation: Stone Soup ``[x, vx, y, vy, z, vz]`` = fgdoppler ``[x, y, z, vx, vy, vz]``\ ``[TO_STONESOUP_3D]``;
#: its inverse is ``np.argsort(TO_STONESOUP_3D)``.
TO_STONESOUP_3D = np.array([0, 3, 1, 4, 2, 5])


def _perm(n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(fgdoppler -> Stone Soup, Stone Soup -> fgdoppler) index arrays for states of ``n`` numbers."""
    if n == 4:
        return TO_STONESOUP, TO_STONESOUP
    if n == 6:
        return TO_STONESOUP_3D, np.argsort(TO_STONESOUP_3D)
    raise ValueError(f"states must have 4 (2-D) or 6 (3-D) numbers, got {n}")


class BistaticDoppler(NonLinearGaussianMeasurement):
    r"""Bistatic Doppler (range rate, m/s) of one or several Tx–Rx pairs as a Stone Soup measurement model.

    :math:`h_i(\mathbf x) = \dot r^T_i + \dot r^R_i`, the sum of the
    target's range rates to transmitter and receiver of pair :math:`i`
    (fgdoppler's :func:`~fgdoppler.models.doppler.bistatic_doppler`), with
    Gaussian noise of covariance ``noise_covar`` (``n × n``, m²/s²).
    ``tx`` and ``rx`` hold one pair as ``(x, y)`` or ``n`` pairs as the
    columns of a ``2 × n`` array (3-D: ``(x, y, z)`` or ``3 × n``, with
    ``mapping=(0, 2, 4)``, ``velocity_mapping=(1, 3, 5)``, ``ndim_state=6``);
    ``ndim_meas`` is ``n``.  One pair per
    detection is the natural model for asynchronous pairs; all pairs of a
    scan in one detection (:func:`detections` with ``per_scan=True``) gives
    Stone Soup's Kalman smoothers the one-prediction-per-scan track they
    need.  ``mapping`` gives the state indices of the position
    (:math:`x, y` or :math:`x, y, z`) and ``velocity_mapping`` those of the
    velocity (Stone Soup's constant-velocity order by default).
    """

    tx: np.ndarray = Property(doc="Transmitter position(s), m: (x, y[, z]) or d × n, one column per pair")
    rx: np.ndarray = Property(doc="Receiver position(s), m: (x, y[, z]) or d × n, one column per pair")
    mapping: Sequence[int] = Property(default=(0, 2), doc="State indices of the position (x, y[, z])")
    velocity_mapping: Sequence[int] = Property(default=(1, 3), doc="State indices of the velocity")
    ndim_state: int = Property(default=4, doc="Number of state dimensions")

    def _sensors(self) -> tuple[FloatArray, FloatArray]:
        d = len(self.mapping)
        if d not in (2, 3) or len(self.velocity_mapping) != d:
            raise ValueError(f"mapping and velocity_mapping must both have 2 or 3 indices, got {self.mapping} "
                             f"and {self.velocity_mapping}")
        tx = np.asarray(self.tx, dtype=float).reshape(d, -1).T
        rx = np.asarray(self.rx, dtype=float).reshape(d, -1).T
        if tx.shape != rx.shape:
            raise ValueError(f"tx and rx must hold as many pairs: {tx.shape[0]} and {rx.shape[0]}")
        return tx, rx

    @property
    def ndim_meas(self) -> int:
        """One Doppler value per pair."""
        return self._sensors()[0].shape[0]

    def _geometry(self) -> Geometry:
        tx, rx = self._sensors()
        return Geometry(pairs=tuple(BistaticPair(tx=tuple(map(float, a)), rx=tuple(map(float, b)))
                                    for a, b in zip(tx, rx, strict=True)))

    def _ours(self, state_vector: ArrayLike) -> FloatArray:
        sv = np.asarray(state_vector, dtype=float)
        sv = sv.reshape(sv.shape[0], -1)
        return np.stack([sv[i] for i in (*self.mapping, *self.velocity_mapping)], axis=-1)

    def function(self, state, noise=False, **kwargs) -> StateVectors:
        """Doppler of every column of ``state.state_vector`` (``n × m``), plus noise if asked."""
        h, _ = bistatic_doppler_and_jacobian(self._ours(state.state_vector), self._geometry())
        out = StateVectors(np.asarray(h, dtype=float).T)
        if isinstance(noise, bool) or noise is None:
            noise = self.rvs(num_samples=out.shape[1], **kwargs) if noise else 0
        return out + noise

    def jacobian(self, state, **kwargs) -> FloatArray:
        """Analytic Jacobian ``n × ndim_state`` at ``state`` (fgdoppler's, re-ordered)."""
        _, J = bistatic_doppler_and_jacobian(self._ours(state.state_vector)[:1], self._geometry())
        idx = (*self.mapping, *self.velocity_mapping)
        J = np.asarray(J, dtype=float).reshape(-1, len(idx))
        out = np.zeros((J.shape[0], self.ndim_state))
        for k, i in enumerate(idx):
            out[:, i] = J[:, k]
        return out


def models(geometry: Geometry, sigma: float | Sequence[float]) -> list[BistaticDoppler]:
    """One single-pair :class:`BistaticDoppler` per pair of ``geometry`` (σ in m/s, one or one per pair)."""
    s = np.broadcast_to(np.asarray(sigma, dtype=float), (geometry.n_pairs,))
    return [BistaticDoppler(tx=geometry.tx[i].copy(), rx=geometry.rx[i].copy(),
                            noise_covar=CovarianceMatrix([[float(s[i]) ** 2]]), **_layout(geometry.dim))
            for i in range(geometry.n_pairs)]


def _layout(d: int) -> dict[str, object]:
    """Stone Soup's constant-velocity index layout for ``d`` spatial dimensions."""
    return {"mapping": tuple(range(0, 2 * d, 2)), "velocity_mapping": tuple(range(1, 2 * d, 2)),
            "ndim_state": 2 * d}


def _timestamp(epoch: dt.datetime, t: float) -> dt.datetime:
    return epoch + dt.timedelta(seconds=float(t))


def detections(measurements: Measurements, geometry: Geometry, epoch: dt.datetime, *,
               per_scan: bool = False) -> list[Detection]:
    """The measurements as Detections with their pairs' model and datetime timestamps, time order kept.

    ``per_scan=False``: one scalar Detection per measurement (its pair's
    model, its σ).  ``per_scan=True``: one Detection per scan (all
    measurements at one time, in file order) whose model holds those pairs
    and a diagonal noise covariance, for filters and smoothers that must
    predict once per time step.  ``metadata`` holds the time in seconds and
    the pair index (``"pair"``) or indices (``"pairs"``), so that
    :func:`measurements_from` reads them back exactly.

    Raises
    ------
    ValueError
        If a measurement names a pair the geometry does not have.
    """
    if len(measurements) and int(np.max(measurements.pair)) >= geometry.n_pairs:
        raise ValueError(f"a measurement names pair {int(np.max(measurements.pair))}, "
                         f"the geometry has {geometry.n_pairs} pairs (0-based)")
    cache: dict[tuple[tuple[int, ...], tuple[float, ...]], BistaticDoppler] = {}

    def model(pairs: tuple[int, ...], sigmas: tuple[float, ...]) -> BistaticDoppler:
        key = (pairs, sigmas)
        if key not in cache:
            idx = list(pairs)
            cache[key] = BistaticDoppler(tx=geometry.tx[idx].T.copy(), rx=geometry.rx[idx].T.copy(),
                                         noise_covar=CovarianceMatrix(np.diag(np.square(sigmas))),
                                         **_layout(geometry.dim))
        return cache[key]

    out = []
    if not per_scan:
        for t, p, z, s in zip(measurements.time, measurements.pair, measurements.doppler, measurements.sigma,
                              strict=True):
            out.append(Detection(StateVector([float(z)]), timestamp=_timestamp(epoch, float(t)),
                                 measurement_model=model((int(p),), (float(s),)),
                                 metadata={"pair": int(p), "time": float(t)}))
        return out
    scans = measurements.scans()
    for k in range(len(scans)):
        rows = scans.rows(k)
        pairs = tuple(int(p) for p in measurements.pair[rows])
        t = float(scans.times[k])
        out.append(Detection(StateVector(measurements.doppler[rows].astype(float)), timestamp=_timestamp(epoch, t),
                             measurement_model=model(pairs, tuple(float(s) for s in measurements.sigma[rows])),
                             metadata={"pairs": pairs, "time": t}))
    return out


def measurements_from(dets: Sequence[Detection]) -> Measurements:
    """The :class:`Measurements` behind Detections made by :func:`detections` (exact round trip)."""
    time, pair, doppler, sigma = [], [], [], []
    for d in dets:
        pairs = d.metadata["pairs"] if "pairs" in d.metadata else (d.metadata["pair"],)
        z = np.asarray(d.state_vector, dtype=float).reshape(-1)
        s = np.sqrt(np.diag(np.asarray(d.measurement_model.covar(), dtype=float)))
        time += [d.metadata["time"]] * len(pairs)
        pair += list(pairs)
        doppler += list(z)
        sigma += list(s)
    return Measurements(time=np.array(time, dtype=float), pair=np.array(pair, dtype=np.intp),
                        doppler=np.array(doppler, dtype=float), sigma=np.array(sigma, dtype=float))


def _to_ss(x: FloatArray, P: FloatArray | None, t: dt.datetime) -> GaussianState:
    fwd, _ = _perm(x.size)
    cov = np.full((x.size, x.size), np.nan) if P is None else P[np.ix_(fwd, fwd)]
    return GaussianState(StateVector(x[fwd]), CovarianceMatrix(cov), timestamp=t)


def prior(init: Initiation, epoch: dt.datetime) -> GaussianState:
    """The initiation's state and covariance at the end of its window, in Stone Soup's order.

    Raises
    ------
    ValueError
        If the initiation's covariance is indeterminate.
    """
    if init.P_end is None:
        raise ValueError("the initiation's covariance is indeterminate: no Gaussian prior")
    return _to_ss(np.asarray(init.x_end, dtype=float), np.asarray(init.P_end, dtype=float),
                  _timestamp(epoch, init.t_end))


def to_track(result: TrackResult, epoch: dt.datetime, kind: str | None = None) -> Track:
    """One estimate of ``result`` (default: its primary) as a Track of GaussianStates.

    An indeterminate covariance becomes a matrix of NaN.  Datetimes resolve
    microseconds only, so the exact times in seconds, the estimator's name
    and the estimate's kind go into the track's ``init_metadata``
    (``"fgdoppler_times"``, ``"fgdoppler_estimator"``, ``"fgdoppler_kind"``)
    and :func:`from_track` restores them.
    """
    est = result.primary if kind is None else result.estimate(kind)  # type: ignore[arg-type]
    states = [_to_ss(est.states[k], est.covariances[k] if est.cov_ok[k] else None, _timestamp(epoch, est.times[k]))
              for k in range(len(est))]
    meta = {"fgdoppler_times": tuple(float(t) for t in est.times), "fgdoppler_estimator": result.estimator,
            "fgdoppler_kind": est.kind}
    return Track(states, init_metadata=meta)


def from_track(track: Track, epoch: dt.datetime, *, estimator: str | None = None,
               kind: str | None = None) -> TrackResult:
    """A Stone Soup track of Gaussian or particle states as a fgdoppler :class:`TrackResult`.

    Times are seconds since ``epoch`` (to the microsecond); a track made by
    :func:`to_track` and not extended since gives back its exact times, and
    its estimator name and kind unless ``estimator`` / ``kind`` are given
    (defaults otherwise: ``"stonesoup"``, ``"filtered"``).  A covariance
    with NaN is marked indeterminate; particle states contribute their
    weighted mean and covariance.  The result carries no verdict findings:
    :func:`~fgdoppler.estimators.judge.judge` or the metrics apply to it like to any other.
    """
    times, xs, Ps = [], [], []
    for s in track.states:
        times.append((s.timestamp - epoch).total_seconds())
        x = np.asarray(s.mean if hasattr(s, "mean") else s.state_vector, dtype=float).reshape(-1)
        P = np.asarray(s.covar, dtype=float)
        _, back = _perm(x.size)
        xs.append(x[back])
        Ps.append(None if not np.all(np.isfinite(P)) else P[np.ix_(back, back)])
    meta = track.metadatas[0] if track.metadatas else {}
    exact = meta.get("fgdoppler_times")
    if exact is not None and len(exact) == len(times) and np.allclose(exact, times, rtol=0.0, atol=1e-6):
        times = list(exact)
        estimator = estimator or meta.get("fgdoppler_estimator")
        kind = kind or meta.get("fgdoppler_kind")
    est = Estimates.from_lists(kind or "filtered", times, xs, Ps)  # type: ignore[arg-type]
    return TrackResult(estimator=estimator or "stonesoup", settings=TrackerSettings(gate_probability=None),
                       estimates=(est,))
