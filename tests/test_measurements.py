"""Measurement container and CSV: validation errors name file and line; writes are atomic."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.measurements import MeasurementError


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


GOOD = "time,pair,doppler,sigma\n0.0,0,1.5,1.0\n0.0,1,2.5,1.0\n0.5,0,1.25,0.5\n"


def test_round_trip_is_exact(tmp_path: Path, rng: np.random.Generator) -> None:
    n = 200
    m = fd.Measurements.from_arrays(
        np.sort(rng.uniform(0, 30, n)), rng.integers(0, 3, n), rng.normal(0, 100, n), rng.uniform(0.1, 3, n)
    )
    m.to_csv(tmp_path / "m.csv")
    back = fd.Measurements.from_csv(tmp_path / "m.csv")
    for name in ("time", "pair", "doppler", "sigma"):
        np.testing.assert_array_equal(getattr(back, name), getattr(m, name))


def test_reads_good_file_and_default_sigma(tmp_path: Path) -> None:
    m = fd.Measurements.from_csv(_write(tmp_path / "m.csv", GOOD), geometry=fd.paper_geometry("a"))
    assert len(m) == 3
    np.testing.assert_array_equal(m.pair, [0, 1, 0])
    no_sigma = _write(tmp_path / "n.csv", "time,pair,doppler\n0,0,1\n1,1,2\n")
    m2 = fd.Measurements.from_csv(no_sigma, default_sigma=2.0)
    np.testing.assert_array_equal(m2.sigma, [2.0, 2.0])
    with pytest.raises(MeasurementError, match="no sigma column"):
        fd.Measurements.from_csv(no_sigma)


def test_columns_are_matched_by_name_in_any_order(tmp_path: Path) -> None:
    """Every order of the four columns (and of the three without sigma) reads as the canonical file does."""
    import itertools

    rows = list(csv.reader(GOOD.splitlines()))
    canonical = fd.Measurements.from_csv(_write(tmp_path / "m.csv", GOOD))
    for k, order in enumerate(itertools.permutations(range(4))):
        text = "\n".join(",".join(row[i] for i in order) for row in rows) + "\n"
        m = fd.Measurements.from_csv(_write(tmp_path / f"p{k}.csv", text))
        for name in ("time", "pair", "doppler", "sigma"):
            np.testing.assert_array_equal(getattr(m, name), getattr(canonical, name))
    for k, order in enumerate(itertools.permutations(range(3))):
        text = "\n".join(",".join(row[i] for i in order) for row in rows) + "\n"
        m = fd.Measurements.from_csv(_write(tmp_path / f"q{k}.csv", text), default_sigma=0.25)
        np.testing.assert_array_equal(m.doppler, canonical.doppler)
        np.testing.assert_array_equal(m.sigma, [0.25] * 3)
    loose = GOOD.replace("time,pair,doppler,sigma", " Pair ,TIME,Doppler,sigma")
    loose = "\n".join([loose.splitlines()[0]] + [",".join((r[1], r[0], *r[2:])) for r in rows[1:]]) + "\n"
    np.testing.assert_array_equal(fd.Measurements.from_csv(_write(tmp_path / "l.csv", loose)).time, canonical.time)


def test_named_extra_columns_are_skipped_and_no_others(tmp_path: Path) -> None:
    """Another tool's extra columns (an SNR, a quality flag in words) are skipped when named, in either layout and
    in any position; the measurements are the file's without them.  Unnamed, they are still refused, and naming a
    column the file is read by is an error, not a way to drop it."""
    rng = np.random.default_rng(5)
    m = fd.simulate(fd.paper_scenarios()[0], rng).measurements.subset(np.arange(40))
    m.to_csv(tmp_path / "m.csv")
    rows = (tmp_path / "m.csv").read_text().splitlines()
    snr = rng.uniform(5.0, 30.0, len(rows) - 1)
    words = ["good" if v > 10 else "weak, noisy" for v in snr]  # text with a comma: quoted
    extra = [f"SNR,{rows[0]}, Quality"] + [f"{v!r},{r},\"{w}\"" for v, r, w in zip(snr, rows[1:], words, strict=True)]
    path = _write(tmp_path / "x.csv", "\n".join(extra) + "\n")
    with pytest.raises(MeasurementError, match="unknown column 'snr', 'quality'"):
        fd.Measurements.from_csv(path)
    with pytest.raises(MeasurementError, match="unknown column 'quality'"):
        fd.Measurements.from_csv(path, ignore_columns=("snr",))
    back = fd.Measurements.from_csv(path, ignore_columns=("snr", "QUALITY ", "not-in-this-file"))
    for col in ("time", "pair", "doppler", "sigma"):
        np.testing.assert_array_equal(getattr(back, col), getattr(m, col))
    # numbers only: the fast reader, the same answer
    plain = _write(tmp_path / "p.csv", "\n".join(line.rsplit(",", 1)[0] if k == 0 else line.rsplit(",\"", 1)[0]
                                                 for k, line in enumerate(extra)) + "\n")
    back = fd.Measurements.from_csv(plain, ignore_columns="snr")
    np.testing.assert_array_equal(back.doppler, m.doppler)
    # in Hz too
    lam = [0.5, 0.6]
    m.to_csv(tmp_path / "hz.csv", wavelengths=lam)
    hz = (tmp_path / "hz.csv").read_text().splitlines()
    hz = [hz[0] + ",snr"] + [f"{r},{v!r}" for r, v in zip(hz[1:], snr, strict=True)]
    geom = replace(fd.paper_geometry("a"), wavelengths=tuple(lam))
    back = fd.Measurements.from_csv(_write(tmp_path / "h.csv", "\n".join(hz) + "\n"), geometry=geom,
                                    ignore_columns=["snr"])
    np.testing.assert_allclose(back.doppler, m.doppler, rtol=1e-15)
    for needed in ("sigma", "Doppler", "sigma_hz"):
        with pytest.raises(ValueError, match=f"cannot ignore '{needed.lower()}': a measurement file is read by"):
            fd.Measurements.from_csv(path, ignore_columns=("snr", needed))


def test_pairs_may_interleave_in_any_order(tmp_path: Path) -> None:
    """One receiver's rows after another's, or any interleaving that keeps each pair's time order, read as the
    time-ordered file does; the duplicate check still names both lines."""
    geom = fd.paper_geometry("a")
    scen = fd.paper_scenarios()[0]
    m = fd.simulate(scen, np.random.default_rng(3)).measurements
    m.to_csv(tmp_path / "m.csv")
    rows = (tmp_path / "m.csv").read_text().splitlines()
    header, body = rows[0], rows[1:]
    by_pair = sorted(body, key=lambda r: int(r.split(",")[1]))  # stable: each pair keeps its time order
    rng = np.random.default_rng(0)
    queues = [[r for r in body if int(r.split(",")[1]) == k] for k in range(geom.n_pairs)]
    shuffled = []
    while any(queues):  # a random merge of the pairs' streams
        k = int(rng.choice([i for i, q in enumerate(queues) if q]))
        shuffled.append(queues[k].pop(0))
    assert shuffled != body and by_pair != body
    for name, lines in (("p.csv", by_pair), ("s.csv", shuffled)):
        back = fd.Measurements.from_csv(_write(tmp_path / name, "\n".join([header, *lines]) + "\n"), geometry=geom)
        for col in ("time", "pair", "doppler", "sigma"):
            np.testing.assert_array_equal(getattr(back, col), getattr(m, col))
    dup = "\n".join([header, *by_pair, by_pair[0]]) + "\n"
    with pytest.raises(MeasurementError, match=r"earlier than pair 0's previous row's"):
        fd.Measurements.from_csv(_write(tmp_path / "d.csv", dup))
    dup = "\n".join([header, *by_pair[:3], by_pair[2]]) + "\n"
    with pytest.raises(MeasurementError, match=r"d2.csv:5: duplicate measurement .* \(first at line 4\)"):
        fd.Measurements.from_csv(_write(tmp_path / "d2.csv", dup))


def test_a_pair_may_be_given_by_its_name(tmp_path: Path) -> None:
    """With a geometry that names its pairs, a file giving the names (quoted or not, with spaces) reads as the one
    giving the indices, names and indices mixed too; an unknown name is refused listing the names; without the
    geometry, or with one that names no pair, a name is not a number."""
    geom = fd.Geometry(pairs=fd.paper_geometry("a").pairs, pair_names=("north", "south rx"))
    m = fd.simulate(fd.paper_scenarios()[0], np.random.default_rng(3)).measurements
    m.to_csv(tmp_path / "m.csv")
    rows = (tmp_path / "m.csv").read_text().splitlines()
    label = {"0": " north ", "1": '"south rx"'}  # spaces around a name are ignored, as around a number
    named = [rows[0]] + [",".join((r.split(",")[0], label[r.split(",")[1]], *r.split(",")[2:])) for r in rows[1:]]
    mixed = [named[0]] + [n if i % 2 else r for i, (n, r) in enumerate(zip(named[1:], rows[1:], strict=True))]
    for name, lines in (("n.csv", named), ("x.csv", mixed)):
        back = fd.Measurements.from_csv(_write(tmp_path / name, "\n".join(lines) + "\n"), geometry=geom)
        for col in ("time", "pair", "doppler", "sigma"):
            np.testing.assert_array_equal(getattr(back, col), getattr(m, col))
    bad = _write(tmp_path / "b.csv", "\n".join([named[0], named[1].replace(" north ", "nort")]) + "\n")
    with pytest.raises(MeasurementError, match=r"b.csv:2: pair 'nort' is neither a number nor one of the names "
                                               r"'north', 'south rx'"):
        fd.Measurements.from_csv(bad, geometry=geom)
    for other in (None, fd.paper_geometry("a")):
        with pytest.raises(MeasurementError, match=r"n.csv:2: pair is not a number: 'north'"):
            fd.Measurements.from_csv(tmp_path / "n.csv", geometry=other)


@pytest.mark.parametrize(
    ("text", "line", "msg"),
    [
        ("", None, "empty measurement file"),
        ("\n\n", None, "empty measurement file"),
        ("time,pair,doppler,sigma\n", None, "no data rows"),
        ("t,p,d,s\n0,0,1,1\n", 1, "bad header"),
        # columns by name: what is wrong is said, nothing unknown is dropped
        ("time,pair,dopler,sigma\n0,0,1,1\n", 1, "no column 'doppler'; unknown column 'dopler'"),
        ("time,pair,doppler,snr\n0,0,1,1\n", 1, "unknown column 'snr'"),
        ("time,pair,doppler,sigma,sigma\n0,0,1,1,1\n", 1, "repeated column 'sigma'"),
        # and why, where the cause is plain: another separator, a comment line
        ("time;pair;doppler;sigma\n0;0;1;1\n", 1, "separates its names with semicolons: the columns must be "
                                                   "separated by commas"),
        ("time\tpair\tdoppler\n0\t0\t1\n", 1, "with tabs"),
        ("# from receiver 2\ntime,pair,doppler\n0,0,1\n", 1, "a comment line: this file has no comments"),
        ("sigma,doppler,time,pair\n1,abc,0,0\n", 2, "doppler is not a number"),
        ("pair,time,doppler,sigma\n0,1,1,1\n0,0.5,1,1\n", 3, "time 0.5 is earlier than pair 0's previous row's 1.0 \\(line 2\\)"),
        ("time,pair,doppler,sigma\n0,0,abc,1\n", 2, "doppler is not a number"),
        # a timestamp where seconds are read: said so, with what to give instead
        ("time,pair,doppler,sigma\n2026-11-30T00:00:00.5Z,0,1,1\n", 2, "time is not a number: "
         "'2026-11-30T00:00:00.5Z': a date or a time of day: fgdoppler reads a number of seconds"),
        ("time,pair,doppler,sigma\n2026/11/30 00:00:00,0,1,1\n", 2, "a date or a time of day"),
        ("time,pair,doppler,sigma\n00:00:01.5,0,1,1\n", 2, "'00:00:01.5': a date or a time of day"),
        ("time,pair,doppler,sigma\n0,0,1,1\n0.5,0,nan,1\n", 3, "doppler is not a number: 'nan'"),
        ("time,pair,doppler,sigma\n0,0,1,1\ninf,0,1,1\n", 3, "time is not a number: 'inf'"),
        # what Python's float() would have taken
        ("time,pair,doppler,sigma\n,,,\n", 2, "time is empty"),
        ("time,pair,doppler,sigma\n0,0,1_000,1\n", 2, "doppler is not a number: '1_000'"),
        ("time,pair,doppler,sigma\n0,0,\u0661\u0662,1\n", 2, "doppler is not a number"),
        ("time,pair,doppler,sigma\n0,0,0x10,1\n", 2, "doppler is not a number"),
        ("time,pair,doppler,sigma\n0,0, ,1\n", 2, "doppler is empty"),
        # values no real file holds: each would overflow or underflow downstream
        ("time,pair,doppler,sigma\n0,0,1,5e-324\n", 2, "sigma 4.94066e-324 is outside"),
        ("time,pair,doppler,sigma\n0,0,1e308,1\n", 2, "doppler 1e\\+308 is outside"),
        ("time,pair,doppler,sigma\n1e300,0,1,1\n", 2, "time 1e\\+300 is outside .*: a corrupt or mis-scaled value"),
        # a Unix time (1.76e9 s on 2025-11-26) written in a finer unit: the unit and the factor are named
        ("time,pair,doppler,sigma\n1764115215000,0,1,1\n", 2, "time 1.76412e\\+12 is outside \\[-1e\\+12, "
         "1e\\+12\\]: likely a Unix time in milliseconds where fgdoppler reads seconds: divide the time column by "
         "1,000"),
        ("time,pair,doppler,sigma\n1764115215000000,0,1,1\n", 2, "Unix time in microseconds .* by 1,000,000$"),
        ("time,pair,doppler,sigma\n1764115215000000000,0,1,1\n", 2, "Unix time in nanoseconds .* by 1,000,000,000$"),
        ("time,pair,doppler,sigma\n-1764115215000,0,1,1\n", 2, "outside .*: a corrupt or mis-scaled value"),
        ("time,pair,doppler,sigma\n0,0,1e999,1\n", 2, "doppler is too large"),
        # bounded reads
        ("time,pair,doppler,sigma\n0,0," + "1" * 200_000 + ",1\n", 2, "longer than 4096 bytes"),
        ("time,pair,doppler,sigma\n0,0,1\x00,1\n", 2, "NUL"),
        ("time,pair,doppler,sigma\n0,0,1,0\n", 2, "sigma must be > 0"),
        ("time,pair,doppler,sigma\n0,0,1,-1\n", 2, "sigma must be > 0"),
        ("time,pair,doppler,sigma\n0,2,1,1\n", 2, "unknown pair index 2: the geometry has 2 pair\\(s\\), indices 0..1$"),
        # pairs numbered 1..2 for the geometry's two: likely from 1, and the message says so; not where 0 appears
        ("time,pair,doppler,sigma\n0,1,1,1\n0,2,1,1\n", 3, "indices 0..1; the file numbers its pairs 1..2: fgdoppler "
         "numbers them from 0 in the geometry's order, so subtract 1 if that is what they mean$"),
        ("time,pair,doppler,sigma\n0,0,1,1\n0,1,1,1\n0,2,1,1\n", 4, "indices 0..1$"),
        ("time,pair,doppler,sigma\n0,0.5,1,1\n", 2, "non-negative integer"),
        ("time,pair,doppler,sigma\n0,-1,1,1\n", 2, "non-negative integer"),
        ("time,pair,doppler,sigma\n0,0,1,1\n0,1,1,1\n0,0,2,1\n", 4, "duplicate measurement"),
        ("time,pair,doppler,sigma\n1,0,1,1\n0.5,1,1,1\n0.5,0,1,1\n", 4, "earlier than pair 0's previous row's"),
        ("time,pair,doppler,sigma\n0,0,1\n", 2, "expected 4 fields"),
    ],
)
def test_malformed_csv(tmp_path: Path, text: str, line: int | None, msg: str) -> None:
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(MeasurementError, match=msg) as info:
        fd.Measurements.from_csv(path, geometry=fd.paper_geometry("a"))
    where = f"{path}:{line}" if line is not None else str(path)
    assert where in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MeasurementError, match="cannot read"):
        fd.Measurements.from_csv(tmp_path / "nope.csv")


def test_endless_and_binary_inputs_are_refused_at_once(tmp_path: Path) -> None:
    with pytest.raises(MeasurementError, match="/dev/zero:1: line longer than"):
        fd.Measurements.from_csv("/dev/zero")
    binary = tmp_path / "latin1.csv"
    binary.write_bytes(b"time,pair,doppler,sigma\n0,0,1,1\n# caf\xe9\n")
    with pytest.raises(MeasurementError, match=r"latin1\.csv:3: not UTF-8"):
        fd.Measurements.from_csv(binary)


def test_constructor_refuses_values_no_file_may_hold() -> None:
    with pytest.raises(MeasurementError, match=r"sigma .* is outside"):
        fd.Measurements.from_arrays([0.0], [0], [1.0], 1e-9)
    with pytest.raises(MeasurementError, match=r"doppler .* is outside"):
        fd.Measurements.from_arrays([0.0], [0], [7e8], 1.0)
    with pytest.raises(MeasurementError, match=r"time .* is outside .*: likely a Unix time in milliseconds"):
        fd.Measurements.from_arrays([1764115215000.0], [0], [1.0], 1.0)


def test_container_validation() -> None:
    with pytest.raises(MeasurementError, match="time order"):
        fd.Measurements.from_arrays([1.0, 0.0], [0, 0], [1.0, 1.0], 1.0)
    with pytest.raises(MeasurementError, match="duplicate"):
        fd.Measurements.from_arrays([0.0, 0.0], [1, 1], [1.0, 1.0], 1.0)
    with pytest.raises(MeasurementError, match="sigma"):
        fd.Measurements.from_arrays([0.0], [0], [1.0], -1.0)
    m = fd.Measurements.from_arrays([1.0, 0.0], [0, 0], [1.0, 2.0], 1.0, sort=True)
    np.testing.assert_array_equal(m.doppler, [2.0, 1.0])
    with pytest.raises(MeasurementError, match="not in the geometry"):
        fd.Measurements.from_arrays([0.0], [3], [1.0], 1.0).check(fd.paper_geometry("a"))


def test_failed_write_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    m = fd.Measurements.from_arrays(np.arange(10.0), np.zeros(10, int), np.ones(10), 1.0)
    target = tmp_path / "out.csv"
    calls = {"n": 0}
    real_writer = csv.writer

    class Failing:
        def __init__(self, fh: object, **kw: object) -> None:
            self._w = real_writer(fh, **kw)

        def writerow(self, row: object) -> None:
            calls["n"] += 1
            if calls["n"] > 3:
                raise OSError("disk full")
            self._w.writerow(row)

    monkeypatch.setattr(csv, "writer", Failing)
    with pytest.raises(OSError, match="disk full"):
        m.to_csv(target)
    assert list(tmp_path.iterdir()) == []


def test_scans_and_windows() -> None:
    m = fd.Measurements.from_arrays([0, 0, 0.25, 0.5, 0.5], [1, 0, 1, 0, 1], [1, 2, 3, 4, 5], 1.0)
    scans = m.scans()
    assert scans is m.scans()  # computed once
    np.testing.assert_array_equal(scans.times, [0.0, 0.25, 0.5])
    np.testing.assert_array_equal(scans.counts, [2, 1, 2])
    np.testing.assert_array_equal(scans.scan_of, [0, 0, 1, 2, 2])
    np.testing.assert_array_equal(m.pair[scans.rows(0)], [0, 1])
    np.testing.assert_array_equal(m.doppler[scans.rows(0)], [2, 1])
    assert len(scans) == 3
    first = m.first_per_pair(1)
    np.testing.assert_array_equal(first.time, [0, 0])
    np.testing.assert_array_equal(m.between(0.2, 0.5).time, [0.25, 0.5, 0.5])
    np.testing.assert_array_equal(m.pair[m.stacked_order()], [0, 0, 1, 1, 1])


def test_initiation_window_is_the_papers_at_2_hz_and_a_span_of_time_when_faster() -> None:
    # At the paper's rate (both pairs every 0.5 s) 10 per pair and 4.5 s are the same window.
    paper = fd.simulate(fd.paper_scenario("a", 45e3), np.random.default_rng(0)).measurements
    w = paper.initiation_window(10, 4.5)
    ref = paper.first_per_pair(10)
    for field in ("time", "pair", "doppler", "sigma"):
        np.testing.assert_array_equal(getattr(w, field), getattr(ref, field))
    # At 20 Hz (0.1-s steps that do not sum exactly) the span decides: every scan up to 4.5 s.
    t = np.round(np.arange(0, 10, 0.05), 10)
    fast = fd.Measurements.from_arrays(np.repeat(t, 2), np.tile([0, 1], t.size), np.zeros(2 * t.size), 1.0)
    w = fast.initiation_window(10, 4.5)
    np.testing.assert_array_equal(np.unique(w.time), t[t <= 4.5 + 1e-9])
    assert np.count_nonzero(w.pair == 0) == np.count_nonzero(w.pair == 1) == 91
    # Slow or sparse data: the count decides (a pair seen once in the first 4.5 s still gets 10).
    slow = fd.Measurements.from_arrays(np.arange(40.0), np.arange(40) % 2, np.zeros(40), 1.0)
    w = slow.initiation_window(10, 4.5)
    assert np.count_nonzero(w.pair == 0) == np.count_nonzero(w.pair == 1) == 10
    np.testing.assert_array_equal(slow.initiation_window(10, 0.0).time, slow.first_per_pair(10).time)
    for bad in ({"per_pair": 0}, {"seconds": -1.0}, {"seconds": float("inf")}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            slow.initiation_window(**bad)


def test_spread_keeps_every_pair_evenly_with_ends() -> None:
    # A staggered schedule (pairs alternate): taking every 4th scan would keep pair 0 only.
    t = np.arange(400) * 0.25
    m = fd.Measurements.from_arrays(t, np.arange(400) % 2, np.zeros(400), 1.0)
    s = m.spread(10)
    for k in (0, 1):
        ts = s.time[s.pair == k]
        all_k = m.time[m.pair == k]
        assert ts.size == 10
        assert ts[0] == all_k[0] and ts[-1] == all_k[-1]
        # evenly spread: gaps differ by at most one step of that pair's own sequence
        gaps = np.diff(ts)
        assert gaps.max() - gaps.min() <= 0.5 + 1e-12
    assert len(m.spread(1000)) == len(m)  # fewer than asked: all of them
    with pytest.raises(ValueError, match="per_pair"):
        m.spread(1)


def test_a_doppler_shift_in_hz_is_read_with_each_pairs_wavelength(tmp_path: Path) -> None:
    """A file of Doppler shifts in Hz (``doppler_hz``, ``sigma_hz``) reads as the bistatic range rate
    -wavelength * f_D with sigma wavelength * sigma_f, each pair with its own carrier; written by ``csv_text`` with
    the wavelengths it reads back to rounding, and a default sigma is in the file's unit (Hz here)."""
    geom = fd.Geometry(pairs=fd.paper_geometry("a").pairs, wavelengths=(3.0, 0.25))
    hz = _write(tmp_path / "hz.csv", "time,pair,doppler_hz,sigma_hz\n0.0,0,10.0,0.5\n0.0,1,-8.0,2.0\n0.5,0,4.0,1.0\n")
    m = fd.Measurements.from_csv(hz, geometry=geom)
    np.testing.assert_array_equal(m.doppler, [-30.0, 2.0, -12.0])  # -3 * 10, -0.25 * -8, -3 * 4
    np.testing.assert_array_equal(m.sigma, [1.5, 0.5, 3.0])
    no_sigma = _write(tmp_path / "n.csv", "pair,time,doppler_hz\n1,0.0,-8.0\n0,0.0,10.0\n")  # in any order
    np.testing.assert_array_equal(fd.Measurements.from_csv(no_sigma, geometry=geom, default_sigma=4.0).sigma,
                                  [12.0, 1.0])
    with pytest.raises(MeasurementError, match="no sigma_hz column"):
        fd.Measurements.from_csv(no_sigma, geometry=geom)

    sim = fd.simulate(fd.paper_scenarios()[0], np.random.default_rng(3)).measurements
    (tmp_path / "s.csv").write_text(sim.csv_text(wavelengths=geom.wavelengths))
    assert (tmp_path / "s.csv").read_text().startswith("time,pair,doppler_hz,sigma_hz\n")
    back = fd.Measurements.from_csv(tmp_path / "s.csv", geometry=geom)
    np.testing.assert_array_equal(back.time, sim.time)
    np.testing.assert_array_equal(back.pair, sim.pair)
    np.testing.assert_allclose(back.doppler, sim.doppler, rtol=4e-16, atol=0)
    np.testing.assert_allclose(back.sigma, sim.sigma, rtol=4e-16, atol=0)
    with pytest.raises(ValueError, match=r"one for each pair 0\.\.1"):
        sim.csv_text(wavelengths=(3.0,))


@pytest.mark.parametrize("unit", ["m/s", "Hz"])
def test_the_whole_file_reader_and_the_row_by_row_reader_give_the_same_measurements(
        tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch, unit: str) -> None:
    """A plain file is parsed and checked all at once; one padded field (and the rows' checks switched to their
    loop) sends the same file through the careful row-by-row reader: the two give the same measurements to the bit (numbers in every form the format allows,
    interleaved pairs, a Doppler shift in Hz converted), and a problem on the last row of a plain file is still
    named with its line."""
    import fgdoppler.csvfile as csvfile
    import fgdoppler.measurements as measurements

    geom = fd.Geometry(pairs=fd.paper_geometry("a").pairs, wavelengths=(3.0, 0.25)) if unit == "Hz" else \
        fd.paper_geometry("a")
    n = 3000
    t = np.sort(rng.choice(600_000, n, replace=False)) / 1000.0  # distinct: no duplicate (time, pair) by chance
    pair = rng.integers(0, 2, n)
    forms = ("{:.17g}", "{:+.6e}", "{:.3f}", "{:.2E}")
    z = [forms[k % 4].format(v) for k, v in enumerate(rng.normal(0.0, 80.0, n).tolist())]
    z[:3] = ["5.", ".5", "-0"]
    head = "time,pair,doppler_hz,sigma_hz" if unit == "Hz" else "time,pair,doppler,sigma"
    rows = [f"{a!r},{b},{c},{d!r}" for a, b, c, d in zip(t.tolist(), pair.tolist(), z, rng.uniform(0.1, 3.0, n).tolist(), strict=True)]
    order = np.argsort(pair, kind="stable")  # one pair's rows after the other's
    plain = _write(tmp_path / "plain.csv", "\n".join([head, *(rows[i] for i in order)]) + "\n")
    padded_rows = [rows[i] for i in order]
    padded_rows[n // 2] = padded_rows[n // 2].replace(",", " , ", 1)
    padded = _write(tmp_path / "padded.csv", "\n".join([head, *padded_rows]) + "\n")

    careful = {"table": 0, "rows": 0}

    def counted(name: str, module: object, function: str) -> None:
        original = getattr(module, function)

        def spy(*args: object, **kwargs: object) -> object:
            careful[name] += 1
            return original(*args, **kwargs)
        monkeypatch.setattr(module, function, spy)

    counted("table", csvfile, "_checked_values")
    counted("rows", measurements, "_pair")
    fast = fd.Measurements.from_csv(plain, geometry=geom)
    assert careful == {"table": 0, "rows": 0}
    monkeypatch.setattr(measurements, "_valid_pairs", lambda *args: None)  # the rows checked one at a time too
    slow = fd.Measurements.from_csv(padded, geometry=geom)
    assert careful["table"] == 1 and careful["rows"] == n
    for col in ("time", "pair", "doppler", "sigma"):
        np.testing.assert_array_equal(getattr(fast, col), getattr(slow, col))
    expect = np.array([float(v) for v in z]) * (-np.array(geom.wavelengths)[pair] if unit == "Hz" else 1.0)
    np.testing.assert_array_equal(np.sort(fast.doppler), np.sort(expect))

    monkeypatch.undo()  # a bad last row: the whole-file checks must decline it, for the loop to name its line
    last = padded_rows[-1].split(",")
    for bad, msg in (([last[0], last[1], last[2], "0"], "must be > 0"),
                     ([padded_rows[-2].split(",")[0], *last[1:]], "duplicate measurement|is earlier than"),
                     ([last[0], "2", *last[2:]], "unknown pair index 2")):
        broken = _write(tmp_path / "broken.csv", "\n".join([head, *(rows[i] for i in order[:-1]), ",".join(bad)]))
        with pytest.raises(MeasurementError, match=msg) as info:
            fd.Measurements.from_csv(broken, geometry=geom)
        assert f"broken.csv:{n + 1}:" in str(info.value)


@pytest.mark.parametrize(
    ("text", "geometry", "msg"),
    [
        ("time,pair,doppler_hz\n0,0,1\n", None, "needs each pair's carrier wavelength: pass the geometry"),
        ("time,pair,doppler_hz\n0,0,1\n", "a", r"give `wavelength` \(metres, c / f_c\) in every \[\[pair\]\]"),
        # the Hz file's columns go together: a sigma in m/s or a second Doppler column is refused, not mixed
        ("time,pair,doppler_hz,sigma\n0,0,1,1\n", "hz", "unknown column 'sigma'"),
        ("time,pair,doppler,doppler_hz\n0,0,1,1\n", "hz", "unknown column 'doppler'"),
        ("time,pair,doppler,sigma_hz\n0,0,1,1\n", "hz", "unknown column 'sigma_hz'"),
        ("time,pair,doppler_hz,sigma_hz\n0,0,1,0\n", "hz", "hz.csv:2: sigma_hz must be > 0"),
        ("time,pair,doppler_hz,sigma_hz\n0,0,1,1\n0,2,1,1\n", "hz", "hz.csv:3: unknown pair index 2"),
        ("time,pair,doppler_hz,sigma_hz\n0,0,1e9,1\n", "hz",
         r"hz.csv:2: doppler \(-wavelength \* doppler_hz\) -3e\+09 is outside"),
    ],
)
def test_a_file_in_hz_is_refused_without_its_wavelengths_or_with_mixed_columns(
        tmp_path: Path, text: str, geometry: str | None, msg: str) -> None:
    geom = {None: None, "a": fd.paper_geometry("a"),
            "hz": fd.Geometry(pairs=fd.paper_geometry("a").pairs, wavelengths=(3.0, 0.25))}[geometry]
    with pytest.raises(MeasurementError, match=msg):
        fd.Measurements.from_csv(_write(tmp_path / "hz.csv", text), geometry=geom)


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="no named pipes here")
def test_a_file_is_read_once_so_a_pipe_reads_as_the_file(tmp_path: Path) -> None:
    """A named pipe (``fgdoppler track /dev/stdin``) can be read only once: the m/s and the Hz layouts, chosen from
    the header, read through one as from the file.  (A reader that opened the pipe twice would wait for a second
    writer: it runs in a thread that the test unblocks and fails after 30 s.)"""
    import os
    import threading

    geom = fd.Geometry(pairs=fd.paper_geometry("a").pairs, wavelengths=(3.0, 0.25))
    sim = fd.simulate(fd.paper_scenarios()[0], np.random.default_rng(3)).measurements
    for name, text in (("ms", sim.csv_text()), ("hz", sim.csv_text(wavelengths=geom.wavelengths))):
        fifo = tmp_path / f"{name}.pipe"
        os.mkfifo(fifo)
        out: dict[str, object] = {}

        def read(path: Path = fifo, box: dict[str, object] = out) -> None:
            try:
                box["m"] = fd.Measurements.from_csv(path, geometry=geom)
            except Exception as exc:  # reported below
                box["error"] = exc

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        fifo.write_text(text)
        reader.join(timeout=30)
        if reader.is_alive():
            fifo.write_text("")  # let a second open return, then fail
            reader.join(timeout=5)
            pytest.fail("reading the pipe waited for a second writer: the file was opened twice")
        assert "error" not in out, out.get("error")
        direct = fd.Measurements.from_csv(_write(tmp_path / f"{name}.csv", text), geometry=geom)
        for col in ("time", "pair", "doppler", "sigma"):
            np.testing.assert_array_equal(getattr(out["m"], col), getattr(direct, col))
