"""Every output is written atomically (issue 15, class 6 and the write errors of class 7).

A failed or interrupted command leaves the previous file or folder exactly as
it was, names the file the user asked for in its error (never a hidden
temporary), and leaves no temporary file behind; killed writers' leftovers
are removed by the next write.
"""

import errno
import os

import numpy as np
import pytest

import subid
from subid import errors, systems
from subid.cli import commands as cli
from subid.cli import identify as cli_identify
from subid.io import _files


@pytest.fixture(scope="module")
def csv_file(tmp_path_factory):
    data = systems.simulate_data(systems.seed001_system(), 400, seed=0)
    path = tmp_path_factory.mktemp("data") / "run.csv"
    np.savetxt(path, np.hstack([data.u, data.y]), delimiter=",", header="u1,u2,y1,y2",
               comments="")
    return path


def _identify(csv_file, out, *extra):
    return cli.main(["--quiet", "identify", str(csv_file), "--inputs", "u1,u2", "--outputs",
                     "y1,y2", "--dt", "1", "--method", "moesp", "--order", "3", "--horizon",
                     "5", "--no-report", "--out", str(out), *extra])


def _snapshot(folder):
    return {name: (folder / name).read_bytes() for name in sorted(os.listdir(folder))}


def _hidden(folder):
    parent = folder.parent
    return sorted(n for n in os.listdir(parent) if n.startswith("."))


def _fail_on(monkeypatch, target, attribute, exc):
    original = getattr(target, attribute)

    def failing(*args, **kwargs):
        if failing.calls == 0:
            failing.calls += 1
            raise exc
        return original(*args, **kwargs)
    failing.calls = 0
    monkeypatch.setattr(target, attribute, failing)


@pytest.mark.parametrize("failure", ["disk full", "interrupt"])
def test_identify_into_an_old_run_is_old_or_new(tmp_path, csv_file, monkeypatch, capsys,
                                                failure):
    """Ctrl-C or a full disk during identify into an existing folder left a new
    model next to the old report; the folder is now the old run's, whole."""
    out = tmp_path / "out"
    assert _identify(csv_file, out, "--order", "2") == 0
    before = _snapshot(out)
    exc = OSError(errno.ENOSPC, "No space left on device") if failure == "disk full" \
        else KeyboardInterrupt()
    _fail_on(monkeypatch, cli_identify, "_write_json", exc)          # the summary
    code = _identify(csv_file, out)
    assert code == (2 if failure == "disk full" else 130)
    assert _snapshot(out) == before
    assert _hidden(out) == []
    err = capsys.readouterr().err
    if failure == "disk full":
        assert str(out) in err and ".staging" not in err and "No space left" in err
    monkeypatch.undo()
    assert _identify(csv_file, out) == 0                # and a later run replaces it whole
    assert subid.StateSpace.load(out / "model.json").order == 3
    assert _hidden(out) == []


def test_identify_refuses_a_folder_with_foreign_files(tmp_path, csv_file, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert _identify(csv_file, out) == 2
    assert "did not write" in capsys.readouterr().err
    assert sorted(os.listdir(out)) == ["notes.txt"]


def test_stale_staging_folders_and_temporary_files_are_removed(tmp_path, csv_file):
    """Killed saves leave no temporary files behind forever: those of dead
    processes are removed by the next write of the same target."""
    out = tmp_path / "out"
    dead = 2**22 + 12345                      # above any pid_max default: never running
    (tmp_path / f".out.{dead}-0123456789abcdef.staging").mkdir()
    (tmp_path / f".out.{os.getpid()}-0123456789abcdef.staging").mkdir()   # alive: kept
    assert _identify(csv_file, out) == 0
    assert _hidden(out) == [f".out.{os.getpid()}-0123456789abcdef.staging"]
    model = tmp_path / "model.json"
    (tmp_path / f".model.json.{dead}-fedcba9876543210.tmp").write_text("partial")
    systems.seed001_system().save(model)
    assert not (tmp_path / f".model.json.{dead}-fedcba9876543210.tmp").exists()


@pytest.mark.parametrize("target", ["control", "scipy", "json", "mat"])
def test_convert_failed_write_keeps_the_previous_file(tmp_path, monkeypatch, capsys, target):
    """convert --to control|scipy --out F wrote in place: a failed write
    truncated the previous F."""
    model = tmp_path / "model.json"
    systems.seed001_system().save(model)
    dest = tmp_path / f"out.{'py' if target in ('control', 'scipy') else target}"
    if target == "json":
        dest = tmp_path / "copy.json"
    dest.write_bytes(b"previous content")
    if target == "control":
        pytest.importorskip("control")
    _fail_on(monkeypatch, os, "fsync", OSError(errno.ENOSPC, "No space left on device"))
    code = cli.main(["--quiet", "convert", str(model), "--to", target, "--out", str(dest)])
    assert code == 2
    assert dest.read_bytes() == b"previous content"
    err = capsys.readouterr().err
    assert str(dest) in err and ".tmp" not in err
    assert sorted(n for n in os.listdir(tmp_path) if n.startswith(".")) == []


def test_gallery_writes_atomically(tmp_path, monkeypatch):
    from subid.cli import demo
    monkeypatch.setattr(demo, "gallery", lambda datasets=None, progress=False:
                        ("| new |\n", [1]))
    dest = tmp_path / "gallery.md"
    dest.write_text("| old |\n")
    _fail_on(monkeypatch, os, "fsync", OSError(errno.ENOSPC, "No space left on device"))
    assert cli.main(["--quiet", "gallery", "--out", str(dest)]) == 2
    assert dest.read_text() == "| old |\n"
    assert cli.main(["--quiet", "gallery", "--out", str(dest)]) == 0
    assert dest.read_text() == "| new |\n"


def test_write_errors_name_the_file_not_the_temporary(tmp_path, monkeypatch):
    """Disk-full errors did not name the file; permission errors named the
    hidden temporary file."""
    path = tmp_path / "model.json"
    _fail_on(monkeypatch, os, "fsync", OSError(errno.ENOSPC, "No space left on device"))
    with pytest.raises(errors.FileWriteError) as info:
        systems.seed001_system().save(path)
    assert info.value.filename == str(path) and ".tmp" not in str(info.value)
    assert isinstance(info.value, OSError) and info.value.errno == errno.ENOSPC
    _fail_on(monkeypatch, os, "open", PermissionError(errno.EACCES, "Permission denied",
                                                      str(tmp_path / ".model.json.1-x.tmp")))
    with pytest.raises(errors.FileWriteError, match="permissions") as info:
        systems.seed001_system().save(path)
    assert str(path) in str(info.value) and ".tmp" not in str(info.value)
    assert not path.exists()
    with pytest.raises(errors.FileWriteError, match="NUL"):
        systems.seed001_system().save(str(tmp_path / "a\x00b.json"))


def test_track_prunes_only_its_own_checkpoints(tmp_path, csv_file):
    """track pruned by sorting names: with an older run's checkpoints of a longer
    record in --out, it deleted the new run's checkpoints."""
    out = tmp_path / "run"
    (out / "checkpoints").mkdir(parents=True)
    for k in (5000, 6000, 7000):                      # an older run on a longer record
        (out / "checkpoints" / f"checkpoint-{k:010d}.npz").write_bytes(b"old")
    code = cli.main(["--quiet", "track", str(csv_file), "--inputs", "u1,u2", "--outputs",
                     "y1,y2", "--dt", "1", "--method", "recursive", "--order", "3",
                     "--checkpoint-every", "100", "--keep-checkpoints", "2", "--no-report",
                     "--out", str(out)])
    assert code == 0
    names = sorted(os.listdir(out / "checkpoints"))
    mine = [n for n in names if n.endswith(".npz") and not n.endswith(".trace.npz")
            and int(n[11:21]) <= 400]
    assert mine == ["checkpoint-0000000300.npz", "checkpoint-0000000400.npz"]
    assert subid.RecursiveSubspace.load(out / "checkpoints" / mine[-1]).n_samples == 400
    assert sorted(os.listdir(out)) == ["checkpoints", "history.npz", "model.json"]
    assert _hidden(out) == []


def test_atomic_directory_swaps_whole_folders(tmp_path):
    out = tmp_path / "f"
    with _files.atomic_directory(out) as stage:
        (open(os.path.join(stage, "a"), "w")).write("1")
    with pytest.raises(RuntimeError):
        with _files.atomic_directory(out) as stage:
            (open(os.path.join(stage, "b"), "w")).write("2")
            raise RuntimeError("stop")
    assert os.listdir(out) == ["a"]
    with _files.atomic_directory(out) as stage:
        (open(os.path.join(stage, "b"), "w")).write("2")
    assert os.listdir(out) == ["b"]
    assert _hidden(out) == []


def test_writers_replace_regular_files_only_and_keep_links(tmp_path):
    """Writing over a device or a folder is refused (os.replace would have
    replaced /dev/null itself when run as root); a symbolic link is refused
    (one output-path policy: nothing is written through a link)."""
    model = systems.seed001_system()
    for target in ("/dev/null", str(tmp_path)):
        with pytest.raises(errors.FileWriteError, match="regular files only"):
            model.save(target)
    real = tmp_path / "real.json"
    model.save(real)
    link = tmp_path / "link.json"
    os.symlink(real, link)
    with pytest.raises(errors.FileWriteError, match="symbolic link"):
        subid.StateSpace(np.eye(1) * 0.5, [[1.0]], [[1.0]], [[0.0]], 1.0).save(link)
    assert os.path.islink(link)
    assert subid.StateSpace.load(real).order == 3


def test_identify_and_track_without_out_write_next_to_the_working_folder(tmp_path, csv_file,
                                                                          monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["--quiet", "identify", str(csv_file), "--inputs", "u1,u2", "--outputs", "y1,y2",
            "--dt", "1", "--method", "moesp", "--order", "3", "--horizon", "5", "--no-report"]
    assert cli.main(args) == 0
    assert sorted(os.listdir(tmp_path / "run_identify")) == ["model.json", "summary.json"]
    assert cli.main(args) == 0                      # its own files: replaced, not refused
    assert cli.main(["--quiet", "track", str(csv_file), "--inputs", "u1,u2", "--outputs",
                     "y1,y2", "--dt", "1", "--method", "recursive", "--order", "3",
                     "--no-report"]) == 0
    assert {"model.json", "history.npz"} <= set(os.listdir(tmp_path / "run_track"))
    # another run's folder of foreign files is refused, as with --out
    (tmp_path / "run_identify" / "notes.txt").write_text("mine")
    assert cli.main(args) == 2
    assert "run_identify holds files subid did not write" in capsys.readouterr().err


def test_default_out_names():
    from subid.cli._shared import _default_out
    assert _default_out("data/plant.csv", "identify") == "plant_identify"
    assert _default_out("dataset:dryer", "track") == "dryer_track"
    assert _default_out("runs/", "identify") == "runs_identify"
