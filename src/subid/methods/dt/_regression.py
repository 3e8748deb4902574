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

import contextlib
import contextvars

import numba
import numpy as np
import scipy.linalg

from subid._kernel_args import frozen
from subid.methods.dt._lag_kernel import scored_solve
from subid.statistic.hankel import householder_r

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


def dual_rows_reference(A, C, u, V0, M0, n_x0):
    """Plain-numpy reference of :func:`dual_rows`.

    The rows ``C S(t)`` of :func:`sensitivity_rows_reference` from a zero-input
    start, by the dual recursions: for output i and input j, the B columns
    ``(C S_B(t))[i, j*n + m] = sum_{k<t} (C A^(t-1-k))[i, m] u_j(k)`` are the state
    ``v_ij(t)`` of ``v(t+1) = A^T v(t) + C[i]^T u_j(t)``, and the x0 columns are
    ``M(t) = C A^t`` (``M(t+1) = M(t) A``): ``n^2 ny (nu + 1)`` flops a sample
    instead of ``n^3 (1 + nu)``.

    Parameters
    ----------
    A : (n, n), C : (ny, n), u : (T, nu)
    V0 : (ny, nu, n) the states ``v_ij`` at the first sample.
    M0 : (ny, n) ``C A^t`` at the first sample (unused when ``n_x0`` is 0).
    n_x0 : int, 0 or n.

    Returns
    -------
    rows : (T, ny, n_x0 + n*nu); V, M after the chunk.
    """
    T, nu = u.shape
    n = A.shape[0]
    ny = C.shape[0]
    V, M = V0.copy(), M0.copy()
    rows = np.empty((T, ny, n_x0 + n * nu))
    for t in range(T):
        if n_x0:
            rows[t, :, :n] = M
        rows[t, :, n_x0:] = V.reshape(ny, nu * n)
        V = V @ A + C[:, None, :] * u[t][None, :, None]
        M = M @ A
        M[np.abs(M) < TINY] = 0.0
    return rows, V, M


@numba.njit(cache=True, nogil=True)
def _dual_step(A, C, ut, V, M, Vn, Mn, n_x0):  # pragma: no cover - compiled
    """One step of the dual recursions into ``Vn`` and ``Mn``: ``Vn = V A + C^T u(t)``
    per (output, input), ``Mn = M A`` (entries below :data:`TINY` set to zero) when
    ``n_x0``."""
    ny, nu, n = V.shape
    # each sum in the order C u, then k = 0..n-1; the loop over m innermost (the
    # rows of A contiguous: vectorised, the same sums to the last bit)
    for i in range(ny):
        for j in range(nu):
            uj = ut[j]
            for m in range(n):
                Vn[i, j, m] = C[i, m] * uj
            for k in range(n):
                v = V[i, j, k]
                for m in range(n):
                    Vn[i, j, m] += v * A[k, m]
    if n_x0:
        for i in range(ny):
            for m in range(n):
                Mn[i, m] = 0.0
            for k in range(n):
                v = M[i, k]
                for m in range(n):
                    Mn[i, m] += v * A[k, m]
            for m in range(n):
                if abs(Mn[i, m]) < TINY:
                    Mn[i, m] = 0.0


@numba.njit(cache=True, nogil=True)
def dual_rows(A, C, u, V0, M0, n_x0):  # pragma: no cover - compiled
    """Compiled kernel: same contract as :func:`dual_rows_reference`."""
    T, nu = u.shape
    n = A.shape[0]
    ny = C.shape[0]
    V = V0.copy()
    M = M0.copy()
    Vn = np.empty_like(V)
    Mn = np.empty_like(M)
    rows = np.empty((T, ny, n_x0 + n * nu))
    for t in range(T):
        for i in range(ny):
            if n_x0:
                for m in range(n):
                    rows[t, i, m] = M[i, m]
            for j in range(nu):
                for m in range(n):
                    rows[t, i, n_x0 + j * n + m] = V[i, j, m]
        _dual_step(A, C, u[t], V, M, Vn, Mn, n_x0)
        V, Vn = Vn, V
        if n_x0:
            M, Mn = Mn, M
    return rows, V, M


def dual_states_reference(A, C, u, V0, M0, n_x0):
    """The states ``V, M`` of :func:`dual_rows_reference` after the samples of ``u``,
    without the rows (the plain reference of :func:`dual_states`)."""
    _, V, M = dual_rows_reference(A, C, u, V0, M0, n_x0)
    return V, M


@numba.njit(cache=True, nogil=True)
def dual_states(A, C, u, V0, M0, n_x0):  # pragma: no cover - compiled
    """Compiled kernel: the states ``V, M`` of :func:`dual_rows` after the samples of
    ``u`` by the same steps, without writing the rows (the head of the record before a
    residual bound's tail, :mod:`subid.methods.dt._residual_bound`)."""
    V = V0.copy()
    M = M0.copy()
    Vn = np.empty_like(V)
    Mn = np.empty_like(M)
    for t in range(u.shape[0]):
        _dual_step(A, C, u[t], V, M, Vn, Mn, n_x0)
        V, Vn = Vn, V
        if n_x0:
            M, Mn = Mn, M
    return V, M


def fit_b_d_x0(A, C, u, y, *, feedthrough=True, estimate_x0=True, output_weights=None,
               kernel=None, path="auto"):
    """Least-squares B, D (and x0) for given A, C on the raw output samples.

    ``path='auto'`` (default) solves the problem by the modal normal equations
    (:func:`fit_b_d_x0_modal`, 10x faster) and falls back to the sequential
    QR factorisation of the regressor (:func:`fit_b_d_x0_qr`, the reference)
    when A is unstable, its eigenvector matrix is ill-conditioned or the
    equilibrated normal matrix is; ``'qr'`` and ``'modal'`` force one path
    (``'modal'`` raises :class:`ValueError` where it does not apply).
    ``diagnostics['regression_path']`` says which path ran.

    This is the engine of one record in memory; :func:`subid.methods.bd.fit_b_d_x0`
    (the entry point of every B, D, x0 route) also runs it on several
    experiments and on many channels (:mod:`subid.methods.dt._bd_large`).
    """
    if path not in ("auto", "qr", "modal"):
        raise ValueError(f"path must be 'auto', 'qr' or 'modal', got {path!r}")
    if path != "qr":
        fitted = fit_b_d_x0_modal(A, C, u, y, feedthrough=feedthrough,
                                  estimate_x0=estimate_x0, output_weights=output_weights)
        if fitted is not None:
            return fitted
        if path == "modal":
            raise ValueError("the modal path does not apply: A is unstable or its eigenvector "
                             "matrix or the normal equations are ill-conditioned")
    return fit_b_d_x0_qr(A, C, u, y, feedthrough=feedthrough, estimate_x0=estimate_x0,
                         output_weights=output_weights, kernel=kernel)


def fit_b_d_x0_qr(A, C, u, y, *, feedthrough=True, estimate_x0=True, output_weights=None,
                  kernel=None):
    """Least-squares B, D (and x0) by a sequential QR factorisation of the regressor.

    Parameters
    ----------
    A, C : ndarray
        Identified state and output matrices.
    u, y : ndarray, shape (N, nu), (N, ny)
    feedthrough : bool
        Estimate D (else D = 0).
    estimate_x0 : bool
        Estimate the initial state (else x0 = 0).
    output_weights : ndarray, shape (ny,), optional
        Each output's errors are multiplied by its weight in the least-squares
        cost (e.g. the inverse of its standard deviation, so that the fit does
        not depend on the output units). Default: all ones.
    kernel : callable, optional
        A sensitivity kernel (:func:`sensitivity_rows` or its reference) to
        build the rows from the sensitivity recursion of the module
        documentation; default: the dual recursions of :func:`dual_rows`
        (the same rows to rounding, 9x fewer flops at n = 10 with two inputs
        and outputs).

    Returns
    -------
    B, D, x0 : ndarray
    diagnostics : dict
        ``residual_rms`` (over all weighted outputs), ``regression_condition`` (an estimate of
        the 1-norm condition number of the column-equilibrated regressor) and
        ``regression_rank_deficient``.
    """
    n = A.shape[0]
    N, nu = u.shape
    ny = y.shape[1]
    nx, q, p = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    if kernel is None:
        R = _dual_qr_factor(A, C, u, y, n_x0=nx, feedthrough=feedthrough,
                            output_weights=output_weights)
    else:
        S = np.zeros((n, q))
        if estimate_x0:
            S[:, :n] = np.eye(n)
        R, _ = qr_factor(A, C, u, y, S, n_x0=nx, feedthrough=feedthrough,
                         output_weights=output_weights, kernel=kernel)
    return solve_qr_factor(R, n, nu, ny, estimate_x0=estimate_x0, feedthrough=feedthrough,
                           n_samples=N)


def _dual_qr_factor(A, C, u, y, *, n_x0, feedthrough, output_weights=None,
                    kernel=dual_rows):
    """:func:`qr_factor` of a whole record from a zero-input start, its rows by the
    dual recursions (:func:`dual_rows`)."""
    N, nu = u.shape
    n, ny = A.shape[0], y.shape[1]
    q = n_x0 + n * nu
    p = q + (ny * nu if feedthrough else 0)
    A, C = frozen(A), frozen(C)         # read-only inputs: one compiled signature
    V = np.zeros((ny, nu, n))
    M = np.array(C)
    R = np.zeros((0, p + 1))
    flat = np.empty((p + 1 + min(_CHUNK, max(N, 1)) * ny) * (p + 1))
    for start in range(0, N, _CHUNK):
        stop = min(start + _CHUNK, N)
        uc = np.ascontiguousarray(u[start:stop], dtype=float)
        rows, V, M = kernel(A, C, frozen(uc), V, M, n_x0)
        block = _with_d_and_y(rows, uc, y[start:stop], p, feedthrough, output_weights)
        if not np.isfinite(block).all():    # overflowed (an unstable A): the factor would
            return np.full((p + 1, p + 1), np.nan)     # be NaN; LAPACK is slow on NaN
        R = _qr_append(R, block, flat)
    return R


def _with_d_and_y(rows, u, y, p, feedthrough, output_weights):
    """Rows ``[C S(t), u(t)^T kron I, y(t)]`` (weighted) from the ``C S(t)`` part."""
    T, ny, q = rows.shape
    block = np.empty((T, ny, p + 1))
    block[:, :, :q] = rows
    if feedthrough:
        block[:, :, q:p] = _kron_u_identity(u, ny)
    block[:, :, p] = y
    if output_weights is not None:
        block *= output_weights[None, :, None]
    return block.reshape(T * ny, p + 1)


def _qr_append(R, rows, flat):
    """Triangular factor of ``[R; rows]``: the two written into one column-major
    work array (from the buffer ``flat``) and factorised in place by LAPACK
    ``geqrt`` (:func:`subid.statistic.hankel.householder_r`)."""
    top, width = R.shape[0], rows.shape[1]
    work = flat[:(top + rows.shape[0]) * width].reshape((top + rows.shape[0], width), order="F")
    work[:top] = R
    work[top:] = rows
    qr = householder_r(work)
    return np.triu(qr[:min(width, qr.shape[0])])


def qr_factor(A, C, u, y, S, *, n_x0, feedthrough, output_weights=None,
              kernel=sensitivity_rows, R=None):
    """Triangular factor of the weighted rows ``[Phi(t), y(t)]`` of one piece.

    ``S`` is the sensitivity at the piece's first sample (``[I, 0]`` at the
    start of the record with x0 estimated). Returns ``(R, S_end)``, ``R`` of
    shape (at most p + 1, p + 1); factors of consecutive pieces merge by a QR
    factorisation of their stack (``R`` continues a previous one).
    """
    N, nu = u.shape
    ny = y.shape[1]
    q = S.shape[1]
    p = q + (ny * nu if feedthrough else 0)
    R = np.zeros((0, p + 1)) if R is None else R
    A = np.ascontiguousarray(A)
    C = np.ascontiguousarray(C)
    flat = np.empty((max(R.shape[0], p + 1) + min(_CHUNK, max(N, 1)) * ny) * (p + 1))
    for start in range(0, N, _CHUNK):
        stop = min(start + _CHUNK, N)
        rows, S = regression_rows(A, C, u[start:stop], y[start:stop], S, n_x0=n_x0,
                                  feedthrough=feedthrough, output_weights=output_weights,
                                  kernel=kernel)
        if not np.isfinite(rows).all():     # overflowed (an unstable A): the factor would
            return np.full((p + 1, p + 1), np.nan), S  # be NaN; LAPACK is slow on NaN
        R = _qr_append(R, rows, flat)
    return R, S


def regression_rows(A, C, u, y, S, *, n_x0, feedthrough, output_weights=None,
                    kernel=sensitivity_rows):
    """Rows ``[Phi(t), y(t)]`` of the regression for the samples of ``u, y``.

    ``S`` is the sensitivity at the first sample. Row ``t * ny + i`` belongs to
    output ``i`` at sample ``t`` (multiplied by ``output_weights[i]`` when given).
    Shared by the QR path (:func:`qr_factor`) and the recursive regression of
    :class:`subid.RecursiveSubspace`.

    Returns
    -------
    rows : (T * ny, p + 1), S_end : sensitivity after the samples
    """
    T, nu = u.shape
    ny = y.shape[1]
    q = S.shape[1]
    p = q + (ny * nu if feedthrough else 0)
    uc = np.ascontiguousarray(u)
    rows, S = kernel(frozen(A), frozen(C), frozen(uc), S, n_x0)
    return _with_d_and_y(rows, uc, y, p, feedthrough, output_weights), S


def solve_qr_factor(R, n, nu, ny, *, estimate_x0, feedthrough, n_samples):
    """B, D, x0 and diagnostics from the triangular factor of the weighted rows."""
    B, D, x0, _, diagnostics = solve_factor(R, n, nu, ny, estimate_x0=estimate_x0,
                                            feedthrough=feedthrough, n_samples=n_samples)
    return B, D, x0, diagnostics


def solve_factor(R, n, nu, ny, *, estimate_x0, feedthrough, n_samples, n_x0=None):
    """:func:`solve_qr_factor` that also returns the parameter vector
    ``theta = [x0; vec B; vec D]`` (``n_samples`` may be an effective count
    under forgetting): ``(B, D, x0, theta, diagnostics)``. ``n_x0`` overrides
    the number of x0 columns (one x0 per experiment: ``n_experiments * n``)."""
    N = n_samples
    nx, q, p = parameter_count(n, nu, ny, estimate_x0, feedthrough, n_x0)
    if R.shape[0] < p + 1:
        R = np.vstack([R, np.zeros((p + 1 - R.shape[0], p + 1))])
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
    x0 = theta[:nx] if estimate_x0 else np.zeros(n)
    B = theta[nx:q].reshape(nu, n).T
    D = theta[q:p].reshape(nu, ny).T if feedthrough else np.zeros((ny, nu))
    resid_norm = abs(R[p, p]) if R.shape[0] > p else 0.0
    diagnostics = {
        "residual_rms": float(resid_norm / np.sqrt(N * ny)),
        "regression_condition": float(1.0 / rcond) if rcond > 0 else float("inf"),
        "regression_rank_deficient": deficient,
        "regression_path": "qr",
    }
    return B, D, x0, theta, diagnostics


def _kron_u_identity(u, ny):
    """Rows of ``u(t)^T kron I_ny`` for every t: shape (T, ny, nu*ny) (column
    ``j*ny + i`` multiplies ``D[i, j]``: ``(u^T kron I_ny) vec(D)``)."""
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
    # Input channel k of block column j: Γ^⊥T H_f's column j*nu + k is
    # GB_j B[:, k] + G_j D[:, k] (GB_j = sum_{i>j} G_i C A^(i-j-1)), so the
    # regressor of (vec B, vec D) is block diagonal over the inputs, each block
    # the same Psi = [GB_j, G_j] stacked over j (f r x (n + ny)): one least
    # squares with nu right-hand sides, [B; D] column by column. The dense
    # kron(I_nu, Psi) was f r nu x (n nu + ny nu) (issue 28: 20 GB at 100 inputs
    # and outputs, horizon 5); this is f r (n + ny + nu).
    n_col = n + (ny if feedthrough else 0)
    Psi = np.zeros((f, r, n_col))
    for j in range(f):
        GB = Psi[j, :, :n]
        for i in range(j + 1, f):
            GB += G[:, i * ny:(i + 1) * ny] @ powers[i - j - 1]
        if feedthrough:
            Psi[j, :, n:] = G[:, j * ny:(j + 1) * ny]
    Psi = Psi.reshape(f * r, n_col)
    rhs = M.reshape(r, f, nu).transpose(1, 0, 2).reshape(f * r, nu)   # row (j, q), column k
    theta, _, rank, _ = scipy.linalg.lstsq(Psi, rhs, lapack_driver="gelsy", check_finite=False)
    B = theta[:n]
    D = theta[n:] if feedthrough else np.zeros((ny, nu))
    resid = np.linalg.norm(Psi @ theta - rhs) / max(np.linalg.norm(rhs), 1e-300)
    return B, D, {"projection_residual": float(resid),
                  "regression_rank_deficient": bool(rank < n_col)}


# ---------------------------------------------------------------------------
# The same regression by modal normal equations
# ---------------------------------------------------------------------------
#
# With A = V diag(λ) V^{-1} (stable, V well conditioned), ``c = C V`` and
# ``W = V^{-1}``, the regressors of output i are
#
#   x0[m]:   sum_l c_il W_lm λ_l^t
#   B[m, j]: sum_l c_il W_lm r_lj(t),   r_lj(t+1) = λ_l r_lj(t) + u_j(t), r_lj(0) = 0
#   D[i, j]: u_j(t)
#
# (expand A^t = V λ^t W in the sensitivity of the module docstring). A complex
# pair contributes twice the real part of its representative (Im λ > 0), so
# every regressor is a fixed real combination of the real signals
#
#   w(t) = [Re/Im λ_l^t ; Re/Im r_lj(t) ; u(t) ; y(t)]
#
# (one column per real mode, two per pair: n free signals, n*nu filtered
# ones), and the weighted normal equations are P_i (sum_t w w^T) P_i^T summed
# over the outputs. ``sum_t w w^T`` costs about (n (nu + 1) + nu + ny)^2 / 2
# multiply-adds per sample, with no dependence on the number of parameters;
# λ^t is dropped once below rounding (:func:`free_length`).
#
# A piece of the record that starts at time t0 with filter state r(t0) has
# r(t) = r(t0) λ^(t-t0) + r0(t) (r0: zero-start filter) and λ^t = λ^t0 λ^(t-t0):
# its moments taken with zero start and local free signals λ^(t-t0) map exactly
# to the global ones (:func:`regressor_maps`). That makes the normal equations
# of consecutive pieces mergeable (subid.methods.dt.stream, subid.methods.dt.distributed).

#: Largest condition number of the eigenvector matrix for the modal path.
MODAL_MAX_EIGVEC_CONDITION = 1e6
#: Largest condition number of the equilibrated normal matrix for the modal path.
MODAL_MAX_NORMAL_CONDITION = 1e4
#: Largest condition number of the equilibrated normal matrix for the normal
#: equations (modal, lag products) of models that are only scored
#: (:func:`scoring_only`): the cross-validation folds and the innovation check.
#: Their parameters then differ from the QR path's by about ``cond * eps``
#: relative (at most 2e-8), and the scores, taken at the least-squares minimum,
#: by its square: what the choice sees is rounding. On the DaISy steamgen record
#: (4 inputs, 4 outputs, orders 11..20 searched) 85 of 182 fold and check fits had
#: conditions 1.1e4..5.5e6 and ran the per-sample QR path (two thirds of the
#: default call).
SCORING_MAX_NORMAL_CONDITION = 1e8
_NORMAL_CONDITION = contextvars.ContextVar("subid_normal_condition",
                                           default=MODAL_MAX_NORMAL_CONDITION)


@contextlib.contextmanager
def scoring_only():
    """Within the block, :func:`solve_normal_equations` (by default) accepts
    equilibrated normal matrices up to :data:`SCORING_MAX_NORMAL_CONDITION` instead of
    :data:`MODAL_MAX_NORMAL_CONDITION`: for fits whose models are scored and dropped
    (:mod:`subid.methods.dt.selection`), never for a model returned. Per thread
    and task (a context variable)."""
    token = _NORMAL_CONDITION.set(SCORING_MAX_NORMAL_CONDITION)
    try:
        yield
    finally:
        _NORMAL_CONDITION.reset(token)


#: |λ|^t below this is rounding: the free signals stop there.
FREE_TOLERANCE = 1e-18
_MODAL_BLOCK = 16384


class ModalForm:
    """Eigen-decomposition of a stable, diagonalisable A for the modal regression.

    Attributes
    ----------
    lam : complex (m,)
        One eigenvalue per real mode or per complex pair (Im > 0).
    is_real : bool (m,)
    coef : complex (ny, m, n)
        ``f_l (C V)_il (V^{-1})_lm`` with ``f_l`` 1 for a real mode, 2 for a pair.
    n_free : int
        Samples after which every ``|λ|^t`` is below :data:`FREE_TOLERANCE`.
    """

    def __init__(self, lam, is_real, coef, n_free):
        self.lam, self.is_real, self.coef, self.n_free = lam, is_real, coef, n_free
        self.widths = np.where(is_real, 1, 2)
        self.offsets = np.concatenate([[0], np.cumsum(self.widths)[:-1]]).astype(np.int64)

    @classmethod
    def of(cls, A, C, max_condition=MODAL_MAX_EIGVEC_CONDITION):
        """The modal form of (A, C), or None when A is unstable, not finite or its
        eigenvector matrix has a condition number above ``max_condition``."""
        A = np.asarray(A, dtype=float)
        if not np.isfinite(A).all():
            return None
        lam, V = scipy.linalg.eig(A, check_finite=False)
        radius = float(np.abs(lam).max()) if lam.size else 0.0
        if radius >= 1.0:
            return None
        cond = np.linalg.cond(V)
        if not np.isfinite(cond) or cond > max_condition:
            return None
        is_real = lam.imag == 0
        upper = lam.imag > 0
        if np.count_nonzero(upper) != np.count_nonzero(lam.imag < 0):
            return None
        keep = is_real | upper
        W = np.linalg.solve(V, np.eye(A.shape[0]))
        factor = np.where(is_real[keep], 1.0, 2.0)
        coef = (C @ V[:, keep])[:, :, None] * W[keep][None, :, :] * factor[None, :, None]
        if radius == 0.0:
            n_free = 1
        else:
            n_free = 1 + int(np.ceil(np.log(FREE_TOLERANCE) / np.log(radius)))
        return cls(lam[keep].astype(complex), is_real[keep].copy(), coef, n_free)

    @property
    def n_state(self):
        return int(self.widths.sum())

    def signal_count(self, n_inputs, n_outputs):
        return self.n_state * (1 + n_inputs) + n_inputs + n_outputs


def modal_signals_reference(lam, is_real, u, y, r, e, tau0, n_free):
    """Plain-numpy reference of :func:`modal_signals`.

    Parameters
    ----------
    lam : complex (m,), is_real : bool (m,)
    u : (T, nu), y : (T, ny) a block of the piece.
    r : complex (m, nu) filter state at the block start (``r_lj`` above).
    e : complex (m,) free signal ``λ^tau0`` at the block start.
    tau0 : int local time of the block start; n_free : int free-signal length.

    Returns
    -------
    w : (T, n (1 + nu) + nu + ny) the real signals (columns), r and e after the block.
    """
    T, nu = u.shape
    ny = y.shape[1]
    widths = np.where(is_real, 1, 2)
    n = int(widths.sum())
    w = np.zeros((T, n * (1 + nu) + nu + ny))
    r = r.copy()
    e = e.copy()
    for t in range(T):
        row = 0
        for l in range(lam.size):
            if tau0 + t < n_free:
                w[t, row] = e[l].real
                if not is_real[l]:
                    w[t, row + 1] = e[l].imag
            row += widths[l]
        for j in range(nu):
            for l in range(lam.size):
                w[t, row] = r[l, j].real
                if not is_real[l]:
                    w[t, row + 1] = r[l, j].imag
                row += widths[l]
        w[t, row:row + nu] = u[t]
        w[t, row + nu:] = y[t]
        if tau0 + t < n_free:
            e = lam * e
        r = lam[:, None] * r + u[t][None, :]
    return w, r, e


@numba.njit(cache=True, nogil=True)
def modal_signals(lam, is_real, u, y, r, e, tau0, n_free):  # pragma: no cover - compiled
    """Compiled kernel: same contract as :func:`modal_signals_reference`."""
    T, nu = u.shape
    ny = y.shape[1]
    m = lam.size
    n = 0
    for l in range(m):
        n += 1 if is_real[l] else 2
    w = np.zeros((T, n * (1 + nu) + nu + ny))
    r = r.copy()
    e = e.copy()
    lr = lam.real.copy()
    li = lam.imag.copy()
    rr = r.real.copy()
    ri = r.imag.copy()
    er = e.real.copy()
    ei = e.imag.copy()
    free_stop = min(max(n_free - tau0, 0), T)
    for t in range(free_stop):
        row = 0
        for l in range(m):
            w[t, row] = er[l]
            a = lr[l] * er[l] - li[l] * ei[l]
            b = lr[l] * ei[l] + li[l] * er[l]
            if is_real[l]:
                row += 1
            else:
                w[t, row + 1] = ei[l]
                row += 2
            er[l] = a
            ei[l] = b
    row0 = n
    for t in range(T):
        row = row0
        for j in range(nu):
            ut = u[t, j]
            for l in range(m):
                a = rr[l, j]
                b = ri[l, j]
                w[t, row] = a
                if is_real[l]:
                    rr[l, j] = lr[l] * a + ut
                    row += 1
                else:
                    w[t, row + 1] = b
                    rr[l, j] = lr[l] * a - li[l] * b + ut
                    ri[l, j] = lr[l] * b + li[l] * a
                    row += 2
        for j in range(nu):
            w[t, row + j] = u[t, j]
        for k in range(ny):
            w[t, row + nu + k] = y[t, k]
    for l in range(m):
        r[l, :] = rr[l, :] + 1j * ri[l, :]
        e[l] = er[l] + 1j * ei[l]
    return w, r, e


def _blocks(form, u, y, block, kernel):
    """The signal blocks ``(start, w)`` of one piece, from a zero filter state."""
    T, nu = u.shape
    r = np.zeros((form.lam.size, nu), dtype=complex)
    e = np.ones(form.lam.size, dtype=complex)
    for start in range(0, T, block):
        stop = min(start + block, T)
        w, r, e = kernel(form.lam, form.is_real, frozen(u[start:stop]), frozen(y[start:stop]),
                         r, e, start, form.n_free)
        yield start, w, r


def piece_moments(form, u, y, *, block=_MODAL_BLOCK, kernel=modal_signals):
    """Moments ``sum_t w w^T`` of one piece, with a zero filter state at its start.

    Returns
    -------
    moments : (d, d) with d = ``form.signal_count(nu, ny)``
    r_end : complex (m, nu) filter state after the piece (its zero-start part)
    """
    nu, ny = u.shape[1], y.shape[1]
    d = form.signal_count(nu, ny)
    n = form.n_state
    moments = np.zeros((d, d))
    r_end = np.zeros((form.lam.size, nu), dtype=complex)
    for start, w, r_end in _blocks(form, u, y, block, kernel):   # noqa: B007 (returned)
        if start < form.n_free:
            moments += w.T @ w
        else:
            tail = w[:, n:]
            moments[n:, n:] += tail.T @ tail
    return moments, r_end


def parameter_count(n, nu, ny, estimate_x0, feedthrough, n_x0=None):
    """``(n_x0, q, p)``: x0 columns, x0 + B columns, all columns (``n_x0``
    overrides the x0 columns, e.g. one x0 per experiment)."""
    nx = (n if n_x0 is None else n_x0) if estimate_x0 else 0
    q = nx + n * nu
    return nx, q, q + (ny * nu if feedthrough else 0)


def regressor_maps(form, n_inputs, n_outputs, *, estimate_x0, feedthrough, t0=0,
                   r_start=None):
    """Rows ``P_i`` with ``[phi_i(t); y_i(t)] = P_i w(t)`` for a piece starting at ``t0``.

    ``w`` are the piece's signals (:func:`piece_moments`, local free signals
    ``λ^(t-t0)``, zero-start filters); ``r_start`` (complex (m, nu)) is the
    global filter state at ``t0`` (zero for the first piece).

    Returns
    -------
    P : (ny, p + 1, d)
    """
    nu, ny = n_inputs, n_outputs
    n = form.n_state
    nx, q, p = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    lam_t0 = form.lam ** t0 if t0 else np.ones_like(form.lam)
    if r_start is None:
        r_start = np.zeros((form.lam.size, nu), dtype=complex)
    P = np.zeros((ny, p + 1, form.signal_count(nu, ny)))
    # every entry is written once (one mode l, input j and state row per column), by
    # blocks: the real part at the mode's column, minus the imaginary part at the next
    # one for a pair
    o, pair = form.offsets, ~form.is_real
    op = o[pair] + 1
    coef = form.coef                                    # (ny, m, n)
    if nx:
        kap = (coef * lam_t0[None, :, None]).transpose(0, 2, 1)     # (ny, n, m)
        P[:, :n, o] = kap.real
        P[:, :n, op] = -kap.imag[:, :, pair]
    ct = coef.transpose(0, 2, 1)                        # (ny, n, m)
    for j in range(nu):
        rows = slice(nx + j * n, nx + (j + 1) * n)
        kap = (coef * r_start[None, :, j, None]).transpose(0, 2, 1)
        P[:, rows, o] = kap.real
        P[:, rows, op] = -kap.imag[:, :, pair]
        P[:, rows, n + j * n + o] = ct.real
        P[:, rows, n + j * n + op] = -ct.imag[:, :, pair]
    base = n * (1 + nu)
    outputs = np.arange(ny)
    if feedthrough:
        for j in range(nu):
            P[outputs, q + j * ny + outputs, base + j] = 1.0
    P[outputs, p, base + nu + outputs] = 1.0
    return P


def next_filter_state(form, r_start, r_zero_end, length):
    """Global filter state after a piece of ``length`` samples that started in
    ``r_start`` and whose zero-start filters ended in ``r_zero_end``."""
    return r_start * (form.lam ** length)[:, None] + r_zero_end


def normal_equations(P, moments, weights):
    """``sum_i weights_i^2 P_i moments P_i^T``: (p + 1, p + 1)."""
    out = np.zeros((P.shape[1], P.shape[1]))
    for i in range(P.shape[0]):
        out += weights[i] ** 2 * (P[i] @ moments @ P[i].T)
    return out


def solve_normal_equations(N, n, nu, ny, *, estimate_x0, feedthrough, n_samples,
                           max_condition=None, n_x0=None, bound_condition=False):
    """B, D, x0 and diagnostics from the (p + 1)-square augmented normal matrix,
    or None when its equilibrated p-square part has a condition number above
    ``max_condition`` (then the QR path must decide; default
    :data:`MODAL_MAX_NORMAL_CONDITION`, :data:`SCORING_MAX_NORMAL_CONDITION` within
    :func:`scoring_only`). ``n_x0`` as in :func:`solve_factor`. ``bound_condition``
    (a model only scored): the condition number is first bounded from the Cholesky
    factor (``||G||_inf ||R^{-1}||_F^2``, a quarter of the cost of the eigenvalues;
    factor, bound and solution in one compiled call,
    :func:`subid.methods.dt._lag_kernel.scored_solve`), the eigenvalues computed only
    when the bound exceeds ``max_condition``: the same decision, the solution equal to
    rounding, ``regression_condition`` then the square root of the bound."""
    if max_condition is None:
        max_condition = _NORMAL_CONDITION.get()
    nx, q, p = parameter_count(n, nu, ny, estimate_x0, feedthrough, n_x0)
    if not np.isfinite(N).all():
        return None
    G, b, yy = N[:p, :p], N[:p, p], N[p, p]
    theta = None
    if bound_condition and p:
        # the Cholesky factor Ge = R^T R of the equilibrated matrix and an upper bound of
        # the condition number, ||Ge||_inf ||R^{-1}||_F^2 >= λ_max / λ_min, in one compiled
        # call (subid.methods.dt._lag_kernel.scored_solve; its LAPACK reference
        # scored_solve_reference): within the limit, the eigenvalues' test would accept
        # too (the same decision; theta from that factor, equal to rounding)
        status, solved, bound = scored_solve(frozen(N), p, float(max_condition))
        if status == 0:
            theta, condition = solved, float(np.sqrt(bound))
    if theta is None:
        diagonal = np.diag(G)
        if (diagonal < 0).any():
            # a normal matrix accumulated from lag products (an online identifier's,
            # subid.methods.bd._accumulated) that lost its positive diagonal to rounding:
            # no Gram matrix of real regressors; the caller takes the other path (its
            # eigenvalues, of a matrix with NaN scales, did not converge: a traceback)
            return None
        scale = np.sqrt(diagonal).copy()
        scale[scale == 0] = 1.0
        Ge = G / scale[:, None] / scale[None, :]
        ev = np.linalg.eigvalsh(Ge) if p else np.ones(1)
        if ev[0] <= 0 or ev[-1] / ev[0] > max_condition:
            return None
        condition = float(np.sqrt(ev[-1] / ev[0]))
        theta = _cholesky_solve(Ge, b / scale) / scale if p else np.zeros(0)
    x0 = theta[:nx] if estimate_x0 else np.zeros(n)
    B = theta[nx:q].reshape(nu, n).T
    D = theta[q:p].reshape(nu, ny).T if feedthrough else np.zeros((ny, nu))
    resid2 = max(yy - theta @ b, 0.0)
    diagnostics = {
        "residual_rms": float(np.sqrt(resid2 / (n_samples * ny))),
        "regression_condition": condition,
        "regression_rank_deficient": False,
        "regression_path": "modal",
    }
    return B, D, x0, theta, diagnostics


def _cholesky_solve(G, rhs, c=None):
    """``scipy.linalg.cho_solve(scipy.linalg.cho_factor(G), rhs)`` for a real ``G``, by
    the same LAPACK calls (``potrf`` of the upper triangle, ``potrs``) without the
    wrappers' checks: the same bits, a third of the time of a candidate's solve.
    ``c``: that ``potrf`` factor, already computed."""
    if c is None:
        c, info = scipy.linalg.lapack.dpotrf(G, lower=0, overwrite_a=0, clean=0)
        if info > 0:
            raise np.linalg.LinAlgError(f"{info}-th leading minor of the array is not "
                                        "positive definite")
    x, info = scipy.linalg.lapack.dpotrs(c, rhs, lower=0, overwrite_b=0)
    if info != 0:
        raise ValueError(f"illegal value in {-info}th argument of internal potrs")
    return x


#: Relative residual (squared) below which the normal equations' residual is
#: rounding and the in-memory path recomputes it sample by sample.
RESIDUAL_RECOMPUTE = 1e-6


def fit_b_d_x0_modal(A, C, u, y, *, feedthrough=True, estimate_x0=True, output_weights=None,
                     block=_MODAL_BLOCK, kernel=modal_signals):
    """The least-squares problem of :func:`fit_b_d_x0_qr` by modal normal equations.

    The regressors are generated as ``n * nu`` scalar recursions in the modal
    basis of A (see the comment above :class:`ModalForm`), and the weighted
    normal equations are accumulated as the moments of those signals. Exact
    in exact arithmetic; in floating point the result agrees with the QR path
    to about ``cond(V) * cond(normal) * eps``, which the guards keep below 1e-6
    (measured ~1e-13 on random stable systems).

    Returns
    -------
    (B, D, x0, diagnostics) as :func:`fit_b_d_x0_qr`, or None when A is
    unstable, its eigenvector matrix has a condition number above
    :data:`MODAL_MAX_EIGVEC_CONDITION`, or the equilibrated normal matrix one
    above :data:`MODAL_MAX_NORMAL_CONDITION`. ``residual_rms`` is recomputed
    sample by sample (one more pass) when the fit is nearly exact, where the
    normal equations' value would be rounding.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    N_samples, nu = u.shape
    ny = y.shape[1]
    form = ModalForm.of(A, C)
    if form is None:
        return None
    weights = np.ones(ny) if output_weights is None else np.asarray(output_weights, float)
    moments, _ = piece_moments(form, u, y, block=block, kernel=kernel)
    P = regressor_maps(form, nu, ny, estimate_x0=estimate_x0, feedthrough=feedthrough)
    N = normal_equations(P, moments, weights)
    solved = solve_normal_equations(N, A.shape[0], nu, ny, estimate_x0=estimate_x0,
                                    feedthrough=feedthrough, n_samples=N_samples)
    if solved is None:
        return None
    B, D, x0, theta, diagnostics = solved
    if diagnostics["residual_rms"] ** 2 * N_samples * ny < RESIDUAL_RECOMPUTE * N[-1, -1]:
        # r_i(t) = (P_i[-1] - theta^T P_i[:-1]) w(t), one row per output
        g = np.stack([weights[i] * (P[i, -1] - theta @ P[i, :-1]) for i in range(ny)])
        total = 0.0
        for _, w, _ in _blocks(form, u, y, block, kernel):
            total += float(np.sum((w @ g.T) ** 2))
        diagnostics["residual_rms"] = float(np.sqrt(total / (N_samples * ny)))
    return B, D, x0, diagnostics
