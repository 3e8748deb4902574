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
    K.kernel(T, u[1:], y[1:], np.zeros(299, dtype=np.int64), steps, lamM, lamT, Fphi, Fg0, Fg1,
             Iphi, Ig0, Ig1, b._H, par, ipar, *(st[k] for k in b._ORDER), *cache, st["hist"],
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
