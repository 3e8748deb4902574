"""Every figure type of subid.plot rendered to PNG: resolution, text size, one colour per
method across figures, legends beside (never over) the data, unstable models marked."""

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

import subid  # noqa: E402
from subid.errors import ModelError  # noqa: E402
from subid.evaluation import plot  # noqa: E402


@pytest.fixture(autouse=True)
def _close():
    before = set(plt.get_fignums())
    yield
    for num in set(plt.get_fignums()) - before:
        plt.close(num)


@pytest.fixture(scope="module")
def case():
    true = subid.systems.seed001_system(dt=0.1)
    data = subid.systems.simulate_data(true, 800, seed=4, output_snr_db=30)
    est, val = data.split(0.7)
    models = {"ls_subspace": subid.ls_subspace(est, 3), "moesp": subid.moesp(est, 3),
              "n4sid": subid.n4sid(est, 3)}
    rec = subid.RecursiveSubspace(3, 2, 2, dt=0.1, history_size=64, history_stride=20)
    rec.update(est.u, est.y)
    return true, data, est, val, models, rec


@pytest.fixture(scope="module")
def figures(case):
    """Each figure type drawn once for the module."""
    true, data, est, val, models, rec = case
    figs = {
        "data_overview": plot.data_overview(data, split=float(val.t[0])),
        "compare": plot.compare(val, models),
        "bode": plot.bode(models),
        "poles": plot.poles({k: [m] for k, m in models.items()}, reference=true, marker="x"),
        "residuals": plot.residuals(models, val),
        "convergence": plot.convergence(rec.history, reference=true),
        "order_selection": plot.order_selection(models),
        "error_histograms": plot.error_histograms(
            {"ls_subspace": np.linspace(1e-3, 1e-2, 30), "moesp": np.linspace(2e-3, 3e-2, 30)}),
    }
    yield figs
    for fig in figs.values():
        plt.close(fig)


@pytest.mark.slow
def test_every_figure_renders_at_150_dpi_with_10_pt_text(figures, tmp_path):
    from PIL import Image
    for name, fig in figures.items():
        path = tmp_path / f"{name}.png"
        fig.savefig(path)
        with Image.open(path) as img:
            w, h = img.size
        fw, fh = fig.get_size_inches()
        assert abs(w - fw * 150) <= 1 and abs(h - fh * 150) <= 1, name
        fig.canvas.draw()
        sizes = [t.get_fontsize() for t in fig.findobj(matplotlib.text.Text)
                 if t.get_text().strip() and t.get_visible()]
        assert sizes and min(sizes) >= 9, (name, min(sizes))
        labels = [ax.xaxis.label for ax in fig.axes if ax.get_xlabel()]
        assert all(lab.get_fontsize() >= 10 for lab in labels), name


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


@pytest.mark.slow
def test_legends_sit_beside_the_data(figures):
    for name, fig in figures.items():
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
        assert legends or name == "data_overview", name      # channels named on the axes
        for legend in legends:
            box = legend.get_window_extent(renderer)
            assert box.x1 <= fig.bbox.x1 + 1 and box.y1 <= fig.bbox.y1 + 1, name   # inside
            for ax in fig.axes:
                assert not _overlaps(box, ax.get_window_extent(renderer)), (name, ax.get_title())


def _line_color(fig, label):
    for ax in fig.axes:
        for ln in ax.get_lines():
            if ln.get_label().startswith(label):
                return to_hex(ln.get_color())
    raise AssertionError(f"no line labelled {label}")


def test_one_colour_per_method_in_every_figure(case, figures):
    models = case[4]
    figs = figures
    expected = {k: to_hex(plot.METHOD_COLORS[k]) for k in models}
    assert len(set(expected.values())) == len(expected)
    for name in ("compare", "bode", "poles", "residuals", "order_selection"):
        for method, color in expected.items():
            assert _line_color(figs[name], method) == color, (name, method)
    # the same method twice in one figure: two different colours
    fig = plot.bode({"a": models["moesp"], "b": models["moesp"]})
    assert _line_color(fig, "a") != _line_color(fig, "b")


def test_bode_marks_unstable_models(case):
    models = case[4]
    bad = subid.StateSpace(np.diag([1.1, 0.5, 0.2]), np.ones((3, 2)), np.ones((2, 3)), 0,
                           dt=0.1)
    fig = plot.bode({"good": models["moesp"], "bad": bad})
    texts = [t.get_text() for ax in fig.axes if ax.get_legend()
             for t in ax.get_legend().get_texts()]
    assert texts == ["good", "bad (unstable)"]
    styles = {ln.get_label(): ln.get_linestyle() for ln in fig.axes[0].get_lines()
              if ln.get_label() in texts}
    assert styles == {"good": "-", "bad (unstable)": "--"}


def test_bode_per_sample_units_when_dt_is_the_default(case):
    models = case[4]
    assert plot.bode(models).axes[-1].get_xlabel() == "frequency (rad/s)"
    m = models["moesp"]
    per_sample = subid.StateSpace(m.A, m.B, m.C, m.D, 1.0)
    assert plot.bode(per_sample).axes[-1].get_xlabel() == "frequency (rad/sample)"
    assert plot.bode(per_sample, hz=True).axes[-1].get_xlabel() == \
        "frequency (cycles/sample)"


def test_convergence_has_a_legend_of_poles_and_truth(case):
    true, *_, rec = case
    fig = plot.convergence(rec.history, reference=true)
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts == ["pole 1", "pole 2", "pole 3", "true poles"]


def test_order_selection_marks_the_chosen_order(case):
    models = case[4]
    auto = subid.moesp(case[2])                  # order chosen at the largest gap
    fig = plot.order_selection({"moesp": auto})
    ax = fig.axes[0]
    vlines = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 2
              and ln.get_xdata()[0] == ln.get_xdata()[1]]
    assert [ln.get_xdata()[0] for ln in vlines] == [auto.order + 0.5]
    (profile,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("moesp")]
    s = auto.info["singular_values"]
    np.testing.assert_allclose(profile.get_ydata(), s / s[0])
    assert f"order {auto.order}" in profile.get_label()
    assert "rank profile" in plot.order_selection(models["ls_subspace"]).axes[0].get_ylabel()
    with pytest.raises(ModelError, match="singular_values"):
        plot.order_selection(subid.StateSpace([[0.5]], [[1.0]], [[1.0]], 0, dt=1))
