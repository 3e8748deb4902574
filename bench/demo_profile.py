"""Where the time of ``subid demo`` goes (issue 29): method x record wall times.

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/demo_profile.py [DATASET ...]
     [--methods ls,moesp,...] [--out bench/demo_profile.md] [--profile FILE.prof]

Every record in this one process, one after the other (no pool): the CPU
time of each method's identification and of each section of the report
(from the report's progress callback), then of the whole record. With
``--profile``, the whole run goes through cProfile and its statistics are
written to FILE.prof (read with ``python -m pstats``). Numba kernels are loaded
from the cache before the timed run (``python -m subid.warmup`` once after
installing, as ``make demo`` does).
"""

import argparse
import os
import sys
import tempfile
import time
import warnings


def profile_dataset(name, methods, out, profiler=None):
    """CPU seconds per method (identification), per section of the report, in all."""
    from subid.cli import demo
    from subid.evaluation import report as report_module
    sections = {}
    original = report_module.identification_report

    def timed_report(*args, **kwargs):
        last = {"name": None, "t": time.process_time()}

        def announce(section):
            now = time.process_time()
            if last["name"] is not None:
                sections[last["name"]] = sections.get(last["name"], 0.0) + now - last["t"]
            last.update(name=section, t=now)
        kwargs["progress"] = announce
        try:
            return original(*args, **kwargs)
        finally:
            announce(None)

    t0 = time.process_time()
    rows, models, _, _ = demo.evaluate(name, methods)
    report_module.identification_report = timed_report
    if profiler is not None:
        profiler.enable()
    try:
        demo.write_report(name, out, rows, models)
    finally:
        if profiler is not None:
            profiler.disable()
        report_module.identification_report = original
    total = time.process_time() - t0
    times = {row["method"]: row["cpu_seconds"] for row in rows}
    return times, sections, total


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="*")
    parser.add_argument("--methods", default=None)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "demo_profile.md"))
    parser.add_argument("--profile", default=None)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    from subid import datasets
    from subid.cli import demo
    names = args.datasets or list(datasets.names())
    methods = args.methods.split(",") if args.methods else None
    columns = list(demo._methods(methods))
    folder = tempfile.mkdtemp()
    profiler = None
    if args.profile:
        import cProfile
        profiler = cProfile.Profile()
    table = {}
    t_all, c_all = time.perf_counter(), time.process_time()
    for name in names:
        table[name] = profile_dataset(name, methods, folder, profiler)
        times, sections, total = table[name]
        print(f"{name}: {total:.1f} s; " + ", ".join(f"{m} {s:.1f}" for m, s in times.items())
              + "; report " + ", ".join(f"{k} {v:.1f}" for k, v in sections.items()),
              file=sys.stderr)
    elapsed, cpu = time.perf_counter() - t_all, time.process_time() - c_all
    if profiler is not None:
        profiler.dump_stats(args.profile)
    section_names = list(dict.fromkeys(k for v in table.values() for k in v[1]))
    lines = ["# Where the demo's time goes (bench/demo_profile.py)", "",
             f"One process, records one after the other, OPENBLAS_NUM_THREADS=1, load average "
             f"{os.getloadavg()[1]:.1f} on {os.cpu_count()} CPUs at the end; CPU seconds of "
             "this process (time.process_time: on a loaded machine the wall times are "
             "longer, the CPU times much less so). Methods: identification; report: each "
             "section of the HTML report (summary includes the fit % of every model).", "",
             "| record | " + " | ".join(columns) + " | report: "
             + " | ".join(section_names) + " | total |",
             "|---|" + "---:|" * (len(columns) + len(section_names) + 1)]
    sums = {}
    for name, (times, sections, total) in table.items():
        cells = [times.get(m) for m in columns] + [sections.get(s) for s in section_names] \
            + [total]
        for k, v in enumerate(cells):
            sums[k] = sums.get(k, 0.0) + (v or 0.0)
        lines.append(f"| {name} | " + " | ".join("—" if v is None else f"{v:.1f}"
                                                 for v in cells) + " |")
    lines.append("| **sum** | " + " | ".join(f"**{sums[k]:.1f}**" for k in sorted(sums))
                 + " |")
    lines += ["", f"The whole loop: {cpu:.1f} CPU s, {elapsed:.1f} s wall.", ""]
    text = "\n".join(lines)
    with open(args.out, "w") as f:   # noqa: SIM115 - the benchmark's table
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
