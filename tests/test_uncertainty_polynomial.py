"""Parameter covariance of the polynomial models (arx, armax, oe, bj) and their bounds."""

import numpy as np
import pytest
from scipy.signal import lfilter

import subid
from subid.errors import ModelError
from subid.model.statespace import StateSpace

W = np.array([0.1, 0.3, 0.6, 1.0, 2.0])
# second-order plant B/A (poles 0.75 +- 0.37i) used as ARX (noise 1/A) and OE (white noise)
B_TRUE, A_TRUE = np.array([0.0, 1.0, 0.5]), np.array([1.0, -1.5, 0.7])


def _record(kind, seed, n_samples=500):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n_samples)
    e = rng.standard_normal(n_samples)
    plant = lfilter(B_TRUE, A_TRUE, u)
    if kind == "arx":
        y = plant + 0.5 * lfilter([1.0], A_TRUE, e)
    else:                                                   # output error, 10 dB
        y = plant + e * plant.std() * 10 ** (-10 / 20)
    return subid.IOData(u, y, dt=1.0)


def _true_magnitude(w):
    z = np.exp(-1j * np.asarray(w))
    return np.abs(np.polyval(B_TRUE[::-1], z) / np.polyval(A_TRUE[::-1], z))


def _monte_carlo(kind, runs, seed0=1000):
    """Coverage of the 95 % |G| bands per frequency, and the estimates and mean
    predicted covariance of the coefficients over ``runs`` records."""
    fn = subid.arx if kind == "arx" else subid.oe
    G = _true_magnitude(W)
    hits, estimates, predicted = [], [], []
    for r in range(runs):
        model = fn(_record(kind, seed0 + r), (2, 2, 1))
        band = subid.freqresp_bounds(model, W)
        hits.append((band.lower[:, 0, 0] <= G) & (G <= band.upper[:, 0, 0]))
        cov = subid.parameter_covariance(model)
        estimates.append(cov.coefficients)
        predicted.append(cov.coefficient_covariance)
    empirical = np.cov(np.array(estimates).T)
    P = np.mean(predicted, axis=0)
    whitened = np.trace(np.linalg.solve(P, empirical)) / P.shape[0]
    return np.mean(hits, axis=0), np.diag(P) / np.diag(empirical), whitened


@pytest.mark.long
@pytest.mark.parametrize("kind", ["arx", "oe"])
def test_polynomial_bands_cover_and_covariance_matches_monte_carlo(kind):
    # 200 runs x 5 frequencies. Measured (seeds 1000-1199): coverage ARX 95.6 %
    # (95-96 % per frequency), OE 94.6 % (92.5-97 % per frequency; the classic
    # covariance before the sandwich: 95.0 %); predicted / empirical variance per
    # coefficient ARX 0.89-1.24, OE 0.90-1.25 (the empirical variance of 200 runs has a
    # relative sd of 0.1); the whitened ratio tr(P^-1 C_emp) / p: ARX 0.98, OE 0.97
    coverage, ratio, whitened = _monte_carlo(kind, 200)
    assert 0.90 <= coverage.mean() <= 0.99
    assert np.all((coverage >= 0.88) & (coverage <= 0.995))
    assert 0.8 <= whitened <= 1.25
    assert np.all((ratio >= 0.7) & (ratio <= 1.4))


@pytest.mark.parametrize("kind", ["arx", "oe"])
def test_polynomial_bands_cover_small(kind):
    # 30 runs x 5 frequencies (150 pairs; p = 0.95: below 0.88 has probability 0.1 %)
    coverage, _, whitened = _monte_carlo(kind, 30, seed0=3000)
    assert 0.88 <= coverage.mean() <= 1.0
    assert 0.6 <= whitened <= 1.6


def test_arx_covariance_is_the_least_squares_formula_mimo():
    # independent computation: per-output regressors, explicit inverses (test only),
    # Cov(c_i, c_k) = Λ_ik (Φ_i^T Φ_i)^-1 Φ_i^T Φ_k (Φ_k^T Φ_k)^-1
    rng = np.random.default_rng(0)
    N = 400
    u = rng.standard_normal((N, 2))
    e = rng.standard_normal((N, 2)) @ np.array([[0.3, 0.0], [0.15, 0.2]])
    y = np.zeros((N, 2))
    for t in range(2, N):
        y[t, 0] = 1.5 * y[t - 1, 0] - 0.7 * y[t - 2, 0] + u[t - 1, 0] + 0.5 * u[t - 2, 1] + e[t, 0]
        y[t, 1] = 0.5 * y[t - 1, 1] + 0.2 * y[t - 1, 0] + u[t - 1, 1] + e[t, 1]
    data = subid.IOData(u, y, dt=1.0)
    na = np.array([[2, 0], [1, 1]])
    model = subid.arx(data, (na, 2, 1))
    cov = subid.parameter_covariance(model)
    first = 2
    t = np.arange(first, N)
    phis = [np.column_stack([-y[t - 1, 0], -y[t - 2, 0], u[t - 1, 0], u[t - 2, 0],
                             u[t - 1, 1], u[t - 2, 1]]),
            np.column_stack([-y[t - 1, 0], -y[t - 1, 1], u[t - 1, 0], u[t - 2, 0],
                             u[t - 1, 1], u[t - 2, 1]])]
    assert cov.coefficient_names[:6] == ["A[0,0][1]", "A[0,0][2]", "B[0,0][1]", "B[0,0][2]",
                                         "B[0,1][1]", "B[0,1][2]"]
    assert cov.coefficient_names[6:8] == ["A[1,0][1]", "A[1,1][1]"]
    thetas = [np.linalg.lstsq(P, y[t, i], rcond=None)[0] for i, P in enumerate(phis)]
    np.testing.assert_allclose(cov.coefficients, np.concatenate(thetas), rtol=1e-9)
    res = np.column_stack([y[t, i] - P @ th for i, (P, th) in enumerate(zip(phis, thetas))])
    dof = t.size - 6
    lam = res.T @ res / dof
    inv = [np.linalg.inv(P.T @ P) for P in phis]
    expected = np.block([[lam[i, k] * inv[i] @ phis[i].T @ phis[k] @ inv[k]
                          for k in range(2)] for i in range(2)])
    np.testing.assert_allclose(cov.coefficient_covariance, expected, rtol=1e-8,
                               atol=1e-12 * np.abs(expected).max())


def _fd_jacobian(predict, c, h=1e-6):
    return np.column_stack([(predict(c + h * e) - predict(c - h * e)) / (2 * h)
                            for e in np.eye(c.size)])


@pytest.mark.parametrize("structure", ["oe", "armax", "bj"])
def test_prediction_error_covariance_matches_a_finite_difference_jacobian(structure):
    # λ (J^T J)^-1 with J by central differences of the predictor written with lfilter
    # (zero initial conditions: estimate_x0=False)
    rng = np.random.default_rng(5)
    N = 600
    u = rng.standard_normal(N)
    e = 0.3 * rng.standard_normal(N)
    y = lfilter(B_TRUE, A_TRUE, u) + lfilter([1.0, 0.4], [1.0, -0.5], e)
    data = subid.IOData(u, y, dt=1.0)
    if structure == "oe":
        model = subid.oe(data, (2, 2, 1), estimate_x0=False)

        def predict(c):                     # B/F u; c = [b1, b2, f1, f2]
            return lfilter([0.0, c[0], c[1]], [1.0, c[2], c[3]], u)
    elif structure == "armax":
        model = subid.armax(data, (2, 2, 1, 1), estimate_x0=False)

        def predict(c):                     # (B u + (C - A) y) / C; c = [a1, a2, b1, b2, c1]
            A, Cp = [1.0, c[0], c[1]], [1.0, c[4]]
            return lfilter([0.0, c[2], c[3]], Cp, u) + y - lfilter(A, Cp, y)
    else:
        model = subid.bj(data, (2, 1, 1, 2, 1), estimate_x0=False)

        def predict(c):                     # D/C (B/F u) + (1 - D/C) y; c = [b1 b2 c1 d1 f1 f2]
            x = lfilter([0.0, c[0], c[1]], [1.0, c[4], c[5]], u)
            Cp, Dp = [1.0, c[2]], [1.0, c[3]]
            return lfilter(Dp, Cp, x) + y - lfilter(Dp, Cp, y)
    cov = subid.parameter_covariance(model)
    c = cov.coefficients
    J = _fd_jacobian(predict, c)
    r = y - predict(c)
    lam = r @ r / (N - c.size)
    expected = lam * np.linalg.inv(J.T @ J)
    if structure == "oe":
        # output error (its noise here coloured): the sandwich R^-1 J^T T J R^-1, T the
        # Bartlett-windowed residual autocovariance at the window the model records
        from subid.methods.dt._sandwich import autocovariance, bartlett
        method = model.info["parameter_covariance"]["method"]
        lag = int(method.split("Bartlett window M = ")[1].split(",")[0])
        k = bartlett(lag) * autocovariance(r[:, None], [(0, N)], lag, N - c.size)[:, 0, 0]
        T = np.zeros((N, N))
        for tau in range(lag + 1):
            T += np.diag(np.full(N - tau, k[tau]), tau) + (
                np.diag(np.full(N - tau, k[tau]), -tau) if tau else 0)
        inv = np.linalg.inv(J.T @ J)
        expected = inv @ J.T @ T @ J @ inv
    np.testing.assert_allclose(cov.coefficient_covariance, expected, rtol=1e-5)


@pytest.mark.parametrize("fn, order", [(subid.oe, (2, 2, 0)), (subid.armax, (2, 2, 1, 1)),
                                       (subid.arx, (2, 3, 0))])
def test_bounds_are_the_delta_method_through_the_transfer_function(fn, order):
    # std of |G| from the realisation's θ equals the delta method through
    # G = B / (A F) with the coefficients' covariance (chain rule), finite differences
    # of the polynomial transfer function as the independent computation
    data = _record("oe", 11)
    model = fn(data, order)
    cov = subid.parameter_covariance(model)
    poly = model.info["polynomials"]
    from subid.model.polynomial import with_coefficients

    def magnitude(c):
        p = with_coefficients(poly, c)
        z = np.exp(-1j * W)
        A, B, F = p["A"][0, 0], p["B"][0, 0], p["F"][0, 0]
        return np.abs(np.polyval(B[::-1], z) / np.polyval(A[::-1], z)
                      / np.polyval(F[::-1], z))
    S = _fd_jacobian(magnitude, cov.coefficients) @ cov.coefficient_factor
    std = np.sqrt(np.sum(S ** 2, axis=1))
    band = subid.freqresp_bounds(model, W)
    np.testing.assert_allclose(band.std[:, 0, 0], std, rtol=1e-6)
    np.testing.assert_allclose(band.value[:, 0, 0], magnitude(cov.coefficients), rtol=1e-10)


@pytest.mark.slow
def test_polynomial_covariance_survives_save_load_and_draws_plots(tmp_path):
    pytest.importorskip("matplotlib")
    import matplotlib
    matplotlib.use("Agg")
    model = subid.oe(_record("oe", 2), (2, 2, 1))
    path = tmp_path / "oe.json"
    model.save(path)
    loaded = StateSpace.load(path)
    a, b = subid.freqresp_bounds(model, W), subid.freqresp_bounds(loaded, W)
    np.testing.assert_allclose(b.upper, a.upper, rtol=1e-12)
    cov = subid.parameter_covariance(loaded)
    assert cov.coefficient_names == ["B[0,0][1]", "B[0,0][2]", "F[0,0][1]", "F[0,0][2]"]
    assert np.all(cov.coefficient_std > 0)
    step = subid.step_bounds(loaded, 20.0)
    assert np.all(step.lower <= step.value) and np.all(step.value <= step.upper)
    subid.plot.bode(loaded, confidence=0.95)
    subid.plot.step(loaded, confidence=0.95)
    matplotlib.pyplot.close("all")


def test_non_minimal_polynomial_model_says_it_has_no_covariance():
    # noise-free data fitted with more poles than the plant has: cancelling
    # pole-zero pairs leave a direction the data do not determine
    data = _record("oe", 4)
    noise_free = subid.IOData(data.u, lfilter(B_TRUE, A_TRUE, data.u[:, 0]), dt=1.0)
    model = subid.oe(noise_free, (3, 3, 1))
    assert "parameter_covariance" not in model.info
    assert "rank deficient" in model.info["parameter_covariance_note"]
    with pytest.raises(ModelError, match="lower orders"):
        subid.freqresp_bounds(model, W)


def test_describe_and_the_report_give_the_coefficients_standard_deviations():
    from subid.evaluation.report import _coefficient_std
    from subid.model.polynomial import describe
    model = subid.arx(_record("arx", 6), (2, 2, 1))
    std = subid.parameter_covariance(model).coefficient_std
    np.testing.assert_allclose(_coefficient_std(model), std, rtol=1e-12)
    lines = describe(model.info["polynomials"], ["u"], ["y"], std)
    a1, a2, b1, b2 = model.info["parameter_covariance"]["coefficients"]
    assert lines[1] == f"A[y,y] = 1 {a1:+.4g} (±{std[0]:.2g}) q^-1 {a2:+.4g} (±{std[1]:.2g}) q^-2"
    assert lines[2].startswith(f"B[y,u] = {b1:.4g} (±{std[2]:.2g}) q^-1 {b2:+.4g}")
    # a state-space model has none
    assert _coefficient_std(subid.n4sid(_record("arx", 6), 2)) is None


@pytest.mark.parametrize("route", ["gram", "qr", "mixed"])
@pytest.mark.parametrize("shared", [False, True])
def test_coefficient_factor_is_the_sandwich_of_the_outputs_least_squares(shared, route,
                                                                          monkeypatch):
    """coefficient_factor (two outputs, each fitted on its own, nuisance columns first,
    correlated noise; their own designs, or one for both as ARX's) against an
    independent computation: the covariance of the outputs' least-squares estimates,
    Λ_ij (J_i^T J_i)^-1 J_i^T J_j (J_j^T J_j)^-1, at the coefficients' rows and
    columns. Each design's R from the Cholesky factor of its Gram matrix (no thin Q),
    from the Householder QR (GRAM_PIVOT above 1 forces it), or one of each."""
    from subid.methods.dt import _poly_covariance, _trust_region
    from subid.methods.dt._poly_covariance import coefficient_factor
    if route == "qr":
        monkeypatch.setattr(_trust_region, "GRAM_PIVOT", 2.0)
    elif route == "mixed":              # the first design's Gram route only
        real, calls = _trust_region.gram_factor, []
        monkeypatch.setattr(_poly_covariance, "gram_factor",
                            lambda G: real(G) if not calls.append(1) and len(calls) == 1
                            else None)
    rng = np.random.default_rng(17)
    N, n1, d = 400, 2, 3
    designs = [rng.standard_normal((N, n1 + d)) @ np.diag([1.0, 2.0, 0.3, 1.0, 5.0])
               for _ in range(2)]
    if shared:
        designs[1] = designs[0]
    residuals = rng.standard_normal((N, 2)) @ np.array([[1.0, 0.6], [0.0, 0.8]])
    F, lam = coefficient_factor(designs, residuals, [n1, n1])
    pinv = [np.linalg.solve(J.T @ J, J.T) for J in designs]
    cov = np.block([[lam[i, j] * (pinv[i] @ pinv[j].T)[n1:, n1:] for j in range(2)]
                    for i in range(2)])
    np.testing.assert_allclose(F @ F.T, cov, rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("method", ["armax", "oe", "bj"])
def test_the_covariance_from_gram_blocks_in_pieces_equals_the_whole_designs_one(
        method, monkeypatch):
    """armax, oe, bj on two outputs and two experiments, at the fitted model: the
    coefficient covariance from the designs' Gram blocks summed over pieces of 301
    samples (every output at the same samples, each kernel continuing where its last
    piece ended) equals that of the whole designs on the Gram route and on the QR route
    (GRAM_PIVOT above 1), and the residuals those of the whole designs' predictions."""
    from subid.methods.dt import _pe_search, _trust_region, pem_poly
    from subid.methods.dt._poly_covariance import (
        coefficient_factor,
        coefficient_factor_from_grams,
    )
    true = subid.systems.random_system(3, 2, 2, seed=51)
    data = subid.merge([subid.systems.simulate_data(true, 1400, seed=s, output_snr_db=25)
                        for s in (52, 53)])
    order = {"armax": (2, 2, 2, 1), "oe": (2, 2, 1), "bj": (2, 1, 1, 2, 1)}[method]
    real, seen = pem_poly._covariance_pass, []
    monkeypatch.setattr(pem_poly, "_covariance_pass",
                        lambda fitted, *a: seen.append(fitted) or real(fitted, *a))
    model = getattr(subid, method)(data, order)
    (fitted,) = seen
    monkeypatch.setattr(_pe_search, "JACOBIAN_PIECE_BYTES", 8 * 301 * 30)
    resid, grams, widths = real(fitted, data, True)
    designs = [pem_poly._sensitivities(sub, theta, x0, np.hstack([data.u, data.y[:, [i]]]),
                                       data.experiment_ranges, True)
               for i, (sub, theta, x0) in enumerate(fitted)]
    np.testing.assert_allclose(resid, data.y - np.column_stack([d[0] for d in designs]),
                               rtol=0, atol=1e-12 * np.abs(data.y).max())
    n1 = [w - sub.size for w, (sub, _, _) in zip(widths, fitted)]
    F, lam = coefficient_factor_from_grams(grams, widths, resid, n1)
    F_gram, lam_gram = coefficient_factor([d[1] for d in designs], resid, n1)
    monkeypatch.setattr(_trust_region, "GRAM_PIVOT", 2.0)
    F_qr, _ = coefficient_factor([d[1] for d in designs], resid, n1)
    for other in (F_gram, F_qr):
        np.testing.assert_allclose(F @ F.T, other @ other.T, rtol=1e-8,
                                   atol=1e-12 * np.abs(other @ other.T).max())
    np.testing.assert_array_equal(lam, lam_gram)
    if method == "oe":
        # output error: the sandwich (its meat from the designs in pieces of 301 samples,
        # each filtered with the last rows of the one before) is the model's (whole)
        from subid.methods.dt._poly_covariance import sandwich_coefficient_factor
        F, _ = sandwich_coefficient_factor(
            lambda: pem_poly._design_blocks(fitted, data, True), grams, widths, resid, n1,
            data.experiment_ranges, {})
        assert "sandwich" in model.info["parameter_covariance"]["method"]
        mine = model.info["parameter_covariance"]["coefficient_factor"]
        np.testing.assert_allclose(mine @ mine.T, F @ F.T, rtol=1e-9,
                                   atol=1e-12 * np.abs(F @ F.T).max())
        return
    np.testing.assert_allclose(model.info["parameter_covariance"]["coefficient_factor"], F,
                               rtol=1e-9, atol=1e-12 * np.abs(F).max())
