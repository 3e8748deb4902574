"""Tests of subid.plot: every function returns a Figure drawing the right numbers."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import subid  # noqa: E402
from subid import systems
from subid.errors import DataError, ModelError  # noqa: E402
from subid.evaluation import plot  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def mimo():
    true = systems.seed001_system(dt=0.1)
    data = systems.simulate_data(true, 600, seed=3)
    return true, data


def _lines(ax):
    return [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]


def test_import_subid_does_not_import_matplotlib():
    code = "import subid, sys; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


def test_bode_draws_the_frequency_response(mimo):
    true, _ = mimo
    w = np.logspace(-1, math.log10(math.pi / 0.1), 50)
    fig = plot.bode(true, w)
    assert isinstance(fig, Figure)
    axes = np.array(fig.axes).reshape(2 * true.n_outputs, true.n_inputs)
    G = true.freqresp(w)
    for i in range(true.n_outputs):
        for j in range(true.n_inputs):
            (mag,) = _lines(axes[2 * i, j])
            (ph,) = _lines(axes[2 * i + 1, j])
            np.testing.assert_allclose(mag.get_xdata(), w)
            np.testing.assert_allclose(mag.get_ydata(), 20 * np.log10(np.abs(G[:, i, j])),
                                       rtol=1e-12, atol=1e-12)
            phase = np.degrees(np.unwrap(np.angle(G[:, i, j])))
            np.testing.assert_allclose(ph.get_ydata(), phase, rtol=1e-12, atol=1e-9)
            assert axes[2 * i, j].get_xscale() == "log"


def test_bode_hz_axis_and_nyquist_cut(mimo):
    true, _ = mimo
    w = np.logspace(-1, 3, 80)                   # beyond pi / dt = 31.4 rad/s
    fig = plot.bode({"a": true, "b": true}, w, hz=True, phase=False)
    ax = fig.axes[0]
    lines = _lines(ax)
    assert len(lines) == 2
    x = lines[0].get_xdata()
    assert x.max() <= math.pi / 0.1 / (2 * math.pi) * (1 + 1e-9)
    np.testing.assert_allclose(x, w[w <= math.pi / 0.1] / (2 * math.pi))
    assert "Hz" in fig.axes[-1].get_xlabel()
    (legend,) = [a.get_legend() for a in fig.axes if a.get_legend() is not None]
    assert [t.get_text() for t in legend.get_texts()] == ["a", "b"]


def test_bode_rejects_models_of_different_shapes(mimo):
    true, _ = mimo
    siso = subid.StateSpace([[0.5]], [[1.0]], [[1.0]], 0, 0.1)
    with pytest.raises(ModelError, match="same shape"):
        plot.bode([true, siso])


def test_frequency_grid_ends_at_nyquist_and_covers_continuous_poles(mimo):
    true, _ = mimo
    w = plot.frequency_grid(true)
    assert w[-1] == pytest.approx(math.pi / 0.1)
    assert np.all(np.diff(w) > 0)
    ct = subid.StateSpace([[-100.0]], [[1.0]], [[1.0]], 0, 0.0)
    w = plot.frequency_grid(ct)
    assert w[0] <= 10 and w[-1] >= 1000


def test_compare_legend_gives_fit_percent(mimo):
    true, data = mimo
    model = subid.moesp(data, 3)
    fig = plot.compare(data, {"moesp": model})
    assert len(fig.axes) == data.n_outputs
    fits = subid.fit_percent(model, data)
    for k, ax in enumerate(fig.axes):
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert texts[0] == "measured"
        assert texts[1] == f"moesp: fit {fits[k]:.1f} %"
        measured = ax.get_lines()[0]
        np.testing.assert_array_equal(measured.get_ydata(), data.y[:, k])


def test_compare_keeps_a_diverging_simulation_off_the_scale():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(2000)
    y = np.convolve(u, [0, 1, 0.5])[:2000]
    data = subid.IOData(u, y)
    unstable = subid.StateSpace([[1.8]], [[1.0]], [[1.0]], 0, 1.0)
    fig = plot.compare(data, unstable)
    lo, hi = fig.axes[0].get_ylim()
    assert lo >= y.min() - (y.max() - y.min()) and hi <= y.max() + (y.max() - y.min())
    assert "n/a" in fig.axes[0].get_legend().get_texts()[1].get_text()


def test_data_overview_one_panel_per_channel_with_split(mimo):
    _, data = mimo
    fig = plot.data_overview(data, split=data.t[400])
    assert len(fig.axes) == data.n_inputs + data.n_outputs
    np.testing.assert_array_equal(fig.axes[0].get_lines()[0].get_ydata(), data.u[:, 0])
    np.testing.assert_array_equal(fig.axes[-1].get_lines()[0].get_ydata(), data.y[:, -1])
    assert len(fig.axes[0].patches) == 1             # the shaded validation part


def _xcorr_reference(a, b, tau):
    n = a.size
    return sum(a[t] * b[t - tau] for t in range(max(tau, 0), min(n, n + tau))) / n


def test_residual_correlations_match_definitions():
    rng = np.random.default_rng(5)
    n = 3000
    u = rng.standard_normal(n)
    model = subid.StateSpace([[0.7]], [[1.0]], [[1.0]], 0, 1.0)
    noise = 0.3 * rng.standard_normal(n)
    y = model.simulate(u)[:, 0] + noise
    data = subid.IOData(u, y)
    res = plot.residual_correlations(model, data, max_lag=10)
    e = res["residual"][:, 0]
    e0 = e - e.mean()
    u0 = u - u.mean()
    assert res["auto"][0, 0] == pytest.approx(1.0)
    for tau in (1, 4, 10):
        ref = _xcorr_reference(e0, e0, tau) / _xcorr_reference(e0, e0, 0)
        assert res["auto"][0, tau] == pytest.approx(ref, abs=1e-12)
    scale = math.sqrt(_xcorr_reference(e0, e0, 0) * _xcorr_reference(u0, u0, 0))
    for tau in (-3, 0, 2):
        ref = _xcorr_reference(e0, u0, tau) / scale
        assert res["cross"][0, 0, tau + 10] == pytest.approx(ref, abs=1e-12)
    assert res["auto_bound"] == pytest.approx(2.5758293035489 / math.sqrt(n))
    # the true model leaves white residuals independent of the input ...
    assert np.mean(np.abs(res["auto"][0, 1:]) < res["auto_bound"]) >= 0.8
    assert np.all(np.abs(res["cross"][0, 0]) < 2 * res["cross_bound"][0, 0])
    # ... a wrong model leaves the input in the residuals
    wrong = subid.StateSpace([[0.2]], [[1.0]], [[1.0]], 0, 1.0)
    bad = plot.residual_correlations(wrong, data, max_lag=10)
    assert np.max(np.abs(bad["cross"][0, 0, 11:])) > 5 * bad["cross_bound"][0, 0]


def test_residuals_figure_layout_and_bands(mimo):
    true, data = mimo
    fig = plot.residuals({"a": true, "b": subid.moesp(data, 3)}, data, max_lag=15)
    ny, nu = data.n_outputs, data.n_inputs
    assert len(fig.axes) == ny * (1 + nu)
    res = plot.residual_correlations(true, data, max_lag=15)
    band = fig.axes[0].patches[0]                       # shaded 99 % band
    if hasattr(band, "get_height"):                     # Rectangle (matplotlib >= 3.9)
        top = band.get_y() + band.get_height()
    else:                                               # Polygon
        top = np.max(np.asarray(band.get_xy())[:, 1])
    assert top == pytest.approx(res["auto_bound"])
    dashed = [ln.get_ydata()[0] for ln in fig.axes[1].get_lines() if ln.get_linestyle() == "--"]
    assert res["cross_bound"][0, 0] == pytest.approx(max(dashed[:2]))



def test_residuals_figure_limits_cover_stems_and_bands(mimo):
    """Each panel's data limits (updated once per panel, not at every artist) span its
    stems, from zero, the dashed bands of every model and the zero line, as the
    per-call ``vlines`` and ``axhline`` spanned them."""
    true, data = mimo
    models = {"a": true, "b": subid.moesp(data, 3)}
    fig = plot.residuals(models, data, max_lag=15)
    res = [plot.residual_correlations(m, data, max_lag=15) for m in models.values()]
    nu = data.n_inputs
    for i in range(data.n_outputs):
        for j in range(nu):
            lim = fig.axes[i * (1 + nu) + 1 + j].dataLim
            values = np.concatenate([np.append(r["cross"][i, j], [r["cross_bound"][i, j],
                                                                   -r["cross_bound"][i, j]])
                                     for r in res] + [[0.0]])
            assert (lim.y0, lim.y1) == (values.min(), values.max())
            assert (lim.x0, lim.x1) == (-15 - 0.2, 15 + 0.2)
        lim = fig.axes[i * (1 + nu)].dataLim
        values = np.concatenate([r["auto"][i] for r in res] + [[0.0]])
        assert lim.y1 >= values.max() and lim.y0 <= values.min()

def test_residuals_of_a_diverging_model_raise_a_clear_error():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(3000)
    data = subid.IOData(u, np.convolve(u, [0, 1])[:3000])
    unstable = subid.StateSpace([[1.8]], [[1.0]], [[1.0]], 0, 1.0)
    with pytest.raises(DataError, match="diverges"):
        plot.residuals(unstable, data)


def test_convergence_from_recursive_history_with_parameters():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 1500, seed=2)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, history_size=50, history_stride=100)
    rs.update(data.u, data.y)
    hist = rs.history
    fig = plot.convergence(hist, reference=true)
    assert len(fig.axes) == 2
    assert len(_lines(fig.axes[0])) == 3                # one trajectory per pole
    np.testing.assert_allclose(_lines(fig.axes[0])[0].get_ydata(), hist["poles"][:, 0].real)
    params = np.cumsum(np.ones((hist["sample"].size, 4)), axis=0)
    fig = plot.convergence({**hist, "parameters": params,
                            "parameter_names": ["a", "b", "c", "d"]})
    assert len(fig.axes) == 4
    assert len(_lines(fig.axes[2])) == 4
    with pytest.raises(DataError):
        plot.convergence({"poles": []})


def test_poles_keeps_its_signature_and_draws_unit_circle_or_axis(mimo):
    true, data = mimo
    fig, ax = plt.subplots()
    out = plot.poles({"m": [subid.moesp(data, 3)]}, reference=true, ax=ax, markersize=3)
    assert out is fig
    circle = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 400]
    assert circle and np.allclose(np.hypot(circle[0].get_xdata(), circle[0].get_ydata()), 1)
    ct = true.to_continuous("bilinear")
    fig = plot.poles({"dt": [true], "ct": [ct]}, marker="x")
    assert len(fig.axes) == 2                           # z plane and s plane
    xs = np.concatenate([ln.get_xdata() for ln in fig.axes[1].get_lines()
                         if ln.get_label() == "ct"])
    np.testing.assert_allclose(np.sort(xs), np.sort(ct.poles().real))


def test_error_histograms_still_works():
    fig = plot.error_histograms({"a": np.array([0.1, 0.2, 0.3]), "b": np.array([1.0, 2.0])})
    assert len(fig.axes) == 2


def test_plot_functions_never_print(mimo, capsys):
    true, data = mimo
    plot.bode(true)
    plot.compare(data, true)
    plot.residuals(true, data)
    plot.data_overview(data)
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""


def test_order_scores_chart():
    import warnings

    import subid
    from subid.evaluation import plot
    est = subid.datasets.load("dryer").detrend()[:600]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        models = {"ls": subid.ls_subspace(est), "n4sid gap": subid.n4sid(est, selection="gap")}
    fig = plot.order_scores(models)
    assert len(fig.axes) == 2
    labels = [t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts()]
    assert "chosen: n=%d, f=%d" % (models["ls"].order, models["ls"].info["horizon"]) in labels
    assert "chosen: n=%d" % models["n4sid gap"].order in labels
    with pytest.raises(subid.errors.DataError, match="order was"):
        plot.order_scores(subid.moesp(est, 2, horizon=10))


def test_labels_must_name_every_model_once():
    """A short or repeated label list dropped models from the figure, silently (zip
    truncated, a dict overwrote); a single string labelled the model with its first
    letter."""
    data = systems.simulate_data(systems.seed001_system(), 800, seed=1, output_snr_db=20)
    a, b, c = subid.n4sid(data, 3), subid.moesp(data, 3), subid.n4sid(data, 2)
    with pytest.raises(ModelError, match="1 label.s. for 3 model"):
        plot.bode([a, b, c], labels=["first"])
    with pytest.raises(ModelError, match="repeat"):
        plot.bode({"x": a, "y": b}, labels=["z", "z"])
    def labels(fig):
        return [ln.get_label() for ln in fig.axes[0].get_lines()
                if not ln.get_label().startswith("_")]

    assert labels(plot.bode(a, labels="only")) == ["only"]
    assert labels(plot.bode([a, b], labels=["p", "q"])) == ["p", "q"]


def test_bode_refuses_frequencies_all_above_nyquist_and_keeps_data_bands_readable():
    """Frequencies all above pi/dt drew an empty figure (a log message and matplotlib's
    legend warning); and the data's two-sigma band, floored at 1e-12 |G|, stretched the
    magnitude axis of a noisy spa estimate to -260 dB: its floor is 60 dB below the point
    now, as the models' bands."""
    true = systems.seed001_system()
    with pytest.raises(DataError, match="above the Nyquist frequency"):
        plot.bode(true, w=[4.0, 5.0])
    data = systems.simulate_data(true, 300, seed=1, output_snr_db=-5)
    fig = plot.bode(subid.spa(data))
    for ax in fig.axes[0::4] + fig.axes[1::4]:          # the magnitude panels
        assert ax.get_ylim()[0] > -120, ax.get_ylim()


def test_bode_bands_of_a_continuous_time_model_say_that_it_carries_none():
    # the message said to refine with subid.pem, which a continuous-time model refined by
    # pem already was: continuous-time models carry no covariance
    from subid.errors import ModelError
    ct = subid.systems.seed000_system()
    w = np.logspace(-1, 1, 50)
    data = subid.FRData(w, ct.freqresp(w) * (1 + 0.01 * np.random.default_rng(0)
                                             .standard_normal((50, 2, 2))))
    refined = subid.pem(data, subid.fd_subspace(data, 4))
    with pytest.raises(ModelError, match="continuous-time models carry none"):
        plot.bode(refined, confidence=0.95, data=data)
