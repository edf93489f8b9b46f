"""Sampled covariances where the likelihood is not Gaussian: the smoother's, the filters' and the fixed-lag smoother's (fgdoppler.estimators.spread)."""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd
import fgdoppler.estimators.registry as registry
import fgdoppler.estimators.spread as spread
from benchmarks._exact import exact_posterior
from benchmarks.bench_widening import pairs
from fgdoppler.estimators.curvature import CURVATURE_LIMIT, probe_axis
from fgdoppler.estimators.linearized_posterior import linearized_filter, mean_square_errors
from fgdoppler.estimators.spread import (
    DETERMINISTIC_MIN,
    FILTER_NOISE_MAX,
    FILTER_WIDEN_MIN,
    _carried,
    _enclosing,
    _information,
    _noise_share,
    _posterior,
    _whitened_eigenvalues,
    _widened_stack,
    filtered_spread,
    posterior_spread,
)
from fgdoppler.simulation import PAPER_CASE_B_OFFSET
from tests.conftest import benchmark_run


def test_enclosing_is_the_larger_covariance_in_every_direction() -> None:
    """By hand for diagonal matrices (elementwise max), and ⪰ both for random ones."""
    np.testing.assert_allclose(_enclosing(np.diag([4.0, 1.0, 9.0, 1.0]), np.diag([1.0, 3.0, 9.0, 0.5])),
                               np.diag([4.0, 3.0, 9.0, 1.0]), atol=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(20):
        A, B = rng.standard_normal((2, 4, 4))
        P, S = A @ A.T + 0.1 * np.eye(4), B @ B.T + 0.1 * np.eye(4)
        E = _enclosing(P, S)
        assert np.linalg.eigvalsh(E - P).min() > -1e-9 * np.abs(E).max()
        assert np.linalg.eigvalsh(E - S).min() > -1e-9 * np.abs(E).max()


def test_a_stack_is_widened_as_the_generalised_eigenproblem_says_and_a_bad_matrix_is_left() -> None:
    r"""Against scipy's generalised eigenvectors (another factorisation of ``P``), one matrix at a time.

    With :math:`\mathbf S\mathbf u = \lambda\mathbf P\mathbf u`,
    :math:`\mathbf U^\top\mathbf P\mathbf U = \mathbf I`, the widened covariance is
    :math:`(\mathbf P\mathbf U)\,\mathrm{diag}(\lambda'_i)\,(\mathbf P\mathbf U)^\top` with
    :math:`\lambda'_i = \lambda_i` above the threshold and 1 elsewhere, whatever the square root of
    ``P`` the whitening uses.  A ``P`` that is not positive definite, placed among good ones, is left and
    not counted, and the good ones come out as they do alone (the stack is halved around it).
    """
    from scipy.linalg import eigh

    n = 37
    P, S = pairs(n, seed=3)  # S near c P with c on both sides of the threshold
    wide, grew = _widened_stack(P, S, FILTER_WIDEN_MIN)
    assert 0 < np.count_nonzero(grew) < n
    for k in range(n):
        lam, U = eigh(S[k], P[k])
        PU = P[k] @ U
        expected = (PU * np.where(lam > FILTER_WIDEN_MIN, lam, 1.0)) @ PU.T
        assert grew[k] == bool(np.any(lam > FILTER_WIDEN_MIN))
        np.testing.assert_allclose(wide[k], expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())
    bad = P.copy()
    bad[11] = np.diag([1.0, -1.0, 1.0, 1.0])
    wide_bad, grew_bad = _widened_stack(bad, S, FILTER_WIDEN_MIN)
    assert not grew_bad[11] and np.array_equal(wide_bad[11], bad[11])
    keep = np.arange(n) != 11
    assert np.array_equal(grew_bad[keep], grew[keep]) and np.array_equal(wide_bad[keep], wide[keep])


def test_the_sampled_excess_is_carried_on_the_smoothers_marginals() -> None:
    r""":math:`\mathbf P_k = \mathbf P^\mathrm L_k + \mathbf F_k\mathbf E\mathbf F_k^\top`, floored.

    A positive semi-definite excess (:math:`\mathbf E = \mathbf B\mathbf B^\top`) with floor 1: the
    formula exactly, no process noise added, every matrix at least its Laplace one.  An indefinite one
    (:math:`\mathbf E = -\tfrac12\mathbf P^\mathrm L_0 + \mathbf u\mathbf u^\top`) against Laplace
    marginals whose later matrices are narrower than the carried first one, so that the formula alone is
    indefinite there, with floor 0.5: no whitened eigenvalue against :math:`\mathbf P^\mathrm L_k` below
    0.5, and where the formula stays above it, it is returned as it is (the first matrix among them).
    """
    model = fd.TrackingModel.of(fd.paper_geometry("a"))
    rng = np.random.default_rng(5)
    times = np.array([3.0, 3.5, 10.0, 33.0])
    F = model.motion.F(times - times[0])
    A = rng.standard_normal((4, 4))
    P0 = A @ A.T + np.eye(4)
    laplace = F @ P0 @ np.swapaxes(F, -1, -2) + model.motion.Q(times - times[0])  # a filter-like stack
    B = rng.standard_normal((4, 2))
    out = _carried(model, laplace, B @ B.T, times, 1.0)
    np.testing.assert_allclose(out, laplace + F @ (B @ B.T) @ np.swapaxes(F, -1, -2), rtol=1e-12, atol=1e-12)
    for P, L in zip(out, laplace, strict=True):
        assert np.linalg.eigvalsh(P - L).min() > -1e-9 * np.abs(P).max()
    u = rng.standard_normal(4)
    excess = -0.5 * P0 + np.outer(u, u)
    squeezed = laplace.copy()
    squeezed[2:] = 0.3 * laplace[2:]
    out = _carried(model, squeezed, excess, times, 0.5)
    formula = squeezed + F @ excess @ np.swapaxes(F, -1, -2)
    assert min(np.linalg.eigvalsh(formula[k]).min() for k in (2, 3)) < 0  # what the floor is for
    kept = 0
    for k in range(4):
        Li = np.linalg.inv(np.linalg.cholesky(squeezed[k]))
        assert np.linalg.eigvalsh(Li @ out[k] @ Li.T).min() > 0.5 - 1e-9
        if np.linalg.eigvalsh(Li @ formula[k] @ Li.T).min() >= 0.5:
            kept += 1
            np.testing.assert_allclose(out[k], formula[k], rtol=1e-12, atol=1e-12 * np.abs(out[k]).max())
    assert kept >= 1


@pytest.mark.parametrize("seed", [0, 1])
def test_after_a_gap_the_smoothers_sampled_covariance_does_not_call_the_filters_doubtful(seed: int) -> None:
    """Case a 30 km, 90 s, both pairs silent for t = 30-60 s (``studies/gap_reference_check.py``).

    The posterior is skewed and the smoother reports its mean, with covariances from constant-velocity
    samples.  Those samples do not hold the process noise's freedom, which over 90 s is most of the
    Laplace covariance in one direction (the samples' own Gaussian model is 0.15 of it there): the
    samples' matrix reported as the first state's was 0.21-0.23 of the Laplace one in some direction,
    and the last had the whole span's process noise Q(90 s) added unconditioned, 2.1-2.6 times the
    EKF's standard deviation along vy in 19 of 20 recordings, so that every filter was ``doubtful`` by
    the ``reference`` finding (these two seeds included) while the EKF's errors were as its
    covariance said.  Now only the samples' departure from their own Gaussian model is added to the
    Laplace marginals: a modest change where the cost is near-quadratic (probe ratio 1.55-1.61; whitened
    eigenvalues measured 0.94-1.58) and no filter is doubtful.
    """
    scen = fd.Scenario(geometry=fd.paper_geometry("a"), x0=(30e3, 2e3, 10.0, -100.0), duration=90.0, dt=0.5)
    m = fd.simulate(scen, np.random.default_rng(seed)).measurements
    m = m.subset(~((m.time >= 30.0) & (m.time < 60.0)))
    init = fd.initiate(m.initiation_window(10, 4.5), scen.geometry)
    smoother = fd.run_estimator("smoother", m, scen.geometry, init)
    assert any(r.code == "nonlinear" and "posterior mean" in r.message for r in smoother.reasons)
    laplace = fd.run_estimator("smoother", m, scen.geometry, init, fd.SmootherSettings(sampled_covariance=False),
                               verify=False).primary
    for P, L in zip(smoother.primary.covariances, laplace.covariances, strict=True):
        Li = np.linalg.inv(np.linalg.cholesky(L))
        lam = np.linalg.eigvalsh(Li @ P @ Li.T)
        assert 0.8 < lam.min() and lam.max() < 2.0, lam
    for name in ("ekf", "isam2", "fixed-lag"):
        run = fd.run_estimator(name, m, scen.geometry, init, reference=smoother)
        assert run.status == "ok", (name, run.message)


@pytest.mark.parametrize("r", [0, 1, 2])
def test_well_observed_tracks_keep_the_laplace_covariance(r: int) -> None:
    """Case a 45 km: the quadratic model holds (probe ratio 1.1-1.7) and the posterior mean is the estimate.

    Nothing is sampled beyond the importance-sampling check of the mean
    (squared shift 0.006-0.02 in 100 runs, limit 0.05).
    """
    sim, model, init = benchmark_run(2, r)
    e = fd.run_estimator("smoother", sim.measurements, model, init, verify=False).primary
    assert posterior_spread(sim.measurements, model, e.times, e.states, e.covariances) is None


@pytest.mark.parametrize(("s", "r"), [(1, 0), (4, 0)])
def test_a_skewed_valley_reports_the_posterior_mean_and_it_is_the_exact_one(s: int, r: int) -> None:
    """Case a and b 25 km, seed 2026, run 0: the cost is quadratic at 3 sigma, the posterior is not.

    Checked against the benchmark's exact posterior (adaptive importance
    sampling with Student-t proposals, no code shared with the smoother's
    Metropolis sampler), in its whitened coordinates: the maximum a
    posteriori start lies 0.30 (a) and 0.40 (b) standard deviations from
    the exact mean, the reported start 0.03 and 0.04 (limit 0.1, the two
    samplers' Monte Carlo error), and the reported covariance's whitened
    eigenvalues are 0.93-1.04 (limits 0.85-1.15).  The reported track is
    the most likely one shifted by the constant-velocity image of one start
    offset, ``F(t - t0) d``, at every time (exactly: the map is linear).
    """
    sim, model, init = benchmark_run(s, r)
    mean = fd.run_estimator("smoother", sim.measurements, model, init, verify=False)
    mode = fd.run_estimator("smoother", sim.measurements, model, init, fd.SmootherSettings(posterior_mean=False),
                            verify=False)
    a, b = mean.primary, mode.primary
    (found,) = [x for x in mean.reasons if x.code == "nonlinear"]
    assert found.status == "ok" and "posterior mean" in found.message
    assert not any(x.code == "nonlinear" for x in mode.reasons)
    exact = exact_posterior(sim.measurements, model, float(sim.measurements.time[-1]), [b.states[0]],
                            np.random.default_rng(0))
    assert exact.t0 == a.times[0]
    Li = np.linalg.inv(np.linalg.cholesky(exact.covariance))
    assert np.linalg.norm(Li @ (b.states[0] - exact.mean)) > 0.2
    assert np.linalg.norm(Li @ (a.states[0] - exact.mean)) < 0.1
    eig = np.linalg.eigvalsh(Li @ a.covariances[0] @ Li.T)
    assert 0.85 < eig.min() and eig.max() < 1.15
    d = a.states[0] - b.states[0]
    carried = np.array([model.motion.F(t - a.times[0]) @ d for t in a.times])
    np.testing.assert_allclose(a.states - b.states, carried, rtol=0, atol=1e-9 * np.abs(a.states).max())
    np.testing.assert_array_equal(a.times, b.times)


def _four_pairs() -> fd.Geometry:
    """Two transmitters and two receivers, each transmitter seen by both: a user's kind of layout."""
    return fd.Geometry(pairs=tuple(fd.BistaticPair(tx=tx, rx=rx) for tx, rx in (
        ((0.0, 0.0), (12e3, 3e3)), ((0.0, 0.0), (-8e3, 9e3)), ((20e3, -5e3), (12e3, 3e3)),
        ((20e3, -5e3), (-8e3, 9e3)))))


def test_where_the_process_noise_has_a_share_the_track_is_not_moved_by_it() -> None:
    """Four pairs about a well-observed target, 10 Hz for 60 s: the smoother's start differs from the
    constant-velocity samples' mode by what the process noise lets the track do, and the importance-sampled
    mean, scattered by its weights, passes the first check of a shift.

    Moved by that mean's shift from the start, the track carried the start's own distance from the mode
    forward along the whole recording: the end-of-track NEES of this recording was 100, with the status
    ``ok``.  The moved samples' mean lies at their mode, so the shift is now measured again after the moves:
    nothing is reported as skewed, the track is the most likely one, and the truth lies inside the
    chi-square(4) 99.9 % point at its end.
    """
    geometry = _four_pairs()
    scenario = fd.Scenario(geometry=geometry, x0=(5e3, 5e3, 150.0, -50.0), duration=60.0, dt=0.1)
    sim = fd.simulate(scenario, np.random.default_rng(7))
    model = fd.TrackingModel.of(geometry)
    result = fd.run_estimator("smoother", sim.measurements, model, fd.initiate(sim.measurements.first_per_pair(10),
                                                                                 model), verify=False)
    assert not any("skewed" in x.message for x in result.reasons)
    e = result.primary
    d = e.states[-1] - sim.truth.at(e.times[-1:])[0]
    assert float(d @ np.linalg.solve(e.covariances[-1], d)) < chi2.ppf(0.999, 4)


def test_a_truth_with_process_noise_keeps_the_most_likely_track() -> None:
    """The same four pairs at 2 Hz for 120 s, the truth moving with the model's own process noise
    (q = 1e-3 m²/s³): the data hold the track about 4.5 standard deviations (a squared Mahalanobis length of
    20.5) from the constant-velocity samples' mode, whose posterior is then not the smoother's.

    Reported as skewed, the track was moved by the mean's shift from its start, nearly all that distance,
    carried along the recording: 'ok' with an end-of-track NEES of 84 (position RMSE 9.0 m).  Now the samples'
    skew is not reported where their mode lies beyond ``MODE_APART_MAX`` of the estimate: the most likely track,
    RMSE 2.7 m, its truth inside the chi-square(4) 99.9 % point at the end (measured 1.6).
    """
    geometry = _four_pairs()
    scenario = fd.Scenario(geometry=geometry, x0=(5e3, 5e3, 150.0, -50.0), duration=120.0, dt=0.5,
                           process_noise=fd.ConstantVelocity(q=1e-3))
    sim = fd.simulate(scenario, np.random.default_rng([9, 10]))
    model = fd.TrackingModel.of(geometry)
    init = fd.initiate(sim.measurements.initiation_window(10, 4.5), model)
    result = fd.run_estimator("smoother", sim.measurements, model, init, verify=False)
    assert not any("skewed" in x.message for x in result.reasons)
    e = result.primary
    d = e.states[-1] - sim.truth.at(e.times[-1:])[0]
    assert float(d @ np.linalg.solve(e.covariances[-1], d)) < chi2.ppf(0.999, 4)


def test_a_curved_valley_widens_the_covariance_and_the_truth_moves_inside_it() -> None:
    """Case a 5 km, a run whose Laplace covariance put the truth at a time-averaged NEES of 354.

    Starting Levenberg–Marquardt from the truth converges to the same optimum
    (the estimate is right); the sampled covariance encloses the Laplace one
    and brings the truth's NEES down by a factor of about 8 (measured 43).
    """
    sim, model, init = benchmark_run(0, 79)
    before = fd.run_estimator("smoother", sim.measurements, model, init, fd.SmootherSettings(sampled_covariance=False),
                              verify=False)

    def nees(e: fd.Estimates) -> float:
        d = e.states - sim.truth.at(e.times)
        v = np.einsum("ki,ki->k", d, np.linalg.solve(e.covariances, d[..., None])[..., 0])
        return float(v[e.times >= 10].mean())

    broad = 0
    for seed in range(4):  # what the sampled covariance does must hold whatever its sampler's seed
        after = fd.run_estimator("smoother", sim.measurements, model, init, fd.SmootherSettings(seed=seed),
                                 verify=False)
        # a curved valley keeps the most likely track: there the posterior mean is the worse point (docs/concepts.md)
        np.testing.assert_array_equal(before.primary.states, after.primary.states)
        assert any(r.code == "nonlinear" and r.status == "ok" for r in after.reasons)
        assert nees(after.primary) < nees(before.primary) / 4
        broad += any("tempered from a proposal" in r.message for r in after.reasons)
        # encloses the Laplace covariance at every time: the samples' excess is carried on its marginals
        for P, S in zip(before.primary.covariances, after.primary.covariances, strict=True):
            Li = np.linalg.inv(np.linalg.cholesky(P))
            assert np.linalg.eigvalsh(Li @ S @ Li.T).min() > 1 - 1e-9
    # the paper's curved valleys lie within the narrow proposal's reach (probe ratio <= 11.8, ESS >= 150 in the
    # benchmark's 400 sampled recordings with sampler seed 0): the broad one is seldom needed there.  Its
    # effective-sample sign fires by chance now and then (on this run with 1 of sampler seeds 0-15: seed 10)
    assert broad <= 1


#: A radar and one bistatic pair: the radar's Doppler leaves the track's rotation about it to the other pair.
RADAR_AND_PAIR = fd.Geometry(pairs=(fd.BistaticPair(tx=(-13906.3, -13421.1), rx=(-13906.3, -13421.1)),
                                    fd.BistaticPair(tx=(-37942.6, -17700.9), rx=(-18821.6, 25248.4))))


def _radar_and_pair(seed: int) -> tuple[fd.Measurements, np.ndarray, Callable[[fd.TrackResult], tuple[float, float]]]:
    """Draw ``seed`` of a target seen by :data:`RADAR_AND_PAIR`: its measurements, its first true state, and a function
    of a smoother's result: its reported major position sigma over the exact posterior's second moment about the
    same estimate (computed once, about the first estimate given), and the truth's NEES under the reported
    covariance."""
    sim = fd.simulate(fd.Scenario(geometry=RADAR_AND_PAIR, x0=(-27335.4, 16782.9, 6.9, -82.7), duration=30.0,
                                  dt=0.5), np.random.default_rng(seed))
    m = sim.measurements
    truth = sim.truth.at(m.scans().times[:1])[0]
    exact: list[np.ndarray] = []

    def first(result: fd.TrackResult) -> tuple[float, float]:
        e = result.primary
        x0, P = e.states[0], e.covariances[0]
        if not exact:
            post = exact_posterior(m, fd.TrackingModel.of(RADAR_AND_PAIR), float(m.time.max()), [x0],
                                   np.random.default_rng(5))
            d = post.mean - x0
            exact.append(post.covariance + np.outer(d, d))
        err = truth - x0
        return (float(np.sqrt(np.linalg.eigvalsh(P[:2, :2])[-1] / np.linalg.eigvalsh(exact[0][:2, :2])[-1])),
                float(err @ np.linalg.solve(P, err)))

    return m, truth, first


def _nonlinear(result: fd.TrackResult) -> str:
    return " ".join(r.message for r in result.reasons if r.code == "nonlinear")


def test_a_valley_that_bends_far_is_sampled_as_far_as_the_exact_posterior_reaches(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the narrow proposal N(x0, 4 P0) cannot reach the valley's far end, the broad one does.

    On this layout the posterior of the first state is a valley kilometres
    long (the exact posterior's position sigma along it 5 km on this draw).
    From the narrow proposal (as before) the samples' major sigma was 0.57
    of the exact posterior's second moment about the same estimate and the
    truth's NEES 366 (exact 5.8); its probe ratio is 30.9.  With the broad
    proposal: 0.99 of the exact sigma, NEES 10.0 (sampler seeds 0-7: 0.88-1.33,
    NEES 2.3-11.2).
    """
    m, _, first = _radar_and_pair(1)
    broad = fd.track(m, RADAR_AND_PAIR, "smoother")
    said = _nonlinear(broad)
    assert "tempered from a proposal" in said and "bends far" in said
    ratio, nees = first(broad)
    assert 0.8 < ratio < 1.5
    assert nees < chi2.ppf(0.999, 4)
    monkeypatch.setattr(spread, "BEND_LIMIT", np.inf)
    monkeypatch.setattr(spread, "ESS_MIN", 0.0)
    monkeypatch.setattr(spread, "GROWTH_LIMIT", np.inf)
    narrow = fd.track(m, RADAR_AND_PAIR, "smoother")
    np.testing.assert_array_equal(narrow.primary.states, broad.primary.states)  # only the covariance changes
    ratio_narrow, nees_narrow = first(narrow)
    assert ratio_narrow < 0.7 and nees_narrow > chi2.ppf(0.999, 4)


def test_a_valley_that_runs_on_is_found_by_the_growth_probe(monkeypatch: pytest.MonkeyPatch) -> None:
    """Draw 0 of the study below with sampler seed 1, the first whose broad proposal the growth probe sent (seed 0's
    went by its effective sample size): sigma 0.75 of the exact posterior's, the truth's NEES 4.4 (measured
    2026-12-01); with the effective sample size alone, as before, the narrow samples stand and miss the valley."""
    m, _, first = _radar_and_pair(0)
    result = fd.track(m, RADAR_AND_PAIR, "smoother", settings=fd.SmootherSettings(seed=1))
    said = _nonlinear(result)
    assert "tempered from a proposal" in said and "times their second moment" in said
    ratio, nees = first(result)
    assert 0.6 < ratio < 1.6 and nees < chi2.ppf(0.999, 4)
    monkeypatch.setattr(spread, "GROWTH_LIMIT", np.inf)
    narrow = fd.track(m, RADAR_AND_PAIR, "smoother", settings=fd.SmootherSettings(seed=1))
    assert "tempered from a proposal" not in _nonlinear(narrow)
    ratio_narrow, nees_narrow = first(narrow)
    assert ratio_narrow < 0.5 and nees_narrow > chi2.ppf(0.999, 4)


# Five sampler seeds (35 s on one core): run with -m slow; by default the test above checks the first the growth
# probe sends.
@pytest.mark.slow
def test_a_valley_that_runs_on_is_sampled_whatever_the_samplers_seed(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the probe ratio (7.8) looks like the paper's, the broad proposal still runs, whatever the seed.

    The one-step draw's effective sample size alone found this valley by
    chance: 29 and 2 of 4096 with sampler seeds 0 and 7, but 130-251 with
    seeds 1-6, whose samples then held 0.32-0.35 of the exact posterior's
    major sigma (truth's NEES 286-442).  The growth probe finds it with each:
    sigma 0.75-1.14 of the exact one and NEES 2.2-4.7 with seeds 0-7 (the
    broad samples' own Monte Carlo spread in a valley 7 km long).
    """
    m, _, first = _radar_and_pair(0)
    ratios, by_growth = [], []
    for seed in range(5):
        result = fd.track(m, RADAR_AND_PAIR, "smoother", settings=fd.SmootherSettings(seed=seed))
        said = _nonlinear(result)
        assert "tempered from a proposal" in said
        if "times their second moment" in said:  # the growth probe's words; else the effective sample size's
            by_growth.append(seed)
        ratio, nees = first(result)
        assert 0.6 < ratio < 1.6 and nees < chi2.ppf(0.999, 4)
        ratios.append(ratio)
    assert 0.8 < float(np.median(ratios)) < 1.25
    assert by_growth  # here seeds 1-4: the effective sample size alone would have missed the valley
    monkeypatch.setattr(spread, "GROWTH_LIMIT", np.inf)  # the effective sample size alone, as before
    narrow = fd.track(m, RADAR_AND_PAIR, "smoother", settings=fd.SmootherSettings(seed=by_growth[0]))
    assert "tempered from a proposal" not in _nonlinear(narrow)
    ratio_narrow, nees_narrow = first(narrow)
    assert ratio_narrow < 0.5 and nees_narrow > chi2.ppf(0.999, 4)


def _draw_64() -> tuple[fd.Measurements, np.ndarray]:
    """Radar-and-pair draw 64: its measurements and its first true state."""
    sim = fd.simulate(fd.Scenario(geometry=RADAR_AND_PAIR, x0=(-27335.4, 16782.9, 6.9, -82.7), duration=30.0,
                                  dt=0.5), np.random.default_rng(64))
    return sim.measurements, sim.truth.at(sim.measurements.scans().times[:1])[0]


def _adapted_passes(result: fd.TrackResult) -> int | None:
    """How many broad passes from the samples' own spread the smoother's ``nonlinear`` finding reports."""
    passes = re.search(r"and (\d+) times more from the samples' own spread", _nonlinear(result))
    return None if passes is None else int(passes.group(1))


def test_the_broad_passes_follow_a_valley_while_it_opens_up_and_stop_where_it_ends() -> None:
    """Radar-and-pair draw 64 with sampler seed 0, the first of the study below: the passes follow the valley on
    (5 passes, the truth's NEES 4.2; measured 2026-12-01: 4 passes with seeds 1 and 2); on the paper's curved
    valley (case a 5 km, run 79), which ends within reach, they stop at the fewest."""
    m, truth = _draw_64()
    result = fd.track(m, RADAR_AND_PAIR, "smoother", settings=fd.SmootherSettings(seed=0))
    passes = _adapted_passes(result)
    assert passes is not None and spread.ADAPTED_PASSES < passes <= spread.MAX_ADAPTED_PASSES
    err = truth - result.primary.states[0]
    assert err @ np.linalg.solve(result.primary.covariances[0], err) < chi2.ppf(0.999, 4)
    _assert_the_paper_valley_takes_the_fewest_passes()


def _assert_the_paper_valley_takes_the_fewest_passes() -> None:
    sim, model, init = benchmark_run(0, 79)
    e = fd.run_estimator("smoother", sim.measurements, model, init, fd.SmootherSettings(sampled_covariance=False),
                         verify=False).primary
    post, _ = _posterior(sim.measurements, model, float(e.times[0]), None, 0, spread.SAMPLES)
    drawn = spread._sample_broad(post, e.states[0], e.covariances[0], spread.SAMPLES, spread.MOVES,
                                 np.random.default_rng(0))
    assert drawn is not None and drawn[2] == spread.ADAPTED_PASSES


# Eight sampler seeds (45 s on one core): run with -m slow; by default the test above checks the first.
@pytest.mark.slow
def test_the_broad_passes_follow_a_valley_while_it_opens_up() -> None:
    """Radar-and-pair draw 64: a valley the broad passes are still opening up gets more of them.

    With two passes from the samples' own spread the major sigma was 3.7 km
    with sampler seed 0 (the truth's NEES 54) and 7.2-8.4 km with seeds 1-3;
    the spread then still grew by more than half a pass.  Followed on (up to
    five passes): 4-5 passes, 6.2-9.2 km, NEES 2.4-4.2.  (The exact
    posterior's own importance sampler is no reference here: 3.7-9.4 km by
    its seed, on 7-2,437 effective samples.)  On the paper's curved valley
    (case a 5 km, run 79), which ends within reach, the passes stop at the
    fewest.  Not with every seed (measured 2026-11-30, seeds 0-7 and 20-23):
    10 of 12 took 4-5 passes (truth's NEES 2.4-4.7), seed 20 stopped at 2
    (NEES 8.7), and with seed 5 no sign sent the samples to the broad
    proposal at all (NEES 678: a miss of the growth probe's); so the test
    asks it of most of eight seeds (fewer than five: a chance of a few %).
    """
    m, truth = _draw_64()
    followed = 0
    for seed in range(8):
        result = fd.track(m, RADAR_AND_PAIR, "smoother", settings=fd.SmootherSettings(seed=seed))
        passes = _adapted_passes(result)
        if passes is None:
            continue
        assert spread.ADAPTED_PASSES <= passes <= spread.MAX_ADAPTED_PASSES
        err = truth - result.primary.states[0]
        if passes > spread.ADAPTED_PASSES:
            followed += 1
            assert err @ np.linalg.solve(result.primary.covariances[0], err) < chi2.ppf(0.999, 4)
    assert followed >= 5
    _assert_the_paper_valley_takes_the_fewest_passes()


def test_where_the_broad_proposal_draws_nothing_the_narrow_ones_samples_stand(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every route to the broad proposal (a probe ratio beyond the bend limit, too few effective samples, a growth
    probe that reaches further) falls back to the narrow proposal's samples, exactly as drawn without the broad
    one, where it draws nothing finite."""
    sim = fd.simulate(fd.Scenario(geometry=RADAR_AND_PAIR, x0=(-27335.4, 16782.9, 6.9, -82.7), duration=30.0,
                                  dt=0.5), np.random.default_rng(0))
    model = fd.TrackingModel.of(RADAR_AND_PAIR)
    e = fd.track(sim.measurements, RADAR_AND_PAIR, "smoother",
                 settings=fd.SmootherSettings(sampled_covariance=False)).primary
    x0, P0 = e.states[0], e.covariances[0]
    def drawn(ratio: float, ess_min: float, growth_limit: float = np.inf) -> tuple[np.ndarray, float, str] | None:
        post, _ = _posterior(sim.measurements, model, float(e.times[0]), None, 0, spread.SAMPLES)
        monkeypatch.setattr(spread, "ESS_MIN", ess_min)
        monkeypatch.setattr(spread, "GROWTH_LIMIT", growth_limit)
        return spread._sample_reaching(post, x0, P0, ratio, np.random.default_rng(3))

    plain = drawn(5.0, 0.0)  # inside every limit: the narrow proposal alone
    assert plain is not None and plain[2] == ""
    monkeypatch.setattr(spread, "_sample_broad", lambda *args: None)  # no broad draw has a finite posterior
    for ratio, ess_min, growth_limit in [(5.0, 4096.0, np.inf), (2.0 * spread.BEND_LIMIT, 0.0, np.inf),
                                         (5.0, 0.0, 0.0)]:
        fallback = drawn(ratio, ess_min, growth_limit)
        assert fallback is not None and fallback[2] == ""
        np.testing.assert_array_equal(fallback[0], plain[0])  # the same generator: the same samples


def _truth_nees(sim: fd.Simulation, e: fd.Estimates, after: float = 10.0) -> float:
    """The truth's NEES averaged over the estimates from ``after`` seconds on."""
    d = e.states - sim.truth.at(e.times)
    v = np.einsum("ki,ki->k", d, np.linalg.solve(e.covariances, d[..., None])[..., 0])
    return float(v[e.times >= after].mean())


def _plain_and_widened(name: str, s: int, r: int, seed: int = 0, split_ratio: float = 2.5
                       ) -> tuple[fd.Simulation, fd.TrackResult, fd.TrackResult]:
    """A filter through the registry without and with the sampled check (sampler ``seed``, the start split by
    ``split_ratio``); asserts what the check may not change.

    The estimates and where covariances exist are the filter's; the checked
    covariances enclose the filter's at every time (whitened eigenvalues >= 1).
    """
    sim, model, init = benchmark_run(s, r)
    kinds: dict[str, type[fd.EKFSettings | fd.ISAM2Settings | fd.FixedLagSettings]] = {
        "ekf": fd.EKFSettings, "isam2": fd.ISAM2Settings, "fixed-lag": fd.FixedLagSettings}
    off = kinds[name](sampled_covariance=False, seed=seed, split_ratio=split_ratio)
    plain = fd.run_estimator(name, sim.measurements, model, init, off)
    wide = fd.run_estimator(name, sim.measurements, model, init, kinds[name](seed=seed, split_ratio=split_ratio))
    a, b = plain.primary, wide.primary
    np.testing.assert_array_equal(a.states, b.states)
    np.testing.assert_array_equal(a.cov_ok, b.cov_ok)
    for P, S in zip(a.covariances[a.cov_ok], b.covariances[b.cov_ok], strict=True):
        Li = np.linalg.inv(np.linalg.cholesky(P))
        assert np.linalg.eigvalsh(Li @ S @ Li.T).min() > 1 - 1e-9
    return sim, plain, wide


def test_filtered_covariances_widen_where_the_posterior_reaches_further_and_the_estimates_stay() -> None:
    """iSAM2 on case a 5 km, seed 2026, run 79: its Gaussian marginals put the truth at a NEES of 335.

    The widened covariances enclose the filter's own at every time (whitened
    eigenvalues >= 1), the estimates are the filter's, the truth's NEES
    drops by more than half (measured 335 -> 109; 121 by the sampled checks
    alone, ``linearised_everywhere=False``), and the finding says what was
    done.  The verdict's ``reference`` covariance test reads the covariance
    reported: on the plain run (its own) it is ``doubtful``, the smoother
    3.8 times less certain; on the widened one it is informational and names
    both numbers.  Before 2026-12-03 it read the own covariance in both and
    this answer was ``doubtful``; that reading called 45 consistent answers
    ``doubtful`` for this one catch in 640 tracker runs of the benchmark's
    recordings, and here the exact posterior's own mean and covariance miss
    the truth too (docs/concepts.md, "The covariance test reads the reported
    covariance").  The track depends on the sampled Gaussian sum it starts from: with sampler
    seeds 0-7 the plain NEES was 156-370 (widened 62-114) but with seed 3,
    whose track is 58 (widened 51) and not doubtful; seeds are tried until
    the track is the over-confident one this test is about.
    """
    for seed in range(4):
        sim, plain, wide = _plain_and_widened("isam2", 0, 79, seed)
        if _truth_nees(sim, plain.primary) > 100.0:
            break
    else:
        pytest.fail("iSAM2's own covariances held the truth (NEES <= 100) with sampler seeds 0-3")
    a, b = plain.primary, wide.primary
    assert _truth_nees(sim, b) < 0.5 * _truth_nees(sim, a)
    assert [r.code for r in wide.reasons if r.code == "nonlinear" and r.status == "ok"] == ["nonlinear"]
    assert {r.code for r in plain.reasons if r.status == "doubtful"} == {"reference"}
    (own,) = [r for r in plain.reasons if "less certain" in r.message]
    (said,) = [r for r in wide.reasons if "less certain" in r.message]
    assert own.status == "doubtful" and said.status == "ok" and "own Gaussian covariance" in said.message
    # the smoothed estimates (the tracker's second set) are untouched
    np.testing.assert_array_equal(plain.estimates[1].covariances, wide.estimates[1].covariances)


def test_the_ekfs_covariances_are_checked_as_isam2s_are() -> None:
    """The EKF on case b 25 km, seed 2026, run 36: its own covariances put the truth at a NEES of 226.

    Through the registry the covariances are widened (whitened eigenvalues
    >= 1 at every time), the estimates and the verdict are the filter's,
    the truth's NEES falls below a quarter (measured 226 -> 12.3, 12.7 by
    the sampled checks alone; the benchmark's 100 runs of that scenario
    6.28 -> 3.28, 3.48 by the checks alone), and the finding says so.  The
    whole-track reference finding reads the covariances the sampled checks
    widened (not the linearised enclosure, built from the smoother's
    track): the plain ones stray from the smoother's track (6.9 sigma on
    average), the checked ones do not.  The covariance test reads the
    covariance reported: ``doubtful`` on the plain one (the smoother 3.8 times
    less certain), informational on the widened one (1.1 times); the other
    findings are the same.

    The EKF starts from the initiation's Gaussian alone (``split_ratio=inf``),
    as it did when these numbers were measured: the window's curvature probe
    ratio is 9.4, just short of the ``nonlinear`` finding, and since
    2026-12-06 the default splits such a start, whose EKF then holds the
    truth at a NEES of 8.1 by itself.
    """
    sim, plain, wide = _plain_and_widened("ekf", 4, 36, split_ratio=float("inf"))
    a, b = plain.primary, wide.primary
    assert _truth_nees(sim, b) < 0.25 * _truth_nees(sim, a)
    assert [r.code for r in wide.reasons if r.code == "nonlinear" and r.status == "ok"] == ["nonlinear"]
    assert wide.status == plain.status == "doubtful"
    track = [r for r in plain.reasons if "lay on average" in r.message]
    assert len(track) == 1 and not any("lay on average" in r.message for r in wide.reasons)
    covariance = [r for r in plain.reasons if "less certain" in r.message]
    (said,) = [r for r in wide.reasons if "less certain" in r.message]
    assert [r.status for r in covariance] == ["doubtful"] and said.status == "ok"
    assert "is 3.8 times less certain" in said.message and "is 1.1 times" in said.message
    assert ([r for r in wide.reasons if r.code != "nonlinear" and r is not said]
            == [r for r in plain.reasons if r not in track and r not in covariance])


def test_the_fixed_lag_smoothers_covariances_are_checked_against_the_data_they_have_read() -> None:
    """The fixed-lag smoother on case a 25 km, seed 2026, run 78: its lagged covariances put the truth at a NEES of 30.

    Through the registry they are widened (whitened eigenvalues >= 1 at
    every time), the estimates and the verdict's other reasons are the
    smoother's, the truth's NEES falls below a third (measured 30.0 -> 6.2;
    the benchmark's 100 runs of that scenario 4.75 -> 3.87, 3.98 by the
    sampled checks alone), and the finding names the look-ahead.

    The smoother starts from the initiation's Gaussian alone
    (``split_ratio=inf``), as when these numbers were measured: since
    2026-12-06 the default splits this window's start (curvature probe
    ratio between 2.5 and the finding's 10), and the split smoother's own
    lagged covariances hold the truth (NEES 4.5) with nothing to widen.
    """
    sim, plain, wide = _plain_and_widened("fixed-lag", 1, 78, split_ratio=float("inf"))
    assert _truth_nees(sim, wide.primary) < _truth_nees(sim, plain.primary) / 3
    (found,) = [r for r in wide.reasons if r.code == "nonlinear" and r.status == "ok"]
    assert "lagged covariances" in found.message and "5 s later" in found.message
    assert [r for r in wide.reasons if r is not found] == list(plain.reasons)
    # the filtered estimates (the smoother's second set) are untouched
    np.testing.assert_array_equal(plain.estimates[1].covariances, wide.estimates[1].covariances)


def test_a_lagged_check_reads_the_data_up_to_one_lag_after_its_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """With ``lag`` the check at t samples the data up to t + lag: no less, no more.

    Recorded at every check (a spy around the one-check function): the
    latest measurement it sees lies within a scan of t + lag, and changing
    the measurements after t + lag of the first check leaves that check's
    widening exactly as it was.  On the track of
    :func:`test_the_fixed_lag_smoothers_covariances_are_checked_against_the_data_they_have_read`
    (its start unsplit), which the checks widen.
    """
    import fgdoppler.estimators.spread as spread

    sim, model, init = benchmark_run(1, 78)
    e = fd.run_estimator("fixed-lag", sim.measurements, model, init,
                         fd.FixedLagSettings(sampled_covariance=False, split_ratio=float("inf"))).primary
    m = sim.measurements
    seen: list[tuple[float, float]] = []
    real = spread._widening

    def spy(data: fd.Measurements, model: fd.TrackingModel, t0: float, t: float, *args: object) -> object:
        seen.append((t, float(np.max(data.time))))
        return real(data, model, t0, t, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(spread, "_widening", spy)
    one = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0, lag=5.0)
    assert one is not None and len(seen) >= 2
    step = float(np.max(np.diff(np.unique(m.time))))
    for t, last in seen:
        assert min(t + 5.0, float(m.time.max())) - step < last <= t + 5.0
    t1 = seen[1][0]  # the second check: the first covers the data up to seen[0][0] + lag only
    late = m.time > t1 + 5.0
    changed = fd.Measurements(time=m.time, pair=m.pair, doppler=np.where(late, m.doppler + 3.0 * m.sigma, m.doppler),
                              sigma=m.sigma)
    two = filtered_spread(changed, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0, lag=5.0)
    assert two is not None
    early = e.times < t1
    np.testing.assert_array_equal(one.covariances[early], two.covariances[early])
    with pytest.raises(ValueError, match="lag"):
        filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0, lag=-1.0)


@functools.cache
def _run_79(name: str, seed: int) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation, fd.TrackResult]:
    """Case a 5 km, seed 2026, run 79 and ``name``'s result on it with sampler seed ``seed``: the smoother's with
    its default settings, a filter's without the sampled check.  Computed once per process: several tests below
    read the same runs (and only read them)."""
    sim, model, init = benchmark_run(0, 79)
    settings = fd.SmootherSettings(seed=seed) if name == "smoother" else {
        "isam2": fd.ISAM2Settings, "fixed-lag": fd.FixedLagSettings}[name](sampled_covariance=False, seed=seed)
    return sim, model, init, fd.run_estimator(name, sim.measurements, model, init, settings)


@functools.cache
def _widened_track(name: str, lag: float) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation, fd.Estimates, int]:
    """Case a 5 km, seed 2026, run 79: ``name``'s estimates without the sampled check, and the first sampler seed
    (0-3) with which the check widens them.  The track starts from a sampled Gaussian sum, and with some seeds it
    is one its checks leave alone (sampler streams shifted by 20: 1 of 4); the tests below need one they widen."""
    for seed in range(4):
        sim, model, init, result = _run_79(name, seed)
        e = result.primary
        if filtered_spread(sim.measurements, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0,
                           lag=lag, seed=seed) is not None:
            return sim, model, init, e, seed
    pytest.fail(f"no sampled check widened {name}'s track with sampler seeds 0-3")


def test_a_filtered_check_reads_only_the_data_up_to_its_time() -> None:
    """Changing every measurement after 15 s leaves the covariances up to 15 s exactly as they were."""
    sim, model, _, e, seed = _widened_track("isam2", 0.0)
    m = sim.measurements
    late = m.time > 15.0
    changed = fd.Measurements(time=m.time, pair=m.pair, doppler=np.where(late, m.doppler + 3.0 * m.sigma, m.doppler),
                              sigma=m.sigma)
    one = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0, seed=seed)
    two = filtered_spread(changed, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0, seed=seed)
    assert one is not None and two is not None
    early = e.times <= 15.0
    np.testing.assert_array_equal(one.covariances[early], two.covariances[early])
    assert not np.array_equal(one.covariances[~early], two.covariances[~early])


def test_well_observed_filters_keep_their_gaussian_covariance() -> None:
    """Case a 45 km, where iSAM2's marginals are consistent: the widening leaves the truth's NEES as it was.

    Over 100 runs (seed 2026) the run-averaged NEES is 3.74 with and
    without it; a check widens only where the samples' variance exceeds the
    filter's FILTER_WIDEN_MIN = 2 times, which the sampler's own noise
    reaches in about 3 % of this scenario's checks.
    """
    assert FILTER_WIDEN_MIN == 2.0
    before, after = [], []
    for r in range(5):
        sim, model, init = benchmark_run(2, r)
        e = fd.run_estimator("isam2", sim.measurements, model, init, fd.ISAM2Settings(sampled_covariance=False),
                             verify=False).primary
        w = filtered_spread(sim.measurements, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0)
        before.append(_truth_nees(sim, e))
        after.append(before[-1] if w is None else _truth_nees(sim, replace(e, covariances=w.covariances)))
    assert np.mean(after) == pytest.approx(np.mean(before), rel=0.05)


@pytest.mark.parametrize("name", ["isam2", "ekf"])
def test_the_filtered_check_leaves_out_what_the_gate_rejected(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """A 40-sigma outlier is rejected by the filter's gate and is not among the measurements the samples see."""
    sim, model, init = benchmark_run(2, 0)
    m = sim.measurements
    j = int(np.flatnonzero(m.time > 12.0)[0])
    doppler = m.doppler.copy()
    doppler[j] += 40.0 * m.sigma[j]
    bad = fd.Measurements(time=m.time, pair=m.pair, doppler=doppler, sigma=m.sigma)
    seen: list[fd.Measurements] = []

    def spy(measurements: fd.Measurements, *args: object, **kwargs: object) -> None:
        seen.append(measurements)
        return None

    monkeypatch.setattr(registry, "filtered_spread", spy)
    res = fd.run_estimator(name, bad, model, init)
    assert any(t == m.time[j] and p == m.pair[j] and not ok for t, p, _, ok in res.nis)
    (kept,) = seen
    assert len(kept) == len(m) - 1
    assert not np.any((kept.time == m.time[j]) & (kept.pair == m.pair[j]))


def test_no_check_where_the_process_noise_outgrows_the_filters_covariance() -> None:
    """The samples move deterministically; where Q(t - t0) exceeds the filter's covariance, no check samples.

    The same estimates with covariances 1e4 times too small from 19.5 s on
    (whitened process noise since the start far above FILTER_NOISE_MAX
    there) keep them as they are from 19.5 s on — a check falls there (every
    5 s from 4.5 s, each widening), so nothing is carried over — while
    before they are widened exactly as with the true covariances (on a slow 600 s track the
    noise term alone had widened a consistent filter, NEES 3.52 -> 2.73).
    """
    sim, model, _, e, seed = _widened_track("isam2", 0.0)
    late = e.times >= 19.5
    tiny = e.covariances.copy()
    tiny[late] *= 1e-4
    Li = np.linalg.inv(np.linalg.cholesky(tiny[late][0]))
    assert np.linalg.eigvalsh(Li @ model.motion.Q(e.times[late][0] - sim.measurements.time.min()) @ Li.T).max() \
        > FILTER_NOISE_MAX
    one = filtered_spread(sim.measurements, model, e.times, e.states, e.covariances, e.cov_ok, interval=5.0, seed=seed)
    two = filtered_spread(sim.measurements, model, e.times, e.states, tiny, e.cov_ok, interval=5.0, seed=seed)
    assert one is not None and two is not None
    np.testing.assert_array_equal(two.covariances[~late], one.covariances[~late])
    np.testing.assert_array_equal(two.covariances[late], tiny[late])


@pytest.mark.parametrize(("name", "lag"), [("isam2", 0.0), ("fixed-lag", 5.0)])
def test_beyond_the_samples_reach_the_covariances_enclose_the_linearised_posterior(name: str, lag: float) -> None:
    """The same tiny covariances from 19.5 s on, with the offline smoother's track as ``reference``.

    Before 19.5 s the covariances are exactly those without a reference
    (the samples reach there).  From the first check at or after 19.5 s the
    tiny covariances put the samples out of reach; when that check falls
    depends on the track (the checks back off where they widen nothing:
    iSAM2's and the old fixed-lag track's at 19.5 s, the fixed-lag track's
    at 24.5 s since its lagged mixture weighs only the data read), and the
    finding counts those times.  Up to it the covariances are the sampled
    checks' alone; from it on, each
    encloses the estimator's own and the posterior mean-square error of its
    estimate under the posterior of the data it has read (up to its time
    for iSAM2's filtered estimates, up to ``lag`` after it for the fixed-lag
    smoother's lagged ones) linearised about the smoother's track
    (``linearized_filter``, started from the first estimate and its widened
    covariance) up to the widening threshold: no whitened eigenvalue of that
    error above ``FILTER_WIDEN_MIN``.
    """
    sim, model, _, e, seed = _widened_track(name, lag)
    m = sim.measurements
    ref = _run_79("smoother", seed)[3].primary
    late = e.times >= 19.5
    tiny = e.covariances.copy()
    tiny[late] *= 1e-4
    one = filtered_spread(m, model, e.times, e.states, tiny, e.cov_ok, interval=5.0, lag=lag, seed=seed)
    two = filtered_spread(m, model, e.times, e.states, tiny, e.cov_ok, interval=5.0, lag=lag, seed=seed,
                          reference=(ref.times, ref.states))
    assert one is not None and two is not None
    np.testing.assert_array_equal(two.covariances[~late], one.covariances[~late])
    assert two.checked is not None
    np.testing.assert_array_equal(two.checked, one.covariances)
    assert "linearised about the offline smoother's track" in two.reason.message
    found = re.search(r"of the (\d+) times beyond the samples' reach", two.reason.message)
    assert found is not None
    n_beyond = int(found.group(1))
    assert 10 <= n_beyond <= np.count_nonzero(late)  # at least 5 s of the last 10.5 s
    np.testing.assert_array_equal(two.covariances[:-n_beyond], one.covariances[:-n_beyond])
    late = np.arange(e.times.size) >= e.times.size - n_beyond
    post = linearized_filter(m, model, ref.times, ref.states, e.times[0], e.states[0], one.covariances[0])
    means, covs = post.at(e.times[late], e.times[late] + lag)
    error = mean_square_errors(e.states[late], means, covs)
    for P, W, S in zip(tiny[late], two.covariances[late], error, strict=True):
        Li = np.linalg.inv(np.linalg.cholesky(W))
        assert np.linalg.eigvalsh(Li @ S @ Li.T).max() <= FILTER_WIDEN_MIN * (1 + 1e-9)
        assert np.linalg.eigvalsh(W - P).min() >= -1e-9 * np.abs(W).max()
    # the tiny covariances do not hold the error: widened at every one of those times
    assert np.all(np.abs(two.covariances[late] - tiny[late]).max(axis=(1, 2)) > 0)
    if lag:  # and the lagged posterior is not the filtered one: those times read the later data
        filtered = post.at(e.times[late])
        assert np.all(np.trace(covs, axis1=1, axis2=2)[e.times[late] < e.times[-1] - lag]
                      < np.trace(filtered[1], axis1=1, axis2=2)[e.times[late] < e.times[-1] - lag])


@pytest.mark.parametrize(("name", "lag"), [("isam2", 0.0), ("fixed-lag", 5.0)])
def test_linearised_everywhere_encloses_the_linearised_posterior_at_every_time(name: str, lag: float) -> None:
    """Case a 5 km, seed 2026, run 79 with ``linearised_everywhere``: the linearised enclosure at every estimate.

    Every covariance encloses the one the sampled checks alone give (whitened
    eigenvalues of the difference >= 0), and at every time leaves no whitened
    eigenvalue of the posterior mean-square error of its estimate under the
    linearised posterior of the data it has read above ``FILTER_WIDEN_MIN``
    (the same posterior as beyond the samples' reach: ``linearized_filter``
    about the smoother's track from the first estimate and its checked
    covariance).  The finding says it was checked at every time; the
    covariances of the sampled checks alone come with it (``checked``);
    without a reference the flag changes nothing.  Whether the linearised
    enclosure widens anything beyond the sampled checks here depends on the
    sampler seed (of the Gaussian sum the tracker starts from, the checks'
    samples and the smoother's; the fixed-lag smoother: with seeds 0-5 it
    does but with seed 2), so seeds are tried until it does.
    """
    for seed in range(4):
        sim, model, _, result = _run_79(name, seed)
        m, e = sim.measurements, result.primary
        ref = _run_79("smoother", seed)[3].primary
        check = {"interval": 5.0, "lag": lag, "seed": seed}
        one = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, **check,
                              reference=(ref.times, ref.states))
        two = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, **check,
                              reference=(ref.times, ref.states), linearised_everywhere=True)
        assert two is not None  # the enclosure at every estimate widens these over-confident tracks
        if one is not None and two.checked is not None:  # the sampled checks widened too (not with every seed)
            break
    else:
        pytest.fail("the linearised enclosure widened nothing with sampler seeds 0-3")
    alone = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, **check,
                            linearised_everywhere=True)
    assert alone is not None
    np.testing.assert_array_equal(alone.covariances, one.covariances)
    # the checks' own covariances ride along, for the finding that compares with the reference's track
    assert one.checked is None
    np.testing.assert_array_equal(two.checked, one.covariances)
    ok = e.cov_ok
    post = linearized_filter(m, model, ref.times, ref.states, e.times[0], e.states[0], one.covariances[0])
    means, covs = post.at(e.times[ok], e.times[ok] + lag)
    error = mean_square_errors(e.states[ok], means, covs)
    for P, W, S in zip(one.covariances[ok], two.covariances[ok], error, strict=True):
        Li = np.linalg.inv(np.linalg.cholesky(W))
        assert np.linalg.eigvalsh(Li @ S @ Li.T).max() <= FILTER_WIDEN_MIN * (1 + 1e-9)
        assert np.linalg.eigvalsh(W - P).min() >= -1e-9 * np.abs(W).max()
    assert np.any(np.abs(two.covariances[ok] - one.covariances[ok]).max(axis=(1, 2)) > 0)
    assert f"of the {int(ok.sum())} times checked" in two.reason.message


def test_linearised_everywhere_holds_isam2s_error_between_the_checks() -> None:
    """Case a 25 km, seed 2026, run 75: iSAM2's checked covariances put the truth at a run-averaged NEES of 20.6
    (t >= 10 s), beyond the chi-square(4) 99.9 % point 18.5, and the verdict said ``ok``.

    The sampled checks found the curved posterior at every check but carry
    each widening to the next check; with ``linearised_everywhere`` the
    covariances at every time enclose the posterior linearised about the
    smoother's track too, and hold the error (measured 7.3).  The estimates
    and the verdict's findings other than the widening's are the same.  The
    registry's default.  iSAM2 starts from the initiation's Gaussian alone
    (``split_ratio=inf``), as when these numbers were measured: since
    2026-12-06 the default splits this window's start (curvature probe ratio
    between 2.5 and the finding's 10), and the split tracker's checked
    covariances hold the truth (NEES 8.3) either way.
    """
    assert fd.ISAM2Settings().linearised_everywhere
    sim, model, init = benchmark_run(1, 75)
    m = sim.measurements
    ref = fd.run_estimator("smoother", m, model, init)
    alone = float("inf")
    plain = fd.run_estimator("isam2", m, model, init,
                             fd.ISAM2Settings(linearised_everywhere=False, split_ratio=alone), reference=ref)
    every = fd.run_estimator("isam2", m, model, init, fd.ISAM2Settings(split_ratio=alone), reference=ref)
    np.testing.assert_array_equal(plain.primary.states, every.primary.states)
    limit = float(chi2.ppf(0.999, 4))
    assert _truth_nees(sim, plain.primary) > limit
    assert _truth_nees(sim, every.primary) < limit
    assert [r for r in plain.reasons if r.code != "nonlinear"] == [r for r in every.reasons if r.code != "nonlinear"]


def test_the_whole_track_finding_reads_the_covariances_without_the_linearised_enclosure(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The registry's whole-track ``reference`` finding compares the estimates with the smoother's track; the
    linearised enclosure is built from that track, so the finding reads the covariances without it: those of
    the sampled checks, plus the calibration offsets' share where offsets are declared (the same share as the
    reported ones get).  Case a 25 km, seed 2026, run 75 (iSAM2; the enclosure widens there)."""
    seen: list[np.ndarray] = []
    real = registry.track_reference

    def spy(est: fd.Estimates, ref: fd.Estimates) -> list[object]:
        seen.append(est.covariances)
        return real(est, ref)

    monkeypatch.setattr(registry, "track_reference", spy)
    sim, model, init = benchmark_run(1, 75)
    m = sim.measurements
    ref = fd.run_estimator("smoother", m, model, init)
    runs = {}
    for name, settings in {"checks": fd.ISAM2Settings(linearised_everywhere=False), "both": fd.ISAM2Settings(),
                           "offsets": fd.ISAM2Settings(bias_sigma=0.05)}.items():
        runs[name] = fd.run_estimator("isam2", m, model, init, settings, reference=ref).primary.covariances
    checks, both, offsets = seen
    np.testing.assert_array_equal(checks, runs["checks"])  # without the enclosure: the reported ones
    np.testing.assert_array_equal(both, runs["checks"])  # with it: the checks' own, not the reported
    assert not np.array_equal(runs["both"], runs["checks"])
    share = runs["offsets"] - runs["both"]
    assert np.abs(share).max() > 0
    np.testing.assert_allclose(offsets, runs["checks"] + share, rtol=1e-9, atol=1e-9 * np.abs(runs["checks"]).max())


@pytest.fixture(scope="module")
def long_recording() -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation, fd.TrackResult]:
    """600 s of case b's pairs with the model's own process noise (seed 7), its initiation and offline smoother
    (the reference a filter with the default gate and loss runs: given to the EKF below, not run twice)."""
    scen = fd.Scenario(geometry=fd.paper_geometry("b"), x0=(20e3, 3e3, 30.0, -40.0), duration=600.0,
                       time_offsets=(0.0, PAPER_CASE_B_OFFSET), process_noise=fd.ConstantVelocity(q=1e-3))
    sim = fd.simulate(scen, np.random.default_rng(7))
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    return sim, model, init, fd.run_estimator("smoother", sim.measurements, model, init)


def test_on_a_long_recording_the_filters_covariances_hold_its_error(long_recording: tuple) -> None:
    """600 s of case b's pairs with the model's own process noise (seed 7): the EKF linearised at its own
    predictions claimed a covariance its error does not fit (run-averaged NEES 49 in 4 dimensions over
    t >= 30 s, beyond the chi-square(4) 99.9 % point 18.5).

    With the offline smoother's track as the linearisation of the data so far
    (``run_estimator``'s reference) the reported covariances hold the error
    (measured 4.3, below the point); the estimates are the filter's.  The
    EKF starts from a sampled Gaussian sum (the initiation is ``nonlinear``),
    and with sampler seeds 10-12 its own covariances happen to fit its track
    (NEES 13-18); seeds are tried until they do not, and the checked ones
    must hold the error with each seed tried.
    """
    sim, model, init, ref = long_recording
    limit = float(chi2.ppf(0.999, 4))
    for seed in range(4):
        own = fd.run_estimator("ekf", sim.measurements, model, init, fd.EKFSettings(seed=seed), verify=False).primary
        checked = fd.run_estimator("ekf", sim.measurements, model, init, fd.EKFSettings(seed=seed),
                                   reference=ref).primary
        np.testing.assert_array_equal(checked.states, own.states)
        assert _truth_nees(sim, checked, 30.0) < limit
        if _truth_nees(sim, own, 30.0) > limit:
            break
    else:
        pytest.fail("the EKF's own covariances fitted its error with sampler seeds 0-3")


def test_on_a_long_recording_the_fixed_lag_smoothers_covariances_hold_its_error(long_recording: tuple) -> None:
    """The same 600 s recording: the fixed-lag smoother's lagged covariances, even after the sampled check,
    put the truth at a run-averaged NEES of 124 (t >= 30 s; the check's samples stop reaching after the
    first minutes).

    With the offline smoother's track as the linearisation of the data up to
    one lag after each estimate (``reference``) they hold the error
    (measured 4.0, below the chi-square(4) 99.9 % point 18.5; at 300 s both are below it, 2.7 and 2.3).
    """
    sim, model, init, reference = long_recording
    m = sim.measurements
    settings = fd.FixedLagSettings(sampled_covariance=False)
    e = fd.run_estimator("fixed-lag", m, model, init, settings, verify=False).primary
    ref = reference.primary
    check = {"interval": fd.FixedLagSettings().sampling_interval, "lag": settings.lag}
    own = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, **check)
    checked = filtered_spread(m, model, e.times, e.states, e.covariances, e.cov_ok, **check,
                              reference=(ref.times, ref.states))
    assert own is not None and checked is not None
    limit = float(chi2.ppf(0.999, 4))
    assert _truth_nees(sim, replace(e, covariances=own.covariances), 30.0) > limit
    assert _truth_nees(sim, replace(e, covariances=checked.covariances), 30.0) < limit


def test_the_process_noise_share_is_the_whitened_eigenvalue() -> None:
    """By hand: with P = s² I the share is the largest eigenvalue of Q(Δt) / s²; the largest over times."""
    model = fd.TrackingModel.of(fd.paper_geometry("a"))
    q = model.motion.q
    for T, s in ((30.0, 3.0), (5.0, 0.1)):
        a, b, c = q * T**3 / 3.0, q * T**2 / 2.0, q * T  # [[a, b], [b, c]] per axis
        expected = (0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)) / s**2
        P = np.stack([s**2 * np.eye(4)] * 2)
        assert _noise_share(model, P, np.array([0.0, T])) == pytest.approx(expected, rel=1e-12)
    with pytest.raises(np.linalg.LinAlgError):
        _noise_share(model, -np.eye(4)[None], np.array([1.0]))


def _precise(sigma: float = 0.05) -> tuple[fd.Measurements, fd.TrackingModel, fd.Initiation]:
    """Case a 45 km with Doppler more precise than the paper's 1 m/s (one recording)."""
    scen = replace(fd.paper_scenario("a", 45e3), sigma=sigma)
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence(11).spawn(1)[0]))
    model = fd.TrackingModel.of(scen.geometry)
    return sim.measurements, model, fd.initiate(sim.measurements.first_per_pair(10), model)


def _on_masts(run: int) -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation]:
    """Run ``run`` of ``studies/process_noise_share.py``'s 3-D cell: four pairs on masts, an aircraft 50-70 km
    out at 1-6 km, 60 s (the study's recordings, drawn the same way)."""
    rng = np.random.default_rng(np.random.SeedSequence(9).spawn(run + 1)[run])
    g = fd.resolve_geometry(Path(__file__).resolve().parents[2] / "studies" / "geometries" / "four_pairs_on_masts.toml")
    start = (60e3 + rng.uniform(-10e3, 10e3), -20e3 + rng.uniform(-10e3, 10e3), rng.uniform(1e3, 6e3))
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(*start, -200.0, 100.0, 0.0), duration=60.0, dt=0.5), rng)
    model = fd.TrackingModel.of(g)
    return sim, model, fd.initiate(sim.measurements.first_per_pair(10), model)


@pytest.mark.parametrize("run", [1, 2])
def test_a_bend_the_process_noise_keeps_from_sampling_is_reported(run: int) -> None:
    """No samples where the process noise sets the variance, and not ``ok`` where the Laplace covariance fails.

    Four pairs in 3-D over 60 s: along the probe's axis the constant-
    velocity cost accounts for less than a quarter of the smoother's
    variance (measured 0.23 and 0.14), below DETERMINISTIC_MIN, so no
    samples are drawn; that cost still bends far beyond its quadratic model
    there (measured 56 and 2.6e4 times: between the verdict's
    CURVATURE_LIMIT and TRUST_LIMIT, and beyond the second), and the truth
    lies far outside the Laplace covariance in six dimensions (measured
    run-averaged NEES 67 and 435; the position block alone 0.29 and 0.42: the
    stretch is in a thin direction mixing speed and position).  Until
    2026-12-06 both tracks were ``ok``; until 2026-12-07 a ``doubtful``
    ``nonlinear`` finding came with the Laplace covariances.  Now the
    covariances are widened to the second moments of the smoother's cost
    profiled along the valley (trajectory_bend), and hold the truth (measured
    NEES 3.2 and 1.6 along one axis, 0.9 and 0.2 with the grid of the two major
    axes too since 2026-12-07, evening); the finding stays ``doubtful`` (3-D), and only beyond
    TRUST_LIMIT does it say that no Gaussian describes the posterior.
    """
    sim, model, init = _on_masts(run)
    m = sim.measurements
    laplace = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(sampled_covariance=False),
                               verify=False).primary
    x0, P0 = laplace.states[0], laplace.covariances[0]
    _, data = _posterior(m, model, float(laplace.times[0]), None, 0, 64)
    axis = probe_axis(P0)[0]
    assert 1.0 / float(axis @ _information(model, data, x0, None, P0) @ axis) < DETERMINISTIC_MIN

    out = fd.run_estimator("smoother", m, model, init, verify=False)
    found = [r for r in out.reasons if r.code == "nonlinear"]
    assert [r.status for r in found] == ["doubtful"], out.message
    assert "process noise sets most of the variance" in found[0].message
    assert re.search(r"track accounts for 0\.\d\d of it", found[0].message), found[0].message
    bend = re.search(r"raise the cost of a constant-velocity track (\S+) times", found[0].message)
    assert bend is not None and float(bend.group(1)) > CURVATURE_LIMIT
    assert ("no Gaussian covariance describes the posterior" in found[0].message) == (
        float(bend.group(1)) > spread.TRUST_LIMIT)
    assert "the cost profiled along the valley's floor at 5 Gauss-Hermite points" in found[0].message
    assert "and on a grid of 5 x 5 points along the position's two major axes" in found[0].message
    assert all(r.status == "ok" for r in out.reasons if r.code != "nonlinear"), out.message
    np.testing.assert_array_equal(out.primary.states, laplace.states)
    grown = np.concatenate([_whitened_eigenvalues(a, b) for a, b in zip(laplace.covariances,
                                                                          out.primary.covariances, strict=True)])
    assert grown.min() > 1.0 - 1e-9
    # what the finding warned of, and what the widening mends: the truth far outside the Laplace covariance, inside
    # the reported one
    err = out.primary.states - sim.truth.states
    late = out.primary.times >= 10.0

    def mean_nees(covariances: np.ndarray) -> float:
        return float(np.einsum("ki,ki->k", err, np.linalg.solve(covariances, err[..., None])[..., 0])[late].mean())

    assert mean_nees(laplace.covariances) > chi2.ppf(0.999, 6) > mean_nees(out.primary.covariances)



def test_in_3d_a_valley_that_bends_far_is_sampled_from_the_broad_proposal_too(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run 10 of the masts cell: sampled (the constant-velocity cost sets the variance), its probe ratio 7.6e3.

    Until 2026-12-07 (late) only the narrow proposal ran in 3-D: the truth's
    run-averaged NEES of the 6-D state was 40.1, beyond the chi-square 99.9 %
    point, with the covariances widened by the sampled spread and the profile
    of the valley both.  From the broad proposal, as in 2-D: 3.4.  The track
    itself does not change, and the finding stays ``doubtful`` (beyond
    TRUST_LIMIT, and 3-D).
    """
    sim, model, init = _on_masts(10)
    err_at = sim.truth.at

    def mean_nees(result: fd.TrackResult) -> float:
        e = result.primary
        late = e.times >= 10.0
        d = e.states[late] - err_at(e.times[late])
        return float(np.einsum("ki,ki->k", d, np.linalg.solve(e.covariances[late], d[..., None])[..., 0]).mean())

    broad = fd.run_estimator("smoother", sim.measurements, model, init, verify=False)
    said = _nonlinear(broad)
    assert "tempered from a proposal" in said and "bends far" in said, said
    assert [r.status for r in broad.reasons if r.code == "nonlinear"] == ["doubtful"]
    assert mean_nees(broad) < chi2.ppf(0.999, 6)
    monkeypatch.setattr(spread, "BEND_LIMIT", np.inf)
    monkeypatch.setattr(spread, "ESS_MIN", 0.0)
    monkeypatch.setattr(spread, "GROWTH_LIMIT", np.inf)
    narrow = fd.run_estimator("smoother", sim.measurements, model, init, verify=False)
    assert "tempered from a proposal" not in _nonlinear(narrow)
    np.testing.assert_array_equal(narrow.primary.states, broad.primary.states)  # only the covariance changes
    assert mean_nees(narrow) > chi2.ppf(0.999, 6)

def test_the_sampled_costs_information_is_its_curvature() -> None:
    """Gauss–Newton information of the constant-velocity cost against its second differences, per axis and mixed.

    At the smoother's first state (residuals of noise size, so their own
    curvature adds little) and steps of 0.3 standard deviations: measured
    agreement 0.06 % on the axes.  (With the Huber loss the rows weigh
    min(1, k/|r|), the smoother's IRLS weights, not the loss's second
    derivative, which is 0 beyond k.)
    """
    huber_k = None
    m, model, init = _precise()
    e = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(sampled_covariance=False),
                         verify=False).primary
    x0, P0 = e.states[0], e.covariances[0]
    post, data = _posterior(m, model, float(e.times[0]), huber_k, 0, 64)

    def cost(x: np.ndarray) -> float:
        return float(-2.0 * post.loglik(x[None], data.t, data.pair, data.z, data.sigma)[0])

    info = _information(model, data, x0, huber_k, np.full((4, 4), np.nan))
    assert np.all(np.isfinite(info))
    steps = 0.3 * np.sqrt(np.diag(P0)) * np.eye(4)
    for u in [*steps, steps[0] + steps[3], steps[1] - steps[2]]:
        second = 0.5 * (cost(x0 + u) - 2.0 * cost(x0) + cost(x0 - u))
        assert second == pytest.approx(u @ info @ u, rel=1e-2)


@pytest.mark.parametrize("sigma", [0.05, 0.1, 0.2])
def test_precise_doppler_keeps_the_smoothers_laplace_covariance(sigma: float) -> None:
    """Where the process noise, not the data, sets the smoother's spread: no samples.

    With sigma 0.05 m/s the process noise since the first measurement (q =
    1e-3 m²/s³: 3 m and 0.17 m/s of standard deviation after 30 s) is as
    large as what the data leave; along the probe's axis the constant-
    velocity cost accounts for 9 % of the smoother's variance (measured),
    below DETERMINISTIC_MIN.  Samples had been drawn (the probe, measuring
    that cost against the smoother's covariance, found it 11 times off) and
    made the last state's covariance up to 195 times the EKF's in variance,
    with Q(30 s) added on top; every filter's verdict was then 'doubtful' for
    a smoother "14 times less certain".  Now the smoother's last covariance
    is the EKF's — the same posterior in a near-linear problem, by an
    independent method — to 1 % (measured 0.999-1.003).

    With sigma 0.1 and 0.2 m/s the share is 0.32 and 0.81, above the limit,
    and the process noise's freedom still misled both tests that decide on
    sampling: measured against the smoother's covariance the constant-
    velocity cost looked 3 times steeper than quadratic (0.1 m/s: sampled),
    and the samples' mean, which sits at that cost's own minimum, lay 0.2-0.3
    standard deviations from the smoother's estimate (0.2 m/s: reported as a
    skewed posterior's mean); either way the carried samples made the EKF's
    verdict 'doubtful' (0 and 6 of 20 'ok').  Against the cost's own
    quadratic model and its own mode both find nothing.
    """
    m, model, init = _precise(sigma)
    laplace = fd.run_estimator("smoother", m, model, init, fd.SmootherSettings(sampled_covariance=False),
                               verify=False).primary
    x0, P0 = laplace.states[0], laplace.covariances[0]
    _, data = _posterior(m, model, float(laplace.times[0]), None, 0, 64)
    axis = probe_axis(P0)[0]
    share = 1.0 / float(axis @ _information(model, data, x0, None, P0) @ axis)
    assert share < DETERMINISTIC_MIN / 2 if sigma < 0.1 else share > DETERMINISTIC_MIN
    assert posterior_spread(m, model, laplace.times, laplace.states, laplace.covariances) is None
    results = fd.run_estimators(["ekf", "smoother"], m, model, init)
    smoother, ekf = results["smoother"], results["ekf"]
    assert "nonlinear" not in [r.code for r in smoother.reasons]
    np.testing.assert_array_equal(smoother.primary.covariances, laplace.covariances)
    ratio = np.linalg.eigvals(np.linalg.solve(ekf.primary.covariances[-1], smoother.primary.covariances[-1])).real
    assert 0.99 < ratio.min() and ratio.max() < 1.01, ratio
    assert ekf.status == "ok", ekf.message


@pytest.mark.parametrize("ratio", [2.5, 3.1e4, 0.0, -0.62])
def test_the_probes_ratio_is_said_as_a_rise_or_as_a_fall_and_reads_back(ratio: float) -> None:
    # A ratio that is not positive is a step along the axis that lowers the cost (the estimate is not that cost's
    # minimum, as where the process noise moved the smoother's track off a straight one: ratios -2.4 to -0.6 on
    # 300 s recordings of studies/unsampled_profiles.py), not a rise "-0.62 times" the model's.  Either way the
    # ratio reads back from the words to the printed precision.
    said = spread._probe_text(ratio, "the cost")
    rise = re.search(r"raise the cost (\S+) times its quadratic model", said)
    fall = re.search(r"lower the cost below the estimate's \(ratio (\S+) to its quadratic model's rise\)", said)
    assert (rise is not None) == (ratio > 0.0) and (fall is not None) == (ratio <= 0.0)
    found = rise or fall
    assert found is not None and float(found.group(1)) == pytest.approx(ratio, rel=1e-3)
