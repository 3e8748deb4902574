"""What the readers of :mod:`subid.io.formats` share: file arguments, size limits, the
limits of what a text line and an error message may hold, and the IOData they build."""

from __future__ import annotations

import numbers
import os
import re
from pathlib import Path

import numpy as np

from subid.data import IOData
from subid.errors import DataError, FileReadError, ResourceLimitError
from subid.io._files import MAX_EXPANDED_BYTES, open_regular, read_regular

_TEXT_EXTENSIONS = (".csv", ".tsv", ".txt", ".dat")
_ARRAY_EXTENSIONS = (".npz", ".mat")
#: File extensions :func:`read` understands.
SUPPORTED_EXTENSIONS = _TEXT_EXTENSIONS + _ARRAY_EXTENSIONS

_WHITESPACE = None            # delimiter value meaning "runs of spaces/TABs"
_SNIFF_LINES = 20             # lines looked at to detect the delimiter
_MAX_LISTED = 40              # column/array names listed in an error message
_INT_RE = re.compile(r"[+-]?\d+")
_DECIMAL_COMMA_RE = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Longest line of a text file, in characters: a longer one is refused
#: (ResourceLimitError) before it is split, so memory stays bounded.
MAX_LINE_CHARS = 4 * 2**20


def _as_path(path) -> tuple[str, Path]:
    """``(name as given, Path)`` of a file argument, or a DataError."""
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if not isinstance(path, (str, os.PathLike)):
        raise DataError(f"path must be a file name (str or os.PathLike), got {type(path).__name__}")
    shown = os.fspath(path)
    return shown, Path(shown)


def _max_bytes(max_bytes) -> int:
    if max_bytes is None:
        return MAX_EXPANDED_BYTES
    if isinstance(max_bytes, bool) or not isinstance(max_bytes, numbers.Integral) \
            or max_bytes < 0:
        raise DataError(f"max_bytes must be a non-negative integer, got {max_bytes!r}")
    return int(max_bytes)


def _check_exists(p: Path, shown: str) -> int:
    """Size of the regular, non-empty file ``p`` (FileReadError otherwise)."""
    fh, size = open_regular(shown, what="data file", max_bytes=None)
    fh.close()
    if size == 0:
        raise FileReadError(f"file {shown} is empty", path=shown)
    return size


def _read_bytes(p: Path, shown: str) -> bytes:
    """The bytes of a regular, non-empty file, read once (FileReadError otherwise)."""
    raw = read_regular(shown, what="data file", max_bytes=None)
    if not raw:
        raise FileReadError(f"file {shown} is empty", path=shown)
    return raw


def _check_line_lengths(raw: bytes, shown: str) -> None:
    """ResourceLimitError when a line of ``raw`` is longer than MAX_LINE_CHARS
    (scanned in blocks, so the check itself needs little memory)."""
    if len(raw) <= MAX_LINE_CHARS:
        return
    view = np.frombuffer(raw, dtype=np.uint8)
    block = 1 << 24
    last, lines = -1, 0                  # position of the previous newline, lines before it
    for a in range(0, len(raw), block):
        ends = np.flatnonzero(view[a:a + block] == 10) + a
        if ends.size:
            gaps = np.diff(ends, prepend=last) - 1
            k = int(np.argmax(gaps))
            if gaps[k] > MAX_LINE_CHARS:
                lines += k
                break
            lines += ends.size
            last = int(ends[-1])
    else:
        if len(raw) - 1 - last <= MAX_LINE_CHARS:
            return
    raise ResourceLimitError(f"{shown}, line {lines + 1}: the line is longer than the "
                             f"{MAX_LINE_CHARS} characters subid reads "
                             "(subid.io.formats.MAX_LINE_CHARS); is this a text data file?",
                             path=shown, line=lines + 1)


def _build(shown: str, u, y, dt, t, in_names, out_names, first_line=None) -> IOData:
    """Construct the IOData, prefixing its validation errors with the file name."""
    try:
        return IOData(u, y, dt=dt, t=t, input_names=in_names, output_names=out_names,
                      copy=False)          # arrays of our own, never seen by the caller
    except DataError as exc:
        where = ""
        if first_line is not None and "row" in str(exc):
            where = f" (rows are counted from 0 at the first data row, line {first_line})"
        raise type(exc)(f"{shown}: {exc}{where}") from None


def _listing(items, limit: int = _MAX_LISTED) -> str:
    items = list(items)
    text = ", ".join(items[:limit])
    if len(items) > limit:
        text += f", ... ({len(items)} in all)"
    return text



def _reason(exc: BaseException) -> str:
    """Short printable description of a library exception, for messages."""
    text = "".join(ch if ch.isprintable() else "?" for ch in str(exc))
    if len(text) > 160:
        text = text[:160] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def first_non_finite(values: np.ndarray):
    """Where the (rows, columns) array ``values`` holds NaN or inf: ``None`` when it is
    finite, else ``(row, column, count, rows)``: the first such cell (its row, then its
    column), the number of such values and the number of rows holding them (the
    readers' messages name the first and count the rest)."""
    finite = np.isfinite(values)
    if finite.all():
        return None
    bad_rows = np.flatnonzero(~finite.all(axis=1))
    row = int(bad_rows[0])
    return row, int(np.flatnonzero(~finite[row])[0]), int((~finite).sum()), bad_rows.size
