"""The accuracy benchmark keeps every per-run number: its records survive a save and load."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.stats import chi2

from benchmarks.bench_accuracy import (
    RUN_NEES_LEVEL,
    T_NEES,
    inconsistent_runs,
    json_summary,
    load_records,
    save_records,
)


def _records() -> list[dict[str, object]]:
    rng = np.random.default_rng(3)
    out: list[dict[str, object]] = []
    for s in range(2):
        for r in range(3):
            res = {name: {"se": rng.random(4), "nees": rng.random(4), "seconds": float(rng.random()),
                          "wall": float(rng.random()), "status": "ok" if r else "doubtful"}
                   for name in ("ekf", "smoother")}
            if r != 1:  # the peer did not run in run 1
                res["filterpy-ekf"] = {"se": rng.random(4), "nees": rng.random(4), "seconds": 0.1,
                                       "wall": float("nan"), "status": "ran"}
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
            np.testing.assert_array_equal(x["wall"], y["wall"])


def test_records_without_wall_times_still_load(tmp_path: Path) -> None:
    """Records written before the wall times were kept load with NaN for them."""
    save_records(_records(), tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz") as z:
        old = {k: z[k] for k in z.files if not k.startswith("wall_")}
    np.savez(tmp_path / "old.npz", **old)
    back = load_records(tmp_path / "old.npz")
    assert back and all(np.isnan(x["wall"]) for rec in back for x in rec["results"].values())


def test_json_summary_leaves_out_the_per_run_arrays() -> None:
    text = json_summary({"runs": 3, "scenarios": {"a": {"_se": {"ekf": np.zeros(2)}, "crlb_filter": 1.0}}})
    assert "_se" not in text and "crlb_filter" in text


def test_inconsistent_runs_counts_the_runs_beyond_the_quantile_and_the_verdicts_that_miss_them() -> None:
    t = np.array([0.0, 5.0, T_NEES, T_NEES + 5.0])
    q = chi2.ppf(RUN_NEES_LEVEL, 4)
    nees = np.array([
        [1e9, 1e9, 4.0, 4.0],            # large only before T_NEES: consistent
        [np.nan, np.nan, q - 1, q + 3],  # average q + 1: inconsistent, judged ok
        [4.0, 4.0, q + 1, np.nan],       # inconsistent where it has a value, judged doubtful
        [4.0, 4.0, np.nan, np.nan],      # no NEES after T_NEES: neither
        [4.0, 4.0, q - 0.5, q - 0.5],    # below the quantile
    ])
    statuses = ["ok", "ok", "doubtful", "ok", "ok"]
    assert inconsistent_runs(nees, t, statuses) == (2, 1)
    assert inconsistent_runs(nees, t, ["doubtful"] * 5) == (2, 0)
    assert inconsistent_runs(np.zeros((0, 4)), t, []) == (0, 0)


def test_the_table_says_when_other_jobs_ran_beside_it() -> None:
    """CPU times beside other jobs come out longer: the Markdown says so when the load exceeds the workers."""
    from benchmarks.bench_accuracy import _load_note

    busy = _load_note({"load": {"average_15_min": 4.2, "workers": 2, "cores": 2}})
    quiet = _load_note({"load": {"average_15_min": 2.1, "workers": 2, "cores": 2}})
    assert "other jobs ran beside it" in busy and "other jobs" not in quiet and "2.1" in quiet
    assert _load_note({}) == ""  # re-summarised records: no load known
