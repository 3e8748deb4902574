"""``subid identify``: a model from a record (in memory, streamed from a large file, or
from a frequency response), its report and summary."""

from __future__ import annotations

import os
import time

import click
import numpy as np

from subid._progress import Steps
from subid.cli._shared import (
    _FREQ,
    _IDENTIFY_FILES,
    IDENTIFY,
    METHODS,
    _about,
    _check_method_options,
    _check_out,
    _command_line,
    _common,
    _data_options,
    _default_detrend,
    _default_out,
    _detrend,
    _fmt_fit,
    _fmt_poles,
    _fmt_stable,
    _hint_method,
    _load_experiments,
    _method_run_options,
    _named,
    _nan_to_none,
    _note_first_run,
    _only,
    _parse_options,
    _parse_order,
    _provenance,
    _reserved_options,
    _run_online,
    _state,
    _warnings_to_log,
    _write_json,
    check_sources,
    cli,
    load_data,
    log,
    new_online,
    run_batch,
)
from subid.io._files import atomic_directory
from subid.methods.describe import AUTO_ORDER_RULE, describe_feedthrough
from subid.methods.describe import describe_order_selection as describe_selection

# -- identify ----------------------------------------------------------------
_RUN = _method_run_options(
    horizon="Block rows of the data Hankel matrix (default: chosen by the method).",
    forgetting="Forgetting of an online method (recursive: factor in (0, 1]; adaptive: "
               "rate, see its documentation).",
    option="Extra keyword argument of the method (JSON value), e.g. "
           "--option instruments=null. Repeatable.",
    report="Write report.html (skip it for batch jobs that need only the model).",
    out="Output folder for model.json, report.html and summary.json (default: "
        "NAME_identify in the current folder, NAME the first DATA's file name without its "
        "extension, or the dataset's name).")


@cli.command(epilog="\b\nExamples:\n"
                    "  subid identify dataset:dryer --method moesp --out dryer_out\n"
                    "  subid identify run1.csv --inputs u1,u2 --outputs y --dt 0.1 \\\n"
                    "      --method ls --order auto --validate 0.3 --out run1_out\n"
                    "  subid identify log.csv --inputs u --outputs y --time t --method ct "
                    "--order 2 --out ct_out\n"
                    "  subid identify run1.csv run2.csv --inputs u --outputs y --dt 0.1 "
                    "--method moesp --out runs_out")
@click.argument("data", metavar="DATA", nargs=-1, required=True)
@_data_options
@click.option("--method", "method_name", type=click.Choice(list(METHODS)), default=None,
              help="Identification method (see 'subid methods'). Default: subid.identify, "
                   "which chooses the subspace estimator, order, feedthrough and horizon "
                   "and refines by PEM where that validates better (with --stream: ls).")
@click.option("--order", default="auto", show_default=True, metavar="N|auto|A:B",
              help=f"Model order: an integer, 'auto' (discrete-time batch methods: "
                   f"{AUTO_ORDER_RULE}), a range '2:8' or a list '2,4,6' of candidates; for "
                   "arx, armax, oe, bj a list is MATLAB's structure, e.g. '2,2,1' = (na, nb, "
                   "nk) for arx, and a range is refused.")
@_RUN["horizon"]
@click.option("--validate", type=click.FloatRange(0, 1, max_open=True), default=0.3,
              show_default=True,
              help="Share of the record, at its end, kept for validation (0: none).")
@_RUN["forgetting"]
@_RUN["option"]
@_FREQ
@click.option("--refine", type=click.Choice(["none", "simulation", "prediction", "pem"]),
              default="none", show_default=True,
              help="Refine the model by prediction-error minimisation (subid.pem) on the "
                   "estimation part with this focus ('pem', deprecated: pem's default, "
                   "'prediction', or 'simulation' for a continuous-time model). "
                   "Without --method, subid.identify already decides on its own refinement; "
                   "with --frequency-response the model is refined by pem on the response "
                   "(as subid.identify does) unless --refine none.")
@_RUN["report"]
@click.option("--stream", is_flag=True, default=False,
              help="Read the file in pieces with bounded memory, for files larger than memory "
                   f"({', '.join(n for n, s in METHODS.items() if s.supports('streaming'))}"
                   "; uniform sampling). Fit and report use the first "
                   "--report-samples samples of each part.")
@click.option("--chunk-size", type=click.IntRange(min=1), default=100_000, show_default=True,
              help="Samples per piece with --stream.")
@click.option("--report-samples", type=click.IntRange(min=100), default=20_000,
              show_default=True, help="Samples of each part kept for the fit and the report "
                                      "with --stream.")
@_RUN["out"]
@click.option("--frequency-response", "frequency_response", is_flag=True, default=False,
              help="DATA is a frequency response (subid.read_frd: columns w or f [Hz] and "
                   "<output>/<input>:re,:im or :db/:mag,:phase; or .mat/.npz); identify it "
                   "with subid.fd_subspace (--dt: its sampling period, default the file's "
                   "'# dt =' line or Ts, else 0 = continuous time; --validate: share of the "
                   "frequencies held out, interleaved).")
@_common
def identify(data, inputs, outputs, dt, time_column, delimiter, decimal, detrend, method_name,
             order, horizon, validate, forgetting, options, frequency_unit, refine,
             write_report, stream, chunk_size, report_samples, out, frequency_response=False):
    """Identify a model from DATA; write model.json and report.html.

    The record is detrended, split into an estimation part (the first 1 -
    VALIDATE) and a validation part (the rest); the model is identified on the
    first and checked on both. Prints the order, fit % on the estimation and
    validation parts, the poles, stability and the time taken.

    Several DATA files are several experiments of one plant (subid.merge):
    no Hankel column crosses from one file to the next, each file has its own
    initial state and loses its own mean (--detrend constant); the validation
    part is the end of the last file. Batch methods only (not the online ones).
    """
    if out is None:
        out = _default_out(data[0], "identify")
    if decimal != "." and (frequency_response or stream):
        raise click.UsageError("--decimal , reads records in memory: it does not work with "
                               f"{'--frequency-response' if frequency_response else '--stream'}")
    if frequency_response:
        return _identify_frequency(data, dt, delimiter, order, horizon, validate, options,
                                   frequency_unit, refine, write_report, out,
                                   ignored=dict(inputs=inputs, outputs=outputs,
                                                time=time_column, detrend=detrend,
                                                forgetting=forgetting, stream=stream or None))
    # without --method: subid.identify, or with --stream (a statistic of the file, which
    # identify cannot refine) the SVD-free ls_subspace, the default before identify
    spec = METHODS[method_name] if method_name is not None else \
        (METHODS["ls"] if stream else IDENTIFY)
    _check_out(out, _IDENTIFY_FILES)
    _check_structure_order(spec, order)
    order = _parse_order(order)
    opts = _parse_options(options)
    _check_method_options(spec, opts, reserved=_reserved_options(spec, horizon=horizon,
                                                                 forgetting=forgetting))
    if forgetting is not None and spec.kind != "online":
        raise click.UsageError(f"--forgetting applies to online methods only, not to "
                               f"{spec.name}")
    spec.load()                                     # "not available" before any work
    _hint_method(spec)
    if stream and refine != "none":
        raise click.UsageError(f"--refine {refine} needs the samples in memory; it does not "
                               "work with --stream")
    sources = list(data)
    check_sources(sources, inputs, outputs)
    if len(sources) > 1:
        if stream:
            raise click.UsageError("--stream reads one file; several DATA files are merged as "
                                   "experiments in memory (drop --stream)")
        if not spec.supports("experiments"):
            takers = [n for n, s in METHODS.items() if s.supports("experiments")]
            raise click.UsageError(f"several DATA files are merged as experiments by the batch "
                                   f"methods ({', '.join(takers)}), not by {spec.name}, which "
                                   "would run over them joined as if contiguous: give one file")
    data = sources[0] if len(sources) == 1 else " + ".join(sources)
    _note_first_run()
    if stream:
        return _identify_streamed(data, inputs, outputs, dt, time_column, delimiter, detrend,
                                  spec, order, horizon, validate, opts, frequency_unit,
                                  write_report, chunk_size, report_samples, out)
    with _steps(write_report) as steps:
        return _identify_in_memory(sources, data, inputs, outputs, dt, time_column,
                                   (delimiter, decimal), detrend, spec, order, horizon,
                                   validate, forgetting, opts, refine, frequency_unit,
                                   write_report, out, steps)


def _check_structure_order(spec, text) -> None:
    """Refuse a range ``--order A:B`` for a method whose order is a polynomial structure
    (arx, armax, oe, bj): it takes no candidate orders, and ``_parse_order``'s list
    would be read as the structure (``2:4`` as na=2, nb=3, nk=4)."""
    if not spec.supports("polynomial") or ":" not in str(text):
        return
    from subid.methods.describe import _STRUCTURE_NAMES
    names = _STRUCTURE_NAMES.get(spec.name, ("na", "nb", "nk"))
    example = ",".join("1" if name == "nk" else "2" for name in names)
    raise click.BadParameter(
        f"{text!r}: {spec.name} takes no range of candidate orders; give its structure "
        f"'{','.join(names)}' (e.g. {example}), an integer n (every degree n) or 'auto' "
        "(the structure chosen by cross-validation)", param_hint="--order")


def _order_line(model) -> str:
    """The summary's order line: the order, a polynomial model's structure, and how the
    order was chosen (nothing about what does not apply, e.g. a horizon)."""
    from subid.methods.describe import describe_structure, structure_orders
    how = describe_selection(model.info["order_selection"]) \
        if model.info.get("order_selection") else ""
    structure = describe_structure(structure_orders(model.info))
    if structure and structure not in how:
        how = f"{structure}; {how}" if how else structure
    return f"order       {model.order}" + (f" ({how})" if how else "")


def _steps(write_report):
    """The progress bar over the steps of ``identify`` (on a terminal only)."""
    names = ["read", "identify", "evaluate", *(["report"] if write_report else []), "write"]
    return Steps(names, "identify", enabled=_state().progress)


def _identify_in_memory(sources, data, inputs, outputs, dt, time_column, text, detrend,
                        spec, order, horizon, validate, forgetting, opts, refine,
                        frequency_unit, write_report, out, steps):
    """``identify`` on a record read into memory (``text``: the text files' delimiter and
    decimal separator)."""
    from subid.evaluation import report
    steps.start("read")
    with _about(data):
        if len(sources) == 1:
            record, label, notes = load_data(data, inputs, outputs, dt, time_column, *text)
        else:
            record, label, notes = _load_experiments(sources, inputs, outputs, dt, time_column,
                                                     *text)
        detrend = detrend or _default_detrend(spec)
        work = _detrend(record, detrend)
        if work is not record:
            record = _RecordFacts(record)  # the raw samples are not needed any more: free them
        if validate > 0:
            est, val = work.split(1 - validate)
        else:
            est, val = work, None
        steps.start("identify")
        t0 = time.perf_counter()
        with _warnings_to_log():
            if spec.kind == "batch":
                model = run_batch(spec, est, order, horizon, opts)
            else:
                ident = new_online(spec, order, est.n_inputs, est.n_outputs, horizon=horizon,
                                   forgetting=forgetting, dt=est.dt, options=opts)
                from subid.methods.online.base import Tracker
                _run_online(spec, Tracker(ident, est), 0, _state().progress,
                            chunk=max(est.n_samples // 100, 1))
                model = _named(ident.model, est)
            if refine != "none":
                from subid.methods.dt.pem import pem
                # 'pem' (deprecated): pem's own default focus, 'prediction' for a
                # discrete-time model, 'simulation' for a continuous-time one
                model = pem(est, model, focus=None if refine == "pem" else refine)
        seconds = time.perf_counter() - t0
        steps.start("evaluate")
        result = report.evaluate(model, est, val)
    model.info.setdefault("method", spec.attribute)
    model.info["data"] = _provenance(data, record, work, detrend, est, validate)
    _write_outputs(out, data, spec, model, result, est, val, seconds, record,
                   title=f"{label}: {spec.attribute}", notes=notes, report_data=work,
                   write_report=write_report, frequency_unit=frequency_unit,
                   outputs=list(est.output_names), n_estimation=est.n_samples,
                   n_validation=val.n_samples if val is not None else 0, steps=steps)
    return 0


def _identify_frequency(data, dt, delimiter, order, horizon, validate, options, frequency_unit,
                        refine, write_report, out, *, ignored):
    """``identify --frequency-response``: subid.fd_subspace (and pem) on an FRData file."""
    import subid
    from subid.evaluation.frequency_report import evaluate_frequency, frequency_report
    ctx = click.get_current_context()
    if ctx.get_parameter_source("method_name") is not click.core.ParameterSource.DEFAULT:
        raise click.UsageError("--frequency-response identifies with fd_subspace; drop "
                               "--method")
    given = [k for k, v in ignored.items() if v]
    if given:
        raise click.UsageError(f"--frequency-response does not take --{given[0]} (the file "
                               "holds a frequency response, not input/output samples)")
    if len(data) != 1:
        raise click.UsageError("--frequency-response reads one DATA file")
    source = data[0]
    if refine == "prediction":
        raise click.UsageError("--refine prediction: a frequency response holds no noise "
                               "model to predict with; --frequency-response refines the "
                               "response by pem unless --refine none")
    # by default refined, as subid.identify does a frequency response (the subspace
    # model alone fitted a lightly damped structure at 23-96 %, refined 99.3-99.8 %)
    refine_pem = refine != "none" or \
        ctx.get_parameter_source("refine") is click.core.ParameterSource.DEFAULT
    _check_out(out, _IDENTIFY_FILES)
    order = _parse_order(order)
    opts = _parse_options(options)
    with _about(source):
        frd = subid.read_frd(source, dt=dt, delimiter=delimiter)
        est, val = frd, None
        if validate > 0:
            every = max(2, round(1 / validate))
            held = np.arange(frd.n_frequencies) % every == every - 1
            if 0 < held.sum() < frd.n_frequencies:
                est, val = frd[~held], frd[held]
        t0 = time.perf_counter()
        with _warnings_to_log():
            kwargs = dict(opts)
            if horizon is not None:
                kwargs["horizon"] = horizon
            model = subid.fd_subspace(est, order, **kwargs)
            if refine_pem:
                model = subid.pem(est, model)
        seconds = time.perf_counter() - t0
        result = evaluate_frequency(model, est, val)
    model.info["data"] = {"source": source, "n_frequencies": frd.n_frequencies,
                          "n_estimation": est.n_frequencies,
                          "n_validation": 0 if val is None else val.n_frequencies}
    model_path = os.path.join(out, "model.json")
    report_path = os.path.join(out, "report.html")
    summary_path = os.path.join(out, "summary.json")
    files = [model_path, *([report_path] if write_report else []), summary_path]
    html = frequency_report({"fd_subspace": model}, est, val, title=f"{source}: fd_subspace",
                            frequency_unit=frequency_unit, seconds={"fd_subspace": seconds},
                            command=_command_line(), source=source) if write_report else None
    summary = {
        "data": source, "method": "fd_subspace", "function": "fd_subspace",
        "order": model.order, "horizon": model.info.get("horizon"), "dt": model.dt,
        "outputs": list(frd.output_names),
        "n_estimation": est.n_frequencies,
        "n_validation": 0 if val is None else val.n_frequencies,
        **_fit_summary(result), "seconds": seconds, "files": files,
    }
    _save_run(out, model, html, summary)
    if not _state().quiet:
        timing = "continuous time" if frd.dt == 0 else f"dt = {frd.dt:g}"
        lines = [f"data        {source}: {frd.n_frequencies} frequencies "
                 f"({frd.w[0]:.4g} to {frd.w[-1]:.4g} rad per time unit), {frd.n_inputs} "
                 f"input(s), {frd.n_outputs} output(s), {timing}",
                 "method      fd_subspace (frequency-domain subspace)",
                 f"order       {model.order}"
                 + (f" ({describe_selection(model.info['order_selection'])})"
                    if model.info.get("order_selection") else ""),
                 f"fit %       estimation {_fmt_fit(result['fit_estimation'])} "
                 f"({est.n_frequencies} frequencies)",
                 "            validation " + (f"{_fmt_fit(result['fit_validation'])} "
                                              f"({val.n_frequencies} frequencies)"
                                              if val is not None else "— (--validate 0)"),
                 f"poles       {_fmt_poles(result['poles'])}",
                 f"stable      {_fmt_stable(result, frd.dt == 0)}"]
        if model.info.get("refined_by") == "pem":
            lines.append(f"refined     pem (frequency response, weights: "
                         f"{model.info['weighting']}): cost {model.info['start_cost']:.4g} "
                         f"-> {model.info['final_cost']:.4g}")
        lines += [f"time        {seconds:.2f} s", f"wrote       {', '.join(files)}"]
        click.echo("\n".join(lines))
    return 0


def _fit_summary(result) -> dict:
    """The fits, stability and poles of an evaluation, for summary.json."""
    return {"fit_estimation": _nan_to_none(result["fit_estimation"]),
            "fit_validation": _nan_to_none(result["fit_validation"]),
            "stable": bool(result["stable"]),
            "poles": [[float(z.real), float(z.imag)] for z in result["poles"]]}


def _save_run(out, model, html, summary) -> None:
    """model.json, report.html (when there is one) and summary.json into ``out``.

    The folder is replaced as a whole: it holds the previous run's outputs or
    this run's, never a mix (Ctrl-C or a full disk leave the previous run's)."""
    from subid.evaluation import report
    with atomic_directory(out, owned=_only(_IDENTIFY_FILES)) as stage:
        model.save(os.path.join(stage, "model.json"))
        if html is not None:
            report.write_html(os.path.join(stage, "report.html"), html)
        _write_json(os.path.join(stage, "summary.json"), summary)


def _write_outputs(out, data, spec, model, result, est, val, seconds, record, *, title, notes,
                   report_data, write_report, frequency_unit, outputs, n_estimation,
                   n_validation, steps, **extra):
    """Write model.json, report.html (optional) and summary.json; print the summary."""
    from subid.evaluation import report
    model_path = os.path.join(out, "model.json")
    report_path = os.path.join(out, "report.html")
    summary_path = os.path.join(out, "summary.json")
    files = [model_path, *([report_path] if write_report else []), summary_path]
    html = None
    if write_report:
        steps.start("report")
        html = report.identification_report(
            {spec.name: model}, est, val, title=title, frequency_unit=frequency_unit,
            seconds={spec.name: seconds}, notes=notes, command=_command_line(), source=data,
            data=report_data, progress=steps.detail, fits={spec.name: result})
    steps.start("write")
    from subid.methods.describe import structure_orders
    structure = structure_orders(model.info)
    summary = {
        "data": data, "method": spec.name, "function": spec.attribute, "order": model.order,
        **({"structure": structure} if structure else {}),
        "horizon": model.info.get("horizon"), "dt": model.dt, "outputs": outputs, **extra,
        "n_estimation": n_estimation, "n_validation": n_validation,
        **_fit_summary(result), "seconds": seconds, "files": files,
    }
    _save_run(out, model, html, summary)
    steps.close()
    _print_summary(data, record, spec, model, result, est, val, seconds, files)


def _identify_streamed(data, inputs, outputs, dt, time_column, delimiter, detrend, spec, order,
                       horizon, validate, opts, frequency_unit, write_report, chunk_size,
                       report_samples, out):
    """``identify --stream``: passes over the file in pieces, bounded memory.

    Pass 1 parses the file (on subid's threads), counts the samples and sums
    the channels (for the means and the estimation/validation cut); pass 2
    feeds the estimation part, means removed, to a
    :class:`~subid.HankelStatistic`; the method then reads the estimation part
    once more for the B, D, x0 regression (:mod:`subid.methods.dt._bd_pass`;
    not with ``bd_method='projection'``), so the model is the in-memory one.
    Passes 2 and 3 read the parsed values back from a temporary file of
    doubles (:class:`subid.methods.dt.stream.ParsedOnce`, deleted at the
    end), in consecutive stretches reduced on subid's threads and merged
    exactly; only the first ``report_samples`` samples of each part are read
    once more, for the fit and the report.
    """
    from subid.io.formats import read_chunks
    if not spec.supports("streaming"):
        streaming = [n for n, s in METHODS.items() if s.supports("streaming")]
        raise click.UsageError(f"--stream works with the batch methods {', '.join(streaming)}, "
                               f"not with {spec.name}")
    if data.startswith("dataset:") or time_column is not None:
        raise click.UsageError("--stream reads a uniformly sampled file: give a file and --dt, "
                               "not a bundled dataset or --time")
    detrend = detrend or "constant"
    if detrend == "linear":
        raise click.UsageError("--stream removes means (--detrend constant) or nothing "
                               "(--detrend none); a linear trend needs the whole record")
    from subid.methods.dt.stream import ParsedOnce
    notes: list[str] = []

    def make():
        return read_chunks(data, inputs, outputs, dt=dt, chunk_size=chunk_size,
                           delimiter=delimiter)
    # the file is parsed once; the later passes read the parsed doubles back
    pieces = ParsedOnce(make if dt is not None else _sampling_noted(make, data, notes))
    try:
        with _steps(write_report) as steps:
            return _identify_pieces(pieces, data, detrend, spec, order, horizon, validate,
                                    opts, frequency_unit, write_report, chunk_size,
                                    report_samples, out, steps, notes)
    finally:
        pieces.close()


def _sampling_noted(make, data, notes: list):
    """``make`` (the pieces of ``identify --stream`` without ``--dt``) that, on the first
    piece, warns as the in-memory path does and adds the note to ``notes``: time is
    counted in samples, and the column that looks like time stamps (read_chunks'
    :class:`SamplingWarning`), if any, with ``--dt`` to give its period (``--time`` is
    refused under --stream)."""
    import warnings

    from subid.errors import SamplingWarning

    def noted():
        pieces = iter(make())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SamplingWarning)
            first = next(pieces, None)
        column = None
        for w in caught:
            if isinstance(w.message, SamplingWarning):
                column = w.message.column
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if not notes:                # once, if the file is parsed again
            notes.append("No sampling period given (--dt): time is counted in samples "
                         "(dt = 1), frequencies in rad/sample." + ("" if column is None else
                         f" The column {column!r} looks like time stamps; --stream reads "
                         "uniformly sampled files without --time: add --dt with their "
                         "sampling period."))
            log.warning("%s: %s", data, notes[-1])
        if first is not None:
            yield first
            yield from pieces
    return noted


def _identify_pieces(pieces, data, detrend, spec, order, horizon, validate, opts,
                     frequency_unit, write_report, chunk_size, report_samples, out, steps,
                     notes=()):
    import types

    from subid.evaluation import report
    from subid.methods.dt.stream import identify_spooled

    def logged(fit, stat, order, horizon, options):
        with _warnings_to_log():
            return fit(stat, order, horizon=horizon, **options)
    steps.start("read")
    with _about(data):
        run = identify_spooled(pieces, spec.load(), spec.name, order, horizon, detrend=detrend,
                               validate=validate, report_samples=report_samples, options=opts,
                               on_step=steps.start, call=logged)
        model, est, val, first, n = run.model, run.est, run.val, run.first, run.n_samples
        seconds, u_mean, y_mean = run.seconds, run.u_mean, run.y_mean
        result = report.evaluate(model, est, val)
    model.info.setdefault("method", spec.attribute)
    model.info["data"] = {"source": str(data), "inputs": list(first.input_names),
                          "outputs": list(first.output_names), "detrend": detrend,
                          "n_estimation": run.n_estimation, "validation_fraction": float(validate),
                          "streamed": True, "report_samples": report_samples,
                          "u_offset": u_mean, "y_offset": y_mean}
    notes = [*notes, f"Streamed in pieces of {chunk_size} samples: identified from the "
             f"statistic of {run.n_estimation} samples; fit and figures use the first "
             f"{report_samples} samples of each part."]
    record = types.SimpleNamespace(dt=first.dt, n_samples=n, n_inputs=first.n_inputs,
                                   n_outputs=first.n_outputs)
    _write_outputs(out, data, spec, model, result, est, val, seconds, record,
                   title=f"{os.path.basename(data)}: {spec.attribute}", notes=notes,
                   report_data=est, write_report=write_report, frequency_unit=frequency_unit,
                   outputs=list(first.output_names), n_estimation=run.n_estimation,
                   n_validation=n - run.n_estimation, streamed=True, steps=steps)
    return 0


class _RecordFacts:
    """What the summary and the provenance need of a record, without its samples
    (so the in-memory ``identify`` holds one copy of the data, the detrended one)."""

    def __init__(self, record):
        self.input_names, self.output_names = record.input_names, record.output_names
        self.dt, self.has_time_stamps = record.dt, record.has_time_stamps
        self.n_samples, self.n_inputs, self.n_outputs = (record.n_samples, record.n_inputs,
                                                         record.n_outputs)




def _print_summary(source, record, spec, model, result, est, val, seconds, files):
    if _state().quiet:
        return
    timing = f"dt = {record.dt:g}" if record.dt is not None else "non-uniform time stamps"
    if record.dt == 1.0 and not getattr(record, "has_time_stamps", False):
        timing += " (time in samples)"
    lines = [f"data        {source}: {record.n_samples} samples, {record.n_inputs} input(s), "
             f"{record.n_outputs} output(s), {timing}",
             f"method      {spec.name} ({spec.attribute})",
             _order_line(model),
             *([f"feedthrough {text}"] if (text := describe_feedthrough(
                 model.info.get("feedthrough"), option="--option feedthrough=true",
                 input_names=est.input_names, output_names=est.output_names)) else []),
             f"outputs     {', '.join(est.output_names)}",
             f"fit %       estimation {_fmt_fit(result['fit_estimation'])} "
             f"({est.n_samples} samples)"]
    if val is not None:
        lines.append(f"            validation {_fmt_fit(result['fit_validation'])} "
                     f"({val.n_samples} samples)")
    else:
        lines.append("            validation — (--validate 0)")
    lines += [f"poles       {_fmt_poles(result['poles'])}",
              f"stable      {_fmt_stable(result, model.dt == 0)}"
              + (" (continuous time)" if model.dt == 0 else "")]
    if model.info.get("refined_by") == "pem":
        start, final = model.info["start_cost"], model.info["final_cost"]
        change = f" ({100 * (final - start) / start:+.2g} %)" if start else ""
        lines.append(f"refined     pem ({model.info['focus']} focus): cost "
                     f"{start:.4g} -> {final:.4g}{change}; {model.info['stop_reason']}")
    if model.noise_cov is not None:
        from subid.methods.dt.noise_model import FROM_RICCATI
        note = ""
        if model.K is not None:
            note = " (innovations, with Kalman gain K" + (
                "; from the Riccati equation, no samples at hand"
                if model.info.get("noise_cov_estimate") == FROM_RICCATI else "") + ")"
        lines.append("noise cov   " + "; ".join(
            " ".join(f"{v:.4g}" for v in row) for row in model.noise_cov) + note)
    lines += [
              f"time        {seconds:.2f} s",
              f"wrote       {', '.join(files)}"]
    click.echo("\n".join(lines))
