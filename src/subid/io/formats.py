"""Reading input/output records from files: :func:`read`.

Supported formats, chosen by the file extension:

``.csv``, ``.tsv``
    Delimited text. The delimiter is detected among ``,`` ``;`` and TAB
    unless ``delimiter`` is given.
``.txt``, ``.dat``
    Text with comma- or semicolon-separated fields, or fields separated by
    runs of spaces and TABs (the DaISy / MATLAB ``save -ascii`` style, trailing
    TABs and exponents such as ``1.0000000e+000`` included).
``.npz``
    NumPy archive (:func:`numpy.savez`); arrays are selected by key.
``.mat``
    MATLAB file up to version 7 (:func:`scipy.io.loadmat`); variables are
    selected by name. Version 7.3 (HDF5) files are read with h5py when it is
    installed (the ``hdf5`` extra: ``pip install ".[hdf5]"`` in the source folder).

Rules for text files
--------------------
* A header row is recognised when the first non-empty line holds a field
  that is not a number; columns can then be selected by header name. Without
  a header, columns are selected by 0-based index only. A ``#`` starts a
  comment up to the end of the line; a header written as a comment line right
  before the data (``numpy.savetxt(..., header="t,u,y")``) is recognised too.
* Inputs and outputs are never guessed: both must be given.
* Column numbers in error messages are 0-based, like the indices accepted by
  ``inputs``/``outputs``; line numbers are 1-based, like in a text editor.
* Cells of columns that are not selected are not converted, so a file may
  hold text columns (dates, comments) besides the numeric ones.

Every problem is reported as a :mod:`subid.errors` exception naming the file
and, for text files, the line and column at fault.
"""

from __future__ import annotations

import collections
import csv
import logging
import numbers
import os
import re
from io import BytesIO, StringIO
from pathlib import Path

import numpy as np

from subid import _threads
from subid._validation import check_dt, checked_call, same_period, stamp_resolution
from subid.data import IOData
from subid.errors import DataError, FileReadError, ModelError, ResourceLimitError
from subid.io._files import MAX_EXPANDED_BYTES, atomic_write, open_regular, read_regular
from subid.io._npz import NpzError, NpzLimitError, load_npz

__all__ = ["read", "read_inputs", "SUPPORTED_EXTENSIONS"]

logger = logging.getLogger(__name__)

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


# ---------------------------------------------------------------------------
# public entry point
# ---------------------------------------------------------------------------
@checked_call
def read(path, inputs=None, outputs=None, dt=None, time=None, *, delimiter=None,
         max_bytes=None) -> IOData:
    """Read one input/output record from a file.

    Parameters
    ----------
    path : str or os.PathLike
        The file. Its extension selects the format: ``.csv``, ``.tsv``,
        ``.txt``, ``.dat`` (text), ``.npz`` (NumPy archive) or ``.mat``
        (MATLAB v4 to v7.3; v7.3 needs h5py).
    inputs, outputs : str, int or sequence of str/int
        The input and the output channels.

        * Text files: header names or 0-based column indices; a single name
          or index, a list of them, or a comma-separated string such as
          ``"u1,u2"`` or ``"0,2"``. An integer-like string is an index unless
          the header has a column of that name. Both are **required**.
        * ``.npz`` / ``.mat``: names of arrays (variables), as a single name,
          a list, or a comma-separated string. A 1-D array is one channel; a
          2-D array has time on axis 0 and one channel per column (a MATLAB
          1-by-N row vector is one channel). Default ``"u"`` and ``"y"``.
    dt : float, optional
        Sampling period. For ``.npz``/``.mat`` files, a scalar array ``dt``
        in the file is used when neither ``dt`` nor ``time`` is given.
    time : str or int, optional
        Column (text files) or array (``.npz``/``.mat``) holding the time
        stamps, which may be non-uniform. ``.npz``/``.mat`` files use an
        array ``t`` by default when it exists and ``dt`` is not given. Give
        ``dt`` or ``time``, not both; with neither, ``dt = 1``.
    delimiter : str, optional
        Field delimiter of a text file, one character. ``" "`` means runs of
        spaces and TABs. Detected among ``,`` ``;`` and TAB when omitted.
    max_bytes : int, optional
        Bytes the arrays of a compressed ``.npz``/``.mat`` file may take
        beyond the file's own size (default 1 GiB). A file that would expand
        further is refused with :class:`~subid.errors.ResourceLimitError`
        before it is decompressed: a few megabytes of compressed zeros can
        otherwise declare gigabytes.

    Returns
    -------
    IOData
        The record. Channel names are the header names, ``col<k>`` for
        column ``k`` of a file without a header, or the array names (with
        ``name[k]`` for column ``k`` of a multi-column array).

    Raises
    ------
    DataFileNotFoundError
        The file does not exist.
    ResourceLimitError
        A compressed file expands beyond ``max_bytes``, or a text line is
        longer than ``MAX_LINE_CHARS``.
    FileReadError
        The file cannot be read or interpreted: not a regular file (a FIFO,
        a device, a directory), empty file, unsupported
        extension, a cell that is not a number, rows with different numbers
        of fields, unknown or repeated column/array names, column index out
        of range, missing ``inputs``/``outputs`` for a text file, corrupted
        ``.npz``/``.mat`` file, MATLAB v7.3 file without h5py installed. The ``path``, ``line`` and
        ``column`` attributes locate the problem when known.
    DataError
        The values are unusable (NaN or infinite values, time stamps that do
        not increase, invalid ``dt``), or the arguments are inconsistent
        (``dt`` and ``time`` both given).

    Examples
    --------
    >>> data = subid.read("run1.csv", inputs="u1,u2", outputs="y", time="t")  # doctest: +SKIP
    >>> data = subid.read("dryer.dat", inputs=0, outputs=1, dt=0.08)  # doctest: +SKIP
    """
    shown, p = _as_path(path)
    if dt is not None and time is not None:
        raise DataError(f"{shown}: give either the sampling period dt or the time column/array "
                        "time, not both")
    if dt is not None:
        dt = check_dt(dt)
    ext = p.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        hint = ""
        if ext in (".xls", ".xlsx", ".ods"):
            hint = " Export the spreadsheet to CSV first."
        elif ext in (".h5", ".hdf5"):
            hint = " Export the data to .npz or CSV first."
        raise FileReadError(f"{shown}: unsupported file extension {ext or '(none)'!r}; "
                            f"supported: {', '.join(SUPPORTED_EXTENSIONS)}.{hint}", path=shown)
    if delimiter is not None:
        if ext not in _TEXT_EXTENSIONS:
            raise DataError(f"{shown}: delimiter applies to text files only, not to {ext} files")
        if not isinstance(delimiter, str) or len(delimiter) != 1 or delimiter in "\r\n\"#":
            raise DataError(f"delimiter must be one character (not a quote, '#' or a line "
                            f"break), got {delimiter!r}")
    max_bytes = _max_bytes(max_bytes)
    if ext in _TEXT_EXTENSIONS:
        fast = _read_text_fast(shown, ext, inputs, outputs, dt, time, delimiter)
        if fast is not None:
            return fast
        return _read_text(p, shown, ext, inputs, outputs, dt, time, delimiter)
    raw = _read_bytes(p, shown)
    if ext == ".npz":
        arrays = _load_npz(p, shown, raw=raw, max_bytes=max_bytes)
    else:
        arrays = _load_mat(p, shown, raw=raw, max_bytes=max_bytes)
    return _from_arrays(arrays, shown, ext, inputs, outputs, dt, time)


# ---------------------------------------------------------------------------
# helpers common to all formats
# ---------------------------------------------------------------------------
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


# ---------------------------------------------------------------------------
# text files
# ---------------------------------------------------------------------------
def _decode(raw: bytes, shown: str) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            text = raw.decode("utf-16")
        except UnicodeDecodeError as exc:
            raise FileReadError(f"{shown}: cannot decode UTF-16 text ({exc.reason})",
                                path=shown) from None
        _check_line_lengths(text.encode("utf-8", "replace"), shown)
    else:
        _check_line_lengths(raw, shown)
        if b"\x00" in raw[:8192]:
            raise FileReadError(f"{shown} looks like a binary file, not text (it holds NUL "
                                "bytes); save the data as plain text (UTF-8) or use .npz/.mat",
                                path=shown)
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError:
            text = raw.decode("latin-1")
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return text


def _content(line: str) -> str:
    """A line without its ``#`` comment and surrounding blanks ('' if nothing is left)."""
    k = line.find("#")
    if k >= 0:
        line = line[:k]
    return line.strip()


def _split(content: str, delim) -> list[str]:
    if delim is _WHITESPACE:
        return [f.strip('"') for f in content.split()] if '"' in content else content.split()
    if '"' in content:
        try:
            fields = next(csv.reader([content], delimiter=delim, quotechar='"'))
        except csv.Error:        # e.g. a quoted field beyond csv's 131,072-character limit
            fields = _split_quoted(content, delim)
    else:
        fields = content.split(delim)
    return [f.strip() for f in fields]


def _split_quoted(content: str, delim: str) -> list[str]:
    """Split a delimited line with ``"``-quoted fields (``""`` is a quote), without
    the csv module's field-size limit; the fields are checked as numbers later."""
    fields, field, quoted, k = [], [], False, 0
    while k < len(content):
        ch = content[k]
        if quoted:
            if ch == '"':
                if content.startswith('""', k):
                    field.append('"')
                    k += 1
                else:
                    quoted = False
            else:
                field.append(ch)
        elif ch == '"':
            quoted = True
        elif ch == delim:
            fields.append("".join(field))
            field = []
        else:
            field.append(ch)
        k += 1
    fields.append("".join(field))
    return fields


def _is_number(s: str) -> bool:
    if "_" in s:
        return False
    try:
        float(s)
    except ValueError:
        return False
    return True


def _sniff(sample: list[str], ext: str) -> str | None:
    """Choose the delimiter from the first non-empty lines."""
    candidates = (";", "\t", ",") if ext in (".csv", ".tsv") else (";", ",")
    counts = {c: [ln.count(c) for ln in sample] for c in candidates}
    for c in candidates:
        if counts[c][0] > 0 and all(n == counts[c][0] for n in counts[c]):
            return c
    # No consistent candidate: take one present on every line (rows of different
    # lengths are then reported with their line numbers), else whitespace.
    present = [c for c in candidates if all(counts[c])]
    if present:
        return max(present, key=lambda c: counts[c][0])
    return _WHITESPACE


class _Table:
    """Layout of a text file: delimiter, header, column count, first data line."""

    line_offset = 0                   # lines before ``text`` in the file (chunked reading)

    def __init__(self, shown, text, ext, delimiter):
        self.shown = shown
        self.text = text
        self.lines = text.split("\n")
        first = None                 # index of the first non-empty, non-comment line
        sample = []
        for k, line in enumerate(self.lines):
            c = _content(line)
            if c:
                if first is None:
                    first = k
                sample.append(c)
                if len(sample) >= _SNIFF_LINES:
                    break
        if first is None:
            raise FileReadError(f"file {shown} is empty (it holds no data, only blank or "
                                "comment lines)", path=shown)
        self.n_sampled = len(sample)
        if delimiter is None:
            self.delim = _sniff(sample, ext)
        else:
            self.delim = _WHITESPACE if delimiter == " " else delimiter
        logger.debug("%s: delimiter %r", shown, self.delim)
        fields = _split(sample[0], self.delim)
        self.header = None
        self.header_line = None
        if not all(_is_number(f) for f in fields):
            self.header = fields
            self.header_line = first + 1
            self.data_start = first + 1           # 0-based index of the line after the header
            numeric = [f for f in fields if _is_number(f)]
            if numeric:
                logger.warning("%s: line %d is taken as the header but has numeric fields %s",
                               shown, first + 1, numeric[:5])
        else:
            self.data_start = first
            self._comment_header(first, len(fields))
        self.first_data = None                    # 1-based line of the first data row
        for k in range(self.data_start, len(self.lines)):
            if _content(self.lines[k]):
                self.first_data = k + 1
                break
        if self.first_data is None:
            raise FileReadError(f"{shown} has a header (line {self.header_line}) but no data "
                                "rows", path=shown, line=self.header_line)
        if self.header is not None:
            self.ncols = len(self.header)
        else:
            self.ncols = len(fields)

    def _comment_header(self, first: int, ncols: int) -> None:
        """Use a comment line right before the data as header (numpy.savetxt style)."""
        k = first - 1
        while k >= 0 and not self.lines[k].strip():
            k -= 1
        if k < 0:
            return
        line = self.lines[k].strip()
        if not line.startswith("#"):
            return
        body = line.lstrip("#").strip()
        if not body:
            return
        for delim in dict.fromkeys((self.delim, ",", ";", "\t", _WHITESPACE)):
            fields = _split(body, delim)
            if len(fields) == ncols and not all(_is_number(f) for f in fields):
                self.header = fields
                self.header_line = k + 1
                return

    # -- names ---------------------------------------------------------------
    def name(self, idx: int) -> str | None:
        if self.header is None:
            return None
        return self.header[idx] or None

    def describe(self, idx: int) -> str:
        name = self.name(idx)
        return f"column {idx} ({name!r})" if name is not None else f"column {idx}"

    def channel_names(self, cols) -> list[str]:
        names = []
        for idx in cols:
            name = self.name(idx)
            if name is None or self.header.count(name) > 1:
                name = f"col{idx}" if name is None else f"{name}_col{idx}"
            names.append(name)
        return names

    def available(self) -> str:
        if self.header is None:
            return (f"the file has no header row, so columns are selected by 0-based index: "
                    f"{self.ncols} column{'s' if self.ncols != 1 else ''}, indices 0 to "
                    f"{self.ncols - 1}")
        return "available columns: " + _listing(
            f"{k} {n!r}" if n else f"{k} (no name)" for k, n in enumerate(self.header))

    # -- column selection ----------------------------------------------------
    def resolve(self, spec, role: str) -> list[int]:
        shown = self.shown
        tokens = _tokens(spec, role, self.header or ())
        if not tokens:
            raise FileReadError(f"{shown}: {role} selects no column; {self.available()}",
                                path=shown)
        cols = []
        for tok in tokens:
            if isinstance(tok, str):
                if self.header is not None and tok in self.header:
                    where = [k for k, n in enumerate(self.header) if n == tok]
                    if len(where) > 1:
                        raise FileReadError(
                            f"{shown}: the column name {tok!r} ({role}) appears more than once "
                            f"in the header (columns {', '.join(map(str, where))}); select it "
                            "by 0-based index instead", path=shown, line=self.header_line,
                            column=tok)
                    idx = where[0]
                elif _INT_RE.fullmatch(tok):
                    idx = int(tok)
                else:
                    if self.header is None:
                        msg = (f"{shown}: {role} names the column {tok!r}, but "
                               f"{self.available()}")
                    else:
                        msg = f"{shown}: unknown column name {tok!r} in {role}; {self.available()}"
                    raise FileReadError(msg, path=shown, column=tok)
            else:
                idx = tok
            if not 0 <= idx < self.ncols:
                raise FileReadError(
                    f"{shown}: column index {idx} in {role} is out of range: the file has "
                    f"{self.ncols} column{'s' if self.ncols != 1 else ''} (indices 0 to "
                    f"{self.ncols - 1}, counted from 0)", path=shown, column=idx)
            if idx in cols:
                raise FileReadError(f"{shown}: {self.describe(idx)} is selected twice in {role}",
                                    path=shown, column=idx)
            cols.append(idx)
        return cols

    # -- values --------------------------------------------------------------
    def data_lines(self) -> tuple[list[int], list[str]]:
        """1-based line numbers and contents of the data rows (two parallel lists)."""
        start = self.data_start
        lines = self.lines[start:]
        if "#" in self.text:
            contents = [_content(line) for line in lines]
        else:
            contents = [line.strip() for line in lines]
        keep = [k for k, c in enumerate(contents) if c]
        if len(keep) != len(contents):
            contents = [contents[k] for k in keep]
        return [k + start + 1 + self.line_offset for k in keep], contents

    def parse(self, cols: list[int]) -> np.ndarray:
        """Values of the columns ``cols``, shape (rows, len(cols))."""
        try:
            values = np.loadtxt(StringIO(self.text), dtype=np.float64,
                                delimiter=self.delim, comments="#", quotechar='"',
                                skiprows=self.data_start, ndmin=2)
        except (ValueError, TypeError, IndexError) as exc:
            logger.debug("%s: fast parse failed (%s); re-reading line by line", self.shown, exc)
            return self._parse_slowly(cols)
        if values.shape[1] != self.ncols:
            return self._parse_slowly(cols)
        return np.ascontiguousarray(values[:, cols])

    def _parse_slowly(self, cols: list[int]) -> np.ndarray:
        """Parse after the fast path failed: check the field count of every row, then
        convert only the selected columns (so text in other columns is allowed), and
        locate the first bad cell when a selected one is not a number."""
        shown, delim, ncols = self.shown, self.delim, self.ncols
        linenos, contents = self.data_lines()
        if delim is _WHITESPACE:
            counts = [len(c.split()) for c in contents]
        else:
            counts = [len(_split(c, delim)) if '"' in c else c.count(delim) + 1
                      for c in contents]
        bad = next((k for k, n in enumerate(counts) if n != ncols), None)
        if bad is not None:
            lineno, found = linenos[bad], counts[bad]
            ref = (f"the header (line {self.header_line})" if self.header is not None
                   else f"the first data row (line {self.first_data})")
            raise FileReadError(
                f"{shown}, line {lineno}: found {found} field{'s' if found != 1 else ''}, "
                f"expected {ncols} like {ref}"
                + (" (is the delimiter right? it was taken to be "
                   f"{_delim_name(delim)})" if found == 1 or ncols == 1 else ""),
                path=shown, line=lineno)
        hint = None
        try:
            values = np.loadtxt(StringIO("\n".join(contents)), dtype=np.float64,
                                delimiter=delim, comments=None, quotechar='"', usecols=cols,
                                ndmin=2)
            if values.shape == (len(contents), len(cols)):
                return values
        except (ValueError, TypeError, IndexError) as exc:
            found = re.search(r"at row (\d+)", str(exc))
            if found and int(found.group(1)) < len(contents):
                hint = int(found.group(1))
        order = range(len(contents)) if hint is None else \
            [hint, *range(len(contents))]           # check the row numpy named first
        rows = []
        for k in order:
            fields = _split(contents[k], delim)
            row = []
            for idx in cols:
                s = fields[idx]
                try:
                    if "_" in s:
                        raise ValueError
                    row.append(float(s))
                except ValueError:
                    raise FileReadError(self._bad_cell(linenos[k], idx, s), path=shown,
                                        line=linenos[k], column=idx) from None
            rows.append(row)
        if hint is not None:
            rows = rows[1:]
        return np.array(rows, dtype=np.float64).reshape(len(rows), len(cols))

    def _bad_cell(self, lineno: int, idx: int, s: str) -> str:
        msg = f"{self.shown}, line {lineno}, {self.describe(idx)}: "
        if not s:
            return msg + "the value is missing (empty field)"
        msg += (f"{s!r} is not a number" if len(s) <= 60 else
                f"{s[:40]!r}... ({len(s)} characters) is not a number")
        if _DECIMAL_COMMA_RE.fullmatch(s):
            msg += " (decimal commas are not supported: use '.' as the decimal separator)"
        return msg

    def check_finite(self, values: np.ndarray, cols: list[int]) -> None:
        finite = np.isfinite(values)
        if finite.all():
            return
        bad_rows = np.flatnonzero(~finite.all(axis=1))
        row = int(bad_rows[0])
        j = int(np.flatnonzero(~finite[row])[0])
        idx = cols[j]
        linenos, contents = self.data_lines()
        lineno = linenos[row]
        text = _split(contents[row], self.delim)[idx]
        n_bad = int((~finite).sum())
        raise DataError(
            f"{self.shown}, line {lineno}, {self.describe(idx)}: {text!r} is not a finite "
            f"number ({n_bad} NaN or infinite value{'s' if n_bad != 1 else ''} in "
            f"{bad_rows.size} row{'s' if bad_rows.size != 1 else ''} of the selected columns); "
            "remove or interpolate them before identification")


def _delim_name(delim) -> str:
    return {None: "runs of spaces/TABs", "\t": "TAB", ",": "','", ";": "';'"}.get(
        delim, repr(delim))


def _tokens(spec, role: str, names) -> list:
    """Split a column/array specification into names (str) and indices (int)."""
    if isinstance(spec, str):
        if spec in names:
            return [spec]
        parts = [s.strip() for s in spec.split(",")]
        if any(not s for s in parts):
            raise DataError(f"{role}={spec!r} holds an empty name")
        return parts
    if isinstance(spec, numbers.Integral) and not isinstance(spec, bool):
        return [int(spec)]
    if isinstance(spec, (bool, bytes, dict, set, frozenset)) or not hasattr(spec, "__iter__"):
        raise DataError(f"{role} must be a name, an index or a list of them, got {spec!r}")
    out = []
    for item in spec:
        if isinstance(item, str):
            out.append(item.strip())
        elif isinstance(item, numbers.Integral) and not isinstance(item, bool):
            out.append(int(item))
        else:
            raise DataError(f"{role} must be names or 0-based indices, got the item {item!r}")
    return out


def _roles(table: "_Table", shown: str, inputs, outputs, time):
    """Column indices of the inputs, outputs and time stamps, checked."""
    missing = [r for r, v in (("inputs", inputs), ("outputs", outputs)) if v is None]
    if missing:
        raise FileReadError(
            f"{shown}: {' and '.join(missing)} must be given for a text file (subid does not "
            f"guess which columns are inputs and outputs); {table.available()}", path=shown)
    in_cols = table.resolve(inputs, "inputs")
    out_cols = table.resolve(outputs, "outputs")
    t_cols = []
    if time is not None:
        if not isinstance(time, (str, numbers.Integral)) or isinstance(time, bool):
            raise DataError(f"time must be one column name or index, got {time!r}")
        t_cols = table.resolve(time, "time")
        if len(t_cols) != 1:
            raise FileReadError(f"{shown}: time must name one column, got {time!r}", path=shown)
    roles = [("an input", in_cols), ("an output", out_cols), ("the time", t_cols)]
    for a in range(len(roles)):
        for b in range(a + 1, len(roles)):
            both = set(roles[a][1]) & set(roles[b][1])
            if both:
                idx = min(both)
                raise FileReadError(f"{shown}: {table.describe(idx)} is used both as "
                                    f"{roles[a][0]} and as {roles[b][0]}", path=shown, column=idx)
    return in_cols, out_cols, t_cols


def _read_text(p, shown, ext, inputs, outputs, dt, time, delimiter, *, raw=None) -> IOData:
    text = _decode(_read_bytes(p, shown) if raw is None else raw, shown)
    table = _Table(shown, text, ext, delimiter)
    in_cols, out_cols, t_cols = _roles(table, shown, inputs, outputs, time)
    cols = in_cols + out_cols + t_cols
    values = table.parse(cols)
    table.check_finite(values, cols)
    n_in, n_out = len(in_cols), len(out_cols)
    u = values[:, :n_in]
    y = values[:, n_in:n_in + n_out]
    t = values[:, -1] if t_cols else None
    return _build(shown, u, y, dt, t, table.channel_names(in_cols),
                  table.channel_names(out_cols), first_line=table.first_data)


# ---------------------------------------------------------------------------
# fast parsing of well-formed text (pandas' C parser, pyarrow.csv or numpy)
# ---------------------------------------------------------------------------
#: Bytes handed to the fast parser at a time (whole lines; memory stays bounded).
_BLOCK_BYTES = 1 << 20
#: Fast parser in use: "pandas", "pyarrow" or "numpy" (None: choose on first use).
_ENGINE = None


def fast_engine() -> str:
    """The parser used for well-formed text: pandas' C parser when pandas is
    installed, else ``pyarrow.csv``, else :func:`numpy.loadtxt`."""
    global _ENGINE
    if _ENGINE is None:
        try:
            import pandas  # noqa: F401
            _ENGINE = "pandas"
        except ImportError:
            try:
                import pyarrow.csv  # noqa: F401
                _ENGINE = "pyarrow"
            except ImportError:
                _ENGINE = "numpy"
    return _ENGINE


def _lone_cr(buf: bytes) -> bool:
    """True when ``buf`` holds a carriage return that is not part of CRLF."""
    return b"\r" in buf and buf.count(b"\r") != buf.count(b"\r\n")


def _fast_values(buf: bytes, delim, ncols: int):
    """All ``ncols`` columns of the complete lines ``buf`` as float64, or None.

    None whenever anything is unusual (quotes, comments, non-ASCII bytes, a
    lone CR, a parse error, another number of fields, a NaN, an infinity or
    an empty cell): the careful parser then reads these lines and names the
    line and column at fault. Every engine accepts only what Python's
    ``float`` accepts and rounds as it does, so values equal the careful
    parser's.
    """
    if b'"' in buf or b"#" in buf or not buf.isascii() or _lone_cr(buf):
        return None
    engine = fast_engine()
    try:
        if engine == "pandas":
            import pandas as pd
            frame = pd.read_csv(BytesIO(buf), sep=r"\s+" if delim is None else delim,
                                header=None, dtype=np.float64, engine="c", na_filter=False,
                                quoting=csv.QUOTE_NONE, skip_blank_lines=True,
                                index_col=False)
            values = frame.to_numpy(dtype=np.float64)
        elif engine == "pyarrow" and delim is not None:
            import pyarrow as pa
            import pyarrow.csv as pcsv
            table = pcsv.read_csv(
                BytesIO(buf),
                read_options=pcsv.ReadOptions(autogenerate_column_names=True,
                                              use_threads=False),
                parse_options=pcsv.ParseOptions(delimiter=delim, quote_char=False),
                convert_options=pcsv.ConvertOptions(
                    column_types={f"f{k}": pa.float64() for k in range(ncols)},
                    strings_can_be_null=False))
            if table.num_columns != ncols:
                return None
            values = np.empty((table.num_rows, ncols))
            for k, column in enumerate(table.columns):
                if column.null_count:
                    return None
                values[:, k] = column.to_numpy()
        else:
            values = np.loadtxt(StringIO(buf.decode("ascii")), dtype=np.float64,
                                delimiter=delim, comments=None, ndmin=2)
    except Exception:  # noqa: BLE001 - any failure: the careful parser decides
        return None
    if values.ndim != 2 or values.shape[1] != ncols or not np.isfinite(values).all():
        return None
    return values


def _parsed_blocks(blocks, delim, ncols: int):
    """``(bytes, number of lines, values or None)`` for each block of ``blocks``
    (see :func:`_blocks`), in order: :func:`_fast_values` of each block,
    computed by :func:`subid._threads.available` threads while the caller uses
    the blocks before (pandas' and pyarrow's parsers release the GIL, so two
    threads parse about twice as fast). At most one block per thread is
    parsed ahead, so memory stays bounded by a few blocks; the values are
    those of one thread, bit for bit.
    """
    def parse(buf):
        return _fast_values(buf, delim, ncols) if len(buf) <= 2 * _BLOCK_BYTES else None

    threads = _threads.available()
    fast_engine()                   # its imports happen here, not in the threads
    if threads == 1:
        for buf, n_lines in blocks:
            yield buf, n_lines, parse(buf)
        return
    from concurrent.futures import ThreadPoolExecutor

    pending = collections.deque()
    with ThreadPoolExecutor(threads, thread_name_prefix="subid-parse") as pool:
        try:
            for buf, n_lines in blocks:
                pending.append((buf, n_lines, pool.submit(parse, buf)))
                if len(pending) > threads:
                    buf, n_lines, values = pending.popleft()
                    yield buf, n_lines, values.result()
            while pending:
                buf, n_lines, values = pending.popleft()
                yield buf, n_lines, values.result()
        finally:                    # stopped early (an error, a closed generator)
            for _, _, values in pending:
                values.cancel()


def _first_long_line(buf: bytes, encoding: str):
    """0-based index of the first line of ``buf`` longer than MAX_LINE_CHARS
    characters (line breaks excluded), or None."""
    ends = np.flatnonzero(np.frombuffer(buf, dtype=np.uint8) == 10)
    if not buf.endswith(b"\n"):
        ends = np.append(ends, len(buf))
    starts = np.concatenate(([0], ends[:-1] + 1))
    for k in np.flatnonzero(ends - starts > MAX_LINE_CHARS):
        text = buf[starts[k]:ends[k]].decode(encoding, "replace").rstrip("\r")
        if len(text) > MAX_LINE_CHARS:
            return int(k)
    return None


def _blocks(fh, shown: str, encoding: str, lines_before: int, limit=None, count=True):
    """``(bytes, number of lines)`` of whole lines of ``fh``, about
    _BLOCK_BYTES at a time (at most ``limit`` bytes in all). A line longer
    than MAX_LINE_CHARS is refused (ResourceLimitError) before it is held
    whole, so memory is bounded by the block size, whatever the file.
    ``count=False``: the line numbers are not needed (the number of lines is
    then 0, and a long line is reported without its number being exact)."""
    pending = b""
    left = limit
    while True:
        size = _BLOCK_BYTES if left is None else min(_BLOCK_BYTES, left)
        try:
            data = fh.read(size) if size else b""
        except OSError as exc:
            raise FileReadError(f"{shown}: cannot read the file ({_reason(exc)})",
                                path=shown) from None
        if left is not None:
            left -= len(data)
        if not data:
            if pending:
                if len(pending) > MAX_LINE_CHARS and _first_long_line(pending, encoding) \
                        is not None:
                    raise _long_line_error(shown, lines_before + 1)
                yield pending, pending.count(b"\n") + 1
            return
        cut = data.rfind(b"\n")
        if cut < 0:
            pending += data
            if len(pending) > MAX_LINE_CHARS and \
                    len(pending.decode(encoding, "replace")) > MAX_LINE_CHARS:
                raise _long_line_error(shown, lines_before + 1)
            continue
        buf, pending = pending + data[:cut + 1], data[cut + 1:]
        if len(buf) > MAX_LINE_CHARS:
            bad = _first_long_line(buf, encoding)
            if bad is not None:
                raise _long_line_error(shown, lines_before + bad + 1)
        lines = _count_lines(buf) if count else 0
        yield buf, lines
        lines_before += lines


def _count_lines(buf: bytes) -> int:
    """Number of line feeds in ``buf`` (5x faster than ``bytes.count`` on a block)."""
    return int(np.count_nonzero(np.frombuffer(buf, dtype=np.uint8) == 10))


def _long_line_error(shown: str, line: int) -> ResourceLimitError:
    return ResourceLimitError(f"{shown}, line {line}: the line is longer than the "
                              f"{MAX_LINE_CHARS} characters subid reads "
                              "(subid.io.formats.MAX_LINE_CHARS); is this a text data file?",
                              path=shown, line=line)


def _line_start(head: bytes, index: int):
    """Byte offset where line ``index`` (0-based) of ``head`` starts, or None."""
    pos = 0
    for _ in range(index):
        pos = head.find(b"\n", pos) + 1
        if pos == 0:
            return None
    return pos


def _head_layout(fh, shown, ext, delimiter):
    """``(layout, head bytes)`` of a text file from its first _HEAD_BYTES, or None
    when the head alone cannot settle the layout as the whole text would
    (UTF-16, a lone CR, too few lines sampled) or shows a problem (the
    careful path then reports it)."""
    try:
        head = fh.read(_HEAD_BYTES)
        size = os.fstat(fh.fileno()).st_size
    except OSError:
        return None
    if not head or head.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in head[:8192]:
        return None
    whole = len(head) >= size
    if not whole:
        cut = head.rfind(b"\n")
        if cut < 0:
            return None
        head = head[:cut + 1]
    if _lone_cr(head):
        return None
    try:
        text = head.decode("utf-8-sig")
    except UnicodeDecodeError:
        return None
    try:
        layout = _Table(shown, text.replace("\r\n", "\n"), ext, delimiter)
    except (FileReadError, DataError):
        return None
    if not whole and layout.n_sampled < _SNIFF_LINES:
        return None
    return layout, head, size


def _read_text_fast(shown, ext, inputs, outputs, dt, time, delimiter):
    """:func:`read` of a well-formed text file by the fast parser, or None
    (then the careful parser reads the file and reports what is wrong).

    The file is parsed in blocks of whole lines and only the selected
    columns are kept, so the peak memory is about twice the selected data
    in doubles (the blocks, then the joined arrays).
    """
    fh, _ = open_regular(shown, what="data file", max_bytes=None)
    with fh:
        found = _head_layout(fh, shown, ext, delimiter)
        if found is None:
            return None
        layout, head, size = found
        try:
            in_cols, out_cols, t_cols = _roles(layout, shown, inputs, outputs, time)
        except (FileReadError, DataError):
            return None
        offset = _line_start(head, layout.data_start)
        if offset is None:
            return None
        if layout.data_start == 0 and head.startswith(b"\xef\xbb\xbf"):
            offset = 3
        cols = in_cols + out_cols + t_cols
        fh.seek(offset)
        parts = []
        try:
            blocks = _blocks(fh, shown, "utf-8", 0, limit=size - offset, count=False)
            for _, _, values in _parsed_blocks(blocks, layout.delim, layout.ncols):
                if values is None:
                    return None
                if values.shape[0]:
                    parts.append(values[:, cols])
            if fh.read(1):                 # the file grew: the careful path says so
                return None
        except (ResourceLimitError, FileReadError):
            return None
    if not parts:
        return None
    n_in, n_out = len(in_cols), len(out_cols)
    # C-ordered arrays of our own (IOData keeps them without a copy), filled block by
    # block while each parsed block is released: the resident peak stays about one
    # copy of the selected data plus a block
    total = sum(v.shape[0] for v in parts)
    u, y = np.empty((total, n_in)), np.empty((total, n_out))
    t = np.empty(total) if t_cols else None
    parts.reverse()
    start = 0
    while parts:
        v = parts.pop()
        stop = start + v.shape[0]
        u[start:stop] = v[:, :n_in]
        y[start:stop] = v[:, n_in:n_in + n_out]
        if t is not None:
            t[start:stop] = v[:, -1]
        start = stop
        del v
    return _build(shown, u, y, dt, t, layout.channel_names(in_cols),
                  layout.channel_names(out_cols), first_line=layout.first_data)


# ---------------------------------------------------------------------------
# .npz and .mat files
# ---------------------------------------------------------------------------
def _reason(exc: BaseException) -> str:
    """Short printable description of a library exception, for messages."""
    text = "".join(ch if ch.isprintable() else "?" for ch in str(exc))
    if len(text) > 160:
        text = text[:160] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _load_npz(p: Path, shown: str, *, raw=None, max_bytes=None) -> dict:
    raw = _read_bytes(p, shown) if raw is None else raw
    magic = raw[:6]
    if magic == b"\x93NUMPY":
        raise FileReadError(f"{shown} holds a single .npy array, not a .npz archive; save the "
                            "record with numpy.savez(path, u=..., y=...)", path=shown)
    if not magic.startswith(b"PK"):
        raise FileReadError(f"{shown} is not a .npz archive (it is not a ZIP file); write it "
                            "with numpy.savez(path, u=..., y=...)", path=shown)
    try:
        return load_npz(BytesIO(raw), size=len(raw), max_expanded=_max_bytes(max_bytes))
    except NpzLimitError as exc:
        raise ResourceLimitError(f"{shown}: {exc}", path=shown) from None
    except NpzError as exc:
        if "pickled" in str(exc):
            raise FileReadError(f"{shown} holds object (pickled) arrays, which subid does not "
                                "load for safety; store plain numeric arrays", path=shown) from None
        raise FileReadError(f"{shown} is not a readable .npz archive (corrupted?): {exc}",
                            path=shown) from None


def mat_variables(path, *, raw=None, max_bytes=None, mat_dtype=False, what="data file"
                  ) -> dict:
    """The variables of a MATLAB file, read through the validated path.

    The file is opened once as a regular file (:func:`subid.io._files.read_regular`),
    its structure is validated (v4 headers, every v5 matrix, compressed
    elements inflated within ``max_bytes``) and only then given to
    :func:`scipy.io.loadmat`, from memory. Used by :func:`read` and by
    :func:`subid.interop.load_mat`.
    """
    shown = os.fspath(path)
    if raw is None:
        raw = read_regular(shown, what=what, max_bytes=None)
        if not raw:
            raise FileReadError(f"file {shown} is empty", path=shown)
    head = raw[:520]
    if b"MATLAB 7.3" in head[:128] or head[512:520] == _HDF5_SIGNATURE \
            or head[:8] == _HDF5_SIGNATURE:
        return _mat73_variables(raw, shown, _max_bytes(max_bytes))
    import scipy.io
    _check_mat_sizes(raw, shown, _max_bytes(max_bytes))
    try:
        return scipy.io.loadmat(BytesIO(raw), squeeze_me=False, mat_dtype=mat_dtype)
    except NotImplementedError:
        raise FileReadError(
            f"{shown} is a MATLAB v7.3 (HDF5) file, which subid cannot read; save it with "
            "save(..., '-v7') in MATLAB, or export the data to CSV", path=shown) from None
    except MemoryError:
        raise
    except Exception as exc:  # scipy raises ValueError, MatReadError, TypeError, OSError, ...
        raise FileReadError(f"{shown} is not a readable MATLAB .mat file (corrupted or not a "
                            f"MAT-file): {_reason(exc)}", path=shown) from None


_MAT_FIELDS = ("A", "B", "C", "D", "Ts")


def write_mat_model(model, path) -> None:
    """Write ``model`` as the fields of MATLAB's ``ss(A, B, C, D, Ts)`` (atomically).

    The writer behind :func:`subid.interop.save_mat` and
    :meth:`subid.StateSpace.to_mat` (which documents the variables).

    Parameters
    ----------
    model : StateSpace
        The model (read through its public attributes).
    path : str or os.PathLike
        The ``.mat`` file.
    """
    import scipy.io
    path = os.fspath(path)
    names_in = np.empty((1, model.n_inputs), dtype=object)
    names_in[0, :] = list(model.input_names)
    names_out = np.empty((1, model.n_outputs), dtype=object)
    names_out[0, :] = list(model.output_names)
    variables = {
        "A": np.array(model.A), "B": np.array(model.B), "C": np.array(model.C),
        "D": np.array(model.D), "Ts": np.array([[float(model.dt)]]),
        "InputName": names_in, "OutputName": names_out,
        "subid_format": "subid.StateSpace",
    }
    if model.hold != "zoh":                      # the input hold it assumes (subid only)
        variables["subid_hold"] = model.hold
    poly = (model.info or {}).get("polynomials")
    if isinstance(poly, dict) and "structure" in poly:    # MATLAB idpoly fields
        for key in ("A", "B", "C", "D"):          # the realisation under subid's names
            variables[f"subid_ss_{key}"] = variables.pop(key)
        variables.update(_idpoly_fields(poly))
        variables["subid_format"] = "subid.idpoly"
    if model.K is not None:                      # MATLAB idss fields
        variables["K"] = np.array(model.K)
    if model.noise_cov is not None:
        variables["NoiseVariance"] = np.array(model.noise_cov)
    with atomic_write(path, "wb") as fh:
        scipy.io.savemat(fh, variables, format="5", do_compression=False, oned_as="row")


def _trimmed(coef) -> np.ndarray:
    coef = np.asarray(coef, dtype=float).ravel()
    nz = np.flatnonzero(coef)
    return coef[:int(nz[-1]) + 1 if nz.size else 1]


def _idpoly_fields(poly: dict) -> dict:
    """MATLAB ``idpoly`` variables of a polynomial model's ``info['polynomials']``
    (:mod:`subid.model.polynomial`): ``A`` (ny x ny), ``B``, ``F`` (ny x nu), ``C``,
    ``D`` (ny x 1) cell arrays of row vectors in ``q^-1`` (``B`` with its ``nk``
    leading zeros), ``nk`` (ny x nu) and ``structure``."""
    A, B, C, D, F = (np.asarray(poly[k], dtype=float) for k in ("A", "B", "C", "D", "F"))
    ny, nu = B.shape[0], B.shape[1]
    nk = np.asarray(poly["nk"], dtype=float).reshape(ny, nu)

    def cells(rows, cols, get):
        out = np.empty((rows, cols), dtype=object)
        for i in range(rows):
            for j in range(cols):
                out[i, j] = np.atleast_2d(get(i, j))
        return out

    def b_row(i, j):
        b = _trimmed(B[i, j])
        return b if b.size > nk[i, j] else np.zeros(int(nk[i, j]) + 1)
    return {"A": cells(ny, ny, lambda i, k: _trimmed(A[i, k])), "B": cells(ny, nu, b_row),
            "C": cells(ny, 1, lambda i, _: _trimmed(C[i])),
            "D": cells(ny, 1, lambda i, _: _trimmed(D[i])),
            "F": cells(ny, nu, lambda i, j: _trimmed(F[i, j])), "nk": nk,
            "subid_structure": str(poly["structure"]),
            **{f"subid_{k}": np.asarray(poly[k], dtype=float)
               for k in ("na", "nb", "nc", "nd", "nf")}}


def _from_idpoly_fields(fields: dict, ny: int, nu: int, path: str) -> dict:
    """``info['polynomials']`` from the variables :func:`_idpoly_fields` wrote."""
    def stack(key, rows, cols):
        v = np.asarray(fields[key], dtype=object).reshape(rows, cols)
        items = [[np.asarray(v[i, j], dtype=float).ravel() for j in range(cols)]
                 for i in range(rows)]
        length = max(1, max(len(c) for row in items for c in row))
        out = np.zeros((rows, cols, length))
        for i, row in enumerate(items):
            for j, c in enumerate(row):
                out[i, j, :len(c)] = c
        return out
    try:
        poly = {"structure": "".join(str(c) for c in np.asarray(
                    fields["subid_structure"]).reshape(-1)).strip(),
                "A": stack("A", ny, ny), "B": stack("B", ny, nu), "C": stack("C", ny, 1)[:, 0],
                "D": stack("D", ny, 1)[:, 0], "F": stack("F", ny, nu)}
        for k, shape in (("na", (ny, ny)), ("nb", (ny, nu)), ("nc", (ny,)), ("nd", (ny,)),
                         ("nf", (ny, nu))):
            poly[k] = np.rint(np.asarray(fields[f"subid_{k}"], float)).astype(
                np.int64).reshape(shape)
        poly["nk"] = np.rint(np.asarray(fields["nk"], float)).astype(np.int64).reshape(ny, nu)
    except (KeyError, ValueError, TypeError) as exc:
        raise ModelError(f"model file '{path}': the idpoly fields written by subid are "
                         f"incomplete or malformed ({exc})") from None
    return poly


def _cell_strings(value, key: str, path: str, count: int) -> list[str] | None:
    """Channel names from a MATLAB cell array (or char matrix); None when absent/empty."""
    arr = np.asarray(value)
    if arr.size == 0:
        return None
    if arr.dtype.kind in "US":
        items = [str(s).strip() for s in arr.reshape(-1)] if arr.ndim else [str(arr)]
    elif arr.dtype == object:
        items = []
        for item in arr.reshape(-1):
            item = np.asarray(item)
            if item.size == 0:
                items.append("")
            elif item.dtype.kind in "US":
                items.append("".join(str(s) for s in item.reshape(-1)).strip())
            else:
                raise ModelError(f"model file '{path}': {key} must hold strings, got "
                                 f"{item.dtype}")
    else:
        raise ModelError(f"model file '{path}': {key} must be a cell array of strings, got "
                         f"{arr.dtype}")
    if len(items) != count:
        raise ModelError(f"model file '{path}': {key} has {len(items)} names but the model "
                         f"has {count} channels")
    if not any(items):
        return None                      # MATLAB's default: all names empty
    prefix = "u" if key == "InputName" else "y"
    return [s if s else f"{prefix}{k + 1}" for k, s in enumerate(items)]


def read_mat_model(path, build, *, dt=None):
    """A model from a MAT-file: the one reader behind :func:`subid.interop.load_mat`
    and :meth:`subid.StateSpace.from_mat` (which document the variables).

    The file goes through :func:`mat_variables`, the validated path of
    :func:`read`. ``build(A, B, C, D, dt, input_names=, output_names=, hold=,
    K=, noise_cov=)`` makes the model (the StateSpace class: this module sits
    below the model module and does not import it).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mat`` file.
    build : callable
        Model constructor.
    dt : float, optional
        Sampling period when ``Ts`` is -1 or missing.

    Returns
    -------
    StateSpace
        What ``build`` returns.
    """
    path = os.fsdecode(path) if isinstance(path, bytes) else os.fspath(path)
    # The same validated path as subid.read: regular files only, every MAT
    # structure checked before scipy's C reader sees it, bounded decompression.
    # mat_dtype=False: scipy's mat_dtype=True casts complex matrices to real,
    # silently dropping the imaginary part; complex values are refused below.
    raw = mat_variables(path, mat_dtype=False, what="model file")
    fields = {k: v for k, v in raw.items() if not k.startswith("__")}
    idpoly = None
    if "subid_ss_A" in fields:        # a polynomial model: idpoly fields and its realisation
        idpoly = {k: fields.pop(k) for k in ("A", "B", "C", "D", "F") if k in fields}
        idpoly.update({k: fields[k] for k in fields if k.startswith("subid_") or k == "nk"})
        for key in ("A", "B", "C", "D"):
            if f"subid_ss_{key}" in fields:
                fields[key] = fields[f"subid_ss_{key}"]
    if not all(k in fields for k in ("A", "B", "C")):
        structs = [k for k, v in fields.items()
                   if isinstance(v, np.ndarray) and v.dtype.names and "A" in v.dtype.names]
        if len(structs) == 1:
            s = fields[structs[0]]
            fields = {name: s[name].reshape(-1)[0] for name in s.dtype.names}
    missing = [k for k in ("A", "B", "C", "D") if k not in fields]
    if missing:
        raise ModelError(f"model file '{path}' lacks the variable{'s' if len(missing) > 1 else ''}"
                         f" {', '.join(missing)}; expected the fields of MATLAB's "
                         f"ss(A, B, C, D, Ts): {', '.join(_MAT_FIELDS)}")
    mats = []
    for key in ("A", "B", "C", "D"):
        value = np.asarray(fields[key])
        if value.dtype.kind == "c":
            raise ModelError(f"model file '{path}': {key} is complex; subid models are "
                             "real-valued (a complex matrix is not the realization of a "
                             "real system)")
        if value.dtype.kind not in "biuf":
            raise ModelError(f"model file '{path}': {key} is not a real numeric matrix "
                             f"(dtype {value.dtype})")
        mats.append(value.astype(np.float64))
    A, B, C, D = mats
    n = A.shape[0]
    if B.size == 0 and A.size:
        B = np.zeros((n, D.shape[1] if D.ndim == 2 else 0))
    if D.size == 0:
        D = np.zeros((C.shape[0], B.shape[1]))
    ts = fields.get("Ts")
    if ts is None:
        period = -1.0
    else:
        ts = np.asarray(ts)
        if ts.size != 1 or ts.dtype.kind not in "biuf":
            if ts.dtype.kind == "c":
                raise ModelError(f"model file '{path}': Ts is complex")
            raise ModelError(f"model file '{path}': Ts must be a scalar, got shape {ts.shape}")
        period = float(ts.reshape(-1)[0])
    if period == -1.0:
        if dt is None:
            raise ModelError(f"model file '{path}': the sampling period is unspecified "
                             "(Ts = -1 or missing); pass dt=")
        period = dt
    elif dt is not None and not same_period(dt, period):
        raise ModelError(f"model file '{path}' has Ts = {period:g} but dt={dt!r} was given")
    if isinstance(period, bool) or not isinstance(period, numbers.Real) or period < 0:
        raise ModelError(f"model file '{path}': Ts must be >= 0 or -1, got {period!r}")
    try:
        inputs = _cell_strings(fields["InputName"], "InputName", path, B.shape[1]) \
            if "InputName" in fields else None
        outputs = _cell_strings(fields["OutputName"], "OutputName", path, C.shape[0]) \
            if "OutputName" in fields else None
        noise = {}
        for key, name in (("K", "K"), ("NoiseVariance", "noise_cov")):
            value = fields.get(key)
            if value is not None and np.asarray(value).size:
                value = np.asarray(value)
                if value.dtype.kind not in "biuf":
                    raise ModelError(f"model file '{path}': {key} is not a real numeric "
                                     f"matrix (dtype {value.dtype})")
                noise[name] = value.astype(np.float64)
        hold = fields.get("subid_hold")
        if hold is not None:
            hold = "".join(str(v) for v in np.asarray(hold).reshape(-1)).strip()
            if hold not in ("zoh", "foh"):
                raise ModelError(f"model file '{path}': subid_hold must be 'zoh' or 'foh', "
                                 f"got {hold[:40]!r}")
        extra = {}
        if idpoly is not None:
            extra["info"] = {"polynomials": _from_idpoly_fields(idpoly, C.shape[0], B.shape[1],
                                                                path)}
        return build(A, B, C, D, period, input_names=inputs, output_names=outputs,
                     hold=hold or "zoh", **noise, **extra)
    except ModelError as exc:
        if str(exc).startswith(f"model file '{path}'"):
            raise
        raise ModelError(f"model file '{path}': {exc}") from None


_MAT73_NUMERIC = {"double": np.float64, "single": np.float32, "int8": np.int8,
                  "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
                  "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
                  "uint64": np.uint64, "logical": np.uint8}
_MAT73_MAX_OBJECTS = 10_000


def _mat73_variables(raw: bytes, shown: str, max_bytes: int) -> dict:
    """The variables of a MATLAB v7.3 (HDF5) file, as :func:`scipy.io.loadmat`
    gives those of a v5 file (2-D arrays in MATLAB's orientation, a struct as a
    1-by-1 record array), read with h5py from memory.

    Every dataset's declared size is checked (as float64, like v5 files:
    at most the file's size plus ``max_bytes``) before any is read, so a
    small file declaring huge (compressed) arrays is refused without
    allocating them. Cell arrays, sparse matrices and objects become object
    arrays, which :func:`read` and :meth:`StateSpace.from_mat` refuse by name.
    """
    try:
        import h5py
    except ImportError:
        from subid._extras import install_hint
        raise FileReadError(f"{shown} is a MATLAB v7.3 (HDF5) file; reading it needs h5py: "
                            f"{install_hint('hdf5', 'h5py')}; or save it with save(..., "
                            "'-v7') in MATLAB", path=shown) from None

    def corrupt(exc):
        return FileReadError(f"{shown} is not a readable MATLAB v7.3 (HDF5) file (corrupted?): "
                             f"{_reason(exc)}", path=shown)

    try:
        fh = h5py.File(BytesIO(raw), "r")
    except Exception as exc:  # noqa: BLE001 - h5py raises OSError, ValueError, KeyError, ...
        raise corrupt(exc) from None
    try:
        with fh:
            plan, budget, count = [], 8 * len(raw) + max_bytes, 0

            def declare(name, obj, depth):
                nonlocal budget, count
                count += 1
                if count > _MAT73_MAX_OBJECTS or depth > 8:
                    raise FileReadError(f"{shown}: the MATLAB v7.3 file holds more than "
                                        f"{_MAT73_MAX_OBJECTS} objects or nests them more than "
                                        "8 deep; subid reads numeric variables", path=shown)
                if isinstance(obj, h5py.Group):
                    if _attr(obj, "MATLAB_class") != "struct":
                        return ("unsupported", name, None)
                    return ("struct", name, [declare(k, obj[k], depth + 1) for k in obj])
                cls = _attr(obj, "MATLAB_class")
                if not isinstance(obj, h5py.Dataset) or obj.dtype.kind == "O" \
                        or cls in ("cell", "function_handle") or "MATLAB_sparse" in obj.attrs:
                    return ("unsupported", name, None)
                elements = 1
                for d in obj.shape:
                    elements *= int(d)
                budget -= 8 * elements * (2 if obj.dtype.names else 1)
                if budget < 0:
                    raise ResourceLimitError(
                        f"{shown}: its variables take more than max_bytes = {max_bytes} bytes "
                        "beyond the file's size as float64; pass a larger max_bytes if the "
                        "file is genuine", path=shown)
                return ("dataset", name, obj)

            for key in fh:
                if key.startswith("#"):
                    continue           # MATLAB's #refs# and #subsystem# groups
                plan.append(declare(key, fh[key], 0))
            return {name: _mat73_value(kind, item, shown) for kind, name, item in plan}
    except (FileReadError, ResourceLimitError):
        raise
    except MemoryError:
        raise
    except Exception as exc:  # noqa: BLE001 - h5py errors of any class
        raise corrupt(exc) from None


def _attr(obj, key):
    value = obj.attrs.get(key)
    if isinstance(value, bytes):
        return value.decode("ascii", "replace")
    if isinstance(value, np.ndarray) and value.dtype.kind == "S":
        return value.reshape(-1)[0].decode("ascii", "replace")
    return None if value is None else str(value)


def _mat73_value(kind, item, shown):
    if kind == "unsupported":
        return np.empty((1, 1), dtype=object)
    if kind == "struct":
        names = [name for _, name, _ in item]
        record = np.empty((1, 1), dtype=[(name, object) for name in names])
        for sub_kind, name, sub in item:
            record[0, 0][name] = _mat73_value(sub_kind, sub, shown)
        return record
    cls = _attr(item, "MATLAB_class")
    if int(np.asarray(item.attrs.get("MATLAB_empty", 0)).reshape(-1)[0]):
        dims = [int(d) for d in np.asarray(item[()]).reshape(-1)]
        return np.zeros(tuple(dims) if len(dims) >= 2 else (0, 0))
    data = item[()]
    if item.dtype.names:                       # complex: a compound of real and imag
        if set(item.dtype.names) != {"real", "imag"}:
            return np.empty((1, 1), dtype=object)
        data = data["real"] + 1j * data["imag"]
    data = np.asarray(data)
    if cls == "char":
        text = "".join(chr(c) for c in data.T.reshape(-1))
        return np.array([text])
    if cls not in _MAT73_NUMERIC and data.dtype.kind not in "biuf":
        return np.empty((1, 1), dtype=object)
    if cls == "logical":
        data = data.astype(bool)
    data = data.T                               # HDF5 holds MATLAB's column-major order
    if data.ndim == 1:
        data = data[None, :]
    elif data.ndim == 0:
        data = data.reshape(1, 1)
    return np.ascontiguousarray(data)


def _load_mat(p: Path, shown: str, *, raw=None, max_bytes=None) -> dict:
    import scipy.sparse
    raw = mat_variables(shown, raw=raw, max_bytes=max_bytes)
    arrays = {}
    for key, val in raw.items():
        if key.startswith("__"):
            continue
        if scipy.sparse.issparse(val):
            val = val.toarray()
        val = np.asarray(val)
        if val.ndim == 2 and val.shape[0] == 1 and val.shape[1] > 1:
            val = val.reshape(-1)          # a 1-by-N row vector is one channel
        arrays[key] = val
    return arrays


_MAT4_ELEMENT_BYTES = {0: 8, 1: 4, 2: 4, 3: 2, 4: 2, 5: 1}


def _check_mat4_headers(raw: bytes, shown: str, size: int) -> None:
    """Walk the variable headers of a MATLAB v4 file (uncompressed): every
    declared name and array must fit in the file. scipy would otherwise
    allocate what a corrupted header declares."""
    import struct
    with BytesIO(raw) as fh:
        offset = 0
        while offset < size:
            fh.seek(offset)
            head = fh.read(20)
            if len(head) < 20:
                raise FileReadError(f"{shown}: MATLAB v4 variable header truncated at byte "
                                    f"{offset}", path=shown)
            for endian in "<>":
                mopt, mrows, ncols, imagf, namlen = struct.unpack(endian + "5i", head)
                if 0 <= mopt < 5000 and mopt // 1000 in (0, 1):
                    break
            else:
                raise FileReadError(f"{shown}: corrupted MATLAB v4 header at byte {offset}",
                                    path=shown)
            elsize = _MAT4_ELEMENT_BYTES.get((mopt // 10) % 10)
            if elsize is None or min(mrows, ncols, namlen) < 0 or imagf not in (0, 1):
                raise FileReadError(f"{shown}: corrupted MATLAB v4 header at byte {offset}",
                                    path=shown)
            step = 20 + namlen + mrows * ncols * elsize * (2 if imagf else 1)
            if offset + step > size:
                raise FileReadError(f"{shown}: a MATLAB v4 header at byte {offset} declares more "
                                    f"data than the {size}-byte file holds; the file is "
                                    "corrupted", path=shown)
            offset += step


# MAT v5 data types: code -> bytes per element (numeric and character data)
_MI_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8, 14: 8,
             16: 1, 17: 2, 18: 4}
_MI_MATRIX, _MI_COMPRESSED = 14, 15
_NUMERIC_CLASSES = range(6, 16)           # mxDOUBLE_CLASS .. mxUINT64_CLASS
_CELL, _STRUCT, _CHAR, _SPARSE = 1, 2, 4, 5


class _MatCorrupt(Exception):
    """A MAT v5 structure that does not follow the format."""


def _mat5_sub(buf: bytes, pos: int, end: int, endian: str):
    """Next sub-element in ``buf[pos:end]``: ``(type, data start, data end, next pos)``."""
    import struct
    if pos + 8 > end:
        raise _MatCorrupt("truncated element tag")
    word, nbytes = struct.unpack(endian + "2I", buf[pos:pos + 8])
    if word >> 16:                                   # small data element: data in the tag
        small = word >> 16
        if small > 4:
            raise _MatCorrupt("small data element longer than 4 bytes")
        return word & 0xFFFF, pos + 4, pos + 4 + small, pos + 8
    start, stop = pos + 8, pos + 8 + nbytes
    if stop > end:
        raise _MatCorrupt("element longer than its parent")
    return word, start, stop, stop + (-nbytes % 8)


def _mat5_data(buf, pos, end, endian, count: int, what: str):
    """A numeric or character sub-element holding exactly ``count`` values."""
    dtype, start, stop, nxt = _mat5_sub(buf, pos, end, endian)
    size = _MI_SIZES.get(dtype)
    if size is None:
        raise _MatCorrupt(f"{what} has unknown data type {dtype}")
    if stop - start != count * size:
        raise _MatCorrupt(f"{what} holds {stop - start} bytes, not {count} values of "
                          f"{size} bytes")
    return nxt


def _mat5_matrix(buf: bytes, start: int, end: int, endian: str, depth: int = 0) -> None:
    """Validate the content of one miMATRIX element (the fields scipy's C
    reader trusts): flags, dimensions, name and data sizes, recursively."""
    import struct
    if start == end:                                 # an empty matrix element
        return
    if depth > 16:
        raise _MatCorrupt("nesting too deep")
    dtype, a, b, pos = _mat5_sub(buf, start, end, endian)
    if dtype != 6 or b - a != 8:
        raise _MatCorrupt("bad array flags")
    flags, nzmax = struct.unpack(endian + "2I", buf[a:b])
    cls, complex_ = flags & 0xFF, bool(flags & 0x800)
    dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
    if dtype != 5 or (b - a) % 4 or b - a < 8:
        raise _MatCorrupt("bad dimensions")
    dims = struct.unpack(endian + f"{(b - a) // 4}i", buf[a:b])
    if min(dims) < 0:
        raise _MatCorrupt("negative dimension")
    count = 1
    for d in dims:
        count *= d
    dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
    if dtype not in (1, 2, 16):
        raise _MatCorrupt("bad array name")
    if cls in _NUMERIC_CLASSES or cls == _CHAR:
        pos = _mat5_data(buf, pos, end, endian, count, "real part")
        if complex_:
            _mat5_data(buf, pos, end, endian, count, "imaginary part")
    elif cls == _CELL:
        for _ in range(count):
            dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
            if dtype != _MI_MATRIX:
                raise _MatCorrupt("cell element is not a matrix")
            _mat5_matrix(buf, a, b, endian, depth + 1)
    elif cls == _STRUCT:
        dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
        if dtype != 5 or b - a != 4:
            raise _MatCorrupt("bad field name length")
        name_len = struct.unpack(endian + "i", buf[a:b])[0]
        dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
        if dtype != 1 or name_len <= 0 or (b - a) % name_len:
            raise _MatCorrupt("bad field names")
        for _ in range(count * ((b - a) // name_len)):
            dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
            if dtype != _MI_MATRIX:
                raise _MatCorrupt("struct field is not a matrix")
            _mat5_matrix(buf, a, b, endian, depth + 1)
    elif cls == _SPARSE:
        if len(dims) != 2:
            raise _MatCorrupt("sparse matrix with more than 2 dimensions")
        pos = _mat5_data(buf, pos, end, endian, nzmax, "sparse row indices")
        pos = _mat5_data(buf, pos, end, endian, dims[1] + 1, "sparse column indices")
        for part in ("real", "imaginary")[:2 if complex_ else 1]:
            dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
            if dtype not in _MI_SIZES or (b - a) // _MI_SIZES[dtype] > nzmax:
                raise _MatCorrupt(f"bad sparse {part} part")
    else:
        raise _MatCorrupt(f"unsupported MATLAB class {cls} (objects, function handles)")


def _check_mat5_elements(raw: bytes, shown: str, size: int, max_bytes: int) -> None:
    """Validate a MATLAB v5 file before scipy reads it.

    Each top-level element must fit in the file; compressed elements must
    inflate (bounded) to what they declare; and every matrix must follow the
    format: scipy's C reader trusts the flags, dimensions, type codes and
    sizes, and a corrupted one made it allocate gigabytes or crash the
    interpreter (found by the fuzzers).
    """
    import struct
    import zlib
    budget = max_bytes                   # decompressed bytes allowed in all
    if len(raw) < 128:
        raise FileReadError(f"{shown}: MATLAB file header truncated", path=shown)
    endian = "<" if raw[126:128] == b"IM" else ">"
    offset = 128
    try:
        while offset < size:
            dtype, start, stop, nxt = _mat5_sub(raw, offset, size, endian)
            if dtype == _MI_COMPRESSED:
                inflater = zlib.decompressobj()
                try:
                    inner = inflater.decompress(raw[start:stop], budget + 1)
                except zlib.error as exc:
                    raise _MatCorrupt(f"corrupted compressed data ({exc})") from None
                if len(inner) > budget or inflater.unconsumed_tail:
                    raise ResourceLimitError(
                        f"{shown}: its compressed variables expand to more than "
                        f"{max_bytes} bytes (max_bytes), from a {size}-byte file; pass a "
                        "larger max_bytes if the file is genuine", path=shown)
                budget -= len(inner)
                itype, istart, istop, _ = _mat5_sub(inner, 0, len(inner), endian)
                if itype == _MI_MATRIX:
                    _mat5_matrix(inner, istart, istop, endian)
                offset = stop                            # compressed elements are not padded
            else:
                if dtype == _MI_MATRIX:
                    _mat5_matrix(raw, start, stop, endian)
                offset = nxt
    except _MatCorrupt as exc:
        raise FileReadError(f"{shown}: corrupted MATLAB file near byte {offset} ({exc})",
                            path=shown) from None
    except struct.error as exc:
        raise FileReadError(f"{shown}: corrupted MATLAB file near byte {offset} ({exc})",
                            path=shown) from None


def _check_mat_sizes(raw: bytes, shown: str, max_bytes: int) -> None:
    """Reject a MAT-file whose structure is corrupted or whose arrays would
    take more than the file plus ``max_bytes`` (a corrupted header would
    otherwise make scipy allocate gigabytes, or crash)."""
    import scipy.io
    size = len(raw)
    first = raw[:4]
    if len(first) == 4 and 0 in first:          # scipy's test for a v4 file
        _check_mat4_headers(raw, shown, size)
    else:
        _check_mat5_elements(raw, shown, size, max_bytes)
    try:
        entries = scipy.io.whosmat(BytesIO(raw))
    except MemoryError:
        raise FileReadError(f"{shown} is not a readable MATLAB .mat file (corrupted header)",
                            path=shown) from None
    except Exception as exc:  # scipy raises many kinds on malformed headers
        raise FileReadError(f"{shown} is not a readable MATLAB .mat file (corrupted or not a "
                            f"MAT-file): {_reason(exc)}", path=shown) from None
    declared = sum(8 * float(np.prod([float(d) for d in shape])) for _, shape, _ in entries)
    if declared > 8 * size + max_bytes:      # as float64 (what IOData holds)
        raise ResourceLimitError(f"{shown}: its variables take {declared / 2**20:.0f} MB as "
                                 f"float64, from a {size}-byte file: more than max_bytes = "
                                 f"{max_bytes} beyond the file's size; pass a larger "
                                 "max_bytes if the file is genuine", path=shown)


def _array_names(spec, role: str, keys, shown: str) -> list[str]:
    tokens = _tokens(spec, role, keys)
    for tok in tokens:
        if not isinstance(tok, str):
            raise FileReadError(f"{shown}: {role} selects arrays of an archive by name, not by "
                                f"index ({tok!r}); available arrays: {_listing(map(repr, keys))}",
                                path=shown, column=tok)
    if not tokens:
        raise FileReadError(f"{shown}: {role} selects no array", path=shown)
    for tok in tokens:
        if tok not in keys:
            raise FileReadError(f"{shown}: no array named {tok!r} ({role}); available arrays: "
                                f"{_listing(map(repr, keys)) or '(none)'}", path=shown, column=tok)
    seen = set()
    for tok in tokens:
        if tok in seen:
            raise FileReadError(f"{shown}: the array {tok!r} is selected twice in {role}",
                                path=shown, column=tok)
        seen.add(tok)
    return tokens


def _numeric(arr: np.ndarray, key: str, shown: str, ext: str) -> np.ndarray:
    if arr.dtype.kind not in "biufc":
        kind = {"U": "text", "S": "text", "O": "a cell array or object array",
                "V": "a struct / record array"}.get(arr.dtype.kind, f"of dtype {arr.dtype}")
        raise FileReadError(f"{shown}: the {'variable' if ext == '.mat' else 'array'} {key!r} "
                            f"is {kind}, not numeric", path=shown, column=key)
    return arr


def _channels(arr, key, shown, ext) -> tuple[np.ndarray, list[str]]:
    arr = _numeric(arr, key, shown, ext)
    if arr.ndim == 0:
        raise FileReadError(f"{shown}: {key!r} is a scalar, not a signal", path=shown, column=key)
    if arr.ndim == 1:
        return arr[:, None], [key]
    if arr.ndim != 2:
        raise FileReadError(f"{shown}: {key!r} has {arr.ndim} dimensions (shape {arr.shape}); "
                            "a signal is 1-D or 2-D with time on axis 0", path=shown, column=key)
    if arr.shape[1] == 1:
        return arr, [key]
    return arr, [f"{key}[{k}]" for k in range(arr.shape[1])]


def _stack(keys, arrays, shown, ext, role):
    parts, names = [], []
    for key in keys:
        arr, nm = _channels(arrays[key], key, shown, ext)
        parts.append(arr)
        names.extend(nm)
    lengths = {k: a.shape[0] for k, a in zip(keys, parts)}
    if len(set(lengths.values())) > 1:
        raise FileReadError(f"{shown}: the {role} arrays have different lengths "
                            f"({', '.join(f'{k}: {n}' for k, n in lengths.items())}); time is "
                            "axis 0", path=shown)
    values = parts[0] if len(parts) == 1 else np.hstack(parts)
    return values, names


def _scalar(arr, key, shown, ext) -> float:
    arr = _numeric(np.asarray(arr), key, shown, ext)
    if arr.size != 1:
        raise FileReadError(f"{shown}: {key!r} should be a scalar sampling period, got shape "
                            f"{arr.shape}", path=shown, column=key)
    return check_dt(float(arr.reshape(-1)[0].real), name=f"{shown}: {key}")


def _from_arrays(arrays: dict, shown, ext, inputs, outputs, dt, time) -> IOData:
    keys = list(arrays)
    what = "variables" if ext == ".mat" else "arrays"
    for role, spec, default in (("inputs", inputs, "u"), ("outputs", outputs, "y")):
        if spec is None and default not in arrays:
            raise FileReadError(f"{shown}: no {what[:-1]} named {default!r}; pass {role}= "
                                f"to choose the {role} among the {what} in the file: "
                                f"{_listing(map(repr, keys)) or '(none)'}", path=shown)
    in_keys = _array_names("u" if inputs is None else inputs, "inputs", keys, shown)
    out_keys = _array_names("y" if outputs is None else outputs, "outputs", keys, shown)
    t_key = None
    if time is not None:
        if not isinstance(time, str):
            raise FileReadError(f"{shown}: time names an array of the file, got {time!r}",
                                path=shown)
        t_key = _array_names(time, "time", keys, shown)[0]
    elif dt is None and "t" in arrays and "t" not in in_keys + out_keys:
        t_key = "t"
    roles = [("an input", in_keys), ("an output", out_keys),
             ("the time", [t_key] if t_key else [])]
    for a in range(len(roles)):
        for b in range(a + 1, len(roles)):
            both = set(roles[a][1]) & set(roles[b][1])
            if both:
                key = sorted(both)[0]
                raise FileReadError(f"{shown}: the {what[:-1]} {key!r} is used both as "
                                    f"{roles[a][0]} and as {roles[b][0]}", path=shown, column=key)
    u, in_names = _stack(in_keys, arrays, shown, ext, "input")
    y, out_names = _stack(out_keys, arrays, shown, ext, "output")
    t = None
    if t_key is not None:
        t = _numeric(np.asarray(arrays[t_key]), t_key, shown, ext)
        if t.ndim == 2 and 1 in t.shape:
            t = t.reshape(-1)
        if dt is None and time is None and "dt" in arrays:
            file_dt = _scalar(arrays["dt"], "dt", shown, ext)
            steps = np.diff(np.asarray(t, dtype=np.float64))
            if steps.size and not same_period(steps, file_dt, resolution=stamp_resolution(t)):
                raise FileReadError(f"{shown}: the file holds both 't' and 'dt' and they "
                                    f"disagree (dt = {file_dt:g}, t steps from {steps.min():g} "
                                    f"to {steps.max():g}); pass dt= or time= to choose",
                                    path=shown)
    elif dt is None and "dt" in arrays and "dt" not in in_keys + out_keys:
        dt = _scalar(arrays["dt"], "dt", shown, ext)
    return _build(shown, u, y, dt, t, in_names, out_names)


# ---------------------------------------------------------------------------
# chunked reading (files larger than memory)
# ---------------------------------------------------------------------------
_HEAD_BYTES = 1 << 20            # bytes read to find the layout of a text file
STREAM_EXTENSIONS = (".csv", ".tsv", ".txt", ".dat", ".npy", ".parquet")


def read_inputs(path, inputs, *, time=None, delimiter=None):
    """Input columns of a file that holds no outputs (:func:`read` needs both).

    Used to simulate a model on a file of inputs (``subid simulate``). The
    file goes through the same validated readers as :func:`read`.

    Parameters
    ----------
    path : str or os.PathLike
        CSV/TXT/TSV, ``.npz`` or ``.mat`` file.
    inputs : str or list
        Columns (names or 0-based indices) or array names of the inputs.
    time : str or int, optional
        Column (or array) holding the time stamps.
    delimiter : str, optional
        Column separator of a text file; detected when omitted.

    Returns
    -------
    u : ndarray, shape (N, n_inputs)
    names : list of str
        The input channel names.
    t : ndarray, shape (N,), or None
        The time stamps, when ``time`` is given.

    Raises
    ------
    FileReadError
        Unsupported or unreadable file, unknown column.
    DataError
        NaN or infinite values.
    """
    shown = os.fspath(path)
    p = Path(shown)
    ext = p.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        raise FileReadError(f"{shown}: unsupported file type {ext or '(no extension)'!r}; "
                            f"supported: {', '.join(SUPPORTED_EXTENSIONS)}", path=shown)
    _check_exists(p, shown)
    if ext in (".npz", ".mat"):
        arrays = _load_npz(p, shown) if ext == ".npz" else _load_mat(p, shown)
        keys = _array_names(inputs, "inputs", list(arrays), shown)
        u, names = _stack(keys, arrays, shown, ext, "input")
        t = None
        if time is not None:
            key = _array_names(time, "time", list(arrays), shown)[0]
            t = np.asarray(arrays[key], dtype=float).reshape(-1)
        u = np.asarray(u, dtype=float)
        if not np.isfinite(u).all():
            raise DataError(f"{shown}: the inputs hold NaN or infinite values")
        return u, names, t
    text = _decode(_read_bytes(p, shown), shown)
    table = _Table(shown, text, ext, delimiter)
    cols = table.resolve(inputs, "inputs")
    t_cols = table.resolve(time, "time") if time is not None else []
    both = set(cols) & set(t_cols)
    if both:
        raise FileReadError(f"{shown}: {table.describe(min(both))} is used both as an input "
                            "and as the time", path=shown)
    all_cols = cols + t_cols
    values = table.parse(all_cols)
    table.check_finite(values, all_cols)
    t = values[:, -1] if t_cols else None
    return values[:, :len(cols)], table.channel_names(cols), t


@checked_call
def read_chunks(path, inputs=None, outputs=None, *, dt=None, chunk_size=100_000,
                delimiter=None):
    """Read a uniformly sampled record piece by piece, with bounded memory.

    Parameters
    ----------
    path : str or os.PathLike
        A text file (``.csv``, ``.tsv``, ``.txt``, ``.dat``; same layout
        rules as :func:`read`), a 2-D ``.npy`` array (memory-mapped; rows =
        samples, columns selected by 0-based index), or a ``.parquet`` file
        (needs ``pyarrow``; columns selected by name).
    inputs, outputs : str, int or sequence
        Columns of the inputs and outputs, as in :func:`read` (required).
    dt : float, optional
        Sampling period (default 1). Streaming assumes uniform sampling:
        the statistic of the subspace methods needs it.
    chunk_size : int
        Samples per piece.
    delimiter : str, optional
        As in :func:`read` (text files).

    Yields
    ------
    IOData
        Consecutive pieces; their time stamps continue from piece to piece.
        Errors name the file, the (global) line and the column.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> import subid
    >>> data = subid.systems.simulate_data(subid.systems.seed001_system(), 3000, seed=0)
    >>> path = os.path.join(tempfile.mkdtemp(), "record.csv")      # a stand-in for a huge file
    >>> np.savetxt(path, np.column_stack([data.u, data.y]), delimiter=",",
    ...            header="u1,u2,y1,y2", comments="")
    >>> stat = subid.HankelStatistic(2, 2, depth=20)
    >>> for piece in subid.read_chunks(path, "u1,u2", "y1,y2", dt=1.0, chunk_size=1000):
    ...     _ = stat.update(piece.u, piece.y)
    >>> stat.n_samples
    3000
    >>> import shutil; shutil.rmtree(os.path.dirname(path))
    """
    shown, p = _as_path(path)
    dt = 1.0 if dt is None else check_dt(dt)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, numbers.Integral) \
            or chunk_size < 1:
        raise DataError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    ext = p.suffix.lower()
    if ext not in STREAM_EXTENSIONS:
        raise FileReadError(f"{shown}: files with extension {ext or '(none)'!r} cannot be read in "
                            f"pieces; supported: {', '.join(STREAM_EXTENSIONS)} (read .npz and "
                            ".mat files whole with subid.read)", path=shown)
    _check_exists(p, shown)
    if ext == ".npy":
        pieces = _npy_pieces(p, shown, inputs, outputs, chunk_size)
    elif ext == ".parquet":
        pieces = _parquet_pieces(p, shown, inputs, outputs, chunk_size)
    else:
        pieces = _text_pieces(p, shown, ext, inputs, outputs, chunk_size, delimiter)
    return _as_records(pieces, dt)


def _as_records(pieces, dt):
    start = 0
    for u, y, in_names, out_names in pieces:
        piece = IOData(u, y, dt=dt, input_names=in_names, output_names=out_names)
        if start:
            piece = piece._derive(piece.u, piece.y, dt=dt, t0=start * dt)
        start += piece.n_samples
        yield piece


def _text_lines(fh, shown: str, consumed: int, chunk_size: int):
    """Lists of up to ``chunk_size`` lines (without their line break) of the
    text file ``fh``, read in bounded blocks: a line longer than
    MAX_LINE_CHARS is refused before it is held whole, so memory is bounded
    by the chunk size, whatever the file."""
    block = 1 << 18                  # characters read at a time
    pending, lines = "", []
    while True:
        try:
            text = fh.read(block)
        except UnicodeDecodeError as exc:
            raise FileReadError(f"{shown}: the file is not UTF-8 text after line "
                                f"{consumed + len(lines)} ({exc.reason})", path=shown,
                                line=consumed + len(lines)) from None
        except OSError as exc:
            raise FileReadError(f"{shown}: cannot read the file ({_reason(exc)})",
                                path=shown) from None
        if not text:
            if pending:
                lines.append(pending)
            if lines:
                yield lines
            return
        parts = (pending + text).split("\n")
        pending = parts.pop()
        if len(pending) > MAX_LINE_CHARS:
            line = consumed + len(lines) + 1
            raise ResourceLimitError(f"{shown}, line {line}: the line is longer than the "
                                     f"{MAX_LINE_CHARS} characters subid reads "
                                     "(subid.io.formats.MAX_LINE_CHARS); is this a text data file?",
                                     path=shown, line=line)
        for line in parts:
            if len(line) > MAX_LINE_CHARS:
                number = consumed + len(lines) + 1
                raise ResourceLimitError(f"{shown}, line {number}: the line is longer than "
                                         f"the {MAX_LINE_CHARS} characters subid reads "
                                         "(subid.io.formats.MAX_LINE_CHARS)", path=shown, line=number)
            lines.append(line)
            if len(lines) == chunk_size:
                yield lines
                consumed += len(lines)
                lines = []


def _text_pieces(p, shown, ext, inputs, outputs, chunk_size, delimiter):
    import io as _io
    fh, _ = open_regular(shown, what="data file", max_bytes=None)
    with fh:
        try:
            head = fh.read(_HEAD_BYTES)
        except OSError as exc:
            raise FileReadError(f"{shown}: cannot read the file ({_reason(exc)})",
                                path=shown) from None
        if not head:
            raise FileReadError(f"file {shown} is empty", path=shown)
        utf16 = head.startswith((b"\xff\xfe", b"\xfe\xff"))
        if len(head) == _HEAD_BYTES:
            newline = "\n".encode("utf-16-le" if head.startswith(b"\xff\xfe") else "utf-16-be") \
                if utf16 else b"\n"
            cut = head.rfind(newline)
            while utf16 and cut > 0 and (cut - 2) % 2:     # a UTF-16 code unit boundary
                cut = head.rfind(newline, 0, cut)
            if cut > 0:
                head = head[: cut + len(newline)]
        layout = _Table(shown, _decode(head, shown), ext, delimiter)
        in_cols, out_cols, _ = _roles(layout, shown, inputs, outputs, None)
        cols = in_cols + out_cols
        in_names, out_names = layout.channel_names(in_cols), layout.channel_names(out_cols)
        n_in = len(in_cols)
        fh.seek(0)
        if utf16:
            encoding = "utf-16"
        else:                        # like read(): UTF-8, else Latin-1 (decided on the head)
            try:
                head.decode("utf-8-sig")
                encoding = "utf-8-sig"
            except UnicodeDecodeError:
                encoding = "latin-1"
        offset = None if utf16 or _lone_cr(head) else _line_start(head, layout.data_start)
        if offset is not None:
            fh.seek(offset)
            yield from _fast_pieces(fh, shown, layout, cols, n_in, in_names, out_names,
                                    chunk_size, encoding)
            return
        text = _io.TextIOWrapper(fh, encoding=encoding, newline=None)
        try:
            consumed = 0
            for _ in range(layout.data_start):
                try:
                    line = text.readline(MAX_LINE_CHARS + 1)
                except UnicodeDecodeError as exc:
                    raise FileReadError(f"{shown}: the file is not {encoding} text at line "
                                        f"{consumed + 1} ({exc.reason})", path=shown,
                                        line=consumed + 1) from None
                if len(line) > MAX_LINE_CHARS:
                    raise ResourceLimitError(f"{shown}, line {consumed + 1}: the line is "
                                             f"longer than the {MAX_LINE_CHARS} characters "
                                             "subid reads (subid.io.formats.MAX_LINE_CHARS)",
                                             path=shown, line=consumed + 1)
                consumed += 1
            for lines in _text_lines(text, shown, consumed, chunk_size):
                piece = _piece(layout, lines, consumed)
                consumed += len(lines)
                if not any(line.strip() and not line.lstrip().startswith("#") for line in lines):
                    continue
                values = piece.parse(cols)
                piece.check_finite(values, cols)
                yield values[:, :n_in], values[:, n_in:], in_names, out_names
        finally:
            text.detach()


def _piece(layout, lines, consumed: int):
    """A table of ``lines`` (line ``consumed + 1`` of the file on) with the layout
    (delimiter, columns, names) of ``layout``, for the careful parser."""
    piece = _Table.__new__(_Table)
    piece.__dict__.update(layout.__dict__)
    piece.text = "\n".join(lines) + "\n"
    piece.lines = piece.text.split("\n")
    piece.data_start = 0
    piece.line_offset = consumed
    return piece


def _careful_block(layout, buf: bytes, encoding: str, consumed: int, cols, shown):
    """Values of the lines ``buf`` (line ``consumed + 1`` on) by the careful
    parser, and their number of lines: used where the fast parser declined,
    so that a bad row is reported with its file, line and column."""
    try:
        text = buf.decode(encoding)
    except UnicodeDecodeError as exc:
        raise FileReadError(f"{shown}: the file is not UTF-8 text after line {consumed} "
                            f"({exc.reason})", path=shown, line=consumed) from None
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    if not any(line.strip() and not line.lstrip().startswith("#") for line in lines):
        return np.empty((0, len(cols))), len(lines)
    piece = _piece(layout, lines, consumed)
    values = piece.parse(cols)
    piece.check_finite(values, cols)
    return values, len(lines)


#: Rows first allocated for a piece of read_chunks (doubled up to chunk_size).
_PIECE_ROWS = 1 << 18


def _fast_pieces(fh, shown, layout, cols, n_in, in_names, out_names, chunk_size, encoding):
    """Pieces of ``chunk_size`` rows of a text file read once, block by block,
    by the fast parser (the careful one for blocks it declines).

    Each parsed block is copied once, column by column, into the C-ordered
    ``u`` and ``y`` of the current piece; the filled piece is handed out
    read-only, so :class:`IOData` keeps it without another copy."""
    consumed = layout.data_start          # lines before the current block
    n_out = len(cols) - n_in
    u = y = None
    filled = 0
    blocks = _blocks(fh, shown, encoding, consumed)
    for buf, n_lines, values in _parsed_blocks(blocks, layout.delim, layout.ncols):
        if values is None:
            values, n_lines = _careful_block(layout, buf, encoding, consumed, cols, shown)
            picked = range(len(cols))
        else:
            picked = cols
        consumed += n_lines
        rows, start = values.shape[0], 0
        while start < rows:
            if u is None:                 # grown past _PIECE_ROWS for huge chunk sizes only
                size = min(chunk_size, _PIECE_ROWS)
                u, y, filled = np.empty((size, n_in)), np.empty((size, n_out)), 0
            elif filled == u.shape[0]:
                size = min(2 * u.shape[0], chunk_size)
                u = np.concatenate([u, np.empty((size - u.shape[0], n_in))])
                y = np.concatenate([y, np.empty((size - y.shape[0], n_out))])
            take = min(u.shape[0] - filled, rows - start)
            for j, c in enumerate(picked):
                target, k = (u, j) if j < n_in else (y, j - n_in)
                target[filled:filled + take, k] = values[start:start + take, c]
            filled += take
            start += take
            if filled == chunk_size:
                yield _frozen(u), _frozen(y), in_names, out_names
                u = y = None
        del values
    if u is not None and filled:
        yield _frozen(u[:filled]), _frozen(y[:filled]), in_names, out_names


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` (an array of our own) made read-only: IOData keeps it as a view."""
    a.setflags(write=False)
    return a


def _column_indices(spec, role: str, n_columns: int, shown: str) -> list[int]:
    tokens = [int(t) if isinstance(t, str) and _INT_RE.fullmatch(t) else t
              for t in _tokens(spec, role, [])]
    out = []
    for tok in tokens:
        if not isinstance(tok, numbers.Integral) or not 0 <= tok < n_columns:
            raise FileReadError(f"{shown}: {role} must be 0-based column indices of the "
                                f"{n_columns}-column array, got {tok!r}", path=shown)
        out.append(int(tok))
    return out


def _npy_pieces(p, shown, inputs, outputs, chunk_size):
    from subid.io._npz import npy_header
    fh, size = open_regular(shown, what="data file", max_bytes=None)
    with fh:
        try:                         # the header is validated before numpy parses it
            shape, _, dtype, head = npy_header(fh, os.path.basename(shown))
        except NpzError as exc:
            raise FileReadError(f"{shown}: not a readable .npy array ({exc})",
                                path=shown) from None
    count = 1
    for d in shape:
        count *= d
    if head + count * dtype.itemsize != size:
        raise FileReadError(f"{shown}: the .npy header declares {count * dtype.itemsize} "
                            f"bytes of data but the file holds {size - head}; it is "
                            "truncated or corrupted", path=shown)
    try:
        arr = np.load(p, mmap_mode="r", allow_pickle=False)
    except Exception as exc:         # numpy's header parser: ValueError, SyntaxError, ...
        raise FileReadError(f"{shown}: not a readable .npy array ({_reason(exc)})",
                            path=shown) from None
    if arr.ndim != 2 or arr.dtype.kind not in "iuf":
        raise FileReadError(f"{shown}: expected a 2-D numeric array (samples x columns), got "
                            f"shape {arr.shape} and dtype {arr.dtype}", path=shown)
    if inputs is None or outputs is None:
        raise FileReadError(f"{shown}: inputs and outputs (column indices) must be given",
                            path=shown)
    in_cols = _column_indices(inputs, "inputs", arr.shape[1], shown)
    out_cols = _column_indices(outputs, "outputs", arr.shape[1], shown)
    in_names = [f"col{k}" for k in in_cols]
    out_names = [f"col{k}" for k in out_cols]
    for a in range(0, arr.shape[0], chunk_size):
        block = np.asarray(arr[a:a + chunk_size], dtype=np.float64)
        yield block[:, in_cols], block[:, out_cols], in_names, out_names


def _parquet_pieces(p, shown, inputs, outputs, chunk_size):
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise FileReadError(f"{shown}: reading Parquet files needs pyarrow "
                            "(pip install pyarrow)", path=shown) from None
    try:
        pf = pq.ParquetFile(p)
    except Exception as exc:           # pyarrow raises its own error classes
        raise FileReadError(f"{shown}: not a readable Parquet file ({_reason(exc)})",
                            path=shown) from None
    names = list(pf.schema_arrow.names)
    if inputs is None or outputs is None:
        raise FileReadError(f"{shown}: inputs and outputs must be given; columns: "
                            f"{_listing(names)}", path=shown)
    chosen = []
    for spec, role in ((inputs, "inputs"), (outputs, "outputs")):
        cols = []
        for tok in _tokens(spec, role, names):
            name = names[tok] if isinstance(tok, numbers.Integral) and 0 <= tok < len(names) \
                else tok
            if name not in names:
                raise FileReadError(f"{shown}: no column {tok!r} for the {role}; columns: "
                                    f"{_listing(names)}", path=shown, column=tok)
            cols.append(name)
        chosen.append(cols)
    in_names, out_names = chosen
    batches = pf.iter_batches(batch_size=chunk_size, columns=in_names + out_names)
    start = 0
    while True:
        try:
            batch = next(batches, None)
            if batch is None:
                return
            block = np.column_stack([np.asarray(batch.column(k), dtype=np.float64)
                                     for k in range(batch.num_columns)])
        except Exception as exc:       # pyarrow's own errors (OSError, ArrowInvalid...)
            raise FileReadError(f"{shown}: cannot read the Parquet data after row {start} "
                                f"({_reason(exc)})", path=shown) from None
        start += block.shape[0]
        yield block[:, :len(in_names)], block[:, len(in_names):], in_names, out_names
