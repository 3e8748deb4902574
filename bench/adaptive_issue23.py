"""Throughput of ``AdaptiveIdentifier`` before and after issue 23, in one process.

Issue 23 added to the kernel a start-up schedule of the (B, D) memory (one
``exp`` per sample of part 2) and a persistent-excitation test of (8) at each
refresh (inverse iteration on the Cholesky factor of the solve). This script
runs the identifier with the current kernel and with the kernel of the commit
before issue 23 (``git show <rev>:src/subid/methods/online/_adaptive_kernel.py``,
written to a temporary module), interleaved, on the paper's system (1 ms,
multisine, defaults), streamed in chunks of 1000 samples, and writes the
medians and their ratio to ``bench/adaptive_issue23.md``.

The previous kernel reads the same state buffers: the arrays it knows keep
their places, the slots added since are at the ends of ``fst``/``ist``/``par``.

Run: ``OPENBLAS_NUM_THREADS=1 python bench/adaptive_issue23.py [--rev main]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import subid.methods.online.adaptive as adaptive
from subid.experiments.seed000 import simulate
from subid.io._files import write_bytes


def previous_kernel(rev: str):
    """The kernel module of ``rev``, imported under another name."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    source = subprocess.run(["git", "-C", root, "show",
                             f"{rev}:src/subid/methods/online/_adaptive_kernel.py"],
                            check=True, capture_output=True, text=True).stdout
    folder = tempfile.mkdtemp(prefix="subid_kernel_")
    path = os.path.join(folder, "_adaptive_kernel_previous.py")
    write_bytes(path, source)
    spec = importlib.util.spec_from_file_location("_adaptive_kernel_previous", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(u, y, kernel, chunk=1000) -> float:
    """Seconds to stream (u, y) through a default identifier with ``kernel``."""
    current = adaptive._k
    adaptive._k = kernel
    try:
        ident = adaptive.AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-3)
        t0 = time.perf_counter()
        for a in range(0, u.shape[0], chunk):
            ident.update(u[a:a + chunk], y[a:a + chunk])
        return time.perf_counter() - t0
    finally:
        adaptive._k = current


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="main", help="revision of the previous kernel")
    parser.add_argument("--samples", type=int, default=300_000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "adaptive_issue23.md"))
    args = parser.parse_args(argv)
    _, u, y = simulate(args.samples * 1e-3)
    u, y = u[:args.samples], y[:args.samples]
    kernels = {"previous": previous_kernel(args.rev), "current": adaptive._k}
    for k in kernels.values():               # compile / load the caches
        run(u[:5000], y[:5000], k)
    times = {name: [] for name in kernels}
    for _ in range(args.repeats):            # interleaved
        for name, k in kernels.items():
            times[name].append(run(u, y, k))
    rate = {name: args.samples / statistics.median(v) for name, v in times.items()}
    ratios = [p / c for p, c in zip(times["previous"], times["current"])]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    text = "\n".join([
        "# AdaptiveIdentifier throughput, issue 23 against the previous kernel",
        "",
        f"Paper's system, 1 ms, multisine, defaults (`method='iv'`), {args.samples:,} samples "
        f"in chunks of 1000, {args.repeats} interleaved repeats, medians; previous kernel: "
        f"`{args.rev}`. {platform.processor() or platform.machine()}, Python "
        f"{sys.version.split()[0]}, numpy {np.__version__}, load average {load:.1f}.",
        "",
        "| kernel | samples/s | µs/sample |",
        "|---|---:|---:|",
        *(f"| {name} | {r:,.0f} | {1e6 / r:.2f} |" for name, r in rate.items()),
        "",
        f"Ratio current / previous: {rate['current'] / rate['previous']:.2f} (median of the "
        f"per-repeat ratios {statistics.median(ratios):.2f}, range {min(ratios):.2f}-"
        f"{max(ratios):.2f}).",
        ""])
    write_bytes(args.out, text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
