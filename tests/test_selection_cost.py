"""The shortcuts that make the order choice cheaper (issue 21, cost of choosing)
against the computations they replace: the feedthrough F-tests of every channel
from one factorisation, and the unstable fold fit skipped when a lower bound of
its residual proves that it cannot be kept. No timing here (bench/run.py)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from functools import partial

import numpy as np
import pytest
import scipy.linalg
import scipy.stats

from subid import systems
from subid.methods.dt import _regression as regression
from subid.methods.dt import _residual_bound as bound
from subid.methods.dt import _subspace as subspace
from subid.methods.dt import feedthrough
from subid.methods.dt.moesp import Moesp
from subid.methods.dt.pipeline import Pipeline
from subid.methods.dt.plan import make_plan
from subid.statistic.hankel import HankelStatistic


def _record(order=4, n=3000, seed=1, snr=20, nu=2, ny=2):
    true = systems.random_system(order, nu, ny, seed=seed)
    return true, systems.simulate_data(true, n, seed=seed + 100, output_snr_db=snr)


def _p_value(L, target, restricted, extra, n_columns):
    """One channel's F-test, one least-squares fit per regressor set (the former code)."""
    def rss(rows):
        t = L[target]
        theta, _, rank, _ = scipy.linalg.lstsq(L[rows].T, t, cond=feedthrough.RANK_TOLERANCE,
                                               lapack_driver="gelsy")
        r = t - theta @ L[rows]
        return float(r @ r), int(rank)
    rss0, rank0 = rss(restricted)
    if rss0 <= feedthrough.EXACT * max(float(L[target] @ L[target]), 1e-300):
        return None
    rss1, rank1 = rss(np.concatenate([restricted, extra]))
    q, dof = rank1 - rank0, n_columns - rank1
    if q <= 0 or dof <= 0:
        return None
    return float(scipy.stats.f.sf(max(rss0 - rss1, 0.0) / q / (rss1 / dof), q, dof))


@pytest.mark.parametrize("shape", [(2, 2), (1, 1), (1, 3)])
def test_feedthrough_tests_equal_one_fit_per_channel(shape):
    nu, ny = shape
    _, data = _record(order=3, nu=nu, ny=ny, seed=nu + 3 * ny)
    factor = HankelStatistic.from_data(data, 12).factor()
    estimate, record = feedthrough.decide(factor)
    norms = np.linalg.norm(factor.L, axis=1)
    L = factor.L / np.where(norms > 0, norms, 1.0)[:, None]
    p = factor.depth - 1
    past_u, past_y = factor.u_rows(0, p), factor.y_rows(0, p)
    current_u, current_y = factor.u_rows(p, p + 1), factor.y_rows(p, p + 1)
    want = [_p_value(L, t, past_u, past_y, factor.n_columns) for t in current_u]
    got = record["feedback"]["p_values"]
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-300)
    if not record["feedback"]["detected"]:
        past = np.concatenate([past_u, past_y])
        want = [_p_value(L, t, past, current_u, factor.n_columns) for t in current_y]
        np.testing.assert_allclose(record["direct_term"]["p_values"], want, rtol=1e-10,
                                   atol=1e-300)
    assert isinstance(estimate, bool)


def _strided_rows(A, C, data, fraction, stride, feedthrough_, weights):
    """The rows of every ``stride``-th sample of the regression on the last ``fraction``
    of ``data`` with a free initial state at its start, by the plain recursion."""
    N = data.n_samples
    start = N - int(np.ceil(fraction * N))
    u, y = data.u[start:], data.y[start:]
    rows, _, _ = regression.dual_rows_reference(A, C, u, np.zeros((2, 2, A.shape[0])),
                                                C.copy(), A.shape[0])
    out = []
    for t in range(0, u.shape[0], stride):
        for i in range(2):
            d = [u[t, j] * (k == i) for j in range(2) for k in range(2)] if feedthrough_ \
                else []
            out.append(np.concatenate([rows[t, i], d, [y[t, i]]]) * weights[i])
    return np.array(out)


def test_residual_bound_is_a_lower_bound():
    """The tail's least-squares residual never exceeds the whole record's (the QR
    path of fit_b_d_x0, the reference for an unstable A); an overflowing regression
    gives an infinite bound, as the full fit gives a non-finite factor."""
    true, data = _record(order=4, n=6000, seed=2)
    radius = float(np.abs(np.linalg.eigvals(true.A)).max())
    weights = np.array([1.0, 2.5])
    for target in (0.95, 1.0005, 1.003):
        A = true.A * (target / radius)
        for x0, d in ((True, True), (False, False)):
            full = regression.fit_b_d_x0_qr(A, true.C, data.u, data.y, feedthrough=d,
                                            estimate_x0=x0, output_weights=weights)[3]
            low = bound.residual_at_least(A, true.C, data.u, data.y, feedthrough=d,
                                          estimate_x0=x0, output_weights=weights)
            assert 0.0 < low <= full["residual_rms"] * (1 + 1e-10)
            every = bound.residual_at_least(A, true.C, data.u, data.y, feedthrough=d,
                                            estimate_x0=x0, output_weights=weights,
                                            stride=bound.STRIDE)     # a subset of its rows
            assert 0.0 < every <= low * (1 + bound.MARGIN)
            for fraction in (bound.SHORT, bound.TAIL):     # free state at the tail's start
                relaxed = bound.relaxed_residual_at_least(A, true.C, data.u, data.y, fraction,
                                                          feedthrough=d,
                                                          output_weights=weights)
                assert 0.0 < relaxed <= full["residual_rms"] * (1 + 1e-10)
                assert relaxed <= low * (1 + bound.MARGIN)
            # every STRIDE-th row of the relaxed TAIL regression: a subset of its rows
            strided = bound.strided_residual_at_least(A, true.C, data.u, data.y, bound.TAIL,
                                                      bound.STRIDE, feedthrough=d,
                                                      output_weights=weights)
            relaxed = bound.relaxed_residual_at_least(A, true.C, data.u, data.y, bound.TAIL,
                                                      feedthrough=d, output_weights=weights)
            assert 0.0 < strided <= relaxed * (1 + bound.MARGIN)
            rows = _strided_rows(A, true.C, data, bound.TAIL, bound.STRIDE, d, weights)
            resid = np.linalg.lstsq(rows[:, :-1], rows[:, -1], rcond=None)[0]
            resid = np.linalg.norm(rows[:, -1] - rows[:, :-1] @ resid)
            np.testing.assert_allclose(strided, resid / np.sqrt(data.n_samples * 2),
                                       rtol=1e-6)
    A = true.A * (1.5 / radius)
    assert bound.residual_at_least(A, true.C, data.u, data.y, feedthrough=True,
                                   estimate_x0=True, output_weights=weights) == np.inf
    assert not np.isfinite(regression.fit_b_d_x0_qr(A, true.C, data.u, data.y)[0]).all()
    assert bound.loses(A, true.C, data.u, data.y, 1.0, feedthrough=True, estimate_x0=True,
                       output_weights=weights) >= 1.0
    assert bound.loses(true.A, true.C, data.u, data.y, np.nan, feedthrough=True,
                       estimate_x0=True, output_weights=weights) is None


def test_dual_states_are_those_of_the_rows_recursion():
    """The compiled state-only recursion (the head of a bound's record) ends in the
    states of the rows recursion, bit for bit, and in its plain reference's."""
    true, data = _record(order=4, n=700, seed=4)
    radius = float(np.abs(np.linalg.eigvals(true.A)).max())
    rng = np.random.default_rng(5)
    u = np.ascontiguousarray(data.u)
    for target, n_x0 in ((0.9, 4), (1.01, 4), (1.01, 0)):
        A = np.ascontiguousarray(true.A * (target / radius))
        C = np.ascontiguousarray(true.C)
        V0, M0 = rng.standard_normal((2, 2, 4)), rng.standard_normal((2, 4))
        _, V, M = regression.dual_rows(A, C, u, V0, M0, n_x0)
        Vs, Ms = regression.dual_states(A, C, u, V0, M0, n_x0)
        np.testing.assert_array_equal(Vs, V)
        np.testing.assert_array_equal(Ms, M)
        Vr, Mr = regression.dual_states_reference(A, C, u, V0, M0, n_x0)
        np.testing.assert_allclose(Vs, Vr, rtol=1e-10, atol=1e-12 * np.abs(Vr).max())
        if n_x0:                         # M is C A^t only with x0 columns
            np.testing.assert_allclose(Ms, Mr, rtol=1e-10, atol=1e-12 * np.abs(Mr).max())


def test_residual_bound_stops_once_it_proves():
    """With ``enough``, a bound's rows stop at the first chunk of EARLY_CHUNK samples
    after which it reaches ``enough``: the value is the plain least-squares residual of
    the rows of those chunks (a subset of the rows: still a lower bound), and where it
    never reaches ``enough``, the bound over every row."""
    true, data = _record(order=4, n=20000, seed=2)
    radius = float(np.abs(np.linalg.eigvals(true.A)).max())
    weights = np.array([1.0, 2.5])
    A = true.A * (1.004 / radius)
    N = data.n_samples
    full = bound.strided_residual_at_least(A, true.C, data.u, data.y, bound.TAIL,
                                           bound.STRIDE, feedthrough=True,
                                           output_weights=weights)
    rows = _strided_rows(A, true.C, data, bound.TAIL, bound.STRIDE, True, weights)
    per_chunk = 2 * bound.EARLY_CHUNK // bound.STRIDE      # two outputs
    prefix = []                                  # the bound after each chunk, plainly
    for stop in range(per_chunk, rows.shape[0] + per_chunk, per_chunk):
        part = rows[:stop]
        theta = np.linalg.lstsq(part[:, :-1], part[:, -1], rcond=None)[0]
        prefix.append(np.linalg.norm(part[:, -1] - part[:, :-1] @ theta) / np.sqrt(2 * N))
    assert np.all(np.diff(prefix) >= -1e-12 * full)          # rows only add residual
    np.testing.assert_allclose(prefix[-1], full, rtol=1e-6)
    proved = 0
    for share in (0.05, 0.3, 0.6, 0.9, 1.5):
        enough = share * full
        got = bound.strided_residual_at_least(A, true.C, data.u, data.y, bound.TAIL,
                                              bound.STRIDE, feedthrough=True,
                                              output_weights=weights, enough=enough)
        k = next((k for k, v in enumerate(prefix) if v >= enough), len(prefix) - 1)
        np.testing.assert_allclose(got, prefix[k], rtol=1e-6)
        assert got <= full * (1 + 1e-8)          # the factor by chunks: rounding
        proved += got >= enough and k < len(prefix) - 1
    assert proved >= 2                           # it did stop early
    # the model's own state and the relaxed bound stop the same way
    own = bound.residual_at_least(A, true.C, data.u, data.y, feedthrough=True,
                                  estimate_x0=True, output_weights=weights)
    early = bound.residual_at_least(A, true.C, data.u, data.y, feedthrough=True,
                                    estimate_x0=True, output_weights=weights,
                                    enough=0.3 * own)
    assert 0.3 * own <= early <= own * (1 + 1e-8)
    relaxed = bound.relaxed_residual_at_least(A, true.C, data.u, data.y, bound.TAIL,
                                              feedthrough=True, output_weights=weights)
    early = bound.relaxed_residual_at_least(A, true.C, data.u, data.y, bound.TAIL,
                                            feedthrough=True, output_weights=weights,
                                            enough=0.3 * relaxed)
    assert 0.3 * relaxed <= early <= relaxed * (1 + 1e-8)


def test_residual_bound_decision_on_a_short_record():
    """On a record too short for the free-state strided bound, a slowly growing A is
    bounded first by its own state on every STRIDE-th tail sample (the value returned
    is that bound), and every bound that proves is at most the full fit's residual: the
    decision (the unstable fit cannot be kept) is the one the full fit makes."""
    true, data = _record(order=4, n=6000, seed=2)
    assert bound.TAIL * data.n_samples < bound.STRIDE * bound.STRIDED_MIN_SAMPLES
    radius = float(np.abs(np.linalg.eigvals(true.A)).max())
    weights = np.array([1.0, 2.5])
    first = 0
    for target in (1.0005, 1.003, 1.02, 1.08):
        A = true.A * (target / radius)
        full = regression.fit_b_d_x0_qr(A, true.C, data.u, data.y, feedthrough=True,
                                        estimate_x0=True, output_weights=weights)[3]
        own = bound.residual_at_least(A, true.C, data.u, data.y, feedthrough=True,
                                      estimate_x0=True, output_weights=weights,
                                      stride=bound.STRIDE)
        slow = bound.TAIL * data.n_samples * np.log10(target) < bound.SLOW_GROWTH_DECADES
        first += slow and own >= 0.2 * full["residual_rms"] * (1 + bound.MARGIN)
        for share in (0.1, 0.2, 0.9, 0.999, 1.01, 1.5):
            threshold = share * full["residual_rms"]
            got = bound.loses(A, true.C, data.u, data.y, threshold, feedthrough=True,
                              estimate_x0=True, output_weights=weights)
            if got is not None:
                assert threshold * (1 + bound.MARGIN) <= got
                assert got <= full["residual_rms"] * (1 + bound.MARGIN)
            if slow and own >= threshold * (1 + bound.MARGIN):
                # the first bound tried, its rows stopped once it proves
                first_tried = bound.residual_at_least(
                    A, true.C, data.u, data.y, feedthrough=True, estimate_x0=True,
                    output_weights=weights, stride=bound.STRIDE,
                    enough=threshold * (1 + bound.MARGIN))
                assert got == first_tried <= own * (1 + 1e-12)
            if share >= 1.01:
                assert got is None
    assert first >= 2


def test_fold_model_skipping_the_unstable_fit_is_the_full_fit_model():
    """A fold model whose unstable A is proven not to be kept (bound_unstable) is the
    model the full computation gives, to the last bit; the bound was used."""
    _, data = _record(order=4, n=4000, seed=1)
    method = Moesp(system_matrices="shift")
    pipeline = Pipeline(method, make_plan(method, data, None, None, selection="cv")[0])
    build = partial(pipeline.fit, estimator="shift")
    used = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = subspace.prepare(data[:2700], list(range(1, 11)), 10, method="moesp")
        for n in range(1, 11):
            full = build(replace(problem, order=n, candidates=[n]))
            fold = build(replace(problem, order=n, candidates=[n], fold=True))
            for name in "ABCD":
                np.testing.assert_array_equal(getattr(fold, name), getattr(full, name))
            assert fold.info["stability"]["action"] == full.info["stability"]["action"]
            used += "residual_unstable_at_least" in fold.info["stability"]
    assert used >= 1
