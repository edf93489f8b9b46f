"""The ``fgdoppler`` command line.

Every subcommand has ``--help``; ``--json`` prints machine-readable output on
stdout; figures are written only where asked (``--plot PATH``).  Errors in the
input end the command with exit status 2 and a message naming the file and
line; nothing is written then.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Callable, Sequence

from fgdoppler import __version__
from fgdoppler.cli.common import CLIError
from fgdoppler.cli.montecarlo import add_montecarlo
from fgdoppler.cli.observability import add_observability
from fgdoppler.cli.reproduce import add_reproduce
from fgdoppler.cli.simulate import add_simulate
from fgdoppler.cli.track import add_track

__all__ = ["build_parser", "main"]

Handler = Callable[[argparse.Namespace], int]
SUBCOMMANDS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (
    add_simulate, add_observability, add_track, add_montecarlo, add_reproduce)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="fgdoppler",
        description="Doppler-only multistatic tracking near the Tx-Rx baseline "
        "(factor graphs, EKF, observability, Monte Carlo).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in SUBCOMMANDS:
        add(sub)
    return parser


#: Exit statuses: 0 success, 1 an internal error, 2 bad input (nothing written), 3 a ``failed`` verdict.
EXIT_OK, EXIT_INTERNAL, EXIT_INPUT = 0, 1, 2


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (:data:`EXIT_OK` ... and 3 for a failed track)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler = args.handler
    try:
        # Warnings are for programmers; users get the messages the commands print themselves.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return handler(args)
    except BrokenPipeError:  # e.g. piped into `head`
        sys.stderr.close()
        return EXIT_OK
    except (CLIError, ValueError, OSError) as exc:
        print(f"fgdoppler {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except Exception as exc:  # a bug, not the user's input: one line, the traceback on request
        if os.environ.get("FGDOPPLER_DEBUG"):
            raise
        print(f"fgdoppler {args.command}: internal error: {type(exc).__name__}: {_one_line(exc)} "
              "(please report it; FGDOPPLER_DEBUG=1 shows the traceback)", file=sys.stderr)
        return EXIT_INTERNAL


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
