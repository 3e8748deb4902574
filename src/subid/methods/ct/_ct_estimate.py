"""The subspace stages of :func:`subid.ct_subspace` (seed 002): the data-equation
matrices of a known model, the interpolation-correction regressors, the factor
revealing range(O), A and C from it, and B from the filtered data equation (15).

Yu, Chen, Ljung, Verhaegen, CDC 2017; the equations and their corrections are
described in :mod:`subid.methods.ct.ct_subspace` and docs/seed002.md.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from subid.methods.ct import _ct_kernels
from subid.methods.ct.basis import FilterBank
from subid.statistic._hankel import lq_lower


# ---------------------------------------------------------------------------
# data-equation matrices of a known model
# ---------------------------------------------------------------------------
def data_equation_matrices(bank: FilterBank, A, B, C, D=None):
    """``O`` and ``T`` of the compact data equation (6') for a known model.

    Parameters
    ----------
    bank : FilterBank
    A, B, C : array_like
    D : array_like, optional

    Returns
    -------
    O : ndarray, shape (N p, n)
    T : ndarray, shape (N p, N m)
        ``y_f(t) = O x(t) + T u_f(t)`` for filters at rest and ``x(t_0) = 0``.
    """
    A, B, C = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, C))
    N = bank.n_functions
    n = A.shape[0]
    _, g = bank.realization()
    S = bank.sylvester_matrix(A)
    IC = np.kron(np.eye(N), C)
    O = IC @ np.linalg.solve(S, np.kron(g[:, None], np.eye(n)))
    T = -IC @ np.linalg.solve(S, np.kron(np.eye(N), B))
    if D is not None:
        T = T + np.kron(np.eye(N), np.atleast_2d(np.asarray(D, dtype=float)))
    return O, T


def observability_matrix(bank: FilterBank, A, C):
    """Extended observability matrix ``O`` of (6'); eq. (10) for real poles."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    return data_equation_matrices(bank, A, np.zeros((A.shape[0], 1)), C)[0]


def tm_convolution_matrix(A, B, C, poles):
    """Convolution matrix ``T`` of the paper's data equation (6), corrected.

    From ``y_i = C (x_i - x_{i+1}) / sqrt(2 sigma_i)`` (proof of Lemma 2) and
    the expansion (5) of ``x_i``, the coefficient of ``[psi_{l,j+1} M_j u]``
    in ``y_i`` is, for ``i >= j``,

        Gamma_j / sqrt(2 sigma_i) * ([l = i - 1] - [l = i]),
        Gamma_j = C Phi(j-1, 0) B_j = sqrt(2 sigma_j) C Phi(j-1, 0) (A + sigma_j I)^{-1} B,

    and zero for ``i < j``. So block column ``T_j`` has ``j`` leading zero
    block rows (the printed ``T_i`` has one), every block row ``i`` carries
    ``1/sqrt(2 sigma_i)`` (missing in print), and the diagonal blocks are
    ``-Gamma_j/sqrt(2 sigma_j)``; for ``j = 0`` that is
    ``C (A + sigma_0 I)^{-1} B = -D_0``, so the printed ``T_0`` (``-D_0`` on
    the diagonal, ``+D_0`` below) has the wrong sign.

    Parameters
    ----------
    A, B, C : array_like
    poles : sequence of float
        Real TM poles ``sigma_0 .. sigma_{N-1}``.

    Returns
    -------
    ndarray, shape (N p, m N (N + 1) / 2)
        Columns in the order of :meth:`FilterBank.paper_input_stack`.
    """
    A, B, C = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, C))
    sig = np.asarray(poles, dtype=float).reshape(-1)
    N, n, p, m = sig.size, A.shape[0], C.shape[0], B.shape[1]
    eye = np.eye(n)
    Phi = eye
    gam = []
    for j in range(N):
        gam.append(np.sqrt(2 * sig[j]) * C @ Phi @ np.linalg.solve(A + sig[j] * eye, B))
        Phi = Phi @ np.linalg.solve(A + sig[j] * eye, A - sig[j] * eye)
    blocks = []
    for j in range(N):
        Tj = np.zeros((N * p, (N - j) * m))
        for i in range(j, N):
            rows = slice(i * p, (i + 1) * p)
            col = i - j
            Tj[rows, col * m:(col + 1) * m] -= gam[j] / np.sqrt(2 * sig[i])
            if i > j:
                Tj[rows, (col - 1) * m:col * m] += gam[j] / np.sqrt(2 * sig[i])
        blocks.append(Tj)
    return np.hstack(blocks)


# ---------------------------------------------------------------------------
# regressors
# ---------------------------------------------------------------------------
def _correction_count(poly_order: int, input_order: int, feedthrough: bool):
    """Orders ``i`` of the correction filters ``H_i``: ``range(i0, j + 1)``."""
    j = poly_order - (1 if input_order >= 1 else 0)
    i0 = 0 if (feedthrough and input_order != poly_order) else 1
    return i0, j


def _correction_regressors(bank: FilterBank, t, u, poly_order, input_order, feedthrough,
                           filtering, uniform, out=None):
    """Filtered interpolation errors of ``H_i u`` (beyond the paper).

    ``y = G u`` with ``G(s) = D + CB/s + CAB/s^2 + ...``. An input
    interpolated continuously between samples (``input_order >= 1``) has jumps
    in its first derivative, so ``H_i u`` with ``H_i(s) = (a/(s + a))^i`` has
    jumps in derivative ``i + 1``; a held input (order 0) has jumps in value,
    giving derivative ``i``. A degree-p interpolating polynomial is accurate to
    ``O(h^{p+1})`` only for signals whose first p derivatives are continuous,
    and ``y - D u - sum_{i<=j} c_i H_i u`` (suitable ``c_i``, matching the
    Markov parameters) is such a signal for ``j = p - [input_order >= 1]``.
    The filtered interpolation error of ``y`` is therefore
    ``sum_i c_i e_i + O(h^{p+1})`` with the known signals
    ``e_i = F[H_i u] - F[P_p H_i u]`` (exact filtering minus filtering of the
    interpolated samples), and the ``O(h^{p+1})`` part, proportional to a
    derivative of ``y``, only perturbs ``O`` and ``T``. The ``e_i`` (``N m``
    columns each) are regressors with free coefficients. ``i = 0`` (the
    input's own interpolation error) is included with a feedthrough when the
    input is not interpolated like the output.

    ``a`` is the slowest basis pole: the remainder must be smooth on the
    scale of the sampling step (``a h << 1``), else its own interpolation
    error is not small (with ``a h = 0.1`` jittered records fail). The price:
    the regressors then carry slow, state-like components, and projecting
    them out costs variance under noise (docs/seed002.md, ablation).

    Parameters
    ----------
    out : ndarray, shape (L, k), optional
        Where to write the regressors (a block of the caller's data matrix: no
        intermediate copies of the record).

    Returns
    -------
    ndarray, shape (L, k)
        ``out`` when given.
    """
    L, m = u.shape
    i0, j = _correction_count(poly_order, input_order, feedthrough)
    if j < i0:
        return np.zeros((L, 0)) if out is None else out
    F, g = bank.realization()
    N = F.shape[0]
    if out is None:
        out = np.empty((L, (j - i0 + 1) * N * m))
    col = 0

    def put(exact, approx):             # exact - approx into the next N m columns
        nonlocal col
        block = out[:, col:col + N * m].view()
        block.shape = (L, N, m)         # a view (raises rather than copy)
        np.subtract(exact, approx, out=block)
        col += N * m

    if i0 == 0:
        put(_ct_kernels.run_bank(F, g, t, u, input_order, uniform=uniform),
            bank.filter(u, t, poly_order=poly_order, chain=filtering))
    k = j
    if k >= 1:
        Fa, Ga = _poisson_chain_bank(bank, k)
        Z = _ct_kernels.run_bank(Fa, Ga, t, u, input_order, uniform=uniform)   # (L, size, m)
        for i in range(k):
            put(Z[:, k + i * N:k + (i + 1) * N, :],
                bank.filter(Z[:, i, :], t, poly_order=poly_order, chain=filtering))
    return out


def _poisson_chain_bank(bank, k: int):
    """``(Fa, Ga)``: the system of the correction regressors of
    :func:`_correction_regressors`, a Poisson chain ``h_1 .. h_k`` of the
    slowest basis pole ``a``, each stage feeding a copy of the bank.

    State ``[h_1 .. h_k, bank_1 .. bank_k]``; its matrix is defective (a
    Jordan chain at ``a``) with every bank pole repeated ``k`` times.
    """
    F, g = bank.realization()
    N = F.shape[0]
    a = min(abs(z.real) for z in bank.poles)
    size = k + k * N
    Fa = np.zeros((size, size))
    Ga = np.zeros(size)
    Ga[0] = a
    for i in range(k):
        Fa[i, i] = -a
        if i:
            Fa[i, i - 1] = a
        blk = slice(k + i * N, k + (i + 1) * N)
        Fa[blk, i] = g
        Fa[blk, blk] = F
    return Fa, Ga


#: Rows per block of :func:`column_rms` (the working memory beside the record's matrices).
BLOCK_ROWS = 8192


def column_rms(parts):
    """``sqrt(mean(M ** 2, axis=0))`` of ``M = hstack(parts)``, bit for bit, without
    forming ``M`` or its square (each as large as the record's filtered signals): the
    column scaling of the LQ factorisation of step 1 (Lemma 3, eq. (8)) and of
    :func:`range_basis`.

    Parameters
    ----------
    parts : list of ndarray, shapes (L, k_i)
        The column blocks of ``M``.

    Returns
    -------
    ndarray, shape (sum k_i,)

    NumPy sums a row-major matrix down its columns one row after the other (a
    reduction across the rows, not along the contiguous axis, so not pairwise):
    blocks of :data:`BLOCK_ROWS` rows added to the running sums, which lead each
    block, give the same sums (``tests/test_ct_fast_paths.py``).
    """
    L = parts[0].shape[0]
    k = sum(P.shape[1] for P in parts)
    if k < 2 or L <= BLOCK_ROWS or all(P.flags.f_contiguous for P in parts):
        # column-major (NumPy joins column-major parts so) or a single column: summed
        # along the contiguous axis, pairwise; as it is
        return np.sqrt(np.mean(np.hstack(parts) ** 2, axis=0))
    total = np.zeros((1, k))
    for a in range(0, L, BLOCK_ROWS):
        square = np.hstack([P[a:a + BLOCK_ROWS] for P in parts]) ** 2
        total = np.add.reduce(np.vstack([total, square]), axis=0, keepdims=True)
    return np.sqrt(total[0] / L)


def _scaled_copy(parts, scale):
    """``hstack(parts) / scale`` in one column-major array (what LAPACK factorises in
    place, :func:`_subspace_factor`, :func:`householder_q`), written part by part: the
    same quotients as the joined matrix's."""
    work = np.empty((parts[0].shape[0], scale.size), order="F")
    col = 0
    for P in parts:
        w = P.shape[1]
        np.divide(P, scale[col:col + w], out=work[:, col:col + w])
        col += w
    return work


def _subspace_factor(R, Z, Y):
    """LQ factor of the signals ``[R, Z, Y]`` (columns) and the block revealing range(O).

    Returns the factor ``Lf`` (``[R Z Y]^T = Lf Q``) and ``W``: the block of
    ``Y`` on the instrument directions (``Y Pi_R^perp Z^T`` up to a right
    factor) when ``Z`` is given, else on its own directions (``Y Pi_R^perp``).
    The columns are scaled to unit RMS (:func:`column_rms`) into one column-major
    array that the Householder QR overwrites: besides the signals, one copy of
    them, not three (``[R Z Y]``, its scaled copy and LAPACK's column-major copy).
    """
    parts = [R, Y] if Z is None else [R, Z, Y]
    scale = column_rms(parts)
    scale[scale == 0] = 1.0
    work = _scaled_copy(parts, scale)
    Lf = lq_lower(work.T, overwrite=True) * scale[:, None]
    del work
    nR = R.shape[1]
    nZ = 0 if Z is None else Z.shape[1]
    iY = slice(nR + nZ, scale.size)
    W = Lf[iY, nR:nR + nZ] if nZ else Lf[iY, iY]
    return Lf, W


def householder_q(work):
    """``numpy.linalg.qr(work)`` (the thin Q and the triangular factor) by the same
    LAPACK routines (``geqrf``, then ``orgqr``), ``work`` (column-major, at least as
    many rows as columns) overwritten by Q: no copies of it (``numpy.linalg.qr`` makes
    three and returns a fourth). The Q of :func:`range_basis` (the directions of the
    regressors that step 1, Lemma 3, projects out).

    Returns
    -------
    Q : ndarray, shape (m, n)
        Column-major (``work`` itself) on the LAPACK route.
    T : ndarray, shape (n, n)
    """
    m, n = work.shape
    if n == 0 or m < n or not work.flags.f_contiguous:
        return np.linalg.qr(work)
    geqrf, orgqr = scipy.linalg.get_lapack_funcs(("geqrf", "orgqr"), (work,))
    lwork = int(geqrf(work, lwork=-1, overwrite_a=1)[-2][0].real)
    qr, tau, _, info = geqrf(work, lwork=lwork, overwrite_a=1)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of the internal LAPACK geqrf")
    T = np.triu(qr[:n])
    lwork = int(orgqr(qr, tau, lwork=-1, overwrite_a=1)[1][0].real)
    Q, _, info = orgqr(qr, tau, lwork=lwork, overwrite_a=1)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of the internal LAPACK orgqr")
    return Q, T


#: Smallest diagonal entry, relative to the instrument's norm, of the triangular factor of
#: the instruments with the regressors' directions removed, for which
#: :func:`instrument_block` works by projection; below it, :func:`_subspace_factor`.
PROJECTION_TOL = 1e-8


#: Smallest diagonal entry, relative to the largest, of the triangular factor of the
#: column-scaled regressors for which :func:`range_basis` gives a basis: below it a
#: direction is rounding, not data, and which one the reflectors take depends on the
#: order of the operations (the whole factor is then used, as before).
RANGE_TOL = 1e-13


def range_basis(R):
    """The thin Q of the Householder QR of the column-scaled ``R``: the directions the
    first ``n_R`` reflectors of the factor of ``[R Z Y]`` remove from ``Z`` and ``Y``
    (the same reflectors: they depend on the columns of ``R`` alone), also where ``R``
    is ill conditioned (the filtered regressors of the default basis have diagonal
    entries down to 5e-10 of the largest). None when it is not finite or numerically
    rank deficient (:data:`RANGE_TOL`).

    The QR overwrites one scaled copy of ``R`` (:func:`householder_q`; bit for bit
    ``numpy.linalg.qr(R / scale)``), and ``R`` is let go as soon as it is copied: a
    caller that passes its only reference (:meth:`subid.methods.ct._ct_problem.Problem.
    take_regressors`) holds at most two arrays of its size at once (the factor and Q
    copied in row-major order, the order of the products that use it, whose rounding
    BLAS may make depend on it).
    """
    scale = column_rms([R])
    scale[scale == 0] = 1.0
    work = _scaled_copy([R], scale)
    del R
    Q, T = householder_q(work)
    del work
    diag = np.abs(np.diag(T))
    ok = np.isfinite(Q).all() and diag.size and diag.min() > RANGE_TOL * diag.max()
    return np.ascontiguousarray(Q) if ok else None


def instrument_block(basis, Z, Y):
    """``W`` of :func:`_subspace_factor` ``(R, Z, Y)`` (``Z`` given) from ``basis``
    (:func:`range_basis` of ``R``), without the factor of the whole ``[R Z Y]``.

    With ``[R Z Y]^T = L Q`` (diagonal of ``L`` non-negative), the block of ``L`` in the
    rows of ``Y`` and the columns of ``Z`` is ``Y^T Q_Z``, ``Q_Z`` the orthonormal
    directions of ``Z`` with those of ``R`` removed (``(I - P_R) Z = Q_Z T``, ``T``
    upper triangular with a positive diagonal): the channels' scaling drops out. So two
    projections on ``basis`` (the second removes what rounding left of the first) and the
    QR of the ``N x n`` remainder replace the QR of the ``N x (n_R + n + n_Y)`` matrix
    (56 + n + 16 columns for the default basis of a 2 x 2 record: about 9 times fewer
    flops per model-instrument iteration). None when the remainder's columns are
    numerically dependent (:data:`PROJECTION_TOL`): the caller then factors the whole."""
    Zp = Z - basis @ (basis.T @ Z)
    Zp -= basis @ (basis.T @ Zp)
    Q, T = np.linalg.qr(Zp)
    diag = np.diag(T)
    norms = np.sqrt(np.mean(Z ** 2, axis=0)) * math.sqrt(Z.shape[0])
    if not (np.isfinite(diag).all() and np.all(np.abs(diag) > PROJECTION_TOL * norms)):
        return None
    return Y.T @ (Q * np.where(diag < 0, -1.0, 1.0))


# ---------------------------------------------------------------------------
# A, C
# ---------------------------------------------------------------------------
def _estimate_a_c(bank: FilterBank, Theta, p, ac_method):
    """A and C from ``O_k A = sum_j F_kj O_j + g_k C`` (k = 0..N-1)."""
    F, g = bank.realization()
    N = F.shape[0]
    n = Theta.shape[1]
    blocks = Theta.reshape(N, p, n)
    rhs = np.einsum("kj,jpn->kpn", F, blocks)
    if ac_method == "joint":
        reg = np.zeros((N, p, n + p))
        reg[:, :, :n] = blocks
        reg[:, :, n:] = -g[:, None, None] * np.eye(p)[None]
        reg = reg.reshape(N * p, n + p)
        sol = scipy.linalg.lstsq(reg, rhs.reshape(N * p, n), lapack_driver="gelsy",
                                 check_finite=False)[0]
        resid = reg @ sol - rhs.reshape(N * p, n)
        return sol[:n], sol[n:], float(np.linalg.norm(resid)
                                       / max(float(np.linalg.norm(rhs)), 1e-300))
    # the paper: C eliminated between consecutive equations with g_k != 0 (for real
    # poles these rows are exactly M and R of (12)); the equations with g_k = 0
    # (second state of a complex pair) contain no C and are kept as they are
    live = np.flatnonzero(np.abs(g) > 0)
    lhs_rows = [blocks[a] / g[a] - blocks[b] / g[b] for a, b in zip(live[:-1], live[1:])]
    rhs_rows = [rhs[a] / g[a] - rhs[b] / g[b] for a, b in zip(live[:-1], live[1:])]
    for k in np.flatnonzero(g == 0):
        lhs_rows.append(blocks[k])
        rhs_rows.append(rhs[k])
    Mm = np.vstack(lhs_rows)
    Rm = np.vstack(rhs_rows)
    A = scipy.linalg.lstsq(Mm, Rm, lapack_driver="gelsy", check_finite=False)[0]  # (13)
    k0 = live[0]
    C = (blocks[k0] @ A - rhs[k0]) / g[k0]        # (14): O_0 (A + sigma_0 I) / sqrt(2 sigma_0)
    resid = np.linalg.norm(Mm @ A - Rm) / max(float(np.linalg.norm(Rm)), 1e-300)
    return A, C, float(resid)




# ---------------------------------------------------------------------------
# B from the filtered data equation, instruments
# ---------------------------------------------------------------------------
def _fit_b_filtered(Tfun, Theta, Lf, iU, n, m, p, feedthrough):
    """Eq. (15): ``min ||Y - Theta X - T(B) U - (other regressors)||`` over X, B (, D).

    With the factor ``[phi; U; ...; Y]^T = L Q`` the regressors before ``U``
    only touch the columns before ``U``'s own, those after it the columns
    after; so only the block ``L_YU`` (``Y`` on ``U``'s own directions) depends
    on B, and ``Theta^perp`` (an orthonormal basis of range(Theta)'s
    complement) removes the free state sequence: minimise
    ``||Theta^perp^T (L_YU - T(B) L_UU)||_F``, linear in B (and D).
    """
    nY = Theta.shape[0]
    Qp = scipy.linalg.qr(Theta, mode="full", check_finite=False)[0][:, n:]
    LUU = Lf[iU, iU]
    LYU = Lf[Lf.shape[0] - nY:, iU]
    target = (Qp.T @ LYU).reshape(-1)
    T0 = Tfun(np.zeros((n, m)), None)
    cols = []
    for a in range(n):
        for j in range(m):
            Bm = np.zeros((n, m))
            Bm[a, j] = 1.0
            cols.append((Qp.T @ (Tfun(Bm, None) - T0) @ LUU).reshape(-1))
    if feedthrough:
        for i in range(p):
            for j in range(m):
                Dm = np.zeros((p, m))
                Dm[i, j] = 1.0
                cols.append((Qp.T @ (Tfun(np.zeros((n, m)), Dm) - T0) @ LUU).reshape(-1))
    R = np.column_stack(cols)
    theta, _, _, sing = scipy.linalg.lstsq(R, target, lapack_driver="gelsd",
                                           check_finite=False)
    B = theta[:n * m].reshape(n, m)
    D = theta[n * m:].reshape(p, m) if feedthrough else np.zeros((p, m))
    cond = float(sing[0] / sing[-1]) if sing[-1] > 0 else float("inf")
    resid = np.linalg.norm(R @ theta - target) / max(float(np.linalg.norm(target)), 1e-300)
    return B, D, {"b_residual_relative": float(resid), "b_regression_condition": cond}



def _markov_change(old, new):
    """Relative change of ``C A^k B`` (k = 0..n): invariant to the state basis."""
    (Ao, Bo, Co), (An, Bn, Cn) = old, new
    worst = 0.0
    Po, Pn = Bo, Bn
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(Ao.shape[0] + 1):
            mo, mn = Co @ Po, Cn @ Pn
            change = np.linalg.norm(mo - mn) / max(float(np.linalg.norm(mo)), 1e-300)
            worst = max(worst, float(change) if np.isfinite(change) else math.inf)
            Po, Pn = Ao @ Po, An @ Pn
    return worst
