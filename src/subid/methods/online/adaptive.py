"""Adaptive identification of continuous-time MIMO state-space models (seed 000).

Afri, Bako, Andrieu, Dufour, "Adaptive identification of continuous time
MIMO state-space models", CDC 2015. From sampled inputs and outputs,
:class:`AdaptiveIdentifier` estimates online a continuous-time realization
``(Ã, B̃, C̃, D)`` in the state basis fixed by a selector matrix H, and the
filtered state ``x̃``. No SVD is computed. Details, measurements and the
corrections to the paper: ``docs/seed000.md``.

Method (equation numbers of the paper)
--------------------------------------
* State-variable filters (6a)-(6b) with ``F(s) = 1/d(s)``, ``deg d = f``
  (the horizon), give ``p = F(s) [y; y'; ...; y^(f-1)]`` and ``q`` likewise
  for u, with ``p = O_f x̄ + T_f q`` (6c), ``x̄ = F(s) x``.
* With ``T = H O_f`` and ``x̃ = T x̄``, ``p = M φ`` (8) with
  ``M = [Õ_f, (I - Õ_f H) T_f]`` (9) and ``φ = [H p; q]`` (10). M is the
  exponentially weighted least-squares estimate (cost V_t, forgetting
  rate α = ``forgetting``); ``C̃ = M11`` and ``Ã`` by shift invariance (13).
* With ``Ψ' = Ψ (I ⊗ Ã) + u^T ⊗ C̃`` (15), ``y = Φ θ`` (16)-(18),
  ``Φ = [Ψ, u^T ⊗ I]``, ``θ = [vec B̃; vec D]`` is a second weighted
  least-squares estimate (forgetting rate β = ``bd_forgetting``).
* The state is ``x̃ = H (p - T_f q)``, a filtered version of ``T x``.

Sampled data
------------
Between samples the signals are held: linear interpolation (first-order
hold, default) or constant (``hold='zoh'``). The filters and Ψ are
propagated by the exact discretisation of their ODEs for the held signals
(:func:`subid.model._simulate.expm_blocks`), so ``p``, ``q`` and ``Ψ`` at the
sample instants are exact for the held signals, whatever the sampling
period, uniform or not. The integrals of V_t are evaluated on the sample
grid (weight ``h_k``, the interval ending at sample k).

Numerics (beyond the paper)
---------------------------
* Time-scaled filter states. With ``ω = |d(0)|^{1/f}`` (the geometric mean
  of the filter pole magnitudes) the filter runs on
  ``p̂_k = ω^{-k} s^k F̂(s) y``, ``F̂ = ω^f / d(s)`` (unit DC gain), i.e. the
  paper's method applied to the time-scaled system ``(A/ω, B/ω, C, D)``:
  ``p̂ = O_f(A/ω, C) F̂ x + T_f(A/ω, B/ω, C, D) q̂``, and (13) returns
  ``Ã/ω``. In the paper's coordinates (``scale_filters=False``) the normal
  matrix of (8) has condition 3.5e9 on the paper's example with filter
  poles at -5 (1.6e11 at -10); scaled, 3.2e6 (``info['condition']``).
* Exact minimisers of V_t instead of an integration of (11)-(12): the
  information form ``R_k = λ_k R_{k-1} + w_k φ_k φ_k^T`` (``λ_k =
  e^{-α h_k}``, ``w_k = h_k / r_k^2``, ``R_0 = P0^{-1}``) with the cross
  term held as ``G = S - M R`` (the gradient at the current estimate,
  updated with the prediction error, so that rounding scales with the
  residual), solved by Cholesky every ``refresh_every`` samples; the same
  for θ. ``method='ode'`` integrates the paper's (11)-(12), (19)-(20)
  instead (semi-implicit Euler), for comparison.
* Normalisation ``r^2 = 1 + |φ|^2`` and ``ρ^2 = 1 + |Φ|_F^2`` (P-free: with
  a P-dependent r, ``d/dt log det R < 1 - α dim φ`` and the information
  cannot outgrow the prior for the paper's α; ``'ode'`` keeps ρ of (20)).
  The 1 fixes a signal size: the estimates depend on the units (docs/seed000.md).
* Windup bound: ``M <- (S + δ M̄)(R + δ I)^{-1}``, ``δ = tr(R) /
  max_condition``, M̄ the previous estimate (proximal term): the solved
  matrix has condition at most ``1 + max_condition``, the estimate is held
  in directions the data no longer excite, and M̄ = M is the fixed point
  (noise-free estimates stay exact). ``'ode'``: forgetting suspended while
  ``tr P > ode_trace_bound`` (Ioannou & Sun, Robust Adaptive Control, 4.3.6).
* Part 2 ((B̃, D)) starts "once the first part has converged" (Section V):
  when the regression (8) is persistently exciting (its weakest direction
  carries at least ``1/max_condition`` of the information, by inverse
  iteration on the factor of the solve; issue 23), Ã is Hurwitz (A1), and
  the relative residual of the shift equation (13) is below ``bd_gate`` or
  has stopped halving (no halving for as long as it took to reach its last
  halving, at most ``1/α``: a consistent estimate's noise floor falls like
  ``t^{-1/2}``, so it halves at four times the elapsed time; issue 23). Ψ
  then starts from 0, and the initial-state term ``C̃ e^{Ã(t - t_g)} x̃(t_g)``
  of (14)/(16), which (19)-(20) drop, is kept as a regressor. Ψ only uses
  estimates that pass the same test.
* Start-up schedule of β (``bd_startup`` κ, issue 23): the rows of (16) are
  built from the (Ã, C̃) of their time, whose error falls as part 1's memory
  fills; θ weighs them by ``e^{-∫ β_eff}``, ``β_eff = max(β, κ / (t - t_g))``,
  i.e. ``((τ - t_g) / (t - t_g))^κ`` while ``t - t_g < κ / β``: the memory of θ
  grows in proportion to the age of part 2, so that the rows of the first
  seconds do not stay in θ for ``1/β``.
"""

from __future__ import annotations

import math
import numbers
import warnings

import numpy as np

from subid._validation import (
    check_bool,
    check_choice,
    check_int,
    check_seed,
    check_selector,
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
from subid.methods._common import conditions_of
from subid.methods._info import model_info
from subid.methods.dt.ls_subspace import random_selector
from subid.methods.online import _adaptive_filters as _filters
from subid.methods.online import _adaptive_kernel as _k
from subid.methods.online import _adaptive_refine as _refit_mod
from subid.methods.online._adaptive_chunk import parse_chunk
from subid.methods.online._adaptive_kernel import pack_tables, state_layout
from subid.methods.online._adaptive_reference import reference
from subid.methods.online.base import (
    OnlineIdentifier,
    check_state_bytes,
    history_dict,
    one_sample,
)
from subid.model.statespace import StateSpace

__all__ = ["AdaptiveIdentifier"]

_OLD_KIND = "AdaptiveIdentifier"     # the kind of checkpoints before subid.<Class>
_VERSION = 4      # 2: instrumental variables (zr, Cz, Gz); 3: t_first, bd_startup; 4: Ev
# Step lengths handled in one kernel call when the time stamps are non-uniform
# (bounds the memory of the per-step discretisation tables).
_BLOCK_UNIQUE = 4096
_BLOCK_SAMPLES = 16384
# Default instrument filter of method 'iv': the filter poles times this ratio
# (slower: instruments that remember more of the input's past).
_INSTRUMENT_POLE_RATIO = 0.25
# Default (forgetting, bd_forgetting) per method. 'ls' and 'ode': the paper's
# noise-free values. 'iv': a long memory for M (the IV estimate is unbiased
# under noise, so averaging pays: measured in docs/seed000.md); bd_forgetting
# None = tied to the forgetting actually used (ratio _IV_BD_RATIO): θ is
# regressed on Ψ, built from the current (Ã, C̃), so a memory for θ shorter
# than that of M buys tracking that (Ã, C̃) cannot follow, at a variance of θ
# proportional to bd_forgetting (exponentially weighted LS: covariance ≈
# β/2 · noise variance · inverse regressor covariance); a longer one would
# mix in rows built from (Ã, C̃) that M itself has forgotten.
_DEFAULT_FORGETTING = {"iv": (0.002, None), "ls": (0.4, 0.08), "ode": (0.4, 0.08)}
_IV_BD_RATIO = 1.0
# Start-up schedule of the (B̃, D) memory ('iv'): β_eff = max(β, κ / age), age =
# time since part 2 started (measured in docs/seed000.md).
_DEFAULT_BD_STARTUP = 4.0
# No refit where the estimated SNR exceeds this on every output (the error left is then the
# deterministic interpolation error, which the noise weighting does not describe; docs)
_SNR_SKIP = 70.0
_NON_FINITE = ("the chunk drove the identifier to non-finite values (are the signals scaled "
               "to moderate magnitudes?); it was rejected and the identifier is unchanged")


def _positive(value, name: str, *, exc=SubidError) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise exc(f"{name} must be a positive number, got {value!r}")
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise exc(f"{name} must be a finite positive number, got {value!r}")
    return value


#: The end of both not-converged reasons: the regressions' normalisation 1 + |phi|^2 fixes
#: a signal size, so channels far from size one (an input in other units: fits of -1.8 %
#: where the same record gives 95 %) look like a poor input too.
_UNITS_CURE = (". Channels far above size one hold it back too (1 + |phi|^2 is not "
               "unit-free): data.scaled(...) or remove their offsets")


class AdaptiveIdentifier(OnlineIdentifier):
    """Online identification of a continuous-time state-space model (seed 000).

    An :class:`~subid.methods.online.base.OnlineIdentifier`: the settings below are
    stored unchanged as attributes of the same names (:meth:`get_params`).

    Parameters
    ----------
    order : int
        Model order n.
    n_inputs, n_outputs : int
        Numbers of input and output channels.
    horizon : int, optional
        f, the number of derivatives in (2) and the order of the filter
        ``F(s) = 1/d(s)``. Needs ``(f - 1) n_outputs >= n`` for (13), and
        ``> n`` for the residual of (13) to measure convergence (the gate of
        part 2). Default: the smallest ``f > n`` (the paper's condition)
        with ``(f - 1) n_outputs > n``. The input must be sufficiently rich
        of order ``f + n`` (Theorem 1).
    filter_poles : float or sequence of complex
        Poles of ``F(s)``: one negative number (repeated f times) or f poles
        with negative real parts. Choose them a little faster than the system
        (about 1-3 times its fastest pole of interest): much slower filters
        hide the fast modes, much faster ones pass more noise and make the
        regression less well conditioned. The default -5 suits systems with
        time constants around 0.3-10 s (the paper's example).
    forgetting : float, optional
        α of V_t and (12), in 1/time unit: the estimate of M averages the
        last ``~1/α`` time units of data. The paper uses 0.4 noise-free and
        0.01 with 50 dB noise; choose ``1/α`` of at least a few of the
        slowest time constants, longer with noise. Default 0.002 for
        ``'iv'`` (unbiased, so a long memory pays), 0.4 otherwise.
    bd_forgetting : float, optional
        β of (20), the same for (B̃, D). The paper takes it smaller than α
        (0.08 and 0.008). Default for ``'iv'``: equal to the forgetting used
        (0.002 with the default forgetting), i.e. θ and M have the same
        memory: θ is regressed on Ψ, built from the current (Ã, C̃), so a
        shorter memory only buys tracking that (Ã, C̃) cannot follow, at a
        variance of θ proportional to β (measured in ``docs/seed000.md``).
        0.08 for ``'ls'`` and ``'ode'`` (the paper's noise-free value).
    selector : array_like, shape (order, horizon * n_outputs), optional
        H, which fixes the state basis (``T = H O_f``, applied to the scaled
        ``p̂`` when ``scale_filters``). Default: uniform random on [-1, 1]
        from ``seed`` (:func:`subid.ls_subspace.random_selector`).
    seed : int
        Seed of the default selector.
    dt : float, optional
        Sampling period used when :meth:`update` gets no time stamps: the
        first sample is at t = 0 (or after the last time stamp given).
    hold : {'foh', 'zoh'}
        Inter-sample behaviour of u and y: linear (first-order hold) or
        constant (zero-order hold).
    method : {'iv', 'ls', 'ode'}
        ``'iv'`` (default): the regression (8) by instrumental variables built
        from the input only (consistent under output noise; see
        ``docs/seed000.md``), (16) by least squares. ``'ls'``: the paper's
        estimator, exact exponentially weighted least squares (information
        form, Cholesky solves; biased under output noise). ``'ode'``: Euler
        integration (semi-implicit:
        the downdate in Sherman-Morrison form, so that P stays positive
        definite) of the paper's (11)-(12) and (19)-(20), for comparison; it
        converges much more slowly (see ``docs/seed000.md``).
    scale_filters : bool
        Run the filters in time-scaled coordinates (see the module notes).
    refresh_every : int
        Samples between solves of the normal equations, (13) and updates of
        the Ψ model; keep ``refresh_every * dt`` small against the time
        constants. The per-sample work is O(d^2); a refresh costs O(d^3).
    bd_gate : float
        Part 2 ((B̃, D) estimation) starts when the relative residual of the
        shift equation (13) falls below ``bd_gate`` (or stops improving for
        ``1/α``, see the module notes) and Ã is Hurwitz.
    max_condition : float
        Windup bound: the regularised information matrices solved at a
        refresh have condition numbers at most ``1 + max_condition``.
    initial_covariance, bd_initial_covariance : float, optional
        P(0) = ``initial_covariance`` I and Q(0) = ``bd_initial_covariance``
        I. Default 1e12 for ``'ls'`` (a negligible prior: the regression's
        weakest direction carries ~1e-7 of the information), 1 for ``'ode'``
        (the paper's P(0) = I). M(0) = 0, θ(0) = 0, Ψ(0) = 0.
    ode_trace_bound : float
        ``'ode'`` only: forgetting is suspended while tr P (tr Q) exceeds it.
    history_size : int
        Capacity of the opt-in history of estimates (0: none). One row per
        refresh until full; then every other row is dropped and the stride
        doubles, so the history spans the whole run in bounded memory.
    engine : {'numba', 'numpy'}
        ``'numpy'`` runs the plain reference loop (slow; for verification).
    input_names, output_names : sequence of str, optional
        Channel names of the model.
    instrument_poles : float or sequence of complex, optional
        ``'iv'``: poles of the second state-variable filter that makes
        instruments from the input (one negative number repeated ``horizon``
        times, or any number ``m`` of poles with ``m * n_inputs >= order``).
        Default 0.25 times ``filter_poles``. Must differ from the filter
        poles.
    max_gap : float, optional
        An interval between samples longer than this is a gap: the filters
        restart at the new sample (held signals over a gap are not data) and
        (14) restarts; the information decays by ``e^{-α h}``. Default ten
        filter time constants, ``10 / |d(0)|^{1/f}`` (2 s for poles at -5).
    bd_startup : float, optional
        κ of the start-up schedule of the (B̃, D) memory:
        ``β_eff = max(bd_forgetting, κ / age)``, age = time since part 2
        started, so that θ forgets the rows built from the early, poorer
        (Ã, C̃) (see the module notes). 0 turns it off (the issue-12
        estimator). Default 4 for ``'iv'``, 0 for ``'ls'`` and ``'ode'`` (the
        paper's; ``'ode'`` ignores it).
    refine : bool, optional
        Report the structured refit of the regression (8) (issue 23): the 20
        parameters of the model fitted, from the current estimate, to the
        instrumental-variable equations of (8), whose rows are weighted by the
        covariance of their equation error (output-noise power per channel
        estimated from the prediction error of (16)); computed when
        :attr:`model` is read, once (B̃, D) are estimated, and only where it
        lowers the criterion and stays Hurwitz (``info['refined']``). It does
        not change the recursion (``state``, the history and Ψ use the
        unrefined estimate). Default True for ``'iv'``, False for ``'ls'`` and
        ``'ode'`` (the paper's estimators). See ``docs/seed000.md``.

    Attributes
    ----------
    model : StateSpace
        Current estimate ``(Ã, B̃, C̃, D)``, continuous time (dt = 0), with
        diagnostics in ``info``.
    state : ndarray, shape (order,)
        Current filtered state ``x̃ = H (p - T_f q)``.
    history : dict of ndarray
        ``sample``, ``t``, ``poles``, ``A``, ``B``, ``C``, ``D`` (time on
        axis 0; the common format of :mod:`subid.methods.online.base`).

    Examples
    --------
    >>> import numpy as np, subid
    >>> from subid.methods.online.adaptive import AdaptiveIdentifier
    >>> from subid.experiments.seed000 import paper_system, multisine
    >>> t = np.arange(20001) * 1e-3
    >>> u = multisine(t, 2, seed=0)
    >>> y = paper_system().simulate(u, t=t, hold="foh")
    >>> ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-3)
    >>> for a in range(0, len(t), 5000):          # a stream, in pieces
    ...     _ = ident.update(u[a:a + 5000], y[a:a + 5000])
    >>> bool(subid.pole_error(ident.model, paper_system()) < 1e-3)
    True
    """

    _VERSION = _VERSION
    _READS = (2, 3, _VERSION)
    _OLD_KINDS = (_OLD_KIND,)

    @checked_call
    def __init__(self, order, n_inputs, n_outputs, *, horizon=None, filter_poles=-5.0,
                 forgetting=None, bd_forgetting=None, selector=None, seed=0, dt=None,
                 hold="foh", method="iv", scale_filters=True, refresh_every=50,
                 bd_gate=1e-2, max_condition=1e10, initial_covariance=None,
                 bd_initial_covariance=None, ode_trace_bound=1e8, history_size=0,
                 engine="numba", input_names=None, output_names=None,
                 instrument_poles=None, max_gap=None, bd_startup=None, refine=None):
        # the settings, stored unchanged (validated below)
        self.order, self.n_inputs, self.n_outputs = order, n_inputs, n_outputs
        self.horizon, self.filter_poles = horizon, filter_poles
        check_seed(seed)
        self.forgetting, self.bd_forgetting, self.seed = forgetting, bd_forgetting, seed
        self.dt, self.hold, self.method, self.scale_filters = dt, hold, method, scale_filters
        self.refresh_every, self.bd_gate = refresh_every, bd_gate
        self.max_condition, self.initial_covariance = max_condition, initial_covariance
        self.bd_initial_covariance, self.ode_trace_bound = bd_initial_covariance, ode_trace_bound
        self.history_size, self.engine, self.refine = history_size, engine, refine
        self.input_names, self.output_names, self.max_gap = input_names, output_names, max_gap
        self.instrument_poles, self.bd_startup = instrument_poles, bd_startup
        if refine is not None:
            refine = check_bool(refine, "refine")
        self._refine = (method == "iv") if refine is None else refine
        # the last structured refit: (sample count, result of _refit)
        self._refit_cache: tuple | None = None
        n = check_int(order, "order")
        nu = check_int(n_inputs, "n_inputs")
        ny = check_int(n_outputs, "n_outputs")
        if horizon is None:     # smallest f > n whose shift equation (13) is overdetermined
            f = n + 1 if ny > 1 else n + 2
        else:
            f = check_int(horizon, "horizon", minimum=2)
        if (f - 1) * ny < n:
            raise OrderError(f"horizon {f} with {ny} output{'s' if ny > 1 else ''} cannot "
                             f"reveal order {n}: (13) needs (horizon - 1) * n_outputs >= order, "
                             f"i.e. horizon >= {-(-n // ny) + 1}")
        self._n, self._nu, self._ny, self._f = n, nu, ny, f
        self._poles = _filters.filter_poles(filter_poles, f)
        if instrument_poles is None:
            self._ipoles = self._poles * _INSTRUMENT_POLE_RATIO
        else:
            self._ipoles = _filters.filter_poles(instrument_poles, f if isinstance(
                instrument_poles, numbers.Number) else None, "instrument_poles")
        if self._ipoles.size == f and np.allclose(np.sort_complex(self._ipoles),
                                                  np.sort_complex(self._poles)):
            raise SubidError("instrument_poles equal the filter poles: the instruments "
                             "would repeat the filtered inputs; choose slower poles, e.g. "
                             f"{float(np.real(self._poles[0])) * _INSTRUMENT_POLE_RATIO:g}")
        if self._ipoles.size * nu < n:
            raise SubidError(f"instrument_poles: {self._ipoles.size} poles give "
                             f"{self._ipoles.size * nu} instruments beyond the filtered "
                             f"inputs; the order {n} needs at least {-(-n // nu)} poles")
        alpha0, beta0 = _DEFAULT_FORGETTING.get(method, (0.4, 0.08))
        self._alpha = alpha0 if forgetting is None else _positive(forgetting, "forgetting")
        if bd_forgetting is not None:
            self._beta = _positive(bd_forgetting, "bd_forgetting")
        else:
            self._beta = self._alpha * _IV_BD_RATIO if beta0 is None else beta0
        if bd_startup is None:
            self._startup = _DEFAULT_BD_STARTUP if method == "iv" else 0.0
        else:
            self._startup = 0.0 if (bd_startup == 0 and not isinstance(bd_startup, bool)) \
                else _positive(bd_startup, "bd_startup")
        check_choice(hold, "hold", ("foh", "zoh"))
        check_choice(method, "method", ("iv", "ls", "ode"))
        check_choice(engine, "engine", ("numba", "numpy"))
        self._hold, self._method, self._engine = hold, method, engine
        self._scale = check_bool(scale_filters, "scale_filters")
        self._refresh = check_int(refresh_every, "refresh_every")
        self._max_cond = _positive(max_condition, "max_condition")
        if self._max_cond <= 1:
            raise OptionError(f"max_condition must exceed 1, got {max_condition!r}")
        default_cov = 1.0 if method == "ode" else 1e12
        self._p0 = default_cov if initial_covariance is None else \
            _positive(initial_covariance, "initial_covariance")
        self._q0 = default_cov if bd_initial_covariance is None else \
            _positive(bd_initial_covariance, "bd_initial_covariance")
        self._gate = _positive(bd_gate, "bd_gate")
        self._trace_bound = _positive(ode_trace_bound, "ode_trace_bound")
        self._hist_cap = check_int(history_size, "history_size", minimum=0)
        self._dt = None if dt is None else _positive(dt, "dt", exc=DataError)
        self._seed = seed
        # before anything of the order's size is allocated (the filters' companion
        # matrices too): the state of _alloc and the history
        layout = state_layout(n, nu, ny, f, self._ipoles.size)
        check_state_bytes(8.0 * (sum(math.prod(shape) for _, shape in layout)
                                 + self._hist_cap * (2 + n * n + n * nu + ny * n + ny * nu)
                                 + 2 * f * f),
                          "AdaptiveIdentifier",
                          f"order {n} with {nu} input(s), {ny} output(s), horizon {f} and "
                          f"history_size {self._hist_cap}",
                          "use a smaller order, horizon or history_size, or fewer channels")
        if selector is None:
            H = random_selector(f, ny, seed=check_seed(seed), rows=n)
        else:
            H = check_selector(selector, f, ny, [n], n, exact=True)
        self._H = np.ascontiguousarray(H)
        self._H.setflags(write=False)
        self._input_names = None if input_names is None else tuple(input_names)
        self._output_names = None if output_names is None else tuple(output_names)
        # filter: d(s) = prod(s - pole); time scale ω = |d(0)|^(1/f)
        self._Af, self._Bf, self._omega = _filters.companion(self._poles, self._scale)
        # instrument filter (method 'iv'): inputs only, its own poles
        self._Ai, self._Bi, _ = _filters.companion(self._ipoles, True)
        # steady states for a constant input (first state only, e_1 * dc)
        self._dcF = float(-np.linalg.solve(self._Af, self._Bf)[0, 0])
        self._dcI = float(-np.linalg.solve(self._Ai, self._Bi)[0, 0])
        wf = float(np.abs(np.prod(self._poles)) ** (1.0 / f))
        self._max_gap = 10.0 / wf if max_gap is None else _positive(max_gap, "max_gap")
        # after a gap the filters' initial-condition transient (~ t^(f-1) e^{-wf t})
        # is below 1e-9 of its start after max(30, 6 f) / wf
        self._settle = max(30.0, 6.0 * f) / wf
        self._step_cache: dict = {}
        self._t_origin = 0.0     # time of the sample with index _k_origin when t is None
        self._k_origin = 0
        self._alloc()

    # ------------------------------------------------------------------ state
    def _alloc(self) -> None:
        """Allocate the state: one float64 buffer holding every float array
        (views, so that a snapshot is one copy), the integer counters and the
        history."""
        n, nu, ny, f = self._n, self._nu, self._ny, self._f
        d, dth = n + f * nu, n + n * nu + ny * nu
        mi = self._ipoles.size
        dz = (f + mi) * nu + n
        layout = state_layout(n, nu, ny, f, mi)
        self._buf = np.zeros(sum(math.prod(shape) for _, shape in layout))
        st = {}
        off = 0
        lay = []                    # (offset, rows, cols): the views for kernel_packed
        for name, shape in layout:
            size = math.prod(shape)
            st[name] = self._buf[off:off + size].reshape(shape)
            lay.append((off, shape[0], shape[1] if len(shape) > 1 else 1))
            off += size
        self._lay = np.array(lay, dtype=np.int64)
        ist = np.zeros(_k.N_IST, dtype=np.int64)
        ist[_k.IST["hist_stride"]] = 1
        st["ist"] = ist
        st["fst"][_k.FST["scale_M"]] = st["fst"][_k.FST["scale_theta"]] = 1.0
        st["fst"][_k.FST["res_ref"]] = 1e300
        st["fst"][_k.FST["t_resume"]] = -1e300     # no gap yet
        if self._method != "ode":
            st["R"][:] = np.eye(d) / self._p0
            st["Rt"][:] = np.eye(dth) / self._q0
            st["Cz"][:n] = np.eye(n) / self._p0
            st["Zz"][:] = np.eye(dz) / self._p0
        else:
            st["R"][:] = np.eye(d) * self._p0
            st["Rt"][:] = np.eye(dth) * self._q0
        st["hist"] = np.zeros((self._hist_cap, 2 + n * n + n * nu + ny * n + ny * nu))
        self._st = st
        self._uniform = None      # discretisation tables for the constructor's dt
        self._uniform_tail = None     # kernel_packed's arguments after idx (dt samples):
        # (cbuf, ibuf, ist, hist, buf)
        self._idx1 = np.zeros(1, dtype=np.int64)    # table entries of a one-sample chunk
        self._T1 = np.zeros(1)                      # time stamp of a one-sample chunk

    _ORDER = ("ist", "fst", "prev_u", "prev_y", "zp", "zq", "R", "G", "M", "Rt", "g",
              "theta", "Am", "Cm", "Bm", "Dm", "Apsi", "Cpsi", "Psi", "zr", "xi", "Cz", "Gz", "Zz",
              "Ev")

    # ------------------------------------------------------------ properties
    @property
    def n_samples(self) -> int:
        """Number of samples processed."""
        return int(self._st["ist"][_k.IST["samples"]])

    @property
    def t(self) -> float | None:
        """Time of the last sample processed (None before the first)."""
        return float(self._st["fst"][0]) if self.n_samples else None

    @property
    def selector(self) -> np.ndarray:
        """The selector H (read-only)."""
        return self._H

    @property
    def time_scale(self) -> float:
        """ω, the time scale of the filter coordinates (1 if not scaled)."""
        return self._omega

    def _sym(self, name: str) -> np.ndarray:
        R = self._st[name]
        if self._method != "ode":     # the kernel updates the lower triangle only
            return np.tril(R) + np.tril(R, -1).T
        return R

    def _iv_cross(self) -> np.ndarray:
        """The IV cross matrix ``Σ w ζ φ^T`` (up to the deferred factor): the
        stored first n columns, then the q̂ columns of Z."""
        Z = self._sym("Zz")
        return np.hstack([self._st["Cz"], Z[:, :self._f * self._nu]])

    def information_condition(self) -> tuple[float, float]:
        """Condition numbers of the two normal matrices as updated (without
        the windup regularisation): R of (8), and the (B̃, D) block of R_θ of
        (16) (the x̃(t_g) block is left out: its regressor decays by design).
        In ``'ode'`` mode those of P and Q."""
        out = []
        for name, skip in (("R", 0), ("Rt", self._n)):
            if name == "R" and self._method == "iv":
                # the IV equations: condition of the cross matrix Cz (the
                # windup bound applies to it, see _adaptive_kernel._solve_iv)
                sv = np.linalg.svd(self._iv_cross(), compute_uv=False)
                out.append(float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf)
                continue
            ev = np.linalg.eigvalsh(self._sym(name)[skip:, skip:])
            out.append(float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf)
        return out[0], out[1]

    @property
    def model(self) -> StateSpace:
        """The current estimate ``(Ã, B̃, C̃, D)`` as a continuous-time model.

        ``info`` holds ``method`` (``'seed000_adaptive'``), ``samples`` (also
        as ``n_samples``, the key of every model),
        ``time``, ``refreshes``, ``horizon``, ``filter_poles``,
        ``time_scale``, ``forgetting``, ``bd_forgetting``, ``bd_startup``,
        ``ls_method``,
        ``hold``, ``condition`` and ``bd_condition`` (of the normal
        matrices, see :meth:`information_condition`), ``max_condition``,
        ``windup_active`` / ``bd_windup_active`` (the condition exceeds the
        bound, so the regularisation is holding the estimate),
        ``bd_started``, ``bd_start_time`` (part 2), ``shift_residual``
        (relative residual of (13) at the last refresh, -1 if rank
        deficient), ``psi_rejected`` (refreshes whose estimate was not used
        for Ψ), ``shift_failed`` (refreshes where (13) was rank deficient),
        ``cholesky_failed``, ``bound_hits`` (``'ode'``: steps with suspended
        forgetting), ``gaps`` and ``max_gap``, ``selector``, ``excited``
        (the last refresh found (8) persistently exciting), ``bd_elapsed``
        (time since part 2 started), ``refine``, ``refined`` (the structured
        refit of (8) is reported), ``refine_cost_ratio`` (its criterion over
        that of the unrefined model) and ``noise_std`` (the output-noise
        estimate it used), ``converged`` and ``convergence``
        (``'converged'`` or the reason it is not: part 2 has not started, or
        the latest (Ã, C̃) failed the gate or the Hurwitz test). A model that
        is not converged also issues a :class:`~subid.errors.NotConvergedWarning`
        (before the (B̃, D) stage starts: (Ã, C̃) with B = D = 0).

        Raises
        ------
        TooFewSamplesError
            Before the first refresh (``refresh_every`` samples): no estimate yet.
        """
        st, ist = self._st, self._st["ist"]
        if int(ist[_k.IST["refreshes"]]) == 0:      # never estimated: all zero, not a model
            raise TooFewSamplesError("AdaptiveIdentifier has " + (
                f"received {self.n_samples} samples and refreshes its estimate every "
                f"{self._refresh} (refresh_every): no estimate of (A, C) yet; give it more "
                "samples" if self.n_samples else "received no samples yet: there is no "
                "estimate (call update(u, y, t) first)"))
        cond, bd_cond = self.information_condition()
        ls = self._method != "ode"
        info = {
            "samples": self.n_samples,
            "time": self.t,
            "refreshes": int(ist[_k.IST["refreshes"]]),
            "filter_poles": self._poles.copy(),
            "time_scale": self._omega,
            "forgetting": self._alpha,
            "bd_forgetting": self._beta,
            "bd_startup": self._startup,
            "ls_method": self._method,
            "condition": cond,
            "bd_condition": bd_cond,
            "max_condition": self._max_cond,
            "windup_active": bool(ls and cond > self._max_cond),
            "bd_windup_active": bool(ls and bd_cond > self._max_cond),
            "bd_started": bool(ist[_k.IST["started"]]),
            "bd_start_time": float(st["fst"][_k.FST["t_start"]]) if ist[_k.IST["started"]]
            else None,
            "shift_residual": float(st["fst"][_k.FST["shift_residual"]]),
            "psi_rejected": int(ist[_k.IST["psi_rejected"]]),
            "shift_failed": int(ist[_k.IST["shift_failed"]]),
            "cholesky_failed": int(ist[_k.IST["chol_failed"]]),
            "bound_hits": int(ist[_k.IST["bound_hits"]]),
            "gaps": int(ist[_k.IST["gaps"]]),
            "excited": not ist[_k.IST["not_excited"]],
            "max_gap": self._max_gap,
            "selector": np.array(self._H),
        }
        info["bd_elapsed"] = (self.t - info["bd_start_time"]) if info["bd_started"] else 0.0
        refit = self._refit() if self._refine and info["bd_started"] else None
        info["refine"] = self._refine
        info["refined"] = refit is not None
        if refit is not None:
            info["refine_cost_ratio"] = refit[1]
            info["noise_std"] = refit[2]
        reason = self._convergence(info)
        info["converged"] = reason is None
        info["convergence"] = "converged" if reason is None else reason
        issued = []
        if reason is not None:
            issued.append(f"AdaptiveIdentifier: the model is not converged: {reason}")
            warnings.warn(issued[0], NotConvergedWarning, stacklevel=2)
        info = model_info("seed000_adaptive", order=self._n, horizon=self._f,
                          n_samples=self.n_samples, x0=None, hold=self._hold,
                          conditions=conditions_of(info), warnings=issued, **info)
        A, B, C, D = st["Am"], st["Bm"], st["Cm"], st["Dm"]
        if info["refined"]:
            A, B, C, D = refit[0]
        return StateSpace(A, B, C, D, 0.0,
                          input_names=self._input_names, output_names=self._output_names,
                          info=info, hold=self._hold)

    def _refit(self):
        """The structured refit of (8) (:mod:`._adaptive_refine`) of the current
        model, cached per sample count: ``((A, B, C, D), cost ratio, noise std)``
        or None (no noise estimate yet, or the refit failed)."""
        if self._refit_cache is not None and self._refit_cache[0] == self.n_samples:
            return self._refit_cache[1]
        st, out = self._st, None
        ev = st["Ev"][0]
        ny = self._ny
        if ev[-1] > 0 and np.any(ev[:ny] > ev[ny:-1] * 10 ** (-_SNR_SKIP / 10)):
            power = np.maximum(ev[:ny], ev[ny:-1] * 10 ** (-_SNR_SKIP / 10)) / ev[-1]
            fit = _refit_mod.refit((st["Am"], st["Bm"], st["Cm"], st["Dm"]), st["M"], st["Cz"],
                                   st["Gz"], st["Zz"], self._H, self._omega, self._Af,
                                   self._Bf, power, self._max_cond)
            out = None if fit is None else (fit[0], fit[1], np.sqrt(power))
        self._refit_cache = (self.n_samples, out)
        return out

    def _convergence(self, info: dict):
        """None if the current model passes the convergence criteria, else
        the reason (a sentence). Criteria: (B̃, D) estimation has started;
        the latest (Ã, C̃) passed the test that starts it (shift residual of
        (13) below the gate or at its noise floor, Ã Hurwitz). How long
        (B̃, D) have been estimated is reported (``bd_elapsed``), to compare
        with their memory ``1/bd_forgetting``."""
        if not self.n_samples:
            return "no samples processed yet"
        res = info["shift_residual"]
        head = "the (B, D) stage has not started, so B and D are not estimated (zero): "
        if not info["bd_started"] and not info["excited"]:
            return (head + "the input is not persistently exciting (the weakest direction "
                    f"of the regression (8) carries less than 1/max_condition = "
                    f"{1 / self._max_cond:.3g} of its information; condition "
                    f"{info['condition']:.3g}), so the data do not determine (A, C). Give an "
                    f"input sufficiently rich of order horizon + order = {self._f + self._n} "
                    "(Theorem 1 of the paper), e.g. white noise or a multisine with enough "
                    "frequencies in the system's band" + _UNITS_CURE)
        if not info["bd_started"]:
            return (head + f"the relative residual of the shift equation (13) is {res:.3g} "
                    f"(gate {self._gate:g}) or the estimated A is not Hurwitz. Give it more "
                    "data or a richer input" + (
                        "; with output noise use method='iv' (the default), which is "
                        "consistent" if self._method != "iv" else
                        "; with output noise, a longer memory (smaller forgetting)")
                    + _UNITS_CURE)
        if self._st["ist"][_k.IST["rejected"]]:
            why = (f"shift residual {res:.3g}, or A not Hurwitz" if info["excited"] else
                   "the data are no longer persistently exciting")
            return (f"the latest (A, C) estimate failed the convergence test ({why}); B and D "
                    "come from earlier estimates")
        return None

    def toeplitz(self) -> np.ndarray:
        """T_f of (3) for the current estimate, in the filter coordinates
        (``T_f(Ã/ω, B̃/ω, C̃, D)``), shape (f ny, f nu)."""
        A, B, C, D = (self._st[k] for k in ("Am", "Bm", "Cm", "Dm"))
        return _refit_mod.toeplitz(A / self._omega, B / self._omega, C, D, self._f)

    @property
    def state(self) -> np.ndarray:
        """Filtered state ``x̃ = H (p̂ - T_f q̂)`` (paper, "Estimation of the
        state") with the current estimate of T_f; it is ``F̂(s)`` applied to
        the state of :attr:`model` (``F̂ = ω^f/d(s)``, unit DC gain, when the
        filters are scaled; ``1/d(s)`` otherwise)."""
        st = self._st
        p = st["zp"].reshape(-1)
        q = st["zq"].reshape(-1)
        return self._H @ (p - self.toeplitz() @ q)

    @property
    def history(self) -> dict:
        """Decimated history of the estimates (see ``history`` above)."""
        n, nu, ny = self._n, self._nu, self._ny
        rows = self._st["hist"][:self._st["ist"][_k.IST["hist_count"]]].copy()
        c = 2
        mats = {}
        for name, shape in (("A", (n, n)), ("B", (n, nu)), ("C", (ny, n)), ("D", (ny, nu))):
            size = shape[0] * shape[1]
            mats[name] = rows[:, c:c + size].reshape((-1,) + shape)
            c += size
        return history_dict(rows[:, 1], rows[:, 0], dt=0.0, **mats)

    # ---------------------------------------------------------------- update
    def _tables(self, steps: np.ndarray):
        """Discretisation tables for the distinct step lengths ``steps``."""
        Ai = self._Ai if self._method == "iv" else None
        return _filters.discretise(steps, self._Af, self._Bf, Ai, self._Bi, self._ipoles.size,
                                   self._hold, self._step_cache, self._alpha, self._beta)

    def update(self, u, y=None, t=None) -> "AdaptiveIdentifier":
        """Process one sample or a chunk of samples.

        Parameters
        ----------
        u : array_like, shape (N, n_inputs) or (n_inputs,), or IOData
            Input samples (time on axis 0; a 1-D array of n_inputs values is
            one sample when there are several inputs). An
            :class:`~subid.data.IOData` record supplies u, y and, if it has
            explicit time stamps, t (otherwise its samples continue the
            stream with its dt).
        y : array_like, shape (N, n_outputs) or (n_outputs,)
            Output samples.
        t : array_like, shape (N,), optional
            Time stamps, strictly increasing and after the last sample
            processed. Default: the constructor's ``dt`` after the last one.
            With the constructor's ``dt``, stamps must be that grid continuing
            the stream (checked, as by :class:`~subid.RecursiveSubspace`); with
            ``dt=None`` they may be non-uniform.

        Returns
        -------
        AdaptiveIdentifier
            ``self``.

        Raises
        ------
        subid.errors.DataError
            NaN or inf values, wrong shapes, time stamps not increasing or off
            the ``dt`` grid, no time information. The identifier is left unchanged.

        Notes
        -----
        The result does not depend on how a stream is cut into chunks. An
        empty chunk (0 samples, with ``t`` None or empty, as a stream may
        deliver) is accepted and changes nothing.
        """
        if t is None and self._uniform_tail is not None and type(u) is np.ndarray \
                and type(y) is np.ndarray:
            # one sample on the constructor's dt grid, as 1-D float64 arrays (a
            # stream's usual call): validated and processed without the
            # general bookkeeping; the same kernel call as below
            U = one_sample(u, self._nu)
            Y = None if U is None else one_sample(y, self._ny)
            if Y is not None:
                self._update_one(U, Y)
                return self
        chunk = parse_chunk(self, u, y, t)
        if chunk is None:               # an empty chunk
            return self
        U, Y, T = chunk
        N = U.shape[0]
        st = self._st
        S0 = int(st["ist"][0])          # self.n_samples
        K = self._refresh
        # rollback state (the float buffer in one copy; the history only if
        # this chunk can reach a refresh)
        snap_buf, snap_ist = self._buf.copy(), st["ist"].copy()
        hist = st["hist"]
        snap_hist = None
        if hist.shape[0] and (S0 + N - 1) // K > max(S0 - 1, 0) // K:
            snap_hist = hist.copy()
        origin = (self._t_origin, self._k_origin)
        try:
            if T is None:
                if N == 1:      # the same double operations as below (0.0 + x == x)
                    T = self._T1      # the kernel only reads it
                    T[0] = self._t_origin + self._dt * float(S0 - self._k_origin)
                else:
                    T = self._t_origin + self._dt * (np.arange(N) + float(S0 - self._k_origin))
                ok = self._run_uniform(T, U, Y)
            else:
                prev = T[0] if S0 == 0 else self.t
                steps_all = np.diff(np.concatenate([[prev], T]))
                if S0 == 0:            # no interval ends at the very first sample
                    steps_all[0] = steps_all[1] if N > 1 else 1.0
                uniq = np.unique(steps_all)
                ok = True
                if uniq.size <= _BLOCK_UNIQUE:
                    ok = self._run(T, U, Y, steps_all, uniq)
                else:
                    for a in range(0, N, _BLOCK_SAMPLES):
                        b = min(a + _BLOCK_SAMPLES, N)
                        ok = self._run(T[a:b], U[a:b], Y[a:b], steps_all[a:b],
                                       np.unique(steps_all[a:b])) and ok
                self._t_origin, self._k_origin = float(T[-1]), S0 + N - 1
            if not ok:
                raise DataError(_NON_FINITE)
        except BaseException:
            self._rollback(snap_buf, snap_ist, snap_hist)
            self._t_origin, self._k_origin = origin
            raise
        return self

    def _update_one(self, U, Y) -> None:
        """:meth:`update` of one validated sample (U, Y of shape (1, channels))
        at the next point of the dt grid, once the uniform tables are built
        (numba engine): the path of ``update`` for ``T is None, N == 1``."""
        tail = self._uniform_tail
        ist = tail[-3]                  # self._st["ist"]
        S0 = int(ist[0])
        snap_buf, snap_ist = self._buf.tobytes(), ist.tolist()     # cheaper than copies
        hist = tail[-2]                 # self._st["hist"]
        # the history only if this sample is a refresh
        snap_hist = hist.copy() if hist.shape[0] and S0 and S0 % self._refresh == 0 else None
        T = self._T1                    # the kernel only reads it
        T[0] = self._t_origin + self._dt * float(S0 - self._k_origin)
        try:
            if not _k.kernel_packed(T, U, Y, self._idx1, *tail):
                raise DataError(_NON_FINITE)
        except BaseException:
            self._rollback(np.frombuffer(snap_buf), snap_ist, snap_hist)
            raise

    def _rollback(self, snap_buf, snap_ist, snap_hist) -> None:
        """Restore the state saved before a chunk that was rejected."""
        self._buf[:] = snap_buf
        self._st["ist"][:] = snap_ist
        if snap_hist is not None:
            self._st["hist"][:] = snap_hist
        if self._uniform is not None:
            self._uniform[-1][-1][:] = -1          # invalidate the Ψ cache

    def _call(self, T, U, Y, idx, steps, tables, cache) -> bool:
        Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, lamM, lamT = tables
        st = self._st
        par, ipar = self._parameters()
        if self._engine == "numba":     # the arrays as a few buffers (cheaper call)
            cbuf, ibuf, _ = pack_tables((steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0, Ig1,
                                         self._H, par), cache, self._lay, ipar)
            return bool(_k.kernel_packed(T, U, Y, idx, cbuf, ibuf, st["ist"], st["hist"],
                                         self._buf))
        return bool(reference(T, U, Y, idx, steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0,
                                 Ig1, self._H, par, ipar,
                                 *(st[k] for k in self._ORDER), *cache, st["hist"], self._buf))

    def _parameters(self):
        """``(par, ipar)`` of the kernel (settings fixed at construction; built once)."""
        cached = self.__dict__.get("_par_ipar")
        if cached is None:
            par = np.array([self._omega, self._alpha, self._beta, self._max_cond,
                            self._trace_bound, self._gate, self._max_gap, self._dcF,
                            self._dcI, self._settle, self._startup])
            ipar = np.array([self._refresh, self._method == "ode", self._hold == "foh",
                             self._method == "iv"], dtype=np.int64)
            cached = self._par_ipar = (par, ipar)
        return cached

    def _psi_cache(self, K: int):
        n, ny = self._n, self._ny
        return (np.empty((K, n, n)), np.empty((K, ny, n)), np.empty((K, ny, n)),
                np.full(K, -1, dtype=np.int64))

    def _run_uniform(self, T, U, Y) -> bool:
        """Samples spaced by the constructor's dt: one cached table entry."""
        if self._uniform is None:
            steps = np.array([self._dt])
            self._uniform = (steps, self._tables(steps), self._psi_cache(1))
        steps, tables, cache = self._uniform
        N = U.shape[0]
        idx = self._idx1 if N == 1 else np.zeros(N, dtype=np.int64)
        if self._engine != "numba":
            return self._call(T, U, Y, idx, steps, tables, cache)
        tail = self._uniform_tail
        if tail is None:    # the arguments after idx never change: built once
            Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, lamM, lamT = tables
            par, ipar = self._parameters()
            cbuf, ibuf, cache = pack_tables((steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0,
                                             Ig1, self._H, par), cache, self._lay, ipar)
            self._uniform = (steps, tables, cache)      # the Ψ cache in the buffers now
            tail = self._uniform_tail = (cbuf, ibuf, self._st["ist"], self._st["hist"],
                                         self._buf)
        return bool(_k.kernel_packed(T, U, Y, idx, *tail))

    def _run(self, T, U, Y, steps_all, uniq) -> bool:
        idx = np.searchsorted(uniq, steps_all).astype(np.int64)
        return self._call(np.ascontiguousarray(T), U, Y, idx, np.ascontiguousarray(uniq),
                          self._tables(uniq), self._psi_cache(uniq.shape[0]))

    # ----------------------------------------------------------- checkpoints
    def _settings(self) -> dict:
        return {
            "order": self._n, "n_inputs": self._nu, "n_outputs": self._ny,
            "horizon": self._f,
            "filter_poles": [[float(p.real), float(p.imag)] for p in self._poles],
            "forgetting": self._alpha, "bd_forgetting": self._beta,
            "seed": self._seed if isinstance(self._seed, int) else None,
            "dt": self._dt, "hold": self._hold, "method": self._method,
            "scale_filters": self._scale, "refresh_every": self._refresh,
            "bd_gate": self._gate,
            "max_condition": self._max_cond, "initial_covariance": self._p0,
            "bd_initial_covariance": self._q0, "ode_trace_bound": self._trace_bound,
            "history_size": self._hist_cap, "engine": self._engine,
            "instrument_poles": [[float(p.real), float(p.imag)] for p in self._ipoles],
            "max_gap": self._max_gap, "bd_startup": self._startup, "refine": self._refine,
            "input_names": None if self._input_names is None else list(self._input_names),
            "output_names": None if self._output_names is None else list(self._output_names),
            "t_origin": self._t_origin, "k_origin": self._k_origin,
        }

    def save(self, path) -> None:
        """Write the whole state to ``path`` (``.npz`` with a JSON header, no
        pickle), atomically: a crash mid-write leaves the previous file."""
        arrays = {k: v for k, v in self._st.items()}
        arrays["hist"] = self._st["hist"]
        arrays["selector"] = np.array(self._H)
        save_state(path, self.checkpoint_kind(), _VERSION, arrays, self._settings())

    @classmethod
    def load(cls, path) -> "AdaptiveIdentifier":
        """Restore an identifier written by :meth:`save`; continuing it gives
        exactly the estimates of a run that never stopped.

        Raises
        ------
        subid.errors.CheckpointError
            Truncated or corrupted file, another kind of checkpoint, wrong
            shapes or non-finite values.
        subid.errors.DataFileNotFoundError
            The file does not exist.
        """
        arrays, s = load_state(path, cls._kinds(), cls._READS)
        try:
            poles = [complex(re, im) for re, im in s["filter_poles"]]
            obj = cls(s["order"], s["n_inputs"], s["n_outputs"], horizon=s["horizon"],
                      filter_poles=poles, forgetting=s["forgetting"],
                      bd_forgetting=s["bd_forgetting"],
                      selector=require(arrays, path, "selector"),
                      seed=s["seed"] if s["seed"] is not None else 0, dt=s["dt"],
                      hold=s["hold"], method=s["method"], scale_filters=s["scale_filters"],
                      refresh_every=s["refresh_every"], bd_gate=s["bd_gate"],
                      max_condition=s["max_condition"],
                      initial_covariance=s["initial_covariance"],
                      bd_initial_covariance=s["bd_initial_covariance"],
                      ode_trace_bound=s["ode_trace_bound"],
                      history_size=s["history_size"] if "history_size" in s else s["history"],
                      engine=s["engine"], input_names=s["input_names"],
                      output_names=s["output_names"],
                      instrument_poles=[complex(re, im) for re, im in s["instrument_poles"]],
                      max_gap=s["max_gap"],
                      # version 2 had no start-up schedule
                      bd_startup=s.get("bd_startup", 0.0),
                      # versions 2 and 3 had no refit of (8)
                      refine=s.get("refine", False))
            version = s.get("_version", _VERSION)
            t_origin, k_origin = float(s["t_origin"]), int(s["k_origin"])
        except CheckpointError:
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"checkpoint {path} has invalid settings ({exc})",
                                  path=path) from None
        if version == 2 and arrays.get("fst", np.empty(0)).shape == (_k.N_FST - 1,) \
                and arrays.get("ist", np.empty(0)).shape == (_k.N_IST - 1,):
            # version 2 had no t_first (the stall rule's clock starts at the
            # time of the last halving of the residual, as if the data began
            # then) and no excitation flag (excited until the next refresh)
            arrays = dict(arrays, fst=np.append(arrays["fst"], arrays["fst"][6]),
                          ist=np.append(arrays["ist"], 0))
        if version < 4 and "Ev" not in arrays:      # no noise estimate before version 4
            arrays = dict(arrays, Ev=np.zeros_like(obj._st["Ev"]))
        for name, ref in obj._st.items():
            value = require(arrays, path, name, ref.shape, dtype=ref.dtype)
            if value.dtype != ref.dtype:
                raise CheckpointError(f"checkpoint {path}: array {name!r} has dtype "
                                      f"{value.dtype}, expected {ref.dtype}", path=path)
            ref[...] = value                 # into the state buffer (views stay valid)
        ist = obj._st["ist"]
        cap = obj._hist_cap
        if (ist < 0).any() or ist[_k.IST["hist_stride"]] < 1 or ist[_k.IST["hist_count"]] > cap:
            raise CheckpointError(f"checkpoint {path} has inconsistent counters", path=path)
        obj._t_origin, obj._k_origin = t_origin, k_origin
        return obj

    def __repr__(self) -> str:
        return (f"AdaptiveIdentifier(order={self._n}, n_inputs={self._nu}, "
                f"n_outputs={self._ny}, horizon={self._f}, samples={self.n_samples})")

    def _repr_html_(self) -> str:
        """Summary for Jupyter: settings, samples seen and the current model."""
        from subid._repr import adaptive_settings, online_html
        return online_html(self, adaptive_settings(self))
