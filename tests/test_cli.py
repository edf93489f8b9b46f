"""The command line: help everywhere, simulate writes its files, errors exit 2."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

import fgdoppler as fd
import fgdoppler.estimators.results
from fgdoppler.cli import build_parser, main


def test_help_on_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    names = list(sub.choices)  # type: ignore[union-attr]
    assert "simulate" in names
    for name in [None, *names]:
        with pytest.raises(SystemExit) as info:
            main(["--help"] if name is None else [name, "--help"])
        assert info.value.code == 0
        assert "usage" in capsys.readouterr().out


def test_huber_alone_is_the_efficient_threshold() -> None:
    from fgdoppler.models.robust import EFFICIENT_K

    parser = build_parser()
    for command in (["track", "m.csv", "--geometry", "g.toml"], ["montecarlo", "--case", "a"]):
        assert parser.parse_args([*command, "--huber"]).huber == EFFICIENT_K
        assert parser.parse_args([*command, "--huber", "2.5"]).huber == 2.5
        assert parser.parse_args(command).huber is None


def test_simulate_writes_three_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", "--case", "a", "--start-x", "25000", "--seed", "1", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["measurements"] == 122
    geom = fd.Geometry.from_toml(out / "geometry.toml")
    assert geom == fd.paper_geometry("a")
    m = fd.Measurements.from_csv(out / "measurements.csv", geometry=geom)
    t = fd.Trajectory.from_csv(out / "truth.csv")
    assert len(m) == 122 and t.states.shape == (61, 4)


def test_simulate_says_when_the_start_lies_outside_the_trackers_zone(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Case a's default zone ends 48 km along the baseline.  A start at 60 km is outside it: simulate says so and
    gives the zone that holds it; simulated again in that zone, nothing is said, and geometry.toml keeps the zone.
    The same for a speed above the bound.  Inside the zone (the defaults), nothing is said."""
    assert main(["simulate", "--case", "a", "--out", str(tmp_path / "in"), "--json"]) == 0
    out, err = capsys.readouterr()
    assert "zone_holding_start" not in json.loads(out) and "zone" not in err
    for start in (["--start-x", "60000"], ["--velocity", "10", "-300"]):
        assert main(["simulate", "--case", "a", *start, "--out", str(tmp_path / "far"), "--json"]) == 0
        out, err = capsys.readouterr()
        advice = json.loads(out)["zone_holding_start"]
        assert err.startswith("note: the start lies outside the zone") and advice in err
        words = advice.split()
        assert main(["simulate", "--case", "a", *start, *words, "--out", str(tmp_path / "wide"), "--json"]) == 0
        out, err = capsys.readouterr()
        assert "zone_holding_start" not in json.loads(out) and "zone" not in err
        geom = fd.Geometry.from_toml(tmp_path / "wide" / "geometry.toml")
        assert geom.zone.options() == advice
    # a Monte Carlo study runs where it is asked to, and says the same of each start outside the zone
    assert main(["montecarlo", "--case", "a", "--start-x", "25000", "60000", "--runs", "1", "--estimators", "ekf",
                 "--out", str(tmp_path / "mc")]) == 0
    err = capsys.readouterr().err
    assert err.count("note:") == 1 and "start 60 km: the start lies outside the zone" in err
    assert "--zone 2000 74500 -5000 5000" in err


def test_simulate_bad_geometry_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--case", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "error" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_observability_cli_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["observability", "--group", "1", "--json", "--plot", str(tmp_path / "m.png")]) == 0
    d = json.loads(capsys.readouterr().out)
    assert len(d["x"]) == 97 and len(d["heading_deg"]) == 36 and d["min"] == -40.0
    assert (tmp_path / "m.png").stat().st_size > 0
    assert main(["observability", "--table", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert len(rows) == 8 and all(abs(r["max"] - r["paper_max"]) <= 0.05 for r in rows)
    assert main(["observability", "--slice", "180", "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)["curves"]) == {"group 2", "group 4"}
    assert main(["observability", "--report", "45000", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "ok"


@pytest.mark.parametrize(("options", "message"), [
    (["--report", "20000", "--speeds", "50"], "--speeds does not apply to --report"),
    (["--report", "20000", "--headings", "0", "90", "10", "--samples", "3"], "--headings, --samples do not apply to "
                                                                             "--report"),
    (["--slice", "180", "--speeds", "50"], "--speeds does not apply to --slice"),
    (["--table", "--velocity", "10", "-100"], "--velocity does not apply to --table"),
    (["--table", "--group", "2"], "--group does not apply to --table"),
    (["--table", "--offset", "500"], "--offset applies to --table with --geometry"),
    (["--start-z", "100"], "--start-z does not apply to the map (the default mode)"),
    (["--duration", "60"], "--duration does not apply to the map (the default mode)"),
    (["--report-lat-lon", "51.7", "0.1", "--offset", "5"], "--offset does not apply to --report-lat-lon"),
    (["--group", "3", "--geometry", "b", "--report", "20000"], "--group sets --geometry and --offset"),
])
def test_observability_refuses_an_option_its_mode_does_not_read(capsys: pytest.CaptureFixture[str],
                                                                options: list[str], message: str) -> None:
    """Each mode reads its own options; one it does not read is refused in one line (it was dropped silently: a
    report with --speeds, a table with --velocity), before any work."""
    assert main(["observability", *options]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_observability_group_sets_geometry_and_offset_in_every_mode_that_reads_it(
        capsys: pytest.CaptureFixture[str]) -> None:
    """``--group 3`` is case b on the baseline: the report (which used to ignore it and report on case a at 2 km)
    and the map equal --geometry b --offset 0."""
    for mode in (["--report", "20000"], ["--x", "5000", "9000", "2000", "--headings", "0", "90", "45"]):
        assert main(["observability", "--group", "3", *mode, "--json"]) == 0
        by_group = json.loads(capsys.readouterr().out)
        assert main(["observability", "--geometry", "b", "--offset", "0", *mode, "--json"]) == 0
        assert by_group == json.loads(capsys.readouterr().out)
    assert by_group["y"] == 0.0


def test_observability_cli_bad_grid(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["observability", "--x", "5000", "1000", "500"]) == 2
    assert "bad grid" in capsys.readouterr().err


def test_track_init_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim"
    main(["simulate", "--case", "b", "--start-x", "5000", "--out", str(out)])
    capsys.readouterr()
    args = ["track", str(out / "measurements.csv"), "--geometry", str(out / "geometry.toml"), "--estimator", "init"]
    assert main([*args, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n_measurements"] == 20 and len(d["x_end"]) == 4 and d["method"] == "lm"
    assert main([*args, "--truth", str(out / "truth.csv"), "--plot", str(tmp_path / "land.png")]) == 0
    assert "error at t_end" in capsys.readouterr().out
    assert (tmp_path / "land.png").stat().st_size > 0
    # The region bound is on by default and switchable; a start well inside the zone
    # does not touch it, so both give the same estimate.
    assert main([*args, "--json", "--no-region-bound"]) == 0
    free = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(free["x_start"], d["x_start"], atol=1e-6)
    assert d["objective"] >= d["cost"]


def test_an_unused_sigma_option_is_said_and_a_used_one_is_used(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """``--sigma`` is the default for a file without a sigma column: with the column it goes unused, and a note on
    stderr says so (nothing the user gave is dropped silently); without it, it is every measurement's sigma (the
    initiation's cost scales as 1/sigma^2)."""
    out = tmp_path / "sim"
    main(["simulate", "--case", "b", "--start-x", "5000", "--out", str(out)])
    capsys.readouterr()
    geometry = ["--geometry", str(out / "geometry.toml"), "--estimator", "init", "--json"]
    assert main(["track", str(out / "measurements.csv"), *geometry, "--sigma", "2"]) == 0
    captured = capsys.readouterr()
    assert f"note: --sigma 2 is not used: {out / 'measurements.csv'} gives each measurement's sigma (its sigma " \
           "column)" in captured.err
    with_column = json.loads(captured.out)
    rows = (out / "measurements.csv").read_text().splitlines()
    assert rows[0] == "time,pair,doppler,sigma" and all(r.endswith(",1.0") for r in rows[1:])
    (tmp_path / "bare.csv").write_text("\n".join(r.rsplit(",", 1)[0] for r in rows) + "\n")
    assert main(["track", str(tmp_path / "bare.csv"), *geometry, "--sigma", "1"]) == 0
    captured = capsys.readouterr()
    assert "note: --sigma" not in captured.err
    assert json.loads(captured.out)["cost"] == pytest.approx(with_column["cost"], rel=1e-9)
    # without the weak prior the data alone set the optimum: the same start (to LM's stopping tolerance, a few cm),
    # the cost a quarter
    unit = [*geometry, "--no-weak-prior"]
    assert main(["track", str(tmp_path / "bare.csv"), *unit, "--sigma", "1"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert main(["track", str(tmp_path / "bare.csv"), *unit, "--sigma", "2"]) == 0
    two = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(two["x_start"], one["x_start"], rtol=1e-4)
    assert two["cost"] == pytest.approx(one["cost"] / 4, rel=1e-4)


def test_an_extra_column_is_refused_unless_named_to_skip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A receiver's SNR column: ``track`` refuses the file (exit 2, the column named), reads it with
    ``--ignore-column snr`` as the file without it, and will not skip a column it reads."""
    out = tmp_path / "sim"
    main(["simulate", "--case", "b", "--start-x", "5000", "--out", str(out)])
    capsys.readouterr()
    rows = (out / "measurements.csv").read_text().splitlines()
    (tmp_path / "snr.csv").write_text("\n".join([rows[0] + ",snr", *(f"{r},{12 + k % 7}" for k, r in
                                                                     enumerate(rows[1:]))]) + "\n")
    args = ["--geometry", str(out / "geometry.toml"), "--estimator", "init", "--json"]
    assert main(["track", str(tmp_path / "snr.csv"), *args]) == 2
    assert "unknown column 'snr'" in capsys.readouterr().err
    assert main(["track", str(out / "measurements.csv"), *args]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(["track", str(tmp_path / "snr.csv"), *args, "--ignore-column", "snr"]) == 0
    assert json.loads(capsys.readouterr().out)["x_start"] == plain["x_start"]
    assert main(["track", str(tmp_path / "snr.csv"), *args, "--ignore-column", "snr", "--ignore-column", "sigma"]) == 2
    assert "cannot ignore 'sigma'" in capsys.readouterr().err


def test_a_recording_in_hz_tracks_as_the_same_recording_in_metres_per_second(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``simulate --wavelength`` writes the geometry's wavelengths and the Doppler in Hz (-range rate / wavelength,
    each pair with its own); ``track`` reads them back, says so, and its track is that of the same recording in
    m/s to rounding (the conversion round-trips to a few units in the last place).  A wrong count of wavelengths
    or a frequency given for one exits 2."""
    for name, extra in (("ms", []), ("hz", ["--wavelength", "3.05", "0.5"])):
        assert main(["simulate", "--case", "a", "--start-x", "40000", "--seed", "5", "--out", str(tmp_path / name),
                     *extra]) == 0
    capsys.readouterr()
    geom = fd.Geometry.from_toml(tmp_path / "hz" / "geometry.toml")
    assert geom.wavelengths == (3.05, 0.5)
    assert (tmp_path / "hz" / "measurements.csv").read_text().startswith("time,pair,doppler_hz,sigma_hz\n")
    ms = fd.Measurements.from_csv(tmp_path / "ms" / "measurements.csv")
    hz = np.loadtxt(tmp_path / "hz" / "measurements.csv", delimiter=",", skiprows=1)
    lam = np.array([3.05, 0.5])[hz[:, 1].astype(int)]
    np.testing.assert_allclose(hz[:, 2], -ms.doppler / lam, rtol=1e-15)
    np.testing.assert_allclose(hz[:, 3], ms.sigma / lam, rtol=1e-15)
    tracks = {}
    for name in ("ms", "hz"):
        args = ["track", str(tmp_path / name / "measurements.csv"), "--estimator", "ekf"]
        assert main(args) == 0
        text = capsys.readouterr().out
        assert ("doppler_hz read as the bistatic range rate -wavelength * doppler_hz, with wavelengths 3.05, 0.5 m"
                in text) == (name == "hz")
        assert main([*args, "--json"]) == 0
        tracks[name] = json.loads(capsys.readouterr().out)
    assert [p.get("wavelength") for p in tracks["hz"]["geometry"]["pairs"]] == [3.05, 0.5]
    assert tracks["hz"]["status"] == tracks["ms"]["status"]
    np.testing.assert_allclose(tracks["hz"]["states"], tracks["ms"]["states"], rtol=1e-6, atol=1e-6)
    assert main(["simulate", "--wavelength", "1", "2", "3", "--out", str(tmp_path / "x")]) == 2
    assert "--wavelength takes one value or one per pair (2), got 3" in capsys.readouterr().err
    assert main(["simulate", "--wavelength", "98.3e6", "--out", str(tmp_path / "x")]) == 2
    assert "the wavelength is 3.04977 m" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    # a geometry that gives its wavelengths: --wavelength replaces them, and a note says which were replaced
    again = ["simulate", "--geometry", str(tmp_path / "hz" / "geometry.toml"), "--out", str(tmp_path / "y")]
    assert main([*again, "--wavelength", "2"]) == 0
    assert ("note: --wavelength replaces the geometry's wavelengths (3.05, 0.5 m) with 2, 2 m in the files written"
            in capsys.readouterr().err)
    assert fd.Geometry.from_toml(tmp_path / "y" / "geometry.toml").wavelengths == (2.0, 2.0)
    assert main([*again, "--wavelength", "3.05", "0.5"]) == 0
    assert "note" not in capsys.readouterr().err


@pytest.mark.parametrize(
    ("content", "msg"),
    [
        ("time,pair,doppler,sigma\n0,0,abc,1\n", ":2: doppler is not a number"),
        ("time,pair,doppler,sigma\n0,5,1,1\n", ":2: unknown pair index 5"),
        ("", "empty measurement file"),
    ],
)
def test_track_malformed_input_exits_2_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, msg: str
) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(content)
    out = tmp_path / "track.csv"
    assert main(["track", str(bad), "--geometry", "a", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and msg in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


@pytest.mark.parametrize("estimator", ["ekf", "isam2", "fixed-lag", "smoother"])
def test_track_every_estimator_json_out_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 estimator: str) -> None:
    sim = tmp_path / "sim"
    main(["simulate", "--case", "b", "--start-x", "5000", "--seed", "3", "--out", str(sim)])
    capsys.readouterr()
    args = ["track", str(sim / "measurements.csv"), "--geometry", "b", "--estimator", estimator,
            *(["--lag", "3"] if estimator == "fixed-lag" else [])]
    assert main([*args, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["estimator"] == estimator
    n = len(d["times"])
    assert n > 10 and len(d["states"]) == n and len(d["covariances"]) == n
    assert all(len(s) == 4 for s in d["states"])
    assert all(c is None or (len(c) == 4 and all(len(r) == 4 for r in c)) for c in d["covariances"])
    if estimator == "smoother":  # the default: `track FILE` with no --estimator reconstructs the whole track
        default = [a for a in args if a not in ("--estimator", estimator)]
        assert main([*default, "--json"]) == 0
        d_default = json.loads(capsys.readouterr().out)
        assert d_default["estimator"] == "smoother" and d_default["states"] == d["states"]
    out = tmp_path / "track.csv"
    assert main([*args, "--out", str(out), "--truth", str(sim / "truth.csv"), "--plot", str(tmp_path / "t.png")]) == 0
    assert "position RMSE vs truth" in capsys.readouterr().out
    back = fd.estimators.results.TrackResult.read_csv(out)
    assert back.states.shape == (n, 4)
    assert json.loads(out.with_suffix(".json").read_text())["estimator"] == estimator
    assert (tmp_path / "t.png").stat().st_size > 0


def test_montecarlo_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stem = tmp_path / "mc"
    assert main(["montecarlo", "--case", "a", "--start-x", "45000", "--runs", "2", "--workers", "1",
                 "--estimators", "lm", "ekf", "--out", str(stem), "--json", "--plot", str(tmp_path / "r.png")]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["runs"] == 2 and d["estimators"] == ["lm", "ekf"]
    assert (tmp_path / "mc.npz").exists() and (tmp_path / "r.png").stat().st_size > 0
    assert main(["montecarlo", "--estimators", "ukf", "--runs", "1", "--out", str(stem)]) == 2
    assert "unknown estimator" in capsys.readouterr().err


# -- geometries and zones (issue: your sensors, your frame) ---------------------------------
def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_track_never_assumes_a_geometry(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sim = tmp_path / "sim"
    assert main(["simulate", "--geometry", "b", "--start-x", "5000", "--out", str(sim)]) == 0
    capsys.readouterr()
    # alone in a folder: refused, with the way out named
    lone = tmp_path / "lone"
    lone.mkdir()
    (lone / "m.csv").write_text((sim / "measurements.csv").read_text())
    assert main(["track", str(lone / "m.csv"), "--estimator", "ekf", "--out", str(lone / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert "no geometry" in err and "--geometry" in err and err.count("\n") == 1
    assert _files(lone) == ["m.csv"]
    # a mistyped file name is named as such, not as a missing geometry
    assert main(["track", str(lone / "n.csv")]) == 2
    err = capsys.readouterr().err
    assert f"{lone / 'n.csv'}: cannot read: No such file or directory" in err and "geometry" not in err
    # a readable file's contents wait for the geometry: pairs given by name are not a mistake without it
    (lone / "named.csv").write_text("time,pair,doppler,sigma\n0,north,10,1\n")
    assert main(["track", str(lone / "named.csv")]) == 2
    assert "no geometry" in capsys.readouterr().err
    (lone / "named.csv").unlink()
    # beside the file: found and named in the summary and the outputs
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "ekf", "--out", str(tmp_path / "t.csv")]) == 0
    out = capsys.readouterr().out
    assert f"geometry {sim / 'geometry.toml'} (2 pair(s))" in out and "zone along 2000..48000 m" in out
    header = [ln for ln in (tmp_path / "t.csv").read_text().splitlines() if ln.startswith("#")]
    assert any("geometry.toml" in ln for ln in header) and any(ln.startswith("# zone: along=[2000.0, 48000.0]")
                                                                for ln in header)
    js = json.loads((tmp_path / "t.json").read_text())
    assert js["geometry"]["source"].endswith("geometry.toml") and js["zone"]["across"] == [-5000.0, 5000.0]


def test_a_file_that_cannot_be_read_is_refused_before_the_estimators_load(tmp_path: Path) -> None:
    """A mistyped name is refused in the reader's words, with or without a geometry, and before the estimators are
    imported (they take a second or more to load; the user waits for nothing).  A fresh interpreter, so that no
    earlier test has imported them already."""
    import subprocess
    import sys

    missing = tmp_path / "typo.csv"
    code = ("import sys; from fgdoppler.cli.main import main; "
            f"status = main(['track', {str(missing)!r}, '--geometry', 'a', '--estimator', 'ekf']); "
            "print(status, 'fgdoppler.estimators.initiation' in sys.modules, 'gtsam' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.split() == ["2", "False", "False"]
    assert proc.stderr.strip() == f"fgdoppler track: error: {missing}: cannot read: No such file or directory"
    # a folder given as FILE: the same words, whatever the geometry
    assert main(["track", str(tmp_path), "--geometry", "b"]) == 2


def test_zone_options_and_the_zone_table_are_used(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sim = tmp_path / "sim"
    # simulate writes the zone options into the geometry file's [zone] table
    assert main(["simulate", "--start-x", "44000", "--start-y", "7000", "--velocity", "-40", "-100",
                 "--zone", "2000", "48000", "-5000", "12000", "--out", str(sim)]) == 0
    assert fd.Geometry.from_toml(sim / "geometry.toml").zone.across == (-5e3, 12e3)
    capsys.readouterr()
    args = ["track", str(sim / "measurements.csv"), "--estimator", "init", "--json"]
    assert main(args) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["zone"]["across"] == [-5000.0, 12000.0] and d["zone"]["speed_max"] == 200.0
    # command-line options go on top of the table
    assert main([*args, "--speed-max", "350", "--zone", "0", "50000", "-6000", "15000", "--grid-step", "2000"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["zone"]["along"] == [0.0, 50000.0] and d["zone"]["across"] == [-6000.0, 15000.0]
    assert d["zone"]["speed_max"] == 350.0


def test_a_fast_target_needs_and_gets_a_higher_speed_bound(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sim = tmp_path / "sim"
    assert main(["simulate", "--start-x", "20000", "--velocity", "1400", "-1400", "--duration", "10",
                 "--out", str(sim)]) == 0
    capsys.readouterr()
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "init", "--out", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert "--speed-max" in err and err.count("\n") == 1 and str(sim / "measurements.csv") in err
    assert _files(tmp_path) == ["sim"]
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "init", "--speed-max", "2500", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert np.hypot(*d["x_start"][2:]) > 1500


@pytest.mark.parametrize(
    ("options", "match"),
    [
        (["--zone", "48000", "2000", "-5000", "5000"], "empty or inverted"),
        (["--zone", "2000", "48000", "5000", "5000"], "empty or inverted"),
        (["--zone", "2000", "nan", "-5000", "5000"], "finite"),
        (["--zone", "2000", "inf", "-5000", "5000"], "finite"),
        (["--zone", "5e8", "6e8", "0", "1"], "from the nearest sensor"),
        (["--speed-max", "0"], "speed_max"),
        (["--speed-max", "-3"], "speed_max"),
        (["--grid-step", "0"], "position_step"),
        (["--speed-step", "-1"], "speed_step"),
    ],
)
def test_bad_zones_are_refused_in_one_line_and_nothing_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], options: list[str], match: str) -> None:
    sim = tmp_path / "sim"
    main(["simulate", "--out", str(sim)])
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "ekf", *options,
                 "--out", str(out / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_bad_zone_table_is_refused_with_file_and_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sim = tmp_path / "sim"
    main(["simulate", "--out", str(sim)])
    capsys.readouterr()
    geometry = sim / "geometry.toml"
    geometry.write_text('name = "a"\n[zone]\nacross = [5000.0, -5000.0]\n[[pair]]\ntx = [50000.0, 0.0]\n'
                        'rx = [0.0, 0.0]\n[[pair]]\ntx = [50000.0, 1000.0]\nrx = [0.0, 0.0]\n')
    assert main(["track", str(sim / "measurements.csv"), "--out", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert f"{geometry}:3:" in err and "empty or inverted" in err
    assert not (tmp_path / "t.csv").exists()


def test_montecarlo_and_observability_on_a_geometry_of_ones_own(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    geometry = tmp_path / "three.toml"
    fd.Geometry(pairs=(fd.BistaticPair(tx=(40e3, 0.0), rx=(0.0, 0.0)),
                       fd.BistaticPair(tx=(40e3, 0.0), rx=(15e3, 25e3)),
                       fd.BistaticPair(tx=(5e3, 30e3), rx=(0.0, 0.0)))).to_toml(geometry)
    assert main(["montecarlo", "--geometry", str(geometry), "--start-x", "20000", "--start-y", "10000",
                 "--velocity", "-60", "70", "--offsets", "0", "0.2", "0.35", "--runs", "2", "--workers", "1",
                 "--estimators", "lm", "ekf", "--out", str(tmp_path / "mc"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["scenarios"] == [f"{geometry}, start 20 km, y 10 km"] and d["estimators"] == ["lm", "ekf"]
    assert all(r["pos_rmse_mean"] is not None for r in d["rows"])
    assert main(["observability", "--geometry", str(geometry), "--offset", "10000", "--json"]) == 0
    m = json.loads(capsys.readouterr().out)
    assert len(m["x"]) == 97 and m["x"][0] == pytest.approx(800.0)  # D = 40 km: D/50 .. D - D/50 every D/100
    assert main(["observability", "--geometry", str(geometry), "--offset", "10000", "--table", "--speeds", "100",
                 "50", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["speed"] for r in rows] == [100.0, 50.0] and rows[0]["max"] > rows[1]["max"]
    assert main(["observability", "--geometry", str(geometry), "--report", "20000", "--offset", "10000",
                 "--velocity", "-60", "70", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "ok"


def test_the_report_on_a_moved_and_rotated_geometry_takes_its_start_in_the_geometrys_coordinates(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``observability --report``'s start and velocity are in the geometry's own coordinates, as ``simulate``'s:
    case a rotated by 30 degrees and moved, with the paper's start and velocity rotated and moved alike, gives the
    paper's report — the weakest direction's sigma and each pair's angle to its ellipse tangent, which no rigid
    motion changes, O and the conditioning — and its first line says so; the pairs are named by the 0-based
    indices of the measurement file (they were once numbered from 1)."""
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    R, shift = np.array([[c, -s], [s, c]]), np.array([5e3, -3e3])
    A = fd.paper_geometry("a")
    fd.Geometry(pairs=tuple(fd.BistaticPair(tx=tuple(R @ p.tx + shift), rx=tuple(R @ p.rx + shift))
                            for p in A.pairs)).to_toml(tmp_path / "turned.toml")
    start, velocity = R @ np.array([25e3, 2e3]) + shift, R @ np.array([10.0, -100.0])
    common = ["observability", "--velocity", *map(repr, map(float, velocity))]
    turned = [*common, "--geometry", str(tmp_path / "turned.toml"), "--report", repr(float(start[0])), "--offset",
              repr(float(start[1]))]
    assert main(turned) == 0
    text = capsys.readouterr().out
    assert "km in the geometry's x, y: status ok" in text.splitlines()[0]
    assert "first/last: pair 0: " in text and ", pair 1: " in text and "pair 2" not in text
    assert main([*turned, "--json"]) == 0
    moved = json.loads(capsys.readouterr().out)
    assert main(["observability", "--report", "25000", "--velocity", "10", "-100", "--json"]) == 0
    paper = json.loads(capsys.readouterr().out)
    for key in ("weakest_std", "tangent_angle_deg", "O_x0", "cond_JtJ"):
        assert np.allclose(moved[key], paper[key], rtol=1e-6, atol=1e-6), key


def test_track_reports_the_verdict_on_stderr_and_exits_3_when_failed(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    sim = tmp_path / "sim"
    main(["simulate", "--start-x", "45000", "--out", str(sim)])
    capsys.readouterr()
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "smoother", "--json"]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("fgdoppler track: status ok") and json.loads(captured.out)["status"] == "ok"
    # the same recording with every Doppler 50 sigma off: the track cannot explain the data
    m = fd.Measurements.from_csv(sim / "measurements.csv")
    noisy = fd.Measurements(time=m.time, pair=m.pair, doppler=m.doppler + 50.0 * np.sin(7.0 * m.time), sigma=m.sigma)
    noisy.to_csv(sim / "noisy.csv")
    out = tmp_path / "t.csv"
    assert main(["track", str(sim / "noisy.csv"), "--estimator", "ekf", "--out", str(out)]) == 3
    err = capsys.readouterr().err
    assert "status failed" in err and "exit status 3" in err
    assert out.exists()  # the outputs are written so that they can be looked at
    assert main(["track", str(sim / "noisy.csv"), "--estimator", "ekf", "--allow-failed"]) == 0


def test_track_particle_and_seed_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--particles, --no-rescue and --check-every reach the particle estimators and --seed (old name --particle-seed) every
    tracker; the seed alone changes the random numbers."""
    sim = tmp_path / "sim"
    main(["simulate", "--case", "b", "--start-x", "5000", "--seed", "3", "--out", str(sim)])
    capsys.readouterr()
    base = ["track", str(sim / "measurements.csv"), "--geometry", "b", "--json"]

    def last_state(*extra: str) -> tuple[list[float], str]:
        assert main([*base, *extra]) == 0
        d = json.loads(capsys.readouterr().out)
        return d["states"][-1], " ".join(e["message"] for e in d["events"])

    x1, events = last_state("--estimator", "map", "--particles", "256", "--seed", "3")
    assert "256 particles" in events
    assert last_state("--estimator", "map", "--particles", "256", "--particle-seed", "3")[0] == x1  # the old name
    assert main([*base, "--estimator", "map", "--particles", "256", "--seed", "3", "--no-rescue"]) == 0
    unrescued = json.loads(capsys.readouterr().out)
    assert unrescued["settings"]["mode_rescue"] is False
    # on the paper's recordings the rescue never acts (docs "Particles that miss the peak"): the same track
    assert unrescued["states"][-1] == x1 and "missed the posterior's peak" not in events
    x2, _ = last_state("--estimator", "particle", "--particles", "256", "--seed", "3")
    x3, _ = last_state("--estimator", "particle", "--particles", "256", "--seed", "4")
    assert x2 != x3  # another seed, another Monte Carlo sample of the same posterior
    assert main([*base, "--estimator", "particle", "--particles", "256", "--seed", "3", "--no-rescue"]) == 0
    unrescued = json.loads(capsys.readouterr().out)
    # the particle estimator rescues in space only by default: in the plane --no-rescue leaves the track alone
    assert unrescued["settings"]["mode_rescue"] is False and unrescued["states"][-1] == x2
    # the restart test at every checkpoint (by default in space only): here the data so far never point to
    # another basin, so it restarts nothing and the track is the one of the test made only where surprised
    for flag, value in (("--check-every", True), ("--no-check-every", False)):
        assert main([*base, "--estimator", "map", "--particles", "256", "--seed", "3", flag]) == 0
        checked = json.loads(capsys.readouterr().out)
        assert checked["settings"]["check_every"] is value and checked["states"][-1] == x1
        assert not any("online re-initiation" in e["message"] for e in checked["events"])
    assert main([*base, "--estimator", "ekf", "--seed", "9"]) == 0
    assert json.loads(capsys.readouterr().out)["settings"]["seed"] == 9  # every tracker takes it
    for bad, msg in ((["--estimator", "particle", "--particles", "10"], "n_particles must be >= 64"),
                     (["--estimator", "map", "--particle-seed", "-1"], "seed must be a whole number"),
                     (["--estimator", "smoother", "--seed", "-2"], "seed must be a whole number"),
                     (["--estimator", "ekf", "--particles", "512"], "not to ekf"),
                     (["--estimator", "init", "--particles", "512"], "not to init"),
                     (["--estimator", "init", "--seed", "1"], "not to init"),
                     (["--estimator", "ekf", "--no-rescue"],
                      "--no-rescue applies to the particle estimators (particle, map), not to ekf"),
                     (["--estimator", "init", "--no-rescue"], "--no-rescue applies to --estimator particle or map, not to init"),
                     (["--estimator", "ekf", "--check-every"],
                      "--check-every applies to the particle estimators (particle, map), not to ekf"),
                     (["--estimator", "init", "--no-check-every"],
                      "--check-every applies to --estimator particle or map, not to init"),
                     (["--particles", "512"], "not to smoother")):
        assert main([*base[:-1], *bad]) == 2  # without --json the initiation would print the geometry first
        captured = capsys.readouterr()
        assert msg in captured.err and "geometry" not in captured.out  # refused before any work


def _with_and_without_most_likely(tmp_path: Path, capsys: pytest.CaptureFixture[str], estimator: str
                                  ) -> tuple[dict, dict]:
    """``track --json`` of ``estimator`` on a case a 25 km recording (seed 2), by default and with ``--most-likely``."""
    sim = tmp_path / "sim"
    main(["simulate", "--case", "a", "--start-x", "25000", "--seed", "2", "--out", str(sim)])
    capsys.readouterr()
    base = ["track", str(sim / "measurements.csv"), "--geometry", "a", "--estimator", estimator, "--json"]

    def run(*extra: str) -> dict:
        assert main([*base, *extra]) == 0
        return json.loads(capsys.readouterr().out)

    return run(), run("--most-likely")


def test_track_most_likely_reports_the_smoothers_mode(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Case a 25 km: by default the smoother reports the posterior mean there, ``--most-likely`` its mode.

    The two tracks differ by one start offset carried by the constant-velocity
    model (spread's "Skewed valleys"), the finding says which was reported, and
    the option is refused, before any work, by every other estimator.
    """
    mean, mode = _with_and_without_most_likely(tmp_path, capsys, "smoother")
    said = [r["message"] for r in mean["reasons"] if r["code"] == "nonlinear"]
    assert len(said) == 1 and "posterior mean" in said[0]
    assert not any(r["code"] == "nonlinear" for r in mode["reasons"])
    # apart by more than a fifth of a sigma (the rule's squared whitened shift 0.05) and far less than one:
    # measured 0.110-0.128 with sampler seeds 0-5, whose Monte Carlo error moves the position alone by 4-46 m
    d = np.subtract(mean["states"][0], mode["states"][0])
    assert 0.05 < d @ np.linalg.solve(np.array(mode["covariances"][0]), d) < 1.0
    assert main(["track", str(tmp_path / "sim" / "measurements.csv"), "--geometry", "a", "--estimator", "ekf",
                 "--most-likely"]) == 2
    captured = capsys.readouterr()
    assert "--most-likely applies to the smoother and map, not to ekf" in captured.err and "geometry" not in captured.out


def test_track_most_likely_reports_maps_mode_at_every_scan(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Case a 25 km: ``map`` reports the posterior mean where it is skewed, ``--most-likely`` the mode throughout.

    Both runs draw the same particles, so the two tracks differ exactly at the reports the default read at the
    mean, which its closing event counts.
    """
    default, mode = _with_and_without_most_likely(tmp_path, capsys, "map")
    said = re.search(r"or at its mean where the posterior is skewed \((\d+) of (\d+)\)", default["events"][-1]["message"])
    assert said is not None
    assert "estimates at the posterior mode" in mode["events"][-1]["message"]
    assert "its mean" not in mode["events"][-1]["message"]
    differ = ~np.all(np.equal(default["states"], mode["states"]), axis=1)
    assert int(said.group(2)) == differ.size and 0 < int(said.group(1)) == int(np.sum(differ))
    assert mode["settings"]["posterior_mean"] is False


def test_track_mode_candidates_reach_the_smoothers_settings(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    """``--mode-candidates N`` sets ``SmootherSettings.mode_candidates``, ``0`` turns the mode search off; the
    option is refused, before any work, by every other estimator and below 0."""
    sim = tmp_path / "sim"
    main(["simulate", "--case", "a", "--start-x", "45000", "--seed", "2", "--out", str(sim)])
    capsys.readouterr()
    base = ["track", str(sim / "measurements.csv"), "--geometry", "a", "--estimator", "smoother", "--json"]
    defaults = fd.SmootherSettings()
    for extra, search, candidates in (([], defaults.mode_search, defaults.mode_candidates),
                                      (["--mode-candidates", "0"], False, defaults.mode_candidates),
                                      (["--mode-candidates", "7"], True, 7)):
        assert main([*base, *extra]) == 0
        settings = json.loads(capsys.readouterr().out)["settings"]
        assert (settings["mode_search"], settings["mode_candidates"]) == (search, candidates)
    for bad, msg in ((["--estimator", "ekf", "--mode-candidates", "5"], "--mode-candidates applies to the smoother"),
                     (["--estimator", "smoother", "--mode-candidates", "-1"], "--mode-candidates must be >= 0"),
                     (["--estimator", "init", "--mode-candidates", "5"],
                      "--mode-candidates applies to the smoother, not to init")):
        assert main([*base[:-3], *bad]) == 2
        captured = capsys.readouterr()
        assert msg in captured.err and "geometry" not in captured.out


def test_track_prints_the_closing_event_even_past_the_limit(capsys: pytest.CaptureFixture[str]) -> None:
    """Past ten events the summary shows the first nine, how many it leaves out, and the run's closing one."""
    from fgdoppler.cli.track import _print_events
    from fgdoppler.estimators.verdict import Event

    events = [Event(time=float(k), message=f"gate {k}") for k in range(14)] + [Event(time=30.0, message="closing")]
    _print_events(events)
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split(": ", 1)[1] for ln in lines[:9]] == [f"gate {k}" for k in range(9)]
    assert "5 more event(s)" in lines[9] and lines[10].endswith("closing") and len(lines) == 11
    _print_events(events[:10])
    assert len(capsys.readouterr().out.splitlines()) == 10  # at the limit: all of them, nothing left out


def test_a_manoeuvring_target_is_simulated_and_its_track_reported_doubtful(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    sim = tmp_path / "sim"
    assert main(["simulate", "--start-x", "45000", "--turn-rate", "2", "--acceleration", "0.5",
                 "--manoeuvre-onset", "10", "--out", str(sim)]) == 0
    truth = fd.Trajectory.from_csv(sim / "truth.csv")
    speed = np.hypot(truth.states[:, 2], truth.states[:, 3])
    heading = np.degrees(np.unwrap(np.arctan2(truth.states[:, 2], truth.states[:, 3])))
    np.testing.assert_allclose(speed[-1] - speed[0], 0.5 * 20.0, rtol=1e-9)  # 0.5 m/s^2 for the last 20 s
    np.testing.assert_allclose(heading[-1] - heading[0], 2.0 * 20.0, rtol=1e-9)  # 2 deg/s clockwise
    capsys.readouterr()
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "smoother", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "doubtful"
    assert any(r["code"] == "manoeuvre" and r["status"] == "doubtful" for r in result["reasons"])
    # values a manoeuvre cannot have are refused naming the option, and nothing is written
    for bad, option in ((["--turn-rate", "nan"], "--turn-rate"), (["--manoeuvre-onset", "-1"], "--manoeuvre-onset"), (["--acceleration", "-10"], "stops the target"),
                        (["--acceleration", "1", "--process-noise", "0.5"], "--process-noise")):
        out = tmp_path / "bad"
        assert main(["simulate", *bad, "--out", str(out)]) == 2
        assert option in capsys.readouterr().err and not out.exists()


def test_offsets_are_simulated_and_the_trackers_told_of_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # simulate --bias offsets each pair's measurements; track --bias-sigma widens a Gaussian tracker's covariances
    # by what such offsets do (the track itself unchanged), changes the particle estimators' model, and is
    # refused where it does not apply
    plain, biased = tmp_path / "plain", tmp_path / "biased"
    assert main(["simulate", "--start-x", "45000", "--seed", "4", "--out", str(plain)]) == 0
    assert main(["simulate", "--start-x", "45000", "--seed", "4", "--bias", "0.5", "-1", "--out", str(biased)]) == 0
    a = fd.Measurements.from_csv(plain / "measurements.csv")
    b = fd.Measurements.from_csv(biased / "measurements.csv")
    np.testing.assert_allclose(b.doppler - a.doppler, np.where(a.pair == 0, 0.5, -1.0), rtol=0, atol=1e-9)
    capsys.readouterr()
    for estimator in ("smoother", "ekf"):
        runs = {}
        for extra in ([], ["--bias-sigma", "1"]):
            assert main(["track", str(biased / "measurements.csv"), "--estimator", estimator, "--json", *extra]) == 0
            runs[bool(extra)] = json.loads(capsys.readouterr().out)
        assert runs[True]["states"] == runs[False]["states"] and runs[True]["status"] == runs[False]["status"]
        assert runs[True]["settings"]["bias_sigma"] == 1.0
        last = [np.array(runs[k]["covariances"][-1]) for k in (False, True)]
        assert np.all(np.linalg.eigvalsh(last[1] - last[0]) > -1e-9) and np.trace(last[1]) > 10 * np.trace(last[0])
    m = str(biased / "measurements.csv")
    # the particle estimators integrate the offsets out: the same particles and seed, another model, another track
    runs = {}
    for extra in ([], ["--bias-sigma", "1"]):
        assert main(["track", m, "--estimator", "particle", "--json", *extra]) == 0
        runs[bool(extra)] = json.loads(capsys.readouterr().out)
    assert runs[True]["settings"]["bias_sigma"] == 1.0 and runs[True]["states"] != runs[False]["states"]
    for bad, said in ((["--estimator", "particle", "--bias-sigma", "1", "--huber"], "(no --huber)"),
                      (["--estimator", "init", "--bias-sigma", "1"],
                       "applies to ekf, isam2, fixed-lag, smoother, particle, map, not to init"),
                      (["--estimator", "smoother", "--bias-sigma", "1", "1", "1"], "one per pair (2)"),
                      (["--estimator", "ekf", "--bias-sigma", "1", "1", "1"], "one per pair (2)"),
                      (["--estimator", "fixed-lag", "--bias-sigma", "-1"], "--bias-sigma")):
        assert main(["track", m, *bad]) == 2
        assert said in capsys.readouterr().err
    assert main(["simulate", "--bias", "1", "2", "3", "--out", str(tmp_path / "bad")]) == 2
    assert "--bias must be" in capsys.readouterr().err and not (tmp_path / "bad").exists()


def test_a_monte_carlo_study_with_offsets_declared_to_the_trackers(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    # the same recordings (seed) with the offsets simulated, the smoother told of them or not: identical errors
    # (the track does not change), a NEES no larger with them declared, in every run and at every time
    out = {}
    for extra in ([], ["--bias-sigma", "1"]):
        stem = tmp_path / ("with" if extra else "without")
        assert main(["montecarlo", "--case", "a", "--start-x", "45000", "--runs", "2", "--workers", "1",
                     "--estimators", "smoother", "ekf", "--bias", "1", "-1", "--out", str(stem), *extra]) == 0
        out[bool(extra)] = np.load(stem.with_suffix(".npz"))
    for name in ("smoother", "ekf"):
        np.testing.assert_array_equal(out[True][f"pos_0_{name}"], out[False][f"pos_0_{name}"])
        with_, without = out[True][f"nees_0_{name}"], out[False][f"nees_0_{name}"]
        finite = np.isfinite(without)
        assert np.all(with_[finite] <= without[finite] + 1e-9) and np.nanmean(with_) < np.nanmean(without) / 5, name
    capsys.readouterr()
    assert main(["montecarlo", "--case", "a", "--runs", "1", "--bias-sigma", "1", "1", "1",
                 "--out", str(tmp_path / "bad")]) == 2
    assert "--bias-sigma takes one value or one per pair (2 in case a" in capsys.readouterr().err
    # the particle estimators cannot integrate offsets out of a Huber likelihood: refused before any work
    assert main(["montecarlo", "--case", "a", "--runs", "1", "--estimators", "particle", "--huber",
                 "--bias-sigma", "1", "--out", str(tmp_path / "huber")]) == 2
    assert "(no --huber)" in capsys.readouterr().err and not (tmp_path / "huber.npz").exists()


def test_a_late_clock_is_simulated_and_the_trackers_told_of_clock_uncertainty(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # simulate --clock-error records pair 1's values 0.5 s late (its truth file covers those times, so --truth
    # reads it); track --clock-sigma widens the smoother's and the EKF's covariances by what such errors do (the
    # track itself unchanged); refused where it does not apply
    plain, late = tmp_path / "plain", tmp_path / "late"
    assert main(["simulate", "--start-x", "45000", "--seed", "4", "--out", str(plain)]) == 0
    assert main(["simulate", "--start-x", "45000", "--seed", "4", "--clock-error", "0", "0.5", "--out",
                 str(late)]) == 0
    a = fd.Measurements.from_csv(plain / "measurements.csv")
    b = fd.Measurements.from_csv(late / "measurements.csv")
    for p, shift in ((0, 0.0), (1, 0.5)):
        np.testing.assert_allclose(b.time[b.pair == p], a.time[a.pair == p] + shift, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.doppler[b.pair == p], a.doppler[a.pair == p], rtol=0, atol=1e-9)
    capsys.readouterr()
    m = str(late / "measurements.csv")
    for estimator in ("smoother", "ekf"):
        runs = {}
        for extra in ([], ["--clock-sigma", "0.5"]):
            assert main(["track", m, "--estimator", estimator, "--truth", str(late / "truth.csv"), "--json",
                         *extra]) == 0
            runs[bool(extra)] = json.loads(capsys.readouterr().out)
        assert runs[True]["states"] == runs[False]["states"] and runs[True]["status"] == runs[False]["status"]
        assert runs[True]["settings"]["clock_sigma"] == 0.5
        last = [np.array(runs[k]["covariances"][-1]) for k in (False, True)]
        assert np.all(np.linalg.eigvalsh(last[1] - last[0]) > -1e-9) and np.trace(last[1]) > 10 * np.trace(last[0])
    for bad, said in ((["--estimator", "init", "--clock-sigma", "0.1"], "not to init"),
                      (["--estimator", "ekf", "--clock-sigma", "1", "1", "1"], "one per pair (2)"),
                      (["--estimator", "fixed-lag", "--clock-sigma", "-1"], "--clock-sigma: clock_sigma must be")):
        assert main(["track", m, *bad]) == 2
        assert said in capsys.readouterr().err
    assert main(["simulate", "--clock-error", "1", "2", "3", "--out", str(tmp_path / "bad")]) == 2
    assert "--clock-error must be" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    # a Monte Carlo study: the same recordings with the late clock, the smoother told of it or not
    out = {}
    for extra in ([], ["--clock-sigma", "0.5"]):
        stem = tmp_path / ("with" if extra else "without")
        assert main(["montecarlo", "--case", "a", "--start-x", "45000", "--runs", "1", "--workers", "1",
                     "--estimators", "smoother", "particle", "--clock-error", "0", "0.5", "--out", str(stem),
                     *extra]) == 0
        out[bool(extra)] = np.load(stem.with_suffix(".npz"))
    for name in ("smoother", "particle"):  # every estimator takes it: the track stays, the NEES falls
        np.testing.assert_array_equal(out[True][f"pos_0_{name}"], out[False][f"pos_0_{name}"])
        assert np.nanmean(out[True][f"nees_0_{name}"]) < np.nanmean(out[False][f"nees_0_{name}"]) / 5


def test_sites_off_their_declared_positions_and_the_trackers_told_of_site_uncertainty(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A recording simulated with case a's sites 30-60 m off (simulate --site-error: Tx1, Rx, Tx2, the same data as
    # a geometry file of the true sites gives), tracked with the paper's: with --site-sigma 40 the smoother's
    # track is the same and its covariances grow by what such sites do, so that the truth's final NEES falls
    # inside chi-square(4)'s 99 % level from far beyond it; refused where it does not apply, and in a Monte Carlo
    # study every estimator takes it
    true_sites = tmp_path / "true_sites.toml"
    fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3 + 40.0, -30.0), rx=(-35.0, 20.0)),
                       fd.BistaticPair(tx=(50e3 - 25.0, 1e3 + 60.0), rx=(-35.0, 20.0)))).to_toml(true_sites)
    rec, same = tmp_path / "rec", tmp_path / "same"
    assert main(["simulate", "--start-x", "45000", "--seed", "3", "--site-error", "40", "-30", "-35", "20", "-25",
                 "60", "--out", str(rec)]) == 0
    assert "sites moved by --site-error" in capsys.readouterr().out
    assert main(["simulate", "--geometry", str(true_sites), "--start-x", "45000", "--seed", "3",
                 "--out", str(same)]) == 0
    assert (rec / "measurements.csv").read_text() == (same / "measurements.csv").read_text()
    written = fd.Geometry.from_toml(rec / "geometry.toml")  # the declared sites
    np.testing.assert_array_equal(written.tx, fd.paper_geometry("a").tx)
    np.testing.assert_array_equal(written.rx, fd.paper_geometry("a").rx)
    assert main(["simulate", "--site-error", "1", "2", "3", "--out", str(tmp_path / "bad")]) == 2
    assert "--site-error needs 2 finite numbers per site (3 sites" in capsys.readouterr().err
    assert main(["observability", "--report", "45000", "--site-error", *["1"] * 6]) == 2
    assert "--site-error does not apply to --report" in capsys.readouterr().err
    capsys.readouterr()
    m = str(rec / "measurements.csv")
    truth = fd.Trajectory.from_csv(rec / "truth.csv")
    runs, nees = {}, {}
    for extra in ([], ["--site-sigma", "40"]):
        assert main(["track", m, "--geometry", "a", "--estimator", "smoother", "--json", *extra]) == 0
        runs[bool(extra)] = out = json.loads(capsys.readouterr().out)
        err = truth.at(np.array(out["times"][-1:]))[0] - np.array(out["states"][-1])
        nees[bool(extra)] = float(err @ np.linalg.solve(np.array(out["covariances"][-1]), err))
    assert runs[True]["states"] == runs[False]["states"] and runs[True]["status"] == runs[False]["status"] == "ok"
    assert runs[True]["settings"]["site_sigma"] == 40.0
    assert nees[False] > chi2.ppf(0.999, 4) and nees[True] < chi2.ppf(0.99, 4)
    for bad, said in ((["--estimator", "init", "--site-sigma", "1"], "--site-sigma applies to"),
                      (["--estimator", "ekf", "--site-sigma", "1", "1"], "one per site (3"),
                      (["--estimator", "map", "--site-sigma", "-1"], "--site-sigma: site_sigma must be")):
        assert main(["track", m, "--geometry", "a", *bad]) == 2
        assert said in capsys.readouterr().err
    assert main(["montecarlo", "--case", "b", "--runs", "1", "--site-sigma", "1", "1",
                 "--out", str(tmp_path / "bad")]) == 2
    assert "--site-sigma in case b" in capsys.readouterr().err and not (tmp_path / "bad.npz").exists()
    out = {}
    for extra in ([], ["--site-sigma", "30"]):
        stem = tmp_path / ("with" if extra else "without")
        assert main(["montecarlo", "--case", "a", "--start-x", "45000", "--runs", "1", "--workers", "1",
                     "--estimators", "ekf", "--out", str(stem), *extra]) == 0
        out[bool(extra)] = np.load(stem.with_suffix(".npz"))
    np.testing.assert_array_equal(out[True]["pos_0_ekf"], out[False]["pos_0_ekf"])
    # the share is positive semi-definite, so no NEES can rise; its runs simulate the sites exactly, so it falls
    # (measured 2.46 to 1.71 averaged over t >= 10 s)
    with_share, without = out[True]["nees_0_ekf"], out[False]["nees_0_ekf"]
    np.testing.assert_array_equal(np.isnan(with_share), np.isnan(without))  # the initiation window's times
    assert np.all(with_share[~np.isnan(without)] <= without[~np.isnan(without)] * (1 + 1e-9))
    assert np.nanmean(out[True]["nees_0_ekf"]) < 0.9 * np.nanmean(out[False]["nees_0_ekf"])


#: Three sensors within 3.3 m of one line (the file says more; studies/zone_advice.py measures on it too).
QUASI_MONOSTATIC = Path(__file__).resolve().parents[1] / "studies" / "geometries" / "quasi_monostatic.toml"


@pytest.mark.parametrize("seed", [1, 2])
def test_following_the_zone_advice_never_ends_in_a_confident_mirror_track(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], seed: int) -> None:
    """A target 9.4 km off the line of three near-collinear sensors, outside the default zone.

    The smoother says the data prefer a start outside the zone and advises
    ``--zone ... --speed-max ...``.  The search found the mirror image's
    start (its Doppler nearly the truth's); an advice holding only that start
    led to an ``ok`` track 14 km from the truth in these recordings.  The
    advice holds the mirror's twin too, so it holds the truth's start, and
    the run that follows it either tracks the truth within its covariance or
    says that another track fits as well — never a confident wrong answer.
    That other track is the mirror image: the finding says so, and the
    command prints the ``--half-plane`` options of either side of the
    sensors' line.
    """
    import re

    from scipy.stats import chi2

    sim = tmp_path / "sim"
    assert main(["simulate", "--geometry", str(QUASI_MONOSTATIC), "--start-x", "15000", "--start-y",
                 "12000", "--velocity", "80", "-60", "--seed", str(seed), "--out", str(sim)]) == 0
    args = ["track", str(sim / "measurements.csv"), "--estimator", "smoother", "--json"]
    capsys.readouterr()
    assert main(args) == 0
    first = json.loads(capsys.readouterr().out)
    advice = [r["message"] for r in first["reasons"] if r["status"] != "ok" and "e.g. --zone" in r["message"]]
    assert first["status"] == "doubtful" and advice
    options = re.search(r"e\.g\. (--zone (-?\d+) (-?\d+) (-?\d+) (-?\d+) --speed-max (\d+))", advice[0])
    assert options is not None
    along, across = tuple(map(float, options.groups()[1:3])), tuple(map(float, options.groups()[3:5]))
    geometry = fd.Geometry.from_toml(sim / "geometry.toml")
    advised = fd.Zone(frame=geometry.frame, along=along, across=across, speed_max=float(options.group(6)))
    truth = fd.Trajectory.from_csv(sim / "truth.csv")
    assert bool(advised.contains(truth.states[0]))
    assert main([*args, *options.group(1).split()]) == 0
    captured = capsys.readouterr()
    second = json.loads(captured.out)
    assert not [r for r in second["reasons"] if r["code"] in ("boundary", "zone") and r["status"] != "ok"]
    x, P = np.array(second["states"][-1]), np.array(second["covariances"][-1])
    e = x[:2] - truth.states[-1, :2]
    consistent = float(e @ np.linalg.solve(P[:2, :2], e)) < chi2.ppf(0.999, 2)
    competing = [r for r in second["reasons"] if r["code"] == "competing" and r["status"] == "doubtful"]
    assert consistent or competing
    assert second["status"] == "doubtful" if competing else second["status"] == "ok"
    # the rival here is the mirror image: the finding says so, and the hint's two half planes, one per side of
    # the sensors' line, split the truth from its mirror image
    from fgdoppler.estimators.smoother_offsets import mirrored
    from fgdoppler.geometry import MIRROR_ADVICE

    assert any(MIRROR_ADVICE in r["message"] and r["mirror"] == "sensors" for r in competing)
    assert all(("mirror" in r) == (MIRROR_ADVICE in r["message"]) for r in second["reasons"])
    hint = re.search(r"--half-plane (\S+) (\S+) (\S+) (\S+) puts .* --half-plane (\S+) (\S+) (\S+) (\S+) on", captured.err)
    assert hint is not None
    planes = np.array(hint.groups(), dtype=float).reshape(2, 4)
    np.testing.assert_allclose(planes[0, 2:], -planes[1, 2:])
    for p in (truth.states[0], mirrored(truth.states[:1], geometry)[0]):
        side = planes[:, 2:] @ (p[:2] - planes[0, :2])
        assert side[0] * side[1] < 0 and min(abs(side)) > 1e3


def test_an_initiation_whose_alternative_is_the_mirror_image_gets_the_half_planes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--estimator init`` on the quasi-monostatic recording of seed 1: the window fits the start and its
    mirror image equally (costs 5.49 and 5.50 when measured); the ``ambiguous`` finding names the mirror and the
    hint's half planes put the start and that alternative on opposite sides."""
    import re

    sim = tmp_path / "sim"
    assert main(["simulate", "--geometry", str(QUASI_MONOSTATIC), "--start-x", "15000", "--start-y",
                 "12000", "--velocity", "80", "-60", "--seed", "1", "--out", str(sim)]) == 0
    capsys.readouterr()
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "init", "--json"]) == 0
    captured = capsys.readouterr()
    res = json.loads(captured.out)
    found = [r for r in res["reasons"] if r["code"] == "ambiguous" and "mirror image" in r["message"]]
    hint = re.search(r"--half-plane (\S+) (\S+) (\S+) (\S+) puts", captured.err)
    assert found and found[0]["status"] == "doubtful" and found[0]["mirror"] == "sensors" and hint is not None
    plane = np.array(hint.groups(), dtype=float)
    sides = [plane[2:] @ (np.asarray(x)[:2] - plane[:2]) for x in (res["x_start"], res["alternatives"][0]["state"])]
    assert sides[0] * sides[1] < 0


def test_a_mistake_finding_comes_before_any_zone_or_half_plane_advice() -> None:
    """A sign, swapped or radial finding (the track's or, prefixed, the initiation's) beside a finding that
    advises a zone or a half plane: the hint is to correct the mistake first; without such advice, or with the
    mistake finding only ``ok`` or absent, there is none; a geometry in kilometres is named whatever the rest.  The
    same for an initiation window that fits without a few outliers (the Huber loss first) and for sigma the manoeuvre
    finding says look too small (the right sigma first)."""
    from fgdoppler.cli.track import mistake_hint
    from fgdoppler.estimators.manoeuvre import SIGMA_ADVICE
    from fgdoppler.estimators.verdict import Reason
    from fgdoppler.estimators.window_mistakes import (
        IN_KILOMETRES,
        OR_OUTSIDE_THE_ZONE,
        WITH_OUTLIERS,
    )

    zone = fd.Zone(along=(1000.0, 30000.0), across=(-3000.0, 3000.0), speed_max=200.0, frame=fd.Frame.identity(2))
    widen = Reason(code="boundary", status="doubtful", message="widen it",
                   zone=zone.reaching(np.array([20000.0, 8000.0, 0.0, 0.0])).box())
    mirror = Reason(code="competing", status="doubtful", message="its mirror image fits", mirror="sensors")
    for code in ("sign", "initiation-swapped", "radial"):
        named = Reason(code=code, status="doubtful", message="with pair 0 negated the window fits")
        for advice in (widen, mirror):
            hint = mistake_hint([named, advice])
            assert hint is not None and hint.startswith(f"a {code.removeprefix('initiation-')} finding above")
        assert mistake_hint([named]) is None
        assert mistake_hint([replace(named, status="ok"), widen, mirror]) is None
    assert mistake_hint([widen, mirror]) is None
    km = Reason(code="initiation-units", status="doubtful", message=f"the window fits: {IN_KILOMETRES} ...")
    assert mistake_hint([km]) is not None and "kilometres" in mistake_hint([km, widen])  # type: ignore[operator]
    # a change the whole recording does not confirm: check the file and the geometry, not correct
    unconfirmed = Reason(code="unconfirmed", status="doubtful", message="the track fits its data as given, ...")
    sign = Reason(code="initiation-sign", status="doubtful", message="with pair 0 negated the window fits")
    assert "does not confirm (the unconfirmed finding): check the file and the geometry" in (
        mistake_hint([sign, unconfirmed, widen]) or "")
    # an outliers finding: track with the Huber loss first; both where a start outside the zone fits too
    outliers = Reason(code="initiation-outliers", status="doubtful", message=f"the window fits: {WITH_OUTLIERS}, ...")
    assert mistake_hint([outliers]) is None and mistake_hint([replace(outliers, status="ok"), widen]) is None
    assert "track with the Huber loss (--huber) before" in (mistake_hint([outliers, widen]) or "")
    either = replace(outliers, message=f"{outliers.message}; {OR_OUTSIDE_THE_ZONE}")
    assert "check those measurements, and if they are right, follow the zone advice" in (
        mistake_hint([either, widen]) or "")
    # sigma that look too small (the manoeuvre finding's clause): give the right sigma first, where advice would follow
    small = Reason(code="manoeuvre", status="doubtful", message=f"the target does not move ...; {SIGMA_ADVICE}")
    assert mistake_hint([small]) is None and mistake_hint([replace(small, message="the target ..."), widen]) is None
    for advice in (widen, mirror):
        assert "sigma look too small: give their right sigma before" in (mistake_hint([small, advice]) or "")
    # outliers the window or the whole recording fits without come before that: with them out the sigma fit
    recording = Reason(code="outliers", status="doubtful", message=f"fitted with one ..., the recording fits: "
                                                                   f"{WITH_OUTLIERS}; ...")
    for found, where in ((outliers, "the initiation window fits"), (recording, "the data fit")):
        hint = mistake_hint([small, found, widen]) or ""
        assert f"says {where} without a few measurements: track with the Huber loss (--huber) before" in hint
        assert "or sigma advice" in hint and mistake_hint([small, found]) is None


def test_the_zone_hint_is_the_union_of_the_advised_zones() -> None:
    """Zones advised by two findings (from :meth:`Zone.reaching`): the hint is their union box, bounds
    rounded outward; one advice, the same advice twice, or advice in an ``ok`` finding gives none."""
    from fgdoppler.cli.track import zone_hint
    from fgdoppler.estimators.verdict import Reason

    for altitude in (None, (0.0, 3000.0)):
        d = 2 if altitude is None else 3
        zone = fd.Zone(along=(1000.0, 30000.0), across=(-3000.0, 3000.0), speed_max=200.0, altitude=altitude,
                       frame=fd.Frame.identity(d))
        a = zone.reaching(np.r_[[20000.0, 8000.5], [0.0] * (d - 2), [250.0], [0.0] * (d - 1)])
        b = zone.reaching(np.r_[[35000.0, -9000.0], [5000.0] * (d - 2), [0.0] * d])
        said = [Reason(code="boundary", status="doubtful", message="widen it", zone=a.box()),
                Reason(code="reference", status="doubtful", message="the smoother's", zone=b.box())]
        union = fd.Zone(along=(1000.0, b.along[1]), across=(b.across[0], a.across[1]), speed_max=a.speed_max,
                        altitude=None if altitude is None else b.altitude, frame=fd.Frame.identity(d))
        assert zone_hint(said) == union.options()
        assert zone_hint(said[:1]) is None
        assert zone_hint([said[0], Reason(code="zone", status="doubtful", message="again", zone=a.box())]) is None
        assert zone_hint([said[0], Reason(code="reference", status="ok", message="", zone=b.box())]) is None


def test_findings_advising_different_zones_get_one_that_holds_them_all(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An EKF on the quasi-monostatic recording of seed 8: the initiation advises a zone holding its window's
    start, the offline smoother one holding the whole recording's start and its mirror image's; only the
    hint's zone holds both, and the truth's start."""
    import re

    sim = tmp_path / "sim"
    assert main(["simulate", "--geometry", str(QUASI_MONOSTATIC), "--start-x", "15000", "--start-y",
                 "12000", "--velocity", "80", "-60", "--seed", "8", "--out", str(sim)]) == 0
    capsys.readouterr()
    assert main(["track", str(sim / "measurements.csv"), "--estimator", "ekf", "--json"]) == 0
    captured = capsys.readouterr()
    err = captured.err
    geometry = fd.Geometry.from_toml(sim / "geometry.toml")
    # each finding that advises a zone carries it in the JSON, as the options its message names
    carried = [r for r in json.loads(captured.out)["reasons"] if "zone" in r]
    assert len(carried) >= 1
    for r in carried:
        assert "e.g. " + r["zone"]["options"] in r["message"]

    def zone(groups: tuple[str, ...]) -> fd.Zone:
        v = tuple(map(float, groups))
        return fd.Zone(frame=geometry.frame, along=v[0:2], across=v[2:4], speed_max=v[4])

    pattern = r"--zone (-?\d+) (-?\d+) (-?\d+) (-?\d+) --speed-max (\d+)"
    advised = {m.groups() for m in re.finditer(r"e\.g\. " + pattern, err)}
    hint = re.search(r"hint: the findings above advise different zones; one holding every start they name: "
                     + pattern, err)
    assert len(advised) == 2 and hint is not None
    held = zone(hint.groups())
    for a in map(zone, advised):
        assert all(h[0] <= v[0] and v[1] <= h[1] for h, v in zip(held.intervals, a.intervals, strict=True))
        assert held.speed_max >= a.speed_max
    truth = fd.Trajectory.from_csv(sim / "truth.csv")
    assert bool(held.contains(truth.states[0])) and sum(bool(a.contains(truth.states[0]))
                                                        for a in map(zone, advised)) == 1


def test_a_default_zone_is_said_to_be_an_assumption(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The zone line says when the zone is the default rule's (every verdict assumes it), not when it is given."""
    sim = tmp_path / "sim"
    assert main(["simulate", "--case", "a", "--start-x", "45000", "--seed", "1", "--out", str(sim)]) == 0
    args = ["track", str(sim / "measurements.csv"), "--estimator", "init"]
    capsys.readouterr()
    assert main(args) == 0
    assert "(the default rule's; every verdict assumes the target starts in it" in capsys.readouterr().out
    assert main([*args, "--zone", "2000", "48000", "-5000", "5000"]) == 0
    assert "default rule" not in capsys.readouterr().out


@pytest.mark.parametrize("origin", [(0.0, 0.0), (503_210.5, 4_512_345.678)], ids=["paper", "utm"])
def test_one_pairs_mirror_is_settled_by_the_half_plane_the_hint_gives(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], origin: tuple[float, float]) -> None:
    """One bistatic pair: a track and its mirror image across the baseline give the same Doppler.

    The ``data`` finding says so and the command prints the two half planes
    of that line; run with the one that holds the truth, the track is on the
    truth's side (and the finding is gone).  The same with the sensors where
    UTM coordinates put them (the Doppler does not change under a
    translation): the hint gives the line's point to the millimetre, not as
    ``4.51235e+06``, 4.3 m off.
    """
    import re

    from fgdoppler.geometry_file import write_geometry

    sim = tmp_path / "sim"
    assert main(["simulate", "--case", "a", "--start-x", "25000", "--start-y", "2000", "--seed", "1",
                 "--out", str(sim)]) == 0
    text = (sim / "measurements.csv").read_text().splitlines()
    one = tmp_path / "one.csv"
    one.write_text("\n".join([text[0], *(r for r in text[1:] if r.split(",")[1] == "0")]) + "\n")
    shift = np.array(origin)
    paper = fd.paper_geometry("a")
    write_geometry(fd.Geometry(pairs=tuple(fd.BistaticPair(tx=tuple(p.tx + shift), rx=tuple(p.rx + shift))
                                           for p in paper.pairs)), tmp_path / "geometry.toml")
    args = ["track", str(one), "--geometry", str(tmp_path / "geometry.toml"), "--estimator", "smoother", "--json"]
    capsys.readouterr()
    assert main(args) == 0
    captured = capsys.readouterr()
    hint = re.search(r"--half-plane (\S+) (\S+) (\S+) (\S+) puts .* --half-plane (\S+) (\S+) (\S+) (\S+) on",
                     captured.err)
    first = json.loads(captured.out)
    assert hint is not None and first["status"] == "doubtful"
    assert [r["mirror"] for r in first["reasons"] if "lie on one line" in r["message"]] == ["reporting"]
    planes = np.array(hint.groups(), dtype=float).reshape(2, 4)
    np.testing.assert_allclose(planes[0, 1], origin[1], rtol=0, atol=5e-4)  # the baseline y = 0 of pair 0, moved
    truth = fd.Trajectory.from_csv(sim / "truth.csv")
    holds = [k for k in range(2) if planes[k, 2:] @ (truth.states[0, :2] + shift - planes[k, :2]) > 0]
    assert len(holds) == 1
    assert main([*args, "--half-plane", *hint.groups()[4 * holds[0]:4 * holds[0] + 4]]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert "hint" not in captured.err
    assert not any("lie on one line" in r["message"] for r in result["reasons"])
    assert np.sign(result["states"][-1][1] - origin[1]) == np.sign(truth.states[-1, 1])


def test_a_side_that_one_measurement_settles_gets_the_half_planes_of_its_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Pair 0 whole and one measurement of pair 1: the track's mirror image across pair 0's baseline fits all of
    pair 0's data exactly as well, and only that one measurement tells them apart.  The ``competing`` finding
    names pair 0's line (``mirror="pairs"``), the hint gives that line's two half planes (the baseline y = 0),
    and with the truth's one the track is on the truth's side and the finding is gone."""
    import re

    sim = tmp_path / "sim"
    assert main(["simulate", "--case", "a", "--start-x", "25000", "--start-y", "2000", "--seed", "1",
                 "--out", str(sim)]) == 0
    text = (sim / "measurements.csv").read_text().splitlines()
    ones = [r for r in text[1:] if r.split(",")[1] == "1"]
    few = tmp_path / "few.csv"
    few.write_text("\n".join([text[0], *(r for r in text[1:] if r.split(",")[1] == "0" or r == ones[len(ones) // 2])])
                   + "\n")
    args = ["track", str(few), "--geometry", str(sim / "geometry.toml"), "--estimator", "smoother", "--json"]
    capsys.readouterr()
    assert main(args) == 0
    captured = capsys.readouterr()
    found = [r for r in json.loads(captured.out)["reasons"] if r.get("mirror") == "pairs"]
    assert [(r["code"], r["status"], r["pairs"]) for r in found] == [("competing", "doubtful", [0])]
    hint = re.search(r"--half-plane (\S+) (\S+) (\S+) (\S+) puts .* --half-plane (\S+) (\S+) (\S+) (\S+) on",
                     captured.err)
    assert hint is not None
    planes = np.array(hint.groups(), dtype=float).reshape(2, 4)
    np.testing.assert_allclose(planes[:, 1], 0.0, rtol=0, atol=5e-4)
    np.testing.assert_allclose(np.abs(planes[:, 3]), 1.0, rtol=0, atol=1e-9)
    truth = fd.Trajectory.from_csv(sim / "truth.csv")
    holds = [k for k in range(2) if planes[k, 2:] @ (truth.states[0, :2] - planes[k, :2]) > 0]
    assert len(holds) == 1
    assert main([*args, "--half-plane", *hint.groups()[4 * holds[0]:4 * holds[0] + 4]]) == 0
    result = json.loads(capsys.readouterr().out)
    assert not any(r.get("mirror") == "pairs" for r in result["reasons"])
    assert np.sign(result["states"][-1][1]) == np.sign(truth.states[-1, 1])


def test_a_measurement_file_may_name_its_pairs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A geometry file that names its pairs: ``simulate`` keeps the names in the geometry it writes, ``track``
    reads a file that gives the pairs by name (rows in another order) as the one with indices, and records the
    names with the geometry in its JSON."""
    geometry = tmp_path / "named.toml"
    fd.Geometry(pairs=fd.paper_geometry("a").pairs, pair_names=("north", "south")).to_toml(geometry)
    sim = tmp_path / "sim"
    assert main(["simulate", "--geometry", str(geometry), "--start-x", "40000", "--out", str(sim)]) == 0
    rows = (sim / "measurements.csv").read_text().splitlines()
    names = {"0": "north", "1": "south"}
    body = [",".join((r.split(",")[0], names[r.split(",")[1]], *r.split(",")[2:])) for r in rows[1:]]
    (sim / "named.csv").write_text("\n".join([rows[0], *sorted(body, key=lambda r: r.split(",")[1])]) + "\n")
    capsys.readouterr()
    runs = []
    for file in ("measurements.csv", "named.csv"):
        assert main(["track", str(sim / file), "--estimator", "init", "--json"]) == 0
        runs.append(json.loads(capsys.readouterr().out))
    assert runs[0]["x_start"] == runs[1]["x_start"] and runs[0]["cost"] == runs[1]["cost"]
    assert [p["name"] for p in runs[1]["geometry"]["pairs"]] == ["north", "south"]


def test_a_recording_in_unix_seconds_is_reported_with_its_own_times(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Times of ~1.7e9 s are printed in full (``:g`` made every one "1.7e+09"), and a truth file whose times
    another program rounded a unit in the last place the other way still matches the measurements' (that unit is
    0.24 µs there, far above the 1 ns that used to be asked)."""
    sim = tmp_path / "sim"
    main(["simulate", "--case", "b", "--start-x", "5000", "--seed", "3", "--out", str(sim)])
    capsys.readouterr()
    m = fd.Measurements.from_csv(sim / "measurements.csv")
    shifted = m.time + 1_764_115_201.1
    fd.Measurements(time=shifted, pair=m.pair, doppler=m.doppler, sigma=m.sigma).to_csv(tmp_path / "m.csv")
    lines = (sim / "truth.csv").read_text().splitlines()
    rows = [ln.split(",", 1)[1] for ln in lines[1:]]
    truth_times = np.unique(shifted)
    truth_times[::2] = np.nextafter(truth_times[::2], np.inf)
    assert len(rows) == truth_times.size
    (tmp_path / "t.csv").write_text("\n".join([lines[0], *(f"{float(t)!r},{r}" for t, r in zip(truth_times, rows,
                                                                                          strict=True))]))
    args = ["track", str(tmp_path / "m.csv"), "--geometry", "b", "--truth", str(tmp_path / "t.csv")]
    assert main([*args, "--estimator", "init"]) == 0
    out = capsys.readouterr().out
    first, last = fd.Measurements.from_csv(tmp_path / "m.csv").first_per_pair(10).time[[0, -1]]
    assert f"t = {float(first)!r}..{float(last)!r} s" in out and "e+09" not in out and "error at t_end" in out
    assert main([*args, "--estimator", "ekf"]) == 0
    out = capsys.readouterr().out
    assert f"..{float(shifted[-1])!r} s, " in out and "e+09" not in out  # filtered from the window's end
    assert "position RMSE vs truth" in out


@pytest.mark.parametrize("t", [0.0, 30.0, 12.25, 0.125, -3601.5, 2.5e-5, 1_764_115_201.1, 1_764_115_231.25, 1e12 + 0.5])
def test_times_are_printed_positionally_and_read_back_exactly(t: float) -> None:
    from fgdoppler._text import time_text

    text = time_text(t)
    assert "e" not in text.lower() and float(text) == t  # every time here has at most six decimals
    assert len(text) <= len(repr(t)) + 1  # no padding: "30", not "30.000000"


def test_track_on_a_geometry_in_kilometres_says_so_instead_of_advising_a_zone(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Case a's sensors written in kilometres: the track fails (exit 3), the initiation's ``units`` finding is
    printed, and the hint says to give the geometry in metres rather than a zone that reads it as metres."""
    sim = tmp_path / "sim"
    main(["simulate", "--start-x", "45000", "--out", str(sim)])
    fd.paper_geometry("a").scaled(1e-3).to_toml(tmp_path / "km.toml")
    capsys.readouterr()
    assert main(["track", str(sim / "measurements.csv"), "--geometry", str(tmp_path / "km.toml"),
                 "--estimator", "smoother"]) == 3
    err = capsys.readouterr().err
    assert "doubtful: initiation: with every sensor position multiplied by 1000 the window fits" in err
    assert "hint: the geometry is likely in kilometres" in err and "one holding every start they name" not in err


def test_track_with_times_in_milliseconds_says_so_instead_of_advising_a_zone(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A recording of case a (a target 45 km out) with its times written in milliseconds: the track fails (exit 3),
    the initiation's ``units`` finding names milliseconds, and the hint says to give the times in seconds rather
    than a zone that reads them as seconds."""
    sim = tmp_path / "sim"
    main(["simulate", "--start-x", "45000", "--out", str(sim)])
    rows = (sim / "measurements.csv").read_text().splitlines()
    ms = [rows[0]] + [",".join((repr(1e3 * float(t)), *rest)) for t, *rest in (r.split(",") for r in rows[1:])]
    (tmp_path / "ms.csv").write_text("\n".join(ms) + "\n")
    capsys.readouterr()
    assert main(["track", str(tmp_path / "ms.csv"), "--geometry", str(sim / "geometry.toml"),
                 "--estimator", "smoother"]) == 3
    err = capsys.readouterr().err
    assert "doubtful: initiation: with every time divided by 1,000 the window fits" in err
    assert "the times are likely in milliseconds" in err
    assert "hint: the times are likely not in seconds" in err and "one holding every start they name" not in err


def test_track_with_a_sign_mistake_says_to_correct_it_before_any_zone_advice(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A file in Hz written with the opposite sign convention (case b, a target 25 km out): the smoother's start is
    held at the zone's edge and that finding advises a wider zone, read from the negated data; the ``sign``
    finding names the mistake, and the hint says to correct it before following any zone advice.  The file as
    simulated gets no hint at all."""
    sim = tmp_path / "sim"
    main(["simulate", "--case", "b", "--wavelength", "3.05", "--seed", "4", "--out", str(sim)])
    rows = (sim / "measurements.csv").read_text().splitlines()
    negated = [rows[0]] + [",".join((t, p, repr(-float(f)), s)) for t, p, f, s in (r.split(",") for r in rows[1:])]
    (tmp_path / "neg.csv").write_text("\n".join(negated) + "\n")
    capsys.readouterr()
    args = ["--geometry", str(sim / "geometry.toml"), "--estimator", "smoother"]
    assert main(["track", str(tmp_path / "neg.csv"), *args]) == 0  # doubtful, not failed
    err = capsys.readouterr().err
    assert "doubtful: the track's first state is held at the zone's boundary" in err and "--zone" in err
    assert "with the Doppler of every pair negated" in err
    assert ("hint: a sign finding above names a likely mistake in the measurement file: correct it before following "
            "any zone or half-plane advice") in err
    assert "one holding every start they name" not in err
    assert main(["track", str(sim / "measurements.csv"), *args]) == 0
    assert "hint" not in capsys.readouterr().err
