"""Default calls on real data against SIPPY and least-squares ARX at their best orders.

For each bundled DaISy record except dryer2 and powerplant: the first 2/3
estimate (their means removed, from both parts), the last 1/3 validates.
Every model, subid's and SIPPY's, is scored by the same code: simulation
fit (NRMSE %, mean over outputs) with the initial state fitted by least
squares on the validation part (:func:`subid.fit_percent`).

* subid: the DEFAULT call of each method, ``method(estimation_data)``, and
  ``subid.identify(estimation_data)`` (estimator, order, feedthrough and
  refinement chosen on the estimation data).
* ARX: plain least squares, ``y(k) = sum_i A_i y(k-i) + sum_j B_j u(k-nk-j)``
  with na = nb = 1..10 and delay nk = 0 or 1, every output on all past
  outputs and inputs; its best validation fit is an oracle too.
* SIPPY (``sippy-unipi``, installed by ``make bench-realdata`` in the
  benchmark's own environment, never a dependency of subid): N4SID, MOESP
  and CVA at orders 1..10 and horizons 10 and 20; its best fit over that
  grid is an oracle (chosen on the validation data).

Usage::

    python bench/realdata.py --out bench/realdata.md [--peers-cache bench/realdata_peers.json]
    python bench/realdata.py --from-json     # redraw the table from bench/realdata.json
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


def arx_model(est, na, nk):
    """Least-squares ARX (na = nb, delay nk) as a (non-minimal) StateSpace.

    State ``x(k) = [y(k-1..k-na), u(k-1..k-nb)]``; ``y(k) = C x(k) + D u(k)``
    with ``D = B_0`` when nk = 0.
    """
    import subid
    u, y = est.u, est.y
    nu, ny = u.shape[1], y.shape[1]
    nb = na
    lags_u = list(range(nk, nk + nb))          # u(k - j), j = nk .. nk + nb - 1
    start = max(na, lags_u[-1])
    rows = []
    for k in range(start, est.n_samples):
        rows.append(np.concatenate([y[k - i] for i in range(1, na + 1)]
                                   + [u[k - j] for j in lags_u]))
    Phi = np.array(rows)
    theta = np.linalg.lstsq(Phi, y[start:], rcond=None)[0].T     # (ny, na ny + nb nu)
    Ay = theta[:, :na * ny]
    Bu = theta[:, na * ny:]
    # state: y(k-1..k-na) (na ny), u(k-1..k-m) (m nu) with m = largest input lag
    m = lags_u[-1]
    n = na * ny + m * nu
    C = np.zeros((ny, n))
    D = np.zeros((ny, nu))
    C[:, :na * ny] = Ay
    for idx, j in enumerate(lags_u):
        block = Bu[:, idx * nu:(idx + 1) * nu]
        if j == 0:
            D = block
        else:
            C[:, na * ny + (j - 1) * nu:na * ny + j * nu] = block
    A = np.zeros((n, n))
    B = np.zeros((n, nu))
    A[:ny] = C                                   # new y(k-1) slot <- y(k)
    B[:ny] = D
    A[ny:na * ny, :(na - 1) * ny] = np.eye((na - 1) * ny)
    if m:
        B[na * ny:na * ny + nu] = np.eye(nu)     # new u(k-1) slot <- u(k)
        A[na * ny + nu:, na * ny:n - nu] = np.eye((m - 1) * nu)
    return subid.StateSpace(A, B, C, D, est.dt)


def arx_grid(est, val) -> dict:
    """ARX fit for every (order, delay)."""
    out = {}
    for na in ORDERS:
        for nk in (0, 1):
            try:
                out[f"ARX/{na}/nk={nk}"] = score(arx_model(est, na, nk), val)
            except Exception as exc:  # noqa: BLE001 - a failure is a table entry
                out[f"ARX/{na}/nk={nk}"] = None
                print(f"  ARX {na}/{nk}: {type(exc).__name__}: {exc}"[:200], file=sys.stderr)
    return out


def subid_defaults(est, val) -> dict:
    import subid
    rows = {}
    for label, method in (("ls_subspace", subid.ls_subspace), ("moesp", subid.moesp),
                          ("n4sid", subid.n4sid), ("arx", subid.arx), ("oe", subid.oe),
                          ("identify", subid.identify)):
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = method(est)
        seconds = time.perf_counter() - start
        if label == "identify":
            ident = model.info["identify"]
            rows[label] = {"estimator": ident.get("estimator"),
                           "refined": bool(ident.get("refinement", {}).get("kept"))}
        rows.setdefault(label, {})
        rows[label].update({"fit": score(model, val), "order": model.order,
                       "horizon": model.info.get("horizon"), "seconds": seconds,
                       "system_matrices": model.info.get("system_matrices"),
                       "stable": bool(model.is_stable()),
                       "stability": model.info.get("stability", {}).get("action")
                       if isinstance(model.info.get("stability"), dict) else None,
                       "feedthrough": bool(np.any(model.D != 0)),
                       "warnings": sorted({type(w.message).__name__ for w in caught})})
    return rows


def render(sets, results, peers) -> list:
    """The Markdown table of ``results`` (subid's rows and the ARX grid, per record)
    and ``peers`` (SIPPY's grid, per record)."""
    lines = [
        "# Default calls on real data against SIPPY's and ARX's best orders",
        "",
        "Command: `make bench-realdata` (`python bench/realdata.py`; `--from-json` redraws "
        "this table from bench/realdata.json and the SIPPY cache). Each DaISy record: first "
        "2/3 to estimate (means removed), last 1/3 to validate; simulation fit (%, mean over "
        "outputs, x0 by least squares on the validation part), the same code for every model. "
        "subid: the default call `method(estimation_data)`, no options. SIPPY (sippy-unipi): "
        "best of N4SID, MOESP and CVA at orders 1..10 and horizons 10 and 20, chosen on the "
        "validation data (an oracle no user has). ARX: plain least squares, na = nb = "
        "1..10, delay 0 or 1, best on the validation data (an oracle too). `oracle`: the "
        "better of the two. A method's default is bold when it is within "
        f"{TOLERANCE:g} points of the oracle, `identify` when it is within 1 point "
        "(issue 21); `shift`/`states` is the estimate of the system matrices "
        "`system_matrices='auto'` kept (the better fit to the estimation data at the chosen "
        "order and horizon), `D` a model with a direct term "
        "(`feedthrough='auto'` found one), `+pem` a refinement `identify` kept.",
        "",
        "| record | SIPPY best (method/order/horizon) | ARX best | oracle | ls_subspace | "
        "moesp | n4sid | arx | oe | identify |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    labels = ("ls_subspace", "moesp", "n4sid", "arx", "oe", "identify")
    met = {k: 0 for k in labels}
    for name in sets:
        grid = {k: v for k, v in peers.get(name, {}).items() if v is not None}
        best_key = max(grid, key=grid.get) if grid else None
        best = grid[best_key] if best_key else None
        arx = {k: v for k, v in results[name]["_arx"].items() if v is not None}
        arx_key = max(arx, key=arx.get) if arx else None
        arx_best = arx[arx_key] if arx_key else None
        both = max(v for v in (best, arx_best) if v is not None) \
            if (best, arx_best) != (None, None) else None
        cells = []
        for label in labels:
            row = results[name][label]
            how = f", {row['system_matrices']}" if row.get("system_matrices") else ""
            how += ", D" if row.get("feedthrough") else ""
            how += f", {row['estimator']}" if row.get("estimator") else ""
            how += ", +pem" if row.get("refined") else ""
            text = f"{row['fit']:.1f} (n={row['order']}, f={row['horizon']}{how})"
            margin = 1.0 if label == "identify" else TOLERANCE
            if both is not None and row["fit"] >= both - margin:
                text = f"**{text}**"
                met[label] += 1
            cells.append(text)
        peer = f"{best:.1f} ({best_key})" if best_key else "not run"
        arx_text = f"{arx_best:.1f} ({arx_key})" if arx_key else "not run"
        oracle = f"{both:.1f}" if both is not None else "-"
        lines.append(f"| {name} | {peer} | {arx_text} | {oracle} | " + " | ".join(cells) + " |")
    lines += ["", f"Within {TOLERANCE:g} points of the oracle: " + ", ".join(
        f"{k} {met[k]}/{len(sets)}" for k in labels[:5])
        + f"; identify within 1 point of the oracle: {met['identify']}/{len(sets)}.", ""]
    lines += ["Wall seconds of each default call on the estimation part (this run, one process "
              "after the numba kernels were loaded by `python -m subid.warmup`; the first "
              "record's calls include loading them; a shared 2-core machine):", "",
              "| record | " + " | ".join(labels) + " |",
              "|---|" + "---:|" * len(labels)]
    for name in sets:
        lines.append(f"| {name} | " + " | ".join(
            f"{results[name][label]['seconds']:.2f}" for label in labels) + " |")
    lines.append("")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="bench/realdata.md")
    parser.add_argument("--peers-cache", default="bench/realdata_peers.json",
                        help="JSON cache of SIPPY's grid (recomputed when missing)")
    parser.add_argument("--sets", default=",".join(SETS))
    parser.add_argument("--from-json", action="store_true",
                        help="redraw the table from the results JSON next to --out and the "
                             "SIPPY cache, without fitting anything")
    args = parser.parse_args(argv)
    sets = args.sets.split(",")
    results_path = os.path.splitext(args.out)[0] + ".json"
    peers = {}
    if os.path.exists(args.peers_cache):
        with open(args.peers_cache) as fh:
            peers = json.load(fh)
    if args.from_json:
        with open(results_path) as fh:
            results = json.load(fh)
    else:
        results = run(sets, peers, args.peers_cache)
        with open(results_path, "w") as fh:
            json.dump(results, fh, indent=1)
    lines = render(sets, results, peers)
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines))
    print("\n".join(lines))
    return 0


def run(sets, peers, peers_cache) -> dict:
    """Every record's subid rows and ARX grid (SIPPY's grid added to ``peers`` and its
    cache where missing)."""
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
            with open(peers_cache, "w") as fh:
                json.dump(peers, fh, indent=1)
        arx = arx_grid(est, val)
        results[name] = subid_defaults(est, val)
        results[name]["_arx"] = arx
        print(name, {k: round(v["fit"], 1) for k, v in results[name].items()
                     if not k.startswith("_")}, file=sys.stderr)
    return results


if __name__ == "__main__":
    sys.exit(main())
