"""The verdict: no wrong answer labelled ok in degenerate cases, no false alarms on consistent runs.

"Wrong" follows the issue: the final position error exceeds three times the
estimate's own reported standard deviation (the largest, along the
covariance's major axis).  A calibrated estimator does that in about 0.3-1 %
of runs by chance (measured with the robust loss on 5 % outliers: 1 run in
100, mean NEES 3.78); the degenerate cases below are about the kilometre
errors with metre-sized sigmas that a verdict must never call ok.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd

A = fd.paper_geometry("a")
SEEDS = (0, 1, 2)


def _sim(x0: tuple[float, float, float, float], *, duration: float = 30.0, sigma: float = 1.0,
         geometry: fd.Geometry = A, seed: int = 0) -> fd.Simulation:
    return fd.simulate(fd.Scenario(geometry=geometry, x0=x0, duration=duration, dt=0.5, sigma=sigma),
                       np.random.default_rng(seed))


def _outliers(m: fd.Measurements, seed: int) -> fd.Measurements:
    rng = np.random.default_rng(1000 + seed)
    z = m.doppler.copy()
    idx = rng.choice(len(m), round(0.05 * len(m)), replace=False)
    z[idx] += rng.choice([-100.0, 100.0], idx.size)
    return fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma)


PAPER = (45e3, 2e3, 10.0, -100.0)
Case = Callable[[int], tuple[fd.Simulation, fd.Geometry, fd.Measurements, float | None]]
CASES: dict[str, Case] = {
    "tangent to an ellipse": lambda s: (sim := _sim((25e3, 2e3, 100.0, 0.0), seed=s), A, sim.measurements, None),
    "along the baseline": lambda s: (sim := _sim((20e3, 0.0, 100.0, 0.0), seed=s), A, sim.measurements, None),
    "near a sensor": lambda s: (sim := _sim((2.5e3, 400.0, 80.0, 20.0), seed=s), A, sim.measurements, None),
    "outside the zone": lambda s: (sim := _sim((55e3, 3e3, -50.0, -20.0), seed=s), A, sim.measurements, None),
    "stationary": lambda s: (sim := _sim((25e3, 2e3, 0.0, 0.0), seed=s), A, sim.measurements, None),
    "5 % outliers, Gaussian loss": lambda s: (sim := _sim(PAPER, seed=s), A, _outliers(sim.measurements, s), None),
    "5 % outliers, Huber loss": lambda s: (sim := _sim(PAPER, seed=s), A, _outliers(sim.measurements, s), 1.345),
    "noise 50x the declared sigma": lambda s: (
        sim := _sim(PAPER, sigma=50.0, seed=s), A,
        fd.Measurements(time=sim.measurements.time, pair=sim.measurements.pair, doppler=sim.measurements.doppler,
                        sigma=np.ones(len(sim.measurements))), None),
    "times in milliseconds": lambda s: (
        sim := _sim(PAPER, seed=s),
        A, fd.Measurements(time=sim.measurements.time * 1e3, pair=sim.measurements.pair,
                           doppler=sim.measurements.doppler, sigma=sim.measurements.sigma), None),
    "geometry in kilometres": lambda s: (
        sim := _sim(PAPER, seed=s),
        fd.Geometry(pairs=tuple(fd.BistaticPair(tx=np.array(p.tx) / 1e3, rx=np.array(p.rx) / 1e3) for p in A.pairs)),
        sim.measurements, None),
    "one pair silent": lambda s: (sim := _sim(PAPER, seed=s), A, sim.measurements.subset(sim.measurements.pair == 0),
                                  None),
    "very few measurements": lambda s: (sim := _sim(PAPER, duration=1.5, seed=s), A, sim.measurements, None),
}


def _wrong(est: fd.Estimates, truth: np.ndarray) -> bool:
    """Final position error beyond three of the estimate's own standard deviations (major axis)."""
    if not est.cov_ok[-1]:
        return False  # no sigma claimed: an indeterminate covariance is a verdict finding of its own
    sd = float(np.sqrt(np.max(np.linalg.eigvalsh(est.covariances[-1][:2, :2]))))
    return bool(np.hypot(*(est.states[-1, :2] - truth[:2])) > 3.0 * sd)


#: The degenerate cases that take 30-40 s each (every estimator over several seeds): run with -m slow.
LONG_CASES = frozenset({"outside the zone", "times in milliseconds"})


def _degenerate_params() -> list[object]:
    """Every case on every seed; by default each case on its first seed (the rest, and the long cases, -m slow:
    each recording takes 5-15 s through every estimator, the whole grid about 200 s of the CI budget)."""
    return [pytest.param(c, seed, marks=pytest.mark.slow) if c in LONG_CASES or seed != SEEDS[0] else
            pytest.param(c, seed) for c in CASES for seed in SEEDS]


@pytest.mark.parametrize(("case", "seed"), _degenerate_params())
def test_degenerate_cases_are_never_wrong_and_ok(case: str, seed: int) -> None:
    failures = []
    sim, geometry, meas, huber = CASES[case](seed)
    truth_times = sim.truth.times * (1e3 if "milliseconds" in case else 1.0)
    truth = fd.Trajectory(times=truth_times, states=sim.truth.states)
    init = fd.initiate(meas.first_per_pair(10), geometry, fd.InitiationSettings(huber_k=huber))
    if init.P_end is not None and init.status == "ok":
        e = fd.Estimates(kind="filtered", times=np.array([init.t_end]), states=init.x_end[None],
                         covariances=init.P_end[None], cov_ok=np.array([True]))
        if _wrong(e, truth.at([init.t_end])[0]):
            failures.append("initiation")
    results = fd.run_estimators(fd.ESTIMATORS, meas, geometry, init,
                                {n: info.settings(huber_k=huber) for n, info in fd.ESTIMATORS.items()})
    for name, r in results.items():
        if r.status == "ok" and _wrong(r.primary, truth.at(r.primary.times[-1:])[0]):
            failures.append(name)
    assert not failures, failures


# 30 runs of every estimator per scenario (40 s each): long studies, run with -m slow
@pytest.mark.slow
@pytest.mark.parametrize(("case", "x"), [("a", 45e3), ("b", 5e3)])
def test_consistent_well_observed_runs_are_ok(case: str, x: float) -> None:
    # It must not cry wolf: in the well-observed scenarios every estimator is "ok" in >= 95 % of
    # clean runs (measured: 40 of 40 for every estimator, seed 99).
    scen = fd.paper_scenario(case, x)
    runs = 30
    ok = dict.fromkeys(fd.ESTIMATORS, 0)
    for seq in np.random.SeedSequence(99).spawn(runs):
        sim = fd.simulate(scen, np.random.default_rng(seq))
        init = fd.initiate(sim.measurements.first_per_pair(10), scen.geometry)
        ref = fd.run_estimator("smoother", sim.measurements, scen.geometry, init)
        ok["smoother"] += ref.status == "ok"
        for name in ok:
            if name != "smoother":
                ok[name] += fd.run_estimator(name, sim.measurements, scen.geometry, init,
                                             reference=ref).status == "ok"
    assert all(n >= 0.95 * runs for n in ok.values()), ok


def test_the_shared_reference_is_the_one_a_filter_would_run(monkeypatch: pytest.MonkeyPatch) -> None:
    # run_estimators runs the reference smoother once for all filters; each answer is run_estimator's own
    from dataclasses import replace

    import fgdoppler.estimators.registry as registry

    # 15 s of the recording: results of the same structure as with 30 s (one hypothesis, every estimator `ok`, the
    # same kinds of estimates each) in half the time (26-32 s for 30 s; the sharing does not depend on the length)
    scen = replace(fd.paper_scenario("a", 5e3), duration=15.0)
    sim = fd.simulate(scen, np.random.default_rng(3))
    m, g = sim.measurements, sim.scenario.geometry
    init = fd.initiate(m.first_per_pair(10), g)
    calls: list[str] = []
    run = registry._run_estimator  # every run, the public entry's and run_estimators' alike, goes through it

    def counted(name: str, *args, **kwargs) -> fd.TrackResult:
        calls.append(name)
        return run(name, *args, **kwargs)

    monkeypatch.setattr(registry, "_run_estimator", counted)
    alone = {n: registry.run_estimator(n, m, g, init) for n in fd.ESTIMATORS}
    smoother_runs_alone = calls.count("smoother")
    calls.clear()
    shared = fd.run_estimators(fd.ESTIMATORS, m, g, init)
    assert list(shared) == list(fd.ESTIMATORS)
    for n in fd.ESTIMATORS:
        assert shared[n].reasons == alone[n].reasons and shared[n].status == alone[n].status, n
        for a, b in zip(alone[n].estimates, shared[n].estimates, strict=True):
            np.testing.assert_array_equal(a.states, b.states)
    assert smoother_runs_alone == len(fd.ESTIMATORS) * calls.count("smoother")
    # a smoother with settings of its own is not the filters' reference: the default one runs as well
    calls.clear()
    other = fd.run_estimators(["smoother", "ekf"], m, g, init, {"smoother": fd.SmootherSettings(mode_search=False)})
    assert calls.count("smoother") == 2 and other["ekf"].reasons == alone["ekf"].reasons
    with pytest.raises(ValueError, match="not run"):
        fd.run_estimators(["ekf"], m, g, init, {"smoother": fd.SmootherSettings()})


def test_judge_findings_on_constructed_results() -> None:
    # A filter whose final state the smoother puts 10 of its sigmas away is doubtful ("reference");
    # one that rejects most of its measurements has failed ("rejections", "lost").
    from dataclasses import replace

    from fgdoppler.estimators.judge import judge

    sim = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(1))
    model = fd.TrackingModel.of(sim.scenario.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    ekf = fd.run_estimator("ekf", sim.measurements, model, init, verify=False)
    ref = fd.run_estimator("smoother", sim.measurements, model, init)
    assert judge(ekf, sim.measurements, model, fd.EKFSettings(), ref).status == "ok"
    shifted = ref.primary.states.copy()
    shifted[-1, 0] += 10 * np.sqrt(ekf.primary.covariances[-1][0, 0])
    moved = replace(ref, estimates=(replace(ref.primary, states=shifted),))
    far = judge(ekf, sim.measurements, model, fd.EKFSettings(), moved)
    assert far.status == "doubtful" and any(r.code == "reference" for r in far.reasons)
    nis = ekf.nis.copy()
    nis[: int(0.6 * len(nis)), 3] = 0  # 60 % rejected, all of the first part
    nis[-(len(nis) // 4):, 3] = 0  # and the last quarter
    lost = judge(replace(ekf, nis=nis), sim.measurements, model, fd.EKFSettings())
    assert lost.status == "failed" and {"rejections", "lost"} <= {r.code for r in lost.reasons}


def test_the_covariance_test_reads_the_reported_covariance_and_names_the_own_one() -> None:
    """Constructed on one recording: the smoother's covariance scaled by c is sqrt(c) times less certain (the
    generalised eigenvalue of c P against P is c); beyond :data:`COVARIANCE_RATIO` the reported covariance is
    ``doubtful``; a reported covariance widened to hold it, the own one still narrow, is an informational
    finding that names both; no finding where neither is beyond the ratio or the covariance is missing."""
    from dataclasses import replace

    from fgdoppler.estimators.judge import COVARIANCE_RATIO, covariance_reference

    sim = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(1))
    model = fd.TrackingModel.of(sim.scenario.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    e = fd.run_estimator("ekf", sim.measurements, model, init, verify=False).primary
    ref = replace(e, kind="smoothed")  # the same covariances: the ratio is 1
    assert covariance_reference(e, e, ref) == []

    def scaled(est: fd.Estimates, c: float) -> fd.Estimates:
        return replace(est, covariances=c * est.covariances)

    c = 9.0
    assert c > COVARIANCE_RATIO
    (found,) = covariance_reference(e, e, scaled(ref, c))
    assert (found.code, found.status) == ("reference", "doubtful") and "is 3.0 times less certain" in found.message
    (said,) = covariance_reference(scaled(e, c), e, scaled(ref, c))
    assert said.status == "ok" and "is 3.0 times less certain" in said.message and "is 1.0 times" in said.message
    assert covariance_reference(scaled(e, c), scaled(e, c), scaled(ref, c)) == []
    assert covariance_reference(e, e, scaled(ref, 0.99 * COVARIANCE_RATIO)) == []
    missing = replace(e, cov_ok=np.r_[e.cov_ok[:-1], False])
    assert covariance_reference(missing, missing, scaled(ref, c)) == []


def test_a_filter_whose_checks_widened_its_covariance_to_the_smoothers_is_not_called_doubtful_for_it() -> None:
    """Case b 45 km, run 28 of the accuracy benchmark's recordings (seed 2026): the EKF's own Gaussian
    covariance is 2.3 times narrower than the smoother's (standard deviation) at the last time, and the
    covariance test read on it called the answer ``doubtful``; its checks against posterior samples widen
    the covariance reported to within 1 of the smoother's, and the truth lies at a final NEES of 4.9 in it.
    Of 240 such runs (EKF and iSAM2, case a 5 km and b 45 km, 60 each) the test on the own covariance called
    28 consistent answers ``doubtful`` and caught no inconsistent one that nothing else caught."""
    from fgdoppler.estimators.judge import COVARIANCE_RATIO

    s, r = 5, 28
    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([2026, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    ref = fd.run_estimator("smoother", sim.measurements, model, init)
    ekf = fd.run_estimator("ekf", sim.measurements, model, init, reference=ref)
    e = ekf.primary
    P, Ps = e.covariances[-1], ref.primary.covariances[-1]
    assert np.max(np.real(np.linalg.eigvals(np.linalg.solve(P, Ps)))) <= COVARIANCE_RATIO
    d = e.states[-1] - sim.truth.at(e.times[-1:])[0]
    assert d @ np.linalg.solve(P, d) < chi2.ppf(0.999, 4)
    (said,) = [f for f in ekf.reasons if f.code == "reference" and "less certain" in f.message]
    assert said.status == "ok" and "own Gaussian covariance" in said.message
    assert ekf.status == "ok", [f.message for f in ekf.reasons if f.status != "ok"]


def test_the_reference_finding_carries_the_smoothers_advice() -> None:
    """A doubtful offline smoother's findings reach the filter as one ``reference`` finding: its zone is the union
    of the advised zones, its mirror the line of the worst findings' (the reporting pairs' before every sensor's),
    both only from the findings that set the smoother's status."""
    from dataclasses import replace

    from fgdoppler.estimators.judge import judge
    from fgdoppler.estimators.verdict import Reason
    from fgdoppler.zone import ZoneBox

    sim = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(1))
    model = fd.TrackingModel.of(sim.scenario.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    ekf = fd.run_estimator("ekf", sim.measurements, model, init, verify=False)
    ref = fd.run_estimator("smoother", sim.measurements, model, init)
    a = ZoneBox(along=(0.0, 10e3), across=(-1e3, 1e3), speed_max=300.0)
    b = ZoneBox(along=(5e3, 20e3), across=(-3e3, 0.0), speed_max=250.0)

    def wrapped(*said: Reason) -> Reason:
        out = judge(ekf, sim.measurements, model, fd.EKFSettings(), replace(ref, reasons=said))
        (found,) = [r for r in out.reasons if r.code == "reference" and "offline smoother" in r.message]
        return found

    found = wrapped(Reason(code="zone", status="doubtful", message="z", zone=a),
                    Reason(code="competing", status="doubtful", message="m", mirror="sensors"),
                    Reason(code="boundary", status="doubtful", message="w", zone=b))
    assert found.zone == a.union(b) and found.mirror == "sensors"
    found = wrapped(Reason(code="competing", status="doubtful", message="m", mirror="sensors"),
                    Reason(code="data", status="doubtful", message="d", mirror="reporting"))
    assert found.zone is None and found.mirror == "reporting"
    # an informational finding does not set the status and advises nothing
    found = wrapped(Reason(code="zone", status="doubtful", message="z"),
                    Reason(code="competing", status="ok", message="m", zone=a, mirror="sensors"))
    assert found.zone is None and found.mirror is None


def test_a_track_confidently_elsewhere_for_a_while_is_doubtful_though_it_ends_well() -> None:
    """The ``reference`` finding over the whole track, not only its last state.

    Constructed: the smoother's track moved by 10 of the EKF's sigmas
    (Mahalanobis) over the middle third of the times (its last state
    untouched) makes the EKF doubtful, by the mean of the per-time
    chi-squares (about 100 x 17 / 52); moved at two times only (about
    100 x 2 / 52), the mean stays below the chi-square quantile, 18.5.  Real: three pairs
    around a 40 x 30 km area, seed 4: the EKF ran 9-12 km from the truth
    from 12 to 25 s, restarted at 25 s and ended 0.24 km from the truth.
    With sampler seed 0 its covariances there (position sigma 0.5-0.7 km,
    truth NEES 1e5) miss the error — 'ok' before this finding, as its final
    state agrees with the smoother's; with seed 1 the sampled checks widen
    them to hold it (median truth NEES 2.2, in 6 of seeds 0-7 they do not)
    and 'ok' is right.  The finding must follow the covariances, whichever
    the seed.  The particle estimator, whose whole track is consistent there
    (truth NEES 1.8), stays 'ok'.  The finding reads the EKF's covariances
    without the enclosure built from the smoother's track
    (``linearised_everywhere``), which hold the error.
    """
    from dataclasses import replace

    from fgdoppler.estimators.judge import judge, track_reference

    sim = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(1))
    model = fd.TrackingModel.of(sim.scenario.geometry)
    init = fd.initiate(sim.measurements.first_per_pair(10), model)
    ekf = fd.run_estimator("ekf", sim.measurements, model, init, verify=False)
    ref = fd.run_estimator("smoother", sim.measurements, model, init)
    e = ekf.primary
    on = np.flatnonzero(np.isin(ref.primary.times, e.times[e.cov_ok]))

    def moved_at(where: np.ndarray) -> fd.TrackResult:
        # by 10 of the EKF's sigmas in Mahalanobis terms: a chi-square of 100 at each of those times
        shifted = ref.primary.states.copy()
        k = np.searchsorted(e.times, ref.primary.times[where])
        shifted[where] += 10.0 * np.linalg.cholesky(e.covariances[k])[..., 0]
        return replace(ref, estimates=(replace(ref.primary, states=shifted),))

    third = on[len(on) // 3: 2 * len(on) // 3]
    assert track_reference(e, ref.primary) == []
    (found,) = track_reference(e, moved_at(third).primary)
    assert (found.code, found.status) == ("reference", "doubtful") and "lay on average" in found.message
    assert track_reference(e, moved_at(third[:2]).primary) == []
    # the final state is untouched: the end-of-track check alone finds nothing
    assert judge(ekf, sim.measurements, model, fd.EKFSettings(), moved_at(third)).status == "ok"

    three = fd.Geometry(pairs=(fd.BistaticPair(tx=(40e3, 0.0), rx=(0.0, 0.0)),
                               fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3)),
                               fd.BistaticPair(tx=(5e3, 30e3), rx=(0.0, 0.0))))
    sim = fd.simulate(fd.Scenario(geometry=three, x0=(20e3, 10e3, -60.0, 70.0)), np.random.default_rng(4))
    init = fd.initiate(sim.measurements.first_per_pair(10), three)
    for seed in (0, 1):
        results = fd.run_estimators(["ekf", "particle"], sim.measurements, three, init, {"ekf": fd.EKFSettings(seed=seed)})
        ekf, particle = results["ekf"], results["particle"]
        error = np.linalg.norm(ekf.primary.states[:, :2] - sim.truth.at(ekf.primary.times)[:, :2], axis=1)
        assert error[-1] < 500.0 and np.max(error) > 5e3
        assert particle.status == "ok", particle.message
        # the finding reads the covariances without the enclosure built from the smoother's track
        plain = fd.run_estimator("ekf", sim.measurements, three, init,
                                 fd.EKFSettings(seed=seed, linearised_everywhere=False))
        assert [r for r in ekf.reasons if r.code == "reference"] == [r for r in plain.reasons if r.code == "reference"]
        held = _truth_nees(plain.primary, sim.truth, 12.0, 25.0)
        if held > 1e3:  # those covariances miss the error kilometres wide: the finding must say so
            assert ekf.status == "doubtful"
            assert [r.code for r in ekf.reasons if "lay on average" in r.message] == ["reference"], ekf.message
        else:  # the sampled checks alone widened them to hold it: nothing to report
            assert held < chi2.ppf(0.999, 4) and ekf.status == "ok", ekf.message
        # the reported covariances, widened towards the posterior linearised about the smoother's track
        # (linearised_everywhere, the default), hold the error there (sampler seed 0: truth NEES 4.4 over
        # t >= 10 s, 47,526 without)
        assert fd.EKFSettings().linearised_everywhere
        assert _truth_nees(ekf.primary, sim.truth, 10.0, np.inf, np.mean) < 10.0
    # on the machine this was written on, both: seed 0 doubtful (median NEES 1e5), seed 1 ok (2.2)


def _truth_nees(e: fd.Estimates, truth: fd.Trajectory, t0: float, t1: float, over: Any = np.median) -> float:
    """``over`` (median by default) of the truth's NEES under ``e``'s covariances at its times in [t0, t1]."""
    d = e.states - truth.at(e.times)
    nees = np.einsum("ki,ki->k", d, np.linalg.solve(e.covariances, d[..., None])[..., 0])
    return float(over(nees[(e.times >= t0) & (e.times <= t1)]))


def test_monte_carlo_records_every_verdict(tmp_path) -> None:
    from fgdoppler.analysis.montecarlo import MonteCarloResult, MonteCarloSpec, run_monte_carlo

    res = run_monte_carlo(MonteCarloSpec(scenarios=(fd.paper_scenario("a", 45e3),), runs=2, seed=5,
                                         estimators=("lm", "ekf", "smoother")), progress=False)
    for e in res.estimators:
        assert res.verdicts[0][e].shape == (2,) and set(res.verdicts[0][e]) <= set(fd.STATUSES)
    rows = res.summary()["rows"]
    assert all(sum(r["verdicts"].values()) == 2 for r in rows)
    res.save(tmp_path / "mc")
    back = MonteCarloResult.load(tmp_path / "mc")
    assert all(np.array_equal(back.verdicts[0][e], res.verdicts[0][e]) for e in res.estimators)


@pytest.mark.parametrize("estimator", ["smoother", "ekf", "particle"])
def test_a_stated_sigma_larger_than_the_datas_is_said_and_measured(estimator: str) -> None:
    """Noise of 0.3 m/s recorded with sigma 1 m/s: χ² ≈ 0.09 ν, far below the 0.1 % quantile (76 for ν = 118).

    The finding is ``ok`` (the track stands), says the stated sigma is
    likely too large, and its residual scale √(χ²/ν) estimates the true over
    the stated sigma, 0.3 (to ±0.05: ν ≈ 100 gives a relative standard
    error of 7 %).  With the sigma stated right there is no such finding.
    """
    import re

    sim = _sim(PAPER, sigma=0.3, seed=4)
    m = sim.measurements
    model = fd.TrackingModel.of(A)
    for stated, expect in ((1.0, True), (0.3, False)):
        data = fd.Measurements(time=m.time, pair=m.pair, doppler=m.doppler, sigma=np.full(len(m), stated))
        init = fd.initiate(data.first_per_pair(10), model)
        r = fd.run_estimator(estimator, data, model, init, verify=False)
        low = [q for q in r.reasons if q.code == "fit" and "scatter less" in q.message]
        assert r.status == "ok" and bool(low) == expect
        if expect:
            scale = float(re.search(r"residuals about ([\d.]+) times", low[0].message).group(1))  # type: ignore[union-attr]
            assert low[0].status == "ok" and abs(scale - 0.3) < 0.05


def test_the_rejections_finding_suggests_the_huber_loss_only_for_a_few_outliers() -> None:
    # 100 measurements with the Gaussian loss: 1 rejected is informational (not above REJECT_DOUBTFUL = 1 %), 5 are
    # doubtful and a few (up to REJECT_ROBUST = 10 %, what the Huber loss is there to absorb): try it; 30 are no
    # longer a few, and the finding says what more likely misfits; with the Huber loss already, no advice at all.
    from fgdoppler.estimators.judge import REJECT_ROBUST, _fit_reasons

    def rejections(rejected: int, robust: bool = False) -> fd.Reason:
        [found] = [r for r in _fit_reasons(80.0, 100 - rejected, 100, rejected, None, robust) if r.code == "rejections"]
        return found

    assert rejections(1).status == "ok" and "Huber" not in rejections(1).message
    assert rejections(5).status == "doubtful" and "try the Huber loss (--huber)" in rejections(5).message
    assert rejections(10).status == "doubtful" and "try the Huber loss" in rejections(10).message
    many = rejections(30).message
    assert f"more than {REJECT_ROBUST:.0%} are not a few outliers" in many and "try the Huber loss" not in many
    assert "Huber" not in rejections(30, robust=True).message


def test_the_final_state_reference_finding_reads_the_filters_own_covariance_and_says_so() -> None:
    # Case a from (25, 3) km at (20, -60) m/s for 200 s, the truth with q = 0.05 m^2/s^3 and the model told so
    # (seed 2): the EKF's own Gaussian covariance puts the smoother's final state at chi-square 145 (measured);
    # its covariance checks widen it to enclose the posterior, and the reported one puts it at 0.93.  The
    # finding is the own covariance's (its widening, towards the posterior linearised about the smoother's
    # track, could not disagree with the smoother), so its number is the run without the checks' number, and
    # its message must say which covariance it read, or a user holding the reported one reads a contradiction.
    motion = fd.ConstantVelocity(q=0.05)
    g = fd.paper_geometry("a")
    model = fd.TrackingModel.of(g, motion=motion)
    scen = fd.Scenario(geometry=g, x0=(25e3, 3e3, 20.0, -60.0), duration=200.0, dt=0.5, time_offsets=(0.0, 0.0),
                       process_noise=motion)
    m = fd.simulate(scen, np.random.default_rng(2)).measurements
    init = fd.initiate(m.first_per_pair(10), model)
    ref = fd.run_estimator("smoother", m, model, init)
    on = fd.run_estimator("ekf", m, model, init, reference=ref)
    off = fd.run_estimator("ekf", m, model, init, dataclasses.replace(fd.EKFSettings(), sampled_covariance=False),
                           reference=ref)
    np.testing.assert_array_equal(on.primary.states, off.primary.states)
    [message] = [r.message for r in on.reasons if r.code == "reference" and "final state lies" in r.message]
    d = on.primary.states[-1] - ref.primary.states[-1]
    own = float(d @ np.linalg.solve(off.primary.covariances[-1], d))
    reported = float(d @ np.linalg.solve(on.primary.covariances[-1], d))
    found = re.search(r"chi-square ([\d.]+) >", message)
    assert found is not None, message
    stated = float(found.group(1))
    assert stated == pytest.approx(own, abs=0.05) and own > 18.5 > reported
    assert "the filter's own Gaussian covariance's, before any widening by its covariance checks" in message
