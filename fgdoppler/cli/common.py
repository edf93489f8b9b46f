"""Shared pieces of the subcommands: user errors, JSON output, progress bars, executors."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

__all__ = ["CLIError", "emit_json", "executor", "progress_bar"]


class CLIError(Exception):
    """A user error: printed without a traceback, exit status 2."""


def emit_json(obj: Any) -> None:
    """Print ``obj`` as JSON on stdout (no NaN or infinity)."""
    json.dump(obj, sys.stdout, indent=2, allow_nan=False)
    sys.stdout.write("\n")


def progress_bar(total: int, desc: str, unit: str = "state") -> Any:
    """A tqdm bar on stderr, shown only on a terminal."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not sys.stderr.isatty(), leave=False)


def executor(args: argparse.Namespace) -> tuple[Any, Any]:
    """(executor, client) for ``--scheduler`` (Dask distributed), or (None, None)."""
    if not getattr(args, "scheduler", None):
        return None, None
    try:
        from distributed import Client
    except ImportError as exc:
        raise CLIError("--scheduler needs the optional extra: pip install 'fgdoppler[distributed]'") from exc
    client = Client(args.scheduler)
    return client.get_executor(), client
