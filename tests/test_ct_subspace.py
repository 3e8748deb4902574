"""Continuous-time subspace identification with basis filters (seed 002).

Exact recovery from exactly filtered signals, the corrected data equation and
formulas, the acceptance figures on the paper's example (sampled, jittered,
noisy), MIMO/feedthrough/ZOH cases, the baselines and errors on bad input.
"""

import numpy as np
import pytest

from subid import IOData, StateSpace, errors
from subid.experiments.seed002 import paper_system, simulate
from subid.methods.ct._ct_estimate import _fit_b_filtered
from subid.methods.ct.basis import default_basis, laguerre, legendre, takenaka_malmquist
from subid.methods.ct.ct_subspace import (
    _estimate_a_c,
    _subspace_factor,
    ct_subspace,
    ct_subspace_paper,
    data_equation_matrices,
    dt_to_ct,
    observability_matrix,
    tm_convolution_matrix,
)

W = np.logspace(-2, 2, 200)
TM = [4.0, 12.0, 20.0, 28.0, 36.0, 44.0, 52.0, 60.0]


@pytest.fixture(scope="module")
def true():
    return paper_system()


@pytest.fixture(scope="module")
def g_true(true):
    return true.freqresp(W)[:, 0, 0]


def max_error(model, g_true):
    return float(np.abs(model.freqresp(W)[:, 0, 0] - g_true).max())


def max_relative_error(model, reference):
    g = reference.freqresp(W)
    return float((np.abs(model.freqresp(W) - g) / np.abs(g).max(axis=(1, 2), keepdims=True))
                 .max())


def exact_filtered(system, bank, t, u, x0, hold="foh"):
    """Exactly filtered (u_f, y_f) and the state, by simulating plant + banks together."""
    F, g = bank.realization()
    N = bank.n_functions
    n, m, p = system.order, system.n_inputs, system.n_outputs
    gp = np.kron(g[:, None], np.eye(p))
    size = n + N * p + N * m
    A = np.zeros((size, size))
    B = np.zeros((size, m))
    A[:n, :n] = system.A
    B[:n] = system.B
    A[n:n + N * p, :n] = gp @ system.C
    A[n:n + N * p, n:n + N * p] = np.kron(F, np.eye(p))
    B[n:n + N * p] = gp @ system.D
    A[n + N * p:, n + N * p:] = np.kron(F, np.eye(m))
    B[n + N * p:] = np.kron(g[:, None], np.eye(m))
    z0 = np.zeros(size)
    z0[:n] = x0
    z = StateSpace(A, B, np.eye(size), 0, 0.0).simulate(u, t=t, x0=z0, hold=hold)
    L = t.size
    return (z[:, n + N * p:].reshape(L, N, m), z[:, n:n + N * p].reshape(L, N, p), z[:, :n])


def record(true, n_samples=400, seed=0, **kw):
    """(data, exact state): the paper's record, started from rest 10 s earlier."""
    data, _, x = simulate(n_samples, seed, return_state=True, **kw)
    return data, x


BANKS = {
    "tm": lambda t: takenaka_malmquist(TM),
    "laguerre4": lambda t: laguerre(4.0, 8),
    "laguerre28": lambda t: laguerre(28.0, 8),
    "laguerre60": lambda t: laguerre(60.0, 8),
    "legendre": lambda t: legendre(10.0, 8),
    "default": default_basis,
    "tm-complex": lambda t: takenaka_malmquist([3 + 4j, 3 - 4j, 10, 20 + 5j, 20 - 5j, 40, 60, 80]),
    "kautz": lambda t: laguerre(5 + 5j, 8),
}


# ---------------------------------------------------------------------------
# the data equation and the corrected formulas
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["tm", "laguerre4", "tm-complex"])
def test_data_equation_is_exact_with_startup_regressors(true, name):
    data, x = record(true, 300, seed=1)
    bank = BANKS[name](data.t)
    uf, yf, xs = exact_filtered(true, bank, data.t, data.u, x[0])
    np.testing.assert_allclose(xs, x, atol=1e-10)
    O, T = data_equation_matrices(bank, true.A, true.B, true.C, true.D)
    resid = yf.reshape(300, -1) - xs @ O.T - uf.reshape(300, -1) @ T.T
    phi = bank.functions(data.t - data.t[0])
    coef = np.linalg.lstsq(phi, resid, rcond=None)[0]
    assert np.abs(resid).max() > 1e-3                      # x(t0) != 0: transients present
    assert np.abs(resid - phi @ coef).max() < 1e-12 * np.abs(yf).max() * 100


def test_observability_matrix_is_eq_10(true):
    sig = np.array(TM)
    A, C, n = true.A, true.C, true.order
    eye = np.eye(n)
    blocks, Phi = [], eye
    for s in sig:
        blocks.append(np.sqrt(2 * s) * C @ np.linalg.solve(A + s * eye, Phi))
        Phi = Phi @ np.linalg.solve(A + s * eye, A - s * eye)
    np.testing.assert_allclose(observability_matrix(takenaka_malmquist(sig), A, C),
                               np.vstack(blocks), rtol=1e-10, atol=1e-13)


def printed_T(A, B, C, poles):
    """T of (6) exactly as printed: -D_0/+D_0 bidiagonal T_0, T_i with one zero row."""
    sig = np.asarray(poles)
    N, n = sig.size, A.shape[0]
    eye = np.eye(n)
    D0 = -C @ np.linalg.solve(A + sig[0] * eye, B)
    blocks = []
    Phi = eye
    for i in range(N):
        gam = D0 if i == 0 else np.sqrt(2 * sig[i]) * C @ np.linalg.solve(A + sig[i] * eye, Phi) @ B
        Ti = np.zeros((N, N - i))
        first = 0 if i == 0 else 1
        for r in range(N - i):
            if first + r < N:
                Ti[first + r, r] = -gam[0, 0]
            if first + r + 1 < N:
                Ti[first + r + 1, r] = gam[0, 0]
        blocks.append(Ti)
        Phi = Phi @ np.linalg.solve(A + sig[i] * eye, A - sig[i] * eye)
    return np.hstack(blocks)


def test_corrected_T_makes_eq_6_exact_and_the_printed_one_does_not(true):
    data, x = record(true, 300, seed=2)
    bank = takenaka_malmquist(TM)
    uf, yf, xs = exact_filtered(true, bank, data.t, data.u, x[0])
    stack = bank.paper_input_stack(data.u, data.t, poly_order=1, chain="exact")[:, :, 0]
    O = observability_matrix(bank, true.A, true.C)
    phi = bank.functions(data.t - data.t[0])
    out = {}
    for name, T in (("corrected", tm_convolution_matrix(true.A, true.B, true.C, TM)),
                    ("printed", printed_T(true.A, true.B, true.C, TM))):
        resid = yf[:, :, 0] - xs @ O.T - stack @ T.T
        resid = resid - phi @ np.linalg.lstsq(phi, resid, rcond=None)[0]
        out[name] = np.abs(resid).max() / np.abs(yf).max()
    assert out["corrected"] < 1e-12
    assert out["printed"] > 1e-2
    # the stacked input (N(N+1)/2 = 36 signals) has rank N = 8 only
    assert np.linalg.matrix_rank(stack, tol=1e-9 * np.abs(stack).max()) == 8


def test_a_c_from_O_joint_and_paper_13_14(true):
    for bank in (takenaka_malmquist(TM), takenaka_malmquist([2 + 1j, 2 - 1j, 5, 9, 14])):
        O = observability_matrix(bank, true.A, true.C)
        Q = np.random.default_rng(3).standard_normal((4, 4))
        Theta = O @ Q                                   # range(O) in another basis
        for method in ("joint", "paper"):
            A, C, resid = _estimate_a_c(bank, Theta, 1, method)
            assert resid < 1e-12
            np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(A)),
                                       np.sort_complex(true.poles()), atol=1e-10)
            np.testing.assert_allclose(observability_matrix(bank, A, C), Theta, atol=1e-10)
    # (14) as printed, with 2 sigma_0 instead of sqrt(2 sigma_0), gives a wrong C
    bank = takenaka_malmquist(TM)
    Theta = observability_matrix(bank, true.A, true.C)
    A, C, _ = _estimate_a_c(bank, Theta, 1, "paper")
    C_printed = Theta[:1] @ (A + TM[0] * np.eye(4)) / (2 * TM[0])
    wrong = np.abs(observability_matrix(bank, A, C_printed) - Theta).max()
    assert wrong > 0.1 * np.abs(Theta).max()


@pytest.mark.parametrize("paper_form", [False, True])
def test_eq_15_recovers_B_from_exact_filtered_data(true, paper_form):
    data, x = record(true, 400, seed=4)
    bank = takenaka_malmquist(TM)
    uf, yf, xs = exact_filtered(true, bank, data.t, data.u, x[0])
    if paper_form:
        U = bank.paper_input_stack(data.u, data.t, poly_order=1, chain="exact")[:, :, 0]
        Tfun = lambda Bm, Dm: tm_convolution_matrix(true.A, Bm, true.C, TM)  # noqa: E731
    else:
        U = uf[:, :, 0]
        Tfun = lambda Bm, Dm: data_equation_matrices(bank, true.A, Bm, true.C, Dm)[1]  # noqa
    R = np.hstack([bank.functions(data.t - data.t[0]), U])
    Lf, W_ = _subspace_factor(R, None, yf[:, :, 0])
    Theta = observability_matrix(bank, true.A, true.C)
    B, D, diag = _fit_b_filtered(Tfun, Theta, Lf, slice(8, 8 + U.shape[1]), 4, 1, 1, False)
    np.testing.assert_allclose(B, true.B, atol=1e-8)


# ---------------------------------------------------------------------------
# acceptance: exact filtering, every basis
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(BANKS))
def test_exact_filtering_recovers_the_system_for_every_basis(true, name):
    data, x = record(true, 400, seed=0)
    bank = BANKS[name](data.t)
    uf, yf, _ = exact_filtered(true, bank, data.t, data.u, x[0])
    model = ct_subspace(data, 4, basis=bank, filtered=(uf, yf), refine=False)
    assert max_relative_error(model, true) < 1e-8
    assert model.info["filtering"] == "given" and model.info["refined"] is False
    if name == "tm":
        for options in ({"ac_method": "paper"}, {"bd_method": "filtered"},
                        {"instruments": None}, {"instruments": "past"}):
            m2 = ct_subspace(data, 4, basis=bank, filtered=(uf, yf), refine=False, **options)
            assert max_relative_error(m2, true) < 1e-8, options


def test_without_startup_regressors_exact_filtering_fails(true):
    data, x = record(true, 400, seed=0)
    bank = takenaka_malmquist(TM)
    uf, yf, _ = exact_filtered(true, bank, data.t, data.u, x[0])
    model = ct_subspace(data, 4, basis=bank, filtered=(uf, yf), refine=False, startup=False,
                        instruments=None, offset=False)
    assert max_relative_error(model, true) > 1e-4


# ---------------------------------------------------------------------------
# acceptance: sampled data, the paper's experiment
# ---------------------------------------------------------------------------
def test_sampled_L400_tm_reaches_1e3_and_beats_every_laguerre(true, g_true):
    """The paper's claim (Section V) after the fixes: TM {4..60} beats each Laguerre."""
    err = {k: [] for k in ("tm", 4.0, 28.0, 60.0)}
    for seed in range(20):
        data, _ = simulate(400, seed)
        # the paper's model: no output offset (offset='auto' would estimate one on these
        # 2 s records from rest, whose mean exceeds their standard deviation)
        err["tm"].append(max_error(ct_subspace(data, 4, basis=takenaka_malmquist(TM), refine=False,
                                               offset=False), g_true))
        for pole in (4.0, 28.0, 60.0):
            err[pole].append(max_error(ct_subspace(data, 4, basis=laguerre(pole, 8), refine=False,
                                                   offset=False), g_true))
    tm = np.array(err["tm"])
    assert tm.max() < 1e-3
    for pole in (4.0, 28.0, 60.0):
        assert np.sum(tm < np.array(err[pole])) >= 18, pole


def test_sampled_L400_default_is_accurate(true, g_true):
    data, _ = simulate(400, 7)
    model = ct_subspace(data, 4)
    assert max_error(model, g_true) < 1e-6
    assert max_error(ct_subspace(data, 4, refine=False), g_true) < 1e-6
    assert model.info["refined"] in (True, False)


def test_paper_method_as_printed_fails_on_the_paper_example(g_true):
    data, _ = simulate(400, 0)
    for bank in (takenaka_malmquist(TM), laguerre(4.0, 8), laguerre(28.0, 8), laguerre(60.0, 8)):
        assert max_error(ct_subspace_paper(data, 4, basis=bank), g_true) > 0.1


def test_correction_regressors_remove_the_interpolation_error(g_true):
    data, _ = simulate(400, 3)
    bank = takenaka_malmquist(TM)
    with_corr = ct_subspace(data, 4, basis=bank, refine=False)
    without = ct_subspace(data, 4, basis=bank, refine=False, correction=False)
    assert with_corr.info["n_correction_regressors"] == 16       # H_1, H_2 for p = 3, FOH
    assert max_error(with_corr, g_true) < 1e-6
    assert max_error(without, g_true) > 1e-2


def test_jittered_sampling_L4000(true, g_true):
    data, _ = simulate(4000, 11, jitter=0.4)
    assert not data.is_uniform
    model = ct_subspace(data, 4)
    assert max_error(model, g_true) < 1e-2
    sub = model.info["subspace_model"]
    subspace = StateSpace(sub["A"], sub["B"], sub["C"], sub["D"], 0.0)
    assert max_error(subspace, g_true) < 1e-2


def test_jittered_fast_kernels_give_the_reference_model(true, monkeypatch):
    """Non-uniform grid: the fused modal kernels against the per-interval tables.

    Noise-free, so the model is determined to rounding (under noise the
    refinement's stopping point moves by more than 1e-10 even for a 1e-14
    perturbation of the data: see "Accuracy" in subid.methods.ct._ct_kernels). Compared
    as transfer functions and simulated outputs: the state basis is not unique.
    """
    from subid.methods.ct import _ct_kernels
    data, _ = simulate(600, 5, jitter=0.4)
    fast = ct_subspace(data, 4, refine=True, offset=False)
    monkeypatch.setattr(_ct_kernels, "modal_bank", lambda *a, **k: None)
    monkeypatch.setattr(_ct_kernels, "modal_sensitivity", lambda *a, **k: None)
    ref = ct_subspace(data, 4, refine=True, offset=False)
    assert max_relative_error(fast, ref) < 1e-9
    sims = [StateSpace(m.A, m.B, m.C, m.D, 0.0).simulate(data.u, t=data.t, x0=m.info["x0"],
                                                         hold="foh") for m in (fast, ref)]
    np.testing.assert_allclose(sims[0], sims[1], rtol=0, atol=1e-10 * np.abs(sims[1]).max())


BIAS_W = np.array([0.1, 0.5, 1.0, 2.0, 5.0])


def bias_z_scores(errors_):
    """|mean complex error| / standard error of the complex mean, per frequency."""
    E = np.array(errors_)
    se = np.sqrt((E.real.var(axis=0, ddof=1) + E.imag.var(axis=0, ddof=1)) / len(E))
    return np.abs(E.mean(axis=0)) / se


@pytest.mark.slow
def test_output_noise_small_monte_carlo(true):
    """The cheap sibling of the 50-run check below (8 runs): small error, no gross bias."""
    gb = true.freqresp(BIAS_W)[:, 0, 0]
    g = true.freqresp(W)[:, 0, 0]
    err, worst = [], []
    for r in range(8):
        data, _ = simulate(4000, r, snr_db=20)
        model = ct_subspace(data, 4)
        err.append(model.freqresp(BIAS_W)[:, 0, 0] - gb)
        worst.append(np.abs(model.freqresp(W)[:, 0, 0] - g).max())
    assert np.median(worst) < 0.1
    assert np.all(bias_z_scores(err) < 3.0), bias_z_scores(err)


@pytest.mark.long
def test_output_noise_monte_carlo_no_bias(true):
    """20 dB output noise, L = 4000, 50 runs (seeds 0-49): the default estimate is unbiased.

    For an unbiased estimator with Gaussian errors, |mean| > 2 standard errors
    happens with probability exp(-4) = 1.8 % per frequency (about 9 % for the
    five together); 200 further runs (seeds 5000-5199) gave z <= 2.02.
    """
    gb = true.freqresp(BIAS_W)[:, 0, 0]
    g = true.freqresp(W)[:, 0, 0]
    err, worst = [], []
    for r in range(50):
        data, _ = simulate(4000, r, snr_db=20)
        model = ct_subspace(data, 4)
        err.append(model.freqresp(BIAS_W)[:, 0, 0] - gb)
        worst.append(np.abs(model.freqresp(W)[:, 0, 0] - g).max())
    assert np.median(worst) < 0.1
    z = bias_z_scores(err)
    assert np.all(z < 2.0), z


@pytest.mark.slow
def test_the_printed_method_is_biased_under_noise(true):
    gb = true.freqresp(BIAS_W)[:, 0, 0]
    err = [ct_subspace_paper(simulate(4000, r, snr_db=20)[0], 4, basis=takenaka_malmquist(TM))
           .freqresp(BIAS_W)[:, 0, 0] - gb for r in range(20)]
    assert np.any(bias_z_scores(err) > 3.0), bias_z_scores(err)


# ---------------------------------------------------------------------------
# more systems and options
# ---------------------------------------------------------------------------
def mimo_system():
    rng = np.random.default_rng(5)
    A = np.array([[-1.0, 2.0, 0.0], [-2.0, -1.0, 0.0], [0.0, 0.0, -3.0]])
    return StateSpace(A, rng.standard_normal((3, 2)), rng.standard_normal((2, 3)),
                      rng.standard_normal((2, 2)), 0.0)


@pytest.mark.parametrize("hold", ["foh", "zoh"])
def test_mimo_with_feedthrough_and_held_input(hold):
    system = mimo_system()
    rng = np.random.default_rng(6)
    t = np.arange(2400) * 0.01
    u = rng.standard_normal((2400, 2))
    y = system.simulate(u, t=t, hold=hold, x0=rng.standard_normal(3))
    data = IOData(u[400:], y[400:], t=t[400:])
    model = ct_subspace(data, 3, hold=hold, feedthrough=True)
    assert max_relative_error(model, system) < 1e-8
    sub = model.info["subspace_model"]
    assert max_relative_error(StateSpace(sub["A"], sub["B"], sub["C"], sub["D"], 0.0),
                              system) < 1e-8
    assert model.n_inputs == 2 and model.n_outputs == 2 and model.dt == 0


def test_order_selection_and_initial_state(true):
    data, x = record(true, 400, seed=5)
    model = ct_subspace(data)
    assert model.order >= 4      # noise-free: the cross-validation's smallest exact order
    assert model.info["order_selection"]["rule"] == "cv"
    x0 = model.info["x0"]
    y_hat = model.simulate(data.u, t=data.t, x0=x0, hold="foh")
    if model.info["offset"]:               # the model relates the deviations from y_offset
        y_hat = y_hat + model.info["y_offset"][0]
    assert np.abs(y_hat - data.y).max() < 1e-8 * np.abs(data.y).max()


def test_info_is_complete_and_storable(true):
    data, _ = simulate(400, 2)
    model = ct_subspace(data, 4, basis=takenaka_malmquist([2 + 1j, 2 - 1j, 5, 9, 14, 30, 60, 90]))
    info = model.info
    for key in ("singular_values", "basis_poles", "order", "instruments", "iterations",
                "ac_residual", "b_regression_condition", "bd_method", "x0",
                "subspace_model", "refined", "n_correction_regressors"):
        assert key in info, key
    assert info["basis_poles"][0] == 2 + 1j
    restored = StateSpace.from_dict(model.to_dict())
    np.testing.assert_allclose(restored.info["singular_values"], info["singular_values"])


def test_dt_to_ct_baseline(true, g_true):
    data, _ = simulate(4000, 1)
    model = dt_to_ct(data, 4, method="n4sid", hold="foh")
    assert model.dt == 0 and max_error(model, g_true) < 1e-3
    assert max_error(dt_to_ct(data, 4, method="moesp", hold="foh"), g_true) < 1e-3
    jittered, _ = simulate(400, 1, jitter=0.4)
    with pytest.raises(errors.DataError, match="uniform"):
        dt_to_ct(jittered, 4)


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
def test_bad_input_raises_clear_errors(true):
    data, _ = simulate(400, 0)
    t_bad = data.t.copy()
    t_bad[10] = t_bad[9]
    with pytest.raises(errors.DataError, match="increasing|repeated"):
        ct_subspace(IOData(data.u, data.y, t=t_bad), 4)
    with pytest.raises(errors.ModelError, match="real part"):
        ct_subspace(data, 4, basis=takenaka_malmquist([4.0, -1.0]))
    short = IOData(data.u[:30], data.y[:30], t=data.t[:30])
    with pytest.raises(errors.TooFewSamplesError, match="too few"):
        ct_subspace(short, 4, basis=takenaka_malmquist(TM))
    with pytest.raises(errors.NotExcitingError):
        ct_subspace(IOData(np.zeros(400), data.y, t=data.t), 4)
    with pytest.raises(errors.DataError, match="constant"):
        ct_subspace(IOData(data.u, np.ones(400), t=data.t), 4)
    with pytest.raises(errors.DataError, match="IOData"):
        ct_subspace((data.u, data.y), 4)
    with pytest.raises(errors.ModelError, match="FilterBank"):
        ct_subspace(data, 4, basis=[4, 12])
    with pytest.raises(errors.OrderError):
        ct_subspace(data, 8, basis=takenaka_malmquist([4.0, 8.0, 12.0]))
    with pytest.raises(errors.OrderError):
        ct_subspace(data, 4, poly_order=9)
    with pytest.raises(errors.SubidError, match="instruments"):
        ct_subspace(data, 4, instruments="future")
    with pytest.raises(errors.SubidError, match="hold"):
        ct_subspace(data, 4, hold="linear")
    with pytest.raises(errors.DataError, match="shapes"):
        ct_subspace(data, 4, basis=takenaka_malmquist(TM), filtered=(np.zeros((400, 8, 1)),
                                                               np.zeros((400, 7, 1))))
    with pytest.raises(errors.ModelError, match="real basis poles"):
        ct_subspace(data, 4, basis=takenaka_malmquist([2 + 1j, 2 - 1j, 5, 9]),
                    data_equation="paper")
    with pytest.raises(errors.ModelError, match="feedthrough"):
        ct_subspace(data, 4, basis=takenaka_malmquist(TM), data_equation="paper", feedthrough=True)


@pytest.mark.parametrize("hold", ["foh", "zoh"])
@pytest.mark.slow
def test_jittered_mimo_fast_kernels_give_the_reference_model(hold, monkeypatch):
    """MIMO with feedthrough on a jittered grid: modal kernels vs per-interval tables."""
    from subid.methods.ct import _ct_kernels
    system = mimo_system()
    rng = np.random.default_rng(7)
    t = np.arange(800) * 0.01 + rng.uniform(-0.4, 0.4, 800) * 0.01
    u = rng.standard_normal((800, 2))
    data = IOData(u, system.simulate(u, t=t, hold=hold), t=t)
    fast = ct_subspace(data, 3, hold=hold, feedthrough=True)
    monkeypatch.setattr(_ct_kernels, "modal_bank", lambda *a, **k: None)
    monkeypatch.setattr(_ct_kernels, "modal_sensitivity", lambda *a, **k: None)
    ref = ct_subspace(data, 3, hold=hold, feedthrough=True)
    assert max_relative_error(fast, ref) < 1e-9
    assert max_relative_error(fast, system) < 1e-5          # the estimator on 800 samples


@pytest.mark.parametrize("length, jitter, seed", [
    pytest.param(1000, 0.1, 0, marks=pytest.mark.long),     # 5-6 s each: the long tier
    pytest.param(1000, 0.1, 5, marks=pytest.mark.long),
    (400, 0.4, 0)])
def test_noise_free_non_uniform_data_of_a_stable_plant_give_a_stable_model(length, jitter,
                                                                            seed):
    # the seed-002 plant from rest: its output grows over the record, and growing data
    # skipped the stability comparison (estimates with poles at +654 and +2976 rad/s that
    # could not even be simulated, returned without a word); two exact fits, the
    # unstable one "clearly better" at residuals 1.7e-7 against 1.1e-6, kept a pole at +3.7
    import subid
    data, _ = simulate(length, seed, jitter=jitter)
    model = subid.ct_subspace(data)
    assert model.is_stable()
    assert model.info["stability"]["action"] in ("enforced", "none")
    assert min(subid.fit_percent(model, data)) > 99


def test_epoch_time_stamps_are_accepted():
    # seconds since 1970 (1.7e9) with 5 ms steps, jittered: the intervals are known to
    # 2.4e-7 s (the stamps' rounding unit); the former bound, 1e-9 of the magnitude (1.7 s),
    # refused them. Intervals within 1,000 rounding units are still refused.
    import subid
    true = paper_system()
    data, _ = simulate(2000, 4, jitter=0.3)
    epoch = IOData(data.u, data.y, t=data.t + 1.7e9)
    model = subid.ct_subspace(epoch, 4)
    w = np.logspace(-2, 2, 100)
    G = true.freqresp(w)
    assert np.abs(model.freqresp(w) - G).max() < 1e-3 * np.abs(G).max()
    t = 1.7e9 + np.cumsum(np.full(200, 100 * np.spacing(1.7e9)))
    rng = np.random.default_rng(0)
    with pytest.raises(errors.DataError, match="below the resolution"):
        subid.ct_subspace(IOData(rng.standard_normal(200), rng.standard_normal(200), t=t), 2)


def test_an_automatic_direct_term_is_fitted_as_a_given_one():
    # feedthrough='auto' chose D on the D = 0 problem (32 correction regressors for the
    # 48 a direct term needs) and compared it with D = 0 on those folds: the seed-000
    # system (D != 0), non-uniform and noise-free, order 4: frequency-response error 0.031
    # refined, 6.3 unrefined (and D = 0 chosen on one seed of six), against 7e-11 and
    # 3.7e-4 with feedthrough=True
    import subid
    true = subid.systems.seed000_system()
    rng = np.random.default_rng(5)
    t = np.arange(1500) * 0.02 + rng.uniform(-0.3, 0.3, 1500) * 0.02
    u = np.random.default_rng(15).standard_normal((1500, 2))
    data = IOData(u, true.simulate(u, t=t, hold="foh"), t=t)
    w = np.logspace(-2, 2, 100)
    G = true.freqresp(w)
    for refine in ("auto", False):
        auto = subid.ct_subspace(data, 4, refine=refine)
        given = subid.ct_subspace(data, 4, refine=refine, feedthrough=True)
        assert auto.info["feedthrough"] and auto.info["n_correction_regressors"] == \
            given.info["n_correction_regressors"]
        np.testing.assert_allclose(auto.freqresp(w), given.freqresp(w), rtol=0,
                                   atol=1e-9 * np.abs(G).max())
    assert np.abs(auto.freqresp(w) - G).max() < 1e-3 * np.abs(G).max()


@pytest.mark.parametrize("jitter", [False, True])
def test_a_record_too_short_for_the_folds_is_identified_from_the_whole(jitter):
    # 20 samples of a first-order plant: the folds (10 samples) are too short for the
    # basis, and the default call raised "10 samples are too few" although the whole
    # record identifies the plant exactly (selection='gap' did); now the whole record's
    # singular values decide and the fold comparisons keep their first build
    import subid
    true = StateSpace([[-1.0]], [[2.0]], [[1.0]], [[0.0]], 0)
    t = np.arange(20) * 0.1
    if jitter:
        t = t + np.random.default_rng(1).uniform(-0.03, 0.03, 20)
    u = np.random.default_rng(1).standard_normal(20)
    data = IOData(u, true.simulate(u, t=t, hold="foh"), t=t)
    w = np.logspace(-1, 1, 20)
    for order in (None, 1):
        model = subid.ct_subspace(data, order)
        assert model.order == 1
        assert np.abs(model.freqresp(w) - true.freqresp(w)).max() < 1e-8
    assert "too short for the cross-validation folds" in \
        subid.ct_subspace(data).info["order_selection"]["reason"]


def test_with_the_order_given_a_converted_n4sid_start_must_be_significantly_better():
    # the seed-002 system, uniform, noise-free, 400 samples (run 4 of the published
    # table): an N4SID start 0.07 points ahead on the folds won by the criterion alone and
    # converted to a model 11 off in frequency response; the basis-filter estimate is exact
    import subid
    true = paper_system()
    data, _ = simulate(400, 4)
    model = subid.ct_subspace(data, 4)
    assert model.info["start"] == "subspace"
    assert model.info["start_selection"]["basis_filter_test"]["significant"] is False
    w = np.logspace(-2, 2, 100)
    assert np.abs(model.freqresp(w) - true.freqresp(w)).max() < 1e-6
