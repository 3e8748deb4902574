"""Residual analysis: whiteness and input correlation (:func:`residuals`,
:func:`residual_correlations`)."""

from __future__ import annotations

import numbers

import numpy as np

from subid.errors import DataError
from subid.evaluation.figures._common import (
    _check_data,
    _layout,
    _legend_beside,
    _legend_room,
    _model_groups,
    _pyplot,
    _styled,
    colors_for,
    log,
    simulated_output,
)
from subid.evaluation.figures._light_axes import subplot_kw


def residual_correlations(model, data, *, max_lag: int = 25, confidence: float = 0.99,
                          x0="estimate") -> dict:
    """Correlations of the residuals, with confidence bounds.

    For a discrete-time model with a Kalman gain ``K`` the residuals are the
    one-step prediction errors (:func:`subid.residuals`, as MATLAB's
    ``resid``). Otherwise the residual is ``e = y - ŷ``, with ``ŷ``
    simulated from an initial state fitted by least squares (the same ``ŷ``
    as :func:`subid.fit_percent`).
    For a good model ``e`` is uncorrelated with past inputs; for a model that
    also explains the disturbances, ``e`` is white.

    Parameters
    ----------
    model : StateSpace
    data : IOData
    max_lag : int
        Largest lag (in samples).
    confidence : float
        Two-sided level of the bands (0.99: 99 %).
    x0 : 'estimate', None, 'zero', 0 or array
        Initial state, as in :func:`subid.fit_percent`.

    Returns
    -------
    dict
        ``lags`` (0..M), ``auto`` (ny, M+1) normalised auto-correlation of
        each residual, ``auto_bound`` (scalar ``z / sqrt(N)``), ``cross_lags``
        (-M..M), ``cross`` (ny, nu, 2M+1) normalised correlation between
        ``e_i(t)`` and ``u_j(t - tau)``, ``cross_bound`` (ny, nu), the band
        ``z sqrt(sum_k r_ee(k) r_uu(k) / N)`` (Ljung, *System Identification*,
        sec. 16.6), ``residual`` (N, ny) and ``confidence``.

    Raises
    ------
    DataError
        The simulation diverges (residuals not finite), or ``max_lag`` is not
        smaller than the record.
    """
    data = _check_data(data)
    if isinstance(max_lag, bool) or not isinstance(max_lag, numbers.Integral) or max_lag < 1:
        raise DataError(f"max_lag must be a positive integer, got {max_lag!r}")
    if not 0 < confidence < 1:
        raise DataError(f"confidence must be in (0, 1), got {confidence!r}")
    n = data.n_samples
    if max_lag >= n:
        raise DataError(f"max_lag {max_lag} must be smaller than the {n} samples of the record")
    from subid._validation import check_magnitude
    from subid.model.prediction import check_model_data, check_x0
    check_model_data(model, data)
    # before the prediction: its DataErrors read as "diverges" (a model left out)
    check_magnitude(data.u, "input", data.input_names)
    check_magnitude(data.y, "output", data.output_names)
    x0 = check_x0(x0, model.order, data.n_experiments)
    if model.K is not None and model.dt > 0:
        # MATLAB's resid: one-step prediction errors of the innovation form
        from subid.evaluation.residuals import residuals as _prediction_residuals
        try:
            return _prediction_residuals(model, data, max_lag=max_lag, confidence=confidence,
                                         x0=x0)
        except DataError as exc:
            raise DataError(f"the one-step prediction diverges: {exc}") from None
    y_hat, _ = simulated_output(model, data, x0=x0)
    e = data.y - y_hat
    if not np.isfinite(e).all():
        raise DataError("the simulated output diverges (residuals are not finite): the model "
                        "is unstable over this record")
    # every correlation is normalised per residual channel, so scale each channel to
    # a maximum of 1 first: a diverging simulation's huge (finite) residual cannot overflow
    peak = np.abs(e).max(axis=0)
    from subid.evaluation.residuals import correlations
    out = correlations(e / np.where(peak > 0, peak, 1.0), data.u, max_lag=max_lag,
                       confidence=confidence)
    if not (np.isfinite(out["auto"]).all() and np.isfinite(out["cross"]).all()):
        raise DataError("the simulated output diverges (its residual correlations overflow): "
                        "the model is unstable over this record")
    return {**out, "residual": e, "kind": "simulation"}


@_styled
def residuals(model, data, *, max_lag: int = 25, confidence: float = 0.99, x0="estimate",
              title=None):
    """Residual analysis (as MATLAB's ``resid``): whiteness and independence of the input.

    Left column: auto-correlation of each output's residual for lags
    0..``max_lag``; other columns: cross-correlation between each input and
    each residual for lags -``max_lag``..``max_lag`` (positive lags: the
    residual against past inputs). Shaded (one model) or dashed (several):
    the ``confidence`` band (99 % by default) under the hypothesis of no
    correlation; see :func:`residual_correlations`.

    Parameters
    ----------
    model : StateSpace, list or dict label -> StateSpace
        One model, or several drawn over each other.
    data : IOData
        Usually the validation part of the record.
    max_lag : int
    confidence : float
    x0 : 'estimate', None, 'zero', 0 or array
        Initial state, as in :func:`subid.fit_percent`.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    DataError
        The simulation of every model diverges (a model whose simulation
        diverges is left out, with a log message, when others remain).
    """
    plt = _pyplot()
    data = _check_data(data)
    groups = _model_groups(model)
    results, failed = {}, {}
    for label, m in groups.items():
        try:
            results[label] = residual_correlations(m, data, max_lag=max_lag,
                                                   confidence=confidence, x0=x0)
        except DataError as exc:
            if "diverges" not in str(exc):
                raise
            failed[label] = str(exc)
            log.info("residuals of %s not drawn: %s", label, exc)
    if not results:
        raise DataError(next(iter(failed.values())))
    ny, nu = data.n_outputs, data.n_inputs
    cols = 1 + nu
    pct = f"{100 * confidence:g} %"
    room = _legend_room(list(results) + [f"{pct} band"])
    fig, axes = plt.subplots(ny, cols, figsize=(min(3.3 * cols + 0.6, 16) + room,
                                                2.0 * ny + 1.0),
                             squeeze=False, subplot_kw=subplot_kw())
    single = len(results) == 1
    offsets = np.linspace(-0.2, 0.2, len(results)) if not single else [0.0]
    colors = colors_for((label, groups[label]) for label in results)
    # the artists of ax.vlines and ax.axhline, made directly and the data limits of each
    # panel updated once (_Panel): those calls recompute the limits at every artist
    panels = [[_Panel(axes[i, c]) for c in range(cols)] for i in range(ny)]
    for k, (label, res) in enumerate(results.items()):
        color = colors[k]
        dx = offsets[k]
        for i in range(ny):
            ax = axes[i, 0]
            b = res["auto_bound"]
            if k == 0:
                ax.axhspan(-b, b, color="0.5", alpha=0.18, lw=0, label=f"{pct} band")
            panels[i][0].stems(res["lags"] + dx, res["auto"][i], color=color, lw=1.1)
            ax.plot(res["lags"] + dx, res["auto"][i], "o", color=color, ms=2.5,
                    label=label)
            for j in range(nu):
                ax = axes[i, 1 + j]
                b = res["cross_bound"][i, j]
                if single:
                    ax.axhspan(-b, b, color="0.5", alpha=0.18, lw=0)
                else:
                    panels[i][1 + j].hline(b, color=color, ls="--", lw=0.7)
                    panels[i][1 + j].hline(-b, color=color, ls="--", lw=0.7)
                panels[i][1 + j].stems(res["cross_lags"] + dx, res["cross"][i, j], color=color,
                                       lw=0.9)
    for i in range(ny):
        for panel in panels[i]:
            panel.hline(0.0, color="k", lw=0.4)
            panel.finish()
    for i in range(ny):
        axes[i, 0].set_title(f"auto-correlation of e({data.output_names[i]})")
        for j in range(nu):
            axes[i, 1 + j].set_title(f"{data.input_names[j]} → e({data.output_names[i]})")
    handles, names = axes[0, 0].get_legend_handles_labels()
    _legend_beside(axes[0, -1], handles, names)
    for j in range(cols):
        axes[-1, j].set_xlabel("lag (samples)")
    heading = title or f"residual analysis ({pct} confidence bands)"
    if failed:
        heading += f"; not drawn (simulation diverges): {', '.join(failed)}"
    fig.suptitle(heading)
    # wgap: room for the cross-correlation panels' tick labels (``−0.015``, ``−0.0015``
    # on long records), which at 0.5 inch ran into the panel on their left
    _layout(fig, axes, top=0.35, hgap=0.6, wgap=0.85, left=0.6, right=room + 0.1)
    return fig


class _Panel:
    """Stems and horizontal lines of one panel, as ``ax.vlines(x, 0, y, color=, lw=)`` and
    ``ax.axhline(y, ...)`` draw them (the same artists, in the order they are added),
    with the data limits updated once by :meth:`finish` instead of at every call."""

    def __init__(self, ax):
        self.ax = ax
        self.low, self.high = [], []          # x (None for a horizontal line), y extents

    def stems(self, x, y, *, color, lw):
        from matplotlib.collections import LineCollection
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        segments = np.zeros((x.size, 2, 2))
        segments[:, :, 0] = x[:, None]
        segments[:, 1, 1] = y
        self.ax.add_collection(LineCollection(segments, colors=[color], linewidths=[lw]),
                               autolim=False)
        if x.size:
            self.low.append((x.min(), min(0.0, y.min())))
            self.high.append((x.max(), max(0.0, y.max())))

    def hline(self, y, **style):
        from matplotlib.lines import Line2D
        self.ax.add_artist(Line2D([0, 1], [y, y], transform=self.ax.get_yaxis_transform(
            which="grid"), **style))
        self.low.append((None, y))
        self.high.append((None, y))

    def finish(self):
        points = self.low + self.high
        xs = [(x, y) for x, y in points if x is not None]
        if xs:
            self.ax.update_datalim(xs)
        self.ax.update_datalim([(0.0, y) for x, y in points if x is None], updatex=False)
        self.ax.autoscale()
