"""Residual analysis of models in innovation form (MATLAB's ``resid``): the whiteness of the
one-step prediction errors and their independence from the inputs (Ljung, *System
Identification*, 2nd ed., 1999, Sec. 16.6). The predictions come from
:func:`subid.model.prediction.predict`.

The verdicts ``whiteness_ok`` and ``independence_ok`` are portmanteau tests at the stated
confidence (:func:`portmanteau`), not "every lag inside its band": with 25 lags per
channel the latter fails on the true model most of the time (each lag has a false-alarm
rate of 1 - confidence on its own). The per-lag bands remain for the plot.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from subid._blas import serial_blas
from subid._validation import check_int, check_magnitude, check_probability, checked_call
from subid.errors import DataError, NoiseModelWarning
from subid.model.prediction import check_model_data, predict

__all__ = ["residuals", "correlations", "portmanteau"]


def correlations(e, u, *, max_lag: int = 25, confidence: float = 0.99, ranges=None) -> dict:
    """Auto-correlation of residuals and their cross-correlation with inputs.

    Parameters
    ----------
    e : ndarray, shape (N, ny)
        Residuals.
    u : ndarray, shape (N, nu)
    max_lag : int
    confidence : float
        Two-sided level of the bands.
    ranges : sequence of (start, stop), optional
        The experiments of a record of several (:attr:`subid.IOData.experiment_ranges`):
        lagged products never pair samples of two experiments.

    Returns
    -------
    dict
        ``lags`` (0..M), ``auto`` (ny, M+1) normalised auto-correlation,
        ``auto_bound`` (``z / sqrt(N)``), ``cross_lags`` (-M..M), ``cross``
        (ny, nu, 2M+1) normalised correlation of ``e_i(t)`` and
        ``u_j(t - tau)``, ``cross_bound`` (ny, nu) the band
        ``z sqrt(sum_k r_ee(k) r_uu(k) / N)`` (Ljung, *System Identification*,
        Sec. 16.6), ``residual`` and ``confidence``.
    """
    max_lag, confidence = _checked(max_lag, confidence, e.shape[0])
    return _correlations_of(_products(e, u, ranges, max_lag), e, confidence)


def _checked(max_lag, confidence, n: int):
    """``(max_lag, confidence)`` checked for a record of ``n`` samples."""
    max_lag = check_int(max_lag, "max_lag", minimum=1)
    confidence = check_probability(confidence, "confidence")
    if max_lag >= n:
        raise DataError(f"max_lag {max_lag} must be smaller than the {n} samples of the record")
    return max_lag, confidence


def _reach(max_lag: int, n: int, white: bool) -> int:
    """The lags of the products :func:`portmanteau` reads: ``max_lag``, and as many more
    for the Bartlett window of coloured (simulation) errors; at most ``n - 1``."""
    return min(max_lag * (1 if white else 2), n - 1)


def _products(e, u, ranges, lags: int):
    """``P[τ] = Σ_t z(t+τ) z(t)^T / N`` for τ = 0..lags, pairs inside one experiment,
    of ``z = [e, u]`` with each channel's mean removed (over the whole record) and
    divided by its largest magnitude (the statistics below are invariant to a channel's
    scale; a large residual cannot overflow):
    what :func:`correlations` and :func:`portmanteau` read, computed once for both by
    :func:`residuals` (one pass over the record instead of five)."""
    z = np.hstack([e, u])
    z -= z.mean(axis=0)
    scale = np.abs(z).max(axis=0)
    scale[scale == 0] = 1.0
    z /= scale
    return _lagged(z, ranges, lags)


def _correlations_of(P, e, confidence) -> dict:
    """:func:`correlations` from the lagged products ``P`` of :func:`_products` (its
    lags the ``max_lag``)."""
    from scipy.special import ndtri
    n, ny = e.shape
    nu = P.shape[1] - ny
    max_lag = P.shape[0] - 1
    z = float(ndtri(0.5 + confidence / 2))
    lags = np.arange(max_lag + 1)
    cross_lags = np.arange(-max_lag, max_lag + 1)
    auto = np.zeros((ny, lags.size))
    cross = np.zeros((ny, nu, cross_lags.size))
    cross_bound = np.zeros((ny, nu))
    ree_full = np.zeros((ny, cross_lags.size))

    # r_ab(tau) = sum_t a(t) b(t - tau) / N: P[tau][a, b] for tau >= 0, P[-tau][b, a] below
    def xcorr(a, b):
        return np.concatenate([P[:0:-1, b, a], P[:, a, b]])

    for i in range(ny):
        r = xcorr(i, i)
        r0 = r[max_lag]
        ree_full[i] = r / r0 if r0 > 0 else 0.0
        auto[i] = ree_full[i][max_lag:]
    for j in range(nu):
        ru = xcorr(ny + j, ny + j)
        ru0 = ru[max_lag]
        ruu = ru / ru0 if ru0 > 0 else np.zeros_like(ru)
        for i in range(ny):
            denom = math.sqrt(max(P[0, i, i] * ru0, 0.0))
            c = xcorr(i, ny + j)
            cross[i, j] = c / denom if denom > 0 else 0.0
            p = float(np.sum(ree_full[i] * ruu))
            cross_bound[i, j] = z * math.sqrt(max(p, 0.0) / n)
    return {"lags": lags, "auto": auto, "auto_bound": z / math.sqrt(n),
            "cross_lags": cross_lags, "cross": cross, "cross_bound": cross_bound,
            "residual": e, "confidence": confidence}


def _lagged(z, ranges, lags: int) -> np.ndarray:
    """``P[τ] = Σ_t z(t+τ) z(t)^T / N`` for τ = 0..lags, pairs inside one experiment."""
    from subid.evaluation.nonparametric import _lag_products
    n = z.shape[0]
    return sum(_lag_products(z[s:t], lags) for s, t in (ranges or [(0, n)])) / n


def _quadratic(r: np.ndarray, cov: np.ndarray) -> tuple[float, int]:
    """``r^T cov^+ r`` and the rank of ``cov`` (its pseudo-inverse: directions of no
    variance, e.g. a record of a few sinusoids, carry no degree of freedom)."""
    w, v = np.linalg.eigh((cov + cov.T) / 2)
    keep = w > max(w.max(initial=0.0), 0.0) * cov.shape[0] * np.finfo(float).eps * 10
    if not keep.any():
        return 0.0, 0
    proj = v[:, keep].T @ r
    return float(np.sum(proj ** 2 / w[keep])), int(keep.sum())


def portmanteau(e, u, *, max_lag: int = 25, confidence: float = 0.99, ranges=None,
                white: bool = True) -> dict:
    """Portmanteau tests of whiteness and of independence from the input, at ``confidence``.

    Whiteness: the multivariate portmanteau statistic of Hosking (1980), with the
    small-sample weights of Ljung & Box (1978),

        Q = N^2 Σ_{k=1..M} tr(C_k^T C_0^{-1} C_k C_0^{-1}) / (N - k)  ~  χ²(ny² M),

    ``C_k = Σ_t ε(t+k) ε(t)^T / N``; for one output it is Ljung's
    ``N Σ_k r_ε(k)² / r_ε(0)² ~ χ²(M)`` (*System Identification*, 2nd ed., 1999,
    eq. (16.65)) with those weights. The residuals are white when ``Q`` stays below the
    ``confidence`` quantile: one test across all outputs and lags, whose false-alarm
    rate on a correct model is ``1 - confidence``.

    Independence: for each output ``i``, Ljung's eqs. (16.68)-(16.69),
    ``ξ_i = N r_i^T P_i^{-1} r_i ~ χ²(nu (M+1))``, with ``r_i = Σ_t φ(t) ε_i(t) / N``,
    ``φ(t) = [u(t); u(t-1); ...; u(t-M)]`` (the inputs the model claims to explain:
    lags 0..M) and ``P_i = Σ_k R_εi(k) R_φ(k)``, the covariance of ``√N r_i``; for white
    residuals ``P_i = λ_i R_φ(0)`` (``white=True``, the hypothesis of a correct model in
    innovation form), otherwise the sum runs over |k| <= M with Bartlett weights (Newey
    & West 1987, which keep ``P_i`` positive semi-definite). The outputs are combined
    by Bonferroni: independent when every ``p_i >= (1 - confidence) / ny`` (a
    false-alarm rate of at most ``1 - confidence``). Negative lags (the residual against
    future inputs: feedback) are not tested; the plot shows them.

    Parameters
    ----------
    e : ndarray, shape (N, ny)
        Residuals.
    u : ndarray, shape (N, nu)
        Inputs.
    max_lag : int
        M, the largest lag tested.
    confidence : float
        Level of the tests (0.99: a false-alarm rate of 1 %).
    ranges : sequence of (start, stop), optional
        Experiments of a record of several: lagged products stay inside one.
    white : bool
        Whether the residuals are white under the hypothesis tested (one-step
        prediction errors of a model in innovation form); False for simulation errors,
        which may be coloured by the disturbances.

    Returns
    -------
    dict
        ``whiteness``: dict with ``statistic``, ``dof``, ``p_value``, ``ok``, ``test``;
        ``independence``: dict with ``statistic``, ``dof``, ``p_value`` (arrays of ny,
        one per output), ``level`` (the Bonferroni level ``(1 - confidence) / ny``),
        ``ok``, ``test``.

    References
    ----------
    Hosking, J. R. M. (1980). The multivariate portmanteau statistic. *JASA* 75(371),
    602-608. Ljung, G. M. & Box, G. E. P. (1978). On a measure of lack of fit in time
    series models. *Biometrika* 65(2), 297-303. Ljung, L. (1999). *System
    Identification: Theory for the User*, 2nd ed., Sec. 16.6. Newey, W. K. & West,
    K. D. (1987). *Econometrica* 55(3), 703-708.
    """
    reach = _reach(max_lag, e.shape[0], white)
    return _portmanteau_of(_products(e, u, ranges, reach), e.shape[0], e.shape[1],
                           max_lag=max_lag, confidence=confidence, white=white)


def _portmanteau_of(P, n: int, ny: int, *, max_lag: int, confidence: float,
                    white: bool) -> dict:
    """:func:`portmanteau` from the lagged products ``P`` of :func:`_products`
    (``max_lag`` lags, twice as many for ``white=False``, at most ``n - 1``)."""
    from scipy.special import chdtrc  # chi2.sf(x, dof) without importing scipy.stats
    nu = P.shape[1] - ny
    alpha = 1.0 - confidence
    # whiteness (Hosking 1980; Ljung & Box 1978 weights); per-channel scaling: Q is invariant
    C = P[:max_lag + 1, :ny, :ny]
    w, v = np.linalg.eigh(C[0])
    keep = w > max(w.max(initial=0.0), 0.0) * ny * np.finfo(float).eps * 10
    rank = int(keep.sum())
    q = 0.0
    if rank:
        root = v[:, keep] / np.sqrt(w[keep])          # C0^{+1/2}: tr(C_k^T C0^+ C_k C0^+)
        for k in range(1, max_lag + 1):
            q += float(np.sum((root.T @ C[k] @ root) ** 2)) / (n - k)
        q *= n * n
    dof_w = rank * rank * max_lag
    p_w = float(chdtrc(dof_w, q)) if dof_w else 1.0
    whiteness = {"statistic": q, "dof": dof_w, "p_value": p_w, "ok": bool(p_w >= alpha),
                 "test": "multivariate portmanteau (Hosking 1980), chi-square"}
    # independence (Ljung 1999, eqs. (16.68)-(16.69)), per output, Bonferroni
    window = 0 if white else max_lag
    reach = P.shape[0] - 1
    Pu = P[:, ny:, ny:]                               # R_u(m) = E u(t) u(t-m)^T

    def r_u(m):
        if abs(m) > reach:
            return np.zeros((nu, nu))
        return Pu[m] if m >= 0 else Pu[-m].T

    def r_phi(k):                                     # E φ(t) φ(t-k)^T, blocks R_u(k+b-a)
        return np.block([[r_u(k + b - a) for b in range(max_lag + 1)]
                         for a in range(max_lag + 1)])

    # r_i: Σ_t u_j(t - τ) ε_i(t) / N, ordered as φ (lag-major, then input)
    rs = [P[:max_lag + 1, i, ny:].reshape(-1) for i in range(ny)]
    rees = [P[:window + 1, i, i] for i in range(ny)]
    phi = r_phi(0)
    covs = [ree[0] * phi for ree in rees]
    for k in range(1, window + 1):                   # one R_φ(k) at a time
        phi = r_phi(k)
        phi = phi + phi.T
        weight = 1.0 - k / (window + 1)
        for i in range(ny):
            covs[i] += weight * rees[i][k] * phi
    stats, dofs, ps = np.zeros(ny), np.zeros(ny, dtype=int), np.ones(ny)
    for i in range(ny):
        stats[i], dofs[i] = _quadratic(rs[i], covs[i])
        stats[i] *= n
        ps[i] = float(chdtrc(dofs[i], stats[i])) if dofs[i] else 1.0
    level = alpha / ny
    independence = {"statistic": stats, "dof": dofs, "p_value": ps, "level": level,
                    "ok": bool(np.all(ps >= level)),
                    "test": "input-residual cross-correlation (Ljung 1999, eq. (16.69)), "
                            "chi-square per output, Bonferroni across outputs"}
    return {"whiteness": whiteness, "independence": independence}


@serial_blas
@checked_call
def residuals(model, data, *, max_lag: int = 25, confidence: float = 0.99, x0=None) -> dict:
    """Residual analysis on the one-step prediction errors (MATLAB's ``resid``).

    The residuals are ``e = y - ŷ[t|t-1]`` of the Kalman predictor
    (:func:`predict` with ``steps=1``): for a correct model in innovation form
    they are white and uncorrelated with past inputs. A model without ``K``
    uses its simulation errors (with a :class:`~subid.errors.NoiseModelWarning`):
    those are white only if the disturbances are white measurement noise.

    Parameters
    ----------
    model : StateSpace
    data : IOData
    max_lag : int
        Largest lag in samples.
    confidence : float
        Level of the bands (0.99: 99 %).
    x0 : None, 'estimate', 'zero', 0 or array_like of shape (n,)
        As in :func:`predict` (None, the default, estimates it).

    Returns
    -------
    dict
        As :func:`correlations`, plus ``kind`` (``'one-step prediction'`` or
        ``'simulation'``), ``whiteness`` and ``independence`` (the tests of
        :func:`portmanteau`: statistics, degrees of freedom, p-values),
        ``whiteness_ok`` (the whiteness test passes at ``confidence``: a correct
        model fails it in a fraction ``1 - confidence`` of records) and
        ``independence_ok`` (likewise for the correlation of the residuals with
        the inputs at lags 0..M). The per-lag bands (``auto_bound``,
        ``cross_bound``) are for the plot: with many lags some fall outside them
        by chance, so they are not the verdict.

    Raises
    ------
    DataError
        Channels or sampling periods that do not match the model, a sample beyond
        1e150 in magnitude (its square overflows: rescale the channel).
    """
    check_model_data(model, data)
    check_magnitude(data.u, "input", data.input_names)
    check_magnitude(data.y, "output", data.output_names)
    kind = "one-step prediction" if (model.K is not None and not model.is_continuous) \
        else "simulation"
    e = data.y - predict(model, data, 1 if kind != "simulation" else math.inf, x0)
    if kind == "simulation":
        warnings.warn("residuals: the model has no Kalman gain K; these are simulation "
                      "errors, white only for white measurement noise", NoiseModelWarning,
                      stacklevel=2)
    n = e.shape[0]
    max_lag, confidence = _checked(max_lag, confidence, n)
    white = kind != "simulation"
    # the lagged products once, for the correlations and the tests
    products = _products(e, data.u, data.experiment_ranges, _reach(max_lag, n, white))
    out = _correlations_of(products[:max_lag + 1], e, confidence)
    out["kind"] = kind
    tests = _portmanteau_of(products, n, e.shape[1], max_lag=max_lag, confidence=confidence,
                            white=white)
    out.update(tests)
    out["whiteness_ok"] = tests["whiteness"]["ok"]
    out["independence_ok"] = tests["independence"]["ok"]
    return out
