"""StateSpace: construction, analysis, conversions, files, other libraries."""

import json
import math
import os
import sys as _sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from subid.errors import DataError, DataFileNotFoundError, ModelError, OrderError
from subid.model import statespace as model_module
from subid.model.statespace import StateSpace


def random_ct(seed, n=4, m=2, p=3):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A -= (np.linalg.eigvals(A).real.max() + 0.3) * np.eye(n)
    return (A, rng.standard_normal((n, m)), rng.standard_normal((p, n)),
            rng.standard_normal((p, m)))


def random_dt(seed, n=4, m=2, p=3):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A *= 0.95 / np.abs(np.linalg.eigvals(A)).max()
    return (A, rng.standard_normal((n, m)), rng.standard_normal((p, n)),
            rng.standard_normal((p, m)))


def assert_same_model(a, b, tol):
    assert a.dt == b.dt
    for name in "ABCD":
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=tol, atol=tol,
                                   err_msg=name)


# ---------------------------------------------------------------------------
# construction
# ---------------------------------------------------------------------------
def test_basic_attributes_and_repr():
    A, B, C, D = random_dt(0)
    sys = StateSpace(A, B, C, D, 0.1, input_names=["f", "g"], info={"fit": 0.9})
    assert (sys.order, sys.n_inputs, sys.n_outputs) == (4, 2, 3)
    assert sys.dt == 0.1 and not sys.is_continuous
    assert sys.input_names == ("f", "g") and sys.output_names == ("y1", "y2", "y3")
    assert sys.info == {"fit": 0.9}
    r = repr(sys)
    assert "order=4" in r and "dt=0.1" in r and "['f', 'g']" in r
    assert "continuous" in repr(StateSpace(*random_ct(0), 0))
    for name in "ABCD":
        M = getattr(sys, name)
        assert M.dtype == np.float64 and not M.flags.writeable
        with pytest.raises(ValueError):
            M[0, 0] = 1.0
    with pytest.raises(AttributeError):
        sys.A = np.eye(4)
    # the caller's arrays are copied, not frozen
    assert A.flags.writeable and sys.A is not A


def test_scalar_zero_d():
    sys = StateSpace([[0.5]], [[1.0]], [[2.0]], 0, 1.0)
    np.testing.assert_array_equal(sys.D, [[0.0]])
    sys = StateSpace(np.eye(2), np.ones((2, 3)), np.ones((1, 2)), 0, 0)
    assert sys.D.shape == (1, 3) and not sys.D.any()
    with pytest.raises(ModelError, match="only the scalar 0"):
        StateSpace([[0.5]], [[1.0]], [[2.0]], 3.0, 1.0)


@pytest.mark.parametrize("args, pattern", [
    ((np.ones((3, 4)), np.ones((3, 1)), np.ones((1, 3)), 0), r"A has shape 3x4.*square"),
    ((np.eye(4), np.ones((3, 1)), np.ones((1, 4)), 0),
     r"B has 3 rows but A is 4x4: B must be 4 x n_inputs"),
    ((np.eye(4), np.ones((4, 1)), np.ones((2, 3)), 0),
     r"C has 3 columns but A is 4x4: C must be n_outputs x 4"),
    ((np.eye(4), np.ones((4, 2)), np.ones((1, 4)), np.ones((2, 2))),
     r"D has shape 2x2.*D must be 1 x 2"),
    ((np.eye(2), np.ones(2), np.ones((1, 2)), 0), r"B must be a 2-D array.*reshape\(-1, 1\)"),
    ((np.eye(2), np.ones((2, 1)), np.ones(2), 0), r"C must be a 2-D array.*reshape\(1, -1\)"),
    ((np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), 0), r"order must be at least 1"),
    ((np.eye(2), np.ones((2, 1)), np.ones((0, 2)), 0), r"C has no rows"),
    ((np.array([[1.0, np.nan], [0, 1]]), np.ones((2, 1)), np.ones((1, 2)), 0),
     r"A has 1 non-finite entry.*row 0, column 1"),
    ((np.eye(2), np.ones((2, 1)), np.ones((1, 2)), [[np.inf]]), r"^D has 1 non-finite"),
    ((np.eye(2) * 1j, np.ones((2, 1)), np.ones((1, 2)), 0), r"A is complex"),
    ((np.eye(2), [["a"], ["b"]], np.ones((1, 2)), 0), r"B has dtype"),
])
def test_shape_and_value_errors_name_the_matrix(args, pattern):
    with pytest.raises(ModelError, match=pattern):
        StateSpace(*args, 1.0)


@pytest.mark.parametrize("dt", [-1.0, math.inf, math.nan, "0.1", True, None])
def test_bad_dt(dt):
    with pytest.raises(ModelError, match="dt"):
        StateSpace([[0.5]], [[1.0]], [[1.0]], 0, dt)


def test_bad_names_and_info():
    args = (np.eye(2), np.ones((2, 2)), np.ones((1, 2)), 0, 1.0)
    with pytest.raises(ModelError, match="1 input name"):
        StateSpace(*args, input_names=["a"])
    with pytest.raises(ModelError, match="repeat"):
        StateSpace(*args, input_names=["a", "a"])
    with pytest.raises(ModelError, match="info must be a dict"):
        StateSpace(*args, info=[1, 2])


# ---------------------------------------------------------------------------
# analysis
# ---------------------------------------------------------------------------
def test_markov():
    A, B, C, D = random_dt(1)
    sys = StateSpace(A, B, C, D, 1.0)
    M = sys.markov(5)
    assert M.shape == (5, 3, 2)
    np.testing.assert_allclose(M[0], D)
    for i in range(1, 5):
        np.testing.assert_allclose(M[i], C @ np.linalg.matrix_power(A, i - 1) @ B,
                                   rtol=1e-12, atol=1e-14)
    # Markov parameters are the impulse response of the discrete model
    u = np.zeros((5, 2))
    u[0, 1] = 1.0
    np.testing.assert_allclose(sys.simulate(u), M[:, :, 1], atol=1e-14)
    assert sys.markov(1).shape == (1, 3, 2)
    with pytest.raises(OrderError):
        sys.markov(0)


def test_poles_sorting():
    A = np.diag([0.1, -0.9, 0.5])
    A[1:, 1:] = [[-0.2, 0.7], [-0.7, -0.2]]        # pair with |z| = 0.728, Re = -0.2
    dt_p = StateSpace(A, np.ones((3, 1)), np.ones((1, 3)), 0, 1.0).poles()
    np.testing.assert_allclose(np.abs(dt_p), [np.hypot(0.2, 0.7)] * 2 + [0.1])
    assert dt_p[0].imag > 0 > dt_p[1].imag
    Ac = np.diag([-3.0, -0.5, -1.0])
    ct_p = StateSpace(Ac, np.ones((3, 1)), np.ones((1, 3)), 0, 0).poles()
    np.testing.assert_allclose(ct_p, [-0.5, -1.0, -3.0])


def test_is_stable():
    assert StateSpace([[0.99]], [[1.0]], [[1.0]], 0, 1.0).is_stable()
    assert not StateSpace([[-1.0]], [[1.0]], [[1.0]], 0, 1.0).is_stable()
    assert StateSpace([[-0.01]], [[1.0]], [[1.0]], 0, 0).is_stable()
    assert not StateSpace([[0.0]], [[1.0]], [[1.0]], 0, 0).is_stable()
    assert not StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 0).is_stable()


def direct_tf(A, B, C, D, s):
    return C @ np.linalg.inv(s * np.eye(A.shape[0]) - A) @ B + D


def test_freqresp_continuous_and_discrete():
    w = np.array([0.0, 0.3, 1.0, 7.5])
    A, B, C, D = random_ct(2)
    G = StateSpace(A, B, C, D, 0).freqresp(w)
    assert G.shape == (4, 3, 2) and G.dtype == complex
    for k, wk in enumerate(w):
        np.testing.assert_allclose(G[k], direct_tf(A, B, C, D, 1j * wk), rtol=1e-10)
    A, B, C, D = random_dt(3)
    dt = 0.4
    G = StateSpace(A, B, C, D, dt).freqresp(w)
    for k, wk in enumerate(w):
        np.testing.assert_allclose(G[k], direct_tf(A, B, C, D, np.exp(1j * wk * dt)),
                                   rtol=1e-10)
    # against scipy for a SISO system
    A, B, C, D = random_ct(4, m=1, p=1)
    _, h = signal.freqresp(signal.StateSpace(A, B, C, D), w=w[1:])
    np.testing.assert_allclose(StateSpace(A, B, C, D, 0).freqresp(w[1:])[:, 0, 0], h,
                               rtol=1e-10)


def test_freqresp_chunks_agree(monkeypatch):
    sys = StateSpace(*random_ct(5), 0)
    w = np.logspace(-2, 2, 50)
    G = sys.freqresp(w)
    monkeypatch.setattr(model_module, "_FREQ_CHUNK_ENTRIES", 1)
    np.testing.assert_array_equal(sys.freqresp(w), G)


def test_freqresp_at_a_pole_raises():
    ct = StateSpace(np.diag([0.0, -1.0]), np.ones((2, 1)), np.ones((1, 2)), 0, 0)
    with pytest.raises(ModelError, match="w=0.0 rad/s falls on the pole"):
        ct.freqresp([1.0, 0.0])
    dt = StateSpace(np.diag([1.0, 0.5]), np.ones((2, 1)), np.ones((1, 2)), 0, 0.1)
    with pytest.raises(ModelError, match="falls on the pole"):
        dt.freqresp([0.0])
    with pytest.raises(DataError):
        ct.freqresp([1.0, np.nan])


def test_transform_invariance_and_errors():
    A, B, C, D = random_dt(6)
    sys = StateSpace(A, B, C, D, 0.5, info={"k": 1})
    T = np.random.default_rng(7).standard_normal((4, 4)) + 3 * np.eye(4)
    tr = sys.transform(T)
    np.testing.assert_allclose(tr.A, T @ A @ np.linalg.inv(T), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tr.B, T @ B)
    np.testing.assert_allclose(tr.C, C @ np.linalg.inv(T), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tr.markov(6), sys.markov(6), rtol=1e-10, atol=1e-12)
    w = np.linspace(0.1, 5, 7)
    np.testing.assert_allclose(tr.freqresp(w), sys.freqresp(w), rtol=1e-10)
    np.testing.assert_allclose(np.sort_complex(tr.poles()), np.sort_complex(sys.poles()),
                               atol=1e-10)
    assert tr.info == {"k": 1} and tr.info is not sys.info
    assert not tr.allclose(sys)
    with pytest.raises(ModelError, match="T must be 4 x 4"):
        sys.transform(np.eye(3))
    with pytest.raises(ModelError, match="T is singular"):
        sys.transform(np.ones((4, 4)))


def test_allclose():
    A, B, C, D = random_dt(8)
    a = StateSpace(A, B, C, D, 0.5)
    assert a.allclose(StateSpace(A + 1e-12, B, C, D, 0.5))
    assert not a.allclose(StateSpace(A + 1e-3, B, C, D, 0.5))
    assert not a.allclose(StateSpace(A, B, C, D, 0.25))
    assert not a.allclose(StateSpace(A, B, C, D, 0))
    assert not a.allclose(StateSpace(A, B[:, :1], C, D[:, :1], 0.5))
    assert not a.allclose("not a model")


# ---------------------------------------------------------------------------
# discretisation and its inverse
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["zoh", "foh", "bilinear"])
def test_to_discrete_matches_scipy(method):
    A, B, C, D = random_ct(9)
    dt = 0.15
    d = StateSpace(A, B, C, D, 0, output_names=["a", "b", "c"]).to_discrete(dt, method)
    Ad, Bd, Cd, Dd, dt_ref = signal.cont2discrete((A, B, C, D), dt, method=method)
    assert d.dt == dt_ref == dt
    for got, ref in zip((d.A, d.B, d.C, d.D), (Ad, Bd, Cd, Dd)):
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-14)
    assert d.output_names == ("a", "b", "c")


@pytest.mark.parametrize("method", ["zoh", "foh", "bilinear"])
@pytest.mark.parametrize("seed", range(5))
def test_round_trips(method, seed):
    rng = np.random.default_rng(100 + seed)
    n, m, p = rng.integers(1, 6), rng.integers(1, 4), rng.integers(1, 4)
    ct = StateSpace(*random_ct(seed, n, m, p), 0)
    dt = float(rng.uniform(0.05, 0.5))
    back = ct.to_discrete(dt, method).to_continuous(method)
    assert back.is_continuous
    assert_same_model(back, ct, 1e-10)
    dm = StateSpace(*random_dt(seed, n, m, p), dt)
    # keep only discrete models with a real logarithm (no eigenvalue on (-inf, 0])
    if method == "bilinear" or not np.any((np.linalg.eigvals(dm.A).real < 0)
                                          & (np.abs(np.linalg.eigvals(dm.A).imag) < 1e-8)):
        again = dm.to_continuous(method).to_discrete(dt, method)
        assert_same_model(again, dm, 1e-10)


def test_foh_round_trip_recovers_d():
    A, B, C, D = random_ct(10)
    ct = StateSpace(A, B, C, D, 0)
    d = ct.to_discrete(0.3, "foh")
    assert np.abs(d.D - D).max() > 1e-3     # foh changes D ...
    np.testing.assert_allclose(d.to_continuous("foh").D, D, rtol=1e-10, atol=1e-10)


def test_to_continuous_failures():
    neg = StateSpace(np.diag([-0.5, 0.3]), np.ones((2, 1)), np.ones((1, 2)), 0, 0.1)
    for method in ("zoh", "foh"):
        with pytest.raises(ModelError, match="negative real axis"):
            neg.to_continuous(method)
    assert neg.to_continuous("bilinear").is_continuous
    sing = StateSpace(np.diag([0.0, 0.3]), np.ones((2, 1)), np.ones((1, 2)), 0, 0.1)
    with pytest.raises(ModelError, match="singular"):
        sing.to_continuous("zoh")
    minus_one = StateSpace(np.diag([-1.0, 0.3]), np.ones((2, 1)), np.ones((1, 2)), 0, 0.1)
    with pytest.raises(ModelError, match="eigenvalue at -1"):
        minus_one.to_continuous("bilinear")
    with pytest.raises(ModelError, match="already continuous"):
        StateSpace(*random_ct(11), 0).to_continuous()
    with pytest.raises(ModelError, match="already discrete"):
        neg.to_discrete(0.1)
    with pytest.raises(ModelError, match="method"):
        StateSpace(*random_ct(11), 0).to_discrete(0.1, "euler")
    with pytest.raises(DataError):
        StateSpace(*random_ct(11), 0).to_discrete(-0.1)


# ---------------------------------------------------------------------------
# dictionaries and files
# ---------------------------------------------------------------------------
def info_example():
    return {
        "singular_values": np.array([3.5, 1.25, np.nan, np.inf]),
        "ints": np.arange(6, dtype=np.int32).reshape(2, 3),
        "empty": np.zeros((0, 3)),
        "mask": np.array([True, False]),
        "cplx": np.array([[1 + 2j, complex(0.0, -np.inf), complex(np.nan, 1.0)]]),
        "z": 1.5 - 0.5j,
        "nan": math.nan,
        "minus_inf": -math.inf,
        "np_scalar": np.float32(0.25),
        "np_int": np.int64(7),
        "flag": np.bool_(True),
        "none": None,
        "name": "n4sid",
        "nested": {"horizon": 10, "weights": [1, 2.5, "x", [np.float64(3.0)]],
                   "deeper": {"a": np.array(2.0)}},
        "labels": np.array(["a", "bc"]),
    }


def assert_info_equal(got, expected):
    if isinstance(expected, np.ndarray):
        assert isinstance(got, np.ndarray)
        assert got.dtype == expected.dtype and got.shape == expected.shape
        np.testing.assert_array_equal(got, expected)
    elif isinstance(expected, dict):
        assert isinstance(got, dict) and set(got) == set(expected)
        for k in expected:
            assert_info_equal(got[k], expected[k])
    elif isinstance(expected, (list, tuple)):
        assert isinstance(got, list) and len(got) == len(expected)
        for a, b in zip(got, expected):
            assert_info_equal(a, b)
    elif isinstance(expected, (float, complex, np.floating)) and not isinstance(expected, bool):
        assert type(got) in (float, complex)
        np.testing.assert_array_equal(got, expected)
    else:
        assert got == expected and type(got) is type(expected.item()
                                                       if isinstance(expected, np.generic)
                                                       else expected)


def test_dict_round_trip_is_json_ready():
    A, B, C, D = random_dt(12)
    sys = StateSpace(A, B, C, D, 0.1, input_names=["a", "b"], info=info_example())
    d = sys.to_dict()
    assert d["format"] == "subid.StateSpace" and d["version"] == 1
    text = json.dumps(d, allow_nan=False)       # strict JSON, no NaN literals
    back = StateSpace.from_dict(json.loads(text))
    assert_same_model(back, sys, 0)
    assert back.input_names == ("a", "b") and back.output_names == sys.output_names
    assert_info_equal(back.info, info_example())


def test_dict_encoding_choices():
    d = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 0.0,
                   info={"z": 1j, "v": np.array([1.0, np.nan]), "x": np.inf}).to_dict()
    assert d["info"]["z"] == {"__complex__": [0.0, 1.0]}
    assert d["info"]["v"] == {"__ndarray__": [1.0, "nan"], "dtype": "float64", "shape": [2]}
    assert d["info"]["x"] == {"__float__": "inf"}
    assert d["A"] == [[0.5]] and d["dt"] == 0.0


def test_unstorable_info_raises():
    sys = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info={"bad": {"f": object()}})
    with pytest.raises(ModelError, match=r"info\['bad'\]\['f'\] is a object"):
        sys.to_dict()
    with pytest.raises(ModelError, match="string keys"):
        StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info={1: 2}).to_dict()
    with pytest.raises(ModelError, match="reserved"):
        StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info={"__float__": 2}).to_dict()


def good_dict():
    return StateSpace(*random_dt(13), 0.1).to_dict()


@pytest.mark.parametrize("mutate, pattern", [
    (lambda d: d.pop("B"), r"missing the key 'B'"),
    (lambda d: d.pop("dt"), r"missing the key 'dt'"),
    (lambda d: d.update(extra=1), r"unknown key.*extra"),
    (lambda d: d.update(format="other"), r"'format'"),
    (lambda d: d.update(version=4), r"newer subid"),
    (lambda d: d.update(version="1"), r"'version'"),
    (lambda d: d.update(A="eye"), r"key 'A' must be a list"),
    (lambda d: d.update(C=[[1, 2], [3]]), r"key 'C'"),
    (lambda d: d.update(D=[["a", "b"]] * 3), r"key 'D' must hold numbers"),
    (lambda d: d.update(B=[1, 2, 3, 4]), r"key 'B' must be a list of rows"),
    (lambda d: d.update(B=[[1.0]] * 3), r"B has 3 rows but A is 4x4"),
    (lambda d: d.update(dt=-1), r"key 'dt'"),
    (lambda d: d.update(dt=None), r"key 'dt'"),
    (lambda d: d.update(input_names="u1"), r"key 'input_names'"),
    (lambda d: d.update(output_names=["a"]), r"1 output name"),
    (lambda d: d.update(info=[1]), r"key 'info'"),
    (lambda d: d.update(info={"x": {"__float__": "big"}}), r"info\['x'\]"),
    (lambda d: d.update(info={"x": {"__ndarray__": [1, 2], "dtype": "float64",
                                    "shape": [3]}}), r"info\['x'\].*shape \[3\]"),
    (lambda d: d.update(info={"x": {"__ndarray__": [1.5], "dtype": "int64",
                                    "shape": [1]}}), r"info\['x'\]"),
    (lambda d: d.update(info={"x": {"__ndarray__": [1], "dtype": "object",
                                    "shape": [1]}}), r"info\['x'\]"),
])
def test_from_dict_errors_name_the_key(mutate, pattern):
    d = good_dict()
    mutate(d)
    with pytest.raises(ModelError, match=pattern):
        StateSpace.from_dict(d)


def test_from_dict_rejects_non_dict():
    with pytest.raises(ModelError, match="dict"):
        StateSpace.from_dict([1, 2])


def test_save_load_round_trip(tmp_path):
    A, B, C, D = random_ct(14)
    sys = StateSpace(A, B, C, D, 0, output_names=["p", "q", "r"], info=info_example())
    path = tmp_path / "model.json"
    sys.save(path)
    back = StateSpace.load(path)
    assert_same_model(back, sys, 0)            # bit-exact floats through JSON
    assert back.output_names == ("p", "q", "r")
    assert_info_equal(back.info, info_example())
    raw = json.loads(path.read_text(encoding="utf-8"))   # any JSON reader accepts it
    assert raw["format"] == "subid.StateSpace" and raw["A"] == A.tolist()
    StateSpace.load(str(path))                 # str paths too
    assert os.listdir(tmp_path) == ["model.json"]     # no temporary files left


@pytest.mark.parametrize("target", ["replace", "fsync"])
def test_failed_save_keeps_the_old_file(tmp_path, monkeypatch, target):
    path = tmp_path / "m.json"
    old = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0)
    old.save(path)
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, target, boom)       # the atomic writer (subid.io._files)
    new = StateSpace([[0.25]], [[2.0]], [[1.0]], 0, 1.0)
    with pytest.raises(OSError, match="disk full"):
        new.save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["m.json"]
    assert StateSpace.load(path).allclose(old)


def test_unstorable_info_writes_nothing(tmp_path):
    sys = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info={"f": print})
    with pytest.raises(ModelError):
        sys.save(tmp_path / "m.json")
    assert os.listdir(tmp_path) == []


def test_load_errors_name_the_file(tmp_path):
    missing = tmp_path / "nope.json"
    with pytest.raises(DataFileNotFoundError, match="nope.json"):
        StateSpace.load(missing)
    with pytest.raises(FileNotFoundError):
        StateSpace.load(missing)
    path = tmp_path / "model.json"
    StateSpace(*random_dt(15), 0.1, info={"a": np.arange(20.0)}).save(path)
    text = path.read_text(encoding="utf-8")
    path.write_text(text[: len(text) // 2], encoding="utf-8")
    with pytest.raises(ModelError, match=r"model\.json.*not valid JSON.*truncated"):
        StateSpace.load(path)
    path.write_text("", encoding="utf-8")
    with pytest.raises(ModelError, match=r"model\.json.*empty"):
        StateSpace.load(path)
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ModelError, match=r"model\.json"):
        StateSpace.load(path)
    d = json.loads(text)
    del d["C"]
    path.write_text(json.dumps(d), encoding="utf-8")
    with pytest.raises(ModelError, match=r"model\.json.*missing the key 'C'"):
        StateSpace.load(path)
    path.write_text("[1, 2, 3]", encoding="utf-8")
    with pytest.raises(ModelError, match=r"model\.json.*JSON object"):
        StateSpace.load(path)


json_leaves = st.one_of(
    st.none(), st.booleans(), st.integers(-10**20, 10**20), st.text(max_size=5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.complex_numbers(allow_nan=False, max_magnitude=1e10),
)
info_values = st.recursive(
    json_leaves,
    lambda children: st.one_of(
        st.lists(children, max_size=4),
        st.dictionaries(st.text(max_size=5).filter(lambda k: not k.startswith("__")),
                        children, max_size=4)),
    max_leaves=12)


@settings(max_examples=60, deadline=None)
@given(st.dictionaries(st.text(max_size=6).filter(lambda k: not k.startswith("__")),
                       info_values, max_size=5))
def test_info_round_trip_property(info):
    sys = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0, info=info)
    back = StateSpace.from_dict(json.loads(json.dumps(sys.to_dict(), allow_nan=False)))
    assert_info_equal(back.info, info)


# ---------------------------------------------------------------------------
# python-control and scipy
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("dt", [0.0, 0.2])
def test_control_round_trip(dt):
    control = pytest.importorskip("control")
    A, B, C, D = random_ct(16) if dt == 0 else random_dt(16)
    sys = StateSpace(A, B, C, D, dt, input_names=["a", "b"])
    csys = sys.to_control()
    assert isinstance(csys, control.StateSpace)
    assert csys.dt == dt and list(csys.input_labels) == ["a", "b"]
    back = StateSpace.from_control(csys)
    assert_same_model(back, sys, 1e-12)
    assert back.input_names == ("a", "b") and back.output_names == sys.output_names
    np.testing.assert_allclose(
        np.asarray(csys(1j * 0.7 if dt == 0 else np.exp(0.7j * dt))),
        sys.freqresp([0.7])[0], rtol=1e-10)


def test_from_control_timebases():
    control = pytest.importorskip("control")
    args = ([[-1.0]], [[1.0]], [[1.0]], [[0.0]])
    with pytest.raises(ModelError, match="unspecified sampling period"):
        StateSpace.from_control(control.ss(*args, True))
    assert StateSpace.from_control(control.ss(*args, True), dt=0.5).dt == 0.5
    assert StateSpace.from_control(control.ss(*args, None)).is_continuous
    with pytest.raises(ModelError, match="contradicts"):
        StateSpace.from_control(control.ss(*args, 0.1), dt=0.2)
    tf = StateSpace.from_control(control.tf([1.0], [1.0, 2.0]))
    assert tf.order == 1 and tf.poles()[0] == pytest.approx(-2.0)
    with pytest.raises(ModelError, match="python-control system"):
        StateSpace.from_control("ss")


def test_control_missing_raises_import_error(monkeypatch):
    monkeypatch.setitem(_sys.modules, "control", None)
    sys = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 1.0)
    with pytest.raises(ImportError, match="pip install control"):
        sys.to_control()
    with pytest.raises(ImportError, match=r"'control' extra \(pip install \"\.\[control\]\""):
        StateSpace.from_control(object())


@pytest.mark.parametrize("dt", [0.0, 0.2])
def test_scipy_round_trip(dt):
    A, B, C, D = random_ct(17) if dt == 0 else random_dt(17)
    sys = StateSpace(A, B, C, D, dt)
    ssys = sys.to_scipy()
    assert isinstance(ssys, signal.StateSpace)
    assert ssys.dt == (None if dt == 0 else dt)
    back = StateSpace.from_scipy(ssys)
    assert_same_model(back, sys, 1e-12)


def test_from_scipy_conversions_and_errors():
    tf = StateSpace.from_scipy(signal.TransferFunction([1.0], [1.0, 3.0]))
    assert tf.is_continuous and tf.poles()[0] == pytest.approx(-3.0)
    with pytest.raises(ModelError, match="unspecified sampling period"):
        StateSpace.from_scipy(signal.dlti([[0.5]], [[1.0]], [[1.0]], [[0.0]]))
    d = StateSpace.from_scipy(signal.dlti([[0.5]], [[1.0]], [[1.0]], [[0.0]]), dt=0.3)
    assert d.dt == 0.3
    with pytest.raises(ModelError, match="scipy.signal"):
        StateSpace.from_scipy((np.eye(1),) * 4)


def test_class_docstring_example():
    import doctest
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for test in finder.find(StateSpace, "StateSpace", globs={}):
        runner.run(test)
    assert runner.failures == 0 and runner.tries > 0
