"""The report's axes make no tick objects (evaluation/figures/_light_axes.py) and draw
the pixels matplotlib's Axes draw."""

from __future__ import annotations

import contextlib
import contextvars
import re

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import matplotlib.axis as maxis  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import subid  # noqa: E402
from subid.evaluation import report  # noqa: E402
from subid.evaluation.figures import _light_axes  # noqa: E402
from subid.evaluation.figures._ticks import light_ticks  # noqa: E402


@pytest.fixture(scope="module")
def record():
    true = subid.systems.random_system(4, 2, 2, seed=29)
    data = subid.IOData(*(lambda d: (d.u, d.y))(
        subid.systems.simulate_data(true, 3000, seed=30, output_snr_db=20)), dt=0.01)
    est, val = data.split(0.7)
    moesp = subid.moesp(est, 4, horizon=10)
    ct = subid.StateSpace(moesp.A, moesp.B, moesp.C, moesp.D, 0.01).to_continuous(
        method="bilinear")                   # a continuous-time model: two pole maps
    models = {"moesp": moesp, "arx": subid.arx(est, (2, 2, 1)), "ct": ct}
    return models, est, val, data


def _images(models, est, val, data):
    html = report.identification_report(models, est, val, title="t", data=data)
    return re.findall(r'src="data:image/png;base64,([^"]+)"', html)


@contextlib.contextmanager
def _stock_axes(monkeypatch):
    """The report built with matplotlib's own Axes (the light ones switched off)."""
    with monkeypatch.context() as m:
        m.setattr(_light_axes, "_ACTIVE", contextvars.ContextVar("off", default=False))
        m.setattr(_light_axes, "report_axes", contextlib.nullcontext)
        yield


@pytest.fixture
def ticks_made(monkeypatch):
    """A counter of the Tick objects made (matplotlib's XTick and YTick)."""
    made = []
    for cls in (maxis.XTick, maxis.YTick):
        original = cls.__init__

        def counting(self, *args, _original=original, **kwargs):
            made.append(type(self).__name__)
            _original(self, *args, **kwargs)
        monkeypatch.setattr(cls, "__init__", counting)
    return made


def test_every_report_image_is_the_one_matplotlib_axes_draw(record, monkeypatch):
    light = _images(*record)
    with _stock_axes(monkeypatch):
        stock = _images(*record)
    assert len(light) == len(stock) >= 7
    # the same PNG bytes: the same pixels, figure by figure (data overview, comparison,
    # Bode, step, pole maps of both time bases, residuals)
    assert [a == b for a, b in zip(light, stock)] == [True] * len(stock)


def test_report_axes_make_no_tick(record, monkeypatch, ticks_made):
    monkeypatch.setattr(_light_axes, "_STYLES", {})
    _images(*record)
    # one tick for each style read (a handful per process), none per axis
    assert 0 < len(ticks_made) == len(_light_axes._STYLES) <= 12
    ticks_made.clear()
    _images(*record)
    assert ticks_made == []                   # every axis drawn by light_ticks
    with _stock_axes(monkeypatch):
        _images(*record)
    assert len(ticks_made) >= 4 * 20          # matplotlib's: a major and a minor per axis


def _kept_axis_figure() -> Figure:
    """Two panels, one with its y ticks on the right (matplotlib's own)."""
    fig = Figure(figsize=(6, 3), dpi=80)
    axes = fig.subplots(1, 2, subplot_kw=_light_axes.subplot_kw())
    t = np.linspace(0.0, 10.0, 200)
    axes[0].plot(t, np.sin(t))
    axes[1].plot(t, 1e6 + 1e-3 * t)
    axes[1].yaxis.tick_right()
    for ax in axes:
        ax.grid(True, lw=0.3)
        ax.set_xlabel("time (s)")
    return fig


def test_an_axis_light_ticks_keeps_makes_its_ticks_as_matplotlib(ticks_made):
    def pixels(light):
        with _light_axes.report_axes() if light else contextlib.nullcontext():
            fig = _kept_axis_figure()
        assert all(ax.name == (_light_axes.PROJECTION if light else "rectilinear")
                   for ax in fig.axes)
        canvas = FigureCanvasAgg(fig)
        replaced = light_ticks(fig, canvas.get_renderer())
        canvas.draw()
        return np.asarray(canvas.buffer_rgba()).copy(), replaced
    before, replaced_stock = pixels(False)
    ticks_made.clear()
    after, replaced_light = pixels(True)
    assert replaced_stock == replaced_light == 3      # the right-hand axis is kept
    assert ticks_made                                 # which made its ticks when drawn
    assert np.array_equal(before, after)


def test_tick_styles_are_kept_as_values(record):
    """The cache of tick styles holds no tick, axes or figure (no figure kept alive)."""
    _images(*record)
    assert _light_axes._STYLES
    for style in _light_axes._STYLES.values():
        assert not any(hasattr(v, "axes") or hasattr(v, "figure") for v in style.values())


def test_a_changed_setting_is_a_new_tick_style(record, monkeypatch):
    """matplotlib settings changed between two reports (tick colour and length): the
    light axes draw what matplotlib's draw under them, not a style read before."""
    import matplotlib
    _images(*record)                                   # styles read under the defaults
    with matplotlib.rc_context({"xtick.color": "red", "ytick.color": "red",
                                "xtick.major.size": 6.0}):
        light = _images(*record)
        with _stock_axes(monkeypatch):
            stock = _images(*record)
    assert [a == b for a, b in zip(light, stock)] == [True] * len(stock)
    assert light != _images(*record)                   # the setting shows in the images


def test_frequency_and_online_reports_draw_the_same_images(monkeypatch):
    """The other reports built on the same figures: from frequency-response data, and of
    an online run with its convergence history."""
    from subid.evaluation.frequency_report import frequency_report
    from subid.methods.online.base import Tracker
    true = subid.systems.random_system(3, 2, 2, seed=29)
    w = np.linspace(0.05, 3.0, 120)
    frd = subid.FRData(w, true.freqresp(w), dt=true.dt)
    fitted = subid.fd_subspace(frd, 3)
    d = subid.systems.simulate_data(true, 1500, seed=30, output_snr_db=20)
    data = subid.IOData(d.u, d.y, dt=1.0)
    tracker = Tracker(subid.RecursiveSubspace(3, 2, 2, dt=1.0), data, trace_every=100)
    tracker.run(chunk=300)
    history, online = tracker.history(), tracker.ident.model

    def images():
        pages = [frequency_report({"fd": fitted}, frd),
                 report.identification_report({"rs": online}, data, history=history)]
        return [img for page in pages
                for img in re.findall(r'src="data:image/png;base64,([^"]+)"', page)]
    light = images()
    with _stock_axes(monkeypatch):
        stock = images()
    assert len(light) == len(stock) >= 6
    assert any("convergence" in page for page in [report.identification_report(
        {"rs": online}, data, history=history)])
    assert [a == b for a, b in zip(light, stock)] == [True] * len(stock)
