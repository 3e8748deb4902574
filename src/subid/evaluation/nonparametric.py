"""Model-free frequency-response estimates: :func:`spa` and :func:`etfe`.

Both return a :class:`subid.FRData` with the response ``(n_freq, ny, nu)``,
its standard deviation and the squared multiple coherence of every output
with all inputs, for checking a parametric model against what the data say
(:func:`subid.plot.bode` overlays them).

:func:`spa` is the Blackman-Tukey estimate (Ljung, *System Identification*,
2nd ed., 1999, Section 6.4; MATLAB ``spa``): sample covariances
``R_yu(τ) = 1/N Σ_t y[t+τ] u[t]^T`` and ``R_u(τ)`` up to the lag-window size
``γ``, weighted by the Hann lag window ``W(τ) = (1 + cos(π τ / γ)) / 2`` and
Fourier transformed,

    Φ_yu(ω) = Σ_{|τ|<=γ} W(τ) R_yu(τ) e^{-iωτ dt},   Ĝ = Φ_yu Φ_u^-1,
    Φ_v = Φ_y - Φ_yu Φ_u^-1 Φ_uy,   κ_i = 1 - Φ_v,ii / Φ_y,ii,

with the asymptotic variance ``Var Ĝ_ij ≈ (1/N) Σ_τ W(τ)^2 Φ_v,ii [Φ_u^-1]_jj``
(Ljung 1999, Section 6.4, the variance of the smoothed estimate; the MIMO form
as in MATLAB). The default window size is MATLAB's ``γ = min(N/10, 30)`` and
the default frequencies ``(1..128)/128 π/dt``. The standard deviation is the
variance part only: the bias of a window too short for a sharp resonance
(resolution about ``2π/γ`` rad per sample) is not in it, so compare windows
(measured: ``E|Ĝ - G|^2 / std^2`` is 1.08 for a first-order system with
``γ = 60``, but 48 for resonances of damping 0.03 with the default ``γ = 30``).

:func:`etfe` is the empirical transfer-function estimate from the discrete
Fourier transforms ``Y_k, U_k`` of the record (Ljung 1999, Section 6.3):
``Ĝ_k = Y_k / U_k`` (one input), or, with ``smoothing = M``, the weighted
least-squares fit over the ``2M + 1`` neighbouring bins with Hann weights
``w_l`` (sum 1; Ljung 1999, eq. (6.46)-type frequency smoothing)::

    Ĝ_k = S_yu S_u^-1,   S_yu = Σ_l w_l Y_{k+l} U_{k+l}^H,   S_u = Σ_l w_l U U^H.

Its standard deviation is that of the weighted least-squares estimate:
``Var Ĝ_ij = Φ̂_v,i [S_u^-1 S_u2 S_u^-1]_jj`` with ``S_u2 = Σ w_l^2 U U^H``
and ``Φ̂_v`` the weighted residual power divided by ``1 - tr(S_u^-1 S_u2)``
(unbiased for a response constant over the window).

Neither function removes means or trends: detrend the record first
(:meth:`subid.IOData.detrend`).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from subid._blas import serial_blas
from subid._validation import check_int, checked_call
from subid.data import IOData, not_a_record
from subid.errors import DataError, NotExcitingError, ResolutionWarning, TooFewSamplesError
from subid.frdata import FRData

__all__ = ["spa", "etfe", "default_window_size"]

#: Number of frequencies of :func:`spa`'s default grid (MATLAB's).
N_FREQUENCIES = 128
# Smallest relative eigenvalue of the input spectrum accepted at a frequency.
SINGULAR_INPUT = 1e-10


def _check(data, name):
    if not isinstance(data, IOData):
        raise not_a_record(data, name)
    if not data.is_uniform:
        raise DataError(f"{name} needs uniformly sampled data")
    if data.n_inputs == 0:
        raise DataError(f"{name} estimates a transfer function and needs at least one input")


def default_window_size(n_samples: int) -> int:
    """MATLAB's default lag-window size of ``spa``: ``min(N / 10, 30)``.

    Parameters
    ----------
    n_samples : int

    Returns
    -------
    int
    """
    return int(min(n_samples // 10, 30))


#: Largest lag count :func:`_covariances` computes by direct products rather than FFTs.
_DIRECT_LAGS = 64


#: Samples per block of the direct lag products of :func:`_covariances`.
_COVARIANCE_BLOCK = 4096


def _lag_products(z, lags: int, scale=None) -> np.ndarray:
    """``P[τ] = Σ_t z[t+τ] z[t]^T`` for τ = 0..lags (zero beyond the record), shape
    (lags + 1, nz, nz): one matrix product per lag and block of :data:`_COVARIANCE_BLOCK`
    samples, each block read from cache by every lag. ``z``: an array (n, nz), or a tuple
    of arrays with n rows whose columns side by side make it (each block joined on its
    own: the record is not copied whole). ``scale`` (nz,): factors each column is
    multiplied by, block by block (the products of ``z * scale`` without a scaled copy
    of the record)."""
    parts = z if isinstance(z, tuple) else (z,)
    n, nz = parts[0].shape[0], sum(p.shape[1] for p in parts)
    P = np.zeros((lags + 1, nz, nz))
    # several parts: side by side in one buffer, filled block by block (a new array per
    # block, above glibc's mmap threshold, costs a fresh mapping and its page faults)
    joined = np.empty((min(n, _COVARIANCE_BLOCK + lags), nz)) \
        if len(parts) > 1 or scale is not None else None
    for t0 in range(0, n, _COVARIANCE_BLOCK):
        t1 = min(n, t0 + _COVARIANCE_BLOCK)
        end = min(n, t1 + lags)
        if joined is None:
            segment = parts[0][t0:end]
        else:
            segment, column = joined[:end - t0], 0
            for p in parts:
                segment[:, column:column + p.shape[1]] = p[t0:end]
                column += p.shape[1]
            if scale is not None:
                segment *= scale
        m = t1 - t0
        # the lags whose window segment[tau:tau + m] lies inside the segment: one stacked
        # product, window[tau] = segment[tau:tau + m].T (a strided view, no copy; numpy
        # runs the same matrix product per lag, without a Python call each: a quarter
        # of the time at 7 x 10^5 samples, 30 lags, 4 channels; the same sums)
        whole = min(lags + 1, end - t0 - m + 1)
        if whole > 0:
            row, column = segment.strides
            window = np.lib.stride_tricks.as_strided(
                segment, shape=(whole, nz, m), strides=(row, column, row), writeable=False)
            P[:whole] += np.matmul(window, segment[:m])
        for tau in range(whole, min(lags + 1, n - t0)):      # near the record's end
            m_tau = min(t1, n - tau) - t0
            P[tau] += segment[tau:tau + m_tau].T @ segment[:m_tau]
    return P


def _covariances(data, lags, scale=None):
    """``R_z(τ) = 1/N Σ_t z[t+τ] z[t]^T`` for ``z = [y, u] * scale`` (``scale``: a
    factor per channel, outputs first; none by default), τ = 0..lags, summed over
    experiments (one product per lag for at most :data:`_DIRECT_LAGS` lags, else by
    FFT). Shape (lags + 1, nz, nz)."""
    nz = data.n_outputs + data.n_inputs
    R = np.zeros((lags + 1, nz, nz))
    for a, b in data.experiment_ranges:
        if lags <= _DIRECT_LAGS:
            # few lags (the default window is at most 30): one product per lag costs
            # (lags + 1) N nz^2, far below the FFTs of 2N points (6x faster at 7 x 10^5
            # samples, 2 inputs, 2 outputs, 30 lags); same sums to rounding. Taken in
            # blocks of _COVARIANCE_BLOCK samples, so that every lag's product reads the
            # block from cache, not the whole record from memory (4x faster again);
            # z = [y, u] joined block by block
            R += _lag_products((data.y[a:b], data.u[a:b]), lags, scale)
            continue
        z = np.hstack([data.y[a:b], data.u[a:b]])
        if scale is not None:
            z *= scale
        n_fft = 1 << int(math.ceil(math.log2(2 * (b - a) + 1)))
        Z = np.fft.rfft(z, n_fft, axis=0)
        for i in range(nz):          # one channel at a time: memory n_fft x nz
            R[:, i, :] += np.fft.irfft(Z[:, i:i + 1] * np.conj(Z), n_fft, axis=0)[:lags + 1]
    return R / data.n_samples


def _unit_scaled(data, name):
    """``(scaled, back)``: ``data`` with each channel multiplied by the power of two that
    brings its largest magnitude into [0.5, 1) (exact: no digit changes), and the factors
    ``back[i, j]`` that turn a response of the scaled record into one of ``data``
    (``G = G_scaled * back``). The spectra are then computed from numbers of order one:
    at 1e200 their squares overflowed (NaN responses, reported as "FRData: response has
    NaN values"), at 1e-300 they underflowed ("input spectrum singular")."""
    fu, fy = _unit_factors(data, name)
    return data.scaled(inputs=fu, outputs=fy), fu[None, :] / fy[:, None]


def _unit_factors(data, name):
    """``(fu, fy)``: the factors of :func:`_unit_scaled`, per input and per output."""
    peaks = [np.abs(x).max(axis=0) if x.shape[0] else np.ones(x.shape[1])
             for x in (data.u, data.y)]
    fu, fy = (np.ldexp(1.0, -np.frexp(np.where(p > 0, p, 1.0))[1]) for p in peaks)
    if not (np.isfinite(fu).all() and np.isfinite(fy).all()):
        raise DataError(f"{name}: a channel's values are all below 1e-307 in magnitude "
                        "(subnormal numbers); express it in other units (multiply it by a "
                        "constant) and scale the result back")
    return fu, fy


def _solve_right(S_yu, S_u):
    """``S_yu S_u^-1`` for every frequency (Hermitian ``S_u``)."""
    return np.conj(np.linalg.solve(S_u, np.conj(S_yu).transpose(0, 2, 1))).transpose(0, 2, 1)


def _check_input_spectrum(S_u, w, name):
    ev = np.linalg.eigvalsh(S_u)
    bad = ev[:, 0] <= SINGULAR_INPUT * np.maximum(ev[:, -1], 1e-300)
    if bad.any():
        raise NotExcitingError(f"{name}: the input spectrum is (nearly) singular at "
                               f"{int(bad.sum())} frequencies (first w = {w[bad][0]:.4g}); "
                               "the inputs do not excite them independently: choose other "
                               "frequencies or a richer input")


@serial_blas
@checked_call
def spa(data, window=None, w=None):
    """Spectral-analysis estimate of the frequency response (MATLAB ``spa``).

    Parameters
    ----------
    data : IOData
        Uniformly sampled, detrended record (several experiments are pooled).
    window : int, optional
        Lag-window size ``γ`` (Hann). Default ``min(N/10, 30)`` (MATLAB's):
        a larger window resolves sharper resonances at the price of variance.
    w : array_like, optional
        Frequencies in rad per time unit, in ``(0, π/dt]``. Default
        ``(1..128)/128 π/dt``.

    Returns
    -------
    FRData
        ``response`` (n_freq, ny, nu), ``std`` (its asymptotic standard
        deviation), ``coherence`` (n_freq, ny), ``dt`` of the data.

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, no input, bad frequencies.
    TooFewSamplesError
        The window is not shorter than the record (or the record has fewer
        than 20 samples, which leaves no default window).
    NotExcitingError
        The input spectrum is singular at a requested frequency.

    Examples
    --------
    >>> import numpy as np, subid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(4000)
    >>> y = np.convolve(u, 0.5 ** np.arange(20))[:4000]
    >>> g = subid.spa(subid.IOData(u, y), w=[0.5, 1.0])
    >>> exact = 1 / (1 - 0.5 * np.exp(-1j * np.array([0.5, 1.0])))
    >>> bool(np.all(np.abs(g.response[:, 0, 0] - exact) < 0.1 * np.abs(exact)))
    True
    """
    _check(data, "spa")
    # the spectra of the channels scaled as by _unit_scaled (exact powers of two), applied
    # to the lagged products block by block rather than to a copy of the record
    fu, fy = _unit_factors(data, "spa")
    back = fu[None, :] / fy[:, None]
    N = data.n_samples
    if window is None:
        window = default_window_size(N)
        if window < 2:
            raise TooFewSamplesError(f"spa: {N} samples are too few for the default lag "
                                     "window min(N/10, 30); pass window=... or more data")
    window = check_int(window, "window", minimum=1)
    if window >= N:
        raise TooFewSamplesError(f"spa: the lag window ({window}) must be shorter than the "
                                 f"record ({N} samples)")
    dt = float(data.dt)
    if w is None:
        w = np.arange(1, N_FREQUENCIES + 1) / N_FREQUENCIES * math.pi / dt
    w = FRData(w, np.zeros(np.size(w)), dt).w           # validated frequencies
    ny, nu = data.n_outputs, data.n_inputs
    R = _covariances(data, window, np.concatenate([fy, fu]))
    tau = np.arange(window + 1)
    lag_w = 0.5 * (1 + np.cos(math.pi * tau / window))
    # Φ(ω) = W(0) R(0) + Σ_{τ>=1} W(τ) (R(τ) e^{-iωτ} + R(τ)^T e^{iωτ})
    E = np.exp(-1j * np.outer(w * dt, tau[1:]))                      # (K, γ)
    WR = lag_w[1:, None, None] * R[1:]
    Phi = lag_w[0] * R[0][None] + np.einsum("kt,tab->kab", E, WR) \
        + np.einsum("kt,tba->kab", np.conj(E), WR)
    Phi_y, Phi_yu, Phi_u = Phi[:, :ny, :ny], Phi[:, :ny, ny:], Phi[:, ny:, ny:]
    _check_input_spectrum(Phi_u, w, "spa")
    G = _solve_right(Phi_yu, Phi_u)
    Phi_v = np.real(np.diagonal(Phi_y - G @ np.conj(Phi_yu).transpose(0, 2, 1),
                                axis1=1, axis2=2))
    if (Phi_v <= 0).any():
        bad = np.flatnonzero((Phi_v <= 0).any(axis=1))
        warnings.warn(f"spa: the lag window ({window} lags) is too short to resolve the "
                      f"response at {bad.size} of {w.size} frequencies (first w = "
                      f"{w[bad[0]]:.4g}): the estimated noise spectrum is not positive "
                      "there and their std is 0; pass a larger window=...",
                      ResolutionWarning, stacklevel=2)
        Phi_v = np.maximum(Phi_v, 0.0)
    power_y = np.maximum(np.real(np.diagonal(Phi_y, axis1=1, axis2=2)), 1e-300)
    coherence = np.clip(1.0 - Phi_v / power_y, 0.0, 1.0)
    eye = np.broadcast_to(np.eye(nu), Phi_u.shape)
    inv_u = np.real(np.diagonal(np.linalg.solve(Phi_u, eye), axis1=1, axis2=2))  # [Φ_u^-1]_jj
    c_w = lag_w[0] ** 2 + 2 * np.sum(lag_w[1:] ** 2)
    std = np.sqrt(c_w / N * Phi_v[:, :, None] * np.maximum(inv_u, 0.0)[:, None, :])
    return FRData(w, G * back, dt, std=std * back, coherence=coherence,
                  input_names=data.input_names,
                  output_names=data.output_names)


def _spectra(data):
    """DFTs of every experiment (all of one length), bins 0..L-1: (E, L, ny), (E, L, nu)."""
    lengths = {b - a for a, b in data.experiment_ranges}
    if len(lengths) != 1:
        raise DataError("etfe: the experiments have different lengths "
                        f"({sorted(lengths)}); their DFT bins differ. Estimate each one "
                        "separately or cut them to one length")
    Y = np.stack([np.fft.fft(data.y[a:b], axis=0) for a, b in data.experiment_ranges])
    U = np.stack([np.fft.fft(data.u[a:b], axis=0) for a, b in data.experiment_ranges])
    return Y, U


def _smooth(P, weights):
    """``Σ_l weights[l] P[(k + l - M) mod L]`` for every bin ``k`` (axis 0)."""
    M = (weights.size - 1) // 2
    out = np.zeros_like(P)
    for l, weight in enumerate(weights):
        out += weight * np.roll(P, M - l, axis=0)
    return out


@serial_blas
@checked_call
def etfe(data, smoothing=None):
    """Empirical transfer-function estimate (MATLAB ``etfe``), optionally smoothed.

    Parameters
    ----------
    data : IOData
        Uniformly sampled, detrended record; several experiments of the same
        length are pooled bin by bin.
    smoothing : int, optional
        Half-width ``M`` (in DFT bins) of the Hann frequency window. None: the
        raw ratio ``Y_k / U_k`` (one input, or as many experiments as inputs;
        no standard deviation or coherence then).

    Returns
    -------
    FRData
        At the DFT frequencies ``2 π k / (L dt)``, ``k = 1 .. floor(L/2)``
        (``L`` the experiment length); ``std`` and ``coherence`` when smoothed.

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, no input, experiments of
        different lengths, several inputs without smoothing or experiments.
    TooFewSamplesError
        Fewer than 4 samples per experiment, or a smoothing window wider than
        the record.
    NotExcitingError
        The input has no power at some frequency (raw estimate) or the
        smoothed input spectrum is singular.

    Examples
    --------
    >>> import numpy as np, subid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(1024)
    >>> y = np.convolve(u, [1.0, 0.5])[:1024]
    >>> g = subid.etfe(subid.IOData(u, y), smoothing=4)
    >>> bool(np.median(np.abs(g.response[:, 0, 0] - (1 + 0.5 * np.exp(-1j * g.w)))) < 0.05)
    True
    """
    _check(data, "etfe")
    data, back = _unit_scaled(data, "etfe")
    Y, U = _spectra(data)
    n_exp, L, nu = U.shape
    if L < 4:
        raise TooFewSamplesError(f"etfe: {L} samples per experiment are too few")
    dt = float(data.dt)
    k = np.arange(1, L // 2 + 1)
    w = 2 * math.pi * k / (L * dt)
    names = dict(input_names=data.input_names, output_names=data.output_names)
    if smoothing is None:
        if n_exp < nu:
            raise DataError(f"etfe: {nu} inputs need smoothing=... (or at least {nu} "
                            "experiments) to separate their responses")
        Uk, Yk = U[:, k], Y[:, k]                                   # (E, K, nu / ny)
        S_u = np.einsum("ekj,ekl->kjl", Uk, np.conj(Uk))
        S_yu = np.einsum("eki,ekl->kil", Yk, np.conj(Uk))
        _check_input_spectrum(S_u, w, "etfe")
        return FRData(w, _solve_right(S_yu, S_u) * back, dt, **names)
    M = check_int(smoothing, "smoothing", minimum=1)
    if 2 * M + 1 > L:
        raise TooFewSamplesError(f"etfe: the smoothing window (2 x {M} + 1 bins) is wider "
                                 f"than the record ({L} bins)")
    offsets = np.arange(-M, M + 1)
    weights = 0.5 * (1 + np.cos(math.pi * offsets / (M + 1)))
    weights /= weights.sum()
    ny = data.n_outputs
    Z = np.concatenate([Y, U], axis=2)                               # (E, L, ny + nu)
    # per-bin cross-periodograms summed over experiments, smoothed over bins k + l
    # (circularly: bin -k is the conjugate of bin k)
    P = np.einsum("eka,ekb->kab", Z, np.conj(Z))
    S = _smooth(P, weights)[k]
    S_u, S_yu, S_y = S[:, ny:, ny:], S[:, :ny, ny:], S[:, :ny, :ny]
    S_u2 = _smooth(P[:, ny:, ny:], weights ** 2)[k]
    _check_input_spectrum(S_u, w, "etfe")
    G = _solve_right(S_yu, S_u)
    # Σ_l w_l |Y - G_k U|^2 = diag(S_y - G_k S_uy), with G_k = S_yu S_u^-1
    power = np.maximum(np.real(np.diagonal(S_y, axis1=1, axis2=2)), 1e-300)
    resid = np.clip(np.real(np.diagonal(S_y - G @ np.conj(S_yu).transpose(0, 2, 1),
                                        axis1=1, axis2=2)), 0.0, None)
    Su_inv_Su2 = np.linalg.solve(S_u, S_u2)
    dof = np.real(np.trace(Su_inv_Su2, axis1=1, axis2=2))
    phi_v = resid / np.maximum(1.0 - dof, 1e-12)[:, None]
    spread = np.real(np.diagonal(np.linalg.solve(S_u, Su_inv_Su2.conj().transpose(0, 2, 1))
                                 .conj().transpose(0, 2, 1), axis1=1, axis2=2))
    std = np.sqrt(phi_v[:, :, None] * np.maximum(spread, 0.0)[:, None, :])
    coherence = np.clip(1.0 - resid / power, 0.0, 1.0)
    return FRData(w, G * back, dt, std=std * back, coherence=coherence, **names)
