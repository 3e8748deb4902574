"""The demo's reports with and without the fast figure path, interleaved (issue 29).

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/report_figures.py --models DIR
     [DATASET ...] [--repeat 2] [--out bench/report_figures.md]

``DIR`` holds the pickled rows and models of ``bench/demo_reports.py`` (written there on
its first run). For each dataset, after a warm-up report, ``demo.write_report`` runs
``--repeat`` times in each of two ways, alternating in this one process: "savefig" embeds
every figure as ``fig.savefig(format="png")`` did before (matplotlib's per-tick objects,
Pillow's PNG encoder at zlib level 1), "fast" through ``report.figure_html``
(``figures/_ticks.light_ticks`` and ``evaluation/_png.png_bytes``). CPU seconds
(``time.process_time``), the fastest repeat of each; the ratio is what a shared machine's
load changes least.
"""

import argparse
import base64
import io
import os
import pickle
import tempfile
import time
import warnings


def _savefig_html(fig, caption="", *, dpi=None, alt=""):
    """``report.figure_html`` as it was: ``savefig`` to PNG, Pillow at zlib level 1."""
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi or fig.dpi, pil_kwargs={"compress_level": 1})
    plt.close(fig)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    return f'<figure><img alt="figure" src="data:image/png;base64,{data}"></figure>'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="*")
    parser.add_argument("--models", required=True)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "report_figures.md"))
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    from subid import datasets
    from subid.cli import demo
    from subid.evaluation import report
    fast = report.figure_html
    ways = {"savefig": _savefig_html, "fast": fast}
    out = tempfile.mkdtemp()
    lines = ["# Report figures: savefig against the fast path (bench/report_figures.py)", "",
             "| dataset | savefig (CPU s) | fast (CPU s) | fast / savefig |",
             "|---|---:|---:|---:|"]
    totals = dict.fromkeys(ways, 0.0)
    for name in args.datasets or datasets.names():
        with open(os.path.join(args.models, f"{name}.pkl"), "rb") as f:
            rows, models = pickle.load(f)
        demo.write_report(name, out, rows, models)                # warm-up
        seconds = {way: [] for way in ways}
        try:
            for _ in range(args.repeat):
                for way, fn in ways.items():
                    report.figure_html = fn
                    c0 = time.process_time()
                    demo.write_report(name, out, rows, models)
                    seconds[way].append(time.process_time() - c0)
        finally:
            report.figure_html = fast
        best = {way: min(v) for way, v in seconds.items()}
        for way in ways:
            totals[way] += best[way]
        lines.append(f"| {name} | {best['savefig']:.2f} | {best['fast']:.2f} | "
                     f"{best['fast'] / best['savefig']:.2f} |")
        print(lines[-1], flush=True)
    lines.append(f"| **sum** | **{totals['savefig']:.1f}** | **{totals['fast']:.1f}** | "
                 f"**{totals['fast'] / totals['savefig']:.2f}** |")
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    lines += ["", f"Fastest of {args.repeat} interleaved repeats after a warm-up report, "
              f"OPENBLAS_NUM_THREADS=1, load average {load} at the end.", ""]
    text = "\n".join(lines)
    with open(args.out, "w") as f:   # noqa: SIM115 - the benchmark's table
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
