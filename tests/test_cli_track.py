"""``subid track --resume``: the method and the detrending come from the checkpoint."""

from __future__ import annotations

import numpy as np
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


def _write(path, rows):
    np.savetxt(path, rows, delimiter=",", header="t,u1,u2,y1,y2", comments="", fmt="%.17g")


@pytest.fixture(scope="module")
def grown(tmp_path_factory):
    """A record of 4000 rows (``short``) that grew to 8000 (``long``); outputs far from 0."""
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 8000, seed=3,
                                       output_snr_db=30)
    rows = np.column_stack([np.arange(8000) * 0.01, data.u + [1.0, -2.0],
                            data.y + [5.0, -3.0]])
    folder = tmp_path_factory.mktemp("grown")
    _write(folder / "short.csv", rows[:4000])
    _write(folder / "long.csv", rows)
    return folder, rows


def _track(capsys, path, out, *extra):
    code, stdout, stderr = run(capsys, "track", path, "--inputs", "u1,u2", "--outputs",
                               "y1,y2", "--dt", "0.01", "--no-report", "--chunk", "500", *extra,
                               "--out", out)
    assert code == 0, stderr
    return subid.StateSpace.load(out / "model.json"), stdout, stderr


def test_resume_on_a_grown_record_removes_the_checkpoints_means(grown, tmp_path, capsys):
    folder, rows = grown
    first, _, _ = _track(capsys, folder / "short.csv", tmp_path / "first", "--order", "3",
                         "--checkpoint-every", "1000")
    ckpt = tmp_path / "first" / "checkpoints" / "checkpoint-0000002000.npz"
    # the same record: the same model as the uninterrupted run
    again, _, stderr = _track(capsys, folder / "short.csv", tmp_path / "again", "--resume", ckpt)
    assert again.allclose(first, rtol=1e-12, atol=1e-14) and "WARNING" not in stderr
    # the grown record: every sample loses the means the checkpoint's run removed (those of
    # the 4000 rows), as one run over the 8000 rows with those means; the new means drifted
    # the model (2e-5 on a 200,000-row record)
    resumed, _, stderr = _track(capsys, folder / "long.csv", tmp_path / "resumed", "--resume",
                                ckpt)
    assert "WARNING" not in stderr
    means = rows[:4000, 1:].mean(axis=0)
    u, y = rows[:, 1:3] - means[:2], rows[:, 3:] - means[2:]
    straight = subid.RecursiveSubspace(3, 2, 2, dt=0.01)
    for a in range(0, 8000, 500):
        straight.update(u[a:a + 500], y[a:a + 500])
    assert resumed.allclose(straight.model, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(resumed.info["data"]["y_offset"], means[2:])
    # a checkpoint without the means (its trace is gone, or from an earlier version): warned
    (tmp_path / "first" / "checkpoints" / "checkpoint-0000002000.trace.npz").unlink()
    _, _, stderr = _track(capsys, folder / "long.csv", tmp_path / "old", "--resume", ckpt)
    assert "the checkpoint does not hold the means of its run" in stderr
    assert "use --detrend none for a growing record" in stderr


def test_resume_keeps_the_checkpoints_detrend(grown, tmp_path, capsys):
    folder, _ = grown
    first, _, _ = _track(capsys, folder / "short.csv", tmp_path / "first", "--order", "3",
                         "--detrend", "none", "--checkpoint-every", "1000")
    ckpt = tmp_path / "first" / "checkpoints" / "checkpoint-0000002000.npz"
    # without --detrend: the checkpoint's (none), not the default (constant)
    again, _, stderr = _track(capsys, folder / "short.csv", tmp_path / "again", "--resume", ckpt)
    assert again.allclose(first, rtol=1e-12, atol=1e-14) and "WARNING" not in stderr
    assert again.info["data"]["detrend"] == "none"
    # a --detrend that contradicts the checkpoint's: warned
    _, _, stderr = _track(capsys, folder / "short.csv", tmp_path / "mixed", "--resume", ckpt,
                          "--detrend", "constant")
    assert "the run that wrote the checkpoint used --detrend none" in stderr


def test_resume_refuses_another_sampling_period_before_reading_on(grown, tmp_path, capsys):
    # it fed the whole rest of the record and wrote a checkpoint, then failed at the end
    folder, _ = grown
    _track(capsys, folder / "short.csv", tmp_path / "first", "--order", "3",
           "--checkpoint-every", "2000")
    ckpt = tmp_path / "first" / "checkpoints" / "checkpoint-0000002000.npz"
    code, stdout, stderr = run(capsys, "track", folder / "long.csv", "--inputs", "u1,u2",
                               "--outputs", "y1,y2", "--dt", "0.02", "--no-report",
                               "--resume", ckpt, "--out", tmp_path / "resumed")
    assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr
    assert "made with dt = 0.01 but the data are sampled with dt = 0.02" in stderr
    assert "pass --dt 0.01" in stderr
    assert not (tmp_path / "resumed").exists()


def test_a_refused_track_leaves_no_output_folder(grown, tmp_path, capsys):
    folder, _ = grown
    for extra in ((), ("--order", "3", "--horizon", "2"), ("--order", "3", "--option",
                                                            "lags=abc")):
        out = tmp_path / f"refused{len(extra)}"
        code, _, stderr = run(capsys, "track", folder / "short.csv", "--inputs", "u1,u2",
                              "--outputs", "y1,y2", "--dt", "0.01", "--no-report", *extra,
                              "--out", out)
        assert code == 2 and not out.exists(), stderr


def test_track_does_not_repeat_the_warnings_of_its_snapshots(tmp_path, capsys):
    # the intermediate models of the convergence plot warned each time (noise-free data:
    # "no stable Kalman predictor was found" five times, each with its own spectral radius)
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 20000, seed=1)
    path = tmp_path / "plant.csv"
    np.savetxt(path, np.column_stack([data.u, data.y]), delimiter=",",
               header="u1,u2,y1,y2", comments="")
    code, stdout, stderr = run(capsys, "track", path, "--inputs", "u1,u2", "--outputs",
                               "y1,y2", "--dt", "0.01", "--order", "3", "--no-report",
                               "--out", tmp_path / "out")
    assert code == 0, stderr
    assert (stdout + stderr).count("Kalman predictor") <= 1
