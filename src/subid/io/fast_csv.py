"""Fast parsing of well-formed delimited text (pandas' C parser, pyarrow.csv or numpy),
block by block; the careful reader of :mod:`subid.io.text` takes over on any doubt."""

from __future__ import annotations

import collections
import csv
import os
from io import BytesIO, StringIO

import numpy as np

from subid import _threads
from subid.errors import DataError, FileReadError, ResourceLimitError
from subid.io._common import _SNIFF_LINES, MAX_LINE_CHARS, _build, _reason
from subid.io._files import open_regular
from subid.io.text import _roles, _Table, warn_unused_time

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

    pending: collections.deque = collections.deque()
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
    except (FileReadError, ResourceLimitError, DataError):
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
        except (FileReadError, ResourceLimitError, DataError):
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
    data = _build(shown, u, y, dt, t, layout.channel_names(in_cols),
                  layout.channel_names(out_cols), first_line=layout.first_data)
    warn_unused_time(layout, shown, in_cols + out_cols, dt, time)
    return data



_HEAD_BYTES = 1 << 20            # bytes read to find the layout of a text file
