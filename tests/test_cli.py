"""The command line: help everywhere, simulate writes its files, errors exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import fgdoppler as fd
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
