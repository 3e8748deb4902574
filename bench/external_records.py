"""The comparison of ``bench/realdata.py`` on records the package does not bundle.

The same protocol and scoring as ``bench/realdata.py`` (first 2/3 to estimate with its
means removed, last 1/3 to validate, or a given estimation/validation pair; simulation
fit with x0 by least squares; SIPPY's and least-squares ARX's best orders on the
validation data as oracles), on files given on the command line: a whitespace-separated
table (DaISy's ``.dat``) or a CSV, with the columns of the inputs and outputs named
(0-based column numbers for a file without a header, names otherwise), read by
``subid.read``::

    python bench/external_records.py heating_system.dat --inputs 1 --outputs 2 --dt 2
    python bench/external_records.py dataBenchmark.csv --inputs uEst --outputs yEst \\
        --validation-inputs uVal --validation-outputs yVal --dt 4
    python bench/external_records.py RLC_id.csv --validation-file RLC_val.csv \\
        --inputs V_IN --outputs I_L --dt 5e-7

SIPPY's grid runs when ``sippy_unipi`` is importable (the benchmark venv). Nothing is
downloaded: the files are the user's (bench/external_records.md says where the records
measured there come from).
"""

from __future__ import annotations

import argparse
import warnings

import subid
from realdata import arx_grid, subid_defaults


def _names(values):
    """Column names, or 0-based column numbers for a file without a header."""
    return [int(v) if v.isdigit() else v for v in values]


def records(args):
    """The estimation and validation records (``subid.read``), estimation means removed."""
    est = subid.read(args.file, inputs=_names(args.inputs), outputs=_names(args.outputs),
                     dt=args.dt)
    if args.validation_file:
        val = subid.read(args.validation_file, inputs=_names(args.inputs),
                         outputs=_names(args.outputs), dt=args.dt)
    elif args.validation_inputs:
        val = subid.read(args.file, inputs=_names(args.validation_inputs),
                         outputs=_names(args.validation_outputs), dt=args.dt)
    else:
        cut = (2 * est.n_samples) // 3
        est, val = est[:cut], est[cut:]
    mu, my = est.u.mean(axis=0), est.y.mean(axis=0)
    return (subid.IOData(est.u - mu, est.y - my, dt=args.dt),
            subid.IOData(val.u - mu, val.y - my, dt=args.dt))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("--inputs", nargs="+", required=True)
    parser.add_argument("--outputs", nargs="+", required=True)
    parser.add_argument("--validation-inputs", nargs="+")
    parser.add_argument("--validation-outputs", nargs="+")
    parser.add_argument("--validation-file",
                        help="a second file of the same columns to validate on")
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
