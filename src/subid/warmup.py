"""Compile subid's numba kernels ahead of their first use.

numba compiles a kernel the first time it is called with a new combination of
argument types and, with ``cache=True`` (every subid kernel), stores the
machine code in its cache (``__pycache__`` next to the module, or
``NUMBA_CACHE_DIR``). Without a cache the first ``AdaptiveIdentifier.update``
waits for the compiler (tens of seconds); with it, it loads in a fraction of
a second. This module fills the cache for the argument types subid's public
calls use (every array is C-contiguous float64 or int64 after validation, so
one specialisation per kernel serves all data):

* :class:`subid.AdaptiveIdentifier` (one kernel for every ``method``; the
  uniform and the time-stamped paths share it),
* :class:`subid.RecursiveSubspace`,
* the batch calls (:func:`subid.ls_subspace`: the B, D, x0 pass; with its
  default order search, the fold candidates' lag-product kernels;
  :func:`subid.identify`, the command line's default: the prediction-error
  refinement's Jacobian), the
  lagged products of long records and streams (:class:`subid.HankelStatistic`),
  the scoring pass of :func:`subid.arx`'s structure search and the prediction
  errors and Riccati doubling of the order search's innovation check,
* :func:`subid.ct_subspace` on a uniform and on a non-uniform grid.

Run it once after installing (``make test`` / ``make demo`` do)::

    python -m subid.warmup

It never prints from :func:`warmup`; the command line prints the seconds per
kernel group.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

__all__ = ["main", "warmup", "kernels_cached"]


def _adaptive():
    from subid.methods.online.adaptive import AdaptiveIdentifier
    from subid.systems import seed000_system

    rng = np.random.default_rng(0)
    t = np.arange(400) * 1e-2
    u = rng.standard_normal((t.size, 2))
    y = seed000_system().simulate(u, t=t, hold="foh")
    AdaptiveIdentifier(4, 2, 2, dt=1e-2).update(u, y)           # uniform path
    AdaptiveIdentifier(4, 2, 2).update(u, y, t=t)               # time-stamped path
    AdaptiveIdentifier(4, 2, 2, dt=1e-2).update(u[0], y[0])     # one sample


def _recursive():
    from subid.methods.online.recursive import RecursiveSubspace
    from subid.systems import seed001_system

    rng = np.random.default_rng(0)
    u = rng.standard_normal((300, 2))
    y = seed001_system().simulate(u)
    RecursiveSubspace(4, 2, 2).update(u, y)


def _batch():
    from subid.data import IOData
    from subid.methods.dt.ls_subspace import ls_subspace
    from subid.methods.dt.pem import pem
    from subid.methods.dt.polynomial import select_structure
    from subid.methods.identify import identify
    from subid.statistic.hankel import HankelStatistic
    from subid.systems import seed001_system

    rng = np.random.default_rng(0)
    u = rng.standard_normal((400, 2))
    y = seed001_system().simulate(u)
    ls_subspace(IOData(u, y), 4)
    # measured records are noisy: on a noise-free one (or folds shorter than the
    # lag-product path's) the order search's scored solve (the fold models' B, D, x0) and
    # the refinement (nothing to refine) never run
    u1 = rng.standard_normal((1000, 2))
    y1 = seed001_system().simulate(u1)
    noisy = IOData(u1, y1 + 0.1 * rng.standard_normal(y1.shape))
    ls_subspace(noisy)                                     # the order search's candidates
    identify(noisy)                 # the command line's default: the search, PEM refinement
    HankelStatistic(2, 2, 4, kind="gram").update(u, y).factor()    # long records, streams
    select_structure(IOData(u, y), max_order=2)            # arx's structure search
    # the order search's innovation check: its prediction errors and Kalman gains
    from subid.methods.dt.choice import innovation_bic
    from subid.methods.dt.noise_model import riccati_by_doubling
    model = seed001_system()
    innovation_bic(model.with_noise_model(np.zeros((model.order, 2)), np.eye(2)), IOData(u, y))
    riccati_by_doubling(0.5 * np.eye(2), np.eye(2), np.eye(2), np.eye(2), np.zeros((2, 2)))
    # a larger model on the noisy record: the blocked form of the sensitivity kernel
    # (model._sensitivity)
    pem(noisy, ls_subspace(noisy, 8), max_iterations=2)


def _ct():
    from subid.data import IOData
    from subid.methods.ct.ct_subspace import ct_subspace
    from subid.systems import seed000_system

    rng = np.random.default_rng(0)
    true = seed000_system()
    t = np.arange(400) * 1e-2
    u = rng.standard_normal((t.size, 2))
    ct_subspace(IOData(u, true.simulate(u, t=t, hold="foh"), t=t), 4)
    tj = np.cumsum(1e-2 * (1.0 + 0.4 * rng.uniform(-1.0, 1.0, t.size)))
    ct_subspace(IOData(u, true.simulate(u, t=tj, hold="foh"), t=tj), 4)


_GROUPS = {"adaptive": _adaptive, "recursive": _recursive, "batch": _batch, "ct": _ct}


def warmup(groups=None) -> dict:
    """Compile (or load from numba's cache) the kernels of subid's common calls.

    Parameters
    ----------
    groups : iterable of str, optional
        Any of ``'adaptive'``, ``'recursive'``, ``'batch'``, ``'ct'``
        (default: all).

    Returns
    -------
    dict
        Seconds spent per group (compilation on an empty cache, loading on a
        filled one).

    Raises
    ------
    subid.errors.SubidError
        An unknown group name.
    """
    from subid.errors import SubidError

    names = list(_GROUPS) if groups is None else list(groups)
    unknown = [g for g in names if g not in _GROUPS]
    if unknown:
        raise SubidError(f"unknown warm-up group(s) {unknown}; choose from {list(_GROUPS)}")
    out = {}
    for name in names:
        t0 = time.perf_counter()
        with warnings.catch_warnings():     # tiny records: convergence warnings expected
            warnings.simplefilter("ignore")
            _GROUPS[name]()
        out[name] = time.perf_counter() - t0
    return out


def kernels_cached() -> bool:
    """Whether numba's cache holds the kernels of the default calls.

    False when the cache index of one of three kernels every default identification
    uses (the simulation, the order search's normal equations, the prediction-error
    refinement's sensitivities) is missing: their first use compiles them, about a
    minute on a 2-core machine, which :func:`warmup` does ahead. The command line
    says so before it computes. True when they are there, and when numba's cache
    cannot be inspected (nothing is then said).

    Returns
    -------
    bool
    """
    try:
        from subid.methods.dt._lag_kernel import normal_matrix
        from subid.model._sensitivity import _recursion_t
        from subid.model._simulate import lti_loop
        # numba's own record of where each dispatcher's cache index lives
        kernels: tuple = (lti_loop, normal_matrix, _recursion_t)
        return all(os.path.exists(kernel._cache._cache_file._index_path) for kernel in kernels)
    except Exception:  # noqa: BLE001 - another numba version: say nothing
        return True


def main(argv=None) -> int:
    """``python -m subid.warmup [--only GROUP ...] [--quiet]``."""
    ap = argparse.ArgumentParser(prog="python -m subid.warmup",
                                 description="Compile subid's numba kernels into numba's "
                                             "cache ahead of their first use.")
    ap.add_argument("--only", nargs="+", choices=list(_GROUPS), help="kernel groups to compile")
    ap.add_argument("--quiet", action="store_true", help="print nothing")
    a = ap.parse_args(argv)
    times = warmup(a.only)
    if not a.quiet:
        for name, sec in times.items():
            print(f"{name:10s} {sec:7.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
