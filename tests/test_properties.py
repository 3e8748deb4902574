"""Property-based tests (hypothesis) of the batch methods, models and data."""

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import subid
from conftest import METHODS
from subid import errors, systems

system_specs = st.tuples(st.integers(1, 5), st.integers(1, 3), st.integers(1, 3),
                         st.integers(0, 10**6))


def _system_and_data(spec, n=900):
    order, nu, ny, seed = spec
    true = systems.random_system(order, nu, ny, seed=seed)
    return true, systems.simulate_data(true, n, seed=seed + 1)


@given(spec=system_specs, method=st.sampled_from(sorted(METHODS)))
def test_noise_free_invariants_recovered(spec, method):
    true, data = _system_and_data(spec)
    model = METHODS[method](data, spec[0])
    assert subid.markov_error(model, true) < 1e-7
    assert subid.pole_error(model, true) < 1e-6
    w = np.array([0.01, 0.3, 1.0, 2.5])
    np.testing.assert_allclose(model.freqresp(w), true.freqresp(w), rtol=1e-6,
                               atol=1e-8 * np.abs(true.freqresp(w)).max())


@given(spec=system_specs, method=st.sampled_from(sorted(METHODS)),
       log_scales=st.lists(st.floats(-6, 6), min_size=6, max_size=6))
def test_scaling_of_channels(spec, method, log_scales):
    """Scaling input and output channels scales the model accordingly."""
    true, data = _system_and_data(spec)
    nu, ny = data.n_inputs, data.n_outputs
    su = 10.0 ** np.array(log_scales[:nu])
    sy = 10.0 ** np.array(log_scales[3:3 + ny])
    scaled = subid.IOData(data.u * su, data.y * sy)
    model = METHODS[method](scaled, spec[0])
    expected = subid.StateSpace(true.A, true.B / su, true.C * sy[:, None],
                                true.D * sy[:, None] / su, 1.0)
    assert subid.markov_error(model, expected) < 1e-6


@given(spec=system_specs, method=st.sampled_from(sorted(METHODS)), data_seed=st.integers(0, 99))
def test_permutation_of_channels(spec, method, data_seed):
    true, data = _system_and_data(spec)
    r = np.random.default_rng(data_seed)
    pu, py = r.permutation(data.n_inputs), r.permutation(data.n_outputs)
    model = METHODS[method](subid.IOData(data.u[:, pu], data.y[:, py]), spec[0])
    expected = subid.StateSpace(true.A, true.B[:, pu], true.C[py], true.D[np.ix_(py, pu)], 1.0)
    assert subid.markov_error(model, expected) < 1e-7


finite = st.floats(-1e300, 1e300, allow_nan=False, allow_infinity=False)


@given(n=st.integers(1, 6), nu=st.integers(0, 3), ny=st.integers(1, 3),
       dt=st.one_of(st.just(0.0), st.floats(1e-9, 1e9)), data=st.data())
def test_model_json_round_trip(n, nu, ny, dt, data):
    def matrix(rows, cols):
        return np.array(data.draw(st.lists(finite, min_size=rows * cols, max_size=rows * cols)),
                        dtype=float).reshape(rows, cols)
    model = subid.StateSpace(matrix(n, n), matrix(n, nu), matrix(ny, n), matrix(ny, nu), dt,
                             info={"note": data.draw(st.text(max_size=20)),
                                   "values": matrix(2, 2), "nan": float("nan")})
    again = subid.StateSpace.from_dict(model.to_dict())
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(again, name), getattr(model, name))
    assert again.dt == model.dt
    assert again.info["note"] == model.info["note"]
    assert np.isnan(again.info["nan"])


@given(n=st.integers(2, 50), bad_row=st.integers(0, 49), bad=st.sampled_from(
    [np.nan, np.inf, -np.inf]), which=st.sampled_from(["u", "y"]))
def test_iodata_rejects_non_finite(n, bad_row, bad, which):
    assume(bad_row < n)
    u, y = np.zeros((n, 2)), np.zeros(n)
    (u if which == "u" else y)[bad_row, ...] = bad
    with pytest.raises(errors.DataError, match=f"row {bad_row}"):
        subid.IOData(u, y)


@given(n=st.integers(3, 40), k=st.integers(1, 38), back=st.floats(0, 5))
def test_iodata_rejects_non_increasing_time(n, k, back):
    assume(k < n)
    t = np.arange(float(n))
    t[k] = t[k - 1] - back
    with pytest.raises(errors.DataError, match=f"row {k}"):
        subid.IOData(np.zeros(n), np.zeros(n), t=t)


@given(nu=st.integers(1, 4), ny=st.integers(1, 4), n_u=st.integers(1, 30),
       n_y=st.integers(1, 30))
def test_iodata_rejects_length_mismatch(nu, ny, n_u, n_y):
    assume(n_u != n_y)
    with pytest.raises(errors.DataError, match="samples"):
        subid.IOData(np.zeros((n_u, nu)), np.zeros((n_y, ny)))


def _random_ct_system(order, nu, ny, seed):
    import scipy.linalg
    r = np.random.default_rng(seed)
    blocks, k = [], order
    while k > 0:
        if k >= 2 and r.random() < 0.5:
            re, im = -r.uniform(0.3, 3.0), r.uniform(0.3, 3.0)
            blocks.append(np.array([[re, im], [-im, re]]))
            k -= 2
        else:
            blocks.append(np.array([[-r.uniform(0.3, 3.0)]]))
            k -= 1
    T = np.linalg.qr(r.standard_normal((order, order)))[0] @ np.diag(r.uniform(0.5, 2, order))
    A = T @ scipy.linalg.block_diag(*blocks) @ np.linalg.inv(T)
    return subid.StateSpace(A, r.standard_normal((order, nu)), r.standard_normal((ny, order)),
                            np.zeros((ny, nu)), 0)


@given(order=st.integers(1, 4), nu=st.integers(1, 2), ny=st.integers(1, 2),
       seed=st.integers(0, 10**6), jitter=st.booleans())
@pytest.mark.slow
def test_ct_subspace_recovers_frequency_response(order, nu, ny, seed, jitter):
    """Continuous-time identification (seed 002) on noise-free FOH data, on a
    uniform or a jittered grid: the frequency response is recovered."""
    true = _random_ct_system(order, nu, ny, seed)
    r = np.random.default_rng(seed + 1)
    t = np.arange(2000) * 0.01
    if jitter:
        t = t + r.uniform(-0.003, 0.003, t.size)
    # each input its own 15 frequencies: two multisines on one set of frequencies span
    # too few directions together (the filtered inputs were linearly dependent)
    w = np.logspace(-1, 1.3, 15)
    u = np.column_stack([np.sin(np.outer(t, w * (1.0 + 0.13 * j)) + r.uniform(0, 6.3, w.size))
                         .sum(axis=1) for j in range(nu)])
    data = subid.IOData(u, true.simulate(u, t=t, hold="foh"), t=t)
    model = subid.ct_subspace(data, order)
    grid = np.logspace(-1, 1, 20)
    G = true.freqresp(grid)
    assert np.abs(model.freqresp(grid) - G).max() < 1e-6 * np.abs(G).max()
