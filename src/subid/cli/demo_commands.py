"""``subid demo`` and ``subid gallery``: the bundled datasets identified with every
method (the job itself is :mod:`subid.cli.demo`)."""

from __future__ import annotations

import os

import click

from subid.cli._shared import _FREQ, _common, _echo, _fmt_fit, _names, _note_first_run, _state, cli
from subid.io._files import atomic_directory, write_bytes


# -- demo and gallery ----------------------------------------------------------
@cli.command(epilog="\b\nExamples:\n"
                    "  subid demo --out demo_out\n"
                    "  subid demo --datasets dryer,ballbeam --methods ls,moesp --out quick")
@click.option("--out", default="demo_out", show_default=True, type=click.Path(file_okay=False),
              help="Output folder: one report per dataset, index.html, gallery.md.")
@click.option("--datasets", "names", default=None, metavar="NAMES",
              help="Comma-separated subset of the bundled datasets (default: all).")
@click.option("--methods", default=None, metavar="NAMES",
              help="Comma-separated batch methods (default: every available one but the "
                   "slow armax, oe and bj).")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Processes working in parallel, one identification or report each "
                   "(default: the CPUs).")
@_FREQ
@_common
def demo(out, names, methods, jobs, frequency_unit):
    """Identify the bundled DaISy datasets with the batch methods (fast ones by default).

    By default every one but the slow polynomial armax, oe and bj (--methods
    names them to run them too).

    Each record: means removed, identified on the first 70 %, fit % on the
    last 30 %. Writes one HTML report per dataset, index.html linking them,
    gallery.md (the table of docs/gallery.md) and summary.json.
    """
    import subid.cli.demo as demo_module
    _note_first_run()
    # The folder is replaced as a whole when the run completes (a previous demo's
    # folder, or an empty one): an interrupted run leaves the previous one.
    owned = lambda path: not os.listdir(path) or os.path.exists(  # noqa: E731
        os.path.join(path, "summary.json"))
    with atomic_directory(out, owned=owned) as stage:
        result = demo_module.run(stage, datasets=_names(names), methods=_names(methods),
                                 frequency_unit=frequency_unit, progress=_state().progress,
                                 jobs=jobs)
        final = os.path.abspath(out)
        for name in os.listdir(stage):          # the pages quote their folder: the final one
            if name.endswith((".html", ".md", ".json")):
                page = os.path.join(stage, name)
                with open(page, encoding="utf-8") as fh:
                    text = fh.read()
                if stage in text:
                    write_bytes(page, text.replace(stage, final))
    for key, value in list(result.items()):       # paths name the final folder
        if isinstance(value, str):
            result[key] = value.replace(stage, final)
        elif isinstance(value, list) and all(isinstance(v, str) for v in value):
            result[key] = [v.replace(stage, final) for v in value]
    if not _state().quiet:
        for name, rows in result["by_dataset"].items():
            click.echo(f"{name}: " + ", ".join(
                f"{r['method']} n={r['order']} val fit {_fmt_fit(r['fit_val'])}"
                if not r["error"] else f"{r['method']} failed" for r in rows))
        click.echo(f"wrote {result['index']} and {len(result['reports'])} reports "
                   f"({result['seconds']:.1f} s)")
    return 0


@cli.command(epilog="\b\nExample:\n  subid gallery --out docs/gallery.md")
@click.option("--out", default="docs/gallery.md", show_default=True, metavar="FILE",
              help="Markdown file to write.")
@click.option("--datasets", "names", default=None, metavar="NAMES",
              help="Comma-separated subset of the bundled datasets (default: all).")
@_common
def gallery(out, names):
    """Write the gallery table: fit % of the demo's default methods on every dataset.

    The discrete-time batch methods but armax, oe and bj, and ct_subspace.
    """
    import subid.cli.demo as demo_module
    text, rows = demo_module.gallery(datasets=_names(names), progress=_state().progress)
    directory = os.path.dirname(os.path.abspath(out))
    os.makedirs(directory, exist_ok=True)
    write_bytes(out, text, what="gallery")
    _echo(f"wrote {out} ({len(rows)} rows)")
    return 0
