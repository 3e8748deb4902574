"""The array arguments of subid's compiled kernels, in one numba specialisation.

numba compiles a ``cache=True`` kernel once for every combination of argument
types it is called with, and an array's type includes its layout (C, F, any)
and whether it is writeable. A kernel called once with the user's (writeable)
arrays and once with an :class:`~subid.data.IOData` record's (read-only) ones
is compiled twice, the second time on the user's first call of that kind
(seconds to tens of seconds) instead of by :mod:`subid.warmup` at install.
The wrappers therefore pass every array a kernel only reads through
:func:`frozen` (a read-only C-contiguous view, no copy when the array already
is C-contiguous float64), and arrays it writes as fresh writeable ones, so that
each kernel sees one signature whatever the caller passed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["frozen", "read_only"]


def frozen(values, dtype=np.float64) -> np.ndarray:
    """``values`` as a read-only C-contiguous array of ``dtype`` (a view when no
    conversion is needed: the caller's array itself is left writeable)."""
    if type(values) is not np.ndarray or values.dtype != dtype \
            or not values.flags.c_contiguous:
        values = np.ascontiguousarray(values, dtype=dtype)
    if values.flags.writeable:
        values = values.view()
        values.flags.writeable = False
    return values


def read_only(*arrays: np.ndarray) -> tuple:
    """:func:`frozen` of each array, keeping its dtype (for a kernel's argument list)."""
    return tuple([frozen(a, a.dtype) for a in arrays])
