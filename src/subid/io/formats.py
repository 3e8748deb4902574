"""Reading input/output records from files: :func:`read`.

Supported formats, chosen by the file extension:

``.csv``, ``.tsv``
    Delimited text. The delimiter is detected among ``,`` ``;`` and TAB
    unless ``delimiter`` is given.
``.txt``, ``.dat``
    Text with comma-, semicolon- or TAB-separated fields (TAB when every line
    has the same number of TABs, no data field holds spaces between values,
    and a field is empty or has spaces: a spreadsheet's "Text (Tab delimited)"
    with names such as ``Input [V]``), or fields separated by runs of spaces
    and TABs (the DaISy / MATLAB ``save -ascii`` style, trailing TABs and
    exponents such as ``1.0000000e+000`` included).
``.npz``
    NumPy archive (:func:`numpy.savez`); arrays are selected by key.
``.mat``
    MATLAB file up to version 7 (:func:`scipy.io.loadmat`); variables are
    selected by name. Version 7.3 (HDF5) files are read with h5py when it is
    installed (the ``hdf5`` extra: ``pip install ".[hdf5]"`` in the source folder).

Rules for text files
--------------------
* A header row is recognised when the first non-empty line holds a field
  that is not a value (a number, an ISO 8601 date-time or a spreadsheet marker
  such as ``#N/A``); columns can then be selected by header name. Without
  a header, columns are selected by 0-based index only. A column selected by
  index whose header cell is a value is refused (is that line a header or the
  first data row?). A line whose first non-blank character is ``#`` is a
  comment, unless it starts with a spreadsheet marker (``#N/A``, ``#VALUE!``,
  ...: a data row with a missing value, reported as such); a ``#`` elsewhere
  is part of a field (``Valve #1``). A header written as a comment line right
  before the data (``numpy.savetxt(..., header="t,u,y")``) is recognised too.
* Inputs and outputs are never guessed: both must be given.
* Column numbers in error messages are 0-based, like the indices accepted by
  ``inputs``/``outputs``; line numbers are 1-based, like in a text editor.
* Cells of columns that are not selected are not converted, so a file may
  hold text columns (dates, comments) besides the numeric ones.
* Numbers use a decimal point, or a decimal comma with ``decimal=','`` (the
  fields then delimited by ``;``, TAB or spaces).
* The time column holds numbers (seconds, or any time unit) or ISO 8601
  date-times (``2024-01-01 00:00:02``, ``2024-01-01T00:00:02.5``; with a UTC
  offset or ``Z``, converted to UTC, so a change of daylight-saving time with
  its offsets keeps the grid): date-times become seconds since the first one.

Every problem is reported as a :mod:`subid.errors` exception naming the file
and, for text files, the line and column at fault.
"""

from __future__ import annotations

from subid._validation import check_dt, checked_call
from subid.data import IOData
from subid.errors import DataError, FileReadError
from subid.io._common import (
    _TEXT_EXTENSIONS,
    SUPPORTED_EXTENSIONS,
    _as_path,
    _max_bytes,
    _read_bytes,
)
from subid.io._common import MAX_LINE_CHARS as MAX_LINE_CHARS
from subid.io.arrays import _from_arrays, _load_npz
from subid.io.chunks import STREAM_EXTENSIONS as STREAM_EXTENSIONS
from subid.io.chunks import read_chunks as read_chunks
from subid.io.chunks import read_inputs as read_inputs
from subid.io.fast_csv import _read_text_fast
from subid.io.fast_csv import fast_engine as fast_engine
from subid.io.mat import _load_mat
from subid.io.mat import mat_variables as mat_variables
from subid.io.mat import read_mat_model as read_mat_model
from subid.io.mat import write_mat_model as write_mat_model
from subid.io.text import _read_text, decimal_commas

# The readers of each format live beside this module (issue 24: one concern per module):
# text.py, fast_csv.py, arrays.py, mat.py, chunks.py; the names imported "as" themselves
# above stay importable from here.
__all__ = ["read", "read_inputs", "SUPPORTED_EXTENSIONS"]


# ---------------------------------------------------------------------------
# public entry point
# ---------------------------------------------------------------------------
@checked_call
def read(path, inputs=None, outputs=None, dt=None, time=None, *, delimiter=None,
         decimal=".", max_bytes=None) -> IOData:
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
        in the file, or else MATLAB's ``Ts`` (``iddata``'s name; -1 or 0 is
        no period), is used when neither ``dt`` nor ``time`` is given; a file
        holding both with different values is a ``FileReadError``.
    time : str or int, optional
        Column (text files) or array (``.npz``/``.mat``) holding the time
        stamps, which may be non-uniform; in a text file, numbers or ISO 8601
        date-times (read as seconds since the first one). ``.npz``/``.mat`` files use an
        array ``t`` by default when it exists and ``dt`` is not given. Give
        ``dt`` or ``time``, not both; with neither, ``dt = 1``.
    delimiter : str, optional
        Field delimiter of a text file, one character. ``" "`` means runs of
        spaces and TABs. Detected among ``,`` ``;`` and TAB when omitted.
    decimal : {'.', ','}
        Decimal separator of a text file's numbers: ``','`` for the exports of
        spreadsheets in many European locales (``0,125;1,5``). The field
        delimiter must then be another character: the one given, else the
        first of ``;``, TAB and runs of spaces on the first line.
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
        of range, missing ``inputs``/``outputs`` for a text file, ``dt`` and ``Ts``
        in a ``.npz``/``.mat`` file that differ, corrupted
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
    if decimal not in (".", ","):
        raise DataError(f"decimal must be '.' or ',', got {decimal!r}")
    if decimal == "," and ext not in _TEXT_EXTENSIONS:
        raise DataError(f"{shown}: decimal applies to text files only, not to {ext} files")
    max_bytes = _max_bytes(max_bytes)
    if ext in _TEXT_EXTENSIONS and decimal == ",":
        raw, delimiter = decimal_commas(_read_bytes(p, shown), shown, ext, delimiter)
        return _read_text(p, shown, ext, inputs, outputs, dt, time, delimiter, raw=raw)
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


