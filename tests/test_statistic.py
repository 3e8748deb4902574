"""HankelStatistic: exact, chunkable, mergeable; identification from it."""

import numpy as np
import pytest

import subid
from subid import errors, systems
from subid.statistic._hankel import hankel_chunk
from subid.statistic.hankel import HankelStatistic, lag_sums, lag_sums_uy


def _direct_gram(u, y, depth):
    H = hankel_chunk(u, y, depth, 0, u.shape[0] - depth + 1)
    return H.T @ H / H.shape[0]


@pytest.fixture(scope="module")
def record():
    r = np.random.default_rng(0)
    return r.standard_normal((20_011, 2)), r.standard_normal((20_011, 3))


@pytest.mark.parametrize("kind", ["qr", "gram"])
def test_chunked_equals_direct(record, kind):
    u, y = record
    G = _direct_gram(u, y, 6)
    stat = HankelStatistic(2, 3, 6, kind=kind)
    r = np.random.default_rng(1)
    k = 0
    while k < u.shape[0]:                      # random chunk sizes, including tiny ones
        n = int(r.choice([1, 2, 3, 7, 500, 9000]))
        stat.update(u[k:k + n], y[k:k + n])
        k += n
    assert stat.n_samples == u.shape[0]
    np.testing.assert_allclose(stat.gram(), G, rtol=1e-12, atol=1e-12)
    L = stat.factor().L
    np.testing.assert_allclose(L @ L.T, G, rtol=1e-10, atol=1e-12)
    assert np.allclose(L, np.tril(L))


@pytest.mark.parametrize("kind", ["qr", "gram"])
def test_merge_tree_equals_sequential(record, kind):
    u, y = record
    cuts = [0, 3, 4000, 4002, 11_000, 20_011]   # includes partitions shorter than depth
    parts = [HankelStatistic(2, 3, 6, kind=kind).update(u[a:b], y[a:b])
             for a, b in zip(cuts, cuts[1:])]
    left = parts[0].merge(parts[1]).merge(parts[2])
    right = parts[3].merge(parts[4])
    tree = left.merge(right)
    np.testing.assert_allclose(tree.gram(), _direct_gram(u, y, 6), rtol=1e-12, atol=1e-12)


def test_lag_sums_direct():
    z = np.random.default_rng(2).standard_normal((50, 3))
    out = lag_sums(z, 5)
    for lag in range(5):
        np.testing.assert_allclose(out[lag], z[:50 - lag].T @ z[lag:], rtol=1e-13)
    np.testing.assert_allclose(lag_sums_uy(z[:, :1], z[:, 1:], 5), out, rtol=1e-13)


@pytest.mark.parametrize("n_samples", [1, 7, 19, 20, 21, 4095, 4096, 4097, 4115, 4116, 4117,
                                       9000])
@pytest.mark.parametrize("nu,ny,depth", [(1, 1, 20), (2, 2, 20), (2, 3, 6), (1, 2, 1)])
def test_compiled_lag_sums_equal_the_matrix_products(n_samples, nu, ny, depth):
    """The kernel (blocks of 4096 samples) against the reference, around every
    border: record shorter than the depth, block ends, last rows."""
    rng = np.random.default_rng(n_samples)
    u, y = rng.standard_normal((n_samples, nu)), rng.standard_normal((n_samples, ny))
    expected = lag_sums(np.hstack([u, y]), depth)
    np.testing.assert_allclose(lag_sums_uy(u, y, depth), expected, rtol=1e-12, atol=1e-12)
    # strided views (a column selection) give the same sums
    wide = np.hstack([y, u])
    np.testing.assert_allclose(lag_sums_uy(wide[:, ny:], wide[:, :ny], depth), expected,
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("fn,kw", [
    (subid.ls_subspace, {"bd_method": "projection"}),
    (subid.ls_subspace, {"bd_method": "projection", "instruments": None}),
    (subid.moesp, {"bd_method": "projection"}),
    (subid.n4sid, {}),
])
@pytest.mark.parametrize("kind", ["qr", "gram"])
def test_identification_from_statistic_equals_in_memory(fn, kw, kind):
    true = systems.seed001_system()
    data = systems.simulate_data(true, 6000, seed=3, process_snr_db=20, output_snr_db=20)
    depth = 5 if kw.get("instruments", "past") is None else 10
    stat = HankelStatistic(2, 2, depth, kind=kind)
    for k in range(0, 6000, 1234):
        stat.update(data.u[k:k + 1234], data.y[k:k + 1234])
    from_stat = fn(stat, 3, **kw)
    in_memory = fn(data, 3, horizon=5, statistic=kind, **kw)
    for name in "ABCD":
        np.testing.assert_allclose(getattr(from_stat, name), getattr(in_memory, name),
                                   rtol=1e-10, atol=1e-10, err_msg=name)
    assert from_stat.info["horizon"] == 5


@pytest.mark.slow
def test_gram_and_qr_agree_on_noisy_data():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 5000, seed=4, output_snr_db=30)
    for fn in (subid.moesp, subid.n4sid, subid.ls_subspace):
        a = fn(data, 3, statistic="qr")
        b = fn(data, 3, statistic="gram")
        assert subid.markov_error(a, b) < 1e-9


@pytest.mark.slow
def test_noise_free_from_gram_statistic_exact():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 3000, seed=5)
    for fn in (subid.moesp, subid.n4sid, subid.ls_subspace):
        assert subid.markov_error(fn(data, 3, statistic="gram"), true) < 1e-9


def test_statistic_errors():
    data = systems.simulate_data(systems.seed001_system(), 500, seed=0)
    stat = HankelStatistic.from_data(data, 10)
    with pytest.raises(errors.DataError, match="horizon 5"):
        subid.moesp(stat, 3, horizon=4)
    with pytest.raises(errors.SubidError, match="statistic only"):
        subid.moesp(stat, 3, bd_method="simulation")
    with pytest.raises(errors.DataError, match="multiple of 2"):
        subid.n4sid(HankelStatistic.from_data(data, 9), 3)
    with pytest.raises(errors.DataError, match="merged"):
        stat.merge(HankelStatistic(2, 2, 8))
    with pytest.raises(errors.DataError, match="3 inputs"):
        HankelStatistic(2, 2, 10).update(np.zeros((5, 3)), np.zeros((5, 2)))
    with pytest.raises(errors.TooFewSamplesError):
        subid.moesp(HankelStatistic(2, 2, 10).update(np.ones((20, 2)), np.ones((20, 2))), 3)
    with pytest.raises(errors.SubidError, match="statistic must be"):
        subid.moesp(data, 3, statistic="fast")


def _qr_rows_reference(R, z, depth, n_inputs, block):
    """The plain path: stack [R; Hankel rows], scipy.linalg.qr(mode='r'), keep m rows."""
    import scipy.linalg
    m = depth * z.shape[1]
    u, y = z[:, :n_inputs], z[:, n_inputs:]
    R = np.zeros((0, m)) if R is None else R

    def triangle(stacked):
        out = scipy.linalg.qr(stacked, mode="r", check_finite=False)[0][:m]
        return np.vstack([out, np.zeros((m - out.shape[0], m))]) if out.shape[0] < m else out
    for start in range(0, max(z.shape[0] - depth + 1, 0), block):
        stop = min(start + block, z.shape[0] - depth + 1)
        R = triangle(np.vstack([R, hankel_chunk(u, y, depth, start, stop)]))
    return triangle(R) if R.shape[0] != m else R


@pytest.mark.parametrize("rows, q, nu, depth, with_r", [
    (3 * 8192 + 17, 4, 2, 10, False), (30, 4, 2, 10, False), (8, 3, 1, 10, False),
    (9000, 3, 1, 6, True), (20, 4, 2, 10, True), (5, 4, 2, 10, True)])
def test_in_place_qr_statistic_is_the_stacked_qr_bit_for_bit(rows, q, nu, depth, with_r):
    """_qr_rows factorises each block in place by geqrf: the same R as stacking
    the blocks and calling scipy.linalg.qr, to the last bit."""
    from subid.statistic import hankel as statistic
    rng = np.random.default_rng(rows)
    z = rng.standard_normal((rows, q))
    R0 = np.triu(rng.standard_normal((2 * depth * q, depth * q))) if with_r else None
    got = statistic._qr_rows(R0, z, depth, nu)
    want = _qr_rows_reference(R0, z, depth, nu, statistic._BLOCK)
    assert got.shape == want.shape
    assert np.array_equal(got, want)



def test_lq_lower_is_scipy_qr_bit_for_bit():
    """lq_lower's R rows come from geqrf called as scipy.linalg.qr(mode='r') calls it:
    the same bits, for wide, tall, square, strided and empty inputs."""
    import scipy.linalg

    from subid.statistic._hankel import geqrf_r, lq_lower
    rng = np.random.default_rng(8)
    for r, m in [(40, 40), (30, 80), (80, 30), (1, 5), (5, 1), (0, 5), (5, 0)]:
        M = rng.standard_normal((r, m))
        for variant in (M, np.asfortranarray(M), M[:, ::2] if m > 1 else M):
            want = scipy.linalg.qr(variant.T, mode="r", check_finite=False)[0][:r]
            kept = variant.copy()
            got = geqrf_r(variant.T, r, overwrite=False)
            assert got.shape == want.shape and np.array_equal(got, want)
            assert np.array_equal(variant, kept)          # overwrite=False: input untouched
            k = min(variant.shape)
            L = lq_lower(variant)
            assert L.shape == (r, r) and np.array_equal(np.abs(L[:, :k]), np.abs(want.T[:, :k]))
