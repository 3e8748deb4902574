"""The sandwich ("robust") covariance of output-error estimates under coloured noise.

An output-error estimate minimises ``Σ_t ε(t, θ)^T W ε(t, θ)`` with ``ε = y - G(q, θ) u``.
In open loop the disturbance ``v = y - G(q, θ0) u`` is independent of the input but, the
noise model being fixed to 1, it need not be white. Linearised at the estimate (Ljung,
*System Identification*, 2nd ed., 1999, Sec. 9.3, eqs. (9.40)-(9.42), the output-error
case of Theorem 9.2; Söderström and Stoica, *System Identification*, 1989, Sec. 7.5),

    θ̂ - θ0 ≈ R^-1 Σ_t ψ(t) W v(t),       R = Σ_t ψ(t) W ψ(t)^T,

    Cov(θ̂) ≈ R^-1 Q R^-1,      Q = Σ_t Σ_s ψ(t) W r_v(t - s) W ψ(s)^T,

with ``ψ(t) = dŷ(t)/dθ`` and ``r_v(τ) = E v(t) v(t - τ)^T``. For white ``v`` (``r_v(τ) =
Λ δ(τ)``, ``W = Λ^-1``) ``Q = R`` and this is the classic ``R^-1`` (``λ [Σ ψ ψ^T]^-1``
for one output); for coloured ``v`` the classic form understates the spread (by a
factor up to 2.9 in standard deviation on a second-order plant with process noise,
bench/sandwich_coverage.md).

``r_v`` is estimated from the residuals for ``|τ| <= M`` and tapered by the Bartlett lag
window ``w(τ) = 1 - |τ| / (M + 1)``, the weighting of Newey and West (1987, *Econometrica*
55, 703-708), whose heteroskedasticity-and-autocorrelation-consistent estimate is
positive semi-definite: the biased sample autocovariance is a positive semi-definite
sequence, the Bartlett window's transform (the Fejér kernel) is non-negative, so their
product is again positive semi-definite (Schur's product theorem) and so is ``Q``. The
lag ``M`` is chosen where the residual autocorrelation has died out by the automatic
windowing rule of Madras and Sokal (1988, *J. Stat. Phys.* 50, 109-186): the least ``M``
with ``M >= c τ_int(M)``, ``τ_int(M) = 1 + 2 Σ_{τ=1}^{M} |ρ(τ)|`` (``c = 5``, absolute
values so that an oscillating autocorrelation is not cancelled, each less the level
``sqrt(ny / N)`` of the estimate of a zero one), at most ``N / 10`` and
:data:`MAX_LAG`. White residuals give ``M = 5-6`` at ``N = 1000`` (the sandwich is then
the classic covariance up to a little estimation noise), an AR(1) disturbance with pole
0.84 ``M ≈ 60`` (34-100 over 20 seeds).

``Q`` is formed as ``Ψ^T (K ⋆ Ψ)``: each column of the Jacobian filtered by the windowed
autocovariance ``k(τ) = w(τ) r̂(τ)``, never the ``N x N`` Toeplitz matrix. With ``S =
Σ_t Z(t)^T H(t)``, ``H(t) = k(0) Z(t) / 2 + Σ_{τ=1}^{M} k(τ) Z(t - τ)`` (a causal
filter: a Jacobian formed in pieces needs the last ``M`` rows of the piece before),
``Q = S + S^T``. Filtering stops at the boundaries of the segments (experiments, or the
windows of a long record): their disturbances are not correlated. The nuisance
parameters (initial states) are eliminated exactly: ``Z`` is the Jacobian with their
columns projected out, taken in the orthonormal coordinates of the classic factor
(``Z = Q2``, the trailing columns of ``Ψ R^-1``), so that the meat ``Q2^T T Q2`` is the
identity for white residuals and the factor ``R22^-1 S_M`` (``S_M S_M^T`` the meat)
reduces to the classic ``R22^-1``. A Jacobian formed in pieces whose Gram matrix is well
conditioned gets the meat ``Ψ^T T Ψ`` of all its columns in the Gram matrix's pass, the
projection ``(R^-T Ψ^T T Ψ R^-1)`` trailing block after it (the same matrix).

Short windows (``M <=`` :data:`_DIRECT_LAGS`) are applied term by term, longer ones by
FFT in blocks of rows: the meat costs ``O(N d min(M, log N))`` beside the Jacobian (a
2 x 2 order-4 model, 2e5 samples: 3.3 s against 0.7 s for the classic covariance).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

__all__ = ["MAX_LAG", "WINDOW_FACTOR", "autocovariance", "choose_lag", "bartlett",
           "LaggedMeat", "psd_sqrt", "describe"]

#: The largest lag of the residual autocovariance the sandwich reads (the filtering
#: costs ``O(N d M)``).
MAX_LAG = 250

#: Windows up to this many lags are applied term by term (``M`` multiply-adds of the
#: Jacobian), longer ones by FFT.
_DIRECT_LAGS = 8

#: ``c`` of the automatic window ``M >= c τ_int(M)`` (Madras and Sokal 1988).
WINDOW_FACTOR = 5.0


def bartlett(lag: int) -> np.ndarray:
    """The Bartlett lag window ``w(τ) = 1 - τ / (M + 1)``, ``τ = 0..M`` (Newey and West
    1987)."""
    return 1.0 - np.arange(lag + 1) / (lag + 1.0)


def autocovariance(residuals, segments, max_lag, dof):
    """``r(τ) = Σ_t e(t) e(t - τ)^T / dof`` for ``τ = 0..max_lag``, the sums within each
    segment only.

    Parameters
    ----------
    residuals : ndarray, shape (N, ny)
    segments : list of (int, int)
        ``(start, stop)`` rows of each segment (experiment or window) of ``residuals``.
    max_lag : int
    dof : float or ndarray (ny, ny)
        The divisor (the degrees of freedom of the classic ``Λ``, so that ``r(0)`` is it).

    Returns
    -------
    ndarray, shape (max_lag + 1, ny, ny)
        ``r[τ, i, j] = E e_i(t) e_j(t - τ)``.
    """
    ny = residuals.shape[1]
    r = np.zeros((max_lag + 1, ny, ny))
    for a, b in segments:
        e = residuals[a:b]
        n = b - a
        if n == 0:
            continue
        nfft = scipy.fft.next_fast_len(n + max_lag + 1, real=True)
        F = scipy.fft.rfft(e, nfft, axis=0)
        c = scipy.fft.irfft(F[:, :, None] * F[:, None, :].conj(), nfft, axis=0)
        top = min(max_lag, n - 1)
        r[:top + 1] += c[:top + 1]
    return r / dof


def choose_lag(r, n_samples, max_lag=None):
    """The lag window's ``M``: the least ``M >= 1`` with ``M >= c (1 + 2 Σ_{τ<=M}
    a(τ))`` (Madras and Sokal 1988; :data:`WINDOW_FACTOR` ``c``), ``a(τ)`` the size of
    the residual autocorrelation at lag ``τ`` above the level of the estimate of a zero
    one (``||ρ(τ)||_F / sqrt(ny) - sqrt(ny / N)``, at least 0; ``ρ`` the autocovariance
    ``r`` scaled by its lag-0 variances); at most ``min(N / 10, MAX_LAG)`` and ``len(r)
    - 1``."""
    ny = r.shape[1]
    top = min(len(r) - 1, MAX_LAG if max_lag is None else max_lag, max(1, n_samples // 10))
    d = np.sqrt(np.maximum(np.diagonal(r[0]), 1e-300))
    rho = r[1:top + 1] / d[None, :, None] / d[None, None, :]
    # above the level of an estimate of zero correlation (sqrt(ny / N)): the noise of
    # the estimates alone would else add about that much per lag to the sum
    a = np.maximum(np.sqrt(np.sum(rho ** 2, axis=(1, 2)) / ny) - np.sqrt(ny / n_samples),
                   0.0)
    tau = 1.0 + 2.0 * np.cumsum(a)
    lags = np.arange(1, top + 1)
    ok = np.flatnonzero(lags >= WINDOW_FACTOR * tau)
    return int(lags[ok[0]]) if ok.size else int(top)


class LaggedMeat:
    """The meat ``Q = Σ_t Σ_s Z(t)^T k(t - s) Z(s)`` of the sandwich, the rows of ``Z``
    given a block at a time in order (a Jacobian formed in pieces).

    Parameters
    ----------
    kernel : ndarray, shape (M + 1, ny, ny)
        ``k(τ) = w(τ) r(τ)`` for ``τ >= 0`` (``k(-τ) = k(τ)^T``).
    segments : list of (int, int)
        The ``(start, stop)`` rows of the segments; no filtering across their boundaries.
    width : int
        The columns of ``Z``.
    """

    def __init__(self, kernel, segments, width):
        self.kernel = np.asarray(kernel, dtype=float)
        self.lag = self.kernel.shape[0] - 1
        self.starts = {int(a) for a, _ in segments}
        self.stops = sorted(int(b) for _, b in segments)
        self.S = np.zeros((width, width))
        self.tail = None
        self.pos = 0

    def add(self, Z):
        """Rows ``Z`` (shape (rows, ny, width)) following those added before."""
        while Z.shape[0]:
            if self.pos in self.starts:
                self.tail = None
            stop = next(b for b in self.stops if b > self.pos)
            part, Z = Z[:stop - self.pos], Z[stop - self.pos:]
            self._add(part)
            self.pos += part.shape[0]

    def _add(self, part):
        n, ny, width = part.shape
        P = np.ascontiguousarray(part.transpose(1, 0, 2))       # (ny, n, width)
        H = 0.5 * np.einsum("ij,jtd->itd", self.kernel[0], P)
        if self.lag >= 1:
            X = P if self.tail is None or self.tail.shape[1] == 0 else \
                np.concatenate([self.tail, P], axis=1)
            h = X.shape[1] - n
            H += self._filtered(X, h, n)
            self.tail = np.array(X[:, -self.lag:])
        for i in range(ny):
            self.S += P[i].T @ H[i]

    def _filtered(self, X, h, n):
        """``Σ_{τ=1}^{M} k(τ) X(t - τ)`` for the rows ``t = h .. h + n - 1`` of ``X``
        (shape (ny, rows, width); rows before 0 taken as zero): term by term for short
        windows, else by FFT in blocks of rows (overlap-save, ``M`` rows of history a
        block)."""
        k, M = self.kernel, self.lag
        ny, _, width = X.shape
        out = np.zeros((ny, n, width))
        if M <= _DIRECT_LAGS:
            for tau in range(1, M + 1):
                lo = max(0, tau - h)          # the first row with a source row
                if lo >= n:
                    break
                for i in range(ny):
                    for j in range(ny):
                        if k[tau, i, j] != 0.0:
                            out[i, lo:] += k[tau, i, j] * X[j, h - tau + lo:h - tau + n]
            return out
        taps = k.copy()
        taps[0] = 0.0
        block = max(8 * M, 8192)
        spectra = {}
        for s in range(0, n, block):
            e = min(s + block, n)
            a = max(0, h + s - M)
            seg = X[:, a:h + e]
            nfft = scipy.fft.next_fast_len(seg.shape[1] + M + 1, real=True)
            if nfft not in spectra:
                spectra[nfft] = scipy.fft.rfft(taps, nfft, axis=0)
            Y = scipy.fft.irfft(np.einsum("fij,jfd->ifd", spectra[nfft],
                                          scipy.fft.rfft(seg, nfft, axis=1)), nfft, axis=1)
            out[:, s:e] = Y[:, h + s - a:h + e - a]
        return out

    def value(self):
        """``Q = S + S^T``."""
        return self.S + self.S.T


def psd_sqrt(G: np.ndarray) -> np.ndarray:
    """``L`` with ``L L^T = G`` for a symmetric positive semi-definite ``G`` (Cholesky
    when it is definite, else a symmetric square root from its eigenvalues, negative
    rounding clipped)."""
    G = 0.5 * (G + G.T)
    try:
        return np.linalg.cholesky(G)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(G)
        return vecs * np.sqrt(np.maximum(vals, 0.0))


def describe(lag: int) -> str:
    """The ``method`` words of a sandwich covariance with lag window ``M = lag``."""
    return (f"sandwich R^-1 Q R^-1 for coloured disturbances (Ljung 1999, eqs. 9.40-9.42; "
            f"Bartlett window M = {lag}, Newey and West 1987)")
