"""The default ``ct_subspace(data)`` (issue 22): several experiments, offsets and the
stability handling, the order by cross-validation, coloured output noise."""

import numpy as np
import pytest

from subid import IOData, StateSpace, merge
from subid.experiments.seed002 import BIAS_FREQUENCIES, paper_system, simulate
from subid.methods.ct import _ct_fit
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
    raw = ct_subspace(data, 3, hold="zoh", offset=False, stability="none", refine=False)
    assert np.abs(raw.poles()).min() < 0.02


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
    assert {c["order"] for c in sel["candidates"]} == set(range(1, 11))
    assert isinstance(model.info["feedthrough"], bool) and "feedthrough_selection" in model.info
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
    """50 runs, L = 4000: no bias at 0.1-5 rad/s (z < 2), and the error against white
    noise at the same SNR within the ratio the noise spectra set (docs/seed002.md)."""
    z, med, _ = coloured_runs(50, 4000, 0.9)
    assert np.all(z < 2.0), z
    _, white, _ = coloured_runs(50, 4000, 0.0)
    assert med < 5.0 * white, (med, white)
