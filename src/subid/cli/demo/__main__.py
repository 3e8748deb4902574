"""``python -m subid.cli.demo [options]``: the same as ``subid demo [options]``.

A module of its own, so that the demo job (``subid.cli.demo``) never imports the command
line that runs it (issue 24: no module of the command line imports another both ways).
"""

import sys

from subid.cli.commands import main

if __name__ == "__main__":
    sys.exit(main(["demo", *sys.argv[1:]]))
