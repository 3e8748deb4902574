"""Reading in pieces and identifying from the statistic with bounded memory."""

import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import subid
from subid import errors, systems


@pytest.fixture(scope="module")
def record():
    true = systems.seed001_system()
    return true, systems.simulate_data(true, 30_000, seed=1, output_snr_db=30)


def _write_csv(path, data):
    np.savetxt(path, np.hstack([data.u, data.y]), delimiter=",", header="u1,u2,y1,y2",
               comments="")


def test_text_pieces_equal_whole_read(tmp_path, record):
    _, data = record
    path = tmp_path / "rec.csv"
    _write_csv(path, data)
    whole = subid.read(path, "u1,u2", "y1,y2", dt=0.5)
    pieces = list(subid.read_chunks(path, "u1,u2", "y1,y2", dt=0.5, chunk_size=7000))
    assert [p.n_samples for p in pieces] == [7000] * 4 + [2000]
    np.testing.assert_array_equal(np.vstack([p.u for p in pieces]), whole.u)
    np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), whole.y)
    assert pieces[1].t[0] == pytest.approx(3500.0)
    assert pieces[0].input_names == ("u1", "u2")


def test_identify_file_equals_in_memory(tmp_path, record):
    true, data = record
    path = tmp_path / "rec.csv"
    _write_csv(path, data)
    streamed = subid.identify_file(path, "u1,u2", "y1,y2", method="moesp", order=3, horizon=5,
                                   chunk_size=4096)
    in_memory = subid.moesp(data, 3, horizon=5, statistic="gram")     # the default
    for name in "ABCDK":
        np.testing.assert_allclose(getattr(streamed, name), getattr(in_memory, name),
                                   rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(streamed.info["x0"], in_memory.info["x0"], rtol=1e-10,
                               atol=1e-10)
    assert streamed.info["bd_method"] == "simulation"
    assert streamed.info["n_samples"] == 30_000
    assert subid.markov_error(streamed, true) < 0.01
    # the statistic-only path stays available
    streamed = subid.identify_file(path, "u1,u2", "y1,y2", method="moesp", order=3, horizon=5,
                                   chunk_size=4096, bd_method="projection")
    in_memory = subid.moesp(data, 3, horizon=5, statistic="gram", bd_method="projection")
    assert streamed.info["bd_method"] == "projection"
    for name in "ABCD":
        np.testing.assert_allclose(getattr(streamed, name), getattr(in_memory, name),
                                   rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("method,fn,kw", [
    ("ls", subid.ls_subspace, {}), ("n4sid", subid.n4sid, {}),
    ("moesp", subid.moesp, {"statistic": "qr"}),
])
def test_identify_stream_pieces_equal_in_memory(record, method, fn, kw):
    _, data = record
    pieces = [data[a:a + 4001] for a in range(0, 30_000, 4001)]
    streamed = subid.identify_stream(pieces, method, 3, 5, **kw)
    in_memory = fn(data, 3, horizon=5, **{"statistic": "gram", **kw})
    for name in "ABCDK":
        np.testing.assert_allclose(getattr(streamed, name), getattr(in_memory, name),
                                   rtol=1e-10, atol=1e-10, err_msg=name)
    np.testing.assert_allclose(streamed.info["x0"], in_memory.info["x0"], rtol=1e-10,
                               atol=1e-10)


def test_identify_stream_one_shot_iterator_warns(record):
    _, data = record
    pieces = (data[a:a + 10_000] for a in range(0, 30_000, 10_000))
    with pytest.warns(UserWarning, match="one-shot iterator"):
        model = subid.identify_stream(pieces, "moesp", 3, 5)
    assert model.info["bd_method"] == "projection"



def test_identify_stream_non_uniform_piece_named_first_or_later(record):
    _, data = record
    pieces = [data[a:a + 5000] for a in range(0, 15_000, 5000)]
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.5, 1.5, 999)])
    odd = subid.IOData(data.u[:1000], data.y[:1000], t=t)
    assert odd.dt is None
    for at, position in ((0, 0), (3, 3)):
        bad = pieces[:at] + [odd] + pieces[at:]
        with pytest.raises(errors.DataError, match=rf"piece {position} is sampled with dt = None"
                                                   r".*resample them first"):
            subid.identify_stream(bad, "moesp", 3, 10)

def test_npy_memory_mapped(tmp_path, record):
    true, data = record
    path = tmp_path / "rec.npy"
    np.save(path, np.hstack([data.u, data.y]))
    model = subid.identify_file(path, "0,1", [2, 3], method="n4sid", order=3, horizon=5,
                                statistic="qr")
    assert model.info["n_samples"] == 30_000
    np.testing.assert_allclose(model.A, subid.n4sid(data, 3, horizon=5, statistic="qr").A,
                               rtol=1e-9, atol=1e-10)
    with pytest.raises(errors.FileReadError, match="column indices"):
        list(subid.read_chunks(path, [7], [2]))


def test_parquet(tmp_path, record):
    pa = pytest.importorskip("pyarrow", reason="pyarrow is not installed")
    import pyarrow.parquet as pq
    _, data = record
    table = pa.table({"u1": data.u[:, 0], "u2": data.u[:, 1], "y1": data.y[:, 0],
                      "y2": data.y[:, 1]})
    path = tmp_path / "rec.parquet"
    pq.write_table(table, path, row_group_size=5000)
    pieces = list(subid.read_chunks(path, ["u1", "u2"], "y1,y2", chunk_size=8000))
    np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), data.y)
    with pytest.raises(errors.FileReadError, match="no column 'y9'"):
        list(subid.read_chunks(path, "u1", "y9"))


def test_errors_name_global_line(tmp_path, record):
    _, data = record
    path = tmp_path / "bad.csv"
    _write_csv(path, data[:5000])
    lines = path.read_text().splitlines()
    lines[4321] = lines[4321].replace(lines[4321].split(",")[2], "oops", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(errors.FileReadError, match=r"line 4322, column 2 \('y1'\): 'oops'"):
        for _ in subid.read_chunks(path, "u1,u2", "y1,y2", chunk_size=1000):
            pass
    with pytest.raises(errors.FileReadError, match="cannot be read in pieces"):
        list(subid.read_chunks(tmp_path / "x.npz", "u", "y"))
    with pytest.raises(errors.DataFileNotFoundError):
        list(subid.read_chunks(tmp_path / "missing.csv", "u1", "y1"))
    with pytest.raises(errors.DataError, match="chunk_size"):
        list(subid.read_chunks(path, "u1", "y1", chunk_size=0))



@pytest.mark.parametrize("chunk", [64, 1000])
def test_npy_nan_names_file_row_and_column(tmp_path, chunk):
    """A NaN of a .npy stream is reported at its row in the file, not in the piece."""
    z = np.random.default_rng(0).standard_normal((20_000, 4))
    z[15_000, 2] = np.nan
    path = tmp_path / "nan.npy"
    np.save(path, z)
    with pytest.raises(errors.DataError, match=r"nan\.npy, row 15000 \(0-based\), column 2: NaN"):
        list(subid.read_chunks(path, [0, 1], [2, 3], chunk_size=chunk))
    z[15_000, 2] = 0.0
    z[19_999, 0] = -np.inf
    np.save(path, z)
    with pytest.raises(errors.DataError, match=r"row 19999 \(0-based\), column 0: -inf"):
        subid.identify_file(path, [0, 1], [2, 3], order=2, horizon=5, chunk_size=chunk)


def test_parquet_null_names_file_row_and_column(tmp_path):
    pa = pytest.importorskip("pyarrow", reason="pyarrow is not installed")
    import pyarrow.parquet as pq
    z = np.random.default_rng(0).standard_normal((300, 4))
    missing = np.zeros(300, bool)
    missing[100:105] = True
    table = pa.table({"u1": z[:, 0], "u2": z[:, 1], "y1": pa.array(z[:, 2], mask=missing),
                      "y2": z[:, 3]})
    path = tmp_path / "nulls.parquet"
    pq.write_table(table, path)
    with pytest.raises(errors.DataError,
                       match=r"nulls\.parquet, row 100 \(0-based\), column 'y1': null or NaN"):
        list(subid.read_chunks(path, "u1,u2", "y1,y2", chunk_size=64))



def test_time_column_without_dt_warns_and_names_dt(tmp_path, record, capsys):
    """read_chunks takes no time column: read without dt, a column named like time
    stamps is worth the warning read() gives (and the command line names --dt)."""
    _, data = record
    path = tmp_path / "timed.csv"
    np.savetxt(path, np.column_stack([np.arange(3000) * 0.5, data.u[:3000], data.y[:3000]]),
               delimiter=",", header="t,u1,u2,y1,y2", comments="")
    with pytest.warns(errors.SamplingWarning, match="the column 't' looks like time stamps: "
                                                    "pass its sampling period as dt"):
        pieces = list(subid.read_chunks(path, "u1,u2", "y1,y2", chunk_size=1000))
    assert pieces[0].dt == 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error", errors.SamplingWarning)
        list(subid.read_chunks(path, "u1,u2", "y1,y2", dt=0.5))
    from subid.cli import commands as cli
    code = cli.main(["identify", str(path), "--inputs", "u1,u2", "--outputs", "y1,y2",
                     "--method", "moesp", "--order", "3", "--stream", "--no-report",
                     "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "time is counted in samples" in err and "The column 't' looks like time stamps" \
        in err and "add --dt" in err, err
    code = cli.main(["identify", str(path), "--inputs", "u1,u2", "--outputs", "y1,y2",
                     "--method", "moesp", "--order", "3", "--stream", "--no-report", "--dt",
                     "0.5", "--out", str(tmp_path / "out2")])
    err = capsys.readouterr().err
    assert code == 0 and "WARNING" not in err, err

_MEMORY_SCRIPT = textwrap.dedent("""
    import sys, tracemalloc
    import subid
    path, mode = sys.argv[1], sys.argv[2]
    warm = subid.systems.simulate_data(subid.systems.seed001_system(), 500, seed=0)
    subid.moesp(warm, 3, horizon=5)                       # compile and import everything
    subid.identify_stream([warm[:250], warm[250:]], order=3, horizon=5)
    import os, tempfile                                   # import the CSV parser too
    small = os.path.join(tempfile.mkdtemp(), "small.csv")
    with open(small, "w") as fh:
        fh.write("u1,u2,y1,y2\\n" + "1,2,3,4\\n" * 10)
    subid.read(small, "u1,u2", "y1,y2")
    list(subid.read_chunks(small, "u1,u2", "y1,y2"))
    tracemalloc.start()                                   # numpy reports to tracemalloc
    if mode == "stream":
        subid.identify_file(path, "u1,u2", "y1,y2", order=3, horizon=5, chunk_size=20000)
    elif mode == "cli":
        from subid.cli import commands as cli
        assert cli.main(["--quiet", "identify", path, "--inputs", "u1,u2", "--outputs",
                         "y1,y2", "--method", "moesp", "--order", "3", "--horizon", "5",
                         "--stream", "--chunk-size", "20000", "--out", sys.argv[3]]) == 0
    else:
        subid.moesp(subid.read(path, "u1,u2", "y1,y2"), 3, horizon=5)
    print(tracemalloc.get_traced_memory()[1] / 2**20)
""")


@pytest.mark.slow
def test_streaming_memory_is_bounded(tmp_path):
    """A 600,000-row CSV: reading it whole costs far more memory than the
    cap that the streamed identification stays under (peak of the traced
    allocations)."""
    r = np.random.default_rng(0)
    block = r.standard_normal((600_000, 4))
    path = tmp_path / "long.csv"
    np.savetxt(path, block, delimiter=",", header="u1,u2,y1,y2", comments="", fmt="%.6f")
    peak = {}
    for mode in ("stream", "cli", "whole"):
        out = subprocess.run([sys.executable, "-c", _MEMORY_SCRIPT, str(path), mode,
                              str(tmp_path / "cli_out")],
                             capture_output=True, text=True, check=True,
                             env={"OPENBLAS_NUM_THREADS": "1", "PATH": ""})
        peak[mode] = float(out.stdout.strip().splitlines()[-1])
    cap = 40.0   # MB
    assert peak["stream"] < cap, peak
    # `subid identify --stream`: also draws the report from its fixed 20,000 kept
    # samples (matplotlib), which does not grow with the file (measured 46 MB)
    assert peak["cli"] < 2 * cap, peak
    # reading whole holds the record (19.2 MB of doubles) and moesp's work arrays;
    # the fast parser keeps it under 3x the doubles plus moesp (measured 44 MB,
    # 206 MB with the line-by-line parser)
    assert 2 * peak["stream"] < peak["whole"] < 4 * 19.2, peak
    assert (tmp_path / "cli_out" / "report.html").exists()


@pytest.mark.slow
def test_cli_identify_stream_equals_library(tmp_path, record):
    from subid.cli import commands as cli
    _, data = record
    path = tmp_path / "rec.csv"
    _write_csv(path, data)
    out = tmp_path / "out"
    assert cli.main(["--quiet", "identify", str(path), "--inputs", "u1,u2", "--outputs",
                     "y1,y2", "--dt", "1", "--method", "n4sid", "--order", "3", "--horizon",
                     "5", "--validate", "0.25", "--stream", "--chunk-size", "7000",
                     "--out", str(out)]) == 0
    model = subid.StateSpace.load(out / "model.json")
    est = data.detrend()[:22_500]            # the estimation part, means of the whole record
    reference = subid.n4sid(est, 3, horizon=5, statistic="gram")
    np.testing.assert_allclose(model.A, reference.A, rtol=1e-9, atol=1e-10)
    assert model.info["data"]["streamed"] and model.info["data"]["n_estimation"] == 22_500
    # moesp: B, D, x0 by the second pass, as the in-memory default
    assert cli.main(["--quiet", "identify", str(path), "--inputs", "u1,u2", "--outputs",
                     "y1,y2", "--dt", "1", "--method", "moesp", "--order", "3", "--horizon",
                     "5", "--validate", "0.25", "--stream", "--chunk-size", "7000",
                     "--out", str(out)]) == 0
    model = subid.StateSpace.load(out / "model.json")
    reference = subid.moesp(est, 3, horizon=5, statistic="gram")
    for name in "ABCD":
        np.testing.assert_allclose(getattr(model, name), getattr(reference, name), rtol=1e-9,
                                   atol=1e-10, err_msg=name)


def test_streamed_order_is_cross_validated_as_in_memory(tmp_path):
    # the statistic alone offered only the largest singular-value gap: order 2 for this
    # 4th-order system at 20 dB (validation fit 84-89 % against 90 %); the order is now
    # cross-validated on the record's last samples, as in memory, at the statistic's
    # horizon
    true = subid.systems.random_system(4, 2, 2, seed=7)
    data = subid.systems.simulate_data(true, 120_000, seed=107, output_snr_db=20)
    streamed = subid.identify_stream([data[:50_000], data[50_000:]], "ls")
    in_memory = subid.ls_subspace(data[-100_000:], horizon=10)
    assert streamed.order == in_memory.order == 4
    assert "last 100000 samples" in streamed.info["order_selection"]["streamed"]
    path = tmp_path / "big.csv"
    np.savetxt(path, np.column_stack([data.u, data.y]), delimiter=",",
               header="u1,u2,y1,y2", comments="")
    assert subid.identify_file(path, "u1,u2", "y1,y2", dt=1.0, method="ls").order == 4
