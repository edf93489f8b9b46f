"""The accuracy benchmark keeps every per-run number: its records survive a save and load."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.bench_accuracy import json_summary, load_records, save_records


def _records() -> list[dict[str, object]]:
    rng = np.random.default_rng(3)
    out: list[dict[str, object]] = []
    for s in range(2):
        for r in range(3):
            res = {name: {"se": rng.random(4), "nees": rng.random(4), "seconds": float(rng.random()),
                          "status": "ok" if r else "doubtful"} for name in ("ekf", "smoother")}
            if r != 1:  # the peer did not run in run 1
                res["filterpy-ekf"] = {"se": rng.random(4), "nees": rng.random(4), "seconds": 0.1, "status": "ran"}
            out.append({"s": s, "r": r, "results": res})
    return out


def test_records_round_trip(tmp_path: Path) -> None:
    recs = _records()
    save_records(recs, tmp_path / "r.npz")
    back = load_records(tmp_path / "r.npz")
    assert [(b["s"], b["r"]) for b in back] == [(a["s"], a["r"]) for a in recs]
    for a, b in zip(recs, back, strict=True):
        assert set(a["results"]) == set(b["results"])  # type: ignore[arg-type]
        for name, x in a["results"].items():  # type: ignore[attr-defined]
            y = b["results"][name]
            np.testing.assert_array_equal(x["se"], y["se"])
            np.testing.assert_array_equal(x["nees"], y["nees"])
            assert x["seconds"] == y["seconds"] and x["status"] == y["status"]


def test_json_summary_leaves_out_the_per_run_arrays() -> None:
    text = json_summary({"runs": 3, "scenarios": {"a": {"_se": {"ekf": np.zeros(2)}, "crlb_filter": 1.0}}})
    assert "_se" not in text and "crlb_filter" in text
