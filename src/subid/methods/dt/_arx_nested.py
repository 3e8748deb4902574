"""The ARX least squares of every structure of a search from one QR factorisation.

The structure search of :func:`subid.arx` (:func:`subid.methods.dt.polynomial.select_structure`)
fits some thirty structures ``(na, nb)`` with the same delays on each training
fold. Each fit is the least squares of :func:`subid.methods.dt.polynomial.fit_arx`:
the regressor ``Φ_s`` of structure ``s`` holds a subset of the columns of the
regressor ``Φ`` of the largest structure, on the rows ``t >= t_s`` (the first
sample at which every lag of ``s`` exists). The order-selection trick of least
squares by QR factorisation (Ljung, *System Identification*, 2nd ed., 1999,
Ch. 10; the idea of MATLAB's ``arxstruc``) factors ``[Φ Y] = Q R`` once and
reads every sub-structure's least squares from ``R``: for a subset ``S`` of the columns,
``[Φ Y]_S = Q R_S`` with ``Q`` of orthonormal columns, so the triangular factor
of ``[Φ_S Y]`` is that of the small matrix ``R_S`` (up to the signs of its
rows, which leave the least-squares solution unchanged). The rows
``t_s <= t < t_max`` that the smaller structure uses and the largest cannot
(at most ``t_max`` per experiment) are appended to ``R_S`` before that small
factorisation (the QR update of Golub and Van Loan, *Matrix Computations*,
4th ed., 2013, Sec. 6.5, done as one factorisation of the stacked matrix).
Each structure then costs a factorisation of a ``(m + t_max) x m`` matrix
instead of a pass over the N samples, and gives the coefficients of
``fit_arx`` to rounding (``tests/test_arx_nested.py``).

Every channel is divided by its RMS over the record, as ``fit_arx`` does, so
the scaled regressor does not depend on the structure.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid.errors import TooFewSamplesError
from subid.statistic.hankel import geqrf_r

__all__ = ["RANK_TOL", "NestedARX", "channel_scales", "regression_start", "check_samples",
           "solve_coefficients", "unpack"]

#: A diagonal entry of the input columns of the regression factor below this
#: fraction of its column's norm marks an input lag that repeats earlier ones.
RANK_TOL = 1e-10


def channel_scales(u: np.ndarray, y: np.ndarray):
    """``(su, sy)``: the RMS of every input and output channel (1 for a zero channel)."""
    su = np.sqrt(np.mean(u ** 2, axis=0))
    sy = np.sqrt(np.mean(y ** 2, axis=0))
    return np.where(su > 0, su, 1.0), np.where(sy > 0, sy, 1.0)


def regression_start(orders) -> int:
    """The first sample (per experiment) at which every lag of ``orders`` exists."""
    return int(max(orders["na"].max(initial=0), (orders["nk"] + orders["nb"] - 1).max(initial=0),
                   0))


def check_samples(ranges, n_samples: int, n_params: int, first: int, method: str) -> None:
    """TooFewSamplesError when the regression on the experiments ``ranges`` (of
    ``n_samples`` samples in all) from sample ``first`` of each has fewer than
    ``2 n_params + 10`` rows."""
    rows = sum(max(b - a - first, 0) for a, b in ranges)
    if rows < 2 * n_params + 10:
        raise TooFewSamplesError(f"{method}: these orders need {n_params} coefficients per "
                                 f"output and at least {2 * n_params + 10 + first} samples; "
                                 f"the record has {n_samples}; use lower orders")


def solve_coefficients(R: np.ndarray, m: int) -> np.ndarray:
    """The coefficients (columns) of the targets ``m:`` of the triangular factor ``R`` of
    ``[Φ T]`` on its first ``m`` columns: columns that repeat the others to
    :data:`RANK_TOL` (e.g. past outputs of noise-free data that the past inputs and
    fewer past outputs already determine) get no weight, the minimum-norm solution,
    not one that cancels huge coefficients."""
    if not m:
        return np.zeros((0, R.shape[1] - m))
    return scipy.linalg.lstsq(R[:m, :m], R[:m, m:], lapack_driver="gelsy", cond=RANK_TOL,
                              check_finite=False)[0]


def unpack(theta, i: int, orders, su, sy, A, B) -> None:
    """Write the coefficients ``theta`` of output ``i`` (regressors: every input's lags
    ``nk..nk+nb-1``, then every output's lags ``1..na``, channels scaled by ``su``,
    ``sy``) into the polynomial arrays ``A`` (ny, ny, .) and ``B`` (ny, nu, .)."""
    na, nb, nk = orders["na"], orders["nb"], orders["nk"]
    at = 0
    for j in range(B.shape[1]):
        B[i, j, nk[i, j]:nk[i, j] + nb[i, j]] = theta[at:at + nb[i, j]] * sy[i] / su[j]
        at += nb[i, j]
    for k in range(A.shape[1]):
        A[i, k, 1:na[i, k] + 1] = -theta[at:at + na[i, k]] * sy[i] / sy[k]
        at += na[i, k]


def _fill(signals, ranges, first: int, stop=None) -> np.ndarray:
    """The rows ``t = a + first .. min(b, a + stop) - 1`` of every experiment ``(a, b)``
    of the columns ``signals`` (a list of ``(signal, lag)``: column ``s[t - lag]``)."""
    spans = [(a + first, b if stop is None else min(b, a + stop)) for a, b in ranges]
    spans = [(lo, hi) for lo, hi in spans if hi > lo]
    out = np.empty((sum(hi - lo for lo, hi in spans), len(signals)))
    at = 0
    for lo, hi in spans:
        for c, (s, lag) in enumerate(signals):
            out[at:at + hi - lo, c] = s[lo - lag:hi - lag]
        at += hi - lo
    return out


class NestedARX:
    """The ARX regressions of every structure ``(na, nb)`` up to ``(max_na, max_nb)``
    with delays ``nk`` on one record, from one QR (module docstring).

    Parameters
    ----------
    data : IOData
        The record (uniformly sampled, at least one input; several experiments
        allowed: no regression row spans two).
    nk : ndarray of int, shape (nu,)
        The delay of each input, the same for every output.
    max_na, max_nb : int
        The largest degrees of the search.
    """

    def __init__(self, data, nk, max_na: int, max_nb: int):
        self.ranges, self.n_samples = data.experiment_ranges, data.n_samples
        self.n_outputs, self.n_inputs = data.n_outputs, data.n_inputs
        self.nk = np.asarray(nk, np.int64)
        self.max_na, self.max_nb = int(max_na), int(max_nb)
        self.su, self.sy = channel_scales(data.u, data.y)
        un, yn = data.u / self.su, data.y / self.sy
        self._u = [np.ascontiguousarray(un[:, j]) for j in range(self.n_inputs)]
        self._y = [np.ascontiguousarray(yn[:, k]) for k in range(self.n_outputs)]
        self.start = int(max(self.max_na, int(self.nk.max(initial=0)) + self.max_nb - 1, 0))
        columns = self._columns(np.full(self.n_inputs, self.max_nb), self.max_na)
        M = _fill(columns, self.ranges, self.start)
        self.R = geqrf_r(M, min(M.shape), overwrite=True) if M.shape[0] else M

    def _columns(self, nb, na: int):
        """``(signal, lag)`` of the regressors (every input's lags, then every output's),
        then of the targets (every output at lag 0)."""
        cols = [(self._u[j], lag) for j in range(self.n_inputs)
                for lag in range(self.nk[j], self.nk[j] + nb[j])]
        cols += [(self._y[k], lag) for k in range(self.n_outputs) for lag in range(1, na + 1)]
        return cols + [(self._y[k], 0) for k in range(self.n_outputs)]

    def _index(self, nb, na: int) -> np.ndarray:
        """The columns of the largest structure's ``[Φ Y]`` that ``(na, nb)`` uses."""
        index = [j * self.max_nb + lag for j in range(self.n_inputs) for lag in range(nb[j])]
        base = self.n_inputs * self.max_nb
        index += [base + k * self.max_na + lag for k in range(self.n_outputs)
                  for lag in range(na)]
        base += self.n_outputs * self.max_na
        return np.array(index + [base + k for k in range(self.n_outputs)], dtype=np.intp)

    def fit(self, orders, method: str = "arx"):
        """The polynomials of ``fit_arx(data, orders, check=False)``, to rounding.

        Parameters
        ----------
        orders : dict
            A :func:`subid.methods.dt.polynomial.parse_orders` dict whose every
            output has the same regressors (``na`` and ``nb`` the same in every
            row), with the delays of the search and degrees up to its largest.
        method : str
            The method named in an error message.

        Returns
        -------
        A : ndarray, shape (ny, ny, na + 1)
        B : ndarray, shape (ny, nu, max(nk + nb))

        Raises
        ------
        TooFewSamplesError
            Fewer rows than the structure needs (as ``fit_arx``).
        ValueError
            A structure outside the search (a programming error).
        """
        na_all, nb_all, nk = orders["na"], orders["nb"], orders["nk"]
        na, nb = int(na_all[0, 0]), nb_all[0]
        ny, nu = self.n_outputs, self.n_inputs
        if not ((na_all == na).all() and (nb_all == nb).all() and (nk == self.nk).all()
                and na <= self.max_na and (nb <= self.max_nb).all()):
            raise ValueError("NestedARX.fit: a structure outside the search")
        first = regression_start(orders)
        n_params = int(na_all.sum(axis=1).max() + nb_all.sum(axis=1).max())
        check_samples(self.ranges, self.n_samples, n_params, first, method)
        extra = _fill(self._columns(nb, na), self.ranges, first, self.start)
        stacked = np.vstack([self.R[:, self._index(nb, na)], extra])
        m = stacked.shape[1] - ny
        R = geqrf_r(stacked, min(stacked.shape[0], m + ny), overwrite=False)
        theta = solve_coefficients(R[:m + ny], m)
        A = np.zeros((ny, ny, int(na_all.max(initial=0)) + 1))
        A[:, :, 0] = np.eye(ny)
        B = np.zeros((ny, nu, int((nk + nb_all).max(initial=1))))
        for i in range(ny):
            unpack(theta[:, i], i, orders, self.su, self.sy, A, B)
        return A, B

