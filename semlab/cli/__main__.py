"""``python -m semlab.cli``: the ``semlab`` command, as before ``semlab/cli.py`` became a package."""

import sys

from semlab.cli import main

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
