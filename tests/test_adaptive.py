"""AdaptiveIdentifier (seed 000): acceptance runs, exactness, chunking,
checkpoints, windup, bad input, kernel against the numpy reference."""

import os

import numpy as np
import pytest

import subid
from subid.data import IOData
from subid.errors import CheckpointError, DataError, DataFileNotFoundError, OrderError, SubidError
from subid.experiments.seed000 import multisine, paper_system, relative_error, simulate
from subid.methods.online import _adaptive_kernel as K
from subid.methods.online import _adaptive_reference as R
from subid.methods.online.adaptive import AdaptiveIdentifier
from subid.model._simulate import expm_blocks
from subid.model.statespace import StateSpace

DT = 1e-3


def paper_ident(**kw):
    kw.setdefault("filter_poles", -5.0)
    return AdaptiveIdentifier(4, 2, 2, horizon=5, dt=DT, **kw)


def true_in_basis(ident, true):
    """(Ã°, B̃°, C̃°) of (23): the true system in the basis fixed by H."""
    w, f = ident.time_scale, 5
    blocks, X = [], true.C
    for _ in range(f):
        blocks.append(X)
        X = X @ (true.A / w)
    T = ident.selector @ np.vstack(blocks)
    Ti = np.linalg.inv(T)
    return T @ true.A @ Ti, T @ true.B, true.C @ Ti


def state_arrays(ident):
    return ident._buf.copy(), ident._st["ist"].copy(), ident._st["hist"].copy()


def assert_same_state(a, b):
    for x, y in zip(state_arrays(a), state_arrays(b)):
        np.testing.assert_array_equal(x, y)


@pytest.fixture(scope="module")
def clean200():
    return simulate(200.0)


@pytest.fixture(scope="module")
def short_record():
    return simulate(8.0)


# ---------------------------------------------------------------------------
# acceptance on the paper's system (Section V)
# ---------------------------------------------------------------------------
@pytest.mark.slow
def test_noise_free_paper_system_within_200s(clean200):
    t, u, y = clean200
    true = paper_system()
    ident = paper_ident(forgetting=0.4, bd_forgetting=0.08, history_size=256)
    ident.update(u, y)
    model = ident.model
    assert model.dt == 0 and model.info["samples"] == t.size
    assert subid.pole_error(model, true) < 1e-3
    assert relative_error(model, true) < 1e-3
    # the basis is the one fixed by H (23), not just any realisation
    A0, B0, C0 = true_in_basis(ident, true)
    assert np.abs(model.A - A0).max() < 1e-3 * np.abs(A0).max()
    assert np.abs(model.C - C0).max() < 1e-3 * np.abs(C0).max()
    assert np.abs(model.B - B0).max() < 1e-3 * np.abs(B0).max()
    assert np.abs(model.D - true.D).max() < 1e-3
    # converged well within the record: the last half of the history is good
    hist = ident.history
    late = hist["t"] > 100
    for k in np.flatnonzero(late):
        m = StateSpace(hist["A"][k], hist["B"][k], hist["C"][k], hist["D"][k], 0)
        assert subid.pole_error(m, true) < 1e-3 and relative_error(m, true) < 1e-3


@pytest.mark.slow
def test_output_noise_50db_after_400s():
    t, u, y = simulate(400.0, snr_db=50.0, noise_seed=7)
    true = paper_system()
    ident = paper_ident(forgetting=0.01, bd_forgetting=0.008, method="ls")
    ident.update(u, y)
    assert relative_error(ident.model, true) < 0.05
    assert subid.pole_error(ident.model, true) < 0.1


def test_part2_starts_when_the_residual_stops_improving():
    """At 40 dB the residual of (13) never reaches bd_gate; (B̃, D) estimation
    starts once it has stopped halving for one elapsed time since the last
    halving (not one memory length 1/α = 100 s: issue 23)."""
    t, u, y = simulate(300.0, snr_db=40.0, noise_seed=2)
    ident = paper_ident(forgetting=0.01, bd_forgetting=0.008, method="ls")
    ident.update(u, y)
    info = ident.model.info
    assert info["bd_started"] and info["shift_residual"] > 1e-2
    assert 5 <= info["bd_start_time"] <= 50
    assert relative_error(ident.model, paper_system()) < 0.1


@pytest.mark.slow
def test_windup_constant_input_then_excitation_returns():
    """10^6 samples, input constant from half-way; then excitation returns."""
    true = paper_system()
    t = np.arange(1_200_000) * DT
    u = multisine(t, 2, seed=3)
    u[500_000:1_000_000] = u[500_000]
    y = true.simulate(u, t=t, hold="foh")
    # the paper's noise-free memory (1/α = 2.5 s): 500 s of constant input
    # decay the unexcited directions far beyond the windup bound
    ident = paper_ident(history_size=512, forgetting=0.4, bd_forgetting=0.08)
    ident.update(u[:500_000], y[:500_000])
    assert subid.pole_error(ident.model, true) < 1e-3
    ident.update(u[500_000:1_000_000], y[500_000:1_000_000])
    # issue 23: the constant input is not persistently exciting, and the model says so
    with pytest.warns(subid.errors.NotConvergedWarning, match="no longer persistently"):
        model = ident.model
    assert not model.info["excited"]
    assert model.info["windup_active"] and model.info["bd_windup_active"]
    assert np.isfinite(ident._buf).all()
    # held where the data stopped informing: bounded and still accurate
    assert subid.pole_error(model, true) < 1e-3
    assert relative_error(model, true) < 1e-3
    hist = ident.history
    A0 = true_in_basis(ident, true)[0]
    after = hist["t"] > 20
    assert np.abs(hist["A"][after]).max() < 2 * np.abs(A0).max()
    ident.update(u[1_000_000:], y[1_000_000:])
    model = ident.model
    assert not model.info["windup_active"]
    assert subid.pole_error(model, true) < 1e-3
    assert relative_error(model, true) < 1e-3


@pytest.mark.slow
def test_ode_form_stays_finite_under_windup():
    true = paper_system()
    t = np.arange(300_000) * DT
    u = multisine(t, 2, seed=4)
    u[100_000:] = u[100_000]
    y = true.simulate(u, t=t, hold="foh")
    ident = paper_ident(method="ode", ode_trace_bound=1e6)
    ident.update(u, y)
    assert np.isfinite(ident._buf).all()
    assert np.abs(ident.model.A).max() < 100
    assert ident.model.info["bound_hits"] > 0      # the bound did act


def test_ls_much_faster_than_ode_form(clean200):
    """The exact minimiser converges in seconds; the Euler-integrated ODE
    form (11)-(12), (19)-(20) is still far off after 60 s."""
    t, u, y = clean200
    true = paper_system()
    n = 60_001
    ls, ode = paper_ident(method="ls"), paper_ident(method="ode")
    ls.update(u[:n], y[:n])
    ode.update(u[:n], y[:n])
    assert relative_error(ls.model, true) < 1e-3
    assert relative_error(ode.model, true) > 1e-2


# ---------------------------------------------------------------------------
# numerics
# ---------------------------------------------------------------------------
def test_scaled_filter_states_are_better_conditioned(clean200):
    t, u, y = clean200
    conds = {}
    for scale in (False, True):
        ident = paper_ident(forgetting=1e-9, bd_forgetting=1e-9, scale_filters=scale,
                            initial_covariance=1e14, method="ls")
        ident.update(u[:60_001], y[:60_001])
        conds[scale] = ident.information_condition()[0]
    assert conds[False] > 1e9
    assert conds[True] < 1e7
    assert conds[False] > 100 * conds[True]


def test_error_floor_is_inter_sample_interpolation():
    """Exact for held signals: the remaining error of the recursion is the
    O(h^2) error of interpolating the true output linearly between samples
    (the recursion's own estimate: refine=False; the refit is not used
    noise-free, see docs/seed000.md)."""
    true = paper_system()
    errs = []
    for h in (2e-3, 1e-3):
        t = np.arange(int(30 / h) + 1) * h
        u = multisine(t, 2)
        y = true.simulate(u, t=t, hold="foh")
        ident = AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0, dt=h, refine=False)
        ident.update(u, y)
        errs.append(subid.pole_error(ident.model, true))
    assert errs[1] < 1e-4
    assert 2.5 < errs[0] / errs[1] < 6      # ~4: second order in h


@pytest.mark.slow
def test_nonuniform_time_stamps_converge():
    true = paper_system()
    rng = np.random.default_rng(5)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 20_000))])
    u = multisine(t, 2)
    y = true.simulate(u, t=t, hold="foh")
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0)
    ident.update(u, y, t=t)
    assert ident.t == t[-1]
    assert subid.pole_error(ident.model, true) < 1e-3
    assert relative_error(ident.model, true) < 1e-3


def test_filtered_state(clean200):
    """x̃ = H (p̂ - T_f q̂) is F̂(s) applied to the state of the model basis."""
    t, u, y = clean200
    n = 30_001
    true = paper_system()
    ident = paper_ident()
    ident.update(u[:n], y[:n])
    _, x = true.simulate(u[:n], t=t[:n], hold="foh", return_state=True)
    filt = StateSpace(ident._Af, ident._Bf, np.eye(5)[:1], 0, 0.0)
    xbar = np.array([filt.simulate(x[:, i], t=t[:n], hold="foh")[-1, 0] for i in range(4)])
    w = ident.time_scale
    blocks, X = [], true.C
    for _ in range(5):
        blocks.append(X)
        X = X @ (true.A / w)
    expected = ident.selector @ np.vstack(blocks) @ xbar
    assert np.abs(ident.state - expected).max() < 1e-3 * np.abs(expected).max()


def test_phi_blocks_match_expm_blocks():
    rng = np.random.default_rng(0)
    for n in (1, 2, 4, 6):
        A = rng.standard_normal((n, n)) * 2
        for h in (1e-4, 1e-2, 0.7, 20.0):
            Phi, G1, G2 = (np.empty((n, n)) for _ in range(3))
            K.phi_blocks(A, h, Phi, G1, G2, np.empty((5, n, n)))
            P0, R1, R2 = expm_blocks(A, np.eye(n), [h], "foh")
            scale = max(1.0, np.abs(P0).max())
            assert np.abs(Phi - P0[0]).max() < 1e-12 * scale
            assert np.abs(G1 - R1[0]).max() < 1e-12 * max(scale, np.abs(R1).max())
            assert np.abs(G2 - R2[0]).max() < 1e-12 * max(scale, np.abs(R2).max())


def test_hurwitz_test_agrees_with_eigenvalues():
    rng = np.random.default_rng(1)
    checked = 0
    for n in range(1, 9):
        for _ in range(40):
            A = rng.standard_normal((n, n)) - rng.uniform(0, 1.5) * np.eye(n)
            margin = np.linalg.eigvals(A).real.max()
            if abs(margin) < 1e-6:
                continue
            assert K._hurwitz(A) == (margin < 0), (n, margin)
            checked += 1
    assert checked > 250


def test_shift_solve_matches_least_squares():
    rng = np.random.default_rng(2)
    M = rng.standard_normal((10, 14))
    A = np.empty((4, 4))
    res = K._shift_solve(M, 4, 2, 3.0, A)
    X, *_ = np.linalg.lstsq(M[:8, :4], M[2:, :4], rcond=None)
    np.testing.assert_allclose(A, 3.0 * X, rtol=1e-12, atol=1e-12)
    expected = np.linalg.norm(M[2:, :4] - M[:8, :4] @ X) / np.linalg.norm(M[2:, :4])
    assert res == pytest.approx(expected, rel=1e-10)
    M[:, 1] = 0.0                                  # rank deficient: no update
    assert K._shift_solve(M, 4, 2, 3.0, A) == -1.0


def _iv_problem(seed, cond_scale=1.0):
    rng = np.random.default_rng(seed)
    dz, d, rows = 24, 14, 10
    zeta = rng.standard_normal((400, dz))
    phi = zeta[:, :d] @ np.diag(np.logspace(0, -np.log10(cond_scale) if cond_scale > 1 else 0, d)) \
        + 0.1 * rng.standard_normal((400, d))
    Z = zeta.T @ zeta
    C = zeta.T @ phi
    S = rng.standard_normal((rows, dz))
    return C, S, Z


@pytest.mark.parametrize("cond_scale", [1.0, 1e4])
def test_iv_step_is_two_stage_least_squares(cond_scale):
    """The refresh step of the IV estimate (normal equations of the whitened
    problem, residual form) against the closed form M = S Z^-1 C (C^T Z^-1 C)^-1
    and against the numpy reference, from X = 0 and after one refinement."""
    C, S, Z = _iv_problem(3, cond_scale)
    dz, d = C.shape
    rows = S.shape[0]
    Zi = np.linalg.inv(Z)
    expected = S @ Zi @ C @ np.linalg.inv(C.T @ Zi @ C)
    X = np.zeros((rows, d))
    G = S.copy()                                   # G = S - X C^T at X = 0
    Xr, Gr = X.copy(), G.copy()
    scratch = (np.zeros((dz, dz)), np.empty((dz, d)), np.empty((rows, dz)), np.empty((d, d)),
               np.empty((rows, d)), np.zeros((d, d)), np.empty((d, rows)), np.zeros(1 + 2 * d))
    for _ in range(2):                             # second pass: refinement of the first
        assert K._solve_iv_weighted(C, G, np.tril(Z), X, 1e10, *scratch)
        excitation = R._ref_solve_iv_weighted(C, Gr, np.tril(Z), Xr, 1e10)
        # the excitation test (issue 23): kernel and reference agree
        assert excitation is not None
        assert abs(scratch[-1][0] - excitation) <= 1e-6 * abs(excitation)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(X, expected, atol=1e-6 * scale)
    np.testing.assert_allclose(X, Xr, atol=1e-9 * scale)
    np.testing.assert_allclose(G, S - X @ C.T, atol=1e-9 * np.abs(S).max())
    assert not K._solve_iv_weighted(C, G, np.zeros_like(Z), X, 1e10, *scratch)


def test_excitation_is_the_weakest_eigenvalue_share():
    """Issue 23: the persistent-excitation test of (8) estimates λ_min / tr
    by inverse iteration with the factor of the solve; kernel = reference,
    close to the exact eigenvalue (an upper bound of it)."""
    rng = np.random.default_rng(5)
    for cond in (1e2, 1e6, 1e12):
        Q = np.linalg.qr(rng.standard_normal((14, 14)))[0]
        X = Q @ np.diag(np.geomspace(1.0, 1.0 / cond, 14)) @ Q.T
        delta = np.trace(X) / 1e10
        L = np.linalg.cholesky(X + delta * np.eye(14))
        got = K._weakest(np.tril(X), L, delta, np.empty(14), np.empty(14))
        exact = 1.0 / cond / np.trace(X)
        floor = delta / np.trace(X)            # the regularisation's share: resolution
        assert abs(got - R._ref_weakest(np.tril(X), delta)) <= 1e-6 * (abs(got) + floor)
        assert exact - 1e-3 * floor <= got <= 1.5 * exact + 10 * floor
        assert (got * 1e10 >= 1.0) == (cond < 1e9)      # the test's verdict


# ---------------------------------------------------------------------------
# kernel against the plain numpy reference
# ---------------------------------------------------------------------------
SMALL = StateSpace([[-1.0, 0.5], [-0.5, -1.5]], [[1.0, 0.3], [0.2, -0.8]],
                   [[1.0, 0.4], [-0.3, 1.0]], [[0.2, 0.0], [0.1, -0.3]], 0.0)


def _small_pair(n_samples, t=None, **kw):
    h = 0.01
    tt = np.arange(n_samples) * h if t is None else t
    u = multisine(tt, 2, w_min=0.3, w_max=10.0)
    y = SMALL.simulate(u, t=tt, hold=kw.get("hold", "foh"))
    pair = []
    for engine in ("numba", "numpy"):
        ident = AdaptiveIdentifier(2, 2, 2, horizon=3, filter_poles=-2.0, forgetting=1.0,
                                   bd_forgetting=0.5, refresh_every=7, engine=engine,
                                   dt=None if t is not None else h, **kw)
        ident.update(u, y, t=t)
        pair.append(ident)
    return pair


def _compare(a, b, rtol):
    sa, sb = a._st, b._st
    np.testing.assert_array_equal(sa["ist"], sb["ist"])
    for name in ("Am", "Bm", "Cm", "Dm", "M", "Psi", "zp", "zq", "R", "Rt", "hist", "zr", "xi",
                 "Cz", "Zz"):
        x, z = sa[name], sb[name]
        if name in ("R", "Rt", "Zz") and a._method != "ode":   # the kernel keeps lower triangles
            x, z = np.tril(x), np.tril(z)
        if z.size:
            assert np.abs(x - z).max() <= rtol * np.abs(z).max(), name


@pytest.mark.parametrize("kw", [{}, {"hold": "zoh"}, {"history_size": 8}],
                         ids=["foh", "zoh", "history"])
@pytest.mark.slow
def test_kernel_matches_reference(kw):
    a, b = _small_pair(4000, **kw)
    assert a.model.info["bd_started"]
    _compare(a, b, 1e-12)


@pytest.mark.slow
def test_kernel_matches_reference_nonuniform_steps():
    rng = np.random.default_rng(3)
    t = np.concatenate([[0.0], np.cumsum(rng.choice([0.008, 0.01, 0.013], 2999))])
    a, b = _small_pair(3000, t=t)
    assert a.model.info["bd_started"]
    _compare(a, b, 1e-12)


def test_kernel_matches_reference_ode_form():
    a, b = _small_pair(1500, method="ode")
    assert a.model.info["bd_started"]
    _compare(a, b, 1e-12)


@pytest.mark.slow
def test_kernel_matches_reference_paper_system(short_record):
    """On the paper's system the regression (8) has condition ~1e7, which
    amplifies the last-bit differences of the two implementations (BLAS vs
    loop summation order); agreement is correspondingly looser."""
    t, u, y = short_record
    a, b = paper_ident(), paper_ident(engine="numpy")
    a.update(u, y)
    b.update(u, y)
    np.testing.assert_array_equal(a._st["ist"], b._st["ist"])
    for name, tol in (("zp", 1e-13), ("zq", 1e-13), ("Am", 1e-8), ("Cm", 1e-8),
                      ("Bm", 1e-6), ("Dm", 1e-6)):
        x, z = a._st[name], b._st[name]
        assert np.abs(x - z).max() <= tol * np.abs(z).max(), name


# ---------------------------------------------------------------------------
# streaming: chunks, checkpoints, bad samples
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("size", [1, 7, 1000])
def test_chunking_does_not_change_the_result(short_record, size):
    t, u, y = short_record
    n = 6000
    whole = paper_ident(history_size=8, refresh_every=20)
    whole.update(u[:n], y[:n])
    assert whole.model.info["bd_started"]
    parts = paper_ident(history_size=8, refresh_every=20)
    for a in range(0, n, size):
        b = min(a + size, n)
        parts.update(u[a:b], y[a:b])
    assert_same_state(whole, parts)


def test_chunking_with_time_stamps(short_record):
    t, u, y = short_record
    n = 3000
    whole = AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0, history_size=8)
    whole.update(u[:n], y[:n], t=t[:n])
    parts = AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0, history_size=8)
    for a, b in ((0, 1), (1, 700), (700, 701), (701, n)):
        parts.update(u[a:b], y[a:b], t=t[a:b])
    assert_same_state(whole, parts)


def test_checkpoint_round_trip_continues_identically(tmp_path, short_record):
    t, u, y = short_record
    ref = paper_ident(history_size=16)
    ref.update(u, y)
    first = paper_ident(history_size=16)
    first.update(u[:4321], y[:4321])
    path = tmp_path / "ident.npz"
    first.save(path)
    again = AdaptiveIdentifier.load(path)
    assert again.n_samples == 4321 and again.t == first.t
    again.update(u[4321:], y[4321:])
    assert_same_state(ref, again)
    np.testing.assert_array_equal(ref.model.A, again.model.A)


def test_checkpoint_write_is_atomic(tmp_path, short_record, monkeypatch):
    t, u, y = short_record
    ident = paper_ident()
    ident.update(u[:2000], y[:2000])
    path = tmp_path / "ident.npz"
    ident.save(path)
    before = path.read_bytes()
    ident.update(u[2000:3000], y[2000:3000])

    def crash(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", crash)
    with pytest.raises(OSError):
        ident.save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["ident.npz"]
    assert AdaptiveIdentifier.load(path).n_samples == 2000


def test_truncated_or_corrupted_checkpoint_raises(tmp_path, short_record):
    t, u, y = short_record
    ident = paper_ident()
    ident.update(u[:2000], y[:2000])
    path = tmp_path / "ident.npz"
    ident.save(path)
    data = path.read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[:len(data) // 2])
    with pytest.raises(CheckpointError, match="truncated or corrupted"):
        AdaptiveIdentifier.load(bad)
    noise = tmp_path / "noise.npz"
    noise.write_bytes(np.random.default_rng(0).bytes(4000))
    with pytest.raises(CheckpointError):
        AdaptiveIdentifier.load(noise)
    flipped = bytearray(data)
    flipped[len(flipped) // 2] ^= 0xFF
    bad.write_bytes(bytes(flipped))
    with pytest.raises(CheckpointError):
        AdaptiveIdentifier.load(bad)
    with pytest.raises(DataFileNotFoundError):
        AdaptiveIdentifier.load(tmp_path / "missing.npz")


def test_checkpoint_with_inconsistent_content_raises(tmp_path):
    from subid.io._checkpoint import load_state, save_state
    ident = paper_ident()
    path = tmp_path / "ident.npz"
    ident.save(path)
    from subid.methods.online.adaptive import _VERSION
    arrays, settings = load_state(path, "subid.AdaptiveIdentifier", _VERSION)
    arrays["R"] = arrays["R"].copy()
    arrays["R"][0, 0] = np.nan
    save_state(path, "AdaptiveIdentifier", _VERSION, arrays, settings)
    with pytest.raises(CheckpointError, match="non-finite"):
        AdaptiveIdentifier.load(path)
    arrays["R"] = np.eye(3)
    save_state(path, "AdaptiveIdentifier", _VERSION, arrays, settings)
    with pytest.raises(CheckpointError, match="shape"):
        AdaptiveIdentifier.load(path)
    save_state(path, "RecursiveSubspace", 1, arrays, settings)
    with pytest.raises(CheckpointError, match="not of subid.AdaptiveIdentifier"):
        AdaptiveIdentifier.load(path)


def _bad_calls(u, y, t):
    nan_u = u.copy()
    nan_u[3, 1] = np.nan
    inf_y = y.copy()
    inf_y[5, 0] = np.inf
    back = t.copy()
    back[4] = back[2]
    return {
        "nan in u": ((nan_u, y), {}),
        "inf in y": ((u, inf_y), {}),
        "u has 3 channels": ((np.hstack([u, u[:, :1]]), y), {}),
        "y transposed": ((u, y.T), {}),
        "lengths differ": ((u, y[:-1]), {}),
        "time not increasing": ((u, y), {"t": back}),
        "time before last sample": ((u, y), {"t": t - 1.0}),
        "t wrong length": ((u, y), {"t": t[:-1]}),
        "strings": ((u.astype(str), y), {}),
        "missing y": ((u,), {}),
        "one-sample wrong size": ((u[0, :1], y[0]), {}),
    }


@pytest.mark.parametrize("case", list(_bad_calls(np.zeros((10, 2)), np.zeros((10, 2)),
                                                 np.arange(10.0))))
def test_bad_samples_raise_and_leave_state_unchanged(short_record, case):
    t, u, y = short_record
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0, history_size=8)
    ident.update(u[:2500], y[:2500], t=t[:2500])
    before = state_arrays(ident)
    n = 10
    args, kw = _bad_calls(u[2500:2500 + n], y[2500:2500 + n], t[2500:2500 + n])[case]
    with pytest.raises(DataError) as err:
        ident.update(*args, **kw)
    assert len(str(err.value)) > 20
    for x, z in zip(before, state_arrays(ident)):
        np.testing.assert_array_equal(x, z)
    # and it continues exactly as if the bad call never happened
    ident.update(u[2500:4000], y[2500:4000], t=t[2500:4000])
    ref = AdaptiveIdentifier(4, 2, 2, horizon=5, filter_poles=-5.0, history_size=8)
    ref.update(u[:4000], y[:4000], t=t[:4000])
    assert_same_state(ident, ref)


def test_nan_message_names_the_row():
    ident = paper_ident()
    u = np.zeros((10, 2))
    u[3, 1] = np.nan
    with pytest.raises(DataError, match="input u has 1 NaN value at row 3"):
        ident.update(u, np.zeros((10, 2)))


def test_no_time_information_raises():
    ident = AdaptiveIdentifier(2, 1, 1)
    with pytest.raises(DataError, match="dt"):
        ident.update(np.zeros(5), np.zeros(5))
    assert ident.n_samples == 0


def test_overflowing_chunk_is_rejected_and_rolled_back(short_record):
    t, u, y = short_record
    ident = paper_ident(history_size=4)
    ident.update(u[:4000], y[:4000])
    before = state_arrays(ident)
    with pytest.raises(DataError, match="overflow double precision"):     # at the boundary
        ident.update(u[4000:4010] * 1e300, y[4000:4010] * 1e300)
    for x, z in zip(before, state_arrays(ident)):
        np.testing.assert_array_equal(x, z)


def test_non_finite_result_rolls_the_chunk_back(short_record, monkeypatch):
    t, u, y = short_record
    ident = paper_ident(history_size=4)
    ident.update(u[:4000], y[:4000])
    before = state_arrays(ident)
    real = K.kernel_packed

    def overflowing(*args):
        real(*args)
        args[-1][7] = np.inf          # a state entry overflows
        return False

    monkeypatch.setattr(K, "kernel_packed", overflowing)
    with pytest.raises(DataError, match="non-finite"):
        ident.update(u[4000:4100], y[4000:4100])
    monkeypatch.undo()
    for x, z in zip(before, state_arrays(ident)):
        np.testing.assert_array_equal(x, z)
    ident.update(u[4000:5000], y[4000:5000])
    ref = paper_ident(history_size=4)
    ref.update(u[:5000], y[:5000])
    assert_same_state(ident, ref)


# ---------------------------------------------------------------------------
# API
# ---------------------------------------------------------------------------
def test_update_accepts_single_samples_and_iodata(short_record):
    t, u, y = short_record
    ref = paper_ident()
    ref.update(u[:600], y[:600])
    ident = paper_ident()
    for k in range(200):
        ident.update(u[k], y[k])                     # one 1-D sample per call
    ident.update(IOData(u[200:600], y[200:600], dt=DT))
    assert_same_state(ref, ident)
    assert ident.update(u[600:601], y[600:601]) is ident
    # explicit time stamps: the same up to the rounding of the steps t[k] - t[k-1]
    stamped = paper_ident()
    stamped.update(IOData(u[:600], y[:600], t=t[:600]))
    assert stamped.t == t[599]
    ref.update(u[600:601], y[600:601])
    stamped.update(u[600:601], y[600:601])
    np.testing.assert_allclose(stamped._st["zp"], ref._st["zp"], rtol=1e-9, atol=1e-12)


def test_siso_one_dimensional_arrays_are_samples():
    sys1 = StateSpace([[-1.0]], [[1.0]], [[2.0]], [[0.5]], 0.0)
    t = np.arange(5001) * 0.01
    u = multisine(t, 1, w_min=0.2, w_max=10)[:, 0]
    y = sys1.simulate(u, t=t, hold="foh")[:, 0]
    ident = AdaptiveIdentifier(1, 1, 1, filter_poles=-2.0, forgetting=0.5, bd_forgetting=0.2,
                               dt=0.01)
    assert ident._f == 3          # smallest f > n with (f-1) ny > n (the default horizon)
    ident.update(u, y)
    assert ident.n_samples == u.size
    assert subid.markov_error(ident.model, sys1, k=5) < 1e-3


def test_model_before_data_is_an_error():
    """Before any sample there is no estimate: a clear error, not an all-zero model."""
    ident = paper_ident()
    with pytest.raises(subid.errors.TooFewSamplesError, match="no samples yet"):
        ident.model
    assert ident.n_samples == 0 and ident.t is None
    assert np.all(np.isfinite(ident.state))
    assert ident.history["A"].shape == (0, 4, 4)


def test_history_is_bounded_and_decimated(clean200):
    t, u, y = clean200
    ident = paper_ident(history_size=16, refresh_every=10)
    n = 100_001
    ident.update(u[:n], y[:n])
    hist = ident.history
    assert 8 <= hist["t"].size <= 16
    steps = np.diff(hist["sample"])
    assert np.all(steps == steps[0]) and steps[0] >= 10 * 16 // 2
    assert hist["t"][-1] > t[n - 1] - steps[0] * DT - 1e-9
    assert ident._st["hist"].shape[0] == 16


def test_basis_fixed_by_selector():
    """Same H, different records: the same matrices (the basis of (23))."""
    true = paper_system()
    models = []
    for seed in (0, 1):
        t = np.arange(30_001) * DT
        u = multisine(t, 2, seed=seed)
        y = true.simulate(u, t=t, hold="foh")
        ident = paper_ident(seed=11)
        ident.update(u, y)
        models.append(ident.model)
    assert np.abs(models[0].A - models[1].A).max() < 1e-3
    assert np.abs(models[0].B - models[1].B).max() < 1e-3


@pytest.mark.parametrize("kw, exc", [
    ({"horizon": 2}, OrderError),
    ({"filter_poles": 2.0}, SubidError),
    ({"filter_poles": [-1.0, -2.0]}, SubidError),
    ({"filter_poles": [-1 + 1j, -1 + 1j, -2, -2, -2]}, SubidError),
    ({"forgetting": 0.0}, SubidError),
    ({"bd_forgetting": -1.0}, SubidError),
    ({"selector": np.ones((3, 10))}, SubidError),
    ({"hold": "cubic"}, SubidError),
    ({"method": "euler"}, SubidError),
    ({"max_condition": 1.0}, SubidError),
    ({"history_size": -1}, OrderError),
    ({"dt": -1.0}, DataError),
])
def test_constructor_validation(kw, exc):
    args = dict(order=4, n_inputs=2, n_outputs=2, horizon=5)
    args.update(kw)
    with pytest.raises(exc):
        AdaptiveIdentifier(**args)


def test_complex_filter_poles_in_pairs_are_accepted():
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5,
                               filter_poles=[-3 + 2j, -3 - 2j, -4, -5, -6], dt=DT)
    assert ident.time_scale == pytest.approx(abs(np.prod([-3 + 2j, -3 - 2j, -4, -5, -6])) ** 0.2)
    t, u, y = simulate(10.0)
    ident.update(u, y)
    assert subid.pole_error(ident.model, paper_system()) < 1e-3


# ---------------------------------------------------------------------------
# issue 12: noise consistency (instrumental variables), gaps, convergence
# ---------------------------------------------------------------------------
def _white_record(duration, snr_db, noise_seed, input_seed=0):
    """The paper's Section V input: white noise at 1 ms (held linearly)."""
    t = np.arange(int(round(duration / DT)) + 1) * DT
    u = np.random.default_rng(input_seed).standard_normal((t.size, 2))
    y = paper_system().simulate(u, t=t, hold="foh")
    std = y.std(axis=0) * 10 ** (-snr_db / 20)
    return t, u, y + np.random.default_rng(noise_seed).standard_normal(y.shape) * std


@pytest.mark.slow
def test_iv_default_is_consistent_where_least_squares_is_biased():
    """White-noise input, 50 dB, 400 s, default settings (method='iv'): the
    paper's least squares never starts (B, D) (errors in variables); IV does
    and is accurate. The LS model warns that it is not converged."""
    true = paper_system()
    t, u, y = _white_record(400.0, 50.0, noise_seed=2)
    iv = paper_ident()
    iv.update(u, y)
    assert iv.model.info["ls_method"] == "iv" and iv.model.info["converged"]
    assert relative_error(iv.model, true) < 0.05
    ls = paper_ident(method="ls", forgetting=0.01, bd_forgetting=0.008)
    ls.update(u, y)
    with pytest.warns(subid.errors.NotConvergedWarning, match="has not started"):
        model = ls.model
    assert not model.info["converged"] and not model.info["bd_started"]
    assert "has not started" in model.info["convergence"]
    assert np.all(model.B == 0)


@pytest.mark.long
def test_iv_consistency_statistic_over_noise_realisations():
    """Five noise realisations each of the white-noise input at 50 dB and the
    issue's multisine (10 sines per input on 0.1-10 rad/s, the same on both
    inputs) at 40 dB, 400 s, defaults: median ε_r of IV below 0.05 / 0.1; the
    paper's LS (α = 0.01, β = 0.008) fails on most (median ε_r = 1)."""
    true = paper_system()
    t = np.arange(400_001) * DT
    w = np.geomspace(0.1, 10.0, 10)
    ph = np.random.default_rng(0).uniform(0, 2 * np.pi, (10, 2))
    ms = np.stack([np.sin(np.outer(t, w) + ph[:, j]).sum(1) for j in range(2)], 1) / 5 ** 0.5
    for u0, snr, bound in ((None, 50.0, 0.05), (ms, 40.0, 0.1)):
        eps_iv, eps_ls = [], []
        for seed in range(1, 6):
            if u0 is None:
                _, u, y = _white_record(400.0, snr, noise_seed=seed)
            else:
                u = u0
                y0 = true.simulate(u, t=t, hold="foh")
                y = y0 + np.random.default_rng(seed).standard_normal(y0.shape) \
                    * y0.std(axis=0) * 10 ** (-snr / 20)
            for method, out in (("iv", eps_iv), ("ls", eps_ls)):
                kw = {} if method == "iv" else {"forgetting": 0.01, "bd_forgetting": 0.008}
                ident = paper_ident(method=method, **kw)
                ident.update(u, y)
                with np.errstate(all="ignore"), warnings_ignored():
                    out.append(relative_error(ident.model, true))
        assert np.median(eps_iv) < bound, eps_iv
        assert np.median(eps_ls) > 0.5, eps_ls



@pytest.mark.long
def test_iv_default_white_noise_50db_every_realisation():
    """Issue 12's acceptance point, on every noise realisation (not only the
    median): white-noise input, 50 dB, 400 s, default settings. Issue 12
    measured (seeds 1-5) 0.017, 0.026, 0.037, 0.041, 0.008 (bound 0.05); with
    issue 23's earlier (B, D) start (and with it the auxiliary-model
    instrument of M) up to 0.066 (seed 3, bd_startup 2): median < 0.05, every
    one < 0.08 (docs/seed000.md)."""
    true = paper_system()
    eps = []
    for seed in range(1, 6):
        _, u, y = _white_record(400.0, 50.0, noise_seed=seed)
        ident = paper_ident()
        ident.update(u, y)
        model = ident.model
        assert model.info["converged"], model.info["convergence"]
        eps.append(relative_error(model, true))
    assert np.median(eps) < 0.05 and max(eps) < 0.08, eps


def test_iv_default_bd_memory_follows_the_forgetting():
    """'iv': bd_forgetting defaults to the forgetting actually used (θ and M
    share one memory); an explicit value wins; 'ls' keeps the paper's 0.08."""
    t, u, y = simulate(0.05)
    cases = [({}, 0.002, 0.002), ({"forgetting": 0.05}, 0.05, 0.05),
             ({"forgetting": 0.05, "bd_forgetting": 0.3}, 0.05, 0.3),
             ({"method": "ls"}, 0.4, 0.08), ({"method": "ls", "forgetting": 0.01}, 0.01, 0.08)]
    for kw, alpha, beta in cases:
        ident = paper_ident(**kw)
        ident.update(u, y)
        with warnings_ignored():
            info = ident.model.info
        assert (info["forgetting"], info["bd_forgetting"]) == (alpha, beta), kw


def warnings_ignored():
    import warnings
    ctx = warnings.catch_warnings()
    ctx.__enter__()
    warnings.simplefilter("ignore")

    class _Exit:
        def __enter__(self):
            return self

        def __exit__(self, *exc):
            ctx.__exit__(*exc)
            return False
    return _Exit()


def _gap_record(before, gap, after):
    """Samples at 1 ms, a logger pause of ``gap`` (the system keeps running:
    simulated on a coarse grid through the pause, which is then dropped)."""
    t1 = np.arange(int(before / DT)) * DT
    tg = t1[-1] + np.arange(1, int(gap / 0.5)) * 0.5
    t2 = t1[-1] + gap + np.arange(int(after / DT)) * DT
    tall = np.concatenate([t1, tg, t2])
    uall = multisine(tall, 2)
    yall = paper_system().simulate(uall, t=tall, hold="foh")
    keep = np.concatenate([np.arange(t1.size), t1.size + tg.size + np.arange(t2.size)])
    return tall[keep], uall[keep], yall[keep], t1.size


@pytest.mark.parametrize("method", ["iv", "ls", "ode"])
def test_long_gap_reinitialises_cleanly(method):
    """A 30-minute pause at the paper's forgetting (e^{-0.4 * 1800} underflows):
    no exception, the filters restart after the gap, and the estimate stays
    (ls, iv) accurate."""
    true = paper_system()
    t, u, y, k = _gap_record(20.0, 1800.0, 25.0)
    ident = AdaptiveIdentifier(4, 2, 2, method=method, forgetting=0.4, bd_forgetting=0.08)
    ident.update(u[:k], y[:k], t=t[:k])
    for a in range(k, t.size, 5000):               # the gap inside a chunk and across
        ident.update(u[a:a + 5000], y[a:a + 5000], t=t[a:a + 5000])
        if method != "ode":                         # held through the gap, no jump
            with warnings_ignored():
                assert subid.pole_error(ident.model, true) < 1e-3
    with warnings_ignored():
        model = ident.model
    assert model.info["gaps"] == 1
    assert np.isfinite(ident._buf).all()
    if method != "ode":
        assert subid.pole_error(model, true) < 1e-3
        assert relative_error(model, true) < 1e-3
        assert model.info["converged"]


@pytest.mark.slow
def test_gap_handling_kernel_matches_reference():
    h = 0.01
    t = np.concatenate([np.arange(1500) * h, 15.0 + 20.0 + np.arange(1500) * h])
    u = multisine(t, 2, w_min=0.3, w_max=10.0)
    y = SMALL.simulate(u, t=t, hold="foh")
    pair = []
    for engine in ("numba", "numpy"):
        ident = AdaptiveIdentifier(2, 2, 2, horizon=3, filter_poles=-2.0, forgetting=1.0,
                                   bd_forgetting=0.5, refresh_every=7, engine=engine)
        ident.update(u, y, t=t)
        pair.append(ident)
    assert pair[0].model.info["gaps"] == 1 and pair[0].model.info["bd_started"]
    # the auxiliary-model instrument feeds the model back into Cz, and the
    # restart after the gap amplifies last-bit differences (measured 2e-12)
    _compare(pair[0], pair[1], 1e-9)


@pytest.mark.slow
def test_iv_noise_free_exact_and_kernel_matches_reference_ls_too():
    a, b = _small_pair(4000, method="ls")
    _compare(a, b, 1e-12)
    true = paper_system()
    t, u, y = simulate(30.0)
    ident = paper_ident()
    ident.update(u, y)
    assert subid.pole_error(ident.model, true) < 1e-3      # measured 3e-5 / 2.7e-4
    assert relative_error(ident.model, true) < 1e-3


def test_instrument_poles_validation():
    with pytest.raises(SubidError, match="instrument_poles"):
        AdaptiveIdentifier(4, 2, 2, dt=DT, instrument_poles=[-1.0])
    with pytest.raises(SubidError, match="instrument_poles must have negative"):
        AdaptiveIdentifier(4, 2, 2, dt=DT, instrument_poles=1.0)
    with pytest.raises(SubidError, match="method"):
        AdaptiveIdentifier(4, 2, 2, dt=DT, method="bias")
    with pytest.raises(SubidError, match="equal the filter poles"):
        AdaptiveIdentifier(4, 2, 2, dt=DT, instrument_poles=-5.0)


# ---------------------------------------------------------------------------
# issue 23: noise-free convergence of the default, the (B, D) start, consistency
# ---------------------------------------------------------------------------
def _issue_record(duration, name, snr_db=None, noise_seed=1):
    from subid.experiments.seed000 import INPUTS
    t = np.arange(int(round(duration / DT)) + 1) * DT
    u = INPUTS[name](t, 2, seed=0)
    y = paper_system().simulate(u, t=t, hold="foh")
    if snr_db is not None:
        y = y + np.random.default_rng(noise_seed).standard_normal(y.shape) \
            * y.std(axis=0) * 10 ** (-snr_db / 20)
    return t, u, y


@pytest.mark.parametrize("name", ["multisine-issue12", "white"])
def test_default_noise_free_converges_early(name):
    """Issue 23, item 1 (cheap sibling of the 200 s test): the default reaches
    pole error and ε_r < 1e-3 within 30 s (measured: from 4-16 s)."""
    true = paper_system()
    t, u, y = _issue_record(30.0, name)
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=DT)
    ident.update(u, y)
    model = ident.model
    assert model.info["converged"] and model.info["excited"]
    assert subid.pole_error(model, true) < 1e-3
    assert relative_error(model, true) < 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("name", ["multisine-issue12", "white"])
def test_default_noise_free_within_200s(name):
    """Issue 23, item 1: the paper's system, 1 ms, the issue's multisine (10
    sines per input on 0.1-10 rad/s, the same frequencies on both inputs) and
    white noise, ``AdaptiveIdentifier(order=4, n_inputs=2, n_outputs=2,
    horizon=5, dt=...)`` defaults: below 1e-3 from 20 s on, to the end of 200 s."""
    from subid.experiments.seed000 import settle_time, trajectories
    true = paper_system()
    t, u, y = _issue_record(200.0, name)
    ident = AdaptiveIdentifier(order=4, n_inputs=2, n_outputs=2, horizon=5, dt=DT,
                               history_size=512)
    ident.update(u, y)
    assert subid.pole_error(ident.model, true) < 1e-3
    assert relative_error(ident.model, true) < 1e-3
    times, _, perr, eps = trajectories(ident, true)
    assert settle_time(times, perr, 1e-3) <= 20.0
    assert settle_time(times, eps, 1e-3) <= 20.0


@pytest.mark.parametrize("method", ["iv", "ls"])
def test_bd_stage_needs_persistent_excitation(method):
    """Issue 23, item 3: a single sine per input is not sufficiently rich
    (order horizon + order = 9 needed): (A, C) are not determined, the (B, D)
    stage does not start, and the model says why."""
    true = paper_system()
    t = np.arange(20001) * DT
    u = np.column_stack([np.sin(t), np.cos(2 * t)])
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=DT, method=method)
    ident.update(u, true.simulate(u, t=t, hold="foh"))
    with pytest.warns(subid.errors.NotConvergedWarning, match="not persistently exciting"):
        model = ident.model
    assert not model.info["bd_started"] and not model.info["excited"]
    assert "sufficiently rich of order horizon + order = 9" in model.info["convergence"]


def test_bd_stage_starts_at_40db_white_noise():
    """Issue 23, item 3 (cheap sibling of the 10-realisation test): with the
    paper's white-noise input at 40 dB the residual of (13) never reaches the
    gate, and the (B, D) stage starts once it stops halving (measured: 6-36 s
    over noise seeds 1-10; before issue 23, in 6 of 10 within 400 s)."""
    for seed in (2, 3):
        t, u, y = _issue_record(60.0, "white", 40.0, noise_seed=seed)
        ident = paper_ident()
        ident.update(u, y)
        with warnings_ignored():        # the latest (A, C) may miss the stalled level
            info = ident.model.info
        assert info["bd_started"] and info["shift_residual"] > 1e-2, info["convergence"]
        assert info["bd_start_time"] < 40.0


@pytest.mark.long
def test_40db_white_noise_ten_realisations():
    """Issue 23 acceptance: 40 dB, white input, 400 s, 10 noise realisations,
    defaults: (B, D) estimated in all 10, median ε_r < 0.05, worst < 0.1
    (measured with the structured refit of (8): median 0.013, worst 0.064;
    without it 0.078 / 0.20)."""
    true = paper_system()
    eps = []
    for seed in range(1, 11):
        t, u, y = _issue_record(400.0, "white", 40.0, noise_seed=seed)
        ident = paper_ident()
        ident.update(u, y)
        with warnings_ignored():
            model = ident.model
        assert model.info["bd_started"] and model.info["refined"]
        eps.append(relative_error(model, true))
    assert np.median(eps) < 0.05 and max(eps) < 0.1


@pytest.mark.long
def test_error_falls_as_memory_and_record_grow_together():
    """Issue 23, item 2: 40 dB, white input, 5 realisations: four times the
    memory over four times the record (forgetting 0.0005 over 3200 s against
    0.002 over 800 s) gives at most 0.7 times the median ε_r."""
    from subid.experiments.seed000 import memory_study
    rows = memory_study(pairs=((0.002, 800.0), (0.0005, 3200.0)))
    short, long_ = (np.median(r["eps_r"]) for r in rows)
    assert all(r["started"] == 5 for r in rows)
    assert long_ <= 0.7 * short


# ---------------------------------------------------------------------------
# issue 23 follow-up: the structured refit of (8)
# ---------------------------------------------------------------------------
def test_structured_m_is_the_matrix_of_equation_9():
    """``structured_m`` of the true system is the M that the regression (8)
    converges to noise-free (an independent computation: the kernel's
    unstructured estimate), in the basis of (23) whatever the basis of θ."""
    from subid.methods.online._adaptive_refine import structured_m
    true = paper_system()
    t, u, y = _issue_record(30.0, "white")
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=DT, refine=False)
    ident.update(u, y)
    S = np.array([[1.0, 0.2, 0.0, -0.3], [0.0, 2.0, 0.5, 0.0], [0.1, 0.0, 1.0, 0.0],
                  [0.0, -0.4, 0.0, 0.5]])          # any basis
    Si = np.linalg.inv(S)
    theta = np.concatenate([(S @ true.A @ Si).ravel(), (S @ true.B).ravel(),
                            (true.C @ Si).ravel(), true.D.ravel()])
    M, (A, B, C, D) = structured_m(theta, 4, 2, 2, 5, ident.selector, ident.time_scale)
    np.testing.assert_allclose(M, ident._st["M"], atol=2e-4 * np.abs(M).max())
    At, Bt, Ct = true_in_basis(ident, true)
    np.testing.assert_allclose(A, At, atol=1e-10 * np.abs(At).max())
    np.testing.assert_allclose(B, Bt, atol=1e-10 * np.abs(Bt).max())


def test_refit_keeps_noise_free_exactness_and_the_basis():
    """Noise-free, the refit reports the exact model in the basis of (23)."""
    true = paper_system()
    t, u, y = _issue_record(30.0, "white")
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=DT)
    ident.update(u, y)
    model = ident.model
    assert model.info["refine"] and model.info["bd_started"]
    assert subid.pole_error(model, true) < 1e-3 and relative_error(model, true) < 1e-3
    if model.info["refined"]:
        At, _, Ct = true_in_basis(ident, true)
        np.testing.assert_allclose(model.A, At, atol=1e-2 * np.abs(At).max())
    with pytest.raises(SubidError, match="refine"):
        AdaptiveIdentifier(4, 2, 2, dt=DT, refine="yes")


@pytest.mark.slow
def test_refit_at_40db_white_noise_one_record():
    """Issue 23 (cheap sibling of the 10-realisation test): the record where the
    unrefined default is worst (noise seed 8: ε_r 0.20) is within the targets."""
    true = paper_system()
    t, u, y = _issue_record(400.0, "white", 40.0, noise_seed=8)
    ident = paper_ident()
    ident.update(u, y)
    with warnings_ignored():
        model = ident.model
    assert model.info["refined"]
    assert relative_error(model, true) < 0.05
    np.testing.assert_allclose(model.info["noise_std"], 0.01 * y.std(axis=0), rtol=0.3)


def test_channels_far_above_size_one_are_named_in_the_warning():
    """The paper's normalisation 1 + |phi|^2 fixes a signal size (docs/seed000.md,
    Units): the contract record with every channel times 1000 never starts the (B, D)
    stage, and the model's warning names that cause and the cure."""
    import warnings as _warnings

    from subid.testing import noise_free_record, scaled_record
    data, _ = noise_free_record("continuous")
    noisy = scaled_record(data)[0]
    big = noisy.scaled(inputs=[1e3], outputs=[1e3, 1e3])
    ident = subid.AdaptiveIdentifier(2, 1, 2, dt=big.dt)
    ident.update(big.u, big.y)
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        ident.model
    text = " ".join(str(w.message) for w in caught)
    assert "the (B, D) stage has not started" in text
    assert "not unit-free" in text and "data.scaled" in text
    small = subid.AdaptiveIdentifier(2, 1, 2, dt=noisy.dt)
    small.update(noisy.u, noisy.y)
    assert min(subid.fit_percent(small.model, noisy)) > 90
    # the input alone in other units fails the excitation test instead: the same cure
    loud = subid.AdaptiveIdentifier(2, 1, 2, dt=noisy.dt)
    loud.update(noisy.scaled(inputs=[1e3]).u, noisy.y)
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        loud.model
    text = " ".join(str(w.message) for w in caught)
    assert "not unit-free" in text and "data.scaled" in text


def test_model_before_the_first_refresh_is_an_error_not_a_zero_model():
    # the contract of the online identifiers (docs/api/online.md): no all-zero model. Up
    # to the first refresh (refresh_every = 50 samples) A, B, C, D were all zero and the
    # model was returned with a warning only; after it, (A, C) with B = D = 0 and the
    # warning that says the (B, D) stage has not started
    t = np.arange(200) * DT
    u = multisine(t, 2, seed=0)
    y = paper_system().simulate(u, t=t, hold="foh")
    for n in (1, 49, 50):
        ident = paper_ident().update(u[:n], y[:n])
        with pytest.raises(subid.errors.TooFewSamplesError, match="no estimate of"):
            ident.model
    ident = paper_ident().update(u[:51], y[:51])
    with pytest.warns(subid.errors.NotConvergedWarning, match="has not started"):
        model = ident.model
    assert model.info["refreshes"] == 1 and np.any(model.A) and np.any(model.C)
    assert not np.any(model.B) and not model.info["bd_started"]
