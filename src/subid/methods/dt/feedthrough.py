"""``feedthrough='auto'``: estimate a direct term D only when the data show one.

MATLAB's ``n4sid`` and ``ssest`` estimate no feedthrough unless asked. A free
D is harmless in open loop (its estimate converges to the true D, zero or
not), but under output feedback ``u(k) = r(k) - F y(k)`` the input at time k
is correlated with the innovation e(k) at time k, and a free D absorbs that
correlation: on the seed-001 plant (D = 0) in closed loop with F = -0.5 I,
PEM started from a model with a free D converged to a Markov error 16x that
of the start with D = 0 (issue 21). The decision is made from the data in two
F-tests on the rows of the block-Hankel factor the method already holds
(least squares on the rows of ``L`` equals least squares on the Hankel rows,
``H = L Q^T``; no extra pass over the record, so it works on a
:class:`subid.HankelStatistic` too):

0. **Noise-free records**: when the past and u(k) explain y(k) to rounding
   (:data:`NOISE_FREE`), there is no noise for a free D to absorb and its
   estimate is exact: D is estimated (a random test must not decide
   noise-free exactness).
1. **Feedback** (Ljung, *System Identification*, 2nd ed., 1999, Sec. 13.4;
   MATLAB's ``feedback``): each input u_j(k) is regressed on the past inputs
   ``u(k-1..k-p)``, then also on the past outputs ``y(k-1..k-p)``. In open
   loop the past outputs add nothing once the past inputs are known (the
   noise is independent of the input), so an F-test of their coefficients
   significant at :data:`LEVEL` (Bonferroni over the inputs) shows feedback.
   Under feedback the lag-zero correlation between u(k) and y(k) cannot be
   told apart from a direct term: D = 0, as MATLAB does. This is a property
   of the data, not of the test: a plant with a direct term under a feedback
   with a delay, and a plant without one under a feedback without delay, can
   give the same second-order statistics of (u, y), so every criterion
   computed from them (held-out simulation or one-step prediction fit, with
   or without D) ranks the two alike. Measured (issue 21,
   ``bench/feedthrough_feedback.py``): on the seed-001 plant (D = 0) under
   u = r + 0.5 y a free D raises the held-out simulation fit by about 1
   point and the one-step prediction fit of PEM-refined fold models by
   0.7-0.8 points, and PEM from it ends 14-26x further from the plant; on
   the DaISy winding record it raises the validation fit by 8 points but
   validates worse on the folds of the estimation record. What a free D
   adds to the one-step prediction is the share ``lag0_share`` below, there
   and on winding alike.
   ``info['feedthrough']['lag0_share']`` records (always), per output, the share of
   the one-step prediction error of the high-order ARX model below that
   u(k) explains: all a free D can take from the lag-0 correlation. Pass
   ``feedthrough=True`` when the plant is known to have a direct term and
   the feedback a delay.
2. **Direct term**, in open loop: each output y_i(k) is regressed on
   ``u(k-1..k-p), y(k-1..k-p)`` (a high-order ARX model, which approximates
   the one-step predictor of any innovation model, Ljung 1999, Sec. 4.3
   and 16.4) with and without ``u(k)``; the coefficients of u(k) are those
   of D in the predictor ``ŷ(k) = C x̂(k) + D u(k)``. D is estimated when the
   F-test of the u(k) coefficients is significant at :data:`LEVEL`
   (Bonferroni over the outputs).

The number of lags is ``p = depth - 1`` of the method's factor (19 for
horizon 10 with past and future rows), so the decision depends only on the
record and the horizon: ``method(data, order=model.order,
horizon=model.info['horizon'])`` makes the same decision. An input that
its own past predicts exactly (a periodic signal) shows no feedback: the
F-test is then undefined and the direct-term test decides. ``info['feedthrough']``
records both tests.

Cost: the four regressions of the tests regress on nested sets of rows (the past
inputs; the past; the past and u(k)), so one QR factorisation of the rows in that order
gives every residual (:func:`_nested_powers`) where the regressors are well conditioned
(the residuals of the rank-revealing least squares to rounding, tested); otherwise each
regression is solved with rank detection (:func:`_residual_powers`). 2.7x (horizon 10)
to 4.5x (horizon 20) faster on a 2x2 record at 20 dB; the order selection decides it
per fold and horizon.
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.linalg
import scipy.special

from subid._validation import check_choice
from subid.statistic.hankel import geqrf_r

#: The values ``feedthrough`` accepts.
FEEDTHROUGH = ("auto", True, False)
#: Significance level of each test (Bonferroni-corrected over the channels).
LEVEL = 0.01
#: A residual below this fraction of the regressand's power means an exact fit
#: (noise-free or deterministic signal): the F-test is undefined.
EXACT = 1e-20
#: Regressor directions below this fraction of the largest are rounding, not data (the
#: rows are first scaled to unit norm, so that the units of the channels do not matter).
RANK_TOLERANCE = 1e-8
#: Relative residual power of y(k) on the past and u(k) below which a record is noise-free
#: (1e-6 relative RMS: rounding of a Gram statistic, far below any measurement noise).
NOISE_FREE = 1e-12


def check_feedthrough(value) -> object:
    """``value`` ('auto', True or False; numpy bools accepted) or :class:`OptionError`."""
    if isinstance(value, np.bool_):
        value = bool(value)
    return check_choice(value, "feedthrough", FEEDTHROUGH)


def _residual_powers(L, targets, regressors):
    """Sums of squares (per Hankel column) of each row ``targets`` of ``L`` minus its
    least-squares fit on the rows ``regressors``, and the numerical rank of the
    regressors: one factorisation for every target.

    Directions of the regressors below :data:`RANK_TOLERANCE` of the largest are
    dropped (QR with column pivoting): on noise-free records the past outputs add only
    n directions to the past inputs, the rest are rounding, and fitted they would make a
    test "significant" by fitting rounding errors.
    """
    T = L[targets]
    if regressors.size == 0:
        return np.einsum("ij,ij->i", T, T), 0
    R = L[regressors]
    theta, _, rank, _ = scipy.linalg.lstsq(R.T, T.T, cond=RANK_TOLERANCE, lapack_driver="gelsy",
                                           check_finite=False)
    r = T - theta.T @ R
    return np.einsum("ij,ij->i", r, r), int(rank)


def _f_tests(L, targets, restricted, extra, n_columns, extended=None, reduced=None):
    """p-value of the test, for each row of ``targets``, that the ``extra`` rows add
    nothing to ``restricted`` (None where the restricted fit is exact or the extra
    rows add no direction). ``extended`` and ``reduced``: the :func:`_residual_powers`
    of the targets on ``restricted`` and ``extra`` together, and on ``restricted``
    alone, when already computed."""
    rss0, rank0 = reduced if reduced is not None else \
        _residual_powers(L, targets, restricted)
    rss1, rank1 = extended if extended is not None else \
        _residual_powers(L, targets, np.concatenate([restricted, extra]))
    power = np.einsum("ij,ij->i", L[targets], L[targets])
    q = rank1 - rank0
    dof = n_columns - rank1
    out = []
    for k in range(len(targets)):
        if rss0[k] <= EXACT * max(power[k], 1e-300) or q <= 0 or dof <= 0:
            out.append(None)
            continue
        F = max(rss0[k] - rss1[k], 0.0) / q / max(rss1[k] / dof, 1e-300 * rss0[k])
        # the survival function of Fisher's F(q, dof) (what scipy.stats.f.sf computes,
        # without its argument handling: the same value)
        out.append(float(scipy.special.fdtrc(q, dof, F)))
    return out


#: Largest 1-norm condition estimate (LAPACK ``trcon``) of the triangular factor of the
#: regressors (rows of unit norm) at which :func:`_nested_powers` trusts it: far below the
#: ``1 / RANK_TOLERANCE`` at which the pivoted least squares of :func:`_residual_powers`
#: start dropping directions (its 2-norm condition is at most ``m`` times this estimate,
#: ``m`` up to a few hundred regressors), so both keep every regressor.
NESTED_MAX_CONDITION = 1e4


def _nested_powers(L, past_u, past_y, current_u, current_y):
    """The four regressions of :func:`decide` from one factorisation, or None.

    With the rows ordered ``[past u; past y; u(k); y(k)]`` and factorised ``M = T Q^T``
    (``T`` lower triangular), the residual of row ``j`` on the rows before position
    ``k`` is ``sum_{c >= k} T[j, c]^2``: every regression of the tests regresses on a
    prefix of that order (u(k) on the past inputs, and on the whole past; y(k) on the
    past, and on the past and u(k)). The same residuals as :func:`_residual_powers` to
    rounding where the regressors have full numerical rank, which is checked (condition
    estimate at most :data:`NESTED_MAX_CONDITION`); None otherwise (the caller then
    solves each regression with rank detection). Returns ``{name: (residual powers,
    rank)}`` for ``'feedback reduced'``, ``'feedback extended'``, ``'on past'``,
    ``'on all'``."""
    rows = np.concatenate([past_u, past_y, current_u, current_y])
    M = L[rows]
    if M.shape[0] > M.shape[1]:
        return None
    T = geqrf_r(M.T, M.shape[0], overwrite=False).T     # scipy's qr(mode='r'), its bits
    n_u, n_past, nu = len(past_u), len(past_u) + len(past_y), len(current_u)
    regressors = n_past + nu
    diag = np.abs(np.diag(T)[:regressors])
    if regressors and not np.all(diag > 0):
        return None
    if regressors:
        Tn = np.ascontiguousarray(T[:regressors, :regressors].T)       # upper triangular
        rcond = scipy.linalg.lapack.dtrcon(Tn, norm="1", uplo="U", diag="N")[0]
        if not (rcond > 0 and 1.0 / rcond <= NESTED_MAX_CONDITION):
            return None
    sq = T * T
    tails = np.cumsum(sq[:, ::-1], axis=1)[:, ::-1]      # tails[j, k] = sum_{c >= k} T[j, c]^2
    tails = np.concatenate([tails, np.zeros((tails.shape[0], 1))], axis=1)
    u_rows = np.arange(n_past, regressors)
    y_rows = np.arange(regressors, M.shape[0])
    return {"feedback reduced": (tails[u_rows, n_u], n_u),
            "feedback extended": (tails[u_rows, n_past], n_past),
            "on past": (tails[y_rows, n_past], n_past),
            "on all": (tails[y_rows, regressors], regressors)}


def decide(factor, *, level: float = LEVEL):
    """Whether to estimate D, from a Hankel factor (:mod:`subid.statistic._hankel`).

    Parameters
    ----------
    factor : HankelFactor
        The factor of the record (any channel scaling).
    level : float
        Significance level of each test.

    Returns
    -------
    estimate : bool
    record : dict
        ``info['feedthrough']``: ``requested``, ``estimated``, ``lags``,
        ``feedback`` (per-input p-values, detected or not), ``direct_term``
        (per-output p-values, or why not tested), ``rule``, ``lag0_share``
        (per output, the share of its one-step prediction error that u(k)
        explains; not on noise-free records).
    """
    nu, ny, s = factor.n_inputs, factor.n_outputs, factor.depth
    norms = np.linalg.norm(factor.L, axis=1)
    L = factor.L / np.where(norms > 0, norms, 1.0)[:, None]     # unit rows: unit-free ranks
    p = s - 1
    K = factor.n_columns
    past_u = factor.u_rows(0, p)
    past_y = factor.y_rows(0, p)
    record = {"requested": "auto", "lags": p, "level": level,
              "rule": "D estimated when the data show a direct term and no feedback "
                      "(F-tests on the Hankel rows, subid.methods.dt.feedthrough)"}
    if nu == 0 or p < 1:
        record.update(estimated=False, feedback=None,
                      direct_term="not tested: no input or no lag")
        return False, record
    current_u = factor.u_rows(p, p + 1)
    current_y = factor.y_rows(p, p + 1)
    past = np.concatenate([past_u, past_y])
    # the regressions on nested regressors, from one factorisation where it is exact
    nested = _nested_powers(L, past_u, past_y, current_u, current_y)
    # noise-free: the past and u(k) explain y(k) to rounding; there is no noise for a free D
    # to absorb and its estimate is exact, so D is estimated (whatever the input)
    on_all = nested["on all"] if nested is not None else \
        _residual_powers(L, current_y, np.concatenate([past, current_u]))
    power = np.einsum("ij,ij->i", L[current_y], L[current_y])
    exact = bool(np.all(on_all[0] <= NOISE_FREE * np.maximum(power, 1e-300)))
    if exact:
        record.update(estimated=True, feedback=None,
                      direct_term="noise-free record: the past and u(k) explain y(k) to "
                                  "rounding; D estimated (exactly)")
        return True, record
    feedback = _f_tests(L, current_u, past_u, past_y, K) if nested is None else \
        _f_tests(L, current_u, past_u, past_y, K, extended=nested["feedback extended"],
                 reduced=nested["feedback reduced"])
    detected = any(v is not None and v < level / nu for v in feedback)
    record["feedback"] = {"p_values": feedback, "detected": bool(detected)}
    # the share of each output's one-step prediction error (high-order ARX) that u(k)
    # explains: what a free D takes from the lag-0 correlation
    on_past = nested["on past"] if nested is not None else \
        _residual_powers(L, current_y, past)
    # np.clip's values (NaN kept) without its dispatch
    share = np.minimum(np.maximum(1.0 - on_all[0] / np.maximum(on_past[0], 1e-300), 0.0), 1.0)
    record["lag0_share"] = [float(v) for v in share]
    if detected:
        record.update(estimated=False,
                      direct_term="not tested: under feedback the lag-0 correlation of u and "
                                  "y cannot be told from a direct term (D = 0, as MATLAB; "
                                  "lag0_share: what a free D would take)")
        return False, record
    direct = _f_tests(L, current_y, past, current_u, K, extended=on_all, reduced=on_past)
    exact = all(v is None for v in direct)
    significant = any(v is not None and v < level / ny for v in direct)
    # a record the past explains exactly (noise-free): keep D free, its estimate is exact
    estimate = bool(significant or exact)
    record.update(estimated=estimate, direct_term={"p_values": direct,
                                                   "significant": bool(significant),
                                                   "exact_fit": bool(exact)})
    return estimate, record


#: Block rows of the Hankel factor on which :func:`feedback_test` runs by default: the
#: depth of the subspace defaults' factor at horizon 10, whose feedthrough test this is.
FEEDBACK_DEPTH = 20


def feedback_test(data, depth: int = FEEDBACK_DEPTH, *, last=True) -> dict:
    """The feedback test of :func:`decide` on ``data``'s Hankel factor of ``depth`` block
    rows (with ``last``, on at most its last
    :data:`~subid.methods.crossval.MAX_SELECTION_SAMPLES` samples, as the order searches
    read): ``{'p_values', 'detected'}``, or ``{'detected': False, 'reason': ...}`` where
    it cannot run (too short a record; noise-free data, where there is no noise for the
    loop to correlate with the input)."""
    from subid.errors import SubidError
    from subid.methods.crossval import selection_part
    from subid.statistic.hankel import HankelStatistic
    part = selection_part(data) if last else data
    if part.u_offset is None:
        # each experiment's means removed: a constant in u and y is no feedback, but the
        # regressions of the test have no intercept, and an operating point left in the
        # record made it fire on open-loop data (p = 9e-18 on a 2 x 2 record with offsets)
        part = part.detrend()
    try:
        factor = HankelStatistic.from_data(part, depth).factor()
    except SubidError as exc:
        return {"detected": False, "reason": f"not tested: {exc}"}
    record = decide(factor)[1].get("feedback")
    return record if record is not None else {"detected": False,
                                              "reason": "not tested: noise-free record"}


#: Level (Bonferroni over the inputs) at which the output-error criteria warn of feedback
#: (``oe``, ``pem(focus='simulation')``): stricter than :data:`LEVEL`, which decides D and
#: ``arx``'s delays, so that an open-loop record warns once in a thousand, not a hundred
#: (measured: 2 warnings in the 200 open-loop runs of ``oe`` in
#: ``tests/test_uncertainty_polynomial.py`` at 1 %, p = 0.0024 and 0.0002).
WARNING_LEVEL = 1e-3


def feedback_warning(record) -> str | None:
    """``'(p = ...)'`` when the :func:`feedback_test` ``record`` shows feedback at
    :data:`WARNING_LEVEL` (the smallest p-value, Bonferroni over the inputs), else None."""
    values = [v for v in record.get("p_values", []) or [] if v is not None]
    if not values or min(values) >= WARNING_LEVEL / len(values):
        return None
    return f"(p = {min(values):.2g})"


#: ``lag0_share`` above which D = 0 under detected feedback is warned of
#: (:func:`dropped_direct_term`): in the closed loops measured (the seed-001 innovation
#: plant under u = r + 0.1 y and r + 0.5 y, 300-3000 samples; DaISy winding, ballbeam,
#: CD_player_arm) the share was 0.00-0.37, while an open-loop record of the seed-001
#: plant (D != 0) on which the feedback test raised a false alarm (p = 1.4e-4, as 1 % of
#: open-loop records do at :data:`LEVEL`) had 0.99 and 1.00, and its model with D = 0
#: fitted 66 and 33 % against 97 and 97 % with D.
DIRECT_SHARE_WARNING = 0.5


def dropped_direct_term(record) -> str | None:
    """The message of a :class:`subid.errors.FeedbackWarning` when ``record``
    (``info['feedthrough']``) set D = 0 because the data show feedback while u(k) explains
    more than :data:`DIRECT_SHARE_WARNING` of an output's one-step prediction error (what
    a direct term would), else None."""
    if not isinstance(record, dict) or record.get("estimated") \
            or not (record.get("feedback") or {}).get("detected"):
        return None
    shares = [v for v in record.get("lag0_share") or [] if v is not None and np.isfinite(v)]
    if not shares or max(shares) <= DIRECT_SHARE_WARNING:
        return None
    p = min(v for v in record["feedback"]["p_values"] if v is not None)
    return (f"feedthrough='auto' set D = 0 because the data show feedback (p = {p:.2g}), "
            f"but u(k) explains {100 * max(shares):.0f} % of an output's one-step prediction "
            "error, as a direct term would (closed loops without one measured at most 37 "
            "%): if the record is open-loop or the plant has a direct term and the feedback "
            "a delay, pass feedthrough=True and compare the two on validation data "
            "(info['feedthrough'])")


#: The last decision of :func:`decided`, as one ``(key, (estimate, record))`` pair.
_LAST = [None]


def decided(factor):
    """:func:`decide` on ``factor``, the last one kept by content (the factor's shape,
    bytes and dimensions): the problems of one record and horizon (the order selection's
    innovation check, then the final model; a fallback candidate) hold equal factors. The
    record returned is the caller's own copy."""
    L = np.ascontiguousarray(factor.L)
    key = (L.shape, L.dtype.str, L.tobytes(), factor.depth, factor.n_inputs,
           factor.n_outputs, factor.n_columns)
    last = _LAST[0]
    if last is None or last[0] != key:
        last = _LAST[0] = (key, decide(factor))      # one assignment: safe across threads
    estimate, record = last[1]
    return estimate, copy.deepcopy(record)


def resolve(feedthrough, problem):
    """The feedthrough a build uses on ``problem`` and its ``info['feedthrough']`` record
    (the decision cached on the problem, shared by the candidate orders)."""
    if feedthrough != "auto":
        return bool(feedthrough), {"requested": bool(feedthrough),
                                   "estimated": bool(feedthrough)}
    cache = problem._cache
    if "feedthrough" not in cache:
        cache["feedthrough"] = decided(problem.factor)
    estimate, record = cache["feedthrough"]
    return estimate, dict(record)
