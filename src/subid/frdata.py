"""Frequency-response data: :class:`FRData`.

A frequency response ``G(i w_k)`` (continuous time, ``dt = 0``) or
``G(exp(i w_k dt))`` (discrete time) sampled at frequencies ``w_k`` in radians
per time unit, as measured by a network analyser, a stepped sine or a spectral
estimate (:func:`subid.spa`, :func:`subid.etfe`). It is the frequency-domain
counterpart of :class:`subid.IOData` and lives in the data layer: it imports
only :mod:`subid.errors`, :mod:`subid._validation` and numpy.

Validation happens once, in the constructor; inside, methods trust the arrays.
"""

from __future__ import annotations

import math

import numpy as np

from subid._validation import UNIFORM_RTOL, check_dt, checked_call, format_rows
from subid.errors import DataError, OptionError

__all__ = ["FRData"]


def _names(names, count: int, prefix: str, which: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{i + 1}" for i in range(count))
    if isinstance(names, str):
        names = [names]
    names = tuple(str(n) for n in names)
    if len(names) != count:
        raise DataError(f"FRData: {which} has {len(names)} name{'s' if len(names) != 1 else ''}"
                        f" {list(names)} but the response has {count} {which} "
                        f"channel{'s' if count != 1 else ''}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise DataError(f"FRData: {which} names repeat {dup}; names must be unique")
    return names


def _numeric(values, name: str, *, complex_ok: bool) -> np.ndarray:
    """``values`` as a float64 (or complex128) array, or a :class:`DataError`."""
    if values is None:
        raise DataError(f"FRData: {name} is missing")
    try:
        arr = np.asarray(values)
    except (ValueError, OverflowError) as exc:
        raise DataError(f"FRData: {name} cannot be read as a rectangular numeric array "
                        f"({type(exc).__name__}: ragged rows or integers beyond the "
                        "float range)") from None
    if arr.dtype == object:
        try:
            arr = arr.astype(np.complex128 if complex_ok else np.float64)
        except (TypeError, ValueError, OverflowError):
            raise DataError(f"FRData: {name} holds values that are not numbers "
                            "(or None); convert it to a numeric array first") from None
    if arr.dtype.kind == "c" and not complex_ok:
        raise DataError(f"FRData: {name} is complex; it must be real")
    if arr.dtype.kind not in "biufc":
        raise DataError(f"FRData: {name} has dtype {arr.dtype}, which is not numeric")
    dtype = np.complex128 if complex_ok else np.float64
    return np.array(arr, dtype=dtype, order="C", copy=True)


def _check_finite(arr: np.ndarray, name: str) -> None:
    bad = ~np.isfinite(arr)
    if not bad.any():
        return
    rows = np.flatnonzero(bad.reshape(arr.shape[0], -1).any(axis=1))
    n_nan = int(np.isnan(arr).sum())
    kind = "NaN" if n_nan == int(bad.sum()) else ("infinite" if n_nan == 0
                                                   else "NaN or infinite")
    raise DataError(f"FRData: {name} has {int(bad.sum())} {kind} value"
                    f"{'s' if bad.sum() != 1 else ''} at frequenc"
                    f"{'ies' if rows.size != 1 else 'y'} index {format_rows(rows)}; "
                    "remove those frequencies (e.g. with a boolean mask) before use")


def _frequencies(w, dt: float) -> np.ndarray:
    w = _numeric(w, "frequencies w", complex_ok=False)
    if w.ndim != 1:
        raise DataError(f"FRData: frequencies w must be one-dimensional, got shape {w.shape}")
    if w.size == 0:
        raise DataError("FRData: frequencies w are empty; pass at least one frequency")
    _check_finite(w, "frequencies w")
    if (w < 0).any():
        rows = np.flatnonzero(w < 0)
        raise DataError(f"FRData: frequencies w must be non-negative (rad per time unit), "
                        f"got negative values at index {format_rows(rows)}; a real "
                        "system's response at -w is the conjugate of the one at w")
    steps = np.diff(w)
    if (steps == 0).any():
        rows = np.flatnonzero(steps == 0) + 1
        raise DataError(f"FRData: frequencies w repeat at index {format_rows(rows)} "
                        f"(w = {w[rows[0]]:g}); each frequency must appear once: "
                        "average the repeated measurements first")
    if (steps < 0).any():
        rows = np.flatnonzero(steps < 0) + 1
        raise DataError(f"FRData: frequencies w must increase strictly, but they decrease "
                        f"at index {format_rows(rows)}; sort them (and the response "
                        "with them: order = np.argsort(w))")
    if dt > 0:
        nyquist = math.pi / dt
        above = np.flatnonzero(w > nyquist * (1 + UNIFORM_RTOL))
        if above.size:
            raise DataError(f"FRData: discrete-time frequencies must be at most the Nyquist "
                            f"frequency pi/dt = {nyquist:.6g} rad per time unit (dt = "
                            f"{dt:g}), but w = {w[above[0]]:.6g} at index "
                            f"{format_rows(above)} is above it; check dt and the units "
                            "of w (rad per time unit, not Hz)")
    return w


def _response(response, n_freq: int) -> np.ndarray:
    g = _numeric(response, "response", complex_ok=True)
    if g.ndim == 1:
        g = g.reshape(-1, 1, 1)
    elif g.ndim != 3:
        hint = (" A 2-D array is ambiguous (several outputs of one input, or several "
                "inputs of one output?): reshape it to (n_freq, ny, nu) yourself, e.g. "
                "g[:, :, None] for one input or g[:, None, :] for one output."
                if g.ndim == 2 else "")
        raise DataError(f"FRData: response must have shape (n_freq, ny, nu) (or 1-D for "
                        f"one input and one output), got shape {g.shape}.{hint}")
    if g.shape[0] != n_freq:
        raise DataError(f"FRData: response has {g.shape[0]} frequencies (axis 0, shape "
                        f"{g.shape}) but w has {n_freq}; frequency is axis 0")
    if g.shape[1] == 0 or g.shape[2] == 0:
        raise DataError(f"FRData: response has no outputs or no inputs (shape {g.shape})")
    _check_finite(g, "response")
    return g


def _per_frequency(values, name: str, shapes, *, positive: bool) -> np.ndarray:
    """A real array of one of ``shapes`` (the first that matches after reshaping)."""
    arr = _numeric(values, name, complex_ok=False)
    for shape in shapes:
        if arr.shape == shape:
            break
        if arr.size == math.prod(shape) and arr.ndim == 1 and len(shape) > 1 \
                and all(s == 1 for s in shape[1:]):
            arr = arr.reshape(shape)
            break
    else:
        allowed = " or ".join(str(s) for s in shapes)
        raise DataError(f"FRData: {name} has shape {arr.shape}; expected {allowed}")
    _check_finite(arr, name)
    if positive and (arr <= 0).any():
        raise DataError(f"FRData: {name} must be positive; {int((arr <= 0).sum())} "
                        "values are zero or negative (drop those frequencies instead "
                        "of weighting them by zero)")
    if not positive and (arr < 0).any():
        raise DataError(f"FRData: {name} must be non-negative; {int((arr < 0).sum())} "
                        "values are negative")
    return arr


class FRData:
    """Frequency-response data of a linear MIMO system.

    Parameters
    ----------
    w : array_like, shape (n_freq,)
        Frequencies in radians per time unit, finite, non-negative, strictly
        increasing. In discrete time at most the Nyquist frequency ``pi/dt``.
    response : array_like, shape (n_freq, ny, nu), complex
        ``response[k]`` is the ``ny x nu`` frequency response at ``w[k]``:
        ``G(i w_k)`` in continuous time, ``G(exp(i w_k dt))`` in discrete time.
        A 1-D array is a single-input single-output response; a 2-D array is
        rejected (its orientation would be a guess).
    dt : float, optional
        Sampling period; 0 (the default) means continuous time.
    weights : array_like, optional
        Positive weights of the fit, shape (n_freq,) (per frequency) or
        (n_freq, ny, nu) (per frequency and channel pair), read as inverse
        standard deviations of the noise. :func:`subid.pem` minimises
        ``sum |weights * (G - G_hat)|**2`` and :func:`subid.fit_percent`
        weights its norms with them.
    std : array_like, shape (n_freq, ny, nu), optional
        Non-negative standard deviation of each response value (as
        :func:`subid.spa` returns it). Without ``weights``, :func:`subid.fd_subspace` and
        :func:`subid.pem` weight by it (``1 / std``); ``fit_percent`` does not.
    coherence : array_like, shape (n_freq, ny), optional
        Squared multiple coherence of each output with all inputs, in [0, 1].
    input_names, output_names : sequence of str, optional
        Channel names (default ``u1, u2, ...`` and ``y1, y2, ...``).

    Attributes
    ----------
    w : ndarray, shape (n_freq,)
        The frequencies (float64).
    response : ndarray, shape (n_freq, ny, nu)
        The response (complex128).
    dt : float
        Sampling period (0: continuous time).
    weights, std, coherence : ndarray or None
        As given (float64), or None.
    input_names, output_names : tuple of str
        Channel names.

    Raises
    ------
    DataError
        Unsorted, repeated, negative or non-finite frequencies; a discrete-time
        frequency above Nyquist; non-finite responses; wrong shapes; bad names.

    Examples
    --------
    >>> import numpy as np, subid
    >>> w = np.logspace(-1, 1, 5)
    >>> data = subid.FRData(w, 1 / (1j * w + 1))
    >>> data.n_frequencies, data.n_outputs, data.n_inputs
    (5, 1, 1)
    """

    @checked_call
    def __init__(self, w, response, dt=0.0, *, weights=None, std=None, coherence=None,
                 input_names=None, output_names=None):
        self.dt = check_dt(dt, allow_zero=True)
        self.w = _frequencies(w, self.dt)
        n = self.w.shape[0]
        self.response = _response(response, n)
        _, ny, nu = self.response.shape
        self.weights = None if weights is None else _per_frequency(
            weights, "weights", [(n,), (n, ny, nu)], positive=True)
        self.std = None if std is None else _per_frequency(
            std, "std", [(n, ny, nu)], positive=False)
        self.coherence = None
        if coherence is not None:
            coh = _per_frequency(coherence, "coherence", [(n, ny)], positive=False)
            if (coh > 1).any():
                raise DataError(f"FRData: coherence must lie in [0, 1]; "
                                f"{int((coh > 1).sum())} values exceed 1")
            self.coherence = coh
        self.input_names = _names(input_names, nu, "u", "input")
        self.output_names = _names(output_names, ny, "y", "output")

    # -- sizes ---------------------------------------------------------------
    @property
    def n_inputs(self) -> int:
        """Number of inputs ``nu``."""
        return self.response.shape[2]

    @property
    def n_outputs(self) -> int:
        """Number of outputs ``ny``."""
        return self.response.shape[1]

    @property
    def n_frequencies(self) -> int:
        """Number of frequencies."""
        return self.response.shape[0]

    def __len__(self) -> int:
        return self.n_frequencies

    # -- slicing -------------------------------------------------------------
    def __getitem__(self, index) -> "FRData":
        """The data at a slice or boolean mask of the frequencies (a new FRData)."""
        if isinstance(index, slice):
            if index.step is not None and index.step < 0:
                raise DataError("FRData: a reversed slice would unsort the frequencies; "
                                "use a positive step")
        else:
            mask = np.asarray(index)
            if mask.dtype != bool or mask.shape != (self.n_frequencies,):
                raise DataError(f"FRData: index by a slice or a boolean mask of "
                                f"{self.n_frequencies} frequencies, got "
                                f"{type(index).__name__}"
                                + (f" of dtype {mask.dtype} and shape {mask.shape}"
                                   if isinstance(index, np.ndarray) or isinstance(index, list)
                                   else ""))
            index = mask
        if not self.w[index].size:
            raise DataError("FRData: the selection holds no frequency")
        return self._take(index)

    def band(self, w_min=0.0, w_max=math.inf) -> "FRData":
        """The data at frequencies ``w_min <= w <= w_max`` (a new FRData).

        Parameters
        ----------
        w_min, w_max : float
            Band edges in radians per time unit (inclusive).

        Returns
        -------
        FRData
            Every per-frequency array cut to the band.

        Raises
        ------
        OptionError
            ``w_min > w_max`` or a non-numeric edge.
        DataError
            No frequency lies in the band.
        """
        try:
            lo, hi = float(w_min), float(w_max)
        except (TypeError, ValueError):
            raise OptionError(f"band: w_min and w_max must be numbers, got {w_min!r}, "
                              f"{w_max!r}") from None
        if math.isnan(lo) or math.isnan(hi) or lo > hi:
            raise OptionError(f"band: need w_min <= w_max, got {lo:g}, {hi:g}")
        mask = (self.w >= lo) & (self.w <= hi)
        if not mask.any():
            raise DataError(f"FRData.band: no frequency in [{lo:g}, {hi:g}]; the data "
                            f"span [{self.w[0]:g}, {self.w[-1]:g}] rad per time unit")
        return self._take(mask)

    def _take(self, index) -> "FRData":
        def cut(a):
            return None if a is None else a[index]
        return FRData(self.w[index], self.response[index], self.dt,
                      weights=cut(self.weights), std=cut(self.std),
                      coherence=cut(self.coherence), input_names=self.input_names,
                      output_names=self.output_names)

    # -- derived quantities --------------------------------------------------
    def fit_weights(self) -> np.ndarray:
        """The weights as an (n_freq, ny, nu) array (ones when none were given)."""
        n, ny, nu = self.response.shape
        if self.weights is None:
            return np.ones((n, ny, nu))
        if self.weights.ndim == 1:
            return np.broadcast_to(self.weights[:, None, None], (n, ny, nu)).copy()
        return self.weights.copy()

    def __repr__(self) -> str:
        timing = "continuous time" if self.dt == 0 else f"dt={self.dt:g}"
        return (f"FRData(n_frequencies={self.n_frequencies}, w=[{self.w[0]:.4g}, "
                f"{self.w[-1]:.4g}], inputs={list(self.input_names)}, "
                f"outputs={list(self.output_names)}, {timing})")
