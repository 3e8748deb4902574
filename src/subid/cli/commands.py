"""The ``subid`` command line.

::

    subid identify DATA --inputs u1,u2 --outputs y1 --dt 0.1 --method ls --out DIR
    subid track DATA --inputs u --outputs y --method recursive --order 4 --out DIR
    subid simulate MODEL --input FILE --out FILE
    subid compare MODEL... --data FILE
    subid convert MODEL --to dt=0.01|ct|mat|json|control|scipy
    subid demo --out demo_out
    subid gallery --out docs/gallery.md
    subid methods

``DATA`` is a file (CSV/TSV/TXT/DAT, ``.npz`` or ``.mat``, see
:func:`subid.read`) or ``dataset:NAME`` for a bundled DaISy record
(``subid methods`` lists both). User errors (bad column names, missing or
empty files, non-numeric cells, unusable data) print one line naming the
file and the problem and exit with status 2; ``--debug`` adds the traceback.
Progress bars appear only on a terminal and never with ``--quiet``.

Identification methods are looked up in :data:`subid.registry.METHODS`
(:data:`METHODS` here: those the command line offers), which imports each
method's module only when it is used, so a method whose module is absent
from this version is reported as "not available" instead of breaking the
tool. The options ``--option KEY=VALUE`` accepts are the registry's
``MethodSpec.options``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import shlex
import sys
import time
import traceback
import warnings

import click
import numpy as np

from subid._progress import Steps, on_terminal, progress_bar
from subid._validation import same_period
from subid._version import __version__
from subid.errors import DataError, OrderError, SubidError
from subid.io._files import atomic_directory, atomic_write, write_bytes
from subid.methods.dt._selection import AUTO_ORDER_RULE
from subid.methods.dt._selection import describe as describe_selection
from subid.methods.registry import METHODS as _REGISTRY
from subid.methods.registry import MethodSpec, MethodUnavailableError

__all__ = ["main", "METHODS", "MethodSpec", "MethodUnavailableError", "available_methods"]

log = logging.getLogger("subid.cli")

EXIT_USER_ERROR = 2


# ---------------------------------------------------------------------------
# method registry (subid.registry; the command line offers the methods marked
# command_line)
# ---------------------------------------------------------------------------
#: The methods ``--method`` offers, by name (a view of :data:`subid.registry.METHODS`).
METHODS: dict[str, MethodSpec] = {name: spec for name, spec in _REGISTRY.items()
                                  if spec.command_line}

#: ``subid identify`` without ``--method``: :func:`subid.identify` (estimator, order,
#: feedthrough, horizon and refinement chosen from the data). Not a registry entry: it
#: chooses among the registered discrete-time methods (and routes continuous time).
IDENTIFY = MethodSpec(
    "identify", "batch", "subid.methods.identify", "identify", "discrete",
    "the best model the data support: subspace estimator, order and feedthrough chosen, "
    "refined by PEM where that validates better (subid.identify)",
    options=("focus", "time_base", "horizon", "feedthrough", "refine"),
    capabilities=frozenset({"order_selection", "horizon", "x0", "refine", "nonuniform"}))


def available_methods(kind: str | None = None, time_base: str | None = None) -> list[str]:
    """Names of the command-line methods whose module is present.

    Parameters
    ----------
    kind : {'batch', 'online'}, optional
    time_base : {'discrete', 'continuous'}, optional
    """
    return [name for name, spec in METHODS.items()
            if (kind is None or spec.kind == kind)
            and (time_base is None or spec.time == time_base) and spec.available()]


def _parse_steps(text) -> float | int:
    """``--steps``: a positive integer or 'inf'."""
    if str(text).strip().lower() in ("inf", "infinity"):
        return math.inf
    try:
        k = int(text)
    except ValueError:
        k = 0
    if k < 1:
        raise click.BadParameter(f"--steps must be a positive integer or 'inf', got {text!r}")
    return k


def run_batch(spec: MethodSpec, data, order, horizon=None, options=None):
    """Identify ``data`` with the batch method ``spec``."""
    fn = spec.load()
    kwargs = dict(options or {})
    if horizon is not None:
        if not spec.accepts("horizon"):
            raise SubidError(f"method {spec.name} has no horizon option")
        kwargs["horizon"] = horizon
    return fn(data, order=order, **kwargs)


def new_online(spec: MethodSpec, order, n_inputs, n_outputs, *, horizon=None, forgetting=None,
               dt=None, options=None):
    """A fresh online identifier of the method ``spec``."""
    cls = spec.load()
    if order is None or isinstance(order, list):
        raise OrderError(f"method {spec.name} identifies online with a fixed order: give "
                         "--order N (an integer)")
    kwargs = dict(options or {})
    if horizon is not None:
        kwargs["horizon"] = horizon
    if forgetting is not None:
        kwargs["forgetting"] = forgetting
    if dt is not None:
        kwargs["dt"] = dt
    return cls(order, n_inputs, n_outputs, **kwargs)


def _named(model, data):
    """``model`` with the channel names of ``data`` (online identifiers use u1, y1...)."""
    from subid.methods.online.base import with_names
    return with_names(model, data)


def load_online(spec: MethodSpec, path):
    """Restore an online identifier from a checkpoint."""
    return spec.load().load(path)


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------
class _State:
    """Options shared by every command."""

    def __init__(self):
        self.quiet = False
        self.debug = False
        self.verbose = False
        self.argv: list[str] = []

    @property
    def progress(self) -> bool:
        return on_terminal(self.quiet)


def _state() -> _State:
    return click.get_current_context().find_root().ensure_object(_State)


def _common(fn):
    """``--quiet``, ``--verbose``, ``--debug`` on a subcommand too."""
    def set_flag(name):
        def callback(ctx, param, value):
            if value:
                setattr(ctx.find_root().ensure_object(_State), name, True)
                _configure_logging(ctx.find_root().ensure_object(_State))
            return value
        return callback
    fn = click.option("--debug", is_flag=True, expose_value=False, callback=set_flag("debug"),
                      help="Show tracebacks and debug messages.")(fn)
    fn = click.option("--verbose", "-v", is_flag=True, expose_value=False,
                      callback=set_flag("verbose"), help="Show informational messages.")(fn)
    fn = click.option("--quiet", "-q", is_flag=True, expose_value=False,
                      callback=set_flag("quiet"),
                      help="No progress bar and no summary; only errors.")(fn)
    return fn


_HANDLER: logging.Handler | None = None


def _configure_logging(state: _State) -> None:
    logger = logging.getLogger("subid")
    level = logging.DEBUG if state.debug else logging.INFO if state.verbose else \
        logging.ERROR if state.quiet else logging.WARNING
    if _HANDLER is not None:
        _HANDLER.setLevel(level)
    logger.setLevel(level)


def _echo(text: str = "") -> None:
    if not _state().quiet:
        click.echo(text)


@contextlib.contextmanager
def _about(path):
    """Prefix errors raised inside with the file they concern (if not named yet)."""
    try:
        yield
    except SubidError as exc:
        if getattr(exc, "subid_file", None) is None and str(path) not in str(exc):
            exc.subid_file = str(path)
        raise


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and not isinstance(exc, SubidError) and exc.strerror:
        name = exc.filename if exc.filename is not None else ""
        text = f"{name}: {exc.strerror}" if name else exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    where = getattr(exc, "subid_file", None)
    if where:
        text = f"{where}: {text}"
    return " ".join(text.split())


def _usage_line(exc: click.UsageError) -> str:
    """A usage error as one line: the problem and where to read the usage."""
    text = " ".join(exc.format_message().split())
    ctx = exc.ctx
    if ctx is not None:
        text += f" (see '{ctx.command_path} --help')"
    return text


def _parse_order(text):
    """'auto' -> None; '4' -> 4; '2:6' -> [2..6]; '2,3,5' -> [2, 3, 5]."""
    if text is None:
        return None
    s = str(text).strip().lower()
    if s in ("auto", ""):
        return None
    try:
        if ":" in s:
            a, b = (int(v) for v in s.split(":"))
            if b < a:
                raise ValueError
            return list(range(a, b + 1))
        if "," in s:
            return [int(v) for v in s.split(",") if v.strip()]
        return int(s)
    except ValueError:
        raise click.BadParameter(f"{text!r}: use an integer, 'auto', a range '2:8' or a list "
                                 "'2,4,6'", param_hint="--order") from None


def _parse_options(items) -> dict:
    """``--option KEY=VALUE`` items -> keyword arguments (VALUE parsed as JSON if it is).

    A missing ``=``, an empty key or a key given twice is a usage error.
    """
    out = {}
    for item in items or ():
        if "=" not in item:
            raise click.BadParameter(f"{item!r}: use KEY=VALUE", param_hint="--option")
        key, value = item.split("=", 1)
        key = key.strip().replace("-", "_")
        if not key.isidentifier():
            raise click.BadParameter(f"{item!r}: KEY must be an option name, as in "
                                     "instruments=null", param_hint="--option")
        if key in out:
            raise click.BadParameter(f"{key} given twice; give each KEY once",
                                     param_hint="--option")
        try:
            out[key] = json.loads(value)
        except ValueError:
            out[key] = value
    return out


def _check_method_options(spec: MethodSpec, options: dict, *, reserved=()) -> None:
    """Reject ``--option`` keys the method does not take (a usage error, exit 2).

    ``reserved`` are keyword arguments the command passes itself (``order``,
    and ``horizon`` when ``--horizon`` is given...): giving them again through
    ``--option`` is a usage error too, not a ``TypeError`` from the call.
    """
    if not options:
        return
    names = list(spec.options)
    for key in options:
        if key in reserved:
            raise click.BadParameter(f"{key} is set by its own command-line option "
                                     f"(--{key.replace('_', '-')}), not by --option",
                                     param_hint="--option")
        if key not in names:
            accepted = [n for n in names if n not in reserved]
            raise click.BadParameter(
                f"method {spec.name} has no option {key!r}; its options are: "
                f"{', '.join(accepted) or '(none)'}", param_hint="--option")


def _reserved_options(spec: MethodSpec, *, horizon=None, forgetting=None) -> set:
    """Keyword arguments a command passes to ``spec`` itself."""
    reserved = {"order"}
    if horizon is not None:
        reserved.add("horizon")
    if forgetting is not None:
        reserved.add("forgetting")
    if spec.kind == "online":
        reserved |= {"n_inputs", "n_outputs", "dt"}
    return reserved


def _names(spec) -> list[str] | None:
    if spec is None:
        return None
    return [s.strip() for s in str(spec).split(",") if s.strip()]


def load_data(source: str, inputs=None, outputs=None, dt=None, time_column=None,
              delimiter=None):
    """The record named on the command line: a file or ``dataset:NAME``.

    Returns
    -------
    data : IOData
    label : str
        Short name for titles.
    notes : list of str
        Provenance notes for the report.
    """
    from subid import datasets, read
    from subid.data import IOData
    if source.startswith("dataset:"):
        name = source.split(":", 1)[1]
        data = datasets.load(name)
        meta = datasets.info(name)
        if time_column is not None:
            raise DataError(f"{source}: the bundled datasets are uniformly sampled; --time "
                            "does not apply")
        notes = [meta["description"], f"Sampling: {meta['dt_note']}", f"Source: {meta['source']}"]
        if inputs is not None or outputs is not None or dt is not None:
            u_idx = _select(data.input_names, inputs, "inputs", source)
            y_idx = _select(data.output_names, outputs, "outputs", source)
            data = IOData(data.u[:, u_idx], data.y[:, y_idx],
                          dt=dt if dt is not None else data.dt,
                          input_names=[data.input_names[k] for k in u_idx],
                          output_names=[data.output_names[k] for k in y_idx])
        return data, meta["name"], notes
    data = read(source, inputs=inputs, outputs=outputs, dt=dt, time=time_column,
                delimiter=delimiter)
    notes = [f"Data file: {source}"]
    if dt is None and time_column is None and data.dt == 1.0 and not data.has_time_stamps:
        notes.append("No sampling period given (--dt) and no time column (--time): time is "
                     "counted in samples (dt = 1), frequencies in rad/sample.")
        log.warning("%s: %s", source, notes[-1])
    return data, os.path.basename(source), notes


def _load_experiments(sources, inputs, outputs, dt, time_column, delimiter):
    """Several DATA arguments as one record of several experiments (:func:`subid.merge`)."""
    from subid.data import merge
    loaded = []
    for source in sources:
        try:
            loaded.append(load_data(source, inputs, outputs, dt, time_column, delimiter))
        except SubidError as exc:          # name this file, not the list
            if getattr(exc, "subid_file", None) is None:
                exc.subid_file = "" if source in str(exc) else source
            raise
    labels = [label for _, label, _ in loaded]
    names = labels if len(set(labels)) == len(labels) else list(sources)
    if len(set(names)) != len(names):
        raise DataError(f"the same DATA is given twice: {', '.join(sources)}")
    record = merge([r for r, _, _ in loaded], names=names)
    notes = [note for _, _, ns in loaded for note in ns]
    notes.append(f"{len(sources)} experiments merged (subid.merge): "
                 + ", ".join(f"{n} ({b - a} samples)" for n, (a, b)
                             in zip(record.experiment_names, record.experiment_ranges))
                 + "; no Hankel column crosses from one to the next, one x0 each.")
    return record, " + ".join(labels), notes


def _select(names, spec, role, source) -> list[int]:
    if spec is None:
        return list(range(len(names)))
    out = []
    for token in _names(spec):
        if token in names:
            out.append(names.index(token))
        elif token.isdigit() and int(token) < len(names):
            out.append(int(token))
        else:
            raise DataError(f"{source}: unknown channel {token!r} in {role}; available: "
                            f"{', '.join(names)}")
    return out


def load_model(path, dt=None):
    """A model from a subid JSON file or a MATLAB ``.mat`` file."""
    from subid.io.interop import load_mat
    from subid.model.statespace import StateSpace
    path = os.fspath(path)
    if path.lower().endswith(".mat"):
        return load_mat(path, dt=dt)
    return StateSpace.load(path)


def _fmt_fit(values) -> str:
    if values is None:
        return "—"
    return " / ".join("n/a" if not np.isfinite(v) else f"{v:.2f}" for v in values)


def _fmt_poles(poles, limit: int = 8) -> str:
    parts = []
    seen = 0
    for z in poles:
        if z.imag < -1e-12 * max(1.0, abs(z)):
            continue                        # the conjugate is printed as ±
        if abs(z.imag) <= 1e-12 * max(1.0, abs(z)):
            parts.append(f"{z.real:.4g}")
        else:
            parts.append(f"{z.real:.4g}±{abs(z.imag):.4g}j")
        seen += 1
        if seen >= limit:
            parts.append("...")
            break
    return ", ".join(parts)


def _progress(total: int, desc: str, enabled: bool, initial: int = 0):
    return progress_bar(total, desc, "sample", enabled=enabled, initial=initial)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """``warnings.showwarning`` of the command line: one log line, no source path."""
    log.warning("%s", " ".join(str(message).split()))


@contextlib.contextmanager
def _warnings_to_log():
    """Show library warnings as one-line log messages."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught
    seen = set()
    for w in caught:
        text = str(w.message)
        if text not in seen:
            seen.add(text)
            log.warning("%s", text)


def _convergence_status(model) -> str:
    """'yes' or 'NO: why' from an online model's info (``converged`` /
    ``convergence``, which both online identifiers set)."""
    info = model.info
    if info.get("converged") is False:
        return f"NO: {info.get('convergence')}" + (
            " (B, D from the projected data equation)" if info.get("bd_fallback") else "")
    return "yes"


def _default_detrend(spec) -> str:
    """--detrend's default: 'constant' (data around an operating point, as MATLAB users
    detrend), for the discrete-time and the continuous-time batch methods alike; 'none'
    for the online continuous-time identifiers, which model the response from rest in
    the user's units: removing the record's means biases them (measured: the adaptive
    identifier's pole error 0.98 instead of 5e-5 on the seed-000 system)."""
    return "none" if spec.time == "continuous" and spec.kind != "batch" else "constant"


def _detrend(data, kind):
    return data if kind in (None, "none") else data.detrend(kind)


def _command_line() -> str:
    return "subid " + " ".join(shlex.quote(a) for a in _state().argv)


def _write_json(path, obj) -> None:
    text = json.dumps(obj, indent=2, allow_nan=False, default=_json_default) + "\n"
    write_bytes(path, text)


#: What each command writes in its --out folder: an existing folder is
#: replaced as a whole only when it is empty or holds nothing else.
#: (``subid compare`` writes compare.png/.html next to the model by default: they
#: belong to the previous run and are replaced with it.)
_COMPARE_FILES = frozenset({"compare.png", "compare.html"})
_IDENTIFY_FILES = frozenset({"model.json", "report.html", "summary.json"}) | _COMPARE_FILES
_TRACK_FILES = frozenset({"model.json", "report.html", "history.npz", "checkpoints"}) \
    | _COMPARE_FILES


def _only(names):
    """Predicate for atomic_directory: the folder holds only ``names``."""
    return lambda path: set(os.listdir(path)) <= names


def _check_out(out, names) -> None:
    """Refuse, before any work, an --out folder holding files subid did not write."""
    from subid.errors import FileWriteError
    if os.path.lexists(out):
        if os.path.islink(out):          # the one output-path policy (refuse_link of the io package)
            raise FileWriteError(f"--out {out} is a symbolic link (to {os.readlink(out)}); "
                                 "subid does not write through links: give the target "
                                 "folder itself", path=out)
        if not os.path.isdir(out):
            raise FileWriteError(f"--out {out} exists and is not a folder", path=out)
        extra = sorted(set(os.listdir(out)) - names)
        if extra:
            raise FileWriteError(f"--out {out} holds files subid did not write "
                                 f"({', '.join(extra[:5])}{', ...' if len(extra) > 5 else ''}); "
                                 "the folder is replaced as a whole, so choose a new or empty "
                                 "folder", path=out)


def _carry_over(src: str, dst: str) -> None:
    """Hard-link (or copy) the files of the folder ``src`` into ``dst``."""
    import shutil
    if not os.path.isdir(src):
        return
    os.makedirs(dst, exist_ok=True)
    for name in os.listdir(src):
        if name.startswith("."):
            continue                       # temporary files of killed saves
        a, b = os.path.join(src, name), os.path.join(dst, name)
        if not os.path.isfile(a):
            continue
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(type(obj).__name__)


def _nan_to_none(values):
    if values is None:
        return None
    return [None if not np.isfinite(v) else float(v) for v in values]


def _data_options(fn):
    """--inputs/--outputs/--dt/--time/--delimiter/--detrend."""
    fn = click.option("--detrend", type=click.Choice(["constant", "linear", "none"]),
                      default=None,
                      help="Remove the means (constant) or straight lines (linear) of "
                           "every channel before identification. Default: constant for "
                           "the batch methods (discrete and continuous time), none for the "
                           "online continuous-time ones (adaptive), which model the "
                           "response from rest.")(fn)
    fn = click.option("--delimiter", default=None, metavar="CHAR",
                      help="Field delimiter of a text file (default: detected).")(fn)
    fn = click.option("--time", "time_column", default=None, metavar="COLUMN",
                      help="Column holding the time stamps (may be non-uniform).")(fn)
    fn = click.option("--dt", type=float, default=None, metavar="SECONDS",
                      help="Sampling period (default 1: time in samples).")(fn)
    fn = click.option("--outputs", default=None, metavar="NAMES",
                      help="Output columns: header names or 0-based indices, comma-separated.")(fn)
    fn = click.option("--inputs", default=None, metavar="NAMES",
                      help="Input columns: header names or 0-based indices, comma-separated.")(fn)
    return fn


_FREQ = click.option("--frequency-unit", type=click.Choice(["rad/s", "Hz"], case_sensitive=False),
                     default="rad/s", show_default=True,
                     help="Unit of the Bode frequency axis and of the pole table.")


# ---------------------------------------------------------------------------
# the command group
# ---------------------------------------------------------------------------
@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
             epilog="\b\nExamples:\n"
                    "  subid identify dataset:dryer --method moesp --out dryer_out\n"
                    "  subid identify run1.csv --inputs u1,u2 --outputs y --dt 0.1 --out out\n"
                    "  subid demo --out demo_out")
@click.version_option(version=__version__, prog_name="subid")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar and no summary.")
@click.option("--verbose", "-v", is_flag=True, help="Show informational messages.")
@click.option("--debug", is_flag=True, help="Show tracebacks and debug messages.")
@click.pass_context
def cli(ctx, quiet, verbose, debug):
    """Identify linear state-space models from input/output data.

    DATA arguments are files (CSV, TSV, TXT, DAT, NPZ, MAT) or dataset:NAME for
    a bundled DaISy record (see 'subid methods'). Every command has --help.
    """
    state = ctx.ensure_object(_State)
    state.quiet = state.quiet or quiet
    state.verbose = state.verbose or verbose
    state.debug = state.debug or debug
    _configure_logging(state)


# -- identify ----------------------------------------------------------------
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
                   "nk) for arx.")
@click.option("--horizon", type=click.IntRange(min=2), default=None,
              help="Block rows of the data Hankel matrix (default: chosen by the method).")
@click.option("--validate", type=click.FloatRange(0, 1, max_open=True), default=0.3,
              show_default=True,
              help="Share of the record, at its end, kept for validation (0: none).")
@click.option("--forgetting", type=click.FloatRange(0, min_open=True), default=None,
              help="Forgetting of an online method (recursive: factor in (0, 1]; adaptive: "
                   "rate, see its documentation).")
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
              help="Extra keyword argument of the method (JSON value), e.g. "
                   "--option instruments=null. Repeatable.")
@_FREQ
@click.option("--refine", type=click.Choice(["none", "simulation", "prediction", "pem"]),
              default="none", show_default=True,
              help="Refine the model by prediction-error minimisation (subid.pem) on the "
                   "estimation part with this focus ('pem': 'prediction', deprecated). "
                   "Without --method, subid.identify already decides on its own refinement.")
@click.option("--report/--no-report", "write_report", default=True, show_default=True,
              help="Write report.html (skip it for batch jobs that need only the model).")
@click.option("--stream", is_flag=True, default=False,
              help="Read the file in pieces with bounded memory, for files larger than memory "
                   "(ls, moesp, n4sid; uniform sampling). Fit and report use the first "
                   "--report-samples samples of each part.")
@click.option("--chunk-size", type=click.IntRange(min=1), default=100_000, show_default=True,
              help="Samples per piece with --stream.")
@click.option("--report-samples", type=click.IntRange(min=100), default=20_000,
              show_default=True, help="Samples of each part kept for the fit and the report "
                                      "with --stream.")
@click.option("--out", required=True, type=click.Path(file_okay=False),
              help="Output folder for model.json, report.html and summary.json.")
@click.option("--frequency-response", "frequency_response", is_flag=True, default=False,
              help="DATA is a frequency response (subid.read_frd: columns w or f [Hz] and "
                   "<output>/<input>:re,:im or :db/:mag,:phase; or .mat/.npz); identify it "
                   "with subid.fd_subspace (--dt: its sampling period, default 0 = continuous "
                   "time; --validate: share of the frequencies held out, interleaved).")
@_common
def identify(data, inputs, outputs, dt, time_column, delimiter, detrend, method_name, order,
             horizon, validate, forgetting, options, frequency_unit, refine, write_report,
             stream, chunk_size, report_samples, out, frequency_response=False):
    """Identify a model from DATA; write model.json and report.html.

    The record is detrended, split into an estimation part (the first 1 -
    VALIDATE) and a validation part (the rest); the model is identified on the
    first and checked on both. Prints the order, fit % on the estimation and
    validation parts, the poles, stability and the time taken.

    Several DATA files are several experiments of one plant (subid.merge):
    no Hankel column crosses from one file to the next, each file has its own
    initial state and loses its own mean (--detrend constant); the validation
    part is the end of the last file. Discrete-time batch methods and ct.
    """
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
    order = _parse_order(order)
    opts = _parse_options(options)
    _check_method_options(spec, opts, reserved=_reserved_options(spec, horizon=horizon,
                                                                 forgetting=forgetting))
    if forgetting is not None and spec.kind != "online":
        raise click.UsageError(f"--forgetting applies to online methods only, not to "
                               f"{spec.name}")
    spec.load()                                     # "not available" before any work
    if stream and refine != "none":
        raise click.UsageError(f"--refine {refine} needs the samples in memory; it does not "
                               "work with --stream")
    sources = list(data)
    if len(sources) > 1:
        if stream:
            raise click.UsageError("--stream reads one file; several DATA files are merged as "
                                   "experiments in memory (drop --stream)")
        if spec.kind != "batch" or (spec.time != "discrete" and spec.name != "ct"):
            raise click.UsageError(f"several DATA files are merged as experiments for the "
                                   f"discrete-time batch methods and ct, not for {spec.name}: "
                                   "it would join them as if contiguous")
    data = sources[0] if len(sources) == 1 else " + ".join(sources)
    if stream:
        return _identify_streamed(data, inputs, outputs, dt, time_column, delimiter, detrend,
                                  spec, order, horizon, validate, opts, frequency_unit,
                                  write_report, chunk_size, report_samples, out)
    with _steps(write_report) as steps:
        return _identify_in_memory(sources, data, inputs, outputs, dt, time_column, delimiter,
                                   detrend, spec, order, horizon, validate, forgetting, opts,
                                   refine, frequency_unit, write_report, out, steps)


def _steps(write_report):
    """The progress bar over the steps of ``identify`` (on a terminal only)."""
    names = ["read", "identify", "evaluate", *(["report"] if write_report else []), "write"]
    return Steps(names, "identify", enabled=_state().progress)


def _identify_in_memory(sources, data, inputs, outputs, dt, time_column, delimiter, detrend,
                        spec, order, horizon, validate, forgetting, opts, refine,
                        frequency_unit, write_report, out, steps):
    from subid.evaluation import report
    steps.start("read")
    with _about(data):
        if len(sources) == 1:
            record, label, notes = load_data(data, inputs, outputs, dt, time_column, delimiter)
        else:
            record, label, notes = _load_experiments(sources, inputs, outputs, dt, time_column,
                                                     delimiter)
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
                model = pem(est, model, focus="prediction" if refine == "pem" else refine)
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
            if refine == "pem":
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
                 f"stable      {'yes' if result['stable'] else 'NO'}"]
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
    summary = {
        "data": data, "method": spec.name, "function": spec.attribute, "order": model.order,
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
    # the file is parsed once; the later passes read the parsed doubles back
    pieces = ParsedOnce(lambda: read_chunks(data, inputs, outputs, dt=dt,
                                            chunk_size=chunk_size, delimiter=delimiter))
    try:
        with _steps(write_report) as steps:
            return _identify_pieces(pieces, data, detrend, spec, order, horizon, validate,
                                    opts, frequency_unit, write_report, chunk_size,
                                    report_samples, out, steps)
    finally:
        pieces.close()


def _identify_pieces(pieces, data, detrend, spec, order, horizon, validate, opts,
                     frequency_unit, write_report, chunk_size, report_samples, out, steps):
    import functools
    import types

    from subid._threads import ordered_map
    from subid.data import IOData, column_sums
    from subid.evaluation import report
    from subid.methods.dt.stream import SPOOL_GROUPS, attach_second_pass, statistic_depth
    from subid.statistic.hankel import HankelStatistic
    steps.start("read")
    with _about(data):
        n, total_u, total_y, first = 0, 0.0, 0.0, None
        for piece in pieces:
            if first is None:
                first = piece
            n += piece.n_samples
            total_u = total_u + column_sums(piece.u)
            total_y = total_y + column_sums(piece.y)
        if first is None:
            raise DataError(f"{data} holds no samples")
        u_mean = total_u / n if detrend == "constant" else np.zeros(first.n_inputs)
        y_mean = total_y / n if detrend == "constant" else np.zeros(first.n_outputs)
        cut = n - int(round(validate * n)) if validate > 0 else n
        hor, depth = statistic_depth(spec.name, order if isinstance(order, int) else None,
                                     horizon, first.n_outputs, opts.get("instruments", "past"))

        def statistic(read):
            part = HankelStatistic(first.n_inputs, first.n_outputs, depth, kind="gram",
                                   dt=first.dt, input_names=first.input_names,
                                   output_names=first.output_names)
            for u, y in read():
                part.update(u, y)
            return part

        steps.start("identify")
        t0 = time.perf_counter()
        # pass 2: the statistic of the estimation part, means removed, from the spooled
        # doubles in consecutive stretches on subid's threads (merged exactly)
        stretches = pieces.groups(SPOOL_GROUPS, stop=cut, offsets=(u_mean, y_mean))
        stat = functools.reduce(HankelStatistic.merge, ordered_map(statistic, stretches))
        if opts.get("bd_method", "auto") != "projection":
            # pass 3 (issue 14): B, D, x0 by the output regression of the in-memory default
            attach_second_pass(stat, groups=stretches)
        with _warnings_to_log():
            model = spec.load()(stat, order, horizon=hor, **opts)
        seconds = time.perf_counter() - t0

        def sample(start, stop):
            """The first ``report_samples`` samples of a part, for the fit and the report."""
            stop = min(stop, start + report_samples)
            if stop <= start:
                return None
            chunks = list(pieces.ranges([(start, stop)], offsets=(u_mean, y_mean))[0]())
            return IOData(np.vstack([u for u, _ in chunks]), np.vstack([y for _, y in chunks]),
                          dt=first.dt, input_names=first.input_names,
                          output_names=first.output_names)
        steps.start("evaluate")
        est, val = sample(0, cut), sample(cut, n)
        result = report.evaluate(model, est, val)
    model.info.setdefault("method", spec.attribute)
    model.info["data"] = {"source": str(data), "inputs": list(first.input_names),
                          "outputs": list(first.output_names), "detrend": detrend,
                          "n_estimation": stat.n_samples, "validation_fraction": float(validate),
                          "streamed": True, "report_samples": report_samples,
                          "u_offset": u_mean, "y_offset": y_mean}
    notes = [f"Streamed in pieces of {chunk_size} samples: identified from the statistic of "
             f"{stat.n_samples} samples; fit and figures use the first {report_samples} "
             "samples of each part."]
    record = types.SimpleNamespace(dt=first.dt, n_samples=n, n_inputs=first.n_inputs,
                                   n_outputs=first.n_outputs)
    _write_outputs(out, data, spec, model, result, est, val, seconds, record,
                   title=f"{os.path.basename(data)}: {spec.attribute}", notes=notes,
                   report_data=est, write_report=write_report, frequency_unit=frequency_unit,
                   outputs=list(first.output_names), n_estimation=stat.n_samples,
                   n_validation=n - stat.n_samples, streamed=True, steps=steps)
    return 0


class _RecordFacts:
    """What the summary and the provenance need of a record, without its samples
    (so the in-memory ``identify`` holds one copy of the data, the detrended one)."""

    def __init__(self, record):
        self.input_names, self.output_names = record.input_names, record.output_names
        self.dt, self.has_time_stamps = record.dt, record.has_time_stamps
        self.n_samples, self.n_inputs, self.n_outputs = (record.n_samples, record.n_inputs,
                                                         record.n_outputs)


def _provenance(source, record, work, detrend, est, validate) -> dict:
    info = {"source": str(source), "inputs": list(record.input_names),
            "outputs": list(record.output_names), "detrend": detrend,
            "n_estimation": est.n_samples, "validation_fraction": float(validate)}
    if getattr(work, "n_experiments", 1) > 1:
        info["experiments"] = [{"name": name, "samples": b - a} for name, (a, b)
                               in zip(work.experiment_names, work.experiment_ranges)]
    if work.u_offset is not None:
        info["u_offset"] = np.asarray(work.u_offset, dtype=float)
        info["y_offset"] = np.asarray(work.y_offset, dtype=float)
    return info


def _print_summary(source, record, spec, model, result, est, val, seconds, files):
    if _state().quiet:
        return
    timing = f"dt = {record.dt:g}" if record.dt is not None else "non-uniform time stamps"
    if record.dt == 1.0 and not getattr(record, "has_time_stamps", False):
        timing += " (time in samples)"
    lines = [f"data        {source}: {record.n_samples} samples, {record.n_inputs} input(s), "
             f"{record.n_outputs} output(s), {timing}",
             f"method      {spec.name} ({spec.attribute})",
             f"order       {model.order}"
             + (f" ({describe_selection(model.info['order_selection'])})"
                if model.info.get("order_selection") else ""),
             f"outputs     {', '.join(est.output_names)}",
             f"fit %       estimation {_fmt_fit(result['fit_estimation'])} "
             f"({est.n_samples} samples)"]
    if val is not None:
        lines.append(f"            validation {_fmt_fit(result['fit_validation'])} "
                     f"({val.n_samples} samples)")
    else:
        lines.append("            validation — (--validate 0)")
    lines += [f"poles       {_fmt_poles(result['poles'])}",
              f"stable      {'yes' if result['stable'] else 'NO'}"
              + (" (continuous time)" if model.dt == 0 else "")]
    if model.info.get("refined_by") == "pem":
        lines.append(f"refined     pem ({model.info['focus']} focus): cost "
                     f"{model.info['start_cost']:.4g} -> {model.info['final_cost']:.4g}; "
                     f"{model.info['stop_reason']}")
    if model.noise_cov is not None:
        lines.append("noise cov   " + "; ".join(
            " ".join(f"{v:.4g}" for v in row) for row in model.noise_cov)
                     + (" (innovations, with Kalman gain K)" if model.K is not None else ""))
    lines += [
              f"time        {seconds:.2f} s",
              f"wrote       {', '.join(files)}"]
    click.echo("\n".join(lines))


# -- track -------------------------------------------------------------------
def _run_online(spec, tracker, start, progress, *, chunk):
    """``tracker.run`` from sample ``start`` with a progress bar on a terminal."""
    bar = _progress(tracker.data.n_samples, f"{spec.name}", progress, initial=start)
    try:
        tracker.run(start, chunk=chunk, progress=None if bar is None else bar.update)
    finally:
        if bar is not None:
            bar.close()


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
              default="recursive", show_default=True, help="Online identification method.")
@click.option("--order", type=click.IntRange(min=1), default=None,
              help="Model order (required unless resuming).")
@click.option("--horizon", type=click.IntRange(min=2), default=None,
              help="Horizon of the identifier (default: chosen by the method).")
@click.option("--forgetting", type=click.FloatRange(0, min_open=True), default=None,
              help="recursive: forgetting factor in (0, 1], 1 (default) weighs all samples "
                   "equally; adaptive: forgetting rate (see its documentation).")
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
              help="Extra keyword argument of the identifier (JSON value). Repeatable.")
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
@click.option("--report/--no-report", "write_report", default=True, show_default=True,
              help="Write report.html.")
@click.option("--out", required=True, type=click.Path(file_okay=False),
              help="Output folder: model.json, report.html, history.npz, checkpoints/.")
@_common
def track(data, inputs, outputs, dt, time_column, delimiter, detrend, method_name, order,
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
    spec = METHODS[method_name]
    spec.load()
    opts = _parse_options(options)
    _check_method_options(spec, opts, reserved=_reserved_options(spec, horizon=horizon,
                                                                 forgetting=forgetting))
    with _about(data):
        raw, label, notes = load_data(data, inputs, outputs, dt, time_column, delimiter)
        detrend = detrend or _default_detrend(spec)
        work = _detrend(raw, detrend)
        if spec.time == "discrete" and work.dt is None:
            raise DataError(f"method {spec.name} needs uniformly sampled data; these time "
                            "stamps are non-uniform")
    n = work.n_samples
    chunk = chunk or max(1, min(1000, n // 100))
    trace_every = max(1, n // 100) if trace_every is None else trace_every
    checkpoint_dir = os.path.join(out, "checkpoints")
    _check_out(out, _TRACK_FILES)
    os.makedirs(out, exist_ok=True)
    with _about(resume or data):
        if resume is not None:
            ident = load_online(spec, resume)
            for attr, want in (("n_inputs", work.n_inputs), ("n_outputs", work.n_outputs)):
                have = getattr(ident, attr, want)
                if have != want:
                    raise DataError(f"the checkpoint has {have} {attr[2:]} but the data "
                                    f"have {want}")
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
    from subid.methods.online.base import Tracker
    tracker = Tracker(ident, work, fingerprint_data=raw, trace_every=trace_every,
                      checkpoint_every=checkpoint_every, checkpoint_dir=checkpoint_dir,
                      keep=keep_checkpoints)
    if resume is not None:
        with _warnings_to_log():
            tracker.load_trace(resume[:-4] + ".trace.npz" if resume.endswith(".npz")
                               else resume + ".trace.npz", start)
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
            f"stable      {'yes' if result['stable'] else 'NO'}",
            f"snapshots   {len(history['sample'])}",
            f"time        {seconds:.2f} s",
            f"checkpoint  {final_ckpt}",
            f"wrote       {', '.join(files)}"]))
    return 0


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
    columns = inputs if inputs is not None else ",".join(model.input_names)
    if time_column is not None and dt is not None:
        raise click.UsageError("give either --time or --dt, not both")
    with _about(input_path):
        u, names, t = _read_signals(input_path, columns, time_column, delimiter)
        if u.shape[1] != model.n_inputs:
            raise DataError(f"{u.shape[1]} input column(s) selected but the model has "
                            f"{model.n_inputs} input(s)")
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
def compare(model_paths, data_source, inputs, outputs, dt, time_column, delimiter, detrend,
            out, steps):
    """Fit % of one or more models on DATA, with an overlay plot.

    Every model is simulated (or, with --steps K, predicted K steps ahead)
    from a least-squares initial state (as subid.fit_percent and MATLAB's
    compare). Inputs and outputs default to the first model's channel names;
    the sampling period to its dt.
    """
    from subid.evaluation.metrics import fit_percent
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
                                         delimiter)
        work = _detrend(record, detrend or "constant")
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
    """Identify the bundled DaISy datasets with every available method.

    Each record: means removed, identified on the first 70 %, fit % on the
    last 30 %. Writes one HTML report per dataset, index.html linking them,
    gallery.md (the table of docs/gallery.md) and summary.json.
    """
    import subid.cli.demo as demo_module
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
    """Write the gallery table: fit % of every discrete-time method on every dataset."""
    import subid.cli.demo as demo_module
    text, rows = demo_module.gallery(datasets=_names(names), progress=_state().progress)
    directory = os.path.dirname(os.path.abspath(out))
    os.makedirs(directory, exist_ok=True)
    write_bytes(out, text, what="gallery")
    _echo(f"wrote {out} ({len(rows)} rows)")
    return 0


@cli.command(name="methods", epilog="\b\nExample:\n  subid methods")
@_common
def methods_command():
    """List the identification methods and the bundled datasets."""
    from subid import datasets
    click.echo("methods (--method):")
    for name, spec in METHODS.items():
        status = "" if spec.available() else "  [not available in this version]"
        click.echo(f"  {name:<10} {spec.kind:<6} {spec.time:<10} {spec.description}{status}")
    click.echo("datasets (DATA = dataset:NAME):")
    for name in datasets.names():
        meta = datasets.info(name)
        click.echo(f"  {name:<14} {meta['n_samples']:>5} samples, {meta['n_inputs']} in, "
                   f"{meta['n_outputs']} out, dt = {meta['dt']:g}"
                   + ("" if meta["dt_known"] else " (assumed)"))
    return 0


# ---------------------------------------------------------------------------
# entry point
# ---------------------------------------------------------------------------
def main(argv=None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 user error).

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name (default ``sys.argv[1:]``).
    """
    global _HANDLER
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("subid: %(levelname)s: %(message)s"))
    logger = logging.getLogger("subid")
    previous = (_HANDLER, logger.level, logger.propagate)
    _HANDLER = handler
    handler.setLevel(logging.WARNING)
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    logger.propagate = False
    state = _State()
    state.argv = args
    try:
        try:
            with warnings.catch_warnings():     # restores showwarning afterwards
                warnings.showwarning = _show_warning
                rv = cli.main(args=args, prog_name="subid", standalone_mode=False, obj=state)
        except click.exceptions.Exit as exc:
            return exc.exit_code
        except click.UsageError as exc:
            click.echo(f"subid: error: {_usage_line(exc)}", err=True)
            return EXIT_USER_ERROR
        except click.ClickException as exc:
            exc.show()
            return EXIT_USER_ERROR
        except click.exceptions.Abort:
            click.echo("Aborted!", err=True)
            return 130
        return rv if isinstance(rv, int) else 0
    except KeyboardInterrupt:
        click.echo("subid: interrupted", err=True)
        return 130
    except MemoryError:
        click.echo("subid: error: out of memory: the record (or a step of the method on it) "
                   "does not fit in this machine's memory; for a large file use "
                   "'subid identify FILE --stream' (bounded memory), or identify a part of "
                   "the record", err=True)
        return EXIT_USER_ERROR
    except (SubidError, OSError, ImportError) as exc:
        if debug:
            traceback.print_exc()
        click.echo(f"subid: error: {_one_line(exc)}", err=True)
        return EXIT_USER_ERROR
    finally:
        logger.removeHandler(handler)
        _HANDLER, level, propagate = previous
        logger.setLevel(level)
        logger.propagate = propagate
