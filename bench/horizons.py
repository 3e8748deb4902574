"""Default calls on oversampled records: the horizons past 20 (issue 21).

A 2x2 continuous-time system of order 4 (an oscillation at 2 rad/s damped at 0.5/s,
and real poles at -0.2 and -1.0 /s; B and C drawn with seed 1), sampled at ``dt`` =
0.1, 0.02 and 0.005 s (about 50, 250 and 1,000 samples per time constant of the
slowest pole), inputs held for 50 samples (random steps), 5 % output noise,
N = 20,000 samples: the first 70 % to estimate, the rest to validate (simulation
fit %, mean over the outputs, x0 by least squares). Each default call
(``moesp``, ``n4sid``, ``ls_subspace``, ``identify``) is run with the horizon
search of before (horizons 10 and 20 only: ``crossval.MAX_HORIZON = 20``) and
with today's (doubling past 20 while the response to the inputs lasts beyond the horizon,
:func:`subid.methods.crossval.longer_horizon`); CPU seconds of each call.

Usage::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/horizons.py [--out bench/horizons.md]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import subid
from subid.methods import crossval

METHODS = ("moesp", "n4sid", "ls_subspace", "identify")


def record(dt, seed=1, n_samples=20_000):
    """The oversampled record of the module docstring, as (estimation, validation)."""
    rng = np.random.default_rng(seed)
    A = np.array([[-0.5, 2.0, 0, 0], [-2.0, -0.5, 0, 0], [0, 0, -0.2, 0], [0, 0, 0, -1.0]])
    B, C = rng.standard_normal((4, 2)), rng.standard_normal((2, 4))
    plant = subid.StateSpace(A, B, C, np.zeros((2, 2)), 0).to_discrete(dt)
    u = np.repeat(rng.standard_normal((n_samples // 50, 2)), 50, axis=0)
    y = plant.simulate(u)
    y = y + 0.05 * y.std(axis=0) * rng.standard_normal(y.shape)
    return subid.IOData(u, y, dt=dt).split(0.7)


def run(method, est, val):
    t0 = time.process_time()
    model = getattr(subid, method)(est)
    seconds = time.process_time() - t0
    fit = float(np.mean(subid.fit_percent(model, val)))
    return model.order, model.info.get("horizon"), fit, seconds


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    rows = []
    today = crossval.MAX_HORIZON
    for dt in (0.1, 0.02, 0.005):
        est, val = record(dt)
        memory = crossval.response_memory(est, 20)
        for method in METHODS:
            crossval.MAX_HORIZON = 20                  # the search of before
            before = run(method, est, val)
            crossval.MAX_HORIZON = today
            after = run(method, est, val)
            rows.append((dt, memory, method, before, after))
            print(dt, method, before, after, flush=True)
    lines = ["# Default calls on oversampled records (bench/horizons.py)", "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             "| dt (s) | response memory at 20 | method | before: n, f, fit %, CPU s | "
             "now: n, f, fit %, CPU s |", "|---:|---:|---|---|---|"]
    for dt, memory, method, b, a in rows:
        lines.append(f"| {dt} | {memory:.2f} | {method} | {b[0]}, {b[1]}, {b[2]:.1f}, "
                     f"{b[3]:.2f} | {a[0]}, {a[1]}, **{a[2]:.1f}**, {a[3]:.2f} |")
    text = "\n".join(lines) + "\n"
    if args.out:
        with open(args.out, "w") as f:   # noqa: SIM115 - the benchmark's table
            f.write(text)
    print(text)


if __name__ == "__main__":
    main()
