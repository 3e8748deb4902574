"""RecursiveSubspace: seed 001 made recursive."""

import warnings

import numpy as np
import pytest

import subid
from subid import errors, systems
from subid.methods.online.recursive import givens_update, givens_update_reference


@pytest.fixture(scope="module")
def noisy():
    return systems.simulate_data(systems.seed001_system(), 3000, seed=1, process_snr_db=25,
                                 output_snr_db=25)


@pytest.mark.parametrize("instruments", ["past", None])
def test_equals_batch_with_forgetting_one(noisy, instruments):
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments,
                                 bd_method="projection")
    rs.update(noisy.u, noisy.y)
    batch = subid.ls_subspace(noisy, 3, horizon=5, instruments=instruments,
                              selector=rs.selector, bd_method="projection",
                              system_matrices="shift")   # the recursion's estimator
    for name in "ABCD":
        np.testing.assert_allclose(getattr(rs.model, name), getattr(batch, name), atol=1e-8,
                                   err_msg=name)
    np.testing.assert_allclose(rs.selector, batch.info["selector"])


def test_noise_free_exact_and_state():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 600, seed=2, x0=[1.0, 0.0, -1.0])
    rs = subid.RecursiveSubspace(3, 2, 2).update(data.u, data.y)
    assert subid.markov_error(rs.model, true) < 1e-9
    m = rs.model
    np.testing.assert_allclose(m.C @ rs.state + m.D @ data.u[-1], data.y[-1], atol=1e-9)


def test_chunking_does_not_matter(noisy):
    whole = subid.RecursiveSubspace(3, 2, 2, forgetting=0.999).update(noisy.u, noisy.y)
    for size in (1, 7, 1000):
        rs = subid.RecursiveSubspace(3, 2, 2, forgetting=0.999)
        for k in range(0, 1200, size):      # the first 1200 samples one piece at a time
            rs.update(noisy.u[k:min(k + size, 1200)], noisy.y[k:min(k + size, 1200)])
        rs.update(noisy.u[1200:], noisy.y[1200:])
        np.testing.assert_allclose(rs._R, whole._R, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(rs.model.A, whole.model.A, rtol=1e-10, atol=1e-12)


def test_single_sample_forms():
    true = systems.random_system(2, 1, 1, seed=0)
    data = systems.simulate_data(true, 300, seed=0)
    a = subid.RecursiveSubspace(2, 1, 1)
    b = subid.RecursiveSubspace(2, 1, 1)
    for k in range(300):
        a.update(data.u[k, 0], data.y[k, 0])          # scalars
    b.update(data.u[:, 0], data.y[:, 0])               # 1-D = one channel, 300 samples
    np.testing.assert_allclose(a.model.A, b.model.A, rtol=1e-12)
    c = subid.RecursiveSubspace(3, 2, 2)
    c.update(np.ones(2), np.zeros(2))                  # one sample of two channels
    assert c.n_samples == 1


def test_tracks_switch_in_same_basis():
    """Seed 001's point for switched systems: after a switch the estimate
    converges to the new system expressed in the same (Λ-fixed) basis."""
    s1 = systems.random_system(3, 2, 2, seed=11)
    s2 = systems.random_system(3, 2, 2, seed=12)
    d1 = systems.simulate_data(s1, 3000, seed=1)
    d2 = systems.simulate_data(s2, 4000, seed=2)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, forgetting=0.995)
    rs.update(d1.u, d1.y)
    assert subid.markov_error(rs.model, s1) < 1e-6
    before = rs.model
    rs.update(d2.u, d2.y)
    after = rs.model
    assert subid.markov_error(after, s2) < 1e-6
    assert subid.markov_error(after, s1) > 0.1
    ref = subid.ls_subspace(d2, 3, horizon=5, selector=rs.selector)   # s2 in the basis of Λ
    for name in "AC":
        np.testing.assert_allclose(getattr(after, name), getattr(ref, name), atol=1e-6)
    ref1 = subid.ls_subspace(d1, 3, horizon=5, selector=rs.selector)
    np.testing.assert_allclose(before.A, ref1.A, atol=1e-6)


def test_checkpoint_round_trip(tmp_path, noisy):
    path = tmp_path / "rs.npz"
    straight = subid.RecursiveSubspace(3, 2, 2, forgetting=0.998, history_size=8,
                                       history_stride=100)
    straight.update(noisy.u, noisy.y)
    first = subid.RecursiveSubspace(3, 2, 2, forgetting=0.998, history_size=8,
                                    history_stride=100)
    first.update(noisy.u[:1234], noisy.y[:1234])
    first.save(path)
    resumed = subid.RecursiveSubspace.load(path)
    resumed.update(noisy.u[1234:], noisy.y[1234:])
    np.testing.assert_array_equal(resumed._R, straight._R)
    np.testing.assert_array_equal(resumed.model.A, straight.model.A)
    np.testing.assert_array_equal(resumed.history["poles"], straight.history["poles"])


def test_corrupted_checkpoint(tmp_path, noisy):
    path = tmp_path / "rs.npz"
    subid.RecursiveSubspace(3, 2, 2).update(noisy.u[:100], noisy.y[:100]).save(path)
    raw = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(errors.CheckpointError, match="truncated or corrupted"):
        subid.RecursiveSubspace.load(tmp_path / "cut.npz")
    with pytest.raises(errors.DataFileNotFoundError):
        subid.RecursiveSubspace.load(tmp_path / "missing.npz")
    subid.StateSpace(np.eye(1) * 0.5, [[1.0]], [[1.0]], 0, 1.0).save(tmp_path / "m.json")
    with pytest.raises(errors.CheckpointError):
        subid.RecursiveSubspace.load(tmp_path / "m.json")


def test_bad_samples_leave_state_unchanged(noisy):
    rs = subid.RecursiveSubspace(3, 2, 2).update(noisy.u[:500], noisy.y[:500])
    R = rs._R.copy()
    bad_u = noisy.u[500:520].copy()
    bad_u[7, 1] = np.nan
    with pytest.raises(errors.DataError, match="NaN value at row 7"):
        rs.update(bad_u, noisy.y[500:520])
    with pytest.raises(errors.DataError, match="3 channels"):
        rs.update(np.zeros((5, 3)), np.zeros((5, 2)))
    with pytest.raises(errors.DataError, match="samples"):
        rs.update(np.zeros((5, 2)), np.zeros((4, 2)))
    np.testing.assert_array_equal(rs._R, R)
    assert rs.n_samples == 500


def test_too_few_samples_and_bad_parameters():
    rs = subid.RecursiveSubspace(3, 2, 2).update(np.ones((10, 2)), np.ones((10, 2)))
    with pytest.raises(errors.TooFewSamplesError, match="received 10 samples"):
        rs.model
    with pytest.raises(errors.SubidError, match="forgetting"):
        subid.RecursiveSubspace(3, 2, 2, forgetting=1.5)
    with pytest.raises(errors.OrderError, match="horizon"):
        subid.RecursiveSubspace(9, 1, 2, horizon=4)


def test_history_bounded():
    true = systems.random_system(2, 1, 1, seed=3)
    data = systems.simulate_data(true, 20_000, seed=3)
    rs = subid.RecursiveSubspace(2, 1, 1, history_size=10, history_stride=50)
    rs.update(data.u, data.y)
    h = rs.history
    assert 5 <= h["sample"].size < 10
    assert np.all(np.diff(h["sample"]) > 0)
    np.testing.assert_allclose(np.sort_complex(h["poles"][-1]), np.sort_complex(true.poles()),
                               atol=1e-8)


def test_kernel_matches_reference():
    r = np.random.default_rng(0)
    rows = r.standard_normal((300, 12))
    R1 = givens_update(np.zeros((12, 12)), rows, np.sqrt(0.98))
    R2 = givens_update_reference(np.zeros((12, 12)), rows, np.sqrt(0.98))
    np.testing.assert_allclose(R1, R2, rtol=1e-12, atol=1e-12)
    # the factor of the weighted correlation
    w = 0.98 ** np.arange(299, -1, -1)
    np.testing.assert_allclose(R1.T @ R1, (rows * w[:, None]).T @ rows, rtol=1e-10, atol=1e-10)


# ---------------------------------------------------------------------------
# issue 12: B, D and the state from the recursive output-error regression
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("instruments", ["past", None])
def test_regression_equals_batch_default_noise_free(instruments):
    """Noise-free: the recursive regression gives the batch model (default
    bd_method, output-error regression with x0) to rounding."""
    true = systems.seed001_system()
    data = systems.simulate_data(true, 800, seed=2, x0=[1.0, 0.0, -1.0])
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments)
    rs.update(data.u, data.y)
    # the batch call the recursive identifier equals: its D estimated and its B, D by the
    # output regression (the batch defaults choose the feedthrough and the estimator)
    batch = subid.ls_subspace(data, 3, horizon=5, instruments=instruments,
                              selector=rs.selector, feedthrough=True, system_matrices="shift")
    assert batch.info["bd_method"] == "simulation"
    model = rs.model
    assert model.info["bd_method"] == "simulation"
    for name in "ABCD":
        np.testing.assert_allclose(getattr(model, name), getattr(batch, name), atol=1e-8,
                                   err_msg=name)
    np.testing.assert_allclose(model.C @ rs.state + model.D @ data.u[-1], data.y[-1],
                               atol=1e-9)


def test_regression_with_noise_close_to_batch(noisy):
    """Forgetting < 1 on noisy data: the propagated recursion uses (A, C) as
    they were when the samples came, so it is close to the batch model, not
    equal (with forgetting 1 it is equal: test_regression_equals_batch_noisy)."""
    true = systems.seed001_system()
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, forgetting=0.99999)
    rs.update(noisy.u, noisy.y)
    batch = subid.ls_subspace(noisy, 3, horizon=5, selector=rs.selector)
    model = rs.model
    np.testing.assert_allclose(model.A, batch.A, rtol=1e-2)    # forgetting 1e-5: near
    assert subid.markov_error(model, true) < 2.5 * subid.markov_error(batch, true)


@pytest.mark.parametrize("instruments", ["past", None])
@pytest.mark.parametrize("samples, lags", [(400, 1000), (3000, 300)])
def test_regression_equals_batch_noisy(instruments, samples, lags):
    """Issue 12: with forgetting 1 the recursive B, D, x0 (and the state) are
    those of the batch default regression on NOISY data too, to 1e-8: the
    normal equations are evaluated from the lagged statistics with the
    current (A, C). Exact for any stable A while samples <= lags + 1, else up
    to |A^(lags+1)| (1e-17 here). The stream arrives in uneven chunks (FFT
    and sample-by-sample paths of the statistic)."""
    true = systems.seed001_system()
    data = systems.simulate_data(true, samples, seed=4, x0=[1.0, -2.0, 0.5],
                                 process_snr_db=20, output_snr_db=20)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments, lags=lags)
    for a, b in ((0, 3), (3, 70), (70, 71), (71, 333), (333, samples)):
        rs.update(data.u[a:b], data.y[a:b])
    # the batch call the recursive identifier equals: its D estimated and its B, D by the
    # output regression (the batch defaults choose the feedthrough and the estimator)
    batch = subid.ls_subspace(data, 3, horizon=5, instruments=instruments,
                              selector=rs.selector, feedthrough=True, system_matrices="shift")
    assert batch.info["bd_method"] == "simulation"
    model = rs.model
    assert model.info["bd_method"] == "simulation"
    assert model.info["bd_truncation"] < 1e-16
    for name in "ABCD":
        np.testing.assert_allclose(getattr(model, name), getattr(batch, name), atol=1e-8,
                                   err_msg=name)
    np.testing.assert_allclose(model.info["x0"], batch.info["x0"], atol=1e-8)
    # the state at the last sample: the batch model run from its x0
    x = batch.info["x0"]
    for k in range(samples - 1):
        x = batch.A @ x + batch.B @ data.u[k]
    np.testing.assert_allclose(rs.state, x, atol=1e-8)


def test_lagged_statistic_matches_direct_sums():
    """The lagged products by the compiled kernel, the numpy reference and the
    FFT path (blocks) equal the direct sums; the ring and head buffers
    hold the last and first samples whatever the chunking."""
    from subid.methods.online._lagged import LaggedStatistic, lag_update_reference
    z = np.random.default_rng(0).standard_normal((900, 3))
    for lags in (5, 64, 400, 2000):
        direct = np.array([z[:900 - d, :1].T @ z[d:] if d < 900 else np.zeros((1, 3))
                           for d in range(lags + 1)])
        ref = LaggedStatistic(1, 2, lags)
        ref.update(z[:, :1], z[:, 1:], kernel=lag_update_reference)
        np.testing.assert_allclose(ref.G, direct, atol=1e-11)
        np.testing.assert_allclose(ref.G0, z.T @ z, atol=1e-11)
        pieces = LaggedStatistic(1, 2, lags)
        for a, b in ((0, 70), (70, 73), (73, 200), (200, 201), (201, 900)):
            pieces.update(z[a:b, :1], z[a:b, 1:])
        assert pieces.n_samples == 900
        pieces.flush()                      # blocks of 256 by FFT, then the rest
        np.testing.assert_allclose(pieces.G, direct, atol=1e-11)
        np.testing.assert_allclose(pieces.G0, z.T @ z, atol=1e-11)
        for name in ("ring", "head"):
            np.testing.assert_array_equal(getattr(pieces, name), getattr(ref, name))
        assert pieces.count == ref.count == 900


def test_lagged_kernel_matches_reference():
    from subid.methods.online._lagged import LaggedStatistic, lag_update, lag_update_reference
    z = np.random.default_rng(1).standard_normal((50, 4))
    a, b = LaggedStatistic(2, 2, 20), LaggedStatistic(2, 2, 20)
    for k in range(0, 50, 7):
        a.count = lag_update(a.G0, a.G, a.ring, a.head, z[k:k + 7], a.count)
        b.count = lag_update_reference(b.G0, b.G, b.ring, b.head, z[k:k + 7], b.count)
    np.testing.assert_allclose(a.G, b.G, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(a.G0, b.G0, rtol=1e-14, atol=1e-14)


def test_regression_truncation_warns():
    """Fewer lags than the impulse response needs: the model says so."""
    true = systems.seed001_system()
    data = systems.simulate_data(true, 600, seed=2)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, lags=10).update(data.u, data.y)
    with pytest.warns(errors.NotConvergedWarning, match="lags"):
        model = rs.model
    assert model.info["bd_truncation"] > 1e-8
    with pytest.raises(errors.SubidError, match="lags"):
        subid.RecursiveSubspace(3, 2, 2, lags=0)


def test_chunking_without_instruments():
    """Regression test: with instruments=None the buffer holds the last
    horizon samples, and a chunk boundary used to add one Hankel column twice
    (A off by 0.05 on 20 dB data in chunks of 1000)."""
    data = systems.simulate_data(systems.seed001_system(), 3000, seed=1,
                                 process_snr_db=20, output_snr_db=20)
    whole = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=None)
    whole.update(data.u, data.y)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=None)
    for k in range(0, 3000, 1000):
        rs.update(data.u[k:k + 1000], data.y[k:k + 1000])
    assert rs._n_columns == whole._n_columns == 3000 - 5 + 1
    np.testing.assert_allclose(rs.model.A, whole.model.A, atol=1e-10)


def test_regression_cd_player_within_3_points_of_batch():
    """The issue's real-data check: CD_player_arm, first 2/3 (means of the
    estimation part removed), order 4, forgetting 1."""
    d = subid.datasets.load("CD_player_arm")
    k = 2 * d.n_samples // 3
    mu, my = d.u[:k].mean(axis=0), d.y[:k].mean(axis=0)
    est = subid.IOData(d.u[:k] - mu, d.y[:k] - my, dt=d.dt)
    val = subid.IOData(d.u[k:] - mu, d.y[k:] - my, dt=d.dt)
    batch = subid.ls_subspace(est, 4)
    rs = subid.RecursiveSubspace(4, 2, 2, horizon=batch.info["horizon"], dt=d.dt)
    rs.update(est.u, est.y)
    fit_b = subid.fit_percent(batch, val)
    fit_r = subid.fit_percent(rs.model, val)
    assert np.all(fit_r > fit_b - 3), (fit_r, fit_b)
    old = subid.RecursiveSubspace(4, 2, 2, horizon=batch.info["horizon"], dt=d.dt,
                                  bd_method="projection").update(est.u, est.y)
    assert np.all(subid.fit_percent(old.model, val) < 0)      # what the issue measured


def test_regression_chunking_and_checkpoint_exact(tmp_path, noisy):
    """Chunking changes the Hankel factor only by rounding (as before), so the
    regression agrees to rounding; a checkpoint continues bit-identically."""
    kw = dict(forgetting=0.999, refresh_every=37)
    whole = subid.RecursiveSubspace(3, 2, 2, **kw).update(noisy.u, noisy.y)
    runs = {}
    for size, resume in ((1, False), (7, False), (7, True), (1000, False)):
        rs = subid.RecursiveSubspace(3, 2, 2, **kw)
        for k in range(0, 1200, size):
            rs.update(noisy.u[k:min(k + size, 1200)], noisy.y[k:min(k + size, 1200)])
        if resume:
            rs.save(tmp_path / "rs.npz")
            rs = subid.RecursiveSubspace.load(tmp_path / "rs.npz")
        rs.update(noisy.u[1200:], noisy.y[1200:])
        runs[size, resume] = rs
        np.testing.assert_allclose(rs._bd_R, whole._bd_R, rtol=1e-9, atol=1e-9)
        for name in "BD":
            np.testing.assert_allclose(getattr(rs.model, name), getattr(whole.model, name),
                                       rtol=1e-9, atol=1e-10)
    a, b = runs[7, False], runs[7, True]
    np.testing.assert_array_equal(a._bd_R, b._bd_R)
    np.testing.assert_array_equal(a.state, b.state)
    np.testing.assert_array_equal(a.model.B, b.model.B)


def test_regression_restarts_after_a_switch_and_tracks():
    s1 = systems.random_system(3, 2, 2, seed=11)
    s2 = systems.random_system(3, 2, 2, seed=12)
    d1 = systems.simulate_data(s1, 3000, seed=1)
    d2 = systems.simulate_data(s2, 4000, seed=2)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, forgetting=0.995)
    rs.update(d1.u, d1.y)
    assert rs.model.info["bd_method"] == "simulation"
    assert subid.markov_error(rs.model, s1) < 1e-6
    restarts = rs.model.info["bd_restarts"]
    rs.update(d2.u, d2.y)
    assert rs.model.info["bd_restarts"] > restarts
    assert subid.markov_error(rs.model, s2) < 1e-6


def test_regression_not_started_warns():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 49, seed=2)     # a model, but no refresh yet (50)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, forgetting=0.999)
    rs.update(data.u, data.y)
    with pytest.warns(errors.NotConvergedWarning, match="has not started"):
        model = rs.model
    assert model.info["bd_method"] == "projection" and model.info["bd_fallback"]
    with pytest.raises(errors.SubidError, match="bd_method"):
        subid.RecursiveSubspace(3, 2, 2, bd_method="regression")


@pytest.mark.parametrize("kw", [{}, {"forgetting": 0.99, "refresh_every": 50}])
def test_one_sample_arrays_equal_one_sample_chunks_bit_for_bit(noisy, kw):
    """The cheap path of 1-D samples gives exactly the state of (1, channels)
    chunks (the general path), and rejects a non-finite sample like it."""
    a = subid.RecursiveSubspace(3, 2, 2, **kw)
    b = subid.RecursiveSubspace(3, 2, 2, **kw)
    for k in range(700):
        a.update(noisy.u[k], noisy.y[k])
        b.update(noisy.u[k:k + 1], noisy.y[k:k + 1])
    bad = noisy.u[700].copy()
    bad[0] = np.nan
    with pytest.raises(errors.DataError, match="input u"):
        a.update(bad, noisy.y[700])
    with pytest.raises(errors.DataError, match="output y"):
        a.update(noisy.u[700], np.array([0.0, np.inf]))
    for name in ("_R", "_bd_R", "_buf_u", "_buf_y"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    if a._lag is not None:
        for name, value in a._lag.arrays().items():
            np.testing.assert_array_equal(value, b._lag.arrays()[name], err_msg=name)
    assert a.n_samples == b.n_samples == 700
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(a.model, name), getattr(b.model, name))


def test_lagged_statistic_one_sample_updates_equal_chunks():
    from subid.methods.online._lagged import BLOCK, LaggedStatistic
    rng = np.random.default_rng(6)
    n = 2 * BLOCK + 37
    u, y = rng.standard_normal((n, 2)), rng.standard_normal((n, 1))
    one, whole = LaggedStatistic(2, 1, 40), LaggedStatistic(2, 1, 40)
    for k in range(n):
        one.update(u[k:k + 1], y[k:k + 1])
    whole.update(u, y)
    assert one.n_samples == whole.n_samples == n
    for name, value in one.arrays().items():
        np.testing.assert_array_equal(value, whole.arrays()[name], err_msg=name)


def test_a_normal_matrix_that_lost_its_positive_diagonal_falls_back():
    """An output with an offset and a trend left in (means of the first half removed):
    the B, D normal matrix accumulated from lag products lost its positive diagonal to
    rounding after 5,500 samples, and `model` ended in numpy's "Eigenvalues did not
    converge" (a traceback through `subid track`). That matrix is now refused like an
    ill-conditioned one, and the projected data equation gives B and D."""
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 8000, seed=3,
                                       output_snr_db=30)
    y = data.y + np.array([5.0, -3.0]) + np.linspace(0, 2, 8000)[:, None]
    y = y - y[:4000].mean(axis=0)
    u = data.u - data.u[:4000].mean(axis=0)
    ident = subid.RecursiveSubspace(3, 2, 2, dt=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", subid.errors.NotConvergedWarning)
        for k in range(0, 8000, 500):
            ident.update(u[k:k + 500], y[k:k + 500])
            model = ident.model
            assert all(np.isfinite(m).all() for m in (model.A, model.B, model.C, model.D))


def test_equals_the_batch_model_with_the_same_selector_on_a_real_record():
    """CD_player_arm (first 2/3, means removed, order 4, horizon 10, forgetting 1): the
    online model equals ls_subspace's for the same Λ (1.8e-12 measured); the defaults
    draw Λ in different units (here the user's, there the normalised channels'), so the
    default calls differ (Markov error 0.17), as the README says."""
    d = subid.datasets.load("CD_player_arm")
    est = d[:2 * d.n_samples // 3].detrend()
    ident = subid.RecursiveSubspace(4, 2, 2, horizon=10, dt=d.dt).update(est.u, est.y)
    online = ident.model
    batch = subid.ls_subspace(est, 4, horizon=10, feedthrough=True, system_matrices="shift",
                              selector=online.info["selector"])
    assert subid.markov_error(online, batch) < 1e-9
