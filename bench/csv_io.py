"""Large-CSV reading: subid.read / read_chunks / identify_file against the
parsers they use, and the peak memory of the in-memory and streamed CLI.

Run from the repository root:

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/csv_io.py --rows 1000000 --repeat 3

Wall times (one BLAS thread; pyarrow with use_threads=False unless marked),
medians of ``--repeat`` runs, ratios taken in this one process. Peak memory
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
import subid.io.formats as sio


def _median(fn, repeat):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


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
    rows = {}

    def pandas_once():
        return pd.read_csv(path, engine="c", dtype=np.float64).to_numpy()

    def arrow_once(threads=False):
        table = pcsv.read_csv(path, read_options=pcsv.ReadOptions(use_threads=threads))
        return np.column_stack([c.to_numpy() for c in table.columns])

    rows["pandas.read_csv (C engine)"] = _median(pandas_once, args.repeat)
    rows["pyarrow.csv.read_csv (1 thread)"] = _median(arrow_once, args.repeat)
    rows["pyarrow.csv.read_csv (threads)"] = _median(lambda: arrow_once(True), args.repeat)
    if args.loadtxt:
        rows["numpy.loadtxt"] = _median(lambda: np.loadtxt(path, delimiter=",", skiprows=1),
                                        1)
    fastest = min(v for k, v in rows.items() if "threads)" not in k)
    rows["subid.read"] = _median(lambda: subid.read(path, "u1,u2", "y1,y2"), args.repeat)
    saved = sio._ENGINE
    for engine in ("pyarrow", "numpy"):
        sio._ENGINE = engine
        reps = 1 if engine == "numpy" else args.repeat
        rows[f"subid.read (engine {engine})"] = _median(
            lambda: subid.read(path, "u1,u2", "y1,y2"), reps)
    sio._ENGINE = saved
    if args.careful:
        from pathlib import Path
        rows["subid.read, careful parser (before)"] = _median(
            lambda: sio._read_text(Path(path), path, ".csv", "u1,u2", "y1,y2", None, None,
                                   None), 1)
    rows["read_chunks, one pass"] = _median(
        lambda: sum(p.n_samples for p in subid.read_chunks(path, "u1,u2", "y1,y2")),
        args.repeat)
    rows["identify_file (moesp: parse once, B/D pass from the spool)"] = _median(
        lambda: subid.identify_file(path, "u1,u2", "y1,y2", method="moesp", order=3,
                                    horizon=10), args.repeat)
    from subid.cli import commands as cli

    def stream_cli():
        assert cli.main(["--quiet", "identify", path, "--inputs", "u1,u2", "--outputs",
                         "y1,y2", "--method", "moesp", "--order", "3", "--horizon", "10",
                         "--no-report", "--stream", "--out", os.path.join(folder, "s")]) == 0
    rows["subid identify --stream (moesp, --no-report)"] = _median(stream_cli, args.repeat)
    data = subid.read(path, "u1,u2", "y1,y2")
    rows["moesp on the record in memory (no I/O)"] = _median(
        lambda: subid.moesp(data, 3, horizon=10), args.repeat)
    data = None                       # free the record before the memory children
    print("| step | seconds | / fastest single-thread parse |")
    print("|---|---:|---:|")
    for name, seconds in rows.items():
        print(f"| {name} | {seconds:.3f} | {seconds / fastest:.2f} |")
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
