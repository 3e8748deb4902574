"""Warnings of ct_subspace: no NumPy ComplexWarning from the reflection of unstable real
poles, and its own warnings in subid.errors classes (ConversionWarning)."""

import warnings

import numpy as np
import pytest

import subid
from subid.errors import ConversionWarning
from subid.methods.ct._ct_fit import reflected


def test_reflected_real_poles_without_complex_warning():
    T = np.array([[1.0, 0.4], [0.2, 1.0]])
    A = np.linalg.solve(T, np.diag([0.5, -1.0]) @ T)       # real poles 0.5 and -1
    with warnings.catch_warnings():
        warnings.simplefilter("error")                       # ComplexWarning included
        out = reflected(A, -0.01)
    assert out.dtype == np.float64
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(out).real), [-1.0, -0.5])
    np.testing.assert_allclose(out, np.linalg.solve(T, np.diag([-0.5, -1.0]) @ T), atol=1e-12)
    # a slow unstable pole goes at least 10 |limit| into the left half-plane
    slow = reflected(np.diag([0.001, -2.0]), -0.01)
    np.testing.assert_allclose(slow, np.diag([-0.1, -2.0]), atol=1e-15)
    # complex pairs: the real part reflected, the imaginary part kept
    pair = reflected(np.array([[0.2, 3.0], [-3.0, 0.2]]), -0.01)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(pair)), [-0.2 - 3j, -0.2 + 3j])


def _closed_loop(seed=3, n_samples=3000):
    true = subid.systems.random_system(2, 1, 1, seed=12, feedthrough=False)
    rng = np.random.default_rng(seed)
    x = np.zeros(2)
    u, y = np.zeros((n_samples, 1)), np.zeros((n_samples, 1))
    r, e = rng.normal(size=n_samples), 0.3 * rng.normal(size=n_samples)
    v = 0.0
    for k in range(n_samples):
        v = 0.9 * v + e[k]
        y[k] = true.C @ x + v
        u[k] = r[k] - 0.5 * y[k]
        x = true.A @ x + true.B @ u[k]
    return subid.IOData(u, y)


def test_ct_subspace_warns_in_subid_classes_only():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        subid.ct_subspace(_closed_loop(), 2)
    kinds = {type(w.message) for w in caught}
    assert ConversionWarning in kinds
    assert all(k.__module__ == "subid.errors" for k in kinds), kinds
    assert not any(issubclass(k, np.exceptions.ComplexWarning) for k in kinds)


def test_conversion_warning_is_a_user_warning():
    assert issubclass(ConversionWarning, UserWarning)
    assert "ConversionWarning" in subid.errors.__all__
    with pytest.warns(UserWarning):
        warnings.warn("x", ConversionWarning, stacklevel=1)
