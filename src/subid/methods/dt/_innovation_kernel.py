"""Compiled kernels of the order selection's innovation check.

**Prediction errors.**
The order selection's innovation check (:func:`subid.methods.dt.choice.innovation_bic`)
needs, for the model of every order, only ``E^T E``, the sum over the record of the
products of the one-step prediction errors ``e(t) = y(t) - C x̂(t) - D u(t)`` of the
Kalman predictor ``x̂(t+1) = (A - K C) x̂(t) + (B - K D) u(t) + K y(t)`` from
``x̂(0) = 0`` (what ``prediction_errors(model, data, 1, x0='zero')`` returns, summed), or
from a given initial state (the innovation covariance of a final model,
:func:`subid.methods.dt.noise_model.with_factor`).
:func:`prediction_power` accumulates it in one pass without storing the predicted
outputs or states; :func:`prediction_power_reference` is the plain loop the tests compare
it against (and ``subid.prediction_errors``).

**Riccati equation by doubling.** :func:`doubling` runs the iteration of
:func:`subid.methods.dt.noise_model.riccati_by_doubling` (the structure-preserving doubling
algorithm) on its prepared matrices in one compiled loop: a dozen small matrix products
per step, which in numpy cost more in call overhead than in arithmetic (about half of a
check model's noise model). :func:`doubling_reference` is the numpy loop it replaces.
"""

from __future__ import annotations

import numba
import numpy as np

from subid._kernel_args import frozen


@numba.njit(cache=True)
def _power_kernel(Ap, Bu, K, C, D, u, y, x0):  # pragma: no cover - compiled
    """``(sum_t e(t) e(t)^T, finite)`` of the predictor ``(Ap, [Bu, K], C, [D, 0])``
    from the state ``x0`` over ``(u, y)``."""
    N = u.shape[0]
    n = Ap.shape[0]
    nu = u.shape[1]
    ny = y.shape[1]
    x = x0.copy()
    xn = np.zeros(n)
    e = np.zeros(ny)
    S = np.zeros((ny, ny))
    for t in range(N):
        for i in range(ny):
            s = y[t, i]
            for j in range(n):
                s -= C[i, j] * x[j]
            for j in range(nu):
                s -= D[i, j] * u[t, j]
            e[i] = s
        for i in range(ny):
            for j in range(i + 1):
                S[i, j] += e[i] * e[j]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += Ap[i, j] * x[j]
            for j in range(nu):
                s += Bu[i, j] * u[t, j]
            for j in range(ny):
                s += K[i, j] * y[t, j]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]
    for i in range(ny):
        for j in range(i + 1, ny):
            S[i, j] = S[j, i]
    finite = True
    for i in range(ny):
        for j in range(ny):
            if not np.isfinite(S[i, j]):
                finite = False
    return S, finite


def _predictor(A, B, C, D, K):
    """The predictor's matrices, read-only (one compiled signature,
    :mod:`subid._kernel_args`)."""
    return frozen(A - K @ C), frozen(B - K @ D), frozen(K), frozen(C), frozen(D)


def _initial_states(x0, n, count):
    """One initial state per piece: zeros, or the rows of ``x0`` (shape (n,) for one
    piece, (count, n) for several)."""
    if x0 is None:
        return [np.zeros(n)] * count
    return list(np.asarray(x0, dtype=float).reshape(count, n))


def prediction_power(A, B, C, D, K, pieces, x0=None):
    """``sum e e^T`` over the pieces ``[(u, y), ...]`` (the experiments of a record),
    each predicted from a zero state or from its row of ``x0``; None when it is not
    finite (the predictor diverged)."""
    Ap, Bu, Kc, Cc, Dc = _predictor(A, B, C, D, K)
    ny = C.shape[0]
    total = np.zeros((ny, ny))
    with np.errstate(all="ignore"):
        for (u, y), start in zip(pieces, _initial_states(x0, A.shape[0], len(pieces))):
            S, finite = _power_kernel(Ap, Bu, Kc, Cc, Dc, frozen(u), frozen(y),
                                      frozen(start))
            if not finite:
                return None
            total += S
    return total if np.isfinite(total).all() else None


def prediction_power_reference(A, B, C, D, K, pieces, x0=None):
    """:func:`prediction_power` by a plain loop over the samples (the reference)."""
    Ap, Bu, Kc, Cc, Dc = _predictor(A, B, C, D, K)
    ny = C.shape[0]
    total = np.zeros((ny, ny))
    with np.errstate(all="ignore"):
        for (u, y), start in zip(pieces, _initial_states(x0, A.shape[0], len(pieces))):
            x = start.copy()
            for t in range(u.shape[0]):
                e = y[t] - Cc @ x - Dc @ u[t]
                total += np.outer(e, e)
                x = Ap @ x + Bu @ u[t] + Kc @ y[t]
    return total if np.isfinite(total).all() else None


@numba.njit(cache=True)
def _doubling_kernel(Ak0, G0, H0, iterations, tolerance):  # pragma: no cover - compiled
    """``(H, status)``: status 0 converged, 1 singular step, 2 not finite, 3 not settled."""
    Ak, G, H = Ak0.copy(), G0.copy(), H0.copy()     # writeable iterates
    n = Ak.shape[0]
    eye = np.eye(n)
    rhs = np.empty((n, 2 * n))
    for _ in range(iterations):
        rhs[:, :n] = Ak
        rhs[:, n:] = G
        M = eye + G @ H
        # the LU factorisation with partial pivoting of np.linalg.solve, its singular
        # case reported instead of raised
        lu = M.copy()
        perm = np.arange(n)
        for k in range(n):
            p = k
            big = abs(lu[k, k])
            for i in range(k + 1, n):
                if abs(lu[i, k]) > big:
                    big = abs(lu[i, k])
                    p = i
            if big == 0.0 or not np.isfinite(big):
                return H, 1
            if p != k:
                for j in range(n):
                    lu[k, j], lu[p, j] = lu[p, j], lu[k, j]
                perm[k], perm[p] = perm[p], perm[k]
            for i in range(k + 1, n):
                lu[i, k] /= lu[k, k]
                f = lu[i, k]
                for j in range(k + 1, n):
                    lu[i, j] -= f * lu[k, j]
        solved = np.empty((n, 2 * n))
        for c in range(2 * n):
            for i in range(n):
                s = rhs[perm[i], c]
                for j in range(i):
                    s -= lu[i, j] * solved[j, c]
                solved[i, c] = s
            for i in range(n - 1, -1, -1):
                s = solved[i, c]
                for j in range(i + 1, n):
                    s -= lu[i, j] * solved[j, c]
                solved[i, c] = s / lu[i, i]
        WA = np.ascontiguousarray(solved[:, :n])
        WG = np.ascontiguousarray(solved[:, n:])
        AkT = np.ascontiguousarray(Ak.T)
        H_next = H + AkT @ H @ WA
        H_next = 0.5 * (H_next + H_next.T)
        G = G + Ak @ WG @ AkT
        G = 0.5 * (G + G.T)
        Ak = Ak @ WA
        change = np.abs(H_next - H).max()
        H = H_next
        if not np.isfinite(change):
            return H, 2
        if change <= tolerance * max(np.abs(H).max(), 1e-300):
            return H, 0
    return H, 3


def doubling(Ak, G, H, iterations, tolerance):
    """The doubling iteration from ``(A_0, G_0, H_0)``: ``P``, or None when a step is
    singular, an iterate is not finite or it does not settle within ``iterations``."""
    with np.errstate(all="ignore"):      # read-only: one compiled signature
        P, status = _doubling_kernel(frozen(Ak), frozen(G), frozen(H), int(iterations),
                                     float(tolerance))
    return P if status == 0 else None


def doubling_reference(Ak, G, H, iterations, tolerance):
    """:func:`doubling` by numpy (the reference)."""
    n = Ak.shape[0]
    eye = np.eye(n)
    rhs = np.empty((n, 2 * n))
    with np.errstate(all="ignore"):
        for _ in range(iterations):
            rhs[:, :n] = Ak
            rhs[:, n:] = G
            try:
                solved = np.linalg.solve(eye + G @ H, rhs)
            except np.linalg.LinAlgError:
                return None
            WA, WG = solved[:, :n], solved[:, n:]
            H_next = H + Ak.T @ H @ WA
            H_next = 0.5 * (H_next + H_next.T)
            G = G + Ak @ WG @ Ak.T
            G = 0.5 * (G + G.T)
            Ak = Ak @ WA
            change = float(np.abs(H_next - H).max())
            H = H_next
            if not np.isfinite(change):
                return None
            if change <= tolerance * max(float(np.abs(H).max()), 1e-300):
                return H
    return None
