"""Reproduction of seed 000, Section V (Afri, Bako, Andrieu, Dufour).

The paper's 4-state, 2-input, 2-output continuous-time system, sampled every
1 ms, driven by a smooth multisine (:func:`multisine`), identified online by
:class:`subid.methods.online.adaptive.AdaptiveIdentifier` (horizon 5, filter poles at -5,
random selector H). As in the paper: α = 0.4, β = 0.08 without noise
(Figs. 1-3) and α = 0.01, β = 0.008 with output noise at 50 dB (Fig. 4).
Writes to the output folder:

* ``fig1_eigenvalues.png`` — eigenvalues of Ã against those of A (Fig. 1),
* ``fig2_bode.png`` — Bode magnitude and phase, output 1 / input 1 (Fig. 2),
* ``fig3_error_noise_free.png`` — ε_r of Õ_f B̃ without noise, with the
  paper's ODE form (11)-(12), (19)-(20) for comparison (Fig. 3),
* ``fig4_error_50db.png`` — ε_r with output noise at 50 dB (Fig. 4),
* ``table.md`` and ``results.json`` — time to convergence, final errors,
  condition numbers of the regression with unscaled and scaled filter states.

Run ``python -m subid.experiments.seed000 --out results/seed000``. Issue 12
and 23 studies (each instead of the above): ``--noise-table`` (ε_r over SNR,
paper's LS against the default), ``--noise-free-table`` (convergence of the
default without noise), ``--memory-study`` (consistency: ε_r as memory and
record grow together, bias against its standard error), ``--startup-study``
(ε_r along 400 s at 40 dB with and without the start-up schedule of the
(B, D) memory).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import time
import warnings

import numpy as np
from scipy.optimize import linear_sum_assignment

from subid._progress import on_terminal, progress_wrapper
from subid.evaluation.metrics import pole_error
from subid.io._files import save_figure, write_bytes, write_json
from subid.methods.online.adaptive import AdaptiveIdentifier
from subid.model.statespace import StateSpace
from subid.systems import seed000_system

log = logging.getLogger(__name__)

HORIZON = 5
FILTER_POLE = -5.0
DT = 1e-3


def paper_system() -> StateSpace:
    """The continuous-time system of seed 000, Section V (:func:`subid.systems.seed000_system`)."""
    return seed000_system()


def multisine(t, n_inputs: int, seed=0, n_freq: int = 20, w_min: float = 0.5,
              w_max: float = 20.0) -> np.ndarray:
    """A smooth, sufficiently rich input: sums of sines, unit RMS per channel.

    ``n_freq * n_inputs`` frequencies log-spaced on ``[w_min, w_max]`` rad/s
    are dealt out to the inputs in turn (each input has its own frequencies,
    so the inputs are uncorrelated), with phases uniform from ``seed``. Each
    input is sufficiently rich of order ``2 n_freq`` (Definition 2 up to the
    start-up transient). The band 0.5-20 rad/s covers the paper's system
    (poles from -0.16 to -3.6) without piling power below its slowest mode.

    Returns
    -------
    ndarray, shape (len(t), n_inputs)
    """
    t = np.asarray(t, dtype=np.float64)
    rng = np.random.default_rng(seed)
    freqs = np.geomspace(w_min, w_max, n_freq * n_inputs).reshape(n_freq, n_inputs)
    phases = rng.uniform(0.0, 2.0 * np.pi, size=(n_freq, n_inputs))
    u = np.empty((t.size, n_inputs))
    for j in range(n_inputs):
        u[:, j] = np.sin(np.outer(t, freqs[:, j]) + phases[:, j]).sum(axis=1)
    return u / math.sqrt(n_freq / 2.0)


def white_input(t, n_inputs: int, seed=0) -> np.ndarray:
    """The paper's Section V input: unit-variance white Gaussian noise at the
    sampling instants (held linearly in between by the simulation)."""
    return np.random.default_rng(seed).standard_normal((np.asarray(t).size, n_inputs))


def issue_multisine(t, n_inputs: int, seed=0, n_freq: int = 10, w_min: float = 0.1,
                    w_max: float = 10.0) -> np.ndarray:
    """Issue 12's multisine: ``n_freq`` sines per input log-spaced on
    ``[w_min, w_max]`` rad/s, the same frequencies on every input, random
    phases; unit RMS per channel. Harder than :func:`multisine`: power below
    the slowest mode and coherent inputs."""
    t = np.asarray(t, dtype=np.float64)
    rng = np.random.default_rng(seed)
    w = np.geomspace(w_min, w_max, n_freq)
    ph = rng.uniform(0.0, 2.0 * np.pi, (n_freq, n_inputs))
    u = np.stack([np.sin(np.outer(t, w) + ph[:, j]).sum(axis=1) for j in range(n_inputs)], 1)
    return u / math.sqrt(n_freq / 2.0)


INPUTS = {"white": white_input, "multisine-issue12": issue_multisine,
          "multisine-reproduction": multisine}


def noise_table(snrs=(30, 40, 50, 60, 70, 80), seeds=(1, 2, 3), duration=400.0,
                inputs=("white", "multisine-issue12"), progress=None):
    """ε_r after ``duration`` s over SNRs and noise realisations: the paper's
    estimator (``method='ls'``, the paper's noisy-data α = 0.01, β = 0.008)
    against the instrumental-variable default (``method='iv'``, defaults).

    Returns a dict ``{(input, snr): {"ls": [...], "iv": [...]}}`` of ε_r
    (1.0 where (B, D) never started: B = 0).
    """
    true = paper_system()
    t = np.arange(int(round(duration / DT)) + 1) * DT
    out = {}
    jobs = [(name, snr) for name in inputs for snr in snrs]
    for name, snr in (jobs if progress is None else progress(jobs)):
        u = INPUTS[name](t, 2, seed=0)
        y0 = true.simulate(u, t=t, hold="foh")
        cell = {"ls": [], "iv": []}
        for seed in seeds:
            y = _noisy(y0, snr, seed)
            for method, kw in (("ls", {"forgetting": 0.01, "bd_forgetting": 0.008}),
                               ("iv", {})):
                ident = AdaptiveIdentifier(4, 2, 2, dt=DT, method=method, **kw)
                ident.update(u, y)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    cell[method].append(relative_error(ident.model, true))
        out[name, snr] = cell
    return out


def _noisy(y0, snr, seed):
    """``y0`` plus white Gaussian noise at ``snr`` dB per channel (noise ``seed``)."""
    return y0 + np.random.default_rng(seed).standard_normal(y0.shape) \
        * y0.std(axis=0) * 10 ** (-snr / 20)


def noise_free_table(duration=200.0, inputs=("multisine-issue12", "white"), progress=None):
    """Issue 23, item 1: noise-free runs of the default (``method='iv'``) and
    the paper's estimator (``method='ls'``, its noise-free α = 0.4, β = 0.08)
    on the issue's inputs: final pole error and ε_r, and the times from which
    each stays below 1e-3. Returns a list of dicts (one per input and method)."""
    true = paper_system()
    t = np.arange(int(round(duration / DT)) + 1) * DT
    jobs = [(name, method) for name in inputs for method in ("iv", "ls")]
    rows = []
    for name, method in (jobs if progress is None else progress(jobs)):
        u = INPUTS[name](t, 2, seed=0)
        y = true.simulate(u, t=t, hold="foh")
        ident = AdaptiveIdentifier(4, 2, 2, horizon=HORIZON, dt=DT, method=method,
                                   history_size=4096)
        ident.update(u, y)
        times, _, perr, eps = trajectories(ident, true)
        model = ident.model
        rows.append({"input": name, "method": method,
                     "final_pole_error": pole_error(model, true),
                     "final_eps_r": relative_error(model, true),
                     "time_pole_error_below_1e-3": settle_time(times, perr, 1e-3),
                     "time_eps_r_below_1e-3": settle_time(times, eps, 1e-3),
                     "bd_start_time": model.info["bd_start_time"]})
    return rows


def noise_free_markdown(rows) -> str:
    out = ["| input | method | pole error < 1e-3 | ε_r < 1e-3 | final pole error | final ε_r |",
           "|---|---|---|---|---:|---:|"]
    for r in rows:
        label = "default ('iv')" if r["method"] == "iv" else "paper's 'ls' (α = 0.4)"
        out.append(f"| {r['input']} | {label} | {_fmt_time(r['time_pole_error_below_1e-3'])} "
                   f"| {_fmt_time(r['time_eps_r_below_1e-3'])} | {r['final_pole_error']:.1e} "
                   f"| {r['final_eps_r']:.1e} |")
    return "\n".join(out)


def memory_study(snr=40.0, pairs=((0.008, 200.0), (0.002, 800.0), (0.0005, 3200.0)),
                 seeds=(1, 2, 3, 4, 5), name="white", progress=None):
    """Issue 23, item 2: consistency. For each ``(forgetting, record)`` pair
    (record = 1.6 memory lengths, so that the memory has filled), ε_r and the
    pole error of the default over noise realisations, and the bias check:
    the mean over realisations of ``Õ_f B̃ - O_f B`` against its standard
    error. Returns a list of dicts, one per pair."""
    true = paper_system()
    ref = obsv_b(true)
    longest = max(d for _, d in pairs)
    t = np.arange(int(round(longest / DT)) + 1) * DT
    u = INPUTS[name](t, 2, seed=0)
    y0 = true.simulate(u, t=t, hold="foh")
    out = []
    for alpha, duration in (pairs if progress is None else progress(pairs)):
        k = int(round(duration / DT)) + 1
        eps, perr, diffs, started = [], [], [], 0
        for seed in seeds:
            ident = AdaptiveIdentifier(4, 2, 2, horizon=HORIZON, dt=DT, forgetting=alpha)
            ident.update(u[:k], _noisy(y0[:k], snr, seed))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = ident.model
            started += bool(model.info["bd_started"])
            eps.append(relative_error(model, true))
            perr.append(pole_error(model, true))
            diffs.append(obsv_b(model) - ref)
        diffs = np.array(diffs)
        mean = diffs.mean(axis=0)
        se = diffs.std(axis=0, ddof=1) / math.sqrt(len(seeds))
        out.append({"forgetting": alpha, "record": duration, "eps_r": eps,
                    "pole_error": perr, "started": started,
                    "bias_over_se": float(np.max(np.abs(mean) / se)),
                    "bias_norm": float(np.linalg.norm(mean) / np.linalg.norm(ref)),
                    "se_norm": float(np.linalg.norm(se) / np.linalg.norm(ref))})
    return out


def memory_markdown(rows, snr, seeds) -> str:
    out = ["| forgetting (memory) | record | (B, D) started | ε_r median (max) | pole error median "
           "| bias / standard error of Õ_f B̃ | largest entry's bias / its standard error |",
           "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        e = np.array(r["eps_r"])
        out.append(f"| {r['forgetting']:g} ({1 / r['forgetting']:.0f} s) | {r['record']:.0f} s "
                   f"| {r['started']} of {len(e)} | {np.median(e):.3f} ({e.max():.3f}) "
                   f"| {np.median(r['pole_error']):.3f} "
                   f"| {r['bias_norm']:.3f} / {r['se_norm']:.3f} | {r['bias_over_se']:.1f} |")
    return "\n".join(out) + (
        f"\n\n{snr:g} dB, white input, noise seeds {', '.join(map(str, seeds))}; bias: "
        "|mean over realisations of Õ_f B̃ - O_f B|_F and its standard error, relative to "
        "|O_f B|_F; last column: the largest ratio over the entries of |mean| to its "
        "standard error (about 2 or less: no bias beyond the standard error).")


def startup_study(snr=40.0, duration=400.0, seeds=tuple(range(1, 11)), name="white",
                  checkpoints=(50.0, 100.0, 200.0, 400.0), settings=None, progress=None):
    """Issue 23: ε_r along the record for several settings (default: the
    start-up schedule ``bd_startup`` off and default), the same records.
    Returns ``{label: {"eps_r": {time: [...]}, "started": [...]}}``."""
    settings = settings or {"bd_startup=0 (issue 12)": {"bd_startup": 0},
                            "default": {}}
    true = paper_system()
    t = np.arange(int(round(duration / DT)) + 1) * DT
    u = INPUTS[name](t, 2, seed=0)
    y0 = true.simulate(u, t=t, hold="foh")
    out = {label: {"eps_r": {c: [] for c in checkpoints}, "started": []}
           for label in settings}
    for seed in (seeds if progress is None else progress(seeds)):
        y = _noisy(y0, snr, seed)
        for label, kw in settings.items():
            ident = AdaptiveIdentifier(4, 2, 2, horizon=HORIZON, dt=DT, **kw)
            a = 0
            for c in checkpoints:
                b = int(round(c / DT)) + 1
                ident.update(u[a:b], y[a:b])
                a = b
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    out[label]["eps_r"][c].append(relative_error(ident.model, true))
            out[label]["started"].append(ident.model.info["bd_start_time"])
    return out


def startup_markdown(res, snr) -> str:
    labels = list(res)
    cps = list(next(iter(res.values()))["eps_r"])
    out = ["| setting | started | " + " | ".join(f"ε_r at {c:g} s, median (max)" for c in cps)
           + " |", "|---|---:|" + "---:|" * len(cps)]
    for label in labels:
        r = res[label]
        n_started = sum(s is not None for s in r["started"])
        cells = []
        for c in cps:
            e = np.array(r["eps_r"][c])
            cells.append(f"{np.median(e):.3f} ({e.max():.3f})")
        out.append(f"| {label} | {n_started} of {len(r['started'])} | " + " | ".join(cells)
                   + " |")
    return "\n".join(out) + f"\n\n{snr:g} dB, white input; ε_r = 1 where (B, D) had not started."


def noise_table_markdown(res, seeds) -> str:
    rows = ["| input | SNR (dB) | paper's LS, ε_r median (max) | IV default, ε_r median (max) |",
            "|---|---:|---:|---:|"]
    for (name, snr), cell in res.items():
        ls, iv = np.array(cell["ls"]), np.array(cell["iv"])
        rows.append(f"| {name} | {snr:g} | {np.median(ls):.2g} ({ls.max():.2g}) "
                    f"| {np.median(iv):.2g} ({iv.max():.2g}) |")
    return "\n".join(rows) + (f"\n\n{len(seeds)} noise realisations per cell (seeds "
                              f"{', '.join(map(str, seeds))}); ε_r = 1 means (B, D) never "
                              "started (B = 0).")


def simulate(duration: float, snr_db=None, *, input_seed=0, noise_seed=1, dt=DT):
    """Sampled record of the paper's system: ``(t, u, y)``.

    The output is the exact response to the input held linearly between the
    samples (first-order hold); white Gaussian noise is added to each output
    channel at ``snr_db`` relative to that channel's noise-free power.
    """
    n = int(round(duration / dt))
    t = np.arange(n + 1) * dt
    u = multisine(t, 2, seed=input_seed)
    y = paper_system().simulate(u, t=t, hold="foh")
    if snr_db is not None:
        std = y.std(axis=0) * 10 ** (-snr_db / 20)
        y = y + np.random.default_rng(noise_seed).standard_normal(y.shape) * std
    return t, u, y


def obsv_b(model: StateSpace, f: int = HORIZON) -> np.ndarray:
    """``O_f B``, invariant to the state basis (the paper's Figs. 3-4)."""
    blocks, X = [], model.B
    for _ in range(f):
        blocks.append(model.C @ X)
        X = model.A @ X
    return np.vstack(blocks)


def relative_error(model: StateSpace, true: StateSpace, f: int = HORIZON) -> float:
    """ε_r = ||Õ_f B̃ - O_f B||_F / ||O_f B||_F (Section V)."""
    ref = obsv_b(true, f)
    return float(np.linalg.norm(obsv_b(model, f) - ref) / np.linalg.norm(ref))


def identify(t, u, y, forgetting, bd_forgetting, *, history=4096, **kw):
    """Run the identifier over the record; returns (identifier, seconds)."""
    ident = AdaptiveIdentifier(4, 2, 2, horizon=HORIZON, filter_poles=FILTER_POLE,
                               forgetting=forgetting, bd_forgetting=bd_forgetting,
                               dt=t[1] - t[0], history_size=history, **kw)
    t0 = time.perf_counter()
    ident.update(u, y)
    return ident, time.perf_counter() - t0


def trajectories(ident: AdaptiveIdentifier, true: StateSpace):
    """Per history row: time, eigenvalues of Ã (column i matched to the i-th
    eigenvalue of A sorted), pole error, ε_r (NaN before the (B̃, D)
    estimation starts)."""
    hist = ident.history
    ref = np.sort_complex(true.poles())
    times = hist["t"]
    eig = np.empty((times.size, ref.size), dtype=complex)
    perr = np.empty(times.size)
    eps = np.full(times.size, np.nan)
    start = ident.model.info["bd_start_time"]
    for k in range(times.size):
        m = StateSpace(hist["A"][k], hist["B"][k], hist["C"][k], hist["D"][k], 0.0)
        ev = m.poles()
        rows, cols = linear_sum_assignment(np.abs(ref[:, None] - ev[None, :]))
        eig[k, rows] = ev[cols]          # eig[k, i]: the estimate matched to ref[i]
        perr[k] = pole_error(m, true)
        if start is not None and times[k] >= start:
            eps[k] = relative_error(m, true)
    return times, eig, perr, eps


def settle_time(times, values, tol):
    """First time after which ``values`` stay below ``tol`` (None if never)."""
    bad = np.flatnonzero(~(values < tol))
    if bad.size == 0:
        return float(times[0])
    if bad[-1] == times.size - 1:
        return None
    return float(times[bad[-1] + 1])


def regression_condition(t, u, y, scale: bool) -> float:
    """Condition number of the normal matrix of (8) over the whole record (no
    forgetting to speak of, negligible prior), unscaled or scaled states."""
    ident = AdaptiveIdentifier(4, 2, 2, horizon=HORIZON, filter_poles=FILTER_POLE,
                               forgetting=1e-9, bd_forgetting=1e-9, dt=t[1] - t[0],
                               scale_filters=scale, initial_covariance=1e14, method="ls")
    ident.update(u, y)
    return ident.information_condition()[0]


def run(duration_clean=200.0, duration_noisy=400.0, noise_seeds=(1, 2, 3, 4, 5),
        progress=None):
    """All runs of the study; returns a dict of results (and identifiers)."""
    true = paper_system()
    jobs = [("clean", None, 0.4, 0.08, "ls", None)]
    jobs += [("clean_ode", None, 0.4, 0.08, "ode", None)]
    jobs += [(f"noisy_{s}", 50.0, 0.01, 0.008, "ls", s) for s in noise_seeds]
    out = {}
    data_clean = simulate(duration_clean)
    iterator = jobs if progress is None else progress(jobs)
    for name, snr, a, b, method, seed in iterator:
        if snr is None:
            t, u, y = data_clean
        else:
            t, u, y = simulate(duration_noisy, snr, noise_seed=seed)
        ident, seconds = identify(t, u, y, a, b, method=method)
        times, eig, perr, eps = trajectories(ident, true)
        model = ident.model
        out[name] = {
            "ident": ident, "times": times, "eig": eig, "pole_error": perr, "eps_r": eps,
            "final_pole_error": pole_error(model, true),
            "final_eps_r": relative_error(model, true),
            "seconds": seconds, "samples": ident.n_samples, "forgetting": a,
            "bd_forgetting": b, "method": method, "snr_db": snr,
            "bd_start_time": model.info["bd_start_time"],
        }
    t, u, y = data_clean
    short = slice(0, min(t.size, 60001))
    out["condition"] = {"unscaled": regression_condition(t[short], u[short], y[short], False),
                        "scaled": regression_condition(t[short], u[short], y[short], True)}
    return out


def _fmt_time(value):
    return "not within the record" if value is None else f"from {value:.1f} s"


def summary(res) -> tuple[str, dict]:
    """Markdown table and JSON-ready summary."""
    clean, ode = res["clean"], res["clean_ode"]
    noisy = [v for k, v in res.items() if k.startswith("noisy_")]
    rows = []
    record = {"condition": res["condition"], "runs": {}}
    for name, r in [("noise-free, exact LS (method='ls')", clean),
                     ("noise-free, paper's ODE form (11)-(12), (19)-(20)", ode)]:
        tp = settle_time(r["times"], r["pole_error"], 1e-3)
        te = settle_time(r["times"], r["eps_r"], 1e-3)
        rows.append(f"| {name} | {r['samples'] / 1000:.0f} s | pole error < 1e-3 "
                    f"{_fmt_time(tp)}, ε_r < 1e-3 {_fmt_time(te)} "
                    f"| {r['final_pole_error']:.1e} | {r['final_eps_r']:.1e} |")
        record["runs"][name] = {"time_pole_error_below_1e-3": tp, "time_eps_r_below_1e-3": te,
                                "final_pole_error": r["final_pole_error"],
                                "final_eps_r": r["final_eps_r"],
                                "bd_start_time": r["bd_start_time"],
                                "samples_per_second": r["samples"] / r["seconds"]}
    eps_final = np.array([r["final_eps_r"] for r in noisy])
    perr_final = np.array([r["final_pole_error"] for r in noisy])
    t05 = [settle_time(r["times"], r["eps_r"], 0.05) for r in noisy]
    worst = None if any(v is None for v in t05) else max(t05)
    rows.append(f"| 50 dB output noise, {len(noisy)} noise realisations (median / worst) "
                f"| {noisy[0]['samples'] / 1000:.0f} s | ε_r < 0.05 {_fmt_time(worst)} "
                f"(worst realisation) | {np.median(perr_final):.1e} / {perr_final.max():.1e} "
                f"| {np.median(eps_final):.1e} / {eps_final.max():.1e} |")
    record["runs"]["50 dB"] = {"final_eps_r": eps_final.tolist(),
                               "final_pole_error": perr_final.tolist(),
                               "time_eps_r_below_0.05": t05}
    cond = res["condition"]
    table = "\n".join([
        "| run | record | time to convergence | final pole error | final ε_r |",
        "|---|---:|---|---:|---:|",
        *rows,
        "",
        "Pole error: largest distance between matched eigenvalues of Ã and A. "
        "ε_r = ||Õ_f B̃ - O_f B||_F / ||O_f B||_F (f = 5). Times: from then on the error "
        "stays below the threshold until the end of the record.",
        "",
        f"Condition number of the normal matrix of (8) on 60 s of the noise-free record: "
        f"{cond['unscaled']:.1e} with the paper's filter states, {cond['scaled']:.1e} with the "
        "time-scaled states.",
    ])
    return table, record


def figures(res, out_dir: str) -> list[str]:
    from subid.evaluation import plot
    plt = plot._pyplot()
    true = paper_system()
    written = []
    clean = res["clean"]
    # Fig. 1: eigenvalues of Ã
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for k in range(clean["eig"].shape[1]):
        ax.plot(clean["times"], clean["eig"][:, k].real, lw=1.2)
    for p in true.poles():
        ax.axhline(p.real, color="k", ls="--", lw=0.8)
    ax.set_ylim(-5, 1)
    ax.set_xscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("Re eig(Ã)")
    ax.set_title(f"Fig. 1: eigenvalues of Ã (noise-free, α = {clean['forgetting']}); "
                 "dashed: A")
    fig.tight_layout()
    written.append(_save(fig, out_dir, "fig1_eigenvalues.png"))
    # Fig. 2: Bode, output 1 / input 1
    w = np.logspace(-2, 2, 400)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    H0 = true.freqresp(w)[:, 0, 0]
    a1.semilogx(w, 20 * np.log10(np.abs(H0)), "k-", lw=2.5, label="true")
    a2.semilogx(w, np.degrees(np.unwrap(np.angle(H0))), "k-", lw=2.5)
    for key, style, label in [("clean", "C1--", "estimate, noise-free (200 s)"),
                              ("noisy_1", "C0:", "estimate, 50 dB (400 s)")]:
        if key in res:
            Hm = res[key]["ident"].model.freqresp(w)[:, 0, 0]
            a1.semilogx(w, 20 * np.log10(np.abs(Hm)), style, lw=1.5, label=label)
            a2.semilogx(w, np.degrees(np.unwrap(np.angle(Hm))), style, lw=1.5)
    a1.set_ylabel("magnitude (dB)")
    a2.set_ylabel("phase (deg)")
    a2.set_xlabel("frequency (rad/s)")
    a1.legend(fontsize="small")
    a1.set_title("Fig. 2: Bode diagram, output 1 / input 1")
    fig.tight_layout()
    written.append(_save(fig, out_dir, "fig2_bode.png"))
    # Fig. 3: ε_r noise-free, LS and the paper's ODE form
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key, label in [("clean", "exact LS (method='ls')"),
                       ("clean_ode", "paper's ODE form (11)-(12), (19)-(20)")]:
        r = res[key]
        ax.semilogy(r["times"], r["eps_r"], label=label)
    ax.axhline(1e-3, color="k", ls=":", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("ε_r")
    ax.set_title(f"Fig. 3: ε_r without noise (α = {clean['forgetting']}, "
                 f"β = {clean['bd_forgetting']})")
    ax.legend(fontsize="small")
    fig.tight_layout()
    written.append(_save(fig, out_dir, "fig3_error_noise_free.png"))
    # Fig. 4: ε_r at 50 dB
    fig, ax = plt.subplots(figsize=(7, 4.2))
    noisy = [(k, v) for k, v in res.items() if k.startswith("noisy_")]
    for k, r in noisy:
        ax.semilogy(r["times"], r["eps_r"], lw=1, label=f"noise seed {k.split('_')[1]}")
    ax.axhline(0.05, color="k", ls=":", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("ε_r")
    ax.set_title(f"Fig. 4: ε_r with output noise at 50 dB (α = {noisy[0][1]['forgetting']}, "
                 f"β = {noisy[0][1]['bd_forgetting']})")
    ax.legend(fontsize="x-small", ncol=2)
    fig.tight_layout()
    written.append(_save(fig, out_dir, "fig4_error_50db.png"))
    return written


def _save(fig, out_dir, name):
    path = os.path.join(out_dir, name)
    save_figure(fig, path, dpi=100)
    return name


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m subid.experiments.seed000",
        description="Reproduce seed 000, Section V: adaptive identification of the paper's "
                    "system (Figs. 1-4).",
        epilog="example: python -m subid.experiments.seed000 --out results/seed000")
    parser.add_argument("--clean-seconds", type=float, default=200.0,
                        help="length of the noise-free record (default 200 s)")
    parser.add_argument("--noisy-seconds", type=float, default=400.0,
                        help="length of the 50 dB records (default 400 s)")
    parser.add_argument("--noise-seeds", type=int, default=5,
                        help="number of noise realisations at 50 dB (default 5)")
    parser.add_argument("--out", default="results/seed000", help="output folder")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--noise-table", action="store_true",
                        help="instead: the table of ε_r over SNR 30-80 dB, white-noise and "
                             "issue-12 multisine inputs, paper's LS against IV (3 noise "
                             "realisations; writes noise_table.md)")
    parser.add_argument("--noise-free-table", action="store_true",
                        help="instead: noise-free convergence of the default and the paper's "
                             "'ls' on the issue-12 multisine and white noise, 200 s "
                             "(writes noise_free.md)")
    parser.add_argument("--memory-study", action="store_true",
                        help="instead: consistency at 40 dB, white input: ε_r as memory and "
                             "record grow together, 5 realisations (writes memory.md)")
    parser.add_argument("--startup-study", action="store_true",
                        help="instead: ε_r along 400 s at 40 dB, white input, 10 "
                             "realisations, with and without the start-up schedule "
                             "bd_startup (writes startup.md)")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    progress = progress_wrapper("runs", "run", enabled=on_terminal(args.quiet))
    studies = [(args.noise_free_table, "noise_free.md",
                lambda: noise_free_markdown(noise_free_table(progress=progress))),
               (args.memory_study, "memory.md",
                lambda: memory_markdown(memory_study(progress=progress), 40.0,
                                        (1, 2, 3, 4, 5))),
               (args.startup_study, "startup.md",
                lambda: startup_markdown(startup_study(progress=progress), 40.0))]
    for wanted, name, build in studies:
        if wanted:
            t0 = time.perf_counter()
            text = build() + f"\n\nRun time {time.perf_counter() - t0:.0f} s."
            write_bytes(os.path.join(args.out, name), text + "\n")
            print(text)
    if any(wanted for wanted, _, _ in studies):
        return 0
    if args.noise_table:
        seeds = tuple(range(1, 4))
        t0 = time.perf_counter()
        text = noise_table_markdown(noise_table(seeds=seeds, progress=progress), seeds)
        text += f" Run time {time.perf_counter() - t0:.0f} s."
        write_bytes(os.path.join(args.out, "noise_table.md"), text + "\n")
        print(text)
        return 0
    t0 = time.perf_counter()
    res = run(args.clean_seconds, args.noisy_seconds, tuple(range(1, args.noise_seeds + 1)),
              progress)
    elapsed = time.perf_counter() - t0
    table, record = summary(res)
    header = (f"Seed 000 Section V: paper's system, sampling period 1 ms, multisine input "
              f"(0.5-20 rad/s), horizon {HORIZON}, filter poles at {FILTER_POLE:g}, "
              f"first-order hold. Noise-free: α = 0.4, β = 0.08; 50 dB: α = 0.01, "
              f"β = 0.008. Run time {elapsed:.1f} s in all.\n\n")
    write_bytes(os.path.join(args.out, "table.md"), header + table + "\n")
    record.update({"seconds": elapsed, "clean_seconds": args.clean_seconds,
                   "noisy_seconds": args.noisy_seconds})
    write_json(os.path.join(args.out, "results.json"), record, indent=1)
    names = ["table.md", "results.json"]
    try:
        names += figures(res, args.out)
    except ImportError as exc:
        log.warning("figures skipped: %s", exc)
    print(header + table)
    print(f"wrote {args.out}/" + ", ".join(names))
    return 0


if __name__ == "__main__":
    sys.exit(main())
