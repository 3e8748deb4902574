"""The cross-validation score of a candidate model, computed directly.

:func:`subid.methods.dt.selection.score_horizon` scores every fold model by
its simulation fit on the held-out block with the initial state fitted by
least squares: the quantity ``mean(fit_percent(model, validation))`` of
:func:`subid.model.fit.fit_percent` (x0 ``'estimate'``). That
general function simulates the model once for the forced response, then once
per state for the free responses ``C A^t e_j`` over the whole block (it stops
only after blocks of 65,536 samples), and reduces the x0 regression by a QR
factorisation of ``N ny`` rows, so its cost grew with ``n`` simulations of
the block per candidate (55 % of the default call at 10^5 samples; minutes
when a stabilised candidate has a pole at radius 0.9999).

Here the same quantity comes from one compiled pass (:func:`forced_error`):
the forced response ``y_f`` and the free response ``F(t) = C A^t`` propagated
as ``F(t+1) = F(t) A`` (``ny n^2`` flops a sample instead of ``n`` state
simulations), the latter only while ``A^t`` has not decayed below
:data:`FREE_DECAYED` (:func:`free_length`, by repeated squaring: beyond it
the rows change x0 by less than rounding, as :func:`subid.model.prediction.simulate_fit`
argues). The x0 regression is the same weighted least-squares problem (each
output weighted by the inverse of its standard deviation over the validation
record), solved through the triangular factor of ``[F w, (y - y_f) w]`` by
the same minimum-norm ``lstsq`` with the same cut-off. Beyond the decay the
error ``y - y_f`` is summed in the same pass, so the simulated output is never
stored; the fit is then ``100 (1 - ||y - ŷ|| / ||y - ȳ||)`` per output, pooled over the experiments
of a merged record (each with its own x0 and mean), as ``fit_percent`` pools
them. The scores equal ``fit_percent``'s to rounding
(``tests/test_selection_speed.py`` compares both on several records).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from subid._kernel_args import read_only
from subid.statistic.hankel import geqrf_r

#: ``A^t`` counts as decayed below this (relative to the identity): later free rows
#: change x0 by less than rounding (:data:`subid.model.prediction._FREE_DECAYED`).
FREE_DECAYED = 1e-20


#: Records up to this many samples keep their whole free response (cheaper than
#: finding where it decays).
SHORT_RECORD = 2048


def free_length(A: np.ndarray, n_samples: int) -> int:
    """Samples of the free response to keep: the smallest power of two ``T`` with
    ``max |A^T| < FREE_DECAYED`` (by repeated squaring), at most ``n_samples``
    (all of them up to :data:`SHORT_RECORD`)."""
    if A.shape[0] == 0:
        return 0
    if n_samples <= SHORT_RECORD:
        return n_samples
    P = np.array(A, dtype=float)
    T = 1
    with np.errstate(all="ignore"):
        while T < n_samples:
            size = np.abs(P).max()
            if not math.isfinite(size):
                return n_samples
            if size < FREE_DECAYED:
                return T
            P = P @ P
            T *= 2
    return n_samples


def forced_and_free_reference(A, B, C, D, u, n_free):
    """Forced response ``y`` (zero initial state) of ``(A, B, C, D)`` to ``u`` and free
    response ``F[t] = C A^t`` for ``t < n_free`` (plain numpy; the reference behind
    :func:`forced_error_reference`). Returns ``(y, F)``."""
    N = u.shape[0]
    n, ny = A.shape[0], C.shape[0]
    y = np.empty((N, ny))
    F = np.empty((n_free, ny, n))
    x = np.zeros(n)
    for t in range(N):
        y[t] = C @ x + D @ u[t]
        x = A @ x + B @ u[t]
    M = C.copy()
    for t in range(n_free):
        F[t] = M
        M = M @ A
    return y, F


def forced_error_reference(A, B, C, D, u, y, weights, inv_scale, n_free):
    """Plain-numpy reference of :func:`forced_error`."""
    forced, F = forced_and_free_reference(A, B, C, D, u, n_free)
    n = A.shape[0]
    rows = np.empty((n_free, y.shape[1], n + 1))
    rows[:, :, :n] = F * weights[None, :, None]
    rows[:, :, n] = (y[:n_free] - forced[:n_free]) * weights
    tail = np.sum(((y[n_free:] - forced[n_free:]) * inv_scale) ** 2, axis=0)
    return rows, tail, bool(np.isfinite(forced).all())


@numba.njit(cache=True, nogil=True, inline="always")
def output_error(C, D, x, u, y, t, weights, inv_scale, n_free, rows, tail):  # pragma: no cover
    """One sample of the simulation-error pass of :func:`forced_error` (and of
    :func:`subid.methods.dt._sparse_scoring.sparse_forced_error`): the error
    ``y(t) - C x - D u(t)`` of every output, weighted into the last column of
    ``rows[t]`` while ``t < n_free``, else scaled by ``inv_scale`` and its square
    added to ``tail``. Returns False when an output's simulated value is not
    finite (the state overflowed)."""
    finite = True
    n = x.shape[0]
    for i in range(C.shape[0]):
        s = 0.0
        for j in range(n):
            s += C[i, j] * x[j]
        for j in range(u.shape[1]):
            s += D[i, j] * u[t, j]
        if not np.isfinite(s):
            finite = False
        e = y[t, i] - s
        if t < n_free:
            rows[t, i, n] = e * weights[i]
        else:
            e *= inv_scale[i]
            tail[i] += e * e
    return finite


@numba.njit(cache=True, nogil=True)
def forced_error(A, B, C, D, u, y, weights, inv_scale, n_free):  # pragma: no cover - compiled
    """The simulation error of ``(A, B, C, D)`` on ``(u, y)`` from a zero initial
    state, in one pass and without storing the simulated output: the weighted
    rows ``[C A^t w, (y(t) - y_f(t)) w]`` of the x0 regression for ``t < n_free``
    (``w`` = ``weights``), and ``sum_{t >= n_free} ((y - y_f) inv_scale)^2`` per
    output, where the free response has decayed. Returns ``(rows, tail, finite)``,
    ``finite`` false when the forced response overflowed."""
    N, nu = u.shape
    n = A.shape[0]
    ny = C.shape[0]
    rows = np.empty((n_free, ny, n + 1))
    tail = np.zeros(ny)
    finite = True
    x = np.zeros(n)
    xn = np.empty(n)
    for t in range(N):
        if not output_error(C, D, x, u, y, t, weights, inv_scale, n_free, rows, tail):
            finite = False
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += A[i, j] * x[j]
            for j in range(nu):
                s += B[i, j] * u[t, j]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]
    M = C.copy()
    Mn = np.empty_like(M)
    for t in range(n_free):
        for i in range(ny):
            for j in range(n):
                rows[t, i, j] = M[i, j] * weights[i]
        for i in range(ny):
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += M[i, k] * A[k, j]
                Mn[i, j] = s
        for i in range(ny):
            for j in range(n):
                M[i, j] = Mn[i, j]
    return rows, tail, finite


def _error_power(A, B, C, D, u, y, weights, inv_scale, kernel):
    """``sum_t ((y - ŷ) inv_scale)^2`` per output of one experiment, ``ŷ`` simulated
    from the least-squares x0; None when the simulation overflows."""
    N, ny = y.shape
    n = A.shape[0]
    n_free = free_length(A, N)
    with np.errstate(all="ignore"):
        # read-only inputs: one compiled signature whatever the caller passed
        rows, tail, finite = kernel(*read_only(A, B, C, D, u, y), weights, inv_scale, n_free)
        if not (finite and np.isfinite(rows[:, :, :n]).all()):
            return None
        if n_free == 0:                 # no state (free_length is 0 for n = 0)
            return tail
        flat = rows.reshape(-1, n + 1)
        R = geqrf_r(flat, min(flat.shape[0], n + 1), overwrite=False)
        # the minimum-norm lstsq of simulate_fit, with its cut-off
        cut = np.finfo(float).eps * max(N * ny, n)
        Rn = np.zeros((n, n + 1))
        Rn[:min(R.shape[0], n)] = R[:n]
        x0 = np.linalg.lstsq(Rn[:, :n], Rn[:, n], rcond=cut)[0]
        # the weighted residual of the x0 regression, back in the units of the score
        head = (flat[:, n] - flat[:, :n] @ x0).reshape(n_free, ny) * (inv_scale / weights)
        if not np.isfinite(head).all():
            return None
        return tail + np.sum(head ** 2, axis=0)


class Held:
    """What the score of every candidate needs from one validation record, once:
    its pieces (one per experiment), the x0 weights (inverse standard deviation
    over the whole record, as ``fit_percent`` weighs them), the scale of each
    output and the spread ``sum (y - ȳ_e)^2`` the fit divides by. With ``lagged``,
    the lag products of every piece (:class:`subid.methods.dt._lag_fit.LagProducts`,
    computed at the first score), from which the score of a stable candidate costs
    no pass over the record."""

    def __init__(self, validation, *, lagged=False):
        self.lagged = lagged
        self._products = None
        self.record = validation          # for continuous-time models (fit_percent, their hold)
        y_all = validation.y
        # channel by channel (numpy's axis-0 reductions over a few columns were 20 ms
        # of the default call at 10^5 samples): the same values to rounding
        channels = np.ascontiguousarray(y_all.T, dtype=float)
        std = np.array([c.std() for c in channels])
        self.weights = 1.0 / np.where(std > 0, std, 1.0)
        self.scale = np.array([max(c.max(), -c.min()) for c in channels], dtype=float)
        self.scale[self.scale == 0] = 1.0
        ranges = validation.experiment_ranges
        self.pieces = [(np.ascontiguousarray(validation.u[a:b], dtype=float),
                        np.ascontiguousarray(y_all[a:b], dtype=float)) for a, b in ranges]
        self.dev2 = np.zeros(y_all.shape[1])
        for a, b in ranges:
            for k, c in enumerate(channels):
                ys = c[a:b] / self.scale[k]
                self.dev2[k] += np.sum((ys - ys.mean()) ** 2)

    def seed(self, products):
        """Use these lag products (one per piece; None where not applicable)."""
        self._products = list(products)

    def products(self):
        """The lag products of every piece (None without ``lagged``)."""
        if not self.lagged:
            return [None] * len(self.pieces)
        if self._products is None:
            from subid.methods.dt._lag_fit import LagProducts, worthwhile
            self._products = [LagProducts(u, y) if worthwhile(*u.shape) else None
                              for u, y in self.pieces]
        return self._products


def simulation_fit(A, B, C, D, validation, *, kernel=forced_error):
    """Simulation fit (%) per output of the discrete model ``(A, B, C, D)`` on
    ``validation`` (an IOData record or its :class:`Held`) with x0 by least
    squares: ``fit_percent(model, validation)`` to rounding (see the module
    documentation), or None when the simulation overflows or an output is
    constant. ``kernel``: :func:`forced_error` or its reference. A :class:`Held`
    with lag products scores a stable candidate from them where they apply
    (:func:`subid.methods.dt._lag_fit.error_power`: the same value to rounding)."""
    from subid.methods.dt._lag_fit import error_power
    held = validation if isinstance(validation, Held) else Held(validation)
    if np.any(held.dev2 == 0):
        return None
    A, B, C, D = (np.ascontiguousarray(M, dtype=float) for M in (A, B, C, D))
    err2 = np.zeros(held.dev2.shape)
    inv_scale = 1.0 / held.scale
    for (u, y), lp in zip(held.pieces, held.products()):
        power = None if lp is None else error_power(A, B, C, D, lp, held.weights, inv_scale)
        if power is None:
            power = _error_power(A, B, C, D, u, y, held.weights, inv_scale, kernel)
        if power is None:
            return None
        err2 += power
    return fits_of_error(err2, held)


def fits_of_error(err2, held):
    """The simulation fit (%) per output of :func:`simulation_fit` from the error power
    ``err2`` per output (in the units of ``held.scale``) on the validation record of
    ``held`` (a :class:`Held`); None when an output of it is constant."""
    if np.any(held.dev2 == 0):
        return None
    with np.errstate(all="ignore"):
        return 100.0 * (1.0 - np.sqrt(err2) / np.sqrt(held.dev2))
