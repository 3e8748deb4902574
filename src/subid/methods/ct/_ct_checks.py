"""Argument checks and defaults of :func:`subid.ct_subspace` (seed 002): the record,
the order, given filtered signals, the default basis size and the instrument lag."""

from __future__ import annotations

import math

import numpy as np

from subid._validation import check_int
from subid.data import IOData, not_a_record
from subid.errors import DataError, OrderError
from subid.methods.ct._ct_estimate import _correction_count
from subid.methods.ct.basis import FilterBank
from subid.methods.dt.checks import check_channels

#: Largest order of the default candidates (and what the default basis reveals).
DEFAULT_MAX_ORDER = 10
#: Polynomial degree of the input between samples for each hold.
HOLD_ORDERS = {"zoh": 0, "foh": 1}


#: Range of the mean sampling step the continuous-time methods accept, in the record's
#: time unit: their default basis and filters are not invariant to the time unit, and
#: beyond it the estimates degrade (steps of 1e-20 gave poles 10^4 times too slow
#: silently, 1e-300 a LinAlgError, 1e300 "SVD did not converge").
STEP_RANGE = (1e-12, 1e12)


def _check_data(data, method: str) -> IOData:
    if not isinstance(data, IOData):
        raise not_a_record(data, method, time="t=... or dt=...")
    check_channels(data)
    low, high = STEP_RANGE
    for e in data.experiments:
        if e.n_samples < 2:
            continue
        step = (float(e.t[-1]) - float(e.t[0])) / (e.n_samples - 1)
        if not low <= step <= high:
            raise DataError(f"{method}: the samples are {step:.3g} time units apart on "
                            f"average, outside the range {low:g} to {high:g} the "
                            "continuous-time methods handle: express time in other units "
                            "(IOData(u, y, t=t * c) or dt=dt * c; the model's poles then "
                            "scale by 1 / c)")
    std = np.array([e.y.std(axis=0) for e in data.experiments]).max(axis=0)
    flat = np.flatnonzero(std <= 1e-14 * np.maximum(np.abs(data.y).max(axis=0), 1e-300))
    if flat.size:
        names = ", ".join(data.output_names[k] for k in flat)
        raise DataError(f"output {names} is constant over the whole record: it carries no "
                        "information about the dynamics; drop that channel")
    for e in data.experiments:
        if e.n_samples < 2:
            continue
        # a spacing near the rounding of the time stamps themselves is known to few digits,
        # and every exact discretisation over it is wrong: say so instead of fitting noise
        # (the intervals of stamps of magnitude T are known to the rounding unit of T,
        # np.spacing(T): an interval of 1,000 of those is known to 0.1 %. The former bound,
        # 1e-9 T, refused epoch seconds, 1.7e9 with 5 ms steps known to 5e-5, as below
        # 1.7 s)
        t = e.t
        h = np.diff(t)
        resolution = RESOLUTION_UNITS * float(np.spacing(np.abs(t).max()))
        k = int(np.argmin(h))
        if h[k] <= resolution:
            raise DataError(f"{method}: the time stamps {t[k]!r} and {t[k + 1]!r} "
                            f"(rows {k}, {k + 1}) are {h[k]:.3g} apart, below the resolution "
                            f"of time stamps of magnitude {np.abs(t).max():.3g} "
                            f"({RESOLUTION_UNITS:g} times their rounding unit, "
                            f"{np.spacing(np.abs(t).max()):.3g}): the interval is known to "
                            "few digits. Merge the two samples, or resample; subtracting "
                            "the start time before the stamps are rounded (in the file) "
                            "keeps their digits")
    return data


#: Intervals between time stamps shorter than this many rounding units of the stamps'
#: magnitude (``np.spacing``) are refused: known to worse than 0.1 %.
RESOLUTION_UNITS = 1000.0


def _parse_order(order, max_order):
    """(fixed order or None, candidate orders)."""
    if order is None or (isinstance(order, str) and order == "auto"):
        return None, list(range(1, max_order + 1))
    if isinstance(order, dict):
        raise OrderError(f"order must be an integer, 'auto' (or None), or a list of "
                         f"candidate orders; got {order!r}"[:300])
    if isinstance(order, (str, bytes)) or not hasattr(order, "__iter__"):
        n = check_int(order, "order", minimum=1)
        if n > max_order:
            raise OrderError(f"order {n} cannot be revealed with this basis: the filtered "
                             f"outputs reveal at most {max_order} states (N p - p, at most "
                             f"{DEFAULT_MAX_ORDER}); use more basis functions")
        return n, [n]
    cands = sorted({check_int(k, "candidate order", minimum=1) for k in order})
    if not cands:
        raise OrderError("order is an empty list of candidate orders: give at least one "
                         "order, an integer, or 'auto'")
    cands = [k for k in cands if k <= max_order]
    if not cands:
        raise OrderError(f"every candidate order exceeds {max_order}, the largest this basis "
                         "reveals; use more basis functions")
    return None, cands


def _check_filtered(filtered, L, N, m, p):
    try:
        uf, yf = filtered
    except (TypeError, ValueError):
        raise DataError("filtered must be a pair (u_f, y_f) of arrays") from None
    uf = np.asarray(uf, dtype=float)
    yf = np.asarray(yf, dtype=float)
    if uf.shape != (L, N, m) or yf.shape != (L, N, p):
        raise DataError(f"filtered signals must have shapes {(L, N, m)} and {(L, N, p)} "
                        f"(samples, basis functions, channels), got {uf.shape} and "
                        f"{yf.shape}")
    if not (np.isfinite(uf).all() and np.isfinite(yf).all()):
        raise DataError("filtered signals contain NaN or infinite values")
    return uf, yf


def _default_size(data: IOData, poly_order, hold, feedthrough, startup, correction,
                  instruments, selection, data_equation="compact") -> int:
    """Number of functions of the default basis: ``max(8, ceil(10 / p) + 1)`` (enough to
    reveal order 10), fewer when the record (with ``selection='cv'``: its shortest fold,
    half of it) has too few samples for the data matrix (at least 2); with
    ``data_equation='paper'`` the matrix holds the paper's stacked input, N (N + 1) / 2
    rows per input (10 samples gave the paper's algorithm a basis of 3 functions and a
    model from a square data matrix)."""
    m, p, E = data.n_inputs, data.n_outputs, data.n_experiments
    wanted = max(8, -(-DEFAULT_MAX_ORDER // p) + 1)
    input_order = poly_order if hold is None or isinstance(hold, str) and hold not in \
        HOLD_ORDERS else HOLD_ORDERS[hold]
    corr = 0
    if correction:
        i0, j = _correction_count(poly_order, input_order, feedthrough is True)
        corr = max(0, j - i0 + 1)
    per = (E if startup else 0) + m + corr * m + p + (m if instruments == "past" else 0)
    samples = data.n_samples // 2 if selection == "cv" else data.n_samples
    size = int(max(2, min(wanted, (samples - 2 - E) // max(per, 1))))
    if data_equation == "paper":        # (per - m) N + m N (N + 1) / 2 rows
        while size > 2 and (per - m) * size + m * size * (size + 1) // 2 > samples - 2 - E:
            size -= 1
    return size


def _lag_for(bank: FilterBank, t: np.ndarray) -> int:
    """Lag of the 'past' instruments: about two time constants of the slowest filter."""
    slow = min(abs(z.real) for z in bank.poles)
    h = (t[-1] - t[0]) / (t.size - 1)
    return max(1, int(math.ceil(2.0 / (slow * h))))
