"""Shared helpers for the study scripts: the output folder, a non-interactive backend, the benchmarks importable."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
# A study run as a script sees only its own folder; the repository root makes the benchmarks' recordings
# importable, so a study measures on exactly the benchmark's data instead of a copy of its definition.
_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.append(_ROOT)


def out_dir(default: str) -> Path:
    """The output folder (``--out``, default under the git-ignored ``output/``)."""
    p = argparse.ArgumentParser()
    p.add_argument("--out", type=Path, default=Path("output") / default)
    return p.parse_args().out


def report(artefact) -> None:  # type: ignore[no-untyped-def]
    """Print what an artefact produced and its claims."""
    print(artefact.summary)
    for claim, ok in artefact.claims.items():
        print(f"  [{'reproduced' if ok else 'NOT reproduced'}] {claim}")
    for f in artefact.files:
        print(f"  wrote {f}")
