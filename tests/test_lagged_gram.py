"""The Gram matrix of lagged regressors summed along its diagonals, and the start
regressions of the polynomial searches that use it (subid.methods.dt._lagged_gram,
subid.methods.dt.polynomial.regress_start)."""

import numpy as np
import pytest

from subid.methods.dt._lagged_gram import (
    contiguous_lags,
    lagged_gram,
    lagged_gram_reference,
)
from subid.methods.dt.polynomial import regress, regress_start


def _signals(n, seed):
    rng = np.random.default_rng(seed)
    u1, u2, e = rng.standard_normal((3, n))
    y = np.zeros(n)
    for t in range(2, n):                       # an ARX output with memory
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + u1[t - 1] + 0.4 * u2[t - 2] + 0.3 * e[t]
    return u1, u2, y


@pytest.mark.parametrize("first", [8, 9, 13])
def test_the_diagonal_sums_give_the_gram_matrix_of_the_lagged_columns(first):
    """Blocks of unequal lengths starting at lags 0, 2 and 1; three experiments, one of
    them no longer than ``first`` (no rows), one barely longer; the target last: the
    matrix of [Phi T]^T [Phi T] formed row by row, to rounding."""
    u1, u2, y = _signals(2500, 1)
    blocks = [(u1, range(0, 7)), (u2, range(2, 5)), (y, range(1, 9))]
    ranges = [(0, 1200), (1200, 1200 + first), (1200 + first, 1200 + first + 11),
              (1200 + first + 11, 2500)]
    G = lagged_gram(y, blocks, ranges, first)
    ref = lagged_gram_reference(y, blocks, ranges, first)
    assert G.shape == (19, 19)
    np.testing.assert_allclose(G, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    np.testing.assert_array_equal(G, G.T)


def test_lags_that_are_not_consecutive_are_not_summed_along_diagonals():
    assert contiguous_lags([(None, range(1, 4)), (None, [0, 2])]) is None
    first, counts = contiguous_lags([(None, range(1, 4)), (None, [5])])
    np.testing.assert_array_equal(first, [1, 5])
    np.testing.assert_array_equal(counts, [3, 1])


def test_the_start_regression_equals_the_qr_one_where_the_regressors_are_well_conditioned():
    """A 20th-order ARX regression (the start of a search) by the normal equations of
    the diagonal sums: the coefficients and residuals of the Householder route to 1e-9,
    on two experiments (NaN residuals before each one's first row, as regress gives)."""
    u1, u2, y = _signals(4000, 2)
    blocks = [(u1, range(0, 20)), (u2, range(0, 20)), (y, range(1, 21))]
    ranges = [(0, 1700), (1700, 4000)]
    theta, resid = regress_start(y, blocks, ranges, 20)
    theta_qr, resid_qr, _ = regress(y, blocks, ranges, 20)
    np.testing.assert_allclose(theta, theta_qr, rtol=0, atol=1e-9 * np.abs(theta_qr).max())
    assert np.array_equal(np.isnan(resid), np.isnan(resid_qr))
    assert np.isnan(resid[1700:1720]).all() and np.isfinite(resid[1720:]).all()
    ok = np.isfinite(resid_qr)
    np.testing.assert_allclose(resid[ok], resid_qr[ok], rtol=0, atol=1e-9)


@pytest.mark.parametrize("case", ["collinear", "not consecutive"])
def test_the_start_regression_falls_back_to_the_qr_route(case):
    """An input that repeats another one delayed (the column-scaled Gram matrix has a
    zero pivot), or a block whose lags are not consecutive: exactly what regress
    gives."""
    u1, u2, y = _signals(3000, 3)
    if case == "collinear":
        u2 = np.concatenate([[0.0], u1[:-1]])
        blocks = [(u1, range(0, 5)), (u2, range(0, 5)), (y, range(1, 6))]
    else:
        blocks = [(u1, [0, 2, 3]), (y, range(1, 6))]
    theta, resid = regress_start(y, blocks, [(0, 3000)], 6)
    theta_qr, resid_qr, _ = regress(y, blocks, [(0, 3000)], 6)
    np.testing.assert_array_equal(theta, theta_qr)
    np.testing.assert_array_equal(resid, resid_qr)
