"""subid's own worker threads: how many, and an ordered map over them.

The parsers of pandas and pyarrow, subid's compiled kernels (``nogil``) and
BLAS release the GIL, so a few threads share the cores without copies of
the data. :func:`subid.thread_limit` caps them with BLAS's and numba's.
"""

from __future__ import annotations

import os

#: At most this many threads of subid's own pools (None: the CPUs this
#: process may use, at most :data:`MAX_THREADS`). Set by :func:`subid.thread_limit`.
limit: int | None = None
MAX_THREADS = 4


def available() -> int:
    """Threads subid's own pools may use (at least 1)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:          # not on Linux
        cpus = os.cpu_count() or 1
    cpus = min(MAX_THREADS, cpus)
    return max(1, cpus if limit is None else min(cpus, int(limit)))


def ordered_map(function, items, *, threads: int | None = None, quiet: bool = False) -> list:
    """``[function(item) for item in items]``, run on :func:`available` threads.

    The result does not depend on the number of threads (each item is one
    task, done by one thread, in a copy of the caller's :mod:`contextvars`
    context, as the loop would run it: the settings subid keeps there, such as
    :func:`subid.statistic.hankel.compact_wy_qr`, hold in the tasks); a task's
    exception is re-raised in the caller, and on it (or on the user's interrupt)
    the tasks not yet started are dropped.

    Parameters
    ----------
    function : callable
    items : iterable
    threads : int, optional
        At most this many threads (and at most :func:`available`); 1 runs the loop in
        the calling thread.
    quiet : bool
        Drop the tasks' warnings. Python's warning filters are the process's (not the
        thread's): the calling thread sets them to ignore every warning and to record
        into a list it drops, for the whole map, and restores them after it, so that
        whatever the tasks' own ``warnings.catch_warnings`` blocks save and restore in
        between (they interleave across threads) no task's warning reaches the caller's
        filters, handlers or recorders.
    """
    items = list(items)
    threads = min(available(), len(items), available() if threads is None else int(threads))
    if quiet:
        import warnings
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("ignore")
            return ordered_map(function, items, threads=threads)
    if threads <= 1:
        return [function(item) for item in items]
    import contextvars
    from concurrent.futures import ThreadPoolExecutor

    context = contextvars.copy_context()

    def task(item):
        return context.copy().run(function, item)     # one copy per task: no sharing

    # Executor.map cancels the tasks not yet started when its results stop being read (a
    # task's error, the user's interrupt); those running end (threads cannot be stopped)
    with ThreadPoolExecutor(threads, thread_name_prefix="subid") as pool:
        return list(pool.map(task, items))
