"""The ``subid`` command line (no library logic lives here)."""

from subid.cli.commands import main

__all__ = ['main']
