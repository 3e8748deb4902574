"""The search of the prediction-error methods: the predictor, its initial states, and
the trust-region minimisation of the weighted prediction error with the analytic
Jacobian, shared by :func:`subid.pem` (:mod:`subid.methods.dt.pem`), the gain step of
:mod:`subid.methods.dt.gain` and the polynomial methods
(:mod:`subid.methods.dt.pem_poly`).

The criterion, the stopping rules and the Jacobian are those described in
:mod:`subid.methods.dt.pem` (Ljung, *System Identification*, 2nd ed., 1999, Ch. 7 and
Theorem 9.1).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.linalg

from subid.methods.dt import _trust_region
from subid.model import _simulate
from subid.model._sensitivity import free_response, jacobian

#: Past this many bytes, the Jacobian of :func:`minimise_prediction_error` is formed a
#: piece of at most this size at a time and only its Gram matrix (or triangular factor)
#: kept (:func:`subid.methods.dt._trust_region.compress_pieces`): a refinement's memory
#: does not grow with the record, and pieces that stay in the cache are faster than one
#: array (bench/pem_pieces.md: 2x2 order-4 innovation model, 10^6 samples, 1.1 -> 0.5
#: GB of peak memory and 8.3 -> 5.2 s; 16 MiB pieces against 8, 32, 64 and 256 MiB).
JACOBIAN_PIECE_BYTES = 16 * 2**20
#: A trial predictor with a spectral radius above this is treated as unstable.
STABILITY_LIMIT = 1.0 - 1e-9
#: The iteration's defaults: :func:`subid.pem`'s, which
#: :func:`subid.methods.dt.pem.refine` and :func:`subid.methods.dt.gain.refine_gain` use too.
MAX_ITERATIONS, TOLERANCE, ROUNDS = 100, 1e-8, 3


def _predictor(A, B, C, D, K, focus):
    if focus == "prediction":
        return (A - K @ C, np.hstack([B - K @ D, K]), C,
                np.hstack([D, np.zeros((C.shape[0], C.shape[0]))]))
    return A, B, C, D


def _start_x0(Ap, Bp, C, Dp, v, y):
    """Least-squares initial state of the predictor (affine in x0): the forced response
    from a zero state, and the free responses ``C Ap^t e_i``
    (:func:`subid.model._sensitivity.free_response`, zero once decayed below 1e-150
    of their start, so the fit uses the samples before that)."""
    n = Ap.shape[0]
    forced = _simulate.simulate_discrete(Ap, Bp, C, Dp, v, np.zeros(n))[0]
    free = free_response(Ap, C, np.eye(n), v.shape[0])
    alive = np.flatnonzero(np.any(free.reshape(free.shape[0], -1) != 0, axis=1))
    if not alive.size:                   # the state never reaches the output
        return np.zeros(n)
    T = int(alive[-1]) + 1
    x0 = scipy.linalg.lstsq(free[:T].reshape(-1, n), (y[:T] - forced[:T]).reshape(-1),
                            lapack_driver="gelsy", check_finite=False)[0]
    return x0


def _simulate_experiments(Ap, Bp, C, Dp, v, x0s, ranges):
    """The predictor (or simulation) of every experiment from its own initial state
    (row ``e`` of ``x0s``): ``(ŷ, X)`` stacked in time order."""
    parts = [_simulate.simulate_discrete(Ap, Bp, C, Dp, v[a:b], x0s[e])
             for e, (a, b) in enumerate(ranges)]
    return np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])


def _radius(M) -> float:
    return float(np.abs(np.linalg.eigvals(M)).max())


def block_jacobian(mats, v, x0, dirs, blocks, dm, *, final_state=False):
    """``(ŷ, J)`` of :func:`subid.model._sensitivity.jacobian` for a block-diagonal
    predictor, the kernel run on each block with its own coordinates and states.

    ``mats = (Ap, Bp, C, Dp)``, ``dirs`` the direction arrays of every
    coordinate (``dm`` model coordinates, then one per state for x0),
    ``blocks`` the ``(states, coordinates)`` index arrays (see
    :func:`minimise_prediction_error`). Each block's output is
    ``C[:, s] x_s``; ``ŷ`` adds them and ``Dp v`` once. ``final_state=True``: also the
    state and the sensitivities (shaped as ``dx0``) after the last sample, each block's
    own (a block's coordinates move only its states), from which the next samples
    continue.
    """
    Ap, Bp, C, Dp = mats
    dAp, dBp, dC, dDp, dx0 = dirs
    N, n = v.shape[0], Ap.shape[0]
    ny = C.shape[0]
    J = np.zeros((N, ny, dm + n))
    yhat = v @ Dp.T
    zero_dp = np.zeros_like(Dp)
    x_end, S_end = np.zeros(n), np.zeros(np.shape(dx0))
    for states, coords in blocks:
        s = np.asarray(states, dtype=np.int64)
        rows = np.concatenate([np.asarray(coords, dtype=np.int64), dm + s])
        sub = [np.ascontiguousarray(a) for a in (
            Ap[np.ix_(s, s)], Bp[s], C[:, s], zero_dp, v, x0[s],
            dAp[np.ix_(rows, s, s)], dBp[rows][:, s], dC[rows][:, :, s], dDp[rows],
            dx0[np.ix_(rows, s)])]
        if final_state:
            yb, Jb, x_end[s], S_end[np.ix_(rows, s)] = jacobian(*sub, final_state=True)
        else:
            yb, Jb = jacobian(*sub)
        yhat += yb
        J[:, :, rows] = Jb
    if final_state:
        return yhat, J, x_end, S_end
    return yhat, J


def minimise_prediction_error(predictor, directions, dm, x0, v, y, ranges, W, max_nfev,
                              tolerance, history, penalty, fit_x0=True, blocks=None,
                              decrement_tol=0.0, stall_tol=0.0):
    """Minimise ``1/(2N) sum ||W (y - ŷ)||^2`` over ``dm`` model coordinates and the
    initial states.

    The optimiser shared by :func:`pem` and the polynomial methods
    (:mod:`subid.methods.dt.pem_poly`). ``predictor(z)`` gives the predictor
    ``(Ap, Bp, C, Dp)`` driven by ``v`` at the model coordinates ``z``;
    ``directions(z)`` its derivatives ``(dAp, dBp, dC, dDp, dx0)`` along the
    ``dm`` coordinates followed by ``n`` rows for the initial state (the
    arrays of :func:`subid.model._sensitivity.jacobian`). ``x0`` holds one
    initial state per experiment (row), each experiment predicted from its
    own (fixed at ``x0`` when ``fit_x0`` is false: then ``directions`` gives
    the ``dm`` model rows only). A trial whose predictor is unstable or
    overflows costs ``penalty`` per residual, more than the start, so the
    trust region rejects it. ``blocks`` (optional) declares a block-diagonal
    predictor: a list of ``(states, coordinates)`` index arrays such that the
    coordinates of a block move only its own rows and columns of ``Ap``, rows
    of ``Bp`` and columns of ``C`` (an output-error model, one block per
    input); the sensitivities are then run block by block
    (:func:`block_jacobian`), which gives the same Jacobian at a fraction of
    the cost. ``decrement_tol`` (optional): stop where the Gauss-Newton step
    predicts a decrease of the criterion below it
    (:func:`subid.methods.dt._trust_region.trust_region_least_squares`;
    :func:`statistical_precision`); ``stall_tol`` (optional): stop where the evaluations
    left would, at the rate of the last steps, decrease it by less.

    Returns
    -------
    z, result
        The coordinates reached (``dm`` model coordinates, then the changes of
        the initial states) and the optimiser's result (``x``, ``cost``,
        ``nfev``, ``status``, ``message`` as :func:`scipy.optimize.least_squares`
        gives them; :func:`subid.methods.dt._trust_region.trust_region_least_squares`).
    """
    N, ny = y.shape
    n_exp, n = x0.shape
    scale = 1.0 / math.sqrt(N)
    n_x0 = n_exp * n if fit_x0 else 0

    def initial(z):
        return x0 + z[dm:].reshape(n_exp, n) if fit_x0 else x0

    def fun(z):
        Ap, Bp, Cp, Dp = predictor(z[:dm])
        if not np.isfinite(Ap).all() or (n and _radius(Ap) >= STABILITY_LIMIT):
            return np.full(N * ny, penalty)
        with np.errstate(all="ignore"):
            yhat = _simulate_experiments(Ap, Bp, Cp, Dp, v, initial(z), ranges)[0]
        if not np.isfinite(yhat).all():
            return np.full(N * ny, penalty)
        return (((y - yhat) @ W.T) * scale).ravel()

    yw = y @ W.T
    width = dm + n_x0

    def kernel_arrays(z):
        # the weighting W is linear in the outputs: run the kernel on the weighted
        # output matrices (W C, W Dp, W dC, W dDp), which gives W ŷ and W J directly
        Ap, Bp, Cp, Dp = predictor(z[:dm])
        mats_c = [np.ascontiguousarray(a) for a in (Ap, Bp, W @ Cp, W @ Dp)]
        dAp, dBp, dC, dDp, dx0 = directions(z[:dm])
        dirs = [np.ascontiguousarray(a) for a in (
            dAp, dBp, np.einsum("ik,jkl->jil", W, dC), np.einsum("ik,jkl->jil", W, dDp), dx0)]
        if not fit_x0 and blocks is None:     # the model directions only (the block
            dirs = [np.ascontiguousarray(a[:dm]) for a in dirs]   # kernel needs all rows)
        return mats_c, dirs

    def columns(Je, e):
        """The rows of J (``-scale`` times the weighted sensitivities, non-finite entries
        zero) from the kernel's array of experiment ``e``: its model columns and its
        initial state's, the other experiments' zero (the kernel's own array where its
        columns are J's)."""
        if len(ranges) == 1 and Je.shape[2] == width:
            J = Je
        else:
            J = np.zeros((Je.shape[0], ny, width))
            J[:, :, :dm] = Je[:, :, :dm]
            if fit_x0:
                J[:, :, dm + e * n:dm + (e + 1) * n] = Je[:, :, dm:]
        J *= -scale
        return J if np.isfinite(J).all() else \
            np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)

    routes = []                           # the compression of every Jacobian in pieces

    def compressed(z, f):
        """The trust region's factor of the Jacobian at ``z`` (``f`` the residual
        there), the Jacobian formed a piece of at most JACOBIAN_PIECE_BYTES at a time,
        each experiment's kernel continuing from the state and sensitivities where its
        last piece ended."""
        mats_c, dirs = kernel_arrays(z)
        x0s = initial(z)
        rows = max(1, int(JACOBIAN_PIECE_BYTES // (8 * ny * width)))
        power, passes = [], []

        def pieces():                     # a second pass on the QR route only
            passes.append(1)
            for e, s, t, yh, Je in kernel_pieces(mats_c, dirs, v, x0s, ranges, rows,
                                                  blocks, dm):
                if len(passes) == 1:
                    power.append(float(np.sum(((yw[s:t] - yh) * scale) ** 2)))
                yield s * ny, t * ny, columns(Je, e).reshape(-1, width)
        # the QR route expected where the last Jacobian took it: one pass, not two
        out = _trust_region.compress_pieces(pieces, f, width,
                                            householder=routes[-1:] == ["qr"])
        routes.append(out[4])
        history.append(0.5 * sum(power))
        return out

    def jac(z):
        mats_c, dirs = kernel_arrays(z)
        x0s = initial(z)
        yhat, parts = np.empty((N, ny)), []
        for e, a, b, yh, Je in kernel_pieces(mats_c, dirs, v, x0s, ranges, None, blocks, dm):
            yhat[a:b] = yh
            parts.append(columns(Je, e))
        history.append(0.5 * float(np.sum(((yw - yhat) * scale) ** 2)))
        J = parts[0] if len(parts) == 1 else np.concatenate(parts)
        return J.reshape(N * ny, -1)

    # past JACOBIAN_PIECE_BYTES the Jacobian is never whole
    pieced = 8.0 * N * ny * width > JACOBIAN_PIECE_BYTES
    z0 = np.zeros(width)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = _trust_region.trust_region_least_squares(
            fun, jac, z0, ftol=tolerance, xtol=tolerance, gtol=tolerance, max_nfev=max_nfev,
            **({"decrement_tol": decrement_tol} if decrement_tol > 0 else {}),
            **({"stall_tol": stall_tol} if stall_tol > 0 else {}),
            **({"compressed": compressed} if pieced else {}))
    return res.x, res


def kernel_pieces(mats, dirs, v, x0s, ranges, rows, blocks, dm):
    """``(e, start, stop, ŷ, J)`` of the sensitivity kernel over the record, in order:
    each experiment ``e`` of ``ranges`` from its initial state ``x0s[e]`` and the
    initial sensitivities ``dirs[4]``, at most ``rows`` samples a piece (None: one piece
    per experiment), each piece continuing from the state and sensitivities where the
    last one ended. ``mats = (Ap, Bp, C, Dp)`` and ``dirs`` as
    :func:`subid.model._sensitivity.jacobian` takes them; ``blocks`` (or None) the
    block-diagonal layout of :func:`block_jacobian`, ``dm`` its model coordinates. The
    pieces of :func:`minimise_prediction_error`'s Jacobian and of the polynomial
    methods' covariance (:mod:`subid.methods.dt.pem_poly`)."""
    for e, (a, b) in enumerate(ranges):
        x, S = np.ascontiguousarray(x0s[e]), dirs[4]
        step = max(b - a if rows is None else int(rows), 1)
        for start in range(a, b, step):
            stop = min(start + step, b)
            vs = np.ascontiguousarray(v[start:stop])
            if blocks is None:
                yh, J, x, S = jacobian(*mats, vs, x, *dirs[:4], S, final_state=True)
            else:
                yh, J, x, S = block_jacobian(mats, vs, x, dirs[:4] + [S], blocks, dm,
                                             final_state=True)
            yield e, start, stop, yh, J


def statistical_precision(n_parameters: int, n_samples: int, fraction: float) -> float:
    """``fraction * d / (2 N)``: a decrease of the criterion the data cannot resolve.

    With the errors whitened by ``W`` (unit covariance at the start), the
    criterion at the true parameters exceeds its minimum by
    ``0.5 (θ0 - θ̂)^T V'' (θ0 - θ̂)``, whose expectation is ``d / (2 N)`` for
    ``d`` parameters, since ``Cov(θ̂) = V''^-1 / N`` (Ljung, *System
    Identification*, 2nd ed., 1999, Sec. 9.2 and Theorem 9.1). An iterate whose
    Gauss-Newton decrement (the decrease the full step predicts,
    ``0.5 (θ - θ̂)^T V'' (θ - θ̂)`` near the minimum) is below ``fraction`` of
    that scale lies ``sqrt(fraction)`` estimation standard deviations (in the
    ``V''`` metric) from the minimum, adding ``fraction`` to the mean squared
    parameter error: with ``fraction = 1e-3`` the estimate keeps its efficiency
    to 0.1 %. A stopping rule in the scale of the problem (Dennis and Schnabel,
    *Numerical Methods for Unconstrained Optimization and Nonlinear Equations*,
    1996, Sec. 7.2), the scale here being the statistical one.
    """
    return fraction * n_parameters / (2.0 * n_samples)


