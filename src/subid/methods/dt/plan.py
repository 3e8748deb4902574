"""The plan of a discrete-time batch identification: every default decided once.

:func:`make_plan` runs at the public boundary of :func:`subid.ls_subspace`,
:func:`subid.moesp`, :func:`subid.n4sid` and :func:`subid.pbsid`, after each
method has validated its own options (its :class:`subid.methods.dt.pipeline.SubspaceMethod`),
and before any work: it decides the order candidates and the horizon (those
given, or the rule that chooses them), the selection rule, the estimators of the
system matrices, the feedthrough, stability, B/D and x0 settings, the refinement
and the input delays, and whether the order/horizon/estimator choice is
cross-validated. The pipeline (:func:`subid.methods.dt.pipeline.run`) then only
follows the plan, and :meth:`Plan.info` gives the entries of ``model.info`` the
plan decided. What needs the data themselves is computed where the plan says: the
cross-validated choice (:func:`subid.methods.dt.choice.choose`), the horizon of
the gap rule (:func:`subid.methods.dt._subspace.check_order_horizon`, the smallest
feasible of ``HORIZON_CANDIDATES``) and ``feedthrough='auto'``
(:func:`subid.methods.dt.feedthrough.resolve`, once per problem).

The constants behind the defaults stay with the code that owns them: the
order candidates and horizons of the selection (:mod:`subid.methods.dt.selection`:
``MAX_ORDER``, ``HORIZON_CANDIDATES``, ``SELECTION_RULES``), the estimator
choice (:data:`AUTO_VARIANT_MAX_SAMPLES`), the feedthrough tests
(:mod:`subid.methods.dt.feedthrough`), the stability rule
(:mod:`subid.methods._stability`), the refinement
(:mod:`subid.methods.dt.noise_model`).
"""

from __future__ import annotations

from dataclasses import dataclass

from subid._validation import check_int
from subid.data import IOData
from subid.delay import shift_for_method
from subid.errors import OptionError
from subid.methods._common import parse_order
from subid.methods.crossval import SELECTION_RULES
from subid.methods.dt.noise_model import check_refine

#: ``system_matrices='auto'`` chooses between its estimators on records up to this many
#: samples; longer records use the first ('shift'), where both are consistent and their
#: models close. The choice is made at the order and horizon used (given, or chosen by
#: the cross-validation with the first estimator) by the models' fit to the whole record
#: (:func:`subid.methods.dt.selection.estimator_by_fit`, no fold fits); a list of candidate
#: orders (``order=[4]``) asks for the estimators to be cross-validated with the orders.
AUTO_VARIANT_MAX_SAMPLES = 20_000


@dataclass(frozen=True)
class Plan:
    """What one call of a discrete-time batch method does, decided before any work.

    ``order`` and ``candidates`` are the order given (or None) and the candidate
    orders given (None: ``1..MAX_ORDER``, extended by the cross-validation while
    the criterion improves, :func:`subid.methods.crossval.next_block`);
    ``horizon`` the horizon given (None: chosen, by the cross-validation among
    ``HORIZON_CANDIDATES`` or, for the gap rule, the smallest feasible one).
    ``estimators`` are the estimators of the system matrices the method may use,
    the first the default (``(None,)`` for a method with one);
    ``estimator_rule`` says why the choice was narrowed before the data were
    looked at (a long record), and ``cross_validate`` whether the order, horizon
    (and, with ``estimator_choice='cv'``, the estimator) are chosen by
    :func:`subid.methods.dt.choice.choose`. ``estimator_choice`` says how the
    estimator is chosen among several: ``'fit'`` at the order and horizon used, by
    :func:`subid.methods.dt.selection.estimator_by_fit` (no fold fits), ``'cv'``
    with the candidate orders by the cross-validation (a list of candidate orders
    given), None (one estimator, or no raw samples, or ``selection='gap'``: the first).
    """

    method: str
    order: int | None
    candidates: tuple | None
    horizon: int | None
    selection: str
    estimators: tuple
    estimator_rule: dict | None
    cross_validate: bool
    estimator_choice: str | None
    blocks_per_horizon: int
    statistic: str
    normalize_outputs: bool
    feedthrough: object
    stability: str
    estimate_x0: bool
    bd_method: str
    refine: str | None
    delays: object

    @property
    def pinned(self) -> bool:
        """The order and the horizon are both given (no fold fits)."""
        return self.order is not None and self.horizon is not None

    @property
    def orders(self):
        """The order argument of :func:`subid.methods.dt._subspace.prepare`: the order,
        the candidate list, or None."""
        if self.order is not None:
            return self.order
        return None if self.candidates is None else list(self.candidates)

    def prepare_options(self) -> dict:
        """The keywords of :func:`subid.methods.dt._subspace.prepare` the plan fixes."""
        return dict(method=self.method, blocks_per_horizon=self.blocks_per_horizon,
                    statistic=self.statistic, normalize_outputs=self.normalize_outputs)

    def info(self, estimator, estimator_rule=None) -> dict:
        """The ``info`` entries of the plan's decisions for a model made with
        ``estimator`` (``estimator_rule``: why, when the choice was made from the
        data; default :attr:`estimator_rule`)."""
        out = {}
        if estimator is not None:
            out["system_matrices"] = estimator
        rule = self.estimator_rule if estimator_rule is None else estimator_rule
        if rule is not None:
            out["system_matrices_selection"] = rule
        return out


def make_plan(method, data, order, horizon, *, selection: str, statistic: str = "auto",
              refine=None, input_delay=0):
    """The :class:`Plan` of ``method`` (a validated
    :class:`subid.methods.dt.pipeline.SubspaceMethod`) on ``data``, and the data
    with the input delays applied.

    Checks, in the order the methods always made them: the refinement
    (:func:`subid.methods.dt.noise_model.check_refine`), the input delays
    (:func:`subid.delay.shift_for_method`), the selection rule, the order and the
    horizon.
    """
    refine = check_refine(refine, data)
    data, delays = shift_for_method(data, input_delay)
    if selection not in SELECTION_RULES:
        raise OptionError(f"selection must be one of {SELECTION_RULES}, got {selection!r}")
    fixed, candidates = parse_order(order)
    if horizon is not None:
        horizon = check_int(horizon, "horizon", minimum=2)
    estimators = tuple(method.estimators)
    estimator_rule = None
    if len(estimators) > 1 and getattr(data, "n_samples", 0) > AUTO_VARIANT_MAX_SAMPLES:
        estimator_rule = {"rule": "long record", "description": (
            f"{estimators[0]!r} beyond {AUTO_VARIANT_MAX_SAMPLES} samples, where both "
            "estimators are consistent")}
        estimators = estimators[:1]
    # order and horizon given: no fold fits (issue 21); the estimator of
    # system_matrices='auto' is chosen at the order and horizon used by the models' fit to
    # the whole record, the same rule after the default call's cross-validation (made with
    # the first estimator), so that method(data, order=m.order, horizon=m.info['horizon'])
    # reproduces the default model m; a list of candidate orders cross-validates them all
    raw = selection == "cv" and isinstance(data, IOData)
    estimator_choice = None
    if len(estimators) > 1 and raw:
        estimator_choice = "cv" if candidates is not None else "fit"
    plan = Plan(method=method.name, order=fixed,
                candidates=None if candidates is None else tuple(candidates), horizon=horizon,
                selection=selection, estimators=estimators, estimator_rule=estimator_rule,
                cross_validate=raw and not (fixed is not None and horizon is not None),
                estimator_choice=estimator_choice,
                blocks_per_horizon=method.blocks_per_horizon, statistic=statistic,
                normalize_outputs=bool(method.normalize_outputs),
                feedthrough=method.feedthrough, stability=method.stability,
                estimate_x0=method.estimate_x0, bd_method=method.bd_method, refine=refine,
                delays=delays)
    return plan, data
