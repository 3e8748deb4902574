"""The demo's ``arx`` and ``pbsid`` default calls on every bundled record, saved or compared
(issue 29: a cheaper default call must leave the model as it was).

``save`` writes, for every bundled DaISy record split as ``subid demo`` splits
it (means removed, the first 70 % for estimation, :func:`subid.cli.demo.identify_one`)
and each of ``arx`` and ``pbsid`` called with their defaults, the chosen
structure (orders, delays, horizon), every candidate's cross-validation score,
the model's matrices, the covariance of its parameters (``F F^T`` of
``info['parameter_covariance']``, which does not depend on the factor's
signs) and the validation fits the demo reports; ``compare`` runs the calls
again and reports the largest differences against a saved file, and the CPU
seconds of each call before and after (one process each: run the two in turn,
never together, on a shared machine). ``floor`` compares like ``compare``
but on the estimation records with every input sample multiplied by ``1 + 2e-16
z`` (z standard normal, seeded): run with the tree that saved the file, it
shows how far rounding alone moves that tree's models, the scale against which
a difference of ``compare`` is read.

Usage::

    PYTHONPATH=/work/main/src python bench/poly_identity.py save before.pkl
    PYTHONPATH=src python bench/poly_identity.py compare before.pkl [RECORD,...]
    PYTHONPATH=/work/main/src python bench/poly_identity.py floor before.pkl
"""

from __future__ import annotations

import sys
import warnings

import numpy as np

import _identity

METHODS = ("arx", "pbsid")


def _candidates(selection):
    """Candidate key -> score of an ``order_selection`` record."""
    out = {}
    for c in (selection or {}).get("candidates", []):
        key = tuple((k, v) for k, v in sorted(c.items())
                    if k not in ("score", "criterion") and not isinstance(v, (list, dict)))
        out[key] = c["score"]
    return out


def _covariance(model):
    pc = model.info.get("parameter_covariance")
    if pc is None:
        return None
    F = np.asarray(pc["factor"])
    return F @ F.T


def _perturb_inputs(demo):
    """Make ``demo._parts`` return the estimation records with their inputs perturbed by
    rounding (``floor``)."""
    import subid
    original = demo._parts
    rng = np.random.default_rng(0)

    def parts(name, fraction):
        est, val = original(name, fraction)
        u = est.u * (1.0 + 2e-16 * rng.standard_normal(est.u.shape))
        return subid.IOData(u, est.y, dt=est.dt, input_names=est.input_names,
                            output_names=est.output_names), val
    demo._parts = parts


def run(names=None, methods=METHODS, perturb=False):
    import subid
    from subid.cli import demo
    if perturb:
        _perturb_inputs(demo)
    out = {}
    with warnings.catch_warnings():       # imports and compiled kernels loaded, not timed
        warnings.simplefilter("ignore")
        demo.identify_one("dryer", "n4sid")
    for name in names or subid.datasets.names():
        for method in methods:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                row, m = demo.identify_one(name, method)
            if m is None:
                out[(name, method)] = {"error": row["error"], "seconds": row["cpu_seconds"]}
                print(f"{name:14s} {method:6s} failed: {row['error']}", flush=True)
                continue
            sel = m.info.get("order_selection") or {}
            orders = m.info.get("orders")
            out[(name, method)] = {
                "order": m.order, "horizon": m.info.get("horizon"),
                "structure": None if orders is None else
                {k: np.asarray(v).tolist() for k, v in orders.items()},
                "selected": sel.get("selected"),
                "matrices": [np.array(M) for M in (m.A, m.B, m.C, m.D)]
                + [np.array(m.K) if m.K is not None else np.zeros(0)],
                "noise_cov": np.array(m.noise_cov) if m.noise_cov is not None else None,
                "x0": None if m.info.get("x0") is None else np.array(m.info["x0"]),
                "covariance": _covariance(m),
                "scores": _candidates(sel),
                "fit_val": np.asarray(row["fit_val"]), "fit_est": np.asarray(row["fit_est"]),
                "seconds": row["cpu_seconds"]}
            print(f"{name:14s} {method:6s} n={m.order:2d} {row['cpu_seconds']:6.2f} s",
                  flush=True)
    return out


def _rel(x, y):
    if x is None or y is None:
        return 0.0 if x is None and y is None else np.inf
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.shape != y.shape:
        return np.inf
    return float(np.max(np.abs(x - y), initial=0.0)) / max(float(np.max(np.abs(x),
                                                                          initial=0.0)), 1e-300)


def compare(before, after):
    worst = {"model": 0.0, "covariance": 0.0, "score": 0.0, "fit": 0.0}
    same = True
    for key, b in before.items():
        a = after[key]
        if "error" in b or "error" in a:
            ok = b.get("error") == a.get("error")
            same &= ok
            print(f"{key}: error {'the same' if ok else 'CHANGED'}")
            continue
        choice_b = (b["order"], b["horizon"], repr(b["structure"]), repr(b["selected"]))
        choice_a = (a["order"], a["horizon"], repr(a["structure"]), repr(a["selected"]))
        if choice_a[:3] != choice_b[:3] or set(a["scores"]) != set(b["scores"]):
            same = False
            print(f"{key}: choice {choice_b} -> {choice_a}")
            continue
        dm = max([_rel(x, y) for x, y in zip(b["matrices"], a["matrices"])]
                 + [_rel(b["noise_cov"], a["noise_cov"]), _rel(b["x0"], a["x0"])])
        dc = _rel(b["covariance"], a["covariance"])
        ds = max((abs(b["scores"][k] - a["scores"][k]) for k in b["scores"]), default=0.0)
        df = float(np.max(np.abs(b["fit_val"] - a["fit_val"]), initial=0.0))
        df = max(df, float(np.max(np.abs(b["fit_est"] - a["fit_est"]), initial=0.0)))
        for k, v in zip(("model", "covariance", "score", "fit"), (dm, dc, ds, df)):
            worst[k] = max(worst[k], v)
        print(f"{key[0]:14s} {key[1]:6s} same choice; model {dm:.1e}, covariance {dc:.1e} "
              f"(relative); scores {ds:.1e}, fits {df:.1e} points; "
              f"{b['seconds']:.2f} s -> {a['seconds']:.2f} s")
    for method in METHODS:
        keys = [k for k in before if k[1] == method]
        tb = sum(before[k]["seconds"] for k in keys)
        ta = sum(after[k]["seconds"] for k in keys)
        print(f"{method}: CPU {tb:.1f} s -> {ta:.1f} s")
    print(f"choices {'all the same' if same else 'CHANGED'}; largest relative difference of "
          f"the model matrices {worst['model']:.1e}, of the parameter covariance "
          f"{worst['covariance']:.1e}; largest difference of a candidate's score "
          f"{worst['score']:.1e}, of a fit {worst['fit']:.1e} points")
    return same


def main(argv):
    names = argv[3].split(",") if len(argv) > 3 else None

    def compare_named(before, after):
        return compare({k: v for k, v in before.items() if not names or k[0] in names}, after)
    return _identity.main(argv, lambda mode: run(names, perturb=mode == "floor"), compare_named,
                          modes=("compare", "floor"))


if __name__ == "__main__":
    sys.exit(main(sys.argv))
