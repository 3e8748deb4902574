"""Progress bars (tqdm) for long work, shown on a terminal only.

Used by the commands (CLI, demo, experiments), never by library numerics.
"""

from __future__ import annotations

import sys


def on_terminal(quiet: bool = False) -> bool:
    """Whether to show a bar: stderr is a terminal and the user did not ask for quiet."""
    return not quiet and sys.stderr.isatty()


def progress_bar(total: int, desc: str, unit: str, *, enabled: bool, initial: int = 0):
    """A manually updated tqdm bar, or None when not ``enabled``."""
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, initial=initial, desc=desc, unit=unit, file=sys.stderr,
                dynamic_ncols=True, leave=False)


def progress_wrapper(desc: str, unit: str, *, enabled: bool):
    """A function wrapping an iterable in a tqdm bar, or None when not ``enabled``."""
    if not enabled:
        return None
    from tqdm import tqdm

    def wrap(iterable, **kwargs):
        return tqdm(iterable, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True,
                    leave=False, **kwargs)
    return wrap
