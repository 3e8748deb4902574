"""The Kalman gains of the innovation check by the doubling algorithm against QZ."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import subid
from subid import systems
from subid.methods.dt import noise_model
from subid.methods.dt.noise_model import innovation_model, riccati_by_doubling


def _problem(rng, n, ny, radius):
    A = rng.standard_normal((n, n))
    A *= radius / np.abs(np.linalg.eigvals(A)).max()
    C = rng.standard_normal((ny, n))
    W, E = rng.standard_normal((n, 60)), rng.standard_normal((ny, 60))
    Q = W @ W.T
    return A, C, Q + 1e-10 * np.trace(Q) * np.eye(n), E @ E.T, W @ E.T


def test_doubling_solves_the_riccati_equation_of_scipy():
    """riccati_by_doubling gives scipy's stabilising solution (QZ) to about 1e-13 on
    random equations with cross terms, unstable A included."""
    rng = np.random.default_rng(21)
    for _ in range(60):
        n, ny = int(rng.integers(1, 16)), int(rng.integers(1, 5))
        A, C, Q, R, S = _problem(rng, n, ny, rng.uniform(0.3, 1.05))
        want = scipy.linalg.solve_discrete_are(A.T, C.T, Q, R, s=S)
        got = riccati_by_doubling(A, C, Q, R, S)
        assert got is not None
        assert np.abs(got - want).max() <= 1e-10 * np.abs(want).max()


def test_doubling_gives_up_where_it_cannot_run():
    """A singular R (no cross-term elimination) or an iteration that cannot settle:
    None, and innovation_model then solves by QZ."""
    rng = np.random.default_rng(3)
    A, C, Q, R, S = _problem(rng, 4, 2, 0.9)
    assert riccati_by_doubling(A, C, Q, np.zeros((2, 2)), S) is None
    assert riccati_by_doubling(A, C, Q, R, S * np.nan) is None


def test_innovation_check_criteria_equal_those_of_qz(monkeypatch):
    """The innovation BIC of every order, with the gains by doubling, equals the one
    with the gains by QZ to rounding, and the choice is the same."""
    true = systems.random_system(4, 2, 2, seed=1)
    data = systems.simulate_data(true, 1000, seed=2, output_snr_db=20)
    fast = subid.moesp(data)
    monkeypatch.setattr(noise_model, "riccati_by_doubling", lambda *args: None)
    slow = subid.moesp(data)
    check_fast = fast.info["order_selection"]["innovation_check"]
    check_slow = slow.info["order_selection"]["innovation_check"]
    assert check_fast["orders"], "the check must have run for this test to compare"
    assert [e["order"] for e in check_fast["orders"]] == [e["order"] for e in check_slow["orders"]]
    for a, b in zip(check_fast["orders"], check_slow["orders"]):
        assert abs(a["criterion"] - b["criterion"]) <= 1e-9 * abs(b["criterion"])
    assert (fast.order, fast.info["horizon"]) == (slow.order, slow.info["horizon"])
    np.testing.assert_array_equal(fast.A, slow.A)
    np.testing.assert_array_equal(fast.K, slow.K)


def test_innovation_model_gain_by_doubling():
    """innovation_model(doubling=True): the gain of the QZ solution to rounding."""
    true = systems.seed001_system()
    data = systems.simulate_data(true, 3000, seed=4, output_snr_db=20)
    model = subid.moesp(data, 3, horizon=10)
    hf = subid.HankelStatistic.from_data(data, 20).factor()
    K0, s0, _ = innovation_model(model.A, model.B, model.C, model.D, hf)
    K1, s1, _ = innovation_model(model.A, model.B, model.C, model.D, hf, doubling=True)
    np.testing.assert_allclose(K1, K0, rtol=1e-10, atol=1e-12 * np.abs(K0).max())
    np.testing.assert_allclose(s1, s0, rtol=1e-10)


def test_compiled_doubling_equals_its_numpy_reference():
    """The compiled doubling loop gives the numpy loop's solution to rounding, and None
    where it does (a singular step, a diverging iterate, no convergence)."""
    from subid.methods.dt._innovation_kernel import doubling, doubling_reference
    from subid.methods.dt.noise_model import DOUBLING_ITERATIONS, DOUBLING_TOLERANCE
    rng = np.random.default_rng(11)
    for n, ny, radius in [(1, 1, 0.5), (3, 2, 0.9), (6, 2, 0.99), (10, 3, 1.2), (4, 4, 0.3)]:
        A, C, Q, R, S = _problem(rng, n, ny, radius)
        Ri_C = np.linalg.solve(R, C)
        Ak = (A - S @ Ri_C).T
        G = C.T @ Ri_C
        G = 0.5 * (G + G.T)
        H = Q - S @ np.linalg.solve(R, S.T)
        H = 0.5 * (H + H.T)
        got = doubling(Ak, G, H, DOUBLING_ITERATIONS, DOUBLING_TOLERANCE)
        ref = doubling_reference(Ak, G, H, DOUBLING_ITERATIONS, DOUBLING_TOLERANCE)
        assert (got is None) == (ref is None)
        if ref is not None:
            np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
    n = 3
    singular = -np.eye(n)                 # I + G H = 0 at the first step
    assert doubling(np.eye(n), np.eye(n), singular, 40, 1e-15) is None
    assert doubling_reference(np.eye(n), np.eye(n), singular, 40, 1e-15) is None
    huge = np.full((n, n), 1e300)         # the iterates overflow
    assert doubling(huge, np.eye(n), np.eye(n), 40, 1e-15) is None
    assert doubling_reference(huge, np.eye(n), np.eye(n), 40, 1e-15) is None
    assert doubling(0.9 * np.eye(n), np.eye(n), np.eye(n), 1, 1e-15) is None   # not settled


def test_gain_of_outputs_in_very_different_units_without_warning():
    """One output in units 1e8 times the other's: the innovation covariance is badly
    scaled, not ill-posed. K is found without scipy's ill-conditioning warning, and it is
    the gain of the record in the original units, rescaled (K' = K S^-1, S the scaling):
    the same predictor."""
    import warnings
    true = systems.random_system(3, 2, 2, seed=1)
    data = systems.simulate_data(true, 2000, seed=2, output_snr_db=30)
    scale = np.array([1e8, 1.0])
    scaled = subid.IOData(data.u, data.y * scale, dt=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = subid.moesp(scaled, 3, horizon=10)
    assert m.info["warnings"] == []
    ref = subid.moesp(data, 3, horizon=10)
    # the same predictor: K rescaled, and the one-step predictions (x0 weighted by each
    # output's spread) in the original units
    assert np.allclose(m.A, ref.A, rtol=0, atol=1e-12)
    assert np.allclose(m.K * scale[None, :], ref.K, rtol=1e-8, atol=1e-12)
    p_scaled = subid.predict(m, scaled, 1) / scale
    p_ref = subid.predict(ref, data, 1)
    assert np.max(np.abs(p_scaled - p_ref)) < 1e-6 * np.std(data.y)


def test_predict_output_std_is_validated_and_weighs_the_initial_state():
    true = systems.random_system(3, 2, 2, seed=1)
    data = systems.simulate_data(true, 400, seed=2, output_snr_db=20)
    model = subid.moesp(data, 3, horizon=10)
    # the predictor's free response has decayed to rounding within the head: its x0,
    # weighted by the spreads of the whole record, is the record's (as
    # noise_model._predictor_initial_states relies on); weighted by its own, it is not
    radius = np.abs(np.linalg.eigvals(model.A - model.K @ model.C)).max()
    head = data[:int(np.ceil(np.log(1e-16) / np.log(radius))) + 10]
    whole = subid.predict(model, data, 1, return_x0=True)[1]
    own = subid.predict(model, head, 1, return_x0=True)[1]
    given = subid.predict(model, head, 1, return_x0=True, output_std=np.std(data.y, axis=0))[1]
    np.testing.assert_allclose(given, whole, rtol=1e-9, atol=1e-12)
    assert not np.allclose(own, whole, rtol=1e-9, atol=1e-12)
    for bad in ([1.0], [1.0, np.nan], [1.0, -1.0]):
        with pytest.raises(subid.errors.DataError, match="output_std must hold 2"):
            subid.predict(model, head, 1, output_std=bad)
