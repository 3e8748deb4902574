"""Per-sample kernels of the continuous-time identification (seed 002).

Everything here works on clean float64 arrays; validation happens in
:mod:`subid.basis` and :mod:`subid.ct_subspace`.

Local polynomial interpolation (seed 002, eq. (21), corrected)
--------------------------------------------------------------
Between the samples ``t[a]`` and ``t[a+1]`` a signal ``v`` is replaced by the
polynomial of degree ``p`` through the ``p + 1`` samples
``s_a, ..., s_a + p`` with ``s_a = clip(a - floor(p/2), 0, L - 1 - p)``:
centred on the interval inside the record and one-sided at its ends (the
paper pads the record with zeros instead, and its index range in (21) gives
only ``p`` points). ``p = 0`` is a zero-order hold (``v = v[a]`` on the
interval) and ``p = 1`` a first-order hold, so an input known to be held is
filtered exactly.

With ``r = (t - t[a]) / h``, ``h = t[a+1] - t[a]``, the polynomial is
``v(r) = sum_q l_q(r) v[s_a + q]`` with Lagrange polynomials ``l_q``. The
state of ``x' = F x + G v`` then moves over the interval exactly as

    x(t[a+1]) = Phi_a x(t[a]) + sum_q W_{a,q} v[s_a + q],
    Phi_a = e^{F h},  W_{a,q} = h int_0^1 e^{F h (1 - r)} G l_q(r) dr,

and the integrals ``h int_0^1 e^{F h (1-r)} G r^j dr`` are the top-right
blocks of one matrix exponential (Van Loan): ``expm([[F h, G h, 0, ...],
[0, 0, I, 0, ...], ..., [0, ..., 0]])`` holds them divided by ``j!``.
This replaces the paper's recursion (20)-(22) (which does the same thing
for one first-order section, with the typos listed in docs/seed002.md) and
works for any realisation ``(F, G)``.

Kernels
-------
``bank_loop`` runs the recursion above for a multichannel signal (the state
is ``N x channels``); ``sens_loop`` runs it for the sensitivities of a model
output to ``B`` and ``x0`` (the regressors of the raw-sample fit of B).
``bank_loop_ref`` and ``sens_loop_ref`` are plain numpy references that the
tests compare the compiled kernels against.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.linalg

__all__ = [
    "stencil_starts",
    "interval_tables",
    "bank_loop",
    "bank_loop_ref",
    "sens_loop",
    "sens_loop_ref",
    "run_bank",
    "run_sensitivity",
]

# Intervals processed per table chunk on non-uniform grids (bounds the memory
# of the per-interval tables).
_CHUNK = 4096


def stencil_starts(n_samples: int, order: int) -> np.ndarray:
    """First sample ``s_a`` of the interpolation stencil of every interval."""
    a = np.arange(n_samples - 1)
    return np.clip(a - order // 2, 0, n_samples - 1 - order).astype(np.int64)


def _lagrange(nodes: np.ndarray) -> np.ndarray:
    """Monomial coefficients of the Lagrange polynomials.

    ``nodes`` has shape (K, P); returns ``c`` (K, P, P) with
    ``l_q(r) = sum_j c[:, j, q] r^j`` (the inverse of the Vandermonde matrix).
    """
    K, P = nodes.shape
    V = nodes[:, :, None] ** np.arange(P)[None, None, :]        # V[k, q, j] = r_q^j
    return np.linalg.solve(V, np.broadcast_to(np.eye(P), (K, P, P)))


def interval_tables(F: np.ndarray, G: np.ndarray, steps: np.ndarray, nodes: np.ndarray):
    """Exact transition and drive matrices for polynomially interpolated input.

    Parameters
    ----------
    F : ndarray, shape (N, N)
    G : ndarray, shape (N, r)
    steps : ndarray, shape (K,)
        Interval lengths ``h``.
    nodes : ndarray, shape (K, P)
        Stencil sample times relative to the interval start, divided by ``h``.

    Returns
    -------
    Phi : ndarray, shape (K, N, N)
    W : ndarray, shape (K, P, N, r)
        ``W[k, q]`` multiplies the stencil sample ``q``.
    """
    N, r = G.shape
    K, P = nodes.shape
    size = N + r * P
    M = np.zeros((K, size, size))
    h = steps[:, None, None]
    M[:, :N, :N] = F * h
    M[:, :N, N:N + r] = G * h
    for j in range(P - 1):
        a = N + j * r
        M[:, a:a + r, a + r:a + 2 * r] = np.eye(r)
    E = scipy.linalg.expm(M)
    Phi = np.ascontiguousarray(E[:, :N, :N])
    mono = E[:, :N, N:].reshape(K, N, P, r)                     # int ... r^j / j!
    fact = np.array([math.factorial(j) for j in range(P)], dtype=float)
    mono = mono * fact[None, None, :, None]
    coef = _lagrange(nodes)                                      # (K, P_j, P_q)
    W = np.einsum("knjr,kjq->kqnr", mono, coef)
    return Phi, np.ascontiguousarray(W)


def _uniform_tables(F, G, t, order):
    """Tables for a uniform grid: one entry per distinct stencil offset."""
    L = t.shape[0]
    starts = stencil_starts(L, order)
    offsets = starts - np.arange(L - 1)
    uniq, tab = np.unique(offsets, return_inverse=True)
    h = (t[-1] - t[0]) / (L - 1)
    nodes = (uniq[:, None] + np.arange(order + 1)[None, :]).astype(float)
    Phi, W = interval_tables(F, G, np.full(uniq.size, h), nodes)
    return Phi, W, tab.astype(np.int64).reshape(-1), starts


def _psi(z: np.ndarray, P: int) -> np.ndarray:
    """``I_j(z) = int_0^1 e^{z (1 - r)} r^j dr`` for ``j = 0..P-1``.

    Power series ``sum_k z^k j! / (k + j + 1)!`` for ``|z| <= 2`` (all terms
    positive in magnitude order, no cancellation), else the recursion
    ``I_0 = (e^z - 1)/z``, ``I_j = (j I_{j-1} - 1)/z``.
    """
    z = np.asarray(z, dtype=complex)
    out = np.empty(z.shape + (P,), dtype=complex)
    small = np.abs(z) <= 2.0
    if small.any():
        zs = z[small]
        for j in range(P):
            term = np.full(zs.shape, 1.0 / (j + 1), dtype=complex)   # k = 0: j!/(j+1)!
            acc = term.copy()
            for k in range(1, 40):
                term = term * zs / (k + j + 1)
                acc = acc + term
            out[small, j] = acc
    big = ~small
    if big.any():
        zb = z[big]
        prev = np.expm1(zb) / zb
        out[big, 0] = prev
        for j in range(1, P):
            prev = (j * prev - 1.0) / zb
            out[big, j] = prev
    return out


# Eigenvector condition number above which the eigen-decomposition route is
# not trusted and the tables come from matrix exponentials.
_EIG_COND_MAX = 1e6


def _eig_tables(F, G, steps, nodes):
    """:func:`interval_tables` through ``F = V diag(lam) V^{-1}`` (or None).

    ``e^{F h} = V e^{lam h} V^{-1}`` and ``h int_0^1 e^{F h (1-r)} r^j dr G
    = h V diag(I_j(lam h)) V^{-1} G``; one pass over all intervals instead of
    one matrix exponential per interval. None when ``F`` is (nearly)
    defective.
    """
    lam, V = np.linalg.eig(F)
    if np.linalg.cond(V) > _EIG_COND_MAX:
        return None
    Vi = np.linalg.inv(V)
    K, P = nodes.shape
    z = steps[:, None] * lam[None, :]                        # (K, N)
    Phi = (V[None] * np.exp(z)[:, None, :]) @ Vi
    VG = Vi @ G                                              # (N, r)
    psi = _psi(z, P) * steps[:, None, None]                  # (K, N, P)
    coef = _lagrange(nodes)                                  # (K, P_j, P_q)
    # W_q = V diag(sum_j psi_j c_jq) V^{-1} G
    weights = psi @ coef                                     # (K, N, P_q)
    W = np.einsum("in,knq,nr->kqir", V, weights, VG, optimize=True)
    return np.ascontiguousarray(Phi.real), np.ascontiguousarray(W.real)


def _chunk_tables(F, G, t, order, starts, a, b, use_eig=False):
    """Per-interval tables of intervals ``a .. b-1`` of a non-uniform grid."""
    steps = t[a + 1:b + 1] - t[a:b]
    idx = starts[a:b, None] + np.arange(order + 1)[None, :]
    nodes = (t[idx] - t[a:b, None]) / steps[:, None]
    tables = _eig_tables(F, G, steps, nodes) if use_eig else None
    if tables is None:
        tables = interval_tables(F, G, steps, nodes)
    return tables[0], tables[1], np.arange(b - a, dtype=np.int64)


# ---------------------------------------------------------------------------
# filter bank: x(t[a+1]) = Phi x(t[a]) + sum_q W_q v[s_a + q]
# ---------------------------------------------------------------------------
@numba.njit(cache=True)
def bank_loop(Phi, W, tab, starts, v, x0, out):  # pragma: no cover - compiled
    """Compiled recursion ``x(t[a+1]) = Phi x(t[a]) + sum_q W_q v[s_a + q]``.

    ``Phi`` (K, N, N) and ``W`` (K, P, N, r) are tables indexed by ``tab``
    (one entry per interval), ``starts`` the stencil starts (indices into
    ``v``), ``v`` (L, r, c) the signal (``r`` inputs, ``c`` independent
    columns), ``x0`` (N, c) the state at the first interval's start. Fills
    ``out`` (len(tab) + 1, N, c) with the state at every interval end point
    (``out[0] = x0``).
    """
    K = tab.shape[0]
    N = x0.shape[0]
    c = x0.shape[1]
    P = W.shape[1]
    r = W.shape[3]
    for i in range(N):
        for j in range(c):
            out[0, i, j] = x0[i, j]
    for a in range(K):
        e = tab[a]
        s = starts[a]
        for i in range(N):
            for j in range(c):
                acc = 0.0
                for k in range(N):
                    acc += Phi[e, i, k] * out[a, k, j]
                for q in range(P):
                    for rho in range(r):
                        acc += W[e, q, i, rho] * v[s + q, rho, j]
                out[a + 1, i, j] = acc
    return out


def bank_loop_ref(Phi, W, tab, starts, v, x0, out):
    """Plain numpy reference of :func:`bank_loop`."""
    out[0] = x0
    P = W.shape[1]
    for a in range(tab.shape[0]):
        e = tab[a]
        s = starts[a]
        out[a + 1] = Phi[e] @ out[a] + np.einsum("qnr,qrc->nc", W[e], v[s:s + P])
    return out


def run_bank(F, G, t, v, order, *, uniform, x0=None, use_eig=True, kernel=bank_loop):
    """States of ``x' = F x + G v`` at every sample, from ``x0`` at ``t[0]``.

    Parameters
    ----------
    F : (N, N)
    G : (N,) or (N, r)
        Input vector (one input, every column of ``v`` filtered by it) or
        input matrix (``r`` inputs, the columns of ``v`` are the inputs).
    t : (L,) time stamps
    v : (L, c) samples (with ``G`` a vector) or (L, r) (with ``G`` a matrix)
    order : int
        Interpolation degree.
    uniform : bool
        Treat the grid as uniform (one table per stencil offset).
    x0 : (N,) or (N, c), optional
        Initial state (default zero: at rest).
    use_eig : bool
        On a non-uniform grid, build the per-interval tables from the
        eigen-decomposition of ``F`` when it is well conditioned (much
        faster than one matrix exponential per interval).

    Returns
    -------
    ndarray, shape (L, N, c) (``c = 1`` with a matrix ``G``)
    """
    L = v.shape[0]
    N = F.shape[0]
    G = np.asarray(G, dtype=float)
    if G.ndim == 1:
        G = G[:, None]
        v3 = np.ascontiguousarray(v, dtype=float).reshape(L, 1, -1)
    else:
        v3 = np.ascontiguousarray(v, dtype=float).reshape(L, G.shape[1], 1)
    c = v3.shape[2]
    out = np.empty((L, N, c))
    start = np.zeros((N, c)) if x0 is None else \
        np.ascontiguousarray(np.broadcast_to(np.asarray(x0, float).reshape(N, -1), (N, c)))
    if L == 1:
        out[0] = start
        return out
    if uniform:
        Phi, W, tab, starts = _uniform_tables(F, G, t, order)
        kernel(Phi, W, tab, starts, v3, start, out)
        return out
    starts = stencil_starts(L, order)
    for a in range(0, L - 1, _CHUNK):
        b = min(a + _CHUNK, L - 1)
        Phi, W, tab = _chunk_tables(F, G, t, order, starts, a, b, use_eig)
        part = np.empty((b - a + 1, N, c))
        kernel(Phi, W, tab, np.ascontiguousarray(starts[a:b]), v3,
               np.ascontiguousarray(out[a]) if a else start, part)
        out[a:b + 1] = part
    return out


# ---------------------------------------------------------------------------
# sensitivities of the output of (A, B, C) to B and x0
# ---------------------------------------------------------------------------
@numba.njit(cache=True)
def sens_loop(Phi, W, tab, starts, u, C, Z, P0, rows_b, rows_x):  # pragma: no cover
    """Compiled sensitivities of ``y = C x`` with ``x' = A x + B u``.

    ``Z`` (m, n, n) holds, per input j, the state response matrix ``Z_j``
    (``x = sum_j Z_j B[:, j]`` for a zero initial state); ``P0`` (n, n) is
    the transition matrix from the first sample. Fills ``rows_b`` (K+1, ny,
    n, m) with ``C Z_j`` and ``rows_x`` (K+1, ny, n) with ``C P`` at every
    sample, and leaves the final ``Z`` and ``P0`` in place.
    """
    K = tab.shape[0]
    m = Z.shape[0]
    n = Z.shape[1]
    ny = C.shape[0]
    P = W.shape[1]
    tmp = np.empty((n, n))
    for a in range(K + 1):
        for i in range(ny):
            for k in range(n):
                acc = 0.0
                for l in range(n):
                    acc += C[i, l] * P0[l, k]
                rows_x[a, i, k] = acc
                for j in range(m):
                    acc = 0.0
                    for l in range(n):
                        acc += C[i, l] * Z[j, l, k]
                    rows_b[a, i, k, j] = acc
        if a == K:
            break
        e = tab[a]
        s = starts[a]
        for i in range(n):
            for k in range(n):
                acc = 0.0
                for l in range(n):
                    acc += Phi[e, i, l] * P0[l, k]
                tmp[i, k] = acc
        for i in range(n):
            for k in range(n):
                P0[i, k] = tmp[i, k]
        for j in range(m):
            for i in range(n):
                for k in range(n):
                    acc = 0.0
                    for l in range(n):
                        acc += Phi[e, i, l] * Z[j, l, k]
                    for q in range(P):
                        acc += W[e, q, i, k] * u[s + q, j]
                    tmp[i, k] = acc
            for i in range(n):
                for k in range(n):
                    Z[j, i, k] = tmp[i, k]
    return rows_b, rows_x


def sens_loop_ref(Phi, W, tab, starts, u, C, Z, P0, rows_b, rows_x):
    """Plain numpy reference of :func:`sens_loop`."""
    K = tab.shape[0]
    P = W.shape[1]
    for a in range(K + 1):
        rows_x[a] = C @ P0
        for j in range(Z.shape[0]):
            rows_b[a, :, :, j] = C @ Z[j]
        if a == K:
            break
        e, s = tab[a], starts[a]
        P0[:] = Phi[e] @ P0
        for j in range(Z.shape[0]):
            Z[j] = Phi[e] @ Z[j] + np.einsum("qik,q->ik", W[e], u[s:s + P, j])
    return rows_b, rows_x


def run_sensitivity(A, C, t, u, order, *, uniform, use_eig=True, kernel=sens_loop):
    """Regressors of the output of ``(A, B, C)`` on ``B`` and on ``x0``.

    The input is interpolated by polynomials of degree ``order`` (0: zero-order
    hold, 1: first-order hold), exactly as in :func:`run_bank`.

    Returns
    -------
    rows_b : ndarray, shape (L, ny, n, m)
        ``y(t_k) = sum_{i,j} rows_b[k, :, i, j] B[i, j]`` (zero initial state).
    rows_x : ndarray, shape (L, ny, n)
        ``C e^{A (t_k - t_0)}``: the output's dependence on ``x0``.
    """
    L, m = u.shape
    n = A.shape[0]
    ny = C.shape[0]
    u = np.ascontiguousarray(u, dtype=float)
    C = np.ascontiguousarray(C, dtype=float)
    I = np.eye(n)
    Z = np.zeros((m, n, n))
    P0 = np.eye(n)
    rows_b = np.empty((L, ny, n, m))
    rows_x = np.empty((L, ny, n))
    if L == 1:
        rows_b[0] = 0.0
        rows_x[0] = C
        return rows_b, rows_x
    if uniform:
        Phi, W, tab, starts = _uniform_tables(A, I, t, order)
        kernel(Phi, W, tab, starts, u, C, Z, P0, rows_b, rows_x)
        return rows_b, rows_x
    starts = stencil_starts(L, order)
    for a in range(0, L - 1, _CHUNK):
        b = min(a + _CHUNK, L - 1)
        Phi, W, tab = _chunk_tables(A, I, t, order, starts, a, b, use_eig)
        rb = np.empty((b - a + 1, ny, n, m))
        rx = np.empty((b - a + 1, ny, n))
        kernel(Phi, W, tab, np.ascontiguousarray(starts[a:b]), u, C, Z, P0, rb, rx)
        rows_b[a:b + 1] = rb
        rows_x[a:b + 1] = rx
    return rows_b, rows_x
