"""MATLAB v7.3 (HDF5) files (issue 16 item 9), written here with h5py as MATLAB
lays them out: a 512-byte user block starting with the MATLAB header, each
variable a dataset in column-major order (HDF5 shape reversed) with a
``MATLAB_class`` attribute, a struct a group."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import subid
from subid import errors

h5py = pytest.importorskip("h5py")

RNG = np.random.default_rng(73)


def _header(fh_path):
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    with open(fh_path, "r+b") as fh:
        fh.write(text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")


def _put(group, name, value, cls="double"):
    value = np.asarray(value)
    if value.ndim < 2:
        value = value.reshape(1, -1)
    if np.iscomplexobj(value):
        compound = np.empty(value.T.shape, dtype=[("real", "<f8"), ("imag", "<f8")])
        compound["real"], compound["imag"] = value.T.real, value.T.imag
        ds = group.create_dataset(name, data=compound)
    else:
        ds = group.create_dataset(name, data=value.T, compression="gzip")
    ds.attrs["MATLAB_class"] = np.bytes_(cls)
    return ds


def _write(path, variables, structs=None):
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name, value in variables.items():
            _put(fh, name, value)
        for name, fields in (structs or {}).items():
            group = fh.create_group(name)
            group.attrs["MATLAB_class"] = np.bytes_("struct")
            for key, value in fields.items():
                _put(group, key, value)
    _header(path)


def test_read_v73_like_v5(tmp_path):
    import scipy.io
    u, y = RNG.standard_normal((500, 2)), RNG.standard_normal(500)
    v73, v5 = tmp_path / "rec73.mat", tmp_path / "rec5.mat"
    _write(v73, {"u": u, "y": y[:, None], "dt": 0.1})
    scipy.io.savemat(v5, {"u": u, "y": y[:, None], "dt": 0.1})
    a, b = subid.read(v73), subid.read(v5)
    np.testing.assert_array_equal(a.u, b.u)
    np.testing.assert_array_equal(a.y, b.y)
    assert a.dt == b.dt == 0.1 and a.input_names == b.input_names
    row = tmp_path / "row.mat"                        # a 1-by-N row vector is one channel
    _write(row, {"u": u[:, 0][None, :], "y": y[None, :]})
    np.testing.assert_array_equal(subid.read(row).y[:, 0], y)


def test_model_from_v73_struct_and_variables(tmp_path):
    model = subid.systems.seed001_system()
    fields = {"A": model.A, "B": model.B, "C": model.C, "D": model.D, "Ts": model.dt}
    flat, packed = tmp_path / "m.mat", tmp_path / "s.mat"
    _write(flat, fields)
    _write(packed, {}, structs={"sys": fields})
    for path in (flat, packed):
        loaded = subid.StateSpace.from_mat(path)
        for key in "ABCD":
            np.testing.assert_array_equal(getattr(loaded, key), getattr(model, key))
        assert loaded.dt == model.dt


def test_v73_complex_and_cells_are_refused_by_name(tmp_path):
    model = subid.systems.seed001_system()
    path = tmp_path / "c.mat"
    _write(path, {"A": model.A + 0j, "B": model.B, "C": model.C, "D": model.D, "Ts": 1.0})
    with pytest.raises(errors.ModelError, match="A is complex"):
        subid.StateSpace.from_mat(path)
    data = tmp_path / "cell.mat"
    _write(data, {"u": np.ones((10, 1))})
    with h5py.File(data, "a") as fh:
        ds = fh.create_dataset("y", data=np.zeros((1, 1), dtype=np.uint64))
        ds.attrs["MATLAB_class"] = np.bytes_("cell")
    with pytest.raises(errors.FileReadError, match="'y' is a cell array"):
        subid.read(data)


def test_v73_declaring_more_than_max_bytes_is_refused_without_reading(tmp_path):
    path = tmp_path / "bomb.mat"
    with h5py.File(path, "w", userblock_size=512) as fh:
        ds = fh.create_dataset("u", shape=(4, 20_000_000), dtype="<f8", chunks=(1, 1_000_000),
                               compression="gzip")        # never written: all fill value
        ds.attrs["MATLAB_class"] = np.bytes_("double")
        _put(fh, "y", np.ones(10))
    _header(path)
    assert path.stat().st_size < 1_000_000
    with pytest.raises(errors.ResourceLimitError, match="max_bytes"):
        subid.read(path, max_bytes=100_000_000)


def test_corrupted_v73_is_a_file_read_error(tmp_path):
    path = tmp_path / "v73.mat"
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    header = header.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM"
    path.write_bytes(header.ljust(512, b"\x00") + b"\x89HDF\r\n\x1a\n" + b"\x00" * 64)
    with pytest.raises(errors.FileReadError, match="not a readable MATLAB v7.3"):
        subid.read(path)
    good = tmp_path / "good.mat"
    _write(good, {"u": np.ones((50, 1)), "y": np.arange(50.0)[:, None]})
    raw = bytearray(good.read_bytes())
    for cut in (600, len(raw) // 2, len(raw) - 10):
        (tmp_path / "cut.mat").write_bytes(bytes(raw[:cut]))
        with pytest.raises(errors.FileReadError):
            subid.read(tmp_path / "cut.mat")


def test_without_h5py_the_message_names_the_extra(tmp_path, monkeypatch):
    path = tmp_path / "rec.mat"
    _write(path, {"u": np.ones((5, 1)), "y": np.ones((5, 1))})
    monkeypatch.setitem(sys.modules, "h5py", None)     # import h5py raises ImportError
    for fn in (lambda: subid.read(path), lambda: subid.StateSpace.from_mat(path)):
        with pytest.raises(errors.FileReadError, match=r"'hdf5' extra \(pip install \"\.\[hdf5\]\""):
            fn()
