"""The B, D, x0 regression on large problems (subid.methods.dt._bd_large; issue 28):
x0 eliminated per experiment, D per output; equal to the dense least squares and
bounded in memory."""

import tracemalloc

import numpy as np
import pytest

import subid
from subid.errors import ResourceLimitError
from subid.methods import bd
from subid.methods.dt import _bd_large
from subid.methods.dt._regression import fit_b_d_x0_qr


def _system(n, nu, ny, seed):
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    A = Q @ np.diag(rng.uniform(-0.9, 0.9, n)) @ Q.T
    return (A, rng.standard_normal((n, nu)), rng.standard_normal((ny, n)),
            rng.standard_normal((ny, nu)))


def _simulate(A, B, C, D, u, x0):
    x, y = x0.copy(), np.empty((u.shape[0], C.shape[0]))
    for t in range(u.shape[0]):
        y[t] = C @ x + D @ u[t]
        x = A @ x + B @ u[t]
    return y


def _dense(A, C, u, y, starts, weights, feedthrough=True, estimate_x0=True):
    """The embedded problem [x0_1 .. x0_E, vec B, vec D], regressors built sample by
    sample and solved by one dense least squares (the reference)."""
    n, nu, ny = A.shape[0], u.shape[1], y.shape[1]
    E = len(starts)
    nx = E * n if estimate_x0 else 0
    ends = list(starts[1:]) + [u.shape[0]]
    rows, rhs = [], []
    for e, (a, b) in enumerate(zip(starts, ends)):
        S = np.zeros((n, nx + n * nu))
        if estimate_x0:
            S[:, e * n:(e + 1) * n] = np.eye(n)
        for t in range(a, b):
            row = C @ S
            if feedthrough:
                row = np.hstack([row, np.kron(u[t], np.eye(ny))])
            rows.append(weights[:, None] * row)
            rhs.append(weights * y[t])
            S = A @ S
            for j in range(nu):
                S[:, nx + j * n:nx + (j + 1) * n] += u[t, j] * np.eye(n)
    theta = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    x0 = theta[:nx].reshape(E, n) if estimate_x0 else None
    B = theta[nx:nx + n * nu].reshape(nu, n).T
    D = theta[nx + n * nu:].reshape(nu, ny).T if feedthrough else np.zeros((ny, nu))
    return B, D, x0


def _close(a, b, tol=1e-10):
    assert np.abs(a - b).max() <= tol * max(1.0, np.abs(b).max())


@pytest.mark.parametrize("path", ["qr", "modal"])
@pytest.mark.parametrize("estimate_x0", [True, False])
def test_experiments_equal_the_dense_least_squares(path, estimate_x0):
    A, B, C, D = _system(3, 2, 2, seed=1)
    rng = np.random.default_rng(2)
    lengths = [40, 25, 60, 33]
    starts = list(np.cumsum([0] + lengths[:-1]))
    u = rng.standard_normal((sum(lengths), 2))
    y = np.vstack([_simulate(A, B, C, D, u[a:a + m], rng.standard_normal(3))
                   for a, m in zip(starts, lengths)])
    y += 0.1 * rng.standard_normal(y.shape)
    weights = np.array([1.0, 0.3])
    B1, D1, x1, diag = _bd_large.fit_experiments(A, C, u, y, starts, output_weights=weights,
                                                 path=path, estimate_x0=estimate_x0)
    B0, D0, x0 = _dense(A, C, u, y, starts, weights, estimate_x0=estimate_x0)
    assert diag["regression_path"] == path and diag["experiments"] == 4
    _close(B1, B0)
    _close(D1, D0)
    if estimate_x0:
        _close(x1, x0)


def test_experiments_exact_noise_free():
    A, B, C, D = _system(4, 1, 2, seed=3)
    rng = np.random.default_rng(4)
    x0s = rng.standard_normal((3, 4))
    u = rng.standard_normal((150, 1))
    starts = [0, 50, 90]
    y = np.vstack([_simulate(A, B, C, D, u[a:b], x)
                   for (a, b), x in zip(zip(starts, [50, 90, 150]), x0s)])
    for path in ("qr", "modal"):
        B1, D1, x1, diag = _bd_large.fit_experiments(A, C, u, y, starts, path=path)
        _close(B1, B, 1e-8)
        _close(D1, D, 1e-8)
        _close(x1, x0s, 1e-8)
        assert diag["residual_rms"] < 1e-8


def _many_experiments(E, length, seed):
    A, B, C, D = _system(3, 2, 2, seed=seed)
    rng = np.random.default_rng(seed + 1)
    u = rng.standard_normal((E * length, 2))
    y = np.vstack([_simulate(A, B, C, D, u[k:k + length], rng.standard_normal(3))
                   for k in range(0, E * length, length)])
    return A, B, C, D, u, y + 0.01 * rng.standard_normal(y.shape)


@pytest.mark.slow
def test_two_thousand_experiments_run_in_bounded_memory():
    """2,000 experiments of 20 samples (issue 28): the dense embedded problem has
    6,010 unknowns (a 289 MB normal matrix; 1 GB of stacked factors); with x0
    eliminated per experiment the peak stays below 20 MB, for either path."""
    E, length = 2000, 20
    A, B, C, D, u, y = _many_experiments(E, length, seed=5)
    starts = list(range(0, E * length, length))
    for path in ("modal", "qr"):
        tracemalloc.start()
        try:
            B1, D1, x1, diag = _bd_large.fit_experiments(A, C, u, y, starts, path=path)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 20 * 2 ** 20, (path, peak)
        assert x1.shape == (E, 3) and diag["experiments"] == E
        assert np.abs(B1 - B).max() < 1e-2 and np.abs(D1 - D).max() < 1e-2


def test_merged_record_through_the_entry_point_has_one_x0_per_experiment():
    A, B, C, D, u, y = _many_experiments(30, 12, seed=7)
    data = subid.merge([subid.IOData(u[k:k + 12], y[k:k + 12]) for k in range(0, 360, 12)])
    B1, D1, x1, diag = bd.fit_b_d_x0(A, C, data)
    assert diag["bd_method"] == "simulation" and x1.shape == (30, 3)
    B0, D0, x0 = _dense(A, C, u, y, list(range(0, 360, 12)), np.ones(2))
    _close(B1, B0, 1e-8)
    _close(x1, x0, 1e-8)


@pytest.mark.parametrize("feedthrough", [True, False])
@pytest.mark.parametrize("estimate_x0", [True, False])
def test_channels_equal_the_dense_regression(feedthrough, estimate_x0):
    """D eliminated output by output (normal equations by chunks) against the QR
    factor of the dense Kronecker regressor."""
    A, B, C, D = _system(4, 5, 7, seed=8)
    rng = np.random.default_rng(9)
    u = rng.standard_normal((400, 5))
    y = _simulate(A, B, C, D if feedthrough else 0 * D, u, rng.standard_normal(4))
    y += 0.2 * rng.standard_normal(y.shape)
    w = rng.uniform(0.5, 2.0, 7)
    kw = dict(feedthrough=feedthrough, estimate_x0=estimate_x0, output_weights=w)
    B0, D0, x0, d0 = fit_b_d_x0_qr(A, C, u, y, **kw)
    B1, D1, x1, d1 = _bd_large.fit_channels(A, C, u, y, chunk_bytes=20_000, **kw)
    assert d1["regression_path"] == "channels" and not d1["regression_rank_deficient"]
    _close(B1, B0)
    _close(D1, D0)
    _close(x1, x0)
    assert abs(d1["residual_rms"] - d0["residual_rms"]) < 1e-8 * d0["residual_rms"]


def test_channels_exact_noise_free_and_chosen_above_the_dense_limit(monkeypatch):
    A, B, C, D = _system(3, 4, 6, seed=10)
    rng = np.random.default_rng(11)
    u = rng.standard_normal((300, 4))
    x0 = rng.standard_normal(3)
    data = subid.IOData(u, _simulate(A, B, C, D, u, x0))
    monkeypatch.setattr(_bd_large, "DENSE_LIMIT", 1000)
    B1, D1, x1, diag = bd.fit_b_d_x0(A, C, data)
    assert diag["regression_path"] == "channels" and diag["bd_method"] == "simulation"
    _close(B1, B, 1e-8)
    _close(D1, D, 1e-8)
    _close(x1, x0, 1e-8)


def test_channels_memory_is_bounded_by_the_chunk():
    """40 inputs and 40 outputs: the dense engines would hold a 1,801-column
    regressor (modal maps of 40 x 1,802 x 284 doubles: 164 MB); by chunks the peak
    stays below 16 MB."""
    A, B, C, D = _system(3, 40, 40, seed=12)
    rng = np.random.default_rng(13)
    u = rng.standard_normal((600, 40))
    y = _simulate(A, B, C, D, u, np.zeros(3)) + 0.1 * rng.standard_normal((600, 40))
    assert _bd_large.dense_bytes(3, 40, 40, 600) > 150 * 2 ** 20
    tracemalloc.start()
    try:
        B1, D1, _, diag = _bd_large.fit_channels(A, C, u, y, chunk_bytes=2 ** 20)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2 ** 20, peak
    assert np.abs(B1 - B).max() < 0.05 and np.abs(D1 - D).max() < 0.05


def test_unstable_a_overflows_to_a_rank_deficient_result():
    A, B, C, D = _system(3, 2, 2, seed=14)
    A = 1.5 * A / np.abs(np.linalg.eigvals(A)).max()
    rng = np.random.default_rng(15)
    u = rng.standard_normal((3000, 2))
    y = rng.standard_normal((3000, 2))
    with np.errstate(all="ignore"):
        fitted = _bd_large.fit_channels(A, C, u, y)
        assert fitted[3]["regression_rank_deficient"]
        fitted = _bd_large.fit_experiments(A, C, u, y, [0, 1500], path="qr")
        assert fitted[3]["regression_rank_deficient"] and fitted[2].shape == (2, 3)


def test_one_vocabulary_and_info_key_across_methods():
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=3)
    for model in (subid.moesp(data, 3), subid.ls_subspace(data, 3), subid.n4sid(data, 3),
                  subid.moesp(data, 3, bd_method="projection"),
                  subid.ct_subspace(data, 3, start="subspace", refine=False)):
        assert model.info[bd.INFO_KEY] in bd.BD_METHODS + bd.INFO_ONLY
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=6)
    rs.update(data.u, data.y)
    assert rs.model.info[bd.INFO_KEY] == "simulation"
    assert set(bd.BATCH_OPTIONS + bd.CT_OPTIONS + bd.ONLINE_OPTIONS) <= set(bd.BD_METHODS)
    with pytest.raises(ValueError, match="bd_method"):
        bd.fit_b_d_x0(np.eye(2) * 0.5, np.ones((1, 2)), data, bd_method="regression")


@pytest.mark.parametrize("defective", [False, True])
def test_second_pass_with_experiments_equals_in_memory(defective):
    """The streamed/Dask second pass (one block per experiment, its x0 eliminated) equals
    the in-memory regression of the merged record: the modal path, and the QR path of a
    nearly defective A."""
    from subid.methods.dt._bd_pass import OutputRegression
    rng = np.random.default_rng(16)
    if defective:
        A = np.array([[0.8, 1.0, 0.0], [0.0, 0.8 + 1e-10, 0.3], [0.0, 0.0, -0.5]])
    else:
        A = _system(3, 2, 2, seed=17)[0]
    C = rng.standard_normal((2, 3))
    u = rng.standard_normal((900, 2))
    y = rng.standard_normal((900, 2)) * [1.0, 30.0]
    weights = 1.0 / y.std(axis=0)
    borders = [0, 100, 300, 310, 600, 900]          # five pieces
    experiments = [0, 0, 1, 1, 2]                   # experiments start at 0, 300, 600

    def map_pieces(function, arguments):
        return [function([(u[a:b], y[a:b])], *args)
                for (a, b), args in zip(zip(borders[:-1], borders[1:]), arguments)]

    second = OutputRegression(map_pieces, 5, 2, 2, experiments=experiments)
    B, D, x0, diag = second(A, C)
    B0, D0, x00, d0 = _bd_large.fit_experiments(A, C, u, y, [0, 300, 600],
                                                output_weights=weights)
    assert diag["regression_path"] == d0["regression_path"] == ("qr" if defective else "modal")
    _close(B, B0, 1e-9)
    _close(D, D0, 1e-9)
    _close(x0, x00, 1e-9)
    assert x0.shape == (3, 3)
    if not defective:
        x_given = second.initial_state(A, B0, C, D0)
        _close(x_given, x00, 1e-8)


@pytest.mark.parametrize("feedthrough", [True, False])
@pytest.mark.parametrize("estimate_x0", [True, False])
def test_channels_with_experiments_equal_the_dense_regression(feedthrough, estimate_x0):
    """The channel elimination on a merged record (one x0 per experiment, the
    sensitivity restarting at each) against the dense embedded problem."""
    A, B, C, D = _system(3, 4, 5, seed=21)
    rng = np.random.default_rng(22)
    starts = [0, 70, 95, 180]
    u = rng.standard_normal((260, 4))
    y = np.vstack([_simulate(A, B, C, D if feedthrough else 0 * D, u[a:b],
                             rng.standard_normal(3))
                   for a, b in zip(starts, starts[1:] + [260])])
    y += 0.1 * rng.standard_normal(y.shape)
    w = rng.uniform(0.5, 2.0, 5)
    B0, D0, x0 = _dense(A, C, u, y, starts, w, feedthrough, estimate_x0)
    B1, D1, x1, diag = _bd_large.fit_channels(A, C, u, y, starts=starts, chunk_bytes=20_000,
                                              feedthrough=feedthrough, estimate_x0=estimate_x0,
                                              output_weights=w)
    assert diag["regression_path"] == "channels" and diag["experiments"] == 4
    _close(B1, B0)
    _close(D1, D0)
    if estimate_x0:
        _close(x1, x0)


def test_merged_record_with_many_channels_takes_the_channel_elimination(monkeypatch):
    """Above the dense limit, a merged record goes to the channel elimination (exact
    noise-free); above the memory limit, a ResourceLimitError before allocating."""
    A, B, C, D = _system(2, 3, 4, seed=23)
    rng = np.random.default_rng(24)
    pieces, x0s = [], []
    for length in (50, 40, 60):
        u = rng.standard_normal((length, 3))
        x0s.append(rng.standard_normal(2))
        pieces.append(subid.IOData(u, _simulate(A, B, C, D, u, x0s[-1])))
    data = subid.merge(pieces)
    monkeypatch.setattr(_bd_large, "DENSE_LIMIT", 1000)
    B1, D1, x1, diag = bd.fit_b_d_x0(A, C, data)
    assert diag["regression_path"] == "channels" and diag["bd_method"] == "simulation"
    _close(B1, B, 1e-8)
    _close(D1, D, 1e-8)
    _close(x1, np.array(x0s), 1e-8)
    monkeypatch.setattr(_bd_large, "MEMORY_LIMIT", 1000)
    with pytest.raises(ResourceLimitError, match="estimate_x0=False"):
        bd.fit_b_d_x0(A, C, data)
