"""Noise model of an identified model: Kalman gain and innovation covariance.

Given the deterministic part ``(A, B, C, D)`` found by a subspace method,
the innovation form

    x[k+1] = A x[k] + B u[k] + K e[k],    y[k] = C x[k] + D u[k] + e[k]

is completed from the state and residual sequences (Van Overschee & De Moor,
*Subspace Identification for Linear Systems*, 1996, Sec. 4.3.1-4.3.2 and
Theorem 12):

1. Kalman-filter state sequences ``X_p`` and ``X_{p+1}`` are the
   least-squares solutions of ``Γ_f X_p = Y_f /_{U_f} W_p`` and
   ``Γ_{f-1} X_{p+1} = Y_f^- /_{U_f^-} W_p^+`` (oblique projections of the
   future outputs on the past data along the future inputs), with
   ``Γ_f = [C; C A; ...; C A^{f-1}]`` the model's own observability matrix.
2. The residuals ``E = Y_{p|p} - C X_p - D U_{p|p}`` and
   ``W = X_{p+1} - A X_p - B U_{p|p}`` give the noise covariances
   ``Q = W W^T``, ``S = W E^T``, ``R = E E^T`` (sample means: ``L L^T`` is
   normalised by the number of columns).
3. The steady-state Kalman filter of ``(A, C, Q, S, R)`` (stabilising
   solution ``P`` of the filter Riccati equation, ibid., Sec. 4.3.2) gives
   ``K = (A P C^T + S)(C P C^T + R)^{-1}`` and ``Σ = C P C^T + R``. For exact
   Kalman states ``W = K E``, ``P = 0`` and this is the regression
   ``K = S R^{-1}``; with the biased states of a wrong or short-record model
   the Riccati solution is the more robust (on the DaISy dryer2 record the
   regression gain gave a one-step validation fit of -95 %, the Riccati gain
   56 %). Should the Riccati equation have no stabilising solution, the
   regression ``K = S R^{-1}``, ``Σ = R`` is used.

4. Where the record is at hand (every batch call on an :class:`~subid.IOData`), the
   innovation covariance reported is the sample covariance of the one-step prediction
   errors of that predictor on the record, ``noise_cov = E^T E / N`` (the maximum-likelihood
   estimate of the innovation covariance given the predictor, Ljung, *System
   Identification*, 2nd ed., 1999, Sec. 7.3), each experiment predicted from an initial
   state fitted to its first samples: one compiled pass
   (:func:`subid.methods.dt._innovation_kernel.prediction_power`). ``Σ`` of step 3 is the
   covariance the predictor would reach were the model and its state sequences exact;
   with the biased states of a real record it was far off: on the DaISy records (first
   2/3, default calls) 1.0-5x the covariance of the predictor's own errors, about 7e3x on
   CD_player_arm (MOESP) and 4e6x on robot_arm (issue 21 follow-up, session 14).
   ``info['noise_cov_estimate']`` says which was used. :class:`subid.RecursiveSubspace`
   passes the last samples of its stream (:mod:`subid.methods.online._window`); from a
   :class:`~subid.HankelStatistic` alone (no samples) it is ``Σ``.

Everything acts on the triangular factor ``L`` of the block-Hankel data matrix
(``H = L Q^T``), as the subspace methods do: projections and least squares on
the rows of ``L`` equal those on the data rows, and ``L L^T`` is the sample
correlation. Only QR-based least squares (``gelsy``) and the generalised Schur (QZ)
decomposition of the Riccati solver are used: no SVD, so
:func:`subid.ls_subspace` stays SVD-free.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.linalg

from subid.data import IOData, column_std
from subid.errors import NoiseModelWarning, OptionError, SubidError
from subid.methods._common import extended_observability
from subid.methods.dt._lapack import least_squares_gelsy
from subid.statistic._hankel import HankelFactor

__all__ = ["innovation_model", "attach_noise_model", "check_refine", "REFINE_OPTIONS"]

REFINE_OPTIONS = (None, "simulation", "prediction")


def _lstsq(M, rhs):
    """Least squares by QR with column pivoting (no SVD): ``scipy.linalg.lstsq(M, rhs,
    lapack_driver='gelsy')[0]`` by the same LAPACK call without its wrapper (the same
    bits, :func:`subid.methods.dt._lapack.least_squares_gelsy`)."""
    return least_squares_gelsy(M, rhs)


def _oblique(hf: HankelFactor, y_rows, u_rows, w_rows) -> np.ndarray:
    """Coefficients (w.r.t. ``Q^T``) of ``Y /_U W``: the ``W`` part of the
    least-squares regression of ``Y`` on ``[W; U]``."""
    L = hf.L
    Wp, Uf, Yf = L[w_rows], L[u_rows], L[y_rows]
    reg = np.vstack([Wp, Uf])
    theta = _lstsq(reg.T, Yf.T).T
    return theta[:, :Wp.shape[0]] @ Wp


def _projections(hf: HankelFactor, p: int):
    """``(O_p, O_{p+1})``: the oblique projections of the future outputs on the past
    along the future inputs, with ``p`` and ``p + 1`` past block rows. They depend on
    the factor only, not on the model: computed once per factor object and ``p``
    (:meth:`subid.statistic._hankel.HankelFactor.derived`), for the models of every
    order fitted on it (:func:`subid.methods.dt.choice.innovation_check`)."""
    def compute():
        s = hf.depth
        o_p = _oblique(hf, hf.y_rows(p, s), hf.u_rows(p, s),
                       np.concatenate([hf.u_rows(0, p), hf.y_rows(0, p)]))
        o_p1 = _oblique(hf, hf.y_rows(p + 1, s), hf.u_rows(p + 1, s),
                        np.concatenate([hf.u_rows(0, p + 1), hf.y_rows(0, p + 1)]))
        return o_p, o_p1
    return hf.derived(("oblique projections", p), compute)


def _spectral_radius(M) -> float:
    return float(np.abs(np.linalg.eigvals(M)).max()) if M.size else 0.0


#: Iterations of :func:`riccati_by_doubling` before it gives up (each squares the
#: contraction of the closed loop: 12 reach rounding for a predictor pole at 0.999).
DOUBLING_ITERATIONS = 40
#: Relative change of the solution below which :func:`riccati_by_doubling` stops.
DOUBLING_TOLERANCE = 1e-15


def riccati_by_doubling(A, C, Q, R, S):
    """The stabilising solution ``P`` of the filter Riccati equation
    ``P = A P A^T - (A P C^T + S)(C P C^T + R)^{-1}(A P C^T + S)^T + Q``, the equation
    ``scipy.linalg.solve_discrete_are(A.T, C.T, Q, R, s=S)`` solves, by the
    structure-preserving doubling algorithm (Chu, Fan, Lin & Wang, "Structure-preserving
    algorithms for periodic discrete-time algebraic Riccati equations", Int. J. Control
    77, 2004; convergence: Lin & Xu, SIAM J. Matrix Anal. Appl. 28, 2006): with the
    cross term removed
    (``Ā = A - S R^{-1} C``, ``Q̄ = Q - S R^{-1} S^T``, ``G = C^T R^{-1} C``) the
    equation reads ``P = Ā P (I + G P)^{-1} Ā^T + Q̄``, and the iteration
    ``A_{k+1} = A_k W^{-1} A_k``, ``G_{k+1} = G_k + A_k W^{-1} G_k A_k^T``,
    ``H_{k+1} = H_k + A_k^T H_k W^{-1} A_k`` (``W = I + G_k H_k``) from ``A_0 = Ā^T``,
    ``G_0 = G``, ``H_0 = Q̄`` gives ``H_k -> P`` quadratically (substitute
    ``A_0^T P (I + G_0 P)^{-1} A_0 + H_0`` into the equation above with the matrix
    inversion lemma; ``tests/test_noise_model_doubling.py`` checks it against scipy to
    1e-10, unstable A included). A few small products per iteration instead of the QZ
    decomposition of a ``2 n + ny`` pencil and its checks (about 4x faster at n = 10,
    seven iterations): used where the gain is only scored
    (:func:`subid.methods.dt.choice.innovation_check`). None when ``R`` is
    singular, an iterate is not finite or the iteration does not settle within
    :data:`DOUBLING_ITERATIONS` (the caller then solves by QZ)."""
    try:
        Rc = scipy.linalg.cho_factor(R, check_finite=False)
        Ri_C = scipy.linalg.cho_solve(Rc, C, check_finite=False)
        Ri_St = scipy.linalg.cho_solve(Rc, S.T, check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        return None
    Ak = (A - S @ Ri_C).T
    G = C.T @ Ri_C
    G = 0.5 * (G + G.T)
    H = Q - S @ Ri_St
    H = 0.5 * (H + H.T)
    # the iteration in one compiled loop (its numpy reference:
    # subid.methods.dt._innovation_kernel.doubling_reference)
    from subid.methods.dt._innovation_kernel import doubling
    return doubling(Ak, G, H, DOUBLING_ITERATIONS, DOUBLING_TOLERANCE)


def innovation_model(A, B, C, D, hf: HankelFactor, past: int | None = None, *,
                     doubling: bool = False):
    """Kalman gain and innovation covariance from a Hankel factor.

    Parameters
    ----------
    A, B, C, D : ndarray
        Deterministic part of the model (user's units).
    hf : HankelFactor
        Factor of the data in the user's units (not channel-normalised),
        depth ``s >= past + 2``.
    past : int, optional
        Past block rows ``p`` (default ``s // 2``); ``f = s - p`` future rows.
    doubling : bool
        Solve the Riccati equation by :func:`riccati_by_doubling` (QZ where it gives
        up): the same gain to about 1e-12 relative, for gains that are only scored.

    Returns
    -------
    K : ndarray, shape (n, ny)
    noise_cov : ndarray, shape (ny, ny)
    diagnostics : dict
        ``noise_model`` (how K was found), ``predictor_spectral_radius``
        (of ``A - K C``), ``noise_model_past``.

    Raises
    ------
    SubidError
        The factor is too shallow for the model order.
    """
    n, ny, nu = A.shape[0], C.shape[0], B.shape[1]
    s = hf.depth
    p = s // 2 if past is None else int(past)
    f = s - p
    if p < 1 or (f - 1) * ny < n:
        raise SubidError(f"the noise model needs at least one past block row and "
                         f"(future rows - 1) * n_outputs >= order; depth {s} with {p} past "
                         f"rows and order {n} does not allow it")
    o_p, o_p1 = _projections(hf, p)
    gamma = extended_observability(A, C, f)
    u_p = hf.L[hf.u_rows(p, p + 1)] if nu else np.zeros((0, hf.L.shape[1]))
    y_p = hf.L[hf.y_rows(p, p + 1)]
    # the state sequences X = Γ^+ O with each output's rows weighted by the inverse of its
    # size (the norm of its row y(p), which scales with its unit): unweighted, the least
    # squares favoured the outputs of the largest units, and K changed with the units of
    # the outputs (6 % on a 2 x 2 record with one output in units 10^8 times smaller);
    # weighted, K' = K S^-1 for outputs scaled by S, as A, B, C, D transform
    size = np.linalg.norm(y_p, axis=1)
    w = 1.0 / np.where(size > 0, size, 1.0)
    w_f = np.tile(w, f)[:, None]
    x_p = _lstsq(gamma * w_f, o_p * w_f)
    x_p1 = _lstsq(gamma[:-ny] * w_f[:-ny], o_p1 * w_f[:-ny])
    E = y_p - C @ x_p - D @ u_p
    W = x_p1 - A @ x_p - B @ u_p
    R = E @ E.T
    R = 0.5 * (R + R.T)
    Q = W @ W.T
    Q = 0.5 * (Q + Q.T)
    S = W @ E.T
    K = sigma = None
    y_power = float(np.sum(y_p ** 2))
    if float(np.trace(R)) <= 1e-20 * max(y_power, 1e-300):
        # noise-free record: the model explains the outputs to rounding, the
        # innovations vanish and the Kalman gain is zero (the predictor is the model)
        return np.zeros((n, ny)), R, {"noise_model": "noise-free data: K = 0",
                                       "predictor_spectral_radius": _spectral_radius(A),
                                       "noise_model_past": p}
    try:
        scale = max(float(np.trace(Q)), 1e-300)
        with np.errstate(all="ignore"):
            P = riccati_by_doubling(A, C, Q + 1e-10 * scale * np.eye(n), R, S) \
                if doubling else None
            if P is None:
                P = scipy.linalg.solve_discrete_are(A.T, C.T, Q + 1e-10 * scale * np.eye(n), R,
                                                    s=S)
        sigma = C @ P @ C.T + R
        sigma = 0.5 * (sigma + sigma.T)
        # K = (A P C^T + S) sigma^-1 with sigma equilibrated by its diagonal: outputs of
        # very different units (1e8 against 1) make sigma badly scaled, not ill-posed,
        # and the unscaled solve warned of its condition (the same K in exact arithmetic)
        diagonal = np.diag(sigma)        # a negative one (noise-free data): no scaling
        d = np.sqrt(np.where(diagonal > 0, diagonal, 1.0))
        K = (scipy.linalg.solve(sigma / np.outer(d, d), (A @ P @ C.T + S).T / d[:, None],
                                assume_a="pos") / d[:, None]).T
        how = "Kalman filter Riccati equation of the residual covariances (VODM 1996, Sec. 4.3)"
        radius = _spectral_radius(A - K @ C)
        if not (np.isfinite(K).all() and radius < 1.0):
            K = None
    except (np.linalg.LinAlgError, ValueError):
        K = None
    if K is None:       # Riccati failed: the gain that maps the innovations to the state noise
        K = _lstsq(E.T, W.T).T
        sigma = R
        how = "state-sequence regression W = K E (VODM 1996, Sec. 4.3)"
        radius = _spectral_radius(A - K @ C)
    return K, sigma, {"noise_model": how, "predictor_spectral_radius": radius,
                      "noise_model_past": p}


#: ``info['noise_cov_estimate']``: how ``noise_cov`` was found.
FROM_PREDICTION_ERRORS = ("sample covariance of the one-step prediction errors of the "
                          "Kalman predictor on the estimation record, initial state by least "
                          "squares (Ljung 1999, Sec. 7.3)")
NOISE_FREE = "R of the state-sequence residuals (a noise-free record: K = 0)"
FROM_RICCATI = ("C P C^T + R of the Kalman filter Riccati equation (no samples at hand; "
                "VODM 1996, Sec. 4.3)")


#: The initial state of the predictor is fitted to the prediction errors of the first
#: samples, as many as its free response takes to decay to this fraction.
TRANSIENT_DECAY = 1e-16


def _predictor_initial_states(model, K, data: IOData, radius: float) -> np.ndarray:
    """Each experiment's initial predicted state, fitted by least squares to the
    prediction errors of its first samples (:func:`subid.predict` with ``x0='estimate'``
    on the samples over which the predictor's free response decays to
    :data:`TRANSIENT_DECAY`: the later samples do not depend on it; the outputs weighted
    by the spreads of the whole experiment, as ``predict`` on it weighs them)."""
    from subid.model.prediction import predict
    n = model.order
    length = n + 1 if radius <= 0.0 else \
        n + 1 + math.ceil(math.log(TRANSIENT_DECAY) / math.log(radius))
    predictor = model.with_noise_model(K, None, info={})
    states = []
    for experiment in data.experiments:
        head = experiment[:min(length, experiment.n_samples)]
        states.append(predict(predictor, head, 1, return_x0=True,
                              output_std=column_std(experiment.y))[1])
    return np.stack(states)


def prediction_error_covariance(model, K, data: IOData, radius: float, x0=None):
    """``E^T E / N``: the sample covariance of the one-step prediction errors of the
    predictor ``(A - K C, B - K D, K)`` of ``model`` (spectral radius ``radius`` < 1) on
    ``data``, each experiment from its initial state fitted by least squares
    (:func:`_predictor_initial_states`; a zero or simulation initial state leaves a
    transient that dominates where the predictor is accurate: 20x the covariance on
    DaISy robot_arm; ``x0``: those states when the caller has them already); None when
    the predictor diverges. The errors' products are summed in one compiled pass
    (:func:`subid.methods.dt._innovation_kernel.prediction_power`)."""
    from subid.methods.dt._innovation_kernel import prediction_power
    pieces = [(data.u[a:b], data.y[a:b]) for a, b in data.experiment_ranges]
    if x0 is None:
        try:
            x0 = _predictor_initial_states(model, K, data, radius)
        except SubidError:           # the prediction of the first samples diverges
            return None
    power = prediction_power(model.A, model.B, model.C, model.D, K, pieces, x0)
    if power is None:
        return None
    sigma = power / data.n_samples
    return 0.5 * (sigma + sigma.T)


#: The key of a problem's cache (:meth:`subid.methods.dt._subspace.Problem.cached`) that
#: holds its factor in the user's units (:func:`user_factor`).
USER_FACTOR = "user factor"


def user_factor(problem) -> HankelFactor:
    """The Hankel factor of a :class:`subid.methods.dt._subspace.Problem` in the user's units."""
    def make():
        hf = problem.factor
        s = hf.depth
        row_scale = np.concatenate([np.tile(problem.input_scale, s),
                                    np.tile(problem.output_scale, s)])
        return HankelFactor(L=hf.L * row_scale[:, None], depth=s, n_inputs=hf.n_inputs,
                            n_outputs=hf.n_outputs, n_columns=hf.n_columns)
    # once per problem: the models of its orders then share the factor's projections
    cached = getattr(problem, "cached", None)
    return make() if cached is None else cached(USER_FACTOR, make)


def _factor_for(model, problem) -> HankelFactor | None:
    """A factor deep enough for the noise model: the method's own, else one
    built from the raw record (depth ``2 * horizon``); None without raw data."""
    n, ny = model.order, model.n_outputs
    hf = problem.factor
    p = hf.depth // 2
    if p >= 1 and (hf.depth - p - 1) * ny >= n:
        return user_factor(problem)
    if not isinstance(problem.data, IOData):
        return None
    from subid.statistic.hankel import HankelStatistic
    h = max(problem.horizon, -(-n // ny) + 2)
    if problem.data.n_samples < 2 * h * (model.n_inputs + ny + 1):
        return None
    return HankelStatistic.from_data(problem.data, 2 * h).factor()


def check_refine(refine, data):
    """``refine`` as the focus of the refinement (None, 'simulation' or 'prediction'),
    or an error; checked before any work. ``'pem'`` is the deprecated spelling of
    ``'prediction'`` (DeprecationWarning)."""
    if isinstance(refine, str) and refine == "pem":
        warnings.warn("subid: refine='pem' is deprecated; say which criterion the refinement "
                      "minimises: refine='prediction' (what 'pem' meant) or "
                      "refine='simulation'", DeprecationWarning, stacklevel=3)
        refine = "prediction"
    if not any(refine is c or (isinstance(refine, str) and refine == c)
               for c in REFINE_OPTIONS):
        raise OptionError(f"refine must be None, 'simulation' or 'prediction', got "
                          f"{refine!r}"[:300])
    if refine is not None and not isinstance(data, IOData):
        raise SubidError(f"refine={refine!r} needs the raw record (IOData): a statistic holds "
                         "no samples to predict")
    return refine


def attach_noise_model(model, problem, *, doubling: bool = False):
    """The model of a batch method with ``K`` and ``noise_cov`` added.

    Called at the end of :func:`subid.ls_subspace`, :func:`subid.moesp` and
    :func:`subid.n4sid` (by ``_subspace.finalize``, which then runs
    the optional refinement: :func:`subid.pem` builds on this module, not the reverse).

    Parameters
    ----------
    model : StateSpace
        The model of the batch method, without a noise model.
    problem : Problem
        The prepared problem it was identified from (its Hankel factor).
    doubling : bool
        The Riccati equation by doubling (:func:`innovation_model`): for models that
        are only scored (:func:`subid.methods.dt.choice.innovation_check`, which
        sums the prediction errors itself: ``noise_cov`` is then the Riccati ``Σ``).

    Returns
    -------
    StateSpace
        ``info['noise_model']`` says how K was found (or why not),
        ``info['noise_cov_estimate']`` how ``noise_cov`` was.
    """
    hf = _factor_for(model, problem)
    info = dict(model.info)
    if hf is None:
        info["noise_model"] = ("not estimated: the statistic is too shallow for the state "
                               "sequences (identify from the record, or with a deeper "
                               "statistic)")
        model = model.with_noise_model(None, None, info=info)
    else:
        record = problem.data if isinstance(problem.data, IOData) and not doubling else None
        model = with_factor(model, hf, doubling=doubling, data=record)
    return model


def with_factor(model, hf: HankelFactor, past: int | None = None, *, doubling: bool = False,
                data: IOData | None = None):
    """``model`` with ``K`` estimated on the factor ``hf`` (used by
    :class:`subid.RecursiveSubspace` on its running factor; ``doubling`` as in
    :func:`innovation_model`) and ``noise_cov`` the covariance of its prediction errors
    on ``data`` (:func:`prediction_error_covariance`; the Riccati ``Σ`` without
    ``data``)."""
    info = dict(model.info)
    K, sigma, diag = innovation_model(model.A, model.B, model.C, model.D, hf, past,
                                      doubling=doubling)
    info.update(diag)
    noise_free = diag["noise_model"].startswith("noise-free")
    if not (np.isfinite(K).all() and np.isfinite(sigma).all()) or (
            diag["predictor_spectral_radius"] >= 1.0 and not noise_free):
        warnings.warn(f"{model.info.get('method', 'identification')}: no stable Kalman "
                      f"predictor was found (spectral radius of A - K C "
                      f"{diag['predictor_spectral_radius']:.4g}); the model has no noise "
                      "model and predicts by simulation", NoiseModelWarning, stacklevel=3)
        info["noise_model"] = "not estimated: no stable predictor"
        return model.with_noise_model(None, None, info=info)
    info["noise_cov_estimate"] = NOISE_FREE if noise_free else FROM_RICCATI
    if data is not None and not noise_free:
        measured = prediction_error_covariance(model, K, data,
                                               diag["predictor_spectral_radius"])
        if measured is not None:
            sigma, info["noise_cov_estimate"] = measured, FROM_PREDICTION_ERRORS
    return model.with_noise_model(K, sigma, info=info)
