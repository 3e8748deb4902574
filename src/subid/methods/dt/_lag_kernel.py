"""Compiled kernels of the lag-product fit and score of a candidate model.

:mod:`subid.methods.dt._lag_fit` reduces the B, D, x0 regression of a candidate
``(A, C)`` on a training fold, and the error power of its simulation on a
validation block, to lag sequences evaluated at the poles of A: with
``A = V diag(λ) V^{-1}``, ``sum_e c_e A^e = V diag(sum_e c_e λ^e) V^{-1}``. In
numpy each candidate took about 40 calls on matrices of a few rows (the poles
of an order-10 model, two channels), whose dispatch cost more than their
arithmetic (issue 21: 77 % of the default call went to the candidates of the
cross-validation). Here the same sums run as one compiled call per step:

* :func:`modal_form`: the eigenvector matrix's inverse and condition number (the
  guard of ``_lag_fit.MAX_EIGVEC_CONDITION``), the lags L with ``ρ(A)^L`` below
  ``_lag_fit.LAG_TOLERANCE``; :func:`powers`, ``λ^e`` (e = 0..L) by doubling;
* :func:`normal_matrix`: the augmented normal matrix ``[[N, b], [b^T, y^T W^2 y]]``
  of the weighted regression ``[x0; vec B; vec D]`` (the equations of the
  :mod:`subid.methods.dt._lag_fit` documentation, training fold);
* :func:`error_power`: ``sum_t (y - ŷ)^2`` per output with the least-squares x0
  (validation score, same documentation).

Each computes exactly the sums of the numpy reference implementation beside it
(:func:`normal_matrix_reference`, :func:`error_power_reference`, the code these
kernels replace); ``tests/test_lag_fit.py`` compares them to rounding. The
lag sequences are passed flattened to two dimensions, ``(lags, entries)``.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def powers(lam, L):  # pragma: no cover - compiled
    """``λ^e`` for e = 0..L as its real and imaginary parts, two (n, L + 1) arrays, by
    doubling: the columns ``[filled, 2 filled)`` are the first ``filled`` times
    ``λ^filled`` (``log2 L`` roundings deep instead of L)."""
    n = lam.shape[0]
    vre = np.empty((n, L + 1))
    vim = np.empty((n, L + 1))
    for i in range(n):
        vre[i, 0] = 1.0
        vim[i, 0] = 0.0
        filled = 1
        sr, si = lam[i].real, lam[i].imag               # λ^filled
        while filled < L + 1:
            k = min(filled, L + 1 - filled)
            for j in range(k):
                a, b = vre[i, j], vim[i, j]
                vre[i, filled + j] = a * sr - b * si
                vim[i, filled + j] = a * si + b * sr
            filled += k
            a, b = vre[i, filled - 1], vim[i, filled - 1]
            sr, si = a * lam[i].real - b * lam[i].imag, a * lam[i].imag + b * lam[i].real
    return vre, vim


@numba.njit(cache=True, nogil=True)
def modal_form(lam, V, lag_tolerance, max_condition):  # pragma: no cover - compiled
    """``(status, L, Wm)`` of the modal form of an A with eigenvalues ``lam`` and
    eigenvectors ``V``: ``status`` 0 when it applies, 1 unstable, 3 eigenvectors
    ill-conditioned (2-norm condition number above ``max_condition``, or singular);
    ``L`` the smallest lag with ``ρ(A)^L`` below ``lag_tolerance`` (at least 1, at
    most 2^40), ``Wm = V^{-1}``."""
    n = lam.shape[0]
    empty_w = np.empty((0, 0), dtype=np.complex128)
    radius = 0.0
    for i in range(n):
        radius = max(radius, abs(lam[i]))
    if radius >= 1.0:
        return 1, 0, empty_w
    L = 1
    if radius > 0.0:
        L = int(max(min(math.ceil(math.log(lag_tolerance) / math.log(radius)), 2.0 ** 40), 1.0))
    cond = np.linalg.cond(V)
    if not (cond <= max_condition):
        return 3, L, empty_w
    return 0, L, np.linalg.solve(V, np.eye(n, dtype=np.complex128))


@numba.njit(cache=True, nogil=True)
def _sums(vand_re, vand_im, G, R, u_tail, u_head, y_head):  # pragma: no cover - compiled
    """Every lag sequence at the poles, ``sum_e s(e) λ^e`` (e = 0..L), as two matrix
    products of the powers (real and imaginary parts) with the sequences side by side
    (zero-padded to L + 1 terms): ``(g, g1, rho, xt, mu, eta)`` (n, entries) complex, the
    sums of ``Γ(e)``, ``Γ(e + 1)``, ``R(e + 1)``, ``u(N - 1 - e)``, ``u(e)`` and ``y(e)``."""
    L = vand_re.shape[1] - 1
    n = vand_re.shape[0]
    kg, kr, nu, ny = G.shape[1], R.shape[1], u_tail.shape[1], y_head.shape[1]
    widths = (kg, kg, kr, nu, nu, ny)
    K = 2 * kg + kr + 2 * nu + ny
    M = np.zeros((L + 1, K))
    for e in range(L + 1):
        for c in range(kg):
            M[e, c] = G[e, c]
        for c in range(nu):
            M[e, 2 * kg + kr + c] = u_tail[e, c]
            M[e, 2 * kg + kr + nu + c] = u_head[e, c]
        for c in range(ny):
            M[e, 2 * kg + kr + 2 * nu + c] = y_head[e, c]
    for e in range(L):
        for c in range(kg):
            M[e, kg + c] = G[e + 1, c]
        for c in range(kr):
            M[e, 2 * kg + c] = R[e + 1, c]
    re = vand_re @ M
    im = vand_im @ M
    out = np.empty((n, K), dtype=np.complex128)
    for i in range(n):
        for c in range(K):
            out[i, c] = re[i, c] + 1j * im[i, c]
    a = 0
    parts = []
    for k in widths:
        parts.append(np.ascontiguousarray(out[:, a:a + k]))
        a += k
    return parts[0], parts[1], parts[2], parts[3], parts[4], parts[5]


@numba.njit(cache=True, nogil=True)
def _power_n(V, Wm, lam, vand_re, vand_im, n_samples):  # pragma: no cover - compiled
    """``A^N`` (real), ``V diag(λ^N) V^{-1}`` with ``λ^N = λ^L λ^(N - L)``."""
    L = vand_re.shape[1] - 1
    n = lam.shape[0]
    lamN = np.empty(n, dtype=np.complex128)
    for i in range(n):
        lamN[i] = (vand_re[i, L] + 1j * vand_im[i, L]) * lam[i] ** (n_samples - L)
    return _matrix(V, Wm, lamN)


@numba.njit(cache=True, nogil=True)
def _re(M):  # pragma: no cover - compiled
    """The real part of a complex matrix, contiguous."""
    out = np.empty(M.shape)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            out[i, j] = M[i, j].real
    return out


@numba.njit(cache=True, nogil=True)
def _c(M):  # pragma: no cover - compiled
    """A real matrix as a contiguous complex one."""
    out = np.empty(M.shape, dtype=np.complex128)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            out[i, j] = M[i, j]
    return out


@numba.njit(cache=True, nogil=True)
def _matrix(V, Wm, values):  # pragma: no cover - compiled
    """``Re(V diag(values) V^{-1})`` (n, n)."""
    n = V.shape[0]
    Vd = np.empty((n, n), dtype=np.complex128)
    for i in range(n):
        for j in range(n):
            Vd[i, j] = V[i, j] * values[j]
    return _re(Vd @ Wm)


@numba.njit(cache=True, nogil=True)
def _gramian(lam, Wm, left):  # pragma: no cover - compiled
    """``Re(V^{-T} [left_i left_j / (1 - λ_i λ_j)] V^{-1})`` for ``left = V^T c^T``
    (n, k): ``sum_t (A^t)^T c^T c A^t``."""
    n = lam.shape[0]
    M = left @ np.ascontiguousarray(left.T)
    for i in range(n):
        for j in range(n):
            M[i, j] /= 1.0 - lam[i] * lam[j]
    return _re(np.ascontiguousarray(Wm.T) @ M @ Wm)


@numba.njit(cache=True, nogil=True)
def normal_matrix(lam, V, Wm, vand_re, vand_im, G, R, Y_diag, u_tail, u_head, y_head,
                  n_samples, C, w, feedthrough, estimate_x0):  # pragma: no cover - compiled
    """The augmented normal matrix (p + 1, p + 1) of the weighted regression of
    :func:`subid.methods.dt._lag_fit.fit_b_d_x0` (module documentation there):
    ``G`` (L + 1, nu nu) and ``R`` (L + 1, ny nu) the lag products ``Γ(e)`` and
    ``R(k)`` flattened, ``Y_diag`` the diagonal of ``y^T y``, ``u_tail`` the last L + 1
    inputs in reverse order, ``u_head`` and ``y_head`` the first L + 1 samples (L < N,
    ``n_samples``), ``w`` the output weights."""
    n = lam.shape[0]
    ny = C.shape[0]
    nu = u_tail.shape[1]
    w2 = w * w
    nx = n if estimate_x0 else 0
    q = nx + n * nu
    p = q + (nu * ny if feedthrough else 0)
    Naug = np.zeros((p + 1, p + 1))
    Vt = np.ascontiguousarray(V.T)
    WmT = np.ascontiguousarray(Wm.T)
    CW2 = np.empty((n, ny))                          # C^T W^2
    Cw = np.empty((n, ny))                           # C^T W
    for j in range(n):
        for r in range(ny):
            CW2[j, r] = C[r, j] * w2[r]
            Cw[j, r] = C[r, j] * w[r]
    P = _gramian(lam, Wm, Vt @ _c(Cw))               # sum_t (A^t)^T C^T W^2 C A^t
    P = 0.5 * (P + np.ascontiguousarray(P.T))
    gz, gz1, rho, xt, s0, eta = _sums(vand_re, vand_im, G, R, u_tail, u_head, y_head)
    # BB[a, :, b, :] = Z[a, b]^T P + P (Z[b, a] - Γ(0)_ba I), Z[a, b] = sum_e Γ(e)_ab A^e
    Z = np.empty((nu, nu, n, n))
    for a in range(nu):
        for b in range(nu):
            Z[a, b] = _matrix(V, Wm, np.ascontiguousarray(gz[:, a * nu + b]))
    for a in range(nu):
        for b in range(nu):
            blk = np.ascontiguousarray(Z[a, b].T) @ P + P @ Z[b, a]
            for i in range(n):
                for j in range(n):
                    Naug[nx + a * n + i, nx + b * n + j] = blk[i, j] - P[i, j] * G[0, b * nu + a]
    # minus X(N)^T P X(N), X(N) = [sum_k u_a(N-k) A^(k-1)]_a
    XN = np.empty((n, nu * n))
    for a in range(nu):
        XN[:, a * n:(a + 1) * n] = _matrix(V, Wm, np.ascontiguousarray(xt[:, a]))
    XPX = np.ascontiguousarray(XN.T) @ P @ XN
    for i in range(nu * n):
        for j in range(nu * n):
            Naug[nx + i, nx + j] -= XPX[i, j]
    # rB[a n + i] = (V^{-T} sum_r (V^T C^T W^2)_lr ρ_lra)_ia, ρ = sum_k R(k) λ^(k-1)
    VtCW2 = Vt @ _c(CW2)                             # (n, ny)
    modal = np.zeros((n, nu), dtype=np.complex128)
    for i in range(n):
        for a in range(nu):
            for r in range(ny):
                modal[i, a] += VtCW2[i, r] * rho[i, r * nu + a]
    back = _re(WmT @ modal)                          # (i, a)
    for a in range(nu):
        for i in range(n):
            Naug[nx + a * n + i, p] = back[i, a]
    s = 0.0
    for r in range(ny):
        s += w2[r] * Y_diag[r]
    Naug[p, p] = s
    if feedthrough:
        for a in range(nu):
            for b in range(nu):
                Z1 = _matrix(V, Wm, np.ascontiguousarray(gz1[:, a * nu + b]))
                blk = np.ascontiguousarray(Z1.T) @ CW2                    # (i, r)
                for i in range(n):
                    for r in range(ny):
                        Naug[nx + a * n + i, q + b * ny + r] = blk[i, r]
        for b in range(nu):
            for c in range(nu):
                for r in range(ny):
                    Naug[q + b * ny + r, q + c * ny + r] = G[0, b * nu + c] * w2[r]
            for r in range(ny):
                Naug[q + b * ny + r, p] = R[0, r * nu + b] * w2[r]
    if estimate_x0:
        # sum_{t<N} (A^t)^T Q A^t = P - (A^N)^T P A^N and sum_{t<N} (A^t)^T Q X(t) =
        # sum_s u(s)^T kron (A^(s+1))^T P - (A^N)^T P X(N): exact for every L < N
        AN = _power_n(V, Wm, lam, vand_re, vand_im, n_samples)
        ANtP = np.ascontiguousarray(AN.T) @ P
        P0 = P - ANtP @ AN
        for i in range(n):
            for j in range(n):
                Naug[i, j] = P0[i, j]
        s1 = np.empty((n, nu), dtype=np.complex128)
        for i in range(n):
            for a in range(nu):
                s1[i, a] = s0[i, a] * lam[i]
        for a in range(nu):
            S1 = _matrix(V, Wm, np.ascontiguousarray(s1[:, a]))
            blk = np.ascontiguousarray(S1.T) @ P - ANtP @ np.ascontiguousarray(
                XN[:, a * n:(a + 1) * n])
            for i in range(n):
                for j in range(n):
                    Naug[i, nx + a * n + j] = blk[i, j]
        mod = np.zeros((n, 1), dtype=np.complex128)
        for i in range(n):
            for r in range(ny):
                mod[i, 0] += VtCW2[i, r] * eta[i, r]
        back = _re(WmT @ mod)
        for i in range(n):
            Naug[i, p] = back[i, 0]
        if feedthrough:
            for b in range(nu):
                S0 = _matrix(V, Wm, np.ascontiguousarray(s0[:, b]))
                blk = np.ascontiguousarray(S0.T) @ CW2                    # (i, r)
                for i in range(n):
                    for r in range(ny):
                        Naug[i, q + b * ny + r] = blk[i, r]
    for i in range(p + 1):
        for j in range(i + 1, p + 1):
            Naug[j, i] = Naug[i, j]
    return Naug


def normal_matrix_reference(lam, V, Wm, vand_re, vand_im, G, R, Y_diag, u_tail, u_head, y_head,
                            n_samples, C, w, feedthrough, estimate_x0):
    """Plain-numpy reference of :func:`normal_matrix` (the same arguments)."""
    vand = vand_re + 1j * vand_im
    n, ny, nu = lam.size, C.shape[0], u_tail.shape[1]
    L = vand.shape[1] - 1
    G = G.reshape(-1, nu, nu)
    R = R.reshape(-1, ny, nu)
    w2 = w * w

    def poly(seq, shift=0, rows=None):
        rows = seq.shape[0] - shift if rows is None else rows
        flat = seq[shift:shift + rows].reshape(rows, -1)
        return (vand[:, :rows] @ flat).reshape((n,) + seq.shape[1:])

    def matrix(values):
        vals = values.reshape(n, -1).T
        return np.real((V[None] * vals[:, None, :]) @ Wm).reshape(values.shape[1:] + (n, n))

    CW2 = C.T * w2[None, :]
    Cw = C * w[:, None]
    den = 1.0 - lam[:, None] * lam[None, :]
    P = np.real(Wm.T @ ((V.T @ Cw.T) @ (Cw @ V) / den) @ Wm)
    P = 0.5 * (P + P.T)
    Z = matrix(poly(G, 0, L + 1))
    Z1 = matrix(poly(G, 1, L))
    I = np.eye(n)
    BB = np.empty((nu, n, nu, n))
    for a in range(nu):
        for b in range(nu):
            BB[a, :, b, :] = Z[a, b].T @ P + P @ (Z[b, a] - G[0][b, a] * I)
    BB = BB.reshape(nu * n, nu * n)
    XN = matrix(poly(u_tail, 0, L + 1)).transpose(1, 0, 2).reshape(n, nu * n)
    BB -= XN.T @ P @ XN
    VtCW2 = V.T @ CW2
    rho = poly(R, 1, L)
    rB = np.real(Wm.T @ np.einsum("lr,lra->la", VtCW2, rho)).T.reshape(-1)
    nx = n if estimate_x0 else 0
    q = nx + n * nu
    p = q + (nu * ny if feedthrough else 0)
    Naug = np.zeros((p + 1, p + 1))
    Naug[nx:q, nx:q] = BB
    Naug[nx:q, p] = rB
    Naug[p, p] = float(np.sum(w2 * Y_diag))
    if feedthrough:
        Naug[nx:q, q:p] = np.einsum("abji,jr->aibr", Z1, CW2).reshape(nu * n, nu * ny)
        Naug[q:p, q:p] = np.kron(G[0], np.diag(w2))
        Naug[q:p, p] = (R[0] * w2[:, None]).T.reshape(-1)
    if estimate_x0:
        AN = matrix(lam ** n_samples)                # A^N
        S1 = matrix(lam[:, None] * poly(u_head, 0, L + 1))
        Naug[:n, :n] = P - AN.T @ P @ AN
        Naug[:n, nx:q] = np.concatenate([S1[a].T @ P for a in range(nu)], axis=1) \
            - AN.T @ P @ XN
        Naug[:n, p] = np.real(Wm.T @ np.einsum("lr,lr->l", VtCW2, poly(y_head, 0, L + 1)))
        if feedthrough:
            S0 = matrix(poly(u_head, 0, L + 1))
            Naug[:n, q:p] = np.einsum("bji,jr->ibr", S0, CW2).reshape(n, nu * ny)
    iu = np.triu_indices(p + 1, 1)
    Naug[(iu[1], iu[0])] = Naug[iu]
    return Naug


@numba.njit(cache=True, nogil=True)
def error_power(lam, V, Wm, vand_re, vand_im, G, R, Y_diag, u_tail, u_head, y_head, n_samples,
                B, C, D, weights, rcond, max_condition):  # pragma: no cover - compiled
    """``err[r] = sum_t (y_r - ŷ_r)^2`` per output, the validation error power of
    :func:`subid.methods.dt._lag_fit.error_power` (module documentation there), ``ŷ``
    simulated from the least-squares x0 (outputs weighted by ``weights``, the
    minimum-norm solution with cut-off ``rcond``); the arguments as
    :func:`normal_matrix`'s, with the candidate's B and D. NaN when the x0 normal
    matrix has a condition number above ``max_condition`` (its rounding would then
    reach the score; the pass over the record factorises the rows instead)."""
    n = lam.shape[0]
    ny = C.shape[0]
    nu = B.shape[1]
    Vt = np.ascontiguousarray(V.T)
    WmT = np.ascontiguousarray(Wm.T)
    Bc = _c(B)
    CV = _c(C) @ V                                   # (ny, n)
    WB = Wm @ Bc                                     # (n, nu)
    # (l, a nu + b), (l, r nu + j), (l, a); mu, eta: sum_t u_b(t) λ^t, sum_t y_r(t) λ^t
    g, g1, rho, xt, mu, eta = _sums(vand_re, vand_im, G, R, u_tail, u_head, y_head)
    # sum_t y_r y_f,r = sum_k (R(k) G_k^T)_rr, G_0 = D, G_k = C A^(k-1) B
    cross = np.zeros(ny)
    for r in range(ny):
        s = 0.0
        for j in range(nu):
            s += R[0, r * nu + j] * D[r, j]
        c = 0.0 + 0.0j
        for l in range(n):
            for j in range(nu):
                c += CV[r, l] * WB[l, j] * rho[l, r * nu + j]
        cross[r] = s + c.real
    h = np.zeros((n, nu), dtype=np.complex128)
    h1 = np.zeros((n, nu), dtype=np.complex128)
    for l in range(n):
        for a in range(nu):
            for b in range(nu):
                h[l, b] += WB[l, a] * g[l, a * nu + b]
                h1[l, b] += WB[l, a] * g1[l, a * nu + b]
    G0 = np.empty((nu, nu))
    for a in range(nu):
        for b in range(nu):
            G0[a, b] = G[0, a * nu + b]
    Bt = np.ascontiguousarray(B.T)
    U0 = _re(V @ h) @ Bt                             # sum_e A^e B Γ(e) B^T
    S = U0 + np.ascontiguousarray((U0 - B @ G0 @ Bt).T)
    M = Wm @ _c(S) @ WmT
    for i in range(n):
        for j in range(n):
            M[i, j] /= 1.0 - lam[i] * lam[j]
    X = _re(V @ M @ Vt)                              # X = A X A^T + S
    SD = _re(V @ h1) @ np.ascontiguousarray(D.T)     # sum_k A^(k-1) B Γ(k) D^T
    Ct = np.ascontiguousarray(C.T)
    CSD = C @ SD
    F = C @ X @ Ct + CSD + np.ascontiguousarray(CSD.T) + D @ G0 @ np.ascontiguousarray(D.T)
    # minus the free response after the record, x_f(N) = V ξ
    xi = np.zeros(n, dtype=np.complex128)
    for l in range(n):
        for a in range(nu):
            xi[l] += WB[l, a] * xt[l, a]
    total = np.empty(ny)
    for r in range(ny):
        c = 0.0 + 0.0j
        for l in range(n):
            for m in range(n):
                c += CV[r, l] * (xi[l] * xi[m] / (1.0 - lam[l] * lam[m])) * CV[r, m]
        total[r] = Y_diag[r] - 2.0 * cross[r] + F[r, r] - c.real
    # x0: β_r = sum_{t<N} (A^t)^T c_r^T (y_r - y_f,r)(t), P_r its Gramian over t < N:
    # the sums over every t minus those past the record, (A^N)^T P_r x_f(N) and
    # (A^N)^T P_r A^N (exact for every L < N)
    AN = _power_n(V, Wm, lam, vand_re, vand_im, n_samples)
    ANt = np.ascontiguousarray(AN.T)
    xN = np.empty((n, 1), dtype=np.complex128)
    for l in range(n):
        xN[l, 0] = xi[l]
    xN = _re(V @ xN)                                 # x_f(N) = V ξ
    beta = np.empty((ny, n))
    Pr = np.empty((ny, n, n))
    for r in range(ny):
        left = np.empty((n, 1), dtype=np.complex128)
        for i in range(n):
            left[i, 0] = CV[r, i]
        Pinf = _gramian(lam, Wm, left)
        PB = Vt @ _c(Pinf @ B)                       # (l, k)
        mod = np.empty((n, 1), dtype=np.complex128)
        for l in range(n):
            d = eta[l, r]
            for b in range(nu):
                d -= mu[l, b] * D[r, b]
            s = CV[r, l] * d
            for k in range(nu):
                s -= PB[l, k] * (lam[l] * mu[l, k])
            mod[l, 0] = s
        beta[r] = _re(WmT @ mod)[:, 0] + (ANt @ (Pinf @ xN))[:, 0]
        Pr[r] = Pinf - ANt @ Pinf @ AN
    Pw = np.zeros((n, n))
    bw = np.zeros(n)
    for r in range(ny):
        w2 = weights[r] * weights[r]
        Pw += w2 * Pr[r]
        bw += w2 * beta[r]
    err = np.empty(ny)
    if not (np.linalg.cond(Pw) <= max_condition):
        err[:] = np.nan             # x0 from normal equations this ill-conditioned: no value
        return err
    x0 = np.linalg.lstsq(Pw, bw, rcond)[0]
    for r in range(ny):
        err[r] = total[r] - 2.0 * np.dot(x0, beta[r]) + np.dot(x0, Pr[r] @ x0)
    return err


def error_power_reference(lam, V, Wm, vand_re, vand_im, G, R, Y_diag, u_tail, u_head, y_head,
                          n_samples, B, C, D, weights, rcond, max_condition):
    """Plain-numpy reference of :func:`error_power` (the same arguments)."""
    vand = vand_re + 1j * vand_im
    n, ny, nu = lam.size, C.shape[0], B.shape[1]
    L = vand.shape[1] - 1
    G = G.reshape(-1, nu, nu)
    R = R.reshape(-1, ny, nu)

    def poly(seq, shift=0, rows=None):
        rows = seq.shape[0] - shift if rows is None else rows
        flat = seq[shift:shift + rows].reshape(rows, -1)
        return (vand[:, :rows] @ flat).reshape((n,) + seq.shape[1:])

    den = 1.0 - lam[:, None] * lam[None, :]
    CV = C @ V
    WB = Wm @ B
    cross = np.einsum("rj,rj->r", R[0], D) + np.real(
        np.einsum("rl,lj,lrj->r", CV, WB, poly(R, 1, L)))
    U0 = np.real(V @ np.einsum("la,lab->lb", WB, poly(G, 0, L + 1))) @ B.T
    S = U0 + (U0 - B @ G[0] @ B.T).T
    X = np.real(V @ ((Wm @ S @ Wm.T) / den) @ V.T)
    SD = np.real(V @ np.einsum("la,lab->lb", WB, poly(G, 1, L))) @ D.T
    F = C @ X @ C.T + C @ SD + SD.T @ C.T + D @ G[0] @ D.T
    xi = np.einsum("la,la->l", WB, poly(u_tail, 0, L + 1))
    after = np.real(np.einsum("rl,lm,rm->r", CV, np.outer(xi, xi) / den, CV))
    total = Y_diag - 2.0 * cross + np.diag(F) - after
    mu = poly(u_head, 0, L + 1)
    nu_ = lam[:, None] * mu
    eta = poly(y_head, 0, L + 1)
    VtCt = V.T @ C.T
    AN = np.real(V @ np.diag(lam ** n_samples) @ Wm)
    xN = np.real(V @ xi)
    beta = np.empty((n, ny))
    Pr = np.empty((ny, n, n))
    for r in range(ny):
        cr = C[r:r + 1]
        Pinf = np.real(Wm.T @ ((V.T @ cr.T) @ (cr @ V) / den) @ Wm)
        modal = VtCt[:, r] * (eta[:, r] - mu @ D[r]) - (V.T @ Pinf @ B * nu_).sum(axis=1)
        beta[:, r] = np.real(Wm.T @ modal) + AN.T @ Pinf @ xN
        Pr[r] = Pinf - AN.T @ Pinf @ AN
    w2 = weights ** 2
    Pw = np.tensordot(w2, Pr, axes=(0, 0))
    if not np.linalg.cond(Pw) <= max_condition:
        return np.full(ny, np.nan)
    x0 = np.linalg.lstsq(Pw, beta @ w2, rcond=rcond)[0]
    return total - 2.0 * (x0 @ beta) + np.einsum("i,rij,j->r", x0, Pr, x0)


@numba.njit(cache=True, nogil=True)
def scored_solve(N, p, max_condition):  # pragma: no cover - compiled
    """``(status, theta, bound)`` of the augmented normal matrix ``N`` ((p + 1)-square,
    ``[[G, b], [b^T, yy]]``) of a candidate that is only scored: its columns
    equilibrated (``Ge = G / s s^T``, ``s = sqrt(diag G)``), the Cholesky factor
    ``Ge = R^T R``, the bound ``||Ge||_inf ||R^{-1}||_F^2`` of the condition number and,
    when it is at most ``max_condition``, ``theta = (G^{-1} b)`` through that factor
    (``status`` 0). ``status`` 1 when the factor or the bound does not settle it (not
    positive definite, bound above the limit, a diagonal entry not positive: the caller
    decides by the eigenvalues), 2 when ``N`` is not finite. The steps of
    :func:`scored_solve_reference` (LAPACK ``potrf``, ``trtri``, ``potrs``) in one
    compiled call: on the matrices of a candidate (p about 40) their wrappers cost
    more than the arithmetic."""
    m = N.shape[0]
    empty = np.empty(0)
    for i in range(m):
        for j in range(m):
            if not np.isfinite(N[i, j]):
                return 2, empty, 0.0
    scale = np.empty(p)
    for i in range(p):
        if not N[i, i] >= 0.0:
            return 1, empty, 0.0
        s = math.sqrt(N[i, i])
        scale[i] = s if s != 0.0 else 1.0
    Ge = np.empty((p, p))
    for i in range(p):
        for j in range(p):
            Ge[i, j] = N[i, j] / scale[i] / scale[j]
    R = np.zeros((p, p))
    for j in range(p):
        s = Ge[j, j]
        for k in range(j):
            s -= R[k, j] * R[k, j]
        if not s > 0.0:
            return 1, empty, 0.0
        d = math.sqrt(s)
        R[j, j] = d
        for i in range(j + 1, p):
            t = Ge[j, i]
            for k in range(j):
                t -= R[k, j] * R[k, i]
            R[j, i] = t / d
    inv2 = 0.0                                   # ||R^{-1}||_F^2, column by column
    col = np.empty(p)
    for j in range(p):
        col[j] = 1.0 / R[j, j]
        inv2 += col[j] * col[j]
        for i in range(j - 1, -1, -1):
            t = 0.0
            for k in range(i + 1, j + 1):
                t += R[i, k] * col[k]
            col[i] = -t / R[i, i]
            inv2 += col[i] * col[i]
    norm_inf = 0.0
    for i in range(p):
        s = 0.0
        for j in range(p):
            s += abs(Ge[i, j])
        norm_inf = max(norm_inf, s)
    bound = norm_inf * inv2
    if not bound <= max_condition:
        return 1, empty, bound
    z = np.empty(p)                              # R^T z = b / s, then R x = z
    for i in range(p):
        t = N[i, p] / scale[i]
        for k in range(i):
            t -= R[k, i] * z[k]
        z[i] = t / R[i, i]
    theta = np.empty(p)
    for i in range(p - 1, -1, -1):
        t = z[i]
        for k in range(i + 1, p):
            t -= R[i, k] * theta[k]
        theta[i] = t / R[i, i]
    for i in range(p):
        theta[i] /= scale[i]
    return 0, theta, bound


def scored_solve_reference(N, p, max_condition):
    """Plain reference of :func:`scored_solve` by LAPACK (``dpotrf``, ``dtrtri``,
    ``dpotrs``: the steps of
    :func:`subid.methods.dt._regression.solve_normal_equations` with
    ``bound_condition``)."""
    import scipy.linalg
    if not np.isfinite(N).all():
        return 2, np.empty(0), 0.0
    G, b = N[:p, :p], N[:p, p]
    diag = np.diag(G)
    if not np.all(diag >= 0):
        return 1, np.empty(0), 0.0
    scale = np.sqrt(diag).copy()
    scale[scale == 0] = 1.0
    Ge = G / scale[:, None] / scale[None, :]
    factor, info = scipy.linalg.lapack.dpotrf(Ge, lower=0, overwrite_a=0, clean=1)
    if info != 0:
        return 1, np.empty(0), 0.0
    inverse, info = scipy.linalg.lapack.dtrtri(factor, lower=0)
    bound = float(np.abs(Ge).sum(axis=1).max()) * float(np.sum(inverse ** 2))
    if info != 0 or not bound <= max_condition:
        return 1, np.empty(0), bound
    theta = scipy.linalg.lapack.dpotrs(factor, b / scale, lower=0)[0]
    return 0, theta / scale, bound


@numba.njit(cache=True, nogil=True)
def complex_eigenvectors(wr, wi, vr):  # pragma: no cover - compiled
    """``(lam, V)`` complex from LAPACK's real storage (``dgeev``'s ``wr``, ``wi``,
    ``vr``: a conjugate pair's eigenvectors ``vr[:, j] ± i vr[:, j + 1]``), as
    ``numpy.linalg.eig`` builds them (the same values)."""
    n = wr.shape[0]
    lam = np.empty(n, dtype=np.complex128)
    V = np.empty((n, n), dtype=np.complex128)
    j = 0
    while j < n:
        if wi[j] != 0.0 and j + 1 < n:
            lam[j] = complex(wr[j], wi[j])
            lam[j + 1] = complex(wr[j + 1], wi[j + 1])
            for i in range(n):
                V[i, j] = complex(vr[i, j], vr[i, j + 1])
                V[i, j + 1] = complex(vr[i, j], -vr[i, j + 1])
            j += 2
        else:
            lam[j] = complex(wr[j], wi[j])
            for i in range(n):
                V[i, j] = complex(vr[i, j], 0.0)
            j += 1
    return lam, V


def complex_eigenvectors_reference(wr, wi, vr):
    """Plain reference of :func:`complex_eigenvectors` (numpy's loop)."""
    n = wr.shape[0]
    lam = wr + 1j * wi
    V = vr.astype(complex)
    j = 0
    while j < n:
        if wi[j] != 0 and j + 1 < n:
            V[:, j] = vr[:, j] + 1j * vr[:, j + 1]
            V[:, j + 1] = vr[:, j] - 1j * vr[:, j + 1]
            j += 2
        else:
            j += 1
    return lam, V
