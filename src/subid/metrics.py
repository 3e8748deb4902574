"""Validation metrics: Markov-parameter error, simulation fit, pole error."""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.csgraph

from ._validation import check_int
from .data import IOData
from .delay import input_delay_of
from .errors import DataError, ModelError
from .model import StateSpace

__all__ = ["markov_error", "fit_percent", "pole_error", "simulate_fit"]


def _check_model(model, name: str) -> StateSpace:
    if not isinstance(model, StateSpace):
        raise ModelError(f"{name} must be a subid.StateSpace, got {type(model).__name__}")
    return model


def _check_pair(model, reference):
    _check_model(model, "model")
    _check_model(reference, "reference")
    if (model.n_inputs, model.n_outputs) != (reference.n_inputs, reference.n_outputs):
        raise ModelError(f"model has {model.n_inputs} inputs and {model.n_outputs} outputs but "
                         f"the reference has {reference.n_inputs} and {reference.n_outputs}")
    if model.dt != reference.dt and not np.isclose(model.dt, reference.dt, rtol=1e-9, atol=0):
        raise ModelError(f"model has dt={model.dt} but the reference has dt={reference.dt}; "
                         "convert one of them first (to_discrete / to_continuous)")


def check_model_data(model, data) -> None:
    """Raise unless ``data`` is an IOData record with the model's channels and sampling."""
    _check_model(model, "model")
    if not isinstance(data, IOData):
        raise DataError(f"data must be an IOData record, got {type(data).__name__}; wrap "
                        "arrays as subid.IOData(u, y, dt=...)")
    if (data.n_inputs, data.n_outputs) != (model.n_inputs, model.n_outputs):
        raise DataError(f"data have {data.n_inputs} inputs and {data.n_outputs} outputs but "
                        f"the model has {model.n_inputs} and {model.n_outputs}")
    if model.dt > 0:
        if not data.is_uniform or not np.isclose(data.dt, model.dt, rtol=1e-9, atol=0):
            raise DataError(f"the model is discrete with dt={model.dt} but the data are "
                            f"sampled with {'non-uniform t' if not data.is_uniform else data.dt}")


def markov_error(model, reference, k: int = 10) -> float:
    """Relative Frobenius error of the first ``k`` Markov parameters.

    ``||M - M_ref||_F / ||M_ref||_F`` with ``M = [D, CB, CAB, ...,
    C A^{k-2} B]``: invariant to the state basis (seed 001, Fig. 2).

    Parameters
    ----------
    model, reference : StateSpace
        Same numbers of inputs and outputs and the same ``dt``.
    k : int
        Number of Markov parameters, D included.
    """
    _check_pair(model, reference)
    k = check_int(k, "k", minimum=1)
    m_ref = reference.markov(k)
    norm = np.linalg.norm(m_ref)
    if norm == 0:
        raise ModelError("the reference's first Markov parameters are all zero; the relative "
                         "error is undefined")
    return float(np.linalg.norm(model.markov(k) - m_ref) / norm)


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
        stable = bool(np.abs(model.poles()).max(initial=0.0) < 1.0)
    else:
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


def simulate_fit(model, data, x0="estimate", hold: str = "zoh", *, output_std=None):
    """Simulated output of ``model`` on ``data`` and the initial state used.

    ``output_std`` (per output) replaces the spread of ``data.y`` in the
    weights of the initial-state regression (used when ``data`` is the
    prefix of a longer record whose weights apply).

    ``x0='estimate'`` fits the initial state to the data by least squares
    (the simulated output is linear in x0), each output weighted by the
    inverse of its standard deviation; ``'zero'`` or an array fixes it.

    Memory stays bounded by a block of :data:`_SIM_BLOCK` samples beyond the
    returned output: the simulations run block by block without the state
    history, and the least-squares problem for x0 (``N n_outputs`` rows,
    ``n`` columns) is reduced block by block to the triangular factor of
    ``[regressors | residual]`` (QR), from which the same minimum-norm
    solution as ``lstsq`` of the whole problem follows (same singular
    values and vectors, same cut-off ``eps * max(rows, n)``). The free
    response of a stable model is only computed until it has decayed below
    rounding.
    """
    check_model_data(model, data)
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
        forced = simulate(np.zeros(n))
        # each output weighted by 1 / its standard deviation, so that the initial state
        # (and the fit) does not depend on the output units
        if output_std is None:
            from ._subspace import column_std
            std = column_std(data.y)
        else:
            std = np.asarray(output_std, float)
        w = 1.0 / np.where(std > 0, std, 1.0)
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
    x0_arr = np.asarray(x0, dtype=float).reshape(-1)
    if x0_arr.shape != (n,):
        raise DataError(f"x0 must have {n} entries (the model order), got {x0_arr.size}")
    return simulate(x0_arr), x0_arr


def fit_percent(model, data, x0="estimate", hold: str = "zoh", steps=np.inf) -> np.ndarray:
    """NRMSE fit in percent, per output: ``100 (1 - ||y - ŷ|| / ||y - mean(y)||)``.

    ``ŷ`` is the simulated output (default, ``steps=inf``) or the
    ``steps``-ahead prediction (:func:`subid.predict`, the Kalman predictor
    of a model with ``K``), from an initial state estimated by least squares
    unless ``x0`` says otherwise. 100 is a perfect fit; 0 is no better than
    the mean; it can be negative.

    Parameters
    ----------
    model : StateSpace
    data : IOData
        Same channels; for a discrete model, the same sampling period.
    x0 : 'estimate', 'zero' or array
    hold : {'zoh', 'foh'}
        Inter-sample behaviour of the input for a continuous-time model.
    steps : int or numpy.inf
        Prediction horizon (MATLAB ``compare(data, model, k)``).

    Returns
    -------
    ndarray, shape (n_outputs,)
    """
    if steps is not None and not (isinstance(steps, float) and np.isinf(steps) and steps > 0):
        from .prediction import predict
        x0p = None if isinstance(x0, str) and x0 == "estimate" else x0
        y_hat = predict(_check_model(model, "model"), data, steps, x0p)
    else:
        y_hat, _ = simulate_fit(model, data, x0=x0, hold=hold)
    # Each output is divided by its largest magnitude first: the ratio is
    # scale-invariant, and squaring values near 1e300 would overflow to inf
    # (inf / inf = NaN) where the fit is perfectly defined.
    # In blocks of rows, so that no N x outputs temporary is allocated.
    N, block = data.n_samples, _SIM_BLOCK
    scale = np.zeros(data.n_outputs)
    for a in range(0, N, block):
        scale = np.maximum(scale, np.abs(data.y[a:a + block]).max(axis=0))
    scale[scale == 0] = 1.0
    mean = sum(np.sum(data.y[a:a + block] / scale, axis=0) for a in range(0, N, block)) / N
    dev2 = np.zeros(data.n_outputs)
    err2 = np.zeros(data.n_outputs)
    for a in range(0, N, block):
        y = data.y[a:a + block] / scale
        dev2 += np.sum((y - mean) ** 2, axis=0)
        err2 += np.sum((y - y_hat[a:a + block] / scale) ** 2, axis=0)
    dev = np.sqrt(dev2)
    flat = np.flatnonzero(dev == 0)
    if flat.size:
        names = ", ".join(data.output_names[k] for k in flat)
        raise DataError(f"output {names} is constant; the fit percentage is undefined for it")
    return 100.0 * (1.0 - np.sqrt(err2) / dev)


def pole_error(model, reference) -> float:
    """Largest pole distance after the best one-to-one matching of poles.

    The matching minimises the largest distance (a bottleneck assignment),
    so the result is the smallest ``d`` such that every pole of ``model``
    can be paired with a distinct pole of ``reference`` within ``d``.
    """
    _check_pair(model, reference)
    p, q = model.poles(), reference.poles()
    if p.size != q.size:
        raise ModelError(f"model has order {p.size} but the reference has order {q.size}; "
                         "pole errors compare models of the same order")
    dist = np.abs(p[:, None] - q[None, :])
    candidates = np.unique(dist)
    lo, hi = 0, candidates.size - 1
    while lo < hi:   # smallest threshold that admits a perfect matching
        mid = (lo + hi) // 2
        graph = scipy.sparse.csr_matrix((dist <= candidates[mid]).astype(np.int8))
        match = scipy.sparse.csgraph.maximum_bipartite_matching(graph, perm_type="column")
        if np.all(match >= 0):
            hi = mid
        else:
            lo = mid + 1
    return float(candidates[lo])
