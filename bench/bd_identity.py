"""Models of every B, D, x0 route, saved or compared bit for bit (issue 24, item 2).

Fits every registered batch method (discrete and continuous time) with its
defaults on every bundled DaISy record, and the routes the defaults do not
take (``bd_method`` choices, merged experiments, the streamed and Dask
second passes, the recursive identifier), and saves A, B, C, D, K and x0 of
each model to an ``.npz``; with ``--compare`` it fits again and prints the
largest absolute difference per case against a saved file.

Usage (from the repository root)::

    PYTHONPATH=src OPENBLAS_NUM_THREADS=1 python bench/bd_identity.py save before.npz
    PYTHONPATH=src OPENBLAS_NUM_THREADS=1 python bench/bd_identity.py compare before.npz

``--quick`` (after the file name): three records and the subspace methods only.
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import _identity
import subid
from subid import datasets
from subid.methods.dt import distributed, stream
from subid.methods.registry import METHODS

# The polynomial prediction-error methods (armax, oe, bj) take no B, D route: on one record
# only. ct_subspace (its own cross-validation, several seconds a fit): the records of up
# to 2,500 samples.
POLYNOMIAL = {"armax", "oe", "bj"}


QUICK = "--quick" in sys.argv      # three records, the subspace methods, no ct extras


def _cases():
    for name in datasets.names():
        if QUICK and name not in ("ballbeam", "dryer", "robot_arm"):
            continue
        data = datasets.load(name)
        for method, spec in METHODS.items():
            if spec.kind != "batch" or (QUICK and method not in ("ls", "moesp", "n4sid")):
                continue
            if method in POLYNOMIAL and name != "dryer":
                continue
            if method == "ct" and data.n_samples > 2500:
                continue
            yield f"{name}/{method}", lambda d=data, s=spec: s.load()(d)
    dryer = datasets.load("dryer")
    robot = datasets.load("robot_arm")
    ballbeam = datasets.load("ballbeam")
    cd = datasets.load("CD_player_arm")
    for data, label in ((dryer, "dryer"), (ballbeam, "ballbeam"), (cd, "CD_player_arm")):
        for bd in ("simulation", "projection"):
            for fn in ("moesp", "ls_subspace"):
                yield (f"{label}/{fn}/bd={bd}",
                       lambda d=data, f=fn, b=bd: getattr(subid, f)(d, 4, bd_method=b))
        yield (f"{label}/moesp/stability=none",
               lambda d=data: subid.moesp(d, 4, stability="none"))
        yield (f"{label}/moesp/x0=False",
               lambda d=data: subid.moesp(d, 4, estimate_x0=False))
        yield (f"{label}/moesp/feedthrough=False",
               lambda d=data: subid.moesp(d, 4, feedthrough=False))
        yield (f"{label}/n4sid/stability=enforce",
               lambda d=data: subid.n4sid(d, 4, stability="enforce"))
        yield (f"{label}/moesp/states", lambda d=data: subid.moesp(d, 4, system_matrices="states"))
    merged = subid.merge([dryer[:400], dryer[400:700], dryer[700:]])
    for fn in ("moesp", "ls_subspace", "n4sid"):
        yield f"merged/{fn}", lambda f=fn: getattr(subid, f)(merged, 4)
        yield (f"merged/{fn}/enforce",
               lambda f=fn: getattr(subid, f)(merged, 4, stability="enforce"))
    yield "merged/moesp/x0=False", lambda: subid.moesp(merged, 4, estimate_x0=False)
    yield "robot/moesp/unstable", lambda: subid.moesp(robot, 7, stability="auto")
    pieces = [dryer[:300], dryer[300:650], dryer[650:]]
    yield "stream/moesp", lambda: subid.identify_stream(pieces, "moesp", 4)
    yield "stream/ls", lambda: subid.identify_stream(pieces, "ls", 4)
    yield ("stream/merged", lambda: subid.identify_stream(
        [dryer[:300], stream.NEW_EXPERIMENT, dryer[300:]], "moesp", 4))
    try:
        import dask.array as da
        yield ("dask/moesp", lambda: distributed.identify(
            da.from_array(dryer.u, chunks=(250, 1)), da.from_array(dryer.y, chunks=(250, 1)),
            "moesp", order=4))
    except ImportError:
        pass
    if QUICK:
        return
    yield "ct/filtered", lambda: subid.ct_subspace(dryer, 4, bd_method="filtered")
    yield "ct/simulation", lambda: subid.ct_subspace(dryer, 4, bd_method="simulation")
    for bd in ("regression", "projection"):
        def run(b=bd):
            ident = subid.RecursiveSubspace(3, 1, 1, horizon=8, seed=1, **_recursive_bd(b))
            for k in range(0, 1000, 100):
                ident.update(dryer.u[k:k + 100], dryer.y[k:k + 100])
            return ident.model
        yield f"recursive/{bd}", run

        def run_forget(b=bd):
            ident = subid.RecursiveSubspace(3, 1, 1, horizon=8, seed=1, forgetting=0.999,
                                            **_recursive_bd(b))
            for k in range(0, 1000, 100):
                ident.update(dryer.u[k:k + 100], dryer.y[k:k + 100])
            return ident.model
        yield f"recursive-forget/{bd}", run_forget


def _recursive_bd(name):
    """The recursive identifier's option value for the output regression (renamed
    'regression' -> 'simulation' by issue 24)."""
    import inspect
    default = inspect.signature(subid.RecursiveSubspace).parameters["bd_method"].default
    if name == "regression":
        return {"bd_method": default}
    return {"bd_method": name}


def _matrices(model):
    out = {}
    for key in ("A", "B", "C", "D", "K"):
        value = getattr(model, key, None)
        if value is not None:
            out[key] = np.asarray(value, dtype=float)
    x0 = model.info.get("x0")
    if x0 is not None:
        out["x0"] = np.asarray(x0, dtype=float)
    return out


def fit_all():
    results, errors = {}, {}
    for case, fit in _cases():
        start = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = fit()
        except Exception as exc:   # noqa: BLE001 - recorded and compared as text
            errors[case] = f"{type(exc).__name__}: {exc}"[:200]
            print(f"{case}: {errors[case]}", file=sys.stderr, flush=True)
            continue
        for key, value in _matrices(model).items():
            results[f"{case}|{key}"] = value
        print(f"{case}: {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    return results, errors


def _save(path, fitted):
    results, errors = fitted
    np.savez(path, **results, **{f"{k}|error": np.array(v) for k, v in errors.items()})


def compare(saved, fitted):
    results, errors = fitted
    worst = 0.0
    bad = 0
    keys = sorted(set(saved.files) | set(results) | {f"{k}|error" for k in errors})
    for key in keys:
        if key.endswith("|error"):
            before = str(saved[key]) if key in saved.files else None
            after = errors.get(key[:-6])
            if before != after:
                bad += 1
                print(f"DIFFERENT ERROR {key}: {before!r} -> {after!r}")
            continue
        if key not in saved.files or key not in results:
            bad += 1
            print(f"MISSING {key}: before {key in saved.files}, after {key in results}")
            continue
        a, b = saved[key], results[key]
        if a.shape != b.shape:
            bad += 1
            print(f"SHAPE {key}: {a.shape} -> {b.shape}")
            continue
        diff = float(np.max(np.abs(a - b))) if a.size else 0.0
        worst = max(worst, diff)
        if diff > 0:
            print(f"{key}: max abs diff {diff:.3g}")
    print(f"{len(keys)} arrays, {bad} mismatched, largest abs difference {worst:.3g}")
    return not bad and worst <= 1e-12


if __name__ == "__main__":
    sys.exit(_identity.main(sys.argv, lambda mode: fit_all(), compare, save=_save,
                            load=np.load))
