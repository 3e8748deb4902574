"""Metrics agree with independent computations."""

import itertools

import numpy as np
import pytest

import subid
from subid import errors, systems


def test_markov_error_basis_invariant(paper_system):
    T = np.random.default_rng(0).standard_normal((3, 3)) + 3 * np.eye(3)
    other = paper_system.transform(T)
    assert subid.markov_error(other, paper_system) < 1e-12


def test_markov_error_direct_formula(paper_system):
    pert = subid.StateSpace(paper_system.A, paper_system.B * 1.01, paper_system.C,
                            paper_system.D, 1.0)
    M = [paper_system.D] + [paper_system.C @ np.linalg.matrix_power(paper_system.A, k)
                            @ paper_system.B for k in range(9)]
    Mp = [pert.D] + [pert.C @ np.linalg.matrix_power(pert.A, k) @ pert.B for k in range(9)]
    expected = np.linalg.norm(np.array(Mp) - np.array(M)) / np.linalg.norm(np.array(M))
    assert subid.markov_error(pert, paper_system) == pytest.approx(expected, rel=1e-12)


def test_markov_error_requires_same_dt(paper_system):
    other = subid.StateSpace(paper_system.A, paper_system.B, paper_system.C, paper_system.D, 0.5)
    with pytest.raises(errors.ModelError, match="dt"):
        subid.markov_error(other, paper_system)


def test_pole_error_matches_brute_force():
    r = np.random.default_rng(3)
    for trial in range(20):
        a = systems.random_system(5, 1, 1, seed=trial)
        b = systems.random_system(5, 1, 1, seed=100 + trial)
        p, q = a.poles(), b.poles()
        brute = min(max(abs(p[i] - q[j]) for i, j in enumerate(perm))
                    for perm in itertools.permutations(range(5)))
        assert subid.pole_error(a, b) == pytest.approx(brute, rel=1e-12)
    del r


def test_pole_error_order_mismatch():
    with pytest.raises(errors.ModelError, match="order"):
        subid.pole_error(systems.random_system(2, 1, 1, seed=0),
                         systems.random_system(3, 1, 1, seed=0))


def test_fit_percent_perfect_with_unknown_x0(paper_system):
    data = systems.simulate_data(paper_system, 400, seed=2, x0=[3.0, -1.0, 2.0])
    fit = subid.fit_percent(paper_system, data)
    assert fit.shape == (2,)
    np.testing.assert_allclose(fit, 100.0, atol=1e-8)
    assert subid.fit_percent(paper_system, data, x0="zero").min() < 100 - 1e-3


def test_fit_percent_formula(paper_system):
    data = systems.simulate_data(paper_system, 400, seed=2, output_snr_db=10)
    y_hat = paper_system.simulate(data.u)
    expected = 100 * (1 - np.linalg.norm(data.y - y_hat, axis=0)
                      / np.linalg.norm(data.y - data.y.mean(axis=0), axis=0))
    np.testing.assert_allclose(subid.fit_percent(paper_system, data, x0="zero"), expected)


def test_fit_percent_continuous_model_non_uniform():
    ct = subid.StateSpace([[-1.0, 0.5], [-0.5, -2.0]], [[1.0], [0.0]], [[1.0, 1.0]], [[0.0]], 0)
    t = np.cumsum(np.random.default_rng(4).uniform(0.05, 0.15, 300))
    u = np.sin(t)
    y = ct.simulate(u, t=t, x0=[1.0, -1.0])
    data = subid.IOData(u, y, t=t)
    np.testing.assert_allclose(subid.fit_percent(ct, data), 100.0, atol=1e-7)


def test_fit_percent_errors(paper_system):
    data = systems.simulate_data(paper_system, 100, seed=0)
    with pytest.raises(errors.DataError, match="dt"):
        subid.fit_percent(paper_system, subid.IOData(data.u, data.y, dt=0.5))
    with pytest.raises(errors.DataError, match="inputs"):
        subid.fit_percent(paper_system, subid.IOData(data.u[:, 0], data.y))


def test_fit_of_a_diverging_model_is_a_clear_error(paper_system):
    data = systems.simulate_data(paper_system, 2000, seed=0)
    unstable = subid.StateSpace(paper_system.A * 2.5, paper_system.B, paper_system.C,
                                paper_system.D, 1.0)
    with pytest.raises(errors.ModelError, match="overflows"):
        subid.fit_percent(unstable, data)


def _simulate_fit_dense(model, data):
    """Reference: all n free responses over the whole record, one lstsq."""
    t = None if model.dt > 0 else data.t
    forced = model.simulate(data.u, t=t)
    free = np.stack([model.simulate(np.zeros_like(data.u), t=t, x0=e)
                     for e in np.eye(model.order)], axis=-1)
    w = 1.0 / data.y.std(axis=0)
    x0 = np.linalg.lstsq((free * w[None, :, None]).reshape(-1, model.order),
                         ((data.y - forced) * w).reshape(-1), rcond=None)[0]
    return forced + free @ x0, x0


def _models_for_blocks():
    A = np.diag([0.999, 0.97, 0.5, -0.3])
    B = np.ones((4, 2))
    C = np.arange(8.0).reshape(2, 4) + 1
    D = np.zeros((2, 2))
    hidden = C.copy()
    hidden[:, 3] = 0.0                                  # one unobservable state
    ct = subid.StateSpace([[-1.0, 2, 0], [-2, -1, 0], [0, 0, -0.5]], [[1.0], [0], [1]],
                          [[1.0, 0, 1], [0, 1, 1]], [[0.0], [0]], 0)
    return {"stable": subid.StateSpace(A, B, C, D, 1.0),
            "integrator": subid.StateSpace(np.diag([1.0, 0.9, 0.5, -0.3]), B, C, D, 1.0),
            "unobservable": subid.StateSpace(A, B, hidden, D, 1.0),
            "delay": subid.StateSpace(A, B, C, D, 1.0, info={"input_delay": [2, 0]}),
            "ct": ct}


@pytest.mark.parametrize("name", ["stable", "integrator", "unobservable", "delay", "ct"])
@pytest.mark.parametrize("kept", [10**9, 500])
def test_blocked_simulate_fit_equals_one_dense_least_squares(monkeypatch, name, kept):
    """simulate_fit in blocks (small blocks here, and with the free response kept or
    simulated again) gives the x0 and fitted output of one dense lstsq over the
    whole record, and fit_percent in blocks the direct NRMSE formula."""
    from subid.model import (
        fit,  # fit_percent
        prediction,  # simulate_fit
    )
    monkeypatch.setattr(fit, "_SIM_BLOCK", 97)
    monkeypatch.setattr(prediction, "_SIM_BLOCK", 97)
    monkeypatch.setattr(prediction, "_FREE_KEPT", kept)
    model = _models_for_blocks()[name]
    rng = np.random.default_rng(5)
    N = 1500
    u = rng.standard_normal((N, model.n_inputs))
    if model.dt > 0:
        y = model.simulate(u, x0=rng.standard_normal(model.order))
        data = subid.IOData(u, y + 0.05 * rng.standard_normal(y.shape), dt=1.0)
    else:
        t = np.cumsum(0.01 * (1 + 0.4 * rng.uniform(-1, 1, N)))
        y = model.simulate(u, t=t, x0=rng.standard_normal(model.order))
        data = subid.IOData(u, y + 0.05 * rng.standard_normal(y.shape), t=t)
    y_fit, x0 = prediction.simulate_fit(model, data)
    # with input delays the delay line's inputs before the record are estimated with the
    # state: the dense problem of the shift-register twin, its first n states returned
    twin = subid.absorb_delay(model) if model.dt > 0 else model
    y_ref, x0_ref = _simulate_fit_dense(twin, data)
    x0_ref = x0_ref[:model.order]
    assert np.abs(x0 - x0_ref).max() <= 1e-9 * max(np.abs(x0_ref).max(), 1.0)
    assert np.abs(y_fit - y_ref).max() <= 1e-10 * np.abs(y_ref).max()
    yn, yh = data.y / np.abs(data.y).max(axis=0), y_ref / np.abs(data.y).max(axis=0)
    direct = 100 * (1 - np.linalg.norm(yn - yh, axis=0)
                    / np.linalg.norm(yn - yn.mean(axis=0), axis=0))
    np.testing.assert_allclose(subid.fit_percent(model, data), direct, rtol=1e-9, atol=1e-9)
