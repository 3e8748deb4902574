"""One validation module, one MAT loader, one version (issue 13, items 4 and 6)."""

from __future__ import annotations

import json
import pathlib
import re
import tomllib

import numpy as np
import pytest

import subid
from subid import _validation, errors
from subid._validation import UNIFORM_RTOL, as_chunk, check_selector, is_uniform, same_period
from subid.data import IOData
from subid.io import interop
from subid.io import mat as io
from subid.model.statespace import StateSpace

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "subid"


# ---------------------------------------------------------------------------
# one uniform-grid tolerance
# ---------------------------------------------------------------------------
def test_uniform_tolerance_is_written_once():
    """No module compares sampling periods or steps with a tolerance of its own."""
    pattern = re.compile(r"(?:rtol|rel_tol)\s*=\s*1e-9\b|_?(?:UNIFORM|DT)_RTOL\s*=")
    found = [f"{p.relative_to(SRC)}:{n}" for p in sorted(SRC.rglob("*.py"))
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if pattern.search(line)]
    assert found == ["_validation.py:" + str(next(
        n for n, line in enumerate((SRC / "_validation.py").read_text().splitlines(), 1)
        if line.startswith("UNIFORM_RTOL =")))]


def test_uniform_and_same_period_at_the_tolerance():
    steps = np.full(10, 0.1)
    assert is_uniform(steps)
    assert is_uniform(steps * (1 + 0.5 * UNIFORM_RTOL * (np.arange(10) % 2)))
    assert not is_uniform(steps * (1 + 3 * UNIFORM_RTOL * (np.arange(10) % 2)))
    assert not is_uniform(np.zeros(0))
    assert same_period(0.1 * (1 + 0.5 * UNIFORM_RTOL), 0.1)
    assert not same_period(0.1 * (1 + 2 * UNIFORM_RTOL), 0.1)
    assert same_period(steps, 0.1) and not same_period(steps + np.r_[np.zeros(9), 1e-6], 0.1)


def test_every_consumer_uses_the_same_tolerance():
    """A record whose stamps wobble within the tolerance is uniform for IOData, the
    model's simulation, fit_percent and the metrics; beyond it, it is not."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal((50, 1))
    model = StateSpace([[0.5]], [[1.0]], [[1.0]], [[0.0]], dt=0.1)
    t_ok = 0.1 * np.arange(50) * (1 + 0.4 * UNIFORM_RTOL)
    data = IOData(u, model.simulate(u), t=t_ok)
    assert data.is_uniform and same_period(data.dt, 0.1)
    np.testing.assert_allclose(model.simulate(data), model.simulate(u))
    assert subid.fit_percent(model, data)[0] > 99.99
    t_bad = 0.1 * np.arange(50) + 0.1 * 5 * UNIFORM_RTOL * (np.arange(50) % 2)
    data_bad = IOData(u, model.simulate(u), t=t_bad)
    assert not data_bad.is_uniform
    with pytest.raises(errors.DataError):
        subid.fit_percent(model, data_bad)


# ---------------------------------------------------------------------------
# chunks and selectors of the online identifiers
# ---------------------------------------------------------------------------
def test_as_chunk_shapes_and_messages():
    assert as_chunk(np.arange(3.0), 3, "u").shape == (1, 3)           # one sample
    assert as_chunk(np.arange(3.0), 1, "u").shape == (3, 1)           # three samples
    assert as_chunk(2.0, 1, "u").shape == (1, 1)
    assert as_chunk([[1, 2], [3, 4]], 2, "u").dtype == np.float64
    with pytest.raises(errors.DataError, match="transposed"):
        as_chunk(np.zeros((2, 5)), 2, "input u")
    with pytest.raises(errors.DataError, match="1-D with 4 entries"):
        as_chunk(np.zeros(4), 3, "input u")
    with pytest.raises(errors.DataError, match="no samples"):
        as_chunk(np.zeros((0, 2)), 2, "input u")
    assert as_chunk(np.zeros((0, 2)), 2, "input u", allow_empty=True).shape == (0, 2)
    with pytest.raises(errors.DataError, match="NaN"):
        as_chunk(np.array([[1.0, np.nan]]), 2, "input u")


def test_as_chunk_copy_never_shares_the_callers_memory():
    values = np.zeros((4, 2))
    assert np.shares_memory(as_chunk(values, 2, "u"), values)         # the fast path
    assert not np.shares_memory(as_chunk(values, 2, "u", copy=True), values)
    assert not np.shares_memory(as_chunk(values[0], 2, "u", copy=True), values)


def test_online_identifiers_share_the_chunk_check():
    rs = subid.RecursiveSubspace(2, 2, 1, horizon=4)
    ai = subid.AdaptiveIdentifier(2, 2, 1, horizon=4, dt=0.01)
    for ident in (rs, ai):
        with pytest.raises(errors.DataError, match="time is axis 0: was it passed transposed"):
            ident.update(np.zeros((2, 7)), np.zeros((7, 1)))


def test_selector_checks_raise_order_error_everywhere():
    bad = np.ones((3, 7))                          # 7 columns: neither 4*1 nor 4*2
    with pytest.raises(errors.OrderError, match="columns"):
        subid.RecursiveSubspace(3, 1, 1, horizon=4, selector=bad)
    with pytest.raises(errors.OrderError, match="columns"):
        subid.AdaptiveIdentifier(3, 1, 1, horizon=4, selector=bad)
    with pytest.raises(errors.OrderError, match="exactly order rows"):
        subid.AdaptiveIdentifier(3, 1, 1, horizon=4, selector=np.ones((4, 4)))
    with pytest.raises(errors.OrderError, match="numeric"):
        check_selector([["a"]], 4, 1, [3], 3)
    with pytest.raises(errors.OrderError, match="non-finite"):
        check_selector(np.full((3, 4), np.inf), 4, 1, [3], 3)
    user = np.eye(3, 4)
    checked = check_selector(user, 4, 1, [3], 3)
    assert not np.shares_memory(checked, user)
    ai = subid.AdaptiveIdentifier(3, 1, 1, horizon=4, selector=user)
    assert user.flags.writeable and np.array_equal(ai.selector, user)


# ---------------------------------------------------------------------------
# one MAT loader
# ---------------------------------------------------------------------------
def test_read_and_model_files_share_the_validated_mat_loader(tmp_path, monkeypatch):
    """subid.read, StateSpace.from_mat and interop.load_mat all read through
    io.mat_variables (the path that validates every MAT structure before scipy)."""
    model = StateSpace([[0.5]], [[1.0]], [[2.0]], [[0.0]], dt=0.1)
    model_path = tmp_path / "model.mat"
    interop.save_mat(model, model_path)
    data_path = tmp_path / "data.mat"
    import scipy.io
    scipy.io.savemat(data_path, {"u": np.arange(20.0), "y": np.arange(20.0) ** 2})
    calls = []
    original = io.mat_variables

    def spy(path, **kwargs):
        calls.append(pathlib.Path(path).name)
        return original(path, **kwargs)

    monkeypatch.setattr(io, "mat_variables", spy)
    assert StateSpace.from_mat(model_path).allclose(model)
    assert interop.load_mat(model_path).allclose(model)
    assert subid.read(data_path, "u", "y").n_samples == 20
    assert calls == ["model.mat", "model.mat", "data.mat"]


def test_a_corrupt_model_file_is_a_file_read_error_everywhere(tmp_path):
    model = StateSpace([[0.5]], [[1.0]], [[2.0]], [[0.0]], dt=0.1)
    good = tmp_path / "model.mat"
    model.to_mat(good)
    raw = good.read_bytes()
    bad = tmp_path / "bad.mat"
    bad.write_bytes(raw[:len(raw) // 2])
    for load in (StateSpace.from_mat, interop.load_mat):
        with pytest.raises(errors.FileReadError):
            load(bad)


# ---------------------------------------------------------------------------
# one version
# ---------------------------------------------------------------------------
def test_version_has_one_source():
    from subid._version import __version__
    assert subid.__version__ == __version__
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" not in project["project"]
    assert "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {
        "attr": "subid._version.__version__"}
    literal = re.compile(re.escape(repr(__version__)) + "|" + re.escape(f'"{__version__}"'))
    elsewhere = [str(p.relative_to(SRC)) for p in SRC.rglob("*.py")
                 if p.name != "_version.py" and literal.search(p.read_text(encoding="utf-8"))]
    assert elsewhere == []


def test_version_in_the_cli_and_the_model_files(tmp_path, capsys):
    from subid.cli.commands import main
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"subid, version {subid.__version__}"
    model = StateSpace([[0.5]], [[1.0]], [[2.0]], [[0.0]], dt=0.1)
    path = tmp_path / "m.json"
    model.save(path)
    stored = json.loads(path.read_text())
    assert stored["subid_version"] == subid.__version__ and stored["version"] == 1
    del stored["subid_version"]                       # files of earlier releases
    assert StateSpace.from_dict(stored).allclose(model)


def test_validation_module_has_no_dependency_on_the_rest():
    """_validation sits at the bottom: it imports only errors."""
    text = (SRC / "_validation.py").read_text()
    assert set(re.findall(r"^from (?:\.|subid\.)(\w*) import", text, re.M)) == {"errors"}
    assert _validation.UNIFORM_RTOL == 1e-9
