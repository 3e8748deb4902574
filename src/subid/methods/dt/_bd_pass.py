"""The B, D, x0 output regression as a mergeable second pass over a record in pieces.

Given (A, C) from the first pass (the statistic), the regression of
:func:`subid.methods.dt._regression.fit_b_d_x0` is a sum over the samples once each
piece of the record knows the regressor state at its start. Each piece is
reduced on its own, from a zero start (:func:`modal_piece`): the moments of
its zero-start modal signals and of the free responses ``λ^(t - t0)``, its
zero-start filter state at its end, and its output mean and spread. A linear
scan over the pieces (:func:`combine_modal`) then gives every piece its start
state, maps its moments to the global regressors
(:func:`subid.methods.dt._regression.regressor_maps`) and sums the normal equations: the
same normal equations as the in-memory record, to rounding. So the second pass
is one more pass over the data, in parallel over the pieces, with memory
bounded by a piece's chunk. (When the fit is nearly exact, the residual RMS
of the normal equations is rounding; one more pass then computes it sample
by sample, as the in-memory path does.)

Where the in-memory path would fall back to the QR factorisation (A
unstable or nearly defective, the normal equations ill-conditioned), so does
this one, in two further passes: the zero-start sensitivities at the piece
ends (:func:`sensitivity_piece`), a scan for the start sensitivities, then the
triangular factors of each piece's rows (:func:`qr_piece`), stacked and
factorised again.

A *record in pieces* is a callable ``map_pieces(function, arguments)`` that
returns ``[function(chunks_k, *arguments[k]) for every piece k]`` in time
order, with ``chunks_k`` an iterable of consecutive ``(u, y)`` arrays of piece
k (``arguments`` a list with one tuple per piece, ``n_pieces`` of them).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid._kernel_args import frozen
from subid._threads import ordered_map
from subid.data import column_sums, minus_columns
from subid.methods.dt._bd_large import solve_factor_blocks, solve_normal_blocks
from subid.methods.dt._regression import (
    _MODAL_BLOCK,
    RESIDUAL_RECOMPUTE,
    ModalForm,
    modal_signals,
    next_filter_state,
    normal_equations,
    parameter_count,
    qr_factor,
    regressor_maps,
    sensitivity_rows,
    solve_factor,
)

__all__ = ["OutputRegression"]


class _Spread:
    """Count, mean and sum of squared deviations per output (merged exactly, Chan et al.)."""

    def __init__(self, ny):
        self.count, self.mean, self.m2 = 0, np.zeros(ny), np.zeros(ny)

    def add(self, y):
        if not len(y):
            return
        mean = column_sums(y) / len(y)
        deviation = minus_columns(y, mean)
        self.merge(len(y), mean, np.array([column @ column for column in deviation.T]))

    def merge(self, count, mean, m2):
        if count == 0:
            return self
        total = self.count + count
        delta = mean - self.mean
        self.mean = self.mean + delta * (count / total)
        self.m2 = self.m2 + m2 + delta ** 2 * (self.count * count / total)
        self.count = total
        return self

    def weights(self):
        """1 / standard deviation, as :func:`subid.methods.dt._subspace.output_weights`."""
        std = np.sqrt(self.m2 / max(self.count, 1))
        return 1.0 / np.where(std > 0, std, 1.0)


def modal_piece(chunks, form, n_inputs, n_outputs):
    """Reduce one piece for the modal normal equations (zero start).

    Returns
    -------
    dict with ``moments`` (d, d), ``r_end`` (zero-start filter state at the
    end), ``length``, and ``count``/``mean``/``m2`` of the outputs.
    """
    d = form.signal_count(n_inputs, n_outputs)
    n = form.n_state
    moments = np.zeros((d, d))
    r = np.zeros((form.lam.size, n_inputs), dtype=complex)
    e = np.ones(form.lam.size, dtype=complex)
    spread = _Spread(n_outputs)
    length = 0
    for u, y in chunks:
        u = np.asarray(u, dtype=float)
        y = np.asarray(y, dtype=float)
        spread.add(y)
        for start in range(0, len(u), _MODAL_BLOCK):
            stop = min(start + _MODAL_BLOCK, len(u))
            tau0 = length + start
            w, r, e = modal_signals(form.lam, form.is_real, frozen(u[start:stop]),
                                    frozen(y[start:stop]), r, e, tau0, form.n_free)
            if tau0 < form.n_free:
                moments += w.T @ w
            else:
                tail = w[:, n:]
                moments[n:, n:] += tail.T @ tail
        length += len(u)
    return {"moments": moments, "r_end": r, "length": length, "count": spread.count,
            "mean": spread.mean, "m2": spread.m2}


def sensitivity_piece(chunks, A, C, q, n_x0):
    """Zero-start sensitivity at the end of one piece, its length and output spread."""
    S = np.zeros((A.shape[0], q))
    spread = None
    length = 0
    for u, y in chunks:
        u = np.ascontiguousarray(u, dtype=float)
        y = np.asarray(y, dtype=float)
        spread = spread or _Spread(y.shape[1])
        spread.add(y)
        with np.errstate(over="ignore", invalid="ignore"):
            _, S = sensitivity_rows(frozen(A), frozen(C), frozen(u), S, n_x0)
        length += len(u)
    return {"S_end": S, "length": length, "count": spread.count if spread else 0,
            "mean": spread.mean if spread else 0.0, "m2": spread.m2 if spread else 0.0}


def qr_piece(chunks, A, C, S, n_x0, feedthrough, weights):
    """Triangular factor of the weighted regressor rows of one piece from start ``S``."""
    R = None
    for u, y in chunks:
        with np.errstate(over="ignore", invalid="ignore"):
            R, S = qr_factor(A, C, np.asarray(u, dtype=float), np.asarray(y, dtype=float), S,
                             n_x0=n_x0, feedthrough=feedthrough, output_weights=weights, R=R)
    return R


def _spread_of(parts, ny):
    spread = _Spread(ny)
    for part in parts:
        spread.merge(part["count"], part["mean"], part["m2"])
    return spread


def combine_modal(form, parts, n_inputs, n_outputs, *, estimate_x0, feedthrough,
                  experiments=None):
    """Normal equations of the whole record from the pieces' reductions (time order).

    ``experiments`` (the experiment of every piece, non-decreasing; default all
    0): at the first piece of an experiment the filters restart from zero and
    the free signals from ``λ^0``, and its x0 has its own unknowns.

    Returns ``(blocks, n_samples, maps, weights)``: ``blocks[e]`` the normal
    equations of experiment e in the layout ``[x0_e; vec B; vec D; y]``
    (:func:`subid.methods.dt._bd_large.solve_normal_blocks` eliminates the x0 of
    each), ``maps`` the per-piece
    :func:`subid.methods.dt._regression.regressor_maps` (None for an empty piece).
    """
    weights = _spread_of(parts, n_outputs).weights()
    experiments = [0] * len(parts) if experiments is None else list(experiments)
    n_exp = (max(experiments) + 1) if experiments else 1
    r = np.zeros((form.lam.size, n_inputs), dtype=complex)
    t0 = 0
    total = 0
    blocks = [0.0] * n_exp
    maps = []
    current = 0
    for part, e in zip(parts, experiments):
        if e != current:                    # a new experiment: its own start
            r = np.zeros((form.lam.size, n_inputs), dtype=complex)
            t0, current = 0, e
        if part["length"] == 0:
            maps.append(None)
            continue
        P = regressor_maps(form, n_inputs, n_outputs, estimate_x0=estimate_x0,
                           feedthrough=feedthrough, t0=t0, r_start=r)
        maps.append(P)
        blocks[e] = blocks[e] + normal_equations(P, part["moments"], weights)
        r = next_filter_state(form, r, part["r_end"], part["length"])
        t0 += part["length"]
        total += part["length"]
    return blocks, total, maps, weights


def residual_piece(chunks, form, g):
    """Sum over one piece of the squared weighted residuals ``(w(t) g^T)``, one column
    per output (``g`` maps the piece's zero-start signals to the residuals)."""
    total = 0.0
    r = np.zeros((form.lam.size, 0), dtype=complex)
    e = np.ones(form.lam.size, dtype=complex)
    length = 0
    for u, y in chunks:
        u = np.asarray(u, dtype=float)
        y = np.asarray(y, dtype=float)
        if r.shape[1] != u.shape[1]:
            r = np.zeros((form.lam.size, u.shape[1]), dtype=complex)
        for start in range(0, len(u), _MODAL_BLOCK):
            stop = min(start + _MODAL_BLOCK, len(u))
            w, r, e = modal_signals(form.lam, form.is_real, frozen(u[start:stop]),
                                    frozen(y[start:stop]), r, e, length + start, form.n_free)
            total += float(np.sum((w @ g.T) ** 2))
        length += len(u)
    return total


class OutputRegression:
    """The B, D, x0 regression of a record held in pieces (see the module docstring).

    Attach it to the record's :class:`~subid.HankelStatistic` as
    ``statistic.output_regression``; :func:`subid.methods.bd.fit_b_d_x0` then
    calls it where the in-memory record runs :func:`subid.methods.dt._regression.fit_b_d_x0`.

    Parameters
    ----------
    map_pieces : callable
        ``map_pieces(function, arguments)`` as described in the module docstring.
    n_pieces : int
    n_inputs, n_outputs : int
    """

    def __init__(self, map_pieces, n_pieces, n_inputs, n_outputs, experiments=None):
        self.map_pieces = map_pieces
        self.n_pieces = n_pieces
        self.n_inputs, self.n_outputs = n_inputs, n_outputs
        self.passes = 0
        #: the experiment of every piece (non-decreasing; :func:`subid.merge`)
        self.experiments = [0] * n_pieces if experiments is None else list(experiments)
        self.n_experiments = max(self.experiments) + 1 if self.experiments else 1

    def _shape_x0(self, x0, n):
        if self.n_experiments == 1 or x0 is None:
            return x0
        return np.asarray(x0).reshape(self.n_experiments, n)

    def _map(self, function, arguments):
        self.passes += 1
        return list(self.map_pieces(function, arguments))

    def __call__(self, A, C, *, feedthrough=True, estimate_x0=True):
        """``(B, D, x0, diagnostics)`` exactly as :func:`subid.methods.dt._regression.fit_b_d_x0`
        on the whole record (output weights 1 / standard deviation)."""
        A = np.ascontiguousarray(A, dtype=float)
        C = np.ascontiguousarray(C, dtype=float)
        n, nu, ny = A.shape[0], self.n_inputs, self.n_outputs
        form = ModalForm.of(A, C)
        if form is not None:
            parts = self._map(modal_piece, [(form, nu, ny)] * self.n_pieces)
            blocks, n_samples, maps, weights = combine_modal(form, parts, nu, ny,
                                                             estimate_x0=estimate_x0,
                                                             feedthrough=feedthrough,
                                                             experiments=self.experiments)
            solved = None if any(np.ndim(N) == 0 for N in blocks) else solve_normal_blocks(
                blocks, n, nu, ny, estimate_x0=estimate_x0, feedthrough=feedthrough,
                n_samples=n_samples)
            if solved is not None:
                B, D, x0, thetas, diagnostics = solved
                diagnostics["regression_passes"] = 1
                if diagnostics["residual_rms"] ** 2 * n_samples * ny < \
                        RESIDUAL_RECOMPUTE * sum(N[-1, -1] for N in blocks):
                    # nearly exact fit: the residual sample by sample, as in memory
                    gs = [np.zeros((ny, form.signal_count(nu, ny))) if P is None else
                          np.stack([weights[i] * (P[i, -1] - thetas[e] @ P[i, :-1])
                                    for i in range(ny)])
                          for P, e in zip(maps, self.experiments)]
                    total = sum(self._map(residual_piece, [(form, g) for g in gs]))
                    diagnostics["residual_rms"] = float(np.sqrt(total / (n_samples * ny)))
                    diagnostics["regression_passes"] = 2
                return B, D, x0, diagnostics
        return self._qr(A, C, feedthrough=feedthrough, estimate_x0=estimate_x0)

    def initial_state(self, A, B, C, D):
        """Least-squares x0 of the model (A, B, C, D) on the record, outputs weighted
        by 1 / standard deviation (as :func:`subid.model.prediction.simulate_fit`): the x0 rows
        of the normal equations with B and D fixed. None where the modal path does
        not apply (A unstable or nearly defective)."""
        A = np.ascontiguousarray(A, dtype=float)
        C = np.ascontiguousarray(C, dtype=float)
        n, nu, ny = A.shape[0], self.n_inputs, self.n_outputs
        form = ModalForm.of(A, C)
        if form is None:
            return None
        parts = self._map(modal_piece, [(form, nu, ny)] * self.n_pieces)
        blocks = combine_modal(form, parts, nu, ny, estimate_x0=True, feedthrough=True,
                               experiments=self.experiments)[0]
        theta = np.concatenate([np.asarray(B, float).T.ravel(), np.asarray(D, float).T.ravel()])
        try:   # the x0 of different experiments do not couple: one block each
            x0 = np.concatenate([scipy.linalg.solve(
                N[:n, :n], N[:n, -1] - N[:n, n:-1] @ theta, assume_a="pos",
                check_finite=False) for N in blocks]) if n else np.zeros(0)
        except (np.linalg.LinAlgError, ValueError, IndexError):
            return None
        return self._shape_x0(x0, n)

    def _qr(self, A, C, *, feedthrough, estimate_x0):
        n, nu, ny = A.shape[0], self.n_inputs, self.n_outputs
        nx, q, _ = parameter_count(n, nu, ny, estimate_x0, feedthrough)   # per experiment
        parts = self._map(sensitivity_piece, [(A, C, q, nx)] * self.n_pieces)
        weights = _spread_of(parts, ny).weights()
        starts = []
        current = -1
        with np.errstate(over="ignore", invalid="ignore"):
            for part, e in zip(parts, self.experiments):
                if e != current:      # an experiment starts: its own x0, B at rest
                    S = np.zeros((n, q))
                    if estimate_x0:
                        S[:, :n] = np.eye(n)
                    current = e
                starts.append(S)
                S = np.linalg.matrix_power(A, part["length"]) @ S + part["S_end"]
        factors = self._map(qr_piece, [(A, C, s, nx, feedthrough, weights) for s in starts])
        # each experiment's pieces stacked and factorised again (layout [x0_e; B; D; y]),
        # in one scan over the pieces (linear in the experiments)
        grouped = [[] for _ in range(self.n_experiments)]
        for R, e in zip(factors, self.experiments):
            if R is not None:
                grouped[e].append(R)
        per_experiment = [_refactor(group) for group in grouped]
        n_samples = sum(part["length"] for part in parts)
        if self.n_experiments == 1:
            B, D, x0, _, diagnostics = solve_factor(per_experiment[0], n, nu, ny,
                                                    estimate_x0=estimate_x0,
                                                    feedthrough=feedthrough,
                                                    n_samples=n_samples, n_x0=n)
        else:       # the x0 of each experiment eliminated (linear in the experiments)
            B, D, x0, diagnostics = solve_factor_blocks(per_experiment, n, nu, ny,
                                                        estimate_x0=estimate_x0,
                                                        feedthrough=feedthrough,
                                                        n_samples=n_samples)
        diagnostics["regression_passes"] = 2
        return B, D, x0, diagnostics


def _refactor(factors):
    """Triangular factor of the stacked factors of consecutive pieces (NaN on overflow)."""
    with np.errstate(over="ignore", invalid="ignore"):
        stacked = np.vstack(factors)
        if np.isfinite(stacked).all():
            return scipy.linalg.qr(stacked, mode="r", check_finite=False)[0][:stacked.shape[1]]
        return np.full((stacked.shape[1], stacked.shape[1]), np.nan)


def threaded(groups):
    """``map_pieces`` of a record in contiguous groups of samples: ``groups[k]()``
    returns a fresh iterable of the consecutive ``(u, y)`` arrays of group k
    (each group is one piece). The groups are reduced on subid's threads
    (:func:`subid._threads.ordered_map`; the kernels release the GIL)."""

    def map_pieces(function, arguments):
        return ordered_map(lambda k: function(groups[k](), *arguments[k]), range(len(groups)))
    return map_pieces


def sequential(make_chunks):
    """``map_pieces`` of one record read sequentially: ``make_chunks()`` returns a
    fresh iterable of consecutive ``(u, y)`` arrays (the whole record is one piece)."""

    def map_pieces(function, arguments):
        return [function(make_chunks(), *arguments[0])]
    return map_pieces
