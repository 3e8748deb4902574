"""Test systems and data generation: the papers' examples and random systems."""

from __future__ import annotations

import math
import numbers

import numpy as np
import scipy.linalg

from subid._validation import check_bool, check_dt, check_int, check_seed
from subid.data import IOData
from subid.errors import ModelError, OptionError, SubidError
from subid.model.statespace import StateSpace

__all__ = ["seed000_system", "seed001_system", "random_system", "simulate_data",
           "seed001_innovation_system", "simulate_innovation_data"]


def _real(value, name: str, *, low: float = -math.inf, high: float = math.inf,
          low_open: bool = False, what: str = "") -> float:
    """``value`` as a finite float in [low, high] (``(low, high]`` with ``low_open``);
    else :class:`OptionError` naming it."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) \
            or not math.isfinite(float(value)) or not low <= float(value) <= high \
            or (low_open and float(value) == low):
        bound = ("" if low == -math.inf else f" {'>' if low_open else '>='} {low:g}") + \
            ("" if high == math.inf else f"{' and' if low > -math.inf else ''} <= {high:g}")
        raise OptionError(f"{name} must be a finite number{bound}{what}; got {value!r}"[:300])
    return float(value)


def _check_system(system, name: str = "system") -> StateSpace:
    if not isinstance(system, StateSpace):
        raise ModelError(f"{name} must be a subid.StateSpace, got {type(system).__name__}"
                         + (" (load a model file with subid.load)"
                            if isinstance(system, str) else ""))
    return system


def _check_snr(value, name: str):
    return None if value is None else _real(value, name, what=" (dB), or None for no noise")


def seed000_system() -> StateSpace:
    """The 4-state, 2-input, 2-output continuous-time system of seed 000, Section V."""
    A = [[-1.4, 0.3, -0.6, -0.3],
         [0.3, -0.9, -0.9, 0.1],
         [-0.6, -0.9, -2.6, -1.0],
         [-0.3, 0.1, -1.0, -1.8]]
    B = [[0.0, 0.0], [-0.4, 1.3], [0.6, 0.2], [0.0, 0.6]]
    C = [[0.9, 0.0, 0.0, 1.3], [-1.1, -0.8, 0.9, 0.4]]
    D = [[0.8, -1.5], [0.0, 0.0]]
    return StateSpace(A, B, C, D, 0.0)


def seed001_system(dt: float = 1.0) -> StateSpace:
    """The 3rd-order, 2-input, 2-output system of seed 001, Section IV."""
    A = [[-0.0398, -0.4909, -0.6115],
         [0.4784, 0.4808, -0.4169],
         [-0.6214, 0.4020, -0.2488]]
    B = [[0.7433, 0.0], [0.0, -1.3193], [-0.8510, -0.0181]]
    C = [[-0.0028, 2.3968, 0.0], [-0.0857, 0.0264, -0.6553]]
    D = [[-1.7384, 0.0425], [0.7127, 0.0]]
    return StateSpace(A, B, C, D, dt)


def seed001_innovation_system(process_std: float = 0.3, measurement_std: float = 0.3,
                              dt: float = 1.0, feedthrough: bool = True) -> StateSpace:
    """Seed 001's system in innovation form.

    ``K`` and ``noise_cov`` are those of the steady-state Kalman filter for
    white process noise (covariance ``process_std**2 I``) on the state and
    white measurement noise (``measurement_std**2 I``) on the output, so
    ``A - K C`` is stable. ``feedthrough=False`` sets ``D = 0`` (closed-loop
    experiments).
    """
    process_std = _real(process_std, "process_std", low=0.0)
    measurement_std = _real(measurement_std, "measurement_std", low=0.0, low_open=True,
                            what=" (the innovation covariance must be positive definite)")
    dt = check_dt(dt)
    feedthrough = check_bool(feedthrough, "feedthrough")
    base = seed001_system(dt)
    A, C = base.A, base.C
    n, ny = A.shape[0], C.shape[0]
    Q = process_std ** 2 * np.eye(n)
    R = measurement_std ** 2 * np.eye(ny)
    P = scipy.linalg.solve_discrete_are(A.T, C.T, Q, R)
    sigma = C @ P @ C.T + R
    K = np.linalg.solve(sigma, (A @ P @ C.T).T).T
    D = base.D if feedthrough else 0
    return StateSpace(A, base.B, C, D, dt, K=K, noise_cov=sigma)


def _hankel_singular_values(A, B, C):
    P = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
    Q = scipy.linalg.solve_discrete_lyapunov(A.T, C.T @ C)
    return np.sqrt(np.sort(np.abs(np.linalg.eigvals(P @ Q)))[::-1])


def random_system(order: int, n_inputs: int, n_outputs: int, *, seed, dt: float = 1.0,
                  pole_radius=(0.2, 0.9), feedthrough: bool = True,
                  min_hsv_ratio: float = 1e-3, min_pole_distance: float = 0.05) -> StateSpace:
    """A random stable, minimal discrete-time system.

    Poles are drawn with magnitudes in ``pole_radius`` (real or in complex
    pairs), at least ``min_pole_distance`` apart; A is made dense by a random
    well-conditioned similarity; B, C (and D) are Gaussian. Draws are repeated
    (deterministically from ``seed``) until the ratio of the smallest to the
    largest Hankel singular value exceeds ``min_hsv_ratio``, i.e. the system
    is minimal with margin.
    """
    n = check_int(order, "order")
    nu = check_int(n_inputs, "n_inputs")
    ny = check_int(n_outputs, "n_outputs")
    rng = np.random.default_rng(check_seed(seed))
    r_lo, r_hi = _pole_radius(pole_radius)
    dt = check_dt(dt)
    feedthrough = check_bool(feedthrough, "feedthrough")
    min_hsv_ratio = _real(min_hsv_ratio, "min_hsv_ratio", low=0.0, high=1.0)
    min_pole_distance = _real(min_pole_distance, "min_pole_distance", low=0.0, high=2.0)
    for _ in range(1000):
        blocks, poles = [], []
        remaining = n
        while remaining > 0:
            r = rng.uniform(r_lo, r_hi)
            if remaining >= 2 and rng.random() < 0.5:
                theta = rng.uniform(0.1, np.pi - 0.1)
                re, im = r * np.cos(theta), r * np.sin(theta)
                blocks.append(np.array([[re, im], [-im, re]]))
                poles += [complex(re, im), complex(re, -im)]
                remaining -= 2
            else:
                p = r * rng.choice([-1.0, 1.0])
                blocks.append(np.array([[p]]))
                poles.append(complex(p))
                remaining -= 1
        p_all = np.array(poles)
        gaps = np.abs(p_all[:, None] - p_all[None, :]) + np.eye(n) * 10
        if gaps.min() < min_pole_distance:
            continue
        Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
        T = Q @ np.diag(rng.uniform(0.5, 2.0, n))
        A = T @ scipy.linalg.block_diag(*blocks) @ np.linalg.inv(T)
        B = rng.standard_normal((n, nu))
        C = rng.standard_normal((ny, n))
        D = rng.standard_normal((ny, nu)) if feedthrough else np.zeros((ny, nu))
        hsv = _hankel_singular_values(A, B, C)
        if hsv[-1] / hsv[0] > min_hsv_ratio:
            return StateSpace(A, B, C, D, dt)
    raise SubidError("random_system found no minimal system within 1000 draws; "
                     "relax min_hsv_ratio or min_pole_distance")


def _pole_radius(pole_radius) -> tuple[float, float]:
    """``(low, high)`` of :func:`random_system`: ``0 <= low <= high < 1``."""
    message = ("pole_radius must be a pair (low, high) of pole magnitudes with "
               "0 <= low <= high < 1 (random_system draws stable systems); got "
               f"{pole_radius!r}"[:300])
    try:
        low, high = pole_radius
        low, high = _real(low, "pole_radius"), _real(high, "pole_radius")
    except (TypeError, ValueError):
        raise OptionError(message) from None
    if not 0.0 <= low <= high < 1.0:
        raise OptionError(message)
    return low, high


def simulate_data(system: StateSpace, n_samples: int, *, seed, process_snr_db=None,
                  output_snr_db=None, x0=None, input_std: float = 1.0) -> IOData:
    """Simulate a discrete-time system driven by white Gaussian input.

    Parameters
    ----------
    system : StateSpace
        Discrete-time system.
    n_samples : int
    seed : int or numpy Generator
        Seed of the input and noise draws.
    process_snr_db, output_snr_db : float, optional
        Signal-to-noise ratios in dB of white Gaussian process noise w (added
        to the state equation) and measurement noise v (added to the output),
        each channel relative to the power of the noise-free state or output
        channel (seed 001, Section IV: 25 dB). None: no noise.
    x0 : array_like, optional
        Initial state (default zero).
    input_std : float
        Standard deviation of the input.
    """
    _check_system(system)
    if system.dt <= 0:
        raise SubidError("simulate_data needs a discrete-time system; discretise it first")
    n_samples = check_int(n_samples, "n_samples")
    process_snr_db = _check_snr(process_snr_db, "process_snr_db")
    output_snr_db = _check_snr(output_snr_db, "output_snr_db")
    input_std = _real(input_std, "input_std", low=0.0, low_open=True)
    rng = np.random.default_rng(check_seed(seed))
    u = input_std * rng.standard_normal((n_samples, system.n_inputs))
    y, x = system.simulate(u, x0=x0, return_state=True)
    y_clean = y
    if process_snr_db is not None:
        w_std = x.std(axis=0) * 10 ** (-process_snr_db / 20)
        w = rng.standard_normal((n_samples, system.order)) * w_std
        augmented = StateSpace(system.A, np.hstack([system.B, np.eye(system.order)]), system.C,
                               np.hstack([system.D, np.zeros((system.n_outputs, system.order))]),
                               system.dt)
        y = augmented.simulate(np.hstack([u, w]), x0=x0)
    if output_snr_db is not None:
        v_std = y_clean.std(axis=0) * 10 ** (-output_snr_db / 20)
        y = y + rng.standard_normal(y.shape) * v_std
    return IOData(u, y, dt=system.dt)


def simulate_innovation_data(system: StateSpace, n_samples: int, *, seed, noise_cov=None,
                             feedback=None, input_std: float = 1.0, x0=None) -> IOData:
    """Simulate a system in innovation form, in open or closed loop.

    ``x[k+1] = A x + B u + K e``, ``y = C x + D u + e`` with white Gaussian
    innovations ``e`` of covariance ``noise_cov`` (default ``system.noise_cov``)
    and ``K = system.K``. In open loop ``u = r``; with ``feedback`` F
    (n_inputs x n_outputs) the loop is closed by ``u = r - F y`` (requires
    ``D = 0``); ``r`` is white Gaussian with standard deviation ``input_std``.

    Parameters
    ----------
    system : StateSpace
        Discrete-time model with ``K``.
    n_samples : int
    seed : int or numpy Generator
    noise_cov : array_like, optional
    feedback : array_like, optional
    input_std : float
    x0 : array_like, optional

    Returns
    -------
    IOData
        ``u`` is the plant input (not the reference).
    """
    _check_system(system)
    if system.dt <= 0 or system.K is None:
        raise SubidError("simulate_innovation_data needs a discrete-time system with a "
                         "Kalman gain K")
    n_samples = check_int(n_samples, "n_samples")
    input_std = _real(input_std, "input_std", low=0.0, low_open=True)
    ny, nu = system.n_outputs, system.n_inputs
    sigma = system.noise_cov if noise_cov is None else _matrix(noise_cov, "noise_cov", ny, ny)
    if sigma is None:
        raise SubidError("give noise_cov (the system has none)")
    try:
        factor = np.linalg.cholesky(sigma)
    except np.linalg.LinAlgError:
        factor = None
    if factor is None or not np.allclose(sigma, sigma.T, rtol=1e-10,
                                         atol=1e-12 * np.abs(sigma).max()):
        raise OptionError("noise_cov must be a symmetric positive definite matrix (the "
                          "covariance of the innovations); its eigenvalues are "
                          f"{np.round(np.linalg.eigvals(sigma).real, 6).tolist()}"[:300])
    if feedback is not None:
        feedback = _matrix(feedback, "feedback", nu, ny, reshape=True)
    rng = np.random.default_rng(check_seed(seed))
    r = input_std * rng.standard_normal((n_samples, nu))
    e = rng.standard_normal((n_samples, ny)) @ factor.T
    A, B, C, D, K = system.A, system.B, system.C, system.D, system.K
    if feedback is None:
        aug = StateSpace(A, np.hstack([B, K]), C, np.hstack([D, np.eye(ny)]), system.dt)
        y = aug.simulate(np.hstack([r, e]), x0=x0)
        return IOData(r, y, dt=system.dt)
    F = np.asarray(feedback, dtype=float).reshape(nu, ny)
    if np.abs(D).max() > 0:
        raise SubidError("closed-loop simulation needs D = 0 (no algebraic loop)")
    # closed loop: x+ = (A - B F C) x + B r + (K - B F) e, y = C x + e, u = r - F y
    Acl = A - B @ F @ C
    aug = StateSpace(Acl, np.hstack([B, K - B @ F]), C, np.hstack([np.zeros((ny, nu)),
                                                                   np.eye(ny)]), system.dt)
    y = aug.simulate(np.hstack([r, e]), x0=x0)
    u = r - y @ F.T
    return IOData(u, y, dt=system.dt)


def _matrix(value, name: str, rows: int, cols: int, *, reshape: bool = False) -> np.ndarray:
    """``value`` as a finite float (rows, cols) matrix (any array of rows*cols entries
    with ``reshape``); else :class:`OptionError` naming the shape expected."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise OptionError(f"{name} must be a numeric {rows} x {cols} matrix, got "
                          f"{type(value).__name__}") from None
    if reshape and arr.size == rows * cols:
        arr = arr.reshape(rows, cols)
    if arr.shape != (rows, cols) or not np.isfinite(arr).all():
        raise OptionError(f"{name} must be a finite {rows} x {cols} matrix, got shape "
                          f"{arr.shape}" + ("" if np.isfinite(arr).all() else
                                            " with non-finite entries"))
    return arr
