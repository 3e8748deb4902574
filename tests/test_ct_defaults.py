"""The default ``ct_subspace(data)`` (issue 22): several experiments, offsets and the
stability handling, the order by cross-validation, coloured output noise."""

import warnings

import numpy as np
import pytest

import subid
from subid import IOData, StateSpace, merge
from subid.experiments.seed002 import BIAS_FREQUENCIES, paper_system, simulate
from subid.experiments.seed002_bound import median_bound
from subid.methods.ct import _ct_discrete, _ct_fit
from subid.methods.ct.ct_subspace import ct_subspace

W = np.logspace(-2, 2, 200)


def max_relative_error(model, reference):
    g = reference.freqresp(W)
    return float((np.abs(model.freqresp(W) - g) / np.abs(g).max(axis=(1, 2), keepdims=True))
                 .max())


def bias_z_scores(errors):
    E = np.array(errors)
    se = np.sqrt((E.real.var(axis=0, ddof=1) + E.imag.var(axis=0, ddof=1)) / len(E))
    return np.abs(E.mean(axis=0)) / se


def test_merged_experiments_are_exact_with_one_initial_state_each():
    true = paper_system()
    one, _ = simulate(400, 1)
    two, _ = simulate(300, 2)
    data = merge([one, two])
    model = ct_subspace(data, 4, feedthrough=False)
    assert max_relative_error(model, true) < 1e-6
    x0 = np.asarray(model.info["x0"])
    assert x0.shape == (2, 4) and model.info["n_experiments"] == 2
    for k, e in enumerate((one, two)):            # each experiment from its own state
        y = model.simulate(e.u, t=e.t, x0=x0[k], hold="foh")
        assert np.abs(y - e.y).max() < 1e-6 * np.abs(e.y).max()
    # the joined record (one experiment) is not the same problem: its initial state is wrong
    joined = IOData(np.vstack([one.u, two.u]), np.vstack([one.y, two.y]),
                    t=np.concatenate([one.t, two.t + one.t[-1] + 0.005 - two.t[0]]))
    assert max_relative_error(ct_subspace(joined, 4, feedthrough=False, refine=False),
                              true) > 1e-3


def offset_record(seed=0, n_samples=1200, dt=0.05):
    """A damped 2nd-order plant around an operating point: u = 3 + w, y = 10 + G w + e."""
    true = StateSpace([[0.0, 1.0], [-1.0, -1.4]], [[0.0], [1.0]], [[2.0, 0.5]], 0, dt=0.0)
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * dt
    w = rng.standard_normal(n_samples)
    y = true.simulate(w, t=t, hold="zoh")
    y = y + 0.02 * y.std() * rng.standard_normal(y.shape)
    return true, IOData(3.0 + w, 10.0 + y, t=t)


def test_offsets_with_a_given_order_give_no_pole_at_the_origin():
    true, data = offset_record(n_samples=600)
    model = ct_subspace(data, 2, hold="zoh", feedthrough=False)
    assert model.info["offset"] is True
    assert model.poles().real.max() < -0.5, model.poles()
    assert max_relative_error(model, true) < 0.05


@pytest.mark.long
def test_offsets_never_become_a_pole_at_the_origin():
    true, data = offset_record()
    model = ct_subspace(data, hold="zoh")
    poles = model.poles()
    assert model.info["offset"] is True
    assert poles.real.max() < -0.1, poles          # true poles -0.7 +- 0.71j: none near 0
    assert model.order >= 2
    assert abs(model.info["y_offset"][0, 0] - (10.0 - 3.0 * 2.0)) < 0.2  # 10 - G(0) u0
    assert max_relative_error(model, true) < 0.05
    # without the offset the data need a pole at the origin, which 'none' keeps
    # (0.032 from the basis-filter estimate, 30x slower than the true poles)
    raw = ct_subspace(data, 3, hold="zoh", offset=False, stability="none", refine=False)
    assert np.abs(raw.poles()).min() < 0.05


def test_stable_choice_reflects_a_pole_the_data_do_not_show():
    _, data = offset_record(1)
    rec = _ct_fit.Record(data.detrend(), 0)
    A = np.array([[0.0, 1.0], [-1.0, -1.4]]) + 0.9 * np.eye(2)    # poles 0.2 +- 0.71j
    C = np.array([[2.0, 0.5]])

    def fit(A_, C_):
        return _ct_fit.fit_linear(A_, C_, rec, feedthrough=False, estimate_x0=True,
                                  offset=False)
    A_s, _, record = _ct_fit.stable_choice(A, C, fit, rec, "auto")
    assert record["action"] == "enforced" and np.linalg.eigvals(A_s).real.max() < 0
    A_n, _, record = _ct_fit.stable_choice(A, C, fit, rec, "none")
    assert record["action"] == "none" and np.array_equal(A_n, A)


@pytest.mark.slow
def test_default_order_is_cross_validated_with_the_hold():
    true, data = offset_record(2, n_samples=500)
    model = ct_subspace(data.detrend(), hold="zoh")
    sel = model.info["order_selection"]
    assert sel["rule"] == "cv" and model.order >= 2
    assert max_relative_error(model, true) < 0.1
    assert {c["order"] for c in sel["candidates"]
            if c["system_matrices"] == "subspace"} == set(range(1, 11))
    assert isinstance(model.info["feedthrough"], bool)
    if model.info["start"] == "subspace":
        assert "feedthrough_selection" in model.info
    else:                                   # the converted n4sid model (its own D)
        assert model.info["discrete_model"]["order"] >= 1
    again = ct_subspace(data.detrend(), model.order, hold="zoh")
    assert np.allclose(again.A, model.A) and np.allclose(again.C, model.C)


def coloured_runs(runs, n_samples, pole, **options):
    true = paper_system()
    gb = true.freqresp(BIAS_FREQUENCIES)[:, 0, 0]
    g = true.freqresp(W)[:, 0, 0]
    err, worst, models = [], [], []
    for r in range(runs):
        data, _ = simulate(n_samples, 100 + r, snr_db=20, noise_pole=pole)
        model = ct_subspace(data, 4, **options)
        err.append(model.freqresp(BIAS_FREQUENCIES)[:, 0, 0] - gb)
        worst.append(np.abs(model.freqresp(W)[:, 0, 0] - g).max())
        models.append(model)
    return bias_z_scores(err), float(np.median(worst)), models


@pytest.mark.slow
def test_coloured_noise_small_monte_carlo():
    """AR(1) output noise (pole 0.9, 20 dB), 4 runs: the AR noise model is found and
    the prewhitened refinement is unbiased and beats the subspace estimate."""
    z, med, models = coloured_runs(4, 4000, 0.9, feedthrough=False, start="subspace",
                                   refine=True)
    assert all(m.info["noise_model"] is not None and m.info["refined"] for m in models)
    assert np.all(z < 3.0), z
    _, med_subspace, _ = coloured_runs(4, 4000, 0.9, feedthrough=False, start="subspace",
                                       refine=False)
    assert med < 0.5 * med_subspace, (med, med_subspace)


@pytest.mark.long
def test_coloured_noise_monte_carlo_50_runs():
    """50 runs, L = 4000: no bias at 0.1-5 rad/s (z < 2), and the error under coloured
    and white noise within 1.3 times the Cramér-Rao bound on the same records
    (docs/seed002.md; the bound's ratio is 4.3, so the ratio measured is near it)."""
    z, med, _ = coloured_runs(50, 4000, 0.9)
    assert np.all(z < 2.0), z
    _, white, _ = coloured_runs(50, 4000, 0.0)
    seeds = range(100, 150)
    assert med < 1.3 * median_bound(4000, seeds, noise_pole=0.9), med
    assert white < 1.3 * median_bound(4000, seeds, noise_pole=0.0), white


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_negative_real_poles_convert_with_nyquist_modes(hold):
    """A discrete-time model with poles on the negative real axis has no continuous-time
    model of its order; with a mode at the Nyquist frequency for each, its hold
    discretisation has the same transfer function (and the same samples, x0 aside)."""
    rng = np.random.default_rng(3)
    A = np.array([[0.5, 0.3, 0, 0], [-0.3, 0.5, 0, 0], [0, 0, -0.5, 0.2], [0, 0, 0, -0.3]])
    T = rng.standard_normal((4, 4))
    dm = StateSpace(np.linalg.solve(T, A @ T), rng.standard_normal((4, 2)),
                    rng.standard_normal((2, 4)), rng.standard_normal((2, 2)), dt=0.1)
    cm, note = _ct_discrete.convert(dm, hold)
    assert cm.order == 6 and "Nyquist" in note and cm.hold == hold
    assert np.allclose(np.sort(np.abs(cm.poles().imag))[2:], np.pi / 0.1)
    w = np.linspace(0.1, 31.0, 9)
    back = cm.to_discrete(0.1, hold)
    assert np.abs(back.freqresp(w) - dm.freqresp(w)).max() < 1e-10
    u = rng.standard_normal((300, 2))
    y = cm.simulate(u, t=np.arange(300) * 0.1, hold=hold)
    assert np.abs(y - dm.simulate(u))[40:].max() < 1e-8 * np.abs(y).max()
    # a pole at the origin has no continuous-time counterpart at all
    none, reason = _ct_discrete.convert(StateSpace(np.diag([0.0, 0.5]), np.ones((2, 1)),
                                                   np.ones((1, 2)), 0, dt=0.1), hold)
    assert none is None and "z = 0" in reason


def test_paired_test_needs_every_fold_to_agree_or_a_clear_mean():
    assert _ct_discrete.significantly_better([60, 61, 62, 63], [59, 60, 61, 62])
    assert not _ct_discrete.significantly_better([70, 60, 62, 59], [60, 61, 62, 60])
    assert not _ct_discrete.significantly_better([60, 61, 62, 63], [60, 61, 62, 63])
    record = _ct_discrete.paired_test([71.0, 63.0, 62.6, -100.0], [59.7, 56.2, 62.2, -100.0])
    assert not record["significant"] and record["mean_difference"] > 0


def n4sid_reference_record(seed=4, n_samples=900):
    """A 2x1 plant with a lightly damped pair, coloured process noise, zero-order hold."""
    true = StateSpace([[0.0, 1.0, 0.0], [-4.0, -0.4, 0.0], [0.0, 0.0, -0.5]],
                      [[0.0], [1.0], [0.5]], [[1.0, 0.0, 1.0], [0.0, 1.0, -1.0]], 0, dt=0.0)
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * 0.1
    u = np.repeat(rng.standard_normal(n_samples // 3), 3)
    y = true.simulate(u, t=t, hold="zoh")
    y = y + 0.1 * y.std(axis=0) * rng.standard_normal(y.shape)
    return IOData(u, y, t=t)


@pytest.mark.slow
def test_default_is_never_far_below_the_discrete_time_default():
    """The default N4SID model, converted, competes in the cross-validation: the default
    ct_subspace model validates within 2 points of the default n4sid model."""
    import subid
    data = n4sid_reference_record()
    est, val = data[:600], data[600:]
    dm = subid.n4sid(est)
    cm = ct_subspace(est)
    assert "discrete_model" in cm.info and cm.info["order_selection"]["rule"] == "cv"
    kinds = {c["system_matrices"] for c in cm.info["order_selection"]["candidates"]}
    assert "subspace" in kinds and any(k.startswith("N4SID, horizon") for k in kinds)
    assert np.mean(subid.fit_percent(cm, val)) >= np.mean(subid.fit_percent(dm, val)) - 2.0


def test_cramer_rao_bound_of_coloured_against_white_noise():
    """What any unbiased estimator can reach (docs/seed002.md): under AR(1) output noise
    (pole 0.9) the Cramér-Rao median of max |G - G_hat| is about 4.4 times that under
    white noise of the same variance, so the issue's 1.5x cannot be met at equal SNR."""
    white = median_bound(4000, range(3), noise_pole=0.0, draws=200)
    coloured = median_bound(4000, range(3), noise_pole=0.9, draws=200)
    assert 0.015 < white < 0.03, white
    assert 3.8 < coloured / white < 5.0, coloured / white


def test_a_state_the_samples_do_not_see_gets_no_initial_state():
    """A converted N4SID model with a Nyquist mode (a pole of the discrete-time model on
    the negative real axis: one state more, unseen at the samples) had info['x0'] =
    -1.3e14 for that state (its rounding-level column equilibrated to unit norm); it is 0
    now, and the initial state reproduces the fit x0='estimate' gives."""
    true = subid.systems.random_system(4, 2, 2, seed=31)
    data = subid.systems.simulate_data(true, 1500, seed=6, process_snr_db=15,
                                       output_snr_db=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = subid.ct_subspace(data)
    assert model.info.get("nyquist_modes")
    x0 = np.asarray(model.info["x0"])
    assert np.all(np.abs(x0) < 100), x0
    np.testing.assert_allclose(subid.fit_percent(model, data, x0=x0),
                               subid.fit_percent(model, data), atol=1e-6)


def test_an_oversampled_plant_gets_its_order_not_cancelling_modes():
    """A 3rd-order plant sampled at dt = 0.05 (20 dB output noise, 1000 samples): with
    its N4SID reference held at horizons 10 and 20 (too short for the dynamics), a
    basis-filter model of order 10 won the folds with nearly undamped, nearly cancelled
    modes, its frequency response 1.48 off (relative). The reference now searches the
    horizons n4sid searches (40 here)."""
    A = np.array([[0.0, 1.0, 0.0], [-4.0, -1.2, 1.0], [0.0, 0.0, -0.5]])
    true = StateSpace(A, [[0.0], [1.0], [0.5]], [[1.0, 0.0, 0.0]], [[0.0]], dt=0,
                      hold="foh")
    rng = np.random.default_rng(0)
    u = rng.standard_normal(1000)
    y = true.simulate(u, t=np.arange(1000) * 0.05, hold="foh")
    data = IOData(u, y + 0.1 * np.std(y) * rng.standard_normal(y.shape), dt=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = ct_subspace(data)
    w = np.logspace(-1, 1, 100)
    G = true.freqresp(w)
    assert model.order <= 4
    assert np.abs(model.freqresp(w) - G).max() < 0.05 * np.abs(G).max()
