"""IOData: shapes, time, slicing, split, detrend."""

import numpy as np
import pytest

import subid
from subid import errors


def test_shapes_and_defaults():
    d = subid.IOData(np.arange(10.0), np.ones((10, 2)))
    assert (d.n_samples, d.n_inputs, d.n_outputs) == (10, 1, 2)
    assert d.dt == 1.0 and d.is_uniform
    np.testing.assert_array_equal(d.t, np.arange(10.0))
    assert d.input_names == ("u1",) and d.output_names == ("y1", "y2")
    assert d.u.dtype == np.float64
    with pytest.raises(ValueError):
        d.u[0, 0] = 5.0   # read-only


def test_integer_and_bool_inputs_become_float():
    d = subid.IOData(np.array([0, 1, 1, 0], dtype=bool), np.arange(4))
    np.testing.assert_array_equal(d.u[:, 0], [0.0, 1.0, 1.0, 0.0])
    assert d.y.dtype == np.float64


def test_inputs_not_aliased():
    u = np.zeros(5)
    d = subid.IOData(u, np.zeros(5))
    u[0] = 3.0
    assert d.u[0, 0] == 0.0


def test_non_uniform_time_kept():
    t = np.array([0.0, 0.1, 0.25, 0.3, 0.5])
    d = subid.IOData(np.zeros(5), np.zeros(5), t=t)
    assert d.dt is None and not d.is_uniform
    np.testing.assert_array_equal(d.t, t)
    part = d[1:4]
    np.testing.assert_array_equal(part.t, t[1:4])


def test_uniform_time_stamps_give_dt():
    d = subid.IOData(np.zeros(5), np.zeros(5), t=2.0 + 0.5 * np.arange(5))
    assert d.dt == pytest.approx(0.5)
    np.testing.assert_allclose(d.t, 2.0 + 0.5 * np.arange(5))


def test_slicing_keeps_time():
    d = subid.IOData(np.arange(20.0), np.arange(20.0) * 2, dt=0.1)
    part = d[5:15]
    assert part.n_samples == 10
    np.testing.assert_allclose(part.t, 0.5 + 0.1 * np.arange(10))
    np.testing.assert_array_equal(part.y[:, 0], 2 * np.arange(5.0, 15.0))
    every_other = d[::2]
    assert every_other.dt == pytest.approx(0.2)
    with pytest.raises(errors.DataError, match="slice"):
        d[3]
    with pytest.raises(errors.DataError, match="no samples"):
        d[5:5]


def test_split():
    d = subid.IOData(np.arange(100.0), np.arange(100.0), dt=0.5, input_names=["a"],
                     output_names=["b"])
    est, val = d.split(0.7)
    assert est.n_samples == 70 and val.n_samples == 30
    assert val.t[0] == pytest.approx(35.0)
    assert est.input_names == ("a",)
    for bad in (0, 1, 1.5, -0.1, "half"):
        with pytest.raises(errors.DataError):
            d.split(bad)


def test_detrend():
    t = np.arange(50.0)
    d = subid.IOData(3 + 0 * t, np.column_stack([2 + 0.5 * t, -t]), dt=1.0)
    c = d.detrend()
    np.testing.assert_allclose(c.u.mean(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(c.y_offset, [2 + 0.5 * 24.5, -24.5])
    lin = d.detrend("linear")
    np.testing.assert_allclose(lin.y, 0, atol=1e-10)
    np.testing.assert_allclose(lin.y_offset[1], [0.5, -1.0])
    with pytest.raises(errors.DataError):
        d.detrend("quadratic")


def test_names_validated():
    with pytest.raises(errors.DataError, match="2 names"):
        subid.IOData(np.zeros(3), np.zeros(3), input_names=["a", "b"])
    with pytest.raises(errors.DataError, match="repeats"):
        subid.IOData(np.zeros((3, 2)), np.zeros(3), input_names=["a", "a"])


# -- arrays that look transposed (issue 29) ------------------------------------
def _transposed_case():
    rng = np.random.default_rng(29)
    u = rng.standard_normal((5000, 2))
    y = rng.standard_normal((5000, 1))
    return u, y


def test_channels_x_samples_arrays_raise_a_data_error_saying_transposed():
    # SIPPY / python-control layout: IOData(u.T, y.T) with u of shape (5000, 2)
    u, y = _transposed_case()
    cases = [((u.T, y.T), {"dt": 0.05}), ((u.T, y), {}), ((u, y.T), {}),
             ((u.T[:1], y.T), {})]
    for args, kwargs in cases:
        with pytest.raises(errors.DataError, match=r"looks transposed.*pass [uy]\.T, of shape "
                                                   r"\(5000, [12]\)"):
            subid.IOData(*args, **kwargs)
    # the method never sees the record: the error comes from the constructor
    with pytest.raises(errors.DataError, match="looks transposed"):
        subid.ls_subspace(subid.IOData(u.T, y.T, dt=0.05))


def test_time_stamps_along_the_second_axis_say_the_time_axis_is_second():
    u, y = _transposed_case()
    t = 0.05 * np.arange(50)
    with pytest.raises(errors.DataError, match="second axis.*time must be axis 0"):
        subid.IOData(u[:50].T, y[:50].T, t=t)


def test_the_transposed_rule_is_channels_above_samples_and_above_the_bound():
    from subid._validation import TRANSPOSED_MIN_CHANNELS as bound
    # at the bound, or fewer channels than samples: a legal record, kept as given
    for shape in [(1, bound), (bound + 1, bound + 1), (3, 2)]:
        d = subid.IOData(np.ones(shape), np.ones((shape[0], 1)))
        assert (d.n_samples, d.n_inputs) == shape
    with pytest.raises(errors.DataError, match="looks transposed"):
        subid.IOData(np.ones((bound, bound + 1)), np.ones((bound, 1)))
    with pytest.raises(errors.DataError, match="looks transposed"):
        subid.IOData(np.ones((1, bound + 1)), np.ones((1, 1)))


def test_no_bundled_dataset_looks_transposed():
    for name in subid.datasets.names():
        d = subid.datasets.load(name)
        assert d.n_samples > max(d.n_inputs, d.n_outputs), name


def test_scaled_changes_the_units_of_each_channel_and_keeps_the_rest():
    rng = np.random.default_rng(0)
    a = subid.IOData(rng.standard_normal((40, 2)), rng.standard_normal((40, 3)), dt=0.5)
    b = subid.IOData(rng.standard_normal((30, 2)), rng.standard_normal((30, 3)), dt=0.5)
    record = subid.merge([a, b]).detrend()
    t = np.cumsum(rng.uniform(0.5, 1.5, 40))
    stamped = subid.IOData(a.u, a.y, t=t)
    np.testing.assert_array_equal(stamped.scaled(outputs=[1.0, 2.0, 3.0]).t, t)
    fu, fy = np.array([1e-3, 2.0]), np.array([5.0, 1e4, 0.5])
    out = record.scaled(inputs=fu, outputs=fy)
    np.testing.assert_array_equal(out.u, record.u * fu)
    np.testing.assert_array_equal(out.y, record.y * fy)
    np.testing.assert_array_equal(out.t, record.t)
    assert out.experiment_ranges == record.experiment_ranges
    assert out.experiment_names == record.experiment_names
    assert out.output_names == record.output_names
    np.testing.assert_array_equal(out.y_offset, record.y_offset * fy)
    np.testing.assert_array_equal(out.u_offset, record.u_offset * fu)
    np.testing.assert_array_equal(record.scaled(outputs=fy).u, record.u)
    for bad in ([1.0, 2.0], [1.0, 0.0, 1.0], [1.0, np.nan, 1.0]):
        with pytest.raises(errors.DataError, match="3 positive finite factors"):
            record.scaled(outputs=bad)


def test_time_stamps_as_date_times_or_durations():
    """``t`` of numpy date-times, a pandas DatetimeIndex or durations: seconds from the
    first stamp, as subid.read and IOData.from_pandas take them."""
    pd = pytest.importorskip("pandas")
    rng = np.random.default_rng(0)
    index = pd.date_range("2024-01-01", periods=50, freq="2s")
    u, y = rng.standard_normal(50), rng.standard_normal(50)
    d = subid.IOData(u, y, t=index)
    assert d.is_uniform and d.dt == 2.0
    assert subid.IOData(u, y, t=index - index[0]).dt == 2.0
    t = np.array(["2024-01-01T00:00:00", "2024-01-01T00:00:01.5", "2024-01-01T00:00:04"],
                 dtype="datetime64[ms]")
    np.testing.assert_array_equal(subid.IOData(np.ones(3), np.arange(3.0), t=t).t,
                                  [0.0, 1.5, 4.0])
    with pytest.raises(errors.DataError, match="missing date-times"):
        subid.IOData(np.ones(3), np.arange(3.0),
                     t=np.array(["2024-01-01", "NaT", "2024-01-03"], dtype="datetime64[D]"))
    with pytest.raises(errors.DataError, match="must be numeric or date-times"):
        subid.IOData(np.ones(3), np.arange(3.0), t=np.array(["a", "b", "c"]))


def test_masked_entries_are_missing_values_like_nan():
    y = np.array([1.0, 2.0, 4.0, 3.0])
    masked = np.ma.array([1.0, 2.0, 3.0, 5.0], mask=[0, 1, 0, 1])
    with pytest.raises(errors.DataError, match="input u has 2 masked values at rows 1, 3"):
        subid.IOData(masked, y)
    with pytest.raises(errors.DataError, match="output y has 1 masked value at row 0"):
        subid.IOData(y, np.ma.array(np.ones((4, 2)), mask=[[1, 0], [0, 0], [0, 0], [0, 0]]))
    with pytest.raises(errors.DataError, match="masked value at row 2"):
        subid.IOData(y, y, t=np.ma.array([0.0, 1.0, 2.0, 3.0], mask=[0, 0, 1, 0]))
    # a masked array with nothing masked is its values
    d = subid.IOData(np.ma.array([1.0, 2.0, 3.0, 5.0]), y)
    np.testing.assert_array_equal(d.u[:, 0], [1.0, 2.0, 3.0, 5.0])


def test_object_arrays_of_strings_are_refused_as_string_arrays_are():
    pd = pytest.importorskip("pandas")
    y = np.array([1.0, 2.0, 4.0])
    with pytest.raises(errors.DataError, match="strings"):
        subid.IOData(np.array(["1", "2", "3"]), y)
    strings = r"holds values that are not numbers \(strings\)"
    with pytest.raises(errors.DataError, match=rf"input u {strings}, e.g. '1' at row 0"):
        subid.IOData(pd.Series(["1", "2", "3"]), y)
    with pytest.raises(errors.DataError, match=rf"output y {strings}, e.g. 'x' at row 1"):
        subid.IOData(y, np.array([[1.0, 2], ["x", 3], [4, 5]], dtype=object))
    with pytest.raises(errors.DataError, match=rf"time stamps t {strings}"):
        subid.IOData(y, y, t=pd.Series(["0", "1", "2"]))
    # object arrays of numbers stay accepted
    d = subid.IOData(np.array([1, 2.5, np.float32(3)], dtype=object), y)
    np.testing.assert_array_equal(d.u[:, 0], [1.0, 2.5, 3.0])


def test_time_stamps_must_be_one_dimensional():
    u = y = np.array([1.0, 2.0, 4.0])
    for t in ([[0, 1, 3]], [[0], [1], [3]]):
        with pytest.raises(errors.DataError, match=r"one-dimensional .* a column or a row of "
                                                   r"3 stamps: pass numpy.ravel\(t\)"):
            subid.IOData(u, y, t=t)
    with pytest.raises(errors.DataError, match=r"one-dimensional .* got shape \(3, 3\)$"):
        subid.IOData(u, y, t=np.zeros((3, 3)))
    np.testing.assert_array_equal(subid.IOData(u, y, t=[0, 1, 3]).t, [0.0, 1.0, 3.0])
