"""Validation of a model's matrices, channel names and time base (:class:`StateSpace`'s
constructor, its conversions and the model files share these checks)."""

from __future__ import annotations

import math
import numbers

import numpy as np

from subid.errors import DataError, ModelError

_EPS = np.finfo(np.float64).eps

#: Input holds a model may assume (:attr:`StateSpace.hold`).
HOLDS = ("zoh", "foh")


def _plural(count: int, word: str, plural: str | None = None) -> str:
    return f"{count} {word if count == 1 else (plural or word + 's')}"


def _as_matrix(value, name: str) -> np.ndarray:
    """``value`` as a finite float64 2-D read-only copy, or ModelError."""
    if value is None:
        raise ModelError(f"{name} is missing (None); pass a 2-D array")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{name} cannot be read as an array ({exc}); "
                         "pass a rectangular 2-D array of numbers") from None
    if arr.dtype == object:
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            raise ModelError(f"{name} holds values that are not numbers") from None
    if arr.dtype.kind == "c":
        raise ModelError(f"{name} is complex; state-space matrices must be real")
    if arr.dtype.kind not in "biuf":
        raise ModelError(f"{name} has dtype {arr.dtype}, which is not numeric")
    if arr.ndim != 2:
        hint = ""
        if arr.ndim == 1 and name == "B":
            hint = " (a single-input B is a column: pass B.reshape(-1, 1))"
        elif arr.ndim == 1 and name == "C":
            hint = " (a single-output C is a row: pass C.reshape(1, -1))"
        elif arr.ndim == 0:
            hint = " (a 1 x 1 matrix is written [[value]])"
        raise ModelError(f"{name} must be a 2-D array, got {arr.ndim}-D with shape "
                         f"{arr.shape}{hint}")
    arr = np.array(arr, dtype=np.float64, order="C", copy=True)
    bad = ~np.isfinite(arr)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        count = int(bad.sum())
        raise ModelError(f"{name} has {count} non-finite entr{'y' if count == 1 else 'ies'} "
                         f"(NaN or inf), the first at row {i}, column {j}; all "
                         "matrix entries must be finite")
    arr.setflags(write=False)
    return arr


def _model_dt(dt, name: str = "dt") -> float:
    if isinstance(dt, (bool, np.bool_)) or not isinstance(dt, numbers.Real):
        raise ModelError(f"{name} must be a number (0 for continuous time, the sampling "
                         f"period for discrete time), got {dt!r}")
    dt = float(dt)
    if not math.isfinite(dt) or dt < 0:
        raise ModelError(f"{name} must be finite and >= 0 (0 = continuous time), got {dt!r}")
    return dt


def _names(names, count: int, prefix: str, which: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{k + 1}" for k in range(count))
    if isinstance(names, str):
        names = [names]
    try:
        names = tuple(names)
    except TypeError:
        raise ModelError(f"{which} names must be a sequence of strings, got {names!r}") from None
    if not all(isinstance(nm, str) for nm in names):
        raise ModelError(f"{which} names must be strings, got {list(names)!r}")
    if len(names) != count:
        raise ModelError(f"{_plural(len(names), which + ' name')} {list(names)} given but the "
                         f"model has {_plural(count, which)}")
    if len(set(names)) != len(names):
        dup = sorted({nm for nm in names if names.count(nm) > 1})
        raise ModelError(f"{which} names repeat {dup}; names must be unique")
    return names


def _noise_matrices(K, noise_cov, n: int, p: int):
    """Validated read-only ``(K, noise_cov)``; each may be None."""
    if K is not None:
        K = _as_matrix(K, "K")
        if K.shape != (n, p):
            raise ModelError(f"K has shape {K.shape[0]}x{K.shape[1]} but the model has order "
                             f"{n} and {_plural(p, 'output')}: K must be {n} x {p} "
                             "(order x n_outputs)")
    if noise_cov is not None:
        S = _as_matrix(noise_cov, "noise_cov")
        if S.shape != (p, p):
            raise ModelError(f"noise_cov has shape {S.shape[0]}x{S.shape[1]} but the model has "
                             f"{_plural(p, 'output')}: it must be {p} x {p}")
        scale = max(float(np.abs(S).max()), 1e-300)
        if np.abs(S - S.T).max() > 1e-8 * scale:
            raise ModelError("noise_cov is not symmetric; it must be a covariance matrix")
        S = 0.5 * (S + S.T)
        if np.linalg.eigvalsh(S).min() < -1e-8 * scale:
            raise ModelError("noise_cov has a negative eigenvalue; it must be positive "
                             "semi-definite (a covariance matrix)")
        S.setflags(write=False)
        noise_cov = S
    return K, noise_cov


def _check_nonsingular(M: np.ndarray, what: str, why: str) -> None:
    """ModelError if ``M`` is singular to working precision."""
    sv = np.linalg.svd(M, compute_uv=False)
    if sv.size and not (sv[-1] > M.shape[0] * _EPS * sv[0]):
        cond = math.inf if sv[-1] == 0 else float(sv[0] / sv[-1])
        raise ModelError(f"{what} is singular (condition number {cond:.3g}); {why}")



def _is_scalar_zero(value) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, np.ndarray):
        return value.ndim == 0 and value.dtype.kind in "iuf" and value == 0
    return isinstance(value, (numbers.Number, np.generic)) and value == 0


def check_x0(x0, order: int, n_experiments: int = 1, *, estimate: bool = True):
    """The initial-state argument ``x0`` of the evaluation functions, checked once.

    The one validator of :func:`predict`, :func:`simulate_fit`,
    :func:`subid.fit_percent`, :func:`subid.residuals`, the figures and
    :func:`subid.simulation_bounds`, so that they accept the same values.

    Parameters
    ----------
    x0 : None, 'estimate', 'zero', 0 or array_like
        None or ``'estimate'``: the least-squares initial state (only with
        ``estimate=True``; otherwise None means zero); ``'zero'`` or the
        number 0: the zero state; an array: the initial state, of shape
        ``(order,)`` (a column or row of ``order`` entries is read as that),
        or ``(n_experiments, order)`` for a record of several experiments.
    order : int
        The model order n.
    n_experiments : int
        Number of experiments of the record.
    estimate : bool
        Whether the caller can estimate the initial state from data.

    Returns
    -------
    'estimate', 'zero' or ndarray
        An array of shape ``(order,)``, or ``(n_experiments, order)`` when
        ``n_experiments > 1``, of finite floats.

    Raises
    ------
    DataError
        ``x0`` is none of these (the message names what is accepted).
    """
    several = n_experiments > 1
    shape = (n_experiments, order) if several else (order,)
    modes = "'estimate' (or None), 'zero' (or 0)" if estimate else "None, 'zero' (or 0)"
    whose = (f"one initial state per experiment of the {n_experiments}" if several
             else "the initial state, n = the model order")
    accepted = f"x0 must be {modes} or an array of shape {shape} ({whose})"
    if x0 is None:
        return "estimate" if estimate else "zero"
    if isinstance(x0, str):
        if x0 == "zero" or (x0 == "estimate" and estimate):
            return x0
        raise DataError(f"{accepted}; got the string {x0!r}")
    if isinstance(x0, (bool, np.bool_)):
        raise DataError(f"{accepted}; got {x0!r}")
    if isinstance(x0, numbers.Number) or (isinstance(x0, np.ndarray) and x0.ndim == 0):
        if isinstance(x0, numbers.Real) or getattr(x0, "dtype", np.dtype(object)).kind in "iuf":
            if x0 == 0:
                return "zero"
        raise DataError(f"{accepted}; got the number {x0!r} (only 0 stands for the zero "
                        "state)")
    try:
        arr = np.asarray(x0)
    except (TypeError, ValueError):        # ragged nested sequences
        raise DataError(f"{accepted}; got a {type(x0).__name__} that is not an array"
                        ) from None
    if arr.dtype.kind not in "iuf":
        raise DataError(f"{accepted} of real numbers; got an array of dtype {arr.dtype}")
    if not several and arr.ndim == 2 and 1 in arr.shape and arr.size == order:
        arr = arr.reshape(-1)              # a column or a row of the n entries
    if arr.shape != shape:
        raise DataError(f"{accepted}; got shape {arr.shape}")
    arr = np.array(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise DataError("initial state x0 has NaN or infinite entries; give finite values "
                        "or x0='estimate'" if estimate else
                        "initial state x0 has NaN or infinite entries; give finite values")
    return arr


def reordered(model_names, data_names) -> bool:
    """True when ``data_names`` are the model's channel names (all distinct) in another
    order: a record whose columns are matched to the model by position would feed one
    channel where the model expects another. Other names (a record with names of its
    own) are not a reordering."""
    model_names, data_names = [str(n) for n in model_names], [str(n) for n in data_names]
    return data_names != model_names and sorted(data_names) == sorted(model_names) \
        and len(set(model_names)) == len(model_names)


def check_channel_order(model, data) -> None:
    """Raise :class:`DataError` when the record's input or output names are the model's in
    another order (:func:`reordered`): channels are matched by position, and swapped
    columns give a meaningless fit, prediction or residual analysis without any other
    sign (a 2x2 record with both pairs swapped: fit -16 % instead of 97 %). Shared by
    :func:`subid.fit_percent`, :func:`subid.predict`, :func:`subid.residuals` and the
    figures (through :func:`subid.model.prediction.check_model_data`); the command line
    has its own message naming ``--inputs`` / ``--outputs``."""
    for role, mine, theirs in (("inputs", model.input_names, data.input_names),
                               ("outputs", model.output_names, data.output_names)):
        if reordered(mine, theirs):
            order = [list(theirs).index(name) for name in mine]
            symbol = "u" if role == "inputs" else "y"
            raise DataError(
                f"the record's {role} {', '.join(map(str, theirs))} are the model's "
                f"({', '.join(map(str, mine))}) in a different order; channels are matched "
                "by position, so the result would be meaningless: put the record's columns "
                f"in the model's order (data.{symbol}[:, {order}], with the names in that "
                "order), or rename them if they are other channels")


def _initial_state(x0, n: int) -> np.ndarray:
    """The initial state ``x0`` of :meth:`StateSpace.simulate` (one experiment) as a
    float64 vector of length ``n`` (zeros for None), or DataError."""
    if x0 is None:
        return np.zeros(n)
    arr = np.asarray(x0)
    if arr.dtype.kind not in "biuf":
        raise DataError(f"initial state x0 must be real numbers, got dtype {arr.dtype}")
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.reshape(-1)
    if arr.shape != (n,):
        raise DataError(f"initial state x0 has shape {arr.shape} but the model order is "
                        f"{n}: x0 must have shape ({n},)")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise DataError("initial state x0 has NaN or infinite entries")
    return arr
