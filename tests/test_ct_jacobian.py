"""The analytic Jacobian of the continuous-time output-error refinement (issue 29)."""

import numpy as np
import pytest

from subid import IOData, merge
from subid.methods.ct import _ct_fit, _ct_jacobian


def record(order, n_experiments=1, n_samples=300, seed=0):
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(n_experiments):
        u = rng.standard_normal((n_samples, 2))
        y = rng.standard_normal((n_samples, 2)) + np.cumsum(u, axis=0)[:, :2] * 0.05
        parts.append(IOData(u, y, dt=0.1))
    data = parts[0] if n_experiments == 1 else merge(parts)
    return _ct_fit.Record(data, order)


def system(seed=1, n=3, p=2):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) - 2.0 * np.eye(n)
    return A, rng.standard_normal((p, n))


@pytest.mark.parametrize("order, n_experiments, whitened, feedthrough",
                         [(0, 1, False, True), (1, 1, False, False), (1, 2, True, True),
                          (3, 1, True, False)])
def test_jacobian_matches_central_differences(order, n_experiments, whitened, feedthrough):
    rec = record(order, n_experiments)
    A, C = system()
    n, p = A.shape[0], C.shape[0]
    kw = dict(feedthrough=feedthrough, estimate_x0=True, offset=True)
    whiten = None
    if whitened:
        whiten = _ct_fit.ARNoise([np.array([1.0, -0.6, 0.2]), np.array([1.0, 0.4])],
                                 [t.size for t, *_ in rec.parts], p)
    prob = _ct_jacobian.VarProProblem(rec, _ct_fit.regressors, _ct_fit.unpack, **kw, whiten=None if whiten is None else whiten.apply,
                                      whiten_transpose=None if whiten is None
                                      else whiten.apply_transpose)
    Q = _ct_fit.similarity_complement(A, C)
    dAs = [Q[:n * n, d].reshape(n, n) for d in range(Q.shape[1])]
    dCs = [Q[n * n:, d].reshape(p, n) for d in range(Q.shape[1])]
    J = prob.jacobian(A, C, dAs, dCs)
    step = 1e-6
    for d in range(Q.shape[1]):
        plus = prob.evaluate(A + step * dAs[d], C + step * dCs[d])
        minus = prob.evaluate(A - step * dAs[d], C - step * dCs[d])
        fd = (plus - minus) / (2 * step)
        assert np.linalg.norm(J[:, d] - fd) <= 1e-6 * np.linalg.norm(fd)


def test_whitening_transpose_is_the_adjoint():
    rng = np.random.default_rng(3)
    noise = _ct_fit.ARNoise([np.array([1.0, -0.5, 0.3]), np.array([1.0, 0.2])], [40, 30], 2)
    M = rng.standard_normal((140, 1))
    v = rng.standard_normal(noise.apply(M).shape[0])
    assert np.isclose(v @ noise.apply(M)[:, 0], noise.apply_transpose(v) @ M[:, 0])


def test_shift_kernel_matches_reference():
    rng = np.random.default_rng(4)
    Phi, F = rng.standard_normal((3, 3)) * 0.5, rng.standard_normal((20, 3, 2))
    out = _ct_jacobian.shift_loop(Phi, F, np.empty((21, 3, 2)))
    ref = _ct_jacobian.shift_loop_ref(Phi, F, np.empty((21, 3, 2)))
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13)


def test_refinement_converges_from_a_non_minimal_start():
    # noise-free data of a second-order system; the start adds a state C cannot see
    # (its regressor columns at rounding level) and perturbs the true poles: the analytic
    # Jacobian takes the refinement to the exact fit
    rng = np.random.default_rng(5)
    A_true = np.array([[-0.3, 1.0], [-1.0, -0.3]])
    B_true, C_true = np.array([[0.0], [1.0]]), np.array([[1.0, 0.5]])
    u = rng.standard_normal((600, 1))
    data = IOData(u, np.zeros((600, 1)), dt=0.1)
    rec = _ct_fit.Record(data, 0)
    R = _ct_fit.regressors(A_true, C_true, rec, feedthrough=False, estimate_x0=False,
                           offset=False)
    y = R @ B_true.ravel()
    rec = _ct_fit.Record(IOData(u, y[:, None], dt=0.1), 0)
    A0 = np.zeros((3, 3))
    A0[:2, :2] = A_true + 0.05 * np.array([[1.0, 0.0], [0.0, -1.0]])
    A0[2, 2] = -1.0
    C0 = np.hstack([C_true, [[0.0]]])
    T = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    A0, C0 = T.T @ A0 @ T, C0 @ T
    kw = dict(feedthrough=False, estimate_x0=True, offset=False, max_iterations=30)
    _, _, diag = _ct_fit.refine_output_error(A0, C0, rec, **kw)
    assert diag["refined"]
    assert diag["refine_rms_after"] < 1e-6 * diag["refine_rms_before"]


def test_refinement_says_whether_it_converged():
    """``refine_converged``: scipy's own tests stopped the refinement (a noise-free fit
    reached), or the evaluations allowed did (one evaluation)."""
    rng = np.random.default_rng(5)
    A_true = np.array([[-0.3, 1.0], [-1.0, -0.3]])
    B_true, C_true = np.array([[0.0], [1.0]]), np.array([[1.0, 0.5]])
    u = rng.standard_normal((600, 1))
    base = _ct_fit.Record(IOData(u, np.zeros((600, 1)), dt=0.1), 0)
    y = _ct_fit.regressors(A_true, C_true, base, feedthrough=False, estimate_x0=False,
                           offset=False) @ B_true.ravel()
    rec = _ct_fit.Record(IOData(u + 0.0, y[:, None], dt=0.1), 0)
    A0 = A_true + 0.05 * np.array([[1.0, 0.0], [0.0, -1.0]])
    kw = dict(feedthrough=False, estimate_x0=True, offset=False)
    _, _, done = _ct_fit.refine_output_error(A0, C_true, rec, max_iterations=50, **kw)
    _, _, cut = _ct_fit.refine_output_error(A0, C_true, rec, max_iterations=2, **kw)
    assert done["refine_converged"] and done["refine_evaluations"] < 50
    assert not cut["refine_converged"] and cut["refine_evaluations"] == 2
