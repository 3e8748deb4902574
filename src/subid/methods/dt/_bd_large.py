"""The B, D, x0 output regression of :mod:`subid.methods.dt._regression` on large problems.

Two structures of the regressor make the dense problem of the in-memory
engines grow faster than the data; both are *block angular* (Björck,
*Numerical Methods for Least Squares Problems*, SIAM 1996, Sec. 6.3): a few
unknowns shared by every block of rows and, per block, unknowns of its own.

* **Several experiments** (:func:`fit_experiments`): each experiment has its
  own initial state ``x0_e`` (``n`` columns that only its rows touch), B and D
  are shared. Each experiment's rows are reduced alone (its triangular factor,
  or its normal equations), its ``x0_e`` columns eliminated (the rows of the
  factor that hold them are set aside; a Schur complement of the normal
  equations), and the reduced problems in (B, D) are summed. Then
  ``x0_e`` follows from its own block. Time and memory are linear in the number
  of experiments, where the embedded problem ``[x0_1 .. x0_E, B, D]`` was
  quadratic in memory and cubic in time.
* **Many channels** (:func:`fit_channels`): ``D`` has ``ny * nu`` unknowns, and
  row ``i`` of D only enters the rows of output ``i``, through the input
  ``u(t)``; the output-error regressors of the other unknowns are
  ``C S(t)`` for the sensitivity ``S(t)`` of :mod:`subid.methods.dt._regression`.
  The normal equations are accumulated from ``S(t)`` over chunks of samples
  (``sum_t S^T C^T W^2 C S``, ``sum_t S^T C^T W^2 y`` and ``sum_t S (x) u``),
  and the D rows are eliminated output by output through ``sum_t u u^T``
  (the same for every output): memory is bounded by the chunk and by the
  ``(n + n nu)``-square reduced problem, not by ``ny nu`` columns times the
  number of rows. A merged record whose per-experiment blocks would be dense
  (:func:`dense_bytes`) takes the same elimination with one x0 per experiment
  (``(E n + n nu)``-square); beyond :data:`MEMORY_LIMIT`,
  :func:`subid.methods.bd.fit_b_d_x0` raises
  :class:`subid.errors.ResourceLimitError` before allocating.

Both give the least-squares solution of the dense problem (to rounding;
tests/test_bd_large.py compares them with it).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid.methods.dt._regression import (
    _CHUNK,
    _MODAL_BLOCK,
    MODAL_MAX_NORMAL_CONDITION,
    RESIDUAL_RECOMPUTE,
    ModalForm,
    _blocks,
    _qr_append,
    dual_rows,
    modal_signals,
    normal_equations,
    parameter_count,
    piece_moments,
    qr_factor,
    regressor_maps,
    sensitivity_rows,
    solve_factor,
    solve_normal_equations,
)

#: Bytes of the largest dense block the in-memory engines may build
#: (:func:`dense_bytes`); above it :func:`fit_channels` runs instead.
DENSE_LIMIT = 256 * 2 ** 20
#: Bytes of the chunk of sensitivities :func:`fit_channels` holds at a time.
CHUNK_BYTES = 8 * 2 ** 20


#: Bytes the channel elimination (:func:`fit_channels`) may hold; beyond it the
#: B, D, x0 regression is a :class:`subid.errors.ResourceLimitError` before allocating.
MEMORY_LIMIT = 2 ** 30


def dense_bytes(n, nu, ny, n_samples, *, estimate_x0=True, feedthrough=True, n_experiments=1):
    """Bytes of the largest array the in-memory engines build: the modal maps
    (``ny (p + 1) d``), the normal matrix and the rows of a QR chunk; with several
    experiments, the normal matrix or factor that :func:`fit_experiments` keeps for
    each."""
    _, _, p = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    d = n * (1 + nu) + nu + ny
    return 8 * max(ny * (p + 1) * d, max(n_experiments, 1) * (p + 1) ** 2,
                   min(_CHUNK, n_samples) * ny * (p + 1))


# ---------------------------------------------------------------------------
# several experiments: one x0 each, eliminated experiment by experiment
# ---------------------------------------------------------------------------
def fit_experiments(A, C, u, y, starts, *, feedthrough=True, estimate_x0=True,
                    output_weights=None, kernel=None, path="auto"):
    """Least-squares B, D and one x0 per experiment (B and D shared).

    The output of experiment e (samples ``starts[e]`` to the next start) is
    ``y(t) = C A^(t - t_e) x0_e + sum_{t_e <= k < t} C A^(t-1-k) B u(k) + D u(t)``:
    the sensitivity restarts at every experiment. ``path`` as in
    :func:`subid.methods.dt._regression.fit_b_d_x0` (the modal normal equations,
    else the QR factors, each with the x0 columns eliminated per experiment;
    see the module docstring).

    Returns
    -------
    B, D, x0 (shape (n_experiments, n)), diagnostics
        ``regression_condition`` is the largest of the reduced problem's and of
        the experiments' x0 blocks' (each a lower bound of the dense one's).
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    n_samples = u.shape[0]
    ranges = list(zip(starts, list(starts[1:]) + [n_samples]))
    weights = np.ones(y.shape[1]) if output_weights is None else \
        np.asarray(output_weights, float)
    if path != "qr":
        fitted = _experiments_modal(A, C, u, y, ranges, weights, feedthrough=feedthrough,
                                    estimate_x0=estimate_x0)
        if fitted is not None:
            return fitted
        if path == "modal":
            raise ValueError("the modal path does not apply: A is unstable or its eigenvector "
                             "matrix or the normal equations are ill-conditioned")
    return _experiments_qr(A, C, u, y, ranges, output_weights, feedthrough=feedthrough,
                           estimate_x0=estimate_x0,
                           kernel=sensitivity_rows if kernel is None else kernel)


def solve_normal_blocks(blocks, n, nu, ny, *, estimate_x0, feedthrough, n_samples):
    """B, D, x0 from the normal equations of each experiment, or None (then the QR
    path must decide).

    ``blocks[e]`` is the augmented normal matrix of experiment e in the layout
    ``[x0_e; vec B; vec D; y]``. One experiment: solved as it is
    (:func:`subid.methods.dt._regression.solve_normal_equations`). Several: each
    x0 block is eliminated (Schur complement ``N_ss - N_sx N_xx^-1 N_xs``,
    equilibrated Cholesky), the reduced problems summed and solved, then
    ``x0_e = N_xx^-1 (N_xy - N_xs theta)``. None where an equilibrated x0 block
    or the reduced matrix has a condition number above
    :data:`subid.methods.dt._regression.MODAL_MAX_NORMAL_CONDITION` (each is at most
    the dense matrix's).

    Returns
    -------
    B, D, x0, thetas, diagnostics
        ``x0`` of shape (n,) for one experiment, (E, n) for several; ``thetas[e]``
        the parameter vector ``[x0_e; vec B; vec D]`` of experiment e.
    """
    if len(blocks) == 1:
        solved = solve_normal_equations(blocks[0], n, nu, ny, estimate_x0=estimate_x0,
                                        feedthrough=feedthrough, n_samples=n_samples)
        if solved is None:
            return None
        B, D, x0, theta, diagnostics = solved
        return B, D, x0, [theta], diagnostics
    nx, _, _ = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    reduced = 0.0
    eliminated, conditions = [], []
    for N in blocks:
        if not np.isfinite(N).all():
            return None
        if not nx:
            reduced = reduced + N
            continue
        scale = np.sqrt(np.diag(N[:nx, :nx])).copy()
        scale[scale == 0] = 1.0
        Ge = N[:nx, :nx] / scale[:, None] / scale[None, :]
        ev = np.linalg.eigvalsh(Ge)
        if ev[0] <= 0 or ev[-1] / ev[0] > MODAL_MAX_NORMAL_CONDITION:
            return None
        F = scipy.linalg.cho_solve(scipy.linalg.cho_factor(Ge, check_finite=False),
                                   N[:nx, nx:] / scale[:, None],
                                   check_finite=False) / scale[:, None]
        reduced = reduced + (N[nx:, nx:] - N[nx:, :nx] @ F)
        eliminated.append(F)
        conditions.append(float(np.sqrt(ev[-1] / ev[0])))
    solved = solve_normal_equations(reduced, n, nu, ny, estimate_x0=False,
                                    feedthrough=feedthrough, n_samples=n_samples)
    if solved is None:
        return None
    B, D, _, theta, diagnostics = solved
    x0_rows = [F[:, -1] - F[:, :-1] @ theta for F in eliminated]
    x0 = np.stack(x0_rows) if nx else np.zeros((len(blocks), n))
    thetas = [np.concatenate([x, theta]) for x in x0_rows] if nx else [theta] * len(blocks)
    _combine_conditions(diagnostics, conditions, len(blocks))
    return B, D, x0, thetas, diagnostics


def solve_factor_blocks(factors, n, nu, ny, *, estimate_x0, feedthrough, n_samples):
    """B, D, x0 from the triangular factor of each experiment's rows.

    ``factors[e]`` is the factor of experiment e's weighted rows in the layout
    ``[x0_e; vec B; vec D; y]`` (``(p_e + 1)`` columns; None for an overflow).
    The rows of each factor that hold its x0 columns are set aside, the others
    (zero there) accumulated into one factor of ``[vec B; vec D; y]`` by
    sequential QR; theta from it, then ``R_xx x0_e = r_xy - R_xs theta``
    (equilibrated as :func:`subid.methods.dt._regression.solve_factor`). The QR
    of the block-angular stack, without its zeros.

    Returns
    -------
    B, D, x0, diagnostics
        ``x0`` as :func:`solve_normal_blocks`; NaN where a factor overflowed.
    """
    nx, _, p = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    width = p - nx + 1
    R = np.zeros((0, width))
    flat = np.empty(2 * width * width)
    tops = []
    for R_e in factors:
        if R_e is None or not np.isfinite(R_e).all():     # overflowed (an unstable A)
            B, D, _, diagnostics = _nan_fit(n, nu, ny, "qr")
            return B, D, np.full((len(factors), n), np.nan), diagnostics
        if R_e.shape[0] < p + 1:
            R_e = np.vstack([R_e, np.zeros((p + 1 - R_e.shape[0], p + 1))])
        tops.append(R_e[:nx])                 # the rows that hold x0_e: set aside
        R = _qr_append(R, R_e[nx:, nx:], flat)
    B, D, _, theta, diagnostics = solve_factor(R, n, nu, ny, estimate_x0=False,
                                               feedthrough=feedthrough, n_samples=n_samples)
    x0_rows, conditions = [], []
    for top in tops:
        if not nx:
            continue
        Rxx = top[:, :nx]
        rhs = top[:, -1] - top[:, nx:-1] @ theta
        scale = np.linalg.norm(Rxx, axis=0)
        scale[scale == 0] = 1.0
        Rt = Rxx / scale
        rcond = scipy.linalg.lapack.dtrcon(Rt, norm="1", uplo="U", diag="N")[0]
        if rcond < np.finfo(float).eps * nx:
            diagnostics["regression_rank_deficient"] = True
            x0_e = scipy.linalg.lstsq(Rt, rhs, lapack_driver="gelsy", check_finite=False)[0]
        else:
            x0_e = scipy.linalg.solve_triangular(Rt, rhs, check_finite=False)
        x0_rows.append(x0_e / scale)
        conditions.append(float(1.0 / rcond) if rcond > 0 else float("inf"))
    x0 = np.stack(x0_rows) if nx else np.zeros((len(tops), n))
    _combine_conditions(diagnostics, conditions, len(tops))
    return B, D, x0, diagnostics


def _combine_conditions(diagnostics, conditions, n_experiments):
    diagnostics["regression_condition"] = float(max([diagnostics["regression_condition"]]
                                                    + conditions))
    diagnostics["experiments"] = n_experiments


def _experiments_modal(A, C, u, y, ranges, weights, *, feedthrough, estimate_x0):
    n, nu, ny = A.shape[0], u.shape[1], y.shape[1]
    n_samples = u.shape[0]
    form = ModalForm.of(A, C)
    if form is None:
        return None
    P = regressor_maps(form, nu, ny, estimate_x0=estimate_x0, feedthrough=feedthrough)
    blocks = [normal_equations(P, piece_moments(form, u[a:b], y[a:b])[0], weights)
              for a, b in ranges]
    solved = solve_normal_blocks(blocks, n, nu, ny, estimate_x0=estimate_x0,
                                 feedthrough=feedthrough, n_samples=n_samples)
    if solved is None:
        return None
    B, D, x0, thetas, diagnostics = solved
    diagnostics["regression_path"] = "modal"
    if diagnostics["residual_rms"] ** 2 * n_samples * ny < \
            RESIDUAL_RECOMPUTE * sum(N[-1, -1] for N in blocks):
        # nearly exact: the residual sample by sample (the normal equations' is rounding)
        total = 0.0
        for (a, b), th in zip(ranges, thetas):
            g = np.stack([weights[i] * (P[i, -1] - th @ P[i, :-1]) for i in range(ny)])
            for _, w, _ in _blocks(form, u[a:b], y[a:b], _MODAL_BLOCK, modal_signals):
                total += float(np.sum((w @ g.T) ** 2))
        diagnostics["residual_rms"] = float(np.sqrt(total / (n_samples * ny)))
    return B, D, x0, diagnostics


def _experiments_qr(A, C, u, y, ranges, output_weights, *, feedthrough, estimate_x0, kernel):
    n, nu, ny = A.shape[0], u.shape[1], y.shape[1]
    nx, q, _ = parameter_count(n, nu, ny, estimate_x0, feedthrough)

    factors = []
    for a, b in ranges:
        S = np.zeros((n, q))
        if estimate_x0:
            S[:, :n] = np.eye(n)
        R_e = qr_factor(A, C, u[a:b], y[a:b], S, n_x0=nx, feedthrough=feedthrough,
                        output_weights=output_weights, kernel=kernel)[0]
        if not np.isfinite(R_e).all():      # overflowed (an unstable A)
            B, D, _, diagnostics = _nan_fit(n, nu, ny, "qr")
            return B, D, np.full((len(ranges), n), np.nan), diagnostics
        factors.append(R_e)
    B, D, x0, diagnostics = solve_factor_blocks(factors, n, nu, ny, estimate_x0=estimate_x0,
                                                feedthrough=feedthrough, n_samples=u.shape[0])
    diagnostics["regression_path"] = "qr"
    return B, D, x0, diagnostics


# ---------------------------------------------------------------------------
# many channels: the D rows eliminated output by output
# ---------------------------------------------------------------------------
def channel_bytes(n, nu, n_experiments=1, *, estimate_x0=True):
    """Bytes of the largest arrays :func:`fit_channels` holds besides its chunk: the
    normal matrix of ``[x0_1 .. x0_E, vec B]`` and the ``Xi`` array (module docstring)."""
    q = (n_experiments * n if estimate_x0 else 0) + n * nu
    return 8 * (2 * q * q + q * n * nu)


def fit_channels(A, C, u, y, *, starts=None, feedthrough=True, estimate_x0=True,
                 output_weights=None, chunk_bytes=CHUNK_BYTES):
    """The regression of :func:`subid.methods.dt._regression.fit_b_d_x0` with
    memory bounded by ``chunk_bytes`` and the ``(n + n nu)``-square reduced
    problem (see the module docstring).

    With ``theta = [x0; vec B]`` and ``d_i`` the row i of D, the weighted normal
    equations are

        G theta + sum_i w_i^2 X_i d_i = h,    w_i^2 (X_i^T theta + U d_i) = w_i^2 c_i

    with ``G = sum_t S^T C^T W^2 C S``, ``h = sum_t S^T C^T W^2 y``,
    ``X_i = sum_t S^T C_i^T u^T``, ``U = sum_t u u^T`` and ``c_i = sum_t u y_i``.
    Eliminating ``d_i = U^-1 (c_i - X_i^T theta)`` leaves
    ``(G - sum_i w_i^2 X_i U^-1 X_i^T) theta = h - sum_i w_i^2 X_i U^-1 c_i``.
    ``X_i = sum_m C[i, m] Xi_m`` with ``Xi_m = sum_t S[m]^T u^T``, so only the
    ``(n + n nu) x n x nu`` array ``Xi`` is accumulated.

    ``starts`` (the first sample of each experiment of a merged record): the
    sensitivity restarts at every experiment, which has its own x0 (``theta =
    [x0_1 .. x0_E; vec B]``, :func:`channel_bytes`); each experiment's sums are
    added into the rows and columns of its x0 and of B.

    Returns
    -------
    B, D, x0, diagnostics
        As :func:`subid.methods.dt._regression.fit_b_d_x0_qr` (``regression_path``
        ``'channels'``; the condition is that of the equilibrated reduced
        normal matrix's square root); ``x0`` of shape (E, n) with ``starts``.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    A = np.ascontiguousarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    N, nu = u.shape
    n, ny = A.shape[0], y.shape[1]
    ranges = [(0, N)] if starts is None else \
        list(zip(starts, list(starts[1:]) + [N]))
    E = len(ranges)
    w2 = np.ones(ny) if output_weights is None else np.asarray(output_weights, float) ** 2
    nx_e, q_e, _ = parameter_count(n, nu, ny, estimate_x0, False)     # one experiment's
    nx, q, _ = parameter_count(n, nu, ny, estimate_x0, False, n_x0=E * n)
    WC = C * np.sqrt(w2)[:, None]
    # a square root L^T L = C^T W^2 C with min(n, ny) rows
    Lt = WC if ny <= n else np.triu(scipy.linalg.qr(WC, mode="r", check_finite=False)[0][:n])
    CW2 = C.T * w2[None, :]                          # C^T W^2, (n, ny)
    G = np.zeros((q, q), order="F")      # its upper triangle, by rank-k updates (syrk)
    h = np.zeros(q)
    Xi = np.zeros((q * n, nu))
    U = np.zeros((nu, nu))
    c = np.zeros((nu, ny))
    yy = np.zeros(ny)
    step = max(1, int(chunk_bytes // (8 * n * max(q_e, 1) * 2)))
    eye = np.ascontiguousarray(np.eye(n))
    for e, (first, end) in enumerate(ranges):
        # the columns of this experiment's [x0_e; vec B] in theta
        cols = slice(None) if E == 1 else \
            np.concatenate([np.arange(e * nx_e, (e + 1) * nx_e), np.arange(nx, q)])
        Ge = G if E == 1 else np.zeros((q_e, q_e), order="F")
        he = h if E == 1 else np.zeros(q_e)
        Xe = Xi if E == 1 else np.zeros((q_e * n, nu))
        V = np.zeros((n, nu, n))
        M = np.eye(n)
        for start in range(first, end, step):
            stop = min(start + step, end)
            uc = np.ascontiguousarray(u[start:stop])
            yc = y[start:stop]
            with np.errstate(over="ignore", invalid="ignore"):
                S, V, M = dual_rows(A, eye, uc, V, M, nx_e)     # S(t): (T, n, q_e)
            if not np.isfinite(S).all():                        # overflowed (an unstable A)
                return _nan_fit(n, nu, ny, "channels", None if E == 1 else E)
            Z = np.matmul(Lt, S).reshape(-1, q_e)
            Ge = _syrk_update(Ge, Z.T, 1.0)                    # += Z^T Z (upper)
            he += np.einsum("tmq,tm->q", S, yc @ CW2.T)
            Xe += S.transpose(0, 2, 1).reshape(stop - start, q_e * n).T @ uc
            U += uc.T @ uc
            c += uc.T @ yc
            yy += np.einsum("ti,ti->i", yc, yc)
        if E == 1:
            G = Ge
        else:
            G[np.ix_(cols, cols)] += Ge
            h[cols] += he
            Xi.reshape(q, n * nu)[cols] += Xe.reshape(q_e, n * nu)
    yy_total = float(w2 @ yy)
    rhs_y = yy_total
    if feedthrough:
        su = np.sqrt(np.diag(U)).copy()
        su[su == 0] = 1.0
        Ue = U / su[:, None] / su[None, :]
        try:
            Lu = scipy.linalg.cholesky(Ue, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            return _nan_fit(n, nu, ny, "channels", None if E == 1 else E)
        Xi3 = Xi.reshape(q, n, nu)
        # sum_i w_i^2 X_i U^-1 X_i^T = sum_{m,m'} (C^T W^2 C)[m, m'] Xi_m U^-1 Xi_m'^T
        # = sum_k Y_k Y_k^T with Y_k = (sum_m Lt[k, m] Xi_m) U^-1/2: min(n, ny) terms
        # instead of ny (the square root Lt of C^T W^2 C holds the output weights)
        r = Lt.shape[0]
        block = max(1, int(chunk_bytes // (8 * q * nu)))
        for k0 in range(0, r, block):
            k1 = min(k0 + block, r)
            X = np.einsum("qmj,km->kqj", Xi3, Lt[k0:k1]) / su[None, None, :]
            Y = scipy.linalg.solve_triangular(Lu, X.reshape(-1, nu).T, lower=True,
                                              check_finite=False)       # (nu, k q)
            Y = Y.reshape(nu, k1 - k0, q).transpose(2, 1, 0).reshape(q, -1)
            G = _syrk_update(G, Y, -1.0)                                 # -= Y Y^T (upper)
        # sum_i w_i^2 X_i U^-1 c_i = sum_m Xi_m U^-1 (c W^2 C)[:, m]
        cy = scipy.linalg.solve_triangular(Lu, c / su[:, None], lower=True,
                                           check_finite=False)          # (nu, ny)
        g = scipy.linalg.solve_triangular(Lu.T, cy @ (C * w2[:, None]), lower=False,
                                          check_finite=False) / su[:, None]   # (nu, n)
        h -= np.einsum("qmj,jm->q", Xi3, g)
        rhs_y -= float(np.sum(w2 * np.sum(cy * cy, axis=0)))
    G = np.triu(G) + np.triu(G, 1).T
    Naug = np.zeros((q + 1, q + 1))
    Naug[:q, :q] = G
    Naug[:q, q] = Naug[q, :q] = h
    Naug[q, q] = rhs_y
    solved = solve_normal_equations(Naug, n, nu, ny, estimate_x0=estimate_x0, feedthrough=False,
                                    n_samples=N, max_condition=1.0 / (np.finfo(float).eps * q),
                                    n_x0=nx if E > 1 else None)
    deficient = solved is None
    if deficient:
        scale = np.sqrt(np.abs(np.diag(G))).copy()
        scale[scale == 0] = 1.0
        theta = scipy.linalg.lstsq(G / scale[:, None] / scale[None, :], h / scale,
                                   lapack_driver="gelsy", check_finite=False)[0] / scale
        x0 = theta[:nx] if estimate_x0 else np.zeros(n)
        B = theta[nx:q].reshape(nu, n).T
        diagnostics = {"residual_rms": float(np.sqrt(max(rhs_y - theta @ h, 0.0) / (N * ny))),
                       "regression_condition": float("inf")}
    else:
        B, _, x0, theta, diagnostics = solved
    diagnostics.update(regression_rank_deficient=deficient, regression_path="channels")
    if E > 1:
        x0 = x0.reshape(E, n) if estimate_x0 else np.zeros((E, n))
        diagnostics["experiments"] = E
    D = np.zeros((ny, nu))
    if feedthrough:
        # d_i = U^-1 (c_i - X_i^T theta), X_i^T theta = sum_m C[i, m] Xi_m^T theta
        Xt = np.einsum("qmj,q->mj", Xi.reshape(q, n, nu), theta)      # (n, nu)
        D = scipy.linalg.cho_solve((Lu, True), ((c - (C @ Xt).T) / su[:, None]),
                                   check_finite=False).T / su[None, :]
    return B, D, x0, diagnostics


def _syrk_update(G, Y, alpha):
    """``G + alpha Y Y^T`` in the upper triangle of ``G`` (Fortran order, in place where
    BLAS allows): half the flops of the full product."""
    return scipy.linalg.blas.dsyrk(alpha, Y, beta=1.0, c=G, trans=0, lower=0,
                                   overwrite_c=1)


def _nan_fit(n, nu, ny, path, n_experiments=None):
    x0 = np.full(n if n_experiments is None else (n_experiments, n), np.nan)
    return (np.full((n, nu), np.nan), np.full((ny, nu), np.nan), x0,
            {"residual_rms": float("nan"), "regression_condition": float("inf"),
             "regression_rank_deficient": True, "regression_path": path})
