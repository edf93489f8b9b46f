"""EKF step: fgdoppler versus FilterPy's ExtendedKalmanFilter on identical data and models (extra `bench`)."""

from __future__ import annotations

import numpy as np

import fgdoppler as fd
from benchmarks._common import Row, median_time
from fgdoppler.estimators.ekf import ExtendedKalmanFilter


def run() -> list[Row]:
    try:
        from filterpy.kalman import ExtendedKalmanFilter as FPEKF
    except ImportError:
        return [Row(name="EKF step vs FilterPy", value="skipped: pip install 'fgdoppler[bench]'")]
    scen = fd.paper_scenario("a", 45e3)
    sim = fd.simulate(scen, np.random.default_rng(3))
    m = sim.measurements
    tracking = fd.TrackingModel.of(scen.geometry)
    model = tracking.observation
    settings = fd.EKFSettings(gate_probability=None)
    motion = tracking.motion
    x0 = np.asarray(scen.x0) + np.array([200.0, -50.0, 3.0, 1.0])
    P0 = np.diag([500.0**2, 100.0**2, 20.0**2, 10.0**2])

    def ours() -> np.ndarray:
        f = ExtendedKalmanFilter(tracking, x0, P0, 0.0, settings)
        for t, p, z, s in zip(m.time, m.pair, m.doppler, m.sigma, strict=True):
            f.update(float(t), int(p), float(z), float(s))
        return f.x

    def theirs() -> np.ndarray:
        f = FPEKF(dim_x=4, dim_z=1)
        f.x = x0.copy()
        f.P = P0.copy()
        t_prev = 0.0
        for t, p, z, s in zip(m.time, m.pair, m.doppler, m.sigma, strict=True):
            dt = float(t) - t_prev
            if dt > 0:
                f.F = motion.F(dt)
                f.Q = motion.Q(dt)
                f.predict()
                t_prev = float(t)

            def hj(x: np.ndarray, p: int = int(p)) -> np.ndarray:
                return model.predict_and_jacobian(x.reshape(1, 4), [p])[1]

            def hx(x: np.ndarray, p: int = int(p)) -> np.ndarray:
                return model.predict(x.reshape(1, 4), [p])

            f.update(np.array([z]), hj, hx, R=np.array([[s * s]]))
        return np.asarray(f.x).reshape(4)

    diff = float(np.max(np.abs(ours() - theirs()) / np.maximum(np.abs(ours()), 1.0)))
    t_ours = median_time(ours)
    t_theirs = median_time(theirs)
    ratio = t_ours / t_theirs
    n = len(m)
    return [Row(name=f"EKF, {n} scalar updates (paper scenario a 45 km) vs FilterPy",
                value=f"{t_ours / n * 1e6:.1f} us/update vs {t_theirs / n * 1e6:.1f} us; estimates agree to {diff:.1e}",
                ratio=ratio, target="<= 0.3x, agree to 1e-9", met=ratio <= 0.3 and diff <= 1e-9)]
