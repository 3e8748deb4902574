"""Records and fits in time: measured against simulated or predicted outputs
(:func:`compare`) and the record itself (:func:`data_overview`)."""

from __future__ import annotations

import math
import numbers

import numpy as np

from subid.errors import DataError, OptionError
from subid.evaluation.figures._common import (
    _autoscale_once,
    _check_data,
    _draw_trace,
    _finite,
    _layout,
    _legend_beside,
    _legend_room,
    _model_groups,
    _note_envelope,
    _pyplot,
    _styled,
    _time_label,
    _times,
    colors_for,
    percent_fit,
    predicted_output,
    simulated_output,
)
from subid.evaluation.figures._light_axes import subplot_kw


@_styled
def compare(data, models, *, labels=None, x0="estimate", title=None, clip=True,
            steps=math.inf, simulated=None):
    """Measured outputs against the outputs simulated by each model (as MATLAB's ``compare``).

    Parameters
    ----------
    data : IOData
        The record to simulate on (usually the validation part).
    models : StateSpace, list or dict label -> StateSpace
    labels : list of str, optional
    x0 : 'estimate', None, 'zero', 0 or array
        Initial state of the simulations and predictions, as in
        :func:`subid.fit_percent` (default: least squares fit to the data).
    title : str, optional
    clip : bool
        Keep the vertical range near the measured signal, so a diverging
        simulation does not squash the plot.
    steps : int or math.inf
        Draw ``steps``-ahead predictions (:func:`subid.predict`) instead of
        the simulation.
    simulated : dict label -> ndarray, optional
        Outputs already simulated on ``data`` with ``x0`` (shape (n_samples,
        n_outputs), NaN where diverging: the ``simulated`` entry of
        :func:`subid.evaluation.report.evaluate`), drawn and scored instead of
        simulating those models again (with ``steps=math.inf`` only).

    Returns
    -------
    matplotlib.figure.Figure
        One panel per output; legends give the fit % of each model.
    """
    from subid.model.prediction import _check_steps
    data = _check_data(data)
    groups = _model_groups(models, labels)
    steps = _check_steps(steps)                      # as subid.predict takes it
    _check_simulated(simulated, groups, data, steps)
    given = simulated if simulated is not None and steps == math.inf else {}
    fits = {label: (given[label], percent_fit(data, given[label]))
            if label in given and np.shape(given[label]) == data.y.shape else
            simulated_output(m, data, x0=x0) if steps == math.inf else
            predicted_output(m, data, steps, x0) for label, m in groups.items()}
    return compare_outputs(data, groups, fits, title=title, clip=clip)


def _check_simulated(simulated, groups, data, steps) -> None:
    """Refuse a ``simulated`` argument of :func:`compare` that would be ignored or drawn
    wrong: not a dict, labels of no model, arrays of another shape, or given with
    predictions (``steps`` finite)."""
    if simulated is None:
        return
    if not isinstance(simulated, dict):
        raise DataError(f"simulated must be a dict label -> simulated outputs (shape "
                        f"{data.y.shape}), got {type(simulated).__name__}")
    if steps != math.inf:
        raise DataError("simulated holds simulations; with steps (predictions) leave it out")
    for label, values in simulated.items():
        if label not in groups:
            raise DataError(f"simulated has the label {label!r}, which is not one of the "
                            f"models {list(groups)}")
        if np.shape(values) != data.y.shape:
            raise DataError(f"simulated[{label!r}] has shape {np.shape(values)}; the "
                            f"outputs of the record have shape {data.y.shape}")


@_styled
def compare_outputs(data, models, outputs, *, title=None, clip=True):
    """The figure of :func:`compare` for outputs already computed and scored.

    Parameters
    ----------
    data : IOData
        The record the outputs were computed on.
    models : dict label -> StateSpace
        The models (their colours).
    outputs : dict label -> (ndarray, ndarray)
        For each label of ``models``: its outputs on ``data`` (shape (n_samples,
        n_outputs), NaN where diverging) and their fit % per output (the legend). The
        report passes the simulations and fits of
        :func:`subid.evaluation.report.evaluate`, computed once.
    title : str, optional
    clip : bool
        As in :func:`compare`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    ny = data.n_outputs
    colors = colors_for(models.items())
    fits = {label: outputs[label] for label in models}
    texts = [f"{label}: fit {_fmt_fit(f[1][i])} %" for label, f in fits.items()
             for i in range(ny)]
    room = _legend_room(texts + ["measured"])
    fig, axes = plt.subplots(ny, 1, figsize=(9 + room, 2.3 * ny + 0.7), sharex=True,
                             squeeze=False, subplot_kw=subplot_kw())
    t = _times(data)      # the stamps the bands draw, not all of them
    # the measured output is drawn on top (zorder), thin and black; the models under
    # it, wider and lighter, so that both stay visible where they agree (a long
    # record: the measured band outlined, the models' bands filled, see _draw_trace)
    with _autoscale_once(axes):      # the limits once, after the plotting calls
        for i in range(ny):
            _draw_trace(axes[i, 0], t, data.y[:, i], color="k", lw=0.7, fill=False,
                        zorder=3, label="measured")
        for k, (label, (y_hat, fit)) in enumerate(fits.items()):
            for i in range(ny):
                _draw_trace(axes[i, 0], t, _finite(y_hat[:, i]), color=colors[k], lw=1.8,
                            alpha=0.75, zorder=2, label=f"{label}: fit {_fmt_fit(fit[i])} %")
    for i in range(ny):
        ax = axes[i, 0]
        ax.set_ylabel(data.output_names[i])
        _legend_beside(ax)
        if clip:
            lo, hi = float(np.min(data.y[:, i])), float(np.max(data.y[:, i]))
            pad = 0.5 * (hi - lo) if hi > lo else 1.0
            ax.set_ylim(lo - pad, hi + pad)
    axes[-1, 0].set_xlabel(_time_label(data))
    if title:
        fig.suptitle(title)
    _layout(fig, axes, hgap=0.2, left=0.85, right=room + 0.1)
    _note_envelope(fig, t.size)
    return fig


def _fmt_fit(value) -> str:
    if not np.isfinite(value):
        return "n/a"
    if abs(value) >= 1e4:
        return f"{value:.3g}"
    return f"{value:.1f}"


@_styled
def data_overview(data, *, split=None, title=None):
    """Inputs and outputs of a record against time.

    Parameters
    ----------
    data : IOData
    split : float, optional
        Time at which the validation part starts; it is shaded and labelled.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        One panel per channel, inputs first.
    """
    plt = _pyplot()
    data = _check_data(data)
    if split is not None:
        t0, t1 = float(data.t[0]), float(data.t[-1])
        if isinstance(split, (bool, np.bool_)) or not isinstance(split, numbers.Real) \
                or not t0 <= float(split) <= t1:
            raise OptionError(f"split is the time at which the validation part starts, a "
                              f"number from {t0:g} to {t1:g} (the record's first and last "
                              f"time stamps); got {split!r}"[:300])
    # measured data in neutral tones (outputs black as in compare): the palette colours
    # belong to the methods (METHOD_COLORS)
    channels = [(f"input\n{n}", data.u[:, k], "0.45") for k, n in enumerate(data.input_names)]
    channels += [(f"output\n{n}", data.y[:, k], "k") for k, n in enumerate(data.output_names)]
    rows = len(channels)
    fig, axes = plt.subplots(rows, 1, figsize=(9, 1.25 * rows + 0.9), sharex=True,
                             squeeze=False, subplot_kw=subplot_kw())
    t = _times(data)      # the stamps the bands draw, not all of them
    with _autoscale_once(axes):      # the limits once, after the plotting calls
        for ax, (name, values, color) in zip(axes[:, 0], channels):
            _draw_trace(ax, t, values, color=color, lw=0.8)
            ax.set_ylabel(name, fontsize=9, rotation=0, ha="right", va="center")
            if split is not None:
                ax.axvspan(split, t[-1], color="0.85", zorder=0)
    if split is not None:
        axes[0, 0].text(split, 1.02, " validation", transform=axes[0, 0].get_xaxis_transform(),
                        fontsize=9, va="bottom")
        axes[0, 0].text(t[0], 1.02, "estimation", transform=axes[0, 0].get_xaxis_transform(),
                        fontsize=9, va="bottom")
    axes[-1, 0].set_xlabel(_time_label(data))
    if title:
        fig.suptitle(title)
    _layout(fig, axes, top=0.35, left=1.6, hgap=0.15)
    _note_envelope(fig, t.size)
    return fig
