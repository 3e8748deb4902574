"""Issue 10: what the default call returns (order, horizon, weighting, B/D, stability)."""

import warnings

import numpy as np
import pytest

import subid
from subid import errors, systems

METHODS = [subid.ls_subspace, subid.moesp, subid.n4sid]


def _split(name):
    data = subid.datasets.load(name)
    cut = 2 * data.n_samples // 3
    est, val = data[:cut], data[cut:]
    mu, my = est.u.mean(axis=0), est.y.mean(axis=0)
    return (subid.IOData(est.u - mu, est.y - my, dt=est.dt),
            subid.IOData(val.u - mu, val.y - my, dt=val.dt))


@pytest.fixture(scope="module")
def noisy():
    true = systems.random_system(4, 2, 2, seed=7)
    return true, systems.simulate_data(true, 3000, seed=8, process_snr_db=20, output_snr_db=20)


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
@pytest.mark.slow
def test_chosen_model_is_reproduced_by_an_explicit_call(method, noisy):
    """method(data, order=model.order, horizon=model.info['horizon']) is the same model."""
    _, data = noisy
    auto = method(data)
    again = method(data, order=auto.order, horizon=auto.info["horizon"])
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(auto, name), getattr(again, name))
    given = method(data, order=auto.order)            # horizon chosen again: the same one
    assert given.info["horizon"] == auto.info["horizon"]
    np.testing.assert_array_equal(given.A, auto.A)


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
@pytest.mark.slow
def test_order_selection_record(method, noisy):
    _, data = noisy
    model = method(data)
    record = model.info["order_selection"]
    assert record["rule"] == "cv"
    orders = {c["order"] for c in record["candidates"]}
    assert orders == set(range(1, 11))
    assert all(np.isfinite(c["score"]) and len(c["folds"]) == 4 for c in record["candidates"])
    assert record["selected"]["order"] == model.order == 4
    gap = method(data, selection="gap")
    assert gap.info["order_selection"]["rule"] == "gap"
    assert all("score" in c for c in gap.info["order_selection"]["candidates"])
    with pytest.raises(errors.SubidError, match="selection must be one of"):
        method(data, selection="aic")


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
def test_output_units_do_not_change_the_fit(method):
    """Rescaling one output by 1e4 leaves the validation fit unchanged."""
    est, val = _split("steamgen")
    scale = np.array([1.0, 1e4, 1.0, 1.0])
    est2 = subid.IOData(est.u, est.y * scale, dt=est.dt)
    val2 = subid.IOData(val.u, val.y * scale, dt=val.dt)
    fit1 = subid.fit_percent(method(est, 4, horizon=10), val)
    fit2 = subid.fit_percent(method(est2, 4, horizon=10), val2)
    np.testing.assert_allclose(fit1, fit2, atol=1e-6)


@pytest.mark.parametrize("weighting", ["moesp", "cva", "n4sid"])
@pytest.mark.parametrize("method", [subid.moesp, subid.n4sid], ids=lambda m: m.__name__)
def test_weightings_exact_on_noise_free_data(method, weighting):
    true = systems.seed001_system()
    data = systems.simulate_data(true, 800, seed=3)
    model = method(data, 3, weighting=weighting)
    assert subid.markov_error(model, true) < 1e-9
    assert model.info["weighting"] == weighting
    with pytest.raises(errors.SubidError, match="N4Weight"):
        method(data, 3, weighting="ssarx")


def test_stability_auto_enforce_none():
    """Classical N4SID at order 7 on robot_arm is unstable; 'auto' and 'enforce' fix it."""
    est, val = _split("robot_arm")
    options = dict(horizon=10, weighting="n4sid")
    with pytest.warns(errors.UnstableModelWarning):
        raw = subid.n4sid(est, 7, stability="none", **options)
    assert not raw.is_stable()
    for stability in ("auto", "enforce"):
        model = subid.n4sid(est, 7, stability=stability, **options)
        record = model.info["stability"]
        assert model.is_stable() and record["action"] == "enforced"
        assert record["spectral_radius_before"] > 1 > record["spectral_radius_after"]
        assert subid.fit_percent(model, val).mean() > 80
    with pytest.raises(errors.SubidError, match="stability must be one of"):
        subid.n4sid(est, 7, stability="yes", **options)


def test_unstable_plant_keeps_unstable_model():
    """ballbeam (an unstable plant under feedback): 'auto' keeps the unstable model the
    estimation data demand, because it explains them far better than a stabilised one."""
    est, val = _split("ballbeam")
    model = subid.moesp(est, 3, horizon=20)
    record = model.info["stability"]
    assert record["action"] == "kept unstable" and not model.is_stable()
    assert record["residual_unstable"] < 0.9 * record["residual_stable"]
    forced = subid.moesp(est, 3, horizon=20, stability="enforce")
    assert forced.is_stable()
    assert subid.fit_percent(model, val).mean() > subid.fit_percent(forced, val).mean() + 10


@pytest.mark.parametrize("method", [subid.moesp, subid.n4sid, subid.pbsid])
def test_auto_keeps_an_unstable_pole_the_data_demand(method):
    """A plant with a pole at 1.01, 400 samples, 1 % output noise (its output grows 1.8x
    over the record around its mean: below the growth limit, so 'auto' compares both
    fits): every subspace method keeps the unstable model, whose fit is 99 %. PBSID,
    whose B and K come from the state equation, compares the simulations of both
    (before, it always reflected the pole: fit -65 %)."""
    rng = np.random.default_rng(0)
    true = subid.StateSpace(np.diag([1.01, 0.5]), [[0.5], [1.0]], [[1.0, 1.0]], [[0.0]], 1.0)
    u = rng.normal(size=400)
    y = true.simulate(u)
    data = subid.IOData(u, y + 0.01 * np.std(y) * rng.normal(size=y.shape))
    model = method(data, 2)
    record = model.info["stability"]
    assert record["action"] == "kept unstable" and not model.is_stable()
    assert record["residual_unstable"] < 0.1 * record["residual_stable"]
    assert subid.fit_percent(model, data).mean() > 98


def test_enforce_on_growing_data_warns():
    """An unstable plant whose output grows: 'enforce' warns, 'auto' keeps it unstable."""
    A = np.array([[1.005, 0.1], [0.0, 0.8]])
    true = subid.StateSpace(A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]),
                            np.zeros((1, 1)), 1.0)
    u = np.random.default_rng(0).standard_normal(2000)
    data = subid.IOData(u, true.simulate(u))
    with pytest.warns(errors.UnstableModelWarning, match="grows"):
        forced = subid.moesp(data, 2, horizon=10, stability="enforce")
    assert forced.is_stable()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = subid.moesp(data, 2, horizon=10)
    # compared with its stabilised model, which cannot follow the growth (session 24:
    # growing data no longer skip the comparison)
    assert model.info["stability"]["action"] == "kept unstable"
    assert model.info["stability"]["residual_unstable"] < \
        1e-6 * model.info["stability"]["residual_stable"]
    assert subid.markov_error(model, true) < 1e-6


def _coloured_record(k):
    """Random stable system (seeded), AR(0.9) input, 20 dB output noise."""
    rng = np.random.default_rng(900 + k)
    order, nu, ny = int(rng.integers(1, 7)), int(rng.integers(1, 3)), int(rng.integers(1, 3))
    true = systems.random_system(order, nu, ny, seed=k)
    e = rng.standard_normal((3000, nu))
    u = np.zeros_like(e)
    for t in range(1, e.shape[0]):
        u[t] = 0.9 * u[t - 1] + e[t]
    y0 = true.simulate(u)
    noise = rng.standard_normal(y0.shape) * y0.std(axis=0) * 10 ** (-20 / 20)
    data = subid.IOData(u, y0 + noise)
    return true, order, data[:2000], data[2000:]


@pytest.mark.long
def test_random_systems_20db_coloured_input():
    """50 random stable systems, 20 dB, AR(0.9) inputs, the true order given: no default
    model overflows in simulation and every method's median validation fit is within
    1 point of the best method's."""
    fits = {m.__name__: [] for m in METHODS}
    for k in range(50):
        _, order, est, val = _coloured_record(k)
        for method in METHODS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = method(est, order)
            assert model.is_stable(), (k, method.__name__)
            fits[method.__name__].append(subid.fit_percent(model, val).mean())
    medians = {k: float(np.median(v)) for k, v in fits.items()}
    assert min(medians.values()) >= max(medians.values()) - 1.0, medians


def test_order_beyond_every_default_horizon_is_named():
    data = systems.simulate_data(systems.random_system(2, 1, 1, seed=1), 3000, seed=1)
    with pytest.raises(errors.OrderError, match="horizon >= 26"):
        subid.moesp(data, 25)
    model = subid.moesp(data, 25, horizon=26, selection="gap", stability="none")
    assert model.order == 25 and model.info["horizon"] == 26


# --- issue 10, remaining records: B, D of an unstable A, the state-sequence estimate ---

def _unstable_closed_loop(seed=3, n_samples=1500):
    """An unstable SISO plant (pole 1.02) under proportional feedback, measured with noise:
    the output does not grow, the plant model must stay unstable."""
    rng = np.random.default_rng(seed)
    a = np.array([[1.02, 0.1], [0.0, 0.6]])
    b = np.array([0.0, 1.0])
    c = np.array([1.0, 0.0])
    x = np.zeros(2)
    r = rng.standard_normal(n_samples)
    u, y = np.empty(n_samples), np.empty(n_samples)
    for k in range(n_samples):
        y[k] = c @ x + 0.05 * rng.standard_normal()
        u[k] = r[k] - 0.8 * y[k]
        x = a @ x + b * u[k] + 0.02 * rng.standard_normal(2)
    return subid.IOData(u[:, None], y[:, None], dt=1.0)


def test_prediction_form_b_d_agrees_with_a_direct_regression():
    """The 'prediction' route (b_d_refit) solves the predictor regression; checked against
    regressors built column by column by simulating the predictor (an independent
    computation)."""
    from subid.methods.dt._subspace import b_d_refit, prepare
    from subid.methods.dt.noise_model import innovation_model, user_factor
    data = _unstable_closed_loop()
    pb = prepare(data, 2, 10, method="moesp")
    model = subid.moesp(data, 2, horizon=10, stability="none", system_matrices="shift")
    A, C = model.A, model.C
    B0, D0 = np.ones((2, 1)), np.zeros((1, 1))
    got = b_d_refit(pb, C, feedthrough=True, estimate_x0=True)(A, (B0, D0, None, {}))
    assert got is not None
    B, D, x0, diag = got
    assert diag["bd_method"] == "prediction" and diag["predictor_spectral_radius"] < 1
    K = innovation_model(A, B0, C, D0, user_factor(pb))[0]
    Ab = A - K @ C
    N = data.n_samples
    u, y = data.u[:, 0], data.y[:, 0]

    def run(x0_, b_, d_, drive_y):
        x, out = x0_.copy(), np.empty(N)
        for k in range(N):
            out[k] = C[0] @ x + d_ * u[k]
            x = Ab @ x + b_ * u[k] + (K[:, 0] * y[k] if drive_y else 0.0)
        return out
    base = run(np.zeros(2), np.zeros(2), 0.0, True)
    cols = [run(e, np.zeros(2), 0.0, False) for e in np.eye(2)]          # x0
    cols += [run(np.zeros(2), e, 0.0, False) for e in np.eye(2)]         # B - K D
    cols += [run(np.zeros(2), np.zeros(2), 1.0, False)]                  # D
    theta = np.linalg.lstsq(np.column_stack(cols), y - base, rcond=None)[0]
    np.testing.assert_allclose(x0, theta[:2], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(D[:, 0], theta[4:], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(B[:, 0], theta[2:4] + K[:, 0] * theta[4], rtol=1e-6, atol=1e-9)


def test_unstable_model_takes_b_d_from_the_prediction_form():
    data = _unstable_closed_loop()
    for method in (subid.moesp, subid.ls_subspace):
        model = method(data, 2, horizon=10, system_matrices="shift")
        assert not model.is_stable()
        assert model.info["bd_method"] == "prediction"
        explicit = method(data, 2, horizon=10, system_matrices="shift", bd_method="simulation")
        assert explicit.info["bd_method"] == "simulation"


@pytest.mark.parametrize("method", [subid.moesp, subid.ls_subspace],
                         ids=lambda m: m.__name__)
def test_state_sequence_estimate_is_exact_on_noise_free_data(method):
    true = systems.random_system(4, 2, 2, seed=11)
    data = systems.simulate_data(true, 800, seed=12)
    for how in ("shift", "states"):
        model = method(data, 4, horizon=6, system_matrices=how)
        assert model.info["system_matrices"] == how
        assert subid.markov_error(model, true) < 1e-9
    auto = method(data, 4, horizon=6)            # noise-free: the tie goes to 'shift'
    assert auto.info["system_matrices"] == "shift"


def test_ls_state_sequence_estimate_keeps_the_basis_of_the_selector():
    true = systems.random_system(3, 1, 2, seed=5)
    data = systems.simulate_data(true, 600, seed=6)
    shift = subid.ls_subspace(data, 3, horizon=5, system_matrices="shift")
    states = subid.ls_subspace(data, 3, horizon=5, system_matrices="states")
    for name in "ABCD":
        np.testing.assert_allclose(getattr(states, name), getattr(shift, name), atol=1e-8)


def test_system_matrices_bad_values():
    true = systems.random_system(2, 1, 1, seed=1)
    data = systems.simulate_data(true, 300, seed=2)
    for method in (subid.moesp, subid.ls_subspace):
        with pytest.raises(errors.SubidError, match="system_matrices must be one of"):
            method(data, 2, system_matrices="svd")
    with pytest.raises(errors.SubidError, match="instruments='past'"):
        subid.ls_subspace(data, 2, instruments=None, system_matrices="states")


@pytest.mark.long
def test_evaporator_default_skips_a_choice_only_the_final_refit_destabilised():
    """The default MOESP model of evaporator needs no stability repair its folds did not
    need: when the CV's best candidate gets a slow unstable pole only when refitted to the
    whole record (MOESP at order 10, horizon 20, before the order search past 10), the
    best candidate whose final model needs no such repair is taken; since the order
    search goes on past 10 the choice (order 12, horizon 20) needs none, so no repair is
    recorded (measured the same on main at the start of 2026-11-27, third session). An
    explicit call with its order and horizon reproduces it."""
    est, val = _split("evaporator")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = subid.moesp(est)
        again = subid.moesp(est, order=model.order, horizon=model.info["horizon"])
    record = model.info["order_selection"]
    assert record.get("repaired_choice", {}).get("taken", "no repair needed") is not None
    assert model.info["stability"]["action"] != "enforced"
    np.testing.assert_array_equal(model.A, again.A)
    assert np.mean(subid.fit_percent(model, val)) > 61.4


def test_long_records_skip_the_system_matrix_choice():
    """``system_matrices='auto'`` cross-validates its two estimators on short records
    only: beyond AUTO_VARIANT_MAX_SAMPLES it is 'shift', with no fold fits (an explicit
    order and horizon cost one fit), and a given order still reproduces the model."""
    from subid.methods.dt.plan import AUTO_VARIANT_MAX_SAMPLES
    data = subid.systems.simulate_data(subid.systems.seed001_system(),
                                       AUTO_VARIANT_MAX_SAMPLES + 500, seed=3,
                                       output_snr_db=30)
    for method in (subid.moesp, subid.ls_subspace):
        auto = method(data, 3, horizon=8)
        shift = method(data, 3, horizon=8, system_matrices="shift")
        assert auto.info["system_matrices"] == "shift"
        assert auto.info["system_matrices_selection"]["rule"] == "long record"
        np.testing.assert_array_equal(auto.A, shift.A)
        np.testing.assert_array_equal(auto.B, shift.B)


def test_a_plant_diverging_from_rest_is_not_said_to_stay_bounded():
    """The unstable-model warning said "the measured output does not grow" of a plant
    diverging in one direction from rest (about its mean, which the late samples
    dominate, the output grows 1.8x; about zero 19x). It no longer fires there, and
    still fires for an unstable model of a stationary record (robot_arm, classical
    N4SID at order 7, stability='none')."""
    rng = np.random.default_rng(0)
    true = subid.StateSpace(np.diag([1.01, 0.5]), [[0.5], [1.0]], [[1.0, 1.0]], [[0.0]], 1.0)
    u = rng.normal(size=400)
    y = true.simulate(u)
    data = subid.IOData(u, y + 0.01 * np.std(y) * rng.normal(size=y.shape))
    with warnings.catch_warnings():
        warnings.simplefilter("error", errors.UnstableModelWarning)
        model = subid.moesp(data, 2)
    assert not model.is_stable()
    est, _ = _split("robot_arm")
    with pytest.warns(errors.UnstableModelWarning, match="does not grow"):
        subid.n4sid(est, 7, stability="none", horizon=10, weighting="n4sid")


@pytest.mark.parametrize("n_samples, seed, before", [(400, 5, 73.4), (400, 6, 39.9),
                                                     (1000, 5, 69.0)])
def test_a_response_building_up_from_rest_gets_a_stable_model(n_samples, seed, before):
    # two modes at 1 and 1.15 rad/s, damping 0.01, dt 0.2 s, 10 % output noise, from
    # rest: the estimation output grows 4.9-10x as the response builds up, and growing
    # data kept their unstable models without comparing them with the stabilised ones
    # (validation fit `before`); now the comparison is made and the stable model kept
    import scipy.signal
    den = np.polymul([1, 0.02, 1.0], [1, 0.023, 1.15 ** 2])
    A, B, C, D = scipy.signal.cont2discrete(scipy.signal.tf2ss([0.5, 0.3, 1.0], den), 0.2,
                                            method="zoh")[:4]
    true = subid.StateSpace(A, B, C, D, 0.2)
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n_samples)
    y = true.simulate(u[:, None]).ravel()
    data = subid.IOData(u, y + 0.1 * y.std() * rng.standard_normal(n_samples), dt=0.2)
    k = round(2 * n_samples / 3)
    est = subid.IOData(data.u[:k] - data.u[:k].mean(0), data.y[:k] - data.y[:k].mean(0),
                       dt=0.2)
    val = subid.IOData(data.u[k:] - data.u[:k].mean(0), data.y[k:] - data.y[:k].mean(0),
                       dt=0.2)
    assert subid.methods._stability.record_growth(est) > 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = subid.identify(est)
    assert model.is_stable()
    assert subid.fit_percent(model, val)[0] > before
