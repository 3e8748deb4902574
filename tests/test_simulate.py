"""Simulation: numba kernels, discrete and continuous-time StateSpace.simulate."""

import numpy as np
import pytest
from scipy import integrate, linalg, signal

from subid._kernel_args import frozen
from subid.data import IOData
from subid.errors import DataError, OptionError
from subid.model import _simulate
from subid.model.statespace import StateSpace


def random_system(seed, n=4, m=2, p=3, continuous=False):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    if continuous:
        A -= (np.linalg.eigvals(A).real.max() + 0.5) * np.eye(n)
    else:
        A *= 0.9 / np.abs(np.linalg.eigvals(A)).max()
    B = rng.standard_normal((n, m))
    C = rng.standard_normal((p, n))
    D = rng.standard_normal((p, m))
    return A, B, C, D


def rel_err(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


# ---------------------------------------------------------------------------
# kernels against the numpy references
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("use_g1", [False, True])
def test_tv_kernel_matches_reference(use_g1):
    rng = np.random.default_rng(3)
    n, m, p, K, N = 3, 2, 2, 5, 200
    Phi = 0.3 * rng.standard_normal((K, n, n))
    G0 = rng.standard_normal((K, n, m))
    G1 = rng.standard_normal((K, n, m))
    idx = rng.integers(0, K, N - 1)
    C = rng.standard_normal((p, n))
    D = rng.standard_normal((p, m))
    u = rng.standard_normal((N, m))
    x0 = rng.standard_normal(n)
    Phi, G0, G1, C, D, u, x0 = map(frozen, (Phi, G0, G1, C, D, u, x0))   # as the library
    idx = frozen(idx, np.int64)
    y, x = _simulate.tv_loop(Phi, G0, G1, idx, C, D, u, x0, use_g1)
    y_ref, x_ref = _simulate.tv_loop_ref(Phi, G0, G1, idx, C, D, u, x0, use_g1)
    assert rel_err(y, y_ref) < 1e-12
    assert rel_err(x, x_ref) < 1e-12
    # G1 really is (not) used
    y2, _ = _simulate.tv_loop(Phi, G0, frozen(2 * G1), idx, C, D, u, x0, use_g1)
    assert np.array_equal(y, y2) != use_g1


@pytest.mark.parametrize("N", [0, 1, 2, 300])
def test_lti_kernel_matches_reference_and_table_kernel(N):
    """The discrete LTI kernel: the reference recursion to rounding, and the
    time-varying kernel with a one-entry table to the bit (the same sums in the
    same order)."""
    rng = np.random.default_rng(N + 7)
    A, B, C, D = random_system(N + 1, n=5, m=3, p=2)
    u = rng.standard_normal((N, 3))
    x0 = rng.standard_normal(5)
    A, B, C, D, u, x0 = map(frozen, (A, B, C, D, u, x0))      # as the library passes them
    y, x = _simulate.lti_loop(A, B, C, D, u, x0)
    assert y.shape == (N, 2) and x.shape == (N, 5)
    table = (frozen(A[None]), frozen(B[None]), frozen(np.zeros((1, 5, 3))),
             frozen(np.zeros(max(N - 1, 0)), np.int64), C, D, u, x0, False)
    y_ref, x_ref = _simulate.tv_loop_ref(*table)
    y_tv, x_tv = _simulate.tv_loop(*table)
    if N:
        assert rel_err(y, y_ref) < 1e-12 and rel_err(x, x_ref) < 1e-12
        np.testing.assert_array_equal(x[0], x0)
    np.testing.assert_array_equal(y, y_tv)
    np.testing.assert_array_equal(x, x_tv)


def test_expm_blocks_closed_forms():
    A, B, _, _ = random_system(4, continuous=True)
    steps = np.array([0.05, 0.3, 1.1])
    Phi, G1, G2 = _simulate.expm_blocks(A, B, steps, "foh")
    Phi_z, G1_z, none = _simulate.expm_blocks(A, B, steps, "zoh")
    assert none is None
    for k, h in enumerate(steps):
        ph = linalg.expm(A * h)
        g1 = np.linalg.solve(A, (ph - np.eye(4)) @ B)
        g2 = np.linalg.solve(A, g1 / h - B)
        np.testing.assert_allclose(Phi[k], ph, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(Phi_z[k], ph, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(G1[k], g1, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(G1_z[k], g1, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(G2[k], g2, rtol=1e-9, atol=1e-11)


# ---------------------------------------------------------------------------
# discrete time
# ---------------------------------------------------------------------------
def test_discrete_simulate_matches_dlsim_with_x0():
    A, B, C, D = random_system(5)
    dt = 0.2
    sys = StateSpace(A, B, C, D, dt)
    rng = np.random.default_rng(6)
    u = rng.standard_normal((150, 2))
    x0 = rng.standard_normal(4)
    _, y_ref, x_ref = signal.dlsim((A, B, C, D, dt), u, x0=x0)
    y, x = sys.simulate(u, x0=x0, return_state=True)
    assert rel_err(y, y_ref) < 1e-12
    assert rel_err(x, x_ref) < 1e-12
    # x0 honoured: the free response differs from the zero-state one
    y0 = sys.simulate(u)
    _, y0_ref, _ = signal.dlsim((A, B, C, D, dt), u)
    assert rel_err(y0, y0_ref) < 1e-12
    assert np.abs(y - y0).max() > 1e-3


def test_discrete_single_input_1d_and_time_stamps():
    A, B, C, D = random_system(7, m=1, p=1)
    sys = StateSpace(A, B, C, D, 0.5)
    u = np.sin(np.arange(40.0))
    y = sys.simulate(u)
    assert y.shape == (40, 1)
    t = 3.0 + 0.5 * np.arange(40)
    np.testing.assert_array_equal(sys.simulate(u, t), y)
    with pytest.raises(DataError, match="period dt=0.5"):
        sys.simulate(u, 0.25 * np.arange(40))
    with pytest.raises(DataError, match="increasing"):
        sys.simulate(u, -t)
    data = IOData(u, np.zeros(40), dt=0.5)
    np.testing.assert_array_equal(sys.simulate(data), y)
    with pytest.raises(DataError, match="dt=1.0"):
        sys.simulate(IOData(u, np.zeros(40)))
    t_bad = np.cumsum(np.linspace(0.4, 0.6, 40))
    with pytest.raises(DataError, match="non-uniform"):
        sys.simulate(IOData(u, np.zeros(40), t=t_bad))
    with pytest.raises(DataError, match="not both"):
        sys.simulate(data, t)


def test_simulate_input_errors():
    A, B, C, D = random_system(8)
    sys = StateSpace(A, B, C, D, 1.0)
    with pytest.raises(DataError, match="1 channel but the model has 2 inputs"):
        sys.simulate(np.ones(10))
    with pytest.raises(DataError, match="transposed"):
        sys.simulate(np.ones((2, 10)))
    with pytest.raises(DataError, match="NaN"):
        sys.simulate(np.array([[1.0, np.nan]] * 3))
    with pytest.raises(DataError, match=r"x0 has shape \(3,\).*order is 4"):
        sys.simulate(np.ones((5, 2)), x0=np.zeros(3))
    with pytest.raises(OptionError, match="hold"):
        sys.simulate(np.ones((5, 2)), hold="cubic")
    with pytest.raises(DataError, match="no samples"):
        sys.simulate(np.ones((0, 2)))
    # x0 as a column is accepted
    y = sys.simulate(np.ones((5, 2)), x0=np.ones((4, 1)))
    np.testing.assert_allclose(y, sys.simulate(np.ones((5, 2)), x0=np.ones(4)))


def test_model_without_inputs():
    A = np.array([[0.5, 1.0], [0.0, 0.2]])
    sys = StateSpace(A, np.zeros((2, 0)), [[1.0, 0.0]], 0, 1.0)
    y = sys.simulate(np.zeros((4, 0)), x0=[0.0, 1.0])
    np.testing.assert_allclose(y[:, 0], [0.0, 1.0, 0.7, 0.39])


# ---------------------------------------------------------------------------
# continuous time
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("hold, interp", [("zoh", False), ("foh", True)])
def test_ct_uniform_matches_lsim(hold, interp):
    A, B, C, D = random_system(9, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    rng = np.random.default_rng(10)
    t = np.linspace(0.0, 6.0, 301)
    u = rng.standard_normal((301, 2))
    x0 = rng.standard_normal(4)
    _, y_ref, x_ref = signal.lsim((A, B, C, D), u, t, X0=x0, interp=interp)
    y, x = sys.simulate(u, t, x0=x0, hold=hold, return_state=True)
    assert rel_err(y, y_ref) < 1e-10
    assert rel_err(x, x_ref) < 1e-10


def test_ct_requires_time_stamps():
    sys = StateSpace(*random_system(11, continuous=True), 0)
    with pytest.raises(DataError, match="continuous-time model.*time stamps"):
        sys.simulate(np.ones((10, 2)))
    with pytest.raises(DataError, match="5 entries but the signals have 10"):
        sys.simulate(np.ones((10, 2)), np.arange(5.0))


def _nonuniform_grid(seed, N):
    rng = np.random.default_rng(seed)
    return np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.2, N - 1))])


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_ct_nonuniform_matches_closed_form_recursion(hold):
    A, B, C, D = random_system(12, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    t = _nonuniform_grid(13, 120)
    rng = np.random.default_rng(14)
    u = rng.standard_normal((120, 2))
    x0 = rng.standard_normal(4)
    y, x = sys.simulate(u, t, x0=x0, hold=hold, return_state=True)
    # independent recursion with closed-form integrals (A is invertible)
    xk = x0.copy()
    for k in range(120):
        np.testing.assert_allclose(x[k], xk, rtol=1e-9, atol=1e-11)
        np.testing.assert_allclose(y[k], C @ xk + D @ u[k], rtol=1e-9, atol=1e-11)
        if k + 1 < 120:
            h = t[k + 1] - t[k]
            ph = linalg.expm(A * h)
            g1 = np.linalg.solve(A, (ph - np.eye(4)) @ B)
            if hold == "zoh":
                xk = ph @ xk + g1 @ u[k]
            else:
                g2 = np.linalg.solve(A, g1 / h - B)
                xk = ph @ xk + (g1 - g2) @ u[k] + g2 @ u[k + 1]


def test_ct_nonuniform_zoh_matches_ode_solver():
    A, B, C, D = random_system(15, n=3, m=1, p=1, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    t = _nonuniform_grid(16, 25)
    u = np.cos(3 * t)[:, None]
    y = sys.simulate(u, t, hold="zoh")
    x = np.zeros(3)
    for k in range(24):   # integrate interval by interval, input held
        sol = integrate.solve_ivp(lambda _, z, k=k: A @ z + B[:, 0] * u[k, 0], (t[k], t[k + 1]), x,
                                  rtol=1e-11, atol=1e-13, method="DOP853")
        x = sol.y[:, -1]
    np.testing.assert_allclose(y[-1], C @ x + D @ u[-1], rtol=1e-7, atol=1e-10)


def test_ct_foh_ramp_is_exact():
    # x' = -a x + b u, y = x, u(t) = t: x(t) = x0 e^{-at} + b (t/a - (1 - e^{-at})/a^2)
    a, b, x0 = 1.7, 0.8, 0.3
    sys = StateSpace([[-a]], [[b]], [[1.0]], 0, 0)
    t = np.array([0.0, 0.1, 0.35, 0.4, 1.3, 1.31, 2.9, 5.0])
    y = sys.simulate(t, t, x0=[x0], hold="foh")[:, 0]
    exact = x0 * np.exp(-a * t) + b * (t / a - (1 - np.exp(-a * t)) / a**2)
    np.testing.assert_allclose(y, exact, rtol=1e-12, atol=1e-14)
    # zero-order hold does not reproduce the ramp
    y_zoh = sys.simulate(t, t, x0=[x0], hold="zoh")[:, 0]
    assert np.abs(y_zoh - exact).max() > 1e-2


def test_ct_piecewise_linear_input_is_exact():
    # triangle input with its kink on a sample: u = t for t <= 1, 2 - t after
    a, b = 0.9, 1.0
    sys = StateSpace([[-a]], [[b]], [[1.0]], 0, 0)
    t = np.array([0.0, 0.25, 1.0, 1.6, 2.0, 3.0])
    u = np.where(t <= 1, t, 2 - t)
    y = sys.simulate(u, t, hold="foh")[:, 0]

    def ramp_response(x0, u0, slope, tau):  # x' = -a x + b (u0 + slope s)
        e = np.exp(-a * tau)
        return x0 * e + b * (u0 * (1 - e) / a + slope * (tau / a - (1 - e) / a**2))

    x1 = ramp_response(0.0, 0.0, 1.0, 1.0)
    expected = np.where(t <= 1, ramp_response(0.0, 0.0, 1.0, t),
                        ramp_response(x1, 1.0, -1.0, t - 1.0))
    np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-14)


def test_ct_with_iodata_uses_its_time_stamps():
    A, B, C, D = random_system(17, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    t = _nonuniform_grid(18, 50)
    u = np.random.default_rng(19).standard_normal((50, 2))
    data = IOData(u, np.zeros(50), t=t)
    np.testing.assert_array_equal(sys.simulate(data, hold="foh"),
                                  sys.simulate(u, t, hold="foh"))


def test_ct_caches_one_discretisation_per_distinct_step(monkeypatch):
    A, B, C, D = random_system(20, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    calls = []
    real = _simulate.expm_blocks

    def spy(A_, B_, steps, hold):
        calls.append(np.array(steps, dtype=float))
        return real(A_, B_, steps, hold)

    monkeypatch.setattr(_simulate, "expm_blocks", spy)
    u = np.ones((41, 2))
    sys.simulate(u, np.linspace(0, 2, 41))
    assert len(calls) == 1 and np.unique(calls[0]).size == 1
    calls.clear()
    steps = np.where(np.arange(40) % 3 == 0, 0.125, 0.25)   # exact in binary
    sys.simulate(u, np.concatenate([[0.0], np.cumsum(steps)]), hold="foh")
    assert len(calls) == 1 and calls[0].size == 2


def test_ct_chunked_nonuniform_equals_single_pass(monkeypatch):
    A, B, C, D = random_system(21, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    t = _nonuniform_grid(22, 700)
    u = np.random.default_rng(23).standard_normal((700, 2))
    x0 = np.ones(4)
    y_one, x_one = sys.simulate(u, t, x0=x0, hold="foh", return_state=True)
    monkeypatch.setattr(_simulate, "_EXPM_STACK_FLOATS", 1)   # chunks of 256 steps
    y_chk, x_chk = sys.simulate(u, t, x0=x0, hold="foh", return_state=True)
    assert rel_err(y_chk, y_one) < 1e-12
    assert rel_err(x_chk, x_one) < 1e-12


def test_ct_single_sample():
    A, B, C, D = random_system(24, continuous=True)
    sys = StateSpace(A, B, C, D, 0)
    u = np.array([[1.0, -2.0]])
    x0 = np.arange(4.0)
    y = sys.simulate(u, [0.0], x0=x0)
    np.testing.assert_allclose(y[0], C @ x0 + D @ u[0])
