"""The side of a line of sensors that few measurements settle (:mod:`fgdoppler.estimators.mirror_side`)."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.ambiguity import COMPETING
from fgdoppler.estimators.initiation import OUTLIER_CUT
from fgdoppler.estimators.mirror_side import sensor_lines, side_margins, side_reason
from fgdoppler.estimators.verdict import Reason
from fgdoppler.geometry import mirrored, principal_line, reflected

#: Pairs 1 and 2 on the line y = 3 km, pair 0 off it.
GEOMETRY = fd.Geometry(pairs=[fd.BistaticPair(tx=(0.0, 6000.0), rx=(3000.0, 6000.0)),
                              fd.BistaticPair(tx=(-2000.0, 3000.0), rx=(2000.0, 3000.0)),
                              fd.BistaticPair(tx=(-6000.0, 3000.0), rx=(5000.0, 3000.0))])
MODEL = fd.TrackingModel.of(GEOMETRY)
LINE = (np.array([0.0, 3000.0]), np.array([1.0, 0.0]))


def recording(keep_of_pair_0: int | None = 1) -> tuple[fd.Measurements, np.ndarray]:
    """30 s of a target 2 km above the line (in the default zone), and its true state at every scan; pair 0
    keeps only its
``keep_of_pair_0`` middle measurements (``None``: all)."""
    rng = np.random.default_rng(3)
    sim = fd.simulate(fd.Scenario(geometry=GEOMETRY, x0=(-1500.0, 5000.0, 120.0, 20.0)), rng)
    m = sim.measurements
    if keep_of_pair_0 is not None:
        rows = np.flatnonzero(m.pair == 0)
        middle = rows[len(rows) // 2 - keep_of_pair_0 // 2:][:keep_of_pair_0]
        m = m.subset((m.pair != 0) | np.isin(np.arange(len(m)), middle))
    return m, sim.truth.at(m.scans().times)


def test_a_reflection_keeps_the_doppler_of_every_pair_on_its_line() -> None:
    """Ranges and range rates to every point of the line are unchanged: the pairs on it see the same Doppler,
    the pair off it does not; reflecting twice gives the states back; :func:`mirrored` is the reflection across
    the sensors' least-squares line."""
    rng = np.random.default_rng(0)
    states = np.column_stack([rng.uniform(-8e3, 8e3, (50, 2)), rng.normal(0.0, 150.0, (50, 2))])
    image = reflected(states, *LINE)
    before, after = fd.bistatic_doppler(states, GEOMETRY), fd.bistatic_doppler(image, GEOMETRY)
    np.testing.assert_allclose(after[:, 1:], before[:, 1:], rtol=1e-12, atol=1e-9)
    assert np.median(np.abs(after[:, 0] - before[:, 0])) > 1.0  # pair 0, off the line, sees the image apart
    np.testing.assert_allclose(reflected(image, *LINE), states, rtol=0, atol=1e-9)
    c, u, _ = principal_line(np.vstack([GEOMETRY.tx, GEOMETRY.rx]))
    np.testing.assert_allclose(mirrored(states, GEOMETRY), reflected(states, c, u), rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="2-D states"):
        reflected(np.zeros((3, 6)), *LINE)


def test_the_lines_are_the_baselines_and_the_lines_through_two_radars() -> None:
    """One line per set of pairs on it: pair 0's baseline, and the line of pairs 1 and 2 (found from either);
    two radars make a line that a bistatic pair on it shares."""
    lines = sensor_lines(GEOMETRY, np.array([0, 1, 2]))
    assert sorted(on for _, _, on in lines) == [(0,), (1, 2)]
    g = fd.Geometry(pairs=[fd.BistaticPair(tx=(0.0, 0.0), rx=(0.0, 0.0)), fd.BistaticPair(tx=(5e3, 0.0), rx=(5e3, 0.0)),
                           fd.BistaticPair(tx=(-3e3, 0.0), rx=(9e3, 0.0)), fd.BistaticPair(tx=(0.0, 4e3), rx=(2e3, 4e3))])
    assert sorted(on for _, _, on in sensor_lines(g, np.arange(4))) == [(0, 1, 2), (3,)]
    assert sorted(on for _, _, on in sensor_lines(g, np.array([0, 3]))) == [(3,)]  # one radar: no line


def test_the_mirror_images_margin_is_the_tracks_negated() -> None:
    """Reflecting the track swaps it and its image: every margin changes sign (each δ_i does)."""
    m, states = recording(keep_of_pair_0=5)
    here = {s.on: s for s in side_margins(m, MODEL, states)}
    there = {s.on: s for s in side_margins(m, MODEL, reflected(states, *LINE))}
    assert here[(1, 2)].off == 5 and here[(0,)].off == int(np.sum(m.pair != 0))
    assert there[(1, 2)].margin == pytest.approx(-here[(1, 2)].margin, rel=1e-9)
    assert here[(1, 2)].distance == pytest.approx(2 * (states[-1, 1] - 3000.0), rel=1e-9)


def test_one_measurement_off_the_line_settles_nothing_without_it() -> None:
    """With one measurement of pair 0 the true track's image is worse by that measurement's term alone, at most
    the outlier cut's square, and without it by nothing: a ``competing`` finding naming the line's pairs.  With
    all of pair 0's measurements the side is settled many times over and there is none."""
    m, states = recording(keep_of_pair_0=1)
    one = {s.on: s for s in side_margins(m, MODEL, states)}[(1, 2)]
    assert one.off == 1 and one.robust_margin == 0.0 and 0.0 < one.margin <= OUTLIER_CUT**2
    found = side_reason(m, MODEL, states)
    assert isinstance(found, Reason) and found.status == "doubtful" and found.code == "competing"
    assert found.mirror == "pairs" and found.pairs == (1, 2)
    assert "only the one measurement of pair 0" in found.message and "--half-plane" in found.message
    full, truth = recording(keep_of_pair_0=None)
    assert min(s.robust_margin for s in side_margins(full, MODEL, truth)) > 100 * COMPETING
    assert side_reason(full, MODEL, truth) is None


def test_a_track_on_the_side_its_few_measurements_reject_is_said_to_be() -> None:
    """The image of the true track, with three measurements of pair 0: the data favour the other side, and the
    finding says the track is likely on the wrong side."""
    m, states = recording(keep_of_pair_0=3)
    found = side_reason(m, MODEL, reflected(states, *LINE))
    assert found is not None and "likely on the wrong side" in found.message
    assert side_reason(m, MODEL, states) is None  # three that agree settle the truth's side


def test_the_verdict_says_so_and_a_half_plane_settles_it() -> None:
    """The smoother's verdict on the recording with one measurement of pair 0 carries the finding, whichever
    side the track ends on; with a half plane it does not (the half plane settles the side)."""
    m, _ = recording(keep_of_pair_0=1)
    result = fd.track(m, GEOMETRY, "smoother")
    assert result.status != "ok"
    assert [r.pairs for r in result.reasons if r.mirror == "pairs"] == [(1, 2)]
    above = fd.InitiationSettings(half_plane=fd.HalfPlane(point=(0.0, 3000.0), normal=(0.0, 1.0)))
    settled = fd.track(m, GEOMETRY, "smoother", initiation=above)
    assert not any(r.mirror == "pairs" for r in settled.reasons) and settled.primary.states[-1, 1] > 3000.0
    assert Reason(code="competing", status="doubtful", message="m", mirror="pairs", pairs=(1, 2)).to_dict() == {
        "code": "competing", "status": "doubtful", "message": "m", "mirror": "pairs", "pairs": [1, 2]}
    with pytest.raises(ValueError, match="needs the pairs"):
        Reason(code="competing", status="doubtful", message="m", mirror="pairs")
    with pytest.raises(ValueError, match="needs the pairs"):
        Reason(code="competing", status="doubtful", message="m", pairs=(1,))


def test_a_dead_pairs_one_value_left_cannot_make_a_wrong_side_ok() -> None:
    """Case a at 25 km with pair 1 dead (every value 0) and all but its first value left out, as by hand: that
    one value alone decides the side of pair 0's baseline, and the smoother ended 21.4 km from the truth, ``ok``
    with no finding, before this finding existed.  Now its verdict names pair 0's line and is not ``ok``."""
    scenario = fd.paper_scenario("a", 25e3)
    sim = fd.simulate(scenario, np.random.default_rng(0))
    m = sim.measurements
    doppler = np.where(m.pair == 1, 0.0, m.doppler)
    first = np.flatnonzero(m.pair == 1)[0]
    kept = fd.Measurements.from_arrays(m.time, m.pair, doppler, m.sigma).subset(
        (m.pair == 0) | (np.arange(len(m)) == first))
    result = fd.track(kept, scenario.geometry, "smoother")
    error = np.hypot(*(result.primary.states[-1, :2] - sim.truth.at(result.primary.times[-1:])[0, :2]))
    assert error > 10e3  # the wrong side, which that value favours: the verdict must say so
    assert result.status == "doubtful"
    assert [r.pairs for r in result.reasons if r.mirror == "pairs"] == [(0,)]
