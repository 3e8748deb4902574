"""The comparison of ``bench/realdata.py`` on records the package does not bundle.

The same protocol and scoring as ``bench/realdata.py`` (first 2/3 to estimate with its
means removed, last 1/3 to validate, or a given estimation/validation pair; simulation
fit with x0 by least squares; SIPPY's and least-squares ARX's best orders on the
validation data as oracles), on files given on the command line: a whitespace-separated
table (DaISy's ``.dat``) or a CSV, with the columns of the inputs and outputs named
(0-based column numbers for ``.dat``, header names for CSV)::

    python bench/external_records.py heating_system.dat --inputs 1 --outputs 2 --dt 2
    python bench/external_records.py dataBenchmark.csv --inputs uEst --outputs yEst \\
        --validation-inputs uVal --validation-outputs yVal --dt 4

SIPPY's grid runs when ``sippy_unipi`` is importable (the benchmark venv). Nothing is
downloaded: the files are the user's (bench/external_records.md says where the records
measured there come from).
"""

from __future__ import annotations

import argparse
import csv
import warnings

import numpy as np

import subid
from realdata import arx_grid, subid_defaults


def _columns(path, names):
    if path.endswith(".csv"):
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
        header = [h.strip() for h in rows[0]]
        index = [header.index(n) for n in names]
        body = [r for r in rows[1:] if len(r) > max(index) and all(r[i].strip() for i in index)]
        return np.array([[float(r[i]) for i in index] for r in body])
    table = np.loadtxt(path)
    return table[:, [int(n) for n in names]]


def records(args):
    u = _columns(args.file, args.inputs)
    y = _columns(args.file, args.outputs)
    if args.validation_inputs:
        u_val = _columns(args.file, args.validation_inputs)
        y_val = _columns(args.file, args.validation_outputs)
        cut = None
    else:
        cut = (2 * len(u)) // 3
        u, u_val, y, y_val = u[:cut], u[cut:], y[:cut], y[cut:]
    mu, my = u.mean(axis=0), y.mean(axis=0)
    est = subid.IOData(u - mu, y - my, dt=args.dt)
    val = subid.IOData(u_val - mu, y_val - my, dt=args.dt)
    return est, val


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("--inputs", nargs="+", required=True)
    parser.add_argument("--outputs", nargs="+", required=True)
    parser.add_argument("--validation-inputs", nargs="+")
    parser.add_argument("--validation-outputs", nargs="+")
    parser.add_argument("--dt", type=float, default=1.0)
    args = parser.parse_args(argv)
    est, val = records(args)
    print(f"{args.file}: {est.n_samples} estimation and {val.n_samples} validation samples")
    arx = arx_grid(est, val)
    best = max((v, k) for k, v in arx.items() if v is not None)
    print(f"ARX oracle {best[0]:.1f} ({best[1]})")
    try:
        from realdata import sippy_grid
        grid = sippy_grid(args.file, est, val)
        top = max((v, k) for k, v in grid.items() if v is not None)
        print(f"SIPPY oracle {top[0]:.1f} ({top[1]})")
    except ImportError:
        print("SIPPY oracle: sippy_unipi not installed (run in the benchmark venv)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = subid_defaults(est, val)
    for label, row in rows.items():
        print(f"{label:12s} {row['fit']:6.1f}  (n={row['order']}, f={row['horizon']}, "
              f"{row['seconds']:.2f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
