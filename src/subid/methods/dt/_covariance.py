"""Asymptotic covariance of prediction-error estimates (used by :func:`subid.pem`).

For the prediction-error estimate with Gaussian innovations of covariance
``Λ``, the parameter covariance is asymptotically

    Cov(θ̂) = [Σ_t ψ_t Λ^-1 ψ_t^T]^-1,     ψ_t = dŷ[t|θ]/dθ  (n_θ x ny)

(Ljung, *System Identification*, 2nd ed., 1999, Ch. 9, Theorem 9.1; in the
scalar case ``λ [Σ ψ ψ^T]^-1``, for several outputs the maximum-likelihood
form weighted by ``Λ^-1``). With the Jacobian ``J`` whose rows
are the whitened sensitivities ``L^-1 ψ_t^T`` (``Λ = L L^T``), this is
``(J^T J)^-1``; it is computed from the triangular factor ``R`` of ``J``
(never an explicit inverse): ``J = Q R`` gives ``Cov = R^-1 R^-T``. ``R`` is
the Cholesky factor of the column-scaled Gram matrix ``J^T J`` (one BLAS-3
product) when that factor is well conditioned (every diagonal entry above
:data:`subid.methods.dt._trust_region.GRAM_PIVOT`, so the normal equations
lose at most about 8 of the 16 digits, as in the optimiser), else the
Householder QR factor of ``J``; the two agree up to the signs of the rows of
``R``, which ``R^-1 R^-T`` does not see.

Nuisance parameters (the initial states) are eliminated exactly: with their
columns first, the trailing block ``R22`` of ``R`` is the factor of the
Schur complement, so ``R22^-1 R22^-T`` is the marginal covariance of the
model parameters.

With ``sandwich`` (output-error fits, whose residuals need not be white) the factor
is that of the sandwich ``R^-1 Q R^-1`` instead (:mod:`subid.methods.dt._sandwich`;
Ljung 1999, Sec. 9.3, eqs. 9.40-9.42): ``R22^-1 S`` with ``S S^T = Q2^T T Q2``,
``Q2`` the trailing columns of ``J R^-1`` (the Jacobian with the nuisance columns
projected out, in the classic factor's orthonormal coordinates) and ``T`` the
Bartlett-windowed autocovariance of the whitened residuals (``S = I`` for white
residuals: the classic factor).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid.methods.dt import _sandwich

__all__ = ["covariance_factor", "covariance_factor_pieces", "RANK_TOLERANCE"]

# A diagonal entry of the (column-scaled) R factor below this times the largest
# one marks a direction the data do not determine: no covariance is returned.
RANK_TOLERANCE = 1e-9


def _triangular_factor(Js, order):
    """``R`` of ``Js[:, order] = Q R`` (columns of unit norm): the Cholesky factor of the
    Gram matrix (of ``Js``, its rows and columns then permuted: no permuted copy of
    ``Js``) when its pivots are above GRAM_PIVOT, else Householder QR."""
    from subid.methods.dt._trust_region import gram_factor
    R = gram_factor((Js.T @ Js)[np.ix_(order, order)])
    return np.linalg.qr(Js[:, order], mode="r") if R is None else R


def covariance_factor(J, residuals, n_nuisance, order=None, *, sandwich=None, segments=None):
    """Square-root factor of the covariance of the non-nuisance parameters.

    Parameters
    ----------
    J : ndarray, shape (N, ny, d), C-contiguous
        Sensitivities ``dŷ[t]/dθ`` (not weighted); the first ``n_nuisance``
        columns are nuisance parameters (eliminated). Overwritten: whitened and
        its columns scaled in place (the Jacobian of a long record is the largest
        array of :func:`subid.pem`; copies of it set the peak memory).
    residuals : ndarray, shape (N, ny)
        Prediction errors at the estimate.
    n_nuisance : int
        Number of leading nuisance columns (of ``J[..., order]``).
    order : array of int, optional
        The columns of ``J`` in the order the factor takes them (the nuisance ones
        first); None: as they are.
    sandwich : dict, optional
        None: the classic covariance (white residuals). A dict: the sandwich covariance
        of an output-error fit under coloured disturbances (:mod:`._sandwich`); a key
        ``'lag'`` fixes the Bartlett window's ``M`` (0: the residual autocovariance
        taken white, the classic covariance), else it is chosen from the residuals;
        ``'lag'`` is written back with the ``M`` used.
    segments : list of (int, int), optional
        The ``(start, stop)`` samples of the independent segments of the record (the
        experiments or windows whose Jacobians are stacked); None: one. The sandwich
        does not correlate residuals across their boundaries.

    Returns
    -------
    factor : ndarray, shape (d - n_nuisance, d - n_nuisance) or None
        ``F`` with ``Cov = F F^T``; None when the Jacobian is rank deficient
        (a non-minimal model or unexciting data).
    noise_cov : ndarray, shape (ny, ny)
        The residual covariance ``Λ`` used, ``E^T E / (N - d / ny)``.
    """
    N, ny, d = J.shape
    lam, L = _noise_cov(residuals, d)
    if L is None:
        return None, lam
    Jw = _whiten(J, L)
    scale = np.sqrt(np.einsum("ij,ij->j", Jw, Jw))
    if not (np.isfinite(scale).all() and scale.min() > 0):
        return None, lam
    Jw /= scale
    order = np.arange(d) if order is None else np.asarray(order)
    R = _triangular_factor(Jw, order)
    if sandwich is None:
        return _marginal(R, scale[order], n_nuisance), lam

    def rows():
        for s in range(0, N, _SANDWICH_ROWS):
            yield Jw[s * ny:min(s + _SANDWICH_ROWS, N) * ny][:, order]
    return _sandwich_marginal(R, scale[order], n_nuisance, rows, residuals, L, segments,
                              sandwich), lam


def covariance_factor_pieces(pieces, residuals, n_nuisance, d, *, sandwich=None,
                             segments=None):
    """:func:`covariance_factor` of a Jacobian given a piece at a time (columns in the
    factor's order, the nuisance ones first): ``pieces()`` yields ``J[start:stop]``
    (shape (stop - start, ny, d), C-contiguous, overwritten) in order and is called a
    second time where the Gram route does not apply (the Householder factor of the
    pieces, each folded into the factor of those before it). ``residuals``: the
    prediction errors of every sample, shape (N, ny). The same factor to rounding,
    with one piece of the Jacobian in memory at a time (a long record). ``sandwich``,
    ``segments``: as for :func:`covariance_factor`; the meat ``J^T T J`` of every column
    is formed in the Gram matrix's pass (each piece filtered with the last ``M`` rows of
    the one before), the nuisance columns projected out after it (on the Householder
    route, where the Gram matrix is ill-conditioned, from the pieces once more)."""
    from subid.methods.dt._trust_region import gram_factor
    lam, L = _noise_cov(residuals, d)
    if L is None:
        return None, lam
    ny = residuals.shape[1]
    # the sandwich's meat of every column (J^T T J) in the Gram matrix's pass: on the
    # Gram route its nuisance-projected block is R^-T (J^T T J) R^-1's trailing block
    full = None if sandwich is None else \
        _sandwich.LaggedMeat(*_sandwich_kernel(residuals, L, d, segments, sandwich), d)
    G = np.zeros((d, d))
    for Jk in pieces():
        Jw = _whiten(Jk, L)
        G += Jw.T @ Jw
        if full is not None:
            full.add(Jw.reshape(-1, ny, d))
    scale = np.sqrt(np.maximum(np.diag(G), 0.0))
    if not (np.isfinite(G).all() and scale.min() > 0):
        return None, lam
    R = gram_factor(G / scale[:, None] / scale[None, :])
    if R is not None and full is not None:
        base = _marginal(R, scale, n_nuisance)
        if base is None:
            return None, lam
        X = scipy.linalg.solve_triangular(R, full.value() / scale[:, None] / scale[None, :],
                                          trans="T", check_finite=False)
        meat = scipy.linalg.solve_triangular(R, X.T, trans="T", check_finite=False).T
        return base @ _sandwich.psd_sqrt(meat[n_nuisance:, n_nuisance:]), lam
    if R is None:
        R = np.zeros((0, d))
        for Jk in pieces():
            Jw = _whiten(Jk, L) / scale
            R = np.linalg.qr(np.vstack([R, Jw]), mode="r")
    if sandwich is None:
        return _marginal(R, scale, n_nuisance), lam
    return _sandwich_marginal(R, scale, n_nuisance,
                              lambda: (_whiten(Jk, L) / scale for Jk in pieces()),
                              residuals, L, segments, sandwich), lam


def _noise_cov(residuals, d):
    """``(Λ, its Cholesky factor or None)``: the residual covariance
    ``E^T E / (N - d / ny)``."""
    N, ny = residuals.shape
    lam = residuals.T @ residuals / max(N - d / ny, 1.0)
    try:
        return lam, np.linalg.cholesky(lam)
    except np.linalg.LinAlgError:
        return lam, None


def _whiten(J, L):
    """``L^-1 ψ_t`` for every t, in place (forward substitution over the outputs, each
    step one operation on the (N, d) rows of an output: no copy of J); returns the
    rows ``J.reshape(N ny, d)`` (a view)."""
    N, ny, d = J.shape
    for i in range(ny):
        for j in range(i):
            J[:, i, :] -= L[i, j] * J[:, j, :]
        J[:, i, :] /= L[i, i]
    return J.reshape(N * ny, d)


def _marginal(R, scale, n_nuisance):
    """The factor of the non-nuisance parameters' covariance from ``R`` (of the
    column-scaled, whitened Jacobian, nuisance columns first; ``scale`` its column
    scales): ``R22^-1`` unscaled, or None when ``R22`` is rank deficient."""
    R22 = R[n_nuisance:, n_nuisance:]
    diag = np.abs(np.diag(R22))
    if diag.size == 0 or diag.min() <= RANK_TOLERANCE * diag.max():
        return None
    inv = scipy.linalg.solve_triangular(R22, np.eye(R22.shape[0]), check_finite=False)
    return inv / scale[n_nuisance:, None]


#: Samples of the whole Jacobian :func:`covariance_factor` takes at a time for the
#: sandwich's meat (a copy of that many rows in the factor's column order).
_SANDWICH_ROWS = 65536


def _sandwich_marginal(R, scale, n_nuisance, rows, residuals, L, segments, record):
    """The sandwich factor ``R22^-1 S / scale`` (module docstring), or None as
    :func:`_marginal`. ``rows()``: the whitened, column-scaled Jacobian (columns in the
    factor's order) a block of whole samples at a time, in order; ``L``: the Cholesky
    factor of ``Λ``; ``record``: the sandwich dict of :func:`covariance_factor`."""
    base = _marginal(R, scale, n_nuisance)
    if base is None:
        return None
    ny = residuals.shape[1]
    d = R.shape[1]
    width = d - n_nuisance
    meat = _sandwich.LaggedMeat(*_sandwich_kernel(residuals, L, d, segments, record), width)
    for block in rows():
        Z = scipy.linalg.solve_triangular(R, block.T, trans="T", check_finite=False)
        meat.add(np.ascontiguousarray(Z[n_nuisance:].T).reshape(-1, ny, width))
    return base @ _sandwich.psd_sqrt(meat.value())


def _sandwich_kernel(residuals, L, d, segments, record):
    """``(k, segments)``: the Bartlett-windowed autocovariance ``k(τ) = w(τ) r(τ)`` of the
    whitened residuals ``L^-1 e`` (``r(0) = I``: the divisor that of ``Λ``), ``τ = 0..M``
    with ``M = record['lag']`` if given, else chosen from them (written to ``record``),
    and the segments (default: one)."""
    N, ny = residuals.shape
    segments = [(0, N)] if segments is None else list(segments)
    Ew = scipy.linalg.solve_triangular(L, residuals.T, lower=True, check_finite=False).T
    fixed = record.get("lag")
    top = min(_sandwich.MAX_LAG, max(1, N // 10)) if fixed is None else int(fixed)
    r = _sandwich.autocovariance(Ew, segments, top, max(N - d / ny, 1.0))
    lag = _sandwich.choose_lag(r, N) if fixed is None else int(fixed)
    record["lag"] = lag
    return _sandwich.bartlett(lag)[:, None, None] * r[:lag + 1], segments
