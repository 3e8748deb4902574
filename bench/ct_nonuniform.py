"""Benchmark: ``ct_subspace`` on non-uniform against uniform time grids (issue 14, item 3).

The paper's example (seed 002, :func:`subid.experiments.seed002.simulate`),
noise-free by default, on a uniform grid and on a grid with +/-40 % jitter
of every sampling instant, at L = 400, 4000, 40000. Three timed cases per L,
interleaved in one process (ratios taken inside the process):

* ``uniform``: the default call on the uniform grid, with ``start='subspace'``
  (issue 22: by default a uniform grid also tries the converted N4SID models,
  which a non-uniform grid cannot; and ``refine=True`` on both grids, which
  ``refine='auto'`` decides per record by cross-validation: the same work on
  both grids is compared);
* ``jittered``: the default call on the jittered grid (fused block-modal
  kernels of :mod:`subid.methods.ct._ct_kernels`);
* ``jittered, tables``: the same with the modal kernels disabled (the
  per-interval tables: eigen-decomposition or matrix exponentials per
  interval), the code before issue 14 (``--no-reference`` skips it).

Besides the whole call, one sensitivity evaluation (the regressors of B and
x0 for the true model; the refinement does one per Levenberg-Marquardt
residual) and one bank filtering are timed per interval: the whole call's
ratio also depends on how many refinement evaluations each record takes.

CPU time of this process (``time.process_time``), median over repeats,
after a warm-up run that compiles the numba kernels. Run with one BLAS
thread::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/ct_nonuniform.py
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from online import machine  # bench/ helpers


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[400, 4000, 40000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--snr", type=float, default=None, help="output SNR in dB (default "
                        "noise-free)")
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the per-interval-table reference")
    args = parser.parse_args(argv)

    from subid.experiments.seed002 import paper_system, simulate
    from subid.methods.ct import _ct_kernels
    from subid.methods.ct.basis import default_basis
    from subid.methods.ct.ct_subspace import ct_subspace

    modal = (_ct_kernels.modal_bank, _ct_kernels.modal_sensitivity)

    def tables(on):
        if on:
            _ct_kernels.modal_bank = lambda *a, **k: None
            _ct_kernels.modal_sensitivity = lambda *a, **k: None
        else:
            _ct_kernels.modal_bank, _ct_kernels.modal_sensitivity = modal

    true = paper_system()
    w = np.logspace(-2, 2, 200)
    print(f"# ct_subspace, non-uniform vs uniform grid\n\n{machine()}; CPU seconds, "
          f"median of {args.repeats}; noise "
          f"{'none' if args.snr is None else f'{args.snr:g} dB'}\n")
    # warm-up: compile every kernel
    for jitter in (0.0, 0.4):
        ct_subspace(simulate(300, 0, jitter=jitter)[0], 4)

    rows = []
    for L in args.sizes:
        du = simulate(L, 11, snr_db=args.snr)[0]
        dj = simulate(L, 11, jitter=0.4, snr_db=args.snr)[0]
        cases = {"uniform": (du, False), "jittered": (dj, False)}
        if not args.no_reference:
            cases["jittered, tables"] = (dj, True)
        times = {k: [] for k in cases}
        models = {}
        for _ in range(args.repeats):
            for name, (data, ref) in cases.items():
                tables(ref)
                try:
                    dt, models[name] = _cpu(lambda data=data: ct_subspace(
                        data, 4, start="subspace", refine=True))
                finally:
                    tables(False)
                times[name].append(dt)
        # kernel level: one sensitivity evaluation and one filtering, per interval
        bank = default_basis(dj.t)
        F, g = bank.realization()
        kern = {}
        for name, (data, ref) in cases.items():
            uniform = data.is_uniform
            tables(ref)
            try:
                ts, tb = [], []
                for _ in range(args.repeats):
                    ts.append(_cpu(lambda d=data, un=uniform: _ct_kernels.run_sensitivity(
                        true.A, true.C, d.t, d.u, 1, uniform=un))[0])
                    tb.append(_cpu(lambda d=data, un=uniform, F=F, g=g: _ct_kernels.run_bank(
                        F, g, d.t, d.y, 3, uniform=un))[0])
            finally:
                tables(False)
            kern[name] = (statistics.median(ts) / (L - 1) * 1e6,
                          statistics.median(tb) / (L - 1) * 1e6)
        med = {k: statistics.median(v) for k, v in times.items()}
        gref = true.freqresp(w)
        for name in cases:
            m = models[name]
            err = float(np.abs(m.freqresp(w) - gref).max() / np.abs(gref).max())
            diff = ""
            if name == "jittered" and "jittered, tables" in models:
                gt = models["jittered, tables"].freqresp(w)
                diff = "%.1e" % (np.abs(m.freqresp(w) - gt).max() / np.abs(gt).max())
            rows.append((L, name, med[name], med[name] / med["uniform"],
                         m.info.get("refine_evaluations", 0), kern[name][0], kern[name][1],
                         err, diff))

    print("| L | grid | ct_subspace s | / uniform | LM evaluations | sensitivity us/interval "
          "| filter (N=8, p=3) us/interval | max rel. error vs true G | vs tables |")
    print("|---|---|---|---|---|---|---|---|---|")
    for L, name, t, ratio, nfev, ks, kb, err, diff in rows:
        print(f"| {L} | {name} | {t:.3f} | {ratio:.2f} | {nfev} | {ks:.2f} | {kb:.2f} "
              f"| {err:.1e} | {diff} |")


if __name__ == "__main__":
    main()
