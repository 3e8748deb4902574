"""Order and horizon chosen from the estimation data by cross-validation.

Real records rarely show a gap in their singular values: they decay
smoothly, and the largest-gap rule then often picks order 1. The default
rule here scores every candidate (order, horizon) by what a user looks at,
the simulation fit on data the model was not fitted to, using the
estimation record only:

* four contiguous folds: fit on the first 2/3 and validate on the last
  1/3, fit on the last 2/3 and validate on the first 1/3, and the same with
  halves (contiguous blocks keep the Hankel columns and the simulated
  trajectories intact; four folds instead of two halved the number of
  DaISy records where the choice missed the best order, e.g. N4SID on
  robot_arm, at twice the cost); a record of several experiments
  (:func:`subid.merge`) has every experiment cut so, and the pieces of all
  experiments merged: no fold joins two experiments;
* on each validation block, the model is simulated from an initial state
  fitted by least squares, and the fit (NRMSE %, per output, which does not
  depend on the output units) is averaged over the outputs; a simulation
  that overflows scores :data:`FLOOR`;
* the score of a candidate is the mean over the folds, each fit first
  clipped below at :data:`FLOOR` so that one diverging fold cannot hide
  the other;
* the selected candidate is the one of the least cross-validated BIC
  (:func:`criterion`: ``2 N ny ln(100 - score) + p ln N``, Schwarz's
  criterion with the error variance measured on the held-out folds,
  ``p = n (nu + ny) + nu ny`` parameters, the misfit floored at 1e-6 points
  so that noise-free data, where every order from the true one up fits to
  rounding, give the true order). A higher order must buy its parameters:
  each costs ``ln N / (2 N ny)`` of the misfit, so on flat scores the
  statistical price of the parameters decides, not a fixed tolerance (the
  former rule, the smallest order within 1 % of the best misfit, is the
  same test with a price that does not depend on N or on how many
  parameters the higher order adds). Measured (issue 21; 40 random 2x2
  systems of orders 2..6, 20 dB process and output noise, N = 2000,
  MOESP's default candidates): true order 30/40 (BIC on the fitted
  innovation models: 31; the former rule 29; a one-standard-error rule on
  the paired fold differences 14, because overfitted orders win by tiny
  but consistent margins), median validation fit 84.3 % for all of them.
  On the nine DaISy records of bench/realdata.py (MOESP) the chosen orders
  are those of the former rule but for steamgen (10 against 9, 75.9 %
  against 75.8 % validation fit) and winding (2 against 5, 74.9 % against
  75.7 %);
* **the innovation check** (:func:`subid.methods.dt.choice.innovation_check`): the
  cross-validated BIC sees a mode only through the held-out simulation fit; a mode the input
  barely excites adds less there than its parameters cost (on those
  systems: at most 0.06 points, against a price of 0.05-0.12). When a
  higher order scores as well on the folds, the models of the chosen
  horizon and estimator are fitted to the record at every order with
  their Kalman gains (by doubling, see below), and the order of the least
  :func:`subid.methods.dt.choice.innovation_bic`
  (one-step prediction errors, which see the noise path too) is taken when
  it is higher and its mean fold score is not lower (1.0-1.2x the default
  call's CPU time without it at 1e3-1e5 samples, ``bench/selection_rules.py
  cost``; at most the last :data:`INNOVATION_CHECK_SAMPLES` samples). Over
  80 seeds of the same Monte Carlo: true order 56/80 (the cross-validated
  BIC alone 54, BIC on the fitted innovation models 57; 58 since ``predict``
  weighs the outputs in its initial state), 31/40 on the first 40 (30 and 31). Twenty-two other rules applied to the same fold scores
  (bench/selection_rules.md: the
  penalty scaled by 0.5-2, AIC, Hannan-Quinn, the penalty less the one the
  held-out misfit already carries, the median or pooled variance of the
  folds, per-fold BIC, one-standard-error rules, steps up by one or two
  standard errors of the paired fold differences, the innovation BIC alone
  or without the fold-score veto) find the true order less often or lose
  validation fit on a DaISy record (the larger of the two orders without
  the veto: 5.0 points on CD_player_arm with N4SID, whose noise needs more
  states than its simulation does);
* **orders past 10**: when no order is given, the candidates are 1..10
  first; while the order of the least criterion is one of the last two searched, the
  next block is scored (11..20, then 22..40 in steps of 2, 44..80 in steps
  of 4, ...; :func:`next_block`), with the horizons that can reveal those
  orders (10, 20 and the next multiple of 10 above ``n / n_outputs + 1``)
  as far as the training folds support them (twice as many Hankel columns
  as rows). The ceiling is what the data can reveal: the largest order a
  feasible horizon reveals, and at least :data:`~subid.methods.crossval.SAMPLES_PER_PARAMETER`
  output samples per free parameter ``n (nu + ny) + nu ny``
  (``info['order_selection']['order_ceiling']``). Each block costs as much
  as the first (ten orders x horizons x folds x estimators, with larger
  orders); ``info['order_selection']['searched']`` lists the blocks scored;
* **horizons past 20**: a horizon of 10 or 20 samples spans a small part of the
  dynamics of an oversampled record (poles near 1), whose subspace is then poorly
  revealed at every order. When no horizon is given, the orders searched are scored
  again at twice the largest horizon while the response to the inputs lasts beyond it
  (:func:`subid.methods.crossval.response_memory` at least
  :data:`~subid.methods.crossval.MEMORY`) and the last horizon so added is the chosen
  one, up to :data:`~subid.methods.crossval.MAX_HORIZON` and as far as the training
  folds support it (:func:`subid.methods.crossval.longer_horizon`). Measured (a 2x2
  order-4 system with time constants of 0.5-5 s, inputs held for 50 samples, 5 % output
  noise, N = 14,000 to estimate; ``bench/horizons.md``): sampled at 0.02 s, MOESP, N4SID
  and ``ls_subspace`` 91.6, 59.3 and 89.2 % validation fit before, 95.3 % each after
  (horizon 80); at 0.005 s 61.8, 52.2 and 62.7 before, 95.4, 94.2 and 95.4 after
  (horizon 160, 6-15 CPU s: slow poles leave the lag-product shortcuts). Every DaISy
  record keeps its model; steamgen tries horizon 40 without choosing it (1.2 -> 2.6 CPU
  s a call).

Horizons that cannot reveal every candidate order compete at the orders
they can reveal (horizon 10 on a single output: orders 1..9). Where a
method offers two estimators of the system matrices from the same subspace
(``system_matrices='auto'`` of MOESP and ``ls_subspace``: shift invariance
with the output regression, or the state sequence), the candidates are
scored with the first, and the estimator is chosen at the chosen order and
horizon by :func:`estimator_by_fit` (both fitted to the whole record, the
better simulation fit, an unstabilised model first): the rule a call given
that order and horizon applies without fold fits. Measured against
cross-validating both estimators with the orders (issue 21; bench/realdata.py,
the nine DaISy records, validation fit): CD_player_arm +5.3 (ls_subspace)
and +3.1 (MOESP), exchanger +0.9, dryer -0.6, steamgen -0.7 (ls_subspace)
and -0.5 (MOESP), evaporator -0.3, the others unchanged; half the
candidates. A list of candidate orders given (``order=[4]``) scores both
estimators as candidates instead. Also measured: the same rule without the
preference for an unstabilised model loses 7-8.5 points on evaporator, and
cross-validating with ``'states'`` then preferring an unstabilised model
loses 10 on CD_player_arm (its good ``'states'`` model is stabilised). When
the chosen candidate's model refitted to the whole record has to be
stabilised although not all of its fold models had, the next candidates are
tried (:func:`subid.methods.dt.choice.unrepaired_choice`): among the candidates whose mean score is within the fold-to-fold standard
deviation of the choice's, first those none of whose fold models needed it,
then the others, each by criterion.

The final model is then fitted to the whole record with the chosen order
and horizon, by the same code path as an explicit call, so that
``method(data, order=model.order, horizon=model.info['horizon'])``
reproduces it exactly.

**Cost.** Shared by the candidates: one statistic per fold and horizon (merged
from the lagged products of four blocks where exact, :func:`fold_factors`: the
straddling products of each merge for every lag at once,
:func:`subid.statistic.hankel.straddle`, and the Gram matrix of the lagged products
by one compiled pass, :func:`subid.statistic._lag_kernel.open_gram_kernel`), one
factorisation and SVD per fold for every order, the feedthrough decision per
fold (every channel's F-tests from one QR factorisation of the Hankel rows in nested
order, :func:`subid.methods.dt.feedthrough._nested_powers`), the
validation records' weights and spreads once for every horizon, and, on records
of at least :data:`subid.methods.dt._lag_fit.MIN_SAMPLES` samples, the lag
products of every training and validation record (``Γ(e) = sum u u^T``, ``R(k) =
sum y u^T`` up to 16,384 lags, the first 4,096 at once and the others when a
candidate's poles need them; one FFT per block of :func:`_blocks_of_folds` and one
cross-correlation per boundary between blocks, :func:`subid.methods.dt._lag_fit.merged`). Per
candidate: its A and C, its B, D, x0 regression on its training fold and its
simulation score on its validation block. For a stable, diagonalisable A whose
poles decay below rounding within the lags kept, both come from the lag products
(:mod:`subid.methods.dt._lag_fit`: the normal equations and the error power are
block-Toeplitz sums of the lag products, evaluated at the poles, with exact terms
for the first and last L samples): ``O(L n)`` flops per lag sequence, no pass over
the record, the same B, D, x0 and scores as the passes to about 1e-12 relative
(``tests/test_lag_fit.py``). Otherwise (an unstable A, a pole too slow for the
lags, a nearly exact fit whose residual the normal equations would leave to
rounding, records of several experiments or shorter ones) one pass over the
training fold (the modal normal equations) and one compiled simulation of the
validation block (:mod:`subid.methods.dt._scoring`); an unstable A that
``stability='auto'`` would not keep is not fitted
(:mod:`subid.methods.dt._residual_bound`: a lower bound of its residual from part of
the rows, the cheapest first by how fast A grows). Measured (``bench/run.py
--selection-only``, 2x2 order-4 system, 20 dB, CPU time, two runs;
bench/results.md; the pinned call fits no fold): the default call costs 14-17x the
pinned call at 10^3 samples and 13-14x at 10^4 (1.05-1.11x and 0.16-0.18x SIPPY's AIC
order search), 11-13x at 10^5 (34-46x before the lag products) and 4.5-5.1x at
10^6 (the folds use at most :data:`~subid.methods.crossval.MAX_SELECTION_SAMPLES`): the per-candidate work no longer
grows with N, but 80 candidate models (orders x horizons x folds), each about a
millisecond of subspace steps, regression, score and bookkeeping (Python calls on
matrices of order 10), remain (what one candidate's steps ask several times is
computed once: the spectral radius of its A, :func:`subid.methods._stability.spectral_radius`;
the noise model's oblique projections of the factor for every order the innovation
check fits, :mod:`subid.methods.dt.noise_model`; the record's factor and its
feedthrough F-tests, built by the innovation check and taken by the final model
(:data:`RECORD_FACTOR`, :func:`subid.methods.dt.feedthrough.decided`); and the modal
regression's maps are filled by blocks,
:func:`subid.methods.dt._regression.regressor_maps`: together 10-11 % of the default
call at 10^3 samples and 8-11 % at 10^4, ``bench/selection_paired.py``, the same
choices and models bit for bit on every bundled record,
``bench/selection_identity.py``). A fold candidate is only scored, so no model object
is made for it (:meth:`subid.methods.dt.pipeline.Pipeline.fold_score`: the steps of
:meth:`~subid.methods.dt.pipeline.Pipeline.fit` without ``finish``, its ``info``, its
stability warning and the :class:`subid.StateSpace`); a stable A of shift invariance,
which no stability rule touches, takes its B, D, x0 and its score on one modal form
without the rule's closures and diagnostics
(:func:`subid.methods.dt._subspace.lag_fold_score`,
:func:`subid.methods.dt._lag_fit.fit_and_error`: the same kernels, the same values),
its normal equations' condition number bounded from their Cholesky factor, the
eigenvalues computed only past the limit (the same decision and solution,
:func:`subid.methods.dt._regression.solve_normal_equations`); the growth of a fold's
record, which every unstable candidate's stability rule asks, is computed once
(:func:`subid.methods._stability.record_growth`). Measured (issue 21, branch
s10-foldbatch, ``bench/selection_paired.py``, 21 paired rounds against the tree
before): 0.87x the default call's CPU time at 10^3 samples, 0.91x at 10^4 and 10^5
(bench/results.md); the same choices and models on every bundled record, the same
fold scores (``ls_subspace``'s to 1e-9 points: scored in the basis of shift invariance,
not the model's; ``bench/selection_identity.py``). What a default call at 10^4 samples still spends
(instrumented, share of the call): the 75 stable fold candidates about 26 % (each the
eigenvalues and modal form of A, the compiled normal matrix and error power, the
Cholesky solve and about 40 small numpy calls), the 5 unstable ones about 14 % (their
residual bounds, :mod:`subid.methods.dt._residual_bound`, each a recursion over the
fold), the folds' feedthrough F-tests about 12 %, their statistics about 13 %, the
innovation check about 22 %, the final model and its estimator choice the rest
(before the work outside the candidates described below).
Stopping the order search once the criterion has not
improved for k orders (measured on the candidates' saved scores,
``bench/selection_identity.py``) would change the choice on DaISy records (k = 3:
CD_player_arm, powerplant and winding with N4SID; k = 4: CD_player_arm and winding,
e.g. N4SID on winding order 10 -> 5) while scoring only 15 % (k = 3) or 9 % (k = 4)
fewer candidates: the criterion of real records has late minima, so the search is not
cut.

Outside the candidates (issue 21, ``bench/selection_paired.py``: 0.69x, 0.73x, 0.87x
and 0.91x the CPU time of the default call before at 10^3, 10^4, 10^5 and 10^6 samples,
the same choices, models and fold scores on every bundled record,
``bench/selection_identity.py``): the innovation check fits the admissible orders
first and the others only until one has a lower criterion (2-7 of 10 orders on the
2x2 order-4 system of ``bench/run.py``: :func:`subid.methods.dt.choice.innovation_check`),
with its Kalman gains by a compiled doubling loop and its prediction errors' products summed by a compiled
pass (:mod:`subid.methods.dt._innovation_kernel`); the oblique projections of the noise
model are kept on their factor (:meth:`subid.statistic._hankel.HankelFactor.derived`),
and the check's factor in the user's units, its lag products and the record's
:class:`subid.methods.dt._scoring.Held` go to the final model
(:class:`subid.methods.dt.choice.RecordWork`); the folds' blocks are recognised by their memory
(:func:`subid.methods.dt.fold_statistics._same_samples`).

Then (issue 21, ``bench/selection_paired.py``, 21 paired rounds: 0.85-0.88x,
0.86-0.89x, 0.76-0.80x and 0.81-0.86x the CPU time of the default call before at 10^3,
10^4, 10^5 and 10^6 samples; the same choices and models bit for bit on every bundled
record, ``bench/selection_identity.py``): the residual bounds of the unstable fold candidates
stop as soon as they prove (:func:`subid.methods.dt._residual_bound.loses`; at 10^5
samples they had cost a third of the default call); the blocks' lagged products are
computed once per search block at the deepest horizon's depth (:func:`fold_factors`;
the compiled lag sums four samples per pass, :mod:`subid.statistic._lag_kernel`);
a fold's merged lag products reach past the shortest block through its own
(:func:`subid.methods.dt._lag_fit.merged`); a fold record is checked once for both
horizons; a scored candidate's normal equations are solved in one compiled call
(:func:`subid.methods.dt._lag_kernel.scored_solve`), and small LAPACK calls (the
noise model's least squares, a candidate's eigenvectors) go without numpy's and
scipy's wrappers (:mod:`subid.methods.dt._lapack`, the same bits). What a default call
at 10^4 samples still spends (about 130 ms against 11 ms pinned; instrumented, share of
the call): the 75 stable fold candidates about 35 % (each about 0.5 ms: the eigenvalues
and modal form of its A, the compiled normal matrix and error power, its A and C, some
40 small numpy calls), the 5 unstable ones about 12 %, the innovation check about 20 %,
the folds' statistics, lag products, factorisations, SVDs and feedthrough tests about
25 %, the final model's two estimators (what the pinned call spends) about 5 %.

**Models that are only scored** (the fold models and the innovation check's): their
B, D, x0 normal equations (modal or lag products) are solved up to an equilibrated
condition of 1e8 instead of 1e4 (:func:`subid.methods.dt._regression.scoring_only`;
the parameters then differ from the QR path's by at most ``cond * eps``), and the
innovation check's Kalman gains come from the doubling algorithm
(:func:`subid.methods.dt.noise_model.riccati_by_doubling`, the QZ solution to about
1e-13), and a fold whose merged lagged products are not exact to rounding takes the
QR statistic of its record factorised by compact-WY Householder blocks
(:func:`subid.statistic.hankel.compact_wy_qr`, 2.5x faster, R equal to rounding). The
model returned is fitted with none of these. On the DaISy steamgen record (4
inputs, 4 outputs, orders 11..20 searched) 85 of 182 fold and check fits had
conditions 1.1e4-5.5e6 and went to the per-sample QR factorisation of the regression,
about 70 % of the default call: MOESP 10.3 -> 2.7 s, ``ls_subspace`` 13.0 -> 3.4 s
(``bench/selection_identity.py``: the same order, horizon and estimator on every
bundled record for MOESP, ``ls_subspace`` and N4SID, models equal to 8e-11 relative,
fold scores to 2.4e-3 points on ballbeam's candidates with stabilised fold models and
3e-5 elsewhere).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np

from subid._threads import ordered_map
from subid.errors import OrderError, SubidError
from subid.methods.crossval import (
    ABSOLUTE_TOLERANCE,
    FLOOR,
    MAX_ORDER,
    experiment_folds,
    feasible_horizons,
    fold_score,
    folds,
    longer_horizon,
    next_block,
    select,
    selection_part,
)
from subid.methods.dt.fold_statistics import (
    FOLD_BLOCKS,
    VALIDATION_BLOCKS,
    _blocks_of_folds,
    fold_factors,
    fold_threads,
)

#: The search goes on to the next block of orders when the best-scoring order is one of
#: the last EXTEND_LAST candidate orders searched.
EXTEND_LAST = 2
#: The key of a problem's cache that holds the Hankel factor of its record as
#: :func:`subid.methods.dt._subspace.prepare` built it (before the channels are
#: normalised): the final model's problem takes the innovation check's.
RECORD_FACTOR = "record factor"


def default_gap_horizon(n_samples, n_inputs, n_outputs, blocks, largest_order, n_experiments=1):
    """Horizon of the gap rule when none is given: the smallest feasible candidate."""
    return feasible_horizons(n_samples, n_inputs, n_outputs, blocks, largest_order,
                             n_experiments=n_experiments)[0]


def _fit_score(model, validation) -> float:
    """Mean over the outputs of the simulation fit (%) of ``model`` on ``validation``
    (a record, or its :class:`subid.methods.dt._scoring.Held`; x0 by least
    squares), clipped below at :data:`FLOOR`; :data:`FLOOR` when the simulation
    overflows. ``mean(fit_percent(model, validation))`` to rounding, by one
    compiled pass (:func:`subid.methods.dt._scoring.simulation_fit`)."""
    if model.is_continuous:           # continuous time (ct_subspace): simulated with its hold
        return fold_score(model, getattr(validation, "record", validation))
    return score_matrices(model.A, model.B, model.C, model.D, validation)


def score_matrices(A, B, C, D, validation) -> float:
    """:func:`_fit_score` of the discrete-time model ``(A, B, C, D)`` (the fold
    candidates of :meth:`subid.methods.dt.pipeline.Pipeline.fold_score`)."""
    from subid.methods.dt._scoring import simulation_fit
    return mean_score(simulation_fit(A, B, C, D, validation))


def mean_score(fits) -> float:
    """The score of a candidate from its fits per output (%, None when its simulation
    overflowed): their mean, clipped below at :data:`FLOOR`."""
    if fits is None:
        return FLOOR
    value = float(np.mean(fits))
    return max(value, FLOOR) if math.isfinite(value) else FLOOR


def score_horizon(parts, orders, horizon, *, fitter, estimators, held=None, lagged=None,
                  deepest=None):
    """Fold scores of every candidate order at one horizon.

    Per fold, one problem (one statistic, by cost: the lagged products merged from
    those of the four blocks of the record where they are exact, :func:`fold_factors`;
    :meth:`subid.HankelStatistic.from_data` otherwise) whose order-independent
    steps (the factorisation, the SVD) every candidate order shares
    (:meth:`subid.methods.dt._subspace.Problem.cached`); the fold
    models are made by the steps of the final model
    (:class:`subid.methods.dt.pipeline.Pipeline`) but skip the estimation x0
    (``Problem.fold``), and each is scored by one
    compiled simulation with the x0 regression on the validation block
    (:mod:`subid.methods.dt._scoring`), whose record-dependent parts are computed
    once per fold. The scores equal those of the straightforward computation (a
    fresh problem per order, ``fit_percent``) to rounding
    (``tests/test_selection_speed.py``). The folds are scored on subid's threads
    where their factors are large (:func:`fold_threads`; the same scores).

    Parameters
    ----------
    parts : list of (IOData, IOData)
        The ``(train, validation)`` records of the folds.
    orders : list of int
        Candidate orders (all revealable at ``horizon``).
    horizon : int
    fitter : :class:`subid.methods.dt.pipeline.Pipeline` or alike
        ``fitter.prepare_fold(record, candidates, horizon, factor=None) -> Problem``
        and ``fitter.fit(problem with a fixed order, estimator) -> StateSpace``, or,
        where it has it, ``fitter.fold_score(problem with a fixed order, estimator,
        held) -> (score, stabilised)`` (the same score without the model object,
        :meth:`subid.methods.dt.pipeline.Pipeline.fold_score`). With
        the attributes ``blocks_per_horizon`` and ``statistic`` (the option) not None,
        the folds' factors are merged from the blocks' statistics and passed as
        ``factor`` (:func:`fold_factors`); otherwise each fold builds its own.
    estimators : sequence
        The names of the estimators ``fitter.fit`` takes (``[None]`` for one).
    held : list of :class:`subid.methods.dt._scoring.Held`, optional
        What the scores need from each validation record (computed here when not
        given; :func:`cross_validate` computes it once for every horizon).
    lagged : list of :class:`subid.methods.dt._lag_fit.LagProducts` or None, optional
        The lag products of each training record (filled in here where missing and
        the fold's problem can take them; :func:`cross_validate` passes one list for
        every horizon): the B, D, x0 fit of every candidate from them
        (:mod:`subid.methods.dt._lag_fit`).
    deepest : dict, optional
        The blocks' statistics at the largest depth of the horizons scored
        (:func:`fold_factors`; :func:`cross_validate` passes one for every horizon).

    Returns
    -------
    per_fold : dict ``(order, estimator index) -> list of float``
        The simulation fit (%) of each fold (:func:`_fit_score`), in fold order.
    repaired : dict ``(order, estimator index) -> int``
        How many of the fold models had to be stabilised (:func:`stabilised`).
    """
    from subid.methods.dt._lag_fit import LAG_PRODUCTS, LagProducts
    from subid.methods.dt._regression import scoring_only
    from subid.methods.dt._scoring import Held
    names = list(estimators)
    per_fold = {(n, v): [] for n in orders for v in range(len(names))}
    repaired = {(n, v): 0 for n in orders for v in range(len(names))}
    factors = fold_factors(parts, horizon, fitter, deepest)
    if held is None:                      # what every candidate's score needs, once
        held = [Held(validation, lagged=True) for _, validation in parts]
    lagged = [None] * len(parts) if lagged is None else lagged
    scorer = getattr(fitter, "fold_score", None)

    def fold(k):
        """``(score, repaired)`` of every candidate on fold k."""
        (train, _), factor, held_out, out = parts[k], factors[k], held[k], {}
        problem = fitter.prepare_fold(train, orders, horizon, factor=factor) \
            if factor is not None else fitter.prepare_fold(train, orders, horizon)
        if hasattr(problem, "cached") and train.n_experiments == 1:
            if lagged[k] is None:         # once per fold, for every horizon
                lagged[k] = LagProducts.of_record(train)
            # B, D, x0 of every candidate
            problem.cached(LAG_PRODUCTS, lambda products=lagged[k]: products)
        # the candidates are only scored: without the model objects where the fitter
        # can (Pipeline.fold_score), else from the models (their warnings dropped below)
        with scoring_only():
            for n in orders:
                at_n = problem.fold_at(n) if hasattr(problem, "fold_at") else \
                    replace(problem, order=n, candidates=[n], fold=True)
                for v, name in enumerate(names):
                    repair = 0
                    try:
                        if scorer is not None:
                            value, repair = scorer(at_n, name, held_out)
                        else:
                            model = fitter.fit(at_n, name)
                            value, repair = _fit_score(model, held_out), stabilised(model)
                    except SubidError:
                        value = FLOOR
                    out[(n, v)] = (value, repair)
        return out

    # the folds on subid's threads where their factors are large; warnings dropped
    depth = (getattr(fitter, "blocks_per_horizon", None) or 2) * horizon
    for out in ordered_map(fold, range(len(parts)), quiet=True,
                           threads=fold_threads(depth, parts)):
        for key, (value, repair) in out.items():
            per_fold[key].append(value)
            repaired[key] += repair
    return per_fold, repaired


def cross_validate(data, fixed, candidates, horizon, *, fitter, estimators):
    """Choose ``(order, horizon)`` by contiguous cross-validation (:func:`folds`).

    Parameters
    ----------
    data : IOData
        The estimation record, already validated (:func:`subid.methods.dt._subspace.check_data`).
    fixed : int or None
        The order when given (only the horizon is chosen).
    candidates : list of int or None
        Candidate orders (``None``: 1..MAX_ORDER as the horizon allows).
    horizon : int or None
        The horizon when given (only the order is chosen).
    fitter : :class:`subid.methods.dt.pipeline.Pipeline` or alike
        What makes a fold's problem and model (:func:`score_horizon`).
    estimators : sequence
        The estimators to choose among (one, named None, when there is no
        choice); on ties the first is preferred.

    Returns
    -------
    order, horizon, variant, record : int, int, str or None, dict
        ``record`` is ``info['order_selection']``; ``given``: what the caller fixed.
    """
    used = selection_part(data)       # validated by the caller (subid.methods.dt.pipeline.run)
    if used.n_experiments > 1:        # folds per experiment (none across a border)
        parts = experiment_folds(used)
        n_train = min(train.n_samples for train, _ in parts)
        n_exp_train = max(train.n_experiments for train, _ in parts)
    else:
        parts = [(used[train], used[validation]) for train, validation in folds(used.n_samples)]
        n_train = min(train.n_samples for train, _ in parts)
        n_exp_train = 1
    extendable = fixed is None and candidates is None
    if fixed is not None:
        wanted = [fixed]
    elif candidates is not None:
        wanted = list(candidates)
    else:
        wanted = list(range(1, MAX_ORDER + 1))
    blocks = fitter.blocks_per_horizon
    n_in, n_out = data.n_inputs, data.n_outputs
    horizons = [horizon] if horizon is not None else feasible_horizons(
        n_train, n_in, n_out, blocks, max(wanted),
        n_experiments=n_exp_train, reveal_all=fixed is not None)
    from subid.methods.dt._scoring import Held
    names = list(estimators)
    held = [Held(validation, lagged=True) for _, validation in parts]   # once for every horizon
    lagged = [None] * len(parts)      # the training records' lag products, when first needed
    # all of them from one FFT per block (and boundary), for the discrete-time methods
    # (whose fold problems take them, subid.methods.dt._subspace.b_d_fit)
    pieces = _blocks_of_folds(parts) if getattr(fitter, "statistic", None) is not None \
        else None
    if pieces is not None:
        from subid.methods.dt._lag_fit import merged
        records = [train for train, _ in parts] + [validation for _, validation in parts]
        products = merged(pieces, records, FOLD_BLOCKS + VALIDATION_BLOCKS)
        if products is not None:
            lagged = products[:len(parts)]
            for h, lp in zip(held, products[len(parts):]):
                h.seed([lp])
    scores, fold_scores, stabilised_folds = {}, {}, {}
    searched = []              # (orders, horizons) of every block of candidates scored
    ceiling = None

    def score(orders, f, deepest=None):
        per_fold, repaired = score_horizon(parts, orders, f, fitter=fitter,
                                           estimators=estimators, held=held,
                                           lagged=lagged, deepest=deepest)
        for (n, v), values in per_fold.items():
            fold_scores[(n, f, v)] = values
            scores[(n, f, v)] = float(np.mean(values))
            stabilised_folds[(n, f, v)] = repaired[(n, v)]
    while True:
        # the blocks' statistics once, at the depth of the largest horizon of this block
        deepest = {"depth": blocks * max(horizons)} if horizons else None
        for f in horizons:
            orders = [n for n in wanted if n <= (f - 1) * n_out]
            if orders:
                score(orders, f, deepest)
        searched.append({"orders": list(wanted), "horizons": list(horizons)})
        if not extendable or not scores:
            break
        top = max(n for n, _, _ in scores)
        step = max(1, top // (2 * MAX_ORDER)) if top > MAX_ORDER else 1
        best = select(fold_scores, used.n_samples, n_in, n_out)[0][0]
        if best <= top - EXTEND_LAST * step:
            break                                   # the criterion stopped improving
        wanted, horizons, ceiling = next_block(top, n_train, n_in, n_out, blocks, n_exp_train,
                                               horizon)
        if not wanted:
            break
    # longer horizons while the largest wins and the outputs remember beyond it
    while horizon is None and scores:
        f = longer_horizon(used, select(fold_scores, used.n_samples, n_in, n_out)[0][1],
                           max(f for _, f, _ in scores), n_train, n_in, n_out, blocks,
                           n_exp_train)
        if f is None:
            break
        orders = sorted({n for n, _, _ in scores if n <= (f - 1) * n_out})
        score(orders, f)
        searched.append({"orders": orders, "horizons": [f]})
    if not scores:
        need = math.ceil(max(wanted) / data.n_outputs) + 1
        raise OrderError(f"order {min(wanted)}{'..' + str(max(wanted)) if len(wanted) > 1 else ''}"
                         f" cannot be revealed with the horizons these data allow "
                         f"({', '.join(map(str, horizons))}) and {data.n_outputs} output"
                         f"{'s' if data.n_outputs != 1 else ''}; give horizon >= {need} "
                         "(with enough samples) or a lower order")
    (order, chosen_h, chosen_v), crit = select(fold_scores, used.n_samples, n_in, n_out)

    def entry(n, f, v):
        out = {"order": n, "horizon": f, "score": scores[(n, f, v)],
               "criterion": crit[(n, f, v)]}
        if names[v] is not None:
            out["system_matrices"] = names[v]
        return out

    record = {
        "rule": "cv",
        "description": ("four-fold contiguous cross-validation on the estimation data: "
                        "simulation fit (%, mean over outputs, x0 by least squares) on the "
                        "held-out part of each fold, mean over the folds; the candidate of the "
                        "least cross-validated BIC, 2 N ny ln(100 - fit) + p ln N"
                        + ("" if len(names) == 1 else
                           f" (then the first of the estimators {', '.join(names)})")),
        "selection_rule": "cross-validated BIC",
        "searched": searched,
        "candidates": [dict(entry(n, f, v), folds=fold_scores[(n, f, v)],
                            stabilised_folds=stabilised_folds[(n, f, v)])
                       for (n, f, v) in sorted(scores)],
        "selected": entry(order, chosen_h, chosen_v),
        "samples_used": used.n_samples,
    }
    if ceiling is not None:
        record["order_ceiling"] = ceiling
    if fixed is not None or horizon is not None:      # what the folds did not choose
        record["given"] = ["order"] * (fixed is not None) + ["horizon"] * (horizon is not None)
    # the other candidates, the fallbacks of unrepaired_choice:
    # among those whose mean fold score is within the fold-to-fold spread (standard
    # deviation) of the choice's, first those none of whose fold models had to be
    # stabilised (the kind of model the final one must be); then the rest; each by
    # least criterion
    chosen = (order, chosen_h, chosen_v)
    spread = float(np.std(fold_scores[chosen], ddof=1)) if len(fold_scores[chosen]) > 1 else 0.0
    ranked = sorted((key for key in scores if key != chosen),
                    key=lambda key: (scores[key] < scores[chosen] - spread,
                                     stabilised_folds[key] > 0, crit[key], key))
    record["ranking"] = [entry(*key) for key in ranked]
    return order, chosen_h, names[chosen_v], record


def stabilised(model) -> bool:
    """Whether ``model``'s A was made stable after its estimation (``stability='auto'``
    found it unstable on data that do not grow and reflected its unstable poles)."""
    return enforced(model.info.get("stability"))


def enforced(stab) -> bool:
    """Whether the stability record ``stab`` (a model's ``info['stability']``) says
    that ``stability='auto'`` made its A stable (:func:`stabilised`)."""
    return isinstance(stab, dict) and stab.get("action") == "enforced" \
        and stab.get("requested") == "auto"



def estimator_by_fit(data, problem, fitter, estimators, *, held=None):
    """The estimator of the system matrices whose model of the whole record fits it
    better (``system_matrices='auto'``), and its model: no fold fits.

    Both estimators take their model of the same order from the same subspace
    (``problem``, at the horizon used), so the models have the same number of free
    parameters, and their simulation fit to the estimation record (%, mean over the
    outputs, x0 by least squares; :func:`_fit_score`) compares them with no price
    for parameters to weigh. A model whose A had to be stabilised (:func:`stabilised`:
    ``stability='auto'`` reflected unstable poles) is a repaired estimate, not the
    estimator's own, and comes after one that needed no repair (on the DaISy
    evaporator record at order 10, horizon 20, the stabilised shift-invariance model
    fits the estimation part 62.8 % against 56.3 %, and the validation part 55.9 %
    against 64.4 %). Otherwise the better fit: the first estimator unless the
    other's misfit is smaller by more than :data:`subid.methods.crossval.ABSOLUTE_TOLERANCE`
    (ties, e.g. noise-free data, go to the first). The warnings of the model returned
    are issued, the other's not.

    ``held``: the :class:`subid.methods.dt._scoring.Held` of ``data`` with its lag
    products, when already made (:class:`subid.methods.dt.choice.RecordWork`).

    Returns
    -------
    estimator, model, rule
        ``rule`` is ``info['system_matrices_selection']``: ``'fit'``, with each
        estimator's ``fits`` and whether its model was ``stabilised``.
    """
    from subid.methods.dt._scoring import Held
    if held is None or held.record is not data:
        held = Held(data, lagged=data.n_experiments == 1)
    models, fits, repaired, issued = {}, {}, {}, {}
    for name in estimators:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                models[name] = fitter.fit(problem, name)
            except SubidError:
                if name == estimators[0]:
                    raise
                continue
        issued[name] = caught
        fits[name] = _fit_score(models[name], held)
        repaired[name] = bool(stabilised(models[name]))
    best = estimators[0]
    for name in models:
        if name == best:
            continue
        if repaired[name] != repaired[best]:
            best = best if repaired[name] else name
        elif 100.0 - fits[name] < max(100.0 - fits[best], ABSOLUTE_TOLERANCE) \
                - ABSOLUTE_TOLERANCE:
            best = name
    for w in issued[best]:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    rule = {"rule": "fit", "fits": fits, "stabilised": repaired, "description": (
        "at the order and horizon used, the estimator whose model fits the whole "
        "estimation record better (simulation fit %, mean over outputs, x0 by least "
        "squares; the same number of parameters), a model that needed no stabilisation "
        "first, the first estimator on ties; no fold fits")}
    return best, models[best], rule
