"""Bad input gets a subid.errors exception that says what is wrong."""

import warnings

import numpy as np
import pytest

import subid
from subid import errors, systems


def _data(n=500, seed=0):
    return systems.simulate_data(systems.seed001_system(), n, seed=seed)


def test_errors_are_value_errors():
    for cls in (errors.DataError, errors.NotExcitingError, errors.OrderError,
                errors.TooFewSamplesError, errors.ModelError, errors.FileReadError):
        assert issubclass(cls, ValueError)
    assert issubclass(errors.DataFileNotFoundError, FileNotFoundError)


def test_nan_rows_listed():
    u = np.ones((50, 2))
    u[[17, 18, 40], 1] = np.nan
    with pytest.raises(errors.DataError, match=r"input u has 3 NaN values at rows 17, 18, 40"):
        subid.IOData(u, np.zeros(50))


def test_inf_rows_listed():
    y = np.zeros(30)
    y[5] = np.inf
    with pytest.raises(errors.DataError, match=r"output y has 1 infinite value at row 5"):
        subid.IOData(np.zeros(30), y)


def test_mismatched_lengths():
    with pytest.raises(errors.DataError, match=r"input u has 10 samples but output y has 12"):
        subid.IOData(np.zeros(10), np.zeros(12))


def test_transposed_hint():
    with pytest.raises(errors.DataError, match="transposed"):
        subid.IOData(np.zeros((2, 100)), np.zeros(100))


def test_time_stamps_not_increasing():
    t = np.arange(10.0)
    t[6] = t[5]
    with pytest.raises(errors.DataError, match=r"repeated at row 6"):
        subid.IOData(np.zeros(10), np.zeros(10), t=t)
    t = np.arange(10.0)
    t[3] = 1.0
    with pytest.raises(errors.DataError, match=r"not increasing at row 3"):
        subid.IOData(np.zeros(10), np.zeros(10), t=t)


@pytest.mark.parametrize("bad", [
    dict(dt=0), dict(dt=-1.0), dict(dt=float("nan")), dict(dt="0.1"), dict(dt=0.1, t=np.arange(5.0)),
])
def test_bad_dt(bad):
    with pytest.raises(errors.DataError):
        subid.IOData(np.zeros(5), np.zeros(5), **bad)


@pytest.mark.parametrize("values,match", [
    (np.array(["a", "b"]), "strings"),
    (np.array([1 + 1j, 2]), "complex"),
    (np.array([[1, "x"], [2, 3]], dtype=object), "not numbers"),
    (np.array([[1, None], [2, 3]], dtype=object), "missing values .None. at row 0"),
    (np.zeros((3, 2, 2)), "3 dimensions"),
    (np.zeros((0,)), "empty"),
])
def test_bad_arrays(values, match):
    with pytest.raises(errors.DataError, match=match):
        subid.IOData(values, np.zeros(values.shape[0]) if values.ndim else 0)


def test_too_few_samples_for_horizon(method):
    data = _data(35)
    with pytest.raises(errors.TooFewSamplesError, match=r"35 samples are too few for horizon 8"):
        method(data, 3, horizon=8)


def test_order_not_revealable(method):
    with pytest.raises(errors.OrderError, match=r"order 9 cannot be revealed with horizon 5 "
                                                r"and 2 outputs.*horizon >= 6"):
        method(_data(), 9, horizon=5)


def test_bad_order_values(method):
    for bad in (0, -1, 2.5, "three"):
        with pytest.raises(errors.OrderError):
            method(_data(), bad)


def test_constant_input_not_exciting(method):
    sys = systems.seed001_system()
    u = np.ones((500, 2))
    u[:, 1] = np.random.default_rng(0).standard_normal(500)
    data = subid.IOData(u, sys.simulate(u))
    with pytest.raises(errors.NotExcitingError, match=r"input u1 at lag 1") as info:
        method(data, 3)
    assert info.value.achieved_order == 1
    assert "persistently exciting of order" in str(info.value)


def test_zero_input_not_exciting(method):
    data = subid.IOData(np.zeros((300, 2)), np.random.default_rng(1).standard_normal((300, 2)))
    with pytest.raises(errors.NotExcitingError, match="identically zero") as info:
        method(data, 3)
    assert info.value.achieved_order == 0


def test_sinusoid_exciting_order_reported():
    """Two sinusoids are persistently exciting of order 4 exactly."""
    sys = systems.random_system(2, 1, 1, seed=3)
    k = np.arange(800)
    u = np.sin(0.3 * k) + np.sin(1.1 * k)
    data = subid.IOData(u, sys.simulate(u))
    with pytest.raises(errors.NotExcitingError, match="exciting of order 4 only") as info:
        subid.ls_subspace(data, 2)
    assert info.value.required_order >= 10 and info.value.achieved_order == 4


def test_constant_output_rejected(method):
    u = np.random.default_rng(0).standard_normal((300, 1))
    data = subid.IOData(u, np.column_stack([u[:, 0], np.full(300, 2.0)]))
    with pytest.raises(errors.DataError, match="output y2 is constant"):
        method(data, 1)


def test_non_uniform_data_rejected(method):
    t = np.cumsum(np.random.default_rng(0).uniform(0.5, 1.5, 300))
    data = subid.IOData(np.random.default_rng(1).standard_normal(300), np.zeros(300) + t, t=t)
    with pytest.raises(errors.DataError, match="non-uniform"):
        method(data, 2)


def test_not_iodata(method):
    with pytest.raises(errors.DataError, match="IOData"):
        method(np.zeros((100, 2)), 2)


def test_bad_selector():
    data = _data()
    with pytest.raises(errors.OrderError, match="10 columns"):
        subid.ls_subspace(data, 3, horizon=5, selector=np.ones((3, 4)))
    with pytest.raises(errors.OrderError, match="horizon 2"):   # 4 columns: horizon 2
        subid.ls_subspace(data, 3, selector=np.ones((3, 4)))
    with pytest.raises(errors.OrderError, match="at least order rows"):
        subid.ls_subspace(data, 3, selector=np.ones((2, 10)))
    with pytest.raises(errors.OrderError, match="blind"):
        subid.ls_subspace(data, 3, selector=np.ones((3, 10)))   # rank one selector


def test_wrong_delimiter_is_named(tmp_path):
    path = tmp_path / "semi.csv"
    path.write_text("u;y\n1;2\n3;4\n5;6\n")
    # the hint itself (the temporary folder's name holds "delimiter" too)
    with pytest.raises(errors.FileReadError, match="is the delimiter right.*delimiter=';'"):
        subid.read(path, inputs=0, outputs=1, delimiter=",")
    with pytest.raises(errors.FileReadError, match="is the delimiter right"):
        subid.read(path, inputs="u", outputs="y", delimiter=",")
    bars = tmp_path / "bars.csv"
    bars.write_text("u|y\n1|2\n3|4\n5|6\n")
    with pytest.raises(errors.FileReadError, match="delimiter='\\|'"):
        subid.read(bars, inputs="u", outputs="y")


def test_unstable_model_from_stable_data_warns():
    """robot_arm with classical N4SID at order 7 gives an unstable model while the
    measured output shows no growth: stability='none' keeps it with a warning, the
    default ('auto') returns a stable model and says so."""
    est, _ = subid.datasets.load("robot_arm").detrend().split(0.7)
    with pytest.warns(errors.UnstableModelWarning, match="unstable"):
        model = subid.n4sid(est, 7, horizon=10, weighting="n4sid", stability="none")
    assert model.info["spectral_radius"] > 1
    assert model.info["output_growth"] < 3
    fixed = subid.n4sid(est, 7, horizon=10, weighting="n4sid")
    assert fixed.is_stable() and fixed.info["stability"]["action"] == "enforced"
    assert subid.n4sid(est).is_stable()


def test_unstable_plant_with_growing_output_does_not_warn():
    true = subid.StateSpace([[1.01]], [[1.0]], [[1.0]], [[0.0]], 1.0)
    u = np.random.default_rng(0).standard_normal(1500)
    with warnings.catch_warnings():
        warnings.simplefilter("error", errors.UnstableModelWarning)
        model = subid.moesp(subid.IOData(u, true.simulate(u)), 1, horizon=5)
    assert model.info["spectral_radius"] == pytest.approx(1.01, rel=1e-6)
