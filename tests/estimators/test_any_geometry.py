"""Accuracy on geometries of one's own: three asynchronous pairs (one of them a monostatic radar), a zone given in the geometry file."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

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


# Two long studies (20 recordings of 60 s each, 50-70 s on two cores), run with -m slow to keep the default
# run inside the CI budget; by default a layout of one's own is held to its bound by
# test_three_d.py::test_batch_smoother_is_near_the_3d_bound_on_an_aircraft_over_ground_sensors and the
# target-outside-the-zone test below, and three pairs, asynchronous or not, by test_invariance's three-pair cases.
@pytest.mark.slow
@pytest.mark.parametrize("first", [
    # Two transmitters and three receivers around a 40 x 30 km area (non-collinear).  Measured: RMSE 91 m
    # against a CRLB of 85 m (1.07x), every run "ok".
    fd.BistaticPair(tx=(40e3, 0.0), rx=(0.0, 0.0)),
    # The first pair a monostatic radar at the origin instead (its bistatic range twice its range), which
    # also sets the sensors' frame (axis towards the next pair's transmitter).  Measured: RMSE 129 m against
    # a CRLB of 110 m (1.17x), every run "ok".  The frame a monostatic first pair sets is checked by default
    # in test_invariance's "monostatic" cases (every estimator).
    fd.BistaticPair(tx=(0.0, 0.0), rx=(0.0, 0.0)),
], ids=["bistatic", "monostatic"])
def test_three_asynchronous_pairs_reach_the_bound_at_the_end_of_a_minute(first: fd.BistaticPair) -> None:
    # Pairs sampled 0.2 and 0.35 s apart; 20 seeded 60 s recordings.  With 20 runs the RMSE's relative standard
    # error is about 11 %.
    three = fd.Geometry(pairs=(first, fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3)),
                               fd.BistaticPair(tx=(5e3, 30e3), rx=(0.0, 0.0))))
    scen = fd.Scenario(geometry=three, x0=(20e3, 10e3, -60.0, 70.0), duration=60.0, dt=0.5,
                       time_offsets=(0.0, 0.2, 0.35))
    rmse, bound, statuses = _end_rmse_and_bound(scen, three, runs=20, seed=12)
    assert rmse <= 1.3 * bound, (rmse, bound)
    assert statuses.count("ok") >= 18


def _outside_the_default_zone(tmp_path: Path) -> tuple[fd.Geometry, fd.Scenario]:
    """The paper's geometry (a) with a [zone] table widening the box across the baseline, and a target starting
    7 km off the baseline, outside the default box (|y| <= 5 km)."""
    path = tmp_path / "geometry.toml"
    path.write_text('[zone]\nacross = [-5000.0, 12000.0]\n[[pair]]\ntx = [50000.0, 0.0]\nrx = [0.0, 0.0]\n'
                    '[[pair]]\ntx = [50000.0, 1000.0]\nrx = [0.0, 0.0]\n')
    geometry = fd.Geometry.from_toml(path)
    assert geometry.zone.across == (-5e3, 12e3) and geometry.zone.along == (2e3, 48e3)
    return geometry, fd.Scenario(geometry=geometry, x0=(44e3, 7e3, -40.0, -100.0), duration=30.0, dt=0.5)


def test_a_target_outside_the_default_zone_is_tracked_in_a_zone_given_in_the_geometry_file(tmp_path: Path) -> None:
    """One recording of the study below (its first seed).  With the default zone the smoother's track is held at
    the zone's boundary, 4.2 km from the truth at the end, and says so ("doubtful"); with the file's zone it is
    ``ok`` and ends 0.98 km from the truth, against the smoothing CRLB's 0.50 km there: within the study's
    3 times the bound."""
    geometry, scen = _outside_the_default_zone(tmp_path)
    paper = fd.paper_geometry("a")
    start = np.asarray(scen.x0)[None]
    assert not paper.zone.contains(start)[0] and geometry.zone.contains(start)[0]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence(5).spawn(20)[0]))
    held = fd.track(sim.measurements, paper, "smoother")
    assert held.status != "ok"
    assert any(r.code == "boundary" and r.status == "doubtful" for r in held.reasons), held.reasons
    found = fd.track(sim.measurements, geometry, "smoother")
    assert found.status == "ok", found.reasons
    P = crlb_deterministic(geometry, scen.x0, sim.measurements, [sim.truth.times[-1]], smoothing=True)[0]
    error = float(np.hypot(*(found.primary.states[-1, :2] - sim.truth.states[-1, :2])))
    assert error <= 3.0 * float(np.sqrt(P[0, 0] + P[1, 1])), error


# A long study (20 recordings, 50-60 s on one core): run with -m slow; by default the test above tracks one of them.
@pytest.mark.slow
def test_a_target_outside_the_default_zone_is_found_in_a_zone_given_in_the_geometry_file(tmp_path: Path) -> None:
    # A [zone] table widening the box across the baseline lets the initiation search there.
    geometry, scen = _outside_the_default_zone(tmp_path)
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
    assert rival, found.reasons
    apart = re.search(r"and ends ([0-9]+) m away", rival[0].message)  # the two modes' ends, 0.46 km apart
    assert apart is not None and 400 <= int(apart.group(1)) <= 520, rival[0].message
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
    from fgdoppler.estimators.smoother_modes import _rival_reason
    from fgdoppler.estimators.smoother_solve import SmootherSolution

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
    import fgdoppler.estimators.smoother_modes as modes
    import fgdoppler.estimators.smoother_zone as zone
    from fgdoppler.estimators.spread import MAX_SPAN

    calls: list[int] = []
    real = modes._recording_starts

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return real(*args, **kwargs)

    # the mode search and the searches outside the zone both start from the recording's initiation
    for searcher in (modes, zone):
        monkeypatch.setattr(searcher, "_recording_starts", counting)
    scen = fd.paper_scenarios()[3]  # case b 5 km, well observed
    for duration, searched in ((30.0, True), (MAX_SPAN + 10.0, False)):
        calls.clear()
        m = fd.simulate(fd.Scenario(geometry=scen.geometry, x0=scen.x0, duration=duration, dt=scen.dt),
                        np.random.default_rng(0)).measurements
        fd.run_estimator("smoother", m, scen.geometry, fd.initiate(m.first_per_pair(10), scen.geometry))
        assert bool(calls) is searched, duration


def test_a_mode_beyond_the_speed_bound_is_found_by_the_boundary_check() -> None:
    # Two pairs in general position (draw 57 of `studies/random_layouts.py --speed-max 250`); the target flies
    # at 229 m/s, above the default zone's 200 m/s bound.  The smoother's track is held at the bound 7 km from
    # the truth (sigma 0.26 km); the wall released where it stopped gains 2.7 in cost (below chi-square(1) at
    # 95 %: "ok").  Measured over seeds 0-7: that local check said "ok" in 3 of 8 (the first, seed 2, is
    # used here); the search beyond the wall (both initiations over the zone widened to 300 m/s) found the
    # truth's mode in all 7 where the wall held, 9-23 lower in cost.
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(-25160.0, -30575.0), rx=(23007.0, 4081.0)),
                           fd.BistaticPair(tx=(26960.0, -32084.0), rx=(-26403.0, 33782.0))))
    scen = fd.Scenario(geometry=g, x0=(-8723.0, 15781.0, -229.2, -4.8), duration=30.0, dt=0.5)
    sim = fd.simulate(scen, np.random.default_rng(2))
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), g)
    results = {ms: fd.run_estimator("smoother", m, g, init, fd.SmootherSettings(mode_search=ms))
               for ms in (False, True)}
    e = results[False].primary
    sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2]))))
    assert np.hypot(*(e.states[-1, :2] - sim.truth.states[-1, :2])) > 3.0 * sd  # wrong by its own sigma
    wall = {ms: next(x for x in r.reasons if x.code == "boundary") for ms, r in results.items()}
    assert results[False].status == "ok" and wall[False].status == "ok"  # what the search is for
    assert results[True].status == "doubtful" and wall[True].status == "doubtful", wall[True].message
    # the track stays (the zone is the user's): the finding tells the user to widen it
    assert np.array_equal(results[True].primary.states, e.states)
    # independently: from the truth, without the wall, the smoother reaches a cost lower than the held
    # track's by more than the test's threshold, at the truth's speed
    from fgdoppler.estimators.smoother import solve_smoother

    model = fd.TrackingModel.of(g)
    free = solve_smoother(m, model, sim.truth.at(m.scans().times), fd.SmootherSettings(region_bound=False),
                          prior=model.prior())
    assert free.cost < results[False].cost - 3.84
    found = float(wall[True].message.split("(speed ")[1].split(" m/s")[0])
    assert abs(found - 229.2) < 10.0, wall[True].message


def test_a_track_held_at_the_speed_bound_that_gave_way_still_tests_the_bound() -> None:
    # Two pairs in general position (draw 317 of `studies/random_layouts.py --first 300 --speed-max 250`,
    # rounded to 0.1 m); the target flies at 212 m/s against the default zone's 200 m/s.  Inside the zone the
    # data fit a track 33.6 km from the truth about as well (cost 100.25; from the truth without the wall
    # 91.53), which the wall does not hold and which fits below the 90 % level of the search outside the zone.
    # Two of the initiation's three hypotheses sit at the bound; the third, below it, leads to that track and
    # has the lowest cost, so the held tracks' `boundary` findings went with their hypotheses: `ok`, with a
    # sigma of 181 m (seeds 0-7 of the layout: `ok` and 33.5 km off in all 8).  Now the held tracks, released
    # from the wall, are tested against the reported one (chi-square(1) at 95 %, the boundary test's level).
    from fgdoppler.estimators.ambiguity import hypotheses
    from fgdoppler.estimators.smoother import run_smoother, solve_smoother

    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(34383.5, -7168.2), rx=(-16350.4, -4503.8)),
                           fd.BistaticPair(tx=(-17002.4, 32310.5), rx=(24996.3, -19591.2))))
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(4810.1, -9593.8, -171.4, -125.1), duration=30.0, dt=0.5),
                      np.random.default_rng(1))
    m, model = sim.measurements, fd.TrackingModel.of(g)
    init = fd.initiate(m.first_per_pair(10), g)
    r = fd.run_estimator("smoother", m, g, init)
    e = r.primary
    sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2]))))
    assert np.hypot(*(e.states[-1, :2] - sim.truth.states[-1, :2])) > 3.0 * sd  # wrong by its own sigma
    held = [x for x in r.reasons if x.code == "boundary"]
    assert r.status == "doubtful" and len(held) == 1 and held[0].status == "doubtful", r.reasons
    assert all(x.status == "ok" for x in r.reasons if x.code != "boundary")  # what the finding is for
    assert held[0].zone is not None and held[0].zone.speed_max > np.hypot(-171.4, -125.1)  # advice: a higher bound
    # independently: from the truth without the wall the smoother reaches a cost lower than the reported
    # track's by more than the test's threshold, at the truth's speed, which the finding names
    free = solve_smoother(m, model, sim.truth.at(m.scans().times), fd.SmootherSettings(region_bound=False,
                          covariances=False), prior=model.prior())
    assert r.cost - free.cost > 3.84
    found = float(held[0].message.split(" away at ")[1].split(" m/s")[0])
    assert abs(found - np.hypot(-171.4, -125.1)) < 5.0, held[0].message
    # one hypothesis alone: its own track is held, fails the chi-square check and gives way to the
    # re-initiation's inside the zone, the finding stays with the run
    at_bound = [h for h in hypotheses(init) if np.hypot(*h.x_start[2:]) > 0.999 * g.zone.speed_max]
    alone = run_smoother(m, model, at_bound[-1])
    assert np.array_equal(alone.primary.times, e.times) and abs(alone.cost - r.cost) < 1e-6 * r.cost
    assert alone.status == "doubtful" and [x.code for x in alone.reasons if x.status == "doubtful"] == ["boundary"]
    assert any("re-initiated from the whole recording" in v.message for v in alone.events)


def test_the_mode_search_refines_enough_candidates_to_find_a_narrow_mode() -> None:
    # Two long crossing baselines (draw 3 of `studies/random_layouts.py --speed-max 250`).  The whole
    # recording's likelihood has narrow modes tens of kilometres apart; the initiation's window lands in a
    # wrong one and the grid over the whole recording ranks the truth's mode below broader, worse basins:
    # refining its 5 best candidates (the initiation's default) misses it, 20 (mode_candidates) find it.
    # Measured over seeds 0-5: without the search 3 tracks were 38 km off with a sigma under 1 km and "ok";
    # with it two of them (seeds 1, 2) moved to the truth's mode (cost 92.76 -> 91.04, 126.68 -> 115.05) and
    # the third is "doubtful" (competing).  Here (seed 1) the wrong mode costs only 1.7 more than the truth's:
    # the data cannot tell them apart, so the answer must say so (competing), whichever it reports.
    g = fd.Geometry(pairs=(fd.BistaticPair(tx=(-32247.0, 39368.0), rx=(32083.0, -37472.0)),
                           fd.BistaticPair(tx=(38434.0, 35804.0), rx=(-10088.0, 32700.0))))
    scen = fd.Scenario(geometry=g, x0=(46715.0, 30189.0, 50.2, -140.9), duration=30.0, dt=0.5)
    sim = fd.simulate(scen, np.random.default_rng(1))
    m = sim.measurements
    init = fd.initiate(m.first_per_pair(10), g)

    def wrong(r: fd.TrackResult) -> bool:
        e = r.primary
        sd = float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2]))))
        return bool(np.hypot(*(e.states[-1, :2] - sim.truth.states[-1, :2])) > 3.0 * sd)

    off = fd.run_estimator("smoother", m, g, init, fd.SmootherSettings(mode_search=False))
    found = fd.run_estimator("smoother", m, g, init)
    few = fd.run_estimator("smoother", m, g, init, fd.SmootherSettings(mode_candidates=5))
    assert off.status == "ok" and wrong(off)  # what the search is for
    assert wrong(few) and few.cost > found.cost  # what the number of candidates is for
    assert not wrong(found) and found.cost < off.cost
    assert found.status == "doubtful" and any(r.code == "competing" and r.status == "doubtful" for r in found.reasons)


def test_the_search_beyond_the_wall_widens_only_the_bounds_that_hold() -> None:
    # A rotated, moved zone: the excess is measured in its own frame.  Beyond the box's far end along its
    # first axis by 1 km and 50 m/s over the speed bound: that end moves out by half the box's length
    # (WIDEN - 1 = 0.5 of 10 km) and the bound to 1.5 x 200 m/s; the near end and the across sides stay.
    from fgdoppler.estimators.smoother_zone import WIDEN, _widened

    frame = fd.Frame(origin=(3e3, -2e3), basis=((0.6, 0.8), (-0.8, 0.6)))
    zone = fd.Zone(frame=frame, along=(0.0, 10e3), across=(-4e3, 4e3), speed_max=200.0)
    x = np.concatenate([frame.points_to_world(np.array([11e3, 1e3])), [250.0 * 0.6, 250.0 * 0.8]])
    wide = _widened(zone, x)
    assert WIDEN == 1.5
    assert wide.along == (0.0, 15e3) and wide.across == (-4e3, 4e3) and wide.speed_max == 300.0
    assert wide.frame == frame
    # before the near end and beside the across sides, at a speed inside the bound
    y = np.concatenate([frame.points_to_world(np.array([-1e3, -5e3])), [100.0, 0.0]])
    wide = _widened(zone, y)
    assert wide.along == (-5e3, 10e3) and wide.across == (-8e3, 4e3) and wide.speed_max == 200.0
    # inside the zone nothing moves
    assert _widened(zone, np.concatenate([frame.points_to_world(np.array([5e3, 0.0])), [0.0, 0.0]])) == zone


def test_a_target_faster_than_the_zone_allows_after_the_window_is_reported_not_a_crash() -> None:
    # Three pairs in general position (draw 248 of `studies/random_layouts.py --speed-max 250`, rounded to
    # 0.1 m); the target flies at 242.6 m/s against the default zone's 200 m/s.  Its first 10 measurements per
    # pair need only 192 m/s (the initiation accepts them), the whole recording 211 m/s: the smoother's
    # whole-recording searches and the trackers' restart checks found nothing in the zone to start from and
    # raised the grid's ValueError out of run_estimator.  Now every estimator answers, and none says `ok`:
    # each carries the `zone` finding with the speed the data need.
    from fgdoppler.estimators.grid import speed_lower_bound
    from fgdoppler.estimators.judge import needed_speed

    pairs = (fd.BistaticPair(tx=(14522.7, 15999.4), rx=(-22635.8, 6324.6)),
             fd.BistaticPair(tx=(-31444.3, 24764.1), rx=(14183.8, 17765.6)),
             fd.BistaticPair(tx=(12781.8, -5764.5), rx=(-15419.7, 13958.4)))
    g = fd.Geometry(pairs=pairs)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(-21389.2, 28035.6, -230.0, 77.0), duration=30.0, dt=0.5),
                      np.random.default_rng(0))
    m = sim.measurements
    window = m.first_per_pair(10)
    assert speed_lower_bound(window.doppler, window.sigma) < g.zone.speed_max < needed_speed(m) < 242.6
    init = fd.initiate(window, g)
    for name, r in fd.run_estimators(fd.ESTIMATORS, m, g, init).items():
        zone = [x for x in r.reasons if x.code == "zone" and "need a speed of at least" in x.message]
        assert r.status != "ok" and len(zone) == 1 and zone[0].status == "doubtful", (name, r.reasons)


def test_the_speed_the_data_need_ignores_isolated_outliers() -> None:
    from fgdoppler.estimators.judge import needed_speed

    # pair 0: a constant Doppler of 300 m/s, sigma 2; pair 1: 100 m/s with one gross outlier of 900 m/s;
    # pair 2: two measurements of 1,000 m/s (too few to tell an outlier from a peak: not counted)
    def recording(z1: np.ndarray) -> fd.Measurements:
        t = np.arange(8) * 0.5
        time = np.concatenate([t, t, t[:2]])
        order = np.argsort(time, kind="stable")
        pair = np.repeat([0, 1, 2], [8, 8, 2])
        z = np.concatenate([np.full(8, -300.0), z1, [1000.0, 1000.0]])
        return fd.Measurements(time=time[order], pair=pair[order], doppler=z[order], sigma=np.full(18, 2.0))

    z1 = np.full(8, 100.0)
    z1[4] = 900.0
    assert needed_speed(recording(z1)) == 0.5 * (300.0 - 5 * 2.0)
    # two outliers in a row are a peak, not an isolated outlier: the bound rises to theirs
    z1[5] = 900.0
    assert needed_speed(recording(z1)) == 0.5 * (900.0 - 5 * 2.0)


@pytest.mark.parametrize("loss", ["gaussian", "huber"])
def test_a_mode_outside_the_zone_is_found_when_the_track_fits_poorly(monkeypatch, loss: str) -> None:
    # Two pairs in general position (draw 231 of `studies/random_layouts.py --first 180 --speed-max 250`,
    # rounded to 0.1 m); the target flies at 248 m/s against the default zone's 200 m/s, and the only mode
    # that fits the data starts outside the zone.  The smoother settles in a mode inside it, 52.6 km from the
    # truth with a sigma of about 60 m; the wall does not hold that track and the searches inside the zone
    # find nothing better.  Gaussian loss, seed 5: its cost (153.2, chi-square p = 0.016) passes the
    # verdict's 99.9 % test.  Huber loss, seed 0, 5 % of the measurements +-100 m/s outliers: the robust
    # cost is no chi-square statistic; the inliers' (159.7, 6 outliers left out) is above the 90 % level.
    import fgdoppler.estimators.smoother_zone as smoother_zone
    from fgdoppler.estimators.smoother import solve_smoother
    from fgdoppler.estimators.smoother_zone import OUTSIDE_GAIN

    pairs = (fd.BistaticPair(tx=(10886.4, 21009.1), rx=(15300.2, 9875.2)),
             fd.BistaticPair(tx=(34369.1, 8539.3), rx=(-25773.7, 10075.6)))
    g = fd.Geometry(pairs=pairs)
    rng = np.random.default_rng(5 if loss == "gaussian" else 0)
    sim = fd.simulate(fd.Scenario(geometry=g, x0=(-18318.2, -2184.1, -92.5, 230.6), duration=30.0, dt=0.5), rng)
    m, k = sim.measurements, None
    if loss == "huber":
        z = m.doppler.copy()
        idx = rng.choice(len(m), round(0.05 * len(m)), replace=False)
        z[idx] += rng.choice([-100.0, 100.0], idx.size)
        m, k = fd.Measurements(time=m.time, pair=m.pair, doppler=z, sigma=m.sigma), 1.345
    init = fd.initiate(m.first_per_pair(10), g, fd.InitiationSettings(huber_k=k))

    def run(motion_check: bool = True) -> tuple[fd.TrackResult, float, float]:
        r = fd.run_estimator("smoother", m, g, init, fd.SmootherSettings(huber_k=k, motion_check=motion_check))
        e = r.primary
        err = float(np.hypot(*(e.states[-1, :2] - sim.truth.states[-1, :2])))
        return r, err, float(np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2]))))

    with monkeypatch.context() as mp:
        mp.setattr(smoother_zone, "OUTSIDE_LEVEL", 1.0)  # the search outside the zone never runs
        # nor the split test of the motion model, which flags this wrong track too with the Gaussian loss
        # (its parts disagree: `manoeuvre`): what the zone search alone does is shown here
        before, err, sd = run(motion_check=False)
    assert before.status == "ok" and err > 50e3 and err > 100.0 * sd  # confidently wrong
    after, err2, _ = run()
    assert err2 == err  # the track stays: the zone is the user's
    zone = [x for x in after.reasons if x.code == "zone"]
    assert after.status == "doubtful" and len(zone) == 1 and "outside the zone fits them better" in zone[0].message
    # independently: started from the truth without the wall, the smoother reaches a cost lower than the
    # reported track's by more than the finding's threshold, from a start above the zone's speed bound
    model = fd.TrackingModel.of(g)
    free = solve_smoother(m, model, sim.truth.at(m.scans().times), fd.SmootherSettings(region_bound=False,
                          covariances=False, huber_k=k), prior=model.prior())
    assert before.cost - free.cost > OUTSIDE_GAIN and np.hypot(*free.states[0, 2:]) > g.zone.speed_max
