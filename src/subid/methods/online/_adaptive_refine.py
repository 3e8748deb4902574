"""Structured refit of the regression (8) of seed 000 (issue 23): the model's 20
parameters fitted to the instrumental-variable equations, rows weighted by the
covariance of their equation error.

The identifier keeps the IV statistics of (8) (``C = Σ w ζ φ^T``, ``Z = Σ w ζ
ζ^T`` and ``G = S - M C^T`` at its unstructured estimate M). The two-stage
least-squares criterion of any M is, with ``Z = L L^T``,

    J(M) = |((M - M̂) C^T - G) L^{-T}|_F^2 ,

minimised by the unstructured M̂ (``f n_y (n + f n_u)`` free entries; 140 for
the paper's system) from which (13) then extracts (Ã, C̃). Here J is minimised
over the matrices of the form (9) instead,

    M(θ) = [Õ_f, (I - Õ_f H) T_f],   Õ_f = O_f(Ã/ω, C̃),  T_f = T_f(Ã/ω, B̃/ω, C̃, D),

with θ = (A, B, C, D) taken to the basis of (23) (``H Õ_f = I``) before M is
formed, so that only the ``n (n_u + n_y) + n_y n_u`` parameters of the model are
fitted (Gauss-Newton / Levenberg-Marquardt, :func:`scipy.optimize.least_squares`,
started from the current model). The rows of (8) do not carry the same noise:
the equation error is ``e = (I - Õ_f H) p̂_v``, ``p̂_v`` the filter states of the
output noise. For white output noise of power σ_c² on channel c, the filter
states of each channel have covariance ``σ_c² P_f``, ``A_f P_f + P_f A_f^T + b_f
b_f^T = 0``, so that ``Cov e = E Σ_p E^T`` (``E = I - Õ_f H``); the rows are
weighted by its inverse Cholesky factor (weighted least squares on the
equations, Gauss-Markov). σ_c² is estimated by the identifier from the
prediction error of (16) (``Ev``), which is the output error of the current
model. Measured gain: ``docs/seed000.md`` (issue 23, "Structured refit").
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.optimize import least_squares

from subid.methods._common import extended_observability

__all__ = ["refit", "structured_m", "toeplitz"]

# Largest number of residual evaluations of the Levenberg-Marquardt search.
_MAX_EVALUATIONS = 4000
# Its tolerances: tight, so that states equal to rounding (chunked, time-stamped
# streams) give refits equal to rounding, not to the search's stopping rule.
_TOLERANCE = 1e-14


def toeplitz(A, B, C, D, f):
    """The block Toeplitz matrix T_f of (3): D on the diagonal, C A^k B below."""
    ny, nu = D.shape
    markov = [D]
    X = B
    for _ in range(f - 1):
        markov.append(C @ X)
        X = A @ X
    T = np.zeros((f * ny, f * nu))
    for i in range(f):
        for j in range(i + 1):
            T[i * ny:(i + 1) * ny, j * nu:(j + 1) * nu] = markov[i - j]
    return T


def structured_m(theta, n, nu, ny, f, H, omega):
    """``(M(θ), (Ã, B̃, C̃, D))``: the matrix (9) of the model θ (A, B, C, D
    flattened) in the basis fixed by H (23); None where ``H O_f`` is singular."""
    A = theta[:n * n].reshape(n, n)
    B = theta[n * n:n * n + n * nu].reshape(n, nu)
    C = theta[n * n + n * nu:n * n + n * nu + ny * n].reshape(ny, n)
    D = theta[n * n + n * nu + ny * n:].reshape(ny, nu)
    T = H @ extended_observability(A / omega, C, f)
    try:
        At = np.linalg.solve(T.T, (T @ A).T).T          # T A T^{-1}
        Ct = np.linalg.solve(T.T, C.T).T                # C T^{-1}
    except np.linalg.LinAlgError:
        return None
    Bt = T @ B
    O = extended_observability(At / omega, Ct, f)
    M = np.hstack([O, (np.eye(f * ny) - O @ H) @ toeplitz(At / omega, Bt / omega, Ct, D, f)])
    return M, (At, Bt, Ct, D)


def refit(model, M, Cz, Gz, Zz, H, omega, Af, Bf, noise_power, max_condition):
    """Refit the model ``(A, B, C, D)`` to the IV equations of (8) (module notes).

    Returns ``((A, B, C, D), cost_ratio)`` in the basis of (23), or None when the
    search fails or the result is not finite or not Hurwitz.
    ``noise_power``: σ_c² per output channel.
    """
    A, B, C, D = model
    n, nu = B.shape
    ny = C.shape[0]
    f = M.shape[0] // ny
    Zs = np.tril(Zz) + np.tril(Zz, -1).T
    Cf = np.hstack([Cz, Zs[:, :f * nu]])
    try:        # the kernel's whitening: Z + (tr Z / max_condition) I = L L^T
        L = np.linalg.cholesky(Zs + np.trace(Zs) / max_condition * np.eye(Zs.shape[0]))
    except np.linalg.LinAlgError:
        return None
    Ct = scipy.linalg.solve_triangular(L, Cf, lower=True)
    Gt = scipy.linalg.solve_triangular(L, Gz.T, lower=True).T
    theta0 = np.concatenate([A.ravel(), B.ravel(), C.ravel(), D.ravel()])
    start = structured_m(theta0, n, nu, ny, f, H, omega)
    if start is None:
        return None
    # row weighting: Cov e = E Σ_p E^T, E = I - Õ_f H, Σ_p = σ_c² P_f per channel
    Pf = scipy.linalg.solve_continuous_lyapunov(Af, -Bf @ Bf.T)
    power = np.maximum(noise_power, 1e-12 * max(float(np.max(noise_power)), 1e-300))
    Sp = np.zeros((f * ny, f * ny))
    for c in range(ny):
        rows = np.arange(f) * ny + c
        Sp[np.ix_(rows, rows)] = Pf * power[c]
    E = np.eye(f * ny) - start[0][:, :n] @ H
    Se = E @ Sp @ E.T
    try:
        Le = np.linalg.cholesky(Se + 1e-12 * np.trace(Se) * np.eye(f * ny))
    except np.linalg.LinAlgError:
        return None

    def residual(theta):
        out = structured_m(theta, n, nu, ny, f, H, omega)
        if out is None:
            return np.full(M.shape[0] * Ct.shape[0], 1e150)
        return scipy.linalg.solve_triangular(Le, (out[0] - M) @ Ct.T - Gt, lower=True).ravel()

    r0 = residual(theta0)
    with np.errstate(all="ignore"):
        sol = least_squares(residual, theta0, method="lm", max_nfev=_MAX_EVALUATIONS,
                            ftol=_TOLERANCE, xtol=_TOLERANCE, gtol=_TOLERANCE)
    # Levenberg-Marquardt only takes steps that lower J, so sol.cost <= J(θ0);
    # no threshold on the decrease (noise-free, where θ0 is already the
    # minimiser, a threshold would decide on rounding)
    if not np.all(np.isfinite(sol.x)):
        return None
    out = structured_m(sol.x, n, nu, ny, f, H, omega)
    if out is None or not np.all(np.isfinite(out[0])):
        return None
    At = out[1][0]
    if not np.all(np.linalg.eigvals(At).real < 0):
        return None
    start_cost = float(r0 @ r0)
    return out[1], float(2.0 * sol.cost / start_cost) if start_cost > 0 else 1.0
