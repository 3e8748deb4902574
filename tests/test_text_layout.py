"""Text files: ``#`` lines, spreadsheet markers, header detection, delimiters and the
chunked reader against :func:`subid.read`."""

import numpy as np
import pytest

import subid
from subid.errors import FileReadError


def test_excel_missing_marker_row_is_reported_not_dropped(tmp_path):
    f = tmp_path / "na.csv"
    f.write_text("u,y\n#N/A,2\n3,4\n5,6\n7,8\n")
    with pytest.raises(FileReadError) as info:
        subid.read(f, inputs="u", outputs="y")
    assert "line 2, column 0 ('u'): '#N/A' is not a number (a missing-value marker" \
        in str(info.value)
    assert (info.value.line, info.value.column) == (2, 0)
    # a header-less file starting with the marker: a data row, not a comment or header
    f.write_text("#N/A,2\n3,4\n")
    with pytest.raises(FileReadError, match="line 1, column 0: '#N/A' is not a number"):
        subid.read(f, inputs=0, outputs=1)
    # in the chunked reader too
    f.write_text("u,y\n1,2\n#DIV/0!,2\n3,4\n")
    with pytest.raises(FileReadError, match="line 3, column 0 \\('u'\\): '#DIV/0!'"):
        list(subid.read_chunks(f, inputs="u", outputs="y", chunk_size=2))


def test_hash_inside_a_field_is_not_a_comment(tmp_path):
    f = tmp_path / "valves.csv"
    f.write_text("t,Valve #1,Flow #1\n0,1,2\n0.1,3,4\n")
    d = subid.read(f, inputs="Valve #1", outputs=2, time=0)
    assert d.input_names == ("Valve #1",) and d.output_names == ("Flow #1",)
    np.testing.assert_array_equal(d.y[:, 0], [2, 4])
    f.write_text("t,u,y\n0,1,2\n0.1,#N/A,4\n")
    with pytest.raises(FileReadError, match="line 3, column 1 \\('u'\\): '#N/A' is not a "
                                            "number"):
        subid.read(f, inputs="u", outputs="y", time="t")


def test_whole_comment_lines_are_still_skipped(tmp_path):
    f = tmp_path / "c.csv"
    f.write_text("# recorded by hand\nu,y\n1,2\n# pause\n3,4\n")
    d = subid.read(f, inputs="u", outputs="y")
    np.testing.assert_array_equal(d.u[:, 0], [1, 3])
    pieces = list(subid.read_chunks(f, inputs="u", outputs="y", chunk_size=1))
    assert [p.u[0, 0] for p in pieces] == [1, 3]


def test_date_time_first_row_is_data_not_header(tmp_path):
    f = tmp_path / "log.csv"
    f.write_text("2024-01-01 00:00:00,1.0,2.0\n2024-01-01 00:00:01,3.0,4.0\n"
                 "2024-01-01 00:00:02,5.0,6.0\n2024-01-01 00:00:03,7.0,8.0\n")
    d = subid.read(f, inputs=1, outputs=2, time=0)
    assert d.n_samples == 4
    np.testing.assert_array_equal(d.u[:, 0], [1, 3, 5, 7])
    assert d.dt == 1.0


def test_would_be_header_with_numbers_selected_by_index_is_refused(tmp_path):
    f = tmp_path / "status.csv"
    f.write_text("ok,1.0,2.0\nok,3.0,4.0\nok,5,6\n")
    with pytest.raises(FileReadError, match="line 1 was taken as the header .* column 1, "
                                            "selected by index in inputs, is the value '1.0'"):
        subid.read(f, inputs=1, outputs=2)
    # a real header selected by name is fine
    f.write_text("status,1,2\nok,3.0,4.0\nok,5,6\n")
    assert subid.read(f, inputs="1", outputs="2").n_samples == 2


@pytest.mark.parametrize("ext", [".txt", ".dat"])
def test_tab_delimited_txt_keeps_names_with_spaces(tmp_path, ext):
    f = tmp_path / f"excel{ext}"
    f.write_text("Time [s]\tInput [V]\tOutput [m]\n0\t1\t2\n0.1\t3\t4\n0.2\t5\t6\n")
    d = subid.read(f, inputs="Input [V]", outputs="Output [m]", time="Time [s]")
    np.testing.assert_array_equal(d.u[:, 0], [1, 3, 5])
    # an empty cell is a missing value, not a shorter row
    f.write_text("t\tu\ty\n0\t1\t2\n0.1\t\t4\n0.2\t5\t6\n")
    with pytest.raises(FileReadError, match="line 3, column 1 \\('u'\\): the value is missing"):
        subid.read(f, inputs="u", outputs="y", time="t")
    # DaISy style (runs of spaces, a trailing TAB) is still whitespace-delimited
    f.write_text("".join(f"  {k:.7e}  {2 * k:.7e}\t\n" for k in range(5)))
    np.testing.assert_array_equal(subid.read(f, inputs=0, outputs=1).y[:, 0], 2 * np.arange(5))


def test_tab_hint_when_names_are_split(tmp_path):
    f = tmp_path / "mixed.txt"
    f.write_text("Time [s]\tInput [V]\tOutput [m]\n0\t1\t2\n0.1 5\t3\t4\n")
    with pytest.raises(FileReadError, match="pass delimiter='\\\\t'"):
        subid.read(f, inputs="Input [V]", outputs="Output [m]")


def test_read_chunks_reads_a_header_and_row_beyond_one_mib(tmp_path):
    f = tmp_path / "wide.csv"
    n = 120_000                                   # header and each row ~0.5-0.8 MiB
    with open(f, "w") as fh:
        fh.write(",".join(f"c{k}" for k in range(n)) + "\n")
        for r in range(5):
            fh.write(",".join(str(r) for _ in range(n)) + "\n")
    assert subid.read(f, inputs="c0", outputs="c1").n_samples == 5
    pieces = list(subid.read_chunks(f, "c0", "c1"))
    np.testing.assert_array_equal(np.vstack([p.u for p in pieces])[:, 0], np.arange(5))


def test_read_chunks_reads_latin1_past_the_head_as_read_does(tmp_path):
    f = tmp_path / "notes.csv"
    rows = "".join(f"{k},{2 * k},ok\n" for k in range(150_000))       # > 1 MiB of ASCII
    f.write_bytes(b"u,y,note\n" + rows.encode() + b"7,8,caf\xe9\n")
    whole = subid.read(f, "u", "y")
    pieces = list(subid.read_chunks(f, "u", "y", chunk_size=100_000))
    np.testing.assert_array_equal(np.vstack([p.y for p in pieces]), whole.y)
    # a UTF-8 head (a name beyond ASCII) then a Latin-1 byte: the exact line is named
    f.write_bytes("u,y\u00e9,note\n".encode() + rows.encode() + b"7,8,caf\xe9\n")
    with pytest.raises(FileReadError, match="line 150002: the file is not UTF-8 text"):
        list(subid.read_chunks(f, "u", "y\u00e9"))


def test_read_chunks_npy_refuses_a_column_as_input_and_output(tmp_path):
    f = tmp_path / "a.npy"
    np.save(f, np.arange(20.0).reshape(10, 2))
    with pytest.raises(FileReadError, match="column 0 is used both as an input and as an "
                                            "output"):
        next(iter(subid.read_chunks(f, [0], [0])))
    with pytest.raises(FileReadError, match="column 1 is selected twice in inputs"):
        next(iter(subid.read_chunks(f, [1, 1], [0])))
    assert next(iter(subid.read_chunks(f, [1], [0]))).n_samples == 10
