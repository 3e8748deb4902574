"""The initial-state argument ``x0``: one validator (``prediction.check_x0``) for
fit_percent, predict, simulate_fit, residuals, the figures and simulation_bounds, so they
accept the same values (None, 'estimate', 'zero', 0, an array) and reject the rest with a
DataError naming what is accepted."""

from __future__ import annotations

import numpy as np
import pytest

import subid
from subid.errors import DataError, NoiseModelWarning
from subid.evaluation.figures.residuals import residual_correlations
from subid.model.prediction import check_x0, simulate_fit
from subid.model.statespace import StateSpace

TRUE = StateSpace([[0.8, 0.2], [0.0, 0.5]], [[1.0], [0.5]], [[1.0, 0.3]], 0, dt=1.0)
WITH_K = StateSpace(TRUE.A, TRUE.B, TRUE.C, TRUE.D, dt=1.0, K=[[0.3], [0.1]])


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(4)
    u = rng.standard_normal((300, 1))
    y = TRUE.simulate(u, x0=[1.0, -1.0]) + 0.01 * rng.standard_normal((300, 1))
    return subid.IOData(u, y, dt=1.0)


BAD = ["foo", "", True, 1.5, [0.0, 0.0, 0.0], np.zeros((2, 2)), ["a", "b"], 1j,
       [1j, 0.0], [[0.0, 0.0], [1.0]], [np.nan, 0.0]]


@pytest.mark.parametrize("x0", BAD, ids=repr)
def test_every_function_rejects_the_same_x0(data, x0):
    calls = [lambda: subid.fit_percent(TRUE, data, x0=x0),
             lambda: subid.fit_percent(WITH_K, data, x0=x0, steps=1),
             lambda: subid.predict(WITH_K, data, x0=x0),
             lambda: subid.predict(TRUE, data, steps=np.inf, x0=x0),
             lambda: simulate_fit(TRUE, data, x0=x0),
             lambda: subid.residuals(WITH_K, data, x0=x0),
             lambda: residual_correlations(TRUE, data, x0=x0),
             lambda: residual_correlations(WITH_K, data, x0=x0)]
    for call in calls:
        with pytest.raises(DataError, match="x0") as info:
            call()
        assert "diverges" not in str(info.value)
        accepted = "'estimate' (or None), 'zero' (or 0) or an array of shape (2,)"
        assert ("NaN" in str(info.value)) if x0 is BAD[-1] else accepted in str(info.value)


@pytest.mark.parametrize("x0", [0, 0.0, np.int64(0), np.array(0.0), "zero", [0.0, 0.0],
                                np.zeros((2, 1))], ids=repr)
def test_every_zero_state_gives_the_same_fit(data, x0):
    zero = subid.fit_percent(TRUE, data, x0="zero")
    assert np.array_equal(subid.fit_percent(TRUE, data, x0=x0), zero)
    assert np.array_equal(subid.predict(WITH_K, data, x0=x0),
                          subid.predict(WITH_K, data, x0="zero"))
    assert np.array_equal(subid.fit_percent(WITH_K, data, x0=x0, steps=2),
                          subid.fit_percent(WITH_K, data, x0="zero", steps=2))


def test_none_and_estimate_are_the_same(data):
    estimated = subid.fit_percent(TRUE, data, x0="estimate")
    assert np.array_equal(subid.fit_percent(TRUE, data, x0=None), estimated)
    assert estimated[0] > subid.fit_percent(TRUE, data, x0=0)[0] + 1.0
    assert np.array_equal(subid.predict(WITH_K, data, x0="estimate"),
                          subid.predict(WITH_K, data))
    with pytest.warns(NoiseModelWarning):
        by_prediction = subid.predict(TRUE, data, x0=None)
    assert np.array_equal(by_prediction, simulate_fit(TRUE, data)[0])


def test_several_experiments_need_one_state_each(data):
    both = subid.merge([data, data])
    fits = subid.fit_percent(TRUE, both, x0=np.zeros((2, 2)), per_experiment=True)
    assert np.array_equal(fits, subid.fit_percent(TRUE, both, x0=0, per_experiment=True))
    for x0 in (np.zeros(2), np.zeros((3, 2)), "foo"):
        with pytest.raises(DataError, match=r"array of shape \(2, 2\) \(one initial state"):
            subid.fit_percent(TRUE, both, x0=x0)
        with pytest.raises(DataError, match=r"array of shape \(2, 2\)"):
            subid.predict(WITH_K, both, x0=x0)


def test_check_x0_normalises():
    assert check_x0(None, 2) == "estimate"
    assert check_x0(None, 2, estimate=False) == "zero"
    assert check_x0(0, 2) == "zero"
    assert np.array_equal(check_x0([[1], [2]], 2), [1.0, 2.0])
    with pytest.raises(DataError, match=r"x0 must be None, 'zero' \(or 0\) or an array"):
        check_x0("estimate", 2, estimate=False)


def test_simulation_bounds_take_the_zero_state_forms():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(400)
    y = TRUE.simulate(u)[:, 0] + 0.05 * rng.standard_normal(400)
    data = subid.IOData(u, y, dt=1.0)
    model = subid.pem(data, subid.n4sid(data, 2))
    base = subid.simulation_bounds(model, u[:50])
    for x0 in (0, "zero", np.zeros(2)):
        band = subid.simulation_bounds(model, u[:50], x0=x0)
        assert np.array_equal(band.value, base.value)
        assert np.array_equal(band.upper, base.upper)
    moved = subid.simulation_bounds(model, u[:50], x0=[1.0, 0.0])
    assert not np.allclose(moved.value, base.value)
    for x0 in ("estimate", "foo", [1.0], True):
        with pytest.raises(DataError, match=r"x0 must be None, 'zero' \(or 0\) or an array"):
            subid.simulation_bounds(model, u[:50], x0=x0)


def test_compare_figure_checks_x0_for_simulation_and_prediction(data):
    pytest.importorskip("matplotlib")
    from subid.evaluation.figures.time_domain import compare
    for steps in (np.inf, 2):
        with pytest.raises(DataError, match=r"x0 must be 'estimate' \(or None\)"):
            compare(data, WITH_K, x0="foo", steps=steps)
