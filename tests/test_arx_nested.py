"""The cheap paths of the arx and pbsid default calls against the computations they
replace: the nested ARX least squares (one QR per record) against ``fit_arx``, the
sparse scoring pass against the dense one (bit for bit), the structure search against
a fresh fit and score per candidate, and pbsid's step-1 regressions from one factor
against one least squares per step."""

import numpy as np
import pytest

import subid
from subid import errors, systems
from subid._kernel_args import frozen, read_only
from subid.methods.crossval import folds
from subid.methods.dt import _scoring, pbsid, polynomial, selection
from subid.methods.dt._arx_nested import NestedARX
from subid.methods.dt._sparse_scoring import sparse_forced_error
from subid.model.polynomial import realise


def _mimo(n=700, seed=4, noise=0.3):
    true = systems.seed001_system()
    data = systems.simulate_data(true, n, seed=seed)
    rng = np.random.default_rng(seed + 1)
    return subid.IOData(data.u, data.y + noise * rng.standard_normal(data.y.shape), dt=1.0)


def _orders(na, nb, nk, ny):
    return polynomial.parse_orders((na, nb, np.tile(nk, (ny, 1))), "arx", ny, len(nk))


@pytest.mark.parametrize("nk", [[1, 1], [0, 2]])
def test_nested_arx_equals_fit_arx(nk):
    """Every sub-structure from the QR of the largest equals its own least squares,
    on one record and on a merged record of two experiments (rows that no
    experiment joins)."""
    data = _mimo()
    merged = subid.merge([data[:400], _mimo(300, seed=9)])
    nk = np.array(nk)
    for record in (data, merged):
        nested = NestedARX(record, nk, 6, 5)
        for na, nb in [(1, 1), (2, 5), (6, 1), (4, 3), (6, 5)]:
            orders = _orders(na, nb, nk, record.n_outputs)
            A, B = nested.fit(orders)
            A_ref, B_ref, _, _ = polynomial.fit_arx(record, orders, check=False)
            np.testing.assert_allclose(A, A_ref, rtol=0, atol=1e-11 * np.abs(A_ref).max())
            np.testing.assert_allclose(B, B_ref, rtol=0, atol=1e-11 * np.abs(B_ref).max())
    with pytest.raises(ValueError):
        nested.fit(_orders(7, 1, nk, data.n_outputs))         # outside the search


def test_nested_arx_refuses_what_fit_arx_refuses():
    short = _mimo(40)
    nk = np.array([1, 1])
    nested = NestedARX(short, nk, 10, 10)
    orders = _orders(8, 8, nk, short.n_outputs)
    with pytest.raises(errors.TooFewSamplesError):
        polynomial.fit_arx(short, orders, check=False)
    with pytest.raises(errors.TooFewSamplesError):
        nested.fit(orders)
    A, B = nested.fit(_orders(1, 1, nk, short.n_outputs))     # the largest had no rows
    A_ref, B_ref, _, _ = polynomial.fit_arx(short, _orders(1, 1, nk, 2), check=False)
    np.testing.assert_allclose(A, A_ref, atol=1e-12)
    np.testing.assert_allclose(B, B_ref, atol=1e-12)


def test_sparse_scoring_pass_is_the_dense_one_bit_for_bit():
    data = _mimo()
    orders = _orders(4, 3, np.array([1, 1]), 2)
    A, B, _, _ = polynomial.fit_arx(data, orders, check=False)
    Ass, Bss, Css, Dss, _ = realise(polynomial._arx_record(A, B, orders))
    rng = np.random.default_rng(0)
    M = rng.standard_normal((5, 5)) * (rng.uniform(size=(5, 5)) < 0.4)
    cases = [(Ass, Bss, Css, Dss),
             (0.5 * M / max(np.abs(np.linalg.eigvals(M)).max(), 1e-3),
              rng.standard_normal((5, 2)) * (rng.uniform(size=(5, 2)) < 0.5),
              np.eye(2, 5), rng.standard_normal((2, 2)))]
    u, y = read_only(rng.standard_normal((300, 2)), rng.standard_normal((300, 2)))
    weights, inv_scale = rng.uniform(0.5, 2.0, 2), rng.uniform(0.5, 2.0, 2)
    for A, B, C, D in cases:
        A, B, C, D = map(frozen, (A, B, C, D))     # the argument types of the library's calls
        for n_free in (0, 40, 300):
            got = sparse_forced_error(A, B, C, D, u, y, weights, inv_scale, n_free)
            dense = _scoring.forced_error(A, B, C, D, u, y, weights, inv_scale, n_free)
            ref = _scoring.forced_error_reference(A, B, C, D, u, y, weights, inv_scale,
                                                  n_free)
            for g, d, r in zip(got[:2], dense[:2], ref[:2]):
                np.testing.assert_array_equal(g, d)
                np.testing.assert_allclose(g, r, rtol=1e-10, atol=1e-10)
            assert got[2] and dense[2] and ref[2]
        big = frozen(1e3 * A + np.diag(np.full(A.shape[0], 2.0)))   # overflows in 300 samples
        assert not sparse_forced_error(big, B, C, D, u, y, weights, inv_scale, 0)[2]
        assert not _scoring.forced_error(big, B, C, D, u, y, weights, inv_scale, 0)[2]


def test_structure_search_scores_equal_a_fresh_fit_per_candidate():
    """Each candidate's score equals fit_arx on the training part and the selection's
    score on the held-out part, computed from scratch."""
    data = _mimo(600)
    orders, record = polynomial.select_structure(data, max_order=4)
    parts = [(data[a], data[b]) for a, b in folds(data.n_samples)]
    assert len(record["delays"]["compared"]) >= 2       # each candidate with its delays
    for cand in record["candidates"]:
        o = _orders(cand["na"], cand["nb"], np.array(cand["nk"]), data.n_outputs)
        values = []
        for train, validation in parts:
            A, B, _, _ = polynomial.fit_arx(train, o, check=False)
            Ass, Bss, Css, Dss, _ = realise(polynomial._arx_record(A, B, o))
            values.append(selection._fit_score(subid.StateSpace(Ass, Bss, Css, Dss, 1.0),
                                               validation))
        assert cand["score"] == pytest.approx(np.mean(values), abs=1e-8)
    assert (orders["na"][0, 0], orders["nb"][0, 0]) == (record["selected"]["na"],
                                                        record["selected"]["nb"])


@pytest.mark.parametrize("feedthrough", [False, True])
def test_pbsid_step_regressions_from_one_factor(feedthrough):
    from subid.methods.dt._subspace import prepare
    noisy = _mimo(800)
    hf = prepare(noisy, None, 6, method="pbsid").factor
    fast = pbsid.step_coefficients(hf, 6, feedthrough)
    ref = pbsid.step_coefficients_reference(hf, 6, feedthrough)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # noise-free: regressors that repeat each other, where the minimum-norm solution of
    # the reference is kept
    exact = systems.simulate_data(systems.seed001_system(), 800, seed=3)
    hf = prepare(exact, None, 6, method="pbsid").factor
    np.testing.assert_array_equal(pbsid.step_coefficients(hf, 6, feedthrough),
                                  pbsid.step_coefficients_reference(hf, 6, feedthrough))
