"""The steps of frequency-domain subspace identification that the refinement needs too.

:func:`subspace`, the projected and noise-weighted SVD of McKelvey, Akçay & Ljung
(1996, Algorithm 2; see :mod:`subid.methods.fd.fd_subspace`), :func:`system_pair`
(A, C by shift invariance), :func:`finish` (back to continuous time, B and D by
least squares), :func:`noise_variance` (the noise level of the weighting,
estimated from iteratively reweighted preliminary fits when the data do not
give it; its inverse, :func:`inverse_level`, weights the fit) and
:func:`variance_model` (the noise variance ``a + b |G|^2`` fitted to a
model's residuals, the weighting of :func:`subid.pem` on frequency data). Stability
handling and order selection live in :mod:`subid.methods.fd.fd_subspace`; this
module imports nothing from the discrete-time methods, so that
:mod:`subid.methods.fd.fd_pem` (reached from :func:`subid.pem`) can use it.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.linalg
import scipy.optimize

from subid.errors import DataError, OrderError, SubidError
from subid.frdata import FRData
from subid.methods.fd import _frequency as fq

__all__ = ["Problem", "default_horizon", "subspace", "system_pair", "finish",
           "noise_variance", "NOISE_FITS", "variance_model", "MIN_NOISE_FREQUENCIES",
           "inverse_level"]


def default_horizon(largest_order: int, n_outputs: int) -> int:
    """Block rows q of order ``largest_order``: twice what it needs (``(q - 1) p >= n``) plus one."""
    return max(2, 2 * math.ceil(largest_order / n_outputs) + 1)


class Problem:
    """The data of one fit in the domain of the subspace step (DT points ``z``)."""

    def __init__(self, data: FRData, alpha, noise_var=None):
        self.data = data
        self.alpha = alpha
        self.z = fq.points(data.w, data.dt) if alpha is None \
            else fq.bilinear_points(data.w, alpha)
        self.s = fq.points(data.w, data.dt)          # where the final model is evaluated
        self.G = data.response
        if noise_var is None:
            noise_var = data.std ** 2 if data.std is not None \
                else 1.0 / data.fit_weights() ** 2
        self.noise_var = noise_var                   # (M, p, m) variance of the response
        # the data's weights, else the inverse noise level (given or estimated): the
        # columns of Y and the B, D regression weighted as the noise demands
        self.weights = data.fit_weights() if data.weights is not None \
            else inverse_level(noise_var)


def check_std(data: FRData, name: str) -> None:
    """Refuse a ``std`` with zeros where it sets the weights (no ``weights`` given): a
    weight ``1 / std`` would be infinite. Floored, three zeros among 100 frequencies got
    10^12 times the others' weight and drove the fit (a relative error of 0.37 against
    4.5e-4 after pem), and an all-zero ``std`` ended in a raw LAPACK error."""
    if data.weights is not None or data.std is None:
        return
    zero = ~(data.std > 0).all(axis=(1, 2))
    if zero.any():
        raise DataError(f"{name}: the data's std is zero at {int(zero.sum())} of "
                        f"{zero.size} frequencies (first w = {data.w[zero][0]:.6g}), where a "
                        "weight 1/std would be infinite; drop those frequencies, give "
                        "weights= instead of std, or floor the std (a zero std from spa "
                        "marks a frequency its lag window does not resolve)")


def inverse_level(noise_var) -> np.ndarray:
    """Weights ``1 / sqrt(v)``, scaled to unit root mean square (a zero variance is
    floored at 1e-24 of the largest, a standard deviation of 1e-12 of the largest)."""
    v = np.maximum(noise_var, 1e-24 * max(float(np.max(noise_var)), 1e-300))
    w = 1.0 / np.sqrt(v)
    return w / math.sqrt(float(np.mean(w ** 2)))


def subspace(problem: Problem, q: int):
    """Orthonormal basis of the observability range (all q p columns) and singular values."""
    G, z, W = problem.G, problem.z, problem.weights
    M, p, m = G.shape
    out_scale = np.sqrt(np.mean(np.abs(G) ** 2, axis=(0, 2)))
    out_scale[out_scale == 0] = 1.0
    in_scale = np.sqrt(np.mean(np.abs(G) ** 2, axis=(0, 1)))
    in_scale[in_scale == 0] = 1.0
    Gs = G / out_scale[None, :, None] / in_scale[None, None, :]
    col = np.sqrt(np.mean(W ** 2, axis=(1, 2)))                 # per-frequency weight
    powers = z[None, :] ** np.arange(q)[:, None]                 # (q, M)
    # Y[r p + i, k m + j] = z_k^r G_k[i, j];  U[r m + i, k m + j] = z_k^r delta_ij
    scaled = powers[:, :, None, None] * col[None, :, None, None]     # (q, M, 1, 1)
    Y = (scaled * Gs[None]).transpose(0, 2, 1, 3).reshape(q * p, M * m)
    U = (scaled * np.eye(m)).transpose(0, 2, 1, 3).reshape(q * m, M * m)
    stacked = np.vstack([np.hstack([U.real, U.imag]), np.hstack([Y.real, Y.imag])])
    if stacked.shape[1] < stacked.shape[0]:
        raise DataError(f"fd_subspace: {M} frequencies give {2 * M * m} real columns but "
                        f"horizon {q} needs at least {q * (p + m)}; give more frequencies "
                        "or a smaller horizon")
    R = scipy.linalg.qr(stacked.T, mode="r", check_finite=False)[0]
    L22 = R[q * m:q * (m + p), q * m:q * (m + p)].T               # projected Y
    noise = _noise_factor(problem, powers, col, out_scale, in_scale)
    Us, sv, _ = scipy.linalg.svd(scipy.linalg.solve_triangular(noise, L22, lower=True),
                                 check_finite=False, lapack_driver="gesvd")
    return noise @ Us, sv, out_scale, in_scale


def _noise_factor(problem, powers, col, out_scale, in_scale):
    """Cholesky factor of the noise covariance of the rows of Y (the weighted algorithm).

    Noise uncorrelated between channels and frequencies, of variance
    ``problem.noise_var`` (:func:`noise_variance`): block ``(r, i), (r', i)`` is
    ``Re sum_k col_k^2 z_k^(r - r') sum_j var_kij`` in the scaled units.
    """
    q = powers.shape[0]
    p = out_scale.size
    var = problem.noise_var / out_scale[None, :, None] ** 2 / in_scale[None, None, :] ** 2
    v = var.sum(axis=2) * col[:, None] ** 2                           # (M, p)
    # T[r, r', i] = Re sum_k v_ki z_k^r conj(z_k^r')
    T = np.einsum("rk,sk,ki->rsi", powers, powers.conj(), v).real
    K = np.zeros((q, p, q, p))
    for i in range(p):
        K[:, i, :, i] = T[:, :, i]
    K = K.reshape(q * p, q * p)
    K += 1e-12 * np.trace(K) / K.shape[0] * np.eye(K.shape[0])
    return np.linalg.cholesky(K)


def system_pair(problem: "Problem", basis, n: int):
    """``(A_d, C_d, condition)``: A and C of order n in the discrete domain of the fit
    (shift invariance of the leading n columns of the basis), C in the data's units."""
    Us, _, out_scale, _ = basis
    p = problem.G.shape[1]
    O = Us[:, :n]
    A_d, _, _, sv = scipy.linalg.lstsq(O[:-p], O[p:], lapack_driver="gelsd",
                                       check_finite=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    return A_d, O[:p] * out_scale[:, None], cond


def finish(problem: Problem, A_d, C_d, feedthrough: bool):
    """A, C in the data's domain, B and D by least squares; ``(A, B, C, D, error, cond)``."""
    if problem.alpha is not None:
        try:
            A, C = fq.bilinear_to_ct(A_d, C_d, problem.alpha)
        except (np.linalg.LinAlgError, ValueError):
            raise OrderError("fd_subspace: the discrete-domain model has a pole at z = -1 "
                             "(infinitely fast in continuous time); try a lower order") from None
    else:
        A, C = A_d, C_d
    with np.errstate(all="ignore"):
        B, D, cond = fq.estimate_b_d(A, C, problem.s, problem.G, problem.weights,
                                     feedthrough=feedthrough)
        err = fq.weighted_error(problem.G, fq.response(A, B, C, D, problem.s), problem.weights)
    if not (np.isfinite(A).all() and np.isfinite(B).all() and np.isfinite(C).all()
            and math.isfinite(err)):
        raise OrderError("fd_subspace: the model is not finite (a pole on a measured "
                         "frequency?); try another order")
    return A, B, C, D, err, cond


#: Preliminary fits of :func:`noise_variance`: the first with equal weights, each
#: further one weighted by the noise level that the previous one's residuals gave.
NOISE_FITS = 3
#: Fewest frequencies from which :func:`variance_model` is fitted (two parameters per
#: channel pair).
MIN_NOISE_FREQUENCIES = 20
#: Iterations of the reweighted least squares of :func:`variance_model`.
VARIANCE_ITERATIONS = 50


def variance_model(G, G_hat):
    """The noise variance ``a_ij + b_ij |G_hat_ij(w)|^2`` fitted to the residuals of a
    consistent model, ``(var (M, p, m), (a, b))``.

    Noise model: the measured ``G_k = G0_k + V_k`` with ``V_k`` circular complex
    Gaussian, independent over frequencies, of variance ``v_k = a + b |G0_k|^2``
    per channel pair: a floor ``a`` (additive output noise of a flat-spectrum
    test: equal variance at every frequency) plus a part proportional to the
    response (``b``: the noise of a spectral estimate, ``var G = |G|^2 (1 -
    γ²) / (2 n γ²)`` at constant coherence ``γ²``, Ljung 1999, eq. 6.59;
    a relative calibration error). Then ``|r_k|^2 = |G_k - G_hat_k|^2`` is
    ``v_k`` times a unit exponential variable, and maximum likelihood over ``a,
    b >= 0`` (``min Σ ln v_k + |r_k|^2 / v_k``) is the gamma regression with
    identity link: iteratively reweighted non-negative least squares of
    ``|r_k|^2`` on ``[1, |G_hat_k|^2]`` with weights ``1 / v_k``
    (McCullagh & Nelder, *Generalized Linear Models*, 1989, Sec. 2.5 and 8.3).
    The maximum-likelihood weighting of the response fit is ``1 / sqrt(v)``
    (Pintelon & Schoukens 2012, Ch. 9). One term alone (``b = 0`` or ``a = 0``, each
    with its closed-form maximum-likelihood value) replaces the pair when the pair
    does not fit significantly better (:func:`_simplest`).
    """
    r = np.abs(G - G_hat) ** 2
    x = np.abs(G_hat) ** 2
    M, p, m = r.shape
    var = np.empty_like(r)
    coef = np.zeros((p, m, 2))
    for i in range(p):
        for j in range(m):
            ri, xi = r[:, i, j], x[:, i, j]
            floor = max(float(ri.mean()), 1e-300)
            ab = np.array([floor, 0.0])
            X = np.column_stack([np.ones(M), xi])
            for _ in range(VARIANCE_ITERATIONS):
                v = np.maximum(X @ ab, 1e-12 * floor)
                new = scipy.optimize.nnls(X / v[:, None], ri / v)[0]
                if not np.any(new > 0):
                    new = np.array([floor, 0.0])
                done = np.allclose(new, ab, rtol=1e-6, atol=0)
                ab = new
                if done:
                    break
            coef[i, j] = _simplest(ri, X, ab, floor)
            var[:, i, j] = np.maximum(X @ coef[i, j], 1e-12 * floor)
    return var, coef


#: Likelihood-ratio threshold of :func:`variance_model`'s choice between the floor
#: alone, the proportional part alone and both: chi-squared with one degree of
#: freedom at the 0.1 % level.
DEVIANCE_THRESHOLD = 10.83


def _simplest(r, X, ab, floor):
    """``(a, b)``: the fitted two-term variance, or one term alone (``b = 0``: equal
    variance; ``a = 0``: proportional to the response) when the deviance
    ``2 Σ (ln v + r / v)`` of the one-term fit exceeds the two-term one's by less
    than :data:`DEVIANCE_THRESHOLD` (the likelihood-ratio test of the nested models).

    Measured: the second term of a two-term fit is estimated from noise when the
    noise has one kind only; fitted to the residuals of preliminary fits of the
    seed-000 response under 5 % noise of equal variance, ``b`` came out up to
    1.6 times the 0.05**2 of a 5 % relative noise on the channel whose ``|G|`` spans
    least, at a deviance gain of at most 3.7 over 10 runs; under 5 % relative noise
    ``a`` gained at most 10.7 over 5 runs; a real term gained 27 to 3400.
    """
    def deviance(coef):
        v = np.maximum(X @ coef, 1e-12 * floor)
        return 2.0 * float(np.sum(np.log(v) + r / v))

    full = deviance(ab)
    x = X[:, 1]
    candidates = [np.array([floor, 0.0])]
    if np.all(x > 0):
        candidates.append(np.array([0.0, float(np.mean(r / x))]))
    scored = [(deviance(c), k, c) for k, c in enumerate(candidates)]
    best, _, coef = min(scored, key=lambda t: (t[0], t[1]))
    return coef if best - full < DEVIANCE_THRESHOLD else ab


def noise_variance(data: FRData, alpha, order: int, feedthrough: bool = True):
    """The variance of the response's noise, ``(var (M, p, m), record)``.

    Given by the data (``std``, or ``weights`` read as inverse standard
    deviations), or, when the data give neither, estimated by iteratively
    reweighted preliminary fits: a fit of order ``order`` (at the default
    horizon) with equal weights, the variance ``a + b |G|^2`` per channel pair
    fitted by maximum likelihood to its residuals (:func:`variance_model`),
    then :data:`NOISE_FITS` - 1 more fits, each weighted by the inverse noise
    level of the previous one (an unweighted fit under noise proportional to
    ``|G|`` leaves model error where ``|G|`` is small, which the first variance
    model reads as a noise floor ``a``).

    Measured (``bench/frequency_acceptance.py``, seed-000 response, 5 % noise
    proportional to ``|G|``, 20 runs, order 4): with the former estimate (the
    squared residuals of one unweighted preliminary fit averaged over 15
    neighbouring frequencies, used in the SVD's noise covariance only) 15 of 20
    models had a spurious slow pole (between -0.05 and -1e-8 rad/s, below the
    true -0.16, the true pair -1.24, -1.68 merged into one) and :func:`subid.pem`
    from them stayed there in 13; with this estimate weighting the columns and
    the B, D regression too, none did.
    """
    if data.std is not None:
        return data.std ** 2, {"source": "std of the data"}
    if data.weights is not None:
        return 1.0 / data.fit_weights() ** 2, {"source": "1 / weights**2"}
    M, p, m = data.response.shape
    q = default_horizon(order, p)
    while q > 2 and 2 * M * m < q * (p + m):
        q -= 1
    order = min(order, (q - 1) * p)
    var = np.ones(data.response.shape)
    if M < MIN_NOISE_FREQUENCIES or order < 1:
        return var, {"source": "constant (too few frequencies to estimate it)"}
    record = None
    for fit in range(NOISE_FITS):
        try:
            problem = Problem(data, alpha, var)
            basis = subspace(problem, q)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                A_d, C_d, _ = system_pair(problem, basis, order)
                A, B, C, D = finish(problem, A_d, C_d, feedthrough)[:4]
        except SubidError:
            if record is None:
                return var, {"source": "constant (the preliminary fit failed)"}
            break                      # keep the variance of the previous fit
        G_hat = fq.response(A, B, C, D, problem.s)
        if record is None and math.sqrt(np.mean(np.abs(data.response - G_hat) ** 2)) \
                <= 1e-9 * math.sqrt(np.mean(np.abs(data.response) ** 2)):
            return var, {"source": "constant (the data fit to rounding: no noise to see)"}
        var, coef = variance_model(data.response, G_hat)
        record = {"source": f"estimated: variance a + b |G|^2 per channel pair fitted by "
                            f"maximum likelihood to the residuals of {fit + 1} iteratively "
                            f"reweighted order-{order} preliminary fits",
                  "a": coef[..., 0], "b": coef[..., 1]}
    return var, record
