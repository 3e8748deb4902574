"""``subid track --resume``: the method and the detrending come from the checkpoint."""

from __future__ import annotations

import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("click")

import subid  # noqa: E402
from test_cli import run  # noqa: E402


def test_resume_takes_the_method_from_the_checkpoint(tmp_path, capsys):
    full = tmp_path / "full"
    code, _, stderr = run(capsys, "track", "dataset:dryer", "--method", "adaptive", "--order",
                          "2", "--checkpoint-every", "500", "--no-report", "-q", "--out", full)
    assert code == 0, stderr
    ckpt = full / "checkpoints" / "checkpoint-0000000500.npz"
    # without --method: the checkpoint's (it failed: --method defaults to recursive)
    code, stdout, stderr = run(capsys, "track", "dataset:dryer", "--resume", ckpt,
                               "--no-report", "--out", tmp_path / "resumed")
    assert code == 0, stderr
    assert "method      adaptive (AdaptiveIdentifier)" in stdout
    resumed = subid.StateSpace.load(tmp_path / "resumed" / "model.json")
    assert resumed.allclose(subid.StateSpace.load(full / "model.json"), rtol=1e-10,
                            atol=1e-12)
    # a --method that contradicts the checkpoint: one line naming the right one
    code, stdout, stderr = run(capsys, "track", "dataset:dryer", "--method", "recursive",
                               "--resume", ckpt, "--no-report", "--out", tmp_path / "wrong")
    assert code == 2 and stdout == "" and len(stderr.strip().splitlines()) == 1, stderr
    assert "checkpoint of subid.AdaptiveIdentifier (--method adaptive)" in stderr
    assert "give --method adaptive or leave --method out" in stderr
    # the matching --method is accepted as before
    code, _, stderr = run(capsys, "track", "dataset:dryer", "--method", "adaptive", "--resume",
                          ckpt, "--no-report", "-q", "--out", tmp_path / "again")
    assert code == 0, stderr
