"""Plots for identified models and data. matplotlib is imported lazily.

Install the ``plot`` extra (``pip install ".[plot]"`` in the source folder).
Every function returns a :class:`matplotlib.figure.Figure` and never shows or
saves it: the caller
decides (``fig.savefig(...)``, or display in a notebook). Without a display
(no ``DISPLAY`` on Linux) the ``Agg`` backend is selected.

=====================================  ==========================================
:func:`data_overview`                  inputs and outputs against time
:func:`compare`                        measured against simulated outputs, fit %
:func:`bode`                           magnitude and phase, bands, measured data
:func:`step`                           step responses (with confidence bands)
:func:`poles`                          pole map with unit circle / imaginary axis
:func:`residuals`                      residual whiteness and input correlation
:func:`convergence`                    poles and parameters of an online run
:func:`order_selection`                singular values / rank profile, chosen order
:func:`error_histograms`               Monte-Carlo error distributions
=====================================  ==========================================

Every figure is drawn at 150 dpi with 10 pt text (:data:`STYLE`); a method has
the same colour in every figure (:data:`METHOD_COLORS`, by
``model.info['method']``); legends sit beside the axes, never over the data;
unstable models are dashed and marked "(unstable)" in the Bode diagram.

>>> import subid
>>> data = subid.datasets.load("dryer").detrend()          # doctest: +SKIP
>>> est, val = data.split(0.7)                              # doctest: +SKIP
>>> model = subid.moesp(est)                                # doctest: +SKIP
>>> subid.plot.compare(val, {"moesp": model})               # doctest: +SKIP
>>> subid.plot.bode(model, hz=True)                         # doctest: +SKIP
"""

from __future__ import annotations

import logging
import math
import numbers

import numpy as np

from subid.errors import DataError, ModelError

__all__ = ["poles", "error_histograms", "bode", "step", "compare", "residuals",
           "residual_correlations", "convergence", "data_overview", "frequency_grid",
           "simulated_output", "order_selection", "STYLE", "METHOD_COLORS"]

log = logging.getLogger(__name__)

# Standard normal quantile for a two-sided 99 % band (scipy.special.ndtri(0.995)).
_Z99 = 2.5758293035489004

#: matplotlib settings of every figure: 150 dpi, 10 pt text (9 pt ticks and legends).
STYLE = {"figure.dpi": 150, "savefig.dpi": "figure", "font.size": 10,
         "axes.titlesize": 10, "axes.labelsize": 10, "xtick.labelsize": 9,
         "ytick.labelsize": 9, "legend.fontsize": 9, "figure.titlesize": 11}

#: Colour of each method (``model.info['method']``) in every figure; a second model
#: of the same method in one figure takes the next free colour.
METHOD_COLORS = {"ls_subspace": "C0", "moesp": "C1", "n4sid": "C2", "ct_subspace": "C3",
                 "ct_subspace_paper": "C4", "RecursiveSubspace": "C5",
                 "seed000_adaptive": "C6", "dt_to_ct": "C7", "true": "k"}
_PALETTE = [f"C{k}" for k in range(10)]
# Width of one legend character at 9 pt, inches (for the room beside the axes).
_LEGEND_CHAR_IN = 0.068


def _styled(fn):
    """Draw ``fn``'s figure under :data:`STYLE` (fonts are fixed when text is created)."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        _pyplot()
        import matplotlib
        with matplotlib.rc_context(STYLE):
            return fn(*args, **kwargs)
    return wrapper


def _method_of(model) -> str | None:
    info = getattr(model, "info", None)
    method = info.get("method") if isinstance(info, dict) else None
    return str(method) if method else None


def colors_for(entries) -> list[str]:
    """One distinct colour per entry: the method's colour (:data:`METHOD_COLORS`)
    when free, else the first unused one. ``entries``: (label, model or None)."""
    used, out = set(), []
    for label, model in entries:
        method = _method_of(model) if model is not None else None
        want = METHOD_COLORS.get(method) or METHOD_COLORS.get(str(label))
        if want is None or want in used:
            want = next((c for c in _PALETTE if c not in used and
                         c not in METHOD_COLORS.values()), None) or \
                next((c for c in _PALETTE if c not in used), _PALETTE[len(out) % 10])
        used.add(want)
        out.append(want)
    return out


def _legend_room(labels, ncol: int = 1) -> float:
    """Inches needed beside the axes for a legend with these labels."""
    longest = max((len(str(t)) for t in labels), default=0)
    return 0.25 + ncol * (0.45 + _LEGEND_CHAR_IN * longest)


def _legend_beside(ax, handles=None, labels=None, ncol: int = 1):
    """Legend to the right of ``ax``, top aligned: it never covers the data."""
    kwargs = dict(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                  ncol=ncol, frameon=False)
    if handles is not None:
        return ax.legend(handles, labels, **kwargs)
    return ax.legend(**kwargs)


def is_unstable(model) -> bool:
    """True when a pole lies outside the unit circle (discrete time) or in the
    right half plane (continuous time); marginal poles count as unstable."""
    p = model.poles()
    return bool(np.any(np.abs(p) >= 1.0)) if model.dt > 0 else bool(np.any(p.real >= 0.0))


def _pyplot():
    try:
        import matplotlib
        if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
            import os
            if not os.environ.get("DISPLAY") and os.name != "nt":
                matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the install
        from subid._extras import install_hint
        raise ImportError("subid.plot needs matplotlib: "
                          + install_hint("plot", "matplotlib")) from exc
    return plt


# ---------------------------------------------------------------------------
# argument helpers
# ---------------------------------------------------------------------------
def _model_groups(models, labels=None) -> dict:
    """``{label: StateSpace}`` from one model, a list or a dict."""
    from subid.model.statespace import StateSpace
    if isinstance(models, StateSpace):
        out = {labels[0] if labels else _default_label(models, 0): models}
    elif isinstance(models, dict):
        out = dict(models)
        if labels is not None:
            out = dict(zip(labels, out.values()))
    else:
        try:
            items = list(models)
        except TypeError:
            raise ModelError(f"expected a StateSpace, a list or a dict of them, got "
                             f"{type(models).__name__}") from None
        names = list(labels) if labels is not None else \
            [_default_label(m, k) for k, m in enumerate(items)]
        out = {}
        for name, m in zip(names, items):
            while name in out:
                name += "'"
            out[name] = m
    if not out:
        raise ModelError("no model to plot")
    for label, m in out.items():
        if not isinstance(m, StateSpace):
            raise ModelError(f"{label!r} is a {type(m).__name__}, not a subid.StateSpace")
    return {str(k): v for k, v in out.items()}


def _default_label(model, k: int) -> str:
    method = model.info.get("method") if isinstance(model.info, dict) else None
    return str(method) if method else f"model {k + 1}"


def _check_data(data):
    from subid.data import IOData
    if not isinstance(data, IOData):
        raise DataError(f"data must be an IOData record, got {type(data).__name__}")
    return data


def _time_label(data) -> str:
    return "time (s)" if data.dt is None or data.dt != 1.0 else "time (samples)"


def _layout(fig, axes, *, top: float = 0.45, bottom: float = 0.55, left: float = 0.85,
            right: float = 0.2, hgap: float = 0.45, wgap: float = 0.7) -> None:
    """Place the axes grid with fixed margins and gaps in inches.

    Much faster than ``tight_layout`` (which draws the figure once more), and
    the margins do not depend on the data. ``hgap``/``wgap`` are the spaces
    between rows/columns (room for the titles and tick labels).
    """
    from matplotlib.ticker import MaxNLocator
    rows, cols = axes.shape
    w, h = fig.get_size_inches()
    if getattr(fig, "_suptitle", None) is not None:
        top += 0.3
    avail_h = max(h - top - bottom, 0.5)
    avail_w = max(w - left - right, 0.5)
    ax_h = max((avail_h - (rows - 1) * hgap) / rows, 0.1)
    ax_w = max((avail_w - (cols - 1) * wgap) / cols, 0.1)
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        hspace=hgap / ax_h, wspace=wgap / ax_w)
    for ax in axes.ravel():
        if ax.get_yscale() == "linear":
            ax.yaxis.set_major_locator(MaxNLocator(nbins=4 if ax_h < 1.6 else 6))


def simulated_output(model, data, x0="estimate"):
    """``(y_hat, fit %)`` of ``model`` on ``data``; NaN where the simulation diverges.

    The same simulation as :func:`subid.fit_percent` (least-squares initial
    state by default), but a model whose simulation overflows gives NaN
    instead of an exception, so that it can still be listed and drawn.
    """
    from subid.evaluation.metrics import simulate_fit
    with np.errstate(all="ignore"):
        try:
            y_hat, _ = simulate_fit(model, data, x0=x0)
        except ModelError:                 # the simulation of an unstable model overflows
            y_hat = np.full(data.y.shape, np.nan)
        y_hat = np.where(np.isfinite(y_hat), y_hat, np.nan)
        dev = np.linalg.norm(data.y - data.y.mean(axis=0), axis=0)
        fit = 100.0 * (1.0 - np.linalg.norm(data.y - y_hat, axis=0) /
                       np.where(dev > 0, dev, np.nan))
    return y_hat, fit


def predicted_output(model, data, steps):
    """``(y_hat, fit %)`` of the ``steps``-ahead prediction; NaN where it diverges."""
    from subid.evaluation.prediction import predict
    try:
        y_hat = predict(model, data, steps)
    except DataError:
        y_hat = np.full(data.y.shape, np.nan)
    dev = np.linalg.norm(data.y - data.y.mean(axis=0), axis=0)
    with np.errstate(all="ignore"):
        fit = 100.0 * (1.0 - np.linalg.norm(data.y - y_hat, axis=0) /
                       np.where(dev > 0, dev, np.nan))
    return y_hat, fit


#: Most points a time trace is drawn with. A longer trace is drawn through the minimum
#: and the maximum of each of ``MAX_TRACE_POINTS // 2`` consecutive blocks of samples,
#: in time order: the envelope that a line a few thousand pixels wide shows anyway
#: (a 9-inch figure at 150 dpi is 1350 pixels), so a record of 10^6 samples draws
#: as fast as one of 4,000 and looks the same. The data are never changed.
MAX_TRACE_POINTS = 4000


def _envelope(t: np.ndarray, values: np.ndarray, max_points: int = MAX_TRACE_POINTS):
    """``(t, values)`` reduced to :data:`MAX_TRACE_POINTS` points for drawing: the
    minimum and maximum of each block, in time order (a NaN in a block is kept, so
    the line breaks where the data are not finite)."""
    n = values.shape[0]
    if n <= max_points:
        return t, values
    blocks = max_points // 2
    size = -(-n // blocks)
    padded = np.concatenate([values, np.full(blocks * size - n, values[-1])])
    grid = padded.reshape(blocks, size)
    with np.errstate(invalid="ignore"):
        low, high = np.argmin(grid, axis=1), np.argmax(grid, axis=1)
    base = np.arange(blocks) * size
    index = np.minimum(np.column_stack([base + np.minimum(low, high),
                                        base + np.maximum(low, high)]).ravel(), n - 1)
    return t[index], values[index]


def _finite(values: np.ndarray) -> np.ndarray:
    """``values`` with non-finite entries replaced by NaN (not drawn)."""
    out = np.array(values, dtype=float)
    out[~np.isfinite(out)] = np.nan
    return out


# ---------------------------------------------------------------------------
# pole map
# ---------------------------------------------------------------------------
@_styled
def poles(models, reference=None, *, labels=None, ax=None, title=None, markersize=4,
          marker=".", alpha=0.4):
    """Pole map of one or several groups of models.

    Discrete-time poles are drawn with the unit circle, continuous-time
    poles with the imaginary axis; a mixture of both gets two panels.

    Parameters
    ----------
    models : StateSpace, list of StateSpace, or dict label -> list of StateSpace
        Models whose poles are drawn (one colour per group; a dict value may
        also be a single model).
    reference : StateSpace, optional
        True system; its poles are drawn as large circles.
    labels : list of str, optional
        Group labels replacing the dict keys.
    ax : matplotlib Axes, optional
        Draw into this axes (all groups must then share a time base).
    title : str, optional
    markersize : float
    marker : str
        Matplotlib marker of the estimates (``'x'`` reads well for a few
        models, ``'.'`` for Monte-Carlo clouds).
    alpha : float
        Opacity of the estimates.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    from subid.model.statespace import StateSpace
    if isinstance(models, StateSpace):
        groups = {"model": [models]}
    elif isinstance(models, dict):
        groups = {str(k): list(v) if not isinstance(v, StateSpace) else [v]
                  for k, v in models.items()}
    else:
        groups = {"models": list(models)}
    if labels is not None:
        groups = dict(zip(labels, groups.values()))
    kinds = {m.dt > 0 for group in groups.values() for m in group}
    if reference is not None:
        kinds.add(reference.dt > 0)
    colors = dict(zip(groups, colors_for((k, g[0] if g else None)
                                         for k, g in groups.items())))
    legend_labels = list(groups) + (["true"] if reference is not None else [])
    room = _legend_room(legend_labels)
    if ax is None and len(kinds) == 2:
        fig, axes = plt.subplots(1, 2, figsize=(10.5 + room, 5))
        for sub, discrete in zip(axes, (True, False)):
            part = {k: [m for m in g if (m.dt > 0) == discrete] for k, g in groups.items()}
            ref = reference if reference is not None and (reference.dt > 0) == discrete \
                else None
            _pole_axes(sub, {k: g for k, g in part.items() if g}, ref, discrete, markersize,
                       marker, alpha, colors, legend=False)
            sub.set_title("discrete time (z plane)" if discrete else
                          "continuous time (s plane)")
        handles = [h for a in axes for h in a.get_legend_handles_labels()[0]]
        names = [n for a in axes for n in a.get_legend_handles_labels()[1]]
        seen = {}
        for h, n in zip(handles, names):
            seen.setdefault(n, h)
        _legend_beside(axes[-1], list(seen.values()), list(seen))
        if title:
            fig.suptitle(title)
        width = fig.get_figwidth()     # fixed margins: tight_layout draws the figure twice
        fig.subplots_adjust(left=0.85 / width, right=1 - (room + 0.1) / width,
                            bottom=0.6 / 5, top=1 - (0.75 if title else 0.45) / 5,
                            wspace=0.9 / ((width - room - 1.85) / 2))
        return fig
    own = ax is None
    fig = ax.figure if ax is not None else plt.figure(figsize=(5.0 + room, 5))
    ax = ax if ax is not None else fig.add_subplot(111)
    discrete = True if not kinds else kinds.pop()
    _pole_axes(ax, groups, reference, discrete, markersize, marker, alpha, colors,
               legend=not own)
    if own and (groups or reference is not None):
        _legend_beside(ax)
        fig.subplots_adjust(left=0.85 / fig.get_figwidth(),
                            right=1 - (room + 0.1) / fig.get_figwidth(),
                            bottom=0.6 / 5, top=1 - (0.5 if title else 0.25) / 5)
    if title:
        ax.set_title(title)
    return fig


def _pole_axes(ax, groups, reference, discrete, markersize, marker, alpha, colors=None,
               legend=True):
    colors = colors or {}
    if reference is not None:      # drawn first: the estimates must stay visible
        q = reference.poles()
        ax.plot(q.real, q.imag, "o", ms=16, mfc="none", mec="k", mew=1.2, zorder=1,
                label="true")
    for label, group in groups.items():
        p = np.concatenate([m.poles() for m in group]) if group else np.array([])
        ax.plot(p.real, p.imag, marker, ms=markersize, alpha=alpha, zorder=2, label=label,
                color=colors.get(label), mew=1.5 if marker in ("x", "+") else None)
    if discrete:
        theta = np.linspace(0, 2 * np.pi, 400)
        ax.plot(np.cos(theta), np.sin(theta), "k-", lw=0.6)
        ax.set_aspect("equal")
    else:
        ax.axvline(0.0, color="k", lw=0.6)
    ax.axhline(0.0, color="k", lw=0.3)
    ax.set_xlabel("real part")
    ax.set_ylabel("imaginary part")
    if legend and (groups or reference is not None):
        ax.legend(loc="best")


@_styled
def error_histograms(errors: dict, *, bins=40, xlabel="relative error", title=None):
    """One histogram panel per method of a Monte-Carlo error sample.

    Parameters
    ----------
    errors : dict label -> array of errors
    bins : int
    xlabel, title : str

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    k = len(errors)
    fig, axes = plt.subplots(k, 1, figsize=(8, 1.9 * k + 0.6), sharex=True, squeeze=False)
    all_vals = np.concatenate([np.asarray(v, float) for v in errors.values()])
    lo, hi = all_vals.min(), all_vals.max()
    edges = np.logspace(np.log10(max(lo, 1e-300)), np.log10(max(hi, lo * 1.01)) + 1e-9, bins)
    colors = colors_for((label, None) for label in errors)
    for ax, (label, vals), color in zip(axes[:, 0], errors.items(), colors):
        ax.hist(vals, bins=edges, color=color, alpha=0.8)
        ax.axvline(np.median(vals), color="k", lw=1.5, ls="--",
                   label=f"median {np.median(vals):.3g}")
        ax.set_xscale("log")
        ax.set_ylabel("runs")
        ax.set_title(label, loc="left")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  frameon=False)
    axes[-1, 0].set_xlabel(xlabel)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------
# frequency response
# ---------------------------------------------------------------------------
def frequency_grid(models, n_points: int = 400) -> np.ndarray:
    """A logarithmic grid of angular frequencies (rad/s) suited to ``models``.

    Discrete-time models: up to the Nyquist frequency ``pi / dt`` of the
    fastest-sampled model. Continuous-time models: a decade beyond their
    fastest pole. The lower end is a decade below the slowest non-zero pole
    (and at most a thousandth of the upper end).

    Parameters
    ----------
    models : StateSpace, list or dict of StateSpace
    n_points : int

    Returns
    -------
    ndarray, shape (n_points,)
    """
    groups = _model_groups(models)
    hi_candidates, pole_speeds = [], []
    for m in groups.values():
        p = m.poles()
        if m.dt > 0:
            hi_candidates.append(math.pi / m.dt)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.log(p.astype(complex)) / m.dt
        else:
            s = p
        speed = np.abs(s)
        speed = speed[np.isfinite(speed) & (speed > 0)]
        pole_speeds.extend(speed.tolist())
        if m.dt == 0:
            hi_candidates.append(10 * (speed.max() if speed.size else 1.0))
    hi = max(hi_candidates)
    lo = hi * 1e-3
    if pole_speeds:
        lo = min(lo, 0.1 * min(pole_speeds))
    lo = max(lo, hi * 1e-6)
    return np.logspace(np.log10(lo), np.log10(hi), n_points)


@_styled
def bode(model_or_models=None, w=None, *, data=None, hz=False, labels=None, phase=True,
         title=None, confidence=None):
    """Bode diagram: magnitude (dB) and phase (degrees) of every input/output pair.

    Parameters
    ----------
    model_or_models : StateSpace, list of StateSpace, dict label -> StateSpace or FRData
        Models drawn on the same axes (same numbers of inputs and outputs).
        An :class:`~subid.FRData` here is drawn as ``data`` (without models).
    w : array_like, optional
        Angular frequencies in **rad/s** (default: :func:`frequency_grid`,
        or the data's frequencies when ``data`` is given).
        A discrete-time model is drawn only up to its Nyquist frequency.
    data : FRData, optional
        Measured frequency response, drawn as points under the models (with
        a band of two standard deviations on the magnitude when it has
        ``std``).
    hz : bool
        Label the frequency axis in Hz (``w / 2 pi``) instead of rad/s.
    labels : list of str, optional
        Legend labels (default: the dict keys or ``model.info['method']``).
    phase : bool
        Draw the phase panels.
    title : str, optional
    confidence : float, optional
        Draw the band of this level (e.g. 0.95) around the magnitude of every
        model that has a parameter covariance (:func:`subid.freqresp_bounds`,
        :func:`subid.pem`); a ``ModelError`` when none has one.

    Returns
    -------
    matplotlib.figure.Figure
        Rows: magnitude (and phase) per output; columns: inputs.

    Examples
    --------
    >>> fig = subid.plot.bode({"moesp": m1, "n4sid": m2}, hz=True)   # doctest: +SKIP
    >>> fig = subid.plot.bode(subid.fd_subspace(frd), data=frd)      # doctest: +SKIP
    """
    from subid.frdata import FRData
    plt = _pyplot()
    if isinstance(model_or_models, FRData):
        if data is not None:
            raise DataError("bode: give the frequency data once (as data=)")
        model_or_models, data = None, model_or_models
    if data is not None and not isinstance(data, FRData):
        raise DataError(f"bode: data must be a subid.FRData, got {type(data).__name__}")
    if model_or_models is None and data is None:
        raise ModelError("bode: nothing to draw; give models, data=FRData, or both")
    groups = {} if model_or_models is None else _model_groups(model_or_models, labels)
    first = next(iter(groups.values())) if groups else data
    ny, nu = first.n_outputs, first.n_inputs
    for label, m in groups.items():
        if (m.n_outputs, m.n_inputs) != (ny, nu):
            raise ModelError(f"model {label!r} has {m.n_inputs} inputs and {m.n_outputs} "
                             f"outputs but the first has {nu} and {ny}; a Bode diagram draws "
                             "models of the same shape")
    if data is not None and (data.n_outputs, data.n_inputs) != (ny, nu):
        raise DataError(f"the frequency data have {data.n_inputs} inputs and "
                        f"{data.n_outputs} outputs but the models have {nu} and {ny}")
    if nu == 0:
        raise ModelError("the model has no inputs: there is no frequency response to draw")
    if confidence is not None:
        _require_covariance(groups)
    if w is None:
        w = frequency_grid(groups) if data is None else _data_grid(data)
    else:
        w = np.atleast_1d(np.asarray(w, dtype=float))
        if w.ndim != 1 or not np.isfinite(w).all() or (w <= 0).any():
            raise DataError("w must be a 1-D array of positive frequencies in rad/s")
    x_scale = 1 / (2 * math.pi) if hz else 1.0
    rows = 2 * ny if phase else ny
    colors = colors_for(groups.items())
    unstable = {label: is_unstable(m) for label, m in groups.items()}
    shown = [label + (" (unstable)" if unstable[label] else "") for label in groups]
    room = _legend_room(shown + (["data"] if data is not None else []))
    fig, axes = plt.subplots(rows, nu, figsize=(min(3.8 * nu + 1.2, 16) + room,
                                                1.9 * rows + 0.8),
                             sharex=True, squeeze=False)
    # one log scale for the shared frequency axis: semilogx on every panel would set it
    # again on all the shared axes each time (quadratic in the panels: 5 s of a 5x3 grid)
    axes[0, 0].set_xscale("log")
    reference = None                     # phase of the first model, to align the data's
    for k, (label, m) in enumerate(groups.items()):
        style = dict(color=colors[k], lw=1.2, ls="--" if unstable[label] else "-")
        wk = w if m.dt == 0 else w[w <= math.pi / m.dt * (1 + 1e-12)]
        if wk.size == 0:
            log.warning("bode: model %r has no frequency below its Nyquist frequency in w",
                        label)
            continue
        G = m.freqresp(wk)
        with np.errstate(divide="ignore"):
            mag = 20 * np.log10(np.maximum(np.abs(G), 1e-300))
        ph = np.degrees(np.unwrap(np.angle(G), axis=0))
        if reference is None:
            reference = (wk, ph)
        band = None
        if confidence is not None and _has_covariance(m):
            from subid.evaluation.uncertainty import freqresp_bounds
            band = freqresp_bounds(m, wk, confidence)
        for i in range(ny):
            for j in range(nu):
                r = 2 * i if phase else i
                axes[r, j].plot(wk * x_scale, mag[:, i, j], label=shown[k], **style)
                if band is not None:
                    lo = np.maximum(band.lower[:, i, j], 1e-3 * band.value[:, i, j])
                    axes[r, j].fill_between(wk * x_scale, 20 * np.log10(lo),
                                            20 * np.log10(band.upper[:, i, j]),
                                            color=colors[k], alpha=0.2, lw=0)
                if phase:
                    axes[r + 1, j].plot(wk * x_scale, ph[:, i, j], **style)
    if data is not None:
        _bode_data(axes, data, x_scale, phase, reference)
    for i in range(ny):
        for j in range(nu):
            r = 2 * i if phase else i
            axes[r, j].set_title(f"{first.input_names[j]} → {first.output_names[i]}")
            axes[r, j].set_ylabel("magnitude (dB)")
            axes[r, j].grid(True, lw=0.3)
            if phase:
                axes[r + 1, j].set_ylabel("phase (deg)")
                axes[r + 1, j].grid(True, lw=0.3)
    # dt = 1 is the period of a record without time information (IOData's default):
    # frequencies per sample then (numerically the same as per second with dt = 1 s)
    per_sample = all(m.dt == 1.0 for m in list(groups.values()) + ([data] if data else []))
    unit = ("cycles/sample" if hz else "rad/sample") if per_sample else ("Hz" if hz else "rad/s")
    for j in range(nu):
        axes[-1, j].set_xlabel(f"frequency ({unit})")
    nyquists = sorted({math.pi / m.dt for m in list(groups.values()) + ([data] if data else [])
                       if m.dt > 0})
    for f_nyq in nyquists:
        for ax in axes.ravel():
            ax.axvline(f_nyq * x_scale, color="0.5", lw=0.6, ls=":")
    # minor log ticks are slow to draw (a Tick object each): none on large grids, only
    # at 2 and 5 of every decade otherwise (a quarter of the default 2..9)
    from matplotlib.ticker import LogLocator, NullLocator
    for ax in axes.ravel():
        ax.xaxis.set_minor_locator(NullLocator() if ny * nu > 4 else
                                   LogLocator(base=10.0, subs=(2.0, 5.0)))
    _legend_beside(axes[0, -1])
    if title:
        fig.suptitle(title)
    _layout(fig, axes, hgap=0.5, wgap=0.85, right=room + 0.1)
    return fig


def _data_grid(data) -> np.ndarray:
    """Model frequencies for a Bode diagram over measured data: a log grid over the data's band."""
    positive = data.w[data.w > 0]
    if positive.size < 2:
        return positive if positive.size else np.array([1.0])
    return np.logspace(np.log10(positive[0]), np.log10(positive[-1]), 400)


def _bode_data(axes, data, x_scale, phase, reference=None):
    """Measured response as points (and a two-sigma magnitude band when ``std`` is known).

    The unwrapped phase of each channel is shifted by whole turns to start
    nearest the ``reference`` ``(w, phase)`` of the first model."""
    keep = data.w > 0                                  # a log axis cannot show w = 0
    w, G = data.w[keep] * x_scale, data.response[keep]
    if w.size == 0:
        return
    with np.errstate(divide="ignore"):
        mag = 20 * np.log10(np.maximum(np.abs(G), 1e-300))
    ph = np.degrees(np.unwrap(np.angle(G), axis=0))
    if reference is not None and reference[0].size:
        w_ref, ph_ref = reference
        for i in range(data.n_outputs):
            for j in range(data.n_inputs):
                target = np.interp(data.w[keep][0], w_ref, ph_ref[:, i, j])
                ph[:, i, j] += 360.0 * np.round((target - ph[0, i, j]) / 360.0)
    for i in range(data.n_outputs):
        for j in range(data.n_inputs):
            r = 2 * i if phase else i
            axes[r, j].plot(w, mag[:, i, j], ".", color="0.35", ms=3, label="data",
                                zorder=1)
            if data.std is not None:
                absG, sd = np.abs(G[:, i, j]), 2 * data.std[keep][:, i, j]
                with np.errstate(divide="ignore"):
                    lo = 20 * np.log10(np.maximum(absG - sd, 1e-300 + 1e-12 * absG))
                    hi = 20 * np.log10(np.maximum(absG + sd, 1e-300))
                axes[r, j].fill_between(w, lo, hi, color="0.8", lw=0, zorder=0)
            if phase:
                axes[r + 1, j].plot(w, ph[:, i, j], ".", color="0.35", ms=3, zorder=1)


def _has_covariance(model) -> bool:
    return isinstance(model.info.get("parameter_covariance"), dict)


def _require_covariance(groups) -> None:
    if not any(_has_covariance(m) for m in groups.values()):
        raise ModelError("confidence bands need a model with a parameter covariance; none of "
                         f"{list(groups)} has one: refine a model with subid.pem(data, model)")


@_styled
def step(model_or_models, t=None, *, labels=None, confidence=None, title=None):
    """Step responses of every input/output pair (MATLAB ``step``).

    Parameters
    ----------
    model_or_models : StateSpace, list of StateSpace or dict label -> StateSpace
        Models of the same shape (:meth:`StateSpace.step`).
    t : float or array_like, optional
        Final time or time stamps (default: the slowest model's settling time).
    labels : list of str, optional
        Legend labels.
    confidence : float, optional
        Draw the band of this level (e.g. 0.95) around the response of every
        model that has a parameter covariance (:func:`subid.step_bounds`); a
        ``ModelError`` when none has one.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        One panel per output (rows) and input (columns).
    """
    plt = _pyplot()
    groups = _model_groups(model_or_models, labels)
    first = next(iter(groups.values()))
    ny, nu = first.n_outputs, first.n_inputs
    if nu == 0:
        raise ModelError("the model has no inputs: there is no step response to draw")
    if any((m.n_outputs, m.n_inputs) != (ny, nu) for m in groups.values()):
        raise ModelError("step: the models differ in their numbers of inputs and outputs")
    if confidence is not None:
        _require_covariance(groups)
    if t is None:
        t = max(float(m.step()[0][-1]) for m in groups.values())
    colors = colors_for(groups.items())
    room = _legend_room(list(groups))
    fig, axes = plt.subplots(ny, nu, figsize=(min(3.8 * nu + 1.2, 16) + room, 2.2 * ny + 0.8),
                             sharex=True, squeeze=False)
    for k, (label, m) in enumerate(groups.items()):
        if confidence is not None and _has_covariance(m):
            from subid.evaluation.uncertainty import step_bounds
            band = step_bounds(m, t, confidence)
            tk, y = band.x, band.value
        else:
            band = None
            tk, y = m.step(t)
        for i in range(ny):
            for j in range(nu):
                draw = axes[i, j].step if m.dt > 0 else axes[i, j].plot
                kwargs = {"where": "post"} if m.dt > 0 else {}
                draw(tk, y[:, i, j], color=colors[k], lw=1.2, label=label, **kwargs)
                if band is not None:
                    axes[i, j].fill_between(tk, band.lower[:, i, j], band.upper[:, i, j],
                                            color=colors[k], alpha=0.2, lw=0,
                                            step="post" if m.dt > 0 else None)
    for i in range(ny):
        for j in range(nu):
            axes[i, j].set_title(f"{first.input_names[j]} → {first.output_names[i]}")
            axes[i, j].grid(True, lw=0.3)
    for j in range(nu):
        axes[-1, j].set_xlabel("time")
    _legend_beside(axes[0, -1])
    if title:
        fig.suptitle(title)
    _layout(fig, axes, hgap=0.5, wgap=0.85, right=room + 0.1)
    return fig


# ---------------------------------------------------------------------------
# time-domain comparison
# ---------------------------------------------------------------------------
@_styled
def compare(data, models, *, labels=None, x0="estimate", title=None, clip=True,
            steps=math.inf):
    """Measured outputs against the outputs simulated by each model (as MATLAB's ``compare``).

    Parameters
    ----------
    data : IOData
        The record to simulate on (usually the validation part).
    models : StateSpace, list or dict label -> StateSpace
    labels : list of str, optional
    x0 : 'estimate', 'zero' or array
        Initial state, as in :func:`subid.fit_percent` (default: least
        squares fit to the data).
    title : str, optional
    clip : bool
        Keep the vertical range near the measured signal, so a diverging
        simulation does not squash the plot.
    steps : int or math.inf
        Draw ``steps``-ahead predictions (:func:`subid.predict`) instead of
        the simulation.

    Returns
    -------
    matplotlib.figure.Figure
        One panel per output; legends give the fit % of each model.
    """
    plt = _pyplot()
    data = _check_data(data)
    groups = _model_groups(models, labels)
    ny = data.n_outputs
    colors = colors_for(groups.items())
    fits = {label: simulated_output(m, data, x0=x0) if steps == math.inf else
            predicted_output(m, data, steps) for label, m in groups.items()}
    texts = [f"{label}: fit {_fmt_fit(f[1][i])} %" for label, f in fits.items()
             for i in range(ny)]
    room = _legend_room(texts + ["measured"])
    fig, axes = plt.subplots(ny, 1, figsize=(9 + room, 2.3 * ny + 0.7), sharex=True,
                             squeeze=False)
    t = data.t
    # the measured output is drawn on top (zorder), thin and black; the models under
    # it, wider and lighter, so that both stay visible where they agree
    for i in range(ny):
        axes[i, 0].plot(*_envelope(t, data.y[:, i]), "k-", lw=0.7, zorder=3,
                        label="measured")
    for k, (label, (y_hat, fit)) in enumerate(fits.items()):
        for i in range(ny):
            axes[i, 0].plot(*_envelope(t, _finite(y_hat[:, i])), color=colors[k], lw=1.8,
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
    # measured data in neutral tones (outputs black as in compare): the palette colours
    # belong to the methods (METHOD_COLORS)
    channels = [(f"input\n{n}", data.u[:, k], "0.45") for k, n in enumerate(data.input_names)]
    channels += [(f"output\n{n}", data.y[:, k], "k") for k, n in enumerate(data.output_names)]
    rows = len(channels)
    fig, axes = plt.subplots(rows, 1, figsize=(9, 1.25 * rows + 0.9), sharex=True,
                             squeeze=False)
    t = data.t
    for ax, (name, values, color) in zip(axes[:, 0], channels):
        ax.plot(*_envelope(t, values), color=color, lw=0.8)
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
    return fig


# ---------------------------------------------------------------------------
# residual analysis
# ---------------------------------------------------------------------------
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
    x0 : 'estimate', 'zero' or array

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
    if getattr(model, "K", None) is not None and model.dt > 0:
        # MATLAB's resid: one-step prediction errors of the innovation form
        from subid.evaluation.prediction import residuals as _prediction_residuals
        mode = None if isinstance(x0, str) and x0 == "estimate" else x0
        try:
            return _prediction_residuals(model, data, max_lag=max_lag, confidence=confidence,
                                         x0=mode)
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
    from subid.evaluation.prediction import correlations
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
    x0 : 'estimate', 'zero' or array
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
                             squeeze=False)
    single = len(results) == 1
    offsets = np.linspace(-0.2, 0.2, len(results)) if not single else [0.0]
    colors = colors_for((label, groups[label]) for label in results)
    for k, (label, res) in enumerate(results.items()):
        color = colors[k]
        dx = offsets[k]
        for i in range(ny):
            ax = axes[i, 0]
            b = res["auto_bound"]
            if k == 0:
                ax.axhspan(-b, b, color="0.5", alpha=0.18, lw=0, label=f"{pct} band")
            ax.vlines(res["lags"] + dx, 0, res["auto"][i], color=color, lw=1.1)
            ax.plot(res["lags"] + dx, res["auto"][i], "o", color=color, ms=2.5,
                    label=label)
            for j in range(nu):
                ax = axes[i, 1 + j]
                b = res["cross_bound"][i, j]
                if single:
                    ax.axhspan(-b, b, color="0.5", alpha=0.18, lw=0)
                else:
                    ax.axhline(b, color=color, ls="--", lw=0.7)
                    ax.axhline(-b, color=color, ls="--", lw=0.7)
                ax.vlines(res["cross_lags"] + dx, 0, res["cross"][i, j], color=color, lw=0.9)
    for i in range(ny):
        axes[i, 0].axhline(0, color="k", lw=0.4)
        axes[i, 0].set_title(f"auto-correlation of e({data.output_names[i]})")
        for j in range(nu):
            axes[i, 1 + j].axhline(0, color="k", lw=0.4)
            axes[i, 1 + j].set_title(f"{data.input_names[j]} → e({data.output_names[i]})")
    handles, names = axes[0, 0].get_legend_handles_labels()
    _legend_beside(axes[0, -1], handles, names)
    for j in range(cols):
        axes[-1, j].set_xlabel("lag (samples)")
    heading = title or f"residual analysis ({pct} confidence bands)"
    if failed:
        heading += f"; not drawn (simulation diverges): {', '.join(failed)}"
    fig.suptitle(heading)
    _layout(fig, axes, top=0.35, hgap=0.6, wgap=0.5, left=0.6, right=room + 0.1)
    return fig


# ---------------------------------------------------------------------------
# online runs
# ---------------------------------------------------------------------------
@_styled
def convergence(history, *, reference=None, title=None, max_parameters: int = 12):
    """Poles and parameters of an online identifier against the samples seen.

    Parameters
    ----------
    history : dict
        ``sample`` (k,) and ``poles`` (k, n) complex, as
        :attr:`subid.RecursiveSubspace.history`; optionally ``parameters``
        (k, p) real (e.g. Markov parameters) and ``parameter_names`` (p,).
    reference : StateSpace, optional
        True system: its poles are drawn as dashed lines.
    title : str, optional
    max_parameters : int
        At most this many parameter trajectories are drawn.

    Returns
    -------
    matplotlib.figure.Figure
        Real and imaginary parts of the poles; with parameters, their
        trajectories and their relative distance to the final estimate.
    """
    plt = _pyplot()
    if not isinstance(history, dict) or "sample" not in history or "poles" not in history:
        raise DataError("history must be a dict with the keys 'sample' and 'poles'")
    sample = np.asarray(history["sample"], dtype=float).reshape(-1)
    pol = np.asarray(history["poles"], dtype=complex)
    if pol.ndim != 2 or pol.shape[0] != sample.size:
        raise DataError(f"history['poles'] must have shape ({sample.size}, order), got "
                        f"{pol.shape}")
    params = history.get("parameters")
    if params is not None:
        params = np.asarray(params, dtype=float)
        if params.ndim != 2 or params.shape[0] != sample.size or params.shape[1] == 0:
            params = None
    rows = 2 + (2 if params is not None else 0)
    names = None
    shown = 0
    if params is not None:
        names = list(history.get("parameter_names", [])) or \
            [f"θ{k + 1}" for k in range(params.shape[1])]
        shown = min(params.shape[1], max_parameters)
    legend_texts = [f"pole {k + 1}" for k in range(pol.shape[1])] + ["true poles"] + \
        [str(n) for n in (names or [])[:shown]]
    room = _legend_room(legend_texts)
    fig, axes = plt.subplots(rows, 1, figsize=(9 + room, 2.2 * rows + 0.6), sharex=True,
                             squeeze=False)
    axes = axes[:, 0]
    if sample.size == 0:
        axes[0].text(0.5, 0.5, "no snapshot recorded", ha="center", va="center",
                     transform=axes[0].transAxes)
    for k in range(pol.shape[1]):
        axes[0].plot(sample, pol[:, k].real, ".-", color=f"C{k % 10}", lw=0.8, ms=3,
                     label=f"pole {k + 1}")
        axes[1].plot(sample, pol[:, k].imag, ".-", color=f"C{k % 10}", lw=0.8, ms=3)
    if reference is not None:
        for r, q in enumerate(reference.poles()):
            axes[0].axhline(q.real, color="k", ls="--", lw=0.6,
                            label="true poles" if r == 0 else None)
            axes[1].axhline(q.imag, color="k", ls="--", lw=0.6)
    if pol.shape[1] or reference is not None:
        _legend_beside(axes[0])
    axes[0].set_ylabel("pole real part")
    axes[1].set_ylabel("pole imag. part")
    if params is not None:
        for k in range(shown):
            axes[2].plot(sample, params[:, k], lw=0.9, label=names[k] if k < len(names) else None)
        _legend_beside(axes[2], ncol=1 if shown <= 8 else 2)
        axes[2].set_ylabel("parameters")
        final = params[-1]
        scale = np.linalg.norm(final)
        with np.errstate(all="ignore"):
            rel = np.linalg.norm(params - final, axis=1) / (scale if scale > 0 else 1.0)
        rel[rel <= 0] = np.nan
        axes[3].semilogy(sample, rel, "k.-", lw=0.8, ms=3)
        axes[3].set_ylabel("‖θ − θ_final‖ / ‖θ_final‖")
    for ax in axes:
        ax.grid(True, lw=0.3)
    axes[-1].set_xlabel("samples processed")
    fig.suptitle(title or "convergence of the online estimate")
    _layout(fig, axes[:, None], top=0.25, hgap=0.2, left=1.0, right=room + 0.1)
    return fig


# ---------------------------------------------------------------------------
# order selection
# ---------------------------------------------------------------------------
_PROFILE_KEYS = (("singular_values", "singular value"),
                 ("rank_profile", "rank profile (Cholesky pivot)"))


@_styled
def order_selection(models, *, labels=None, title=None):
    """The order-selection chart: the values whose largest gap picks the order.

    ``info['singular_values']`` (MOESP, N4SID, ct_subspace) or
    ``info['rank_profile']`` (ls_subspace, SVD-free, seed 001 Remark 2) of each
    model, normalised by the first value, on a log scale against their index;
    the order of each model is marked (a ring on its last kept value and a
    vertical line), with the ratio across the gap in the legend.

    Parameters
    ----------
    models : StateSpace, list or dict label -> StateSpace
        Models from the batch methods (their ``info`` holds the profile).
    labels : list of str, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ModelError
        No model carries a profile (e.g. only online models, or models built
        by hand).
    """
    plt = _pyplot()
    groups = _model_groups(models, labels)
    profiles = {}
    for label, m in groups.items():
        for key, what in _PROFILE_KEYS:
            values = m.info.get(key)
            if values is not None and np.size(values) > 0:
                profiles[label] = (np.abs(np.asarray(values, dtype=float).reshape(-1)), what, m)
                break
    if not profiles:
        raise ModelError("no model has info['singular_values'] or info['rank_profile']: the "
                         "order-selection chart needs models from the batch methods")
    texts = []
    for label, (v, _, m) in profiles.items():
        n = m.order
        gap = v[n - 1] / v[n] if n < v.size and v[n] > 0 else math.inf
        texts.append(f"{label}: order {n} (gap ×{gap:.3g})" if math.isfinite(gap)
                     else f"{label}: order {n}")
    room = _legend_room(texts)
    fig, ax = plt.subplots(figsize=(6.5 + room, 3.6))
    colors = colors_for((label, m) for label, (_, _, m) in profiles.items())
    kinds = set()
    for (_label, (v, what, m)), color, text in zip(profiles.items(), colors, texts):
        kinds.add(what)
        scaled = v / v[0] if v[0] > 0 else v
        idx = np.arange(1, v.size + 1)
        with np.errstate(divide="ignore"):
            ax.semilogy(idx, np.where(scaled > 0, scaled, np.nan), "o-", color=color, lw=1.0,
                        ms=4, label=text)
        n = m.order
        if n <= v.size:
            ax.plot([n], [scaled[n - 1]], "o", ms=11, mfc="none", mec=color, mew=1.5)
        ax.axvline(n + 0.5, color=color, ls=":", lw=1.0)
    ax.set_xlabel("index (order)")
    ax.set_ylabel(" / ".join(sorted(kinds)) + "\n(relative to the first)")
    from matplotlib.ticker import MaxNLocator
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, lw=0.3)
    _legend_beside(ax)
    if title:
        ax.set_title(title)
    _layout(fig, np.array([[ax]]), left=1.0, right=room + 0.1, top=0.35 if title else 0.2)
    return fig


@_styled
def order_scores(models, *, labels=None, title=None):
    """The score of every candidate order (and horizon) a model was chosen from.

    For ``selection='cv'`` (the default of the DT batch methods): the
    cross-validated simulation fit % of each candidate order, one line per
    horizon, the chosen candidate ringed; for ``selection='gap'``: the gap
    (log10) after each candidate order. One panel per model; see
    :func:`order_selection` for the singular values / rank profile.

    Parameters
    ----------
    models : StateSpace, list or dict label -> StateSpace
        Models with ``info['order_selection']`` (rule ``'cv'`` or ``'gap'``).
    labels : list of str, optional
        Labels replacing the dict keys (default: the keys or ``model.info['method']``).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    DataError
        No model carries a selection record (their orders were given).
    """
    plt = _pyplot()
    groups = _model_groups(models, labels)
    rows = [(label, m) for label, m in groups.items()
            if isinstance(m.info.get("order_selection"), dict)
            and m.info["order_selection"].get("rule") in ("cv", "gap")]
    if not rows:
        raise DataError("none of the models carries an order selection record "
                        "(info['order_selection'] with rule 'cv' or 'gap'): their order was "
                        "given")
    fig, axes = plt.subplots(len(rows), 1, figsize=(6.5, 2.4 * len(rows) + 0.6),
                             squeeze=False)
    for (label, m), ax in zip(rows, axes[:, 0]):
        record = m.info["order_selection"]
        candidates = record.get("candidates", [])
        if record["rule"] == "cv":
            # one line per horizon (and per estimator of the system matrices, when the
            # cross-validation chose that too: system_matrices='auto')
            groups = sorted({(c["horizon"], c.get("system_matrices") or "")
                             for c in candidates})
            for j, (f, how) in enumerate(groups):
                pts = sorted((c["order"], c["score"]) for c in candidates
                             if (c["horizon"], c.get("system_matrices") or "") == (f, how))
                ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, lw=0.9,
                        color=f"C{j}", label=f"horizon {f}" + (f", {how}" if how else ""))
            chosen = record["selected"]
            ax.plot([chosen["order"]], [chosen["score"]], "o", mfc="none", mec="C3", ms=11,
                    mew=1.5, label=f"chosen: n={chosen['order']}, f={chosen['horizon']}")
            ax.set_ylabel("CV fit %")
            scores = [c["score"] for c in candidates]
            ax.set_ylim(max(min(scores), max(scores) - 60) - 2, min(max(scores) + 5, 102))
        else:
            pts = sorted((c["order"], c["score"]) for c in candidates)
            ax.bar([p[0] for p in pts], [p[1] for p in pts], color="C0", width=0.6)
            ax.bar([m.order], [dict(pts).get(m.order, 0)], color="C3", width=0.6,
                   label=f"chosen: n={m.order}")
            ax.set_ylabel("gap (log10)")
        ax.set_title(f"{label}: " + ("cross-validated simulation fit (estimation data)"
                                     if record["rule"] == "cv" else "largest gap of the profile"))
        ax.legend(loc="lower right")
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.grid(True, lw=0.3)
    axes[-1, 0].set_xlabel("order")
    if title:
        fig.suptitle(title)
    _layout(fig, axes, top=0.45, hgap=0.75, left=0.95)
    return fig
