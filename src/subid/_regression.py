"""Linear least-squares estimation of B, D and the initial state x0 given (A, C).

With A and C known, the output of (1) in seed 001 is linear in the remaining
unknowns:

    y(t) = C A^t x0 + sum_{k<t} C A^{t-1-k} B u(k) + D u(t)
         = C S(t) [x0; vec(B)] + (u(t)^T kron I_ny) vec(D),

where the sensitivity ``S(t)`` (n x (n + n*nu)) obeys

    S(0) = [I_n, 0],   S(t+1) = A S(t) + [0, u(t)^T kron I_n]

(``vec`` stacks columns, so ``B u = (u^T kron I_n) vec(B)``). The regressor
rows ``Phi(t) = [C S(t), u(t)^T kron I_ny]`` are produced chunk by chunk by a
compiled kernel and reduced at once by a sequential QR factorisation, so the
memory used does not grow with the record length.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.linalg

_CHUNK = 4096
TINY = 1e-250


def sensitivity_rows_reference(A, C, u, S0, n_x0_cols):
    """Plain-numpy reference of :func:`sensitivity_rows`.

    Parameters
    ----------
    A : (n, n), C : (ny, n), u : (T, nu) inputs of the chunk,
    S0 : (n, q) sensitivity at the first sample of the chunk, with
        ``q = n_x0_cols + n*nu``.

    Returns
    -------
    rows : (T, ny, q) the values ``C S(t)``; S_end : (n, q) sensitivity after
    the chunk.
    """
    T, nu = u.shape
    n = A.shape[0]
    S = S0.copy()
    rows = np.empty((T, C.shape[0], S0.shape[1]))
    for t in range(T):
        rows[t] = C @ S
        S = A @ S
        S[np.abs(S) < TINY] = 0.0
        for j in range(nu):
            c0 = n_x0_cols + j * n
            S[:, c0:c0 + n] += u[t, j] * np.eye(n)
    return rows, S


@numba.njit(cache=True, nogil=True)
def sensitivity_rows(A, C, u, S0, n_x0_cols):  # pragma: no cover - compiled
    """Compiled kernel: same contract as :func:`sensitivity_rows_reference`."""
    T, nu = u.shape
    n = A.shape[0]
    ny = C.shape[0]
    q = S0.shape[1]
    S = S0.copy()
    S_next = np.empty_like(S)
    rows = np.empty((T, ny, q))
    for t in range(T):
        for i in range(ny):
            for c in range(q):
                acc = 0.0
                for k in range(n):
                    acc += C[i, k] * S[k, c]
                rows[t, i, c] = acc
        for i in range(n):
            for c in range(q):
                acc = 0.0
                for k in range(n):
                    acc += A[i, k] * S[k, c]
                S_next[i, c] = acc if abs(acc) >= TINY else 0.0
        for j in range(nu):
            c0 = n_x0_cols + j * n
            for i in range(n):
                S_next[i, c0 + i] += u[t, j]
        S, S_next = S_next, S
    return rows, S


def fit_b_d_x0(A, C, u, y, *, feedthrough=True, estimate_x0=True, kernel=sensitivity_rows):
    """Least-squares B, D (and x0) for given A, C on the raw output samples.

    Parameters
    ----------
    A, C : ndarray
        Identified state and output matrices.
    u, y : ndarray, shape (N, nu), (N, ny)
    feedthrough : bool
        Estimate D (else D = 0).
    estimate_x0 : bool
        Estimate the initial state (else x0 = 0).

    Returns
    -------
    B, D, x0 : ndarray
    diagnostics : dict
        ``residual_rms`` (over all outputs), ``regression_condition`` (an estimate of
        the 1-norm condition number of the column-equilibrated regressor) and
        ``regression_rank_deficient``.
    """
    n = A.shape[0]
    N, nu = u.shape
    ny = y.shape[1]
    nx = n if estimate_x0 else 0
    q = nx + n * nu
    p = q + (ny * nu if feedthrough else 0)
    S = np.zeros((n, q))
    if estimate_x0:
        S[:, :n] = np.eye(n)
    R = np.zeros((0, p + 1))
    A = np.ascontiguousarray(A)
    C = np.ascontiguousarray(C)
    for start in range(0, N, _CHUNK):
        stop = min(start + _CHUNK, N)
        uc = np.ascontiguousarray(u[start:stop])
        rows, S = kernel(A, C, uc, S, nx)
        T = stop - start
        block = np.empty((T, ny, p + 1))
        block[:, :, :q] = rows
        if feedthrough:
            # (u^T kron I_ny) vec(D): column j*ny + i multiplies D[i, j]
            block[:, :, q:p] = _kron_u_identity(uc, ny)
        block[:, :, p] = y[start:stop]
        R = scipy.linalg.qr(np.vstack([R, block.reshape(T * ny, p + 1)]), mode="r",
                            check_finite=False)[0][: p + 1]
    # Equilibrate the columns so that the condition number (and the rank
    # decision) do not depend on the state basis or the signal scaling.
    scale = np.linalg.norm(R[:p, :p], axis=0)
    scale[scale == 0] = 1.0
    Rt = R[:p, :p] / scale
    rhs = R[:p, p]
    rcond = scipy.linalg.lapack.dtrcon(Rt, norm="1", uplo="U", diag="N")[0] if p else 1.0
    deficient = bool(rcond < np.finfo(float).eps * p)
    if deficient:
        theta = scipy.linalg.lstsq(Rt, rhs, lapack_driver="gelsy", check_finite=False)[0]
    else:
        theta = scipy.linalg.solve_triangular(Rt, rhs, check_finite=False)
    theta = theta / scale
    x0 = theta[:n] if estimate_x0 else np.zeros(n)
    B = theta[nx:q].reshape(nu, n).T
    D = theta[q:p].reshape(nu, ny).T if feedthrough else np.zeros((ny, nu))
    resid_norm = abs(R[p, p]) if R.shape[0] > p else 0.0
    diagnostics = {
        "residual_rms": float(resid_norm / np.sqrt(N * ny)),
        "regression_condition": float(1.0 / rcond) if rcond > 0 else float("inf"),
        "regression_rank_deficient": deficient,
    }
    return B, D, x0, diagnostics


def _kron_u_identity(u, ny):
    """Rows of ``u(t)^T kron I_ny`` for every t: shape (T, ny, nu*ny)."""
    T, nu = u.shape
    out = np.zeros((T, ny, nu * ny))
    for j in range(nu):
        for i in range(ny):
            out[:, i, j * ny + i] = u[:, j]
    return out


def fit_b_d_projection(A, C, gamma, L11, L_yu, *, feedthrough=True):
    """B and D from the data statistic, without simulating the model.

    From the data equation ``Y_f = Γ X_f + H_f U_f + E`` (seed 001, eq. (5)),
    multiplying by an orthonormal basis ``Γ^⊥`` of the complement of range(Γ)
    removes the state; regressing on ``U_f`` removes the noise (open loop):

        Γ^⊥T Y_f U_f^T (U_f U_f^T)^{-1} = Γ^⊥T H_f(B, D),

    which is linear in (B, D) given A and C. With ``[U_f; ...; Y_f] = L Q^T``,
    ``Y_f U_f^T (U_f U_f^T)^{-1} = L_yu L11^{-1}``. Block column j of
    ``Γ^⊥T H_f`` is ``G_j D + sum_{i>j} G_i C A^{i-j-1} B`` with ``G_i`` the
    i-th block column of ``Γ^⊥T``. Only f-1 powers of A appear, so this also
    works when A is unstable, where simulating the model overflows.

    Parameters
    ----------
    A, C : ndarray
    gamma : ndarray, shape (f*ny, n)
        Extended observability matrix in the basis of (A, C).
    L11 : ndarray, shape (f*nu, f*nu)
        Lower-triangular factor of the future inputs.
    L_yu : ndarray, shape (f*ny, f*nu)
        Block of the factor coupling the future outputs to ``Q1``.

    Returns
    -------
    B, D : ndarray
    diagnostics : dict
    """
    n = A.shape[0]
    ny = C.shape[0]
    nu = L11.shape[0] * ny // gamma.shape[0]
    f = gamma.shape[0] // ny
    Q = scipy.linalg.qr(gamma, mode="full", check_finite=False)[0]
    G = Q[:, n:].T                                          # (r, f*ny)
    r = G.shape[0]
    M = G @ scipy.linalg.solve_triangular(L11.T, L_yu.T, lower=False,
                                          check_finite=False).T   # Γ^⊥T L_yu L11^{-1}
    powers = [C]
    for _ in range(f - 2):
        powers.append(powers[-1] @ A)
    n_par = n * nu + (ny * nu if feedthrough else 0)
    Phi = np.zeros((f, r * nu, n_par))
    eye_u = np.eye(nu)
    for j in range(f):
        GB = np.zeros((r, n))
        for i in range(j + 1, f):
            GB += G[:, i * ny:(i + 1) * ny] @ powers[i - j - 1]
        Phi[j, :, :n * nu] = np.kron(eye_u, GB)
        if feedthrough:
            Phi[j, :, n * nu:] = np.kron(eye_u, G[:, j * ny:(j + 1) * ny])
    rhs = np.concatenate([M[:, j * nu:(j + 1) * nu].reshape(-1, order="F") for j in range(f)])
    Phi = Phi.reshape(f * r * nu, n_par)
    theta, _, rank, _ = scipy.linalg.lstsq(Phi, rhs, lapack_driver="gelsy", check_finite=False)
    B = theta[:n * nu].reshape(nu, n).T
    D = theta[n * nu:].reshape(nu, ny).T if feedthrough else np.zeros((ny, nu))
    resid = np.linalg.norm(Phi @ theta - rhs) / max(np.linalg.norm(rhs), 1e-300)
    return B, D, {"projection_residual": float(resid),
                  "regression_rank_deficient": bool(rank < n_par)}


# ---------------------------------------------------------------------------
# the same regression, recursively (subid.RecursiveSubspace)
# ---------------------------------------------------------------------------
def b_d_x0_rows(A, C, u, y, S, *, feedthrough=True, n_x0_cols=None, kernel=sensitivity_rows):
    """Rows ``[C S(t), u(t)^T kron I_ny, y(t)]`` of the regression of
    :func:`fit_b_d_x0` for one chunk, and the sensitivity after it.

    The building block of the recursive form of :func:`fit_b_d_x0` (the rows
    are reduced into a triangular factor sample by sample instead of all at
    once); ``S`` is the sensitivity at the first sample of the chunk
    (``[I_n, 0]`` at the start of the regression). Returns ``rows`` of shape
    (T * ny, p + 1) and the sensitivity after the chunk.
    """
    n = A.shape[0]
    T, nu = u.shape
    ny = y.shape[1]
    nx = n if n_x0_cols is None else n_x0_cols
    q = nx + n * nu
    p = q + (ny * nu if feedthrough else 0)
    rows, S = kernel(np.ascontiguousarray(A), np.ascontiguousarray(C),
                     np.ascontiguousarray(u), S, nx)
    block = np.empty((T, ny, p + 1))
    block[:, :, :q] = rows
    if feedthrough:
        block[:, :, q:p] = _kron_u_identity(u, ny)
    block[:, :, p] = y
    return block.reshape(T * ny, p + 1), S


def solve_b_d_x0(R, n, nu, ny, *, n_rows, feedthrough=True, estimate_x0=True):
    """B, D, x0 from the upper-triangular factor ``R`` of the rows of
    :func:`b_d_x0_rows` (reduced by QR or Givens rotations): the solve of
    :func:`fit_b_d_x0`, with the same column equilibration, rank decision and
    diagnostics. ``n_rows``: the (effective) number of rows, for
    ``residual_rms``."""
    nx = n if estimate_x0 else 0
    q = nx + n * nu
    p = q + (ny * nu if feedthrough else 0)
    scale = np.linalg.norm(R[:p, :p], axis=0)
    scale[scale == 0] = 1.0
    Rt = R[:p, :p] / scale
    rhs = R[:p, p]
    rcond = scipy.linalg.lapack.dtrcon(Rt, norm="1", uplo="U", diag="N")[0] if p else 1.0
    deficient = bool(rcond < np.finfo(float).eps * p)
    if deficient:
        theta = scipy.linalg.lstsq(Rt, rhs, lapack_driver="gelsy", check_finite=False)[0]
    else:
        theta = scipy.linalg.solve_triangular(Rt, rhs, check_finite=False)
    theta = theta / scale
    x0 = theta[:n] if estimate_x0 else np.zeros(n)
    B = theta[nx:q].reshape(nu, n).T
    D = theta[q:p].reshape(nu, ny).T if feedthrough else np.zeros((ny, nu))
    resid_norm = abs(R[p, p]) if R.shape[0] > p else 0.0
    diagnostics = {
        "residual_rms": float(resid_norm / np.sqrt(max(n_rows, 1.0))),
        "regression_condition": float(1.0 / rcond) if rcond > 0 else float("inf"),
        "regression_rank_deficient": deficient,
    }
    return B, D, x0, theta, diagnostics
