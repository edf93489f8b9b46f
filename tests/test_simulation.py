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
