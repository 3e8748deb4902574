"""Peak memory of the B, D, x0 regression with many channels and many experiments (issue 28).

Runs on whichever subid is on the path (compare two trees by running it twice)
and prints the tracemalloc peak and the wall time of each case; a MemoryError
is reported as such. Run it under a memory limit, e.g.::

    (ulimit -v 6000000; PYTHONPATH=src OPENBLAS_NUM_THREADS=1 python bench/bd_memory.py)

Cases: a seeded record of 100 inputs and 100 outputs (3,000 samples, a stable
system of order 4, noise) through the regression for the true (A, C); 2,000
experiments of 20 samples (2 inputs, 2 outputs, order 3) through the regression with
one x0 per experiment. With ``--methods``, the 100 x 100 record through ``n4sid`` (the
reference), ``ls_subspace`` and ``moesp``: at order 4 and horizon 5 and with their
defaults (``order=None``: the cross-validated order and horizon), each after a
warm-up on a small record (the compiled kernels), with its time relative to
``n4sid``'s in the same process. The times are taken under tracemalloc.
"""

from __future__ import annotations

import sys
import time
import tracemalloc

import numpy as np

import subid


def _system(n, nu, ny, seed):
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    A = Q @ np.diag(rng.uniform(-0.9, 0.9, n)) @ Q.T
    return A, rng.standard_normal((n, nu)), rng.standard_normal((ny, n)), \
        rng.standard_normal((ny, nu))


def _record(n, nu, ny, length, seed):
    A, B, C, D = _system(n, nu, ny, seed)
    rng = np.random.default_rng(seed + 1)
    u = rng.standard_normal((length, nu))
    model = subid.StateSpace(A, B, C, D, 1.0)
    y = np.asarray(model.simulate(u)) + 0.1 * rng.standard_normal((length, ny))
    return A, C, subid.IOData(u, y)


def _regression(A, C, data):
    try:
        from subid.methods.bd import fit_b_d_x0  # after issue 24/28
        return fit_b_d_x0(A, C, data, output_weights=1 / data.y.std(axis=0))
    except ImportError:
        from subid.methods.dt._regression import fit_b_d_x0
        starts = [a for a, _ in data.experiment_ranges] if data.n_experiments > 1 else None
        return fit_b_d_x0(A, C, data.u, data.y, output_weights=1 / data.y.std(axis=0),
                          starts=starts)


def _measure(label, run, reference=None):
    tracemalloc.start()
    start = time.perf_counter()
    try:
        result = run()
        outcome = "ok"
        if getattr(result, "order", None) is not None:
            outcome += f" (order {result.order}, horizon {result.info.get('horizon')})"
    except MemoryError:
        outcome = "MemoryError"
    elapsed = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    ratio = "" if reference is None else f" ({elapsed / reference:.2f}x n4sid)"
    print(f"| {label} | {outcome} | {peak / 2 ** 20:.1f} MiB | {elapsed:.2f} s{ratio} |",
          flush=True)
    return elapsed


def _methods(data):
    """The methods on the 100 x 100 record, pinned and by default, against n4sid."""
    _, _, small = _record(2, 3, 3, 400, seed=2)
    for name in ("n4sid", "ls_subspace", "moesp"):              # warm-up: compiled kernels
        getattr(subid, name)(small, 2, horizon=4)
        getattr(subid, name)(small)
    for label, args in (("order=4, horizon=5", dict(order=4, horizon=5)),
                        ("default", {})):
        reference = _measure(f"n4sid({label}), 100 x 100", lambda a=args: subid.n4sid(data, **a))
        for name in ("ls_subspace", "moesp"):
            _measure(f"{name}({label}), 100 x 100",
                     lambda n=name, a=args: getattr(subid, n)(data, **a), reference)


def main():
    print("| case | outcome | tracemalloc peak | time |")
    print("|---|---|---|---|")
    A, C, data = _record(4, 100, 100, 3000, seed=1)
    _measure("B, D, x0 regression, 100 x 100, 3,000 samples", lambda: _regression(A, C, data))
    if "--methods" in sys.argv:     # the whole methods too (minutes)
        _methods(data)
    A, C, one = _record(3, 2, 2, 40000, seed=3)
    merged = subid.merge([one[k:k + 20] for k in range(0, 40000, 20)])
    _measure("B, D, x0 regression, 2,000 experiments of 20 samples",
             lambda: _regression(A, C, merged))
    return 0


if __name__ == "__main__":
    sys.exit(main())
