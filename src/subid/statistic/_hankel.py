"""Block-Hankel data statistics shared by the subspace methods.

Every subspace method here works on the triangular factor of the block-Hankel
data matrix

    H = [U_{0|s-1}; Y_{0|s-1}]  (s(nu+ny) rows, K = N - s + 1 columns),

where block row ``i`` of ``U_{0|s-1}`` is ``[u(i), u(i+1), ..., u(i+K-1)]``.
With ``H^T = Q R`` (thin QR, ``Q`` with orthonormal columns), ``H = L Q^T``
with ``L = R^T`` lower triangular; every projection of the subspace
algorithms acts on the row space of ``H`` only through ``L``, because
``Q^T`` has orthonormal rows. The factor is accumulated in chunks of columns,
so an N-column Hankel matrix is never built.

A method that needs the rows in another order (say ``[U_f; U_p; Y_p; Y_f]``)
re-triangularises ``L`` with the rows permuted: if ``H = L Q^T`` then
``P H = (P L) Q^T`` and an LQ factorisation of the small matrix ``P L``
gives the factor of ``P H`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg


@dataclass(frozen=True)
class HankelFactor:
    """Triangular factor of a block-Hankel data matrix.

    Attributes
    ----------
    L : ndarray, shape (s*(nu+ny), s*(nu+ny))
        Lower-triangular factor, scaled by ``1/sqrt(K)`` so that
        ``L L^T = H H^T / K`` (a sample correlation matrix).
    depth : int
        Number of block rows ``s`` of each signal.
    n_inputs, n_outputs : int
    n_columns : int
        ``K = N - s + 1``.
    """

    L: np.ndarray
    depth: int
    n_inputs: int
    n_outputs: int
    n_columns: int
    #: What is computed from this factor alone, by key (:meth:`derived`); not an
    #: argument: a factor made by ``dataclasses.replace`` starts empty.
    _derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def derived(self, key, compute):
        """``compute()``, once per factor and ``key``: for what depends on the factor
        only (the oblique projections of the noise model, which the models of every
        order on one factor share). The result must be treated as read-only."""
        if key not in self._derived:
            self._derived[key] = compute()
        return self._derived[key]

    def u_rows(self, first: int, stop: int) -> np.ndarray:
        """Row indices of input block rows ``first .. stop-1``."""
        nu = self.n_inputs
        return np.arange(first * nu, stop * nu)

    def y_rows(self, first: int, stop: int) -> np.ndarray:
        """Row indices of output block rows ``first .. stop-1``."""
        nu, ny, s = self.n_inputs, self.n_outputs, self.depth
        return s * nu + np.arange(first * ny, stop * ny)

    def rows(self, *blocks) -> np.ndarray:
        """Rows of ``L`` for the concatenation of the given index arrays."""
        return self.L[np.concatenate(blocks)]

    def retriangularize(self, *blocks) -> np.ndarray:
        """Lower-triangular factor of the Hankel rows ``blocks`` in that order.

        Returns ``L'`` with ``P H = L' Q'^T`` for the row selection ``P``.
        """
        return lq_lower(self.rows(*blocks))


def lq_lower(M: np.ndarray, *, overwrite: bool = False) -> np.ndarray:
    """Lower-triangular ``L`` of the LQ factorisation ``M = L Q^T``.

    ``M`` is (r, m); ``L`` is (r, r) when ``r <= m``. The sign of each
    diagonal entry is made non-negative so the factor is unique. With
    ``overwrite``, a row-major ``M`` is factorised in place (:func:`geqrf_r`;
    its contents are lost), bit for bit the same factor.
    """
    L = geqrf_r(M.T, M.shape[0], overwrite=overwrite).T
    if L.shape[1] < M.shape[0]:
        L = np.hstack([L, np.zeros((M.shape[0], M.shape[0] - L.shape[1]))])
    signs = np.sign(np.diag(L)[: min(L.shape)])
    signs[signs == 0] = 1.0
    L[:, : signs.size] *= signs
    return L


def geqrf_r(work: np.ndarray, rows: int, *, overwrite: bool) -> np.ndarray:
    """The first ``rows`` rows of ``scipy.linalg.qr(work, mode='r', check_finite=False)[0]``,
    bit for bit: the same LAPACK ``geqrf`` call (its optimal workspace, queried first)
    without the wrapper's checks, copies and the ``triu`` of the whole result (called for
    every fold, horizon and order set and every block of the QR statistic: the wrapper was
    about 40 % of the time). With ``overwrite``, a column-major ``work`` is factorised in
    place (its contents are lost)."""
    if work.size == 0:
        return scipy.linalg.qr(work, mode="r", check_finite=False)[0][:rows]
    geqrf, = scipy.linalg.get_lapack_funcs(("geqrf",), (work,))
    # the query reads only the shape: overwrite_a spares the copy of ``work``
    lwork = int(geqrf(work, lwork=-1, overwrite_a=1)[-2][0].real)
    qr, _, _, info = geqrf(work, lwork=lwork, overwrite_a=int(overwrite))
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of the internal LAPACK geqrf")
    return np.triu(qr[:rows])


def hankel_chunk(u: np.ndarray, y: np.ndarray, depth: int, start: int, stop: int) -> np.ndarray:
    """Columns ``start .. stop-1`` of ``H^T`` (rows = time, as a dense block)."""
    nu, ny = u.shape[1], y.shape[1]
    k = stop - start
    out = np.empty((k, depth * (nu + ny)))
    for i in range(depth):
        out[:, i * nu:(i + 1) * nu] = u[start + i:stop + i]
        out[:, depth * nu + i * ny: depth * nu + (i + 1) * ny] = y[start + i:stop + i]
    return out
