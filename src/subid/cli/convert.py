"""``subid convert``: a model file converted (sampled, made continuous, written as a
MATLAB file, JSON, or Python source for python-control or scipy)."""

from __future__ import annotations

import math
import os

import click
import numpy as np

from subid._validation import same_period
from subid.cli._shared import _about, _common, _echo, _state, cli, load_model
from subid.io._files import write_bytes

# -- convert -----------------------------------------------------------------
_PY_TEMPLATE = '''"""{what} written by subid convert from {source}."""
import numpy as np
{import_line}

A = np.array({A!r})
B = np.array({B!r})
C = np.array({C!r})
D = np.array({D!r})
{build}
'''


def _operating_point_source(model) -> str:
    """Python lines stating the operating point (the means removed by --detrend)."""
    from subid.evaluation.report import operating_point
    point = operating_point(model)
    if point is None:
        return ""
    u0, y0 = point
    return ("# The model relates deviations from the operating point, the channel means\n"
            "# removed before identification: in the data's units y = G(u - u0) + y0.\n"
            f"u0 = np.array({u0.tolist()!r})  # {', '.join(model.input_names)}\n"
            f"y0 = np.array({y0.tolist()!r})  # {', '.join(model.output_names)}\n")


def _python_source(model, target: str, source: str) -> str:
    mats = {k: getattr(model, k).tolist() for k in "ABCD"}
    if target == "control":
        dt = model.dt
        build = (f"sys = control.ss(A, B, C, D, {dt!r}, inputs={list(model.input_names)!r}, "
                 f"outputs={list(model.output_names)!r})")
        return _PY_TEMPLATE.format(what="python-control model", source=source,
                                   import_line="import control", build=build, **mats) \
            + _operating_point_source(model)
    build = "sys = signal.StateSpace(A, B, C, D)" if model.dt == 0 else \
        f"sys = signal.StateSpace(A, B, C, D, dt={model.dt!r})"
    return _PY_TEMPLATE.format(what="scipy.signal model", source=source,
                               import_line="from scipy import signal", build=build, **mats) \
        + _operating_point_source(model)


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
              default="zoh", show_default=True, help="Discretisation method (c2d / d2c).")
@click.option("--dt", type=float, default=None,
              help="Sampling period for a .mat model whose Ts is -1 (unspecified).")
@click.option("--out", default=None, metavar="FILE",
              help="Output file (default: next to MODEL, named after the target).")
@_common
def convert(model_path, target, conversion, dt, out):
    """Convert MODEL (subid JSON or MATLAB .mat) to another time base or format."""
    from subid.io.interop import save_mat
    with _about(model_path):
        model = load_model(model_path, dt=dt)
    stem = os.path.splitext(model_path)[0]
    t = target.strip().lower()
    with _about(model_path):
        if t.startswith("dt="):
            try:
                new_dt = float(t[3:])
            except ValueError:
                raise click.BadParameter(f"{target!r}: use dt=SECONDS, e.g. dt=0.01",
                                         param_hint="--to") from None
            if not new_dt > 0 or not math.isfinite(new_dt):
                raise click.BadParameter(f"{target!r}: the period must be positive",
                                         param_hint="--to")
            if model.dt == 0:
                result = model.to_discrete(new_dt, conversion)
            elif same_period(new_dt, model.dt):
                result = model
            else:
                result = model.to_continuous(conversion).to_discrete(new_dt, conversion)
            path = out or f"{stem}_dt{new_dt:g}.json"
            result.save(path)
            what = f"discrete-time model, dt = {new_dt:g} ({conversion})"
        elif t == "ct":
            result = model.to_continuous(conversion)
            path = out or f"{stem}_ct.json"
            result.save(path)
            what = f"continuous-time model ({conversion})"
        elif t == "mat":
            path = out or f"{stem}.mat"
            save_mat(model, path)
            what = "MATLAB ss fields A, B, C, D, Ts, InputName, OutputName"
            from subid.evaluation.report import operating_point
            if (point := operating_point(model)) is not None:
                what += ("; the model is around the operating point u0 = "
                         f"{np.round(point[0], 6).tolist()}, y0 = "
                         f"{np.round(point[1], 6).tolist()} (not stored in the .mat file)")
        elif t == "json":
            path = out or f"{stem}.json"
            if os.path.abspath(path) == os.path.abspath(model_path):
                raise click.UsageError(f"{model_path} is already a JSON model; give --out")
            model.save(path)
            what = "subid model file"
        elif t in ("control", "scipy"):
            if t == "control":
                model.to_control()          # ImportError with an install hint if missing
            path = out or f"{stem}_{t}.py"
            write_bytes(path, _python_source(model, t, model_path), what="script")
            what = "python-control script" if t == "control" else "scipy.signal script"
        else:
            raise click.BadParameter(f"{target!r}: use dt=SECONDS, ct, mat, json, control or "
                                     "scipy", param_hint="--to")
    _echo(f"wrote {path} ({what})")
    if t == "control" and not _state().quiet:
        click.echo(str(model.to_control()))
    return 0
