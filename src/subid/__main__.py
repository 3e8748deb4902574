"""``python -m subid``: the ``subid`` command line (see :mod:`subid.cli.commands`)."""

import sys

from subid.cli.commands import main

if __name__ == "__main__":
    sys.exit(main())
