"""PO-MOESP: past-output multivariable output-error state-space identification.

Verhaegen (1994), "Identification of the deterministic part of MIMO state
space models given in innovations form from input-output data", Automatica
30(1); Verhaegen & Verdult, *Filtering and System Identification* (2007),
Sec. 9.6. The classical SVD-based baseline against which seed 001 compares.

With the LQ factorisation ``[U_f; W_p; Y_f] = L Q^T`` (W_p = past inputs and
outputs), ``Y_f Π⊥_{U_f} = L32 Q2^T + L33 Q3^T`` and the oblique projection
``O = Y_f /_{U_f} W_p = L32 L22^{-1} W_p``. The column space of the
weighted matrix ``W1 O W2`` is the column space of the extended
observability matrix (asymptotically, under process and measurement
noise), for the weightings of MATLAB's ``N4Weight`` (Van Overschee & De
Moor 1996, Sec. 4.3.4, Theorem 12):

* ``'moesp'``: ``W1 = I, W2 = Π⊥_{U_f}``: the SVD of ``L32``;
* ``'cva'``: ``W1 = (Y_f Π⊥ Y_f^T)^{-1/2}, W2 = Π⊥_{U_f}`` (canonical
  variate analysis, Larimore 1990): the SVD of ``R^{-T} L32``;
* ``'n4sid'``: ``W1 = W2 = I``: the SVD of ``L32 L22^† [L21 L22]``.

Γ = W1^{-1} U_n S_n^{1/2}; A and C follow by shift invariance (made stable
when asked, :func:`subid.methods.dt._subspace.stable_shift_invariance`) and B, D, x0
by least squares on the output.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import check_bool, check_choice, checked_call
from subid.methods.bd import BATCH_OPTIONS
from subid.methods.dt._subspace import (
    check_system_matrices,
    check_weighting,
    cva_factor,
    future_past_factor,
    orthonormal_basis,
    shift_invariance,
)
from subid.methods.dt.feedthrough import check_feedthrough
from subid.methods.dt.n4sid import state_model
from subid.methods.dt.pipeline import Shift, States, Subspace, SubspaceMethod, run
from subid.model.statespace import StateSpace

__all__ = ["moesp"]


@serial_blas
@checked_call
def moesp(data, order=None, *, horizon=None, weighting="moesp", selection="cv",
          stability="auto", system_matrices="auto", feedthrough="auto", estimate_x0=True,
          bd_method="auto", statistic="auto", refine=None, input_delay=0) -> StateSpace:
    """Identify a discrete-time model by PO-MOESP.

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
        Past and future horizon (block rows). Default: chosen with the order
        among 10 and 20 (as far as the record allows) by ``selection``; with
        ``selection='gap'``, 10 (or what the record allows).
    weighting : {'moesp', 'cva', 'n4sid'}
        Weighting of the projection before the SVD (MATLAB's ``N4Weight``).
    selection : {'cv', 'gap'}
        How an order or horizon not given is chosen: ``'cv'`` by
        cross-validated simulation fit on the estimation data
        (:mod:`subid.methods.dt.selection`); ``'gap'`` at the largest gap of the
        singular values. ``info['order_selection']`` holds every candidate
        with its score.
    stability : {'auto', 'enforce', 'none'}
        ``'auto'``: an unstable A is made stable when the data do not grow
        (:func:`subid.methods.dt._stability.stability_request`); ``'enforce'``: always;
        ``'none'``: never. ``info['stability']`` says what was done.
    system_matrices : {'auto', 'shift', 'states'}
        How A, B, C, D follow from the estimated Γ. ``'shift'``: A and C by
        shift invariance, B, D, x0 by least squares on the output (the
        classical MOESP; for an unstable A, B, D, x0 by the prediction-error
        form, :func:`subid.methods.dt._subspace.b_d_refit`). ``'states'``: the
        state sequence ``X = Γ^† O`` and ``[A B; C D]`` by least squares on
        it, as :func:`subid.n4sid` does (VODM 1996, Sec. 4.3.2).
        ``'auto'`` (default): with ``selection='cv'`` on a record of up to
        20,000 samples, both at the order and horizon used (given, or
        cross-validated with ``'shift'``), and the model with the better
        simulation fit to the whole record (x0 by least squares; one that
        needed no stabilisation first; ``'shift'`` on ties, so noise-free data
        give the classical model), with no fold fits
        (:func:`subid.methods.dt.selection.estimator_by_fit`); a list of
        candidate orders (``order=[n]``) cross-validates the estimators with
        the orders instead; otherwise (longer records, statistics) ``'shift'``.
        ``info['system_matrices']`` names the one used and
        ``info['system_matrices_selection']`` why (with both fits);
        ``moesp(data, order=m.order, horizon=m.info['horizon'])`` reproduces a
        default model ``m``, and with
        ``system_matrices=m.info['system_matrices']`` at the cost of one fit. Neither is better on
        every record: on the DaISy evaporator record ``'states'`` reaches
        64 % validation fit against 61 %; on exchanger ``'shift'`` 65 %
        against 58 % (bench/realdata.md).
    feedthrough : {'auto', True, False}
        Estimate D (``False``: D = 0). ``'auto'`` (default): D only when the
        data show a direct term and no feedback
        (:mod:`subid.methods.dt.feedthrough`; ``info['feedthrough']``).
    estimate_x0 : bool
        Estimate the initial state with B and D (``info['x0']``).
    bd_method : {'auto', 'simulation', 'projection'}
        As in :func:`subid.ls_subspace`.
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
    method = Moesp(weighting=weighting, stability=stability, system_matrices=system_matrices,
                   feedthrough=feedthrough, estimate_x0=estimate_x0, bd_method=bd_method)
    return run(method, data, order, horizon, selection=selection, statistic=statistic,
               refine=refine, input_delay=input_delay)


class Moesp(SubspaceMethod):
    """PO-MOESP's steps (:class:`subid.methods.dt.pipeline.SubspaceMethod`): the SVD of the
    weighted projection, then Γ and the system matrices by shift invariance or from the
    state sequence."""

    name = "moesp"

    def __init__(self, *, weighting="moesp", stability="auto", system_matrices="auto",
                 feedthrough="auto", estimate_x0=True, bd_method="auto"):
        self.weighting = check_weighting(weighting)
        feedthrough = check_feedthrough(feedthrough)
        check_bool(estimate_x0, "estimate_x0")
        check_choice(bd_method, "bd_method", BATCH_OPTIONS)
        check_system_matrices(system_matrices)
        self.common_options(feedthrough=feedthrough, estimate_x0=estimate_x0,
                            stability=stability, bd_method=bd_method)
        self.estimators = ("shift", "states") if system_matrices == "auto" \
            else (system_matrices,)

    def decompose(self, pb, feedthrough) -> Subspace:
        """The SVD of the weighted projection (once per problem: shared by every order)."""
        f, nu, ny = pb.horizon, pb.data.n_inputs, pb.data.n_outputs
        a, b = f * nu, f * (nu + ny)
        L = future_past_factor(pb)

        def svd():
            M, W1_inv = weighted_projection(L, a, b, self.weighting)
            U, s, _ = scipy.linalg.svd(M, full_matrices=False, check_finite=False)
            return W1_inv, U, s

        W1_inv, U, s = pb.cached(("moesp svd", self.weighting), svd)
        return Subspace(s, parts={"W1_inv": W1_inv, "U": U, "L": L, "a": a, "b": b})

    def system_matrices(self, pb, subspace, n, estimator, *, feedthrough, ft_record, plan):
        """Γ = W1^{-1} U_n S_n^{1/2}; A and C by shift invariance in an orthonormal basis
        of range(Γ) (``'shift'``), or A, B, C, D from the state sequence (``'states'``)."""
        parts, s = subspace.parts, subspace.profile
        gamma = parts["U"][:, :n] * np.sqrt(s[:n])
        if parts["W1_inv"] is not None:
            gamma = parts["W1_inv"] @ gamma
        if estimator == "states":
            A, B, C, D, _, extra = state_model(pb, gamma, stability=plan.stability,
                                                feedthrough=feedthrough,
                                                estimate_x0=plan.estimate_x0)
            return States(A, B, C, D, dict(singular_values=s, weighting=self.weighting,
                                           feedthrough=ft_record, **extra))
        # A and C in an orthonormal basis Q of range(Γ) (any basis is valid for MOESP)
        Q = orthonormal_basis(gamma)
        A, C, shift_residual = shift_invariance(Q, pb.data.n_outputs, residual=not pb.fold)
        L, a, b = parts["L"], parts["a"], parts["b"]
        return Shift(A, C, Q, L[:a, :a], L[a + b:, :a],
                     info=dict(singular_values=s, weighting=self.weighting,
                               shift_residual=shift_residual))


def weighted_projection(L: np.ndarray, a: int, b: int, weighting: str):
    """The matrix whose left singular vectors span range(W1 Γ), and W1^{-1}.

    ``L`` is the factor of ``[U_f; W_p; Y_f]`` with ``a`` rows of U_f and
    ``b`` rows of W_p. Returns ``(M, W1_inv)`` (``W1_inv`` None for W1 = I).
    """
    L32 = L[a + b:, a:a + b]
    if weighting == "moesp":
        return L32, None
    if weighting == "cva":
        R = cva_factor(L[a + b:, a:])                     # R^T R = L32 L32^T + L33 L33^T
        return scipy.linalg.solve_triangular(R.T, L32, lower=True, check_finite=False), R.T
    # 'n4sid': O = L32 L22^† [L21 L22] (coefficients of the oblique projection)
    coef = scipy.linalg.lstsq(L[a:a + b, a:a + b].T, L32.T, lapack_driver="gelsy",
                              check_finite=False)[0].T
    return coef @ L[a:a + b, :a + b], None
