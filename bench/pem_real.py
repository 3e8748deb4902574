"""Benchmark: does ``subid.pem`` improve the default model on the bundled real records?

For every bundled DaISy record (uniformly sampled): the first 2/3 is the
estimation part, the last 1/3 the validation part, both with the estimation
means removed. The default model ``ls_subspace(est)`` (order chosen
automatically) is refined by ``pem(est, model)`` with each focus. The table
gives the validation fit % (mean over the outputs) of the simulation
(``fit_percent``) and of the one-step prediction (``fit_percent(steps=1)``).

Run: ``OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/pem_real.py``.
"""

from __future__ import annotations

import statistics
import sys
import time
import warnings

import numpy as np

import subid
from subid.data import IOData


def split(name):
    data = subid.datasets.load(name)
    n = data.n_samples
    cut = (2 * n) // 3
    u_mean = data.u[:cut].mean(axis=0)
    y_mean = data.y[:cut].mean(axis=0)
    kw = dict(dt=data.dt, input_names=data.input_names, output_names=data.output_names)
    est = IOData(data.u[:cut] - u_mean, data.y[:cut] - y_mean, **kw)
    val = IOData(data.u[cut:] - u_mean, data.y[cut:] - y_mean, **kw)
    return est, val


def fits(model, val):
    sim = float(np.mean(subid.fit_percent(model, val)))
    one = float(np.mean(subid.fit_percent(model, val, steps=1)))
    return sim, one


def main(names=None):
    names = names or subid.datasets.names()
    rows = []
    for name in names:
        est, val = split(name)
        if not est.is_uniform:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = subid.ls_subspace(est)
            row = {"dataset": name, "order": start.order, "n": est.n_samples}
            row["default"] = fits(start, val)
            for focus in ("prediction", "simulation"):
                t0 = time.perf_counter()
                try:
                    refined = subid.pem(est, start, focus=focus)
                    row[focus] = fits(refined, val)
                    row[focus + "_stop"] = refined.info["stop_reason"]
                except subid.errors.SubidError as exc:
                    row[focus] = (float("nan"), float("nan"))
                    row[focus + "_stop"] = f"error: {exc}"
                row[focus + "_s"] = time.perf_counter() - t0
        rows.append(row)
        print(name, row, file=sys.stderr, flush=True)
    print("| dataset | order | default: sim / 1-step | pem prediction: sim / 1-step | "
          "pem simulation: sim / 1-step | pem time (s) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        cell = lambda v: f"{v[0]:.1f} / {v[1]:.1f}"  # noqa: E731
        print(f"| {r['dataset']} | {r['order']} | {cell(r['default'])} | {cell(r['prediction'])}"
              f" | {cell(r['simulation'])} | {r['prediction_s']:.1f} + {r['simulation_s']:.1f} |")
    for key in ("default", "prediction", "simulation"):
        sim = statistics.median(r[key][0] for r in rows if np.isfinite(r[key][0]))
        one = statistics.median(r[key][1] for r in rows if np.isfinite(r[key][1]))
        print(f"median {key}: simulation fit {sim:.1f} %, one-step fit {one:.1f} %")


if __name__ == "__main__":
    main(sys.argv[1:] or None)
