"""Axes whose minor ticks are made when first used, not when the axes is made.

Making an Axes costs matplotlib about 5 to 6 ms, and a quarter of that goes to ticks
nobody asked for yet: ``Axes.clear`` turns the grid off and on again and clips the
axes to their patch, and those steps make the first major and the first minor
``Tick`` of both axes (five artists each) and apply the settings to them, one step
at a time. Yet matplotlib keeps every tick setting in ``Axis._major_tick_kw`` and
``_minor_tick_kw`` precisely so that ticks made later are made with them; and the
minor ticks of a linear axis are never drawn (its minor locator places none), nor
are a report's (:mod:`._ticks` replaces the ticks before drawing).

:class:`LazyTickAxes` is an Axes whose x and y axes apply tick settings and the clip
path to the ticks already made and record them for the others, which get them when
they are made (on first access of ``axis.majorTicks`` or ``minorTicks``, as in
matplotlib). A tick also reads the rcParams when it is made (label size, tick
length...): :func:`finish` makes the major ticks at the end of a figure's build,
under the style it was built with (:data:`._common.STYLE`), and records that style
for the minor ticks made later. So the ticks carry the settings matplotlib's would
and a figure draws to the same pixels (tests/test_report_figures.py); one
difference remains, a tick list that a later ``tick_params(reset=True)`` or
``Axis.clear()`` empties is made again with the build's rcParams rather than the
ones in force at that call. Without the matplotlib internals this relies on
(``Axis._get_tick``, ``Axes._init_axis``, the spines' ``register_axis``, the lazy
tick lists: :data:`SUPPORTED`), it is matplotlib's own Axes. The classes are
module-level, so the figures pickle as matplotlib's do.
"""

from __future__ import annotations

import inspect

import matplotlib as mpl
import matplotlib.axis as maxis
from matplotlib.axes import Axes
from matplotlib.spines import Spine

__all__ = ["LazyTickAxes", "SUPPORTED", "finish"]

_TICK_LISTS = ("majorTicks", "minorTicks")

#: Whether this matplotlib has the internals the lazy axes rely on (3.8 and later).
_LAZY_LIST = getattr(maxis, "_LazyTickList", None)
SUPPORTED = (_LAZY_LIST is not None and hasattr(maxis.Axis, "_get_tick")
             and hasattr(Axes, "_init_axis") and hasattr(Spine, "register_axis")
             and "clear" in inspect.signature(maxis.Axis.__init__).parameters
             and all(isinstance(maxis.Axis.__dict__.get(name), _LAZY_LIST)
                     for name in _TICK_LISTS))


class _LazyTicks:
    """What the lazy x and y axes add to matplotlib's (module doc)."""

    _tick_clip = None

    def _unmade(self):
        """Stand-in empty lists for the tick lists not made yet: matplotlib's methods
        then apply their settings to the ticks that exist."""
        unmade = [name for name in _TICK_LISTS if name not in self.__dict__]
        for name in unmade:
            self.__dict__[name] = []
        return unmade

    def _restore(self, unmade):
        for name in unmade:              # lazy again unless a tick was made meanwhile
            if self.__dict__.get(name) == []:
                del self.__dict__[name]

    def set_tick_params(self, which="major", reset=False, **kwargs):
        # the settings go to _major/_minor_tick_kw (the ticks made later are made
        # with them) and to the ticks already made
        unmade = self._unmade()
        try:
            return super().set_tick_params(which, reset, **kwargs)
        finally:
            self._restore(unmade)

    def set_clip_path(self, path, transform=None):
        unmade = self._unmade()
        try:
            super().set_clip_path(path, transform)
        finally:
            self._restore(unmade)
        self._tick_clip = (path, transform)

    def _get_tick(self, major):
        style = getattr(self.axes, "_tick_style", None)
        # the first tick of a list under the rcParams of the figure's build (finish),
        # as matplotlib would have made it; the others copy its properties at draw
        # time (Axis.get_major_ticks), whatever the rcParams then
        if style is None or self.__dict__.get("majorTicks" if major else "minorTicks"):
            tick = super()._get_tick(major)
        else:
            with mpl.rc_context(style):
                tick = super()._get_tick(major)
        if self._tick_clip is not None:
            tick.set_clip_path(*self._tick_clip)
        return tick


class LazyTickXAxis(_LazyTicks, maxis.XAxis):
    """matplotlib's XAxis with ticks made when first used."""


class LazyTickYAxis(_LazyTicks, maxis.YAxis):
    """matplotlib's YAxis with ticks made when first used."""


class LazyTickAxes(Axes):
    """matplotlib's Axes with ticks made when first used (module doc)."""

    #: The rcParams of the figure's build, for the ticks made after it (:func:`finish`).
    _tick_style: dict | None = None

    def _init_axis(self):
        if not SUPPORTED:
            return super()._init_axis()
        # Axes._init_axis with the lazy axes (matplotlib 3.8 to 3.11)
        self.xaxis = LazyTickXAxis(self, clear=False)
        self.spines.bottom.register_axis(self.xaxis)
        self.spines.top.register_axis(self.xaxis)
        self.yaxis = LazyTickYAxis(self, clear=False)
        self.spines.left.register_axis(self.yaxis)
        self.spines.right.register_axis(self.yaxis)


def finish(fig) -> None:
    """End the build of ``fig`` (called under the rcParams it was built with): make
    the first major tick of every lazy axis, and record the rcParams for the minor
    ticks made later (module doc)."""
    style = None
    for ax in getattr(fig, "axes", ()):
        if isinstance(ax, LazyTickAxes) and SUPPORTED:
            if style is None:
                style = dict(mpl.rcParams.copy())
                style.pop("backend", None)     # never switched by a tick
            ax.xaxis.majorTicks, ax.yaxis.majorTicks   # noqa: B018 - made on access
            ax._tick_style = style
