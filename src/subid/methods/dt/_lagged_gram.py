"""The Gram matrix of lagged regressors from sums along its diagonals (the start
regressions of the polynomial searches).

A regression of ``target[t]`` on lagged signals ``s(t - l)`` (:func:`subid.methods.dt.
polynomial.regress`) costs, by Householder QR of the ``N x (m + 1)`` matrix ``[Φ T]``,
``2 N (m + 1)^2`` flops: for the 50th-order ARX model that starts ``oe``, ``bj`` and
``armax`` on two inputs (150 columns), 4.5 x 10^10 flops an output at 10^6 samples, two
thirds of ``oe(data, 2)``. Its Gram matrix ``[Φ T]^T [Φ T]`` has an entry for every
pair of columns, ``G[(s1, l1), (s2, l2)] = Σ_t s1(t - l1) s2(t - l2)`` over the rows
``t = t0 .. t1 - 1`` of an experiment, and along a diagonal of a block (``l1 - l2``
fixed) consecutive entries are sums over windows shifted by one sample:

    G[(s1, l1 + 1), (s2, l2 + 1)] = G[(s1, l1), (s2, l2)]
                                    + s1(t0 - 1 - l1) s2(t0 - 1 - l2)
                                    - s1(t1 - 1 - l1) s2(t1 - 1 - l2).

So one sum over the record per diagonal (``c1 + c2 - 1`` for blocks of ``c1`` and
``c2`` lags) and two products per further entry give the whole matrix exactly (the
same sums in another order): ``N`` times the number of diagonals, about ``2 h ns^2 N /
2`` multiply-adds for ``ns`` signals of ``h`` lags, against ``N m^2`` for the Gram
matrix by a matrix product (50x fewer at ``h = 50``, ``ns = 3``). This is the
"covariance method" of least-squares ARX estimation (Ljung, *System Identification*,
2nd ed., 1999, Sec. 10.1: the normal equations from the sample covariances, with the
sums over the rows actually regressed, not the windowed "autocorrelation method").

The normal equations square the regressors' condition number; their solution serves
as the *start* of a prediction-error search, which then moves it, and
:func:`subid.methods.dt.polynomial.regress_start` takes this route only where the
column-scaled Gram matrix has every Cholesky pivot above
:data:`subid.methods.dt._trust_region.GRAM_PIVOT` (at most about 8 of the 16 digits
lost, the rule of the optimiser's own Gram route), and the QR otherwise.

:func:`lagged_gram` is the compiled kernel's driver; :func:`lagged_gram_reference`
forms ``[Φ T]`` and its product, for the tests.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _diagonal_sum(x, y, lo_x, lo_y, count):  # pragma: no cover
    """``Σ_k x[lo_x + k] y[lo_y + k]`` for ``k < count`` (reassociated: vectorised)."""
    acc = 0.0
    for k in range(count):
        acc += x[lo_x + k] * y[lo_y + k]
    return acc


@numba.njit(cache=True)
def _gram_kernel(Z, first_lag, counts, t0, t1, G):  # pragma: no cover
    """Add the Gram matrix of the lagged columns of the rows ``t0 .. t1 - 1`` to ``G``.

    ``Z`` (ns, N): the signals, one per row; signal ``s`` gives the columns of lags
    ``first_lag[s] .. first_lag[s] + counts[s] - 1``, the columns of the signals in
    turn. Every diagonal of every block ``(s1, s2)``, ``s1 <= s2``, is summed once over
    the rows and slid along (module docstring); the blocks below the diagonal are
    their transposes. Needs ``t0 - first_lag[s] - counts[s] >= 0`` for every ``s``
    (every lag of the rows, and the one past it, inside the record)."""
    ns = Z.shape[0]
    offsets = np.zeros(ns + 1, dtype=np.int64)
    for s in range(ns):
        offsets[s + 1] = offsets[s] + counts[s]
    rows = t1 - t0
    for s1 in range(ns):
        x = Z[s1]
        for s2 in range(s1, ns):
            y = Z[s2]
            c1, c2 = counts[s1], counts[s2]
            o1, o2 = offsets[s1], offsets[s2]
            for k in range(-(c2 - 1), c1):           # k = i - j along the diagonal
                i = max(k, 0)
                j = i - k
                l1 = first_lag[s1] + i
                l2 = first_lag[s2] + j
                acc = _diagonal_sum(x, y, t0 - l1, t0 - l2, rows)
                while i < c1 and j < c2:
                    G[o1 + i, o2 + j] += acc
                    if s1 != s2:
                        G[o2 + j, o1 + i] += acc
                    # the next entry: the window one sample earlier
                    acc += x[t0 - 1 - l1] * y[t0 - 1 - l2] - x[t1 - 1 - l1] * y[t1 - 1 - l2]
                    i += 1
                    j += 1
                    l1 += 1
                    l2 += 1


def contiguous_lags(blocks):
    """``(first_lag, counts)`` of ``blocks`` (``(signal, lags)``) when every block's lags
    are consecutive and ascending; else None."""
    first, counts = [], []
    for _, lags in blocks:
        lags = list(lags)
        if lags and lags != list(range(lags[0], lags[0] + len(lags))):
            return None
        first.append(lags[0] if lags else 0)
        counts.append(len(lags))
    return np.asarray(first, np.int64), np.asarray(counts, np.int64)


def lagged_gram(target, blocks, ranges, first: int):
    """The Gram matrix of ``[Φ T]``, shape ``(m + 1, m + 1)``: the lagged columns of
    ``blocks`` (``(signal, lags)``, each block's lags consecutive, :func:`contiguous_lags`)
    then ``target``, over the rows ``t = a + first .. b - 1`` of every experiment
    ``(a, b)`` of ``ranges`` (those of :func:`subid.methods.dt.polynomial.regress`:
    ``first`` at least the largest lag). Summed along the diagonals (module docstring)."""
    first_lag, counts = contiguous_lags(blocks)
    signals = [s for s, _ in blocks] + [target]
    first_lag = np.append(first_lag, 0)
    counts = np.append(counts, 1)
    m1 = int(counts.sum())
    G = np.zeros((m1, m1))
    # the kernel's last slide of a diagonal reads one sample before its deepest lag; each
    # experiment is copied after that many zeros (read, never kept: the slide that reads
    # them makes no entry)
    reach = int((first_lag + counts).max(initial=0))
    for a, b in ranges:
        if b - a <= first:
            continue
        Z = np.zeros((len(signals), reach + b - a))
        for r, s in enumerate(signals):
            Z[r, reach:] = s[a:b]
        _gram_kernel(Z, first_lag, counts, reach + first, Z.shape[1], G)
    return G


def lagged_gram_reference(target, blocks, ranges, first: int):
    """:func:`lagged_gram` by forming ``[Φ T]`` (for the tests)."""
    rows = []
    for a, b in ranges:
        for t in range(a + first, b):
            rows.append([s[t - lag] for s, lags in blocks for lag in lags] + [target[t]])
    M = np.asarray(rows, dtype=float).reshape(-1, sum(len(lags) for _, lags in blocks) + 1)
    return M.T @ M
