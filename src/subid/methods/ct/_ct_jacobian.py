"""Analytic Jacobian of the output-error refinement of :func:`subid.ct_subspace`.

The refinement (:func:`subid.methods.ct._ct_fit.refine_output_error`) minimises
``||r||^2``, ``r = P_perp(A, C) W y``, where ``R(A, C)`` regresses the raw output
samples on ``B, x0, y0, D`` (:func:`subid.methods.ct._ct_fit.regressors`), ``W`` is the
prewhitening filter (identity without one) and ``P_perp`` the projector on the orthogonal
complement of ``W R`` (variable projection). Along a direction ``(dA, dC)`` its derivative is
(Golub and Pereyra 1973, eq. (4.4); the full derivative, not Kaufman's approximation)

    dr = -P_perp W dR theta_hat - (W R)^{+T} dR^T W^T r,                              (J)

with ``theta_hat`` the least-squares linear parameters. Both terms come from the exactly
discretised system on a uniform grid, ``x_{k+1} = Phi x_k + sum_q W_q B u[s_k + q]``
(:mod:`subid.methods.ct._ct_kernels`), whose tables are blocks of one matrix exponential
(Van Loan 1978); their derivatives ``dPhi, dW_q`` along ``dA`` are the same blocks of the
Frechet derivative of that exponential (``scipy.linalg.expm_frechet``; Al-Mohy and Higham
2009; all directions at once, :func:`subid.methods.ct._ct_frechet.frechet_many`).

* ``dR theta_hat`` is the derivative of the model output at fixed linear parameters:
  ``dy_k = dC x_k + C dx_k``, ``dx_{k+1} = Phi dx_k + dPhi x_k + sum_q dW_q B u[s_k + q]``
  (forward sensitivities, one ``n``-state recursion per direction).
* ``dR^T rho`` (``rho = W^T r``) needs, for every regressor column, the sum over the samples
  of ``rho_k`` against the column's derivative. With the state responses ``Z_{j,k}`` to
  input ``j`` and ``P_k = Phi^k`` (the columns are ``C Z_{j,k} e_a`` and ``C P_k e_a``) and
  the adjoint ``mu_i = Phi^T mu_{i+1} + C^T rho_{i+1}`` (``mu_{L-1} = 0``) it is
  ``sum_k rho_k^T dC S_k e_a + sum_i mu_i^T (dPhi S_i e_a + sum_q dW_q e_a u_j[s_i + q])``
  for ``S = Z_j`` or ``P`` (no input term for ``P``): sums over the record formed once, then
  contracted with every direction.

One Jacobian costs one sensitivity run, ``n p`` Frechet derivatives of a small matrix
exponential and ``n p + 1`` ``n``-state recursions, instead of ``n p`` residual evaluations
(each a sensitivity run of ``n (n m + 1)`` trajectories and a least-squares solve) for
finite differences. Uniform grids only; the refinement keeps finite differences elsewhere.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.linalg

from subid.methods.ct import _ct_kernels
from subid.methods.ct._ct_frechet import frechet_many

__all__ = ["VarProProblem"]

#: Regressor columns below this fraction of the largest column's norm are dropped.
DEAD_COLUMN = 1e-8


@numba.njit(cache=True)
def shift_loop(Phi, F, out):  # pragma: no cover - compiled
    """Compiled ``out[0] = 0``, ``out[k+1] = Phi out[k] + F[k]`` (``out`` (K+1, n, D))."""
    K, n, D = F.shape
    for i in range(n):
        for d in range(D):
            out[0, i, d] = 0.0
    for k in range(K):
        for i in range(n):
            for d in range(D):
                acc = F[k, i, d]
                for l in range(n):
                    acc += Phi[i, l] * out[k, l, d]
                out[k + 1, i, d] = acc
    return out


def shift_loop_ref(Phi, F, out):
    """Plain numpy reference of :func:`shift_loop`."""
    out[0] = 0.0
    for k in range(F.shape[0]):
        out[k + 1] = Phi @ out[k] + F[k]
    return out


def table_derivatives(A, dAs, t, order):
    """``Phi``, ``W`` (U, P, n, n), their derivatives ``dPhi`` (D, n, n) and ``dW``
    (D, U, P, n, n) along the directions ``dAs`` (D, n, n), the offset index ``tab`` and
    the stencil starts of a uniform grid (input matrix ``I``)."""
    n = A.shape[0]
    h, nodes, tab, starts, coef = _ct_kernels.uniform_stencil(t, order)
    U = nodes.shape[0]
    M = _ct_kernels.van_loan_matrix(A, np.eye(n), np.full(U, h), nodes.shape[1])
    Phi, W = _ct_kernels.tables_from_exponential(scipy.linalg.expm(M), n, n, nodes, coef)
    dPhi = np.empty((len(dAs), n, n))
    dW = np.empty((len(dAs),) + W.shape)
    dMs = []
    for dA in dAs:
        dM = np.zeros(M.shape[1:])
        dM[:n, :n] = dA * h
        dMs.append(dM)
    # every direction's derivative at each M[u]: the parts of M[u] alone computed once
    dE = [frechet_many(M[u], dMs)[1] for u in range(U)]
    for d in range(len(dAs)):
        dP, dW[d] = _ct_kernels.tables_from_exponential(
            np.stack([dE[u][d] for u in range(U)]), n, n, nodes, coef)
        dPhi[d] = dP[0]
    return Phi[0], W, dPhi, dW, tab, starts


class VarProProblem:
    """Residual and analytic Jacobian (J) of the refinement's criterion on a uniform grid.

    ``regressors`` and ``unpack`` are those of :mod:`subid.methods.ct._ct_fit` (passed in:
    that module imports this one). ``evaluate(A, C)`` returns the (whitened) residual of the least-squares fit of the
    linear parameters, or None when ``A`` overflows, and keeps what :meth:`jacobian` needs
    at that point.
    """

    def __init__(self, rec, regressors, unpack, *, feedthrough, estimate_x0, offset,
                 whiten=None, whiten_transpose=None):
        self.rec = rec
        self.regressors, self.unpack = regressors, unpack
        self.kw = dict(feedthrough=feedthrough, estimate_x0=estimate_x0, offset=offset)
        self.whiten = whiten
        self.whiten_transpose = whiten_transpose
        y = rec.y.reshape(-1)
        self.target = y if whiten is None else whiten(y[:, None])[:, 0]
        self.point = None

    def evaluate(self, A, C):
        R = self.regressors(A, C, self.rec, **self.kw)
        self.point = None
        if R is None:
            return None
        Rw = R if self.whiten is None else self.whiten(R)
        scale = np.linalg.norm(Rw, axis=0)
        # a column at rounding level (the column of a state the model cannot see) gets
        # a linear parameter of 1e14 that cancels others: (J) would lose every digit;
        # it is dropped (its parameter 0, its derivative outside the fixed-rank projector)
        dead = scale <= DEAD_COLUMN * scale.max()
        if dead.any():
            Rw = Rw.copy()
            Rw[:, dead] = 0.0
        scale[dead] = 1.0
        try:
            Uu, sv, Vt = np.linalg.svd(Rw / scale, full_matrices=False)
        except np.linalg.LinAlgError:
            return None
        keep = sv > sv[0] * np.finfo(float).eps * max(Rw.shape) if sv.size else sv > 0
        Uk, sk, Vk = Uu[:, keep], sv[keep], Vt[keep]
        proj = Uk.T @ self.target
        theta = (Vk.T @ (proj / sk)) / scale
        resid = self.target - Uk @ proj
        self.point = (A, C, theta, Uk, sk, Vk, scale, resid)
        return resid

    def jacobian(self, A, C, dAs, dCs):
        """Derivatives (J) of the residual at ``(A, C)`` along ``(dAs[d], dCs[d])``:
        shape (residuals, D)."""
        if self.point is None or self.point[0] is not A or self.point[1] is not C:
            if self.evaluate(A, C) is None:
                return np.zeros((self.target.size, len(dAs)))
        _, _, theta, Uk, sk, Vk, scale, resid = self.point
        rec, order = self.rec, self.rec.input_order
        n, p, m, E = A.shape[0], C.shape[0], rec.n_inputs, rec.n_experiments
        D = len(dAs)
        dCs = np.asarray(dCs)
        B, _, x0, _ = self.unpack(theta, n, m, p, E, **self.kw)
        x0 = None if x0 is None else np.reshape(x0, (E, n))
        rho = resid if self.whiten_transpose is None else self.whiten_transpose(resid)
        rho = rho.reshape(-1, p)
        G = np.empty((rho.shape[0], p, D))
        H = np.zeros((theta.size, D))
        row = 0
        for e, (t, u, _, _) in enumerate(rec.parts):
            L = t.size
            Phi, W, dPhi, dW, tab, starts = table_derivatives(A, dAs, t, order)
            P = W.shape[1]
            with np.errstate(over="ignore", invalid="ignore"):
                Zb, Px = _ct_kernels.run_sensitivity(A, np.eye(n), t, u, order, uniform=True)
            S = np.concatenate([Zb, Px[..., None]], axis=3)          # (L, n, n, m + 1)
            x = np.einsum("klaj,aj->kl", Zb, B, optimize=True)
            if x0 is not None:
                x += Px @ x0[e]
            stencil = u[starts[:, None] + np.arange(P)[None, :]]      # (L-1, P, m)
            Bu = np.einsum("aj,kqj->kqa", B, stencil, optimize=True)
            F = np.einsum("dnc,kc->knd", dPhi, x[:-1], optimize=True)
            mu_f = np.empty((L, n, 1))
            rho_e = rho[row:row + L]
            _shift(Phi.T, (rho_e[:0:-1] @ C)[:, :, None], mu_f)
            mu = mu_f[::-1, :, 0]                                     # mu[L-1] = 0
            hW = np.zeros((D, n, m))
            for v in range(W.shape[0]):
                sel = tab == v
                F[sel] += np.einsum("dqna,kqa->knd", dW[:, v], Bu[sel], optimize=True)
                V = np.einsum("kr,kqj->qrj", mu[:-1][sel], stencil[sel], optimize=True)
                hW += np.einsum("dqra,qrj->daj", dW[:, v], V, optimize=True)
            dX = _shift(Phi, F, np.empty((L, n, D)))
            G[row:row + L] = (np.einsum("dic,kc->kid", dCs, x, optimize=True)
                              + np.einsum("ic,kcd->kid", C, dX, optimize=True))
            T = np.einsum("ki,klaj->ilaj", rho_e, S, optimize=True)
            h = np.einsum("dil,ilaj->daj", dCs, T, optimize=True)
            h += np.einsum("drc,rcaj->daj", dPhi,
                           np.einsum("kr,kcaj->rcaj", mu[:-1], S[:-1], optimize=True))
            h[:, :, :m] += hW
            H[:n * m] += h[:, :, :m].reshape(D, n * m).T
            if x0 is not None:
                H[n * m + e * n:n * m + (e + 1) * n] = h[:, :, m].T
            row += L
        Wg = G.reshape(-1, D)
        if self.whiten is not None:
            Wg = self.whiten(Wg)
        return -(Wg - Uk @ (Uk.T @ Wg)) - Uk @ ((Vk @ (H / scale[:, None])) / sk[:, None])


def _shift(Phi, F, out):
    return shift_loop(np.ascontiguousarray(Phi), np.ascontiguousarray(F), out)
