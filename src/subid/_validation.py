"""Validation helpers used at the public boundary.

Each helper either returns a clean float64 array or raises a
:mod:`subid.errors` exception whose message names the array and the rows at
fault. Code behind the boundary trusts its inputs.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from subid.errors import DataError, OptionError, OrderError

_MAX_ROWS_LISTED = 8


def format_rows(rows) -> str:
    """``'17, 18, 40'`` or ``'17, 18, ... (1200 rows in all)'``."""
    rows = [int(r) for r in rows]
    head = ", ".join(str(r) for r in rows[:_MAX_ROWS_LISTED])
    if len(rows) > _MAX_ROWS_LISTED:
        head += f", ... ({len(rows)} rows in all)"
    return head


def as_signal(values, name: str, *, allow_empty_columns: bool = False,
              copy: bool = True) -> np.ndarray:
    """Return ``values`` as a C-contiguous float64 array of shape (N, channels).

    With ``copy=False`` an array that is already float64 and C-contiguous is
    returned as a new view of the same memory (not copied); anything else is
    converted (copied) as with ``copy=True``.

    A 1-D array is one channel. Time is axis 0; the orientation is never
    guessed. Raises :class:`DataError` on complex, non-numeric, >2-D or
    non-finite values.
    """
    if values is None:
        raise DataError(f"{name} is missing: pass an array with time on axis 0")
    if isinstance(values, np.ma.MaskedArray):
        check_unmasked(values, name)
        values = values.data                 # no entry is masked: the values themselves
    try:
        arr = np.asarray(values)
    except ValueError as exc:
        if "inhomogeneous" in str(exc) or "sequence" in str(exc):
            raise DataError(f"{name} is ragged: its rows have different lengths (or mix "
                            "numbers and lists); pass a rectangular array with time on "
                            "axis 0") from None
        raise DataError(f"{name} cannot be read as an array ({exc})") from None
    except OverflowError:
        raise DataError(f"{name} holds an integer too large to be a float (beyond "
                        "1.8e308); rescale the data") from None
    if arr.dtype == object:
        missing: np.ndarray | list = np.flatnonzero(np.vectorize(lambda v: v is None, otypes=[bool])(arr)
                                 .reshape(arr.shape[0], -1).any(axis=1)) if arr.ndim else []
        if len(missing):
            raise DataError(f"{name} has missing values (None) at row"
                            f"{'s' if len(missing) != 1 else ''} {format_rows(missing)}; "
                            "fill or remove them before identification")
        check_object_numbers(arr, name)
        try:
            arr = arr.astype(np.float64)
        except OverflowError:
            raise DataError(f"{name} holds an integer too large to be a float (beyond "
                            "1.8e308); rescale the data") from None
        except (TypeError, ValueError) as exc:
            raise DataError(f"{name} holds values that are not numbers ({exc}); "
                            "convert it to a numeric array first") from None
    if arr.dtype.kind in "US":
        raise DataError(f"{name} is an array of strings; convert it to numbers first")
    if arr.dtype.kind == "c":
        raise DataError(f"{name} is complex; subid identifies real-valued systems")
    if arr.dtype.kind not in "biuf":
        raise DataError(f"{name} has dtype {arr.dtype}, which is not numeric")
    if arr.ndim == 0:
        raise DataError(f"{name} is a scalar; pass an array with time on axis 0")
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise DataError(f"{name} has {arr.ndim} dimensions (shape {arr.shape}); "
                        "expected (samples, channels) with time on axis 0")
    if arr.shape[1] == 0 and not allow_empty_columns:
        raise DataError(f"{name} has no channels (shape {arr.shape})")
    if copy or arr.dtype != np.float64 or not arr.flags.c_contiguous \
            or arr.dtype.byteorder not in "=|":
        arr = np.array(arr, dtype=np.float64, order="C", copy=True)
    else:
        arr = arr.view()                 # a new view: its flags are ours to set
    check_finite(arr, name)
    return arr


def as_chunk(values, channels: int, name: str, *, allow_empty: bool = False,
             copy: bool = False) -> np.ndarray:
    """A chunk of samples for an online identifier, as a float64 (N, channels) array.

    ``values`` is (N, channels), or a 1-D array of ``channels`` values (one
    sample) when ``channels > 1``, or N samples when ``channels == 1``, or a
    scalar when ``channels == 1``. A float64 array that needs no conversion is
    checked without a copy (the one-sample path of a stream).

    Parameters
    ----------
    values : array_like
        The samples, time on axis 0.
    channels : int
        Channels the identifier was created with.
    name : str
        Name of the argument in messages (``'input u'``).
    allow_empty : bool
        Accept a chunk of 0 samples (else a :class:`DataError`).
    copy : bool
        Return memory the caller does not share.

    Returns
    -------
    ndarray, shape (N, channels)
        C-contiguous float64, finite.

    Raises
    ------
    DataError
        Wrong number of channels (with a hint when the chunk looks transposed),
        non-finite or non-numeric values, no samples.
    """
    if type(values) is np.ndarray and values.dtype == np.float64:   # fast path
        out = None
        if values.ndim == 1 and values.shape[0] == channels and channels > 1:
            entries = values.tolist()
            # one sample: testing a few Python floats is cheaper than two ufunc calls
            if all(map(math.isfinite, entries)) and \
                    -HUGE_VALUE <= min(entries) and max(entries) <= HUGE_VALUE:
                out = np.ascontiguousarray(values.reshape(1, channels))
        else:
            arr = values.reshape(-1, 1) if values.ndim == 1 and channels == 1 else values
            if arr.ndim == 2 and arr.shape[1] == channels and arr.shape[0] > 0 \
                    and np.isfinite(arr).all() and -HUGE_VALUE <= arr.min() \
                    and arr.max() <= HUGE_VALUE:
                out = np.ascontiguousarray(arr)
        if out is not None:
            return out.copy() if copy and np.shares_memory(out, values) else out
    arr = np.asarray(values) if not isinstance(values, np.ndarray) else values
    if arr.ndim == 0 and channels == 1:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1 and channels > 1:
        if arr.shape[0] != channels:
            raise DataError(f"{name} is 1-D with {arr.shape[0]} entries; one sample of "
                            f"{channels} channels has {channels} (time is axis 0 of a "
                            "2-D chunk)")
        arr = arr.reshape(1, channels)
    out = as_signal(arr, name)
    if out.shape[1] != channels:
        hint = ""
        if out.shape[0] == channels:
            hint = " (time is axis 0: was it passed transposed?)"
        raise DataError(f"{name} has {out.shape[1]} channel{'s' if out.shape[1] != 1 else ''}"
                        f" but the identifier has {channels}{hint}")
    if out.shape[0] == 0 and not allow_empty:
        raise DataError(f"{name} has no samples")
    check_magnitude(out, name)
    return out


#: Largest magnitude of a sample the identification accepts: its square must not
#: overflow (the batch methods' check, :func:`subid.methods.dt.checks.check_data`, and
#: the online identifiers' chunks, :func:`as_chunk`).
HUGE_VALUE = 1e150


def check_magnitude(values: np.ndarray, name: str, channels=None) -> None:
    """Raise :class:`DataError` when a sample of the finite (N, channels) array
    ``values`` exceeds :data:`HUGE_VALUE` in magnitude, naming the channel (by its name
    in ``channels`` when given) and row: its square overflows (a 1e200 in one sample, or
    ``DBL_MAX`` as a missing-value marker, broke an online identifier's statistic for
    good, silently). The batch methods' check too
    (:func:`subid.methods.dt.checks.check_data`); two whole-array reductions when the
    values are within range."""
    if not values.size or (-HUGE_VALUE <= values.min() and values.max() <= HUGE_VALUE):
        return
    row, column = np.unravel_index(int(np.argmax(np.abs(values))), values.shape)
    which = f"{name} {channels[column]}" if channels is not None else name
    where = f"row {row}" if channels is not None else f"row {row}, channel {column}"
    raise DataError(f"{which} reaches {values[row, column]:.3g} at {where}: squares and "
                    "products of such values overflow double precision; is it a "
                    "missing-value marker? remove it, or express the channel in other units "
                    "(divide it by a constant) and scale the model back")


#: Smallest largest magnitude of a channel the identification accepts (the mirror of
#: :data:`HUGE_VALUE`): products of such values underflow double precision (1e-160
#: squared is below the smallest double), and the methods' factorizations return
#: zeros or fail on them.
TINY_VALUE = 1e-150


def check_tiny(values: np.ndarray, name: str, channels=None) -> None:
    """Raise :class:`DataError` when a channel of the finite (N, channels) array
    ``values`` is not all zeros but never exceeds :data:`TINY_VALUE` in magnitude,
    naming the channel and asking for other units: its squares underflow (``moesp`` on
    outputs of 1e-300 returned C = 0 silently, ``ls_subspace`` on 1e-160 failed in
    LAPACK). An all-zero channel is left to the excitation and constant-output checks.
    The batch methods' check (:func:`subid.methods.dt.checks.check_data`)."""
    if not values.size:
        return
    # the first rows settle most channels; the others column by column (numpy's axis-0
    # reductions of a C-ordered array of few columns are slow: 0.16 s on 10^6 x 2)
    peak = np.abs(values[:64]).max(axis=0)
    for j in np.flatnonzero(peak < TINY_VALUE):
        column = values[:, j]
        peak[j] = max(float(column.max()), -float(column.min()))
    small = np.flatnonzero((peak > 0) & (peak < TINY_VALUE))
    if not small.size:
        return
    k = int(small[0])
    which = f"{name} {channels[k]}" if channels is not None else f"{name} channel {k}"
    raise DataError(f"{which} never exceeds {peak[k]:.3g} in magnitude: squares and "
                    "products of such values underflow double precision. Express the "
                    "channel in other units (multiply it by a constant, e.g. "
                    "data.scaled(inputs=..., outputs=...)) and scale the model back")


def check_unmasked(values: np.ma.MaskedArray, name: str) -> None:
    """Raise :class:`DataError` listing the rows of a masked array with masked entries.

    A masked entry is a missing value, as a NaN is: subid neither drops its row nor
    reads the value under the mask.
    """
    mask = np.ma.getmaskarray(values)
    if not mask.any():
        return
    rows = np.flatnonzero(mask.reshape(mask.shape[0], -1).any(axis=1)) if mask.ndim else [0]
    count = int(mask.sum())
    raise DataError(f"{name} has {count} masked value{'s' if count != 1 else ''} at row"
                    f"{'s' if len(rows) != 1 else ''} {format_rows(rows)}; masked entries "
                    "are missing values: remove or interpolate them before identification "
                    "(subid neither drops them nor uses the values under the mask)")


def check_object_numbers(arr: np.ndarray, name: str,
                         hint: str = "pandas.to_numeric, or numpy.asarray(..., dtype=float)"
                         ) -> None:
    """Raise :class:`DataError` unless every entry of the object array ``arr`` is a
    number (an int, a float, a NumPy scalar...): strings such as ``'1.5'`` (a pandas
    column read as text) are refused, as a NumPy array of strings is, not parsed."""
    flat = arr.reshape(-1)
    numeric = np.vectorize(lambda v: isinstance(v, numbers.Number), otypes=[bool])(flat) \
        if flat.size else np.ones(0, bool)
    if numeric.all():
        return
    first = int(np.flatnonzero(~numeric)[0])
    value = flat[first]
    kind = "strings" if isinstance(value, (str, bytes)) else type(value).__name__
    kind = f"values that are not numbers ({kind})"
    row = f" at row {first // max(1, flat.size // arr.shape[0])}" if arr.ndim else ""
    raise DataError(f"{name} holds {kind}, e.g. {value!r}{row}; convert it to numbers "
                    f"first (e.g. {hint})")


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raise :class:`DataError` listing the rows of ``arr`` holding NaN or inf."""
    if np.isfinite(arr).all():
        return
    nan_rows = np.flatnonzero(np.isnan(arr).any(axis=1) if arr.ndim == 2 else np.isnan(arr))
    inf_rows = np.flatnonzero(np.isinf(arr).any(axis=1) if arr.ndim == 2 else np.isinf(arr))
    parts = []
    if nan_rows.size:
        n_nan = int(np.isnan(arr).sum())
        parts.append(f"{n_nan} NaN value{'s' if n_nan != 1 else ''} at row"
                     f"{'s' if nan_rows.size != 1 else ''} {format_rows(nan_rows)}")
    if inf_rows.size:
        n_inf = int(np.isinf(arr).sum())
        parts.append(f"{n_inf} infinite value{'s' if n_inf != 1 else ''} at row"
                     f"{'s' if inf_rows.size != 1 else ''} {format_rows(inf_rows)}")
    raise DataError(f"{name} has " + " and ".join(parts)
                    + "; remove or interpolate them before identification")


#: A signal looks transposed (time on axis 1 instead of axis 0) when it has more
#: channels than samples and more than this many channels: the layout
#: channels x samples of SIPPY, python-control and ControlSystemIdentification.jl,
#: which :func:`check_orientation` refuses instead of transposing it silently. A
#: record with fewer samples than channels cannot be identified anyway; the bound
#: keeps short chunks of a record with a few channels (one row of a stream) legal.
TRANSPOSED_MIN_CHANNELS = 100


def check_orientation(arr: np.ndarray, name: str, symbol: str) -> None:
    """Refuse a (samples x channels) array ``arr`` that looks transposed.

    The rule: ``n_channels > n_samples`` and ``n_channels >`` :data:`TRANSPOSED_MIN_CHANNELS`
    (e.g. ``u.T`` of shape (2, 5000) for two input channels of 5000 samples). The
    message says how to pass the array (``symbol.T``); the array is never
    transposed here.
    """
    samples, channels = arr.shape
    if channels > samples and channels > TRANSPOSED_MIN_CHANNELS:
        raise DataError(
            f"{name} has shape {arr.shape}: {samples} sample{'s' if samples != 1 else ''} of "
            f"{channels} channels, which looks transposed (channels x samples); time must be "
            f"axis 0, one column per channel, and subid never transposes data itself: pass "
            f"{symbol}.T, of shape ({channels}, {samples})")


def check_time_stamps(t, n_samples: int, name: str = "time stamps t") -> np.ndarray:
    """Validate strictly increasing, finite time stamps of length ``n_samples``.

    Numbers, or date-times (numpy ``datetime64``, a pandas ``DatetimeIndex`` or
    Series with or without a time zone, ``datetime.datetime`` objects and pandas
    ``Timestamp``s; time-zone aware ones converted to UTC) counted in seconds from the
    first, or durations (``timedelta64``) in seconds."""
    if getattr(getattr(t, "dtype", None), "tz", None) is not None:
        t = np.asarray(t, dtype="datetime64[ns]")      # pandas, time-zone aware: UTC
    try:
        arr = np.asarray(t)
    except (ValueError, OverflowError) as exc:
        raise DataError(f"{name} cannot be read as a one-dimensional array of numbers "
                        f"({type(exc).__name__}: ragged, or integers beyond the float "
                        "range)") from None
    if isinstance(t, np.ma.MaskedArray):
        check_unmasked(t, name)
        arr = np.asarray(t.data)
    if arr.ndim != 1:
        column = (f"; a column or a row of {arr.size} stamps: pass numpy.ravel(t)"
                  if arr.ndim == 2 and 1 in arr.shape else "")
        raise DataError(f"{name} must be one-dimensional (one stamp per sample), got shape "
                        f"{arr.shape}{column}")
    if arr.dtype == object and arr.ndim == 1:
        arr = _date_time_objects(arr, name)
    if arr.dtype == object:
        check_object_numbers(arr, name, "pandas.to_numeric, or pandas.to_datetime for "
                             "date-times")
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError, OverflowError):
            raise DataError(f"{name} must be numeric, got values that are not numbers "
                            "(or integers beyond the float range)") from None
    if arr.dtype.kind == "M" and arr.ndim >= 1 and arr.size:
        # date-times (numpy's datetime64, a pandas DatetimeIndex or Series): seconds since
        # the first, as subid.read and IOData.from_pandas take them
        if np.isnat(arr).any():
            raise DataError(f"{name} holds missing date-times (NaT)")
        arr = (arr - arr.reshape(-1)[0]) / np.timedelta64(1, "s")
    elif arr.dtype.kind == "m":
        if np.isnat(arr).any():
            raise DataError(f"{name} holds missing durations (NaT)")
        arr = arr / np.timedelta64(1, "s")
    if arr.dtype.kind not in "iuf":
        raise DataError(f"{name} must be numeric or date-times, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if arr.shape[0] != n_samples:
        raise DataError(f"{name} has {arr.shape[0]} entries but the signals have "
                        f"{n_samples} samples")
    check_finite(arr, name)
    steps = np.diff(arr)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        kinds = "repeated" if np.all(steps[bad] == 0) else "not increasing"
        raise DataError(f"{name} are {kinds} at row{'s' if bad.size != 1 else ''} "
                        f"{format_rows(bad + 1)} (t[k] <= t[k-1]); time stamps must "
                        "be strictly increasing")
    return arr


def _date_time_objects(arr: np.ndarray, name: str) -> np.ndarray:
    """An object array of ``datetime.datetime`` objects (pandas ``Timestamp``s too) as
    ``datetime64[ns]`` (time-zone aware ones in UTC); any other array unchanged."""
    import datetime

    if not arr.size or not all(isinstance(v, datetime.datetime) for v in arr):
        return arr
    aware = [v.utcoffset() is not None for v in arr]
    if any(aware) and not all(aware):
        k = aware.index(not aware[0])
        raise DataError(f"{name} mixes date-times with and without a time zone (row 0: "
                        f"{arr[0]!s}, row {k}: {arr[k]!s}); give all of them a time zone, "
                        "or none")
    out = np.empty(arr.size, dtype="datetime64[ns]")
    for k, v in enumerate(arr):
        if aware[k]:
            v = v.astimezone(datetime.timezone.utc).replace(tzinfo=None)
        out[k] = v.to_datetime64() if hasattr(v, "to_datetime64") else np.datetime64(v, "ns")
    return out


def check_selector(selector, horizon: int, n_outputs: int, candidates, fixed_order, *,
                   exact: bool = False):
    """The user's selector Λ (seed 001, eq. (13)) as a float array, or None.

    Shared by :func:`subid.ls_subspace`, :class:`subid.RecursiveSubspace` and
    :class:`subid.AdaptiveIdentifier`.

    Parameters
    ----------
    selector : array_like or None
        Λ, shape (rows, horizon * n_outputs).
    horizon : int
        Future horizon f.
    n_outputs : int
        Output channels ny.
    candidates : sequence of int
        The candidate orders; Λ needs at least ``max(candidates)`` rows.
    fixed_order : int or None
        The order when it is fixed (None: chosen among the candidates).
    exact : bool
        Require exactly ``max(candidates)`` rows (an online identifier with
        a fixed order).

    Returns
    -------
    ndarray or None
        A new float64 array (the caller's is never shared).

    Raises
    ------
    OrderError
        Wrong shape, non-numeric or non-finite entries.
    """
    if selector is None:
        return None
    c = horizon * n_outputs
    try:
        selector = np.array(selector, dtype=float)      # a copy: never the caller's array
    except (TypeError, ValueError):
        raise OrderError("selector must be a numeric matrix of horizon*n_outputs = "
                         f"{c} columns") from None
    if selector.ndim != 2 or selector.shape[1] != c:
        raise OrderError(f"selector must have horizon*n_outputs = {c} columns, got shape "
                         f"{selector.shape}")
    if not np.isfinite(selector).all():
        raise OrderError("selector has non-finite entries")
    if selector.shape[0] < max(candidates) or (exact and selector.shape[0] != max(candidates)):
        raise OrderError(f"selector has {selector.shape[0]} rows but the order is "
                         f"{'up to ' if fixed_order is None else ''}{max(candidates)}; "
                         f"it needs {'exactly' if exact else 'at least'} order rows")
    return selector


def check_dt(dt, *, allow_zero: bool = False, name: str = "dt") -> float:
    """Validate a sampling period: a finite positive number (or 0 if allowed)."""
    if isinstance(dt, bool) or not isinstance(dt, numbers.Real):
        raise DataError(f"{name} must be a number, got {dt!r}"[:300])
    try:
        dt = float(dt)
    except OverflowError:
        raise DataError(f"{name} must be a finite number, got an integer beyond the float "
                        "range") from None
    if not np.isfinite(dt) or dt < 0 or (dt == 0 and not allow_zero):
        need = "a finite number >= 0 (0 = continuous time)" if allow_zero else \
            "a finite positive number"
        raise DataError(f"{name} must be {need}, got {dt!r}")
    return dt


#: Relative tolerance of every sampling-period comparison: steps that agree to this
#: fraction of the largest make a uniform grid, and two periods that agree to it
#: are one period. The one value for the whole package (records, models,
#: simulation, basis filters, streams, files, online identifiers).
UNIFORM_RTOL = 1e-9


def _double_resolution(t: np.ndarray) -> float:
    """Four units in the last place of the largest ``|t|`` of the (sorted) stamps."""
    if not t.size:
        return 0.0
    return 4.0 * float(np.spacing(max(abs(float(t[0])), abs(float(t[-1])))))


#: Largest written precision of time stamps, as a share of their mean step, that
#: :func:`stamp_resolution` allows for: beyond, a missing sample could hide in it.
MAX_WRITTEN_RESOLUTION = 0.1


def stamp_resolution(t) -> float:
    """How far apart two steps of the time stamps ``t`` can be through rounding alone.

    A stamp ``t_k`` is a double: it carries a rounding error of up to half a
    unit in the last place of ``|t_k|`` (from the decimal text of a file, or
    from arithmetic), so a step carries up to one unit, and two steps differ
    by up to two. Epoch seconds (``|t|`` ~ 1.7e9, unit 2.4e-7 s) sampled at
    1 kHz have steps that differ by ~2e-7 s, 2e-4 of the period: uniform
    sampling all the same. Four units of the largest ``|t|`` (a margin of 2).

    Stamps written at a limited precision carry that rounding too: ``d`` decimals
    (:func:`stamp_decimals`; 30 Hz stamps logged in milliseconds have steps of 0.033
    and 0.034 s) or single precision (stamps that are float32 numbers). Their
    resolution, ``10**-d`` or two float32 units, is added when it is at most
    :data:`MAX_WRITTEN_RESOLUTION` of the mean step (so a missing sample, a step of
    twice the period, is never within it) and every stamp lies within it of the
    straight line from the first stamp to the last (a uniform grid, rounded).
    """
    t = np.asarray(t, dtype=np.float64)
    base = _double_resolution(t)
    if t.size < 3:
        return base
    mean = (float(t[-1]) - float(t[0])) / (t.size - 1)
    decimals = stamp_decimals(t[:1000])
    if decimals is not None and 10.0 ** -decimals > MAX_WRITTEN_RESOLUTION * mean:
        return base                      # too coarse to matter (0.5 s steps: 1 decimal)
    decimals = stamp_decimals(t) if decimals is not None else None
    if decimals is not None:
        written = 10.0 ** -decimals
    elif _single_precision(t):
        written = 2.0 * float(np.spacing(np.float32(max(abs(float(t[0])),
                                                            abs(float(t[-1]))))))
    else:
        return base
    if not 0 < written <= MAX_WRITTEN_RESOLUTION * mean:
        return base
    grid = float(t[0]) + mean * np.arange(t.size)
    if float(np.max(np.abs(t - grid))) > written + base:
        return base
    return base + written


def _single_precision(t: np.ndarray) -> bool:
    """True when every stamp is a float32 number (stamps stored in single precision)."""
    head = t[:1000]
    if not np.array_equal(head.astype(np.float32).astype(np.float64), head):
        return False
    return bool(np.array_equal(t.astype(np.float32).astype(np.float64), t))


#: Most decimals :func:`grid_step` looks for in time stamps (beyond, they carry the
#: rounding of a computation, not a grid written at a precision).
MAX_STAMP_DECIMALS = 12


def stamp_decimals(t: np.ndarray) -> int | None:
    """The fewest decimals ``d`` (0..:data:`MAX_STAMP_DECIMALS`) with
    ``round(t, d) == t`` for every stamp, or None: the precision at which the time
    stamps were written (``0.05, 0.1, 0.15`` read from a file: 2).

    Parameters
    ----------
    t : ndarray, shape (N,)

    Returns
    -------
    int or None
    """
    head = t[:1000]
    for d in range(MAX_STAMP_DECIMALS + 1):
        if np.array_equal(np.round(head, d), head):
            return d if np.array_equal(np.round(t, d), t) else None
    return None


def grid_step(t: np.ndarray, steps: np.ndarray) -> float:
    """The sampling period of uniform time stamps ``t``: the mean step, rounded to the
    decimals the stamps carry (:func:`stamp_decimals`), so that stamps
    ``0, 0.05, 0.1, ...`` read from a file give ``dt = 0.05``, not the
    ``0.049999999999999996`` of their float differences. Stamps without such a
    precision (computed ones, ``0.1 * np.arange(N)``) keep the mean step.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Uniform time stamps.
    steps : ndarray, shape (N - 1,)
        ``np.diff(t)``.

    Returns
    -------
    float
    """
    mean = float(np.mean(steps))
    decimals = stamp_decimals(t)
    if decimals is None:
        return mean
    rounded = round(mean, decimals)
    # the rounding must keep the step (a grid of 0.3 s written with 1 decimal, not a
    # step of 0.25 s written with 1 decimal at the stamps by coincidence), to the
    # tolerance of a uniform grid and the rounding of the stamps themselves
    tolerance = UNIFORM_RTOL * mean + _double_resolution(t)
    return rounded if rounded > 0 and abs(rounded - mean) <= tolerance else mean


def is_uniform(steps, *, resolution: float = 0.0) -> bool:
    """True when the sampling steps (``np.diff(t)``, at least one) agree to
    :data:`UNIFORM_RTOL` of the largest, plus ``resolution``.

    Parameters
    ----------
    steps : ndarray, shape (N - 1,)
        Positive time steps.
    resolution : float
        The rounding of the stamps the steps come from
        (:func:`stamp_resolution`); 0 for steps known exactly.

    Returns
    -------
    bool
    """
    steps = np.asarray(steps)
    return steps.size > 0 and float(np.ptp(steps)) <= \
        UNIFORM_RTOL * float(np.abs(steps).max()) + resolution


def same_period(value, period, *, resolution: float = 0.0) -> bool:
    """True when ``value`` (a period, or an array of steps) equals ``period``
    to :data:`UNIFORM_RTOL` of ``period`` plus ``resolution``
    (``numpy.isclose(value, period, rtol=UNIFORM_RTOL, atol=resolution)`` for
    every entry).

    Parameters
    ----------
    value : float or ndarray
        Sampling period(s) or time steps to compare.
    period : float
        The reference period.
    resolution : float
        The rounding of the stamps ``value`` comes from
        (:func:`stamp_resolution`); 0 for periods known exactly.

    Returns
    -------
    bool
    """
    return bool(np.all(np.abs(np.asarray(value, dtype=np.float64) - period)
                       <= UNIFORM_RTOL * abs(period) + resolution))


#: Largest value of an integer that sizes a matrix (order, horizon, channels):
#: a state-space or Hankel matrix of this dimension already takes ~80 GB.
MAX_DIMENSION = 100_000
#: Largest value of any other integer setting (counts, sizes of histories).
MAX_COUNT = 2**40
_DIMENSION_NAMES = {"order", "candidate order", "horizon", "depth", "n_inputs",
                    "n_outputs", "k", "poly_order"}
#: Largest history an online identifier keeps (snapshots of the model; the
#: adaptive identifier allocates it up front).
MAX_HISTORY = 10_000_000
_HISTORY_NAMES = {"history", "history_size"}


def check_int(value, name: str, *, minimum: int = 1, maximum: int | None = None) -> int:
    """Validate an integer parameter (order, horizon, ...).

    ``maximum`` defaults to :data:`MAX_DIMENSION` for integers that size a
    matrix (orders, horizons, channel counts), :data:`MAX_HISTORY` for
    history lengths and :data:`MAX_COUNT` for the others, so that an absurd
    value is an :class:`OrderError` naming it, not a ``MemoryError`` or
    ``OverflowError`` deep inside numpy.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise OrderError(f"{name} must be an integer, got {value!r}"[:300])
    value = int(value)
    if value < minimum:
        raise OrderError(f"{name} must be at least {minimum}, got {value}"[:300])
    if maximum is None:
        maximum = MAX_DIMENSION if name in _DIMENSION_NAMES else \
            MAX_HISTORY if name in _HISTORY_NAMES else MAX_COUNT
    if value > maximum:
        shown = str(value) if value < 10**30 else f"an integer of {len(str(value))} digits"
        raise OrderError(f"{name} must be at most {maximum}, got {shown}: a larger value needs "
                         "arrays beyond any computer's memory")
    return value


def check_choice(value, name: str, choices) -> object:
    """``value`` if it is one of ``choices``; else :class:`OptionError` listing them.

    The comparison is by equality for hashable values (strings, None, bools);
    an unhashable value (a list, an array) is never a choice.
    """
    try:
        ok = any(value is c or (type(value) is type(c) and value == c) for c in choices)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        allowed = ", ".join(repr(c) for c in choices)
        raise OptionError(f"{name} must be one of {allowed}; got {value!r}"[:300])
    return value


def check_seed(value, name: str = "seed") -> int:
    """A seed: a non-negative integer (numpy integers too); else
    :class:`OptionError` (not numpy's ``TypeError``/``ValueError`` from inside
    the draw). Integers only, so that the same call always draws the same
    numbers (a ``Generator`` would advance between calls)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral) \
            or value < 0:
        raise OptionError(f"{name} must be a non-negative integer; got {value!r}"[:300])
    return int(value)


def check_optimiser_options(max_iterations, tolerance, rounds=1) -> None:
    """The options of every prediction-error search (:func:`subid.pem` on time or
    frequency data, :func:`subid.armax`, :func:`subid.oe`, :func:`subid.bj`):
    positive integers ``max_iterations`` and ``rounds``, and a ``tolerance`` in
    ``[eps, 1)`` (below machine precision scipy's ``least_squares`` refuses it);
    else :class:`OptionError`."""
    eps = float(np.finfo(float).eps)
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) \
            or max_iterations < 1:
        raise OptionError(f"max_iterations must be a positive integer, got {max_iterations!r}")
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) \
            or not eps <= tolerance < 1:
        raise OptionError(f"tolerance must be in [{eps:.3g}, 1) (below machine precision no "
                          f"step can meet it), got {tolerance!r}")
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise OptionError(f"rounds must be a positive integer, got {rounds!r}")


def check_probability(value, name: str) -> float:
    """A level strictly between 0 and 1 (confidence levels); else :class:`OptionError`."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) \
            or not 0.0 < float(value) < 1.0:
        raise OptionError(f"{name} must be a number strictly between 0 and 1 (e.g. 0.99); "
                          f"got {value!r}"[:300])
    return float(value)


def check_bool(value, name: str) -> bool:
    """``value`` as a bool if it is one (numpy bools too); else :class:`OptionError`."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise OptionError(f"{name} must be True or False; got {value!r}"[:300])


def name_caller(exc: Exception, callee: str, caller: str) -> Exception:
    """``exc`` with a message that starts ``'callee: '`` (the function that raised it)
    starting ``'caller: '`` instead: the function the user called, which ran
    ``callee`` for them (:func:`subid.identify` its estimators,
    :func:`subid.ct_subspace_paper` :func:`subid.ct_subspace`). Class and attributes
    are kept; re-raise it."""
    text = exc.args[0] if exc.args and isinstance(exc.args[0], str) else ""
    if text.startswith(f"{callee}:"):
        exc.args = (f"{caller}:{text[len(callee) + 1:]}",) + exc.args[1:]
    return exc


def checked_call(fn):
    """Decorator of a public function (or a class's ``__init__``): a call that does
    not fit its signature raises :class:`OptionError` naming the options it
    takes, instead of Python's ``TypeError``.

    Only the binding of the call is concerned: a ``TypeError`` is converted
    when the arguments do not bind to the signature (``inspect.signature``,
    which follows ``__wrapped__``), never when ``fn`` raised it on arguments
    that bind. An unknown keyword gets the closest
    option names as a suggestion (``horizn`` -> ``horizon``).
    """
    import difflib
    import functools
    import inspect

    signature = inspect.signature(fn)                # follows __wrapped__: the real one
    parameters = signature.parameters
    options = [p.name for p in parameters.values()
               if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name != "self"]
    name = fn.__qualname__.replace(".__init__", "")

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except TypeError as exc:
            try:                                     # the call itself, or raised inside fn?
                signature.bind(*args, **kwargs)
            except TypeError:
                pass
            else:
                raise
            unknown = [k for k in kwargs if k not in parameters]
            if unknown:
                close = difflib.get_close_matches(unknown[0], options, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise OptionError(f"{name}() has no option {unknown[0]!r}{hint}; its options "
                                  f"are {', '.join(options)}"[:600]) from None
            raise OptionError(f"{name}(): {exc}; its arguments are "
                              f"{', '.join(options)}"[:600]) from None
    return wrapper
