"""What the figures of :mod:`subid.evaluation.plot` share: the style and the colour of
each method, legends beside the axes, matplotlib's lazy import, the arguments every plot
takes (models with labels, a record), and the simulated outputs they draw."""

from __future__ import annotations

import contextlib
import logging

import numpy as np

from subid.errors import DataError, ModelError

log = logging.getLogger("subid.evaluation.plot")

# Standard normal quantile for a two-sided 99 % band (scipy.special.ndtri(0.995)).
_Z99 = 2.5758293035489004

#: matplotlib settings of every figure: 150 dpi, 10 pt text (9 pt ticks and legends).
#: ``axes.titley`` fixed at the top of the axes: matplotlib otherwise places every
#: title above the tick labels it measures at each draw (the bounding boxes of all the
#: tick labels of the axes: a fifth of the drawing time of a report's figures); no
#: figure here puts tick labels above its axes.
STYLE = {"figure.dpi": 150, "savefig.dpi": "figure", "font.size": 10,
         "axes.titlesize": 10, "axes.labelsize": 10, "xtick.labelsize": 9,
         "ytick.labelsize": 9, "legend.fontsize": 9, "figure.titlesize": 11,
         "axes.titley": 1.0}

#: Colour of each method (``model.info['method']``) in every figure; a second model
#: of the same method in one figure takes the next free colour.
METHOD_COLORS = {"ls_subspace": "C0", "moesp": "C1", "n4sid": "C2", "ct_subspace": "C3",
                 "ct_subspace_paper": "C4", "RecursiveSubspace": "C5",
                 "seed000_adaptive": "C6", "dt_to_ct": "C7", "true": "k"}
_PALETTE = [f"C{k}" for k in range(10)]
# Width of one legend character at 9 pt, inches (for the room beside the axes).
_LEGEND_CHAR_IN = 0.068


def frequency_unit(dts, hz: bool = False) -> str:
    """The unit of the frequencies of models or records of sampling periods ``dts``.

    ``dt = 1`` is the period of a record without time information (IOData's default):
    when every period is 1, time is counted in samples and frequencies per sample (the
    same numbers as per second with dt = 1 s). The Bode axis, the report's caption of
    it and the pole table all name the unit from here.

    Parameters
    ----------
    dts : iterable of float
        Sampling periods (0: continuous time).
    hz : bool
        Cycles instead of radians.

    Returns
    -------
    str
        ``'rad/sample'`` or ``'cycles/sample'`` when every period is 1, else ``'rad/s'``
        or ``'Hz'``.

    Examples
    --------
    >>> frequency_unit([1.0], hz=True), frequency_unit([1.0, 0.1])
    ('cycles/sample', 'rad/s')
    """
    dts = list(dts)
    if dts and all(dt == 1.0 for dt in dts):
        return "cycles/sample" if hz else "rad/sample"
    return "Hz" if hz else "rad/s"


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


@contextlib.contextmanager
def _autoscale_once(axes):
    """Autoscale ``axes`` (an array of Axes) once, after the plotting calls of the block.

    Each ``plot``, ``fill_between``, ``vlines``... asks for an autoscale, and the next
    call that adds a collection or reads a limit carries it out, over every axes that
    shares the axis: on the shared frequency axis of a Bode grid, each band recomputed
    the limits of all the panels (a quarter of the time to build a 4 x 4 diagram).
    Within the block autoscaling is off (the data limits still grow with every
    artist); at its end it is switched back on and requested once, lazily. The
    limits are those of the last autoscale either way: computed from the final data
    limits, which do not depend on when they were computed.
    """
    flat = list(np.ravel(axes))
    before = [(ax.get_autoscalex_on(), ax.get_autoscaley_on()) for ax in flat]
    for ax in flat:
        ax.set_autoscale_on(False)
    try:
        yield
    finally:
        for ax, (x_on, y_on) in zip(flat, before):
            if x_on:
                ax.autoscale(axis="x")
            if y_on:
                ax.autoscale(axis="y")


def _method_of(model) -> str | None:
    info = getattr(model, "info", None)
    method = info.get("method") if isinstance(info, dict) else None
    return str(method) if method else None


def colors_for(entries) -> list[str]:
    """One distinct colour per entry: the method's colour (:data:`METHOD_COLORS`)
    when free, else the first unused one. ``entries``: (label, model or None)."""
    from subid.errors import OptionError
    try:
        entries = [tuple(entry) for entry in entries]
    except TypeError:
        raise OptionError(f"colors_for takes (label, model) pairs, e.g. "
                          f"colors_for(models.items()); got {type(entries).__name__}") from None
    if any(len(entry) != 2 for entry in entries):
        raise OptionError("colors_for takes (label, model) pairs (model None for a label "
                          "without one), e.g. colors_for(models.items())")
    used: set[str] = set()
    out: list[str] = []
    for label, model in entries:
        method = _method_of(model) if model is not None else None
        want = (METHOD_COLORS.get(method) if method else None) or METHOD_COLORS.get(str(label))
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
    from subid.model.statespace import StateSpace
    if not isinstance(model, StateSpace):
        raise ModelError(f"is_unstable needs a subid.StateSpace, got {type(model).__name__}")
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



def _model_groups(models, labels=None) -> dict:
    """``{label: StateSpace}`` from one model, a list or a dict; ``labels``, when
    given, one distinct label per model (a :class:`ModelError` otherwise: a label short
    or repeated dropped models from the figure, silently)."""
    from subid.model.statespace import StateSpace
    if isinstance(models, StateSpace):
        items = [models]
    elif isinstance(models, dict):
        items = list(models.values())
    else:
        try:
            items = list(models)
        except TypeError:
            raise ModelError(f"expected a StateSpace, a list or a dict of them, got "
                             f"{type(models).__name__}") from None
    if isinstance(models, str):
        raise ModelError(f"expected a StateSpace, a list or a dict of them, got the string "
                         f"{models!r}"[:300] + ": load a model file with subid.load first")
    for k, m in enumerate(items):
        if not isinstance(m, StateSpace):
            raise ModelError(f"model {k + 1} is a {type(m).__name__}, not a subid.StateSpace"
                             + (" (load a model file with subid.load)"
                                if isinstance(m, str) else ""))
    if labels is not None:
        labels = [str(v) for v in ([labels] if isinstance(labels, str) else labels)]
        if len(labels) != len(items):
            raise ModelError(f"{len(labels)} label(s) for {len(items)} model(s): give one "
                             "label per model (or none)")
        if len(set(labels)) != len(labels):
            repeated = sorted({v for v in labels if labels.count(v) > 1})
            raise ModelError(f"the labels repeat {repeated}: give every model its own label")
    if isinstance(models, StateSpace):
        out = {labels[0] if labels else _default_label(models, 0): models}
    elif isinstance(models, dict):
        out = dict(models) if labels is None else dict(zip(labels, items))
    else:
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
    from subid.data import IOData, not_a_record
    if not isinstance(data, IOData):
        raise not_a_record(data, "data", time="t=... or dt=...")
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
    # at most 5 intervals on an x axis narrower than 4 inches (matplotlib's default fits
    # one per 27 points: 9 ticks, each a Tick of five artists created and drawn, on
    # every panel of a grid); an integer or fixed locator is kept
    x_bins = 5 if ax_w < 4.0 else 8
    for ax in axes.ravel():
        if ax.get_yscale() == "linear":
            ax.yaxis.set_major_locator(MaxNLocator(nbins=4 if ax_h < 1.6 else 6))
        locator = ax.xaxis.get_major_locator()
        if ax.get_xscale() == "linear" and isinstance(locator, MaxNLocator):
            locator.set_params(nbins=x_bins)


def simulated_output(model, data, x0="estimate"):
    """``(y_hat, fit %)`` of ``model`` on ``data``; NaN where the simulation diverges.

    The same simulation as :func:`subid.fit_percent` (least-squares initial
    state by default), but a model whose simulation overflows gives NaN
    instead of an exception, so that it can still be listed and drawn.
    """
    from subid.model.prediction import simulate_fit
    with np.errstate(all="ignore"):
        try:
            y_hat, _ = simulate_fit(model, data, x0=x0)
        except ModelError:                 # the simulation of an unstable model overflows
            y_hat = np.full(data.y.shape, np.nan)
        y_hat = np.where(np.isfinite(y_hat), y_hat, np.nan)
    return y_hat, percent_fit(data, y_hat)


def percent_fit(data, y_hat) -> np.ndarray:
    """Fit % per output of outputs ``y_hat`` computed on ``data``: the value of
    :func:`subid.fit_percent` (:func:`subid.model.fit.output_fit`, each experiment of a
    merged record against its own mean), NaN where ``y_hat`` is not finite or the output
    is constant (a figure's legend, never an error)."""
    from subid.model.fit import output_fit
    y_hat = np.asarray(y_hat, dtype=float)
    finite = np.isfinite(y_hat).all(axis=0)
    if not finite.all():
        y_hat = np.where(finite, y_hat, 0.0)
    with np.errstate(all="ignore"):
        fits = np.asarray(output_fit(data, y_hat, constant="nan"), dtype=float)
    fits[~finite] = np.nan
    return fits


def predicted_output(model, data, steps, x0="estimate"):
    """``(y_hat, fit %)`` of the ``steps``-ahead prediction from ``x0`` (as in
    :func:`subid.predict`); NaN where it diverges. A malformed ``x0`` raises."""
    from subid.model.prediction import _check_steps, check_model_data, check_x0, predict
    check_model_data(model, data)
    x0 = check_x0(x0, model.order, data.n_experiments)
    steps = _check_steps(steps)                     # as predict: refused, not all NaN
    try:
        y_hat = predict(model, data, steps, x0)
    except DataError:
        y_hat = np.full(data.y.shape, np.nan)
    return y_hat, percent_fit(data, y_hat)


#: Most points a time trace is drawn with. A longer trace is drawn as the band between
#: the minimum and the maximum of each of ``MAX_TRACE_POINTS // 2`` consecutive blocks of
#: samples: the envelope that a line a thousand pixels wide shows anyway. 1350
#: blocks: one per pixel column of a 9-inch figure at 150 dpi, at least one per column
#: of the narrower axes of the time plots (more only add edges to rasterise: with 2,000
#: blocks the bands of a 10^6-sample report took 1.3 to 1.6 times as long to draw), so a
#: record of 10^6 samples draws as fast as one of 2,700 and looks the same. The data are
#: never changed.
MAX_TRACE_POINTS = 2700


def _min_max_blocks(t: np.ndarray, values: np.ndarray, max_points: int = MAX_TRACE_POINTS):
    """``(start, low, high)``: the start time, minimum and maximum of each of
    ``max_points // 2`` consecutive blocks of ``values`` (the last one may be shorter),
    what :func:`_draw_trace` draws of a long trace. A block with a NaN gives NaN (the
    band breaks where the data are not finite)."""
    n = values.shape[0]
    size = -(-n // (max_points // 2))
    full = n // size
    grid = values[:full * size].reshape(full, size)     # a view of a column, not a copy
    with np.errstate(invalid="ignore"):
        low, high = grid.min(axis=1), grid.max(axis=1)
        if full * size < n:
            rest = values[full * size:]
            low, high = np.append(low, rest.min()), np.append(high, rest.max())
    return t[::size], low, high


class _UniformTimes:
    """The time stamps ``t0 + dt k`` (k = 0..n-1) of a long uniformly sampled record,
    computed only where indexed: ``times[::size]`` (the block starts of
    :func:`_min_max_blocks`), ``times[0]``, ``times[-1]``. Each value is the one of
    ``data.t`` (the same floating-point operations), without building the ``n``
    stamps a min/max band never draws (10 ms for 10^6 samples)."""

    def __init__(self, t0: float, dt: float, n: int):
        self.t0, self.dt, self.size = t0, dt, n
        self.shape = (n,)

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, key):
        if isinstance(key, slice):
            return self.t0 + self.dt * np.arange(*key.indices(self.size))
        k = int(key)
        k = k + self.size if k < 0 else k
        if not 0 <= k < self.size:
            raise IndexError(f"index {key} out of range for {self.size} time stamps")
        return float(self.t0 + self.dt * np.float64(k))

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self[:], dtype=dtype)


def _times(data):
    """``data.t``, or for a long uniform record of one experiment without time stamps
    the :class:`_UniformTimes` of the same values (what the time plots index)."""
    if data.n_samples > MAX_TRACE_POINTS and data.dt is not None \
            and not data.has_time_stamps and data.n_experiments == 1:
        return _UniformTimes(float(data[:1].t[0]), float(data.dt), data.n_samples)
    return data.t


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _decade_label(value, _position=None) -> str:
    """Tick label of a log axis in plain text (``10⁻²``; other values as ``%g``):
    matplotlib's default labels are mathtext, parsed by pyparsing at every new label
    (a third of the drawing time of the order-selection chart)."""
    if not value > 0 or not np.isfinite(value):
        return ""
    exponent = np.log10(value)
    if abs(exponent - round(exponent)) < 1e-9:
        return "10" + str(int(round(exponent))).translate(_SUPERSCRIPT)
    return f"{value:g}"


def _plain_log_labels(axis) -> None:
    """Label the decades of a log ``axis`` (an XAxis or YAxis) in plain text."""
    from matplotlib.ticker import FuncFormatter
    axis.set_major_formatter(FuncFormatter(_decade_label))


def _draw_trace(ax, t, values, *, color, lw, fill=True, **style):
    """Draw a time trace on ``ax``: its samples as a line, or, beyond
    :data:`MAX_TRACE_POINTS`, the band between the minimum and the maximum of each
    block of :func:`_min_max_blocks` (filled, or only outlined with ``fill=False``),
    its outline ``lw`` wide so that a quiet stretch still shows as a line.

    The band draws what the zig-zag line through the same points covers, an order
    of magnitude faster (a filled polygon instead of thousands of strokes across
    the signal's range); it is rasterised in vector output. A block with a
    non-finite value leaves a gap. Returns the artist."""
    if values.shape[0] <= MAX_TRACE_POINTS:
        return ax.plot(t, values, color=color, lw=lw, **style)[0]
    start, low, high = _min_max_blocks(t, values)
    band = ax.fill_between(start, low, high, facecolor=color if fill else "none",
                           edgecolor=color, lw=lw, rasterized=True, **style)
    # what the report draws as an image instead of the polygon (figures/_raster.py)
    from subid.evaluation.figures._raster import tag_envelope
    tag_envelope(band, start, low, high, fill=fill, lw=lw)
    return band


def _envelope_note(n_samples: int, max_points: int = MAX_TRACE_POINTS) -> str | None:
    """What a figure says under traces of ``n_samples`` drawn by :func:`_draw_trace`
    (None when they are drawn sample by sample)."""
    if n_samples <= max_points:
        return None
    size = -(-n_samples // (max_points // 2))
    return (f"{n_samples:,} samples per trace: band between the minimum and the maximum "
            f"of every {size:,} (peaks kept)")


def _note_envelope(fig, n_samples: int) -> None:
    """Write :func:`_envelope_note` in the bottom right corner of ``fig``."""
    note = _envelope_note(n_samples)
    if note is not None:
        fig.text(0.995, 0.005, note, ha="right", va="bottom", fontsize=7, color="0.35")


def _finite(values: np.ndarray) -> np.ndarray:
    """``values`` with non-finite entries replaced by NaN (not drawn): the array itself
    when every entry is finite (drawn, never written)."""
    values = np.asarray(values, dtype=float)
    if np.isfinite(values).all():
        return values
    out = values.copy()
    out[~np.isfinite(out)] = np.nan
    return out
