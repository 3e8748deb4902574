"""Benchmark (issue 21): the cost of PEM refinement, before and after the
compressed-Jacobian trust-region step and the vectorised sensitivity kernel.

For each record (DaISy steamgen, 9600 x (4 in, 4 out); dryer, 1000 x (1, 1)):
estimation part = first 2/3 with its means removed (bench/realdata.py).
Measured, CPU time (``time.process_time``), one process per (source, record):

* ``moesp(est)``: the default subspace model, and ``pem(est, model,
  focus='simulation')`` started from it (final cost, evaluations);
* ``identify(est)``: total, and the part spent inside ``pem`` or
  ``subid.methods.dt.pem.refine`` (the four fold refinements and the final one:
  "refinement"); "subspace" is the rest (order,
  horizon, feedthrough and estimator selection, fold start models, scoring).
  The ratio refinement / subspace is the issue's "its refinement <= 2x the
  subspace model it starts from".

"before" is the library at ``--before`` (a git revision, default ``main``,
exported with ``git archive``), "after" this checkout's ``src``. The runs
alternate before/after record by record (one process at a time); each process
first compiles the kernels on a small problem, untimed.

Run: ``OPENBLAS_NUM_THREADS=1 python bench/pem_cost.py [--before REV] [--repeats 1]
[--records steamgen,dryer]``; writes ``bench/pem_cost.md``. ``--optimisers`` appends
a comparison on steamgen of this library's optimiser with scipy's ``trf`` (exact
SVD, the former optimiser), ``trf`` with ``tr_solver='lsmr'`` and ``lm`` (MINPACK).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

WORKER = r'''
import json, sys, time, warnings
sys.path.insert(0, sys.argv[3])
import numpy as np
import subid
import subid.methods.dt.pem as pem_module
from realdata import split, score

name = sys.argv[1]
est, val = split(name)
with warnings.catch_warnings():              # compile the kernels, untimed
    warnings.simplefilter("ignore")
    small = subid.datasets.load("dryer")[:300]
    subid.pem(small, subid.moesp(small, 2), focus="simulation")
    subid.pem(small, subid.moesp(small, 2), focus="prediction")
    subid.identify(small)
out = {"record": name, "samples": est.n_samples, "source": sys.argv[2]}
t = time.process_time()
model = subid.moesp(est)
out["moesp_s"] = time.process_time() - t
out["order"] = model.order
t = time.process_time()
refined = subid.pem(est, model, focus="simulation")
out["pem_s"] = time.process_time() - t
out["pem_start_cost"] = float(refined.info["start_cost"])
out["pem_final_cost"] = float(refined.info["final_cost"])
out["pem_evaluations"] = int(refined.info["n_evaluations"])
out["pem_fit"] = score(refined, val)

spent = [0.0, 0]
depth = [0]

def timing(inner):
    def timed(*args, **kwargs):
        depth[0] += 1
        t0 = time.process_time()
        try:
            return inner(*args, **kwargs)
        finally:
            depth[0] -= 1
            if depth[0] == 0:
                spent[0] += time.process_time() - t0
                spent[1] += 1
    return timed

pem_module.pem = timing(pem_module.pem)
if hasattr(pem_module, "refine"):            # identify's refinement (pem stopped early)
    pem_module.refine = timing(pem_module.refine)
t = time.process_time()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    chosen = subid.identify(est)
out["identify_s"] = time.process_time() - t
out["refinement_s"] = spent[0]
out["pem_calls"] = spent[1]
out["identify_fit"] = score(chosen, val)
out["identify_kept_refinement"] = chosen.info.get("refined_by") == "pem"
print("RESULT " + json.dumps(out))
'''


OPTIMISERS = r'''
import json, sys, time, warnings
sys.path.insert(0, sys.argv[2])
import scipy.optimize
import subid
import subid.methods.dt.pem as pem_module
from subid.methods.dt import _trust_region
from realdata import split

est, _ = split(sys.argv[1])
small = subid.datasets.load("dryer")[:300]
subid.pem(small, subid.moesp(small, 2), focus="simulation")          # compile, untimed
model = subid.moesp(est)
original = scipy.optimize.least_squares
variants = {
    "compressed Jacobian (this library)": None,
    "scipy trf, exact (SVD of J)": dict(),
    "scipy trf, tr_solver='lsmr'": dict(tr_solver="lsmr"),
    "scipy lm (MINPACK, QR of J)": dict(method="lm"),
}
for label, options in variants.items():
    if options is None:
        _trust_region.available = lambda: True
    else:
        _trust_region.available = lambda: False

        def patched(*args, _o=options, **kwargs):
            kwargs.update(_o)
            return original(*args, **kwargs)
        pem_module.scipy.optimize.least_squares = patched
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.process_time()
        r = subid.pem(est, model, focus="simulation")
        spent = time.process_time() - t
    pem_module.scipy.optimize.least_squares = original
    print("RESULT " + json.dumps(dict(label=label, seconds=spent,
                                      cost=float(r.info["final_cost"]),
                                      evaluations=int(r.info["n_evaluations"]))), flush=True)
'''


def optimisers(name: str) -> str:
    """Markdown table: ``pem(est, moesp(est), focus='simulation')`` with each optimiser."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(ROOT / "src"))
    done = subprocess.run([sys.executable, "-c", OPTIMISERS, name, str(ROOT / "bench")],
                          env=env, capture_output=True, text=True, check=True)
    rows = [json.loads(x[len("RESULT "):]) for x in done.stdout.splitlines()
            if x.startswith("RESULT ")]
    lines = [f"`pem(est, moesp(est), focus='simulation')` on {name}, one process, CPU s:", "",
             "| optimiser | CPU s | final cost | evaluations |", "|---|---:|---|---:|"]
    lines += [f"| {r['label']} | {r['seconds']:.2f} | {r['cost']:.13g} | {r['evaluations']} |"
              for r in rows]
    return "\n".join(lines)


def export(rev: str, where: Path) -> Path:
    """``src`` of git revision ``rev`` extracted under ``where``."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "src"],
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(where)], input=archive, check=True)
    return where / "src"


def run(source: str, src: Path, name: str, worker: str = WORKER) -> dict:
    """The ``RESULT`` line of ``worker`` (a script) run on record ``name`` with the
    library at ``src``, in its own process."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(src))
    done = subprocess.run([sys.executable, "-c", worker, name, source, str(ROOT / "bench")],
                          env=env, capture_output=True, text=True, check=True)
    line = [x for x in done.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def table(results) -> str:
    rows = ["| record | source | moesp(est) s | pem(est, moesp) s | pem cost start -> final "
            "(evals) | identify s | refinement s (pem calls) | subspace s | "
            "refinement / subspace | identify val fit % |",
            "|---|---|---:|---:|---|---:|---:|---:|---:|---:|"]
    for r in results:
        sub = r["identify_s"] - r["refinement_s"]
        rows.append(
            f"| {r['record']} | {r['source']} | {r['moesp_s']:.2f} | {r['pem_s']:.2f} | "
            f"{r['pem_start_cost']:.6g} -> {r['pem_final_cost']:.13g} "
            f"({r['pem_evaluations']}) | {r['identify_s']:.2f} | "
            f"{r['refinement_s']:.2f} ({r['pem_calls']}) | {sub:.2f} | "
            f"{r['refinement_s'] / max(sub, 1e-9):.2f} | {r['identify_fit']:.2f} |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="main")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--records", default="steamgen,dryer")
    parser.add_argument("--out", default=str(ROOT / "bench" / "pem_cost.md"))
    parser.add_argument("--optimisers", action="store_true",
                        help="only compare the optimisers on steamgen (appended to --out)")
    args = parser.parse_args()
    if args.optimisers:
        text = "\n".join(["", "## Optimisers compared", "", optimisers("steamgen"), ""])
        with open(args.out, "a") as fh:
            fh.write(text)
        print(text)
        return
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        before = export(args.before, Path(tmp))
        for _ in range(args.repeats):
            for name in args.records.split(","):
                for source, src in ((f"before ({args.before})", before),
                                    ("after", ROOT / "src")):
                    results.append(run(source, src, name))
                    print(json.dumps(results[-1]), flush=True)
    load = os.getloadavg()
    text = "\n".join([
        "# PEM refinement cost (issue 21)", "",
        "Generated by `OPENBLAS_NUM_THREADS=1 python bench/pem_cost.py` "
        f"(before = `{args.before}`) on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"CPU seconds (`time.process_time`), one process per row, rows in the order run; "
        f"machine load average at the end {load[0]:.1f} (2 cores shared).", "",
        table(results), "",
        "refinement = CPU time inside `subid.pem` or `subid.methods.dt.pem.refine` (identify's "
        "refinement, stopped at statistical precision) during `identify(est)` (four fold "
        "refinements and the final one); subspace = the rest of `identify(est)`.", ""])
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
