"""Numerics shared by the frequency-domain methods (:mod:`subid.methods.fd`).

* :func:`response`: ``D + C (z I - A)^{-1} B`` at many points ``z`` at once;
* :func:`bilinear_points`, :func:`bilinear_to_ct`: the frequency-scaled
  bilinear map that turns a continuous-time problem on a wide frequency range
  into a discrete-time one on the unit circle (points spread over (0, pi)
  instead of a Vandermonde matrix in ``i w`` with entries up to ``w_max**q``);
* :func:`estimate_b_d`: B and D by weighted linear least squares on the
  response for given A and C (the last step of McKelvey, Akçay & Ljung 1996,
  Algorithm 2), one input column at a time;
* :func:`weighted_error`: the weighted residual and its norm.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

__all__ = ["points", "response", "bilinear_points", "bilinear_to_ct", "frequency_scale",
           "estimate_b_d", "weighted_error", "resolvent_c"]


def points(w, dt: float) -> np.ndarray:
    """The points where the response is evaluated: ``i w`` (CT) or ``exp(i w dt)`` (DT)."""
    w = np.asarray(w, dtype=float)
    return 1j * w if dt == 0 else np.exp(1j * w * dt)


def resolvent_c(A, C, z) -> np.ndarray:
    """``C (z_k I - A)^{-1}`` for every point, shape (M, p, n)."""
    n = A.shape[0]
    M = z[:, None, None] * np.eye(n) - A                       # (M, n, n)
    # (z I - A)^T X^T = C^T  <=>  X = C (z I - A)^{-1}
    Ct = np.broadcast_to(C.T.astype(complex), (z.size,) + C.T.shape)
    return np.swapaxes(np.linalg.solve(np.swapaxes(M, 1, 2), Ct), 1, 2)


def response(A, B, C, D, z) -> np.ndarray:
    """``D + C (z_k I - A)^{-1} B``, shape (M, p, m)."""
    return resolvent_c(A, C, z) @ B + D


def frequency_scale(w) -> float:
    """The bilinear map's scale α: the geometric mean of the smallest and largest
    positive frequency, which the map ``w -> 2 arctan(w / α)`` sends to pi/2."""
    positive = w[w > 0]
    if positive.size == 0:
        return 1.0
    return float(math.sqrt(positive[0] * positive[-1]))


def bilinear_points(w, alpha: float) -> np.ndarray:
    """The unit-circle points ``z = (α + i w) / (α - i w)`` (``s = α (z - 1)/(z + 1)``)."""
    s = 1j * np.asarray(w, dtype=float)
    return (alpha + s) / (alpha - s)


def bilinear_to_ct(A_d, C_d, alpha: float):
    """Continuous-time ``(A, C)`` whose response space equals the discrete one's.

    With ``s = α (z - 1)/(z + 1)``: ``A = α (A_d + I)^{-1} (A_d - I)`` and
    ``C = sqrt(2 α) C_d (A_d + I)^{-1}``; then for every ``B_d, D_d`` there are
    ``B = sqrt(2 α) (A_d + I)^{-1} B_d`` and ``D = D_d - C_d (A_d + I)^{-1} B_d``
    with ``D + C (s I - A)^{-1} B = D_d + C_d (z I - A_d)^{-1} B_d``. B and D
    are then estimated in continuous time (:func:`estimate_b_d`). Needs
    ``A_d + I`` invertible (no pole at z = -1, i.e. at s = infinity).
    """
    n = A_d.shape[0]
    lu = scipy.linalg.lu_factor(A_d + np.eye(n), check_finite=False)
    A = alpha * scipy.linalg.lu_solve(lu, A_d - np.eye(n), check_finite=False)
    C = math.sqrt(2.0 * alpha) * scipy.linalg.lu_solve(lu, C_d.T, trans=1,
                                                       check_finite=False).T
    return A, C


def estimate_b_d(A, C, z, G, weights, *, feedthrough: bool):
    """B and D minimising ``sum_k ||weights_k * (G_k - D - C (z_k I - A)^{-1} B)||_F^2``.

    Linear least squares, real and imaginary parts stacked, one input column
    at a time (the columns do not interact). Returns ``(B, D, condition)``,
    the condition number of the largest regression.
    """
    M, p, m = G.shape
    n = A.shape[0]
    CR = resolvent_c(A, C, z)                                   # (M, p, n)
    B = np.zeros((n, m))
    D = np.zeros((p, m))
    worst = 1.0
    for j in range(m):
        wj = weights[:, :, j]                                   # (M, p)
        blocks = [CR * wj[:, :, None]]
        if feedthrough:
            blocks.append(np.broadcast_to(np.eye(p), (M, p, p)) * wj[:, :, None])
        X = np.concatenate(blocks, axis=2).reshape(M * p, -1)
        rhs = (G[:, :, j] * wj).reshape(-1)
        Xr = np.vstack([X.real, X.imag])
        rr = np.concatenate([rhs.real, rhs.imag])
        scale = np.linalg.norm(Xr, axis=0)
        scale[scale == 0] = 1.0
        sol, _, rank, sv = scipy.linalg.lstsq(Xr / scale, rr, lapack_driver="gelsd",
                                              check_finite=False)
        sol = sol / scale
        if sv.size and sv[-1] > 0:
            worst = max(worst, float(sv[0] / sv[-1]))
        elif sv.size:
            worst = math.inf
        B[:, j] = sol[:n]
        if feedthrough:
            D[:, j] = sol[n:]
    return B, D, worst


def weighted_error(G, G_hat, weights) -> float:
    """``sqrt(sum |weights * (G - G_hat)|^2)``."""
    return float(np.linalg.norm((weights * (G - G_hat)).ravel()))
