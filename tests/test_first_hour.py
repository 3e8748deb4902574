"""Issue 29, the first hour of a new user: the help and the docs say the same, every
install instruction works, one-line command-line messages, the demo explains its red
flags, ``dt`` from a time column, measured data drawn on top."""

from __future__ import annotations

import pathlib
import re
import sys

import numpy as np
import pytest

import subid
from subid.cli.commands import main
from subid.methods.crossval import AUTO_ORDER_RULE

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _flat(text: str) -> str:
    """``text`` on one line: whitespace and line breaks collapsed, backticks removed, and
    words that a help text wrapped at their hyphen ("cross-" / "validated") joined."""
    return re.sub(r"(\w)- (\w)", r"\1-\2", " ".join(text.replace("`", "").split()))


def run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


# -- one source of truth for the defaults ----------------------------------------------
def test_order_auto_is_described_alike_by_help_readme_cli_docs_and_notebook(capsys):
    code, out, _ = run(capsys, "identify", "--help")
    assert code == 0
    rule = _flat(AUTO_ORDER_RULE)
    assert rule in _flat(out)
    for doc in ("README.md", "docs/cli.md", "docs/gallery.md", "examples/quickstart.ipynb"):
        assert rule in _flat((ROOT / doc).read_text(encoding="utf-8")), doc
    # the phrase is made from the constants the selection uses
    from subid.methods import crossval
    assert f"1..{crossval.MAX_ORDER}" in rule
    assert "BIC" in rule
    assert "largest gap among" not in _flat(out)


def _documents():
    paths = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *(ROOT / "docs").rglob("*.md"),
             *(ROOT / "examples").glob("*.ipynb"), *(ROOT / "src" / "subid").rglob("*.py")]
    return [p for p in paths if p.is_file()]


def test_no_install_instruction_names_a_package_index_release_of_subid():
    # subid is not published: "pip install subid" and "pip install 'subid[extra]'" fail on
    # a fresh machine; installs are from the source folder (pip install ".[extra]")
    bad = re.compile(r"""pip install\s+["']?subid\b""")
    found = [f"{p.relative_to(ROOT)}:{n}" for p in _documents()
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if bad.search(line)]
    assert found == []


def test_every_extra_named_in_an_install_hint_exists_in_pyproject():
    import tomllib
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    named = {m.group(1) for p in _documents()
             for m in re.finditer(r"""pip install\s+["']?\.\[(\w+)\]""",
                                  p.read_text(encoding="utf-8"))}
    assert named and named <= set(extras)


# -- command-line messages -------------------------------------------------------------
@pytest.fixture()
def model_file(tmp_path):
    model = subid.StateSpace([[0.9, 0.1], [0.0, 0.5]], [[1.0], [0.5]], [[1.0, 0.0]], [[0.0]],
                             0.1, K=[[0.2], [0.1]], noise_cov=[[0.01]])
    path = tmp_path / "model.json"
    model.save(path)
    return path


def test_convert_to_control_without_python_control_names_the_extra(model_file, capsys,
                                                                     monkeypatch):
    monkeypatch.setitem(sys.modules, "control", None)
    code, out, err = run(capsys, "convert", model_file, "--to", "control")
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert "'control' extra" in err and 'pip install ".[control]"' in err
    assert not (model_file.parent / "model_control.py").exists()


def test_convert_to_ct_shows_the_warning_on_one_line_without_a_source_path(model_file,
                                                                            capsys):
    code, out, err = run(capsys, "convert", model_file, "--to", "ct")
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("subid: WARNING: to_continuous")
    assert ".py" not in err and "Warning:" not in err
    code, out, err = run(capsys, "--quiet", "convert", model_file, "--to", "ct")
    assert code == 0 and err == ""


# -- the demo explains its red flags ---------------------------------------------------
def _parts(drift: float):
    """Estimation and validation parts; the validation outputs moved by ``drift`` std."""
    rng = np.random.default_rng(5)
    u = rng.standard_normal((300, 1))
    y = rng.standard_normal((300, 2))
    est = subid.IOData(u[:200], y[:200], output_names=["a", "b"])
    val = subid.IOData(u[200:], y[200:] + [drift * y[200:, 0].std(), 0.0],
                       output_names=["a", "b"])
    return est, val


def _row(**kw):
    row = dict(dataset="dryer2", method="moesp", function="moesp", order=6, horizon=10,
               fit_est=np.array([80.0, 90.0]), fit_val=np.array([-7.0, -20.0]), stable=True,
               seconds=0.1, warnings=[], error=None)
    row.update(kw)
    return row


def test_demo_diagnosis_names_the_cause_of_every_bad_result_and_what_to_try():
    from subid.cli.demo import diagnose
    est, val = _parts(drift=0.0)
    assert diagnose(_row(fit_val=np.array([30.0, 8.0])), est, val) is None
    cases = {
        "failed": (_row(error="ct_subspace: 140 samples are too few for a basis of 8 "
                               "functions; supply more data or use fewer basis functions",
                        fit_val=None, fit_est=None, stable=None, order=None),
                   "--validate 0.2", "summary"),
        "diverges": (_row(fit_val=np.array([np.nan, 8.0])), "stability=enforce", "compare"),
        "unstable model": (_row(stable=False), "stability=enforce", "poles"),
        "plant itself may be unstable": (_row(stable=False, fit_val=np.array([90.0, 80.0])),
                                         "if it is not", "poles"),
        "but not the validation part": (_row(), "--order 1:5", "compare"),
        "explain little": (_row(fit_est=np.array([10.0, 20.0]), fit_val=np.array([-20.0, 5.0])),
                           "--refine pem", "residuals"),
    }
    for word, (row, hint, section) in cases.items():
        reason, what, where = diagnose(row, est, val)
        assert word in reason and hint in what and where == section, (word, reason, what)
        assert "\n" not in reason + what and len(reason) <= 200
    # the validation part at another operating point: detrend linearly
    est, val = _parts(drift=2.0)
    reason, what, where = diagnose(_row(), est, val)
    assert "operating point moves" in reason and "a's mean" in reason
    assert "--detrend linear" in what and where == "data"


def test_demo_index_shows_the_reason_beside_the_cell_with_a_link():
    from subid.evaluation.report import index_page
    page = index_page([{"name": "dryer2", "href": "dryer2.html", "moesp": "-13.2 (6)",
                        "notes": {"moesp": ("the operating point moves", "subid identify "
                                            "dataset:dryer2 --detrend linear",
                                            "dryer2.html#data")}},
                       {"name": "dryer", "href": "dryer.html", "moesp": "88.5 (6)"}],
                      columns=["moesp"])
    cell = re.search(r"<td>-13\.2 \(6\)<div class=\"why\">(.*?)</div></td>", page).group(1)
    assert "the operating point moves" in cell and 'href="dryer2.html#data"' in cell
    assert "--detrend linear" in cell
    assert "<td>88.5 (6)</td>" in page


# -- progress on a terminal ------------------------------------------------------------
def test_steps_bar_names_each_step_on_stderr_and_is_silent_when_disabled(capsys):
    from subid._progress import Steps
    with Steps(["read", "identify"], "identify", enabled=True, refresh=0.01) as steps:
        steps.start("read")
        steps.start("identify")
        steps.detail("bode")
    err = capsys.readouterr().err
    assert "read" in err and "identify: bode" in err
    with Steps(["read"], "identify", enabled=False) as steps:
        steps.start("read")
        steps.detail("x")
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("quiet", [False, True])
def test_identify_shows_its_steps_on_a_terminal_never_with_quiet(quiet, tmp_path, capsys,
                                                                 monkeypatch):
    from subid.cli import _shared as commands
    monkeypatch.setattr(commands, "on_terminal", lambda quiet=False: not quiet)
    code, out, err = run(capsys, *(["--quiet"] if quiet else []), "identify", "dataset:dryer",
                         "--order", "2", "--horizon", "10", "--no-report",
                         "--out", tmp_path / "o")
    assert code == 0
    if quiet:
        assert err == "" and out == ""
    else:
        for step in ("read", "identify", "evaluate", "write"):
            assert step in err


# -- dt from a time column; measured data on top -----------------------------------------
def test_dt_from_a_time_column_is_the_grid_step_to_the_precision_of_the_file(tmp_path):
    rng = np.random.default_rng(3)
    n = 400
    t = [f"{0.05 * k:.2f}" for k in range(n)]
    path = tmp_path / "log.csv"
    path.write_text("t,u,y\n" + "".join(f"{a},{b:.6f},{c:.6f}\n" for a, b, c in
                                         zip(t, rng.standard_normal(n), rng.standard_normal(n))))
    data = subid.read(str(path), inputs=["u"], outputs=["y"], time="t")
    assert np.mean(np.diff(data.t)) != 0.05          # what the float differences give
    assert data.dt == 0.05
    # stamps written with more decimals than the step needs, and computed stamps
    assert subid.IOData(np.ones(5), np.ones(5), t=[0.0, 0.25, 0.5, 0.75, 1.0]).dt == 0.25
    computed = 0.1 * np.arange(1000)
    assert subid.IOData(np.ones(1000), np.ones(1000), t=computed).dt == np.mean(
        np.diff(computed))


def test_compare_draws_the_measured_output_on_top_and_distinguishable():
    pytest.importorskip("matplotlib")
    true = subid.systems.random_system(2, 1, 1, seed=4)
    data = subid.systems.simulate_data(true, 300, seed=5)
    fig = subid.plot.compare(data, {"true": true})
    measured, model = fig.axes[0].get_lines()[:2]
    assert measured.get_label() == "measured"
    assert measured.get_zorder() > model.get_zorder()
    assert measured.get_linewidth() < model.get_linewidth()
    assert measured.get_color() != model.get_color() or model.get_alpha() < 1


def test_long_traces_are_drawn_through_their_min_max_blocks():
    from subid.evaluation.plot import MAX_TRACE_POINTS, _min_max_blocks
    n = 100_003
    t = np.arange(n) * 0.01
    y = np.sin(t) + np.where(np.arange(n) == 55_555, 9.0, 0.0)    # one spike
    start, low, high = _min_max_blocks(t, y)
    size = -(-n // (MAX_TRACE_POINTS // 2))
    assert len(start) == len(low) == len(high) == -(-n // size) <= MAX_TRACE_POINTS // 2
    np.testing.assert_array_equal(start, t[::size])                   # each block's start
    for k in (0, 27, len(low) - 1):                                   # the last is shorter
        np.testing.assert_array_equal([low[k], high[k]], [y[k * size:(k + 1) * size].min(),
                                                          y[k * size:(k + 1) * size].max()])
    assert high.max() == y.max() and low.min() == y.min()            # the spike is kept
    y[70_000] = np.nan                                                # a gap in the band
    _, low, high = _min_max_blocks(t, y)
    assert np.isnan(low[70_000 // size]) and np.isnan(high[70_000 // size])
    assert np.isfinite(np.delete(low, 70_000 // size)).all()


def test_one_step_x0_from_decayed_free_responses_equals_the_full_regression():
    # the fast path of predict (free responses only until they decay) against the
    # regression over every sample (the path without ``data``)
    from subid.model import prediction
    true = subid.systems.random_system(3, 1, 2, seed=11)
    data = subid.systems.simulate_data(true, 3000, seed=12, output_snr_db=20)
    model = subid.moesp(data, 3, horizon=10)
    assert model.K is not None
    fast = prediction._estimate_x0(model, data.u, data.y, 1, data)
    full = prediction._estimate_x0(model, data.u, data.y, 1)
    np.testing.assert_allclose(fast[0], full[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fast[1], full[1], rtol=1e-9, atol=1e-12)
    y_hat, x0 = subid.predict(model, data, 1, return_x0=True)
    np.testing.assert_allclose(x0, full[0], rtol=1e-9, atol=1e-12)


def test_spa_covariances_by_direct_products_equal_the_fft_ones(monkeypatch):
    # the report's spa overlay on long records: few lags by products, many by FFT
    from subid.evaluation import nonparametric
    true = subid.systems.random_system(3, 2, 1, seed=21)
    data = subid.systems.simulate_data(true, 3000, seed=22, output_snr_db=10).detrend()
    merged = subid.merge([data[:1200], data[1200:]])
    for record in (data, merged):
        direct = nonparametric._covariances(record, 30)
        monkeypatch.setattr(nonparametric, "_COVARIANCE_BLOCK", 97)    # blocks, short last
        blocks = nonparametric._covariances(record, 30)
        monkeypatch.setattr(nonparametric, "_DIRECT_LAGS", -1)
        fft = nonparametric._covariances(record, 30)
        monkeypatch.undo()
        np.testing.assert_allclose(direct, fft, rtol=0, atol=1e-12 * np.abs(fft).max())
        np.testing.assert_allclose(blocks, fft, rtol=0, atol=1e-12 * np.abs(fft).max())


def test_readme_signatures_of_the_online_identifiers_show_dt_and_the_required_arguments():
    import inspect
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for cls in (subid.RecursiveSubspace, subid.AdaptiveIdentifier):
        row = re.search(rf"`{cls.__name__}\(([^`]*)\)`", readme).group(1)
        shown = {part.split("=")[0].strip(" *") for part in row.split(",")}
        params = inspect.signature(cls).parameters.values()
        required = {p.name for p in params if p.default is p.empty}
        assert required <= shown and "dt" in shown, (cls.__name__, shown)


def test_report_charts_order_scores_only_for_records_over_orders_and_horizons():
    # the polynomial methods' structure records (na, nb) are not order/horizon scores: the
    # demo's reports broke on them (KeyError 'horizon')
    from subid.evaluation.report import _order_scored
    model = subid.StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], 1.0)
    model.info["order_selection"] = {"rule": "cv", "candidates": [
        {"na": 1, "nb": 1, "score": 60.0}], "selected": {"na": 1, "nb": 1, "score": 60.0}}
    assert not _order_scored(model)
    model.info["order_selection"] = {"rule": "cv", "candidates": [
        {"order": 1, "horizon": 10, "score": 60.0}], "selected": {"order": 1, "horizon": 10}}
    assert _order_scored(model)
    model.info["order_selection"] = {"rule": "given"}
    assert not _order_scored(model)


def test_long_traces_are_drawn_as_their_min_max_band_with_a_note():
    pytest.importorskip("matplotlib")
    from subid.evaluation.plot import MAX_TRACE_POINTS
    n = 50_001
    t = np.arange(n) * 0.01
    y = np.sin(t) + np.where(np.arange(n) == 33_333, 9.0, 0.0)     # one spike
    u = np.cos(0.3 * t)
    fig = subid.plot.data_overview(subid.IOData(u, y, dt=0.01))
    band = fig.axes[-1].collections[-1]
    top = np.concatenate([p.vertices[:, 1] for p in band.get_paths()])
    assert np.isclose(top.max(), y.max()) and np.isclose(top.min(), y.min())
    assert len(top) <= 2 * MAX_TRACE_POINTS + 8
    assert any("samples per trace" in text.get_text() for text in fig.texts)
    short = subid.plot.data_overview(subid.IOData(u[:500], y[:500], dt=0.01))
    assert not short.texts and short.axes[-1].get_lines()
    true = subid.systems.random_system(2, 1, 1, seed=4)
    data = subid.systems.simulate_data(true, n, seed=5)
    fig = subid.plot.compare(data, {"true": true})
    measured, model = fig.axes[0].collections[:2]
    assert measured.get_label() == "measured" and measured.get_zorder() > model.get_zorder()
    assert not np.any(np.asarray(measured.get_facecolor()).reshape(-1, 4)[:, 3] > 0)  # outlined
    assert np.all(np.asarray(model.get_facecolor()).reshape(-1, 4)[:, 3] > 0)         # filled


def test_log_axes_are_labelled_in_plain_text():
    from subid.evaluation.figures._common import _decade_label
    assert [_decade_label(v) for v in (0.01, 1.0, 1e3, 2.0, 0.0)] == \
        ["10\u207b\u00b2", "10\u2070", "10\u00b3", "2", ""]


def test_residual_correlations_from_lag_products_equal_the_direct_sums():
    from subid.evaluation.residuals import correlations
    rng = np.random.default_rng(8)
    e, u = rng.standard_normal((700, 2)), rng.standard_normal((700, 3))
    ranges = [(0, 300), (300, 700)]
    for parts in (None, ranges):
        out = correlations(e, u, max_lag=6, ranges=parts)
        e0, u0 = e - e.mean(axis=0), u - u.mean(axis=0)

        def r(a, b, tau, blocks=parts or [(0, 700)]):    # sum_t a(t) b(t - tau) / N
            return sum(sum(a[t] * b[t - tau] for t in range(max(s, s + tau), min(f, f + tau)))
                       for s, f in blocks) / 700          # inside each experiment
        auto = [r(e0[:, 1], e0[:, 1], tau) for tau in range(7)]
        np.testing.assert_allclose(out["auto"][1], np.array(auto) / auto[0], atol=1e-12)
        cross = [r(e0[:, 0], u0[:, 2], tau) for tau in range(-6, 7)]
        scale = np.sqrt(e0[:, 0] @ e0[:, 0] / 700 * r(u0[:, 2], u0[:, 2], 0))
        np.testing.assert_allclose(out["cross"][0, 2], np.array(cross) / scale, atol=1e-12)
