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
tests compare the compiled kernels against. On uniform grids the sensitivities come
from the fused kernel of :mod:`subid.methods.ct._ct_sensitivity` (the same sums in the
same order as ``sens_loop``, vectorised, written straight into the regressor).

On non-uniform grids the default is the fused block-modal kernel
``modal_loop`` (see the notes above :class:`ModalForm`): no per-interval
tables, one pass over the record, about 5x (bank) to 7x (sensitivities)
faster than the tables. The tables (``fast=False``) remain the reference and
the fallback when the block-modal form is ill-conditioned.

Accuracy. Both eigen routes (tables and kernel) carry errors of order
``cond(X) eps`` relative to the largest state. For the correction
regressors of :mod:`subid.ct_subspace` (defective Poisson-chain system,
matrix exponentials before) the kernel's errors are about 1e-13 instead of
2e-14, and those regressors are differences of nearly equal filtered
signals, so the difference grows to 1e-7 of their size (1e-8 with the
tables). Noise-free, the identified model agrees with the table path to
1e-12; under output noise the least-squares steps amplify such rounding
differences (the final model of either path moves by 1e-5 at L = 1500,
20 dB, when the data are perturbed by 1e-14), far below the statistical
error.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
import scipy.linalg

from subid._kernel_args import frozen, read_only
from subid.methods.ct import _ct_sensitivity

__all__ = [
    "stencil_starts",
    "interval_tables",
    "bank_loop",
    "bank_loop_ref",
    "sens_loop",
    "sens_loop_ref",
    "run_bank",
    "run_sensitivity",
    "sensitivity_into",
    "ModalForm",
    "modal_form",
    "modal_loop",
    "modal_bank",
    "modal_sensitivity",
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


def interval_tables(F: np.ndarray, G: np.ndarray, steps: np.ndarray, nodes: np.ndarray,
                    coef=None):
    """Exact transition and drive matrices for polynomially interpolated input.

    Parameters
    ----------
    F : ndarray, shape (N, N)
    G : ndarray, shape (N, r)
    steps : ndarray, shape (K,)
        Interval lengths ``h``.
    nodes : ndarray, shape (K, P)
        Stencil sample times relative to the interval start, divided by ``h``.
    coef : ndarray, shape (K, P, P), optional
        ``_lagrange(nodes)``, when already known.

    Returns
    -------
    Phi : ndarray, shape (K, N, N)
    W : ndarray, shape (K, P, N, r)
        ``W[k, q]`` multiplies the stencil sample ``q``.
    """
    N, r = G.shape
    M = van_loan_matrix(F, G, steps, nodes.shape[1])
    return tables_from_exponential(scipy.linalg.expm(M), N, r, nodes, coef)


def van_loan_matrix(F: np.ndarray, G: np.ndarray, steps: np.ndarray, P: int) -> np.ndarray:
    """The block matrices whose exponentials hold the tables of :func:`interval_tables`."""
    N, r = G.shape
    K = steps.shape[0]
    size = N + r * P
    M = np.zeros((K, size, size))
    h = steps[:, None, None]
    M[:, :N, :N] = F * h
    M[:, :N, N:N + r] = G * h
    for j in range(P - 1):
        a = N + j * r
        M[:, a:a + r, a + r:a + 2 * r] = np.eye(r)
    return M


def tables_from_exponential(E: np.ndarray, N: int, r: int, nodes: np.ndarray, coef=None):
    """``Phi, W`` of :func:`interval_tables` from the exponentials ``E`` of
    :func:`van_loan_matrix` (a linear map of ``E``: applied to a Frechet derivative
    of the exponential it gives the derivatives of the tables); ``coef`` is
    ``_lagrange(nodes)`` when already known."""
    K, P = nodes.shape
    Phi = np.ascontiguousarray(E[:, :N, :N])
    mono = E[:, :N, N:].reshape(K, N, P, r)                     # int ... r^j / j!
    fact = np.array([math.factorial(j) for j in range(P)], dtype=float)
    mono = mono * fact[None, None, :, None]
    if coef is None:
        coef = _lagrange(nodes)                                  # (K, P_j, P_q)
    W = np.einsum("knjr,kjq->kqnr", mono, coef)
    return Phi, np.ascontiguousarray(W)


def _uniform_tables(F, G, t, order):
    """Tables for a uniform grid: one entry per distinct stencil offset."""
    h, nodes, tab, starts, coef = uniform_stencil(t, order)
    Phi, W = interval_tables(F, G, np.full(nodes.shape[0], h), nodes, coef)
    return Phi, W, tab, starts


def uniform_layout(t, order):
    """Step ``h``, stencil ``nodes`` of every distinct stencil offset, the offset index
    ``tab`` and the stencil start ``starts`` of every interval of a uniform grid."""
    return uniform_stencil(t, order)[:4]


def uniform_stencil(t, order):
    """:func:`uniform_layout` and the Lagrange coefficients of its ``nodes``
    (``_lagrange(nodes)``), read-only: they depend only on the number of samples, the
    ends of the grid and ``order``, and are computed once for each."""
    return _stencil(t.shape[0], order, float(t[0]), float(t[-1]))


@functools.lru_cache(maxsize=32)
def _stencil(L, order, first, last):
    starts = stencil_starts(L, order)
    offsets = starts - np.arange(L - 1)
    uniq, tab = np.unique(offsets, return_inverse=True)
    h = (last - first) / (L - 1)
    nodes = (uniq[:, None] + np.arange(order + 1)[None, :]).astype(float)
    out = (nodes, tab.astype(np.int64).reshape(-1), starts, _lagrange(nodes))
    for a in out:
        a.flags.writeable = False
    return (h,) + out


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


def run_bank(F, G, t, v, order, *, uniform, x0=None, use_eig=True, kernel=bank_loop,
             fast=True):
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
    fast : bool
        On a non-uniform grid, run the fused block-modal kernel
        (:func:`modal_bank`) when the block-modal form of ``F`` is well
        conditioned; else (and with ``fast=False``, the reference) the
        per-interval tables.

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
        kernel(*read_only(Phi, W, tab, starts, v3, start), out)
        return out
    if fast and use_eig:
        res = modal_bank(np.asarray(F, dtype=float), G, t, v3, order, start)
        if res is not None:
            return res
    starts = stencil_starts(L, order)
    for a in range(0, L - 1, _CHUNK):
        b = min(a + _CHUNK, L - 1)
        Phi, W, tab = _chunk_tables(F, G, t, order, starts, a, b, use_eig)
        part = np.empty((b - a + 1, N, c))
        kernel(*read_only(Phi, W, tab, starts[a:b], v3, out[a] if a else start), part)
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


def run_sensitivity(A, C, t, u, order, *, uniform, use_eig=True, kernel=sens_loop,
                    fast=True):
    """Regressors of the output of ``(A, B, C)`` on ``B`` and on ``x0``.

    The input is interpolated by polynomials of degree ``order`` (0: zero-order
    hold, 1: first-order hold), exactly as in :func:`run_bank`. On a
    non-uniform grid with ``fast`` the regressors come from the modal
    recursion (:func:`modal_sensitivity`) when the eigenvectors of ``A`` are
    well conditioned; else (and with ``fast=False``, the reference) from
    per-interval tables.

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
    if uniform and kernel is sens_loop:           # the fused kernel, bit for bit the same
        out = np.empty((L, ny, n * m + n))
        sensitivity_into(A, C, t, u, order, uniform=True, out=out, col_b=0, col_x=n * m)
        return out[:, :, :n * m].reshape(L, ny, n, m), out[:, :, n * m:]
    if uniform:
        Phi, W, tab, starts = _uniform_tables(A, I, t, order)
        kernel(*read_only(Phi, W, tab, starts, u, C), Z, P0, rows_b, rows_x)
        return rows_b, rows_x
    if fast and use_eig:
        res = modal_sensitivity(np.asarray(A, dtype=float), C, t, u, order)
        if res is not None:
            return res
    starts = stencil_starts(L, order)
    for a in range(0, L - 1, _CHUNK):
        b = min(a + _CHUNK, L - 1)
        Phi, W, tab = _chunk_tables(A, I, t, order, starts, a, b, use_eig)
        rb = np.empty((b - a + 1, ny, n, m))
        rx = np.empty((b - a + 1, ny, n))
        kernel(*read_only(Phi, W, tab, starts[a:b], u, C), Z, P0, rb, rx)
        rows_b[a:b + 1] = rb
        rows_x[a:b + 1] = rx
    return rows_b, rows_x


def sensitivity_into(A, C, t, u, order, *, uniform, out, col_b, col_x=None):
    """The regressors of :func:`run_sensitivity`, written into ``out`` (L, ny, columns):
    ``rows_b`` (flattened, column ``col_b + k m + j`` multiplies ``B[k, j]``) and, unless
    ``col_x`` is None, ``rows_x`` at columns ``col_x .. col_x + n - 1``.

    On a uniform grid the fused kernel
    :func:`subid.methods.ct._ct_sensitivity.sens_fused` fills ``out`` in place (no
    intermediate arrays; the same values as :func:`sens_loop` to the last bit); elsewhere
    the rows of :func:`run_sensitivity` are copied in.
    """
    L, m = u.shape
    n = A.shape[0]
    if uniform and L > 1:
        Phi, W, tab, starts = _uniform_tables(A, np.eye(n), t, order)
        X = _ct_sensitivity.fused_state(n, m, col_x is not None)
        _ct_sensitivity.sens_fused(*read_only(Phi, W, tab, starts), frozen(u), frozen(C), X,
                                   out, col_b, -1 if col_x is None else col_x)
        return out
    rows_b, rows_x = run_sensitivity(A, C, t, u, order, uniform=uniform)
    out[:, :, col_b:col_b + n * m] = rows_b.reshape(L, C.shape[0], n * m)
    if col_x is not None:
        out[:, :, col_x:col_x + n] = rows_x
    return out


# ---------------------------------------------------------------------------
# fused modal kernels for non-uniform grids
# ---------------------------------------------------------------------------
# On a non-uniform grid every interval needs its own tables. Instead of
# building them (one N x N transition matrix and P drive matrices per
# interval, then a dense recursion), the recursion runs in the block-modal
# basis ``F = X diag(lam_c I + N_c) X^{-1}`` of the system matrix, where the
# tables of one interval are scalars (a one-eigenvalue block) or small
# matrix polynomials in ``N_c h`` (a cluster of equal or close eigenvalues,
# e.g. the Jordan chains of a Laguerre bank or of the Poisson chain of the
# correction regressors). With ``tau = h (1 - r)``
#
#     e^{(lam + N) tau} = e^{lam tau} sum_k (N tau)^k / k!,
#     h int_0^1 e^{(lam + N) h (1-r)} r^j dr = h sum_k (N h)^k J_{k,j}(lam h) / k!,
#     J_{k,j}(z) = int_0^1 e^{z s} s^k (1 - s)^j ds
#                = sum_n z^n (n + k)! j! / (n! (n + k + j + 1)!),
#
# exact for any ``N`` when the sum over ``k`` runs until its terms fall below
# rounding (for an exactly nilpotent ``N`` it ends by itself). For ``k = 0``
# and ``|z| > 2`` the series is replaced by the recursion of :func:`_psi`.
# The Lagrange coefficients of every interval are computed in the kernel, so
# one pass over the record does all the work (no per-interval tables).

# Relative spread of eigenvalues treated as one cluster (a Jordan block of
# size 4 computed in floating point spreads its eigenvalues by ~eps^(1/4)).
_CLUSTER_TOL = 1e-3
# Largest |lam h| of a multi-eigenvalue cluster (its J_{k,j} come from the
# power series, accurate for |z| <= 2 like :func:`_psi`).
_CLUSTER_Z_MAX = 2.0
# Largest number of Taylor terms in N_c h before falling back.
_TAYLOR_MAX = 40
# Intervals per chunk of the modal filter bank (bounds its complex work space).
_MODAL_CHUNK = 16384


class ModalForm:
    """Block-modal form ``F = X diag(B_c) X^{-1}``, ``B_c = lam_c I + N_c``.

    Attributes
    ----------
    X, Xi : ndarray (N, N) complex
    lam : ndarray (n_clusters,) complex
    bounds : ndarray (n_clusters + 1,) int64
        Cluster ``c`` occupies modal coordinates ``bounds[c]:bounds[c+1]``.
    npow : ndarray (K, N, N) complex
        ``npow[k]`` holds ``N_c^k / k!`` in the diagonal blocks.
    terms : ndarray (n_clusters,) int64
        Taylor terms of each cluster (1 for a single eigenvalue).
    mirror : ndarray (n_clusters,) bool
        The cluster is the complex conjugate of the previous one.
    """

    def __init__(self, X, Xi, lam, bounds, npow, terms):
        # complex even when every eigenvalue is real: one compiled kernel signature
        X, Xi = np.asarray(X, dtype=complex), np.array(Xi, dtype=complex)
        self.X, self.Xi, self.lam = X, Xi, lam
        self.bounds, self.npow, self.terms = bounds, npow, terms
        # singleton clusters that are the exact conjugate of the previous one
        # (eigenvalue and eigenvector; their inverse rows are made conjugate too)
        ncl = lam.size
        self.mirror = np.zeros(ncl, dtype=np.bool_)
        sizes = np.diff(bounds)
        for c in range(1, ncl):
            if sizes[c] == 1 and sizes[c - 1] == 1 and terms[c] == 1 and terms[c - 1] == 1 \
                    and not self.mirror[c - 1] and lam[c].imag != 0 \
                    and lam[c] == np.conj(lam[c - 1]) \
                    and np.array_equal(X[:, bounds[c]], np.conj(X[:, bounds[c - 1]])):
                self.mirror[c] = True
                Xi[bounds[c]] = np.conj(Xi[bounds[c - 1]])


def modal_form(F: np.ndarray, h_max: float, *, clusters: bool = True):
    """:class:`ModalForm` of ``F`` for steps up to ``h_max``, or None.

    The eigen-decomposition is used when its eigenvector matrix has condition
    at most ``_EIG_COND_MAX`` (as :func:`_eig_tables`). Otherwise, with
    ``clusters``, eigenvalues closer than ``_CLUSTER_TOL`` (relative to their
    size) are grouped, each group's invariant subspace is spanned by the
    leading vectors of a complex Schur form with the group's eigenvalues
    ordered first, and the form is accepted when those bases are well
    conditioned together, decouple ``F`` to rounding and the Taylor sums
    converge within ``_TAYLOR_MAX`` terms with ``|lam_c h| <= 2``. None
    means: use the per-interval tables.
    """
    F = np.asarray(F, dtype=float)
    if not np.isfinite(F).all():
        return None
    Nn = F.shape[0]
    lam, V = np.linalg.eig(F)
    if np.isfinite(V).all() and np.linalg.cond(V) <= _EIG_COND_MAX:
        Vi = np.linalg.inv(V)
        npow = np.eye(Nn, dtype=complex)[None]
        return ModalForm(V, Vi, lam.astype(complex), np.arange(Nn + 1, dtype=np.int64),
                         npow, np.ones(Nn, dtype=np.int64))
    if not clusters:
        return None
    scale = max(float(np.abs(lam).max()), 1e-300)
    # group eigenvalues closer than _CLUSTER_TOL relative to their size (single linkage)
    group = list(range(Nn))

    def root(i):
        while group[i] != i:
            i = group[i]
        return i
    for i in range(Nn):
        for j in range(i + 1, Nn):
            if abs(lam[i] - lam[j]) <= _CLUSTER_TOL * max(abs(lam[i]), abs(lam[j])) \
                    + 1e-12 * scale:
                group[root(j)] = root(i)
    labels = np.array([root(i) for i in range(Nn)])
    cols, lams, sizes = [], [], []
    for g in np.unique(labels):
        members = np.flatnonzero(labels == g)
        mc = members.size
        lc = complex(lam[members].mean())
        if np.all(np.abs(lam[members].imag) <= _CLUSTER_TOL * abs(lc) + 1e-12 * scale):
            lc = complex(lc.real, 0.0)
        # a defective cluster's eigenvalues move by ~(eps |F|)^(1/m_c) between
        # algorithms: select by half the distance to the other eigenvalues
        others = np.delete(lam, members)
        radius = max(float(np.abs(lam[members] - lc).max()) * 2.0, 1e-12 * scale,
                     0.5 * float(np.abs(others - lc).min()) if others.size else np.inf)
        # invariant subspace of the cluster: leading Schur vectors with the
        # cluster's eigenvalues ordered first (backward stable, no powers of F)
        _, Zs, sdim = scipy.linalg.schur(F.astype(complex), output="complex",
                                         sort=lambda x, lc=lc, radius=radius:
                                         abs(x - lc) <= radius)
        if sdim != mc:
            return None
        cols.append(Zs[:, :mc])
        lams.append(lc)
        sizes.append(mc)
    X = np.hstack(cols)
    if not np.isfinite(X).all() or np.linalg.cond(X) > _EIG_COND_MAX:
        return None
    Xi = np.linalg.inv(X)
    T = Xi @ F @ X
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    block = np.zeros((Nn, Nn), dtype=bool)
    for c in range(len(sizes)):
        block[bounds[c]:bounds[c + 1], bounds[c]:bounds[c + 1]] = True
    if np.abs(T[~block]).max(initial=0.0) > 1e-10 * max(np.abs(F).max(), 1e-300):
        return None
    Nm = np.where(block, T, 0.0) - np.diag(np.repeat(lams, sizes))
    terms = np.ones(len(sizes), dtype=np.int64)
    pows = [np.eye(Nn, dtype=complex)]
    for c, mc in enumerate(sizes):
        if mc == 1:
            continue
        if abs(lams[c]) * h_max > _CLUSTER_Z_MAX:
            return None
        sl = slice(bounds[c], bounds[c + 1])
        Nc = Nm[sl, sl]
        Pk = np.eye(mc, dtype=complex)
        k = 0
        while True:
            k += 1
            Pk = Pk @ Nc / k                              # N^k / k!
            if len(pows) <= k:
                pows.append(np.zeros((Nn, Nn), dtype=complex))
            pows[k][sl, sl] = Pk
            if np.abs(Pk).max() * h_max ** k <= 1e-18 or k >= _TAYLOR_MAX:
                break
        if k >= _TAYLOR_MAX:
            return None
        terms[c] = k + 1
    return ModalForm(X, Xi, np.array(lams, dtype=complex), bounds, np.array(pows), terms)


@numba.njit(cache=True)
def _lagrange_coef(r, coef, poly):  # pragma: no cover - compiled
    """``coef[j, q]``: monomial coefficients of the Lagrange polynomials of nodes ``r``.

    ``poly`` is work space of length ``len(r)``.
    """
    P = r.shape[0]
    for q in range(P):
        poly[:] = 0.0
        poly[0] = 1.0
        deg = 0
        den = 1.0
        for p in range(P):
            if p == q:
                continue
            # poly *= (x - r_p)
            for i in range(deg + 1, 0, -1):
                poly[i] = poly[i - 1] - r[p] * poly[i]
            poly[0] = -r[p] * poly[0]
            deg += 1
            den *= r[q] - r[p]
        for j in range(P):
            coef[j, q] = poly[j] / den


@numba.njit(cache=True)
def _jtable(z, K, P, J):  # pragma: no cover - compiled
    """``J[k, j] = int_0^1 e^{z s} s^k (1 - s)^j ds`` for ``k < K``, ``j < P``.

    ``J[0, j]`` is :func:`_psi`'s ``I_j(z)``. For ``|z| <= 2`` the power
    series (stopped when the terms fall below rounding): with ``K = 1`` only
    for ``j = P - 1``, the others by the backward recursion
    ``I_{j-1} = (z I_j + 1) / j`` (stable there: it damps errors by
    ``|z| / j``). For ``|z| > 2`` (``K = 1`` only) the forward recursion
    ``I_0 = (e^z - 1) / z``, ``I_j = (j I_{j-1} - 1) / z`` of :func:`_psi`.
    """
    if abs(z) <= 2.0:
        for k in range(K):
            jlo = P - 1 if K == 1 else 0
            for j in range(jlo, P):
                # n = 0 term: k! j! / (k + j + 1)!
                term = 1.0 + 0.0j
                for i in range(1, j + 1):
                    term = term * i / (k + i)
                term = term / (k + j + 1)
                acc = term
                for n in range(200):
                    term = term * z * ((n + k + 1) / ((n + 1) * (n + k + j + 2)))
                    acc += term
                    if term.real * term.real + term.imag * term.imag \
                            <= 1e-34 * (acc.real * acc.real + acc.imag * acc.imag):
                        break
                J[k, j] = acc
        if K == 1:
            for j in range(P - 1, 0, -1):
                J[0, j - 1] = (z * J[0, j] + 1.0) / j
    else:
        ez = np.exp(z)
        prev = (ez - 1.0) / z
        J[0, 0] = prev
        for j in range(1, P):
            prev = (j * prev - 1.0) / z
            J[0, j] = prev


@numba.njit(cache=True)
def modal_loop(t, starts, order, lam, bounds, npow, terms, mirror, drive, d0, xi0,
               out, a0):  # pragma: no cover - compiled
    """Fused non-uniform-grid recursion in the block-modal basis.

    Runs the intervals ``a0 .. a0 + len(out) - 2`` of the grid ``t``
    (stencil starts ``starts``): ``drive`` (rows, N, c) complex is
    ``X^{-1} G v`` at the samples ``d0, d0 + 1, ...``, ``xi0`` (N, c) the
    modal state at ``t[a0]``; fills ``out`` with the modal state at
    ``t[a0], t[a0 + 1], ...``. One pass: per interval the Lagrange coefficients,
    per cluster ``J_{k,j}(lam_c h)``, the transition and drive of the
    cluster, and the update. A singleton cluster flagged in ``mirror`` is
    the complex conjugate of the previous one (conjugate eigenvalue,
    eigenvectors and drive): its state is the conjugate, not recomputed.
    """
    N = xi0.shape[0]
    c = xi0.shape[1]
    P = order + 1
    ncl = lam.shape[0]
    Kmax = npow.shape[0]
    r = np.empty(P)
    coef = np.empty((P, P))
    poly = np.empty(P)
    J = np.empty((Kmax, P), dtype=np.complex128)
    JC = np.empty((Kmax, P), dtype=np.complex128)
    wq = np.empty(P, dtype=np.complex128)
    E = np.empty((N, N), dtype=np.complex128)
    Wm = np.empty((P, N, N), dtype=np.complex128)
    hp = np.empty(Kmax)
    for i in range(N):
        for col in range(c):
            out[0, i, col] = xi0[i, col]
    for a in range(a0, a0 + out.shape[0] - 1):
        h = t[a + 1] - t[a]
        s = starts[a]
        for q in range(P):
            r[q] = (t[s + q] - t[a]) / h
        _lagrange_coef(r, coef, poly)
        for cl in range(ncl):
            b0 = bounds[cl]
            b1 = bounds[cl + 1]
            if mirror[cl]:                  # conjugate of the previous mode
                for col in range(c):
                    out[a + 1 - a0, b0, col] = np.conj(out[a + 1 - a0, b0 - 1, col])
                continue
            K = terms[cl]
            z = lam[cl] * h
            _jtable(z, K, P, J)
            ez = np.exp(z)
            if b1 - b0 == 1 and K == 1:
                for q in range(P):
                    acc = 0.0j
                    for j in range(P):
                        acc += J[0, j] * coef[j, q]
                    wq[q] = acc * h
                for col in range(c):
                    x = ez * out[a - a0, b0, col]
                    for q in range(P):
                        x += wq[q] * drive[s + q - d0, b0, col]
                    out[a + 1 - a0, b0, col] = x
                continue
            hp[0] = 1.0
            for k in range(1, K):
                hp[k] = hp[k - 1] * h
            for k in range(K):                  # JC[k, q] = h^k sum_j J[k, j] coef[j, q]
                for q in range(P):
                    jk = 0.0j
                    for j in range(P):
                        jk += J[k, j] * coef[j, q]
                    JC[k, q] = jk * hp[k]
            for i in range(b0, b1):
                for l in range(b0, b1):
                    e = 0.0j
                    for k in range(K):
                        e += npow[k, i, l] * hp[k]
                    E[i, l] = ez * e
                    for q in range(P):
                        w = 0.0j
                        for k in range(K):
                            w += npow[k, i, l] * JC[k, q]
                        Wm[q, i, l] = w * h
            for col in range(c):
                for i in range(b0, b1):
                    x = 0.0j
                    for l in range(b0, b1):
                        x += E[i, l] * out[a - a0, l, col]
                        for q in range(P):
                            x += Wm[q, i, l] * drive[s + q - d0, l, col]
                    out[a + 1 - a0, i, col] = x
    return out


def modal_bank(F, G, t, v3, order, start):
    """:func:`run_bank` on a non-uniform grid by :func:`modal_loop`, or None.

    ``G`` (N, r), ``v3`` (L, r, c), ``start`` (N, c); returns (L, N, c).
    """
    L = t.shape[0]
    h_max = float(np.max(np.diff(t)))
    form = modal_form(F, h_max)
    if form is None:
        return None
    XG = form.Xi @ G                                        # (N, r)
    xi = (form.Xi @ start).astype(complex)
    starts = stencil_starts(L, order)
    t = np.array(t, dtype=float)                # writable: one compiled kernel signature
    out = np.empty((L, F.shape[0], v3.shape[2]))
    out[0] = start
    P = order + 1
    for a in range(0, L - 1, _MODAL_CHUNK):             # bounded complex work space
        b = min(a + _MODAL_CHUNK, L - 1)
        d0, d1 = int(starts[a]), int(starts[b - 1]) + P
        drive = np.ascontiguousarray(np.einsum("nr,lrc->lnc", XG, v3[d0:d1]))
        part = np.empty((b - a + 1,) + xi.shape, dtype=complex)
        modal_loop(t, starts, order, form.lam, form.bounds, form.npow, form.terms,
                   form.mirror, drive, d0, np.ascontiguousarray(xi), part, a)
        out[a + 1:b + 1] = np.einsum("in,lnc->lic", form.X, part[1:]).real
        xi = part[-1]
    return out


def modal_sensitivity(A, C, t, u, order):
    """:func:`run_sensitivity` on a non-uniform grid in the modal basis of ``A``, or None.

    With ``A = V diag(lam) V^{-1}`` the state response to ``B`` is
    ``x = sum_j V diag(zeta_j) V^{-1} B[:, j]``, ``zeta_j' = lam zeta_j + u_j``
    (n scalar recursions per input), and ``C e^{A (t - t_0)} = C V
    diag(e^{lam (t - t_0)}) V^{-1}``. None when ``V`` is ill-conditioned.
    """
    L, m = u.shape
    n = A.shape[0]
    form = modal_form(A, float(np.max(np.diff(t))), clusters=False)
    if form is None:
        return None
    # a writeable copy (one compiled signature; a broadcast of n = 1 would be read-only)
    drive = np.array(np.broadcast_to(u.astype(complex)[:, None, :], (L, n, m)))
    t = np.array(t, dtype=float)                # writable: one compiled kernel signature
    starts = stencil_starts(L, order)
    zeta = np.empty((L, n, m), dtype=complex)
    modal_loop(t, starts, order, form.lam, form.bounds, form.npow, form.terms, form.mirror,
               drive, 0, np.zeros((n, m), dtype=complex), zeta, 0)
    # Re(sum_l Q_l w_l) with Q_l = (C V)[:, l] (V^{-1})[l, :] as one real product; a
    # mode mirroring its predecessor adds the conjugate: 2 Re(Q_l w_l) for the pair
    keep = ~form.mirror
    twice = np.append(form.mirror[1:], False)[keep]
    Q = ((C @ form.X)[:, None, :] * form.Xi.T[None, :, :]).reshape(-1, n)[:, keep]
    Q = Q * np.where(twice, 2.0, 1.0)
    Qr = np.concatenate([Q.real.T, -Q.imag.T])                              # (2k, ny n)
    ny, k = C.shape[0], int(keep.sum())

    def real_part(w):                    # w (K, k) complex -> Re(Q w) (K, ny n)
        return np.concatenate([w.real, w.imag], axis=1) @ Qr
    zt = zeta[:, keep, :].transpose(0, 2, 1).reshape(L * m, k)
    rows_b = real_part(zt).reshape(L, m, ny, n).transpose(0, 2, 3, 1)
    rows_x = real_part(np.exp(np.outer(t - t[0], form.lam[keep]))).reshape(L, ny, n)
    return np.ascontiguousarray(rows_b), rows_x
