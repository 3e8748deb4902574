"""What every cross-validated choice of the methods shares, for every time base: the four
contiguous folds of a record (:func:`folds`, :func:`experiment_folds`), the horizons a
fold supports (:func:`feasible_horizons`), the score of a model on a held-out part
(:func:`fold_score`: the simulation fit of :func:`subid.fit_percent`, mean over the
outputs, clipped below at :data:`FLOOR`) and the rule that picks a candidate from its
fold scores (:func:`criterion`, the cross-validated BIC, and :func:`select`), with the
constants of the automatic order search (:data:`AUTO_ORDER_RULE`).

The discrete-time batch methods search the candidates with them
(:mod:`subid.methods.dt.selection`, where the rule and its measurements are described);
the continuous-time, frequency-domain and polynomial methods and :func:`subid.identify`
import them from here.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from subid.errors import SubidError

__all__ = ["HORIZON_CANDIDATES", "MAX_ORDER", "ABSOLUTE_TOLERANCE", "FLOOR",
           "MAX_SELECTION_SAMPLES", "MEMORY", "MAX_HORIZON", "SELECTION_RULES",
           "AUTO_ORDER_RULE", "folds", "experiment_folds", "feasible_horizons",
           "response_memory", "longer_horizon", "next_block",
           "selection_part",
           "SAMPLES_PER_PARAMETER", "fold_score", "criterion", "select"]

#: Horizons tried when none is given (kept when the data allow them).
HORIZON_CANDIDATES = (10, 20)
#: Largest order of the first block of candidates (1..MAX_ORDER) when the order is to be
#: chosen; the search goes on past it while the criterion improves
#: (:func:`next_block`).
MAX_ORDER = 10
#: Misfit (fit points) below which candidates are equal (rounding level, noise-free data).
ABSOLUTE_TOLERANCE = 1e-6
#: Fit (%) below which a candidate's fold scores are clipped.
FLOOR = -100.0
#: Samples above which the cross-validation uses only the last part of the record.
MAX_SELECTION_SAMPLES = 100_000
#: Past :data:`HORIZON_CANDIDATES`, twice the largest horizon searched is tried while the
#: share of the input-output correlation beyond it (:func:`response_memory`) is at least
#: this (the horizon spans less than the response lasts: oversampled records) and the
#: last horizon so tried is the chosen one (:func:`longer_horizon`).
MEMORY = 0.8
#: Largest horizon the search goes on to (:func:`longer_horizon`).
MAX_HORIZON = 160
#: :func:`response_memory` reads at most the last this many samples (its noise level
#: there, 3 / sqrt(20,000) = 0.02, is far below :data:`MEMORY`; a pass over 10^5
#: samples cost 9 ms, a tenth of the default call's search).
MEMORY_SAMPLES = 20_000
#: An order is tried only when the training fold holds at least this many output samples
#: per free parameter of the model (n (nu + ny) + nu ny).
SAMPLES_PER_PARAMETER = 10
SELECTION_RULES = ("cv", "gap")
#: What ``order=None`` (``--order auto``) does, in one phrase made from the constants
#: above: the command line's help quotes it, and ``tests/test_docs_agree.py`` checks
#: that the README and docs/cli.md say the same.
AUTO_ORDER_RULE = (f"orders 1..{MAX_ORDER} and horizons "
                   f"{' and '.join(str(h) for h in HORIZON_CANDIDATES)}, or the horizon given, "
                   "scored by cross-validated simulation fit on the estimation data; the "
                   "least cross-validated BIC wins (a higher order where the innovation "
                   "BIC asks for it and its fold score is no lower), and the search goes "
                   "on past order "
                   f"{MAX_ORDER} while the best is among the last orders tried, and past "
                   f"horizon {max(HORIZON_CANDIDATES)}, doubling it while the response to "
                   "the inputs lasts beyond the largest horizon tried and the last doubled "
                   "one is chosen")


def selection_part(data):
    """The record's last :data:`MAX_SELECTION_SAMPLES` samples at most: what the order
    and structure searches, and the tests they make (delays, feedback), read."""
    return data[data.n_samples - MAX_SELECTION_SAMPLES:] \
        if data.n_samples > MAX_SELECTION_SAMPLES else data


def experiment_folds(data):
    """``(train, validation)`` records of the four folds of a record of several
    experiments: every experiment is cut as :func:`folds` cuts one record, and
    the training (validation) pieces of all the experiments are merged, so that
    no fold joins two experiments or two pieces of one."""
    from subid.data import merge
    cut = [folds(e.n_samples) for e in data.experiments]
    out = []
    for k in range(4):
        train = [e[cut[j][k][0]] for j, e in enumerate(data.experiments)
                 if _length(cut[j][k][0]) > 0]
        validation = [e[cut[j][k][1]] for j, e in enumerate(data.experiments)
                      if _length(cut[j][k][1]) > 0]
        out.append((merge(train), merge(validation)))
    return out


def _length(part: slice) -> int:
    return part.stop - part.start


def folds(n_samples: int):
    """``(train, validation)`` slices of the four contiguous folds."""
    third = n_samples // 3
    half = n_samples // 2
    return [(slice(0, n_samples - third), slice(n_samples - third, n_samples)),
            (slice(third, n_samples), slice(0, third)),
            (slice(0, half), slice(half, n_samples)),
            (slice(half, n_samples), slice(0, half))]


def _hankel_shape(f: int, n_train: int, n_inputs: int, n_outputs: int, blocks: int,
                  n_experiments: int = 1) -> tuple[int, int]:
    """``(rows, columns)`` of a training fold's block-Hankel matrix at horizon ``f``
    (``blocks`` block rows of ``f`` samples; ``n_experiments`` experiments lose
    ``blocks * f - 1`` columns each)."""
    return (blocks * f * (n_inputs + n_outputs),
            n_train - n_experiments * (blocks * f - 1))


def _supported(f: int, n_train: int, n_inputs: int, n_outputs: int, blocks: int,
               n_experiments: int = 1) -> bool:
    """Whether that matrix has at least twice as many columns as rows."""
    rows, cols = _hankel_shape(f, n_train, n_inputs, n_outputs, blocks, n_experiments)
    return cols >= 2 * rows


def feasible_horizons(n_train: int, n_inputs: int, n_outputs: int, blocks: int,
                      largest_order: int, candidates=HORIZON_CANDIDATES, n_experiments=1, *,
                      reveal_all: bool = True):
    """Horizons of ``candidates`` a training fold of ``n_train`` samples supports.

    A horizon is kept when its Hankel matrix has at least twice as many
    columns as rows and, with ``reveal_all``, it can reveal ``largest_order``
    (``(f-1) ny >= n``). Without ``reveal_all`` (the cross-validation), a
    horizon that reveals only the lower orders is kept too and competes at
    those orders: on a single-output record horizon 10 reveals orders 1..9,
    and excluding it left horizon 20 alone (on the DaISy ballbeam record the
    shorter horizon gives the better models at every order). When none is
    kept, the largest horizon (at least 2) with at least as many columns as
    rows is returned alone. ``n_experiments`` experiments lose
    ``blocks * f - 1`` columns each.
    """
    shape = lambda f: _hankel_shape(f, n_train, n_inputs, n_outputs, blocks,  # noqa: E731
                                    n_experiments)
    need = min(largest_order, MAX_ORDER) if reveal_all else 1
    kept = [f for f in candidates
            if _supported(f, n_train, n_inputs, n_outputs, blocks, n_experiments)
            and (f - 1) * n_outputs >= need]
    if kept:
        return kept
    f = max(candidates)
    while f > 2 and shape(f)[1] < shape(f)[0]:
        f -= 1
    return [f]


def response_memory(data, lag: int) -> float:
    """How much of the input-output correlation of ``data`` lies ``lag`` samples back or
    more. For each output ``i`` and input ``j``, the correlation coefficients
    ``ρ_ij(τ)`` of ``y_i(t)`` and ``u_j(t - τ)`` (both less their means, summed within
    each experiment) at ``τ = 0 .. 2 lag - 1``, less the level ``3 / sqrt(N)`` that
    independent white signals stay below (clipped at 0); the result is
    ``Σ_ij max_{τ >= lag} ρ_ij / Σ_ij max_τ ρ_ij`` (pairs weighted by their own peak, so
    that a weak pair does not decide). Near 1 when the outputs still answer inputs of
    ``2 lag`` samples before as strongly as recent ones (a record sampled much faster
    than its dynamics), near 0 when the response is over within ``lag`` samples or no
    response stands out. Measured on the response to the input, not on the outputs
    alone: coloured output noise remembers too, but does not call for a longer horizon
    (tests/test_horizons.py). At most the last :data:`MEMORY_SAMPLES` samples are read."""
    if data.n_samples > MEMORY_SAMPLES:
        data = data[data.n_samples - MEMORY_SAMPLES:]
    y = data.y - data.y.mean(axis=0)
    u = data.u - data.u.mean(axis=0)
    c = np.zeros((2 * lag, data.n_outputs, data.n_inputs))
    for a, b in data.experiment_ranges:
        for tau in range(min(2 * lag, b - a)):
            c[tau] += y[a + tau:b].T @ u[a:b - tau]
    scale = np.sqrt(np.outer(np.einsum("ti,ti->i", y, y), np.einsum("tj,tj->j", u, u)))
    rho = np.abs(c) / np.where(scale > 0, scale, np.inf)
    rho = np.maximum(rho - 3.0 / math.sqrt(data.n_samples), 0.0)
    peak = rho.max(axis=0).sum()
    return float(rho[lag:].max(axis=0).sum() / peak) if peak > 0 else 0.0


def longer_horizon(data, chosen: int, largest: int, n_train: int, n_inputs: int,
                   n_outputs: int, blocks: int, n_experiments: int = 1):
    """The next horizon of the search, or None: twice the ``largest`` searched, when the
    response of ``data``'s outputs to its inputs lasts beyond it
    (:func:`response_memory` at least :data:`MEMORY`), the last horizon tried past
    :data:`HORIZON_CANDIDATES` (if any) is the ``chosen`` one, it is at most
    :data:`MAX_HORIZON` and the training folds support it (:func:`feasible_horizons`);
    The first step does not ask the largest
    candidate to win: on an oversampled record the fit need not grow with the horizon
    until the horizon spans the dynamics (10 may beat 20, and 160 both by 30 points)."""
    f = 2 * largest
    if (largest > max(HORIZON_CANDIDATES) and chosen != largest) or f > MAX_HORIZON \
            or response_memory(data, largest) < MEMORY:
        return None
    return f if _supported(f, n_train, n_inputs, n_outputs, blocks, n_experiments) else None


def next_block(top, n_train, n_inputs, n_outputs, blocks, n_experiments, horizon=None):
    """The next block of candidate orders past ``top``, its horizons and the ceiling.

    Orders ``top + step .. 2 top`` in steps of ``step = max(1, top // MAX_ORDER)``
    (11..20, then 22..40 by 2, 44..80 by 4: ten candidates a block), each
    within what the data can reveal: a horizon among (10, 20, and the
    smallest multiple of 10 above ``ceil(n / n_outputs) + 1``) whose
    training-fold Hankel matrix has at least twice as many columns as rows
    and that reveals the order (``(f - 1) n_outputs >= n``), or the given
    horizon; and at least :data:`SAMPLES_PER_PARAMETER` output samples per
    free parameter. Returns ``(orders, horizons, ceiling)``; no orders when
    the ceiling is reached.
    """
    step = max(1, top // MAX_ORDER)
    orders = list(range(top + step, 2 * top + 1, step))
    params = lambda n: n * (n_inputs + n_outputs) + n_inputs * n_outputs   # noqa: E731
    by_samples = [n for n in orders if SAMPLES_PER_PARAMETER * params(n) <= n_train * n_outputs]
    if horizon is not None:
        horizons = [horizon]
    else:
        need = math.ceil(max(orders) / n_outputs) + 1
        tried = sorted(set(HORIZON_CANDIDATES) | {10 * math.ceil(need / 10)})
        horizons = [f for f in tried
                    if _supported(f, n_train, n_inputs, n_outputs, blocks, n_experiments)
                    and (f - 1) * n_outputs >= orders[0]]
    revealable = max(((f - 1) * n_outputs for f in horizons), default=0)
    kept = [n for n in by_samples if n <= revealable]
    ceiling = {"order": max(kept) if kept else top,
               "limited_by": ("samples per parameter" if len(by_samples) < len(orders)
                              else "horizons the data allow" if len(kept) < len(orders)
                              else None)}
    return kept, horizons, ceiling


def fold_score(model, validation, steps=np.inf) -> float:
    """The score of ``model`` on a held-out part ``validation`` (a record, or
    frequency-response data): ``mean(fit_percent(model, validation, steps=steps))``
    (simulation by default, x0 by least squares, the model's own hold), clipped below
    at :data:`FLOOR`; :data:`FLOOR` when the fit cannot be computed (a simulation or
    prediction that overflows)."""
    from subid.model.fit import fit_percent
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            fits = fit_percent(model, validation, steps=steps)
    except SubidError:
        return FLOOR
    value = float(np.mean(fits))
    return max(value, FLOOR) if math.isfinite(value) else FLOOR


def criterion(score: float, order: int, n_samples: int, n_inputs: int,
              n_outputs: int) -> float:
    """Cross-validated BIC of a candidate: ``2 N ny ln(100 - score) + p ln N``.

    ``100 - score`` is the cross-validated misfit (NRMSE %, proportional to
    the standard deviation of the simulation error), floored at
    :data:`ABSOLUTE_TOLERANCE` (rounding level: every order from the true one
    up fits noise-free data to rounding); ``p = n (nu + ny) + nu ny`` the
    free parameters of an order-n model (B, C and D; A adds none beyond
    what a similarity transformation absorbs), ``N`` the samples. Schwarz's
    criterion (Ann. Statist. 6, 1978; Ljung 1999, Sec. 16.4, eq. 16.33) for a
    Gaussian error whose variance is estimated on held-out data instead of the
    estimation data.
    """
    misfit = max(100.0 - score, ABSOLUTE_TOLERANCE)
    params = order * (n_inputs + n_outputs) + n_inputs * n_outputs
    return 2.0 * n_samples * n_outputs * math.log(misfit) + params * math.log(n_samples)


def select(fold_scores, n_samples: int, n_inputs: int, n_outputs: int):
    """The candidate ``(order, horizon, estimator index)`` of the least
    :func:`criterion` (mean fold score), and the criterion of every candidate.

    Ties (equal criterion, e.g. the same order at two horizons that fit
    alike) go to the smallest order, then horizon, then the first estimator.
    """
    crit = {k: criterion(float(np.mean(v)), k[0], n_samples, n_inputs, n_outputs)
            for k, v in fold_scores.items()}
    return min(crit, key=lambda k: (crit[k], k)), crit
