"""Repeated values in a pair's Doppler (:mod:`fgdoppler.repeats`): the chance against a simulation of rounded
noise, no false alarms on right data however it is rounded, and a held or dead receiver found and left out."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

import fgdoppler as fd
from fgdoppler.cli.main import main
from fgdoppler.estimators.judge import LEVEL, REJECT_DOUBTFUL, REPEATS_ADVICE, ROUNDING_ADVICE
from fgdoppler.repeats import (
    GRID_DIVISORS,
    coarse_rounding,
    drop_repeats,
    find_repeats,
    grid_step,
    repeat_probability,
)

A = fd.paper_geometry("a")


def _recording(seed: int, geometry: fd.Geometry = A, x0: tuple[float, ...] = (25e3, 2e3, 10.0, -100.0),
               sigma: float = 1.0, duration: float = 30.0) -> fd.Measurements:
    scen = fd.Scenario(geometry=geometry, x0=x0, duration=duration, dt=0.5, sigma=sigma)
    return fd.simulate(scen, np.random.default_rng(seed)).measurements


def _with(m: fd.Measurements, doppler: np.ndarray, sigma: np.ndarray | None = None) -> fd.Measurements:
    return fd.Measurements(time=m.time, pair=m.pair, doppler=doppler, sigma=m.sigma if sigma is None else sigma)


def _held(m: fd.Measurements, pair: int, every: int) -> tuple[fd.Measurements, np.ndarray]:
    """``m`` with every ``every``-th measurement of ``pair`` replaced by the one before it, and those rows."""
    z = m.doppler.copy()
    rows = np.flatnonzero(m.pair == pair)
    held = rows[every::every]
    z[held] = z[held - (rows[1] - rows[0])]
    return _with(m, z), held


@pytest.mark.parametrize("a", [0.01, 0.1, 0.4, 1.0 / np.sqrt(2.0)])
def test_the_chance_of_a_repeat_is_that_of_rounded_noise(a: float) -> None:
    # Two values, each noise of sigma 1 about one truth, rounded to a grid of step q = a sqrt(2) with a random
    # offset: the share of equal pairs against the closed form, within 4.5 binomial standard deviations.
    rng = np.random.default_rng(11)
    q, n = a * np.sqrt(2.0), 2_000_000
    offset = rng.uniform(0.0, q, n)
    x = rng.normal(0.0, 1.0, (2, n))
    share = float(np.mean(np.floor((x[0] - offset) / q) == np.floor((x[1] - offset) / q)))
    p = float(repeat_probability(a))
    assert abs(share - p) < 4.5 * np.sqrt(p * (1.0 - p) / n)


def test_the_chance_on_a_fine_grid_is_its_density_at_zero() -> None:
    # For q << sigma the two values share a cell with probability q times the density of their difference at 0,
    # N(0, 2 sigma^2): q / (2 sigma sqrt(pi)) = a phi(0).
    a = np.array([1e-9, 1e-6, 1e-3])
    np.testing.assert_allclose(repeat_probability(a), a * norm.pdf(0.0), rtol=1e-3)


@pytest.mark.parametrize(("step", "scale"), [(0.001, 1.0), (0.1, 3.05), (0.5, 1.0), (1.0, 0.2998)])
def test_the_grid_of_rounded_values_is_found(step: float, scale: float) -> None:
    # values rounded to a step (in Hz), converted with a wavelength as the reader does: every gap a whole multiple
    # of step * wavelength, which is found however the smallest gap lies
    z = -scale * np.round(np.random.default_rng(3).normal(0.0, 40.0, 200) / step) * step
    u = np.unique(z)
    assert grid_step(np.diff(u), float(np.max(np.abs(z)))) == pytest.approx(step * scale, rel=1e-9)


def test_values_on_no_grid_get_their_smallest_gap_over_the_divisors() -> None:
    u = np.unique(np.random.default_rng(4).normal(0.0, 40.0, 200))
    assert grid_step(np.diff(u), 200.0) == pytest.approx(np.diff(u).min() / GRID_DIVISORS)


@pytest.mark.parametrize("step", [0.0, 0.02, 0.2, 0.5, 1.0, 2.0])
def test_right_data_are_not_found_repeating_however_rounded(step: float) -> None:
    # Right recordings rounded to a grid from none to twice sigma (where most successive values repeat); the
    # tests are at 99.9 % a recording together, so over 40 recordings a finding would come by chance with
    # probability at most 0.04.
    found = []
    for seed in range(40):
        # a quarter of them stationary: the Doppler near 0 throughout, where one value recurs most by chance
        velocity = (0.0, 0.0) if seed % 4 == 0 else (10.0, -100.0)
        m = _recording(seed, x0=(25e3 + 500.0 * seed, 2e3, *velocity))
        z = m.doppler if step == 0.0 else np.round(m.doppler / step) * step
        found += find_repeats(_with(m, z), level=LEVEL)
    assert not found


def test_stated_sigma_too_large_on_a_coarse_grid_is_not_read_as_repeats() -> None:
    # Noise of 0.2 m/s rounded to 0.5 m/s repeats half the time; sigma stated as 1 m/s would make that unlikely,
    # but the steps' own scatter bounds the noise the test takes.
    found = []
    for seed in range(40):
        m = _recording(seed, sigma=0.2, x0=(25e3, 2e3 + 50.0 * seed, 10.0, -100.0))
        found += find_repeats(_with(m, np.round(m.doppler / 0.5) * 0.5, np.ones(len(m))))
    assert not found


def test_a_held_value_is_found_and_only_the_repeats_are_left_out() -> None:
    m = _recording(3)
    held, rows = _held(m, pair=1, every=3)
    (r,) = find_repeats(held)
    assert (r.pair, r.repeats, r.measurements) == (1, rows.size, int(np.sum(m.pair == 1)))
    np.testing.assert_array_equal(r.rows, rows)
    assert r.longest == 2 and r.resolution is not None and r.chance < 1e-20
    kept = drop_repeats(held)
    assert len(kept) == len(m) - rows.size
    # every measurement left is one of the right data's, none of the copies
    np.testing.assert_array_equal(kept.doppler, np.delete(m.doppler, rows))


def test_a_held_value_on_a_fine_grid_is_found() -> None:
    # Rounded to a tenth of sigma, a receiver holding a fifth of its values: 0.1 / (2 sqrt(pi)) = 2.8 % of
    # successive values repeat by chance, a fifth do here.
    m = _recording(4)
    held, rows = _held(m, pair=0, every=5)
    z = np.round(held.doppler / 0.1) * 0.1
    (r,) = find_repeats(_with(held, z))
    assert r.pair == 0 and r.repeats >= rows.size


def test_a_value_written_in_the_gaps_is_found_fixed_and_left_out_wherever_it_stands() -> None:
    # a receiver writing 0 where it has no detection, at a tenth of its scans, none of them in a row
    m = _recording(8)
    rows = np.flatnonzero(m.pair == 1)[2::10]
    z = m.doppler.copy()
    z[rows] = 0.0
    (r,) = find_repeats(_with(m, z))
    assert r.pair == 1 and r.repeats == 0 and r.fixed == 0.0 and r.fixed_count == rows.size
    np.testing.assert_array_equal(r.rows, rows)
    np.testing.assert_array_equal(drop_repeats(_with(m, z)).doppler, np.delete(m.doppler, rows))


def test_a_held_run_is_no_fixed_value() -> None:
    # one value held for ten scans: its first measurement is the receiver's, and stays
    m = _recording(9)
    rows = np.flatnonzero(m.pair == 0)
    z = m.doppler.copy()
    z[rows[21:30]] = z[rows[20]]
    (r,) = find_repeats(_with(m, z))
    assert r.fixed is None and r.longest == 10
    np.testing.assert_array_equal(r.rows, rows[21:30])


def test_a_dead_receiver_is_left_out_whole() -> None:
    m = _recording(5)
    z = np.where(m.pair == 1, 0.0, m.doppler)
    (r,) = find_repeats(_with(m, z))
    assert r.resolution is None and r.value == r.fixed == 0.0 and r.longest == r.measurements == r.repeats + 1
    kept = drop_repeats(_with(m, z))
    assert set(kept.pair.tolist()) == {0} and len(kept) == int(np.sum(m.pair == 0))


def test_the_finding_does_not_depend_on_the_pairs_numbering_or_the_clock() -> None:
    m = _recording(6)
    held, _ = _held(m, pair=1, every=4)
    moved = fd.Measurements.from_arrays(held.time + 1.7e9, 1 - held.pair, held.doppler, held.sigma, sort=True)
    (r,) = find_repeats(held)
    (s,) = find_repeats(moved)
    assert (s.pair, s.repeats, s.chance, s.resolution) == (0, r.repeats, r.chance, r.resolution)
    assert s.start == pytest.approx(r.start + 1.7e9)


def test_the_verdict_names_a_dead_receiver_and_counts_a_few_repeats_as_information() -> None:
    m = _recording(7)
    dead = _with(m, np.where(m.pair == 1, 0.0, m.doppler))
    result = fd.track(dead, A, "ekf")
    # the filter's own finding (its check against the smoother carries the smoother's words too)
    (finding,) = [r for r in result.reasons if r.code == "data" and REPEATS_ADVICE in r.message]
    assert finding.status == "doubtful" and result.status != "ok"
    # One run of equal values in a two-minute recording (482 measurements): found either way; 4 repeats are
    # 0.8 % of the data, information only, 7 are 1.5 %, doubtful as that share of rejections would be.
    m = _recording(7, duration=120.0)
    rows = np.flatnonzero(m.pair == 0)
    for repeats, status in ((4, "ok"), (7, "doubtful")):
        assert (repeats / len(m) > REJECT_DOUBTFUL) == (status == "doubtful")
        z = m.doppler.copy()
        z[rows[41:41 + repeats]] = z[rows[40]]
        few = _with(m, z)
        (r,) = find_repeats(few)
        assert r.repeats == repeats and r.longest == repeats + 1
        (finding,) = [x for x in fd.track(few, A, "ekf").reasons if x.code == "data" and REPEATS_ADVICE in x.message]
        assert finding.status == status


def test_track_drops_repeats_when_asked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--case", "a", "--start-x", "45000", "--seed", "2", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    m = fd.Measurements.from_csv(tmp_path / "measurements.csv", geometry=A)
    held, rows = _held(m, pair=0, every=3)
    held.to_csv(tmp_path / "held.csv")
    main(["track", str(tmp_path / "held.csv"), "--estimator", "ekf", "--allow-failed"])
    err = capsys.readouterr().err
    assert REPEATS_ADVICE in err and "hint: a pair repeats its values" in err
    # the initiation alone: its window (10 measurements a pair, 3 of pair 0's held) is tested
    main(["track", str(tmp_path / "held.csv"), "--estimator", "init", "--json"])
    d = json.loads(capsys.readouterr().out)
    assert any(r["code"] == "data" and REPEATS_ADVICE in r["message"] and "3 of its 10" in r["message"]
               for r in d["reasons"])
    assert main(["track", str(tmp_path / "held.csv"), "--estimator", "ekf", "--drop-repeats", "--json"]) == 0
    out = capsys.readouterr()
    assert f"left out {rows.size} of pair 0's" in out.err
    d = json.loads(out.out)
    assert d["dropped_repeats"] == {"0": rows.size}
    assert not any(REPEATS_ADVICE in r["message"] for r in d["reasons"])
    # right data: nothing to leave out, and said so
    assert main(["track", str(tmp_path / "measurements.csv"), "--estimator", "ekf", "--drop-repeats",
                 "--json"]) == 0
    out = capsys.readouterr()
    assert "every measurement kept" in out.err and json.loads(out.out)["dropped_repeats"] == {}


def test_too_few_measurements_to_repeat() -> None:
    none = fd.Measurements(time=np.array([]), pair=np.array([], dtype=int), doppler=np.array([]), sigma=np.array([]))
    one = _recording(0).subset(np.array([0]))
    two = fd.Measurements(time=np.array([0.0, 1.0]), pair=np.array([0, 0]), doppler=np.array([3.0, 3.0]),
                          sigma=np.array([1.0, 1.0]))
    for m in (none, one, two):  # two equal values of one pair: chance 0.27 with the resolution unknown
        assert find_repeats(m) == () and len(drop_repeats(m)) == len(m)
    assert coarse_rounding(none) == coarse_rounding(one) == ()


def test_level_out_of_range_is_refused() -> None:
    with pytest.raises(ValueError, match="level"):
        find_repeats(_recording(0), level=1.0)


def test_values_rounded_coarsely_explain_a_misfit_and_sigma_with_the_rounding_mend_it() -> None:
    # Two minutes of case a rounded to 2 m/s with sigma 1 m/s stated: the residuals' variance is 1 + 4/12 times
    # the model's, which the 476-dof fit test sees; sigma sqrt(1 + 1/3) state it and the track fits.
    m = _recording(0, x0=(45e3, 2e3, 10.0, -100.0), duration=120.0)
    coarse = _with(m, np.round(m.doppler / 2.0) * 2.0)
    (r0, r1) = coarse_rounding(coarse)
    assert (r0.pair, r1.pair) == (0, 1) and r0.step == pytest.approx(2.0)
    assert r0.with_rounding == pytest.approx(np.sqrt(1.0 + 4.0 / 12.0))
    result = fd.track(coarse, A, "smoother")
    assert any(x.code == "fit" and x.status == "doubtful" for x in result.reasons)
    (finding,) = [x for x in result.reasons if ROUNDING_ADVICE in x.message]
    assert finding.code == "data" and finding.status == "ok" and "sigma 1.15 m/s with the rounding" in finding.message
    mended = fd.track(_with(coarse, coarse.doppler, np.full(len(m), r0.with_rounding)), A, "smoother")
    assert not any(x.code == "fit" and x.status != "ok" for x in mended.reasons)
    assert not any(ROUNDING_ADVICE in x.message for x in mended.reasons)


def test_fine_rounding_and_full_precision_are_not_coarse() -> None:
    m = _recording(1)
    assert not coarse_rounding(m)
    assert not coarse_rounding(_with(m, np.round(m.doppler / 0.5) * 0.5))  # 0.25/12 = 2 % of sigma^2


def test_a_dead_pair_is_named_before_any_change_of_the_data() -> None:
    # Four pairs far apart (draw 7 of studies/random_layouts.py, rounded), pair 1 reading 0 throughout: its window
    # fits with pairs 2 and 3 exchanged, which is no mistake of the file; the repeats come first, and no change is
    # named, by the window or the track.
    from fgdoppler.estimators.window_mistakes import find_mistake

    pairs = [((250.0, 26480.0), (22260.0, -17410.0)), ((38060.0, 18760.0), (-12640.0, 2320.0)),
             ((-38850.0, 11760.0), (2410.0, -3570.0)), ((-7380.0, 18850.0), (39990.0, 37570.0))]
    g = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=np.array(t), rx=np.array(r)) for t, r in pairs))
    m = _recording(1, geometry=g, x0=(49081.0, 5187.0, -24.0, 70.0))
    dead = _with(m, np.where(m.pair == 1, 0.0, m.doppler))
    window = dead.first_per_pair(10)
    init = fd.initiate(window, g)
    found = find_mistake(window, fd.TrackingModel.of(g), fd.InitiationSettings(), init)
    assert found is not None and found.code == "swapped"  # what the window alone would name
    assert init.mistake is None and not any(r.code in ("sign", "swapped", "radial") for r in init.reasons)
    result = fd.run_estimator("smoother", dead, g, init)
    assert not any(r.code in ("sign", "swapped", "radial") for r in result.reasons)
    assert any(r.code == "data" and REPEATS_ADVICE in r.message and r.status == "doubtful" for r in result.reasons)
