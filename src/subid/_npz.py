"""Loading ``.npz`` archives safely: no pickles, no allocation a header lies about.

``numpy.load`` trusts each member's ``.npy`` header: a corrupted header can
declare a shape of terabytes (numpy then tries to allocate it) or be text
that its parser rejects with ``SyntaxError``/``tokenize.TokenError``. Here
every member's header is read first and its declared size checked against
the member's actual size in the archive; only then are the arrays loaded.
"""

from __future__ import annotations

import zipfile

import numpy as np


class NpzError(Exception):
    """The archive is not a readable, trustworthy .npz file (the message says why)."""


def load_npz(path) -> dict:
    """All arrays of an ``.npz`` archive, or :class:`NpzError`."""
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with archive.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(member)
                    elif version in ((2, 0), (3, 0)):
                        shape, _, dtype = np.lib.format.read_array_header_2_0(member)
                    else:
                        raise NpzError(f"member {info.filename} has .npy version {version}")
                    declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
                    if declared > info.file_size:
                        raise NpzError(f"member {info.filename} declares {declared} bytes but "
                                       f"holds {info.file_size}")
        with np.load(path, allow_pickle=False) as npz:
            return {key: npz[key] for key in npz.files}
    except NpzError:
        raise
    except Exception as exc:  # zipfile, zlib, numpy header parsing (SyntaxError, TokenError...)
        if "allow_pickle" in str(exc):
            raise NpzError("it holds object (pickled) arrays, which are not loaded for "
                           "safety") from None
        raise NpzError(f"{type(exc).__name__}: {exc}") from None
