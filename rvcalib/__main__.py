"""``python -m rvcalib``: the ``rv-calibrate`` command line."""
from rvcalib.cli import main

raise SystemExit(main())
