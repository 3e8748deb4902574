"""State-variable filters of :class:`subid.methods.online.adaptive.AdaptiveIdentifier`.

The filters (6a)-(6b) of seed 000 (Afri, Bako, Andrieu, Dufour, CDC 2015) and
the instrument filter of ``method='iv'``: validation of their poles, the
time-scaled companion form ``ż = ω (Λ_c(â) z + l w)`` (``docs/seed000.md``,
"Time-scaled filter states"), and the exact discretisation tables per step
length for the held signals (:func:`subid.model._simulate.expm_blocks`).
"""

from __future__ import annotations

import numbers

import numpy as np

from subid.errors import SubidError
from subid.model._simulate import expm_blocks

__all__ = ["companion", "discretise", "filter_poles"]

# Step lengths whose tables are cached (non-uniform streams).
STEP_CACHE = 64


def filter_poles(poles, f, name: str = "filter_poles") -> np.ndarray:
    """Validate ``filter_poles``: a negative number (repeated f times) or f
    poles with negative real parts, complex ones in conjugate pairs
    (``f=None``: any number of poles)."""
    if isinstance(poles, numbers.Number) and not isinstance(poles, bool):
        poles = [poles] * f
    try:
        arr = np.asarray(poles, dtype=np.complex128).reshape(-1)
    except (TypeError, ValueError):
        raise SubidError(f"{name} must be a negative number or {f} poles, "
                         f"got {poles!r}") from None
    if f is not None and arr.size != f:
        raise SubidError(f"{name} has {arr.size} poles but the filter order is the "
                         f"horizon, {f}; give {f} poles or one negative number")
    if arr.size == 0:
        raise SubidError(f"{name} is empty")
    if not np.all(np.isfinite(arr)):
        raise SubidError(f"{name} must be finite")
    if np.any(arr.real >= 0):
        raise SubidError(f"{name} must have negative real parts (a stable filter), got "
                         f"{np.round(arr, 6).tolist()}; e.g. {name}=-2.0")
    if not np.allclose(np.sort_complex(arr), np.sort_complex(arr.conj()), rtol=1e-12, atol=0):
        raise SubidError(f"complex {name} must come in conjugate pairs")
    return arr


def companion(poles: np.ndarray, scale: bool):
    """State-variable filter ``F̂(s) = ω^m / d(s)`` in time-scaled companion
    form: ``ż = ω (Λ_c(â) z + l w)``, ``z_k = ω^{-k} s^k F̂(s) w``, with
    ``ω = |d(0)|^{1/m}`` (1 when not ``scale``). Returns (Af, Bf, ω)."""
    m = poles.size
    coeffs = np.real(np.poly(poles))                 # [1, a_{m-1}, ..., a_0]
    omega = float(np.abs(np.prod(poles)) ** (1.0 / m)) if scale else 1.0
    scaled = coeffs[1:] / omega ** np.arange(1, m + 1)   # â_{m-1}, ..., â_0
    Lc = np.zeros((m, m))
    Lc[:-1, 1:] = np.eye(m - 1)
    Lc[-1, :] = -scaled[::-1]                        # [-â_0, ..., -â_{m-1}]
    Bf = np.zeros((m, 1))
    Bf[-1, 0] = omega
    return omega * Lc, Bf, omega


def discretise(steps, Af, Bf, Ai, Bi, mi, hold, cache, alpha, beta):
    """Discretisation tables for the distinct step lengths ``steps``.

    Returns ``(Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, lamM, lamT)``: per step h, the
    filter ``z_k = Fphi z_{k-1} + Fg0 w_{k-1} + Fg1 w_k`` (exact for the held
    signal, ``hold``), the same for the instrument filter ``(Ai, Bi)`` (order
    ``mi``; zeros when ``Ai`` is None), and the forgetting factors
    ``e^{-α h}``, ``e^{-β h}``. ``cache`` (a dict, step -> tables) keeps up to
    ``STEP_CACHE`` steps between calls.
    """
    f = Af.shape[0]
    K = steps.shape[0]
    Fphi = np.empty((K, f, f))
    Fg0 = np.empty((K, f))
    Fg1 = np.empty((K, f))
    Iphi = np.zeros((K, mi, mi))
    Ig0 = np.zeros((K, mi))
    Ig1 = np.zeros((K, mi))
    iv = Ai is not None

    def blocks(A, B, hs):
        Ph, G1, G2 = expm_blocks(A, B, hs, hold)
        g0 = G1[:, :, 0] - G2[:, :, 0] if G2 is not None else G1[:, :, 0]
        g1 = G2[:, :, 0] if G2 is not None else np.zeros_like(g0)
        return Ph, g0, g1

    missing = [i for i, h in enumerate(steps) if float(h) not in cache]
    if missing:
        F = blocks(Af, Bf, steps[missing])
        I = blocks(Ai, Bi, steps[missing]) if iv else None
        for j, i in enumerate(missing):
            entry = (F[0][j], F[1][j], F[2][j]) + (
                (I[0][j], I[1][j], I[2][j]) if iv else (Iphi[i], Ig0[i], Ig1[i]))
            if len(cache) < STEP_CACHE:
                cache[float(steps[i])] = entry
            Fphi[i], Fg0[i], Fg1[i], Iphi[i], Ig0[i], Ig1[i] = entry
    for i, h in enumerate(steps):
        entry = cache.get(float(h))
        if entry is not None:
            Fphi[i], Fg0[i], Fg1[i], Iphi[i], Ig0[i], Ig1[i] = entry
    return Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, np.exp(-alpha * steps), np.exp(-beta * steps)
