"""``subid.identify``: the best model the data support, in one call.

MATLAB's pattern (``n4sid`` then ``ssest``/``pem``; Ljung, *System
Identification*, 2nd ed., 1999, Sec. 10.6 and 16.4): a subspace model gives
the structure and a start, prediction-error minimisation refines it. Every
choice is made on the estimation record and recorded in
``model.info['identify']``:

0. **Frequency-response data** (:class:`subid.FRData`) go to
   :func:`subid.fd_subspace` (the order chosen on frequency folds, the model in
   the data's time base), refined by :func:`subid.pem`'s weighted least squares
   on the response (:func:`_frequency`).
1. **Time base.** A non-uniformly sampled record, or ``time_base='ct'``, goes
   to :func:`subid.ct_subspace` (continuous time, its own defaults); the rest
   of this page is the discrete-time path.
2. **Subspace estimator, order, horizon, feedthrough.** :func:`subid.moesp`
   (with its two estimators of the system matrices, ``system_matrices='auto'``)
   and :func:`subid.n4sid` (CVA weighting) each choose their order and
   horizon by cross-validation on the estimation record
   (:mod:`subid.methods.dt.selection`: four contiguous folds, simulation fit,
   the rule aware of the fold-to-fold spread, orders past 10 while the
   criterion improves) and their feedthrough from the data
   (``feedthrough='auto'``, :mod:`subid.methods.dt.feedthrough`). The
   estimator with the better mean fold score of its chosen candidate is taken
   (the two are scored on the same folds by the same fit). Where
   :func:`subid.estimate_delay` finds an input delay beyond the one sample of a
   strictly proper response (:func:`_dead_time`), both estimators are also run
   with those delays (``input_delay=``) and compete on the same footing: a dead
   time as long as the horizon is otherwise invisible to them.
3. **Refinement.** The chosen configuration (estimator, order, horizon,
   feedthrough) is fitted on the training part of every fold, refined there by
   :func:`subid.pem` with ``focus``, and both are scored on the held-out part:
   simulation fit for ``focus='simulation'`` (output error; K re-estimated
   afterwards), one-step prediction fit for ``focus='prediction'`` (the
   innovation form). The refinement of the whole record is kept only when the
   refined fold models score better than the subspace fold models by more
   than one standard error of the paired fold differences (on the DaISy
   evaporator record a mean gain of 0.6 points over fold gains of -7.8 to
   +8.2 would have been kept by the mean alone, and lost 26 points of
   validation fit) and by at least :data:`MIN_RELATIVE_GAIN` of their misfit
   (``info['identify']['refinement']`` holds both sets of fold scores, the
   decision and the cost history of the final refinement). Where the data
   show feedback (the test of ``feedthrough='auto'``), the output-error
   criterion is biased (the input is correlated with the noise), so the
   refinement minimises and is judged by one-step prediction errors, the
   criterion that stays consistent in closed loop (Ljung 1999, Sec. 13.4,
   the direct approach); with ``focus='simulation'`` that refinement is kept
   only when it also raises the simulation misfit on the folds by at most
   :data:`SIMULATION_LOSS` (10 %): the price of consistency the simulation
   criterion accepts (``info['identify']['refinement']['focus_reason']``). The
   fold refinements stop as soon as those done exceed that limit whatever the
   others give (a misfit is never negative): the same decision without the
   remaining refinements (on DaISy CD_player_arm, the command line's 70 %
   split, order 18: two of four, and the call takes 6 s instead of 83 s).
   An unstable subspace model (an unstable plant under feedback) cannot be
   refined by simulation; it is kept as it is.

4. **The gain.** Unless a prediction-focus refinement estimated K with the rest, the
   model's K (the state-sequence gain of :mod:`subid.methods.dt.noise_model`) is
   re-estimated by prediction error with A, B, C, D fixed
   (:func:`subid.methods.dt.gain.refine_gain`; ``info['identify']['gain']``): the
   simulation is unchanged, the one-step predictor is the best that deterministic part
   allows (``bench/gain_realdata.md``: on the DaISy records 0.07-0.95x the validation
   prediction error power on CD_player_arm, winding, dryer2, powerplant, robot_arm and
   steamgen, within 1 % on dryer, evaporator, exchanger, 4 % higher on ballbeam,
   glassfurnace mixed). ``refine=False`` keeps the subspace model as it is.
5. **The parameter covariance.** A refined model carries :func:`subid.pem`'s; a
   subspace model the covariance a prediction-error estimate would have at it
   (:func:`_subspace_covariance`: with ``focus='simulation'`` the output-error
   sandwich covariance, valid for coloured disturbances; with ``focus='prediction'``
   the innovation form with its K, as MATLAB attaches to ``n4sid`` models), so that
   the confidence bounds and the report's bands work on every discrete-time result
   (``info['identify']['covariance']``).

The choices cost the subspace cross-validations of two estimators plus four
fold refinements and one final refinement; the fold refinements use the same
part of a long record as the cross-validation (its last
:data:`subid.methods.crossval.MAX_SELECTION_SAMPLES` samples). Every
refinement is :func:`subid.pem` stopped at the statistical precision of its
criterion (:func:`subid.methods.dt.pem.refine`: the Gauss-Newton decrement
below 1e-3 of ``d / (2N)``, the expected excess of the criterion at the true
parameters; Ljung 1999, Theorem 9.1), which keeps the estimate's efficiency to
0.1 %; the fold models, which are only scored, skip the parameter covariance
and the re-estimated K, and stop at a quarter of ``d / (2N)`` (within half an
estimation standard deviation of the fold's minimum) or after 40 evaluations
per round (:func:`subid.methods.dt.pem.refine` argues both). Each iteration
costs a Jacobian (:mod:`subid.model._sensitivity`, whose blocked form builds
the forcing of all directions by matrix products over blocks of samples) and
its triangular factor (:mod:`subid.methods.dt._trust_region`). At 1e5 samples
(``bench/identify_cost.py``, 2x2 order-4 system, 20 dB) the refinement costs
1.3x the subspace model it starts from (0.43 against 0.34 CPU s; the whole call
0.10x SIPPY's own order search). On the DaISy records with large models, whose fold refinements
crawl to their evaluation bound, the refinement stage took 11.2 s of CPU on
steamgen (order 20, four inputs and outputs, 6,400 samples; 64.3 s before these
bounds and the blocked kernel), 2.8 s on evaporator (10.8 s) and 1.4 s on
CD_player_arm (7.1 s). The four folds of a large model are refined on subid's
threads (:data:`THREADED_JACOBIAN`, :func:`_fold_refinement`; the same fold
scores): on steamgen the stage takes 8.2 -> 5.5 s wall on 2 cores and the whole
call 13.8 -> 10.3 s (``bench/identify_refinement.md``).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from subid._blas import one_thread, serial_blas
from subid._threads import available, ordered_map
from subid._validation import check_choice, checked_call, name_caller
from subid.data import IOData, not_a_record
from subid.errors import DataError, FeedbackWarning, ModelError, OptionError, SubidError
from subid.methods._info import collect_warnings
from subid.methods.crossval import FLOOR, fold_score
from subid.model.statespace import StateSpace

__all__ = ["identify"]

FOCUS = ("simulation", "prediction")
TIME_BASES = ("auto", "dt", "ct")
#: The discrete-time estimators compared, by name, with their fixed options.
ESTIMATORS = ("moesp", "n4sid")
#: Under feedback with ``focus='simulation'``: the (consistent) prediction-error refinement
#: is kept only when it raises the mean simulation misfit on the folds by at most this
#: fraction (measured: 3 % on the closed-loop seed-001 runs of issue 21, 32 % on the DaISy
#: CD_player_arm record, whose simulation fit it lowered from 75.5 % to 67.5 %).
SIMULATION_LOSS = 0.10
#: The refinement is kept only when its mean fold gain is also at least this fraction of
#: the subspace fold models' misfit (100 - fit %): a gain the fit's reported precision
#: cannot show buys nothing for the cost of refining the whole record (10^7 samples: a
#: fold gain of 0.00014 points, significant against its standard error of 0.00005, kept a
#: refinement that took 25 of the call's 34 s and changed no fit in its second decimal).
MIN_RELATIVE_GAIN = 1e-3
#: The fold models are made and refined on subid's threads when a fold's Jacobian (rows
#: times parameters, K's included) has at least this many entries: below it the steps
#: that hold the GIL dominate and two threads are no faster than one, or slower. The
#: fold stage on 2 cores, one thread against two (DaISy records, 2/3 to estimate):
#: robot_arm (1.1e5 entries) 0.24 -> 0.31 s, glassfurnace (4.8e5) 0.32 -> 0.31 s,
#: CD_player_arm (8.7e5, under feedback) 0.56 -> 0.77 s; evaporator (2.2e6) 1.44 ->
#: 1.25 s, steamgen (1.1e7) 8.5 -> 5.8 s; the whole ``identify`` of the 2x2 order-4
#: system of bench/run.py at 1e5 and 1e6 samples (4.6e6 and 6.6e6 entries, the folds'
#: scores on the threads too) 0.70 -> 0.63 s and 0.84 -> 0.77 s.
THREADED_JACOBIAN = 1_000_000


def _estimator(name):
    if name == "moesp":
        from subid.methods.dt.moesp import moesp
        return moesp
    from subid.methods.dt.n4sid import n4sid
    return n4sid


def _configuration(model) -> dict:
    """The options that make ``method(data, **options)`` rebuild ``model`` (pinned)."""
    out = {"order": model.order, "horizon": model.info["horizon"],
           "feedthrough": bool(model.info.get("feedthrough", {}).get("estimated",
                                                                     np.any(model.D != 0)))}
    if model.info.get("system_matrices") is not None:
        out["system_matrices"] = model.info["system_matrices"]
    if model.info.get("input_delay") is not None:
        out["input_delay"] = [int(d) for d in model.info["input_delay"]]
    return out


#: The delayed candidates are tried only when an input's delay beyond one sample is at
#: least this: a shorter one costs the subspace model a few states, which its order
#: search finds, while the delayed candidates double the search's cost. On the DaISy
#: records (2/3 to estimate) delays of 1-3 samples were found on dryer, evaporator,
#: glassfurnace and steamgen: tried, they changed one fit by 0.1 point (evaporator) and
#: made identify 1.6-2.6x dearer there.
DEAD_TIME_MIN = 5


def _dead_time(data):
    """``(delays, record)``: the input delays :func:`subid.estimate_delay` (ARX losses over
    the candidate delays, MATLAB's ``delayest``) finds beyond the one sample of a strictly
    proper response, or None where no input has one; ``record`` says what was looked for.

    Tried only where one is at least :data:`DEAD_TIME_MIN` and its ARX loss at most
    :data:`subid.delay.DELAY_LOSS_SHARE` of the undelayed one's (without that check a
    30-state structure ran every candidate twice for a spurious delay: 12.7 -> 28 s at
    4,200 samples). A dead time as long as the
    subspace horizon leaves the default models nothing to see: SISO plants behind 20-40
    samples of dead time (1000 samples) were fitted by ``identify`` without it at
    2.9-37 %, with it at 87-90.5 % (session 24's exploratory test). The delays found are
    a candidate that :func:`_discrete` cross-validates against none, not a decision."""
    from subid.delay import DELAY_LOSS_SHARE, wide_delay_search
    search = wide_delay_search(data)
    record = {"rule": "subid.estimate_delay (na = nb = 2) on the last "
                      f"{search['samples']} samples, delays 0..{search['searched']}: each "
                      f"input's delay beyond one sample where its ARX loss is at most "
                      f"{DELAY_LOSS_SHARE:g} of the undelayed one's, cross-validated against "
                      f"none when one is at least {DEAD_TIME_MIN}",
              "searched": search["searched"]}
    if "nk" not in search:
        return None, dict(record, found=None, reason=search["reason"])
    nk, share = search["nk"], search["loss_share"]
    extra = np.where(share <= DELAY_LOSS_SHARE, np.maximum(nk - 1, 0), 0)
    record.update(found=[int(d) for d in np.maximum(nk - 1, 0)],
                  loss_share=[float(x) for x in share],
                  kept=[int(d) for d in extra])
    record["tried"] = bool(extra.max() >= DEAD_TIME_MIN)
    return ([int(d) for d in extra] if record["tried"] else None), record


def _selected_folds(model):
    """The fold scores the cross-validation gave the model's own candidate, or None."""
    record = model.info.get("order_selection")
    if not isinstance(record, dict) or record.get("rule") != "cv":
        return None
    chosen = record.get("selected", {})
    if chosen.get("system_matrices") not in (None, model.info.get("system_matrices")):
        return None          # the estimator chosen after the cross-validation (by fit)
    for c in record.get("candidates", []):
        if (c["order"], c["horizon"], c.get("system_matrices")) == \
                (chosen.get("order"), chosen.get("horizon"), chosen.get("system_matrices")):
            return list(c["folds"])
    return None


def _fold_parts(data):
    from subid.methods.crossval import experiment_folds, folds, selection_part
    used = selection_part(data)
    if used.n_experiments > 1:
        return experiment_folds(used)
    return [(used[a], used[b]) for a, b in folds(used.n_samples)]


def _score(model, validation, focus) -> float:
    """:func:`subid.methods.crossval.fold_score` by simulation or one-step prediction."""
    return fold_score(model, validation, steps=np.inf if focus == "simulation" else 1)


def _refine(data, model, focus, held_out=False, why=None):
    """``pem(data, model, focus=focus)`` stopped at the statistical precision of its
    criterion (:func:`subid.methods.dt.pem.refine`; ``held_out``: a fold model, only
    scored), or None when the start cannot be refined so (``why``, a list, then receives
    the error's message)."""
    from subid.methods.dt.pem import refine
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return refine(data, model, focus, held_out=held_out)
    except (ModelError, DataError) as exc:
        if why is not None:
            why.append(f"{type(exc).__name__}: {exc}")
        return None


def _warn_biased(what: str) -> None:
    """The :class:`subid.errors.FeedbackWarning` of a ``focus='simulation'`` call under
    feedback that keeps the subspace model (biased in closed loop) because the
    consistent prediction-error refinement ``what`` (how it lost as a simulator)."""
    warnings.warn("identify: the data show feedback from the outputs to the inputs, and the "
                  "model returned is the subspace estimate, biased in closed loop: the "
                  "prediction-error refinement, consistent there, " + what + ", so "
                  "focus='simulation' kept the subspace model as the better simulator of "
                  "these data; for the plant itself (control design) use "
                  "focus='prediction' (info['identify']['refinement'])", FeedbackWarning,
                  stacklevel=3)


def _feedback(data, model) -> bool:
    """Whether the data show feedback from the outputs to the inputs: the test of
    ``feedthrough='auto'`` (:func:`subid.methods.dt.feedthrough.decide`), from the
    model's own record when it ran, else on the record's statistic at its horizon."""
    ran = model.info.get("feedthrough", {})
    if ran.get("requested") == "auto":           # the test ran (None: a noise-free record)
        return bool(isinstance(ran.get("feedback"), dict) and ran["feedback"]["detected"])
    from subid.methods.dt.feedthrough import feedback_test
    return bool(feedback_test(data, 2 * int(model.info["horizon"]), last=False)["detected"])


def _fold_scores(data, method, config):
    """Simulation fit of the pinned configuration on the held-out part of every fold."""
    fn = _estimator(method)
    options = dict(config)
    order = options.pop("order")
    out = []
    for train, validation in _fold_parts(data):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out.append(_score(fn(train, order, **options), validation, "simulation"))
        except SubidError:
            out.append(FLOOR)
    return out


def _fold_refinement(data, method, config, focus, scores=None, guard=None):
    """Fold scores of the pinned subspace configuration and of its refinement by
    ``pem(focus=focus)``: ``(subspace, refined)``, each ``{score focus: scores}`` for
    each focus of ``scores`` (default: ``focus`` alone).

    The folds are independent: where a fold's Jacobian is large
    (:data:`THREADED_JACOBIAN`; a refinement holds at most
    :data:`subid.methods.dt._pe_search.JACOBIAN_PIECE_BYTES` of it at a time) and BLAS
    runs one thread (:func:`subid._blas.one_thread`, the default), their subspace
    models, then their refinements, are
    made and scored on subid's threads (:func:`subid._threads.ordered_map`; the
    Jacobians' compiled kernels, matrix products and QR factorisations release the
    GIL), the same models as one after the other (on DaISy steamgen, order 20: the same
    fold scores, the fold stage 8.5 -> 5.5 s wall on 2 cores). Their warnings are not
    shown (the fold models are only scored).

    ``guard`` (a focus of ``scores``, under feedback): the refinements stop as soon as
    those done raise the summed misfit ``100 - score`` by that focus above
    ``1 + SIMULATION_LOSS`` times the subspace models' over all folds: a fold's misfit is
    never negative, so the mean misfit of the refined models exceeds the limit whatever
    the remaining folds give, and :func:`_discrete` would drop the refinement (the same
    decision, the fold refinements left undone; ``refined`` then holds the folds done,
    in fold order: the folds refined together with the one that crossed the limit, in
    one round of as many folds as threads, are dropped)."""
    fn = _estimator(method)
    options = dict(config)
    order = options.pop("order")
    scores = (focus,) if scores is None else tuple(scores)
    parts = _fold_parts(data)

    def scored(model, validation):
        return {s: _score(model, validation, s) for s in scores}

    def start(part):
        """The fold's subspace model and its scores (None, FLOOR when it fails)."""
        try:
            model = fn(part[0], order, **options)
        except SubidError:
            return None, {s: FLOOR for s in scores}
        return model, scored(model, part[1])

    def refined_scores(k):
        """The scores of the fold's refined model (its subspace model's when the
        refinement fails)."""
        better = None if starts[k] is None else _refine(parts[k][0], starts[k], focus,
                                                        held_out=True)
        return base_of[k] if better is None else scored(better, parts[k][1])

    nu, ny = data.n_inputs, data.n_outputs
    jacobian = max(train.n_samples for train, _ in parts) * ny * \
        (order * (order + nu + 2 * ny) + ny * nu)
    threads = available() if THREADED_JACOBIAN <= jacobian and one_thread() else 1

    def quietly(function, items):
        # the fold models are only scored: their warnings dropped
        return ordered_map(function, items, threads=threads, quiet=True)

    starts, base_of = zip(*quietly(start, parts))
    base = {s: [b[s] for b in base_of] for s in scores}
    refined = {s: [] for s in scores}
    limit = None if guard is None else \
        (1.0 + SIMULATION_LOSS) * float(np.sum(100.0 - np.asarray(base[guard])))
    # in rounds of as many folds as threads where the guard may stop the refinements
    # early; all at once otherwise
    step = len(parts) if limit is None else threads
    for first in range(0, len(parts), step):
        folds = range(first, min(first + step, len(parts)))
        for values in quietly(refined_scores, folds):
            for s in scores:
                refined[s].append(values[s])
            if limit is not None and \
                    float(np.sum(100.0 - np.asarray(refined[guard]))) > limit:
                return base, refined
    return base, refined


@serial_blas
@checked_call
def identify(data, order=None, *, focus="simulation", time_base="auto", horizon=None,
             feedthrough="auto", refine=True, hold=None) -> StateSpace:
    """Identify the best model the data support: subspace start, order, refinement.

    Parameters
    ----------
    data : IOData or FRData
        The estimation record (uniformly sampled for discrete time; a record of
        several experiments, :func:`subid.merge`, is handled experiment by
        experiment). Remove the means (or trends) first, as for every method.
        A frequency response (:class:`subid.FRData`) is identified by
        :func:`subid.fd_subspace` and :func:`subid.pem` (:func:`_frequency`).
    order : int, None, 'auto' or iterable of int
        Model order; ``None`` (default) lets the cross-validation choose it
        (orders past 10 while the criterion improves); an iterable gives the
        candidates.
    focus : {'simulation', 'prediction'}
        What the model is for, and what the refinement minimises and is
        judged by: ``'simulation'`` (default) the simulation error (output
        error; K re-estimated afterwards by prediction error with A, B, C, D
        fixed, :mod:`subid.methods.dt.gain`), ``'prediction'`` the one-step
        prediction error of the innovation form.
    time_base : {'auto', 'dt', 'ct'}
        ``'auto'``: discrete time for uniformly sampled data, continuous time
        (:func:`subid.ct_subspace`) for non-uniform time stamps; ``'ct'``:
        continuous time always; ``'dt'``: discrete time (non-uniform data are
        then an error).
    horizon : int, optional
        The subspace horizon (default: chosen with the order). Discrete time
        only: the continuous-time path has none (an ``OptionError``).
    feedthrough : {'auto', True, False}
        Direct term D (discrete time): ``'auto'`` estimates it only when the
        data show one and no feedback (:mod:`subid.methods.dt.feedthrough`).
        Continuous time: passed to :func:`subid.ct_subspace` when a bool.
    refine : bool
        Try the prediction-error refinement (kept only when it validates
        better on the folds); ``False``: the subspace model. Continuous time:
        ``ct_subspace``'s ``refine='auto'`` (its output-error refinement, kept
        where it scores better on the folds) or ``refine=False``.
    hold : {None, 'foh', 'zoh'}
        Continuous time only: how the input moves between samples
        (:func:`subid.ct_subspace`'s ``hold``; None: its default, ``'foh'``).
        A discrete-time model needs none (an ``OptionError`` when given there).

    Returns
    -------
    StateSpace
        With ``K`` and ``noise_cov``; ``info['method']`` is ``'identify'``,
        ``info['identify']`` records every decision: ``time_base``,
        ``estimators`` (each estimator's chosen order, horizon, feedthrough,
        system matrices and fold scores), ``estimator`` (the one taken),
        ``refinement`` (``focus``, fold scores of the subspace and refined
        fold models, ``kept``, and for the final refinement ``cost_history``,
        ``start_cost``, ``final_cost``, ``n_evaluations``), ``gain`` (the
        gain step: ``samples``, ``start_cost``, ``final_cost``,
        ``n_evaluations``, ``stop_reason``), ``covariance`` (for a model not
        refined: how its ``info['parameter_covariance']`` was computed, or why
        not). Discrete-time results carry ``info['parameter_covariance']``
        (:func:`subid.parameter_covariance`, :func:`subid.freqresp_bounds`).

    Raises
    ------
    DataError
        Neither an IOData record nor an FRData; non-uniform data with ``time_base='dt'``.
    OptionError
        Bad option values.

    Examples
    --------
    >>> import subid
    >>> true = subid.systems.seed001_system()
    >>> data = subid.systems.simulate_data(true, 600, seed=1, output_snr_db=30)
    >>> model = subid.identify(data)
    >>> model.order, model.info["identify"]["estimator"] in ("moesp", "n4sid")
    (3, True)
    """
    check_choice(focus, "focus", FOCUS)
    check_choice(time_base, "time_base", TIME_BASES)
    if not isinstance(refine, (bool, np.bool_)):
        raise OptionError(f"refine must be True or False; got {refine!r}"[:300])
    from subid.frdata import FRData
    if isinstance(data, FRData):
        return _frequency(data, order, focus=focus, time_base=time_base, horizon=horizon,
                          feedthrough=feedthrough, refine=bool(refine), hold=hold)
    if not isinstance(data, IOData):
        raise not_a_record(data, "identify", time="t=... or dt=...")
    if hold is not None:
        check_choice(hold, "hold", ("foh", "zoh"))
    if time_base == "ct" or (time_base == "auto" and not data.is_uniform):
        reason = "time_base='ct' requested" if time_base == "ct" else "non-uniform time stamps"
        # the options the continuous-time path cannot honour are errors, not ignored
        if horizon is not None:
            raise OptionError(f"horizon={horizon!r}: the continuous-time path ({reason}) has "
                              "no subspace horizon (ct_subspace's basis filters take its "
                              "place); leave horizon out, or call subid.ct_subspace(data, "
                              "basis=...) for another basis")
        if focus != "simulation":
            raise OptionError(f"focus={focus!r}: the continuous-time path ({reason}) refines "
                              "the simulation (output) error only; leave focus out, or "
                              "resample uniformly for time_base='dt'")
        return _continuous(data, order, feedthrough, bool(refine), hold, reason=reason)
    if hold is not None:
        raise OptionError(f"hold={hold!r} applies to the continuous-time path (time_base='ct' "
                          "or non-uniform time stamps); a discrete-time model, exact at the "
                          "samples, needs none: leave hold out")
    from subid.methods.dt.checks import check_data
    from subid.methods.dt.feedthrough import check_feedthrough
    feedthrough = check_feedthrough(feedthrough)
    check_data(data, "identify")
    with collect_warnings() as issued:
        model, record = _discrete(data, order, horizon, feedthrough, focus, bool(refine))
        from subid.methods.dt.choice import warn_poor_fit
        from subid.methods.dt.feedthrough import dropped_direct_term
        if (message := dropped_direct_term(model.info.get("feedthrough"))) is not None:
            warnings.warn("identify: " + message, FeedbackWarning, stacklevel=2)
        if isinstance(model.info.get("order_selection"), dict):
            warn_poor_fit(model.info["order_selection"], stacklevel=2)
        if refine and "gain_refinement" not in model.info and model.info.get("focus") != \
                "prediction":
            # K of the subspace model re-estimated by prediction error (subid.pem's
            # simulation focus does it on the model it refines)
            from subid.methods.dt.gain import refine_gain
            model = refine_gain(data, model)
        if "gain_refinement" in model.info:
            record["gain"] = {"rule": "K by prediction-error minimisation with A, B, C, D "
                                      "fixed (subid.methods.dt.gain)",
                              **model.info["gain_refinement"]}
        if not isinstance(model.info.get("parameter_covariance"), dict):
            model = _subspace_covariance(data, model, record)
    info = dict(model.info)
    info["subspace_method"] = info.get("method")
    info["method"] = "identify"
    info["identify"] = record
    info["warnings"] = list(dict.fromkeys(list(info.get("warnings", [])) + list(issued)))
    return model.with_noise_model(model.K, model.noise_cov, info=info)


#: The samples the parameter covariance of a model :func:`identify` did not refine reads
#: at most (:func:`subid.methods.dt.pem.with_covariance`'s windows, its sum scaled to the
#: record): the time and memory of its Jacobian bounded at any length. On the seed-001
#: innovation system at 40,000 samples, 20,000 of them gave the standard deviations of
#: the whole record's to 0.6-1 %, 2,000 to 3 %.
COVARIANCE_SAMPLES = 20_000


def _subspace_covariance(data, model, record):
    """``model`` (a subspace model, the refinement not kept or not asked for) with the
    parameter covariance a prediction-error estimate would have at it
    (:func:`subid.methods.dt.pem.with_covariance`), so that the confidence bounds
    (:func:`subid.freqresp_bounds`, ``subid.plot.bode(..., confidence=0.95)``, the
    report's bands) work on the default result. With ``identify``'s ``focus='simulation'``
    (the default) that of the output-error estimate, the sandwich ``R^-1 Q R^-1`` valid
    for coloured disturbances (:mod:`subid.methods.dt._sandwich`): the innovation form's
    (with its K, what MATLAB attaches to an ``n4sid`` model) is that of an estimator
    with a noise model, more efficient than the subspace estimate where the
    disturbance is coloured, and its bands held the true ``|G|`` in 66 % of the pairs
    on a second-order plant with process noise (5 dB, plus 20 dB output noise, 100
    runs; the sandwich 96.8 %, bench/sandwich_coverage.md); with ``focus='prediction'``
    the innovation form's. Measured coverage of the 95 % bounds of ``|G|``
    (tests/test_uncertainty.py): 93.3 % on a SISO output-error system with white noise
    (100 runs) and 94.2 % on the 2x2 seed-001 innovation system (40 runs; 89.6 % with
    the innovation form's covariance), against 95 % for ``pem`` models there. Where the data show feedback
    (:func:`_feedback`) no
    covariance is attached: MOESP and N4SID are biased in closed loop, and bands around
    the biased model cover nothing (the closed-loop seed-001 system of issue 21, 30 runs
    of ``identify(data, 3, refine=False)``: 21 % of the 95 % bounds held the true |G|;
    ``identify``'s default, which keeps its prediction-error refinement there, 96 %).
    ``record['covariance']`` says what was done; a model whose covariance cannot be
    computed (feedback, an unstable predictor, a rank-deficient Jacobian) is returned
    without it, with the reason."""
    feedback = record["feedback"] if "feedback" in record else _feedback(data, model)
    if feedback:
        record["covariance"] = {
            "at": "the subspace model", "computed": False,
            "reason": "the data show feedback: the subspace estimate is biased in closed "
                      "loop and bounds around it would not hold the plant; refine it "
                      "with subid.pem(data, model) (consistent in closed loop) for bounds"}
        return model
    focus = "prediction" if model.K is not None and record.get("focus") == "prediction" \
        else "simulation"
    copy = model.with_noise_model(model.K, model.noise_cov, info=dict(model.info))
    try:
        out = _record_covariance(data, copy, focus, start=model)
    except SubidError as exc:
        out, why = model, f"{type(exc).__name__}: {exc}"
    else:
        why = out.info.get("parameter_covariance_note", "the model has no initial state of "
                           "every experiment or no K")
    entry = out.info.get("parameter_covariance")
    record["covariance"] = (
        {"at": "the subspace model", "focus": focus,
         "samples_used": entry["samples_used"],
         "rule": ("the asymptotic covariance an output-error estimate would have at the "
                  "model (the sandwich, valid for coloured disturbances)"
                  if focus == "simulation" else
                  "the asymptotic covariance a prediction-error estimate would have at the "
                  "model (MATLAB's for n4sid models); the subspace estimate may be less "
                  "efficient")} if isinstance(entry, dict) else
        {"at": "the subspace model", "computed": False, "reason": why})
    return out


def _delayed(data, model):
    """``data`` with its inputs shifted by ``model``'s input delays (as :func:`subid.pem`
    refines such a model), or as it is."""
    from subid.delay import delay_inputs, input_delay_of
    delays = input_delay_of(model)
    return data if delays is None else delay_inputs(data, delays)[0]


def _record_covariance(data, model, focus, *, start):
    """``model`` (its ``info`` the caller's own copy) with the parameter covariance of
    :func:`subid.methods.dt.pem.with_covariance` over the record (at most
    :data:`COVARIANCE_SAMPLES` of it read), D among the parameters where ``start`` has
    one, as :func:`subid.pem` does. Raises SubidError as that does."""
    from subid.methods.dt.pem import with_covariance
    with np.errstate(all="ignore"):
        return with_covariance(model, _delayed(data, model), focus,
                               with_feedthrough=bool(np.any(start.D != 0)),
                               max_samples=COVARIANCE_SAMPLES)


def _frequency(data, order, *, focus, time_base, horizon, feedthrough, refine, hold):
    """:func:`identify` on a frequency response: :func:`subid.fd_subspace` (McKelvey,
    Akçay & Ljung 1996; the order chosen on interleaved frequency folds), then
    :func:`subid.pem` (weighted nonlinear least squares on the response, the weights the
    inverse noise level, given or estimated: the maximum-likelihood criterion; Pintelon &
    Schoukens 2012, Ch. 9), which never ends above its start, so its result is kept.

    The subspace step alone is a poor model where the noise weighting and the
    structure disagree: on a lightly damped 2x2 continuous-time structure (four modes,
    damping 0.002-0.02, 400 frequencies over two decades, 1 % noise proportional to
    |G|, seeds 0-9) ``fd_subspace(data)`` fitted the true response at 23.5 / 85.4 /
    96.2 % (least / median / most) and this at 99.28 / 99.56 / 99.76 %, for a median
    2.5 CPU s (``tests/test_identify_frequency.py``)."""
    from subid.methods.dt.feedthrough import check_feedthrough
    from subid.methods.dt.pem import pem
    from subid.methods.fd.fd_subspace import fd_subspace
    feedthrough = check_feedthrough(feedthrough)
    continuous = data.dt == 0
    kind = "continuous" if continuous else "discrete"
    if time_base == ("dt" if continuous else "ct"):
        raise OptionError(f"time_base={time_base!r}: the frequency response is {kind}-time "
                          f"(dt = {data.dt:g}) and the model takes the data's time base; "
                          "leave time_base out, or build the FRData with the dt wanted")
    if focus != "simulation":
        raise OptionError(f"focus={focus!r}: a frequency response holds the input-output "
                          "part only, no noise model to predict with; leave focus out")
    if hold is not None:
        raise OptionError(f"hold={hold!r}: a frequency response needs no input hold; "
                          "leave hold out")
    options = {} if horizon is None else {"horizon": horizon}
    if feedthrough != "auto":
        options["feedthrough"] = bool(feedthrough)
    model = fd_subspace(data, order, **options)
    record = {"time_base": kind, "data": "frequency response", "estimator": "fd_subspace",
              "options": dict(options),
              "feedthrough": ("D estimated (fd_subspace's default: the response at the "
                              "highest frequencies shows a direct term)"
                              if feedthrough == "auto" else f"given: {feedthrough}")}
    if refine:
        model = pem(data, model)
        info = model.info
        record["refinement"] = {
            "kept": True, "criterion": "weighted least squares on the response",
            "weighting": info.get("weighting"), "start_cost": info.get("start_cost"),
            "final_cost": info.get("final_cost"), "cost_history": info.get("cost_history"),
            "n_evaluations": info.get("n_evaluations"),
            "rule": "pem on the response never ends above its start: its result is kept"}
    else:
        record["refinement"] = {"kept": False, "reason": "refine=False"}
    info = dict(model.info)
    info["subspace_method"] = "fd_subspace"
    info["method"] = "identify"
    info["identify"] = record
    return StateSpace(model.A, model.B, model.C, model.D, model.dt,
                      input_names=model.input_names, output_names=model.output_names,
                      info=info, hold=model.hold)


def _continuous(data, order, feedthrough, refine, hold, *, reason):
    from subid.methods.ct.ct_subspace import ct_subspace
    options = {} if feedthrough == "auto" else {"feedthrough": bool(feedthrough)}
    if not refine:
        options["refine"] = False
    if hold is not None:
        options["hold"] = hold
    model = ct_subspace(data, order, **options)
    info = dict(model.info)
    info["subspace_method"] = info.get("method")
    info["method"] = "identify"
    info["identify"] = {"time_base": "continuous", "reason": reason,
                        "estimator": "ct_subspace", "options": dict(options),
                        "description": "continuous-time path: subid.ct_subspace with its "
                                       "own defaults, and the options given (refine=False, "
                                       "hold, feedthrough)"}
    return StateSpace(model.A, model.B, model.C, model.D, model.dt, K=model.K,
                      noise_cov=model.noise_cov, input_names=model.input_names,
                      output_names=model.output_names, info=info, hold=model.hold)


def _discrete(data, order, horizon, feedthrough, focus, refine):
    record = {"time_base": "discrete", "focus": focus, "estimators": []}
    fits = {}
    errors = {}
    delays, record["dead_time"] = _dead_time(data)
    # every estimator without input delays, and with the dead time found (a candidate)
    candidates = [(name, None) for name in ESTIMATORS] + \
        ([(name, delays) for name in ESTIMATORS] if delays is not None else [])
    for name, delay in candidates:
        label = name if delay is None else f"{name}, input_delay={delay}"
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fits[label] = _estimator(name)(data, order, horizon=horizon,
                                               feedthrough=feedthrough,
                                               **({} if delay is None else
                                                  {"input_delay": delay}))
        except SubidError as exc:
            errors[label] = f"{type(exc).__name__}: {exc}"
    if not fits:
        # every estimator failed: raise the first estimator's error again, with its
        # warnings, naming identify (the function the user called)
        try:
            _estimator(ESTIMATORS[0])(data, order, horizon=horizon, feedthrough=feedthrough)
        except SubidError as exc:
            raise name_caller(exc, ESTIMATORS[0], "identify") from None
    scores = {}
    for label, model in fits.items():
        name = label.split(",")[0]
        config = _configuration(model)
        folds = _selected_folds(model)
        if folds is None:                      # order and horizon given: score them here
            folds = _fold_scores(data, name, config) if len(fits) > 1 else []
        scores[label] = float(np.mean(folds)) if folds else math.nan
        record["estimators"].append({"estimator": name, **config, "folds": folds,
                                     "score": scores[label]})
    for label, message in errors.items():
        record["estimators"].append({"estimator": label.split(",")[0], "error": message})
    # the better mean fold score; on ties (or no scores) the first estimator, undelayed
    order_of = list(fits)
    label = max(fits, key=lambda k: (scores[k] if math.isfinite(scores[k]) else -math.inf,
                                     -order_of.index(k)))
    chosen = label.split(",")[0]
    record["estimator"] = chosen
    record["rule"] = ("the estimator (and input delays) whose chosen candidate has the "
                      "better mean simulation fit over the four cross-validation folds")
    model = fits[label]
    config = _configuration(model)
    refinement = {"focus": focus, "tried": refine}
    record["refinement"] = refinement
    if not refine:
        refinement["kept"] = False
        refinement["reason"] = "refine=False"
        return model, record
    record["feedback"] = _feedback(data, model)
    guard = None
    if record["feedback"] and focus == "simulation":
        # under feedback the output-error criterion is biased (the input is correlated
        # with the noise); the prediction-error criterion of the innovation form stays
        # consistent (Ljung 1999, Sec. 13.4, the direct approach)
        focus, guard = "prediction", "simulation"
        refinement.update(focus=focus, requested_focus="simulation",
                          focus_reason="feedback detected in the data: the simulation "
                                       "(output-error) criterion is biased in closed loop; "
                                       "refined and judged by one-step prediction, kept "
                                       "unless it raises the simulation misfit on the folds "
                                       f"by more than {100 * SIMULATION_LOSS:g} %")
    if focus == "simulation" and not model.is_stable():
        refinement.update(kept=False, reason="the subspace model is unstable (the data demand "
                                             "it): no simulation error to minimise")
        return model, record
    bases, refineds = _fold_refinement(data, chosen, config, focus,
                                       scores=(focus,) if guard is None else (focus, guard),
                                       guard=guard)
    base, refined = bases[focus], refineds[focus]
    refinement.update(subspace_folds=base, refined_folds=refined,
                      score=("simulation fit (%)" if focus == "simulation"
                             else "one-step prediction fit (%)") + " on the held-out folds")
    if len(refined) < len(base):
        before = 100.0 - float(np.mean(bases[guard]))
        _warn_biased(f"raised the simulation misfit over the folds above "
                     f"{1 + SIMULATION_LOSS:g} x the subspace models' ({before:.3g} %) "
                     f"after {len(refined)} of {len(base)} fold refinements, whatever the "
                     "others give")
        refinement.update(
            subspace_simulation_folds=bases[guard], refined_simulation_folds=refineds[guard],
            kept=False, reason=(f"after {len(refined)} of {len(base)} fold refinements the simulation "
                    f"misfit on the folds is above {1 + SIMULATION_LOSS:g} x the subspace "
                    f"models' ({before:.3g}) whatever the other folds give: the subspace "
                    "model is kept as the simulator asked for (the remaining fold "
                    "refinements were not run)"))
        return model, record
    diff = np.subtract(refined, base)
    gain = float(np.mean(diff))
    error = float(np.std(diff, ddof=1)) / math.sqrt(diff.size) if diff.size > 1 else 0.0
    refinement.update(mean_gain=gain, standard_error=error)
    if not gain > error:
        refinement.update(kept=False, reason="the refined fold models do not validate better "
                                             "by more than one standard error of the paired "
                                             "fold differences")
        return model, record
    misfit = 100.0 - float(np.mean(base))
    if gain < MIN_RELATIVE_GAIN * misfit:
        refinement.update(kept=False, reason=(
            f"the refined fold models validate better by {gain:.2g} points, less than "
            f"{MIN_RELATIVE_GAIN:g} of the subspace models' misfit ({misfit:.3g} %): no "
            "gain worth refining the whole record"))
        return model, record
    if guard is not None:
        base_s, refined_s = bases[guard], refineds[guard]
        refinement.update(subspace_simulation_folds=base_s, refined_simulation_folds=refined_s)
        before, after = 100.0 - float(np.mean(base_s)), 100.0 - float(np.mean(refined_s))
        if after > (1.0 + SIMULATION_LOSS) * before:
            _warn_biased(f"raised the simulation misfit on the folds from {before:.3g} to "
                         f"{after:.3g} %")
            refinement.update(kept=False, reason=(
                f"the refinement raises the simulation misfit on the folds from "
                f"{before:.3g} to {after:.3g} (more than {100 * SIMULATION_LOSS:g} %): "
                "the subspace model is kept as the simulator asked for"))
            return model, record
    why = []
    final = _refine(data, model, focus, why=why)
    if final is None:
        refinement.update(kept=False, reason="the refinement of the whole record failed ("
                          + (why[0] if why else "no result") + ")")
        return model, record
    refinement.update(kept=True, cost_history=[float(c) for c in final.info["cost_history"]],
                      start_cost=final.info["start_cost"], final_cost=final.info["final_cost"],
                      n_evaluations=final.info["n_evaluations"],
                      stop_reason=final.info["stop_reason"])
    return final, record
