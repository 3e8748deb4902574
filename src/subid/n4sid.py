"""N4SID: numerical algorithm for subspace state-space system identification.

Van Overschee & De Moor (1994), "N4SID: Subspace algorithms for the
identification of combined deterministic-stochastic systems", Automatica
30(1); *Subspace Identification for Linear Systems* (1996), Sec. 4.3,
algorithm 2 with unit weights (W1 = W2 = I).

Steps, all on the triangular factor ``L`` of the block-Hankel data matrix
(``H = L Q^T``; a row block of ``H`` is a row block of ``L`` times ``Q^T``,
and projections of row spaces act on the small coefficient rows because
``Q^T`` has orthonormal rows):

1. Oblique projections ``O_i = Y_f /_{U_f} W_p`` and
   ``O_{i-1} = Y_f^- /_{U_f^-} W_p^+``.
2. SVD of ``O_i``: Γ_i = U_n S_n^{1/2}; Γ_{i-1} is Γ_i without its last
   block row.
3. States ``X_i = Γ_i^† O_i`` and ``X_{i+1} = Γ_{i-1}^† O_{i-1}``.
4. ``[X_{i+1}; Y_{i|i}] = [A B; C D] [X_i; U_{i|i}]`` by least squares.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ._subspace import choose_order, finish, prepare
from .delay import record_delay, shift_for_method
from .model import StateSpace

__all__ = ["n4sid"]


def _row_space_projector(M: np.ndarray) -> np.ndarray:
    """Orthogonal projector onto the row space of ``M`` (QR with pivoting).

    Rows are normalised first: that leaves the row space unchanged and makes
    the rank decision independent of how the channels are scaled.
    """
    norms = np.linalg.norm(M, axis=1)
    M = M[norms > 0] / norms[norms > 0, None]
    Q, R, _ = scipy.linalg.qr(M.T, mode="economic", pivoting=True, check_finite=False)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > d.max(initial=0.0) * 1e-12 * max(M.shape))) if d.size else 0
    Qr = Q[:, :rank]
    return Qr @ Qr.T


def _oblique(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Coefficients of the oblique projection ``A /_B C`` of row spaces.

    ``A /_B C = (A Π_B^⊥)(C Π_B^⊥)^† C``; ``a, b, c`` are the coefficient
    rows of A, B, C with respect to the common orthonormal rows ``Q^T``.
    """
    perp = np.eye(a.shape[1]) - _row_space_projector(b)
    a_perp, c_perp = a @ perp, c @ perp
    coef = scipy.linalg.lstsq(c_perp.T, a_perp.T, lapack_driver="gelsy",
                              check_finite=False)[0].T
    return coef @ c


def _lstsq_rows(regressors: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Theta minimising ``||targets - Theta regressors||_F`` (rows = variables)."""
    return scipy.linalg.lstsq(regressors.T, targets.T, lapack_driver="gelsy",
                              check_finite=False)[0].T


def n4sid(data, order=None, horizon=None, *, feedthrough=True, statistic="auto",
          input_delay=0) -> StateSpace:
    """Identify a discrete-time model by N4SID (unit weights, state sequences).

    Parameters
    ----------
    data : IOData or HankelStatistic
        Uniformly sampled input/output record, or its statistic (depth
        ``2*horizon``; :class:`subid.HankelStatistic`).
    order : int, None, 'auto' or iterable of int
        Model order; ``None`` (or ``'auto'``) takes the largest gap of the
        singular values of the oblique projection (``info['singular_values']``)
        among orders 1..10; an iterable gives the candidate orders.
    horizon : int, optional
        Number of past and of future block rows i. Default
        ``max(5, ceil(n/ny)+2)`` with a given order, 10 (or the largest the record
        supports) otherwise.
    feedthrough : bool
        Estimate D (else D = 0 and the state regression omits it).
    statistic : {'auto', 'qr', 'gram'}
        As in :func:`subid.ls_subspace`.
    input_delay : int or sequence of int
        Delay of every input in samples (one integer: all inputs): the model
        is identified from ``u_j[k - d_j]`` to ``y[k]`` (the first ``max(d)``
        output samples are left out, so ``info['x0']`` is the state at sample
        ``max(d)``) and the delays are kept in ``info['input_delay']``, which
        ``simulate`` and ``freqresp`` honour (:mod:`subid.delay`). IOData only.

    Returns
    -------
    StateSpace
        Discrete-time model with ``dt = data.dt``.
    """
    data, delays = shift_for_method(data, input_delay)
    pb = prepare(data, order, horizon, method="n4sid", statistic=statistic)
    data, i, hf = pb.data, pb.horizon, pb.factor
    ny, nu = data.n_outputs, data.n_inputs
    L = hf.L
    wp = hf.rows(hf.u_rows(0, i), hf.y_rows(0, i))
    uf = hf.rows(hf.u_rows(i, 2 * i))
    yf = hf.rows(hf.y_rows(i, 2 * i))
    wp_plus = hf.rows(hf.u_rows(0, i + 1), hf.y_rows(0, i + 1))
    uf_minus = hf.rows(hf.u_rows(i + 1, 2 * i))
    yf_minus = hf.rows(hf.y_rows(i + 1, 2 * i))
    o_i = _oblique(yf, uf, wp)
    o_im1 = _oblique(yf_minus, uf_minus, wp_plus)
    U, s, _ = scipy.linalg.svd(o_i, full_matrices=False, check_finite=False)
    n, order_selection = choose_order(pb.order, pb.candidates, s, "singular values")
    gamma = U[:, :n] * np.sqrt(s[:n])
    x_i = scipy.linalg.lstsq(gamma, o_i, lapack_driver="gelsy", check_finite=False)[0]
    x_ip1 = scipy.linalg.lstsq(gamma[:-ny], o_im1, lapack_driver="gelsy",
                               check_finite=False)[0]
    u_ii = L[hf.u_rows(i, i + 1)]
    y_ii = L[hf.y_rows(i, i + 1)]
    xu = np.vstack([x_i, u_ii])
    AB = _lstsq_rows(xu, x_ip1)
    A, B = AB[:, :n], AB[:, n:]
    if feedthrough:
        CD = _lstsq_rows(xu, y_ii)
        C, D = CD[:, :n], CD[:, n:]
    else:
        C, D = _lstsq_rows(x_i, y_ii), np.zeros((ny, nu))
    lhs = np.vstack([x_ip1, y_ii])
    resid = lhs - np.vstack([A @ x_i + B @ u_ii, C @ x_i + D @ u_ii])
    B, C, D = pb.unscale(B, C, D)        # from the normalised channels to the user's units
    residual = np.linalg.norm(resid) / max(np.linalg.norm(lhs), 1e-300)
    return record_delay(finish(pb, A, B, C, D, n, order_selection, singular_values=s,
                               state_regression_residual=float(residual)), delays)
