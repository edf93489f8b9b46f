from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd


def test_paper_scenarios_layout() -> None:
    scen = fd.paper_scenarios()
    assert len(scen) == 6
    a = fd.paper_scenario("a", 25e3)
    assert a.x0 == (25e3, 2e3, 10.0, -100.0)
    ta = a.measurement_times()
    assert len(ta[0]) == 61 and np.array_equal(ta[0], ta[1])
    b = fd.paper_scenario("b", 5e3)
    tb = b.measurement_times()
    np.testing.assert_allclose(tb[1] - tb[0][: tb[1].size], 0.25)


def test_noise_free_simulation_matches_model() -> None:
    scen = fd.paper_scenario("a", 45e3, sigma=1.0)
    sim = fd.simulate(scen, np.random.default_rng(0))
    truth = sim.truth
    # constant velocity truth
    np.testing.assert_allclose(truth.states[:, :2], np.asarray(scen.x0[:2]) + truth.times[:, None] * [10.0, -100.0])
    m = sim.measurements
    clean = fd.bistatic_doppler(truth.at(m.time), scen.geometry)[np.arange(len(m)), m.pair]
    resid = m.doppler - clean
    # 122 N(0,1) draws: mean within 4/sqrt(n), variance within a 99.9 % chi-square band
    assert abs(resid.mean()) < 4 / np.sqrt(resid.size)
    from scipy.stats import chi2

    n = resid.size
    assert chi2.ppf(0.0005, n) < np.sum(resid**2) < chi2.ppf(0.9995, n)


def test_same_seed_same_data_and_process_noise() -> None:
    scen = fd.Scenario(
        geometry=fd.paper_geometry("b"), x0=(5e3, 2e3, 10, -100), process_noise=fd.ConstantVelocity(q=0.5)
    )
    a = fd.simulate(scen, np.random.default_rng(3))
    b = fd.simulate(scen, np.random.default_rng(3))
    np.testing.assert_array_equal(a.measurements.doppler, b.measurements.doppler)
    np.testing.assert_array_equal(a.truth.states, b.truth.states)
    assert np.std(np.diff(a.truth.states[:, 2])) > 0  # the velocity wanders


def test_scenario_validation() -> None:
    g = fd.paper_geometry("a")
    with pytest.raises(ValueError, match="x0"):
        fd.Scenario(geometry=g, x0=(1.0, 2.0, 3.0))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="dt"):
        fd.Scenario(geometry=g, x0=(1, 2, 3, 4), dt=0)
    with pytest.raises(ValueError, match="time_offsets"):
        fd.Scenario(geometry=g, x0=(1, 2, 3, 4), time_offsets=(0.0,))
    with pytest.raises(ValueError, match="sigma"):
        fd.Scenario(geometry=g, x0=(1, 2, 3, 4), sigma=0.0)


def test_truth_round_trip(tmp_path) -> None:
    sim = fd.simulate(fd.paper_scenario("b", 25e3), np.random.default_rng(1))
    sim.truth.to_csv(tmp_path / "t.csv")
    back = fd.Trajectory.from_csv(tmp_path / "t.csv")
    np.testing.assert_array_equal(back.states, sim.truth.states)
    # the columns by name, in another tool's order
    lines = [row.split(",") for row in (tmp_path / "t.csv").read_text().splitlines()]
    order = [2, 4, 0, 3, 1]  # y, vy, time, vx, x
    (tmp_path / "o.csv").write_text("\n".join(",".join(row[i] for i in order) for row in lines) + "\n")
    other = fd.Trajectory.from_csv(tmp_path / "o.csv")
    np.testing.assert_array_equal(other.times, sim.truth.times)
    np.testing.assert_array_equal(other.states, sim.truth.states)


# 0.03 deg/s: theta = w tau crosses 1e-2, where the Taylor series hand over to the closed forms
@pytest.mark.parametrize(("turn", "accel"), [(3.0, 0.5), (-1.5, -2.0), (0.0, 1.0), (2.0, 0.0), (0.03, 0.3)])
def test_a_manoeuvre_turns_and_accelerates_as_defined(turn: float, accel: float) -> None:
    # the closed form against its definition: constant velocity up to the onset; then speed v0 + a tau, heading
    # h0 + w tau (clockwise from +y), and a position whose derivative is the velocity (Simpson's rule of the
    # velocity over each step integrates it to round-off for this smooth motion)
    x0 = np.array([1e3, 2e3, 10.0, -100.0])
    man = fd.Manoeuvre(onset=5.0, turn_rate_deg=turn, acceleration=accel)
    t = np.linspace(0.0, 30.0, 601)
    x = man.states(x0, t)
    before = t <= 5.0
    np.testing.assert_allclose(x[before, :2], x0[:2] + t[before, None] * x0[2:], rtol=0, atol=1e-9)
    tau = np.maximum(t - 5.0, 0.0)
    speed = np.hypot(x[:, 2], x[:, 3])
    np.testing.assert_allclose(speed, np.hypot(10.0, 100.0) + accel * tau, rtol=1e-12)
    heading = np.unwrap(np.arctan2(x[:, 2], x[:, 3]))
    np.testing.assert_allclose(np.degrees(heading - heading[0]), turn * tau, atol=1e-9)
    mid = man.states(x0, (t[:-1] + t[1:]) / 2)
    step = (t[1] - t[0]) / 6 * (x[:-1, 2:] + 4 * mid[:, 2:] + x[1:, 2:])
    after = t[:-1] >= 5.0  # steps that do not straddle the onset (the acceleration jumps there)
    np.testing.assert_allclose(np.diff(x[:, :2], axis=0)[after], step[after], rtol=0, atol=1e-6)


def test_a_manoeuvre_is_continuous_in_its_turn_rate_and_keeps_the_climb_in_3d() -> None:
    # the straight-line branch (turn rate 0) is the limit of the closed form: turning 1e-6 deg/s for 25 s at
    # ~100 m/s moves the target by v w tau^2 / 2 ~ 1e-3 m
    x0 = (0.0, 0.0, 30.0, 95.0)
    t = np.linspace(0.0, 30.0, 61)
    straight = fd.Manoeuvre(onset=5.0, acceleration=0.7).states(x0, t)
    barely = fd.Manoeuvre(onset=5.0, turn_rate_deg=1e-6, acceleration=0.7).states(x0, t)
    np.testing.assert_allclose(barely, straight, rtol=0, atol=2e-3)
    x3 = fd.Manoeuvre(onset=2.0, turn_rate_deg=4.0).states((0.0, 0.0, 3e3, 30.0, 95.0, -5.0), t)
    np.testing.assert_allclose(x3[:, 2], 3e3 - 5.0 * t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(x3[:, 5], -5.0)
    np.testing.assert_allclose(np.hypot(x3[:, 3], x3[:, 4]), np.hypot(30.0, 95.0), rtol=1e-12)


def test_a_manoeuvring_scenario_simulates_its_manoeuvre_and_refuses_what_it_cannot_be() -> None:
    g = fd.paper_geometry("a")
    man = fd.Manoeuvre(onset=10.0, turn_rate_deg=2.0, acceleration=-1.0)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(25e3, 2e3, 10.0, -100.0), manoeuvre=man), np.random.default_rng(0))
    np.testing.assert_array_equal(sim.truth.states, man.states((25e3, 2e3, 10.0, -100.0), sim.truth.times))
    m = sim.measurements
    clean = fd.bistatic_doppler(sim.truth.at(m.time), g)[np.arange(len(m)), m.pair]
    assert np.sqrt(np.mean((m.doppler - clean) ** 2)) < 1.5  # sigma 1 about the manoeuvring truth
    with pytest.raises(ValueError, match="stops the target"):
        fd.Scenario(geometry=g, x0=(25e3, 2e3, 10.0, -100.0), manoeuvre=fd.Manoeuvre(acceleration=-4.0))
    with pytest.raises(ValueError, match="not both"):
        fd.Scenario(geometry=g, x0=(25e3, 2e3, 10.0, -100.0), manoeuvre=man, process_noise=fd.ConstantVelocity(q=1.0))
    with pytest.raises(ValueError, match="onset"):
        fd.Manoeuvre(onset=-1.0)
    with pytest.raises(ValueError, match="finite"):
        fd.Manoeuvre(turn_rate_deg=float("nan"))
    with pytest.raises(ValueError, match="stopped target"):
        fd.Manoeuvre(turn_rate_deg=1.0).states((0.0, 0.0, 0.0, 0.0), [0.0, 1.0])
