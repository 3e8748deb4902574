"""No silent wrong results (issue 15, classes 4 and 7, the parts in the
loading/validation layer): each case is a clear subid.errors exception or a
correct result."""

import numpy as np
import pytest
import scipy.io
from hypothesis import given
from hypothesis import strategies as st

import subid
from subid import errors, systems
from subid.cli import commands as cli


@given(row=st.integers(0, 2), col=st.integers(0, 2), imag=st.floats(1e-12, 1e3),
       key=st.sampled_from(["A", "B", "C", "D"]), struct=st.booleans())
def test_complex_mat_model_is_refused(tmp_path_factory, row, col, imag, key, struct):
    """A .mat model with complex matrices lost the imaginary part (scipy's
    mat_dtype cast); now a ModelError naming the matrix."""
    m = systems.seed001_system()
    mats = {"A": m.A, "B": m.B, "C": m.C, "D": m.D}
    value = mats[key].astype(complex)
    value[row % value.shape[0], col % value.shape[1]] += 1j * imag
    mats[key] = value
    mats["Ts"] = 1.0
    path = tmp_path_factory.mktemp("mat") / "model.mat"
    scipy.io.savemat(path, {"sys": mats} if struct else mats)
    with pytest.raises(errors.ModelError, match=f"{key} is complex"):
        subid.StateSpace.from_mat(path)


@pytest.mark.parametrize("dt", [1.0, 0.0])
def test_simulating_an_unstable_model_past_overflow_is_an_error(dt):
    A = np.array([[1e3]]) if dt else np.array([[800.0]])
    model = subid.StateSpace(A, [[1.0]], [[1.0]], [[0.0]], dt)
    t = np.arange(200.0)
    with pytest.raises(errors.ModelError, match="overflows at sample"):
        model.simulate(np.ones(200), t=None if dt else t)
    assert np.isfinite(model.simulate(np.ones(20), t=None if dt else t[:20] / 1e3)).all()


def test_subid_simulate_does_not_write_overflowed_rows(tmp_path, capsys):
    """subid simulate wrote inf/NaN rows of an unstable model with exit 0."""
    model = tmp_path / "unstable.json"
    subid.StateSpace([[1e3]], [[1.0]], [[1.0]], [[0.0]], 1.0).save(model)
    inputs = tmp_path / "u.csv"
    inputs.write_text("u1\n" + "1\n" * 300)
    out = tmp_path / "y.csv"
    assert cli.main(["--quiet", "simulate", str(model), "--input", str(inputs),
                     "--out", str(out)]) == 2
    assert "overflows" in capsys.readouterr().err
    assert not out.exists()


@given(exponent=st.integers(-300, 300))
def test_fit_percent_is_scale_invariant(exponent):
    """fit_percent returned NaN for outputs near 1e300 (inf / inf)."""
    m = systems.seed001_system()
    data = systems.simulate_data(m, 200, seed=0, output_snr_db=20)
    from subid.evaluation.metrics import fit_percent  # not an attribute before import
    ref = fit_percent(m, data, x0="zero")
    scale = 10.0 ** exponent
    scaled = subid.IOData(data.u, data.y * scale, dt=data.dt)
    model = subid.StateSpace(m.A, m.B, m.C * scale, m.D * scale, m.dt)
    got = fit_percent(model, scaled, x0="zero")
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9)


def test_stream_pieces_with_another_period_are_not_merged():
    data = systems.simulate_data(systems.seed001_system(), 600, seed=0)
    other = subid.IOData(data.u[300:], data.y[300:], dt=2 * data.dt)
    with pytest.raises(errors.DataError, match="piece 1 is sampled with dt"):
        subid.identify_stream([data[:300], other], order=3, horizon=5)


@given(rows=st.lists(st.lists(st.floats(-1, 1), min_size=1, max_size=3), min_size=2,
                     max_size=6),
       big=st.integers(2**1024, 2**1100))
def test_iodata_ragged_and_huge_ints_are_data_errors(rows, big):
    """Ragged lists and Python integers beyond the float range raised numpy's
    ValueError/OverflowError."""
    y = np.zeros(len(rows))
    if len({len(r) for r in rows}) > 1:
        with pytest.raises(errors.DataError, match="ragged"):
            subid.IOData(rows, y, dt=1.0)
    else:
        subid.IOData(rows, y, dt=1.0)
    with pytest.raises(errors.DataError, match="too large"):
        subid.IOData([big] + [0] * (len(rows) - 1), y, dt=1.0)
    with pytest.raises(errors.DataError):
        subid.IOData(y, y, dt=big)


@pytest.mark.parametrize("call", [
    lambda d: subid.moesp(d, 10**9),
    lambda d: subid.n4sid(d, 3, horizon=10**12),
    lambda d: subid.ls_subspace(d, 2**80),
    lambda d: subid.RecursiveSubspace(10**7, 2, 2),
    lambda d: subid.HankelStatistic(2, 2, depth=10**10),
    lambda d: subid.AdaptiveIdentifier(2, 2, 2, dt=0.01, history_size=10**9),
    lambda d: subid.RecursiveSubspace(2, 2, 2, lags=10**9),
    lambda d: subid.RecursiveSubspace(2, 2, 2, history_size=2**50),
])
def test_absurd_sizes_are_order_errors_not_memory_errors(call):
    data = systems.simulate_data(systems.seed001_system(), 300, seed=0)
    with pytest.raises(errors.OrderError, match="at most"):
        call(data)


def test_adaptive_model_before_any_data_is_an_error():
    import subid
    with pytest.raises(subid.errors.TooFewSamplesError, match="no samples yet"):
        subid.AdaptiveIdentifier(2, 1, 1).model


@pytest.mark.parametrize("method", ["ls_subspace", "moesp", "n4sid"])
def test_data_whose_squares_overflow_are_named(method):
    import subid
    true = subid.systems.seed001_system()
    d = subid.systems.simulate_data(true, 600, seed=1)
    with pytest.raises(subid.errors.DataError, match="output y1 reaches .*overflow"):
        getattr(subid, method)(subid.IOData(d.u, d.y * 1e155), 3, horizon=5)
    big = getattr(subid, method)(subid.IOData(d.u, d.y * 1e17), 3, horizon=5)
    assert subid.pole_error(big, true) < 1e-9          # large but representable: exact


def test_ct_spacing_below_time_stamp_resolution_is_named():
    import subid
    ct = subid.StateSpace([[-1.0, 2.0], [-2.0, -1.0]], [[1.0], [0.5]], [[1.0, 0.0]], 0, dt=0)
    t = 1e6 + np.arange(400) * 0.05
    # an interval of 50 rounding units of 1e6 (5.8e-9): known to 2 %; one of 1e-4 is
    # known to 1e-6 and is fitted (it was refused as below 1e-9 of the magnitude; an
    # interval 500 times shorter than the others costs the noise-free fit 3 points)
    t[200] = t[199] + 50 * np.spacing(1e6)
    u = np.random.default_rng(0).standard_normal(400)
    data = subid.IOData(u, ct.simulate(u, t=t - t[0]), t=t)
    with pytest.raises(subid.errors.DataError, match="rows 199, 200.*below the resolution"):
        subid.ct_subspace(data, 2)
    t[200] = t[199] + 1e-4
    fine = subid.IOData(u, ct.simulate(u, t=t - t[0]), t=t)
    assert min(subid.fit_percent(subid.ct_subspace(fine, 2), fine)) > 95


def test_fit_percent_from_a_non_zero_initial_state_is_scale_invariant():
    """The initial-state regression weighs the outputs by 1/std: above 1e153 the
    spread overflowed to inf, the weights became 0 and x0 silently 0 (the fit of a record
    starting away from rest fell from 96.9 to the x0 = 0 fit). subid.data.column_std
    rescales such channels first."""
    true = subid.systems.random_system(3, 2, 2, seed=1)
    data = subid.systems.simulate_data(true, 1000, seed=1, output_snr_db=30,
                                       x0=np.array([5.0, -3.0, 2.0]))[50:]
    model = subid.moesp(data, 3)
    reference = subid.fit_percent(model, data)
    for s in (1e153, 1e300):
        scaled = subid.StateSpace(model.A, model.B, model.C * s, model.D * s, model.dt)
        np.testing.assert_allclose(subid.fit_percent(scaled, data.scaled(outputs=[s, s])),
                                   reference, atol=1e-9)
