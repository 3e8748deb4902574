"""The min/max bands of long time traces drawn as images, for the report's figures.

:func:`subid.evaluation.figures._common._draw_trace` draws a trace longer than
``MAX_TRACE_POINTS`` as the band between the minimum and the maximum of each block of
samples (``fill_between``: a polygon of about 2,700 vertices, outlined). Agg rasterises
that polygon and its outline with the general path machinery: a quarter of the time to
draw a report's data overview and a third of its comparison's (bench/report_ratio.md).
:func:`raster_envelopes` replaces each such band, on a finished figure about to be
saved, by an image of the pixels it covers, computed column by column with numpy: in
each pixel column the polygon's upper edge (the maxima, linear between block starts)
and its lower edge (the minima) span a vertical interval each; the fill covers from
the lowest point of the lower edge to the highest of the upper one, the outline (``lw``
wide) each edge's interval widened by half the line width, also to the neighbouring
columns the line's width reaches. Each pixel's coverage is the length of the interval
inside it (anti-aliased vertically, as Agg), and fill and outline are composited as
Agg composites the two (``1 - (1 - a f)(1 - a e)``, ``a`` the band's alpha). The image
is the polygon's up to single pixels at the steep flanks, where Agg's polygon covers
the partial columns a little differently (tests/test_report_envelopes.py compares them).

Only the report's images use this (``report.figure_html``), like ``_ticks.light_ticks``:
the figures :mod:`subid.plot` returns keep the ``fill_between`` band (vector output).
"""

from __future__ import annotations

import numpy as np

from subid.evaluation.figures._light_axes import rectilinear

__all__ = ["raster_envelopes", "tag_envelope"]

#: Name of the attribute that marks a band of ``_draw_trace`` and holds what it draws.
_TAG = "_subid_envelope"


def tag_envelope(artist, start, low, high, *, fill: bool, lw: float) -> None:
    """Mark ``artist`` (``_draw_trace``'s band) with the blocks it draws; a band whose
    times do not increase (experiments of a merged record drawn over each other) is
    left to Agg."""
    if not np.all(np.diff(start) > 0):
        return
    setattr(artist, _TAG, (np.asarray(start, float), np.asarray(low, float),
                           np.asarray(high, float), bool(fill), float(lw)))


def raster_envelopes(fig) -> int:
    """Replace every tagged band of ``fig`` by an image artist drawing the same pixels.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        A finished figure (limits, layout), about to be drawn by Agg.

    Returns
    -------
    int
        The number of bands replaced.
    """
    count = 0
    for ax in fig.axes:
        tagged = [c for c in ax.collections if getattr(c, _TAG, None) is not None
                  and c.get_visible()]
        if not tagged or not rectilinear(ax) or ax.get_xscale() != "linear" \
                or ax.get_yscale() != "linear" or ax.xaxis_inverted() or ax.yaxis_inverted():
            continue                      # drawn by Agg: the columns assume increasing axes
        ax.get_xlim(), ax.get_ylim()       # the limits now, with the bands' data
        for band in tagged:
            ax.add_artist(_envelope_artist(band))
            band.set_visible(False)
            count += 1
    return count


_Envelope = None


def _envelope_artist(band):
    """The artist that draws ``band`` as an image (the class made once, matplotlib
    imported lazily)."""
    global _Envelope
    from matplotlib.colors import to_rgba
    if _Envelope is None:
        from matplotlib.artist import Artist

        class Envelope(Artist):
            """A ``_draw_trace`` band drawn as an image (:func:`_draw`)."""

            def __init__(self, band):
                super().__init__()
                self.band = band
                colors = band.get_edgecolor()
                self.rgba = to_rgba((colors if len(colors) else band.get_facecolor())[0])
                self.set_zorder(band.get_zorder())

            def draw(self, renderer):
                if self.get_visible():
                    _draw(self, renderer)
                self.stale = False

        _Envelope = Envelope
    return _Envelope(band)


def _edge_span(x, v, left: int, n_cols: int):
    """Lowest and highest point, in each pixel column ``[left + c, left + c + 1)``,
    of the polyline through ``(x, v)`` (x increasing); NaN in the columns it does not
    reach and where a segment touches a non-finite vertex (``fill_between``'s gap)."""
    edges = left + np.arange(n_cols + 1, dtype=float)
    with np.errstate(invalid="ignore"):
        at_edges = np.interp(edges, x, v)        # NaN next to a NaN vertex
        low = np.minimum(at_edges[:-1], at_edges[1:])
        high = np.maximum(at_edges[:-1], at_edges[1:])
        column = np.floor(x - left).astype(np.intp)
        inside = (column >= 0) & (column < n_cols)
        np.minimum.at(low, column[inside], v[inside])
        np.maximum.at(high, column[inside], v[inside])
    outside = (edges[1:] <= x[0]) | (edges[:-1] > x[-1])
    low[outside] = high[outside] = np.nan
    return low, high


def _widen(low, high, radius: float):
    """The intervals ``[low, high]`` of each column dilated by a disc of ``radius``
    pixels (a line of width ``2 radius`` along the polyline), over the neighbouring
    columns it reaches."""
    lo, hi = low - radius, high + radius
    for d in range(1, int(np.floor(radius)) + 1):
        reach = np.sqrt(radius * radius - d * d)
        lo[:-d] = np.fmin(lo[:-d], low[d:] - reach)
        hi[:-d] = np.fmax(hi[:-d], high[d:] + reach)
        lo[d:] = np.fmin(lo[d:], low[:-d] - reach)
        hi[d:] = np.fmax(hi[d:], high[:-d] + reach)
    return lo, hi


def _coverage(rows, low, high):
    """Coverage (0..1, float32) of each pixel row (bottom edges ``rows``, a column) by
    the interval ``[low, high]`` of each column (NaN: empty)."""
    # pixel rows far outside the image (a diverging simulation: 1e147) clipped to just
    # beyond it before the float32 cast, which overflowed (numpy's warning reached the
    # command line twice); coverage is the same for any row past the image
    edge = float(rows[0, 0]) - 2.0, float(rows[-1, 0]) + 3.0
    low = np.nan_to_num(np.clip(low, *edge).astype(np.float32), nan=-1.0)
    high = np.nan_to_num(np.clip(high, *edge).astype(np.float32), nan=-2.0)
    cover = np.minimum(high, rows + np.float32(1.0))
    cover -= np.maximum(low, rows)
    return np.clip(cover, 0.0, 1.0, out=cover)


def _draw(artist, renderer) -> None:
    band = artist.band
    start, low, high, fill, lw = getattr(band, _TAG)
    box = artist.axes.bbox
    x0, x1 = int(round(box.x0)), int(round(box.x1))
    y0, y1 = int(round(box.y0)), int(round(box.y1))
    if x1 <= x0 or y1 <= y0 or start.size < 2:
        return
    finite = np.isfinite(low) & np.isfinite(high)
    if not finite.any():
        return
    # in pixels (NaN kept: the transform's matrix would spread it to x as well)
    trans = band.get_transform()
    x, y_low = trans.transform(np.column_stack([start, np.where(finite, low, 0.0)])).T
    y_high = trans.transform(np.column_stack([start, np.where(finite, high, 0.0)]))[:, 1]
    y_low[~finite] = y_high[~finite] = np.nan
    n_cols = x1 - x0
    lo_low, hi_low = _edge_span(x, y_low - y0, x0, n_cols)       # the lower edge
    lo_high, hi_high = _edge_span(x, y_high - y0, x0, n_cols)    # the upper edge
    radius = 0.5 * lw * renderer.points_to_pixels(1.0)
    a_low, b_low = _widen(lo_low, hi_low, radius)
    a_high, b_high = _widen(lo_high, hi_high, radius)
    # the outline: both edges' intervals, merged where they overlap and in the columns
    # of the first and last block, where the polygon's outline closes (low to high)
    with np.errstate(invalid="ignore"):
        merged = b_low >= a_high
    ends = np.floor(x[[0, -1]] - x0).astype(np.intp)
    merged[ends[(ends >= 0) & (ends < n_cols)]] = True
    first = (np.where(merged, np.fmin(a_low, a_high), a_low),
             np.where(merged, np.fmax(b_low, b_high), b_low))
    second = (np.where(merged, np.nan, a_high), np.where(merged, np.nan, b_high))
    # only the rows the band reaches (inside the axes)
    with np.errstate(invalid="ignore"):
        bottom = np.nanmin(np.r_[first[0], second[0], np.inf])
        top = np.nanmax(np.r_[first[1], second[1], -np.inf])
    if not top > max(bottom, 0.0) or not bottom < y1 - y0:     # nothing inside the axes
        return
    bottom, top = max(0, int(np.floor(bottom))), min(y1 - y0, int(np.ceil(top)))
    rows = np.arange(bottom, top, dtype=np.float32)[:, None]  # bottom first, as draw_image
    edge = _coverage(rows, *first)
    edge += _coverage(rows, *second)
    alpha = artist.rgba[3]
    if fill:             # Agg's fill, then its outline over it, both with the band's alpha
        face = _coverage(rows, lo_low, hi_high)
        face *= -alpha
        face += 1.0
        np.minimum(edge, 1.0, out=edge)
        edge *= -alpha
        edge += 1.0
        face *= edge
        value = np.subtract(1.0, face, out=face)
    else:
        value = np.minimum(edge, 1.0, out=edge)
        value *= alpha
    # RGBA bytes as one little-endian 32-bit word per pixel: the colour, alpha on top
    r, g, b = (int(round(255 * c)) for c in artist.rgba[:3])
    np.multiply(value, 255.0, out=value)
    value += 0.5                                             # truncated below: rounded
    word = value.astype(np.uint32)
    word <<= 24
    word |= r | g << 8 | b << 16
    image = word.astype("<u4", copy=False).view(np.uint8).reshape(value.shape + (4,))
    gc = renderer.new_gc()
    gc.set_clip_rectangle(box)
    renderer.draw_image(gc, x0, y0 + bottom, image)
    gc.restore()
