"""``python -m fgdoppler`` runs the command line."""

import sys

from fgdoppler.cli.main import main

sys.exit(main())
