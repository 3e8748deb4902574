"""The choice made from the fold scores, and the model of the whole record made with it.

:func:`subid.methods.dt.selection.cross_validate` scores the candidates on the folds;
:func:`choose` takes its choice, lets :func:`innovation_check` raise the order when the
innovation form of the models fitted to the record demands it (Schwarz's criterion on
the one-step prediction errors, :func:`innovation_bic`), fits the model of the whole
record (sharing with it what the check computed there, :class:`RecordWork`) and, when
only that model had to be stabilised, falls back to a runner-up
(:func:`unrepaired_choice`). The rules and their measurements are in
:mod:`subid.methods.dt.selection`'s docstring.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np

from subid.errors import SubidError
from subid.methods.crossval import ABSOLUTE_TOLERANCE
from subid.methods.dt.selection import (
    RECORD_FACTOR,
    cross_validate,
    estimator_by_fit,
    stabilised,
)

#: Candidates tried, best first, when the final model of the chosen one had to be
#: stabilised although not all of its fold models had (:func:`unrepaired_choice`).
MAX_FALLBACKS = 4


def choose(data, plan, fitter):
    """The cross-validated choice of a plan's order and horizon (and, with
    ``plan.estimator_choice == 'cv'``, estimator), and the model of the whole record
    made with it.

    ``plan`` (:class:`subid.methods.dt.plan.Plan`) gives what is chosen: the order
    and horizon not given. :func:`subid.methods.dt.selection.cross_validate` scores
    the candidates on the folds of ``data``, with every estimator of
    ``plan.estimators`` when ``plan.estimator_choice == 'cv'`` (a list of candidate
    orders given), with the first otherwise. The model is fitted to the whole record
    (``fitter.prepare``, ``fitter.fit``) with the choice, its estimator chosen at the
    chosen order and horizon by :func:`subid.methods.dt.selection.estimator_by_fit`
    when ``plan.estimator_choice == 'fit'`` (as a call given that order and horizon
    chooses it), and :func:`unrepaired_choice` replaces the choice by a runner-up when
    only the final model had to be stabilised.

    Returns
    -------
    problem, model, estimator, estimator_rule
        ``model.info`` holds ``order_selection``; ``estimator_rule`` is
        ``info['system_matrices_selection']`` when there was a choice of estimator
        (None otherwise).
    """
    estimators = list(plan.estimators)
    scored = estimators if plan.estimator_choice == "cv" else estimators[:1]
    candidates = None if plan.candidates is None else list(plan.candidates)
    n, f, estimator, record = cross_validate(data, plan.order, candidates, plan.horizon,
                                             fitter=fitter, estimators=scored)
    shared = RecordWork()             # what the innovation check computed on the record
    if plan.order is None:
        n, f, estimator = innovation_check(data, record, fitter, (n, f, estimator),
                                           shared=shared)

    def final(order, horizon, name):
        """``(problem, estimator, model, rule)`` of the whole record at a candidate."""
        # (the record was checked by the caller, pipeline.run, before the folds)
        problem = fitter.prepare(data, order, horizon, factor=shared.factors.get(horizon),
                                 checked=True)
        shared.seed(problem)
        if plan.estimator_choice == "fit":
            return (problem,) + estimator_by_fit(data, problem, fitter, estimators,
                                                 held=shared.held)
        return problem, name, fitter.fit(problem, name), None

    n, f, estimator, problem, model, rule = unrepaired_choice(record, final, (n, f, estimator))
    model.info["order_selection"] = record
    warn_poor_fit(record)
    if plan.estimator_choice == "cv":
        rule = {"rule": "cv", "description": (
            "cross-validated with the order and horizon (info['order_selection'])")}
    return problem, model, estimator, rule


class RecordWork:
    """What :func:`innovation_check` computed on the whole record that the final model's
    steps would compute again (:func:`choose`): by horizon, the record's Hankel factor
    (:data:`RECORD_FACTOR`, which :func:`subid.methods.dt._subspace.prepare` takes) and
    the check's problem (whose factor in the user's units holds the noise model's
    oblique projections, :func:`subid.methods.dt.noise_model.user_factor`); and the
    record's :class:`subid.methods.dt._scoring.Held` with its lag products
    (:func:`subid.methods.dt.selection.estimator_by_fit` scores both estimators with them)."""

    def __init__(self):
        self.factors = {}
        self.problems = {}
        self.held = None

    def seed(self, problem):
        """Give ``problem`` (of the whole record) the check's factor in the user's units
        when the two problems hold the same factor and channel scales (then it is the
        factor the problem would make, bit for bit)."""
        from subid.methods.dt.noise_model import USER_FACTOR, user_factor
        other = self.problems.get(problem.horizon)
        if other is None or other.data is not problem.data:
            return
        if np.array_equal(other.factor.L, problem.factor.L) \
                and np.array_equal(other.input_scale, problem.input_scale) \
                and np.array_equal(other.output_scale, problem.output_scale):
            problem.cached(USER_FACTOR, lambda: user_factor(other))


#: Samples (the last ones) on which :func:`innovation_check` fits and compares its models:
#: up to ten fits of the whole record, some by a pass over it (a pole too slow for the lag
#: products), doubled the default call's CPU time at 1e5 samples; every record of
#: bench/selection.py and bench/realdata.py is shorter.
INNOVATION_CHECK_SAMPLES = 20_000


def innovation_bic(model, data, spread=None) -> float | None:
    """Schwarz's criterion of ``model``'s innovation form on ``data``:
    ``N ln det(E^T E / N) + (n (nu + 2 ny) + nu ny) ln N``, ``E`` its one-step
    prediction errors from a zero initial state (the conditional likelihood; the
    transient of the stable predictor weighs O(1) against the O(ln N) price of an
    order), the parameters those of A, B, C, D and K up to a similarity (Ljung 1999,
    Sec. 7.3 and 16.4, eq. 16.33); None when the model has no noise model (no stable
    predictor) or the errors are not finite. Each output's errors are divided by
    its standard deviation (which shifts the criterion of every order alike) and the
    eigenvalues of their covariance floored at ``(ABSOLUTE_TOLERANCE / 100)^2``, the
    rounding level below which the cross-validated criterion counts no misfit either.
    ``spread``: ``np.std(data.y, axis=0)`` when already computed (the same for every
    order of :func:`innovation_check`). ``E^T E`` is summed in one compiled pass
    (:func:`subid.methods.dt._innovation_kernel.prediction_power`: that of
    ``subid.prediction_errors(model, data, 1, x0='zero')`` to rounding, tested)."""
    from subid.methods.dt._innovation_kernel import prediction_power
    if model.K is None:
        return None
    pieces = [(data.u[a:b], data.y[a:b]) for a, b in data.experiment_ranges]
    power = prediction_power(model.A, model.B, model.C, model.D, model.K, pieces)
    if power is None:
        return None
    N, nu, ny = data.n_samples, data.n_inputs, data.n_outputs
    # each output's errors relative to its spread (a constant of ln det for every
    # order), the covariance's eigenvalues floored at the rounding level of the
    # cross-validated criterion (ABSOLUTE_TOLERANCE points of misfit): on noise-free
    # data every order from the true one up predicts to rounding, and the smallest wins
    if spread is None:
        spread = np.std(data.y, axis=0)
    scale = np.where(spread > 0, spread, 1.0)
    floor = (ABSOLUTE_TOLERANCE / 100.0) ** 2
    eig = np.maximum(np.linalg.eigvalsh(power / np.outer(scale, scale) / N), floor)
    return N * float(np.sum(np.log(eig))) + (model.order * (nu + 2 * ny) + nu * ny) * math.log(N)


def innovation_check(data, record, fitter, chosen, *, shared=None):
    """The cross-validated choice, or a higher order the innovation form demands.

    The cross-validated BIC sees a mode only through the held-out simulation fit,
    i.e. as far as the input excites it; a mode the input barely excites but the
    noise does (process noise entering through the plant) adds nothing measurable
    there and is missed (issue 21: on bench/selection.py's systems the orders
    missed add at most 0.06 points of fold fit, less than their parameters cost).
    The one-step prediction errors of the innovation form see both paths. So,
    when some higher order scores as well on the folds, the models of the chosen
    horizon and estimator are fitted to the record (its last
    :data:`INNOVATION_CHECK_SAMPLES` samples; B, D, x0 from its lag products
    where exact) at every order scored there, each with its Kalman gain,
    and the order of the least :func:`innovation_bic` (Schwarz's criterion:
    consistent, so it does not add orders as the record grows) is taken when it
    is higher than the choice and its best candidate's mean fold score is not
    lower. The folds veto an order the noise model wants but the simulation does
    not (on real records the noise often needs more states than the input path:
    on the DaISy CD_player_arm record, N4SID, the innovation BIC's order without
    the veto loses 5 points of validation fit); the order taken is always one a
    criterion chose on its own (the least innovation BIC among the admissible
    orders only, a compromise neither chose, lost 6.6 points on exchanger with
    MOESP's shift-invariance estimate, bench/selection_rules.md). Measured (bench/selection_rules.md, the
    rule marked "the default"; bench/selection.py): true order 31/40 and 56/80
    instead of 30/40 and 54/80 (BIC on the innovation models: 31/40, 57/80), the
    same median validation fit; on the DaISy records no default lower by more
    than 0.5 points of validation fit (bench/realdata.md).

    ``chosen`` is ``(order, horizon, estimator)``; so is the result, and
    ``shared`` (a :class:`RecordWork`), when given, receives what the check computed
    on the whole record (when it fitted the whole record: its Hankel factor at the
    chosen horizon, the same factor :func:`subid.methods.dt._subspace.prepare` would
    build again, its problem, and the record's lag products) for the final model;
    ``record['innovation_check']`` records the cross-validated choice
    (``cross_validated``), the criterion of every order fitted (``orders``), the order
    of the least of them (``order``), whether every order was fitted (``complete``) and
    the decision (``taken``, ``reason``); ``record['selected']`` follows it.

    The decision needs the criterion of every admissible order (higher than the
    choice, mean fold score not lower), but of the others only until one is below the
    least admissible criterion (ties to the lower order): then the least of all is not
    admissible whatever the orders not fitted would give, and the choice stands. So the
    admissible orders are fitted first, then the others from the cross-validated choice
    outwards (the choice itself is usually the one): the same decision as fitting every
    order, for 4 of 10 orders at 10^3 samples and 2 of 10 at 10^6 on the 2x2 order-4
    system of ``bench/run.py``.
    """
    from subid.methods.dt._lag_fit import LAG_PRODUCTS, LagProducts
    from subid.methods.dt._regression import scoring_only
    from subid.methods.dt._scoring import Held
    from subid.methods.dt.noise_model import attach_noise_model
    n, f, estimator = chosen
    used = data[data.n_samples - INNOVATION_CHECK_SAMPLES:] \
        if data.n_samples > INNOVATION_CHECK_SAMPLES else data
    by_key = {(c["order"], c["horizon"], c.get("system_matrices")): c
              for c in record["candidates"]}
    mine = float(np.mean(by_key[(n, f, estimator)]["folds"]))
    best_of = {}                      # the best candidate of every order (mean fold score)
    for c in record["candidates"]:
        if c["order"] not in best_of or \
                np.mean(c["folds"]) > np.mean(best_of[c["order"]]["folds"]):
            best_of[c["order"]] = c
    # the choice and the higher orders the folds do not reject, as far as the chosen
    # horizon reveals them
    at_f = sorted({c["order"] for c in record["candidates"] if c["horizon"] == f})
    admissible = [m for m in at_f if m > n and np.mean(best_of[m]["folds"]) >= mine]
    orders = at_f
    check = {"rule": "the order of the least innovation BIC (models of the chosen horizon "
                     "and estimator on the whole record, every order scored there) when it "
                     "is higher than the cross-validated choice and its best mean fold "
                     "score is not lower (the admissible orders fitted first, the others "
                     "until one has a lower criterion)", "orders": [],
             "cross_validated": dict({"order": n, "horizon": f},
                                     **({} if estimator is None
                                        else {"system_matrices": estimator}))}
    record["innovation_check"] = check
    if not admissible:
        check.update(order=None, taken=False,
                     reason="no higher order scores as well on the folds")
        return chosen
    values = {}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            problem = fitter.prepare(used, orders, f, checked=True)   # run() checked it
            mine_too = shared is not None and used is data and hasattr(problem, "stored")
            if mine_too:                  # the final model's, at f
                shared.factors[f] = problem.stored(RECORD_FACTOR)
                shared.problems[f] = problem
            # B, D, x0 of every order from the record's lag products, as on the folds
            # (equal to the pass over the record to about 1e-12 relative); those of the
            # record's Held, which scores the final model's estimators
            if mine_too and used.n_experiments == 1:
                shared.held = Held(used, lagged=True)
                lagged = shared.held.products()[0]
            else:
                lagged = LagProducts.of_record(used) if hasattr(problem, "_cache") else None
            if lagged is not None:
                problem.cached(LAG_PRODUCTS, lambda: lagged)
            spread = np.std(used.y, axis=0)
            # the admissible orders first, then the others from the choice outwards:
            # once one of these has a criterion (and order) below the least admissible
            # one, no admissible order can be the least of all: the rest is not fitted

            def criterion(order):
                fitted.append(order)
                with scoring_only():          # scored and dropped: the normal equations
                    model = fitter.fit(replace(problem, order=order, candidates=[order]),
                                       estimator)
                value = innovation_bic(attach_noise_model(model, problem, doubling=True),
                                       used, spread)
                if value is not None:
                    values[order] = value
                return value

            fitted, least = [], None      # least: the least admissible (criterion, order)
            for order in admissible:
                value = criterion(order)
                if value is not None and (least is None or (value, order) < least):
                    least = (value, order)
            others = sorted((m for m in orders if m not in admissible),
                            key=lambda m: (abs(m - n), m))
            for order in (others if least is not None else []):
                value = criterion(order)
                if value is not None and (value, order) < least:
                    break
    except SubidError as exc:
        check.update(order=None, taken=False, reason=f"{type(exc).__name__}: {exc}")
        return chosen
    check["orders"] = [{"order": m, "criterion": values[m]} for m in sorted(values)]
    check["complete"] = len(fitted) == len(orders)
    if not values:
        check.update(order=None, taken=False, reason="no order has a stable predictor")
        return chosen
    best = min(values, key=lambda k: (values[k], k))
    check["order"] = best
    if best not in admissible:
        check.update(taken=False, reason=(
            "no admissible order has a stable predictor" if least is None else
            "not higher than the cross-validated choice" if best <= n else
            "its mean fold score is lower than the cross-validated choice's"))
        return chosen
    other = best_of[best]
    check.update(taken=True, reason="higher, and its mean fold score is not lower")
    # should the final model of the new choice need a repair its folds did not
    # (unrepaired_choice), the cross-validated choice is the first fallback
    key = (other["order"], other["horizon"], other.get("system_matrices"))
    mine_entry = {k: by_key[(n, f, estimator)][k] for k in ("order", "horizon", "score",
                                                             "criterion")}
    if estimator is not None:
        mine_entry["system_matrices"] = estimator
    record["ranking"] = [mine_entry] + [
        e for e in record.get("ranking", [])
        if (e["order"], e["horizon"], e.get("system_matrices")) != key]
    record["selected"] = dict({k: other[k] for k in ("order", "horizon", "score", "criterion")
                               if k in other}, innovation_check=True,
                              **({"system_matrices": other["system_matrices"]}
                                 if other.get("system_matrices") is not None else {}))
    return other["order"], other["horizon"], other.get("system_matrices", estimator)


def unrepaired_choice(record, final, chosen):
    """The cross-validated choice, or a runner-up when only the choice had to be repaired.

    The cross-validation scores the models fitted to its folds. When the
    model of the chosen candidate refitted to the whole record comes out
    unstable and ``stability='auto'`` reflects its poles
    (:func:`subid.methods.dt._subspace.stable_choice`) while not all of its fold
    models needed that, the final model is not the kind of model that was scored
    (on the DaISy evaporator record, MOESP at order 10, horizon 20: two of four fold
    models stable, the final one with a slow unstable pole, 56 % validation
    fit once stabilised). The candidates are then tried in the order of their
    scores (at most :data:`MAX_FALLBACKS`), and the first
    whose final model needs no repair the folds did not need is taken; if
    none, the original choice stands. ``record['repaired_choice']`` tells.
    ``final(order, horizon, estimator) -> (problem, estimator, model, rule)`` makes
    the model of the whole record at a candidate (its estimator chosen there by
    :func:`subid.methods.dt.selection.estimator_by_fit` when the cross-validation
    scored only the first);
    ``chosen`` is ``(order, horizon, estimator)`` and the result ``(order, horizon,
    estimator, problem, model, rule)``.
    """
    n, f, variant = chosen
    by_key = {(c["order"], c["horizon"], c.get("system_matrices")): c
              for c in record["candidates"]}

    def needs_repair(key, m):
        c = by_key.get(key, {})
        return stabilised(m) and c.get("stabilised_folds", 0) < len(c.get("folds", ()))

    problem, name, model, rule = final(n, f, variant)
    if not needs_repair((n, f, variant), model):
        return n, f, name, problem, model, rule
    skipped = [{"order": n, "horizon": f, "system_matrices": name}]
    for entry in record.get("ranking", [])[:MAX_FALLBACKS]:
        key = (entry["order"], entry["horizon"], entry.get("system_matrices"))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                _, got, m, _ = final(*key)
        except SubidError:
            continue
        made = dict(entry, system_matrices=got) if got is not None else dict(entry)
        if not needs_repair(key, m):
            record["repaired_choice"] = {"skipped": skipped, "taken": made}
            record["selected"] = dict(entry, fallback=True)
            # the warnings of the model returned, as a direct call gives them
            problem, got, model, rule = final(*key)
            return key[0], key[1], got, problem, model, rule
        skipped.append(made)
    record["repaired_choice"] = {"skipped": skipped, "taken": None}
    return n, f, name, problem, model, rule


def warn_poor_fit(record, stacklevel: int = 4) -> None:
    """A :class:`subid.errors.PoorFitWarning` when the chosen candidate's mean fold score
    is negative (DaISy powerplant: ``pbsid(data)`` chose order 4 at -22 % on the folds
    and validated at -188 %, silently)."""
    score = (record.get("selected") or {}).get("score")
    if score is None or not np.isfinite(score) or score >= 0.0:
        return
    from subid.errors import PoorFitWarning
    chosen = record["selected"]
    warnings.warn(
        f"the chosen model (order {chosen.get('order')}, horizon {chosen.get('horizon')}) "
        f"simulates the held-out folds worse than their means (cross-validated fit "
        f"{score:.1f} %, info['order_selection']): no candidate describes these data; "
        "look for drifts or offsets (data.detrend('linear')), feedback (feedthrough=True, "
        "or arx/armax/pbsid, consistent in closed loop) or a nonlinearity before using it",
        PoorFitWarning, stacklevel=stacklevel)
