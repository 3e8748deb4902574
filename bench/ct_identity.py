"""The continuous-time default on every bundled record, saved or compared (issue 29).

A change that only makes ``ct_subspace`` cheaper must leave its models as they
were. ``save`` writes, for every bundled record split as ``subid demo`` splits
it (means removed, the first 70 % for estimation), the model of
``ct_subspace(est)`` with its defaults: the chosen order, the number of basis
functions, the basis poles, the chosen start, feedthrough and refinement, every
candidate's cross-validation score, the matrices and the fit % on both parts;
``compare`` runs the calls again and reports the largest differences against a
saved file.

Usage (the baseline from another tree, e.g. main's)::

    PYTHONPATH=/work/main/src python bench/ct_identity.py save before.pkl
    PYTHONPATH=src python bench/ct_identity.py compare before.pkl [DATASET ...]
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import _identity


def _scores(selection):
    """``{(order, horizon, variant): score}`` of a cross-validation record."""
    if not isinstance(selection, dict):
        return {}
    return {(c.get("order"), c.get("horizon"), c.get("system_matrices")): c["score"]
            for c in selection.get("candidates", []) if "score" in c}


def run(names=None):
    import subid
    from subid.cli.demo import FRACTION
    from subid.evaluation.report import evaluate
    from subid.methods.ct.ct_subspace import ct_subspace
    out = {}
    for name in names or subid.datasets.names():
        est, val = subid.datasets.load(name).detrend().split(FRACTION)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.process_time()
            m = ct_subspace(est)
            seconds = time.process_time() - t0
            fits = evaluate(m, est, val)
        info = m.info
        x0 = info.get("x0")
        out[name] = {
            "choice": (m.order, info.get("horizon"), info.get("start"),
                       bool(info.get("feedthrough")), bool(info.get("refined"))),
            "poles": np.array(info.get("basis_poles"), dtype=complex),
            "matrices": [np.array(M, dtype=float) for M in (m.A, m.B, m.C, m.D)]
            + [np.zeros(0) if x0 is None else np.array(x0, dtype=float)],
            "scores": {key: _scores(info.get(key)) for key in
                       ("order_selection", "feedthrough_selection", "bd_selection",
                        "refine_selection")},
            "fits": np.concatenate([fits["fit_estimation"], fits["fit_validation"]]),
            "seconds": seconds}
        print(f"{name:14s} n={m.order:2d} N={info.get('horizon'):2d} "
              f"{info.get('start')!s:24s} {seconds:6.2f} s", flush=True)
    return out


def _relative(x, y):
    x, y = np.asarray(x), np.asarray(y)
    if x.shape != y.shape:
        return np.inf
    return float(np.max(np.abs(x - y), initial=0.0)) / max(float(np.max(np.abs(x),
                                                                       initial=0.0)), 1e-300)


def compare(before, after):
    worst_model = worst_score = worst_fit = 0.0
    same = True
    for name, a in after.items():
        b = before[name]
        if a["choice"] != b["choice"] or _relative(b["poles"], a["poles"]) > 1e-12:
            same = False
            print(f"{name}: choice {b['choice']} -> {a['choice']}")
            continue
        dm = max(_relative(x, y) for x, y in zip(b["matrices"], a["matrices"]))
        ds = 0.0
        for key, scores in b["scores"].items():
            other = a["scores"].get(key, {})
            if set(other) != set(scores):
                ds = np.inf
            ds = max([ds] + [abs(scores[k] - other.get(k, np.inf)) for k in scores])
        df = float(np.max(np.abs(b["fits"] - a["fits"]), initial=0.0))
        worst_model, worst_score = max(worst_model, dm), max(worst_score, ds)
        worst_fit = max(worst_fit, df)
        print(f"{name:14s} same choice; model rel. diff {dm:.1e}; score diff {ds:.1e}; "
              f"fit diff {df:.1e} points; {b['seconds']:.2f} s -> {a['seconds']:.2f} s")
    total_b = sum(before[k]["seconds"] for k in after)
    total_a = sum(a["seconds"] for a in after.values())
    print(f"choices {'all the same' if same else 'CHANGED'}; largest model difference "
          f"{worst_model:.1e} (relative, per matrix), largest score difference "
          f"{worst_score:.1e}, largest fit difference {worst_fit:.1e} points; "
          f"CPU {total_b:.1f} s -> {total_a:.1f} s")
    return same and worst_model <= 1e-9


if __name__ == "__main__":
    sys.exit(_identity.main(sys.argv, lambda mode: run(sys.argv[3:] or None), compare))
