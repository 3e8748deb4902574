"""Atomic, pickle-free checkpoints for the online identifiers.

A checkpoint is a ``.npz`` file holding named float/int arrays plus a JSON
header (kind, version, scalar settings) stored as a uint8 array, so that
loading never unpickles anything (``allow_pickle=False``). Writing goes to a
temporary file in the same directory, is flushed and fsynced, then renamed
over the target (``os.replace``): a crash mid-write leaves the previous
checkpoint intact.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ._files import atomic_write
from ._npz import NpzError, load_npz
from .errors import CheckpointError, DataFileNotFoundError

_HEADER = "__header__"


def save_state(path, kind: str, version: int, arrays: dict, settings: dict) -> None:
    """Write a checkpoint atomically.

    Parameters
    ----------
    path : str or path-like
    kind : str
        Class of the saved object, checked on load.
    version : int
        Format version, checked on load.
    arrays : dict of str -> ndarray
        Numeric arrays (no object arrays).
    settings : dict
        JSON-serialisable scalars and lists.
    """
    path = os.fspath(path)
    header = json.dumps({"kind": kind, "version": version, "settings": settings})
    payload = {name: np.asarray(value) for name, value in arrays.items()}
    payload[_HEADER] = np.frombuffer(header.encode("utf-8"), dtype=np.uint8)
    with atomic_write(path, "wb") as fh:
        np.savez(fh, **payload)


def load_state(path, kind: str, version: int):
    """Read a checkpoint written by :func:`save_state`.

    Returns
    -------
    arrays : dict of str -> ndarray
    settings : dict

    Raises
    ------
    DataFileNotFoundError
        The file does not exist.
    CheckpointError
        Truncated or corrupted file, another kind of object, another version.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise DataFileNotFoundError(f"checkpoint {path} does not exist", path=path)
    try:
        arrays = load_npz(path)
    except NpzError as exc:
        raise CheckpointError(f"checkpoint {path} is truncated or corrupted ({exc}); "
                              "use an earlier checkpoint", path=path) from None
    if _HEADER not in arrays:
        raise CheckpointError(f"{path} is not a subid checkpoint (no header)", path=path)
    try:
        header = json.loads(arrays.pop(_HEADER).tobytes().decode("utf-8"))
        found_kind, found_version = header["kind"], header["version"]
        settings = header["settings"]
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"checkpoint {path} has a corrupted header ({exc})",
                              path=path) from None
    if found_kind != kind:
        raise CheckpointError(f"{path} is a checkpoint of {found_kind}, not of {kind}",
                              path=path)
    if found_version != version:
        raise CheckpointError(f"{path} has checkpoint format version {found_version}; this "
                              f"version of subid reads version {version}", path=path)
    return arrays, settings


def require(arrays: dict, path, name: str, shape=None) -> np.ndarray:
    """The array ``name`` of a loaded checkpoint, with its shape checked."""
    if name not in arrays:
        raise CheckpointError(f"checkpoint {path} lacks the array {name!r}", path=path)
    value = arrays[name]
    if shape is not None and value.shape != tuple(shape):
        raise CheckpointError(f"checkpoint {path}: array {name!r} has shape {value.shape}, "
                              f"expected {tuple(shape)}", path=path)
    if value.dtype.kind == "f" and not np.isfinite(value).all():
        raise CheckpointError(f"checkpoint {path}: array {name!r} holds non-finite values",
                              path=path)
    return value
