"""`fgdoppler reproduce --quick` end to end (small): every artefact is in the report."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fgdoppler.cli import main


@pytest.mark.reproduce
def test_reproduce_quick_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "repro"
    assert main(["reproduce", "--quick", "--runs", "2", "--out", str(out), "--json"]) == 0
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
