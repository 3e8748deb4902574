"""The Kalman gain K of a model whose deterministic part is fixed, by prediction error.

A subspace method's K comes from its state sequences and the filter Riccati equation
(:mod:`subid.methods.dt.noise_model`, Van Overschee & De Moor 1996, Sec. 4.3); an
output-error fit (:func:`subid.pem` with ``focus='simulation'``) has no K of its own
and gets one the same way. Those gains are consistent, but on a record of finite length
with a model that is not the true system they are far from the best predictor the
deterministic part allows. Measured (``bench/gain_realdata.py``, ``subid.identify`` on
the first 2/3 of the DaISy records, means removed; one-step prediction error power on
the last 1/3, state-sequence gain -> the gain below): CD_player_arm 0.0083, 0.0216 ->
0.0012, 0.0042; winding 0.109, 0.319 -> 0.017, 0.133; dryer2 0.024, 0.014, 0.045 ->
0.0056, 0.0009, 0.037; powerplant 0.15-0.45x; robot_arm 8.2e-8 -> 5.2e-8; steamgen
0.0155, 0.0269 -> 0.0122, 0.0169 on its last two outputs; dryer, evaporator and
exchanger within 1 %; glassfurnace 12-22 % higher on three of its six outputs and
6-12 % lower on two; ballbeam 4 % higher.

:func:`refine_gain` minimises the prediction-error criterion of :func:`subid.pem`,
``V(K) = 1/(2N) sum_t ||W (y[t] - ŷ[t|K])||^2`` with ``ŷ`` the one-step predictor
``x̂[t+1] = (A - K C) x̂[t] + (B - K D) u[t] + K y[t]``, ``ŷ[t] = C x̂[t] + D u[t]``,
over ``K`` and the initial states only (Ljung, *System Identification*, 2nd ed., 1999,
Sec. 7.2-7.3: with the weighting ``W`` the inverse Cholesky factor of the start's error
covariance, the Gaussian likelihood of the innovation form given ``A, B, C, D``). The
predictor is affine in nothing but x0, so the iteration is the one :func:`subid.pem`
runs (:func:`subid.methods.dt._pe_search.minimise_prediction_error`: Gauss-Newton in a trust
region, analytic Jacobian by the compiled sensitivity equations, a trial with an
unstable predictor rejected), with the ``n ny`` entries of K as coordinates (no
similarity directions: A and C are fixed), started from the model's own K and stopped
at :data:`GAIN_PRECISION` of the criterion's statistical scale. On a record longer than
:data:`subid.methods.crossval.MAX_SELECTION_SAMPLES` the gain is fitted to its last
100,000 samples (``info['gain_refinement']['samples']``; the part the order selection
and the fold refinements use: a gain has ``n ny`` entries, and a Jacobian of 10^6
samples cost 0.5 s for an order-4 2x2 model, 1.4 s for the step, as much as the rest of
``subid.identify``). Closed loop: with A, B, C, D fixed, the prediction errors are a
filter of ``y - G(q) u = H(q) e`` alone, which does not depend on how the input was
generated, so the step behaves alike in open and closed loop (the consistency Monte
Carlo of ``tests/test_gain.py`` run under the feedback ``u = r + 0.5 y`` of issue 21
gave the same gain errors to 1e-15); the consistency of the deterministic part in
closed loop is the subspace start's and the refinement's (:mod:`subid.methods.identify`).
``noise_cov`` is then the sample covariance of the errors at the gain reached, over the
whole record
(:func:`subid.methods.dt.noise_model.prediction_error_covariance`). Cost (2x2, order 4,
20 dB): one Jacobian and one prediction where the state-sequence gain is already at
that precision (10^5 samples: about 0.08 s; ``identify`` 0.99 against 0.94 CPU s
without the step, 10^6: 1.68 against 1.82, paired in one process).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from subid.delay import delay_inputs, input_delay_of, record_delay
from subid.errors import SubidError
from subid.methods.crossval import selection_part
from subid.methods.dt._pe_search import (
    MAX_ITERATIONS,
    STABILITY_LIMIT,
    TOLERANCE,
    _predictor,
    _radius,
    minimise_prediction_error,
    statistical_precision,
)
from subid.methods.dt.noise_model import (
    FROM_PREDICTION_ERRORS,
    _predictor_initial_states,
    prediction_error_covariance,
)

__all__ = ["refine_gain", "checked_gain"]

#: Prediction errors whose power is below this fraction of the outputs' are rounding
#: (a noise-free record, whose K is zero): no gain is fitted to them (the level of
#: :func:`subid.methods.dt.noise_model.innovation_model`).
NOISE_FREE = 1e-20
#: ``info['noise_model']`` of a model whose K :func:`refine_gain` estimated.
DESCRIPTION = ("prediction-error minimisation over K with A, B, C, D fixed, from the "
               "state-sequence gain (subid.methods.dt.gain)")


def _directions(A, C, D, n, nu, ny):
    """The derivatives of the predictor ``(A - K C, [B - K D, K], C, [D, 0])`` along each
    entry of K (row-major), then along each entry of the initial state: the direction
    arrays of :func:`subid.model._sensitivity.jacobian`."""
    dm = n * ny
    d = dm + n
    dAp = np.zeros((d, n, n))
    dBp = np.zeros((d, n, nu + ny))
    dC = np.zeros((d, ny, n))
    dDp = np.zeros((d, ny, nu + ny))
    dx0 = np.zeros((d, n))
    unit = np.eye(dm).reshape(dm, n, ny)           # dK of each coordinate
    dAp[:dm] = -unit @ C
    dBp[:dm, :, :nu] = -unit @ D
    dBp[:dm, :, nu:] = unit
    dx0[dm:] = np.eye(n)
    return dAp, dBp, dC, dDp, dx0


#: Where :func:`refine_gain` stops: the Gauss-Newton decrement below this fraction of
#: ``d / (2N)`` (:func:`subid.methods.dt._pe_search.statistical_precision`). K serves the
#: one-step predictor, not the parameter covariance (which a simulation-focus model
#: computes for A, B, C, D alone): a gain within half an estimation standard deviation
#: of the minimum adds at most a quarter of ``d / (2N)`` to the expected prediction
#: error (the argument of the fold models' stop, :func:`subid.methods.dt.pem.refine`);
#: on long records the state-sequence gain is already there and the step costs one
#: Jacobian.
GAIN_PRECISION = 0.25


def refine_gain(data, model, *, precision: float = GAIN_PRECISION,
                max_iterations: int = MAX_ITERATIONS, tolerance: float = TOLERANCE):
    """``model`` with ``K`` re-estimated by prediction error, A, B, C, D fixed.

    Parameters
    ----------
    data : IOData
        The estimation record (several experiments: each predicted from its own
        initial state).
    model : StateSpace
        Discrete-time model with a Kalman gain whose predictor ``A - K C`` is stable
        (the start); returned unchanged otherwise, or when the record has no more
        output samples than twice the free parameters.
    precision : float
        Stop where the Gauss-Newton decrement is below this fraction of ``d / (2N)``
        (:func:`subid.methods.dt._pe_search.statistical_precision`).
    max_iterations, tolerance
        Of the iteration, as in :func:`subid.pem`.

    Returns
    -------
    StateSpace
        With the gain reached (the start's when nothing improves), ``noise_cov`` the
        sample covariance of its one-step prediction errors, ``info['noise_model']``
        :data:`DESCRIPTION` and ``info['gain_refinement']`` (``samples``: those the
        gain was fitted to, ``start_cost``, ``final_cost``, ``n_evaluations``,
        ``stop_reason``).
    """
    if model.K is None or model.is_continuous:
        return model
    if (delays := input_delay_of(model)) is not None:
        shifted, _ = delay_inputs(data, delays)
        inner = model.with_noise_model(model.K, model.noise_cov,
                                       info={k: v for k, v in model.info.items()
                                             if k != "input_delay"})
        return record_delay(refine_gain(shifted, inner, precision=precision,
                                        max_iterations=max_iterations, tolerance=tolerance),
                            delays)
    A, B, C, D, K0 = (np.array(m, dtype=float) for m in (model.A, model.B, model.C,
                                                          model.D, model.K))
    n, nu, ny = A.shape[0], B.shape[1], C.shape[0]
    N = data.n_samples
    ranges = data.experiment_ranges
    dm = n * ny
    radius = _radius(A - K0 @ C) if n else 0.0
    if n == 0 or N * ny <= 2 * (dm + len(ranges) * n) or radius >= STABILITY_LIMIT:
        return model
    whole = data
    data = selection_part(data)              # the gain from the record's last part
    N, ranges = data.n_samples, data.experiment_ranges
    # the start: its initial states by least squares, its errors' covariance (``own``:
    # the model's noise_cov where the noise model computed it so, on the whole record)
    try:
        x0 = _predictor_initial_states(model, K0, data, radius)
    except SubidError:                      # the start's prediction diverges
        return model
    own = np.array(model.noise_cov, dtype=float) if model.noise_cov is not None and \
        model.info.get("noise_cov_estimate") == FROM_PREDICTION_ERRORS else None
    sigma0 = own if own is not None and data is whole else \
        prediction_error_covariance(model, K0, data, radius, x0)
    if sigma0 is None or float(np.trace(sigma0)) <= NOISE_FREE * max(
            float(np.sum(data.y ** 2)) / N, 1e-300):
        return model                       # noise-free: no innovations, K = 0 stays
    try:
        L0 = np.linalg.cholesky(sigma0)
    except np.linalg.LinAlgError:            # an output predicted exactly
        return model
    W = scipy.linalg.solve_triangular(L0, np.eye(ny), lower=True)
    start_cost = 0.5 * float(np.trace(W @ sigma0 @ W.T))
    directions = _directions(A, C, D, n, nu, ny)

    def gain(z):
        return K0 + z.reshape(n, ny)

    history: list = []
    z, res = minimise_prediction_error(
        lambda z: _predictor(A, B, C, D, gain(z), "prediction"), lambda z: directions,
        dm, x0, np.hstack([data.u, data.y]), data.y, ranges, W, max_iterations, tolerance,
        history, math.sqrt(2.0 * (10.0 * start_cost + 1.0) / (N * ny)),
        decrement_tol=statistical_precision(dm + len(ranges) * n, N, precision))
    info = dict(model.info)
    record = {"samples": N, "start_cost": start_cost, "final_cost": start_cost,
              "n_evaluations": int(res.nfev), "stop_reason": str(res.message)}
    # the covariance of the whole record's errors as every noise model states it
    # (initial states by least squares at the gain; the iteration's own stop at its
    # precision)
    reached = gain(z[:dm])
    reached_radius = _radius(A - reached @ C)
    measured = prediction_error_covariance(model, reached, whole, reached_radius) \
        if res.cost < start_cost and np.any(z[:dm]) else None
    if measured is not None:
        K, sigma, radius = reached, measured, reached_radius
        record["final_cost"] = float(res.cost)
    else:
        K = K0
        sigma = own if own is not None else sigma0 if data is whole else \
            prediction_error_covariance(model, K0, whole, radius)
        if sigma is None:                    # the start's errors diverge on the record
            return model
        record["stop_reason"] = (
            "the start is within the statistical precision of the minimum (Gauss-Newton "
            "decrement below decrement_tol): kept" if res.status == 5 and not np.any(z[:dm])
            else f"no improvement on the start ({res.message}); start kept")
    info["predictor_spectral_radius"] = radius
    info["noise_model"] = DESCRIPTION
    info["noise_cov_estimate"] = FROM_PREDICTION_ERRORS
    info["gain_refinement"] = record
    return model.with_noise_model(K, sigma, info=info)


#: A state-sequence gain is set aside (:func:`checked_gain`) when its one-step errors on
#: the estimation record exceed the simulation errors' by this factor (the geometric mean
#: over the outputs of the covariance ratio, from the determinants): a gain that is
#: clearly no Kalman gain. On the closed-loop DaISy CD_player_arm record the factor was
#: 4-300; a gain estimated where the true one is zero (white output noise: the seed-001
#: plant at 30 dB, 30,000 samples) is worse by its estimation error alone, 0.3 %, and is
#: kept, so that the model is the one a statistic without the samples gives
#: (:func:`subid.identify_file`).
WORSE_THAN_SIMULATION = 1.1


def _log_det(sigma) -> float:
    """``log det sigma`` of a covariance; ``-inf`` where it is singular (an output
    predicted exactly)."""
    sign, value = np.linalg.slogdet(sigma)
    return float(value) if sign > 0 else -math.inf


def checked_gain(data, model):
    """``model`` (a subspace model with its state-sequence noise model,
    :func:`subid.methods.dt.noise_model.attach_noise_model`, on the estimation record
    ``data``), or, when that gain predicts clearly worse than no gain at all, the model
    with the gain fitted by prediction error from ``K = 0`` (:func:`refine_gain`).

    A Kalman predictor never predicts worse than the simulation it corrects, so a gain
    whose one-step errors on the estimation record have a covariance determinant above
    :data:`WORSE_THAN_SIMULATION` ``** ny`` times the simulation errors' (``K = 0``,
    initial states by least squares; a stable A) is not the model's. On the DaISy
    CD_player_arm record (closed loop; ``moesp`` at order 4 on the first 70 %) the
    state-sequence gain's errors had variances 0.89 and 0.19 on the last 30 % against
    0.011 and 0.019 for the simulation, and ``noise_cov`` exceeded the outputs' variances
    tenfold. ``info['noise_model_rejected']`` records the gain set aside (its and the
    simulation's error covariances); the gain reached is at least as good as ``K = 0``
    on the record (:func:`refine_gain` keeps its start otherwise).
    """
    if model.K is None or model.info.get("noise_cov_estimate") != FROM_PREDICTION_ERRORS \
            or not model.order:
        return model
    radius = _radius(model.A)
    if radius >= 1.0:                  # the simulation is no predictor: nothing to compare
        return model
    K0 = np.zeros((model.order, model.n_outputs))
    # both on the record's last part as the order selection reads it (a pass over 10^6
    # samples cost 12 % of moesp(data) there); the gain's own covariance is the whole
    # record's when that is the part
    part = selection_part(data)
    simulation = prediction_error_covariance(model, K0, part, radius)
    measured = np.asarray(model.noise_cov, dtype=float) if part is data else \
        prediction_error_covariance(model, model.K, part, _radius(model.A - model.K @ model.C))
    if simulation is None or measured is None or not _log_det(measured) > \
            _log_det(simulation) + model.n_outputs * math.log(WORSE_THAN_SIMULATION):
        return model
    info = dict(model.info, predictor_spectral_radius=radius, noise_model_rejected={
        "noise_model": model.info.get("noise_model"),
        "prediction_error_cov": measured, "simulation_error_cov": simulation,
        "reason": "its one-step prediction errors on the estimation record have a larger "
                  f"covariance (determinant, over {WORSE_THAN_SIMULATION:g} ** ny) than the "
                  "simulation errors (K = 0): the gain was fitted by prediction error from "
                  "K = 0 instead"})
    return refine_gain(data, model.with_noise_model(K0, simulation, info=info))
