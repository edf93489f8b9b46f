"""Run every benchmark and write a Markdown table: ``python -m benchmarks [--out PATH] [--only NAME ...]``."""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

from benchmarks import (
    bench_accuracy,
    bench_check_values,
    bench_ekf,
    bench_factors,
    bench_grid,
    bench_io,
    bench_kernels,
    bench_long,
    bench_mode_search,
    bench_montecarlo,
    bench_motion_check,
    bench_particle,
    bench_scaling,
    bench_shared_reference,
    bench_small_inverse,
    bench_startup,
    bench_widening,
)

BENCHES = {"grid": bench_grid, "ekf": bench_ekf, "scaling": bench_scaling, "montecarlo": bench_montecarlo,
           "long": bench_long, "particle": bench_particle, "modes": bench_mode_search,
           "motion": bench_motion_check, "shared": bench_shared_reference, "widening": bench_widening,
           "accuracy": bench_accuracy, "factors": bench_factors, "io": bench_io,
           "startup": bench_startup, "inverse": bench_small_inverse,
           "check": bench_check_values, "kernels": bench_kernels}


def main() -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks")
    p.add_argument("--out", type=Path, default=Path("output/benchmarks.md"))
    p.add_argument("--only", nargs="+", choices=sorted(BENCHES), default=list(BENCHES))
    args = p.parse_args()
    rows = []
    for name in args.only:
        print(f"running {name} ...", flush=True)
        rows += BENCHES[name].run()
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    lines = [f"Machine: {machine}", "", "| benchmark | measured | ratio | target | met |", "|---|---|---|---|---|"]
    for r in rows:
        ratio = "" if r.ratio is None else f"{r.ratio:.2f}"
        met = "" if r.met is None else ("yes" if r.met else "**no**")
        lines.append(f"| {r.name} | {r.value} | {ratio} | {r.target} | {met} |")
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
