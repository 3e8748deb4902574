"""Continuous-time subspace identification with orthonormal basis filters (seed 002).

Yu, Chen, Ljung, Verhaegen, "Subspace identification of continuous-time
models using generalized orthonormal bases", CDC 2017. Numbers in
parentheses are the paper's equations; docs/seed002.md lists every
correction made to them.

Data equation
-------------
Filter the output and the input by the same bank of ``N`` orthonormal basis
filters ``xi' = F xi + g v`` (:mod:`subid.basis`), all at rest at ``t_0``.
Stack the filtered samples function-major: ``y_f(t)`` has ``N p`` rows,
block ``k`` being basis function ``k`` applied to every output (the paper's
``y_k``), and likewise ``u_f(t)`` (``N m`` rows). For ``x' = A x + B u``,
``y = C x + D u`` the filtered state ``Xi_x`` (n x N) obeys both
``Xi_x' = Xi_x F^T + x g^T`` and ``Xi_x' = A Xi_x + B Xi_u`` (filtering
commutes with the system), hence the Sylvester equation
``A Xi_x - Xi_x F^T = x g^T - B Xi_u`` and

    y_f(t) = O x(t) + T u_f(t) + Psi phi(t - t_0),                     (6')

    O = (I_N kron C) S^{-1} (g kron I_n),
    T = -(I_N kron C) S^{-1} (I_N kron B) + I_N kron D,
    S = I_N kron A - F kron I_n,

with ``phi(t) = e^{F t} g`` the basis functions: the start-up transients of
the filters and the response to a non-zero ``x(t_0)`` are free responses of
the bank (``x(t_0) phi(t - t_0)^T`` enters the Sylvester equation), so they
lie in the span of ``phi(t - t_0)``, which are therefore used as regressors
(``startup=True``). For real poles ``O`` is exactly the paper's extended
observability matrix (10). The paper's (6) stacks instead the
``N (N + 1) / 2`` signals ``psi_{l,j+1} M_j u``; they all lie in the span of
the ``N`` filtered inputs, so that stacked input has rank ``N m`` only. Its
convolution matrix is printed wrong (:func:`tm_convolution_matrix` gives the
corrected one). Both forms are available (``data_equation``).

Estimation
----------
1. LQ factorisation of the signals ``[phi; u_f; r; z; y_f]`` (``r``
   interpolation-correction regressors, ``z`` instruments) and SVD of the
   block of ``y_f`` on the instruments, or on its own rows without them:
   range(O) (Lemma 3, eq. (8)).
2. ``A`` and ``C``. The blocks ``K_k`` of ``S^{-1} (g kron I)`` are
   rational functions of ``A``, so they commute with it and block row ``k`` of
   ``O`` obeys ``O_k A = sum_j F_kj O_j + g_k C``. ``ac_method='joint'``
   solves these ``N p`` block equations for ``[A; C]`` by least squares;
   ``'paper'`` eliminates ``C`` between consecutive equations normalised by
   ``g_k``, which for real poles is exactly the paper's ``M A = R`` (11)-(12)
   solved as ``A = M^+ R`` ((13) as printed reads ``L_A^+ R_A``), and takes
   ``C = O_0 (A + sigma_0 I) / sqrt(2 sigma_0)`` ((14) prints ``2 sigma_0``).
3. ``B`` (and ``D``, ``x0``): ``bd_method='simulation'`` fits them to the raw
   output samples through the exactly discretised model (the output is
   linear in them); ``'filtered'`` solves (15) on the filtered data equation.

Beyond the paper
----------------
* Interpolation-correction regressors (``correction=True``). The output
  inherits the non-smoothness of the input: with ``G(s) = D + CB/s + CAB/s^2
  + ...``, ``y - D u - sum_i c_i H_i u`` is smooth to the order the
  degree-p interpolation needs once ``i`` runs to ``p - 1`` (input continuous
  between samples) or ``p`` (held input), ``H_i(s) = (a/(s + a))^i``. The
  filtered interpolation errors of ``H_i u`` are computable from the input
  alone; entering them as regressors with free coefficients removes the
  dominant filtering error of ``y`` (4th-order system, L = 400: from O(1) to
  1e-9 in max |G - G_hat|).
* Instruments (``instruments='model'``): after a first estimate, the states
  of the model simulated from the input alone replace ``y_f``'s own rows in
  the SVD (iterated). They are functions of the input only, uncorrelated with
  output noise of any colour, so range(O) is consistent.
* Output-error refinement (``refine=True``; the default ``'auto'`` keeps it
  where the cross-validation folds prefer it): Levenberg-Marquardt on the raw
  output samples over (A, C) in local coordinates transversal to the state
  basis, with B, D, x0 eliminated by linear least squares (variable
  projection). It turns the consistent subspace estimate into the
  least-squares (maximum-likelihood for white Gaussian output noise)
  estimate. ``info['subspace_model']`` keeps the subspace estimate.
* Discrete-time candidates (``start='auto'``, uniform grids): the default
  N4SID models converted with the hold compete in the cross-validation
  with n4sid's own fold scores (:mod:`subid.methods.ct._ct_discrete`).
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import replace
from functools import partial

import numpy as np

from subid._blas import serial_blas
from subid._validation import check_bool, check_choice, check_int, checked_call, name_caller
from subid.data import column_spread
from subid.errors import (
    ConversionWarning,
    DataError,
    ModelError,
    OptionError,
    OrderError,
    SubidError,
    TooFewSamplesError,
)
from subid.methods._common import choose_order
from subid.methods._info import model_info, records_warnings
from subid.methods.bd import CT_OPTIONS, INFO_KEY, fit_b_d_x0
from subid.methods.ct import _ct_discrete, _ct_fit, _ct_refine
from subid.methods.ct._ct_checks import (
    DEFAULT_MAX_ORDER,
    HOLD_ORDERS,
    _check_data,
    _check_filtered,
    _default_size,
    _lag_for,
    _parse_order,
)
from subid.methods.ct._ct_discrete import dt_to_ct
from subid.methods.ct._ct_estimate import (
    _correction_count,
    _estimate_a_c,
    _markov_change,
    _subspace_factor,
    data_equation_matrices,
    instrument_block,
    observability_matrix,
    range_basis,
    tm_convolution_matrix,
)
from subid.methods.ct._ct_folds import _Folds, _second_wins
from subid.methods.ct._ct_problem import Problem
from subid.methods.ct._ct_problem import prepare as _prepare
from subid.methods.ct.basis import MAX_POLY_ORDER, FilterBank, default_basis
from subid.methods.dt.selection import cross_validate
from subid.model.statespace import StateSpace

__all__ = [
    "ct_subspace",
    "ct_subspace_paper",
    "dt_to_ct",
    "data_equation_matrices",
    "observability_matrix",
    "tm_convolution_matrix",
]

#: Folds up to this many samples are filtered once per call and reused by the choices.
FOLD_CACHE_SAMPLES = 50_000
#: Instrument iterations of the models fitted to the cross-validation folds.
FOLD_ITERATIONS = 3
#: ``refine='auto'`` considers the refinement only where its budget
#: (:func:`subid.methods.ct._ct_fit.refine_steps`) affords this many steps.
MIN_REFINE_STEPS = 5
def _linear_fit(problem: Problem, feedthrough: bool, whiten=None):
    """``fit(A, C) -> (B, D, x0, y0, diagnostics)`` (None where simulating A overflows):
    the ``'simulation'`` route of :func:`subid.methods.bd.fit_b_d_x0`."""
    s = problem.settings

    def fit(A, C):
        fitted = fit_b_d_x0(A, C, problem.record, bd_method="simulation",
                            feedthrough=feedthrough, estimate_x0=s["estimate_x0"],
                            offset=s["offset"], whiten=whiten)
        if fitted is None:
            return None
        B, D, x0, diag = fitted
        return B, D, x0, diag.pop("y_offset"), diag
    return fit


#: An initial-state column of the regression of :func:`_given_bd` below this fraction of
#: the largest of its experiment is a state the samples do not see (its x0 is set to 0).
UNSEEN_STATE = 1e-10


def _given_bd(problem: Problem, A, B, C, D):
    """x0 and offsets for a model whose B and D are given (from the filtered equation (15)
    or a converted model), and the regressor of :func:`subid.methods.ct._ct_fit.predicted`
    for them (None where it is not the one computed here)."""
    s, rec = problem.settings, problem.record
    n, m, p, E = A.shape[0], rec.n_inputs, rec.n_outputs, rec.n_experiments
    if not (s["estimate_x0"] or s["offset"]):
        return None, None, None
    R = _ct_fit.regressors(A, C, rec, feedthrough=True, estimate_x0=s["estimate_x0"],
                           offset=s["offset"])
    if R is None:
        return None, None, None
    forced = R[:, :n * m] @ B.reshape(-1) + R[:, R.shape[1] - p * m:] @ D.reshape(-1)
    free = R[:, n * m:R.shape[1] - p * m]
    # a state the samples do not see (the second copy of a Nyquist mode of a converted
    # model, _ct_discrete.with_nyquist_modes: its response is zero at every sample up to
    # rounding) has no initial state to fit: its column, rounding equilibrated to unit
    # norm, got entries of 1e14 (fitting the noise with rounding); left out, its x0 is 0
    kept = np.ones(free.shape[1], dtype=bool)
    if s["estimate_x0"] and n:
        norms = np.linalg.norm(free[:, :n * E], axis=0).reshape(E, n)
        kept[:n * E] = (norms > UNSEEN_STATE * norms.max(axis=1, keepdims=True)).ravel()
    theta = np.zeros(free.shape[1])
    theta[kept] = _ct_fit.solve(free[:, kept], rec.y.reshape(-1) - forced)[0]
    _, _, x0, y0 = _ct_fit.unpack(np.concatenate([np.zeros(n * m), theta]), n, m, p, E,
                                  feedthrough=False, estimate_x0=s["estimate_x0"],
                                  offset=s["offset"])
    # predicted() regresses on x0 and y0 exactly when they are not None
    same = (x0 is not None) == s["estimate_x0"] and (y0 is not None) == s["offset"]
    return x0, y0, R if same else None


def _complete(problem: Problem, Theta, factor, feedthrough: bool):
    """A, C from ``Theta``; then B, D, x0 (y0): ``(A, B, C, D, x0, y0, diag)``.
    ``factor()`` gives the factor of :func:`subid.methods.ct._ct_estimate._subspace_factor`
    (called only for the filtered B, eq. (15), which reads it)."""
    s = problem.settings
    basis, p = s["basis"], problem.record.n_outputs
    A, C, ac_resid = _estimate_a_c(basis, Theta, p, s["ac_method"])
    diag = {"ac_residual": ac_resid}
    if s["bd_method"] == "simulation":
        try:
            A, fitted, stab = _ct_fit.stable_choice(A, C, _linear_fit(problem, feedthrough),
                                                    problem.record, s["stability"])
            B, D, x0, y0, bd = fitted
            diag.update(bd, stability=stab)
            return A, B, C, D, x0, y0, diag
        except ModelError:          # A too unstable to simulate over the record
            pass
    if s["data_equation"] == "paper":
        def Tfun(Bm, Dm):
            return tm_convolution_matrix(A, Bm, C, basis.poles)
    else:
        def Tfun(Bm, Dm):
            return data_equation_matrices(basis, A, Bm, C, Dm)[1]
    B, D, _, bd = fit_b_d_x0(A, C, problem.record, bd_method="filtered", feedthrough=feedthrough,
                             filtered=(Tfun, Theta, factor(), problem.iU))
    x0, y0, _ = _given_bd(problem, A, B, C, D)
    diag.update(bd, stability={"requested": s["stability"],
                                                         "action": "none (filtered B)"})
    return A, B, C, D, x0, y0, diag


def _subspace_estimate(problem: Problem, n: int, feedthrough: bool):
    """The paper's estimate (corrected), with model instruments iterated."""
    s = problem.settings
    Theta = problem.Uo[:, :n] * problem.sv[:n]
    A, B, C, D, x0, y0, diag = _complete(problem, Theta, lambda: problem.Lf, feedthrough)
    changes = []
    if s["instruments"] == "model":
        if "range basis" not in problem.memo:      # shared by the orders of the problem
            # the basis replaces the regressors (filtered again only by the fallbacks)
            problem.memo["range basis"] = range_basis(problem.take_regressors())
        basis = problem.memo["range basis"]
        for _ in range(s["iterations"]):
            Xs = _ct_fit.simulated_states(A, B, x0, problem.record)
            if Xs is None:
                break
            # W by projection on range(R) (the factor of [R Xs Y] only where the
            # filtered B needs it), else from that factor
            W = None if basis is None else instrument_block(basis, Xs, problem.Y)
            if W is None:
                Lf, W = _subspace_factor(problem.regressors(), Xs, problem.Y)

                def factor(Lf=Lf):
                    return Lf
            else:
                def factor(Xs=Xs):
                    return _subspace_factor(problem.regressors(), Xs, problem.Y)[0]
            Uo, s2, _ = np.linalg.svd(W, full_matrices=False)
            previous = (A, B, C)
            A, B, C, D, x0, y0, diag = _complete(problem, Uo[:, :n] * s2[:n], factor, feedthrough)
            changes.append(_markov_change(previous, (A, B, C)))
            if changes[-1] < s["tolerance"]:
                break
    diag.update(iterations=len(changes), iteration_changes=changes)
    return A, B, C, D, x0, y0, diag


def _discrete_starts(problem: Problem, n: int, horizons=None):
    """``(label, continuous model)`` of the discrete-time N4SID models of order ``n`` (at
    ``horizons``, default every horizon of
    :func:`subid.methods.crossval.feasible_horizons`) converted with the hold
    (:mod:`subid.methods.ct._ct_discrete`), and ``{horizon: reason}`` for those that have
    no continuous-time counterpart; none on a non-uniform grid."""
    if not problem.data.is_uniform:
        return [], {}
    key = ("discrete starts", n, None if horizons is None else tuple(horizons))
    if key not in problem.memo:
        problem.memo[key] = _convert_starts(problem, n, horizons)
    return problem.memo[key]


def _convert_starts(problem: Problem, n: int, horizons):
    """:func:`_discrete_starts` computed (not looked up)."""
    from subid.methods.crossval import feasible_horizons
    data, s = problem.data, problem.settings
    work = data.detrend() if s["offset"] else data
    if horizons is None:
        horizons = feasible_horizons(data.n_samples, data.n_inputs, data.n_outputs, 2, n,
                                     n_experiments=data.n_experiments)
    models, failures = _ct_discrete.discrete_models(
        work, n, horizons, hold=_model_hold(s), feedthrough=s["dt_feedthrough"],
        stability=s["stability"], nyquist=s["nyquist_modes"])
    return [(f"discrete ({_ct_discrete.label(f)})", cm, note)
            for f, cm, note in models], failures


def _model_hold(s: dict) -> str:
    """The hold the model records (``'foh'`` for an interpolated input)."""
    return "foh" if s["hold"] is None else s["hold"]


def _converted(problem: Problem, cm: StateSpace, note=None, refit=None):
    """A converted discrete-time model as it is (its B and D are those of the hold, so
    that it simulates to the discrete-time model's samples), x0 (and offsets) fitted;
    stability as :func:`subid.methods.ct._ct_fit.stable_choice` handles it, B and D
    refitted only where it reflects a pole. ``refit`` (True/False: with or without D):
    its A and C with B, D, x0 from the output regression (the earlier default start)."""
    s = problem.settings
    if refit is not None:
        A, fitted, stab = _ct_fit.stable_choice(cm.A, cm.C, _linear_fit(problem, refit),
                                                problem.record, s["stability"])
        B, D, x0, y0, bd = fitted
        bd = dict(bd, **{INFO_KEY: "simulation"}, stability=stab, iterations=0)
        if note:
            bd["nyquist_modes"] = note
        return A, B, cm.C, D, x0, y0, bd
    feedthrough = bool(np.any(cm.D != 0))
    x0, y0, R = _given_bd(problem, cm.A, cm.B, cm.C, cm.D)
    y_hat = _ct_fit.predicted(cm.A, cm.B, cm.C, cm.D, x0, y0, problem.record, R)
    as_is = (cm.B, cm.D, x0, y0, {
        "b_residual_rms": float(np.sqrt(np.mean((problem.record.y - y_hat) ** 2))),
        INFO_KEY: "converted"})
    refit = _linear_fit(problem, feedthrough)

    def fit(A, C):
        return as_is if A is cm.A else refit(A, C)

    A, (B, D, x0, y0, bd), stab = _ct_fit.stable_choice(cm.A, cm.C, fit, problem.record,
                                                        s["stability"])
    bd = dict(bd)
    bd.setdefault(INFO_KEY, "simulation")
    bd = dict(bd, stability=stab, iterations=0)
    if note:
        bd["nyquist_modes"] = note
    return A, B, cm.C, D, x0, y0, bd


def _build(problem: Problem, feedthrough=None, start=None, refit=False) -> StateSpace:
    """The model of order ``problem.order`` (no refinement) from ``start``: 'subspace' (the
    basis-filter estimate), a discrete-time candidate ``'N4SID, horizon f'``, or the
    ``start`` option ('discrete': the converted N4SID models, 'auto': those and the subspace
    estimate, the best by the estimation residual). ``feedthrough`` is the subspace
    estimate's; a converted model has the D of its hold, or with ``refit`` its A and C
    keep B, D (``feedthrough``), x0 refitted by the output regression.

    Built once per problem and arguments (``problem.memo``; its error too): the model
    is the same object every time, not to be modified until the last build of the call.
    """
    s = problem.settings
    if feedthrough is None:
        feedthrough = s["feedthrough"] is True
    start = s["start"] if start is None else start
    key = ("build", problem.order, bool(feedthrough), start, bool(refit))
    if key not in problem.memo:
        try:
            problem.memo[key] = (_build_model(problem, feedthrough, start, refit), None)
        except SubidError as exc:
            problem.memo[key] = (None, exc)
    model, error = problem.memo[key]
    if error is not None:
        raise error
    return model


def _build_model(problem: Problem, feedthrough: bool, start: str, refit) -> StateSpace:
    """:func:`_build` computed (not looked up)."""
    s = problem.settings
    horizons = None
    if _ct_discrete.horizon_of(start) is not None:
        horizons, start = [_ct_discrete.horizon_of(start)], "discrete"
    n = problem.order
    if n > problem.sv.size and start != "discrete":
        raise OrderError(f"order {n} exceeds the {problem.sv.size} directions the "
                         "instruments reveal")
    options, failures = [], {}
    if start in ("auto", "subspace"):
        options.append(("subspace", lambda: _subspace_estimate(problem, n, feedthrough)))
    if start in ("auto", "discrete") and s["bd_method"] == "simulation":
        converted, failures = _discrete_starts(problem, n, horizons)
        options += [(name, partial(_converted, problem, cm, note, feedthrough if refit
                                   else None)) for name, cm, note in converted]
    best = None
    for name, run in options:
        try:
            got = run()
        except ModelError:
            if start != "auto":
                raise
            continue
        score = got[6].get("b_residual_rms", math.inf)
        if best is None or score < best[1]:
            best = (name, score, got)
    if best is None:
        if start == "discrete":
            why = "; ".join(f"horizon {f}: {r}" for f, r in failures.items())
            raise DataError(f"{s['method']}: start='discrete' needs a uniformly sampled "
                            f"record whose N4SID model of order {n} converts to continuous "
                            f"time{' (' + why + ')' if why else ''}; use start='subspace'")
        raise ModelError(f"{s['method']}: no model of order {n} could be simulated over the "
                         "record; try a lower order")
    name, _, (A, B, C, D, x0, y0, diag) = best
    diag["start"] = name
    if name != "subspace":
        feedthrough = bool(np.any(D != 0))
    return _model(problem, A.shape[0], A, B, C, D, x0, y0, diag, feedthrough)


def _model(problem: Problem, n, A, B, C, D, x0, y0, diag, feedthrough) -> StateSpace:
    s, data = problem.settings, problem.data
    basis = s["basis"]
    lam = np.linalg.eigvals(A)
    if not (np.isfinite(A).all() and np.isfinite(B).all() and np.isfinite(C).all()):
        raise ModelError(f"{s['method']}: the estimate of order {n} is not finite")
    info = model_info(
        s["method"], order=n, order_selection=None, horizon=problem.horizon,
        n_samples=data.n_samples, x0=x0, hold="foh" if s["hold"] is None else s["hold"],
        conditions={"bd": diag.get("b_regression_condition")},
        rank_profile=problem.sv, singular_values=problem.sv, basis=basis.name,
        basis_poles=list(basis.poles), n_basis_functions=basis.n_functions,
        poly_order=s["poly_order"], input_order=s["input_order"],
        interpolated_input=s["hold"] is None, startup=s["startup"],
        n_correction_regressors=problem.n_corr, instruments=s["instruments"],
        instrument_lag=problem.lag if s["instruments"] == "past" else None,
        ac_method=s["ac_method"],
        filtering=s["filtering"] if s["filtered"] is None else "given",
        data_equation=s["data_equation"], feedthrough=bool(feedthrough),
        offset=s["offset"], y_offset=y0, largest_real_part=float(lam.real.max()), refined=False,
        subspace_model={"A": A, "B": B, "C": C, "D": D}, **diag)
    if data.n_experiments > 1:
        info["n_experiments"] = data.n_experiments
        info["experiment_names"] = list(data.experiment_names)
    return StateSpace(A, B, C, D, 0.0, input_names=data.input_names,
                      output_names=data.output_names, info=info, hold=info["hold"])


def _build_refined(problem: Problem, feedthrough=None, start=None,
                   refit=False) -> StateSpace:
    """:func:`_build`, then :func:`subid.methods.ct._ct_refine.refine_model` (a candidate of the
    refinement's choice)."""
    return _ct_refine.refine_model(_build(problem, feedthrough, start, refit), problem.record,
                                problem.settings)


# ---------------------------------------------------------------------------
# the method
# ---------------------------------------------------------------------------
@serial_blas
@checked_call
@records_warnings
def ct_subspace(data, order=None, *, basis=None, poly_order: int = 3, estimate_x0: bool = True,
                feedthrough="auto", hold="foh", selection: str = "cv", start: str = "auto",
                offset="auto", stability: str = "auto", noise_model="ar",
                instruments="model", iterations: int = 10, tolerance: float = 1e-4,
                refine="auto", refine_iterations: int = 20, startup: bool = True,
                correction: bool = True, ac_method: str = "joint",
                bd_method: str = "simulation", filtering: str = "exact",
                data_equation: str = "compact", filtered=None) -> StateSpace:
    """Identify a continuous-time state-space model from sampled data (seed 002).

    Parameters
    ----------
    data : IOData
        Input/output samples on a uniform or non-uniform time grid; a record
        of several experiments (:func:`subid.merge`) has one initial state
        (and offset) per experiment, its filters at rest at each start.
    order : int, None, 'auto' or iterable of int
        Model order n. ``None``: chosen among 1..min(10, N p - p) (or the
        candidates given) by ``selection``; the converted N4SID candidates
        (``start='auto'``) come at the orders n4sid scores (past 10 where its
        search goes on), plus one state per Nyquist mode; with the order
        given, only converted models of that order compete.
    basis : FilterBank, optional
        Basis filter bank (:func:`subid.basis.takenaka_malmquist`,
        :func:`~subid.basis.laguerre`, :func:`~subid.basis.legendre`).
        Default :func:`subid.basis.default_basis` of the time stamps (the
        record length and the sampling step) with ``max(8, ceil(10 / p) + 1)``
        functions, enough to reveal order 10.
    poly_order : int
        Degree p of the local polynomials interpolating the output samples
        (eq. (21); 3 in the paper).
    estimate_x0 : bool
        Estimate the initial state ``x(t_0)`` of every experiment with B
        (``info['x0']``).
    feedthrough : {'auto', True, False}
        Estimate D of the basis-filter estimate. ``'auto'``: D = 0 unless the
        cross-validation (at the chosen order) scores the model with D
        significantly better (``info['feedthrough']``). A converted N4SID
        model has the D of its hold (n4sid's own ``feedthrough='auto'``
        decides the discrete-time D; True/False are passed to it).
    hold : {'foh', 'zoh', None}
        The input between samples: linear (first-order hold, the paper's
        Section V), constant (zero-order hold), or None when unknown: then it
        is interpolated like the output (degree ``poly_order``). The input is
        filtered and simulated exactly under this assumption, and the model
        records it (:attr:`StateSpace.hold`; ``'foh'`` for None), so that
        ``simulate``, ``fit_percent`` and the reports use it by default.
    selection : {'cv', 'gap'}
        How an order not given is chosen: ``'cv'``, the discrete-time
        methods' cross-validation (:mod:`subid.methods.dt.selection`: four
        contiguous folds, simulation fit with the model's hold, the smallest
        order within 1 % of the best misfit), or the largest gap of the
        singular values.
    start : {'auto', 'subspace', 'discrete'}
        Where the model comes from before the refinement. ``'subspace'``: the
        basis-filter estimate (the paper's, corrected, with model
        instruments). ``'discrete'``: the discrete-time N4SID model converted
        with the hold, its B and D those of the hold, so that it simulates to
        the N4SID model's samples (MATLAB's route; uniform grids only; a pole
        on the negative real axis becomes a damped mode at the Nyquist
        frequency, ``info['nyquist_modes']``). ``'auto'``: with the default
        basis on a uniform grid both compete in one cross-validation
        (:mod:`subid.methods.ct._ct_discrete`): the basis-filter estimates at
        every candidate order, and the default ``n4sid`` call's candidates
        (every order and horizon it scored, with its own fold scores, orders
        past 10 included); with the order not given the N4SID model is the
        reference, replaced by a basis-filter estimate only when that has the
        lower cross-validated BIC and scores significantly better on the
        folds (better on every fold, or a one-sided paired t-test at 5 %;
        ``info['order_selection']['basis_filter_test']``); with the order
        given, the least criterion wins (``info['start_selection']``). By
        the estimation residual with ``selection='gap'``; the subspace
        estimate alone on a non-uniform grid or with a basis or filtered
        signals given (``info['start']``).
    offset : {'auto', True, False}
        Estimate a constant output offset per experiment (``info['y_offset']``)
        with x0, and project a constant out of the filtered data: the model
        relates the deviations from it, and an offset in the data does not
        become a pole at the origin. ``'auto'``: when the record sits at an
        operating point, i.e. some output's mean exceeds its standard
        deviation in some experiment (``info['offset']``). On a record a few
        time constants long an offset trades with the slow dynamics (seed-002
        system, 10 s records: fit 87 % without, 67 % with), hence not always.
    stability : {'auto', 'enforce', 'none'}
        Poles with real part above ``-1 / (100 T)`` (T the record length:
        unstable, or an integrator to these data) are reflected into the left
        half-plane and B, D, x0 refitted; ``'auto'`` does so unless the output
        grows over the record or the estimate fits clearly better, as the
        discrete-time methods do (``info['stability']``).
    noise_model : {'ar', None}
        ``'ar'``: after the output-error refinement, an AR model of the
        output error (order by BIC) prewhitens a second refinement (the
        Box-Jenkins criterion, as the refined instrumental-variable method
        SRIVC/RIVC does); uniform grids only. None: output error only.
    instruments : {'model', 'past', None}
        ``'model'``: after a first estimate, the SVD uses the correlation of
        the filtered outputs with the states of the model simulated from the
        input alone (re-estimated ``iterations`` times); consistent under output
        noise of any colour. ``'past'``: filtered inputs about two time
        constants of the slowest filter earlier (seed 001 style). None: the
        paper's projection, Lemma 3.
    iterations : int
        Maximum number of instrument iterations (``'model'``).
    tolerance : float
        The instrument iterations stop when the Markov parameters change by
        less than this (relative).
    refine : {'auto', True, False}
        Refine (A, C) of the final model by output-error least squares on the
        raw samples (B, D, x0, offsets eliminated by variable projection),
        then with the noise model. ``info['subspace_model']`` keeps the
        estimate before it. ``'auto'``: the refined and the unrefined model
        compete in the cross-validation at the chosen order and start; the
        refinement is kept only where it scores better on the held-out folds
        (``info['refine_selection']``; on the DaISy evaporator record an
        output-error fit moved a pole to a time constant of half the record
        and lowered the validation fit from 60.3 to 34.1 %), and considered
        only where the work budget affords at least
        :data:`MIN_REFINE_STEPS` steps (a refinement stopped after one or
        two steps is no fit to compare). Without the cross-validation
        (``selection='gap'``, ``filtered``): refined when the model comes from
        the subspace start.
    refine_iterations : int
        Bound on Levenberg-Marquardt steps (Jacobian evaluations) per
        refinement; a work budget (:data:`subid.methods.ct._ct_fit.REFINE_BUDGET`)
        lowers it on large problems (``info['refine_budget_limited']``).
        ``info['refine_converged']`` says whether the refinement stopped on
        its own tests (step, cost or gradient) rather than on this bound.
    startup : bool
        Use the basis functions ``phi(t - t_0)`` as regressors: they absorb
        the filters' start-up transients and the initial-state response.
    correction : bool
        Use the interpolation-correction regressors (see the module notes).
    ac_method : {'joint', 'paper'}
        A and C by least squares on all block equations jointly, or as in the
        paper, (12)-(14) corrected.
    bd_method : {'simulation', 'filtered'}
        B (D, x0) by least squares on the raw output samples through the
        exactly discretised model, or from the filtered data equation (15).
        'simulation' falls back to 'filtered' if simulating A overflows
        (``info['bd_method']`` names the route that ran: also 'converted'
        for a start converted from discrete time).
    filtering : {'exact', 'sections'}
        Interpolate each signal once and propagate the whole filter chain
        exactly, or re-interpolate after every section (the paper's S1-S4).
    data_equation : {'compact', 'paper'}
        The N filtered inputs of (6'), or the paper's N (N + 1) / 2 stacked
        signals per input with the corrected T (real poles, no D).
    filtered : tuple of arrays, optional
        ``(u_f, y_f)``, shapes (L, N, m) and (L, N, p): filtered signals
        computed by the caller (e.g. exactly, for tests), one experiment.
        They replace the filtering step; no correction regressors are used
        then, and an order not given is chosen by the gap rule.

    Returns
    -------
    StateSpace
        Continuous-time model (``dt = 0``) with the data's channel names.
        ``info`` holds the order selection, the singular values, the basis,
        the options, the start used, the stability handling, residuals and
        condition numbers, ``x0``, ``y_offset``, the instrument iterations,
        the refinement and the noise model. Every step runs on the inputs and
        outputs divided by their standard deviations, so the model does not
        depend on their units (``subid.testing``'s ``units`` check); the residual RMS
        values of ``info`` (keys ending in ``_rms``) and the singular values are
        in those units.

    Raises
    ------
    DataError
        ``data`` is not an IOData, an output is constant, a channel's magnitudes
        overflow or underflow in squares (beyond 1e150, or never above 1e-150),
        the mean sampling step is outside 1e-12 to 1e12 time units, ``filtered``
        is malformed.
    TooFewSamplesError
        Fewer samples than the data matrix has rows.
    NotExcitingError
        The filtered inputs are linearly dependent.
    OrderError
        ``order``, ``poly_order``, ``iterations`` invalid.
    ModelError
        ``basis`` is not a FilterBank, or the options need real poles.

    Examples
    --------
    >>> import numpy as np, subid
    >>> from subid.methods.ct.ct_subspace import ct_subspace
    >>> true = subid.StateSpace([[-1.0]], [[1.0]], [[2.0]], 0, dt=0.0)
    >>> t = np.arange(300) * 0.01
    >>> u = np.random.default_rng(0).standard_normal(300)
    >>> y = true.simulate(u, t=t, hold="foh")
    >>> model = ct_subspace(subid.IOData(u, y, t=t), 1)
    >>> float(np.round(model.poles()[0].real, 6))
    -1.0
    """
    method = "ct_subspace"
    data = _check_data(data, method)
    # before the default basis, which reads them
    poly_order = check_int(poly_order, "poly_order", minimum=0)
    if poly_order > MAX_POLY_ORDER:
        raise OrderError(f"poly_order must be at most {MAX_POLY_ORDER}, got {poly_order}")
    check_choice(data_equation, "data_equation", ("compact", "paper"))
    p = data.n_outputs
    # every step on the outputs in units of their standard deviations: the SVD of the
    # filtered outputs, the regressions of A, C and of B, D, x0, and the refinement then
    # weigh the outputs alike whatever their units (unscaled, an output in units 10^4
    # times smaller moved the poles by 2 %); C, D and the offsets are returned in the
    # user's units (_in_user_units). Given filtered signals are used as they are.
    spread = input_spread = None
    if filtered is None:
        # the inputs too (B and D are scaled back): the regressors of B, D and x0 are the
        # simulated responses to the inputs, refused beyond 1e100 (an input of 1e100 met
        # a matmul error deep inside)
        spread, input_spread = column_spread(data.y), column_spread(data.u)
        data = data.scaled(inputs=1.0 / input_spread, outputs=1.0 / spread)
    default_bank = basis is None and filtered is None
    if basis is None:
        basis = default_basis(data.experiments[0].t,
                              _default_size(data, poly_order, hold, feedthrough, startup,
                                            correction, instruments, selection,
                                            data_equation))
    elif not isinstance(basis, FilterBank):
        raise ModelError(f"basis must be a subid.basis.FilterBank (takenaka_malmquist, "
                         f"laguerre, legendre), got {type(basis).__name__}")
    check_choice(refine, "refine", ("auto", True, False))
    for name, flag in (("estimate_x0", estimate_x0), ("startup", startup),
                       ("correction", correction)):
        check_bool(flag, name)
    check_choice(offset, "offset", ("auto", True, False))
    if offset == "auto":
        offset = any(bool(np.any(np.abs(e.y.mean(axis=0)) > e.y.std(axis=0)))
                     for e in data.experiments)
    check_choice(feedthrough, "feedthrough", ("auto", True, False))
    check_choice(hold, "hold", ("foh", "zoh", None))
    check_choice(selection, "selection", ("cv", "gap"))
    check_choice(start, "start", ("auto", "subspace", "discrete"))
    check_choice(stability, "stability", ("auto", "enforce", "none"))
    check_choice(noise_model, "noise_model", ("ar", None))
    check_choice(instruments, "instruments", ("model", "past", None))
    check_choice(ac_method, "ac_method", ("joint", "paper"))
    check_choice(bd_method, "bd_method", CT_OPTIONS)
    check_choice(filtering, "filtering", ("exact", "sections"))
    iterations = check_int(iterations, "iterations", minimum=0)
    refine_iterations = check_int(refine_iterations, "refine_iterations", minimum=1)
    if isinstance(tolerance, bool) or not isinstance(tolerance, numbers.Real) \
            or not tolerance > 0:
        raise OptionError(f"tolerance must be a positive number, got {tolerance!r}")
    if data_equation == "paper":
        if not basis.is_real:
            raise ModelError("data_equation='paper' needs real basis poles (the paper's "
                             "stacked input); use data_equation='compact' for complex poles")
        if feedthrough is True:
            raise ModelError("the paper's data equation (6) has no feedthrough term; use "
                             "data_equation='compact' with feedthrough=True")
        feedthrough = False
        if filtered is not None:
            raise DataError("filtered signals can only be given with data_equation='compact'")
    N = basis.n_functions
    m = data.n_inputs
    if filtered is not None:
        if data.n_experiments > 1:
            raise DataError("filtered signals can only be given for a single experiment")
        filtered = _check_filtered(filtered, data.n_samples, N, m, p)
    input_order = poly_order if hold is None else HOLD_ORDERS[hold]
    max_order = min(DEFAULT_MAX_ORDER, N * p - p)
    if max_order < 1:
        raise OrderError(f"a basis of {N} function(s) with {p} output(s) reveals no state: "
                         "use at least 2 basis functions")
    fixed, candidates = _parse_order(order, max_order)
    def corrections(with_d: bool) -> int:
        """The interpolation-correction regressors of a model with (without) D."""
        if not correction or filtered is not None:
            return 0
        i0, j = _correction_count(poly_order, input_order, with_d)
        return max(0, j - i0 + 1) * N * m

    n_corr = corrections(feedthrough is True)
    settings = dict(method=method, basis=basis, poly_order=poly_order, input_order=input_order,
                    hold=hold, estimate_x0=estimate_x0, feedthrough=feedthrough, offset=offset,
                    stability=stability, start=start, noise_model=noise_model,
                    instruments=instruments, iterations=iterations, tolerance=tolerance,
                    refine_iterations=refine_iterations, startup=startup, n_corr=n_corr,
                    ac_method=ac_method, bd_method=bd_method, filtering=filtering,
                    data_equation=data_equation, filtered=filtered,
                    dt_feedthrough=feedthrough if isinstance(feedthrough, bool) else "auto",
                    nyquist_modes=fixed is None,
                    lag=_lag_for(basis, data.experiments[0].t) if instruments == "past" else 0)
    cv = selection == "cv" and filtered is None

    # the fold models iterate the instruments at most FOLD_ITERATIONS times (cost); they
    # are scored by fit_percent, which fits x0 but knows no offset: with offsets the
    # cross-validation runs on the record with each experiment's means removed, and its
    # models estimate none
    fold_settings = dict(settings, iterations=min(iterations, FOLD_ITERATIONS), offset=False)

    fold_cache = {}

    def prepare_fold(record, orders, horizon):
        # the order, feedthrough and refinement choices use the same folds: each fold is
        # filtered and factored once per call (on records up to FOLD_CACHE_SAMPLES)
        key = (record.n_samples, record.n_experiments, float(record.experiments[0].t[0]),
               float(record.experiments[-1].t[-1]))
        if key not in fold_cache:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem = _prepare(record, orders, fold_settings)
            if record.n_samples > FOLD_CACHE_SAMPLES:
                return problem
            fold_cache[key] = problem
        return replace(fold_cache[key], candidates=list(orders))

    cv_data = data.detrend() if offset else data
    # the discrete-time candidates: on a uniform grid the default N4SID models, converted
    # with the hold, compete in the same cross-validation (their fold scores are n4sid's
    # own, _ct_discrete); with start='auto' only with the default basis
    discrete = cv and data.is_uniform and bd_method == "simulation" and (
        start == "discrete" or (start == "auto" and default_bank))
    subspace = start in ("auto", "subspace") or not discrete
    dt_scores, dm, dm_failure = {}, None, None
    if discrete:
        dm, dm_failure = _ct_discrete.n4sid_default(cv_data, order,
                                        feedthrough=settings["dt_feedthrough"],
                                        stability=stability)
        if dm is None and not subspace:
            raise DataError(f"{method}: start='discrete' needs an N4SID model of the record, "
                            f"and n4sid failed ({dm_failure}); use start='subspace'")
        dt_scores = _ct_discrete.fold_scores(dm)
        if dm is not None and not dt_scores:         # n4sid ran no cross-validation
            dt_scores = None
    order_selection = start_selection = folds_too_short = None
    conversion_notes = []
    if cv and (fixed is None or discrete):
        builds = {}
        if subspace:
            builds["subspace"] = partial(_build, feedthrough=feedthrough is True,
                                         start="subspace")
        if dt_scores is None:                         # scored here instead, at its horizon
            name = _ct_discrete.label(dm.info["horizon"])
            builds[name] = partial(_build, start=name)
            dt_scores = {}
        ct_record = None
        if builds:
            try:
                ct_record = cross_validate(cv_data, fixed, None if fixed else candidates, N,
                                           fitter=_Folds(prepare_fold, builds),
                                           estimators=list(builds))[3]
            except TooFewSamplesError as exc:
                # folds too short for the basis (a record of 20 samples: folds of 10),
                # the whole record is not: its singular values decide, as selection='gap'
                # (the discrete-time methods do the same)
                folds_too_short = (f"the record ({data.n_samples} samples) is too short "
                                   f"for the cross-validation folds ({exc}); the largest "
                                   "gap of the whole record's singular values decides "
                                   "instead")
                cv = False
    if cv and (fixed is None or discrete):
        ranking, record, entries = _ct_discrete.merged_selection(
            ct_record, dt_scores, (ct_record or {}).get("samples_used", cv_data.n_samples),
            m, p, reference=fixed is None)
        if fixed is not None:
            ranking = [c for c in ranking if c[0] == fixed] or ranking
        model = None
        whole = _prepare(data, [ranking[0][0]], settings)
        for n, chosen in ranking:
            problem = replace(whole, order=n, candidates=[n])
            if chosen == "subspace":
                break
            try:
                model = _build(problem, start=chosen)
                break
            except (ModelError, DataError) as exc:
                conversion_notes.append(f"order {n}, {chosen}: {exc}")
        if model is None and chosen != "subspace" and subspace:
            # every discrete-time start ranked failed to convert (an N4SID model at the
            # horizon a barely exciting input allows, with a pole on the negative real
            # axis): the subspace start, which the ranking did not reach
            n, chosen = ranking[-1][0], "subspace"
            problem = replace(whole, order=n, candidates=[n])
        record["selected"] = entries.get((n, chosen), record.get("selected"))
        if fixed is None:
            order_selection = record
        else:
            start_selection = record
    else:
        problem = _prepare(data, candidates, settings)
        usable = [k for k in candidates if k < problem.sv.size] or [candidates[0]]
        n, order_selection = (fixed, None) if fixed is not None else choose_order(
            None, usable, problem.sv, "singular values")
        # start='auto' without the cross-validation: the best by the estimation residual
        both = data.is_uniform and bd_method == "simulation" and default_bank
        chosen = start if start != "auto" else "auto" if both else "subspace"
        problem = replace(problem, order=n, candidates=[n])
        model = None
        if folds_too_short is not None and order_selection is not None:
            order_selection = dict(order_selection, reason=folds_too_short)
    if model is not None and model.info.get("nyquist_modes"):
        warnings.warn(f"{method}: the chosen N4SID model (order {n}): "
                      f"{model.info['nyquist_modes']}", ConversionWarning, stacklevel=3)
    if conversion_notes:
        warnings.warn(f"{method}: the cross-validation preferred discrete-time models that "
                      "have no continuous-time counterpart under the hold; the next "
                      f"candidate was used ({'; '.join(conversion_notes)})",
                      ConversionWarning, stacklevel=3)
    feedthrough_selection = None
    if model is None:
        use_d = feedthrough is True
        if feedthrough == "auto" and cv:
            with_d = {}

            def estimated_d(fold):
                """The fold's model with D, on the problem feedthrough=True prepares (its
                correction regressors; the fold problems are D = 0's)."""
                if corrections(True) != fold.n_corr:
                    key = (fold.data.n_samples, float(fold.data.experiments[0].t[0]))
                    if key not in with_d:
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            with_d[key] = _prepare(fold.data, fold.candidates,
                                                   dict(fold.settings, feedthrough=True,
                                                        n_corr=corrections(True)))
                    fold = replace(with_d[key], order=fold.order, candidates=fold.candidates,
                                   fold=fold.fold)
                return _build(fold, feedthrough=True, start=chosen)

            use_d, feedthrough_selection = _second_wins(
                cv_data, n, N, prepare_fold, ("D = 0", partial(_build, feedthrough=False,
                                                               start=chosen)),
                ("D estimated", estimated_d))
            use_d = bool(use_d)                       # None (folds too short): D = 0
            if use_d and corrections(True) != problem.n_corr:
                # the correction regressors a direct term needs, as feedthrough=True
                # prepares them: without them the D chosen here came with the D = 0
                # problem's (32 regressors for 48; seed-000 system, non-uniform and
                # noise-free, order 4: frequency-response error 0.031 refined, 6.3
                # unrefined, against 7e-11 and 3.7e-4)
                problem = replace(_prepare(data, [n], dict(settings, feedthrough=True,
                                                           n_corr=corrections(True))),
                                  order=n, candidates=[n])
        model = _build(problem, use_d, chosen)
    refit, bd_selection = False, None
    if cv and chosen != "subspace" and n <= (N - 1) * p:
        # the converted model as it is, or its A and C with B, D, x0 from the output
        # regression (output-error optimal for them; D as the subspace estimate's)
        refit, bd_selection = _second_wins(
            cv_data, n, N, prepare_fold, ("converted", partial(_build, start=chosen)),
            ("B, D refitted", partial(_build, feedthrough=feedthrough is True, start=chosen,
                                      refit=True)), test=fixed is None)
        if refit:
            model = _build(problem, feedthrough is True, chosen, refit=True)
    use_d = model.info["feedthrough"]
    refine_selection = None
    steps = _ct_fit.refine_steps(model.order, problem.record)
    if refine == "auto" and cv and steps < MIN_REFINE_STEPS:
        # a refinement stopped by its budget after a step or two is no fit to compare
        do_refine = False
        refine_selection = {"rule": "skipped", "description": (
            f"not refined: the work budget affords {steps} Levenberg-Marquardt step(s) "
            f"at order {model.order} on {data.n_samples} samples, fewer than "
            f"{MIN_REFINE_STEPS}; refine=True refines within the budget")}
    elif refine == "auto" and cv and n <= (N - 1) * p:
        # kept only where it scores better on the held-out folds (ties: not refined)
        do_refine, refine_selection = _second_wins(
            cv_data, n, N, prepare_fold,
            ("as estimated", partial(_build, feedthrough=use_d, start=chosen, refit=refit)),
            ("refined", partial(_build_refined, feedthrough=use_d, start=chosen,
                                refit=refit)))
        if do_refine is None:                         # folds too short: as without them
            do_refine = model.info["start"] == "subspace"
    else:
        do_refine = refine is True or (refine == "auto" and model.info["start"] == "subspace")
    if do_refine:
        model = _ct_refine.refine_model(model, problem.record, problem.settings)
    if refine_selection is not None:
        model.info["refine_selection"] = refine_selection
    model.info["order_selection"] = order_selection if order_selection is not None \
        else {"rule": "given"}
    if feedthrough_selection is not None:
        model.info["feedthrough_selection"] = feedthrough_selection
    if bd_selection is not None:
        model.info["bd_selection"] = bd_selection
    if start_selection is not None:
        model.info["start_selection"] = start_selection
    if dm is not None:
        model.info["discrete_model"] = {"order": dm.order, "horizon": dm.info["horizon"]}
    elif dm_failure is not None:
        model.info["discrete_model"] = {"failed": dm_failure}
    return _in_user_units(model, spread, input_spread)


def _in_user_units(model: StateSpace, spread, input_spread) -> StateSpace:
    """``model`` of the outputs divided by ``spread`` and the inputs by ``input_spread``
    (one factor per channel; None: as it is) in the user's units: C, D,
    ``info['y_offset']`` and ``info['subspace_model']``'s C, D multiplied by ``spread``
    (row by row), B and D divided by ``input_spread`` (column by column), K and the noise
    covariance scaled alike (A and the state, hence x0, unchanged). The residual RMS
    values of ``info`` stay in units of each output's standard deviation."""
    if spread is None:
        return model
    info = dict(model.info)
    if info.get("y_offset") is not None:
        info["y_offset"] = np.asarray(info["y_offset"]) * spread
    if isinstance(info.get("subspace_model"), dict):
        sub = dict(info["subspace_model"])
        sub["C"] = np.asarray(sub["C"]) * spread[:, None]
        sub["D"] = np.asarray(sub["D"]) * spread[:, None] / input_spread[None, :]
        if sub.get("B") is not None:
            sub["B"] = np.asarray(sub["B"]) / input_spread[None, :]
        info["subspace_model"] = sub
    K, cov = model.K, model.noise_cov
    return StateSpace(model.A, model.B / input_spread[None, :], model.C * spread[:, None],
                      model.D * spread[:, None] / input_spread[None, :],
                      0.0, input_names=model.input_names, output_names=model.output_names,
                      info=info, hold=model.hold, K=None if K is None else K / spread,
                      noise_cov=None if cov is None else cov * np.outer(spread, spread))


@serial_blas
@checked_call
def ct_subspace_paper(data, order=None, *, basis=None, poly_order: int = 3) -> StateSpace:
    """The paper's printed algorithm, with its typos corrected (seed 002).

    Data equation (6) with the stacked input and the corrected ``T``
    (:func:`tm_convolution_matrix`), both signals interpolated by degree-p
    polynomials and filtered section by section (S1-S4), no start-up or
    correction regressors, no instruments, A and C by (12)-(14), B by (15),
    no refinement, no offset, no stability handling, the order (when not given)
    at the largest singular-value gap. For comparison with :func:`ct_subspace`;
    real poles only.
    """
    try:
        return ct_subspace(data, order, basis=basis, poly_order=poly_order, estimate_x0=False,
                           feedthrough=False, hold=None, instruments=None, startup=False,
                           correction=False, refine=False, ac_method="paper",
                           bd_method="filtered", filtering="sections", data_equation="paper",
                           selection="gap", start="subspace", offset=False, stability="none",
                           noise_model=None)
    except SubidError as exc:           # the messages name the function the user called
        raise name_caller(exc, "ct_subspace", "ct_subspace_paper") from None
