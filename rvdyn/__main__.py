import sys

from rvdyn.cli import main

sys.exit(main())
