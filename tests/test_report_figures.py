"""The report's figure pipeline: PNG encoding (evaluation/_png.py) and ticks drawn as a
few artists per axis (evaluation/figures/_ticks.py) give the pixels matplotlib draws."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest

pytest.importorskip("matplotlib")
Image = pytest.importorskip("PIL.Image")

from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from subid.evaluation import report  # noqa: E402
from subid.evaluation._png import png_bytes  # noqa: E402
from subid.evaluation.figures._ticks import light_ticks  # noqa: E402


def _decode(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (40, 33)])
def test_png_bytes_round_trip(shape):
    rng = np.random.default_rng(0)
    rgba = rng.integers(0, 256, (*shape, 4), dtype=np.uint8)
    rgba[..., 3] = 255
    assert np.array_equal(_decode(png_bytes(rgba)), rgba[..., :3])
    assert np.array_equal(_decode(png_bytes(rgba[..., :3])), rgba[..., :3])


def test_png_bytes_composites_transparency_on_white():
    rgba = np.zeros((2, 3, 4), dtype=np.uint8)          # transparent black
    rgba[1, :, 3] = 255                                 # opaque black row
    rgba[0, 2] = (255, 0, 0, 128)                       # half-transparent red
    out = _decode(png_bytes(rgba))
    assert (out[0, 0] == 255).all() and (out[1] == 0).all()
    assert tuple(out[0, 2]) == (255, 127, 127)


def test_png_bytes_rejects_other_arrays():
    with pytest.raises(ValueError, match="uint8"):
        png_bytes(np.zeros((4, 4, 4)))
    with pytest.raises(ValueError, match="shape"):
        png_bytes(np.zeros((4, 4), dtype=np.uint8))


def _figure(kind: str) -> Figure:
    fig = Figure(figsize=(6, 4), dpi=80)
    axes = fig.subplots(2, 2, sharex=True, squeeze=False)
    t = np.linspace(0.0, 10.0, 200)
    for k, ax in enumerate(axes.ravel()):
        ax.plot(t, np.sin(t + k) * 10 ** k, lw=1.0)
        ax.grid(True, lw=0.3)
        ax.set_ylabel(f"output {k}")
    axes[-1, 0].set_xlabel("time (s)")
    if kind == "log":
        from subid.evaluation.figures._common import _plain_log_labels
        axes[0, 0].set_xscale("log")
        _plain_log_labels(axes[0, 0].xaxis)
        axes[0, 1].set_yscale("log")
    elif kind == "offset":                     # a formatter offset on a y axis
        axes[0, 1].plot(t, 1e6 + 1e-3 * t)
    elif kind == "scale":      # scale factors: a shared x axis (1e6) and a y axis (1e-5)
        for ax in axes.ravel():
            ax.lines[0].set_xdata(t * 1e5)
            ax.relim()
            ax.autoscale_view()
        axes[1, 1].lines[0].set_ydata(np.sin(t) * 1e-5)
        axes[1, 1].relim()
        axes[1, 1].autoscale_view()
    return fig


def _pixels(fig: Figure, light: bool) -> np.ndarray:
    canvas = FigureCanvasAgg(fig)
    replaced = light_ticks(fig, canvas.get_renderer()) if light else 0
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(int), replaced


@pytest.mark.parametrize("kind", ["linear", "log", "offset", "scale"])
def test_light_ticks_draw_what_matplotlib_draws(kind):
    """Every axis replaced, a formatter's offset or scale factor drawn as one more text
    where matplotlib puts it: the same pixels up to anti-aliasing."""
    before, _ = _pixels(_figure(kind), light=False)
    after, replaced = _pixels(_figure(kind), light=True)
    assert replaced == 8
    # the same marks, labels, grid lines and axis-label positions: no pixel changes by
    # more than the anti-aliasing of a sub-pixel shift
    assert np.abs(before - after).max() <= 64
    assert np.abs(before - after).mean() < 0.05


def test_light_ticks_keep_axes_they_cannot_reproduce():
    fig = Figure(figsize=(3, 3))
    host = fig.subplots()
    twin = host.twinx()                        # ticks on the right, x hidden and shared
    twin.plot([0, 1], [1, 0])
    assert light_ticks(fig, FigureCanvasAgg(fig).get_renderer()) == 1  # host's y only
    assert host.xaxis.get_major_locator().__class__.__name__ != "NullLocator"


def _pole_figure(adjustable: str) -> Figure:
    fig = Figure(figsize=(6.5, 5), dpi=80)     # wider than tall, as the pole map
    ax = fig.subplots()
    theta = np.linspace(0.0, 2 * np.pi, 200)
    ax.plot(np.cos(theta), np.sin(theta), lw=0.6)
    ax.plot([0.5, 0.9], [0.3, -0.1], "x")
    ax.set_aspect("equal", adjustable=adjustable)  # the box or the limits set at draw time
    ax.set_xlabel("real part")
    ax.set_ylabel("imaginary part")
    return fig


@pytest.mark.parametrize("adjustable", ["box", "datalim"])
def test_light_ticks_draw_a_fixed_aspect_axes_as_matplotlib(adjustable):
    def pixels(light):
        fig = _pole_figure(adjustable)
        canvas = FigureCanvasAgg(fig)
        replaced = light_ticks(fig, canvas.get_renderer()) if light else 0
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].astype(int), replaced
    (before, _), (after, replaced) = pixels(False), pixels(True)
    assert replaced == 2
    assert np.abs(before - after).max() <= 64
    assert np.abs(before - after).mean() < 0.05


def test_figure_html_embeds_the_drawn_pixels():
    fig = _figure("linear")
    expected, _ = _pixels(_figure("linear"), light=False)
    text = report.figure_html(fig, "caption")
    src = text.split('src="', 1)[1].split('"', 1)[0]
    png = base64.b64decode(src.split(",", 1)[1])
    assert np.abs(_decode(png).astype(int) - expected).max() <= 64
    assert f'width="{round(6 * 96)}"' in text and "<figcaption>caption</figcaption>" in text


def test_figure_html_closes_a_pyplot_figure():
    from subid.evaluation.figures._common import _pyplot
    plt = _pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    number = fig.number
    report.figure_html(fig)
    assert number not in plt.get_fignums()


def _text_figure() -> Figure:
    fig = Figure(figsize=(4, 3), dpi=150)
    axes = fig.subplots(1, 2)
    for k, ax in enumerate(axes):
        ax.plot([0.0, 1.0 + k], [0.5, -2.0], label=f"model {k} → y{k}")
        ax.set_title("auto-correlation of e(y1)")
        ax.set_ylabel("magnitude (dB)")          # rotated
        ax.legend()
    fig.text(0.123456, 0.03, "10⁻² at a fraction of a pixel", fontsize=7)
    fig.text(0.5, 0.5, "rotated 30°", rotation=30)
    fig.text(0.7, 0.1, "aliased", antialiased=False)
    fig.text(0.02, 0.5, "input\nu1 (two lines)", fontsize=9, ha="left")   # line gaps
    fig.text(0.1, 0.9, r"$\alpha^2$ math")               # matplotlib's own path
    return fig


def test_canvas_text_draws_what_matplotlib_draws():
    from subid.evaluation._canvas import canvas
    plain = FigureCanvasAgg(_text_figure())
    plain.draw()
    expected = np.asarray(plain.buffer_rgba()).copy()
    for _ in range(2):          # then from the caches filled by the first figure
        cached = canvas(_text_figure())
        cached.draw()
        assert np.array_equal(np.asarray(cached.buffer_rgba()), expected)
