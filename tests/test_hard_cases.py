"""Numerically hard cases: a finite model with diagnostics, or a clear error."""

import warnings

import numpy as np
import pytest
import scipy.linalg

import subid
from conftest import METHODS
from subid import errors, systems


def _finite(model):
    return all(np.isfinite(getattr(model, k)).all() for k in "ABCD")


def _run_all(data, order, **kw):
    """Every batch method: a finite model, or a subid error (never anything else)."""
    out = {}
    for name, fn in METHODS.items():
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = fn(data, order, **kw)
        except errors.SubidError as exc:
            out[name] = exc
            continue
        assert _finite(model), name
        assert "input_condition" in model.info
        out[name] = model
    return out


def test_stiff_continuous_plant_sampled():
    """Time constants from 1e-3 s to 1e3 s, sampled at 1 ms."""
    A = np.diag([-1e3, -1.0, -1e-3])
    ct = subid.StateSpace(A, [[1e3], [1.0], [1e-3]], [[1.0, 1.0, 1.0]], [[0.0]], 0)
    dt_model = ct.to_discrete(1e-3)
    data = systems.simulate_data(dt_model, 20_000, seed=0)
    for name, res in _run_all(data, 3, horizon=8).items():
        assert not isinstance(res, Exception), (name, res)
        assert subid.markov_error(res, dt_model, k=50) < 1e-6, name


def test_lightly_damped_modes():
    poles = 0.9995 * np.exp(1j * np.array([0.05, 0.8, 2.0]))
    blocks = [np.array([[p.real, p.imag], [-p.imag, p.real]]) for p in poles]
    A = scipy.linalg.block_diag(*blocks)
    r = np.random.default_rng(1)
    true = subid.StateSpace(A, r.standard_normal((6, 1)), r.standard_normal((1, 6)), [[0.0]], 1.0)
    data = systems.simulate_data(true, 8000, seed=2)
    for name, res in _run_all(data, 6, horizon=10).items():
        assert not isinstance(res, Exception), (name, res)
        assert subid.pole_error(res, true) < 1e-6, name


@pytest.mark.slow
def test_high_order_twenty():
    true = systems.random_system(20, 2, 2, seed=4, min_hsv_ratio=1e-5)
    data = systems.simulate_data(true, 20_000, seed=5)
    for name, res in _run_all(data, 20).items():
        if isinstance(res, Exception):
            assert isinstance(res, errors.SubidError)
            continue
        assert subid.markov_error(res, true, k=40) < 1e-5, name


def test_nearly_unobservable_mode():
    """A mode seen with gain 1e-9: identify the observable part at order 2
    (exactly, up to that gain), or at order 3 get a finite model or an error."""
    A = np.diag([0.9, 0.5, -0.3])
    true = subid.StateSpace(A, [[1.0], [1.0], [1.0]], [[1.0, 1.0, 1e-9]], [[0.0]], 1.0)
    data = systems.simulate_data(true, 3000, seed=6)
    for name, res in _run_all(data, 2).items():
        assert not isinstance(res, Exception), (name, res)
        assert subid.markov_error(res, true) < 1e-7, name
    _run_all(data, 3)                    # finite or a clear error, checked inside


def test_nearly_uncontrollable_mode():
    A = np.diag([0.9, 0.5, -0.3])
    true = subid.StateSpace(A, [[1.0], [1.0], [1e-9]], [[1.0, 1.0, 1.0]], [[0.2]], 1.0)
    data = systems.simulate_data(true, 3000, seed=7)
    for name, res in _run_all(data, 2).items():
        assert not isinstance(res, Exception), (name, res)
        assert subid.markov_error(res, true) < 1e-7, name


@pytest.mark.slow
def test_tiny_and_huge_signal_scales():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 2000, seed=8)
    for scale in (1e-12, 1e12):
        scaled = subid.IOData(data.u * scale, data.y / scale)
        expected = subid.StateSpace(true.A, true.B / scale, true.C / scale,
                                    true.D / scale ** 2, 1.0)
        for name, res in _run_all(scaled, 3).items():
            assert not isinstance(res, Exception), (name, res)
            assert subid.markov_error(res, expected) < 1e-8, (name, scale)


@pytest.mark.long
def test_million_samples_every_method():
    true = systems.random_system(4, 2, 2, seed=9)
    data = systems.simulate_data(true, 1_000_000, seed=10, output_snr_db=30)
    for name, res in _run_all(data, 4).items():
        assert not isinstance(res, Exception), (name, res)
        assert subid.markov_error(res, true) < 0.01, name


@pytest.mark.slow
def test_stiff_plant_continuous_time_methods():
    """Time constants 1e-3 s to 1e3 s, 20 s of data at 1 ms: the slowest mode
    cannot be seen; both continuous-time methods return a finite model (or a
    clear error), never NaN or a crash."""
    A = np.diag([-1e3, -1.0, -1e-3])
    ct = subid.StateSpace(A, [[1e3], [1.0], [1e-3]], [[1.0, 1.0, 1.0]], [[0.0]], 0)
    t = np.arange(20_000) * 1e-3
    u = np.sin(np.outer(t, np.logspace(-1, 2.5, 12))).sum(axis=1)
    data = subid.IOData(u, ct.simulate(u, t=t, hold="foh"), t=t)
    for fit in (lambda d: subid.ct_subspace(d, 3), lambda d: subid.ct_subspace(d, 2)):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = fit(data)
        except errors.SubidError:
            continue
        assert _finite(model)
    ai = subid.AdaptiveIdentifier(3, 1, 1, dt=1e-3)
    ai.update(data.u, data.y)
    assert _finite(ai.model)


@pytest.mark.parametrize("method", [subid.moesp, subid.ls_subspace, subid.n4sid,
                                    subid.identify])
def test_records_too_short_for_the_folds_use_the_whole_record(method):
    """A record whose cross-validation folds are too short for the horizon the order
    needs (20 samples, order 1; 30 samples, order 2: the folds allow horizon 2 only)
    takes the order or horizon from the whole record's singular values, says so in
    info['order_selection']['reason'], and is reproduced by passing the choice back;
    before, the default call raised an error about a fold's length ("10 samples are too
    few for horizon 2 ... reduce the horizon") that the user had not chosen."""
    true = subid.systems.random_system(2, 1, 1, seed=3)
    for n_samples, order in ((20, 1), (20, None), (30, 2)):
        data = subid.systems.simulate_data(true, n_samples, seed=1, output_snr_db=40)
        model = method(data, order)
        reason = model.info["order_selection"]["reason"]
        assert f"record ({n_samples} samples) is too short" in reason
        assert subid.fit_percent(model, data).mean() > 90
        again = method(data, model.order, horizon=model.info["horizon"])
        np.testing.assert_allclose(again.freqresp([0.1, 1.0]), model.freqresp([0.1, 1.0]),
                                   rtol=1e-9, atol=1e-12)
    tiny = subid.systems.simulate_data(true, 8, seed=1)
    with pytest.raises(subid.errors.SubidError, match="8 samples"):
        method(tiny)


def test_a_step_late_in_the_record_is_not_called_a_zero_input():
    """A step at sample 700 of 1400: the first cross-validation fold's input is all
    zero, and the default call raised "the input is identically zero ... needs order 20"
    about the whole record. The folds are then skipped for the whole record's singular
    values (info['order_selection']['reason']); the step response is fitted."""
    true = systems.random_system(3, 1, 1, seed=40, pole_radius=(0.5, 0.9))
    u = np.zeros(1400)
    u[700:] = 1.0
    y = true.simulate(u).reshape(-1) + 0.01 * np.random.default_rng(0).standard_normal(1400)
    data = subid.IOData(u, y)
    for method in (subid.moesp, subid.identify):
        model = method(data)
        assert "poorly excited" in model.info["order_selection"]["reason"]
        assert subid.fit_percent(model, data).mean() > 95
