"""Benchmark of the batch methods (``make bench``; never part of ``make test``).

Runs ``ls_subspace``, ``moesp`` and ``n4sid`` in one process on the same
generated data (a random stable 4th-order system with 2 inputs and 2
outputs, white input, noise-free, horizon 5) for growing record lengths,
and writes a Markdown table of median wall time over repeats, the ratio to
``n4sid`` in the same process, throughput and Markov error.

Run with one BLAS thread (the Makefile sets ``OPENBLAS_NUM_THREADS=1``):
threaded BLAS made timings erratic by up to 50x on the shared 2-core machines.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

import subid
from subid import systems

METHODS = {"ls_subspace": subid.ls_subspace, "moesp": subid.moesp, "n4sid": subid.n4sid}


def _median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"numpy {np.__version__}, OPENBLAS_NUM_THREADS={threads}")


ONLINE_SAMPLES = 200_000


def bench_recursive():
    """Samples per second of RecursiveSubspace (update only, model not requested)."""
    true = systems.seed001_system()
    data = systems.simulate_data(true, ONLINE_SAMPLES, seed=3)
    rows = []
    for instruments in ("past", None):
        subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments).update(
            data.u[:100], data.y[:100])                      # compile

        def run():
            rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments)
            for k in range(0, ONLINE_SAMPLES, 1000):
                rs.update(data.u[k:k + 1000], data.y[k:k + 1000])
            return rs

        seconds, _ = _median_time(run, 3)
        rows.append(f"| RecursiveSubspace, instruments={instruments!r} | seed 001 (n=3, 2x2), "
                    f"horizon 5 | {ONLINE_SAMPLES / seconds:,.0f} |")
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Benchmark subid's batch methods.")
    parser.add_argument("--sizes", default="1000,10000,100000,1000000",
                        help="comma-separated record lengths")
    parser.add_argument("--horizon", type=int, default=5)
    parser.add_argument("--out", default="bench/results.md")
    args = parser.parse_args(argv)
    true = systems.random_system(4, 2, 2, seed=1)
    warm = systems.simulate_data(true, 500, seed=0)
    for fn in METHODS.values():          # compile kernels before timing
        fn(warm, 4, horizon=args.horizon)
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        data = systems.simulate_data(true, n, seed=2)
        repeats = 7 if n <= 10_000 else 3 if n <= 100_000 else 1
        res = {}
        for name, fn in METHODS.items():
            seconds, model = _median_time(lambda: fn(data, 4, horizon=args.horizon), repeats)
            res[name] = (seconds, subid.markov_error(model, true))
        base = res["n4sid"][0]
        for name, (seconds, err) in res.items():
            rows.append(f"| {n:,} | {name} | {seconds * 1e3:.1f} | {seconds / base:.2f} | "
                        f"{n / seconds / 1e6:.2f} | {err:.1e} | {repeats} |")
        print(f"N={n:,} done", flush=True)
    online = bench_recursive()
    print("online done", flush=True)
    table = "\n".join([
        f"Machine: {machine()}. System: random stable, order 4, 2 inputs, 2 outputs, "
        f"noise-free white input; horizon {args.horizon}. Median of the repeats.",
        "",
        "| N | method | median time (ms) | time / n4sid | Msamples/s | Markov error | repeats |",
        "|---:|---|---:|---:|---:|---:|---:|",
        *rows,
        "",
        "Online identifiers, samples per second on one core (median of 3 runs over "
        f"{ONLINE_SAMPLES:,} samples, chunks of 1000):",
        "",
        "| identifier | system | samples/s |",
        "|---|---|---:|",
        *online])
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
