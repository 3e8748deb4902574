"""Wall time of ``subid demo`` (what ``make demo`` runs after installing; issue 29).

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/demo_time.py [--out /tmp/demo_out]
     [--jobs N] [--summary FILE]   (--summary: only analyse a summary.json already written)

Runs ``python -m subid.cli.demo --out DIR`` in a child process and reports its wall
time with the load average before and after. On a shared machine the wall time
scales with the load, so the table also gives what the run would take with the
cores to itself: the CPU seconds of every task (each identification, each report,
from ``summary.json``) scheduled as the demo schedules them (longest first, a
report when its dataset's last method is done) on ``jobs`` cores, plus the start
of the workers (measured: the wall time less the CPU of the longest worker is not
known, so this is a lower bound of an idle run).
"""

import argparse
import heapq
import json
import os
import subprocess
import sys
import time


def makespan(summary, jobs):
    """Finish time of the demo's schedule with the recorded CPU seconds on ``jobs`` cores:
    the pool's queue is first in, first out, so every identification (longest first)
    starts before any report, and the reports follow in the order their datasets
    were done."""
    from subid.cli import demo
    rows = summary["rows"]
    cost = {(r["dataset"], r["method"]): r["cpu_seconds"] for r in rows}
    methods = list(dict.fromkeys(r["method"] for r in rows))
    free = [0.0] * jobs                       # when each core is free
    done = {}                                 # dataset -> time its last method ended
    left = {r["dataset"]: len(methods) for r in rows}
    for task in sorted(cost, key=lambda task: demo._expected_cost(*task), reverse=True):
        end = heapq.heappop(free) + cost[task]
        heapq.heappush(free, end)
        left[task[0]] -= 1
        if left[task[0]] == 0:
            done[task[0]] = end
    for name, ready in sorted(done.items(), key=lambda item: item[1]):
        end = max(heapq.heappop(free), ready) + summary["report_cpu_seconds"][name]
        heapq.heappush(free, end)
    return max(free)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="/tmp/demo_out")
    parser.add_argument("--jobs", type=int, default=None)
    parser.add_argument("--summary", default=None)
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    wall = None
    if args.summary is None:
        command = [sys.executable, "-m", "subid.cli.demo", "--out", args.out, "--quiet"]
        if args.jobs:
            command += ["--jobs", str(args.jobs)]
        t0 = time.perf_counter()
        subprocess.run(command, check=True)
        wall = time.perf_counter() - t0
        args.summary = os.path.join(args.out, "summary.json")
    load_after = os.getloadavg()
    with open(args.summary) as f:
        summary = json.load(f)
    jobs = summary.get("jobs") or args.jobs or os.cpu_count()
    ident = sum(r["cpu_seconds"] for r in summary["rows"])
    reports = sum(summary["report_cpu_seconds"].values())
    per_method = {}
    for r in summary["rows"]:
        per_method[r["method"]] = per_method.get(r["method"], 0.0) + r["cpu_seconds"]
    longest = max(summary["rows"], key=lambda r: r["cpu_seconds"])
    lines = [
        "# Time of the demo (bench/demo_time.py)", "",
        f"`subid demo` with {jobs} jobs on {os.cpu_count()} CPUs, OPENBLAS_NUM_THREADS=1.", "",
        "| what | seconds |", "|---|---:|",
        *([f"| wall time of the command (load average {load_before[0]:.1f} before, "
           f"{load_after[0]:.1f} after) | {wall:.1f} |"] if wall is not None else []),
        f"| wall time the demo measured itself (summary.json) | {summary['seconds']:.1f} |",
        f"| CPU: identifications | {ident:.1f} |",
        *(f"| CPU: identifications, `{m}` | {v:.1f} |" for m, v in per_method.items()),
        f"| CPU: reports | {reports:.1f} |",
        f"| longest task: `{longest['method']}` on {longest['dataset']} | "
        f"{longest['cpu_seconds']:.1f} |",
        f"| the demo's schedule of these CPU seconds on {jobs} idle cores (lower bound of an "
        f"idle run: no start-up) | {makespan(summary, jobs):.1f} |", "",
    ]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
