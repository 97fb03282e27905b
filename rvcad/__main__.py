"""``python -m rvcad``: the rvcad command line (see :mod:`rvcad.cli`)."""
from __future__ import annotations

import sys

from rvcad.cli import main

if __name__ == "__main__":
    sys.exit(main())
