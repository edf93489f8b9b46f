"""``fgdoppler reproduce``: every table and figure of the paper, with report.md."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fgdoppler.cli.common import CLIError, emit_json, executor

__all__ = ["add_reproduce"]


def add_reproduce(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "reproduce",
        help="every table and figure of the paper plus the new studies, with report.md",
        description="Reproduce Table 2, Figs 3-8 and 10-11 of the paper, the lag sweep, NEES and "
        "observability reports into --out, with report.md comparing the paper's values and ours.",
    )
    p.add_argument("--quick", action="store_true", help="few runs (5 per scenario, 1 per cell of the altitude study): about 3 min on 2 idle cores")
    p.add_argument("--runs", type=int, default=None, help="runs per scenario (default 100; 5 with --quick)")
    p.add_argument("--altitude-runs", type=int, default=None, metavar="N",
                   help="runs per scenario and height of the 3-D altitude study (default: runs / 10, at least 1; "
                   "0 skips the study)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=2026, help="root seed (default 2026)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler address (optional extra)")
    p.add_argument("--out", type=Path, default=Path("output/reproduce"), help="output folder (default output/reproduce)")
    p.add_argument("--json", action="store_true", help="print the claims as JSON")
    p.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    import os

    from fgdoppler.analysis.reproduce import ReproduceSettings, reproduce

    os.environ.setdefault("MPLBACKEND", "Agg")
    runs = args.runs if args.runs is not None else (5 if args.quick else 100)
    if runs < 1:
        raise CLIError("--runs must be >= 1")
    if args.altitude_runs is not None and args.altitude_runs < 0:
        raise CLIError("--altitude-runs must be >= 0")
    pool, client = executor(args)
    try:
        report = reproduce(args.out, ReproduceSettings(runs=runs, workers=args.workers, seed=args.seed,
                                                         altitude_runs=args.altitude_runs),
                           executor=pool)
    finally:
        if client is not None:
            client.close()
    claims = json.loads((args.out / "claims.json").read_text())
    if args.json:
        emit_json(claims)
    else:
        n_ok = sum(claims["claims"].values())
        print(f"wrote {report} ({runs} runs per scenario, {claims['wall_time']:.1f} s)")
        print(f"{n_ok} of {len(claims['claims'])} claims reproduced:")
        for c, ok in claims["claims"].items():
            print(f"  [{'yes' if ok else 'NO '}] {c}")
        if "note" in claims:
            print(claims["note"])
    return 0
