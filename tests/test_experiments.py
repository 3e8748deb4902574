"""Several experiments (subid.merge): no Hankel column, simulation or fold across a border."""

import warnings

import numpy as np
import pytest

import subid
from subid.errors import DataError
from subid.evaluation.metrics import markov_error
from subid.methods.dt._bd_large import fit_experiments
from subid.statistic._hankel import hankel_chunk

TRUE = subid.systems.seed001_system()
N_STATE = TRUE.order


def _record(n_samples, seed, x0_scale=5.0, system=TRUE):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n_samples, system.n_inputs))
    x0 = x0_scale * rng.standard_normal(system.order)
    return subid.IOData(u, system.simulate(u, x0=x0), dt=system.dt), x0


@pytest.fixture(scope="module")
def two_records():
    (a, xa), (b, xb) = _record(600, 1), _record(500, 2)
    return a, b, xa, xb


def _naive(a, b):
    return subid.IOData(np.vstack([a.u, b.u]), np.vstack([a.y, b.y]), dt=a.dt)


# ---------------------------------------------------------------------------
# the acceptance test of issue 16: every discrete-time method
# ---------------------------------------------------------------------------
DT_METHODS = [
    ("ls_subspace", lambda d, n: subid.ls_subspace(d, n)),
    ("ls_subspace no instruments", lambda d, n: subid.ls_subspace(d, n, instruments=None)),
    ("moesp", lambda d, n: subid.moesp(d, n)),
    ("moesp cva", lambda d, n: subid.moesp(d, n, weighting="cva")),
    ("n4sid", lambda d, n: subid.n4sid(d, n)),
    ("n4sid unit weights", lambda d, n: subid.n4sid(d, n, weighting="n4sid")),
    ("moesp order chosen", lambda d, n: subid.moesp(d)),
    ("moesp qr regression", lambda d, n: subid.moesp(d, n, stability="none",
                                                     statistic="gram")),
]


@pytest.mark.parametrize("name, method", DT_METHODS, ids=[m[0] for m in DT_METHODS])
def test_merge_is_exact_for_every_dt_method(two_records, name, method):
    a, b, _, _ = two_records
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        merged = method(subid.merge([a, b]), N_STATE)
        naive = method(_naive(a, b), N_STATE)
    assert merged.order == N_STATE
    assert markov_error(merged, TRUE) < 1e-8
    # the jump at the border of the naive concatenation is no linear response
    assert markov_error(naive, TRUE) > 1e-4
    assert markov_error(naive, TRUE) > 1e4 * markov_error(merged, TRUE)


def test_one_initial_state_per_experiment(two_records):
    a, b, _, _ = two_records
    data = subid.merge([a, b])
    model = subid.moesp(data, N_STATE)
    x0 = model.info["x0"]
    assert x0.shape == (2, N_STATE)
    assert model.info["n_experiments"] == 2
    # each experiment simulated from its own row reproduces its samples exactly
    for k, exp in enumerate(data.experiments):
        y = model.simulate(exp.u, x0=x0[k])
        assert np.abs(y - exp.y).max() < 1e-8 * np.abs(exp.y).max()
    fits = subid.fit_percent(model, data, per_experiment=True)
    assert fits.shape == (2, TRUE.n_outputs) and fits.min() > 100 - 1e-6
    # n4sid's x0 (from initial_state) and ls_subspace's (selector basis) too
    for other in (subid.n4sid(data, N_STATE), subid.ls_subspace(data, N_STATE)):
        x0 = other.info["x0"]
        assert x0.shape == (2, N_STATE)
        for k, exp in enumerate(data.experiments):
            y = other.simulate(exp.u, x0=x0[k])
            assert np.abs(y - exp.y).max() < 1e-7 * np.abs(exp.y).max()


def test_three_experiments_and_determinism():
    recs = [_record(n, seed)[0] for n, seed in ((400, 3), (350, 4), (300, 5))]
    data = subid.merge(recs)
    first = subid.n4sid(data, N_STATE)
    again = subid.n4sid(subid.merge(recs), N_STATE)
    assert markov_error(first, TRUE) < 1e-8
    np.testing.assert_array_equal(first.A, again.A)
    np.testing.assert_array_equal(first.info["x0"], again.info["x0"])


def test_merged_statistic_equals_the_hankel_columns_of_each_experiment():
    recs = [_record(n, seed)[0] for n, seed in ((200, 6), (150, 7), (40, 8))]
    depth = 8
    H = np.vstack([hankel_chunk(r.u, r.y, depth, 0, r.n_samples - depth + 1) for r in recs])
    reference = H.T @ H / H.shape[0]
    for kind in ("qr", "gram"):
        stat = subid.HankelStatistic.from_data(subid.merge(recs), depth, kind=kind)
        assert stat.n_columns == H.shape[0] and stat.n_experiments == 3
        assert np.abs(stat.gram() - reference).max() < 1e-12 * np.abs(reference).max()
        # the same statistic from separate statistics, in a tree
        parts = [subid.HankelStatistic.from_data(r, depth, kind=kind) for r in recs]
        tree = parts[0].merge(parts[1].merge(parts[2], new_experiment=True),
                              new_experiment=True)
        assert np.abs(tree.gram() - reference).max() < 1e-12 * np.abs(reference).max()
        # and chunk by chunk with new_experiment()
        stat = subid.HankelStatistic(2, 2, depth, kind=kind)
        for k, r in enumerate(recs):
            if k:
                stat.new_experiment()
            stat.update(r.u[:17], r.y[:17]).update(r.u[17:], r.y[17:])
        assert np.abs(stat.gram() - reference).max() < 1e-12 * np.abs(reference).max()


def test_contiguous_merge_of_a_multi_experiment_statistic_is_refused():
    recs = [_record(100, s)[0] for s in (1, 2)]
    stat = subid.HankelStatistic.from_data(subid.merge(recs), 6, kind="gram")
    first = subid.HankelStatistic.from_data(recs[0], 6, kind="gram")
    with pytest.raises(DataError, match="several experiments"):
        first.merge(stat)


@pytest.mark.parametrize("path", ["qr", "modal"])
def test_regression_with_one_x0_per_experiment_agrees_with_a_direct_solution(path):
    """The embedded per-experiment problem equals one least-squares solve of the
    stacked regressors (built here sample by sample, independently)."""
    rng = np.random.default_rng(11)
    data = subid.merge([_record(120, 12)[0], _record(90, 13)[0]])
    noisy_y = data.y + 0.1 * rng.standard_normal(data.y.shape)
    A, C = TRUE.A, TRUE.C
    n, nu, ny = N_STATE, 2, 2
    starts = [a for a, _ in data.experiment_ranges]
    B, D, x0, diag = fit_experiments(A, C, data.u, noisy_y, starts, path=path)
    assert diag["regression_path"] == path and x0.shape == (2, n)
    rows, rhs = [], []
    for e, (a, b) in enumerate(data.experiment_ranges):
        S = np.zeros((n, 2 * n + n * nu))
        S[:, e * n:(e + 1) * n] = np.eye(n)
        for t in range(a, b):
            rows.append(np.hstack([C @ S, np.kron(data.u[t], np.eye(ny))]))
            rhs.append(noisy_y[t])
            S = A @ S
            for j in range(nu):
                S[:, 2 * n + j * n:2 * n + (j + 1) * n] += data.u[t, j] * np.eye(n)
    theta = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    np.testing.assert_allclose(x0.ravel(), theta[:2 * n], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(B, theta[2 * n:2 * n + n * nu].reshape(nu, n).T, rtol=1e-7,
                               atol=1e-9)
    np.testing.assert_allclose(D, theta[2 * n + n * nu:].reshape(nu, ny).T, rtol=1e-7,
                               atol=1e-9)


# ---------------------------------------------------------------------------
# the record: merge, ranges, slicing, detrending
# ---------------------------------------------------------------------------
def test_merge_keeps_the_borders(two_records):
    a, b, _, _ = two_records
    data = subid.merge([a, b], names=["run A", "run B"])
    assert data.n_experiments == 2 and data.n_samples == 1100
    assert data.experiment_ranges == ((0, 600), (600, 1100))
    assert data.experiment("run B").n_samples == 500
    np.testing.assert_array_equal(data.experiment(1).u, b.u)
    np.testing.assert_array_equal(data.t[598:602], [598, 599, 0, 1])
    assert "experiments=2" in repr(data) and "run A" in data._repr_html_()
    # slices keep the borders inside them
    part = data[500:700]
    assert part.experiment_ranges == ((0, 100), (100, 200))
    assert part.experiment_names == ("run A", "run B")
    assert data[650:].n_experiments == 1
    est, val = data.split(0.5)
    assert est.n_experiments == 1 and val.n_experiments == 2
    # merging merged records flattens them
    assert subid.merge([data, a]).n_experiments == 3
    assert subid.merge([a]).n_experiments == 1


def test_detrend_per_experiment(two_records):
    a, b, _, _ = two_records
    shifted = subid.IOData(b.u + 3.0, b.y - 2.0, dt=b.dt)
    data = subid.merge([a, shifted]).detrend()
    assert data.u_offset.shape == (2, 2) and data.y_offset.shape == (2, 2)
    for k, exp in enumerate(data.experiments):
        assert np.abs(exp.u.mean(axis=0)).max() < 1e-12
        np.testing.assert_allclose(exp.u_offset, data.u_offset[k])
    np.testing.assert_allclose(data.u_offset[1], b.u.mean(axis=0) + 3.0)
    pooled = subid.merge([a, shifted]).detrend(per_experiment=False)
    assert pooled.u_offset.shape == (2,)
    assert abs(pooled.u.mean(axis=0)).max() < 1e-12
    # records detrended one by one merge with their offsets stacked
    both = subid.merge([a.detrend(), shifted.detrend()])
    np.testing.assert_allclose(both.u_offset, data.u_offset)
    np.testing.assert_allclose(both.u, data.u)


def test_experiments_at_different_operating_points(two_records):
    """An experiment at another steady operating point (u0, y0 = G(1) u0) is the same
    system from another initial state: exact without detrending; detrending each
    experiment leaves only the small error of the sample means."""
    a, b, _, _ = two_records
    gain = TRUE.C @ np.linalg.solve(np.eye(N_STATE) - TRUE.A, TRUE.B) + TRUE.D
    u0 = np.array([3.0, -2.0])
    shifted = subid.IOData(b.u + u0, b.y + gain @ u0, dt=b.dt)
    assert markov_error(subid.moesp(subid.merge([a, shifted]), N_STATE), TRUE) < 1e-8
    detrended = subid.merge([a, shifted]).detrend()
    assert markov_error(subid.moesp(detrended, N_STATE), TRUE) < 1e-3


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
def test_merge_refuses_what_does_not_match(two_records):
    a, b, _, _ = two_records
    with pytest.raises(DataError, match="list of IOData"):
        subid.merge(a)
    with pytest.raises(DataError, match="at least one"):
        subid.merge([])
    with pytest.raises(DataError, match=r"item 1\) expects an IOData record, got ndarray"):
        subid.merge([a, b.u])
    with pytest.raises(DataError, match="dt=0.5"):
        subid.merge([a, subid.IOData(b.u, b.y, dt=0.5)])
    with pytest.raises(DataError, match="1 inputs"):
        subid.merge([a, subid.IOData(b.u[:, 0], b.y, dt=b.dt)])
    with pytest.raises(DataError, match="rename or reorder"):
        subid.merge([a, subid.IOData(b.u, b.y, dt=b.dt, input_names=["p", "q"])])
    with pytest.raises(DataError, match="non-uniform"):
        subid.merge([a, subid.IOData(b.u[:3], b.y[:3], t=[0.0, 1.0, 3.0])])
    with pytest.raises(DataError, match="detrended and others not"):
        subid.merge([a.detrend(), b])
    with pytest.raises(DataError, match="2 names for 3"):
        subid.merge([a, b, a], names=["x", "y"])
    with pytest.raises(DataError, match="repeat"):
        subid.merge([a, b], names=["x", "x"])
    data = subid.merge([a, b])
    with pytest.raises(DataError, match="experiment index"):
        data.experiment(2)
    with pytest.raises(DataError, match="no experiment named"):
        data.experiment("nope")
    with pytest.raises(DataError, match="step"):
        data[::2]
    with pytest.raises(DataError, match=r"x0 must be .* array of shape \(2, 3\)"):
        subid.fit_percent(TRUE, data, x0=np.zeros(3))


def test_methods_that_cannot_use_experiments_apart_say_so(two_records):
    a, b, _, _ = two_records
    ct = subid.IOData(a.u, a.y, dt=0.1)
    ct_data = subid.merge([ct, subid.IOData(b.u, b.y, dt=0.1)])   # ct_subspace takes it (issue 22)
    online = subid.AdaptiveIdentifier(order=2, n_inputs=2, n_outputs=2)
    with pytest.raises(DataError, match="does not support several experiments"):
        online.update(ct_data)


def test_too_short_experiments_are_reported(two_records):
    a, _, _, _ = two_records
    short = subid.merge([a[:30], a[30:60], a[60:90]])
    with pytest.raises(subid.errors.TooFewSamplesError, match="3 experiments"):
        subid.moesp(short, N_STATE, horizon=10)


# ---------------------------------------------------------------------------
# prediction-error refinement
# ---------------------------------------------------------------------------
def test_pem_with_one_x0_per_experiment_converges_exactly():
    """From a perturbed start on noise-free data, pem reaches the true model to rounding
    only when each experiment has its own initial state (its x0 Jacobian columns)."""
    a, b = _record(400, 41)[0], _record(300, 42)[0]
    start = subid.StateSpace(TRUE.A * 0.97, TRUE.B * 1.05, TRUE.C, TRUE.D, TRUE.dt)
    merged = subid.pem(subid.merge([a, b]), start, focus="simulation", max_iterations=200)
    naive = subid.pem(_naive(a, b), start, focus="simulation", max_iterations=200)
    assert merged.info["x0"].shape == (2, N_STATE)
    assert markov_error(merged, TRUE) < 1e-8
    assert markov_error(naive, TRUE) > 1e-3
    for k, exp in enumerate((a, b)):
        y = merged.simulate(exp.u, x0=merged.info["x0"][k])
        assert np.abs(y - exp.y).max() < 1e-6 * np.abs(exp.y).max()


def test_pem_on_one_merged_experiment_is_pem_on_the_record():
    a = _record(300, 43)[0]
    noisy = subid.IOData(a.u, a.y + 0.1 * np.random.default_rng(0).standard_normal(a.y.shape),
                         dt=a.dt)
    start = subid.moesp(noisy, N_STATE)
    one = subid.pem(noisy, start)
    merged = subid.pem(subid.merge([noisy]), start)
    np.testing.assert_array_equal(one.A, merged.A)
    assert merged.info["x0"].shape == (N_STATE,)
    refined = subid.moesp(subid.merge([noisy, _record(200, 44)[0]]), N_STATE, refine="pem")
    assert refined.info["refined_by"] == "pem" and refined.info["x0"].shape == (2, N_STATE)
    assert refined.info["final_cost"] <= refined.info["start_cost"]


# ---------------------------------------------------------------------------
# validation, prediction, residuals, delays
# ---------------------------------------------------------------------------
def test_prediction_and_residuals_per_experiment(two_records):
    a, b, _, _ = two_records
    data = subid.merge([a, b])
    model = subid.n4sid(data, N_STATE)
    y_hat, x0 = subid.predict(model, data, 1, return_x0=True)
    assert x0.shape == (2, N_STATE)
    assert np.abs(y_hat - data.y).max() < 1e-7 * np.abs(data.y).max()
    pooled = subid.fit_percent(model, data)
    assert pooled.shape == (2,) and pooled.min() > 100 - 1e-6
    # residual correlations pair no samples of two experiments: the residuals of a
    # model simulated without x0 are the free responses; with the pairs across the
    # border removed the lag-1 correlation is that of the two pieces alone
    e = data.y - subid.predict(model, data, np.inf, x0="zero")
    from subid.evaluation.residuals import correlations
    joint = correlations(e, data.u, max_lag=5, ranges=data.experiment_ranges)
    # lagged products summed inside each experiment only, by hand
    e0 = e - e.mean(axis=0)
    u0 = data.u - data.u.mean(axis=0)
    ranges = data.experiment_ranges
    for lag in (1, 3):
        auto = sum(e0[s + lag:t, 0] @ e0[s:t - lag, 0] for s, t in ranges)
        np.testing.assert_allclose(joint["auto"][0, lag], auto / (e0[:, 0] @ e0[:, 0]),
                                   rtol=1e-12)
    cross = sum(e0[s + 2:t, 1] @ u0[s:t - 2, 0] for s, t in ranges) / len(e0)
    scale = np.sqrt((e0[:, 1] @ e0[:, 1]) * (u0[:, 0] @ u0[:, 0])) / len(e0)
    np.testing.assert_allclose(joint["cross"][1, 0, 5 + 2], cross / scale, rtol=1e-10)
    whole = correlations(e, data.u, max_lag=5)       # joins the experiments
    assert abs(whole["auto"][0, 1] - joint["auto"][0, 1]) > 1e-6


def test_fit_is_pooled_with_each_experiments_mean():
    rec = _record(300, 21)[0]
    other = subid.IOData(rec.u, rec.y + 100.0, dt=rec.dt)     # a far operating point
    data = subid.merge([rec, other])
    # the pooled fit computed by hand, reference = each experiment's own mean
    model = TRUE
    fits = subid.fit_percent(model, data, x0=np.zeros((2, N_STATE)))
    sim = np.vstack([model.simulate(rec.u), model.simulate(other.u)])
    err = np.linalg.norm(data.y - sim, axis=0)
    dev = np.sqrt(sum(np.linalg.norm(e.y - e.y.mean(axis=0), axis=0) ** 2
                      for e in data.experiments))
    np.testing.assert_allclose(fits, 100 * (1 - err / dev), rtol=1e-10)


def test_input_delay_shifts_every_experiment():
    """y[k] responds to u[k - 2] in both experiments (each from its own x0): with
    input_delay=2 every experiment loses its own first 2 samples and the model is exact."""
    recs = []
    for seed in (31, 32):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal((500, 2))
        late = np.vstack([np.zeros((2, 2)), u[:-2]])
        recs.append(subid.IOData(u, TRUE.simulate(late, x0=rng.standard_normal(N_STATE)),
                                 dt=TRUE.dt))
    data = subid.merge(recs)
    shifted, _ = subid.delay.delay_inputs(data, 2)
    assert shifted.experiment_ranges == ((0, 498), (498, 996))
    model = subid.moesp(data, N_STATE, input_delay=2)
    assert model.info["input_delay"] == [2, 2]
    undelayed = subid.StateSpace(model.A, model.B, model.C, model.D, model.dt)
    assert markov_error(undelayed, TRUE) < 1e-8
    assert subid.fit_percent(model, data).min() > 100 - 1e-6


def test_estimate_delay_uses_every_experiment():
    rng = np.random.default_rng(5)
    recs = []
    for seed in (1, 2):
        r = np.random.default_rng(seed)
        u = r.standard_normal((400, 1))
        y = np.zeros((400, 1))
        y[3:, 0] = 0.8 * u[:-3, 0]
        y += 0.01 * rng.standard_normal(y.shape)
        recs.append(subid.IOData(u, y))
    assert subid.estimate_delay(subid.merge(recs), 6).tolist() == [3]


# ---------------------------------------------------------------------------
# streaming and files
# ---------------------------------------------------------------------------
def test_identify_stream_with_new_experiment_marker(two_records):
    a, b, _, _ = two_records
    from subid.methods.dt.stream import NEW_EXPERIMENT, identify_stream
    pieces = [a[:250], a[250:], NEW_EXPERIMENT, b[:100], b[100:]]
    model = identify_stream(pieces, "moesp", N_STATE, horizon=10)
    assert markov_error(model, TRUE) < 1e-8
    assert model.info["x0"].shape == (2, N_STATE)
    assert model.info["n_experiments"] == 2
    in_memory = subid.moesp(subid.merge([a, b]), N_STATE, horizon=10, statistic="gram")
    np.testing.assert_allclose(model.info["x0"], in_memory.info["x0"], rtol=1e-6, atol=1e-8)
    # a merged piece carries its border; joined pieces are one record
    assert markov_error(identify_stream([subid.merge([a, b])], "moesp", N_STATE, horizon=10),
                        TRUE) < 1e-8
    joined = identify_stream([a, b], "moesp", N_STATE, horizon=10)
    assert markov_error(joined, TRUE) > 1e-4


def test_identify_file_with_several_files(tmp_path, two_records):
    a, b, _, _ = two_records
    paths = []
    for k, rec in enumerate((a, b)):
        path = tmp_path / f"exp{k}.csv"
        np.savetxt(path, np.hstack([rec.u, rec.y]), delimiter=",",
                   header="u1,u2,y1,y2", comments="")
        paths.append(str(path))
    model = subid.identify_file(paths, ["u1", "u2"], ["y1", "y2"], order=N_STATE, horizon=10,
                                chunk_size=128)
    assert markov_error(model, TRUE) < 1e-8
    assert model.info["x0"].shape == (2, N_STATE)


def test_distributed_files_as_experiments(tmp_path, two_records):
    pytest.importorskip("dask")
    from subid.methods.dt.distributed import identify_files
    a, b, _, _ = two_records
    paths = []
    for k, rec in enumerate((a, b)):
        path = tmp_path / f"exp{k}.csv"
        np.savetxt(path, np.hstack([rec.u, rec.y]), delimiter=",",
                   header="u1,u2,y1,y2", comments="")
        paths.append(str(path))
    model = identify_files(paths, ["u1", "u2"], ["y1", "y2"], order=N_STATE, horizon=10,
                           experiments=True)
    assert markov_error(model, TRUE) < 1e-8
    assert model.info["x0"].shape == (2, N_STATE)
    joined = identify_files(paths, ["u1", "u2"], ["y1", "y2"], order=N_STATE, horizon=10)
    assert markov_error(joined, TRUE) > 1e-4


# ---------------------------------------------------------------------------
# command line: several DATA files are experiments
# ---------------------------------------------------------------------------
def _write_csv(path, rec):
    np.savetxt(path, np.hstack([rec.u, rec.y]), delimiter=",", header="u1,u2,y1,y2",
               comments="")
    return str(path)


def test_cli_identify_merges_several_files(tmp_path, two_records, capsys):
    pytest.importorskip("click")
    pytest.importorskip("matplotlib")
    import json

    from subid.cli.commands import main
    a, b, _, _ = two_records
    paths = [_write_csv(tmp_path / "a.csv", a), _write_csv(tmp_path / "b.csv", b)]
    out = tmp_path / "out"
    channels = ["--inputs", "u1,u2", "--outputs", "y1,y2"]
    code = main(["identify", *paths, *channels, "--method", "moesp", "--order", "3",
                 "--no-report", "--out", str(out)])
    capsys.readouterr()
    assert code == 0
    model = subid.StateSpace.load(out / "model.json")
    assert np.shape(model.info["x0"]) == (2, N_STATE)
    assert [e["name"] for e in model.info["data"]["experiments"]] == ["a.csv", "b.csv"]
    assert np.shape(model.info["data"]["u_offset"]) == (2, 2)
    summary = json.loads((out / "summary.json").read_text())
    assert min(summary["fit_estimation"]) > 99   # means removed per file: not exact
    # an online method would join the files: refused
    code = main(["identify", *paths, *channels, "--method", "recursive", "--order", "3",
                 "--out", str(tmp_path / "bad")])
    captured = capsys.readouterr()
    assert code != 0 and "experiments" in captured.err
    # a missing file is named alone, not as the list
    code = main(["identify", paths[0], str(tmp_path / "missing.csv"), *channels, "--out",
                 str(tmp_path / "bad2")])
    captured = capsys.readouterr()
    assert code != 0 and "missing.csv" in captured.err and " + " not in captured.err


def test_n4sid_enforced_stability_on_several_experiments():
    # a near-integrator: the fold models of the cross-validation have an unstable A that
    # 'enforce' stabilises; x0 then has one row per experiment (was a raw ValueError)
    def record(seed, n_samples=300):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal((n_samples, 1))
        y, x = np.zeros((n_samples, 1)), 0.0
        for k in range(n_samples):
            y[k] = x + 0.3 * rng.standard_normal()
            x = x + 0.1 * u[k, 0]
        return subid.IOData(u, y, dt=1.0)

    data = subid.merge([record(1), record(2), record(3)])
    model = subid.n4sid(data, 2, stability="enforce")
    assert np.all(np.isfinite(model.A)) and np.abs(np.linalg.eigvals(model.A)).max() < 1
    assert np.shape(model.info["x0"]) == (3, 2)


def test_simulate_and_simulation_bounds_restart_at_each_experiment():
    """StateSpace.simulate and simulation_bounds on a merged record simulate each
    experiment from its own initial state (zeros, or one row per experiment), as the
    methods model it; before, both ran the second experiment on from the first one's
    final state, silently (0.80 off on this record)."""
    true = subid.systems.random_system(3, 1, 1, seed=7)
    d1 = subid.systems.simulate_data(true, 400, seed=1)
    d2 = subid.systems.simulate_data(true, 250, seed=2)
    merged = subid.merge([d1, d2])
    model = subid.identify(merged, 3)
    per = np.vstack([model.simulate(d1.u), model.simulate(d2.u)])
    np.testing.assert_array_equal(model.simulate(merged), per)
    x0 = model.info["x0"]
    assert x0.shape == (2, 3)
    y, x = model.simulate(merged, x0=x0, return_state=True)
    np.testing.assert_array_equal(y, np.vstack([model.simulate(d1.u, x0=x0[0]),
                                                model.simulate(d2.u, x0=x0[1])]))
    np.testing.assert_array_equal(x[400], x0[1])
    with pytest.raises(subid.errors.DataError, match="one initial state per experiment"):
        model.simulate(merged, x0=x0[0])
    bounds = subid.simulation_bounds(model, merged, x0=x0)
    np.testing.assert_allclose(bounds.value, y, atol=1e-12)
    first = subid.simulation_bounds(model, d1, x0=x0[0])
    np.testing.assert_allclose(bounds.std[:400], first.std, atol=1e-14)
    assert bounds.x[400] == 0.0 and bounds.x.shape == (650,)
    with pytest.raises(subid.errors.DataError, match="one initial state per experiment"):
        subid.simulation_bounds(model, merged, x0=x0[0])
