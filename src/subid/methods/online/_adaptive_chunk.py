"""The validation of a chunk given to :meth:`subid.AdaptiveIdentifier.update` (out of
:mod:`subid.methods.online.adaptive`, which is at the size limit of a module)."""

from __future__ import annotations

import numbers

import numpy as np

from subid._validation import as_chunk, check_time_stamps
from subid.errors import DataError
from subid.methods.online.base import check_stream_grid, writeable

__all__ = ["parse_chunk"]


def parse_chunk(ident, u, y, t):
    """Validate one chunk of ``ident`` (an AdaptiveIdentifier).

    Returns
    -------
    tuple or None
        ``(U, Y, T)``: the samples as writeable float64 arrays (one kernel
        specialisation) and the time stamps, None on the constructor's ``dt``
        grid; None for an empty chunk (0 samples, ``t`` None or empty), which
        changes nothing.

    Raises
    ------
    DataError
        Bad samples; no time information; time stamps not after the last sample,
        or, with the constructor's ``dt``, off its grid
        (:func:`~subid.methods.online.base.check_stream_grid`, the check of
        :class:`~subid.RecursiveSubspace`).
    """
    data = None
    if y is None or type(u) is not np.ndarray:
        u, y, t, data = ident._unpack(u, y, t)
    U = writeable(as_chunk(u, ident._nu, "input u", allow_empty=True))
    Y = writeable(as_chunk(y, ident._ny, "output y", allow_empty=True))
    if U.shape[0] != Y.shape[0]:
        raise DataError(f"input u has {U.shape[0]} samples but output y has {Y.shape[0]}; "
                        "they must have the same length")
    N = U.shape[0]
    if N == 0:                  # an empty chunk (a stream may deliver one): nothing to do
        if t is not None:
            check_time_stamps(np.reshape(t, -1) if np.ndim(t) else t, 0)
        return None
    if data is not None and t is None and ident._dt is None:
        t = next_times(ident, data.n_samples, data.dt)   # the record's dt continues
    if t is None:
        if ident._dt is None:
            raise DataError("no time stamps: pass t=... to update() or set dt=... in the "
                            "AdaptiveIdentifier constructor")
        return U, Y, None
    try:
        T = np.asarray(t, dtype=np.float64) if not isinstance(t, numbers.Real) else \
            np.array([float(t)])
    except (TypeError, ValueError, OverflowError):
        raise DataError(f"time stamps t must be numbers (a number, or an array of {N}), got "
                        f"{type(t).__name__} {t!r}"[:300]) from None
    T = writeable(check_time_stamps(T.reshape(-1) if T.ndim == 0 else T, N))
    if ident.n_samples and not T[0] > ident.t:
        raise DataError(f"time stamps t start at {float(T[0])!r}, not after the last sample "
                        f"processed (t = {ident.t!r}); time must increase from chunk to "
                        "chunk")
    if ident._dt is not None:
        check_stream_grid(T, ident._dt, ident.t if ident.n_samples else None,
                          f"the AdaptiveIdentifier was created with dt={ident._dt!r}",
                          "resample the data, or create the identifier with dt=None for "
                          "non-uniform time stamps")
    return U, Y, T


def next_times(ident, N: int, dt: float) -> np.ndarray:
    """Time stamps of N samples of period ``dt`` continuing the stream of ``ident``."""
    k = ident.n_samples + np.arange(N)
    return ident._t_origin + dt * (k - ident._k_origin)
