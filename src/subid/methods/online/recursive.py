"""Recursive SVD-free subspace identification: seed 001 made recursive.

Seed 001 (Bako, Mercère, Lecoeuche) turns subspace identification into a
least-squares problem with a user-fixed state basis precisely so that it can
run online. :class:`RecursiveSubspace` keeps the triangular factor ``R`` of
the (exponentially weighted) block-Hankel data matrix and updates it with
every new Hankel column by Givens rotations:

    [sqrt(λ) R; h^T] = Q [R_new; 0],

i.e. ``R_new^T R_new = λ R^T R + h h^T``: the square-root (information) form
of the weighted data correlation, which never squares the condition number.
The model is computed on demand from ``R`` through exactly the code path of
the batch :func:`subid.ls_subspace` (eq. (23) or (28), Λ-fixed basis, A and C
by shift invariance). So with forgetting 1, A and C equal the batch estimate
on the same data, and the state basis stays the one fixed by Λ whatever the
data: the property that makes the method usable for tracking and switched
systems.

B, D and the current state come, by default (``bd_method='simulation'``),
from the output-error regression of the batch method
(:func:`subid.methods.bd.fit_b_d_x0`: ``y(t) = C S(t) [x0; vec B] +
(u(t)^T ⊗ I) vec D``, ``S(t+1) = A S(t) + [0, u(t)^T ⊗ I]``, outputs weighted
by 1 / their standard deviation). With forgetting 1 it is evaluated exactly,
for the current (A, C), from fixed-size lagged statistics of the data
(:mod:`subid.methods.online._lagged`: lags 0..``lags``, the first and the last samples), so
the model equals the batch :func:`subid.ls_subspace` model on noisy data too
(up to terms in ``A^(lags+1)``, reported in ``info['bd_truncation']``). With
forgetting below 1 the regression is made recursive: its rows are reduced
into a triangular factor by the same Givens rotations and forgetting as the
Hankel data. The sensitivity S is propagated with the model's (A, C),
refreshed every ``refresh_every`` samples; when they change by more than
``restart_tolerance`` (relative) since the last refresh (start up, a switch)
the regression restarts with ``S = [I, 0]``, a new x0 (close to the batch
model, not equal: (A, C) as they were when each sample came). ``bd_method='projection'`` uses the projected data
equation on the statistic instead (the former default; it equals the batch
``bd_method='projection'`` exactly, but is much less accurate on some real
data: CD_player_arm, docs/seed000.md).

No SVD is computed, memory is fixed (``R`` and the last ``2*horizon``
samples), and the per-sample update runs in a compiled kernel.
"""

from __future__ import annotations

import math
import numbers
import warnings

import numba
import numpy as np

from subid._validation import (
    MAX_DIMENSION,
    as_chunk,
    check_bool,
    check_choice,
    check_dt,
    check_int,
    check_seed,
    check_selector,
    check_time_stamps,
    checked_call,
)
from subid.errors import (
    CheckpointError,
    DataError,
    NotConvergedWarning,
    OptionError,
    OrderError,
    SubidError,
    TooFewSamplesError,
)
from subid.io._checkpoint import load_state, require, save_state
from subid.methods._common import (
    check_excitation,
    conditions_of,
    default_horizon,
    min_samples,
    normalize_channels,
)
from subid.methods._info import model_info
from subid.methods.bd import (
    INFO_KEY,
    ONLINE_OPTIONS,
    Accumulated,
    Projection,
    fit_b_d_x0,
    regression_rows,
)
from subid.methods.dt import noise_model
from subid.methods.dt.ls_subspace import check_options, gamma_from_factor, random_selector
from subid.methods.online._lagged import LaggedStatistic, end_sensitivity
from subid.methods.online._window import SampleWindow, window_size
from subid.methods.online.base import (
    OnlineIdentifier,
    check_state_bytes,
    check_stream_grid,
    history_dict,
    one_sample,
)
from subid.model.statespace import StateSpace
from subid.statistic._hankel import HankelFactor, hankel_chunk

__all__ = ["RecursiveSubspace"]

_CHUNK = 8192
_FIRST_REFRESH = 50     # first refresh of the B, D regression's (A, C), then doubling
_TRUNCATION_WARN = 1e-8    # |A^(lags+1)| above this: the exact regression is approximate


@numba.njit(cache=True, nogil=True)
def givens_update(R, rows, lam_sqrt):  # pragma: no cover - compiled
    """Update the upper-triangular ``R`` in place with the rows of ``rows``.

    For each row h: ``R <- sqrt(λ) R``, then Givens rotations zero h against
    the diagonal of R, so that ``R'^T R' = λ R^T R + h h^T``.
    """
    m = R.shape[0]
    h = np.empty(m)
    for r in range(rows.shape[0]):
        if lam_sqrt != 1.0:
            for i in range(m):
                for j in range(i, m):
                    R[i, j] *= lam_sqrt
        for j in range(m):
            h[j] = rows[r, j]
        for i in range(m):
            b = h[i]
            if b == 0.0:
                continue
            a = R[i, i]
            rr = math.hypot(a, b)
            c = a / rr
            s = b / rr
            R[i, i] = rr
            for j in range(i + 1, m):
                rij = R[i, j]
                hj = h[j]
                R[i, j] = c * rij + s * hj
                h[j] = c * hj - s * rij
    return R


def givens_update_reference(R, rows, lam_sqrt):
    """Plain-numpy reference of :func:`givens_update` (same operations)."""
    m = R.shape[0]
    for r in range(rows.shape[0]):
        if lam_sqrt != 1.0:
            R *= lam_sqrt
        h = rows[r].astype(np.float64).copy()
        for i in range(m):
            b = h[i]
            if b == 0.0:
                continue
            a = R[i, i]
            rr = math.hypot(a, b)
            c, s = a / rr, b / rr
            R[i, i] = rr
            rij = R[i, i + 1:].copy()
            hj = h[i + 1:].copy()
            R[i, i + 1:] = c * rij + s * hj
            h[i + 1:] = c * hj - s * rij
    return R


class RecursiveSubspace(OnlineIdentifier):
    """Online SVD-free subspace identification with a fixed state basis.

    An :class:`~subid.methods.online.base.OnlineIdentifier`: the settings below are
    stored unchanged as attributes of the same names (:meth:`get_params`).

    Parameters
    ----------
    order : int
        Model order n.
    n_inputs, n_outputs : int
    horizon : int, optional
        Future horizon f (and past horizon of the instruments). Default
        ``max(5, ceil(n/ny) + 2)``, as :func:`subid.ls_subspace`.
    forgetting : float
        Exponential forgetting factor λ in (0, 1]: a Hankel column seen k
        samples ago has weight λ^k. 1 = no forgetting (equals the batch
        estimate); below 1 the estimate tracks changing dynamics with a memory
        of about ``1 / (1 - λ)`` samples.
    instruments : {'past', None}
        As in :func:`subid.ls_subspace`.
    selector : array_like, optional
        The matrix Λ (order x horizon*ny) fixing the state basis. Default: a
        random matrix drawn from ``seed`` (:func:`subid.ls_subspace.random_selector`).
    seed : int
    instrument_weighting, power_iterations, feedthrough
        As in :func:`subid.ls_subspace`.
    dt : float
        Sampling period of the data (and of ``model``).
    history_size : int, optional
        Keep at most this many snapshots of the model's poles (opt-in). When
        the buffer is full, every other snapshot is dropped and the stride
        doubles, so memory stays bounded however long the stream.
    history_stride : int
        Samples between snapshots at the start (default 1000).
    input_names, output_names : sequence of str, optional
        Channel names carried by ``model``.
    bd_method : {'simulation', 'projection'}
        How B, D (and the state) are estimated: the recursive output-error
        regression (default; see the module notes) or the projected data
        equation on the statistic.
    refresh_every : int, optional
        ``'simulation'``: samples between refreshes of the (A, C) that
        propagate the regression's sensitivity (after refreshes at 50, 100,
        200, ... samples below it, so that the regression starts early). A
        refresh costs about one model computation. Default: a quarter of the
        memory ``1 / (1 - forgetting)``, within [50, 2000].
    restart_tolerance : float
        ``'simulation'``: relative change of (A, C) between two refreshes
        above which the regression restarts (start-up, switches).
    lags : int
        ``'simulation'`` with forgetting 1: lags of the statistics of the
        exact regression (memory and work per sample grow with it). Exact
        for any stable A while at most ``lags + 1`` samples have come, else
        up to ``|A^(lags+1)|`` (1e-16 for a spectral radius of 0.965 at the
        default 1000; above 1e-8 the model warns).

    Attributes
    ----------
    n_samples : int
        Samples received so far.
    t : float or None
        Time of the latest sample.
    model : StateSpace
        The current estimate (computed on demand).
    state : ndarray
        Estimate of the state at the latest sample, in the basis of Λ.
    history : dict
        ``sample``, ``t``, ``poles``, ``A``, ``B``, ``C``, ``D`` snapshots (the
        common format of :mod:`subid.methods.online.base`; empty if off).

    Examples
    --------
    >>> import subid
    >>> true = subid.systems.seed001_system()
    >>> data = subid.systems.simulate_data(true, 2000, seed=1)
    >>> rs = subid.RecursiveSubspace(3, 2, 2, horizon=5)
    >>> for k in range(0, 2000, 100):          # a stream in pieces
    ...     _ = rs.update(data.u[k:k + 100], data.y[k:k + 100])
    >>> subid.markov_error(rs.model, true) < 1e-9
    True
    """

    # 2: the recursive B, D regression; 3: lagged statistics (forgetting 1); 4: bd_method
    # 'regression' named 'simulation' (the vocabulary of subid.methods.bd); 5: the window
    # of the last samples (noise_cov of the current model, subid.methods.online._window)
    _VERSION = 5
    _READS = (2, 3, 4, 5)

    @checked_call
    def __init__(self, order, n_inputs, n_outputs, *, horizon=None, forgetting=1.0,
                 instruments="past", selector=None, seed=0, instrument_weighting=True,
                 power_iterations=8, feedthrough=True, dt=1.0, history_size=None,
                 history_stride=1000, input_names=None, output_names=None,
                 bd_method="simulation", refresh_every=None, restart_tolerance=1.0,
                 lags=1000):
        # the settings, stored unchanged (validated below; the values in use
        # are private: e.g. the default horizon)
        self.order, self.n_inputs, self.n_outputs = order, n_inputs, n_outputs
        self.horizon, self.forgetting, self.instruments = horizon, forgetting, instruments
        check_seed(seed)
        self.seed, self.instrument_weighting = seed, instrument_weighting
        self.power_iterations, self.feedthrough, self.dt = power_iterations, feedthrough, dt
        self.history_size, self.history_stride = history_size, history_stride
        self.input_names, self.output_names = input_names, output_names
        self.bd_method, self.refresh_every = bd_method, refresh_every
        self.restart_tolerance, self.lags = restart_tolerance, lags
        check_int(order, "order")
        check_int(n_inputs, "n_inputs")
        check_int(n_outputs, "n_outputs")
        self._f = default_horizon(self.order, self.n_outputs, self.n_inputs, 0, 2) \
            if horizon is None else check_int(horizon, "horizon", minimum=2)
        if self.order > (self._f - 1) * self.n_outputs:
            need = math.ceil(self.order / self.n_outputs) + 1
            raise OrderError(f"RecursiveSubspace: order {self.order} cannot be revealed with "
                             f"horizon {self._f} and {self.n_outputs} outputs; use "
                             f"horizon >= {need}")
        if isinstance(forgetting, bool) or not isinstance(forgetting, numbers.Real) \
                or not 0 < forgetting <= 1:
            raise SubidError(f"forgetting must be a number in (0, 1], got {forgetting!r}")
        self._lam = float(forgetting)
        self._power_iterations = check_options(instruments, power_iterations)
        # before anything of the order's size is allocated (the selector too)
        n, nu, ny = self.order, self.n_inputs, self.n_outputs
        m = (2 * self._f if instruments == "past" else self._f) * (nu + ny)
        nbd = n + n * nu + ny * nu                  # the B, D regression, at most
        check_state_bytes(8.0 * (m * m + (nbd + 1) ** 2 + 2 * n * (n + n * nu)
                                 + self._f * ny * n),
                          "RecursiveSubspace",
                          f"order {n} with {nu} input(s), {ny} output(s) and horizon "
                          f"{self._f} (a statistic of {m} rows)",
                          "use a smaller order or horizon, or fewer channels")
        self._instrument_weighting = check_bool(instrument_weighting, "instrument_weighting")
        self._feedthrough = check_bool(feedthrough, "feedthrough")
        self._dt = check_dt(dt)
        self._t_origin, self._k_origin = 0.0, 0     # time of sample k: t0 + (k - k0) dt
        selector = check_selector(selector, self._f, self.n_outputs, [self.order],
                                  self.order)
        self._input_names = tuple(input_names) if input_names is not None else \
            tuple(f"u{k + 1}" for k in range(self.n_inputs))
        self._output_names = tuple(output_names) if output_names is not None else \
            tuple(f"y{k + 1}" for k in range(self.n_outputs))
        for names, count, what in ((self._input_names, self.n_inputs, "input_names"),
                                   (self._output_names, self.n_outputs, "output_names")):
            if len(names) != count:
                raise DataError(f"{what} has {len(names)} names for {count} channels")
        self._selector = random_selector(self._f, self.n_outputs, seed, rows=self.order) \
            if selector is None else selector[: self.order].copy()
        self._depth = 2 * self._f if instruments == "past" else self._f
        m = self._depth * (self.n_inputs + self.n_outputs)
        self._R = np.zeros((m, m))
        self._keep = max(self._depth - 1, self._f)
        self._buf_u = np.zeros((0, self.n_inputs))
        self._buf_y = np.zeros((0, self.n_outputs))
        # the last samples, for the innovation covariance of the current model
        self._window = SampleWindow(self.n_inputs, self.n_outputs, window_size(self._lam))
        self._n_samples = 0
        self._n_columns = 0
        self._weight = 0.0            # sum of λ^k over the columns seen
        if history_size is not None:
            history_size = check_int(history_size, "history_size", minimum=2)
        self._history_size = history_size
        self._history_stride = check_int(history_stride, "history_stride")
        self._hist_sample = np.zeros(0, dtype=np.int64)
        self._hist_poles = np.zeros((0, self.order), dtype=complex)
        self._hist_abcd = np.zeros((0, self._abcd_size()))
        self._hist_t = np.zeros(0)
        self._model = None            # the current model, with its noise model
        self._plain = None            # the same without it (history snapshots)
        check_choice(bd_method, "bd_method", ONLINE_OPTIONS)
        if refresh_every is None:      # a quarter of the memory, within [50, 2000]
            memory = math.inf if self._lam == 1.0 else 1.0 / (1.0 - self._lam)
            refresh_every = int(min(2000, max(_FIRST_REFRESH, memory / 4)))
        self._refresh_every = check_int(refresh_every, "refresh_every")
        if isinstance(restart_tolerance, bool) or not isinstance(restart_tolerance,
                                                                 numbers.Real) \
                or not (math.isfinite(restart_tolerance) and restart_tolerance > 0):
            raise OptionError(f"restart_tolerance must be a positive number, got "
                              f"{restart_tolerance!r}")
        self._restart_tolerance = float(restart_tolerance)
        n, nu, ny = self.order, self.n_inputs, self.n_outputs
        self._nbd = n + n * nu + (ny * nu if self._feedthrough else 0)   # x0, B, D
        self._bd_R = np.zeros((self._nbd + 1, self._nbd + 1))
        self._bd_S = np.zeros((n, n + n * nu))
        self._bd_S_last = np.zeros((n, n + n * nu))
        self._bd_A = np.zeros((n, n))
        self._bd_C = np.zeros((ny, n))
        self._bd_started = False
        self._bd_start = 0            # sample index of x0 of the regression
        self._bd_rows = 0.0           # effective number of samples in the regression
        self._bd_restarts = 0
        self._lags = check_int(lags, "lags", maximum=MAX_DIMENSION)
        # forgetting 1: the exact batch regression from lagged statistics
        self._exact = self.bd_method == "simulation" and self._lam == 1.0
        self._lag = LaggedStatistic(nu, ny, self._lags) if self._exact else None

    # -- input ------------------------------------------------------------
    def __repr__(self) -> str:
        from subid._repr import recursive_repr
        return recursive_repr(self)

    def _repr_html_(self) -> str:
        """Summary for Jupyter: settings, samples seen and the current model."""
        from subid._repr import online_html, recursive_settings
        return online_html(self, recursive_settings(self))

    def _abcd_size(self) -> int:
        n, nu, ny = self.order, self.n_inputs, self.n_outputs
        return n * n + n * nu + ny * n + ny * nu

    @property
    def n_samples(self) -> int:
        """Samples received so far."""
        return self._n_samples

    @property
    def t(self) -> float | None:
        """Time of the latest sample (None before the first): ``dt`` times its
        index, or continuing the time stamps given to :meth:`update`."""
        if not self._n_samples:
            return None
        return self._t_origin + (self._n_samples - 1 - self._k_origin) * self._dt

    def _times(self, t, N: int):
        """Validate time stamps of a chunk of N samples: a uniform grid of step
        dt that continues the stream. Returns the time of its first sample."""
        T = np.asarray(t, dtype=np.float64).reshape(-1)
        T = check_time_stamps(T, N)
        check_stream_grid(T, self._dt, self.t, f"RecursiveSubspace is discrete-time with "
                          f"dt={self._dt!r}", "resample the data or create the identifier "
                          "with their dt")
        return float(T[0])

    def update(self, u, y=None, t=None) -> "RecursiveSubspace":
        """Add samples: one sample or a chunk (time on axis 0).

        Parameters
        ----------
        u : array_like or IOData
            (N, n_inputs), or a 1-D array of n_inputs values (one sample)
            when n_inputs > 1, or N samples when n_inputs == 1. An
            :class:`~subid.data.IOData` record supplies u, y (and its time
            stamps, if explicit); its dt must be the identifier's.
        y : array_like
            Outputs, likewise.
        t : array_like, optional
            Time stamps: a uniform grid of step ``dt`` continuing the stream
            (checked; the identifier is discrete-time).

        Returns
        -------
        self

        Raises
        ------
        subid.errors.DataError
            NaN or inf, wrong shapes, time stamps off the grid. A rejected
            chunk leaves the identifier unchanged.

        Notes
        -----
        The result does not depend on how a stream is cut into chunks (to
        rounding). An empty chunk (0 samples, with ``t`` None or empty, as a
        stream may deliver) is accepted and changes nothing, as in
        :meth:`subid.AdaptiveIdentifier.update`.
        """
        U = Y = None
        if t is None and type(u) is np.ndarray and type(y) is np.ndarray:
            # one sample as 1-D float64 arrays (a stream's usual call): views,
            # only read during this call (the buffers below copy them)
            U = one_sample(u, self.n_inputs)
            Y = None if U is None else one_sample(y, self.n_outputs)
        if Y is not None:
            u, y = U, Y
        else:
            u, y, t, _ = self._unpack(u, y, t)
            u = as_chunk(u, self.n_inputs, "input u", allow_empty=True, copy=True)
            y = as_chunk(y, self.n_outputs, "output y", allow_empty=True, copy=True)
        if u.shape[0] != y.shape[0]:
            raise DataError(f"input u has {u.shape[0]} samples but output y has {y.shape[0]}")
        if u.shape[0] == 0:           # an empty chunk: nothing to do (its t must be empty)
            if t is not None:
                check_time_stamps(np.reshape(t, -1) if np.ndim(t) else t, 0)
            return self
        t0 = None if t is None else self._times(t, u.shape[0])
        if t0 is not None:
            self._t_origin, self._k_origin = t0, self._n_samples
        # validated: from here on the state changes
        start = 0
        n = u.shape[0]
        regression = self.bd_method == "simulation" and not self._exact
        if self._lag is not None:
            self._lag.update(u, y)
        self._window.add(u, y)
        while start < n:
            stop = n if self._history_size is None else min(n, start + self._to_snapshot())
            if regression:
                stop = min(stop, start + self._to_refresh())
            self._ingest(u[start:stop], y[start:stop])
            if regression:
                self._bd_feed(u[start:stop], y[start:stop])
                if self._is_refresh_point():
                    self._bd_refresh()
            start = stop
            if self._history_size is not None and self._n_samples % self._history_stride == 0:
                self._snapshot()
        return self

    # -- the recursive output-error regression of B, D, x0 -------------------
    def _is_refresh_point(self) -> bool:
        """Refresh points: _FIRST_REFRESH * 2^j below ``refresh_every`` (so
        that the regression starts early), then the multiples of
        ``refresh_every``."""
        k, K = self._n_samples, self._refresh_every
        if k <= 0:
            return False
        if k % K == 0:
            return True
        j = k // _FIRST_REFRESH
        return k < K and k % _FIRST_REFRESH == 0 and j & (j - 1) == 0

    def _to_refresh(self) -> int:
        """Samples to the next refresh point (points: _FIRST_REFRESH * 2^j
        below ``refresh_every``, then the multiples of ``refresh_every``)."""
        k = self._n_samples
        step = _FIRST_REFRESH
        while step <= k and step < self._refresh_every:
            step *= 2
        nxt = step if step < self._refresh_every else (k // self._refresh_every + 1) \
            * self._refresh_every
        return nxt - k

    def _bd_feed(self, u, y):
        """Regression rows of the chunk (model (A, C) of the last refresh),
        reduced into the factor by Givens rotations with the forgetting
        (λ per sample: λ^(1/ny) per row)."""
        if not self._bd_started:
            return
        A, C = self._bd_A, self._bd_C
        T = u.shape[0]
        if T > 1:
            rows0, S = regression_rows(A, C, u[:-1], y[:-1], self._bd_S, n_x0=self.order,
                                       feedthrough=self._feedthrough)
            givens_update(self._bd_R, rows0, self._lam ** (0.5 / self.n_outputs))
        else:
            S = self._bd_S
        self._bd_S_last = S
        rows1, S = regression_rows(A, C, u[-1:], y[-1:], S, n_x0=self.order,
                                   feedthrough=self._feedthrough)
        givens_update(self._bd_R, rows1, self._lam ** (0.5 / self.n_outputs))
        self._bd_S = S
        lam = self._lam
        self._bd_rows = self._bd_rows * lam ** T + (
            T if lam == 1.0 else (1 - lam ** T) / (1 - lam))

    def _a_c(self):
        """(A, C) of the current factor in the basis of Λ (raises SubidError
        when the data do not yet determine them)."""
        need = min_samples(self._depth, self.n_inputs, self.n_outputs)
        if self._n_samples < need:
            raise TooFewSamplesError("too few samples")
        hf = self.factor()
        check_excitation(hf, self._input_names, method="RecursiveSubspace")
        core, su, sy = self._core(hf, "RecursiveSubspace")
        A, _, C, _ = core.to_selector_basis(np.zeros((self.order, self.n_inputs)))
        return A, C * sy[:, None]

    def _core(self, hf, method):
        """Seed 001 on the current factor as the batch method computes it: channels
        normalised by their RMS, Λ acting on the user's units (``Λ (I ⊗ S)`` on the
        normalised outputs). Returns ``(core, input_scale, output_scale)``."""
        hf_n, su, sy = normalize_channels(hf, outputs=True)
        core = gamma_from_factor(hf_n, self._f, self.order, [self.order],
                                 instruments=self.instruments,
                                 instrument_weighting=self._instrument_weighting,
                                 selector=self._selector * np.tile(sy, self._f),
                                 seed=self.seed, power_iterations=self._power_iterations,
                                 method=method)
        return core, su, sy

    def _bd_refresh(self):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                A, C = self._a_c()
        except SubidError:
            return
        if not (np.isfinite(A).all() and np.isfinite(C).all()):
            return
        if self._bd_started:
            change = (np.linalg.norm(A - self._bd_A) / max(np.linalg.norm(self._bd_A), 1e-300)
                      + np.linalg.norm(C - self._bd_C) / max(np.linalg.norm(self._bd_C),
                                                             1e-300))
            if change <= self._restart_tolerance:
                self._bd_A, self._bd_C = A, C
                return
        n = self.order
        self._bd_A, self._bd_C = A, C
        self._bd_R[:] = 0.0
        self._bd_S = np.zeros((n, n + n * self.n_inputs))
        self._bd_S[:, :n] = np.eye(n)
        self._bd_S_last = self._bd_S.copy()
        self._bd_started = True
        self._bd_start = self._n_samples
        self._bd_rows = 0.0
        self._bd_restarts += 1

    def _to_snapshot(self) -> int:
        return self._history_stride - self._n_samples % self._history_stride

    def _ingest(self, u, y):
        keep = self._keep
        if u.shape[0] == 1 and self._buf_u.shape[0] == keep:
            # one sample with a full buffer (keep >= depth - 1): the one new
            # Hankel column is the last depth samples; the same values and
            # operations as below, without stacking the buffers twice
            bu, by = self._buf_u, self._buf_y
            first = keep - self._depth + 1
            row = np.concatenate((bu[first:].reshape(-1), u.reshape(-1),
                                  by[first:].reshape(-1), y.reshape(-1)))[None]
            givens_update(self._R, row, math.sqrt(self._lam))
            self._add_columns(1)
            self._buf_u = np.concatenate((bu[1:], u))
            self._buf_y = np.concatenate((by[1:], y))
            self._n_samples += 1
            self._model = self._plain = None
            return
        all_u = np.concatenate((self._buf_u, u))
        all_y = np.concatenate((self._buf_y, y))
        # the buffer may hold more than depth - 1 samples (the last horizon, for
        # the state): the columns that start before its last depth - 1 samples
        # were counted by the previous chunk
        first = max(self._buf_u.shape[0] - self._depth + 1, 0)
        columns = all_u.shape[0] - self._depth + 1
        lam_sqrt = math.sqrt(self._lam)
        for a in range(first, max(columns, first), _CHUNK):
            b = min(a + _CHUNK, columns)
            rows = hankel_chunk(all_u, all_y, self._depth, a, b)
            givens_update(self._R, rows, lam_sqrt)
        columns -= first
        if columns > 0:
            self._add_columns(columns)
        self._buf_u = all_u[-self._keep:].copy()
        self._buf_y = all_y[-self._keep:].copy()
        self._n_samples += u.shape[0]
        self._model = self._plain = None

    def _add_columns(self, columns: int) -> None:
        """Count ``columns`` new Hankel columns (and their weight)."""
        lam = self._lam
        self._weight = self._weight * lam ** columns + (
            columns if lam == 1.0 else (1 - lam ** columns) / (1 - lam))
        self._n_columns += columns

    def _snapshot(self):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)
                m = self._deterministic()        # no noise model: A, B, C, D only
                poles = m.poles()
        except SubidError:
            return
        abcd = np.concatenate([m.A.ravel(), m.B.ravel(), m.C.ravel(), m.D.ravel()])
        self._hist_sample = np.append(self._hist_sample, self._n_samples)
        self._hist_t = np.append(self._hist_t, self.t)
        self._hist_poles = np.vstack([self._hist_poles, poles[None]])
        self._hist_abcd = np.vstack([self._hist_abcd, abcd[None]])
        if self._hist_sample.size >= self._history_size:
            self._hist_sample = self._hist_sample[1::2]
            self._hist_t = self._hist_t[1::2]
            self._hist_poles = self._hist_poles[1::2]
            self._hist_abcd = self._hist_abcd[1::2]
            self._history_stride *= 2

    # -- output -----------------------------------------------------------
    def factor(self) -> HankelFactor:
        """The current (weighted, normalised) Hankel factor, as the batch path uses."""
        L = self._R.T / math.sqrt(max(self._weight, 1e-300))
        signs = np.sign(np.diag(L))
        signs[signs == 0] = 1.0
        return HankelFactor(L=L * signs, depth=self._depth, n_inputs=self.n_inputs,
                            n_outputs=self.n_outputs, n_columns=self._n_columns)

    @property
    def model(self) -> StateSpace:
        """The current model (discrete time, dt of the identifier).

        With instruments (``'past'``), the model is in innovation form: ``K`` is
        estimated on the running Hankel factor by
        :func:`subid.methods.dt.noise_model.with_factor` (state sequences and the
        Kalman filter Riccati equation, no SVD), ``noise_cov`` is the covariance of
        this model's one-step prediction errors on the last samples of the stream
        (:mod:`subid.methods.online._window`: 10,000 with forgetting 1, three memories
        ``1 / (1 - λ)`` otherwise; the Riccati covariance it replaced was 5e4-1.8e7x
        that on DaISy robot_arm).

        Raises
        ------
        TooFewSamplesError
            Fewer samples than one full-rank data matrix needs.
        NotExcitingError
            The (weighted) input data are not exciting enough.
        """
        if self._model is None:
            plain = self._deterministic()
            # K from the running factor, noise_cov from the current model's prediction
            # errors on the last samples (the window)
            self._model = noise_model.with_factor(
                plain, self.factor(), data=self._window.record(self._dt)) \
                if self.instruments == "past" else plain
        return self._model

    def _deterministic(self) -> StateSpace:
        """The current model without its noise model (what :attr:`model` adds to it,
        and all a history snapshot records); raises as :attr:`model` does."""
        if self._plain is not None:
            return self._plain
        method = "RecursiveSubspace"
        need = min_samples(self._depth, self.n_inputs, self.n_outputs)
        if self._n_samples < need:
            raise TooFewSamplesError(f"{method} has received {self._n_samples} samples; a model "
                                     f"needs at least {need} (horizon {self._f})")
        hf = self.factor()
        input_condition = check_excitation(hf, self._input_names, method=method)
        core, su, sy = self._core(hf, method)
        bd_method, reg, self._theta = "projection", {}, None
        A, _, C, _ = core.to_selector_basis(np.zeros((self.order, self.n_inputs)))
        C = C * sy[:, None]
        reason = issued = None
        if self._exact:
            reason, solved = self._exact_b_d(core, sy)
            if solved is not None:
                B_q, D, x0_q, theta, reg = solved
                A, B, C, x0 = core.to_selector_basis(B_q, x0_q)
                C = C * sy[:, None]
                bd_method, self._theta = "simulation", theta
                self._exact_basis = (core.A_q, core.T)
                reg["x0"] = x0
            if reason is not None:
                issued = f"{method}: {reason}" + (
                    "" if solved is not None else
                    "; B and D come from the projected data equation (less accurate)")
                warnings.warn(issued, NotConvergedWarning, stacklevel=2)
        elif self.bd_method == "simulation":
            if not self._bd_started:
                reason = ("the B, D regression has not started (no refresh with a usable "
                          "model yet)")
            elif self._bd_rows * self.n_outputs < self._nbd:
                reason = (f"the B, D regression has {self._bd_rows:.0f} samples, fewer than "
                          f"its {self._nbd} unknowns")
            else:
                B, D, x0, reg = fit_b_d_x0(
                    self._bd_A, self._bd_C,
                    Accumulated("factor", self._bd_R, self.n_inputs, max(self._bd_rows, 1.0)),
                    feedthrough=self._feedthrough)
                theta = reg.pop("theta")
                if reg["regression_rank_deficient"] or not np.isfinite(theta).all():
                    reason = "the B, D regression is rank deficient"
                else:
                    bd_method, self._theta = "simulation", theta
                    reg.update(x0=x0, bd_start_sample=self._bd_start,
                               bd_restarts=self._bd_restarts)
            if reason is not None:
                issued = (f"{method}: {reason}; B and D come from the projected data "
                          "equation (less accurate)")
                warnings.warn(issued, NotConvergedWarning, stacklevel=2)
        if bd_method == "projection":
            B_q, D, _, reg2 = fit_b_d_x0(
                core.A_q, core.C_q, None, bd_method="projection", feedthrough=self._feedthrough,
                projection=Projection(core.C_q, core.basis, core.L11, core.L_yu,
                                      lambda B_n, C_n, D_n: (B_n, C_n, D_n)))
            A, B, C, _ = core.to_selector_basis(B_q)
            # from the normalised channels to the user's units
            B, C, D = B / su, C * sy[:, None], D * sy[:, None] / su
            reg = {**reg, **reg2}
        extra = {"forgetting": self._lam,
                 "effective_samples": self._weight, "input_condition": input_condition,
                 INFO_KEY: bd_method,
                 "bd_fallback": reason if bd_method == "projection" else None,
                 "converged": reason is None,
                 "convergence": "converged" if reason is None else reason,
                 **core.info(self.instruments, self._instrument_weighting,
                             self._power_iterations), **reg,
                 "selector": self._selector.copy()}
        x0 = extra.pop("x0", None)
        for key in ("order", "order_selection", "horizon"):
            extra.pop(key, None)
        info = model_info(method, order=self.order, horizon=self._f,
                          n_samples=self._n_samples, x0=x0, hold="zoh",
                          conditions=conditions_of(extra),
                          warnings=[issued] if issued else [], **extra)
        self._plain = StateSpace(A, B, C, D, self._dt, input_names=self._input_names,
                                 output_names=self._output_names, info=info)
        return self._plain

    def _exact_b_d(self, core, sy):
        """Forgetting 1: B, D, x0 of the batch output-error regression for the
        current (A, C), from the lagged statistics (:mod:`subid.methods.online._lagged`),
        solved in the orthonormal basis of the estimate (``core.A_q``, as the
        batch method; the basis of Λ can be badly conditioned) and returned
        in it. Returns ``(reason, solved)``: ``solved`` is None when the
        regression cannot be evaluated (unstable A, singular), ``reason`` a
        warning text or None."""
        nu = self.n_inputs
        A, C = core.A_q, core.C_q * sy[:, None]
        if not (np.isfinite(A).all() and np.isfinite(C).all()):
            return "the estimated (A, C) are not finite", None
        radius = float(np.abs(np.linalg.eigvals(A)).max())
        if radius >= 1.0:
            return (f"the estimated A is not stable (spectral radius {radius:.4g}), so the "
                    "B, D regression is not evaluated"), None
        stat = self._lag.flushed()           # reading leaves the statistic as it is
        weights = stat.output_weights()
        Nmat, truncation = stat.normal_equations(A, C, weights, feedthrough=self._feedthrough)
        fitted = fit_b_d_x0(A, C, Accumulated("normal", Nmat, nu, self._n_samples),
                            feedthrough=self._feedthrough)
        if fitted is None:
            return "the B, D regression is rank deficient", None
        B, D, x0, diag = fitted
        solved = (B, D, x0, diag.pop("theta"), diag)
        diag.update(bd_truncation=truncation, spectral_radius=radius)
        reason = None
        if truncation > _TRUNCATION_WARN:
            reason = (f"the B, D regression resolves {self._lags} lags but A^{self._lags + 1} "
                      f"still has norm {truncation:.1e} (spectral radius {radius:.4g}): B "
                      f"and D are approximate; use lags >= "
                      f"{int(math.ceil(math.log(1e-16) / math.log(radius)))}")
        return reason, solved

    @property
    def state(self) -> np.ndarray:
        """State estimate at the latest sample, in the basis fixed by Λ.

        With the B, D regression: ``x(t) = S(t) [x0; vec B]``, the state of
        the regression's output-error model at the latest sample. Otherwise
        from the last ``horizon`` samples, ``x̄(t-f+1) = Λ (y_f - H_f u_f)``
        (seed 001, eq. (21)), then propagated through the model to time t.
        """
        model = self.model
        if model.info[INFO_KEY] == "simulation" and self._exact:
            A, T = self._exact_basis
            stat = self._lag.flushed()
            t_end = self._n_samples - 1
            powers = np.empty((min(t_end, self._lags + 1) + 1, self.order, self.order))
            powers[0] = np.eye(self.order)
            for d in range(1, powers.shape[0]):
                powers[d] = powers[d - 1] @ A
            S = end_sensitivity(stat, A, powers, t_end)
            return T @ (S @ self._theta[:self.order + self.order * self.n_inputs])
        if model.info[INFO_KEY] == "simulation":
            k = self.order + self.order * self.n_inputs
            return self._bd_S_last @ self._theta[:k]
        f, ny, nu = self._f, self.n_outputs, self.n_inputs
        u_w, y_w = self._buf_u[-f:], self._buf_y[-f:]
        markov = model.markov(f)                       # D, CB, ..., C A^{f-2} B
        H = np.zeros((f * ny, f * nu))
        for i in range(f):
            for j in range(i + 1):
                H[i * ny:(i + 1) * ny, j * nu:(j + 1) * nu] = markov[i - j]
        x = self._selector @ (y_w.reshape(-1) - H @ u_w.reshape(-1))
        for k in range(f - 1):
            x = model.A @ x + model.B @ u_w[k]
        return x

    @property
    def history(self) -> dict:
        """Decimated snapshots ``{'sample', 'poles'}`` (bounded in size)."""
        n, nu, ny = self.order, self.n_inputs, self.n_outputs
        rows = self._hist_abcd
        mats, c = {}, 0
        for name, shape in (("A", (n, n)), ("B", (n, nu)), ("C", (ny, n)), ("D", (ny, nu))):
            mats[name] = rows[:, c:c + shape[0] * shape[1]].reshape((-1,) + shape)
            c += shape[0] * shape[1]
        out = history_dict(self._hist_sample, self._hist_t, dt=self._dt, **mats)
        out["poles"] = self._hist_poles.copy()     # those of the models (as computed then)
        return out

    @property
    def selector(self) -> np.ndarray:
        """The matrix Λ that fixes the state basis."""
        return self._selector.copy()

    # -- checkpoints --------------------------------------------------------
    def save(self, path) -> None:
        """Write the whole state to ``path`` (``.npz``, atomic, no pickle)."""
        settings = {
            "order": self.order, "n_inputs": self.n_inputs, "n_outputs": self.n_outputs,
            "horizon": self.horizon, "forgetting": self._lam,
            "instruments": self.instruments, "instrument_weighting": self._instrument_weighting,
            "power_iterations": self._power_iterations, "feedthrough": self._feedthrough,
            "dt": self._dt, "seed": self.seed if isinstance(self.seed, int) else None,
            "n_samples": self._n_samples, "n_columns": self._n_columns, "weight": self._weight,
            "history_size": self._history_size, "history_stride": self.history_stride,
            "history_stride_now": self._history_stride,
            "input_names": None if self.input_names is None else list(self.input_names),
            "output_names": None if self.output_names is None else list(self.output_names),
            "bd_method": self.bd_method, "refresh_every": self.refresh_every,
            "restart_tolerance": self._restart_tolerance, "bd_started": self._bd_started,
            "bd_start": self._bd_start, "bd_rows": self._bd_rows,
            "bd_restarts": self._bd_restarts, "lags": self._lags, "exact": self._exact,
            "t_origin": self._t_origin, "k_origin": self._k_origin,
            "lag_pending_count": 0 if self._lag is None else self._lag.n_pending,
        }
        arrays = {"R": self._R, "buf_u": self._buf_u, "buf_y": self._buf_y,
                  "bd_R": self._bd_R, "bd_S": self._bd_S, "bd_S_last": self._bd_S_last,
                  "bd_A": self._bd_A, "bd_C": self._bd_C,
                  "selector": self._selector, "hist_sample": self._hist_sample,
                  "hist_poles_re": self._hist_poles.real, "hist_poles_im": self._hist_poles.imag,
                  "hist_t": self._hist_t, "hist_abcd": self._hist_abcd}
        arrays["window_u"], arrays["window_y"] = self._window.ordered()
        if self._lag is not None:
            arrays.update(self._lag.arrays())
        save_state(path, self.checkpoint_kind(), self._VERSION, arrays, settings)

    @classmethod
    def load(cls, path) -> "RecursiveSubspace":
        """Restore an identifier saved by :meth:`save`."""
        arrays, s = load_state(path, cls._kinds(), cls._READS)
        try:
            obj = cls(s["order"], s["n_inputs"], s["n_outputs"], horizon=s["horizon"],
                      forgetting=s["forgetting"], instruments=s["instruments"],
                      selector=require(arrays, path, "selector"), seed=s["seed"] or 0,
                      instrument_weighting=s["instrument_weighting"],
                      power_iterations=s["power_iterations"], feedthrough=s["feedthrough"],
                      dt=s["dt"], history_size=s["history_size"],
                      history_stride=s["history_stride"],
                      input_names=s.get("input_names"), output_names=s.get("output_names"),
                      bd_method=("simulation" if s["_version"] < 4 and
                                 s["bd_method"] == "regression" else s["bd_method"]),
                      refresh_every=s["refresh_every"],
                      restart_tolerance=s["restart_tolerance"], lags=s.get("lags", 1000))
            if not s.get("exact", False):
                # version 2 (or forgetting < 1): the propagated regression
                obj._exact, obj._lag = False, None
            else:
                lag = obj._lag
                for name, ref in lag.arrays().items():
                    ref[...] = require(arrays, path, name, ref.shape)
                n_pending = int(s.get("lag_pending_count", 0))
                lag.count = int(s["n_samples"]) - n_pending
                lag.n_pending = n_pending
            for name in ("bd_R", "bd_S", "bd_S_last", "bd_A", "bd_C"):
                ref = getattr(obj, "_" + name)
                setattr(obj, "_" + name, require(arrays, path, name, ref.shape).copy())
            obj._bd_started = bool(s["bd_started"])
            obj._bd_start = int(s["bd_start"])
            obj._bd_rows = float(s["bd_rows"])
            obj._bd_restarts = int(s["bd_restarts"])
            m = obj._R.shape[0]
            obj._R = require(arrays, path, "R", (m, m)).copy()
            obj._buf_u = require(arrays, path, "buf_u").reshape(-1, obj.n_inputs).copy()
            obj._buf_y = require(arrays, path, "buf_y").reshape(-1, obj.n_outputs).copy()
            obj._n_samples = int(s["n_samples"])
            obj._history_stride = int(s.get("history_stride_now", s["history_stride"]))
            obj._n_columns = int(s["n_columns"])
            obj._weight = float(s["weight"])
            obj._hist_sample = require(arrays, path, "hist_sample", dtype=np.int64)
            obj._hist_poles = (require(arrays, path, "hist_poles_re")
                               + 1j * require(arrays, path, "hist_poles_im"))
            k = obj._hist_sample.size
            if s["_version"] >= 3:
                obj._hist_t = require(arrays, path, "hist_t", (k,)).copy()
                obj._hist_abcd = require(arrays, path, "hist_abcd",
                                         (k, obj._abcd_size())).copy()
            else:        # version 2 kept the poles only: times from dt, no matrices
                obj._hist_t = (obj._hist_sample - 1) * obj._dt
                obj._hist_abcd = np.full((k, obj._abcd_size()), np.nan)
            if s["_version"] >= 5:       # version 4 and before kept no window
                obj._window.restore(
                    require(arrays, path, "window_u").reshape(-1, obj.n_inputs),
                    require(arrays, path, "window_y").reshape(-1, obj.n_outputs))
            obj._t_origin = float(s.get("t_origin", 0.0))
            obj._k_origin = int(s.get("k_origin", 0))
        except CheckpointError:
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"checkpoint {path} is inconsistent: {exc}",
                                  path=str(path)) from None
        return obj
