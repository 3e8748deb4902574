"""Default calls on real data against SIPPY at its best order (issue 10).

For each bundled DaISy record except dryer2 and powerplant: the first 2/3
estimate (their means removed, from both parts), the last 1/3 validates.
Every model, subid's and SIPPY's, is scored by the same code: simulation
fit (NRMSE %, mean over outputs) with the initial state fitted by least
squares on the validation part (:func:`subid.fit_percent`).

* subid: the DEFAULT call of each method, ``method(estimation_data)``.
* SIPPY (``sippy-unipi``, installed by ``make bench-realdata`` in the
  benchmark's own environment, never a dependency of subid): N4SID, MOESP
  and CVA at orders 1..10 and horizons 10 and 20; its best fit over that
  grid is an oracle (chosen on the validation data).

Usage::

    python bench/realdata.py --out bench/realdata.md [--peers-cache bench/realdata_peers.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings

import numpy as np

SETS = ["ballbeam", "CD_player_arm", "dryer", "evaporator", "exchanger", "glassfurnace",
        "robot_arm", "steamgen", "winding"]
SIPPY_METHODS = ["N4SID", "MOESP", "CVA"]
ORDERS = range(1, 11)
HORIZONS = (10, 20)
TOLERANCE = 3.0


def split(name):
    """Estimation (first 2/3) and validation (last 1/3) parts, estimation means removed."""
    import subid
    data = subid.datasets.load(name)
    cut = (2 * data.n_samples) // 3
    est, val = data[:cut], data[cut:]
    mu, my = est.u.mean(axis=0), est.y.mean(axis=0)
    est = subid.IOData(est.u - mu, est.y - my, dt=est.dt, input_names=est.input_names,
                       output_names=est.output_names)
    val = subid.IOData(val.u - mu, val.y - my, dt=val.dt, input_names=val.input_names,
                       output_names=val.output_names)
    return est, val


def score(model, val) -> float:
    """Mean simulation fit over the outputs; -inf when the simulation overflows."""
    import subid
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fits = subid.fit_percent(model, val)
    except subid.errors.SubidError:
        return -np.inf
    value = float(np.mean(fits))
    return value if np.isfinite(value) else -np.inf


def sippy_grid(name, est, val) -> dict:
    """SIPPY's fit for every (method, order, horizon); None where it failed."""
    from sippy_unipi import system_identification

    import subid
    out = {}
    for method in SIPPY_METHODS:
        for f in HORIZONS:
            for n in ORDERS:
                key = f"{method}/{n}/{f}"
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        sys_id = system_identification(est.y.T, est.u.T, method,
                                                       SS_fixed_order=n, SS_f=f, SS_p=f,
                                                       SS_D_required=True)
                    model = subid.StateSpace(sys_id.A, sys_id.B, sys_id.C, sys_id.D, est.dt)
                    out[key] = score(model, val)
                except Exception as exc:  # noqa: BLE001 - a peer's failure is a table entry
                    out[key] = None
                    print(f"  SIPPY {name} {key}: {type(exc).__name__}: {exc}"[:200],
                          file=sys.stderr)
    return out


def subid_defaults(est, val) -> dict:
    import subid
    rows = {}
    for label, method in (("ls_subspace", subid.ls_subspace), ("moesp", subid.moesp),
                          ("n4sid", subid.n4sid), ("arx", subid.arx), ("oe", subid.oe)):
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = method(est)
        seconds = time.perf_counter() - start
        rows[label] = {"fit": score(model, val), "order": model.order,
                       "horizon": model.info.get("horizon"), "seconds": seconds,
                       "system_matrices": model.info.get("system_matrices"),
                       "stable": bool(model.is_stable()),
                       "stability": model.info.get("stability", {}).get("action")
                       if isinstance(model.info.get("stability"), dict) else None,
                       "warnings": sorted({type(w.message).__name__ for w in caught})}
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="bench/realdata.md")
    parser.add_argument("--peers-cache", default="bench/realdata_peers.json",
                        help="JSON cache of SIPPY's grid (recomputed when missing)")
    parser.add_argument("--sets", default=",".join(SETS))
    args = parser.parse_args(argv)
    sets = args.sets.split(",")
    peers = {}
    if os.path.exists(args.peers_cache):
        with open(args.peers_cache) as fh:
            peers = json.load(fh)
    try:
        import sippy_unipi  # noqa: F401
        have_sippy = True
    except ImportError:
        have_sippy = False
    results = {}
    for name in sets:
        est, val = split(name)
        if name not in peers and have_sippy:
            print(f"SIPPY grid on {name} ...", file=sys.stderr)
            peers[name] = sippy_grid(name, est, val)
            with open(args.peers_cache, "w") as fh:
                json.dump(peers, fh, indent=1)
        results[name] = subid_defaults(est, val)
        print(name, {k: round(v["fit"], 1) for k, v in results[name].items()}, file=sys.stderr)
    lines = [
        "# Default calls on real data against SIPPY's best order",
        "",
        f"Command: `make bench-realdata` (`python bench/realdata.py`). Each DaISy record: first "
        "2/3 to estimate (means removed), last 1/3 to validate; simulation fit (%, mean over "
        "outputs, x0 by least squares on the validation part), the same code for every model. "
        "subid: the default call `method(estimation_data)`, no options. SIPPY (sippy-unipi): "
        "best of N4SID, MOESP and CVA at orders 1..10 and horizons 10 and 20, chosen on the "
        "validation data (an oracle no user has). A subid entry is bold when it is within "
        f"{TOLERANCE:g} points of that oracle; `shift`/`states` is the estimate of the "
        "system matrices the cross-validation chose (`system_matrices='auto'`).",
        "",
        "| record | SIPPY best (method/order/horizon) | ls_subspace | moesp | n4sid | arx | "
        "oe |",
        "|---|---|---|---|---|---|---|",
    ]
    met = {k: 0 for k in ("ls_subspace", "moesp", "n4sid", "arx", "oe")}
    for name in sets:
        grid = {k: v for k, v in peers.get(name, {}).items() if v is not None}
        best_key = max(grid, key=grid.get) if grid else None
        best = grid[best_key] if best_key else None
        cells = []
        for label, row in results[name].items():
            how = f", {row['system_matrices']}" if row.get("system_matrices") else ""
            text = f"{row['fit']:.1f} (n={row['order']}, f={row['horizon']}{how})"
            if best is not None and row["fit"] >= best - TOLERANCE:
                text = f"**{text}**"
                met[label] += 1
            cells.append(text)
        peer = f"{best:.1f} ({best_key})" if best_key else "not run"
        lines.append(f"| {name} | {peer} | " + " | ".join(cells) + " |")
    lines += ["", "Within 3 points of SIPPY's oracle: " + ", ".join(
        f"{k} {v}/{len(sets)}" for k, v in met.items()), ""]
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines))
    with open(os.path.splitext(args.out)[0] + ".json", "w") as fh:
        json.dump(results, fh, indent=1)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
