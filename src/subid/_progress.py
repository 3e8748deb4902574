"""Progress bars (tqdm) for long work, shown on a terminal only.

Used by the commands (CLI, demo, experiments), never by library numerics.
"""

from __future__ import annotations

import sys
import threading


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


class Steps:
    """A bar over the named steps of a command (read, identify, report, ...).

    The bar names the step under way and is redrawn every ``refresh`` seconds by
    a daemon thread, so that its elapsed time keeps moving through a step that
    reports nothing itself (an identification, a report). With ``enabled``
    False every method does nothing. Use as a context manager; :meth:`start`
    begins the next step, :meth:`detail` names a part of it.
    """

    def __init__(self, names, desc: str, *, enabled: bool, refresh: float = 0.5):
        self._names = list(names)
        self._bar = progress_bar(len(self._names), desc, "step", enabled=enabled)
        self._current: str | None = None
        self._done: threading.Event | None = None
        if self._bar is not None:
            self._done = threading.Event()
            self._thread = threading.Thread(target=self._redraw, args=(refresh,), daemon=True)
            self._thread.start()

    def _redraw(self, refresh):
        while not self._done.wait(refresh):
            self._bar.refresh()

    def start(self, name: str) -> None:
        """Begin step ``name`` (the previous one is counted as done)."""
        if self._bar is None:
            return
        if self._current is not None:
            self._bar.update(1)
        self._current = name
        self._bar.set_postfix_str(name, refresh=True)

    def finished(self, name: str) -> None:
        """Count step ``name`` as done (steps run in parallel, finishing in any order)."""
        if self._bar is not None:
            self._bar.update(1)
            self._bar.set_postfix_str(f"{name} done", refresh=True)

    def detail(self, text: str) -> None:
        """Name a part of the current step (``report: bode``)."""
        if self._bar is not None:
            self._bar.set_postfix_str(f"{self._current}: {text}", refresh=True)

    def close(self) -> None:
        if self._bar is None:
            return
        if self._done is not None:
            self._done.set()
        self._thread.join()
        self._bar.close()
        self._bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
