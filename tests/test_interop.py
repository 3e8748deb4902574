"""Round trips to python-control, scipy.signal, MATLAB .mat files and pandas."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io

import subid
from subid import systems
from subid.errors import DataError, DataFileNotFoundError, FileReadError, ModelError
from subid.io.interop import iodata_from_pandas, iodata_to_pandas, load_mat, save_mat

TOL = 1e-12


def _models():
    d = systems.random_system(4, 2, 3, seed=11, dt=0.05)
    d = subid.StateSpace(d.A, d.B, d.C, d.D + 0.3, 0.05, input_names=["force", "torque"],
                         output_names=["x", "v", "a"])
    c = d.to_continuous("bilinear")
    return {"discrete": d, "continuous": c}


MODELS = _models()


def _same(a, b, tol=TOL):
    assert a.dt == pytest.approx(b.dt, abs=0, rel=1e-15) or a.dt == b.dt
    for name in "ABCD":
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=tol)


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_python_control_round_trip(kind):
    pytest.importorskip("control")
    model = MODELS[kind]
    sys_ = model.to_control()
    assert sys_.dt == model.dt
    back = subid.StateSpace.from_control(sys_)
    _same(back, model)
    assert back.input_names == model.input_names
    assert back.output_names == model.output_names


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_scipy_round_trip(kind):
    model = MODELS[kind]
    sys_ = model.to_scipy()
    back = subid.StateSpace.from_scipy(sys_)
    _same(back, model)
    assert back.is_continuous == model.is_continuous


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_mat_round_trip_is_exact_with_matlab_field_names(kind, tmp_path):
    model = MODELS[kind]
    path = tmp_path / "model.mat"
    save_mat(model, path)
    raw = scipy.io.loadmat(path)
    for field in ("A", "B", "C", "D", "Ts", "InputName", "OutputName"):
        assert field in raw
    assert raw["Ts"].item() == model.dt                 # 0 for continuous, as MATLAB
    assert raw["InputName"].shape == (1, 2)             # a 1-by-m cell array
    assert [str(c[0]) for c in raw["InputName"][0]] == ["force", "torque"]
    back = load_mat(path)
    _same(back, model, tol=0)
    assert back.dt == model.dt
    assert back.input_names == model.input_names
    assert back.output_names == model.output_names


def test_mat_as_written_by_matlab_struct_and_unspecified_ts(tmp_path):
    model = MODELS["discrete"]
    path = tmp_path / "sys.mat"
    # what save('sys.mat', 'S') gives for S = struct('A', sys.A, ..., 'Ts', -1)
    scipy.io.savemat(path, {"S": {"A": model.A, "B": model.B, "C": model.C, "D": model.D,
                                  "Ts": -1.0}})
    with pytest.raises(ModelError, match="unspecified"):
        load_mat(path)
    back = load_mat(path, dt=0.05)
    _same(back, model, tol=0)
    assert back.input_names == ("u1", "u2")


def test_mat_with_empty_matlab_names_and_missing_d(tmp_path):
    path = tmp_path / "m.mat"
    names = np.empty((1, 1), dtype=object)
    names[0, 0] = ""
    scipy.io.savemat(path, {"A": [[0.5]], "B": [[1.0]], "C": [[2.0]], "D": np.zeros((0, 0)),
                            "Ts": 0.1, "InputName": names, "OutputName": names})
    back = load_mat(path)
    assert back.input_names == ("u1",) and back.output_names == ("y1",)
    np.testing.assert_array_equal(back.D, [[0.0]])


def test_mat_errors(tmp_path):
    with pytest.raises(DataFileNotFoundError):
        load_mat(tmp_path / "nope.mat")
    bad = tmp_path / "bad.mat"
    bad.write_text("not a mat file")
    with pytest.raises(FileReadError, match="bad.mat"):
        load_mat(bad)
    partial = tmp_path / "partial.mat"
    scipy.io.savemat(partial, {"A": [[1.0]], "B": [[1.0]]})
    with pytest.raises(ModelError, match="lacks the variables C, D"):
        load_mat(partial)
    with pytest.raises(ModelError):
        save_mat("not a model", tmp_path / "x.mat")


def test_statespace_wrappers_when_present(tmp_path):
    if not hasattr(subid.StateSpace, "to_mat"):
        pytest.skip("StateSpace.to_mat/from_mat wrappers not added to model.py yet")
    model = MODELS["discrete"]
    model.to_mat(tmp_path / "w.mat")
    _same(subid.StateSpace.from_mat(tmp_path / "w.mat"), model, tol=0)


# ---------------------------------------------------------------------------
# pandas
# ---------------------------------------------------------------------------
@pytest.fixture
def pd():
    return pytest.importorskip("pandas", reason="pandas is optional (pip install pandas)")


def test_pandas_round_trip_uniform_and_nonuniform(pd):
    data = subid.datasets.load("CD_player_arm")
    df = iodata_to_pandas(data)
    assert list(df.columns) == [*data.input_names, *data.output_names]
    back = iodata_from_pandas(df, list(data.input_names), list(data.output_names))
    np.testing.assert_array_equal(back.u, data.u)
    np.testing.assert_array_equal(back.y, data.y)
    assert back.dt == pytest.approx(data.dt, rel=1e-12)
    t = np.cumsum(np.random.default_rng(1).uniform(0.5, 1.5, 50))
    rec = subid.IOData(np.arange(50.0), np.arange(50.0) ** 2, t=t, input_names="u",
                       output_names="y")
    back = iodata_from_pandas(iodata_to_pandas(rec), "u", "y")
    assert back.dt is None
    np.testing.assert_array_equal(back.t, t)


def test_iodata_of_pandas_columns_takes_their_names(pd):
    rng = np.random.default_rng(0)
    df = pd.DataFrame(rng.standard_normal((50, 3)), columns=["force", "volt", "accel"])
    rec = subid.IOData(df[["force", "volt"]], df["accel"], dt=0.1)
    assert (rec.input_names, rec.output_names) == (("force", "volt"), ("accel",))
    np.testing.assert_array_equal(rec.u, df[["force", "volt"]].to_numpy())
    # names given win; default labels, unnamed Series and arrays keep u1.., y1..
    rec = subid.IOData(df[["force", "volt"]], df["accel"], input_names=["a", "b"])
    assert rec.input_names == ("a", "b")
    rec = subid.IOData(pd.DataFrame(rng.standard_normal((50, 2))),
                       df["accel"].rename(None))
    assert (rec.input_names, rec.output_names) == (("u1", "u2"), ("y1",))
    with pytest.raises(DataError, match="repeats the channel name"):
        subid.IOData(df[["force", "force"]], df["accel"])


@pytest.mark.parametrize("call", [
    lambda df: subid.identify(df), lambda df: subid.moesp(df), lambda df: subid.arx(df),
    lambda df: subid.ct_subspace(df), lambda df: subid.spa(df),
    lambda df: subid.impulseest(df, 10), lambda df: subid.merge([df]),
    lambda df: subid.pem(df, subid.StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], 1.0)),
    lambda df: subid.fit_percent(subid.StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], 1.0),
                                 df),
])
def test_a_dataframe_where_a_record_is_expected_says_how_to_make_one(pd, call):
    df = pd.DataFrame({"u": np.arange(20.0), "y": np.arange(20.0)})
    with pytest.raises(DataError, match=r"got DataFrame; make one from its columns: "
                                        r"subid\.IOData\(df\[input_columns\]"):
        call(df)


def test_pandas_time_column_datetime_index_and_defaults(pd):
    df = pd.DataFrame({"t": [0.0, 0.1, 0.2, 0.3], "u": [1.0, 2, 3, 4], "y": [0.0, 1, 0, 1]})
    rec = iodata_from_pandas(df, "u", "y", time="t")
    assert rec.dt == pytest.approx(0.1)
    rec = iodata_from_pandas(df, ["u"], ["y"])           # RangeIndex: time in samples
    assert rec.dt == 1.0
    rec = iodata_from_pandas(df, "u", "y", dt=0.5)
    assert rec.dt == 0.5
    stamped = df.set_index(pd.date_range("2024-05-01", periods=4, freq="250ms"))
    rec = iodata_from_pandas(stamped, "u", "y")
    assert rec.dt == pytest.approx(0.25)
    assert rec.input_names == ("u",) and rec.output_names == ("y",)


@pytest.mark.parametrize("frame, kwargs, match", [
    ({"u": [1.0, 2.0], "y": [1.0, 2.0]}, {"inputs": "w", "outputs": "y"}, "no column 'w'"),
    ({"u": [1.0, "x"], "y": [1.0, 2.0]}, {"inputs": "u", "outputs": "y"}, "not numeric"),
    ({"u": [1.0, 2.0], "y": [1.0, np.nan]}, {"inputs": "u", "outputs": "y"}, "row 1"),
    ({"u": [1.0, 2.0], "y": [1.0, 2.0]}, {"inputs": "u", "outputs": "u"}, "twice"),
    ({"u": [1.0, 2.0], "y": [1.0, 2.0], "t": [0.0, 1.0]},
     {"inputs": "u", "outputs": "y", "time": "t", "dt": 1.0}, "not both"),
])
def test_pandas_errors_name_the_column(pd, frame, kwargs, match):
    with pytest.raises(DataError, match=match):
        iodata_from_pandas(pd.DataFrame(frame), **kwargs)


def test_iodata_wrappers_when_present(pd):
    if not hasattr(subid.IOData, "from_pandas"):
        pytest.skip("IOData.from_pandas/to_pandas wrappers not added to data.py yet")
    df = pd.DataFrame({"u": [1.0, 2, 3], "y": [3.0, 1, 2]})
    rec = subid.IOData.from_pandas(df, "u", "y")
    pd.testing.assert_frame_equal(rec.to_pandas().reset_index(drop=True), df)
