"""subid.warmup: fills numba's cache for the common calls (issue 14 item 5)."""

import pytest

from subid.errors import SubidError
from subid.warmup import main, warmup


def test_warmup_runs_the_adaptive_group_and_reports_seconds():
    out = warmup(["adaptive"])
    assert list(out) == ["adaptive"]
    assert out["adaptive"] >= 0.0


def test_warmup_rejects_unknown_groups():
    with pytest.raises(SubidError, match="unknown warm-up group"):
        warmup(["adaptive", "gpu"])


def test_warmup_command_line(capsys):
    assert main(["--only", "adaptive"]) == 0
    assert capsys.readouterr().out.startswith("adaptive")
    with pytest.raises(SystemExit):
        main(["--only", "nonsense"])
