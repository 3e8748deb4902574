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


def ordered_map(function, items) -> list:
    """``[function(item) for item in items]``, run on :func:`available` threads.

    The result does not depend on the number of threads (each item is one
    task, done by one thread); exceptions are re-raised in the caller.
    """
    items = list(items)
    threads = min(available(), len(items))
    if threads <= 1:
        return [function(item) for item in items]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads, thread_name_prefix="subid") as pool:
        return list(pool.map(function, items))
