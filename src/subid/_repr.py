"""Text and HTML summaries of models, records and online identifiers, and the decisions a
model records in ``info`` in words (:func:`describe_feedthrough`, which the reports and
the command line read through :mod:`subid.methods.describe`).

Jupyter shows an object through its ``_repr_html_`` method; the classes
(:class:`~subid.model.StateSpace`, :class:`~subid.data.IOData`,
:class:`~subid.methods.online.recursive.RecursiveSubspace`,
:class:`~subid.methods.online.adaptive.AdaptiveIdentifier`) delegate to the functions here so
that presentation stays out of the numerics. Everything is computed from
quantities the object already holds, plus at most one eigenvalue problem of
the model order: the summaries are cheap on any record size (signals are
reduced to at most :data:`SPARK_POINTS` min/max pairs before drawing). The
figures are small inline SVG drawings, so no plotting library is needed.
"""

from __future__ import annotations

import html
import math

import numpy as np

# Points (min/max pairs) of a signal drawn in a sparkline.
SPARK_POINTS = 120
# Channels of a record drawn as sparklines; the others are listed only.
MAX_SPARK_CHANNELS = 6
# Largest order whose matrices are printed in full.
MAX_MATRIX_ORDER = 6
# Poles listed in text.
MAX_POLES_LISTED = 8

_STYLE = ("border-collapse:collapse;font-family:sans-serif;font-size:12px;"
          "margin:2px 0")
_TD = "padding:1px 8px;text-align:left;border-bottom:1px solid #ddd"
_COLOR = "#1f77b4"


def _esc(value) -> str:
    return html.escape(str(value))


def _names(names, limit: int = 8) -> str:
    names = list(names)
    shown = ", ".join(names[:limit])
    return shown + (f", … ({len(names)} in all)" if len(names) > limit else "")


def _default(count: int, prefix: str) -> list[str]:
    return [f"{prefix}{i + 1}" for i in range(count)]


def _fmt(x: float) -> str:
    if x is None:
        return "–"
    x = float(x)
    if not math.isfinite(x):
        return str(x)
    return f"{x:.4g}"


def _table(rows) -> str:
    body = "".join(f"<tr><th style='{_TD};font-weight:600'>{_esc(k)}</th>"
                   f"<td style='{_TD}'>{v}</td></tr>" for k, v in rows)
    return f"<table style='{_STYLE}'>{body}</table>"


def _timing(dt) -> str:
    if dt is None:
        return "non-uniform time stamps"
    if dt == 0:
        return "continuous time (dt = 0)"
    return f"discrete time, dt = {_fmt(dt)}"


def _fmt_complex(z: complex) -> str:
    if abs(z.imag) <= 1e-12 * max(1.0, abs(z.real)):
        return _fmt(z.real)
    sign = "+" if z.imag >= 0 else "−"
    return f"{_fmt(z.real)} {sign} {_fmt(abs(z.imag))}j"


# ---------------------------------------------------------------------------
# StateSpace
# ---------------------------------------------------------------------------
def stability_text(model, poles=None) -> str:
    """'stable', 'unstable' or 'marginally stable', with the number that says so."""
    poles = model.poles() if poles is None else poles
    if model.is_continuous:
        edge = float(np.max(poles.real))
        what = f"max Re(pole) = {_fmt(edge)}"
        stable, marginal = edge < 0, edge == 0
    else:
        edge = float(np.max(np.abs(poles)))
        what = f"spectral radius = {_fmt(edge)}"
        stable, marginal = edge < 1, edge == 1
    word = "stable" if stable else ("marginally stable" if marginal else "unstable")
    return f"{word} ({what})"


def _pole_svg(poles, continuous: bool, size: int = 130) -> str:
    """Pole map: unit circle (discrete) or imaginary axis (continuous)."""
    re, im = poles.real, poles.imag
    if continuous:
        span = max(1e-12, float(np.max(np.abs(np.concatenate([re, im])))) * 1.15)
    else:
        span = max(1.15, float(np.max(np.abs(poles))) * 1.15)
    half = size / 2

    def px(x, y):
        return half + x / span * (half - 4), half - y / span * (half - 4)

    parts = [f"<svg xmlns='http://www.w3.org/2000/svg' width='{size}' height='{size}' "
             f"viewBox='0 0 {size} {size}' role='img' aria-label='pole map'>",
             f"<line x1='0' y1='{half}' x2='{size}' y2='{half}' stroke='#bbb'/>",
             f"<line x1='{half}' y1='0' x2='{half}' y2='{size}' stroke='#bbb'/>"]
    if not continuous:
        r = (half - 4) / span
        parts.append(f"<circle cx='{half}' cy='{half}' r='{r:.2f}' fill='none' "
                     "stroke='#888' stroke-dasharray='3,2'/>")
    for x, y, z in zip(re, im, poles):
        cx, cy = px(x, y)
        bad = (x >= 0) if continuous else (abs(z) >= 1)
        color = "#d62728" if bad else _COLOR
        parts.append(f"<path d='M{cx - 3:.1f},{cy - 3:.1f}L{cx + 3:.1f},{cy + 3:.1f}"
                     f"M{cx - 3:.1f},{cy + 3:.1f}L{cx + 3:.1f},{cy - 3:.1f}' "
                     f"stroke='{color}' stroke-width='1.6'/>")
    parts.append("</svg>")
    return "".join(parts)


def _matrix_html(name: str, M: np.ndarray) -> str:
    rows = "".join("<tr>" + "".join(f"<td style='padding:0 6px;text-align:right'>"
                                    f"{_fmt(v)}</td>" for v in row) + "</tr>" for row in M)
    return (f"<div style='display:inline-block;margin-right:12px;vertical-align:top'>"
            f"<b>{name}</b><table style='{_STYLE};font-family:monospace'>{rows}</table></div>")


def statespace_html(model) -> str:
    """HTML summary of a :class:`~subid.model.StateSpace` for Jupyter."""
    info = model.info
    poles = model.poles()
    rows = [("order", model.order),
            ("inputs", f"{model.n_inputs}: {_esc(_names(model.input_names))}"
             if model.n_inputs else "none"),
            ("outputs", f"{model.n_outputs}: {_esc(_names(model.output_names))}"),
            ("time", _timing(model.dt)),
            ("stability", _esc(stability_text(model, poles)))]
    if "method" in info:
        rows.insert(0, ("method", _esc(info["method"])))
    for key, label in (("horizon", "horizon"), ("n_samples", "samples"),
                       ("input_delay", "input delay (samples)")):
        if key in info and info[key] is not None:
            value = info[key]
            if isinstance(value, np.ndarray):
                value = value.tolist()
            rows.append((label, _esc(value)))
    for key in ("fit_estimation", "fit_validation", "fit"):
        if key in info and info[key] is not None:
            vals = np.atleast_1d(np.asarray(info[key], dtype=float))
            rows.append((key.replace("_", " ") + " %", ", ".join(_fmt(v) for v in vals)))
    direct = describe_feedthrough(info.get("feedthrough"), input_names=model.input_names,
                                  output_names=model.output_names)
    if direct is not None:
        rows.append(("direct term", _esc(direct)))
    covariance = info.get("parameter_covariance")
    if isinstance(covariance, dict):
        rows.append(("covariance", "parameter covariance: confidence bounds available "
                     "(subid.freqresp_bounds, plot.bode(..., confidence=0.95))"))
    listed = ", ".join(_fmt_complex(complex(p)) for p in poles[:MAX_POLES_LISTED])
    if poles.size > MAX_POLES_LISTED:
        listed += f", … ({poles.size} in all)"
    rows.append(("poles", listed))
    data = info.get("data")
    if isinstance(data, dict) and data.get("u_offset") is not None:
        rows.append(("operating point",
                     "u₀ = " + _esc(np.round(np.asarray(data["u_offset"], float), 6).tolist())
                     + ", y₀ = "
                     + _esc(np.round(np.asarray(data["y_offset"], float), 6).tolist())))
    out = ["<div><b>StateSpace</b>",
           "<div style='display:flex;gap:16px;align-items:flex-start'>",
           _table(rows), _pole_svg(poles, model.is_continuous), "</div>"]
    if model.order <= MAX_MATRIX_ORDER and model.n_inputs <= 6 and model.n_outputs <= 6:
        out.append("<div>" + "".join(_matrix_html(n, M) for n, M in
                                     (("A", model.A), ("B", model.B), ("C", model.C),
                                      ("D", model.D)) if M.size) + "</div>")
    out.append("</div>")
    return "".join(out)


# ---------------------------------------------------------------------------
# IOData
# ---------------------------------------------------------------------------
def _envelope(x: np.ndarray, points: int = SPARK_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of ``x`` over at most ``points`` consecutive blocks."""
    n = x.size
    if n <= points:
        return x, x
    edges = np.linspace(0, n, points + 1).astype(np.int64)
    return np.minimum.reduceat(x, edges[:-1]), np.maximum.reduceat(x, edges[:-1])


def sparkline_svg(x: np.ndarray, width: int = 180, height: int = 28) -> str:
    """A min/max envelope of one channel as a small inline SVG."""
    lo, hi = _envelope(np.asarray(x, dtype=float))
    vmin, vmax = float(lo.min()), float(hi.max())
    scale = (height - 2) / (vmax - vmin) if vmax > vmin else 0.0
    k = lo.size
    xs = np.linspace(1, width - 1, k) if k > 1 else np.array([width / 2])

    def ys(v):
        return height - 1 - (v - vmin) * scale if scale else np.full(v.shape, height / 2)

    top = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(xs, ys(hi)))
    bottom = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(xs[::-1], ys(lo)[::-1]))
    return (f"<svg xmlns='http://www.w3.org/2000/svg' width='{width}' height='{height}' "
            f"role='img' aria-label='signal'><polygon points='{top} {bottom}' "
            f"fill='{_COLOR}' fill-opacity='0.35' stroke='{_COLOR}' stroke-width='0.8'/></svg>")


def iodata_html(data) -> str:
    """HTML summary of an :class:`~subid.data.IOData` record for Jupyter."""
    t = data.t
    span = float(t[-1] - t[0])
    timing = _timing(data.dt)
    if data.dt == 1.0 and not data.has_time_stamps:
        timing += " (the default: time counted in samples)"
    rows = [("samples", data.n_samples), ("time", timing),
            ("span", f"{_fmt(t[0])} to {_fmt(t[-1])} ({_fmt(span)})")]
    if data.n_experiments > 1:
        rows.append(("experiments", _esc(", ".join(
            f"{name} ({b - a})" for name, (a, b) in zip(data.experiment_names,
                                                         data.experiment_ranges)))))
    if data.u_offset is not None:
        rows.append(("removed offsets", "u: " + _esc(np.round(np.asarray(data.u_offset), 6)
                                                     .tolist())
                     + "; y: " + _esc(np.round(np.asarray(data.y_offset), 6).tolist())))
    head = (f"<tr><th style='{_TD}'>channel</th><th style='{_TD}'>role</th>"
            f"<th style='{_TD}'>mean</th><th style='{_TD}'>std</th>"
            f"<th style='{_TD}'>min</th><th style='{_TD}'>max</th>"
            f"<th style='{_TD}'>signal</th></tr>")
    lines = []
    channels = [(n, "input", data.u[:, j]) for j, n in enumerate(data.input_names)] + \
        [(n, "output", data.y[:, j]) for j, n in enumerate(data.output_names)]
    for i, (name, role, x) in enumerate(channels):
        spark = sparkline_svg(x) if i < MAX_SPARK_CHANNELS else ""
        lines.append(f"<tr><td style='{_TD}'>{_esc(name)}</td><td style='{_TD}'>{role}</td>"
                     f"<td style='{_TD}'>{_fmt(x.mean())}</td><td style='{_TD}'>{_fmt(x.std())}"
                     f"</td><td style='{_TD}'>{_fmt(x.min())}</td><td style='{_TD}'>"
                     f"{_fmt(x.max())}</td><td style='{_TD}'>{spark}</td></tr>")
    return (f"<div><b>IOData</b>{_table(rows)}<table style='{_STYLE}'>{head}"
            + "".join(lines) + "</table></div>")


# ---------------------------------------------------------------------------
# online identifiers
# ---------------------------------------------------------------------------
def online_html(ident, settings) -> str:
    """HTML summary of an online identifier: its settings, the samples seen
    and, once it has one, its current model."""
    name = type(ident).__name__
    rows = [(k, _esc(v)) for k, v in settings]
    from subid.errors import SubidError
    try:
        model = ident.model if ident.n_samples else None
        why = "no samples yet" if model is None else ""
    except SubidError as exc:     # too few samples, not exciting yet, ...
        model, why = None, str(exc)
    out = [f"<div><b>{_esc(name)}</b>", _table(rows)]
    if model is not None:
        out.append("<div style='margin-left:12px'>current model:" + statespace_html(model)
                   + "</div>")
    else:
        out.append(f"<div style='font-family:sans-serif;font-size:12px'>no model yet: "
                   f"{_esc(why)}</div>")
    out.append("</div>")
    return "".join(out)


def recursive_repr(ident) -> str:
    return (f"RecursiveSubspace(order={ident.order}, n_inputs={ident.n_inputs}, "
            f"n_outputs={ident.n_outputs}, horizon={ident._f}, "
            f"forgetting={ident._lam:g}, dt={ident._dt:g}, samples={ident.n_samples})")


def recursive_settings(ident) -> list[tuple[str, object]]:
    return [("order", ident.order),
            ("inputs", f"{ident.n_inputs}: {_names(ident._input_names)}"),
            ("outputs", f"{ident.n_outputs}: {_names(ident._output_names)}"),
            ("time", _timing(ident._dt)), ("horizon", ident._f),
            ("forgetting", ident._lam), ("instruments", ident.instruments),
            ("samples", ident.n_samples)]


def adaptive_settings(ident) -> list[tuple[str, object]]:
    last = ident.t
    return [("order", ident._n),
            ("inputs", f"{ident._nu}: {_names(ident._input_names or _default(ident._nu, 'u'))}"),
            ("outputs",
             f"{ident._ny}: {_names(ident._output_names or _default(ident._ny, 'y'))}"),
            ("time", "continuous time (dt = 0)"), ("horizon", ident._f),
            ("filter poles", np.round(np.asarray(ident._poles), 6).tolist()),
            ("forgetting", f"{ident._alpha:g} (A, C), {ident._beta:g} (B, D)"),
            ("samples", ident.n_samples),
            ("last time", "–" if last is None else _fmt(last))]


# ---------------------------------------------------------------------------
# decisions in words
# ---------------------------------------------------------------------------
def describe_feedthrough(record, *, option: str = "feedthrough=True", input_names=None,
                         output_names=None) -> str | None:
    """One line saying whether the model has a direct term D, and why.

    Under ``feedthrough='auto'`` (:mod:`subid.methods.dt.feedthrough`) D is fixed at
    zero when the data show feedback from the outputs to the inputs, because a direct
    term and a feedback without delay give the same lag-0 correlation; the line then
    names the inputs the feedback test flagged and what a free D would take from each
    output's one-step prediction error (``lag0_share``), and how to ask for D: the
    decision stays the data's, and the user who knows the plant has the last word.

    Parameters
    ----------
    record : dict or None
        ``model.info['feedthrough']``.
    option : str
        How the reader asks for D (``'--option feedthrough=true'`` on the command line).
    input_names, output_names : list of str, optional
        Channel names for the line (default ``u1..``, ``y1..``).

    Returns
    -------
    str or None
        None without a record.
    """
    if not isinstance(record, dict) or "estimated" not in record:
        return None
    estimated = bool(record["estimated"])
    if record.get("requested") != "auto":
        return "D estimated (asked)" if estimated else "D = 0 (asked)"
    direct = record.get("direct_term")
    feedback = record.get("feedback")
    if estimated:
        if isinstance(direct, dict) and direct.get("significant"):
            p = min((v for v in direct.get("p_values", []) if v is not None), default=None)
            return "D estimated: the data show a direct term" + (
                f" (F-test, p = {p:.2g})" if p is not None else "")
        return "D estimated: " + (str(direct) if isinstance(direct, str)
                                   else "the past explains the outputs exactly")
    if isinstance(feedback, dict) and feedback.get("detected"):
        level = float(record.get("level", 0.01))
        p_values = feedback.get("p_values", [])
        names = list(input_names) if input_names is not None else \
            _default(len(p_values), "u")
        flagged = [names[j] for j, v in enumerate(p_values)
                   if v is not None and v < level / max(len(p_values), 1)]
        shares = record.get("lag0_share") or []
        outs = list(output_names) if output_names is not None else \
            _default(len(shares), "y")
        share = ", ".join(f"{100 * v:.0f} % ({name})" for name, v in zip(outs, shares))
        return (f"D = 0: the data show feedback to {', '.join(flagged) or 'the inputs'}, "
                "under which a direct term cannot be told apart"
                + (f"; a free D would take {share} of the one-step prediction error"
                   if share else "")
                + f"; pass {option} if the plant has a direct term and the feedback a delay")
    if isinstance(direct, dict):
        p = min((v for v in direct.get("p_values", []) if v is not None), default=None)
        return "D = 0: no direct term in the data" + (
            f" (F-test, p = {p:.2g})" if p is not None else "")
    return "D = 0" + (f": {direct}" if isinstance(direct, str) else "")
