"""Conversions of StateSpace models and what they carry (session 22, exploratory test of
the model): the time base of foreign systems, the hold as the default conversion method,
the info entries a conversion no longer matches, the step horizon of delayed and FIR
models, model files that load, and the covariance under a change of state basis."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.io
from scipy import signal

import subid
from subid import IOData, StateSpace
from subid.errors import ConversionWarning, DelayWarning, FileReadError, ModelError

A3 = np.array([[-1.0, 2, 0], [-2, -1, 0], [0, 0, -0.5]])
B3 = np.array([[0.3], [-1.0], [0.8]])
C3 = np.array([[1.0, 0.5, -0.7]])


def _foh_model(**kw):
    return StateSpace(A3, B3, C3, 0, 0, hold="foh", **kw)


# 1 ---------------------------------------------------------------------------------
def test_from_scipy_refuses_a_period_for_a_continuous_system():
    """scipy's dt None is continuous time: before, dt=0.1 read the matrices as discrete
    (pole -1 instead of exp(-0.1), DC gain 0.5 instead of 1)."""
    ct = signal.lti([[-1.0]], [[1.0]], [[1.0]], [[0.0]])
    with pytest.raises(ModelError, match=r"continuous-time.*to_discrete\(0\.1\)"):
        StateSpace.from_scipy(ct, dt=0.1)
    m = StateSpace.from_scipy(ct).to_discrete(0.1)
    assert m.poles()[0].real == pytest.approx(np.exp(-0.1))
    assert m.freqresp([0.0])[0, 0, 0].real == pytest.approx(1.0)


def test_from_control_refuses_a_period_for_a_continuous_system():
    control = pytest.importorskip("control")
    with pytest.raises(ModelError, match="continuous-time"):
        StateSpace.from_control(control.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]], 0), dt=0.1)
    # python-control's dt None is an unspecified time base, which dt may fix
    assert StateSpace.from_control(control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], None),
                                   dt=0.1).dt == 0.1


# 2 ---------------------------------------------------------------------------------
def test_conversions_default_to_the_models_hold():
    """Before, the default 'zoh' sampled a first-order-hold model with the wrong hold
    (fit 92.3 % on its own foh data instead of 100 %)."""
    ct = _foh_model()
    t = np.arange(200) * 0.2
    u = np.sin(0.7 * t)[:, None] + 0.3 * np.random.default_rng(0).standard_normal((200, 1))
    data = IOData(u, ct.simulate(u, t), dt=0.2)
    d = ct.to_discrete(0.2)
    assert d.hold == "foh" and d.allclose(ct.to_discrete(0.2, "foh"), rtol=0, atol=0)
    assert subid.fit_percent(d, data)[0] == pytest.approx(100.0, abs=1e-6)
    back = d.to_continuous()
    w = np.array([0.1, 1.0, 5.0])
    assert back.hold == "foh"
    np.testing.assert_allclose(back.freqresp(w), ct.freqresp(w), atol=1e-10)
    assert ct.to_discrete(0.2, "zoh").hold == "zoh"          # explicit method still wins


# 3 ---------------------------------------------------------------------------------
def test_fit_percent_passes_the_hold_to_a_finite_horizon():
    """A continuous-time model's k-step prediction is its simulation: it now uses the
    hold passed to fit_percent (before: the model's own, 79 % instead of 100 %)."""
    ct = _foh_model()
    t = np.arange(300) * 0.2
    u = np.random.default_rng(0).standard_normal((300, 1))
    data = IOData(u, ct.simulate(u, t, hold="zoh"), dt=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", subid.errors.NoiseModelWarning)
        fit = subid.fit_percent(ct, data, x0="zero", hold="zoh", steps=5)
        y = subid.predict(ct, data, 5, x0="zero", hold="zoh")
    assert fit[0] == pytest.approx(100.0, abs=1e-8)
    np.testing.assert_allclose(y, data.y, atol=1e-10)
    with pytest.raises(subid.errors.OptionError, match="hold"):
        subid.predict(ct, data, 5, hold="linear")


# 4 ---------------------------------------------------------------------------------
def test_step_horizon_covers_input_delays_and_poles_at_zero():
    """Before: 21 samples for both, all zero for the delay, 0.4 of 1.0 for the FIR."""
    m = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 0.1, info={"input_delay": [50]})
    t, y = m.step()
    assert t.size > 50 + 20 and y[-1, 0, 0] == pytest.approx(2.0, rel=1e-3)
    fir = StateSpace(np.eye(50, k=-1), np.eye(50, 1), 0.02 * np.ones((1, 50)), 0, 1.0)
    t, y = fir.step()
    assert t.size >= 51 and y[-1, 0, 0] == pytest.approx(1.0)
    t, y = fir.impulse()
    assert y[-1, 0, 0] == 0 and y[50, 0, 0] == pytest.approx(0.02)


# 5 ---------------------------------------------------------------------------------
def test_initial_state_kept_by_zoh_only():
    """The foh sampled state is x - Gamma2 u: a copied x0 simulated 0.098 off."""
    A = np.array([[-1.0, 2], [-2, -1]])
    ct = StateSpace(A, [[1.0], [0.5]], [[1.0, 0]], [[0.3]], 0, hold="foh",
                    info={"x0": np.array([1.0, -1.0])})
    t = np.arange(40) * 0.2
    u = np.cos(t)[:, None]
    d = ct.to_discrete(0.2, "zoh")
    np.testing.assert_allclose(d.simulate(u, x0=d.info["x0"]),
                               ct.simulate(u, t, x0=ct.info["x0"], hold="zoh"), atol=1e-12)
    for method in ("foh", "bilinear"):
        d = ct.to_discrete(0.2, method)
        assert "x0" not in d.info and method in d.info["dropped"]["x0"]
        assert "x0" not in d.to_continuous(method).info


# 6 ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def arx_model():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = subid.systems.simulate_data(subid.systems.seed001_system(), 800, seed=1,
                                           output_snr_db=25)
        return subid.arx(data, (2, 2, 1))


def test_conversions_drop_stale_polynomials(arx_model, tmp_path):
    """Before, a continuous-time model was written as the DT idpoly of the model it came
    from, and a delayed model's polynomials with the nk before the delays."""
    m = arx_model
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = m.to_continuous("bilinear")
    for key in ("polynomials", "orders", "parameter_covariance"):
        assert key not in c.info and "to_continuous" in c.info["dropped"][key]
    c.info["polynomials"] = m.info["polynomials"]            # even if put back by hand
    c.to_mat(tmp_path / "c.mat")
    v = scipy.io.loadmat(tmp_path / "c.mat")
    assert v["subid_format"][0] == "subid.StateSpace" and v["Ts"][0, 0] == 0
    np.testing.assert_array_equal(v["A"], c.A)
    md = StateSpace(m.A, m.B, m.C, m.D, 1.0, K=m.K, noise_cov=m.noise_cov,
                    info={**m.info, "input_delay": [3, 3]})
    a = subid.absorb_delay(md)
    assert "polynomials" not in a.info and "absorb_delay" in a.info["dropped"]["polynomials"]
    for write in (md.to_mat, lambda p: subid.interop.save_mat(md, p)):
        write(tmp_path / "d.mat")
        v = scipy.io.loadmat(tmp_path / "d.mat")
        assert v["subid_format"][0] == "subid.StateSpace" and v["A"].shape == (a.order,) * 2


# 7 ---------------------------------------------------------------------------------
def test_save_refuses_what_load_refuses(tmp_path, monkeypatch):
    m = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info={"seed": 2**64 - 1})
    with pytest.raises(ModelError, match=r"info\['seed'\].*64-bit.*str\(value\)"):
        m.save(tmp_path / "m.json")
    assert not (tmp_path / "m.json").exists()
    ids = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0,
                     info={"ids": np.array([1, 2**63], dtype=np.uint64)})
    with pytest.raises(ModelError, match=r"info\['ids'\] \(an array\)"):
        ids.save(tmp_path / "m.json")
    assert m.to_dict()["info"]["seed"] == 2**64 - 1         # a dictionary keeps it
    import subid.io.models as models
    monkeypatch.setattr(models, "MAX_MODEL_BYTES", 4000)
    big = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info={"big": np.zeros(1000)})
    with pytest.raises(ModelError, match=r"would be \d+ bytes.*'big'"):
        big.save(tmp_path / "big.json")
    assert not (tmp_path / "big.json").exists()
    (tmp_path / "huge.json").write_text(" " * 5000)
    with pytest.raises(FileReadError, match="not a subid model file") as info:
        StateSpace.load(tmp_path / "huge.json")
    assert "max_bytes" not in str(info.value)          # load has no such argument


# 8, 9 ------------------------------------------------------------------------------
def test_delay_warning_of_to_continuous_gives_advice_that_works():
    d = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 0.1, info={"input_delay": [3]})
    with pytest.warns(DelayWarning, match="no finite-dimensional.*bilinear"):
        c = d.to_continuous()
    assert c.info["dropped"]["input_delay"].startswith("to_continuous")
    approx = subid.absorb_delay(d).to_continuous("bilinear")   # the advice works
    assert approx.order == 4 and approx.is_stable()


def test_continuous_model_refuses_input_delays():
    """Before, the delay was accepted and ignored by simulate, freqresp and markov."""
    with pytest.raises(ModelError, match=r"input_delay.*discrete-time"):
        StateSpace([[-1.0]], [[1.0]], [[1.0]], 0, 0, info={"input_delay": [3]})
    assert StateSpace([[-1.0]], [[1.0]], [[1.0]], 0, 0, info={"input_delay": [0]}).order == 1


# 10 --------------------------------------------------------------------------------
def test_to_discrete_overflow_names_the_sampling_period():
    m = StateSpace([[10.0]], [[1.0]], [[1.0]], 0, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                       # no RuntimeWarning leaks
        with pytest.raises(ModelError, match="sampling period is too long"):
            m.to_discrete(100)
        assert m.to_discrete(0.1).poles()[0].real == pytest.approx(np.exp(1.0))


# 11 --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pem_model():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = subid.systems.simulate_innovation_data(
            subid.systems.seed001_innovation_system(), 800, seed=1)
        return subid.pem(data, subid.n4sid(data, 3, input_delay=1))


def test_absorb_delay_maps_the_parameter_covariance(pem_model):
    # the shift-register model's entries are the delayed model's, moved, or constants:
    # the covariance maps by a selection matrix, and the bands are the same (before, it
    # was dropped)
    w = np.linspace(0.1, 3, 5)
    absorbed = subid.absorb_delay(pem_model)
    assert absorbed.order == pem_model.order + 2 and "dropped" not in absorbed.info
    ref, got = subid.freqresp_bounds(pem_model, w), subid.freqresp_bounds(absorbed, w)
    np.testing.assert_allclose(got.std, ref.std, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(got.value, ref.value, rtol=1e-12, atol=1e-14)
    simulation = subid.pem(subid.systems.simulate_innovation_data(
        subid.systems.seed001_innovation_system(), 800, seed=1), pem_model,
        focus="simulation")                      # no K among the parameters
    ref = subid.freqresp_bounds(simulation, w)
    got = subid.freqresp_bounds(subid.absorb_delay(simulation), w)
    np.testing.assert_allclose(got.std, ref.std, rtol=1e-9, atol=1e-14)


def test_transform_maps_the_parameter_covariance(pem_model):
    m = pem_model
    w = np.linspace(0.1, 3, 5)
    T = np.array([[2.0, 0.3, 0], [0, 1, -0.5], [0.1, 0, 1.5]])
    ref = subid.freqresp_bounds(m, w)
    got = subid.freqresp_bounds(m.transform(T), w)
    np.testing.assert_allclose(got.std, ref.std, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(got.value, ref.value, rtol=1e-10)


def test_covariance_dropped_with_advice(pem_model):
    w = np.linspace(0.1, 3, 3)
    model = pem_model.with_noise_model()
    assert "parameter_covariance" in model.info["dropped"]
    with pytest.raises(ModelError, match=r"dropped.*subid\.pem"):
        subid.freqresp_bounds(model, w)
    # the same gain again keeps it
    same = pem_model.with_noise_model(pem_model.K, pem_model.noise_cov)
    assert "parameter_covariance" in same.info


# 12 --------------------------------------------------------------------------------
def test_exports_warn_about_a_first_order_hold():
    ct = _foh_model()
    with pytest.warns(ConversionWarning, match="first-order hold"):
        ct.to_scipy()
    control = pytest.importorskip("control")
    with pytest.warns(ConversionWarning, match="to_discrete"):
        ct.to_control()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = ct.to_discrete(0.2)
    with pytest.warns(ConversionWarning, match="to_continuous"):
        d.to_control()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        StateSpace(A3, B3, C3, 0, 0).to_control()            # zoh: nothing to say
    with pytest.raises(ModelError, match=r"static gain.*sys\.D"):
        StateSpace.from_control(control.tf(2, 1))


def test_from_control_mimo_transfer_function():
    control = pytest.importorskip("control")
    tf = control.tf([[[1], [1]], [[2], [1]]], [[[1, 1], [1, 2]], [[1, 3], [1, 4]]])
    try:
        ss = control.ss(tf)
    except NotImplementedError:
        with pytest.raises(ModelError, match=r"slycot.*control\.ss"):
            StateSpace.from_control(tf)
    else:                                                    # slycot is installed
        assert StateSpace.from_control(tf).order == ss.nstates


def test_dt_to_ct_with_foh_gives_the_continuous_initial_state():
    """to_continuous('foh') drops the sampled state; dt_to_ct computes x = xi + Gamma2 u
    from the data (before, it kept xi, which is not the continuous state)."""
    ct = _foh_model()
    t = np.arange(400) * 0.2
    u = np.sin(0.7 * t)[:, None] + 0.5 * np.random.default_rng(1).standard_normal((400, 1))
    data = IOData(u + 1.0, ct.simulate(u + 1.0, t, x0=[1.0, -2.0, 0.5]), dt=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = subid.dt_to_ct(data, 3, hold="foh")
    assert list(m.info)[:7][-2:] == ["x0", "hold"] and "dropped" not in m.info
    y = m.simulate(data, x0=m.info["x0"])
    np.testing.assert_allclose(y, data.y, atol=1e-6 * np.abs(data.y).max())


def test_convert_model_defaults_to_the_models_hold(tmp_path):
    """subid convert (convert_model) sampled a 'foh' model with 'zoh' by default."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        text = subid.interop.convert_model(_foh_model(), tmp_path / "d.json", "discrete",
                                           dt=0.2)
    d = StateSpace.load(tmp_path / "d.json")
    assert "(foh)" in text and d.hold == "foh"
    assert d.allclose(_foh_model().to_discrete(0.2, "foh"), rtol=0, atol=0)


def test_negative_eigenvalues_in_pairs_have_a_real_logarithm():
    """A_d = -0.5 I is exp(L h) for the real L = log(0.5)/h I + pi/h J (a mode at the
    Nyquist frequency); it was refused as having no real logarithm. A single negative
    eigenvalue still has none."""
    h = 0.1
    rng = np.random.default_rng(0)
    S = rng.standard_normal((4, 4))
    for diag in ([-0.5, -0.5], [-0.5, -0.5, 0.3, 0.8], [-0.5, -0.5, -0.2, -0.2]):
        k = len(diag)
        Ad = S[:k, :k] @ np.diag(diag) @ np.linalg.inv(S[:k, :k])
        d = StateSpace(Ad, rng.standard_normal((k, 2)), np.ones((1, k)), 0, h)
        for method in ("zoh", "foh"):
            back = d.to_continuous(method).to_discrete(h, method)
            assert back.allclose(d, rtol=1e-9, atol=1e-9)
    c = StateSpace(-0.5 * np.eye(2), np.eye(2), np.eye(2), 0, h).to_continuous()
    np.testing.assert_allclose(np.sort_complex(c.poles()),
                               np.log(0.5) / h + np.array([-1j, 1j]) * np.pi / h)
    odd = StateSpace(np.diag([-0.5, -0.5, -0.2]), np.ones((3, 1)), np.ones((1, 3)), 0, h)
    with pytest.raises(ModelError, match=r"-0\.5, -0\.5, -0\.2 on the negative real"):
        odd.to_continuous()


def test_a_bilinear_discretisation_converts_back_by_default():
    # to_discrete(dt, 'bilinear') left the model's hold at 'zoh', so to_continuous()
    # inverted a zero-order hold instead: 7.4e-3 off; it now inverts the bilinear map
    import subid
    ct = subid.systems.seed000_system()
    dt_model = ct.to_discrete(0.05, "bilinear")
    assert dt_model.info["discretisation"] == "bilinear"
    w = np.logspace(-2, 2, 50)
    back = dt_model.to_continuous()
    assert np.abs(back.freqresp(w) - ct.freqresp(w)).max() < 1e-10
    # an explicit method still wins
    assert not np.allclose(dt_model.to_continuous("zoh").A, back.A)
