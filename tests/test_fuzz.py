"""Fuzzing of every file reader and loader.

Random and mutated bytes must give a ``subid.errors`` exception or a valid
object: never another exception, a hang or unbounded memory. ``make test``
runs a few examples per format; ``make test-long`` (SUBID_HYPOTHESIS_PROFILE=long)
runs many more.
"""

import io
import os
import tracemalloc

import numpy as np
import pytest
import scipy.io
from hypothesis import given, settings
from hypothesis import strategies as st

import subid
from subid import errors, systems

LONG = os.environ.get("SUBID_HYPOTHESIS_PROFILE") == "long"
EXAMPLES = 1500 if LONG else 25
MEMORY_LIMIT = 256 * 2**20        # bytes of traced allocations per load


def _valid_files():
    data = systems.simulate_data(systems.seed001_system(), 40, seed=0)
    table = np.hstack([data.u, data.y])
    files = {}
    buf = io.StringIO()
    np.savetxt(buf, table, delimiter=",", header="u1,u2,y1,y2", comments="")
    files[".csv"] = buf.getvalue().encode()
    buf = io.StringIO()
    np.savetxt(buf, table, delimiter="\t")
    files[".dat"] = buf.getvalue().encode()
    buf = io.BytesIO()
    np.savez(buf, u=data.u, y=data.y, dt=np.array(0.1))
    files[".npz"] = buf.getvalue()
    buf = io.BytesIO()
    scipy.io.savemat(buf, {"u": data.u, "y": data.y})
    files[".mat"] = buf.getvalue()
    files[".json"] = __import__("json").dumps(systems.seed001_system().to_dict()).encode()
    return files


VALID = _valid_files()
ARGS = {".csv": ("u1,u2", "y1,y2"), ".dat": ([0, 1], [2, 3]), ".npz": (None, None),
        ".mat": (None, None)}


def _mutate(raw: bytes, edits) -> bytes:
    data = bytearray(raw)
    for kind, pos, value in edits:
        if not data:
            data = bytearray(bytes([value]))
            continue
        pos %= len(data)
        if kind == 0:
            data[pos] = value
        elif kind == 1:
            data.insert(pos, value)
        elif kind == 2:
            del data[pos]
        else:
            data = data[:pos]
    return bytes(data)


edits = st.lists(st.tuples(st.integers(0, 3), st.integers(0, 10**9), st.integers(0, 255)),
                 min_size=1, max_size=8)


def _load(path, ext):
    tracemalloc.start()
    try:
        if ext == ".json":
            return subid.StateSpace.load(path)
        if ext == ".ckpt.npz":
            return subid.RecursiveSubspace.load(path)
        if ext == ".adaptive.npz":
            return subid.AdaptiveIdentifier.load(path)
        return subid.read(path, *ARGS[ext])
    except errors.SubidError:
        return None
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < MEMORY_LIMIT, f"loading used {peak / 2**20:.0f} MB"


@pytest.mark.parametrize("ext", sorted(VALID))
@settings(max_examples=EXAMPLES, deadline=5000)
@given(changes=edits)
def test_mutated_files(tmp_path_factory, ext, changes):
    path = tmp_path_factory.mktemp("fuzz") / f"file{ext}"
    path.write_bytes(_mutate(VALID[ext], changes))
    _load(path, ext)


@pytest.mark.parametrize("ext", sorted(VALID))
@settings(max_examples=EXAMPLES, deadline=5000)
@given(raw=st.binary(max_size=2000))
def test_random_bytes(tmp_path_factory, ext, raw):
    path = tmp_path_factory.mktemp("fuzz") / f"file{ext}"
    path.write_bytes(raw)
    _load(path, ext)


def _saved_bytes(identifier) -> bytes:
    """The bytes of ``identifier.save(...)``."""
    path = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"subid-fuzz-{os.getpid()}.npz")
    identifier.save(path)
    with open(path, "rb") as fh:
        raw = fh.read()
    os.unlink(path)
    return raw


def _checkpoint_bytes():
    data = systems.simulate_data(systems.seed001_system(), 200, seed=0)
    return _saved_bytes(subid.RecursiveSubspace(3, 2, 2).update(data.u, data.y))


def _adaptive_checkpoint_bytes():
    from subid.experiments.seed000 import multisine
    t = np.arange(0.0, 2.0, 0.001)
    u = multisine(t, 2)
    ai = subid.AdaptiveIdentifier(4, 2, 2, dt=0.001)
    ai.update(u, subid.systems.seed000_system().simulate(u, t=t, hold="foh"))
    return _saved_bytes(ai)


CHECKPOINT = _checkpoint_bytes()
ADAPTIVE_CHECKPOINT = _adaptive_checkpoint_bytes()


@pytest.mark.parametrize("kind", [".ckpt.npz", ".adaptive.npz"])
@settings(max_examples=EXAMPLES, deadline=5000)
@given(changes=edits)
def test_mutated_checkpoints(tmp_path_factory, kind, changes):
    path = tmp_path_factory.mktemp("fuzz") / "state.npz"
    raw = CHECKPOINT if kind == ".ckpt.npz" else ADAPTIVE_CHECKPOINT
    path.write_bytes(_mutate(raw, changes))
    _load(path, kind)


# -- regressions found by the fuzzers ---------------------------------------
def test_mat_first_byte_zeroed_is_rejected_without_allocating(tmp_path):
    """Found by test_mutated_files[.mat]: a zero first byte made scipy read a
    v5 file as MATLAB v4 and allocate 1.7 GB for a garbage header."""
    path = tmp_path / "bad.mat"
    path.write_bytes(_mutate(VALID[".mat"], [(0, 0, 0)]))
    tracemalloc.start()
    with pytest.raises(errors.FileReadError, match="corrupted"):
        subid.read(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 * 2**20


def test_genuine_mat4_file_still_reads(tmp_path):
    path = tmp_path / "v4.mat"
    u, y = np.arange(10.0)[:, None], np.arange(10.0)[:, None] * 2
    scipy.io.savemat(path, {"u": u, "y": y}, format="4")
    data = subid.read(path)
    np.testing.assert_array_equal(data.y[:, 0], 2 * np.arange(10.0))


def test_mat_element_declaring_more_than_the_file_is_rejected(tmp_path):
    """Found by the long fuzz run: a truncated v5 file whose next element tag
    was corrupted made scipy allocate 256 MB before failing."""
    path = tmp_path / "bad.mat"
    path.write_bytes(_mutate(VALID[".mat"], [(3, 500000000, 0), (0, 19713303, 16)]))
    tracemalloc.start()
    with pytest.raises(errors.FileReadError, match="corrupted"):
        subid.read(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 * 2**20


def test_checkpoint_with_garbled_npy_header_is_a_checkpoint_error(tmp_path):
    """Found by the long fuzz run: numpy's header parser raised
    tokenize.TokenError on a mutated checkpoint."""
    path = tmp_path / "state.npz"
    path.write_bytes(_mutate(CHECKPOINT, [(0, 63, 1)]))
    with pytest.raises(errors.CheckpointError):
        subid.RecursiveSubspace.load(path)


def test_npz_member_declaring_more_than_it_holds_is_rejected(tmp_path):
    """A well-formed .npy member (valid CRC) whose header claims 1e12
    elements: numpy would allocate the claim before reading."""
    import zipfile
    member = io.BytesIO()
    np.lib.format.write_array_header_1_0(member, {"descr": "<f8", "fortran_order": False,
                                                   "shape": (10**12,)})
    member.write(np.zeros(10).tobytes())
    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("u.npy", member.getvalue())
        archive.writestr("y.npy", member.getvalue())
    tracemalloc.start()
    with pytest.raises(errors.FileReadError, match="declares 8000000000000 bytes"):
        subid.read(path)
    assert tracemalloc.get_traced_memory()[1] < 16 * 2**20
    tracemalloc.stop()


@pytest.mark.parametrize("edit", [(0, 199185505, 73), (0, 501331136, 212), (0, 295214577, 187)])
def test_mat_fields_scipy_trusts_are_validated(tmp_path, edit):
    """Found by the long fuzz run: a complex flag without an imaginary part,
    or an unknown data-type code, made scipy's C reader crash the interpreter
    (segmentation fault). The structure is now validated before scipy reads."""
    path = tmp_path / "bad.mat"
    path.write_bytes(_mutate(VALID[".mat"], [edit]))
    with pytest.raises(errors.FileReadError, match="corrupted MATLAB file"):
        subid.read(path)
