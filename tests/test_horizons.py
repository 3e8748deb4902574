"""Horizons past 20 on oversampled records (subid.methods.crossval.longer_horizon)."""

from __future__ import annotations

import numpy as np
import pytest

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


def test_output_memory_tells_white_from_slow_and_oscillating_outputs():
    rng = np.random.default_rng(0)
    N = 5000
    white = subid.IOData(rng.standard_normal((N, 1)), rng.standard_normal((N, 2)))
    assert crossval.output_memory(white, 20) < 0.1          # |rho| ~ 1/sqrt(N)
    e = rng.standard_normal(N)
    slow = np.zeros(N)
    for t in range(1, N):                                     # AR(1), pole 0.995
        slow[t] = 0.995 * slow[t - 1] + e[t]
    assert crossval.output_memory(subid.IOData(e, slow), 20) > 0.8
    # a lightly damped oscillation of period 40 crosses zero at lags 30, 50, ...: judged
    # by its envelope over lags 20..39 (|rho(20)| = 1 at the half period)
    t = np.arange(N)
    ring = np.cos(2 * np.pi * t / 40) + 0.05 * rng.standard_normal(N)
    assert crossval.output_memory(subid.IOData(e, ring), 10) > 0.9
    # several experiments: no product across the border (the same as each alone)
    one = subid.IOData(e[:2500], slow[:2500])
    assert crossval.output_memory(subid.merge([one, one]), 20) == \
        pytest.approx(crossval.output_memory(one, 20), rel=1e-12)


def test_longer_horizon_rules():
    rng = np.random.default_rng(1)
    e = rng.standard_normal(20_000)
    slow = np.convolve(e, np.ones(400) / 400, mode="same")   # remembers ~400 samples
    data = subid.IOData(e, slow)
    args = (20_000, 1, 1, 2)
    assert crossval.longer_horizon(data, 10, 20, *args) == 40    # 10 chosen: still tried
    assert crossval.longer_horizon(data, 40, 40, *args) == 80    # the doubled one chosen
    assert crossval.longer_horizon(data, 20, 40, *args) is None  # the doubled one lost
    assert crossval.longer_horizon(data, 160, 160, *args) is None   # past MAX_HORIZON
    assert crossval.longer_horizon(data, 20, 20, 300, 1, 1, 2) is None   # too few columns
    white = subid.IOData(e, rng.standard_normal(20_000))
    assert crossval.longer_horizon(white, 20, 20, *args) is None  # forgets within 20


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
