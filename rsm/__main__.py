"""``python -m rsm`` runs the command line (see :mod:`rsm.cli`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
