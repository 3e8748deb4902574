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
