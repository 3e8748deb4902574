"""Two versions of subid in one process, ``moesp(data)`` calls interleaved (issue 21).

The cost of choosing changes by a few per cent per step, less than the load of the
shared machine moves a timing between two processes. This script imports both
versions (two ``src`` directories) into one process, swapping ``sys.modules`` before
each call (lazy imports inside a call resolve to its own version), alternates the
order of the calls each round, and reports the median of the paired ratios
(second / first) of ``moesp(data)`` CPU time, and the medians of the default and of
``moesp(data, 4, horizon=10)``; 2x2 order-4 random system, 20 dB output noise.

Usage::

    python bench/selection_paired.py /work/main/src src [rounds] [sizes, e.g. 1000,10000]
"""

from __future__ import annotations

import statistics
import sys
import time
import warnings


def load(path):
    """``(subid, its modules)`` imported from ``path``, compiled kernels warmed up."""
    for k in [k for k in sys.modules if k == "subid" or k.startswith("subid.")]:
        del sys.modules[k]
    sys.path.insert(0, path)
    import subid
    from subid import systems
    true = systems.random_system(4, 2, 2, seed=1)
    warm = systems.simulate_data(true, 2000, seed=3, output_snr_db=20)
    subid.moesp(warm)
    subid.moesp(warm, 4, horizon=10)
    sys.path.remove(path)
    return subid, {k: v for k, v in sys.modules.items() if k == "subid" or k.startswith("subid.")}


def main(argv):
    warnings.simplefilter("ignore")
    paths = argv[1:3]
    rounds = int(argv[3]) if len(argv) > 3 else 21
    sizes = [int(k) for k in argv[4].split(",")] if len(argv) > 4 else [1000, 10000]
    versions = [load(p) for p in paths]

    def use(k):
        sys.modules.update(versions[k][1])
        return versions[k][0]

    for n in sizes:
        sub = use(0)
        data = sub.systems.simulate_data(sub.systems.random_system(4, 2, 2, seed=1), n, seed=2,
                                         output_snr_db=20)
        t = {(k, c): [] for k in (0, 1) for c in ("default", "pinned")}
        for r in range(rounds):
            for k in ((0, 1) if r % 2 == 0 else (1, 0)):
                s = use(k)
                d = s.IOData(data.u, data.y, dt=data.dt)
                t0 = time.process_time()
                s.moesp(d)
                t1 = time.process_time()
                s.moesp(d, 4, horizon=10)
                t2 = time.process_time()
                t[(k, "default")].append(t1 - t0)
                t[(k, "pinned")].append(t2 - t1)
        med = {key: statistics.median(x) for key, x in t.items()}
        ratio = statistics.median(b / a for a, b in zip(t[(0, "default")], t[(1, "default")]))
        print(f"N={n}: default {med[(0, 'default')]:.4f} s -> {med[(1, 'default')]:.4f} s "
              f"(median paired ratio {ratio:.3f}); pinned {med[(0, 'pinned')]:.4f} s -> "
              f"{med[(1, 'pinned')]:.4f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
