"""The output of a state-space system and its sensitivities to directions in its matrices.

Two users: the Jacobian of the prediction error in :func:`subid.pem` and the
polynomial methods, and the delta-method bands of simulated outputs and step
responses (:func:`subid.simulation_bounds`, :func:`subid.step_bounds`), all
directions in one pass instead of one simulation per direction.

The predictor is a discrete-time system driven by the known signal ``v``
(``v = [u, y]`` for the one-step predictor, ``v = u`` for the simulation):

    x[t+1] = Ap x[t] + Bp v[t],    ŷ[t] = C x[t] + Dp v[t].

For a direction ``j`` in parameter space (``dAp_j, dBp_j, dC_j, dDp_j`` and an
initial-state direction ``dx0_j``) the sensitivity ``s_j = dx/dθ_j`` obeys
(differentiate the recursion)

    s_j[t+1] = Ap s_j[t] + dAp_j x[t] + dBp_j v[t],   s_j[0] = dx0_j,
    dŷ[t]/dθ_j = C s_j[t] + dC_j x[t] + dDp_j v[t].

:func:`jacobian` is the compiled loop (vectorised over the directions), :func:`jacobian_ref` a plain numpy
implementation kept for the tests.

Two forms of the loop. The per-direction loop (:func:`_jacobian_t`) reads
every direction's matrices ``dAp_j, dBp_j, dC_j, dDp_j`` at every sample:
``d (n + ny)(n + m)`` numbers, 0.9 MB for the 196 directions of an order-20
model with four inputs and outputs, streamed from the cache at each of the
``N`` samples (about 4 multiply-adds per nanosecond, memory-bound). The
forcing terms ``dAp_j x[t] + dBp_j v[t]`` and ``dC_j x[t] + dDp_j v[t]`` do
not depend on the sensitivities, so the blocked form (:func:`_jacobian_blocked`)
first simulates the state ``x[t]``, then forms them for a block of samples as
one matrix product ``[x[t], v[t]] M`` (``M`` the direction matrices stacked,
``(n + m) x (n + ny) d``: read once per block instead of once per sample),
and runs only the recursion ``[s[t+1]; dŷ[t] - forcing] = [Ap; C] s[t]``,
one ``(n + ny) x n`` by ``n x d`` product per sample (:func:`_recursion_t`).
The same sums in another order (equal to rounding; the tests compare both
with :func:`jacobian_ref`); 2.5x faster on that model, and used from
:data:`BLOCKED_WORK` multiply-adds per sample, below which the per-direction
loop is as fast.

A direction that moves the initial state alone (``dAp_j, dBp_j, dC_j, dDp_j``
zero: the initial-state columns of :func:`subid.pem`) has the free response
``dŷ[t]/dθ_j = C Ap^t dx0_j``, which decays geometrically for a stable
predictor and, run to the end of a long record, spends most of the loop in
subnormal floating-point numbers (below 2.2e-308), which the processor
handles about a hundred times slower than normal ones: on 66,667 samples of
an order-4 model with 16 model and 4 initial-state directions the loop took
0.19 s against 0.019 s without those four. When the spectral radius of
``Ap`` says the free response falls below :data:`FREE_RESPONSE_FLOOR` within
the record, :func:`jacobian` therefore runs such directions in their own loop
(:func:`free_response`), which stops once the response has fallen below that
fraction of its start and leaves the rest zero (the entries dropped are below
1e-150 of the column's first: zero to rounding in every product the callers
form); otherwise every direction stays in the one loop. That loop goes by blocks
of :data:`FREE_BLOCK` samples, each block's responses one matrix product with
``[C; C Ap; ...; C Ap^63]`` (the step recursion's ``n x n`` product per sample
replaced by one per block): the output-error defaults, whose slow poles run the free
response over the whole record, 1.3-2.3x faster (DaISy evaporator 9.9 -> 7.6 s,
glassfurnace 3.3 -> 1.4 s, steamgen 8.4 -> 5.8 s).
"""

from __future__ import annotations

import numba
import numpy as np

from subid._kernel_args import frozen
from subid.model._simulate import _simulate_discrete

#: A free response (:func:`free_response`) is taken as zero once every entry of its
#: state has fallen below this fraction of the largest entry of its initial state.
FREE_RESPONSE_FLOOR = 1e-150


@numba.njit(cache=True, fastmath={'contract'}, inline="always")
def _affine_row(M, N, x, vt, S, dMT, dNT, i, row):  # pragma: no cover
    """Row i of ``M x + N v(t)`` (returned) and of its sensitivity
    ``M S + dM x + dN v(t)`` (written into ``row``, the direction index last): the one
    step of both the output and the state equation."""
    n, m, d = x.shape[0], vt.shape[0], row.shape[0]
    acc = 0.0
    for k in range(n):
        acc += M[i, k] * x[k]
    for k in range(m):
        acc += N[i, k] * vt[k]
    for j in range(d):
        row[j] = 0.0
    for k in range(n):
        a, xk = M[i, k], x[k]
        Sk, da = S[k], dMT[i, k]
        for j in range(d):
            row[j] += a * Sk[j] + da[j] * xk
    for k in range(m):
        vk = vt[k]
        db = dNT[i, k]
        for j in range(d):
            row[j] += db[j] * vk
    return acc


@numba.njit(cache=True, fastmath={'contract'})
def _jacobian_t(Ap, Bp, C, Dp, v, x0, dApT, dBpT, dCT, dDpT, S, J):  # pragma: no cover
    """:func:`jacobian` on direction arrays with the direction index last (contiguous),
    so that every inner loop is an axpy over the directions (vectorised); the ``d``
    directions fill the first ``d`` columns of ``J`` (N, ny, >= d). Returns ``(ŷ,
    x[N])``; ``S`` (``s[0]``, (n, d)) holds ``s[N]`` on return."""
    N = v.shape[0]
    n = Ap.shape[0]
    ny = C.shape[0]
    d = S.shape[1]
    yhat = np.empty((N, ny))
    x = x0.copy()
    xn = np.empty(n)
    S_in = S
    Sn = np.empty((n, d))
    for t in range(N):
        vt = v[t]
        for i in range(ny):
            yhat[t, i] = _affine_row(C, Dp, x, vt, S, dCT, dDpT, i, J[t, i, :d])
        for i in range(n):
            xn[i] = _affine_row(Ap, Bp, x, vt, S, dApT, dBpT, i, Sn[i])
        for i in range(n):
            x[i] = xn[i]
        S, Sn = Sn, S
    if N % 2 == 1:                    # the last sensitivities into the caller's array
        S_in[:, :] = S
    return yhat, x


#: Samples per block of the blocked form (its state forcing, ``BLOCK x n x d``, stays
#: in the cache).
BLOCK = 32
#: Multiply-adds per sample of the direction recursion (``d (n + ny)(n + m)``) from
#: which :func:`jacobian` takes the blocked form (module docstring).
BLOCKED_WORK = 1_000


@numba.njit(cache=True)
def _recursion_t(G, S, Z, Ms, J, n):  # pragma: no cover
    """The recursion of the blocked form over the record, a block of :data:`BLOCK`
    samples at a time: the block's state forcing ``F = Z[t0:t0 + T] Ms`` (``(T, n d)``,
    one matrix product), then, with ``G = [Ap; C]`` and ``P = G s[t]``,
    ``J[t, :, :d] += P[n:]`` (``J`` holds the output forcing) and
    ``s[t+1] = P[:n] + F[t - t0]``; ``S`` (``s[0]``, ``(n, d)``) is advanced in place
    to ``s[N]``. One call per record (a call per block cost 6 µs of dispatch each: 40 %
    of :func:`subid.bj` at 10^5 samples)."""
    N = Z.shape[0]
    d = S.shape[1]
    ny = G.shape[0] - n
    P = np.empty((G.shape[0], d))
    F = np.empty((BLOCK, n * d))
    for t0 in range(0, N, BLOCK):
        T = min(BLOCK, N - t0)
        np.dot(Z[t0:t0 + T], Ms, F[:T])
        for tt in range(T):
            np.dot(G, S, P)
            row = J[t0 + tt]
            for i in range(ny):
                for j in range(d):
                    row[i, j] += P[n + i, j]
            Ft = F[tt]
            for i in range(n):
                for j in range(d):
                    S[i, j] = P[i, j] + Ft[i * d + j]




def _jacobian_blocked(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, S, J):
    """:func:`_jacobian_t` in the blocked form (module docstring): the ``d``
    directions (direction index first) fill the first ``d`` columns of ``J``; the same
    ``(ŷ, x[N])`` and ``S`` advanced to ``s[N]``."""
    N, m = v.shape
    n, ny, d = Ap.shape[0], C.shape[0], dAp.shape[0]
    width = J.shape[2]
    with np.errstate(all="ignore"):        # overflow propagates as in the loop form
        yhat, X = _simulate_discrete(Ap, Bp, C, Dp, v, x0)
    Z = np.hstack([X, v])                                           # (N, n + m)
    # M[k, i, j]: the k-th entry of [x; v] in row i of direction j's forcing (columns of
    # J beyond d get zero forcing here; the caller fills them)
    Ms = np.ascontiguousarray(np.concatenate([dAp, dBp], axis=2).transpose(2, 1, 0))
    Mo = np.zeros((n + m, ny, width))
    Mo[:, :, :d] = np.concatenate([dC, dDp], axis=2).transpose(2, 1, 0)
    np.matmul(Z, Mo.reshape(n + m, ny * width), out=J.reshape(N, ny * width))
    G = frozen(np.vstack([Ap, C]))
    _recursion_t(G, S, frozen(Z), frozen(Ms.reshape(n + m, n * d)), J, n)
    with np.errstate(all="ignore"):
        x_end = Ap @ X[-1] + Bp @ v[-1] if N else np.array(x0, dtype=float)
    return yhat, x_end


#: Samples per block of :func:`_free_response_t`: the responses of a block are one matrix
#: product with ``C Ap^τ`` (``τ`` < this), made once per call.
FREE_BLOCK = 64


@numba.njit(cache=True)
def _free_response_t(Ap, C, S, floor, out, offset):  # pragma: no cover
    """``C Ap^t S`` for ``t < N`` into the columns ``offset:offset + k`` of ``out``
    (N, ny, >= offset + k), zero from the first block of :data:`FREE_BLOCK` samples at
    whose start every entry of ``Ap^t S`` is below ``floor``. Returns ``Ap^N S`` (zero
    once below ``floor``).

    By blocks: with ``M = [C; C Ap; ...; C Ap^(T-1)]`` (made once) a block's responses
    are ``M s[t0]`` and the next block starts from ``s[t0 + T] = Ap^T s[t0]``: one
    product of ``(T ny) x n`` by ``n x k`` and one of ``n x n`` by ``n x k`` per block
    instead of a step of the recursion per sample (the same values to rounding; a
    response that decays within a block is computed to its end, a block at most below
    the floor)."""
    n, k = S.shape
    N, ny = out.shape[0], out.shape[1]
    T = FREE_BLOCK
    M = np.empty((T * ny, n))
    P = np.ascontiguousarray(C).copy()
    A = np.ascontiguousarray(Ap).copy()
    AT = np.eye(n)
    for tau in range(T):
        M[tau * ny:(tau + 1) * ny, :] = P
        P = np.dot(P, A)
        AT = np.dot(A, AT)
    S = np.ascontiguousarray(S).copy()
    stop = N
    t0 = 0
    while t0 < N:
        big = 0.0
        for i in range(n):
            for j in range(k):
                big = max(big, abs(S[i, j]))
        if big < floor:
            stop = t0
            break
        L = min(T, N - t0)
        B = np.dot(M[:L * ny], S)
        for tau in range(L):
            for i in range(ny):
                for j in range(k):
                    out[t0 + tau, i, offset + j] = B[tau * ny + i, j]
        if L == T:
            S = np.dot(AT, S)
        else:
            for _ in range(L):
                S = np.dot(A, S)
        t0 += L
    for t in range(stop, N):
        for i in range(ny):
            for j in range(k):
                out[t, i, offset + j] = 0.0
    if stop < N:
        S[:, :] = 0.0
    return S


def _floor(S0) -> float:
    return FREE_RESPONSE_FLOOR * float(np.abs(S0).max(initial=0.0))


def free_response(Ap, C, S0, N):
    """``C Ap^t S0`` for ``t = 0 .. N-1``, shape (N, ny, k) (``S0`` is (n, k)): the
    output sensitivity to the initial-state directions ``S0``, set to zero from the
    first block of :data:`FREE_BLOCK` samples at whose start every entry of
    ``Ap^t S0`` is below :data:`FREE_RESPONSE_FLOOR` times the largest entry of ``S0``
    (module docstring: the loop does not run on in subnormal numbers)."""
    S0, C = frozen(S0), frozen(C)       # read-only inputs: one compiled signature
    out = np.empty((int(N), C.shape[0], S0.shape[1]))
    _free_response_t(frozen(Ap), C, S0, _floor(S0), out, 0)
    return out


def _decays(Ap, N) -> bool:
    """Whether a free response of ``Ap`` falls below :data:`FREE_RESPONSE_FLOOR`
    within ``N`` samples (spectral radius ``rho`` with ``rho^N`` below it); else the
    initial-state directions stay in the one loop (no second pass over ``J``)."""
    if Ap.shape[0] == 0 or not np.isfinite(Ap).all():
        return False
    rho = float(np.abs(np.linalg.eigvals(Ap)).max())
    return rho == 0.0 or N * np.log(rho) < np.log(FREE_RESPONSE_FLOOR)


def jacobian(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, dx0, *, final_state=False):
    """``(ŷ, J)`` with ``J[t, i, j] = dŷ_i[t] / dθ_j``; shapes (N, ny), (N, ny, d).

    The directions that move the initial state alone get their free response
    (:func:`free_response`, module docstring) when it decays below
    :data:`FREE_RESPONSE_FLOOR` within the record; the others (all, when it
    does not) run in the compiled loop.

    ``final_state=True``: ``(ŷ, J, x[N], s[N])``, the state and the sensitivities
    (shaped as ``dx0``, (d, n)) after the last sample, from which the next samples of
    the record continue (``x0`` and ``dx0`` of the call on them: the record's Jacobian
    a piece at a time, :func:`subid.methods.dt._pe_search.minimise_prediction_error`);
    a free response that fell below the floor continues from zero.
    """
    def last(a):
        return frozen(np.moveaxis(a, 0, -1))
    # read-only inputs: one compiled signature whatever the caller passed
    Ap, Bp, C, Dp, v, x0 = map(frozen, (Ap, Bp, C, Dp, v, x0))
    dAp, dBp, dC, dDp, dx0 = (np.asarray(a, dtype=float) for a in (dAp, dBp, dC, dDp, dx0))
    d = dAp.shape[0]
    moves = np.ones(d, dtype=bool)
    if _decays(Ap, v.shape[0]):
        moves[:] = False
        for a in (dAp, dBp, dC, dDp):
            moves |= np.any(a.reshape(d, -1) != 0, axis=1)
    order = np.concatenate([np.flatnonzero(moves), np.flatnonzero(~moves)])
    if not np.array_equal(order, np.arange(d)):   # the free directions last
        dAp, dBp, dC, dDp, dx0 = (a[order] for a in (dAp, dBp, dC, dDp, dx0))
    k = int(np.count_nonzero(moves))
    J = np.empty((v.shape[0], C.shape[0], d))
    S = np.array(np.moveaxis(dx0[:k], 0, -1), order="C")     # the kernel's state: written
    n, ny, m = Ap.shape[0], C.shape[0], v.shape[1]
    if k * (n + ny) * (n + m) >= BLOCKED_WORK:
        yhat, x_end = _jacobian_blocked(Ap, Bp, C, Dp, v, x0, dAp[:k], dBp[:k], dC[:k],
                                        dDp[:k], S, J)
    else:
        yhat, x_end = _jacobian_t(Ap, Bp, C, Dp, v, x0, last(dAp[:k]), last(dBp[:k]),
                                  last(dC[:k]), last(dDp[:k]), S, J)
    S_end = np.empty((d, n))
    S_end[:k] = S.T
    if k < d:
        S0 = frozen(dx0[k:].T)
        S_end[k:] = _free_response_t(Ap, C, S0, _floor(S0), J, k).T
    if not np.array_equal(order, np.arange(d)):
        J[:, :, order] = J.copy()
        S_end[order] = S_end.copy()
    if final_state:
        return yhat, J, x_end, S_end
    return yhat, J


def jacobian_ref(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, dx0, *, final_state=False):
    """Plain numpy reference of :func:`jacobian`."""
    N = v.shape[0]
    d = dAp.shape[0]
    x = np.array(x0, dtype=float)
    S = np.array(dx0, dtype=float)
    yhat = np.empty((N, C.shape[0]))
    J = np.empty((N, C.shape[0], d))
    for t in range(N):
        yhat[t] = C @ x + Dp @ v[t]
        J[t] = (S @ C.T + np.einsum("jik,k->ji", dC, x) + np.einsum("jik,k->ji", dDp, v[t])).T
        S = S @ Ap.T + np.einsum("jik,k->ji", dAp, x) + np.einsum("jik,k->ji", dBp, v[t])
        x = Ap @ x + Bp @ v[t]
    if final_state:
        return yhat, J, x, S
    return yhat, J
