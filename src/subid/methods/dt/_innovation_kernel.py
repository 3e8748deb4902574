"""Compiled sum of the one-step prediction errors' products of an innovation model.

The order selection's innovation check (:func:`subid.methods.dt.selection.innovation_bic`)
needs, for the model of every order, only ``E^T E``, the sum over the record of the
products of the one-step prediction errors ``e(t) = y(t) - C x̂(t) - D u(t)`` of the
Kalman predictor ``x̂(t+1) = (A - K C) x̂(t) + (B - K D) u(t) + K y(t)`` from
``x̂(0) = 0`` (what ``prediction_errors(model, data, 1, x0='zero')`` returns, summed).
:func:`prediction_power` accumulates it in one pass without storing the predicted
outputs or states; :func:`prediction_power_reference` is the plain loop the tests compare
it against (and ``subid.prediction_errors``).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _power_kernel(Ap, Bu, K, C, D, u, y):  # pragma: no cover - compiled
    """``(sum_t e(t) e(t)^T, finite)`` of the predictor ``(Ap, [Bu, K], C, [D, 0])``
    from a zero state over ``(u, y)``."""
    N = u.shape[0]
    n = Ap.shape[0]
    nu = u.shape[1]
    ny = y.shape[1]
    x = np.zeros(n)
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
    f = lambda M: np.ascontiguousarray(M, dtype=np.float64)     # noqa: E731
    return f(A - K @ C), f(B - K @ D), f(K), f(C), f(D)


def prediction_power(A, B, C, D, K, pieces):
    """``sum e e^T`` over the pieces ``[(u, y), ...]`` (each from a zero state: the
    experiments of a record), or None when it is not finite (the predictor diverged)."""
    Ap, Bu, Kc, Cc, Dc = _predictor(A, B, C, D, K)
    ny = C.shape[0]
    total = np.zeros((ny, ny))
    with np.errstate(all="ignore"):
        for u, y in pieces:
            S, finite = _power_kernel(Ap, Bu, Kc, Cc, Dc,
                                      np.ascontiguousarray(u, dtype=np.float64),
                                      np.ascontiguousarray(y, dtype=np.float64))
            if not finite:
                return None
            total += S
    return total if np.isfinite(total).all() else None


def prediction_power_reference(A, B, C, D, K, pieces):
    """:func:`prediction_power` by a plain loop over the samples (the reference)."""
    Ap, Bu, Kc, Cc, Dc = _predictor(A, B, C, D, K)
    ny = C.shape[0]
    total = np.zeros((ny, ny))
    with np.errstate(all="ignore"):
        for u, y in pieces:
            x = np.zeros(A.shape[0])
            for t in range(u.shape[0]):
                e = y[t] - Cc @ x - Dc @ u[t]
                total += np.outer(e, e)
                x = Ap @ x + Bu @ u[t] + Kc @ y[t]
    return total if np.isfinite(total).all() else None
