"""Accuracy on geometries of one's own: three asynchronous pairs, and a zone given in the geometry file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import fgdoppler as fd
from fgdoppler.analysis.bounds import crlb_deterministic


def _end_rmse_and_bound(scen: fd.Scenario, geometry: fd.Geometry, runs: int, seed: int
                        ) -> tuple[float, float, list[str]]:
    """Position RMSE of the smoother's last state over seeded runs, the smoothing CRLB there, the verdicts."""
    se, statuses = [], []
    for seq in np.random.SeedSequence(seed).spawn(runs):
        sim = fd.simulate(scen, np.random.default_rng(seq))
        r = fd.track(sim.measurements, geometry, "smoother")
        e = r.primary.states[-1] - sim.truth.states[-1]
        se.append(e[0] ** 2 + e[1] ** 2)
        statuses.append(r.status)
    sim = fd.simulate(scen, np.random.default_rng(0))  # the bound needs only the times, pairs and sigmas
    P = crlb_deterministic(scen.geometry, scen.x0, sim.measurements, [sim.truth.times[-1]], smoothing=True)[0]
    return float(np.sqrt(np.mean(se))), float(np.sqrt(P[0, 0] + P[1, 1])), statuses


def test_three_asynchronous_pairs_reach_the_bound_at_the_end_of_a_minute() -> None:
    # Two transmitters and three receivers around a 40 x 30 km area (non-collinear), pairs sampled 0.2
    # and 0.35 s apart; 20 seeded 60 s recordings.  Measured: RMSE 91 m against a CRLB of 85 m (1.07x),
    # every run "ok".  With 20 runs the RMSE's relative standard error is about 11 %.
    three = fd.Geometry(pairs=(fd.BistaticPair(tx=(40e3, 0.0), rx=(0.0, 0.0)),
                               fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3)),
                               fd.BistaticPair(tx=(5e3, 30e3), rx=(0.0, 0.0))))
    scen = fd.Scenario(geometry=three, x0=(20e3, 10e3, -60.0, 70.0), duration=60.0, dt=0.5,
                       time_offsets=(0.0, 0.2, 0.35))
    rmse, bound, statuses = _end_rmse_and_bound(scen, three, runs=20, seed=12)
    assert rmse <= 1.3 * bound, (rmse, bound)
    assert statuses.count("ok") >= 18


def test_a_target_outside_the_default_zone_is_found_in_a_zone_given_in_the_geometry_file(tmp_path: Path) -> None:
    # The paper's geometry (a); the target starts 7 km off the baseline, outside the default box (|y| <= 5 km).
    # A [zone] table widening the box across the baseline lets the initiation search there.
    path = tmp_path / "geometry.toml"
    path.write_text('[zone]\nacross = [-5000.0, 12000.0]\n[[pair]]\ntx = [50000.0, 0.0]\nrx = [0.0, 0.0]\n'
                    '[[pair]]\ntx = [50000.0, 1000.0]\nrx = [0.0, 0.0]\n')
    geometry = fd.Geometry.from_toml(path)
    assert geometry.zone.across == (-5e3, 12e3) and geometry.zone.along == (2e3, 48e3)
    scen = fd.Scenario(geometry=geometry, x0=(44e3, 7e3, -40.0, -100.0), duration=30.0, dt=0.5)
    rmse, bound, statuses = _end_rmse_and_bound(scen, geometry, runs=20, seed=5)
    # measured: 798 m against a CRLB of 498 m (1.60x), 18 of 20 "ok"
    assert rmse <= 3.0 * bound, (rmse, bound)
    assert statuses.count("ok") >= 15


def test_two_modes_of_the_whole_recording_are_reported_not_hidden() -> None:
    # Two pairs in general position; the target ends 270 m from a receiver.  The whole recording's
    # likelihood has two narrow modes 0.46 km apart (position sigma 2-4 m each) whose costs differ by
    # less than chi-square(1) at 95 %, and the initiation's window holds both in one basin: in 2 of 12
    # seeds the smoother lands in the wrong one (measured: seed 6, 457 m off with a sigma of 3 m), which
    # the residuals' chi-square test cannot see.  The multi-start over the whole recording
    # (SmootherSettings.mode_search) finds the other mode and reports it as a competing track.
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(35019.0, -6875.0), rx=(20219.0, 12004.0)),
                           fd.BistaticPair(tx=(14605.0, -10119.0), rx=(2278.0, 28812.0))))
    scen = fd.Scenario(geometry=g, x0=(24616.0, 12312.0, -150.0, -18.4), duration=30.0, dt=0.5)
    sim = fd.simulate(scen, np.random.default_rng(6))
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), g)
    results = {ms: fd.run_estimator("smoother", m, g, init, fd.SmootherSettings(mode_search=ms))
               for ms in (False, True)}
    for r in results.values():
        e = r.primary
        sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2]))))
        assert np.hypot(*(e.states[-1, :2] - sim.truth.states[-1, :2])) > 3.0 * sd  # wrong by its own sigma
    assert results[False].status == "ok"  # what the search is for
    found = results[True]
    assert found.status == "doubtful"
    rival = [r for r in found.reasons if r.code == "competing" and r.status == "doubtful"]
    assert rival and "km away" in rival[0].message, found.reasons
    # the search changes no answer, only the verdict: the track is the same mode, to the bit
    np.testing.assert_array_equal(found.primary.states, results[False].primary.states)


def test_the_mode_search_leaves_a_track_whose_mode_it_finds_again_to_the_bit() -> None:
    # Case a 45 km (well observed): the whole recording's multi-start finds the smoother's own mode,
    # which does not replace the track (measured: 10 runs of each paper scenario, none moved).
    scen = fd.paper_scenarios()[2]
    for seed in (0, 1):
        m = fd.simulate(scen, np.random.default_rng(seed)).measurements
        init = fd.initiate(m.first_per_pair(10), scen.geometry)
        on, off = (fd.run_estimator("smoother", m, scen.geometry, init, fd.SmootherSettings(mode_search=ms))
                   for ms in (True, False))
        np.testing.assert_array_equal(on.primary.states, off.primary.states)
        np.testing.assert_array_equal(on.primary.covariances, off.primary.covariances)
        assert on.status == off.status == "ok"


def test_a_rival_mode_is_reported_by_its_cost_and_its_share_of_the_error() -> None:
    # _rival_reason's rule on constructed 2-D solutions: the reported one ends at the origin with a
    # position sigma of 10 m.  A track 1 km away is a rival when the data cannot tell them apart
    # (cost difference 1 < 3.84) or when its posterior weight w = exp(-delta / 2) gives it a share
    # w / (1 + w) d^2 of the mean-square error above (3 sigma)^2 = 900 m^2: delta = 20 gives
    # 4.5e-5 * 1e6 = 45 m^2, not a rival; delta = 10 gives 6.7e-3 * 1e6 = 6,700 m^2, a rival.  A track
    # 20 m away (within 50 m) is the same mode.
    from fgdoppler.estimators.smoother import SmootherSolution, _rival_reason

    P = np.diag([100.0, 100.0, 1.0, 1.0])

    def sol(end: tuple[float, float], cost: float) -> SmootherSolution:
        states = np.array([[end[0] - 100.0, end[1], 10.0, 0.0], [end[0], end[1], 10.0, 0.0]])
        return SmootherSolution(times=np.array([0.0, 10.0]), states=states, covariances=np.array([P, P]),
                                cost=cost, iterations=1)

    zone = fd.paper_geometry("a").zone
    best = sol((0.0, 0.0), 100.0)
    assert _rival_reason([best, sol((1e3, 0.0), 101.0)], best, zone) is not None
    assert _rival_reason([best, sol((0.0, 1e3), 110.0)], best, zone) is not None
    assert _rival_reason([best, sol((1e3, 0.0), 120.0)], best, zone) is None
    assert _rival_reason([best, sol((20.0, 0.0), 99.0)], best, zone) is None


def test_the_mode_search_keeps_to_the_half_plane_the_user_gave() -> None:
    # All sensors on y = 0: the mirror image (x, -y, vx, -vy) of every track fits the data exactly.  The
    # whole recording's multi-start would find it as a rival of equal cost; bound by the initiation's
    # half plane it searches the north side only, so the smoother's track and verdict there are what they
    # are without the search, and without the half plane the mirror is reported.
    from fgdoppler.estimators.grid import HalfPlane

    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3, 0.0), rx=(0.0, 0.0)),
                           fd.BistaticPair(tx=(60e3, 0.0), rx=(0.0, 0.0))))
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(42e3, 4e3, -60.0, -80.0), duration=30.0, sigma=0.5),
                      np.random.default_rng(0))
    m = sim.measurements
    north = fd.initiate(m.first_per_pair(20), g,
                        fd.InitiationSettings(half_plane=HalfPlane(point=(0.0, 0.0), normal=(0.0, 1.0))))
    on, off = (fd.run_estimator("smoother", m, g, north, fd.SmootherSettings(mode_search=ms)) for ms in (True, False))
    assert np.all(on.primary.states[:, 1] > 0)
    np.testing.assert_array_equal(on.primary.states, off.primary.states)
    assert not any(r.code == "competing" and r.status != "ok" for r in on.reasons)
    both = fd.initiate(m.first_per_pair(20), g)
    free = fd.run_estimator("smoother", m, g, both, fd.SmootherSettings(mode_search=True))
    assert free.status != "ok"  # the mirror image: reported, whichever side the track is on


def test_recordings_longer_than_the_sampled_span_are_not_searched(monkeypatch) -> None:
    # Over more than spread.MAX_SPAN (300 s) a deterministic constant-velocity fit of the whole recording
    # no longer describes a track with process noise: the search is not run there (and on a 30 s one it is).
    import fgdoppler.estimators.smoother as smoother

    calls: list[int] = []
    real = smoother._recording_starts

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(smoother, "_recording_starts", counting)
    scen = fd.paper_scenarios()[3]  # case b 5 km, well observed
    for duration, searched in ((30.0, True), (smoother.MAX_SPAN + 10.0, False)):
        calls.clear()
        m = fd.simulate(fd.Scenario(geometry=scen.geometry, x0=scen.x0, duration=duration, dt=scen.dt),
                        np.random.default_rng(0)).measurements
        fd.run_estimator("smoother", m, scen.geometry, fd.initiate(m.first_per_pair(10), scen.geometry))
        assert bool(calls) is searched, duration
