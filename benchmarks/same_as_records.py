"""Whether some estimators still give the accuracy benchmark's recorded answers, to the bit, without the whole run.

For a change meant to leave the paper's recordings alone (a test that never fires there): every run of
``python -m benchmarks.bench_accuracy --seed S`` is simulated and initiated again as the benchmark does, the
reference smoother run, then each named estimator with it; their squared position errors, NEES and verdicts on
the truth's time grid are compared with the per-run records (``accuracy_seedS.npz``) the benchmark saved.
Printed: per scenario and estimator, the runs that differ, and the median CPU time against the records' (another
day's timing: only indicative; paired ratios need both in one run).

For a change meant to move some estimators, ``--write MERGED.npz`` saves the records with those estimators' runs
replaced by the new ones (every other estimator's, and the peers', as recorded), and ``python -m
benchmarks.bench_accuracy --records MERGED.npz --seed S`` summarises them as a whole benchmark run would: the new
rows beside the old ones on the same 600 recordings, for a fraction of the run time.

Run: python -m benchmarks.same_as_records output/acc/accuracy_seed2026.npz --seed 2026 [--estimators particle map]
[--runs 100] [--workers 2] [--write MERGED.npz]   (about 15 min a seed on 2 cores)
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

import fgdoppler as fd
from benchmarks.bench_accuracy import VARIANTS, _on_grid, recording
from fgdoppler.analysis.workers import one_blas_thread
from fgdoppler.estimators.registry import estimator_info


@one_blas_thread
def one_run(args: tuple[int, int, int, tuple[str, ...]]) -> dict[str, Any]:
    """Run ``r`` of scenario ``s`` as the benchmark records it, for the named estimators only."""
    s, r, seed, names = args
    sim, model, init = recording(s, r, seed)
    m = sim.measurements
    reference = fd.run_estimator("smoother", m, model, init)
    out: dict[str, Any] = {"s": s, "r": r}
    for name in names:
        estimator, settings = VARIANTS.get(name, (name, None))
        cpu, wall = time.process_time(), time.perf_counter()
        res = fd.run_estimator(estimator, m, model, init, settings, reference=reference)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        e = res.primary
        se, ne = _on_grid(sim.truth.times, e.times, e.states, e.covariances, sim.truth.states, e.cov_ok)
        out[name] = {"se": se, "nees": ne, "status": str(res.status), "seconds": cpu, "wall": wall}
    return out


def compare(records: Any, rows: list[dict[str, Any]], names: tuple[str, ...]) -> list[str]:
    """A table of the runs that differ from the records, per scenario and estimator."""
    lines = ["| scenario | estimator | runs the same | differ (runs) | median CPU now / recorded (s) |",
             "|---|---|---|---|---|"]
    for s, scen in enumerate(fd.paper_scenarios()):
        rs = sorted((x for x in rows if x["s"] == s), key=lambda x: x["r"])
        for name in names:
            differ = [x["r"] for x in rs if not (
                np.array_equal(x[name]["se"], records[f"se_{s}_{name}"][x["r"]], equal_nan=True)
                and np.array_equal(x[name]["nees"], records[f"nees_{s}_{name}"][x["r"]], equal_nan=True)
                and x[name]["status"] == str(records[f"status_{s}_{name}"][x["r"]]))]
            now = np.median([x[name]["seconds"] for x in rs])
            then = np.median(records[f"seconds_{s}_{name}"][[x["r"] for x in rs]])
            lines.append(f"| {scen.name} | {name} | {len(rs) - len(differ)} of {len(rs)} | "
                         f"{', '.join(map(str, differ)) or '-'} | {now:.3f} / {then:.3f} |")
    return lines


def merged(records: Any, rows: list[dict[str, Any]], names: tuple[str, ...]) -> dict[str, Any]:
    """The records' arrays with the runs of ``names`` replaced by ``rows`` (the benchmark's ``field_s_name`` keys)."""
    # verdicts as text wide enough for any of them: a column that held only "ok" would cut "doubtful" short
    out: dict[str, Any] = {k: np.array(records[k], dtype="<U16" if k.startswith("status_") else None)
                           for k in records.files}
    for x in rows:
        for name in names:
            for field in ("se", "nees", "status", "seconds", "wall"):
                key = f"{field}_{x['s']}_{name}"
                if key in out:
                    out[key][x["r"]] = x[name][field]
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("records", type=Path, help="the benchmark's per-run records (accuracy_seedS.npz)")
    p.add_argument("--seed", type=int, required=True, help="the seed the records were made with")
    p.add_argument("--estimators", nargs="+", default=["particle", "map"],
                   help="registry names or the benchmark's variants (ekf-scan)")
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--write", type=Path, default=None,
                   help="save the records with the named estimators' runs replaced by the new ones here")
    a = p.parse_args()
    names = tuple(n if n in VARIANTS else estimator_info(n).name for n in a.estimators)
    records = np.load(a.records, allow_pickle=False)
    if records[f"se_0_{names[0]}"].shape[0] < a.runs:
        p.error(f"the records hold {records[f'se_0_{names[0]}'].shape[0]} runs per scenario, fewer than --runs")
    tasks = [(s, r, a.seed, names) for s in range(len(fd.paper_scenarios())) for r in range(a.runs)]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one_run, tasks, chunksize=4))
    print("\n".join(compare(records, rows, names)))
    if a.write is not None:
        a.write.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(a.write, **merged(records, rows, names))
        print(f"wrote {a.write}")


if __name__ == "__main__":
    main()
