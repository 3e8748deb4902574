"""Input delays: estimate them, remove them from data, and keep them on models.

A discrete-time model with input delays ``d_j`` (in samples) is

    x[k+1] = A x[k] + sum_j B[:, j] u_j[k - d_j],
    y[k]   = C x[k] + sum_j D[:, j] u_j[k - d_j].

:func:`estimate_delay` finds ``nk_j``, the lag of the first input sample that
reaches the output, as MATLAB's ``delayest`` counts it: ``nk = 1`` for a
strictly proper model (``D = 0``) without extra delay, ``nk = 0`` with a
direct feedthrough. So the extra dead time of a strictly proper model is
``nk - 1``; of a model with feedthrough, ``nk``.

The discrete-time batch methods take ``input_delay`` (one integer per input,
or one for all): the record is shifted with :func:`delay_inputs` so that the
method sees ``u_j[k - d_j]`` as its input, and the delays are recorded in
``model.info['input_delay']``, which :meth:`subid.StateSpace.simulate` and
:meth:`subid.StateSpace.freqresp` honour (see :func:`apply_to_inputs` and
:func:`frequency_factor`). :func:`absorb_delay` turns the delays into states
(shift registers) for tools that know no delays (exports, ``markov``).
"""

from __future__ import annotations

import numbers

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import check_int, checked_call
from subid.data import IOData, column_std
from subid.errors import (
    DataError,
    ModelError,
    NotExcitingError,
    ResourceLimitError,
    TooFewSamplesError,
)

__all__ = ["estimate_delay", "delay_search_limit", "wide_delay_search", "DELAY_LOSS_SHARE",
           "delay_inputs", "apply_to_inputs", "frequency_factor", "absorb_delay",
           "input_delay_of"]

INFO_KEY = "input_delay"
#: Past this many bytes of regression rows, :func:`estimate_delay` folds them into its
#: triangular factor a block at a time.
REGRESSION_BYTES = 16 * 2**20


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------
def _check_delays(input_delay, n_inputs: int, error=DataError) -> np.ndarray:
    """``input_delay`` as an int array of length ``n_inputs`` (>= 0)."""
    if isinstance(input_delay, (bool, np.bool_)):
        raise error(f"input_delay must be a non-negative integer or one per input, "
                    f"got {input_delay!r}")
    if isinstance(input_delay, (numbers.Integral, np.integer)):
        values = np.full(n_inputs, int(input_delay))
    else:
        try:
            arr = np.asarray(input_delay)
        except (TypeError, ValueError):
            arr = np.asarray([object()])
        if arr.ndim != 1 or arr.dtype.kind not in "iu" and not (
                arr.dtype.kind == "f" and np.all(np.isfinite(arr))
                and np.all(arr == np.round(arr))):
            raise error(f"input_delay must be a non-negative integer or a list of "
                        f"{n_inputs} of them (one per input, in samples), got {input_delay!r}")
        if arr.size != n_inputs:
            raise error(f"input_delay has {arr.size} entries but there "
                        f"{'is' if n_inputs == 1 else 'are'} {n_inputs} input"
                        f"{'' if n_inputs == 1 else 's'}: give one delay per input "
                        "(or one integer for all)")
        values = arr.astype(np.int64)
    if (values < 0).any():
        raise error(f"input_delay must be >= 0 samples, got {values.tolist()}")
    return values


# ---------------------------------------------------------------------------
# estimation
# ---------------------------------------------------------------------------
#: The largest delay the automatic searches try (:func:`delay_search_limit`).
DELAY_SEARCH = 50
#: A delay a wide automatic search finds is taken only when the ARX loss with it
#: (:func:`estimate_delay`'s, na = nb = 2) is at most this share of the loss without one
#: (``nk = 1``): a dead time leaves the undelayed regression nothing to explain. Measured
#: shares: real dead times of 3-40 samples 0.07-0.17, DaISy dryer's 0.19; the spurious
#: delays a low-order ARX finds in lightly damped structures of 10-30 states (6-14
#: samples) and in an oversampled plant (28 samples, relative degree 2 at 1 kHz), and on
#: the other DaISy records, 0.93-1.00.
DELAY_LOSS_SHARE = 0.5


def delay_search_limit(n_samples: int, n_inputs: int, n_outputs: int) -> int:
    """The ``max_delay`` of the wide automatic delay searches (the dead time of
    :func:`subid.identify`, the long delays of the polynomial defaults):
    :data:`DELAY_SEARCH`, fewer where the record holds fewer than ten samples per column
    of its regression (``na = nb = 2``); negative when the record is too short to look.
    Their delays are taken only under :data:`DELAY_LOSS_SHARE`: a wide search alone found
    ``nk = 28`` on an oversampled plant (relative degree 2 at 1 kHz, true 1-2), and
    ``oe``'s default then validated at 78.9 % against 95 %+."""
    return min(DELAY_SEARCH, n_samples // (10 * n_inputs) - 2 * n_outputs - 2)


#: Samples (the last ones of the last experiment) :func:`wide_delay_search` reads at most.
WIDE_SEARCH_SAMPLES = 5_000


def wide_delay_search(data) -> dict:
    """The wide automatic delay search of :func:`subid.identify` (its dead time) and of the
    polynomial defaults (their long delays): :func:`estimate_delay` up to
    :func:`delay_search_limit` on the last :data:`WIDE_SEARCH_SAMPLES` samples of the
    last experiment.

    Returns ``{'samples', 'searched', 'nk', 'loss_share'}``: ``nk`` per input, and
    ``loss_share`` the ARX loss at that ``nk`` over the loss at ``nk = 1`` (1 where ``nk
    <= 1``); a delay is confirmed where its share is at most :data:`DELAY_LOSS_SHARE`.
    When the record is too short to look, or the search fails, ``{'samples',
    'searched', 'reason'}``."""
    from subid.errors import SubidError
    part = data.experiments[-1]
    if part.n_samples > WIDE_SEARCH_SAMPLES:
        part = part[part.n_samples - WIDE_SEARCH_SAMPLES:]
    largest = delay_search_limit(part.n_samples, part.n_inputs, part.n_outputs)
    out = {"samples": part.n_samples, "searched": max(largest, 0)}
    if largest < 2:
        return dict(out, reason="too few samples to look for a delay")
    try:
        nk, loss = estimate_delay(part, largest, return_loss=True)
    except SubidError as exc:
        return dict(out, reason=f"{type(exc).__name__}: {exc}")
    nk = np.asarray(nk, dtype=int)
    share = np.array([loss[j, nk[j]] / loss[j, 1] if nk[j] >= 2 and loss[j, 1] > 0 else 1.0
                      for j in range(nk.size)])
    return dict(out, nk=nk, loss_share=share)


@serial_blas
@checked_call
def estimate_delay(data, max_delay: int = 10, *, na: int = 2, nb: int = 2,
                   return_loss: bool = False):
    """Estimate the delay of every input, in samples (MATLAB ``delayest``).

    For each input ``j`` and each candidate ``nk`` in ``0..max_delay`` an ARX
    model is fitted by least squares,

        y[k] = - sum_{i=1..na} A_i y[k-i] + sum_{l=nk..nk+nb-1} b_l u_j[k-l]
               + (every other input at lags 0..max_delay+nb-1) + e[k],

    all outputs together (each normalised to unit variance), and the ``nk``
    with the smallest residual sum of squares wins. Every candidate has the
    same number of parameters, so the losses compare directly (as in
    ``arxstruc``/``selstruc`` with a fixed ``na``, ``nb``). The regression is
    factored once (QR of the full regressor, every lag of every input); each
    candidate is then a small least-squares problem on columns of the
    triangular factor, which gives exactly the candidate's residual.

    Parameters
    ----------
    data : IOData
        Uniformly sampled record with at least one input. Means are removed and
        every channel is divided by its standard deviation, so the units of the
        channels do not change the answer.
    max_delay : int
        Largest delay tried, in samples.
    na : int
        Autoregressive order (past outputs, every output).
    nb : int
        Number of input coefficients from lag ``nk`` on.
    return_loss : bool
        Also return the losses, shape ``(n_inputs, max_delay + 1)``: the
        residual sum of squares for each candidate.

    Returns
    -------
    ndarray of int, shape (n_inputs,)
        ``nk`` per input: 1 for a strictly proper model without extra dead
        time, 0 with direct feedthrough, ``1 + d`` for ``d`` extra samples
        of dead time before a strictly proper response.

    Raises
    ------
    DataError
        Not an IOData record, no inputs, non-uniform sampling, bad options, a
        constant output.
    NotExcitingError
        A constant input (zero included): its delay cannot be seen.
    TooFewSamplesError
        Fewer samples than the regression needs.
    """
    if not isinstance(data, IOData):
        raise DataError(f"estimate_delay needs an IOData record, got {type(data).__name__}")
    if data.n_inputs == 0:
        raise DataError("estimate_delay needs a record with at least one input")
    if data.dt is None:
        raise DataError("estimate_delay needs uniformly sampled data (delays are counted in "
                        "samples); this record has non-uniform time stamps")
    max_delay = check_int(max_delay, "max_delay", minimum=0)
    na = check_int(na, "na", minimum=0)
    nb = check_int(nb, "nb", minimum=1)
    # every channel to unit variance, so that units do not change the answer
    u, u_spread = _standardised(data.u)
    y, y_spread = _standardised(data.y)
    if (y_spread == 0).any():
        k = int(np.flatnonzero(y_spread == 0)[0])
        raise DataError(f"estimate_delay: output {data.output_names[k]!r} is constant: there "
                        "is no response to find a delay in")
    if (u_spread == 0).any():
        k = int(np.flatnonzero(u_spread == 0)[0])
        raise NotExcitingError(f"estimate_delay: input {data.input_names[k]!r} is constant, "
                               "so no delay of its effect can be seen; estimate the delay "
                               "from a record where it varies (a step or a random signal), "
                               "or leave that input out", required_order=1, achieved_order=0)
    N, nu = u.shape
    ny = y.shape[1]
    lags = max_delay + nb                   # input lags 0..lags-1
    start = max(na, lags - 1)
    # one block of regression rows per experiment (no lag reaches into another one)
    ranges = [(a, b) for a, b in data.experiment_ranges if b - a > start]
    rows = sum(b - a - start for a, b in ranges)
    n_cols = ny * na + nu * lags
    if rows < 2 * n_cols + 10:
        raise TooFewSamplesError(f"estimate_delay with max_delay={max_delay}, na={na}, "
                                 f"nb={nb} regresses on {n_cols} columns and needs at least "
                                 f"{2 * n_cols + 10 + start} samples; the record has {N}")

    def block(ue, ye):
        n_e = ue.shape[0]
        cols = [ye[start - i:n_e - i] for i in range(1, na + 1)]      # (rows, ny) each
        cols += [ue[start - lag:n_e - lag] for lag in range(lags)]    # (rows, nu) each
        return np.hstack(cols + [ye[start:]])

    # the triangular factor of the regression, its rows a block at a time past
    # REGRESSION_BYTES, each block folded into the factor of those before it (the same
    # factor up to the signs of its rows, which the losses do not see): the memory of a
    # long record is one block (10^6 samples of a 2 x 2 record held 0.75 GB whole)
    width = n_cols + ny
    step = max(2 * width, int(REGRESSION_BYTES // (8 * width)))
    R = np.zeros((0, width))
    for a, b in ranges:
        for s in range(a + start, b, step):
            t = min(s + step, b)
            rows_k = block(u[s - start:t], y[s - start:t])
            R = scipy.linalg.qr(np.vstack([R, rows_k]), mode="r", overwrite_a=True,
                                check_finite=False)[0][:width]
    # column index of output/input channels in M
    past_y = list(range(ny * na))

    def u_col(j, lag):
        return ny * na + lag * nu + j

    Ry = R[:, n_cols:]
    losses = np.empty((nu, max_delay + 1))
    for j in range(nu):
        others = [u_col(i, lag) for i in range(nu) if i != j for lag in range(lags)]
        for nk in range(max_delay + 1):
            S = past_y + others + [u_col(j, lag) for lag in range(nk, nk + nb)]
            RS = R[:, S]
            coef = scipy.linalg.lstsq(RS, Ry, check_finite=False, lapack_driver="gelsy")[0]
            losses[j, nk] = float(np.sum((Ry - RS @ coef) ** 2))
    delays = np.argmin(losses, axis=1).astype(np.int64)
    return (delays, losses) if return_loss else delays


def _standardised(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x less its column means, divided by their spreads; the spreads)``, one per
    column of the (samples x channels) ``x`` (0 for a constant column, left as 0s).
    Each column is first divided by its largest magnitude, so that values near the
    double-precision limit do not overflow (a spread of 1e155 squares to inf)."""
    peak = np.abs(x).max(axis=0)
    x = x / np.where(peak > 0, peak, 1.0)
    x = x - x.mean(axis=0)
    std = column_std(x)
    spread = std * peak
    return x / np.where(std > 0, std, 1.0), spread


# ---------------------------------------------------------------------------
# delays on data and models
# ---------------------------------------------------------------------------
@checked_call
def delay_inputs(data, input_delay):
    """The record with input ``j`` shifted by ``d_j`` samples.

    Sample ``k`` of the result holds ``u_j[k + D - d_j]`` and ``y[k + D]``,
    ``D = max(d)``: the first ``D`` output samples, whose delayed inputs lie
    before the record, are left out (no input value is invented). A method
    run on the result identifies the model from ``u_j[k - d_j]`` to
    ``y[k]``. A record of several experiments (:func:`subid.merge`) is
    shifted experiment by experiment (each loses its first ``D`` samples).

    Parameters
    ----------
    data : IOData
        Uniformly sampled record.
    input_delay : int or sequence of int
        Delay of every input in samples (one integer: the same for all).

    Returns
    -------
    data : IOData
        The shifted record (the same object when every delay is 0).
    delays : ndarray of int, shape (n_inputs,)
    """
    if not isinstance(data, IOData):
        raise DataError("input_delay shifts the samples of an IOData record; a "
                        f"{type(data).__name__} cannot be shifted: build the statistic from "
                        "the shifted record (subid.delay.delay_inputs)")
    if data.dt is None:
        raise DataError("input_delay counts samples and needs uniformly sampled data; this "
                        "record has non-uniform time stamps")
    delays = _check_delays(input_delay, data.n_inputs)
    D = int(delays.max()) if delays.size else 0
    if D == 0:
        return data, delays
    if data.n_experiments > 1:          # each experiment loses its own first D samples
        from subid.data import merge
        return merge([delay_inputs(e, delays)[0] for e in data.experiments],
                     names=data.experiment_names), delays
    N = data.n_samples
    if N - D < 2:
        raise TooFewSamplesError(f"input_delay {delays.tolist()} leaves {max(N - D, 0)} "
                                 f"samples of a {N}-sample record")
    u = np.column_stack([data.u[D - d:N - d, j] for j, d in enumerate(delays)])
    out = data[D:]
    shifted = out._derive(u, out.y, t=None if not data.has_time_stamps else out.t,
                          dt=out.dt, t0=float(out.t[0]))
    return shifted, delays


def shift_for_method(data, input_delay):
    """What a batch method does with its ``input_delay`` argument: ``(data, None)``
    when it is 0 or None (the data may then be a HankelStatistic), else
    :func:`delay_inputs`."""
    if input_delay is None or (isinstance(input_delay, (numbers.Integral, np.integer))
                               and not isinstance(input_delay, bool) and input_delay == 0):
        return data, None
    shifted, delays = delay_inputs(data, input_delay)
    return shifted, (delays if delays.any() else None)


def input_delay_of(model) -> np.ndarray | None:
    """The input delays recorded on ``model`` (``info['input_delay']``), or
    None when there are none (or all are 0)."""
    value = model.info.get(INFO_KEY)
    if value is None:
        return None
    delays = _check_delays(value, model.n_inputs, error=ModelError)
    return delays if delays.any() else None


def record_delay(model, delays):
    """Store ``delays`` in ``model.info['input_delay']`` (a list of int); returns
    ``model`` (unchanged when ``delays`` is None)."""
    if delays is None:
        return model
    model.info[INFO_KEY] = [int(d) for d in np.asarray(delays).reshape(-1)]
    return model


#: Largest size of the matrices :func:`absorb_delay` builds (A, B, C, D; bytes).
ABSORB_BYTES_LIMIT = 2.0**30


def _registers(A, B, C, D, delays, zero, one):
    """The matrices of :func:`absorb_delay` built from ``A, B, C, D`` (any dtype):
    ``zero`` where the absorbed model has a structural zero, ``one`` at the shift
    registers' unit entries. Input ``j`` delayed by ``d_j`` passes through ``d_j``
    states, the first holding ``u_j[k-1]``, the last ``u_j[k-d_j]``, which enters as
    ``B[:, j]`` and ``D[:, j]`` did."""
    n, m = B.shape
    p = C.shape[0]
    N = n + int(np.sum(delays))
    dtype = np.result_type(A, B, C, D, np.asarray(zero), np.asarray(one))
    Ab, Bb = np.full((N, N), zero, dtype=dtype), np.full((N, m), zero, dtype=dtype)
    Cb, Db = np.full((p, N), zero, dtype=dtype), np.full((p, m), zero, dtype=dtype)
    Ab[:n, :n] = A
    Cb[:, :n] = C
    pos = n
    for j, d in enumerate(delays):
        if d == 0:
            Bb[:n, j] = B[:, j]
            Db[:, j] = D[:, j]
            continue
        first, last = pos, pos + d - 1
        Bb[first, j] = one
        for r in range(first + 1, last + 1):
            Ab[r, r - 1] = one
        Ab[:n, last] = B[:, j]
        Cb[:, last] = D[:, j]
        pos += d
    return Ab, Bb, Cb, Db


def _absorbed_covariance(entry, model, delays, absorbed):
    """``info['parameter_covariance']`` of :func:`absorb_delay`'s model, whose matrices
    are ``absorbed = (A, B, C, D, K)``, or None when ``entry`` does not fit ``model``'s
    matrices. The absorbed matrices' entries are
    either the delayed model's (moved: a delayed input's ``B`` column into ``A``, its
    ``D`` column into ``C``) or structural constants, so the packed parameters
    (``A, B, C`` row-major, then ``D`` and ``K`` where they are parameters) map by a
    selection matrix ``T``, ``θ' = T θ + c``, and the covariance factor by ``T``: the
    same covariance, exactly. The polynomial coefficients' covariance is left out (the
    polynomials are dropped)."""
    n, m, p = model.order, model.n_inputs, model.n_outputs
    with_d, with_k = bool(entry.get("with_feedthrough")), bool(entry.get("with_gain"))
    shapes = [(n, n), (n, m), (p, n)] + ([(p, m)] if with_d else []) + \
        ([(n, p)] if with_k else [])
    sizes = [a * b for a, b in shapes]
    try:
        params = np.asarray(entry["parameters"], dtype=float)
        factor = np.asarray(entry["factor"], dtype=float)
    except (KeyError, TypeError, ValueError):
        return None
    if params.shape != (sum(sizes),) or factor.ndim != 2 or factor.shape[0] != sum(sizes) \
            or (with_k and model.K is None):
        return None
    offsets = np.cumsum([0] + sizes)
    index = [np.arange(a, b).reshape(shape)
             for a, b, shape in zip(offsets[:-1], offsets[1:], shapes)]
    fixed_d = np.full((p, m), -1)                # D not among the parameters: constants
    Ai, Bi, Ci, Di = _registers(index[0], index[1], index[2], index[3] if with_d else fixed_d,
                                delays, -1, -1)
    blocks = [Ai, Bi, Ci] + ([Di] if with_d else [])
    if with_k:
        blocks.append(np.vstack([index[-1], np.full((int(np.sum(delays)), p), -1)]))
    rows = np.concatenate([b.ravel() for b in blocks])
    T = np.zeros((rows.size, params.size))
    moved = rows >= 0
    T[np.flatnonzero(moved), rows[moved]] = 1.0
    A, B, C, D, K = absorbed
    values = [A, B, C] + ([D] if with_d else []) + ([K] if with_k else [])
    out = {k: v for k, v in entry.items()
           if k not in ("coefficients", "coefficient_factor", "coefficient_names")}
    out["parameters"] = np.concatenate([v.ravel() for v in values])
    out["factor"] = T @ factor
    return out


def effective_input(model, u: np.ndarray) -> np.ndarray:
    """The input samples as ``model``'s state equations see them.

    The one place where a model's input delays (``info['input_delay']``, in
    samples) are applied to a record's inputs: :meth:`StateSpace.simulate`,
    :func:`subid.predict`, :func:`subid.residuals`, :func:`subid.fit_percent`
    (simulation and k-step prediction) and :func:`subid.pem` all obtain the
    input through it, so that nothing derived from a model ignores its delays.
    ``u`` is one experiment's input, shape (N, n_inputs); the input before
    the first sample is taken as zero.
    """
    delays = input_delay_of(model)
    return u if delays is None else apply_to_inputs(u, delays)


def apply_to_inputs(u: np.ndarray, delays: np.ndarray) -> np.ndarray:
    """``u_j[k - d_j]`` for every sample, zero before the first sample (the
    input before the record is taken as zero, as the initial state is by
    default)."""
    out = np.zeros_like(u)
    N = u.shape[0]
    for j, d in enumerate(delays):
        if d < N:
            out[d:, j] = u[:N - d, j]
    return out


def frequency_factor(delays: np.ndarray, w: np.ndarray, dt: float) -> np.ndarray:
    """``exp(-1j w dt d_j)``, shape (len(w), 1, n_inputs): the delays' factor on
    the columns of the frequency response."""
    return np.exp(-1j * np.outer(np.asarray(w, dtype=float) * dt, delays))[:, None, :]


@checked_call
def absorb_delay(model):
    """An equivalent model without input delays: each delayed input passes
    through ``d_j`` extra states (a shift register), so the order grows by
    ``sum(d)``. Use it for tools that know no delays (``.mat``, control,
    scipy exports; Markov parameters).

    Returns the model itself when it has no delays. The Kalman gain K (zero rows for
    the registers), ``noise_cov`` and ``info['x0']`` (zeros for the registers) carry
    over: one-step predictions are unchanged. The parameter covariance is mapped
    exactly (:func:`_absorbed_covariance`: the same bounds). The polynomials of a
    polynomial method and their degrees no longer describe the matrices: they are
    dropped, each named in ``info['dropped']``.

    Raises
    ------
    ResourceLimitError
        The absorbed model's dense matrices would take more than
        :data:`ABSORB_BYTES_LIMIT` (a delay of 1e5 samples: 75 GiB), checked
        before anything is allocated; the delayed model itself simulates,
        predicts and gives its frequency response without absorbing.
    """
    if not all(hasattr(model, name) for name in ("A", "B", "C", "D", "info", "dt")):
        raise ModelError(f"absorb_delay takes a subid.StateSpace model, got "
                         f"{type(model).__name__}")
    delays = input_delay_of(model)
    if delays is None:
        return model
    if model.is_continuous:
        raise ModelError("input delays in samples are defined for discrete-time models only")
    n, m, p = model.order, model.n_inputs, model.n_outputs
    extra = int(delays.sum())
    N = n + extra
    need = 8.0 * N * (N + m + p)
    if need > ABSORB_BYTES_LIMIT:
        raise ResourceLimitError(
            f"absorbing input delays {delays.tolist()[:8]}{'...' if m > 8 else ''} adds "
            f"{extra} states: the order-{N} matrices need {need / 2**30:.3g} GiB (limit "
            f"{ABSORB_BYTES_LIMIT / 2**30:g} GiB). Keep the delay in the model "
            "(info['input_delay'] is honoured by simulate, predict and freqresp) or export "
            "it as a delay (e.g. MATLAB's InputDelay) instead of as states")
    A, B, C, D = _registers(model.A, model.B, model.C, model.D, delays, 0.0, 1.0)
    # the registers take no noise: K's rows zero
    K = None if model.K is None else np.vstack([model.K, np.zeros((extra, p))])
    info = {k: v for k, v in model.info.items() if k != INFO_KEY}
    info["absorbed_input_delay"] = delays.tolist()
    # the polynomials (their nk) and their degrees describe the model before absorption:
    # dropped, each named in info['dropped'] (as the model's conversions do,
    # subid.model._conversions.drop_info); the covariance is mapped
    dropped = dict(info.get("dropped") or {})
    for key in ("polynomials", "orders"):
        if info.pop(key, None) is not None:
            dropped[key] = "absorb_delay() turned the input delays into states"
    entry = info.pop("parameter_covariance", None)
    if isinstance(entry, dict):
        mapped = _absorbed_covariance(entry, model, delays, (A, B, C, D, K))
        if mapped is not None:
            info["parameter_covariance"] = mapped
        else:
            dropped["parameter_covariance"] = "absorb_delay() could not map it (its " \
                "parameters do not match the model's matrices)"
            info["parameter_covariance_note"] = (
                "the covariance was dropped: absorb_delay() could not map it (ask for bounds "
                "on the model with info['input_delay'])")
    if dropped:
        info["dropped"] = dropped
    # the innovation form and the initial state(s) carry over: the registers start empty
    # (the delayed model's inputs before the record are zero too), so predictions and
    # simulations from info['x0'] are the same
    x0 = info.get("x0")
    if x0 is not None and np.shape(x0)[-1:] == (n,):
        x0 = np.asarray(x0, dtype=float)
        info["x0"] = np.concatenate([x0, np.zeros(x0.shape[:-1] + (extra,))], axis=-1)
    # type(model): the model's own class (StateSpace), without importing the model
    # module, which builds on this one
    return type(model)(A, B, C, D, model.dt, hold=model.hold, input_names=model.input_names,
                       output_names=model.output_names, info=info, K=K,
                       noise_cov=model.noise_cov)
