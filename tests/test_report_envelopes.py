"""The report's long traces: min/max bands drawn as images (evaluation/figures/_raster.py)
give the pixels of matplotlib's polygons; the time plots' block starts and the
comparison's given fits are those the public figures compute."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402

import subid  # noqa: E402
from subid.evaluation.figures import _raster  # noqa: E402
from subid.evaluation.figures._common import (  # noqa: E402
    MAX_TRACE_POINTS,
    _times,
    simulated_output,
)
from subid.evaluation.figures.time_domain import compare_outputs  # noqa: E402


def _record(n=40_000):
    true = subid.systems.random_system(3, 1, 2, seed=7)
    data = subid.systems.simulate_data(true, n, seed=8, output_snr_db=20)
    y = data.y.copy()
    y[n // 3, 0] += 25.0 * np.abs(y[:, 0]).max()        # a spike the band must keep
    return true, subid.IOData(data.u, y, dt=data.dt)


def _render(fig, raster: bool):
    fig.set_dpi(80)
    canvas = FigureCanvasAgg(fig)
    count = _raster.raster_envelopes(fig) if raster else 0
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(int), count


def _dark_extent(image, ax, level=180):
    """Top and bottom rows (from the top) with a dark pixel inside ``ax``'s box."""
    box = ax.bbox
    height = image.shape[0]
    top, bottom = int(height - box.y1) + 2, int(height - box.y0) - 2
    inside = image[top:bottom, int(box.x0) + 2:int(box.x1) - 2]
    rows = np.flatnonzero((inside.min(axis=2) < level).any(axis=1))
    return top + rows[0], top + rows[-1]


@pytest.mark.parametrize("kind", ["data", "compare"])
def test_envelope_images_draw_the_pixels_of_the_bands(kind):
    true, data = _record()

    def make():
        if kind == "data":
            return subid.plot.data_overview(data, split=20_000.0 * data.dt)
        return subid.plot.compare(data, {"true": true})

    before, _ = _render(make(), raster=False)
    fig = make()
    after, count = _render(fig, raster=True)
    assert count == (data.n_inputs + data.n_outputs if kind == "data" else 2 * data.n_outputs)
    bands = [c for ax in fig.axes for c in ax.collections if hasattr(c, _raster._TAG)]
    assert len(bands) == count and not any(c.get_visible() for c in bands)
    diff = np.abs(before - after).max(axis=2)
    # the same bands: single pixels differ at the steep flanks of the zig-zag edges
    assert diff.mean() < 4.0 and (diff > 128).mean() < 0.02
    for ax in fig.axes:                # every panel spans the same minimum and maximum
        old, new = _dark_extent(before, ax), _dark_extent(after, ax)
        assert abs(old[0] - new[0]) <= 1 and abs(old[1] - new[1]) <= 1, (old, new)


def test_bands_of_merged_records_are_left_to_agg():
    fig = subid.plot.compare(subid.IOData(np.zeros((3000, 1)), np.ones((3000, 1))),
                             {"m": subid.StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], 1.0)})
    band = fig.axes[0].collections[0]
    start = np.r_[np.arange(10.0), np.arange(10.0)]      # two experiments' times
    delattr(band, _raster._TAG)
    _raster.tag_envelope(band, start, start, start + 1, fill=True, lw=1.0)
    assert not hasattr(band, _raster._TAG)
    assert _raster.raster_envelopes(fig) == 1            # the other band only
    true, data = _record(5000)
    flipped = subid.plot.compare(data, {"true": true})
    flipped.axes[0].invert_yaxis()                       # the columns assume increasing axes
    assert _raster.raster_envelopes(flipped) == 2        # the second panel's two bands only


def test_block_starts_of_a_uniform_record_equal_its_time_stamps():
    u = np.zeros((50_001, 1))
    data = subid.IOData(u, u, dt=0.01)[7:]               # t0 = 0.07
    times = _times(data)
    assert not isinstance(times, np.ndarray)              # the stamps are not all built
    for step in (1, 37, -(-data.n_samples // (MAX_TRACE_POINTS // 2))):
        np.testing.assert_array_equal(times[::step], data.t[::step])
    assert times[0] == data.t[0] and times[-1] == data.t[-1] and times.size == data.n_samples
    np.testing.assert_array_equal(np.asarray(times), data.t)
    short = data[:100]
    assert isinstance(_times(short), np.ndarray)


def test_compare_outputs_draws_the_given_outputs_and_fits():
    true, data = _record(5000)
    simulated, _ = simulated_output(true, data)
    fits = subid.fit_percent(true, data)
    public = subid.plot.compare(data, {"true": true}, simulated={"true": simulated})
    given = compare_outputs(data, {"true": true}, {"true": (simulated, fits)})
    labels = [[t.get_text() for t in ax.get_legend().get_texts()] for ax in public.axes]
    assert labels == [[t.get_text() for t in ax.get_legend().get_texts()] for ax in given.axes]
    assert all(f"fit {fits[i]:.1f} %" in labels[i][1] for i in range(data.n_outputs))
    shown = compare_outputs(data, {"true": true}, {"true": (simulated, fits + 1.0)})
    assert f"fit {fits[0] + 1.0:.1f} %" in shown.axes[0].get_legend().get_texts()[1].get_text()
    assert math.isfinite(fits[0])
