"""Time and peak memory of the streamed second pass with many experiments (issue 28).

The B, D, x0 regression of a record held in pieces
(``subid.methods.dt._bd_pass.OutputRegression``, the second pass of
``subid.identify_stream`` and ``subid.methods.dt.distributed``) with one
experiment per piece, as ``identify_stream`` builds it from ``NEW_EXPERIMENT``
markers: E experiments of 20 samples (2 inputs, 2 outputs, order 3, seeded,
1 % output noise), for the true (A, C), on the modal path and on the QR path
(``--qr``: A with a nearly defective pair of eigenvalues). Then, for the largest
E, ``identify_stream`` end to end (moesp, order 3, horizon 5), under tracemalloc
(which slows the Python parts several times) and without it. Runs on whichever
subid is on the path (compare two trees by running it twice); prints the
tracemalloc peak and the wall time (median of ``--repeat``, default 1)::

    PYTHONPATH=src OPENBLAS_NUM_THREADS=1 python bench/bd_pass_experiments.py [--qr]
"""

from __future__ import annotations

import sys
import time
import tracemalloc

import numpy as np

import subid
from subid.methods.dt._bd_pass import OutputRegression
from subid.methods.dt.stream import NEW_EXPERIMENT


def _record(E, length, defective, seed=5):
    rng = np.random.default_rng(seed)
    if defective:
        A = np.array([[0.8, 1.0, 0.0], [0.0, 0.8 + 1e-10, 0.3], [0.0, 0.0, -0.5]])
    else:
        Q = np.linalg.qr(rng.standard_normal((3, 3)))[0]
        A = Q @ np.diag(rng.uniform(-0.9, 0.9, 3)) @ Q.T
    B, C, D = (rng.standard_normal(s) for s in ((3, 2), (2, 3), (2, 2)))
    u = rng.standard_normal((E * length, 2))
    y = np.empty((E * length, 2))
    for a in range(0, E * length, length):
        x = rng.standard_normal(3)
        for t in range(a, a + length):
            y[t] = C @ x + D @ u[t]
            x = A @ x + B @ u[t]
    return A, C, u, y + 0.01 * rng.standard_normal(y.shape)


def _second_pass(A, C, u, y, E, length):
    def map_pieces(function, arguments):
        return [function([(u[k * length:(k + 1) * length], y[k * length:(k + 1) * length])],
                         *arguments[k]) for k in range(E)]
    return OutputRegression(map_pieces, E, 2, 2, experiments=list(range(E)))(A, C)


def _pieces(u, y, E, length):
    """E pieces of ``length`` samples, :data:`NEW_EXPERIMENT` between them."""
    pieces = []
    for k in range(E):
        if k:
            pieces.append(NEW_EXPERIMENT)
        pieces.append(subid.IOData(u[k * length:(k + 1) * length],
                                   y[k * length:(k + 1) * length]))
    return pieces


def _measure(label, run, repeat):
    times, peak = [], 0
    for _ in range(repeat):
        tracemalloc.start()
        start = time.perf_counter()
        try:
            result = run()
            outcome = "ok"
        except MemoryError:
            result, outcome = None, "MemoryError"
        times.append(time.perf_counter() - start)
        peak = max(peak, tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    if isinstance(result, tuple):
        outcome += f" ({result[3]['regression_path']})"
    print(f"| {label} | {outcome} | {peak / 2 ** 20:.1f} MiB | {np.median(times):.2f} s |",
          flush=True)


def main():
    defective = "--qr" in sys.argv
    repeat = int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 1
    length = 20
    A, C, u, y = _record(10, length, defective)          # warm-up: the compiled kernels
    _second_pass(A, C, u, y, 10, length)
    print("| case | outcome | tracemalloc peak | time |")
    print("|---|---|---|---|")
    for E in (250, 500, 1000, 2000):
        A, C, u, y = _record(E, length, defective)
        _measure(f"second pass, {E:,} experiments of {length} samples"
                 f"{' (QR)' if defective else ''}",
                 lambda a=(A, C, u, y, E, length): _second_pass(*a), repeat)
    pieces = _pieces(u, y, E, length)
    _measure(f"identify_stream(moesp, 3, 5), {E:,} experiments of {length} samples",
             lambda: subid.identify_stream(pieces, "moesp", 3, 5), repeat)
    print("\nidentify_stream(moesp, 3, 5) without tracemalloc (median of 3):")
    for E in (500, 1000, 2000):
        pieces = _pieces(*_record(E, length, defective)[2:], E, length)
        times = []
        for _ in range(3):
            start = time.perf_counter()
            subid.identify_stream(pieces, "moesp", 3, 5)
            times.append(time.perf_counter() - start)
        print(f"- {E:,} experiments: {np.median(times):.2f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
