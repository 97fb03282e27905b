"""``python -m rvstudy`` = ``rv-stackup``."""
import sys

from rvstudy.cli import main

if __name__ == "__main__":
    sys.exit(main())
