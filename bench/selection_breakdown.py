"""Where a default ``moesp(data)`` call spends its time, step by step (issue 21).

Wraps the steps of the order search (the folds' lag products and statistics, their
problems, the fold candidates split into those with a stable A, scored from the lag
products, and those whose A is unstable, which take the stability rule and its residual
bounds; the innovation check; the final model) with wall-clock timers, runs the default
call on the 2x2 order-4 random system of ``bench/run.py`` (20 dB output noise) and prints
the median of each step over the calls. The steps a fold problem's ten orders share (its
SVD, future-past factor and feedthrough F-tests, computed at its first candidate) are
counted apart from the candidates. bench/selection_cost.md holds a run.

Usage::

    PYTHONPATH=src python bench/selection_breakdown.py [samples] [calls]
"""

from __future__ import annotations

import collections
import functools
import statistics
import sys
import time
import warnings


def main(argv):
    warnings.simplefilter("ignore")
    import subid
    from subid.methods.dt import _lag_fit, choice, pipeline
    from subid.methods.dt import selection as sel
    from subid.methods.dt.moesp import Moesp

    n_samples = int(argv[1]) if len(argv) > 1 else 10_000
    calls = int(argv[2]) if len(argv) > 2 else 9
    true = subid.systems.random_system(4, 2, 2, seed=1)
    data = subid.systems.simulate_data(true, n_samples, seed=2, output_snr_db=20)
    spent = collections.defaultdict(float)
    counts = collections.Counter()
    shared = [0.0]                    # a fold problem's steps, inside its first candidate

    def timed(owner, name, label=None):
        f = getattr(owner, name)

        @functools.wraps(f)
        def wrapper(*args, **kwargs):
            t = time.perf_counter()
            try:
                return f(*args, **kwargs)
            finally:
                dt = time.perf_counter() - t
                if label is None:
                    shared[0] += dt
                else:
                    spent[label] += dt
        setattr(owner, name, wrapper)

    timed(_lag_fit, "merged", "lag products of the folds (merged FFTs)")
    timed(sel, "fold_factors", "fold statistics (fold_factors)")
    timed(pipeline.Pipeline, "prepare_fold", "fold problems (prepare_fold)")
    timed(choice, "innovation_check", "innovation check")
    timed(choice, "unrepaired_choice", "final model (both estimators)")
    timed(Moesp, "decompose")
    timed(pipeline, "resolve_feedthrough")
    b_d_x0, fold_score = pipeline.b_d_x0, pipeline.Pipeline.fold_score

    def counted_b_d_x0(*args, **kwargs):
        counts["b_d_x0"] += 1
        return b_d_x0(*args, **kwargs)

    def split_fold_score(self, problem, estimator, held):
        t, before, inside = time.perf_counter(), counts["b_d_x0"], shared[0]
        out = fold_score(self, problem, estimator, held)
        steps = shared[0] - inside
        spent["fold problems' SVD, factor, feedthrough tests"] += steps
        label = ("unstable fold candidates (stability rule, bounds)"
                 if counts["b_d_x0"] > before else "stable fold candidates (lag products)")
        spent[label] += time.perf_counter() - t - steps
        counts[label] += 1
        return out

    pipeline.b_d_x0 = counted_b_d_x0
    pipeline.Pipeline.fold_score = split_fold_score
    for _ in range(3):                # compiled kernels, caches
        subid.moesp(data)
    rows, totals = collections.defaultdict(list), []
    for _ in range(calls):
        spent.clear()
        counts.clear()
        t = time.perf_counter()
        subid.moesp(data)
        totals.append(time.perf_counter() - t)
        for label, value in spent.items():
            rows[label].append(value)
        per_call = dict(counts)
    total = statistics.median(totals)
    print(f"N = {n_samples}: default call {total * 1e3:.1f} ms (median of {calls})")
    for label, values in rows.items():
        value = statistics.median(values)
        count = per_call.get(label)
        print(f"  {label:52s} {value * 1e3:6.1f} ms {100 * value / total:5.1f} %"
              + (f"  ({count} candidates)" if count else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
