"""Horizons past 20 on oversampled records (subid.methods.crossval.longer_horizon)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

import subid
from subid.methods import crossval


def _oversampled(dt=0.02, n_samples=20_000, seed=1):
    """bench/horizons.py's record: a 2x2 order-4 plant with time constants of 0.5-5 s,
    inputs held for 50 samples, 5 % output noise; (estimation, validation)."""
    rng = np.random.default_rng(seed)
    A = np.array([[-0.5, 2.0, 0, 0], [-2.0, -0.5, 0, 0], [0, 0, -0.2, 0], [0, 0, 0, -1.0]])
    B, C = rng.standard_normal((4, 2)), rng.standard_normal((2, 4))
    plant = subid.StateSpace(A, B, C, np.zeros((2, 2)), 0).to_discrete(dt)
    u = np.repeat(rng.standard_normal((n_samples // 50, 2)), 50, axis=0)
    y = plant.simulate(u)
    y = y + 0.05 * y.std(axis=0) * rng.standard_normal(y.shape)
    return subid.IOData(u, y, dt=dt).split(0.7)


def _low_pass(x, pole):
    return scipy.signal.lfilter([1.0], [1.0, -pole], x)


def test_response_memory_measures_the_response_not_the_noise():
    rng = np.random.default_rng(0)
    N = 5000
    u = rng.standard_normal(N)
    fast = np.convolve(u, [1.0, 0.5, 0.25], mode="full")[:N] + 0.1 * rng.standard_normal(N)
    assert crossval.response_memory(subid.IOData(u, fast), 20) < 0.15   # over in 3 samples
    slow = _low_pass(u, 0.995)                     # a time constant of 200 samples
    assert crossval.response_memory(subid.IOData(u, slow), 20) > 0.8
    # coloured output noise remembers, but not the response to the input
    coloured = fast + 5.0 * _low_pass(rng.standard_normal(N), 0.995) / 10.0
    assert crossval.response_memory(subid.IOData(u, coloured), 20) < 0.5
    # several experiments: the lagged products summed within each, none across the border
    first, second = subid.IOData(u[:2500], slow[:2500]), subid.IOData(u[2500:], fast[2500:])
    both = subid.merge([first, second])
    yc, uc = both.y[:, 0] - both.y.mean(), both.u[:, 0] - both.u.mean()
    rho = np.array([sum(yc[a + tau:b] @ uc[a:b - tau] for a, b in ((0, 2500), (2500, N)))
                    for tau in range(40)]) / np.sqrt((yc @ yc) * (uc @ uc))
    rho = np.maximum(np.abs(rho) - 3 / np.sqrt(N), 0.0)
    assert crossval.response_memory(both, 20) == pytest.approx(rho[20:].max() / rho.max(),
                                                               rel=1e-12)


def test_longer_horizon_rules():
    rng = np.random.default_rng(1)
    e = rng.standard_normal(20_000)
    slow = _low_pass(e, 0.998)                                 # responds for ~500 samples
    data = subid.IOData(e, slow)
    args = (20_000, 1, 1, 2)
    assert crossval.longer_horizon(data, 10, 20, *args) == 40    # 10 chosen: still tried
    assert crossval.longer_horizon(data, 40, 40, *args) == 80    # the doubled one chosen
    assert crossval.longer_horizon(data, 20, 40, *args) is None  # the doubled one lost
    assert crossval.longer_horizon(data, 160, 160, *args) is None   # past MAX_HORIZON
    assert crossval.longer_horizon(data, 20, 20, 300, 1, 1, 2) is None   # too few columns
    white = subid.IOData(e, rng.standard_normal(20_000))
    assert crossval.longer_horizon(white, 20, 20, *args) is None  # forgets within 20
    assert crossval.longer_horizon(data, 10, 20, *args) == 40


def test_oversampled_record_gets_a_horizon_that_spans_its_dynamics(monkeypatch):
    est, val = _oversampled()
    model = subid.n4sid(est)
    searched = [b["horizons"] for b in model.info["order_selection"]["searched"]]
    assert model.info["horizon"] > 20 and [40] in searched
    fit = np.mean(subid.fit_percent(model, val))
    # the search of horizons 10 and 20 alone: a poor model on the same record
    monkeypatch.setattr(crossval, "MAX_HORIZON", 20)
    short = subid.n4sid(est)
    assert short.info["horizon"] <= 20
    assert fit > 93.0 and fit > np.mean(subid.fit_percent(short, val)) + 20.0
    # the chosen order and horizon passed back give the same model
    again = subid.n4sid(est, model.order, horizon=model.info["horizon"])
    np.testing.assert_allclose(again.A, model.A, rtol=1e-10, atol=1e-12)


def _multisine(n_sines, n_samples=1500, seed=0):
    """A SISO order-4 plant under a multisine of ``n_sines`` sines (persistently
    exciting of order 2 x n_sines), noise-free; (estimation, validation)."""
    plant = subid.systems.random_system(4, 1, 1, seed=31, pole_radius=(0.7, 0.97))
    k = np.arange(n_samples)
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, n_sines)
    u = np.sin(np.outer(k, np.linspace(0.02, 1.5, n_sines)) + phases).sum(axis=1)
    return subid.IOData(u, plant.simulate(u)).split(2 / 3), plant


@pytest.mark.parametrize("n_sines, horizon", [(12, 10), (5, 5)])
def test_the_chosen_horizon_is_one_the_input_excites(n_sines, horizon):
    # a multisine of 12 sines excites order 24 (31 on 1000 samples' rounding): horizon
    # 20's 40 block rows raised NotExcitingError from every default call, horizon 10
    # identifies the plant; 5 sines (order 10) leave horizon 5
    (est, val), plant = _multisine(n_sines)
    for method in (subid.moesp, subid.n4sid, subid.ls_subspace, subid.identify):
        with pytest.warns(subid.errors.ExcitationWarning) if n_sines == 12 and \
                method is not subid.identify else _no_check():
            model = method(est)
        assert model.info["horizon"] == horizon
        assert min(subid.fit_percent(model, val)) > 99.9
        if method is not subid.identify:
            limited = model.info["order_selection"]["horizon_limited"]
            assert limited["horizon"] == horizon and limited["achieved_excitation"] < 40
    # a horizon given is honoured, or refused
    with pytest.raises(subid.errors.NotExcitingError, match="exciting of order"):
        subid.moesp(est, horizon=20)


def _no_check():
    import contextlib
    return contextlib.nullcontext()


def test_a_step_test_is_identified_at_the_horizon_it_excites():
    # a single step, noise-free: exciting of order 21 on 400 samples (rounding), the
    # folds of order 1 or 2; the default calls raised NotExcitingError for horizon 20's
    # 40 block rows, while n4sid(data, 2) gave the plant to 8e-15
    plant = subid.StateSpace([[0.0, 1.0], [-3.0, -2.0]], [[0.0], [1.0]], [[3.0, 0.0]],
                             [[0.0]], 0).to_discrete(0.05)
    u = np.ones((400, 1))
    u[:20] = 0.0
    data = subid.IOData(u, plant.simulate(u), dt=0.05)
    model = subid.identify(data)
    assert model.order == 2
    w = np.logspace(-1, 1, 20)
    assert np.abs(model.freqresp(w) - plant.freqresp(w)).max() < 1e-8
    moesp = subid.moesp(data)
    assert moesp.info["order_selection"]["horizon_limited"]["horizon"] == 10
