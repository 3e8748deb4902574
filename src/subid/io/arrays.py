"""Records stored as named arrays (``.npz`` archives and the variables of ``.mat`` files):
loading ``.npz`` safely and selecting the input, output and time arrays."""

from __future__ import annotations

from io import BytesIO
from pathlib import Path

import numpy as np

from subid._validation import check_dt, same_period, stamp_resolution
from subid.data import IOData
from subid.errors import FileReadError, ResourceLimitError
from subid.io._common import _build, _listing, _max_bytes, _read_bytes
from subid.io._npz import NpzError, NpzLimitError, load_npz
from subid.io.text import _tokens


def _load_npz(p: Path, shown: str, *, raw=None, max_bytes=None) -> dict:
    raw = _read_bytes(p, shown) if raw is None else raw
    magic = raw[:6]
    if magic == b"\x93NUMPY":
        raise FileReadError(f"{shown} holds a single .npy array, not a .npz archive; save the "
                            "record with numpy.savez(path, u=..., y=...)", path=shown)
    if not magic.startswith(b"PK"):
        raise FileReadError(f"{shown} is not a .npz archive (it is not a ZIP file); write it "
                            "with numpy.savez(path, u=..., y=...)", path=shown)
    try:
        return load_npz(BytesIO(raw), size=len(raw), max_expanded=_max_bytes(max_bytes))
    except NpzLimitError as exc:
        raise ResourceLimitError(f"{shown}: {exc}", path=shown) from None
    except NpzError as exc:
        if "pickled" in str(exc):
            raise FileReadError(f"{shown} holds object (pickled) arrays, which subid does not "
                                "load for safety; store plain numeric arrays", path=shown) from None
        raise FileReadError(f"{shown} is not a readable .npz archive (corrupted?): {exc}",
                            path=shown) from None



def _array_names(spec, role: str, keys, shown: str) -> list[str]:
    tokens = _tokens(spec, role, keys)
    for tok in tokens:
        if not isinstance(tok, str):
            raise FileReadError(f"{shown}: {role} selects arrays of an archive by name, not by "
                                f"index ({tok!r}); available arrays: {_listing(map(repr, keys))}",
                                path=shown, column=tok)
    if not tokens:
        raise FileReadError(f"{shown}: {role} selects no array", path=shown)
    for tok in tokens:
        if tok not in keys:
            raise FileReadError(f"{shown}: no array named {tok!r} ({role}); available arrays: "
                                f"{_listing(map(repr, keys)) or '(none)'}", path=shown, column=tok)
    seen = set()
    for tok in tokens:
        if tok in seen:
            raise FileReadError(f"{shown}: the array {tok!r} is selected twice in {role}",
                                path=shown, column=tok)
        seen.add(tok)
    return tokens


def _numeric(arr: np.ndarray, key: str, shown: str, ext: str) -> np.ndarray:
    if arr.dtype.kind not in "biufc":
        kind = {"U": "text", "S": "text", "O": "a cell array or object array",
                "V": "a struct / record array"}.get(arr.dtype.kind, f"of dtype {arr.dtype}")
        raise FileReadError(f"{shown}: the {'variable' if ext == '.mat' else 'array'} {key!r} "
                            f"is {kind}, not numeric", path=shown, column=key)
    return arr


def _channels(arr, key, shown, ext) -> tuple[np.ndarray, list[str]]:
    arr = _numeric(arr, key, shown, ext)
    if arr.ndim == 0:
        raise FileReadError(f"{shown}: {key!r} is a scalar, not a signal", path=shown, column=key)
    if arr.ndim == 1:
        return arr[:, None], [key]
    if arr.ndim != 2:
        raise FileReadError(f"{shown}: {key!r} has {arr.ndim} dimensions (shape {arr.shape}); "
                            "a signal is 1-D or 2-D with time on axis 0", path=shown, column=key)
    if arr.shape[1] == 1:
        return arr, [key]
    return arr, [f"{key}[{k}]" for k in range(arr.shape[1])]


def _stack(keys, arrays, shown, ext, role):
    parts, names = [], []
    for key in keys:
        arr, nm = _channels(arrays[key], key, shown, ext)
        parts.append(arr)
        names.extend(nm)
    lengths = {k: a.shape[0] for k, a in zip(keys, parts)}
    if len(set(lengths.values())) > 1:
        raise FileReadError(f"{shown}: the {role} arrays have different lengths "
                            f"({', '.join(f'{k}: {n}' for k, n in lengths.items())}); time is "
                            "axis 0", path=shown)
    values = parts[0] if len(parts) == 1 else np.hstack(parts)
    return values, names


def _seconds(t: np.ndarray, key: str, shown: str) -> np.ndarray:
    """Date-times (``datetime64``: seconds from the first) or durations (``timedelta64``)
    of an archive's time array as float seconds."""
    if np.isnat(t).any():
        row = int(np.flatnonzero(np.isnat(t))[0])
        raise FileReadError(f"{shown}: the time array {key!r} holds a missing date-time "
                            f"(NaT) at row {row}", path=shown, column=key)
    if t.dtype.kind == "M":
        t = t - t[0]
    return t / np.timedelta64(1, "s")


def _scalar(arr, key, shown, ext) -> float:
    arr = _numeric(np.asarray(arr), key, shown, ext)
    if arr.size != 1:
        raise FileReadError(f"{shown}: {key!r} should be a scalar sampling period, got shape "
                            f"{arr.shape}", path=shown, column=key)
    return check_dt(float(arr.reshape(-1)[0].real), name=f"{shown}: {key}")


def _from_arrays(arrays: dict, shown, ext, inputs, outputs, dt, time) -> IOData:
    keys = list(arrays)
    what = "variables" if ext == ".mat" else "arrays"
    for role, spec, default in (("inputs", inputs, "u"), ("outputs", outputs, "y")):
        if spec is None and default not in arrays:
            raise FileReadError(f"{shown}: no {what[:-1]} named {default!r}; pass {role}= "
                                f"to choose the {role} among the {what} in the file: "
                                f"{_listing(map(repr, keys)) or '(none)'}", path=shown)
    in_keys = _array_names("u" if inputs is None else inputs, "inputs", keys, shown)
    out_keys = _array_names("y" if outputs is None else outputs, "outputs", keys, shown)
    t_key = None
    if time is not None:
        if not isinstance(time, str):
            raise FileReadError(f"{shown}: time names an array of the file, got {time!r}",
                                path=shown)
        t_key = _array_names(time, "time", keys, shown)[0]
    elif dt is None and "t" in arrays and "t" not in in_keys + out_keys:
        t_key = "t"
    roles = [("an input", in_keys), ("an output", out_keys),
             ("the time", [t_key] if t_key else [])]
    for a in range(len(roles)):
        for b in range(a + 1, len(roles)):
            both = set(roles[a][1]) & set(roles[b][1])
            if both:
                key = sorted(both)[0]
                raise FileReadError(f"{shown}: the {what[:-1]} {key!r} is used both as "
                                    f"{roles[a][0]} and as {roles[b][0]}", path=shown, column=key)
    u, in_names = _stack(in_keys, arrays, shown, ext, "input")
    y, out_names = _stack(out_keys, arrays, shown, ext, "output")
    t = None
    if t_key is not None:
        t = np.asarray(arrays[t_key])
        if t.ndim == 2 and 1 in t.shape:
            t = t.reshape(-1)
        if t.dtype.kind in "Mm" and t.ndim == 1 and t.size:
            t = _seconds(t, t_key, shown)
        t = _numeric(t, t_key, shown, ext)
        period = _file_period(arrays, shown, ext, in_keys + out_keys) \
            if dt is None and time is None else None
        if period is not None:
            name, file_dt = period
            steps = np.diff(np.asarray(t, dtype=np.float64))
            if steps.size and not same_period(steps, file_dt, resolution=stamp_resolution(t)):
                raise FileReadError(f"{shown}: the file holds both 't' and {name!r} and they "
                                    f"disagree ({name} = {file_dt:g}, t steps from "
                                    f"{steps.min():g} to {steps.max():g}); pass dt= or time= "
                                    "to choose", path=shown)
    elif dt is None:
        period = _file_period(arrays, shown, ext, in_keys + out_keys)
        if period is not None:
            dt = period[1]
    return _build(shown, u, y, dt, t, in_names, out_names)


#: The names of a sampling period stored beside the signals: subid's ``dt``, and
#: ``Ts``, MATLAB's (``iddata``'s property, as ``save('d.mat', 'u', 'y', 'Ts')`` stores it).
PERIOD_NAMES = ("dt", "Ts")


def _file_period(arrays: dict, shown, ext, channels) -> tuple[str, float] | None:
    """``(name, period)`` of the sampling period stored in the file, or None.

    ``dt``, or MATLAB's ``Ts`` when there is no ``dt`` (a ``Ts`` of -1, MATLAB's
    "unspecified", or 0 is no period). Both present with different values is a
    :class:`~subid.errors.FileReadError`. Arrays used as channels are not periods."""
    found = {}
    for name in PERIOD_NAMES:
        if name not in arrays or name in channels:
            continue
        if name == "Ts":
            raw = _numeric(np.asarray(arrays[name]), name, shown, ext)
            if raw.size == 1 and float(raw.reshape(-1)[0].real) <= 0:
                continue                    # MATLAB's unspecified (-1) or continuous (0)
        found[name] = _scalar(arrays[name], name, shown, ext)
    if len(found) == 2 and not same_period(found["dt"], found["Ts"]):
        raise FileReadError(f"{shown}: the file holds both 'dt' = {found['dt']:g} and MATLAB's "
                            f"'Ts' = {found['Ts']:g}, which differ; remove one of them, or "
                            "pass dt= (on the command line --dt) to choose", path=shown)
    return next(iter(found.items()), None)
