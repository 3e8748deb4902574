"""Ticks, tick labels and grid lines of a finished figure drawn as a few artists per axis.

matplotlib draws every tick as a ``Tick``: five artists (two marks, a grid line, two
labels) created, copied from the first tick and laid out at each draw. On the panel
grids of a report (30 Bode panels of a 5-input, 3-output record) that is most of the
drawing time (bench/demo_profile.md): the axes, their ticks and their text, not the
data. :func:`light_ticks` replaces them, on a figure about to be saved, by what they
draw: per axis one line of tick marks (markers), one collection of grid lines and
one text per tick label, at the positions and labels the axis' own locator and
formatter give for its final limits, styled as its first tick, and moves the axis
label as far from the spine as the tick labels reach (what matplotlib does at each
draw). The image is the same up to the anti-aliasing of single pixels.

The offset or scale factor of the formatter (``1e6`` under the time axis of a record
of a million samples, ``1e-5`` beside an output in SI units) is one more text, where
matplotlib puts it (below the tick labels at the right end of an x axis, above the top
of a y axis; ``Axis._update_offset_text_position``) and styled as the axis' own. An
axis whose ticks this does not reproduce keeps matplotlib's, and so do the axes that
share its locator: hidden axes, axes that are not rectilinear or place themselves at
draw time (an axes locator; a fixed aspect ratio is applied first, as the draw will),
ticks, labels or the axis label on the second side (top, right), labelled minor
ticks. Only the report's images use this (``report.figure_html``): the
figures :mod:`subid.plot` returns keep matplotlib's ticks.
"""

from __future__ import annotations

import numpy as np

__all__ = ["light_ticks"]


def light_ticks(fig, renderer) -> int:
    """Replace the tick machinery of every axis of ``fig`` that allows it (module doc).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        A finished figure (limits, labels, layout): called just before it is saved.
    renderer : matplotlib.backend_bases.RendererBase
        The renderer it will be drawn with (tick-label extents).

    Returns
    -------
    int
        The number of axes (x or y) replaced.
    """
    from subid.evaluation.figures._light_axes import rectilinear as is_rectilinear
    plans, kept = [], set()
    for ax in fig.axes:
        fixed = ax.get_aspect() != "auto" and ax.get_axes_locator() is None
        rectilinear = is_rectilinear(ax)
        if fixed and rectilinear and ax.get_visible():
            # the box (or the limits) a fixed aspect ratio gives at draw time, now: the
            # draw applies it again to the same effect, and the ticks are those of the
            # final limits and length
            ax.apply_aspect()
        for axis in (ax.xaxis, ax.yaxis):
            plan = None
            if rectilinear and (ax.get_aspect() == "auto" or fixed) \
                    and ax.get_visible() and axis.get_visible():
                plan = _plan(ax, axis)
            if plan is None:
                kept.add(id(axis.major))
            else:
                plans.append(plan)
    # shared axes share their locators (``axis.major``): replaced only when every axis
    # sharing them is, and after every plan is made
    plans = [p for p in plans if id(p[1].major) not in kept]
    from matplotlib.ticker import NullLocator
    for ax, axis, artists in plans:
        axis.set_major_locator(NullLocator())
        axis.set_minor_locator(NullLocator())
        # no ticks left to draw, none to make: the draw asks for none
        axis.majorTicks, axis.minorTicks = [], []
        for artist in artists:
            if artist.get_label() == "_light_grid":         # clipped to the axes
                ax.add_artist(artist)
            else:       # outside the axes: on the figure, without a clip path to set up
                fig.add_artist(artist, clip=False)
    for ax, axis, artists in plans:
        labels = [a for a in artists if a.get_label() == "_light_label"]
        offsets = [a for a in artists if a.get_label() == "_light_offset"]
        if offsets:
            _place_offset(ax, axis, offsets[0], labels, renderer, fig.dpi)
        _move_label(ax, axis, labels, renderer, fig.dpi)
    return len(plans)


def _place_offset(ax, axis, text, labels, renderer, dpi) -> None:
    """Put the formatter's offset text where ``Axis.draw`` puts the axis' own (which is
    hidden): below the tick labels (the axes' bottom without any) for an x axis, above
    the axes for a y axis, ``OFFSETTEXTPAD`` points away."""
    pad = axis.OFFSETTEXTPAD * dpi / 72.0
    x = axis.offsetText.get_position()[0]
    if axis.axis_name == "x":
        boxes = [t.get_window_extent(renderer) for t in labels]
        bottom = min(b.y0 for b in boxes) if boxes else ax.bbox.ymin
        text.set_position((x, bottom - pad))
    else:
        text.set_position((x, ax.bbox.ymax + pad))
    axis.offsetText.set_visible(False)


def _in_view(axis, locs):
    """Which ``locs`` lie inside the axis' view interval (those ``Axis._update_ticks``
    draws), as a boolean mask."""
    low, high = sorted(axis.get_view_interval())
    transform = axis.get_transform()
    lo_t, hi_t = transform.transform([low, high])
    with np.errstate(all="ignore"):
        values = transform.transform(np.asarray(locs, dtype=float))
    tol = 1e-10 * abs(hi_t - lo_t)
    return np.isfinite(values) & (values >= lo_t - tol) & (values <= hi_t + tol)


def _plan(ax, axis):
    """``(ax, axis, artists)`` drawing the axis' ticks, or None to keep matplotlib's."""
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.text import Text
    from matplotlib.ticker import NullLocator

    from subid.evaluation.figures._light_axes import tick_style
    x = axis.axis_name == "x"
    if axis.get_label_position() != ("bottom" if x else "left"):
        return None
    zorder = axis.get_zorder()
    artists = []
    groups = [(axis.major.formatter, tick_style(ax, axis, True), True)]
    if not isinstance(axis.get_minor_locator(), NullLocator):
        groups.append((axis.minor.formatter, tick_style(ax, axis, False), False))
    for formatter, tick, is_major in groups:
        if tick["tick2"] or tick["label2"]:
            return None
        locs = np.asarray(axis.get_majorticklocs() if is_major else axis.get_minorticklocs(),
                          dtype=float)
        labels = formatter.format_ticks(locs) if len(locs) else []
        offset = formatter.get_offset() \
            if callable(getattr(formatter, "get_offset", None)) else ""
        if offset and not is_major:
            return None
        if offset and axis.offsetText.get_visible():
            # the offset text (matplotlib's, hidden), placed by light_ticks
            source = axis.offsetText
            artists.append(Text(
                0.0, 0.0, offset, fontproperties=source.get_fontproperties(),
                color=source.get_color(), horizontalalignment=source.get_ha(),
                verticalalignment=source.get_va(), transform=source.get_transform(),
                zorder=source.get_zorder(), label="_light_offset"))
        keep = _in_view(axis, locs) if len(locs) else np.zeros(0, bool)
        locs, labels = locs[keep], [s for s, k in zip(labels, keep) if k]
        if not is_major and tick["label"] and any(labels):
            return None
        if not len(locs):
            continue
        zeros = np.zeros(locs.size)
        frame = ax.get_xaxis_transform() if x else ax.get_yaxis_transform()
        points = (locs, zeros) if x else (zeros, locs)
        if tick["grid"]:
            ends = ([[(v, 0.0), (v, 1.0)] for v in locs] if x else
                    [[(0.0, v), (1.0, v)] for v in locs])
            artists.append(LineCollection(
                ends, colors=[tick["grid_color"]], linewidths=tick["grid_linewidth"],
                linestyles=tick["grid_linestyle"], alpha=tick["grid_alpha"], transform=frame,
                zorder=zorder, label="_light_grid"))
        if tick["mark"]:
            artists.append(Line2D(
                *points, linestyle="None", marker=tick["marker"],
                markersize=tick["markersize"], markeredgewidth=tick["markeredgewidth"],
                color=tick["color"], markeredgecolor=tick["markeredgecolor"],
                transform=frame, zorder=zorder, label="_light_mark"))
        if tick["label"]:
            # where the tick puts its label: the axes' text transform at the tick's pad
            place = (ax.get_xaxis_text1_transform if x else ax.get_yaxis_text1_transform)
            transform = place(tick["pad"])[0]
            for px, py, s in zip(*points, labels):
                if s:
                    artists.append(Text(
                        px, py, s, fontproperties=tick["font"], color=tick["label_color"],
                        rotation=tick["rotation"], horizontalalignment=tick["ha"],
                        verticalalignment=tick["va"], transform=transform, zorder=zorder,
                        label="_light_label"))
    return ax, axis, artists


def _move_label(ax, axis, texts, renderer, dpi) -> None:
    """Place the axis label beyond the tick labels, as matplotlib's own layout does."""
    if not texts or not axis.label.get_text() or not axis.label.get_visible():
        return
    boxes = [t.get_window_extent(renderer) for t in texts]
    if axis.axis_name == "x":
        edge = ax.spines["bottom"].get_window_extent(renderer).y0 if "bottom" in ax.spines \
            else ax.get_window_extent(renderer).y0
        reach = edge - min(b.y0 for b in boxes)
    else:
        edge = ax.spines["left"].get_window_extent(renderer).x0 if "left" in ax.spines \
            else ax.get_window_extent(renderer).x0
        reach = edge - min(b.x0 for b in boxes)
    if reach > 0:
        axis.labelpad += reach * 72.0 / dpi
