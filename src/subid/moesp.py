"""PO-MOESP: past-output multivariable output-error state-space identification.

Verhaegen (1994), "Identification of the deterministic part of MIMO state
space models given in innovations form from input-output data", Automatica
30(1); Verhaegen & Verdult, *Filtering and System Identification* (2007),
Sec. 9.6. The classical SVD-based baseline against which seed 001 compares.

With the LQ factorisation ``[U_f; Z; Y_f] = L Q^T`` (Z = past inputs and
outputs), the column space of ``L32`` is the column space of the extended
observability matrix (asymptotically, under process and measurement noise).
Its leading left singular vectors give Γ = U_n S_n^{1/2}; A and C follow by
shift invariance and B, D, x0 by least squares on the output.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ._subspace import choose_order, estimate_b_d, finish, prepare, shift_invariance
from .delay import record_delay, shift_for_method
from .model import StateSpace

__all__ = ["moesp"]


def moesp(data, order=None, horizon=None, *, feedthrough=True, estimate_x0=True,
          bd_method="auto", statistic="auto", input_delay=0) -> StateSpace:
    """Identify a discrete-time model by PO-MOESP.

    Parameters
    ----------
    data : IOData or HankelStatistic
        Uniformly sampled input/output record, or its statistic (depth
        ``2*horizon``; :class:`subid.HankelStatistic`).
    order : int, None, 'auto' or iterable of int
        Model order; ``None`` (or ``'auto'``) takes the largest gap of the
        singular values (``info['singular_values']``) among orders 1..10;
        an iterable gives the candidate orders.
    horizon : int, optional
        Past and future horizon (block rows). Default ``max(5, ceil(n/ny)+2)``
        with a given order, 10 (or the largest the record supports) otherwise.
    feedthrough : bool
        Estimate D (else D = 0).
    estimate_x0 : bool
        Estimate the initial state with B and D (``info['x0']``).
    bd_method : {'auto', 'simulation', 'projection'}
        As in :func:`subid.ls_subspace`.
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
    pb = prepare(data, order, horizon, method="moesp", statistic=statistic)
    data, f, hf = pb.data, pb.horizon, pb.factor
    ny, nu = data.n_outputs, data.n_inputs
    L = hf.retriangularize(hf.u_rows(f, 2 * f), hf.u_rows(0, f), hf.y_rows(0, f),
                           hf.y_rows(f, 2 * f))
    a, b = f * nu, f * (nu + ny)
    L32 = L[a + b:, a:a + b]
    U, s, _ = scipy.linalg.svd(L32, full_matrices=False, check_finite=False)
    n, order_selection = choose_order(pb.order, pb.candidates, s, "singular values")
    gamma = U[:, :n] * np.sqrt(s[:n])
    A, C, shift_residual = shift_invariance(gamma, ny)
    B, D, x0, reg = estimate_b_d(A, C, gamma, L[:a, :a], L[a + b:, :a], pb,
                                 bd_method=bd_method, feedthrough=feedthrough,
                                 estimate_x0=estimate_x0)
    C = C * pb.output_scale[:, None]
    return record_delay(finish(pb, A, B, C, D, n, order_selection, singular_values=s,
                               shift_residual=shift_residual, x0=x0, **reg), delays)
