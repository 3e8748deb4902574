"""The cross-validated choices of :func:`subid.methods.ct.ct_subspace.ct_subspace` between
two builds of a model at one order (feedthrough, B and D, refinement): the folds'
fitter (:class:`_Folds`) and the comparison (:func:`_second_wins`)."""

from __future__ import annotations

from subid.errors import TooFewSamplesError
from subid.methods.ct import _ct_discrete
from subid.methods.dt.selection import cross_validate

__all__ = ["_Folds", "_second_wins"]


class _Folds:
    """What :func:`subid.methods.dt.selection.cross_validate` runs on its folds: the
    fold's problem (``prepare_fold``) and the model of each build (``builds``, name ->
    callable); one block row per basis function, no merged statistic."""

    blocks_per_horizon = 1
    statistic = None

    def __init__(self, prepare_fold, builds):
        self._prepare, self._builds = prepare_fold, builds

    def prepare_fold(self, record, orders, horizon, factor=None):
        return self._prepare(record, orders, horizon)

    def fit(self, problem, name):
        return self._builds[name](problem)


def _second_wins(data, order, n_functions, prepare_fold, first, second, test=False):
    """Whether the cross-validation at ``order`` prefers the build ``second`` to ``first``
    (``(name, build)`` pairs; ties go to ``first``; None when the record is too short
    for the folds), and its record; with ``test``,
    ``second`` must also score significantly better on the folds
    (:func:`subid.methods.ct._ct_discrete.paired_test`)."""
    builds = dict([first, second])
    try:
        _, _, variant, record = cross_validate(data, order, None, n_functions,
                                               fitter=_Folds(prepare_fold, builds),
                                               estimators=list(builds))
    except TooFewSamplesError as exc:          # folds too short for the basis: no choice
        return None, {"rule": "skipped", "description": (
            f"not cross-validated: the record ({data.n_samples} samples) is too short for "
            f"the cross-validation folds ({exc}); the choice without folds")}
    folds = {c.get("system_matrices"): c["folds"] for c in record["candidates"]}
    wins = variant == second[0]
    if test:
        record["paired_test"] = _ct_discrete.paired_test(folds[second[0]], folds[first[0]])
        wins = wins and record["paired_test"]["significant"]
    if not wins and variant == second[0]:
        kept = next(c for c in record["candidates"] if c.get("system_matrices") == first[0])
        record["selected"] = {k: v for k, v in kept.items()
                              if k not in ("folds", "stabilised_folds")}
    return wins, record
