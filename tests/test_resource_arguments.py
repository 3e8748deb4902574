"""Arguments of subid.basis, subid.interop and the step response that gave raw
exceptions or ran for seconds into a MemoryError are subid errors, up front."""

import time

import numpy as np
import pytest

import subid
from subid.errors import DataError, ModelError, OrderError, ResourceLimitError

MODEL = subid.StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], 1.0)


@pytest.mark.parametrize("call, error, text", [
    (lambda: subid.basis.takenaka_malmquist(None), ModelError, "sequence of poles"),
    (lambda: subid.basis.default_basis("t"), DataError, "time stamps"),
    (lambda: subid.basis.laguerre(1.0, 10**6), OrderError, "7.28 TiB"),
    (lambda: subid.basis.legendre(1.0, 10**6), OrderError, "7.28 TiB"),
    (lambda: subid.basis.default_basis(np.arange(100.0), 10**6), OrderError, "TiB"),
    (lambda: subid.basis.default_basis(np.arange(100.0), 10**4), OrderError, "763 MiB"),
    (lambda: subid.basis.takenaka_malmquist(np.arange(1, 10**6)), OrderError, "at most 500"),
    (lambda: MODEL.step(1e9), ResourceLimitError, "14.9 GiB"),
    (lambda: subid.interop.python_source("m"), ModelError, "subid.StateSpace"),
    (lambda: subid.interop.operating_point("m"), ModelError, "subid.StateSpace"),
    (lambda: subid.interop.operating_point(MODEL, estimation="x"), DataError, "IOData"),
])
def test_refused_up_front(call, error, text):
    start = time.perf_counter()
    with pytest.raises(error, match=text):
        call()
    assert time.perf_counter() - start < 2.0


def test_reasonable_sizes_still_work():
    assert subid.basis.laguerre(2.0, 20).n_functions == 20
    assert subid.basis.default_basis(np.arange(100.0), 8).n_functions == 8
    assert MODEL.step(1e4)[0].size == 10_001
    assert subid.interop.operating_point(MODEL) is None
    assert "control.ss" in subid.interop.python_source(MODEL)
