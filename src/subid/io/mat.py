"""MATLAB files: :func:`mat_variables`, the one validated MAT loader (v4, v5, v7.3 through
h5py), and the ``ss``/``idpoly`` fields of models (:func:`write_mat_model`,
:func:`read_mat_model`)."""

from __future__ import annotations

import numbers
import os
from io import BytesIO
from pathlib import Path

import numpy as np

from subid._validation import same_period
from subid.delay import absorb_delay, input_delay_of
from subid.errors import FileReadError, ModelError, ResourceLimitError
from subid.io._common import _HDF5_SIGNATURE, _max_bytes, _reason
from subid.io._files import atomic_write, read_regular


def mat_variables(path, *, raw=None, max_bytes=None, mat_dtype=False, what="data file"
                  ) -> dict:
    """The variables of a MATLAB file, read through the validated path.

    The file is opened once as a regular file (:func:`subid.io._files.read_regular`),
    its structure is validated (v4 headers, every v5 matrix, compressed
    elements inflated within ``max_bytes``) and only then given to
    :func:`scipy.io.loadmat`, from memory. Used by :func:`read` and by
    :func:`subid.interop.load_mat`.
    """
    shown = os.fspath(path)
    if raw is None:
        raw = read_regular(shown, what=what, max_bytes=None)
        if not raw:
            raise FileReadError(f"file {shown} is empty", path=shown)
    head = raw[:520]
    if b"MATLAB 7.3" in head[:128] or head[512:520] == _HDF5_SIGNATURE \
            or head[:8] == _HDF5_SIGNATURE:
        return _mat73_variables(raw, shown, _max_bytes(max_bytes))
    import scipy.io
    _check_mat_sizes(raw, shown, _max_bytes(max_bytes))
    try:
        return scipy.io.loadmat(BytesIO(raw), squeeze_me=False, mat_dtype=mat_dtype)
    except NotImplementedError:
        raise FileReadError(
            f"{shown} is a MATLAB v7.3 (HDF5) file, which subid cannot read; save it with "
            "save(..., '-v7') in MATLAB, or export the data to CSV", path=shown) from None
    except MemoryError:
        raise
    except Exception as exc:  # scipy raises ValueError, MatReadError, TypeError, OSError, ...
        raise FileReadError(f"{shown} is not a readable MATLAB .mat file (corrupted or not a "
                            f"MAT-file): {_reason(exc)}", path=shown) from None


_MAT_FIELDS = ("A", "B", "C", "D", "Ts")


def write_mat_model(model, path) -> None:
    """Write ``model`` as the fields of MATLAB's ``ss(A, B, C, D, Ts)`` (atomically).

    The writer behind :func:`subid.interop.save_mat` and
    :meth:`subid.StateSpace.to_mat` (which documents the variables).

    Parameters
    ----------
    model : StateSpace
        The model (read through its public attributes). Its input delays become
        extra states (:func:`subid.absorb_delay`, which drops the polynomials whose
        ``nk`` they were); the ``idpoly`` fields are written for a discrete-time
        polynomial model only (the polynomials are in ``q^-1``).
    path : str or os.PathLike
        The ``.mat`` file.
    """
    import scipy.io
    if input_delay_of(model) is not None:     # MATLAB's ss fields here carry no delays
        model = absorb_delay(model)
    path = os.fspath(path)
    names_in = np.empty((1, model.n_inputs), dtype=object)
    names_in[0, :] = list(model.input_names)
    names_out = np.empty((1, model.n_outputs), dtype=object)
    names_out[0, :] = list(model.output_names)
    variables = {
        "A": np.array(model.A), "B": np.array(model.B), "C": np.array(model.C),
        "D": np.array(model.D), "Ts": np.array([[float(model.dt)]]),
        "InputName": names_in, "OutputName": names_out,
        "subid_format": "subid.StateSpace",
    }
    if model.hold != "zoh":                      # the input hold it assumes (subid only)
        variables["subid_hold"] = model.hold
    poly = (model.info or {}).get("polynomials")
    if isinstance(poly, dict) and "structure" in poly and not model.is_continuous:
        for key in ("A", "B", "C", "D"):          # the realisation under subid's names
            variables[f"subid_ss_{key}"] = variables.pop(key)
        variables.update(_idpoly_fields(poly))
        variables["subid_format"] = "subid.idpoly"
    if model.K is not None:                      # MATLAB idss fields
        variables["K"] = np.array(model.K)
    if model.noise_cov is not None:
        variables["NoiseVariance"] = np.array(model.noise_cov)
    with atomic_write(path, "wb") as fh:
        scipy.io.savemat(fh, variables, format="5", do_compression=False, oned_as="row")


def _trimmed(coef) -> np.ndarray:
    coef = np.asarray(coef, dtype=float).ravel()
    nz = np.flatnonzero(coef)
    return coef[:int(nz[-1]) + 1 if nz.size else 1]


def _idpoly_fields(poly: dict) -> dict:
    """MATLAB ``idpoly`` variables of a polynomial model's ``info['polynomials']``
    (:mod:`subid.model.polynomial`): ``A`` (ny x ny), ``B``, ``F`` (ny x nu), ``C``,
    ``D`` (ny x 1) cell arrays of row vectors in ``q^-1`` (``B`` with its ``nk``
    leading zeros), ``nk`` (ny x nu) and ``structure``."""
    A, B, C, D, F = (np.asarray(poly[k], dtype=float) for k in ("A", "B", "C", "D", "F"))
    ny, nu = B.shape[0], B.shape[1]
    nk = np.asarray(poly["nk"], dtype=float).reshape(ny, nu)

    def cells(rows, cols, get):
        out = np.empty((rows, cols), dtype=object)
        for i in range(rows):
            for j in range(cols):
                out[i, j] = np.atleast_2d(get(i, j))
        return out

    def b_row(i, j):
        b = _trimmed(B[i, j])
        return b if b.size > nk[i, j] else np.zeros(int(nk[i, j]) + 1)
    return {"A": cells(ny, ny, lambda i, k: _trimmed(A[i, k])), "B": cells(ny, nu, b_row),
            "C": cells(ny, 1, lambda i, _: _trimmed(C[i])),
            "D": cells(ny, 1, lambda i, _: _trimmed(D[i])),
            "F": cells(ny, nu, lambda i, j: _trimmed(F[i, j])), "nk": nk,
            "subid_structure": str(poly["structure"]),
            **{f"subid_{k}": np.asarray(poly[k], dtype=float)
               for k in ("na", "nb", "nc", "nd", "nf")}}


def _from_idpoly_fields(fields: dict, ny: int, nu: int, path: str) -> dict:
    """``info['polynomials']`` from the variables :func:`_idpoly_fields` wrote."""
    def stack(key, rows, cols):
        v = np.asarray(fields[key], dtype=object).reshape(rows, cols)
        items = [[np.asarray(v[i, j], dtype=float).ravel() for j in range(cols)]
                 for i in range(rows)]
        length = max(1, max(len(c) for row in items for c in row))
        out = np.zeros((rows, cols, length))
        for i, row in enumerate(items):
            for j, c in enumerate(row):
                out[i, j, :len(c)] = c
        return out
    try:
        poly = {"structure": "".join(str(c) for c in np.asarray(
                    fields["subid_structure"]).reshape(-1)).strip(),
                "A": stack("A", ny, ny), "B": stack("B", ny, nu), "C": stack("C", ny, 1)[:, 0],
                "D": stack("D", ny, 1)[:, 0], "F": stack("F", ny, nu)}
        for k, shape in (("na", (ny, ny)), ("nb", (ny, nu)), ("nc", (ny,)), ("nd", (ny,)),
                         ("nf", (ny, nu))):
            poly[k] = np.rint(np.asarray(fields[f"subid_{k}"], float)).astype(
                np.int64).reshape(shape)
        poly["nk"] = np.rint(np.asarray(fields["nk"], float)).astype(np.int64).reshape(ny, nu)
    except (KeyError, ValueError, TypeError) as exc:
        raise ModelError(f"model file '{path}': the idpoly fields written by subid are "
                         f"incomplete or malformed ({exc})") from None
    return poly


def _cell_strings(value, key: str, path: str, count: int) -> list[str] | None:
    """Channel names from a MATLAB cell array (or char matrix); None when absent/empty."""
    arr = np.asarray(value)
    if arr.size == 0:
        return None
    if arr.dtype.kind in "US":
        items = [str(s).strip() for s in arr.reshape(-1)] if arr.ndim else [str(arr)]
    elif arr.dtype == object:
        items = []
        for item in arr.reshape(-1):
            item = np.asarray(item)
            if item.size == 0:
                items.append("")
            elif item.dtype.kind in "US":
                items.append("".join(str(s) for s in item.reshape(-1)).strip())
            else:
                raise ModelError(f"model file '{path}': {key} must hold strings, got "
                                 f"{item.dtype}")
    else:
        raise ModelError(f"model file '{path}': {key} must be a cell array of strings, got "
                         f"{arr.dtype}")
    if len(items) != count:
        raise ModelError(f"model file '{path}': {key} has {len(items)} names but the model "
                         f"has {count} channels")
    if not any(items):
        return None                      # MATLAB's default: all names empty
    prefix = "u" if key == "InputName" else "y"
    return [s if s else f"{prefix}{k + 1}" for k, s in enumerate(items)]


def read_mat_model(path, build, *, dt=None):
    """A model from a MAT-file: the one reader behind :func:`subid.interop.load_mat`
    and :meth:`subid.StateSpace.from_mat` (which document the variables).

    The file goes through :func:`mat_variables`, the validated path of
    :func:`read`. ``build(A, B, C, D, dt, input_names=, output_names=, hold=,
    K=, noise_cov=)`` makes the model (the StateSpace class: this module sits
    below the model module and does not import it).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mat`` file.
    build : callable
        Model constructor.
    dt : float, optional
        Sampling period when ``Ts`` is -1 or missing.

    Returns
    -------
    StateSpace
        What ``build`` returns.
    """
    path = os.fsdecode(path) if isinstance(path, bytes) else os.fspath(path)
    # The same validated path as subid.read: regular files only, every MAT
    # structure checked before scipy's C reader sees it, bounded decompression.
    # mat_dtype=False: scipy's mat_dtype=True casts complex matrices to real,
    # silently dropping the imaginary part; complex values are refused below.
    raw = mat_variables(path, mat_dtype=False, what="model file")
    fields = {k: v for k, v in raw.items() if not k.startswith("__")}
    idpoly = None
    if "subid_ss_A" in fields:        # a polynomial model: idpoly fields and its realisation
        idpoly = {k: fields.pop(k) for k in ("A", "B", "C", "D", "F") if k in fields}
        idpoly.update({k: fields[k] for k in fields if k.startswith("subid_") or k == "nk"})
        for key in ("A", "B", "C", "D"):
            if f"subid_ss_{key}" in fields:
                fields[key] = fields[f"subid_ss_{key}"]
    if not all(k in fields for k in ("A", "B", "C")):
        structs = [k for k, v in fields.items()
                   if isinstance(v, np.ndarray) and v.dtype.names and "A" in v.dtype.names]
        if len(structs) == 1:
            s = fields[structs[0]]
            fields = {name: s[name].reshape(-1)[0] for name in s.dtype.names}
    missing = [k for k in ("A", "B", "C", "D") if k not in fields]
    if missing:
        raise ModelError(f"model file '{path}' lacks the variable{'s' if len(missing) > 1 else ''}"
                         f" {', '.join(missing)}; expected the fields of MATLAB's "
                         f"ss(A, B, C, D, Ts): {', '.join(_MAT_FIELDS)}")
    mats = []
    for key in ("A", "B", "C", "D"):
        value = np.asarray(fields[key])
        if value.dtype.kind == "c":
            raise ModelError(f"model file '{path}': {key} is complex; subid models are "
                             "real-valued (a complex matrix is not the realization of a "
                             "real system)")
        if value.dtype.kind not in "biuf":
            raise ModelError(f"model file '{path}': {key} is not a real numeric matrix "
                             f"(dtype {value.dtype})")
        mats.append(value.astype(np.float64))
    A, B, C, D = mats
    n = A.shape[0]
    if B.size == 0 and A.size:
        B = np.zeros((n, D.shape[1] if D.ndim == 2 else 0))
    if D.size == 0:
        D = np.zeros((C.shape[0], B.shape[1]))
    ts = fields.get("Ts")
    if ts is None:
        period = -1.0
    else:
        ts = np.asarray(ts)
        if ts.size != 1 or ts.dtype.kind not in "biuf":
            if ts.dtype.kind == "c":
                raise ModelError(f"model file '{path}': Ts is complex")
            raise ModelError(f"model file '{path}': Ts must be a scalar, got shape {ts.shape}")
        period = float(ts.reshape(-1)[0])
    if period == -1.0:
        if dt is None:
            raise ModelError(f"model file '{path}': the sampling period is unspecified "
                             "(Ts = -1 or missing); pass dt=")
        period = dt
    elif dt is not None and not same_period(dt, period):
        raise ModelError(f"model file '{path}' has Ts = {period:g} but dt={dt!r} was given")
    if isinstance(period, bool) or not isinstance(period, numbers.Real) or period < 0:
        raise ModelError(f"model file '{path}': Ts must be >= 0 or -1, got {period!r}")
    try:
        inputs = _cell_strings(fields["InputName"], "InputName", path, B.shape[1]) \
            if "InputName" in fields else None
        outputs = _cell_strings(fields["OutputName"], "OutputName", path, C.shape[0]) \
            if "OutputName" in fields else None
        noise = {}
        for key, name in (("K", "K"), ("NoiseVariance", "noise_cov")):
            value = fields.get(key)
            if value is not None and np.asarray(value).size:
                value = np.asarray(value)
                if value.dtype.kind not in "biuf":
                    raise ModelError(f"model file '{path}': {key} is not a real numeric "
                                     f"matrix (dtype {value.dtype})")
                noise[name] = value.astype(np.float64)
        hold = fields.get("subid_hold")
        if hold is not None:
            hold = "".join(str(v) for v in np.asarray(hold).reshape(-1)).strip()
            if hold not in ("zoh", "foh"):
                raise ModelError(f"model file '{path}': subid_hold must be 'zoh' or 'foh', "
                                 f"got {hold[:40]!r}")
        extra = {}
        if idpoly is not None:
            extra["info"] = {"polynomials": _from_idpoly_fields(idpoly, C.shape[0], B.shape[1],
                                                                path)}
        return build(A, B, C, D, period, input_names=inputs, output_names=outputs,
                     hold=hold or "zoh", **noise, **extra)
    except ModelError as exc:
        if str(exc).startswith(f"model file '{path}'"):
            raise
        raise ModelError(f"model file '{path}': {exc}") from None


_MAT73_NUMERIC = {"double": np.float64, "single": np.float32, "int8": np.int8,
                  "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
                  "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
                  "uint64": np.uint64, "logical": np.uint8}
_MAT73_MAX_OBJECTS = 10_000


def _mat73_variables(raw: bytes, shown: str, max_bytes: int) -> dict:
    """The variables of a MATLAB v7.3 (HDF5) file, as :func:`scipy.io.loadmat`
    gives those of a v5 file (2-D arrays in MATLAB's orientation, a struct as a
    1-by-1 record array), read with h5py from memory.

    Every dataset's declared size is checked (as float64, like v5 files:
    at most the file's size plus ``max_bytes``) before any is read, so a
    small file declaring huge (compressed) arrays is refused without
    allocating them. Cell arrays, sparse matrices and objects become object
    arrays, which :func:`read` and :meth:`StateSpace.from_mat` refuse by name.
    """
    try:
        import h5py
    except ImportError:
        from subid._extras import install_hint
        raise FileReadError(f"{shown} is a MATLAB v7.3 (HDF5) file; reading it needs h5py: "
                            f"{install_hint('hdf5', 'h5py')}; or save it with save(..., "
                            "'-v7') in MATLAB", path=shown) from None

    def corrupt(exc):
        return FileReadError(f"{shown} is not a readable MATLAB v7.3 (HDF5) file (corrupted?): "
                             f"{_reason(exc)}", path=shown)

    try:
        fh = h5py.File(BytesIO(raw), "r")
    except Exception as exc:  # noqa: BLE001 - h5py raises OSError, ValueError, KeyError, ...
        raise corrupt(exc) from None
    try:
        with fh:
            plan, budget, count = [], 8 * len(raw) + max_bytes, 0

            def declare(name, obj, depth):
                nonlocal budget, count
                count += 1
                if count > _MAT73_MAX_OBJECTS or depth > 8:
                    raise FileReadError(f"{shown}: the MATLAB v7.3 file holds more than "
                                        f"{_MAT73_MAX_OBJECTS} objects or nests them more than "
                                        "8 deep; subid reads numeric variables", path=shown)
                if isinstance(obj, h5py.Group):
                    if _attr(obj, "MATLAB_class") != "struct":
                        return ("unsupported", name, None)
                    return ("struct", name, [declare(k, obj[k], depth + 1) for k in obj])
                cls = _attr(obj, "MATLAB_class")
                if not isinstance(obj, h5py.Dataset) or obj.dtype.kind == "O" \
                        or cls in ("cell", "function_handle") or "MATLAB_sparse" in obj.attrs:
                    return ("unsupported", name, None)
                elements = 1
                for d in obj.shape:
                    elements *= int(d)
                budget -= 8 * elements * (2 if obj.dtype.names else 1)
                if budget < 0:
                    raise ResourceLimitError(
                        f"{shown}: its variables take more than max_bytes = {max_bytes} bytes "
                        "beyond the file's size as float64; pass a larger max_bytes if the "
                        "file is genuine", path=shown)
                return ("dataset", name, obj)

            for key in fh:
                if key.startswith("#"):
                    continue           # MATLAB's #refs# and #subsystem# groups
                plan.append(declare(key, fh[key], 0))
            return {name: _mat73_value(kind, item, shown) for kind, name, item in plan}
    except (FileReadError, ResourceLimitError):
        raise
    except MemoryError:
        raise
    except Exception as exc:  # noqa: BLE001 - h5py errors of any class
        raise corrupt(exc) from None


def _attr(obj, key):
    value = obj.attrs.get(key)
    if isinstance(value, bytes):
        return value.decode("ascii", "replace")
    if isinstance(value, np.ndarray) and value.dtype.kind == "S":
        return value.reshape(-1)[0].decode("ascii", "replace")
    return None if value is None else str(value)


def _mat73_value(kind, item, shown):
    if kind == "unsupported":
        return np.empty((1, 1), dtype=object)
    if kind == "struct":
        names = [name for _, name, _ in item]
        record = np.empty((1, 1), dtype=[(name, object) for name in names])
        for sub_kind, name, sub in item:
            record[0, 0][name] = _mat73_value(sub_kind, sub, shown)
        return record
    cls = _attr(item, "MATLAB_class")
    if int(np.asarray(item.attrs.get("MATLAB_empty", 0)).reshape(-1)[0]):
        dims = [int(d) for d in np.asarray(item[()]).reshape(-1)]
        return np.zeros(tuple(dims) if len(dims) >= 2 else (0, 0))
    data = item[()]
    if item.dtype.names:                       # complex: a compound of real and imag
        if set(item.dtype.names) != {"real", "imag"}:
            return np.empty((1, 1), dtype=object)
        data = data["real"] + 1j * data["imag"]
    data = np.asarray(data)
    if cls == "char":
        text = "".join(chr(c) for c in data.T.reshape(-1))
        return np.array([text])
    if cls not in _MAT73_NUMERIC and data.dtype.kind not in "biuf":
        return np.empty((1, 1), dtype=object)
    if cls == "logical":
        data = data.astype(bool)
    data = data.T                               # HDF5 holds MATLAB's column-major order
    if data.ndim == 1:
        data = data[None, :]
    elif data.ndim == 0:
        data = data.reshape(1, 1)
    return np.ascontiguousarray(data)


def _load_mat(p: Path, shown: str, *, raw=None, max_bytes=None) -> dict:
    import scipy.sparse
    raw = mat_variables(shown, raw=raw, max_bytes=max_bytes)
    arrays = {}
    for key, val in raw.items():
        if key.startswith("__"):
            continue
        if scipy.sparse.issparse(val):
            val = val.toarray()
        val = np.asarray(val)
        if val.ndim == 2 and val.shape[0] == 1 and val.shape[1] > 1:
            val = val.reshape(-1)          # a 1-by-N row vector is one channel
        arrays[key] = val
    return arrays


_MAT4_ELEMENT_BYTES = {0: 8, 1: 4, 2: 4, 3: 2, 4: 2, 5: 1}


def _check_mat4_headers(raw: bytes, shown: str, size: int) -> None:
    """Walk the variable headers of a MATLAB v4 file (uncompressed): every
    declared name and array must fit in the file. scipy would otherwise
    allocate what a corrupted header declares."""
    import struct
    with BytesIO(raw) as fh:
        offset = 0
        while offset < size:
            fh.seek(offset)
            head = fh.read(20)
            if len(head) < 20:
                raise FileReadError(f"{shown}: MATLAB v4 variable header truncated at byte "
                                    f"{offset}", path=shown)
            for endian in "<>":
                mopt, mrows, ncols, imagf, namlen = struct.unpack(endian + "5i", head)
                if 0 <= mopt < 5000 and mopt // 1000 in (0, 1):
                    break
            else:
                raise FileReadError(f"{shown}: corrupted MATLAB v4 header at byte {offset}",
                                    path=shown)
            elsize = _MAT4_ELEMENT_BYTES.get((mopt // 10) % 10)
            if elsize is None or min(mrows, ncols, namlen) < 0 or imagf not in (0, 1):
                raise FileReadError(f"{shown}: corrupted MATLAB v4 header at byte {offset}",
                                    path=shown)
            step = 20 + namlen + mrows * ncols * elsize * (2 if imagf else 1)
            if offset + step > size:
                raise FileReadError(f"{shown}: a MATLAB v4 header at byte {offset} declares more "
                                    f"data than the {size}-byte file holds; the file is "
                                    "corrupted", path=shown)
            offset += step


# MAT v5 data types: code -> bytes per element (numeric and character data)
_MI_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8, 14: 8,
             16: 1, 17: 2, 18: 4}
_MI_MATRIX, _MI_COMPRESSED = 14, 15
_NUMERIC_CLASSES = range(6, 16)           # mxDOUBLE_CLASS .. mxUINT64_CLASS
_CELL, _STRUCT, _CHAR, _SPARSE = 1, 2, 4, 5


class _MatCorrupt(Exception):
    """A MAT v5 structure that does not follow the format."""


def _mat5_sub(buf: bytes, pos: int, end: int, endian: str):
    """Next sub-element in ``buf[pos:end]``: ``(type, data start, data end, next pos)``."""
    import struct
    if pos + 8 > end:
        raise _MatCorrupt("truncated element tag")
    word, nbytes = struct.unpack(endian + "2I", buf[pos:pos + 8])
    if word >> 16:                                   # small data element: data in the tag
        small = word >> 16
        if small > 4:
            raise _MatCorrupt("small data element longer than 4 bytes")
        return word & 0xFFFF, pos + 4, pos + 4 + small, pos + 8
    start, stop = pos + 8, pos + 8 + nbytes
    if stop > end:
        raise _MatCorrupt("element longer than its parent")
    return word, start, stop, stop + (-nbytes % 8)


def _mat5_data(buf, pos, end, endian, count: int, what: str):
    """A numeric or character sub-element holding exactly ``count`` values."""
    dtype, start, stop, nxt = _mat5_sub(buf, pos, end, endian)
    size = _MI_SIZES.get(dtype)
    if size is None:
        raise _MatCorrupt(f"{what} has unknown data type {dtype}")
    if stop - start != count * size:
        raise _MatCorrupt(f"{what} holds {stop - start} bytes, not {count} values of "
                          f"{size} bytes")
    return nxt


def _mat5_matrix(buf: bytes, start: int, end: int, endian: str, depth: int = 0) -> None:
    """Validate the content of one miMATRIX element (the fields scipy's C
    reader trusts): flags, dimensions, name and data sizes, recursively."""
    import struct
    if start == end:                                 # an empty matrix element
        return
    if depth > 16:
        raise _MatCorrupt("nesting too deep")
    dtype, a, b, pos = _mat5_sub(buf, start, end, endian)
    if dtype != 6 or b - a != 8:
        raise _MatCorrupt("bad array flags")
    flags, nzmax = struct.unpack(endian + "2I", buf[a:b])
    cls, complex_ = flags & 0xFF, bool(flags & 0x800)
    dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
    if dtype != 5 or (b - a) % 4 or b - a < 8:
        raise _MatCorrupt("bad dimensions")
    dims = struct.unpack(endian + f"{(b - a) // 4}i", buf[a:b])
    if min(dims) < 0:
        raise _MatCorrupt("negative dimension")
    count = 1
    for d in dims:
        count *= d
    dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
    if dtype not in (1, 2, 16):
        raise _MatCorrupt("bad array name")
    if cls in _NUMERIC_CLASSES or cls == _CHAR:
        pos = _mat5_data(buf, pos, end, endian, count, "real part")
        if complex_:
            _mat5_data(buf, pos, end, endian, count, "imaginary part")
    elif cls == _CELL:
        for _ in range(count):
            dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
            if dtype != _MI_MATRIX:
                raise _MatCorrupt("cell element is not a matrix")
            _mat5_matrix(buf, a, b, endian, depth + 1)
    elif cls == _STRUCT:
        dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
        if dtype != 5 or b - a != 4:
            raise _MatCorrupt("bad field name length")
        name_len = struct.unpack(endian + "i", buf[a:b])[0]
        dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
        if dtype != 1 or name_len <= 0 or (b - a) % name_len:
            raise _MatCorrupt("bad field names")
        for _ in range(count * ((b - a) // name_len)):
            dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
            if dtype != _MI_MATRIX:
                raise _MatCorrupt("struct field is not a matrix")
            _mat5_matrix(buf, a, b, endian, depth + 1)
    elif cls == _SPARSE:
        if len(dims) != 2:
            raise _MatCorrupt("sparse matrix with more than 2 dimensions")
        pos = _mat5_data(buf, pos, end, endian, nzmax, "sparse row indices")
        pos = _mat5_data(buf, pos, end, endian, dims[1] + 1, "sparse column indices")
        for part in ("real", "imaginary")[:2 if complex_ else 1]:
            dtype, a, b, pos = _mat5_sub(buf, pos, end, endian)
            if dtype not in _MI_SIZES or (b - a) // _MI_SIZES[dtype] > nzmax:
                raise _MatCorrupt(f"bad sparse {part} part")
    else:
        raise _MatCorrupt(f"unsupported MATLAB class {cls} (objects, function handles)")


def _check_mat5_elements(raw: bytes, shown: str, size: int, max_bytes: int) -> None:
    """Validate a MATLAB v5 file before scipy reads it.

    Each top-level element must fit in the file; compressed elements must
    inflate (bounded) to what they declare; and every matrix must follow the
    format: scipy's C reader trusts the flags, dimensions, type codes and
    sizes, and a corrupted one made it allocate gigabytes or crash the
    interpreter (found by the fuzzers).
    """
    import struct
    import zlib
    budget = max_bytes                   # decompressed bytes allowed in all
    if len(raw) < 128:
        raise FileReadError(f"{shown}: MATLAB file header truncated", path=shown)
    endian = "<" if raw[126:128] == b"IM" else ">"
    offset = 128
    try:
        while offset < size:
            dtype, start, stop, nxt = _mat5_sub(raw, offset, size, endian)
            if dtype == _MI_COMPRESSED:
                inflater = zlib.decompressobj()
                try:
                    inner = inflater.decompress(raw[start:stop], budget + 1)
                except zlib.error as exc:
                    raise _MatCorrupt(f"corrupted compressed data ({exc})") from None
                if len(inner) > budget or inflater.unconsumed_tail:
                    raise ResourceLimitError(
                        f"{shown}: its compressed variables expand to more than "
                        f"{max_bytes} bytes (max_bytes), from a {size}-byte file; pass a "
                        "larger max_bytes if the file is genuine", path=shown)
                budget -= len(inner)
                itype, istart, istop, _ = _mat5_sub(inner, 0, len(inner), endian)
                if itype == _MI_MATRIX:
                    _mat5_matrix(inner, istart, istop, endian)
                offset = stop                            # compressed elements are not padded
            else:
                if dtype == _MI_MATRIX:
                    _mat5_matrix(raw, start, stop, endian)
                offset = nxt
    except _MatCorrupt as exc:
        raise FileReadError(f"{shown}: corrupted MATLAB file near byte {offset} ({exc})",
                            path=shown) from None
    except struct.error as exc:
        raise FileReadError(f"{shown}: corrupted MATLAB file near byte {offset} ({exc})",
                            path=shown) from None


def _check_mat_sizes(raw: bytes, shown: str, max_bytes: int) -> None:
    """Reject a MAT-file whose structure is corrupted or whose arrays would
    take more than the file plus ``max_bytes`` (a corrupted header would
    otherwise make scipy allocate gigabytes, or crash)."""
    import scipy.io
    size = len(raw)
    first = raw[:4]
    if len(first) == 4 and 0 in first:          # scipy's test for a v4 file
        _check_mat4_headers(raw, shown, size)
    else:
        _check_mat5_elements(raw, shown, size, max_bytes)
    try:
        entries = scipy.io.whosmat(BytesIO(raw))
    except MemoryError:
        raise FileReadError(f"{shown} is not a readable MATLAB .mat file (corrupted header)",
                            path=shown) from None
    except Exception as exc:  # scipy raises many kinds on malformed headers
        raise FileReadError(f"{shown} is not a readable MATLAB .mat file (corrupted or not a "
                            f"MAT-file): {_reason(exc)}", path=shown) from None
    declared = sum(8 * float(np.prod([float(d) for d in shape])) for _, shape, _ in entries)
    if declared > 8 * size + max_bytes:      # as float64 (what IOData holds)
        raise ResourceLimitError(f"{shown}: its variables take {declared / 2**20:.0f} MB as "
                                 f"float64, from a {size}-byte file: more than max_bytes = "
                                 f"{max_bytes} beyond the file's size; pass a larger "
                                 "max_bytes if the file is genuine", path=shown)
