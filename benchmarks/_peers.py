"""Peer filters from FilterPy (extra ``bench``), started from fgdoppler's initiation on the same data.

Each peer gets exactly what fgdoppler's EKF gets: the initiation's state and
covariance at the end of its window, the same constant-velocity motion
model (F and Q per step), the same Doppler model and σ, and every scan after
the window, all of a scan's measurements in one (vector) update.  No gate.

* ``filterpy-ekf``: :class:`filterpy.kalman.ExtendedKalmanFilter`, the
  analytic Jacobian of :class:`fgdoppler.DopplerModel`.
* ``filterpy-ukf``: :class:`filterpy.kalman.UnscentedKalmanFilter` with
  Van der Merwe's scaled sigma points, α = 1, β = 2, κ = 0 (nine points
  spread to one standard deviation times √n: a wide spread suits the
  strongly curved Doppler model; small α collapses the UKF onto the EKF).
* ``filterpy-urts``: that UKF's filtered track smoothed by FilterPy's
  unscented Rauch–Tung–Striebel smoother (the same Q and time steps).

With the extra ``stonesoup`` installed, Stone Soup's smoothers join, run on
fgdoppler's model through :mod:`fgdoppler.interop.stonesoup` (one vector
detection per scan, Stone Soup's ``ConstantVelocity`` with the same ``q``):

* ``stonesoup-ekf-rts``: ``ExtendedKalmanUpdater`` then
  ``ExtendedKalmanSmoother``;
* ``stonesoup-ukf-urts``: ``UnscentedKalmanUpdater`` (α = 1, β = 2,
  κ = 0, as above) then ``UnscentedKalmanSmoother``.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

import fgdoppler as fd

__all__ = ["PEERS", "run_peers"]

FloatArray = NDArray[np.float64]

PEERS: tuple[str, ...] = ("filterpy-ekf", "filterpy-ukf", "filterpy-urts")
SMOOTHERS: tuple[str, ...] = ("filterpy-urts", "stonesoup-ekf-rts", "stonesoup-ukf-urts")


def stonesoup_available() -> bool:
    """Whether the extra ``stonesoup`` is installed (its peers are then run too)."""
    import importlib.util

    return importlib.util.find_spec("stonesoup") is not None


def _stream(meas: fd.Measurements, t_end: float) -> tuple[FloatArray, list[slice], fd.Measurements]:
    stream = meas.subset(meas.time > t_end + 1e-9)
    sc = stream.scans()
    return sc.times, [sc.rows(k) for k in range(len(sc))], stream


def _ekf(model: fd.TrackingModel, init: fd.Initiation, meas: fd.Measurements
         ) -> tuple[FloatArray, FloatArray, FloatArray]:
    from filterpy.kalman import ExtendedKalmanFilter

    obs, motion = model.observation, model.motion
    times, rows, stream = _stream(meas, init.t_end)
    f = ExtendedKalmanFilter(dim_x=4, dim_z=1)
    f.x = init.x_end.copy()
    f.P = np.asarray(init.P_end).copy()
    ts, xs, Ps = [init.t_end], [f.x.copy()], [f.P.copy()]
    t_prev = init.t_end
    for t, sl in zip(times, rows, strict=True):
        f.F = motion.F(t - t_prev)
        f.Q = motion.Q(t - t_prev)
        f.predict()
        pairs = stream.pair[sl]

        def hj(x: FloatArray, pairs: NDArray[np.intp] = pairs) -> FloatArray:
            return obs.predict_and_jacobian(np.broadcast_to(x, (pairs.size, 4)), pairs)[1]

        def hx(x: FloatArray, pairs: NDArray[np.intp] = pairs) -> FloatArray:
            return obs.predict(np.broadcast_to(x, (pairs.size, 4)), pairs)

        f.update(stream.doppler[sl], hj, hx, R=np.diag(stream.sigma[sl] ** 2))
        ts.append(t)
        xs.append(np.asarray(f.x, dtype=float).reshape(4).copy())
        Ps.append(np.asarray(f.P, dtype=float).copy())
        t_prev = t
    return np.array(ts), np.array(xs), np.array(Ps)


def _ukf(model: fd.TrackingModel, init: fd.Initiation, meas: fd.Measurements
         ) -> tuple[FloatArray, FloatArray, FloatArray]:
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    obs, motion = model.observation, model.motion
    times, rows, stream = _stream(meas, init.t_end)

    def fx(x: FloatArray, dt: float) -> FloatArray:
        return motion.F(dt) @ x

    points = MerweScaledSigmaPoints(n=4, alpha=1.0, beta=2.0, kappa=0.0)
    f = UnscentedKalmanFilter(dim_x=4, dim_z=1, dt=0.5, hx=None, fx=fx, points=points)
    f.x = init.x_end.copy()
    f.P = np.asarray(init.P_end).copy()
    ts, xs, Ps = [init.t_end], [f.x.copy()], [f.P.copy()]
    t_prev = init.t_end
    for t, sl in zip(times, rows, strict=True):
        dt = t - t_prev
        f.Q = motion.Q(dt)
        f.predict(dt=dt)
        pairs = stream.pair[sl]

        def hx(x: FloatArray, pairs: NDArray[np.intp] = pairs) -> FloatArray:
            return obs.predict(np.broadcast_to(x, (pairs.size, 4)), pairs)

        f.update(stream.doppler[sl], R=np.diag(stream.sigma[sl] ** 2), hx=hx)
        ts.append(t)
        xs.append(np.asarray(f.x, dtype=float).copy())
        Ps.append(np.asarray(f.P, dtype=float).copy())
        t_prev = t
    return np.array(ts), np.array(xs), np.array(Ps)


def _urts(model: fd.TrackingModel, ts: FloatArray, xs: FloatArray, Ps: FloatArray) -> tuple[FloatArray, FloatArray]:
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    motion = model.motion

    def fx(x: FloatArray, dt: float) -> FloatArray:
        return motion.F(dt) @ x

    points = MerweScaledSigmaPoints(n=4, alpha=1.0, beta=2.0, kappa=0.0)
    f = UnscentedKalmanFilter(dim_x=4, dim_z=1, dt=0.5, hx=None, fx=fx, points=points)
    steps = np.diff(ts)
    # FilterPy's smoother propagates step k with dts[k] but always adds its one self.Q (it ignores
    # Qs in the transform); the paper's recordings have one step after the window, so that is exact.
    if steps.size and np.ptp(steps) > 1e-9:
        raise ValueError("FilterPy's URTS needs a constant time step")
    dt = float(steps[0]) if steps.size else 0.5
    f.Q = motion.Q(dt)
    xs_s, Ps_s, _ = f.rts_smoother(xs, Ps, dts=np.full(len(ts), dt))
    return np.asarray(xs_s), np.asarray(Ps_s)


def run_peers(model: fd.TrackingModel, init: fd.Initiation, meas: fd.Measurements
              ) -> dict[str, tuple[FloatArray, FloatArray, FloatArray, float]]:
    """``{name: (times, states, covariances, seconds)}`` of every peer, from ``init``'s window end (CPU seconds)."""
    out = {}
    t0 = time.process_time()
    ts, xs, Ps = _ekf(model, init, meas)
    out["filterpy-ekf"] = (ts, xs, Ps, time.process_time() - t0)
    t0 = time.process_time()
    ts, xs, Ps = _ukf(model, init, meas)
    t_ukf = time.process_time() - t0
    out["filterpy-ukf"] = (ts, xs, Ps, t_ukf)
    t0 = time.process_time()
    xs_s, Ps_s = _urts(model, ts, xs, Ps)
    out["filterpy-urts"] = (ts, xs_s, Ps_s, t_ukf + time.process_time() - t0)
    if stonesoup_available():
        out.update(_stonesoup_smoothers(model, init, meas))
    return out


def _stonesoup_smoothers(model: fd.TrackingModel, init: fd.Initiation, meas: fd.Measurements
                         ) -> dict[str, tuple[FloatArray, FloatArray, FloatArray, float]]:
    import datetime as dt

    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor, UnscentedKalmanPredictor
    from stonesoup.smoother.kalman import ExtendedKalmanSmoother, UnscentedKalmanSmoother
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater

    from fgdoppler.interop.stonesoup import detections, from_track, prior

    epoch = dt.datetime(2026, 1, 1)
    q = model.motion.q
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    dets = [d for d in detections(meas, model.geometry, epoch, per_scan=True)
            if d.metadata["time"] > init.t_end + 1e-9]
    sigma = {"alpha": 1.0, "beta": 2.0, "kappa": 0.0}
    runs = {
        "stonesoup-ekf-rts": (ExtendedKalmanPredictor(transition), ExtendedKalmanUpdater(measurement_model=None),
                              ExtendedKalmanSmoother(transition)),
        "stonesoup-ukf-urts": (UnscentedKalmanPredictor(transition, **sigma),
                               UnscentedKalmanUpdater(measurement_model=None, **sigma),
                               UnscentedKalmanSmoother(transition, **sigma)),
    }
    out = {}
    for name, (predictor, updater, smoother) in runs.items():
        t0 = time.process_time()
        state = prior(init, epoch)
        track = Track([state])
        for d in dets:
            state = updater.update(SingleHypothesis(predictor.predict(state, timestamp=d.timestamp), d))
            track.append(state)
        est = from_track(smoother.smooth(track), epoch).primary
        out[name] = (est.times, est.states, est.covariances, time.process_time() - t0)
    return out


def run_stonesoup_pf(model: fd.TrackingModel, meas: fd.Measurements, *, n_particles: int = 20_000,
                     seed: int = 0, moves: int = 10) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """Stone Soup's particle filter (extra ``stonesoup``): no initiation needed.

    ``n_particles`` drawn uniformly over the zone (positions in its box,
    velocities uniform in the disc of its speed bound) at the first
    measurement time, the same constant-velocity model (Stone Soup's
    ``ConstantVelocity`` with the same ``q``: the same continuous white-noise
    Q), fgdoppler's Doppler model through :mod:`fgdoppler.interop.stonesoup`,
    systematic resampling when the effective sample size falls below half
    and ``moves`` of Stone Soup's Metropolis–Hastings moves
    (``MCMCRegulariser``) after each resampling: the resample-move filter
    of the accuracy issue.  (One move per resampling, Stone Soup's default,
    collapses: from a uniform prior the few particles that explain the first
    measurements are duplicated and one small move cannot spread them.)
    Returns ``(times, states, covariances, seconds)`` at every scan time.
    """
    import datetime as dt

    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.regulariser.particle import MCMCRegulariser
    from stonesoup.resampler.particle import ESSResampler
    from stonesoup.types.array import StateVectors
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import ParticleState
    from stonesoup.updater.particle import ParticleUpdater

    from fgdoppler.interop.stonesoup import TO_STONESOUP, detections

    zone = model.zone
    assert zone is not None
    t_begin = time.process_time()
    np.random.seed(seed)  # noqa: NPY002 -- Stone Soup draws from numpy's global generator
    rng = np.random.default_rng(seed)
    q = model.motion.q
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    predictor = ParticlePredictor(transition)
    regulariser = MCMCRegulariser(transition_model=transition)
    updater = ParticleUpdater(measurement_model=None, resampler=ESSResampler(), regulariser=regulariser)
    local = np.column_stack([rng.uniform(*zone.along, n_particles), rng.uniform(*zone.across, n_particles)])
    pos = zone.frame.points_to_world(local)
    speed = zone.speed_max * np.sqrt(rng.uniform(0, 1, n_particles))
    heading = rng.uniform(0, 2 * np.pi, n_particles)
    ours = np.column_stack([pos, speed * np.sin(heading), speed * np.cos(heading)])
    epoch = dt.datetime(2026, 1, 1)
    t0 = float(meas.time[0])
    state = ParticleState(StateVectors(ours[:, TO_STONESOUP].T), weight=np.full(n_particles, 1.0 / n_particles),
                          timestamp=epoch + dt.timedelta(seconds=t0))
    dets = detections(meas, model.geometry, epoch)
    times, xs, Ps = [], [], []
    for k, det in enumerate(dets):
        prediction = predictor.predict(state, timestamp=det.timestamp)
        state = updater.update(SingleHypothesis(prediction, det))
        if np.ptp(np.asarray(state.log_weight, dtype=float)) == 0.0:  # resampled (and moved once)
            # the move's prior term pairs each particle with its own parent: the resampled state's
            # parent (indexed with it), as the updater's own first move does
            for _ in range(moves - 1):
                state = regulariser.regularise(state.parent, state)
        last_of_scan = k + 1 == len(dets) or dets[k + 1].timestamp != det.timestamp
        if last_of_scan:
            times.append(det.metadata["time"])
            xs.append(np.asarray(state.mean, dtype=float).reshape(-1)[TO_STONESOUP])
            P = np.asarray(state.covar, dtype=float)
            Ps.append(P[np.ix_(TO_STONESOUP, TO_STONESOUP)])
    return np.array(times), np.array(xs), np.array(Ps), time.process_time() - t_begin
