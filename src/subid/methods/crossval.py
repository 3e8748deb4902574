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
           "MAX_SELECTION_SAMPLES", "SELECTION_RULES", "AUTO_ORDER_RULE", "folds",
           "experiment_folds", "feasible_horizons", "fold_score", "criterion", "select"]

#: Horizons tried when none is given (kept when the data allow them).
HORIZON_CANDIDATES = (10, 20)
#: Largest order of the first block of candidates (1..MAX_ORDER) when the order is to be
#: chosen; the search goes on past it while the criterion improves
#: (:func:`subid.methods.dt.selection.next_block`).
MAX_ORDER = 10
#: Misfit (fit points) below which candidates are equal (rounding level, noise-free data).
ABSOLUTE_TOLERANCE = 1e-6
#: Fit (%) below which a candidate's fold scores are clipped.
FLOOR = -100.0
#: Samples above which the cross-validation uses only the last part of the record.
MAX_SELECTION_SAMPLES = 100_000
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
                   f"{MAX_ORDER} while the best is among the last orders tried")


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
    rows = lambda f: blocks * f * (n_inputs + n_outputs)   # noqa: E731
    cols = lambda f: n_train - n_experiments * (blocks * f - 1)   # noqa: E731
    need = min(largest_order, MAX_ORDER) if reveal_all else 1
    kept = [f for f in candidates if cols(f) >= 2 * rows(f) and (f - 1) * n_outputs >= need]
    if kept:
        return kept
    f = max(candidates)
    while f > 2 and cols(f) < rows(f):
        f -= 1
    return [f]


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
