"""Fuzzing of every file reader and loader.

Random and mutated bytes must give a ``subid.errors`` exception or a valid
object: never another exception, a hang or unbounded memory. ``make test``
runs a few examples per format; ``make test-long`` (SUBID_HYPOTHESIS_PROFILE=long)
runs many more.
"""

import io
import json
import os
import signal
import tracemalloc
import zipfile

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


TIME_LIMIT = 20.0                 # seconds per load (a hang fails the test, never blocks it)


class _Timeout(Exception):
    pass


def _on_alarm(signum, frame):
    raise _Timeout()


def guarded(fn, *, memory=MEMORY_LIMIT, seconds=TIME_LIMIT, swallow=True):
    """Run ``fn()`` under a wall-clock timeout and a limit on traced allocations.

    Returns its result, or None when it raised a ``subid.errors`` exception
    (re-raised when ``swallow`` is false); any other exception, a timeout
    (e.g. a FIFO blocking forever) or a peak allocation above ``memory``
    fails the test.
    """
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    tracemalloc.start()
    try:
        return fn()
    except errors.SubidError:
        if not swallow:
            raise
        return None
    except _Timeout:
        pytest.fail(f"no answer within {seconds} s (blocked or too slow)")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < memory, f"loading used {peak / 2**20:.0f} MB"


def _load(path, ext):
    if ext == ".json":
        return guarded(lambda: subid.StateSpace.load(path))
    if ext == ".ckpt.npz":
        return guarded(lambda: subid.RecursiveSubspace.load(path))
    if ext == ".adaptive.npz":
        return guarded(lambda: subid.AdaptiveIdentifier.load(path))
    if ext == ".model.mat":
        return guarded(lambda: subid.StateSpace.from_mat(path))
    return guarded(lambda: subid.read(path, *ARGS[ext]))


@pytest.mark.parametrize("ext", sorted(VALID))
@settings(max_examples=EXAMPLES, deadline=5000)
@given(changes=edits)
@pytest.mark.slow
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


# -- round two (issue 15): every loader, every class of hostile input --------
def _model_mat_bytes() -> bytes:
    from subid.io.interop import save_mat
    path = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"subid-fuzz-{os.getpid()}.mat")
    save_mat(systems.seed001_system(), path)
    with open(path, "rb") as fh:
        raw = fh.read()
    os.unlink(path)
    return raw


MODEL_MAT = _model_mat_bytes()


@settings(max_examples=EXAMPLES, deadline=None)
@given(changes=edits)
def test_mutated_model_mat_files(tmp_path_factory, changes):
    """Class 1: model .mat files go through the validated MAT reader (a
    mutated file crashed scipy's C reader through from_mat)."""
    path = tmp_path_factory.mktemp("fuzz") / "model.mat"
    path.write_bytes(_mutate(MODEL_MAT, changes))
    model = _load(path, ".model.mat")
    assert model is None or np.isfinite(model.A).all()


@pytest.mark.parametrize("edit", [(0, 199185505, 73), (0, 501331136, 212), (0, 295214577, 187)])
def test_model_mat_with_corrupted_matrix_is_refused_not_a_crash(tmp_path, edit):
    """The edits that made scipy segfault in subid.read also reach from_mat."""
    raw = bytearray(MODEL_MAT)
    path = tmp_path / "bad.mat"
    path.write_bytes(_mutate(VALID[".mat"], [edit]))
    with pytest.raises(errors.FileReadError, match="corrupted MATLAB file"):
        subid.StateSpace.from_mat(path)
    assert raw == MODEL_MAT


def _simulate_cli(model_path, input_path):
    from subid.cli import commands as cli
    out = os.path.join(os.path.dirname(str(input_path)), "sim-out.csv")
    code = cli.main(["--quiet", "simulate", str(model_path), "--input", str(input_path),
                     "--out", out])
    if code != 0:
        raise errors.FileReadError("simulate refused the file")
    return code


def _special_loaders(tmp_path):
    model = tmp_path / "model.json"
    systems.seed001_system().save(model)
    inputs = tmp_path / "inputs.csv"
    inputs.write_text("u1,u2\n" + "".join(f"{k},{-k}\n" for k in range(20)))
    return {
        "read .csv": (".csv", lambda p: subid.read(p, "u1", "y1")),
        "read .npz": (".npz", lambda p: subid.read(p)),
        "read .mat": (".mat", lambda p: subid.read(p)),
        "read_chunks": (".csv", lambda p: list(subid.read_chunks(p, "u1", "y1"))),
        "StateSpace.load": (".json", subid.StateSpace.load),
        "StateSpace.from_mat": (".mat", subid.StateSpace.from_mat),
        "RecursiveSubspace.load": (".npz", subid.RecursiveSubspace.load),
        "AdaptiveIdentifier.load": (".npz", subid.AdaptiveIdentifier.load),
        "subid simulate MODEL": (".json", lambda p: _simulate_cli(p, inputs)),
        "subid simulate --input": (".csv", lambda p: _simulate_cli(model, p)),
    }


LOADER_NAMES = ["read .csv", "read .npz", "read .mat", "read_chunks", "StateSpace.load",
                "StateSpace.from_mat", "RecursiveSubspace.load", "AdaptiveIdentifier.load",
                "subid simulate MODEL", "subid simulate --input"]


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "/dev/urandom", "directory"])
@pytest.mark.parametrize("loader", LOADER_NAMES)
def test_loaders_refuse_fifos_devices_and_folders(tmp_path, loader, kind):
    """Class 1: a FIFO blocked every model/checkpoint loader forever and
    /dev/zero filled memory; every loader now opens regular files only."""
    ext, fn = _special_loaders(tmp_path)[loader]
    path = tmp_path / f"special{ext}"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    else:
        if not os.path.exists(kind):
            pytest.skip(f"no {kind}")
        os.symlink(kind, path)
    with pytest.raises(errors.FileReadError, match="not a regular|directory|refused") \
            if not loader.startswith("subid") else pytest.raises(errors.FileReadError):
        guarded(lambda: fn(path), memory=16 * 2**20, seconds=10, swallow=False)


def test_nul_byte_in_a_path_is_a_file_read_error(tmp_path):
    for fn in (lambda p: subid.read(p, "u", "y"), subid.StateSpace.load,
               subid.StateSpace.from_mat, subid.RecursiveSubspace.load):
        with pytest.raises(errors.FileReadError, match="NUL byte"):
            fn(str(tmp_path / "a\x00b.csv"))


# -- class 2: decompression and size bombs ------------------------------------------
def _bomb(path, name, size, *, npy=True):
    block = bytes(2**20)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive, \
            archive.open(name, "w", force_zip64=True) as member:
        if npy:
            head = io.BytesIO()
            np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False,
                                                         "shape": (size // 8,)})
            member.write(head.getvalue())
        for _ in range(size // len(block)):         # written in pieces, never held whole
            member.write(block)


@pytest.mark.parametrize("member, npy", [("u.npy", True), ("u", False), ("y.bin", False)])
@pytest.mark.slow
def test_npz_bombs_are_refused_without_allocating(tmp_path, member, npy):
    """Class 2: 3 MB of compressed zeros made read allocate gigabytes (members
    not named *.npy bypassed the header check)."""
    path = tmp_path / "bomb.npz"
    _bomb(path, member, 160 * 2**20, npy=npy)
    assert path.stat().st_size < 1 * 2**20
    with pytest.raises((errors.FileReadError, errors.ResourceLimitError)) as info:
        subid.read(path, max_bytes=64 * 2**20) if npy else subid.read(path)
    assert guarded(lambda: subid.read(path, max_bytes=64 * 2**20),
                   memory=16 * 2**20) is None
    if npy:
        assert isinstance(info.value, errors.ResourceLimitError)
        assert "max_bytes" in str(info.value)


def test_npz_within_the_budget_reads_and_beyond_is_a_clear_limit(tmp_path):
    data = systems.simulate_data(systems.seed001_system(), 20000, seed=0)
    path = tmp_path / "big.npz"
    np.savez_compressed(path, u=np.zeros((200000, 2)), y=np.zeros((200000, 2)))
    assert subid.read(path).n_samples == 200000
    with pytest.raises(errors.ResourceLimitError, match="max_bytes"):
        subid.read(path, max_bytes=2**20)
    path = tmp_path / "ok.npz"
    np.savez_compressed(path, u=data.u, y=data.y)
    np.testing.assert_array_equal(subid.read(path).y, data.y)


def test_compressed_mat_with_a_large_zero_array_is_valid(tmp_path):
    """Class 7: a valid compressed .mat (ratio beyond 1000:1) was called corrupted;
    beyond max_bytes it is now a ResourceLimitError that says so."""
    path = tmp_path / "zeros.mat"
    u = np.zeros((1_500_000, 1))
    y = np.zeros((1_500_000, 1))
    y[::100_000] = 1.0
    scipy.io.savemat(path, {"u": u, "y": y}, do_compression=True)
    assert path.stat().st_size * 500 < u.nbytes + y.nbytes
    data = subid.read(path)
    np.testing.assert_array_equal(data.y, y)
    with pytest.raises(errors.ResourceLimitError, match="max_bytes"):
        subid.read(path, max_bytes=2**20)


@pytest.mark.parametrize("reader", ["read", "read_chunks"])
def test_long_lines_are_refused_with_bounded_memory(tmp_path, reader):
    """Class 2: a very long CSV line made read use 3.6 GB and read_chunks raise
    MemoryError: streaming memory was not bounded by the chunk size."""
    path = tmp_path / "long.csv"
    with open(path, "w") as fh:
        fh.write("u,y\n1,2\n")
        fh.write("1," * (12 * 2**20) + "1\n")
        fh.write("3,4\n")
    size = path.stat().st_size
    if reader == "read":
        fn, memory = (lambda: subid.read(path, "u", "y")), 3 * size
    else:
        fn, memory = (lambda: list(subid.read_chunks(path, "u", "y", chunk_size=10))), \
            32 * 2**20
    with pytest.raises(errors.ResourceLimitError, match="line 3"):
        fn()
    assert guarded(fn, memory=memory) is None


@settings(max_examples=max(10, EXAMPLES // 10), deadline=None)     # files of up to 12 MB
@given(lengths=st.lists(st.integers(0, 3 * 2**20), min_size=1, max_size=4),
       chunk=st.integers(1, 50))
@pytest.mark.slow
def test_streaming_memory_is_bounded_by_the_chunk_whatever_the_lines(tmp_path_factory,
                                                                      lengths, chunk):
    """Class 2 (property): read_chunks' peak allocation stays bounded however
    long the lines are (errors are fine, unbounded memory is not)."""
    path = tmp_path_factory.mktemp("fuzz") / "lines.csv"
    with open(path, "w") as fh:
        fh.write("u,y\n")
        for n in lengths:
            fh.write("1," * (n // 2) + "1\n")
            fh.write("1,2\n" * chunk)
    guarded(lambda: list(subid.read_chunks(path, "u", "y", chunk_size=chunk)),
            memory=48 * 2**20)


def test_utf16_file_in_read_chunks(tmp_path):
    """Class 7: read accepted UTF-16 files, read_chunks raised UnicodeDecodeError."""
    path = tmp_path / "wide.csv"
    path.write_text("u,y\n" + "".join(f"{k},{2 * k}\n" for k in range(500)), encoding="utf-16")
    whole = subid.read(path, "u", "y")
    pieces = list(subid.read_chunks(path, "u", "y", chunk_size=128))
    np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), whole.y)


def test_quoted_field_beyond_the_csv_limit_is_a_bad_cell(tmp_path):
    path = tmp_path / "quoted.csv"
    path.write_text('u,y\n1,2\n"' + "x" * 200_000 + '",3\n')
    for fn in (lambda: subid.read(path, "u", "y"), lambda: list(subid.read_chunks(path, "u", "y"))):
        with pytest.raises(errors.FileReadError, match="line 3.*200000 characters"):
            fn()


# -- class 3: untrusted structure in JSON and checkpoints -----------------------------
json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats(allow_nan=False)
    | st.text(max_size=5) | st.sampled_from(["nan", "inf", "float64", "str", "complex128",
                                              "int8", "O", "V8", "<U2"]),
    lambda inner: st.lists(inner, max_size=3)
    | st.dictionaries(st.sampled_from(["__ndarray__", "__float__", "__complex__", "dtype",
                                       "shape", "A", "x"]), inner, max_size=3),
    max_leaves=12)


def _nested(value, depth: int) -> str:
    """JSON text of ``value`` inside ``depth`` lists (json.dumps would recurse)."""
    return "[" * depth + json.dumps(value) + "]" * depth


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for key, value in obj.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(obj, list):
        for k, value in enumerate(obj):
            yield from _paths(value, prefix + (k,))


def _replace(obj, path, value):
    if not path:
        return value
    obj[path[0]] = _replace(obj[path[0]], path[1:], value)
    return obj


MODEL_DICT = json.loads(json.dumps(dict(systems.seed001_system().to_dict(),
                                        info={"note": "x", "m": np.eye(2)}),
                                   default=lambda a: {"__ndarray__": a.tolist(),
                                                      "dtype": "float64",
                                                      "shape": list(a.shape)}))


@settings(max_examples=EXAMPLES, deadline=None)
@given(where=st.integers(0, 10**6), value=json_values, depth=st.sampled_from([0, 0, 200, 5000]))
def test_structured_model_json(tmp_path_factory, where, value, depth):
    """Class 3: deep nesting (RecursionError), huge integers (ValueError,
    OverflowError) and malformed tags (TypeError) in model JSON."""
    doc = json.loads(json.dumps(MODEL_DICT))
    paths = list(_paths(doc))
    doc = _replace(doc, paths[where % len(paths)], "@@value@@")
    path = tmp_path_factory.mktemp("fuzz") / "model.json"
    path.write_text(json.dumps(doc).replace('"@@value@@"', _nested(value, depth)))
    _load(path, ".json")


@pytest.mark.parametrize("text", ["[" * 100_000 + "]" * 100_000, '{"A": 1' + "0" * 5000 + "}",
                                  '{"A": 1e400}', '{"A": NaN}', '{"dt": 123456789012345678901234}',
                                  '{"info": {"__float__": ["nan"]}}'])
def test_hostile_model_json_is_a_model_error(tmp_path, text):
    path = tmp_path / "model.json"
    path.write_text(text)
    with pytest.raises(errors.ModelError):
        guarded(lambda: subid.StateSpace.load(path), swallow=False)


def _rewrite_checkpoint(raw: bytes, change) -> bytes:
    with zipfile.ZipFile(io.BytesIO(raw)) as archive:
        arrays = {n[:-4]: np.lib.format.read_array(io.BytesIO(archive.read(n)))
                  for n in archive.namelist()}
    change(arrays)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


CHECKPOINT_DTYPES = ["<i8", "<i4", "<f4", ">f8", "<c16", "|b1", "<U3", "|u1", ">i8", "<f2"]


@pytest.mark.parametrize("dtype", CHECKPOINT_DTYPES)
@pytest.mark.parametrize("kind", ["recursive", "adaptive"])
@pytest.mark.slow
def test_checkpoint_arrays_of_every_dtype_and_byte_order(tmp_path, kind, dtype):
    """Class 3: a checkpoint with integer, big-endian or complex arrays loaded
    and then failed in numba or gave a wrong model. Each array is checked
    against the schema: the same values in another byte order load to the same
    identifier; any other dtype is a CheckpointError."""
    cls = subid.RecursiveSubspace if kind == "recursive" else subid.AdaptiveIdentifier
    raw = CHECKPOINT if kind == "recursive" else ADAPTIVE_CHECKPOINT
    path = tmp_path / "ref.npz"
    path.write_bytes(raw)
    reference = cls.load(path).model
    with zipfile.ZipFile(io.BytesIO(raw)) as archive:
        names = [n[:-4] for n in archive.namelist() if n != "__header__.npy"]
    for name in names:
        def change(arrays, name=name):
            value = arrays[name]
            if np.dtype(dtype).kind == "U":
                arrays[name] = value.astype(str).astype(dtype)
            else:
                with np.errstate(all="ignore"):
                    arrays[name] = value.astype(dtype)
        path.write_bytes(_rewrite_checkpoint(raw, change))
        same_values = np.dtype(dtype).newbyteorder("=") == \
            np.load(io.BytesIO(raw), allow_pickle=False)[name].dtype.newbyteorder("=")
        try:
            loaded = guarded(lambda: cls.load(path), swallow=False)
        except errors.CheckpointError as exc:
            assert not same_values, f"{name} as {dtype}: {exc}"
            continue
        assert same_values, f"{name} as {dtype} was accepted"
        model = loaded.model
        np.testing.assert_array_equal(model.A, reference.A)


settings_values = st.one_of(json_values, st.just(10**30), st.just(-10**30), st.just(1e308),
                            st.text(max_size=3))


@pytest.mark.parametrize("kind", ["recursive", "adaptive"])
@settings(max_examples=EXAMPLES, deadline=None)
@given(key=st.integers(0, 100), value=settings_values, depth=st.sampled_from([0, 0, 50, 3000]))
@pytest.mark.slow
def test_checkpoint_header_fields(tmp_path_factory, kind, key, value, depth):
    """Class 3: huge integers (OverflowError), deep nesting (RecursionError) and
    values of the wrong type in the JSON header of a checkpoint."""
    raw = CHECKPOINT if kind == "recursive" else ADAPTIVE_CHECKPOINT

    def change(arrays):
        header = json.loads(arrays["__header__"].tobytes())
        names = sorted(header["settings"])
        header["settings"][names[key % len(names)]] = "@@value@@"
        text = json.dumps(header).replace('"@@value@@"', _nested(value, depth))
        arrays["__header__"] = np.frombuffer(text.encode(), dtype=np.uint8)

    path = tmp_path_factory.mktemp("fuzz") / "state.npz"
    path.write_bytes(_rewrite_checkpoint(raw, change))
    _load(path, ".ckpt.npz" if kind == "recursive" else ".adaptive.npz")


# -- online update under the same limits ----------------------------------------------
samples = st.lists(st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6),
                             st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)),
                   min_size=1, max_size=60)


@settings(max_examples=EXAMPLES, deadline=None)
@given(rows=samples, scale=st.sampled_from([1.0, 1e-150, 1e150, 1e300]))
def test_recursive_update_under_limits(rows, scale):
    """Every online update returns or raises a subid error, within the time and
    memory limits, whatever the (finite) samples."""
    table = np.array(rows) * scale
    ident = subid.RecursiveSubspace(2, 2, 2, horizon=3)
    guarded(lambda: ident.update(table[:, :2], table[:, 2:]), memory=64 * 2**20)
    guarded(lambda: ident.model, memory=64 * 2**20)


@settings(max_examples=max(5, EXAMPLES // 5), deadline=None)
@given(rows=samples, scale=st.sampled_from([1.0, 1e-150, 1e150]))
def test_adaptive_update_under_limits(rows, scale):
    """The adaptive identifier's update under the same limits (uniform
    sampling; gaps and extreme settings are issue 15's class 5)."""
    table = np.array(rows) * scale
    ident = subid.AdaptiveIdentifier(2, 2, 2, dt=0.01)
    guarded(lambda: ident.update(table[:, :2], table[:, 2:]), memory=64 * 2**20)
    guarded(lambda: ident.model, memory=64 * 2**20)


@pytest.mark.parametrize("ext", [".csv", ".dat"])
@settings(max_examples=EXAMPLES, deadline=None)
@given(changes=edits, chunk=st.integers(1, 30))
def test_mutated_text_files_streamed(tmp_path_factory, ext, changes, chunk):
    """read_chunks on mutated text files: pieces or a subid error, within the
    limits, and the pieces hold the same values as read() when both succeed."""
    path = tmp_path_factory.mktemp("fuzz") / f"file{ext}"
    path.write_bytes(_mutate(VALID[ext], changes))
    pieces = guarded(lambda: list(subid.read_chunks(path, *ARGS[ext], chunk_size=chunk)))
    whole = guarded(lambda: subid.read(path, *ARGS[ext]))
    if pieces and whole is not None:
        np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), whole.y)


def test_compressed_checkpoint_bomb_is_refused_without_allocating(tmp_path):
    """Checkpoints are written uncompressed, so their arrays may not take more
    than the file: a recompressed checkpoint declaring 48 MB is refused."""
    def change(arrays):
        arrays["R"] = np.zeros(6 * 2**20)
    raw = _rewrite_checkpoint(CHECKPOINT, change)
    with zipfile.ZipFile(io.BytesIO(raw)) as src:
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as dst:
            for name in src.namelist():
                dst.writestr(name, src.read(name))
    path = tmp_path / "bomb.npz"
    path.write_bytes(buf.getvalue())
    assert path.stat().st_size < 2**20
    with pytest.raises(errors.CheckpointError):
        guarded(lambda: subid.RecursiveSubspace.load(path), memory=16 * 2**20, swallow=False)


def _npy_bytes() -> bytes:
    data = systems.simulate_data(systems.seed001_system(), 40, seed=0)
    buf = io.BytesIO()
    np.save(buf, np.hstack([data.u, data.y]))
    return buf.getvalue()


NPY = _npy_bytes()


@settings(max_examples=EXAMPLES, deadline=None)
@given(changes=edits, chunk=st.integers(1, 30))
def test_mutated_npy_streamed(tmp_path_factory, changes, chunk):
    """read_chunks on mutated .npy arrays (memory-mapped): pieces or a subid
    error, within the limits."""
    path = tmp_path_factory.mktemp("fuzz") / "file.npy"
    path.write_bytes(_mutate(NPY, changes))
    guarded(lambda: list(subid.read_chunks(path, [0, 1], [2, 3], chunk_size=chunk)))


def _parquet_bytes():
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq
    data = systems.simulate_data(systems.seed001_system(), 40, seed=0)
    table = pa.table({"u1": data.u[:, 0], "u2": data.u[:, 1], "y1": data.y[:, 0],
                      "y2": data.y[:, 1]})
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


@settings(max_examples=EXAMPLES, deadline=None)
@given(changes=edits)
def test_mutated_parquet_streamed(tmp_path_factory, changes):
    """read_chunks on mutated Parquet files: pieces or a subid error."""
    raw = _parquet_bytes()
    path = tmp_path_factory.mktemp("fuzz") / "file.parquet"
    path.write_bytes(_mutate(raw, changes))
    guarded(lambda: list(subid.read_chunks(path, "u1,u2", "y1,y2", chunk_size=16)))
