"""``subid simulate``: the response of a model file to an input file."""

from __future__ import annotations

import os

import click
import numpy as np

from subid.cli._shared import _about, _common, _echo, check_channel_order, cli, load_model
from subid.errors import DataError
from subid.io._files import atomic_write


# -- simulate ----------------------------------------------------------------
def _read_signals(path, columns, time_column, delimiter):
    """Columns of a file that holds only inputs (subid.read needs outputs too)."""
    from subid.io.formats import read_inputs
    return read_inputs(path, columns, time=time_column, delimiter=delimiter)


def _write_signals(path, t, u, y, input_names, output_names) -> None:
    ext = os.path.splitext(path)[1].lower()
    if ext == ".npz":
        with atomic_write(path, "wb", what="output file") as fh:
            np.savez(fh, t=t, u=u, y=y, input_names=np.array(input_names, dtype=str),
                     output_names=np.array(output_names, dtype=str))
        return
    if ext not in (".csv", ".txt", ".tsv"):
        raise click.UsageError(f"--out {path}: use a .csv, .tsv, .txt or .npz file name")
    delim = "\t" if ext == ".tsv" else ","
    header = delim.join(["time", *input_names, *output_names])
    with atomic_write(path, "wb", what="output file") as fh:
        np.savetxt(fh, np.column_stack([t, u, y]), delimiter=delim, header=header,
                   comments="", fmt="%.15g")


@cli.command(epilog="\b\nExamples:\n"
                    "  subid simulate out/model.json --input test_input.csv --out predicted.csv\n"
                    "  subid simulate ct_model.json --input u.csv --inputs u --time t --out y.csv")
@click.argument("model_path", metavar="MODEL")
@click.option("--input", "input_path", required=True, metavar="FILE",
              help="File with the input signals (CSV/TSV/TXT/DAT, NPZ or MAT).")
@click.option("--inputs", default=None, metavar="NAMES",
              help="Input columns (default: the model's input names).")
@click.option("--time", "time_column", default=None, metavar="COLUMN",
              help="Column with time stamps (needed for a continuous-time model unless --dt).")
@click.option("--dt", type=float, default=None, metavar="SECONDS",
              help="Sampling period of the input (default: the model's for discrete time).")
@click.option("--delimiter", default=None, metavar="CHAR", help="Delimiter of a text file.")
@click.option("--offsets/--no-offsets", default=True, show_default=True,
              help="Apply the means removed from the data before identification "
                   "(stored in the model by 'subid identify') so the output is in the "
                   "original units.")
@click.option("--hold", type=click.Choice(["zoh", "foh"]), default=None,
              help="Inter-sample input of a continuous-time model (default: the hold the "
                   "model assumes, e.g. foh for a ct model).")
@click.option("--out", required=True, metavar="FILE",
              help="Output file: .csv/.tsv/.txt (time, inputs, outputs) or .npz.")
@_common
def simulate(model_path, input_path, inputs, time_column, dt, delimiter, offsets, hold, out):
    """Simulate MODEL (JSON or .mat) with the inputs of a file, from a zero state."""
    from subid._validation import check_dt
    with _about(model_path):
        model = load_model(model_path)
        recorded = model.info.get("data") if isinstance(model.info, dict) else None
        if offsets and isinstance(recorded, dict) and recorded.get("detrend") == "linear":
            raise DataError("the model was identified with --detrend linear: the lines removed "
                            "are functions of the identification record's time, not an "
                            "operating point to add to another input; use --no-offsets "
                            "(deviations from the lines, of inputs detrended the same way), "
                            "or identify with --detrend constant to simulate in the data's "
                            "units")
    columns = inputs if inputs is not None else ",".join(model.input_names)
    if time_column is not None and dt is not None:
        raise click.UsageError("give either --time or --dt, not both")
    with _about(input_path):
        u, names, t = _read_signals(input_path, columns, time_column, delimiter)
        if u.shape[1] != model.n_inputs:
            raise DataError(f"{u.shape[1]} input column(s) selected but the model has "
                            f"{model.n_inputs} input(s)")
        check_channel_order(model.input_names, names, "inputs", model_path)
        n = u.shape[0]
        if t is None:
            step = check_dt(dt) if dt is not None else (model.dt if model.dt > 0 else None)
            if step is None:
                raise DataError("a continuous-time model needs the time stamps: give --time "
                                "COLUMN or --dt")
            t = step * np.arange(n)
        u_eff = u
        info = model.info.get("data") if isinstance(model.info, dict) else None
        applied = False
        if offsets and isinstance(info, dict) and info.get("detrend") == "constant" \
                and "u_offset" in info and np.ndim(info["u_offset"]) == 2:
            raise DataError("the model was identified on several experiments, each around its "
                            "own operating point (one row of offsets per experiment): there is "
                            "no single offset to add; use --no-offsets (deviations) or "
                            "subtract the operating point you want yourself")
        if offsets and isinstance(info, dict) and info.get("detrend") == "constant" \
                and "u_offset" in info:
            u_eff = u - np.asarray(info["u_offset"], dtype=float).reshape(1, -1)
            applied = True
        y = model.simulate(u_eff, t=t, hold=hold)
        if applied:
            y = y + np.asarray(info["y_offset"], dtype=float).reshape(1, -1)
    _write_signals(out, t, u, y, list(names), list(model.output_names))
    _echo(f"simulated {n} samples of {', '.join(model.output_names)}"
          + (" (with the identification offsets)" if applied else "") + f"; wrote {out}")
    return 0
