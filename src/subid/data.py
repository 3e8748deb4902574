"""Input/output data records: :class:`IOData`."""

from __future__ import annotations

import numbers

import numpy as np

from ._validation import as_signal, check_dt, check_time_stamps, is_uniform
from .errors import DataError

__all__ = ["IOData"]


def _channel_names(names, count: int, prefix: str, which: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{k + 1}" for k in range(count))
    if isinstance(names, str):
        names = [names]
    names = tuple(str(n) for n in names)
    if len(names) != count:
        raise DataError(f"{which} has {len(names)} name{'s' if len(names) != 1 else ''} "
                        f"{list(names)} but {count} channel{'s' if count != 1 else ''}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise DataError(f"{which} repeats the channel name(s) {dup}; names must be unique")
    return names


def _writeable(values) -> bool:
    """False for a read-only numpy array (kept without a copy by IOData)."""
    return not isinstance(values, np.ndarray) or values.flags.writeable


class IOData:
    """A record of sampled inputs and outputs.

    Parameters
    ----------
    u : array_like, shape (N, n_inputs) or (N,)
        Input samples. Time is axis 0; a 1-D array is one channel.
    y : array_like, shape (N, n_outputs) or (N,)
        Output samples, same number of rows as ``u``.
    dt : float, optional
        Uniform sampling period. Give either ``dt`` or ``t``; with neither,
        ``dt = 1`` (time counted in samples).
    t : array_like, shape (N,), optional
        Strictly increasing time stamps, uniform or not. Non-uniform time
        stamps are kept as given.
    input_names, output_names : sequence of str, optional
        Channel names (default ``u1, u2, ...`` and ``y1, y2, ...``).
    copy : bool
        Copy writable arrays (default). ``False`` keeps read-only views of
        float64 C-contiguous arrays instead (see Notes).

    Notes
    -----
    Arrays are converted to read-only float64 arrays. A float64, C-contiguous
    array that is already read-only (``arr.flags.writeable`` False: the
    arrays of another record, of :func:`subid.read`, a read-only memory map)
    is not copied: the record keeps a read-only view of it, so a 1e7-sample
    record costs no second copy. Writable arrays are copied unless
    ``copy=False`` is given, which keeps a read-only view of them too (then
    do not change them afterwards). An ``IOData`` never changes after
    construction. Methods that transform data (``detrend``,
    slicing) return new objects.

    Examples
    --------
    >>> import numpy as np, subid
    >>> data = subid.IOData(np.ones((100, 2)), np.zeros(100), dt=0.1)
    >>> data.n_samples, data.n_inputs, data.n_outputs
    (100, 2, 1)
    """

    def __init__(self, u, y, dt=None, t=None, input_names=None, output_names=None, *,
                 copy=True):
        u = as_signal(u, "input u", copy=copy and _writeable(u))
        y = as_signal(y, "output y", copy=copy and _writeable(y))
        if u.shape[0] != y.shape[0]:
            hint = ""
            if u.shape[1] == y.shape[0] or y.shape[1] == u.shape[0]:
                hint = " (time is axis 0: was one of them passed transposed?)"
            raise DataError(f"input u has {u.shape[0]} samples but output y has "
                            f"{y.shape[0]}; they must have the same length{hint}")
        if u.shape[0] == 0:
            raise DataError("the record is empty (0 samples)")
        n = u.shape[0]
        if dt is not None and t is not None:
            raise DataError("give either the sampling period dt or the time stamps t, not both")
        if t is not None:
            t = check_time_stamps(t, n).view()      # never the caller's array's flags
            steps = np.diff(t)
            if n > 1 and is_uniform(steps):
                self._dt = float(np.mean(steps))
            else:
                self._dt = None
            self._t = t
            self._t0 = float(t[0])
        else:
            self._dt = 1.0 if dt is None else check_dt(dt)
            self._t = None
            self._t0 = 0.0
        for arr in (u, y):
            arr.setflags(write=False)
        if self._t is not None:
            self._t.setflags(write=False)
        self._u = u
        self._y = y
        self.input_names = _channel_names(input_names, u.shape[1], "u", "input u")
        self.output_names = _channel_names(output_names, y.shape[1], "y", "output y")
        self.u_offset = None
        self.y_offset = None

    # -- basic properties -------------------------------------------------
    @property
    def u(self) -> np.ndarray:
        """Inputs, shape (n_samples, n_inputs), read-only."""
        return self._u

    @property
    def y(self) -> np.ndarray:
        """Outputs, shape (n_samples, n_outputs), read-only."""
        return self._y

    @property
    def n_samples(self) -> int:
        return self._u.shape[0]

    @property
    def n_inputs(self) -> int:
        return self._u.shape[1]

    @property
    def n_outputs(self) -> int:
        return self._y.shape[1]

    @property
    def dt(self) -> float | None:
        """Uniform sampling period, or None when the time stamps are non-uniform."""
        return self._dt

    @property
    def is_uniform(self) -> bool:
        return self._dt is not None

    @property
    def has_time_stamps(self) -> bool:
        """True when the record was given explicit time stamps ``t`` (uniform
        or not) rather than a sampling period ``dt``."""
        return self._t is not None

    @property
    def t(self) -> np.ndarray:
        """Time stamps, shape (n_samples,)."""
        if self._t is not None:
            return self._t
        t = self._t0 + self._dt * np.arange(self.n_samples)
        t.setflags(write=False)
        return t

    def __len__(self) -> int:
        return self.n_samples

    def __repr__(self) -> str:
        timing = f"dt={self._dt:g}" if self._dt is not None else "non-uniform t"
        return (f"IOData(n_samples={self.n_samples}, inputs={list(self.input_names)}, "
                f"outputs={list(self.output_names)}, {timing})")

    def _repr_html_(self) -> str:
        """Summary for Jupyter: samples, timing, per-channel statistics and sparklines."""
        from ._repr import iodata_html
        return iodata_html(self)

    # -- interoperability -------------------------------------------------
    @classmethod
    def from_pandas(cls, df, inputs, outputs, time=None, *, dt=None) -> "IOData":
        """Record from DataFrame columns (:func:`subid.interop.iodata_from_pandas`)."""
        return iodata_from_pandas(df, inputs, outputs, time=time, dt=dt)

    def to_pandas(self):
        """DataFrame with one column per channel and time as the index
        (:func:`subid.interop.iodata_to_pandas`)."""
        return iodata_to_pandas(self)

    # -- derived records --------------------------------------------------
    def _derive(self, u, y, *, t=None, dt=None, t0=0.0) -> "IOData":
        out = IOData.__new__(IOData)
        u = np.ascontiguousarray(u)
        y = np.ascontiguousarray(y)
        u.setflags(write=False)
        y.setflags(write=False)
        out._u, out._y = u, y
        out._dt, out._t, out._t0 = dt, t, t0
        if t is not None:
            t.setflags(write=False)
        out.input_names, out.output_names = self.input_names, self.output_names
        out.u_offset, out.y_offset = self.u_offset, self.y_offset
        return out

    def __getitem__(self, index) -> "IOData":
        """Samples ``index`` (a slice of sample indices) as a new record."""
        if not isinstance(index, slice):
            raise DataError("IOData is indexed by a slice of samples, e.g. data[100:500]; "
                            f"got {type(index).__name__}")
        start, stop, step = index.indices(self.n_samples)
        if step <= 0:
            raise DataError("IOData slices must go forward in time (positive step)")
        rows = range(start, stop, step)
        if len(rows) == 0:
            raise DataError(f"the slice {index} selects no samples out of {self.n_samples}")
        sl = slice(start, stop, step)
        if self._t is not None:
            t = np.ascontiguousarray(self._t[sl])
            return self._derive(self._u[sl], self._y[sl], t=t, dt=self._dt * step
                                if self._dt is not None else None, t0=float(t[0]))
        return self._derive(self._u[sl], self._y[sl], dt=self._dt * step,
                            t0=self._t0 + start * self._dt)

    def split(self, fraction: float = 0.7) -> tuple["IOData", "IOData"]:
        """Split into an estimation part and a validation part.

        Parameters
        ----------
        fraction : float
            Share of the samples, from the start of the record, that goes into
            the first (estimation) part; the rest is the validation part.
        """
        if isinstance(fraction, bool) or not isinstance(fraction, numbers.Real) \
                or not 0 < fraction < 1:
            raise DataError(f"split fraction must be a number strictly between 0 and 1, "
                            f"got {fraction!r}")
        cut = int(round(fraction * self.n_samples))
        if cut < 1 or cut > self.n_samples - 1:
            raise DataError(f"splitting {self.n_samples} samples at fraction {fraction} "
                            "leaves one part empty")
        return self[:cut], self[cut:]

    def detrend(self, kind: str = "constant") -> "IOData":
        """Remove the mean (``kind='constant'``) or a least-squares line
        (``kind='linear'``) from every channel.

        The removed offsets are kept in ``u_offset`` and ``y_offset`` (the
        channel means for ``'constant'``; the (intercept, slope) rows for
        ``'linear'``, as functions of the time stamps).
        """
        if kind == "constant":
            u_off, y_off = self._u.mean(axis=0), self._y.mean(axis=0)
            u, y = self._u - u_off, self._y - y_off
        elif kind == "linear":
            t = self.t - self.t[0]
            basis = np.column_stack([np.ones_like(t), t])
            coef, *_ = np.linalg.lstsq(basis, np.hstack([self._u, self._y]), rcond=None)
            resid = np.hstack([self._u, self._y]) - basis @ coef
            u, y = resid[:, :self.n_inputs], resid[:, self.n_inputs:]
            u_off, y_off = coef[:, :self.n_inputs], coef[:, self.n_inputs:]
        else:
            raise DataError(f"detrend kind must be 'constant' or 'linear', got {kind!r}")
        out = self._derive(u, y, t=self._t, dt=self._dt, t0=self._t0)
        out.u_offset, out.y_offset = u_off, y_off
        return out


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
