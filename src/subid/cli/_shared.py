"""What the commands of ``subid`` share: the command group and its common options
(``--quiet``/``--verbose``/``--debug``, the DATA options, ``--frequency-unit``), the
methods the command line offers (a view of :data:`subid.registry.METHODS`), reading
DATA and MODEL arguments, output folders and the one-line messages.

Each command lives in its own module (:mod:`subid.cli.identify`, ``track``,
``simulate``, ``compare``, ``convert``, ``demo_commands``, ``methods``), which
registers it on :func:`cli`; :mod:`subid.cli.commands` imports them all and runs the
group (:func:`subid.cli.commands.main`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
import shlex
import warnings

import click
import numpy as np

from subid import _blas
from subid._progress import on_terminal, progress_bar
from subid._version import __version__
from subid.errors import DataError, OrderError, SamplingWarning, SubidError
from subid.io._files import write_bytes
from subid.methods.registry import METHODS as _REGISTRY
from subid.methods.registry import MethodSpec

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
    capabilities=frozenset({"order_selection", "horizon", "x0", "refine", "nonuniform",
                            "experiments"}))


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
        # what cli_hint translates library hints to: the running command's flags
        # ('--method', ...) and the keyword options of its method (--option KEY=VALUE)
        self.hint_flags: frozenset = frozenset()
        self.hint_options: tuple = ()

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


#: Library advice in Python words, and what the command line says instead.
_HINT_PHRASES = (
    ("data.scaled(...) or remove their offsets",
     "scale the channels in the file, or remove their offsets with --detrend constant"),
)
#: ``use method='bilinear'``, ``give horizon=20``...: a verb, then a keyword argument.
_HINT_KEYWORD = re.compile(r"\b(use|give|pass|set|try|add) ([a-z_]+)="
                           r"(?:'([^']*)'|\"([^\"]*)\"|([\w.+-]+))")
#: Keyword arguments that a command takes as its own flag even when the method's
#: options list them too (``--horizon 20``, not ``--option horizon=20``).
_OWN_FLAGS = frozenset({"horizon", "forgetting"})


def cli_hint(text: str, state: _State | None = None) -> str:
    """``text`` (a library message) with its hints in the command line's options.

    The library's messages advise in Python (``use method='bilinear' instead``,
    ``data.scaled(...)``); on the command line the same advice names the running
    command's flag (``use --method bilinear instead``) or its method's ``--option``
    (``use --option method=iv``). Keyword arguments neither takes are left as they are.

    Parameters
    ----------
    text : str
    state : _State, optional
        The command's flags and method options (``hint_flags``, ``hint_options``);
        default: the current click context's.
    """
    if state is None:
        ctx = click.get_current_context(silent=True)
        state = ctx.find_root().ensure_object(_State) if ctx is not None else _State()
    for python, words in _HINT_PHRASES:
        text = text.replace(python, words)

    def one(match):
        verb, key = match.group(1), match.group(2)
        value = next(v for v in match.groups()[2:] if v is not None)
        flag = "--" + key.replace("_", "-")
        if flag in state.hint_flags and (key in _OWN_FLAGS or key not in state.hint_options):
            return f"{verb} {flag} {shlex.quote(value)}"
        if key in state.hint_options:
            value = {"True": "true", "False": "false", "None": "null"}.get(value, value)
            return f"{verb} --option {shlex.quote(f'{key}={value}')}"
        return match.group(0)
    return _HINT_KEYWORD.sub(one, text)


def _hint_method(spec: MethodSpec) -> None:
    """Let :func:`cli_hint` name ``spec``'s options as ``--option KEY=VALUE``."""
    _state().hint_options = tuple(spec.options)


class _HintFilter(logging.Filter):
    """Log records of the command line with their hints in its options (:func:`cli_hint`)."""

    def __init__(self, state: _State):
        super().__init__()
        self.state = state

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        hinted = cli_hint(text, self.state)
        if hinted != text:
            record.msg, record.args = hinted, ()
        return True


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


def check_sources(sources, inputs=None, outputs=None) -> None:
    """Reject DATA arguments that are not files but look like channel names.

    ``--inputs u1 u2`` gives click ``inputs='u1'`` and a second DATA argument ``'u2'``,
    which the reader would then report as a file of unsupported extension. A DATA
    argument that is neither a file nor ``dataset:NAME`` and has no extension, given
    beside a file that exists, is such a stray channel name: a
    :class:`subid.errors.DataError` says so and shows the comma-separated form."""
    stray = [s for s in sources if not s.startswith("dataset:") and not os.path.exists(s)
             and not os.path.splitext(s)[1]]
    if not stray or len(stray) == len(sources):
        return
    given = " ".join(f"--{role} {value}" for role, value in (("inputs", inputs),
                                                             ("outputs", outputs))
                     if value is not None)
    names = ", ".join(repr(s) for s in stray)
    raise DataError(f"{names} {'is not a file' if len(stray) == 1 else 'are not files'}: "
                    "several channels are one comma-separated value, e.g. --inputs u1,u2 "
                    f"(read here: {given or 'no --inputs or --outputs'}, and "
                    f"{names} as DATA)")


def load_data(source: str, inputs=None, outputs=None, dt=None, time_column=None,
              delimiter=None, decimal="."):
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
        if time_column is not None or decimal != ".":
            raise DataError(f"{source}: the bundled datasets are uniformly sampled arrays; "
                            f"{'--time' if time_column is not None else '--decimal'} "
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
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SamplingWarning)
        data = read(source, inputs=inputs, outputs=outputs, dt=dt, time=time_column,
                    delimiter=delimiter, decimal=decimal)
    time_like = None
    for w in caught:                      # the reader's time-column hint joins the note
        if isinstance(w.message, SamplingWarning):
            time_like = w.message.column
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    notes = [f"Data file: {source}"]
    if dt is None and time_column is None and data.dt == 1.0 and not data.has_time_stamps:
        notes.append("No sampling period given (--dt) and no time column (--time): time is "
                     "counted in samples (dt = 1), frequencies in rad/sample."
                     + ("" if time_like is None else
                        f" The column {time_like!r} looks like time stamps: add --time "
                        f"{shlex.quote(time_like)} to take the sampling period from it."))
        log.warning("%s: %s", source, notes[-1])
    return data, os.path.basename(source), notes


def _load_experiments(sources, inputs, outputs, dt, time_column, delimiter, decimal="."):
    """Several DATA arguments as one record of several experiments (:func:`subid.merge`)."""
    from subid.data import merge
    loaded = []
    for source in sources:
        try:
            loaded.append(load_data(source, inputs, outputs, dt, time_column, delimiter,
                                    decimal))
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


def check_channel_order(model_names, data_names, role: str, model: str) -> None:
    """Refuse channels that are the model's in another order.

    The commands match a record's columns to a model by position: ``--inputs u2,u1``
    on a model of inputs ``[u1, u2]`` would feed u2 where the model expects u1 and give
    a meaningless fit. Names that are the same set as the model's, in another order,
    are a :class:`subid.errors.DataError` naming both orders and the option to give;
    other names (a record with other channel names) are not checked.

    Parameters
    ----------
    model_names, data_names : sequence of str
    role : {'inputs', 'outputs'}
        The option that selects them (``--inputs``, ``--outputs``).
    model : str
        The model file, for the message.
    """
    from subid.model.prediction import reordered
    model_names, data_names = [str(n) for n in model_names], [str(n) for n in data_names]
    if not reordered(model_names, data_names):
        return
    raise DataError(f"--{role} {','.join(data_names)} are the {role} of {model} in another "
                    f"order (the model's: {','.join(model_names)}); the columns are matched "
                    f"to the model by position: give --{role} {','.join(model_names)}")


def _select(names, spec, role, source) -> list[int]:
    if spec is None:
        return list(range(len(names)))
    out = []
    for token in _names(spec) or []:
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
    """Fit % per output: two decimals; a diverging simulation's (an unstable model: fits
    of -3.6e147 % were printed with their 150 digits) in three significant digits."""
    if values is None:
        return "—"
    return " / ".join("n/a" if not np.isfinite(v) else f"{v:.3g}" if abs(v) >= 1e4
                      else f"{v:.2f}" for v in values)


#: A pole this close to the stability boundary (discrete time: |z| above 1 minus it;
#: continuous time: a real part above minus it times the largest |s|) is marginal: the
#: summary says so next to "stable yes", whose poles print as 1 (or 0) to 4 digits.
MARGINAL = 1e-6


def _fmt_stable(result, continuous: bool) -> str:
    """The summary's ``stable`` value: ``yes``, ``NO``, or ``yes (marginally: ...)`` when
    a pole lies within :data:`MARGINAL` of the boundary (an integrator to rounding: a
    per-experiment offset the states absorb, e.g.), with its distance."""
    if not result["stable"]:
        return "NO"
    poles = np.asarray(result["poles"], dtype=complex)
    if poles.size == 0:
        return "yes"
    if continuous:
        margin = float(-poles.real.max())
        if margin > MARGINAL * max(float(np.abs(poles).max()), 1e-300):
            return "yes"
        return (f"yes (marginally: a pole with real part {-margin:.2g}, an integrator to "
                "rounding)")
    margin = 1.0 - float(np.abs(poles).max())
    if margin > MARGINAL:
        return "yes"
    return f"yes (marginally: a pole at |z| = 1 - {margin:.2g}, an integrator to rounding)"


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


def _note_first_run() -> None:
    """On a terminal, one line before a command computes when numba's cache lacks the
    default calls' kernels (:func:`subid.warmup.kernels_cached`): their first use
    compiles them, about a minute, with nothing else to explain the wait."""
    if not _state().progress:
        return
    from subid.warmup import kernels_cached
    if not kernels_cached():
        click.echo("subid: first run: compiling the numerical kernels into numba's cache "
                   "(about a minute, once; `python -m subid.warmup` does it ahead)", err=True)


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
        return f"NO: {cli_hint(str(info.get('convergence')))}" + (
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


def _default_out(source: str, command: str) -> str:
    """The ``--out`` folder of a command run without it: ``NAME_COMMAND`` in the current
    folder, NAME the first DATA's file name without its extension (``plant.csv`` ->
    ``plant_identify``) or the dataset's name (``dataset:dryer`` -> ``dryer_identify``)."""
    name = source.split(":", 1)[1] if source.startswith("dataset:") else \
        os.path.splitext(os.path.basename(os.path.normpath(source)))[0]
    return f"{name or 'data'}_{command}"


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
    fn = click.option("--decimal", type=click.Choice([".", ","]), default=".",
                      show_default=True,
                      help="Decimal separator of a text file's numbers (',' for a "
                           "spreadsheet export such as 0,125;1,5: the fields are then "
                           "delimited by ';', TAB or spaces).")(fn)
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


def _method_run_options(*, horizon: str, forgetting: str, option: str, report: str,
                        out: str):
    """``--horizon``, ``--forgetting``, ``--option``, ``--report/--no-report`` and
    ``--out`` of the commands that run a method (``identify``, ``track``): declared
    once, with each command's help."""
    decorators = [
        click.option("--horizon", type=click.IntRange(min=2), default=None, help=horizon),
        click.option("--forgetting", type=click.FloatRange(0, min_open=True), default=None,
                     help=forgetting),
        click.option("--option", "options", multiple=True, metavar="KEY=VALUE", help=option),
        click.option("--report/--no-report", "write_report", default=True,
                     show_default=True, help=report),
        click.option("--out", default=None, type=click.Path(file_okay=False), help=out),
    ]
    return {name: d for name, d in zip(("horizon", "forgetting", "option", "report", "out"),
                                       decorators)}


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
    command = cli.get_command(ctx, ctx.invoked_subcommand) if ctx.invoked_subcommand else None
    if command is not None:          # its flags, for the hints of cli_hint
        state.hint_flags = frozenset(o for p in command.params for o in p.opts
                                     if o.startswith("--"))
    state.quiet = state.quiet or quiet
    state.verbose = state.verbose or verbose
    state.debug = state.debug or debug
    _configure_logging(state)



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


def _run_online(spec, tracker, start, progress, *, chunk):
    """``tracker.run`` from sample ``start`` with a progress bar on a terminal."""
    bar = _progress(tracker.data.n_samples, f"{spec.name}", progress, initial=start)
    try:
        with _blas.serial(now=True):          # one BLAS thread, as every computation
            tracker.run(start, chunk=chunk, progress=None if bar is None else bar.update)
    finally:
        if bar is not None:
            bar.close()
