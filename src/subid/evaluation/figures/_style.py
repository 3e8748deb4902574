"""The matplotlib settings every figure of :mod:`subid.plot` is drawn under."""

from __future__ import annotations

__all__ = ["STYLE"]

#: matplotlib settings of every figure: 150 dpi, 10 pt text (9 pt ticks and legends).
#: ``axes.titley`` fixed at the top of the axes: matplotlib otherwise places every
#: title above the tick labels it measures at each draw (the bounding boxes of all the
#: tick labels of the axes: a fifth of the drawing time of a report's figures); no
#: figure here puts tick labels above its axes.
STYLE = {"figure.dpi": 150, "savefig.dpi": "figure", "font.size": 10,
         "axes.titlesize": 10, "axes.labelsize": 10, "xtick.labelsize": 9,
         "ytick.labelsize": 9, "legend.fontsize": 9, "figure.titlesize": 11,
         "axes.titley": 1.0}
