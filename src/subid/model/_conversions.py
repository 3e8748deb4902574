"""Conversions of models: sampling (:meth:`StateSpace.to_discrete`), its exact inverse
(:meth:`StateSpace.to_continuous`), and python-control and :mod:`scipy.signal` systems.

The functions return matrices; the class builds the model (names, ``info``, hold).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

import subid.model._simulate as _simulate
from subid.delay import input_delay_of
from subid.errors import ModelError
from subid.model._checks import _EPS, _check_nonsingular, _model_dt

_CONVERSION_METHODS = {"zoh": "zoh", "foh": "foh", "bilinear": "bilinear",
                       "tustin": "bilinear"}


def _method(method) -> str:
    if not isinstance(method, str) or method.lower() not in _CONVERSION_METHODS:
        raise ModelError(f"method must be 'zoh', 'foh' or 'bilinear' (alias 'tustin'), "
                         f"got {method!r}")
    return _CONVERSION_METHODS[method.lower()]


def _require_control():
    try:
        import control
    except ImportError:
        from subid._extras import install_hint
        raise ImportError("python-control is not installed: "
                          + install_hint("control", "control")) from None
    return control


def _resolve_dt(sys_dt, dt, source: str) -> float:
    """Sampling period of a foreign system whose dt may be True/None."""
    if sys_dt is True:
        if dt is None:
            raise ModelError(f"the {source} system is discrete-time with an unspecified "
                             "sampling period (dt=True); pass the period, e.g. dt=0.1")
        return _model_dt(dt)
    if sys_dt is None or sys_dt is False:
        return 0.0 if dt is None else _model_dt(dt)
    value = _model_dt(sys_dt, name=f"the {source} system's dt")
    if dt is not None and _model_dt(dt) != value:
        raise ModelError(f"dt={dt!r} contradicts the {source} system's sampling "
                         f"period {value!r}")
    return value


def discretise(A, B, C, D, dt: float, method: str):
    """``(Ad, Bd, Cd, Dd)`` of the continuous-time ``(A, B, C, D)`` sampled with period
    ``dt`` and ``method`` ('zoh', 'foh' or 'bilinear'): the formulas of
    :func:`scipy.signal.cont2discrete`."""
    n = A.shape[0]
    if method == "bilinear":
        ima = np.eye(n) - 0.5 * dt * A
        _check_nonsingular(ima, "I - dt/2 A",
                           f"A has an eigenvalue at 2/dt = {2 / dt:g}, where the "
                           "bilinear transform is undefined")
        Ad = np.linalg.solve(ima, np.eye(n) + 0.5 * dt * A)
        Bd = np.linalg.solve(ima, dt * B)
        Cd = np.linalg.solve(ima.T, C.T).T
        Dd = D + 0.5 * C @ Bd
    else:
        Phi, G1, G2 = _simulate.expm_blocks(A, B, [dt], method)
        Ad, Bd, Cd, Dd = Phi[0], G1[0], C, D
        if method == "foh":
            Bd = G1[0] - G2[0] + Phi[0] @ G2[0]
            Dd = D + C @ G2[0]
    return Ad, Bd, Cd, Dd


def continuise(Ad, Bd, Cd, Dd, h: float, method: str):
    """``(A, B, C, D, hold)`` of the continuous-time model whose discretisation with
    period ``h`` and ``method`` is ``(Ad, Bd, Cd, Dd)``; ``hold`` None for
    'bilinear' (the model keeps its own)."""
    n = Ad.shape[0]
    eye = np.eye(n)
    if method == "bilinear":
        E = eye + Ad
        _check_nonsingular(E, "I + A_d", "A_d has an eigenvalue at -1, which the "
                           "bilinear transform maps to infinity")
        M = np.linalg.solve(E, 2.0 * eye)          # M = I - h/2 A
        A = (2.0 / h) * (eye - M)
        B = M @ Bd / h
        C = Cd @ M
        D = Dd - 0.5 * C @ Bd
        return A, B, C, D, None
    A = _real_logm(Ad) / h
    Phi, W1, W2 = _simulate.expm_blocks(A, eye, [h], method)
    if method == "zoh":
        _check_nonsingular(W1[0], "the hold integral of exp(A t)",
                           "B cannot be recovered from A_d and B_d")
        B = np.linalg.solve(W1[0], Bd)
        return A, B, Cd, Dd, "zoh"
    K = W1[0] - W2[0] + Phi[0] @ W2[0]
    _check_nonsingular(K, "the first-order-hold input map",
                       "B cannot be recovered from A_d and B_d")
    B = np.linalg.solve(K, Bd)
    D = Dd - Cd @ (W2[0] @ B)
    return A, B, Cd, D, "foh"


def to_control(model):
    """python-control system of ``model`` (:meth:`StateSpace.to_control`)."""
    control = _require_control()
    m = _without_delay(model)
    return control.ss(np.array(m._A), np.array(m._B), np.array(m._C),
                      np.array(m._D), m._dt, inputs=list(m.input_names),
                      outputs=list(m.output_names))


def from_control(cls, sys, dt=None):
    """``cls`` from a python-control system (:meth:`StateSpace.from_control`)."""
    control = _require_control()
    if not isinstance(sys, control.StateSpace):
        if isinstance(sys, control.LTI):
            sys = control.ss(sys)
        else:
            raise ModelError(f"expected a python-control system, got "
                             f"{type(sys).__name__}")
    period = _resolve_dt(sys.dt, dt, "python-control")
    return cls(np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C),
               np.asarray(sys.D), period, input_names=list(sys.input_labels),
               output_names=list(sys.output_labels))


def to_scipy(model):
    """:class:`scipy.signal.StateSpace` of ``model`` (:meth:`StateSpace.to_scipy`)."""
    from scipy import signal
    m = _without_delay(model)
    mats = [np.array(M) for M in (m._A, m._B, m._C, m._D)]
    if m.is_continuous:
        return signal.StateSpace(*mats)
    return signal.StateSpace(*mats, dt=m._dt)


def from_scipy(cls, sys, dt=None):
    """``cls`` from a :mod:`scipy.signal` LTI system (:meth:`StateSpace.from_scipy`)."""
    from scipy import signal
    if not isinstance(sys, (signal.lti, signal.dlti)):
        raise ModelError(f"expected a scipy.signal lti or dlti system, got "
                         f"{type(sys).__name__}")
    if not isinstance(sys, signal.StateSpace):
        sys = sys.to_ss()
    period = _resolve_dt(sys.dt, dt, "scipy")
    return cls(sys.A, sys.B, sys.C, sys.D, period)


def _real_logm(Ad: np.ndarray) -> np.ndarray:
    """Principal real logarithm of ``Ad``, or ModelError when none exists."""
    ev = np.linalg.eigvals(Ad)
    scale = max(1.0, float(np.abs(ev).max()))
    tiny = np.abs(ev) <= Ad.shape[0] * _EPS * scale
    if tiny.any():
        raise ModelError("A_d is singular (eigenvalue 0): no continuous-time model "
                         "discretises to it (a pole at z = 0 is an infinitely fast "
                         "continuous pole); use method='bilinear' instead")
    negative = (ev.real < 0) & (np.abs(ev.imag) <= 1e-8 * np.abs(ev))
    if negative.any():
        raise ModelError(f"A_d has the eigenvalue {ev[negative][0].real:.6g} on the "
                         "negative real axis, which has no real matrix logarithm: no "
                         "continuous-time model with this sampling period has this "
                         "discretisation; use method='bilinear' instead")
    with np.errstate(all="ignore"):
        L = linalg.logm(Ad)
    L = np.asarray(L)
    if not np.isfinite(L).all():
        raise ModelError("the matrix logarithm of A_d is not finite; A_d is too close "
                         "to singular")
    if np.iscomplexobj(L):
        if np.abs(L.imag).max() > 1e-8 * max(1.0, float(np.abs(L.real).max())):
            raise ModelError("A_d has no real matrix logarithm (the principal "
                             "logarithm is complex)")
        L = L.real
    return np.ascontiguousarray(L)


def _without_delay(model):
    """``model`` with its input delays as states, for exports that know no delays."""
    if input_delay_of(model) is None:
        return model
    from subid.delay import absorb_delay
    return absorb_delay(model)
