"""One BLAS thread inside subid's computations, unless the user chose the number.

subid's heavy steps are its per-sample kernels (numba, serial) and factorisations and
products of small or tall, thin matrices, where BLAS threads save little; on a machine
whose cores are busy with other work they cost many times over, because OpenBLAS
threads wait for each other spinning while the cores they need run something else.
Measured on this project's 2-core machine (``bench/blas_threads.md``), two BLAS
threads against one: ``subid.identify`` on the 2,048-sample CD_player_arm record 3.1x
slower with the machine otherwise idle and 18x slower with one other process running;
``moesp`` 2.3x and 41x; ``identify`` on 10^5 and 10^6 samples 1.2-1.3x and 2.4x. No
case was faster with two.

So every public computation (the identification methods, ``pem``, ``identify``, the
evaluation functions; :func:`serial_blas` marks them) runs with one BLAS thread per
library loaded in the process (numpy's and scipy's OpenBLAS, MKL, ...), set when the
outermost such call of the main thread starts and restored when it ends. Calls made
in other threads (a Dask worker's) leave the pools as they are: the setting is the
process's, and OpenBLAS (0.3.31 here) ignores one made from another thread (its
pools then keep what the main thread set). The user's choice wins: inside a
:func:`subid.thread_limit` block its number holds, and with any of
:data:`CHOICE_VARIABLES` set in the environment the pools are left as they are. The
command line runs under the same rule (``subid.cli``).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import threading

__all__ = ["serial", "serial_blas", "CHOICE_VARIABLES", "chosen", "one_thread"]

#: Environment variables by which a user sets the number of BLAS/OpenMP threads: with
#: any of them set, subid leaves the thread pools as they are.
CHOICE_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                    "BLIS_NUM_THREADS", "GOTO_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")

_depth = 0                   # decorated calls in progress in the main thread
_applied = False             # the pools set by the outermost call's first computation
_restore: list = []          # (library controller, its threads before) while limited
_chosen = 0                  # subid.thread_limit blocks open
_controllers: list | None = None


def chosen(delta: int) -> None:
    """Count a :func:`subid.thread_limit` block opened (+1) or closed (-1): while one
    is open, its number of threads holds."""
    global _chosen
    _chosen += delta


def _blas_libraries() -> list:
    """The BLAS libraries loaded in the process (threadpoolctl's controllers), found
    once (numpy's and scipy's are loaded first: subid uses both)."""
    global _controllers
    if _controllers is None:
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401
        from threadpoolctl import ThreadpoolController
        _controllers = [c for c in ThreadpoolController().lib_controllers
                        if c.user_api == "blas"]
    return _controllers


def one_thread() -> bool:
    """Whether every BLAS library loaded runs one thread now (what :func:`serial_blas`
    sets unless the user chose otherwise): subid's own threads may then share the cores
    with work that calls BLAS (the folds of large models,
    :func:`subid.methods.dt.fold_statistics.fold_threads`) without two levels of
    threads competing for them."""
    try:
        return all(lib.num_threads == 1 for lib in _blas_libraries())
    except Exception as exc:  # noqa: BLE001 - a speed setting: never stops the computation
        logging.getLogger("subid").debug("BLAS threads unknown: %s", exc)
        return False


def _enter(apply: bool = True) -> None:
    global _depth, _applied
    if threading.current_thread() is not threading.main_thread():
        return
    _depth += 1
    if not apply or _applied or _chosen or any(os.environ.get(v) for v in CHOICE_VARIABLES):
        return
    _applied = True
    try:
        for lib in _blas_libraries():
            before = lib.num_threads
            if before != 1:
                lib.set_num_threads(1)
                _restore.append((lib, before))
    except Exception as exc:  # noqa: BLE001 - a speed setting: never stops the computation
        logging.getLogger("subid").debug("BLAS threads left as they are: %s", exc)


def _leave() -> None:
    global _depth, _applied
    if threading.current_thread() is not threading.main_thread():
        return
    _depth -= 1
    if _depth == 0:
        _applied = False
        while _restore:
            lib, before = _restore.pop()
            try:
                lib.set_num_threads(before)
            except Exception as exc:  # noqa: BLE001 - as in _enter
                logging.getLogger("subid").debug("BLAS threads not restored: %s", exc)


@contextlib.contextmanager
def serial(now: bool = False):
    """A block (the command line's command) in which the first computation sets the
    pools to one thread, kept until the block ends (module documentation): the
    libraries are looked up only once a computation runs (``subid --help`` loads no
    scipy). ``now``: set them at once (a loop of online updates, which are not marked
    one by one: a single-sample update would pay the setting each time)."""
    _enter(apply=now)
    try:
        yield
    finally:
        _leave()


def serial_blas(fn):
    """Decorator of a public computation: ``fn`` runs with one BLAS thread (module
    documentation) unless the user chose the number."""
    @functools.wraps(fn)
    def in_serial(*args, **kwargs):
        with serial(now=True):
            return fn(*args, **kwargs)
    in_serial.serial_blas = True     # (tests check the marks)
    return in_serial
