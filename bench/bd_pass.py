"""Cost of the default B, D, x0 regression against the statistic-only path (issue 14.1).

The default ``moesp(data, 4, horizon=10)`` and ``ls_subspace(data, 4, horizon=10)``
against the same calls with ``bd_method='projection'`` (the statistic only), on
a random stable system with 2 inputs and 2 outputs, white input, 30 dB output
noise. Medians over repeats, all in one process; the ratios are the figures to
read (the machines are shared). Also the regression pass alone: the modal
normal equations against the QR reference path, with their largest relative
differences in B, D and x0.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/bd_pass.py --samples 10000000
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np


def _median(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--qr", action="store_true", help="also time the QR reference path")
    args = parser.parse_args(argv)
    import subid
    from subid import systems
    from subid.methods.dt._regression import fit_b_d_x0_modal, fit_b_d_x0_qr
    from subid.methods.dt._subspace import output_weights

    if os.environ.get("OPENBLAS_NUM_THREADS") != "1":
        print("warning: OPENBLAS_NUM_THREADS is not 1")
    true = systems.random_system(4, 2, 2, seed=1)
    data = systems.simulate_data(true, args.samples, seed=2, output_snr_db=30)
    small = systems.simulate_data(true, 5_000, seed=2, output_snr_db=30)
    subid.moesp(small, 4, horizon=10)            # compile the kernels outside the timing
    print(f"N = {args.samples}, medians of {args.repeats}, one process")
    print("| method | default (s) | statistic only (s) | ratio |")
    print("|---|---:|---:|---:|")
    for name, fn in (("moesp", subid.moesp), ("ls_subspace", subid.ls_subspace)):
        default = _median(lambda fn=fn: fn(data, 4, horizon=10), args.repeats)
        proj = _median(lambda fn=fn: fn(data, 4, horizon=10, bd_method="projection"), args.repeats)
        print(f"| {name} | {default:.2f} | {proj:.2f} | {default / proj:.2f} |")
    w = output_weights(data.y)
    modal = _median(lambda: fit_b_d_x0_modal(true.A, true.C, data.u, data.y,
                                             output_weights=w), args.repeats)
    print(f"\nregression pass alone, modal: {modal:.2f} s "
          f"({modal / args.samples * 1e9:.0f} ns/sample)")
    if args.qr:
        qr = _median(lambda: fit_b_d_x0_qr(true.A, true.C, data.u, data.y, output_weights=w),
                     1)
        a = fit_b_d_x0_modal(true.A, true.C, data.u, data.y, output_weights=w)
        b = fit_b_d_x0_qr(true.A, true.C, data.u, data.y, output_weights=w)
        rel = [float(np.abs(x - z).max() / np.abs(z).max()) for x, z in zip(a[:3], b[:3])]
        print(f"regression pass alone, QR (1 run): {qr:.2f} s; speed-up {qr / modal:.1f}x; "
              f"relative differences B {rel[0]:.1e}, D {rel[1]:.1e}, x0 {rel[2]:.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
