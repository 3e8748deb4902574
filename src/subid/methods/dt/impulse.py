"""Regularised impulse-response (FIR) estimation: :func:`impulseest`.

The output is modelled as a finite impulse response of ``n`` lags,

    y_i[t] = sum_j sum_{k=0}^{n-1} g_ij[k] u_j[t-k] + e_i[t],

one output at a time. With ``kernel=None`` the coefficients are the least-
squares estimate. Otherwise they get the Gaussian prior ``g ~ N(0, P(η))``
(independent across inputs) and the estimate is the posterior mean
(Chen, Ohlsson and Ljung, "On the estimation of transfer functions,
regularizations and Gaussian processes - revisited", Automatica 48, 2012,
eqs. (9)-(10); Pillonetto, Dinuzzo, Chen, De Nicolao and Ljung, "Kernel
methods in system identification, machine learning and function estimation:
a survey", Automatica 50, 2014, Section 5):

    ĝ = P Φ^T (Φ P Φ^T + σ^2 I)^-1 Y,
    Cov(g | Y) = P - P Φ^T (Φ P Φ^T + σ^2 I)^-1 Φ P.

The kernels (lag index ``k = 1..n`` for lags ``0..n-1``; Chen et al. 2012,
eqs. (14)-(16); Pillonetto et al. 2014, eq. (40) for the stable spline):

* ``'tc'`` (tuned/correlated, first-order stable spline): ``c λ^max(k,l)``;
* ``'dc'`` (diagonal/correlated): ``c ρ^|k-l| λ^((k+l)/2)``;
* ``'ss'`` (second-order stable spline):
  ``c (λ^(k+l+max(k,l)) / 2 - λ^(3 max(k,l)) / 6)``.

The hyperparameters ``η`` (``c``, ``λ`` and for DC ``ρ``, one set per input)
maximise the marginal likelihood (empirical Bayes; Chen et al. 2012, eq.
(12)):

    η̂ = argmin  Y^T Σ(η)^-1 Y + log det Σ(η),    Σ = Φ P Φ^T + σ^2 I.

``σ^2`` is fixed beforehand at the residual variance of the least-squares FIR
estimate (Chen et al. 2012, Section 4). Everything is computed from the QR
factor ``R`` of ``[Φ, Y]`` (Chen and Ljung, "Implementation of algorithms for
tuning parameters in regularized least squares problems in system
identification", Automatica 49, 2013): with ``Φ = Q1 R1``, ``Y = Q1 r + ρ q``,
``Y^T Σ^-1 Y = ρ^2/σ^2 + r^T H^-1 r`` and ``log det Σ = (N - m) log σ^2 +
log det H`` where ``H = σ^2 I + R1 P R1^T`` is ``m x m`` (``m = n nu``), so
one evaluation costs ``O(m^3)``, independent of the record length.

The standard deviations allow for coloured disturbances. The posterior covariance
``S = P - P Φ^T Σ^-1 Φ P = σ^2 M``, ``M = (Φ^T Φ + σ^2 P^-1)^-1``, splits into a noise
part and a prior part, ``S = M (σ^2 Φ^T Φ) M + M (σ^4 P^-1) M``; the noise part assumes
white noise (``Cov(Φ^T e) = σ^2 Φ^T Φ``). With the sandwich meat
``Q = Σ_t Σ_s φ(t) k(t - s) φ(s)^T`` in its place (``k(τ) = w(τ) r(τ)``, the residual
autocovariance under a Bartlett lag window, Newey and West 1987; its lag chosen as for
the output-error fits, :mod:`subid.methods.dt._sandwich`; Ljung, *System
Identification*, 2nd ed., 1999, eqs. (9.40)-(9.42)),

    Cov = M Q M + M (σ^4 P^-1) M = S + S (Q / σ^2 - Φ^T Φ) S / σ^2,

which needs no ``P^-1``; for least squares (``S = σ^2 (Φ^T Φ)^-1``) it is the usual
``(Φ^T Φ)^-1 Q (Φ^T Φ)^-1``, and for white residuals ``Q ≈ σ^2 Φ^T Φ`` gives back ``S``.
On a second-order plant with process noise (N = 2000, 60 lags, TC kernel, 100 runs,
``tests/test_nonparametric.py``) the coverage of ``ĝ ± 1.96 std`` was 82.5 % with the
white-noise posterior.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.optimize

from subid._blas import serial_blas
from subid._validation import check_choice, check_int, checked_call
from subid.data import IOData, not_a_record
from subid.errors import DataError, NotExcitingError, PoorFitWarning, TooFewSamplesError
from subid.methods.dt._lag_fit import correlations
from subid.methods.dt.checks import check_channels
from subid.model.statespace import StateSpace

__all__ = ["impulseest", "ImpulseEstimate", "kernel_matrix"]

KERNELS = ("tc", "dc", "ss")
# Rows beyond the number of coefficients needed for the noise-variance estimate.
MIN_EXTRA_ROWS = 10
# Starting decay rates of the marginal-likelihood search (the best one is refined).
DECAY_GRID = (0.3, 0.6, 0.8, 0.9, 0.95, 0.98, 0.995)
# Bounds of the decay rate λ and of |ρ| during the search.
DECAY_BOUNDS = (1e-4, 1.0 - 1e-6)
# Entries of one block of regressor rows factored at a time.
QR_BLOCK_ENTRIES = 4_000_000
# Effective parameters (degrees of freedom of the regularised fit) below which the data
# do not determine the estimate (a warning): on a second-order plant, 30 runs each, the
# median was 9.9-18.7 at 10 dB white noise or process noise (N = 400-2000, 60 lags) and
# 0.78 at -20 dB; the marginal likelihood's collapse to a zero prior gives 0.
MIN_EFFECTIVE_PARAMETERS = 1.0


def kernel_matrix(kernel, n, scale, decay, correlation=0.0):
    """The prior covariance ``P`` of ``n`` impulse-response coefficients.

    Parameters
    ----------
    kernel : {'tc', 'dc', 'ss'}
    n : int
    scale : float
        ``c``.
    decay : float
        ``λ`` in (0, 1).
    correlation : float
        ``ρ`` in (-1, 1) (DC only).

    Returns
    -------
    ndarray, shape (n, n)
    """
    k = np.arange(1, n + 1, dtype=float)
    mx = np.maximum(k[:, None], k[None, :])
    if kernel == "tc":
        return scale * decay ** mx
    if kernel == "dc":
        return scale * correlation ** np.abs(k[:, None] - k[None, :]) \
            * decay ** ((k[:, None] + k[None, :]) / 2)
    return scale * (decay ** (k[:, None] + k[None, :] + mx) / 2 - decay ** (3 * mx) / 6)


@dataclass(frozen=True)
class ImpulseEstimate:
    """An estimated impulse response (the result of :func:`impulseest`).

    Attributes
    ----------
    coefficients : ndarray, shape (n, ny, nu)
        ``g[k, i, j]``: response of output ``i`` at lag ``k`` to a unit pulse
        on input ``j`` at lag 0.
    std : ndarray, shape (n, ny, nu)
        Standard deviation of every coefficient: the posterior one (least squares:
        the sampling one) with the noise's part from the residuals' autocovariance,
        valid for coloured disturbances (module docstring).
    dt : float
        Sampling period.
    kernel : str or None
        The kernel, or None (least squares).
    hyperparameters : list of dict
        Per output: ``scale``, ``decay`` (and ``correlation`` for DC), one
        value per input; empty dicts for least squares.
    noise_variance : ndarray, shape (ny,)
        ``σ^2`` of every output.
    input_names, output_names : tuple of str
    info : dict
        ``n_samples`` (rows used), ``marginal_likelihood`` (per output, the
        minimised ``-2 log p(Y) - N log 2 pi``; None for least squares),
        ``effective_parameters`` (per output, ``tr(Φ P Φ^T Σ^-1)``, the degrees of
        freedom of the regularised fit; the coefficient count for least squares:
        below :data:`MIN_EFFECTIVE_PARAMETERS` the estimate is the prior's, with a
        :class:`~subid.errors.PoorFitWarning`), ``std`` (``method``, and
        ``lag_window``: the Bartlett window's lag per output).
    """

    coefficients: np.ndarray
    std: np.ndarray
    dt: float
    kernel: str | None
    hyperparameters: list
    noise_variance: np.ndarray
    input_names: tuple
    output_names: tuple
    info: dict = field(default_factory=dict)

    def model(self) -> StateSpace:
        """The FIR model as a state space (one shift register of ``n - 1``
        states per input).

        Returns
        -------
        StateSpace
            Discrete time; its Markov parameters are :attr:`coefficients`.
        """
        g = self.coefficients
        n, ny, nu = g.shape
        r = n - 1
        A = np.zeros((r * nu, r * nu))
        B = np.zeros((r * nu, nu))
        C = np.zeros((ny, r * nu))
        for j in range(nu):
            s = j * r
            A[s + 1:s + r, s:s + r - 1] = np.eye(r - 1)
            B[s, j] = 1.0
            C[:, s:s + r] = g[1:, :, j].T
        info = {"method": "impulseest", "order": r * nu, "kernel": self.kernel,
                "n_coefficients": n, "hyperparameters": self.hyperparameters}
        return StateSpace(A, B, C, g[0], self.dt, input_names=self.input_names,
                          output_names=self.output_names, info=info)


def _regressors(data, n, start=0, stop=None):
    """``(Φ, Y)`` over every experiment: the rows whose ``n`` lags are all measured
    (rows ``start:stop`` of that stack, counted over the experiments in order)."""
    phis, ys = [], []
    nu = data.n_inputs
    offset = 0
    stop = math.inf if stop is None else stop
    for a, b in data.experiment_ranges:
        rows = max(b - a - n + 1, 0)
        lo, hi = max(start - offset, 0), min(stop - offset, rows)
        offset += rows
        if hi <= lo:
            continue
        u = data.u[a + lo:a + hi + n - 1]
        win = np.lib.stride_tricks.sliding_window_view(u, n, axis=0)   # (rows, nu, n)
        phis.append(win[:, :, ::-1].reshape(-1, nu * n))               # lag 0 first
        ys.append(data.y[a + lo + n - 1:a + hi + n - 1])
    if not phis:
        return np.empty((0, nu * n)), np.empty((0, data.n_outputs))
    return np.vstack(phis), np.vstack(ys)


def _factor(data, n):
    """Row count and the triangular factor ``R`` of ``[Φ, Y]``, by QR over blocks of
    rows (``[R; next block]`` refactored), so that ``Φ`` is never held whole."""
    m = n * data.n_inputs
    total = sum(max(b - a - n + 1, 0) for a, b in data.experiment_ranges)
    block = max(QR_BLOCK_ENTRIES // (m + data.n_outputs), 4 * (m + data.n_outputs))
    R = np.empty((0, m + data.n_outputs))
    for start in range(0, total, block):
        Phi, Y = _regressors(data, n, start, start + block)
        R = np.linalg.qr(np.vstack([R, np.hstack([Phi, Y])]), mode="r")
    return total, R


def _unpack(kernel, eta, nu):
    """Hyperparameters (per input) from the unconstrained search vector."""
    per = 3 if kernel == "dc" else 2
    e = eta.reshape(nu, per)
    scale = np.exp(e[:, 0])
    decay = DECAY_BOUNDS[0] + (DECAY_BOUNDS[1] - DECAY_BOUNDS[0]) / (1 + np.exp(-e[:, 1]))
    corr = 0.999 * np.tanh(e[:, 2]) if kernel == "dc" else np.zeros(nu)
    return scale, decay, corr


def _prior(kernel, n, scale, decay, corr):
    nu = scale.size
    P = np.zeros((n * nu, n * nu))
    for j in range(nu):
        P[j * n:(j + 1) * n, j * n:(j + 1) * n] = kernel_matrix(kernel, n, scale[j], decay[j],
                                                                corr[j])
    return P


def _objective(P, R1, r, rho2, sigma2, n_rows):
    """``Y^T Σ^-1 Y + log det Σ`` from the reduced quantities (module docstring)."""
    m = R1.shape[0]
    H = R1 @ P @ R1.T
    H[np.diag_indices(m)] += sigma2
    try:
        L = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return math.inf, None
    v = scipy.linalg.solve_triangular(L, r, lower=True, check_finite=False)
    value = (rho2 / sigma2 + v @ v + (n_rows - m) * math.log(sigma2)
             + 2 * np.sum(np.log(np.diag(L))))
    return float(value), L


def _tune(kernel, n, nu, R1, r, rho2, sigma2, n_rows, g_ls):
    """Marginal-likelihood hyperparameters: the best of a grid of decay rates
    (scale matched to the least-squares energy), then L-BFGS-B from there."""
    per = 3 if kernel == "dc" else 2
    lo, hi = DECAY_BOUNDS

    def f(eta):
        value = _objective(_prior(kernel, n, *_unpack(kernel, eta, nu)), R1, r, rho2, sigma2,
                           n_rows)[0]
        return value if math.isfinite(value) else 1e300

    def f_and_gradient(eta):
        value, gradient = _objective_gradient(kernel, n, nu, eta, R1, r, rho2, sigma2, n_rows)
        return (value, gradient) if math.isfinite(value) else (1e300, np.zeros_like(eta))

    best = None
    energy = np.array([np.mean(g_ls[j * n:(j + 1) * n] ** 2) for j in range(nu)])
    for lam in DECAY_GRID:
        for factor in (0.1, 1.0, 10.0):
            eta = np.zeros((nu, per))
            mean_prior = np.mean(lam ** np.arange(1, n + 1))
            eta[:, 0] = np.log(np.maximum(energy * factor / mean_prior, 1e-300))
            eta[:, 1] = math.log((lam - lo) / (hi - lam))
            if per == 3:
                eta[:, 2] = math.atanh(min(math.sqrt(lam), 0.99) / 0.999)
            value = f(eta.ravel())
            if best is None or value < best[0]:
                best = (value, eta.ravel())
    res = scipy.optimize.minimize(f_and_gradient, best[1], jac=True, method="L-BFGS-B")
    return res.x if res.fun <= best[0] else best[1]


def _objective_gradient(kernel, n, nu, eta, R1, r, rho2, sigma2, n_rows):
    """:func:`_objective` at the search vector ``eta`` and its gradient.

    With ``H = σ² I + R1 P R1^T``, ``d(r^T H^-1 r + log det H) = tr((W - a a^T) dP)``,
    ``W = R1^T H^-1 R1``, ``a = R1^T H^-1 r`` (``d log det H = tr(H^-1 dH)``, ``d H^-1 =
    -H^-1 dH H^-1``); ``P`` is block diagonal by input, so each input's hyperparameters
    see their own block. One evaluation costs about three of the objective's Cholesky
    factorisations, against ``1 + 2 nu`` (``1 + 3 nu`` for DC) objectives for a
    finite-difference gradient (which the search used before: 10 inputs, 21 of them)."""
    scale, decay, corr = _unpack(kernel, eta, nu)
    value, L = _objective(_prior(kernel, n, scale, decay, corr), R1, r, rho2, sigma2, n_rows)
    if L is None:
        return math.inf, np.zeros_like(eta)
    X = scipy.linalg.solve_triangular(L, R1, lower=True, check_finite=False)   # L^-1 R1
    z = scipy.linalg.solve_triangular(L, r, lower=True, check_finite=False)
    a = X.T @ z
    G = X.T @ X - np.outer(a, a)
    per = 3 if kernel == "dc" else 2
    gradient = np.empty((nu, per))
    for j in range(nu):
        block = G[j * n:(j + 1) * n, j * n:(j + 1) * n]
        for k, dK in enumerate(_kernel_derivatives(kernel, n, scale[j], decay[j], corr[j])):
            gradient[j, k] = float(np.sum(block * dK))
    return value, gradient.ravel()


def _kernel_derivatives(kernel, n, scale, decay, correlation):
    """The derivatives of :func:`kernel_matrix` with respect to the search coordinates of
    :func:`_unpack`: ``log c``, the logit of ``λ`` over :data:`DECAY_BOUNDS` and, for
    DC, ``atanh(ρ / 0.999)``."""
    K = kernel_matrix(kernel, n, scale, decay, correlation)
    k = np.arange(1, n + 1, dtype=float)
    mx = np.maximum(k[:, None], k[None, :])
    lo, hi = DECAY_BOUNDS
    dlam = (decay - lo) * (hi - decay) / (hi - lo)      # dλ / d(logit)
    if kernel == "tc":
        d_decay = K * mx / decay
    elif kernel == "dc":
        d_decay = K * (k[:, None] + k[None, :]) / (2 * decay)
    else:
        s = k[:, None] + k[None, :] + mx
        d_decay = scale * (s * decay ** (s - 1) / 2 - 3 * mx * decay ** (3 * mx - 1) / 6)
    out = [K, d_decay * dlam]
    if kernel == "dc":
        dist = np.abs(k[:, None] - k[None, :])
        d_corr = np.where(dist > 0, scale * dist * correlation ** np.maximum(dist - 1, 0)
                          * decay ** ((k[:, None] + k[None, :]) / 2), 0.0)
        out.append(d_corr * (0.999 - correlation ** 2 / 0.999))   # dρ / d(atanh(ρ/0.999))
    return out


@serial_blas
@checked_call
def impulseest(data, n, *, kernel="tc"):
    """Estimate the impulse response (MATLAB ``impulseest``), regularised by a kernel.

    Parameters
    ----------
    data : IOData
        Uniformly sampled record (several experiments are stacked). The
        first ``n - 1`` samples of each experiment only serve as past inputs.
    n : int
        Number of coefficients (lags ``0 .. n-1``), ``n >= 2``.
    kernel : {'tc', 'dc', 'ss'} or None
        Prior covariance of the coefficients (module docstring), tuned by
        marginal likelihood; None: plain least squares.

    Returns
    -------
    ImpulseEstimate
        ``coefficients`` and ``std`` of shape (n, ny, nu);
        :meth:`ImpulseEstimate.model` gives the FIR state-space model.

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, no inputs, a constant output, or a
        channel whose magnitudes overflow or underflow in squares (beyond 1e150, or
        never above 1e-150).
    TooFewSamplesError
        Fewer than ``n nu + 10`` usable rows (the noise variance is estimated
        from the least-squares fit).
    NotExcitingError
        The input does not excite all ``n`` lags (rank-deficient regressor).
    OptionError
        Unknown kernel.

    Examples
    --------
    >>> import numpy as np, subid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(400)
    >>> y = np.convolve(u, 0.8 ** np.arange(30))[:400] + 0.1 * rng.standard_normal(400)
    >>> est = subid.impulseest(subid.IOData(u, y), 40)
    >>> est.coefficients.shape
    (40, 1, 1)
    >>> bool(abs(est.coefficients[1, 0, 0] - 0.8) < 0.05)
    True
    """
    if not isinstance(data, IOData):
        raise not_a_record(data, "impulseest")
    if not data.is_uniform:
        raise DataError("impulseest needs uniformly sampled data (an FIR model counts lags "
                        "in samples)")
    if data.n_inputs == 0:
        raise DataError("impulseest needs at least one input")
    check_channels(data)
    n = check_int(n, "n", minimum=2)
    if kernel is not None:
        kernel = check_choice(kernel, "kernel", KERNELS)
    nu, ny = data.n_inputs, data.n_outputs
    m = n * nu
    rows = sum(max(b - a - n + 1, 0) for a, b in data.experiment_ranges)
    if rows < m + MIN_EXTRA_ROWS:
        raise TooFewSamplesError(
            f"impulseest: {data.n_samples} samples give {rows} rows with all {n} lags "
            f"measured, but {n} coefficients x {nu} input(s) need at least "
            f"{m + MIN_EXTRA_ROWS}; use fewer coefficients (n <= "
            f"{max((data.n_samples - MIN_EXTRA_ROWS + 1) // (nu + 1), 0)}) or more data")
    rows, R = _factor(data, n)
    R1 = R[:m, :m]
    d = np.abs(np.diag(R1))
    if d.min() <= 1e-10 * d.max():
        raise NotExcitingError("impulseest: the input does not excite all "
                        f"{n} lags (rank-deficient regressor); use fewer coefficients or a "
                        "richer input")
    coef = np.empty((m, ny))
    std = np.empty((m, ny))
    posterior = []                  # per output: the white-noise covariance of the estimate
    effective = []                  # per output: the parameters the data determine
    sigma2 = np.empty(ny)
    hyper, likelihood = [], []
    R1inv = scipy.linalg.solve_triangular(R1, np.eye(m), check_finite=False)
    for i in range(ny):
        r = R[:m, m + i]
        rho2 = float(np.sum(R[m:, m + i] ** 2))    # least-squares residual of output i
        sigma2[i] = max(rho2 / (rows - m), 1e-300)
        g_ls = scipy.linalg.solve_triangular(R1, r, check_finite=False)
        if kernel is None:
            coef[:, i] = g_ls
            posterior.append(sigma2[i] * (R1inv @ R1inv.T))      # σ² (Φ^T Φ)^-1
            effective.append(float(m))
            hyper.append({})
            likelihood.append(None)
            continue
        eta = _tune(kernel, n, nu, R1, r, rho2, sigma2[i], rows, g_ls)
        scale, decay, corr = _unpack(kernel, eta, nu)
        P = _prior(kernel, n, scale, decay, corr)
        value, L = _objective(P, R1, r, rho2, sigma2[i], rows)
        PR = P @ R1.T                                      # P Φ^T Q1
        W = scipy.linalg.cho_solve((L, True), PR.T, check_finite=False)   # H^-1 R1 P
        coef[:, i] = W.T @ r
        posterior.append(P - PR @ W)                     # P - P Φ^T Σ^-1 Φ P
        # tr(Φ P Φ^T Σ^-1) = m - σ² tr(H^-1): the degrees of freedom of the fit
        Linv = scipy.linalg.solve_triangular(L, np.eye(m), lower=True, check_finite=False)
        effective.append(float(m - sigma2[i] * np.sum(Linv ** 2)))
        entry = {"scale": scale.tolist(), "decay": decay.tolist()}
        if kernel == "dc":
            entry["correlation"] = corr.tolist()
        hyper.append(entry)
        likelihood.append(value)
    lags = []
    for i, (variance, S) in enumerate(zip(_coloured_meats(data, n, coef, rows, m), posterior)):
        meat, lag = variance
        # Cov = S + S (Q / σ² - Φ^T Φ) S / σ² (module docstring): the posterior with its
        # noise part σ² M Φ^T Φ M replaced by the sandwich M Q M (M = S / σ²)
        D = meat / sigma2[i] - R1.T @ R1
        value = np.diag(S) + np.einsum("ij,ji->i", S @ D, S) / sigma2[i]
        std[:, i] = np.sqrt(np.maximum(value, 0.0))
        lags.append(lag)
    weak = [data.output_names[i] for i in range(ny) if effective[i] < MIN_EFFECTIVE_PARAMETERS]
    if weak:
        warnings.warn(
            f"impulseest: the data determine less than {MIN_EFFECTIVE_PARAMETERS:g} of the "
            f"impulse response's parameters for output(s) {', '.join(weak)} (effective "
            f"number {min(effective):.2g}: the marginal likelihood shrank the prior to the "
            "noise): the estimate is close to the prior mean, zero, and its std reflects "
            "the prior's fitted scale, not what the data show. The response is not "
            "distinguishable from the noise at this signal-to-noise ratio and record "
            "length; use more data, a stronger input, or fewer coefficients (n)",
            PoorFitWarning, stacklevel=2)
    # regressor column j*n + k holds u_j[t-k]: reorder to (lag, output, input)
    coefficients = coef.reshape(nu, n, ny).transpose(1, 2, 0)
    stds = std.reshape(nu, n, ny).transpose(1, 2, 0)
    return ImpulseEstimate(coefficients, stds, float(data.dt), kernel, hyper, sigma2,
                           tuple(data.input_names), tuple(data.output_names),
                           {"n_samples": rows, "marginal_likelihood": likelihood,
                            "effective_parameters": effective,
                            "std": {"method": STD_METHOD, "lag_window": lags}})


#: What :attr:`ImpulseEstimate.std` is (``info['std']['method']``).
STD_METHOD = ("posterior (least squares: sampling) covariance with the white-noise part "
              "replaced by the sandwich Φ^T K Φ of the residuals' Bartlett-windowed "
              "autocovariance K (Newey and West 1987; Ljung 1999, eqs. 9.40-9.42)")


def _coloured_meats(data, n, coef, rows, m):
    """Per output, ``(Q, M)``: the meat ``Q = Σ_t Σ_s φ(t) k(t - s) φ(s)^T`` of the
    sandwich, ``k(τ) = w(τ) r(τ)`` the residual autocovariance of the estimate ``coef``
    under the Bartlett window of :func:`subid.methods.dt._sandwich.choose_lag`'s ``M``
    (no products across experiments): ``Q = k(0) G(0) + Σ_{τ=1..M} k(τ) (G(τ) +
    G(τ)^T)``, ``G(τ) = Σ_t φ(t) φ(t - τ)^T`` over the rows of one experiment
    (:func:`_lagged_grams`, from the inputs' lagged products: ``O(N nu^2 (M + 2n))``
    instead of the ``O(N m^2)`` of ``Φ^T`` times the filtered ``Φ``). One pass over the
    regressor rows, a block at a time, for the residuals."""
    from subid.methods.dt._sandwich import MAX_LAG, autocovariance, bartlett, choose_lag
    ny = coef.shape[1]
    block = max(QR_BLOCK_ENTRIES // (m + ny), 4 * (m + ny))
    e = np.empty((rows, ny))
    for start in range(0, rows, block):
        Phi, Y = _regressors(data, n, start, start + block)
        e[start:start + Phi.shape[0]] = Y - Phi @ coef
    bounds = np.cumsum([0] + [max(b - a - n + 1, 0) for a, b in data.experiment_ranges])
    segments = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    kernels, lags = [], []
    for i in range(ny):
        r = autocovariance(e[:, i:i + 1], segments, min(MAX_LAG, rows - 1), rows - m)
        lags.append(choose_lag(r, rows))
        kernels.append(bartlett(lags[-1]) * r[:lags[-1] + 1, 0, 0])
    meats = [np.zeros((m, m)) for _ in range(ny)]
    for a, b in data.experiment_ranges:
        if b - a < n:
            continue
        for tau, G in enumerate(_lagged_grams(data.u[a:b], n, max(lags))):
            for Q, k in zip(meats, kernels):
                if tau < k.size:
                    Q += k[tau] * G if tau == 0 else k[tau] * (G + G.T)
    return list(zip(meats, lags))


def _lagged_grams(u, n: int, max_lag: int):
    """``G(τ) = Σ_t φ(t) φ(t - τ)^T`` for ``τ = 0..max_lag`` (fewer when the record has
    fewer rows), ``φ(t)`` the regressor row of one experiment's input ``u`` (shape
    ``(L, nu)``; rows ``t = n-1..L-1``, column ``j n + a`` holding ``u_j(t - a)``), the
    sum over the rows with ``t - τ`` a row too.

    Entry ``((j, a), (l, b))`` is ``Σ_{t'=A}^{E-1} u_j(t') u_l(t' - s)`` with ``s = τ + b
    - a``, ``A = n - 1 + τ - a``, ``E = L - a``: the sum over the whole record of the
    lagged products at lag ``s`` less a prefix (``t' < A``, at most ``n + M`` terms) and
    a suffix (``t' >= E``, fewer than ``n``), so that the record is read once per lag
    ``s`` (``-(n-1)..M+n-1``), not once per pair of columns. Yields one ``G(τ)`` (shape
    ``(n nu, n nu)``) at a time."""
    L, nu = u.shape
    top = min(max_lag, L - n)                 # G(τ) needs rows t and t - τ
    S = top + 2 * n - 1                       # lags s = -(n-1) .. top + n - 1
    shifts = np.arange(S) - (n - 1)
    head = min(n + top, L)                    # prefix points A = 0 .. n - 1 + top
    tail0 = L - n + 1                         # suffix points E = L - n + 1 .. L
    # Σ over t' of u_j(t') u_l(t' - s): the input's lag products Γ(e) = Σ u(t) u(t+e)^T
    # (subid.methods.dt._lag_fit.correlations, by FFT), Γ(s)^T for s >= 0, Γ(-s) below
    gamma = correlations(u, u[:, :0], max(top + n - 1, n - 1))[0]
    total = np.concatenate([gamma[n - 1:0:-1], gamma[:top + n].transpose(0, 2, 1)])
    total = total.transpose(1, 2, 0)          # (j, l, s + n - 1)

    def products(t):
        """``u_j(t') u_l(t' - s)`` for the samples ``t`` (zero where ``t' - s`` falls
        outside the record): shape (nu, nu, S, len(t))."""
        src = t[None, :] - shifts[:, None]                        # (S, len(t))
        ok = (src >= 0) & (src < L)
        lagged = np.where(ok[..., None], u[np.clip(src, 0, L - 1)], 0.0)   # (S, T, nu)
        return np.einsum("tj,stl->jlst", u[t], lagged)

    pre = np.zeros((nu, nu, S, head + 1))     # pre[..., x] = Σ_{t' < x}
    pre[..., 1:] = np.cumsum(products(np.arange(head)), axis=-1)
    suf = np.zeros((nu, nu, S, n))            # suf[..., x - tail0] = Σ_{t' >= x}
    if n > 1:
        suf[..., :n - 1] = np.cumsum(products(np.arange(tail0, L))[..., ::-1],
                                     axis=-1)[..., ::-1]
    lag_of = np.arange(n)
    E = np.broadcast_to((n - 1 - lag_of)[:, None], (n, n))          # E - tail0, by a
    for tau in range(top + 1):
        s_idx = tau + lag_of[None, :] - lag_of[:, None] + n - 1      # (a, b)
        A = np.broadcast_to((n - 1 + tau - lag_of)[:, None], (n, n))
        G = total[:, :, s_idx] - pre[:, :, s_idx, A] - suf[:, :, s_idx, E]   # (j, l, a, b)
        # rows j n + a, columns l n + b
        yield G.transpose(0, 2, 1, 3).reshape(nu * n, nu * n)
