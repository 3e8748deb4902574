"""Predictor-based subspace identification (PBSID-opt), consistent in closed loop.

Chiuso, "The role of vector autoregressive modeling in predictor-based
subspace identification", Automatica 43(6), 2007 (the PBSID-opt algorithm,
Sec. 5); the SSARX of Jansson (2003) and MATLAB's ``n4sid`` with
``N4Weight='SSARX'`` are of the same family. The innovation form
``x(t+1) = A x + B u + K e``, ``y = C x + D u + e`` has the predictor form
(``Ā = A - K C``, ``B̄ = [B - K D, K]``, ``z = [u; y]``)

    x(t+1) = Ā x(t) + B̄ z(t),   y(t) = C x(t) + D u(t) + e(t),

so with the past window ``z_p(t) = [z(t-p); ...; z(t-1)]`` the state is
``x(t) = K_p z_p(t) + Ā^p x(t-p)``, ``K_p = [Ā^(p-1) B̄, ..., B̄]``, and the
last term vanishes as ``p`` grows (exactly, for noise-free data, once p
reaches the observability index: a dead-beat predictor exists). Steps, on
the triangular factor of the block-Hankel data matrix (``p = f =
horizon``; all products of data rows are products of the factor's rows):

1. For every future step ``k = 0..f-1``, regress ``y(t+k)`` on
   ``[z_p(t); z(t); ...; z(t+k-1); u(t+k)]`` (``u(t+k)`` only with
   feedthrough): ``y(t+k) = C Ā^k x(t) + sum_l C Ā^(k-1-l) B̄ z(t+l) + D
   u(t+k) + e(t+k)`` (Chiuso 2007, eq. 21), whose regressors are all in the
   past of ``e(t+k)``: no correlation between input and noise enters, so
   the estimate stays consistent under feedback. The coefficient on
   ``z_p`` estimates row block ``k`` of ``Γ_f K_p``.
2. SVD of ``Γ_f K_p Z_p``: the order from its singular values and the state
   sequence ``X = U_n^T (Γ_f K_p) Z_p``, and one sample later ``X^+`` from
   the window shifted by one sample (as :func:`subid.n4sid` does).
3. ``[C D]`` by least squares from ``y(t) = C x(t) + D u(t) + e(t)``, the
   innovations ``ê = y - C x - D u``, then ``[A B K]`` from ``x(t+1) = A
   x(t) + B u(t) + K ê(t)`` (with ``ê`` as a regressor, which keeps the
   regression consistent in closed loop, where ``u(t)`` depends on
   ``e(t)``).

With ``stability`` asking for it, an unstable A is stabilised
(:func:`subid.methods.dt._subspace.stable_choice`) and B, K refitted from
the same state equation. Order and horizon selection, the noise model and
the delays come from the shared pipeline (:mod:`subid.methods.dt.pipeline`).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import check_bool, checked_call
from subid.data import IOData
from subid.methods.bd import INFO_KEY
from subid.methods.dt._subspace import (
    check_experiment_lengths,
    initial_state,
    simulation_residual,
    stable_choice,
)
from subid.methods.dt.feedthrough import check_feedthrough
from subid.methods.dt.n4sid import _lstsq_rows
from subid.methods.dt.pipeline import States, Subspace, SubspaceMethod, run
from subid.model.statespace import StateSpace

__all__ = ["pbsid", "step_coefficients", "step_coefficients_reference"]


@serial_blas
@checked_call
def pbsid(data, order=None, *, horizon=None, selection="cv", stability="auto",
          feedthrough="auto", estimate_x0=True, statistic="auto", refine=None,
          input_delay=0) -> StateSpace:
    """Identify a discrete-time model by predictor-based subspace identification.

    PBSID-opt (Chiuso 2007; module docstring): consistent with data measured
    in closed loop (the input depends on past outputs), where
    :func:`subid.moesp`, :func:`subid.n4sid` and :func:`subid.ls_subspace`
    are biased.

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
        Past window ``p`` and future window ``f`` (``p = f``). Default: chosen
        with the order among 10 and 20 (as far as the record allows) by
        ``selection``; with ``selection='gap'``, 10 (or what the record
        allows). The bias ``Ā^p`` falls with ``p``.
    selection : {'cv', 'gap'}
        As in :func:`subid.moesp`.
    stability : {'auto', 'enforce', 'none'}
        As in :func:`subid.moesp`; B and K are then refitted from the state
        equation.
    feedthrough : {'auto', True, False}
        Estimate D (``False``: D = 0). ``'auto'`` (default), as in
        :func:`subid.n4sid`: D only when the data show a direct term and no
        feedback (:mod:`subid.methods.dt.feedthrough`; ``info['feedthrough']``).
        In closed loop with a direct feedback ``u(t) = r(t) - F y(t)`` the plant
        must be strictly proper (D = 0) for any method to be consistent, which
        the feedback test detects.
    estimate_x0 : bool
        Estimate the initial state (``info['x0']``) by least squares on the
        output, given the identified model.
    statistic : {'auto', 'qr', 'gram'}
        As in :func:`subid.ls_subspace`.
    refine : {None, 'pem'}
        As in :func:`subid.ls_subspace`.
    input_delay : int or sequence of int
        As in :func:`subid.ls_subspace`.

    Returns
    -------
    StateSpace
        Discrete-time model with ``dt = data.dt``; ``info['singular_values']``
        of ``Γ_f K_p Z_p``, ``info['state_regression_residual']``.

    Examples
    --------
    >>> import subid
    >>> data = subid.systems.simulate_data(subid.systems.seed001_system(), 600, seed=3)
    >>> model = subid.pbsid(data, 3)
    >>> float(subid.markov_error(model, subid.systems.seed001_system())) < 1e-8
    True
    """
    method = PBSID(stability=stability, feedthrough=feedthrough, estimate_x0=estimate_x0)
    return run(method, data, order, horizon, selection=selection, statistic=statistic,
               refine=refine, input_delay=input_delay)


#: The nested regressions of :func:`step_coefficients` are solved on one factor when its
#: smallest diagonal entry is above this fraction of the largest; below, each step by
#: its own rank-revealing least squares (:func:`step_coefficients_reference`).
NESTED_CONDITION = 1e-8


def step_coefficients_reference(hf, i: int, feedthrough: bool) -> np.ndarray:
    """Step 1 one regression at a time: the coefficients on ``z_p`` of ``y(t+k)`` on
    ``[z_p(t); u(t..t+k-1); y(t..t+k-1)]`` (and ``u(t+k)`` with ``feedthrough``),
    ``k = 0..i-1``, stacked (``Γ_f K_p`` in the coordinates of the factor ``hf``),
    each by its own minimum-norm least squares (Chiuso 2007, eq. 21).

    Parameters
    ----------
    hf : HankelFactor
        The triangular factor of the block-Hankel data (depth ``2 i``).
    i : int
        The horizon (past and future windows).
    feedthrough : bool
        Whether ``u(t+k)`` is a regressor of ``y(t+k)`` (D estimated).

    Returns
    -------
    ndarray, shape (i ny, i (nu + ny))
        ``Γ_f K_p`` in the coordinates of ``hf``, row block ``k`` from step ``k``.
    """
    wp = hf.rows(hf.u_rows(0, i), hf.y_rows(0, i))
    rows = []
    for k in range(i):
        parts = [wp]
        if k:
            parts += [hf.rows(hf.u_rows(i, i + k)), hf.rows(hf.y_rows(i, i + k))]
        if feedthrough:
            parts.append(hf.rows(hf.u_rows(i + k, i + k + 1)))
        theta = _lstsq_rows(np.vstack(parts), hf.rows(hf.y_rows(i + k, i + k + 1)))
        rows.append(theta[:, :wp.shape[0]])
    return np.vstack(rows)


def step_coefficients(hf, i: int, feedthrough: bool) -> np.ndarray:
    """:func:`step_coefficients_reference` from one factorisation.

    The regressors of step ``k`` are those of step ``k-1`` and ``z(t+k-1) =
    [u(t+k-1); y(t+k-1)]``: with the factor's rows ordered ``[z_p; u(t); y(t);
    u(t+1); y(t+1); ...]``, those of step ``k`` are its first ``r_k`` rows
    (``r_k = i (nu + ny) + k (nu + ny)``, plus ``nu`` with ``feedthrough``) and
    its target, ``y(t+k)``, the ``ny`` rows from ``r_k + nu`` (``r_k`` with
    feedthrough). One LQ factorisation of the reordered rows, ``P L = L' Q'^T``
    (:meth:`subid.statistic.HankelFactor.retriangularize`), makes every step the
    triangular system ``θ L'[:r_k, :r_k] = L'[target, :r_k]`` (Ljung 1999, Ch. 10:
    one QR for every nested least-squares problem). The orderings of the
    regressors within a step differ, which leaves the coefficients on ``z_p``
    unchanged. When the factor is ill-conditioned (a diagonal entry below
    :data:`NESTED_CONDITION` of the largest: regressors that nearly repeat each
    other, where the minimum-norm solution is wanted), the reference computes them.
    Arguments and result as :func:`step_coefficients_reference`'s (to rounding).
    """
    nu, ny = hf.n_inputs, hf.n_outputs
    order = [hf.u_rows(0, i), hf.y_rows(0, i)]
    for k in range(i):
        order += [hf.u_rows(i + k, i + k + 1), hf.y_rows(i + k, i + k + 1)]
    Lr = hf.retriangularize(*order)
    n_wp, block = i * (nu + ny), nu + ny
    size = n_wp + (i - 1) * block + (nu if feedthrough else 0)
    diag = np.abs(np.diag(Lr)[:size])
    if diag.size == 0 or diag.min() <= NESTED_CONDITION * diag.max():
        return step_coefficients_reference(hf, i, feedthrough)
    rows = []
    for k in range(i):
        r = n_wp + k * block + (nu if feedthrough else 0)
        target = n_wp + k * block + nu
        theta = scipy.linalg.solve_triangular(Lr[:r, :r], Lr[target:target + ny, :r].T,
                                              trans="T", lower=True, check_finite=False).T
        rows.append(theta[:, :n_wp])
    return np.vstack(rows)


class PBSID(SubspaceMethod):
    """PBSID-opt's steps (:class:`subid.methods.dt.pipeline.SubspaceMethod`; module
    docstring): the regressions and SVD of steps 1 and 2, then step 3 with the
    stability rule (B, K refitted from the state equation)."""

    name = "pbsid"

    def __init__(self, *, stability="auto", feedthrough="auto", estimate_x0=True):
        feedthrough = check_feedthrough(feedthrough)
        check_bool(estimate_x0, "estimate_x0")
        self.common_options(feedthrough=feedthrough, estimate_x0=estimate_x0,
                            stability=stability)

    def decompose(self, pb, feedthrough) -> Subspace:
        """Steps 1 and 2's SVD: they do not depend on the order, so once per problem,
        shared by the candidate orders of a cross-validation fold (Problem.cached)."""
        i, hf = pb.horizon, pb.factor
        wp = hf.rows(hf.u_rows(0, i), hf.y_rows(0, i))

        def regressions():
            coef = step_coefficients(hf, i, feedthrough)   # Γ_f K_p (factor coordinates)
            U, s, _ = scipy.linalg.svd(coef @ wp, full_matrices=False, check_finite=False)
            return coef, U, s

        coef, U, s = pb.cached(("pbsid regressions", feedthrough), regressions)
        return Subspace(s, parts={"coef": coef, "U": U, "wp": wp})

    def system_matrices(self, pb, subspace, n, estimator, *, feedthrough, ft_record, plan):
        """Step 3 (module docstring), with the stability rule and x0."""
        i, hf, data = pb.horizon, pb.factor, pb.data
        ny, nu = hf.n_outputs, hf.n_inputs
        coef, U, wp, s = (subspace.parts["coef"], subspace.parts["U"], subspace.parts["wp"],
                          subspace.profile)
        wp_next = hf.rows(hf.u_rows(1, i + 1), hf.y_rows(1, i + 1))
        Q = U[:, :n]                              # orthonormal basis of range(Γ_f)
        M = Q.T @ coef                            # x(t) = M z_p(t)
        x, x_next = M @ wp, M @ wp_next
        u_t = hf.rows(hf.u_rows(i, i + 1))
        y_t = hf.rows(hf.y_rows(i, i + 1))
        # step 3: C, D from the output equation, then A, B, K with the innovations as
        # regressors
        if feedthrough:
            CD = _lstsq_rows(np.vstack([x, u_t]), y_t)
            C, D = CD[:, :n], CD[:, n:]
        else:
            C, D = _lstsq_rows(x, y_t), np.zeros((ny, nu))
        e = y_t - C @ x - D @ u_t
        ABK = _lstsq_rows(np.vstack([x, u_t, e]), x_next)
        A = ABK[:, :n]          # B (and K) again in fit(A), for the A finally kept
        resid = x_next - ABK @ np.vstack([x, u_t, e])
        residual = float(np.linalg.norm(resid) / max(float(np.linalg.norm(x_next)), 1e-300))

        # the stability rule compares the unstable A's simulation with the stabilised one's
        compare = plan.stability == "auto" and isinstance(data, IOData) and \
            np.abs(np.linalg.eigvals(A)).max() >= 1.0

        def fit(A_try):
            """B (and D, x0) for a given A from the state equation (K refitted with it),
            with the residual RMS of its simulation on the record where the stability
            rule compares an unstable A with its stabilised one (``'auto'``)."""
            BK = _lstsq_rows(np.vstack([u_t, e]), x_next - A_try @ x)
            B_n, C_n, D_n = pb.unscale(BK[:, :nu], C, D)
            diagnostics = {INFO_KEY: "states"}
            if compare:
                diagnostics["simulation_residual_rms"] = simulation_residual(
                    A_try, B_n, C_n, D_n, data, pb.weights())
            return B_n, D_n, None, diagnostics

        A, fitted, stab = stable_choice(A, Q, ny, fit, stability=plan.stability, data=data,
                                        method=pb.method)
        B, D = fitted[0], fitted[1]
        _, C, _ = pb.unscale(np.zeros((n, nu)), C, np.zeros((ny, nu)))
        if plan.estimate_x0 and pb.fold and isinstance(data, IOData) \
                and data.n_experiments > 1:
            check_experiment_lengths(data, n)     # what initial_state would raise
        # a fold model is scored with an x0 fitted on the held-out data (Problem.fold)
        x0 = initial_state(A, B, C, D, data) if plan.estimate_x0 and not pb.fold else None
        return States(A, B, C, D, dict(singular_values=s, x0=x0,
                                       state_regression_residual=residual, stability=stab,
                                       feedthrough=ft_record))
