"""IOData: the caller's time stamps, scaled records, detrending twice, slices of
detrended records and the refusals of bad arguments."""

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
