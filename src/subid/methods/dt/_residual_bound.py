"""A lower bound of the residual of the B, D, x0 regression from part of the record.

``stability='auto'`` (:func:`subid.methods.dt._subspace.stable_choice`) fits B,
D, x0 twice for an unstable A: for the stabilised A, then for the unstable one,
and keeps the unstable model only when its residual RMS is below
``KEEP_UNSTABLE_RATIO`` times the stabilised one's. The unstable fit cannot take
the modal path (its regressors grow), so it is a QR factorisation of the whole
record's regressor: in the cross-validation of the order it cost 20 % of the
default call at 10^5 samples and 35 % at 10^6 (issue 21), on fold models whose
unstable fit nearly always lost.

The least-squares residual over all the samples is at least the least-squares
residual over any subset of them (the minimum of a sum of non-negative terms is at
least the minimum of part of the sum), and at least that of any problem with more
free parameters on that subset. :func:`loses` tries, cheapest first:

1. :func:`strided_residual_at_least`: the same regression as in 2. on every
   :data:`STRIDE`-th sample of the last :data:`TAIL` only (the least-squares residual
   of a subset of the rows of a regression is at most that of all of them): the
   misfit of an unstable A grows over a long window, which a short contiguous tail
   does not show, while the factorisation costs what a tail of ``TAIL / STRIDE``
   does (issue 21: at 10^6 samples the bounds of 21 unstable fold models took 0.28 s of
   the 0.9 s default call, the :data:`SHORT` tail failing on the slightly unstable
   ones, spectral radius 1.005, and the :data:`TAIL` one then proving it at five times
   the cost; 0.14 s in this order); tried
   after 2. when A grows by more than :data:`FAST_GROWTH_DECADES` decades over the
   short tail (its rows over the whole tail would overflow);
2. :func:`relaxed_residual_at_least`: the regression on the last :data:`SHORT`,
   then :data:`TAIL`, of the record alone, with a free initial state of its own
   (the model's state at the start of the tail is one such state, so the full
   fit's residual there is one of the residuals this minimum runs over): the
   reference QR path (:func:`subid.methods.dt._regression.fit_b_d_x0_qr`) on those
   samples only;
3. :func:`residual_at_least`: the rows of the last :data:`TAIL` with the model's own
   state (first those of every :data:`STRIDE`-th sample; when A grows by fewer than
   :data:`SLOW_GROWTH_DECADES` decades over the tail, where 1. and 2. do not prove,
   this alone, or, on a record too short for 1., this first), from the same dual recursions
   (:func:`subid.methods.dt._regression.dual_rows`) run over the whole record (a
   third of the cost of the QR path; a regression that overflows anywhere gives no
   usable fit either).

When a bound already reaches the threshold, the unstable fit loses whatever the
other samples hold, and the fold model is the stabilised one, exactly as the full
fit would have decided. So :func:`loses` factorises a bound's rows by chunks of
:data:`EARLY_CHUNK` samples and stops once the residual of the rows so far reaches the
threshold (:func:`_rows_residual`; issue 21: at 10^5 samples the strided bound proved
20-30 % into its tail, and the unstable fold candidates' cost fell from a third of the
default call to a sixth).
"""

from __future__ import annotations

import math

import numpy as np

from subid.methods._stability import spectral_radius
from subid.methods.dt._regression import (
    _with_d_and_y,
    dual_rows,
    dual_states,
    parameter_count,
)
from subid.statistic.hankel import geqrf_r

#: Fraction of the record (its end) whose residual bounds the whole record's.
TAIL = 0.25
#: The shorter tail tried first (with a free initial state).
SHORT = 0.05
#: Every STRIDE-th sample of the last TAIL enters the first bound tried.
STRIDE = 4
#: The strided bound is tried only when it keeps at least this many samples (on
#: shorter records it rarely proves anything: measured at 10^4 samples).
STRIDED_MIN_SAMPLES = 2048
#: On a record too short for the strided bound, the model's own state on every STRIDE-th
#: sample of the TAIL is tried first (for a slowly growing A) when it keeps at least this
#: many samples (measured: it proved every such fold model at 10^4 samples, none at 10^3).
OWN_STRIDED_MIN_SAMPLES = 256
#: A grows by more than this many decades over the SHORT tail: that tail is tried first.
FAST_GROWTH_DECADES = 30
#: A grows by fewer than this many decades over the TAIL: the bounds with a free state
#: at the tail's start are skipped (measured: they did not prove below 16 decades and
#: did above 27), for 3. on every STRIDE-th sample of the tail first.
SLOW_GROWTH_DECADES = 20
#: Rows of the dual recursion run at a time over the head of the record.
_CHUNK = 8192
#: Samples of the tail (a multiple of the stride) factorised at a time by a bound that may
#: stop once it proves (:func:`_rows_residual`; issue 21: 256 instead of 1024 samples
#: halved the bounds' cost at 10^4 samples, where they prove within the first quarter
#: of the 1,875-sample tails, and left it unchanged at 10^5; the decision does not
#: depend on where a bound stops).
EARLY_CHUNK = 256
#: The bound must exceed the threshold by this relative margin: the QR residuals of
#: the nearly collinear regressors of an A with poles near the unit circle carry
#: rounding errors of up to 2e-4 (relative; measured between the tail's residual with
#: a free and with its own initial state, which equal in exact arithmetic).
MARGIN = 1e-3


def _rows_residual(blocks, p: int, enough=None):
    """``|R[p, p]|`` of the triangular factor of the rows the iterable ``blocks`` yields
    (arrays of ``p + 1`` columns: the regressors, then the output), 0 with fewer than
    ``p + 1`` rows, None when a block is not finite. The blocks are factorised as they
    come (the factor of ``[R; block]``), and once the residual reaches ``enough`` the
    others are not asked for (the least-squares residual of a subset of the rows is at
    most that of all of them: what is returned is still a lower bound of the whole
    record's residual, and it already proves what the caller asks; issue 21: the
    residual of an unstable fold model jumps once its growing mode dominates, 20-30 %
    into the tail on the 10^5-sample folds of ``bench/run.py``)."""
    R = np.zeros((0, p + 1))
    for block in blocks:
        if not np.isfinite(block).all():
            return None
        # scipy.linalg.qr(..., mode='r')[0][:p + 1] by its LAPACK call (the same bits)
        R = geqrf_r(np.vstack([R, block]), p + 1, overwrite=False)
        if enough is not None and R.shape[0] > p and abs(R[p, p]) >= enough:
            break
    return float(abs(R[p, p])) if R.shape[0] > p else 0.0


def _tail_blocks(A, C, u, y, start, V, M, n_x0, stride, p, feedthrough, weights, early):
    """The weighted rows ``[regressors, y]`` of every ``stride``-th sample from ``start``
    (the dual states ``V``, ``M`` there, :func:`subid.methods.dt._regression.dual_rows`):
    in chunks of about :data:`EARLY_CHUNK` samples when ``early`` (each computed when
    asked), else as one block."""
    N = u.shape[0]
    size = EARLY_CHUNK if early else _CHUNK
    chunk = stride * max(size // stride, 1)        # chunks keep the stride's phase
    kept = []
    for a in range(start, N, chunk):
        b = min(a + chunk, N)
        uc = np.ascontiguousarray(u[a:b], dtype=float)
        rows, V, M = dual_rows(A, C, uc, V, M, n_x0)
        block = _with_d_and_y(np.ascontiguousarray(rows[::stride]), uc[::stride],
                              y[a:b:stride], p, feedthrough, weights)
        if early:
            yield block
        else:
            kept.append(block)
    if not early and kept:
        yield np.vstack(kept)


def residual_at_least(A, C, u, y, *, feedthrough: bool, estimate_x0: bool,
                      output_weights, stride: int = 1, enough=None) -> float:
    """A lower bound of the ``residual_rms`` that :func:`subid.methods.dt._regression.fit_b_d_x0`
    reports for ``(A, C)`` on the single record ``(u, y)``: the least-squares residual
    of the rows of its last :data:`TAIL` samples (of every ``stride``-th of them),
    divided by ``sqrt(N ny)`` (``inf`` when the regressors overflow: the full fit
    cannot be used either). With ``enough``, the rows stop once the bound reaches it
    (:func:`_rows_residual`)."""
    A = np.ascontiguousarray(A, dtype=float)
    C = np.ascontiguousarray(C, dtype=float)
    N, nu = u.shape
    n, ny = A.shape[0], y.shape[1]
    n_x0, q, p = parameter_count(n, nu, ny, estimate_x0, feedthrough)
    start = N - max(int(math.ceil(TAIL * N)), 1)
    V, M = np.zeros((ny, nu, n)), C.copy()
    for a in range(0, start, _CHUNK):           # the dual states at the start of the tail
        b = min(a + _CHUNK, start)
        V, M = dual_states(A, C, np.ascontiguousarray(u[a:b], dtype=float), V, M, n_x0)
        if not (np.isfinite(V).all() and np.isfinite(M).all()):
            return math.inf                     # overflowed: so does the full regression
    scale = math.sqrt(N * ny)
    resid = _rows_residual(
        _tail_blocks(A, C, u, y, start, V, M, n_x0, stride, p, feedthrough,
                     np.asarray(output_weights, dtype=float), enough is not None),
        p, None if enough is None else enough * scale)
    return math.inf if resid is None else resid / scale


def relaxed_residual_at_least(A, C, u, y, fraction: float, *, feedthrough: bool,
                              output_weights, enough=None) -> float:
    """A lower bound of the ``residual_rms`` that :func:`subid.methods.dt._regression.fit_b_d_x0`
    reports for ``(A, C)`` on ``(u, y)``, with or without x0: the residual of the same
    regression on the last ``fraction`` of the record alone with a free initial state
    (the rows of the QR path, :func:`subid.methods.dt._regression.fit_b_d_x0_qr`, on
    those samples), divided by ``sqrt(N ny)``; 0 when that regression overflows (no
    bound). With ``enough``, the rows stop once the bound reaches it
    (:func:`_rows_residual`)."""
    return strided_residual_at_least(A, C, u, y, fraction, 1, feedthrough=feedthrough,
                                     output_weights=output_weights, enough=enough)


def strided_residual_at_least(A, C, u, y, fraction: float, stride: int, *,
                              feedthrough: bool, output_weights, enough=None) -> float:
    """A lower bound of the ``residual_rms`` that :func:`subid.methods.dt._regression.fit_b_d_x0`
    reports for ``(A, C)`` on ``(u, y)``, with or without x0: the least-squares residual
    of the rows of every ``stride``-th sample of the regression of
    :func:`relaxed_residual_at_least` on the last ``fraction`` of the record (a free
    initial state at its start), divided by ``sqrt(N ny)``; 0 when those rows overflow
    (no bound). The rows of the whole window come from the dual recursions
    (:func:`subid.methods.dt._regression.dual_rows`); only the kept ones are factorised.
    With ``enough``, the rows stop once the bound reaches it (:func:`_rows_residual`)."""
    A = np.ascontiguousarray(A, dtype=float)
    C = np.ascontiguousarray(C, dtype=float)
    N, nu = u.shape
    n, ny = A.shape[0], y.shape[1]
    _, q, p = parameter_count(n, nu, ny, True, feedthrough)
    T = max(int(math.ceil(fraction * N)), 1)
    weights = None if output_weights is None else np.asarray(output_weights, dtype=float)
    scale = math.sqrt(N * ny)
    resid = _rows_residual(
        _tail_blocks(A, C, u, y, N - T, np.zeros((ny, nu, n)), C.copy(), n, stride, p,
                     feedthrough, weights, enough is not None),
        p, None if enough is None else enough * scale)
    return 0.0 if resid is None else resid / scale


def loses(A, C, u, y, threshold: float, *, feedthrough: bool, estimate_x0: bool,
          output_weights) -> float | None:
    """A bound (those of the module documentation, in the order its spectral radius
    makes cheapest) when one proves the residual RMS of the fit of ``(A, C)`` at least
    ``threshold`` (so that the fit cannot be kept), else None."""
    if not math.isfinite(threshold) or threshold <= 0:
        return None
    from subid.methods.dt._bd_large import DENSE_LIMIT, dense_bytes
    n, nu, ny = A.shape[0], u.shape[1], y.shape[1]
    if dense_bytes(n, nu, ny, max(int(math.ceil(SHORT * u.shape[0])), 1),
                   estimate_x0=True, feedthrough=feedthrough) > DENSE_LIMIT:
        # many channels: both bounds are dense QR factors of n + n nu + ny nu columns (at
        # 100 inputs and outputs, 3 GB: issue 28); no bound, the full fit decides (by the
        # channel elimination of subid.methods.dt._bd_large, bounded in memory)
        return None
    need = threshold * (1.0 + MARGIN)
    radius = spectral_radius(A) if A.size else 0.0     # the one the stability rule took
    N = u.shape[0]
    # the cheapest bound first: on a contiguous SHORT tail when A grows fast over it
    # (its rows overflow over the whole TAIL), every STRIDE-th sample of the TAIL
    # otherwise (a slowly growing mode shows only over a long window)
    decades = math.log10(radius) if radius > 1.0 else 0.0
    fast = SHORT * N * decades > FAST_GROWTH_DECADES
    tries = [("short", SHORT), ("strided", TAIL), ("tail", TAIL)] if fast else \
        [("strided", TAIL), ("short", SHORT), ("tail", TAIL)]
    if TAIL * N < STRIDE * STRIDED_MIN_SAMPLES:
        # a short record: too few rows for the free-state strided bound to prove much.
        # A mode too slow to show within the tail with a free state there (as below):
        # the model's own state over every STRIDE-th sample of the TAIL first, a dual
        # recursion over a few thousand samples and a small QR (issue 21: at 10^4
        # samples it proved the three unstable fold models, 14-15 decades over the
        # tail, that both free-state tails left to the full bound, at under half their
        # cost), when it keeps OWN_STRIDED_MIN_SAMPLES samples (at 10^3 it proved
        # nothing); the free-state tails after it
        tries.remove(("strided", TAIL))
        if TAIL * N * decades < SLOW_GROWTH_DECADES \
                and TAIL * N >= STRIDE * OWN_STRIDED_MIN_SAMPLES:
            tries.insert(0, ("own strided", TAIL))
    elif TAIL * N * decades >= SLOW_GROWTH_DECADES:
        tries.append(("own strided", TAIL))
    else:
        # a mode too slow to show within the tail with a free state there: only the
        # model's own state (the whole record's growth) bounds it
        tries = [("own strided", TAIL)]
    with np.errstate(all="ignore"):
        for kind, fraction in tries:
            if kind == "strided":
                bound = strided_residual_at_least(A, C, u, y, fraction, STRIDE,
                                                  feedthrough=feedthrough,
                                                  output_weights=output_weights, enough=need)
            elif kind == "own strided":
                bound = residual_at_least(A, C, u, y, feedthrough=feedthrough,
                                          estimate_x0=estimate_x0,
                                          output_weights=output_weights, stride=STRIDE,
                                          enough=need)
            else:
                bound = relaxed_residual_at_least(A, C, u, y, fraction, feedthrough=feedthrough,
                                                  output_weights=output_weights, enough=need)
            if bound >= need:
                return bound
        bound = residual_at_least(A, C, u, y, feedthrough=feedthrough, estimate_x0=estimate_x0,
                                  output_weights=output_weights, enough=need)
    return bound if bound >= need else None
