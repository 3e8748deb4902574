"""Refinement of a state-space model on frequency-response data.

:func:`fd_pem` (reached through :func:`subid.pem` with an :class:`subid.FRData`)
minimises the weighted nonlinear least-squares criterion

    V(θ) = 1/2 Σ_k ||W_k ⊙ (G_k - D - C (z_k I - A)^{-1} B)||_F^2

(Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*,
2nd ed., 2012, Ch. 9; McKelvey, "Frequency domain identification methods",
Circuits Systems Signal Process. 21(1), 2002; MATLAB ``ssest`` on ``idfrd``
data), with ``z_k = exp(i w_k dt)`` in discrete time and ``z_k = i w_k`` in
continuous time. ``W`` is the data's ``weights``; without them ``1 / std``;
without either, ``1 / sqrt(v)`` with the noise variance ``v = a + b |G_hat|^2``
(per channel pair) fitted by maximum likelihood to the residuals of the
starting model (:func:`subid.methods.fd._core.variance_model`), so that the
criterion is the Gaussian likelihood of the noise whether it has equal
variance at every frequency, is proportional to the response (a spectral
estimate's) or both; pass ``weights=np.ones(n_freq)`` for the unweighted fit.

Measured (``bench/frequency_acceptance.py``, seed-000 response, 5 % noise, 20
runs from :func:`subid.fd_subspace` at order 4). Under noise proportional to
``|G|``: the relative RMS error ``|G - G_hat| / |G|`` 0.0082 -> 0.0056 (0.0057
with the true noise level as weights), lower in 18 of 20 runs; the maximal
error ``max |G - G_hat| / max |G|`` 0.0052 -> 0.0031, lower in 17 of 20 (as
with the true noise level). Under noise of equal variance: the maximal error
0.0077 -> 0.0052, lower in 17 of 20. The criterion is the likelihood, not the
maximal error, which sits at the low-frequency end where ``|G|`` is largest:
models of nearly equal likelihood can differ there. When fd_subspace weighted
only its SVD by the noise level, 15 of 20 starts under relative noise had a
spurious slow pole near the lowest frequency (the true pair -1.24, -1.68
merged), pem stayed in that local minimum (criterion up to 23 % above the
minimum reached from the true system) and lowered the maximal error in 10 of
20 runs; started from the true system it lowered it in 15.

Parametrisation. Continuous time is scaled in frequency: with α the geometric
mean of the smallest and largest positive frequency,
``(A, B, C) = (α A', sqrt(α) B', sqrt(α) C')`` and the points ``i w_k / α``, so
that the points straddle 1 and the parameters are of order one. The state
basis is then made data-driven: the frequency-domain controllability Gramian
on the measured grid, ``P = Re Σ_k (z_k I - A)^{-1} B B^T (z_k I - A)^{-H}``,
is brought to the identity, again at the start of every round. The search moves in data-driven local coordinates
(McKelvey, Helmersson & Ribarits, Automatica 40, 2004; as :func:`subid.pem` in
the time domain): the orthogonal complement of the ``n^2`` similarity
directions, so the Jacobian has full rank for a minimal model. The Jacobian is
analytic and exact: ``∂G_k = C R_k ∂A R_k B + C R_k ∂B + ∂C R_k B + ∂D`` with
``R_k = (z_k I - A)^{-1}``.

The optimiser is :func:`scipy.optimize.least_squares` (Levenberg-Marquardt;
trust-region reflective when there are fewer residuals than parameters); a
trial model that is unstable where the start is stable gets a cost above the
start's, so the step is rejected. The result never has a cost above the
start's: the start is returned unchanged when nothing improves.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.linalg
import scipy.optimize

from subid._validation import check_optimiser_options, same_period
from subid.delay import frequency_factor, input_delay_of
from subid.errors import (
    DataError,
    ModelError,
    NoiseModelWarning,
    OptionError,
    ResourceLimitError,
)
from subid.frdata import FRData
from subid.methods.fd import _frequency as fq
from subid.methods.fd._core import MIN_NOISE_FREQUENCIES, check_std, variance_model
from subid.model.statespace import StateSpace

__all__ = ["fd_pem"]

#: Entries of the complex Jacobian in θ formed at a time (a block of frequencies).
JACOBIAN_BLOCK_ENTRIES = 4_000_000
#: Largest Jacobian in local coordinates (real and imaginary rows, float64) ``pem`` forms on
#: frequency data; the least-squares search holds a few arrays of its size.
JACOBIAN_BYTES_LIMIT = 2.0**31


def _check(data, model, max_iterations, tolerance, rounds, feedthrough):
    if not isinstance(model, StateSpace):
        raise ModelError(f"pem needs a starting subid.StateSpace, got {type(model).__name__}")
    if (data.n_inputs, data.n_outputs) != (model.n_inputs, model.n_outputs):
        raise DataError(f"the frequency data have {data.n_inputs} inputs and "
                        f"{data.n_outputs} outputs but the model has {model.n_inputs} and "
                        f"{model.n_outputs}")
    if (model.dt == 0) != (data.dt == 0) or (data.dt > 0 and not same_period(model.dt,
                                                                              data.dt)):
        raise DataError(f"the model has dt={model.dt} but the frequency data have "
                        f"dt={data.dt} (0 = continuous time); convert the model first "
                        "(to_discrete / to_continuous)")
    check_optimiser_options(max_iterations, tolerance, rounds)
    check_std(data, "pem")
    if feedthrough is not None and not isinstance(feedthrough, (bool, np.bool_)):
        raise OptionError(f"feedthrough must be True, False or None, got {feedthrough!r}")


def _stable(A, continuous: bool) -> bool:
    lam = np.linalg.eigvals(A)
    return bool(lam.real.max() < 0) if continuous else bool(np.abs(lam).max() < 1 - 1e-9)


def _tangent_complement(A, B, C, with_d: bool) -> np.ndarray:
    """Orthonormal basis of the complement of the similarity directions (DDLC)."""
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    cols = []
    for i in range(n):
        for j in range(n):
            E = np.zeros((n, n))
            E[i, j] = 1.0
            parts = [(E @ A - A @ E).ravel(), (E @ B).ravel(), (-C @ E).ravel()]
            if with_d:
                parts.append(np.zeros(p * m))
            cols.append(np.concatenate(parts))
    T = np.array(cols).T                                           # (n_par, n^2)
    U, s, _ = np.linalg.svd(T, full_matrices=True)
    rank = int(np.sum(s > s[0] * 1e-10)) if s.size and s[0] > 0 else 0
    return U[:, rank:]


def _gramian_basis(A, B, z) -> np.ndarray:
    """T with ``T P T^T = I`` for the frequency-grid Gramian P (identity if P is singular)."""
    n = A.shape[0]
    X = np.linalg.solve(z[:, None, None] * np.eye(n) - A,
                        np.broadcast_to(B.astype(complex), (z.size,) + B.shape))
    P = np.einsum("kim,kjm->ij", X, X.conj()).real / z.size
    try:
        L = np.linalg.cholesky(P)
        if np.linalg.cond(L) < 1e10:
            return scipy.linalg.solve_triangular(L, np.eye(n), lower=True)
    except np.linalg.LinAlgError:
        pass
    return np.eye(n)


class _Criterion:
    """Residuals and exact Jacobian of the weighted response error."""

    def __init__(self, G, z, weights, factor, with_d, D0, continuous):
        self.G, self.z, self.W, self.F = G, z, weights, factor
        self.with_d, self.D0, self.continuous = with_d, D0, continuous
        self.M, self.p, self.m = G.shape

    def unpack(self, theta, n):
        p, m = self.p, self.m
        A = theta[:n * n].reshape(n, n)
        B = theta[n * n:n * n + n * m].reshape(n, m)
        C = theta[n * n + n * m:n * n + n * m + p * n].reshape(p, n)
        D = theta[n * n + n * m + p * n:].reshape(p, m) if self.with_d else self.D0
        return A, B, C, D

    def pack(self, A, B, C, D):
        parts = [A.ravel(), B.ravel(), C.ravel()] + ([D.ravel()] if self.with_d else [])
        return np.concatenate(parts)

    def parts(self, A, B, C):
        n = A.shape[0]
        R = np.linalg.inv(self.z[:, None, None] * np.eye(n) - A)   # (M, n, n), n small
        return R @ B, C @ R                                         # (M, n, m), (M, p, n)

    def residual(self, A, B, C, D):
        RB, _ = self.parts(A, B, C)
        G_hat = (C @ RB + D) * self.F
        e = self.W * (self.G - G_hat)
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    def jacobian(self, A, B, C, basis):
        """``d(residual)/dθ @ basis`` (real and imaginary rows, as :meth:`residual`), the
        full complex Jacobian in θ (``M p m`` x ``n² + n m + p n (+ p m)``) formed a block
        of frequencies at a time (:data:`JACOBIAN_BLOCK_ENTRIES`) and projected at once:
        8 x 8 at order 16 held 6 GB at 2,000 frequencies and failed at 10,000."""
        M, p, m = self.M, self.p, self.m
        n = A.shape[0]
        RB, CR = self.parts(A, B, C)
        WF = -(self.W * self.F)                                     # d(residual)/dG_hat
        P = n * n + n * m + p * n + (p * m if self.with_d else 0)
        out = np.empty((2, M, p, m, basis.shape[1]))
        step = max(1, JACOBIAN_BLOCK_ENTRIES // (p * m * P))
        for a in range(0, M, step):
            b = min(a + step, M)
            k = b - a
            blocks = [np.einsum("kia,kbj->kijab", CR[a:b], RB[a:b]).reshape(k, p, m, n * n),
                      np.einsum("kia,jb->kijab", CR[a:b], np.eye(m)).reshape(k, p, m, n * m),
                      np.einsum("ia,kbj->kijab", np.eye(p), RB[a:b]).reshape(k, p, m, p * n)]
            if self.with_d:
                blocks.append(np.einsum("ia,jb->ijab", np.eye(p), np.eye(m))
                              .reshape(1, p, m, p * m).repeat(k, axis=0))
            J = np.concatenate(blocks, axis=3) * WF[a:b, ..., None]
            projected = J.reshape(k * p * m, P) @ basis
            out[0, a:b] = projected.real.reshape(k, p, m, -1)
            out[1, a:b] = projected.imag.reshape(k, p, m, -1)
        return out.reshape(2 * M * p * m, basis.shape[1])


def _round(crit: _Criterion, A, B, C, D, max_nfev, tolerance, start_residual, history,
           require_stable):
    n = A.shape[0]
    theta0 = crit.pack(A, B, C, D)
    basis = _tangent_complement(A, B, C, crit.with_d)

    def fun(x):
        Ax, Bx, Cx, Dx = crit.unpack(theta0 + basis @ x, n)
        if require_stable and not _stable(Ax, crit.continuous):
            return 2.0 * start_residual
        with np.errstate(all="ignore"):
            r = crit.residual(Ax, Bx, Cx, Dx)
        if not np.isfinite(r).all():
            return 2.0 * start_residual
        history.append(0.5 * float(r @ r))
        return r

    def jac(x):
        Ax, Bx, Cx, _ = crit.unpack(theta0 + basis @ x, n)
        with np.errstate(all="ignore"):
            J = crit.jacobian(Ax, Bx, Cx, basis)
        return np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        # Levenberg-Marquardt (MINPACK) needs at least as many residuals as parameters
        method = "lm" if 2 * crit.M * crit.p * crit.m >= basis.shape[1] else "trf"
        res = scipy.optimize.least_squares(fun, np.zeros(basis.shape[1]), jac=jac,
                                           method=method, x_scale="jac", ftol=tolerance,
                                           xtol=tolerance, gtol=tolerance, max_nfev=max_nfev)
    return crit.unpack(theta0 + basis @ res.x, n), res


def _criterion_weights(data: FRData, start_response):
    """The weights of the criterion, what they are and the fitted noise model.

    The data's ``weights``; else ``1 / std``; else ``1 / sqrt(v)`` with the
    noise variance ``v = a + b |G_hat|^2`` per channel pair fitted by maximum
    likelihood to the residuals of the starting model ``G - G_hat``
    (:func:`subid.methods.fd._core.variance_model`): with weights equal to the
    inverse noise standard deviation the criterion is the Gaussian likelihood
    (Pintelon & Schoukens 2012, Ch. 9), for noise of equal variance (``b = 0``),
    proportional to the response (``a = 0``, a spectral estimate's) or both.
    The start must be a consistent estimate (e.g. :func:`subid.fd_subspace`'s);
    for another start give ``std`` or ``weights``.
    """
    if data.weights is not None:
        return data.fit_weights(), "the data's weights", None
    if data.std is not None:
        std = np.maximum(data.std, 1e-12 * max(float(data.std.max()), 1e-300))
        return 1.0 / std, "1 / std", None
    G = data.response
    ones = np.ones(G.shape)
    if G.shape[0] < MIN_NOISE_FREQUENCIES:
        return ones, "none (too few frequencies to estimate the noise level)", None
    if math.sqrt(np.mean(np.abs(G - start_response) ** 2)) \
            <= 1e-9 * math.sqrt(np.mean(np.abs(G) ** 2)):
        return ones, "none (the start fits the data to rounding)", None
    var, coef = variance_model(G, start_response)
    return 1.0 / np.sqrt(var), ("1 / estimated noise level (a + b |G|^2 per channel pair, "
                                "fitted to the start's residuals)"), coef


def fd_pem(data, model, *, max_iterations=100, tolerance=1e-8, rounds=3, feedthrough=None):
    """Refine ``model`` on frequency-response data by weighted nonlinear least squares.

    Parameters
    ----------
    data : FRData
        The measured response. Its ``weights`` weight the fit; without them
        ``1 / std``, else the inverse of the noise level estimated from the
        start's residuals (see the module documentation).
    model : StateSpace
        Starting model with the data's time base (``dt``), e.g. from
        :func:`subid.fd_subspace`.
    max_iterations : int
        Bound on the criterion evaluations per round.
    tolerance : float
        ``ftol = xtol = gtol`` of :func:`scipy.optimize.least_squares`.
    rounds : int
        Rounds of local coordinates rebuilt at the current model.
    feedthrough : bool, optional
        Estimate D. Default: when the starting D is not identically zero.

    Returns
    -------
    StateSpace
        The refined model in the state basis of the search (unit
        frequency-grid controllability Gramian at the start of its last
        round; the start is returned unchanged when nothing improves), without
        a noise model (frequency-response data say nothing about it). ``info``
        is the start's, updated with ``refined_by`` ('pem'), ``criterion``
        ('frequency response'), ``weighting`` (which weights),
        ``noise_variance_model`` (the estimated ``a``, ``b``, each (ny, nu),
        when the weights were estimated), ``start_cost``,
        ``final_cost`` (the weighted criterion),
        ``cost_history``, ``stop_reason``, ``n_evaluations``,
        ``parametrisation``, ``frequency_scale`` and, in discrete time,
        ``parameter_covariance`` (the asymptotic covariance that
        :func:`subid.parameter_covariance` and the confidence bounds read).

    Raises
    ------
    DataError
        Channels or time base of data and model differ.
    ModelError
        ``model`` is not a StateSpace.
    OptionError
        Bad option values.
    """
    if not isinstance(data, FRData):
        raise DataError(f"fd_pem expects a subid.FRData, got {type(data).__name__}")
    _check(data, model, max_iterations, tolerance, rounds, feedthrough)
    continuous = data.dt == 0
    with_d = bool(np.any(model.D)) if feedthrough is None else bool(feedthrough)
    n, m, p = model.order, data.n_inputs, data.n_outputs
    need = 16.0 * data.n_frequencies * p * m * (n * (m + p) + (p * m if with_d else 0))
    if need > JACOBIAN_BYTES_LIMIT:       # before a raw numpy MemoryError mid-search
        raise ResourceLimitError(
            f"pem on {data.n_frequencies} frequencies of a {p} x {m} response at order {n} "
            f"forms a Jacobian of {need / 2**30:.3g} GiB (limit "
            f"{JACOBIAN_BYTES_LIMIT / 2**30:g} GiB); use fewer frequencies (every k-th, or "
            "the band of interest), refine a few input/output pairs at a time, or keep the "
            "fd_subspace model")
    alpha = fq.frequency_scale(data.w) if continuous else 1.0
    z = fq.points(data.w, data.dt) / (alpha if continuous else 1.0)
    delays = input_delay_of(model)
    factor = np.ones((1, 1, data.n_inputs)) if delays is None or continuous \
        else frequency_factor(delays, data.w, data.dt)
    D0 = np.zeros_like(model.D) if not with_d else model.D
    s = math.sqrt(alpha)
    A, B, C = model.A / alpha, model.B / s, model.C / s
    plain = _Criterion(data.response, z, np.ones(data.response.shape), factor, with_d, D0,
                       continuous)
    r0 = plain.residual(A, B, C, D0)
    start_response = data.response - (r0[:r0.size // 2]
                                      + 1j * r0[r0.size // 2:]).reshape(data.response.shape)
    weights, weighting, noise_coef = _criterion_weights(data, start_response)
    crit = _Criterion(data.response, z, weights, factor, with_d, D0, continuous)
    T = _gramian_basis(A, B, z)
    Tinv = np.linalg.solve(T, np.eye(A.shape[0]))
    cur = (T @ A @ Tinv, T @ B, C @ Tinv, D0)
    r_start = crit.residual(*cur)
    # the start's own cost (its D even when D is not estimated: then D0 = 0 is the start)
    start_cost = 0.5 * float(r_start @ r_start)
    require_stable = _stable(cur[0], continuous)
    history = [start_cost]
    best_cost, n_eval = start_cost, 0
    exact = start_cost <= 1e-30 * max(float(np.sum(np.abs(crit.W * data.response) ** 2)),
                                      1e-300)
    stop_reason = "the start fits the data to rounding (noise-free): kept unchanged"
    if not exact:
        for _ in range(rounds):
            # each round in the Gramian-balanced basis of the current model
            Tr = _gramian_basis(cur[0], cur[1], z)
            Tr_inv = np.linalg.solve(Tr, np.eye(Tr.shape[0]))
            cur = (Tr @ cur[0] @ Tr_inv, Tr @ cur[1], cur[2] @ Tr_inv, cur[3])
            new, res = _round(crit, *cur, max_iterations, tolerance, r_start, history,
                              require_stable)
            n_eval += int(res.nfev)
            stop_reason = str(res.message)
            if not res.cost < best_cost:
                break
            gain = (best_cost - res.cost) / max(best_cost, 1e-300)
            cur, best_cost = new, float(res.cost)
            if gain < tolerance:
                break
    accepted = [start_cost]
    for h in history[1:] + [best_cost]:
        if h < accepted[-1]:
            accepted.append(h)
    info = dict(model.info)
    info.pop("noise_variance_model", None)
    if noise_coef is not None:
        info["noise_variance_model"] = {"a": noise_coef[..., 0], "b": noise_coef[..., 1]}
    info.update(refined_by="pem", criterion="frequency response", weighting=weighting,
                start_cost=start_cost,
                final_cost=min(best_cost, accepted[-1]), cost_history=np.array(accepted),
                stop_reason=stop_reason, n_evaluations=n_eval,
                frequency_scale=alpha if continuous else None,
                parametrisation="data-driven local coordinates (McKelvey et al. 2004) in a "
                                "basis with unit frequency-grid controllability Gramian"
                                + (", frequency scaled by alpha" if continuous else ""))
    if model.K is not None:
        warnings.warn("pem on frequency-response data refines the deterministic part only; "
                      "the starting model's noise model (K, noise_cov) is dropped",
                      NoiseModelWarning, stacklevel=3)
    if not best_cost < start_cost:
        if not exact:
            info["stop_reason"] = f"no improvement on the start ({stop_reason}); start kept"
        info["final_cost"] = start_cost
        return StateSpace(model.A, model.B, model.C, D0, model.dt,
                          input_names=model.input_names, output_names=model.output_names,
                          info=info, hold=model.hold)
    # the result in the basis of the last round (unit frequency-grid Gramian), not
    # the start's: the accumulated transformation back to the start's basis can be
    # ill-conditioned (a pole that moved far, cond 1e7 measured), and applying it
    # lost the fit (criterion 408 in the balanced basis, 426 after it)
    A, B, C, D = cur
    A, B, C = A * alpha, B * s, C * s
    if not continuous:
        _attach_covariance(info, crit, A, B, C, D)
    return StateSpace(A, B, C, D, model.dt, input_names=model.input_names,
                      output_names=model.output_names, info=info, hold=model.hold)


def _attach_covariance(info, crit: "_Criterion", A, B, C, D) -> None:
    """``info['parameter_covariance']`` of a discrete-time estimate, in the format of
    :func:`subid.parameter_covariance`: the asymptotic covariance of weighted least
    squares, ``σ² (J^T J)^-1`` in the local coordinates of the estimate (``J`` the
    Jacobian of the weighted residuals, real and imaginary parts; ``σ²`` the
    residual variance ``r^T r / (2 M p m - d)``), mapped to θ = (A, B, C[, D])
    (Pintelon & Schoukens 2012, Sec. 9.4). From QR of the column-scaled Jacobian;
    a rank-deficient one (a non-minimal model) gives a note instead."""
    basis = _tangent_complement(A, B, C, crit.with_d)
    J = crit.jacobian(A, B, C, basis)
    r = crit.residual(A, B, C, D)
    dof = r.size - basis.shape[1]
    scale = np.linalg.norm(J, axis=0)
    if dof <= 0 or not (np.isfinite(scale).all() and scale.min() > 0):
        info["parameter_covariance_note"] = "no parameter covariance: too few frequencies"
        return
    R = np.asarray(np.linalg.qr(J / scale, mode="r"))     # mode="r": R alone
    diag = np.abs(np.diag(R))
    if diag.min() <= 1e-9 * diag.max():
        info["parameter_covariance_note"] = (
            "no parameter covariance: the Jacobian at the estimate is rank deficient "
            "(a non-minimal model or frequencies that do not excite it)")
        return
    sigma = math.sqrt(float(r @ r) / dof)
    inv = scipy.linalg.solve_triangular(R, np.eye(R.shape[0]), check_finite=False)
    info["parameter_covariance"] = {
        "parameters": crit.pack(A, B, C, D),
        "factor": basis @ (inv / scale[:, None]) * sigma,
        "with_feedthrough": crit.with_d,
        "with_gain": False,
        "noise_cov": None,
        "n_frequencies": crit.M,
        "method": "asymptotic covariance of weighted least squares on the frequency "
                  "response, sigma^2 (J^T J)^-1 in data-driven local coordinates",
    }
