"""``subid convert``: a model file converted (sampled, made continuous, written as a
MATLAB file, JSON, or Python source for python-control or scipy): the options parsed here,
the conversion by :func:`subid.interop.convert_model`."""

from __future__ import annotations

import math
import os

import click

from subid.cli._shared import _about, _common, _echo, _state, cli, load_model


@cli.command(epilog="\b\nExamples:\n"
                    "  subid convert out/model.json --to dt=0.01     # resample (d2d / c2d)\n"
                    "  subid convert out/model.json --to ct          # continuous time (d2c)\n"
                    "  subid convert out/model.json --to mat         # MATLAB ss fields\n"
                    "  subid convert model.mat --to json --dt 0.1    # from MATLAB\n"
                    "  subid convert out/model.json --to control     # python-control script")
@click.argument("model_path", metavar="MODEL")
@click.option("--to", "target", required=True, metavar="dt=SECONDS|ct|mat|json|control|scipy",
              help="dt=T: discrete time with period T (from continuous time, or resampled); "
                   "ct: continuous time; mat: MATLAB ss(A,B,C,D,Ts) fields; json: subid model "
                   "file; control / scipy: a Python script building the python-control / "
                   "scipy.signal system.")
@click.option("--method", "conversion", type=click.Choice(["zoh", "foh", "bilinear"]),
              default=None, help="Discretisation method (c2d / d2c); default: the "
              "model's hold (zoh, or foh for a model identified with a first-order hold).")
@click.option("--dt", type=float, default=None,
              help="Sampling period for a .mat model whose Ts is -1 (unspecified).")
@click.option("--out", default=None, metavar="FILE",
              help="Output file (default: next to MODEL, named after the target; a model "
                   "file of that name already there, .json or .mat, is not replaced "
                   "unless named here).")
@_common
def convert(model_path, target, conversion, dt, out):
    """Convert MODEL (subid JSON or MATLAB .mat) to another time base or format."""
    from subid.interop import convert_model
    with _about(model_path):
        model = load_model(model_path, dt=dt)
    stem = os.path.splitext(model_path)[0]
    t = target.strip().lower()
    period = None
    if t.startswith("dt="):
        try:
            period = float(t[3:])
        except ValueError:
            raise click.BadParameter(f"{target!r}: use dt=SECONDS, e.g. dt=0.01",
                                     param_hint="--to") from None
        if not period > 0 or not math.isfinite(period):
            raise click.BadParameter(f"{target!r}: the period must be positive",
                                     param_hint="--to")
        to, path = "discrete", out or f"{stem}_dt{period:g}.json"
    elif t == "ct":
        to, path = "continuous", out or f"{stem}_ct.json"
    elif t in ("mat", "json"):
        to, path = t, out or f"{stem}.{t}"
        if t == "json" and os.path.abspath(path) == os.path.abspath(model_path):
            raise click.UsageError(f"{model_path} is already a JSON model; give --out")
        if out is None and os.path.exists(path):
            # the default name is another model file of the same stem: the model.json of
            # `subid identify` (its info: operating point, diagnostics) beside the .mat
            # converted from it, or a MATLAB file beside the JSON; not replaced unasked
            raise click.UsageError(f"{path} exists (the default output of --to {t} for "
                                   f"{model_path}); give --out FILE to write elsewhere, or "
                                   f"--out {path} to replace it")
    elif t in ("control", "scipy"):
        to, path = t, out or f"{stem}_{t}.py"
    else:
        raise click.BadParameter(f"{target!r}: use dt=SECONDS, ct, mat, json, control or "
                                 "scipy", param_hint="--to")
    with _about(model_path):
        what = convert_model(model, path, to, dt=period, method=conversion, source=model_path)
    _echo(f"wrote {path} ({what})")
    if t == "control" and not _state().quiet:
        click.echo(str(model.to_control()))
    return 0
