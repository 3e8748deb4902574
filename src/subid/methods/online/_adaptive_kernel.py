"""Per-sample recursion of :class:`subid.methods.online.adaptive.AdaptiveIdentifier` (seed 000).

Two implementations of the same recursion operate in place on the same state
arrays:

* :func:`kernel` — the compiled (numba) loop used by the identifier (called
  through :func:`kernel_packed`);
* :func:`subid.methods.online._adaptive_reference.reference` — a plain numpy
  loop written for readability, kept as the reference the tests compare the
  kernel against (agreement to 1e-12).

Everything here trusts its inputs: validation happens in
:mod:`subid.methods.online.adaptive`. Notation follows the paper (Afri, Bako, Andrieu,
Dufour, CDC 2015); ``^`` marks the time-scaled filter coordinates described
in :mod:`subid.methods.online.adaptive`.

One step from sample ``k-1`` to sample ``k`` (interval ``h``, table entry
``q = idx[k]``):

1. state-variable filters (6a)-(6b), exact discretisation for the held
   signals: ``z_k = Fphi z_{k-1} + Fg0 w_{k-1} + Fg1 w_k`` per channel (and
   the instrument filter on the input, ``iv`` mode); after a gap longer than
   ``max_gap`` the filters restart at the steady state of the new sample;
2. regression (8) ``p̂ = M φ̂``: information-form update of the weighted
   normal equations (``iv`` mode: of the instrumental-variable equations
   with the whitening matrix Z; an Euler step of (11)-(12) in ``ode`` mode);
3. once part 2 has started: Ξ = C̃ e^{Ã(t - t_g)} and Ψ of (15), exact
   discretisation for the held input with the accepted ``(Apsi, Cpsi)``:
   ``Ξ <- Ξ e^{Ã h}``, ``Ψ_j <- Ψ_j e^{Ã h} + u_j[k-1] C̃ G0 + u_j[k] C̃ G1``;
   regression (14)/(16) ``y = [Ξ, Ψ, u^T ⊗ I] [x̃(t_g); vec B̃; vec D]``:
   same update (or an Euler step of (19)-(20));
4. every ``K`` steps a refresh: solve the regularised normal equations,
   (Ã, C̃) by (13) with its shift residual, (B̃, D) from θ; accept (Ã, C̃)
   for Ψ if Ã is Hurwitz and the residual is below the gate (or within a
   factor 2 of its best value once it has stopped improving for 1/α); the
   first acceptance starts part 2 with Ψ = 0, Ξ = C̃; append to the
   history.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["kernel", "kernel_packed", "pack_tables", "phi_blocks", "state_layout", "IST", "FST"]

# Integer state ``ist`` (int64 array) slots.
IST = {
    "samples": 0,       # samples seen
    "refreshes": 1,     # refreshes done
    "hist_count": 2,    # history rows in use
    "hist_stride": 3,   # refreshes between history rows
    "psi_rejected": 4,  # refreshes whose Ã was not Hurwitz (Ψ kept the last one)
    "shift_failed": 5,  # refreshes where (13) was rank deficient (model kept)
    "psi_version": 6,   # incremented whenever (Apsi, Cpsi) change
    "chol_failed": 7,   # refreshes where a Cholesky factorisation failed
    "bound_hits": 8,    # ode mode: steps where the trace bound suspended forgetting
    "started": 9,       # 1 once part 2 ((B̃, D) estimation) has started
    "stalled": 10,      # 1 once the residual of (13) has stopped improving
    "rejected": 11,     # 1 if the last refresh's (Ã, C̃) failed the gate / Hurwitz test
    "gaps": 12,         # intervals longer than max_gap (filters re-initialised)
    "not_excited": 13,  # 1 if the last refresh found (8) not persistently exciting
}
N_IST = 14
# Float state ``fst`` slots.
FST = {
    "t_last": 0,          # time of the last sample
    "t_start": 1,         # time part 2 started (0 before)
    "shift_residual": 2,  # relative residual of (13) at the last refresh (-1: failed)
    "scale_M": 3,         # deferred forgetting: true (R, S) = scale_M * stored
    "scale_theta": 4,     # the same for (R_θ, s_θ)
    "res_ref": 5,         # best residual of (13), updated when it halves
    "t_ref": 6,           # time of the last halving
    "t_resume": 7,        # after a gap: (8) gets no weight before this time
    "t_first": 8,         # time of the first sample (the stall rule's clock)
}
N_FST = 9


def state_layout(n: int, nu: int, ny: int, f: int, mi: int) -> list:
    """The layout table of the float state buffer: ``(name, shape)`` per
    array, in the order of :func:`kernel`'s arguments ``fst`` ... ``Zz``
    (the index of :func:`kernel_packed`'s ``lay``; ``Ev`` last). Order n, inputs nu,
    outputs ny, filter order f, instrument filter order mi."""
    d, dp, dth = n + f * nu, f * ny, n + n * nu + ny * nu
    dz = (f + mi) * nu + n
    return [("fst", (N_FST,)), ("prev_u", (nu,)), ("prev_y", (ny,)),
            ("zp", (f, ny)), ("zq", (f, nu)),
            ("R", (d, d)),        # information matrix of (8) ('ode': P)
            ("G", (dp, d)),       # S - M R: residual form of the cross term
            ("M", (dp, d)),
            ("Rt", (dth, dth)),   # information matrix of (16) ('ode': Q)
            ("g", (1, dth)),      # s_θ - R_θ θ
            ("theta", (1, dth)),  # [x̃(t_g); vec B̃; vec D]
            ("Am", (n, n)), ("Cm", (ny, n)), ("Bm", (n, nu)), ("Dm", (ny, nu)),
            ("Apsi", (n, n)), ("Cpsi", (ny, n)),
            ("Psi", (ny, n + n * nu)),   # [Ξ, Ψ]
            ("zr", (mi, nu)),     # instrument filter ('iv')
            ("xi", (1, n)),       # auxiliary-model instrument ('iv')
            ("Cz", (dz, n)),      # IV cross matrix sum w ζ φ^T, first n columns
                                  # (the others are columns of Zz) ('iv')
            ("Gz", (dp, dz)),     # S_ζ - M Cz^T ('iv')
            ("Zz", (dz, dz)),     # sum w ζ ζ^T, the IV weighting ('iv')
            ("Ev", (1, 2 * ny + 1))]  # Σ λ h (y - Φ θ)^2 per output of (16), Σ λ h y^2,
                                      # Σ λ h


# Part 2 also starts when the residual of (13) is below this value and has
# stopped halving (converged to its noise floor): no halving during
# min(1/α, max(t_ref - t_first, settle)) since the last one at t_ref. A
# consistent estimate whose memory still grows (t < 1/α) has a noise floor
# falling like t^{-1/2}: it halves at 4 t_ref, so the window of one elapsed
# time (t_ref - t_first) detects the stall at ~2 t_ref, whatever the memory;
# one memory length 1/α (issue 12) never fired within a record shorter than
# 1/α. From then on Ψ accepts models within a factor _STALL_FACTOR of the
# best residual.
_STALL_MAX = 0.25
_STALL_FACTOR = 2.0

# Floating-point contraction of a*b + c into fused multiply-adds only (no
# reassociation; NaN and inf keep their IEEE semantics): 10-20% faster.
_FASTMATH = {"contract"}

# Inverse iterations of the excitation test (:func:`_weakest`).
_EXCITATION_ITERATIONS = 8

# Relative pivot threshold of the QR factor in (13): below it the shift
# equation is rank deficient and the previous (Ã, C̃) are kept.
SHIFT_RANK_TOL = 1e-12
# Taylor series of the exponential blocks: largest number of terms and the
# 1-norm of A*tau after scaling.
_TAYLOR_TERMS = 20
_TAYLOR_NORM = 0.5
# Largest order tested for stability by a Lyapunov equation (n(n+1)/2
# unknowns); larger orders use eigenvalues.
_LYAP_MAX_ORDER = 6
# The deferred forgetting factor is folded back into the accumulators when it
# falls below this value (keeps them bounded).
_RESCALE_BELOW = 1e-100
# A folded forgetting factor below this (a gap of hundreds of memory lengths)
# is total forgetting: the matrices are zeroed rather than scaled into
# subnormal numbers, whose lost precision would leave garbage behind.
_FORGOTTEN = 1e-250


# ---------------------------------------------------------------------------
# small dense helpers (compiled; the reference uses numpy/scipy instead)
# ---------------------------------------------------------------------------
@numba.njit(cache=True, fastmath=_FASTMATH)
def phi_blocks(A, h, Phi, G1, G2, work):  # pragma: no cover - compiled
    """Exact discretisation blocks of ``x' = A x + v`` over ``h``.

    ``Phi = e^{A h}``, ``G1 = int_0^h e^{A s} ds`` and
    ``G2 = (1/h) int_0^h e^{A s} (h - s) ds`` (the conventions of
    :func:`subid.model._simulate.expm_blocks` with ``B = I``), by a Taylor series
    after scaling ``h`` down to ``||A tau||_1 <= 0.5`` and squaring back with
    ``Phi(2t) = Phi^2``, ``G1(2t) = (I + Phi) G1``,
    ``G2'(2t) = (I + Phi) G2' + t G1`` (``G2' = int e^{As}(t-s) ds``).
    ``work``: scratch of shape (5, n, n).
    """
    n = A.shape[0]
    norm = 0.0
    for j in range(n):
        s = 0.0
        for i in range(n):
            s += abs(A[i, j])
        if s > norm:
            norm = s
    norm *= h
    squarings = 0
    while norm > _TAYLOR_NORM:
        norm *= 0.5
        squarings += 1
    tau = h
    for _ in range(squarings):
        tau *= 0.5
    T = work[0]
    Tn = work[1]
    for i in range(n):
        for j in range(n):
            Phi[i, j] = 0.0
            G1[i, j] = 0.0
            G2[i, j] = 0.0
            T[i, j] = 1.0 if i == j else 0.0
    # terms: the first K with norm^K / K! below 1e-18 (at most _TAYLOR_TERMS)
    terms = 1
    bound = 1.0
    while terms < _TAYLOR_TERMS and bound > 1e-18:
        bound *= norm / terms
        terms += 1
    for k in range(terms):
        c1 = tau / (k + 1.0)
        c2 = tau * tau / ((k + 1.0) * (k + 2.0))
        for i in range(n):
            for j in range(n):
                t = T[i, j]
                Phi[i, j] += t
                G1[i, j] += c1 * t
                G2[i, j] += c2 * t
        if k + 1 < terms:
            ck = tau / (k + 1.0)
            for i in range(n):
                for j in range(n):
                    Tn[i, j] = 0.0
                for l in range(n):
                    t = T[i, l] * ck
                    for j in range(n):
                        Tn[i, j] += t * A[l, j]
            for i in range(n):
                for j in range(n):
                    T[i, j] = Tn[i, j]
    P1 = work[2]
    N1 = work[3]
    N2 = work[4]
    for _ in range(squarings):
        for i in range(n):
            for j in range(n):
                P1[i, j] = 0.0
                N1[i, j] = G1[i, j]
                N2[i, j] = G2[i, j] + tau * G1[i, j]
            for l in range(n):
                x = Phi[i, l]
                for j in range(n):
                    P1[i, j] += x * Phi[l, j]
                    N1[i, j] += x * G1[l, j]
                    N2[i, j] += x * G2[l, j]
        for i in range(n):
            for j in range(n):
                Phi[i, j] = P1[i, j]
                G1[i, j] = N1[i, j]
                G2[i, j] = N2[i, j]
        tau *= 2.0
    for i in range(n):
        for j in range(n):
            G2[i, j] /= h


@numba.njit(cache=True, fastmath=_FASTMATH)
def _chol(R, delta, L):  # pragma: no cover - compiled
    """Lower Cholesky factor of ``R + delta I`` (lower triangle of R read).
    Returns False (L unusable) if a pivot is not positive."""
    d = R.shape[0]
    for j in range(d):
        s = R[j, j] + delta
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        ljj = np.sqrt(s)
        L[j, j] = ljj
        for i in range(j + 1, d):
            s = R[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / ljj
        for i in range(j):
            L[i, j] = 0.0
    return True


@numba.njit(cache=True, fastmath=_FASTMATH)
def _solve_normal(R, G, X, max_cond, L, B):  # pragma: no cover - compiled
    """One refresh of a least-squares estimate held in residual form.

    ``R`` (lower triangle) is the information matrix and ``G = S - X R`` the
    gradient of the cost at the current estimate X (S: the cross term).
    Computes ``Δ = G (R + δ I)^{-1}``, ``δ = tr(R)/max_cond``, then
    ``X <- X + Δ`` (i.e. ``X = (S + δ X)(R + δ I)^{-1}``) and re-centres
    ``G <- G - Δ R``. The windup bound: ``cond(R + δ I) <= 1 + max_cond``,
    and X is kept in directions R no longer informs. G, X: (rows, d);
    L (d, d), B (d, rows): scratch. Returns False (nothing changed) when
    tr(R) <= 0 or the Cholesky factorisation fails.
    """
    d = R.shape[0]
    rows = G.shape[0]
    tr = 0.0
    for i in range(d):
        tr += R[i, i]
    if not tr > 0.0:
        return False
    delta = tr / max_cond
    if not _chol(R, delta, L):
        return False
    for i in range(d):
        for r in range(rows):
            B[i, r] = G[r, i]
    for i in range(d):                      # L Z = G^T
        for k in range(i):
            lik = L[i, k]
            for r in range(rows):
                B[i, r] -= lik * B[k, r]
        inv = 1.0 / L[i, i]
        for r in range(rows):
            B[i, r] *= inv
    for i in range(d - 1, -1, -1):          # L^T Δ^T = Z
        for k in range(i + 1, d):
            lki = L[k, i]
            for r in range(rows):
                B[i, r] -= lki * B[k, r]
        inv = 1.0 / L[i, i]
        for r in range(rows):
            B[i, r] *= inv
    for r in range(rows):
        for i in range(d):
            X[r, i] += B[i, r]
    for i in range(d):                      # G <- G - Δ R (R symmetric, lower stored)
        for j in range(d):
            rij = R[i, j] if j <= i else R[j, i]
            for r in range(rows):
                G[r, j] -= B[i, r] * rij
    return True


@numba.njit(cache=True, fastmath=_FASTMATH)
def _weakest(X, L, delta, v, w):  # pragma: no cover - compiled
    """Excitation of the information matrix X (lower triangle read):
    ``λ_min(X) / tr(X)``, by inverse iteration with the Cholesky factor L of
    ``X + δ I`` (from the solve just done): ``_EXCITATION_ITERATIONS`` steps
    from a fixed start, then ``λ_min(X + δ I) ≈ 1 / |(L L^T)^{-1} v|`` (an
    upper bound of λ_min for a unit v), minus δ. v, w: scratch of length d."""
    d = X.shape[0]
    tr = 0.0
    for i in range(d):
        tr += X[i, i]
        v[i] = 1.0 + 0.5 * np.sin(i + 1.0)
    nrm = _normalise(v)
    for _ in range(_EXCITATION_ITERATIONS):
        for i in range(d):                   # L w = v
            s = v[i]
            for k in range(i):
                s -= L[i, k] * w[k]
            w[i] = s / L[i, i]
        for i in range(d - 1, -1, -1):       # L^T v = w
            s = w[i]
            for k in range(i + 1, d):
                s -= L[k, i] * v[k]
            v[i] = s / L[i, i]
        nrm = _normalise(v)
    return (1.0 / nrm - delta) / tr


@numba.njit(cache=True, fastmath=_FASTMATH)
def _normalise(v):  # pragma: no cover - compiled
    """Scale v to unit 2-norm in place; returns the norm it had."""
    nrm = 0.0
    for i in range(v.shape[0]):
        nrm += v[i] * v[i]
    nrm = np.sqrt(nrm)
    for i in range(v.shape[0]):
        v[i] /= nrm
    return nrm


@numba.njit(cache=True, fastmath=_FASTMATH)
def _solve_iv_weighted(C, G, Z, X, max_cond, L, Ct, Gt, N, Gn, Ln, Bn, ex):  # pragma: no cover
    """One refresh of an instrumental-variable estimate in residual form,
    with the instruments whitened by ``Z = sum w ζ ζ^T`` (lower triangle).

    ``C`` (dz, d), dz >= d, is the cross matrix ``sum w ζ φ^T`` of the
    instruments and the regressors, ``G = S - X C^T`` (rows, dz) the residual
    of the (extended) IV equations ``X C^T = S`` at the current estimate X.
    With ``Z + ε I = L L^T`` (``ε = tr Z / max_cond``, so that the whitening
    cannot amplify directions the instruments no longer excite by more than
    ``sqrt(max_cond)``), ``C̃ = L^{-1} C`` and ``G̃ = G L^{-T}``, the step
    ``Δ = argmin |Δ C̃^T - G̃|_F^2 + δ |Δ|_F^2``, ``δ = |C̃|_F^2 /
    max_cond^2`` (the windup bound on C̃ itself): without δ the two-stage
    least-squares weighting of the extended IV equations, ``M = S Z^{-1} C
    (C^T Z^{-1} C)^{-1}``. It is solved by :func:`_solve_normal` on the
    normal equations ``(N + δ I) Δ^T = G_N^T``, ``N = C̃^T C̃``, ``G_N = G̃
    C̃`` (the gradient at X); if their Cholesky factorisation fails (cond(C̃)
    near 1e8, at start-up), with the least-squares path's bound ``δ = tr N /
    max_cond`` instead. Then ``G <- G - Δ C^T``. Solving
    the normal equations squares the condition number of C̃, but in residual
    form the error of a step is only a fraction of the step, and the next
    refresh starts from the exactly re-centred residual G (iterative
    refinement), so the estimate converges to the solution of the IV
    equations to rounding of the residual.

    Scratch: L (dz, dz), Ct (dz, d), Gt (rows, dz), N, Ln (d, d), Gn (rows,
    d), Bn (d, rows). Returns False (nothing changed) if Z or N is not
    positive definite; ``ex[0]`` receives the excitation ``λ_min(N) / tr N``
    (:func:`_weakest`; ``ex`` has length >= 2 d, the rest scratch).
    """
    dz, d = C.shape
    rows = G.shape[0]
    tr = 0.0
    for i in range(dz):
        tr += Z[i, i]
    if not tr > 0.0:
        return False
    if not _chol(Z, tr / max_cond, L):
        return False
    for i in range(dz):                      # Ct = L^{-1} C (row by row)
        for j in range(d):
            Ct[i, j] = C[i, j]
        for k in range(i):
            lik = L[i, k]
            for j in range(d):
                Ct[i, j] -= lik * Ct[k, j]
        inv = 1.0 / L[i, i]
        for j in range(d):
            Ct[i, j] *= inv
    for r in range(rows):                    # Gt = G L^{-T}
        for i in range(dz):
            s = G[r, i]
            for k in range(i):
                s -= L[i, k] * Gt[r, k]
            Gt[r, i] = s / L[i, i]
    for i in range(d):                       # N = Ct^T Ct (lower), Gn = Gt Ct
        for j in range(i + 1):
            N[i, j] = 0.0
    for r in range(rows):
        for j in range(d):
            Gn[r, j] = 0.0
    for k in range(dz):
        for i in range(d):
            cki = Ct[k, i]
            for j in range(i + 1):
                N[i, j] += cki * Ct[k, j]
        for r in range(rows):
            g = Gt[r, k]
            for j in range(d):
                Gn[r, j] += g * Ct[k, j]
    # δ = tr N / max_cond^2 = |C̃|_F^2 / max_cond^2: the windup bound on C̃
    # itself (cond(C̃) <= max_cond), the same step as a QR of [C̃; sqrt(δ) I];
    # if N + δ I is numerically singular for Cholesky (start-up, cond(C̃) near
    # 1e8), the LS path's bound cond(N + δ I) <= 1 + max_cond instead
    scale = max_cond * max_cond
    if not _solve_normal(N, Gn, X, scale, Ln, Bn):
        scale = max_cond
        if not _solve_normal(N, Gn, X, scale, Ln, Bn):
            return False
    trn = 0.0
    for i in range(d):
        trn += N[i, i]
    ex[0] = _weakest(N, Ln, trn / scale, ex[1:1 + d], ex[1 + d:1 + 2 * d])
    for r in range(rows):                    # G <- G - Δ C^T (Bn holds Δ^T)
        for i in range(dz):
            s = 0.0
            for j in range(d):
                s += Bn[j, r] * C[i, j]
            G[r, i] -= s
    return True


@numba.njit(cache=True, fastmath=_FASTMATH)
def _hurwitz(A):  # pragma: no cover - compiled
    """True if every eigenvalue of A has a negative real part.

    For n <= _LYAP_MAX_ORDER: A is Hurwitz iff ``A^T P + P A = -I`` has a
    (unique) solution P that is positive definite (Lyapunov; the solution
    over the n(n+1)/2 entries of the symmetric P by Gaussian elimination with
    partial pivoting, definiteness by Cholesky). Otherwise by eigenvalues.
    """
    n = A.shape[0]
    if n > _LYAP_MAX_ORDER:
        ev = np.linalg.eigvals(A.astype(np.complex128))
        for k in range(n):
            if not ev[k].real < 0.0:
                return False
        return True
    m = n * (n + 1) // 2
    pos = np.empty((n, n), dtype=np.int64)
    c = 0
    for i in range(n):
        for j in range(i, n):
            pos[i, j] = c
            pos[j, i] = c
            c += 1
    Lm = np.zeros((m, m + 1))
    big = 0.0
    for i in range(n):
        for j in range(i, n):
            e = pos[i, j]
            # (A^T P + P A)_{ij} = sum_k A_ki P_kj + P_ik A_kj
            for k in range(n):
                Lm[e, pos[k, j]] += A[k, i]
                Lm[e, pos[i, k]] += A[k, j]
            Lm[e, m] = -1.0 if i == j else 0.0
    for e in range(m):
        for f in range(m):
            if abs(Lm[e, f]) > big:
                big = abs(Lm[e, f])
    if not big > 0.0:
        return False
    for col in range(m):
        piv = col
        for r in range(col + 1, m):
            if abs(Lm[r, col]) > abs(Lm[piv, col]):
                piv = r
        if not abs(Lm[piv, col]) > 1e-13 * big:
            return False
        if piv != col:
            for f in range(m + 1):
                tmp = Lm[col, f]
                Lm[col, f] = Lm[piv, f]
                Lm[piv, f] = tmp
        for r in range(col + 1, m):
            fac = Lm[r, col] / Lm[col, col]
            if fac != 0.0:
                for f in range(col, m + 1):
                    Lm[r, f] -= fac * Lm[col, f]
    sol = np.empty(m)
    for r in range(m - 1, -1, -1):
        s = Lm[r, m]
        for f in range(r + 1, m):
            s -= Lm[r, f] * sol[f]
        sol[r] = s / Lm[r, r]
    P = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            P[i, j] = sol[pos[i, j]]
    Lc = np.empty((n, n))
    return _chol(P, 0.0, Lc)


@numba.njit(cache=True, fastmath=_FASTMATH)
def _shift_solve(M, n, ny, omega, Aout):  # pragma: no cover - compiled
    """(13): Ã = ω [M11; M21]^† [M21; M31] by Householder QR.

    Returns the relative residual ``||W - U X||_F / ||W||_F`` of the shift
    equation ``U X = W`` (U = [M11; M21], W = [M21; M31]), or -1 when U is
    rank deficient (relative pivot below SHIFT_RANK_TOL; Aout untouched).
    """
    dp = M.shape[0]
    m = dp - ny
    U = np.empty((m, n))
    W = np.empty((m, n))
    for i in range(m):
        for j in range(n):
            U[i, j] = M[i, j]
            W[i, j] = M[i + ny, j]
    diag = np.empty(n)
    v = np.empty(m)
    for k in range(n):
        norm2 = 0.0
        for i in range(k, m):
            norm2 += U[i, k] * U[i, k]
        nrm = np.sqrt(norm2)
        if nrm == 0.0:
            diag[k] = 0.0
            continue
        alpha = -nrm if U[k, k] >= 0.0 else nrm
        for i in range(k, m):
            v[i] = U[i, k]
        v[k] -= alpha
        vnorm2 = norm2 - U[k, k] * U[k, k] + v[k] * v[k]
        diag[k] = alpha
        if vnorm2 == 0.0:
            continue
        for j in range(k + 1, n):
            s = 0.0
            for i in range(k, m):
                s += v[i] * U[i, j]
            s = 2.0 * s / vnorm2
            for i in range(k, m):
                U[i, j] -= s * v[i]
        for j in range(n):
            s = 0.0
            for i in range(k, m):
                s += v[i] * W[i, j]
            s = 2.0 * s / vnorm2
            for i in range(k, m):
                W[i, j] -= s * v[i]
    big = 0.0
    for k in range(n):
        if abs(diag[k]) > big:
            big = abs(diag[k])
    if not big > 0.0:
        return -1.0
    for k in range(n):
        if not abs(diag[k]) > SHIFT_RANK_TOL * big:
            return -1.0
    res = 0.0
    tot = 0.0
    for i in range(m):
        for j in range(n):
            tot += M[i + ny, j] * M[i + ny, j]
            if i >= n:
                res += W[i, j] * W[i, j]
    X = np.empty((n, n))
    for j in range(n):
        for i in range(n - 1, -1, -1):
            s = W[i, j]
            for k in range(i + 1, n):
                s -= U[i, k] * X[k, j]
            X[i, j] = s / diag[i]
    for i in range(n):
        for j in range(n):
            Aout[i, j] = omega * X[i, j]
    return np.sqrt(res / tot) if tot > 0.0 else 0.0


@numba.njit(cache=True, fastmath=_FASTMATH)
def _refresh(n, nu, ny, omega, alpha, max_cond, gate, settle, ode, iv, T_now, ist, fst,
             R, G, M, Rt, gt, theta, Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, hist,
             Ld, Bd, Lt, Bt, Anew, Cz, Gz, Zz, Lz, Ct, Gt, Nz, Gn, Cf, ex):  # pragma: no cover
    """Model refresh: solve both LS problems (the first by instrumental
    variables when ``iv``), (13), B̃, D, Ψ model, history."""
    if not ode:
        if iv:
            # the cross matrix Σ w ζ φ^T: its first n columns are kept (Cz), the
            # rest are the q̂ columns of Z (φ = [H p̂; q̂], ζ = [q̂; r̂; x_i])
            nz = Cz.shape[1]
            for i in range(Cf.shape[0]):
                for j in range(Cf.shape[1]):
                    if j < nz:
                        Cf[i, j] = Cz[i, j]
                    else:
                        jj = j - nz
                        Cf[i, j] = Zz[i, jj] if jj <= i else Zz[jj, i]
            if not _solve_iv_weighted(Cf, Gz, Zz, M, max_cond, Lz, Ct, Gt, Nz, Gn, Ld, Bd, ex):
                ist[7] += 1
                ex[0] = 0.0
        elif not _solve_normal(R, G, M, max_cond, Ld, Bd):
            ist[7] += 1
            ex[0] = 0.0
        else:
            trr = 0.0
            for i in range(R.shape[0]):
                trr += R[i, i]
            ex[0] = _weakest(R, Ld, trr / max_cond, ex[1:1 + R.shape[0]],
                             ex[1 + R.shape[0]:1 + 2 * R.shape[0]])
        # persistent excitation of (8): its weakest direction carries at least
        # the share 1/max_condition of the information (issue 23)
        ist[13] = 0 if ex[0] * max_cond >= 1.0 else 1
        if ist[9]:
            if not _solve_normal(Rt, gt, theta, max_cond, Lt, Bt):
                ist[7] += 1
    res = _shift_solve(M, n, ny, omega, Anew)
    fst[2] = res
    if res >= 0.0:
        for i in range(n):
            for j in range(n):
                Am[i, j] = Anew[i, j]
        for i in range(ny):
            for j in range(n):
                Cm[i, j] = M[i, j]
    else:
        ist[5] += 1
    if ist[9]:
        for j in range(nu):
            for i in range(n):
                Bm[i, j] = theta[0, n + i + n * j]
            for i in range(ny):
                Dm[i, j] = theta[0, n + n * nu + i + ny * j]
    level = gate
    if res >= 0.0:
        if res < 0.5 * fst[5]:
            fst[5] = res
            fst[6] = T_now
        elif (not ist[10] and fst[5] <= _STALL_MAX
              and T_now - fst[6] >= min(1.0 / alpha, max(fst[6] - fst[8], settle))):
            ist[10] = 1
        if ist[10]:
            level = max(gate, _STALL_FACTOR * fst[5])
    if res >= 0.0 and res <= level and ist[13] == 0 and _hurwitz(Am):
        for i in range(n):
            for j in range(n):
                Apsi[i, j] = Am[i, j]
        for i in range(ny):
            for j in range(n):
                Cpsi[i, j] = Cm[i, j]
        ist[6] += 1
        ist[11] = 0
        if not ist[9]:
            # part 2 starts: Ψ(t_g) = 0, Ξ(t_g) = C̃. Ξ is the regressor of the
            # initial-state term C̃ e^{Ã(t - t_g)} x̃(t_g) of (14)/(16), which
            # (19)-(20) drop; it is estimated with θ.
            for i in range(ny):
                for j in range(Psi.shape[1]):
                    Psi[i, j] = Cm[i, j] if j < n else 0.0
            ist[9] = 1
            fst[1] = T_now
    else:
        ist[4] += 1
        ist[11] = 1
    ist[1] += 1
    cap = hist.shape[0]
    if cap > 0:
        r = ist[1]
        if r % ist[3] == 0:
            if ist[2] == cap:
                keep = 0
                for k in range(1, cap, 2):
                    for c in range(hist.shape[1]):
                        hist[keep, c] = hist[k, c]
                    keep += 1
                ist[2] = keep
                ist[3] *= 2
            if r % ist[3] == 0:
                row = ist[2]
                hist[row, 0] = T_now
                hist[row, 1] = ist[0]
                c = 2
                for i in range(n):
                    for j in range(n):
                        hist[row, c] = Am[i, j]
                        c += 1
                for i in range(n):
                    for j in range(nu):
                        hist[row, c] = Bm[i, j]
                        c += 1
                for i in range(ny):
                    for j in range(n):
                        hist[row, c] = Cm[i, j]
                        c += 1
                for i in range(ny):
                    for j in range(nu):
                        hist[row, c] = Dm[i, j]
                        c += 1
                ist[2] = row + 1


@numba.njit(cache=True)
def _scratch_layout(n, ny, f, mi, dz, d, dp, dth):  # pragma: no cover - compiled
    """The layout table of :func:`kernel`'s scratch buffer: ``(offset, rows,
    cols)`` per array (1-D arrays have one column), in the order the kernel
    cuts them (``_view1``/``_view2`` with the same index). Dimensions: order
    n, outputs ny, filter order f, instrument filter order mi, instruments
    dz, regressor d of (8), its left-hand side dp, and θ of (16), dth."""
    shapes = ((dz, 1),          # 0 ζ, the instruments ('iv')
              (dp, 1),          # 1 weighted residual of (8) ('iv')
              (mi, 1),          # 2 new instrument-filter state
              (n, 1),           # 3 new auxiliary-model instrument
              (dz, dz),         # 4 Cholesky factor of Z
              (dz, d),          # 5 whitened cross matrix C̃
              (dp, dz),         # 6 whitened residual G̃
              (d, d),           # 7 normal matrix of the whitened IV step
              (dp, d),          # 8 its right-hand side
              (dz, d),          # 9 the whole cross matrix
              (dp, 1),          # 10 p̂
              (d, 1),           # 11 φ̂
              (d, 1),           # 12 w φ̂
              (f, 1),           # 13 new filter state
              (ny, dth),        # 14 Φ of (16) ('ode')
              (ny, n),          # 15 new Ψ block
              (d, 1),           # 16 P φ ('ode')
              (dp, 1),          # 17 residual of (8) ('ode')
              (dth, ny),        # 18 Q Φ^T ('ode')
              (ny, 1),          # 19 residual of (16)
              (n, n),           # 20 e^{Ã h}
              (n, n),           # 21 G1 of Ψ
              (n, n),           # 22 G2 of Ψ
              (dp, 1),          # 23 weighted residual of (8) ('ls')
              (d, d),           # 24 Cholesky factor of (8)
              (d, dp),          # 25 its right-hand sides
              (dth, dth),       # 26 Cholesky factor of (16)
              (dth, 1),         # 27 its right-hand side
              (n, n),           # 28 Ã from (13)
              (5 * n, n),       # 29 phi_blocks' work, (5, n, n)
              (1 + 2 * d, 1))   # 30 excitation of (8) and its inverse iteration
    out = np.empty((len(shapes), 3), dtype=np.int64)
    o = 0
    for i in range(len(shapes)):
        out[i, 0] = o
        out[i, 1] = shapes[i][0]
        out[i, 2] = shapes[i][1]
        o += shapes[i][0] * shapes[i][1]
    return out


# ---------------------------------------------------------------------------
# the compiled loop
# ---------------------------------------------------------------------------
@numba.njit(cache=True, fastmath=_FASTMATH)
def kernel(Tm, U, Y, idx, steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, Hsel, par,
           ipar, ist, fst, prev_u, prev_y, zp, zq, R, G, M, Rt, gt, theta,
           Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, zr, xi, Cz, Gz, Zz, Ev,
           PsiPhi, PsiG0, PsiG1, pstamp, hist, buf):  # pragma: no cover - compiled
    """Process the samples ``(Tm, U, Y)`` in place (see the module docstring).

    ``buf`` is the buffer holding every float state array; returns True if it
    is finite at the end (False: the caller rolls the chunk back).

    ``par = [ω, α, β, max_condition, ode_trace_bound, gate]``,
    ``ipar = [refresh_every, ode, foh, iv]``. ``Iphi, Ig0, Ig1``: tables of
    the instrument filter (state ``zr``); with ``iv`` the regression (8) is
    solved by instrumental variables ``ζ = [q̂; r̂; x_i]`` (the first n
    columns of the cross matrix in ``Cz``, the others are columns of ``Zz =
    Σ w ζ ζ^T``; residual ``Gz = S_ζ - M C^T``) instead of least squares (R,
    G unused). ``idx[k]`` is the table entry of the interval ending at
    sample k (unused for the very first sample).
    ``PsiPhi, PsiG0, PsiG1, pstamp`` cache the Ψ discretisation per entry.

    In ``'ls'`` mode the normal equations are held in residual form: R and
    ``G = S - M R`` (the gradient of V_t at the current estimate M), updated
    with the prediction error ``p̂ - M φ̂``, so that rounding errors scale
    with the residual rather than with the signals (see
    :func:`_solve_normal`). The forgetting is deferred: the stored
    ``(R, G)`` are the true ones divided by ``fst[3]`` (the product of the
    λ_k since the last rescaling), so that a sample costs one rank-one update
    without rescaling the whole matrices; the solve is invariant to the
    common factor. The same holds for ``(R_θ, g_θ)`` with ``fst[4]``.
    """
    omega, alpha, beta, max_cond, trace_bound, gate = (par[0], par[1], par[2], par[3],
                                                       par[4], par[5])
    max_gap, dcF, dcI, settle, startup = par[6], par[7], par[8], par[9], par[10]
    K, ode, foh, iv = ipar[0], ipar[1] != 0, ipar[2] != 0, ipar[3] != 0
    N = U.shape[0]
    f, ny = zp.shape
    nu = zq.shape[1]
    n = Am.shape[0]
    dp, d = M.shape
    mi = zr.shape[0]
    dz = Cz.shape[0]
    dth = theta.shape[1]
    nX = Psi.shape[1]          # n + n nu: columns of [Ξ, Ψ]
    # scratch: one allocation per call (a one-sample call pays for one, not 30),
    # carved by its layout table (_scratch_layout, same order)
    sl = _scratch_layout(n, ny, f, mi, dz, d, dp, dth)
    sc = np.empty(sl[-1, 0] + sl[-1, 1] * sl[-1, 2])
    zeta, ez, zi, zi2 = _view1(sc, sl, 0), _view1(sc, sl, 1), _view1(sc, sl, 2), _view1(sc, sl, 3)
    Lz, Ct, Gt, Nz = _view2(sc, sl, 4), _view2(sc, sl, 5), _view2(sc, sl, 6), _view2(sc, sl, 7)
    Gn, Cf = _view2(sc, sl, 8), _view2(sc, sl, 9)
    p, phi, wphi, znew = _view1(sc, sl, 10), _view1(sc, sl, 11), _view1(sc, sl, 12), \
        _view1(sc, sl, 13)
    Phi, Pn, g, e = _view2(sc, sl, 14), _view2(sc, sl, 15), _view1(sc, sl, 16), _view1(sc, sl, 17)
    Phi[:, :] = 0.0
    Gq, ey = _view2(sc, sl, 18), _view1(sc, sl, 19)
    Ph, G1h, G2h = _view2(sc, sl, 20), _view2(sc, sl, 21), _view2(sc, sl, 22)
    ep, Ld, Bd = _view1(sc, sl, 23), _view2(sc, sl, 24), _view2(sc, sl, 25)
    Lt, Bt, Anew = _view2(sc, sl, 26), _view2(sc, sl, 27), _view2(sc, sl, 28)
    work = _view2(sc, sl, 29).reshape((5, n, n))
    ex = _view1(sc, sl, 30)         # excitation of (8) and its scratch
    for k in range(N):
        if ist[0] == 0:
            for j in range(nu):
                prev_u[j] = U[k, j]
            for j in range(ny):
                prev_y[j] = Y[k, j]
            fst[0] = Tm[k]
            fst[8] = Tm[k]
            ist[0] = 1
            continue
        q = idx[k]
        h = steps[q]
        gap = h > max_gap
        # 1. state-variable filters (6a)-(6b), one channel at a time; after a
        # gap longer than max_gap, re-initialised at the steady state of the
        # current sample held constant (as if at rest: the held signals over
        # a long gap are not data), and the interval gets no weight
        if gap:
            ist[12] += 1
            fst[7] = Tm[k] + settle
            for i in range(f):
                for c in range(ny):
                    zp[i, c] = dcF * Y[k, c] if i == 0 else 0.0
                for c in range(nu):
                    zq[i, c] = dcF * U[k, c] if i == 0 else 0.0
            for i in range(mi):
                for c in range(nu):
                    zr[i, c] = dcI * U[k, c] if i == 0 else 0.0
        for c in range(ny if not gap else 0):
            for i in range(f):
                s = Fg0[q, i] * prev_y[c] + Fg1[q, i] * Y[k, c]
                for j in range(f):
                    s += Fphi[q, i, j] * zp[j, c]
                znew[i] = s
            for i in range(f):
                zp[i, c] = znew[i]
        for c in range(nu if not gap else 0):
            for i in range(f):
                s = Fg0[q, i] * prev_u[c] + Fg1[q, i] * U[k, c]
                for j in range(f):
                    s += Fphi[q, i, j] * zq[j, c]
                znew[i] = s
            for i in range(f):
                zq[i, c] = znew[i]
        if iv and not gap:
            # instrument filter: the inputs only, through a second filter bank
            for c in range(nu):
                for i in range(mi):
                    s = Ig0[q, i] * prev_u[c] + Ig1[q, i] * U[k, c]
                    for j in range(mi):
                        s += Iphi[q, i, j] * zr[j, c]
                    zi[i] = s
                for i in range(mi):
                    zr[i, c] = zi[i]
        # 2. regression (8): p̂ = M φ̂, φ̂ = [H p̂; q̂] (10), r^2 = 1 + |φ̂|^2.
        # (11)-(12) leave r open; an r depending on P (like ρ of (20)) gives
        # d/dt log det P^{-1} < 1 - α dim φ, so that the data could never
        # outweigh the prior for the paper's α = 0.4, dim φ = 14.
        for i in range(f):
            for c in range(ny):
                p[i * ny + c] = zp[i, c]
        for i in range(n):
            s = 0.0
            for j in range(dp):
                s += Hsel[i, j] * p[j]
            phi[i] = s
        for i in range(f):
            for c in range(nu):
                phi[n + i * nu + c] = zq[i, c]
        r2 = 1.0
        for i in range(d):
            r2 += phi[i] * phi[i]
        if iv:
            # instrumental variables, ζ = [q̂; r̂; x_i] (from the input only):
            # C <- λ C + w ζ φ^T (first n columns kept in Cz, the rest are
            # columns of Zz), Zz <- λ Zz + w ζ ζ^T, S_ζ <- λ S_ζ + w p ζ^T held
            # as Gz = S_ζ - M C^T. Deferred λ; a factor below _RESCALE_BELOW (a
            # long gap) is folded in first, so that the divisor stays 1.
            c2 = fst[3] * lamM[q]
            if c2 < _RESCALE_BELOW:
                c2 = c2 if c2 > _FORGOTTEN else 0.0
                for i in range(dz):
                    for j in range(n):
                        Cz[i, j] *= c2
                for i in range(dp):
                    for j in range(dz):
                        Gz[i, j] *= c2
                for i in range(dz):
                    for j in range(i + 1):
                        Zz[i, j] *= c2
                fst[3] = 1.0
            else:
                fst[3] = c2
            w = 0.0 if Tm[k] <= fst[7] else h / (r2 * fst[3])
            for i in range(f):
                for c in range(nu):
                    zeta[i * nu + c] = zq[i, c]
            for i in range(mi):
                for c in range(nu):
                    zeta[f * nu + i * nu + c] = zr[i, c]
            for i in range(n):
                zeta[(f + mi) * nu + i] = xi[0, i]
            for i in range(dz):
                wi = w * zeta[i]
                for j in range(n):          # the q̂ columns of Σ w ζ φ^T are in Z
                    Cz[i, j] += wi * phi[j]
                for j in range(i + 1):
                    Zz[i, j] += wi * zeta[j]
            for i in range(dp):
                s = p[i]
                for j in range(d):
                    s -= M[i, j] * phi[j]
                ez[i] = w * s
            for i in range(dp):
                wi = ez[i]
                for j in range(dz):
                    Gz[i, j] += wi * zeta[j]
        elif not ode:
            # R <- λ R + w φ φ^T, S <- λ S + w p φ^T (w = h / r^2), deferred λ;
            # a factor below _RESCALE_BELOW (a long gap) is folded in first
            c2 = fst[3] * lamM[q]
            if c2 < _RESCALE_BELOW:
                c2 = c2 if c2 > _FORGOTTEN else 0.0
                for i in range(d):
                    for j in range(i + 1):
                        R[i, j] *= c2
                for i in range(dp):
                    for j in range(d):
                        G[i, j] *= c2
                fst[3] = 1.0
            else:
                fst[3] = c2
            w = 0.0 if Tm[k] <= fst[7] else h / (r2 * fst[3])
            for i in range(d):
                wphi[i] = w * phi[i]
            for i in range(d):
                wi = wphi[i]
                for j in range(i + 1):
                    R[i, j] += wi * phi[j]
            for i in range(dp):             # G += w (p - M φ) φ^T
                s = p[i]
                for j in range(d):
                    s -= M[i, j] * phi[j]
                ep[i] = w * s
            for i in range(dp):
                wi = ep[i]
                for j in range(d):
                    G[i, j] += wi * phi[j]
        elif Tm[k] > fst[7]:
            # (11)-(12), semi-implicit Euler step; R holds P. The gain
            # h / (r^2 + h φ^T P φ) (Sherman-Morrison form of the downdate)
            # keeps P positive definite for any step; it is forward Euler's
            # h / r^2 to first order in h.
            gp = 0.0
            for i in range(d):
                s = 0.0
                for j in range(d):
                    s += R[i, j] * phi[j]
                g[i] = s
                gp += phi[i] * s
            c2 = h / (r2 + h * gp)
            for i in range(dp):
                s = p[i]
                for j in range(d):
                    s -= M[i, j] * phi[j]
                e[i] = s * c2
            for i in range(dp):
                for j in range(d):
                    M[i, j] += e[i] * g[j]
            tr = 0.0
            for i in range(d):
                tr += R[i, i]
            grow = h * alpha
            if tr > trace_bound:
                grow = 0.0
                ist[8] += 1
            for i in range(d):
                for j in range(d):
                    R[i, j] += grow * R[i, j] - c2 * g[i] * g[j]
        if ist[9]:
            # 3. Ξ and Ψ of (15), exact for the held input
            if pstamp[q] != ist[6]:
                phi_blocks(Apsi, h, Ph, G1h, G2h, work)
                for i in range(n):
                    for j in range(n):
                        PsiPhi[q, i, j] = Ph[i, j]
                for i in range(ny):
                    for j in range(n):
                        s0 = 0.0
                        s1 = 0.0
                        for l in range(n):
                            if foh:
                                s0 += Cpsi[i, l] * (G1h[l, j] - G2h[l, j])
                                s1 += Cpsi[i, l] * G2h[l, j]
                            else:
                                s0 += Cpsi[i, l] * G1h[l, j]
                        PsiG0[q, i, j] = s0
                        PsiG1[q, i, j] = s1
                pstamp[q] = ist[6]
            for b in range(nu + 1):
                off = b * n
                a0 = 0.0 if b == 0 else prev_u[b - 1]
                a1 = 0.0 if b == 0 else U[k, b - 1]
                for i in range(ny):
                    for j in range(n):
                        Pn[i, j] = a0 * PsiG0[q, i, j] + a1 * PsiG1[q, i, j]
                    for l in range(n):
                        x = Psi[i, off + l]
                        for j in range(n):
                            Pn[i, j] += x * PsiPhi[q, l, j]
                for i in range(ny):
                    for j in range(n):
                        Psi[i, off + j] = Pn[i, j]
            if gap:
                # restart (14) at this sample: Ψ = 0, Ξ = C̃, and the unknown
                # state x̃ now replaces x̃(t_g) in θ (its information dropped)
                for i in range(ny):
                    for j in range(nX):
                        Psi[i, j] = Cpsi[i, j] if j < n else 0.0
                if not ode:
                    for a in range(dth):
                        for b in range(a + 1):
                            if b < n:
                                Rt[a, b] = 0.0
                    for a in range(n):
                        gt[0, a] = 0.0
            if iv:
                # auxiliary-model instrument: x_i <- e^{Ã h} x_i + h B̃ q̂_0 (the
                # accepted Ã, the current B̃, the filtered input F̂ u; any
                # function of the input is a valid instrument, so the simple
                # quadrature is enough); the next sample uses it
                for i in range(n):
                    s = 0.0
                    for j in range(nu):
                        s += Bm[i, j] * zq[0, j]
                    zi2[i] = h * s
                    for j in range(n):
                        zi2[i] += PsiPhi[q, i, j] * xi[0, j]
                for i in range(n):
                    xi[0, i] = zi2[i]
            # regression (16): y = Φ θ, Φ = [Ξ, Ψ, u^T ⊗ I], ρ^2 = 1 + |Φ|_F^2
            # (P-free for the same reason as r; 'ode' keeps ρ of (20))
            rho2 = 1.0
            for i in range(ny):
                for j in range(nX):
                    rho2 += Psi[i, j] * Psi[i, j]
            for jj in range(nu):
                rho2 += ny * (U[k, jj] * U[k, jj])
            if not ode:
                # start-up schedule of β: the memory of θ grows with the age
                # of part 2 (β_eff = max(β, startup / age), see the module notes)
                lam = lamT[q]
                age = Tm[k] - fst[1]
                if startup > beta * age:
                    lam = np.exp(-startup * h / age)
                c2 = fst[4] * lam
                if c2 < _RESCALE_BELOW:
                    c2 = c2 if c2 > _FORGOTTEN else 0.0
                    for a in range(dth):
                        for b in range(a + 1):
                            Rt[a, b] *= c2
                        gt[0, a] *= c2
                    fst[4] = 1.0
                else:
                    fst[4] = c2
                w = 0.0 if gap else h / (rho2 * fst[4])
                # prediction error y - Φ θ
                for r in range(ny):
                    s = Y[k, r]
                    for a in range(nX):
                        s -= Psi[r, a] * theta[0, a]
                    for jj in range(nu):
                        s -= U[k, jj] * theta[0, nX + r + ny * jj]
                    ey[r] = w * s
                    # its power per channel (the output-noise estimate of the
                    # refinement, see adaptive._refined)
                    # (θ's memory, start-up schedule included: the rows of the
                    # first seconds, with θ still far off, are forgotten as fast)
                    Ev[0, r] = lam * Ev[0, r] + (0.0 if gap else h * (s * s))
                    Ev[0, ny + r] = lam * Ev[0, ny + r] + (0.0 if gap else h * (Y[k, r] * Y[k, r]))
                Ev[0, 2 * ny] = lam * Ev[0, 2 * ny] + (0.0 if gap else h)
                # R_θ += w Φ^T Φ, g_θ += w Φ^T (y - Φ θ), exploiting u^T ⊗ I
                for r in range(ny):
                    er = ey[r]
                    for a in range(nX):
                        wa = w * Psi[r, a]
                        for b in range(a + 1):
                            Rt[a, b] += wa * Psi[r, b]
                        gt[0, a] += er * Psi[r, a]
                for jj in range(nu):
                    for i in range(ny):
                        a = nX + i + ny * jj
                        uj = U[k, jj]
                        for b in range(nX):
                            Rt[a, b] += w * (uj * Psi[i, b])
                        for j2 in range(jj + 1):
                            Rt[a, nX + i + ny * j2] += w * (uj * U[k, j2])
                        gt[0, a] += ey[i] * uj
            elif not gap:
                # (19)-(20), semi-implicit Euler step (gain h / (ρ^2 + h tr(Φ Q Φ^T)),
                # Q stays positive definite); Rt holds Q; ρ^2 = 1 + tr(Φ Q Φ^T)
                for i in range(ny):
                    for j in range(nX):
                        Phi[i, j] = Psi[i, j]
                    for jj in range(nu):
                        Phi[i, nX + i + ny * jj] = U[k, jj]
                rho2 = 1.0
                for i in range(dth):
                    for r in range(ny):
                        s = 0.0
                        for j in range(dth):
                            s += Rt[i, j] * Phi[r, j]
                        Gq[i, r] = s
                for r in range(ny):
                    for i in range(dth):
                        rho2 += Phi[r, i] * Gq[i, r]
                c2 = h / (rho2 + h * (rho2 - 1.0))
                for r in range(ny):
                    s = Y[k, r]
                    for j in range(dth):
                        s -= Phi[r, j] * theta[0, j]
                    ey[r] = s * c2
                for i in range(dth):
                    s = 0.0
                    for r in range(ny):
                        s += Gq[i, r] * ey[r]
                    theta[0, i] += s
                tr = 0.0
                for i in range(dth):
                    tr += Rt[i, i]
                grow = h * beta
                if tr > trace_bound:
                    grow = 0.0
                    ist[8] += 1
                for i in range(dth):
                    for j in range(dth):
                        s = 0.0
                        for r in range(ny):
                            s += Gq[i, r] * Gq[j, r]
                        Rt[i, j] += grow * Rt[i, j] - c2 * s
        for jj in range(nu):
            prev_u[jj] = U[k, jj]
        for c in range(ny):
            prev_y[c] = Y[k, c]
        fst[0] = Tm[k]
        ist[0] += 1
        if (ist[0] - 1) % K == 0:
            _refresh(n, nu, ny, omega, alpha, max_cond, gate, settle, ode, iv, Tm[k], ist, fst,
                     R, G, M, Rt, gt, theta, Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, hist, Ld, Bd, Lt,
                     Bt, Anew, Cz, Gz, Zz, Lz, Ct, Gt, Nz, Gn, Cf, ex)
    return _all_finite(buf)


_EXPONENT = np.int64(0x7FF0000000000000)     # the exponent bits of a float64


@numba.njit(cache=True)
def _all_finite(buf):  # pragma: no cover - compiled
    """True if no entry of the float64 array ``buf`` is NaN or infinite (all
    exponent bits set): counted over the integer bits, a loop without an
    early exit that vectorises (7 times faster than testing ``np.isfinite``
    entry by entry on the 1,800 entries of a typical state)."""
    bits = buf.view(np.int64)
    bad = 0
    for i in range(bits.shape[0]):
        bad += (bits[i] & _EXPONENT) == _EXPONENT
    return bad == 0


@numba.njit(cache=True, fastmath=_FASTMATH)
def kernel_packed(Tm, U, Y, idx, cbuf, ibuf, ist, hist, buf):  # pragma: no cover - compiled
    """:func:`kernel` with its arrays passed as a few buffers.

    ``buf`` holds the float state: ``lay[i] = (offset, rows, cols)`` locates
    the i-th float state array of :func:`kernel` (``fst`` ... ``Zz``, in its
    argument order; the first three are 1-D). ``cbuf`` holds the tables
    ``steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, Hsel, par`` and the
    Ψ cache ``PsiPhi, PsiG0, PsiG1`` (that order): ``clay[i] = (offset, d0,
    d1, d2)``. ``ibuf`` holds ``[len(clay), len(lay), len(ipar)]``, then
    ``clay``, ``lay``, ``ipar`` and the cache stamps ``pstamp`` (one per table
    entry). The views are cut here, in compiled code: calling from Python
    costs nine array arguments instead of 46 (each costs its unboxing, a
    one-sample call pays it every time). Then it calls :func:`kernel`.
    """
    n_c, n_lay, n_ipar = ibuf[0], ibuf[1], ibuf[2]
    clay = ibuf[3:3 + 4 * n_c].reshape((n_c, 4))
    o = 3 + 4 * n_c
    lay = ibuf[o:o + 3 * n_lay].reshape((n_lay, 3))
    o += 3 * n_lay
    ipar = ibuf[o:o + n_ipar]
    pstamp = ibuf[o + n_ipar:o + n_ipar + clay[0, 1]]
    PsiPhi = _view3(cbuf, clay, 11)
    PsiG0 = _view3(cbuf, clay, 12)
    PsiG1 = _view3(cbuf, clay, 13)
    steps, lamM, lamT = _view1(cbuf, clay, 0), _view1(cbuf, clay, 1), _view1(cbuf, clay, 2)
    Fphi = _view3(cbuf, clay, 3)
    Fg0 = _view2(cbuf, clay, 4)
    Fg1 = _view2(cbuf, clay, 5)
    Iphi = _view3(cbuf, clay, 6)
    Ig0 = _view2(cbuf, clay, 7)
    Ig1 = _view2(cbuf, clay, 8)
    Hsel = _view2(cbuf, clay, 9)
    par = _view1(cbuf, clay, 10)
    fst, prev_u, prev_y = _view1(buf, lay, 0), _view1(buf, lay, 1), _view1(buf, lay, 2)
    zp = _view2(buf, lay, 3)
    zq = _view2(buf, lay, 4)
    R = _view2(buf, lay, 5)
    G = _view2(buf, lay, 6)
    M = _view2(buf, lay, 7)
    Rt = _view2(buf, lay, 8)
    gt = _view2(buf, lay, 9)
    theta = _view2(buf, lay, 10)
    Am = _view2(buf, lay, 11)
    Cm = _view2(buf, lay, 12)
    Bm = _view2(buf, lay, 13)
    Dm = _view2(buf, lay, 14)
    Apsi = _view2(buf, lay, 15)
    Cpsi = _view2(buf, lay, 16)
    Psi = _view2(buf, lay, 17)
    zr = _view2(buf, lay, 18)
    xi = _view2(buf, lay, 19)
    Cz = _view2(buf, lay, 20)
    Gz = _view2(buf, lay, 21)
    Zz = _view2(buf, lay, 22)
    Ev = _view2(buf, lay, 23)
    return kernel(Tm, U, Y, idx, steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, Hsel,
                  par, ipar, ist, fst, prev_u, prev_y, zp, zq, R, G, M, Rt, gt, theta,
                  Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, zr, xi, Cz, Gz, Zz, Ev,
                  PsiPhi, PsiG0, PsiG1, pstamp, hist, buf)


@numba.njit(cache=True)
def _view3(buf, lay, i):  # pragma: no cover - compiled
    """The 3-D array ``i`` of :func:`kernel_packed`'s constant tables, a view of ``buf``."""
    o = lay[i, 0]
    return buf[o:o + lay[i, 1] * lay[i, 2] * lay[i, 3]].reshape((lay[i, 1], lay[i, 2],
                                                                  lay[i, 3]))


@numba.njit(cache=True)
def _view2(buf, lay, i):  # pragma: no cover - compiled
    """The 2-D array ``i`` (rows ``lay[i, 1]``, columns ``lay[i, 2]``) of
    :func:`kernel_packed`, a view of ``buf``."""
    o = lay[i, 0]
    return buf[o:o + lay[i, 1] * lay[i, 2]].reshape((lay[i, 1], lay[i, 2]))


@numba.njit(cache=True)
def _view1(buf, lay, i):  # pragma: no cover - compiled
    """The array ``i`` of a layout table ``lay`` as a 1-D view of ``buf``."""
    o = lay[i, 0]
    return buf[o:o + lay[i, 1] * lay[i, 2]]


def pack_tables(arrays, cache, lay, ipar):
    """``(cbuf, ibuf, cache)`` of :func:`kernel_packed`.

    ``cbuf``: the float ``arrays`` then the Ψ cache (``PsiPhi, PsiG0,
    PsiG1``) copied into one buffer; ``ibuf``: the counts ``[tables, state
    arrays, ipar]``, their layout ``clay`` (offset, d0, d1, d2 per array of
    cbuf), the state layout ``lay``, ``ipar`` and the cache stamps, copied into
    one int64 buffer. The returned ``cache`` are views of the buffers (the
    kernel updates the cache there)."""
    floats = list(arrays) + list(cache[:3])
    sizes = [a.size for a in floats]
    cbuf = np.empty(sum(sizes))
    clay = np.ones((len(floats), 4), dtype=np.int64)
    views = []
    off = 0
    for i, (a, size) in enumerate(zip(floats, sizes)):
        cbuf[off:off + size] = a.reshape(-1)
        clay[i, 0] = off
        clay[i, 1:1 + a.ndim] = a.shape
        views.append(cbuf[off:off + size].reshape(a.shape))
        off += size
    stamps = cache[3]
    ibuf = np.concatenate([[len(floats), lay.shape[0], ipar.size], clay.reshape(-1),
                           lay.reshape(-1), ipar, stamps]).astype(np.int64)
    return cbuf, ibuf, (views[-3], views[-2], views[-1], ibuf[ibuf.size - stamps.size:])
