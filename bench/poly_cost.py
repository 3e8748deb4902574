"""CPU of the demo's ``arx`` and ``pbsid`` default calls: the cheap paths against the
computations they replaced, interleaved in one process (issue 29).

The reference paths are those of the tree before the change, selected by
monkeypatching: ``arx``'s structure search with one ``fit_arx`` (a QR of the
whole training record per output) per structure and fold and the dense scoring
pass (``_scoring.forced_error``); ``pbsid``'s step 1 with one least squares per
future step (``step_coefficients_reference``). The calls are the demo's
(:func:`subid.cli.demo.identify_one`: means removed, the first 70 % of the
record); every call is timed by ``time.process_time``, the two paths alternated
``--repeat`` times; the table gives medians and their ratio. The validation
block's scoring data are shared across the candidates in both paths (the tree
before the change recomputed them per candidate: a few milliseconds a
structure), so the ratio slightly understates the change.

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/poly_cost.py [RECORD ...]
     [--methods arx,pbsid] [--repeat 5] [--out bench/poly_cost.md]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys
import time
import warnings


@contextlib.contextmanager
def reference_paths():
    """The computations the cheap paths replaced, patched in."""
    from subid.methods.dt import _scoring, pbsid, polynomial

    class PerStructure:
        def __init__(self, data, nk, max_na, max_nb):
            self.data = data

        def fit(self, orders, method="arx"):
            return polynomial.fit_arx(self.data, orders, check=False)[:2]

    saved = (polynomial.NestedARX, polynomial.sparse_forced_error, pbsid.step_coefficients)
    polynomial.NestedARX = PerStructure
    polynomial.sparse_forced_error = _scoring.forced_error
    pbsid.step_coefficients = pbsid.step_coefficients_reference
    try:
        yield
    finally:
        polynomial.NestedARX, polynomial.sparse_forced_error, pbsid.step_coefficients = saved


def timed(name, method):
    from subid.cli import demo
    c0 = time.process_time()
    row, model = demo.identify_one(name, method)
    return time.process_time() - c0, model


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="*")
    parser.add_argument("--methods", default="arx,pbsid")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    from subid import datasets
    names = args.datasets or list(datasets.names())
    methods = args.methods.split(",")
    timed("dryer", "n4sid")                       # imports and compiled kernels loaded
    for method in methods:
        timed("dryer", method)
        with reference_paths():
            timed("dryer", method)
    table = {}
    for name in names:
        for method in methods:
            fast, ref = [], []
            for _ in range(args.repeat):
                seconds, model = timed(name, method)
                fast.append(seconds)
                with reference_paths():
                    seconds, model_ref = timed(name, method)
                ref.append(seconds)
            assert model.order == model_ref.order
            table[(name, method)] = (statistics.median(ref), statistics.median(fast))
            r, f = table[(name, method)]
            print(f"{name:14s} {method:6s} {r:6.2f} -> {f:6.2f} s ({f / r:.2f})",
                  file=sys.stderr, flush=True)
    lines = ["# CPU of the arx and pbsid default calls (bench/poly_cost.py)", "",
             f"Median CPU seconds (time.process_time) of {args.repeat} calls per path, the "
             "two paths alternated in one process, OPENBLAS_NUM_THREADS=1, load average "
             f"{os.getloadavg()[1]:.1f} on {os.cpu_count()} CPUs at the end. Reference: "
             "the computations the cheap paths replaced (module docstring).", "",
             "| record | method | reference s | now s | ratio |", "|---|---|---:|---:|---:|"]
    sums = {}
    for (name, method), (r, f) in table.items():
        lines.append(f"| {name} | {method} | {r:.2f} | {f:.2f} | {f / r:.2f} |")
        a, b = sums.get(method, (0.0, 0.0))
        sums[method] = (a + r, b + f)
    for method, (r, f) in sums.items():
        lines.append(f"| **sum** | {method} | **{r:.2f}** | **{f:.2f}** | **{f / r:.2f}** |")
    text = "\n".join(lines) + "\n"
    if args.out:
        with open(args.out, "w") as fh:   # noqa: SIM115 - the benchmark's table
            fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
