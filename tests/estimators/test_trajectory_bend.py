"""The probe of the whole track's likelihood beyond the sampled span: the conditional step against the dense
covariance, the quadratic model's rise, and the finding where a long recording's valley bends."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.curvature import CURVATURE_LIMIT, probe_axis
from fgdoppler.estimators.smoother_solve import solve_smoother
from fgdoppler.estimators.spread import MAX_SPAN
from fgdoppler.estimators.trajectory_bend import (
    _problem,
    conditional_step,
    long_track_reason,
    trajectory_ratio,
)


def _long(case: str, x0: tuple[float, float, float, float], duration: float, q: float, seed: int
          ) -> tuple[fd.TrackingModel, fd.Simulation]:
    motion = fd.ConstantVelocity(q=q)
    g = fd.paper_geometry(case)
    scen = fd.Scenario(geometry=g, x0=x0, duration=duration, dt=0.5, time_offsets=(0.0, 0.0), process_noise=motion)
    return fd.TrackingModel.of(g, motion=motion), fd.simulate(scen, np.random.default_rng(seed))


def _optimum(model: fd.TrackingModel, sim: fd.Simulation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    m = sim.measurements
    times = m.scans().times
    sol = solve_smoother(m, model, sim.truth.at(times), fd.SmootherSettings(region_bound=False),
                         prior=model.prior())
    assert sol.covariances is not None
    return sol.times, sol.states, sol.covariances


def test_the_conditional_step_is_the_dense_covariances_regression() -> None:
    # Another construction: the dense inverse (by SVD) of the Gauss-Newton information J'J of the whole track (case a
    # 25 km, 10 s, 21 states) gives each state's shift given state k moved by delta_k as P_jk P_kk^-1 delta_k.
    # The chain solve with state k held must give the same, and its quadratic rise |A step|^2 must be
    # delta_k' P_kk^-1 delta_k = 1 (one standard deviation along the marginal's major axis).
    model, sim = _long("a", (25e3, 2e3, 10.0, -100.0), 10.0, 1e-3, 0)
    times, x, covs = _optimum(model, sim)
    prob = _problem(sim.measurements, model, times, None)
    A, _ = prob.system(x, 0.0, wall=False).jacobian()
    _, s, Vt = np.linalg.svd(A, full_matrices=False)  # not inv(A'A): that squares a condition number of ~1e6
    P = (Vt.T / s**2) @ Vt
    n, nx = x.shape
    blocks = P.reshape(n, nx, n, nx)
    np.testing.assert_allclose(np.einsum("kikj->kij", blocks), covs, rtol=1e-6, atol=1e-9)  # the same ordering
    for k in (0, n // 2, n - 1):
        step, quad, sd = conditional_step(prob, x, covs[k], k)
        delta, sd_axis = probe_axis(covs[k])
        expected = blocks[:, :, k, :] @ np.linalg.solve(covs[k], delta)
        np.testing.assert_allclose(step, expected, rtol=1e-5, atol=1e-6 * np.max(np.abs(expected)))
        assert quad == pytest.approx(1.0, rel=1e-6) and sd == sd_axis


def test_a_long_recordings_curved_valley_is_found_and_a_straight_one_is_not() -> None:
    # Case a from (25, 3) km at (20, -60) m/s for 400 s, the truth with q = 0.05 m^2/s^3 and the model told so:
    # the track ends 21 km off the sensors' line, on a valley whose curvature radius is about its distance
    # (module docstring: on 600 s recordings the last state's ratio was 265-395).  Case a 45 km flown 400 s with
    # q = 1e-3 is well observed: its likelihood is the Laplace model's to within 1.3 times at every probed
    # state (measured 0.99-1.21 on four seeds).
    model, sim = _long("a", (25e3, 3e3, 20.0, -60.0), 400.0, 0.05, 3)
    times, x, covs = _optimum(model, sim)
    prob = _problem(sim.measurements, model, times, None)
    last = trajectory_ratio(prob, x, covs[-1], prob.n - 1)[0]
    assert last > CURVATURE_LIMIT
    found = long_track_reason(sim.measurements, model, times, x, covs)
    assert found is not None and found.code == "nonlinear" and found.status == "doubtful", found
    assert "t = 400 s" in found.message and "curved valley" in found.message
    model, sim = _long("a", (45e3, 2e3, 10.0, -100.0), 400.0, 1e-3, 1)
    times, x, covs = _optimum(model, sim)
    prob = _problem(sim.measurements, model, times, None)
    for k in (0, prob.n // 2, prob.n - 1):
        assert 1.0 / 1.3 < trajectory_ratio(prob, x, covs[k], k)[0] < 1.3
    assert long_track_reason(sim.measurements, model, times, x, covs) is None


def test_the_smoother_says_so_beyond_the_sampled_span_and_reports_its_laplace_answer() -> None:
    # Through the registry: past MAX_SPAN nothing is sampled, and where the probe finds the bend the smoother is
    # doubtful with the nonlinear finding while its track and covariances are the Laplace ones (those it reports
    # with the sampled covariances off).  The same recording cut to MAX_SPAN is sampled instead, and says nothing
    # of the kind.
    model, sim = _long("a", (25e3, 3e3, 20.0, -60.0), 400.0, 0.05, 3)
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), model)
    plain = fd.SmootherSettings(motion_check=False)
    on = fd.run_estimator("smoother", m, model, init, plain)
    off = fd.run_estimator("smoother", m, model, init, dataclasses.replace(plain, sampled_covariance=False))
    assert on.status == "doubtful" and [r.code for r in on.reasons if r.status != "ok"] == ["nonlinear"]
    assert "no posterior samples are drawn" in next(r.message for r in on.reasons if r.code == "nonlinear")
    np.testing.assert_array_equal(on.primary.states, off.primary.states)
    np.testing.assert_array_equal(on.primary.covariances, off.primary.covariances)
    assert not any(r.code == "nonlinear" and r.status != "ok" for r in off.reasons)
    short = m.between(0.0, MAX_SPAN)
    cut = fd.run_estimator("smoother", short, model, init, plain)
    assert not any("no posterior samples are drawn" in r.message for r in cut.reasons)
