"""Online re-initiation of the trackers: when it fires, what it changes, and that it stays online."""

from __future__ import annotations

from dataclasses import replace
from itertools import pairwise

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd
from benchmarks.bench_long import THREE_PAIRS
from fgdoppler.analysis.metrics import errors
from fgdoppler.estimators import restart
from fgdoppler.estimators.ambiguity import hypotheses
from fgdoppler.estimators.basin_screen import basin_screen
from fgdoppler.estimators.particle import RESCUE_EVENT, rescued
from fgdoppler.estimators.registry import hypotheses_of
from fgdoppler.estimators.restart import (
    DISAGREEMENT,
    GROWTH,
    MODE_MARGIN,
    SURPRISE,
    checkpoints,
    fresh_start,
    surprise_check,
    surprised,
)
from tests.conftest import benchmark_run


def _end_error(sim: fd.Simulation, res: fd.TrackResult) -> float:
    e = res.primary
    i = int(np.searchsorted(sim.truth.times, e.times[-1]))
    return float(np.sqrt(errors(e.states[-1], sim.truth.states[i])[0]))


def test_checkpoints_grow_geometrically_from_the_window() -> None:
    sim, _, init = benchmark_run(0, 0)
    m = sim.measurements
    t = np.sort(m.time)
    n0 = int(np.count_nonzero(t <= init.t_end))
    cps = checkpoints(m, init)
    assert cps and init.t_end < cps[0] and all(a < b for a, b in pairwise(cps))
    assert cps[-1] < m.scans().times[-1]
    # each checkpoint is the time of the measurement that brings the count to n0 * GROWTH^k
    counts = [int(np.count_nonzero(t <= c)) for c in cps]
    expected = [int(np.ceil(n0 * GROWTH**k)) for k in range(1, 40) if np.ceil(n0 * GROWTH**k) <= t.size]
    assert all(c >= e for c, e in zip(counts, expected, strict=False))
    assert len(cps) <= len(expected)


def test_a_lagging_gaussian_sum_restarts_and_recovers() -> None:
    # Run 32 of case a 5 km (benchmark seed 2026): all eight terms of the EKF's Gaussian sum lag kilometres
    # behind the maximum of their own posterior; the best fit of the first 7 s is 4.3 sigma away by the EKF's
    # covariance and the tracker restarts there.
    sim, model, init = benchmark_run(0, 32)
    m = sim.measurements
    plain = fd.run_estimator("ekf", m, model, init, fd.EKFSettings(restarts=False), verify=False)
    res = fd.run_estimator("ekf", m, model, init, verify=False)
    restarts = [e for e in res.events if "online re-initiation" in e.message]
    assert restarts, "the EKF did not restart"
    assert _end_error(sim, res) < 0.5 * _end_error(sim, plain)
    # the estimates before the first restart are the plain run's, to the bit: nothing in the past is rewritten
    t0 = restarts[0].time
    before = plain.primary.times < t0
    np.testing.assert_array_equal(res.primary.times[: np.count_nonzero(before)], plain.primary.times[before])
    np.testing.assert_array_equal(res.primary.states[: np.count_nonzero(before)], plain.primary.states[before])


def test_restarts_stay_online() -> None:
    # The estimate at t must not depend on data after t: cutting the recording at 20 s changes nothing before it.
    sim, model, init = benchmark_run(0, 32)
    m = sim.measurements
    cut = 20.0
    full = fd.run_estimator("ekf", m, model, init, verify=False)
    part = fd.run_estimator("ekf", m.subset(m.time <= cut), model, init, verify=False)
    sel = full.primary.times <= cut
    np.testing.assert_array_equal(part.primary.times, full.primary.times[sel])
    np.testing.assert_allclose(part.primary.states, full.primary.states[sel], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(part.primary.covariances, full.primary.covariances[sel], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("estimator", ["ekf", "fixed-lag", "particle", "map"])
def test_a_well_observed_track_never_restarts(estimator: str) -> None:
    # case a 45 km: the trackers sit on the best fit of the data; the restart test changes nothing at all
    sim, model, init = benchmark_run(2, 0)
    m = sim.measurements
    settings = fd.ESTIMATORS[estimator].settings
    plain = fd.run_estimator(estimator, m, model, init, settings(restarts=False), verify=False)
    res = fd.run_estimator(estimator, m, model, init, verify=False)
    assert not [e for e in res.events if "online re-initiation" in e.message]
    for a, b in zip(res.estimates, plain.estimates, strict=True):
        np.testing.assert_array_equal(a.states, b.states)
        np.testing.assert_array_equal(a.covariances, b.covariances)


def _slow_run(seed: int, sampler_seed: int = 0) -> tuple[fd.Simulation, fd.TrackResult, fd.TrackResult]:
    # the slow 7 m/s target of the long-run benchmark, on its three pairs, for 120 s
    scen = fd.Scenario(geometry=THREE_PAIRS, x0=(15e3, 8e3, 5.0, 5.0), duration=120.0, dt=0.5, name="slow")
    sim = fd.simulate(scen, np.random.default_rng(seed))
    m = sim.measurements
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(m.first_per_pair(10), model)
    plain = fd.run_estimator("ekf", m, model, init, fd.EKFSettings(restarts=False, seed=sampler_seed), verify=False)
    return sim, plain, fd.run_estimator("ekf", m, model, init, fd.EKFSettings(seed=sampler_seed), verify=False)


def _rmse(sim: fd.Simulation, res: fd.TrackResult) -> float:
    e = res.primary
    return float(np.sqrt(np.mean(errors(e.states, sim.truth.at(e.times))[0])))


def test_a_mode_barely_better_than_the_trackers_own_does_not_displace_it() -> None:
    # Seed 0: at 11 s a fresh initiation finds a mode 23 km from the truth whose cost is only 1.7 below the EKF's
    # own basin (likelihood ratio 2.3, not the 1,000 of MODE_MARGIN), and at 37.5 s a fit less certain than the
    # EKF; when the lower cost always won and the fit was judged by the EKF's covariance alone, the EKF jumped
    # to both and its RMSE went from 2.3 km to 7.6 km.  Now neither may move it: the run is the plain run's.
    _, plain, res = _slow_run(0)
    assert not [e for e in res.events if "online re-initiation" in e.message]
    np.testing.assert_array_equal(res.primary.states, plain.primary.states)
    np.testing.assert_array_equal(res.primary.covariances, plain.primary.covariances)


def test_a_decisively_better_fit_restarts_the_slow_track() -> None:
    # Seed 3 of the same recording with sampler seed 0, the first of the study below: the EKF restarts and its RMSE
    # falls from 7.4 to 2.8 km (measured 2026-12-01; sampler seeds 1-3 fire too, seed 4 does not).
    sim, plain, res = _slow_run(3, 0)
    assert any("online re-initiation" in e.message for e in res.events)
    assert _rmse(sim, res) < 0.85 * _rmse(sim, plain)


# Eight sampled starts (30 s on one core): run with -m slow; by default the test above checks the first.
@pytest.mark.slow
def test_a_decisively_better_fit_still_restarts_the_slow_track() -> None:
    # Seed 3 of the same recording: the EKF, started from a sampled Gaussian sum, ends up far from the best fit of
    # the data so far by both covariances, and restarting there cuts its error, so the guards have not switched
    # restarts off.  How much depends on the sampled start: with sampler seeds 0-7 restarts fired in 6 of 8 runs,
    # RMSE 7.4 -> 2.8, 8.7 -> 7.0, 8.4 -> 6.6, 13.8 -> 3.8, 8.6 -> 7.0 and 5.5 -> 8.8 km (seed 6 the worse for
    # it: a restart at 25 s to a fit of the data so far 17.8 km off, which the data favour by little,
    # docs/concepts.md); the RMS over the eight runs 8.1 -> 5.8 km (0.72), over seeds 8-15 7.8 -> 5.8 km (0.75;
    # over 12-15 alone 0.93, so not four seeds).
    with_restarts, without, fired = [], [], 0
    for sampler_seed in range(8):
        sim, plain, res = _slow_run(3, sampler_seed)
        fired += any("online re-initiation" in e.message for e in res.events)
        with_restarts.append(_rmse(sim, res))
        without.append(_rmse(sim, plain))
    assert fired >= 4
    assert np.sqrt(np.mean(np.square(with_restarts))) < 0.85 * np.sqrt(np.mean(np.square(without)))


def test_mode_margin_is_the_disagreement_level_as_a_likelihood_ratio() -> None:
    # sum r^2 is -2 log-likelihood, so a cost margin D is a likelihood ratio exp(D / 2) = 1 / (1 - DISAGREEMENT)
    assert np.exp(MODE_MARGIN / 2.0) == pytest.approx(1.0 / (1.0 - DISAGREEMENT), rel=1e-12)


def test_restarts_setting_is_checked() -> None:
    with pytest.raises(ValueError, match="restarts"):
        fd.EKFSettings(restarts=1)  # type: ignore[arg-type]


def test_a_restart_keeps_to_the_users_half_plane() -> None:
    # All sensors on y = 0: a track and its mirror image fit the data exactly alike.  A tracker that has
    # drifted onto the mirror side sits in a basin as good as the truth's, so without the half plane the
    # checkpoint sees nothing to correct; given the half plane (as the first initiation was) the fresh
    # start and the running estimate's basin are held to the user's side, and the tracker restarts there.
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)),
                           fd.BistaticPair(tx=(60e3, 0.0), rx=(0.0, 0.0))))
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(42e3, 4e3, -60.0, -80.0), duration=20.0, sigma=0.5),
                      np.random.default_rng(0))
    m, model = sim.measurements, fd.TrackingModel.of(g)
    north = fd.HalfPlane(point=(0.0, 0.0), normal=(0.0, 1.0))
    tc = 10.0
    truth = sim.truth.at(np.array([tc]))[0]
    mirror = truth * np.array([1.0, -1.0, 1.0, -1.0])
    P = np.diag([200.0, 200.0, 2.0, 2.0]) ** 2
    assert fresh_start(m, model, fd.EKFSettings(), (mirror, P), tc) is None
    fresh = fresh_start(m, model, fd.EKFSettings(), (mirror, P), tc, half_plane=north)
    assert fresh is not None
    new, message = fresh
    assert "restarts" in message and new.half_plane == north
    assert new.x_end[1] > 0 and np.hypot(*(new.x_end[:2] - truth[:2])) < 1e3
    # the mirror-side running estimate is not carried into the restart as a hypothesis of its own
    assert all(a.state[1] > 0 for a in new.alternatives)
    # a running estimate on the user's side stands
    assert fresh_start(m, model, fd.EKFSettings(), (truth, P), tc, half_plane=north) is None


def test_a_restart_carries_the_running_estimate_along() -> None:
    # Run 32 of case a 5 km restarts at its first checkpoint.  The restart's start holds the fit of the data so
    # far and, as one more solution, the running estimate carried back to the fit's window start, with its data
    # cost over the same measurements on the fit's own scale: the restarted tracker weighs the two by the data.
    sim, model, init = benchmark_run(0, 32)
    m = sim.measurements
    plain = fd.run_estimator("ekf", m, model, init, fd.EKFSettings(restarts=False), verify=False)
    tc = checkpoints(m, init)[0]
    old = restart._state_at(plain, tc)
    assert old is not None
    fresh = fresh_start(m, model, fd.EKFSettings(), old, tc)
    assert fresh is not None
    new, message = fresh
    assert "carrying its running estimate along" in message
    carried = new.alternatives[-1]
    F = model.motion.F(tc - new.t_start)
    np.testing.assert_allclose(F @ carried.state, old[0], rtol=1e-12, atol=1e-6)
    assert carried.covariance is not None
    np.testing.assert_allclose(F @ carried.covariance @ F.T, old[1], rtol=1e-9, atol=1e-9)
    data = m.subset(m.time <= tc)
    # the numpy cost of the carried state and the fit's own (GTSAM graph) cost are one scale: the fit's state
    # costs its reported cost there
    assert restart._cost(model, new.x_start, new.t_start, data, None) == pytest.approx(new.cost, rel=1e-6)
    assert carried.cost > new.cost
    # as one solution among the fit's, it is a hypothesis of its own (where the window is Gaussian enough)
    copy = hypotheses(new)[-1]
    np.testing.assert_allclose(copy.x_end, old[0], rtol=1e-12, atol=1e-6)
    # here the fit's window is non-Gaussian and the EKF restarts from a Gaussian sum of its sampled posterior,
    # which the carried estimate also proposes from: most of the sum's weight (0.63-0.88 with sampler seeds
    # 0-2) lies in terms whose 99.9 % region holds the running estimate
    assert any(r.code == "nonlinear" and r.status != "ok" for r in new.reasons)
    hyps, weights = hypotheses_of("ekf", data, model, new, fd.EKFSettings())
    held = [float((h.x_end - old[0]) @ np.linalg.solve(h.P_end, h.x_end - old[0])) < chi2.ppf(DISAGREEMENT, 4)
            for h in hyps]
    assert float(np.sum(weights[held])) > 0.5
    # where the fit's solutions have their shares of the window's posterior, the carried estimate's share
    # stands to the fit's as the data's likelihood ratio exp(-(c_o - c_b) / 2)
    with_shares = replace(new, alternatives=new.alternatives[:-1], log_evidence=-12.5)
    x_back = np.linalg.solve(F, old[0])
    again = restart._running_estimate(model, with_shares, x_back, old[1], carried.cost, tc, None)
    assert again is not None and again.log_evidence is not None
    shares = replace(with_shares, alternatives=(again,)).posterior_shares()
    assert shares is not None
    assert shares[1] / shares[0] == pytest.approx(np.exp(-0.5 * (carried.cost - new.cost)), rel=1e-9)


def test_the_offsets_share_of_a_restarted_track_is_that_of_the_runs_it_is_spliced_from() -> None:
    # Run 32 of case a 5 km restarts once, at its first checkpoint.  The calibration offsets' share of its
    # covariances is what the offsets do to the track it reports: before the restart what they do to the first
    # run, after it what they do to the restarted run, each the share that run has alone (no restarts of its own).
    # (It was the first run's share throughout, a track the tracker no longer reports after the checkpoint.)
    sim, model, init = benchmark_run(0, 32)
    m = sim.measurements
    declared = fd.EKFSettings(bias_sigma=0.3)

    def share(start: fd.Initiation, settings: fd.EKFSettings) -> fd.Estimates:
        without = fd.run_estimator("ekf", m, model, start, replace(settings, bias_sigma=0.0), verify=False)
        res = fd.run_estimator("ekf", m, model, start, settings, verify=False)
        np.testing.assert_array_equal(res.primary.states, without.primary.states)
        return replace(res.primary, covariances=res.primary.covariances - without.primary.covariances)

    tc = checkpoints(m, init)[0]
    reported = share(init, declared)
    first = share(init, replace(declared, restarts=False))
    old = restart._state_at(fd.run_estimator("ekf", m, model, init, fd.EKFSettings(restarts=False), verify=False), tc)
    fresh = fresh_start(m, model, declared, old, tc)
    assert fresh is not None
    restarted = share(fresh[0], replace(declared, restarts=False))
    before = reported.times < tc
    after = restarted.times >= tc
    np.testing.assert_array_equal(reported.times, np.concatenate([first.times[first.times < tc],
                                                                  restarted.times[after]]))
    np.testing.assert_allclose(reported.covariances[before], first.covariances[first.times < tc],
                               rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(reported.covariances[~before], restarted.covariances[after], rtol=1e-9, atol=1e-9)
    # and it is a share, not nothing: the offsets move the restarted track by tens of metres at least
    assert np.all(np.trace(reported.covariances[~before][:, :2, :2], axis1=1, axis2=2) > 10.0**2)


def _rotated(g: fd.Geometry, angle: float, shift: tuple[float, float]) -> fd.Geometry:
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s], [s, c]])
    return fd.Geometry(pairs=tuple(fd.BistaticPair(tx=R @ np.array(p.tx) + shift, rx=R @ np.array(p.rx) + shift)
                                   for p in g.pairs), name=g.name)


def test_the_trackers_of_one_call_share_their_fresh_fits(monkeypatch: pytest.MonkeyPatch) -> None:
    # Step 1 of a check (the fit of all data up to the checkpoint) does not depend on the tracker: in
    # run_estimators the EKF and the fixed-lag smoother (iSAM2 alike) compute each checkpoint's fit once (and,
    # where a check calls for a restart, its fit under the Huber loss once: restart._pulled),
    # and their tracks are those of one run_estimator call each, to the bit.  Run 32 of case a 5 km (the EKF
    # restarts there), with the geometry rotated and moved 830 km, so that every tracker computes in the
    # geometry's own frame and the fits are shared through one local model.
    sim, _, _ = benchmark_run(0, 32)
    m = sim.measurements
    g = _rotated(sim.scenario.geometry, 0.37, (3.2e5, -7.7e5))
    init = fd.initiate(m.first_per_pair(10), g)
    calls: list[tuple[float, float]] = []  # (checkpoint, Huber threshold or 0 for the squared loss) of each fit
    fit = restart._fresh_fit

    def counted(*args: object) -> object:
        calls.append((float(args[-1]), float(args[2] or 0.0)))  # type: ignore[arg-type]
        return fit(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(restart, "_fresh_fit", counted)
    names = ("ekf", "fixed-lag")
    alone = {n: fd.run_estimator(n, m, g, init, verify=False) for n in names}
    alone_calls = list(calls)
    calls.clear()
    shared = fd.run_estimators(names, m, g, init, verify=False)
    assert any("online re-initiation" in e.message for e in alone["ekf"].events)
    assert sorted(calls) == sorted(set(alone_calls)) and len(alone_calls) == 2 * len(calls) > 0
    assert any(k > 0 for _, k in calls)  # the restart's check fitted under the Huber loss too, shared as well
    for n in names:
        a, b = alone[n], shared[n]
        assert [e.kind for e in a.estimates] == [e.kind for e in b.estimates]
        for ea, eb in zip(a.estimates, b.estimates, strict=True):
            np.testing.assert_array_equal(eb.states, ea.states)
            np.testing.assert_array_equal(eb.covariances, ea.covariances)
        assert b.status == a.status and [e.message for e in b.events] == [e.message for e in a.events], n


def test_fresh_fits_serve_one_recording() -> None:
    sim, model, _ = benchmark_run(0, 0)
    fits = restart.FreshFits(sim.measurements)
    other = sim.measurements.subset(sim.measurements.time <= 20.0)
    with pytest.raises(ValueError, match="one recording"):
        fits.fit(other, model, None, None, 10.0)
    first = fits.fit(sim.measurements, model, None, None, 10.0)
    assert first is not None and fits.fit(sim.measurements, model, None, None, 10.0) is first
    assert fits.computed == 1
    assert fits.local_model(model) is fits.local_model(model)


def _with_nis(nis: list[tuple[float, int, float, bool]]) -> fd.TrackResult:
    sim, model, init = benchmark_run(2, 0)
    res = fd.run_estimator("ekf", sim.measurements, model, init, fd.EKFSettings(restarts=False), verify=False)
    return replace(res, nis=np.array(nis, dtype=float).reshape(-1, 4))


def test_surprise_is_a_nis_sum_beyond_the_chi_square_quantile() -> None:
    # Surprised when the NIS of the n measurements in (t_from, t_to], kept or rejected, sum beyond the
    # chi-square(n) quantile at SURPRISE; rows at t_from or after t_to do not count (were they counted, their
    # 1e6 would surprise it), and neither do rows whose NIS is not finite.
    n = 11
    q = chi2.ppf(SURPRISE, n)
    outside = [(10.0, 0, 1e6, False)] * 3 + [(30.0, 1, 1e6, False)] * 3 + [(12.5, 0, np.nan, False)]
    for scale, expected in ((1.001, True), (0.999, False)):
        inside = [(11.0 + k, k % 2, scale * q / n, k % 3 > 0) for k in range(n)]
        assert surprised(_with_nis(inside + outside), 10.0, 22.0) is expected
    # one measurement far off among many is a surprise: the sum sees it, whatever the others do
    assert surprised(_with_nis([(11.0, 0, 1e3, False)] + [(12.0 + k, 1, 0.0, True) for k in range(n - 1)]),
                     10.0, 22.0)
    assert not surprised(_with_nis([]), 0.0, 100.0)
    # a checkpoint beyond the span is never tested, however surprising the data
    loud = _with_nis([(5.0, 0, 1e6, False), (15.0, 0, 1e6, False)])
    check = surprise_check(0.0, 10.0)
    assert check(loud, 0.0, 10.0) and not check(loud, 10.0, 20.0)
    # made at every checkpoint: however quiet the data, within the span and not beyond it
    quiet = _with_nis([(5.0, 0, 0.0, True), (15.0, 0, 0.0, True)])
    assert not check(quiet, 0.0, 10.0)
    every = surprise_check(0.0, 10.0, every=True)
    assert every(quiet, 0.0, 10.0) and not every(quiet, 10.0, 20.0) and not every(loud, 10.0, 20.0)


def _gapped_recording(seed: int) -> tuple[fd.Simulation, fd.Measurements, fd.Geometry]:
    # Two pairs in general position (draw 23 of `studies/random_layouts.py`, rounded), 60 s at 2 Hz with 30 %
    # of the measurements after the initiation's window dropped and pair 2 silent from 25 to 35 s: the
    # "2-D gaps" cell of `studies/noisy_truth_layouts.py`.  Of noise seeds 0-15, the particle estimator
    # without restarts failed on seed 14 alone, 12.6 km off at the end.
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(-18318.0, 26625.0), rx=(-34132.0, 23298.0)),
                           fd.BistaticPair(tx=(-19181.0, 13556.0), rx=(-37145.0, -2928.0))))
    rng = np.random.default_rng(seed)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(-29393.0, 20184.0, -127.4, -53.2), duration=60.0, dt=0.5), rng)
    m = sim.measurements
    keep = rng.random(len(m)) > 0.3
    keep[:20] = True
    keep &= ~((m.pair == 1) & (m.time > 25.0) & (m.time < 35.0))
    return sim, m.subset(keep), g


@pytest.mark.parametrize("estimator", ["particle", "map"])
def test_a_lost_particle_estimator_restarts_and_recovers(estimator: str) -> None:
    # The window's posterior was sampled in the wrong basin and every particle stayed there, confident:
    # 12.6 km off, 53 m sigma, "failed".  The measurements up to the checkpoint at 20 s surprise it (their NIS
    # sum beyond its quantile), the best fit of all the data up to then lies 950-960 sigma away, and the restarted
    # estimator ends within 100 m.
    sim, m, g = _gapped_recording(14)
    init = fd.initiate(m.first_per_pair(10), g)
    settings = fd.ESTIMATORS[estimator].settings
    plain = fd.run_estimator(estimator, m, g, init, settings(restarts=False), verify=False)
    res = fd.run_estimator(estimator, m, g, init, verify=False)
    assert plain.status == "failed" and _end_error(sim, plain) > 10e3
    restarts = [e for e in res.events if "online re-initiation" in e.message]
    assert len(restarts) == 1 and restarts[0].time <= 40.0
    assert _end_error(sim, res) < 100.0 and res.status != "failed"
    # nothing before the restart is rewritten, and nothing after it is judged by data yet to come
    before = plain.primary.times < restarts[0].time
    np.testing.assert_array_equal(res.primary.states[: np.count_nonzero(before)], plain.primary.states[before])
    cut = fd.run_estimator(estimator, m.subset(m.time <= 45.0), g, init, verify=False)
    sel = res.primary.times <= 45.0
    np.testing.assert_array_equal(cut.primary.states, res.primary.states[sel])


def _rescued_into_a_wrong_basin() -> tuple[fd.Simulation, fd.TrackingModel, fd.Initiation]:
    """Draw 13 of ``studies/random_layouts_3d.py`` (three ground pairs, an aircraft at 2.2 km), its first 20 s: the
    draw's own values and the state of its generator after the draw, which then simulates the recording."""
    pairs = [((19766.745318357025, 6051.519996135663, 0.0), (25604.22099336596, 12427.324875802922, 0.0)),
             ((32153.77258491247, -28046.777630875964, 0.0), (-12819.153831500465, 2699.666506220259, 0.0)),
             ((-1337.33219951942, -32175.520055453577, 0.0), (-30326.32136317454, 14555.26886384809, 0.0))]
    x0 = (19729.119058101474, -6019.396741805518, 2153.041765623383, 4.486660161304062, -65.4157403431881,
          3.3219061713037044)
    sim, g, init = _layout_3d_recording(pairs, x0, (1192146049, 207639287032345122370115077018470011005,
                                                     233476570586696911600097664360034763769), 20.0)
    return sim, fd.TrackingModel.of(g), init


def _layout_3d_recording(pairs: list[tuple[tuple[float, ...], tuple[float, ...]]], x0: tuple[float, ...],
                         state: tuple[int, int, int], duration: float
                         ) -> tuple[fd.Simulation, fd.Geometry, fd.Initiation]:
    """A draw of ``studies/random_layouts_3d.py`` rebuilt from its pairs, start and its generator's PCG64 state
    after the draw (``uinteger``, ``state``, ``inc``): the recording of ``duration`` s and its initiation."""
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = {"bit_generator": "PCG64", "has_uint32": 1, "uinteger": state[0],
                               "state": {"state": state[1], "inc": state[2]}}
    g = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=tx, rx=rx) for tx, rx in pairs))
    sim = fd.simulate(fd.Scenario(geometry=g, x0=x0, duration=duration, dt=0.5), rng)
    return sim, g, fd.initiate(sim.measurements.first_per_pair(10), fd.TrackingModel.of(g))


def test_a_rescue_arms_the_next_checkpoints_test() -> None:
    # At the window's end (4.5 s) the particle estimator's particles miss a peak of the posterior far higher than
    # the best of them, 9 km from the truth, and are sampled again about it.  There the data that follow do not
    # surprise them, nor does any start's basin fit the data better (the screen): left alone the run stays 8.6 km
    # off at the end, its final state 145,000 in squared Mahalanobis distance from the truth.  The rescue arms the
    # test at the next checkpoint (7 s), which restarts it from the best fit of the data so far.
    sim, model, init = _rescued_into_a_wrong_basin()
    tc = checkpoints(sim.measurements, init)[0]
    plain = fd.run_estimator("particle", sim.measurements, model, init, fd.ParticleSettings(restarts=False),
                             verify=False)
    # rescued at the window's end (4.5 s) and at 5 s: both before the first checkpoint, none after it
    said = [ev.time for ev in plain.events if ev.message.startswith(RESCUE_EVENT)]
    assert said == [init.t_end, init.t_end + 0.5]
    assert rescued(plain, init.t_end, tc) and not rescued(plain, tc, sim.measurements.time[-1])
    at_end = tuple(ev for ev in plain.events if ev.time <= init.t_end)
    assert rescued(replace(plain, events=at_end), init.t_end, tc)  # the window's end alone counts
    assert rescued(plain, init.t_end + 0.5, init.t_end + 0.5)  # closed at both ends
    assert not surprised(plain, init.t_end, tc)
    e = plain.primary
    i = int(np.searchsorted(e.times, tc))
    assert e.times[i] == tc and not basin_screen(sim.measurements, model, init, MODE_MARGIN)(e.states[i], tc)
    assert surprise_check(init.t_start, 300.0, armed=rescued)(plain, init.t_end, tc)
    assert not surprise_check(init.t_start, 300.0)(plain, init.t_end, tc)
    res = fd.run_estimator("particle", sim.measurements, model, init, verify=False)
    restarts = [ev.time for ev in res.events if "online re-initiation" in ev.message]
    assert restarts == [tc]
    before, after = (_final_m2(r, sim) for r in (plain, res))
    assert before > 1e4 and after < before / 100
    assert _end_error(sim, res) < _end_error(sim, plain) - 1000.0


def _final_m2(res: fd.TrackResult, sim: fd.Simulation) -> float:
    e = res.primary
    d = e.states[-1] - sim.truth.at(e.times[-1:])[0]
    return float(d @ np.linalg.solve(e.covariances[-1], d))


@pytest.mark.parametrize(("estimator", "seed"), [("ekf", 3), ("isam2", 3), ("fixed-lag", 3), ("particle", 0),
                                               ("particle", 2)])
def test_a_few_outliers_do_not_restart_a_tracker(estimator: str, seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # 5 % of the measurements moved by +-100 sigma, squared loss (a verdict case of test_verdict.py): the
    # estimators reject them by their gate or likelihood and end 3-17 m (seed 3), 58 m and 88 m (particle,
    # seeds 0 and 2) from the truth.  The outliers pull the check's squared-loss fit 19-182 sigma from the fit
    # under the Huber loss, so the check is decided under the Huber loss, whose fit agrees with the running
    # estimate: no restart.  With the squared-loss check alone they restarted onto fits the outliers had pulled
    # and ended 239-1,102 m (seed 3) and 829 m and 1,042 m off.  The NIS sum that tests the particle estimators is
    # set off by the outliers, so their check does run.
    from tests.estimators.test_verdict import CASES

    sim, g, m, _ = CASES["5 % outliers, Gaussian loss"](seed)
    init = fd.initiate(m.first_per_pair(10), g)
    settings = fd.ESTIMATORS[estimator].settings
    plain = fd.run_estimator(estimator, m, g, init, settings(restarts=False), verify=False)
    res = fd.run_estimator(estimator, m, g, init, verify=False)
    assert np.any(res.nis[:, 3] == 0)  # the outliers were there and rejected
    if estimator == "particle":
        ends = [init.t_end, *checkpoints(m, init)]
        assert any(surprised(plain, t_from, t_to) for t_from, t_to in pairwise(ends))
    assert not [e for e in res.events if "online re-initiation" in e.message]
    np.testing.assert_array_equal(res.primary.states, plain.primary.states)
    assert _end_error(sim, res) < 200.0
    monkeypatch.setattr(restart, "EFFICIENT_K", None)  # the robust fit is the squared-loss one: never pulled
    pulled = fd.run_estimator(estimator, m, g, init, verify=False)
    assert [e for e in pulled.events if "online re-initiation" in e.message]
    assert _end_error(sim, pulled) > 4.0 * _end_error(sim, res) + 100.0


def test_on_gaussian_data_the_robust_fit_leaves_a_restart_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    # Case a 5 km, run 36 of the accuracy benchmark (seed 2026): the EKF restarts at 7 s, 4.5 sigma from the
    # best fit (the threshold: 4.3).  The fit under the Huber loss lies 0.3 sigma from the squared-loss one, so
    # the squared-loss check stands.  Deciding every restart under the Huber loss too vetoed this one, and the
    # run's RMSE went from 1,063 m to 1,288 m.
    sim, model, init = benchmark_run(0, 36)
    res = fd.run_estimator("ekf", sim.measurements, model, init, verify=False)
    assert [e for e in res.events if "online re-initiation" in e.message]
    monkeypatch.setattr(restart, "EFFICIENT_K", None)
    squared = fd.run_estimator("ekf", sim.measurements, model, init, verify=False)
    np.testing.assert_array_equal(res.primary.states, squared.primary.states)


def test_in_space_map_tests_every_checkpoint_and_leaves_a_basin_nothing_else_flagged() -> None:
    # Draw 39 of `studies/random_layouts_3d.py` (four ground pairs, an aircraft at 1.4 km), 60 s: the draw's own
    # values and the state of its generator after the draw.  Tested only where something called for it, `map`
    # settles in a wrong basin that no later measurement surprises and no start of the initiation's beats: it
    # ends 1.7 km from the truth, 97 in squared Mahalanobis distance.  The fresh fit of all the data so far,
    # made at every checkpoint in space (`MapSettings.check_every`), finds the truth's basin at 37.5 s.
    pairs = [((-39167.64357977596, 17434.73223612184, 0.0), (29416.409856075406, -16762.843365903467, 0.0)),
             ((9365.392246144984, -23019.795142096875, 0.0), (-33091.734561023724, -2047.8620643472095, 0.0)),
             ((-7532.245439847429, -9154.247289074534, 0.0), (13718.041769938543, -20570.116828679667, 0.0)),
             ((21601.224184187762, 1812.0407716772315, 0.0), (-24946.672843768225, -30475.664805331267, 0.0))]
    x0 = (-6167.808612590219, -21188.088177166457, 1354.77059973945, -78.72772163119116, 7.288210963512285,
          -3.7844359648105494)
    sim, g, init = _layout_3d_recording(pairs, x0, (1369611075, 74454217517471840705027492217964001978,
                                                     292360484278955852132246029368796412709), 60.0)
    assert fd.MapSettings().checks_every(3)
    quiet = fd.run_estimator("map", sim.measurements, g, init, fd.MapSettings(check_every=False), verify=False)
    res = fd.run_estimator("map", sim.measurements, g, init, verify=False)
    assert not [e for e in quiet.events if "online re-initiation" in e.message]
    restarts = [e.time for e in res.events if "online re-initiation" in e.message]
    assert len(restarts) == 1
    limit = chi2.ppf(0.999, 6)
    assert _final_m2(quiet, sim) > limit and _end_error(sim, quiet) > 1000.0
    assert _final_m2(res, sim) < limit and _end_error(sim, res) < _end_error(sim, quiet) / 5
    # the estimates before the restart are the quiet run's: the checks only add a fresh fit of the data so far
    before = quiet.primary.times < restarts[0]
    np.testing.assert_array_equal(res.primary.states[: np.count_nonzero(before)], quiet.primary.states[before])
