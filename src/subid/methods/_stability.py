"""Stability of a discrete-time estimate (from time or frequency data): when it must
be enforced (``stability='auto' | 'enforce' | 'none'``, from the growth of the data) and
how (regularised shift invariance, or reflection of the unstable poles).
:func:`subid.methods.dt._subspace.stable_choice` applies them to an estimate."""

from __future__ import annotations

import math
import warnings
import weakref

import numpy as np
import scipy.linalg

from subid.data import IOData
from subid.errors import OptionError, UnstableModelWarning

STABILITY = ("auto", "enforce", "none")
#: 'auto' keeps an unstable model only when its residual on the estimation data is
#: below this fraction of the stabilised model's: the data demand the instability.
KEEP_UNSTABLE_RATIO = 0.9
#: Spectral radius of a model whose stability was enforced, at most.
STABLE_RADIUS = 0.9999
#: Output growth (RMS of the last tenth over the first) above which data "grow".
GROWTH_LIMIT = 3.0
#: How many recent spectral radii :func:`spectral_radius` keeps.
_RADII_KEPT = 4
#: The last spectral radii computed, as ``((shape, dtype, bytes), radius)`` pairs.
_RADII: tuple = ()
#: The last record growths computed, as ``(weak reference to the record, growth)`` pairs.
_GROWTHS: tuple = ()


def spectral_radius(A) -> float:
    """``max |eig(A)|`` of a square float matrix (``numpy.linalg.eigvals``), the last
    few kept by content: the steps of one candidate model (the stability rule, the B,
    D, x0 regression, the model's diagnostics) ask it of the same A several times. The
    same value as computing it afresh (the same routine on the same bytes)."""
    global _RADII
    A = np.asarray(A)
    key = (A.shape, A.dtype.str, A.tobytes())
    for k, value in _RADII:
        if k == key:
            return value
    value = float(np.abs(np.linalg.eigvals(A)).max())
    _RADII = ((key, value),) + _RADII[:_RADII_KEPT - 1]    # one assignment: thread-safe
    return value


def stability_request(stability: str, A, data, method: str) -> bool:
    """Whether stability must be enforced on ``A``.

    ``'none'``: never. ``'enforce'``: whenever A is unstable, with a warning
    when the data themselves grow (:func:`output_growth` at least
    :data:`GROWTH_LIMIT`). ``'auto'`` (default): when A is unstable (spectral
    radius >= 1) and the record's raw samples are at hand; the caller then fits
    both and keeps the unstable A only where it explains the estimation data
    clearly better (:data:`KEEP_UNSTABLE_RATIO`): an unstable plant, growing or
    held by feedback, keeps it, a spurious unstable mode is removed. From a
    statistic alone (no raw samples) ``'auto'`` cannot compare and does not act.

    Until session 24 data whose output grew kept the unstable A without the
    comparison. A lightly damped plant building up from rest grows too: two modes
    at 1 and 1.15 rad/s, damping 0.01, sampled at 0.2 s, 10 % output noise, 400 and
    1000 samples (session 24's exploratory test, estimation output growing 4.9-10x)
    kept unstable models (spectral radius 1.0003-1.005) whose stabilised ones fitted
    the estimation data as well (residual RMS within 4 %) and validated better.
    """
    if stability not in STABILITY:
        raise OptionError(f"stability must be one of {STABILITY}, got {stability!r}")
    if stability == "none" or spectral_radius(A) < 1.0:
        return False
    if stability == "enforce":
        growth = record_growth(data) if isinstance(data, IOData) else None
        if growth is not None and growth >= GROWTH_LIMIT:
            warnings.warn(f"{method}: stability='enforce' on data whose output grows "
                          f"{growth:.3g}x over the record: the plant looks unstable, and a "
                          "stable model cannot follow it; use stability='none' to keep the "
                          "unstable estimate", UnstableModelWarning, stacklevel=4)
        return True
    return isinstance(data, IOData)


def stable_shift_invariance(Q: np.ndarray, n_outputs: int, radius: float = STABLE_RADIUS):
    """A stable A from an orthonormal basis ``Q`` of the observability range.

    Regularised shift invariance (Maciejowski, "Guaranteed stability with
    subspace methods", Systems & Control Letters 26, 1995; Van Gestel et al.,
    IEEE TAC 46(9), 2001): minimise
    ``||Q_up A - Q_down||^2 + c ||Q_last A||^2`` with ``Q_last`` the last block
    row. For c = 0 it is the ordinary estimate; for c = 1 the solution is
    ``A = Q_up^T Q_down = Q^T S Q`` (``Q^T Q = I``, S the block shift, of norm
    1), so ``||A||_2 <= 1`` and A is stable. The smallest c in [0, 1] giving a
    spectral radius at most ``radius`` is found by bisection (40 steps); if
    even c = 1 reaches only ``radius < rho <= 1``, A is scaled by
    ``radius / rho``.

    Returns
    -------
    A : ndarray
        In the basis of ``Q``.
    c : float
        The regularisation weight used.
    """
    up, down, last = Q[:-n_outputs], Q[n_outputs:], Q[-n_outputs:]
    n = Q.shape[1]

    def solve(c):
        lhs = np.vstack([up, math.sqrt(c) * last])
        rhs = np.vstack([down, np.zeros((n_outputs, n))])
        return scipy.linalg.lstsq(lhs, rhs, lapack_driver="gelsy", check_finite=False)[0]

    def rho(M):
        return float(np.abs(np.linalg.eigvals(M)).max())

    A1 = solve(1.0)
    if rho(A1) > radius:
        return A1 * (radius / rho(A1)), 1.0
    lo, hi, best = 0.0, 1.0, A1
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        A = solve(mid)
        if rho(A) <= radius:
            hi, best = mid, A
        else:
            lo = mid
    return best, hi


def reflect_unstable_poles(A, radius: float = STABLE_RADIUS, max_condition: float = 1e8):
    """A with every pole p outside the unit circle replaced by ``1/conj(p)``.

    The reflected pole has the same frequency and the reciprocal radius (the
    stable spectral factor of the same amplitude response); a pole on the
    unit circle or reflected above ``radius`` is pulled in to ``radius``.
    Computed through the eigendecomposition ``A = V Λ V^{-1}`` (basis
    invariant); None when V is ill-conditioned (a nearly defective A), where
    the eigenvector basis is unreliable.
    """
    lam, V = np.linalg.eig(A)
    if np.linalg.cond(V) > max_condition:
        return None
    mag = np.abs(lam)
    new = np.where(mag >= 1.0, lam / np.maximum(mag, 1e-300) ** 2, lam)
    new_mag = np.abs(new)
    new = np.where(new_mag > radius, new / np.maximum(new_mag, 1e-300) * radius, new)
    return np.linalg.solve(V.T, (V * new).T).T.real      # V diag(new) V^{-1}


def record_growth(data) -> float:
    """:func:`output_growth` of a record: the largest over its experiments. The last few
    records asked are kept (by identity, weakly: an :class:`subid.IOData` never changes):
    every unstable candidate of a cross-validation fold asks it of the fold's record
    (at 10^5 samples, 5 ms a time)."""
    global _GROWTHS
    for ref, value in _GROWTHS:
        if ref() is data:
            return value
    value = max(output_growth(e.y) for e in data.experiments)
    try:
        ref = weakref.ref(data)
    except TypeError:                 # not weakly referenceable: not kept
        return value
    _GROWTHS = ((ref, value),) + _GROWTHS[:_RADII_KEPT - 1]   # one assignment: thread-safe
    return value


def output_growth(y: np.ndarray, centred: bool = True) -> float:
    """Ratio of the RMS of the last tenth of ``y`` to that of its first tenth
    (largest over the channels, after removing each channel's mean; with
    ``centred=False`` about zero: a plant diverging in one direction from rest, whose
    mean the late samples dominate, grows 19x so and 1.8x centred)."""
    k = max(y.shape[0] // 10, 1)
    mean = y.mean(axis=0) if centred else 0.0   # only the two tenths are centred
    first = np.sqrt(np.mean((y[:k] - mean) ** 2, axis=0))
    last = np.sqrt(np.mean((y[-k:] - mean) ** 2, axis=0))
    return float(np.max(last / np.maximum(first, 1e-300)))
