"""``python -m subid``: the ``subid`` command line (see :mod:`subid.cli`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
