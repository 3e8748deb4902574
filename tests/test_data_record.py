"""IOData: the caller's time stamps, scaled records, detrending twice, slices of
detrended records and the refusals of bad arguments."""

import warnings

import numpy as np
import pytest

import subid
from subid.data import offset_kind
from subid.errors import DataError, OptionError


def test_time_stamps_are_copied():
    t = np.arange(5) * 0.1
    d = subid.IOData(np.arange(5.0), np.arange(5.0), t=t)
    t[2], t[3] = 99.0, -1.0
    np.testing.assert_array_equal(d.t, np.arange(5) * 0.1)
    assert t.flags.writeable                      # the caller's array is left alone


def test_scaled_beyond_the_double_range_is_refused():
    d = subid.IOData(np.column_stack([np.linspace(1, 2, 20), np.ones(20)]),
                     np.arange(20.0), dt=0.1)
    with pytest.raises(DataError, match="scaled\\(inputs=...\\): the factor 1e\\+308 of "
                                        "channel 'u1'"):
        d.scaled(inputs=[1e308, 1.0])
    with pytest.raises(DataError, match="needs 1 positive finite factor, one per channel"):
        d.scaled(outputs=["a", "b"])
    # the offsets of detrend overflow too
    big = subid.IOData(np.full(4, 1e300) + np.arange(4), np.arange(4.0))
    with pytest.raises(DataError, match="offsets removed by detrend"):
        big.detrend().scaled(inputs=[1e10])


def test_detrend_twice_keeps_the_operating_point():
    t = np.arange(20) * 0.5
    d = subid.IOData(3 * t + 1, t ** 2 + 100, dt=0.5)
    once = d.detrend()
    twice = once.detrend()
    np.testing.assert_allclose(twice.u_offset, once.u_offset)
    np.testing.assert_allclose(twice.y_offset, once.y_offset)
    both = d.detrend().detrend("linear")
    assert offset_kind(both) == "linear"
    np.testing.assert_allclose(both.u_offset, d.detrend("linear").u_offset, atol=1e-12)
    np.testing.assert_allclose(both.y_offset, d.detrend("linear").y_offset, atol=1e-9)
    # a merged record accumulates too (it refused before)
    m = subid.merge([d, d[2:]])
    np.testing.assert_allclose(m.detrend().detrend().u_offset, m.detrend().u_offset)


def test_slice_of_linear_detrend_has_its_own_intercepts():
    t = np.arange(20) * 0.5
    d = subid.IOData(3 * t + 1, 2 * t + 7, dt=0.5)
    e = d.detrend("linear")
    s = e[4:10]                                    # starts at t = 2
    np.testing.assert_allclose(s.u_offset, [[7.0], [3.0]])
    np.testing.assert_allclose(s.y_offset, [[11.0], [2.0]])
    # the slice equals the slice detrended itself
    np.testing.assert_allclose(s.y_offset, d[4:10].detrend("linear").y_offset)
    m = subid.merge([d, d]).detrend("linear")
    np.testing.assert_allclose(m[15:25].y_offset[:, 0, 0], [22.0, 7.0])


def test_bad_arguments_raise_subid_errors():
    d = subid.IOData(np.arange(10.0), np.arange(10.0) * 2, dt=0.1)
    with pytest.raises(DataError, match="integer sample indices"):
        d[1.5:3]
    with pytest.raises(DataError, match="positive step"):
        d[::0]
    with pytest.raises(DataError, match="names must be a list of strings"):
        subid.IOData(np.ones(3), np.ones(3), input_names=5)
    with pytest.raises(DataError, match="names must be a list of strings"):
        subid.merge([d, d], names=3)
    with pytest.raises(DataError, match="in 0..1"):
        subid.merge([d, d]).experiment(-1)
    with pytest.raises(OptionError, match="copy must be True or False"):
        subid.IOData(np.ones(3), np.ones(3), copy="no")
    with pytest.raises(OptionError, match="per_experiment must be True or False"):
        d.detrend(per_experiment="x")
    f32 = subid.IOData(np.ones(3), np.ones(3), dt=np.float32(0.1))
    with pytest.raises(DataError, match="dt=0.10000000149011612 but record 0 with dt=0.1;"):
        subid.merge([d, f32])


def test_stamps_written_at_limited_precision_are_uniform():
    n = 600
    u, y = np.sin(np.arange(n) * 0.1), np.cos(np.arange(n) * 0.07)
    ms = subid.IOData(u, y, t=np.round(np.arange(n) / 30, 3))       # 30 Hz logged in ms
    assert ms.is_uniform and abs(ms.dt - 1 / 30) < 1e-5
    single = subid.IOData(u, y, t=(np.arange(n) * 0.01).astype(np.float32))
    assert single.is_uniform and abs(single.dt - 0.01) < 1e-8
    assert subid.moesp(subid.IOData(np.random.default_rng(0).standard_normal(n), y,
                                    t=np.round(np.arange(n) / 30, 3)), 2).dt == ms.dt
    # a missing sample is not rounding: integer stamps with a gap stay non-uniform
    gap = np.delete(np.arange(n + 1.0), 300)
    assert not subid.IOData(u, y, t=gap).is_uniform
    # nor is a jitter beyond the written precision
    jitter = np.round(np.arange(n) / 30 + 0.004 * (np.arange(n) % 2), 3)
    assert not subid.IOData(u, y, t=jitter).is_uniform
    with pytest.raises(DataError, match="dt=\\.\\.\\."):
        subid.moesp(subid.IOData(u, y, t=jitter), 2)


def test_date_time_objects_and_time_zones_as_time_stamps():
    pd = pytest.importorskip("pandas")
    import datetime
    u = [1.0, 2.0, 3.0]
    # across the change to summer time: UTC keeps the 1 s grid
    stamps = pd.date_range("2024-03-31 01:59:59", periods=3, freq="1s", tz="Europe/Paris")
    for t in (stamps, pd.Series(stamps), list(stamps)):
        d = subid.IOData(u, u, t=t)
        assert d.dt == 1.0
        np.testing.assert_array_equal(d.t, [0.0, 1.0, 2.0])
    naive = [datetime.datetime(2024, 1, 1, 0, 0, 0, 500_000 * k) for k in range(2)] + \
        [datetime.datetime(2024, 1, 1, 0, 0, 1)]
    assert subid.IOData(u, u, t=naive).dt == 0.5
    zone = datetime.timezone(datetime.timedelta(hours=2))
    with pytest.raises(DataError, match="mixes date-times with and without a time zone"):
        subid.IOData(u, u, t=[naive[0], naive[1].replace(tzinfo=zone), naive[2]])


def test_npz_with_date_time_stamps(tmp_path):
    f = tmp_path / "dt.npz"
    np.savez(f, u=[1.0, 2, 3], y=[1.0, 2, 3],
             t=np.datetime64("2024-01-01") + np.arange(3) * np.timedelta64(250, "ms"))
    d = subid.read(f)
    assert d.dt == 0.25
    np.testing.assert_array_equal(d.t, [0.0, 0.25, 0.5])


def test_merge_takes_a_one_sample_record_with_a_stamp():
    a = subid.IOData([1.0, 2, 3], [1.0, 2, 3], dt=0.5)
    one = subid.IOData([1.0], [1.0], t=[5.0])
    assert subid.merge([one, a]).dt == 0.5
    assert subid.merge([a, one]).experiment_ranges == ((0, 3), (3, 4))
    with pytest.raises(DataError, match="no sampling period"):
        subid.merge([one, one])


def test_pandas_indexes_are_not_ignored():
    pd = pytest.importorskip("pandas")
    from subid.errors import SamplingWarning
    df = pd.DataFrame({"u": [1.0, 2, 3], "y": [4.0, 5, 6]},
                      index=pd.date_range("2024", periods=3, freq="10ms"))
    with pytest.warns(SamplingWarning, match="pass t=u.index"):
        assert subid.IOData(df[["u"]], df["y"]).dt == 1.0
    assert subid.IOData(df[["u"]], df["y"], t=df.index).dt == 0.01
    with pytest.raises(DataError, match="different indexes \\(row 0"):
        subid.IOData(df["u"], df["y"].iloc[::-1])
    with pytest.raises(DataError, match="different indexes"):
        subid.IOData(df["u"], df["y"].reset_index(drop=True))
    plain = df.reset_index(drop=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # a default or filtered index: quiet
        assert subid.IOData(plain.u, plain.y).dt == 1.0
        kept = plain[plain.u > 1]
        assert subid.IOData(kept.u, kept.y).n_samples == 2
