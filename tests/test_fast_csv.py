"""The fast CSV path (issue 16 item 8, issue 14 item 4): the same values and the
same errors as the careful line-by-line parser, one parse per pass, bounded memory."""

from __future__ import annotations

import tracemalloc
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import subid
import subid.io._common as io_common
import subid.io.chunks as io_chunks
import subid.io.fast_csv as io_fast
import subid.io.text as io_text
import subid.methods.dt.stream  # noqa: E402  (a submodule: the package imports it lazily)
from subid import errors

RNG = np.random.default_rng(16)


def _engines():
    found = ["numpy"]
    for name, module in (("pandas", "pandas"), ("pyarrow", "pyarrow.csv")):
        try:
            __import__(module)
            found.append(name)
        except ImportError:
            pass
    return found


@pytest.fixture(params=_engines())
def engine(request, monkeypatch):
    monkeypatch.setattr(io_fast, "_ENGINE", request.param)
    return request.param


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks and heads of a few kilobytes, so small files take many blocks."""
    monkeypatch.setattr(io_fast, "_BLOCK_BYTES", 4096)
    for module in (io_fast, io_chunks):          # the layout probe and the chunk reader
        monkeypatch.setattr(module, "_HEAD_BYTES", 8192)


def _careful(path, inputs, outputs, time=None, delimiter=None):
    """The careful parser alone (the reference)."""
    p = Path(path)
    return io_text._read_text(p, str(p), p.suffix.lower(), inputs, outputs, None, time,
                          delimiter)


def _same(a, b):
    np.testing.assert_array_equal(a.u, b.u)
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.t, b.t)
    assert a.input_names == b.input_names and a.output_names == b.output_names
    assert a.dt == b.dt


def _cases(tmp_path):
    m = (RNG.standard_normal((3000, 4)) * 10.0 ** RNG.integers(-300, 300, (3000, 4))).tolist()
    m = np.array(m)
    t = np.cumsum(RNG.uniform(0.5, 1.5, 3000))
    cases = []
    f = tmp_path / "header.csv"
    np.savetxt(f, np.column_stack([t, m]), delimiter=",", fmt="%.17g",
               header="t,u1,u2,y1,y2", comments="")
    cases.append((f, "u1,u2", "y1,y2", "t"))
    f = tmp_path / "index.csv"                       # pandas' to_csv with its index
    lines = [",u1,y1"] + [f"{k},{a!r},{b!r}" for k, (a, b) in enumerate(m[:, :2].tolist())]
    f.write_text("\n".join(lines) + "\n")
    cases.append((f, "u1", "y1", None))
    f = tmp_path / "crlf.csv"
    f.write_bytes(b"u;y\r\n" + b"".join(b"%r;%r\r\n" % (a, b) for a, b in m[:, :2].tolist()))
    cases.append((f, "u", "y", None))
    f = tmp_path / "noheader.tsv"
    np.savetxt(f, m, delimiter="\t", fmt="%.10e")
    cases.append((f, "0,1", "3", None))
    f = tmp_path / "daisy.dat"                       # DaISy: 3-digit exponents, trailing TAB
    f.write_text("".join(f"  {a:.7e}  {b:.7e}\t\n".replace("e+0", "e+00").replace("e-0", "e-00")
                         for a, b in m[:, :2] / 1e280))
    cases.append((f, 0, 1, None))
    f = tmp_path / "nolf.csv"                        # no line break after the last row
    f.write_text("u,y\n" + "\n".join(f"{a},{b}" for a, b in m[:, :2]))
    cases.append((f, "u", "y", None))
    f = tmp_path / "comments.csv"                    # comments and blank lines: careful path
    f.write_text("# made by hand\nu,y\n" + "".join(
        f"{a},{b}\n" + ("\n# note\n" if k % 700 == 0 else "")
        for k, (a, b) in enumerate(m[:, :2])))
    cases.append((f, "u", "y", None))
    f = tmp_path / "text.csv"                        # text in a column that is not selected
    f.write_text("date,u,y\n" + "".join(f"2024-01-{k % 28 + 1:02d},{a},{b}\n"
                                        for k, (a, b) in enumerate(m[:, :2])))
    cases.append((f, "u", "y", None))
    f = tmp_path / "bom.csv"
    f.write_bytes(b"\xef\xbb\xbfu,y\n" + b"".join(b"%r,%r\n" % (a, b) for a, b in m[:, :2].tolist()))
    cases.append((f, "u", "y", None))
    return cases


@pytest.mark.parametrize("blocks", ["default", "small"])
@pytest.mark.slow
def test_fast_read_equals_the_careful_parser(tmp_path, engine, blocks, request):
    if blocks == "small":
        request.getfixturevalue("small_blocks")
    for path, inputs, outputs, time in _cases(tmp_path):
        reference = _careful(path, inputs, outputs, time)
        _same(subid.read(path, inputs, outputs, time=time), reference)
        if time is None:
            pieces = list(subid.read_chunks(path, inputs, outputs, chunk_size=777))
            assert max(p.n_samples for p in pieces) <= 777
            np.testing.assert_array_equal(np.vstack([p.u for p in pieces]), reference.u)
            np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), reference.y)
            assert pieces[-1].t[-1] == reference.n_samples - 1


def test_bundled_daisy_records_equal_the_careful_parser(engine):
    folder = resources.files("subid.datasets").joinpath("data")
    names = sorted(p.name for p in folder.iterdir() if p.name.endswith(".dat"))
    assert names
    for name in names:
        with resources.as_file(folder.joinpath(name)) as path:
            width = np.loadtxt(path, max_rows=1, ndmin=1).size
            reference = _careful(path, 0, width - 1)
            _same(subid.read(path, 0, width - 1), reference)


_BAD = [
    ("1,abc,3", r"bad\.csv, line 1502, column 1 \('u'\): 'abc' is not a number"),
    ("1,,3", r"bad\.csv, line 1502, column 1 \('u'\): the value is missing"),
    ("1,2", r"bad\.csv, line 1502: found 2 fields, expected 3 like the header \(line 1\)"),
    ("1,2,3,4", r"bad\.csv, line 1502: found 4 fields, expected 3"),
    ("1,1_0,3", r"bad\.csv, line 1502, column 1 \('u'\): '1_0' is not a number"),
    ("1,2,3.5,5", r"bad\.csv, line 1502: found 4 fields"),
    ("1,2,nan", r"bad\.csv, line 1502, column 2 \('y'\): 'nan' is not a finite number"),
    ("1,inf,3", r"bad\.csv, line 1502, column 1 \('u'\): 'inf' is not a finite number"),
    ("1,NA,3", r"bad\.csv, line 1502, column 1 \('u'\): 'NA' is not a number"),
]


@pytest.mark.parametrize("row, message", _BAD)
def test_bad_rows_get_the_careful_message(tmp_path, engine, small_blocks, row, message):
    f = tmp_path / "bad.csv"
    good = "".join(f"{k},{k * 0.5},{k * 0.25}\n" for k in range(3000))
    lines = good.splitlines()
    lines[1500] = row                                # line 1502 of the file
    f.write_text("t,u,y\n" + "\n".join(lines) + "\n")
    kind = errors.DataError if "finite" in message else errors.FileReadError
    with pytest.raises(kind, match=message) as careful:
        _careful(f, "u", "y")
    with pytest.raises(kind) as fast:
        subid.read(f, "u", "y")
    assert str(fast.value) == str(careful.value)
    with pytest.raises(kind, match=message):
        list(subid.read_chunks(f, "u", "y", chunk_size=500))


def test_long_lines_still_refused_by_the_fast_path(tmp_path, monkeypatch):
    for module in (io_common, io_fast, io_chunks):    # every reader that bounds lines
        monkeypatch.setattr(module, "MAX_LINE_CHARS", 5000)
    f = tmp_path / "long.csv"
    f.write_text("u,y\n" + "1,2\n" * 3000 + "1," * 3000 + "1\n" + "1,2\n" * 10)
    for fn in (lambda: subid.read(f, "u", "y"), lambda: list(subid.read_chunks(f, "u", "y"))):
        with pytest.raises(errors.ResourceLimitError, match="line 3002"):
            fn()


def test_streaming_parses_the_file_once(tmp_path, monkeypatch):
    """identify_file and `subid identify --stream` hand every data byte to the parser
    once: the later passes read the parsed doubles back; the spool is deleted."""
    clean = subid.systems.simulate_data(subid.systems.seed001_system(), 20_000, seed=1)
    noise = np.random.default_rng(2).standard_normal(clean.y.shape) * 0.1 * clean.y.std(0)
    data = subid.IOData(clean.u, clean.y + noise)
    f = tmp_path / "rec.csv"
    np.savetxt(f, np.column_stack([data.u, data.y]), delimiter=",", fmt="%.17g",
               header="u1,u2,y1,y2", comments="")
    body = f.stat().st_size - len("u1,u2,y1,y2\n")
    seen, spools = [], []
    original = io_fast._fast_values
    monkeypatch.setattr(io_fast, "_fast_values",
                        lambda buf, *a: seen.append(len(buf)) or original(buf, *a))
    real_close = subid.methods.dt.stream.ParsedOnce.close

    def close(self):
        spools.append(self.spool)
        real_close(self)
    monkeypatch.setattr(subid.methods.dt.stream.ParsedOnce, "close", close)
    model = subid.identify_file(f, "u1,u2", "y1,y2", order=3, horizon=5, chunk_size=3000)
    assert sum(seen) == body
    assert model.info["bd_method"] != "projection"
    reference = subid.moesp(data, 3, horizon=5, statistic="gram")
    np.testing.assert_allclose(model.A, reference.A, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(model.B, reference.B, rtol=1e-7, atol=1e-9)
    assert all(s is None or not Path(s).exists() for s in spools)
    seen.clear()
    from subid.cli import commands as cli
    assert cli.main(["--quiet", "identify", str(f), "--inputs", "u1,u2", "--outputs", "y1,y2",
                     "--method", "moesp", "--order", "3", "--horizon", "5", "--stream",
                     "--chunk-size", "3000", "--no-report", "--out", str(tmp_path / "o")]) == 0
    assert sum(seen) == body
    assert all(s is None or not Path(s).exists() for s in spools)


@pytest.mark.slow
def test_read_peak_memory_is_below_three_times_the_doubles(tmp_path):
    n = 200_000
    m = RNG.standard_normal((n, 5))
    f = tmp_path / "big.csv"
    np.savetxt(f, m, delimiter=",", fmt="%.17g", header="t,u1,u2,y1,y2", comments="")
    subid.read(f, "u1", "y1")                       # imports done before measuring
    tracemalloc.start()
    try:
        data = subid.read(f, "u1,u2", "y1,y2")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    doubles = n * 4 * 8
    assert peak < 3 * doubles, (peak, doubles)     # the file itself is 3.4x the doubles
    np.testing.assert_array_equal(data.y, m[:, 3:])


def test_iodata_keeps_read_only_float64_arrays_without_a_copy():
    u = np.arange(10.0)
    u.setflags(write=False)
    y = np.ones((10, 2))
    d = subid.IOData(u, y)
    assert np.shares_memory(d.u, u) and not np.shares_memory(d.y, y)
    y[0, 0] = 5.0                                    # writable input: copied by default
    assert d.y[0, 0] == 1.0 and y.flags.writeable
    shared = subid.IOData(u, y, copy=False)
    assert np.shares_memory(shared.y, y) and not shared.y.flags.writeable
    assert y.flags.writeable                         # the caller's array is untouched
    again = subid.IOData(d.u, d.y)
    assert np.shares_memory(again.u, d.u) and np.shares_memory(again.y, d.y)
    other = subid.IOData(u.astype(np.float32), y[::2].repeat(2, axis=0))
    assert other.u.dtype == np.float64 and other.u.flags.c_contiguous
    t = np.arange(10.0) * 0.5
    subid.IOData(u, y, t=t)
    assert t.flags.writeable                         # time stamps' flags untouched too
    with pytest.raises(errors.DataError, match="NaN"):
        bad = np.ones((10, 1))
        bad[3] = np.nan
        bad.setflags(write=False)
        subid.IOData(u, bad)


def test_pieces_grow_past_the_first_allocation_and_replay_bit_for_bit(tmp_path, monkeypatch):
    """read_chunks fills each piece block by block (growing it past _PIECE_ROWS, across a
    block the careful parser reads), and ParsedOnce replays the same pieces from its
    spool: the same doubles, names and time stamps as subid.read."""
    monkeypatch.setattr(io_fast, "_BLOCK_BYTES", 4096)
    monkeypatch.setattr(io_chunks, "_PIECE_ROWS", 100)
    m = RNG.standard_normal((3000, 3))
    f = tmp_path / "rec.csv"
    lines = [",".join(repr(v) for v in row) for row in m.tolist()]
    lines.insert(1700, "# a comment: this block goes to the careful parser")
    f.write_text("a,b,c\n" + "\n".join(lines) + "\n")
    whole = subid.read(f, "c,a", "b")
    for chunk in (1, 99, 450, 3000, 5000):
        once = subid.methods.dt.stream.ParsedOnce(
            lambda chunk=chunk: subid.read_chunks(f, "c,a", "b", chunk_size=chunk))
        try:
            first = list(once)
            assert once.sizes is not None
            again = list(once)
        finally:
            once.close()
        assert [p.n_samples for p in first] == [p.n_samples for p in again]
        assert max(p.n_samples for p in first) == min(chunk, 3000)
        for pieces in (first, again):
            np.testing.assert_array_equal(np.vstack([p.u for p in pieces]), whole.u)
            np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), whole.y)
            assert [p.t[0] for p in pieces] == [p.t[0] for p in first]
            assert pieces[-1].t[-1] == 2999
            assert all(list(p.input_names) == ["c", "a"] and list(p.output_names) == ["b"]
                       for p in pieces)


def test_stretches_of_the_spool_equal_slices_of_the_record(tmp_path, monkeypatch):
    """ParsedOnce.ranges reads any stretch of samples straight from the spool (or, with
    no spool, by parsing again); groups cut the record at piece borders into
    consecutive stretches that cover it exactly."""
    monkeypatch.setattr(io_fast, "_BLOCK_BYTES", 4096)
    m = RNG.standard_normal((3000, 3))
    f = tmp_path / "rec.csv"
    f.write_text("a,b,c\n" + "".join(",".join(repr(v) for v in row) + "\n"
                                     for row in m.tolist()))
    once = subid.methods.dt.stream.ParsedOnce(
        lambda: subid.read_chunks(f, "c,a", "b", chunk_size=450))
    u, y = m[:, [2, 0]], m[:, [1]]
    bounds = [(0, 3000), (0, 1), (449, 451), (450, 900), (1234, 2999), (2999, 3000), (7, 7)]

    def check():
        for (a, b), read in zip(bounds, once.ranges(bounds)):
            chunks = list(read())
            assert all(len(cu) for cu, _ in chunks)
            got_u = np.vstack([cu for cu, _ in chunks]) if chunks else np.zeros((0, 2))
            got_y = np.vstack([cy for _, cy in chunks]) if chunks else np.zeros((0, 1))
            np.testing.assert_array_equal(got_u, u[a:b])
            np.testing.assert_array_equal(got_y, y[a:b])
    try:
        check()                                  # before any pass: parses as it goes
        assert once.n_samples is None and len(once.groups(4)) == 1
        list(once)
        assert once.n_samples == 3000
        check()
        for stop in (None, 1000, 2000, 10):
            groups = once.groups(4, stop=stop)
            chunks = [c for read in groups for c in read()]
            end = 3000 if stop is None else stop
            np.testing.assert_array_equal(np.vstack([c[0] for c in chunks]), u[:end])
            assert 1 <= len(groups) <= 4
        assert len(once.groups(4)) == 4
    finally:
        once.close()


@pytest.mark.parametrize("threads", [1, 3])
def test_parse_threads_give_the_values_of_one_thread(tmp_path, monkeypatch, threads):
    """The blocks parsed ahead on several threads come back in order, bit for bit,
    blocks the fast parser declines included; closing the reader early stops the
    threads."""
    monkeypatch.setattr(io_fast, "_BLOCK_BYTES", 4096)
    m = RNG.standard_normal((5000, 3))
    lines = [",".join(repr(v) for v in row) for row in m.tolist()]
    lines.insert(2500, "# a comment: this block goes to the careful parser")
    f = tmp_path / "rec.csv"
    f.write_text("a,b,c\n" + "\n".join(lines) + "\n")
    reference = _careful(f, "c,a", "b")
    with subid.thread_limit(threads):
        assert subid._threads.available() <= threads
        pieces = list(subid.read_chunks(f, "c,a", "b", chunk_size=700))
        whole = subid.read(f, "c,a", "b")
        reader = subid.read_chunks(f, "c,a", "b", chunk_size=100)
        next(reader)
        reader.close()
    np.testing.assert_array_equal(np.vstack([p.u for p in pieces]), reference.u)
    np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), reference.y)
    _same(whole, _careful(f, "c,a", "b"))
    assert subid._threads.limit is None


def test_streamed_model_does_not_depend_on_the_number_of_threads(tmp_path):
    """The passes after the parse run in a fixed number of stretches, whatever the
    threads: the same model bit for bit with one thread and with several."""
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 12_000, seed=4,
                                       output_snr_db=20)
    f = tmp_path / "rec.csv"
    np.savetxt(f, np.column_stack([data.u, data.y]), delimiter=",", fmt="%.17g",
               header="u1,u2,y1,y2", comments="")
    models = []
    for threads in (1, 2):
        with subid.thread_limit(threads):
            models.append(subid.identify_file(f, "u1,u2", "y1,y2", order=3, horizon=5,
                                              chunk_size=1000))
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(models[0], name), getattr(models[1], name))
    np.testing.assert_array_equal(models[0].info["x0"], models[1].info["x0"])
