"""Sensor errors drawn afresh for every run of a Monte Carlo study (``ErrorDraws``, ``montecarlo --draw-*``)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.analysis.montecarlo import MonteCarloResult, MonteCarloSpec, run_monte_carlo
from fgdoppler.cli import main


def _spec(draws: fd.ErrorDraws | None, runs: int = 400, **scenario: object) -> MonteCarloSpec:
    scen = replace(fd.paper_scenario("a", 45e3), **scenario)  # type: ignore[arg-type]
    return MonteCarloSpec(scenarios=(scen, fd.paper_scenario("b", 5e3)), runs=runs, seed=7, error_draws=draws)


def test_each_run_draws_its_own_errors_about_the_scenarios_with_the_declared_spread() -> None:
    # 400 runs' draws of a scenario with fixed offsets (0.3, -0.2) m/s and one site 5 m off: the drawn parts have
    # mean zero and the standard deviations asked for, per pair, per site and coordinate (chi-square bounds on the
    # sample variance at 0.999, fixed seed); a part drawn with sigma 0 keeps the scenario's own exactly
    sigma_b, sigma_s = (0.5, 0.1), (30.0, 0.0, 10.0)
    spec = _spec(fd.ErrorDraws(bias_sigma=sigma_b, site_sigma=sigma_s), bias=(0.3, -0.2),
                 site_error=(0.0, 0.0, 0.0, 5.0, 0.0, 0.0))
    own = spec.scenarios[0]
    runs = [spec.scenario_of_run(0, r) for r in range(spec.runs)]
    beta = np.array([s.biases for s in runs]) - own.biases
    eps = np.array([s.site_errors for s in runs]) - own.site_errors  # (runs, sites, 2)
    n = spec.runs
    lo, hi = chi2.ppf([0.0005, 0.9995], n) / n
    for drawn, sigma in ((beta, np.array(sigma_b)), (eps[:, [0, 2]], np.array(sigma_s)[[0, 2], None])):
        var = np.mean(drawn**2, axis=0) / sigma**2
        assert np.all((lo < var) & (var < hi)), var
        assert np.all(np.abs(drawn.mean(axis=0)) < 3.3 * sigma / np.sqrt(n))
    np.testing.assert_array_equal(eps[:, 1], 0.0)  # the receiver's sigma is 0: it stays 5 m off, as declared
    assert all(s.geometry == own.geometry for s in runs)  # the declared geometry; the draws move the true one
    # reproducible, and each run its own
    again = spec.scenario_of_run(0, 17)
    assert again == runs[17] and runs[17] != runs[18]
    assert spec.scenario_of_run(1, 17) != runs[17]
    with pytest.raises(IndexError):
        spec.scenario_of_run(0, spec.runs)


def test_in_3d_every_site_moves_in_height_too() -> None:
    # four ground sites under an aircraft (tests/test_three_d.py's): each run moves every site in x, y and z
    from tests.test_three_d import AIRCRAFT

    spec = MonteCarloSpec(scenarios=(AIRCRAFT,), runs=200, seed=1, error_draws=fd.ErrorDraws(site_sigma=20.0))
    eps = np.array([spec.scenario_of_run(0, r).site_errors for r in range(spec.runs)])
    assert eps.shape == (200, 4, 3)
    var = np.mean(eps**2, axis=0) / 20.0**2
    lo, hi = chi2.ppf([0.0005, 0.9995], spec.runs) / spec.runs
    assert np.all((lo < var) & (var < hi)), var


def test_the_draws_leave_the_runs_noise_as_it_was() -> None:
    # run r's noise comes from its stream and the draws from that stream's first child: with drawn offsets the
    # recording is the one without, shifted by each pair's draw (to rounding), the truth the same
    with_draws, without = _spec(fd.ErrorDraws(bias_sigma=2.0), runs=3), _spec(None, runs=3)
    streams = np.random.SeedSequence(with_draws.seed).spawn(2 * with_draws.runs)
    for s, r in ((0, 0), (1, 2)):
        drawn = with_draws.scenario_of_run(s, r)
        assert without.scenario_of_run(s, r) is without.scenarios[s]
        seq = streams[s * with_draws.runs + r]
        a = fd.simulate(drawn, np.random.default_rng(seq))
        b = fd.simulate(without.scenarios[s], np.random.default_rng(seq))
        np.testing.assert_array_equal(a.truth.states, b.truth.states)
        m = a.measurements
        np.testing.assert_allclose(m.doppler - b.measurements.doppler, drawn.biases[m.pair], rtol=0, atol=1e-12)
        assert np.all(drawn.biases != 0.0)


def test_a_study_with_draws_is_the_same_on_any_number_of_workers_and_not_the_one_without(tmp_path: Path) -> None:
    scen = replace(fd.paper_scenario("a", 45e3), duration=12.0)
    draws = fd.ErrorDraws(site_sigma=(200.0, 0.0, 100.0), bias_sigma=0.1)
    spec = MonteCarloSpec(scenarios=(scen,), estimators=("ekf",), runs=2, seed=3, error_draws=draws, verify=False)
    one = run_monte_carlo(spec, workers=1, progress=False)
    two = run_monte_carlo(spec, workers=2, progress=False)
    plain = run_monte_carlo(replace(spec, error_draws=None), workers=1, progress=False)
    np.testing.assert_array_equal(one.pos_se[0]["ekf"], two.pos_se[0]["ekf"])
    np.testing.assert_array_equal(one.nees[0]["ekf"], two.nees[0]["ekf"])
    assert not np.allclose(one.pos_se[0]["ekf"], plain.pos_se[0]["ekf"], equal_nan=True)
    # the result says what was drawn, in its summary and in the files it writes
    assert one.error_draws == draws and plain.error_draws is None and "error_draws" not in plain.summary()
    assert one.summary()["error_draws"] == {"bias_sigma": 0.1, "site_sigma": [200.0, 0.0, 100.0]}
    one.save(tmp_path / "mc")
    assert MonteCarloResult.load(tmp_path / "mc").error_draws == draws


@pytest.mark.parametrize(("draws", "said"), [
    ({"bias_sigma": -0.1}, "bias_sigma must be one value >= 0 (m/s) or one per pair"),
    ({"site_sigma": float("nan")}, "site_sigma must be one value >= 0 (m) or one per site"),
    ({"site_sigma": ()}, "site_sigma must be"),
])
def test_bad_standard_deviations_are_refused(draws: dict[str, object], said: str) -> None:
    with pytest.raises(ValueError, match=said.replace("(", r"\(").replace(")", r"\)")):
        fd.ErrorDraws(**draws)  # type: ignore[arg-type]


def test_counts_are_checked_against_every_scenario_of_the_study() -> None:
    with pytest.raises(ValueError, match=r"error_draws in case a, start 45 km: site_sigma .* one per site \(3"):
        _spec(fd.ErrorDraws(site_sigma=(1.0, 2.0)))
    with pytest.raises(ValueError, match=r"bias_sigma .* one per pair \(2\)"):
        _spec(fd.ErrorDraws(bias_sigma=(1.0, 2.0, 3.0)))


def test_montecarlo_draws_on_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["montecarlo", "--case", "a", "--start-x", "45000", "--duration", "12", "--runs", "2",
            "--estimators", "ekf", "--workers", "1", "--out", str(tmp_path / "mc")]
    assert main([*base, "--draw-bias", "0.5", "--draw-site-error", "30", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["error_draws"] == {"bias_sigma": 0.5, "site_sigma": 30.0}
    assert main([*base, "--draw-site-error", "30"]) == 0
    assert "sites N(0, sigma^2) in every coordinate with sigma 30.0 m" in capsys.readouterr().out
    for bad, said in ((["--draw-bias", "-1"], "--draw-bias: it must be one value >= 0 (m/s)"),
                      (["--draw-site-error", "1", "2"], "--draw-site-error in case a, start 45 km: it must be"),
                      (["--draw-bias", "1", "2", "3"], "--draw-bias in case a, start 45 km: it must be")):
        assert main([*base, *bad]) == 2
        assert said in capsys.readouterr().err
