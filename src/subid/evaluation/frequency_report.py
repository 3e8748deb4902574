"""The HTML report of models identified from frequency-response data.

One self-contained page like :func:`subid.evaluation.report.identification_report`
(figures embedded, no script), with sections suited to frequency data:

=================  ==========================================================
``summary``        table: method, order, frequency-domain fit % (estimation /
                   validation frequencies), stability, time; notes, command
``bode``           measured response (points) with the models overlaid
``error``          magnitude of the error ``|G - Ĝ|`` against frequency
``order``          the cross-validated score of every candidate order
``poles``          pole map and pole table
``matrices``       A, B, C, D, diagnostics, MATLAB code
=================  ==========================================================
"""

from __future__ import annotations

import math

import numpy as np

from subid.evaluation.report import (
    _e,
    _figures_aside,
    _fmt,
    _fmt_fit,
    _info_table,
    _labelled,
    _matlab_code,
    _matrix_table,
    _page,
    _plot_or_note,
    _pole_table,
    _section,
)

__all__ = ["frequency_report", "evaluate_frequency", "SECTIONS"]

#: Section ids of a frequency-data report, in order.
SECTIONS = ("summary", "bode", "error", "order", "poles", "matrices")


def evaluate_frequency(model, estimation, validation=None) -> dict:
    """Frequency-domain fit % (:func:`subid.fit_percent` on FRData), poles and stability.

    Parameters
    ----------
    model : StateSpace
    estimation : FRData
    validation : FRData, optional

    Returns
    -------
    dict
        ``fit_estimation``, ``fit_validation`` (None without validation data),
        ``poles``, ``stable``.
    """
    from subid.model.fit import fit_percent
    return {"fit_estimation": fit_percent(model, estimation),
            "fit_validation": None if validation is None else fit_percent(model, validation),
            "poles": model.poles(), "stable": model.is_stable()}


def _error_figure(models, data, hz: bool):
    from subid.evaluation import plot
    from subid.evaluation.figures._common import _layout, _legend_beside, _legend_room
    plt = plot._pyplot()
    ny, nu = data.n_outputs, data.n_inputs
    room = _legend_room(list(models) + ["|G| (data)", "std (data)"])
    fig, axes = plt.subplots(ny, nu, figsize=(min(3.8 * nu + 1.2, 16) + room, 2.0 * ny + 0.8),
                             sharex=True, squeeze=False)
    keep = data.w > 0
    w = data.w[keep] / (2 * math.pi if hz else 1.0)
    colors = plot.colors_for(models.items())
    for k, (label, m) in enumerate(models.items()):
        err = np.abs(data.response[keep] - m.freqresp(data.w[keep]))
        with np.errstate(divide="ignore"):
            err_db = 20 * np.log10(np.maximum(err, 1e-300))
        for i in range(ny):
            for j in range(nu):
                axes[i, j].semilogx(w, err_db[:, i, j], color=colors[k], lw=1.0, label=label)
    with np.errstate(divide="ignore"):
        level = 20 * np.log10(np.maximum(np.abs(data.response[keep]), 1e-300))
    for i in range(ny):
        for j in range(nu):
            ax = axes[i, j]
            ax.semilogx(w, level[:, i, j], ".", color="0.6", ms=2, label="|G| (data)")
            if data.std is not None:
                with np.errstate(divide="ignore"):
                    ax.semilogx(w, 20 * np.log10(np.maximum(data.std[keep][:, i, j], 1e-300)),
                                ":", color="0.3", lw=1.0, label="std (data)")
            ax.set_title(f"{data.input_names[j]} → {data.output_names[i]}")
            ax.set_ylabel("dB")
            ax.grid(True, lw=0.3)
    for j in range(nu):
        axes[-1, j].set_xlabel(f"frequency ({'Hz' if hz else 'rad/s'})")
    _legend_beside(axes[0, -1])          # fixed margins: tight_layout draws the figure twice
    _layout(fig, axes, hgap=0.5, wgap=0.85, right=room + 0.1)
    return fig


@_figures_aside
def frequency_report(models, estimation, validation=None, *, title="subid report",
                     frequency_unit="rad/s", seconds=None, notes=(), command=None,
                     source=None) -> str:
    """HTML text of the report of models identified from frequency-response data.

    Parameters
    ----------
    models : StateSpace or dict label -> StateSpace
    estimation : FRData
        The frequencies the models were identified on.
    validation : FRData, optional
        Held-out frequencies.
    title : str
    frequency_unit : {'rad/s', 'Hz'}
        Unit of the frequency axes and of the pole table.
    seconds : dict label -> float, optional
        Identification time of each model.
    notes : sequence of str
        Paragraphs under the summary.
    command : str, optional
        The command line that produced the report.
    source : str, optional
        Where the data come from.

    Returns
    -------
    str
        The HTML document (sections: :data:`SECTIONS`).
    """
    from subid.evaluation import plot
    models = _labelled(models)
    hz = str(frequency_unit).lower() == "hz"
    seconds = seconds or {}
    body, nav = [], []
    results = {label: evaluate_frequency(m, estimation, validation)
               for label, m in models.items()}
    outs = ", ".join(estimation.output_names)
    rows = []
    for label, m in models.items():
        r = results[label]
        stable = '<span class="good">yes</span>' if r["stable"] else \
            '<span class="bad">NO</span>'
        rows.append(
            f'<tr><td class="l">{_e(label)}</td><td class="l">{_e(m.info.get("method", ""))}'
            f"</td><td>{m.order}</td><td>{'continuous' if m.dt == 0 else _fmt(m.dt)}</td>"
            f"<td>{_fmt_fit(r['fit_estimation'])}</td><td>{_fmt_fit(r['fit_validation'])}</td>"
            f"<td>{stable}</td><td>{_fmt(seconds[label], 3) if label in seconds else '—'}"
            "</td></tr>")
    table = ("<table><tr><th class=\"l\">model</th><th class=\"l\">method</th><th>order</th>"
             f"<th>dt</th><th>fit % estimation ({_e(outs)})</th>"
             f"<th>fit % validation ({_e(outs)})</th><th>stable</th><th>time (s)</th></tr>"
             + "".join(rows) + "</table>")
    n_val = validation.n_frequencies if validation is not None else 0
    band = f"{_fmt(estimation.w[0], 4)} to {_fmt(estimation.w[-1], 4)} rad per time unit"
    timing = "continuous time" if estimation.dt == 0 else f"dt = {_fmt(estimation.dt)}"
    facts = (f"<p>{_e(source) + ': ' if source else ''}frequency response at "
             f"{estimation.n_frequencies + n_val} frequencies ({estimation.n_frequencies} for "
             f"estimation, {n_val} held out for validation), {_e(band)}, "
             f"{estimation.n_inputs} input(s) ({_e(', '.join(estimation.input_names))}), "
             f"{estimation.n_outputs} output(s) ({_e(outs)}), {_e(timing)}.</p>")
    fit_note = ("<p class=\"note\">Fit % = 100 (1 − ‖W (G − Ĝ)‖ / ‖W (G − Ḡ)‖) per output, "
                "over all frequencies and inputs, W the data's weights, Ḡ the mean response "
                "of each channel pair (subid.fit_percent on FRData); 100 is perfect.</p>")
    extra = "".join(f"<p class=\"note\">{_e(n)}</p>" for n in notes)
    cmd = f"<p>Reproduce with:</p><pre>{_e(command)}</pre>" if command else ""
    body.append(_section("summary", "Summary", facts + table + fit_note + extra + cmd))
    nav.append(("summary", "summary"))

    whole = estimation if validation is None else _joined(estimation, validation)
    body.append(_section("bode", "Frequency response (Bode)", _plot_or_note(
        lambda: plot.bode(models, data=whole, hz=hz),
        "measured response (points; grey band: two standard deviations where known) and the "
        "models", "Bode diagram")))
    nav.append(("bode", "Bode"))
    body.append(_section("error", "Error against frequency", _plot_or_note(
        lambda: _error_figure(models, whole, hz),
        "|G − Ĝ| of each model (dB) with the measured level |G|", "error plot")))
    nav.append(("error", "error"))

    chosen = {label: m for label, m in models.items()
              if isinstance(m.info.get("order_selection"), dict)
              and m.info["order_selection"].get("rule") in ("cv", "gap")}
    if chosen:
        body.append(_section("order", "Order selection", _plot_or_note(
            lambda: plot.order_scores(chosen),
            "score of every candidate order: the fit on held-out frequencies (four "
            "interleaved folds), or the singular-value gap; ring: the chosen order",
            "order scores")))
        nav.append(("order", "order"))

    pole_tables = "".join(f"<h3>{_e(label)}</h3>{_pole_table(m, hz)}"
                          for label, m in models.items())
    body.append(_section("poles", "Poles", _plot_or_note(
        lambda: plot.poles({k: [m] for k, m in models.items()}, marker="x", markersize=8,
                           alpha=0.9),
        "poles of each model", "pole map") + pole_tables))
    nav.append(("poles", "poles"))

    parts = []
    for label, m in models.items():
        states = [f"x{k + 1}" for k in range(m.order)]
        kind = "continuous time (dt = 0)" if m.dt == 0 else f"discrete time, dt = {_fmt(m.dt)}"
        block = [f"<h3>{_e(label)}</h3>", f"<p>{kind}, order {m.order}</p>",
                 "<p>A</p>", _matrix_table(m.A, states, states),
                 "<p>B</p>", _matrix_table(m.B, states, m.input_names),
                 "<p>C</p>", _matrix_table(m.C, m.output_names, states),
                 "<p>D</p>", _matrix_table(m.D, m.output_names, m.input_names)]
        info = _info_table(m.info)
        if info:
            block += ["<p>diagnostics (model.info)</p>", info]
        block += ["<p>MATLAB</p>", f"<pre>{_e(_matlab_code(m))}</pre>"]
        parts.append("".join(block))
    body.append(_section("matrices", "Model matrices", "".join(parts)))
    nav.append(("matrices", "matrices"))
    return _page(title, body, nav)


def _joined(a, b):
    """Estimation and validation frequencies together (sorted), for the figures."""
    from subid.frdata import FRData
    w = np.concatenate([a.w, b.w])
    order = np.argsort(w, kind="stable")

    def both(x, y):
        return None if x is None or y is None else np.concatenate([x, y])[order]
    weights = None
    if a.weights is not None and b.weights is not None and a.weights.ndim == b.weights.ndim:
        weights = both(a.weights, b.weights)
    return FRData(w[order], np.concatenate([a.response, b.response])[order], a.dt,
                  weights=weights, std=both(a.std, b.std),
                  coherence=both(a.coherence, b.coherence), input_names=a.input_names,
                  output_names=a.output_names)
