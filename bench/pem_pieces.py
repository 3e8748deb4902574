"""pem's Jacobian in pieces against the whole Jacobian: time and peak memory.

``subid.pem`` forms its Jacobian (``N ny`` rows, a column per free parameter and
initial state) a piece of at most ``JACOBIAN_PIECE_BYTES`` at a time and keeps only
its Gram matrix (:mod:`subid.methods.dt._trust_region`, ``compress_pieces``). This
script refines the same start with the piece size set to each of ``--pieces`` (MiB;
``whole``: one array, what pem did before) on a 2x2 order-4 system with process and
output noise (20 dB), in separate processes (peak resident memory,
``ru_maxrss``, is per process), alternated, ``--repeat`` times; each process first
compiles the kernels on 2,000 samples, untimed. Medians of wall and CPU seconds and
of the peak memory; the final costs must agree (the same iterates to rounding).

Run: ``OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/pem_pieces.py
[--samples 100000,300000,1000000] [--pieces whole,16,64] [--repeat 2]
[--focus prediction,simulation] [--out bench/pem_pieces.md]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHILD = r"""
import json, resource, sys, time, warnings
warnings.simplefilter("ignore")
import subid
from subid.methods.dt import _pe_search
N, piece, focus = int(sys.argv[1]), sys.argv[2], sys.argv[3]
if piece != "whole":
    _pe_search.JACOBIAN_PIECE_BYTES = int(float(piece) * 2**20)
else:
    _pe_search.JACOBIAN_PIECE_BYTES = float("inf")
true = subid.systems.random_system(4, 2, 2, seed=29)
data = subid.systems.simulate_data(true, N, seed=30, output_snr_db=20, process_snr_db=20)
start = subid.moesp(data, 4, horizon=10)
subid.pem(data[:2000], start, focus=focus)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t, c = time.perf_counter(), time.process_time()
model = subid.pem(data, start, focus=focus)
wall, cpu = time.perf_counter() - t, time.process_time() - c
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"wall": wall, "cpu": cpu, "peak_gb": peak / 1e6, "before_gb": before / 1e6,
                  "cost": model.info["final_cost"],
                  "evaluations": model.info["n_evaluations"]}))
"""


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", default="100000,300000,1000000")
    parser.add_argument("--pieces", default="whole,16,64")
    parser.add_argument("--focus", default="prediction,simulation")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "pem_pieces.md"))
    args = parser.parse_args(argv)
    samples = [int(s) for s in args.samples.split(",")]
    pieces = args.pieces.split(",")
    focuses = args.focus.split(",")
    runs: dict = {}
    for _ in range(args.repeat):
        for N in samples:
            for focus in focuses:
                for piece in pieces:           # alternated within each configuration
                    out = subprocess.run([sys.executable, "-c", CHILD, str(N), piece, focus],
                                         capture_output=True, text=True, check=True)
                    row = json.loads(out.stdout.strip().splitlines()[-1])
                    runs.setdefault((N, focus, piece), []).append(row)
                    print(N, focus, piece, row, file=sys.stderr)
    lines = ["# pem's Jacobian in pieces (bench/pem_pieces.py)", "",
             f"`OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/pem_pieces.py --samples "
             f"{args.samples} --pieces {args.pieces} --focus {args.focus} --repeat "
             f"{args.repeat}`: 2x2 order-4 system, 20 dB process and output noise, "
             "`pem(data, moesp(data, 4, horizon=10), focus=...)`; one process per run, "
             "alternated; medians. `whole`: the Jacobian as one array (pem before the "
             "pieces); a number: the piece size in MiB.", "",
             "| samples | focus | Jacobian | wall s | CPU s | peak memory GB (before the "
             "call) | final cost | evaluations |", "|---:|---|---|---:|---:|---:|---:|---:|"]
    for N in samples:
        for focus in focuses:
            for piece in pieces:
                rs = runs[(N, focus, piece)]

                def med(key, rs=rs):
                    return statistics.median(r[key] for r in rs)
                label = "whole" if piece == "whole" else f"{piece} MiB pieces"
                lines.append(f"| {N} | {focus} | {label} | {med('wall'):.2f} | "
                             f"{med('cpu'):.2f} | {med('peak_gb'):.2f} ({med('before_gb'):.2f})"
                             f" | {rs[0]['cost']:.12g} | {rs[0]['evaluations']} |")
    text = "\n".join(lines) + "\n"
    with open(args.out, "w") as f:
        f.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
