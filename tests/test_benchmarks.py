"""The accuracy benchmark keeps every per-run number: its records survive a save and load."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import numpy as np
from scipy.stats import chi2

from benchmarks.bench_accuracy import (
    RUN_NEES_LEVEL,
    T_NEES,
    goal_table,
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


def _reproduction_page() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "studies" / "reproduction_page.py"
    spec = importlib.util.spec_from_file_location("reproduction_page", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_reproduction_page_reads_back_the_goals_the_benchmark_writes(tmp_path: Path) -> None:
    """docs/reproduction.md marks the goals from the benchmark's own Markdown: writer and reader agree."""
    page = _reproduction_page()
    scenarios = list(page.SCENARIO_COLUMNS)
    rng = np.random.default_rng(5)
    met: dict[tuple[int, str, str], bool] = {}
    for seed in (7, 2026):
        rows = []
        for goal in ("1: EKF <= plain EKF and UKF", "2: best online <= best peer filter"):
            for sn in scenarios:
                met[seed, goal, sn] = bool(rng.random() < 0.5)
                rows.append((goal, sn, met[seed, goal, sn], "ekf 1 vs 2", ""))
        rows.append(("3: smoother <= 1.1 x smoothing CRLB", scenarios[2], True, "0.94", ""))
        text = f"100 runs per scenario, seed {seed}.\n\n| x |\n|---|\n\n" + "\n".join(goal_table(rows)) + "\n"
        (tmp_path / f"accuracy_seed{seed}.md").write_text(text)
        back = page.goal_rows(text)
        assert back == {(g, page.SCENARIO_COLUMNS[sn]): "yes" if ok else "no" for g, sn, ok, _, _ in rows}
    part = page.accuracy_part(tmp_path)
    assert "seeds 7 and 2026" in part and "100 runs per scenario" in part
    for goal in ("1: EKF <= plain EKF and UKF", "2: best online <= best peer filter"):
        line = next(x for x in part.splitlines() if x.startswith(f"| {goal} |"))
        cells = [c.strip() for c in line.strip("|").split("|")[1:]]
        assert cells == [" / ".join("yes" if met[seed, goal, sn] else "no" for seed in (7, 2026)) for sn in scenarios]
    crlb = next(x for x in part.splitlines() if x.startswith("| 3:"))
    assert crlb.count("yes / yes") == 1 and crlb.count("– / –") == 5
    assert page.accuracy_part(tmp_path / "nothing") == ""
