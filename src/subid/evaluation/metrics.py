"""Validation metrics: Markov-parameter error, simulation fit, pole error.

The fit (NRMSE %) lives below the methods, which score their candidates with it
(:mod:`subid.model.fit`); it is exported here with the other metrics."""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from subid._validation import check_int, checked_call, same_period
from subid.errors import ModelError
from subid.model.fit import fit_percent, frequency_fit
from subid.model.prediction import check_model

__all__ = ["markov_error", "fit_percent", "frequency_fit", "pole_error"]


def _check_pair(model, reference):
    check_model(model, "model")
    check_model(reference, "reference")
    if (model.n_inputs, model.n_outputs) != (reference.n_inputs, reference.n_outputs):
        raise ModelError(f"model has {model.n_inputs} inputs and {model.n_outputs} outputs but "
                         f"the reference has {reference.n_inputs} and {reference.n_outputs}")
    if model.dt != reference.dt and not same_period(model.dt, reference.dt):
        raise ModelError(f"model has dt={model.dt} but the reference has dt={reference.dt}; "
                         "convert one of them first (to_discrete / to_continuous)")


@checked_call
def markov_error(model, reference, k: int = 10) -> float:
    """Relative Frobenius error of the first ``k`` Markov parameters.

    ``||M - M_ref||_F / ||M_ref||_F`` with ``M = [D, CB, CAB, ...,
    C A^{k-2} B]``: invariant to the state basis (seed 001, Fig. 2).

    Parameters
    ----------
    model, reference : StateSpace
        Same numbers of inputs and outputs and the same ``dt``.
    k : int
        Number of Markov parameters, D included.
    """
    _check_pair(model, reference)
    k = check_int(k, "k", minimum=1)
    m_ref = reference.markov(k)
    norm = np.linalg.norm(m_ref)
    if norm == 0:
        raise ModelError("the reference's first Markov parameters are all zero; the relative "
                         "error is undefined")
    return float(np.linalg.norm(model.markov(k) - m_ref) / norm)


@checked_call
def pole_error(model, reference) -> float:
    """Largest pole distance after the best one-to-one matching of poles.

    The matching minimises the largest distance (a bottleneck assignment),
    so the result is the smallest ``d`` such that every pole of ``model``
    can be paired with a distinct pole of ``reference`` within ``d``.
    """
    _check_pair(model, reference)
    p, q = model.poles(), reference.poles()
    if p.size != q.size:
        raise ModelError(f"model has order {p.size} but the reference has order {q.size}; "
                         "pole errors compare models of the same order")
    dist = np.abs(p[:, None] - q[None, :])
    candidates = np.unique(dist)
    lo, hi = 0, candidates.size - 1
    while lo < hi:   # smallest threshold that admits a perfect matching
        mid = (lo + hi) // 2
        graph = scipy.sparse.csr_matrix((dist <= candidates[mid]).astype(np.int8))
        match = scipy.sparse.csgraph.maximum_bipartite_matching(graph, perm_type="column")
        if np.all(match >= 0):
            hi = mid
        else:
            lo = mid + 1
    return float(candidates[lo])
