"""``python -m semlab``: the same command line as the ``semlab`` console script."""

import sys

from semlab.cli import main

if __name__ == "__main__":
    sys.exit(main())
