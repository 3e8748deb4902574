"""The README's quick start runs as written."""

import pathlib
import re

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_quick_start_runs(tmp_path, monkeypatch):
    text = README.read_text()
    block = re.search(r"## Quick start\s+```python\n(.*?)```", text, re.S).group(1)
    assert len(block.strip().splitlines()) <= 12
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(block, "README quick start", "exec"), namespace)
    model, true = namespace["model"], namespace["true"]
    import subid
    assert subid.markov_error(model, true) < 0.05
    assert namespace["again"].allclose(model)
    assert (tmp_path / "model.json").exists()
