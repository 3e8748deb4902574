"""Residual analysis of models in innovation form (MATLAB's ``resid``): the whiteness of the
one-step prediction errors and their independence from the inputs (Ljung, *System
Identification*, 2nd ed., 1999, Sec. 16.6). The predictions come from
:func:`subid.model.prediction.predict`.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from subid._blas import serial_blas
from subid._validation import check_int, check_probability, checked_call
from subid.errors import DataError, NoiseModelWarning
from subid.model.prediction import check_model_data, predict

__all__ = ["residuals", "correlations"]


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
    from scipy.special import ndtri
    max_lag = check_int(max_lag, "max_lag", minimum=1)
    confidence = check_probability(confidence, "confidence")
    n = e.shape[0]
    if max_lag >= n:
        raise DataError(f"max_lag {max_lag} must be smaller than the {n} samples of the record")
    z = float(ndtri(0.5 + confidence / 2))
    ny = e.shape[1]
    # [e, u], each channel's mean removed (one copy of the record)
    z_all = np.hstack([e, u])
    z_all -= z_all.mean(axis=0)
    e0 = z_all[:, :ny]
    lags = np.arange(max_lag + 1)
    cross_lags = np.arange(-max_lag, max_lag + 1)
    nu = u.shape[1]
    auto = np.zeros((ny, lags.size))
    cross = np.zeros((ny, nu, cross_lags.size))
    cross_bound = np.zeros((ny, nu))
    ree_full = np.zeros((ny, cross_lags.size))
    # every lagged product of z = [e, u] at once (pairs inside one experiment), then
    # r_ab(tau) = sum_t a(t) b(t - tau) / N: P[tau][a, b] for tau >= 0, P[-tau][b, a] below
    from subid.evaluation.nonparametric import _lag_products
    P = sum(_lag_products(z_all[s:t], max_lag) for s, t in (ranges or [(0, n)])) / n

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
            ree0 = e0[:, i] @ e0[:, i] / n
            denom = math.sqrt(max(ree0 * ru0, 0.0))
            c = xcorr(i, ny + j)
            cross[i, j] = c / denom if denom > 0 else 0.0
            p = float(np.sum(ree_full[i] * ruu))
            cross_bound[i, j] = z * math.sqrt(max(p, 0.0) / n)
    return {"lags": lags, "auto": auto, "auto_bound": z / math.sqrt(n),
            "cross_lags": cross_lags, "cross": cross, "cross_bound": cross_bound,
            "residual": e, "confidence": confidence}


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
        ``'simulation'``), ``whiteness_ok`` (every auto-correlation at lags
        1..M inside the band) and ``independence_ok`` (every
        cross-correlation inside its band).
    """
    check_model_data(model, data)
    kind = "one-step prediction" if (model.K is not None and not model.is_continuous) \
        else "simulation"
    e = data.y - predict(model, data, 1 if kind != "simulation" else math.inf, x0)
    if kind == "simulation":
        warnings.warn("residuals: the model has no Kalman gain K; these are simulation "
                      "errors, white only for white measurement noise", NoiseModelWarning,
                      stacklevel=2)
    out = correlations(e, data.u, max_lag=max_lag, confidence=confidence,
                       ranges=data.experiment_ranges)
    out["kind"] = kind
    out["whiteness_ok"] = bool(np.all(np.abs(out["auto"][:, 1:]) <= out["auto_bound"]))
    out["independence_ok"] = bool(np.all(np.abs(out["cross"]) <=
                                         out["cross_bound"][:, :, None]))
    return out
