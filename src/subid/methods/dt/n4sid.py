"""N4SID: numerical algorithm for subspace state-space system identification.

Van Overschee & De Moor (1994), "N4SID: Subspace algorithms for the
identification of combined deterministic-stochastic systems", Automatica
30(1); *Subspace Identification for Linear Systems* (1996), Sec. 4.3,
algorithm 2, with the weightings of Theorem 12 (unit, MOESP, CVA).

Steps, all on the triangular factor ``L`` of the block-Hankel data matrix
(``H = L Q^T``; a row block of ``H`` is a row block of ``L`` times ``Q^T``,
and projections of row spaces act on the small coefficient rows because
``Q^T`` has orthonormal rows):

1. Oblique projection ``O_i = Y_f /_{U_f} W_p = coef W_p``.
2. SVD of ``W1 O_i W2``: Γ_i = W1^{-1} U_n S_n^{1/2}.
3. States ``X_i = Γ_i^† O_i = K W_p`` and, shifted by one sample,
   ``X_{i+1} = K W_p^+`` (the past window one sample later).
4. ``[X_{i+1}; Y_{i|i}] = [A B; C D] [X_i; U_{i|i}]`` by least squares.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import check_bool, checked_call
from subid.data import IOData
from subid.methods.bd import INFO_KEY
from subid.methods.dt._subspace import (
    b_d_fit,
    check_experiment_lengths,
    check_weighting,
    cva_factor,
    future_past_factor,
    initial_state,
    least_squares_gelsy,
    stability_request,
    stable_choice,
)
from subid.methods.dt.feedthrough import check_feedthrough
from subid.methods.dt.pipeline import States, Subspace, SubspaceMethod, run
from subid.model.statespace import StateSpace

__all__ = ["n4sid"]


def _row_space_projector(M: np.ndarray) -> np.ndarray:
    """Orthogonal projector onto the row space of ``M`` (QR with pivoting).

    Rows are normalised first: that leaves the row space unchanged and makes
    the rank decision independent of how the channels are scaled.
    """
    norms = np.linalg.norm(M, axis=1)
    M = M[norms > 0] / norms[norms > 0, None]
    Q, R, _ = scipy.linalg.qr(M.T, mode="economic", pivoting=True, check_finite=False)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > d.max(initial=0.0) * 1e-12 * max(M.shape))) if d.size else 0
    Qr = Q[:, :rank]
    return Qr @ Qr.T


def _oblique_coefficients(a: np.ndarray, b: np.ndarray, c: np.ndarray,
                          perp: np.ndarray) -> np.ndarray:
    """K with ``A /_B C = K C`` for row spaces (``perp`` = projector onto B's complement).

    ``A /_B C = (A Π_B^⊥)(C Π_B^⊥)^† C``; ``a, b, c`` are the coefficient
    rows of A, B, C with respect to the common orthonormal rows ``Q^T``.
    """
    del b
    return least_squares_gelsy((c @ perp).T, (a @ perp).T).T


def _lstsq_rows(regressors: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Theta minimising ``||targets - Theta regressors||_F`` (rows = variables)."""
    return least_squares_gelsy(regressors.T, targets.T).T


@serial_blas
@checked_call
def n4sid(data, order=None, *, horizon=None, weighting="cva", selection="cv",
          stability="auto", feedthrough="auto", estimate_x0=True,
          statistic="auto", refine=None, input_delay=0) -> StateSpace:
    """Identify a discrete-time model by N4SID (state sequences).

    Parameters
    ----------
    data : IOData or HankelStatistic
        Uniformly sampled input/output record, or its statistic (depth
        ``2*horizon``; :class:`subid.HankelStatistic`).
    order : int, None, 'auto' or iterable of int
        Model order; ``None`` (or ``'auto'``) chooses it by ``selection``: among
        1..10 and on past 10 while the best is among the last orders tried
        (:mod:`subid.methods.dt.selection`); an iterable gives the candidate orders.
    horizon : int, optional
        Number of past and of future block rows i. Default: chosen with the
        order among 10 and 20 (as far as the record allows) by ``selection``;
        with ``selection='gap'``, 10 (or what the record allows).
    weighting : {'cva', 'moesp', 'n4sid'}
        Weighting ``W1 O_i W2`` of the oblique projection before the SVD
        (MATLAB's ``N4Weight``; Van Overschee & De Moor 1996, Theorem 12):
        ``'n4sid'`` unit weights (the classical N4SID), ``'moesp'``
        ``W2 = Π⊥_{U_f}``, ``'cva'`` (default; canonical variate analysis,
        the most reliable on the bundled real records, bench/realdata.md)
        also ``W1 = (Y_f Π⊥ Y_f^T)^{-1/2}``.
    selection : {'cv', 'gap'}
        As in :func:`subid.moesp`.
    stability : {'auto', 'enforce', 'none'}
        As in :func:`subid.moesp`. When it acts, A and C come from the
        stabilised shift invariance of Γ and B, D, x0 from the output
        regression (:func:`subid.methods.bd.fit_b_d_x0`).
    feedthrough : {'auto', True, False}
        Estimate D (``False``: D = 0 and the state regression omits it).
        ``'auto'`` (default): D only when the data show a direct term and no
        feedback (:mod:`subid.methods.dt.feedthrough`; ``info['feedthrough']``).
    estimate_x0 : bool
        Estimate the initial state (``info['x0']``) by least squares on the
        output, given the identified model.
    statistic : {'auto', 'qr', 'gram'}
        As in :func:`subid.ls_subspace`.
    refine : {None, 'simulation', 'prediction'}
        As in :func:`subid.ls_subspace`.
    input_delay : int or sequence of int
        As in :func:`subid.ls_subspace`.

    Returns
    -------
    StateSpace
        Discrete-time model with ``dt = data.dt``.
    """
    method = N4sid(weighting=weighting, stability=stability, feedthrough=feedthrough,
                   estimate_x0=estimate_x0)
    return run(method, data, order, horizon, selection=selection, statistic=statistic,
               refine=refine, input_delay=input_delay)


class N4sid(SubspaceMethod):
    """N4SID's steps (:class:`subid.methods.dt.pipeline.SubspaceMethod`): the SVD of the
    weighted oblique projection, then A, B, C, D from the state sequence."""

    name = "n4sid"

    def __init__(self, *, weighting="cva", stability="auto", feedthrough="auto",
                 estimate_x0=True):
        self.weighting = check_weighting(weighting)
        feedthrough = check_feedthrough(feedthrough)
        check_bool(estimate_x0, "estimate_x0")
        self.common_options(feedthrough=feedthrough, estimate_x0=estimate_x0,
                            stability=stability)

    def decompose(self, pb, feedthrough) -> Subspace:
        """Steps 1 and 2's SVD (module docstring), once per problem: shared by every
        candidate order."""
        i, hf = pb.horizon, pb.factor
        weighting = self.weighting
        wp = hf.rows(hf.u_rows(0, i), hf.y_rows(0, i))
        coef, perp = _projection(pb)

        def svd():
            o_i = coef @ wp
            W1_inv = None
            if weighting == "n4sid":
                M = o_i
            elif weighting == "moesp":
                M = o_i @ perp
            else:
                R = cva_factor(hf.rows(hf.y_rows(i, 2 * i)) @ perp)
                M = scipy.linalg.solve_triangular(R.T, o_i @ perp, lower=True,
                                                  check_finite=False)
                W1_inv = R.T
            U, s, _ = scipy.linalg.svd(M, full_matrices=False, check_finite=False)
            return W1_inv, U, s

        W1_inv, U, s = pb.cached(("n4sid svd", weighting), svd)
        return Subspace(s, parts={"W1_inv": W1_inv, "U": U, "coef": coef})

    def system_matrices(self, pb, subspace, n, estimator, *, feedthrough, ft_record, plan):
        """Γ = W1^{-1} U_n S_n^{1/2}, then steps 3 and 4 (:func:`state_model`)."""
        parts, s = subspace.parts, subspace.profile
        gamma = parts["U"][:, :n] * np.sqrt(s[:n])
        if parts["W1_inv"] is not None:
            gamma = parts["W1_inv"] @ gamma
        A, B, C, D, _, extra = state_model(pb, gamma, stability=plan.stability,
                                           feedthrough=feedthrough,
                                           estimate_x0=plan.estimate_x0,
                                           coefficients=parts["coef"])
        return States(A, B, C, D, dict(singular_values=s, weighting=self.weighting,
                                       feedthrough=ft_record, **extra))


def _projection(pb):
    """``(coef, perp)``: the oblique projection ``O_i = coef W_p`` and the projector
    on the complement of the future inputs' row space, once per problem."""
    def compute():
        i, hf = pb.horizon, pb.factor
        wp = hf.rows(hf.u_rows(0, i), hf.y_rows(0, i))
        uf = hf.rows(hf.u_rows(i, 2 * i))
        yf = hf.rows(hf.y_rows(i, 2 * i))
        perp = np.eye(hf.L.shape[1]) - _row_space_projector(uf)
        return _oblique_coefficients(yf, uf, wp, perp), perp
    return pb.cached("oblique projection", compute)


def state_model(pb, gamma, *, stability, feedthrough, estimate_x0, coefficients=None):
    """A, B, C, D (and x0) from the state sequence that Γ and the data determine.

    ``gamma`` is an estimate of the extended observability matrix (``horizon``
    block rows) in the units of the normalised channels of ``pb``, from any
    method (N4SID, MOESP, seed 001's least squares). The states are
    ``X_i = Γ^† O_i = K W_p`` with ``O_i = Y_f /_{U_f} W_p = coef W_p``
    (VODM 1996, Sec. 4.3, eq. 4.24 ff.), the next states ``X_{i+1} = K W_p^+``
    (the past window one sample later), and ``[X_{i+1}; Y_{i|i}] = [A B; C D]
    [X_i; U_{i|i}]`` by least squares (VODM 1996, Sec. 4.3.2, eq. 4.29). With
    ``stability`` asking for it, a stable A (:func:`subid.methods.dt._subspace.stable_choice`).

    Returns
    -------
    A, B, C, D, x0, info
        In the state basis of ``gamma`` (B, C, D in the user's units);
        ``info`` holds ``state_regression_residual``, ``x0``, ``stability``
        and the B, D regression's diagnostics when stability was enforced.
    """
    data, i, hf = pb.data, pb.horizon, pb.factor
    ny, nu = data.n_outputs, data.n_inputs
    n = gamma.shape[1]
    L = hf.L
    wp = hf.rows(hf.u_rows(0, i), hf.y_rows(0, i))
    wp_next = hf.rows(hf.u_rows(1, i + 1), hf.y_rows(1, i + 1))
    coef = _projection(pb)[0] if coefficients is None else coefficients   # O_i = coef W_p
    # States X_i = Γ^† O_i = K W_p with K = Γ^† coef: x(k) is a fixed linear function
    # of the past window w_p(k), so the next state is the same function of the window
    # one sample later, x(k+1) = K w_p(k+1): the state sequence shifted by one sample
    # (as SIPPY and nfoursid do). Van Overschee & De Moor's second projection
    # X_{i+1} = Γ_{i-1}^† O_{i-1} comes from another oblique projection whose finite-data
    # errors differ from those of X_i, and made A diverge on real records (issue 10).
    K = least_squares_gelsy(gamma, coef)
    x_i, x_ip1 = K @ wp, K @ wp_next
    u_ii = L[hf.u_rows(i, i + 1)]
    y_ii = L[hf.y_rows(i, i + 1)]
    xu = np.vstack([x_i, u_ii])
    AB = _lstsq_rows(xu, x_ip1)
    A, B = AB[:, :n], AB[:, n:]
    if feedthrough:
        CD = _lstsq_rows(xu, y_ii)
        C, D = CD[:, :n], CD[:, n:]
    else:
        C, D = _lstsq_rows(x_i, y_ii), np.zeros((ny, nu))
    lhs = np.vstack([x_ip1, y_ii])
    resid = lhs - np.vstack([A @ x_i + B @ u_ii, C @ x_i + D @ u_ii])
    residual = np.linalg.norm(resid) / max(np.linalg.norm(lhs), 1e-300)
    stab = {"requested": stability, "action": "none",
            "spectral_radius_before": float(np.abs(np.linalg.eigvals(A)).max())}
    extra, x0 = {}, None
    if stability_request(stability, A, data, pb.method):
        # A stable A from Γ by regularised shift invariance (in an orthonormal basis Q
        # of range(Γ), where the states above are R x for gamma = Q R), B, D, x0 by the
        # output regression; the classical model is kept when the estimation data demand
        # its instability (stable_choice)
        Q, Rg = scipy.linalg.qr(gamma, mode="economic", check_finite=False)
        A_unstable = scipy.linalg.solve(Rg.T, (Rg @ A).T, check_finite=False).T
        C_q = Q[:ny]
        Lr = future_past_factor(pb)
        a, b = i * nu, i * (nu + ny)

        fit = b_d_fit(pb, C_q, Q, Lr[:a, :a], Lr[a + b:, :a], bd_method="auto",
                      feedthrough=feedthrough, estimate_x0=estimate_x0)
        A_q, fitted, stab = stable_choice(A_unstable, Q, ny, fit, stability=stability,
                                          data=data, method=pb.method, bound_unstable=pb.fold)
        if stab["action"] == "enforced":
            # back from the basis Q to that of gamma (x = Rg^{-1} x_q)
            B_q, D, x0_q, extra = fitted
            A = scipy.linalg.solve(Rg, A_q @ Rg, check_finite=False)
            B = scipy.linalg.solve(Rg, B_q, check_finite=False)
            C = (C_q @ Rg) * pb.output_scale[:, None]
            # x0 has one row per experiment (a vector for one): x = Rg^{-1} x_q row by row
            x0 = None if x0_q is None else scipy.linalg.solve(
                Rg, np.asarray(x0_q).T, check_finite=False).T
            return A, B, C, D, x0, {"state_regression_residual": float(residual), "x0": x0,
                                    "stability": stab, **extra}
    B, C, D = pb.unscale(B, C, D)    # from the normalised channels to the user's units
    if estimate_x0 and pb.fold and isinstance(data, IOData) and data.n_experiments > 1:
        check_experiment_lengths(data, n)     # what initial_state would raise
    x0 = initial_state(A, B, C, D, data) if estimate_x0 and not pb.fold else None
    return A, B, C, D, x0, {"state_regression_residual": float(residual), "x0": x0,
                            "stability": stab, INFO_KEY: "states"}
