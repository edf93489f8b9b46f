"""The ``fgdoppler`` command line: one module per subcommand, the entry point in :mod:`fgdoppler.cli.main`."""

from fgdoppler.cli.common import CLIError
from fgdoppler.cli.main import build_parser, main

__all__ = ["CLIError", "build_parser", "main"]
