"""Tests of subid.io.read: round trips through every format and every error case."""

from __future__ import annotations

import time as _time
import zipfile

import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from subid.errors import DataError, DataFileNotFoundError, FileReadError
from subid.io.formats import read

RNG = np.random.default_rng(1234)


def _write_table(path, header, rows, delim=",", newline="\n", trailing=""):
    lines = []
    if header is not None:
        lines.append(delim.join(header) + trailing)
    for row in rows:
        lines.append(delim.join(repr(float(x)) for x in row) + trailing)
    path.write_bytes((newline.join(lines) + newline).encode())
    return path


# ---------------------------------------------------------------------------
# round trips
# ---------------------------------------------------------------------------
def test_csv_with_header_by_name(tmp_path):
    t = np.arange(50) * 0.25
    u = RNG.standard_normal((50, 2))
    y = RNG.standard_normal(50) * 1e-7
    f = _write_table(tmp_path / "run.csv", ["t", "u1", "u2", "y"],
                     np.column_stack([t, u, y]))
    data = read(f, inputs=["u1", "u2"], outputs="y", time="t")
    np.testing.assert_array_equal(data.u, u)
    np.testing.assert_array_equal(data.y[:, 0], y)
    assert data.input_names == ("u1", "u2")
    assert data.output_names == ("y",)
    assert data.dt == pytest.approx(0.25)
    np.testing.assert_array_equal(data.t, t)


def test_csv_comma_separated_string_and_column_order(tmp_path):
    m = RNG.standard_normal((20, 4))
    f = _write_table(tmp_path / "d.csv", ["a", "b", "c", "d"], m)
    data = read(f, inputs="c, a", outputs="d,b", dt=0.5)
    np.testing.assert_array_equal(data.u, m[:, [2, 0]])
    np.testing.assert_array_equal(data.y, m[:, [3, 1]])
    assert data.input_names == ("c", "a")
    assert data.output_names == ("d", "b")
    assert data.dt == 0.5


def test_csv_header_indices_also_work(tmp_path):
    m = RNG.standard_normal((10, 3))
    f = _write_table(tmp_path / "d.csv", ["t", "u", "y"], m)
    data = read(f, inputs=1, outputs="2")
    np.testing.assert_array_equal(data.u[:, 0], m[:, 1])
    assert data.input_names == ("u",) and data.output_names == ("y",)


def test_integer_like_header_names_win_over_indices(tmp_path):
    # The header names "0" and "1" refer to columns 2 and 1, not to indices 0 and 1.
    m = RNG.standard_normal((10, 3))
    f = _write_table(tmp_path / "d.csv", ["x", "1", "0"], m)
    data = read(f, inputs="0", outputs="1")
    np.testing.assert_array_equal(data.u[:, 0], m[:, 2])
    np.testing.assert_array_equal(data.y[:, 0], m[:, 1])
    # "2" is not a header name, so it is an index; but column 2's header cell is the
    # number "0": line 1 may be a data row (with a text cell "x"), so it is refused
    with pytest.raises(FileReadError, match="line 1 was taken as the header .* column 2, "
                                            "selected by index in inputs, is the value '0'"):
        read(f, inputs="2", outputs="x")


def test_csv_without_header_by_index(tmp_path):
    m = RNG.standard_normal((30, 4))
    f = _write_table(tmp_path / "noheader.csv", None, m)
    data = read(f, inputs=[0, 2], outputs="3")
    np.testing.assert_array_equal(data.u, m[:, [0, 2]])
    np.testing.assert_array_equal(data.y, m[:, [3]])
    assert data.input_names == ("col0", "col2")
    assert data.output_names == ("col3",)
    assert data.dt == 1.0
    data = read(f, inputs="0,1", outputs=[np.int64(3)])
    np.testing.assert_array_equal(data.u, m[:, [0, 1]])


def test_semicolon_csv(tmp_path):
    m = RNG.standard_normal((25, 3))
    f = _write_table(tmp_path / "semi.csv", ["t", "u", "y"], m, delim=";")
    data = read(f, inputs="u", outputs="y")
    np.testing.assert_array_equal(data.u[:, 0], m[:, 1])
    np.testing.assert_array_equal(data.y[:, 0], m[:, 2])


def test_tab_separated_csv_and_explicit_delimiter(tmp_path):
    m = RNG.standard_normal((15, 3))
    f = _write_table(tmp_path / "tab.csv", ["t", "u", "y"], m, delim="\t")
    data = read(f, inputs="u", outputs="y")
    np.testing.assert_array_equal(data.y[:, 0], m[:, 2])
    g = _write_table(tmp_path / "pipe.txt", ["t", "u", "y"], m, delim="|")
    data = read(g, inputs="u", outputs="y", delimiter="|")
    np.testing.assert_array_equal(data.u[:, 0], m[:, 1])


def test_quoted_header_and_bom(tmp_path):
    f = tmp_path / "q.csv"
    f.write_bytes(b'\xef\xbb\xbf"time","input u","output y"\r\n0,1.5,2\r\n1,2.5,3\r\n')
    data = read(f, inputs="input u", outputs="output y", time="time")
    np.testing.assert_array_equal(data.u[:, 0], [1.5, 2.5])
    assert data.input_names == ("input u",)


def test_whitespace_dat_trailing_tabs_crlf_three_digit_exponents(tmp_path):
    m = np.array([[1.0, 0.3, 98.6281], [2.0, 0.31, 98.5], [3.0, -1.25e-5, 1.0e100]])
    text = "".join(f"  {a:.7e}\t {b:.7e}\t{c:.7e}\t\r\n" for a, b, c in m)
    # three-digit exponents as in DaISy's exchanger.dat: 1.0000000e+000
    text = text.replace("e+00", "e+000").replace("e-05", "e-005").replace("e+100", "e+100")
    assert "e+000" in text and "\t\r\n" in text
    f = tmp_path / "daisy.dat"
    f.write_bytes(text.encode())
    data = read(f, inputs=1, outputs=2)
    np.testing.assert_array_equal(data.u[:, 0], m[:, 1])
    np.testing.assert_array_equal(data.y[:, 0], m[:, 2])
    assert data.input_names == ("col1",)


def test_whitespace_txt_with_header_line(tmp_path):
    f = tmp_path / "h.txt"
    f.write_text("t   u\ty\n0  1 2\n1\t3   4\n\n")
    data = read(f, inputs="u", outputs="y", time="t")
    np.testing.assert_array_equal(data.u[:, 0], [1, 3])
    np.testing.assert_array_equal(data.t, [0, 1])


def test_comment_header_numpy_savetxt(tmp_path):
    m = RNG.standard_normal((12, 3))
    f = tmp_path / "saved.txt"
    np.savetxt(f, m, header="t u y", fmt="%.17g")
    data = read(f, inputs="u", outputs="y")
    np.testing.assert_array_equal(data.u[:, 0], m[:, 1])
    assert data.output_names == ("y",)


def test_comma_txt_is_delimited(tmp_path):
    m = RNG.standard_normal((8, 2))
    f = _write_table(tmp_path / "c.txt", None, m)
    data = read(f, inputs=0, outputs=1)
    np.testing.assert_array_equal(data.y[:, 0], m[:, 1])


def test_non_uniform_time_column(tmp_path):
    t = np.cumsum(RNG.uniform(0.1, 1.0, 40))
    m = np.column_stack([t, RNG.standard_normal((40, 2))])
    f = _write_table(tmp_path / "nu.csv", ["t", "u", "y"], m)
    data = read(f, inputs="u", outputs="y", time="t")
    assert data.dt is None
    assert not data.is_uniform
    np.testing.assert_array_equal(data.t, t)


def test_text_in_unselected_columns_is_allowed(tmp_path):
    f = tmp_path / "log.csv"
    f.write_text("date,u,y,comment\n2024-01-01,1,2,ok\n2024-01-02,3,4,\n\n   \n"
                 "2024-01-03,5,6,late\n")
    data = read(f, inputs="u", outputs="y")
    np.testing.assert_array_equal(data.u[:, 0], [1, 3, 5])
    np.testing.assert_array_equal(data.y[:, 0], [2, 4, 6])


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=st.lists(st.tuples(*[st.floats(allow_nan=False, allow_infinity=False,
                                             width=64)] * 3), min_size=1, max_size=20),
       delim=st.sampled_from([",", ";", "\t"]))
def test_csv_round_trip_property(tmp_path, values, delim):
    m = np.array(values, dtype=float)
    f = _write_table(tmp_path / "p.csv", ["a", "b", "c"], m, delim=delim)
    data = read(f, inputs=["a", "c"], outputs="b")
    np.testing.assert_array_equal(data.u, m[:, [0, 2]])
    np.testing.assert_array_equal(data.y[:, 0], m[:, 1])


def test_npz_defaults_and_channel_names(tmp_path):
    u = RNG.standard_normal((100, 2))
    y = RNG.standard_normal(100)
    f = tmp_path / "rec.npz"
    np.savez(f, u=u, y=y, dt=np.float64(0.05))
    data = read(f)
    np.testing.assert_array_equal(data.u, u)
    np.testing.assert_array_equal(data.y[:, 0], y)
    assert data.input_names == ("u[0]", "u[1]")
    assert data.output_names == ("y",)
    assert data.dt == 0.05
    # an explicit dt wins over the file's dt
    assert read(f, dt=2.0).dt == 2.0


def test_npz_named_arrays_and_time(tmp_path):
    t = np.cumsum(RNG.uniform(0.5, 1.5, 30))
    a, b, c = RNG.standard_normal((3, 30))
    f = tmp_path / "named.npz"
    np.savez_compressed(f, force=a, torque=b, pos=c.reshape(-1, 1), stamps=t)
    data = read(f, inputs="force,torque", outputs=["pos"], time="stamps")
    np.testing.assert_array_equal(data.u, np.column_stack([a, b]))
    np.testing.assert_array_equal(data.y[:, 0], c)
    assert data.input_names == ("force", "torque")
    assert data.output_names == ("pos",)
    assert data.dt is None
    np.testing.assert_array_equal(data.t, t)


def test_npz_default_time_key(tmp_path):
    t = np.arange(10) * 0.2 + 5.0
    f = tmp_path / "t.npz"
    np.savez(f, u=np.ones(10), y=np.arange(10.0), t=t)
    data = read(f)
    np.testing.assert_array_equal(data.t, t)
    assert data.dt == pytest.approx(0.2)


def test_mat_round_trip(tmp_path):
    n = 64
    u = RNG.standard_normal(n)                # saved as a 1 x N row vector
    y = RNG.standard_normal((n, 2))
    f = tmp_path / "rec.mat"
    scipy.io.savemat(f, {"u": u, "y": y, "dt": 0.01})
    assert scipy.io.loadmat(f)["u"].shape == (1, n)
    data = read(f)
    np.testing.assert_array_equal(data.u[:, 0], u)
    np.testing.assert_array_equal(data.y, y)
    assert data.input_names == ("u",)
    assert data.output_names == ("y[0]", "y[1]")
    assert data.dt == 0.01


def test_mat_column_vectors_and_time(tmp_path):
    n = 40
    t = np.cumsum(RNG.uniform(0.1, 0.2, n))
    u1, u2, y = RNG.standard_normal((3, n))
    f = tmp_path / "cols.mat"
    scipy.io.savemat(f, {"u1": u1[:, None], "u2": u2[:, None], "out": y[:, None],
                         "time": t[:, None]})
    data = read(f, inputs=["u1", "u2"], outputs="out", time="time")
    np.testing.assert_array_equal(data.u, np.column_stack([u1, u2]))
    np.testing.assert_array_equal(data.y[:, 0], y)
    np.testing.assert_array_equal(data.t, t)
    assert data.input_names == ("u1", "u2")


def test_large_csv_is_fast(tmp_path):
    n = 200_000
    m = RNG.standard_normal((n, 3))
    f = tmp_path / "big.csv"
    np.savetxt(f, m, delimiter=",", fmt="%.17g", header="t,u,y", comments="")
    start = _time.perf_counter()
    data = read(f, inputs="u", outputs="y")
    elapsed = _time.perf_counter() - start
    np.testing.assert_array_equal(data.y[:, 0], m[:, 2])
    assert elapsed < 5.0


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------
def test_missing_file(tmp_path):
    f = tmp_path / "nothere.csv"
    with pytest.raises(DataFileNotFoundError, match="nothere.csv") as info:
        read(f, inputs=0, outputs=1)
    assert isinstance(info.value, FileNotFoundError)
    assert isinstance(info.value, FileReadError)
    assert info.value.path == str(f)


@pytest.mark.parametrize("name", ["empty.csv", "empty.dat", "empty.npz", "empty.mat"])
def test_empty_file(tmp_path, name):
    f = tmp_path / name
    f.write_bytes(b"")
    with pytest.raises(FileReadError, match=f"file .*{name} is empty"):
        read(f, inputs=0, outputs=1) if name.endswith((".csv", ".dat")) else read(f)


def test_blank_file_and_header_only(tmp_path):
    f = tmp_path / "blank.csv"
    f.write_text("\n   \n\n")
    with pytest.raises(FileReadError, match="blank.csv is empty"):
        read(f, inputs=0, outputs=1)
    g = tmp_path / "head.csv"
    g.write_text("t,u,y\n")
    with pytest.raises(FileReadError, match="head.csv has a header .*no data"):
        read(g, inputs="u", outputs="y")


def test_non_numeric_cell_names_line_and_column(tmp_path):
    rows = [[k, 2.0 * k, 3.0 * k] for k in range(20)]
    f = _write_table(tmp_path / "data.csv", ["t", "u1", "y1"], rows)
    lines = f.read_text().splitlines()
    fields = lines[16].split(",")
    fields[2] = "abc"
    lines[16] = ",".join(fields)
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileReadError) as info:
        read(f, inputs="u1", outputs="y1")
    msg = str(info.value)
    assert "data.csv, line 17, column 2 ('y1'): 'abc' is not a number" in msg
    assert info.value.line == 17
    assert info.value.column == 2
    assert info.value.path == str(f)


def test_non_numeric_cell_without_header(tmp_path):
    f = tmp_path / "raw.dat"
    f.write_text("1 2 3\n4 5 6\n7 x8 9\n")
    with pytest.raises(FileReadError) as info:
        read(f, inputs=0, outputs=1)
    assert "raw.dat, line 3, column 1: 'x8' is not a number" in str(info.value)
    assert (info.value.line, info.value.column) == (3, 1)


def test_empty_cell_and_decimal_comma(tmp_path):
    f = tmp_path / "gap.csv"
    f.write_text("u,y\n1,2\n3,\n")
    with pytest.raises(FileReadError, match=r"gap.csv, line 3, column 1 \('y'\): .*missing"):
        read(f, inputs="u", outputs="y")
    g = tmp_path / "euro.csv"
    g.write_text("u;y\n1,5;2,25\n")
    with pytest.raises(FileReadError, match=r"euro.csv, line 2, column 0 .*'1,5'.*decimal"):
        read(g, inputs="u", outputs="y")


def test_ragged_rows(tmp_path):
    f = tmp_path / "ragged.csv"
    f.write_text("t,u,y\n0,1,2\n1,2,3\n2,3\n3,4,5\n")
    with pytest.raises(FileReadError) as info:
        read(f, inputs="u", outputs="y")
    msg = str(info.value)
    assert "ragged.csv, line 4" in msg and "found 2 fields, expected 3" in msg
    assert info.value.line == 4
    g = tmp_path / "ragged.dat"
    g.write_text("1 2 3\n4 5 6 7\n")
    with pytest.raises(FileReadError, match=r"ragged.dat, line 2: found 4 fields, expected 3"):
        read(g, inputs=0, outputs=1)


def test_ragged_row_in_unselected_column_still_fails(tmp_path):
    f = tmp_path / "r.csv"
    f.write_text("u,y,z\n1,2,3\n1,2,3,4\n")
    with pytest.raises(FileReadError, match="line 3: found 4 fields, expected 3"):
        read(f, inputs="u", outputs="y")


def test_unknown_column_lists_available(tmp_path):
    f = _write_table(tmp_path / "names.csv", ["t", "u", "y"], [[0, 1, 2]])
    with pytest.raises(FileReadError) as info:
        read(f, inputs="v", outputs="y")
    msg = str(info.value)
    assert "names.csv" in msg and "'v'" in msg
    assert "0 't', 1 'u', 2 'y'" in msg
    assert info.value.column == "v"


def test_name_on_headerless_file(tmp_path):
    f = _write_table(tmp_path / "nh.csv", None, [[0, 1, 2]])
    with pytest.raises(FileReadError, match=r"nh.csv: .*'u'.*no header.*indices 0 to 2"):
        read(f, inputs="u", outputs=1)


def test_index_out_of_range(tmp_path):
    f = _write_table(tmp_path / "oor.csv", None, [[0, 1, 2]])
    with pytest.raises(FileReadError, match=r"oor.csv: column index 3 .* 3 columns") as info:
        read(f, inputs=0, outputs=3)
    assert info.value.column == 3
    with pytest.raises(FileReadError, match="out of range"):
        read(f, inputs=-1, outputs=1)


@pytest.mark.parametrize("inputs,outputs,time", [
    ("u", "u", None), (["u", "u"], "y", None), ("u", "y", "u"), (1, "u", None),
])
def test_column_used_twice(tmp_path, inputs, outputs, time):
    f = _write_table(tmp_path / "dup.csv", ["t", "u", "y"], [[0, 1, 2], [1, 2, 3]])
    with pytest.raises(FileReadError, match=r"dup.csv: column 1 \('u'\) is (selected twice|"
                                            r"used both)"):
        read(f, inputs=inputs, outputs=outputs, time=time)


def test_inputs_outputs_required_for_text(tmp_path):
    f = _write_table(tmp_path / "req.csv", ["t", "u", "y"], [[0, 1, 2]])
    with pytest.raises(FileReadError, match=r"req.csv: outputs must be given.*0 't', 1 'u'"):
        read(f, inputs="u")
    with pytest.raises(FileReadError, match=r"inputs and outputs must be given"):
        read(f)


def test_dt_and_time_both_given(tmp_path):
    f = _write_table(tmp_path / "both.csv", ["t", "u", "y"], [[0, 1, 2], [1, 2, 3]])
    with pytest.raises(DataError, match="not both"):
        read(f, inputs="u", outputs="y", dt=0.1, time="t")


def test_nan_cell_is_data_error_with_line(tmp_path):
    f = tmp_path / "nan.csv"
    f.write_text("u,y\n1,2\n\n3,nan\n4,5\n")
    with pytest.raises(DataError, match=r"nan.csv, line 4, column 1 \('y'\): 'nan' is not "
                                        r"a finite"):
        read(f, inputs="u", outputs="y")


def test_bad_time_column_names_file(tmp_path):
    f = _write_table(tmp_path / "back.csv", ["t", "u", "y"], [[0, 1, 2], [2, 1, 2], [1, 1, 2]])
    with pytest.raises(DataError, match=r"back.csv: time stamps .*not increasing"):
        read(f, inputs="u", outputs="y", time="t")


def test_binary_text_file(tmp_path):
    f = tmp_path / "bin.csv"
    f.write_bytes(b"PK\x03\x04\x00\x00binary")
    with pytest.raises(FileReadError, match="bin.csv looks like a binary file"):
        read(f, inputs=0, outputs=1)


def test_unsupported_extension(tmp_path):
    f = tmp_path / "sheet.xlsx"
    f.write_bytes(b"x")
    with pytest.raises(FileReadError, match=r"sheet.xlsx: unsupported .*\.csv.*\.npz.*\.mat"):
        read(f, inputs=0, outputs=1)


def test_corrupted_npz(tmp_path):
    f = tmp_path / "bad.npz"
    f.write_bytes(b"this is not a zip archive at all")
    with pytest.raises(FileReadError, match="bad.npz") as info:
        read(f)
    assert info.value.path == str(f)
    # a truncated archive
    good = tmp_path / "good.npz"
    np.savez(good, u=np.arange(1000.0), y=np.arange(1000.0))
    raw = good.read_bytes()
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(FileReadError, match="trunc.npz"):
        read(trunc)
    # a damaged member (bytes flipped inside a compressed array)
    comp = tmp_path / "comp.npz"
    np.savez_compressed(comp, u=RNG.standard_normal(5000), y=RNG.standard_normal(5000))
    raw = bytearray(comp.read_bytes())
    for k in range(200, 400):
        raw[k] ^= 0xFF
    comp.write_bytes(bytes(raw))
    with pytest.raises(FileReadError, match="comp.npz"):
        read(comp)


def test_npz_pickled_object_array_is_wrapped(tmp_path):
    f = tmp_path / "obj.npz"
    np.savez(f, u=np.array([{"a": 1}], dtype=object), y=np.ones(1))
    with pytest.raises(FileReadError, match="obj.npz"):
        read(f)


def test_npz_missing_default_and_unknown_key(tmp_path):
    f = tmp_path / "keys.npz"
    np.savez(f, inp=np.ones(5), out=np.zeros(5))
    with pytest.raises(FileReadError, match=r"keys.npz: no array named 'u'.*'inp', 'out'"):
        read(f)
    with pytest.raises(FileReadError, match=r"keys.npz: no array named 'x'.*'inp', 'out'"):
        read(f, inputs="x", outputs="out")
    with pytest.raises(FileReadError, match=r"keys.npz: the array 'inp' is used both"):
        read(f, inputs="inp", outputs="inp")
    with pytest.raises(FileReadError, match=r"keys.npz: inputs selects arrays .* by name"):
        read(f, inputs=0, outputs="out")


def test_npz_bad_shapes(tmp_path):
    f = tmp_path / "shape.npz"
    np.savez(f, u=np.ones((4, 2, 2)), y=np.ones(4), z=np.ones(3), s=np.array(["a", "b"]))
    with pytest.raises(FileReadError, match=r"shape.npz: 'u' has 3 dimensions"):
        read(f)
    with pytest.raises(FileReadError, match=r"shape.npz: the input arrays have different"):
        read(f, inputs="y,z", outputs="s")
    with pytest.raises(FileReadError, match=r"shape.npz: the array 's' is text"):
        read(f, inputs="y", outputs="s")


def test_corrupted_mat(tmp_path):
    f = tmp_path / "bad.mat"
    f.write_bytes(b"\x01\x02garbage that is not a MAT-file" * 10)
    with pytest.raises(FileReadError, match="bad.mat") as info:
        read(f)
    assert info.value.path == str(f)
    good = tmp_path / "good.mat"
    scipy.io.savemat(good, {"u": np.arange(500.0), "y": np.arange(500.0)})
    raw = good.read_bytes()
    trunc = tmp_path / "trunc.mat"
    trunc.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(FileReadError, match="trunc.mat"):
        read(trunc)


def test_mat_v73_is_explained(tmp_path):
    f = tmp_path / "v73.mat"
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    header = header.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM"
    f.write_bytes(header.ljust(512, b"\x00") + b"\x89HDF\r\n\x1a\n" + b"\x00" * 64)
    # read with h5py when installed (this one is corrupted); else the extra is named
    match = (r"v73.mat is not a readable MATLAB v7.3 \(HDF5\)" if _has_h5py() else
             r"v73.mat is a MATLAB v7.3 \(HDF5\) file; reading it needs h5py: "
             r"install the 'hdf5' extra \(pip install \"\.\[hdf5\]\".*-v7")
    with pytest.raises(FileReadError, match=match):
        read(f)


def _has_h5py():
    try:
        import h5py  # noqa: F401
    except ImportError:
        return False
    return True


def test_mat_unknown_variable_lists_names(tmp_path):
    f = tmp_path / "vars.mat"
    scipy.io.savemat(f, {"volt": np.ones(5), "temp": np.ones(5)})
    with pytest.raises(FileReadError, match=r"vars.mat: no variable named 'u'.*'volt'"):
        read(f)
    data = read(f, inputs="volt", outputs="temp")
    assert data.input_names == ("volt",)


def test_text_selection_argument_types(tmp_path):
    f = _write_table(tmp_path / "a.csv", ["u", "y"], [[1, 2]])
    with pytest.raises(DataError):
        read(f, inputs=1.5, outputs="y")
    with pytest.raises(DataError):
        read(f, inputs=[True], outputs="y")
    with pytest.raises(FileReadError, match="selects no column"):
        read(f, inputs=[], outputs="y")


def test_daisy_file_reads_like_loadtxt():
    from importlib import resources
    ref = resources.files("subid.datasets").joinpath("data", "exchanger.dat")
    with resources.as_file(ref) as path:
        data = read(path, inputs=1, outputs=2, dt=1.0)
        table = np.loadtxt(path)
    np.testing.assert_array_equal(data.u[:, 0], table[:, 1])
    np.testing.assert_array_equal(data.y[:, 0], table[:, 2])


def test_zip_members_are_read_lazily_not_required(tmp_path):
    # an npz written by hand with zipfile: non-array member -> wrapped error
    f = tmp_path / "hand.npz"
    with zipfile.ZipFile(f, "w") as z:
        z.writestr("u.npy", b"not an npy payload")
    with pytest.raises(FileReadError, match="hand.npz"):
        read(f)


def test_bad_cell_after_comments_and_blank_lines(tmp_path):
    f = tmp_path / "noisy.csv"
    f.write_text("# recorded 2024\nt,u,y,note\n\n0,1,2,a\n# pause\n1,2,3,b\n\n2,3,?,c\n3,4,5,d\n")
    with pytest.raises(FileReadError) as info:
        read(f, inputs="u", outputs="y", time="t")
    assert "noisy.csv, line 8, column 2 ('y'): '?' is not a number" in str(info.value)
    assert (info.value.line, info.value.column) == (8, 2)
    # the same file reads once the bad cell is fixed; comments and blanks are skipped
    f.write_text(f.read_text().replace("2,3,?,c", "2,3,4,c"))
    data = read(f, inputs="u", outputs="y", time="t")
    np.testing.assert_array_equal(data.y[:, 0], [2, 3, 4, 5])
    np.testing.assert_array_equal(data.t, [0, 1, 2, 3])


def test_header_and_rows_disagree(tmp_path):
    f = tmp_path / "wide.csv"
    f.write_text("u,y\n1,2,3\n4,5,6\n")
    with pytest.raises(FileReadError, match=r"wide.csv, line 2: found 3 fields, expected 2 "
                                            r"like the header \(line 1\)"):
        read(f, inputs="u", outputs="y")


def test_comma_in_header_name_of_whitespace_file(tmp_path):
    f = tmp_path / "names.dat"
    f.write_text("t  u,ref  y\n0 1 2\n1 3 4\n")
    data = read(f, inputs="u,ref", outputs="y")
    np.testing.assert_array_equal(data.u[:, 0], [1, 3])
    assert data.input_names == ("u,ref",)


def test_npz_t_and_dt_must_agree(tmp_path):
    f = tmp_path / "tdt.npz"
    np.savez(f, u=np.ones(10), y=np.arange(10.0), t=np.arange(10) * 0.1, dt=0.2)
    with pytest.raises(FileReadError, match=r"tdt.npz: the file holds both 't' and 'dt'"):
        read(f)
    assert read(f, dt=0.5).dt == 0.5          # an explicit choice settles it
    g = tmp_path / "ok.npz"
    np.savez(g, u=np.ones(10), y=np.arange(10.0), t=np.arange(10) * 0.2, dt=0.2)
    assert read(g).dt == pytest.approx(0.2)


@pytest.mark.parametrize("careful", [False, True])
@pytest.mark.parametrize("name, warns", [("time", True), ("t", True), ("Time [s]", True),
                                         ("time_s", True), ("Seconds", True),
                                         ("temperature", False), ("tension", False)])
def test_an_unused_time_column_is_named_when_no_sampling_period_is_given(
        tmp_path, monkeypatch, name, warns, careful):
    """A record read without dt or time from a file with a column that looks like time
    stamps: dt = 1 as documented, and a SamplingWarning naming the column (both parsers);
    none when dt or time is given or the column is not time-like."""
    import warnings

    from subid.errors import SamplingWarning
    from subid.io import formats
    if careful:                                       # the careful parser reads the file
        monkeypatch.setattr(formats, "_read_text_fast", lambda *args: None)
    rows = np.column_stack([np.arange(20) * 0.5, RNG.standard_normal((20, 2))])
    f = _write_table(tmp_path / "run.csv", [name, "u", "y"], rows)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = read(f, inputs="u", outputs="y")
        read(f, inputs="u", outputs="y", dt=0.5)
        read(f, inputs="u", outputs="y", time=name)
    assert data.dt == 1.0
    hints = [w for w in caught if issubclass(w.category, SamplingWarning)]
    assert len(hints) == int(warns)
    if warns:
        assert hints[0].message.column == name and repr(name) in str(hints[0].message)
        assert hints[0].filename == __file__           # points at the caller's line


def test_time_column_of_iso_date_times(tmp_path):
    """A time column of ISO 8601 date-times (a historian's export) gives the stamps in
    seconds since the first one; with UTC offsets, converted to UTC, so a change of
    daylight-saving time in between leaves the grid uniform."""
    f = tmp_path / "log.csv"
    f.write_text("timestamp,valve,flow\n"
                 "2024-01-01 00:00:00,0.1,1.0\n2024-01-01 00:00:02,0.2,2.0\n"
                 "2024-01-01 00:00:04,0.3,3.0\n2024-01-01 00:00:06,0.4,4.0\n")
    d = read(f, inputs="valve", outputs="flow", time="timestamp")
    assert d.is_uniform and d.dt == 2.0
    np.testing.assert_array_equal(d.y[:, 0], [1.0, 2.0, 3.0, 4.0])
    g = tmp_path / "fractional.csv"
    g.write_text("t;u;y\n2024-03-31T00:59:59.5+01:00;1;2\n2024-03-31T02:00:00+02:00;3;4\n"
                 "2024-03-31T02:00:00.5+02:00;5;6\n")
    d = read(g, inputs="u", outputs="y", time="t")
    np.testing.assert_allclose(d.t, [0.0, 0.5, 1.0])
    assert d.dt == 0.5
    h = tmp_path / "local.csv"
    h.write_text("t,u,y\n01.01.2024 00:00:00,1,2\n01.01.2024 00:00:02,3,4\n")
    with pytest.raises(FileReadError, match="ISO 8601 date-times") as info:
        read(h, inputs="u", outputs="y", time="t")
    assert info.value.line == 2 and info.value.column == 0
    # a date-time in a channel column is no number
    with pytest.raises(FileReadError, match="is not a number"):
        read(f, inputs="timestamp", outputs="flow")


def test_decimal_commas_on_request(tmp_path):
    """``decimal=','`` reads a spreadsheet export of many European locales; the header's
    commas are kept; the delimiter is ';', TAB or spaces (given or found)."""
    g = tmp_path / "euro.csv"
    g.write_text("u [V], raw;y\n1,5;2,25\n-0,125;3e-1\n1,0E+2;4\n")
    with pytest.raises(FileReadError, match="pass decimal=','"):
        read(g, inputs=0, outputs=1)
    d = read(g, inputs="u [V], raw", outputs="y", decimal=",")
    np.testing.assert_array_equal(d.u[:, 0], [1.5, -0.125, 100.0])
    np.testing.assert_array_equal(d.y[:, 0], [2.25, 0.3, 4.0])
    assert d.input_names == ("u [V], raw",)
    tab = tmp_path / "euro.txt"
    tab.write_text("0,5\t1,25\n0,75\t1,5\n")
    np.testing.assert_array_equal(read(tab, inputs=0, outputs=1, decimal=",").y[:, 0],
                                  [1.25, 1.5])
    spaced = tmp_path / "euro.dat"
    spaced.write_text("0,5   1,25\n0,75  1,5\n")
    np.testing.assert_array_equal(read(spaced, inputs=0, outputs=1, decimal=",").u[:, 0],
                                  [0.5, 0.75])
    with pytest.raises(DataError, match="another field delimiter than ','"):
        read(g, inputs=0, outputs=1, decimal=",", delimiter=",")
    with pytest.raises(DataError, match="decimal must be '.' or ','"):
        read(g, inputs=0, outputs=1, decimal=";")
    np.savez(tmp_path / "a.npz", u=np.ones(3), y=np.ones(3))
    with pytest.raises(DataError, match="decimal applies to text files only"):
        read(tmp_path / "a.npz", decimal=",")


def test_second_header_row_is_named_as_such(tmp_path):
    f = tmp_path / "units.csv"
    f.write_text("time,u,y\ns,V,m\n0,1,2\n1,3,4\n")
    with pytest.raises(FileReadError, match=r"line 2 holds no number at all: a second "
                                            r"header row, such as the units\? remove it"):
        read(f, inputs="u", outputs="y", time="time")
    g = tmp_path / "text.csv"
    g.write_text("time,u,y\n0,V,2\n")              # a number elsewhere on the line: no hint
    with pytest.raises(FileReadError) as info:
        read(g, inputs="u", outputs="y", time="time")
    assert "second header row" not in str(info.value)
