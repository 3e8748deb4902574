"""Parameter covariance of the polynomial models (:func:`subid.arx`, :func:`subid.armax`,
:func:`subid.oe`, :func:`subid.bj`).

The polynomial methods fit each output ``i`` on its own: its coefficients
``c_i`` (:func:`subid.model.polynomial.coefficient_slots`) minimise the sum of
squares of its prediction errors ``e_i = y_i - ŷ_i(c_i)``. Linearised at the
estimate (exact for ARX, whose predictor is linear in the coefficients),

    ĉ_i - c_i ≈ (J_i^T J_i)^-1 J_i^T e_i,       J_i = dŷ_i/dc_i  (N x d_i),

so that ``Cov(ĉ_i, ĉ_k) = Λ_ik (J_i^T J_i)^-1 J_i^T J_k (J_k^T J_k)^-1`` for
innovations ``e`` of covariance ``Λ`` (white in time). For one output this is
Ljung's ``λ (Σ ψ ψ^T)^-1`` (*System Identification*, 2nd ed., 1999, Theorem
9.1 and eq. 9.17; for ARX, whose ``ψ`` is the regressor ``φ``, the
least-squares covariance ``σ² (Φ^T Φ)^-1`` of eq. 9.20 / Sec. II.2); with
several outputs the outputs' estimates are correlated through ``Λ`` (the
covariance of equation-by-equation least squares, a "sandwich" since it is
not the multivariable maximum-likelihood estimate).

Computation (no explicit inverse of a data matrix): QR of the column-scaled
``J_i = Q_i R_i``; nuisance columns (the predictor's initial states) first,
so that the trailing block ``R22_i`` of ``R_i`` and the trailing columns
``Q2_i`` of ``Q_i`` carry the coefficients with the initial states
eliminated: ``ĉ_i - c_i ≈ R22_i^-1 Q2_i^T e_i``. With ``Λ = L L^T`` and
``e_i = Σ_k L_ik w_k`` (``w`` white, unit variance), the stacked errors are
``blockdiag(R22_i^-1) M^T w`` with ``M`` the (N ny) x (Σ d_i) matrix of blocks
``L_ik Q2_i``; QR of ``M`` gives ``M^T M = R_M^T R_M`` and the factor
``F_c = blockdiag(R22_i^-1) R_M^T`` with ``Cov(ĉ) = F_c F_c^T`` (for one
output, ``σ R22^-1``). ``Λ_ik = e_i^T e_k / sqrt((N - d_i)(N - d_k))``, the
residual covariance with each output's degrees of freedom. ``R_M`` is taken as a
square root of ``M^T M``, whose blocks ``Λ_ik Q2_i^T Q2_k`` need no ``M``; and where
the column-scaled ``J_i^T J_i`` has every Cholesky pivot above
:data:`subid.methods.dt._trust_region.GRAM_PIVOT` (the optimiser's rule), ``R_i`` is its
Cholesky factor and ``Q2_i^T Q2_k`` the trailing block of ``R_i^-T J_i^T J_k R_k^-1``
(``Q_i = J_i R_i^-1``): no thin ``Q`` (``N x d_i`` numbers an output) is formed.

For :func:`subid.oe` (output error: the noise model is 1, the disturbance need not be
white) :func:`sandwich_coefficient_factor` replaces ``Λ_ik Q2_i^T Q2_k`` by ``Q2_i^T
T_ik Q2_k``, ``T_ik(t, s) = w(t - s) r_ik(t - s)`` the Bartlett-windowed
cross-covariance of the residuals of outputs ``i`` and ``k``: the sandwich covariance
``R^-1 Q R^-1`` of Ljung (1999, Sec. 9.3, eqs. 9.40-9.42) with the window of Newey and
West (1987) (:mod:`subid.methods.dt._sandwich`), the classic one for white residuals.

The coefficient covariance is mapped to the state-space parameters θ =
``vec(A, B, C[, D], K)`` of the model's realisation
(:func:`subid.model.polynomial.realise`), which :func:`subid.freqresp_bounds`,
:func:`subid.step_bounds` and :func:`subid.simulation_bounds` read: ``F_θ = T
F_c`` with ``T = dθ/dc``, exact (:func:`subid.model.polynomial.realisation_jacobian`).
The chain rule makes the delta-method bounds identical to those propagated
through ``G(e^{jw}) = B / (A F)`` with the coefficient covariance.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid.methods.dt import _sandwich
from subid.methods.dt._covariance import RANK_TOLERANCE
from subid.methods.dt._trust_region import gram_factor
from subid.model.polynomial import coefficient_slots, coefficients, realisation_jacobian

__all__ = ["coefficient_factor", "coefficient_factor_from_grams", "sandwich_coefficient_factor",
           "attach_covariance"]


def _psd_sqrt(lam: np.ndarray) -> np.ndarray:
    """``L`` with ``L L^T = lam`` for a positive semi-definite ``lam`` (Cholesky when it
    is definite; a symmetric square root when it is singular, e.g. noise-free data)."""
    try:
        return np.linalg.cholesky(lam)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(0.5 * (lam + lam.T))
        return vecs * np.sqrt(np.maximum(vals, 0.0))


def coefficient_factor(designs, residuals, n_nuisance):
    """Square-root factor of the covariance of every output's coefficients.

    Parameters
    ----------
    designs : list of ndarray, each (N, n_nuisance[i] + d_i)
        ``J_i = dŷ_i/d(x0_i, c_i)``, nuisance columns first (for ARX the
        regressors), on the rows of ``residuals``; the same array object for
        several outputs is factored once.
    residuals : ndarray, shape (N, ny)
        The prediction errors of the outputs at the estimate.
    n_nuisance : list of int
        Leading nuisance columns of each design.

    Returns
    -------
    factor : ndarray, shape (sum d_i, sum d_i) or None
        ``F_c`` with ``Cov(c) = F_c F_c^T`` (coefficients output by output);
        None when a design is rank deficient (a non-minimal structure or
        data that do not excite it) or not finite.
    noise_cov : ndarray, shape (ny, ny)
        The residual covariance ``Λ`` used.
    """
    N, ny = residuals.shape
    lam = _noise_covariance(residuals, [J.shape[1] for J in designs])
    q_parts, parts, grams = [], [], []
    done = {}       # a design shared by several outputs (ARX: the same regressors) once
    # one design for every output (ARX): Q2_i^T Q2_j = I for every pair, so only R is
    # formed (the thin Q of a long record's regressors is the largest array here)
    shared = len({(id(J), n1) for J, n1 in zip(designs, n_nuisance)}) == 1
    for J, n1 in zip(designs, n_nuisance):
        if (id(J), n1) in done:
            q, part, gram = done[(id(J), n1)]
            q_parts.append(q)
            parts.append(part)
            grams.append(gram)
            continue
        scale = np.sqrt(np.einsum("ij,ij->j", J, J))
        if J.shape[1] == n1:
            q_parts.append(np.zeros((N, 0)))
            parts.append(_NO_COEFFICIENTS)
            grams.append(None)
            continue
        if not (np.isfinite(scale).all() and scale.min() > 0):
            return None, lam
        Js = J / scale
        # R from the Cholesky factor of the Gram matrix where it is well conditioned
        # (gram_factor: the optimiser's rule); Q is then never formed, Q2_i^T Q2_j comes
        # from J_i^T J_j (below). Else the Householder QR with its thin Q.
        R, Q = gram_factor(Js.T @ Js), None
        if R is None:
            if shared:
                R = np.linalg.qr(Js, mode="r")
            else:
                Q, R = np.linalg.qr(Js)
        part = _part(R, n1, scale)
        if part is None:
            return None, lam
        q_parts.append(None if Q is None else Q[:, n1:])
        parts.append(part)
        grams.append((Js, R, n1))
        done[(id(J), n1)] = (q_parts[-1], parts[-1], grams[-1])

    def cross(i, j):
        """``Q2_i^T Q2_j``: from the thin Q factors, or, where Q was not formed
        (``J_i = Q_i R_i``), the trailing block of ``R_i^-T J_i^T J_j R_j^-1``."""
        if shared or i == j:
            return np.eye(parts[i][0].shape[0])
        if q_parts[i] is not None and q_parts[j] is not None:
            return q_parts[i].T @ q_parts[j]
        if grams[i] is None or grams[j] is None:        # an output without coefficients
            return np.zeros((parts[i][0].shape[0], parts[j][0].shape[0]))
        (Ji, Ri, ni), (Jj, Rj, nj) = grams[i], grams[j]
        return _cross(Ri, Ji.T @ Jj, Rj, ni, nj)
    return _assemble(lam, parts, cross), lam



def _scaled_gram_factor(G):
    """``(R, scale)``: the Cholesky factor (:func:`gram_factor`, None when its pivots are
    too small) of the Gram matrix ``G`` with its columns scaled to unit norm, and the
    scales; None when ``G`` is not finite or has a zero column."""
    scale = np.sqrt(np.maximum(np.diag(G), 0.0))
    if not (np.isfinite(G).all() and scale.min() > 0):
        return None
    return gram_factor(G / scale[:, None] / scale[None, :]), scale

def coefficient_factor_from_grams(grams, widths, residuals, n_nuisance):
    """:func:`coefficient_factor` from the designs' Gram blocks ``grams[(i, j)] = J_i^T
    J_j`` (``i <= j``; every pair of outputs with coefficients), summed by the caller
    over pieces of the record, so that no design is held whole: the Gram route of
    :func:`coefficient_factor` (the same factor to rounding). ``widths``: the columns of
    each design. Returns ``(None, Λ)`` where a design's column-scaled Gram matrix fails
    :func:`subid.methods.dt._trust_region.gram_factor` or is rank deficient: the caller
    then forms the designs whole for :func:`coefficient_factor` (its QR route)."""
    lam = _noise_covariance(residuals, widths)
    parts, factors = [], []
    for i, (width, n1) in enumerate(zip(widths, n_nuisance)):
        if width == n1:
            parts.append(_NO_COEFFICIENTS)
            factors.append(None)
            continue
        scaled = _scaled_gram_factor(grams[(i, i)])
        if scaled is None:
            return None, lam
        R, scale = scaled
        part = None if R is None else _part(R, n1, scale)
        if part is None:
            return None, lam
        parts.append(part)
        factors.append((R, scale, n1))

    def cross(i, j):
        if i == j:
            return np.eye(parts[i][0].shape[0])
        if factors[i] is None or factors[j] is None:
            return np.zeros((parts[i][0].shape[0], parts[j][0].shape[0]))
        (Ri, si, ni), (Rj, sj, nj) = factors[i], factors[j]
        Gij = grams[(i, j)] if i < j else grams[(j, i)].T
        return _cross(Ri, Gij / si[:, None] / sj[None, :], Rj, ni, nj)
    return _assemble(lam, parts, cross), lam


#: The part (inverse of R22, scales) of an output without coefficients.
_NO_COEFFICIENTS = (np.zeros((0, 0)), np.zeros(0))


def _noise_covariance(residuals, widths):
    """``Λ_ik = e_i^T e_k / sqrt((N - d_i)(N - d_k))``, each output's degrees of freedom
    those of its design's ``widths`` columns."""
    N = residuals.shape[0]
    dofs = np.array([max(N - w, 1) for w in widths], dtype=float)
    return residuals.T @ residuals / np.sqrt(np.outer(dofs, dofs))


def _part(R, n1, scale):
    """``(R22^-1, the coefficients' column scales)`` of an output whose scaled design has
    the triangular factor ``R`` (nuisance columns first), or None when R is rank
    deficient."""
    diag = np.abs(np.diag(R))
    if diag.min() <= RANK_TOLERANCE * diag.max():
        return None
    R22 = R[n1:, n1:]
    return (scipy.linalg.solve_triangular(R22, np.eye(R22.shape[0]), check_finite=False),
            scale[n1:])


def _cross(Ri, Gij, Rj, ni, nj):
    """The trailing block of ``R_i^-T G_ij R_j^-1`` (``Q2_i^T Q2_j`` for ``J_i = Q_i R_i``
    with ``G_ij = J_i^T J_j``)."""
    C = scipy.linalg.solve_triangular(Ri, Gij, trans="T", check_finite=False)
    return scipy.linalg.solve_triangular(Rj, C.T, trans="T", check_finite=False).T[ni:, nj:]


def _assemble(lam, parts, cross):
    """The factor from each output's ``(R22^-1, scales)`` and ``cross(i, j) = Q2_i^T Q2_j``.

    M: row block k (noise component w_k), column block i: L_ik Q2_i (L L^T = Λ), and R_M
    its triangular factor. Its Gram matrix G = R_M^T R_M has the blocks Λ_ij Q2_i^T Q2_j,
    Q2_i^T Q2_i = I: conditioned as Λ, so a square root of G (its Cholesky factor; where Λ
    is singular, by eigenvalues) serves as R_M^T (the factor F F^T sees only R_M^T R_M)
    without M, 2 ny^2 N d numbers (10^6 samples of two outputs: 0.86 GB of the covariance
    step)."""
    ny = len(parts)
    G = np.block([[lam[i, j] * cross(i, j) for j in range(ny)] for i in range(ny)])
    return _factor_of_meat(G, parts)


def _factor_of_meat(G, parts):
    """``blockdiag(R22_i^-1) R_M^T`` unscaled, ``R_M^T R_M = G`` (the meat in the
    outputs' orthonormal coordinates ``Q2_i``)."""
    R_M = _psd_sqrt(0.5 * (G + G.T)).T
    factor = scipy.linalg.block_diag(*[p[0] for p in parts]) @ R_M.T
    return factor / np.concatenate([p[1] for p in parts])[:, None]


def sandwich_coefficient_factor(pieces, grams, widths, residuals, n_nuisance, segments,
                                record):
    """:func:`coefficient_factor_from_grams` for output-error fits under coloured
    disturbances: the sandwich ``R^-1 Q R^-1`` (module docstring;
    :mod:`subid.methods.dt._sandwich`).

    Parameters
    ----------
    pieces : callable
        ``pieces()`` yields, in order over the record, a list of every output's design
        rows ``J_i[a:b]`` (nuisance columns first; the same rows for every output).
        Read once for the meat (twice where a Gram matrix fails
        :func:`subid.methods.dt._trust_region.gram_factor`: its Householder factor).
    grams, widths, residuals, n_nuisance
        As for :func:`coefficient_factor_from_grams` (only the diagonal Gram blocks
        are read).
    segments : list of (int, int)
        The experiments' ``(start, stop)`` samples (no correlation across them).
    record : dict
        ``'lag'``: the Bartlett window's ``M`` if given (0: the residuals taken white,
        :func:`coefficient_factor`'s factor), else chosen from the residuals
        (:func:`subid.methods.dt._sandwich.choose_lag`); written back with the ``M``
        used.

    Returns
    -------
    factor : ndarray or None
        ``F_c`` with ``Cov(c) = F_c F_c^T``; None as :func:`coefficient_factor`.
    noise_cov : ndarray, shape (ny, ny)
        ``Λ``, as there.
    """
    lam = _noise_covariance(residuals, widths)
    N, ny = residuals.shape
    factors = []
    for i, (width, n1) in enumerate(zip(widths, n_nuisance)):
        if width == n1:
            factors.append(None)
            continue
        scaled = _scaled_gram_factor(grams[(i, i)])
        if scaled is None:
            return None, lam
        factors.append([*scaled, n1])
    if any(f is not None and f[0] is None for f in factors):      # the Householder route
        folded = [np.zeros((0, w)) for w in widths]
        for blocks in pieces():
            for i, f in enumerate(factors):
                if f is not None and f[0] is None:
                    folded[i] = np.linalg.qr(np.vstack([folded[i], blocks[i] / f[1]]),
                                             mode="r")
        for i, f in enumerate(factors):
            if f is not None and f[0] is None:
                f[0] = folded[i]
    parts = []
    for f in factors:
        part = _NO_COEFFICIENTS if f is None else _part(f[0], f[2], f[1])
        if part is None:
            return None, lam
        parts.append(part)
    dofs = np.array([max(N - w, 1) for w in widths], dtype=float)
    fixed = record.get("lag")
    top = min(_sandwich.MAX_LAG, max(1, N // 10)) if fixed is None else int(fixed)
    r = _sandwich.autocovariance(residuals, segments, top, np.sqrt(np.outer(dofs, dofs)))
    lag = _sandwich.choose_lag(r, N) if fixed is None else int(fixed)
    sizes = [p[0].shape[0] for p in parts]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    meat = _sandwich.LaggedMeat(_sandwich.bartlett(lag)[:, None, None] * r[:lag + 1],
                                segments, int(offsets[-1]))
    for blocks in pieces():
        Z = np.zeros((blocks[0].shape[0], ny, int(offsets[-1])))
        for i, f in enumerate(factors):
            if f is None:
                continue
            R, scale, n1 = f
            Zi = scipy.linalg.solve_triangular(R, (blocks[i] / scale).T, trans="T",
                                               check_finite=False)
            Z[:, i, offsets[i]:offsets[i + 1]] = Zi[n1:].T
        meat.add(Z)
    record["lag"] = lag
    return _factor_of_meat(meat.value(), parts), lam


def attach_covariance(model, designs, residuals, n_nuisance, method: str, *, factor=None):
    """Write ``info['parameter_covariance']`` of the polynomial ``model`` (in place).

    The format of :func:`subid.parameter_covariance` (θ of the realisation,
    its factor, ``with_feedthrough``, ``with_gain``, ``noise_cov``,
    ``n_samples``, ``method``) plus the coefficients' own: ``coefficients``,
    ``coefficient_factor`` and ``coefficient_names``
    (:func:`subid.model.polynomial.coefficient_slots`). A rank-deficient
    design gives ``info['parameter_covariance_note']`` instead. ``factor``: the
    ``(F_c, Λ)`` of :func:`coefficient_factor_from_grams`, when the caller has it (then
    ``designs`` and ``n_nuisance`` are not read).
    """
    poly = model.info["polynomials"]
    info = model.info
    factor_c, lam = coefficient_factor(designs, residuals, n_nuisance) if factor is None \
        else factor
    if factor_c is None:
        info["parameter_covariance_note"] = (
            "no parameter covariance: the prediction-error Jacobian (for ARX the "
            "regressors) at the estimate is rank deficient or not finite (a non-minimal "
            "structure or data that do not excite it)")
        return model
    T = realisation_jacobian(poly)
    n, nu, ny = model.order, model.n_inputs, model.n_outputs
    sizes = [n * n, n * nu, ny * n, ny * nu, n * ny]
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    moves = [bool(np.any(T[bounds[k]:bounds[k + 1]])) for k in range(5)]
    keep = [True, True, True, moves[3], moves[4]]
    rows = np.concatenate([np.arange(bounds[k], bounds[k + 1]) for k in range(5) if keep[k]])
    mats = [model.A, model.B, model.C, model.D,
            model.K if model.K is not None else np.zeros((n, ny))]
    theta = np.concatenate([np.asarray(m, float).ravel() for m, k in zip(mats, keep) if k])
    info["parameter_covariance"] = {
        "parameters": theta,
        "factor": T[rows] @ factor_c,
        "with_feedthrough": moves[3],
        "with_gain": moves[4],
        "noise_cov": lam,
        "n_samples": int(residuals.shape[0]),
        "coefficients": coefficients(poly),
        "coefficient_factor": factor_c,
        "coefficient_names": [name for _, _, name in coefficient_slots(poly)],
        "method": method,
    }
    info.pop("parameter_covariance_note", None)
    return model
