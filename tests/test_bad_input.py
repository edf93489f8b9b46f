"""Hostile and malformed input through the command line: exit 2, one line naming the file, nothing written.

Every class below was measured to misbehave once (accepted as valid, a
traceback, or outputs left behind); each must now end with exit status 2, a
single line on stderr that names the file (and the line where there is one),
no traceback, and no file written.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from fgdoppler.cli import main

HEADER = "time,pair,doppler,sigma\n"


@pytest.fixture
def recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    """A simulated paper recording (case a, 25 km) in ``tmp_path / "sim"``."""
    sim = tmp_path / "sim"
    assert main(["simulate", "--out", str(sim), "--duration", "10"]) == 0
    capsys.readouterr()
    return sim


def _refused(capsys: pytest.CaptureFixture[str], code: int, *names: str) -> str:
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and "Warning" not in err, err
    for name in names:
        assert name in err, (name, err)
    return err


def _nothing_new(folder: Path, before: set[str]) -> None:
    assert {p.name for p in folder.iterdir()} == before


@pytest.mark.parametrize(
    ("body", "where"),
    [
        (HEADER + ",,,\n", ":2: time is empty"),
        (HEADER + "0,0,1_000,1\n", ":2: doppler is not a number"),
        (HEADER + "0,0,\u0661\u0660,1\n", ":2: doppler is not a number"),
        (HEADER + "0,0,1," + "9" * 200_000 + "\n", ":2: line longer than"),
        (HEADER + "0,0,1,5e-324\n", ":2: sigma"),
        (HEADER + "0,0,1e308,1\n", ":2: doppler 1e+308 is outside"),
        (HEADER + "0,0,1,1\n0.5,0,nan,1\n", ":3: doppler is not a number"),
    ],
)
def test_malformed_measurements(tmp_path: Path, capsys: pytest.CaptureFixture[str], body: str, where: str) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(body)
    before = {p.name for p in tmp_path.iterdir()}
    code = main(["track", str(bad), "--geometry", "a", "--estimator", "ekf", "--out", str(tmp_path / "t.csv")])
    _refused(capsys, code, f"{bad}{where}")
    _nothing_new(tmp_path, before)


def test_endless_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["track", "/dev/zero", "--geometry", "a", "--out", str(tmp_path / "t.csv")])
    _refused(capsys, code, "/dev/zero:1: line longer than")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("truth", "match"),
    [
        ("time,x,y,vx,vy\n", "no data rows"),
        ("time,x,y,vx,vy\n0,1,2,3,4\n7.3,1,2,3,4\n", "no truth at t = 0.5"),
        ("time,x,y,vx,vy\n1,1,2,3,4\n0.5,1,2,3,4\n", ":3: time 0.5 is not after"),
        ("t,x,y\n0,1,2\n", ":1: bad header"),
    ],
)
def test_truth_is_checked_before_anything_runs(recording: Path, capsys: pytest.CaptureFixture[str], truth: str,
                                               match: str) -> None:
    path = recording / "truth.csv"
    path.write_text(truth)
    before = {p.name for p in recording.iterdir()}
    code = main(["track", str(recording / "measurements.csv"), "--estimator", "smoother", "--truth", str(path),
                 "--out", str(recording / "t.csv"), "--plot", str(recording / "t.png")])
    _refused(capsys, code, str(path), match)
    _nothing_new(recording, before)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        (["--plot", "x.xyz"], "unknown figure format 'xyz'"),
        (["--out", "t.json"], "give a .csv path"),
        (["--init-per-pair", "2"], "--init-per-pair"),
        (["--init-seconds", "-1"], "--init-seconds"),
        (["--init-seconds", "nan"], "--init-seconds"),
        # the verdict's reference smoother needs process noise: said up front, in the option's words
        (["--q", "0"], "--q must be a finite number > 0 (m^2/s^3), got 0"),
        (["--q", "-1"], "--q must be a finite number > 0 (m^2/s^3), got -1"),
        (["--q", "inf"], "--q must be a finite number > 0"),
        # an estimator's own option given to another is refused, not dropped (as --particles and --most-likely are)
        (["--lag", "3"], "--lag applies to fixed-lag, not to ekf"),
    ],
)
def test_bad_track_options(recording: Path, capsys: pytest.CaptureFixture[str], options: list[str],
                           match: str) -> None:
    before = {p.name for p in recording.iterdir()}
    code = main(["track", str(recording / "measurements.csv"), "--estimator", "ekf",
                 *[str(recording / o) if o.startswith(("x.", "t.")) else o for o in options]])
    _refused(capsys, code, match)
    _nothing_new(recording, before)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        (["--process-noise", "-1"], "--process-noise"),
        (["--process-noise", "nan"], "--process-noise"),
        (["--dt", "1e-9"], "more than 10,000,000 samples"),
        (["--dt", "0"], "--dt"),
        (["--duration", "-5"], "--duration"),
        (["--sigma", "0"], "sigma"),
        (["--sigma", "1", "2", "3"], "sigma"),
        (["--offsets", "0"], "time_offsets"),
        (["--velocity", "inf", "0"], "--velocity"),
        (["--geometry", "nope.toml"], "neither a preset"),
        # the dimension's mismatch names only the option to fix (the default velocity is 3-D in 3-D)
        (["--altitude", "0", "9000"], "the start has 2 coordinates and the velocity 3: give --start-z, the start's "
                                      "height\n"),
        (["--altitude", "0", "9000", "--start-z", "1000", "--velocity", "10", "-100"],
         "the start has 3 coordinates and the velocity 2: give --velocity VX VY VZ\n"),
        (["--start-z", "1000"], "the geometry is 2-D (make it 3-D with --altitude LO HI) but the start has 3 "
                                "coordinates and the velocity 2: drop --start-z\n"),
        (["--velocity", "10", "-100", "5"], "the velocity 3: give --velocity VX VY\n"),
    ],
)
def test_bad_simulate_options(tmp_path: Path, capsys: pytest.CaptureFixture[str], options: list[str],
                              match: str) -> None:
    code = main(["simulate", "--out", str(tmp_path / "sim"), *options])
    _refused(capsys, code, match)
    assert not (tmp_path / "sim").exists()


@pytest.mark.parametrize(("options", "match"), [(["--workers", "0"], "--workers"), (["--runs", "0"], "--runs"),
                                                (["--estimators", "ukf"], "unknown estimator"),
                                                (["--estimators", "lag:-1"], "bad lag"),
                                                (["--q", "0"], "--q must be a finite number > 0")])
def test_bad_montecarlo_options(tmp_path: Path, capsys: pytest.CaptureFixture[str], options: list[str],
                                match: str) -> None:
    code = main(["montecarlo", "--runs", "1", "--out", str(tmp_path / "mc"), *options])
    _refused(capsys, code, match)
    assert not list(tmp_path.iterdir())


def test_outputs_follow_the_umask_and_init_writes_the_documented_csv(recording: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    old = os.umask(0o022)
    try:
        out = recording / "init.csv"
        assert main(["track", str(recording / "measurements.csv"), "--estimator", "init", "--out", str(out)]) == 0
    finally:
        os.umask(old)
    capsys.readouterr()
    for path in (out, out.with_suffix(".json"), recording / "measurements.csv"):
        assert stat.S_IMODE(path.stat().st_mode) == 0o644, path
    lines = out.read_text().splitlines()
    assert lines[0].startswith("# fgdoppler initiation (lm)")
    rows = [ln for ln in lines if not ln.startswith("#")]
    assert rows[0].startswith("time,x,y,vx,vy,P00") and len(rows) == 3  # the window's first and last state
