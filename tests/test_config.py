"""thread_limit really limits the BLAS pool, and restores it."""

import numba
from threadpoolctl import threadpool_info

import subid


def _blas_threads():
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_thread_limit_applies_and_restores():
    import numpy as np
    np.ones((2, 2)) @ np.ones((2, 2))          # make sure BLAS is loaded
    before_blas, before_numba = _blas_threads(), numba.get_num_threads()
    with subid.thread_limit(1):
        assert all(n == 1 for n in _blas_threads())
        assert numba.get_num_threads() == 1
    assert _blas_threads() == before_blas
    assert numba.get_num_threads() == before_numba
