"""Atomic file writes, shared by every writer (models, checkpoints, reports, .mat)."""

from __future__ import annotations

import contextlib
import os
import secrets


def _fsync_directory(directory: str) -> None:
    """Make a rename durable (POSIX); ignored where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path, mode: str = "wb", encoding: str | None = None):
    """Yield a file handle whose content replaces ``path`` only when complete.

    The data go to a new temporary file in the same directory, which is
    flushed, synced to disk and renamed over ``path``: a reader, or a crash
    mid-write, never sees a partly written file, and an existing file is left
    untouched when writing fails.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    tmp = os.path.join(directory, f".{os.path.basename(path)}.{secrets.token_hex(8)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, mode, encoding=encoding) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_directory(directory)
