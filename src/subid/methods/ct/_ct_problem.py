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
    its folds; ``horizon`` is the number of basis functions. The filtered
    regressors ``R`` (:meth:`regressors`) are held only until the range basis
    of the instrument iterations is formed from them (:meth:`release`): the
    record's largest array, not needed beside that basis except by the rare
    fallbacks, which filter the record again (the same values).
    """

    method: str
    data: IOData
    order: int | None
    candidates: list
    horizon: int
    settings: dict
    record: _ct_fit.Record
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
    #: ``{'R': regressors}`` while they are held; shared by the copies, like ``memo``.
    held: dict = field(default_factory=dict, repr=False, compare=False)

    def regressors(self) -> np.ndarray:
        """The filtered regressors ``R = [phi, 1, u_f, r]`` of :func:`prepare` (held, or
        filtered again after :meth:`release`: the same deterministic kernels, the same
        values bit for bit)."""
        R = self.held.get("R")
        if R is None:
            R = _filtered(self.data, self.settings, outputs=False)[0]
            self.held["R"] = R
        return R

    def take_regressors(self) -> np.ndarray:
        """:meth:`regressors`, no longer held: the caller's reference is the only one."""
        R = self.regressors()
        self.release()
        return R

    def release(self) -> None:
        """Drop the held regressors (:meth:`regressors` filters them again if asked)."""
        self.held.pop("R", None)


def _fill_experiment(basis, e: IOData, s: dict, k: int, E: int, R, Z, Y, UF):
    """Filter experiment ``k`` (of ``E``; filters at rest at its start) into its rows of
    the regressors ``R`` (columns ``[phi_1 .. phi_E, 1_1 .. 1_E, u_f, r]``, the start-up
    and offset columns of the other experiments left zero), the instruments ``Z``, the
    filtered outputs ``Y`` and the filtered inputs ``UF`` (each None where not wanted)."""
    N = basis.n_functions
    t, u, y = e.t, e.u, e.y
    poly_order, input_order, filtering = s["poly_order"], s["input_order"], s["filtering"]
    L = t.size
    if s["filtered"] is not None:
        uf, yf = s["filtered"]
    else:
        yf = None if Y is None else basis.filter(y, t, poly_order=poly_order, chain=filtering)
        uf = basis.filter(u, t, poly_order=input_order, chain=filtering)
    if Y is not None:
        Y[:] = yf.reshape(L, -1)
    del yf
    col = 0
    if s["startup"]:                  # phi(t - t_e) of each experiment, on its own rows
        R[:, k * N:(k + 1) * N] = basis.functions(t - t[0])
        col = N * E
    if s["offset"]:                   # a constant per experiment: the filtered output offset
        R[:, col + k] = 1.0
        col += E
    ufl = uf.reshape(L, -1)
    if s["data_equation"] == "paper":
        U = basis.paper_input_stack(u, t, poly_order=input_order, chain=filtering)
        U = U.reshape(L, -1)
    else:
        U = ufl
    R[:, col:col + U.shape[1]] = U
    col += U.shape[1]
    del U
    if s["n_corr"]:
        _correction_regressors(basis, t, u, poly_order, input_order, s["feedthrough"] is True,
                               filtering, e.is_uniform, out=R[:, col:col + s["n_corr"]])
    if Z is not None:
        Z[s["lag"]:] = ufl[:-s["lag"]]
    if UF is not None:
        UF[:] = ufl


def _filtered(data: IOData, s: dict, outputs: bool = True):
    """``(R, Z, Y, UF)``: the filtered regressors, instruments (None unless ``'past'``),
    outputs (None without ``outputs``) and, for the paper's data equation, inputs of
    every experiment, stacked; each written in place, experiment by experiment."""
    basis = s["basis"]
    N = basis.n_functions
    m, p = data.n_inputs, data.n_outputs
    exps = data.experiments
    E = len(exps)
    paper = s["data_equation"] == "paper"
    n_u = (N * (N + 1) // 2 if paper else N) * m
    width = (N * E if s["startup"] else 0) + (E if s["offset"] else 0) + n_u + s["n_corr"]
    total = data.n_samples
    R = np.zeros((total, width))
    Z = np.zeros((total, N * m)) if s["instruments"] == "past" else None
    Y = np.empty((total, N * p)) if outputs else None
    UF = np.empty((total, N * m)) if paper else None
    row = 0
    for k, e in enumerate(exps):
        rows = slice(row, row + e.n_samples)
        _fill_experiment(basis, e, s, k, E, R[rows], None if Z is None else Z[rows],
                         None if Y is None else Y[rows], None if UF is None else UF[rows])
        row += e.n_samples
    return R, Z, Y, UF


def prepare(data: IOData, candidates, s: dict) -> Problem:
    """Filter every experiment, factor ``[phi; 1; u_f; r; z; y_f]`` and take the SVD.

    The signals are written experiment by experiment into the regressors, instruments
    and outputs (no per-experiment pieces stacked, no joined copy of them), and the
    factor overwrites one scaled copy (:func:`subid.methods.ct._ct_estimate._subspace_factor`):
    the same factor, bit for bit.
    """
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
    R, Z, Y, UF = _filtered(data, s)
    total = data.n_samples
    n_before = (N * E if s["startup"] else 0) + (E if s["offset"] else 0)
    iU = slice(n_before, n_before + n_u_rows)
    Lf, W = _subspace_factor(R, Z, Y)
    del Z
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
        X = np.hstack([S, UF])
        del S, UF
        dU = np.abs(np.diag(np.linalg.qr(X, mode="r")))[N * E:]
    if dU.max(initial=0.0) == 0 or dU.min() <= _RANK_TOL * dU.max():
        raise NotExcitingError(f"{s['method']}: the filtered inputs are linearly dependent: "
                               "the input does not excite every basis function (is it zero, "
                               "constant, or are two inputs proportional?); use a richer "
                               "input (white noise, multisine)")
    Uo, sv, _ = np.linalg.svd(W, full_matrices=False)
    return Problem(s["method"], data, None, list(candidates), N, s,
                   _ct_fit.Record(data, s["input_order"]), Y, Lf, iU, Uo, sv, s["n_corr"],
                   lag, held={"R": R})
