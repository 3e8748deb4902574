"""``subid track``: an online identifier run over a record, with checkpoints, the
history of its estimates and a report."""

from __future__ import annotations

import contextlib
import os
import time

import click
import numpy as np

from subid._progress import Steps
from subid.cli._shared import (
    _FREQ,
    _TRACK_FILES,
    METHODS,
    _about,
    _carry_over,
    _check_method_options,
    _check_out,
    _command_line,
    _common,
    _convergence_status,
    _data_options,
    _default_detrend,
    _default_out,
    _detrend,
    _fmt_fit,
    _fmt_poles,
    _fmt_stable,
    _hint_method,
    _method_run_options,
    _named,
    _only,
    _parse_options,
    _provenance,
    _reserved_options,
    _run_online,
    _state,
    _warnings_to_log,
    cli,
    load_data,
    log,
    new_online,
)
from subid.errors import CheckpointError, DataError
from subid.io._files import atomic_directory

_RUN = _method_run_options(
    horizon="Horizon of the identifier (default: chosen by the method).",
    forgetting="recursive: forgetting factor in (0, 1], 1 (default) weighs all samples "
               "equally; adaptive: forgetting rate (see its documentation).",
    option="Extra keyword argument of the identifier (JSON value). Repeatable.",
    report="Write report.html.",
    out="Output folder: model.json, report.html, history.npz, checkpoints/ (default: "
        "NAME_track in the current folder, NAME the DATA file's name without its extension, "
        "or the dataset's name).")


@cli.command(epilog="\b\nExamples:\n"
                    "  subid track dataset:dryer --method recursive --order 4 --out track_out\n"
                    "  subid track plant.csv --inputs u --outputs y --dt 0.01 --method recursive "
                    "\\\n      --order 3 --forgetting 0.999 --checkpoint-every 50000 --out run\n"
                    "  subid track plant.csv --inputs u --outputs y --dt 0.01 --method recursive "
                    "\\\n      --resume run/checkpoints/checkpoint-0000050000.npz --out run")
@click.argument("data", metavar="DATA")
@_data_options
@click.option("--method", "method_name",
              type=click.Choice([n for n, s in METHODS.items() if s.kind == "online"]),
              default=None, help="Online identification method (default: recursive; with "
                                 "--resume, the checkpoint's).")
@click.option("--order", type=click.IntRange(min=1), default=None,
              help="Model order (required unless resuming).")
@_RUN["horizon"]
@_RUN["forgetting"]
@_RUN["option"]
@click.option("--chunk", type=click.IntRange(min=1), default=None,
              help="Samples fed per update (default: 1 % of the record, at most 1000).")
@click.option("--trace-every", type=click.IntRange(min=0), default=None,
              help="Samples between snapshots of the model for the convergence plot "
                   "(default: 1 % of the record; 0: only at the end).")
@click.option("--checkpoint-every", type=click.IntRange(min=0), default=10000,
              show_default=True, help="Write a checkpoint every K samples (0: only at the end).")
@click.option("--keep-checkpoints", type=click.IntRange(min=0), default=3, show_default=True,
              help="Keep the last N periodic checkpoints (0: keep all).")
@click.option("--resume", type=click.Path(dir_okay=False), default=None, metavar="CHECKPOINT",
              help="Continue from a checkpoint written by an earlier run on the same data.")
@_FREQ
@_RUN["report"]
@_RUN["out"]
@_common
def track(data, inputs, outputs, dt, time_column, delimiter, decimal, detrend, method_name, order,
          horizon, forgetting, options, chunk, trace_every, checkpoint_every, keep_checkpoints,
          resume, frequency_unit, write_report, out):
    """Run an online identifier over DATA and write the convergence report.

    Samples are fed in chunks (progress bar on a terminal); the model is
    snapshot every --trace-every samples for the convergence plot, and the
    identifier is checkpointed every --checkpoint-every samples (and at the
    end) so that --resume can continue. Writes model.json (final model),
    history.npz (snapshots), report.html and checkpoints/.
    """
    from subid.evaluation import report
    if out is None:
        out = _default_out(data, "track")
    resumed = None
    if resume is not None:
        with _about(resume):
            resumed, method_name = _resume_method(resume, method_name)
    spec = METHODS[method_name or "recursive"]
    spec.load()
    _hint_method(spec)
    opts = _parse_options(options)
    _check_method_options(spec, opts, reserved=_reserved_options(spec, horizon=horizon,
                                                                 forgetting=forgetting))
    from subid.methods.online.base import Tracker
    # the offsets the checkpoint's run removed (None: unknown), removed again
    offsets = None if resume is None else Tracker.stored_offsets(Tracker.trace_path(resume))
    with _about(data):
        raw, label, notes = load_data(data, inputs, outputs, dt, time_column, delimiter, decimal)
        detrend = detrend or _stored_detrend(offsets) or _default_detrend(spec)
        work = _detrend(raw, detrend) if resume is None else \
            _resumed_detrend(raw, detrend, offsets)
        if spec.time == "discrete" and work.dt is None:
            raise DataError(f"method {spec.name} needs uniformly sampled data; these time "
                            "stamps are non-uniform")
    n = work.n_samples
    chunk = chunk or max(1, min(1000, n // 100))
    trace_every = max(1, n // 100) if trace_every is None else trace_every
    checkpoint_dir = os.path.join(out, "checkpoints")
    _check_out(out, _TRACK_FILES)
    with _about(resume or data):
        if resume is not None:
            ident = resumed
            for attr, want in (("n_inputs", work.n_inputs), ("n_outputs", work.n_outputs)):
                have = getattr(ident, attr, want)
                if have != want:
                    raise DataError(f"the checkpoint has {have} {attr[2:]} but the data "
                                    f"have {want}")
            have, want = getattr(ident, "dt", None), work.dt
            if have is not None and want is not None and \
                    abs(have - want) > 1e-9 * max(abs(have), abs(want)):
                # before the rest of the record is fed (it failed only at the end, after
                # a pass over the record and a checkpoint written)
                raise DataError(f"the checkpoint was made with dt = {have:g} but the data are "
                                f"sampled with dt = {want:g}: pass --dt {have:g} (or the "
                                "time column of the checkpoint's run)")
            start = int(getattr(ident, "n_samples", 0))
            if start > n:
                raise DataError(f"the checkpoint has already seen {start} samples but the "
                                f"record has only {n}")
            for name, given in (("order", order), ("horizon", horizon),
                                ("forgetting", forgetting)):
                have = getattr(ident, name, None)
                if given is not None and have is not None and given != have:
                    log.warning("--%s %s ignored: the checkpoint has %s = %s", name, given,
                                name, have)
        else:
            if order is None:
                raise click.UsageError("--order is required (unless --resume is given)")
            ident = new_online(spec, order, work.n_inputs, work.n_outputs, horizon=horizon,
                               forgetting=forgetting, dt=work.dt, options=opts)
            start = 0
    os.makedirs(out, exist_ok=True)           # after the checks: a refused run leaves nothing
    tracker = Tracker(ident, work, fingerprint_data=raw, trace_every=trace_every,
                      checkpoint_every=checkpoint_every, checkpoint_dir=checkpoint_dir,
                      keep=keep_checkpoints)
    if resume is not None:
        with _warnings_to_log():
            tracker.load_trace(Tracker.trace_path(resume), start)
    t0 = time.perf_counter()
    with _about(data), _warnings_to_log():
        _run_online(spec, tracker, start, _state().progress, chunk=chunk)
        model = _named(ident.model, work)
    seconds = time.perf_counter() - t0
    steps = Steps(["evaluate", *(["report"] if write_report else []), "write"], "track",
                  enabled=_state().progress)
    click.get_current_context().call_on_close(steps.close)     # on errors too
    steps.start("evaluate")
    final_ckpt = tracker.checkpoint(n) if start < n or resume is None else resume
    model.info.setdefault("method", spec.attribute)
    model.info["data"] = _provenance(data, raw, work, detrend, work, 0.0)
    history = tracker.history()
    model_path = os.path.join(out, "model.json")
    history_path = os.path.join(out, "history.npz")
    report_path = os.path.join(out, "report.html")
    # the converged fit: the final model on the last third of the record (the
    # part an online estimate that has converged should explain)
    tail = work[2 * n // 3:] if n >= 3 else work
    fit_tail = report.evaluate(model, tail)["fit_estimation"]
    status = _convergence_status(model)
    model.info["fit_last_third"] = None if fit_tail is None else [float(v) for v in fit_tail]
    result = report.evaluate(model, work)
    html = None
    if write_report:
        steps.start("report")
        html = report.identification_report(
            {spec.name: model}, work, None, title=f"{label}: {spec.attribute} (online)",
            frequency_unit=frequency_unit, history=history, seconds={spec.name: seconds},
            notes=notes + [f"Samples {start}..{n} processed in this run"
                           + (f" (resumed from {resume})" if resume else "") +
                           f"; final checkpoint {final_ckpt}. Fit % is on the whole record; "
                           f"on its last third (the converged fit): {_fmt_fit(fit_tail)}. "
                           f"Convergence: {status}."],
            command=_command_line(), source=data, progress=steps.detail,
            fits={spec.name: result})
    steps.start("write")
    # The final outputs replace the folder as a whole (old run's or new run's,
    # never a mix); the checkpoints written during the run are carried over.
    with atomic_directory(out, owned=_only(_TRACK_FILES)) as stage:
        _carry_over(checkpoint_dir, os.path.join(stage, "checkpoints"))
        model.save(os.path.join(stage, "model.json"))
        tracker.save_trace(os.path.join(stage, "history.npz"), n)
        if html is not None:
            report.write_html(os.path.join(stage, "report.html"), html)
    steps.close()
    files = [model_path, *([report_path] if write_report else []), history_path]
    if not _state().quiet:
        click.echo("\n".join([
            f"data        {data}: {n} samples ({start} already seen, {n - start} processed now)",
            f"method      {spec.name} ({spec.attribute})",
            f"order       {model.order}",
            f"fit %       {_fmt_fit(result['fit_estimation'])} on the whole record, "
            f"{_fmt_fit(fit_tail)} on its last third ({', '.join(work.output_names)})",
            f"converged   {status}",
            f"poles       {_fmt_poles(result['poles'])}",
            f"stable      {_fmt_stable(result, model.dt == 0)}",
            f"snapshots   {len(history['sample'])}",
            f"time        {seconds:.2f} s",
            f"checkpoint  {final_ckpt}",
            f"wrote       {', '.join(files)}"]))
    return 0


def _resume_method(path, method_name):
    """The identifier of the checkpoint ``path`` and the name of its method; ``--method``
    (``method_name``, None when not given) must agree with the checkpoint."""
    from subid.methods.online.base import OnlineIdentifier
    from subid.methods.registry import MethodUnavailableError
    classes = {}
    for name, spec in METHODS.items():
        if spec.kind == "online":
            with contextlib.suppress(MethodUnavailableError):     # imported: load() finds it
                classes[name] = spec.load()
    ident = OnlineIdentifier.load(path)
    found = next((name for name, cls in classes.items() if type(ident) is cls), None)
    kind = f"subid.{type(ident).__name__}"
    if found is None:
        raise CheckpointError(f"{path} is a checkpoint of {kind}, which subid track does not "
                              "run; continue it in Python (subid.OnlineIdentifier.load)",
                              path=path)
    if method_name not in (None, found):
        raise CheckpointError(f"{path} is a checkpoint of {kind} (--method {found}), not of "
                              f"subid.{METHODS[method_name].attribute} (--method "
                              f"{method_name}); give --method {found} or leave --method out",
                              path=path)
    return ident, found


def _stored_detrend(offsets) -> str | None:
    """The --detrend of the run whose trace stored ``offsets`` (None: unknown)."""
    if offsets is None:
        return None
    return "none" if offsets[0].size == 0 else "constant" if offsets[0].ndim == 1 else "linear"


def _resumed_detrend(raw, detrend, offsets):
    """``raw`` detrended for a resumed run: less the means the checkpoint's run removed
    (stored beside the checkpoint), so that the samples the identifier has seen and the
    new ones lose the same means, as in an uninterrupted run, even when the record grew.
    A one-line warning when that cannot be done."""
    before = _stored_detrend(offsets)
    if detrend == "constant" and before == "constant" and \
            offsets[0].shape == (raw.n_inputs,) and offsets[1].shape == (raw.n_outputs,):
        return raw._less_offsets(*offsets)
    if before is not None and before != detrend:
        log.warning("--detrend %s: the run that wrote the checkpoint used --detrend %s, so the "
                    "samples it has seen and the new ones are detrended differently (leave "
                    "--detrend out to continue as it did)", detrend, before)
    elif detrend == "constant":
        log.warning("--detrend constant: the checkpoint does not hold the means of its run "
                    "(an earlier version of subid, or no convergence trace beside it); if the "
                    "record grew, its samples lost other means than the new ones (use "
                    "--detrend none for a growing record)")
    elif detrend == "linear":
        work = _detrend(raw, detrend)
        if before == "linear" and offsets[0].shape == work.u_offset.shape and \
                np.array_equal(offsets[0], work.u_offset) and \
                offsets[1].shape == work.y_offset.shape and np.array_equal(offsets[1], work.y_offset):
            return work                    # the same record: the same trend
        log.warning("--detrend linear: the samples the checkpoint has seen lost the trend of "
                    "its run's record, the new ones this record's; if the record grew they "
                    "differ (use --detrend none for a growing record)")
        return work
    return _detrend(raw, detrend)
