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
form); otherwise every direction stays in the one loop.
"""

from __future__ import annotations

import numba
import numpy as np

from subid._kernel_args import frozen

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
    directions fill the first ``d`` columns of ``J`` (N, ny, >= d)."""
    N = v.shape[0]
    n = Ap.shape[0]
    ny = C.shape[0]
    d = S.shape[1]
    yhat = np.empty((N, ny))
    x = x0.copy()
    xn = np.empty(n)
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
    return yhat


@numba.njit(cache=True, fastmath={'contract'})
def _free_response_t(Ap, C, S, floor, out, offset):  # pragma: no cover
    """``C Ap^t S`` for ``t < N`` into the columns ``offset:offset + k`` of ``out``
    (N, ny, >= offset + k), zero from the first ``t`` at which every entry of
    ``Ap^t S`` is below ``floor``."""
    n, k = S.shape
    N, ny = out.shape[0], out.shape[1]
    S = S.copy()
    Sn = np.empty((n, k))
    stop = N
    for t in range(N):
        big = 0.0
        for i in range(n):
            for j in range(k):
                big = max(big, abs(S[i, j]))
        if big < floor:
            stop = t
            break
        for i in range(ny):
            row = out[t, i, offset:offset + k]
            for j in range(k):
                row[j] = 0.0
            for m in range(n):
                c = C[i, m]
                Sm = S[m]
                for j in range(k):
                    row[j] += c * Sm[j]
        for i in range(n):
            for j in range(k):
                Sn[i, j] = 0.0
            for m in range(n):
                a = Ap[i, m]
                Sm = S[m]
                for j in range(k):
                    Sn[i, j] += a * Sm[j]
        S, Sn = Sn, S
    for t in range(stop, N):
        for i in range(ny):
            for j in range(k):
                out[t, i, offset + j] = 0.0


def _floor(S0) -> float:
    return FREE_RESPONSE_FLOOR * float(np.abs(S0).max(initial=0.0))


def free_response(Ap, C, S0, N):
    """``C Ap^t S0`` for ``t = 0 .. N-1``, shape (N, ny, k) (``S0`` is (n, k)): the
    output sensitivity to the initial-state directions ``S0``, set to zero from the
    first sample at which every entry of ``Ap^t S0`` is below
    :data:`FREE_RESPONSE_FLOOR` times the largest entry of ``S0`` (module
    docstring: the loop never enters subnormal numbers)."""
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


def jacobian(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, dx0):
    """``(ŷ, J)`` with ``J[t, i, j] = dŷ_i[t] / dθ_j``; shapes (N, ny), (N, ny, d).

    The directions that move the initial state alone get their free response
    (:func:`free_response`, module docstring) when it decays below
    :data:`FREE_RESPONSE_FLOOR` within the record; the others (all, when it
    does not) run in the compiled loop.
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
    yhat = _jacobian_t(Ap, Bp, C, Dp, v, x0, last(dAp[:k]), last(dBp[:k]), last(dC[:k]),
                       last(dDp[:k]), S, J)
    if k < d:
        S0 = frozen(dx0[k:].T)
        _free_response_t(Ap, C, S0, _floor(S0), J, k)
    if not np.array_equal(order, np.arange(d)):
        J[:, :, order] = J.copy()
    return yhat, J


def jacobian_ref(Ap, Bp, C, Dp, v, x0, dAp, dBp, dC, dDp, dx0):
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
    return yhat, J
