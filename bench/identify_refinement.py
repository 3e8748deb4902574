"""Benchmark (issue 21): the cost of ``subid.identify``'s refinement stage on real records.

For each bundled DaISy record (estimation part = first 2/3, means removed,
``bench/realdata.py``'s ``split``), CPU time (``time.process_time``, summed over
threads) and wall time of
``identify(est)`` and of its refinement stage (the time inside identify's
``_feedback``, ``_fold_refinement`` and ``_refine``: the feedback test, the
four fold refinements with their start models and scores, and the final
refinement when kept); "in refine" is the part spent inside
``subid.methods.dt.pem.refine`` (the process's CPU time while a call runs: with the
fold refinements on threads, the calls overlap and it counts the other threads'
work too), "subspace" the rest (both estimators' order searches). "before" is the library at ``--before`` (a git
revision, default ``main``, exported with ``git archive``), "after" this
checkout's ``src``; one process per (source, record, repeat), alternating
before/after, each compiling the kernels first on a small record, untimed.

The decisions table takes one ``identify(est)`` per source on every record of
``--decisions`` (the first timed run where there is one) and compares ``info['identify']['refinement']['kept']``, the
fold scores and the returned model (largest entry-wise difference of A, B, C,
D, K relative to the largest entry of the matrix).

Run: ``OPENBLAS_NUM_THREADS=1 python bench/identify_refinement.py [--before REV]
[--repeats 2] [--records steamgen,evaporator,CD_player_arm] [--decisions all]``;
writes ``bench/identify_refinement.md``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import pem_cost  # bench/: the export of a revision and the worker runner

ROOT = Path(__file__).resolve().parent.parent
SETS = ["ballbeam", "CD_player_arm", "dryer", "evaporator", "exchanger", "glassfurnace",
        "robot_arm", "steamgen", "winding"]

WORKER = r'''
import json, sys, time, warnings
sys.path.insert(0, sys.argv[3])
import numpy as np
import subid
import subid.methods.dt.pem as pem_module
from realdata import split

name = sys.argv[1]
est, val = split(name)
warnings.simplefilter("ignore")
small = subid.datasets.load("dryer")[:300]             # compile the kernels, untimed
subid.identify(small)
subid.identify(subid.datasets.load("steamgen")[:600])
out = {"record": name, "source": sys.argv[2]}
import subid.methods.identify as identify_module
spent = {"in_refine_s": 0.0, "stage_s": 0.0, "stage_wall_s": 0.0}
depth = {"in_refine_s": 0, "stage_s": 0}


def timing(module, name, key):
    inner = getattr(module, name)

    def timed(*args, **kwargs):            # the outermost call of each group only
        depth[key] += 1
        t0, w0 = time.process_time(), time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            depth[key] -= 1
            if depth[key] == 0:
                spent[key] += time.process_time() - t0
                if key == "stage_s":
                    spent["stage_wall_s"] += time.perf_counter() - w0
    setattr(module, name, timed)


timing(pem_module, "refine", "in_refine_s")
for name in ("_feedback", "_fold_refinement", "_refine"):     # the refinement stage
    timing(identify_module, name, "stage_s")
t, w = time.process_time(), time.perf_counter()
model = subid.identify(est)
out["identify_s"] = time.process_time() - t
out["identify_wall_s"] = time.perf_counter() - w
out.update(spent)
ref = model.info["identify"]["refinement"]
out["kept"] = bool(ref.get("kept"))
out["reason"] = ref.get("reason", "")
out["subspace_folds"] = ref.get("subspace_folds")
out["refined_folds"] = ref.get("refined_folds")
out["mean_gain"] = ref.get("mean_gain")
out["standard_error"] = ref.get("standard_error")
out["matrices"] = {k: np.asarray(getattr(model, k)).tolist()
                   for k in "ABCDK" if getattr(model, k) is not None}
print("RESULT " + json.dumps(out))
'''


def run(source: str, src: Path, name: str) -> dict:
    return pem_cost.run(source, src, name, WORKER)


def relative_difference(a: dict, b: dict) -> float:
    import numpy as np
    if a.keys() != b.keys():
        return float("inf")
    worst = 0.0
    for k in a:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        if x.shape != y.shape:
            return float("inf")
        if x.size:
            worst = max(worst, float(np.abs(x - y).max() / max(np.abs(x).max(), 1e-300)))
    return worst


def cost_table(results: list, records: list) -> str:
    rows = ["| record | source | identify s | refinement stage s | in refine s | subspace "
            "s | identify wall s | refinement stage wall s | kept |",
            "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    ratios = []
    for name in records:
        med = {}
        for source in ("before", "after"):
            rs = [r for r in results if r["record"] == name and r["source"] == source]
            med[source] = {k: statistics.median(r[k] for r in rs)
                           for k in ("identify_s", "stage_s", "in_refine_s",
                                     "identify_wall_s", "stage_wall_s")}
            m = med[source]
            rows.append(f"| {name} | {source} | {m['identify_s']:.2f} | {m['stage_s']:.2f} | "
                        f"{m['in_refine_s']:.2f} | {m['identify_s'] - m['stage_s']:.2f} | "
                        f"{m['identify_wall_s']:.2f} | {m['stage_wall_s']:.2f} | "
                        f"{rs[0]['kept']} |")
        b, a = med["before"], med["after"]
        ratios.append(f"| {name} | {b['stage_s'] / max(a['stage_s'], 1e-9):.2f} | "
                      f"{b['identify_s'] / max(a['identify_s'], 1e-9):.2f} | "
                      f"{a['stage_s'] / max(a['identify_s'] - a['stage_s'], 1e-9):.2f} | "
                      f"{b['stage_wall_s'] / max(a['stage_wall_s'], 1e-9):.2f} | "
                      f"{b['identify_wall_s'] / max(a['identify_wall_s'], 1e-9):.2f} |")
    return "\n".join(rows + ["", "| record | refinement stage before / after | identify "
                             "before / after | refinement / subspace after | refinement "
                             "stage wall before / after | identify wall before / after |",
                             "|---|---:|---:|---:|---:|---:|"] + ratios)


def decision_table(results: list, records: list) -> str:
    rows = ["| record | kept before | kept after | gain (se) before | gain (se) after | "
            "largest fold-score change | model difference |", "|---|---|---|---|---|---:|---:|"]
    for name in records:
        b, a = (next(r for r in results if r["record"] == name and r["source"] == s)
                for s in ("before", "after"))

        def gain(r):
            if r["mean_gain"] is None:
                return "-"
            return f"{r['mean_gain']:.3f} ({r['standard_error']:.3f})"
        moves = [abs(x - y) for key in ("subspace_folds", "refined_folds")
                 for x, y in zip(a[key] or [], b[key] or [])]
        rows.append(f"| {name} | {b['kept']} | {a['kept']} | {gain(b)} | {gain(a)} | "
                    f"{max(moves, default=0.0):.3f} | "
                    f"{relative_difference(b['matrices'], a['matrices']):.1e} |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="main")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--records", default="steamgen,evaporator,CD_player_arm")
    parser.add_argument("--decisions", default="all",
                        help="records of the decisions table ('all': the nine DaISy "
                             "records of bench/realdata.py; '' for none)")
    parser.add_argument("--out", default=str(ROOT / "bench" / "identify_refinement.md"))
    args = parser.parse_args()
    records = [r for r in args.records.split(",") if r]
    decisions = SETS if args.decisions == "all" else [r for r in args.decisions.split(",")
                                                       if r]
    with tempfile.TemporaryDirectory() as tmp:
        sources = {"before": pem_cost.export(args.before, Path(tmp)), "after": ROOT / "src"}
        timed = []
        for _ in range(args.repeats):
            for name in records:
                for source, src in sources.items():
                    timed.append(run(source, src, name))
                    print(json.dumps({k: v for k, v in timed[-1].items()
                                      if k != "matrices"}), flush=True)
        decided = []
        for name in decisions:
            for source, src in sources.items():     # the first timed run, where there is one
                decided.append(next((r for r in timed if r["record"] == name
                                     and r["source"] == source), None) or run(source, src, name))
                print(json.dumps({k: v for k, v in decided[-1].items() if k != "matrices"}),
                      flush=True)
    text = ["# The cost of `subid.identify`'s refinement stage (issue 21)", "",
            f"`python bench/identify_refinement.py --before {args.before} --repeats "
            f"{args.repeats}`: CPU s (summed over threads) and wall s, median of "
            f"{args.repeats} runs per source, one process per run, alternating before/after "
            "(module docstring).", ""]
    if records:
        text += [cost_table(timed, records), ""]
    if decisions:
        text += ["## Decisions and returned models", "",
                 "One `identify(est)` per source and record.", "",
                 decision_table(decided, decisions), ""]
    Path(args.out).write_text("\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
