"""The streamed/Dask second pass of the B, D, x0 regression with many experiments
(subid.methods.dt._bd_pass; issue 28): each experiment's x0 eliminated from its own
pieces' normal equations (or factors), so the pass is linear in the number of
experiments; equal to the dense embedded least squares."""

import tracemalloc

import numpy as np
import pytest

from subid.methods.dt._bd_pass import OutputRegression
from test_bd_large import _close, _dense, _simulate, _system

DEFECTIVE = np.array([[0.8, 1.0, 0.0], [0.0, 0.8 + 1e-10, 0.3], [0.0, 0.0, -0.5]])


def _pieces(u, y, borders):
    """``map_pieces`` of the record cut at ``borders`` (one chunk per piece)."""
    def map_pieces(function, arguments):
        return [function([(u[a:b], y[a:b])], *args)
                for (a, b), args in zip(zip(borders[:-1], borders[1:]), arguments)]
    return map_pieces


def _merged(A, B, C, D, lengths, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((sum(lengths), B.shape[1]))
    starts = list(np.cumsum([0] + lengths[:-1]))
    y = np.vstack([_simulate(A, B, C, D, u[a:a + m], rng.standard_normal(A.shape[0]))
                   for a, m in zip(starts, lengths)])
    return u, y + 0.1 * rng.standard_normal(y.shape) * [1.0, 20.0], starts


@pytest.mark.parametrize("defective", [False, True])
@pytest.mark.parametrize("feedthrough", [True, False])
@pytest.mark.parametrize("estimate_x0", [True, False])
def test_pieces_of_experiments_equal_the_dense_least_squares(defective, feedthrough,
                                                             estimate_x0):
    """Five experiments in nine pieces (an experiment in one piece, in two, in three):
    B, D and every x0 equal the dense least squares of ``[x0_1 .. x0_E, vec B, vec D]``
    built sample by sample, on the modal path and on the QR path (nearly defective A)."""
    A, B, C, D = _system(3, 2, 2, seed=21)
    if defective:
        A = DEFECTIVE
    u, y, starts = _merged(A, B, C, D, [30, 45, 17, 60, 28], seed=22)
    cuts = sorted(set(starts) | {10, 50, 62, 110, 140})
    borders = cuts + [u.shape[0]]
    experiments = [int(np.searchsorted(starts, a, side="right")) - 1 for a in cuts]
    second = OutputRegression(_pieces(u, y, borders), len(cuts), 2, 2,
                              experiments=experiments)
    B1, D1, x1, diag = second(A, C, feedthrough=feedthrough, estimate_x0=estimate_x0)
    B0, D0, x0 = _dense(A, C, u, y, starts, 1.0 / y.std(axis=0), feedthrough=feedthrough,
                        estimate_x0=estimate_x0)
    assert diag["regression_path"] == ("qr" if defective else "modal")
    assert diag["experiments"] == 5
    _close(B1, B0)
    _close(D1, D0)
    if estimate_x0:
        assert x1.shape == (5, 3)
        _close(x1, x0)


def test_pieces_of_experiments_exact_noise_free():
    A, B, C, D = _system(3, 2, 2, seed=23)
    rng = np.random.default_rng(24)
    lengths = [25, 40, 31]
    x0s = rng.standard_normal((3, 3))
    u = rng.standard_normal((sum(lengths), 2))
    starts = [0, 25, 65]
    y = np.vstack([_simulate(A, B, C, D, u[a:a + m], x) for a, m, x in zip(starts, lengths, x0s)])
    second = OutputRegression(_pieces(u, y, [0, 25, 50, 65, 96]), 4, 2, 2,
                              experiments=[0, 1, 1, 2])
    B1, D1, x1, diag = second(A, C)
    _close(B1, B, 1e-8)
    _close(D1, D, 1e-8)
    _close(x1, x0s, 1e-8)
    assert diag["residual_rms"] < 1e-8


def _peak(E, length, A):
    """tracemalloc peak of the second pass of E experiments of ``length`` samples."""
    _, B, C, D = _system(3, 2, 2, seed=25)
    u, y, starts = _merged(A, B, C, D, [length] * E, seed=26)
    second = OutputRegression(_pieces(u, y, starts + [u.shape[0]]), E, 2, 2,
                              experiments=list(range(E)))
    tracemalloc.start()
    try:
        B1, D1, x1, diag = second(A, C)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert x1.shape == (E, 3) and diag["experiments"] == E
    return peak


@pytest.mark.parametrize("defective", [False, True])
def test_memory_grows_linearly_with_the_experiments(defective):
    """100 and 400 experiments of 10 samples: 4x the experiments, under 6x the peak.
    The embedded normal equations grow with the square (a (E n + 16)-square matrix:
    0.8 MB, then 11.8 MB), so the ratio would be above 9; the peak at 400 also stays
    below that one matrix."""
    A = DEFECTIVE if defective else _system(3, 2, 2, seed=25)[0]
    _peak(5, 10, A)                               # warm-up: the compiled kernels
    small, large = _peak(100, 10, A), _peak(400, 10, A)
    assert large < 6 * small, (small, large)
    assert large < 8 * (400 * 3 + 16) ** 2, large
