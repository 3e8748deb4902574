"""Input delays: subid.estimate_delay (MATLAB delayest), the input_delay option
of the discrete-time batch methods, and models that carry delays."""

import numpy as np
import pytest

import subid
from subid.errors import DataError, ModelError, NotExcitingError, TooFewSamplesError


def _with_delay(model, delays):
    m = subid.StateSpace(model.A, model.B, model.C, model.D, model.dt, info={})
    m.info["input_delay"] = list(delays)
    return m


def test_simulate_with_delay_equals_shift_register_model():
    # two independent computations: the shifted input, and delays as states
    true = _with_delay(subid.systems.seed001_system(), [2, 5])
    big = subid.absorb_delay(true)
    assert big.order == 3 + 7 and "input_delay" not in big.info
    u = np.random.default_rng(0).standard_normal((200, 2))
    np.testing.assert_allclose(true.simulate(u), big.simulate(u), rtol=0, atol=1e-12)
    w = np.linspace(0.01, np.pi, 50)
    np.testing.assert_allclose(true.freqresp(w), big.freqresp(w), rtol=1e-10, atol=1e-12)
    # the delay really acts: input 2 has no effect before sample 5
    u2 = np.zeros((40, 2))
    u2[0, 1] = 1.0
    y = true.simulate(u2)
    assert np.all(y[:5] == 0)
    np.testing.assert_array_equal(y[5], true.D[:, 1])      # feedthrough at the delayed sample
    assert np.any(y[6:] != 0)


def test_delay_with_feedthrough_absorbs_into_c():
    sys = subid.systems.random_system(3, 2, 1, seed=4, feedthrough=True)
    true = _with_delay(sys, [0, 3])
    u = np.random.default_rng(1).standard_normal((100, 2))
    np.testing.assert_allclose(true.simulate(u), subid.absorb_delay(true).simulate(u),
                               atol=1e-12)


def _strictly_proper():
    s = subid.systems.seed001_system()
    return subid.StateSpace(s.A, s.B, s.C, 0, s.dt)


def _delayed_record(delays, n=2000, seed=0, snr=None):
    true = _with_delay(_strictly_proper(), delays)
    big = subid.absorb_delay(true)
    data = subid.systems.simulate_data(big, n, seed=seed, output_snr_db=snr)
    return true, data


@pytest.mark.parametrize("method", ["ls_subspace", "moesp", "n4sid"])
def test_batch_methods_recover_a_delayed_system_exactly(method):
    true, data = _delayed_record([1, 3])
    model = getattr(subid, method)(data, 3, input_delay=[1, 3])
    assert model.order == 3 and model.info["input_delay"] == [1, 3]
    assert subid.markov_error(model, true) < 1e-8      # Markov parameters honour the delays
    # simulate honours the delay: the whole record reproduced from rest
    np.testing.assert_allclose(model.simulate(data.u), data.y, atol=1e-6)
    # ... and a model saved and loaded keeps it
    again = subid.StateSpace.from_dict(model.to_dict())
    assert again.info["input_delay"] == [1, 3]
    # without the delay option the same order cannot explain the data
    plain = getattr(subid, method)(data, 3)
    assert subid.fit_percent(plain, data).min() < 99


def test_delay_inputs_shifts_without_inventing_samples():
    u = np.arange(10.0).reshape(-1, 1) * [1, 10]
    y = np.arange(10.0) + 100
    data = subid.IOData(u, y, dt=0.5)
    out, d = subid.delay_inputs(data, [1, 3])
    assert d.tolist() == [1, 3] and out.n_samples == 7
    np.testing.assert_array_equal(out.u[:, 0], np.arange(2, 9))      # u1[k-1]
    np.testing.assert_array_equal(out.u[:, 1], np.arange(0, 7) * 10)  # u2[k-3]
    np.testing.assert_array_equal(out.y[:, 0], np.arange(3, 10) + 100)
    assert out.t[0] == 1.5 and out.dt == 0.5
    same, d0 = subid.delay_inputs(data, 0)
    assert same is data and d0.tolist() == [0, 0]


@pytest.mark.parametrize("bad, message", [
    (-1, ">= 0"), ([1, 2, 3], "3 entries"), (1.5, "non-negative integer"),
    (True, "non-negative integer"), ("2", "non-negative integer")])
def test_bad_input_delay_is_an_error(bad, message):
    data = subid.IOData(np.ones((50, 2)), np.ones(50))
    with pytest.raises(DataError, match=message):
        subid.delay_inputs(data, bad)


def test_input_delay_on_a_statistic_or_nonuniform_record_is_an_error():
    true, data = _delayed_record([0, 0], n=400)
    stat = subid.HankelStatistic.from_data(data, depth=10)
    with pytest.raises(DataError, match="IOData"):
        subid.ls_subspace(stat, 3, horizon=5, input_delay=2)
    nonuni = subid.IOData(data.u[:50], data.y[:50], t=np.cumsum(np.linspace(1, 2, 50)))
    with pytest.raises(DataError, match="uniformly sampled"):
        subid.delay_inputs(nonuni, 1)
    with pytest.raises(DataError, match="uniformly sampled"):
        subid.estimate_delay(nonuni)
    with pytest.raises(TooFewSamplesError):
        subid.estimate_delay(data[:30], max_delay=10)


def test_estimate_delay_noise_free_counts_like_delayest():
    # strictly proper (D = 0): nk = 1 + extra delay
    _, data = _delayed_record([0, 4], n=1500)
    assert subid.estimate_delay(data).tolist() == [1, 5]
    # feedthrough (seed 001's D has no zero column): nk = extra delay
    true = _with_delay(subid.systems.seed001_system(), [3, 0])
    data = subid.systems.simulate_data(subid.absorb_delay(true), 1000, seed=5)
    nk, loss = subid.estimate_delay(data, max_delay=8, return_loss=True)
    assert nk.tolist() == [3, 0] and loss.shape == (2, 9)


def test_estimate_delay_monte_carlo_noisy():
    """Seeded Monte Carlo at 0 dB output SNR (noise as strong as the output),
    1000 samples, random delays 0..6 on both inputs: both found in at least
    95 % of 40 runs (40 of 40 when written)."""
    rng = np.random.default_rng(2026)
    hits, runs = 0, 40
    for run in range(runs):
        d = rng.integers(0, 7, size=2)
        _, data = _delayed_record(d.tolist(), n=1000, seed=run, snr=0)
        hits += subid.estimate_delay(data, max_delay=10).tolist() == (d + 1).tolist()
    assert hits >= 0.95 * runs, hits


def test_estimate_delay_folds_its_regression_a_block_at_a_time(monkeypatch):
    """REGRESSION_BYTES small enough for blocks of 83 rows (two experiments, the second
    shorter than a block): the same losses as the regression factored whole, to
    rounding, and the same delays."""
    from subid import delay
    parts = [_delayed_record([1, 3], n=n, seed=s, snr=10)[1] for n, s in ((700, 1), (60, 2))]
    data = subid.merge(parts)
    nk, whole = subid.estimate_delay(data, max_delay=6, return_loss=True)
    width = 2 * 2 + 2 * (6 + 2) + 2                 # past outputs, input lags, targets
    monkeypatch.setattr(delay, "REGRESSION_BYTES", 8 * width * 83)
    nk_blocks, blocks = subid.estimate_delay(data, max_delay=6, return_loss=True)
    np.testing.assert_allclose(blocks, whole, rtol=1e-10)
    assert nk_blocks.tolist() == nk.tolist() == [2, 4]


def test_models_with_bad_recorded_delay_are_an_error():
    m = _with_delay(subid.systems.seed001_system(), [1])
    with pytest.raises(ModelError, match="2 inputs"):
        m.simulate(np.zeros((10, 2)))


def test_delays_in_markov_exports_and_conversions():
    """Markov parameters, control/scipy exports honour the delays (as states); a change of
    sampling drops them with a warning instead of keeping a wrong count of samples."""
    import warnings
    true = subid.systems.seed001_system()
    d = subid.systems.simulate_data(true, 800, seed=3)
    m = subid.moesp(d, 3, horizon=5, input_delay=[1, 3])
    a = subid.absorb_delay(m)
    np.testing.assert_allclose(m.markov(12), a.markov(12), atol=1e-12)
    assert m.to_scipy().A.shape == (a.order, a.order)
    with pytest.warns(subid.errors.DelayWarning, match="drops the input delays"):
        c = m.to_continuous("bilinear")
    assert "input_delay" not in c.info and "input_delay" in c.info["dropped"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same = m.transform(np.eye(3) * 2.0)          # same sampling: the delays stay
    assert same.info["input_delay"] == [1, 3]


def test_absorb_delay_keeps_the_noise_model_and_the_initial_state():
    """absorb_delay carries K (zero rows for the registers), noise_cov and info['x0']
    (zeros for the registers): one-step predictions and the simulation from
    info['x0'] are those of the delayed model; before, K was dropped and predict
    silently became a simulation."""
    true = subid.systems.random_system(2, 2, 1, seed=4, feedthrough=False)
    rng = np.random.default_rng(5)
    u = rng.normal(size=(1500, 2))
    ud = u.copy()
    ud[3:, 0], ud[:3, 0] = u[:-3, 0], 0.0
    y = true.simulate(ud)
    data = subid.IOData(u, y + 0.1 * np.std(y) * rng.normal(size=y.shape))
    model = subid.moesp(data, 2, input_delay=[3, 0])
    absorbed = subid.absorb_delay(model)
    assert absorbed.order == 5 and absorbed.K is not None
    np.testing.assert_array_equal(absorbed.noise_cov, model.noise_cov)
    np.testing.assert_allclose(subid.predict(absorbed, data, 1, x0=absorbed.info["x0"]),
                               subid.predict(model, data, 1, x0=model.info["x0"]),
                               atol=1e-10)
    np.testing.assert_allclose(absorbed.simulate(data, x0=absorbed.info["x0"]),
                               model.simulate(data, x0=model.info["x0"]), atol=1e-10)


@pytest.mark.parametrize("su,sy", [(1.0, 1e155), (1.0, 1e-20), (1e20, 1.0), (1e-20, 1e300),
                                   (1e155, 1e-155)])
def test_estimate_delay_does_not_depend_on_units(su, sy):
    dryer = subid.datasets.load("dryer")
    assert subid.estimate_delay(dryer).tolist() == [3]
    assert subid.estimate_delay(subid.IOData(dryer.u * su, dryer.y * sy)).tolist() == [3]


@pytest.mark.parametrize("level", [0.0, 1.0])
def test_estimate_delay_refuses_a_constant_input(level):
    d = subid.systems.simulate_data(subid.systems.seed001_system(), 300, seed=3)
    with pytest.raises(NotExcitingError, match="input 'u1' is constant"):
        subid.estimate_delay(subid.IOData(np.full(300, level), d.y[:, 0]))


def test_absorb_delay_refuses_a_record():
    d = subid.IOData(np.arange(5.0), np.arange(5.0))
    with pytest.raises(ModelError, match="absorb_delay takes a subid.StateSpace model, got "
                                         "IOData"):
        subid.absorb_delay(d)


def _delayed_plant():
    A = np.array([[1.5, -0.7], [1.0, 0.0]])
    return subid.StateSpace(A, np.array([[1.0], [0.0]]), np.array([[0.5, 0.3]]),
                            np.zeros((1, 1)), dt=0.1, info={"input_delay": [3]})


def test_estimated_initial_state_includes_the_delay_line():
    # a validation record split from a longer one does not start at rest: the inputs in
    # the delay line before it are as unknown as the state, and x0='estimate' estimates
    # them (zero-filled, the true model fitted 98.37 % against its shift-register twin's
    # 99.56 %, and its one-step residuals failed the whiteness test)
    true = _delayed_plant()
    rng = np.random.default_rng(0)
    u = rng.standard_normal((2000, 1))
    y = true.simulate(u) + 0.01 * rng.standard_normal((2000, 1))
    _, val = subid.IOData(u, y, dt=0.1).split(0.7)
    twin = subid.absorb_delay(true)
    np.testing.assert_allclose(subid.fit_percent(true, val), subid.fit_percent(twin, val),
                               rtol=0, atol=1e-9)
    assert subid.fit_percent(true, val)[0] > 99.5
    with_k = true.with_noise_model(np.zeros((2, 1)), np.eye(1) * 1e-4)
    twin_k = subid.absorb_delay(with_k)
    np.testing.assert_allclose(subid.predict(with_k, val), subid.predict(twin_k, val),
                               rtol=0, atol=1e-9)
    _, x0 = subid.predict(with_k, val, return_x0=True)
    assert x0.shape == (2,)                   # the model's own state, not the registers
    # a given x0 still takes the delay line as zero
    zero = subid.fit_percent(true, val, x0=np.zeros(2))[0]
    assert zero < subid.fit_percent(true, val)[0]


@pytest.mark.parametrize("method", ["moesp", "n4sid"])
def test_identified_initial_state_is_at_the_first_sample_of_the_record(method):
    # input_delay= fits the shifted record, whose first sample is sample max(d): its x0
    # was the state there, and fit_percent(m, data, x0=m.info['x0']) fitted 85.5 %
    true = _delayed_plant()
    rng = np.random.default_rng(0)
    u = rng.standard_normal((2000, 1))
    y = true.simulate(u, x0=[5.0, -3.0]) + 0.01 * rng.standard_normal((2000, 1))
    data = subid.IOData(u, y, dt=0.1)
    m = getattr(subid, method)(data, 2, input_delay=3)
    given = subid.fit_percent(m, data, x0=m.info["x0"])[0]
    assert abs(given - subid.fit_percent(m, data)[0]) < 0.05
    refined = subid.pem(data, m)
    assert abs(subid.fit_percent(refined, data, x0=refined.info["x0"], steps=1)[0]
               - subid.fit_percent(refined, data, steps=1)[0]) < 0.05
