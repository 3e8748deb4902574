"""Large-CSV reading: subid.read / read_chunks / identify_file against the
parsers they use, and the peak memory of the in-memory and streamed CLI.

Run from the repository root:

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/csv_io.py --rows 1000000 --repeat 3

Wall times (one BLAS thread; pyarrow with use_threads=False unless marked),
medians of ``--repeat`` runs taken round-robin, ratios taken in this one
process; also the CPU time of the process (all threads: subid's parser and
pass threads), which does not depend on whether the other cores are free. Peak memory
is the maximum resident set of a child process (``/usr/bin/time -v``) minus
that of a child that only imports subid and warms up, against the size of
the record's selected columns in doubles. The file is generated (4 columns,
%.8g, about 52 bytes a row like the 520 MB file of issue 14) and deleted.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import subid
import subid.io.fast_csv as sio
import subid.io.text as stext


def _interleaved(steps, repeat):
    """``{name: (median wall s, median CPU s)}`` of the callables ``steps``
    (``{name: (function, repeat or None)}``), timed round-robin: repeat ``k``
    of every step runs before repeat ``k + 1`` of any, so a change of load on
    this shared machine hits every step alike. CPU time is the process's (all
    its threads), which does not depend on whether other cores are free."""
    times = {name: [] for name in steps}
    for k in range(repeat):
        for name, (fn, reps) in steps.items():
            if k >= (reps or repeat):
                continue
            start, start_cpu = time.perf_counter(), time.process_time()
            fn()
            times[name].append((time.perf_counter() - start, time.process_time() - start_cpu))
    return {name: (statistics.median(w for w, _ in t), statistics.median(c for _, c in t))
            for name, t in times.items()}


def _make(path, rows):
    rng = np.random.default_rng(0)
    system = subid.systems.seed001_system()
    block = 200_000
    with open(path, "w") as fh:
        fh.write("u1,u2,y1,y2\n")
        for start in range(0, rows, block):
            n = min(block, rows - start)
            data = subid.systems.simulate_data(system, n, seed=start)
            values = np.column_stack([data.u, data.y + 0.05 * rng.standard_normal(data.y.shape)])
            np.savetxt(fh, values, delimiter=",", fmt="%.8g")


_CHILD = """
import sys, subid
from subid.cli import commands as cli
warm = subid.systems.simulate_data(subid.systems.seed001_system(), 500, seed=0)
subid.moesp(warm, 3, horizon=5)
mode, path, out = sys.argv[1:4]
if mode == "base":
    import pandas, pyarrow.csv
    sys.exit(0)
args = ["--quiet", "identify", path, "--inputs", "u1,u2", "--outputs", "y1,y2",
        "--method", "moesp", "--order", "3", "--horizon", "10", "--no-report", "--out", out]
if mode == "stream":
    args.append("--stream")
sys.exit(cli.main(args))
"""


def _peak_rss_mb(mode, path, out):
    cmd = ["/usr/bin/time", "-f", "%M", sys.executable, "-c", _CHILD, mode, path, out]
    done = subprocess.run(cmd, capture_output=True, text=True, check=True,
                          env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    return int(done.stderr.strip().splitlines()[-1]) / 1024


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--careful", action="store_true",
                        help="also time the careful line-by-line parser (slow)")
    parser.add_argument("--loadtxt", action="store_true", help="also time numpy.loadtxt")
    args = parser.parse_args()
    import pandas as pd
    import pyarrow.csv as pcsv
    folder = tempfile.mkdtemp(prefix="subid-csv-bench-")
    path = os.path.join(folder, "big.csv")
    _make(path, args.rows)
    size = os.path.getsize(path)
    doubles = args.rows * 4 * 8
    print(f"# {args.rows} rows, {size / 2**20:.0f} MiB of CSV, {doubles / 2**20:.0f} MiB of "
          f"doubles; engine {sio.fast_engine()}; pandas {pd.__version__}; numpy "
          f"{np.__version__}; median of {args.repeat}")
    steps = {}

    def pandas_once():
        return pd.read_csv(path, engine="c", dtype=np.float64).to_numpy()

    def arrow_once(threads=False):
        table = pcsv.read_csv(path, read_options=pcsv.ReadOptions(use_threads=threads))
        return np.column_stack([c.to_numpy() for c in table.columns])

    def with_engine(engine):
        def read():
            saved = sio._ENGINE
            sio._ENGINE = engine
            try:
                subid.read(path, "u1,u2", "y1,y2")
            finally:
                sio._ENGINE = saved
        return read

    from subid.cli import commands as cli

    def stream_cli():
        assert cli.main(["--quiet", "identify", path, "--inputs", "u1,u2", "--outputs",
                         "y1,y2", "--method", "moesp", "--order", "3", "--horizon", "10",
                         "--no-report", "--stream", "--out", os.path.join(folder, "s")]) == 0

    steps["pandas.read_csv (C engine)"] = (pandas_once, None)
    steps["pyarrow.csv.read_csv (1 thread)"] = (arrow_once, None)
    steps["pyarrow.csv.read_csv (threads)"] = (lambda: arrow_once(True), None)
    if args.loadtxt:
        steps["numpy.loadtxt"] = (lambda: np.loadtxt(path, delimiter=",", skiprows=1), 1)
    steps["subid.read"] = (lambda: subid.read(path, "u1,u2", "y1,y2"), None)
    steps["subid.read (engine pyarrow)"] = (with_engine("pyarrow"), None)
    steps["subid.read (engine numpy)"] = (with_engine("numpy"), 1)
    if args.careful:
        from pathlib import Path
        steps["subid.read, careful parser (before)"] = (
            lambda: stext._read_text(Path(path), path, ".csv", "u1,u2", "y1,y2", None, None,
                                   None), 1)
    steps["read_chunks, one pass"] = (
        lambda: sum(p.n_samples for p in subid.read_chunks(path, "u1,u2", "y1,y2")), None)
    steps["identify_file (moesp: parse once, B/D pass from the spool)"] = (
        lambda: subid.identify_file(path, "u1,u2", "y1,y2", method="moesp", order=3,
                                    horizon=10), None)
    steps["subid identify --stream (moesp, --no-report)"] = (stream_cli, None)
    data = subid.read(path, "u1,u2", "y1,y2")
    steps["moesp on the record in memory (no I/O)"] = (
        lambda: subid.moesp(data, 3, horizon=10), None)
    rows = _interleaved(steps, args.repeat)
    steps = data = None               # free the record before the memory children
    parsers = [k for k in rows if not k.startswith(("subid", "read_chunks", "identify_file",
                                                    "moesp")) and "threads)" not in k]
    wall, cpu = rows[min(parsers, key=lambda k: rows[k][0])]
    print(f"| step | seconds | / fastest single-thread parse | CPU s (all threads) "
          f"| CPU / its CPU ({subid._threads.available()} subid threads) |")
    print("|---|---:|---:|---:|---:|")
    for name, (seconds, seconds_cpu) in rows.items():
        print(f"| {name} | {seconds:.3f} | {seconds / wall:.2f} | {seconds_cpu:.3f} "
              f"| {seconds_cpu / cpu:.2f} |")
    base = _peak_rss_mb("base", path, os.path.join(folder, "o0"))
    whole = _peak_rss_mb("whole", path, os.path.join(folder, "o1"))
    stream = _peak_rss_mb("stream", path, os.path.join(folder, "o2"))
    mb = doubles / 2**20
    print()
    print(f"peak RSS beyond a warmed-up child ({base:.0f} MiB): in-memory CLI "
          f"{whole - base:.0f} MiB = {(whole - base) / mb:.2f}x the doubles; --stream CLI "
          f"{stream - base:.0f} MiB = {(stream - base) / mb:.2f}x")
    shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
