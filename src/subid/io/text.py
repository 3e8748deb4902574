"""Delimited text files (``.csv``, ``.tsv``, ``.txt``, ``.dat``): the careful,
line-by-line reader behind :func:`subid.io.formats.read` (the rules are in that module's
docstring), which names the line and column of every problem."""

from __future__ import annotations

import csv
import logging
import numbers
import re
import warnings
from io import StringIO

import numpy as np

from subid.data import IOData
from subid.errors import DataError, FileReadError, SamplingWarning
from subid.io._common import (
    _DECIMAL_COMMA_RE,
    _INT_RE,
    _SNIFF_LINES,
    _WHITESPACE,
    _build,
    _check_line_lengths,
    _listing,
    _read_bytes,
    first_non_finite,
)

logger = logging.getLogger(__name__)

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


#: Spreadsheet error and missing-value markers (Excel, LibreOffice, Google Sheets): a line
#: starting with one of them is a data row with a missing value, not a ``#`` comment.
MISSING_MARKERS = frozenset({
    "#N/A", "#NA", "#VALUE!", "#REF!", "#DIV/0!", "#NUM!", "#NAME?", "#NULL!", "#SPILL!",
    "#CALC!", "#FIELD!", "#BLOCKED!", "#CONNECT!", "#BUSY!", "#UNKNOWN!", "#ERROR!",
    "#GETTING_DATA"})
_FIRST_CELL_RE = re.compile(r'[^,;\t "]*')


def is_comment(line: str) -> bool:
    """True when ``line`` is a comment line: its first non-blank character is ``#`` and
    its first cell is not a spreadsheet marker (:data:`MISSING_MARKERS`, such as Excel's
    ``#N/A``). A ``#`` elsewhere on a line is part of a field (a header name such as
    ``Valve #1``), never the start of a comment."""
    s = line.lstrip()
    if not s.startswith("#"):
        return False
    first = _FIRST_CELL_RE.match(s)
    return first is None or first.group().upper() not in MISSING_MARKERS


def _content(line: str) -> str:
    """A line without surrounding blanks ('' for a blank or comment line)."""
    return "" if is_comment(line) else line.strip()


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


_DATE_TIME_RE = re.compile(r"\d{4}-\d{2}-\d{2}(?:[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d+)?)?)?"
                           r"(?:Z|[+-]\d{2}:?\d{2})?")


def _is_date_time(s: str) -> bool:
    """True when ``s`` is an ISO 8601 date or date-time (``2024-01-01 00:00:02``)."""
    if not _DATE_TIME_RE.fullmatch(s):
        return False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)       # a UTC offset: no time zone kept
        try:
            np.datetime64(s.rstrip("Z") if s.endswith("Z") else s, "us")
        except ValueError:
            return False
    return True


def _is_value(field: str) -> bool:
    """True when a field of the first line is a value, not a column name: a number, an
    ISO 8601 date-time or a spreadsheet missing-value marker (``#N/A``); a line of such
    fields is the first data row, not a header."""
    f = field.strip('"').strip()
    return _is_number(f) or f.upper() in MISSING_MARKERS or _is_date_time(f)


def _sniff(sample: list[str], ext: str) -> str | None:
    """Choose the delimiter from the first non-empty lines."""
    candidates = (";", "\t", ",") if ext in (".csv", ".tsv") else (";", ",")
    if ext not in (".csv", ".tsv") and _tab_table(sample):
        return "\t"
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


def _tab_table(sample: list[str]) -> bool:
    """True when the (stripped) first lines of a ``.txt``/``.dat`` file are a table of
    TAB-delimited fields (a spreadsheet's "Text (Tab delimited)" export): the same
    number of TABs on every line, no field of a data line holding two values apart by
    spaces (the DaISy / ``save -ascii`` style separates columns by runs of spaces and
    TABs alike), and TABs splitting a line otherwise than runs of blanks do (a name
    with spaces, an empty cell): else runs of blanks stay the delimiter, as before."""
    tabs = sample[0].count("\t")
    if not tabs or any(ln.count("\t") != tabs for ln in sample):
        return False
    if any(len(f.split()) > 1 for ln in sample[1:] for f in ln.split("\t")):
        return False
    return any([f.strip() for f in ln.split("\t")] != ln.split() for ln in sample)


def decimal_commas(raw: bytes, shown: str, ext: str, delimiter) -> tuple[bytes, str]:
    """``(raw, delimiter)`` of a text file whose numbers have decimal commas
    (``decimal=','`` of :func:`subid.io.formats.read`), rewritten with decimal points:
    every comma of the data lines becomes a point. The delimiter is the one given (not
    ``,``) or the first of ``;``, TAB and runs of spaces found on the first content line.
    The first content line keeps its commas when it is a header (a field that is not a
    number, its commas read as points)."""
    if delimiter == ",":
        raise DataError(f"{shown}: decimal=',' needs another field delimiter than ','; "
                        "give delimiter=';' (or TAB, or ' ' for runs of spaces)")
    lines = _decode(raw, shown).split("\n")
    first = next((k for k, line in enumerate(lines) if _content(line)), None)
    if first is None:
        return raw, delimiter
    if delimiter is None:
        head = _content(lines[first])
        delimiter = ";" if ";" in head else "\t" if "\t" in head else " "
    fields = _split(_content(lines[first]), _WHITESPACE if delimiter == " " else delimiter)
    header = any(not _is_number(f.strip().strip('"').replace(",", ".")) for f in fields)
    text = "\n".join(line if (k == first and header) else line.replace(",", ".")
                     for k, line in enumerate(lines))
    return text.encode("utf-8"), delimiter


class _Table:
    """Layout of a text file: delimiter, header, column count, first data line."""

    line_offset = 0                   # lines before ``text`` in the file (chunked reading)
    ascii_head = True                 # the head of the file is ASCII (chunked reading)

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
        if not all(_is_value(f) for f in fields):
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
        if not is_comment(line):
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
                    f"{self.ncols - 1}{self.delimiter_hint()}")
        return "available columns: " + _listing(
            f"{k} {n!r}" if n else f"{k} (no name)" for k, n in enumerate(self.header)) \
            + self.delimiter_hint()

    def delimiter_hint(self) -> str:
        """When the file was split into one column but its first line holds another
        usual delimiter, or split at blanks a first line whose TAB-delimited fields hold
        spaces (names such as ``Input [V]``): ``' (is the delimiter right? ...)'``
        naming it, else ``''``."""
        if not self.lines:
            return ""
        first = self.lines[0]
        parts = first.strip().split("\t")
        if self.delim is _WHITESPACE and len(parts) > 1 and \
                any(len(f.split()) > 1 for f in parts):
            return (" (is the delimiter right? it was taken to be runs of spaces/TABs, "
                    "which splits names with spaces, and the first line holds TAB: pass "
                    "delimiter='\\t', on the command line --delimiter $'\\t')")
        if self.ncols != 1:
            return ""
        for other in (";", ",", "\t", "|"):
            if other != self.delim and other in first:
                name = _delim_name(other)
                return (f" (is the delimiter right? it was taken to be "
                        f"{_delim_name(self.delim)}, and the first line holds {name}: pass "
                        f"delimiter={other!r}, on the command line --delimiter {other!r})")
        return ""

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
                    f"{self.ncols - 1}, counted from 0){self.delimiter_hint()}", path=shown,
                    column=idx)
            if idx in cols:
                raise FileReadError(f"{shown}: {self.describe(idx)} is selected twice in {role}",
                                    path=shown, column=idx)
            if self.header is not None and not (isinstance(tok, str) and tok in self.header) \
                    and _is_value(self.header[idx]):
                self._ambiguous_header(idx, role)
            cols.append(idx)
        return cols

    def _ambiguous_header(self, idx: int, role: str):
        """FileReadError: column ``idx``, selected by index, has a value (a number, a
        date-time) in the line taken as the header, which may be the first data row."""
        names = [f for f in self.header if not _is_value(f)]
        raise FileReadError(
            f"{self.shown}: line {self.header_line} was taken as the header (it holds "
            f"{names[0]!r}, which is not a number), but its cell in column {idx}, selected "
            f"by index in {role}, is the value {self.header[idx]!r}: if line "
            f"{self.header_line} is the first data row, add a header line of column names "
            "before it; if it is the header, select the columns by name (subid does not "
            "guess)", path=self.shown, line=self.header_line, column=idx)

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
                                delimiter=self.delim, comments=None, quotechar='"',
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
            named = re.search(r"at row (\d+)", str(exc))
            if named and int(named.group(1)) < len(contents):
                hint = int(named.group(1))
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

    def date_times(self, idx: int) -> np.ndarray | None:
        """Column ``idx`` read as ISO 8601 date-times (``2024-01-01 00:00:02``,
        ``2024-01-01T00:00:02.5``; with a UTC offset or ``Z``, converted to UTC), as
        seconds since the first one; None when a cell is not such a date-time."""
        _, contents = self.data_lines()
        cells = [_split(c, self.delim)[idx].strip().strip('"') for c in contents]
        if not cells or _is_number(cells[0]):
            return None
        with warnings.catch_warnings():
            # numpy converts a UTC offset to UTC, and warns that it keeps no time zone
            warnings.simplefilter("ignore", UserWarning)
            try:
                stamps = np.array(cells, dtype="datetime64[us]")
            except ValueError:
                return None
        if np.isnat(stamps).any():
            return None
        return (stamps - stamps[0]) / np.timedelta64(1, "s")

    def _bad_cell(self, lineno: int, idx: int, s: str) -> str:
        msg = f"{self.shown}, line {lineno}, {self.describe(idx)}: "
        if not s:
            return msg + "the value is missing (empty field)"
        msg += (f"{s!r} is not a number" if len(s) <= 60 else
                f"{s[:40]!r}... ({len(s)} characters) is not a number")
        if s.strip('"').upper() in MISSING_MARKERS or s.upper() in ("NA", "N/A", "NULL"):
            msg += (" (a missing-value marker: subid does not drop or fill samples; "
                    "interpolate the gap, or split the record there and merge the parts)")
        elif _DECIMAL_COMMA_RE.fullmatch(s):
            # the command line rewrites decimal=',' as its --decimal , (cli_hint)
            msg += " (a decimal comma: pass decimal=',' and a field delimiter other than ',')"
        elif self.header is not None and lineno == self.first_data:
            _, contents = self.data_lines()
            if not any(_is_number(f.strip().strip('"')) for f in _split(contents[0],
                                                                        self.delim)):
                msg += (f" (line {lineno} holds no number at all: a second header row, "
                        "such as the units? remove it)")
        return msg

    def check_finite(self, values: np.ndarray, cols: list[int]) -> None:
        found = first_non_finite(values)
        if found is None:
            return
        row, j, n_bad, n_rows = found
        idx = cols[j]
        linenos, contents = self.data_lines()
        lineno = linenos[row]
        text = _split(contents[row], self.delim)[idx]
        raise DataError(
            f"{self.shown}, line {lineno}, {self.describe(idx)}: {text!r} is not a finite "
            f"number ({n_bad} NaN or infinite value{'s' if n_bad != 1 else ''} in "
            f"{n_rows} row{'s' if n_rows != 1 else ''} of the selected columns); "
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
    out: list[str | int] = []
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


#: First words (lower case) of a column name that :func:`_read_text` takes for time stamps
#: when it warns that a record read without ``dt`` or ``time`` has such a column.
_TIME_WORDS = frozenset({"t", "time", "times", "timestamp", "timestamps", "seconds", "second",
                         "sec", "secs"})


def _time_like(table: "_Table", used) -> str | None:
    """The name of the first column not in ``used`` whose name's first word (up to a
    space, underscore or bracket: ``Time [s]``, ``time_s``) is one of
    :data:`_TIME_WORDS`, or None."""
    return time_like_name(table.header or (), used)


def time_like_name(names, used) -> str | None:
    """The first of the column ``names`` whose index is not in ``used`` and that
    looks like time stamps (:func:`_time_like`), or None."""
    for idx, name in enumerate(names):
        if idx in used or not name:
            continue
        if re.split(r"[\s_\[\(]", name.strip().lower(), maxsplit=1)[0] in _TIME_WORDS:
            return name
    return None


def warn_unused_time(table: "_Table", shown: str, used, dt, time) -> None:
    """A :class:`subid.errors.SamplingWarning` when a record is read without ``dt`` or
    ``time`` from a file with a column that looks like time stamps (:func:`_time_like`;
    ``used``: the input and output columns). Both parsers call it once they have read
    the file."""
    if dt is not None or time is not None:
        return
    name = _time_like(table, set(used))
    if name is not None:
        warnings.warn(SamplingWarning(
            f"{shown}: no sampling period (dt) or time column (time) given, so time is "
            f"counted in samples (dt = 1); the column {name!r} looks like time stamps: "
            f"pass time={name!r} to take the sampling period from it", column=name),
            stacklevel=5)


def _read_text(p, shown, ext, inputs, outputs, dt, time, delimiter, *, raw=None) -> IOData:
    text = _decode(_read_bytes(p, shown) if raw is None else raw, shown)
    table = _Table(shown, text, ext, delimiter)
    in_cols, out_cols, t_cols = _roles(table, shown, inputs, outputs, time)
    cols = in_cols + out_cols + t_cols
    try:
        values = table.parse(cols)
    except FileReadError as exc:
        # a time column of date-times: the channels as numbers, the stamps as seconds
        if not (t_cols and exc.column == t_cols[0]):
            raise
        stamps = table.date_times(t_cols[0])
        if stamps is None:
            raise FileReadError(f"{exc} (time stamps must be numbers or ISO 8601 date-times "
                                "such as 2024-01-01 00:00:02 or 2024-01-01T00:00:02.5)",
                                path=shown, line=exc.line, column=exc.column) from None
        values = np.column_stack([table.parse(in_cols + out_cols), stamps])
    table.check_finite(values, cols)
    n_in, n_out = len(in_cols), len(out_cols)
    u = values[:, :n_in]
    y = values[:, n_in:n_in + n_out]
    t = values[:, -1] if t_cols else None
    data = _build(shown, u, y, dt, t, table.channel_names(in_cols),
                  table.channel_names(out_cols), first_line=table.first_data)
    warn_unused_time(table, shown, in_cols + out_cols, dt, time)
    return data
