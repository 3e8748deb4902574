"""One-sample calls of AdaptiveIdentifier.update: the cheap path gives the
state of one chunk bit for bit, and validates as strictly as the general path."""

import numpy as np
import pytest

from subid import AdaptiveIdentifier
from subid.errors import DataError
from subid.methods.online import _adaptive_kernel as K


def _record(n=700, seed=3):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, 2)), rng.standard_normal((n, 2))


def _state(ident):
    return ident._buf.copy(), ident._st["ist"].copy(), ident._st["hist"].copy()


def test_sample_by_sample_equals_one_chunk_bit_for_bit():
    u, y = _record()
    chunk = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2, history_size=8)
    chunk.update(u, y)
    single = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2, history_size=8)
    for k in range(u.shape[0]):
        single.update(u[k], y[k])
    for a, b in zip(_state(chunk), _state(single)):
        np.testing.assert_array_equal(a, b)


def test_packed_kernel_equals_the_kernel_on_the_views():
    u, y = _record(300)
    a = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    b = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    a.update(u, y)                                  # kernel_packed
    b.update(u[:1], y[:1])
    steps, tables, cache = b._uniform
    T = b._t_origin + b._dt * (np.arange(299) + float(1 - b._k_origin))
    Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, lamM, lamT = tables
    par, ipar = b._parameters()
    st = b._st
    H = np.array(b._H)      # writeable, as kernel_packed's views: the signature warmup compiles
    K.kernel(T, u[1:], y[1:], np.zeros(299, dtype=np.int64), steps, lamM, lamT, Fphi, Fg0, Fg1,
             Iphi, Ig0, Ig1, H, par, ipar, *(st[k] for k in b._ORDER), *cache, st["hist"],
             b._buf)
    for x, z in zip(_state(a), _state(b)):
        np.testing.assert_array_equal(x, z)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_one_non_finite_sample_is_rejected_and_leaves_the_state(bad):
    u, y = _record(50)
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    ident.update(u[:40], y[:40])
    before = _state(ident)
    sample = u[40].copy()
    sample[1] = bad
    with pytest.raises(DataError, match="input u"):
        ident.update(sample, y[40])
    with pytest.raises(DataError, match="output y"):
        ident.update(u[40], np.array([bad, 0.0]))
    for x, z in zip(before, _state(ident)):
        np.testing.assert_array_equal(x, z)


def test_strided_one_sample_views_are_accepted():
    u, y = _record(60)
    wide = np.zeros((60, 4))
    wide[:, ::2] = u
    a = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    b = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    for k in range(60):
        a.update(wide[k, ::2], y[k])               # non-contiguous 1-D sample
        b.update(u[k], y[k])
    for x, z in zip(_state(a), _state(b)):
        np.testing.assert_array_equal(x, z)


def test_one_sample_forms_take_the_general_path_with_the_same_result():
    """Samples the cheap path does not take (byte order, lists, other dtypes,
    shapes) give the state of plain float64 samples."""
    u, y = _record(120)
    ref = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    other = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
    for k in range(120):
        ref.update(u[k], y[k])
        form = k % 4
        if form == 0:
            other.update(u[k].astype(">f8"), y[k])              # byte-swapped
        elif form == 1:
            other.update(list(u[k]), y[k].tolist())             # lists
        elif form == 2:
            other.update(u[k:k + 1], y[k:k + 1])                # a (1, 2) chunk
        else:
            other.update(u[k].astype(np.longdouble), y[k])      # another float dtype
    for x, z in zip(_state(ref), _state(other)):
        np.testing.assert_array_equal(x, z)


def test_huge_finite_one_sample_is_treated_as_by_the_general_path():
    """Entries whose sum overflows are finite: the cheap path's test of the sum
    falls back to the entries, and the outcome is that of a (1, 2) chunk: the boundary
    refuses both (their squares overflow), the state unchanged."""
    u, y = _record(60)
    outcomes = []
    for shape in ((2,), (1, 2)):
        ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2)
        ident.update(u[:50], y[:50])
        try:
            ident.update(np.full(shape, 1e308), y[50].reshape(shape))
            outcomes.append(("ok",) + _state(ident))
        except DataError as exc:
            outcomes.append((str(exc),) + _state(ident))
    assert outcomes[0][0] == outcomes[1][0]
    assert "input u reaches 1e+308" in outcomes[0][0]
    for x, z in zip(outcomes[0][1:], outcomes[1][1:]):
        np.testing.assert_array_equal(x, z)


@pytest.mark.parametrize("at_refresh", [False, True])
def test_one_sample_rejected_by_the_kernel_is_rolled_back(monkeypatch, at_refresh):
    """A one-sample call whose kernel run ends non-finite (or raises) leaves
    the state as it was, history included when the sample is a refresh."""
    u, y = _record(400)
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2, history_size=4, refresh_every=10)
    start = 300 if at_refresh else 303      # n_samples 300: this sample is a refresh
    ident.update(u[:start], y[:start])
    before = _state(ident)
    real = K.kernel_packed

    def overflowing(*args):
        real(*args)
        args[-1][5] = np.inf
        if at_refresh:
            args[-2][:] = -1.0          # the history, written at a refresh
        return False

    def raising(*args):
        real(*args)
        args[-1][:] = 7.0
        raise ZeroDivisionError("mid-run")

    for fake, err in ((overflowing, DataError), (raising, ZeroDivisionError)):
        monkeypatch.setattr(K, "kernel_packed", fake)
        with pytest.raises(err):
            ident.update(u[start], y[start])
        monkeypatch.undo()
        for x, z in zip(before, _state(ident)):
            np.testing.assert_array_equal(x, z)
    for k in range(start, 400):
        ident.update(u[k], y[k])
    ref = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-2, history_size=4, refresh_every=10)
    ref.update(u, y)
    for x, z in zip(_state(ref), _state(ident)):
        np.testing.assert_array_equal(x, z)


def test_all_finite_agrees_with_numpy():
    rng = np.random.default_rng(5)
    base = rng.standard_normal(1806) * 10.0 ** rng.integers(-300, 300, 1806)
    assert K._all_finite(base)
    for value in (np.nan, np.inf, -np.inf, 1.7e308, -0.0, 5e-324, -np.nan):
        for pos in (0, 1, 3, 4, 7, 1024, 1805):
            x = base.copy()
            x[pos] = value
            assert K._all_finite(x) == bool(np.isfinite(x).all()), (value, pos)
    assert K._all_finite(np.zeros(0))


def test_one_sample_helper_accepts_exactly_the_cheap_forms():
    """``one_sample``: a (1, channels) view of a contiguous finite float64
    sample (any float64 descriptor object), None for anything else (left to
    the general validation)."""
    import pickle

    from subid.methods.online.base import one_sample

    plain = np.array([1.0, -2.0])
    other_descr = np.array([1.0, -2.0]).view(pickle.loads(pickle.dumps(np.dtype(np.float64))))
    assert other_descr.dtype is not np.dtype(np.float64)
    for values in (plain, other_descr, np.array([1e150, -1e150])):
        out = one_sample(values, 2)
        assert out.shape == (1, 2) and out.flags.c_contiguous and np.shares_memory(out, values)
    assert one_sample(np.array([3.0]), 1).shape == (1, 1)
    for values in (plain.astype(">f8"), plain.astype(np.float32), np.zeros(3),
                   np.zeros((1, 2)), np.zeros(4)[::2], np.array([np.nan, 0.0]),
                   np.array([0.0, -np.inf]), np.array([np.inf, -np.inf]),
                   np.array([1e308, 1e308]), np.array([0.0, -1e200])):
        assert one_sample(values, 2) is None
