"""The output of a state-space system and its sensitivities to directions in its matrices.

Two users: the Jacobian of the prediction error in :func:`subid.pem` and the
polynomial methods, and the delta-method bands of simulated outputs and step
responses (:func:`subid.simulation_bounds`, :func:`subid.step_bounds`), all
directions in one pass instead of one simulation per direction.

The predictor is a discrete-time system driven by the known signal ``v``
(``v = [u, y]`` for the one-step predictor, ``v = u`` for the simulation):

    x[t+1] = Ap x[t] + Bp v[t],    ŷ[t] = C x[t] + Dp v[t].

For a direction ``j`` in parameter space (``dAp_j, dBp_j, dC_j, dDp_j`` and an
initial-state direction ``dx0_j``) the sensitivity ``s_j = dx/dθ_j`` obeys
(differentiate the recursion)

    s_j[t+1] = Ap s_j[t] + dAp_j x[t] + dBp_j v[t],   s_j[0] = dx0_j,
    dŷ[t]/dθ_j = C s_j[t] + dC_j x[t] + dDp_j v[t].

:func:`jacobian` is the compiled loop, :func:`jacobian_ref` a plain numpy
implementation kept for the tests.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def jacobian(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, dx0):  # pragma: no cover - compiled
    """``(ŷ, J)`` with ``J[t, i, j] = dŷ_i[t] / dθ_j``; shapes (N, ny), (N, ny, d)."""
    N, m = v.shape
    n = Ap.shape[0]
    ny = C.shape[0]
    d = dAp.shape[0]
    yhat = np.empty((N, ny))
    J = np.empty((N, ny, d))
    x = x0.copy()
    xn = np.empty(n)
    S = dx0.copy()                      # (d, n)
    Sn = np.empty((d, n))
    for t in range(N):
        for i in range(ny):
            acc = 0.0
            for k in range(n):
                acc += C[i, k] * x[k]
            for k in range(m):
                acc += Dp[i, k] * v[t, k]
            yhat[t, i] = acc
        for j in range(d):
            for i in range(ny):
                acc = 0.0
                for k in range(n):
                    acc += C[i, k] * S[j, k] + dC[j, i, k] * x[k]
                for k in range(m):
                    acc += dDp[j, i, k] * v[t, k]
                J[t, i, j] = acc
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += Ap[i, k] * x[k]
            for k in range(m):
                acc += Bp[i, k] * v[t, k]
            xn[i] = acc
        for j in range(d):
            for i in range(n):
                acc = 0.0
                for k in range(n):
                    acc += Ap[i, k] * S[j, k] + dAp[j, i, k] * x[k]
                for k in range(m):
                    acc += dBp[j, i, k] * v[t, k]
                Sn[j, i] = acc
        for i in range(n):
            x[i] = xn[i]
        for j in range(d):
            for i in range(n):
                S[j, i] = Sn[j, i]
    return yhat, J


def jacobian_ref(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, dx0):
    """Plain numpy reference of :func:`jacobian`."""
    N = v.shape[0]
    d = dAp.shape[0]
    x = np.array(x0, dtype=float)
    S = np.array(dx0, dtype=float)
    yhat = np.empty((N, C.shape[0]))
    J = np.empty((N, C.shape[0], d))
    for t in range(N):
        yhat[t] = C @ x + Dp @ v[t]
        J[t] = (S @ C.T + np.einsum("jik,k->ji", dC, x) + np.einsum("jik,k->ji", dDp, v[t])).T
        S = S @ Ap.T + np.einsum("jik,k->ji", dAp, x) + np.einsum("jik,k->ji", dBp, v[t])
        x = Ap @ x + Bp @ v[t]
    return yhat, J
