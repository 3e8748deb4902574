"""Default calls with one BLAS thread against two (subid._blas: why subid runs with one).

Run: PYTHONPATH=src python bench/blas_threads.py [--repeat 5] [--busy 1]
     [--out bench/blas_threads.md]

(without OPENBLAS_NUM_THREADS: the script sets the pools itself, with
``subid.thread_limit(1)`` and ``subid.thread_limit(2)``). In one process, the calls
alternate between the two settings; wall seconds, medians and ranges over the repeats
after a first untimed call. ``--busy N`` runs N processes that spin for the whole run
(what other jobs on a shared machine do; 0 for a machine left to itself). Records:
the bundled CD_player_arm (first 2/3, means removed, as bench/realdata.py), and a
2-input, 2-output 4th-order system at 20 dB with 10^5 and 10^6 samples.
"""

import argparse
import multiprocessing
import os
import statistics
import time
import warnings


def _spin(stop):
    while not stop.is_set():
        sum(range(10_000))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--busy", type=int, default=1)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "blas_threads.md"))
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    import subid
    from selection_identity import split  # first 2/3, means removed
    cd = split("CD_player_arm")
    true = subid.systems.random_system(4, 2, 2, seed=29)
    big = {n: subid.systems.simulate_data(true, n, seed=30, output_snr_db=20)
           for n in (100_000, 1_000_000)}
    cases = [("CD_player_arm", "identify", lambda: subid.identify(cd)),
             ("CD_player_arm", "moesp", lambda: subid.moesp(cd)),
             ("10^5 samples", "identify", lambda: subid.identify(big[100_000])),
             ("10^6 samples", "identify", lambda: subid.identify(big[1_000_000]))]
    stop = multiprocessing.Event()
    busy = [multiprocessing.Process(target=_spin, args=(stop,), daemon=True)
            for _ in range(args.busy)]
    for p in busy:
        p.start()
    rows = []
    try:
        for record, call, fn in cases:
            fn()
            times = {1: [], 2: []}
            for _ in range(args.repeat):
                for threads in (1, 2):
                    with subid.thread_limit(threads):
                        t0 = time.perf_counter()
                        fn()
                        times[threads].append(time.perf_counter() - t0)
            rows.append((record, call, times))
            print(record, call, {k: [round(t, 2) for t in v] for k, v in times.items()},
                  flush=True)
    finally:
        stop.set()
        for p in busy:
            p.join(5)
    load = os.getloadavg()[0]
    lines = ["# One BLAS thread against two in the default calls (bench/blas_threads.py)", "",
             f"`PYTHONPATH=src python bench/blas_threads.py --repeat {args.repeat} "
             f"--busy {args.busy}` ({args.busy} spinning process(es) beside the run; "
             f"1-minute load average at the end {load:.1f}; 2 cores). Wall seconds, "
             "median (range) over the repeats, the two settings alternated in one process.",
             "", "| record | call | 1 thread | 2 threads | 2 threads / 1 thread |",
             "|---|---|---:|---:|---:|"]
    for record, call, times in rows:
        m1, m2 = statistics.median(times[1]), statistics.median(times[2])
        lines.append(f"| {record} | {call} | {m1:.2f} ({min(times[1]):.2f}-{max(times[1]):.2f})"
                     f" | {m2:.2f} ({min(times[2]):.2f}-{max(times[2]):.2f}) | {m2 / m1:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        mode = "a" if os.path.exists(args.out) else "w"
        with open(args.out, mode) as f:
            f.write(("\n" if mode == "a" else "") + text)


if __name__ == "__main__":
    main()
