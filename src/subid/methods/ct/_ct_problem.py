"""The prepared problem of :func:`subid.ct_subspace`: one record's filtered signals, factor
and SVD, shared by every candidate order (seed 002; the data equation and its
regressors are described in :mod:`subid.methods.ct.ct_subspace`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from subid.data import IOData
from subid.errors import NotExcitingError, TooFewSamplesError
from subid.methods.ct import _ct_fit
from subid.methods.ct._ct_checks import _lag_for
from subid.methods.ct._ct_estimate import _correction_regressors, _subspace_factor

__all__ = ["Problem", "prepare"]

# Relative size of a diagonal entry of the filtered-input factor below which
# the filtered inputs count as linearly dependent.
_RANK_TOL = 1e-10


# ---------------------------------------------------------------------------
# the prepared problem: filtered signals, factor and SVD of one record
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Problem:
    """One record's subspace step, shared by every candidate order.

    ``order`` and ``candidates`` follow the discrete-time ``Problem``, so that
    :func:`subid.methods.dt.selection.cross_validate` can run the method on
    its folds; ``horizon`` is the number of basis functions.
    """

    method: str
    data: IOData
    order: int | None
    candidates: list
    horizon: int
    settings: dict
    record: _ct_fit.Record
    R: np.ndarray = field(repr=False)
    Y: np.ndarray = field(repr=False)
    Lf: np.ndarray = field(repr=False)
    iU: slice
    Uo: np.ndarray = field(repr=False)
    sv: np.ndarray
    n_corr: int
    lag: int
    #: A cross-validation fold's problem (set by ``score_horizon``; unused here).
    fold: bool = False
    #: Models (and discrete-time starts) already built on this record, by what decides
    #: them: the choices of one call (order, feedthrough, B and D, refinement) score the
    #: same builds on the same folds, and copies made by ``replace`` share it.
    memo: dict = field(default_factory=dict, repr=False, compare=False)


def _experiment_regressors(basis, e: IOData, s: dict, uniform: bool):
    """Filtered signals and regressors of one experiment (filters at rest at its start)."""
    t, u, y = e.t, e.u, e.y
    poly_order, input_order, filtering = s["poly_order"], s["input_order"], s["filtering"]
    if s["filtered"] is not None:
        uf, yf = s["filtered"]
    else:
        yf = basis.filter(y, t, poly_order=poly_order, chain=filtering)
        uf = basis.filter(u, t, poly_order=input_order, chain=filtering)
    L = t.size
    if s["data_equation"] == "paper":
        U = basis.paper_input_stack(u, t, poly_order=input_order, chain=filtering).reshape(L, -1)
    else:
        U = uf.reshape(L, -1)
    start = basis.functions(t - t[0]) if s["startup"] else np.zeros((L, 0))
    corr = np.zeros((L, 0))
    if s["n_corr"]:
        corr = _correction_regressors(basis, t, u, poly_order, input_order,
                                      s["feedthrough"] is True, filtering, uniform)
    Z = None
    if s["instruments"] == "past":
        ufl = uf.reshape(L, -1)
        Z = np.zeros_like(ufl)
        Z[s["lag"]:] = ufl[:-s["lag"]]
    return start, U, corr, Z, yf.reshape(L, -1), uf.reshape(L, -1)


def prepare(data: IOData, candidates, s: dict) -> Problem:
    """Filter every experiment, factor ``[phi; 1; u_f; r; z; y_f]`` and take the SVD."""
    basis = s["basis"]
    N = basis.n_functions
    m, p = data.n_inputs, data.n_outputs
    exps = data.experiments
    E = len(exps)
    lag = _lag_for(basis, exps[0].t) if s["instruments"] == "past" else 0
    n_u_rows = (N * (N + 1) // 2 if s["data_equation"] == "paper" else N) * m
    rows = (N * E if s["startup"] else 0) + (E if s["offset"] else 0) + n_u_rows \
        + s["n_corr"] + N * p + (N * m if s["instruments"] == "past" else 0)
    need = max(rows + 1, s["poly_order"] + 1) + lag
    shortest = min(e.n_samples for e in exps)
    if data.n_samples < need or shortest <= max(s["poly_order"], lag) + 1:
        raise TooFewSamplesError(
            f"{s['method']}: {data.n_samples} samples are too few for a basis of {N} "
            f"functions with {m} input(s) and {p} output(s): the data matrix has {rows} rows "
            f"and needs at least {need} samples; supply more data or use fewer basis functions")
    pieces = [_experiment_regressors(basis, e, s, e.is_uniform) for e in exps]
    total = data.n_samples
    blocks = []
    if s["startup"]:                  # phi(t - t_e) of each experiment, on its own rows
        S = np.zeros((total, N * E))
        row = 0
        for k, (start, *_) in enumerate(pieces):
            S[row:row + start.shape[0], k * N:(k + 1) * N] = start
            row += start.shape[0]
        blocks.append(S)
    if s["offset"]:                   # a constant per experiment: the filtered output offset
        ones = np.zeros((total, E))
        row = 0
        for k, e in enumerate(exps):
            ones[row:row + e.n_samples, k] = 1.0
            row += e.n_samples
        blocks.append(ones)
    n_before = sum(b.shape[1] for b in blocks)
    U = np.vstack([piece[1] for piece in pieces])
    blocks.append(U)
    if s["n_corr"]:
        blocks.append(np.vstack([piece[2] for piece in pieces]))
    R = np.hstack(blocks)
    iU = slice(n_before, n_before + U.shape[1])
    Z = None if s["instruments"] != "past" else np.vstack([piece[3] for piece in pieces])
    Y = np.vstack([piece[4] for piece in pieces])
    Lf, W = _subspace_factor(R, Z, Y)
    dU = np.abs(np.diag(Lf)[iU])
    if s["data_equation"] == "paper":
        # the paper's stacked input has dependent rows by construction: the test is the
        # compact equation's, on the filtered inputs beside the filters' start-up
        # responses (a constant input gave an unstable model)
        S = np.zeros((total, N * E))
        row = 0
        for k, e in enumerate(exps):
            S[row:row + e.n_samples, k * N:(k + 1) * N] = basis.functions(e.t - e.t[0])
            row += e.n_samples
        X = np.hstack([S, np.vstack([piece[5] for piece in pieces])])
        dU = np.abs(np.diag(np.linalg.qr(X, mode="r")))[N * E:]
    if dU.max(initial=0.0) == 0 or dU.min() <= _RANK_TOL * dU.max():
        raise NotExcitingError(f"{s['method']}: the filtered inputs are linearly dependent: "
                               "the input does not excite every basis function (is it zero, "
                               "constant, or are two inputs proportional?); use a richer "
                               "input (white noise, multisine)")
    Uo, sv, _ = np.linalg.svd(W, full_matrices=False)
    return Problem(s["method"], data, None, list(candidates), N, s,
                   _ct_fit.Record(data, s["input_order"]), R, Y, Lf, iU, Uo, sv, s["n_corr"],
                   lag)
