"""Metrics against hand computations; bounds against a Kalman filter and the observability report."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.analysis.bounds import crlb_deterministic, pcrlb_filter
from fgdoppler.analysis.metrics import (
    compare_rmse,
    errors,
    nees,
    nees_band,
    rmse,
    time_averaged_rmse,
)
from fgdoppler.analysis.observability import observability_report
from tests.estimators.test_trackers import PositionModel, _kalman


def test_rmse_and_nees_by_hand() -> None:
    est = np.array([[[3.0, 4.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0]],
                    [[0.0, 0.0, 0.0, 2.0], [np.nan, np.nan, np.nan, np.nan]]])  # (runs=2, times=2, 4)
    truth = np.zeros((2, 2, 4))
    pe, ve = errors(est, truth)
    np.testing.assert_array_equal(pe[0], [25.0, 0.0])
    np.testing.assert_array_equal(ve[1, :1], [4.0])
    r = rmse(pe)
    # time 0: sqrt((25 + 0) / 2); time 1: one finite run (0) -> 0
    np.testing.assert_allclose(r, [np.sqrt(12.5), 0.0])
    assert np.isnan(rmse(np.full((3, 1), np.nan))[0])
    P = np.diag([4.0, 1.0, 1.0, 0.25])
    # e = (3, 4, 1, 0): 9/4 + 16/1 + 1/1 + 0 = 19.25
    assert nees(est[0, 0], P, truth[0, 0]) == pytest.approx(19.25)


def test_time_averaged_rmse_by_hand_and_with_counts() -> None:
    se = np.array([[4.0, 9.0, np.nan], [16.0, np.nan, 1.0]])
    t = np.array([0.0, 1.0, 2.0])
    # t >= 1: time 1 has run 0 only (3), time 2 run 1 only (1) -> (3 + 1) / 2
    assert time_averaged_rmse(se, t, t0=1.0) == pytest.approx(2.0)
    # all times: sqrt(10), 3, 1
    assert time_averaged_rmse(se, t) == pytest.approx((np.sqrt(10.0) + 3.0 + 1.0) / 3)
    # counts are run multiplicities: run 1 twice equals stacking it twice
    stacked = np.vstack([se, se[1:]])
    np.testing.assert_allclose(time_averaged_rmse(se, t, counts=[[1, 2], [1, 1]]),
                               [time_averaged_rmse(stacked, t), time_averaged_rmse(se, t)])
    with pytest.raises(ValueError, match="counts"):
        time_averaged_rmse(se, t, counts=[[1, 1, 1]])
    with pytest.raises(ValueError, match="times"):
        time_averaged_rmse(se, t[:2])


def test_paired_bootstrap_resolves_a_small_common_shift_and_not_noise() -> None:
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 10.0, 21)
    # heavy run-to-run spread (some runs 100x worse) shared by both estimators
    scale = np.exp(rng.normal(0.0, 1.5, 40))[:, None]
    base = scale * rng.chisquare(2, (40, t.size))
    same = compare_rmse(base, base, t)
    assert same.difference == 0.0 and same.low == 0.0 and same.high == 0.0 and not same.resolved
    # B errs 1 % more in every run and time: RMSE_A - RMSE_B = -0.01 RMSE_A exactly
    worse = compare_rmse(base, 1.01**2 * base, t)
    assert worse.difference == pytest.approx(-0.01 * time_averaged_rmse(base, t))
    assert worse.resolved and worse.high < 0
    # while the spread of either RMSE alone is far larger than that difference
    counts = rng.multinomial(40, np.full(40, 1 / 40), size=500)
    assert np.std(time_averaged_rmse(base, t, counts=counts)) > 10 * abs(worse.difference)
    with pytest.raises(ValueError, match="same runs"):
        compare_rmse(base, base[:-1], t)


def test_paired_bootstrap_interval_covers_zero_when_estimators_are_exchangeable() -> None:
    # A and B are independent draws of the same error law: the 95 % interval should hold 0 in about 95 %
    # of repetitions; 200 repetitions, binomial 99.9 % lower limit 0.95 - 3.1 sqrt(0.95 * 0.05 / 200) = 0.90
    rng = np.random.default_rng(11)
    t = np.arange(5.0)
    covered = 0
    for k in range(200):
        a, b = rng.chisquare(2, (2, 30, t.size))
        covered += not compare_rmse(a, b, t, resamples=400, seed=k).resolved
    assert covered / 200 >= 0.90


def test_nees_band_has_its_coverage() -> None:
    rng = np.random.default_rng(11)
    runs, trials = 40, 4000
    lo, hi = nees_band(runs)
    means = rng.chisquare(4, size=(trials, runs)).mean(axis=1)
    cover = np.mean((means >= lo) & (means <= hi))
    # binomial standard error of 0.95 over 4000 trials is 0.0034: allow 4 of them
    assert abs(cover - 0.95) < 4 * np.sqrt(0.95 * 0.05 / trials)


def test_pcrlb_equals_kalman_covariance_for_linear_gaussian() -> None:
    rng = np.random.default_rng(2)
    motion = fd.ConstantVelocity(q=0.3)
    x0 = np.array([10.0, 20.0, 1.0, -2.0])
    P0 = np.diag([9.0, 16.0, 1.0, 1.0])
    times = np.arange(1, 31) * 0.7
    t_all = np.repeat(times, 2)
    ch = np.tile([0, 1], times.size)
    truth = fd.Trajectory(times=np.concatenate([[0.0], times]),
                          states=np.vstack([x0, x0 + np.outer(times, [1.0, -2.0, 0, 0])]))
    meas = fd.Measurements.from_arrays(t_all, ch, rng.normal(0, 1, t_all.size), 1.5)
    t_b, bound = pcrlb_filter(PositionModel(), truth, meas, motion, np.linalg.inv(P0), 0.0)
    scans = [(t, [0, 1], np.zeros(2), [1.5, 1.5]) for t in times]
    ref = _kalman(x0, P0, 0.0, scans, motion)
    np.testing.assert_array_equal(t_b, times)
    for B, (_, P) in zip(bound, ref, strict=True):
        np.testing.assert_allclose(B, P, rtol=1e-9, atol=1e-12)


def test_deterministic_crlb_matches_report_and_shrinks_with_data() -> None:
    scen = fd.paper_scenario("b", 5e3)
    sim = fd.simulate(scen, np.random.default_rng(0))
    t = sim.truth.times
    smooth = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, t, smoothing=True)
    filt = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, t)
    rep = observability_report(scen.geometry, sim.truth, sim.measurements)
    assert rep.covariances is not None
    np.testing.assert_allclose(smooth, rep.covariances, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(filt[-1], smooth[-1], rtol=1e-9)
    # before four measurements the information is singular: reported as NaN, not garbage
    assert np.all(np.isnan(filt[0]))
    # filtering bound (data up to t) is never below the smoothing bound (all data)
    ok = np.all(np.isfinite(filt), axis=(1, 2))
    tr_f = np.trace(filt[ok][:, :2, :2], axis1=1, axis2=2)
    tr_s = np.trace(smooth[ok][:, :2, :2], axis1=1, axis2=2)
    assert np.all(tr_f >= tr_s * (1 - 1e-9))
