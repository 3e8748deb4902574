"""What the identification methods of every time base share, out of the discrete-time
pipeline's private modules (issue 24): default horizons and sample counts of a Hankel
factor, the persistent-excitation check, channel normalisation, the order at the largest
singular-value gap, and ``info['conditions']``. The discrete-time batch methods
(:mod:`subid.methods.dt._subspace`), the online identifiers, the continuous-time and
the frequency-domain methods import them from here.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.linalg

from subid._validation import check_int
from subid.errors import ExcitationWarning, NotExcitingError, OrderError
from subid.statistic._hankel import HankelFactor

# A diagonal entry of the input block of the Hankel factor below this fraction
# of the largest one marks a linearly dependent Hankel row.
RANK_TOL = 1e-10
# Input-Hankel condition number above which identification warns.
CONDITION_WARN = 1e7
DEFAULT_HORIZON_UNKNOWN_ORDER = 10


def default_horizon(order: int | None, n_outputs: int, n_inputs: int, n_samples: int,
                    blocks_per_horizon: int) -> int:
    """Horizon of the online and streamed identifiers when none is given.

    ``max(5, ceil(order / n_outputs) + 2)`` with a known order; 10 (or the
    largest horizon the record supports) otherwise. The batch methods choose
    their horizon from the data instead (:mod:`subid.methods.dt.selection`).
    """
    if order is not None:
        return max(5, math.ceil(order / n_outputs) + 2)
    horizon = DEFAULT_HORIZON_UNKNOWN_ORDER
    while horizon > 2 and n_samples < min_samples(horizon * blocks_per_horizon, n_inputs,
                                                   n_outputs):
        horizon -= 1
    return horizon


def min_samples(depth: int, n_inputs: int, n_outputs: int) -> int:
    """Samples needed for a full-rank Hankel factor with ``depth`` block rows."""
    return depth * (n_inputs + n_outputs) + depth - 1


def parse_order(order):
    """``(fixed order or None, explicit candidate orders or None)``."""
    if order is None or (isinstance(order, str) and order == "auto"):
        return None, None
    if isinstance(order, dict):
        raise OrderError(f"order must be an integer, 'auto' (or None), or a list of "
                         f"candidate orders; got {order!r}"[:300])
    if isinstance(order, (str, bytes)) or not hasattr(order, "__iter__"):
        return check_int(order, "order", minimum=1), None
    candidates = sorted({check_int(k, "candidate order", minimum=1) for k in order})
    if not candidates:
        raise OrderError("order is an empty list of candidate orders: give at least one "
                         "order, an integer, or 'auto'")
    return None, candidates


def check_excitation(hf: HankelFactor, input_names, *, method: str) -> float:
    """Raise :class:`NotExcitingError` if the input Hankel rows are dependent.

    The leading ``depth*nu`` rows of the factor are the factor of the input
    block-Hankel matrix alone; a negligible diagonal entry marks the first
    input row that is a combination of the earlier ones.

    Returns
    -------
    float
        Estimated 1-norm condition number of the input block-Hankel factor.
    """
    nu, depth = hf.n_inputs, hf.depth
    Lu = hf.L[: depth * nu, : depth * nu]
    # Each diagonal entry relative to the norm of its row is the sine of the
    # angle between that Hankel row and the span of the earlier ones: the
    # decision does not depend on how the input channels are scaled.
    norms = np.linalg.norm(Lu, axis=1)
    scale = norms.max(initial=0.0)
    d = np.abs(np.diag(Lu)) / np.where(norms > 0, norms, 1.0)
    dependent = np.flatnonzero((d <= RANK_TOL) | (norms == 0)) if scale > 0 \
        else np.arange(d.size)
    if dependent.size:
        k = int(dependent[0])
        achieved = k // nu
        channel = input_names[k % nu]
        if scale == 0:
            what = "the input is identically zero"
        elif achieved == 0:
            what = f"input {channel} is a combination of the other inputs"
        else:
            what = (f"input {channel} at lag {achieved} is a linear combination of earlier "
                    "input samples")
        raise NotExcitingError(
            f"{method}: the input is not sufficiently exciting: {what}. The method needs an "
            f"input persistently exciting of order {depth} (its block-Hankel matrix with "
            f"{depth} block rows must have full row rank {depth * nu}); these data are "
            f"exciting of order {achieved} only. Use a richer input (white noise, PRBS, "
            "multisine) or a smaller horizon",
            required_order=depth, achieved_order=achieved)
    Ln = Lu / norms[:, None]                      # condition of the row-normalised factor
    rcond = scipy.linalg.lapack.dtrcon(np.ascontiguousarray(Ln.T), norm="1", uplo="U",
                                       diag="N")[0]
    cond = 1.0 / rcond if rcond > 0 else math.inf
    if cond > CONDITION_WARN:
        warnings.warn(f"{method}: the input block-Hankel matrix is ill-conditioned "
                      f"(condition ~{cond:.1e}); the input barely excites order {depth} and "
                      "the model may be unreliable", ExcitationWarning, stacklevel=3)
    return float(cond)


def gap_scores(values, candidates) -> dict:
    """Gap after each candidate order of a decreasing profile (log10 scale).

    ``values`` are singular values, or the pivots of an SVD-free rank
    profile; the gap after position ``k`` is
    ``log10(min(values[:k])) - log10(max(values[k:]))``.
    """
    v = np.abs(np.asarray(values, dtype=float))
    floor = max(v.max(initial=0.0), 1e-300) * np.finfo(float).eps * v.size
    logv = np.log10(np.maximum(v, floor))
    return {k: float(logv[:k].min() - logv[k:].max()) for k in candidates if k < v.size}


def order_from_gap(values, candidates) -> int:
    """Order at the largest gap of a decreasing profile (:func:`gap_scores`)."""
    gaps = gap_scores(values, candidates)
    if not gaps:
        return candidates[0]
    return max(gaps, key=lambda k: (gaps[k], -k))


def normalize_channels(hf: HankelFactor, outputs: bool):
    """The factor of the data with every channel divided by its RMS.

    Row ``r`` of ``L`` has norm ``sqrt(mean of the square of Hankel row r)``;
    the first block row of each signal gives the channel RMS. Scaling rows of
    ``H`` scales rows of ``L`` (``S H = (S L) Q^T``, still triangular), so this
    costs nothing and makes the rank decisions of the methods independent of
    the units of the channels. Outputs are left alone when ``outputs`` is
    false (seed 001's selector Λ acts on the outputs in the user's units).
    """
    nu, ny, s = hf.n_inputs, hf.n_outputs, hf.depth
    norms = np.linalg.norm(hf.L, axis=1)
    su = norms[:nu].copy()
    sy = norms[s * nu:s * nu + ny].copy() if outputs else np.ones(ny)
    su[su == 0] = 1.0
    sy[sy == 0] = 1.0
    row_scale = np.concatenate([np.tile(su, s), np.tile(sy, s)])
    scaled = HankelFactor(L=hf.L / row_scale[:, None], depth=s, n_inputs=nu, n_outputs=ny,
                          n_columns=hf.n_columns)
    return scaled, su, sy


def choose_order(fixed, candidates, profile, source: str):
    """The fixed order, or the candidate at the largest gap of ``profile``.

    Returns the order and the ``info['order_selection']`` record.
    """
    if fixed is not None:
        return fixed, {"rule": "given"}
    gaps = gap_scores(profile, candidates)
    n = order_from_gap(profile, candidates)
    return n, {"rule": "gap", "description": f"largest gap of the {source} (log10)",
               "candidates": [{"order": k, "score": g} for k, g in gaps.items()],
               "selected": {"order": n, "score": gaps.get(n)}}


#: Flat ``info`` keys of condition numbers -> their name in ``info['conditions']``.
CONDITION_KEYS = {"input_condition": "input", "selector_condition": "selector",
                  "regression_condition": "bd", "b_regression_condition": "bd",
                  "condition": "ac", "bd_condition": "bd"}


def conditions_of(info: dict, **given) -> dict:
    """``info['conditions']`` from the flat condition keys of ``info`` (and ``given``)."""
    out = dict(given)
    for key, name in CONDITION_KEYS.items():
        if info.get(key) is not None:
            out.setdefault(name, info[key])
    return out


def extended_observability(A, C, f: int):
    """The extended observability matrix ``[C; C A; ...; C A^(f-1)]`` (``f`` block rows)."""
    blocks, row = [], C
    for _ in range(f):
        blocks.append(row)
        row = row @ A
    return np.vstack(blocks)
