"""Input/output data records: :class:`IOData`."""

from __future__ import annotations

import numbers

import numpy as np

from subid._validation import (
    as_signal,
    check_bool,
    check_dt,
    check_orientation,
    check_time_stamps,
    checked_call,
    grid_step,
    is_uniform,
    same_period,
    stamp_resolution,
)
from subid.errors import DataError

__all__ = ["IOData", "merge"]


def _channel_names(names, count: int, prefix: str, which: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{k + 1}" for k in range(count))
    if isinstance(names, str):
        names = [names]
    try:
        names = tuple(str(n) for n in names)
    except TypeError:
        raise DataError(f"{which} names must be a list of strings, one per channel, got "
                        f"{names!r}"[:300]) from None
    if len(names) != count:
        raise DataError(f"{which} has {len(names)} name{'s' if len(names) != 1 else ''} "
                        f"{list(names)} but {count} channel{'s' if count != 1 else ''}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise DataError(f"{which} repeats the channel name(s) {dup}; names must be unique")
    return names


def _pandas_names(values):
    """The channel names a pandas DataFrame (its column labels) or named Series carries,
    else None (arrays; a DataFrame's default 0, 1, ... labels; an unnamed Series)."""
    columns = getattr(values, "columns", None)
    if columns is not None and type(values).__module__.startswith("pandas"):
        labels = list(columns)
        return None if labels == list(range(len(labels))) else [str(c) for c in labels]
    name = getattr(values, "name", None)
    if name is not None and type(values).__module__.startswith("pandas") \
            and getattr(values, "ndim", 0) == 1:
        return [str(name)]
    return None


def _check_pandas_index(u, y, *, timed: bool) -> None:
    """Refuse pandas inputs and outputs whose indexes differ (samples are paired by
    position, so rows of different times would be paired); warn (SamplingWarning) when
    a time-like index (date-times, durations, floats) is left out because neither ``t``
    nor ``dt`` is given (time is then counted in samples)."""
    indexes = [(who, v.index) for who, v in (("u", u), ("y", y))
               if type(v).__module__.startswith("pandas")
               and getattr(v, "index", None) is not None]
    if len(indexes) == 2 and not indexes[0][1].equals(indexes[1][1]):
        a, b = indexes[0][1], indexes[1][1]
        k = next((k for k in range(min(len(a), len(b))) if a[k] != b[k]), min(len(a), len(b)))
        where = (f"row {k}: {a[k]!r} against {b[k]!r}" if k < min(len(a), len(b)) else
                 f"{len(a)} against {len(b)} rows")
        raise DataError(f"u and y are pandas objects with different indexes ({where}); "
                        "IOData pairs samples by position, not by label: align them first "
                        "(u, y = u.align(y, join='inner', axis=0)), or pass u.to_numpy() and "
                        "y.to_numpy() if the positions match")
    if timed or not indexes:
        return
    who, index = indexes[0]
    kind = getattr(index, "inferred_type", "")
    if kind.startswith(("datetime", "timedelta")) or kind == "floating":
        import warnings

        from subid.errors import SamplingWarning
        warnings.warn(SamplingWarning(
            f"{who} has a time-like index ({type(index).__name__}) but no time stamps (t) "
            "or sampling period (dt) were given, so time is counted in samples (dt = 1): "
            f"pass t={who}.index to take the time from it, or dt="), stacklevel=4)


def not_a_record(value, who: str, *, time: str = "dt=...") -> DataError:
    """The :class:`DataError` for ``value`` passed where ``who`` (a function's name, or
    ``'data'``) expects an :class:`IOData` record, with how to make one: from a pandas
    DataFrame's columns (which then name the channels), or from arrays (``time``: the
    keyword the caller's data need, ``'dt=...'`` or ``'t=... or dt=...'``)."""
    kind = type(value).__name__
    if kind == "DataFrame":
        how = ("make one from its columns: subid.IOData(df[input_columns], "
               f"df[output_columns], {time}) (the column labels name the channels), or "
               "subid.interop.iodata_from_pandas(df, inputs, outputs, time=...)")
    else:
        how = f"wrap arrays as subid.IOData(u, y, {time})"
    subject = "data must be" if who == "data" else f"{who} expects"
    return DataError(f"{subject} an IOData record, got {kind}; {how}")


def _writeable(values) -> bool:
    """False for a read-only numpy array (kept without a copy by IOData)."""
    return not isinstance(values, np.ndarray) or values.flags.writeable


def _shares_memory(a: np.ndarray, values) -> bool:
    """True when ``a`` may share memory with the caller's ``values`` (any array-like)."""
    try:
        return bool(np.shares_memory(a, np.asarray(values)))
    except (TypeError, ValueError):
        return True


def column_sums(a: np.ndarray) -> np.ndarray:
    """``a.sum(axis=0)`` of a (samples x channels) array, channel by channel: numpy's
    axis-0 reduction of a C-ordered array with few columns is ~25x slower."""
    return np.array([column.sum() for column in a.T])


def minus_columns(a: np.ndarray, offsets, out=None) -> np.ndarray:
    """``a - offsets`` (one offset per column of a (samples x channels) array) into
    ``out`` (default: a new array; ``a`` itself is allowed), channel by channel:
    numpy's broadcast over few columns is ~5x slower."""
    out = np.empty(a.shape) if out is None else out
    for k, offset in enumerate(np.broadcast_to(offsets, a.shape[1:])):
        np.subtract(a[:, k], offset, out=out[:, k])
    return out


def column_std(y: np.ndarray, block: int = 65536) -> np.ndarray:
    """``y.std(axis=0)`` computed in blocks of rows (two passes), without the N x
    channels temporary numpy's ``std`` allocates (160 MB for 10^7 samples of 2 outputs),
    and channel by channel (numpy's axis-0 reductions were 0.38 s of a 1.6 s call)."""
    n = y.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        if n <= block:
            std = y.std(axis=0)
        else:
            mean = column_sums(y) / n            # channel by channel: see column_sums
            ss = sum(np.array([d @ d for d in minus_columns(y[k:k + block], mean).T])
                     for k in range(0, n, block))
            std = np.sqrt(ss / n)
    if n and not np.isfinite(std).all() and np.isfinite(y).all():
        # squares of values near 1e154 overflow: the spread of the channels divided by
        # their largest magnitudes, scaled back (the weights 1/std of the initial-state
        # regressions were 1/inf = 0 there, and x0 silently zero)
        peak = np.abs(y).max(axis=0)
        peak = np.where(peak > 0, peak, 1.0)
        return column_std(y / peak, block) * peak
    return std



def column_spread(y: np.ndarray, block: int = 65536) -> np.ndarray:
    """:func:`column_std` with a constant channel's 0 taken as 1: the scale by which the
    methods divide (or weigh) each channel so that its units do not matter."""
    std = column_std(y, block)
    return np.where(std > 0, std, 1.0)

class IOData:
    """A record of sampled inputs and outputs.

    Parameters
    ----------
    u : array_like, shape (N, n_inputs) or (N,)
        Input samples. Time is axis 0; a 1-D array is one channel. An array
        that looks transposed (more channels than samples, and more than
        100 channels; or time stamps ``t`` as long as its second axis) raises
        :class:`~subid.errors.DataError`: it is never transposed silently.
    y : array_like, shape (N, n_outputs) or (N,)
        Output samples, same number of rows as ``u``. Pandas ``u`` and ``y`` must
        have the same index (samples are paired by position); a time-like index
        (date-times, durations, floats) given neither ``t`` nor ``dt`` gives a
        :class:`~subid.errors.SamplingWarning`.
    dt : float, optional
        Uniform sampling period. Give either ``dt`` or ``t``; with neither,
        ``dt = 1`` (time counted in samples).
    t : array_like, shape (N,), optional
        Strictly increasing time stamps, uniform or not. Non-uniform time
        stamps are kept as given. Uniform ones give ``dt``: their mean step,
        rounded to the decimals the stamps are written with (``0.05``, not
        ``0.049999999999999996``, for stamps ``0, 0.05, 0.1`` read from a file).
        Stamps written at a limited precision (30 Hz logged in milliseconds,
        float32) are uniform when they lie within it of a uniform grid
        (:func:`subid._validation.stamp_resolution`); ``dt`` is then their mean step.
        Date-times (``numpy.datetime64``, a pandas ``DatetimeIndex``, ``datetime``
        objects; time-zone aware ones in UTC) count in seconds from the first;
        durations (``timedelta64``) in seconds.
    input_names, output_names : sequence of str, optional
        Channel names (default: the column labels of a pandas DataFrame, the name of
        a pandas Series, else ``u1, u2, ...`` and ``y1, y2, ...``).
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

    A record may hold several experiments (:func:`subid.merge`):
    ``n_experiments``, ``experiment_ranges`` (their rows), ``experiment(k)``
    and ``experiments`` give them; slicing keeps the borders inside the
    slice, and the methods never join two experiments.

    Examples
    --------
    >>> import numpy as np, subid
    >>> data = subid.IOData(np.ones((100, 2)), np.zeros(100), dt=0.1)
    >>> data.n_samples, data.n_inputs, data.n_outputs
    (100, 2, 1)
    """

    @checked_call
    def __init__(self, u, y, dt=None, t=None, input_names=None, output_names=None, *,
                 copy=True):
        # a DataFrame's column labels (a named Series's name) name the channels
        copy = check_bool(copy, "copy")
        _check_pandas_index(u, y, timed=dt is not None or t is not None)
        input_names = _pandas_names(u) if input_names is None else input_names
        output_names = _pandas_names(y) if output_names is None else output_names
        u = as_signal(u, "input u", copy=copy and _writeable(u))
        y = as_signal(y, "output y", copy=copy and _writeable(y))
        check_orientation(u, "input u", "u")
        check_orientation(y, "output y", "y")
        stamps = np.shape(t)[0] if t is not None and np.ndim(t) == 1 else None
        if stamps is not None and stamps not in (u.shape[0], y.shape[0]) \
                and stamps in (u.shape[1], y.shape[1]):
            raise DataError(f"the {stamps} time stamps t match the second axis of the signals "
                            f"(u {u.shape}, y {y.shape}), not their rows: time must be axis "
                            "0; pass u.T and y.T")
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
            given = t
            t = check_time_stamps(t, n).view()      # never the caller's array's flags
            if copy and _writeable(given) and _shares_memory(t, given):
                t = t.copy()                        # the caller may change theirs later
            steps = np.diff(t)
            if n > 1 and is_uniform(steps, resolution=stamp_resolution(t)):
                self._dt = grid_step(t, steps)      # to the precision of the stamps
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
        self._starts = (0,)
        self._t0s = (self._t0,)
        self._offsets_per_experiment = False
        self.experiment_names = ("exp1",)

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
        """Time stamps, shape (n_samples,). For several experiments
        (:func:`subid.merge`), each experiment's own time stamps in turn (they
        restart at every experiment's start time, so they need not increase)."""
        if self._t is not None:
            return self._t
        if self.n_experiments > 1:
            t = np.concatenate([t0 + self._dt * np.arange(b - a) for t0, (a, b)
                                in zip(self._t0s, self.experiment_ranges)])
            t.setflags(write=False)
            return t
        t = self._t0 + self._dt * np.arange(self.n_samples)
        t.setflags(write=False)
        return t

    def __len__(self) -> int:
        return self.n_samples

    # -- several experiments (subid.merge) ---------------------------------
    @property
    def n_experiments(self) -> int:
        """Number of experiments (1 unless the record comes from :func:`subid.merge`)."""
        return len(self._starts)

    @property
    def experiment_ranges(self) -> tuple[tuple[int, int], ...]:
        """``(start, stop)`` sample indices of every experiment in ``u`` and ``y``."""
        stops = self._starts[1:] + (self.n_samples,)
        return tuple((int(a), int(b)) for a, b in zip(self._starts, stops))

    def experiment(self, index) -> "IOData":
        """Experiment ``index`` (an int, or its name) as a single-experiment record
        (MATLAB ``getexp``). Its offsets are that experiment's row of ``u_offset``
        and ``y_offset`` when the merged record was detrended per experiment."""
        if isinstance(index, str):
            if index not in self.experiment_names:
                raise DataError(f"no experiment named {index!r}; the experiments are "
                                f"{list(self.experiment_names)}")
            index = self.experiment_names.index(index)
        if isinstance(index, bool) or not isinstance(index, numbers.Integral) \
                or not 0 <= int(index) < self.n_experiments:
            raise DataError(f"experiment index must be an integer in 0..{self.n_experiments - 1}"
                            f" (or a name), got {index!r}")
        index = int(index)
        if self.n_experiments == 1:
            return self
        a, b = self.experiment_ranges[index]
        out = self._derive(self._u[a:b], self._y[a:b], dt=self._dt, t0=self._t0s[index])
        out.experiment_names = (self.experiment_names[index],)
        if self._offsets_per_experiment:
            out.u_offset, out.y_offset = self.u_offset[index], self.y_offset[index]
        out._offsets_per_experiment = False
        return out

    @property
    def experiments(self) -> tuple["IOData", ...]:
        """Every experiment as a single-experiment record."""
        return tuple(self.experiment(k) for k in range(self.n_experiments))

    def __repr__(self) -> str:
        timing = f"dt={self._dt:g}" if self._dt is not None else "non-uniform t"
        exps = f", experiments={self.n_experiments}" if self.n_experiments > 1 else ""
        return (f"IOData(n_samples={self.n_samples}, inputs={list(self.input_names)}, "
                f"outputs={list(self.output_names)}, {timing}{exps})")

    def _repr_html_(self) -> str:
        """Summary for Jupyter: samples, timing, per-channel statistics and sparklines."""
        from subid._repr import iodata_html
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
    def _derive(self, u, y, *, t=None, dt=None, t0=0.0, starts=(0,), t0s=None,
                names=None) -> "IOData":
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
        out._starts = tuple(int(k) for k in starts)
        out._t0s = (t0,) if t0s is None else tuple(float(v) for v in t0s)
        out.experiment_names = ("exp1",) if names is None else tuple(names)
        out._offsets_per_experiment = self._offsets_per_experiment and len(out._starts) > 1
        return out

    def __getitem__(self, index) -> "IOData":
        """Samples ``index`` (a slice of sample indices) as a new record."""
        if not isinstance(index, slice):
            raise DataError("IOData is indexed by a slice of samples, e.g. data[100:500]; "
                            f"got {type(index).__name__}")
        try:
            start, stop, step = index.indices(self.n_samples)
        except (TypeError, ValueError):              # a float bound, a step of 0
            raise DataError(f"IOData slices take integer sample indices and a positive step "
                            f"(e.g. data[100:500], data[::2]); got {index}") from None
        if step <= 0:
            raise DataError("IOData slices must go forward in time (positive step)")
        rows = range(start, stop, step)
        if len(rows) == 0:
            raise DataError(f"the slice {index} selects no samples out of {self.n_samples}")
        sl = slice(start, stop, step)
        if self.n_experiments > 1:
            return self._slice_experiments(start, stop, step)
        if self._t is not None:
            t = np.ascontiguousarray(self._t[sl])
            out = self._derive(self._u[sl], self._y[sl], t=t, dt=self._dt * step
                               if self._dt is not None else None, t0=float(t[0]))
        else:
            out = self._derive(self._u[sl], self._y[sl], dt=self._dt * step,
                               t0=self._t0 + start * self._dt)
        return out._moved_lines(out._t0 - self._t0)

    def _moved_lines(self, shift) -> "IOData":
        """This record (a slice) with the lines removed by ``detrend('linear')``, whose
        intercepts were ``shift`` seconds before its first stamp (one shift per
        experiment for lines removed per experiment), moved to that first stamp: the
        intercepts of a record are at its first stamp (each experiment's)."""
        if offset_kind(self) != "linear":
            return self
        shift = np.reshape(shift, np.shape(shift) + (1,))
        for name in ("u_offset", "y_offset"):
            lines = np.array(getattr(self, name), dtype=float)
            lines[..., 0, :] += shift * lines[..., 1, :]
            setattr(self, name, lines)
        return self

    def _slice_experiments(self, start: int, stop: int, step: int) -> "IOData":
        """Samples ``start:stop`` of a record of several experiments: the borders
        inside the slice are kept; experiments left out are dropped."""
        kept = [(k, max(a, start), min(b, stop)) for k, (a, b)
                in enumerate(self.experiment_ranges) if max(a, start) < min(b, stop)]
        if step != 1 and len(kept) > 1:
            raise DataError("a slice with a step over several experiments would mix their "
                            "samples; slice each experiment (data.experiment(k)[::step]) and "
                            "merge them again")
        if len(kept) == 1:
            k, a, b = kept[0]
            return self.experiment(k)[a - self.experiment_ranges[k][0]:
                                      b - self.experiment_ranges[k][0]:step]
        ks = [k for k, _, _ in kept]
        starts = np.cumsum([0] + [b - a for _, a, b in kept[:-1]])
        t0s = [self._t0s[k] + (a - self.experiment_ranges[k][0]) * self._dt for k, a, _ in kept]
        out = self._derive(self._u[start:stop], self._y[start:stop], dt=self._dt,
                           t0=t0s[0], starts=starts, t0s=t0s,
                           names=[self.experiment_names[k] for k in ks])
        if self._offsets_per_experiment:
            out.u_offset = np.asarray(self.u_offset)[ks]
            out.y_offset = np.asarray(self.y_offset)[ks]
            out._moved_lines(np.array(t0s) - np.array(self._t0s)[ks])
        else:
            out._moved_lines(t0s[0] - self._t0)
        return out

    def scaled(self, *, inputs=None, outputs=None) -> "IOData":
        """The record in other units: each input and output channel multiplied by a
        positive factor (``inputs``, ``outputs``: one per channel; None leaves them).
        Time stamps, experiments, names and the offsets of :meth:`detrend` (scaled
        alike) are kept.

        Parameters
        ----------
        inputs : array_like of shape (n_inputs,), optional
        outputs : array_like of shape (n_outputs,), optional

        Returns
        -------
        IOData

        Examples
        --------
        >>> import numpy as np, subid
        >>> d = subid.IOData(np.ones((3, 1)), np.arange(6.0).reshape(3, 2), dt=0.1)
        >>> d.scaled(outputs=[1.0, 1e-3]).y[2]
        array([4.   , 0.005])
        """
        factors = []
        for name, given, count in (("inputs", inputs, self.n_inputs),
                                   ("outputs", outputs, self.n_outputs)):
            try:
                f = np.ones(count) if given is None else \
                    np.asarray(given, dtype=float).ravel()
            except (TypeError, ValueError, OverflowError):
                f = np.full(0, np.nan)                      # refused below
            if f.shape != (count,) or not (np.isfinite(f).all() and (f > 0).all()):
                raise DataError(f"scaled({name}=...) needs {count} positive finite "
                                f"factor{'s' if count != 1 else ''}, "
                                f"one per channel; got {given!r}"[:300])
            factors.append(f)
        fu, fy = factors
        with np.errstate(over="ignore"):
            u, y = self._u * fu, self._y * fy
            u_off = None if self.u_offset is None else np.asarray(self.u_offset) * fu
            y_off = None if self.y_offset is None else np.asarray(self.y_offset) * fy
        for name, values, names, f in (("inputs", (u, u_off), self.input_names, fu),
                                       ("outputs", (y, y_off), self.output_names, fy)):
            over = [np.flatnonzero(~np.isfinite(v).reshape(-1, len(names)).all(axis=0))
                    for v in values if v is not None]
            if any(k.size for k in over):
                k = int(np.concatenate(over).min())
                raise DataError(f"scaled({name}=...): the factor {f[k]:.6g} of channel "
                                f"{names[k]!r} takes its values (or the offsets removed by "
                                "detrend) beyond the double-precision range (1.8e308); use "
                                "a smaller factor")
        out = self._derive(u, y, t=self._t, dt=self._dt, t0=self._t0, starts=self._starts,
                           t0s=self._t0s, names=self.experiment_names)
        out.u_offset, out.y_offset = u_off, y_off
        return out

    def split(self, fraction: float = 0.7) -> tuple["IOData", "IOData"]:
        """Split into an estimation part and a validation part.

        Parameters
        ----------
        fraction : float
            Share of the samples, from the start of the record, that goes into
            the first (estimation) part; the rest is the validation part. With
            several experiments the cut is at that share of all the samples
            (the borders on each side are kept).
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

    def detrend(self, kind: str = "constant", *, per_experiment: bool = True) -> "IOData":
        """Remove the mean (``kind='constant'``) or a least-squares line
        (``kind='linear'``) from every channel.

        The removed offsets are kept in ``u_offset`` and ``y_offset`` (the
        channel means for ``'constant'``; the (intercept, slope) rows for
        ``'linear'``, as functions of the time from the record's first stamp; a
        slice's intercepts are moved to its own first stamp). Detrending a detrended
        record again adds what it removes to these offsets, so the operating point is
        kept (a constant and a line add up to a line).

        A record of several experiments (:func:`subid.merge`) is detrended
        experiment by experiment, as MATLAB's ``detrend`` does: each
        experiment loses its own mean (or line), and ``u_offset``/``y_offset``
        get one leading row per experiment (shape ``(n_experiments,
        n_channels)`` for ``'constant'``), i.e. the model relates the
        deviations from each experiment's own operating point.
        ``per_experiment=False`` (``'constant'`` only) removes one mean over
        all the samples instead: one operating point for every experiment,
        with offsets of shape ``(n_channels,)``.
        """
        per_experiment = check_bool(per_experiment, "per_experiment")
        if self.n_experiments > 1 and per_experiment:
            if kind not in ("constant", "linear"):
                raise DataError(f"detrend kind must be 'constant' or 'linear', got {kind!r}")
            parts = [e.detrend(kind) for e in self.experiments]     # offsets accumulate
            out = self._derive(np.vstack([p.u for p in parts]), np.vstack([p.y for p in parts]),
                               dt=self._dt, t0=self._t0, starts=self._starts, t0s=self._t0s,
                               names=self.experiment_names)
            out.u_offset = np.stack([p.u_offset for p in parts])
            out.y_offset = np.stack([p.y_offset for p in parts])
            out._offsets_per_experiment = True
            return out
        if self.n_experiments > 1 and kind != "constant":
            raise DataError("per_experiment=False removes one constant from all the "
                            "experiments; a linear trend is fitted per experiment "
                            "(per_experiment=True)")
        if kind == "constant":
            return self._less_offsets(self._u.mean(axis=0), self._y.mean(axis=0))
        if kind == "linear":
            t = self.t - self.t[0]
            basis = np.column_stack([np.ones_like(t), t])
            coef, *_ = np.linalg.lstsq(basis, np.hstack([self._u, self._y]), rcond=None)
            resid = np.hstack([self._u, self._y]) - basis @ coef
            u, y = resid[:, :self.n_inputs], resid[:, self.n_inputs:]
            u_off, y_off = coef[:, :self.n_inputs], coef[:, self.n_inputs:]
        else:
            raise DataError(f"detrend kind must be 'constant' or 'linear', got {kind!r}")
        return self._with_offsets(u, y, u_off, y_off)

    def _less_offsets(self, u_off, y_off) -> "IOData":
        """The record less the constant offsets ``u_off``, ``y_off`` (its means, or
        those another run removed: ``subid track --resume``), kept as its offsets."""
        return self._with_offsets(self._u - u_off, self._y - y_off, u_off, y_off)

    def _with_offsets(self, u, y, u_off, y_off) -> "IOData":
        """The record ``u``, ``y`` less the offsets ``u_off``, ``y_off``, added to those
        removed before (a detrended record detrended again keeps its operating point:
        a constant on top of a line, or a line on top of a constant, is a line)."""
        out = self._derive(u, y, t=self._t, dt=self._dt, t0=self._t0, starts=self._starts,
                           t0s=self._t0s, names=self.experiment_names)
        per = self._offsets_per_experiment
        if self.u_offset is not None:
            u_off = _summed_offsets(self.u_offset, u_off, per)
            y_off = _summed_offsets(self.y_offset, y_off, per)
        out.u_offset, out.y_offset = u_off, y_off
        out._offsets_per_experiment = per and self.u_offset is not None
        return out


def _summed_offsets(old, new, per_experiment: bool) -> np.ndarray:
    """Offsets ``old`` (of :meth:`IOData.detrend`; one leading row per experiment when
    ``per_experiment``) plus ``new`` (one record's: a constant row, or (intercept, slope)
    rows): a line when either is one."""
    old, new = np.asarray(old, dtype=float), np.asarray(new, dtype=float)
    if old.ndim == 2 + per_experiment or new.ndim == 2:
        def line(c):
            return np.stack([c, np.zeros_like(c)], axis=-2)
        old = old if old.ndim == 2 + per_experiment else line(old)
        new = new if new.ndim == 2 else line(new)
    return old + new


def require_single_experiment(data, method: str) -> None:
    """Raise a clear :class:`DataError` when ``method`` gets a record of several
    experiments it cannot use apart."""
    if isinstance(data, IOData) and data.n_experiments > 1:
        raise DataError(f"{method} does not support several experiments (this record merges "
                        f"{data.n_experiments}); it would join them as if contiguous. Use a "
                        "discrete-time subspace method (ls_subspace, moesp, n4sid), or pass "
                        "one experiment: data.experiment(k)")


def offset_kind(record):
    """What :meth:`IOData.detrend` removed from ``record``: ``None`` (nothing),
    ``'constant'`` (means) or ``'linear'`` (straight lines: an intercept and a slope per
    channel, one pair per experiment when each experiment lost its own)."""
    if record.u_offset is None:
        return None
    per_experiment = 1 if record._offsets_per_experiment else 0
    return "constant" if np.ndim(record.u_offset) == 1 + per_experiment else "linear"


def check_same_channels(record, first, what: str, reference: str) -> None:
    """:class:`~subid.errors.DataError` unless ``record`` has the channels of ``first``
    (names and order; any objects with ``input_names`` and ``output_names``): the
    records of one identification (:func:`merge`, the files of
    :func:`subid.identify_file` and :func:`subid.distributed.identify_files`), whose
    columns chosen by position would else mix outputs into inputs silently."""
    if tuple(record.input_names) != tuple(first.input_names) or \
            tuple(record.output_names) != tuple(first.output_names):
        raise DataError(f"{what} has channels {list(record.input_names)} -> "
                        f"{list(record.output_names)} but {reference} has "
                        f"{list(first.input_names)} -> {list(first.output_names)}; "
                        "rename or reorder the channels so that they match")


@checked_call
def merge(records, names=None) -> IOData:
    """One record of several experiments (MATLAB ``merge`` of iddata objects).

    The experiments are kept apart: the batch methods build no Hankel column
    and no simulated trajectory across the border between two experiments,
    and the initial state is estimated once per experiment
    (``model.info['x0']`` has one row per experiment). Without ``merge``,
    concatenating the arrays of two experiments joins them as if the second
    had started where the first ended, which leaves a jump that no linear
    model explains.

    Parameters
    ----------
    records : sequence of IOData
        Uniformly sampled records with the same sampling period and the same
        input and output channels (names included). A record that is itself a
        merge contributes all its experiments.
    names : sequence of str, optional
        Experiment names (default ``exp1, exp2, ...``; a merged record keeps
        its own).

    Returns
    -------
    IOData
        ``n_experiments`` experiments; ``experiment_ranges`` gives their
        samples and ``experiment(k)`` returns one of them.

    Raises
    ------
    DataError
        Fewer than one record, a non-IOData item, non-uniform time stamps,
        different sampling periods, channel counts or names, or records of
        which only some were detrended (or detrended differently).

    Examples
    --------
    >>> import subid
    >>> true = subid.systems.seed001_system()
    >>> a = subid.systems.simulate_data(true, 400, seed=1)
    >>> b = subid.systems.simulate_data(true, 300, seed=2)
    >>> data = subid.merge([a, b])
    >>> data.n_experiments, data.experiment_ranges
    (2, ((0, 400), (400, 700)))
    """
    if isinstance(records, IOData):
        raise DataError("merge takes a list of IOData records, e.g. subid.merge([data1, "
                        "data2]); got a single record")
    try:
        records = list(records)
    except TypeError:
        raise DataError(f"merge takes a list of IOData records, got "
                        f"{type(records).__name__}") from None
    if not records:
        raise DataError("merge needs at least one record")
    for k, rec in enumerate(records):
        if not isinstance(rec, IOData):
            raise not_a_record(rec, f"merge (item {k})")
        if not rec.is_uniform and rec.n_samples > 1:    # one stamp: any period fits
            raise DataError(f"merge: record {k} has non-uniform time stamps; merged "
                            "experiments must be uniformly sampled: interpolate it onto a "
                            "uniform grid first (numpy.interp per channel), or identify it "
                            "alone (subid.ct_subspace takes one non-uniform record)")
    first = records[0]
    timed = [k for k, rec in enumerate(records) if rec.dt is not None]
    if not timed:
        raise DataError("merge: every record is one sample with a time stamp, which gives "
                        "no sampling period; build them with dt=")
    ref = timed[0]
    period = records[ref].dt
    for k, rec in enumerate(records[1:], start=1):
        if rec.dt is not None and not same_period(rec.dt, period):
            raise DataError(f"merge: record {k} is sampled with dt={float(rec.dt)!r} but "
                            f"record {ref} with dt={float(period)!r}; resample one of them "
                            "first")
        if (rec.n_inputs, rec.n_outputs) != (first.n_inputs, first.n_outputs):
            raise DataError(f"merge: record {k} has {rec.n_inputs} inputs and {rec.n_outputs} "
                            f"outputs but record 0 has {first.n_inputs} and "
                            f"{first.n_outputs}")
        check_same_channels(rec, first, f"merge: record {k}", "record 0")
    experiments = [e for rec in records for e in rec.experiments]
    kinds = {offset_kind(e) for e in experiments}
    if len(kinds) > 1:
        raise DataError("merge: some records were detrended and others not (or with "
                        "different kinds); detrend all of them the same way, or detrend "
                        "the merged record")
    if names is None:
        # a merged record keeps its experiments' names when they stay unique
        kept = [n for r in records for n in (r.experiment_names if r.n_experiments > 1
                                             else [None])]
        names = [n if n is not None else f"exp{k + 1}" for k, n in enumerate(kept)]
        if len(set(names)) != len(names):
            names = [f"exp{k + 1}" for k in range(len(experiments))]
    else:
        if isinstance(names, str):
            names = [names]
        if not hasattr(names, "__iter__"):
            raise DataError(f"merge: names must be a list of strings, one per experiment, "
                            f"got {names!r}"[:300])
        names = [str(n) for n in names]
        if len(names) != len(experiments):
            raise DataError(f"merge: {len(names)} names for {len(experiments)} experiments")
    if len(set(names)) != len(names):
        raise DataError(f"merge: the experiment names repeat: {names}")
    lengths = [e.n_samples for e in experiments]
    out = first._derive(np.vstack([e.u for e in experiments]),
                        np.vstack([e.y for e in experiments]), dt=period,
                        t0=experiments[0]._t0s[0], starts=np.cumsum([0] + lengths[:-1]),
                        t0s=[e.t[0] for e in experiments], names=names)
    if kinds != {None}:
        out.u_offset = np.stack([np.asarray(e.u_offset) for e in experiments])
        out.y_offset = np.stack([np.asarray(e.y_offset) for e in experiments])
        out._offsets_per_experiment = True
        if len(experiments) == 1:
            out.u_offset, out.y_offset = out.u_offset[0], out.y_offset[0]
            out._offsets_per_experiment = False
    else:
        out.u_offset = out.y_offset = None
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
        raise not_a_record(data, "iodata_to_pandas")
    both = set(data.input_names) & set(data.output_names)
    if both:
        raise DataError(f"the channel name(s) {sorted(both)} are used by an input and an "
                        "output; rename the channels first")
    columns = {name: data.u[:, k] for k, name in enumerate(data.input_names)}
    columns.update({name: data.y[:, k] for k, name in enumerate(data.output_names)})
    index = pd.Index(np.array(data.t, dtype=float), name="time")
    return pd.DataFrame(columns, index=index)
