"""A small, exactly mergeable sufficient statistic of an input/output record.

Every subspace method here needs the data only through the correlation
matrix of the block-Hankel data matrix ``H`` (depth ``s`` block rows of
``z(t) = [u(t); y(t)]``, ``K = N - s + 1`` columns):

    G[(i, a), (k, b)] = sum_{j=0}^{K-1} z_a(i + j) z_b(k + j).

With ``l = k - i >= 0`` this is a windowed lagged product
``sum_{t=i}^{i+K-1} z_a(t) z_b(t + l)``, which equals the full-record lagged
product ``S_l = sum_{t=0}^{N-1-l} z(t) z(t+l)^T`` minus two edge corrections:
the ``i`` products at the start (``t < i``, within the first ``s - 1``
samples) and the ``s - 1 - l - i`` products at the end (``t >= i + K``,
within the last ``s - 1`` samples). So the statistic

    {S_0, ..., S_{s-1}; first s-1 samples; last s-1 samples; N}

(``s q^2`` numbers plus ``2 (s-1) q``, independent of N) determines ``G``
exactly. It accumulates chunk by chunk, and two statistics of consecutive
records merge exactly: the lagged products add, plus the products of pairs
that straddle the border, which involve only the tail of the first record
and the head of the second. That is what makes streaming from files and
distributed (Dask) identification equal to the in-memory computation.

Cost: one pass over the data with ``2 s q^2`` flops per sample, done by a
compiled kernel (:mod:`subid.statistic._lag_kernel`; far cheaper than a QR
factorisation of ``H``).
The price: ``G`` squares the condition number of ``H``. Directions of ``H``
weaker than about 1e-8 of the strongest are lost: a model of fixed order is
still accurate to rounding on noise-free data (measured: Markov errors
~1e-15), but the rank profile shows junk at ~1e-6 instead of zeros (so an
automatic order choice on noise-free data can err) and an input whose
Hankel matrix has a condition number above ~1e8 looks rank-deficient.

So the statistic comes in two kinds:

* ``kind='qr'``: the triangular factor ``R`` of ``H^T`` (``H = R^T Q^T``),
  updated by QR of ``[R; new Hankel rows]`` and merged by QR of
  ``[R_1; R_2; rows straddling the border]``. Accurate to rounding; costs
  ``2 m^2`` flops per sample (``m = s (nu + ny)`` rows).
* ``kind='gram'``: the lagged products above; ``2 s q^2`` flops per sample
  (25x fewer at m = 80), for long records.

The batch methods choose by cost (``kind='auto'`` of
:meth:`HankelStatistic.from_data`): the lagged products, 10-40x cheaper, are
kept wherever they are exact to rounding, i.e. where the Hankel matrix (each
row scaled to unit norm) has a condition number up to
:data:`GRAM_MAX_CONDITION` (its square, the condition of ``G``, times the
unit roundoff is then below 1e-8, and the factor agrees with the QR factor
to ~1e-12: measured 1e-14 at 20 dB SNR, 2e-13 at 40 dB, 3e-12 on the DaISy
records that qualify); otherwise (noise-free or nearly, ill-conditioned
inputs) the QR factor, up to :data:`QR_MAX_SAMPLES` samples, and the lagged
products beyond (``statistic=`` overrides).

Several experiments (:func:`subid.merge`): the Hankel matrix of a record of
E experiments is ``H = [H_1, ..., H_E]``, the columns of each experiment's
own Hankel matrix side by side, with no column whose window straddles a
border. So ``H H^T = sum_e H_e H_e^T``: :meth:`HankelStatistic.new_experiment`
closes the current experiment (its products are kept, its edge samples
dropped: nothing straddles the next border), and ``merge(later,
new_experiment=True)`` joins two statistics without the straddling products.
"""

from __future__ import annotations

import contextlib
import contextvars

import numpy as np
import scipy.linalg

from subid._kernel_args import frozen
from subid._validation import (
    as_signal,
    check_dt,
    check_int,
    check_magnitude,
    check_tiny,
    checked_call,
    same_period,
)
from subid.data import IOData, not_a_record
from subid.errors import DataError, ResourceLimitError, TooFewSamplesError
from subid.statistic._hankel import HankelFactor, geqrf_r, lq_lower

__all__ = ["HankelStatistic"]

_BLOCK = 8192
# Samples per piece when a whole record is reduced (bounds the extra memory).
_PIECE = 1_000_000
#: Longest record for which the batch methods use the QR statistic by default.
QR_MAX_SAMPLES = 200_000
#: Largest condition number (1-norm estimate, rows scaled to unit norm) of the Hankel
#: factor at which ``kind='auto'`` keeps the lagged products (see the module documentation).
GRAM_MAX_CONDITION = 1e4
KINDS = ("qr", "gram")
#: Largest triangular factor (``(depth (nu + ny))^2`` doubles) a statistic may need:
#: beyond it, :class:`HankelStatistic` is a :class:`subid.errors.ResourceLimitError`
#: on creation, before anything is allocated (the factor grows with the square of the
#: number of channels times the depth; the methods hold a few arrays of its size).
FACTOR_BYTES_LIMIT = 2 ** 31


def lag_sums(z: np.ndarray, depth: int) -> np.ndarray:
    """``out[l] = sum_{t=0}^{T-1-l} z(t) z(t+l)^T`` for ``l = 0 .. depth-1``.

    By matrix products: used on the few samples around a merge border, and
    as the reference of the compiled :func:`lag_sums_uy`. Blocks of
    :data:`_BLOCK` samples stay in cache while the ``depth`` small matrix
    products of each block run (one product per lag beat one wide product
    over a shifted copy by 20x).
    """
    T, q = z.shape
    out = np.zeros((depth, q, q))
    main = T - depth + 1                 # rows t for which every lag is inside z
    for b0 in range(0, max(main, 0), _BLOCK):
        b1 = min(b0 + _BLOCK, main)
        head = z[b0:b1].T
        for lag in range(depth):
            out[lag] += head @ z[b0 + lag:b1 + lag]
    for lag in range(depth):             # the last rows, where long lags run out
        t0 = max(main, 0)
        if t0 < T - lag:
            out[lag] += z[t0:T - lag].T @ z[t0 + lag:T]
    return out


def straddle(tail: np.ndarray, head: np.ndarray, depth: int) -> np.ndarray:
    """The lagged products of the pairs that straddle the border between two records:
    ``out[l] = sum z(t) z(t + l)^T`` over ``t`` in ``tail`` (the last samples of the
    first record) and ``t + l`` in ``head`` (the first of the second), ``l < depth``.

    What ``lag_sums(border) - lag_sums(tail) - lag_sums(head)`` gives (``border`` the
    two stacked; equal to rounding, without its cancellation), for every lag at once:
    ``tail[t]`` pairs with ``head[t + l - len(tail)]``, read from the head padded with
    zeros where that index leaves it."""
    n_tail, q = tail.shape
    n_head = head.shape[0]
    if n_tail == 0 or n_head == 0:
        return np.zeros((depth, q, q))
    padded = np.zeros((n_tail + n_head + depth, q))
    padded[n_tail:n_tail + n_head] = head
    # partner of tail[t] at lag l: padded[t + l] (zero unless it falls in the head)
    index = np.arange(depth)[:, None] + np.arange(n_tail)[None, :]
    return np.einsum("ta,ltb->lab", tail, padded[index])


def lag_sums_uy(u: np.ndarray, y: np.ndarray, depth: int) -> np.ndarray:
    """:func:`lag_sums` of ``z = [u, y]`` without forming ``z``: the compiled
    :func:`subid.statistic._lag_kernel.lag_sums_kernel` (same sums, to rounding;
    it releases the GIL)."""
    from subid.statistic._lag_kernel import lag_sums_kernel

    return lag_sums_kernel(frozen(u), frozen(y), depth)     # one compiled signature


class HankelStatistic:
    """Lagged products and edge samples of a record: all the batch methods need.

    Parameters
    ----------
    n_inputs, n_outputs : int
    depth : int
        Block rows of the Hankel matrix: ``2 * horizon`` for methods with
        past instruments (moesp, n4sid, ls_subspace with instruments),
        ``horizon`` for ls_subspace without instruments.
    kind : {'qr', 'gram'}
        Triangular factor updated by QR (accurate to rounding) or lagged
        products (faster, squares the condition number); see the module
        documentation.
    dt : float
        Sampling period of the record.
    input_names, output_names : sequence of str, optional

    Raises
    ------
    subid.errors.ResourceLimitError
        The triangular factor, ``(depth (n_inputs + n_outputs))^2`` doubles, would
        exceed :data:`FACTOR_BYTES_LIMIT` (2 GiB): raised before anything is allocated.

    Examples
    --------
    >>> import subid
    >>> true = subid.systems.seed001_system()
    >>> data = subid.systems.simulate_data(true, 5000, seed=0, output_snr_db=30)
    >>> stat = subid.HankelStatistic(2, 2, depth=10)
    >>> for k in range(0, 5000, 1000):                 # chunk by chunk
    ...     _ = stat.update(data.u[k:k + 1000], data.y[k:k + 1000])
    >>> model = subid.moesp(stat, 3)                   # from the statistic only
    >>> model.order
    3
    """

    @checked_call
    def __init__(self, n_inputs, n_outputs, depth, *, kind="gram", dt=1.0, input_names=None,
                 output_names=None):
        if kind not in KINDS:
            raise DataError(f"statistic kind must be one of {KINDS}, got {kind!r}")
        self.kind = kind
        self.n_inputs = check_int(n_inputs, "n_inputs")
        self.n_outputs = check_int(n_outputs, "n_outputs")
        self.depth = check_int(depth, "depth", minimum=2)
        self.dt = check_dt(dt)
        q = self.n_inputs + self.n_outputs
        self.input_names = tuple(input_names) if input_names is not None else \
            tuple(f"u{k + 1}" for k in range(self.n_inputs))
        self.output_names = tuple(output_names) if output_names is not None else \
            tuple(f"y{k + 1}" for k in range(self.n_outputs))
        m = self.depth * q
        if 8.0 * m * m > FACTOR_BYTES_LIMIT:
            raise ResourceLimitError(
                f"a Hankel statistic of depth {self.depth} with {self.n_inputs} inputs and "
                f"{self.n_outputs} outputs has {m} rows: its triangular factor alone takes "
                f"{8.0 * m * m / 2**30:.3g} GiB (limit {FACTOR_BYTES_LIMIT / 2**30:g} GiB). "
                f"Use a smaller horizon (depth <= {int((FACTOR_BYTES_LIMIT / 8) ** 0.5) // q}; "
                "the subspace methods use depth 2 * horizon), or identify fewer channels at "
                "a time")
        self.lagged = np.zeros((self.depth, q, q)) if kind == "gram" else None
        self.R = np.zeros((m, m)) if kind == "qr" else None
        self.head = np.zeros((0, q))
        self.tail = np.zeros((0, q))
        self.n_samples = 0
        self._reset_experiments()

    def _reset_experiments(self):
        """One open experiment holding all the samples (the state of a new statistic)."""
        self.n_experiments = 1
        self._open_samples = self.n_samples
        self._closed_columns = 0
        self._closed_gram = None          # kind 'gram': sum of H_e H_e^T of closed experiments

    @classmethod
    def from_data(cls, data: IOData, depth: int, kind: str = "auto") -> "HankelStatistic":
        """The statistic of a whole (uniformly sampled) record.

        ``kind='auto'``: ``'gram'`` where it is exact to rounding (the
        condition number of its factor, rows scaled to unit norm, at most
        :data:`GRAM_MAX_CONDITION`: :func:`factor_condition`) or beyond
        :data:`QR_MAX_SAMPLES` samples, ``'qr'`` otherwise (the factor of the
        statistic returned is then already computed). A record of several experiments (:func:`subid.merge`)
        gives the statistic of their Hankel columns only (none across a border).
        """
        if not isinstance(data, IOData):
            raise not_a_record(data, "HankelStatistic.from_data")
        if not data.is_uniform:
            raise DataError("HankelStatistic needs uniformly sampled data")
        for role, values, names in (("input", data.u, data.input_names),
                                    ("output", data.y, data.output_names)):
            check_magnitude(values, role, names)     # squares overflow, or underflow
            check_tiny(values, role, names)
        if kind == "auto":
            stat = cls.from_data(data, depth, "gram")
            if data.n_samples > QR_MAX_SAMPLES:
                return stat
            try:
                factor = stat.exact_factor()
            except TooFewSamplesError:
                return stat                   # the caller reports it
            if factor is not None:
                return stat
            kind = "qr"
        stat = cls(data.n_inputs, data.n_outputs, depth, kind=kind, dt=data.dt,
                   input_names=data.input_names, output_names=data.output_names)
        for k, (start, stop) in enumerate(data.experiment_ranges):
            if k:
                stat.new_experiment()
            for a in range(start, stop, _PIECE):
                b = min(a + _PIECE, stop)
                stat._absorb(data.u[a:b], data.y[a:b])
        return stat

    def shallower(self, depth: int) -> "HankelStatistic":
        """The ``'gram'`` statistic of the same record (one experiment) at a smaller depth.

        Its first ``depth`` lagged products and the first and last ``depth - 1``
        samples of this one are those :meth:`from_data` computes at that depth (the
        same sums in the same order: the same bits), so one pass over a record serves
        every horizon up to this statistic's.

        Parameters
        ----------
        depth : int
            Block rows of the new statistic, from 2 to ``self.depth``.

        Returns
        -------
        HankelStatistic

        Raises
        ------
        DataError
            Not a ``'gram'`` statistic of one experiment, or a depth out of range.
        """
        if self.kind != "gram" or self.n_experiments != 1 or self._closed_columns \
                or not 2 <= depth <= self.depth:
            raise DataError("only a 'gram' statistic of one experiment has a shallower copy, "
                            f"at a depth from 2 to {self.depth}")
        out = HankelStatistic.__new__(HankelStatistic)
        out.__dict__.update(self.__dict__)
        out.__dict__.pop("_cached_factor", None)
        keep = depth - 1
        out.depth = depth
        out.lagged = self.lagged[:depth].copy()
        out.head = self.head[:keep].copy()
        out.tail = self.tail[self.tail.shape[0] - min(keep, self.tail.shape[0]):].copy()
        return out

    # -- experiments ----------------------------------------------------------
    def _open_columns(self) -> int:
        return max(self._open_samples - self.depth + 1, 0)

    def new_experiment(self) -> "HankelStatistic":
        """Start a new experiment: the next samples do not continue the previous ones.

        The Hankel columns of the experiment so far are kept; no column will
        straddle this border (:func:`subid.merge`).
        """
        if self._open_samples == 0:
            return self                   # nothing to close (a new or just-closed statistic)
        self.__dict__.pop("_cached_factor", None)
        if self.kind == "gram" and self._open_columns():
            closed = self._open_gram_sum()
            self._closed_gram = closed if self._closed_gram is None else \
                self._closed_gram + closed
        self._closed_columns += self._open_columns()
        q = self.n_inputs + self.n_outputs
        if self.kind == "gram":
            self.lagged = np.zeros_like(self.lagged)
        self.head = np.zeros((0, q))
        self.tail = np.zeros((0, q))
        self._open_samples = 0
        self.n_experiments += 1
        return self

    # -- accumulation -------------------------------------------------------
    def update(self, u, y) -> "HankelStatistic":
        """Append a chunk of samples (time on axis 0) to the record."""
        u = as_signal(u, "input u", copy=False)     # read only; nothing of it is kept
        y = as_signal(y, "output y", copy=False)
        if u.shape[1] != self.n_inputs or y.shape[1] != self.n_outputs:
            raise DataError(f"the chunk has {u.shape[1]} inputs and {y.shape[1]} outputs; the "
                            f"statistic was created for {self.n_inputs} and {self.n_outputs}")
        if u.shape[0] != y.shape[0]:
            raise DataError(f"input u has {u.shape[0]} samples but output y has {y.shape[0]}")
        check_magnitude(u, "input", self.input_names)   # squares must not overflow
        check_magnitude(y, "output", self.output_names)
        return self._absorb(u, y)

    def _absorb(self, u: np.ndarray, y: np.ndarray) -> "HankelStatistic":
        chunk = HankelStatistic.__new__(HankelStatistic)
        chunk.__dict__.update(self.__dict__)
        keep = self.depth - 1
        if self.kind == "gram":
            chunk.lagged = lag_sums_uy(u, y, self.depth)
        else:
            # z = [u, y] as the transpose of a channel-major copy: _qr_rows reads channels
            chunk.R = _qr_rows(None, np.vstack([u.T, y.T]).T, self.depth, self.n_inputs)
        chunk.head = np.hstack([u[:keep], y[:keep]])
        chunk.tail = np.hstack([u[u.shape[0] - min(keep, u.shape[0]):],
                                y[y.shape[0] - min(keep, y.shape[0]):]])
        chunk.n_samples = u.shape[0]
        chunk._reset_experiments()
        merged = self.merge(chunk)
        self.__dict__.pop("_cached_factor", None)
        self.lagged, self.R = merged.lagged, merged.R
        self.head, self.tail = merged.head, merged.tail
        self.n_samples = merged.n_samples
        self._open_samples = merged._open_samples
        return self

    def merge(self, later: "HankelStatistic", *, new_experiment: bool = False
              ) -> "HankelStatistic":
        """The statistic of this record followed immediately by ``later``.

        Exact: the lagged products add, plus the products of the pairs that
        straddle the border (the tail of this record with the head of the
        next). Merging is associative, so partitions can be combined in any
        tree as long as their time order is kept.

        ``new_experiment=True``: ``later`` is another experiment (or starts
        one), not the continuation of this record: no products straddle the
        border (:func:`subid.merge`).
        """
        if not isinstance(later, HankelStatistic):
            raise DataError(f"merge takes another HankelStatistic, got "
                            f"{type(later).__name__}")
        if (later.n_inputs, later.n_outputs, later.depth, later.kind) != \
                (self.n_inputs, self.n_outputs, self.depth, self.kind):
            raise DataError("statistics with different channels, depth or kind cannot be "
                            "merged")
        if not same_period(later.dt, self.dt):
            raise DataError(f"statistics sampled at dt={self.dt:g} and dt={later.dt:g} "
                            "cannot be merged: their lagged products are of different "
                            "sampling periods. Resample one record to the other's period "
                            "first, or identify from each statistic separately")
        if new_experiment:
            return self._merge_experiments(later)
        if later.n_experiments > 1:
            raise DataError("the later statistic holds several experiments, so its first "
                            "experiment was closed without these samples: merge the pieces "
                            "of each experiment first, then the experiments with "
                            "merge(..., new_experiment=True)")
        out = HankelStatistic.__new__(HankelStatistic)
        out.__dict__.update(self.__dict__)
        out.__dict__.pop("_cached_factor", None)
        keep = self.depth - 1
        border = np.vstack([self.tail, later.head])
        if self.kind == "gram":
            out.lagged = self.lagged + later.lagged + straddle(self.tail, later.head,
                                                               self.depth)
        else:
            # columns whose window starts in the tail and ends in the head
            m = self.R.shape[0]
            stacked = np.vstack([self.R, later.R])
            out.R = _qr_rows(stacked, border, self.depth, self.n_inputs) \
                if border.shape[0] >= self.depth else _triangle(stacked, m)
        out.head = np.vstack([self.head, later.head])[:keep].copy()
        both_tails = np.vstack([self.tail, later.tail])
        out.tail = both_tails[both_tails.shape[0] - min(keep, both_tails.shape[0]):].copy()
        out.n_samples = self.n_samples + later.n_samples
        out._open_samples = self._open_samples + later._open_samples
        return out

    def _merge_experiments(self, later: "HankelStatistic") -> "HankelStatistic":
        out = HankelStatistic.__new__(HankelStatistic)
        out.__dict__.update(self.__dict__)
        out.__dict__.pop("_cached_factor", None)
        if self._open_samples:
            out.new_experiment()
            out.n_experiments -= 1           # counted once below
        if self.kind == "gram":
            grams = [g for g in (out._closed_gram, later._closed_gram) if g is not None]
            out._closed_gram = sum(grams) if grams else None
            out.lagged = later.lagged.copy()
        else:
            out.R = _triangle(np.vstack([self.R, later.R]), self.R.shape[0])
        out._closed_columns = out._closed_columns + later._closed_columns
        out.head, out.tail = later.head.copy(), later.tail.copy()
        out._open_samples = later._open_samples
        out.n_samples = self.n_samples + later.n_samples
        # an experiment just opened by new_experiment() and still empty is not counted twice
        pending = 1 if (self.n_samples and not self._open_samples) else 0
        out.n_experiments = (self.n_experiments - pending if self.n_samples else 0) \
            + later.n_experiments
        return out

    # -- results ------------------------------------------------------------
    @property
    def n_columns(self) -> int:
        """Columns of the Hankel matrix, ``N - depth + 1`` (summed over the
        experiments: ``N_e - depth + 1`` each)."""
        if self.n_experiments == 1 and not self._closed_columns:
            return self.n_samples - self.depth + 1
        return self._closed_columns + self._open_columns()

    def gram(self) -> np.ndarray:
        """``H H^T / K`` in the row order ``[U_0..U_{s-1}; Y_0..Y_{s-1}]``."""
        if self.kind == "qr":
            L = self.factor().L
            return L @ L.T
        s, K = self.depth, self.n_columns
        if K < 1:
            raise TooFewSamplesError(f"the statistic holds {self.n_samples} samples; the "
                                     f"Hankel matrix with {s} block rows needs at least {s}"
                                     + (" in one experiment" if self.n_experiments > 1 else ""))
        G = self._open_gram_sum() if self._open_columns() else 0.0
        if self._closed_gram is not None:
            G = G + self._closed_gram
        return np.asarray(G / K)

    def _open_gram_sum(self) -> np.ndarray:
        """``H H^T`` (not normalised) of the open experiment's Hankel columns.

        Block ``(i, i + l)`` is the lagged product ``S_l`` less the ``i`` products at
        the start of the record (``t < i``, all within the head) and the products at its
        end (``t >= i + K``, all within the tail): one compiled pass
        (:func:`subid.statistic._lag_kernel.open_gram_kernel`) that makes the additions of
        :meth:`_open_gram_sum_by_lag` in the same order, so the same bits."""
        from subid.statistic._lag_kernel import open_gram_kernel
        s = self.depth
        if self.head.shape[0] < s - 1 or self.tail.shape[0] < s - 1:
            return self._open_gram_sum_by_lag()      # an experiment shorter than the edges
        return open_gram_kernel(frozen(self.lagged), frozen(self.head[:s - 1]),
                                frozen(self.tail[:s - 1]), self.n_inputs)  # one signature

    def _open_gram_sum_by_lag(self) -> np.ndarray:
        """:meth:`_open_gram_sum` lag by lag (the reference; also for an open experiment
        shorter than the edges)."""
        s = self.depth
        q = self.n_inputs + self.n_outputs
        head, tail = self.head, self.tail
        Gz = np.zeros((s, q, s, q))      # blocks by (block row, channel of z)
        for lag in range(s):
            n = s - 1 - lag              # block rows i = 0 .. n take this lag
            # products z(t) z(t+lag)^T with t < i: all inside the first s-1 samples
            early = np.zeros((n + 1, q, q))     # early[i]: the sum over t < i
            early[1:] = np.cumsum(np.einsum("ta,tb->tab", head[:n], head[lag:lag + n]), axis=0)
            # products with t >= i + K = N - s + 1 + i: the tail holds samples
            # N-s+1 .. N-1, so these are tail[k], i <= k < s - 1 - lag
            late = np.zeros((n + 1, q, q))      # late[i]: the sum over k >= i
            products = np.einsum("ta,tb->tab", tail[:n], tail[lag:lag + n])
            late[:n] = np.cumsum(products[::-1], axis=0)[::-1]
            window = self.lagged[lag] - early - late
            rows = np.arange(n + 1)
            Gz[rows, :, rows + lag, :] = window
            Gz[rows + lag, :, rows, :] = window.transpose(0, 2, 1)
        nu = self.n_inputs
        order = [(i, a) for i in range(s) for a in range(nu)] + \
                [(i, nu + b) for i in range(s) for b in range(self.n_outputs)]
        idx = np.array([i * q + a for i, a in order])
        return Gz.reshape(s * q, s * q)[np.ix_(idx, idx)]

    def exact_factor(self) -> HankelFactor | None:
        """:meth:`factor`, or None when it is that of lagged products that are not
        exact to rounding (kind ``'gram'``, :func:`factor_condition` above
        :data:`GRAM_MAX_CONDITION`): then the QR statistic is needed."""
        factor = self.factor()
        if self.kind == "qr" or factor_condition(factor.L) <= GRAM_MAX_CONDITION:
            self._cached_factor = factor
            return factor
        return None

    def factor(self) -> HankelFactor:
        """The lower-triangular factor ``L`` with ``L L^T = H H^T / K``.

        ``kind='qr'``: ``L = R^T / sqrt(K)``. ``kind='gram'``: pivoted
        Cholesky of the correlation (LAPACK ``pstrf``, which handles the
        semi-definite matrices of noise-free data), then an LQ factorisation
        that brings the factor back to the triangular form of the row order.
        """
        cached = self.__dict__.get("_cached_factor")
        if cached is not None:
            return cached
        if self.kind == "qr":
            K = self.n_columns
            if K < 1:
                raise TooFewSamplesError(f"the statistic holds {self.n_samples} samples; the "
                                         f"Hankel matrix with {self.depth} block rows needs "
                                         f"at least {self.depth}")
            L = self.R.T / np.sqrt(K)
            signs = np.sign(np.diag(L))
            signs[signs == 0] = 1.0
            return HankelFactor(L=L * signs, depth=self.depth, n_inputs=self.n_inputs,
                                n_outputs=self.n_outputs, n_columns=K)
        G = self.gram()
        m = G.shape[0]
        scale = np.sqrt(np.maximum(np.diag(G), 0.0))
        scale[scale == 0] = 1.0
        Gs = G / np.outer(scale, scale)
        c, piv, rank, info = scipy.linalg.lapack.dpstrf(Gs, lower=1, tol=-1.0)
        if info < 0:
            raise DataError(f"pivoted Cholesky failed (LAPACK info {info})")
        Lp = np.tril(c)
        Lp[:, rank:] = 0.0
        F = np.zeros((m, m))
        F[piv - 1] = Lp                   # F F^T = Gs
        L = lq_lower(F * scale[:, None])
        return HankelFactor(L=L, depth=self.depth, n_inputs=self.n_inputs,
                            n_outputs=self.n_outputs, n_columns=self.n_columns)


def factor_condition(L: np.ndarray) -> float:
    """1-norm condition number estimate (LAPACK ``trcon``) of the lower-triangular
    factor ``L`` with every row scaled to unit norm: the condition of the Hankel
    matrix whatever the units of the channels (inf when a row is zero or the
    factor singular)."""
    norms = np.linalg.norm(L, axis=1)
    if not np.all(norms > 0) or not np.isfinite(L).all():
        return np.inf
    Ln = np.ascontiguousarray((L / norms[:, None]).T)
    rcond = scipy.linalg.lapack.dtrcon(Ln, norm="1", uplo="U", diag="N")[0]
    return 1.0 / rcond if rcond > 0 else np.inf


def _triangle(stacked: np.ndarray, m: int) -> np.ndarray:
    """The m x m triangular factor of the rows ``stacked``."""
    R = scipy.linalg.qr(stacked, mode="r", check_finite=False)[0][:m]
    if R.shape[0] < m:
        R = np.vstack([R, np.zeros((m - R.shape[0], m))])
    return R


def _qr_rows(R, z: np.ndarray, depth: int, n_inputs: int) -> np.ndarray:
    """Triangular factor of ``[R; rows of H^T built from z]``, chunk by chunk.

    ``R`` (or None) is the factor so far; ``z = [u, y]`` holds the samples
    whose Hankel columns (all windows of ``depth`` samples) are added.

    Each block ``[R; next rows of H^T]`` is written straight into one
    column-major work array and factorised in place by LAPACK ``geqrf``
    (:func:`subid.statistic._hankel.geqrf_r`):
    the same Householder factorisation (same input, same routine, same
    workspace) as ``scipy.linalg.qr(mode='r')`` without its copies (a
    Fortran copy of the C-ordered block, the stacking, and ``triu`` of the
    whole tall result), which took about 40 % of the statistic's time.
    """
    q = z.shape[1]
    m = depth * q
    ny = q - n_inputs
    columns = z.shape[0] - depth + 1
    if columns <= 0:
        R = np.zeros((0, m)) if R is None else R
        return _triangle(R, m) if R.shape[0] != m else R
    zt = np.ascontiguousarray(z.T)        # one channel per row: contiguous column copies
    # column order of H^T: [u(t), ..., u(t+s-1), y(t), ..., y(t+s-1)]
    source = [(i, a) for i in range(depth) for a in range(n_inputs)] + \
             [(i, n_inputs + b) for i in range(depth) for b in range(ny)]
    top = 0 if R is None else R.shape[0]
    flat = np.empty((max(top, m) + min(_BLOCK, columns)) * m)
    blocked = _COMPACT_WY.get()
    for start in range(0, columns, _BLOCK):
        stop = min(start + _BLOCK, columns)
        rows = top + stop - start
        work = flat[:rows * m].reshape((rows, m), order="F")
        if top:
            work[:top] = R
        for j, (i, c) in enumerate(source):
            work[top:, j] = zt[c, start + i:stop + i]
        R = np.zeros((m, m))
        R[:min(rows, m)] = np.triu(householder_r(work)[:m]) if blocked \
            else geqrf_r(work, m, overwrite=True)
        top = m
    return R


#: Block size of LAPACK ``geqrt`` in :func:`householder_r`.
QR_BLOCK = 32


def householder_r(work):
    """``work`` (column-major, overwritten) with R in its upper triangle: the
    Householder QR factorisation of ``scipy.linalg.qr(mode='r')`` (LAPACK ``geqrf``:
    the same reflectors and signs, R equal to rounding) by LAPACK ``geqrt``, whose
    compact-WY blocks (:data:`QR_BLOCK` columns) keep the tall panels in cache:
    2.5-3.5x faster than ``geqrf`` on the output regressions of
    :mod:`subid.methods.dt._regression` (4480-17920 rows, 40-117 columns) and on the
    Hankel rows of cross-validation folds (4460 x 160-320), one thread."""
    m, n = work.shape
    if min(m, n) == 0:
        return work
    qr, _, info = scipy.linalg.lapack.dgeqrt(min(QR_BLOCK, m, n), work, overwrite_a=1)
    if info < 0:
        raise DataError(f"QR factorisation failed (LAPACK info {info})")
    return qr


_COMPACT_WY = contextvars.ContextVar("subid_compact_wy_qr", default=False)


@contextlib.contextmanager
def compact_wy_qr():
    """Within the block, the QR statistics (``kind='qr'``) factorise their Hankel rows
    by :func:`householder_r` instead of ``geqrf``: R equal to rounding, 2.5x faster,
    but not bit for bit, and the models of ill-conditioned records move by more than
    rounding (N4SID on robot_arm at order 15: 3e-4 relative). For statistics whose
    models are only scored: the cross-validation folds
    (:func:`subid.methods.dt.fold_statistics.fold_factors`). Per thread and task."""
    token = _COMPACT_WY.set(True)
    try:
        yield
    finally:
        _COMPACT_WY.reset(token)
