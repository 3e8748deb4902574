"""The batch output-error regression of B, D, x0 from fixed-size lagged statistics.

:func:`subid.methods.dt._regression.fit_b_d_x0` solves, for given (A, C) and output
weights w (1 / standard deviation of each output),

    min  sum_t sum_i w_i^2 (y_i(t) - c_i S(t) [x0; vec B] - (u(t)^T ⊗ e_i^T) vec D)^2,

    S(0) = [I, 0],   S(t+1) = A S(t) + [0, u(t)^T ⊗ I].

Its normal equations are quadratic forms of the data with an (A, C)-dependent
kernel. :class:`LaggedStatistic` keeps, for a stream of N samples, the lagged
products of ``z = [u; y]`` for lags 0..L,

    G(d) = sum_{s=0}^{N-1-d} z(s) z(s+d)^T,

the first L + 1 samples and the last L + 1 samples (ring buffer): a size that
does not grow with N. (Beyond lag 0 only the rows of u are used, so only
those are kept.) :func:`normal_equations` evaluates the normal equations
of the regression exactly from them, for any stable A given later, up to the
terms in ``A^k`` with k > L (below rounding once ``|A^L|`` is; exact for any
stable A while N <= L + 1).

Derivation. Let ``ũ = [e; u]`` with e an impulse at s = -1 (``e(s) = [s = -1]``):
then ``S(t) = sum_{l>=0} A^l (ũ(t-1-l)^T ⊗ I)`` (the x0 columns are the
response to e). With ``Q = C^T diag(w^2) C`` and every signal zero outside
the record, the weighted Gram matrix of the S columns is

    sum_{t<N} S(t)^T Q S(t) = sum_{t in Z} S(t)^T Q S(t) - sum_{t>=N} S(t)^T Q S(t).

In the first sum, column (j, m) of S(t) is ``sum_l A^l e_m ũ_j(t-1-l)``, so
the entry [(j, m), (j', m')] is ``sum_{l,l'} (A^l)^T Q A^{l'} [m, m']
c_jj'(l - l')`` with ``c_jj'(d) = sum_s ũ_j(s) ũ_j'(s+d)``. Summing over the
pairs of equal difference d >= 0 gives ``A^{dT} W`` with W the Gramian
``W = A^T W A + Q`` (and ``W A^{|d|}`` for d < 0), so

    sum_{t in Z} S^T Q S = X + X^T - c(0) ⊗ W,   X = sum_{d=0}^{L} c(d) ⊗ A^{dT} W.

For t >= N the input is zero, ``S(t) = A^{t-N} S(N)``, so the second sum is
``S(N)^T W S(N)``, with S(N) from the last L samples. The input and output
columns need no correction (they are zero for t >= N):

    sum_t w_i^2 (c_i S(t))_{(j,m)} u_k(t) = w_i^2 sum_{l>=0} (C A^l)[i, m] c_{j,u_k}(l+1),

likewise with y_i, and the u/y blocks are G(0). The lagged products of the
impulse are ``c_ee(d) = [d = 0]``, ``c_{e,z}(d) = z(d-1)`` (the first samples),
``c_{z,e}(d) = 0`` for d >= 0.
"""

from __future__ import annotations

import copy

import numba
import numpy as np
import scipy.fft
import scipy.linalg

from subid.methods.dt._regression import parameter_count

#: Samples are buffered and added in blocks of this many by FFT (O(p^2 log L)
#: per sample instead of O(L p^2)); a model request adds the rest.
BLOCK = 256
#: A remainder of at least this many samples is added by FFT too, a shorter
#: one sample by sample (:func:`lag_update`).
FFT_MIN_SAMPLES = 64


@numba.njit(cache=True, nogil=True)
def lag_update(G0, G, ring, head, z, count):  # pragma: no cover - compiled
    """Add the samples ``z`` (T, p) to the lagged products.

    ``G0`` (p, p) is ``sum z z^T``; ``G`` (L + 1, nu, p) holds the input rows
    of the lagged products, ``G[d] = sum_s u(s) z(s+d)^T`` (the only ones
    the regression needs beyond lag 0). ``ring`` (L + 1, p) holds the last
    L + 1 samples (sample k in row ``k % (L + 1)``), ``head`` (L + 1, p) the
    first L + 1; ``count`` is the number of samples before ``z``. Returns the
    new count. The sums are accumulated sample by sample, so the result does
    not depend on how the stream is cut into chunks (bit for bit).
    """
    size = G.shape[0]
    nu = G.shape[1]
    p = z.shape[1]
    for t in range(z.shape[0]):
        pos = count % size
        for a in range(p):
            ring[pos, a] = z[t, a]
        if count < size:
            for a in range(p):
                head[count, a] = z[t, a]
        for a in range(p):
            za = z[t, a]
            for b in range(p):
                G0[a, b] += za * z[t, b]
        top = min(count, size - 1)
        for d in range(top + 1):
            r = pos - d
            if r < 0:
                r += size
            for a in range(nu):
                za = ring[r, a]
                for b in range(p):
                    G[d, a, b] += za * z[t, b]
        count += 1
    return count


def lag_update_reference(G0, G, ring, head, z, count):
    """Plain-numpy reference of :func:`lag_update` (same operations)."""
    size, nu = G.shape[0], G.shape[1]
    for t in range(z.shape[0]):
        pos = count % size
        ring[pos] = z[t]
        if count < size:
            head[count] = z[t]
        G0 += np.outer(z[t], z[t])
        for d in range(min(count, size - 1) + 1):
            G[d] += np.outer(ring[(pos - d) % size][:nu], z[t])
        count += 1
    return count


class LaggedStatistic:
    """Lagged products of a stream ``z = [u; y]`` for lags 0..``lags`` (fixed size).

    Attributes
    ----------
    G0 : ndarray (p, p)
        ``sum z z^T``.
    G : ndarray (lags + 1, n_inputs, p)
        The input rows of the lagged products, ``sum_s u(s) z(s+d)^T``.
    ring, head : ndarray (lags + 1, p)
    count : int
    """

    def __init__(self, n_inputs: int, n_outputs: int, lags: int):
        p = n_inputs + n_outputs
        self.n_inputs, self.n_outputs, self.lags = n_inputs, n_outputs, lags
        self.G0 = np.zeros((p, p))
        self.G = np.zeros((lags + 1, n_inputs, p))
        self.ring = np.zeros((lags + 1, p))
        self.head = np.zeros((lags + 1, p))
        self.count = 0                  # samples added to the sums
        self.sum_y = np.zeros(n_outputs)
        self.pending = np.zeros((BLOCK, p))     # samples not yet added
        self.n_pending = 0

    @property
    def n_samples(self) -> int:
        return self.count + self.n_pending

    def update(self, u, y, kernel=lag_update) -> None:
        """Add samples: buffered, and added to the sums in blocks of
        :data:`BLOCK` samples (at fixed sample indices, so that the sums do
        not depend on how the stream is cut into chunks); ``kernel`` other
        than the compiled one adds every sample at once (for the tests)."""
        if u.shape[0] == 1 and kernel is lag_update:    # one sample: no stacked copy
            row = self.pending[self.n_pending]
            row[:self.n_inputs] = u[0]
            row[self.n_inputs:] = y[0]
            self.n_pending += 1
            if self.n_pending == BLOCK:
                self.flush()
            return
        z = np.hstack([u, y])
        if kernel is not lag_update:
            self.flush(kernel)
            self._add(np.ascontiguousarray(z), kernel)
            return
        k = 0
        T = z.shape[0]
        while k < T:
            take = min(BLOCK - self.n_pending, T - k)
            self.pending[self.n_pending:self.n_pending + take] = z[k:k + take]
            self.n_pending += take
            k += take
            if self.n_pending == BLOCK:
                self.flush()

    def flush(self, kernel=lag_update) -> None:
        """Add the buffered samples to the sums (only when a block is full, or by a
        reader on its own copy, :meth:`flushed`: the blocks stay at fixed sample
        indices)."""
        if self.n_pending:
            z = self.pending[:self.n_pending].copy()
            self.n_pending = 0
            self._add(z, kernel)

    def _add(self, z, kernel) -> None:
        if z.shape[0] >= FFT_MIN_SAMPLES and kernel is lag_update:
            self._update_fft(z)
        else:
            self.count = int(kernel(self.G0, self.G, self.ring, self.head, z, self.count))
        for row in z[:, self.n_inputs:]:     # the same order for every chunking
            self.sum_y += row

    def _update_fft(self, z) -> None:
        """:func:`lag_update` for a long chunk by FFT cross-correlation: with
        ``E = [L samples before the chunk (zeros before the stream); z]``,
        ``G(d) += sum_t E(L + t - d) z(t)^T``, the correlation of E and z at
        ``L - d`` (no wrap-around: the FFT length is at least L + T). Equal to
        the sample-by-sample sums to rounding (relative to the signal energy)."""
        L = self.lags
        size = L + 1
        T, p = z.shape
        prev = min(self.count, L)
        E = np.zeros((L + T, p))
        if prev:
            E[L - prev:L] = self.last(prev)
        E[L:] = z
        nfft = scipy.fft.next_fast_len(L + T, real=True)
        nu = self.n_inputs
        FE = scipy.fft.rfft(E[:, :nu], nfft, axis=0)
        FZ = scipy.fft.rfft(z, nfft, axis=0)
        X = scipy.fft.irfft(FE[:, :, None] * FZ[:, None, :].conj(), nfft, axis=0)
        self.G += X[L::-1]
        self.G0 += z.T @ z
        if self.count < size:
            k = min(size - self.count, T)
            self.head[self.count:self.count + k] = z[:k]
        keep = min(T, size)
        idx = (self.count + T - keep + np.arange(keep)) % size
        self.ring[idx] = z[T - keep:]
        self.count += T

    def flushed(self) -> "LaggedStatistic":
        """The statistic with its buffered samples added to the sums: itself when none
        are buffered, else a flushed copy. Readers use it, so that reading (a model, a
        state) never moves the block borders of the sums, which then would differ at
        rounding from those of a stream that was not read."""
        if not self.n_pending:
            return self
        out = copy.deepcopy(self)
        out.flush()
        return out

    def arrays(self) -> dict:
        return {"lag_G0": self.G0, "lag_G": self.G, "lag_ring": self.ring,
                "lag_head": self.head, "lag_sum_y": self.sum_y, "lag_pending": self.pending}

    def output_weights(self) -> np.ndarray:
        """1 / standard deviation of each output (population), as
        :func:`subid.methods.dt._subspace.output_weights` on the whole record."""
        stat = self.flushed()
        N = stat.count
        nu = self.n_inputs
        mean = stat.sum_y / N
        var = np.diag(stat.G0)[nu:] / N - mean ** 2
        std = np.sqrt(np.maximum(var, 0.0))
        return 1.0 / np.where(std > 0, std, 1.0)

    def last(self, k: int) -> np.ndarray:
        """The last ``k`` samples (k <= min(count, lags + 1)), oldest first."""
        size = self.G.shape[0]
        idx = (self.count - k + np.arange(k)) % size
        return self.ring[idx]

    def normal_equations(self, A, C, weights, *, feedthrough=True):
        """See :func:`normal_equations` (on :meth:`flushed`)."""
        return normal_equations(self.flushed(), A, C, weights, feedthrough=feedthrough)


def _impulse_augmented(stat: LaggedStatistic):
    """``cz (L + 1, 1 + p, 1 + p)``: lagged products of ``[e; u; y]`` (e the
    impulse at s = -1) for lags 0..L (rows of y beyond lag 0 left zero: the
    regression does not use them)."""
    L = stat.lags
    p = stat.n_inputs + stat.n_outputs
    N = stat.count
    cz = np.zeros((L + 1, 1 + p, 1 + p))
    nu = stat.n_inputs
    cz[:, 1:1 + nu, 1:] = stat.G          # the output rows beyond lag 0 are not needed
    cz[0, 1:, 1:] = stat.G0
    cz[0, 0, 0] = 1.0
    k = min(L, N)               # c_{e,z}(d) = z(d - 1), d = 1..L
    cz[1:k + 1, 0, 1:] = stat.head[:k]
    return cz


def normal_equations(stat: LaggedStatistic, A, C, weights, *, feedthrough=True):
    """Augmented normal matrix of the weighted output-error regression.

    Returns ``(N, truncation)``: N, (p + 1) square, is ``sum_i w_i^2 sum_t
    [phi_i(t); y_i(t)] [phi_i(t); y_i(t)]^T`` with the columns of
    :func:`subid.methods.dt._regression.regression_rows` (x0, vec B, vec D, y);
    ``truncation`` bounds the relative size of the neglected terms,
    ``|A^(L+1)|_2`` (0 while the stream has at most L + 1 samples).
    Requires a stable A (spectral radius below 1).
    """
    n = A.shape[0]
    nu, ny = stat.n_inputs, stat.n_outputs
    L = stat.lags
    N = stat.count
    nx, q, p = parameter_count(n, nu, ny, True, feedthrough)
    w2 = np.asarray(weights, dtype=float) ** 2
    Q = C.T @ (w2[:, None] * C)
    W = scipy.linalg.solve_discrete_lyapunov(A.T, Q)
    W = 0.5 * (W + W.T)
    powers = np.empty((L + 2, n, n))
    powers[0] = np.eye(n)
    for d in range(1, L + 2):
        powers[d] = powers[d - 1] @ A
    truncation = 0.0 if N <= L + 1 else float(np.linalg.norm(powers[L + 1], 2))
    cz = _impulse_augmented(stat)
    ju = 1 + nu                                   # channels of ũ = [e; u]
    cu = cz[:, :ju, :ju]
    # X = sum_d c(d) ⊗ A^{dT} W
    M = np.einsum("dba,bc->dac", powers[:L + 1], W)          # A^{dT} W
    X = np.einsum("djk,dmq->jmkq", cu, M).reshape(ju * n, ju * n)
    SS = X + X.T - np.kron(cu[0], W)
    # the end correction: S(N)^T W S(N), S(N) = [A^N, sum_s A^(N-1-s) (u(s)^T ⊗ I)]
    S_end = end_sensitivity(stat, A, powers, N)
    SS -= S_end.T @ W @ S_end
    out = np.zeros((p + 1, p + 1))
    out[:q, :q] = SS
    # cross terms with u(t) (D columns) and y(t): lags 1..L
    H = np.einsum("ia,lab->lib", C, powers[:L])            # C A^l, l = 0..L-1
    Hw = H * w2[None, :, None]
    cnext = cz[1:L + 1]                                    # c(l + 1), l = 0..L-1
    # S-y: sum_i w_i^2 sum_l H[l][i, m] c_{j, y_i}(l + 1)
    Sy = np.einsum("lim,lji->jm", Hw, cnext[:, :ju, 1 + nu:]).reshape(-1)
    out[:q, p] = Sy
    if feedthrough:
        # S-D: [(j, m), (k, i)] = w_i^2 sum_l H[l][i, m] c_{j, u_k}(l + 1)
        SD = np.einsum("lim,ljk->jmki", Hw, cnext[:, :ju, 1:1 + nu]).reshape(q, nu * ny)
        out[:q, q:p] = SD
        G0 = stat.G0
        DD = np.kron(G0[:nu, :nu], np.diag(w2))            # [(k, i), (k', i')]
        out[q:p, q:p] = DD
        out[q:p, p] = (G0[:nu, nu:] * w2[None, :]).reshape(-1)      # [(k, i)]
    out[p, p] = float(np.sum(w2 * np.diag(stat.G0)[nu:]))
    out = np.triu(out) + np.triu(out, 1).T
    return out, truncation


def end_sensitivity(stat: LaggedStatistic, A, powers, t_end: int) -> np.ndarray:
    """``S(t_end) = [A^t_end, sum_{s<t_end} A^(t_end-1-s) (u(s)^T ⊗ I)]`` from the
    last samples (t_end = count or count - 1), the terms beyond L lags dropped."""
    n = A.shape[0]
    nu = stat.n_inputs
    L = stat.lags
    S = np.zeros((n, n + n * nu))
    S[:, :n] = powers[t_end] if t_end <= L + 1 else np.linalg.matrix_power(A, t_end)
    back = stat.count - t_end                   # samples after t_end (0 or 1)
    k = min(stat.count, L + 1)
    z = stat.last(k)[: k - back] if back else stat.last(k)
    u = z[:, :nu]
    m = u.shape[0]
    lags = min(m, L + 1)
    # sum over the last `lags` inputs s = t_end - 1 - l, l = 0..lags-1
    for j in range(nu):
        acc = np.einsum("lab,l->ab", powers[:lags], u[m - 1 - np.arange(lags), j])
        S[:, n + j * n:n + (j + 1) * n] = acc
    return S
