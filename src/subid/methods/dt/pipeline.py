"""One pipeline for the discrete-time batch subspace methods.

A method (:func:`subid.ls_subspace`, :func:`subid.moesp`, :func:`subid.n4sid`,
:func:`subid.pbsid`, and any later one) is a :class:`SubspaceMethod`: an object
holding its validated options, with explicit steps. Its public function makes
the object, then calls :func:`run`, which

1. makes the :class:`subid.methods.dt.plan.Plan` (every default decided once);
2. chooses the order and horizon (:func:`subid.methods.dt.choice.choose`,
   the one module that owns that choice, on the folds of the record) or takes
   them from the plan, and the estimator where the method offers several
   (:func:`subid.methods.dt.selection.estimator_by_fit` at the order and horizon
   used, no fold fits; by the cross-validation when a list of orders is given);
3. on the whole record, :meth:`Pipeline.fit`: the statistic
   (:func:`subid.methods.dt._subspace.prepare`), the method's subspace step
   (:meth:`SubspaceMethod.decompose`, whose profile gives the order by the gap
   rule when it is not fixed), the system matrices
   (:meth:`SubspaceMethod.system_matrices`), then B, D and x0 with the stability
   rule (:func:`b_d_x0`: the output regression of :func:`subid.methods.bd.fit_b_d_x0`
   for the A and C of shift invariance, refitted for a stable A where
   :func:`subid.methods.dt._subspace.stable_choice` asks; the state-sequence
   estimators bring their own B, D from the state regression and the same stability
   rule, :func:`subid.methods.dt.n4sid.state_model`), and
   :func:`subid.methods.dt._subspace.finish`;
4. the noise model, the refinement and the delays
   (:func:`subid.methods.dt._subspace.finalize`), once, on the final model.

The cross-validation runs step 3 on its folds through the same :class:`Pipeline`
(``prepare_fold`` and ``fit``), so a fold model is made exactly as the final one.
"""

from __future__ import annotations

import abc
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from subid.errors import FeedbackWarning, NotExcitingError, OrderError, TooFewSamplesError
from subid.methods._common import choose_order
from subid.methods._info import collect_warnings
from subid.methods.dt._subspace import (
    b_d_fit,
    b_d_refit,
    finalize,
    finish,
    lag_fold_score,
    prepare,
    stable_choice,
)
from subid.methods.dt.checks import check_data
from subid.methods.dt.choice import choose
from subid.methods.dt.feedthrough import dropped_direct_term
from subid.methods.dt.feedthrough import resolve as resolve_feedthrough
from subid.methods.dt.plan import Plan, make_plan
from subid.methods.dt.selection import enforced, estimator_by_fit, score_matrices
from subid.model.statespace import StateSpace


@dataclass(frozen=True)
class Subspace:
    """What a method's subspace step gives, before the order is known: ``profile``,
    the values whose largest gap gives the order (``source`` names them in
    ``info['order_selection']``), and the method's own pieces (``parts``)."""

    profile: np.ndarray
    source: str = "singular values"
    parts: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Shift:
    """System matrices by shift invariance: A and C (in the units of the normalised
    channels) in the orthonormal basis ``basis`` of the estimated range(Γ), with what
    the B, D, x0 regression needs (``L11``, ``L_yu``: the factor's blocks for the
    ``'projection'`` route); ``info``, the method's own ``info`` entries; ``parts``,
    what :meth:`SubspaceMethod.output_basis` needs."""

    A: np.ndarray
    C: np.ndarray
    basis: np.ndarray
    L11: np.ndarray
    L_yu: np.ndarray
    info: dict
    parts: dict = field(default_factory=dict)


@dataclass(frozen=True)
class States:
    """System matrices with B, D (in the user's units) and x0 already estimated (the
    state-sequence regression, stability handled with it); ``info``, every entry of
    the method's own (its ``feedthrough`` record included)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    info: dict


class SubspaceMethod(abc.ABC):
    """The protocol of a discrete-time batch subspace method (the base class).

    A subclass validates its options in its constructor (the shared ones with
    :meth:`common_options`) and defines the steps the pipeline calls:

    * :meth:`decompose` (``problem, feedthrough -> Subspace``): the subspace step
      that does not depend on the order (cache it on the problem with
      :meth:`subid.methods.dt._subspace.Problem.cached`: the candidate orders of a
      cross-validation fold share one problem);
    * :meth:`system_matrices` (``problem, subspace, order, estimator, feedthrough,
      ft_record, plan -> Shift | States``: ``feedthrough``, whether D is estimated,
      ``ft_record`` its ``info['feedthrough']``, ``plan`` the
      :class:`subid.methods.dt.plan.Plan`);
    * :meth:`output_basis` (``Shift, A, B, x0 -> A, B, C, x0``), for a method whose
      state basis is not that of :class:`Shift` (identity by default).

    Class attributes: ``name`` (``info['method']``), ``blocks_per_horizon`` (2 with
    past and future block rows, 1 with future rows only), ``estimators`` (the names of
    the estimators of the system matrices it may choose among, the first the
    default; ``(None,)`` when it has one).
    """

    name = ""
    blocks_per_horizon = 2
    normalize_outputs = True
    estimators: tuple = (None,)

    def common_options(self, *, feedthrough, estimate_x0, stability="auto", bd_method="auto"):
        """Store the options every method shares (already validated)."""
        self.feedthrough = feedthrough
        self.estimate_x0 = estimate_x0
        self.stability = stability
        self.bd_method = bd_method

    @abc.abstractmethod
    def decompose(self, problem, feedthrough) -> Subspace:
        """The order-independent subspace step on ``problem`` (D estimated when
        ``feedthrough``)."""

    @abc.abstractmethod
    def system_matrices(self, problem, subspace, order, estimator, *, feedthrough, ft_record,
                        plan):
        """:class:`Shift` or :class:`States` at ``order`` with ``estimator``."""

    def output_basis(self, estimate: Shift, A, B, x0):
        """A, B, C (normalised channels) and x0 in the basis the model is returned in."""
        return A, B, estimate.C, x0


def b_d_x0(problem, estimate: Shift, *, feedthrough: bool, plan):
    """B, D and x0 of the A and C of ``estimate``, with the stability rule.

    The output regression (:func:`subid.methods.dt._subspace.b_d_fit`, route
    ``plan.bd_method``; for an A kept unstable under ``'auto'``, the predictor form,
    :func:`subid.methods.dt._subspace.b_d_refit`) inside
    :func:`subid.methods.dt._subspace.stable_choice`.

    Returns
    -------
    A_q, (B, D, x0, diagnostics), stability record
    """
    fit = b_d_fit(problem, estimate.C, estimate.basis, estimate.L11, estimate.L_yu,
                  bd_method=plan.bd_method, feedthrough=feedthrough,
                  estimate_x0=plan.estimate_x0)
    # an unstable A: B, D, x0 by the one-step predictor
    refit = b_d_refit(problem, estimate.C * problem.output_scale[:, None],
                      feedthrough=feedthrough, estimate_x0=plan.estimate_x0)
    return stable_choice(estimate.A, estimate.basis, problem.data.n_outputs, fit,
                         stability=plan.stability, data=problem.data, method=problem.method,
                         refit_unstable=refit if plan.bd_method == "auto" else None,
                         bound_unstable=problem.fold)


@dataclass(frozen=True)
class Pipeline:
    """A method and its plan: what makes one model from a record, on the whole record
    and on the cross-validation folds alike."""

    method: SubspaceMethod
    plan: Plan
    #: The fold records :meth:`prepare_fold` has checked (:func:`subid.methods.dt.checks.check_data`)
    #: in this call, with their output weights: a fold is checked, and its weights
    #: computed, once for every horizon.
    checked_folds: list = field(default_factory=list, compare=False, repr=False)

    @property
    def blocks_per_horizon(self) -> int:
        return self.plan.blocks_per_horizon

    @property
    def statistic(self) -> str:
        return self.plan.statistic

    def prepare(self, record, orders, horizon, factor=None, *, checked=False):
        """The problem of ``record`` (:func:`subid.methods.dt._subspace.prepare`)."""
        return prepare(record, orders, horizon, factor=factor, checked=checked,
                       **self.plan.prepare_options())

    def prepare_fold(self, record, orders, horizon, factor=None):
        """:meth:`prepare` on a cross-validation fold (its warnings are not the user's),
        the record's checks made and its output weights computed at its first horizon
        only (the same record: the same outcome and weights; 1.4 ms and 1 ms a fold at
        10^5 samples)."""
        weights = next((w for r, w in self.checked_folds if r is record), None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if weights is None:           # the checks that raise; no warnings to show
                check_data(record, self.plan.method, warn=False)
            problem = self.prepare(record, orders, horizon, factor=factor, checked=True)
        if weights is None:
            self.checked_folds.append((record, problem.weights()))
        else:
            problem._cache["weights"] = weights
        return problem

    def fit(self, problem, estimator) -> StateSpace:
        """The model of ``problem`` (its order fixed or chosen by the gap rule) with
        ``estimator``: subspace step, system matrices, B/D/x0 and stability,
        :func:`subid.methods.dt._subspace.finish`."""
        method, plan = self.method, self.plan
        feedthrough, ft_record = resolve_feedthrough(plan.feedthrough, problem)
        if (message := dropped_direct_term(ft_record)) is not None:
            warnings.warn(message, FeedbackWarning, stacklevel=2)
        subspace = method.decompose(problem, feedthrough)
        n, order_selection = choose_order(problem.order, problem.candidates,
                                          subspace.profile, subspace.source)
        est = method.system_matrices(problem, subspace, n, estimator,
                                     feedthrough=feedthrough, ft_record=ft_record, plan=plan)
        if isinstance(est, States):
            return finish(problem, est.A, est.B, est.C, est.D, n, order_selection, **est.info)
        A_q, (B_q, D, x0_q, reg), stab = b_d_x0(problem, est, feedthrough=feedthrough,
                                                plan=plan)
        A, B, C, x0 = method.output_basis(est, A_q, B_q, x0_q)
        C = C * problem.output_scale[:, None]
        return finish(problem, A, B, C, D, n, order_selection, **est.info, x0=x0,
                      stability=stab, feedthrough=ft_record, **reg)

    def fold_score(self, problem, estimator, held):
        """``(score, stabilised)`` of the model :meth:`fit` makes on ``problem`` (a
        cross-validation fold at a fixed order) on the validation record of ``held``
        (:class:`subid.methods.dt._scoring.Held`): the same steps and matrices without the
        model object (no ``finish``: ``info``, the stability warning, the
        :class:`subid.StateSpace`), for a candidate that is only scored
        (:func:`subid.methods.dt.selection.score_horizon`). A stable A of shift
        invariance (whose model :func:`b_d_x0` leaves as estimated, in any basis: the
        score does not depend on it) takes its B, D, x0 from the lag products of the
        training record where they apply, without the stability rule's closures and
        diagnostics (:func:`subid.methods.dt._subspace.lag_fold_score`). ``stabilised``: whether
        ``stability='auto'`` reflected its unstable poles
        (:func:`subid.methods.dt.selection.stabilised`)."""
        method, plan = self.method, self.plan
        feedthrough, ft_record = resolve_feedthrough(plan.feedthrough, problem)
        subspace = method.decompose(problem, feedthrough)
        est = method.system_matrices(problem, subspace, problem.order, estimator,
                                     feedthrough=feedthrough, ft_record=ft_record, plan=plan)
        if isinstance(est, States):
            return score_matrices(est.A, est.B, est.C, est.D, held), \
                enforced(est.info.get("stability"))
        fast = lag_fold_score(problem, est.A, est.C, held, bd_method=plan.bd_method,
                              feedthrough=feedthrough, estimate_x0=plan.estimate_x0)
        if fast is not None:              # a stable A: no stability rule to apply
            return fast, False
        A_q, (B_q, D, x0_q, _), stab = b_d_x0(problem, est, feedthrough=feedthrough,
                                              plan=plan)
        A, B, C, _ = method.output_basis(est, A_q, B_q, x0_q)
        return score_matrices(A, B, C * problem.output_scale[:, None], D, held), \
            enforced(stab)


def excited_horizon(exc: NotExcitingError, plan: Plan, n_outputs: int) -> dict | None:
    """The horizon the choice falls back to when the input cannot support the candidate
    horizons (``exc``, raised by a fold or the whole record at the depth ``blocks x f``
    of a candidate ``f``), as a record for ``info['order_selection']['horizon_limited']``;
    None when the horizon was given, or the input supports no horizon that reveals the
    order given (the smallest candidate; order 1 when none is given)."""
    # the largest of HORIZON_CANDIDATES whose block rows the input excites
    # (blocks x f <= achieved), else achieved // blocks
    from subid.methods.crossval import HORIZON_CANDIDATES
    achieved = exc.achieved_order
    if plan.horizon is not None or achieved is None or exc.required_order is None \
            or achieved >= exc.required_order:
        return None
    blocks = plan.blocks_per_horizon
    fitting = [f for f in HORIZON_CANDIDATES if blocks * f <= achieved]
    f = max(fitting) if fitting else achieved // blocks
    lowest = plan.order if plan.order is not None else min(plan.candidates or (1,))
    if f < 2 or (f - 1) * n_outputs < lowest:
        return None
    return {"horizon": f, "achieved_excitation": achieved,
            "reason": f"the input is persistently exciting of order {achieved} only (a "
                      f"horizon f needs {blocks} f): horizon {f}, the largest it supports"}


def run(method: SubspaceMethod, data, order, horizon, *, selection: str,
        statistic: str = "auto", refine=None, input_delay=0) -> StateSpace:
    """The model of ``method`` on ``data``: the plan, the choice, the fit, the
    noise model and refinement (module docstring).

    With ``selection='cv'`` (default) and a raw record, an order or horizon not
    given is chosen by cross-validation on the record
    (:func:`subid.methods.dt.choice.choose`); the model is then fitted to the
    whole record with that choice, exactly as an explicit call would, the
    estimator (where the method offers several) chosen at that order and horizon
    by :func:`subid.methods.dt.selection.estimator_by_fit` (with a list of
    candidate orders, cross-validated with them). ``'gap'``, or a statistic without raw samples, takes the
    largest gap of the method's profile. ``info['system_matrices']`` names the
    estimator used and ``info['system_matrices_selection']`` says why when there
    was a choice; ``method(data, order=model.order, horizon=model.info['horizon'])``
    reproduces a default model.
    """
    record = data                     # before the input delays shift it
    plan, data = make_plan(method, data, order, horizon, selection=selection,
                           statistic=statistic, refine=refine, input_delay=input_delay)
    pipeline = Pipeline(method, plan)
    with collect_warnings() as issued:
        too_short = limited = None
        if plan.cross_validate:
            check_data(data, plan.method)
            try:
                try:
                    problem, model, estimator, rule = choose(data, plan, pipeline)
                except NotExcitingError as exc:
                    # the horizons the input cannot support left out (a multisine of 12
                    # sines, exciting of order 31, cannot take horizon 20's 40 block rows)
                    limited = excited_horizon(exc, plan, data.n_outputs)
                    if limited is None:
                        raise
                    plan = replace(plan, horizon=limited["horizon"],
                                   cross_validate=plan.order is None)
                    pipeline = Pipeline(method, plan)
                    if not plan.cross_validate:
                        raise
                    problem, model, estimator, rule = choose(data, plan, pipeline)
            except (TooFewSamplesError, OrderError, NotExcitingError) as exc:
                # the folds (three quarters of the record each) are too short for the
                # horizon the order needs, or a fold's inputs do not excite it (a step
                # late in the record: the first fold's input is zero), the whole record
                # is not: its singular values decide, as selection='gap' (a record too
                # short or too poorly excited for that too raises the error of the whole
                # record, which names its own length and excitation)
                too_short = (f"the record ({data.n_samples} samples) is too short or too "
                             f"poorly excited for the cross-validation folds ({exc}); the "
                             "largest gap of the whole record's singular values decides "
                             "instead")
                if limited is None or plan.order is None:
                    plan = replace(plan, selection="gap", cross_validate=False,
                                   estimator_choice="fit" if len(plan.estimators) > 1
                                   else None)
                    pipeline = Pipeline(method, plan)
                else:                     # the order given, the horizon now fixed: no folds
                    too_short = None
        if not plan.cross_validate:
            try:
                problem = pipeline.prepare(data, plan.orders, plan.horizon)
            except NotExcitingError as exc:
                # the whole record's excitation (a fold's may have been lower): the
                # horizon it supports, when none was given (a step: exciting of order 21)
                if limited is not None or (again := excited_horizon(
                        exc, plan, data.n_outputs)) is None:
                    raise
                limited = again
                plan = replace(plan, horizon=limited["horizon"])
                pipeline = Pipeline(method, plan)
                problem = pipeline.prepare(data, plan.orders, plan.horizon)
            if plan.estimator_choice == "fit":   # order and horizon given: no fold fits
                estimator, model, rule = estimator_by_fit(data, problem, pipeline,
                                                          plan.estimators)
            else:
                estimator, rule = plan.estimators[0], None
                model = pipeline.fit(problem, estimator)
            if too_short is not None:
                model.info["order_selection"] = dict(model.info["order_selection"],
                                                     reason=too_short)
        if limited is not None:
            model.info["order_selection"] = dict(model.info["order_selection"],
                                                 horizon_limited=limited)
        model.info.update(plan.info(estimator, rule))
        model = finalize(model, problem, refine=plan.refine, delays=plan.delays,
                         statistic=plan.statistic, record=record)
    model.info["warnings"] = list(issued)
    return model
