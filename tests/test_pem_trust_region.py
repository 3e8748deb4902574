"""The optimiser of subid.pem (subid.methods.dt._trust_region): scipy's trust-region
iteration on the compressed Jacobian reaches the same optimum as
scipy.optimize.least_squares(method='trf') (issue 21: refinement made cheap without
changing what it converges to)."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import scipy.optimize

import subid
from subid import systems
from subid.methods.dt import _trust_region

pem_module = importlib.import_module("subid.methods.dt.pem")


def _exponentials(seed):
    """A seeded nonlinear least-squares problem: a sum of three damped exponentials."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 4.0, 400)
    truth = np.array([1.0, 0.7, -0.5, 2.5, 0.8, 0.2])

    def model(x):
        return x[0] * np.exp(-x[3] * t) + x[1] * np.exp(-x[4] * t) + x[2] * np.exp(-x[5] * t)

    y = model(truth) + 0.01 * rng.standard_normal(t.size)

    def fun(x):
        return model(x) - y

    def jac(x):
        e = [np.exp(-x[3 + i] * t) for i in range(3)]
        return np.column_stack(e + [-x[i] * t * e[i] for i in range(3)])

    return fun, jac, np.array([0.8, 0.5, -0.3, 2.0, 1.0, 0.3])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("pivot", [_trust_region.GRAM_PIVOT, 2.0])   # Gram, then QR route
def test_same_iterates_as_scipy_trf(seed, pivot, monkeypatch):
    monkeypatch.setattr(_trust_region, "GRAM_PIVOT", pivot)
    fun, jac, x0 = _exponentials(seed)
    ref = scipy.optimize.least_squares(fun, x0, jac=jac, method="trf", x_scale="jac",
                                       ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=200)
    new = _trust_region.trust_region_least_squares(fun, jac, x0, ftol=1e-10, xtol=1e-10,
                                                   gtol=1e-10, max_nfev=200)
    exact = _trust_region.trust_region_least_squares(fun, jac, x0, ftol=1e-10, xtol=1e-10,
                                                     gtol=1e-10, max_nfev=200, exact=True)
    assert set(new.routes) == {"gram" if pivot < 1 else "qr"}
    # scipy's iteration itself (the SVD of the whole Jacobian): the same iterates
    assert exact.nfev == ref.nfev and exact.status == ref.status
    assert np.abs(exact.x - ref.x).max() < 1e-12 * np.abs(ref.x).max()
    # on the compressed Jacobian: the same optimum (the last iterations of this
    # ill-conditioned problem differ by rounding, so the stopping test may too;
    # seed 2 exhausts the budget on both)
    assert np.abs(new.x - ref.x).max() < 1e-6 * np.abs(ref.x).max()
    assert abs(new.cost - ref.cost) <= 1e-12 * ref.cost


def test_budget_exhausted_reports_status_zero():
    fun, jac, x0 = _exponentials(0)
    ref = scipy.optimize.least_squares(fun, x0, jac=jac, method="trf", x_scale="jac",
                                       max_nfev=3)
    new = _trust_region.trust_region_least_squares(fun, jac, x0, ftol=1e-8, xtol=1e-8,
                                                   gtol=1e-8, max_nfev=3)
    assert new.status == ref.status == 0 and new.message == ref.message
    assert np.allclose(new.x, ref.x, rtol=1e-8)


def test_rank_deficient_jacobian_takes_the_qr_route():
    rng = np.random.default_rng(4)
    A = rng.standard_normal((50, 3))
    A = np.column_stack([A, A[:, 0]])                  # a repeated column
    b = rng.standard_normal(50)
    res = _trust_region.trust_region_least_squares(lambda x: A @ x - b, lambda x: A,
                                                   np.zeros(4), ftol=1e-12, xtol=1e-12,
                                                   gtol=1e-12, max_nfev=50)
    assert "qr" in res.routes
    best = np.linalg.lstsq(A, b, rcond=None)[0]
    assert 0.5 * np.sum((A @ res.x - b) ** 2) <= 0.5 * np.sum((A @ best - b) ** 2) * (1 + 1e-9)


@pytest.mark.parametrize("focus", ["prediction", "simulation"])
def test_pem_reaches_the_optimum_of_scipy_least_squares(focus, monkeypatch):
    """pem with the compressed-Jacobian step equals pem with scipy's least_squares
    (the optimiser it replaced) on a seeded noisy problem."""
    true = systems.seed001_innovation_system()
    data = systems.simulate_innovation_data(true, 1000, seed=5)
    start = subid.n4sid(data, 3)
    new = subid.pem(data, start, focus=focus)

    def scipy_trf(fun, jac, x0, *, ftol, xtol, gtol, max_nfev, decrement_tol=None):
        # decrement_tol: the stop of the gain step after a simulation-focus fit
        # (subid.methods.dt.gain), which scipy does not have; the deterministic part
        # compared here does not depend on it
        return scipy.optimize.least_squares(fun, x0, jac=jac, method="trf", x_scale="jac",
                                            ftol=ftol, xtol=xtol, gtol=gtol,
                                            max_nfev=max_nfev)
    monkeypatch.setattr(_trust_region, "trust_region_least_squares", scipy_trf)
    old = subid.pem(data, start, focus=focus)
    assert new.info["final_cost"] <= new.info["start_cost"]
    assert abs(new.info["final_cost"] - old.info["final_cost"]) <= \
        1e-9 * old.info["final_cost"]
    assert subid.markov_error(new, old, k=30) < 1e-5
    hist = new.info["cost_history"]
    assert hist[0] == new.info["start_cost"] and np.all(np.diff(hist) < 0)


def test_simulation_focus_equals_an_independent_output_error_fit():
    """pem(focus='simulation') reaches the optimum of an independent output-error fit:
    a second-order model in observable canonical form with its initial state, fitted
    by scipy.optimize.least_squares with finite differences (no pem code involved)."""
    rng = np.random.default_rng(21)
    N = 600
    u = rng.standard_normal(N)
    a_true, b_true = (-1.2, 0.5), (1.0, 0.4)

    def simulate(theta):
        a1, a2, b1, b2, x1, x2 = theta
        x = np.array([x1, x2])
        out = np.empty(N)
        for t in range(N):
            out[t] = x[0]
            x = np.array([-a1 * x[0] + x[1] + b1 * u[t], -a2 * x[0] + b2 * u[t]])
        return out

    y = simulate(np.array([*a_true, *b_true, 0.0, 0.0])) + 0.3 * rng.standard_normal(N)
    data = subid.IOData(u[:, None], y[:, None], dt=1.0)
    start = subid.n4sid(data, 2, feedthrough=False)
    refined = subid.pem(data, start, focus="simulation", tolerance=1e-12)
    e_pem = y - refined.simulate(u[:, None], x0=refined.info["x0"])[:, 0]
    # the independent fit, started from the pem start's transfer function
    den = np.real(np.poly(start.A))
    num = np.real(np.poly(start.A - start.B @ start.C) - den)      # C adj(zI-A) B
    theta0 = np.array([den[1], den[2], num[1], num[2], 0.0, 0.0])
    ind = scipy.optimize.least_squares(lambda th: simulate(th) - y, theta0, xtol=1e-14,
                                       ftol=1e-14, gtol=1e-14, max_nfev=2000)
    sse_pem, sse_ind = float(e_pem @ e_pem), 2.0 * ind.cost
    assert abs(sse_pem - sse_ind) <= 1e-10 * sse_ind, (sse_pem, sse_ind)


@pytest.mark.parametrize("focus", ["simulation", "prediction"])
def test_statistical_stop_keeps_the_estimate(focus):
    """identify's refinement (pem stopped where the Gauss-Newton decrement is below
    1e-3 d/(2N), pem.refine) ends within that precision of pem's own optimum, and its
    distance to that optimum is a small fraction of the estimation error."""
    true = systems.seed001_innovation_system(feedthrough=False)
    data = systems.simulate_innovation_data(true, 2000, seed=7)
    start = subid.n4sid(data, 3, feedthrough=False)
    full = subid.pem(data, start, focus=focus)
    quick = pem_module.refine(data, start, focus)
    d = quick.info["parameter_covariance"]["factor"].shape[1] + 3      # model + x0
    scale = d / (2.0 * data.n_samples)
    assert quick.info["final_cost"] <= quick.info["start_cost"]
    assert quick.info["final_cost"] - full.info["final_cost"] <= \
        pem_module.statistical_precision(d, data.n_samples, 2 * pem_module.PRECISION)
    assert quick.info["final_cost"] - full.info["final_cost"] < 1e-2 * scale
    assert quick.info["n_evaluations"] <= full.info["n_evaluations"]
    assert subid.markov_error(quick, full) < 0.1 * subid.markov_error(full, true)
    held = pem_module.refine(data, start, focus, held_out=True)     # only scored
    assert "parameter_covariance" not in held.info
    # a fold model stops at HELD_OUT_PRECISION of d/(2N): within that of the optimum
    assert held.info["final_cost"] - full.info["final_cost"] <= \
        pem_module.statistical_precision(d, data.n_samples,
                                         2 * pem_module.HELD_OUT_PRECISION)
    assert held.info["n_evaluations"] <= quick.info["n_evaluations"]
    assert held.info["n_evaluations"] <= pem_module.HELD_OUT_EVALUATIONS * pem_module.ROUNDS


def test_decrement_tolerance_stops_the_iteration():
    """decrement_tol: status 5 at the first iterate whose Gauss-Newton decrement is
    below it, with fewer evaluations than scipy's tests need."""
    fun, jac, x0 = _exponentials(0)
    full = _trust_region.trust_region_least_squares(fun, jac, x0, ftol=1e-12, xtol=1e-12,
                                                    gtol=1e-12, max_nfev=200)
    quick = _trust_region.trust_region_least_squares(fun, jac, x0, ftol=1e-12, xtol=1e-12,
                                                     gtol=1e-12, max_nfev=200,
                                                     decrement_tol=1e-6 * full.cost)
    assert quick.status == 5 and quick.nfev < full.nfev
    assert 0.0 <= quick.cost - full.cost < 1e-6 * full.cost


def _rosenbrock():
    def fun(x):
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def jac(x):
        return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])
    return fun, jac, np.array([-1.2, 1.0])


def test_stall_tolerance_stops_a_crawl_where_the_budget_would_buy_little():
    """stall_tol: status 6 at the first accepted step after which the decrease per
    evaluation of the last STALL_STEPS accepted steps, times the evaluations left, is
    below it; the iterate is the one the plain iteration holds after as many
    evaluations (the same path, stopped early); never without stall_tol."""
    fun, jac, x0 = _rosenbrock()
    options = {"ftol": 1e-15, "xtol": 1e-15, "gtol": 1e-15, "max_nfev": 200}
    plain = _trust_region.trust_region_least_squares(fun, jac, x0, **options)
    assert plain.status != 6
    costs = []

    def counted(x):
        f = fun(x)
        costs.append(0.5 * float(f @ f))
        return f
    stalled = _trust_region.trust_region_least_squares(counted, jac, x0, stall_tol=1e2,
                                                       **options)
    assert stalled.status == 6 and stalled.nfev < plain.nfev
    assert "stall_tol" in stalled.message
    again = _trust_region.trust_region_least_squares(fun, jac, x0, **dict(
        options, max_nfev=stalled.nfev))
    np.testing.assert_array_equal(stalled.x, again.x)
    # the rule, recomputed from the evaluations: the accepted steps are the new lows
    accepted, low = [], costs[0]
    for k, c in enumerate(costs[1:], start=2):
        if c < low:
            accepted.append((low - c, k))
            low = c
    steps = _trust_region.STALL_STEPS

    def stops(i):                     # after accepted step i (0-based)
        recent = accepted[i - steps + 1:i + 1]
        rate = sum(r for r, _ in recent) / (accepted[i][1] - accepted[i - steps][1])
        return rate * (options["max_nfev"] - accepted[i][1]) < 1e2
    first = next(i for i in range(steps, len(accepted)) if stops(i))
    assert accepted[first][1] == stalled.nfev
