"""Steps shared by the discrete-time subspace methods.

Argument checks at the public boundary, the data statistic and the excitation
check (:func:`prepare`, :class:`Problem`), the shift-invariance step that gives
A and C from an extended observability matrix, the B, D, x0 regression and the
stability rule (:func:`b_d_fit`, :func:`b_d_refit`, :func:`stable_choice`), the
model and its ``info`` (:func:`finish`), the noise model and refinement
(:func:`finalize`). :mod:`subid.methods.dt.pipeline` calls them in order.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from subid._validation import check_int
from subid.data import IOData, column_spread, column_std
from subid.errors import (
    DataError,
    OptionError,
    OrderError,
    SubidError,
    TooFewSamplesError,
    UnstableModelWarning,
)
from subid.methods._common import (  # noqa: F401 (names of this module's API)
    CONDITION_KEYS,
    CONDITION_WARN,
    DEFAULT_HORIZON_UNKNOWN_ORDER,
    RANK_TOL,
    check_excitation,
    choose_order,
    conditions_of,
    default_horizon,
    gap_scores,
    min_samples,
    normalize_channels,
    order_from_gap,
)
from subid.methods._common import parse_order as _parse_order
from subid.methods._info import model_info
from subid.methods._stability import (  # noqa: F401 (names of this module's API)
    GROWTH_LIMIT,
    KEEP_UNSTABLE_RATIO,
    STABILITY,
    STABLE_RADIUS,
    output_growth,
    record_growth,
    reflect_unstable_poles,
    spectral_radius,
    stability_request,
    stable_shift_invariance,
)
from subid.methods.bd import (  # noqa: F401 (check_experiment_lengths: names of this API)
    INFO_KEY,
    Projection,
    check_experiment_lengths,
    experiment_starts,
    fit_b_d_x0,
)
from subid.methods.crossval import MAX_ORDER
from subid.methods.dt._lag_fit import LAG_PRODUCTS
from subid.methods.dt._lapack import (  # noqa: F401 (names of this module's API)
    least_squares_gelsy,
    orthonormal_basis,
)
from subid.methods.dt.checks import check_data
from subid.methods.dt.selection import RECORD_FACTOR, default_gap_horizon
from subid.model.statespace import StateSpace
from subid.statistic._hankel import HankelFactor
from subid.statistic.hankel import HankelStatistic

#: The largest of the default candidate orders (the selection's).
DEFAULT_MAX_ORDER = MAX_ORDER


def check_order_horizon(order, horizon, data, *, method: str, blocks_per_horizon: int = 2):
    """Validate the order and the horizon.

    ``order`` is an int, ``None``/``'auto'`` (candidates 1..10), or an
    iterable of candidate orders (as MATLAB's ``n4sid(data, 1:10)``).

    Returns
    -------
    order : int or None
        The fixed order, or None when it is to be chosen.
    candidates : list of int
        Orders to choose from (``[order]`` when fixed).
    horizon : int
    """
    fixed, candidates = _parse_order(order)
    n_outputs = data.n_outputs
    largest = fixed if fixed is not None else (max(candidates) if candidates else None)
    horizon = default_gap_horizon(data.n_samples, data.n_inputs, n_outputs, blocks_per_horizon,
                                  largest or DEFAULT_MAX_ORDER,
                                  n_experiments=getattr(data, "n_experiments", 1)) \
        if horizon is None else \
        check_int(horizon, "horizon", minimum=2)
    max_order = (horizon - 1) * n_outputs
    if largest is not None and largest > max_order:
        need = math.ceil(largest / n_outputs) + 1
        raise OrderError(f"{method}: order {largest} cannot be revealed with horizon {horizon} "
                         f"and {n_outputs} output{'s' if n_outputs != 1 else ''}: the shifted "
                         f"observability matrix has only {max_order} rows; use horizon >= {need}")
    if fixed is not None:
        candidates = [fixed]
    elif candidates is None:
        candidates = list(range(1, min(DEFAULT_MAX_ORDER, max_order) + 1))
    return fixed, candidates, horizon


def data_factor(data: IOData, depth: int, *, method: str, horizon: int,
                statistic: str = "auto", factor: HankelFactor | None = None) -> HankelFactor:
    """Hankel factor of ``data`` with ``depth`` block rows, after the sample check
    (``factor``: that factor, already computed)."""
    nu, ny = data.n_inputs, data.n_outputs
    rows = depth * (nu + ny)
    need = min_samples(depth, nu, ny)
    if data.n_experiments > 1:
        columns = sum(max(b - a - depth + 1, 0) for a, b in data.experiment_ranges)
        if columns < rows:
            raise TooFewSamplesError(
                f"{method}: the {data.n_experiments} experiments give {columns} Hankel columns "
                f"of {depth} block rows (each experiment N_e - {depth - 1}) but horizon "
                f"{horizon} needs at least {rows}; reduce the horizon or supply more data")
    elif data.n_samples < need:
        raise TooFewSamplesError(
            f"{method}: {data.n_samples} samples are too few for horizon {horizon} with "
            f"{nu} input{'s' if nu != 1 else ''} and {ny} output{'s' if ny != 1 else ''}: "
            f"the {depth}-block-row Hankel matrix has {rows} rows and needs at least "
            f"{need} samples; reduce the horizon or supply more data")
    if factor is not None:
        return factor
    return HankelStatistic.from_data(data, depth, kind=statistic).factor()


def shift_invariance(gamma: np.ndarray, n_outputs: int, *, residual: bool = True):
    """A and C from an extended observability matrix by shift invariance.

    ``C = Gamma[0:ny]`` and ``A`` solves ``Gamma[:-ny] A = Gamma[ny:]`` in the
    least-squares sense (QR with column pivoting; no SVD; :func:`least_squares_gelsy`).

    Returns
    -------
    A, C, relative_residual
        ``relative_residual`` (``info['shift_residual']``) None without ``residual`` (a
        cross-validation fold's candidate, whose ``info`` is not kept).
    """
    up, down = gamma[:-n_outputs], gamma[n_outputs:]
    A = least_squares_gelsy(up, down)
    C = gamma[:n_outputs].copy()
    if not residual:
        return A, C, None
    resid = np.linalg.norm(up @ A - down) / max(np.linalg.norm(down), 1e-300)
    return A, C, float(resid)


def output_weights(y: np.ndarray) -> np.ndarray:
    """Weights of the outputs in the B, D, x0 regression: 1 / standard deviation.

    The regression then minimises the sum over the outputs of the squared
    errors relative to each output's spread, so that no output dominates the
    fit because of its units (a constant output cannot reach here:
    :func:`check_data` rejects it).
    """
    return 1.0 / column_spread(y, block=8192)    # channel by channel, 8192 samples a block


def b_d_fit(problem: "Problem", C_n, gamma, L11, L_yu, *, bd_method: str, feedthrough: bool,
            estimate_x0: bool):
    """``fit(A) -> (B, D, x0, diagnostics)`` of :func:`stable_choice`: B, D and x0 by
    :func:`subid.methods.bd.fit_b_d_x0` (``bd_method``) on the problem's data.

    ``C_n``, ``gamma``, ``L11`` and ``L_yu`` are in the units of the normalised
    channels of ``problem`` (what the ``'projection'`` route needs); B and D come
    back in the user's units. The output regression weights each output by the
    inverse of its standard deviation (:func:`output_weights`). ``fit(A,
    worse_than=r)``: no fit where the residual RMS is proven at least ``r``
    (:func:`subid.methods.bd.fit_b_d_x0`, route ``'bound'``).
    """
    projection = Projection(C_n, gamma, L11, L_yu, problem.unscale)
    C = C_n * problem.output_scale[:, None]
    weights = problem.weights() if isinstance(problem.data, IOData) else None
    # a cross-validation fold: the record's lag products, shared by every candidate
    # (subid.methods.dt.selection.score_horizon; subid.methods.dt._lag_fit)
    lagged = problem._cache.get(LAG_PRODUCTS) if bd_method in ("auto", "simulation") else None

    def fit(A, worse_than=None):
        if lagged is not None:
            from subid.methods.dt._lag_fit import fit_b_d_x0 as lag_fit
            fitted = lag_fit(A, C, lagged, weights, feedthrough=feedthrough,
                             estimate_x0=estimate_x0)
            if fitted is not None:
                fitted[3].update({INFO_KEY: "simulation",
                                  "spectral_radius": spectral_radius(A)})
                return fitted[0], fitted[1], fitted[2] if estimate_x0 else None, fitted[3]
        return fit_b_d_x0(A, C, problem.data, bd_method=bd_method, feedthrough=feedthrough,
                          estimate_x0=estimate_x0, output_weights=weights,
                          projection=projection, worse_than=worse_than)
    return fit


def lag_fold_score(problem: "Problem", A_q, C_n, held, *, bd_method: str, feedthrough: bool,
                   estimate_x0: bool):
    """The score (:func:`subid.methods.dt.selection.score_matrices`) on the validation
    record of ``held`` (:class:`subid.methods.dt._scoring.Held`) of a fold candidate
    whose A (``A_q``, with ``C_n`` in the units of the normalised channels) is stable,
    its B, D, x0 from the lag products of ``problem``'s training record: the model
    :func:`b_d_fit` and :func:`stable_choice` make for a stable A (no stability rule
    applies), without their closures and diagnostics, and, where the validation
    record's lag products give it, its error power from the same modal form
    (:func:`subid.methods.dt._lag_fit.fit_and_error`). None where the products do not
    give the fit (an unstable A, a pole too slow for the lags, a nearly exact fit, no
    products): the caller then takes those steps."""
    from subid.methods.dt._lag_fit import fit_and_error
    from subid.methods.dt._scoring import fits_of_error
    from subid.methods.dt.selection import mean_score, score_matrices
    lagged = problem._cache.get(LAG_PRODUCTS)
    if lagged is None or bd_method not in ("auto", "simulation") \
            or not isinstance(problem.data, IOData):
        return None
    products = held.products()
    C = C_n * problem.output_scale[:, None]
    if len(products) != 1 or products[0] is None:
        from subid.methods.dt._lag_fit import fit_b_d_x0 as lag_fit
        fitted = lag_fit(A_q, C, lagged, problem.weights(), feedthrough=feedthrough,
                         estimate_x0=estimate_x0)
        return None if fitted is None else score_matrices(A_q, fitted[0], C, fitted[1], held)
    got = fit_and_error(A_q, C, lagged, problem.weights(), products[0], held.weights,
                        1.0 / held.scale, feedthrough=feedthrough, estimate_x0=estimate_x0)
    if got is None:
        return None
    B, D, err = got
    if err is None:                   # the products give the fit, not the score: the pass
        return score_matrices(A_q, B, C, D, held)
    return mean_score(fits_of_error(err, held))


def b_d_refit(problem: "Problem", C, *, feedthrough: bool, estimate_x0: bool):
    """``refit_unstable(A, fitted)`` of :func:`stable_choice`: B, D, x0 of an unstable
    A by the ``'prediction'`` route of :func:`subid.methods.bd.fit_b_d_x0`, or None.

    For an unstable A the output-error regression is ill-posed over a long
    record: the sensitivities ``C A^t`` grow without bound, the regression fits
    the growth of the last samples and the initial state rather than the
    input-output behaviour (on the DaISy ballbeam record, MOESP at order 2:
    validation fit 79.8 %; the same A and C with B, D from the state regression
    of N4SID: 88.9 %). The one-step predictor is well posed because ``A - K C``
    is stable; K comes from the noise model of the output-error estimate
    ``fitted = (B, D, ...)`` (:func:`subid.methods.dt.noise_model.innovation_model`).
    None when there are no raw samples, the factor is too shallow for the
    noise model, or it gives no stable predictor.
    """
    from subid.methods.dt.noise_model import innovation_model, user_factor

    def refit(A, fitted):
        if not isinstance(problem.data, IOData):
            return None
        try:
            with np.errstate(all="ignore"):
                K, _, diag = innovation_model(A, fitted[0], C, fitted[1], user_factor(problem))
        except (SubidError, np.linalg.LinAlgError, ValueError):
            return None
        if not np.isfinite(K).all() or diag["predictor_spectral_radius"] >= 1.0:
            return None
        refitted = fit_b_d_x0(A, C, problem.data, bd_method="prediction", noise_gain=K,
                              feedthrough=feedthrough, estimate_x0=estimate_x0,
                              output_weights=problem.weights())
        if refitted is not None:
            refitted[3]["predictor_spectral_radius"] = diag["predictor_spectral_radius"]
        return refitted
    return refit


WEIGHTINGS = ("moesp", "cva", "n4sid")


def check_weighting(weighting: str) -> str:
    if weighting not in WEIGHTINGS:
        raise OptionError(f"weighting must be one of {WEIGHTINGS} (MATLAB's N4Weight), got "
                         f"{weighting!r}")
    return weighting


def cva_factor(y_perp: np.ndarray) -> np.ndarray:
    """Upper-triangular R with ``R^T R = Y_f Π⊥ Y_f^T`` (plus a tiny ridge).

    ``y_perp`` holds the coefficient rows of ``Y_f Π⊥_{U_f}``. CVA weights
    the oblique projection by ``W1 = (Y_f Π⊥ Y_f^T)^{-1/2}``; ``R^{-T}`` is
    such a square root up to an orthogonal factor, which leaves the singular
    values and the recovered range(Γ) = range(W1^{-1} U_n) unchanged. The
    ridge (1e-10 of the mean diagonal) keeps R invertible on noise-free data,
    where ``Y_f Π⊥`` has rank n only; any invertible W1 gives the exact range
    there.
    """
    m = y_perp.shape[0]
    ridge = 1e-10 * max(np.linalg.norm(y_perp) ** 2 / m, 1e-300)
    stacked = np.vstack([y_perp.T, math.sqrt(ridge) * np.eye(m)])
    return scipy.linalg.qr(stacked, mode="r", check_finite=False)[0][:m]


def stable_choice(A_q, Q, n_outputs: int, fit, *, stability: str, data, method: str,
                  refit_unstable=None, bound_unstable: bool = False):
    """A in the orthonormal basis ``Q``, stable when that is right, with its B, D, x0.

    ``fit(A_q)`` returns ``(B, D, x0, diagnostics)`` for a given A (the
    output regression of :func:`b_d_fit`, in the basis of ``Q``).

    * ``'none'``, a stable A, or :func:`stability_request` false: A as
      estimated.
    * ``'enforce'``: a stable A, with B, D, x0 refitted for it: the unstable
      poles reflected into the unit circle (:func:`reflect_unstable_poles`),
      or, for a nearly defective A, the regularised shift invariance
      (:func:`stable_shift_invariance`). On the bundled records reflection
      kept the validation fit (robot_arm, classical N4SID at order 7:
      57.9 % unstable, 96.7 % reflected, 7.0 % regularised), because the
      regularisation moves every pole and parks the unstable ones at the
      unit circle, where they drift.
    * ``'auto'``: both are fitted; the unstable A is kept only when it explains
      the estimation data clearly better (its
      residual RMS below :data:`KEEP_UNSTABLE_RATIO` times the stable one's):
      an unstable plant in closed loop (e.g. a ball on a beam) keeps its
      unstable model, while a spurious unstable mode, which the data do not
      need, is removed (growing data too: :func:`stability_request`).

    When the A returned is unstable and ``refit_unstable(A_q, fitted)`` is
    given, B, D, x0 come from it instead (:func:`b_d_refit`: the
    output-error regression is ill-posed for an unstable A), unless it
    returns None.

    ``bound_unstable`` (the models of the cross-validation folds, whose ``info``
    is not kept): under ``'auto'`` the unstable A is fitted only when it can be
    kept: not when the stabilised fit has no residual to compare with, nor when
    part of the record already proves its residual too large
    (``fit(A_q, worse_than=...)``, :mod:`subid.methods.dt._residual_bound`). The
    model is the same as with the full fit; ``record['residual_unstable']`` is then
    missing (``'residual_unstable_at_least'`` holds the bound).

    Returns
    -------
    A_q, (B, D, x0, diagnostics), record
        ``record`` is ``info['stability']``.
    """
    before = spectral_radius(A_q)
    record = {"requested": stability, "action": "none", "spectral_radius_before": before}

    def unstable(fitted):
        if refit_unstable is None:
            return fitted
        refitted = refit_unstable(A_q, fitted)
        return fitted if refitted is None else refitted

    if not stability_request(stability, A_q, data, method):
        return A_q, (unstable(fit(A_q)) if before >= 1.0 else fit(A_q)), record
    # the unstable poles reflected; where the eigenvectors are unreliable (a nearly
    # defective A), the regularised shift invariance
    A_s = reflect_unstable_poles(A_q)
    if A_s is not None:
        how = {"how": "unstable poles reflected into the unit circle (1/conj(p))"}
    else:
        A_s, c = stable_shift_invariance(Q, n_outputs)
        how = {"how": "regularised shift invariance (Maciejowski 1995)", "regularization": c}
    fitted_s = fit(A_s)
    record.update(action="enforced", **how,
                  spectral_radius_after=spectral_radius(A_s))
    record["how"] += "; B, D, x0 refitted for the stable A"
    if stability == "auto":
        r_s = _simulation_rms(fitted_s[3], stable=True)
        if bound_unstable:
            if r_s is None or math.isnan(r_s):        # the unstable model cannot win
                record.update(residual_stable=r_s)
                return A_s, fitted_s, record
            fitted_u = fit(A_q, worse_than=KEEP_UNSTABLE_RATIO * r_s)
            if fitted_u[3].get(INFO_KEY) == "bound":
                record.update(residual_unstable_at_least=fitted_u[3]["residual_at_least"],
                              residual_stable=r_s)
                return A_s, fitted_s, record
        else:
            fitted_u = fit(A_q)
        r_u = _simulation_rms(fitted_u[3], stable=False)
        record.update(residual_unstable=r_u, residual_stable=r_s)
        if r_u is not None and r_s is not None and math.isfinite(r_u) \
                and r_u < KEEP_UNSTABLE_RATIO * r_s:
            record.update(action="kept unstable",
                          how=f"the unstable model fits the estimation data clearly better "
                              f"(residual RMS {r_u:.3g} against {r_s:.3g} when stabilised)")
            return A_q, unstable(fitted_u), record
    return A_s, fitted_s, record


def _simulation_rms(diagnostics, *, stable: bool):
    """The residual RMS of a fit's simulation that :func:`stable_choice` compares: the
    output regression's own (any route for the stabilised A; the simulation route only
    for the unstable one, whose prediction route fits another criterion), else the
    ``simulation_residual_rms`` a state-sequence fit computed
    (:func:`simulation_residual`; :func:`subid.pbsid`); None without one."""
    if diagnostics.get("residual_rms") is not None and (
            stable or diagnostics.get(INFO_KEY) == "simulation"):
        return diagnostics["residual_rms"]
    return diagnostics.get("simulation_residual_rms")


def simulation_residual(A, B, C, D, data, weights) -> float:
    """RMS over the samples and outputs of ``weights * (y - ŷ)``, ``ŷ`` the simulation of
    ``(A, B, C, D)`` on ``data`` from its least-squares initial state(s)
    (:func:`subid.model.prediction.simulate_fit`): the ``residual_rms`` of the output
    regression for B, D, x0 given, which :func:`stable_choice` compares between an
    unstable A and its stabilised one; ``inf`` where the simulation overflows."""
    from subid.model.prediction import simulate_fit
    try:
        with np.errstate(all="ignore"):
            y_hat = simulate_fit(StateSpace(A, B, C, D, data.dt), data)[0]
    except SubidError:
        return math.inf
    value = float(np.sqrt(np.mean(((data.y - y_hat) * weights) ** 2)))
    return value if math.isfinite(value) else math.inf


def initial_state(A, B, C, D, data):
    """Least-squares initial state of the model on ``data`` (None without raw samples
    or when the simulation overflows); one row per experiment for a record of
    several (:func:`subid.merge`)."""
    if not isinstance(data, IOData):
        second_pass = getattr(data, "output_regression", None)   # subid.methods.dt._bd_pass
        return None if second_pass is None else second_pass.initial_state(A, B, C, D)
    if data.n_experiments > 1:
        check_experiment_lengths(data, A.shape[0])
        rows = [_initial_state_one(A, B, C, D, e, column_std(data.y)) for e in data.experiments]
        return None if any(r is None for r in rows) else np.stack(rows)
    return _initial_state_one(A, B, C, D, data, column_std(data.y))


def _initial_state_one(A, B, C, D, data, output_std):
    from subid.model.prediction import simulate_fit
    # The free response C A^t x0 of a stable A falls below 1e-18 of its start after
    # `decay` samples: beyond them the samples carry no information on x0 (to rounding),
    # so the regression runs on that prefix only (bounded time and memory).
    radius = spectral_radius(A) if A.size else 0.0
    used = data
    if radius < 1.0:
        decay = A.shape[0] + 1 if radius == 0.0 else \
            A.shape[0] + 1 + int(math.ceil(math.log(1e-18) / math.log(radius)))
        if decay < data.n_samples:
            used = data[:decay]
    try:
        with np.errstate(all="ignore"):
            return simulate_fit(StateSpace(A, B, C, D, data.dt), used,
                                output_std=output_std)[1]
    except SubidError:
        return None


@dataclass(frozen=True)
class Problem:
    """A validated identification problem and its data statistic."""

    method: str
    data: IOData
    order: int | None
    candidates: list
    horizon: int
    factor: HankelFactor
    input_condition: float
    input_scale: np.ndarray
    output_scale: np.ndarray
    #: A cross-validation fold model (:func:`subid.methods.dt.selection.score_horizon`):
    #: it is scored with an x0 fitted on the held-out data, so the estimation x0 that
    #: costs a simulation of its own (the state-sequence estimate's) is skipped.
    fold: bool = False
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def fold_at(self, order: int) -> "Problem":
        """``dataclasses.replace(self, order=order, candidates=[order], fold=True)`` (the
        same fields, the cache shared) without its checks: the problem of a
        cross-validation candidate (:func:`subid.methods.dt.selection.score_horizon`, one
        per order of every fold and horizon)."""
        out = object.__new__(Problem)
        out.__dict__.update(self.__dict__)
        out.__dict__.update(order=order, candidates=[order], fold=True)
        return out

    def weights(self) -> np.ndarray:
        """:func:`output_weights` of the record, computed once per problem."""
        cached = self._cache.get("weights")
        if cached is None:
            cached = self._cache["weights"] = output_weights(self.data.y)
        return cached

    def cached(self, key, compute):
        """``compute()``, once per problem and ``key``: the steps that do not depend
        on the order (the problems of one fold's candidate orders share this cache,
        :func:`subid.methods.dt.selection.score_horizon`, so that every order comes
        from one factorisation and one SVD). The result must be treated as read-only."""
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]

    def stored(self, key):
        """What :meth:`cached` (or :func:`prepare`) stored under ``key``, or None."""
        return self._cache.get(key)

    def unscale(self, B_n, C_n, D_n):
        """B, C, D in the user's units from those of the normalised channels."""
        su, sy = self.input_scale, self.output_scale
        return B_n / su, C_n * sy[:, None], D_n * sy[:, None] / su


def future_past_factor(pb) -> np.ndarray:
    """The factor of ``[U_f; U_p; Y_p; Y_f]``, once per problem (:meth:`Problem.cached`)."""
    hf, f = pb.factor, pb.horizon
    return pb.cached("future-past factor", lambda: hf.retriangularize(
        hf.u_rows(f, 2 * f), hf.u_rows(0, f), hf.y_rows(0, f), hf.y_rows(f, 2 * f)))


STATISTICS = ("auto", "qr", "gram")


def prepare(data, order, horizon, *, method: str, blocks_per_horizon: int = 2,
            statistic: str = "auto", normalize_outputs: bool = True,
            factor: HankelFactor | None = None, checked: bool = False) -> Problem:
    """Validate the arguments, build the Hankel factor and check excitation.

    ``factor``: the Hankel factor of the record (depth ``blocks_per_horizon *
    horizon``), when already computed (:func:`subid.methods.dt.selection.score_horizon`
    merges the folds' statistics from those of their blocks). ``checked``: the record
    already passed :func:`check_data` (a fold at its second horizon).

    ``data`` is an :class:`IOData` record or a :class:`HankelStatistic`
    (identification from the statistic only). ``blocks_per_horizon`` is 2
    when past and future block rows are used (instruments), 1 for future
    rows only. ``statistic`` chooses the kind of statistic built from a
    record (see :mod:`subid.statistic.hankel`).
    """
    if statistic not in STATISTICS:
        raise OptionError(f"statistic must be one of {STATISTICS}, got {statistic!r}")
    if isinstance(data, HankelStatistic):
        if data.depth % blocks_per_horizon:
            raise DataError(f"{method} needs a statistic whose depth is a multiple of "
                            f"{blocks_per_horizon}; this one has depth {data.depth}")
        implied = data.depth // blocks_per_horizon
        if horizon is not None and check_int(horizon, "horizon", minimum=2) != implied:
            raise DataError(f"the statistic was built with depth {data.depth}, i.e. horizon "
                            f"{implied} for {method}; got horizon={horizon}. Build the "
                            f"statistic with depth {blocks_per_horizon * horizon}")
        fixed, candidates, horizon = check_order_horizon(
            order, implied, data, method=method, blocks_per_horizon=blocks_per_horizon)
        need = min_samples(data.depth, data.n_inputs, data.n_outputs)
        if data.n_samples < need:
            raise TooFewSamplesError(f"{method}: the statistic holds {data.n_samples} samples; "
                                     f"horizon {horizon} needs at least {need}")
        hf = data.factor()
    else:
        data = data if checked else check_data(data, method)
        fixed, candidates, horizon = check_order_horizon(
            order, horizon, data, method=method, blocks_per_horizon=blocks_per_horizon)
        hf = data_factor(data, blocks_per_horizon * horizon, method=method, horizon=horizon,
                         statistic=statistic, factor=factor)
    input_condition = check_excitation(hf, data.input_names, method=method)
    record_factor = hf
    hf, su, sy = normalize_channels(hf, outputs=normalize_outputs)
    problem = Problem(method, data, fixed, candidates, horizon, hf, input_condition, su, sy)
    # the factor as built from the record (before the channels are normalised): another
    # problem of the same record and horizon takes it as ``factor``
    problem._cache[RECORD_FACTOR] = record_factor
    return problem


SYSTEM_MATRICES = ("auto", "shift", "states")


def check_system_matrices(system_matrices: str) -> str:
    if system_matrices not in SYSTEM_MATRICES:
        raise OptionError(f"system_matrices must be one of {SYSTEM_MATRICES}, got "
                         f"{system_matrices!r}")
    return system_matrices


def finalize(model: StateSpace, problem: Problem, *, refine, delays,
             statistic: str = "auto", record=None) -> StateSpace:
    """The final model of a DT batch method: its noise model (K and the innovation
    covariance, :func:`subid.methods.dt.noise_model.attach_noise_model`; a gain that
    predicts clearly worse than none refitted, :func:`subid.methods.dt.gain.checked_gain`),
    then the optional refinement, :func:`refined`) and its input delays (:func:`subid.delay.record_delay`;
    ``info['input_delay']`` None without delays), with the ``refine`` and ``statistic``
    options in use recorded in ``info``; with delays, ``info['x0']`` is the state at the
    first sample of ``record`` (the caller's record before the shift,
    :func:`subid.methods._info.delayed_x0`). Run once, on the final model."""
    from subid.delay import record_delay
    from subid.methods._info import delayed_x0
    from subid.methods.dt.gain import checked_gain
    from subid.methods.dt.noise_model import attach_noise_model
    model = attach_noise_model(model, problem)
    if isinstance(problem.data, IOData):
        model = checked_gain(problem.data, model)
    if refine is not None:
        model = refined(problem.data, model, refine)
    model.info["refine"] = refine          # the values in use, as every option's
    model.info["statistic"] = statistic
    model.info["input_delay"] = None        # no delay; record_delay stores the delays
    model = record_delay(model, delays)
    if delays is not None and isinstance(record, IOData):
        model = delayed_x0(model, record, prediction=refine == "prediction")
    return model


def refined(data, model: StateSpace, focus: str) -> StateSpace:
    """``model`` refined by :func:`subid.pem` with ``focus`` ('simulation' or 'prediction').

    An unstable model has no simulation error to minimise: with focus
    'simulation' it is returned unrefined, with a warning and
    ``info['refinement']`` saying why (a silent fallback to the other
    criterion would not be what was asked).
    """
    from subid.errors import ModelError
    from subid.methods.dt.pem import pem
    try:
        return pem(data, model, focus=focus)
    except ModelError as exc:
        warnings.warn(f"{model.info.get('method', 'identification')}: refine={focus!r} not "
                      f"done: {exc}", UnstableModelWarning, stacklevel=4)
        info = dict(model.info)
        info["refinement"] = f"not done: {exc}"
        return model.with_noise_model(model.K, model.noise_cov, info=info)


def check_stability(A, data, method: str) -> dict:
    """Warn when the model is unstable though the data show no growth.

    An unstable mode with spectral radius r would multiply the output by
    about ``r^(0.9 N)`` between the first and the last tenth of the record;
    when that exceeds 10 but the measured output grew by less than 3x, the
    data do not show the instability: an over-fitted order or noise, unless
    the plant itself is unstable and was measured in closed loop.
    """
    radius = spectral_radius(A)
    diag = {"spectral_radius": radius}
    if radius < 1 or not isinstance(data, IOData):
        return diag
    growth = record_growth(data)
    diag["output_growth"] = growth
    longest = max(b - a for a, b in data.experiment_ranges)
    predicted = 0.9 * longest * math.log10(radius)
    # "does not grow" only when neither about the mean nor about zero: a plant diverging
    # in one direction from rest grows 19x about zero and 1.8x about its mean
    if predicted > 1 and growth < 3 and \
            max(output_growth(e.y, centred=False) for e in data.experiments) < 3:
        warnings.warn(f"{method}: the identified model is unstable (spectral radius "
                      f"{radius:.4g}) although the measured output does not grow over the "
                      f"record (last/first RMS {growth:.2g}). Unless the plant is unstable and "
                      "was measured in closed loop, the order may be too high or the data too "
                      "noisy: try a lower order or compare the fits of several",
                      UnstableModelWarning, stacklevel=4)
    return diag


def finish(problem: Problem, A, B, C, D, n: int, order_selection: dict, **info) -> StateSpace:
    """The identified model with the diagnostics every method reports."""
    data = problem.data
    x0 = info.pop("x0", None)
    info = model_info(problem.method, order=n, order_selection=order_selection,
                      horizon=problem.horizon, n_samples=data.n_samples, x0=x0, hold="zoh",
                      conditions=conditions_of(info, input=problem.input_condition),
                      **{"input_condition": problem.input_condition, **info,
                         **check_stability(A, data, problem.method)})
    if "rank_profile" not in info and "singular_values" in info:
        info["rank_profile"] = info["singular_values"]     # one name across methods
    if getattr(data, "n_experiments", 1) > 1:
        info["n_experiments"] = data.n_experiments
        if isinstance(data, IOData):
            info["experiment_names"] = list(data.experiment_names)
    return StateSpace(A, B, C, D, data.dt, input_names=data.input_names,
                      output_names=data.output_names, info=info)

