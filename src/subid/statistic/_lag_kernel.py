"""Compiled kernel of the lagged products of the ``'gram'`` statistic.

:func:`lag_sums_kernel` computes what :func:`subid.statistic.hankel.lag_sums`
computes with matrix products (the reference the tests compare against), in
one pass over the samples: for each sample ``t`` the ``depth`` lagged
products ``z(t) z(t + l)^T`` are one stretch of ``depth * q`` consecutive
numbers of the channel-interleaved record, so they accumulate as ``q``
contiguous multiply-adds (vectorised) into a per-block partial sum. It
releases the GIL, so it can run beside a parser thread. Measured 1.7x (2x2,
depth 20) to 4x (1x1) faster than the blocked matrix products, whose tiny
``q x q`` results leave BLAS memory-bound. Four samples go through each partial sum at
a time (its additions in the same order, so the same bits: one load and store of it per
four multiply-adds; issue 21: 1.6-2x faster at 2x2, depth 40, the fold statistics of the
order search).
"""

from __future__ import annotations

import numba
import numpy as np

#: Samples per partial sum: the interleaved block (``(_BLOCK + depth) q``
#: doubles) stays in the first-level caches, and the rounding error grows
#: with the block, not with the record.
_BLOCK = 4096


@numba.njit(cache=True, nogil=True)
def lag_sums_kernel(u, y, depth):  # pragma: no cover - compiled
    """``out[l] = sum_{t=0}^{T-1-l} z(t) z(t+l)^T``, ``z = [u, y]``, ``l < depth``."""
    T = u.shape[0]
    nu = u.shape[1]
    ny = y.shape[1]
    q = nu + ny
    width = depth * q
    out = np.zeros((depth, q, q))
    part = np.empty((q, width))
    z = np.empty((_BLOCK + depth - 1) * q)
    for b0 in range(0, T, _BLOCK):
        b1 = min(b0 + _BLOCK, T)
        stop = min(b1 + depth - 1, T)      # the block and the samples its lags reach
        for t in range(b0, stop):
            base = (t - b0) * q
            for j in range(nu):
                z[base + j] = u[t, j]
            for j in range(ny):
                z[base + nu + j] = y[t, j]
        part[:, :] = 0.0
        full = max(min(b1, T - depth + 1) - b0, 0)    # rows with every lag inside
        # four rows at a time, each entry's additions in the order of the rows (the
        # same sums, the same bits as one row at a time) with one load and store of
        # the partial sum per four rows instead of per row
        four = full - full % 4
        for t in range(0, four, 4):
            r0 = t * q
            r1 = r0 + q
            r2 = r1 + q
            r3 = r2 + q
            for i in range(q):
                a0 = z[r0 + i]
                a1 = z[r1 + i]
                a2 = z[r2 + i]
                a3 = z[r3 + i]
                for w in range(width):
                    acc = part[i, w]
                    acc += a0 * z[r0 + w]
                    acc += a1 * z[r1 + w]
                    acc += a2 * z[r2 + w]
                    acc += a3 * z[r3 + w]
                    part[i, w] = acc
        for t in range(four, full):
            base = t * q
            for i in range(q):
                a = z[base + i]
                for w in range(width):
                    part[i, w] += a * z[base + w]
        for t in range(full, b1 - b0):                 # the last rows: long lags run out
            base = t * q
            reach = (stop - b0 - t) * q
            for i in range(q):
                a = z[base + i]
                for w in range(reach):
                    part[i, w] += a * z[base + w]
        for lag in range(depth):
            for i in range(q):
                for j in range(q):
                    out[lag, i, j] += part[i, lag * q + j]
    return out


@numba.njit(cache=True)
def open_gram_kernel(lagged, head, tail, n_inputs):  # pragma: no cover - compiled
    """``H H^T`` of the open experiment from its lagged products and edge samples, in
    the row order ``[U_0..U_{s-1}; Y_0..Y_{s-1}]``: what
    :meth:`subid.statistic.hankel.HankelStatistic._open_gram_sum_by_lag` computes, with
    the same additions in the same order (so the same bits). Block ``(i, i + l)`` is
    ``S_l`` less the products ``z(t) z(t+l)^T`` with ``t < i`` (within the head) and
    those with ``t >= i + K`` (the tail's ``k >= i``)."""
    s = lagged.shape[0]
    q = lagged.shape[1]
    ny = q - n_inputs
    m = s * q
    out = np.zeros((m, m))
    early = np.zeros((q, q))
    late = np.zeros((s, q, q))
    for lag in range(s):
        n = s - 1 - lag                  # block rows i = 0 .. n take this lag
        # late[i] = sum_{k = i}^{n-1} tail[k] tail[k + lag]^T, summed from k = n - 1 down
        for a in range(q):
            for b in range(q):
                late[n, a, b] = 0.0
        for k in range(n - 1, -1, -1):
            for a in range(q):
                for b in range(q):
                    late[k, a, b] = late[k + 1, a, b] + tail[k, a] * tail[k + lag, b] \
                        if k < n - 1 else tail[k, a] * tail[k + lag, b]
        for a in range(q):
            for b in range(q):
                early[a, b] = 0.0
        for i in range(n + 1):
            if i > 0:                    # early = sum_{t < i} head[t] head[t + lag]^T
                t = i - 1
                for a in range(q):
                    for b in range(q):
                        early[a, b] = early[a, b] + head[t, a] * head[t + lag, b] \
                            if t > 0 else head[t, a] * head[t + lag, b]
            j = i + lag
            for a in range(q):
                ra = i * n_inputs + a if a < n_inputs else s * n_inputs + i * ny + a - n_inputs
                for b in range(q):
                    rb = j * n_inputs + b if b < n_inputs else \
                        s * n_inputs + j * ny + b - n_inputs
                    v = lagged[lag, a, b] - early[a, b] - late[i, a, b]
                    if lag > 0:          # block (i, i + lag), and its mirror below
                        out[ra, rb] = v
                    out[rb, ra] = v      # (at lag 0 the mirror is what the reference keeps)
    return out
