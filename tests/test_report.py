"""Tests of subid.evaluation.report: self-contained HTML with every section and embedded figures."""

from __future__ import annotations

import base64
import html.parser
import os
import re
import shutil
import subprocess
import tempfile

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import subid  # noqa: E402
from subid import systems
from subid.evaluation import report  # noqa: E402

PNG = b"\x89PNG\r\n\x1a\n"
PLOT_SECTIONS = ("data", "compare", "bode", "poles", "residuals")


class _Sections(html.parser.HTMLParser):
    """Section ids, the images and links inside each, and every external reference."""

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.images: dict[str, list[str]] = {}
        self.external: list[str] = []
        self.tags: set[str] = set()
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.add(tag)
        if tag == "section":
            self.stack.append(attrs.get("id"))
            self.images.setdefault(attrs.get("id"), [])
        for key in ("src", "href"):
            value = attrs.get(key)
            if value and re.match(r"^(https?:)?//", value):
                self.external.append(value)
        if tag == "img" and self.stack:
            self.images[self.stack[-1]].append(attrs.get("src", ""))
        if tag == "a" and attrs.get("href"):
            self.links.append(attrs["href"])

    def handle_endtag(self, tag):
        if tag == "section" and self.stack:
            self.stack.pop()


def parse(text: str) -> _Sections:
    p = _Sections()
    p.feed(text)
    return p


def check_png(src: str) -> bytes:
    assert src.startswith("data:image/png;base64,")
    raw = base64.b64decode(src.split(",", 1)[1], validate=True)
    assert raw.startswith(PNG) and len(raw) > 2000
    return raw


@pytest.fixture(scope="module")
def dryer_models():
    data = subid.datasets.load("dryer").detrend()
    est, val = data.split(0.7)
    return {"ls": subid.ls_subspace(est), "moesp": subid.moesp(est, 4)}, est, val


@pytest.fixture(scope="module")
def dryer_report(dryer_models):
    models, est, val = dryer_models
    return report.identification_report(models, est, val, title="dryer <test>",
                                        frequency_unit="Hz", seconds={"ls": 0.5},
                                        notes=["a note & more"], command="subid identify x",
                                        source="dataset:dryer")


@pytest.mark.slow
def test_report_has_every_section_with_embedded_images(dryer_report):
    p = parse(dryer_report)
    expected = [s for s in report.SECTIONS if s != "convergence"]
    assert list(p.images) == expected
    check_png(p.images["order"][0])                                        # orders chosen
    for sid in PLOT_SECTIONS:
        assert p.images[sid], f"section {sid} has no image"
        for src in p.images[sid]:
            check_png(src)
    assert p.external == []
    assert not p.tags & {"script", "link", "iframe", "object", "embed"}
    assert "dryer &lt;test&gt;" in dryer_report and "a note &amp; more" in dryer_report
    order_chart, scores_chart = p.images["order"]   # profiles, then the CV candidate scores
    check_png(scores_chart)
    check_png(order_chart)


def test_report_numbers_are_those_of_the_library(dryer_models, dryer_report):
    models, est, val = dryer_models
    for m in models.values():
        fit = subid.fit_percent(m, val)[0]
        assert f"<td>{fit:.1f}</td>" in dryer_report
        assert f"{m.A[0, 0]:.6g}" in dryer_report
    r = report.evaluate(models["ls"], est, val)
    np.testing.assert_array_equal(r["fit_validation"], subid.fit_percent(models["ls"], val))
    np.testing.assert_array_equal(r["fit_estimation"], subid.fit_percent(models["ls"], est))
    assert r["stable"] == models["ls"].is_stable()
    assert "natural frequency (Hz)" in dryer_report and "frequency (Hz)" in dryer_report


def test_report_matlab_code_rebuilds_the_model(dryer_models, dryer_report):
    m = dryer_models[0]["ls"]
    block = re.search(r"A = (\[.*?\]);", dryer_report.split('id="matrices"')[1]).group(1)
    rows = [[float(v) for v in r.split()] for r in block.strip("[]").split(";")]
    np.testing.assert_array_equal(np.array(rows), m.A)


@pytest.mark.slow
def test_online_report_adds_convergence():
    true = systems.seed001_system()
    data = systems.simulate_data(true, 1200, seed=4)
    rs = subid.RecursiveSubspace(3, 2, 2, horizon=5, history_size=40, history_stride=100)
    rs.update(data.u, data.y)
    text = report.identification_report({"recursive": rs.model}, data, history=rs.history)
    p = parse(text)
    assert list(p.images) == list(report.SECTIONS)   # the rank profile; no candidate scores
    assert len(p.images["order"]) == 1
    check_png(p.images["convergence"][0])


def test_diverging_model_is_reported_not_fatal():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(3000)
    data = subid.IOData(u, np.convolve(u, [0, 1, 0.5])[:3000], dt=0.1)
    good = subid.StateSpace([[0.0, 0.0], [1.0, 0.0]], [[1.0], [0.0]], [[1.0, 0.5]], 0, 0.1)
    unstable = subid.StateSpace([[1.8]], [[1.0]], [[1.0]], 0, 0.1)
    text = report.identification_report({"good": good, "bad": unstable}, data)
    assert 'class="bad">NO' in text
    assert "n/a" in text                                # fit of the diverging model
    r = report.evaluate(unstable, data)
    assert np.isnan(r["fit_estimation"]).all()
    p = parse(text)
    check_png(p.images["residuals"][0])                 # drawn for the good model


def test_index_page_links_and_escapes():
    text = report.index_page([{"name": "a<b", "href": "a.html", "fit": "1.0"},
                              {"name": "c", "href": "c.html", "fit": "2.0"}],
                             title="t", columns=["fit"])
    p = parse(text)
    assert p.links == ["a.html", "c.html"]
    assert "a&lt;b" in text


def test_write_html_is_atomic_and_utf8(tmp_path):
    path = tmp_path / "r.html"
    report.write_html(path, "<p>‖y − ŷ‖</p>")
    assert path.read_text(encoding="utf-8") == "<p>‖y − ŷ‖</p>"
    assert [f for f in os.listdir(tmp_path)] == ["r.html"]


def test_report_functions_never_print(dryer_models, capsys):
    models, est, val = dryer_models
    report.identification_report(models["moesp"], est, val)
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""


# ---------------------------------------------------------------------------
# headless Chromium (Debian's `chromium` package)
# ---------------------------------------------------------------------------
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _chromium(page, png, size="1200,3000"):
    profile = tempfile.mkdtemp(prefix="subid-chromium-")
    try:
        proc = subprocess.run(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0",
             f"--screenshot={png}", f"--window-size={size}", f"file://{page}"],
            capture_output=True, text=True, timeout=120)
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    console = [ln for ln in proc.stderr.splitlines() if ":CONSOLE" in ln]
    return proc, console


@pytest.mark.skipif(CHROMIUM is None, reason="headless check needs Debian's `chromium` on PATH "
                    "(apt-get install chromium); make test never installs it")
@pytest.mark.slow
def test_report_renders_in_headless_chromium_without_console_errors(dryer_report, tmp_path):
    from PIL import Image
    # the check itself must be able to fail: a page with a script error is caught
    bad = tmp_path / "bad.html"
    bad.write_text("<!DOCTYPE html><html><body><script>console.error('boom');"
                   "notDefined();</script></body></html>")
    _, console = _chromium(bad, tmp_path / "bad.png", "400,300")
    assert any("boom" in ln for ln in console) and any("notDefined" in ln for ln in console)

    page = tmp_path / "report.html"
    report.write_html(page, dryer_report)
    png = tmp_path / "report.png"
    proc, console = _chromium(page, png)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert console == []
    im = Image.open(png).convert("RGB")
    assert im.size == (1200, 3000)
    arr = np.asarray(im)
    # not blank: the heading, tables and embedded plots give many colours and dark pixels
    assert len(np.unique(arr.reshape(-1, 3), axis=0)) > 200
    assert (arr[:200].min(axis=2) < 80).mean() > 0.001     # the title is drawn
    assert (arr[600:].min(axis=2) < 250).mean() > 0.05      # figures below the summary


def test_evaluate_keeps_the_simulation_that_the_comparison_draws(dryer_models, monkeypatch):
    import gc

    from subid.evaluation.figures import time_domain
    from subid.model.fit import output_fit
    from subid.model.prediction import simulate_fit
    models, est, val = dryer_models
    m = models["ls"]
    r = report.evaluate(m, est, val)
    np.testing.assert_array_equal(r["simulated"], simulate_fit(m, val)[0])
    np.testing.assert_array_equal(output_fit(val, r["simulated"]), r["fit_validation"])
    assert report.evaluate(m, est)["simulated"].shape == est.y.shape    # no validation part
    fig = subid.plot.compare(val, {"ls": m}, simulated={"ls": r["simulated"]})
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert f"ls: fit {r['fit_validation'][0]:.1f} %" in legend

    def simulated_again(*args, **kwargs):
        raise AssertionError("the comparison simulated the model again")

    monkeypatch.setattr(time_domain, "simulated_output", simulated_again)
    states = []
    text = report.identification_report({"ls": m}, est, val, fits={"ls": r},
                                        progress=lambda s: states.append(gc.isenabled()))
    check_png(parse(text).images["compare"][0])
    # the collector paused while the report is built, then restored as it was
    assert states and not any(states) and gc.isenabled()


def test_report_leaves_the_garbage_collector_as_it_was(dryer_models):
    import gc
    models, est, val = dryer_models

    def stop(section):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        report.identification_report({"ls": models["ls"]}, est, val, progress=stop)
    assert gc.isenabled()
    gc.disable()
    try:
        with pytest.raises(KeyboardInterrupt):
            report.identification_report({"ls": models["ls"]}, est, val, progress=stop)
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_figure_fit_is_fit_percent_on_merged_records():
    """The legends' fit (figures/_common.percent_fit) is subid.fit_percent's: each
    experiment of a merged record against its own mean; NaN, not an error, for an
    output that is constant or a simulation that is not finite."""
    from subid.evaluation.figures._common import percent_fit
    from subid.model.fit import output_fit
    true = systems.seed001_system()
    a = systems.simulate_data(true, 400, seed=1, output_snr_db=20)
    b = systems.simulate_data(true, 300, seed=2, output_snr_db=20)
    b = subid.IOData(b.u, b.y + 5.0, dt=b.dt)            # another operating point
    data = subid.merge([a, b])
    model = subid.moesp(data, 3, horizon=10)
    y_hat = subid.model.prediction.simulate_fit(model, data)[0]
    np.testing.assert_allclose(percent_fit(data, y_hat), subid.fit_percent(model, data),
                               rtol=1e-12)
    constant = subid.IOData(a.u, np.column_stack([a.y[:, 0], np.ones(a.n_samples)]), dt=a.dt)
    guess = np.column_stack([a.y[:, 0] + 0.1, np.zeros(a.n_samples)])
    fits = percent_fit(constant, guess)
    assert np.isfinite(fits[0]) and np.isnan(fits[1])
    with pytest.raises(subid.errors.DataError, match="constant"):
        output_fit(constant, guess)
    guess[5, 0] = np.inf
    assert np.isnan(percent_fit(constant, guess)).all()
    with pytest.raises(subid.errors.OptionError):
        output_fit(constant, guess, constant="zero")


def test_figures_encoded_aside_give_the_same_report(dryer_models, monkeypatch):
    """The report's PNGs encoded on its worker thread while the next figures are drawn
    (report._figures_aside): the same HTML, byte for byte, as encoding each figure in
    turn (the builder without the worker), and no placeholder left in it."""
    import re
    models, est, val = dryer_models
    kwargs = dict(title="dryer", seconds={"ls": 0.5}, source="dataset:dryer")
    aside = report.identification_report(models, est, val, **kwargs)
    in_turn = report.identification_report.__wrapped__.__wrapped__(models, est, val, **kwargs)
    assert report._ENCODER.get() is None
    assert "\x00" not in aside and aside.count("data:image/png;base64,") >= 8

    def unstamped(text):
        return re.sub(r"<p class=\"meta\">[^<]*</p>", "", text)
    assert unstamped(aside) == unstamped(in_turn)


def test_report_with_a_validation_record_of_its_own_and_matlab_delays():
    """A validation record of its own (both records from t = 0, MATLAB's ze/zv of two
    experiments) failed with 'time stamps t are not increasing at row 600': the data
    overview draws it after the estimation record now. The MATLAB code of a model with
    input delays names them ('InputDelay'); it rebuilt a model without them."""
    true = systems.seed001_system()
    est = systems.simulate_data(true, 600, seed=1, output_snr_db=20)
    val = systems.simulate_data(true, 400, seed=2, output_snr_db=20)
    text = report.identification_report({"n4sid": subid.n4sid(est, 3)}, est, val)
    assert "data" in parse(text).images
    delayed = subid.n4sid(est, 3, input_delay=[2, 0])
    text = report.identification_report({"n4sid": delayed}, est, val)
    assert "&#x27;InputDelay&#x27;, [2 0]" in text or "'InputDelay', [2 0]" in text
