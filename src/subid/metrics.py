"""Validation metrics: Markov-parameter error, simulation fit, pole error."""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from ._validation import check_int
from .data import IOData
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


def simulate_fit(model, data, x0="estimate", hold=None, *, output_std=None):
    """Simulated output of ``model`` on ``data`` and the initial state used.

    ``output_std`` (per output) replaces the spread of ``data.y`` in the
    weights of the initial-state regression (used when ``data`` is the
    prefix of a longer record whose weights apply).

    ``x0='estimate'`` fits the initial state to the data by least squares
    (the simulated output is linear in x0), each output weighted by the
    inverse of its standard deviation; ``'zero'`` or an array fixes it.

    A record of several experiments (:func:`subid.merge`) is simulated
    experiment by experiment, each from its own initial state: the returned
    x0 then has shape (n_experiments, n), and an array given as ``x0`` must
    have that shape.
    ``hold`` (continuous-time models) defaults to the model's :attr:`~subid.StateSpace.hold`.
    """
    check_model_data(model, data)
    if data.n_experiments > 1:
        std = data.y.std(axis=0) if output_std is None else output_std
        parts = [simulate_fit(model, e, x0=x0_e, hold=hold, output_std=std)
                 for e, x0_e in zip(data.experiments,
                                    experiment_x0(x0, data.n_experiments, model.order))]
        return np.vstack([p[0] for p in parts]), np.stack([p[1] for p in parts])
    if model.dt > 0:
        sim = lambda u, x0v: model.simulate(u, x0=x0v)  # noqa: E731
    else:
        sim = lambda u, x0v: model.simulate(u, t=data.t, x0=x0v, hold=hold)  # noqa: E731
    n = model.order

    def overflow():
        radius = float(np.abs(model.poles()).max()) if model.dt > 0 else \
            float(model.poles().real.max())
        kind = "spectral radius" if model.dt > 0 else "largest real part of a pole"
        return ModelError(f"simulating the model over {data.n_samples} samples overflows (its "
                          f"{kind} is {radius:.4g}): the model is unstable and its simulated "
                          "output, hence its fit, is undefined")

    with np.errstate(over="ignore", invalid="ignore"):
        forced = sim(data.u, None)
    if not np.isfinite(forced).all():
        raise overflow()
    if isinstance(x0, str) and x0 == "zero":
        return forced, np.zeros(n)
    if isinstance(x0, str) and x0 == "estimate":
        zeros = np.zeros_like(data.u)
        with np.errstate(over="ignore", invalid="ignore"):
            free = np.stack([sim(zeros, e) for e in np.eye(n)], axis=-1)  # (N, ny, n)
        if not np.isfinite(free).all():
            raise overflow()
        # each output weighted by 1 / its standard deviation, so that the initial state
        # (and the fit) does not depend on the output units
        std = data.y.std(axis=0) if output_std is None else np.asarray(output_std, float)
        w = 1.0 / np.where(std > 0, std, 1.0)
        x0_hat = np.linalg.lstsq((free * w[None, :, None]).reshape(-1, n),
                                 ((data.y - forced) * w).reshape(-1), rcond=None)[0]
        return forced + free @ x0_hat, x0_hat
    x0_arr = np.asarray(x0, dtype=float).reshape(-1)
    if x0_arr.shape != (n,):
        raise DataError(f"x0 must have {n} entries (the model order), got {x0_arr.size}")
    return sim(data.u, x0_arr), x0_arr


def experiment_x0(x0, n_experiments: int, order: int) -> list:
    """``x0`` of :func:`simulate_fit` split per experiment: a string or ``0`` for
    every experiment, or an array of shape (n_experiments, order)."""
    if isinstance(x0, str) or (isinstance(x0, (int, float)) and not isinstance(x0, bool)
                               and x0 == 0) or x0 is None:
        return [x0] * n_experiments
    arr = np.asarray(x0, dtype=float)
    if arr.shape != (n_experiments, order):
        raise DataError(f"the record has {n_experiments} experiments: x0 must have shape "
                        f"({n_experiments}, {order}), one initial state per experiment, "
                        f"got shape {arr.shape}")
    return list(arr)


def fit_percent(model, data, x0="estimate", hold=None, steps=np.inf, *,
                per_experiment: bool = False) -> np.ndarray:
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
    hold : {'zoh', 'foh'}, optional
        Inter-sample behaviour of the input for a continuous-time model.
        Default: the model's :attr:`~subid.StateSpace.hold` (``'foh'`` for a
        ``ct_subspace`` model).
    steps : int or numpy.inf
        Prediction horizon (MATLAB ``compare(data, model, k)``).
    per_experiment : bool
        For a record of several experiments (:func:`subid.merge`; each is
        simulated from its own initial state): ``False`` (default) gives one
        pooled fit per output, ``100 (1 - ||y - ŷ|| / ||y - ȳ_e||)`` over all
        samples with each experiment's own mean ``ȳ_e`` as the reference;
        ``True`` gives one fit per experiment and output (as MATLAB's
        ``compare``).

    Returns
    -------
    ndarray, shape (n_outputs,), or (n_experiments, n_outputs) with
    ``per_experiment=True``
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
    scale = np.abs(data.y).max(axis=0)
    scale[scale == 0] = 1.0
    y, y_hat = data.y / scale, y_hat / scale
    ranges = data.experiment_ranges
    dev2 = np.array([((y[a:b] - y[a:b].mean(axis=0)) ** 2).sum(axis=0) for a, b in ranges])
    err2 = np.array([((y[a:b] - y_hat[a:b]) ** 2).sum(axis=0) for a, b in ranges])
    if per_experiment:
        dev2_used, err2_used = dev2, err2
    else:
        dev2_used, err2_used = dev2.sum(axis=0), err2.sum(axis=0)
    flat = np.flatnonzero(np.atleast_2d(dev2_used).min(axis=0) == 0)
    if flat.size:
        names = ", ".join(data.output_names[k] for k in flat)
        where = " in an experiment" if per_experiment and data.n_experiments > 1 else ""
        raise DataError(f"output {names} is constant{where}; the fit percentage is undefined "
                        "for it")
    return 100.0 * (1.0 - np.sqrt(err2_used) / np.sqrt(dev2_used))


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
