"""Basis filter banks (seed 002): orthonormality, exact filtering, kernels, errors."""

import numpy as np
import pytest
import scipy.linalg

from subid import errors
from subid._kernel_args import read_only
from subid.methods.ct import _ct_kernels
from subid.methods.ct._ct_estimate import _poisson_chain_bank
from subid.methods.ct.basis import FilterBank, default_basis, laguerre, legendre, takenaka_malmquist

BANKS = {
    "tm-real": lambda: takenaka_malmquist([4, 12, 20, 28, 36, 44, 52, 60]),
    "tm-complex": lambda: takenaka_malmquist([3 + 4j, 3 - 4j, 10, 20 + 5j, 20 - 5j, 40]),
    "laguerre": lambda: laguerre(5.0, 6),
    "kautz": lambda: laguerre(2 + 3j, 6),
    "legendre": lambda: legendre(8.0, 5),
}


@pytest.fixture(params=sorted(BANKS))
def bank(request):
    return BANKS[request.param]()


def tm_formula(poles, s):
    """The TM functions (2) for real or complex poles, in closed form."""
    out = []
    for k, sk in enumerate(poles):
        val = np.sqrt(2 * sk.real) / (s + sk)
        for sl in poles[:k]:
            val = val * (s - np.conj(sl)) / (s + sl)
        out.append(val)
    return np.stack(out, axis=1)


# ---------------------------------------------------------------------------
# structure
# ---------------------------------------------------------------------------
def test_gramian_is_identity(bank):
    F, g = bank.realization()
    P = scipy.linalg.solve_continuous_lyapunov(F, -np.outer(g, g))
    np.testing.assert_allclose(P, np.eye(bank.n_functions), atol=1e-12)


def test_real_poles_match_formula_2():
    poles = [4.0, 12.0, 20.0, 28.0]
    bank = takenaka_malmquist(poles)
    s = 1j * np.logspace(-1, 2, 30)
    np.testing.assert_allclose(bank.freqresp(s.imag), tm_formula(np.array(poles), s),
                               rtol=1e-12, atol=1e-14)


def test_complex_pair_spans_the_complex_tm_functions():
    poles = np.array([3 + 4j, 3 - 4j, 10.0])
    bank = takenaka_malmquist(poles)
    s = 1j * np.logspace(-1, 2, 60)
    real_basis = bank.freqresp(s.imag)
    complex_tm = tm_formula(poles, s)
    # the complex TM functions are combinations of the real ones and vice versa
    coef = np.linalg.lstsq(real_basis, complex_tm, rcond=None)[0]
    np.testing.assert_allclose(real_basis @ coef, complex_tm, atol=1e-12)
    assert np.linalg.matrix_rank(complex_tm, tol=1e-9) == 3


def test_functions_are_the_impulse_responses(bank):
    F, g = bank.realization()
    t = np.array([0.0, 0.013, 0.2, 0.7, 1.5, 0.2])
    expected = np.stack([scipy.linalg.expm(F * ti) @ g for ti in t])
    np.testing.assert_allclose(bank.functions(t), expected, atol=1e-13)


def test_laguerre_and_legendre_are_tm_special_cases():
    np.testing.assert_array_equal(laguerre(3.0, 4).poles, (3.0, 3.0, 3.0, 3.0))
    np.testing.assert_allclose(legendre(2.0, 4).poles, [1.0, 3.0, 5.0, 7.0])
    F1, g1 = laguerre(3.0, 4).realization()
    F2, g2 = takenaka_malmquist([3, 3, 3, 3]).realization()
    np.testing.assert_array_equal(F1, F2)
    assert laguerre(1 + 1j, 4).n_functions == 4


def test_default_basis_spans_record_to_quarter_nyquist():
    t = np.arange(4000) * 0.005
    bank = default_basis(t)
    poles = np.array(bank.poles)
    assert poles.size == 8 and bank.is_real
    np.testing.assert_allclose(poles[0], 4 * np.pi / (t[-1] - t[0]), rtol=1e-12)
    np.testing.assert_allclose(poles[-1], np.pi / 0.005 / 4, rtol=1e-12)
    ratios = poles[1:] / poles[:-1]
    np.testing.assert_allclose(ratios, ratios[0], rtol=1e-12)
    short = np.array(default_basis(np.arange(50) * 0.005).poles)
    assert short[-1] / short[0] == pytest.approx(20.0)


# ---------------------------------------------------------------------------
# filtering
# ---------------------------------------------------------------------------
def grids(n, h, seed):
    rng = np.random.default_rng(seed)
    uniform = np.arange(n) * h
    jittered = np.arange(n) * h + rng.uniform(-0.4, 0.4, n) * h
    return {"uniform": uniform, "jittered": jittered}


@pytest.mark.parametrize("hold, order", [("zoh", 0), ("foh", 1)])
def test_filtering_a_held_signal_is_exact(bank, hold, order):
    for name, t in grids(300, 0.01, 1).items():
        v = np.random.default_rng(2).standard_normal((300, 2))
        out = bank.filter(v, t, poly_order=order)
        exact = bank.state_space(2).simulate(v, t=t, hold=hold)
        np.testing.assert_allclose(out.reshape(300, -1), exact, atol=1e-12, err_msg=name)


def test_polynomials_up_to_degree_p_are_filtered_exactly():
    bank = takenaka_malmquist([2.0, 5.0, 9.0])
    F, g = bank.realization()
    coef = [1.0, -0.5, 0.3, 0.2]                       # v(t) = 1 - t/2 + 0.3 t^2 + 0.2 t^3
    # v generated exactly by the integrator chain w' = J w, v = c w
    J = np.diag([1.0, 1.0, 1.0], 1)                    # w = [t^3/6, t^2/2, t, 1] reversed
    w0 = np.array([0.0, 0.0, 0.0, 1.0])
    c = np.array([coef[3] * 6, coef[2] * 2, coef[1], coef[0]])
    Aug = np.block([[J, np.zeros((4, 3))], [np.outer(g, c), F]])
    for t in grids(120, 0.02, 3).values():
        v = np.polyval(coef[::-1], t - t[0])
        exact = np.stack([(scipy.linalg.expm(Aug * (tk - t[0])) @ np.r_[w0, 0, 0, 0])[4:]
                          for tk in t])
        np.testing.assert_allclose(bank.filter(v, t, poly_order=3)[:, :, 0], exact,
                                   atol=1e-11)


def test_interpolation_error_shrinks_with_the_step_as_h_to_the_p_plus_1():
    bank = takenaka_malmquist([3.0, 7.0])
    errs = {}
    for p in (1, 3):
        e = []
        for h in (0.02, 0.01):
            t = np.arange(int(2 / h) + 1) * h
            v = np.sin(3 * t) + 0.5 * np.cos(7 * t)
            fine = np.arange(int(2 / h) * 64 + 1) * (h / 64)          # reference: 64x finer
            vf = np.sin(3 * fine) + 0.5 * np.cos(7 * fine)
            ref = bank.filter(vf, fine, poly_order=5)[::64]
            e.append(np.abs(bank.filter(v, t, poly_order=p) - ref).max())
        errs[p] = e
    assert errs[1][0] / errs[1][1] > 3.0          # ~ 2^2
    assert errs[3][0] / errs[3][1] > 12.0         # ~ 2^4
    assert errs[3][1] < errs[1][1] / 100


def test_sections_filtering_is_exact_for_one_section_and_converges():
    one = takenaka_malmquist([5.0])
    t = np.arange(200) * 0.01
    v = np.cos(2 * t)
    np.testing.assert_allclose(one.filter(v, t, chain="sections"), one.filter(v, t), atol=1e-15)
    bank = takenaka_malmquist([4.0, 12.0, 20.0])
    errors_ = []
    for h in (0.02, 0.005):
        t = np.arange(int(2 / h) + 1) * h
        v = np.cos(2 * t) + np.sin(11 * t)
        errors_.append(np.abs(bank.filter(v, t, chain="sections")
                              - bank.filter(v, t)).max())
    assert errors_[1] < errors_[0] / 20 and errors_[1] < 1e-6


def test_paper_input_stack_exact_chain_matches_its_definition():
    bank = takenaka_malmquist([4.0, 12.0, 20.0])
    t = np.arange(150) * 0.01
    u = np.random.default_rng(4).standard_normal(150)
    stack = bank.paper_input_stack(u, t, poly_order=1, chain="exact")[:, :, 0]
    assert stack.shape == (150, 6)
    # (j, l) = (1, 2): u through M_1, then through the all-pass W_2 -- simulated exactly
    s1, s2 = 12.0, 20.0
    from subid.model.statespace import StateSpace
    chain = StateSpace([[-s1, 0], [np.sqrt(2 * s2), -s2]],
                       [[np.sqrt(2 * s1)], [0.0]], [[1.0, -np.sqrt(2 * s2)]], 0, 0.0)
    np.testing.assert_allclose(stack[:, 4], chain.simulate(u, t=t, hold="foh")[:, 0],
                               atol=1e-12)
    # all stacked signals lie in the span of the N bank outputs: rank N
    assert np.linalg.matrix_rank(stack, tol=1e-10 * np.abs(stack).max()) == 3


# ---------------------------------------------------------------------------
# kernels against their references
# ---------------------------------------------------------------------------
def random_tables(rng, K, N, P, r):
    Phi = rng.standard_normal((K, N, N)) * 0.3
    W = rng.standard_normal((K, P, N, r))
    return Phi, W


def test_bank_kernel_matches_reference():
    rng = np.random.default_rng(5)
    Phi, W = random_tables(rng, 3, 4, 3, 2)
    L = 50
    tab = rng.integers(0, 3, L - 1)
    starts = np.clip(np.arange(L - 1) - 1, 0, L - 3).astype(np.int64)
    v = rng.standard_normal((L, 2, 3))
    x0 = rng.standard_normal((4, 3))
    args = read_only(Phi, W, tab, starts, v, x0)    # the signature the library compiles
    a = _ct_kernels.bank_loop(*args, np.empty((L, 4, 3)))
    b = _ct_kernels.bank_loop_ref(*args, np.empty((L, 4, 3)))
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_sensitivity_kernel_matches_reference():
    rng = np.random.default_rng(6)
    n, m, ny, L = 3, 2, 2, 40
    Phi, W = random_tables(rng, 2, n, 2, n)
    tab = rng.integers(0, 2, L - 1)
    starts = np.arange(L - 1, dtype=np.int64)
    u = rng.standard_normal((L, m))
    C = rng.standard_normal((ny, n))
    out = []
    for kernel in (_ct_kernels.sens_loop, _ct_kernels.sens_loop_ref):
        Z, P0 = np.zeros((m, n, n)), np.eye(n)
        rb, rx = np.empty((L, ny, n, m)), np.empty((L, ny, n))
        kernel(*read_only(Phi, W, tab, starts, u, C), Z, P0, rb, rx)
        out.append((rb, rx))
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=1e-12, atol=1e-12)


def test_sensitivity_rows_reproduce_a_simulation():
    from subid.model.statespace import StateSpace
    rng = np.random.default_rng(7)
    A = np.array([[-1.0, 2.0], [-2.0, -0.5]])
    B = rng.standard_normal((2, 2))
    C = rng.standard_normal((1, 2))
    x0 = rng.standard_normal(2)
    for name, t in grids(200, 0.02, 8).items():
        u = rng.standard_normal((200, 2))
        rb, rx = _ct_kernels.run_sensitivity(A, C, t, u, 1, uniform=name == "uniform")
        y = np.einsum("lpnm,nm->lp", rb, B) + rx @ x0
        ref = StateSpace(A, B, C, 0, 0.0).simulate(u, t=t, x0=x0, hold="foh")
        np.testing.assert_allclose(y, ref, atol=1e-12, err_msg=name)


def test_nonuniform_path_agrees_with_uniform_path_across_chunks(monkeypatch):
    monkeypatch.setattr(_ct_kernels, "_CHUNK", 37)
    monkeypatch.setattr(_ct_kernels, "_MODAL_CHUNK", 41)
    bank = takenaka_malmquist([4.0, 9.0, 3 + 2j, 3 - 2j])
    F, g = bank.realization()
    t = np.arange(300) * 0.01
    v = np.random.default_rng(9).standard_normal((300, 2))
    a = _ct_kernels.run_bank(F, g, t, v, 3, uniform=True)
    for use_eig, fast in ((False, False), (True, False), (True, True)):
        b = _ct_kernels.run_bank(F, g, t, v, 3, uniform=False, use_eig=use_eig, fast=fast)
        np.testing.assert_allclose(a, b, atol=1e-11)


def test_eigen_tables_agree_with_matrix_exponentials():
    rng = np.random.default_rng(10)
    F = np.array([[-3.0, 1.0, 0.0], [-1.0, -3.0, 0.0], [0.5, 0.2, -7.0]])
    G = rng.standard_normal((3, 2))
    steps = rng.uniform(0.002, 0.02, 25)
    nodes = np.sort(rng.uniform(-1.5, 2.5, (25, 4)), axis=1)
    Phi1, W1 = _ct_kernels.interval_tables(F, G, steps, nodes)
    Phi2, W2 = _ct_kernels._eig_tables(F, G, steps, nodes)
    np.testing.assert_allclose(Phi1, Phi2, atol=1e-13)
    np.testing.assert_allclose(W1, W2, atol=1e-12)
    # a defective matrix is refused
    assert _ct_kernels._eig_tables(np.array([[-1.0, 1.0], [0.0, -1.0]]), G[:2], steps,
                                   nodes) is None


MODAL_CASES = {
    "tm-real": lambda: takenaka_malmquist([4, 12, 20, 28, 36, 44, 52, 60]).realization(),
    "tm-complex": lambda: takenaka_malmquist([3 + 4j, 3 - 4j, 10, 20 + 5j, 20 - 5j,
                                              40]).realization(),
    "laguerre": lambda: laguerre(5.0, 6).realization(),
    "kautz": lambda: laguerre(2 + 3j, 6).realization(),
    "kautz8": lambda: laguerre(5 + 5j, 8).realization(),   # clusters move ~1e-3 in zgees
    "poisson-chain": lambda: _poisson_chain_bank(default_basis(np.arange(400) * 0.01), 2),
}


@pytest.mark.parametrize("name", sorted(MODAL_CASES))
@pytest.mark.parametrize("order", [0, 1, 3])
def test_modal_bank_matches_the_table_reference(name, order):
    """The fused block-modal kernel against per-interval tables (expm / eig), jittered grid.

    The real TM bank's eigenvectors have condition 8e4: both eigen routes
    (tables and kernel) sit 1e-12 from the matrix exponentials there.
    """
    F, g = MODAL_CASES[name]()
    t = grids(400, 0.01, 21)["jittered"]
    rng = np.random.default_rng(22)
    v = rng.standard_normal((400, 2))
    x0 = rng.standard_normal((F.shape[0], 2))
    assert _ct_kernels.modal_form(F, np.diff(t).max()) is not None
    a = _ct_kernels.run_bank(F, g, t, v, order, uniform=False, x0=x0)
    b = _ct_kernels.run_bank(F, g, t, v, order, uniform=False, x0=x0, fast=False)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.abs(b).max())


def test_modal_bank_large_steps_use_the_recursion():
    """|lam h| up to 12: the J_{0,j} recursion branch of the kernel, matrix input."""
    F, _ = takenaka_malmquist([4, 20 + 30j, 20 - 30j, 150]).realization()
    G = np.random.default_rng(23).standard_normal((4, 2))
    t = grids(300, 0.05, 24)["jittered"]
    v = np.random.default_rng(25).standard_normal((300, 2))
    a = _ct_kernels.run_bank(F, G, t, v, 3, uniform=False)
    b = _ct_kernels.run_bank(F, G, t, v, 3, uniform=False, fast=False)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())


@pytest.mark.parametrize("order", [0, 1, 3])
def test_modal_sensitivity_matches_the_table_reference(order):
    rng = np.random.default_rng(26)
    A = np.array([[-1.0, 2.0, 0.0, 0.0], [-2.0, -0.5, 0.0, 0.0], [0.0, 0.0, -3.0, 1.0],
                  [0.3, 0.0, 0.0, -8.0]])
    C = rng.standard_normal((2, 4))
    t = grids(500, 0.02, 27)["jittered"]
    u = rng.standard_normal((500, 3))
    form = _ct_kernels.modal_form(A, np.diff(t).max(), clusters=False)
    assert form is not None and form.mirror.sum() == 1           # one conjugate pair
    a = _ct_kernels.run_sensitivity(A, C, t, u, order, uniform=False)
    b = _ct_kernels.run_sensitivity(A, C, t, u, order, uniform=False, fast=False)
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * np.abs(y).max())


def test_modal_form_refuses_what_it_cannot_do_and_the_tables_take_over():
    h = 0.01
    # defective A: no modal sensitivity (the table path runs, and is exact)
    A = np.array([[-1.0, 1.0], [0.0, -1.0]])
    assert _ct_kernels.modal_form(A, h, clusters=False) is None
    assert _ct_kernels.modal_form(A, h) is not None                # one Jordan cluster
    # nearly parallel invariant subspaces of separate eigenvalues
    assert _ct_kernels.modal_form(np.array([[-1.0, 1e8], [0.0, -1.1]]), h) is None
    # close eigenvalues with a huge coupling form one cluster, filtered exactly
    Fc, g = np.array([[-1.0, 1e3], [0.0, -1.0005]]), np.array([0.0, 1.0])
    form = _ct_kernels.modal_form(Fc, h)
    assert form is not None and list(form.terms) == [form.npow.shape[0]]
    t = grids(200, h, 30)["jittered"]
    v = np.random.default_rng(31).standard_normal((200, 1))
    a = _ct_kernels.run_bank(Fc, g, t, v, 1, uniform=False)
    b = _ct_kernels.run_bank(Fc, g, t, v, 1, uniform=False, fast=False)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())
    # a cluster too fast for the series (|lam h| > 2)
    assert _ct_kernels.modal_form(np.array([[-300.0, 1.0], [0.0, -300.0]]), h) is None
    C = np.array([[1.0, 0.5]])
    t = grids(200, h, 28)["jittered"]
    u = np.random.default_rng(29).standard_normal((200, 1))
    from subid.model.statespace import StateSpace
    rb, rx = _ct_kernels.run_sensitivity(A, C, t, u, 1, uniform=False)
    B, x0 = np.array([[0.3], [1.0]]), np.array([1.0, -2.0])
    y = np.einsum("lpnm,nm->lp", rb, B) + rx @ x0
    ref = StateSpace(A, B, C, 0, 0.0).simulate(u, t=t, x0=x0, hold="foh")
    np.testing.assert_allclose(y, ref, atol=1e-12)


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("poles", [[4, 0, 8], [4, -1], [1j, -1j], [2 + 1j], [4, float("nan")]])
def test_bad_poles_raise(poles):
    with pytest.raises(errors.ModelError):
        takenaka_malmquist(poles)


def test_bad_constructor_arguments_raise():
    with pytest.raises(errors.ModelError):
        takenaka_malmquist([])
    with pytest.raises(errors.ModelError):
        takenaka_malmquist("4, 12")
    with pytest.raises(errors.OrderError):
        laguerre(4, 0)
    with pytest.raises(errors.OrderError):
        laguerre(1 + 1j, 3)
    with pytest.raises(errors.ModelError):
        legendre(-2.0, 4)
    with pytest.raises(errors.ModelError):
        laguerre(0.0, 4)


def test_bad_filter_arguments_raise():
    bank = takenaka_malmquist([4.0, 8.0])
    t = np.arange(10) * 0.1
    with pytest.raises(errors.DataError):
        bank.filter(np.ones(10), t[::-1])                        # decreasing time stamps
    with pytest.raises(errors.DataError):
        bank.filter(np.ones(10), np.r_[t[:5], t[4:9]])           # repeated time stamp
    with pytest.raises(errors.TooFewSamplesError):
        bank.filter(np.ones(3), t[:3], poly_order=3)
    with pytest.raises(errors.OrderError):
        bank.filter(np.ones(10), t, poly_order=-1)
    with pytest.raises(errors.DataError):
        bank.filter(np.ones(10), t, chain="approximate")
    with pytest.raises(errors.DataError):
        bank.filter(np.r_[np.ones(9), np.nan], t)
    with pytest.raises(errors.ModelError):
        takenaka_malmquist([1 + 1j, 1 - 1j]).paper_input_stack(np.ones(10), t)
    with pytest.raises(errors.DataError):
        bank.functions([-1.0])
    assert isinstance(bank, FilterBank)
