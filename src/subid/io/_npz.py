"""Loading ``.npz`` archives safely: no pickles, no allocation a header lies about.

``numpy.load`` trusts each member's ``.npy`` header and the archive's
directory: a corrupted header can declare a shape of terabytes (numpy then
tries to allocate it), a member not named ``*.npy`` is decompressed whole
into memory (a 3 MB archive of zeros expands to gigabytes), and header text
can make its parser raise ``SyntaxError``/``tokenize.TokenError``. Here every
member must be a ``.npy`` array whose header parses, whose declared size is
exactly what the member holds, and whose total stays within the caller's
budget: the file's own size plus ``max_expanded`` bytes of decompression.
Data are then read in bounded pieces, never more than the header declares.
"""

from __future__ import annotations

import ast
import zipfile

import numpy as np

from subid.io._files import MAX_EXPANDED_BYTES

_PIECE = 1 << 20                 # bytes read from a member at a time
_MAX_HEADER = 1 << 16            # a .npy header is a short dict literal
_MAX_MEMBERS = 10_000


class NpzError(Exception):
    """The archive is not a readable, trustworthy .npz file (the message says why)."""


class NpzLimitError(NpzError):
    """The archive is well formed but expands to more than the caller allowed."""


def _read_exact(member, count: int, name: str) -> bytes:
    """``count`` bytes of ``member``, read in bounded pieces."""
    buf = bytearray()          # grows with the data actually read, not the declared size
    while len(buf) < count:
        piece = member.read(min(count - len(buf), _PIECE))
        if not piece:
            raise NpzError(f"member {name} is truncated")
        buf += piece
    return bytes(buf)


def _header(member, name: str):
    """``(shape, fortran_order, dtype, header length)`` of a ``.npy`` member."""
    magic = member.read(8)
    if len(magic) != 8 or magic[:6] != b"\x93NUMPY":
        raise NpzError(f"member {name} is not a .npy array")
    major = magic[6]
    if major == 1:
        size_bytes, length = 2, None
    elif major in (2, 3):
        size_bytes = 4
    else:
        raise NpzError(f"member {name} has .npy version {major}.{magic[7]}")
    raw = member.read(size_bytes)
    if len(raw) != size_bytes:
        raise NpzError(f"member {name} has a truncated header")
    length = int.from_bytes(raw, "little")
    if length > _MAX_HEADER:
        raise NpzError(f"member {name} declares a {length}-byte header")
    text = _read_exact(member, length, name)
    try:
        header = ast.literal_eval(bytes(text).decode("utf-8" if major == 3 else "latin-1"))
    except Exception as exc:        # SyntaxError, ValueError, MemoryError on nesting...
        raise NpzError(f"member {name} has a corrupted header ({type(exc).__name__})") from None
    if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
        raise NpzError(f"member {name} has a corrupted header")
    shape, fortran, descr = header["shape"], header["fortran_order"], header["descr"]
    if not isinstance(shape, tuple) or len(shape) > 32 or not all(
            isinstance(d, int) and not isinstance(d, bool) and 0 <= d < 2**63 for d in shape):
        raise NpzError(f"member {name} has an invalid shape {shape!r}"[:200])
    if not isinstance(fortran, bool) or not isinstance(descr, str):
        raise NpzError(f"member {name} has a corrupted header")
    try:
        dtype = np.dtype(descr)
    except Exception:
        raise NpzError(f"member {name} has an invalid dtype {descr!r}"[:200]) from None
    if dtype.hasobject:
        raise NpzError("it holds object (pickled) arrays, which are not loaded for safety")
    if dtype.kind not in "biufcUSMm" or dtype.itemsize == 0 and dtype.kind not in "US":
        raise NpzError(f"member {name} has the unsupported dtype {dtype}")
    return shape, fortran, dtype, 8 + size_bytes + length


def npy_header(fh, name: str):
    """``(shape, fortran_order, dtype, header bytes)`` of the ``.npy`` file ``fh``,
    validated (bounded header, literal parsing, numeric or text dtype), or NpzError."""
    try:
        return _header(fh, name)
    except NpzError:
        raise
    except Exception as exc:
        raise NpzError(f"{type(exc).__name__}: {exc}"[:200]) from None


def load_npz(source, *, max_expanded: int = MAX_EXPANDED_BYTES, size: int | None = None) -> dict:
    """All arrays of an ``.npz`` archive, or :class:`NpzError`.

    Parameters
    ----------
    source : path or binary file object
        The archive (a file object opened by :func:`subid.io._files.open_regular`).
    max_expanded : int
        Bytes the arrays may occupy beyond the archive's own size (what a
        compressed archive may expand to). :class:`NpzLimitError` beyond.
    size : int, optional
        The archive's size in bytes (found from ``source`` when omitted).
    """
    try:
        if size is None:
            if hasattr(source, "seek"):
                size = source.seek(0, 2)
                source.seek(0)
            else:
                import os
                size = os.stat(source).st_size
        budget = size + max_expanded
        out, total = {}, 0
        with zipfile.ZipFile(source) as archive:
            infos = archive.infolist()
            if len(infos) > _MAX_MEMBERS:
                raise NpzError(f"the archive has {len(infos)} members")
            for info in infos:
                name = info.filename
                if not name.endswith(".npy"):
                    raise NpzError(f"member {name!r} is not a .npy array (a .npz archive "
                                   "holds only arrays written by numpy.savez)")
                key = name[:-4]
                if key in out:
                    raise NpzError(f"the array {key!r} appears twice")
                with archive.open(info) as member:
                    shape, fortran, dtype, head = _header(member, name)
                    count = 1
                    for d in shape:
                        count *= d
                    declared = count * dtype.itemsize
                    if head + declared != info.file_size:
                        raise NpzError(f"member {name} declares {declared} bytes but holds "
                                       f"{info.file_size - head}")
                    total += declared
                    if total > budget:
                        raise NpzLimitError(
                            f"its arrays take {total} bytes (member {name} alone declares "
                            f"{declared}), more than the {size}-byte file plus the "
                            f"{max_expanded} bytes of decompression allowed (max_bytes); "
                            "pass a larger max_bytes if the file is genuine")
                    raw = _read_exact(member, declared, name)
                    if member.read(1):
                        raise NpzError(f"member {name} holds more data than it declares")
                arr = np.frombuffer(raw, dtype=dtype, count=count) if declared else \
                    np.zeros(count, dtype=dtype)
                arr = arr.reshape(shape[::-1]).T if fortran else arr.reshape(shape)
                out[key] = arr
        return out
    except NpzError:
        raise
    except RecursionError:
        raise NpzError("RecursionError: nested too deeply") from None
    except Exception as exc:  # zipfile, zlib, CRC errors, struct errors...
        text = "".join(ch if ch.isprintable() else "?" for ch in str(exc))[:160]
        raise NpzError(f"{type(exc).__name__}: {text}") from None
