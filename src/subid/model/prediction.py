"""Simulation and k-step-ahead prediction of a model on a record (below the methods, which
score their candidates with them, and the evaluation, which reports them).

A discrete-time model with a Kalman gain ``K``,

    x[t+1] = A x[t] + B u[t] + K e[t],    y[t] = C x[t] + D u[t] + e[t],

has the one-step predictor (the steady-state Kalman filter)

    x̂[t+1|t] = (A - K C) x̂[t|t-1] + (B - K D) u[t] + K y[t],
    ŷ[t|t-1] = C x̂[t|t-1] + D u[t]

(Ljung, *System Identification*, 2nd ed., 1999, eq. (4.86)), and the
k-step-ahead predictor ``ŷ[t|t-k]`` starts from ``x̂[t-k+1|t-k]`` and
propagates the deterministic part with the known inputs over the remaining
``k - 1`` steps (ibid., eq. (3.31): future innovations are predicted by
zero). ``k = inf`` (or any ``k`` beyond the record) is the simulation from
the initial state. The predicted output is affine in the initial state
``x̂[0]``, which is therefore estimated by linear least squares on the
prediction errors when not given.
"""

from __future__ import annotations

import math
import numbers
import warnings

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import checked_call, same_period
from subid.data import IOData, column_spread, column_std, not_a_record
from subid.delay import absorb_delay, effective_input, input_delay_of
from subid.errors import (
    DataError,
    ModelError,
    NoiseModelWarning,
    OptionError,
    ResourceLimitError,
)
from subid.model import _simulate
from subid.model._checks import HOLDS, check_channel_order, check_x0, reordered
from subid.model.statespace import StateSpace

__all__ = ["predict", "prediction_errors", "simulate_fit", "check_model", "check_model_data",
           "reordered",
           "check_x0", "experiment_x0"]

# Beyond this many steps the k-step predictor of a model with a stable A uses the
# closed form ŷ(t|t-k) = y_sim(t) + C A^(k-1) (x̂(t-k+1) - x_sim(t-k+1)) instead of
# k-1 propagation sweeps over the record (an unstable A keeps the sweeps: its
# simulation would overflow).
_LOOP_STEPS = 32


# The checks and the simulation fit live here, below subid.model.fit (which imports them):
# fit_percent(steps=k) predicts, and predict simulates.
def check_model(model, name: str) -> StateSpace:
    """``model``, or ModelError unless it is a :class:`~subid.StateSpace`."""
    if not isinstance(model, StateSpace):
        raise ModelError(f"{name} must be a subid.StateSpace, got {type(model).__name__}")
    return model


def check_model_data(model, data) -> None:
    """Raise unless ``data`` is an IOData record with the model's channels and sampling."""
    check_model(model, "model")
    if not isinstance(data, IOData):
        raise not_a_record(data, "data")
    if (data.n_inputs, data.n_outputs) != (model.n_inputs, model.n_outputs):
        raise DataError(f"data have {data.n_inputs} inputs and {data.n_outputs} outputs but "
                        f"the model has {model.n_inputs} and {model.n_outputs}")
    check_channel_order(model, data)
    if model.dt > 0:
        if not data.is_uniform or not same_period(data.dt, model.dt):
            raise DataError(f"the model is discrete with dt={model.dt} but the data are "
                            f"sampled with {'non-uniform t' if not data.is_uniform else data.dt}")


#: Samples per block of the simulations in :func:`simulate_fit` (bounds its memory).
_SIM_BLOCK = 65536
#: The free response counts as decayed when the state-transition matrix has fallen
#: below this, relative to its start (the identity): later rows change x0 by less.
_FREE_DECAYED = 1e-20
#: Free-response values kept for the fitted output (beyond, it is simulated again).
_FREE_KEPT = 1 << 22


def _simulate_blocks(model, data, x0, hold, out, stop=None, block=_SIM_BLOCK):
    """Simulated output of ``model`` on ``data`` from ``x0``, written to ``out``
    block by block (samples ``0 .. stop-1``), without the state history.

    Blocks overlap by one sample: the state at a block's last sample (as the
    one-record simulation computes it) starts the next block, so a
    discrete-time model gives the one-record simulation bit for bit.
    Yields ``(a, b, state at b)`` after each block ``[a, b)``.
    """
    N = data.n_samples if stop is None else stop
    if input_delay_of(model) is not None:       # delays shift inputs across block borders
        block = max(N, 1)
    u, t = data.u, (data.t if model.dt == 0 else None)
    x = np.asarray(x0, dtype=float)
    for a in range(0, N, block):
        b = min(a + block, N)
        c = min(b + 1, data.n_samples)
        with np.errstate(over="ignore", invalid="ignore"):
            y, xs = model.simulate(u[a:c], t=None if t is None else t[a:c], x0=x, hold=hold,
                                   return_state=True)
        out[a:b] = y[:b - a]
        x = xs[b - a] if c > b else xs[-1]
        yield a, b, x


def _free_blocks(model, data, hold, block=_SIM_BLOCK):
    """Free responses ``(a, b, F)`` with ``F[t - a, i, j]`` the output ``i`` at
    sample ``t`` from the initial state ``e_j`` (zero input), block by block,
    until the state-transition matrix of a stable model has decayed below
    :data:`_FREE_DECAYED` (the rest contributes nothing at rounding level)."""
    N, n, ny = data.n_samples, model.order, model.n_outputs
    if model.dt > 0:
        yield from _free_blocks_discrete(model.A, model.C, N, block)
        return
    stable = bool(model.poles().real.max(initial=-1.0) < 0.0)
    zeros = np.zeros((min(block, N) + 1, model.n_inputs))
    X = np.eye(n)
    for a in range(0, N, block):
        b = min(a + block, N)
        c = min(b + 1, N)
        F = np.empty((b - a, ny, n))
        Xn = np.empty((n, n))
        for j in range(n):
            with np.errstate(over="ignore", invalid="ignore"):
                y, xs = model.simulate(zeros[:c - a], t=None if model.dt > 0 else data.t[a:c],
                                       x0=X[:, j], hold=hold, return_state=True)
            F[:, :, j] = y[:b - a]
            Xn[:, j] = xs[b - a] if c > b else xs[-1]
        yield a, b, F
        X = Xn
        if stable and np.abs(X).max(initial=0.0) < _FREE_DECAYED:
            return


#: Largest entry of a power of A (m >= 2) beyond which :func:`_free_blocks_discrete`
#: multiplies the powers one by one instead of squaring (the rounding of a squared power
#: grows with the square of its size).
TRANSIENT_GROWTH = 1e3


def _free_blocks_discrete(A, C, N, block=_SIM_BLOCK):
    """:func:`_free_blocks` of a discrete-time model: ``F[t] = C A^t`` by doubling
    (``C A^{t+m} = (C A^t) A^m`` for ``t < m``, ``A^{2m} = A^m A^m``): log2(block)
    matrix products per block instead of one simulation per state, the same values
    to rounding."""
    n, ny = A.shape[0], C.shape[0]
    stable = bool(np.abs(np.linalg.eigvals(A)).max(initial=0.0) < 1.0) if n else True
    X = None                                   # A^a (None: the identity)
    # squaring is exact to rounding for a well-behaved A; one whose powers first grow
    # (a non-normal A: a near-integrator with a large Kalman gain in a predictor, its
    # powers 2e5 times A's size before they decay) loses the small late powers to the
    # rounding of the large ones (predictions 1e-3 off on DaISy robot_arm's refined
    # model, 4x the one-step error covariance): then the powers one by one
    sequential = False
    with np.errstate(over="ignore", invalid="ignore"):
        for a in range(0, N, block):
            b = min(a + block, N)
            length = b - a
            P = np.empty((length, ny, n))      # C A^t, t < length
            P[0] = C
            power, m = A.copy(), 1             # power = A^m
            while m < length and not sequential:
                k = min(m, length - m)
                P[m:m + k] = P[:k] @ power
                if k == m and m + k < length:
                    power = power @ power
                    sequential = not np.abs(power).max() <= TRANSIENT_GROWTH
                m += k
            if sequential:
                step = np.eye(n)
                for t in range(1, length):
                    P[t] = P[t - 1] @ A
                for _ in range(length):
                    step = step @ A
            else:
                step = np.linalg.matrix_power(A, length)
            yield a, b, P if X is None else P @ X
            X = step if X is None else step @ X
            if stable and np.abs(X).max(initial=0.0) < _FREE_DECAYED:
                return


def _delay_line_model(model):
    """``model`` with its input delays as states (:func:`subid.delay.absorb_delay`: x
    first, then the delayed inputs), whose estimated initial state includes the inputs
    of the delay line before the record; None for a model without input delays (or one
    whose absorbed matrices would exceed :data:`subid.delay.ABSORB_BYTES_LIMIT`: the
    inputs before the record are then taken as zero).

    ``x0='estimate'`` estimates them with the state: they are as unknown as the state
    at the first sample, and taking them as zero biased the first ``max(d)`` samples of
    every record that does not start at rest (a validation record split from a longer
    one: the true model fitted 98.4 % against 99.6 % with the delay line estimated, and
    its residuals failed the whiteness test). MATLAB's ``compare`` does the same under
    ``InitialCondition='d'`` ("absorb delays and estimate")."""
    if model.dt == 0 or input_delay_of(model) is None:
        return None
    try:
        return absorb_delay(model)
    except ResourceLimitError:
        return None


def simulate_fit(model, data, x0="estimate", hold=None, *, output_std=None):
    """Simulated output of ``model`` on ``data`` and the initial state used.

    ``output_std`` (per output) replaces the spread of ``data.y`` in the
    weights of the initial-state regression (used when ``data`` is the
    prefix of a longer record whose weights apply).

    ``x0='estimate'`` fits the initial state to the data by least squares
    (the simulated output is linear in x0), each output weighted by the
    inverse of its standard deviation; ``'zero'`` or an array fixes it. For a
    model with input delays, the inputs of the delay line before the record are
    estimated with it (:func:`_delay_line_model`; the x0 returned is the model's
    own state); a given x0 takes them as zero.

    Memory stays bounded by a block of :data:`_SIM_BLOCK` samples beyond the
    returned output: the simulations run block by block without the state
    history, and the least-squares problem for x0 (``N n_outputs`` rows,
    ``n`` columns) is reduced block by block to the triangular factor of
    ``[regressors | residual]`` (QR), from which the same minimum-norm
    solution as ``lstsq`` of the whole problem follows (same singular
    values and vectors, same cut-off ``eps * max(rows, n)``). The free
    response of a stable model is only computed until it has decayed below
    rounding.

    A record of several experiments (:func:`subid.merge`) is simulated
    experiment by experiment, each from its own initial state: the returned
    x0 then has shape (n_experiments, n), and an array given as ``x0`` must
    have that shape. ``hold`` (continuous-time models) defaults to the
    model's :attr:`~subid.StateSpace.hold`.
    """
    check_model_data(model, data)
    if data.n_experiments > 1:
        std = column_std(data.y) if output_std is None else output_std
        parts = [simulate_fit(model, e, x0=x0_e, hold=hold, output_std=std)
                 for e, x0_e in zip(data.experiments,
                                    experiment_x0(x0, data.n_experiments, model.order))]
        return np.vstack([p[0] for p in parts]), np.stack([p[1] for p in parts])
    x0 = check_x0(x0, model.order)
    n, N, ny = model.order, data.n_samples, model.n_outputs

    def overflow():
        radius = float(np.abs(model.poles()).max()) if model.dt > 0 else \
            float(model.poles().real.max())
        kind = "spectral radius" if model.dt > 0 else "largest real part of a pole"
        return ModelError(f"simulating the model over {data.n_samples} samples overflows (its "
                          f"{kind} is {radius:.4g}): the model is unstable and its simulated "
                          "output, hence its fit, is undefined")

    def simulate(x0v):
        out = np.empty((N, ny))
        try:
            for _ in _simulate_blocks(model, data, x0v, hold, out):
                pass
        except ModelError:
            raise overflow() from None
        if not np.isfinite(out).all():
            raise overflow()
        return out

    if isinstance(x0, str) and x0 == "zero":
        return simulate(np.zeros(n)), np.zeros(n)
    if isinstance(x0, str) and x0 == "estimate":
        if (line := _delay_line_model(model)) is not None:
            y_hat, x0_line = simulate_fit(line, data, x0, hold, output_std=output_std)
            return y_hat, x0_line[:n]
        forced = simulate(np.zeros(n))
        # each output weighted by 1 / its standard deviation, so that the initial state
        # (and the fit) does not depend on the output units
        w = _x0_weights(data.y, output_std)
        R = np.zeros((0, n + 1))
        kept, size = [], 0                # free-response blocks, while they stay small
        try:
            for a, b, F in _free_blocks(model, data, hold):
                if not np.isfinite(F).all():
                    raise overflow()
                rows = np.empty((b - a, ny, n + 1))
                rows[:, :, :n] = F * w[None, :, None]
                rows[:, :, n] = (data.y[a:b] - forced[a:b]) * w
                R = scipy.linalg.qr(np.vstack([R, rows.reshape(-1, n + 1)]), mode="r",
                                    check_finite=False)[0][:n + 1]
                size += F.size
                kept = kept + [(a, b, F)] if kept is not None and size <= _FREE_KEPT else None
        except ModelError:
            raise overflow() from None
        # lstsq of the whole (N ny) x n problem, through its triangular factor
        cut = np.finfo(float).eps * max(N * ny, n)
        Rn = np.zeros((n, n + 1))
        Rn[:R.shape[0]] = R[:n]
        x0_hat = np.linalg.lstsq(Rn[:, :n], Rn[:, n], rcond=cut)[0]
        if kept is None:                  # a long free response: simulate from x0_hat
            return simulate(x0_hat), x0_hat
        for a, b, F in kept:              # forced + free response from x0_hat
            forced[a:b] += F @ x0_hat
        return forced, x0_hat
    return simulate(x0), x0


def experiment_x0(x0, n_experiments: int, order: int) -> list:
    """``x0`` of :func:`simulate_fit` split per experiment (after :func:`check_x0`): a
    string for every experiment, or the rows of an array of shape (n_experiments, order)."""
    x0 = check_x0(x0, order, n_experiments)
    if isinstance(x0, str):
        return [x0] * n_experiments
    return list(x0)


def _check(model, data) -> tuple[StateSpace, IOData]:
    check_model_data(model, data)
    return model, data


def _check_steps(steps):
    if isinstance(steps, (bool, np.bool_)):
        raise DataError(f"steps must be a positive integer or numpy.inf, got {steps!r}")
    if isinstance(steps, numbers.Real) and math.isinf(steps) and steps > 0:
        return math.inf
    if isinstance(steps, numbers.Integral) and steps >= 1:
        return int(steps)
    if isinstance(steps, numbers.Real) and float(steps).is_integer() and steps >= 1:
        return int(steps)
    raise DataError(f"steps must be a positive integer or numpy.inf, got {steps!r}")


def _predictor_matrices(model):
    A, B, C, D, K = model.A, model.B, model.C, model.D, model.K
    Ap = A - K @ C
    Bp = np.hstack([B - K @ D, K])
    Dp = np.hstack([D, np.zeros((model.n_outputs, model.n_outputs))])
    return Ap, Bp, C, Dp


def _one_step_states(model, u, y, x0):
    """``(ŷ[t|t-1], x̂[t|t-1])`` of the Kalman predictor from ``x̂[0] = x0``."""
    Ap, Bp, C, Dp = _predictor_matrices(model)
    return _simulate.simulate_discrete(Ap, Bp, C, Dp, np.hstack([u, y]), x0)


def _k_step(model, u, y, x0, k):
    """k-step-ahead predictions (k finite, >= 1) from the initial state x0."""
    N = u.shape[0]
    A, B, C, D = model.A, model.B, model.C, model.D
    if k >= N or model.K is None:
        return _simulate.simulate_discrete(A, B, C, D, u, x0)[0]
    y1, X = _one_step_states(model, u, y, x0)
    if k == 1:
        return y1
    t = np.arange(N)
    start = np.maximum(t - k + 1, 0)
    if k <= _LOOP_STEPS or np.abs(np.linalg.eigvals(A)).max() >= 1.0:
        Z = X[start].copy()
        for j in range(k - 1):
            idx = start + j
            active = idx < t
            Z[active] = Z[active] @ A.T + u[idx[active]] @ B.T
        return Z @ C.T + u @ D.T
    ysim, xsim = _simulate.simulate_discrete(A, B, C, D, u, x0)
    CAk = C @ np.linalg.matrix_power(A, k - 1)
    late = t - k + 1 >= 0
    out = ysim.copy()
    out[late] += (X[start[late]] - xsim[start[late]]) @ CAk.T
    return out


def _x0_weights(y, output_std=None) -> np.ndarray:
    """The weights of the outputs in an initial-state regression: the inverse of each
    output's standard deviation (``output_std``, default that of ``y``; 1 for a
    constant output)."""
    if output_std is None:
        return 1.0 / column_spread(y)
    std = np.asarray(output_std, dtype=float)
    return 1.0 / np.where(std > 0, std, 1.0)


def _estimate_x0(model, u, y, k, data=None, output_std=None):
    """Least-squares initial state of the k-step predictor, each output weighted by the
    inverse of its standard deviation (``output_std``, default that of ``y``), as
    :func:`simulate_fit` weighs the simulation's: the initial state, and so the
    prediction, do not depend on the output units.

    For ``k = 1`` with a stable predictor ``A - K C`` (and ``data`` given), the
    free responses are computed only until they have decayed below
    :data:`_FREE_DECAYED` (:func:`_free_blocks`): the later rows of the
    regression are zero to rounding and do not change its solution, and the
    cost falls from ``n + 1`` simulations of the record to about one.
    """
    n = model.order
    forced = _k_step(model, u, y, np.zeros(n), k)
    w = _x0_weights(y, output_std)
    if k == 1 and data is not None and n > 0:
        Ap, Bp, C, Dp = _predictor_matrices(model)
        if np.abs(np.linalg.eigvals(Ap)).max() < 1.0:
            predictor = StateSpace(Ap, Bp, C, Dp, model.dt)
            free = np.concatenate([F for _, _, F in _free_blocks(predictor, data, None)])
            rows = free.shape[0]
            if not (np.isfinite(forced).all() and np.isfinite(free).all()):
                return None, forced
            x0 = scipy.linalg.lstsq((free * w[None, :, None]).reshape(-1, n),
                                    ((y[:rows] - forced[:rows]) * w).reshape(-1),
                                    lapack_driver="gelsy", check_finite=False)[0]
            y_hat = forced.copy()
            y_hat[:rows] += free @ x0
            return x0, y_hat
    zu, zy = np.zeros_like(u), np.zeros_like(y)
    free = np.stack([_k_step(model, zu, zy, e, k) for e in np.eye(n)], axis=-1)
    if not (np.isfinite(forced).all() and np.isfinite(free).all()):
        return None, forced
    x0 = scipy.linalg.lstsq((free * w[None, :, None]).reshape(-1, n),
                            ((y - forced) * w).reshape(-1),
                            lapack_driver="gelsy", check_finite=False)[0]
    return x0, forced + free @ x0


@serial_blas
@checked_call
def predict(model, data, steps=1, x0=None, *, return_x0=False, output_std=None, hold=None):
    """k-step-ahead predicted outputs of a model on a record.

    Parameters
    ----------
    model : StateSpace
        Discrete-time model; with a Kalman gain ``K`` the predictor is the
        Kalman filter (module docstring). Without ``K`` (or for a
        continuous-time model) the prediction is the simulation, with a
        :class:`~subid.errors.NoiseModelWarning` unless ``steps=inf``.
    data : IOData
        Same channels and sampling period as the model.
    steps : int or numpy.inf
        Prediction horizon k >= 1: ``ŷ[t|t-k]`` uses outputs up to ``t-k``
        and inputs up to ``t``. 1 is the one-step (Kalman) predictor,
        ``numpy.inf`` the simulation.
    x0 : None, 'estimate', 'zero', 0 or array_like of shape (n,)
        Initial state ``x̂[0]``; None/'estimate' fits it by least squares to
        the prediction errors (the predictions are affine in it), each output
        weighted by the inverse of its standard deviation, as the simulation's
        initial state is (:func:`simulate_fit`): the prediction does not depend
        on the output units. A record of
        several experiments (:func:`subid.merge`) is predicted experiment by
        experiment, each from its own initial state (an array: shape
        (n_experiments, n); the returned x0 has that shape).
    return_x0 : bool
        Also return the initial state used.
    output_std : array_like of shape (n_outputs,), optional
        The spreads that weight the outputs in the initial-state regression,
        instead of those of ``data.y`` (for ``data`` the head of a longer
        record whose weights apply).
    hold : {'zoh', 'foh'}, optional
        For a continuous-time model, whose prediction is the simulation: the
        input between samples (default the model's
        :attr:`~subid.StateSpace.hold`). A discrete-time model ignores it.

    Returns
    -------
    y_hat : ndarray, shape (N, n_outputs)
    x0 : ndarray, shape (n,)
        Only with ``return_x0=True``.

    Raises
    ------
    DataError
        Channels or sampling period do not match, ``steps`` or ``x0`` is
        malformed, or the prediction diverges (not finite).
    ModelError
        ``model`` is not a StateSpace.
    """
    model, data = _check(model, data)
    k = _check_steps(steps)
    if hold is not None and (not isinstance(hold, str) or hold not in HOLDS):
        raise OptionError(f"hold must be 'zoh' or 'foh', got {hold!r}"[:300])
    if output_std is not None:
        output_std = np.asarray(output_std, dtype=float)
        if output_std.shape != (data.n_outputs,) or not (np.isfinite(output_std).all()
                                                         and (output_std >= 0).all()):
            raise DataError(f"output_std must hold {data.n_outputs} finite non-negative "
                            f"spreads, one per output; got shape {output_std.shape}")
    x0 = check_x0(x0, model.order, data.n_experiments)
    if isinstance(x0, str) and x0 == "estimate" and \
            (line := _delay_line_model(model)) is not None:
        # the inputs of the delay line before the record estimated with the state
        y_hat, x0_line = predict(line, data, steps, x0, return_x0=True,
                                 output_std=output_std, hold=hold)
        return (y_hat, x0_line[..., :model.order]) if return_x0 else y_hat
    if data.n_experiments > 1:          # each experiment from its own initial state
        parts = [predict(model, e, steps, x0_e, return_x0=True, output_std=output_std,
                         hold=hold)
                 for e, x0_e in zip(data.experiments,
                                    experiment_x0(x0, data.n_experiments, model.order))]
        y_hat = np.vstack([p[0] for p in parts])
        return (y_hat, np.stack([p[1] for p in parts])) if return_x0 else y_hat
    if model.is_continuous or model.K is None:
        if k != math.inf:
            why = "a continuous-time model" if model.is_continuous else \
                "the model has no Kalman gain K"
            warnings.warn(f"predict(steps={steps}): {why}, so the prediction is the "
                          "simulation (steps=inf); identify with a discrete-time method "
                          "(or subid.pem) for a noise model", NoiseModelWarning, stacklevel=2)
        y_hat, x0v = simulate_fit(model, data, x0=x0, hold=hold, output_std=output_std)
        return (y_hat, x0v) if return_x0 else y_hat
    u, y = effective_input(model, data.u), data.y        # the model's input delays
    if k != math.inf and model.order:
        with np.errstate(all="ignore"):
            Ap = model.A - model.K @ model.C
            rho_p = float(np.abs(np.linalg.eigvals(Ap)).max()) if np.isfinite(Ap).all() \
                else math.inf
        if rho_p >= 1.0:
            # refused before it overflows: a short record gave finite values of 1e101 and
            # fits of -1e102 % without a word (the error came only past the overflow)
            raise DataError(f"the {k}-step prediction diverges: {_divergence_cause(model, k)}")
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            if isinstance(x0, str) and x0 == "estimate":
                x0v, y_hat = _estimate_x0(model, u, y, k, data, output_std)
            else:
                x0v = np.zeros(model.order) if isinstance(x0, str) else x0
                y_hat = _k_step(model, u, y, x0v, k)
    except ModelError:                   # a simulation inside overflowed
        x0v = y_hat = None
    if x0v is None or not np.isfinite(y_hat).all():
        raise DataError(f"the {k}-step prediction diverges over {data.n_samples} samples: "
                        f"{_divergence_cause(model, k)}")
    return (y_hat, x0v) if return_x0 else y_hat


def _divergence_cause(model, k) -> str:
    """Which part of a model with K makes its k-step prediction diverge, and what to do."""
    radius = lambda M: float(np.abs(np.linalg.eigvals(M)).max(initial=0.0))   # noqa: E731
    with np.errstate(all="ignore"):
        rho = radius(model.A) if np.isfinite(model.A).all() else math.inf
        Ap = model.A - model.K @ model.C
        rho_p = radius(Ap) if np.isfinite(Ap).all() else math.inf
    if rho_p >= 1.0:
        state = "stable" if rho < 1.0 else f"unstable too (spectral radius {rho:.4g})"
        return (f"its Kalman predictor A - K C is unstable (spectral radius {rho_p:.4g}); A "
                f"itself is {state}. The noise model (K) does not give a stable predictor: "
                "re-estimate it (subid.pem(data, model)) or compare by simulation (steps=inf)")
    return (f"A is unstable (spectral radius {rho:.4g}) and the {k}-step prediction "
            "propagates it over the horizon; use a shorter horizon (steps) or a stable model")


def prediction_errors(model, data, steps=1, x0=None) -> np.ndarray:
    """``y - predict(model, data, steps, x0)``, shape (N, n_outputs)."""
    model, data = _check(model, data)
    return data.y - predict(model, data, steps, x0)
