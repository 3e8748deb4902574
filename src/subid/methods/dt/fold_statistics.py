"""The Hankel statistics of the order selection's cross-validation folds (issue 21).

The four contiguous folds of :func:`subid.methods.crossval.folds` train on unions of four
blocks of the record (:func:`_blocks_of_folds`); the lagged-product statistic of each block
is computed once and the folds' statistics merged from them (:func:`fold_factors`), one
pass over the record instead of one per fold. Used by
:func:`subid.methods.dt.selection.score_horizon` (the names are re-exported there).
"""

from __future__ import annotations

import numpy as np

from subid._blas import one_thread
from subid._threads import ordered_map


def _same_samples(a, b) -> bool:
    """Whether two arrays hold the same samples: the same memory viewed alike (the folds
    of :func:`subid.methods.crossval.folds` are views of one record), else compared value by value."""
    if a.shape == b.shape and a.strides == b.strides and a.dtype == b.dtype and (
            a.size == 0 or a.__array_interface__["data"][0] == b.__array_interface__["data"][0]):
        return True
    return bool(np.array_equal(a, b))


def _blocks_of_folds(parts):
    """The four blocks ``[0, N/3), [N/3, N/2), [N/2, N - N/3), [N - N/3, N)`` whose
    unions are the training records of :func:`subid.methods.crossval.folds`, or None when ``parts`` are not
    the four folds of one experiment (checked on the samples themselves)."""
    if len(parts) != 4 or any(r.n_experiments > 1 for part in parts for r in part):
        return None
    (t0, v0), (t1, v1), (t2, v2), (t3, v3) = parts
    N = t0.n_samples + v0.n_samples
    third, half = N // 3, N // 2
    lengths = [(N - third, third), (N - third, third), (half, N - half), (N - half, half)]
    if [(t.n_samples, v.n_samples) for t, v in parts] != lengths:
        return None

    def same(a, b):
        return _same_samples(a.u, b.u) and _same_samples(a.y, b.y)

    if not (same(v1, t0[:third]) and same(v0, t1[N - 2 * third:])
            and same(t2, t0[:half]) and same(t3, t1[half - third:])
            and same(v2, t3) and same(v3, t2)):
        return None
    return [v1, t0[third:half], t0[half:N - third], v0]


#: The folds of :func:`subid.methods.dt.selection.score_horizon` (and their factors,
#: :func:`fold_factors`) are scored on subid's threads
#: (:func:`subid._threads.ordered_map`) when their Hankel factors have at least this many
#: rows (depth times channels): then the factorisations and fits of a fold, which release
#: the GIL, outweigh the Python steps of its candidates, which do not. Measured,
#: ``moesp(data)`` on 2 cores, wall s, one thread against this rule (DaISy records, 2/3
#: to estimate): steamgen (4x4: 160 and 320 rows at horizons 10 and 20) 2.75 -> 2.37,
#: evaporator (3x3: 120, 240) 0.99 -> 0.86, CD_player_arm (2x2: 240 rows at horizon 30)
#: 1.07 -> 1.00; the same time for robot_arm and the 2x2 order-4 system of bench/run.py
#: (below the rule). Threads at every horizon instead: robot_arm (1x1) 0.25 -> 0.32 s and
#: that 2x2 system at 10^3 to 10^5 samples 10 % slower. The scores are the same either
#: way (the folds are independent; tests/test_identify.py).
THREADED_ROWS = 200


def fold_threads(depth, parts) -> int | None:
    """The ``threads`` of :func:`subid._threads.ordered_map` for the folds ``parts`` (their
    ``(train, validation)`` records) at Hankel depth ``depth``: subid's threads (None) when
    the factors have :data:`THREADED_ROWS` rows or more and BLAS runs one thread
    (:func:`subid._blas.one_thread`: the default; a user who gave BLAS more threads has
    them spent there), else 1."""
    train = parts[0][0]
    large = depth * (train.n_inputs + train.n_outputs) >= THREADED_ROWS
    return None if large and one_thread() else 1


#: The blocks of :func:`_blocks_of_folds` whose concatenation is each fold's training
#: record, and its validation record.
FOLD_BLOCKS = [(0, 1, 2), (1, 2, 3), (0, 1), (2, 3)]
VALIDATION_BLOCKS = [(3,), (0,), (2, 3), (0, 1)]


def fold_factors(parts, horizon, fitter, deepest=None):
    """Hankel factors of the training records of the folds, each merged from the
    lagged-product statistics of the blocks of :func:`_blocks_of_folds` (one pass
    over the record instead of one per fold: 2.3 records), where that statistic is
    the one the fold would use (:meth:`subid.HankelStatistic.exact_factor`), the QR
    statistic of the fold's record where it is not (with ``statistic='auto'``, up to
    :data:`subid.statistic.hankel.QR_MAX_SAMPLES` samples: what the fold would build,
    without computing its lagged products a second time to find that out); None for
    every fold when ``parts`` are not the four folds of one experiment:
    ``fitter.prepare_fold`` then builds the factor from the record.

    ``deepest`` (a dict, one per cross-validation, :func:`subid.methods.dt.selection.
    cross_validate`): ``deepest['depth']`` the largest depth its horizons need; the
    blocks' statistics are computed once at that depth (kept as ``deepest['stats']``)
    and those of a smaller depth taken from them
    (:meth:`subid.HankelStatistic.shallower`: the same bits; one pass over the
    blocks instead of one per horizon)."""
    from subid.statistic.hankel import QR_MAX_SAMPLES, HankelStatistic, compact_wy_qr
    none = [None] * len(parts)
    blocks_per_horizon = getattr(fitter, "blocks_per_horizon", None)
    kind = getattr(fitter, "statistic", None)
    if blocks_per_horizon is None or kind not in ("auto", "gram"):
        return none
    depth = blocks_per_horizon * horizon
    blocks = _blocks_of_folds(parts)
    if blocks is None or min(b.n_samples for b in blocks) < depth:
        return none
    stats = None
    if deepest is not None and min(b.n_samples for b in blocks) >= deepest.get("depth", 0):
        kept = deepest.get("stats")
        if kept is None or kept[0].depth < depth:
            kept = deepest["stats"] = [
                HankelStatistic.from_data(b, max(depth, deepest.get("depth", 0)), kind="gram")
                for b in blocks]
        stats = [s if s.depth == depth else s.shallower(depth) for s in kept]
    if stats is None:
        stats = [HankelStatistic.from_data(b, depth, kind="gram") for b in blocks]
    s12, s34 = stats[0].merge(stats[1]), stats[2].merge(stats[3])
    merged = [s12.merge(stats[2]), stats[1].merge(stats[2]).merge(stats[3]), s12, s34]

    def factor(k):
        stat, train = merged[k], parts[k][0]
        if stat.n_columns < depth * (train.n_inputs + train.n_outputs):
            return None                  # too few columns: prepare_fold reports it
        if kind == "gram" or train.n_samples > QR_MAX_SAMPLES:
            return stat.factor()
        # not exact to rounding: the QR statistic of the record, as the fold's
        # statistic='auto' would build it after computing the lagged products again
        exact = stat.exact_factor()
        if exact is None:
            with compact_wy_qr():         # scored and dropped: 2.5x faster QR
                exact = HankelStatistic.from_data(train, depth, kind="qr").factor()
        return exact
    # each fold's factorisation on subid's threads where the factors are large, as the
    # folds' candidates are scored
    return ordered_map(factor, range(len(parts)), threads=fold_threads(depth, parts))
