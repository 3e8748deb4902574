"""ARX models by QR least squares, and the orders of every polynomial method.

:func:`arx` fits the multi-output ARX model (Ljung, *System
Identification*, 2nd ed., 1999, Sec. 4.2 and 10.1, eq. 10.5)

    y(t) + A_1 y(t-1) + ... + A_na y(t-na) = B_0 u(t-nk) + ... + e(t)

by linear least squares: the regressors of every lag of every channel
(each channel divided by its RMS) are factored once by QR, and each output's
coefficients solve a small triangular problem on the columns of the factor
it uses (as :func:`subid.estimate_delay` does). The regression runs from
the first sample at which every lag exists (the samples before it are the
initial conditions), experiment by experiment for a record of several.

``orders='auto'`` (or None) chooses ``(na, nb, nk)`` from the estimation
record, MATLAB's ``arxstruc``/``selstruc`` idea with the selection rule of
the subspace defaults (:mod:`subid.methods.dt.selection`): for each of the
delays ``nk`` compared (per input from :func:`subid.estimate_delay`, one sample
on every input, and none unless the data show feedback, :data:`DELAY_HYPOTHESES`,
:func:`select_structure`), every ``na, nb``
in 1..10 is fitted on the training part of the four contiguous folds and scored
by its simulation fit on the held-out part (searched, for each delay hypothesis,
along ``na = nb``, then ``nb`` at the best ``na`` and ``na`` at the best ``nb``: 28
structures each, not the 100 of the full grid; per fold every structure's least squares comes from one
QR factorisation of the largest regressor, Ljung 1999, Ch. 10,
:mod:`subid.methods.dt._arx_nested`, and its score from a simulation over the
nonzero entries of its realisation, :mod:`subid.methods.dt._sparse_scoring`);
the structure of the least cross-validated BIC is chosen, ``2 N ny ln(100 - fit) + p ln N`` with ``p = ny (na ny + nb nu)``
parameters (the criterion of the subspace defaults,
:func:`subid.methods.crossval.criterion`, for an ARX parametrisation). As the subspace
defaults, the delays and the folds read at most the record's last
:data:`~subid.methods.crossval.MAX_SELECTION_SAMPLES` samples (``N`` their number;
``info['order_selection']['samples_used']``): ``arx(data)`` on 10^6 samples of a 2 x 2
system took 22 s, 20 of them in the search (5.0 s now, with the covariance below); the
model is fitted to the whole record.

The least squares of lagged regressors (:func:`regress`) form them a block of rows at a
time past :data:`REGRESS_BYTES`, each block folded into the triangular factor of those
before it, so a long record's regression holds one block, not the matrix and its copies.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Mapping

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import check_bool, check_choice, checked_call
from subid.data import IOData
from subid.errors import (
    DataError,
    NotExcitingError,
    OrderError,
    SubidError,
    TooFewSamplesError,
)
from subid.methods._info import collect_warnings, model_info
from subid.methods.crossval import (
    ABSOLUTE_TOLERANCE,
    FLOOR,
    MAX_ORDER,
    MAX_SELECTION_SAMPLES,
    experiment_folds,
    folds,
    selection_part,
)
from subid.methods.dt import _subspace
from subid.methods.dt._arx_nested import (
    RANK_TOL,
    NestedARX,
    channel_scales,
    check_samples,
    regression_start,
    solve_coefficients,
    unpack,
)
from subid.methods.dt._lagged_gram import contiguous_lags, lagged_gram
from subid.methods.dt._poly_covariance import attach_covariance
from subid.methods.dt._scoring import Held, simulation_fit
from subid.methods.dt._sparse_scoring import sparse_forced_error
from subid.methods.dt._trust_region import gram_factor
from subid.methods.dt.checks import check_data
from subid.methods.dt.feedthrough import feedback_test
from subid.model.polynomial import coefficients, polynomial_record, realise
from subid.model.statespace import StateSpace
from subid.statistic.hankel import geqrf_r

__all__ = ["arx", "parse_orders", "structure_orders", "fit_arx", "ORDER_NAMES",
           "polynomial_model", "check_polynomial_data", "regress", "lagged",
           "select_structure"]

#: The orders of each structure, in MATLAB's order.
ORDER_NAMES = {"arx": ("na", "nb", "nk"), "armax": ("na", "nb", "nc", "nk"),
               "oe": ("nb", "nf", "nk"), "bj": ("nb", "nc", "nd", "nf", "nk")}
SELECTIONS = ("cv",)


def check_polynomial_data(data, method: str) -> IOData:
    """The record a polynomial method may use (IOData, uniform, at least one input)."""
    data = check_data(data, method)
    if data.n_inputs == 0:
        raise DataError(f"{method} needs a record with at least one input")
    return data


def _order_array(value, shape, name: str, minimum: int, method: str) -> np.ndarray:
    """``value`` (a scalar or an array of integers) as an int array of ``shape``."""
    arr = np.asarray(value, dtype=object)
    flat = []
    for v in arr.ravel():
        integral = isinstance(v, numbers.Integral) or (
            isinstance(v, numbers.Real) and float(v).is_integer())
        if isinstance(v, (bool, np.bool_)) or not integral:
            raise OrderError(f"{method}: {name} must be a non-negative integer or an array "
                             f"of them, got {value!r}")
        flat.append(int(v))
    out = np.array(flat, dtype=np.int64).reshape(arr.shape)
    if out.ndim == 0:
        out = np.full(shape, int(out))
    elif out.size == np.prod(shape):
        out = out.reshape(shape)
    else:
        raise OrderError(f"{method}: {name} must be a scalar or have shape {shape} (one per "
                         f"{'output' if len(shape) == 1 else 'channel pair'}), got "
                         f"{np.shape(value)}")
    if (out < minimum).any():
        raise OrderError(f"{method}: {name} must be >= {minimum}, got {value!r}")
    return out


def _per_output(value, ny: int, structure: str):
    """``na`` of a model fitted output by output: one degree per output, or the diagonal
    of an (ny, ny) array of degrees (``model.info['orders']['na']``) whose other entries
    are zero."""
    arr = np.asarray(value, dtype=object)
    if arr.shape != (ny, ny) or ny == 1:
        return value
    if any(arr[i, j] != 0 for i in range(ny) for j in range(ny) if i != j):
        raise OrderError(f"{structure}: na {value!r} couples the outputs, but {structure} "
                         f"fits one model per output: give na per output, shape ({ny},)")
    return np.diagonal(arr)


def parse_orders(order, structure: str, ny: int, nu: int, nk_default=None) -> dict:
    """The orders of a polynomial structure from MATLAB's tuple or an integer.

    ``order`` is the tuple of :data:`ORDER_NAMES` (each a scalar or an array:
    ``na`` (ny, ny) for ARX, per output otherwise (or an (ny, ny) array that is zero
    off its diagonal); ``nb``, ``nf``, ``nk`` (ny, nu); ``nc``, ``nd`` per output), a
    dict of them by name (``model.info['orders']``), or an integer ``n``: every
    denominator (and ``C``, ``D``) of degree ``n``, ``nk = nk_default``
    (estimated delays) and ``nb = n``, plus one where ``nk = 0`` (a proper
    numerator), with a diagonal ``A`` for ARX (one autoregression per output).

    Returns
    -------
    dict of int arrays ``na`` (ny, ny), ``nb``, ``nk``, ``nf`` (ny, nu), ``nc``, ``nd`` (ny,)
    """
    names = ORDER_NAMES[structure]
    out = {"na": np.zeros((ny, ny), np.int64), "nb": np.zeros((ny, nu), np.int64),
           "nk": np.ones((ny, nu), np.int64), "nf": np.zeros((ny, nu), np.int64),
           "nc": np.zeros(ny, np.int64), "nd": np.zeros(ny, np.int64)}
    if isinstance(order, (bool, np.bool_, str, bytes, float)):
        raise OrderError(f"{structure}: order must be an integer or the tuple "
                         f"({', '.join(names)}), got {order!r}")
    if isinstance(order, (int, np.integer)):
        n = int(order)
        if n < 1:
            raise OrderError(f"{structure}: order must be >= 1, got {n}")
        nk = np.ones((ny, nu), np.int64) if nk_default is None else \
            np.broadcast_to(np.asarray(nk_default, np.int64), (ny, nu)).copy()
        out["nk"] = nk
        out["nb"] = n + (nk == 0).astype(np.int64)
        for key in names:
            if key in ("nc", "nd"):
                out[key] = np.full(ny, n, np.int64)
            elif key == "nf":
                out[key] = np.full((ny, nu), n, np.int64)
            elif key == "na":
                out[key] = n * np.eye(ny, dtype=np.int64) if structure == "arx" else \
                    np.diag(np.full(ny, n, np.int64))
        return out
    if isinstance(order, Mapping):           # model.info['orders'] of a fitted model
        if set(order) != set(names):
            raise OrderError(f"{structure}: a dict of orders needs exactly the keys "
                             f"{', '.join(names)}, got {', '.join(map(str, order)) or 'none'}")
        order = tuple(order[k] for k in names)
    try:
        items = list(order)
    except TypeError:
        raise OrderError(f"{structure}: order must be an integer or the tuple "
                         f"({', '.join(names)}), got {order!r}") from None
    if len(items) != len(names):
        raise OrderError(f"{structure}: the orders are ({', '.join(names)}): {len(names)} "
                         f"values, got {len(items)} ({order!r})")
    for key, value in zip(names, items):
        if key == "na":
            if structure == "arx":
                out["na"] = _order_array(value, (ny, ny), key, 0, structure)
            else:
                out["na"] = np.diag(_order_array(_per_output(value, ny, structure), (ny,),
                                                 key, 0, structure))
        elif key in ("nc", "nd"):
            out[key] = _order_array(value, (ny,), key, 0, structure)
        else:
            out[key] = _order_array(value, (ny, nu), key, 1 if key == "nb" and
                                    structure in ("oe", "bj") else 0, structure)
    delayed = (out["nb"] > 0) & (out["nb"] + out["nk"] >= 2)
    if not (out["na"].any() or out["nc"].any() or out["nd"].any() or out["nf"].any()
            or delayed.any()):
        raise OrderError(f"{structure}: the orders {order!r} ({', '.join(names)}) give a "
                         "model without dynamics (no state: no denominator, noise model or "
                         "delayed input term); give a positive degree to a denominator or "
                         "nb + nk >= 2 for an input"[:400])
    return out


def lagged(blocks, ranges, first: int):
    """``(Phi, t)``: the regressor matrix of lagged signals and the sample of each row.

    ``blocks`` is a list of ``(signal, lags)`` (1-D signal, iterable of lags
    >= 0); the rows are ``t = a + first .. b - 1`` of every experiment
    ``(a, b)`` of ``ranges``, column ``(s, lag)`` holding ``s[t - lag]``.
    """
    cols = [(s, lag) for s, lags in blocks for lag in lags]
    times = [np.arange(a + first, b) for a, b in ranges if b - a > first]
    t = np.concatenate(times) if times else np.zeros(0, dtype=np.int64)
    Phi = np.column_stack([s[t - lag] for s, lag in cols]) if cols else np.zeros((t.size, 0))
    return Phi, t


#: Past this many bytes of lagged regressors (and target), :func:`regress` forms them a
#: block of rows at a time and folds each block into the triangular factor of those before
#: it: the memory of a long record's regression is one block, not the matrix and its
#: copies (a 50th-order ARX start of ``oe`` on 10^6 samples of two inputs: 5.4 GB).
REGRESS_BYTES = 64 * 2**20


def _rows(blocks, t, target, out):
    """``[Φ(t) target(t)]`` of the rows ``t`` into ``out`` (len(t), m + 1)."""
    c = 0
    for s, lags in blocks:
        for lag in lags:
            np.take(s, t - lag, out=out[:, c])
            c += 1
    np.take(target, t, out=out[:, c])


def regress(target: np.ndarray, blocks, ranges, first: int):
    """Least squares of ``target[t]`` on lagged signals, experiment by experiment.

    ``blocks`` is a list of ``(signal, lags)`` (1-D signal, iterable of lags
    >= 0); rows ``t = a + first .. b - 1`` of every experiment ``(a, b)`` of
    ``ranges``. Returns ``theta, residual (full length, NaN before first),
    R`` (the triangular factor of the regressors, for rank decisions).

    By Householder QR of ``[Φ T]``; past :data:`REGRESS_BYTES`, of its blocks of rows
    in turn (``[R; Φ_k T_k] = Q R'``, the factor of the whole up to the signs of its rows,
    which the solution and the rank decisions do not see).
    """
    m = sum(len(lags) for _, lags in blocks)
    times = [np.arange(a + first, b) for a, b in ranges if b - a > first]
    t = np.concatenate(times) if times else np.zeros(0, dtype=np.int64)
    resid = np.full(target.shape[0], np.nan)
    rows = max(2 * (m + 1), int(REGRESS_BYTES // (8 * (m + 1))))
    if t.size <= rows:
        Phi, _ = lagged(blocks, ranges, first)
        T = target[t]
        R = geqrf_r(np.column_stack([Phi, T]), m + 1, overwrite=False)[:, :m + 1]
        theta = solve_coefficients(R, m)[:, 0]
        resid[t] = T - Phi @ theta
        return theta, resid, R[:m, :m]
    R = np.zeros((0, m + 1))
    for k in range(0, t.size, rows):
        tk = t[k:k + rows]
        stacked = np.empty((R.shape[0] + tk.size, m + 1), order="F")
        stacked[:R.shape[0]] = R
        _rows(blocks, tk, target, stacked[R.shape[0]:])
        R = geqrf_r(stacked, m + 1, overwrite=True)      # its first m + 1 rows only
        del stacked                      # one block in memory at a time
    theta = solve_coefficients(R, m)[:, 0]
    block = np.empty((min(rows, t.size), m + 1), order="F")
    for k in range(0, t.size, rows):
        tk = t[k:k + rows]
        _rows(blocks, tk, target, block[:tk.size])
        resid[tk] = block[:tk.size, m] - block[:tk.size, :m] @ theta
    return theta, resid, R[:m, :m]


def regress_start(target: np.ndarray, blocks, ranges, first: int):
    """:func:`regress` for a start value of a prediction-error search: ``(theta,
    residual)``.

    The normal equations from the Gram matrix of ``[Φ T]`` summed along its diagonals
    (:mod:`subid.methods.dt._lagged_gram`, ``N`` multiply-adds per diagonal instead of
    ``2 N (m + 1)^2`` flops for the QR: the 50th-order ARX start of ``oe`` on 10^6
    samples of two inputs 10 s -> 0.5 s an output), solved by Cholesky where the
    column-scaled Gram matrix of ``Φ`` has every pivot above
    :data:`subid.methods.dt._trust_region.GRAM_PIVOT` (at most about 8 digits lost, in a
    start the search then moves); else, or where a block's lags are not consecutive,
    :func:`regress`. The residual is ``target - Φ θ`` (NaN before ``first``), each
    block's part one convolution.
    """
    lags = contiguous_lags(blocks)
    m = sum(len(lags) for _, lags in blocks)
    if lags is not None and m:
        G = lagged_gram(target, blocks, ranges, first)
        norms = np.sqrt(np.maximum(np.diag(G)[:m], 0.0))
        Rs = gram_factor(G[:m, :m] / norms[:, None] / norms[None, :]) \
            if np.all(norms > 0) and np.isfinite(G).all() else None
        if Rs is not None:
            R = Rs * norms[None, :]                       # R^T R = Φ^T Φ
            theta = scipy.linalg.solve_triangular(
                R, scipy.linalg.solve_triangular(R, G[:m, m], trans="T", check_finite=False),
                check_finite=False)
            resid = np.full(target.shape[0], np.nan)
            for a, b in ranges:
                if b - a <= first:
                    continue
                fitted = np.zeros(b - a)
                at = 0
                for (s, _), lo, count in zip(blocks, *lags):
                    # Σ_i θ_i s(t - lo - i): the first b - a - lo samples of s * θ, from lo
                    fitted[lo:] += np.convolve(s[a:b], theta[at:at + count])[:b - a - lo]
                    at += count
                resid[a + first:b] = target[a + first:b] - fitted[first:]
            return theta, resid
    theta, resid, _ = regress(target, blocks, ranges, first)
    return theta, resid


def _check_input_columns(R, labels, method: str):
    """NotExcitingError when an input lag of the regression repeats the earlier ones."""
    norms = np.linalg.norm(R, axis=0)
    for k, label in enumerate(labels):
        if norms[k] == 0 or abs(R[k, k]) <= RANK_TOL * norms[k]:
            raise NotExcitingError(
                f"{method}: the input is not sufficiently exciting: {label} is a linear "
                "combination of the earlier input samples (or zero), so the input "
                "coefficients are not determined. Use a richer input (white noise, PRBS, "
                "multisine) or fewer input coefficients (nb)",
                required_order=len(labels), achieved_order=k)


def fit_arx(data: IOData, orders: dict, *, method: str = "arx", check: bool = True):
    """The ARX polynomials of ``orders`` (a :func:`parse_orders` dict) by least squares.

    Every channel is divided by its RMS for the regression and the
    coefficients scaled back. Returns ``(A, B, residuals, info)`` with ``A``
    (ny, ny, na+1), ``B`` (ny, nu, max(nk+nb)), the one-step residuals (NaN
    over the initial conditions) and the regression's rank profile and
    condition number.
    """
    u, y = data.u, data.y
    ny, nu = y.shape[1], u.shape[1]
    su, sy = channel_scales(u, y)
    un, yn = u / su, y / sy
    na, nb, nk = orders["na"], orders["nb"], orders["nk"]
    first = regression_start(orders)
    n_params = int(na.sum(axis=1).max() + nb.sum(axis=1).max())
    check_samples(data.experiment_ranges, data.n_samples, n_params, first, method)
    A = np.zeros((ny, ny, int(na.max(initial=0)) + 1))
    A[:, :, 0] = np.eye(ny)
    B = np.zeros((ny, nu, int((nk + nb).max(initial=1))))
    resid = np.empty_like(y)
    profile, conds = [], []
    ranges = data.experiment_ranges
    for i in range(ny):
        blocks = [(un[:, j], range(nk[i, j], nk[i, j] + nb[i, j])) for j in range(nu)]
        labels = [f"input {data.input_names[j]} at lag {lag}" for j in range(nu)
                  for lag in range(nk[i, j], nk[i, j] + nb[i, j])]
        blocks += [(yn[:, k], range(1, na[i, k] + 1)) for k in range(ny)]
        theta, r, R = regress(yn[:, i], blocks, ranges, first)
        if check:
            _check_input_columns(R[:len(labels), :len(labels)], labels, method)
        profile.append(np.abs(np.diag(R)))
        conds.append(float(np.max(np.abs(np.diag(R))) / max(np.min(np.abs(np.diag(R))),
                                                              1e-300)) if R.size else 1.0)
        unpack(theta, i, orders, su, sy, A, B)
        resid[:, i] = r * sy[i]
    return A, B, resid, {"rank_profile": np.sort(np.concatenate(profile))[::-1],
                         "regression_condition": max(conds)}


def predictor_x0(model: StateSpace, data: IOData):
    """Least-squares initial state(s) of the one-step predictor of ``model`` on ``data``
    (one row per experiment; a vector for a single experiment)."""
    from subid.methods.dt._pe_search import _predictor, _start_x0
    K = model.K if model.K is not None else np.zeros((model.order, model.n_outputs))
    Ap, Bp, Cp, Dp = _predictor(model.A, model.B, model.C, model.D, K, "prediction")
    v = np.hstack([data.u, data.y])
    if model.order == 0:
        return np.zeros(0)
    rows = [_start_x0(Ap, Bp, Cp, Dp, v[a:b], data.y[a:b]) for a, b in data.experiment_ranges]
    return rows[0] if len(rows) == 1 else np.stack(rows)


def polynomial_model(data: IOData, poly: dict, *, method: str, order_selection=None,
                     residuals=None, conditions=None, **extra) -> StateSpace:
    """The StateSpace of the polynomials ``poly`` with the core ``info`` keys.

    ``residuals`` (N, ny) give ``noise_cov`` (samples with NaN, the initial
    conditions, left out); ``info['x0']`` is the predictor's initial state
    by least squares.
    """
    A, B, C, D, K = realise(poly)
    ny = data.n_outputs
    if residuals is not None:
        r = residuals[np.isfinite(residuals).all(axis=1)]
        noise_cov = r.T @ r / max(r.shape[0], 1)
    else:
        noise_cov = np.eye(ny)
    with np.errstate(all="ignore"):
        base = StateSpace(A, B, C, D, data.dt, input_names=data.input_names,
                          output_names=data.output_names, K=K, noise_cov=noise_cov)
        x0 = predictor_x0(base, data) if A.shape[0] else np.zeros(0)
    info = model_info(method, order=A.shape[0], order_selection=order_selection, horizon=None,
                      n_samples=data.n_samples, x0=x0, hold="zoh", conditions=conditions,
                      **extra)
    info["polynomials"] = poly
    info.update(_subspace.check_stability(A, data, method) if A.shape[0] else {})
    predictor = A - K @ C
    info["predictor_spectral_radius"] = float(np.abs(np.linalg.eigvals(predictor)).max()) \
        if A.shape[0] else 0.0
    info["noise_model"] = "the polynomial model's own (C/(A D))"
    return base.with_noise_model(K, noise_cov, info=info)


def _arx_record(A, B, orders) -> dict:
    ny, nu = B.shape[:2]
    return polynomial_record("arx", A=A, B=B, C=np.ones((ny, 1)), D=np.ones((ny, 1)),
                             F=np.ones((ny, nu, 1)), na=orders["na"], nb=orders["nb"],
                             nc=np.zeros(ny), nd=np.zeros(ny), nf=np.zeros((ny, nu)),
                             nk=orders["nk"])


#: The delays :func:`select_structure` compares besides :func:`subid.estimate_delay`'s:
#: none (unless the data show feedback) and one sample on every input.
DELAY_HYPOTHESES = (0, 1)


def select_structure(data: IOData, max_order: int = MAX_ORDER):
    """``(orders, record)``: ``(na, nb, nk)`` chosen by cross-validation (module docstring).

    The delays are part of the structure compared, as in MATLAB's ``arxstruc`` grid:
    the estimate of :func:`subid.estimate_delay` and every input at each delay of
    :data:`DELAY_HYPOTHESES`, each searched over ``na, nb`` alike, the structure of the
    least cross-validated BIC over all (ties to the estimate). The estimate alone
    overstated the delays of DaISy steamgen (2, 2, 4, 4 samples against 1: 70.1 %
    validation fit against 76.4 %, ``bench/realdata.py``) and ballbeam (8 against 1: 86.7
    against 89.7 %). Where the data show feedback (the test of
    ``feedthrough='auto'``, :func:`subid.methods.dt.feedthrough.decide`), no delay of zero
    is added to the estimate's: the lag-0 correlation of u and y is then no evidence of a
    direct term (a feedback without delay gives the same), and the folds, which see the
    same loop, prefer it (issue 21's closed loop, the seed-001 plant without feedthrough
    under u = r + 0.5 y: the default ``arx`` took no delay on both inputs and its median
    Markov error went from 0.17 to 0.40 over six runs).
    """
    ny, nu = data.n_outputs, data.n_inputs
    # the delays and the folds from the record's last MAX_SELECTION_SAMPLES samples at
    # most, as the subspace methods' cross-validation
    # (subid.methods.dt.selection.cross_validate): on 10^6 samples of a 2x2 system the
    # search took 20 of the call's 22 s; the model is then fitted to the whole record
    used = selection_part(data)
    estimated = _delays(used)
    feedback = feedback_test(used)
    hypotheses = [] if estimated is None else [estimated]
    for delay in DELAY_HYPOTHESES:
        nk = np.full(nu, delay, np.int64)
        if delay == 0 and feedback.get("detected"):
            continue
        if not any(np.array_equal(nk, h) for h in hypotheses):
            hypotheses.append(nk)
    if used.n_experiments > 1:
        parts = experiment_folds(used)
    else:
        parts = [(used[a], used[b]) for a, b in folds(used.n_samples)]
    # the validation blocks' scoring data, computed once (what every candidate shares)
    held = [Held(validation) for _, validation in parts]
    scores: dict = {}                    # (nk, na, nb) -> mean fold score

    grid = range(1, max_order + 1)
    N = used.n_samples

    def bic(key):            # the cross-validated BIC of the subspace defaults, ARX parameters
        misfit = max(100.0 - scores[key], ABSOLUTE_TOLERANCE)
        params = ny * (key[1] * ny + key[2] * nu)
        return 2.0 * N * ny * np.log(misfit) + params * np.log(N)

    def scorer(nk):
        """The function scoring ``(na, nb)`` at the delays ``nk`` into ``scores``: per
        fold, one QR gives every structure's regression (Ljung 1999, Ch. 10;
        :mod:`subid.methods.dt._arx_nested`)."""
        nested = [NestedARX(train, nk, max_order, max_order) for train, _ in parts]
        key = tuple(int(v) for v in nk)

        def score(na, nb):
            if (key, na, nb) in scores:
                return
            orders = parse_orders((na, nb, np.tile(nk, (ny, 1))), "arx", ny, nu)
            values = []
            try:
                for fold, validation in zip(nested, held):
                    A, B = fold.fit(orders)
                    Ass, Bss, Css, Dss, _ = realise(_arx_record(A, B, orders))
                    values.append(_sparse_fit_score(Ass, Bss, Css, Dss, validation))
            except SubidError:
                return
            scores[(key, na, nb)] = float(np.mean(values))
        return key, score

    def best(key, pairs):
        pairs = [p for p in pairs if (key,) + p in scores]
        return max(pairs, key=lambda p: (scores[(key,) + p], -p[0] - p[1])) if pairs else None

    # every delay hypothesis searched alike: along na = nb, then nb at the best na and na
    # at the best nb (28 structures each). Searching the lines at the delays of the least
    # criterion along na = nb only (28 structures and 10 for each other hypothesis, a
    # third less time) made the same DaISy choices but lost elsewhere: on the heating
    # system of bench/external_records.md the delays went 1 -> 2 and oe's default fit
    # 85.1 -> 80.1 %, on the cascaded tanks arx's 71.1 -> 69.7 %
    scorers = [scorer(nk) for nk in hypotheses]
    for key, score in scorers:
        for k in grid:
            score(k, k)
        top = best(key, [(k, k) for k in grid])
        if top is None:
            continue
        for nb in grid:
            score(top[0], nb)
        top = best(key, [(top[0], nb) for nb in grid])
        for na in grid:
            score(na, top[1])
    if not scores:
        raise TooFewSamplesError("arx: the record is too short to compare ARX structures "
                                 "by cross-validation; give the orders (na, nb, nk)")
    rank = {key: r for r, (key, _) in enumerate(scorers)}

    def preference(k):       # the least criterion; ties to the earlier delays, fewer terms
        return bic(k), rank[k[0]], k[1] + k[2], k[1]
    chosen = min(scores, key=preference)
    key_nk, na, nb = chosen
    nk = np.asarray(key_nk, np.int64)
    record = {"rule": "cv",
              "description": ("ARX structures (na, nb in 1.."f"{max_order} along na = nb, "
                              "then nb, then na; nk the estimate of estimate_delay, 1 on "
                              "every input, and 0 without feedback) scored by four-fold "
                              "contiguous "
                              "cross-validation (simulation fit % on the held-out part; at "
                              f"most the last {MAX_SELECTION_SAMPLES} samples); "
                              "the structure of the least cross-validated BIC"),
              "delays": {"estimated": None if estimated is None else estimated.tolist(),
                         "compared": [h.tolist() for h in hypotheses],
                         "feedback": feedback},
              "candidates": [{"nk": list(k[0]), "na": k[1], "nb": k[2], "score": v,
                              "criterion": bic(k)} for k, v in sorted(scores.items())],
              "selected": {"na": na, "nb": nb, "nk": nk.tolist(), "score": scores[chosen]},
              "samples_used": used.n_samples}
    return parse_orders((na, nb, np.tile(nk, (ny, 1))), "arx", ny, nu), record


def _sparse_fit_score(A, B, C, D, held) -> float:
    """The score of :func:`subid.methods.dt.selection._fit_score` (mean simulation fit %,
    clipped below at ``FLOOR``) of a discrete model whose realisation is mostly
    zeros, by the same pass over its nonzero entries only
    (:func:`subid.methods.dt._sparse_scoring.sparse_forced_error`: the same value)."""
    fits = simulation_fit(A, B, C, D, held, kernel=sparse_forced_error)
    if fits is None:
        return FLOOR
    value = float(np.mean(fits))
    return max(value, FLOOR) if np.isfinite(value) else FLOOR


def _delays(data) -> np.ndarray | None:
    """``nk`` per input by :func:`subid.estimate_delay` (None when the record is too short):
    up to 10 samples, and beyond where the wide search
    (:func:`subid.delay.wide_delay_search`) finds a delay whose ARX loss is at most
    :data:`subid.delay.DELAY_LOSS_SHARE` of the undelayed one's. Behind 20 samples of
    dead time (1000 samples) the narrow search alone gave ``arx``'s default 3.0 % and
    ``oe``'s 81.7 % of validation fit; 90.1 and 90.3 % with the wide one."""
    from subid.delay import DELAY_LOSS_SHARE, estimate_delay, wide_delay_search
    ny, nu = data.n_outputs, data.n_inputs
    max_delay = int(min(10, max(data.n_samples // (20 * (nu + ny + 1)) - 3, 0)))
    try:
        nk = np.asarray(estimate_delay(data, max_delay=max_delay), np.int64)
    except SubidError:
        return None
    search = wide_delay_search(data)
    if "nk" in search:
        far, share = search["nk"], search["loss_share"]
        confirmed = (far > max_delay) & (share <= DELAY_LOSS_SHARE)
        nk[confirmed] = far[confirmed]
    return nk


def output_error_order(data):
    """``(n, record)``: the order of ``oe``'s default structure, ``n`` the order that
    :func:`subid.moesp` chooses by cross-validation on ``data`` (None, with the reason,
    when it raises a :class:`subid.errors.SubidError`).

    The output-error criterion is the simulation error, which the subspace methods'
    cross-validated choice scores on held-out folds (:mod:`subid.methods.dt.selection`);
    the ARX structure search scores the same fits, but of ARX models, whose one-step
    predictor needs its own degrees: on an oversampled plant (a 2nd-order system at
    1 kHz) it chose ``na = 1, nb = 10``, and ``oe`` with those degrees validated at
    -33.8 % against 97.8 % at ``n = 2`` (the order MOESP chooses there). On the DaISy
    records (bench/realdata.md, with the searches from every start) ``oe``'s default
    validates within 3 points of the oracle on 8 of 9 records instead of 6 (exchanger
    56.2 -> 61.3 %, CD_player_arm 79.7 -> 81.7 %), worse only on ballbeam (an unstable
    plant under feedback, where ``oe`` is biased and warns: 30.7 -> 8.0 %). ``record`` is ``info['order_selection']``: the rule, the order
    and MOESP's own selection record (``'subspace'``)."""
    from subid.methods.dt.moesp import moesp
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = moesp(data)
    except SubidError as exc:
        return None, {"rule": "subspace", "order": None,
                      "reason": f"{type(exc).__name__}: {exc}"}
    return model.order, {
        "rule": "subspace", "order": model.order, "method": "moesp",
        "description": f"n = {model.order}, the order moesp chooses by cross-validation "
                       "(simulation fit on held-out folds, the output-error criterion); "
                       "nf = n, nb = n (n + 1 where nk = 0), nk from estimate_delay",
        "subspace": model.info.get("order_selection")}


def structure_orders(order, structure: str, data: IOData):
    """``(orders, order_selection)`` of a polynomial method's ``order`` argument.

    None/'auto': for ``oe``, the integer order of :func:`output_error_order` (the
    subspace methods' cross-validated order); for the others the ARX structure
    chosen by :func:`select_structure`, its degrees ``n = max(na)``, ``nb`` and ``nk``
    used for ``armax`` and ``bj`` (``(n, nb, n, nk)``, ``(nb, n, n, n, nk)``). An
    integer: :func:`parse_orders` with the delays of :func:`subid.estimate_delay` on
    the part of the record the search reads
    (:func:`subid.methods.crossval.selection_part`). A tuple: :func:`parse_orders`.
    """
    ny, nu = data.n_outputs, data.n_inputs
    auto = order is None or (isinstance(order, str) and order == "auto")
    record = None
    if auto and structure == "oe":
        n, record = output_error_order(data)
        if n is not None:             # the integer order n, its delays as below
            order, auto = n, False
    if auto:
        subspace = record             # oe: why output_error_order found no order
        orders, record = select_structure(data)
        if structure == "arx":
            return orders, record
        n, nb, nk = int(orders["na"].max()), orders["nb"], orders["nk"]
        given = {"armax": (n, nb, n, nk), "oe": (nb, n, nk), "bj": (nb, n, n, n, nk)}[structure]
        record = dict(record, description=f"the degrees of the cross-validated ARX structure "
                                          f"(n = {n}, nb, nk): " + record["description"])
        if subspace is not None:
            record["subspace"] = subspace
        return parse_orders(given, structure, ny, nu), record
    integer = isinstance(order, (int, np.integer)) and not isinstance(order, bool)
    # the delays of an integer order from the part of the record the structure search
    # reads (the whole of 10^6 samples cost 0.75 GB in estimate_delay's regressors)
    nk = _delays(selection_part(data)) if integer and order >= 1 else None
    return parse_orders(order, structure, ny, nu, nk_default=nk), record


@serial_blas
@checked_call
def arx(data, order=None, *, selection="cv", estimate_x0=True):
    """Identify an ARX model by least squares (MATLAB ``arx``).

    Parameters
    ----------
    data : IOData
        Uniformly sampled record with at least one input (several
        experiments: :func:`subid.merge`; no regression row spans two).
    order : tuple, dict, int, 'auto' or None
        MATLAB's ``(na, nb, nk)``: ``na`` a scalar or a (ny, ny) array of the
        degrees of the entries of the matrix polynomial ``A(q)`` (a scalar
        means every entry, as in MATLAB), ``nb`` the number of coefficients
        and ``nk`` the delay of each input (scalars or (ny, nu) arrays; nk=0
        for direct feedthrough). An integer ``n``: ``na = n`` on the diagonal
        (one autoregression per output), ``nk`` from
        :func:`subid.estimate_delay`, ``nb = n`` (``n + 1`` where ``nk = 0``).
        ``None``/``'auto'``: chosen by cross-validation (module docstring).
        A dict of them by name (``model.info['orders']``) reproduces the
        structure of ``model``.
    selection : {'cv'}
        The rule of the structure choice (cross-validation, the rule of the
        subspace defaults).
    estimate_x0 : bool
        Estimate the initial state of the model's one-step predictor
        (``info['x0']``); the regression itself starts at the first sample
        where every lag exists.

    Returns
    -------
    StateSpace
        The innovation form of the ARX model (noise model ``1/A``: ``K``
        and ``noise_cov``, the residual covariance) with
        ``info['polynomials']`` (:mod:`subid.model.polynomial`).

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, or no input.
    OrderError
        Orders that are not non-negative integers of the right shapes.
    NotExcitingError
        An input lag of the regression is a combination of the others.
    TooFewSamplesError
        Fewer samples than the coefficients need.

    Examples
    --------
    >>> import numpy as np, subid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(500)
    >>> y = np.zeros(500)
    >>> for t in range(2, 500):
    ...     y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + u[t - 1] + 0.5 * u[t - 2]
    >>> model = subid.arx(subid.IOData(u, y, dt=1.0), (2, 2, 1))
    >>> np.round(model.info["polynomials"]["A"][0, 0], 6)
    array([ 1. , -1.5,  0.7])
    """
    check_choice(selection, "selection", SELECTIONS)
    check_bool(estimate_x0, "estimate_x0")
    data = check_polynomial_data(data, "arx")
    with collect_warnings() as issued:
        orders, record = structure_orders(order, "arx", data)
        A, B, resid, reg = fit_arx(data, orders)
        poly = _arx_record(A, B, orders)
        model = polynomial_model(data, poly, method="arx", order_selection=record,
                                 residuals=resid,
                                 conditions={"regression": reg["regression_condition"]},
                                 rank_profile=reg["rank_profile"],
                                 orders={"na": orders["na"], "nb": orders["nb"],
                                         "nk": orders["nk"]})
        _arx_covariance(model, data, orders)
        if not estimate_x0:
            model.info["x0"] = None
    model.info["warnings"] = list(issued)
    return model


def _arx_covariance(model: StateSpace, data: IOData, orders: dict) -> StateSpace:
    """``info['parameter_covariance']`` of an ARX model: ``Λ``-weighted ``(Φ^T Φ)^-1``
    per output from the QR factor of each output's regressors (Ljung 1999, eq. 9.20;
    :mod:`subid.methods.dt._poly_covariance`). The regressor of ``A[i, k]`` at lag
    ``l`` is ``-y_k(t - l)``, of ``B[i, j]`` at lag ``l`` ``u_j(t - l)``."""
    ny, nu = data.n_outputs, data.n_inputs
    na, nb, nk = orders["na"], orders["nb"], orders["nk"]
    first = regression_start(orders)
    designs: list[np.ndarray] = []
    times = None
    for i in range(ny):
        if i and (na[i] == na[0]).all() and (nb[i] == nb[0]).all() and (nk[i] == nk[0]).all():
            designs.append(designs[0])      # the same regressors: one array, factored once
            continue
        blocks = [(-data.y[:, k], range(1, na[i, k] + 1)) for k in range(ny)]
        blocks += [(data.u[:, j], range(nk[i, j], nk[i, j] + nb[i, j])) for j in range(nu)]
        Phi, times = lagged(blocks, data.experiment_ranges, first)
        designs.append(Phi)
    residuals = data.y[times] - np.column_stack(
        [Phi @ c for Phi, c in zip(designs, np.split(coefficients(model.info["polynomials"]),
                                                       np.cumsum([J.shape[1]
                                                                  for J in designs])[:-1]))])
    return attach_covariance(model, designs, residuals, [0] * ny,
                             "least-squares covariance, per output Lambda_ii (Phi_i^T "
                             "Phi_i)^-1 with the outputs' cross-covariances (Ljung 1999, "
                             "eq. 9.20), mapped to the realisation's matrices")

