"""Benchmarks (``make bench``; never part of ``make test``).

1. Batch methods against the peers SIPPY (``sippy-unipi``, N4SID) and
   ``nfoursid``, on the same generated data: a random stable 4th-order system
   with 2 inputs and 2 outputs, white input, noise-free, horizon 5, for
   N = 1e3 ... 1e7. Each (method, N) runs in a fresh subprocess. Wall time
   is the median over repeats inside that process; peak memory is the
   largest traced allocation (tracemalloc, which sees numpy's arrays) during
   one more, traced, run of the call. A method is skipped at a
   size where the previous size predicts (linear scaling) more than the time
   or memory budget, and the table says so.
2. The cost of choosing the order and horizon (issue 21): ``moesp(data)``
   against the same call with the order and horizon given, the lag-product
   floor and SIPPY's own order search, in one process, calls interleaved,
   CPU time (``--selection-only`` runs this table alone).
3. Online identifiers: samples per second on one core.

Run with one BLAS thread (the Makefile sets ``OPENBLAS_NUM_THREADS=1``):
threaded BLAS made timings erratic by up to 50x on the shared 2-core machines.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

from online import bench_adaptive, machine  # bench/ is sys.path[0]
from online import table as adaptive_table

TIME_BUDGET_S = 120.0
MEMORY_BUDGET_MB = 8000.0
ONLINE_SAMPLES = 200_000
ORDER, HORIZON = 4, 5

OURS = ["subid.ls_subspace", "subid.moesp", "subid.n4sid", "subid.moesp (statistic only)"]
PEERS = ["SIPPY N4SID", "nfoursid"]


# ---------------------------------------------------------------------------
# one case, in its own process
# ---------------------------------------------------------------------------
def _make_data(n):
    from subid import systems
    true = systems.random_system(ORDER, 2, 2, seed=1)
    return true, systems.simulate_data(true, n, seed=2)


def _runner(method, horizon=HORIZON):
    import subid
    if method == "subid.ls_subspace":
        return lambda d: subid.ls_subspace(d, ORDER, horizon=horizon)
    if method == "subid.moesp":
        return lambda d: subid.moesp(d, ORDER, horizon=horizon)
    if method == "subid.n4sid":
        return lambda d: subid.n4sid(d, ORDER, horizon=horizon)
    if method == "subid.moesp (statistic only)":
        return lambda d: subid.moesp(d, ORDER, horizon=horizon, bd_method="projection")
    if method == "subid.ls_subspace (statistic only)":
        return lambda d: subid.ls_subspace(d, ORDER, horizon=horizon, bd_method="projection")
    if method == "SIPPY N4SID":
        from sippy_unipi import system_identification

        def sippy(d):
            sys_id = system_identification(d.y.T, d.u.T, "N4SID", SS_fixed_order=ORDER,
                                           SS_f=HORIZON, SS_p=HORIZON, SS_D_required=True)
            return subid.StateSpace(sys_id.A, sys_id.B, sys_id.C, sys_id.D, 1.0)
        return sippy
    if method == "nfoursid":
        import pandas as pd
        from nfoursid.nfoursid import NFourSID

        def nfour(d):
            df = pd.DataFrame(np.hstack([d.u, d.y]), columns=["u1", "u2", "y1", "y2"])
            n4 = NFourSID(df, output_columns=["y1", "y2"], input_columns=["u1", "u2"],
                          num_block_rows=HORIZON)
            n4.subspace_identification()
            ss, _ = n4.system_identification(rank=ORDER)
            return subid.StateSpace(ss.a, ss.b, ss.c, ss.d, 1.0)
        return nfour
    raise ValueError(method)


def run_case(method, n, repeats, horizon=HORIZON):
    import tracemalloc

    import subid
    true, data = _make_data(n)
    fn = _runner(method, horizon)
    fn(_make_data(2000)[1])                       # imports and compiled kernels
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        model = fn(data)
        times.append(time.perf_counter() - t0)
    tracemalloc.start()                           # one more run, traced, for the memory
    fn(data)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"seconds": statistics.median(times), "peak_mb": peak / 2**20,
            "markov_error": subid.markov_error(model, true), "repeats": repeats}


def _case_in_subprocess(method, n, repeats, horizon=HORIZON):
    cmd = [sys.executable, __file__, "--case", method, str(n), str(repeats), str(horizon)]
    out = subprocess.run(cmd, capture_output=True, text=True,
                         timeout=TIME_BUDGET_S * (repeats + 2) + 120)
    if out.returncode != 0:
        return {"error": (out.stderr.strip().splitlines() or ["failed"])[-1][:160]}
    return json.loads(out.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------
# the cost of choosing (issue 21.6), in this process, calls interleaved
# ---------------------------------------------------------------------------
SELECTION_SIZES = (1_000, 10_000, 100_000, 1_000_000)
SELECTION_SIPPY_MAX = 10_000         # SIPPY's own order search only up to this size
SELECTION_SNR_DB = 20


def _selection_calls(n):
    """The calls of the selection table: name -> function of the record."""
    import subid
    calls = {
        "default": lambda d: subid.moesp(d),
        "pinned": lambda d: subid.moesp(d, ORDER, horizon=10),
        # the lag-product floor: one fit on the lagged products, the first estimator
        "floor": lambda d: subid.moesp(d, ORDER, horizon=10, statistic="gram",
                                       system_matrices="shift"),
    }
    if n <= SELECTION_SIPPY_MAX and _available("SIPPY N4SID"):
        from sippy_unipi import system_identification

        def sippy_aic(d):
            sys_id = system_identification(d.y.T, d.u.T, "N4SID", IC="AIC", SS_orders=[1, 10],
                                           SS_f=10, SS_p=10, SS_D_required=True)
            return subid.StateSpace(sys_id.A, sys_id.B, sys_id.C, sys_id.D, 1.0)
        calls["SIPPY N4SID, AIC 1..10"] = sippy_aic
    return calls


def bench_selection(sizes=SELECTION_SIZES):
    """CPU seconds (median over interleaved rounds, one process) of ``moesp(data)``,
    of the call with the order and horizon given, of the lag-product floor and of
    SIPPY's own order search; 2x2 order-4 random system, 20 dB output noise."""
    import warnings

    from subid import systems
    true = systems.random_system(ORDER, 2, 2, seed=1)
    warm = systems.simulate_data(true, 2000, seed=3, output_snr_db=SELECTION_SNR_DB)
    rows = []
    for n in sizes:
        data = systems.simulate_data(true, n, seed=2, output_snr_db=SELECTION_SNR_DB)
        calls = _selection_calls(n)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for fn in calls.values():                   # imports and compiled kernels
                fn(warm)
            rounds = 5 if n <= 10_000 else 3
            times = {name: [] for name in calls}
            orders = {}
            for _ in range(rounds):
                for name, fn in calls.items():          # interleaved
                    t0 = time.process_time()
                    model = fn(data)
                    times[name].append(time.process_time() - t0)
                    orders[name] = (model.order, model.info.get("horizon"))
        t = {name: statistics.median(v) for name, v in times.items()}
        sippy = t.get("SIPPY N4SID, AIC 1..10")
        rows.append(
            f"| {n:,} | {t['default']:.3f} | {t['pinned']:.4f} | {t['floor']:.4f} | "
            + (f"{sippy:.3f}" if sippy else "—") + " | "
            f"{t['default'] / t['pinned']:.1f} | "
            + (f"{t['default'] / sippy:.2f}" if sippy else "—") + " | "
            f"{t['pinned'] / t['floor']:.2f} | n={orders['default'][0]}, "
            f"f={orders['default'][1]} |")
        print(rows[-1], flush=True)
    return rows


def selection_table(rows):
    return "\n".join([
        f"The cost of choosing (issue 21): CPU seconds, median of interleaved rounds in one "
        f"process (5 up to 1e4 samples, 3 above); random stable 2x2 system of order {ORDER}, "
        f"white input, {SELECTION_SNR_DB} dB output noise. `default` = `moesp(data)` (order "
        f"and horizon cross-validated); `pinned` = `moesp(data, {ORDER}, horizon=10)`; `floor` "
        "= the same on the lag-product statistic with the first estimator "
        "(`statistic='gram', system_matrices='shift'`); SIPPY = N4SID with its own order "
        "search (`IC='AIC'`, orders 1..10, f = p = 10). Goals: default/pinned <= 5, "
        "default/SIPPY <= 1, pinned/floor <= 2.",
        "",
        "| N | default (s) | pinned (s) | floor (s) | SIPPY AIC (s) | default / pinned | "
        "default / SIPPY | pinned / floor | chosen |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---|",
        *rows])


# ---------------------------------------------------------------------------
# online identifiers (in this process)
# ---------------------------------------------------------------------------
def _median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench_recursive():
    """Samples per second of RecursiveSubspace (update only, model not requested)."""
    import subid
    from subid import systems
    data = systems.simulate_data(systems.seed001_system(), ONLINE_SAMPLES, seed=3)
    rows = []
    for instruments in ("past", None):
        subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments).update(
            data.u[:100], data.y[:100])                      # compile

        def run(instruments=instruments):
            rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, instruments=instruments)
            for k in range(0, ONLINE_SAMPLES, 1000):
                rs.update(data.u[k:k + 1000], data.y[k:k + 1000])

        seconds = _median_time(run, 3)
        rows.append(f"| RecursiveSubspace, instruments={instruments!r} | seed 001 (n=3, 2x2), "
                    f"horizon 5 | {ONLINE_SAMPLES / seconds:,.0f} |")
    return rows


def _available(method):
    module = {"SIPPY N4SID": "sippy_unipi", "nfoursid": "nfoursid"}.get(method)
    if module is None:
        return True
    try:
        __import__(module)
        return True
    except ImportError:
        return False


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Benchmark subid against SIPPY and nfoursid.")
    parser.add_argument("--sizes", default="1000,10000,100000,1000000,10000000")
    parser.add_argument("--out", default="bench/results.md")
    parser.add_argument("--selection-only", action="store_true",
                        help="only the table of the cost of choosing (printed)")
    parser.add_argument("--case", nargs=4, metavar=("METHOD", "N", "REPEATS", "HORIZON"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.case:
        method, n, repeats, horizon = args.case
        print(json.dumps(run_case(method, int(n), int(repeats), int(horizon))))
        return 0
    if args.selection_only:
        print(selection_table(bench_selection()))
        return 0
    sizes = [int(s) for s in args.sizes.split(",")]
    methods = OURS + [p for p in PEERS if _available(p)]
    missing = [p for p in PEERS if not _available(p)]
    results, last = {}, {}
    for n in sizes:
        repeats = 5 if n <= 10_000 else 3 if n <= 100_000 else 1
        for method in methods:
            prev = last.get(method)
            if prev and "error" not in prev:
                scale = n / prev["n"]
                if prev["seconds"] * scale > TIME_BUDGET_S:
                    results[(method, n)] = {"skipped": f"predicted {prev['seconds'] * scale:.0f} s "
                                                       f"> {TIME_BUDGET_S:.0f} s budget"}
                    continue
                if prev["peak_mb"] * scale > MEMORY_BUDGET_MB:
                    results[(method, n)] = {"skipped": f"predicted {prev['peak_mb'] * scale:.0f} MB"
                                                       f" > {MEMORY_BUDGET_MB:.0f} MB budget"}
                    continue
            elif prev and "error" in prev:
                results[(method, n)] = {"skipped": "failed at a smaller size"}
                continue
            res = _case_in_subprocess(method, n, repeats)
            res["n"] = n
            results[(method, n)] = res
            last[method] = res
            print(f"N={n:,} {method}: {res}", flush=True)
    rows = []
    for n in sizes:
        peers = {p: results.get((p, n), {}) for p in PEERS}
        for method in methods:
            r = results[(method, n)]
            if "skipped" in r or "error" in r:
                rows.append(f"| {n:,} | {method} | — | — | — | {r.get('skipped') or r['error']} |")
                continue
            ratios = []
            if method in OURS:
                for p, pr in peers.items():
                    if "seconds" in pr:
                        ratios.append(f"{pr['seconds'] / r['seconds']:.1f}x faster than {p}")
            rows.append(f"| {n:,} | {method} | {r['seconds'] * 1e3:,.1f} | {r['peak_mb']:,.0f} | "
                        f"{r['markov_error']:.1e} | {'; '.join(ratios)} |")
    goal, seconds = [], {}
    for method in ("subid.n4sid", "subid.moesp", "subid.moesp (statistic only)",
                   "subid.ls_subspace", "subid.ls_subspace (statistic only)"):
        r = _case_in_subprocess(method, 10_000_000, 3, horizon=10)
        print(f"goal {method}: {r}", flush=True)
        seconds[method] = r.get("seconds")
        goal.append(f"| {method} | {r['seconds']:.2f} | {r['peak_mb']:,.0f} | "
                    f"{r['markov_error']:.1e} |" if "seconds" in r else
                    f"| {method} | — | — | {r.get('error')} |")
        if method.endswith("(statistic only)") and r.get("seconds"):
            default = seconds.get(method.replace(" (statistic only)", ""))
            if default:
                goal[-1] += f" default {default / r['seconds']:.2f}x this |"
                continue
        goal[-1] += " |"
    selection = selection_table(bench_selection())
    online = bench_recursive()
    adaptive = adaptive_table(bench_adaptive())
    text = "\n".join([
        f"Machine: {machine()}.",
        f"System: random stable, order {ORDER}, 2 inputs, 2 outputs, noise-free white input; "
        f"horizon {HORIZON} (SIPPY: SS_f = SS_p = {HORIZON}; nfoursid: num_block_rows = "
        f"{HORIZON}). Time: median over the repeats (5 up to 1e4 samples, 3 up to 1e5, 1 "
        "above). Budgets: "
        f"{TIME_BUDGET_S:.0f} s and {MEMORY_BUDGET_MB:.0f} MB per call."
        + (f" Not installed, not run: {', '.join(missing)}." if missing else ""),
        "",
        "`moesp (statistic only)` identifies from the statistic alone (B and D by the "
        "projected data equation); the other subid rows fit B, D and x0 to the raw output "
        "samples, the default when the raw data are at hand.",
        "",
        "Peak memory: the largest traced allocation (numpy arrays included) during one more "
        "run of the call; the data themselves (N x 4 doubles) are not counted.",
        "",
        "| N | method | time (ms) | peak memory (MB) | Markov error | vs peers |",
        "|---:|---|---:|---:|---:|---|",
        *rows,
        "",
        "Goal check: 10^7 samples, 2 inputs, 2 outputs, horizon 10 (median of 3 runs):",
        "",
        "| method | time (s) | peak memory (MB) | Markov error | default / statistic only |",
        "|---|---:|---:|---:|---|",
        *goal,
        "",
        selection,
        "",
        f"Online identifiers, samples per second on one core (median of 3 runs over "
        f"{ONLINE_SAMPLES:,} samples, chunks of 1000):",
        "",
        "| identifier | system | samples/s |",
        "|---|---|---:|",
        *online,
        "",
        adaptive])
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
