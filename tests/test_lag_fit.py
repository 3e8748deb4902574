"""B, D, x0 and the validation score from lag products (subid.methods.dt._lag_fit)
against the per-candidate passes over the record they replace (issue 21.6)."""

import numpy as np
import pytest
import scipy.signal

import subid
from subid import systems
from subid._kernel_args import read_only
from subid.methods.describe import describe_order_selection
from subid.methods.dt import _lag_fit, _regression, _scoring
from subid.methods.dt import selection as _selection


def _system(n, seed, radius=0.9):
    """A random stable (A, B, C, D) with 2 inputs, 2 outputs and poles up to ``radius``,
    in a non-modal basis."""
    rng = np.random.default_rng(seed)
    A = np.zeros((n, n))
    i = 0
    while i < n:
        r, phi = rng.uniform(0.3, radius), rng.uniform(0.1, 3.0)
        if i + 1 < n:
            A[i:i + 2, i:i + 2] = r * np.array([[np.cos(phi), np.sin(phi)],
                                                [-np.sin(phi), np.cos(phi)]])
            i += 2
        else:
            A[i, i] = r
            i += 1
    T = rng.standard_normal((n, n)) + 3 * np.eye(n)
    A = np.linalg.solve(T, A @ T)
    return A, rng.standard_normal((n, 2)), rng.standard_normal((2, n)), \
        rng.standard_normal((2, 2))


def _record(A, B, C, D, N, seed, noise=0.1):
    rng = np.random.default_rng(seed)
    u = scipy.signal.lfilter([1.0], [1.0, -0.7], rng.standard_normal((N, 2)), axis=0)
    x = rng.standard_normal(A.shape[0])
    y = np.empty((N, C.shape[0]))
    for t in range(N):
        y[t] = C @ x + D @ u[t]
        x = A @ x + B @ u[t]
    return u, y + noise * rng.standard_normal(y.shape) * y.std(axis=0)


def test_correlations_equal_the_plain_sums():
    rng = np.random.default_rng(0)
    u, y = rng.standard_normal((700, 2)), rng.standard_normal((700, 3))
    fast = _lag_fit.correlations(u, y, 150)
    plain = _lag_fit.correlations_reference(u, y, 150)
    for a, b in zip(fast, plain):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())


def test_straddle_correlations_equal_the_plain_sums():
    """The products across a boundary (the two sides' cross-correlations) equal the
    plain sums, and those of the window across it minus those of its halves."""
    rng = np.random.default_rng(1)
    for K, lags in ((60, 60), (50, 80), (300, 120)):
        lu, ly = rng.standard_normal((K, 2)), rng.standard_normal((K, 3))
        ru, ry = rng.standard_normal((K, 2)), rng.standard_normal((K, 3))
        fast = _lag_fit.straddle_correlations(lu, ru, ry, lags)
        plain = _lag_fit.straddle_correlations_reference(lu, ru, ry, lags)
        whole = _lag_fit.correlations(np.vstack([lu, ru]), np.vstack([ly, ry]), lags)
        left, right = _lag_fit.correlations(lu, ly, lags), _lag_fit.correlations(ru, ry, lags)
        for k in range(2):
            np.testing.assert_allclose(fast[k], plain[k], rtol=0,
                                       atol=1e-12 * np.abs(plain[k]).max())
            np.testing.assert_allclose(whole[k] - left[k] - right[k], plain[k], rtol=0,
                                       atol=1e-12 * np.abs(plain[k]).max())


def test_lags_past_the_first_computed_when_needed():
    """A record's lags past FIRST_LAGS come when a slow pole needs them: the same
    products, fit and score as with every lag computed at once."""
    A, B, C, D = _system(4, 12)
    slow = 0.995 * A / np.abs(np.linalg.eigvals(A)).max()        # L about 7350
    u, y = _record(slow, B, C, D, 40000, 12)
    lazy, whole = _lag_fit.LagProducts(u, y), _lag_fit.LagProducts(u, y)
    whole.lags(whole.max_lag)
    assert lazy.G.shape[0] == _lag_fit.FIRST_LAGS + 1 < whole.G.shape[0] == whole.max_lag + 1
    weights = np.array([1.0, 2.0])
    got = _lag_fit.fit_b_d_x0(slow, C, lazy, weights)
    assert got[3]["lags"] > _lag_fit.FIRST_LAGS and lazy.G.shape == whole.G.shape
    want = _lag_fit.fit_b_d_x0(slow, C, whole, weights)
    for a, b in zip(got[:3], want[:3]):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(lazy.G, whole.G, rtol=0, atol=1e-11 * np.abs(whole.G).max())


@pytest.mark.parametrize("n, seed", [(1, 1), (3, 2), (4, 3), (6, 4), (8, 5)])
def test_regression_equals_the_pass_over_the_record(n, seed):
    """The normal equations from the lag products give the B, D, x0 and residual of
    the QR factorisation of the regressor rows (the reference), for every combination
    of feedthrough and initial state, for a candidate (A, C) that is not the truth."""
    A, B, C, D = _system(n, seed)
    u, y = _record(A, B, C, D, 3000, seed)
    rng = np.random.default_rng(seed + 100)
    A_c = A + 0.01 * rng.standard_normal(A.shape)
    C_c = C + 0.01 * rng.standard_normal(C.shape)
    products = _lag_fit.LagProducts(u, y)
    weights = 1.0 / y.std(axis=0)
    for feedthrough in (True, False):
        for estimate_x0 in (True, False):
            fast = _lag_fit.fit_b_d_x0(A_c, C_c, products, weights, feedthrough=feedthrough,
                                       estimate_x0=estimate_x0)
            ref = _regression.fit_b_d_x0_qr(A_c, C_c, u, y, feedthrough=feedthrough,
                                            estimate_x0=estimate_x0, output_weights=weights)
            assert fast is not None and fast[3]["regression_path"] == "lag products"
            for got, want in zip(fast[:3] if estimate_x0 else fast[:2], ref):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
            assert fast[3]["residual_rms"] == pytest.approx(ref[3]["residual_rms"], rel=1e-9)


@pytest.mark.parametrize("n, seed, radius", [(2, 6, 0.9), (4, 7, 0.9), (8, 8, 0.95),
                                             (5, 9, 0.99)])
def test_score_equals_the_simulation(n, seed, radius):
    """The error power of the validation score (x0 by least squares) from the lag
    products equals that of the compiled simulation, per output."""
    A, B, C, D = _system(n, seed, radius)
    u, y = _record(A, B, C, D, 20000, seed)
    rng = np.random.default_rng(seed + 200)
    B_c, D_c = B + 0.05 * rng.standard_normal(B.shape), D + 0.05 * rng.standard_normal(D.shape)
    weights, inv_scale = 1.0 / y.std(axis=0), 1.0 / np.abs(y).max(axis=0)
    fast = _lag_fit.error_power(A, B_c, C, D_c, _lag_fit.LagProducts(u, y), weights, inv_scale)
    ref = _scoring._error_power(A, B_c, C, D_c, u, y, weights, inv_scale,
                                _scoring.forced_error)
    assert fast is not None
    np.testing.assert_allclose(fast, ref, rtol=1e-10)


@pytest.mark.parametrize("n, seed, radius", [(1, 21, 0.9), (3, 22, 0.9), (6, 23, 0.97),
                                             (9, 24, 0.8)])
def test_kernels_equal_their_references(n, seed, radius):
    """The compiled normal matrix and error power (subid.methods.dt._lag_kernel) equal
    their numpy references, and the compiled modal form numpy's eigenvector inverse
    and powers, for every combination of feedthrough and initial state."""
    from subid.methods.dt import _lag_kernel
    A, B, C, D = _system(n, seed, radius)
    u, y = _record(A, B, C, D, 5000, seed)
    products = _lag_fit.LagProducts(u, y)
    form = _lag_fit._Modal._of(A)
    assert form is not None
    np.testing.assert_allclose(form.Wm @ form.V, np.eye(n), atol=1e-10)
    L = form.lags_for(products)
    vre, vim = form.powers(L)
    powers = form.lam[:, None] ** np.arange(L + 1)[None, :]
    np.testing.assert_allclose(vre + 1j * vim, powers, rtol=1e-11, atol=1e-14)
    args = form.arguments(products, L)
    C, w = read_only(C, 1.0 / y.std(axis=0))     # the argument types of the library's calls
    B, D = read_only(B, D)
    for feedthrough in (True, False):
        for estimate_x0 in (True, False):
            got = _lag_kernel.normal_matrix(*args, C, w, feedthrough, estimate_x0)
            want = _lag_kernel.normal_matrix_reference(*args, C, w, feedthrough, estimate_x0)
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    got = _lag_kernel.error_power(*args, B, C, D, w, 1e-13, 1e12)
    want = _lag_kernel.error_power_reference(*args, B, C, D, w, 1e-13, 1e12)
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_eigenvectors_are_those_of_numpy_eig():
    """The modal form's eigenvalues and eigenvectors (LAPACK's dgeev without numpy's
    wrapper, the complex pairs built by the compiled kernel) are numpy.linalg.eig's, bit
    for bit, on real and complex spectra; the kernel equals its plain reference."""
    from subid.methods.dt import _lag_kernel
    from subid.methods.dt._lapack import eig_real
    rng = np.random.default_rng(12)
    kinds = set()
    for k in range(120):
        n = int(rng.integers(1, 13))
        A = rng.standard_normal((n, n)) * rng.uniform(0.05, 1.0)
        if k % 3 == 0:
            A = A + A.T                          # a real spectrum
        wr, wi, vr = eig_real(read_only(A)[0])
        lam, V = _lag_kernel.complex_eigenvectors(wr, wi, vr)
        w, v = np.linalg.eig(A)
        assert np.array_equal(lam, w.astype(complex))
        assert np.array_equal(V, v.astype(complex))
        ref = _lag_kernel.complex_eigenvectors_reference(wr, wi, vr)
        assert np.array_equal(lam, ref[0]) and np.array_equal(V, ref[1])
        kinds.add(bool(np.any(wi != 0)))
    assert kinds == {True, False}


def test_scored_solve_equals_its_lapack_reference():
    """The compiled solve of a scored candidate's normal equations equals its LAPACK
    reference (status, bound, solution to rounding) on normal matrices of real
    regressions, well and badly conditioned, not positive definite and not finite,
    and solve_normal_equations decides as with the eigenvalues."""
    from subid.methods.dt import _lag_kernel
    rng = np.random.default_rng(7)
    cases = []
    for p, spread in ((1, 0.0), (12, 0.0), (36, 2.0), (36, 6.0), (20, 9.0)):
        X = rng.standard_normal((400, p + 1)) * 10.0 ** (spread * rng.random(p + 1))
        X[:, :p] = X[:, :p] @ np.linalg.qr(rng.standard_normal((p, p)))[0] \
            * np.logspace(0, -spread, p)
        cases.append((X.T @ X, p))
    N, p = cases[1]
    N = N.copy()
    N[3, 3] = -1.0                               # not positive definite
    cases.append((N, p))
    cases.append((np.full((4, 4), np.nan), 3))   # not finite
    statuses = set()
    for N, p in cases:
        for limit in (1e4, 1e8):
            got = _lag_kernel.scored_solve(read_only(N)[0], p, limit)
            want = _lag_kernel.scored_solve_reference(N, p, limit)
            assert got[0] == want[0]
            statuses.add(got[0])
            if got[0] == 0:
                np.testing.assert_allclose(got[2], want[2], rtol=1e-8)
                np.testing.assert_allclose(got[1], want[1], rtol=1e-8,
                                           atol=1e-10 * np.abs(want[1]).max())
            n, nu, ny = 1, 1, 1
            if p == 3:                           # x0 (1), B (1), D (1)
                fast = _regression.solve_normal_equations(
                    N, n, nu, ny, estimate_x0=True, feedthrough=True, n_samples=400,
                    max_condition=limit, bound_condition=True)
                slow = _regression.solve_normal_equations(
                    N, n, nu, ny, estimate_x0=True, feedthrough=True, n_samples=400,
                    max_condition=limit)
                assert (fast is None) == (slow is None)
    assert statuses == {0, 1, 2}
    # a real fold regression: B, D, x0 as by the eigenvalues' path
    A, B, C, D = _system(4, 25, 0.9)
    u, y = _record(A, B, C, D, 3000, 25)
    form = _lag_fit._Modal._of(A)
    products = _lag_fit.LagProducts(u, y)
    L = form.lags_for(products)
    C, w = read_only(C, 1.0 / y.std(axis=0))
    Naug = _lag_kernel.normal_matrix(*form.arguments(products, L), C, w, True, True)
    kw = dict(estimate_x0=True, feedthrough=True, n_samples=3000, max_condition=1e8)
    fast = _regression.solve_normal_equations(Naug, 4, 2, 2, bound_condition=True, **kw)
    slow = _regression.solve_normal_equations(Naug, 4, 2, 2, **kw)
    for a, b in zip(fast[:4], slow[:4]):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("n, seed, radius, N", [(2, 31, 0.995, 400), (4, 32, 0.999, 700),
                                                (6, 33, 0.9, 300)])
def test_short_record_slow_poles_exact(n, seed, radius, N):
    """On a record shorter than the decay of A (every lag kept, the sums past the end
    subtracted by A^N) the fit equals the QR pass and the score the simulation."""
    A, B, C, D = _system(n, seed, radius)
    u, y = _record(A, B, C, D, N, seed)
    rng = np.random.default_rng(seed)
    A_c = A + 0.002 * rng.standard_normal(A.shape)
    A_c *= min(1.0, radius / np.abs(np.linalg.eigvals(A_c)).max())
    C_c = C + 0.01 * rng.standard_normal(C.shape)
    products = _lag_fit.LagProducts(u, y)
    assert products.max_lag == N - 1
    weights = 1.0 / y.std(axis=0)
    for feedthrough in (True, False):
        fast = _lag_fit.fit_b_d_x0(A_c, C_c, products, weights, feedthrough=feedthrough)
        ref = _regression.fit_b_d_x0_qr(A_c, C_c, u, y, feedthrough=feedthrough,
                                        estimate_x0=True, output_weights=weights)
        assert fast is not None and fast[3]["lags"] <= N - 1
        for got, want in zip(fast[:3], ref):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-8 * np.abs(want).max())
        assert fast[3]["residual_rms"] == pytest.approx(ref[3]["residual_rms"], rel=1e-8)
    inv_scale = 1.0 / np.abs(y).max(axis=0)
    got = _lag_fit.error_power(A_c, fast[0], C_c, fast[1], products, weights, inv_scale)
    want = _scoring._error_power(A_c, fast[0], C_c, fast[1], u, y, weights, inv_scale,
                                 _scoring.forced_error)
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_where_the_products_do_not_apply():
    """No result (the caller runs the pass over the record) for an unstable A, a pole
    too slow for the lags kept, and a nearly exact fit (the normal equations would
    leave the residual and the error power to rounding)."""
    A, B, C, D = _system(4, 10)
    u, y = _record(A, B, C, D, 2000, 10, noise=0.0)
    products = _lag_fit.LagProducts(u, y)
    weights, inv_scale = np.ones(2), np.ones(2)
    assert _lag_fit.fit_b_d_x0(A, C, products, weights) is None          # noise-free
    assert _lag_fit.error_power(A, B, C, D, products, weights, inv_scale) is None
    assert _lag_fit.fit_b_d_x0(1.01 * A / np.abs(np.linalg.eigvals(A)).max(), C, products,
                               weights) is None                          # unstable
    slow = 0.9995 * A / np.abs(np.linalg.eigvals(A)).max()               # L > max_lag
    assert _lag_fit.fit_b_d_x0(slow, C, _lag_fit.LagProducts(u, y, max_lag=500),
                               weights) is None


@pytest.mark.parametrize("n, seed, radius", [(2, 41, 0.9), (5, 42, 0.97), (8, 43, 0.9)])
def test_fit_and_error_equals_the_fit_then_the_score(n, seed, radius):
    """fit_and_error (one modal form for a fold candidate's fit and score) gives the B, D
    of fit_b_d_x0 (to rounding: its normal equations solved by the compiled
    scored_solve) and the error power of error_power on the fitted model, to the bit; no
    fit where fit_b_d_x0 gives none; the fit without a score where error_power gives
    none."""
    A, B, C, D = _system(n, seed, radius)
    u, y = _record(A, B, C, D, 4000, seed)
    train, held = _lag_fit.LagProducts(u[:3000], y[:3000]), _lag_fit.LagProducts(u[3000:],
                                                                                  y[3000:])
    rng = np.random.default_rng(seed)
    A_c = A + 0.01 * rng.standard_normal(A.shape)
    weights, held_weights = 1.0 / y[:3000].std(axis=0), 1.0 / y[3000:].std(axis=0)
    inv_scale = 1.0 / np.abs(y[3000:]).max(axis=0)
    for feedthrough in (True, False):
        for estimate_x0 in (True, False):
            got = _lag_fit.fit_and_error(A_c, C, train, weights, held, held_weights, inv_scale,
                                         feedthrough=feedthrough, estimate_x0=estimate_x0)
            want = _lag_fit.fit_b_d_x0(A_c, C, train, weights, feedthrough=feedthrough,
                                       estimate_x0=estimate_x0)
            for a, b in zip(got[:2], want[:2]):
                np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12 * np.abs(b).max())
            err = _lag_fit.error_power(A_c, got[0], C, got[1], held, held_weights,
                                       inv_scale)
            np.testing.assert_array_equal(got[2], err)
            err = _lag_fit.error_power(A_c, np.ascontiguousarray(want[0]), C,
                                       np.ascontiguousarray(want[1]), held, held_weights,
                                       inv_scale)
            np.testing.assert_allclose(got[2], err, rtol=1e-9)
    unstable = 1.01 * A / np.abs(np.linalg.eigvals(A)).max()
    assert _lag_fit.fit_and_error(unstable, C, train, weights, held, held_weights,
                                  inv_scale) is None
    short = _lag_fit.LagProducts(u[3000:], y[3000:], max_lag=5)     # L > max_lag
    B_f, D_f, err = _lag_fit.fit_and_error(A_c, C, train, weights, short, held_weights,
                                           inv_scale)
    assert err is None and np.isfinite(B_f).all()        # the pass scores it


def test_fold_scores_equal_those_of_the_passes(monkeypatch):
    """Every candidate's fold scores of the cross-validation are those of the per-
    candidate passes (lag products switched off) to 1e-9 points, and the chosen
    candidate is the same."""
    true = systems.random_system(4, 2, 2, seed=1)
    data = systems.simulate_data(true, 6000, seed=2, output_snr_db=20)
    with_products = subid.moesp(data)
    monkeypatch.setattr(_lag_fit.LagProducts, "of_record", classmethod(lambda cls, r: None))
    monkeypatch.setattr(_scoring.Held, "products", lambda self: [None] * len(self.pieces))
    monkeypatch.setattr(_lag_fit, "merged", lambda *args: None)
    without = subid.moesp(data)
    a = with_products.info["order_selection"]["candidates"]
    b = without.info["order_selection"]["candidates"]
    assert [(c["order"], c["horizon"], c["system_matrices"]) for c in a] == \
        [(c["order"], c["horizon"], c["system_matrices"]) for c in b]
    for ca, cb in zip(a, b):
        np.testing.assert_allclose(ca["folds"], cb["folds"], rtol=0, atol=1e-9)
    assert with_products.order == without.order
    assert with_products.info["horizon"] == without.info["horizon"]
    np.testing.assert_allclose(with_products.A, without.A, rtol=0, atol=1e-12)
    assert describe_order_selection(with_products.info["order_selection"])


def test_fold_products_merged_from_blocks():
    """The lag products of every fold's training and validation record, merged from
    those of the four blocks and their boundaries, equal the record's own."""
    rng = np.random.default_rng(3)
    data = subid.IOData(rng.standard_normal((60000, 2)), rng.standard_normal((60000, 2)))
    parts = [(data[a], data[b]) for a, b in _selection.folds(data.n_samples)]
    records = [t for t, _ in parts] + [v for _, v in parts]
    merged = _lag_fit.merged(_selection._blocks_of_folds(parts), records,
                             _selection.FOLD_BLOCKS + _selection.VALIDATION_BLOCKS)
    shortest = min(b.n_samples for b in _selection._blocks_of_folds(parts))
    for record, lp in zip(records, merged):
        own = _lag_fit.LagProducts.of_record(record)
        # merged up to half the record, no lag past the shortest block (a fit takes a
        # quarter); past it, the record's own products
        assert lp.merged_lags == min(own.max_lag, shortest) >= record.n_samples // 4
        assert lp.max_lag == own.max_lag
        assert lp.n_samples == record.n_samples
        own.lags(own.max_lag)            # every lag (those past FIRST_LAGS when needed)
        lp.lags(lp.merged_lags)
        k = lp.merged_lags + 1
        assert lp.G.shape[0] == k        # the merged lags only
        for a, b in ((lp.G, own.G[:k]), (lp.R, own.R[:k]), (lp.Y, own.Y)):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.abs(b).max())
        if lp.max_lag > lp.merged_lags:  # past them: the record's own
            G, R = lp.lags(lp.max_lag)
            assert G.shape[0] == lp.max_lag + 1 and lp.extend is None
            for a, b in ((G, own.G), (R, own.R)):
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.abs(b).max())


@pytest.mark.slow
def test_search_past_10_on_a_long_record(monkeypatch):
    """The search past order 10 with the folds' lag products in use (training folds
    longer than MIN_SAMPLES): the blocks of the folds are not the block rows of the
    horizons, and the order found is the true one."""
    used = []
    real = _lag_fit.fit_b_d_x0

    def counting(*args, **kwargs):
        out = real(*args, **kwargs)
        used.append(out is not None)
        return out

    monkeypatch.setattr(_lag_fit, "fit_b_d_x0", counting)
    true = systems.random_system(12, 2, 4, seed=4)
    data = systems.simulate_data(true, 12000, seed=5, output_snr_db=40)
    model = subid.moesp(data, system_matrices="shift")
    assert len(model.info["order_selection"]["searched"]) >= 2
    assert model.order == 12
    assert sum(used) > len(used) / 2


def test_noise_free_default_call_is_exact_on_a_long_record():
    """Noise-free data long enough for the lag products: the default call still finds
    the true order and recovers the system to rounding (the nearly exact fits fall
    back to the passes, which resolve them)."""
    true = systems.random_system(4, 2, 2, seed=11)
    data = systems.simulate_data(true, 10000, seed=12)
    model = subid.moesp(data)
    assert model.order == 4
    assert subid.markov_error(model, true) < 1e-8


def test_records_of_many_inputs_are_not_reduced_to_lag_products():
    """Lag products only where they pay (``(L + 1) nu <= 8 N``): every record of up to 8
    inputs, none of a short record of many (100 inputs, 3,000 samples: the default
    call's folds held 8.9 GB of them), and the cross-correlations are formed one row
    at a time (memory ``nfft nu``, not ``nfft nu^2``) with the plain sums' values."""
    assert _lag_fit.worthwhile(256, 8) and not _lag_fit.worthwhile(255, 1)
    assert not _lag_fit.worthwhile(3000, 9) and not _lag_fit.worthwhile(3000, 100)
    assert _lag_fit.worthwhile(300_000, 100)           # 16,385 lags x 100 <= 8 N
    rng = np.random.default_rng(5)
    blocks = [subid.IOData(rng.standard_normal((1500, 12)), rng.standard_normal((1500, 2)))
              for _ in range(2)]
    whole = subid.IOData(np.vstack([b.u for b in blocks]), np.vstack([b.y for b in blocks]))
    assert _lag_fit.merged(blocks, [whole], [(0, 1)]) == [None]
    assert _lag_fit.LagProducts.of_record(whole) is None
    u, y = rng.standard_normal((400, 12)), rng.standard_normal((400, 3))
    for fast, plain in zip(_lag_fit.correlations(u, y, 30),
                           _lag_fit.correlations_reference(u, y, 30)):
        np.testing.assert_allclose(fast, plain, rtol=0, atol=1e-12 * np.abs(plain).max())
