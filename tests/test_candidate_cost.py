"""What the candidates of the order selection share is reused exactly (issue 21, item 6)."""

import dataclasses

import numpy as np

from subid import systems
from subid.methods._stability import output_growth, record_growth, spectral_radius
from subid.methods.dt.noise_model import innovation_model
from subid.statistic.hankel import HankelStatistic


def test_spectral_radius_is_the_fresh_value_whatever_was_asked_before():
    r = np.random.default_rng(5)
    mats = [r.standard_normal((k, k)) for k in (1, 3, 3, 6, 10)]
    mats.append(mats[1].copy())                 # the same values, another array
    mats.append(mats[1].T)                      # the transpose: another matrix
    mats.append(np.asfortranarray(mats[3]))     # the same matrix, other memory order
    for order in (range(len(mats)), reversed(range(len(mats))), [0, 2, 0, 5, 1, 6, 1, 7]):
        for k in order:
            assert spectral_radius(mats[k]) == float(np.abs(np.linalg.eigvals(mats[k])).max())


def test_record_growth_is_the_fresh_value_whatever_was_asked_before():
    """The growth of a record kept by identity is that record's: equal records (other
    objects), slices, merged records and records made after others were freed give
    their own value."""
    import subid
    r = np.random.default_rng(3)
    y = r.standard_normal((2000, 2)) * np.linspace(1, 5, 2000)[:, None]
    base = subid.IOData(r.standard_normal((2000, 2)), y)
    records = [base, base[:1000], base[500:], subid.IOData(base.u, base.y),
               subid.merge([base[:700], base[700:]])]
    for order in (range(len(records)), reversed(range(len(records))), [0, 1, 0, 4, 2, 0]):
        for k in order:
            want = max(output_growth(e.y) for e in records[k].experiments)
            assert record_growth(records[k]) == want
    for seed in range(6):                            # new records, old ones freed
        fresh = subid.IOData(r.standard_normal((300, 1)),
                             r.standard_normal((300, 1)) * (1 + seed))
        assert record_growth(fresh) == output_growth(fresh.y)
        del fresh


def test_innovation_model_same_with_reused_projections():
    """The second model on one factor reuses its oblique projections: K and the
    innovation covariance equal those computed on a fresh copy of the factor."""
    data = systems.simulate_data(systems.random_system(3, 2, 2, seed=4), 1500, seed=6,
                                 output_snr_db=20)
    hf = HankelStatistic.from_data(data, 12).factor()
    r = np.random.default_rng(7)
    models = []
    for n in (2, 3, 4):
        A = r.standard_normal((n, n))
        A *= 0.8 / np.abs(np.linalg.eigvals(A)).max()
        models.append((A, r.standard_normal((n, 2)), r.standard_normal((2, n)),
                       r.standard_normal((2, 2))))
    for A, B, C, D in models + models[:1]:
        K, sigma, diag = innovation_model(A, B, C, D, hf)           # shared projections
        copy = dataclasses.replace(hf, L=hf.L.copy())               # computed afresh
        K0, sigma0, diag0 = innovation_model(A, B, C, D, copy)
        np.testing.assert_array_equal(K, K0)
        np.testing.assert_array_equal(sigma, sigma0)
        assert diag == diag0


def test_feedthrough_decision_kept_by_content():
    """Equal factors (another object, the same bytes) give the decision of a fresh
    call, each caller its own record; another factor is decided afresh."""
    from subid.methods.dt.feedthrough import decide, decided
    data = systems.simulate_data(systems.random_system(3, 2, 2, seed=4), 1500, seed=6,
                                 output_snr_db=20)
    for depth in (8, 12, 8):
        hf = HankelStatistic.from_data(data, depth).factor()
        first = decided(hf)
        again = decided(dataclasses.replace(hf, L=hf.L.copy()))
        assert repr(first) == repr(again) == repr(decide(hf))
        first[1]["feedback"]["detected"] = "changed"        # the caller's own copy
        assert decided(hf)[1]["feedback"]["detected"] != "changed"


def test_nested_regressions_of_the_feedthrough_tests_equal_one_regression_each():
    """The four regressions of the feedthrough F-tests from one factorisation give the
    residual powers and ranks of one rank-revealing least squares each, and the same
    decision; an ill-conditioned (noise-free) factor goes to the least squares."""
    from subid.methods.dt import feedthrough as ft
    checked = 0
    for seed, snr, depth in [(1, 20, 8), (2, 20, 20), (3, 40, 12), (4, 10, 40), (5, None, 12)]:
        kw = {} if snr is None else {"output_snr_db": snr}
        data = systems.simulate_data(systems.random_system(3, 2, 2, seed=seed), 1500, seed=6,
                                     **kw)
        hf = HankelStatistic.from_data(data, depth).factor()
        L = hf.L / np.linalg.norm(hf.L, axis=1)[:, None]
        p = depth - 1
        pu, py, cu, cy = hf.u_rows(0, p), hf.y_rows(0, p), hf.u_rows(p, p + 1), \
            hf.y_rows(p, p + 1)
        nested = ft._nested_powers(L, pu, py, cu, cy)
        if snr is None:
            assert nested is None
            continue
        past = np.concatenate([pu, py])
        reference = {"feedback reduced": ft._residual_powers(L, cu, pu),
                     "feedback extended": ft._residual_powers(L, cu, past),
                     "on past": ft._residual_powers(L, cy, past),
                     "on all": ft._residual_powers(L, cy, np.concatenate([past, cu]))}
        for key, (rss, rank) in reference.items():
            assert nested[key][1] == rank
            np.testing.assert_allclose(nested[key][0], rss, rtol=1e-9)
        fast = ft.decide(hf)
        original = ft._nested_powers
        try:
            ft._nested_powers = lambda *args: None
            slow = ft.decide(hf)
        finally:
            ft._nested_powers = original
        assert fast[0] == slow[0]
        for key in ("feedback", "direct_term"):
            a, b = fast[1][key], slow[1][key]
            if isinstance(a, dict):
                np.testing.assert_allclose(np.array(a["p_values"], dtype=float),
                                           np.array(b["p_values"], dtype=float), rtol=1e-6,
                                           atol=1e-300)
        np.testing.assert_allclose(fast[1]["lag0_share"], slow[1]["lag0_share"], rtol=1e-9,
                                   atol=1e-15)
        checked += 1
    assert checked == 4


def test_prediction_power_kernel_equals_its_reference_and_the_prediction_errors():
    """The compiled sum of the one-step prediction errors' products equals the plain
    loop and ``prediction_errors(model, data, 1, x0='zero')`` summed (per experiment
    from a zero state); a diverging predictor gives None."""
    import subid
    from subid.methods.dt._innovation_kernel import prediction_power, prediction_power_reference
    from subid.model.prediction import prediction_errors
    true = systems.random_system(3, 2, 2, seed=4)
    data = systems.simulate_data(true, 600, seed=6, output_snr_db=20)
    model = subid.moesp(data, 3, horizon=6)
    for record in (data, subid.merge([data[:250], data[250:]])):
        pieces = [(record.u[a:b], record.y[a:b]) for a, b in record.experiment_ranges]
        got = prediction_power(model.A, model.B, model.C, model.D, model.K, pieces)
        ref = prediction_power_reference(model.A, model.B, model.C, model.D, model.K, pieces)
        errors = prediction_errors(model, record, 1, x0="zero")
        np.testing.assert_allclose(got, ref, rtol=1e-12)
        np.testing.assert_allclose(got, errors.T @ errors, rtol=1e-10)
        # from given initial states, one per experiment
        x0 = np.random.default_rng(8).standard_normal((len(pieces), 3))
        got = prediction_power(model.A, model.B, model.C, model.D, model.K, pieces, x0)
        ref = prediction_power_reference(model.A, model.B, model.C, model.D, model.K, pieces,
                                         x0)
        errors = prediction_errors(model, record, 1, x0=x0 if len(pieces) > 1 else x0[0])
        np.testing.assert_allclose(got, ref, rtol=1e-12)
        np.testing.assert_allclose(got, errors.T @ errors, rtol=1e-10)
    K = np.zeros_like(model.K)
    A = 3.0 * np.eye(3)                           # a predictor that leaves the float range
    long = systems.simulate_data(true, 2000, seed=7)
    pieces = [(long.u, long.y)]
    assert prediction_power(A, model.B, model.C, model.D, K, pieces) is None
    assert prediction_power_reference(A, model.B, model.C, model.D, K, pieces) is None
