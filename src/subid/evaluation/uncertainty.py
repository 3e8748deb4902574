"""Parameter covariance of a model and confidence bounds of its responses.

A model refined by :func:`subid.pem` (or returned by a polynomial method, see
below) carries the asymptotic covariance of its parameters (``info['parameter_covariance']``, written by
:mod:`subid.methods.dt._covariance`; it survives :meth:`StateSpace.save` /
:meth:`~StateSpace.load`). The parametrisation is

    θ = [vec(A), vec(B), vec(C), vec(D)?, vec(K)?]      (row-major, ``?``: when
                                                          estimated)

and ``Cov(θ) = F F^T`` with a factor ``F`` of rank ``d`` whose columns span the
data-driven local coordinates of :func:`subid.pem` (McKelvey, Helmersson and
Ribarits 2004): the ``n^2`` similarity directions, which do not change the
input/output behaviour, carry no variance. :func:`parameter_covariance`
returns it as a :class:`ParameterCovariance`, whose :meth:`~ParameterCovariance.model`
maps a parameter vector back to a model and :meth:`~ParameterCovariance.sample`
draws models from the Gaussian.

Bounds (:func:`freqresp_bounds`, :func:`step_bounds`,
:func:`simulation_bounds`):

* ``method='delta'`` (default): first-order propagation (the delta method;
  Ljung 1999, Section 9.4): for a response ``r(θ)`` with sensitivity
  ``S = dr/dθ F`` the standard deviation is ``||S||`` (row norm), and the
  band is ``r ± z std`` with ``z`` the two-sided normal quantile of
  ``level``. The magnitude ``|G|`` has the sensitivity
  ``Re(conj(G) dG) / |G|``. The sensitivities of a simulated output are
  exact (the sensitivity equations of the state recursion, all directions
  in one compiled pass).
* ``method='sampling'``: ``n_samples`` parameter vectors ``θ + F ξ``,
  ``ξ ~ N(0, I)`` (seeded), and the empirical ``(1 - level)/2`` and
  ``(1 + level)/2`` quantiles of the response.

The polynomial models (:func:`subid.arx`, :func:`subid.armax`,
:func:`subid.oe`, :func:`subid.bj`) carry the covariance of their
coefficients (ARX: the least-squares covariance from the QR factor of the
regressors; ARMAX, OE, BJ: the prediction-error covariance from the
Jacobian at the optimum, Ljung 1999, Theorem 9.1; both per output with the
outputs' cross-covariances, :mod:`subid.methods.dt._poly_covariance`),
mapped to the θ of their state-space realisation by the exact derivative of
the realisation, so that every bound above applies to them unchanged; the
delta-method bounds are then those of ``G = B / (A F)`` propagated from the
coefficient covariance (chain rule). The coefficients' own covariance is
:attr:`ParameterCovariance.coefficient_covariance` (names as
``'B[0,1][2]'``: polynomial, output, input, lag). Sampled models
(``method='sampling'``) perturb θ along the factor, i.e. the realisation
linearised in the coefficients (exact unless some ``nk = 0``: then the
observer form's ``b_k - a_k b_0`` is bilinear).

Subspace models (:func:`subid.n4sid`, :func:`subid.moesp`, ...) and
continuous-time models carry no covariance: asking for bounds raises
:class:`subid.errors.ModelError` that says to refine the model with
:func:`subid.pem` first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.special

from subid._blas import serial_blas
from subid._validation import as_signal, check_int, checked_call, same_period
from subid.data import IOData
from subid.delay import apply_to_inputs, input_delay_of
from subid.errors import DataError, ModelError, OptionError
from subid.model._sensitivity import jacobian
from subid.model.prediction import check_x0
from subid.model.statespace import StateSpace

__all__ = ["ParameterCovariance", "Bounds", "parameter_covariance", "freqresp_bounds",
           "step_bounds", "simulation_bounds"]

METHODS = ("delta", "sampling")
# Relative tolerance of the check that the covariance belongs to the model's matrices.
REALISATION_RTOL = 1e-8


class ParameterCovariance:
    """Covariance of the parameters of a model (see the module docstring).

    Parameters
    ----------
    model : StateSpace
        The model the covariance belongs to.
    parameters : ndarray, shape (P,)
        θ, the stacked row-major ``A, B, C`` (and ``D``, ``K`` when estimated).
    factor : ndarray, shape (P, d)
        ``F`` with ``Cov(θ) = F F^T``.
    with_feedthrough, with_gain : bool
        Whether ``D`` and ``K`` are parameters.
    coefficients : ndarray, shape (Q,), optional
        The free polynomial coefficients of a polynomial model
        (:func:`subid.model.polynomial.coefficient_slots`).
    coefficient_factor : ndarray, shape (Q, Q), optional
        Their covariance factor.
    coefficient_names : list of str, optional
        Their names, ``'B[0,1][2]'``: polynomial, output, input, lag.

    Attributes
    ----------
    parameters, factor : ndarray
    with_feedthrough, with_gain : bool
    names : list of str
        ``'A[0,1]'``-style name of every entry of θ.
    coefficients, coefficient_factor : ndarray or None
    coefficient_names : list of str or None
        The polynomial coefficients' (None for a state-space model).
    """

    def __init__(self, model, parameters, factor, with_feedthrough, with_gain, *,
                 coefficients=None, coefficient_factor=None, coefficient_names=None):
        self._model = model
        self.parameters = np.asarray(parameters, dtype=float)
        self.factor = np.asarray(factor, dtype=float)
        self.with_feedthrough = bool(with_feedthrough)
        self.with_gain = bool(with_gain)
        n, nu, ny = model.order, model.n_inputs, model.n_outputs
        shapes = [("A", n, n), ("B", n, nu), ("C", ny, n)]
        if self.with_feedthrough:
            shapes.append(("D", ny, nu))
        if self.with_gain:
            shapes.append(("K", n, ny))
        self._shapes = shapes
        self.names = [f"{name}[{i},{j}]" for name, rows, cols in shapes
                      for i in range(rows) for j in range(cols)]
        self.coefficients = None if coefficients is None else \
            np.asarray(coefficients, dtype=float)
        self.coefficient_factor = None if coefficient_factor is None else \
            np.asarray(coefficient_factor, dtype=float)
        self.coefficient_names = None if coefficient_names is None else \
            [str(name) for name in coefficient_names]

    @property
    def coefficient_covariance(self) -> np.ndarray | None:
        """Covariance of the polynomial coefficients (None for a state-space model)."""
        f = self.coefficient_factor
        return None if f is None else f @ f.T

    @property
    def coefficient_std(self) -> np.ndarray | None:
        """Standard deviation of every polynomial coefficient (None for a state-space
        model)."""
        f = self.coefficient_factor
        return None if f is None else np.sqrt(np.einsum("ij,ij->i", f, f))

    @property
    def covariance(self) -> np.ndarray:
        """``Cov(θ) = F F^T``, shape (P, P) (singular along the similarity directions)."""
        return self.factor @ self.factor.T

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of every entry of θ (in the model's state basis)."""
        return np.sqrt(np.einsum("ij,ij->i", self.factor, self.factor))

    def matrices(self, theta):
        """``(A, B, C, D, K)`` of a parameter vector (``D`` and ``K`` those of the
        model when they are not parameters; ``K`` may be None)."""
        theta = np.asarray(theta, dtype=float)
        out, pos = {}, 0
        for name, rows, cols in self._shapes:
            out[name] = theta[pos:pos + rows * cols].reshape(rows, cols)
            pos += rows * cols
        D = out.get("D", np.array(self._model.D))
        return out["A"], out["B"], out["C"], D, out.get("K", self._model.K)

    def model(self, theta) -> StateSpace:
        """The model with parameters ``theta`` (same dt, names, hold and ``info``
        without the covariance and, for a polynomial model, without the
        polynomials, which ``theta`` no longer matches).

        Parameters
        ----------
        theta : array_like, shape (P,)

        Returns
        -------
        StateSpace
        """
        theta = np.asarray(theta, dtype=float)
        if theta.shape != self.parameters.shape:
            raise DataError(f"theta has shape {theta.shape}; this model has "
                            f"{self.parameters.size} parameters")
        A, B, C, D, K = self.matrices(theta)
        m = self._model
        info = {k: v for k, v in m.info.items()
                if k not in ("parameter_covariance", "polynomials")}
        return StateSpace(A, B, C, D, m.dt, input_names=m.input_names,
                          output_names=m.output_names, info=info, K=K,
                          noise_cov=None if K is None else m.noise_cov, hold=m.hold)

    def sample(self, n_samples, *, seed):
        """Models drawn from the Gaussian ``N(θ, F F^T)``.

        Parameters
        ----------
        n_samples : int
        seed : int or numpy.random.Generator

        Returns
        -------
        list of StateSpace
        """
        n_samples = check_int(n_samples, "n_samples", minimum=1)
        rng = np.random.default_rng(seed)
        xi = rng.standard_normal((self.factor.shape[1], n_samples))
        thetas = self.parameters[:, None] + self.factor @ xi
        return [self.model(thetas[:, k]) for k in range(n_samples)]


@dataclass(frozen=True)
class Bounds:
    """A response with its confidence band.

    Attributes
    ----------
    x : ndarray
        Frequencies (rad per time unit) or time stamps.
    value : ndarray
        The model's response: ``|G|`` (n_freq, ny, nu) for
        :func:`freqresp_bounds`, the step response (N, ny, nu) or the
        simulated output (N, ny).
    lower, upper : ndarray
        The band, same shape as ``value``.
    std : ndarray or None
        Standard deviation of ``value`` (delta method; None when sampled).
    level : float
        Confidence level of the band.
    method : str
        ``'delta'`` or ``'sampling'``.
    response : ndarray or None
        The complex frequency response (:func:`freqresp_bounds` only).
    """

    x: np.ndarray
    value: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    std: np.ndarray | None
    level: float
    method: str
    response: np.ndarray | None = None


def _continuous_origin(model) -> bool:
    """Whether ``model`` is, or was sampled from, a continuous-time estimate (for which
    no parameter covariance is computed)."""
    record = model.info.get("identify")
    return model.is_continuous or model.info.get("method") == "ct_subspace" or (
        isinstance(record, dict) and record.get("time_base") == "continuous")


def _continuous_message(model) -> str:
    """The :class:`ModelError` message for a continuous-time model without covariance:
    how it came to be continuous-time, and the discrete-time path that gives bounds."""
    info = model.info
    record = info.get("identify")
    if isinstance(record, dict) and record.get("time_base") == "continuous":
        how = (f"subid.identify took its continuous-time path (ct_subspace: "
               f"{record.get('reason', 'continuous time requested')})")
    else:
        how = f"it was estimated in continuous time ({info.get('method', 'unknown method')}"
        how += f", refined by {info['refined_by']})" if info.get("refined_by") else ")"
    sampled = "" if model.is_continuous else ", then sampled"
    return (f"the model has no parameter covariance: {how}{sampled}, and subid computes "
            "parameter covariances only for discrete-time estimates (subid.identify on "
            "uniformly sampled data, subid.pem, the polynomial methods). For bounds, "
            "identify a discrete-time model from uniformly sampled data: subid.identify(data) "
            "or subid.pem(data, model.to_discrete(dt)) attach the covariance; non-uniformly "
            "sampled data must first be interpolated onto a uniform grid (e.g. numpy.interp "
            "per channel), as pem and the discrete-time methods need one")


def _identify_reason(model) -> str | None:
    """Why :func:`subid.identify` attached no covariance to ``model``
    (``info['identify']['covariance']['reason']``), or None when it did not record one."""
    record = model.info.get("identify")
    entry = record.get("covariance") if isinstance(record, dict) else None
    if isinstance(entry, dict) and entry.get("computed") is False and entry.get("reason"):
        return str(entry["reason"])
    return None


@serial_blas
@checked_call
def parameter_covariance(model) -> ParameterCovariance:
    """The parameter covariance a model carries (MATLAB ``getcov``).

    Parameters
    ----------
    model : StateSpace
        A model returned by :func:`subid.identify` (discrete time; for a model it did
        not refine, the covariance a prediction-error estimate would have at it), by
        :func:`subid.pem` or by a polynomial method (:func:`subid.arx`,
        :func:`subid.armax`, :func:`subid.oe`, :func:`subid.bj`), or loaded from its
        file.

    Returns
    -------
    ParameterCovariance

    Raises
    ------
    ModelError
        The model has no covariance (a subspace model: refine it with
        :func:`subid.pem`; a continuous-time model, e.g. :func:`subid.identify`
        on non-uniform data: the message names the discrete-time path), or its
        matrices are not those the covariance was computed for (edited after
        ``pem``; :meth:`StateSpace.transform` and :func:`subid.absorb_delay` map the
        covariance, conversions drop it).
    """
    if not isinstance(model, StateSpace):
        raise ModelError(f"expected a subid.StateSpace, got {type(model).__name__}")
    entry = model.info.get("parameter_covariance")
    if not isinstance(entry, dict):
        note = model.info.get("parameter_covariance_note")
        if not note and _continuous_origin(model):
            raise ModelError(_continuous_message(model))
        reason = _identify_reason(model)
        if reason is not None:
            advice = "" if "subid.pem" in reason else (
                "; refine it with subid.pem(data, model), which attaches the covariance, "
                "and ask for bounds on that model")
            raise ModelError(f"the model has no parameter covariance: subid.identify attached "
                             f"none because {reason}{advice}")
        method = model.info.get("method", "this method")
        why = note if note else (
            f"models estimated by {method} carry no parameter covariance"
            if "refined_by" not in model.info else
            "the model was converted or edited after pem and its covariance was dropped")
        if isinstance(model.info.get("polynomials"), dict) and note:
            raise ModelError(f"the model has no parameter covariance ({why}); identify it "
                             "again with lower orders or on data that excite it more")
        raise ModelError(f"the model has no parameter covariance ({why}); identify it with "
                         "subid.identify(data), or refine it with subid.pem(data, model) on "
                         "its discrete-time form: both attach the asymptotic covariance; "
                         "ask for bounds on that model")
    if model.is_continuous:
        raise ModelError("a continuous-time model carries no parameter covariance; ask for "
                         "bounds on the discrete-time model subid.identify or subid.pem "
                         "returns")
    try:
        cov = ParameterCovariance(model, entry["parameters"], entry["factor"],
                                  entry["with_feedthrough"], entry["with_gain"],
                                  coefficients=entry.get("coefficients"),
                                  coefficient_factor=entry.get("coefficient_factor"),
                                  coefficient_names=entry.get("coefficient_names"))
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"info['parameter_covariance'] is malformed ({exc!r}); it must hold "
                         "'parameters', 'factor', 'with_feedthrough' and 'with_gain'") from None
    expected = len(cov.names)
    if cov.parameters.shape != (expected,) or cov.factor.ndim != 2 \
            or cov.factor.shape[0] != expected:
        raise ModelError(f"info['parameter_covariance'] has {cov.parameters.size} parameters "
                         f"(factor {cov.factor.shape}) but the model has {expected} (order "
                         f"{model.order}): the covariance belongs to the model before its "
                         "order changed (subid.absorb_delay adds a state per delay sample; a "
                         "reduction or conversion changes the matrices) and does not carry "
                         "over. Ask for bounds on the model pem returned, or refit this one "
                         "with subid.pem(data, model), which attaches its own covariance")
    own = [np.asarray(model.A), np.asarray(model.B), np.asarray(model.C)]
    if cov.with_feedthrough:
        own.append(np.asarray(model.D))
    if cov.with_gain:
        if model.K is None:
            raise ModelError("the covariance was computed for the model with its Kalman gain "
                             "K, which this model no longer has (with_noise_model(None, None) "
                             "removes it; to_continuous and to_discrete drop it), so it does "
                             "not apply: ask for bounds on the model pem returned, or refit "
                             "this one with subid.pem(data, model, focus='simulation'), which "
                             "attaches the covariance of a model without K")
        own.append(np.asarray(model.K))
    own = np.concatenate([m.ravel() for m in own])
    if not np.allclose(own, cov.parameters, rtol=REALISATION_RTOL,
                       atol=REALISATION_RTOL * max(np.abs(own).max(), 1e-300)):
        raise ModelError("info['parameter_covariance'] belongs to other matrices than the "
                         "model's (its matrices were converted or edited after pem); ask for bounds on "
                         "the model pem returned, or refine this one with "
                         "subid.pem(data, model)")
    return cov


def _z(level) -> float:
    if isinstance(level, bool) or not isinstance(level, (int, float)) \
            or not 0 < level < 1:
        raise OptionError(f"level must be a probability in (0, 1), e.g. 0.95, got {level!r}")
    return float(scipy.special.ndtri(0.5 + level / 2))


def _check_method(method, n_samples):
    if method not in METHODS:
        raise OptionError(f"method must be 'delta' or 'sampling', got {method!r}")
    return check_int(n_samples, "n_samples", minimum=10)


def _quantile_band(values, level):
    """Empirical band of sampled responses (axis 0: samples)."""
    lo, hi = np.quantile(values, [0.5 - level / 2, 0.5 + level / 2], axis=0)
    return lo, hi


def _sampled(cov, n_samples, seed, response):
    rng = np.random.default_rng(seed)
    xi = rng.standard_normal((cov.factor.shape[1], n_samples))
    thetas = cov.parameters[:, None] + cov.factor @ xi
    return np.stack([response(cov.model(thetas[:, k])) for k in range(n_samples)])


def _directions(cov):
    """``(dA, dB, dC, dD)`` of every column of the factor, each (d, rows, cols)."""
    parts = [cov.matrices(cov.factor[:, j]) for j in range(cov.factor.shape[1])]
    dA = np.array([p[0] for p in parts])
    dB = np.array([p[1] for p in parts])
    dC = np.array([p[2] for p in parts])
    dD = np.array([p[3] for p in parts]) if cov.with_feedthrough else \
        np.zeros((len(parts),) + np.shape(cov.matrices(cov.parameters)[3]))
    return dA, dB, dC, dD


@serial_blas
@checked_call
def freqresp_bounds(model, w, level=0.95, *, method="delta", n_samples=1000, seed=0):
    """Confidence bounds of the magnitude of the frequency response (MATLAB
    ``showConfidence`` on a Bode plot).

    Parameters
    ----------
    model : StateSpace
        A model with a parameter covariance (:func:`subid.pem`, the polynomial
        methods).
    w : array_like, shape (K,)
        Frequencies in rad per time unit.
    level : float
        Confidence level, e.g. 0.95.
    method : {'delta', 'sampling'}
        First-order propagation, or quantiles over sampled parameter vectors.
    n_samples : int
        Number of draws (``method='sampling'``).
    seed : int
        Seed of the draws (``method='sampling'``).

    Returns
    -------
    Bounds
        ``value`` = ``|G|`` (K, ny, nu), ``lower``/``upper`` (the lower one
        clipped at 0), ``std`` of ``|G|`` (delta method), ``response`` = G.

    Raises
    ------
    ModelError
        The model has no parameter covariance (refine it with :func:`subid.pem`).
    OptionError
        Bad ``level``, ``method`` or ``n_samples``.

    Examples
    --------
    >>> import numpy as np, subid
    >>> true = subid.systems.seed001_innovation_system()
    >>> data = subid.systems.simulate_innovation_data(true, 1000, seed=1)
    >>> model = subid.pem(data, subid.n4sid(data, 3))
    >>> band = subid.freqresp_bounds(model, np.linspace(0.1, 3.0, 5))
    >>> bool(np.all(band.lower <= band.value) and np.all(band.value <= band.upper))
    True
    """
    cov = parameter_covariance(model)
    z = _z(level)
    n_samples = _check_method(method, n_samples)
    G = model.freqresp(w)
    w = np.atleast_1d(np.asarray(w, dtype=float))
    mag = np.abs(G)
    if method == "sampling":
        lo, hi = _quantile_band(_sampled(cov, n_samples, seed,
                                         lambda m: np.abs(m.freqresp(w))), level)
        return Bounds(w, mag, lo, hi, None, float(level), method, G)
    dA, dB, dC, dD = _directions(cov)
    A, B, C = np.asarray(model.A), np.asarray(model.B), np.asarray(model.C)
    n = A.shape[0]
    s = np.exp(1j * w * model.dt)
    M = s[:, None, None] * np.eye(n) - A
    X = np.linalg.solve(M, np.broadcast_to(B.astype(complex), (w.size, n, B.shape[1])))
    Y = np.linalg.solve(M.transpose(0, 2, 1),
                        np.broadcast_to(C.T.astype(complex), (w.size, n, C.shape[0])))
    Y = Y.transpose(0, 2, 1)                               # C (sI - A)^-1
    G0 = C @ X + np.asarray(model.D)                       # without input delays
    std = _magnitude_std(G0, X, Y, dA, dB, dC, dD)
    return Bounds(w, mag, np.maximum(mag - z * std, 0.0), mag + z * std, std, float(level),
                  method, G)


#: Largest number of complex entries of an intermediate array of :func:`_magnitude_std`
#: (the frequencies are taken in blocks below it).
_BLOCK_ENTRIES = 2 ** 21


def _magnitude_std(G0, X, Y, dA, dB, dC, dD):
    """The delta-method standard deviation of ``|G(s_k)|`` (K, ny, nu).

    ``dG[k, j] = dC_j X_k + Y_k dA_j X_k + Y_k dB_j + dD_j`` is the derivative of
    ``G(s_k) = C (s_k I - A)^-1 B + D`` along direction ``j``, with
    ``X_k = (s_k I - A)^-1 B`` (K, n, nu) and ``Y_k = C (s_k I - A)^-1`` (K, ny, n);
    ``|G|`` moves by ``Re(conj(G) dG) / |G|`` and ``std = sqrt(sum_j (...)^2)``.
    The sums run as matrix products over all directions at once (the real directions
    times the real and imaginary parts), the frequencies in blocks that keep every
    intermediate under :data:`_BLOCK_ENTRIES` entries: the sums of one ``einsum`` per
    term, at BLAS speed (an ``einsum`` over the shared frequency index loops in C
    without BLAS: 85 % of a report's Bode figure for an ARX model of order 36).
    Only the rows and columns of ``A`` (and the columns of ``C``) that some direction
    moves enter the products: a polynomial model's realisation has its coefficients
    in a few of them (6 of 36 rows and columns for the ARX model above, whose ``C``
    none moves), the other entries of ``dA_j X_k`` being sums of exact zeros.
    """
    d = dA.shape[0]
    K, ny, nu = X.shape[0], Y.shape[1], X.shape[2]
    rows = np.flatnonzero(np.any(dA != 0, axis=(0, 2)))
    cols = np.flatnonzero(np.any(dA != 0, axis=(0, 1)))
    c_cols = np.flatnonzero(np.any(dC != 0, axis=(0, 1)))
    r, c = rows.size, cols.size
    flat_A = dA[:, rows][:, :, cols].reshape(d * r, c)
    flat_C = dC[:, :, c_cols].reshape(d * ny, c_cols.size)
    flat_B = dB.transpose(1, 0, 2).reshape(dB.shape[1], d * nu)
    std = np.empty((K, ny, nu))
    step = max(1, _BLOCK_ENTRIES // max(1, d * max(r, ny) * nu))

    def times(real, Z):                    # real (r, n) @ complex (n, c)
        return real @ Z.real + 1j * (real @ Z.imag)

    def columns(Z, index):                 # rows ``index`` of every Z_k, as (len, k nu)
        return Z[:, index].transpose(1, 0, 2).reshape(index.size, -1)

    for lo in range(0, K, step):
        hi = min(K, lo + step)
        k = hi - lo
        YB = Y[lo:hi].reshape(k * ny, -1)
        dG = (YB.real @ flat_B + 1j * (YB.imag @ flat_B)).reshape(
            k, ny, d, nu).transpose(0, 2, 1, 3)                               # Y_k dB_j
        if r and c:
            AX = times(flat_A, columns(X[lo:hi], cols)).reshape(d, r, k, nu).transpose(
                2, 0, 1, 3)                                                   # dA_j X_k
            dG += Y[lo:hi, None][..., rows] @ AX
        if c_cols.size:
            dG += times(flat_C, columns(X[lo:hi], c_cols)).reshape(
                d, ny, k, nu).transpose(2, 0, 1, 3)                           # dC_j X_k
        dG += dD[None]
        G = G0[lo:hi]
        with np.errstate(divide="ignore", invalid="ignore"):
            dmag = np.real(np.conj(G)[:, None] * dG) / np.maximum(np.abs(G), 1e-300)[:, None]
        std[lo:hi] = np.sqrt(np.sum(dmag ** 2, axis=1))
    return std


def _forced(model, u, x0):
    """Output, state and (delayed) input of a discrete-time simulation."""
    y, x = model.simulate(u, x0=x0, return_state=True)
    delays = input_delay_of(model)
    return y, x, (apply_to_inputs(u, delays) if delays is not None else u)


def _output_sensitivities(model, cov, u, x0):
    """``(y, dy)``: simulated output (N, ny) and its sensitivities to the columns of
    the factor, (N, ny, d): ``s_j[t+1] = A s_j[t] + dA_j x[t] + dB_j u[t]``,
    ``s_j[0] = 0``, ``dy_j = C s_j + dC_j x + dD_j u``, every direction in one
    compiled pass (:func:`subid.model._sensitivity.jacobian`)."""
    y, _, ud = _forced(model, u, x0)
    dA, dB, dC, dD = _directions(cov)
    n = model.order
    start = np.zeros(n) if x0 is None else x0
    arrays = (model.A, model.B, model.C, model.D, ud, start, dA, dB, dC, dD,
              np.zeros((dA.shape[0], n)))
    _, dy = jacobian(*(np.ascontiguousarray(a, dtype=float) for a in arrays))
    return y, dy


@serial_blas
@checked_call
def simulation_bounds(model, u, level=0.95, *, x0=None, method="delta", n_samples=1000,
                      seed=0):
    """Confidence bounds of the simulated output (MATLAB ``sim`` with ``SD``).

    Parameters
    ----------
    model : StateSpace
        A discrete-time model with a parameter covariance (:func:`subid.pem`, the
        polynomial methods).
    u : array_like, shape (N, n_inputs), or IOData
        Input samples (an IOData record: its inputs; a record of several
        experiments, :func:`subid.merge`, is simulated experiment by experiment,
        each from its own initial state).
    level : float
        Confidence level, e.g. 0.95.
    x0 : None, 'zero', 0 or array_like of shape (n,), optional
        Initial state (default zeros; treated as known); for a record of several
        experiments one row per experiment, shape ``(n_experiments, n)``. There are
        no outputs to estimate it from: ``'estimate'`` raises a
        :class:`~subid.errors.DataError`.
    method : {'delta', 'sampling'}
        First-order propagation, or quantiles over sampled parameter vectors.
    n_samples : int
        Number of draws (``method='sampling'``).
    seed : int
        Seed of the draws (``method='sampling'``).

    Returns
    -------
    Bounds
        ``x`` = time stamps ``k dt`` (each experiment's from 0), ``value`` the
        simulated output (N, ny).

    Raises
    ------
    ModelError
        The model has no parameter covariance.
    DataError
        Bad input samples.
    OptionError
        Bad ``level``, ``method`` or ``n_samples``.
    """
    cov = parameter_covariance(model)
    z = _z(level)
    n_samples = _check_method(method, n_samples)
    if isinstance(u, IOData):
        if not same_period(u.dt or 0.0, model.dt):
            raise DataError(f"the record is sampled with dt={u.dt!r} but the model's period "
                            f"is dt={model.dt!r}")
        if u.n_experiments > 1:
            k = u.n_experiments
            rows = check_x0(x0, model.order, k, estimate=False)
            rows = [None] * k if isinstance(rows, str) else list(rows)
            parts = [simulation_bounds(model, e, level, x0=r, method=method,
                                       n_samples=n_samples, seed=seed)
                     for e, r in zip(u.experiments, rows)]
            std = None if parts[0].std is None else np.vstack([p.std for p in parts])
            return Bounds(*(np.concatenate([getattr(p, f) for p in parts])
                            for f in ("x", "value", "lower", "upper")),
                          std, float(level), method)
        u = u.u
    u = as_signal(u, "input u", allow_empty_columns=model.n_inputs == 0)
    if u.shape[1] != model.n_inputs:
        raise DataError(f"input u has {u.shape[1]} channels but the model has "
                        f"{model.n_inputs} inputs")
    x0 = check_x0(x0, model.order, estimate=False)
    x0 = np.zeros(model.order) if isinstance(x0, str) else x0
    t = np.arange(u.shape[0]) * model.dt
    return _band(model, cov, u, x0, z, level, method, n_samples, seed, t)


def _band(model, cov, u, x0, z, level, method, n_samples, seed, t):
    if method == "sampling":
        y = model.simulate(u, x0=x0)
        lo, hi = _quantile_band(_sampled(cov, n_samples, seed,
                                         lambda m: m.simulate(u, x0=x0)), level)
        return Bounds(t, y, lo, hi, None, float(level), method)
    y, dy = _output_sensitivities(model, cov, u, x0)
    std = np.sqrt(np.sum(dy ** 2, axis=-1))
    return Bounds(t, y, y - z * std, y + z * std, std, float(level), method)


@serial_blas
@checked_call
def step_bounds(model, t=None, level=0.95, *, method="delta", n_samples=1000, seed=0):
    """Confidence bounds of the step response (MATLAB ``step`` with
    ``showConfidence``).

    Parameters
    ----------
    model : StateSpace
        A discrete-time model with a parameter covariance (:func:`subid.pem`, the
        polynomial methods).
    t : float or array_like, optional
        Final time or time stamps (:meth:`StateSpace.step`).
    level : float
        Confidence level, e.g. 0.95.
    method : {'delta', 'sampling'}
        First-order propagation, or quantiles over sampled parameter vectors.
    n_samples : int
        Number of draws (``method='sampling'``).
    seed : int
        Seed of the draws (``method='sampling'``).

    Returns
    -------
    Bounds
        ``x`` = time stamps, ``value`` the step response (N, ny, nu).

    Raises
    ------
    ModelError
        The model has no parameter covariance.
    OptionError
        Bad ``level``, ``method`` or ``n_samples``.
    """
    cov = parameter_covariance(model)
    z = _z(level)
    n_samples = _check_method(method, n_samples)
    t, _ = model.step(t)
    nu = model.n_inputs
    parts = []
    for j in range(nu):
        u = np.zeros((t.size, nu))
        u[:, j] = 1.0
        parts.append(_band(model, cov, u, None, z, level, method, n_samples, seed, t))
    stack = [np.stack([getattr(p, f) for p in parts], axis=-1)
             for f in ("value", "lower", "upper")]
    std = None if method == "sampling" else np.stack([p.std for p in parts], axis=-1)
    return Bounds(t, stack[0], stack[1], stack[2], std, float(level), method)

