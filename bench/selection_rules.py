"""Candidate order-selection rules of issue 21, item 3, measured on the same candidates.

For every Monte Carlo system of bench/selection.py (``random_system(2 + k % 5, 2, 2,
seed=k)``, 20 dB process and output noise, N = 2000 to estimate and 2000 to validate)
and for the DaISy records of bench/realdata.py (first 2/3 to estimate, means removed,
last 1/3 to validate; ``moesp`` and ``n4sid``), ``dump`` keeps the default call's
cross-validation record (the four fold scores of every candidate order x horizon x
estimator), the validation fit of the model refitted to the whole estimation record at
every candidate (``method(est, n, horizon=f, system_matrices=...)``), the order of the
innovation BIC of bench/selection.py, and the innovation BIC of the method's own models
at the horizon and estimator of the cross-validated choice (the cross-validated BIC
alone, before :func:`subid.methods.dt.choice.innovation_check`), every order: from the
innovation
covariance the model carries (``noise_cov``, from the Hankel factor) and from its
one-step prediction errors on the estimation record. ``table`` then applies every
rule to the same fold scores: how often it finds the true order (Monte Carlo), the
median validation fit of the model it picks, and on the records the change of
validation fit against the cross-validated choice (the pick is the rule's candidate
refitted to the whole record; the fallback of ``unrepaired_choice`` is left out for every
rule). The rule marked "the default" is what ``order=None`` does since this benchmark.

``geomean`` reruns the Monte Carlo with the fold score's misfit averaged over the
outputs geometrically (so that ``2 N ny ln misfit`` is the Gaussian log-likelihood of
outputs with their own variances) instead of arithmetically; ``refine`` prints, on a
record, the fold scores of a pinned subspace configuration and of its refinement by
``pem(focus='simulation')`` (what :func:`subid.identify` keeps or not) for a few orders.

Usage::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/selection_rules.py dump --runs 80 \\
        --records ballbeam,winding,CD_player_arm,dryer,evaporator,exchanger,glassfurnace,robot_arm,steamgen
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/selection_rules.py table > bench/selection_rules.md
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/selection_rules.py geomean --runs 80
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/selection_rules.py refine ballbeam 2,3,6,9
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/selection_rules.py cost
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import warnings

import numpy as np

import subid
from subid.methods.crossval import ABSOLUTE_TOLERANCE, select

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from selection import bic_order  # noqa: E402  (bench/selection.py)

DUMP = os.path.join(HERE, "selection_rules.json")


# ----------------------------------------------------------------------------- dump

def _fit(model, val):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            v = float(np.mean(subid.fit_percent(model, val)))
    except subid.errors.SubidError:
        return -math.inf
    return v if math.isfinite(v) else -math.inf


def _options(c):
    out = {"horizon": c["horizon"]}
    if c.get("sm") is not None:
        out["system_matrices"] = c["sm"]
    return out


def _innovation_bic(method, est, today, orders):
    """``{n: (from noise_cov, from one-step errors)}``: ``N ln det Σ + p ln N``,
    ``p = n (nu + 2 ny) + nu ny``, of ``method(est, n, **today's horizon/estimator)``."""
    N, nu, ny = est.n_samples, est.n_inputs, est.n_outputs
    out = {}
    for n in orders:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                m = method(est, n, **_options(today))
                e = est.y - subid.predict(m, est, 1)
        except subid.errors.SubidError:
            continue
        if m.noise_cov is None or not np.all(np.isfinite(e)):
            continue
        p = (n * (nu + 2 * ny) + nu * ny) * math.log(N)
        out[str(n)] = (N * np.linalg.slogdet(m.noise_cov)[1] + p,
                       N * np.linalg.slogdet(e.T @ e / N)[1] + p)
    return out


def dump_case(method, est, val):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = method(est)
    rec = model.info["order_selection"]
    cands = []
    for c in rec["candidates"]:
        entry = {"order": c["order"], "horizon": c["horizon"], "sm": c.get("system_matrices"),
                 "folds": c["folds"], "stabilised_folds": c["stabilised_folds"]}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                entry["val"] = _fit(method(est, c["order"], **_options(entry)), val)
        except subid.errors.SubidError:
            entry["val"] = -math.inf
        cands.append(entry)
    case = {"default_order": model.order, "default_val": _fit(model, val),
            "samples": rec["samples_used"], "nu": est.n_inputs, "ny": est.n_outputs,
            "candidates": cands}
    today = today_rule(case)
    orders = sorted({c["order"] for c in cands if c["horizon"] == today["horizon"]})
    case["innovation"] = _innovation_bic(method, est, today, orders)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        n_bic, m_bic = bic_order(est)
    case.update(bic=n_bic, bic_val=_fit(m_bic, val))
    return case


def _mc_data(k):
    order = 2 + k % 5
    true = subid.systems.random_system(order, 2, 2, seed=k)
    data = subid.systems.simulate_data(true, 4000, seed=1000 + k, process_snr_db=20,
                                       output_snr_db=20)
    return order, data[:2000], data[2000:]


def dump(args):
    out = {}
    if os.path.exists(args.file):
        with open(args.file) as fh:
            out = json.load(fh)

    def save():
        with open(args.file, "w") as fh:
            json.dump(out, fh)

    for k in range(args.first, args.first + args.runs):
        if f"mc{k}" in out:
            continue
        order, est, val = _mc_data(k)
        out[f"mc{k}"] = dict(dump_case(subid.moesp, est, val), true=order)
        print(f"mc{k}", order, out[f"mc{k}"]["default_order"], out[f"mc{k}"]["bic"], flush=True)
        save()
    from realdata import split
    for name in filter(None, args.records.split(",")):
        est, val = split(name)
        for label in ("moesp", "n4sid"):
            key = f"{name}/{label}"
            if key not in out:
                out[key] = dump_case(getattr(subid, label), est, val)
                print(key, out[key]["default_order"], round(out[key]["default_val"], 1),
                      flush=True)
                save()
    return 0


# ----------------------------------------------------------------------------- rules

def _key(c):
    return (c["order"], c["horizon"], c["sm"] or "")


def _params(n, nu, ny):
    return n * (nu + ny) + nu * ny


def today_rule(case):
    """The cross-validated choice (:func:`subid.methods.crossval.select`, the
    cross-validated BIC), before the innovation check of
    :func:`subid.methods.dt.choice.innovation_check` (the rule marked "the default")."""
    keyed = {_key(c): c for c in case["candidates"]}
    best = select({k: c["folds"] for k, c in keyed.items()}, case["samples"], case["nu"],
                  case["ny"])[0]
    return keyed[best]


def cv_ic(case, penalty, aggregate=np.mean):
    """Least ``2 N ny ln(100 - aggregate(folds)) + p penalty(N)``."""
    N, nu, ny = case["samples"], case["nu"], case["ny"]

    def crit(c):
        misfit = max(100.0 - float(aggregate(c["folds"])), ABSOLUTE_TOLERANCE)
        return 2 * N * ny * math.log(misfit) + _params(c["order"], nu, ny) * penalty(N)
    return min(case["candidates"], key=lambda c: (crit(c), _key(c)))


def pooled_variance(case):
    """Misfit as the root mean square over the folds (pooled variance)."""
    return cv_ic(case, math.log,
                 aggregate=lambda f: 100.0 - math.sqrt(np.mean(np.square(100.0 - np.asarray(f)))))


def best_mean(case):
    return max(case["candidates"], key=lambda c: (np.mean(c["folds"]), -c["order"]))


def per_order(case):
    """The candidate of the least criterion (= best mean score) of every order."""
    out = {}
    for c in case["candidates"]:
        n = c["order"]
        if n not in out or np.mean(c["folds"]) > np.mean(out[n]["folds"]):
            out[n] = c
    return out


def _paired_se(a, b):
    d = np.subtract(a, b)
    return float(np.mean(d)), float(np.std(d, ddof=1)) / math.sqrt(d.size)


def one_se(case, paired=True):
    """Smallest order whose best candidate is within one standard error of the best mean
    score: the SE of the paired fold differences, or of the best candidate's folds."""
    top = best_mean(case)
    for _, c in sorted(per_order(case).items()):
        if paired:
            gap, se = _paired_se(top["folds"], c["folds"])
        else:
            gap = np.mean(top["folds"]) - np.mean(c["folds"])
            se = np.std(top["folds"], ddof=1) / math.sqrt(len(top["folds"]))
        if gap <= se + ABSOLUTE_TOLERANCE:
            return c
    return top


def bic_then_up(case, k):
    """Today's choice, replaced by a higher order that scores better on the folds by more
    than k standard errors of the paired differences (repeated)."""
    cur = today_rule(case)
    orders = per_order(case)
    while True:
        better = [c for n, c in orders.items() if n > cur["order"]
                  and _paired_se(c["folds"], cur["folds"])[0]
                  > k * _paired_se(c["folds"], cur["folds"])[1]]
        if not better:
            return cur
        cur = max(better, key=lambda c: np.mean(c["folds"]))


def fold_bic(case):
    """BIC of every fold's misfit with its own validation length, averaged."""
    N, nu, ny = case["samples"], case["nu"], case["ny"]
    lengths = [N // 3, N // 3, N - N // 2, N // 2]

    def crit(c):
        return np.mean([2 * L * ny * math.log(max(100.0 - s, ABSOLUTE_TOLERANCE))
                        + _params(c["order"], nu, ny) * math.log(L)
                        for L, s in zip(lengths, c["folds"])])
    return min(case["candidates"], key=lambda c: (crit(c), _key(c)))


def cv_own_penalty(case):
    """``p (ln N - 1 - mean N / N_train)``: the penalty the held-out misfit already
    carries over the in-sample fit (about ``(1 + N / N_train) p``, Stone 1977) taken
    off Schwarz's ``p ln N``."""
    N = case["samples"]
    excess = 1.0 + np.mean([N / t for t in (N - N // 3, N - N // 3, N // 2, N - N // 2)])
    return cv_ic(case, lambda n: math.log(n) - excess)


def _innovation_order(case, column):
    table = {int(n): v[column] for n, v in case["innovation"].items()}
    return min(table, key=lambda n: (table[n], n)) if table else None


def with_innovation(case, column, how):
    """Today's choice combined with the innovation BIC of the method's own models
    (``column`` 0: Σ from the factor, 1: one-step errors): ``'max'`` the larger of
    the two orders; ``'guarded'`` the innovation BIC's order when it is the higher
    and its mean fold score is not lower; ``'among'`` the least innovation BIC among
    the choice and the higher orders whose mean fold score is not lower; ``'tie'`` the least innovation BIC among the orders whose mean fold
    score is within one paired standard error of today's choice."""
    today = today_rule(case)
    orders = per_order(case)
    table = {int(n): v[column] for n, v in case["innovation"].items()}
    if not table:
        return today
    if how == "max":
        return orders.get(max(today["order"], _innovation_order(case, column)), today)
    if how == "among":
        allowed = [today["order"]] + [n for n, c in orders.items() if n > today["order"]
                                      and np.mean(c["folds"]) >= np.mean(today["folds"])]
        kept = [n for n in allowed if n in table]
        return orders[min(kept, key=lambda n: (table[n], n))] if kept else today
    if how == "guarded":
        other = orders.get(_innovation_order(case, column))
        if other is not None and other["order"] > today["order"] \
                and np.mean(other["folds"]) >= np.mean(today["folds"]):
            return other
        return today
    tied = [today["order"]] + [n for n, c in orders.items() if n != today["order"]
                               and abs(_paired_se(c["folds"], today["folds"])[0])
                               <= _paired_se(c["folds"], today["folds"])[1]]
    return orders[min((n for n in tied if n in table), key=lambda n: table[n],
                      default=today["order"])]


RULES = {
    "cv-BIC, p ln N (the cross-validated choice)": today_rule,
    "cv-IC, 0.5 p ln N": lambda c: cv_ic(c, lambda N: 0.5 * math.log(N)),
    "cv-IC, 0.8 p ln N": lambda c: cv_ic(c, lambda N: 0.8 * math.log(N)),
    "cv-IC, 1.2 p ln N": lambda c: cv_ic(c, lambda N: 1.2 * math.log(N)),
    "cv-IC, 1.5 p ln N": lambda c: cv_ic(c, lambda N: 1.5 * math.log(N)),
    "cv-IC, 2 p ln N": lambda c: cv_ic(c, lambda N: 2 * math.log(N)),
    "cv-AIC, 2 p": lambda c: cv_ic(c, lambda N: 2.0),
    "cv-HQ, 2 p ln ln N": lambda c: cv_ic(c, lambda N: 2 * math.log(math.log(N))),
    "cv-BIC less CV's own penalty, p (ln N - 2.75)": cv_own_penalty,
    "cv-BIC on the median fold": lambda c: cv_ic(c, math.log, aggregate=np.median),
    "cv-BIC on the pooled fold variance": pooled_variance,
    "cv-BIC per fold (own lengths), averaged": fold_bic,
    "best mean fold score": best_mean,
    "one-SE, paired fold differences": one_se,
    "one-SE, the best's fold spread": lambda c: one_se(c, paired=False),
    "cv-BIC, then up while > 1 paired SE better": lambda c: bic_then_up(c, 1.0),
    "cv-BIC, then up while > 2 paired SE better": lambda c: bic_then_up(c, 2.0),
    "innovation BIC (Σ of the factor), own models": lambda c: per_order(c).get(
        _innovation_order(c, 0), today_rule(c)),
    "innovation BIC (one-step errors), own models": lambda c: per_order(c).get(
        _innovation_order(c, 1), today_rule(c)),
    "max(cv-BIC, innovation BIC one-step)": lambda c: with_innovation(c, 1, "max"),
    "max(cv-BIC, innovation BIC Σ)": lambda c: with_innovation(c, 0, "max"),
    "innovation BIC one-step if higher and its mean fold score not lower (the default)":
        lambda c: with_innovation(c, 1, "guarded"),
    "least innovation BIC one-step among the choice and the higher orders scoring no lower":
        lambda c: with_innovation(c, 1, "among"),
    "innovation BIC Σ if higher and its mean fold score not lower":
        lambda c: with_innovation(c, 0, "guarded"),
    "cv-BIC, ties (1 paired SE) to innovation BIC one-step":
        lambda c: with_innovation(c, 1, "tie"),
}


def table(path):
    with open(path) as fh:
        cases = json.load(fh)
    mc = {k: v for k, v in cases.items() if k.startswith("mc")}
    real = {k: v for k, v in cases.items() if not k.startswith("mc")}
    first = [k for k in mc if int(k[2:]) < 40]
    lines = ["# Order-selection rules on the same fold scores (issue 21, item 3)", "",
             "Command: `python bench/selection_rules.py dump --runs 80 --records ...` then "
             "`python bench/selection_rules.py table` (docstring of bench/selection_rules.py). "
             f"Monte Carlo: bench/selection.py's systems, seeds 0..{len(mc) - 1} (the "
             "acceptance uses 0..39), MOESP's default candidates (orders 1..10 x horizons "
             "10, 20 x estimators shift/states, four folds). Every rule picks from the same "
             "fold scores; the pick is refitted to the whole estimation record and "
             "validated on 2000 further samples. `under`/`over`: picks below/above the "
             "true order (all seeds). The candidates are those the cross-validation scores "
             "(`'shift'` only since `system_matrices='auto'` is chosen by fit afterwards), "
             "each refitted with the estimator it was scored with; bench/selection.py, whose "
             "default models take their estimator by fit: 31/40 and 56/80 for the default "
             "(the cross-validated BIC alone: 30/40, 54/80), 31/40 and 57/80 for BIC.", "",
             "| rule | true order, seeds 0..39 | all seeds | under | over | median validation "
             "fit 0..39 | all seeds |", "|---|---|---|---|---|---|---|"]
    def row(name, orders, vals):
        h40 = sum(orders[k] == mc[k]["true"] for k in first)
        hall = sum(orders[k] == mc[k]["true"] for k in mc)
        under = sum(orders[k] < mc[k]["true"] for k in mc)
        over = sum(orders[k] > mc[k]["true"] for k in mc)
        lines.append(f"| {name} | {h40}/{len(first)} | {hall}/{len(mc)} | {under} | {over} | "
                     f"{np.median([vals[k] for k in first]):.2f} | "
                     f"{np.median(list(vals.values())):.2f} |")
    row("innovation BIC of bench/selection.py (n4sid, horizon 10)",
        {k: v["bic"] for k, v in mc.items()}, {k: v["bic_val"] for k, v in mc.items()})
    for name, rule in RULES.items():
        picks = {k: rule(v) for k, v in mc.items()}
        row(name, {k: p["order"] for k, p in picks.items()},
            {k: p["val"] for k, p in picks.items()})
    lines += ["", "The cross-validated choice's misses (all seeds): the fold scores of today's pick and of the true "
              "order's best candidate, the mean gain of the true order over the pick on the "
              "folds with the standard error of the paired fold differences, the gain the "
              "criterion asks for (the misfit factor exp(-Δp ln N / (2 N ny))), and the "
              "difference of validation fit of the two refitted models.", "",
              "| seed | true | cross-validated | bench BIC | pick's folds | true order's folds | fold gain "
              "(SE) | gain asked | validation: true - pick |", "|---|---|---|---|---|---|---|---|---|"]
    for k, v in mc.items():
        pick, true = today_rule(v), per_order(v).get(v["true"])
        if pick["order"] == v["true"] or true is None:
            continue
        gain, se = _paired_se(true["folds"], pick["folds"])
        N, nu, ny = v["samples"], v["nu"], v["ny"]
        dp = _params(true["order"], nu, ny) - _params(pick["order"], nu, ny)
        asked = (100.0 - np.mean(pick["folds"])) * (1.0 - math.exp(-dp * math.log(N)
                                                                   / (2 * N * ny)))
        lines.append(f"| {k[2:]} | {v['true']} | {pick['order']} | {v['bic']} | "
                     f"{' '.join(f'{s:.2f}' for s in pick['folds'])} | "
                     f"{' '.join(f'{s:.2f}' for s in true['folds'])} | {gain:+.3f} ({se:.3f}) | "
                     f"{asked:+.3f} | {true['val'] - pick['val']:+.3f} |")
    if real:
        names = sorted(real, key=str.lower)
        lines += ["", "DaISy records (bench/realdata.py's split): validation fit of the "
                  "cross-validated choice (order), and every other rule's change against it in points "
                  "(order); worst loss in the last column.", "",
                  "| rule | " + " | ".join(names) + " | worst |",
                  "|---|" + "---|" * (len(names) + 1)]
        for name, rule in RULES.items():
            cells, worst = [], 0.0
            for k in names:
                base, c = today_rule(real[k]), rule(real[k])
                if rule is today_rule:
                    cells.append(f"{base['val']:.1f} ({base['order']})")
                else:
                    delta = c["val"] - base["val"]
                    worst = min(worst, delta)
                    cells.append(f"{delta:+.1f} ({c['order']})")
            lines.append(f"| {name} | " + " | ".join(cells)
                         + f" | {'' if rule is today_rule else f'{worst:+.1f}'} |")
    print("\n".join(lines))
    return 0


# ----------------------------------------------------------------------------- others

def geomean(args):
    """bench/selection.py's Monte Carlo with the fold misfit averaged geometrically over
    the outputs (patched into the selection's fold score)."""
    import subid.methods.dt.selection as selection
    from subid.methods.crossval import FLOOR
    from subid.methods.dt._scoring import simulation_fit

    def score(model, validation):
        fits = simulation_fit(model.A, model.B, model.C, model.D, validation)
        if fits is None:
            return FLOOR
        misfit = np.maximum(100.0 - np.asarray(fits, float), ABSOLUTE_TOLERANCE)
        value = 100.0 - float(np.exp(np.mean(np.log(misfit))))
        return max(value, FLOOR) if math.isfinite(value) else FLOOR

    selection._fit_score = score
    hits, fits = [], []
    for k in range(args.first, args.first + args.runs):
        order, est, val = _mc_data(k)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = subid.moesp(est)
        hits.append(model.order == order)
        fits.append(_fit(model, val))
        print(k, order, model.order, flush=True)
    print(f"true order {sum(hits[:40])}/{min(40, len(hits))} (first 40), "
          f"{sum(hits)}/{len(hits)}; median validation fit {np.median(fits[:40]):.2f}, "
          f"{np.median(fits):.2f}")
    return 0


def refine_check(args):
    """Fold scores of pinned subspace models and of their simulation refinement."""
    from realdata import split
    from subid.methods.identify import _fold_refinement, _refine
    est, val = split(args.record)
    for method, horizon in (("n4sid", 10), ("moesp", 10), ("moesp", 20)):
        for n in map(int, args.orders.split(",")):
            if (horizon - 1) * est.n_outputs < n:
                continue
            config = {"order": n, "horizon": horizon, "feedthrough": False}
            base, refined = _fold_refinement(est, method, config, "simulation")["simulation"]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = getattr(subid, method)(est, n, horizon=horizon, feedthrough=False)
            final = _refine(est, model, "simulation")
            gain, se = _paired_se(refined, base)
            print(f"{method} f={horizon} n={n}: subspace folds {np.round(base, 1).tolist()}, "
                  f"refined {np.round(refined, 1).tolist()} (gain {gain:.2f}, SE {se:.2f}); "
                  f"stable {model.is_stable()}; validation {_fit(model, val):.1f}, refined "
                  + ("not refinable" if final is None else f"{_fit(final, val):.1f}"))
    return 0


def cost(args):
    """CPU time of ``moesp(data)`` with and without the innovation check (interleaved,
    medians of three rounds; 2x2 order-4 system, 20 dB output noise)."""
    import statistics
    import time

    import subid.methods.dt.choice as choice
    check = choice.innovation_check
    true = subid.systems.random_system(4, 2, 2, seed=3)
    for n_samples in (1000, 10000, 100000):
        data = subid.systems.simulate_data(true, n_samples, seed=1, output_snr_db=20)
        times = {True: [], False: []}
        for _ in range(3):
            for on in (True, False):
                choice.innovation_check = check if on else (lambda d, r, f, c: c)
                start = time.process_time()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    subid.moesp(data)
                times[on].append(time.process_time() - start)
        choice.innovation_check = check
        with_, without = statistics.median(times[True]), statistics.median(times[False])
        print(f"N = {n_samples}: with {with_:.3f} s, without {without:.3f} s, "
              f"ratio {with_ / without:.2f}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("--runs", type=int, default=80)
    d.add_argument("--first", type=int, default=0)
    d.add_argument("--records", default="")
    d.add_argument("--file", default=DUMP)
    t = sub.add_parser("table")
    t.add_argument("--file", default=DUMP)
    g = sub.add_parser("geomean")
    g.add_argument("--runs", type=int, default=80)
    g.add_argument("--first", type=int, default=0)
    sub.add_parser("cost")
    r = sub.add_parser("refine")
    r.add_argument("record")
    r.add_argument("orders")
    args = parser.parse_args(argv)
    if args.cmd == "dump":
        return dump(args)
    if args.cmd == "table":
        return table(args.file)
    if args.cmd == "geomean":
        return geomean(args)
    if args.cmd == "cost":
        return cost(args)
    return refine_check(args)


if __name__ == "__main__":
    raise SystemExit(main())
