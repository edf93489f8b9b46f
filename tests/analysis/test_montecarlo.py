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
