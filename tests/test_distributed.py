"""Dask: per-partition statistics merged exactly, on a 2-worker LocalCluster."""

import numpy as np
import pytest

import subid
from subid import systems

dask = pytest.importorskip("dask", reason="dask is not installed")
da = pytest.importorskip("dask.array")
distributed = pytest.importorskip("dask.distributed", reason="dask.distributed is not installed")

from subid.methods.dt import distributed as sd  # noqa: E402


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="module")
def record():
    true = systems.seed001_system()
    return true, systems.simulate_data(true, 40_000, seed=7, process_snr_db=20,
                                       output_snr_db=20)


@pytest.mark.parametrize("method,fn,kw", [
    ("moesp", subid.moesp, {}), ("n4sid", subid.n4sid, {}), ("ls", subid.ls_subspace, {}),
    ("ls", subid.ls_subspace, {"instruments": None}),
])
@pytest.mark.slow
def test_dask_arrays_equal_single_machine(client, record, method, fn, kw):
    true, data = record
    u = da.from_array(data.u, chunks=(6_007, 2))      # borders fall anywhere
    y = da.from_array(data.y, chunks=(6_007, 2))
    model = sd.identify(u, y, method, dt=1.0, order=3, horizon=5, client=client, **kw)
    single = fn(data, 3, horizon=5, statistic="gram", **kw)    # the in-memory default
    for name in "ABCDK":
        np.testing.assert_allclose(getattr(model, name), getattr(single, name), rtol=1e-10,
                                   atol=1e-10, err_msg=name)
    np.testing.assert_allclose(model.info["x0"], single.info["x0"], rtol=1e-10, atol=1e-10)
    assert model.info.get("bd_method") == single.info.get("bd_method")
    assert model.info["n_samples"] == 40_000


def test_dask_projection_kept(client, record):
    """bd_method='projection': the statistic only, one pass, as before."""
    _, data = record
    u = da.from_array(data.u, chunks=(6_007, 2))
    y = da.from_array(data.y, chunks=(6_007, 2))
    model = sd.identify(u, y, "moesp", order=3, horizon=5, client=client,
                        bd_method="projection")
    single = subid.moesp(data, 3, horizon=5, statistic="gram", bd_method="projection")
    assert model.info["bd_method"] == "projection"
    for name in "ABCD":
        np.testing.assert_allclose(getattr(model, name), getattr(single, name), rtol=1e-10,
                                   atol=1e-10, err_msg=name)


def test_dask_second_pass_differs_from_projection(client):
    """On a short noisy record the projection and the regression differ clearly, and
    the distributed model is the regression's (guards against a silent projection)."""
    true = systems.random_system(4, 2, 2, seed=3)
    data = systems.simulate_data(true, 20_000, seed=4, output_snr_db=10)
    u = da.from_array(data.u, chunks=(3_001, 2))
    y = da.from_array(data.y, chunks=(3_001, 2))
    model = sd.identify(u, y, "ls", order=4, horizon=6, client=client)
    single = subid.ls_subspace(data, 4, horizon=6, statistic="gram")
    projection = subid.ls_subspace(data, 4, horizon=6, statistic="gram", bd_method="projection")
    assert np.abs(single.B - projection.B).max() > 1e-6
    np.testing.assert_allclose(model.B, single.B, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(model.D, single.D, rtol=1e-10, atol=1e-10)


@pytest.mark.slow
def test_dask_qr_statistic_and_uneven_chunks(client, record):
    _, data = record
    u = da.from_array(data.u, chunks=((5, 20_000, 19_995), (2,)))   # a tiny partition
    y = da.from_array(data.y, chunks=(1000, 1))                      # rechunked to match u
    model = sd.identify(u, y, "moesp", order=3, horizon=5, statistic="qr", client=client)
    single = subid.moesp(data, 3, horizon=5, statistic="qr", bd_method="projection")
    np.testing.assert_allclose(model.A, single.A, rtol=1e-10, atol=1e-10)


@pytest.mark.slow
def test_identify_files(client, record, tmp_path):
    _, data = record
    paths = []
    for k, (a, b) in enumerate([(0, 12_000), (12_000, 12_003), (12_003, 40_000)]):
        path = tmp_path / f"day{k}.csv"
        np.savetxt(path, np.hstack([data.u[a:b], data.y[a:b]]), delimiter=",",
                   header="u1,u2,y1,y2", comments="", fmt="%.17g")
        paths.append(path)
    model = sd.identify_files(paths, "u1,u2", "y1,y2", "n4sid", order=3, horizon=5,
                              client=client, chunk_size=5000)
    single = subid.n4sid(data, 3, horizon=5, statistic="gram")
    np.testing.assert_allclose(model.A, single.A, rtol=1e-10, atol=1e-10)
    assert model.input_names == ("u1", "u2")
    model = sd.identify_files(paths, "u1,u2", "y1,y2", "moesp", order=3, horizon=5,
                              client=client, chunk_size=5000)
    single = subid.moesp(data, 3, horizon=5, statistic="gram")
    for name in "ABCDK":
        np.testing.assert_allclose(getattr(model, name), getattr(single, name), rtol=1e-10,
                                   atol=1e-10, err_msg=name)
    np.testing.assert_allclose(model.info["x0"], single.info["x0"], rtol=1e-10, atol=1e-10)


def test_identify_many(client):
    systems_ = [systems.random_system(2, 1, 1, seed=k) for k in range(6)]
    records = [systems.simulate_data(s, 800, seed=k) for k, s in enumerate(systems_)]
    records.append(subid.IOData(np.zeros(300), np.random.default_rng(0).standard_normal(300)))
    models, summary = sd.identify_many(records, "moesp", 2, client=client)
    for s, m in zip(systems_, models):
        assert subid.markov_error(m, s) < 1e-8
    assert models[-1] is None and "not sufficiently exciting" in summary[-1]["error"]
    assert [row["order"] for row in summary[:6]] == [2] * 6
    assert "| record6 |" in sd.summary_markdown(summary)


def test_threads_scheduler_without_client(record):
    _, data = record
    u = da.from_array(data.u, chunks=(10_000, 2))
    y = da.from_array(data.y, chunks=(10_000, 2))
    model = sd.identify(u, y, "moesp", order=3, horizon=5)
    single = subid.moesp(data, 3, horizon=5, statistic="gram")
    for name in "ABCD":
        np.testing.assert_allclose(getattr(model, name), getattr(single, name), rtol=1e-10,
                                   atol=1e-10, err_msg=name)


def test_seed001_monte_carlo_through_dask_is_reproducible(client):
    from subid.experiments import seed001
    local = seed001.run(runs=4, n_samples=400)
    remote = seed001.run(runs=4, n_samples=400, client=client)
    for name in seed001.METHODS:
        np.testing.assert_array_equal(local[0][name], remote[0][name])


def test_files_whose_columns_by_position_name_other_channels_are_refused(client, record,
                                                                         tmp_path):
    # columns chosen by position ("0,1", "2,3") in files whose headers order the channels
    # differently mixed outputs into inputs silently (validation fit 6 % against 90 %);
    # subid.merge refuses the same records in memory
    _, data = record
    first, second = tmp_path / "a.csv", tmp_path / "b.csv"
    np.savetxt(first, np.hstack([data.u[:20_000], data.y[:20_000]]), delimiter=",",
               header="u1,u2,y1,y2", comments="")
    np.savetxt(second, np.hstack([data.y[20_000:], data.u[20_000:]]), delimiter=",",
               header="y1,y2,u1,u2", comments="")
    match = r"has channels \['y1', 'y2'\] -> \['u1', 'u2'\] but .*file 1.* has \['u1'"
    with pytest.raises(subid.errors.DataError, match=match):
        subid.identify_file([first, second], "0,1", "2,3", dt=1.0, method="moesp", order=3,
                            horizon=5)
    with pytest.raises(subid.errors.DataError, match=match):
        sd.identify_files([first, second], "0,1", "2,3", "moesp", order=3, horizon=5,
                          client=client)
    # by name, the files agree: the same model either way
    by_name = subid.identify_file([first, second], "u1,u2", "y1,y2", dt=1.0, method="moesp",
                                  order=3, horizon=5)
    assert by_name.input_names == ("u1", "u2")
