"""The plan and the pipeline of the discrete-time batch methods (issue 24, item 1).

A method is a :class:`SubspaceMethod` with explicit steps; :func:`make_plan` decides every
default before any work; :func:`run` serves every method, its folds included.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import subid
from subid.errors import OptionError
from subid.methods.dt._subspace import future_past_factor, shift_invariance
from subid.methods.dt.moesp import Moesp
from subid.methods.dt.n4sid import N4sid
from subid.methods.dt.pipeline import Shift, Subspace, SubspaceMethod, run
from subid.methods.dt.plan import AUTO_VARIANT_MAX_SAMPLES, make_plan


class Unweighted(SubspaceMethod):
    """A method written afresh on the protocol: PO-MOESP's unit weighting (the SVD of
    L32) and shift invariance, i.e. ``moesp(weighting='moesp', system_matrices='shift')``."""

    name = "unweighted"

    def __init__(self):
        self.common_options(feedthrough="auto", estimate_x0=True)

    def decompose(self, problem, feedthrough):
        f = problem.horizon
        a, b = f * problem.data.n_inputs, f * (problem.data.n_inputs + problem.data.n_outputs)
        L = future_past_factor(problem)
        U, s, _ = scipy.linalg.svd(L[a + b:, a:a + b], full_matrices=False,
                                   check_finite=False)
        return Subspace(s, parts={"U": U, "L": L, "a": a, "b": b})

    def system_matrices(self, problem, subspace, order, estimator, *, feedthrough, ft_record,
                        plan):
        p = subspace.parts
        gamma = p["U"][:, :order] * np.sqrt(subspace.profile[:order])
        Q = scipy.linalg.qr(gamma, mode="economic", check_finite=False)[0]
        A, C, residual = shift_invariance(Q, problem.data.n_outputs)
        L, a, b = p["L"], p["a"], p["b"]
        return Shift(A, C, Q, L[:a, :a], L[a + b:, :a],
                     info={"singular_values": subspace.profile, "weighting": "moesp",
                           "shift_residual": residual})


def test_a_new_method_is_two_steps_on_the_pipeline():
    """A method of two steps gets the order choice on the folds, B, D, x0 with the
    stability rule, the noise model and the info of the pipeline: noise-free, the true
    order and exact Markov parameters; with an order and horizon, the model of the same
    steps inside subid.moesp bit for bit."""
    true = subid.systems.seed001_system()
    data = subid.systems.simulate_data(true, 500, seed=1)
    model = run(Unweighted(), data, None, None, selection="cv")
    assert model.order == true.order
    assert model.info["method"] == "unweighted"
    assert model.info["order_selection"]["rule"] == "cv"
    assert model.K is not None and model.info["warnings"] == []
    assert subid.markov_error(model, true) < 1e-9
    noisy = subid.systems.simulate_data(true, 600, seed=2, output_snr_db=20)
    mine = run(Unweighted(), noisy, 3, 8, selection="cv")
    theirs = subid.moesp(noisy, 3, horizon=8, system_matrices="shift")
    for key in ("A", "B", "C", "D", "K"):
        np.testing.assert_array_equal(getattr(mine, key), getattr(theirs, key))


def test_the_plan_decides_before_any_work():
    """Which estimators, whether the choice is cross-validated, the long-record rule and
    the option checks come from make_plan, before the data are factored."""
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 300, seed=1)
    plan, _ = make_plan(Moesp(), data, 4, 8, selection="cv")
    assert plan.pinned and not plan.cross_validate and plan.estimators == ("shift", "states")
    assert plan.estimator_choice == "fit"
    plan, _ = make_plan(Moesp(), data, None, None, selection="cv")
    assert plan.cross_validate and plan.estimator_choice == "fit"
    plan, _ = make_plan(Moesp(), data, [4], 8, selection="cv")      # asks for the folds
    assert plan.cross_validate and plan.estimator_choice == "cv"
    plan, _ = make_plan(Moesp(system_matrices="shift"), data, 4, 8, selection="cv")
    assert not plan.cross_validate and plan.info("shift") == {"system_matrices": "shift"}
    assert plan.estimator_choice is None
    plan, _ = make_plan(N4sid(), data, [2, 5, 3], None, selection="gap")
    assert not plan.cross_validate and plan.estimators == (None,)
    assert plan.candidates == (2, 3, 5) and plan.orders == [2, 3, 5]
    stat = subid.HankelStatistic.from_data(data, 16)
    plan = make_plan(Moesp(), stat, None, None, selection="cv")[0]
    assert not plan.cross_validate and plan.estimator_choice is None
    long = subid.systems.simulate_data(subid.systems.seed001_system(),
                                       AUTO_VARIANT_MAX_SAMPLES + 1, seed=1)
    plan, _ = make_plan(Moesp(), long, 4, 8, selection="cv")
    assert plan.estimators == ("shift",) and not plan.cross_validate
    assert plan.info("shift")["system_matrices_selection"]["rule"] == "long record"
    plan, shifted = make_plan(Moesp(), data, None, None, selection="cv", input_delay=2,
                              refine="prediction")
    assert plan.refine == "prediction" and shifted.n_samples == data.n_samples - 2
    with pytest.raises(OptionError, match="selection"):
        make_plan(Moesp(), data, None, None, selection="best")
    with pytest.raises(OptionError, match="weighting"):
        Moesp(weighting="none")
