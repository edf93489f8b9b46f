"""Compare two output folders of the regression reference or a benchmark, run times aside.

``python -m benchmarks.compare_outputs OLD NEW`` reads every ``.npz`` and
``.json`` file of folder ``OLD`` and the file of the same name in ``NEW``
(``fgdoppler reproduce --out``, ``python -m benchmarks.bench_accuracy --out``,
``fgdoppler montecarlo --out``) and reports what differs: arrays bit for bit
(NaN equal to NaN; shape and dtype too), JSON values exactly, at any depth.
Run times and the machine's load are expected to differ between two runs and
are left out: arrays named ``seconds_*`` or ``wall_*`` and JSON keys in
:data:`TIMING_KEYS`.  A file or array present on one side only is a
difference.  Exit status 0 when nothing else differs, 1 otherwise (or when
neither folder holds such a file) — the before/after check of a change that
should leave every estimate alone.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

#: JSON keys whose values are run times or the machine's state, not results.
TIMING_KEYS = frozenset({"wall_time", "timing", "timing_per_run", "seconds", "wall", "load"})
#: Array-name prefixes of run times in the ``.npz`` records.
TIMING_PREFIXES = ("seconds_", "wall_")


def _same_array(a: np.ndarray, b: np.ndarray) -> bool:
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))


def npz_differences(old: Path, new: Path) -> tuple[list[str], int]:
    """Names of the arrays of two ``.npz`` files that differ (or are on one side only), and how many were compared.

    Arrays named with a :data:`TIMING_PREFIXES` prefix are neither compared nor counted.
    """
    with np.load(old, allow_pickle=False) as a, np.load(new, allow_pickle=False) as b:
        names = sorted(set(a.files) | set(b.files))
        kept = [n for n in names if not n.startswith(TIMING_PREFIXES)]
        out = [n for n in kept if n not in a.files or n not in b.files or not _same_array(a[n], b[n])]
    return out, len(kept)


def json_differences(old: Any, new: Any, path: str = "") -> Iterator[str]:
    """Paths (``/key[index]``) where two JSON values differ, keys in :data:`TIMING_KEYS` left out."""
    if isinstance(old, dict) and isinstance(new, dict):
        for key in sorted(set(old) | set(new), key=str):
            if key in TIMING_KEYS:
                continue
            if key not in old or key not in new:
                yield f"{path}/{key} (one side only)"
            else:
                yield from json_differences(old[key], new[key], f"{path}/{key}")
    elif isinstance(old, list) and isinstance(new, list):
        if len(old) != len(new):
            yield f"{path} (length {len(old)} vs {len(new)})"
            return
        for i, (x, y) in enumerate(zip(old, new, strict=True)):
            yield from json_differences(x, y, f"{path}[{i}]")
    elif old != new or type(old) is not type(new):
        yield f"{path}: {old!r} vs {new!r}"[:300]


def compare(old: Path, new: Path) -> list[str]:
    """One line per file of ``old`` (and per ``.npz``/``.json`` file only in ``new``); the differences marked."""
    lines = []
    files = sorted({p.name for p in old.iterdir() if p.suffix in (".npz", ".json")}
                   | {p.name for p in new.iterdir() if p.suffix in (".npz", ".json")})
    for name in files:
        a, b = old / name, new / name
        if not a.exists() or not b.exists():
            lines.append(f"DIFFERS {name}: only in {old if a.exists() else new}")
        elif a.suffix == ".npz":
            diff, n = npz_differences(a, b)
            lines.append(f"DIFFERS {name}: {len(diff)} of {n} arrays: {', '.join(diff[:20])}"
                         + (" ..." if len(diff) > 20 else "") if diff else f"same    {name}: {n} arrays")
        else:
            found = list(json_differences(json.loads(a.read_text()), json.loads(b.read_text())))
            lines.append(f"DIFFERS {name}: " + "; ".join(found[:10]) + (" ..." if len(found) > 10 else "")
                         if found else f"same    {name}")
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.compare_outputs", description=__doc__.splitlines()[0])
    p.add_argument("old", type=Path, help="the reference's output folder")
    p.add_argument("new", type=Path, help="the output folder to check against it")
    args = p.parse_args(argv)
    for folder in (args.old, args.new):
        if not folder.is_dir():
            p.error(f"{folder} is not a folder")
    lines = compare(args.old, args.new)
    print("\n".join(lines) if lines else "no .npz or .json files in either folder")
    return 1 if not lines or any(line.startswith("DIFFERS") for line in lines) else 0


if __name__ == "__main__":
    raise SystemExit(main())
