"""The modal normal-equation path of the B, D, x0 regression against the QR path."""

import numpy as np
import pytest

from subid import systems
from subid._kernel_args import read_only
from subid.methods.dt._regression import (
    ModalForm,
    fit_b_d_x0,
    fit_b_d_x0_modal,
    fit_b_d_x0_qr,
    modal_signals,
    modal_signals_reference,
    next_filter_state,
    normal_equations,
    piece_moments,
    regressor_maps,
    solve_normal_equations,
)


def _relative(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


def test_modal_kernel_matches_reference():
    r = np.random.default_rng(3)
    lam = np.array([0.5 + 0.6j, -0.7 + 0j, 0.2 + 0.1j])
    is_real = np.array([False, True, False])
    u, y = read_only(r.standard_normal((200, 2)), r.standard_normal((200, 3)))   # as the library
    r0 = r.standard_normal((3, 2)) + 1j * r.standard_normal((3, 2))
    r0[1] = r0[1].real
    e0 = np.array([0.3 - 0.2j, 0.4 + 0j, 1.0 + 0j])
    for tau0, n_free in ((0, 50), (30, 120), (300, 50)):
        w, r1, e1 = modal_signals(lam, is_real, u, y, r0, e0, tau0, n_free)
        w_ref, r_ref, e_ref = modal_signals_reference(lam, is_real, u, y, r0, e0, tau0, n_free)
        np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(r1, r_ref, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(e1, e_ref, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("estimate_x0,feedthrough", [(True, True), (False, True), (True, False)])
@pytest.mark.slow
def test_modal_path_equals_qr_path(seed, estimate_x0, feedthrough):
    true = systems.random_system(4, 2, 2, seed=seed)
    data = systems.simulate_data(true, 30_000, seed=seed, output_snr_db=30,
                                 x0=np.arange(1.0, 5.0))
    weights = 1.0 / data.y.std(axis=0)
    ref = fit_b_d_x0_qr(true.A, true.C, data.u, data.y, output_weights=weights,
                        estimate_x0=estimate_x0, feedthrough=feedthrough)
    fast = fit_b_d_x0_modal(true.A, true.C, data.u, data.y, output_weights=weights,
                            estimate_x0=estimate_x0, feedthrough=feedthrough, block=4096)
    assert fast is not None and fast[3]["regression_path"] == "modal"
    for name, a, b in zip("BD", fast[:2], ref[:2]):
        assert _relative(a, b) < 1e-10, name
    if estimate_x0:
        assert _relative(fast[2], ref[2]) < 1e-10
    assert fast[3]["residual_rms"] == pytest.approx(ref[3]["residual_rms"], rel=1e-10)


def test_modal_residual_exact_on_noise_free_data():
    true = systems.random_system(3, 2, 2, seed=5)
    data = systems.simulate_data(true, 20_000, seed=6, x0=np.ones(3))
    B, D, x0, diag = fit_b_d_x0(true.A, true.C, data.u, data.y)
    assert diag["regression_path"] == "modal"
    np.testing.assert_allclose(B, true.B, atol=1e-10)
    np.testing.assert_allclose(D, true.D, atol=1e-10)
    np.testing.assert_allclose(x0, np.ones(3), atol=1e-9)
    assert diag["residual_rms"] < 1e-12


def test_pieces_merge_to_the_whole_record():
    """Moments of pieces, each from a zero start, mapped through the scan of their
    filter states, give the normal equations of the whole record."""
    true = systems.random_system(4, 2, 2, seed=7)
    data = systems.simulate_data(true, 9_000, seed=8, output_snr_db=20, x0=np.ones(4))
    form = ModalForm.of(true.A, true.C)
    weights = 1.0 / data.y.std(axis=0)
    kw = dict(estimate_x0=True, feedthrough=True)
    whole, _ = piece_moments(form, data.u, data.y)
    N_whole = normal_equations(regressor_maps(form, 2, 2, **kw), whole, weights)
    borders = [0, 7, 150, 2_000, 2_001, 9_000]          # pieces shorter than n_free too
    r = np.zeros((form.lam.size, 2), dtype=complex)
    N = 0.0
    for a, b in zip(borders[:-1], borders[1:]):
        moments, r_zero = piece_moments(form, data.u[a:b], data.y[a:b], block=64)
        N = N + normal_equations(regressor_maps(form, 2, 2, t0=a, r_start=r, **kw), moments,
                                 weights)
        r = next_filter_state(form, r, r_zero, b - a)
    np.testing.assert_allclose(N, N_whole, rtol=1e-11, atol=1e-11 * np.abs(N_whole).max())
    one = solve_normal_equations(N_whole, 4, 2, 2, n_samples=9_000, **kw)
    many = solve_normal_equations(N, 4, 2, 2, n_samples=9_000, **kw)
    for a, b in zip(one[:3], many[:3]):
        assert _relative(a, b) < 1e-10


def test_fallbacks_to_qr():
    r = np.random.default_rng(0)
    u = r.standard_normal((3_000, 1))
    C = np.array([[1.0, 0.5]])
    # unstable
    A = np.array([[1.01, 0.0], [0.0, 0.5]])
    y = r.standard_normal((3_000, 1))
    assert ModalForm.of(A, C) is None
    # nearly defective: eigenvector matrix ill-conditioned
    A = np.array([[0.8, 1.0], [0.0, 0.8 + 1e-9]])
    assert ModalForm.of(A, C) is None
    B, D, x0, diag = fit_b_d_x0(A, C, u, y)
    assert diag["regression_path"] == "qr"
    with pytest.raises(ValueError, match="modal path"):
        fit_b_d_x0(A, C, u, y, path="modal")
    # nearly collinear regressors: a pole cancelled by a tiny output weight
    A = np.diag([0.5, 0.5000001])
    C = np.array([[1.0, 1.0]])
    assert ModalForm.of(A, C) is not None
    assert fit_b_d_x0_modal(A, C, u, y) is None
    assert fit_b_d_x0(A, C, u, y)[3]["regression_path"] == "qr"


def _list_map(u, y, borders):
    def map_pieces(function, arguments):
        return [function([(u[a:b], y[a:b])], *args)
                for (a, b), args in zip(zip(borders[:-1], borders[1:]), arguments)]
    return map_pieces


@pytest.mark.parametrize("defective", [False, True])
def test_second_pass_over_pieces_equals_in_memory(defective):
    """The distributed regression (modal, or its QR fall-back for a nearly defective A)
    equals the in-memory one."""
    from subid.methods.dt._bd_pass import OutputRegression
    r = np.random.default_rng(11)
    if defective:
        A = np.array([[0.8, 1.0, 0.0], [0.0, 0.8 + 1e-10, 0.3], [0.0, 0.0, -0.5]])
    else:
        A = systems.random_system(3, 2, 2, seed=12).A
    C = r.standard_normal((2, 3))
    u = r.standard_normal((5_000, 2))
    y = r.standard_normal((5_000, 2)) * [1.0, 30.0]
    weights = 1.0 / y.std(axis=0)
    borders = [0, 3, 400, 4_000, 5_000]
    second = OutputRegression(_list_map(u, y, borders), len(borders) - 1, 2, 2)
    for kw in (dict(estimate_x0=True, feedthrough=True), dict(estimate_x0=False,
                                                              feedthrough=False)):
        whole = fit_b_d_x0(A, C, u, y, output_weights=weights, **kw)
        pieces = second(A, C, **kw)
        assert pieces[3]["regression_path"] == whole[3]["regression_path"] == \
            ("qr" if defective else "modal")
        for a, b in zip(pieces[:3], whole[:3]):
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10 * np.abs(b).max())
        assert pieces[3]["residual_rms"] == pytest.approx(whole[3]["residual_rms"], rel=1e-9)


def test_second_pass_initial_state_equals_simulate_fit():
    import subid
    from subid.methods.dt._bd_pass import OutputRegression
    from subid.model.prediction import simulate_fit
    true = systems.random_system(3, 2, 2, seed=13)
    data = systems.simulate_data(true, 6_000, seed=14, output_snr_db=20, x0=[1.0, -2.0, 0.5])
    model = subid.StateSpace(true.A, true.B * 1.01, true.C, true.D, 1.0)
    second = OutputRegression(_list_map(data.u, data.y, [0, 100, 6_000]), 2, 2, 2)
    np.testing.assert_allclose(second.initial_state(model.A, model.B, model.C, model.D),
                               simulate_fit(model, data)[1], rtol=1e-10, atol=1e-10)


def test_second_pass_residual_on_noise_free_pieces():
    from subid.methods.dt._bd_pass import OutputRegression
    true = systems.random_system(3, 2, 2, seed=15)
    data = systems.simulate_data(true, 8_000, seed=16, x0=np.ones(3))
    second = OutputRegression(_list_map(data.u, data.y, [0, 50, 3_000, 8_000]), 3, 2, 2)
    B, D, x0, diag = second(true.A, true.C)
    whole = fit_b_d_x0(true.A, true.C, data.u, data.y, output_weights=1 / data.y.std(axis=0))
    assert diag["regression_passes"] == 2 and diag["residual_rms"] < 1e-12
    assert whole[3]["residual_rms"] < 1e-12
    np.testing.assert_allclose(B, true.B, atol=1e-10)
    np.testing.assert_allclose(x0, np.ones(3), atol=1e-9)


def test_scoring_only_takes_normal_equations_the_qr_path_would_have_solved():
    """Within scoring_only (the fold and innovation-check fits of the order selection),
    normal matrices of equilibrated condition 1e4..1e8 are solved instead of sent to
    the QR path: on the DaISy steamgen record (4 inputs, 4 outputs, order 12, where the
    default guard refuses them) the same B, D, x0 and residual as the QR path to about
    1e-11 relative; the guard is back in force after the block."""
    import subid
    from subid.methods.dt._regression import (
        MODAL_MAX_NORMAL_CONDITION,
        SCORING_MAX_NORMAL_CONDITION,
        scoring_only,
    )
    data = subid.datasets.load("steamgen").detrend()[:2000]
    model = subid.moesp(data, 12, horizon=10)
    weights = 1.0 / np.std(data.y, axis=0)
    args = (model.A, model.C, data.u, data.y)
    assert fit_b_d_x0_modal(*args, output_weights=weights) is None
    with scoring_only():
        fast = fit_b_d_x0_modal(*args, output_weights=weights)
        assert fit_b_d_x0(*args, output_weights=weights)[3]["regression_path"] == "modal"
    assert fit_b_d_x0_modal(*args, output_weights=weights) is None
    assert fast is not None
    condition = fast[3]["regression_condition"] ** 2
    assert MODAL_MAX_NORMAL_CONDITION < condition <= SCORING_MAX_NORMAL_CONDITION
    qr = fit_b_d_x0_qr(*args, output_weights=weights)
    for got, want in zip(fast[:3], qr[:3]):
        assert _relative(got, want) < 1e-9
    assert abs(fast[3]["residual_rms"] - qr[3]["residual_rms"]) < 1e-12 * qr[3]["residual_rms"]


def test_householder_r_is_scipy_qr():
    """householder_r (LAPACK geqrt) gives the R of scipy.linalg.qr (geqrf), signs
    included, to rounding; the output regression's QR factor through it too."""
    import scipy.linalg

    from subid.methods.dt._regression import _qr_append, householder_r
    rng = np.random.default_rng(5)
    for rows, cols in ((3000, 67), (40, 40), (20, 33), (1, 5)):
        X = rng.standard_normal((rows, cols))
        want = scipy.linalg.qr(X, mode="r")[0][:min(rows, cols)]
        got = np.triu(householder_r(np.asfortranarray(X))[:min(rows, cols)])
        assert np.max(np.abs(got - want)) <= 1e-13 * np.max(np.abs(want))
    R0 = np.triu(rng.standard_normal((12, 12)))
    rows = rng.standard_normal((500, 12))
    got = _qr_append(R0, rows, np.empty(512 * 12))
    want = scipy.linalg.qr(np.vstack([R0, rows]), mode="r")[0][:12]
    assert np.max(np.abs(got - want)) <= 1e-13 * np.max(np.abs(want))


def test_cholesky_solve_is_scipys_bit_for_bit():
    """_cholesky_solve: scipy's cho_factor/cho_solve by the same LAPACK calls, the same
    bits; a matrix that is not positive definite raises LinAlgError as scipy does."""
    import scipy.linalg

    from subid.methods.dt._regression import _cholesky_solve
    rng = np.random.default_rng(12)
    for p in (1, 5, 30, 117):
        X = rng.standard_normal((p + 50, p))
        G = X.T @ X
        b = rng.standard_normal(p)
        want = scipy.linalg.cho_solve(scipy.linalg.cho_factor(G, check_finite=False), b,
                                      check_finite=False)
        assert np.array_equal(_cholesky_solve(G, b), want)
    with pytest.raises(np.linalg.LinAlgError):
        _cholesky_solve(-np.eye(3), np.ones(3))
