"""Ctrl-C that is never lost: the command line's SIGINT handling.

Python raises :class:`KeyboardInterrupt` at the next bytecode the main thread
runs after SIGINT. When that bytecode belongs to a finaliser or a weak-reference
callback (``importlib``'s module-lock callback runs one on every import), the
exception is printed as "Exception ignored in ..." and lost: the command ran on
to the end, about once in 40 interrupts at 1-3 s into ``subid identify``
(measured by sending SIGINT at random times; issue 28). :func:`interrupts`
installs a handler that raises the interrupt and, until the command has
handled it, delivers it again every :data:`REDELIVERY` seconds, and silences
the "Exception ignored" report of an interrupt it will deliver again.
"""

from __future__ import annotations

import _thread
import contextlib
import signal
import sys
import threading

#: Seconds between deliveries of an interrupt the command has not handled yet.
REDELIVERY = 0.2


class _Interrupts:
    """The SIGINT handler: raises, and re-delivers until :meth:`handled` is called."""

    def __init__(self):
        self.pending = False
        self.done = False
        self._timer = None
        self._lock = threading.Lock()

    def __call__(self, signum, frame):
        if self.done:
            return
        self.pending = True
        with self._lock:
            if self._timer is None:
                self._timer = threading.Timer(REDELIVERY, self._redeliver)
                self._timer.daemon = True
                self._timer.start()
        raise KeyboardInterrupt

    def _redeliver(self):
        with self._lock:
            self._timer = None
        if not self.done:
            _thread.interrupt_main(signal.SIGINT)

    def handled(self):
        """The command has caught the interrupt (or finished): deliver no more."""
        self.done = True
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None


@contextlib.contextmanager
def interrupts():
    """Install the handler for the duration of a command (main thread only).

    Yields the handler; ``handler.pending`` tells whether an interrupt arrived,
    so a command that finished while its interrupt was lost can still end as
    interrupted. Elsewhere than in the main thread (a test runner's worker) the
    signal handler cannot be set and nothing is installed.
    """
    handler = _Interrupts()
    if threading.current_thread() is not threading.main_thread():
        yield handler
        return
    previous = signal.signal(signal.SIGINT, handler)
    previous_hook = sys.unraisablehook

    def hook(unraisable):
        # an interrupt lost in a finaliser: it is delivered again, do not report it
        if not (handler.pending and isinstance(unraisable.exc_value, KeyboardInterrupt)):
            previous_hook(unraisable)

    sys.unraisablehook = hook
    try:
        yield handler
    finally:
        handler.handled()
        signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = previous_hook
