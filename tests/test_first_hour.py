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
