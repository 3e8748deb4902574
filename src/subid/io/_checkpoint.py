"""Atomic, pickle-free checkpoints for the online identifiers.

A checkpoint is a ``.npz`` file holding named float/int arrays plus a JSON
header (kind, version, scalar settings) stored as a uint8 array, so that
loading never unpickles anything (``allow_pickle=False``). Writing goes to a
temporary file in the same directory, is flushed and fsynced, then renamed
over the target (``os.replace``): a crash mid-write leaves the previous
checkpoint intact.
"""

from __future__ import annotations

import functools
import json
import os

import numpy as np

from subid.errors import CheckpointError, OptionError
from subid.io._files import MAX_FILE_BYTES, atomic_write, open_regular
from subid.io._npz import NpzError, load_npz
from subid.io._schema import check_array, parse_json

_HEADER = "__header__"
_HEADER_DEPTH = 6                # header object > settings > a list of lists of scalars


def _checkpoint_path(path, action: str) -> str:
    """``path`` as a str, or :class:`OptionError` when it is no file name (None, a number:
    os.fspath's TypeError before)."""
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise OptionError(f"the checkpoint to {action} must be a file name (a str or an "
                          f"os.PathLike such as pathlib.Path), got {path!r}"[:300])
    return os.fsdecode(path) if isinstance(path, bytes) else os.fspath(path)


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
    path = _checkpoint_path(path, "save")
    header = json.dumps({"kind": kind, "version": version, "settings": settings})
    payload = {name: np.asarray(value) for name, value in arrays.items()}
    payload[_HEADER] = np.frombuffer(header.encode("utf-8"), dtype=np.uint8)
    with atomic_write(path, "wb", what="checkpoint") as fh:
        np.savez(fh, **payload)  # type: ignore[arg-type]  # numpy's stub: **kwds may be allow_pickle


def load_state(path, kind: str | tuple[str, ...] | None,
               version: int | tuple[int, ...] | None, *, max_bytes: int = MAX_FILE_BYTES):
    """Read a checkpoint written by :func:`save_state`.

    The file is opened as a regular file only (a FIFO or a device is
    refused, never read), its size is checked against ``max_bytes``, its
    arrays are read by the bounded ``.npz`` reader, and every array and
    header field is validated against the checkpoint schema before use:
    arrays are float64 or int64 (a non-native byte order is converted, any
    other dtype is refused), the header is a JSON object of bounded depth
    whose numbers fit in 64 bits and are finite.

    ``kind`` and ``version`` may be tuples of the accepted kinds and
    versions (older formats a class still reads); the version found is
    ``settings['_version']``. ``kind=None`` accepts any kind and any version
    (the kind found is then ``settings['_kind']``): how
    :meth:`subid.OnlineIdentifier.load` finds the class to restore.

    Returns
    -------
    arrays : dict of str -> ndarray
    settings : dict

    Raises
    ------
    DataFileNotFoundError
        The file does not exist.
    CheckpointError
        Not a regular file, too large, truncated or corrupted file, another
        kind of object, another version, arrays or header fields of the
        wrong type.
    """
    path = _checkpoint_path(path, "load")
    error = functools.partial(CheckpointError, path=path)
    fh, size = open_regular(path, what="checkpoint", max_bytes=max_bytes, error=CheckpointError)
    with fh:
        try:
            # subid writes checkpoints uncompressed: their arrays never take more
            # than the file itself, so nothing may expand (a compressed bomb cannot).
            arrays = load_npz(fh, size=size, max_expanded=0)
        except NpzError as exc:
            raise error(f"checkpoint {path} is truncated or corrupted ({exc}); "
                        "use an earlier checkpoint") from None
    if _HEADER not in arrays:
        raise error(f"{path} is not a subid checkpoint (no header)")
    raw = arrays.pop(_HEADER)
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise error(f"checkpoint {path} has a corrupted header (dtype {raw.dtype}, "
                    f"shape {raw.shape})")
    header = parse_json(raw.tobytes(), f"checkpoint {path}: the header", error,
                        max_depth=_HEADER_DEPTH)
    if not isinstance(header, dict) or not {"kind", "version", "settings"} <= set(header):
        raise error(f"checkpoint {path} has a corrupted header (kind, version and settings "
                    "are required)")
    found_kind, found_version = header["kind"], header["version"]
    settings = header["settings"]
    if not isinstance(found_kind, str) or isinstance(found_version, bool) \
            or not isinstance(found_version, int) or not isinstance(settings, dict):
        raise error(f"checkpoint {path} has a corrupted header (kind, version or settings "
                    "of the wrong type)")
    if kind is None:
        return arrays, dict(settings, _version=found_version, _kind=found_kind)
    kinds = (kind,) if isinstance(kind, str) else tuple(kind)
    versions = (version,) if isinstance(version, int) else tuple(version)  # type: ignore[arg-type]  # None only with kind None (returned above)
    if found_kind not in kinds:
        raise error(f"{path} is a checkpoint of {found_kind[:80]!r}, not of {kinds[0]}")
    if found_version not in versions:
        raise error(f"{path} has checkpoint format version {found_version}; this "
                    f"version of subid reads version {' or '.join(map(str, versions))}")
    for name in list(arrays):
        value = arrays[name]
        want = np.int64 if value.dtype.kind in "iu" else np.float64
        arrays[name] = check_array(value, f"checkpoint {path}: array {name!r}", error,
                                   dtype=want, finite=False)
    settings = dict(settings, _version=found_version)
    return arrays, settings


def require(arrays: dict, path, name: str, shape=None, dtype=np.float64) -> np.ndarray:
    """The array ``name`` of a loaded checkpoint, with its dtype, shape and
    finiteness checked against the schema (``dtype`` exactly, native order)."""
    if name not in arrays:
        raise CheckpointError(f"checkpoint {path} lacks the array {name!r}", path=str(path))
    return check_array(arrays[name], f"checkpoint {path}: array {name!r}",
                       functools.partial(CheckpointError, path=str(path)), dtype=dtype,
                       shape=shape)
