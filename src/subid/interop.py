"""Exchange with MATLAB (``.mat`` files) and pandas.

MATLAB
------
:func:`save_mat` writes the fields of MATLAB's ``ss(A, B, C, D, Ts)`` as
top-level variables of a MAT-file (version 5, readable by MATLAB and GNU
Octave): ``A``, ``B``, ``C``, ``D``, ``Ts`` (0 for continuous time, the
sampling period otherwise), ``InputName`` and ``OutputName`` (cell arrays of
strings). In MATLAB::

    S = load('model.mat');
    sys = ss(S.A, S.B, S.C, S.D, S.Ts, 'InputName', S.InputName, 'OutputName', S.OutputName);

and back, from a MATLAB model ``sys``::

    A = sys.A; B = sys.B; C = sys.C; D = sys.D; Ts = sys.Ts;
    InputName = sys.InputName; OutputName = sys.OutputName;
    save('model.mat', 'A', 'B', 'C', 'D', 'Ts', 'InputName', 'OutputName');

(or ``S = struct('A', sys.A, ...); save('model.mat', '-struct', 'S')``;
a file holding one struct variable with these fields, such as
``save('model.mat', 'S')``, is read too). MATLAB's ``Ts = -1`` (discrete
time, unspecified period) needs the ``dt`` argument of :func:`load_mat`.

pandas
------
:func:`iodata_from_pandas` and :func:`iodata_to_pandas` convert between
:class:`~subid.IOData` and a :class:`pandas.DataFrame` (one column per
channel, time in the index or in a column). pandas is optional and imported
only here.
"""

from __future__ import annotations

import logging
import numbers
import os

import numpy as np

from .data import IOData
from ._files import atomic_write
from .errors import DataError, ModelError
from .model import StateSpace

__all__ = ["save_mat", "load_mat", "iodata_from_pandas", "iodata_to_pandas"]

log = logging.getLogger(__name__)

_MAT_FIELDS = ("A", "B", "C", "D", "Ts")


# ---------------------------------------------------------------------------
# MATLAB
# ---------------------------------------------------------------------------
def save_mat(model, path) -> None:
    """Write a model as the fields of MATLAB's ``ss(A, B, C, D, Ts)``.

    Parameters
    ----------
    model : StateSpace
    path : str or os.PathLike
        The ``.mat`` file (written atomically: a temporary file renamed over
        ``path``).

    Notes
    -----
    Variables: ``A``, ``B``, ``C``, ``D`` (double matrices), ``Ts`` (0 for
    continuous time), ``InputName``, ``OutputName`` (1-by-m cell arrays of
    char), and ``subid_format`` (the string ``'subid.StateSpace'``, ignored
    by MATLAB), ``subid_hold`` for a model that assumes a first-order hold
    (:attr:`StateSpace.hold`; ignored by MATLAB). A model in innovation form adds ``K`` and ``NoiseVariance``,
    the names of the fields of MATLAB's ``idss`` (build it there with
    ``idss(A, B, C, D, K, zeros(n,1), Ts, 'NoiseVariance', NoiseVariance)``). Values are stored as IEEE doubles, so a round trip is exact.

    Raises
    ------
    ModelError
        ``model`` is not a StateSpace.
    OSError
        The file cannot be written.
    """
    import scipy.io
    if not isinstance(model, StateSpace):
        raise ModelError(f"save_mat expects a subid.StateSpace, got {type(model).__name__}")
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
    if model.K is not None:                      # MATLAB idss fields
        variables["K"] = np.array(model.K)
    if model.noise_cov is not None:
        variables["NoiseVariance"] = np.array(model.noise_cov)
    with atomic_write(path, "wb") as fh:
        scipy.io.savemat(fh, variables, format="5", do_compression=False, oned_as="row")


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


def load_mat(path, *, dt=None) -> StateSpace:
    """Read a model written by :func:`save_mat` or saved from MATLAB's ``ss`` fields.

    Parameters
    ----------
    path : str or os.PathLike
        MAT-file up to version 7 with the variables ``A``, ``B``, ``C``,
        ``D`` and ``Ts`` (optional: ``InputName``, ``OutputName``, and the
        ``idss`` fields ``K`` and ``NoiseVariance``), or a single
        struct variable with these fields.
    dt : float, optional
        Sampling period to use when ``Ts`` is -1 (MATLAB's "unspecified") or
        missing.

    Returns
    -------
    StateSpace
        ``dt = Ts`` (0: continuous time).

    Raises
    ------
    DataFileNotFoundError
        The file does not exist.
    FileReadError
        The file is not a readable MAT-file (or is a v7.3 HDF5 file).
    ModelError
        A variable is missing or malformed, or ``Ts`` is -1 and ``dt`` is not
        given.
    """
    from .io import mat_variables
    path = os.fsdecode(path) if isinstance(path, bytes) else os.fspath(path)
    # The same validated path as subid.read: regular files only, every MAT
    # structure checked before scipy's C reader sees it, bounded decompression.
    # mat_dtype=False: scipy's mat_dtype=True casts complex matrices to real,
    # silently dropping the imaginary part; complex values are refused below.
    raw = mat_variables(path, mat_dtype=False, what="model file")
    fields = {k: v for k, v in raw.items() if not k.startswith("__")}
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
    elif dt is not None and not np.isclose(dt, period, rtol=1e-12, atol=0):
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
        return StateSpace(A, B, C, D, period, input_names=inputs, output_names=outputs,
                          hold=hold or "zoh", **noise)
    except ModelError as exc:
        if str(exc).startswith(f"model file '{path}'"):
            raise
        raise ModelError(f"model file '{path}': {exc}") from None


# ---------------------------------------------------------------------------
# pandas
# ---------------------------------------------------------------------------
def _require_pandas():
    try:
        import pandas
    except ImportError:
        raise ImportError("pandas is not installed: pip install pandas") from None
    return pandas


def _as_names(spec, role: str) -> list:
    if isinstance(spec, str):
        return [s.strip() for s in spec.split(",")] if "," in spec else [spec]
    if spec is None:
        raise DataError(f"{role} must be given (a column name or a list of them)")
    try:
        names = list(spec)
    except TypeError:
        return [spec]
    if not names:
        raise DataError(f"{role} selects no column")
    return names


def _seconds(values, pd, what: str) -> np.ndarray:
    """Time stamps as float seconds (datetimes: from the first stamp)."""
    if pd.api.types.is_datetime64_any_dtype(values):
        stamps = pd.to_datetime(values)
        delta = stamps - stamps[0] if isinstance(stamps, pd.Index) else stamps - stamps.iloc[0]
        return np.asarray(delta / pd.Timedelta(seconds=1), dtype=float)
    if pd.api.types.is_timedelta64_dtype(values):
        return np.asarray(pd.to_timedelta(values) / pd.Timedelta(seconds=1), dtype=float)
    if pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values):
        return np.asarray(values, dtype=float)
    raise DataError(f"{what} must hold numbers, datetimes or timedeltas, not "
                    f"{getattr(values, 'dtype', type(values))}")


def iodata_from_pandas(df, inputs, outputs, time=None, *, dt=None) -> IOData:
    """An :class:`~subid.IOData` record from the columns of a DataFrame.

    Parameters
    ----------
    df : pandas.DataFrame
    inputs, outputs : str or list of str
        Column labels of the input and output channels (a comma-separated
        string is split). They become the channel names.
    time : str, optional
        Column holding the time stamps (numbers in seconds, datetimes or
        timedeltas; may be non-uniform). Without ``time`` and ``dt``, the
        index is used when it holds times: a DatetimeIndex or TimedeltaIndex
        (seconds from the first stamp) or a numeric index other than the
        default 0, 1, 2, ... range; otherwise ``dt = 1``.
    dt : float, optional
        Uniform sampling period (instead of time stamps).

    Returns
    -------
    IOData

    Raises
    ------
    ImportError
        pandas is not installed.
    DataError
        Unknown or repeated column, non-numeric or missing (NaN) values
        (the message names the column and the row label), both ``time`` and
        ``dt`` given, time stamps that do not increase.
    """
    pd = _require_pandas()
    if not isinstance(df, pd.DataFrame):
        raise DataError(f"expected a pandas DataFrame, got {type(df).__name__}")
    if len(df) == 0:
        raise DataError("the DataFrame has no rows")
    if time is not None and dt is not None:
        raise DataError("give either time (a column) or dt, not both")
    in_cols = _as_names(inputs, "inputs")
    out_cols = _as_names(outputs, "outputs")
    cols = in_cols + out_cols + ([time] if time is not None else [])
    available = list(df.columns)
    for c in cols:
        if c not in df.columns:
            raise DataError(f"the DataFrame has no column {c!r}; columns: "
                            f"{', '.join(map(repr, available[:40]))}")
    seen = set()
    for c in cols:
        if c in seen:
            raise DataError(f"column {c!r} is selected twice (as input, output or time)")
        seen.add(c)
    if not df.columns.is_unique:
        dup = [c for c in cols if (df.columns == c).sum() > 1]
        if dup:
            raise DataError(f"the DataFrame has several columns labelled {dup[0]!r}")

    def numeric(c):
        col = df[c]
        if pd.api.types.is_bool_dtype(col) or not pd.api.types.is_numeric_dtype(col):
            bad = pd.to_numeric(col, errors="coerce")
            rows = col.index[bad.isna() & col.notna()]
            where = f" (first at row {rows[0]!r}: {col.loc[rows[0]]!r})" if len(rows) else ""
            raise DataError(f"column {c!r} is not numeric (dtype {col.dtype}){where}")
        values = col.to_numpy(dtype=float, na_value=np.nan)
        bad = ~np.isfinite(values)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise DataError(f"column {c!r} has {int(bad.sum())} NaN or infinite value"
                            f"{'s' if bad.sum() != 1 else ''}, the first at row "
                            f"{df.index[k]!r}; remove or interpolate them")
        return values

    u = np.column_stack([numeric(c) for c in in_cols])
    y = np.column_stack([numeric(c) for c in out_cols])
    t = None
    if time is not None:
        t = _seconds(df[time], pd, f"time column {time!r}")
    elif dt is None:
        index = df.index
        if isinstance(index, (pd.DatetimeIndex, pd.TimedeltaIndex)):
            t = _seconds(index, pd, "the index")
        elif not isinstance(index, pd.RangeIndex) and pd.api.types.is_numeric_dtype(index) \
                and not pd.api.types.is_bool_dtype(index):
            t = np.asarray(index, dtype=float)
    return IOData(u, y, dt=dt, t=t, input_names=[str(c) for c in in_cols],
                  output_names=[str(c) for c in out_cols])


def iodata_to_pandas(data):
    """A DataFrame with one column per channel and the time stamps as index.

    Parameters
    ----------
    data : IOData

    Returns
    -------
    pandas.DataFrame
        Columns: the input names then the output names; index: ``data.t``
        named ``'time'``. :func:`iodata_from_pandas` reads it back (the index
        is taken as the time stamps).

    Raises
    ------
    ImportError
        pandas is not installed.
    DataError
        An input and an output share a name (a DataFrame needs distinct
        column labels).
    """
    pd = _require_pandas()
    if not isinstance(data, IOData):
        raise DataError(f"expected an IOData record, got {type(data).__name__}")
    both = set(data.input_names) & set(data.output_names)
    if both:
        raise DataError(f"the channel name(s) {sorted(both)} are used by an input and an "
                        "output; rename the channels first")
    columns = {name: data.u[:, k] for k, name in enumerate(data.input_names)}
    columns.update({name: data.y[:, k] for k, name in enumerate(data.output_names)})
    index = pd.Index(np.array(data.t, dtype=float), name="time")
    return pd.DataFrame(columns, index=index)
