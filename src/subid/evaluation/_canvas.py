"""The Agg canvas of the report's figures, with its text shaped and rasterised once.

Half of the time to draw a report's figure goes to its text (bench/report_figures.md):
for every tick label, title, legend entry, matplotlib's Agg renderer measures the
string, lays it out (FreeType and HarfBuzz) and renders each glyph at its sub-pixel
position, again for every figure (its caches live with one renderer, one figure).
Across the eight figures of a report the same strings (``0.5``, ``10⁻¹``,
``magnitude (dB)``, the channel names) and glyphs recur: about three quarters of the
layouts and two thirds of the glyph images of a 4 x 4 report are repeats.

:func:`canvas` returns a canvas whose renderer keeps, across figures, the width, height
and descent of each string, the layout of each string, and the image of each glyph at
each of the 64 x 64 sub-pixel offsets FreeType positions it at (a translation by whole
pixels moves the outline on the pixel grid without changing its coverage: the cached
image is drawn at the whole-pixel shift), and the line heights of each font and size
(which matplotlib otherwise looks up in the font's tables for every text it lays out).
Each cached value is the one matplotlib's renderer computes for the same key, so the
pixels are the same (tests/test_report_figures.py). Mathematical text, TeX, font
features and languages go to matplotlib's renderer unchanged; without the internals
used here (older matplotlib versions) the canvas is matplotlib's own.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["canvas"]

#: Entries kept in each cache (a report holds a few thousand glyph images of ~100 bytes).
_LIMIT = 20000

_metrics: dict = {}
_layouts: dict = {}
_glyphs: dict = {}
_heights: dict = {}


def _font_heights(prop, dpi):
    """``(ascent, descent, line gap)`` in pixels of the font of ``prop``, as
    ``matplotlib.text.Text._get_layout`` computes them (matplotlib 3.11)."""
    from matplotlib.font_manager import fontManager, get_font
    font = get_font(fontManager._find_fonts_by_props(prop))
    for table_name, gap, ascent, descent in (
            ("OS/2", "sTypoLineGap", "sTypoAscender", "sTypoDescender"),
            ("hhea", "lineGap", "ascent", "descent")):
        table = font.get_sfnt_table(table_name)
        if table is None:
            continue
        scale = 1 / font.get_sfnt_table("head")["unitsPerEm"] \
            * prop.get_size_in_points() * dpi / 72
        return table[ascent] * scale, -table[descent] * scale, table[gap] * scale
    return None, None, None


def _limited(cache: dict) -> dict:
    if len(cache) >= _LIMIT:
        cache.clear()
    return cache


def canvas(fig):
    """A ``FigureCanvasAgg`` of ``fig`` that draws text through the caches (module doc)."""
    from matplotlib.backends import backend_agg
    global _Canvas
    if _Canvas is None:
        _Canvas = _make_classes(backend_agg)
    return _Canvas(fig)


_Canvas = None


def _make_classes(agg):
    import matplotlib as mpl
    from matplotlib.font_manager import fontManager
    from matplotlib.ft2font import FT2Font
    fast = (hasattr(agg, "RenderMode") and hasattr(agg, "get_hinting_flag")
            and hasattr(agg.RendererAgg, "_draw_text_glyphs_and_boxes")
            and hasattr(fontManager, "_find_fonts_by_props")
            and all(hasattr(FT2Font, name) for name in ("_layout", "_render_glyph",
                                                         "_set_transform")))

    class Renderer(agg.RendererAgg):
        def get_text_width_height_descent(self, s, prop, ismath):
            if ismath:
                return super().get_text_width_height_descent(s, prop, ismath)
            key = (s, hash(prop), self.dpi, agg.get_hinting_flag(),
                   mpl.rcParams["text.hinting_factor"])
            value = _metrics.get(key)
            if value is None:
                value = super().get_text_width_height_descent(s, prop, ismath)
                _limited(_metrics)[key] = value
            return value

        def _get_font_height_metrics(self, prop):
            """The ascent, descent and line gap of ``prop``'s font (what
            ``Text._get_layout`` reads from the font's OS/2 or hhea table for every
            text at every draw: a font lookup and two table reads), once per font and
            size (None when the font has neither table: matplotlib then measures)."""
            key = (hash(prop), self.dpi)
            value = _heights.get(key)
            if value is None:
                value = _font_heights(prop, self.dpi)
                _limited(_heights)[key] = value
            return value

        def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
            features = mtext.get_fontfeatures() if mtext is not None else None
            language = mtext.get_language() if mtext is not None else None
            if ismath or features is not None or language is not None:
                return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            flags = agg.get_hinting_flag()
            key = (s, hash(prop), self.dpi, flags, mpl.rcParams["text.hinting_factor"])
            items = _layouts.get(key)
            if items is None:       # what RendererAgg.draw_text lays out
                font = self._prepare_font(prop)
                items = [(item.ft_object, item.glyph_index, item.x, item.y)
                         for item in font._layout(s, flags=flags)]
                _limited(_layouts)[key] = items
            self._glyphs(gc, x, y, angle, prop.get_size_in_points(), items, flags)

        def _glyphs(self, gc, x, y, angle, size, items, flags):
            """RendererAgg._draw_text_glyphs_and_boxes of a string without boxes, each
            glyph image rendered once per font, size, angle and sub-pixel offset."""
            cos, sin = math.cos(math.radians(angle)), math.sin(math.radians(angle))
            antialiased = gc.get_antialiased()
            matrix = None
            for font, glyph, dx, dy in items:        # dy is upwards, y downwards
                tx = round(0x40 * (x + dx * cos - dy * sin))
                ty = round(0x40 * (self.height - y + dx * sin + dy * cos))
                key = (font, size, self.dpi, glyph, angle, tx % 64, ty % 64, flags,
                       antialiased)
                entry = _glyphs.get(key)
                if entry is None:
                    if matrix is None:
                        matrix = (0x10000 * np.array([[cos, -sin], [sin, cos]])
                                  ).round().astype(int)
                    font.set_size(size, self.dpi)
                    font._set_transform(matrix, [tx % 64, ty % 64])
                    bitmap = font._render_glyph(
                        glyph, flags,
                        agg.RenderMode.NORMAL if antialiased else agg.RenderMode.MONO)
                    image = np.array(bitmap.buffer)
                    if not antialiased:
                        image *= 0xff
                    entry = (image, bitmap.left, bitmap.top)
                    _limited(_glyphs)[key] = entry
                image, left, top = entry
                # a translation by whole pixels (tx // 64) shifts the image by as many
                self._renderer.draw_text_image(
                    image, left + tx // 64,
                    int(self.height) - (top + ty // 64) + image.shape[0], 0, gc)

    if not fast:                # matplotlib's canvas and renderer, as they are
        return agg.FigureCanvasAgg

    class Canvas(agg.FigureCanvasAgg):
        def get_renderer(self):
            w, h = self.get_width_height(physical=True)
            key = w, h, self.figure.dpi
            if self._lastKey != key:
                self.renderer = Renderer(w, h, self.figure.dpi)
                self._lastKey = key
            return self.renderer

    return Canvas
