"""The job behind ``subid demo`` (and ``make demo``): the bundled DaISy datasets.

For each bundled dataset: remove the means, identify on the first 70 % of
the record with every available batch method but the slow polynomial ``armax``,
``oe`` and ``bj`` (order chosen automatically),
and measure the simulation fit on the last 30 %. :func:`run` writes one HTML
report per dataset (:mod:`subid.evaluation.report`), ``index.html`` linking them all,
``gallery.md`` (the table of ``docs/gallery.md``) and ``summary.json``.
:func:`gallery` computes only the table.

Command line: ``subid demo --out demo_out`` or ``subid gallery --out
docs/gallery.md``; ``python -m subid.cli.demo --out demo_out`` is an alias of
``subid demo``. Library functions here never print; they log.
"""

from __future__ import annotations

import functools
import logging
import os
import time
import warnings

import numpy as np

from subid import datasets
from subid._progress import Steps, progress_wrapper
from subid.errors import OptionError, SubidError
from subid.io._files import write_bytes, write_json
from subid.methods.describe import AUTO_ORDER_RULE

__all__ = ["evaluate", "identify_one", "diagnose", "report_dataset", "write_report", "run",
           "gallery", "gallery_markdown", "GALLERY_COMMAND", "FRACTION"]

log = logging.getLogger(__name__)

#: Share of each record used for identification (the rest validates).
FRACTION = 0.7
#: The command that regenerates docs/gallery.md.
GALLERY_COMMAND = "subid gallery --out docs/gallery.md"
#: An output whose validation-part mean is this many of its standard deviations away
#: from the estimation part's has moved to another operating point (:func:`diagnose`).
DRIFT = 0.5
#: A mean estimation fit (%) at least this good, with a negative validation fit: the
#: model explains the data it saw, not the rest.
GOOD_FIT = 50.0


#: Batch methods the demo and the gallery leave out unless named (``--methods``): the
#: polynomial models fitted by prediction-error minimisation, one per output, take
#: minutes on the multi-output records (bj alone 358 s of the 388 s demo measured after
#: issue 25), while every other method takes seconds.
SLOW_METHODS = ("armax", "oe", "bj")


def _methods(methods=None, time_base=None):
    from subid.methods.registry import METHODS, available_methods
    names = [name for name in available_methods("batch", time_base)
             if name not in SLOW_METHODS] if methods is None else list(methods)
    out = {}
    for name in names:
        if name not in METHODS or METHODS[name].kind != "batch":
            raise OptionError(f"unknown batch method {name!r}; available: "
                              f"{', '.join(available_methods('batch'))}")
        out[name] = METHODS[name]
    return out


def evaluate(name: str, methods=None, fraction: float = FRACTION):
    """Identify dataset ``name`` with each method.

    Parameters
    ----------
    name : str
        A bundled dataset (:func:`subid.datasets.names`).
    methods : list of str, optional
        Registry names (:data:`subid.registry.METHODS`) of batch methods; default
        every available one but ``armax``, ``oe`` and ``bj`` (:data:`SLOW_METHODS`).
    fraction : float
        Share of the record used for identification.

    Returns
    -------
    rows : list of dict
        One per method: ``dataset``, ``method``, ``function``, ``order``,
        ``horizon``, ``fit_est``, ``fit_val`` (arrays per output, from
        :func:`subid.fit_percent`), ``stable``, ``seconds``, ``cpu_seconds``,
        ``warnings``, ``error`` (message, or None).
    models : dict method -> StateSpace
    est, val : IOData
    """
    rows, models = [], {}
    for method in _methods(methods):
        row, model = identify_one(name, method, fraction)
        rows.append(row)
        if model is not None:
            models[method] = model
    est, val = _parts(name, fraction)
    return rows, models, est, val


@functools.lru_cache(maxsize=2)
def _parts(name: str, fraction: float):
    """The record ``name`` without its means, split: loaded once per process."""
    return datasets.load(name).detrend().split(fraction)


def identify_one(name: str, method: str, fraction: float = FRACTION):
    """One method on one dataset with the library defaults: ``(row, model)``.

    Parameters
    ----------
    name : str
        A bundled dataset.
    method : str
        A registry name of a batch method.
    fraction : float
        Share of the record used for identification.

    Returns
    -------
    row : dict
        The row of :func:`evaluate`; its fit % on both parts (from
        :func:`subid.evaluation.report.evaluate`) is what the report shows.
    model : StateSpace or None
        None when the method failed (its error is in the row).
    """
    from subid.evaluation.report import evaluate as fits
    spec = _methods([method])[method]
    est, val = _parts(name, fraction)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = spec.load()(est, order=None)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        r = fits(model, est, val)
    except SubidError as exc:
        log.info("%s: %s failed: %s", name, method, exc)
        return dict(dataset=name, method=method, function=spec.attribute, order=None,
                    horizon=None, fit_est=None, fit_val=None, stable=None,
                    seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - c0,
                    warnings=[], error=str(exc)), None
    return dict(dataset=name, method=method, function=spec.attribute, order=model.order,
                horizon=model.info.get("horizon"), fit_est=r["fit_estimation"],
                fit_val=r["fit_validation"], stable=r["stable"], seconds=seconds,
                cpu_seconds=cpu, warnings=sorted({str(w.message) for w in caught}),
                error=None), model


def _fit_text(values) -> str:
    if values is None:
        return "—"
    return " / ".join("n/a" if not np.isfinite(v) else
                      (f"{v:.3g}" if abs(v) >= 1e4 else f"{v:.1f}") for v in values)


def _mean_fit(values):
    if values is None:
        return None
    v = np.asarray(values, dtype=float)
    return float(np.mean(v)) if np.isfinite(v).all() else float("nan")


def _reason(error: str, width: int = 90) -> str:
    """The first line of an error message, cut to ``width`` characters."""
    line = str(error).strip().splitlines()[0] if str(error).strip() else "no message"
    return line if len(line) <= width else line[:width - 1] + "…"


def _cell(row) -> str:
    if row["error"]:
        return f"failed: {_reason(row['error'])}"
    mean = _mean_fit(row["fit_val"])
    text = "n/a" if not np.isfinite(mean) else (f"{mean:.3g}" if abs(mean) >= 1e4
                                                else f"{mean:.1f}")
    return f"{text} ({row['order']}{'' if row['stable'] else ', unstable'})"


def _split_message(text: str, limit: int = 160) -> tuple[str, str]:
    """An error message as (what is wrong, what it says to do): its first sentence or
    clause up to ``'; '`` (at most ``limit`` characters, on one line) and the rest."""
    text = " ".join(str(text).split())
    ends = [k for k in (text.find(". "), text.find("; ")) if k > 0]
    end = min(ends) if ends else len(text)
    what, advice = text[:end], text[end + 2:]
    if len(what) > limit:
        what = what[:limit - 1].rstrip() + "…"
    return what, advice


def diagnose(row, est, val) -> tuple[str, str, str] | None:
    """Why a demo result is bad, in one line, what to try, and where the report shows it.

    Parameters
    ----------
    row : dict
        A row of :func:`evaluate`.
    est, val : IOData
        The estimation and validation parts it was computed on.

    Returns
    -------
    (reason, hint, section) or None
        None for a result that is neither failed nor negative; ``section`` is
        the id of the report section that shows the problem.

    Notes
    -----
    The checks, in order: an error (its first sentence, and its advice; with too
    few samples, try a longer estimation part); no finite validation fit (the
    simulation diverges); an unstable model (with a good fit: the plant may be
    unstable itself); a negative mean validation fit where
    the output means of the validation part lie :data:`DRIFT` standard
    deviations or more from the estimation part's (the operating point moved: a
    model of deviations from
    the estimation means cannot fit, try ``--detrend linear``); a negative
    validation fit after a good estimation fit (:data:`GOOD_FIT`, the plant or
    the noise changed, or the model is over-fitted: try lower orders); otherwise
    the inputs explain little of the outputs (try the one-step predictor,
    ``--refine pem`` and ``compare --steps 1``).
    """
    name, method = row["dataset"], row["method"]
    command = f"subid identify dataset:{name} --method {method}"
    if row["error"]:
        what, advice = _split_message(row["error"])
        if "too few" in what:        # a longer estimation part
            hint = f"{command} --validate 0.2 --out {name}_{method}"
        else:
            hint = f"{command} --order 1:6 --debug --out {name}_{method}"
        return f"failed: {what}", (f"{advice}: " if advice else "") + hint, "summary"
    mean = _mean_fit(row["fit_val"])
    if mean is None:
        return None
    if not np.isfinite(mean):
        return ("the simulation diverges on the validation part",
                f"{command} --option stability=enforce --out {name}_{method}", "compare")
    if not row["stable"]:
        if mean >= 0:       # an unstable plant (ballbeam) gives an unstable model that fits
            return (f"a pole outside the stability region, yet the simulation fits "
                    f"({mean:.0f} %): the plant itself may be unstable",
                    f"if it is not, {command} --option stability=enforce --out "
                    f"{name}_{method}", "poles")
        return ("unstable model: its simulation drifts away",
                f"{command} --option stability=enforce --out {name}_{method}", "poles")
    if mean >= 0:
        return None
    fits = np.asarray(row["fit_val"], dtype=float)
    worst = int(np.argmin(fits))
    output = est.output_names[worst]
    spread = np.where(val.y.std(axis=0) > 0, val.y.std(axis=0), 1.0)
    drift = np.abs(val.y.mean(axis=0) - est.y.mean(axis=0)) / spread
    if drift.max() >= DRIFT:
        k = int(np.argmax(drift))
        return (f"the operating point moves: {est.output_names[k]}'s mean on the validation "
                f"part is {drift[k]:.1f} standard deviations from the estimation part's",
                f"{command} --detrend linear --out {name}_{method}", "data")
    fit_est = _mean_fit(row["fit_est"])
    if fit_est is not None and fit_est >= GOOD_FIT:
        return (f"fits the estimation part ({fit_est:.0f} %) but not the validation part "
                f"({output}: {fits[worst]:.0f} %): the plant changed or the order is too high",
                f"{command} --order 1:{max(1, row['order'] - 1)} --out {name}_{method}",
                "compare")
    return (f"the inputs explain little of {output} (estimation fit "
            f"{_fit_text(row['fit_est'])} %): unmeasured disturbances dominate",
            f"{command} --refine pem --out {name}_{method}, then subid compare --steps 1",
            "residuals")


def gallery_markdown(rows, *, command: str = GALLERY_COMMAND, seconds=None) -> str:
    """The gallery page (Markdown) from the rows of :func:`evaluate`."""
    by_ds: dict[str, dict] = {}
    for r in rows:
        by_ds.setdefault(r["dataset"], {})[r["method"]] = r
    methods = list(dict.fromkeys(r["method"] for r in rows))
    labels = {r["method"]: r["function"] for r in rows}
    lines = [
        "# Gallery: the bundled DaISy datasets",
        "",
        f"Each record has its means removed, is identified on the first {FRACTION:.0%} of its "
        f"samples with the order and horizon chosen automatically ({AUTO_ORDER_RULE}; "
        "`selection='cv'`; `ct_subspace`: the same cross-validation, its model simulated "
        "with its hold), and is "
        f"validated on the last {1 - FRACTION:.0%}: the model is simulated from a "
        "least-squares initial state and compared with the measured output.",
        "Fit % = 100 (1 − ‖y − ŷ‖ / ‖y − mean y‖) per output (`subid.fit_percent`); 100 is "
        "perfect, 0 is no better than the mean, and it can be negative.",
        "",
        "Reproduce this page with",
        "",
        "```sh",
        command,
        "```",
        "",
        "(`subid demo --out demo_out` computes the same numbers and also writes an HTML "
        "report per dataset.)",
        "",
        "## Validation fit % (mean over the outputs) and chosen order",
        "",
        "| dataset | samples | inputs × outputs | "
        + " | ".join(f"`{labels[m]}`" for m in methods) + " |",
        "|---|---:|---:|" + "---:|" * len(methods),
    ]
    for name, per in by_ds.items():
        meta = datasets.info(name)
        lines.append(f"| {name} | {meta['n_samples']} | {meta['n_inputs']} × "
                     f"{meta['n_outputs']} | "
                     + " | ".join(_cell(per[m]) if m in per else "—" for m in methods) + " |")
    lines += ["", "Cells: mean validation fit % (order); \"unstable\" marks a model with a pole "
              "outside the unit circle.", "",
              "## Per output", "",
              "| dataset | method | order | horizon | fit % estimation | fit % validation "
              "| stable |",
              "|---|---|---:|---:|---|---|---|"]
    for name, per in by_ds.items():
        for m in methods:
            r = per.get(m)
            if r is None:
                continue
            if r["error"]:
                lines.append(f"| {name} | `{labels[m]}` | — | — | failed: {_reason(r['error'])} "
                             "| | |")
                continue
            horizon = "—" if r["horizon"] is None else r["horizon"]   # polynomial methods
            lines.append(f"| {name} | `{labels[m]}` | {r['order']} | {horizon} | "
                         f"{_fit_text(r['fit_est'])} | {_fit_text(r['fit_val'])} | "
                         f"{'yes' if r['stable'] else 'NO'} |")
    lines += ["", "Outputs are listed in the order of `subid.datasets.info(name)['output_names']`."
              " The automatic order is a heuristic: on records without a clear gap it can pick "
              "a low order or one that gives an unstable model; pass candidate orders "
              "(`--order 2:8`) and compare the fits.", ""]
    if seconds is not None:
        lines += [f"Computed in {seconds:.1f} s.", ""]
    return "\n".join(lines)


def _gallery_methods(methods):
    """The discrete-time batch methods and the default continuous-time one (``ct``)."""
    return [name for name, spec in _methods(methods).items()
            if spec.time == "discrete" or name == "ct"]


def gallery(datasets=None, methods=None, progress=False):
    """Markdown of the gallery table (discrete-time methods and ``ct_subspace``) and its rows.

    Parameters
    ----------
    datasets : list of str, optional
        Default: every bundled dataset.
    methods : list of str, optional
        Default: every available discrete-time batch method but ``armax``, ``oe``
        and ``bj``, and ``ct``.
    progress : bool
        Show a progress bar (tqdm) over the datasets.

    Returns
    -------
    text : str
    rows : list of dict
    """
    names = datasets or _all_names()
    methods = _gallery_methods(methods)
    rows = []
    for name in _iterate(names, progress, "gallery"):
        r, _, _, _ = evaluate(name, methods)
        rows += r
    return gallery_markdown(rows), rows


def _all_names():
    return list(datasets.names())


def _iterate(names, progress, desc):
    wrap = progress_wrapper(desc, "dataset", enabled=bool(progress))
    return names if wrap is None else wrap(names)


def report_dataset(name: str, out: str, methods=None, frequency_unit="rad/s") -> dict:
    """Identify one dataset and write its report ``out/NAME.html``.

    Returns
    -------
    dict
        ``name``, ``rows`` (of :func:`evaluate`), ``path`` of the report,
        ``entry`` (the row of the index page) and ``seconds``.
    """
    t0 = time.perf_counter()
    rows, models, _, _ = evaluate(name, methods)
    result = write_report(name, out, rows, models, frequency_unit)
    result["seconds"] = time.perf_counter() - t0
    return result


def write_report(name: str, out: str, rows, models, frequency_unit="rad/s") -> dict:
    """Write the report ``out/NAME.html`` of models already identified.

    Parameters
    ----------
    name : str
        A bundled dataset.
    out : str
        Output folder.
    rows : list of dict
        The rows of :func:`evaluate` (their fit % is shown, not computed again).
    models : dict method -> StateSpace
    frequency_unit : {'rad/s', 'Hz'}

    Returns
    -------
    dict
        ``name``, ``rows``, ``path`` of the report, ``entry`` (the row of the
        index page), ``seconds`` and ``cpu_seconds`` (writing the report).
    """
    from subid.evaluation import report
    from subid.methods.registry import METHODS
    t0, c0 = time.perf_counter(), time.process_time()
    est, val = _parts(name, FRACTION)
    meta = datasets.info(name)
    notes = [meta["description"], f"Sampling: {meta['dt_note']}", f"Source: {meta['source']}"]
    if meta["notes"]:
        notes.append(meta["notes"])
    for r in rows:
        if r["warnings"]:
            notes.append(f"{r['method']}: " + "; ".join(r["warnings"]))
    if models:
        seconds = {r["method"]: r["seconds"] for r in rows if not r["error"]}
        errors = {r["method"]: r["error"] for r in rows if r["error"]}
        fits = {r["method"]: {"fit_estimation": r["fit_est"], "fit_validation": r["fit_val"],
                              "stable": r["stable"]} for r in rows if not r["error"]}
        html = report.identification_report(
            models, est, val, title=f"{name}: DaISy dataset",
            frequency_unit=frequency_unit, seconds=seconds, errors=errors, notes=notes,
            command=f"subid demo --datasets {name} --out {out}", source=f"dataset:{name}",
            fits=fits)
    else:
        html = report.failure_page(f"{name}: DaISy dataset",
                                   {r["method"]: r["error"] for r in rows})
    path = os.path.join(out, f"{name}.html")
    report.write_html(path, html)
    entry = {"name": name, "href": f"{name}.html", "samples": meta["n_samples"],
             "inputs × outputs": f"{meta['n_inputs']} × {meta['n_outputs']}", "notes": {}}
    for r in rows:
        column = METHODS[r["method"]].attribute
        entry[column] = _cell(r)
        why = diagnose(r, est, val)
        if why is not None:
            reason, hint, section = why
            entry["notes"][column] = (reason, hint, f"{name}.html#{section}")
    return {"name": name, "rows": rows, "path": path, "entry": entry,
            "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0}


#: Thread-count variables of the BLAS/OpenMP libraries, set to 1 in the worker
#: processes (one job per core; several BLAS threads per job would compete for them).
_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _worker_init():
    """Worker processes stay silent: the parent reports what they return. Each computes
    in one thread (subid's own too, :mod:`subid._threads`): the pool's processes already
    fill the CPUs."""
    from subid import _threads
    logging.getLogger("subid").addHandler(logging.NullHandler())
    logging.getLogger("subid").propagate = False
    warnings.simplefilter("ignore")
    _threads.limit = 1


def default_jobs(count: int) -> int:
    """Parallel jobs for ``count`` tasks: the CPUs available to this process."""
    return _default_jobs(count)


def _default_jobs(count: int) -> int:
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, count))


def _expected_cost(name: str, method: str) -> float:
    """A rough relative cost of ``method`` on dataset ``name``, to start the longest
    tasks first (longest-processing-time order keeps the pool busy to the end):
    samples x channels, with ``ct`` (a search over the basis scale, each candidate
    refined) several times the discrete-time methods (bench/demo_profile.md)."""
    meta = datasets.info(name)
    size = meta["n_samples"] * (meta["n_inputs"] + meta["n_outputs"])
    return size * (_CT_WEIGHT if method.startswith("ct") else 1.0)


#: How many times a discrete-time method's cost ``ct`` takes (bench/demo_profile.md).
_CT_WEIGHT = 4.0


class _Environment:
    """Set environment variables for a block (the spawned workers inherit them)."""

    def __init__(self, **values):
        self.values, self.saved = values, {}

    def __enter__(self):
        for key, value in self.values.items():
            self.saved[key] = os.environ.get(key)
            os.environ[key] = value
        return self

    def __exit__(self, *exc):
        for key, value in self.saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _in_pool(names, methods, out, frequency_unit, jobs, bar):
    """Every (dataset, method) identification as its own task in a pool of ``jobs``
    processes, longest first; a dataset's report is a task too, submitted when its
    last method is done. Returns ``{name: write_report result}``."""
    import concurrent.futures
    import multiprocessing
    columns = list(_methods(methods))
    tasks = sorted(((name, method) for name in names for method in columns),
                   key=lambda task: _expected_cost(*task), reverse=True)
    done = {name: {} for name in names}
    results = {}
    context = multiprocessing.get_context("spawn")     # no forked BLAS or numba state
    with _Environment(**{key: "1" for key in _THREAD_VARIABLES}), \
            concurrent.futures.ProcessPoolExecutor(jobs, mp_context=context,
                                                   initializer=_worker_init) as pool:
        pending = {pool.submit(identify_one, name, method): (name, method)
                   for name, method in tasks}
        while pending:
            finished, _ = concurrent.futures.wait(
                pending, return_when=concurrent.futures.FIRST_COMPLETED)
            for future in finished:
                name, method = pending.pop(future)
                if method is None:                       # a report
                    results[name] = future.result()
                    bar.finished(f"{name}: report")
                    continue
                done[name][method] = future.result()
                bar.finished(f"{name}: {method}")
                if len(done[name]) == len(columns):
                    rows = [done[name][m][0] for m in columns]
                    models = {m: done[name][m][1] for m in columns
                              if done[name][m][1] is not None}
                    pending[pool.submit(write_report, name, out, rows, models,
                                        frequency_unit)] = (name, None)
    return results


def run(out, datasets=None, methods=None, *, frequency_unit="rad/s", progress=False,
        jobs=1) -> dict:
    """Identify every dataset, write one report each, the index and the gallery.

    Parameters
    ----------
    out : str
        Output folder (created).
    datasets : list of str, optional
        Default: every bundled dataset.
    methods : list of str, optional
        Batch methods of the registry; default every available one but ``armax``,
        ``oe`` and ``bj`` (:data:`SLOW_METHODS`).
    frequency_unit : {'rad/s', 'Hz'}
    progress : bool
        Progress bar over the datasets.
    jobs : int or None
        Processes working at the same time (spawned, one BLAS thread each):
        every (dataset, method) identification is a task, and so is every
        dataset's report, the longest first. 1 (default) runs everything in
        this process, None uses the CPUs available. With more than 1, a
        script calling this function needs the usual
        ``if __name__ == "__main__":`` guard.

    Returns
    -------
    dict
        ``rows`` (all rows of :func:`evaluate`), ``by_dataset``, ``reports``
        (paths), ``index``, ``gallery``, ``summary``, ``seconds``.
    """
    from subid.evaluation import report
    from subid.methods.registry import METHODS
    names = list(datasets or _all_names())
    unknown = [n for n in names if n not in _all_names()]
    if unknown:
        from subid.errors import DataError
        raise DataError(f"unknown dataset(s) {', '.join(unknown)}; bundled: "
                        f"{', '.join(_all_names())}")
    _methods(methods)                                  # unknown names fail before any work
    os.makedirs(out, exist_ok=True)
    jobs = _default_jobs(len(names) * len(_methods(methods))) if jobs is None \
        else max(1, int(jobs))
    t0 = time.perf_counter()
    results = {}
    # one step per dataset in this process; in the pool, one per task (every
    # identification and every report), so that the bar moves from the start
    steps = names if jobs == 1 else [f"{name}: {task}" for name in names
                                     for task in [*_methods(methods), "report"]]
    bar = Steps(steps, "demo", enabled=bool(progress))    # elapsed time moves on
    try:
        if jobs == 1:
            for name in names:
                bar.start(name)
                results[name] = report_dataset(name, out, methods, frequency_unit)
        else:
            results = _in_pool(names, methods, out, frequency_unit, jobs, bar)
    finally:
        bar.close()
    all_rows, by_dataset, reports, entries = [], {}, [], []
    for name in names:                                 # the order asked for
        res = results[name]
        all_rows += res["rows"]
        by_dataset[name] = res["rows"]
        reports.append(res["path"])
        entries.append(res["entry"])
        for r in res["rows"]:
            if r["error"]:
                log.warning("%s: %s failed: %s", name, r["method"], r["error"])
        log.info("%s done: identification %.1f s (summed over the methods)", name,
                 sum(r["seconds"] for r in res["rows"]))
    seconds = time.perf_counter() - t0
    method_cols = list(dict.fromkeys(METHODS[r["method"]].attribute for r in all_rows))
    index = os.path.join(out, "index.html")
    report.write_html(index, report.index_page(
        entries, title="subid demo: bundled DaISy datasets",
        intro=(f"Each record: means removed, identified on the first {FRACTION:.0%} with the "
               f"order chosen automatically, validated on the last {1 - FRACTION:.0%}. "
               "Cells: mean validation fit % over the outputs (order). Click a dataset for "
               "its report." + _left_out(methods)),
        columns=["samples", "inputs × outputs", *method_cols],
        footer=f"{len(names)} datasets in {seconds:.1f} s. Reproduce with: subid demo "
               f"--out {out}"))
    shown = set(_gallery_methods(methods))
    gallery_rows = [r for r in all_rows if r["method"] in shown]
    gallery_path = os.path.join(out, "gallery.md")
    write_bytes(gallery_path, gallery_markdown(gallery_rows), what="gallery")
    summary_path = os.path.join(out, "summary.json")
    write_json(summary_path, {"seconds": seconds, "jobs": jobs,
                              "report_cpu_seconds": {name: results[name]["cpu_seconds"]
                                                     for name in names},
                              "rows": [_jsonable(r) for r in all_rows]},
               what="summary", indent=1)
    return {"rows": all_rows, "by_dataset": by_dataset, "reports": reports, "index": index,
            "gallery": gallery_path, "summary": summary_path, "seconds": seconds}


def _left_out(methods) -> str:
    """The index's sentence on the methods the default run leaves out, and how to run them."""
    if methods is not None:
        return ""
    from subid.methods.registry import available_methods
    slow = [m for m in SLOW_METHODS if m in available_methods("batch")]
    if not slow:
        return ""
    every = ",".join(available_methods("batch"))
    return (f" Left out: {', '.join(slow)} (polynomial models fitted by prediction-error "
            "minimisation, one per output: minutes on each multi-output record); run them "
            f"with: subid demo --methods {every}")


def _jsonable(row: dict) -> dict:
    out = {}
    for k, v in row.items():
        if isinstance(v, np.ndarray):
            v = [None if not np.isfinite(x) else float(x) for x in v]
        elif isinstance(v, (np.bool_, np.generic)):
            v = v.item()
        out[k] = v
    return out

