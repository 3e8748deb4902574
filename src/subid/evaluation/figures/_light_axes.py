"""Axes whose tick objects are made only when something draws or reads them.

matplotlib's ``Axis`` keeps its ticks in lazy lists, but a new Axes fills them at once:
``Axis.reset_ticks`` sets the clip path of every tick and ``Axes.clear`` sets the grid
and the tick sides through ``Axis.set_tick_params``, and both walk the lists. So every
axis of every Axes makes a major and a minor ``Tick`` (two marks, a grid line and two
labels each) while it is built: 108 ticks for the 27 axes of a report of a 2-input,
2-output record, a fifth of the report's time (``bench/report_ratio.md``), for ticks
that :func:`subid.evaluation.figures._ticks.light_ticks` then replaces by a few artists
per axis.

The axes of :data:`PROJECTION` (the report's figures, :func:`report_axes`) keep the
lists lazy through those two calls: the parameters are stored as matplotlib stores
them for the ticks it makes later (``Axis._major_tick_kw``), and no tick exists until
one is asked for. ``light_ticks`` then reads the style of the first tick from a tick
made once per style (:func:`tick_style`: the axis' parameters and the matplotlib
settings of its figure's build, :data:`_TICK_SETTINGS`) and leaves the replaced axes
with empty tick lists; an axis it keeps makes its ticks when drawn, under the settings
its figure was built with and clipped to the axes as matplotlib's own. The images are
those of matplotlib's Axes, byte for byte (tests/test_report_light_axes.py compares
every image of reports built both ways).
"""

from __future__ import annotations

import contextlib
import contextvars

__all__ = ["PROJECTION", "rectilinear", "report_axes", "subplot_kw", "tick_style"]

#: The name the axes class is registered under (``projection=`` of ``add_subplot``).
PROJECTION = "subid-light"

_ACTIVE = contextvars.ContextVar("subid_light_axes", default=False)
#: The matplotlib settings a tick is made from (sizes, colours, pads, directions and
#: label fonts of ``xtick.*``/``ytick.*``, grid lines, fonts, lines and text).
_TICK_SETTINGS = ("xtick.", "ytick.", "grid.", "font.", "lines.", "text.", "mathtext.")
#: Styles read from a tick made for them, by axis, tick kind, parameters and settings.
_STYLES: dict = {}
#: At most this many styles are kept (a report uses a handful).
_MAX_STYLES = 64


def rectilinear(ax) -> bool:
    """Whether ``ax`` is matplotlib's rectilinear Axes or the light one."""
    return ax.name in ("rectilinear", PROJECTION)


@contextlib.contextmanager
def report_axes():
    """Figures made in this block (by the figure functions of :mod:`subid.plot`) get
    axes of :data:`PROJECTION` (this thread or task only)."""
    token = _ACTIVE.set(True)
    try:
        yield
    finally:
        _ACTIVE.reset(token)


def subplot_kw(kwargs=None) -> dict:
    """``subplot_kw`` for ``pyplot.subplots`` (or keywords of ``add_subplot``): the
    caller's, with the light projection inside :func:`report_axes`."""
    kwargs = dict(kwargs or {})
    if _ACTIVE.get():
        _register()
        kwargs.setdefault("projection", PROJECTION)
    return kwargs


@contextlib.contextmanager
def _lists_kept(axis):
    """Within the block the axis' tick lists that are still lazy are empty lists (a
    call that walks them walks none), and lazy again after it."""
    added = [name for name in ("majorTicks", "minorTicks") if name not in axis.__dict__]
    for name in added:
        axis.__dict__[name] = []
    try:
        yield
    finally:
        for name in added:
            if not axis.__dict__.get(name):
                axis.__dict__.pop(name, None)


class _LazyTicks:
    """The ``Axis`` methods that would fill the lazy tick lists, made not to (module
    docstring); mixed into ``XAxis`` and ``YAxis``."""

    def set_clip_path(self, path, transform=None):
        with _lists_kept(self):
            super().set_clip_path(path, transform)

    def set_tick_params(self, which="major", reset=False, **kwargs):
        with _lists_kept(self):
            super().set_tick_params(which=which, reset=reset, **kwargs)

    def _get_tick(self, major):
        # made under the settings of the figure's build, and clipped to the axes as
        # reset_ticks clips the ticks matplotlib makes at once
        rc = getattr(self.axes, "_subid_rc", None) if self.axes is not None else None
        if rc:
            import matplotlib
            with matplotlib.rc_context(rc):
                tick = super()._get_tick(major)
        else:
            tick = super()._get_tick(major)
        if self.axes is not None:
            tick.set_clip_path(self.axes.patch)
        return tick


_REGISTERED: list = []


def _register():
    """Define the axes classes (matplotlib imported) and register the projection."""
    if _REGISTERED:
        return
    import matplotlib
    import matplotlib.axis as maxis
    from matplotlib.axes import Axes
    from matplotlib.projections import register_projection

    class LightXAxis(_LazyTicks, maxis.XAxis):
        pass

    class LightYAxis(_LazyTicks, maxis.YAxis):
        pass

    class LightAxes(Axes):
        """matplotlib's Axes, its ticks made when asked for (module docstring)."""

        name = PROJECTION

        def __init__(self, fig, *args, **kwargs):
            # the settings a tick of this axes would be made under: those of the figure's
            # build, read once per figure (its axes are made together)
            rc = fig.__dict__.get("_subid_tick_rc")
            if rc is None:
                values = {key: value for key, value in dict.items(matplotlib.rcParams)
                          if key.startswith(_TICK_SETTINGS)}
                rc = fig._subid_tick_rc = (values, repr(sorted(values.items())))
            self._subid_rc, self._subid_rc_key = rc
            super().__init__(fig, *args, **kwargs)

        def clear(self):
            super().clear()
            # a new tick asks its axes for the transforms of the bottom and top (left
            # and right) spines, which fixes their positions (matplotlib's default,
            # 'outward' 0); without ticks the spines are positioned here instead
            for spine in self.spines.values():
                if spine._position is None:       # Spine._ensure_position_is_set, but
                    spine._position = ("outward", 0.0)   # no reset_ticks of its axis:
                    spine.set_transform(spine.get_spine_transform())   # no ticks yet

        def _init_axis(self):
            self.xaxis = LightXAxis(self, clear=False)
            self.spines.bottom.register_axis(self.xaxis)
            self.spines.top.register_axis(self.xaxis)
            self.yaxis = LightYAxis(self, clear=False)
            self.spines.left.register_axis(self.yaxis)
            self.spines.right.register_axis(self.yaxis)

    register_projection(LightAxes)
    _REGISTERED.append(LightAxes)


def tick_style(ax, axis, major: bool) -> dict:
    """What :func:`subid.evaluation.figures._ticks.light_ticks` reads of the first
    tick of ``axis`` (major or minor): its visibility flags, grid line, mark and
    label style, and its pad. From the axis' first tick when it has made one, else
    from a tick made once for the axis' parameters and its axes' build settings."""
    made = axis.__dict__.get("majorTicks" if major else "minorTicks")
    if made:
        return _read(made[0])
    params = axis._major_tick_kw if major else axis._minor_tick_kw
    rc = ax._subid_rc
    key = (type(axis).__name__, major, repr(sorted(params.items())), ax._subid_rc_key)
    style = _STYLES.get(key)
    if style is None:
        import matplotlib
        with matplotlib.rc_context(rc):
            style = _read(axis._tick_class(ax, 0, major=major, **params))
        if len(_STYLES) >= _MAX_STYLES:
            _STYLES.clear()
        _STYLES[key] = style
    return style


def _read(tick) -> dict:
    """The style of ``tick`` as plain values (no reference to its axes or figure)."""
    mark, grid, label = tick.tick1line, tick.gridline, tick.label1
    return {
        "tick2": tick.tick2line.get_visible(), "label2": tick.label2.get_visible(),
        "grid": grid.get_visible(), "grid_color": grid.get_color(),
        "grid_linewidth": grid.get_linewidth(), "grid_linestyle": grid.get_linestyle(),
        "grid_alpha": grid.get_alpha(),
        "mark": mark.get_visible(), "marker": mark.get_marker(),
        "markersize": mark.get_markersize(), "markeredgewidth": mark.get_markeredgewidth(),
        "color": mark.get_color(), "markeredgecolor": mark.get_markeredgecolor(),
        "label": label.get_visible(), "font": label.get_fontproperties().copy(),
        "label_color": label.get_color(), "rotation": label.get_rotation(),
        "ha": label.get_horizontalalignment(), "va": label.get_verticalalignment(),
        "pad": tick._pad,
    }
