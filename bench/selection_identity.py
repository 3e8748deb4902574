"""The default calls on every bundled record, saved or compared (issue 21, cost of choosing).

A change that only makes the order choice cheaper must leave the choice and the
model as they were. ``save`` writes, for every bundled DaISy record (the first
2/3, means removed, as ``bench/realdata.py`` splits it) and each of
``moesp``, ``ls_subspace`` and ``n4sid`` called with their defaults, the chosen
order, horizon and estimator, every candidate's cross-validation score and the
model's matrices; ``compare`` runs the calls again and reports the largest
differences against a saved file.

Usage::

    python bench/selection_identity.py save before.pkl
    python bench/selection_identity.py compare before.pkl
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import _identity

METHODS = ("moesp", "ls_subspace", "n4sid")


def split(name):
    import subid
    data = subid.datasets.load(name)
    est = data[:(2 * data.n_samples) // 3]
    return subid.IOData(est.u - est.u.mean(axis=0), est.y - est.y.mean(axis=0), dt=est.dt)


def run():
    import subid
    out = {}
    for name in subid.datasets.names():
        data = split(name)
        for method in METHODS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.process_time()
                m = getattr(subid, method)(data)
                seconds = time.process_time() - t0
            sel = m.info.get("order_selection", {})
            scores = {(c["order"], c["horizon"], c.get("system_matrices")): c["score"]
                      for c in sel.get("candidates", [])}
            out[(name, method)] = {
                "order": m.order, "horizon": m.info["horizon"],
                "system_matrices": m.info.get("system_matrices"),
                "matrices": [np.array(M) for M in (m.A, m.B, m.C, m.D)]
                + [np.array(m.K) if m.K is not None else np.zeros(0)],
                "scores": scores, "seconds": seconds}
            print(f"{name:14s} {method:12s} n={m.order:2d} f={m.info['horizon']:2d} "
                  f"{m.info.get('system_matrices')!s:7s} {seconds:6.2f} s", flush=True)
    return out


def compare(before, after):
    worst_model = worst_score = 0.0
    same = True
    for key, b in before.items():
        a = after[key]
        choice_b = (b["order"], b["horizon"], b["system_matrices"])
        choice_a = (a["order"], a["horizon"], a["system_matrices"])
        if choice_a != choice_b:
            same = False
            print(f"{key}: choice {choice_b} -> {choice_a}")
            continue
        dm = max(float(np.max(np.abs(x - y), initial=0.0)) / max(float(np.max(np.abs(x),
                 initial=0.0)), 1e-300) for x, y in zip(b["matrices"], a["matrices"]))
        ds = max((abs(b["scores"][k] - a["scores"].get(k, np.inf)) for k in b["scores"]),
                 default=0.0)
        worst_model, worst_score = max(worst_model, dm), max(worst_score, ds)
        print(f"{key[0]:14s} {key[1]:12s} same choice; model rel. diff {dm:.1e}; "
              f"largest score diff {ds:.1e} points; {b['seconds']:.2f} s -> {a['seconds']:.2f} s")
    total_b = sum(b["seconds"] for b in before.values())
    total_a = sum(after[k]["seconds"] for k in before)
    print(f"choices {'all the same' if same else 'CHANGED'}; largest model difference "
          f"{worst_model:.1e} (relative, per matrix), largest score difference "
          f"{worst_score:.1e} points; CPU {total_b:.1f} s -> {total_a:.1f} s")
    return same


if __name__ == "__main__":
    sys.exit(_identity.main(sys.argv, lambda mode: run(), compare))
