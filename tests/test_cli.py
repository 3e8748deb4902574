"""End-to-end tests of the ``subid`` command line, in-process and once as a program."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import runpy
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("click")

import subid  # noqa: E402
from subid import datasets
from subid.cli import commands as cli
from subid.cli import demo  # noqa: E402
from subid.cli.commands import main  # noqa: E402
from subid.io.interop import load_mat  # noqa: E402
from test_report import PLOT_SECTIONS, check_png, parse  # noqa: E402


@pytest.fixture(scope="module")
def dryer_csv(tmp_path_factory):
    """The bundled dryer record as a CSV file with a header, as a user would have it."""
    d = datasets.load("dryer")
    path = tmp_path_factory.mktemp("data") / "dryer.csv"
    np.savetxt(path, np.column_stack([d.t, d.u, d.y]), delimiter=",",
               header="t,voltage,temperature", comments="", fmt="%.17g")
    return str(path)


@pytest.fixture(scope="module")
def dryer_inputs_csv(tmp_path_factory):
    d = datasets.load("dryer")
    path = tmp_path_factory.mktemp("data") / "u.csv"
    np.savetxt(path, np.column_stack([d.t, d.u]), delimiter=",", header="t,voltage",
               comments="", fmt="%.17g")
    return str(path)


def run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _summary_value(out: str, key: str) -> float:
    return float(re.search(rf"{key} (-?[\d.]+)", out).group(1))


def _check_report(path, sections=PLOT_SECTIONS):
    p = parse(open(path, encoding="utf-8").read())
    for sid in ("summary", *sections, "matrices"):
        assert sid in p.images, f"{path}: no section {sid}"
    for sid in sections:
        assert p.images[sid], f"{path}: section {sid} has no image"
        for src in p.images[sid]:
            check_png(src)
    assert p.external == []
    return p


# ---------------------------------------------------------------------------
# identify
# ---------------------------------------------------------------------------
@pytest.mark.slow
def test_identify_end_to_end_from_a_csv_file(dryer_csv, tmp_path, capsys):
    out = tmp_path / "out"
    code, stdout, stderr = run(capsys, "identify", dryer_csv, "--inputs", "voltage",
                               "--outputs", "temperature", "--dt", "0.08", "--method", "moesp",
                               "--validate", "0.3", "--out", out)
    assert code == 0, stderr
    assert sorted(os.listdir(out)) == ["model.json", "report.html", "summary.json"]
    model = subid.StateSpace.load(out / "model.json")
    # the model is the library's, and loads back equal
    data = subid.read(dryer_csv, inputs="voltage", outputs="temperature", dt=0.08).detrend()
    est, val = data.split(0.7)
    ref = subid.moesp(est)
    assert model.allclose(ref, rtol=1e-12, atol=1e-12)
    assert model.input_names == ("voltage",) and model.output_names == ("temperature",)
    # the printed fit % is subid.fit_percent
    assert _summary_value(stdout, "estimation") == round(subid.fit_percent(model, est)[0], 2)
    assert _summary_value(stdout, "validation") == round(subid.fit_percent(model, val)[0], 2)
    assert f"order       {ref.order}" in stdout
    assert "stable      yes" in stdout and re.search(r"time\s+[\d.]+ s", stdout)
    assert "poles" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fit_validation"][0] == pytest.approx(subid.fit_percent(model, val)[0],
                                                         abs=1e-12)
    assert summary["order"] == model.order and summary["method"] == "moesp"
    _check_report(out / "report.html")
    info = model.info["data"]
    assert info["detrend"] == "constant"
    np.testing.assert_allclose(info["y_offset"], data.y_offset)


@pytest.mark.slow
def test_identify_dataset_without_validation_in_hz(tmp_path, capsys):
    out = tmp_path / "ls"
    code, stdout, stderr = run(capsys, "identify", "dataset:ballbeam", "--method", "ls",
                               "--order", "2:6", "--validate", "0", "--frequency-unit", "Hz",
                               "--out", out)
    assert code == 0, stderr
    model = subid.StateSpace.load(out / "model.json")
    ref = subid.ls_subspace(datasets.load("ballbeam").detrend(), [2, 3, 4, 5, 6])
    assert model.allclose(ref, rtol=1e-12, atol=1e-12)
    assert "validation — (--validate 0)" in stdout
    text = (out / "report.html").read_text()
    assert "frequency in Hz" in text
    _check_report(out / "report.html")


def test_identify_quiet_prints_nothing(tmp_path, capsys):
    code, stdout, stderr = run(capsys, "identify", "dataset:dryer", "--method", "n4sid",
                               "--order", "3", "--out", tmp_path / "q", "--quiet",
                               "--no-report")
    assert code == 0 and stdout == "" and stderr == ""
    assert sorted(os.listdir(tmp_path / "q")) == ["model.json", "summary.json"]


# ---------------------------------------------------------------------------
# every registered method is reachable
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_csv(tmp_path_factory):
    true = subid.systems.seed001_system(dt=0.1)
    data = subid.systems.simulate_data(true, 600, seed=7, output_snr_db=40)
    path = tmp_path_factory.mktemp("data") / "small.csv"
    np.savetxt(path, np.column_stack([data.t, data.u, data.y]), delimiter=",",
               header="t,u1,u2,y1,y2", comments="", fmt="%.17g")
    return str(path)


@pytest.mark.parametrize("name", list(cli.METHODS))
@pytest.mark.slow
def test_every_registered_method_is_reachable(name, small_csv, tmp_path, capsys):
    spec = cli.METHODS[name]
    command = "identify" if spec.kind == "batch" else "track"
    args = [command, small_csv, "--inputs", "u1,u2", "--outputs", "y1,y2", "--time", "t",
            "--method", name, "--order", "3", "--out", tmp_path / name]
    code, stdout, stderr = run(capsys, *args)
    if not spec.available():
        assert code == 2
        assert f"method {name} is not available in this version" in stderr
        return
    assert code == 0, stderr
    model = subid.StateSpace.load(tmp_path / name / "model.json")
    assert model.order == 3 or spec.supports("polynomial")     # their order is a structure
    assert (model.dt == 0) == (spec.time == "continuous")
    _check_report(tmp_path / name / "report.html")


def test_a_missing_method_module_is_a_clear_error(monkeypatch, tmp_path, capsys):
    gone = dataclasses.replace(cli.METHODS["ct"], module="subid._no_such_module")
    monkeypatch.setitem(cli.METHODS, "ct", gone)
    code, stdout, stderr = run(capsys, "identify", "dataset:dryer", "--method", "ct",
                               "--out", tmp_path / "x")
    assert code == 2
    assert stderr.startswith("subid: error: method ct is not available in this version")
    assert len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert not (tmp_path / "x").exists()
    code, _, stderr = run(capsys, "methods")
    assert code == 0


# ---------------------------------------------------------------------------
# track
# ---------------------------------------------------------------------------
@pytest.mark.slow
def test_track_checkpoints_resume_and_convergence_report(tmp_path, capsys):
    out = tmp_path / "run"
    code, stdout, stderr = run(capsys, "track", "dataset:dryer", "--method", "recursive",
                               "--order", "4", "--checkpoint-every", "300",
                               "--keep-checkpoints", "0", "--out", out)
    assert code == 0, stderr
    ckpts = sorted(f for f in os.listdir(out / "checkpoints") if not f.endswith("trace.npz"))
    assert ckpts == [f"checkpoint-{k:010d}.npz" for k in (300, 600, 900, 1000)]
    final = subid.StateSpace.load(out / "model.json")
    data = datasets.load("dryer").detrend()
    rs = subid.RecursiveSubspace(4, 1, 1, dt=0.08).update(data.u, data.y)
    assert final.allclose(rs.model, rtol=1e-9, atol=1e-10)       # chunking changes nothing
    # the innovation form is kept when the channels are renamed (K and noise_cov were
    # dropped while info still described them)
    np.testing.assert_allclose(final.K, rs.model.K, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(final.noise_cov, rs.model.noise_cov, rtol=1e-9)
    fit = subid.fit_percent(final, data)[0]
    assert _summary_value(stdout, "fit %      ") == round(fit, 2)
    p = _check_report(out / "report.html", PLOT_SECTIONS + ("convergence",))
    assert p.images["convergence"]
    with np.load(out / "history.npz") as h:
        assert h["sample"][-1] == 1000 and h["poles_re"].shape[1] == 4
        full_samples = h["sample"].copy()
    # resume from the middle: the same final model and the same history
    resumed = tmp_path / "resumed"
    code, stdout, stderr = run(capsys, "track", "dataset:dryer", "--method", "recursive",
                               "--resume", out / "checkpoints" / "checkpoint-0000000600.npz",
                               "--out", resumed)
    assert code == 0, stderr
    assert "600 already seen, 400 processed now" in stdout
    again = subid.StateSpace.load(resumed / "model.json")
    assert again.allclose(final, rtol=1e-10, atol=1e-12)
    with np.load(resumed / "history.npz") as h:
        np.testing.assert_array_equal(h["sample"], full_samples)
    # keep only the last N periodic checkpoints
    code, _, _ = run(capsys, "track", "dataset:dryer", "--order", "2", "--checkpoint-every",
                     "200", "--keep-checkpoints", "2", "--out", tmp_path / "k", "-q",
                     "--no-report")
    assert code == 0 and not (tmp_path / "k" / "report.html").exists()
    kept = sorted(f for f in os.listdir(tmp_path / "k" / "checkpoints")
                  if not f.endswith("trace.npz"))
    assert kept == [f"checkpoint-{k:010d}.npz" for k in (800, 1000)]


def test_track_resume_errors(tmp_path, capsys):
    bogus = tmp_path / "bogus.npz"
    bogus.write_bytes(b"not a checkpoint")
    code, _, stderr = run(capsys, "track", "dataset:dryer", "--resume", bogus, "--out",
                          tmp_path / "o")
    assert code == 2 and "bogus.npz" in stderr and "Traceback" not in stderr
    code, _, stderr = run(capsys, "track", "dataset:dryer", "--out", tmp_path / "o")
    assert code == 2 and "--order is required" in stderr


@pytest.mark.slow
def test_progress_bar_only_on_a_terminal_and_not_with_quiet(tmp_path, capsys, monkeypatch):
    args = ["track", "dataset:dryer", "--order", "2", "--checkpoint-every", "0", "--no-report"]
    code, _, stderr = run(capsys, *args, "--out", tmp_path / "a")
    assert code == 0 and "sample" not in stderr                 # not a terminal
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    code, _, stderr = run(capsys, *args, "--out", tmp_path / "b")
    assert code == 0 and "recursive:" in stderr and "/1000" in stderr
    code, stdout, stderr = run(capsys, *args, "--out", tmp_path / "c", "--quiet")
    assert code == 0 and stderr == "" and stdout == ""


# ---------------------------------------------------------------------------
# simulate, compare, convert
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def identified(dryer_csv, tmp_path_factory):
    out = tmp_path_factory.mktemp("ident")
    assert main(["identify", dryer_csv, "--inputs", "voltage", "--outputs", "temperature",
                 "--dt", "0.08", "--method", "n4sid", "--order", "2", "--out", str(out), "-q"]) == 0
    return out / "model.json"


@pytest.mark.slow
def test_simulate_writes_the_model_output_in_original_units(identified, dryer_inputs_csv,
                                                             tmp_path, capsys):
    target = tmp_path / "y.csv"
    code, stdout, stderr = run(capsys, "simulate", identified, "--input", dryer_inputs_csv,
                               "--out", target)
    assert code == 0, stderr
    model = subid.StateSpace.load(identified)
    table = np.genfromtxt(target, delimiter=",", names=True)
    assert table.dtype.names == ("time", "voltage", "temperature")
    raw = datasets.load("dryer")
    info = model.info["data"]
    expected = model.simulate(raw.u - info["u_offset"])[:, 0] + info["y_offset"][0]
    np.testing.assert_allclose(table["temperature"], expected, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(table["time"], raw.t, atol=1e-12)
    code, _, _ = run(capsys, "simulate", identified, "--input", dryer_inputs_csv,
                     "--no-offsets", "--out", tmp_path / "z.npz")
    with np.load(tmp_path / "z.npz") as z:
        np.testing.assert_allclose(z["y"], model.simulate(raw.u), rtol=1e-13, atol=1e-13)


def test_linear_detrending_is_said_everywhere_downstream(dryer_csv, dryer_inputs_csv,
                                                        tmp_path, capsys):
    """--detrend linear removes lines, functions of the record's time, not an operating
    point: simulate with offsets refuses (it fed the raw input to the model of detrended
    data, and the output was in neither units), with --no-offsets it simulates; the
    report, the python and MATLAB code say that no operating point applies."""
    out = tmp_path / "lin"
    code, _, err = run(capsys, "identify", dryer_csv, "--inputs", "voltage", "--outputs",
                       "temperature", "--dt", "0.08", "--method", "n4sid", "--order", "2",
                       "--detrend", "linear", "--out", out, "-q")
    assert code == 0, err
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "No operating point: the model relates deviations from the straight lines" in html
    assert "% the model relates deviations from the straight lines" in html
    code, _, err = run(capsys, "simulate", out / "model.json", "--input", dryer_inputs_csv,
                       "--out", tmp_path / "y.csv")
    assert code == 2 and "--detrend linear" in err and "--no-offsets" in err
    assert len(err.strip().splitlines()) == 1
    code, _, err = run(capsys, "simulate", out / "model.json", "--input", dryer_inputs_csv,
                       "--no-offsets", "--out", tmp_path / "y.csv")
    assert code == 0, err
    code, _, err = run(capsys, "convert", out / "model.json", "--to", "scipy", "--out",
                       tmp_path / "m.py")
    assert code == 0, err
    assert "# The model relates deviations from the straight lines" in \
        (tmp_path / "m.py").read_text()


@pytest.mark.slow
def test_compare_prints_the_fit_table_and_writes_the_overlay(identified, tmp_path, capsys):
    other = tmp_path / "moesp"
    assert main(["identify", "dataset:dryer", "--method", "moesp", "--out", str(other),
                 "-q"]) == 0
    code, stdout, stderr = run(capsys, "compare", identified, other / "model.json", "--data",
                               "dataset:dryer", "--out", tmp_path / "cmp")
    assert code == 0, stderr
    data = datasets.load("dryer").detrend()
    rows = [ln.split() for ln in stdout.splitlines()[2:4]]
    for row, path in zip(rows, (identified, other / "model.json")):
        fit = subid.fit_percent(subid.StateSpace.load(path), data)[0]
        assert float(row[-1]) == round(fit, 2)
    assert (tmp_path / "cmp" / "compare.png").read_bytes().startswith(b"\x89PNG")
    p = parse((tmp_path / "cmp" / "compare.html").read_text())
    check_png(p.images["compare"][0])


def test_convert_to_every_target(identified, tmp_path, capsys):
    model = subid.StateSpace.load(identified)
    base = tmp_path / "m.json"
    shutil.copy(identified, base)
    code, _, stderr = run(capsys, "convert", base, "--to", "dt=0.04")
    assert code == 0, stderr
    resampled = subid.StateSpace.load(tmp_path / "m_dt0.04.json")
    assert resampled.dt == 0.04
    assert resampled.allclose(model.to_continuous().to_discrete(0.04), rtol=1e-12, atol=1e-12)
    assert run(capsys, "convert", base, "--to", "ct", "--method", "bilinear")[0] == 0
    ct = subid.StateSpace.load(tmp_path / "m_ct.json")
    assert ct.allclose(model.to_continuous("bilinear"), rtol=1e-12, atol=1e-12)
    assert run(capsys, "convert", tmp_path / "m_ct.json", "--to", "dt=0.08", "--method",
               "bilinear")[0] == 0
    assert subid.StateSpace.load(tmp_path / "m_ct_dt0.08.json").allclose(model, atol=1e-10)
    assert run(capsys, "convert", base, "--to", "mat")[0] == 0
    # the way back does not replace the JSON model beside it unasked (its info would go)
    code, _, stderr = run(capsys, "convert", tmp_path / "m.mat", "--to", "json")
    assert code == 2 and "exists" in stderr and "--out" in stderr
    assert run(capsys, "convert", base, "--to", "mat")[0] == 2      # m.mat exists now
    assert load_mat(tmp_path / "m.mat").allclose(model, rtol=0, atol=0)
    assert run(capsys, "convert", tmp_path / "m.mat", "--to", "json", "--out",
               tmp_path / "back.json")[0] == 0
    assert subid.StateSpace.load(tmp_path / "back.json").allclose(model, rtol=0, atol=0)
    control = pytest.importorskip("control")
    code, stdout, _ = run(capsys, "convert", base, "--to", "control")
    assert code == 0 and "StateSpace" in stdout
    ns = runpy.run_path(str(tmp_path / "m_control.py"))
    assert isinstance(ns["sys"], control.StateSpace)
    assert subid.StateSpace.from_control(ns["sys"]).allclose(model, rtol=0, atol=0)
    assert run(capsys, "convert", base, "--to", "scipy")[0] == 0
    ns = runpy.run_path(str(tmp_path / "m_scipy.py"))
    assert subid.StateSpace.from_scipy(ns["sys"]).allclose(model, rtol=0, atol=0)
    code, _, stderr = run(capsys, "convert", base, "--to", "laplace")
    assert code == 2 and "laplace" in stderr


# ---------------------------------------------------------------------------
# demo and gallery
# ---------------------------------------------------------------------------
@pytest.mark.slow
def test_demo_alias_writes_reports_and_an_index_linking_them(tmp_path, capsys, monkeypatch):
    out = tmp_path / "demo"
    # ``python -m subid.cli.demo ARGS`` is ``subid demo ARGS``
    monkeypatch.setattr(sys, "argv", ["subid.cli.demo", "--datasets", "dryer,robot_arm", "--methods",
                                      "ls,n4sid", "--jobs", "2", "--out", str(out)])
    with pytest.raises(SystemExit) as exit_info, warnings.catch_warnings():
        # runpy notes that subid.cli.demo is already imported: harmless here
        warnings.simplefilter("ignore", RuntimeWarning)
        runpy.run_module("subid.cli.demo", run_name="__main__", alter_sys=False)
    code = exit_info.value.code
    stdout = capsys.readouterr().out
    assert code == 0
    assert "dryer: ls n=" in stdout and "wrote" in stdout
    index = parse((out / "index.html").read_text())
    reports = sorted(f for f in os.listdir(out) if f.endswith(".html") and f != "index.html")
    assert reports == ["dryer.html", "robot_arm.html"]
    assert sorted(index.links) == reports
    for name in reports:
        _check_report(out / name)
    gallery = (out / "gallery.md").read_text()
    assert "| dryer |" in gallery and "| robot_arm |" in gallery
    summary = json.loads((out / "summary.json").read_text())
    row = next(r for r in summary["rows"] if r["dataset"] == "dryer" and r["method"] == "ls")
    d = datasets.load("dryer").detrend()
    est, val = d.split(0.7)
    m = subid.ls_subspace(est)
    assert row["order"] == m.order
    assert row["fit_val"][0] == pytest.approx(subid.fit_percent(m, val)[0], abs=1e-12)


@pytest.mark.slow
def test_demo_run_in_process_is_silent_and_checks_names(tmp_path, capsys):
    result = demo.run(str(tmp_path / "d"), datasets=["dryer"], methods=["moesp"])
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    assert result["reports"] == [str(tmp_path / "d" / "dryer.html")]
    assert parse((tmp_path / "d" / "index.html").read_text()).links == ["dryer.html"]
    code, _, stderr = run(capsys, "demo", "--datasets", "dryer,nope", "--out", tmp_path / "e")
    assert code == 2 and "unknown dataset(s) nope" in stderr
    code, _, stderr = run(capsys, "demo", "--methods", "svd", "--out", tmp_path / "e")
    assert code == 2 and "unknown batch method 'svd'" in stderr


@pytest.mark.slow
def test_gallery_command_writes_the_table(tmp_path, capsys):
    target = tmp_path / "docs" / "gallery.md"
    code, stdout, stderr = run(capsys, "gallery", "--datasets", "dryer", "--out", target)
    assert code == 0, stderr
    text = target.read_text()
    assert demo.GALLERY_COMMAND in text
    d = datasets.load("dryer").detrend()
    est, val = d.split(0.7)
    for fn in (subid.ls_subspace, subid.moesp, subid.n4sid):
        m = fn(est)
        assert f"{subid.fit_percent(m, val)[0]:.1f} ({m.order})" in text


# ---------------------------------------------------------------------------
# user errors
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def bad_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("bad")
    (root / "text.csv").write_text("t,u,y\n0,1,2\n1,abc,3\n2,1,1\n")
    (root / "empty.csv").write_text("")
    (root / "good.csv").write_text("t,u,y\n" + "".join(f"{k},{k % 3},{k % 5}\n"
                                                         for k in range(50)))
    return root


@pytest.mark.parametrize("case, args, needle", [
    ("wrong column", ["good.csv", "--inputs", "u9", "--outputs", "y"], "unknown column name 'u9'"),
    ("missing file", ["nosuch.csv", "--inputs", "u", "--outputs", "y"], "no such file"),
    ("non-numeric cell", ["text.csv", "--inputs", "u", "--outputs", "y"], "'abc' is not a number"),
    ("empty file", ["empty.csv", "--inputs", "u", "--outputs", "y"], "is empty"),
])
def test_user_errors_are_one_line_exit_2(case, args, needle, bad_files, tmp_path, capsys,
                                         monkeypatch):
    monkeypatch.chdir(bad_files)
    code, stdout, stderr = run(capsys, "identify", *args, "--out", tmp_path / "o")
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("subid: error: ") and args[0] in lines[0] and needle in lines[0]
    assert "Traceback" not in stderr
    code, _, stderr = run(capsys, "identify", *args, "--out", tmp_path / "o", "--debug")
    assert code == 2 and "Traceback" in stderr and needle in stderr


def test_model_file_errors_name_the_file(tmp_path, capsys):
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    for args in (["simulate", broken, "--input", "x.csv", "--out", tmp_path / "y.csv"],
                 ["convert", broken, "--to", "ct"],
                 ["compare", broken, "--data", "dataset:dryer"]):
        code, _, stderr = run(capsys, *args)
        assert code == 2 and "broken.json" in stderr and "Traceback" not in stderr


def test_errors_after_reading_name_the_data_file(bad_files, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(bad_files)
    code, _, stderr = run(capsys, "identify", "good.csv", "--inputs", "u", "--outputs", "y",
                          "--order", "30", "--out", tmp_path / "o")
    # (a first line may warn that no --dt was given: time is counted in samples)
    assert code == 2 and stderr.splitlines()[-1].startswith("subid: error: good.csv: ")


# ---------------------------------------------------------------------------
# help, and the installed program
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("command", [[], ["identify"], ["track"], ["simulate"], ["compare"],
                                     ["convert"], ["demo"], ["gallery"], ["methods"]])
def test_help_of_every_command_has_an_example(command, capsys):
    code, stdout, _ = run(capsys, *command, "--help")
    assert code == 0
    assert "Example" in stdout and "subid " in stdout.split("Example")[1]


def _program():
    exe = shutil.which("subid", path=os.path.dirname(sys.executable))
    return [exe] if exe else [sys.executable, "-m", "subid"]


@pytest.mark.slow
def test_installed_program_end_to_end(tmp_path):
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([*_program(), "identify", "dataset:dryer", "--method", "ls",
                           "--out", str(tmp_path / "o")], capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    model = subid.StateSpace.load(tmp_path / "o" / "model.json")
    est, val = datasets.load("dryer").detrend().split(0.7)
    assert _summary_value(proc.stdout, "validation") == round(
        subid.fit_percent(model, val)[0], 2)
    proc = subprocess.run([*_program(), "identify", str(tmp_path / "missing.csv"), "--inputs",
                           "u", "--outputs", "y", "--out", str(tmp_path / "p")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"subid: error: no such file: {tmp_path / 'missing.csv'}"


@pytest.mark.slow
def test_track_adaptive_defaults_to_no_detrending(tmp_path):
    """Continuous-time methods model the response from rest: removing the
    record's means biased the adaptive identifier (pole error 0.98)."""
    import subid as sd
    from subid.experiments.seed000 import multisine
    true = sd.systems.seed000_system()
    t = np.arange(0.0, 30.0, 0.001)
    u = multisine(t, 2)
    y = true.simulate(u, t=t, hold="foh")
    path = tmp_path / "ct.csv"
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u1,u2,y1,y2",
               comments="")
    out = tmp_path / "run"
    assert cli.main(["--quiet", "track", str(path), "--inputs", "u1,u2", "--outputs", "y1,y2",
                     "--time", "t", "--method", "adaptive", "--order", "4",
                     "--out", str(out)]) in (0, None)
    model = sd.StateSpace.load(out / "model.json")
    assert sd.pole_error(model, true) < 1e-3
    assert model.info["data"]["detrend"] == "none"


def test_track_reports_convergence_and_warns(tmp_path, capsys):
    """Issue 12: an online model that has not converged says so (warning on
    stderr, 'converged NO: ...' in the summary); the converged fit is the
    final model's on the last third of the record."""
    from subid.experiments.seed000 import multisine
    true = subid.systems.seed000_system()
    t = np.arange(0.0, 2.0, 0.001)                   # too short for the (B, D) stage
    u = multisine(t, 2)
    y = true.simulate(u, t=t, hold="foh")
    path = tmp_path / "short.csv"
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u1,u2,y1,y2",
               comments="")
    code, stdout, stderr = run(capsys, "track", path, "--inputs", "u1,u2", "--outputs",
                               "y1,y2", "--time", "t", "--method", "adaptive", "--order", "4",
                               "--no-report", "--out", tmp_path / "run")
    assert code == 0, stderr
    assert "converged   NO: the (B, D) stage has not started" in stdout
    assert "not converged" in stderr
    code, stdout, stderr = run(capsys, "track", "dataset:dryer", "--order", "4",
                               "--checkpoint-every", "0", "--no-report", "--out",
                               tmp_path / "dryer")
    assert code == 0 and "converged   yes" in stdout and "on its last third" in stdout
    model = subid.StateSpace.load(tmp_path / "dryer" / "model.json")
    assert model.info["bd_method"] == "simulation" and len(model.info["fit_last_third"]) == 1


def test_a_time_column_not_given_is_named_in_the_one_sampling_warning(dryer_csv, tmp_path,
                                                                      capsys):
    """dryer.csv has a column 't': identify without --dt or --time says once, in one
    line, that time is counted in samples and that --time t would take dt from it."""
    code, _, stderr = run(capsys, "identify", dryer_csv, "--inputs", "voltage", "--outputs",
                          "temperature", "--method", "n4sid", "--order", "2", "--no-report",
                          "--out", tmp_path / "o")
    lines = [line for line in stderr.splitlines() if "dt = 1" in line]
    assert code == 0 and len(lines) == 1
    assert "The column 't' looks like time stamps: add --time t" in lines[0]
