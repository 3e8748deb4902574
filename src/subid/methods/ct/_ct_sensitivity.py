"""Fused kernel of the output sensitivities of :func:`subid.ct_subspace` (seed 002).

The raw-sample regression of ``B`` and ``x0`` (:func:`subid.methods.ct._ct_fit.regressors`)
needs, at every sample ``a``, the output's dependence ``C Z_j(a)`` on ``B[:, j]``
and ``C P(a)`` on ``x0``, with

    Z_j(a+1) = Phi_a Z_j(a) + sum_q W_{a,q} u[s_a + q, j],   Z_j(0) = 0,
    P(a+1) = Phi_a P(a),                                     P(0) = I,

the exactly discretised interval of :mod:`subid.methods.ct._ct_kernels` (input
matrix ``I``). :func:`subid.methods.ct._ct_kernels.sens_loop` runs this recursion
matrix by matrix, each entry a strided dot product. Here the ``m + 1`` state
matrices sit side by side in one ``n x (n m + n)`` array ``X`` (column
``k m + j`` is column ``k`` of ``Z_j``, the last ``n`` columns are ``P``), so
that every product is a sweep along contiguous rows the compiler vectorises,
and the rows are written straight into the caller's regressor matrix. The input
terms are sweeps too (the drive matrices and the stencil samples spread over the
columns). Every entry is summed in the same order as in ``sens_loop`` (the ``Phi`` or
``C`` terms by increasing index, then the input terms by increasing ``q``), so the two
kernels agree to the last bit.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["sens_fused", "sens_fused_ref", "fused_state"]


def fused_state(n: int, m: int, free: bool) -> np.ndarray:
    """The initial ``X``: ``Z_j = 0`` (``n m`` columns), then ``P = I`` with ``free``."""
    X = np.zeros((n, n * m + (n if free else 0)))
    if free:
        X[:, n * m:] = np.eye(n)
    return X


@numba.njit(cache=True)
def sens_fused(Phi, W, tab, starts, u, C, X, out, col_b, col_x):  # pragma: no cover
    """Compiled sensitivities of ``y = C x``, written into ``out``.

    Parameters
    ----------
    Phi : ndarray, shape (K_tab, n, n)
        Transition matrices, indexed by ``tab``.
    W : ndarray, shape (K_tab, P, n, n)
        Drive matrices of the stencil samples (input matrix ``I``).
    tab : ndarray of int64, shape (K,)
        Table entry of every interval.
    starts : ndarray of int64, shape (K,)
        First stencil sample of every interval.
    u : ndarray, shape (L, m)
        Input samples.
    C : ndarray, shape (ny, n)
        Output matrix.
    X : ndarray, shape (n, n m) or (n, n m + n)
        State at the first sample (:func:`fused_state`); left at the last one.
    out : ndarray, shape (K + 1, ny, columns)
        Receives ``C Z_j`` at columns ``col_b + k m + j`` and ``C P`` at columns
        ``col_x .. col_x + n - 1`` (when ``X`` has them) for every sample.
    col_b, col_x : int
        First columns of the two blocks in ``out``.

    Returns
    -------
    ndarray
        ``out``.
    """
    K = tab.shape[0]
    n = X.shape[0]
    nc = X.shape[1]
    m = u.shape[1]
    nb = n * m
    ny = C.shape[0]
    P = W.shape[1]
    acc = np.empty(nc)
    nxt = np.empty((n, nc))
    # the drive matrices spread over the columns (Wx[e, q, i, k m + j] = W[e, q, i, k]) and
    # the stencil's input samples likewise (v[q, k m + j] = u[s + q, j]): the input terms
    # become sweeps along the columns too
    Wx = np.empty((W.shape[0], P, n, nb))
    for e in range(W.shape[0]):
        for q in range(P):
            for i in range(n):
                for k in range(n):
                    for j in range(m):
                        Wx[e, q, i, k * m + j] = W[e, q, i, k]
    v = np.empty((P, nb))
    for a in range(K + 1):
        for i in range(ny):
            for c in range(nc):
                acc[c] = 0.0
            for l in range(n):
                f = C[i, l]
                for c in range(nc):
                    acc[c] += f * X[l, c]
            for c in range(nb):
                out[a, i, col_b + c] = acc[c]
            for c in range(nb, nc):
                out[a, i, col_x + c - nb] = acc[c]
        if a == K:
            break
        e = tab[a]
        s = starts[a]
        for q in range(P):
            for k in range(n):
                for j in range(m):
                    v[q, k * m + j] = u[s + q, j]
        for i in range(n):
            for c in range(nc):
                acc[c] = 0.0
            for l in range(n):
                f = Phi[e, i, l]
                for c in range(nc):
                    acc[c] += f * X[l, c]
            for q in range(P):
                for c in range(nb):
                    acc[c] += Wx[e, q, i, c] * v[q, c]
            for c in range(nc):
                nxt[i, c] = acc[c]
        for i in range(n):
            for c in range(nc):
                X[i, c] = nxt[i, c]
    return out


def sens_fused_ref(Phi, W, tab, starts, u, C, X, out, col_b, col_x):
    """Plain numpy reference of :func:`sens_fused` (same parameters)."""
    n, nc = X.shape
    m = u.shape[1]
    nb = n * m
    P = W.shape[1]
    for a in range(tab.shape[0] + 1):
        rows = C @ X
        out[a, :, col_b:col_b + nb] = rows[:, :nb]
        out[a, :, col_x:col_x + nc - nb] = rows[:, nb:]
        if a == tab.shape[0]:
            break
        e, s = tab[a], starts[a]
        drive = np.einsum("qik,qj->ikj", W[e], u[s:s + P]).reshape(n, nb)
        X[:] = Phi[e] @ X
        X[:, :nb] += drive
    return out
