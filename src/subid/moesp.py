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

from ._subspace import (check_data, check_excitation, check_order_horizon, data_factor,
                        estimate_b_d, order_from_gap, shift_invariance)
from .model import StateSpace

__all__ = ["moesp"]


def moesp(data, order=None, horizon=None, *, feedthrough=True, estimate_x0=True,
          bd_method="auto") -> StateSpace:
    """Identify a discrete-time model by PO-MOESP.

    Parameters
    ----------
    data : IOData
        Uniformly sampled input/output record.
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

    Returns
    -------
    StateSpace
        Discrete-time model with ``dt = data.dt``.
    """
    method = "moesp"
    data = check_data(data, method)
    ny, nu = data.n_outputs, data.n_inputs
    order, candidates, f = check_order_horizon(order, horizon, data, method=method)
    hf = data_factor(data, 2 * f, method=method, horizon=f)
    input_condition = check_excitation(hf, data, method=method)
    L = hf.retriangularize(hf.u_rows(f, 2 * f), hf.u_rows(0, f), hf.y_rows(0, f),
                           hf.y_rows(f, 2 * f))
    a, b = f * nu, f * (nu + ny)
    L32 = L[a + b:, a:a + b]
    U, s, _ = scipy.linalg.svd(L32, full_matrices=False, check_finite=False)
    if order is None:
        order = order_from_gap(s, candidates)
        order_selection = "largest gap of the singular values"
    else:
        order_selection = "given"
    n = order
    gamma = U[:, :n] * np.sqrt(s[:n])
    A, C, shift_residual = shift_invariance(gamma, ny)
    B, D, x0, reg = estimate_b_d(A, C, gamma, L[:a, :a], L[a + b:, :a], data,
                                 bd_method=bd_method, feedthrough=feedthrough,
                                 estimate_x0=estimate_x0)
    info = {
        "method": method,
        "order": n,
        "order_selection": order_selection,
        "horizon": f,
        "singular_values": s,
        "shift_residual": shift_residual,
        "input_condition": input_condition,
        "x0": x0,
        "n_samples": data.n_samples,
        **reg,
    }
    return StateSpace(A, B, C, D, data.dt, input_names=data.input_names,
                      output_names=data.output_names, info=info)
