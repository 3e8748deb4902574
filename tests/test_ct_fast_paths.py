"""The fast paths of ct_subspace (issue 29) compute what the plain ones compute.

The fused sensitivity kernel against its numpy reference and, to the last bit, against
the kernel it replaces; the Frechet derivatives of many directions against
``scipy.linalg.expm_frechet``; the least-squares call without a copy against
``scipy.linalg.lstsq``; the cached stencil against a fresh one; the models of
``ct_subspace`` with its memo of builds against those without it; and, to the last bit,
the memory-lean factor, range basis and column scales against the joined computations
(with blocks of a few rows), and the regressors filtered again against the held ones.
"""

import dataclasses
import warnings

import numpy as np
import pytest
import scipy.linalg

import subid
from subid._kernel_args import read_only
from subid.methods.ct import _ct_kernels, _ct_sensitivity
from subid.methods.ct import ct_subspace as ct_module
from subid.methods.ct._ct_fit import _gelsd
from subid.methods.ct._ct_frechet import frechet_many


def _tables(rng, K, n, P):
    return rng.standard_normal((K, n, n)) * 0.3, rng.standard_normal((K, P, n, n))


@pytest.mark.parametrize("free", [True, False])
def test_fused_sensitivity_matches_reference_and_old_kernel(free):
    rng = np.random.default_rng(11)
    n, m, ny, L, P = 4, 3, 2, 60, 3
    Phi, W = _tables(rng, 2, n, P)
    tab = rng.integers(0, 2, L - 1).astype(np.int64)
    starts = np.clip(np.arange(L - 1) - 1, 0, L - P).astype(np.int64)
    u = rng.standard_normal((L, m))
    C = rng.standard_normal((ny, n))
    width = 2 + n * m + 5 + n                          # the blocks inside a wider matrix
    col_b, col_x = 2, (2 + n * m + 5) if free else -1
    outs = []
    for kernel in (_ct_sensitivity.sens_fused, _ct_sensitivity.sens_fused_ref):
        out = np.full((L, ny, width), 7.0)
        X = _ct_sensitivity.fused_state(n, m, free)
        kernel(*read_only(Phi, W, tab, starts, u, C), X, out, col_b, col_x)
        outs.append((out, X))
    np.testing.assert_allclose(outs[0][0], outs[1][0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(outs[0][1], outs[1][1], rtol=1e-12, atol=1e-12)
    # untouched columns stay as they were
    assert np.all(outs[0][0][:, :, :2] == 7.0)
    assert np.all(outs[0][0][:, :, 2 + n * m:2 + n * m + 5] == 7.0)
    # bit for bit the rows of sens_loop (same summation order)
    Z, P0 = np.zeros((m, n, n)), np.eye(n)
    rb, rx = np.empty((L, ny, n, m)), np.empty((L, ny, n))
    _ct_kernels.sens_loop(*read_only(Phi, W, tab, starts, u, C), Z, P0, rb, rx)
    out = outs[0][0]
    np.testing.assert_array_equal(out[:, :, col_b:col_b + n * m], rb.reshape(L, ny, n * m))
    if free:
        np.testing.assert_array_equal(out[:, :, col_x:col_x + n], rx)


def test_run_sensitivity_uniform_path_is_the_old_kernel_bit_for_bit():
    rng = np.random.default_rng(12)
    A = np.array([[-1.0, 2.0, 0.0], [-2.0, -0.5, 1.0], [0.0, 0.0, -3.0]])
    C = rng.standard_normal((2, 3))
    t = np.arange(300) * 0.02
    u = rng.standard_normal((300, 2))
    fast = _ct_kernels.run_sensitivity(A, C, t, u, 1, uniform=True)
    plain = _ct_kernels.run_sensitivity(A, C, t, u, 1, uniform=True,
                                        kernel=_ct_kernels.sens_loop_ref)
    old = _ct_kernels.run_sensitivity(A, C, t, u, 1, uniform=True,
                                      kernel=_ct_kernels.sens_loop.py_func)
    for a, b, c in zip(fast, plain, old):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(a, c)       # the same sums in the same order
    # the non-uniform route copies the rows of run_sensitivity into place
    tn = np.cumsum(rng.uniform(0.01, 0.03, 300))
    out = np.zeros((300, 2, 2 * 3 + 3))
    _ct_kernels.sensitivity_into(A, C, tn, u, 1, uniform=False, out=out, col_b=0, col_x=6)
    rb, rx = _ct_kernels.run_sensitivity(A, C, tn, u, 1, uniform=False)
    np.testing.assert_array_equal(out[:, :, :6], rb.reshape(300, 2, 6))
    np.testing.assert_array_equal(out[:, :, 6:], rx)


def test_uniform_stencil_is_cached_read_only_and_the_same():
    t = np.arange(500) * 0.1
    a = _ct_kernels.uniform_stencil(t, 3)
    assert _ct_kernels.uniform_stencil(t.copy(), 3)[1] is a[1]
    nodes = a[1]
    np.testing.assert_array_equal(a[4], _ct_kernels._lagrange(nodes))
    with pytest.raises(ValueError):
        a[2][0] = 5


@pytest.mark.parametrize("norm", [1e-3, 0.05, 0.5, 1.5, 3.0, 40.0])
def test_frechet_many_is_scipys_frechet_derivative(norm):
    # every branch of Al-Mohy and Higham's algorithm: Pade 3, 5, 7, 9, 13, and squaring
    rng = np.random.default_rng(13)
    A = rng.standard_normal((7, 7))
    A *= norm / np.abs(A).sum(axis=0).max()
    Es = [rng.standard_normal((7, 7)) for _ in range(3)]
    expm_A, Ls = frechet_many(A, Es)
    for E, L in zip(Es, Ls):
        np.testing.assert_array_equal(L, scipy.linalg.expm_frechet(A, E, compute_expm=False))
    np.testing.assert_array_equal(expm_A, scipy.linalg.expm_frechet(A, Es[0])[0])
    # and it is the derivative: a central difference of expm agrees
    step = 1e-6
    fd = (scipy.linalg.expm(A + step * Es[0]) - scipy.linalg.expm(A - step * Es[0])) / (2 * step)
    np.testing.assert_allclose(Ls[0], fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())
    with pytest.raises(ValueError):
        frechet_many(A, [np.full((7, 7), np.nan)])


@pytest.mark.parametrize("shape", [(400, 12), (12, 12), (8, 12)])
def test_gelsd_without_copy_is_scipys_lstsq(shape):
    rng = np.random.default_rng(14)
    a = rng.standard_normal(shape)
    b = rng.standard_normal(shape[0])
    x, _, _, sing = scipy.linalg.lstsq(a, b, lapack_driver="gelsd", check_finite=False)
    x2, sing2 = _gelsd(np.asfortranarray(a), b)
    np.testing.assert_array_equal(x, x2)
    np.testing.assert_array_equal(sing, sing2)


class _Forgetful(dict):
    """A memo that never remembers: every build is computed again."""

    def __contains__(self, key):
        return False


@pytest.mark.slow
def test_memoised_builds_give_the_same_model(monkeypatch):
    data = subid.datasets.load("dryer").detrend()[:700]
    counts = {}
    build = ct_module._build_model

    def counting(problem, *args):
        key = (id(problem.memo), problem.order) + args
        counts[key] = counts.get(key, 0) + 1
        return build(problem, *args)

    monkeypatch.setattr(ct_module, "_build_model", counting)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fast = ct_module.ct_subspace(data)
    assert counts and max(counts.values()) == 1            # nothing built twice
    prepare = ct_module._prepare
    monkeypatch.setattr(ct_module, "_prepare", lambda *a: dataclasses.replace(
        prepare(*a), memo=_Forgetful()))
    counts.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        slow = ct_module.ct_subspace(data)
    assert max(counts.values()) > 1                        # the choices repeat builds
    assert (fast.order, fast.info["start"]) == (slow.order, slow.info["start"])
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))
    assert fast.info["order_selection"]["selected"] == slow.info["order_selection"]["selected"]



@pytest.mark.parametrize("dependence", [1e-3, 3e-10])
def test_the_instrument_block_by_projection_is_the_factor_block(dependence):
    """instrument_block (projections on the Householder Q of the regressors, then the QR
    of the instruments' remainder) gives the block of the LQ factor of [R Z Y] that
    _subspace_factor reads, to rounding, also with two regressors as nearly dependent
    as the default basis's (column-scaled diagonal down to 3e-10 of the largest); None
    where an instrument lies in the span of the regressors, no basis where they are
    dependent to rounding (the caller then factors the whole)."""
    from subid.methods.ct import _ct_estimate
    rng = np.random.default_rng(3)
    N = 4000
    R = rng.standard_normal((N, 12)) @ np.diag(np.logspace(0, 3, 12))
    R[:, -1] = R[:, -2] + dependence * np.abs(R[:, -2]).max() * rng.standard_normal(N)
    Z = rng.standard_normal((N, 3)) + 0.5 * R[:, :3]
    Y = 4.0 * rng.standard_normal((N, 5)) + Z[:, :1] + 0.1 * R[:, 3:4]
    basis = _ct_estimate.range_basis(R)
    W = _ct_estimate.instrument_block(basis, Z, Y)
    W0 = _ct_estimate._subspace_factor(R, Z, Y)[1]
    # both computations lose the digits the near dependence costs (eps / dependence)
    tolerance = 100 * np.finfo(float).eps / dependence
    np.testing.assert_allclose(W, W0, rtol=0, atol=tolerance * np.abs(W0).max())
    inside = np.column_stack([Z[:, 0], R[:, 2] - 3.0 * R[:, 5]])
    assert _ct_estimate.instrument_block(basis, inside, Y) is None
    R[:, -1] = 2.0 * R[:, -2]
    assert _ct_estimate.range_basis(R) is None


@pytest.mark.parametrize("widths", [(2,), (3, 1), (5, 2, 4)])
def test_the_blocked_column_rms_is_numpys_to_the_last_bit(monkeypatch, widths):
    """column_rms (running sums over blocks of rows, no joined matrix or square) equals
    ``sqrt(mean(hstack(parts) ** 2, axis=0))`` bit for bit, also with blocks of a few
    rows that do not divide the record, on row-major and column-major parts."""
    from subid.methods.ct import _ct_estimate
    rng = np.random.default_rng(5)
    parts = [rng.standard_normal((1003, w)) * 10.0 ** rng.uniform(-3, 3, w) for w in widths]
    parts[-1] = np.asfortranarray(parts[-1])
    expected = np.sqrt(np.mean(np.hstack(parts) ** 2, axis=0))
    for rows in (7, 64, 5000):
        monkeypatch.setattr(_ct_estimate, "BLOCK_ROWS", rows)
        np.testing.assert_array_equal(_ct_estimate.column_rms(parts), expected)


def test_the_factor_and_range_basis_in_place_are_the_joined_ones(monkeypatch):
    """_subspace_factor (scaled into one column-major array that the QR overwrites) and
    range_basis (geqrf and orgqr in place, Q returned row-major) give, bit for bit, what
    the joined computations gave: ``lq_lower`` of the scaled copy of ``[R Z Y]`` and
    ``numpy.linalg.qr`` of the scaled ``R``; with blocks of 5 rows."""
    from subid.methods.ct import _ct_estimate
    from subid.statistic._hankel import lq_lower
    monkeypatch.setattr(_ct_estimate, "BLOCK_ROWS", 5)
    rng = np.random.default_rng(8)
    N = 700
    R = rng.standard_normal((N, 9)) @ np.diag(np.logspace(0, 4, 9))
    R[:, -1] = R[:, -2] + 1e-6 * rng.standard_normal(N)
    Z = rng.standard_normal((N, 3)) + 0.5 * R[:, :3]
    Y = rng.standard_normal((N, 4)) + Z[:, :1]
    for instruments in (None, Z):
        M = np.hstack([R, Y] if instruments is None else [R, instruments, Y])
        scale = np.sqrt(np.mean(M ** 2, axis=0))
        Lf0 = lq_lower((M / scale).T) * scale[:, None]
        Lf, _ = _ct_estimate._subspace_factor(R, instruments, Y)
        np.testing.assert_array_equal(Lf, Lf0)
    scale = np.sqrt(np.mean(R ** 2, axis=0))
    Q0 = np.linalg.qr(R / scale)[0]
    Q = _ct_estimate.range_basis(R)
    assert Q.flags.c_contiguous
    np.testing.assert_array_equal(Q, Q0)


def test_released_regressors_are_filtered_again_to_the_same_bits(monkeypatch):
    """The problem lets its regressors go once the range basis is formed; asked again
    (the fallbacks), they are filtered again: the same array, bit for bit, and held."""
    data = subid.datasets.load("dryer").detrend()[:600]
    captured = {}
    prepare = ct_module._prepare

    def keep(*args):
        captured["problem"] = problem = prepare(*args)
        return problem

    monkeypatch.setattr(ct_module, "_prepare", keep)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ct_module.ct_subspace(data, 2, selection="gap", refine=False)
    problem = captured["problem"]
    assert "range basis" in problem.memo and "R" not in problem.held   # let go
    R = problem.regressors()
    assert problem.held["R"] is R
    np.testing.assert_array_equal(R, prepare(problem.data, [2], problem.settings).held["R"])
