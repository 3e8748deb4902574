"""Self-contained HTML reports of identified models.

A report is one HTML file: figures are embedded as base64 PNG images, the
style sheet is inline, there is no script, no font and no other file to
fetch, so it opens anywhere without a network. Sections carry stable ids:

=================  ==========================================================
``summary``        table: method, order, fit % (estimation / validation),
                   stability, time; notes and the command that made it
``data``           overview of the record (validation part shaded)
``compare``        measured against simulated outputs, fit % per model
``bode``           magnitude and phase (rad/s or Hz), 95 % bands of the models
                   refined by pem, the spa estimate of the estimation data
``step``           step responses, 95 % bands of the models refined by pem
``poles``          pole map (unit circle or imaginary axis) and pole table
``residuals``      residual auto-correlation and input/residual
                   cross-correlation with 99 % bands
``convergence``    online runs only: poles and parameters against samples
``matrices``       A, B, C, D, initial state, diagnostics, MATLAB code
=================  ==========================================================

>>> html = identification_report({"moesp": model}, est, val, title="dryer")  # doctest: +SKIP
>>> write_html("report.html", html)                                          # doctest: +SKIP
"""

from __future__ import annotations

import base64
import contextvars
import datetime
import functools
import gc
import html
import logging
import math
import re
import textwrap

import numpy as np

from subid.errors import ModelError, SubidError
from subid.evaluation.figures._common import frequency_unit as unit_of_frequency
from subid.io._files import atomic_write
from subid.io.interop import operating_point, removed_lines
from subid.model.polynomial import describe as describe_polynomials
from subid.model.polynomial import polynomials_of

__all__ = ["identification_report", "index_page", "comparison_page", "failure_page", "evaluate",
           "figure_html", "write_html", "SECTIONS"]

log = logging.getLogger(__name__)

#: Section ids of an identification report, in order (``convergence`` only for online runs).
SECTIONS = ("summary", "data", "order", "compare", "bode", "step", "poles", "residuals",
            "convergence", "matrices")

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
margin:0 auto;max-width:1180px;padding:0 1.2em 3em;color:#1d1d1f;line-height:1.45}
h1{font-size:1.6em;margin:.8em 0 .2em}h2{font-size:1.25em;border-bottom:1px solid #ccc;
padding-bottom:.2em;margin-top:1.6em}h3{font-size:1.05em;margin:1.2em 0 .4em}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}
th,td{border:1px solid #d0d0d0;padding:.25em .55em;text-align:right;vertical-align:top}
th{background:#f2f2f2}td.l,th.l{text-align:left}
img{max-width:100%;height:auto;display:block;margin:.4em 0}
figure{margin:.6em 0}figcaption{font-size:.85em;color:#555}
pre{background:#f7f7f7;border:1px solid #e2e2e2;padding:.6em;overflow-x:auto;font-size:.8em}
.bad{color:#b00020;font-weight:600}.good{color:#0a7a2f}.note{color:#555;font-size:.9em}
nav a{margin-right:.9em}.meta{color:#666;font-size:.85em}
.why{color:#8a4b00;font-size:.8em;text-align:left;max-width:22em;margin-top:.15em}
"""


# ---------------------------------------------------------------------------
# building blocks
# ---------------------------------------------------------------------------
def _e(text) -> str:
    return html.escape(str(text), quote=True)


#: Resolution of the report's images. Each image is shown at its figure's size in inches,
#: 96 CSS pixels per inch (``figure_html``): 120 dpi gives 1.25 image pixels per CSS
#: pixel, sharp on ordinary screens and at 125 % zoom. At the 150 dpi of the figures
#: :mod:`subid.plot` returns, rasterising and PNG-encoding the 1.56 times as many
#: pixels cost a report of 10^6 samples 60 to 70 ms more (of about 0.8 CPU s,
#: bench/report_ratio.md): the report trades them for images a little softer at 2x
#: zoom or on high-density screens.
REPORT_DPI = 120


def figure_html(fig, caption: str = "", *, dpi: int | None = None, alt: str = "") -> str:
    """A ``<figure>`` holding ``fig`` as an embedded PNG; the figure is closed.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    caption : str
    dpi : int, optional
        Resolution of the PNG (default: the figure's, 150 for :mod:`subid.plot`;
        the report's sections use :data:`REPORT_DPI`).
        The image is shown at the figure's size in inches (96 CSS px per inch),
        so its 10 pt text reads as 10 pt and stays sharp on high-density screens.
    alt : str
        Alternative text (default: the caption).

    Returns
    -------
    str
    """
    from subid.evaluation._canvas import canvas as agg_canvas
    from subid.evaluation.figures._raster import raster_envelopes
    from subid.evaluation.figures._ticks import light_ticks
    width = int(round(fig.get_figwidth() * 96))
    if dpi is not None and dpi != fig.dpi:
        fig.set_dpi(dpi)
    canvas = agg_canvas(fig)
    # ticks as a few artists per axis (figures/_ticks.py), text laid out and rasterised
    # once per report (_canvas.py), and the PNG encoded by _png (one row filter, zlib
    # level 1: two to three times faster than savefig's, as small)
    raster_envelopes(fig)            # long traces' min/max bands as images (_raster.py)
    light_ticks(fig, canvas.get_renderer())
    canvas.draw()
    pixels = np.asarray(canvas.buffer_rgba())     # a view of the figure's own renderer
    try:
        import matplotlib.pyplot as plt
        plt.close(fig)
    except ImportError:  # pragma: no cover
        pass
    aside = _ENCODER.get()
    if aside is None:
        data = _encoded(pixels)
    else:                            # encoded on the report's worker (_figures_aside)
        pool, pending = aside
        pending.append(pool.submit(_encoded, pixels))
        data = f"\x00subid-figure-{len(pending) - 1}\x00"
    cap = f"<figcaption>{_e(caption)}</figcaption>" if caption else ""
    return (f'<figure><img alt="{_e(alt or caption or "figure")}" width="{width}" '
            f'src="data:image/png;base64,{data}">{cap}</figure>')


def _encoded(pixels) -> str:
    """The base64 text of the PNG of ``pixels`` (:func:`subid.evaluation._png.png_bytes`)."""
    from subid.evaluation._png import png_bytes
    return base64.b64encode(png_bytes(pixels)).decode("ascii")


#: ``(executor, futures)`` of the report being built (:func:`_figures_aside`), or None.
_ENCODER: contextvars.ContextVar = contextvars.ContextVar("subid_report_encoder",
                                                          default=None)
_PENDING = re.compile("\x00subid-figure-(\\d+)\x00")


def _figures_aside(fn):
    """``fn`` (a report builder returning HTML) with its figures' PNG encoding on one
    worker thread while the next figures are built and drawn.

    The encoding (the row filter, zlib, base64: about a tenth of a report, 43 ms of a
    10^6-sample report's 0.40 s) runs in numpy and zlib, which release the interpreter
    lock; matplotlib's drawing is Python. :func:`figure_html` hands each drawn figure's
    pixels (a view of its own renderer's buffer, which the view keeps alive) to the
    worker and leaves a placeholder in the HTML, which is filled once ``fn`` returns:
    the same bytes as encoding in turn."""
    @functools.wraps(fn)
    def aside(*args, **kwargs):
        if _ENCODER.get() is not None:            # inside another report: its worker
            return fn(*args, **kwargs)
        from concurrent.futures import ThreadPoolExecutor
        pending: list = []
        with ThreadPoolExecutor(1, thread_name_prefix="subid-report") as pool:
            token = _ENCODER.set((pool, pending))
            try:
                text = fn(*args, **kwargs)
            finally:
                _ENCODER.reset(token)
            if not pending:
                return text
            return _PENDING.sub(lambda match: pending[int(match.group(1))].result(), text)
    return aside


def _plot_or_note(make, caption: str, what: str) -> str:
    """Figure from ``make()``, or a note saying why it could not be drawn. The figure's
    axes make no tick objects before they are drawn (:mod:`.figures._light_axes`)."""
    from subid.evaluation.figures._light_axes import report_axes
    try:
        with report_axes():
            fig = make()
    except ImportError as exc:
        log.warning("%s not drawn: %s", what, exc)
        return f'<p class="note">{_e(what)} not drawn: {_e(exc)}</p>'
    except SubidError as exc:
        log.info("%s not drawn: %s", what, exc)
        return f'<p class="note">{_e(what)} not drawn: {_e(exc)}</p>'
    return figure_html(fig, caption, dpi=REPORT_DPI)


def _fmt(x, digits: int = 6) -> str:
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return "n/a"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    return f"{v:.{digits}g}"


def _fmt_fit(values) -> str:
    if values is None:
        return "—"
    return " / ".join("n/a" if not np.isfinite(v) else
                      (f"{v:.3g}" if abs(v) >= 1e4 else f"{v:.1f}") for v in values)


def _fmt_complex(z: complex, digits: int = 5) -> str:
    if abs(z.imag) <= 1e-12 * max(1.0, abs(z)):
        return f"{z.real:.{digits}g}"
    sign = "+" if z.imag >= 0 else "−"
    return f"{z.real:.{digits}g} {sign} {abs(z.imag):.{digits}g}j"


def _coefficient_std(model):
    """The standard deviations of a polynomial model's coefficients (None without them)."""
    entry = model.info.get("parameter_covariance")
    factor = entry.get("coefficient_factor") if isinstance(entry, dict) else None
    return None if factor is None else np.sqrt(np.sum(np.asarray(factor) ** 2, axis=1))


def _matrix_table(M, row_labels, col_labels) -> str:
    M = np.asarray(M)
    if M.size == 0:
        return '<p class="note">(empty)</p>'
    head = "".join(f"<th>{_e(c)}</th>" for c in col_labels)
    rows = []
    for label, row in zip(row_labels, M):
        cells = "".join(f"<td>{_fmt(v)}</td>" for v in row)
        rows.append(f'<tr><th class="l">{_e(label)}</th>{cells}</tr>')
    return f"<table><tr><th></th>{head}</tr>{''.join(rows)}</table>"


def _matlab_matrix(M) -> str:
    M = np.asarray(M)
    if M.size == 0:
        return f"zeros({M.shape[0]}, {M.shape[1]})"
    return "[" + "; ".join(" ".join(repr(float(v)) for v in row) for row in M) + "]"


def _matlab_code(model, point=None, lines=None) -> str:
    names_in = ", ".join(f"'{n}'" for n in model.input_names)
    names_out = ", ".join(f"'{n}'" for n in model.output_names)
    delay = _matlab_delay(model)
    code = (f"A = {_matlab_matrix(model.A)};\nB = {_matlab_matrix(model.B)};\n"
            f"C = {_matlab_matrix(model.C)};\nD = {_matlab_matrix(model.D)};\n"
            f"sys = ss(A, B, C, D, {model.dt!r}, 'InputName', {{{names_in}}}, "
            f"'OutputName', {{{names_out}}}{delay});" + _matlab_noise(model, delay))
    if point is not None:
        u0, y0 = point
        code += ("\n% the model relates deviations from the operating point (the means removed "
                 "before identification):\n"
                 f"u0 = {_matlab_matrix(u0[None, :])};\ny0 = {_matlab_matrix(y0[None, :])};\n"
                 "% in the data's units: y = lsim(sys, u - u0, t) + y0")
    elif lines is not None:
        code += "\n" + "\n".join(f"% {line}" for line in textwrap.wrap(lines + ".", 86))
    return code


def _matlab_delay(model) -> str:
    """``, 'InputDelay', [...]`` for a model with input delays (``info['input_delay']``,
    in samples: MATLAB's unit for a discrete-time model), else empty: without it the code
    would rebuild a model without the delays."""
    from subid.delay import input_delay_of
    delays = input_delay_of(model)
    if delays is None:
        return ""
    return ", 'InputDelay', [" + " ".join(str(int(d)) for d in delays) + "]"


def _matlab_noise(model, delay: str = "") -> str:
    """The innovation form as MATLAB's idss (System Identification Toolbox)."""
    if model.K is None or model.is_continuous:
        return ""
    text = f"\nK = {_matlab_matrix(model.K)};"
    extra = ""
    if model.noise_cov is not None:
        text += f"\nNoiseVariance = {_matlab_matrix(model.noise_cov)};"
        extra = ", 'NoiseVariance', NoiseVariance"
    return text + (f"\nmodel = idss(A, B, C, D, K, zeros({model.order}, 1), {model.dt!r}"
                   f"{extra}{delay});")


def _pole_table(model, hz: bool) -> str:
    p = model.poles()
    # dt = 1: the period of a record without time information (IOData's default), so
    # frequencies per sample and time constants in samples (the same numbers as per
    # second with dt = 1 s)
    unit = unit_of_frequency([model.dt], hz)
    time_unit = "samples" if model.dt == 1.0 else "s"
    rows = []
    for z in p:
        if model.dt > 0:
            s = complex(np.log(complex(z))) / model.dt if z != 0 else complex(-np.inf)
            mag = abs(z)
        else:
            s = complex(z)
            mag = None
        wn = abs(s)
        zeta = -s.real / wn if wn > 0 and np.isfinite(wn) else float("nan")
        freq = wn / (2 * math.pi) if hz else wn
        tau = -1.0 / s.real if s.real < 0 and np.isfinite(s.real) else float("nan")
        cells = [_fmt_complex(complex(z))]
        if mag is not None:
            cells.append(_fmt(mag, 5))
        cells += [_fmt(freq, 4), _fmt(zeta, 3), _fmt(tau, 4)]
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    head = "<th>pole</th>" + ("<th>|pole|</th>" if model.dt > 0 else "") + \
        f"<th>natural frequency ({unit})</th><th>damping</th><th>time constant ({time_unit})</th>"
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def _info_table(info: dict, input_names=None, output_names=None) -> str:
    info = {k: v for k, v in info.items() if k != "polynomials"}   # shown as polynomials
    rows = []
    for key in sorted(info):
        value = info[key]
        if isinstance(value, (bool, np.bool_, int, float, str, np.integer, np.floating)) \
                and not isinstance(value, np.ndarray):
            rows.append(f'<tr><th class="l">{_e(key)}</th><td class="l">{_e(_fmt(value))}</td></tr>')
        elif isinstance(value, (list, tuple, np.ndarray)) and np.asarray(value).ndim == 1 \
                and np.asarray(value).size <= 12 and np.asarray(value).dtype.kind in "biuf":
            text = ", ".join(_fmt(v, 4) for v in np.asarray(value))
            rows.append(f'<tr><th class="l">{_e(key)}</th><td class="l">{_e(text)}</td></tr>')
        elif key == "order_selection" and isinstance(value, dict):
            from subid.methods.describe import describe_order_selection as describe
            rows.append(f'<tr><th class="l">{_e(key)}</th><td class="l">{_e(describe(value))}'
                        "</td></tr>")
        elif key == "feedthrough" and isinstance(value, dict):
            from subid.methods.describe import describe_feedthrough
            text = describe_feedthrough(value, option="feedthrough=True (on the command "
                                                      "line: --option feedthrough=true)",
                                        input_names=input_names, output_names=output_names)
            if text:
                rows.append(f'<tr><th class="l">{_e(key)}</th><td class="l">{_e(text)}'
                            "</td></tr>")
        elif key == "stability" and isinstance(value, dict):
            text = value.get("action", "")
            if value.get("how") and text != "none":
                text += f": {value['how']}"
            rows.append(f'<tr><th class="l">{_e(key)}</th><td class="l">{_e(text)}</td></tr>')
    if not rows:
        return ""
    return f"<table>{''.join(rows)}</table>"


def write_html(path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(text)


def _labelled(models) -> dict:
    """The models of a report as ``{label: model}``: one model is labelled by its method."""
    from subid.model.statespace import StateSpace
    if isinstance(models, StateSpace):
        return {str(models.info.get("method", "model")): models}
    return dict(models)


def _page(title: str, body: list[str], nav: list[tuple[str, str]] = ()) -> str:
    links = "".join(f'<a href="#{_e(i)}">{_e(t)}</a>' for i, t in nav)
    from subid import __version__ as version
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<title>{_e(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
            f"<h1>{_e(title)}</h1>\n<p class=\"meta\">subid {_e(version)}, {stamp}</p>\n"
            + (f"<nav>{links}</nav>\n" if links else "") + "\n".join(body) +
            "\n</body>\n</html>\n")


def _section(sid: str, heading: str, content: str) -> str:
    return f'<section id="{_e(sid)}">\n<h2>{_e(heading)}</h2>\n{content}\n</section>'


def comparison_page(fits, output_names, *, title: str, source: str, n_samples: int,
                    what: str, figure: str = "", command: str = "") -> str:
    """The page of ``subid compare``: one row of fit % per model, then the figure.

    Parameters
    ----------
    fits : dict
        Model label -> fit % per output.
    output_names : sequence of str
        Column headings.
    title : str
        Page title.
    source : str
        Where the data come from (shown above the table).
    n_samples : int
        Length of the record the fits were computed on.
    what : str
        ``'simulated'`` or ``'K-step predicted'``: the heading of the figure.
    figure : str
        HTML of the figure (:func:`figure_html`).
    command : str
        Command line that made the page.

    Returns
    -------
    str
        A complete HTML document (write it with :func:`write_html`).
    """
    rows = "".join(
        f"<tr><td class=\"l\">{_e(name)}</td>"
        + "".join(f"<td>{_fmt_fit([v])}</td>" for v in values) + "</tr>"
        for name, values in fits.items())
    head = "".join(f"<th>{_e(n)}</th>" for n in output_names)
    body = [_section("summary", "Fit %",
                     f"<p>{_e(source)}: {n_samples} samples.</p>"
                     f"<table><tr><th class=\"l\">model</th>{head}</tr>{rows}</table>"
                     f"<pre>{_e(command)}</pre>"),
            _section("compare", f"{what.capitalize()} and measured outputs", figure)]
    return _page(title, body)


def failure_page(title: str, errors) -> str:
    """A page saying that every method failed, with each one's error.

    Parameters
    ----------
    title : str
        Page title.
    errors : dict
        Method name -> error message.

    Returns
    -------
    str
        A complete HTML document.
    """
    return _page(title, [_section(
        "summary", "Summary", "<p>every method failed:</p><ul>" + "".join(
            f"<li>{_e(name)}: {_e(message)}</li>" for name, message in errors.items())
        + "</ul>")])


# ---------------------------------------------------------------------------
# numbers
# ---------------------------------------------------------------------------
def evaluate(model, estimation, validation=None) -> dict:
    """Fit % on the estimation and validation parts, stability and poles.

    Parameters
    ----------
    model : StateSpace
    estimation : IOData
    validation : IOData, optional

    Returns
    -------
    dict
        ``fit_estimation`` and ``fit_validation`` (arrays per output, from
        :func:`subid.fit_percent`; ``None`` without validation data; NaN
        where the simulation diverges), ``stable``, ``poles``, ``order``, and
        ``simulated``: the simulated outputs behind the last fit (on
        ``validation``, else on ``estimation``; NaN where the simulation
        diverges), which :func:`identification_report` draws in its comparison
        instead of simulating the model again.
    """
    from subid.evaluation.plot import simulated_output
    from subid.model.fit import output_fit
    from subid.model.prediction import simulate_fit

    def fit(data):
        if data is None:
            return None, None
        with np.errstate(all="ignore"):
            try:         # fit_percent's simulation and fit, the simulation kept
                y_hat, _ = simulate_fit(model, data)
                values = np.asarray(output_fit(data, y_hat), dtype=float)
            except ModelError:                 # the simulation overflows
                y_hat, values = simulated_output(model, data)
        values[~np.isfinite(values)] = np.nan
        return values, y_hat

    fit_estimation, simulated = fit(estimation)
    fit_validation, simulated_validation = fit(validation)
    if validation is not None:
        simulated = simulated_validation
    return {"fit_estimation": fit_estimation, "fit_validation": fit_validation,
            "stable": model.is_stable(), "poles": model.poles(), "order": model.order,
            "simulated": simulated}


# ---------------------------------------------------------------------------
# the report
# ---------------------------------------------------------------------------
def _spa_estimate(estimation, models):
    """The spa estimate of the estimation record for the Bode overlay, or None when
    it does not apply (non-uniform or input-free data, other channels, too short)."""
    from subid.evaluation.nonparametric import spa
    first = next(iter(models.values()), None)
    if first is None or estimation.dt is None or estimation.n_inputs == 0 or \
            (first.n_inputs, first.n_outputs) != (estimation.n_inputs, estimation.n_outputs):
        return None
    import warnings
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return spa(estimation)
    except SubidError as exc:
        log.info("report: no spa overlay (%s)", exc)
        return None


def _collector_paused(fn):
    """``fn`` run with Python's cyclic garbage collector paused, as :mod:`timeit` times
    a statement.

    A report builds and drops tens of thousands of matplotlib objects (artists,
    transforms, paths: a figure's are reference cycles, freed by the collector only).
    Their allocations set off collections of the whole heap, which in a process that
    has identified a model holds every module loaded (numpy, scipy, numba, the
    methods): 0.1 to 0.25 CPU s of a report's 1.3 s in ``bench/report_ratio.py``,
    depending on when the full collections fall. With the collector paused they do
    not run; the report's own garbage is collected once at the end (the youngest
    generation: the objects made during the report), so the figures' memory is
    released as before. The pause is the process's for the duration of the call
    (another thread's cycles wait until it ends); a collector disabled by the
    caller stays disabled, and an exception restores it as well.
    """
    @functools.wraps(fn)
    def paused(*args, **kwargs):
        enabled = gc.isenabled()
        gc.disable()
        try:
            return fn(*args, **kwargs)
        finally:
            if enabled:
                gc.enable()
                gc.collect(0)
    return paused


@_collector_paused
@_figures_aside
def identification_report(models, estimation, validation=None, *, title="subid report",
                          frequency_unit="rad/s", history=None, seconds=None, notes=(),
                          command=None, source=None, errors=None, data=None,
                          max_lag: int = 25, progress=None, fits=None) -> str:
    """HTML text of a complete identification report.

    Parameters
    ----------
    models : StateSpace or dict label -> StateSpace
        The identified models (same channels).
    estimation : IOData
        Data the models were identified on.
    validation : IOData, optional
        Held-out data; the comparison and residual sections use it when
        given (else the estimation data).
    title : str
    frequency_unit : {'rad/s', 'Hz'}
        Unit of the Bode frequency axis and of the pole table.
    history : dict, optional
        Online runs: snapshots for :func:`subid.plot.convergence`; adds the
        ``convergence`` section.
    seconds : dict label -> float, optional
        Identification time of each model, shown in the summary.
    notes : sequence of str
        Paragraphs shown under the summary (data provenance, caveats).
    command : str, optional
        The command line that produced the report.
    source : str, optional
        Where the data come from (file name or dataset).
    errors : dict label -> str, optional
        Methods that failed, listed in the summary.
    data : IOData, optional
        The whole record for the overview (default: estimation followed by
        validation, as split).
    max_lag : int
        Largest lag of the residual correlations.
    progress : callable, optional
        Called with each section's id as its work starts (a progress display).
    fits : dict label -> dict, optional
        The :func:`evaluate` result of a model on ``estimation`` and
        ``validation``, when the caller has it already (not computed again).

    Returns
    -------
    str
        The HTML document (sections: :data:`SECTIONS`).
    """
    from subid.evaluation import plot
    models = _labelled(models)
    hz = str(frequency_unit).lower() == "hz"
    seconds = seconds or {}
    errors = errors or {}
    check = validation if validation is not None else estimation
    check_name = "validation" if validation is not None else "estimation"
    body, nav = [], []
    announce = progress or (lambda section: None)
    announce("summary")
    fits = fits or {}
    results = {label: fits[label] if label in fits else evaluate(m, estimation, validation)
               for label, m in models.items()}

    # -- summary ---------------------------------------------------------
    ny = estimation.n_outputs
    outs = ", ".join(estimation.output_names)
    rows = []
    for label, m in models.items():
        r = results[label]
        stable = '<span class="good">yes</span>' if r["stable"] else \
            '<span class="bad">NO</span>'
        rows.append(
            f'<tr><td class="l">{_e(label)}</td><td class="l">{_e(m.info.get("method", ""))}</td>'
            f"<td>{m.order}</td><td>{_e(_horizon_cell(m))}</td>"
            f"<td>{'continuous' if m.dt == 0 else _fmt(m.dt)}</td>"
            f"<td>{_fmt_fit(r['fit_estimation'])}</td><td>{_fmt_fit(r['fit_validation'])}</td>"
            f"<td>{stable}</td><td>{_fmt(seconds[label], 3) if label in seconds else '—'}</td></tr>")
    for label, msg in errors.items():
        rows.append(f'<tr><td class="l">{_e(label)}</td><td class="l bad" colspan="8">'
                    f"failed: {_e(msg)}</td></tr>")
    table = ("<table><tr><th class=\"l\">model</th><th class=\"l\">method</th><th>order</th>"
             "<th>horizon</th><th>dt</th>"
             f"<th>fit % estimation ({_e(outs)})</th><th>fit % validation ({_e(outs)})</th>"
             "<th>stable</th><th>time (s)</th></tr>" + "".join(rows) + "</table>")
    n_est = estimation.n_samples
    n_val = validation.n_samples if validation is not None else 0
    timing = f"dt = {_fmt(estimation.dt)}" if estimation.dt is not None else \
        "non-uniform time stamps"
    if estimation.dt == 1.0 and not estimation.has_time_stamps:
        timing += " (time in samples, frequencies per sample)"
    facts = (f"<p>{_e(source) + ': ' if source else ''}{n_est + n_val} samples "
             f"({n_est} for estimation, {n_val} for validation), "
             f"{estimation.n_inputs} input{'s' if estimation.n_inputs != 1 else ''} "
             f"({_e(', '.join(estimation.input_names))}), {ny} output{'s' if ny != 1 else ''} "
             f"({_e(outs)}), {_e(timing)}.</p>")
    fit_note = ("<p class=\"note\">Fit % = 100 (1 − ‖y − ŷ‖ / ‖y − mean y‖) per output, ŷ "
                "simulated from a least-squares initial state (subid.fit_percent); 100 is "
                "perfect, 0 no better than the mean.</p>")
    extra = "".join(f"<p class=\"note\">{_e(n)}</p>" for n in notes)
    first_model = next(iter(models.values()), None)
    point = operating_point(first_model, estimation) if first_model is not None else None
    if point is not None:
        u0, y0 = point
        extra += ("<p class=\"note\">Operating point: the models relate deviations from the "
                  "channel means removed before identification, "
                  + _e(", ".join(f"{n} = {_fmt(v)}" for n, v in zip(estimation.input_names, u0))
                       + "; " + ", ".join(f"{n} = {_fmt(v)}"
                                          for n, v in zip(estimation.output_names, y0)))
                  + ". In the data's units: y = G(u − u0) + y0 (the MATLAB code below "
                    "includes u0 and y0).</p>")
    elif first_model is not None and \
            (lines := removed_lines(first_model, estimation)) is not None:
        extra += f"<p class=\"note\">No operating point: {_e(lines)}.</p>"
    cmd = f"<p>Reproduce with:</p><pre>{_e(command)}</pre>" if command else ""
    body.append(_section("summary", "Summary", facts + table + fit_note + extra + cmd))
    nav.append(("summary", "summary"))

    # -- data overview ---------------------------------------------------
    announce("data")
    whole = data
    split = None
    if validation is not None:
        split = float(validation[:1].t[0])      # not the whole record's stamps
    if whole is None and validation is not None:
        whole, split = _concat(estimation, validation)
    if whole is None:
        whole = estimation
    body.append(_section("data", "Data", _plot_or_note(
        lambda: plot.data_overview(whole, split=split),
        "inputs (grey) and outputs (black); the validation part is shaded", "data overview")))
    nav.append(("data", "data"))

    # -- order selection -------------------------------------------------
    announce("order")
    profiled = {label: m for label, m in models.items()
                if m.info.get("singular_values") is not None
                or m.info.get("rank_profile") is not None}
    chosen = {label: m for label, m in models.items() if _order_scored(m)}
    if profiled:
        scores = _plot_or_note(
            lambda: plot.order_scores(chosen),
            "the score of every candidate order and horizon: cross-validated simulation fit "
            "on the estimation data (selection='cv'), or the gap of the profile "
            "(selection='gap'); ring: the chosen candidate", "order scores") if chosen else ""
        body.append(_section("order", "Order selection", _plot_or_note(
            lambda: plot.order_selection(profiled),
            "singular values (MOESP, N4SID, ct) or SVD-free rank profile (ls) relative to the "
            "first; ring and dotted line: the order of each model", "order-selection chart")
            + scores))
        nav.append(("order", "order"))

    # -- comparison ------------------------------------------------------
    announce("compare")
    # the simulations behind the fits (evaluate): not run again for the figure
    simulated = {label: r["simulated"] for label, r in results.items()
                 if r.get("simulated") is not None}
    fit_key = "fit_validation" if validation is not None else "fit_estimation"
    scored = {label: (simulated[label], np.asarray(results[label][fit_key], dtype=float))
              for label in models if label in simulated
              and np.shape(simulated[label]) == check.y.shape
              and results[label].get(fit_key) is not None}

    def comparison():
        if len(scored) == len(models):       # the fits of the summary, not computed again
            from subid.evaluation.figures.time_domain import compare_outputs
            return compare_outputs(check, models, scored)
        return plot.compare(check, models, simulated=simulated)

    body.append(_section("compare", f"Simulated and measured outputs ({check_name} data)",
                         _plot_or_note(comparison,
                                       f"simulation on the {check_name} data from a "
                                       "least-squares initial state; fit % in the legend",
                                       "comparison")))
    nav.append(("compare", "compare"))

    # -- Bode ------------------------------------------------------------
    announce("bode")
    nyquist = "; dotted: Nyquist frequency" if any(m.dt > 0 for m in models.values()) else ""
    level = 0.95 if any(isinstance(m.info.get("parameter_covariance"), dict)
                        for m in models.values()) else None
    band = ("; shaded: 95 % confidence band (models with a parameter covariance: identify, "
            "pem and the polynomial methods)") if level else ""
    estimate = _spa_estimate(estimation, models)
    # the unit of the axis plot.bode draws (per sample when time is counted in samples)
    bode_unit = unit_of_frequency([m.dt for m in models.values()]
                               + ([estimate.dt] if estimate is not None else []), hz)
    overlay = "; grey points: spa estimate of the estimation data (± 2 std shaded)" \
        if estimate is not None else ""
    body.append(_section("bode", "Frequency response (Bode)", _plot_or_note(
        lambda: plot.bode(models, hz=hz, confidence=level, data=estimate),
        f"magnitude and phase; frequency in {bode_unit}{nyquist}{band}{overlay}",
        "Bode diagram")))
    nav.append(("bode", "Bode"))
    announce("step")
    body.append(_section("step", "Step response", _plot_or_note(
        lambda: plot.step(models, confidence=level),
        f"response to a unit step on each input{band}", "step response")))
    nav.append(("step", "step"))

    # -- poles -----------------------------------------------------------
    announce("poles")
    pole_tables = "".join(f"<h3>{_e(label)}</h3>{_pole_table(m, hz)}"
                          for label, m in models.items())
    body.append(_section("poles", "Poles", _plot_or_note(
        lambda: plot.poles({k: [m] for k, m in models.items()}, marker="x", markersize=8,
                           alpha=0.9),
        "poles of each model with the unit circle (discrete time) or the imaginary axis "
        "(continuous time)", "pole map") + pole_tables))
    nav.append(("poles", "poles"))


    # -- residuals -------------------------------------------------------
    announce("residuals")
    body.append(_section("residuals", "Residual analysis", _plot_or_note(
        lambda: plot.residuals(models, check, max_lag=max_lag,
                               title=f"residuals on the {check_name} data (99 % bands)"),
        "left: auto-correlation of the residuals e = y − ŷ, the one-step prediction errors for a "
        "model with a Kalman gain K (as MATLAB's resid), the simulation errors otherwise (white "
        f"residuals stay inside the band); right: correlation of each input with the residuals at lags −{max_lag}..{max_lag} "
        "(a good "
        "model leaves none at positive lags); bands: 99 % confidence under no correlation",
        "residual analysis")))
    nav.append(("residuals", "residuals"))

    # -- convergence -----------------------------------------------------
    announce("convergence")
    if history is not None:
        body.append(_section("convergence", "Convergence of the online estimate", _plot_or_note(
            lambda: plot.convergence(history),
            "poles and parameters of the online estimate against the number of samples "
            "processed", "convergence plot")))
        nav.append(("convergence", "convergence"))

    # -- matrices --------------------------------------------------------
    announce("matrices")
    parts = []
    for label, m in models.items():
        states = [f"x{k + 1}" for k in range(m.order)]
        block = [f"<h3>{_e(label)}</h3>",
                 f"<p>{'continuous time (dt = 0)' if m.dt == 0 else f'discrete time, dt = {_fmt(m.dt)}'}"
                 f", order {m.order}</p>"]
        poly = polynomials_of(m)
        if poly is not None:       # a polynomial model: its polynomials, then the realisation
            block += ["<p>polynomials (in q<sup>-1</sup>; the state-space matrices below "
                      "are their realisation)</p>",
                      f"<pre>{_e(chr(10).join(describe_polynomials(poly, m.input_names, m.output_names, _coefficient_std(m))))}</pre>"]
        block += ["<p>A</p>", _matrix_table(m.A, states, states),
                 "<p>B</p>", _matrix_table(m.B, states, m.input_names),
                 "<p>C</p>", _matrix_table(m.C, m.output_names, states),
                 "<p>D</p>", _matrix_table(m.D, m.output_names, m.input_names)]
        if m.K is not None:
            block += ["<p>K (Kalman gain of the innovation form x⁺ = A x + B u + K e, "
                      "y = C x + D u + e)</p>", _matrix_table(m.K, states, m.output_names)]
        if m.noise_cov is not None:
            how = m.info.get("noise_cov_estimate")
            block += [f"<p>noise covariance (of the innovations e{'; ' + _e(how) if how else ''})"
                      "</p>", _matrix_table(m.noise_cov, m.output_names, m.output_names)]
        x0 = m.info.get("x0")
        if x0 is not None and np.asarray(x0).size == m.order:
            block += ["<p>initial state x0 (estimation data)</p>",
                      _matrix_table(np.asarray(x0, dtype=float)[None, :], ["x0"], states)]
        elif x0 is not None and np.ndim(x0) == 2 and np.shape(x0)[1] == m.order:
            names = m.info.get("experiment_names") or [f"exp{k + 1}"
                                                       for k in range(np.shape(x0)[0])]
            block += ["<p>initial state x0 of every experiment (estimation data)</p>",
                      _matrix_table(np.asarray(x0, dtype=float), list(names), states)]
        info = _info_table(m.info, m.input_names, m.output_names)
        if info:
            block += ["<p>diagnostics (model.info)</p>", info]
        code = _matlab_code(m, operating_point(m, estimation), removed_lines(m, estimation))
        block += ["<p>MATLAB</p>", f"<pre>{_e(code)}</pre>"]
        parts.append("".join(block))
    body.append(_section("matrices", "Model matrices", "".join(parts)))
    nav.append(("matrices", "matrices"))
    return _page(title, body, nav)


def _horizon_cell(model) -> str:
    """The summary table's horizon of a model: '—' where none applies (a polynomial
    model's ``info['horizon']`` is None)."""
    horizon = model.info.get("horizon")
    return "—" if horizon is None else str(horizon)


def _order_scored(model) -> bool:
    """Whether ``plot.order_scores`` can chart the model's order selection: a 'cv' or
    'gap' record over state orders (and horizons for 'cv'), not, say, the ARX
    structures (na, nb) of the polynomial methods."""
    record = model.info.get("order_selection")
    if not isinstance(record, dict) or record.get("rule") not in ("cv", "gap"):
        return False
    keys = ("order",) if record["rule"] == "gap" else ("order", "horizon")
    return all(all(k in c for k in keys) for c in record.get("candidates", []))


def _concat(a, b):
    """The record ``a`` followed by ``b`` for the data overview, and the time at which
    ``b`` starts there. Halves of a split keep their stamps; a validation record of its
    own (MATLAB's ``ze``/``zv`` from two experiments: both from t = 0) is drawn after
    the estimation record, its stamps shifted to follow it by one step (its own times
    are in the other figures); records of several experiments are merged."""
    from subid.data import IOData, merge
    if a.n_experiments > 1 or b.n_experiments > 1:    # for the figures only
        return merge([a, b]), float(b[:1].t[0])
    u = np.vstack([a.u, b.u])
    y = np.vstack([a.y, b.y])
    tb = b.t
    if tb[0] <= a.t[-1]:
        step = a.dt if a.dt is not None else float(np.median(np.diff(a.t))) \
            if a.n_samples > 1 else 1.0
        tb = tb - tb[0] + a.t[-1] + step
    t = np.concatenate([a.t, tb])
    return (IOData(u, y, t=t, input_names=a.input_names, output_names=a.output_names),
            float(tb[0]))


def _cell_note(reason: str, hint: str, link: str) -> str:
    """The line under a bad value of the index: why, and what to try (linked)."""
    return (f'<div class="why">{_e(reason)}; <a href="{_e(link)}">try</a>: {_e(hint)}</div>')


def index_page(entries, *, title="subid reports", intro="", columns=(), footer="") -> str:
    """HTML index linking several reports.

    Parameters
    ----------
    entries : list of dict
        Each with ``name``, ``href`` (relative link to the report) and one
        value per column name in ``columns`` (HTML-escaped text); optionally
        ``notes``, ``{column: (reason, hint, link)}``: a line shown under that
        cell saying why its value is bad, what to try, and a relative link
        (say to the report section that shows it).
    title, intro : str
    columns : sequence of str
        Extra table columns.
    footer : str

    Returns
    -------
    str
    """
    head = "<tr><th class=\"l\">report</th>" + "".join(f"<th>{_e(c)}</th>" for c in columns) \
        + "</tr>"
    rows = []
    for entry in entries:
        notes = entry.get("notes") or {}
        cells = "".join(f"<td>{_e(entry.get(c, ''))}{_cell_note(*notes[c]) if c in notes else ''}"
                        "</td>" for c in columns)
        rows.append(f'<tr><td class="l"><a href="{_e(entry["href"])}">{_e(entry["name"])}</a>'
                    f"</td>{cells}</tr>")
    body = []
    if intro:
        body.append(f"<p>{_e(intro)}</p>")
    body.append(_section("reports", "Reports", f"<table>{head}{''.join(rows)}</table>"))
    if footer:
        body.append(f"<p class=\"note\">{_e(footer)}</p>")
    return _page(title, body)

