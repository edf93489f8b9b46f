"""The curvature probe: silent on quadratic costs, loud on curved or flat ones, and where it matters."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd
from fgdoppler.estimators.curvature import (
    CURVATURE_LIMIT,
    curvature_check,
    curvature_reason,
    probe_rises,
)
from fgdoppler.estimators.registry import hypotheses_of
from tests.conftest import benchmark_run

RNG = np.random.default_rng(5)
_B = RNG.normal(size=(4, 4))
INFO = _B @ _B.T + 4 * np.eye(4)  # a generic, correlated information matrix
MEAN = np.array([3e4, 2e3, 10.0, -100.0])


def _quadratic(x: np.ndarray) -> float:
    e = x - MEAN
    return float(e @ INFO @ e)


def test_a_quadratic_cost_rises_exactly_as_its_model_predicts() -> None:
    P = np.linalg.inv(INFO)
    lo, hi, quad, sd = probe_rises(_quadratic, MEAN, P, INFO)
    assert quad == pytest.approx(9.0, rel=1e-12)  # delta' I delta = 1 for delta built from P = I^-1
    assert lo == pytest.approx(9.0, rel=1e-9) and hi == pytest.approx(9.0, rel=1e-9)
    assert sd == pytest.approx(np.sqrt(np.linalg.eigvalsh(P[:2, :2]).max()), rel=1e-12)
    assert curvature_reason(_quadratic, MEAN, P, INFO) is None
    # a reported covariance twice the true one: the probe goes sqrt(2) further and predicts 18
    lo, hi, quad, _ = probe_rises(_quadratic, MEAN, 2 * P, INFO)
    assert quad == pytest.approx(18.0, rel=1e-12) and lo == pytest.approx(18.0, rel=1e-9)
    assert curvature_reason(_quadratic, MEAN, 2 * P, INFO) is None
    # away from the optimum (a grid node) the linear term is taken out: the rises are curvature only
    off = MEAN + np.array([300.0, -200.0, 1.0, 2.0])
    lo, hi, quad, _ = probe_rises(_quadratic, off, P, INFO)
    assert lo == pytest.approx(9.0, rel=1e-6) and hi == pytest.approx(9.0, rel=1e-6)


def test_a_curved_valley_and_a_flat_bottom_are_reported() -> None:
    # A banana: along the position's major axis the valley bends away (x1 = c x0^2).
    c = 5.0

    def banana(x: np.ndarray) -> float:
        return float(1e4 * (x[1] - c * x[0] ** 2) ** 2 + x[0] ** 2 + x[2] ** 2 + x[3] ** 2)

    x = np.zeros(4)
    info = np.diag([1.0, 1e4, 1.0, 1.0])  # its Gauss-Newton model at the minimum
    found = curvature_reason(banana, x, np.linalg.inv(info), info)
    assert found is not None and found.status == "doubtful" and "curved" in found.message
    # A quartic bottom: the covariance of a nearly flat quadratic model is too small.

    def flat(x: np.ndarray) -> float:
        return float(np.sum(x**2) * 1e-3 + np.sum(x**2) ** 2)

    info = np.eye(4) * 100.0  # claims sigma 0.1; the cost at 3 sigma is 0.0082, not 9
    found = curvature_reason(flat, np.zeros(4), np.linalg.inv(info), info)
    assert found is not None and found.status == "doubtful" and "flatter" in found.message
    assert CURVATURE_LIMIT > 1


def _windows(case: str, x: float, n: int) -> list[tuple[fd.Initiation, float]]:
    sc = fd.paper_scenario(case, x)
    out = []
    for seq in np.random.SeedSequence(99).spawn(n):
        sim = fd.simulate(sc, np.random.default_rng(seq))
        init = fd.initiate(sim.measurements.first_per_pair(10), sc.geometry)
        assert init.P_start is not None
        e = init.x_start - sim.truth.states[0]
        out.append((init, float(e @ np.linalg.solve(init.P_start, e))))
    return out


@pytest.mark.parametrize(("case", "x"), [("a", 5e3), ("a", 45e3), ("b", 45e3)])
def test_an_initiation_with_an_untrustworthy_covariance_is_not_ok(case: str, x: float) -> None:
    # In the poorly observed scenarios the window's covariance is far too small (NEES in the
    # hundreds); the probe must flag those windows, and among the windows left ok the NEES must be
    # about as consistent as in a well-observed scenario.
    thr = chi2.ppf(0.999, 4)
    runs = _windows(case, x, 30)
    ok = [nees for init, nees in runs if init.status == "ok"]
    assert sum(n > thr for n in ok) <= 0.05 * max(len(ok), 1) + 1
    flagged = [init for init, _ in runs if any(r.code == "nonlinear" for r in init.reasons)]
    if x == 45e3 and case == "a":  # well observed: no false alarms
        assert not flagged
    else:  # the check has something to catch here, and catches all of it
        assert sum(n > thr for _, n in runs) >= 0.3 * len(runs)
        assert len(flagged) == len(runs)


def test_the_finding_stays_doubtful_only_for_a_filter_that_carries_the_covariance_on() -> None:
    sc = fd.paper_scenario("a", 5e3)
    sim = fd.simulate(sc, np.random.default_rng(3))
    init = fd.initiate(sim.measurements.first_per_pair(10), sc.geometry)
    assert any(r.code == "nonlinear" and r.status == "doubtful" for r in init.reasons)

    def inherited(name: str, settings: fd.TrackerSettings | None = None) -> list[str]:
        r = fd.run_estimator(name, sim.measurements, sc.geometry, init, settings, verify=False)
        return [x.status for x in r.reasons if x.code == "initiation-nonlinear"]

    assert inherited("smoother") == ["ok"]  # re-solves from all the data
    assert inherited("ekf") == ["ok"]  # started from the Gaussian sum of the window's posterior
    assert inherited("ekf", fd.EKFSettings(components=1)) == ["doubtful"]  # carries the covariance on


def test_the_ratio_is_the_probes_and_the_finding_is_read_from_it() -> None:
    """``curvature_check``: 1 on a quadratic cost (exactly its model); the rise over 9 on a banana; the finding
    exactly where the ratio leaves [1/L, L]."""
    P = np.linalg.inv(INFO)
    ratio, found = curvature_check(_quadratic, MEAN, P, INFO)
    assert ratio == pytest.approx(1.0, rel=1e-9) and found is None
    # the reported covariance twice the true one: the cost rises by 18 where the model of 2P predicts 9 * 2
    assert curvature_check(_quadratic, MEAN, 2 * P, INFO)[0] == pytest.approx(1.0, rel=1e-9)
    # the cost steeper than its model by a factor k: the ratio is k, a finding beyond the limit only
    for k in (2.0, 0.5 * CURVATURE_LIMIT, 2.0 * CURVATURE_LIMIT, 1.0 / (2.0 * CURVATURE_LIMIT)):
        ratio, found = curvature_check(lambda x, k=k: k * _quadratic(x), MEAN, P, INFO)
        assert ratio == pytest.approx(k, rel=1e-9)
        assert (found is not None) == (not 1.0 / CURVATURE_LIMIT <= k <= CURVATURE_LIMIT)
        assert found == curvature_reason(lambda x, k=k: k * _quadratic(x), MEAN, P, INFO)
        # away from an optimum only the curved side is read: a flat ratio is returned as 1, with no finding
        away, found = curvature_check(lambda x, k=k: k * _quadratic(x), MEAN, P, INFO, at_optimum=False)
        assert away == pytest.approx(max(k, 1.0), rel=1e-9)
        assert (found is not None) == (k > CURVATURE_LIMIT)


def test_split_ratio_is_checked_and_splits_beyond_it_on_either_side() -> None:
    s = fd.EKFSettings(split_ratio=3.0)
    assert [s.splits(c) for c in (None, 1.0, 3.0, 1 / 3, 3.01, 0.33, 40.0)] == [
        False, False, False, False, True, True, True]
    assert not any(fd.ISAM2Settings(split_ratio=float("inf")).splits(c) for c in (1e-9, 1.0, 1e9))
    assert fd.FixedLagSettings(split_ratio=1.0).splits(1.0001)
    for bad in (0.5, float("nan"), True, "2"):
        with pytest.raises(ValueError, match="split_ratio"):
            fd.EKFSettings(split_ratio=bad)  # type: ignore[arg-type]


def test_the_initiation_records_its_probe_and_the_trackers_split_by_it() -> None:
    """Case a 25 km, seed 2026: run 78's window has no ``nonlinear`` finding but a probe ratio beyond 2.5, so the
    Gaussian trackers start from its posterior's terms; ``split_ratio=inf`` keeps the initiation's Gaussian.
    Case a 45 km run 0 (well observed): a ratio near 1, one Gaussian either way."""
    sim, model, init = benchmark_run(1, 78)
    assert not any(r.code == "nonlinear" for r in init.reasons)
    assert init.curvature is not None and 2.5 < init.curvature < CURVATURE_LIMIT
    for name in ("ekf", "isam2", "fixed-lag"):
        split, w = hypotheses_of(name, sim.measurements, model, init, fd.ESTIMATORS[name].settings())
        assert w is not None and 1 < len(split) <= 8 and all(h.window_summarised for h in split)
        alone, _ = hypotheses_of(name, sim.measurements, model, init,
                                 fd.ESTIMATORS[name].settings(split_ratio=float("inf")))
        assert len(alone) == 1 and alone[0] is init
    sim, model, init = benchmark_run(2, 0)
    assert init.curvature is not None and 1.0 < init.curvature < 2.0
    assert len(hypotheses_of("ekf", sim.measurements, model, init, fd.EKFSettings())[0]) == 1


def test_the_split_start_tracks_the_25_km_scenarios_closer() -> None:
    """The EKF on the runs among 0-19 of case a and b 25 km (seed 2026) whose start only the probe's ratio splits:
    split, it is closer to the truth over t >= 5 s, in total and in most runs (measured: 20 such runs, RMSE 1,562
    against 2,096 m, 16 of 20 closer; studies/start_split.py on 60 runs: -343 m and -365 m, 95 % intervals
    below -120 m)."""
    from benchmarks.bench_accuracy import _on_grid, mean_after

    split_se, alone_se = [], []
    for s in (1, 4):
        for r in range(20):
            sim, model, init = benchmark_run(s, r)
            if any(x.code == "nonlinear" for x in init.reasons) or not fd.EKFSettings().splits(init.curvature):
                continue
            for out, ratio in ((split_se, 2.5), (alone_se, float("inf"))):
                settings = fd.EKFSettings(split_ratio=ratio, sampled_covariance=False)
                e = fd.run_estimator("ekf", sim.measurements, model, init, settings, verify=False).primary
                se, _ = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
                out.append(mean_after(se, sim.truth.times, 5.0))
    split, alone = np.array(split_se), np.array(alone_se)
    assert split.size >= 10
    assert np.sqrt(split.mean()) < 0.9 * np.sqrt(alone.mean())
    assert np.sum(split < alone) > 0.6 * split.size
