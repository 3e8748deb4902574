"""Chunks of the online identifiers: time stamps against the constructor's dt (one
check, ``base.check_stream_grid``, for RecursiveSubspace and AdaptiveIdentifier) and
empty chunks (a no-op in both)."""

import numpy as np
import pytest

import subid
from subid.errors import DataError

DT = 0.05


def _record(n=200, seed=5):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, 1)), rng.standard_normal((n, 1))


def _identifiers(dt=DT):
    return [subid.RecursiveSubspace(2, 1, 1, dt=dt), subid.AdaptiveIdentifier(2, 1, 1, dt=dt)]


@pytest.mark.parametrize("kind", [0, 1], ids=["RecursiveSubspace", "AdaptiveIdentifier"])
def test_time_stamps_must_be_the_dt_grid(kind):
    u, y = _record()
    ident = _identifiers()[kind]
    with pytest.raises(DataError, match=r"not a uniform grid of step dt \(steps 1.0 to 1.0\)"):
        ident.update(u[:3], y[:3], t=[0.0, 1.0, 2.0])
    assert ident.n_samples == 0
    ident.update(u[:3], y[:3], t=10.0 + DT * np.arange(3))       # any start, then the grid
    with pytest.raises(DataError, match=r"start at 10.2, but the next sample of the stream is "
                                        r"due at t = 10.15"):
        ident.update(u[3:6], y[3:6], t=10.2 + DT * np.arange(3))
    with pytest.raises(DataError, match="not a uniform grid"):
        ident.update(u[3:6], y[3:6], t=[10.15, 10.2, 10.3])
    ident.update(u[3:6], y[3:6], t=10.15 + DT * np.arange(3))
    ident.update(u[6:8], y[6:8])                                   # continues the grid
    assert ident.n_samples == 8 and ident.t == pytest.approx(10.0 + 7 * DT)


def test_adaptive_identifier_without_dt_keeps_non_uniform_stamps():
    u, y = _record()
    ident = subid.AdaptiveIdentifier(2, 1, 1)
    ident.update(u[:3], y[:3], t=[0.0, 1.0, 2.0])
    ident.update(u[3:5], y[3:5], t=[2.5, 4.0])
    assert ident.n_samples == 5 and ident.t == 4.0


def _state(ident):
    if isinstance(ident, subid.AdaptiveIdentifier):
        return [ident._buf.copy(), ident._st["ist"].copy()]
    return [np.asarray(ident.model.A).copy(), ident.n_samples, ident.t]


@pytest.mark.parametrize("kind", [0, 1], ids=["RecursiveSubspace", "AdaptiveIdentifier"])
def test_an_empty_chunk_is_a_no_op(kind):
    u, y = _record()
    ident, reference = _identifiers()[kind], _identifiers()[kind]
    empty = np.zeros((0, 1))
    ident.update(empty, empty)                    # before the first sample, too
    ident.update(empty, empty, t=[])
    assert ident.n_samples == 0 and ident.t is None
    for part in (slice(0, 150), slice(150, 200)):
        ident.update(u[part], y[part])
        ident.update(empty, empty)
        ident.update(empty, empty, t=np.zeros(0))
        reference.update(u[part], y[part])
    for a, b in zip(_state(ident), _state(reference)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(DataError, match="t has 1 entries but the signals have 0 samples"):
        ident.update(empty, empty, t=[100.0])
    with pytest.raises(DataError, match="2 channels but the identifier has 1"):
        ident.update(np.zeros((0, 2)), empty)
    assert ident.n_samples == 200


def test_an_empty_chunk_without_dt_needs_no_time():
    u, y = _record()
    ident = subid.AdaptiveIdentifier(2, 1, 1)
    ident.update(u[:3], y[:3], t=[0.0, 0.1, 0.25])
    ident.update(np.zeros((0, 1)), np.zeros((0, 1)))
    assert ident.n_samples == 3 and ident.t == 0.25
