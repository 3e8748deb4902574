"""subid.pem: prediction-error refinement.

Acceptance of issue 11: exact on noise-free data, never worse than its start
(property test), closed-loop Monte Carlo against n4sid, open-loop 25 dB
behaviour; the compiled Jacobian against its reference and finite differences.
"""

from __future__ import annotations

import importlib  # noqa: E402
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import subid
from subid import systems
from subid.errors import DataError, ModelError, SubidError
from subid.model._sensitivity import jacobian, jacobian_ref

pem_module = importlib.import_module("subid.methods.dt.pem")   # the module (subid.pem is the function)


def _random_directions(rng, d, n, ny, m):
    return (rng.standard_normal((d, n, n)), rng.standard_normal((d, n, m)),
            rng.standard_normal((d, ny, n)), rng.standard_normal((d, ny, m)),
            rng.standard_normal((d, n)))


def _random_predictor(rng, n, ny, m, N, gain):
    """A random stable predictor ``(Ap, Bp, C, Dp)``, its signal ``v`` and ``x0``."""
    Ap = gain * rng.standard_normal((n, n)) / np.sqrt(n)
    Bp, C, Dp = rng.standard_normal((n, m)), rng.standard_normal((ny, n)), \
        rng.standard_normal((ny, m))
    return Ap, Bp, C, Dp, rng.standard_normal((N, m)), rng.standard_normal(n)


def test_compiled_jacobian_matches_reference():
    rng = np.random.default_rng(0)
    n, ny, m, d, N = 3, 2, 4, 5, 60
    Ap, Bp, C, Dp, v, x0 = _random_predictor(rng, n, ny, m, N, 0.5)
    dirs = _random_directions(rng, d, n, ny, m)
    y1, J1 = jacobian(Ap, Bp, C, Dp, v, x0, *dirs)
    y2, J2 = jacobian_ref(Ap, Bp, C, Dp, v, x0, *dirs)
    assert np.abs(y1 - y2).max() < 1e-12 and np.abs(J1 - J2).max() < 1e-12


@pytest.mark.parametrize("blocked", [False, True])
def test_both_forms_of_the_jacobian_match_reference(blocked, monkeypatch):
    """The per-direction loop and the blocked form (forcing by matrix products over
    blocks of samples, a record length not a multiple of the block) give the reference's
    Jacobian, with and without initial-state-only directions run apart."""
    from subid.model import _sensitivity
    monkeypatch.setattr(_sensitivity, "BLOCKED_WORK", 0 if blocked else 10**12)
    rng = np.random.default_rng(5)
    n, ny, m, d, N = 6, 3, 2, 14, 3 * _sensitivity.BLOCK + 7
    Ap, Bp, C, Dp, v, x0 = _random_predictor(rng, n, ny, m, N, 0.6)
    dirs = list(_random_directions(rng, d, n, ny, m))
    y1, J1 = jacobian(Ap, Bp, C, Dp, v, x0, *dirs)
    y2, J2 = jacobian_ref(Ap, Bp, C, Dp, v, x0, *dirs)
    assert np.abs(y1 - y2).max() < 1e-12 and np.abs(J1 - J2).max() < 1e-12
    for j in (2, 9):                          # pure initial-state directions
        for a in dirs[:4]:
            a[j] = 0.0
    long = np.vstack([v] * 40)
    y1, J1 = jacobian(Ap, Bp, C, Dp, long, x0, *dirs)
    y2, J2 = jacobian_ref(Ap, Bp, C, Dp, long, x0, *dirs)
    assert np.abs(y1 - y2).max() < 1e-12 and np.abs(J1 - J2).max() < 1e-12
    assert np.all(J1[-1, :, [2, 9]] == 0.0)


@pytest.mark.parametrize("blocked", [False, True])
def test_the_jacobian_continues_from_its_final_state(blocked, monkeypatch):
    """``final_state=True`` gives the state and sensitivities after the last sample: the
    record run in pieces (odd and even lengths, each from the last piece's end) gives
    the whole record's output and Jacobian, with free initial-state directions too, and
    the reference's final state."""
    from subid.model import _sensitivity
    monkeypatch.setattr(_sensitivity, "BLOCKED_WORK", 0 if blocked else 10**12)
    rng = np.random.default_rng(8)
    n, ny, m, d, N = 5, 2, 3, 9, 301
    Ap, Bp, C, Dp, v, x0 = _random_predictor(rng, n, ny, m, N, 0.7)
    dirs = list(_random_directions(rng, d, n, ny, m))
    for a in dirs[:4]:
        a[4] = 0.0                            # a pure initial-state direction
    y_ref, J_ref, x_ref, S_ref = jacobian_ref(Ap, Bp, C, Dp, v, x0, *dirs, final_state=True)
    ys, Js, x, S = [], [], x0, dirs[4]
    for a, b in ((0, 33), (33, 100), (100, 101), (101, N)):
        y, J, x, S = jacobian(Ap, Bp, C, Dp, v[a:b], x, *dirs[:4], S, final_state=True)
        ys.append(y)
        Js.append(J)
    assert np.abs(np.vstack(ys) - y_ref).max() < 1e-12
    assert np.abs(np.concatenate(Js) - J_ref).max() < 1e-12
    assert np.abs(x - x_ref).max() < 1e-12 and np.abs(S - S_ref).max() < 1e-12


@pytest.mark.parametrize("radius, N", [(0.999, 1000), (0.9, 64), (0.3, 5000)])
def test_free_response_by_blocks_matches_the_recursion(radius, N):
    """The free response ``C Ap^t S0`` computed by blocks of FREE_BLOCK samples equals
    the step-by-step recursion (a slow pole over a record that is not a multiple of the
    block, one block exactly, and a fast pole whose response is zero past the floor),
    and so does the state it returns."""
    from subid.model import _sensitivity
    rng = np.random.default_rng(3)
    n, ny, k = 4, 2, 3
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    Ap = Q @ np.diag(radius * np.array([1.0, -0.9, 0.7, 0.2])) @ Q.T
    C, S0 = rng.standard_normal((ny, n)), rng.standard_normal((n, k))
    ref, S = np.empty((N, ny, k)), S0.copy()
    for t in range(N):
        ref[t] = C @ S
        S = Ap @ S
    out = np.empty((N, ny, k))
    end = _sensitivity._free_response_t(Ap, C, S0, _sensitivity._floor(S0), out, 0)
    scale = np.abs(ref).max()
    assert np.abs(out - ref).max() <= 1e-12 * scale
    if radius ** N > 1e-140:
        assert np.abs(end - S).max() <= 1e-12 * np.abs(S0).max()
    else:                                    # decayed: zero past the floor
        assert np.all(out[-1] == 0.0) and np.all(end == 0.0)


def test_initial_state_directions_match_reference():
    # directions that move x0 alone run in their own loop (free_response), stopped once
    # decayed: same Jacobian as the reference, in any column order, on a record long
    # enough for the free response to fall far below the subnormal range
    rng = np.random.default_rng(2)
    n, ny, m, N = 3, 2, 2, 3000
    Ap, Bp, C, Dp, v, x0 = _random_predictor(rng, n, ny, m, N, 0.5)
    dirs = list(_random_directions(rng, 5, n, ny, m))
    for j in (1, 3, 4):                       # pure initial-state directions
        for a in dirs[:4]:
            a[j] = 0.0
    y1, J1 = jacobian(Ap, Bp, C, Dp, v, x0, *dirs)
    y2, J2 = jacobian_ref(Ap, Bp, C, Dp, v, x0, *dirs)
    assert np.abs(y1 - y2).max() < 1e-12 and np.abs(J1 - J2).max() < 1e-12
    assert np.all(J1[-1, :, [1, 3, 4]] == 0.0) and np.all(J1[-1, :, [0, 2]] != 0.0)
    only = [a[[1, 3, 4]] for a in dirs]        # free directions alone
    y3, J3 = jacobian(Ap, Bp, C, Dp, v, x0, *only)
    assert np.abs(y3 - y2).max() < 1e-12 and np.abs(J3 - J2[:, :, [1, 3, 4]]).max() < 1e-12


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    n, ny, m, N = 3, 2, 3, 40
    Ap, Bp, C, Dp, v, x0 = _random_predictor(rng, n, ny, m, N, 0.4)
    dirs = _random_directions(rng, 1, n, ny, m)
    _, J = jacobian_ref(Ap, Bp, C, Dp, v, x0, *dirs)
    h = 1e-6

    def out(s):
        return jacobian_ref(Ap + s * dirs[0][0], Bp + s * dirs[1][0], C + s * dirs[2][0],
                            Dp + s * dirs[3][0], v, x0 + s * dirs[4][0],
                            *_random_directions(rng, 0, n, ny, m))[0]
    fd = (out(h) - out(-h)) / (2 * h)
    assert np.abs(fd - J[:, :, 0]).max() < 1e-6 * max(1.0, np.abs(fd).max())


def test_local_coordinates_are_orthogonal_to_similarity_directions():
    true = systems.seed001_innovation_system()
    layout = pem_module._Layout(3, 2, 2, True, True)
    basis = pem_module._local_coordinates(layout, true.A, true.B, true.C, true.D, true.K)
    assert basis.shape == (layout.size, layout.size - 9)
    E = np.zeros((3, 3))
    E[0, 2] = 1.0
    tangent = layout.pack(E @ true.A - true.A @ E, E @ true.B, -true.C @ E, 0 * true.D,
                          E @ true.K)
    assert np.abs(basis.T @ tangent).max() < 1e-12


@pytest.mark.parametrize("focus", ["prediction", "simulation"])
def test_noise_free_data_keep_the_exact_model(paper_system, focus):
    data = systems.simulate_data(paper_system, 800, seed=3)
    start = subid.ls_subspace(data, 3)
    refined = subid.pem(data, start, focus=focus)
    assert subid.markov_error(refined, paper_system, k=20) < 1e-10
    assert refined.info["final_cost"] <= refined.info["start_cost"]


def test_true_start_stays_near_truth():
    true = systems.seed001_innovation_system()
    data = systems.simulate_innovation_data(true, 3000, seed=11)
    refined = subid.pem(data, true)
    assert subid.markov_error(refined, true) < 0.02
    assert refined.info["final_cost"] <= refined.info["start_cost"]


@given(seed=st.integers(0, 10_000), order=st.integers(1, 3), n_inputs=st.integers(1, 2),
       n_outputs=st.integers(1, 2), scale=st.floats(0.0, 0.3))
def test_pem_never_increases_the_estimation_cost(seed, order, n_inputs, n_outputs, scale):
    sys_ = systems.random_system(order, n_inputs, n_outputs, seed=seed)
    data = systems.simulate_data(sys_, 400, seed=seed + 1, output_snr_db=15,
                                 process_snr_db=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = subid.n4sid(data, order)
    rng = np.random.default_rng(seed)
    A = start.A + scale * rng.standard_normal(start.A.shape) / max(order, 1)
    if np.abs(np.linalg.eigvals(A)).max() < 0.98:                 # a perturbed, worse start
        start = subid.StateSpace(A, start.B, start.C, start.D, start.dt, K=start.K,
                                 noise_cov=start.noise_cov)
    for focus in ("prediction", "simulation"):
        try:
            refined = subid.pem(data, start, focus=focus, max_iterations=30)
        except ModelError:
            assert focus == "simulation" and not start.is_stable()
            continue
        info = refined.info
        assert info["final_cost"] <= info["start_cost"] * (1 + 1e-12)
        hist = np.asarray(info["cost_history"])
        assert hist[0] == info["start_cost"] and np.all(np.diff(hist) < 0) and \
            hist[-1] == info["final_cost"]
        assert isinstance(info["stop_reason"], str) and info["stop_reason"]
        if focus == "prediction":
            assert np.abs(np.linalg.eigvals(refined.A - refined.K @ refined.C)).max() < 1
        else:
            assert refined.is_stable()


def _closed_loop_runs(runs=10):
    true = systems.seed001_innovation_system(feedthrough=False)
    F = -0.3 * np.eye(2)          # u = r - F y, closed loop spectral radius 0.755
    subspace, refined = [], []
    for r in range(runs):
        data = systems.simulate_innovation_data(true, 3000, seed=100 + r, feedback=F)
        start = subid.n4sid(data, 3, feedthrough=False)
        subspace.append(subid.markov_error(start, true))
        refined.append(subid.markov_error(subid.pem(data, start), true))
    return np.median(subspace), np.median(refined)


@pytest.mark.slow
def test_closed_loop_pem_halves_the_n4sid_error():
    # measured: n4sid 0.0837, pem 0.0157 (0.19x)
    e_n4sid, e_pem = _closed_loop_runs()
    assert e_pem <= 0.5 * e_n4sid, (e_n4sid, e_pem)


@pytest.mark.slow
def test_open_loop_25db_pem_is_not_worse_than_its_start(paper_system):
    start_err, pem_err, start_pred, pem_pred = [], [], [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for r in range(20):
            data = systems.simulate_data(paper_system, 1000, seed=r, process_snr_db=25,
                                         output_snr_db=25)
            fresh = systems.simulate_data(paper_system, 1000, seed=1000 + r,
                                          process_snr_db=25, output_snr_db=25)
            start = subid.n4sid(data, 3)
            refined = subid.pem(data, start)
            start_err.append(subid.markov_error(start, paper_system))
            pem_err.append(subid.markov_error(refined, paper_system))
            for m, out in ((start, start_pred), (refined, pem_pred)):
                e = fresh.y - subid.predict(m, fresh, 1)
                out.append(np.linalg.det(np.cov(e.T)))
    # measured: median Markov error 0.00907 -> 0.00864 (0.95x); det of the fresh one-step
    # error covariance 0.995x
    assert np.median(pem_err) <= 1.2 * np.median(start_err)
    assert np.median(pem_pred) <= np.median(start_pred)


def test_refine_option_of_the_batch_methods(paper_data):
    for method in (subid.ls_subspace, subid.moesp, subid.n4sid):
        model = method(paper_data, 3, refine="pem")
        assert model.info["refined_by"] == "pem" and model.K is not None
    with pytest.raises(SubidError, match="refine"):
        subid.n4sid(paper_data, 3, refine="ssest")
    stat = subid.HankelStatistic.from_data(paper_data, 10)
    with pytest.raises(SubidError, match="raw record"):
        subid.moesp(stat, 3, refine="pem")


def test_continuous_time_start_is_refined_through_its_discretisation():
    true = systems.seed000_system()
    dt = 0.05
    t = np.arange(1500) * dt
    u = np.random.default_rng(0).standard_normal((1500, true.n_inputs))
    y = true.simulate(u, t=t)
    y = y + 0.05 * y.std(axis=0) * np.random.default_rng(1).standard_normal(y.shape)
    data = subid.IOData(u, y, dt=dt)
    start = subid.StateSpace(1.05 * true.A, true.B, true.C, true.D, 0.0)   # a biased start
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        refined = subid.pem(data, start, focus="simulation")
    assert refined.is_continuous and refined.K is None
    assert "discretisation" in refined.info["pem_through"]
    assert refined.info["final_cost"] < refined.info["start_cost"]
    u2 = np.random.default_rng(2).standard_normal((1500, true.n_inputs))
    fresh = subid.IOData(u2, true.simulate(u2, t=t), t=t)
    assert np.all(subid.fit_percent(refined, fresh) > subid.fit_percent(start, fresh))


def test_refined_model_saves_and_loads(paper_data, tmp_path):
    model = subid.pem(paper_data, subid.n4sid(paper_data, 3))
    model.save(tmp_path / "m.json")
    back = subid.StateSpace.load(tmp_path / "m.json")
    assert np.array_equal(back.K, model.K)
    assert np.array_equal(back.info["cost_history"], model.info["cost_history"])


def test_pem_bad_input(paper_system, paper_data):
    start = subid.n4sid(paper_data, 3)
    with pytest.raises(DataError, match="outputs"):
        subid.pem(subid.IOData(paper_data.u, paper_data.y[:, :1], dt=1.0), start)
    with pytest.raises(DataError, match="IOData"):
        subid.pem((paper_data.u, paper_data.y), start)
    with pytest.raises(ModelError):
        subid.pem(paper_data, "model")
    with pytest.raises(SubidError, match="focus"):
        subid.pem(paper_data, start, focus="both")
    with pytest.raises(SubidError, match="max_iterations"):
        subid.pem(paper_data, start, max_iterations=0)
    with pytest.raises(DataError, match="too few"):
        subid.pem(paper_data.split(0.01)[0], start)
    unstable = subid.StateSpace(1.2 * np.eye(3), start.B, start.C, start.D, 1.0)
    with pytest.raises(ModelError, match="unstable"):
        subid.pem(paper_data, unstable, focus="simulation")


def test_covariance_gram_route_equals_qr_route(monkeypatch):
    """The parameter covariance from the Cholesky factor of the Gram matrix (the route
    taken when well conditioned) equals the one from the Householder QR of J."""
    from subid.methods.dt import _covariance, _trust_region
    rng = np.random.default_rng(4)
    J = rng.standard_normal((500, 2, 7)) @ np.diag([1.0, 3.0, 0.2, 1.0, 5.0, 1.0, 0.5])
    res = rng.standard_normal((500, 2))
    gram, lam = _covariance.covariance_factor(J.copy(), res, 2)   # J is overwritten
    # the columns in another order, put back by the factor's permutation: the same
    perm = np.array([3, 0, 6, 1, 5, 2, 4])
    back = np.argsort(perm)
    permuted, _ = _covariance.covariance_factor(J[:, :, perm].copy(), res, 2, order=back)
    assert np.allclose(gram @ gram.T, permuted @ permuted.T, rtol=1e-10, atol=0)
    monkeypatch.setattr(_trust_region, "GRAM_PIVOT", 2.0)           # forces the QR route
    qr, lam2 = _covariance.covariance_factor(J.copy(), res, 2)
    assert np.allclose(gram @ gram.T, qr @ qr.T, rtol=1e-10, atol=0)
    assert np.array_equal(lam, lam2)
    qr_permuted, _ = _covariance.covariance_factor(J[:, :, perm].copy(), res, 2, order=back)
    assert np.allclose(qr @ qr.T, qr_permuted @ qr_permuted.T, rtol=1e-10, atol=0)


@pytest.mark.parametrize("pivot", [None, 2.0])
def test_a_jacobian_given_in_pieces_gives_the_whole_ones_factors(pivot, monkeypatch):
    """The trust region's factor (R, Q^T f, J^T f, norms) and the covariance factor of a
    Jacobian summed a piece at a time equal those of the whole Jacobian, on the Gram
    route and on the QR route (GRAM_PIVOT above 1 forces it); pieces of uneven length,
    one shorter than the number of columns."""
    from subid.methods.dt import _covariance, _trust_region
    if pivot is not None:
        monkeypatch.setattr(_trust_region, "GRAM_PIVOT", pivot)
    rng = np.random.default_rng(9)
    J = rng.standard_normal((431, 2, 7)) @ np.diag([1.0, 3.0, 0.2, 1.0, 5.0, 1.0, 0.5])
    f = rng.standard_normal(431 * 2)
    cuts = [0, 3, 120, 121, 300, 431]                   # samples; 3 samples: 6 rows < 7
    whole = _trust_region.compress(J.reshape(-1, 7), f)

    def rows():
        for a, b in zip(cuts[:-1], cuts[1:]):
            yield 2 * a, 2 * b, J[a:b].reshape(-1, 7)
    passes, folded = [], []

    def counted_rows():
        passes.append(1)
        yield from rows()
    real_geqrf = _trust_region.geqrf_r
    monkeypatch.setattr(_trust_region, "geqrf_r",
                        lambda w, r, **k: folded.append(w.shape[0]) or real_geqrf(w, r, **k))
    pieced = _trust_region.compress_pieces(counted_rows, f, 7)
    assert whole[4] == pieced[4] == ("gram" if pivot is None else "qr")
    R1, R2 = whole[0], pieced[0]
    np.testing.assert_allclose(R1.T @ R1, R2.T @ R2, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(R1.T @ whole[1], R2.T @ pieced[1], rtol=1e-10, atol=1e-10)
    for a, b in zip(whole[2:4], pieced[2:4]):
        np.testing.assert_allclose(a, b, rtol=1e-12)
    # the QR route: a second pass over the pieces, each folded under the triangle of
    # those before it alone (at most 8 rows), not under every row of their R
    assert len(passes) == (1 if pivot is None else 2)
    pieces_rows = [2 * (b - a) for a, b in zip(cuts[:-1], cuts[1:])]
    assert folded == ([] if pivot is None else
                      [pieces_rows[0]] + [min(8, sum(pieces_rows[:k])) + r
                                          for k, r in enumerate(pieces_rows) if k])
    # expecting the QR route (householder=True): one pass, the same factor either way
    passes.clear()
    expected = _trust_region.compress_pieces(counted_rows, f, 7, householder=True)
    assert len(passes) == 1
    for a, b in zip(pieced[:4], expected[:4]):
        np.testing.assert_array_equal(a, b)
    assert expected[4] == pieced[4]
    res = rng.standard_normal((431, 2))
    F1, lam1 = _covariance.covariance_factor(J.copy(), res, 2)
    F2, lam2 = _covariance.covariance_factor_pieces(
        lambda: (J[a:b].copy() for a, b in zip(cuts[:-1], cuts[1:])), res, 2, 7)
    np.testing.assert_allclose(F1 @ F1.T, F2 @ F2.T, rtol=1e-10, atol=0)
    assert np.array_equal(lam1, lam2)


@pytest.mark.parametrize("focus", ["prediction", "simulation"])
def test_pem_with_its_jacobian_in_pieces_gives_the_same_model(focus, monkeypatch):
    """JACOBIAN_PIECE_BYTES made small enough that a record of two experiments is run in
    pieces of 701 samples (each continuing from the last's state and sensitivities):
    the same refined model, initial states and parameter covariance as with the whole
    Jacobian (to the rounding the sums' order leaves after the iterations)."""
    from subid.methods.dt import _pe_search
    true = systems.random_system(3, 2, 2, seed=11)
    parts = [systems.simulate_data(true, 2500, seed=s, output_snr_db=25,
                                   process_snr_db=20 if focus == "prediction" else None)
             for s in (12, 13)]
    data = subid.merge(parts)
    start = subid.n4sid(data, 3, feedthrough=False)
    whole = subid.pem(data, start, focus=focus)
    width = 3 * (2 + 2) + 6 * (focus == "prediction") + 2 * 3      # > the columns
    monkeypatch.setattr(_pe_search, "JACOBIAN_PIECE_BYTES", 8 * 2 * width * 701)
    from subid.methods.dt import _trust_region, pem
    calls = []

    def counted(module, name):
        real = getattr(module, name)
        monkeypatch.setattr(module, name,
                            lambda *a, **k: calls.append(name) or real(*a, **k))
    counted(_trust_region, "compress_pieces")
    counted(pem, "covariance_factor_pieces")
    pieced = subid.pem(data, start, focus=focus)
    assert calls.count("covariance_factor_pieces") == 1
    assert calls.count("compress_pieces") >= 2        # every Jacobian of the iterations
    for name in ("A", "B", "C", "D") + (("K",) if focus == "prediction" else ()):
        np.testing.assert_allclose(getattr(pieced, name), getattr(whole, name),
                                   rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(pieced.info["x0"], whole.info["x0"], rtol=1e-5, atol=1e-8)
    assert pieced.info["final_cost"] == pytest.approx(whole.info["final_cost"], rel=1e-9)
    F1 = whole.info["parameter_covariance"]["factor"]
    F2 = pieced.info["parameter_covariance"]["factor"]
    np.testing.assert_allclose(F2 @ F2.T, F1 @ F1.T, rtol=1e-4,
                               atol=1e-6 * np.abs(F1 @ F1.T).max())


def test_a_refined_polynomial_model_keeps_no_stale_polynomials():
    """pem refines an arx start as a state-space model: the start's polynomials (which
    the report and the .mat idpoly fields used) no longer describe the result, whose
    poles moved (their simulations differed by 27 % of the peak): they move to
    info['refined_from'], and the bounds still work."""
    import scipy.signal as ss
    rng = np.random.default_rng(0)
    u, e = rng.standard_normal(600), 0.2 * rng.standard_normal(600)
    y = ss.lfilter([0, 1, 0.5], [1, -1.2, 0.5], u) + ss.lfilter([1, 0.5], [1, -1.2, 0.5], e)
    data = subid.IOData(u, y, dt=1.0)
    start = subid.arx(data, (2, 2, 1))
    refined = subid.pem(data, start)
    assert "polynomials" not in refined.info and "orders" not in refined.info
    moved = refined.info["refined_from"]
    assert moved["method"] == "arx"
    np.testing.assert_array_equal(moved["start_polynomials"]["A"],
                                  start.info["polynomials"]["A"])
    assert not np.allclose(np.sort_complex(refined.poles()), np.sort_complex(start.poles()))
    assert subid.freqresp_bounds(refined, [0.1, 1.0]).std is not None


@pytest.mark.parametrize("u_unit,y_unit", [(1e-2, 1e2), (1e2, 1e-2), (1e3, 1.0)])
def test_pem_reaches_a_noise_free_model_in_any_units(u_unit, y_unit):
    """The same start in other units: the iteration runs on unit-spread channels, so a
    noise-free record is fitted exactly whatever the units (inputs 100x smaller and
    outputs 100x larger stopped on ftol at a Markov error of 0.04 before)."""
    true = subid.systems.seed001_system()
    data = subid.systems.simulate_data(true, 800, seed=1)
    scaled = data.scaled(inputs=[u_unit, u_unit], outputs=[y_unit, y_unit])
    A0 = true.A * (1 + 0.03 * np.random.default_rng(3).standard_normal((3, 3)))
    start = subid.StateSpace(A0, true.B * 1.05 / u_unit, true.C * y_unit,
                             true.D * y_unit / u_unit, 1.0, K=np.zeros((3, 2)),
                             noise_cov=np.eye(2) * y_unit ** 2)
    in_units = subid.StateSpace(true.A, true.B / u_unit, true.C * y_unit,
                                true.D * y_unit / u_unit, 1.0)
    refined = subid.pem(scaled, start)
    assert subid.markov_error(refined, in_units) < 1e-9
