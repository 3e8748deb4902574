"""Package metadata: licence file and SPDX expression, typing marker, extras, URLs of
the README's images, and what `make demo` installs."""

import pathlib
import re
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _project():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_license_is_bsd3_in_current_pyproject_form():
    project = _project()
    assert project["license"] == "BSD-3-Clause"           # SPDX string, not a table
    assert project["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License") and "Neither the name" in text
    assert not any("License ::" in c for c in project["classifiers"])   # superseded by SPDX


def test_typed_marker_is_shipped():
    assert (ROOT / "src" / "subid" / "py.typed").exists()
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "py.typed" in data["tool"]["setuptools"]["package-data"]["subid"]


def test_extras_for_docs_and_notebooks():
    extras = _project()["optional-dependencies"]
    assert any(d.startswith("mkdocs-material") for d in extras["docs"])
    assert any(d.startswith("nbclient") for d in extras["test"])


def test_make_demo_installs_only_the_plot_extra():
    make = (ROOT / "Makefile").read_text()
    demo = re.search(r"^demo: (\S+)", make, re.M).group(1)
    stamp = re.search(rf"^\$\({demo[2:-1]}\):.*\n((?:\t.*\n)+)", make, re.M).group(1)
    assert '-e ".[plot]"' in stamp and ".[test]" not in stamp


def test_readme_images_exist():
    text = (ROOT / "README.md").read_text()
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert images
    for ref in images:
        assert (ROOT / ref).exists(), ref
