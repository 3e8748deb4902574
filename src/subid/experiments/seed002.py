"""Reproduction of seed 002, Section V (Yu, Chen, Ljung, Verhaegen, CDC 2017).

The paper's 4th-order system G(s), a Gaussian input interpolated by a
first-order hold, sampling period Ts = 0.005 s, N = 8 basis functions,
Takenaka-Malmquist poles {4, 12, ..., 60} (which are the Legendre poles
sigma (m + 1/2) with sigma = 8) against Laguerre bases with the single pole
4, 28 or 60, local cubic interpolation (p = 3). The system runs from rest
``warmup`` seconds before the record, so the record starts from a non-zero
state, and the output is sampled at ``t_k = k Ts``, k = 1..L.

Writes to the output folder:

* ``fig3_bode.png`` — Bode plot of the true and identified systems, L = 400
  (the paper's Fig. 3), our method and the paper's printed method;
* ``fig4_error.png`` — ``|G(jw) - G_hat(jw)|`` (the paper's Fig. 4);
* ``table.md`` and ``results.json`` — the median over runs of
  ``max_w |G - G_hat|`` on ``w = logspace(-2, 2)`` for L = 400, 4000, 40000,
  uniform noise-free, jittered sampling (``t_k = k Ts + U(-0.4, 0.4) Ts``)
  and 20 dB output noise; how often the TM basis beats each Laguerre basis;
  and the bias of the mean estimate under noise.

Run ``python -m subid.experiments.seed002 --out results/seed002``.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
import warnings

import numpy as np
import scipy.signal

from subid._progress import on_terminal, progress_wrapper
from subid.data import IOData
from subid.errors import SubidError
from subid.io._files import save_figure, write_bytes, write_json
from subid.methods.ct.basis import laguerre, takenaka_malmquist
from subid.methods.ct.ct_subspace import ct_subspace, ct_subspace_paper, dt_to_ct
from subid.model.statespace import StateSpace

log = logging.getLogger(__name__)

NUMERATOR = [-0.8471, 0.9081, -5.972, 5.519]
DENOMINATOR = [1.0, 3.115, 5.036, 4.577, 2.254]
TS = 0.005
ORDER = 4
TM_POLES = [4.0, 12.0, 20.0, 28.0, 36.0, 44.0, 52.0, 60.0]
LAGUERRE_POLES = (4.0, 28.0, 60.0)
N_BASIS = 8
FREQUENCIES = np.logspace(-2, 2, 200)
BIAS_FREQUENCIES = np.array([0.1, 0.5, 1.0, 2.0, 5.0])


def paper_system() -> StateSpace:
    """The paper's G(s) (Section V) as a continuous-time state-space model."""
    A, B, C, D = scipy.signal.tf2ss(NUMERATOR, DENOMINATOR)
    return StateSpace(A, B, C, D, 0.0)


def simulate(n_samples: int, seed, *, ts: float = TS, jitter: float = 0.0, snr_db=None,
             warmup: float = 10.0, system: StateSpace | None = None,
             return_state: bool = False, noise_pole: float = 0.0):
    """Sampled data of the paper's experiment.

    Parameters
    ----------
    n_samples : int
        Record length L.
    seed : int
        Seed of the input, jitter and noise draws.
    ts : float
        Nominal sampling period.
    jitter : float
        Sampling instants ``t_k = k ts + U(-jitter, jitter) ts``.
    snr_db : float, optional
        Gaussian output noise, its standard deviation the output's divided
        by ``10^(snr_db / 20)``.
    warmup : float
        The system starts at rest this long before the first sample (so the
        record starts from a random, non-zero state).
    system : StateSpace, optional
        Default :func:`paper_system`.
    return_state : bool
        Also return the state at every sample.
    noise_pole : float
        The output noise is AR(1), ``v_k = noise_pole v_{k-1} + e_k`` in
        sample steps, started stationary (0: white).

    Returns
    -------
    data : IOData
        Input and (noisy) output samples with their time stamps.
    y_clean : ndarray
        Noise-free output samples.
    x : ndarray
        State at every sample (with ``return_state=True``).
    """
    system = paper_system() if system is None else system
    rng = np.random.default_rng(seed)
    n_warm = int(round(warmup / ts))
    k = np.arange(1 - n_warm, n_samples + 1, dtype=float)
    t = k * ts
    if jitter:
        t = t + rng.uniform(-jitter, jitter, t.size) * ts
    u = rng.standard_normal((t.size, system.n_inputs))
    y, x = system.simulate(u, t=t, hold="foh", return_state=True)
    t, u, y, x = t[n_warm:], u[n_warm:], y[n_warm:], x[n_warm:]
    y_noisy = y
    if snr_db is not None:
        v = rng.standard_normal(y.shape)
        if noise_pole:
            v[0] /= np.sqrt(1.0 - noise_pole ** 2)          # stationary start
            v = scipy.signal.lfilter([1.0], [1.0, -noise_pole], v, axis=0)
            v *= np.sqrt(1.0 - noise_pole ** 2)              # unit variance
        y_noisy = y + v * y.std(axis=0) * 10 ** (-snr_db / 20)
    data = IOData(u, y_noisy, t=t)
    return (data, y, x) if return_state else (data, y)


def tm_basis():
    return takenaka_malmquist(TM_POLES)


def laguerre_basis(pole):
    return laguerre(pole, N_BASIS)


def methods():
    """Name -> (function(data) -> model, works on non-uniform grids)."""
    out = {
        "ours, default (default basis, refined)": (lambda d: ct_subspace(d, ORDER), True),
        "ours, default basis, subspace only": (
            lambda d: ct_subspace(d, ORDER, refine=False), True),
        "ours, TM {4..60}": (lambda d: ct_subspace(d, ORDER, basis=tm_basis(), refine=False), True),
    }
    for pole in LAGUERRE_POLES:
        out[f"ours, Laguerre {pole:g}"] = (
            lambda d, pole=pole: ct_subspace(d, ORDER, basis=laguerre_basis(pole),
                                             refine=False), True)
    out["paper (6)-(15), TM {4..60}"] = (
        lambda d: ct_subspace_paper(d, ORDER, basis=tm_basis()), True)
    for pole in LAGUERRE_POLES:
        out[f"paper (6)-(15), Laguerre {pole:g}"] = (
            lambda d, pole=pole: ct_subspace_paper(d, ORDER, basis=laguerre_basis(pole)), True)
    out["n4sid -> CT (foh)"] = (lambda d: dt_to_ct(d, ORDER, method="n4sid", hold="foh"), False)
    return out


def response_error(model, true_response):
    """``G_hat(jw) - G(jw)`` on :data:`FREQUENCIES` (NaN if the model is unusable)."""
    try:
        return model.freqresp(FREQUENCIES)[:, 0, 0] - true_response
    except SubidError:
        return np.full(FREQUENCIES.size, np.nan + 0j)


CONDITIONS = {
    "uniform, noise-free": dict(jitter=0.0, snr_db=None),
    "jittered +-40% Ts, noise-free": dict(jitter=0.4, snr_db=None),
    "uniform, 20 dB output noise": dict(jitter=0.0, snr_db=20.0),
}


def run(lengths=(400, 4000, 40000), runs: int = 20, runs_large: int = 3, seed: int = 0,
        progress=None, conditions=None):
    """Run every method on every condition and record length.

    Returns
    -------
    dict
        ``results[condition][L][method]`` = dict with ``max_error`` (list
        over runs, NaN for failures) and ``bias`` (complex mean error and
        standard errors at :data:`BIAS_FREQUENCIES`).
    """
    true = paper_system()
    g_true = true.freqresp(FREQUENCIES)[:, 0, 0]
    g_bias = true.freqresp(BIAS_FREQUENCIES)[:, 0, 0]
    table = methods()
    conditions = CONDITIONS if conditions is None else conditions
    jobs = [(c, L, r) for c in conditions for L in lengths
            for r in range(runs if L < 40000 else runs_large)]
    iterator = jobs if progress is None else progress(jobs)
    raw: dict = {}
    for cond, L, r in iterator:
        data, _ = simulate(L, seed + r, **conditions[cond])
        for name, (fn, nonuniform) in table.items():
            if not data.is_uniform and not nonuniform:
                continue
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():     # the baseline warns on unstable fits
                    warnings.simplefilter("ignore")
                    model = fn(data)
                err = response_error(model, g_true)
                eb = model.freqresp(BIAS_FREQUENCIES)[:, 0, 0] - g_bias
            except SubidError as exc:
                log.info("%s failed on %s L=%d run %d: %s", name, cond, L, r, exc)
                err = np.full(FREQUENCIES.size, np.nan + 0j)
                eb = np.full(BIAS_FREQUENCIES.size, np.nan + 0j)
            entry = raw.setdefault(cond, {}).setdefault(L, {}).setdefault(
                name, {"max_error": [], "bias_errors": [], "seconds": []})
            entry["max_error"].append(float(np.abs(err).max()))
            entry["bias_errors"].append(eb)
            entry["seconds"].append(time.perf_counter() - t0)
    return raw


ABLATIONS: dict[str, dict | None] = {
    "ours (all corrections; subspace only)": {},
    "- without interpolation-correction regressors": {"correction": False},
    "- without start-up regressors": {"startup": False},
    "- B by (15) instead of the raw-sample fit": {"bd_method": "filtered"},
    "- filtering by S1-S4 (re-interpolating each section)": {"filtering": "sections"},
    "- the paper's stacked input (6)": {"data_equation": "paper"},
    "- A, C by (12)-(14)": {"ac_method": "paper"},
    "- input interpolated like the output (hold unknown)": {"hold": None},
    "- no instruments": {"instruments": None},
    "paper's printed method (all of the above)": None,
}


def ablation(cases=((400, None, "tm"), (4000, 20.0, "default")), runs: int = 20,
             seed: int = 0):
    """Median max |G - G_hat| with one of our corrections undone at a time.

    ``cases`` are (L, snr_db or None, 'tm' or 'default' basis). Returns
    ``{case: {variant: [max errors]}}``.
    """
    from subid.methods.ct.basis import default_basis
    true = paper_system()
    g_true = true.freqresp(FREQUENCIES)[:, 0, 0]
    out: dict = {}
    for case in cases:
        L, snr, which = case
        res = out.setdefault(case, {k: [] for k in ABLATIONS})
        for r in range(runs):
            data, _ = simulate(L, seed + r, snr_db=snr)
            bank = tm_basis() if which == "tm" else default_basis(data.t)
            for name, options in ABLATIONS.items():
                try:
                    if options is None:
                        model = ct_subspace_paper(data, ORDER, basis=bank)
                    else:
                        model = ct_subspace(data, ORDER, basis=bank, refine=False, **options)
                    err = float(np.abs(response_error(model, g_true)).max())
                except SubidError:
                    err = float("nan")
                res[name].append(err)
    return out


def _error_row(results, cases, name) -> str:
    """Table row: median [90th percentile] of ``name``'s errors in each case (NaN: inf)."""
    cells = []
    for case in cases:
        v = np.nan_to_num(np.array(results[case][name]), nan=np.inf)
        cells.append(f"{np.median(v):.2e} [{np.percentile(v, 90, method='higher'):.2e}]")
    return f"| {name} | " + " | ".join(cells) + " |"


def ablation_table(abl) -> str:
    cases = list(abl)
    lines = ["\n**Ablation** (subspace estimate, no refinement): median [90th percentile] of "
             "max_w |G - G_hat| with one of our corrections undone\n",
             "| variant | " + " | ".join(
                 f"L = {L}, {'noise-free' if snr is None else f'{snr:g} dB'}, "
                 f"{'TM {4..60}' if which == 'tm' else 'default basis'}"
                 for L, snr, which in cases) + " |", "|---|" + "---:|" * len(cases)]
    lines += [_error_row(abl, cases, name) for name in ABLATIONS]
    return "\n".join(lines)


def basis_choices(data):
    """Bases compared for the default: ours, the paper's suggestion, the TM example."""
    from subid.methods.ct.basis import default_basis, legendre
    h = float(np.mean(np.diff(data.t)))
    return {
        "default (log-spaced, 4 pi/T .. w_N/4)": default_basis(data.t),
        "Legendre up to 1/Ts (paper, Sec. III)": legendre(1.0 / h / (N_BASIS - 0.5), N_BASIS),
        "Legendre up to w_N = pi/Ts": legendre(np.pi / h / (N_BASIS - 0.5), N_BASIS),
        "TM {4..60} (= Legendre, sigma = 8)": tm_basis(),
    }


def basis_study(cases=((400, None), (4000, 20.0)), runs: int = 20, seed: int = 0):
    """Median max |G - G_hat| of the subspace estimate for the candidate default bases."""
    true = paper_system()
    g_true = true.freqresp(FREQUENCIES)[:, 0, 0]
    out: dict = {}
    for L, snr in cases:
        res = out.setdefault((L, snr), {})
        for r in range(runs):
            data, _ = simulate(L, seed + r, snr_db=snr)
            for name, bank in basis_choices(data).items():
                try:
                    model = ct_subspace(data, ORDER, basis=bank, refine=False)
                    err = float(np.abs(response_error(model, g_true)).max())
                except SubidError:
                    err = float("nan")
                res.setdefault(name, []).append(err)
    return out


def basis_table(study) -> str:
    cases = list(study)
    lines = ["\n**Choice of the default basis** (subspace estimate, no refinement): median "
             "[90th percentile] of max_w |G - G_hat|\n",
             "| basis | " + " | ".join(f"L = {L}, {'noise-free' if snr is None else f'{snr:g} dB'}"
                                       for L, snr in cases) + " |",
             "|---|" + "---:|" * len(cases)]
    lines += [_error_row(study, cases, name) for name in study[cases[0]]]
    return "\n".join(lines)


def bias_statistics(errors):
    """Mean complex error and its standard error at each bias frequency."""
    E = np.asarray(errors)
    E = E[np.isfinite(E).all(axis=1)]
    if E.shape[0] < 2:
        return None
    mean = E.mean(axis=0)
    se = np.sqrt((E.real.var(axis=0, ddof=1) + E.imag.var(axis=0, ddof=1)) / E.shape[0])
    return mean, se


def wins(raw, L=400, cond="uniform, noise-free", prefix="ours"):
    """Runs in which the TM basis beats each Laguerre basis (smaller max error)."""
    res = raw[cond][L]
    tm = np.array(res[f"{prefix}, TM {{4..60}}"]["max_error"])
    out = {}
    for pole in LAGUERRE_POLES:
        lag = np.array(res[f"{prefix}, Laguerre {pole:g}"]["max_error"])
        out[pole] = (int(np.sum(np.nan_to_num(tm, nan=np.inf) < np.nan_to_num(lag, nan=np.inf))),
                     int(tm.size))
    return out


def summary_table(raw) -> str:
    """Markdown tables of the median (and 90th percentile) of max |G - G_hat|."""
    lines = []
    for cond, by_length in raw.items():
        lengths = sorted(by_length)
        lines.append(f"\n**{cond}** — median [90th percentile] of max_w |G - G_hat| over runs "
                     "(failures counted as infinite)\n")
        runs = {L: len(next(iter(by_length[L].values()))["max_error"]) for L in lengths}
        lines.append("| method | " + " | ".join(f"L = {L} ({runs[L]} runs)" for L in lengths)
                     + " |")
        lines.append("|---|" + "---:|" * len(lengths))
        names = []
        for L in lengths:
            names += [k for k in by_length[L] if k not in names]
        for name in names:
            cells = []
            for L in lengths:
                entry = by_length[L].get(name)
                if entry is None:
                    cells.append("n/a")
                    continue
                v = np.nan_to_num(np.array(entry["max_error"]), nan=np.inf)
                cells.append(f"{np.median(v):.2e} [{np.percentile(v, 90, method='higher'):.2e}]")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def bias_table(raw, cond="uniform, 20 dB output noise") -> str:
    if cond not in raw:
        return ""
    lines = [f"\n**Bias under 20 dB output noise**: |mean(G_hat - G)| / standard error of "
             f"the mean, at w = {', '.join(f'{w:g}' for w in BIAS_FREQUENCIES)} rad/s "
             "(values above 2 are significant)\n",
             "| method | L | " + " | ".join(f"w = {w:g}" for w in BIAS_FREQUENCIES) + " |",
             "|---|---:|" + "---:|" * BIAS_FREQUENCIES.size]
    for L in sorted(raw[cond]):
        for name, entry in raw[cond][L].items():
            stats = bias_statistics(entry["bias_errors"])
            if stats is None:
                continue
            mean, se = stats
            lines.append(f"| {name} | {L} | " + " | ".join(f"{z:.1f}" for z in np.abs(mean) / se)
                         + " |")
    return "\n".join(lines)


def wins_table(raw) -> str:
    cond = "uniform, noise-free"
    if cond not in raw:
        return ""
    L = min(raw[cond])
    lines = [f"\n**TM {{4..60}} beats Laguerre** (smaller max |G - G_hat|, uniform, noise-free, "
             f"L = {L})\n", "| method | vs Laguerre 4 | vs Laguerre 28 | vs Laguerre 60 |",
             "|---|---:|---:|---:|"]
    for prefix in ("ours", "paper (6)-(15)"):
        w = wins(raw, L, cond, prefix)
        lines.append(f"| {prefix} | " + " | ".join(f"{a}/{b}" for a, b in w.values()) + " |")
    return "\n".join(lines)


def figures(out_dir, seed: int = 0, n_samples: int = 400):
    """Fig. 3 (Bode) and Fig. 4 (|G - G_hat|) for one record of length ``n_samples``."""
    from subid.evaluation.plot import _pyplot
    plt = _pyplot()
    true = paper_system()
    data, _ = simulate(n_samples, seed)
    w = FREQUENCIES
    g = true.freqresp(w)[:, 0, 0]
    models = {"TM {4..60}": ct_subspace(data, ORDER, basis=tm_basis(), refine=False)}
    for pole in LAGUERRE_POLES:
        models[f"Laguerre {pole:g}"] = ct_subspace(data, ORDER, basis=laguerre_basis(pole),
                                                   refine=False)
    paper = {"TM {4..60}": ct_subspace_paper(data, ORDER, basis=tm_basis())}
    for pole in LAGUERRE_POLES:
        paper[f"Laguerre {pole:g}"] = ct_subspace_paper(data, ORDER, basis=laguerre_basis(pole))
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    for col, (title, group) in enumerate((("ours (corrected, start-up and correction "
                                            "regressors)", models),
                                          ("paper's printed method (typos fixed)", paper))):
        ax_m, ax_p = axes[0, col], axes[1, col]
        ax_m.loglog(w, np.abs(g), "k-", lw=3, alpha=0.35, label="true")
        ax_p.semilogx(w, np.unwrap(np.angle(g)) * 180 / np.pi, "k-", lw=3, alpha=0.35)
        for i, (name, model) in enumerate(group.items()):
            gh = model.freqresp(w)[:, 0, 0]
            ax_m.loglog(w, np.abs(gh), f"C{i}-", lw=1.2, label=name)
            ax_p.semilogx(w, np.unwrap(np.angle(gh)) * 180 / np.pi, f"C{i}-", lw=1.2)
        ax_m.set_title(title, fontsize="medium")
        ax_m.set_ylabel("|G(jw)|")
        ax_p.set_ylabel("phase (deg)")
        ax_p.set_xlabel("w (rad/s)")
        ax_m.legend(fontsize="small")
    fig.suptitle(f"Fig. 3: Bode plots, L = {n_samples}, Ts = {TS} s, p = 3")
    fig.tight_layout()
    save_figure(fig, os.path.join(out_dir, "fig3_bode.png"), dpi=100)
    fig2, axes2 = plt.subplots(1, 2, figsize=(12, 4.2), sharey=True)
    for ax, (title, group) in zip(axes2, (("ours", models), ("paper's printed method", paper))):
        for i, (name, model) in enumerate(group.items()):
            ax.loglog(w, np.abs(model.freqresp(w)[:, 0, 0] - g), f"C{i}-", label=name)
        ax.set_title(title)
        ax.set_xlabel("w (rad/s)")
        ax.legend(fontsize="small")
    axes2[0].set_ylabel("|G(jw) - G_hat(jw)|")
    fig2.suptitle(f"Fig. 4: frequency-response error, L = {n_samples}")
    fig2.tight_layout()
    save_figure(fig2, os.path.join(out_dir, "fig4_error.png"), dpi=100)
    plt.close(fig)
    plt.close(fig2)


def _jsonable(raw):
    out = {}
    for cond, by_length in raw.items():
        out[cond] = {}
        for L, by_method in by_length.items():
            out[cond][str(L)] = {}
            for name, entry in by_method.items():
                stats = bias_statistics(entry["bias_errors"])
                rec = {"max_error": [None if not np.isfinite(v) else v
                                     for v in entry["max_error"]],
                       "seconds": entry["seconds"]}
                if stats is not None:
                    rec["bias_mean"] = [[float(z.real), float(z.imag)] for z in stats[0]]
                    rec["bias_standard_error"] = [float(s) for s in stats[1]]
                out[cond][str(L)][name] = rec
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m subid.experiments.seed002",
        description="Reproduce seed 002, Section V: TM vs Laguerre bases on the paper's system.",
        epilog="example: python -m subid.experiments.seed002 --out results/seed002")
    parser.add_argument("--runs", type=int, default=20,
                        help="runs per cell for L = 400 and 4000 (default 20)")
    parser.add_argument("--runs-large", type=int, default=3,
                        help="runs per cell for L = 40000 (default 3)")
    parser.add_argument("--lengths", type=int, nargs="+", default=[400, 4000, 40000],
                        help="record lengths (default 400 4000 40000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first run")
    parser.add_argument("--out", default="results/seed002", help="output folder")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    progress = progress_wrapper("seed 002", "record", enabled=on_terminal(args.quiet))
    t0 = time.perf_counter()
    raw = run(tuple(args.lengths), args.runs, args.runs_large, args.seed, progress)
    abl = ablation(runs=args.runs, seed=args.seed)
    study = basis_study(runs=args.runs, seed=args.seed)
    elapsed = time.perf_counter() - t0
    header = (f"Seed 002 Section V: G(s) of the paper, FOH Gaussian input, Ts = {TS} s, "
              f"N = {N_BASIS}, p = 3, order {ORDER}; max |G - G_hat| over "
              f"w = logspace(-2, 2, {FREQUENCIES.size}). Run time {elapsed:.0f} s.\n")
    text = (header + summary_table(raw) + "\n" + wins_table(raw) + "\n" + bias_table(raw)
            + "\n" + ablation_table(abl) + "\n" + basis_table(study) + "\n")
    write_bytes(os.path.join(args.out, "table.md"), text)
    write_json(os.path.join(args.out, "results.json"), {"lengths": args.lengths, "runs": args.runs, "runs_large": args.runs_large,
                   "seed": args.seed, "seconds": elapsed, "frequencies": FREQUENCIES.tolist(),
                   "bias_frequencies": BIAS_FREQUENCIES.tolist(),
                   "results": _jsonable(raw),
                   "ablation": {f"L={L}, snr={snr}, basis={which}": {
                       k: [None if not np.isfinite(x) else x for x in v]
                       for k, v in res.items()} for (L, snr, which), res in abl.items()},
                   "basis_study": {f"L={L}, snr={snr}": {
                       k: [None if not np.isfinite(x) else x for x in v]
                       for k, v in res.items()} for (L, snr), res in study.items()}})
    try:
        figures(args.out, args.seed, min(args.lengths))
        figs = ", fig3_bode.png, fig4_error.png"
    except ImportError as exc:
        log.warning("figures skipped: %s", exc)
        figs = ""
    print(text)
    print(f"wrote {args.out}/table.md, results.json{figs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
