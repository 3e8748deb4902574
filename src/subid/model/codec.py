"""The JSON codec of models: :class:`StateSpace` <-> a dictionary of plain JSON values.

The encoding is the one the :mod:`subid.model.statespace` module docstring documents
(``format``, ``version``, the matrices row by row, ``info`` with tagged non-finite
floats, complex numbers and arrays). Opening and writing files is :mod:`subid.io.models`'
concern; this module only turns models into JSON values and back.
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping

import numpy as np

from subid._version import __version__
from subid.errors import ModelError
from subid.model._checks import HOLDS

FORMAT_NAME = "subid.StateSpace"
FORMAT_VERSION = 3

_TAG_ARRAY = "__ndarray__"
_TAG_COMPLEX = "__complex__"
_TAG_FLOAT = "__float__"
_RESERVED_KEYS = (_TAG_ARRAY, _TAG_COMPLEX, _TAG_FLOAT)
_NONFINITE_NAMES = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}
# Integers a model file holds: the JSON readers of subid.io._schema refuse others.
_INT_MIN, _INT_MAX = -2**63, 2**63 - 1


def _enc_float(x: float):
    if math.isfinite(x):
        return x
    return {_TAG_FLOAT: "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")}


def _nonfinite_to_str(obj):
    if isinstance(obj, list):
        return [_nonfinite_to_str(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


def _enc_array(arr: np.ndarray, where: str) -> dict:
    kind = arr.dtype.kind
    if kind == "b":
        data, dtype = arr.tolist(), "bool"
    elif kind in "iu":
        data, dtype = arr.tolist(), str(arr.dtype)
    elif kind in "fc":
        if kind == "c":
            dtype = str(arr.dtype)
            real = np.stack([arr.real, arr.imag], axis=-1).astype(np.float64)
        else:
            dtype = str(arr.dtype)
            real = arr.astype(np.float64)
        data = real.tolist()
        if not np.isfinite(real).all():
            data = _nonfinite_to_str(data)
    elif kind == "U":
        data, dtype = arr.tolist(), "str"
    else:
        raise ModelError(f"{where} is a numpy array of dtype {arr.dtype}, which cannot be "
                         "stored in a model file; use numeric, bool or string arrays")
    return {_TAG_ARRAY: data, "dtype": dtype, "shape": list(arr.shape)}


def _encode(obj, where: str):
    """JSON-ready copy of ``obj`` (see the module docstring for the encoding)."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.ndarray):
        return _enc_array(obj, where)
    if isinstance(obj, np.generic):
        if obj.dtype.kind not in "biufcU":
            raise ModelError(f"{where} is a numpy {obj.dtype} scalar, which cannot be "
                             "stored in a model file")
        obj = obj.item()
        if isinstance(obj, (bool, str)):
            return obj
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        return _enc_float(float(obj))
    if isinstance(obj, numbers.Complex):
        c = complex(obj)
        return {_TAG_COMPLEX: [_enc_float(c.real), _enc_float(c.imag)]}
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, str):
                raise ModelError(f"{where} has the key {key!r} of type {type(key).__name__}; "
                                 "dictionaries stored in a model file need string keys")
            if key in _RESERVED_KEYS:
                raise ModelError(f"{where} uses the reserved key {key!r}; rename it")
            out[key] = _encode(value, f"{where}[{key!r}]")
        return out
    if isinstance(obj, (list, tuple)):
        return [_encode(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    raise ModelError(f"{where} is a {type(obj).__name__}, which cannot be stored in a model "
                     "file; use numbers, strings, bools, None, lists, dicts or numpy arrays")


def _dec_float(value, where: str) -> float:
    if isinstance(value, Mapping):
        if set(value) == {_TAG_FLOAT} and isinstance(value[_TAG_FLOAT], str) \
                and value[_TAG_FLOAT] in _NONFINITE_NAMES:
            return _NONFINITE_NAMES[value[_TAG_FLOAT]]
        raise ModelError(f"{where} is not a valid encoded float: {value!r}")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ModelError(f"{where} must be a number, got {value!r}")
    return float(value)


def _dec_array(obj: Mapping, where: str) -> np.ndarray:
    if set(obj) != {_TAG_ARRAY, "dtype", "shape"}:
        raise ModelError(f"{where} is an encoded array but has the keys {sorted(obj)}; "
                         f"expected {_TAG_ARRAY!r}, 'dtype' and 'shape'")
    dtype, shape, data = obj["dtype"], obj["shape"], obj[_TAG_ARRAY]
    if not isinstance(shape, list) or not all(
            isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape):
        raise ModelError(f"{where}: 'shape' must be a list of non-negative integers, "
                         f"got {shape!r}")
    try:
        if dtype == "str":
            arr = np.array(data, dtype=str)
        else:
            dt = np.dtype(dtype)
            if dt.kind not in "biufc":
                raise TypeError(f"unsupported dtype {dtype!r}")
            if dt.kind == "c":
                pairs = np.array(data, dtype=np.float64)
                if pairs.ndim == 0 or pairs.shape[-1] != 2:
                    raise ValueError("complex entries must be [re, im] pairs")
                arr = np.empty(pairs.shape[:-1], dtype=dt)
                arr.real = pairs[..., 0]
                arr.imag = pairs[..., 1]
            elif dt.kind == "f":
                arr = np.array(data, dtype=np.float64).astype(dt)
            else:
                if not _all_ints(data, bool_ok=dt.kind == "b"):
                    raise ValueError("entries are not all integers" if dt.kind != "b"
                                     else "entries are not all booleans")
                arr = np.array(data, dtype=dt)
        arr = arr.reshape(shape)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ModelError(f"{where} is not a valid encoded {dtype} array of shape {shape} "
                         f"({exc})") from None
    return arr


def _all_ints(data, *, bool_ok: bool) -> bool:
    if isinstance(data, list):
        return all(_all_ints(v, bool_ok=bool_ok) for v in data)
    if bool_ok:
        return isinstance(data, bool)
    return isinstance(data, int) and not isinstance(data, bool)


def _decode(obj, where: str):
    """Inverse of :func:`_encode`."""
    if obj is None or isinstance(obj, (bool, str, int, float)):
        return obj
    if isinstance(obj, Mapping):
        keys = set(obj)
        if _TAG_ARRAY in keys:
            return _dec_array(obj, where)
        if _TAG_FLOAT in keys:
            return _dec_float(obj, where)
        if _TAG_COMPLEX in keys:
            pair = obj[_TAG_COMPLEX]
            if keys != {_TAG_COMPLEX} or not isinstance(pair, (list, tuple)) or len(pair) != 2:
                raise ModelError(f"{where} is not a valid encoded complex number: {obj!r}")
            return complex(_dec_float(pair[0], where), _dec_float(pair[1], where))
        out = {}
        for key, value in obj.items():
            if not isinstance(key, str):
                raise ModelError(f"{where} has the non-string key {key!r}")
            out[key] = _decode(value, f"{where}[{key!r}]")
        return out
    if isinstance(obj, (list, tuple)):
        return [_decode(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    raise ModelError(f"{where} is a {type(obj).__name__}, which is not a JSON value")


def _matrix_from_json(value, key: str) -> np.ndarray:
    if isinstance(value, np.ndarray):
        arr = value
    elif isinstance(value, list):
        try:
            arr = np.array(value)
        except (TypeError, ValueError):
            raise ModelError(f"key {key!r} is not a rectangular 2-D array of numbers") from None
    else:
        raise ModelError(f"key {key!r} must be a list of rows (a 2-D array), got "
                         f"{type(value).__name__}")
    if arr.dtype.kind not in "iuf":
        raise ModelError(f"key {key!r} must hold numbers only, got entries of type "
                         f"{arr.dtype}")
    if arr.ndim != 2:
        raise ModelError(f"key {key!r} must be a list of rows (a 2-D array), got an array "
                         f"of shape {arr.shape}")
    return arr


def _fmt_json(d: dict) -> str:
    """Strict JSON text of a model dictionary, one matrix row per line."""
    parts = []
    for key, value in d.items():
        if key in ("A", "B", "C", "D", "K", "noise_cov"):
            rows = [json.dumps(row, allow_nan=False) for row in value]
            text = "[\n    " + ",\n    ".join(rows) + "\n  ]" if rows else "[]"
        elif key == "info":
            text = json.dumps(value, indent=2, allow_nan=False).replace("\n", "\n  ")
        else:
            text = json.dumps(value, allow_nan=False)
        parts.append(f"  {json.dumps(key)}: {text}")
    return "{\n" + ",\n".join(parts) + "\n}\n"



def to_dict(model) -> dict:
    """JSON-ready dictionary of ``model`` (:meth:`StateSpace.to_dict`)."""
    d = {
        "format": FORMAT_NAME,
        "version": 1,
        "subid_version": __version__,
        "A": model._A.tolist(),
        "B": model._B.tolist(),
        "C": model._C.tolist(),
        "D": model._D.tolist(),
        "dt": model._dt,
        "input_names": list(model.input_names),
        "output_names": list(model.output_names),
        "info": _encode(model.info, "info"),
    }
    # version 2 adds the optional noise model; a model without one is still
    # written as version 1, readable by older subid releases
    if model._K is not None:
        d["K"] = model._K.tolist()
        d["version"] = 2
    if model._noise_cov is not None:
        d["noise_cov"] = model._noise_cov.tolist()
        d["version"] = 2
    # version 3 adds the input hold; a zero-order-hold model omits it
    if model._hold != "zoh":
        d["hold"] = model._hold
        d["version"] = 3
    return d


def from_dict(cls, d):
    """``cls`` built from a dictionary written by :func:`to_dict`
    (:meth:`StateSpace.from_dict`)."""
    if not isinstance(d, Mapping):
        raise ModelError(f"a model description must be a JSON object (dict), got "
                         f"{type(d).__name__}")
    required = ("format", "version", "A", "B", "C", "D", "dt")
    allowed = set(required) | {"input_names", "output_names", "info", "K", "noise_cov",
                               "hold", "subid_version"}
    missing = [k for k in required if k not in d]
    if missing:
        raise ModelError(f"the model description is missing the key"
                         f"{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(repr(k) for k in missing)}")
    unknown = sorted(str(k) for k in d if k not in allowed)
    if unknown:
        raise ModelError(f"the model description has unknown key"
                         f"{'s' if len(unknown) > 1 else ''} {unknown}")
    if d["format"] != FORMAT_NAME:
        raise ModelError(f"key 'format' is {d['format']!r}; expected {FORMAT_NAME!r}")
    version = d["version"]
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ModelError(f"key 'version' must be a positive integer, got {version!r}")
    if version > FORMAT_VERSION:
        raise ModelError(f"key 'version' is {version}: the model was written by a newer "
                         f"subid (this one reads version {FORMAT_VERSION}); upgrade subid")
    mats = [_matrix_from_json(d[k], k) for k in ("A", "B", "C", "D")]
    dt = d["dt"]
    if isinstance(dt, bool) or not isinstance(dt, numbers.Real) \
            or not math.isfinite(dt) or dt < 0:
        raise ModelError(f"key 'dt' must be a finite number >= 0, got {dt!r}")
    names = {}
    for key in ("input_names", "output_names"):
        value = d.get(key)
        if value is not None and (not isinstance(value, (list, tuple)) or
                                  not all(isinstance(v, str) for v in value)):
            raise ModelError(f"key {key!r} must be a list of strings, got {value!r}")
        names[key] = value
    info = d.get("info")
    if info is None:
        info = {}
    elif not isinstance(info, Mapping):
        raise ModelError(f"key 'info' must be an object (dict), got {type(info).__name__}")
    info = _decode(info, "info")
    noise = {k: (_matrix_from_json(d[k], k) if d.get(k) is not None else None)
             for k in ("K", "noise_cov")}
    hold = d.get("hold", "zoh")
    if hold not in HOLDS:
        raise ModelError(f"key 'hold' must be one of {', '.join(map(repr, HOLDS))}, got "
                         f"{hold!r}"[:300])
    return cls(*mats, dt, info=info, **names, **noise, hold=hold)


def to_json_value(value) -> str:
    """JSON text of one ``info`` value (its size in a model file)."""
    return json.dumps(_encode(value, "info"), allow_nan=False)


def _check_file_ints(obj, where: str) -> None:
    """ModelError for an integer of the encoded ``obj`` beyond 64 bits, which the JSON
    readers of model files (:mod:`subid.io._schema`) refuse: saved, it could not be
    loaded (a dictionary keeps such integers, :meth:`StateSpace.to_dict`)."""
    stack = [(obj, where)]
    while stack:
        value, at = stack.pop()
        if isinstance(value, dict):
            if _TAG_ARRAY in value:          # an array: named by its own key
                stack.append((value[_TAG_ARRAY], f"{at} (an array)"))
            else:
                stack.extend((v, f"{at}[{k!r}]") for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, at if at.endswith("(an array)") else f"{at}[{i}]")
                         for i, v in enumerate(value))
        elif isinstance(value, int) and not isinstance(value, bool) \
                and not _INT_MIN <= value <= _INT_MAX:
            raise ModelError(f"{at} holds the integer {value}, beyond the 64-bit signed "
                             "range of a model file (load would refuse it); nothing was "
                             "written. Store it as a string (str(value)) or a float")


def to_json(model) -> str:
    """Strict JSON text of ``model``, one matrix row per line.

    Raises ModelError for an ``info`` integer beyond 64 bits (:func:`_check_file_ints`).
    """
    d = to_dict(model)
    _check_file_ints(d["info"], "info")
    return _fmt_json(d)
