"""The particle estimators' basin screen: its batched climbs, when it fires, and how the restart test reads it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares

import fgdoppler as fd
from fgdoppler.estimators.basin_screen import basin_screen, refined_costs
from fgdoppler.estimators.restart import MODE_MARGIN, surprise_check
from fgdoppler.models.doppler import StackedTimes, cv_doppler, cv_doppler_and_jacobian


def _data_to(m: fd.Measurements, t0: float, tc: float) -> tuple[StackedTimes, np.ndarray, np.ndarray]:
    sel = m.time <= tc
    return StackedTimes(pair=m.pair[sel], t=m.time[sel] - t0), m.doppler[sel], m.sigma[sel]


def _scipy_cost(geometry: fd.Geometry, x0: np.ndarray, times: StackedTimes, z: np.ndarray, sigma: np.ndarray
                ) -> float:
    """The same least cost by SciPy's MINPACK Levenberg–Marquardt from the same start."""
    fit = least_squares(lambda x: (z - cv_doppler(x, geometry, times)) / sigma, x0,
                        jac=lambda x: -cv_doppler_and_jacobian(x, geometry, times)[1] / sigma[:, None],
                        method="lm", x_scale="jac", max_nfev=400)
    return float(2.0 * fit.cost)


def test_noise_free_data_climb_to_zero_from_near_the_truth() -> None:
    # The data are the model's own values along the truth: the least cost in its basin is 0, reached from
    # starts a few hundred metres and ten m/s off; a start on the track's mirror (sensors near one line) climbs
    # its own basin, whose least cost is positive.
    sc = fd.paper_scenario("a", 25e3)
    times = StackedTimes(pair=np.tile([0, 1], 60), t=np.repeat(np.arange(60) * 0.5, 2))
    x0 = np.asarray(sc.x0, dtype=float)
    z = cv_doppler(x0, sc.geometry, times)
    starts = x0 + np.array([[300.0, -200.0, 10.0, -5.0], [-400.0, 250.0, -8.0, 6.0], [0.0, 0.0, 0.0, 0.0]])
    costs = refined_costs(sc.geometry, starts, times, z, np.ones(z.size))
    assert np.all(costs < 1e-6), costs
    mirror = refined_costs(sc.geometry, (x0 * [1.0, -1.0, 1.0, -1.0])[None], times, z, np.ones(z.size))
    assert mirror[0] > 1.0


def test_batched_climbs_reach_the_minima_scipy_reaches_in_2d_and_3d() -> None:
    # An independent method from the same starts: SciPy's least_squares (MINPACK) on the same cost.  In 3-D over
    # ground sensors the Doppler is even in the height, whose derivative vanishes at 0: the scaling must not let
    # that direction's damping vanish with it (with the current diagonal as the scale, 5 of the 6 starts below
    # stalled 48-3,770 above SciPy's minima).
    sc = fd.paper_scenario("b", 25e3)
    sim = fd.simulate(sc, np.random.default_rng(3))
    init = fd.initiate(sim.measurements.first_per_pair(10), sc.geometry)
    starts = np.array([init.x_start, *(a.state for a in init.alternatives), *(c.state for c in init.candidates)])
    times, z, sigma = _data_to(sim.measurements, init.t_start, 20.0)
    batched = refined_costs(sc.geometry, starts, times, z, sigma)
    scipy = np.array([_scipy_cost(sc.geometry, x, times, z, sigma) for x in starts])
    np.testing.assert_allclose(batched, scipy, atol=1e-3)

    # the layout and starts of draw 21 of `studies/random_layouts_3d.py` (rounded): three pairs on the ground,
    # the target at 2 km, the initiation's solutions at 0.3-7 km
    g3 = fd.Geometry(pairs=(fd.BistaticPair(tx=(-21116.0, -4966.0, 0.0), rx=(-1709.0, -16581.0, 0.0)),
                            fd.BistaticPair(tx=(4759.0, -24910.0, 0.0), rx=(-35138.0, -11145.0, 0.0)),
                            fd.BistaticPair(tx=(15237.0, -16782.0, 0.0), rx=(9573.0, 36853.0, 0.0))))
    sim3 = fd.simulate(fd.Scenario(geometry=g3, x0=(-12782.0, 19285.0, 1959.0, -162.1, -110.7, 8.1), duration=25.0,
                                   dt=0.5), np.random.default_rng(0))
    starts3 = np.array([[7113.5, -16000.0, 255.7, -123.9, -86.5, 0.9], [-14813.9, 13688.2, 1441.3, -148.5, -120.7, 0.0],
                        [-12957.8, 9781.2, 7206.4, -148.5, -120.7, 0.0], [3115.1, -12420.4, 1441.3, -93.2, -155.7, 0.0],
                        [5173.9, -13652.5, 7206.4, -140.8, -114.4, 0.0], [6827.3, -20234.3, 1441.3, -143.1, -49.5, 0.0]])
    times3, z3, sigma3 = _data_to(sim3.measurements, 0.0, 25.0)
    batched3 = refined_costs(g3, starts3, times3, z3, sigma3)
    scipy3 = np.array([_scipy_cost(g3, x, times3, z3, sigma3) for x in starts3])
    np.testing.assert_allclose(batched3, scipy3, atol=0.05)
    # a start exactly on the ground has no derivative in height or climb rate: it climbs in the plane (as SciPy
    # does) and its singular normal matrix stops no other start's climb
    grounded = starts3.copy()
    grounded[3, [2, 5]] = 0.0
    batched_g = refined_costs(g3, grounded, times3, z3, sigma3)
    scipy_g = np.array([_scipy_cost(g3, x, times3, z3, sigma3) for x in grounded])
    np.testing.assert_allclose(batched_g, scipy_g, atol=0.05)


def test_the_screen_fires_where_a_start_fits_the_data_so_far_better_by_the_margin() -> None:
    # Case a at 25 km: the track and its mirror across the sensors' line fit the first 10 s about equally
    # (least costs 35.8 and 36.3 on this recording), after 30 s no longer (90 and 669).  A running estimate in
    # the mirror's basin is screened out at 30 s, not at 10 s; one on the truth never is.
    sc = fd.paper_scenario("a", 25e3)
    sim = fd.simulate(sc, np.random.default_rng(1))
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), sc.geometry)
    fires = basin_screen(m, fd.TrackingModel.of(sc.geometry), init, MODE_MARGIN)
    assert fires is not None
    flip = np.array([1.0, -1.0, 1.0, -1.0])
    for tc, mirror_fires in ((10.0, False), (30.0, True)):
        truth = sim.truth.at([tc])[0]
        assert not fires(truth, tc)
        assert fires(truth * flip, tc) is mirror_fires
    # the margin is the test's: one beyond the costs' whole difference keeps it quiet
    times, z, sigma = _data_to(m, init.t_start, 30.0)
    own = fd.TrackingModel.of(sc.geometry).motion.F(init.t_start - 30.0) @ (sim.truth.at([30.0])[0] * flip)
    gap = refined_costs(sc.geometry, own[None], times, z, sigma)[0] - refined_costs(
        sc.geometry, init.x_start[None], times, z, sigma)[0]
    assert gap > MODE_MARGIN
    quiet = basin_screen(m, fd.TrackingModel.of(sc.geometry), init, gap + 1.0)
    assert quiet is not None and not quiet(sim.truth.at([30.0])[0] * flip, 30.0)


def test_the_restart_test_asks_the_screen_with_the_filtered_estimate_where_nothing_surprised() -> None:
    sc = fd.paper_scenario("b", 5e3)
    sim = fd.simulate(sc, np.random.default_rng(2))
    init = fd.initiate(sim.measurements.first_per_pair(10), sc.geometry)
    res = fd.run_estimator("ekf", sim.measurements, sc.geometry, init, fd.EKFSettings(restarts=False), verify=False)
    quiet = replace(res, nis=np.zeros((0, 4)))  # no innovation: nothing surprises it
    e = res.primary
    tc = float(e.times[30])
    asked: list[tuple[np.ndarray, float]] = []

    def screen(state: np.ndarray, t: float) -> bool:
        asked.append((state, t))
        return True

    assert surprise_check(init.t_start, 100.0, screen)(quiet, tc - 1.0, tc)
    np.testing.assert_array_equal(asked[0][0], e.states[30])
    assert asked[0][1] == tc
    # no filtered estimate at that time, beyond the span, or no screen: not asked, no test
    asked.clear()
    assert not surprise_check(init.t_start, 100.0, screen)(quiet, tc - 1.0, tc + 0.123)
    assert not surprise_check(init.t_start, tc - init.t_start - 1.0, screen)(quiet, tc - 1.0, tc)
    assert not surprise_check(init.t_start, 100.0)(quiet, tc - 1.0, tc)
    assert asked == []
