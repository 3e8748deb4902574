"""B, D, x0 and the validation score of a candidate model from lag products.

The cross-validation of the order (:mod:`subid.methods.dt.selection`) fits B,
D, x0 for every candidate (A, C) on its training fold and scores the model by
its simulation fit on the validation block. Both are least-squares problems
whose data enter only through second moments: for a stable A the forced
response is, up to ``|A^L|``, a FIR of length L,

    y(t) = C A^t x0 + sum_{k=1..L} C A^(k-1) B u(t-k) + D u(t),

so the normal equations need the lag products of the record,

    Γ(e) = sum_s u(s) u(s+e)^T,   R(k) = sum_t y(t) u(t-k)^T,   Y = sum_t y(t) y(t)^T,

(e, k = 0..L), and its first and last L samples. These are computed once per
record (:class:`LagProducts`, by FFT: ``O(N log N)`` whatever L; for the folds of
the cross-validation, once per block and boundary, :func:`merged`) and shared by
every candidate order, horizon and estimator. Every sum below is a lag sequence
times powers of A; with ``A = V diag(λ) V^{-1}`` each is evaluated at the poles,
``sum_e c_e A^e = V diag(sum_e c_e λ^e) V^{-1}`` (:class:`_Modal`), and the infinite
sums of the Gramians in closed form (``sum_t λ_l^t λ_m^t = 1 / (1 - λ_l λ_m)``), so a
candidate costs ``O(L n)`` flops per sequence plus ``O(n^3)``, independent of N.
L is the smallest lag with ``ρ(A)^L`` below :data:`LAG_TOLERANCE` (rounding), or
``N - 1`` on a shorter record (where every lag is kept): the sums past the record
are then subtracted exactly, by ``A^N = V diag(λ^N) V^{-1}`` (below), so that the
products give the passes' values for every stable A whatever N (issue 21: the
records of the folds of 10^3 samples took the passes).

**Training fold** (the regression of :func:`subid.methods.dt._regression.fit_b_d_x0`,
parameters ``[x0; vec B; vec D]``, each output weighted by ``w_r``, ``W = diag w``).
With the state sensitivity ``X(t) = sum_{k=1..t} u(t-k)^T kron A^(k-1)``,
``Q = C^T W^2 C`` and ``P = sum_{t>=0} (A^t)^T Q A^t`` (the weighted observability
Gramian, ``P = A^T P A + Q``):

* ``sum_{t<N} X^T Q X = Γ(0) kron P + sum_{e>=1} [Γ(e) kron (A^e)^T P + Γ(e)^T kron P A^e]
  - X(N)^T P X(N)``: the sum over every t of the input zero-padded beyond the
  record is block Toeplitz in the lag products (with ``a = j-1``, ``b = k-1``,
  ``e = a - b``, the inner sum over b is P); the samples ``t >= N`` of that padded
  sum are the free response from ``X(N) = sum_{k=1..L+1} u(N-k)^T kron A^(k-1)``,
  which the last L + 1 samples give exactly;
* ``sum_t X^T C^T W^2 (u^T kron I) = sum_{k>=1} Γ(k) kron (C A^(k-1))^T W^2`` and
  ``sum_t X^T C^T W^2 y = sum_{k>=1} vec((C A^(k-1))^T W^2 R(k))``: no edge term
  (the D and y rows stop at N themselves);
* the D block ``Γ(0) kron W^2`` and ``vec(W^2 R(0))``;
* the x0 rows: ``sum_{t<N} (A^t)^T Q A^t = P - (A^N)^T P A^N``,
  ``sum_{t<N} (A^t)^T Q X(t) = sum_s u(s)^T kron (A^(s+1))^T P - (A^N)^T P X(N)``
  (s <= L; the terms ``t >= N`` are the free response from ``X(N)``),
  ``sum_t (A^t)^T C^T W^2 (u(t)^T kron I)`` and ``sum_t (A^t)^T C^T W^2 y(t)``
  over the first L + 1 samples.

The augmented normal matrix is solved by
:func:`subid.methods.dt._regression.solve_normal_equations` with the guards of the
modal path (the same problem it solves by a pass over the record).

**Validation score** (:func:`subid.methods.dt._scoring.simulation_fit`): per output r,
the error power ``sum_t (y_r - y_f,r)^2`` of the forced response ``y_f`` (zero initial
state) is ``Y_rr - 2 sum_k (R(k) G_k^T)_rr + (sum_t y_f y_f^T)_rr`` with the Markov
parameters ``G_0 = D``, ``G_k = C A^(k-1) B``; ``sum_t y_f y_f^T = C X C^T + C S_D +
S_D^T C^T + D Γ(0) D^T`` minus the free response after the record, where ``S_D =
sum_{k>=1} A^(k-1) B Γ(k) D^T`` and ``X = A X A^T + S`` with ``S = sum_{e>=0} A^e B Γ(e)
B^T + sum_{e>=1} B Γ(e)^T B^T (A^e)^T`` (the same block-Toeplitz sum). The
least-squares x0 (outputs weighted) involves the first L + 1 samples only: per
output, ``β_r = sum_{t<N} (A^t)^T c_r^T (y_r - y_f,r)(t)`` is ``sum_t (A^t)^T c_r^T y_r(t)
- sum_t (A^t)^T c_r^T D_r u(t) - sum_s (A^(s+1))^T P_r B u(s) + (A^N)^T P_r x_f(N)``
(``P_r`` the Gramian of output r, ``x_f(N)`` the forced state at the end), x0 solves
``(sum_r w_r^2 P_r') x0 = sum_r w_r^2 β_r`` with ``P_r' = P_r - (A^N)^T P_r A^N`` (the
sum over t < N), and the error power falls by ``2 x0^T β_r - x0^T P_r' x0``.

**Where it does not apply** the callers take the per-candidate passes: an unstable
A, one whose eigenvector matrix is ill-conditioned (:data:`MAX_EIGVEC_CONDITION`) or
whose L exceeds the lags kept (:data:`MAX_LAG`; those of a record merged from the
blocks of the folds, :func:`merged`, no further than the shortest block); a
regression or error power whose value the normal equations leave to rounding
(nearly exact fits, :data:`ROUNDING_GUARD`), where the passes are exact; a record
shorter than the decay of A over which ``ρ(A)^N`` exceeds :data:`EDGE_DECAY` (the sums
past its end would dominate); a score whose x0 Gramian has a condition number above
:data:`MAX_X0_CONDITION`; records of several experiments, of fewer than
:data:`MIN_SAMPLES` samples or of more inputs than lag products pay for
(:func:`worthwhile`: more than 8 on a short record).
"""

from __future__ import annotations

from functools import partial

import numpy as np
import scipy.fft
import scipy.linalg

from subid._kernel_args import frozen, read_only
from subid.methods.dt._lag_kernel import complex_eigenvectors, modal_form, normal_matrix, powers
from subid.methods.dt._lag_kernel import error_power as kernel_error_power
from subid.methods.dt._lapack import eig_real
from subid.methods.dt._regression import RESIDUAL_RECOMPUTE, solve_normal_equations

#: The key of a problem's cache that holds its record's lag products (a
#: cross-validation fold, :func:`subid.methods.dt.selection.score_horizon`).
LAG_PRODUCTS = "lag products"
#: ``ρ(A)^L`` (the spectral radius) below which the terms
#: past L lags are dropped: below rounding relative to the data.
LAG_TOLERANCE = 1e-16
#: Largest lag L used (the lag products are computed up to min(MAX_LAG, N - 1)).
MAX_LAG = 16384
#: Lags computed at once (:class:`LagProducts`, :func:`merged`): those of poles of radius
#: up to 0.991; the others up to MAX_LAG when a candidate first needs them.
FIRST_LAGS = 4096
#: Records shorter than this are not reduced to lag products (a pass over them costs
#: little).
MIN_SAMPLES = 256
#: Records shorter than this get lag products of their own (:func:`merged`).
MERGE_SAMPLES = 4096
#: Most input lag products per input sample, ``(L + 1) nu`` against ``N``, for which a
#: record is reduced to lag products (:func:`worthwhile`): they hold ``(L + 1) nu (nu +
#: ny)`` floats, and a candidate's quadratic forms cost ``O(L nu^2)`` against the direct
#: pass's ``O(N (nu + ny))``: past the bound (many inputs) the products would outweigh
#: the record many times over in memory (100 inputs, 3,000 samples: 8.9 GB traced for
#: the default call's folds) and in arithmetic. With at most 8 inputs every record of
#: MIN_SAMPLES or more qualifies.
PRODUCTS_PER_SAMPLE = 8
#: An error power below this fraction of the output's power is rounding-limited in
#: the quadratic form (cancellation): the direct pass computes it instead.
ROUNDING_GUARD = 1e-6


def worthwhile(n_samples, n_inputs, max_lag=MAX_LAG) -> bool:
    """Whether a record of ``n_samples`` samples and ``n_inputs`` inputs is reduced to
    lag products up to ``min(max_lag, n_samples - 1)``: at least :data:`MIN_SAMPLES`
    samples and at most :data:`PRODUCTS_PER_SAMPLE` input lag products per input
    sample."""
    lags = min(int(max_lag), n_samples - 1) + 1
    return n_samples >= MIN_SAMPLES and lags * n_inputs <= PRODUCTS_PER_SAMPLE * n_samples


def _cross_lags(A, B, nfft, max_lag):
    """``out[e, i, j]``: the inverse FFT of ``A[:, i] B[:, j]`` at lags 0..max_lag, one
    row ``i`` at a time (the products of every pair at once would hold ``nfft nu^2``
    values: 100 times the record at 100 inputs)."""
    out = np.empty((max_lag + 1, A.shape[1], B.shape[1]))
    for i in range(A.shape[1]):
        out[:, i, :] = scipy.fft.irfft(A[:, i:i + 1] * B, nfft, axis=0)[:max_lag + 1]
    return out


def correlations(u, y, max_lag):
    """``(Γ, R, Y)``: ``Γ[e] = sum_s u(s) u(s+e)^T`` (nu, nu), ``R[k] = sum_t y(t) u(t-k)^T``
    (ny, nu) for lags 0..max_lag (by FFT, the lag 0 terms directly) and ``Y = y^T y``."""
    N = u.shape[0]
    nfft = scipy.fft.next_fast_len(N + max_lag + 1, real=True)
    U = scipy.fft.rfft(u, nfft, axis=0)
    Uc = np.conj(U)
    Yf = scipy.fft.rfft(y, nfft, axis=0)
    G = _cross_lags(Uc, U, nfft, max_lag)
    R = _cross_lags(Yf, Uc, nfft, max_lag)
    G[0] = u.T @ u
    R[0] = y.T @ u
    return G, R, y.T @ y


def merged(blocks, records, groups):
    """:class:`LagProducts` of ``records``, each the concatenation of the consecutive
    ``blocks`` (IOData) whose indices ``groups`` lists, from one FFT per block and one
    per boundary between blocks instead of one per record: the lag sums of a
    concatenation are those of its blocks plus the products that straddle each
    boundary (:func:`straddle_correlations` of the samples either side). The first
    :data:`FIRST_LAGS` lags are computed at once, the others (up to each record's
    ``max_lag``) for all the records together when a candidate first needs them
    (:meth:`LagProducts.lags`), merged up to the length of the shortest block
    (``merged_lags``: a lag could straddle two boundaries), past it from the record's
    own products (:func:`correlations`, when a candidate first needs them). A record
    shorter than :data:`MERGE_SAMPLES` has its own (one FFT of a short record costs
    little, and its lags then reach all of it); one shorter than :data:`MIN_SAMPLES`,
    or of more inputs than lag products pay for (:func:`worthwhile`), None. None
    altogether when a block is shorter than a quarter of a record to merge."""
    out = [LagProducts(r.u, r.y) if r.n_samples < MERGE_SAMPLES
           and worthwhile(r.n_samples, r.n_inputs) else None for r in records]
    lengths = [b.n_samples for b in blocks]
    big = [k for k, r in enumerate(records) if r.n_samples >= MERGE_SAMPLES
           and worthwhile(r.n_samples, r.n_inputs)]    # lags up to N - 1 in the end
    if not big:
        return out
    records = [records[k] for k in big]
    groups = [groups[k] for k in big]
    # no lag past the shortest block (a lag could straddle two boundaries); blocks
    # shorter than a quarter of a record: none merged (each fold its own products)
    caps = [min(MAX_LAG, r.n_samples - 1, min(lengths)) for r in records]
    K = max(caps)
    if any(min(lengths) < min(MAX_LAG, r.n_samples // 4) for r in records):
        return None

    def sums_up_to(lags):
        sums = [correlations(b.u, b.y, lags) for b in blocks]
        straddle = [straddle_correlations(left.u[-lags:], right.u[:lags], right.y[:lags], lags)
                    for left, right in zip(blocks[:-1], blocks[1:])]
        out = []
        for group in groups:
            G = sum(sums[i][0] for i in group) + sum(straddle[i][0] for i in group[:-1])
            R = sum(sums[i][1] for i in group) + sum(straddle[i][1] for i in group[:-1])
            Y = sum(sums[i][2] for i in group)
            out.append((G, R, Y))
        return out

    first = min(K, FIRST_LAGS)
    kept = [LagProducts.from_sums(record.u, record.y, sums, cap)
            for record, cap, sums in zip(records, caps, sums_up_to(first))]
    pending = [first < K]                 # the merged lags past the first, not yet summed

    def extend(lp, L):
        if L <= lp.merged_lags and pending[0]:
            pending[0] = False            # every record's merged lags up to its cap, once
            for other, (G, R, _) in zip(kept, sums_up_to(K)):
                if other.G.shape[0] <= other.merged_lags:
                    other.G, other.R = G[:other.merged_lags + 1], R[:other.merged_lags + 1]
        if L >= lp.G.shape[0]:
            # past the shortest block (a pole too slow for the merged lags): the
            # record's own lag products up to its max_lag, by one FFT of it (the
            # same sums to rounding; issue 21: at 10^4 samples the stabilised fold
            # models of poles near 0.98 took a pass over their folds instead)
            lp.G, lp.R, _ = correlations(lp.u, lp.y, lp.max_lag)
        lp.extend = partial(extend, lp) if lp.G.shape[0] <= lp.max_lag else None

    for lp in kept:
        lp.merged_lags = lp.max_lag
        lp.max_lag = min(MAX_LAG, lp.n_samples - 1)
        lp.extend = partial(extend, lp) if lp.G.shape[0] <= lp.max_lag else None
    for k, lp in zip(big, kept):
        out[k] = lp
    return out


def straddle_correlations(left_u, right_u, right_y, max_lag):
    """``(Γ, R)`` of the pairs that straddle a boundary: ``Γ[e] = sum u(s) u(s+e)^T`` and
    ``R[k] = sum_t y(t) u(t-k)^T`` over the pairs with ``s`` (``t - k``) among the samples
    ``left_u`` just before it and ``s + e`` (``t``) among the samples just after it
    (``right_u``, ``right_y``), lags 0..max_lag: the cross-correlations of the two
    sides, each zero-padded to the other's length, by one FFT of each signal (the
    products of the window across the boundary minus those of its halves took three
    FFT correlations)."""
    K = left_u.shape[0]
    nfft = scipy.fft.next_fast_len(2 * K + max_lag + 1, real=True)
    # the left samples at 0..K-1 and the right ones at K..2K-1 of one time axis
    Lc = np.conj(scipy.fft.rfft(left_u, nfft, axis=0))
    Ru = scipy.fft.rfft(np.vstack([np.zeros_like(right_u), right_u]), nfft, axis=0)
    Ry = scipy.fft.rfft(np.vstack([np.zeros_like(right_y), right_y]), nfft, axis=0)
    G = _cross_lags(Lc, Ru, nfft, max_lag)
    R = _cross_lags(Ry, Lc, nfft, max_lag)
    G[0] = 0.0                          # no pair at lag 0 straddles the boundary
    R[0] = 0.0
    return G, R


def straddle_correlations_reference(left_u, right_u, right_y, max_lag):
    """Plain sums behind :func:`straddle_correlations` (the tests compare them)."""
    u = np.vstack([left_u, right_u])
    y = np.vstack([np.zeros((left_u.shape[0], right_y.shape[1])), right_y])
    K, nu = left_u.shape
    G = np.zeros((max_lag + 1, nu, nu))
    R = np.zeros((max_lag + 1, right_y.shape[1], nu))
    for e in range(1, max_lag + 1):
        s = np.arange(max(K - e, 0), K)          # s on the left, s + e on the right
        s = s[s + e < u.shape[0]]
        G[e] = u[s].T @ u[s + e]
        R[e] = y[s + e].T @ u[s]
    return G, R


def correlations_reference(u, y, max_lag):
    """Plain sums behind :func:`correlations` (the tests compare them)."""
    N, nu = u.shape
    ny = y.shape[1]
    G = np.zeros((max_lag + 1, nu, nu))
    R = np.zeros((max_lag + 1, ny, nu))
    for e in range(max_lag + 1):
        G[e] = u[:N - e].T @ u[e:]
        R[e] = y[e:].T @ u[:N - e]
    return G, R, y.T @ y


class LagProducts:
    """The lag products of one record (:func:`correlations`) up to ``max_lag``, and the
    record itself (its first and last samples enter the edge terms). The first
    :data:`FIRST_LAGS` lags are computed at once, the others when a candidate's poles
    first need them (:meth:`lags`)."""

    def __init__(self, u, y, max_lag=MAX_LAG):
        self.u = np.ascontiguousarray(u, dtype=float)
        self.y = np.ascontiguousarray(y, dtype=float)
        self.n_samples = self.u.shape[0]
        self.max_lag = max(min(int(max_lag), self.n_samples - 1), 0)
        self.G, self.R, self.Y = correlations(self.u, self.y, min(self.max_lag, FIRST_LAGS))
        self.extend = self._extend if self.max_lag > FIRST_LAGS else None

    def _extend(self, L=None):
        self.G, self.R, _ = correlations(self.u, self.y, self.max_lag)
        self.extend = None

    def lags(self, L):
        """``(Γ, R)`` for the lags 0..L (``L <= max_lag``), computing the lags past those
        kept so far first where needed (``extend(L)``)."""
        if L >= self.G.shape[0] and self.extend is not None:
            self.extend(L)
        return self.G[:L + 1], self.R[:L + 1]

    def kernel_arguments(self, L) -> tuple:
        """The lag products up to L and the record's edges as the kernels of
        :mod:`subid.methods.dt._lag_kernel` take them (read-only C-contiguous arrays: one
        compiled signature): the record's edges and the diagonal made once for all the
        lags held (the candidates of a fold share them)."""
        G, R = self.lags(L)              # the lags past those held, if needed
        held = self.__dict__.get("_kernel_arguments")
        if held is None or held[0] is not self.G:
            K, u = self.G.shape[0], self.u
            held = self._kernel_arguments = (self.G, read_only(
                u[::-1][:K], u[:K], self.y[:K]), frozen(np.diag(self.Y)))
        u_tail, u_head, y_head = (a[:L + 1] for a in held[1])
        # the lag products per call: a copy of the L + 1 lags asked at most (those of
        # every lag held would be K nu^2 floats per fold: 160 MB at 100 inputs)
        G, R = read_only(G.reshape(L + 1, -1), R.reshape(L + 1, -1))
        return G, R, held[2], u_tail, u_head, y_head, self.n_samples

    @classmethod
    def from_sums(cls, u, y, sums, max_lag):
        """The lag products of the record ``(u, y)`` whose lag sums ``(Γ, R, Y)`` are
        known up to ``min(max_lag, N - 1)`` or, with ``extend`` set on the result, up
        to fewer lags."""
        out = cls.__new__(cls)
        out.u = np.ascontiguousarray(u, dtype=float)
        out.y = np.ascontiguousarray(y, dtype=float)
        out.n_samples = out.u.shape[0]
        out.max_lag = max(min(int(max_lag), out.n_samples - 1), 0)
        G, R, out.Y = sums
        out.G, out.R = G[:out.max_lag + 1], R[:out.max_lag + 1]
        out.extend = None
        return out

    @classmethod
    def of_record(cls, record, max_lag=MAX_LAG):
        """The lag products of an IOData record of one experiment of at least
        :data:`MIN_SAMPLES` samples that is :func:`worthwhile`, else None."""
        if getattr(record, "n_experiments", 1) != 1 or \
                not worthwhile(record.n_samples, record.n_inputs, max_lag):
            return None
        return cls(record.u, record.y, max_lag)


#: Largest condition number of the eigenvector matrix of A for the modal evaluation
#: (its rounding errors grow with it: about 1e-10 relative at this bound).
MAX_EIGVEC_CONDITION = 1e6


#: Largest condition number of the weighted x0 Gramian ``sum_r w_r^2 P_r`` of a
#: validation score: past it the normal equations' rounding reaches the score (on
#: the DaISy CD_player_arm record, 1e-3 relative at orders 16-17 on blocks of 682
#: samples) and the pass, which factorises the rows, scores the candidate.
MAX_X0_CONDITION = 1e6
#: ``ρ(A)^N`` above which a record of N samples shorter than the decay of A is left to
#: the passes: the sums past its end, subtracted by ``A^N``, then dominate the sums
#: over the record and the difference loses digits (measured on the DaISy
#: CD_player_arm record: 0.06 points of fold score at an order-18 candidate whose
#: slowest pole had not decayed over the 455 samples of the block).
EDGE_DECAY = 1e-3


#: The last modal form computed (:meth:`_Modal.of`), as one ``(key, form)`` pair.
_LAST = [None]


class _Modal:
    """A stable, diagonalisable A in modal form, ``A = V diag(λ) V^{-1}``, and the
    lags ``lags`` after which ``ρ(A)^L`` is below :data:`LAG_TOLERANCE`; the powers
    ``λ^e`` (e = 0..L) evaluate every lag sum at the poles, ``sum_e c_e A^e = V
    diag(sum_e c_e λ^e) V^{-1}``, ``O(L n)`` per sequence instead of ``O(L n^3)`` for
    the powers of A (:mod:`subid.methods.dt._lag_kernel`)."""

    def __init__(self, lam, V, Wm, lags):
        self.lam, self.V, self.Wm = read_only(lam, V, Wm)    # as the kernels take them
        self.lags = lags
        self.radius = float(np.abs(lam).max())
        self._powers = (None, None)

    @classmethod
    def of(cls, A):
        """The modal form of A, or None (unstable, not finite, ill-conditioned
        eigenvectors). The last one computed is kept: a candidate's fit and its score
        share it."""
        key = (A.shape, A.tobytes())
        last = _LAST[0]                    # one (key, form) pair: safe across threads
        if last is None or last[0] != key:
            last = _LAST[0] = (key, cls._of(A))
        return last[1]

    @classmethod
    def _of(cls, A):
        if A.shape[0] == 0 or not np.isfinite(A).all():
            return None
        # numpy.linalg.eig(A) as complex arrays, by its LAPACK call without the wrapper
        # (the same bits; a fifth of a fold candidate's modal step)
        lam, V = complex_eigenvectors(*eig_real(frozen(A)))
        status, lags, Wm = modal_form(lam, V, LAG_TOLERANCE, MAX_EIGVEC_CONDITION)
        return cls(lam, V, Wm, lags) if status == 0 else None

    def lags_for(self, lp):
        """The lags L the sums over the record of ``lp`` take, ``min(lags, N - 1)`` (the
        corrections by ``A^N`` make them exact for any L < N), or None when ``lp`` does
        not hold them or A has not decayed over the record below :data:`EDGE_DECAY`."""
        N = lp.n_samples
        if self.lags >= N and self.radius ** N > EDGE_DECAY:
            return None
        L = min(self.lags, N - 1)
        return L if 1 <= L <= lp.max_lag else None

    def powers(self, L):
        """``(Re λ^e, Im λ^e)`` for e = 0..L (the last L asked kept)."""
        if self._powers[0] != L:
            self._powers = (L, read_only(*powers(self.lam, L)))
        return self._powers[1]

    def arguments(self, lp, L) -> tuple:
        """The modal form and the lag products of ``lp`` (up to L) as the kernels of
        :mod:`subid.methods.dt._lag_kernel` take them."""
        return (self.lam, self.V, self.Wm) + self.powers(L) + lp.kernel_arguments(L)


def fit_b_d_x0(A, C, lp: LagProducts, output_weights, *, feedthrough=True, estimate_x0=True):
    """B, D, x0 and diagnostics of the output regression of (A, C) on the record of
    ``lp`` (the problem of :func:`subid.methods.dt._regression.fit_b_d_x0`), from its
    lag products (module documentation), or None where they do not apply (then the
    per-candidate pass must run)."""
    A = np.asarray(A, dtype=float)
    md = _Modal.of(A)
    fitted = None if md is None else _modal_fit(md, C, lp, output_weights, feedthrough,
                                                 estimate_x0)
    if fitted is None:
        return None
    B, D, x0, diagnostics, L = fitted
    diagnostics["regression_path"] = "lag products"
    diagnostics["lags"] = L
    return B, D, x0, diagnostics


def _modal_fit(md, C, lp, output_weights, feedthrough, estimate_x0, bound_condition=False):
    """:func:`fit_b_d_x0` on the modal form ``md``: ``(B, D, x0, diagnostics, L)`` or
    None (``bound_condition``: as
    :func:`subid.methods.dt._regression.solve_normal_equations` takes it)."""
    L = md.lags_for(lp)
    if L is None:
        return None
    C = np.ascontiguousarray(C, dtype=float)
    n, ny, nu = md.lam.shape[0], C.shape[0], lp.u.shape[1]
    N = lp.n_samples
    w = np.ones(ny) if output_weights is None else np.asarray(output_weights, dtype=float)
    Naug = normal_matrix(*md.arguments(lp, L) + read_only(C, w) + (feedthrough, estimate_x0))
    p = Naug.shape[0] - 1
    solved = solve_normal_equations(Naug, n, nu, ny, estimate_x0=estimate_x0,
                                    feedthrough=feedthrough, n_samples=N,
                                    bound_condition=bound_condition)
    if solved is None:
        return None
    B, D, x0, _, diagnostics = solved
    if diagnostics["residual_rms"] ** 2 * N * ny < RESIDUAL_RECOMPUTE * Naug[p, p]:
        return None                  # a nearly exact fit: the residual is rounding here
    return B, D, x0, diagnostics, L


def error_power(A, B, C, D, lp: LagProducts, weights, inv_scale):
    """``sum_t ((y - ŷ) inv_scale)^2`` per output on the record of ``lp``, ``ŷ`` simulated
    from the least-squares x0 (each output weighted by ``weights``), as
    :func:`subid.methods.dt._scoring._error_power` computes it by a pass over the
    record; None where the lag products do not apply (the pass must run)."""
    A = np.asarray(A, dtype=float)
    md = _Modal.of(A)
    return None if md is None else _modal_error(md, B, C, D, lp, weights, inv_scale)


def _modal_error(md, B, C, D, lp, weights, inv_scale):
    """:func:`error_power` on the modal form ``md`` (B, C, D contiguous floats)."""
    L = md.lags_for(lp)
    if L is None:
        return None
    err = kernel_error_power(*md.arguments(lp, L) + read_only(B, C, D)
                             + (frozen(weights), 1e-13, MAX_X0_CONDITION))
    if not np.isfinite(err).all() or np.any(err < ROUNDING_GUARD * np.diag(lp.Y)):
        return None                  # a nearly exact fit: the pass is exact, this is not
    return err * inv_scale ** 2


def fit_and_error(A, C, lp: LagProducts, output_weights, held: LagProducts, held_weights,
                  inv_scale, *, feedthrough=True, estimate_x0=True):
    """B and D of :func:`fit_b_d_x0` on the record of ``lp`` and the :func:`error_power`
    of the model ``(A, B, C, D)`` on the record of ``held``, on one modal form of A
    computed once (a cross-validation candidate, only scored: no diagnostics, no cache
    of the form by content). Returns ``(B, D, err)``, ``err`` None where the products
    do not give the score (the pass must score the model); None where they do not
    give the fit."""
    A = np.asarray(A, dtype=float)
    md = _Modal._of(A)
    fitted = None if md is None else _modal_fit(md, C, lp, output_weights, feedthrough,
                                                 estimate_x0, bound_condition=True)
    if fitted is None:
        return None
    B, D = np.ascontiguousarray(fitted[0]), np.ascontiguousarray(fitted[1])
    C = np.ascontiguousarray(C, dtype=float)
    return B, D, _modal_error(md, B, C, D, held, held_weights, inv_scale)
