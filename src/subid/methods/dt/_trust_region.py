"""Trust-region least squares on a compressed Jacobian (the optimiser of :func:`subid.pem`).

:func:`scipy.optimize.least_squares` (``method='trf'``, exact trust-region
solver, no bounds) takes a dense SVD of the whole ``m x p`` Jacobian at every
iteration; for a prediction-error fit ``m = N * ny`` is tens of thousands of
rows and that SVD dominated :func:`subid.pem`. The trust-region subproblem
depends on the Jacobian only through ``J^T J`` and ``J^T f``: with ``J = Q R``
(``R`` upper triangular, ``p x p``) the singular values and right singular
vectors of ``J`` are those of ``R``, and ``U^T f = U_R^T (Q^T f)``. So
:func:`trust_region_least_squares` runs the same iteration as scipy's
``trf_no_bounds`` (the same radius updates, Levenberg-Marquardt parameter,
``x_scale='jac'`` scaling and termination tests; Moré 1977) on ``R`` and
``Q^T f``. ``R`` comes from the Cholesky factor of the Gram matrix ``J^T J``
(one BLAS-3 product, about 10x cheaper than the SVD) when the column-scaled
Jacobian is well conditioned (every diagonal entry of the scaled factor above
``GRAM_PIVOT``, so the normal equations lose at most about 8 of the 16
digits in the weakest direction), else from a Householder QR of ``J``
(LAPACK ``geqrf``, no ``Q`` formed). A Jacobian too large to hold whole is given a
block of rows at a time (:func:`compress_pieces`: the Gram matrix summed over the
blocks, or each block folded into the Householder factor of those before it), the
same factor to rounding. The pieces of the iteration are written
here from Moré (1977): the step with its Levenberg-Marquardt parameter
(:func:`trust_region_step`), the radius update (:func:`update_radius`) and
scipy's termination tests (:func:`termination`); with ``exact=True`` (the SVD
of the whole Jacobian) the iterates equal scipy's to 1e-12
(``tests/test_pem_trust_region.py``), and on the compressed Jacobian to rounding.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.optimize import OptimizeResult

from subid.statistic.hankel import geqrf_r

__all__ = ["trust_region_least_squares"]

#: Smallest diagonal entry of the Cholesky factor of the column-scaled Gram matrix
#: for which the Gram route is taken (else Householder QR of the Jacobian).
GRAM_PIVOT = 1e-4

MESSAGES = {
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
    5: "the Gauss-Newton decrement is below `decrement_tol` (statistical precision).",
    6: "the evaluations left would decrease the criterion by less than `stall_tol` "
       "(statistical precision) at the rate of the last steps.",
}


#: Relative accuracy of ||p|| = Delta at which the Levenberg-Marquardt parameter search
#: stops, and its iteration bound (Moré 1977, Sec. 5; Nocedal and Wright 2006, Alg. 4.3).
ALPHA_RTOL, ALPHA_ITERATIONS = 0.01, 10


def _step_norm(alpha, suf, s, Delta):
    """``phi(alpha) = ||p(alpha)|| - Delta`` and its derivative for the step
    ``p(alpha) = -V diag(s / (s^2 + alpha)) U^T f`` (``suf = s * U^T f``)."""
    denom = s ** 2 + alpha
    p_norm = float(np.linalg.norm(suf / denom))
    phi = p_norm - Delta
    phi_prime = -float(np.sum(suf ** 2 / denom ** 3)) / p_norm
    return phi, phi_prime


def trust_region_step(n, m, uf, s, V, Delta, initial_alpha=None):
    """The solution of ``min ||J p + f||`` subject to ``||p|| <= Delta`` from the SVD
    ``J = U diag(s) V^T`` (``uf = U^T f``): the Gauss-Newton step when it lies inside
    the region, else the Levenberg-Marquardt step ``(J^T J + alpha I) p = -J^T f`` whose
    norm is Delta to :data:`ALPHA_RTOL`, with alpha found by the safeguarded Newton
    iteration on ``phi(alpha) = ||p(alpha)|| - Delta`` of Moré (1977, "The
    Levenberg-Marquardt algorithm: implementation and theory", Sec. 5), the step then
    scaled onto the boundary. Returns ``(p, alpha, iterations)``."""
    suf = s * uf
    full_rank = m >= n and s[-1] > np.finfo(float).eps * m * s[0]
    if full_rank:
        p = -V @ (uf / s)
        if np.linalg.norm(p) <= Delta:
            return p, 0.0, 0
    alpha_upper = float(np.linalg.norm(suf)) / Delta
    if full_rank:
        phi, phi_prime = _step_norm(0.0, suf, s, Delta)
        alpha_lower = -phi / phi_prime
    else:
        alpha_lower = 0.0
    if initial_alpha is None or (not full_rank and initial_alpha == 0):
        alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
    else:
        alpha = initial_alpha
    iterations = 0
    while iterations < ALPHA_ITERATIONS:
        iterations += 1
        if alpha < alpha_lower or alpha > alpha_upper:
            alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
        phi, phi_prime = _step_norm(alpha, suf, s, Delta)
        if phi < 0:
            alpha_upper = alpha
        ratio = phi / phi_prime
        alpha_lower = max(alpha_lower, alpha - ratio)
        alpha -= (phi + Delta) * ratio / Delta
        if abs(phi) < ALPHA_RTOL * Delta:
            break
    p = -V @ (suf / (s ** 2 + alpha))
    p *= Delta / np.linalg.norm(p)           # onto the boundary
    return p, alpha, iterations


def update_radius(Delta, actual_reduction, predicted_reduction, step_norm, bound_hit):
    """The next trust radius and the reduction ratio (Moré 1977, Sec. 4: shrink to a
    quarter of the step below a ratio of 1/4, double when the step reached the
    boundary above 3/4)."""
    if predicted_reduction > 0:
        ratio = actual_reduction / predicted_reduction
    elif predicted_reduction == actual_reduction == 0:
        ratio = 1.0
    else:
        ratio = 0.0
    if ratio < 0.25:
        Delta = 0.25 * step_norm
    elif ratio > 0.75 and bound_hit:
        Delta *= 2.0
    return Delta, ratio


def termination(dF, F, dx_norm, x_norm, ratio, ftol, xtol):
    """scipy's status codes of the ``ftol`` and ``xtol`` tests (None: go on)."""
    ftol_met = dF < ftol * F and ratio > 0.25
    xtol_met = dx_norm < xtol * (xtol + x_norm)
    if ftol_met and xtol_met:
        return 4
    if ftol_met:
        return 2
    if xtol_met:
        return 3
    return None


def gram_factor(Gs):
    """``R`` (upper triangular, ``Gs = R^T R``) of the Gram matrix ``Gs`` of a Jacobian
    whose columns have unit norm, by Cholesky, when every pivot is above
    :data:`GRAM_PIVOT` (the normal equations then lose at most about 8 digits); else
    None (the caller takes the Householder QR of the Jacobian). The route decision of
    the optimiser and of the covariance steps
    (:mod:`subid.methods.dt._covariance`)."""
    try:
        L = np.linalg.cholesky(Gs)
    except np.linalg.LinAlgError:
        return None
    if np.isfinite(L).all() and np.diag(L).min(initial=1.0) > GRAM_PIVOT:
        return L.T
    return None


def _from_gram(G, g):
    """``(R, Q^T f, J^T f, norms, 'gram')`` from ``G = J^T J`` and ``g = J^T f`` when the
    Cholesky factor of the column-scaled ``G`` has every pivot above
    :data:`GRAM_PIVOT` (:func:`gram_factor`); else ``(None, None, g, norms, None)`` (the
    QR route)."""
    norms = np.sqrt(np.maximum(np.diag(G), 0.0))
    safe = np.where(norms > 0, norms, 1.0)
    if np.all(norms > 0) and np.isfinite(G).all():
        Rs = gram_factor(G / safe[:, None] / safe[None, :])
        if Rs is not None:
            R = Rs * safe[None, :]                  # J = Q R, R = L^T diag(norms)
            qtf = scipy.linalg.solve_triangular(R, g, trans="T", check_finite=False)
            return R, qtf, g, norms, "gram"
    return None, None, g, norms, None


def compress(J, f):
    """``(R, Q^T f, J^T f, column norms of J, route)`` for ``J = Q R``."""
    out = _from_gram(J.T @ J, J.T @ f)
    if out[0] is not None:
        return out
    p = J.shape[1]
    Jf = np.empty((J.shape[0], p + 1), order="F")       # LAPACK's order: no second copy
    Jf[:, :p] = J
    Jf[:, p] = f
    # the triangle alone (scipy's qr(mode='r') returns all m rows of R, zeros below it)
    Ra = geqrf_r(Jf, p + 1, overwrite=True)
    return Ra[:p, :p], Ra[:p, p], out[2], out[3], "qr"


def compress_pieces(pieces, f, p, *, householder=False):
    """:func:`compress` of a Jacobian given a block of rows at a time: ``pieces()``
    yields ``(start, stop, J[start:stop])`` (rows of ``J``, ``p`` columns) in order. The
    Gram matrix and ``J^T f`` are summed over the pieces (the same route decision); the
    QR route folds each piece into the triangular factor of the pieces before it
    (``[R; J_k] = Q R'``, the Householder factor of the whole ``[J f]`` up to the signs
    of its rows). Only a piece of ``J`` is held at a time: the memory of
    :func:`subid.pem` on a long record.

    ``pieces()`` is called a second time on the QR route, unless ``householder`` is
    true: the pieces are then folded into the Householder factor in the first pass too
    (the caller expects the QR route, e.g. because the last Jacobian took it), so that
    the Jacobian is not formed twice; the Gram route, when it applies, is still taken.
    The same factor either way."""
    G, g = np.zeros((p, p)), np.zeros(p)
    Ra = np.zeros((0, p + 1))

    def fold(Ra, a, b, Jk):
        stacked = np.empty((Ra.shape[0] + b - a, p + 1), order="F")
        stacked[:Ra.shape[0]] = Ra
        stacked[Ra.shape[0]:, :p] = Jk
        stacked[Ra.shape[0]:, p] = f[a:b]
        # only the triangle goes on (scipy's qr(mode='r') returns every row of R, the
        # zeros below the triangle too: each piece stacked under all of them cost time
        # quadratic in the pieces, 38 % of bj at 10^5 samples)
        return geqrf_r(stacked, min(stacked.shape[0], p + 1), overwrite=True)

    for a, b, Jk in pieces():
        G += Jk.T @ Jk
        g += Jk.T @ f[a:b]
        if householder:
            Ra = fold(Ra, a, b, Jk)
    out = _from_gram(G, g)
    if out[0] is not None:
        return out
    if not householder:
        for a, b, Jk in pieces():
            Ra = fold(Ra, a, b, Jk)
    if Ra.shape[0] <= p:                 # fewer rows than columns: R is trapezoidal
        Ra = np.vstack([Ra, np.zeros((p + 1 - Ra.shape[0], p + 1))])
    return Ra[:p, :p], Ra[:p, p], out[2], out[3], "qr"


#: Accepted steps over which :func:`trust_region_least_squares` measures its rate of
#: progress for ``stall_tol``.
STALL_STEPS = 5


def trust_region_least_squares(fun, jac, x0, *, ftol, xtol, gtol, max_nfev, exact=False,
                               decrement_tol=0.0, stall_tol=0.0, compressed=None):
    """Minimise ``0.5 ||fun(x)||^2`` as :func:`scipy.optimize.least_squares` with
    ``method='trf'``, ``tr_solver='exact'``, ``x_scale='jac'`` and no bounds
    does, on the compressed Jacobian (module docstring).

    Parameters
    ----------
    fun : callable
        Residual vector (length ``m``) at ``x``.
    jac : callable
        Its Jacobian ``(m, p)`` at ``x``.
    x0 : ndarray
        Starting point (length ``p``).
    ftol, xtol, gtol : float
        scipy's termination tolerances.
    max_nfev : int
        Bound on the evaluations of ``fun``.
    exact : bool
        Take the SVD of the whole Jacobian as scipy does (for the tests).
    decrement_tol : float
        Stop (status 5) at an iterate whose Gauss-Newton decrement
        ``0.5 ||U^T f||^2`` (the decrease of ``0.5 ||f||^2`` the full Gauss-Newton
        step predicts, ``J = U diag(s) V^T``) is below this; 0 (default): scipy's
        tests alone. :func:`subid.identify` sets it from the statistical
        precision of the criterion (:func:`subid.methods.dt._pe_search.statistical_precision`).
    stall_tol : float
        Stop (status 6) after an accepted step when the decrease of ``0.5 ||f||^2`` per
        evaluation over the last :data:`STALL_STEPS` accepted steps, times the
        evaluations left (``max_nfev - nfev``), is below this: what the rest of the
        budget would still buy at the current rate (a search crawling along a flat
        valley, e.g. the near-cancelling noise polynomials of an over-parametrised
        Box-Jenkins model). 0 (default): never.
    compressed : callable, optional
        ``compressed(x, f) -> (R, Q^T f, J^T f, column norms of J, route)``, what
        :func:`compress` gives for the Jacobian at ``x`` and the residual ``f`` there,
        computed without ``J`` whole (:func:`compress_pieces`); ``jac`` is then not
        called.

    Returns
    -------
    OptimizeResult
        ``x``, ``cost``, ``fun``, ``nfev``, ``njev``, ``status``, ``message``,
        ``success`` and ``routes`` (the compression taken at every Jacobian).
    """
    x = np.array(x0, dtype=float)
    f = np.asarray(fun(x), dtype=float)
    nfev, njev = 1, 1
    m, n = f.size, x.size
    cost = 0.5 * float(f @ f)
    routes = []

    def factor(x, f):
        if compressed is not None:
            out = compressed(x, f)
        else:
            J = np.asarray(jac(x), dtype=float)
            if exact:
                g = J.T @ f
                norms = np.sqrt(np.sum(J ** 2, axis=0))
                return J, f, g, norms, "svd"
            out = compress(J, f)
        routes.append(out[4])
        return out

    # the compressed factor is all the iteration needs (exact: R is J itself): no second
    # Jacobian alive while the next one is computed (the largest arrays of subid.pem)
    R, qtf, g, norms, _ = factor(x, f)
    scale_inv = norms.copy()
    scale_inv[scale_inv == 0] = 1.0
    scale = 1.0 / scale_inv
    Delta = float(np.linalg.norm(x * scale_inv)) or 1.0
    alpha = 0.0
    status = None
    progress = []                        # (reduction, evaluations) of the accepted steps
    while True:
        g_norm = float(np.linalg.norm(g, ord=np.inf))
        if g_norm < gtol:
            status = 1
        if status is not None or nfev == max_nfev:
            break
        d = scale
        g_h = d * g
        R_h = R * d
        U, s, VT = scipy.linalg.svd(R_h, full_matrices=False, check_finite=False)
        V = VT.T
        uf = U.T @ qtf
        if 0.5 * float(uf @ uf) < decrement_tol:
            status = 5
            break
        actual_reduction = -1.0
        while actual_reduction <= 0 and nfev < max_nfev:
            step_h, alpha, _ = trust_region_step(n, m, uf, s, V, Delta, initial_alpha=alpha)
            Js = R_h @ step_h
            predicted_reduction = -(0.5 * float(Js @ Js) + float(g_h @ step_h))
            step = d * step_h
            x_new = x + step
            f_new = np.asarray(fun(x_new), dtype=float)
            nfev += 1
            step_h_norm = float(np.linalg.norm(step_h))
            if not np.all(np.isfinite(f_new)):
                Delta = 0.25 * step_h_norm
                continue
            cost_new = 0.5 * float(f_new @ f_new)
            actual_reduction = cost - cost_new
            Delta_new, ratio = update_radius(Delta, actual_reduction, predicted_reduction,
                                                step_h_norm, step_h_norm > 0.95 * Delta)
            status = termination(actual_reduction, cost, float(np.linalg.norm(step)),
                                       float(np.linalg.norm(x)), ratio, ftol, xtol)
            if status is not None:
                break
            alpha *= Delta / Delta_new
            Delta = Delta_new
        if actual_reduction > 0:
            x, f, cost = x_new, f_new, cost_new
            progress.append((actual_reduction, nfev))
            if status is None and stall_tol > 0 and len(progress) > STALL_STEPS:
                recent = progress[-STALL_STEPS:]
                rate = sum(r for r, _ in recent) / (nfev - progress[-STALL_STEPS - 1][1])
                if rate * (max_nfev - nfev) < stall_tol:
                    status = 6
            njev += 1
            R, qtf, g, norms, _ = factor(x, f)
            scale_inv = np.maximum(norms, scale_inv)
            scale = 1.0 / scale_inv
    if status is None:
        status = 0
    return OptimizeResult(x=x, cost=cost, fun=f, nfev=nfev, njev=njev, status=status,
                          message=MESSAGES[status], success=status > 0, routes=routes)
