"""CPU seconds of the demo's report of each dataset, on models identified once (issue 29).

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/demo_reports.py --models DIR
     [--repeat R] [DATASET ...]

The first run identifies every dataset with the demo's methods (``demo.evaluate``) and
pickles the rows and models into ``DIR``; later runs load them, so that two trees (say
``PYTHONPATH=/path/to/main/src`` and this one) write the reports of the same models. Each
report (``demo.write_report``) is timed with ``time.process_time`` after a warm-up report
(imports, numba kernels); prints one line per dataset, the sum and the load average.
"""

import argparse
import os
import pickle
import sys
import tempfile
import time
import warnings


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="*")
    parser.add_argument("--models", required=True, help="folder of the pickled models")
    parser.add_argument("--repeat", type=int, default=1,
                        help="write each report this many times, keep the fastest")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    from subid import datasets
    from subid.cli import demo
    os.makedirs(args.models, exist_ok=True)
    out = tempfile.mkdtemp()
    total, warm = 0.0, False
    for name in args.datasets or datasets.names():
        path = os.path.join(args.models, f"{name}.pkl")
        if os.path.exists(path):
            with open(path, "rb") as f:
                rows, models = pickle.load(f)
        else:
            rows, models, _, _ = demo.evaluate(name)
            with open(path, "wb") as f:
                pickle.dump((rows, models), f)
        if not warm:
            demo.write_report(name, out, rows, models)
            warm = True
        seconds = float("inf")
        for _ in range(max(1, args.repeat)):
            c0 = time.process_time()
            demo.write_report(name, out, rows, models)
            seconds = min(seconds, time.process_time() - c0)
        total += seconds
        print(f"| {name} | {seconds:.2f} |", flush=True)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f"| **sum** | **{total:.1f}** |\n\nload average {load}", file=sys.stdout)


if __name__ == "__main__":
    main()
