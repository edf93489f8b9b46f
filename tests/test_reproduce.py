"""`fgdoppler reproduce --quick` end to end (small): every artefact is in the report."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fgdoppler.cli import main


@pytest.mark.reproduce
def test_reproduce_quick_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "repro"
    # the altitude study (3-D) has its own test below: skipped here to keep the suite short; one run per
    # scenario exercises every step of the job (its statistics are the Monte Carlo tests' and `-m slow`'s)
    assert main(["reproduce", "--quick", "--runs", "1", "--altitude-runs", "0", "--out", str(out), "--json"]) == 0
    claims = json.loads(capsys.readouterr().out)["claims"]
    assert any(k.startswith("Table 2") for k in claims)
    report = (out / "report.md").read_text()
    expected = ["table2.md", "fig3_geometry.png", "fig4_map_group1.png", "fig5_map_group2.png", "fig6_map_group3.png",
                "fig7_map_group4.png", "fig7a_ellipses.png", "fig8_slices.png", "fig10_rmse_case_a.png",
                "fig11_rmse_case_b.png", "nees.png", "lag_sweep.png", "montecarlo.npz", "montecarlo.json",
                "lag_sweep.npz"]
    for name in expected:
        assert (out / name).stat().st_size > 0, name
    for name in [n for n in expected if n.endswith(".png")]:
        assert name in report, name
    for section in ("Table 2", "Figs. 10–11", "Lag sweep", "NEES", "Observability report"):
        assert section in report
    # one run settles no Monte Carlo claim, and the report, the JSON and the printed summary say so
    n_mc = sum(k.split(":")[0] in ("Fig. 10", "Fig. 11", "Section 5", "smoother") for k in claims)
    note = json.loads((out / "claims.json").read_text())["note"]
    assert note.startswith(f"With 1 run per scenario, the last {n_mc} claims") and note in report
    assert list(claims)[-n_mc:] == [k for k in claims if k.split(":")[0] in ("Fig. 10", "Fig. 11", "Section 5",
                                                                             "smoother")]
    # the lag sweep takes a fifth of the runs, at least 4, but never more than the study was given
    assert json.loads((out / "lag_sweep.json").read_text())["runs"] == 1
    assert "## Lag sweep (case b, start 5 km, 1 run)" in report


def test_altitude_section_of_the_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The 3-D altitude study's report section: its table, one row per scenario and height, and the figure.
    The study itself runs at two of its four heights here, with the EKF as its only online estimator (each
    height is then a run of the 3-D smoother, the EKF and the 2-D smoother; the heights and their bounds are
    test_three_d's, the particle estimator in 3-D is its command-line test's)."""
    from fgdoppler.analysis import altitude
    from fgdoppler.analysis.reproduce import ReproduceSettings, altitude_section

    real = altitude.altitude_study
    monkeypatch.setattr(altitude, "altitude_study", lambda **kw: real(altitudes=(0.0, 3e3), online=("ekf",), **kw))
    lines, fig = altitude_section(tmp_path, ReproduceSettings(runs=2, workers=1, altitude_runs=1,
                                                              altitude_scenarios=(("b", 5e3),)))
    assert fig is not None and fig.stat().st_size > 0
    text = "\n".join(lines)
    assert text.startswith("## Beyond the paper")
    assert "The scenario flown level at 0, 3 km" in text  # one scenario, said so
    assert sum(row.startswith("| case b, start 5 km |") for row in text.splitlines()) == 2  # 0 and 3 km
    assert json.loads((tmp_path / "altitude.json").read_text())["runs"] == 1
    assert altitude_section(tmp_path, ReproduceSettings(runs=2, altitude_runs=0)) == ([], None)


def test_a_reproduction_with_the_papers_runs_carries_no_few_runs_note() -> None:
    from fgdoppler.analysis.reproduce import ReproduceSettings, _few_runs_note

    full = ReproduceSettings().runs
    assert full == 100  # the paper's
    assert _few_runs_note(full, 9) is None and _few_runs_note(full + 1, 9) is None
    assert "the last 9 claims" in (_few_runs_note(full - 1, 9) or "")
