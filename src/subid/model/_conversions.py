"""Conversions of models: sampling (:meth:`StateSpace.to_discrete`), its exact inverse
(:meth:`StateSpace.to_continuous`), and python-control and :mod:`scipy.signal` systems.

The functions return matrices; the class builds the model (names, ``info``, hold).
"""

from __future__ import annotations

import math

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
    """Sampling period of a foreign system whose dt may be True/None.

    ``dt=None`` is continuous time for scipy (its ``lti``) but an unspecified time
    base for python-control, which ``dt`` may then fix."""
    if sys_dt is True:
        if dt is None:
            raise ModelError(f"the {source} system is discrete-time with an unspecified "
                             "sampling period (dt=True); pass the period, e.g. dt=0.1")
        return _model_dt(dt)
    continuous = sys_dt is None if source == "scipy" else (
        sys_dt is not None and sys_dt is not False and sys_dt == 0)
    if continuous:
        if dt is not None:
            reader = "from_scipy" if source == "scipy" else "from_control"
            raise ModelError(f"the {source} system is continuous-time, so dt={dt!r} would "
                             "read its matrices as discrete-time ones; convert it without "
                             f"dt and sample it: StateSpace.{reader}(sys).to_discrete({dt!r})")
        return 0.0
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
        with np.errstate(over="ignore", invalid="ignore"):
            Phi, G1, G2 = _simulate.expm_blocks(A, B, [dt], method)
        if not all(np.isfinite(M).all() for M in (Phi, G1, G2) if M is not None):
            fast = float(np.linalg.eigvals(A).real.max())
            raise ModelError(f"sampling with dt={dt!r} overflows: the model's fastest "
                             f"unstable mode grows as exp({fast:.6g} t), beyond the floating "
                             f"point range after one period (exp({fast * dt:.6g})); the "
                             "sampling period is too long for this model, use a shorter dt")
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


#: ``info`` entries that describe one realisation on one time base: the polynomials of a
#: polynomial method (in ``q^-1``), their degrees and the parameter covariance of the
#: matrices. A change of time base or of the realisation's meaning leaves them stale.
REALISATION_KEYS = ("polynomials", "orders", "parameter_covariance")
#: ``info`` entries in the state basis, which only a zero-order-hold conversion keeps: its
#: sampled state is the continuous state at the samples; a first-order hold's is
#: ``x - Gamma2 u`` (it depends on the input at the first sample), a bilinear one's
#: another combination of ``x`` and ``u``.
STATE_KEYS = ("x0", "selector")


def drop_info(info: dict, reasons: dict, *, note: bool = True) -> dict:
    """``info`` without the keys of ``reasons``, each one it held named with its reason in
    ``info['dropped']`` (and, for the covariance with ``note``,
    ``info['parameter_covariance_note']``, which :func:`subid.parameter_covariance`
    reports)."""
    out = dict(info)
    dropped = dict(out.get("dropped") or {})
    for key, reason in reasons.items():
        if out.pop(key, None) is not None:
            dropped[key] = reason
            if key == "parameter_covariance" and note:
                out["parameter_covariance_note"] = f"the covariance was dropped: {reason}"
    if dropped:
        out["dropped"] = dropped
    return out


def gain_info(info: dict, old_K, new_K) -> dict:
    """``info`` for a model whose Kalman gain ``old_K`` became ``new_K``
    (:meth:`StateSpace.with_noise_model`): without a parameter covariance that includes
    the gain, unless the gain is the same."""
    cov = info.get("parameter_covariance")
    same = old_K is not None and new_K is not None and np.array_equal(old_K, new_K)
    if isinstance(cov, dict) and cov.get("with_gain") and not same:
        return drop_info(info, {"parameter_covariance": (
            "with_noise_model() replaced the Kalman gain it includes")})
    return dict(info)


def converted_info(info: dict, what: str, method: str) -> dict:
    """``info`` for the result of ``what`` (``'to_discrete'``, ``'to_continuous'``) with
    ``method``: without the entries it no longer matches (:data:`REALISATION_KEYS`; the
    state-basis ones unless ``method`` is 'zoh')."""
    reason = f"{what}(method={method!r}) changed the time base of the model"
    reasons = dict.fromkeys(REALISATION_KEYS, reason)
    if method != "zoh":
        reasons.update(dict.fromkeys(STATE_KEYS, (
            f"{what}(method={method!r}): the state of the converted model is not the "
            "original state (it mixes in the input at the first sample); estimate the "
            "initial state on data (subid.fit_percent's x0='estimate')")))
    # no covariance note: subid.parameter_covariance explains a converted model itself
    return drop_info(info, reasons, note=False)


def transformed_info(info: dict, T: np.ndarray, Tinv: np.ndarray, shape) -> dict:
    """``info`` in the state basis ``z = T x`` (:meth:`StateSpace.transform`): the initial
    state(s), ``ls_subspace``'s selector and the parameter covariance follow it.

    ``shape`` is ``(n, n_inputs, n_outputs)``. The parameters (the row-major ``A, B, C``
    and ``D``, ``K`` when estimated) map linearly, ``vec(X M Y) = (X kron Y^T) vec(M)``
    row-major, so the covariance factor maps with the same matrix (exact)."""
    n, nu, ny = shape
    out = dict(info)
    value = out.get("x0")
    if value is not None and np.shape(value)[-1:] == (n,):
        out["x0"] = np.asarray(value, dtype=float) @ T.T
    value = out.get("selector")
    if value is not None and np.ndim(value) == 2 and np.shape(value)[0] == n:
        out["selector"] = T @ np.asarray(value, dtype=float)
    entry = out.get("parameter_covariance")
    if isinstance(entry, dict) and "factor" in entry and "parameters" in entry:
        blocks = [np.kron(T, Tinv.T), np.kron(T, np.eye(nu)), np.kron(np.eye(ny), Tinv.T)]
        if entry.get("with_feedthrough"):
            blocks.append(np.eye(ny * nu))
        if entry.get("with_gain"):
            blocks.append(np.kron(T, np.eye(ny)))
        M = linalg.block_diag(*blocks)
        params = np.asarray(entry["parameters"], dtype=float)
        factor = np.asarray(entry["factor"], dtype=float)
        if params.shape == (M.shape[0],) and factor.ndim == 2 \
                and factor.shape[0] == M.shape[0]:
            out["parameter_covariance"] = {**entry, "parameters": M @ params,
                                           "factor": M @ factor}
        else:
            out = drop_info(out, {"parameter_covariance": (
                "transform() could not map it (its parameters do not match the model's "
                "matrices); refine the model with subid.pem for a covariance")})
    return out


def _warn_hold(model, target: str) -> None:
    """ConversionWarning: ``target`` has no slot for the model's first-order hold."""
    if model.hold != "zoh":
        import warnings

        from subid.errors import ConversionWarning
        what = ("its simulation and sampling there will read it as a zero-order hold; "
                "sample it with its hold first (model.to_discrete(dt))"
                if model.is_continuous else
                "a conversion back to continuous time there will assume a zero-order hold; "
                "convert with model.to_continuous() (which uses the hold) instead")
        warnings.warn(f"the model assumes a first-order hold (hold={model.hold!r}), which a "
                      f"{target} system cannot carry: {what}, or set hold='foh' again on "
                      "the way back (StateSpace(..., hold='foh'))",
                      ConversionWarning, stacklevel=4)


def to_control(model):
    """python-control system of ``model`` (:meth:`StateSpace.to_control`)."""
    control = _require_control()
    _warn_hold(model, "python-control")
    m = _without_delay(model)
    return control.ss(np.array(m._A), np.array(m._B), np.array(m._C),
                      np.array(m._D), m._dt, inputs=list(m.input_names),
                      outputs=list(m.output_names))


def from_control(cls, sys, dt=None):
    """``cls`` from a python-control system (:meth:`StateSpace.from_control`)."""
    control = _require_control()
    if not isinstance(sys, control.StateSpace):
        if not isinstance(sys, control.LTI):
            raise ModelError(f"expected a python-control system, got "
                             f"{type(sys).__name__}")
        try:
            sys = control.ss(sys)
        except NotImplementedError as exc:   # control.exception.ControlMIMONotImplemented
            raise ModelError(f"python-control cannot turn this {type(sys).__name__} into "
                             f"a state-space system ({exc}); a MIMO transfer function "
                             "needs slycot (pip install slycot): convert it with "
                             "control.ss(sys) there and pass the state-space system") from None
    if np.asarray(sys.A).shape[0] == 0:
        raise ModelError("the python-control system is a static gain (no states), which a "
                         "subid model cannot hold (order >= 1); use its gain matrix sys.D "
                         "directly")
    period = _resolve_dt(sys.dt, dt, "python-control")
    return cls(np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C),
               np.asarray(sys.D), period, input_names=list(sys.input_labels),
               output_names=list(sys.output_labels))


def to_scipy(model):
    """:class:`scipy.signal.StateSpace` of ``model`` (:meth:`StateSpace.to_scipy`)."""
    from scipy import signal
    _warn_hold(model, "scipy.signal")
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


def drop_noise_model(model, what: str) -> None:
    """Warn that ``what`` (a conversion of ``model``) drops its noise model."""
    if model.K is not None or model.noise_cov is not None:
        import warnings

        from subid.errors import NoiseModelWarning
        warnings.warn(f"{what}: the Kalman gain K and the innovation covariance are "
                      "dropped (an innovation model is tied to its sampling period and "
                      "has no exact counterpart under this conversion); re-estimate "
                      "them on data (subid.pem) if needed", NoiseModelWarning,
                      stacklevel=3)


def raise_pole_hit(model, w, s):
    """ModelError: a frequency of :meth:`StateSpace.freqresp` falls on a pole."""
    poles = np.linalg.eigvals(model.A)
    dist = np.abs(s[:, None] - poles[None, :])
    i, j = np.unravel_index(np.argmin(dist), dist.shape)
    where = "s = j w" if model.is_continuous else "z = exp(j w dt)"
    raise ModelError(f"the frequency w={float(w[i])!r} rad/s falls on the pole {poles[j]:.6g} "
                     f"({where}): the frequency response is infinite there")


def _real_logm(Ad: np.ndarray) -> np.ndarray:
    """Principal real logarithm of ``Ad``, or ModelError when none exists.

    Eigenvalues on the negative real axis have a real logarithm only in pairs (Culver
    1966: their Jordan blocks pair up); ``Ad`` with semisimple negative eigenvalues of
    even multiplicity (e.g. ``-0.5 I``) gets the one whose pairs are ``log|z| +- i pi``
    (modes at the Nyquist frequency), see :func:`_negative_pairs_logm`."""
    ev = np.linalg.eigvals(Ad)
    scale = max(1.0, float(np.abs(ev).max()))
    tiny = np.abs(ev) <= Ad.shape[0] * _EPS * scale
    if tiny.any():
        raise ModelError("A_d is singular (eigenvalue 0): no continuous-time model "
                         "discretises to it (a pole at z = 0 is an infinitely fast "
                         "continuous pole); use method='bilinear' instead")
    negative = (ev.real < 0) & (np.abs(ev.imag) <= 1e-8 * np.abs(ev))
    if negative.any():
        L = _negative_pairs_logm(Ad)
        if L is None:
            values = ", ".join(f"{v:.6g}" for v in np.sort(ev[negative].real))
            raise ModelError(f"A_d has the eigenvalues {values} on the negative real "
                             "axis, which have no real matrix logarithm (one without an "
                             "equal partner, or not diagonalisable): no "
                             "continuous-time model with this sampling period has this "
                             "discretisation; use method='bilinear' instead")
        return L
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


def _negative_pairs_logm(Ad: np.ndarray):
    """A real logarithm of ``Ad`` whose eigenvalues on the negative real axis are
    semisimple and come in pairs; None otherwise.

    The real Schur form puts the negative eigenvalues first and a Sylvester equation
    decouples them from the others (principal logarithm). On the invariant plane of each
    pair (two real eigenvectors of ``z``, or ``Re v, Im v`` of a pair ``rho e^{+-i theta}``
    split off the axis by rounding) ``Ad`` acts as ``rho R(theta)`` (``theta = pi`` for
    the real pair), whose logarithm is ``log(rho) I + theta J`` (``J`` the rotation by 90
    degrees). The result is checked: ``expm(L) = Ad`` to 1e-8."""
    n = Ad.shape[0]
    with np.errstate(all="ignore"):
        try:
            T, Z, k = linalg.schur(Ad, output="real", sort=lambda re, im: bool(
                re < 0 and abs(im) <= 1e-8 * abs(complex(re, im))))
        except (linalg.LinAlgError, ValueError):
            return None
    if k == 0 or k % 2:
        return None
    T11, T12, T22 = T[:k, :k], T[:k, k:], T[k:, k:]
    try:
        X = linalg.solve_sylvester(T11, -T22, -T12) if k < n else np.zeros((k, 0))
        w, V = np.linalg.eig(T11)
    except (linalg.LinAlgError, ValueError):
        return None
    planes = [(V[:, i].real, V[:, i].imag, abs(w[i]), math.atan2(w[i].imag, w[i].real))
              for i in np.flatnonzero(w.imag > 0)]
    real = np.flatnonzero(w.imag == 0)
    real = real[np.argsort(w[real].real)]
    if real.size % 2 or 2 * len(planes) + real.size != k:
        return None
    for a, b in zip(real[::2], real[1::2]):
        if abs(w[a] - w[b]) > 1e-6 * abs(w[a]):
            return None                        # an unpaired negative eigenvalue
        planes.append((V[:, a].real, V[:, b].real, 0.5 * abs(w[a] + w[b]), math.pi))
    basis = np.column_stack([v for x, y, _, _ in planes for v in (x, y)])
    if np.linalg.cond(basis) > 1e8:
        return None                            # not diagonalisable: no pairs
    M = linalg.block_diag(*[[[math.log(rho), theta], [-theta, math.log(rho)]]
                            for _, _, rho, theta in planes])
    L11 = basis @ np.linalg.solve(basis.T, M.T).T
    with np.errstate(all="ignore"):
        L22 = np.asarray(linalg.logm(T22)) if k < n else np.zeros((0, 0))
    if np.iscomplexobj(L22):
        if L22.size and np.abs(L22.imag).max() > 1e-8 * max(1.0, np.abs(L22.real).max()):
            return None
        L22 = L22.real
    S = np.eye(n)
    S[:k, k:] = X                               # T = S blockdiag(T11, T22) S^-1
    Sinv = np.eye(n)
    Sinv[:k, k:] = -X
    L = Z @ S @ linalg.block_diag(L11, L22) @ Sinv @ Z.T
    with np.errstate(all="ignore"):
        ok = np.isfinite(L).all() and np.allclose(linalg.expm(L), Ad, rtol=1e-8,
                                                  atol=1e-8 * np.abs(Ad).max())
    return np.ascontiguousarray(L) if ok else None


def _without_delay(model):
    """``model`` with its input delays as states, for exports that know no delays."""
    if input_delay_of(model) is None:
        return model
    from subid.delay import absorb_delay
    return absorb_delay(model)
