"""B, D, x0 and the validation score of a candidate model from lag products.

The cross-validation of the order (:mod:`subid.methods.dt._selection`) fits B,
D, x0 for every candidate (A, C) on its training fold and scores the model by
its simulation fit on the validation block. Both are least-squares problems
whose data enter only through second moments: for a stable A the forced
response is, up to ``|A^L|``, a FIR of length L,

    y(t) = C A^t x0 + sum_{k=1..L} C A^(k-1) B u(t-k) + D u(t),

so the normal equations need the lag products of the record,

    Γ(e) = sum_s u(s) u(s+e)^T,   R(k) = sum_t y(t) u(t-k)^T,   Y = sum_t y(t) y(t)^T,

(e, k = 0..L), and its first and last L samples. These are computed once per
record (:class:`LagProducts`, by FFT: ``O(N log N)`` whatever L) and shared by
every candidate order, horizon and estimator; each candidate then costs
``O(L n^3)`` flops, independent of N.

**Training fold** (the regression of :func:`subid.methods.dt._regression.fit_b_d_x0`,
parameters ``[x0; vec B; vec D]``, each output weighted by ``w_r``, ``W = diag w``).
With the state sensitivity ``X(t) = sum_{k=1..t} u(t-k)^T kron A^(k-1)``,
``Q = C^T W^2 C`` and ``P = sum_{t>=0} (A^t)^T Q A^t`` (the weighted observability
Gramian, ``P = A^T P A + Q``):

* ``sum_{t<N} X^T Q X = Γ(0) kron P + sum_{e>=1} [Γ(e) kron (A^e)^T P + Γ(e)^T kron P A^e]
  - X(N)^T P X(N)``: the sum over every t of the input zero-padded beyond the
  record is block Toeplitz in the lag products (with ``a = j-1``, ``b = k-1``,
  ``e = a - b``, the inner sum over b is P); the samples ``t >= N`` of that padded
  sum are the free response from ``X(N) = sum_{k=1..L} u(N-k)^T kron A^(k-1)``, which
  the last L samples give exactly;
* ``sum_t X^T C^T W^2 (u^T kron I) = sum_{k>=1} Γ(k) kron (C A^(k-1))^T W^2`` and
  ``sum_t X^T C^T W^2 y = sum_{k>=1} vec((C A^(k-1))^T W^2 R(k))``: no edge term
  (the D and y rows stop at N themselves);
* the D block ``Γ(0) kron W^2`` and ``vec(W^2 R(0))``;
* the x0 rows, ``C A^t`` negligible after L samples: ``sum_t (A^t)^T Q A^t = P``,
  ``sum_t (A^t)^T Q X(t) = sum_s u(s)^T kron (A^(s+1))^T P`` (s < L),
  ``sum_t (A^t)^T C^T W^2 (u(t)^T kron I)`` and ``sum_t (A^t)^T C^T W^2 y(t)``
  over the first L samples.

The augmented normal matrix is solved by
:func:`subid.methods.dt._regression.solve_normal_equations` with the guards of the
modal path (the same problem it solves by a pass over the record).

**Validation score** (:func:`subid.methods.dt._scoring.simulation_fit`): per output r,
the error power ``sum_t (y_r - y_f,r)^2`` of the forced response ``y_f`` (zero initial
state) is ``Y_rr - 2 sum_k (R(k) G_k^T)_rr + (sum_t y_f y_f^T)_rr`` with the Markov
parameters ``G_0 = D``, ``G_k = C A^(k-1) B``; ``sum_t y_f y_f^T = C X C^T + C S_D +
S_D^T C^T + D Γ(0) D^T`` minus the free response after the record, where ``S_D =
sum_{k>=1} A^(k-1) B Γ(k) D^T`` and ``X = sum_b A^b S A^(b)T`` with ``S = sum_{e>=0}
A^e B Γ(e) B^T + sum_{e>=1} B Γ(e)^T B^T (A^e)^T`` (the same block-Toeplitz sum).
The least-squares x0 involves the first L samples only: they are simulated by the
compiled kernel of :mod:`subid.methods.dt._scoring`, and their rows reduced exactly
as there; the error power of the other samples is the total minus that of the first
L.

**Where it does not apply** the callers take the per-candidate passes: an unstable
A, or one whose ``|A^L|`` (max entry, by repeated squaring) stays above
:data:`LAG_TOLERANCE` for L up to the record's cap (:data:`MAX_LAG`, and a quarter of
the record); a regression or error power whose value the normal equations leave to
rounding (nearly exact fits, :data:`ROUNDING_GUARD`), where the direct passes are
exact; records of several experiments.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft
import scipy.linalg

from subid.methods.dt._regression import (
    RESIDUAL_RECOMPUTE,
    parameter_count,
    solve_normal_equations,
)

#: ``|A^L|`` (max entry; A in any basis of a normalised problem) below which the terms
#: past L lags are dropped: below rounding relative to the data.
LAG_TOLERANCE = 1e-16
#: Largest lag L used (the lag products are computed up to min(MAX_LAG, N // 4)).
MAX_LAG = 4096
#: An error power below this fraction of the output's power is rounding-limited in
#: the quadratic form (cancellation): the direct pass computes it instead.
ROUNDING_GUARD = 1e-6


def correlations(u, y, max_lag):
    """``(Γ, R, Y)``: ``Γ[e] = sum_s u(s) u(s+e)^T`` (nu, nu), ``R[k] = sum_t y(t) u(t-k)^T``
    (ny, nu) for lags 0..max_lag (by FFT, the lag 0 terms directly) and ``Y = y^T y``."""
    N = u.shape[0]
    nfft = scipy.fft.next_fast_len(N + max_lag + 1, real=True)
    U = scipy.fft.rfft(u, nfft, axis=0)
    Uc = np.conj(U)
    Yf = scipy.fft.rfft(y, nfft, axis=0)
    G = scipy.fft.irfft(Uc[:, :, None] * U[:, None, :], nfft, axis=0)[:max_lag + 1]
    R = scipy.fft.irfft(Yf[:, :, None] * Uc[:, None, :], nfft, axis=0)[:max_lag + 1]
    G[0] = u.T @ u
    R[0] = y.T @ u
    return np.ascontiguousarray(G), np.ascontiguousarray(R), y.T @ y


def correlations_reference(u, y, max_lag):
    """Plain sums behind :func:`correlations` (the tests compare them)."""
    N, nu = u.shape
    ny = y.shape[1]
    G = np.zeros((max_lag + 1, nu, nu))
    R = np.zeros((max_lag + 1, ny, nu))
    for e in range(max_lag + 1):
        G[e] = u[:N - e].T @ u[e:]
        R[e] = y[e:].T @ u[:N - e]
    return G, R, y.T @ y


class LagProducts:
    """The lag products of one record (:func:`correlations`) up to ``max_lag``, and the
    record itself (its first and last samples enter the edge terms)."""

    def __init__(self, u, y, max_lag=MAX_LAG):
        self.u = np.ascontiguousarray(u, dtype=float)
        self.y = np.ascontiguousarray(y, dtype=float)
        self.n_samples = self.u.shape[0]
        self.max_lag = max(min(int(max_lag), self.n_samples // 4), 0)
        self.G, self.R, self.Y = correlations(self.u, self.y, self.max_lag)

    @classmethod
    def of_record(cls, record, max_lag=MAX_LAG):
        """The lag products of an IOData record of one experiment, else None."""
        if getattr(record, "n_experiments", 1) != 1:
            return None
        return cls(record.u, record.y, max_lag)


def decay_length(A, cap):
    """The smallest power of two L with ``max |A^L| < LAG_TOLERANCE`` (by repeated
    squaring), or None when it exceeds ``cap`` (or A is not finite)."""
    n = A.shape[0]
    if n == 0:
        return 1
    P = np.array(A, dtype=float)
    L = 1
    with np.errstate(all="ignore"):
        while L <= cap:
            size = np.abs(P).max()
            if not math.isfinite(size):
                return None
            if size < LAG_TOLERANCE:
                return L
            P = P @ P
            L *= 2
    return None


def powers(A, L):
    """``A^0 .. A^L`` stacked (L + 1, n, n), by doubling (one batched product a step)."""
    n = A.shape[0]
    out = np.empty((L + 1, n, n))
    out[0] = np.eye(n)
    if L >= 1:
        out[1] = A
    filled = 2
    while filled < L + 1:
        step = out[filled - 1] @ A                  # A^filled
        k = min(filled, L + 1 - filled)
        out[filled:filled + k] = out[:k] @ step
        filled += k
    return out


class _Candidate:
    """The powers, Markov rows and Gramian of a stable (A, C) up to lag L."""

    def __init__(self, A, C, L, w2):
        self.L = L
        self.Pw = powers(A, L)                       # A^t, t = 0..L
        self.H = np.matmul(C, self.Pw)               # C A^t (L + 1, ny, n)
        self.HW2 = self.H * w2[None, :, None]
        n = A.shape[0]
        self.P = self.HW2.reshape(-1, n).T @ self.H.reshape(-1, n) if n else np.zeros((0, 0))
        self.P = 0.5 * (self.P + self.P.T)


def _lag(A, lags_available):
    return decay_length(A, lags_available) if np.isfinite(A).all() else None


def fit_b_d_x0(A, C, lp: LagProducts, output_weights, *, feedthrough=True, estimate_x0=True):
    """B, D, x0 and diagnostics of the output regression of (A, C) on the record of
    ``lp`` (the problem of :func:`subid.methods.dt._regression.fit_b_d_x0`), from its
    lag products (module documentation), or None where they do not apply (then the
    per-candidate pass must run)."""
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    n, ny, nu = A.shape[0], C.shape[0], lp.u.shape[1]
    N = lp.n_samples
    L = _lag(A, lp.max_lag)
    if L is None or L > lp.max_lag or N < 4 * L or n == 0:
        return None
    w = np.ones(ny) if output_weights is None else np.asarray(output_weights, dtype=float)
    w2 = w * w
    c = _Candidate(A, C, L, w2)
    Pw, H, HW2, P = c.Pw, c.H, c.HW2, c.P
    G, R = lp.G[:L + 1], lp.R[:L + 1]
    u, y = lp.u, lp.y
    K = np.matmul(P, Pw)                             # P A^e
    # B block: Γ(e) kron (A^e)^T P (e >= 0) + Γ(e)^T kron P A^e (e >= 1), index a n + i
    BB = np.tensordot(G, K, axes=(0, 0)).transpose(0, 3, 1, 2) \
        + np.tensordot(G[1:], K[1:], axes=(0, 0)).transpose(1, 2, 0, 3)
    BB = BB.reshape(nu * n, nu * n)
    urev = u[N - 1:N - 1 - L:-1]                     # u(N-1) .. u(N-L)
    XN = np.tensordot(urev, Pw[:L], axes=(0, 0))     # (a, i, j): sum_k u_a(N-k) A^(k-1)
    XN = XN.transpose(1, 0, 2).reshape(n, nu * n)
    BB -= XN.T @ P @ XN
    rB = np.tensordot(R[1:], HW2[:L], axes=([0, 1], [0, 1])).reshape(-1)   # (a, i)
    nx, q, p = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    Naug = np.zeros((p + 1, p + 1))
    Naug[nx:q, nx:q] = BB
    Naug[nx:q, p] = rB
    Naug[p, p] = float(np.sum(w2 * np.diag(lp.Y)))
    if feedthrough:
        BD = np.tensordot(G[1:], HW2[:L], axes=(0, 0)).transpose(0, 3, 1, 2)  # (a, i, b, r)
        Naug[nx:q, q:p] = BD.reshape(nu * n, nu * ny)
        Naug[q:p, q:p] = np.kron(G[0], np.diag(w2))
        Naug[q:p, p] = (R[0] * w2[:, None]).T.reshape(-1)
    if estimate_x0:
        S1 = np.tensordot(u[:L], Pw[1:L + 1], axes=(0, 0))   # (a, i, j): sum_s u_a(s) A^(s+1)
        Naug[:n, :n] = P
        Naug[:n, nx:q] = np.concatenate([S1[a].T @ P for a in range(nu)], axis=1)
        Naug[:n, p] = np.tensordot(y[:L + 1], HW2, axes=([0, 1], [0, 1]))
        if feedthrough:
            x0D = np.tensordot(u[:L + 1], HW2, axes=(0, 0))       # (b, r, i)
            Naug[:n, q:p] = x0D.transpose(2, 0, 1).reshape(n, nu * ny)
    iu = np.triu_indices(p + 1, 1)
    Naug[(iu[1], iu[0])] = Naug[iu]
    solved = solve_normal_equations(Naug, n, nu, ny, estimate_x0=estimate_x0,
                                    feedthrough=feedthrough, n_samples=N)
    if solved is None:
        return None
    B, D, x0, _, diagnostics = solved
    if diagnostics["residual_rms"] ** 2 * N * ny < RESIDUAL_RECOMPUTE * Naug[p, p]:
        return None                  # a nearly exact fit: the residual is rounding here
    diagnostics["regression_path"] = "lag products"
    diagnostics["lags"] = L
    return B, D, x0, diagnostics


def error_power(A, B, C, D, lp: LagProducts, weights, inv_scale, kernel):
    """``sum_t ((y - ŷ) inv_scale)^2`` per output on the record of ``lp``, ``ŷ`` simulated
    from the least-squares x0 (weights ``weights``), as
    :func:`subid.methods.dt._scoring._error_power` computes it by a pass over the
    record; None where the lag products do not apply (the pass must run)."""
    from subid.methods.dt._scoring import head_power
    A = np.asarray(A, dtype=float)
    n, ny, nu = A.shape[0], C.shape[0], B.shape[1]
    N = lp.n_samples
    L = _lag(A, lp.max_lag)
    if L is None or L > lp.max_lag or N < 2 * L or n == 0:
        return None
    c = _Candidate(A, C, L, np.ones(ny))
    Pw, H = c.Pw, c.H
    G, R = lp.G[:L + 1], lp.R[:L + 1]
    # Markov parameters G_0 = D, G_k = C A^(k-1) B (k = 1..L)
    M = np.empty((L + 1, ny, nu))
    M[0] = D
    M[1:] = np.matmul(H[:L], B)
    cross = np.einsum("krj,krj->r", R, M)                  # sum_t y_r y_f,r
    # sum_t y_f y_f^T over the zero-padded record (t >= 0)
    BG = np.matmul(B, G)                                   # B Γ(e) (L + 1, n, nu)
    T = np.matmul(np.matmul(Pw, BG), B.T)                  # A^e B Γ(e) B^T
    S = T.sum(axis=0) + T[1:].sum(axis=0).T   # e >= 1 also as B Γ(e)^T B^T (A^e)^T
    X = np.tensordot(np.matmul(Pw, S), Pw, axes=([0, 2], [0, 2]))   # sum_b A^b S (A^b)^T
    SD = np.tensordot(Pw[:L], BG[1:], axes=([0, 2], [0, 1])) @ D.T  # sum_k A^(k-1) B Γ(k) D^T
    F = C @ X @ C.T + C @ SD + SD.T @ C.T + D @ G[0] @ D.T
    # minus the free response after the record, from x_f(N) = sum_k A^(k-1) B u(N-k)
    urev = lp.u[N - 1:N - 1 - L:-1]
    xN = np.einsum("kij,jb,kb->i", Pw[:L], B, urev)
    after = np.sum((H @ xN) ** 2, axis=0)
    ff = np.diag(F) - after
    total = np.diag(lp.Y) - 2.0 * cross + ff               # sum_t (y - y_f)^2 per output
    if not np.isfinite(total).all() or np.any(total < ROUNDING_GUARD * np.diag(lp.Y)):
        return None
    head = head_power(A, B, C, D, lp.u[:L], lp.y[:L], weights, inv_scale, kernel, N)
    if head is None:
        return None
    head_resid, head_forced = head
    return (total - head_forced) * inv_scale ** 2 + head_resid
