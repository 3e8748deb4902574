"""Where a report of 10^6 samples spends its CPU time, section by section (issue 29).

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/report_sections.py [--repeat 8]
     [--samples 1000000] [--identify]

The record of ``bench/report_ratio.py`` (2 inputs, 2 outputs, a 4th-order system at
20 dB SNR, dt = 0.01, means removed, 70 % estimation), identified once with
``subid.identify``; then ``--repeat`` reports (:func:`subid.evaluation.report.
identification_report`, with the ``evaluate`` result passed in as the command line
does). Each figure's building ("make": the plotting function, with what it computes)
and rendering ("render": ``figure_html``, Agg and the PNG) are timed apart, and so is
the spa estimate of the Bode overlay; CPU seconds (``time.process_time``), medians
over the repeats after the first. ``--identify`` runs the identification again before
every report, as ``bench/report_ratio.py`` does (the report is then slower: the
identification leaves the caches cold). Compare two checkouts by running this
script alternately on each.
"""

import argparse
import collections
import statistics
import time
import warnings


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=8)
    parser.add_argument("--identify", action="store_true",
                        help="identify again before every report (as report_ratio.py)")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    import subid
    from subid.evaluation import report
    true = subid.systems.random_system(4, 2, 2, seed=29)
    record = subid.systems.simulate_data(true, args.samples, seed=30, output_snr_db=20)
    record = subid.IOData(record.u, record.y, dt=0.01, input_names=["u1", "u2"],
                          output_names=["y1", "y2"])
    work = record.detrend()
    est, val = work.split(0.7)
    model = subid.identify(est)
    result = report.evaluate(model, est, val)

    parts = collections.defaultdict(list)
    draw = report.figure_html
    spa = report._spa_estimate

    from subid.evaluation.figures._light_axes import report_axes

    def timed_figure(make, caption, what):
        t0 = time.process_time()
        with report_axes():               # the report's axes, as report._plot_or_note
            fig = make()
        t1 = time.process_time()
        out = draw(fig, caption, dpi=report.REPORT_DPI)
        parts[what].append((t1 - t0, time.process_time() - t1))
        return out

    def timed_spa(*a):
        t0 = time.process_time()
        out = spa(*a)
        parts["spa estimate (Bode overlay)"].append((time.process_time() - t0, 0.0))
        return out

    report._plot_or_note, report._spa_estimate = timed_figure, timed_spa
    totals = []
    for _ in range(args.repeat):
        if args.identify:
            subid.identify(est)
        t0 = time.process_time()
        report.identification_report({"identify": model}, est, val, title="bench",
                                     seconds={"identify": 1.0}, source="record.csv",
                                     data=work, fits={"identify": result})
        totals.append(time.process_time() - t0)
    print(f"report: median {statistics.median(totals[1:]):.3f} CPU s, min "
          f"{min(totals[1:]):.3f} ({args.repeat - 1} repeats after the first)")
    print("| section | make | render |")
    print("|---|---:|---:|")
    for what, values in parts.items():
        make = statistics.median(v[0] for v in values[1:])
        render = statistics.median(v[1] for v in values[1:])
        print(f"| {what} | {make:.3f} | {render:.3f} |")


if __name__ == "__main__":
    main()
