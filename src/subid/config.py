"""Run-time settings: the number of threads numerical kernels may use."""

from __future__ import annotations

import contextlib

import numba
from threadpoolctl import threadpool_limits

from subid import _blas, _threads
from subid._validation import check_int, checked_call

__all__ = ["thread_limit"]


@contextlib.contextmanager
@checked_call
def thread_limit(n_threads: int):
    """Limit the threads of BLAS/LAPACK, OpenMP, numba and subid inside a ``with`` block.

    Without it, subid's computations run with one BLAS thread (faster on small and
    medium problems, and many times faster on a machine whose cores are shared;
    docs/scale.md, Threads); inside it, ``n_threads`` holds for them too: the way to give
    BLAS more threads (a large QR statistic on an idle many-core machine).

    subid's own per-sample kernels are serial; the thread pools that matter
    are BLAS's (QR, matrix products of the data statistic), numba's, and
    subid's own (the CSV parser, the passes over a streamed record, the folds
    of the order selection and of :func:`subid.identify` on large models,
    which use threads only while BLAS runs one).

    Parameters
    ----------
    n_threads : int
        At most this many threads (1 for reproducible timings on shared
        machines; see the README's benchmark notes).

    Examples
    --------
    >>> import subid
    >>> with subid.thread_limit(1):
    ...     model = subid.moesp(subid.systems.simulate_data(
    ...         subid.systems.seed001_system(), 500, seed=0), 3)
    """
    n_threads = check_int(n_threads, "n_threads")
    previous = numba.get_num_threads()
    own = _threads.limit
    numba.set_num_threads(min(n_threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]  # numba.config sets it at import
    _threads.limit = n_threads
    _blas.chosen(+1)                 # the user's number holds in subid's calls (_blas)
    try:
        with threadpool_limits(limits=n_threads):
            yield
    finally:
        _blas.chosen(-1)
        numba.set_num_threads(previous)
        _threads.limit = own
