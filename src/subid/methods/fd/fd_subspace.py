"""Subspace identification from frequency-response data.

McKelvey, Akçay & Ljung, "Subspace-based multivariable system identification
from frequency response data", IEEE TAC 41(7), 1996, Algorithm 2 (arbitrary
frequency spacing). With ``z_k`` the points on the unit circle and ``G_k`` the
measured ``p x m`` responses, the block rows ``z_k^r G_k`` (r = 0..q-1) obey

    Y = O_q X + Γ_q W,   Y = [W_1 ⊗ G_1 ... W_M ⊗ G_M],
                         W = [W_1 ⊗ I_m ... W_M ⊗ I_m],   W_k = [1, z_k, ..., z_k^{q-1}]^T,

with ``X = [(z_1 I - A)^{-1} B ... (z_M I - A)^{-1} B]``, ``O_q`` the extended
observability matrix and ``Γ_q`` the lower block-triangular Toeplitz matrix of
the Markov parameters (``z^r (z I - A)^{-1} = A^r (z I - A)^{-1} + sum_{l<r}
z^{r-1-l} A^l``). Real and imaginary parts are stacked side by side (a real
system's response at ``-w`` is the conjugate of that at ``w``), ``W`` is
projected out by an LQ factorisation of ``[W; Y]``, and the ``n`` leading left
singular vectors of the projected ``Y``, weighted by the inverse Cholesky factor
of the noise covariance of its rows (the covariance-weighted variant of the
algorithm), span ``O_q``. A and C follow by shift invariance, B and D by linear
least squares on the response. The relations were derived here and checked
numerically (no equation numbers are quoted: the paper's text was not at hand);
noise-free, the model is exact to rounding (1.7e-15 relative on the seed-000 and
2.1e-15 on the seed-001 responses, ``tests/test_frequency.py``).

Continuous time. The points ``i w`` make ``W`` a Vandermonde matrix with
entries up to ``w_max^{q-1}``, useless on wide ranges (``[0.01, 100]`` rad/s and
q = 6: a condition number beyond 1e20). Instead the frequency-scaled bilinear
map ``z = (α + i w)/(α - i w)`` (the route the paper suggests for
continuous-time data, with a frequency scaling chosen here) sends the frequencies onto the unit circle, ``w -> 2
arctan(w/α)``, with α the geometric mean of the smallest and largest positive
frequency (sent to pi/2), so that a range of decades spreads over (0, pi); the
discrete-time subspace step runs there, ``(A, C)`` are mapped back exactly
(:func:`subid.methods.fd._frequency.bilinear_to_ct`), and B, D are estimated by
least squares on the continuous-time response itself. Stability is preserved
by the map (``|z| < 1`` iff ``Re s < 0``).

Noise. The fit is weighted by the noise level of the response: ``std`` when
the data give it, the inverse ``weights`` when they give weights, and otherwise
an estimate (:func:`subid.methods.fd._core.noise_variance`: the variance
``a + b |G|^2`` per channel pair fitted by maximum likelihood to the residuals
of iteratively reweighted preliminary fits). Its inverse square root weights
the columns of ``Y`` and ``W`` and the B, D regression (as given weights do),
and it gives the noise covariance of the rows of ``Y`` that weights the SVD.
The paper's equal-variance assumption (``weights=1``) is wrong for most
measured responses, whose noise scales with ``|G|``: under 5 % noise
proportional to ``|G|`` on the seed-000 response (20 runs, order 4,
``bench/frequency_acceptance.py``) the median maximal error is 0.024 with it
and 0.0052 with the estimate, the median relative RMS error 1.20 and 0.0082.
Used in the SVD's noise covariance alone, the former estimate (the squared
residuals of one unweighted preliminary fit averaged over 15 neighbouring
frequencies) left a relative RMS error of 0.10 and a spurious slow pole
(between -0.05 and -1e-8, the true pair -1.24, -1.68 merged) in 15 of the 20
models, from which :func:`subid.pem` could not escape; now none has one.

Weights. Per-frequency weights scale the columns of ``Y`` and ``W`` (which
keeps the data equation exact); weights per channel pair enter the B, D regression in
full and the subspace step through their root mean square per frequency.
Outputs and inputs are scaled to unit RMS response before the SVD (balanced
units) and unscaled after.

The order is chosen, when not given, by the cross-validation idea of the
time-domain methods (:mod:`subid.methods.crossval`) with frequency folds:
four folds, each holding out every fourth frequency (interleaved, so that no
fold has to extrapolate beyond the measured band); each candidate order's fold
models are scored by :func:`subid.fit_percent` on the held-out frequencies,
clipped below at ``FLOOR`` and averaged, and the same rule as the time-domain
methods picks the order: the least cross-validated BIC
(:func:`subid.methods.crossval.select`), with ``2 n_freq n_inputs``
"samples" (each frequency holds ``n_outputs x n_inputs`` complex values: the
real observations of ``2 n_freq n_inputs`` samples of ``n_outputs`` outputs).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from subid._blas import serial_blas
from subid._validation import check_bool, check_choice, check_int, checked_call
from subid.errors import DataError, OrderError, SubidError, UnstableModelWarning
from subid.frdata import FRData
from subid.methods._common import choose_order
from subid.methods._common import parse_order as _parse_order
from subid.methods._info import model_info, records_warnings
from subid.methods._stability import (
    KEEP_UNSTABLE_RATIO,
    STABILITY,
    STABLE_RADIUS,
    reflect_unstable_poles,
)
from subid.methods.crossval import FLOOR, MAX_ORDER, SELECTION_RULES, fold_score, select
from subid.methods.fd import _frequency as fq
from subid.methods.fd._core import (
    Problem,
    check_std,
    default_horizon,
    finish,
    noise_variance,
    subspace,
    system_pair,
)
from subid.model.statespace import StateSpace

__all__ = ["fd_subspace"]

#: Folds of the cross-validated order choice (every ``FOLDS``-th frequency held out).
FOLDS = 4


def _model(problem: Problem, basis, n: int, *, feedthrough: bool, stability: str):
    """The order-n model from the subspace basis; ``(A, B, C, D, diagnostics)``."""
    A_d, C_d, cond_ac = system_pair(problem, basis, n)
    radius = float(np.abs(np.linalg.eigvals(A_d)).max())
    record = {"requested": stability, "action": "none", "spectral_radius_before": radius}
    fit_plain = finish(problem, A_d, C_d, feedthrough)
    if stability == "none" or radius < 1.0:
        return fit_plain + ({"ac": cond_ac}, record)
    reflected = reflect_unstable_poles(A_d, STABLE_RADIUS)
    if reflected is None:
        record["action"] = "failed (nearly defective A)"
        warnings.warn(f"fd_subspace: the order-{n} model is unstable (spectral radius "
                      f"{radius:.4g} in the discrete domain of the fit) and its poles could "
                      "not be reflected; try a lower order", UnstableModelWarning, stacklevel=4)
        return fit_plain + ({"ac": cond_ac}, record)
    fit_stable = finish(problem, reflected, C_d, feedthrough)
    if stability == "auto" and fit_plain[4] < KEEP_UNSTABLE_RATIO * fit_stable[4]:
        record["action"] = "kept unstable (the data demand it)"
        return fit_plain + ({"ac": cond_ac}, record)
    record["action"] = "enforced"
    return fit_stable + ({"ac": cond_ac}, record)


def _build(data: FRData, problem, basis, n, q, *, feedthrough, stability):
    A, B, C, D, err, cond, conditions, record = _model(problem, basis, n,
                                                        feedthrough=feedthrough,
                                                        stability=stability)
    conditions = dict(conditions, bd=cond)
    return StateSpace(A, B, C, D, data.dt, input_names=data.input_names,
                      output_names=data.output_names), conditions, record, err


def _fold_scores(data: FRData, alpha, noise_var, candidates, horizons, *, feedthrough,
                 stability) -> dict:
    """``{order: [fold fit, ...]}``: each candidate order, at its own horizon
    (``horizons[n]``, as an explicit call with that order uses), fitted on the training
    frequencies of every interleaved fold and scored on the held-out ones."""
    index = np.arange(data.n_frequencies)
    per_fold: dict[int, list] = {n: [] for n in candidates}
    for k in range(FOLDS):
        held = index % FOLDS == k
        train, validation = data[~held], data[held]
        problem = Problem(train, alpha, noise_var[~held])
        bases = {}
        for n in candidates:
            q = horizons[n]
            try:
                if q not in bases:
                    bases[q] = subspace(problem, q)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    model = _build(train, problem, bases[q], n, q, feedthrough=feedthrough,
                                   stability=stability)[0]
                per_fold[n].append(fold_score(model, validation))
            except SubidError:
                per_fold[n].append(FLOOR)
    return per_fold


def _cross_validated(data: FRData, per_fold: dict, horizons):
    """``(order, record)``: the least cross-validated BIC over the fold scores
    :func:`_fold_scores` gave (candidates in increasing order)."""
    candidates = sorted(per_fold)
    scores = {(n,): float(np.mean(v)) for n, v in per_fold.items()}
    (order,), crit = select({(n,): per_fold[n] for n in candidates},
                            2 * data.n_frequencies * data.n_inputs, data.n_inputs,
                            data.n_outputs)
    record = {
        "rule": "cv",
        "description": (f"{FOLDS}-fold cross-validation over frequencies (every {FOLDS}th "
                        "frequency held out): frequency-domain fit (%, mean over outputs) on "
                        "the held-out frequencies, mean over the folds; the order of the "
                        "least cross-validated BIC (the time-domain rule)"),
        "candidates": [{"order": n, "horizon": horizons[n], "score": scores[(n,)],
                        "criterion": crit[(n,)], "folds": per_fold[n]} for n in candidates],
        "selected": {"order": order, "horizon": horizons[order], "score": scores[(order,)]},
    }
    return order, record


@serial_blas
@checked_call
@records_warnings
def fd_subspace(data, order=None, *, horizon=None, feedthrough=True, stability="auto",
                selection="cv") -> StateSpace:
    """Identify a state-space model from frequency-response data (McKelvey et al. 1996).

    Parameters
    ----------
    data : FRData
        The measured response. Continuous time (``dt = 0``) gives a
        continuous-time model, discrete time one with the data's ``dt``.
    order : int, iterable of int, 'auto' or None
        Model order, or candidate orders to choose from (None/'auto': 1..10,
        as many as the data allow).
    horizon : int, optional
        Block rows q of the data matrices (McKelvey's q); needs
        ``(q - 1) ny >= order``. Default :func:`default_horizon` of the order
        (each candidate order at its own when the order is chosen), reduced
        when the frequencies give too few columns.
    feedthrough : bool
        Estimate D (else D = 0).
    stability : {'auto', 'enforce', 'none'}
        What to do with an unstable estimate: ``'enforce'`` reflects its
        unstable poles (in the discrete domain of the fit) and refits B and D;
        ``'auto'`` does the same unless the unstable model fits the data
        clearly better (its weighted error below 0.9 times the stabilised
        model's); ``'none'`` keeps it.
    selection : {'cv', 'gap'}
        How the order is chosen when not given: cross-validation over
        frequency folds (default) or the largest gap of the singular values.

    Returns
    -------
    StateSpace
        ``info`` has the core keys (``method`` 'fd_subspace', ``order``,
        ``order_selection``, ``horizon``, ``n_samples`` None, ``x0`` None,
        ``hold``, ``conditions``, ``warnings``) and ``rank_profile`` (the
        singular values of the projected data), ``n_frequencies``,
        ``frequency_scale`` (the bilinear map's α, None in discrete time),
        ``stability``, ``feedthrough`` and ``noise_model`` (where the noise
        level of the weighting came from).

    Raises
    ------
    DataError
        ``data`` is not an FRData, or holds too few frequencies for the
        horizon.
    OrderError
        The order cannot be revealed with the horizon.
    OptionError
        A bad option value.

    Examples
    --------
    >>> import numpy as np, subid
    >>> true = subid.systems.seed000_system()
    >>> w = np.logspace(-2, 2, 200)
    >>> data = subid.FRData(w, true.freqresp(w))
    >>> model = subid.fd_subspace(data, 4)
    >>> bool(np.abs(model.freqresp(w) - data.response).max() < 1e-8)
    True
    """
    if not isinstance(data, FRData):
        raise DataError(f"fd_subspace expects a subid.FRData, got {type(data).__name__}; "
                        "wrap a measured response as subid.FRData(w, response, dt)")
    check_bool(feedthrough, "feedthrough")
    check_choice(stability, "stability", STABILITY)
    check_choice(selection, "selection", SELECTION_RULES)
    check_std(data, "fd_subspace")
    fixed, candidates = _parse_order(order)
    p, m, M = data.n_outputs, data.n_inputs, data.n_frequencies
    if horizon is not None:
        horizon = check_int(horizon, "horizon", minimum=2)

    def block_rows(n):
        """The horizon of order n: given, or the default that the frequencies allow."""
        if horizon is not None:
            return horizon
        q = default_horizon(n, p)
        while q > 2 and 2 * M * m < q * (p + m):
            q -= 1
        return q

    def revealable(n):
        return n <= (block_rows(n) - 1) * p

    if fixed is not None and not revealable(fixed):
        raise OrderError(f"fd_subspace: order {fixed} cannot be revealed with horizon "
                         f"{block_rows(fixed)} and {p} output{'s' if p != 1 else ''}: use "
                         f"horizon >= {math.ceil(fixed / p) + 1}"
                         + ("" if horizon is not None else " and more frequencies"))
    extendable = fixed is None and candidates is None and selection == "cv"
    if fixed is None:
        candidates = [n for n in (candidates or range(1, MAX_ORDER + 1)) if revealable(n)]
        if not candidates:
            raise OrderError("fd_subspace: no candidate order can be revealed with the "
                             f"horizon{' given' if horizon is not None else 's the data allow'}"
                             "; give a larger horizon, more frequencies or lower orders")
    alpha = None if data.dt > 0 else fq.frequency_scale(data.w)
    largest = fixed if fixed is not None else max(candidates)
    noise_var, noise_record = noise_variance(data, alpha, max(MAX_ORDER, largest),
                                            feedthrough)
    problem = Problem(data, alpha, noise_var)
    if fixed is not None:
        n, record = fixed, {"rule": "given"}
    elif selection == "gap" or len(candidates) == 1 or M < 2 * FOLDS:
        profile = subspace(problem, block_rows(max(candidates)))[1]
        n, record = choose_order(None, candidates, profile, "singular values of the "
                                 "projected frequency data")
    else:
        horizons = {k: block_rows(k) for k in candidates}
        per_fold = _fold_scores(data, alpha, noise_var, candidates, horizons,
                                feedthrough=feedthrough, stability=stability)
        n, record = _cross_validated(data, per_fold, horizons)
        # orders past 10, as the time-domain search: another block of candidates (only
        # those scored) while the choice is the largest tried and the frequencies reveal
        # more (a 12-state structure got order 10 and a fit of 46 %, silently)
        while extendable and n == max(per_fold):
            more = [k for k in range(n + 1, n + MAX_ORDER + 1) if revealable(k)
                    and k * (m + p) + p * m < M * m * p]
            if not more:
                break
            horizons.update({k: block_rows(k) for k in more})
            per_fold.update(_fold_scores(data, alpha, noise_var, more, horizons,
                                         feedthrough=feedthrough, stability=stability))
            n, record = _cross_validated(data, per_fold, horizons)
        if n > MAX_ORDER:         # the noise model of an explicit call with this order
            noise_var, noise_record = noise_variance(data, alpha, n, feedthrough)
            problem = Problem(data, alpha, noise_var)
    q = block_rows(n)
    basis = subspace(problem, q)
    model, conditions, stab, _ = _build(data, problem, basis, n, q, feedthrough=feedthrough,
                                        stability=stability)
    info = model_info("fd_subspace", order=n, order_selection=record, horizon=q,
                      n_samples=None, x0=None, hold="zoh", conditions=conditions,
                      rank_profile=basis[1], n_frequencies=M, frequency_scale=alpha,
                      stability=stab, feedthrough=feedthrough, noise_model=noise_record)
    model.info = info
    return model
