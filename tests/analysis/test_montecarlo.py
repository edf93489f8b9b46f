"""Monte Carlo harness: worker-count invariance, Dask, save/load."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.analysis.montecarlo import MonteCarloResult, MonteCarloSpec, run_monte_carlo

SPEC = MonteCarloSpec(scenarios=(fd.paper_scenario("a", 45e3), fd.paper_scenario("b", 5e3)), runs=2,
                      estimators=("grid", "lm", "ekf", "smoother"), seed=99)


def _same(a: MonteCarloResult, b: MonteCarloResult) -> bool:
    return all(
        np.array_equal(getattr(a, f)[s][e], getattr(b, f)[s][e], equal_nan=True)
        for f in ("pos_se", "vel_se", "nees") for s in range(len(a.scenario_names)) for e in a.estimators
    )


@pytest.fixture(scope="module")
def serial() -> MonteCarloResult:
    """SPEC in one process: what every other way of running it must give."""
    return run_monte_carlo(SPEC, workers=1, progress=False)


def test_same_seed_same_results_with_1_and_2_workers(serial: MonteCarloResult, tmp_path) -> None:
    one = serial
    two = run_monte_carlo(SPEC, workers=2, progress=False)
    assert _same(one, two)
    # different seeds differ
    other = run_monte_carlo(MonteCarloSpec(scenarios=SPEC.scenarios[:1], runs=2, estimators=("ekf",), seed=1),
                            progress=False)
    assert not np.array_equal(other.pos_se[0]["ekf"], one.pos_se[0]["ekf"][:2], equal_nan=True)
    # save / load round trip without re-running
    one.save(tmp_path / "mc")
    back = MonteCarloResult.load(tmp_path / "mc")
    assert _same(one, back) and back.estimators == one.estimators
    assert back.summary()["rows"][0]["scenario"] == one.scenario_names[0]


def test_summary_nees_is_the_run_average_after_10_s_and_the_command_prints_it_against_its_band(
        serial: MonteCarloResult, capsys: pytest.CaptureFixture[str]) -> None:
    """The summary's NEES of each row, recomputed from the stored per-run arrays (mean over the runs that have a
    value at each time, then over t >= 10 s), its band the chi-square quantiles of 4 x runs degrees of freedom over
    runs, and the verdict counts summing to the runs; the command's tables print those numbers."""
    from scipy.stats import chi2

    from fgdoppler.cli.montecarlo import _print_summary

    summ = serial.summary()
    lo, hi = summ["nees_band"]
    assert (lo, hi) == pytest.approx((chi2.ppf(0.025, 4 * SPEC.runs) / SPEC.runs, chi2.ppf(0.975, 4 * SPEC.runs) / SPEC.runs))
    assert summ["nees_from"] == 10.0
    for s, name in enumerate(serial.scenario_names):
        t = serial.times[s]
        for e in serial.estimators:
            (row,) = [r for r in summ["rows"] if r["scenario"] == name and r["estimator"] == e]
            x = serial.nees[s][e][:, t >= 10.0]
            expect = np.mean([np.mean(col[np.isfinite(col)]) for col in x.T if np.any(np.isfinite(col))])
            assert row["nees_mean"] == pytest.approx(expect, rel=1e-12)
            assert sum(row["verdicts"].values()) == SPEC.runs
    _print_summary(summ)
    out = capsys.readouterr().out
    assert f"95 % band for {SPEC.runs} runs: {lo:.2f}-{hi:.2f}" in out
    smoother = next(r for r in summ["rows"] if r["estimator"] == "smoother")
    mark = "*" if smoother["nees_mean"] > hi else "~" if smoother["nees_mean"] < lo else ""
    assert f"{smoother['nees_mean']:.3g}{mark}" in out and "verdicts ok/doubtful/failed" in out


def test_initiation_estimators_have_values_before_the_trackers() -> None:
    res = run_monte_carlo(MonteCarloSpec(scenarios=SPEC.scenarios[:1], runs=1, estimators=("lm", "ekf")),
                          progress=False)
    t = res.times[0]
    lm, ekf = res.pos_se[0]["lm"][0], res.pos_se[0]["ekf"][0]
    assert np.all(np.isfinite(lm))  # the CV extrapolation covers every time
    assert np.all(np.isnan(ekf[t < 4.5])) and np.all(np.isfinite(ekf[t >= 4.5]))


def test_dask_local_cluster_gives_identical_results(serial: MonteCarloResult) -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
            distributed.Client(cl) as client:
        res = run_monte_carlo(SPEC, executor=client.get_executor(), progress=False)
    assert _same(res, serial)


def test_spec_validation() -> None:
    with pytest.raises(ValueError, match="unknown estimator"):
        MonteCarloSpec(scenarios=SPEC.scenarios, estimators=("ukf",))
    with pytest.raises(ValueError, match="runs"):
        MonteCarloSpec(scenarios=SPEC.scenarios, runs=0)
