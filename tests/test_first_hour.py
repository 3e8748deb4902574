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
from subid.methods.dt._selection import AUTO_ORDER_RULE

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _flat(text: str) -> str:
    """Whitespace collapsed, Markdown emphasis and line breaks removed."""
    return " ".join(text.replace("`", "").split())


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
    for doc in ("README.md", "docs/cli.md", "examples/quickstart.ipynb"):
        assert rule in _flat((ROOT / doc).read_text(encoding="utf-8")), doc
    # the phrase is made from the constants the selection uses
    from subid.methods.dt import _selection
    assert f"1..{_selection.MAX_ORDER}" in rule
    assert f"{100 * _selection.RELATIVE_TOLERANCE:g} %" in rule
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
        "unstable": (_row(stable=False), "stability=enforce", "poles"),
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
