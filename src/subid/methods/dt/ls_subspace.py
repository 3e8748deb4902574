"""SVD-free least-squares subspace identification (seed 001).

Bako, Mercère, Lecoeuche, "A least squares approach to the subspace
identification problem". A user-chosen selector matrix Λ (``selector``,
n x horizon*ny) fixes the state basis by the constraint ``Λ Γ̄ = I``; the
extended observability matrix Γ̄ then follows from a linear least-squares
problem, eq. (23) without instruments and eq. (28) with past inputs and
outputs (29) as instruments. A and C follow by shift invariance, B, D and
x0 by linear least squares on the output. No SVD is computed anywhere.

Numerics (notation of the paper, future block rows Y = Y_{f+1,f,N},
U = U_{f+1,f,N}; instruments Z = [U_{1,f,N}; Y_{1,f,N}]):

* The LQ factorisation ``[U; Z; Y] = L Q^T`` gives ``Y Π_U^⊥ Z^T = L32 L22^T``
  and, without instruments, ``[U; Y] = L Q^T`` gives ``Y Π_U^⊥ = L22 Q2^T``.
  Eq. (23), ``Γ̄ = Y Π_U^⊥ (Λ Y Π_U^⊥)^†``, becomes ``Γ̄ = L22 (Λ L22)^†``
  (``Q2`` has orthonormal columns); eq. (28) is the least-squares solution of
  ``W = Γ̄ Λ W`` with ``W = L32 L22^T`` (the paper's instrument correlation).
* Beyond the paper, two SVD-free refinements (both can be switched off):

  - ``instrument_weighting=True`` uses ``W = L32`` instead, i.e. the
    instrument correlation right-multiplied by ``(Z Π_U^⊥ Z^T)^{-1/2}``
    (``L22^{-T}``, a Cholesky factor, not an SVD). This is the weighting of
    PO-MOESP: it whitens the instruments so that no instrument direction
    dominates the fit because of its scale.
  - ``power_iterations=k`` re-solves the least-squares problem k times with
    the selector taken from the previous estimate (Λ_k = orthonormal basis
    of the previous Γ̄, by QR). Each step maps range(Γ̄) to
    range(W W^T Λ_k^T), so this is orthogonal (power) iteration towards the
    dominant n-dimensional left singular subspace of W, the subspace an SVD
    would give, at the rate (σ_{n+1}/σ_n)^2 per step, while computing no SVD.
    The result is finally expressed in the basis of the user's Λ,
    ``Γ̄ = G (Λ G)^{-1}``; noise-free, range(G) = range(Γ_f) for every k, so
    the basis fixed by Λ is exactly the paper's.

* Order estimation (Remark 2): with a square random Λ, the pivots of the
  Cholesky factorisation of ``Σ = Λ W W^T Λ^T`` (computed without forming Σ,
  as the diagonal of the R factor of ``(Λ W)^T``) are the square roots of
  ``det Σ(1:r,1:r) / det Σ(1:r-1,1:r-1)``. They drop to rounding level after
  r = n on noise-free data; the order is taken at the largest drop.
"""

from __future__ import annotations

import numbers
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from subid._blas import serial_blas
from subid._validation import (
    check_bool,
    check_choice,
    check_seed,
    check_selector,
    checked_call,
)
from subid.errors import OptionError, OrderError
from subid.methods.bd import BATCH_OPTIONS
from subid.methods.dt._subspace import (
    check_system_matrices,
    choose_order,
    least_squares_gelsy,
    shift_invariance,
)
from subid.methods.dt.feedthrough import check_feedthrough
from subid.methods.dt.n4sid import state_model
from subid.methods.dt.pipeline import Shift, States, Subspace, SubspaceMethod, run
from subid.model.statespace import StateSpace

__all__ = ["ls_subspace", "random_selector"]


def random_selector(horizon: int, n_outputs: int, seed=0, rows: int | None = None) -> np.ndarray:
    """The selector Λ drawn when none is given.

    Entries are uniform on [-1, 1] (Proposition 3 of seed 001: rank(ΛΓ) = n
    with probability one). The full square matrix (horizon*ny rows) is drawn
    and its first ``rows`` rows returned, so that a model of order n always
    uses the same Λ whether the order was given or estimated (Remark 2).
    """
    size = horizon * n_outputs
    full = np.random.default_rng(check_seed(seed)).uniform(-1.0, 1.0, size=(size, size))
    return full if rows is None else full[:rows].copy()


def _solve_gamma(W: np.ndarray, selector: np.ndarray) -> np.ndarray:
    """Least-squares Γ̄ of ``W ≈ Γ̄ (Λ W)``: ``Γ̄ = W (Λ W)^†`` (QR, no SVD)."""
    return least_squares_gelsy((selector @ W).T, W.T).T


def _condition_1norm(M: np.ndarray) -> float:
    """1-norm condition estimate of a square matrix via LU (no SVD)."""
    with warnings.catch_warnings():   # a singular M is the case this function reports
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        lu, _ = scipy.linalg.lu_factor(M, check_finite=False)
    anorm = np.abs(M).sum(axis=0).max()
    rcond = scipy.linalg.lapack.dgecon(lu, anorm, norm="1")[0]
    return float(1.0 / rcond) if rcond > 0 else float("inf")


@serial_blas
@checked_call
def ls_subspace(data, order=None, *, horizon=None, instruments="past", selector=None, seed=0,
                estimate_x0=True, feedthrough="auto", instrument_weighting=True,
                power_iterations=8, normalize_outputs=True, selection="cv",
                stability="auto", system_matrices="auto", bd_method="auto",
                statistic="auto", refine=None, input_delay=0) -> StateSpace:
    """Identify a discrete-time state-space model without SVD (seed 001).

    Parameters
    ----------
    data : IOData or HankelStatistic
        Uniformly sampled input/output record, or its statistic
        (:class:`subid.HankelStatistic`, depth ``2*horizon`` with instruments,
        ``horizon`` without): identification then uses the statistic only.
    order : int, None, 'auto' or iterable of int
        Model order n. ``None`` (or ``'auto'``) chooses it by ``selection``:
        among 1..10 (as far as the horizon allows) and on past 10 while the best
        is among the last orders tried (:mod:`subid.methods.dt.selection`); an
        iterable gives the candidate orders.
    horizon : int, optional
        Future horizon f (block rows of Y); the instruments use f past block
        rows too. Default: implied by ``selector`` when one is given; else
        chosen with the order among 10 and 20 (as far as the record allows)
        by ``selection``; with ``selection='gap'``, 10 (or what the record
        allows).
    instruments : {'past', None}
        ``'past'``: eq. (28) with past inputs and outputs (29) as
        instruments, consistent under process and measurement noise.
        ``None``: eq. (23), exact on noise-free data, biased under noise.
    selector : array_like, optional
        The matrix Λ (n x horizon*ny; more rows are allowed, the first n are
        used). It fixes the state basis: ``Λ Γ̄ = I``. Two records of the same
        system identified with the same Λ give the same matrices. Default: a
        uniform random matrix drawn from ``seed`` (:func:`random_selector`).
    seed : int
        Seed of the random selector (ignored when ``selector`` is given).
    estimate_x0 : bool
        Estimate the initial state with B and D (stored in ``info['x0']``).
    feedthrough : {'auto', True, False}
        Estimate D (``False``: D = 0). ``'auto'`` (default): D only when the
        data show a direct term (an F-test of u(k) in a high-order ARX
        regression on the Hankel rows) and no feedback (past outputs do not
        help predict the input), as MATLAB estimates no feedthrough unless
        asked: a free D absorbs the correlation of u(k) and the noise in
        closed loop (:mod:`subid.methods.dt.feedthrough`;
        ``info['feedthrough']`` records the tests).
    instrument_weighting : bool
        Whiten the instrument correlation (``W = L32``, PO-MOESP weighting)
        instead of the paper's ``W = Y Π_U^⊥ Z^T`` of eq. (28).
    power_iterations : int
        SVD-free refinement steps with Λ taken from the previous estimate;
        0 gives the paper's one-shot estimate; at most 100.
    normalize_outputs : bool
        Divide each output by its RMS before the least-squares problems (the
        selector then acts as ``Λ (I ⊗ S)`` on the normalised outputs, so the
        basis it fixes is unchanged), so that the estimate does not depend
        on the output units. ``False`` solves eq. (23)/(28) in the user's
        units, as printed in the paper.
    selection : {'cv', 'gap'}
        How an order or horizon not given is chosen: ``'cv'`` by
        cross-validated simulation fit on the estimation data
        (:mod:`subid.methods.dt.selection`); ``'gap'`` at the largest gap of the
        SVD-free rank profile of Remark 2 (``info['rank_profile']``).
        ``info['order_selection']`` holds every candidate with its score.
    stability : {'auto', 'enforce', 'none'}
        ``'auto'``: an unstable A is made stable when the data do not grow
        (:func:`subid.methods.dt._stability.stability_request`), by regularised shift
        invariance, then B, D and x0 are refitted; ``'enforce'``: always;
        ``'none'``: never. ``info['stability']`` says what was done.
    system_matrices : {'auto', 'shift', 'states'}
        How A, B, C, D follow from the estimated Γ̄. ``'shift'``: A and C by
        shift invariance (the paper), B, D, x0 by ``bd_method``. ``'states'``
        (with instruments only): the state sequence ``X = Γ̄^† O`` with ``O``
        the oblique projection of the future outputs on the past data, and
        ``[A B; C D]`` by least squares on it (:func:`subid.n4sid`'s step,
        QR-based, still SVD-free; the basis is still the one Λ fixes).
        ``'auto'`` (default): as in :func:`subid.moesp` (on records of up to
        20,000 samples, the one whose model fits the whole record better at
        the order and horizon used, given or cross-validated, with no fold
        fits; ``'shift'`` otherwise). ``info['system_matrices']`` names the
        one used.
    bd_method : {'auto', 'simulation', 'projection'}
        How B, D (and x0) are found given A and C: least squares on the raw
        output samples through the model (``'simulation'``, most accurate,
        overflows for a clearly unstable A), or the projected data equation on
        the statistic (``'projection'``, no simulation, no x0). The output
        regression weights each output by the inverse of its standard
        deviation, so that the fit does not depend on the output units. ``'auto'``:
        simulation, and projection when simulating the identified model
        overflows or leaves the regression numerically singular (always
        projection when ``data`` is a statistic); for an unstable A that is
        kept, the prediction-error form of the regression with the Kalman
        gain of the noise model (:func:`subid.methods.dt._subspace.b_d_refit`),
        which stays well posed where simulating the model does not.
    statistic : {'auto', 'qr', 'gram'}
        How the data are reduced (:mod:`subid.statistic.hankel`): QR factor of the
        Hankel matrix (accurate to rounding) or lagged products (25x faster,
        squares the condition number). ``'auto'``: the lagged products where
        they are exact to rounding (a Hankel matrix of condition number up to
        1e4, e.g. noisy data), else QR up to 200,000 samples
        (:meth:`subid.HankelStatistic.from_data`).
    refine : {None, 'simulation', 'prediction'}
        Refine the final subspace estimate by prediction-error minimisation
        (:func:`subid.pem`) on the record with that ``focus``:
        ``'simulation'`` (output error, K re-estimated afterwards: the better
        simulator), ``'prediction'`` (the innovation form: the better one-step
        predictor). ``'pem'`` is a deprecated alias of ``'prediction'``. An
        unstable start cannot be refined by simulation: the model is then
        returned unrefined with a warning. :func:`subid.identify` keeps a
        refinement only where it validates better.
    input_delay : int or sequence of int
        Dead time of each input in samples (:func:`subid.estimate_delay`):
        the model is identified from the delayed inputs and records the
        delays in ``info['input_delay']``; ``simulate`` and ``freqresp``
        honour them.

    Returns
    -------
    StateSpace
        Discrete-time model with ``dt = data.dt`` in the basis fixed by Λ.
        ``info`` holds ``selector`` (reuse it to identify other records in the
        same basis), ``rank_profile``, ``horizon``, ``order``,
        ``order_selection``, ``x0``, ``shift_residual``, ``selector_condition``,
        ``input_condition``, ``residual_rms``, ``regression_condition``.

    Raises
    ------
    subid.errors.DataError
        Non-uniform sampling, constant output.
    subid.errors.TooFewSamplesError, subid.errors.NotExcitingError,
    subid.errors.OrderError

    Examples
    --------
    >>> import subid
    >>> true = subid.systems.seed001_system()
    >>> data = subid.systems.simulate_data(true, 500, seed=1)
    >>> model = subid.ls_subspace(data, order=3)
    >>> subid.markov_error(model, true) < 1e-9
    True
    """
    method = LSSubspace(instruments=instruments, selector=selector, seed=seed,
                        estimate_x0=estimate_x0, feedthrough=feedthrough,
                        instrument_weighting=instrument_weighting,
                        power_iterations=power_iterations, normalize_outputs=normalize_outputs,
                        stability=stability, system_matrices=system_matrices,
                        bd_method=bd_method)
    if selector is not None and horizon is None:
        horizon = selector_horizon(selector, data)
    return run(method, data, order, horizon, selection=selection, statistic=statistic,
               refine=refine, input_delay=input_delay)


def selector_horizon(selector, data) -> int:
    """The horizon a user's selector implies (its columns are horizon * n_outputs)."""
    ny = getattr(data, "n_outputs", None)
    cols = np.shape(selector)[-1] if np.ndim(selector) == 2 else None
    if not ny or cols is None or cols % ny:
        raise OrderError(f"selector must be a 2-D array with horizon*n_outputs columns; got "
                         f"shape {np.shape(selector)} for {ny} outputs")
    return cols // ny


class LSSubspace(SubspaceMethod):
    """Seed 001's steps (:class:`subid.methods.dt.pipeline.SubspaceMethod`): the SVD-free
    rank profile, Γ̄ in the basis fixed by Λ, then the system matrices by shift
    invariance or from the state sequence.

    The outputs are normalised by their RMS s (unless ``normalize_outputs=False``), so
    that the estimate does not depend on their units; Λ acts on the user's units, so on
    the normalised data it is Λ_n = Λ (I ⊗ S): then Λ Γ̄ = Λ_n Γ̄_n = I fixes the same
    basis. The default random Λ is drawn for the normalised outputs, and
    ``info['selector']`` holds it in the user's units (Λ = Λ_n (I ⊗ S^{-1})), ready to
    be passed again.
    """

    name = "ls_subspace"

    def __init__(self, *, instruments="past", selector=None, seed=0, estimate_x0=True,
                 feedthrough="auto", instrument_weighting=True, power_iterations=8,
                 normalize_outputs=True, stability="auto", system_matrices="auto",
                 bd_method="auto"):
        self.power_iterations = check_options(instruments, power_iterations)
        feedthrough = check_feedthrough(feedthrough)
        for name, flag in (("estimate_x0", estimate_x0),
                           ("instrument_weighting", instrument_weighting),
                           ("normalize_outputs", normalize_outputs)):
            check_bool(flag, name)
        self.instruments, self.selector, self.seed = instruments, selector, seed
        self.instrument_weighting = instrument_weighting
        self.normalize_outputs = bool(normalize_outputs)
        self.blocks_per_horizon = 2 if instruments == "past" else 1
        check_choice(bd_method, "bd_method", BATCH_OPTIONS)
        check_seed(seed)
        check_system_matrices(system_matrices)
        self.common_options(feedthrough=feedthrough, estimate_x0=estimate_x0,
                            stability=stability, bd_method=bd_method)
        if system_matrices == "states" and instruments != "past":
            raise OptionError("system_matrices='states' needs the past data "
                              "(instruments='past'): the state sequence is the projection "
                              "of the future outputs on them")
        self.estimators = ("shift", "states") \
            if system_matrices == "auto" and self.instruments == "past" else \
            ("shift" if system_matrices == "auto" else system_matrices,)

    def decompose(self, pb, feedthrough) -> Subspace:
        """The weighted instrument correlation W and the SVD-free rank profile of
        Remark 2 (with the user's Λ in the units of the normalised outputs)."""
        selector = check_selector(self.selector, pb.horizon, pb.data.n_outputs,
                                  pb.candidates, pb.order)
        column_scale = np.tile(pb.output_scale, pb.horizon)
        stat = ls_statistic(pb.factor, pb.horizon, instruments=self.instruments,
                            instrument_weighting=self.instrument_weighting,
                            selector=None if selector is None else selector * column_scale,
                            seed=self.seed, cached=pb.cached)
        return Subspace(stat.rank_profile, RANK_PROFILE,
                        parts={"statistic": stat, "column_scale": column_scale})

    def system_matrices(self, pb, subspace, n, estimator, *, feedthrough, ft_record, plan):
        """Γ̄ at order n (:func:`ls_gamma`), then A and C by shift invariance
        (``'shift'``), or the state step of N4SID on Γ̄ (``'states'``)."""
        stat, column_scale = subspace.parts["statistic"], subspace.parts["column_scale"]
        core = ls_gamma(stat, n, power_iterations=self.power_iterations, method=self.name)
        info = core.info(self.instruments, self.instrument_weighting, self.power_iterations)
        info["selector"] = core.selector / column_scale
        if estimator == "states":
            # the state step of N4SID on Γ̄ (in the basis Q), then the basis of Λ (T = Λ Q)
            A_q, B_q, C_q, D, x0_q, extra = state_model(pb, core.basis,
                                                        stability=plan.stability,
                                                        feedthrough=feedthrough,
                                                        estimate_x0=plan.estimate_x0)
            T = core.T
            A = scipy.linalg.solve(T.T, (T @ A_q).T, check_finite=False).T    # T A_q T^{-1}
            C = scipy.linalg.solve(T.T, C_q.T, check_finite=False).T          # C_q T^{-1}
            extra["x0"] = None if x0_q is None else x0_q @ T.T    # T x0_q (rows: experiments)
            return States(A, T @ B_q, C, D, dict(**info, **extra, feedthrough=ft_record))
        return Shift(core.A_q, core.C_q, core.basis, core.L11, core.L_yu, info,
                     parts={"core": core})

    def output_basis(self, estimate, A, B, x0):
        """From the orthonormal basis Q to the basis fixed by Λ."""
        return estimate.parts["core"].to_selector_basis(B, x0, A_q=A)


#: Most ``power_iterations``: each step brings the estimate closer to the dominant
#: subspace by (σ_{n+1}/σ_n)^2, so that even a ratio of 0.9 leaves 1e-9 after 100 steps;
#: beyond, the steps only cost (10^6 of them ran for minutes).
MAX_POWER_ITERATIONS = 100


def check_options(instruments, power_iterations) -> int:
    """Validate the estimator options; returns ``power_iterations`` as int."""
    if instruments not in ("past", None):
        raise OptionError(f"instruments must be 'past' or None, got {instruments!r}")
    if isinstance(power_iterations, bool) or not isinstance(power_iterations, numbers.Integral) \
            or not 0 <= int(power_iterations) <= MAX_POWER_ITERATIONS:
        raise OptionError(f"power_iterations must be an integer from 0 to "
                          f"{MAX_POWER_ITERATIONS} (each step shrinks the distance to the "
                          "SVD's subspace by the squared ratio of singular values: 100 "
                          f"steps have converged), got {power_iterations!r}"[:300])
    return int(power_iterations)


@dataclass(frozen=True)
class LSCore:
    """A and C identified from a data statistic.

    ``A_q, C_q, basis`` are in the orthonormal basis ``Q`` of the estimated
    range(Γ) (well conditioned); ``T = Λ Q`` maps them to the basis fixed by
    Λ: ``A = T A_q T^{-1}``, ``C = C_q T^{-1}``, ``B = T B_q``.
    """

    A_q: np.ndarray
    C_q: np.ndarray
    basis: np.ndarray
    T: np.ndarray
    L11: np.ndarray
    L_yu: np.ndarray
    order: int
    order_selection: dict
    selector: np.ndarray
    rank_profile: np.ndarray
    selector_condition: float
    shift_residual: float

    def to_selector_basis(self, B_q, x0_q=None, A_q=None):
        """``(A, B, C, x0)`` in the basis fixed by Λ from ``B_q`` (and ``x0_q``;
        ``A_q`` replaces the estimated ``self.A_q``, e.g. when made stable)."""
        T = self.T
        A_q = self.A_q if A_q is None else A_q
        A = scipy.linalg.solve(T.T, (T @ A_q).T, check_finite=False).T        # T A_q T^{-1}
        C = scipy.linalg.solve(T.T, self.C_q.T, check_finite=False).T          # C_q T^{-1}
        return A, T @ B_q, C, (None if x0_q is None else x0_q @ T.T)   # rows: experiments

    def info(self, instruments, instrument_weighting, power_iterations) -> dict:
        return dict(instruments=instruments,
                    instrument_weighting=bool(instrument_weighting and instruments == "past"),
                    power_iterations=power_iterations, selector=self.selector,
                    rank_profile=self.rank_profile, selector_condition=self.selector_condition,
                    shift_residual=self.shift_residual)


#: What ``info['order_selection']`` calls the profile of :func:`ls_statistic`.
RANK_PROFILE = "SVD-free rank profile (seed 001, Remark 2)"


@dataclass(frozen=True)
class LSStatistic:
    """What seed 001 needs from a Hankel factor before the order is known: the
    triangular factor ``L`` (``a`` rows of future inputs), the weighted instrument
    correlation ``W``, ``L_yu``, the square selector and the rank profile."""

    L: np.ndarray
    a: int
    W: np.ndarray
    L_yu: np.ndarray
    selector: np.ndarray
    rank_profile: np.ndarray
    n_outputs: int


def ls_statistic(hf, f, *, instruments, instrument_weighting, selector, seed,
                 cached=None) -> LSStatistic:
    """Seed 001 on a Hankel factor up to the order: W (eq. 23 or 28) and the SVD-free
    rank profile of Remark 2 (with a square selector). ``cached``: a problem's
    :meth:`subid.methods.dt._subspace.Problem.cached`, so that the candidate orders of
    one problem share the factorisation of its rows (on 100 inputs and 100 outputs it
    was refactorised for each of 81 candidates, issue 28)."""
    nu, ny = hf.n_inputs, hf.n_outputs
    depth = hf.depth
    uf = hf.u_rows(depth - f, depth)
    yf = hf.y_rows(depth - f, depth)

    def factor():
        if instruments == "past":
            return hf.retriangularize(uf, np.concatenate([hf.u_rows(0, f), hf.y_rows(0, f)]),
                                      yf)
        return hf.retriangularize(uf, yf)
    L = factor() if cached is None else cached(("ls_subspace factor", instruments), factor)
    if instruments == "past":
        a, b = f * nu, f * (nu + ny)
        L22 = L[a:a + b, a:a + b]
        L32 = L[a + b:, a:a + b]
        W = L32 if instrument_weighting else L32 @ L22.T
        L_yu = L[a + b:, :a]
    else:
        a = f * nu
        W = L[a:, a:]
        L_yu = L[a:, :a]

    # Order: SVD-free rank profile (Remark 2) with a square selector.
    full = selector if selector is not None else random_selector(f, ny, seed)
    rank_profile = np.abs(np.diag(scipy.linalg.qr((full @ W).T, mode="r",
                                                  check_finite=False)[0]))
    return LSStatistic(L, a, W, L_yu, full, rank_profile, ny)


def ls_gamma(stat: LSStatistic, n: int, *, power_iterations, method,
             order_selection=None) -> LSCore:
    """Γ̄ at order ``n`` in the basis of Λ (its first n rows), then A and C."""
    Lam = stat.selector[:n]
    W = stat.W
    G = _solve_gamma(W, Lam)
    for _ in range(power_iterations):
        basis = scipy.linalg.qr(G, mode="economic", check_finite=False)[0]
        G = _solve_gamma(W, basis.T)
    LG = Lam @ G
    selector_condition = _condition_1norm(LG)
    if not np.isfinite(selector_condition) or selector_condition > 1e12:
        raise OrderError(f"{method}: the selector Λ is (nearly) blind to the observable "
                         f"subspace (condition of ΛΓ ~{selector_condition:.1e}); order {n} may be "
                         "too high for these data, or choose another selector / seed")
    # Γ̄ = G (ΛG)^{-1} = Q (ΛQ)^{-1} with Q an orthonormal basis of range(G). A and C
    # are computed in the basis Q, where the shift-invariance problem is well
    # conditioned whatever Λ, then mapped with T = ΛQ (least squares is covariant:
    # the result is the same matrix in exact arithmetic, far more accurate when
    # ΛΓ is ill-conditioned).
    Q = scipy.linalg.qr(G, mode="economic", check_finite=False)[0]
    A_q, C_q, shift_residual = shift_invariance(Q, stat.n_outputs)
    a = stat.a
    return LSCore(A_q=A_q, C_q=C_q, basis=Q, T=Lam @ Q, L11=stat.L[:a, :a], L_yu=stat.L_yu,
                  order=n, order_selection=order_selection, selector=Lam,
                  rank_profile=stat.rank_profile, selector_condition=selector_condition,
                  shift_residual=shift_residual)


def gamma_from_factor(hf, f, fixed_order, candidates, *, instruments, instrument_weighting,
                      selector, seed, power_iterations, method) -> LSCore:
    """Seed 001 on a Hankel factor: Γ̄ in the basis of Λ, then A and C
    (:func:`ls_statistic`, the order, :func:`ls_gamma`).

    Used by :class:`subid.RecursiveSubspace` (which updates the same factor sample by
    sample); :func:`ls_subspace` runs the same steps through the pipeline.
    """
    stat = ls_statistic(hf, f, instruments=instruments,
                        instrument_weighting=instrument_weighting, selector=selector,
                        seed=seed)
    n, order_selection = choose_order(fixed_order, candidates, stat.rank_profile,
                                      RANK_PROFILE)
    return ls_gamma(stat, n, power_iterations=power_iterations, method=method,
                    order_selection=order_selection)
