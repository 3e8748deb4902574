"""``subid compare``: models against a record (fit %, k-step prediction), with a figure
and an HTML page."""

from __future__ import annotations

import math
import os

import click
import numpy as np

from subid.cli._shared import (
    _about,
    _command_line,
    _common,
    _data_options,
    _detrend,
    _parse_steps,
    _state,
    _warnings_to_log,
    check_channel_order,
    cli,
    load_data,
    load_model,
)
from subid.io._files import atomic_write


# -- compare -----------------------------------------------------------------
@cli.command(epilog="\b\nExamples:\n"
                    "  subid compare ls_out/model.json moesp_out/model.json --data dataset:dryer\n"
                    "  subid compare out/model.json --data test.csv --inputs u --outputs y "
                    "--dt 0.1 --out cmp")
@click.argument("model_paths", metavar="MODEL...", nargs=-1, required=True)
@click.option("--data", "data_source", required=True, metavar="DATA",
              help="Data file or dataset:NAME to simulate on.")
@_data_options
@click.option("--out", default=None, type=click.Path(file_okay=False),
              help="Folder for compare.html and compare.png (default: the first model's "
                   "folder).")
@click.option("--steps", default="inf", show_default=True, metavar="K|inf",
              help="Prediction horizon: K-step-ahead predictions (subid.predict; the Kalman "
                   "predictor of a model with K) instead of the simulation (inf).")
@_common
def compare(model_paths, data_source, inputs, outputs, dt, time_column, delimiter, decimal,
            detrend, out, steps):
    """Fit % of one or more models on DATA, with an overlay plot.

    Every model is simulated (or, with --steps K, predicted K steps ahead)
    from a least-squares initial state (as subid.fit_percent and MATLAB's
    compare). Inputs and outputs default to the first model's channel names;
    the sampling period to its dt.
    """
    from subid.model.fit import fit_percent
    steps = _parse_steps(steps)
    from subid.evaluation import plot, report
    models, paths = {}, {}
    for path in model_paths:
        with _about(path):
            m = load_model(path)
        label = os.path.splitext(path)[0]
        while label in models:
            label += "'"
        models[label] = m
        paths[label] = path
    first = next(iter(models.values()))
    if inputs is None:
        inputs = ",".join(first.input_names)
    if outputs is None:
        outputs = ",".join(first.output_names)
    if dt is None and time_column is None and first.dt > 0 \
            and not data_source.startswith("dataset:"):
        dt = first.dt
    with _about(data_source):
        record, label, notes = load_data(data_source, inputs, outputs, dt, time_column,
                                         delimiter, decimal)
        work = _detrend(record, detrend or "constant")
    for name, m in models.items():
        check_channel_order(m.input_names, record.input_names, "inputs", paths[name])
        check_channel_order(m.output_names, record.output_names, "outputs", paths[name])
    fits = {}
    for name, m in models.items():
        with _about(paths[name]):
            if steps == math.inf:
                fits[name] = report.evaluate(m, work)["fit_estimation"]
            else:
                with _warnings_to_log():
                    fits[name] = fit_percent(m, work, steps=steps)
    what = "simulated" if steps == math.inf else f"{steps}-step predicted"
    out = out or os.path.dirname(os.path.abspath(model_paths[0]))
    os.makedirs(out, exist_ok=True)
    png = os.path.join(out, "compare.png")
    page = os.path.join(out, "compare.html")
    with _warnings_to_log():
        fig = plot.compare(work, models, title=f"{label}: {what} and measured outputs",
                           steps=steps)
    with atomic_write(png, "wb", what="figure") as fh:
        fig.savefig(fh, format="png", dpi=90)
    figure = report.figure_html(fig, f"{what} outputs from a least-squares initial state; "
                                "fit % in the legend")
    report.write_html(page, report.comparison_page(
        {name: fits[name] for name in models}, work.output_names,
        title=f"{label}: model comparison", source=data_source, n_samples=work.n_samples,
        what=what, figure=figure, command=_command_line()))
    if not _state().quiet:
        width = max(len(n) for n in models) + 2
        header = "model".ljust(width) + "  ".join(f"{n:>12}" for n in work.output_names)
        click.echo(f"fit % on {data_source} ({work.n_samples} samples, {what})")
        click.echo(header)
        for name in models:
            click.echo(name.ljust(width) + "  ".join(
                f"{v:12.2f}" if np.isfinite(v) else f"{'n/a':>12}" for v in fits[name]))
        click.echo(f"wrote {png}, {page}")
    return 0
