"""Report time against identification time on 10^6 samples (issue 29 item 6).

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/report_ratio.py [--samples 1000000]
     [--cold]
     [--repeat 3] [--method ls] [--profile FILE.prof] [--out bench/report_ratio.md]

What ``subid identify FILE.csv --out DIR`` does, step by step, in one process,
on a 10^6-row CSV (2 inputs, 2 outputs, a 4th-order system at 20 dB SNR):
read the file (:func:`subid.read`), remove the means, identify with the
command line's default method (``subid.identify``; ``--method`` another one) on
the first 70 %, evaluate (fit % on both
parts: the summary needs it, with or without a report), then write the report
(:func:`subid.evaluation.report.identification_report` and the HTML file).
Repeats are interleaved; the table gives medians and the ratio
report / identification of each repeat (target: <= 0.5). The first call of
every step runs once before the timed repeats (numba kernels loaded, matplotlib
imported).
"""

import argparse
import os
import statistics
import sys
import tempfile
import time
import warnings


def _default_method():
    """The method ``subid identify`` uses without --method."""
    from subid.cli.commands import IDENTIFY, METHODS, identify
    (option,) = [p for p in identify.params if p.name == "method_name"]
    # no --method: subid.identify (the CLI's IDENTIFY entry)
    return IDENTIFY if option.default is None else METHODS[option.default]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--method", default=None,
                        help="a registry method name (default: what subid identify uses "
                             "without --method, subid.identify)")
    parser.add_argument("--cold", action="store_true",
                        help="one run without the warm-up run: what a fresh process of "
                             "`subid identify` pays (numba kernels loaded and matplotlib "
                             "imported inside the timed steps); run it several times")
    parser.add_argument("--profile", default=None, metavar="FILE.prof",
                        help="profile the report step of the timed repeats (cProfile)")
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "report_ratio.md"))
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    import numpy as np

    import subid
    from subid.evaluation import report
    if args.method is None:
        spec = _default_method()
    else:
        from subid.methods.registry import METHODS
        spec = METHODS[args.method]
    true = subid.systems.random_system(4, 2, 2, seed=29)
    record = subid.systems.simulate_data(true, args.samples, seed=30, output_snr_db=20)
    folder = tempfile.mkdtemp()
    path = os.path.join(folder, "record.csv")
    with open(path, "w") as f:   # noqa: SIM115 - a benchmark input, not a subid output
        f.write("u1,u2,y1,y2\n")
        np.savetxt(f, np.column_stack([record.u, record.y]), delimiter=",", fmt="%.9g")
    del record

    profiler = None
    if args.profile:
        import cProfile
        profiler = cProfile.Profile()

    def once(profile=False):
        times = {}
        t0, c0 = time.perf_counter(), time.process_time()
        data = subid.read(path, inputs=["u1", "u2"], outputs=["y1", "y2"], dt=0.01)
        times["read"] = time.perf_counter() - t0
        times["cpu_read"] = time.process_time() - c0
        work = data.detrend()
        est, val = work.split(0.7)
        t0, c0 = time.perf_counter(), time.process_time()
        model = spec.load()(est, order=None)
        times["identify"] = time.perf_counter() - t0
        times["cpu_identify"] = time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        result = report.evaluate(model, est, val)
        times["evaluate"] = time.perf_counter() - t0
        times["cpu_evaluate"] = time.process_time() - c0
        if profile:
            profiler.enable()
        t0, c0 = time.perf_counter(), time.process_time()
        html = report.identification_report(
            {spec.name: model}, est, val, title="bench", seconds={spec.name: 1.0},
            source=path, data=work, fits={spec.name: result})
        report.write_html(os.path.join(folder, "report.html"), html)
        times["report"] = time.perf_counter() - t0
        times["cpu_report"] = time.process_time() - c0
        if profile:
            profiler.disable()
        times["order"] = model.order
        return times

    if not args.cold:
        print(f"{args.samples} samples, method {spec.name}: warm-up run", file=sys.stderr)
        once()
    runs = []
    for k in range(1 if args.cold else args.repeat):
        runs.append(once(profiler is not None))
        r = runs[-1]
        print(f"repeat {k + 1}: read {r['read']:.2f} s, identify {r['identify']:.2f} s, "
              f"evaluate {r['evaluate']:.2f} s, report {r['report']:.2f} s, ratio "
              f"{r['report'] / r['identify']:.2f}", file=sys.stderr)
    steps = ("read", "identify", "evaluate", "report")
    med = {key: statistics.median(r[key] for r in runs) for key in steps}
    cpu = {key: statistics.median(r["cpu_" + key] for r in runs) for key in steps}
    ratio = statistics.median(r["report"] / r["identify"] for r in runs)
    cpu_ratio = statistics.median(r["cpu_report"] / r["cpu_identify"] for r in runs)
    load = os.getloadavg()[1]           # the machine's load over the last 5 minutes
    lines = [
        "# Report time against identification time (bench/report_ratio.py)",
        "",
        f"{args.samples} samples (CSV, 2 inputs, 2 outputs), default method "
        f"`{spec.attribute}` (order {runs[-1]['order']}), 70 % estimation; "
        + ("one run in a fresh process (numba kernels loaded and matplotlib imported "
           "inside the timed steps), " if args.cold else
           f"medians of {args.repeat} interleaved repeats after a warm-up run, ")
        + "OPENBLAS_NUM_THREADS=1; "
        f"load average {load:.1f} on {os.cpu_count()} CPUs at the end (on a shared machine "
        "the seconds scale with the load; the ratio is measured in one process).",
        "",
        "| step | seconds (wall) | CPU seconds |",
        "|---|---:|---:|",
        *(f"| {key} | {value:.2f} | {cpu[key]:.2f} |" for key, value in med.items()),
        "",
        f"Report / identification: **{ratio:.2f}** (median of the per-repeat ratios; "
        f"target <= 0.5); in CPU time (time.process_time, less sensitive to the load): "
        f"{cpu_ratio:.2f}.",
        "",
    ]
    if profiler is not None:
        profiler.dump_stats(args.profile)
        lines += ["(The report step ran under cProfile: its seconds include the profiler's "
                  "overhead.)", ""]
    text = "\n".join(lines)
    with open(args.out, "w") as f:   # noqa: SIM115 - the benchmark's table
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
