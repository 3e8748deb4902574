"""The simulation pass of the validation score for realisations with many zeros.

:func:`subid.methods.dt._scoring.forced_error` simulates a candidate
``(A, B, C, D)`` over a validation block and propagates its free response
``C A^t`` with dense loops: ``n^2`` multiply-adds a sample for the state update
and ``ny n^2`` for the free response. The realisations of the polynomial models
(:func:`subid.model.polynomial.realise`) are mostly zeros: the block observer
form of an ARX model of ``ny`` outputs and degree ``p`` (``n = ny p``) has
``A = [-A_1 I 0 ...; -A_2 0 I ...; ...]`` (``n (ny + 1)`` nonzero entries of
``n^2``) and ``C = [I 0 ... 0]`` (Kailath, *Linear Systems*, 1980, Ch. 6).
The structure search of :func:`subid.arx` scores some thirty such candidates
per fold, each by this pass.

:func:`sparse_forced_error` is the same pass over the nonzero entries of ``A``
(its compressed rows for the state update, its compressed columns for ``C A^t``;
``B``, ``C``, ``D`` dense, as the data they multiply are), each sum taken in the
same order as the dense loop. A skipped term is an exact zero product, and
adding it leaves a floating-point sum unchanged, so the result equals
``forced_error``'s bit for bit (``tests/test_arx_nested.py``). A state that
overflows makes the output sum (over every state, as in the dense loop)
non-finite at the same sample, so the pass is marked not finite as there; what
follows is not used.
"""

from __future__ import annotations

import numba
import numpy as np

from subid.methods.dt._scoring import output_error

__all__ = ["sparse_forced_error"]


@numba.njit(cache=True, nogil=True)
def _compressed(M, by_columns):  # pragma: no cover - compiled
    """``(start, index, value)`` of the nonzero entries of ``M`` by rows (by columns
    with ``by_columns``), the indices of each row (column) ascending."""
    rows, cols = M.shape
    outer, inner = (cols, rows) if by_columns else (rows, cols)
    start = np.zeros(outer + 1, dtype=np.int64)
    for a in range(outer):
        count = 0
        for b in range(inner):
            v = M[b, a] if by_columns else M[a, b]
            if v != 0.0:
                count += 1
        start[a + 1] = start[a] + count
    index = np.empty(start[outer], dtype=np.int64)
    value = np.empty(start[outer])
    k = 0
    for a in range(outer):
        for b in range(inner):
            v = M[b, a] if by_columns else M[a, b]
            if v != 0.0:
                index[k] = b
                value[k] = v
                k += 1
    return start, index, value


@numba.njit(cache=True, nogil=True)
def sparse_forced_error(A, B, C, D, u, y, weights, inv_scale, n_free):  # pragma: no cover
    """:func:`subid.methods.dt._scoring.forced_error` over the nonzero entries of
    ``A`` (module docstring): the weighted rows ``[C A^t w,
    (y(t) - y_f(t)) w]`` of the x0 regression for ``t < n_free``, and ``sum_{t >=
    n_free} ((y - y_f) inv_scale)^2`` per output. Returns ``(rows, tail, finite)``,
    ``finite`` false when the forced response overflowed."""
    N, nu = u.shape
    n = A.shape[0]
    ny = C.shape[0]
    a_start, a_index, a_value = _compressed(A, False)
    rows = np.empty((n_free, ny, n + 1))
    tail = np.zeros(ny)
    finite = True
    x = np.zeros(n)
    xn = np.empty(n)
    for t in range(N):             # the outputs as the dense loop: an infinite state
        if not output_error(C, D, x, u, y, t, weights, inv_scale, n_free, rows, tail):
            finite = False         # makes their sum NaN there
        for i in range(n):
            s = 0.0
            for k in range(a_start[i], a_start[i + 1]):
                s += a_value[k] * x[a_index[k]]
            for j in range(nu):
                s += B[i, j] * u[t, j]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]
    if n_free == 0:
        return rows, tail, finite
    col_start, col_index, col_value = _compressed(A, True)
    M = C.copy()
    Mn = np.empty_like(M)
    for t in range(n_free):
        for i in range(ny):
            for j in range(n):
                rows[t, i, j] = M[i, j] * weights[i]
        for i in range(ny):
            for j in range(n):
                s = 0.0
                for k in range(col_start[j], col_start[j + 1]):
                    s += M[i, col_index[k]] * col_value[k]
                Mn[i, j] = s
        M, Mn = Mn, M
    return rows, tail, finite
