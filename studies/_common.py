"""Shared helpers for the study scripts: the output folder and a non-interactive backend."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")


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
