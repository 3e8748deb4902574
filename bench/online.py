"""Benchmark of the online identifier of seed 000 (``AdaptiveIdentifier``).

Throughput in samples per second on the paper's system (4 states, 2 inputs,
2 outputs, horizon 5, sampled every 1 ms, noise-free multisine input), for

* the compiled kernel, the whole record in one ``update`` call,
* the compiled kernel, the record streamed in chunks of 1000 samples,
* one sample per ``update`` call (Python overhead per call),
* the plain numpy reference loop (``engine='numpy'``), on a shorter record.

Wall-clock medians over repeats, numba compilation excluded (a warm-up run
comes first). Run with one BLAS thread: ``OPENBLAS_NUM_THREADS=1 python
bench/online.py``. :func:`bench_adaptive` is called by ``bench/run.py``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from subid.experiments.seed000 import simulate
from subid.methods.online.adaptive import AdaptiveIdentifier


def _new(engine="numba", method="iv"):
    return AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0, dt=1e-3, engine=engine,
                              method=method)


def _median_rate(run, n, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        times.append(time.perf_counter() - t0)
    return n / statistics.median(times), times


def bench_adaptive(n_samples: int = 1_000_000, repeats: int = 5, reference_samples: int = 20_000,
                   single_samples: int = 20_000) -> dict:
    """Samples per second of :class:`AdaptiveIdentifier` (median of repeats).

    Returns
    -------
    dict
        ``numba`` (one call), ``numba_chunks_1000``, ``numba_single_sample``
        and ``numpy`` (reference loop) in samples/s, ``speedup`` (numba one
        call / numpy), the sample counts and repeats, and ``machine``.
    """
    _, u, y = simulate(n_samples * 1e-3)
    u, y = u[:n_samples], y[:n_samples]
    _new().update(u[:5000], y[:5000])               # compile / load the kernel cache

    def whole():
        _new().update(u, y)

    def chunks():
        ident = _new()
        for a in range(0, n_samples, 1000):
            ident.update(u[a:a + 1000], y[a:a + 1000])

    ns = min(single_samples, n_samples)

    def single():
        ident = _new()
        for k in range(ns):
            ident.update(u[k], y[k])

    nr = min(reference_samples, n_samples)

    def reference():
        _new("numpy").update(u[:nr], y[:nr])

    out = {"n_samples": n_samples, "repeats": repeats, "reference_samples": nr,
           "single_samples": ns, "machine": machine()}
    out["numba"], _ = _median_rate(whole, n_samples, repeats)

    def whole_ls():
        _new(method="ls").update(u, y)

    _new(method="ls").update(u[:5000], y[:5000])
    # the paper's least squares (the default before issue 12), same process
    out["numba_ls"], _ = _median_rate(whole_ls, n_samples, repeats)
    out["numba_chunks_1000"], _ = _median_rate(chunks, n_samples, repeats)
    out["numba_single_sample"], _ = _median_rate(single, ns, max(1, repeats // 2))
    out["numpy"], _ = _median_rate(reference, nr, max(1, repeats // 2))
    out["speedup"] = out["numba"] / out["numpy"]
    return out


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
    try:
        load = "load average %.1f" % os.getloadavg()[0]
    except OSError:
        load = "load unknown"
    return (f"{cpu}, {os.cpu_count()} cores ({load}), Python {platform.python_version()}, "
            f"numpy {np.__version__}, OPENBLAS_NUM_THREADS={threads}")


def table(res: dict) -> str:
    rows = [
        ("numba kernel, one update call (default method='iv')", res["numba"],
         res["n_samples"]),
        ("numba kernel, one update call, method='ls'", res["numba_ls"], res["n_samples"]),
        ("numba kernel, chunks of 1000 samples", res["numba_chunks_1000"], res["n_samples"]),
        ("numba kernel, one sample per update call", res["numba_single_sample"],
         res["single_samples"]),
        ("numpy reference loop", res["numpy"], res["reference_samples"]),
    ]
    lines = [
        f"AdaptiveIdentifier (seed 000) on the paper's system: 4 states, 2 inputs, 2 outputs, "
        f"horizon 5, dt = 1 ms, refresh every 50 samples. Machine: {res['machine']}. "
        f"Wall-clock median of {res['repeats']} repeats (numba compilation excluded).",
        "",
        "| variant | samples | samples/s | µs/sample |",
        "|---|---:|---:|---:|",
    ]
    for name, rate, n in rows:
        lines.append(f"| {name} | {n:,} | {rate:,.0f} | {1e6 / rate:.2f} |")
    lines.append("")
    lines.append(f"Speed-up of the kernel over the numpy reference: {res['speedup']:.0f}x.")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Benchmark subid's AdaptiveIdentifier.")
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="bench/online.md")
    args = parser.parse_args(argv)
    text = table(bench_adaptive(args.samples, args.repeats))
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
