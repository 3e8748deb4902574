"""Report time against the identification time it contains (issue 14 item 6).

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/demo_ratio.py [DATASET ...]

For each bundled dataset: wall time of :func:`subid.cli.demo.report_dataset`
(identification with every batch method + the HTML report with its figures)
against the sum of the identification times it records; target ratio <= 2.
"""

import sys
import tempfile
import time
import warnings


def main(names):
    warnings.simplefilter("ignore")
    from subid import datasets
    from subid.cli import demo
    names = names or datasets.names()
    out = tempfile.mkdtemp()
    print(f"{'dataset':14s} {'total s':>8s} {'ident s':>8s} {'ratio':>6s}")
    for name in names:
        t0 = time.perf_counter()
        r = demo.report_dataset(name, out)
        total = time.perf_counter() - t0
        ident = sum(row["seconds"] for row in r["rows"] if row.get("seconds"))
        print(f"{name:14s} {total:8.2f} {ident:8.2f} {total / ident:6.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
