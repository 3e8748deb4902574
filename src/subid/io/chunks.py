"""Reading files larger than memory: :func:`read_chunks` (consecutive pieces of a record)
and :func:`read_inputs` (the input columns of a file without outputs)."""

from __future__ import annotations

import numbers
import os
import warnings
from pathlib import Path

import numpy as np

from subid._validation import check_dt, checked_call
from subid.data import IOData
from subid.errors import DataError, FileReadError, ResourceLimitError, SamplingWarning
from subid.io._common import (
    _INT_RE,
    MAX_LINE_CHARS,
    SUPPORTED_EXTENSIONS,
    _as_path,
    _check_exists,
    _listing,
    _read_bytes,
    _reason,
    first_non_finite,
)
from subid.io._files import open_regular
from subid.io._npz import NpzError
from subid.io.arrays import _array_names, _load_npz, _stack
from subid.io.fast_csv import _HEAD_BYTES, _blocks, _line_start, _lone_cr, _parsed_blocks
from subid.io.mat import _load_mat
from subid.io.text import _content, _decode, _roles, _Table, _tokens, time_like_name

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
        Errors name the file, the place in the file (the line of a text file,
        the 0-based row of a ``.npy`` or Parquet file) and the column.

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
    hint = dt is None                # a column named like time stamps is then worth a warning
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
        pieces = _parquet_pieces(p, shown, inputs, outputs, chunk_size, hint)
    else:
        pieces = _text_pieces(p, shown, ext, inputs, outputs, chunk_size, delimiter, hint)
    return _as_records(pieces, dt)


def _hint_time(shown: str, names, used) -> None:
    """A :class:`~subid.errors.SamplingWarning` when a stream read without ``dt``
    has a column named like time stamps (``names``; ``used``: the indices of the
    inputs and outputs): read_chunks takes no time column, its period is ``dt``."""
    name = time_like_name(names, set(used))
    if name is not None:
        warnings.warn(SamplingWarning(
            f"{shown}: no sampling period (dt) given, so time is counted in samples (dt = 1); "
            f"the column {name!r} looks like time stamps: pass its sampling period as dt "
            "(read_chunks reads uniformly sampled records, without a time column)",
            column=name), stacklevel=4)


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
    pending = ""
    lines: list[str] = []
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


def _text_pieces(p, shown, ext, inputs, outputs, chunk_size, delimiter, hint=False):
    import io as _io
    fh, _ = open_regular(shown, what="data file", max_bytes=None)
    with fh:
        raw = b""
        while True:             # the head: whole lines, up to the first data row at least
            try:
                more = fh.read(_HEAD_BYTES)
            except OSError as exc:
                raise FileReadError(f"{shown}: cannot read the file ({_reason(exc)})",
                                    path=shown) from None
            raw += more
            if not raw:
                raise FileReadError(f"file {shown} is empty", path=shown)
            head, whole = _whole_lines(raw, len(more) < _HEAD_BYTES)
            try:
                layout = _Table(shown, _decode(head, shown), ext, delimiter)
                break
            except FileReadError:
                # no data row in the head yet (a header and a first row of over 1 MiB):
                # read on, as read() does; a line too long is refused as it is there
                if whole or len(raw) > 2 * MAX_LINE_CHARS * 4:
                    raise
        utf16 = head.startswith((b"\xff\xfe", b"\xfe\xff"))
        layout.ascii_head = head.isascii()
        in_cols, out_cols, _ = _roles(layout, shown, inputs, outputs, None)
        cols = in_cols + out_cols
        in_names, out_names = layout.channel_names(in_cols), layout.channel_names(out_cols)
        n_in = len(in_cols)
        if hint:
            _hint_time(shown, layout.header or (), cols)
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
                if not any(_content(line) for line in lines):
                    continue
                values = piece.parse(cols)
                piece.check_finite(values, cols)
                yield values[:, :n_in], values[:, n_in:], in_names, out_names
        finally:
            text.detach()


def _whole_lines(raw: bytes, whole: bool) -> tuple[bytes, bool]:
    """``(the complete lines of raw, whole)``: all of ``raw`` when it is the whole file
    (``whole``), else up to its last line break (UTF-16 code units kept whole)."""
    if whole:
        return raw, True
    utf16 = raw.startswith((b"\xff\xfe", b"\xfe\xff"))
    newline = "\n".encode("utf-16-le" if raw.startswith(b"\xff\xfe") else "utf-16-be") \
        if utf16 else b"\n"
    cut = raw.rfind(newline)
    while utf16 and cut > 0 and (cut - 2) % 2:          # a UTF-16 code unit boundary
        cut = raw.rfind(newline, 0, cut)
    return (raw[: cut + len(newline)] if cut > 0 else raw), False


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
        if layout.ascii_head:
            # read() decodes a file that is not UTF-8 as Latin-1; the lines before were
            # ASCII, the same in both, so this block is Latin-1 as read() reads it
            text = buf.decode("latin-1")
        else:
            line = consumed + buf[:exc.start].count(b"\n") + 1
            raise FileReadError(f"{shown}, line {line}: the file is not UTF-8 text "
                                f"({exc.reason}), though its first lines are (with "
                                "characters beyond ASCII): save it as UTF-8 (or all of it "
                                "as Latin-1)", path=shown, line=line) from None
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    if not any(_content(line) for line in lines):
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


def _distinct(shown: str, in_cols, out_cols, what: str) -> None:
    """FileReadError when a column is selected twice, or as an input and an output
    (as the text reader refuses it)."""
    for role, cols in (("inputs", in_cols), ("outputs", out_cols)):
        twice = [c for k, c in enumerate(cols) if c in cols[:k]]
        if twice:
            raise FileReadError(f"{shown}: {what} {twice[0]!r} is selected twice in {role}",
                                path=shown, column=twice[0])
    both = [c for c in in_cols if c in out_cols]
    if both:
        raise FileReadError(f"{shown}: {what} {both[0]!r} is used both as an input and as "
                            "an output", path=shown, column=both[0])


def _column_indices(spec, role: str, n_columns: int, shown: str) -> list[int]:
    tokens = [int(t) if isinstance(t, str) and _INT_RE.fullmatch(t) else t
              for t in _tokens(spec, role, [])]
    out = []
    for tok in tokens:
        if not isinstance(tok, numbers.Integral) or not 0 <= int(tok) < n_columns:
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
    _distinct(shown, in_cols, out_cols, "column")
    in_names = [f"col{k}" for k in in_cols]
    out_names = [f"col{k}" for k in out_cols]
    labels = [f"column {k}" for k in in_cols + out_cols]
    for a in range(0, arr.shape[0], chunk_size):
        block = np.asarray(arr[a:a + chunk_size], dtype=np.float64)
        u, y = block[:, in_cols], block[:, out_cols]
        _check_rows_finite(np.hstack([u, y]), a, shown, labels, "NaN")
        yield u, y, in_names, out_names


def _check_rows_finite(values: np.ndarray, first: int, shown: str, labels, nan: str) -> None:
    """Refuse NaN or infinite ``values`` (rows ``first`` on of the file ``shown``;
    columns named by ``labels``), naming the file, the row in the file and the
    column, as the text reader does with lines (``nan`` says what a NaN is
    called: ``'NaN'``, or ``'null or NaN'`` for Parquet)."""
    found = first_non_finite(values)
    if found is None:
        return
    row, j, n_bad, n_rows = found
    value = values[row, j]
    text = nan if np.isnan(value) else ("inf" if value > 0 else "-inf")
    last = first + values.shape[0] - 1
    raise DataError(
        f"{shown}, row {first + row} (0-based), {labels[j]}: {text} is not a finite number "
        f"({n_bad} NaN or infinite value{'s' if n_bad != 1 else ''} in {n_rows} "
        f"row{'s' if n_rows != 1 else ''} of the selected columns among rows "
        f"{first}-{last}); remove or interpolate them before identification")


def _parquet_pieces(p, shown, inputs, outputs, chunk_size, hint=False):
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
    _distinct(shown, in_names, out_names, "column")
    labels = [f"column {name!r}" for name in in_names + out_names]
    if hint:
        _hint_time(shown, names, [names.index(name) for name in in_names + out_names])
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
        _check_rows_finite(block, start, shown, labels, "null or NaN")
        start += block.shape[0]
        yield block[:, :len(in_names)], block[:, len(in_names):], in_names, out_names
