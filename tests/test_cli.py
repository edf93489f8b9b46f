"""The command line: help everywhere, simulate writes its files, errors exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

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


@pytest.mark.parametrize(
    ("content", "msg"),
    [
        ("time,pair,doppler,sigma\n0,0,abc,1\n", ":2: doppler is not a number"),
        ("time,pair,doppler,sigma\n0,5,1,1\n", ":2: unknown pair index 5"),
        ("", "empty file"),
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
    args = ["track", str(sim / "measurements.csv"), "--geometry", "b", "--estimator", estimator, "--lag", "3"]
    assert main([*args, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["estimator"] == estimator
    n = len(d["times"])
    assert n > 10 and len(d["states"]) == n and len(d["covariances"]) == n
    assert all(len(s) == 4 for s in d["states"])
    assert all(c is None or (len(c) == 4 and all(len(r) == 4 for r in c)) for c in d["covariances"])
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
