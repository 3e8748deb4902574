"""Linear state-space models: :class:`StateSpace`.

A model is ``x' = A x + B u, y = C x + D u`` in continuous time (``dt == 0``,
``x'`` the derivative) or ``x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]``
in discrete time (``dt > 0``, the sampling period). Time is axis 0 of every
signal array.

Model files
-----------
:meth:`StateSpace.save` writes JSON (never pickle) with the keys ``format``
(``"subid.StateSpace"``), ``version`` (1; 2 when the model has a noise
model; 3 when it assumes a first-order hold), ``A``, ``B``, ``C``, ``D``
(nested lists, one row per matrix row), ``dt``, ``input_names``,
``output_names``, ``info``, for a model in innovation form ``K`` (Kalman
gain) and ``noise_cov`` (innovation covariance), and ``hold`` when it is
``'foh'`` (:attr:`StateSpace.hold`; absent means ``'zoh'``). Values in ``info`` are encoded so that they come back unchanged:

* ``bool``, ``int``, ``str``, ``None`` and finite floats are plain JSON values;
  numpy scalars become the matching Python scalar;
* a non-finite float is ``{"__float__": "nan"}`` (or ``"inf"``, ``"-inf"``);
* a complex number is ``{"__complex__": [re, im]}``;
* a numpy array is ``{"__ndarray__": nested list, "dtype": "float64",
  "shape": [...]}``; inside a float array a non-finite entry is the string
  ``"nan"``, ``"inf"`` or ``"-inf"``; a complex array stores ``[re, im]``
  pairs (one extra trailing axis in the nested list);
* lists and tuples become JSON lists (tuples come back as lists); dicts must
  have string keys, and the three tag names above are reserved.

The file is strict JSON (no ``NaN`` literals), readable by any JSON parser.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping

import numpy as np
from scipy import linalg

import subid.model._conversions as _conversions
import subid.model._responses as _responses
import subid.model._simulate as _simulate
import subid.model.codec as _codec
import subid.model.storage as _files
from subid._validation import (
    as_signal,
    check_dt,
    check_int,
    check_time_stamps,
    checked_call,
    same_period,
    stamp_resolution,
)
from subid.data import IOData
from subid.delay import effective_input, frequency_factor, input_delay_of
from subid.errors import DataError, ModelError, OptionError
from subid.model._checks import (
    HOLDS,
    _as_matrix,
    _check_nonsingular,
    _initial_state,
    _is_scalar_zero,
    _model_dt,
    _names,
    _noise_matrices,
    _plural,
    check_x0,
)

__all__ = ["StateSpace"]

# Bound on the number of complex entries handled at once by freqresp.
_FREQ_CHUNK_ENTRIES = 4_000_000

# Files are the concern of subid.io, which sits above this package: the file methods of
# StateSpace (save, load, to_mat, from_mat) call the readers and writers that
# subid.io.models registers in subid.model.storage (issue 24: model imports no io).

# ---------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------
class StateSpace:
    """A linear time-invariant state-space model.

    Continuous time (``dt == 0``)::

        x'(t) = A x(t) + B u(t),    y(t) = C x(t) + D u(t)

    Discrete time (``dt > 0``, the sampling period)::

        x[k+1] = A x[k] + B u[k],   y[k] = C x[k] + D u[k]

    Parameters
    ----------
    A : array_like, shape (n, n)
        State matrix, ``n >= 1``.
    B : array_like, shape (n, n_inputs)
        Input matrix. Always 2-D: a single-input ``B`` is a column.
        ``n_inputs`` may be 0 (a model without inputs).
    C : array_like, shape (n_outputs, n)
        Output matrix, ``n_outputs >= 1``.
    D : array_like, shape (n_outputs, n_inputs), or 0 or None
        Feedthrough matrix; the scalar 0 (or None) means zeros.
    dt : float
        Sampling period; 0 for a continuous-time model.
    input_names, output_names : sequence of str, optional
        Channel names (default ``u1, u2, ...`` and ``y1, y2, ...``).
    info : dict, optional
        Diagnostics set by the identification methods (singular values,
        fit, horizon, ...). Kept as given; stored in model files (see the
        module docstring for the values that can be stored).
    K : array_like, shape (n, n_outputs), optional
        Kalman gain of the innovation form ``x[k+1] = A x + B u + K e``,
        ``y = C x + D u + e`` (discrete time; :func:`subid.predict` uses it).
    noise_cov : array_like, shape (n_outputs, n_outputs), optional
        Covariance of the innovations ``e`` (MATLAB's ``NoiseVariance``).
    hold : {'zoh', 'foh'}
        The input between samples that the model assumes: constant
        (zero-order hold, default) or linear (first-order hold).
        :meth:`simulate`, :func:`subid.fit_percent`, :func:`subid.predict`,
        the residuals and the reports use it unless told otherwise; it is
        set by the method that identified the model (``ct_subspace``
        assumes ``'foh'``), kept by copies, :meth:`transform`, model files
        and ``.mat`` files, the default method of :meth:`to_continuous` /
        :meth:`to_discrete`, which set it to the hold of the conversion.

    Attributes
    ----------
    A, B, C, D : ndarray
        Read-only float64 copies of the matrices.
    dt : float
        Sampling period (0 = continuous time).
    input_names, output_names : tuple of str
    info : dict
    hold : str

    Raises
    ------
    ModelError
        Shapes disagree (the message names the matrix), values are not
        finite or not numbers, ``dt`` is negative, names do not match.

    Examples
    --------
    >>> import numpy as np
    >>> from subid.model.statespace import StateSpace
    >>> sys = StateSpace([[0.9, 0.1], [0.0, 0.5]], [[0.0], [1.0]], [[1.0, 0.0]], 0, dt=0.1)
    >>> sys
    StateSpace(order=2, n_inputs=1, n_outputs=1, dt=0.1, inputs=['u1'], outputs=['y1'])
    >>> y = sys.simulate(np.ones(50))
    >>> y.shape
    (50, 1)
    >>> sys.is_stable()
    True
    >>> sys.markov(4)[:, 0, 0].round(3).tolist()
    [0.0, 0.0, 0.1, 0.14]
    """

    @checked_call
    def __init__(self, A, B, C, D, dt, *, input_names=None, output_names=None, info=None,
                 K=None, noise_cov=None, hold="zoh"):
        A = _as_matrix(A, "A")
        B = _as_matrix(B, "B")
        C = _as_matrix(C, "C")
        if A.shape[0] != A.shape[1]:
            raise ModelError(f"A has shape {A.shape[0]}x{A.shape[1]}; it must be square "
                             "(n x n, n = model order)")
        n = A.shape[0]
        if n == 0:
            raise ModelError("A is 0x0: the model order must be at least 1")
        if B.shape[0] != n:
            raise ModelError(f"B has {_plural(B.shape[0], 'row')} but A is {n}x{n}: "
                             f"B must be {n} x n_inputs")
        if C.shape[1] != n:
            raise ModelError(f"C has {_plural(C.shape[1], 'column')} but A is {n}x{n}: "
                             f"C must be n_outputs x {n}")
        if C.shape[0] == 0:
            raise ModelError("C has no rows: a model needs at least one output")
        p, m = C.shape[0], B.shape[1]
        if D is None or _is_scalar_zero(D):
            D = np.zeros((p, m))
            D.setflags(write=False)
        else:
            if isinstance(D, (numbers.Number, np.generic)) or \
                    (isinstance(D, np.ndarray) and D.ndim == 0):
                raise ModelError(f"D is the scalar {D!r}; only the scalar 0 is accepted as "
                                 "shorthand for zeros, pass a 2-D array "
                                 f"({p} x {m}) otherwise")
            D = _as_matrix(D, "D")
            if D.shape != (p, m):
                raise ModelError(f"D has shape {D.shape[0]}x{D.shape[1]} but C has "
                                 f"{_plural(p, 'row')} and B has {_plural(m, 'column')}: "
                                 f"D must be {p} x {m} (n_outputs x n_inputs)")
        self._A, self._B, self._C, self._D = A, B, C, D
        self._dt = _model_dt(dt)
        self.input_names = _names(input_names, m, "u", "input")
        self.output_names = _names(output_names, p, "y", "output")
        if info is None:
            info = {}
        elif not isinstance(info, Mapping):
            raise ModelError(f"info must be a dict, got {type(info).__name__}")
        self.info = dict(info)
        if self._dt == 0 and input_delay_of(self) is not None:
            raise ModelError(f"info['input_delay'] = {self.info['input_delay']!r} gives input "
                             "delays in samples, which only a discrete-time model has "
                             "(dt > 0); remove the entry from info for a continuous-time "
                             "model, or sample the model (to_discrete) and set it there")
        self._K, self._noise_cov = _noise_matrices(K, noise_cov, n, p)
        if not isinstance(hold, str) or hold not in HOLDS:
            raise ModelError(f"hold must be one of {', '.join(map(repr, HOLDS))}; got "
                             f"{hold!r}"[:300])
        self._hold = hold

    # -- properties ------------------------------------------------------
    @property
    def K(self):
        """Kalman gain of the innovation form, shape (n, n_outputs), read-only; None
        when the model has no noise model."""
        return self._K

    @property
    def noise_cov(self):
        """Covariance of the innovations ``e`` (n_outputs x n_outputs), read-only;
        None when unknown."""
        return self._noise_cov

    @property
    def hold(self) -> str:
        """The input between samples the model assumes: ``'zoh'`` or ``'foh'``
        (the default of :meth:`simulate` and of the fit and prediction functions)."""
        return self._hold

    @property
    def has_noise_model(self) -> bool:
        """True when the model carries a Kalman gain ``K``."""
        return self._K is not None

    def with_noise_model(self, K=None, noise_cov=None, *, info=None) -> "StateSpace":
        """The same model with another (or no) Kalman gain and innovation covariance.

        Parameters
        ----------
        K : array_like, shape (n, n_outputs), optional
        noise_cov : array_like, shape (n_outputs, n_outputs), optional
        info : dict, optional
            Replaces ``info`` (default: a copy of this model's, without a parameter
            covariance that includes the Kalman gain replaced here, named in
            ``info['dropped']``).

        Returns
        -------
        StateSpace
        """
        out = StateSpace(self._A, self._B, self._C, self._D, self._dt,
                         input_names=self.input_names, output_names=self.output_names,
                         info=info, K=K, noise_cov=noise_cov, hold=self._hold)
        if info is None:
            out.info = _conversions.gain_info(self.info, self._K, out._K)
        return out
    @property
    def A(self) -> np.ndarray:
        """State matrix, shape (n, n), read-only."""
        return self._A

    @property
    def B(self) -> np.ndarray:
        """Input matrix, shape (n, n_inputs), read-only."""
        return self._B

    @property
    def C(self) -> np.ndarray:
        """Output matrix, shape (n_outputs, n), read-only."""
        return self._C

    @property
    def D(self) -> np.ndarray:
        """Feedthrough matrix, shape (n_outputs, n_inputs), read-only."""
        return self._D

    @property
    def dt(self) -> float:
        """Sampling period; 0 for continuous time."""
        return self._dt

    @property
    def order(self) -> int:
        """Number of states ``n``."""
        return self._A.shape[0]

    @property
    def n_inputs(self) -> int:
        """Number of inputs."""
        return self._B.shape[1]

    @property
    def n_outputs(self) -> int:
        """Number of outputs."""
        return self._C.shape[0]

    @property
    def is_continuous(self) -> bool:
        """True for a continuous-time model (``dt == 0``)."""
        return self._dt == 0.0

    def __repr__(self) -> str:
        timing = "dt=0 (continuous)" if self.is_continuous else f"dt={self._dt!r}"
        return (f"StateSpace(order={self.order}, n_inputs={self.n_inputs}, "
                f"n_outputs={self.n_outputs}, {timing}, inputs={list(self.input_names)}, "
                f"outputs={list(self.output_names)})")

    def _repr_html_(self) -> str:
        """Summary for Jupyter: order, channels, dt, stability, poles (see :mod:`subid._repr`)."""
        from subid._repr import statespace_html
        return statespace_html(self)

    def _like(self, A, B, C, D, dt, K=None, noise_cov=None, hold=None,
              info=None) -> "StateSpace":
        info = dict(self.info if info is None else info)
        if dt != self._dt and (delays := input_delay_of(self)) is not None:
            import warnings

            from subid.errors import DelayWarning
            info = _conversions.drop_info(info, {"input_delay": (
                f"to_continuous(): the delays {delays.tolist()} samples of dt={self._dt!r} "
                "have no continuous-time state-space form")})
            warnings.warn(f"to_continuous drops the input delays {delays.tolist()} (samples "
                          f"of dt={self._dt!r}; info['dropped'] names them): dead time has no "
                          "finite-dimensional continuous-time state-space form, and its "
                          "states (subid.absorb_delay) have poles at z = 0, which no matrix "
                          "logarithm maps. Keep the discrete-time model to keep the delay, or "
                          "approximate it by rational states with "
                          "subid.absorb_delay(model).to_continuous('bilinear')",
                          DelayWarning, stacklevel=3)
        hold = self._hold if hold is None else hold
        if "hold" in info:
            info["hold"] = hold
        return StateSpace(A, B, C, D, dt, input_names=self.input_names,
                          output_names=self.output_names, info=info, K=K,
                          noise_cov=noise_cov, hold=hold)

    # -- simulation ------------------------------------------------------
    def simulate(self, u, t=None, x0=None, *, hold=None, return_state=False):
        """Response of the model to an input signal.

        Parameters
        ----------
        u : array_like, shape (N, n_inputs) or (N,), or IOData
            Input samples, time on axis 0 (1-D for a single input). With an
            :class:`~subid.data.IOData` record its inputs ``u`` and time
            stamps ``t`` are used.
        t : array_like, shape (N,), optional
            Time stamps of the samples. Required for a continuous-time model
            (strictly increasing, uniform or not). For a discrete-time model
            it may be omitted; if given it must be uniform with the model's
            period ``dt``.
        x0 : array_like, shape (n,), optional
            State at the first sample (default zeros). For a record of several
            experiments (:func:`subid.merge`), one row per experiment, shape
            ``(n_experiments, n)`` (as ``model.info['x0']`` of a model identified
            from it).
        hold : {'zoh', 'foh'}, optional
            Continuous time only: the input is constant on ``[t_k, t_{k+1})``
            (``'zoh'``) or linear between ``u[k]`` and ``u[k+1]``
            (``'foh'``). Default: the model's :attr:`hold`. The state is
            propagated by the exact discretisation of every interval (one
            matrix exponential per distinct interval length). Ignored for
            discrete-time models.
        return_state : bool
            Also return the state at every sample.

        Returns
        -------
        y : ndarray, shape (N, n_outputs)
            Output at every sample. A record of several experiments is simulated
            experiment by experiment, each from its own initial state (no state
            carried across a border), the outputs in the record's order.
        x : ndarray, shape (N, n)
            State at every sample (only with ``return_state=True``).

        Raises
        ------
        DataError
            ``u`` is not finite or has the wrong number of channels, ``x0``
            has the wrong shape, ``t`` is missing (continuous time), not
            increasing, or not uniform with period ``dt`` (discrete time).
        """
        if hold is None:
            hold = self._hold
        elif not isinstance(hold, str) or hold not in HOLDS:
            raise OptionError(f"hold must be 'zoh' or 'foh', got {hold!r}"[:300])
        if isinstance(u, IOData):
            if t is not None:
                raise DataError("pass either an IOData record or time stamps t, not both: "
                                "the record carries its own time stamps")
            if u.n_experiments > 1:
                # zeros, or one row per experiment (the evaluation functions' validator)
                rows = check_x0(x0, self.order, u.n_experiments, estimate=False)
                rows = [None] * u.n_experiments if isinstance(rows, str) else list(rows)
                parts = [self.simulate(e, x0=x, hold=hold, return_state=True)
                         for e, x in zip(u.experiments, rows)]
                y, x = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
                return (y, x) if return_state else y
            data = u
            u = data.u
            if self.is_continuous:
                t = data.t
            elif data.dt is None:
                raise DataError("the IOData record has non-uniform time stamps but the model "
                                f"is discrete-time with period dt={self._dt!r}")
            elif not same_period(data.dt, self._dt):
                raise DataError(f"the IOData record is sampled with dt={data.dt!r} but the "
                                f"model's sampling period is dt={self._dt!r}; pass data.u "
                                "to simulate sample by sample")
        # read only (the simulation keeps nothing of it): no copy of a float64 C array
        u = as_signal(u, "input u", allow_empty_columns=self.n_inputs == 0, copy=False)
        N, m = u.shape
        if m != self.n_inputs:
            hint = ""
            if N == self.n_inputs and m != N:
                hint = " (time is axis 0: was u passed transposed?)"
            raise DataError(f"input u has {_plural(m, 'channel')} but the model has "
                            f"{_plural(self.n_inputs, 'input')}{hint}")
        if N == 0:
            raise DataError("input u has no samples")
        x0 = _initial_state(x0, self.order)
        if self.is_continuous:
            if t is None:
                raise DataError("a continuous-time model (dt=0) needs the time stamps t of "
                                "the input samples: pass t=... or an IOData record")
            t = check_time_stamps(t, N)
            y, x = _simulate.simulate_continuous(self._A, self._B, self._C, self._D,
                                                 t, u, x0, hold)
        else:
            if t is not None:
                t = check_time_stamps(t, N)
                steps = np.diff(t)
                if steps.size and not same_period(steps, self._dt,
                                                  resolution=stamp_resolution(t)):
                    raise DataError(f"time stamps t have steps from {float(steps.min())!r} to "
                                    f"{float(steps.max())!r} but the model is discrete-time with "
                                    f"period dt={self._dt!r}; t must be uniform with that "
                                    "period (or omit t)")
            u = effective_input(self, u)                         # info['input_delay']
            y, x = _simulate.simulate_discrete(self._A, self._B, self._C, self._D, u, x0)
        return (y, x) if return_state else y

    # -- analysis --------------------------------------------------------
    def markov(self, k: int) -> np.ndarray:
        """Markov parameters (impulse response coefficients).

        Parameters
        ----------
        k : int
            Number of parameters, ``k >= 1``.

        Returns
        -------
        ndarray, shape (k, n_outputs, n_inputs)
            ``[D, C B, C A B, ..., C A^(k-2) B]``; with input delays
        (``info['input_delay']``, discrete time) input j's column is shifted
        by its delay.

        Raises
        ------
        OrderError
            ``k`` is not an integer >= 1.
        """
        k = check_int(k, "k", minimum=1)
        out = np.empty((k, self.n_outputs, self.n_inputs))
        out[0] = self._D
        row = self._C
        for i in range(1, k):
            out[i] = row @ self._B
            row = row @ self._A
        if not self.is_continuous and (delays := input_delay_of(self)) is not None:
            shifted = np.zeros_like(out)       # input j delayed by d_j samples
            for col, d in enumerate(delays):
                if d < k:
                    shifted[d:, :, col] = out[:k - d, :, col]
            out = shifted
        return out

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A``.

        Returns
        -------
        ndarray of complex, shape (n,)
            Sorted by descending magnitude (discrete time) or descending real
            part (continuous time); ties by descending imaginary part.
        """
        ev = np.linalg.eigvals(self._A).astype(complex)
        primary = np.abs(ev) if not self.is_continuous else ev.real
        order = np.lexsort((-ev.imag, -primary))
        return ev[order]

    def is_stable(self) -> bool:
        """Asymptotic stability.

        Returns
        -------
        bool
            ``max |eig(A)| < 1`` for discrete time, ``max Re eig(A) < 0`` for
            continuous time.
        """
        ev = np.linalg.eigvals(self._A)
        if self.is_continuous:
            return bool(ev.real.max() < 0)
        return bool(np.abs(ev).max() < 1)

    def freqresp(self, w) -> np.ndarray:
        """Frequency response.

        Parameters
        ----------
        w : array_like, shape (K,)
            Angular frequencies in rad/s (a scalar counts as one frequency).

        Returns
        -------
        ndarray of complex, shape (K, n_outputs, n_inputs)
            ``G(j w) = C (j w I - A)^-1 B + D`` for continuous time,
            ``G(exp(j w dt))`` for discrete time.

        Raises
        ------
        DataError
            ``w`` is not a finite real 1-D array.
        ModelError
            A frequency falls exactly on a pole (the response is infinite).
        """
        w = np.asarray(w)
        if w.dtype.kind not in "biuf":
            raise DataError(f"frequencies w must be real numbers (rad/s), got dtype {w.dtype}")
        w = np.atleast_1d(w.astype(np.float64))
        if w.ndim != 1:
            raise DataError(f"frequencies w must be a 1-D array, got shape {w.shape}")
        if not np.isfinite(w).all():
            raise DataError("frequencies w contain NaN or infinite values")
        s = 1j * w if self.is_continuous else np.exp(1j * w * self._dt)
        n, m, p = self.order, self.n_inputs, self.n_outputs
        G = np.empty((w.size, p, m), dtype=complex)
        if m == 0 or w.size == 0:
            return G
        A = self._A.astype(complex)
        Bc = self._B.astype(complex)
        eye = np.eye(n)
        chunk = max(1, _FREQ_CHUNK_ENTRIES // (n * (n + m)))
        for a in range(0, w.size, chunk):
            sc = s[a:a + chunk]
            M = sc[:, None, None] * eye - A
            try:
                X = np.linalg.solve(M, np.broadcast_to(Bc, (sc.size, n, m)))
            except np.linalg.LinAlgError:
                X = None
            if X is None or not np.isfinite(X).all():
                _conversions.raise_pole_hit(self, w[a:a + chunk], sc)
            G[a:a + chunk] = self._C @ X + self._D
        if not self.is_continuous and (delays := input_delay_of(self)) is not None:
            G *= frequency_factor(delays, w, self._dt)       # info['input_delay']
        return G

    def step(self, t=None):
        """Step response (MATLAB ``step``): every input in turn held at 1 from
        ``t = 0``, zero initial state.

        Parameters
        ----------
        t : float or array_like, optional
            Final time, or the time stamps (from 0; discrete time: ``0, dt,
            2 dt, ...``). Default: about the 0.1 % settling time of the
            slowest mode (:mod:`subid.model._responses`).

        Returns
        -------
        t : ndarray, shape (N,)
            Time stamps.
        y : ndarray, shape (N, n_outputs, n_inputs)
            ``y[k, i, j]``: output ``i`` at ``t[k]`` for a unit step on input ``j``.

        Raises
        ------
        DataError
            ``t`` is not a positive final time or valid time stamps.

        Examples
        --------
        >>> from subid.model.statespace import StateSpace
        >>> t, y = StateSpace([[0.5]], [[1.0]], [[1.0]], 0, dt=1.0).step(4.0)
        >>> y[:, 0, 0].tolist()
        [0.0, 1.0, 1.5, 1.75, 1.875]
        """
        return _responses.step_response(self, t)

    def impulse(self, t=None):
        """Impulse response (MATLAB ``impulse``, without its ``1/dt`` scaling in
        discrete time).

        Discrete time: the response to the unit pulse ``u_j[0] = 1`` (the
        Markov parameters, :meth:`markov`). Continuous time: ``C exp(A t) B``
        (the Dirac part ``D delta(t)`` is not drawn).

        Parameters
        ----------
        t : float or array_like, optional
            Final time or time stamps, as for :meth:`step`.

        Returns
        -------
        t : ndarray, shape (N,)
            Time stamps.
        y : ndarray, shape (N, n_outputs, n_inputs)
            ``y[k, i, j]``: output ``i`` at ``t[k]`` for an impulse on input ``j``.

        Raises
        ------
        DataError
            ``t`` is not a positive final time or valid time stamps.
        """
        return _responses.impulse_response(self, t)

    # -- conversions -----------------------------------------------------
    def to_discrete(self, dt, method=None) -> "StateSpace":
        """Discretise a continuous-time model.

        Parameters
        ----------
        dt : float
            Sampling period, > 0.
        method : {None, 'zoh', 'foh', 'bilinear'}
            Zero-order hold, first-order hold (triangle hold) or the bilinear
            (Tustin) transform (alias ``'tustin'``); the same formulas as
            :func:`scipy.signal.cont2discrete`. None (default): the model's
            :attr:`hold` (``'foh'`` for a ``ct_subspace`` model).

        Returns
        -------
        StateSpace
            Discrete-time model with the same names and a copy of ``info``
            without the entries it no longer matches, each named with its
            reason in ``info['dropped']``: the polynomials, their degrees and
            the parameter covariance; for ``'foh'`` and ``'bilinear'`` also the
            initial state ``info['x0']`` (the sampled state is then not the
            continuous one: ``x - Gamma2 u`` for the first-order hold).
            A Kalman gain ``K`` and ``noise_cov`` are not carried over (with a
            :class:`~subid.errors.NoiseModelWarning`): a continuous-time
            innovation model has no exact sampled counterpart without the
            noise intensity.

        Raises
        ------
        ModelError
            The model is already discrete-time, the method is unknown,
            (bilinear) ``I - dt/2 A`` is singular, or (holds) ``dt`` is too
            long for an unstable mode (``exp(A dt)`` overflows).
        DataError
            ``dt`` is not a positive number.
        """
        if not self.is_continuous:
            raise ModelError(f"the model is already discrete-time (dt={self._dt!r}); "
                             "convert it with to_continuous() first to resample it")
        dt = check_dt(dt)
        method = _conversions._method(self._hold if method is None else method)
        Ad, Bd, Cd, Dd = _conversions.discretise(self._A, self._B, self._C, self._D, dt,
                                                 method)
        _conversions.drop_noise_model(self, "to_discrete")
        info = _conversions.converted_info(self.info, "to_discrete", method)
        if method not in HOLDS:     # to_continuous()'s default (the hold: 7e-3 off)
            info["discretisation"] = method
        return self._like(Ad, Bd, Cd, Dd, dt, hold=method if method in HOLDS else None,
                          info=info)

    def to_continuous(self, method=None) -> "StateSpace":
        """Continuous-time model whose discretisation is this model.

        Exact inverse of :meth:`to_discrete` with the same ``method``: the
        matrix logarithm ``A = logm(A_d) / dt`` for ``'zoh'`` and ``'foh'``
        (``B`` and ``D`` from the linear relations of the hold), the inverse
        bilinear transform for ``'bilinear'``.

        Parameters
        ----------
        method : {None, 'zoh', 'foh', 'bilinear'}
            None (default): ``'bilinear'`` for a model :meth:`to_discrete` made so
            (``info['discretisation']``), else the model's :attr:`hold`.

        Returns
        -------
        StateSpace
            Continuous-time model (``dt == 0``) with the same names and a copy
            of ``info`` without the entries it no longer matches (as for
            :meth:`to_discrete`). Input delays are dropped (with a
            :class:`~subid.errors.DelayWarning`): dead time has no
            finite-dimensional continuous-time state-space form. ``K`` and
            ``noise_cov`` are dropped (with a
            :class:`~subid.errors.NoiseModelWarning`): a sampled innovation
            model (white innovations at the sampling instants) has no
            continuous-time counterpart.

        Raises
        ------
        ModelError
            The model is already continuous-time; ``A_d`` is singular or has an
            eigenvalue on the negative real axis without an equal partner (no
            real logarithm, ``'zoh'``/``'foh'``; a pair gives a mode at the
            Nyquist frequency); ``A_d`` has an eigenvalue at -1
            (``'bilinear'``).
        """
        if self.is_continuous:
            raise ModelError("the model is already continuous-time (dt=0)")
        method = _conversions._method(method or self.info.get("discretisation") or self._hold)
        A, B, C, D, hold = _conversions.continuise(self._A, self._B, self._C, self._D,
                                                   self._dt, method)
        _conversions.drop_noise_model(self, "to_continuous")
        return self._like(A, B, C, D, 0.0, hold=hold,
                          info=_conversions.converted_info(self.info, "to_continuous", method))

    def transform(self, T) -> "StateSpace":
        """Similarity transformation to the state ``z = T x``.

        Parameters
        ----------
        T : array_like, shape (n, n)
            Nonsingular transformation.

        Returns
        -------
        StateSpace
            ``(T A T^-1, T B, C T^-1, D)`` and ``T K``, same dt, names,
            ``noise_cov`` and a copy of ``info`` with its state-basis entries
            transformed too: the initial state(s) ``info['x0']`` become ``T x0``
            (one row per experiment), the selector Λ of ``ls_subspace``
            ``info['selector']`` becomes ``T Λ`` (the state it fixes, ``Λ Γ x``,
            is then ``z``), and the parameter covariance maps with the
            (linear) change of the matrices, so that the bounds of
            :mod:`subid.evaluation.uncertainty` are unchanged. Markov
            parameters, frequency response, predictions and simulations from
            ``info['x0']`` are unchanged.

        Raises
        ------
        ModelError
            ``T`` has the wrong shape, is not finite, or is singular.
        """
        T = _as_matrix(T, "T")
        n = self.order
        if T.shape != (n, n):
            raise ModelError(f"T has shape {T.shape[0]}x{T.shape[1]} but the model order is "
                             f"{n}: T must be {n} x {n}")
        _check_nonsingular(T, "T", "a similarity transformation must be invertible")
        lu = linalg.lu_factor(T, check_finite=False)
        # X T^-1 = (T^-T X^T)^T
        A = linalg.lu_solve(lu, (T @ self._A).T, trans=1, check_finite=False).T
        C = linalg.lu_solve(lu, self._C.T, trans=1, check_finite=False).T
        Tinv = linalg.lu_solve(lu, np.eye(n), check_finite=False)
        info = _conversions.transformed_info(self.info, T, Tinv,
                                             (n, self.n_inputs, self.n_outputs))
        return self._like(A, T @ self._B, C, self._D, self._dt,
                          None if self._K is None else T @ self._K, self._noise_cov,
                          info=info)

    def allclose(self, other: "StateSpace", rtol: float = 1e-5, atol: float = 1e-8) -> bool:
        """Whether two models have the same shapes, time base and (to the given
        tolerances, as in :func:`numpy.allclose`) the same matrices.

        Parameters
        ----------
        other : StateSpace
        rtol, atol : float

        Returns
        -------
        bool
            Note that this compares realisations, not input/output behaviour:
            a similarity-transformed model is generally not ``allclose``.
        """
        if not isinstance(other, StateSpace):
            return False
        if (self._A.shape, self._B.shape, self._C.shape) != (
                other._A.shape, other._B.shape, other._C.shape):
            return False
        if self.is_continuous != other.is_continuous:
            return False
        if not np.isclose(self._dt, other._dt, rtol=rtol, atol=atol):
            return False
        return all(np.allclose(a, b, rtol=rtol, atol=atol) for a, b in
                   zip((self._A, self._B, self._C, self._D),
                       (other._A, other._B, other._C, other._D)))

    # -- serialisation ---------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-ready dictionary of the model (see the module docstring).

        Returns
        -------
        dict
            Keys ``format``, ``version`` (of the format), ``subid_version``
            (of the writer, :data:`subid.__version__`), ``A``, ``B``, ``C``,
            ``D``, ``dt``, ``input_names``, ``output_names``, ``info``; only plain Python
            values, serialisable with ``json.dumps(d, allow_nan=False)``.

        Raises
        ------
        ModelError
            ``info`` holds a value that cannot be stored (the message gives
            its location).
        """
        return _codec.to_dict(self)

    @classmethod
    def from_dict(cls, d) -> "StateSpace":
        """Model from a dictionary written by :meth:`to_dict`.

        Parameters
        ----------
        d : dict
            Required keys ``format``, ``version``, ``A``, ``B``, ``C``, ``D``,
            ``dt``; optional ``input_names``, ``output_names``, ``info``,
            ``subid_version`` (ignored), ``K``, ``noise_cov``, ``hold``.

        Returns
        -------
        StateSpace

        Raises
        ------
        ModelError
            A key is missing, unknown or holds a bad value (the message names
            it), or the matrices are inconsistent.
        """
        return _codec.from_dict(cls, d)

    def save(self, path) -> None:
        """Write the model to a JSON file, atomically.

        The text goes to a temporary file in the same directory, which is
        flushed, synced to disk and then renamed over ``path``: a reader (or
        a crash) never sees a partly written file, and an existing file is
        left untouched if writing fails.

        Parameters
        ----------
        path : str or os.PathLike

        Raises
        ------
        ModelError
            ``info`` holds a value that cannot be stored (an integer beyond 64
            bits too), or the file would exceed the 256 MB :meth:`load` reads
            (nothing is written).
        OSError
            The file cannot be written.
        """
        _files.writer("json")(self, path)

    @classmethod
    def load(cls, path) -> "StateSpace":
        """Read a model written by :meth:`save`.

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        StateSpace

        Raises
        ------
        DataFileNotFoundError
            The file does not exist.
        FileReadError
            The file exists but cannot be read: not a regular file (a
            directory, a FIFO, a device), or larger than 256 MB.
        ModelError
            The file is not valid JSON (truncated, corrupted, nested too
            deeply, numbers beyond 64 bits or overflowing) or does not
            describe a valid model; the message names the file.
        """
        return _files.reader("json")(path, cls)

    # -- other libraries -------------------------------------------------
    def to_control(self):
        """Convert to a python-control state-space system.

        Returns
        -------
        control.StateSpace
            ``dt`` 0 for continuous time, the sampling period otherwise;
            input and output labels are the channel names.

        Raises
        ------
        ImportError
            python-control is not installed (``pip install control``).

        Notes
        -----
        ``control.StateSpace`` has no slot for a Kalman gain or a noise
        covariance: ``K`` and ``noise_cov`` are not exported. To keep them,
        export the predictor or the noise channels yourself, e.g.
        ``ss(A, [B K], C, [D I], dt)`` with the innovations as extra inputs.
        Input delays (``info['input_delay']``) are exported as extra states
        (:func:`subid.absorb_delay`). A first-order hold (:attr:`hold`) has no
        slot either: exporting a ``'foh'`` model warns
        (:class:`~subid.errors.ConversionWarning`).
        """
        return _conversions.to_control(self)

    def to_mat(self, path) -> None:
        """Write the model as MATLAB ``ss(A, B, C, D, Ts)`` fields (:func:`subid.interop.save_mat`);
        input delays become extra states (:func:`subid.absorb_delay`)."""
        _files.writer("mat")(self, path)

    @classmethod
    def from_mat(cls, path, *, dt=None) -> "StateSpace":
        """Read a model from a MATLAB ``.mat`` file (:func:`subid.interop.load_mat`).

        The file is read by :func:`subid.io.mat.mat_variables`, the validated MAT
        loader of :func:`subid.read`.
        """
        return _files.reader("mat")(path, cls, dt=dt)

    @classmethod
    def from_control(cls, sys, *, dt=None) -> "StateSpace":
        """Model from a python-control system.

        Parameters
        ----------
        sys : control.StateSpace or other control LTI system
            Transfer functions are converted with ``control.ss``.
        dt : float, optional
            Sampling period to use when ``sys.dt`` does not give one:
            python-control's ``dt=True`` (discrete time, unspecified period)
            requires it. ``dt=None`` (unspecified time base) is read as
            continuous time unless ``dt`` is given here.

        Returns
        -------
        StateSpace
            With the system's input and output labels as channel names.

        Raises
        ------
        ImportError
            python-control is not installed.
        ModelError
            ``sys`` is not a python-control LTI system, is a static gain (no
            states), is a MIMO transfer function python-control cannot realise
            (without slycot), its sampling period is unspecified and ``dt`` is
            not given, or ``dt`` is given for a continuous-time system
            (``sys.dt == 0``; sample the result with :meth:`to_discrete`).
        """
        return _conversions.from_control(cls, sys, dt=dt)

    def to_scipy(self):
        """Convert to :class:`scipy.signal.StateSpace`.

        Returns
        -------
        scipy.signal.StateSpace
            Continuous (``dt=None``) or discrete with the sampling period.

        Notes
        -----
        ``scipy.signal.StateSpace`` has no slot for a Kalman gain or a noise
        covariance: ``K`` and ``noise_cov`` are not exported. Input delays are
        exported as extra states (:func:`subid.absorb_delay`). A ``'foh'`` model
        warns (:class:`~subid.errors.ConversionWarning`): scipy has no hold.
        """
        return _conversions.to_scipy(self)

    @classmethod
    def from_scipy(cls, sys, *, dt=None) -> "StateSpace":
        """Model from a :mod:`scipy.signal` LTI system.

        Parameters
        ----------
        sys : scipy.signal.lti or scipy.signal.dlti
            Transfer-function and zero-pole-gain systems are converted with
            ``sys.to_ss()``.
        dt : float, optional
            Sampling period for a discrete system created with scipy's
            default ``dt=True`` (unspecified period). A continuous-time
            system (``lti``, ``sys.dt`` None) refuses it: sample the result
            instead, ``StateSpace.from_scipy(sys).to_discrete(dt)``.

        Returns
        -------
        StateSpace

        Raises
        ------
        ModelError
            ``sys`` is not a scipy LTI system, has no states, its sampling
            period is unspecified and ``dt`` is not given, or ``dt`` is given
            for a continuous-time system.
        """
        return _conversions.from_scipy(cls, sys, dt=dt)
