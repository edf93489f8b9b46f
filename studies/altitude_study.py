"""The paper's six scenarios at altitude over the same ground sensors (3-D): table, figure, JSON.

Run: python studies/altitude_study.py --runs 10 --workers 2 --out output/altitude
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

from fgdoppler.analysis.altitude import altitude_study


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=10, help="runs per scenario and height (default 10)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=2028, help="root seed (default 2028, as reproduce's 2026 + 2)")
    p.add_argument("--out", type=Path, default=Path("output") / "altitude")
    args = p.parse_args()
    study = altitude_study(runs=args.runs, seed=args.seed, workers=args.workers)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "altitude.md").write_text(study.table_markdown() + "\n", encoding="utf-8")
    (args.out / "altitude.json").write_text(json.dumps(study.to_dict(), indent=1), encoding="utf-8")
    study.figure(args.out / "altitude.png")
    print(study.table_markdown())
    print(f"{study.wall_time:.0f} s; wrote {args.out}/altitude.md, .json, .png")


if __name__ == "__main__":
    main()
