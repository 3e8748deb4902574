"""Parameter covariance of pem models and the confidence bounds of their responses."""

import numpy as np
import pytest

import subid
from subid.errors import DataError, ModelError, OptionError
from subid.model.statespace import StateSpace

# second-order output-error system (poles 0.75 +- 0.37i, |p| = 0.84)
TRUE = StateSpace([[1.5, -0.7], [1.0, 0.0]], [[1.0], [0.0]], [[1.0, 0.5]], 0, dt=1.0)
W = np.array([0.1, 0.3, 0.6, 1.0, 2.0])


def _oe_data(seed, n_samples=1000, snr_db=10.0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n_samples)
    y0 = TRUE.simulate(u)[:, 0]
    y = y0 + rng.standard_normal(n_samples) * y0.std() * 10 ** (-snr_db / 20)
    return subid.IOData(u, y, dt=1.0)


@pytest.fixture(scope="module")
def refined():
    data = _oe_data(0)
    return subid.pem(data, subid.n4sid(data, 2)), data


def _pem_of_n4sid(data):
    return subid.pem(data, subid.n4sid(data, 2))


def _covered(estimate, records, true, w, skipped=None):
    """Share of (record, frequency, channel pair) whose 95 % bounds of the model
    ``estimate(data)`` hold the |G| of ``true``. With ``skipped`` (a list), a model that
    carries no covariance is left out and its record appended there."""
    G = np.abs(true.freqresp(w))
    hits = []
    for data in records:
        model = estimate(data)
        if skipped is not None and not isinstance(model.info.get("parameter_covariance"),
                                                  dict):
            skipped.append(data)
            continue
        band = subid.freqresp_bounds(model, w)
        hits.append((band.lower <= G) & (G <= band.upper))
    return float(np.mean(hits))


def _coverage(runs, estimate=_pem_of_n4sid, skipped=None):
    """:func:`_covered` on the output-error records of ``_oe_data`` (seeds 1000..)."""
    return _covered(estimate, (_oe_data(1000 + r) for r in range(runs)), TRUE, W, skipped)


@pytest.mark.slow
def test_coverage_of_95_percent_bounds_small():
    # 20 runs x 5 frequencies; 100 pairs with p = 0.95: 88 <= hits <= 99 (binomial
    # tail below 88: 0.4 %)
    assert 0.88 <= _coverage(20) <= 1.0


@pytest.mark.long
def test_coverage_of_95_percent_bounds():
    # acceptance: 100 runs, 5 frequencies, true |G| inside in 88-99 % of the pairs
    # (measured 93.6 %; 97 % with seeds 0-99)
    assert 0.88 <= _coverage(100) <= 0.99


def test_covariance_survives_save_load(refined, tmp_path):
    model, _ = refined
    path = tmp_path / "m.json"
    model.save(path)
    loaded = StateSpace.load(path)
    a = subid.freqresp_bounds(model, W)
    b = subid.freqresp_bounds(loaded, W)
    np.testing.assert_allclose(b.upper, a.upper, rtol=1e-12)
    cov = subid.parameter_covariance(loaded)
    assert cov.covariance.shape == (cov.parameters.size,) * 2
    # the model map reproduces the model at θ
    assert cov.model(cov.parameters).allclose(loaded, rtol=0, atol=0)


def test_delta_agrees_with_sampling(refined):
    model, _ = refined
    delta = subid.freqresp_bounds(model, W, 0.9)
    sampled = subid.freqresp_bounds(model, W, 0.9, method="sampling", n_samples=2000, seed=3)
    width_d = delta.upper - delta.lower
    width_s = sampled.upper - sampled.lower
    np.testing.assert_allclose(width_s, width_d, rtol=0.15)


def test_delta_sensitivity_matches_finite_differences(refined):
    # the analytic dG/dθ of the delta method against central differences of freqresp
    model, _ = refined
    cov = subid.parameter_covariance(model)
    band = subid.freqresp_bounds(model, W)
    h = 1e-6
    rows = []
    for j in range(cov.factor.shape[1]):
        step = h * cov.factor[:, j]
        up = np.abs(cov.model(cov.parameters + step).freqresp(W))
        down = np.abs(cov.model(cov.parameters - step).freqresp(W))
        rows.append((up - down) / (2 * h))
    std = np.sqrt(np.sum(np.array(rows) ** 2, axis=0))
    np.testing.assert_allclose(band.std, std, rtol=1e-5)


def test_step_and_simulation_bounds_match_sampling(refined):
    model, data = refined
    delta = subid.step_bounds(model, 30.0)
    assert delta.value.shape == (31, 1, 1)
    np.testing.assert_allclose(delta.value, model.step(30.0)[1])
    samples = np.stack([m.step(30.0)[1] for m in
                        subid.parameter_covariance(model).sample(1500, seed=2)])
    np.testing.assert_allclose(delta.std[5:], samples.std(axis=0)[5:], rtol=0.15,
                               atol=1e-3)
    sim = subid.simulation_bounds(model, data.u[:200])
    sims = np.stack([m.simulate(data.u[:200]) for m in
                     subid.parameter_covariance(model).sample(800, seed=4)])
    np.testing.assert_allclose(sim.std[20:], sims.std(axis=0)[20:], rtol=0.2, atol=1e-3)


def test_subspace_model_has_no_covariance(refined):
    _, data = refined
    with pytest.raises(ModelError, match="or refine it with subid.pem"):
        subid.freqresp_bounds(subid.n4sid(data, 2), W)
    with pytest.raises(ModelError, match="pem"):
        subid.plot.step(subid.n4sid(data, 2), confidence=0.95)


def test_edited_model_is_refused_and_transformed_model_keeps_its_bounds(refined):
    """transform() maps the covariance with the matrices (session 22; it was refused as
    'other matrices'); matrices edited by hand under the old covariance are refused."""
    model, _ = refined
    edited = StateSpace(model.A * 1.01, model.B, model.C, model.D, model.dt, K=model.K,
                        noise_cov=model.noise_cov, info=model.info)
    with pytest.raises(ModelError, match="other matrices"):
        subid.freqresp_bounds(edited, W)
    same = subid.freqresp_bounds(model.transform(np.array([[2.0, 0.0], [0.0, 1.0]])), W)
    np.testing.assert_allclose(same.std, subid.freqresp_bounds(model, W).std, rtol=1e-7)


def test_bad_options(refined):
    model, _ = refined
    with pytest.raises(OptionError, match="level"):
        subid.freqresp_bounds(model, W, level=95)
    with pytest.raises(OptionError, match="method"):
        subid.step_bounds(model, method="bootstrap")


def test_continuous_time_pem_drops_the_covariance(refined):
    _, data = refined
    with pytest.warns(subid.errors.NoiseModelWarning):
        ct = subid.n4sid(data, 2).to_continuous()
    refined_ct = subid.pem(data, ct)
    assert "parameter_covariance" not in refined_ct.info
    with pytest.raises(ModelError, match="no parameter covariance"):
        subid.freqresp_bounds(refined_ct, W)


def _mimo_coverage(runs, estimate, skipped=None):
    """:func:`_covered` on the 2x2 seed-001 innovation system (N = 1000, seeds 100..)."""
    true = subid.systems.seed001_innovation_system()
    records = (subid.systems.simulate_innovation_data(true, 1000, seed=100 + r)
               for r in range(runs))
    return _covered(estimate, records, true, np.array([0.2, 0.8, 1.5]), skipped)


@pytest.mark.slow
def test_mimo_innovation_model_coverage():
    # 2 inputs, 2 outputs, order 3, K estimated: 10 runs x 3 frequencies x 4 channel
    # pairs; 30 runs measured 94.7 %
    assert 0.85 <= _mimo_coverage(10, lambda data: subid.pem(data, subid.n4sid(data, 3))) <= 1.0


def test_mimo_delta_matches_finite_differences_with_and_without_feedthrough():
    true = subid.systems.seed001_innovation_system()
    data = subid.systems.simulate_innovation_data(true, 600, seed=7)
    with_d = subid.n4sid(data, 3, refine="pem")       # through the option; D estimated
    without = subid.pem(data, subid.n4sid(data, 3), feedthrough=False)
    for model, n_d in ((with_d, 4), (without, 0)):
        cov = subid.parameter_covariance(model)
        assert cov.with_gain and cov.with_feedthrough == bool(n_d)
        assert cov.parameters.size == 9 + 6 + 6 + n_d + 6
        assert cov.factor.shape[1] == cov.parameters.size - 9    # no similarity directions
        band = subid.freqresp_bounds(model, W[:3])
        h = 1e-6
        rows = [(np.abs(cov.model(cov.parameters + h * f).freqresp(W[:3]))
                 - np.abs(cov.model(cov.parameters - h * f).freqresp(W[:3]))) / (2 * h)
                for f in cov.factor.T]
        np.testing.assert_allclose(band.std, np.sqrt(np.sum(np.array(rows) ** 2, axis=0)),
                                   rtol=1e-5)


def test_frequency_blocks_give_the_bounds_of_one_block(monkeypatch):
    """The magnitude std summed over blocks of frequencies (one frequency at a time
    here) is the std of one block, and the step band's compiled sensitivities are
    those of one simulation per direction (the sensitivity equations run by the
    model's own simulation)."""
    from subid.evaluation import uncertainty
    true = subid.systems.seed001_innovation_system()
    data = subid.systems.simulate_innovation_data(true, 600, seed=7)
    model = subid.pem(data, subid.n4sid(data, 3))
    w = np.linspace(0.05, 3.0, 7)
    whole = subid.freqresp_bounds(model, w)
    monkeypatch.setattr(uncertainty, "_BLOCK_ENTRIES", 1)
    np.testing.assert_allclose(subid.freqresp_bounds(model, w).std, whole.std, rtol=1e-12,
                               atol=1e-14)
    cov = subid.parameter_covariance(model)
    u = np.random.default_rng(3).standard_normal((40, model.n_inputs))
    x0 = np.array([0.3, -0.2, 0.1])
    y, dy = uncertainty._output_sensitivities(model, cov, u, x0)
    dA, dB, dC, dD = uncertainty._directions(cov)
    x = model.simulate(u, x0=x0, return_state=True)[1]
    state = StateSpace(model.A, np.eye(3), np.eye(3), 0, model.dt)
    for j in range(dA.shape[0]):
        s = state.simulate(x @ dA[j].T + u @ dB[j].T)
        np.testing.assert_allclose(dy[:, :, j], s @ np.asarray(model.C).T + x @ dC[j].T
                                   + u @ dD[j].T, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(y, model.simulate(u, x0=x0), rtol=1e-12)


@pytest.mark.parametrize("sparse", [False, True])
def test_magnitude_std_is_the_definition(sparse):
    """The delta-method std of |G| (the products restricted to the rows and columns of A
    and columns of C that the directions move) equals dG summed by its definition."""
    from subid.evaluation.uncertainty import _magnitude_std
    rng = np.random.default_rng(7)
    n, ny, nu, d, K = 6, 2, 3, 5, 4
    A = 0.3 * rng.standard_normal((n, n))
    B, C = rng.standard_normal((n, nu)), rng.standard_normal((ny, n))
    D = rng.standard_normal((ny, nu))
    dA, dB = rng.standard_normal((d, n, n)), rng.standard_normal((d, n, nu))
    dC, dD = rng.standard_normal((d, ny, n)), rng.standard_normal((d, ny, nu))
    if sparse:                # a polynomial realisation: few rows/columns of A move, C fixed
        dA[:, [0, 2, 3, 5]] = 0.0
        dA[:, :, 1:] = 0.0
        dC[:] = 0.0
    s = np.exp(1j * np.linspace(0.1, 3.0, K))
    X = np.array([np.linalg.solve(z * np.eye(n) - A, B) for z in s])
    Y = np.array([C @ np.linalg.inv(z * np.eye(n) - A) for z in s])
    G = C @ X + D
    expected = np.empty((K, ny, nu))
    for k in range(K):
        dG = [dC[j] @ X[k] + Y[k] @ dA[j] @ X[k] + Y[k] @ dB[j] + dD[j] for j in range(d)]
        expected[k] = np.sqrt(sum((np.real(np.conj(G[k]) * g) / np.abs(G[k])) ** 2
                                  for g in dG))
    np.testing.assert_allclose(_magnitude_std(G, X, Y, dA, dB, dC, dD), expected,
                               rtol=1e-12)


# ---------------------------------------------------------------------------
# subid.identify: the covariance of a model it does not refine
# ---------------------------------------------------------------------------
def _identify_unrefined(data):
    model = subid.identify(data, 2, refine=False)
    assert model.info["identify"]["covariance"]["at"] == "the subspace model"
    return model


@pytest.mark.slow
def test_identify_subspace_model_bounds_cover_small():
    # 20 runs x 5 frequencies of the output-error system (measured 100 runs: 93.3 %)
    skipped = []
    assert 0.85 <= _coverage(20, _identify_unrefined, skipped) <= 1.0
    assert not skipped


@pytest.mark.long
def test_identify_subspace_model_bounds_cover():
    # 100 runs: measured 93.3 % with the output-error sandwich (93.7 % with the innovation
    # form's covariance; pem's own bounds on the same records: 93.6 %); in 2 runs
    # (seeds 1041, 1072) the feedback test's 1 % level flags feedback in these open-loop
    # records and no covariance is attached (test_identify_attaches_no_covariance_...)
    skipped = []
    assert 0.88 <= _coverage(100, _identify_unrefined, skipped) <= 0.99
    assert len(skipped) <= 3


@pytest.mark.long
def test_identify_subspace_model_bounds_cover_mimo_innovation():
    # the 2x2 seed-001 innovation system, 40 runs x 3 frequencies x 4 channel pairs:
    # measured 94.2 % with the output-error sandwich (89.6 % with the innovation form's
    # covariance: the subspace estimate is less efficient than pem's, whose bounds cover
    # 94.7 % in 30 runs of test_mimo_innovation_model_coverage)
    skipped = []
    assert 0.85 <= _mimo_coverage(40, lambda data: subid.identify(data, 3, refine=False),
                                  skipped) <= 1.0
    assert len(skipped) <= 2


def test_identify_default_model_carries_a_covariance_for_the_bounds():
    data = _oe_data(3)
    model = subid.identify(data)
    cov = subid.parameter_covariance(model)
    assert cov.parameters.size > 0
    record = model.info["identify"]
    if record["refinement"]["kept"]:
        assert "covariance" not in record           # pem's own
    else:       # the output-error sandwich (identify's focus='simulation')
        assert record["covariance"]["focus"] == "simulation" and not cov.with_gain
        assert "sandwich" in model.info["parameter_covariance"]["method"]
    band = subid.freqresp_bounds(model, W)
    assert np.all(band.std > 0) and np.all(np.isfinite(band.std))
    step = subid.step_bounds(model, 10)
    assert np.all(np.isfinite(step.std)) and np.all(step.std[1:] > 0)


def test_windowed_covariance_is_the_whole_records_when_it_fits_and_close_otherwise(
        monkeypatch):
    from subid.methods.dt.pem import with_covariance
    true = subid.systems.seed001_innovation_system()
    data = subid.systems.simulate_innovation_data(true, 30000, seed=3)
    model = subid.pem(data, subid.n4sid(data, 3))
    entry = model.info["parameter_covariance"]
    w = np.array([0.2, 0.8, 1.5])
    full = subid.freqresp_bounds(model, w).std

    def again(max_samples):
        bare = model.with_noise_model(model.K, model.noise_cov, info={
            k: v for k, v in model.info.items() if k != "parameter_covariance"})
        return with_covariance(bare, data, "prediction",
                               with_feedthrough=entry["with_feedthrough"],
                               max_samples=max_samples)

    same = again(30000)
    np.testing.assert_array_equal(same.info["parameter_covariance"]["factor"],
                                  entry["factor"])            # pem's covariance, bit for bit
    windows = again(12000)
    assert windows.info["parameter_covariance"]["samples_used"] == 12000
    assert windows.info["parameter_covariance"]["n_samples"] == 30000
    # the information of 12,000 of 30,000 samples scaled to all: the same std to 3 %
    np.testing.assert_allclose(subid.freqresp_bounds(windows, w).std, full, rtol=0.03)
    # the predictor's states at the windows, run in chunks of 1000: the same bits
    from subid.methods.dt import pem as pem_module
    monkeypatch.setattr(pem_module, "_PREDICTOR_CHUNK", 1000)
    np.testing.assert_array_equal(again(12000).info["parameter_covariance"]["factor"],
                                  windows.info["parameter_covariance"]["factor"])


def _closed_loop_coverage(runs, estimate):
    """:func:`_covered` on the seed-001 plant under output feedback u = r + 0.5 y (issue
    21's closed loop, N = 3000, seeds 200..)."""
    true = subid.systems.seed001_innovation_system(feedthrough=False)
    records = (subid.systems.simulate_innovation_data(true, 3000, seed=200 + r,
                                                      feedback=-0.5 * np.eye(2))
               for r in range(runs))
    return _covered(estimate, records, true, np.array([0.2, 0.8, 1.5]))


def test_identify_attaches_no_covariance_to_a_subspace_model_under_feedback():
    # MOESP and N4SID are biased in closed loop: bands around their model held the true
    # |G| in 21 % of the pairs (30 runs of identify(data, 3, refine=False), measured)
    true = subid.systems.seed001_innovation_system(feedthrough=False)
    data = subid.systems.simulate_innovation_data(true, 3000, seed=200,
                                                  feedback=-0.5 * np.eye(2))
    model = subid.identify(data, 3, refine=False)
    record = model.info["identify"]["covariance"]
    assert record["computed"] is False and "feedback" in record["reason"]
    with pytest.raises(ModelError, match="no parameter covariance"):
        subid.parameter_covariance(model)


@pytest.mark.long
def test_identify_default_bounds_cover_in_closed_loop():
    # the default keeps its prediction-error refinement under feedback (every run here):
    # 30 runs x 3 frequencies x 4 pairs, measured 95.6 %
    assert 0.88 <= _closed_loop_coverage(30, lambda data: subid.identify(data, 3)) <= 1.0


def test_continuous_time_models_name_the_discrete_time_path_to_bounds():
    # identify on non-uniform data goes to ct_subspace: the message said "models estimated
    # by identify carry no parameter covariance; identify it with subid.identify(data), or
    # refine it with subid.pem", circular (pem refuses non-uniform data)
    true = TRUE.to_continuous()
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.5, 1.5, size=800))
    u = rng.standard_normal(800)
    y = true.simulate(u, t=t, hold="zoh")[:, 0] + 0.05 * rng.standard_normal(800)
    irregular = subid.IOData(u, y, t=t)
    model = subid.identify(irregular, 2)
    assert model.is_continuous
    for m in (model, model.to_discrete(1.0)):
        with pytest.raises(ModelError, match=r"identify took its continuous-time path "
                                             r"\(ct_subspace: non-uniform time stamps\)") as e:
            subid.step_bounds(m)
        assert "interpolated onto a uniform grid" in str(e.value)
        assert "refine it with subid.pem" not in str(e.value)
    with pytest.raises(DataError, match="uniformly sampled"):      # what the message says
        subid.pem(irregular, model.to_discrete(1.0))
    # ... and the path it names gives bounds
    grid = np.arange(t[0], t[-1], 1.0)
    uniform = subid.IOData(np.interp(grid, t, u), np.interp(grid, t, y), dt=1.0)
    assert subid.step_bounds(subid.identify(uniform, 2)).std is not None
    ct = subid.ct_subspace(uniform, 2)
    with pytest.raises(ModelError, match=r"estimated in continuous time \(ct_subspace\)"):
        subid.parameter_covariance(ct)
    refined = subid.pem(uniform, ct.to_discrete(1.0))
    assert subid.step_bounds(refined).std is not None


def test_pem_of_a_continuous_time_model_refines_its_simulation_error():
    # focus='prediction' (pem's default for discrete-time models) fitted an innovation
    # form through the discretisation and dropped it: the seed-002 system at 20 dB,
    # ct_subspace(data, 4) validating at 98.9 %, fell to -90.0 %; a continuous-time
    # model is now refined by its simulation error, and 'prediction' is refused
    from subid.experiments.seed002 import simulate
    data, _ = simulate(2000, 0, snr_db=20)
    validation, y = simulate(2000, 99)
    validation = subid.IOData(validation.u, y, t=validation.t)
    start = subid.ct_subspace(data, 4)
    refined = subid.pem(data, start)
    assert refined.info["focus"] == "simulation" and refined.is_continuous
    assert subid.fit_percent(refined, validation)[0] > 98
    np.testing.assert_allclose(subid.pem(data, start, focus="simulation").A, refined.A)
    with pytest.raises(OptionError, match="continuous-time model"):
        subid.pem(data, start, focus="prediction")
