"""Figures of issue 27's acceptance checks (the same computations as
tests/test_frequency.py, printed): fd_subspace and pem on frequency-response data.

Run: ``OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/frequency_acceptance.py``;
``... frequency_acceptance.py 20 40``: the noisy runs on seeds 20 to 59 (a check on
seeds the acceptance figures were not measured on).
"""

from __future__ import annotations

import sys

import numpy as np

import subid


def max_relative_error(model, system, w) -> float:
    G = system.freqresp(w)
    return float(np.abs(model.freqresp(w) - G).max() / np.abs(G).max())


def noise_free():
    ct = subid.systems.seed000_system()
    dt = subid.systems.seed001_system()
    w_ct = np.logspace(-2, 2, 200)
    w_dt = np.linspace(0, np.pi, 202)[1:-1]
    for name, system, w, period in (("seed 000, CT, [0.01, 100] rad/s", ct, w_ct, 0.0),
                                    ("seed 001, DT, (0, pi)", dt, w_dt, 1.0)):
        data = subid.FRData(w, system.freqresp(w), period)
        for order in (system.order, None):
            model = subid.fd_subspace(data, order)
            print(f"noise-free {name}, order {'given' if order else 'chosen'} "
                  f"({model.order}): max |G - G_hat| / max |G| = "
                  f"{max_relative_error(model, system, w):.2e}")


def slow_pole(model, system) -> bool:
    """A pole slower than half the true slowest (seed 000: -0.16 rad/s): the spurious
    slow pole of a local minimum, near the lowest frequency."""
    return bool(np.abs(model.poles().real).min() < 0.5 * np.abs(system.poles().real).min())


def noisy(runs: int = 20, level: float = 0.05, *, relative: bool, equal_variance=False,
          first_seed: int = 0):
    """5 % complex noise: of standard deviation ``level |G_ij|`` (``relative``, as a
    spectral estimate's) or ``level rms(G)``; ``equal_variance``: fd_subspace under
    the paper's equal-variance assumption (``weights=1``) instead of the estimated
    noise model."""
    system = subid.systems.seed000_system()
    w = np.logspace(-2, 2, 200)
    G = system.freqresp(w)
    level_of = np.abs(G) if relative else np.sqrt(np.mean(np.abs(G) ** 2))
    start, refined, rel_start, rel_refined, oracle, rel_oracle = [], [], [], [], [], []
    slow = [0, 0]
    for seed in range(first_seed, first_seed + runs):
        rng = np.random.default_rng(seed)
        noise = level * level_of * (rng.standard_normal(G.shape)
                                    + 1j * rng.standard_normal(G.shape)) / np.sqrt(2)
        data = subid.FRData(w, G + noise, weights=np.ones(w.size) if equal_variance else None)
        model = subid.fd_subspace(data, 4)
        better = subid.pem(data, model)
        # the reference: pem weighted by the true noise level (maximum likelihood)
        best = subid.pem(subid.FRData(w, G + noise, std=level * np.broadcast_to(level_of,
                                                                                G.shape)),
                         model)
        slow[0] += slow_pole(model, system)
        slow[1] += slow_pole(better, system)
        start.append(max_relative_error(model, system, w))
        refined.append(max_relative_error(better, system, w))
        oracle.append(max_relative_error(best, system, w))
        rel_start.append(np.sqrt(np.mean(np.abs((model.freqresp(w) - G) / G) ** 2)))
        rel_refined.append(np.sqrt(np.mean(np.abs((better.freqresp(w) - G) / G) ** 2)))
        rel_oracle.append(np.sqrt(np.mean(np.abs((best.freqresp(w) - G) / G) ** 2)))
    start, refined, oracle = np.array(start), np.array(refined), np.array(oracle)
    rel_start, rel_refined = np.array(rel_start), np.array(rel_refined)
    rel_oracle = np.array(rel_oracle)
    print(f"{100 * level:g} % noise {'relative to |G|' if relative else 'of level rms(G)'}"
          f"{', weights=1 (equal variance)' if equal_variance else ''}, {runs} runs "
          f"(seeds {first_seed}-{first_seed + runs - 1}), order 4: "
          f"max error fd_subspace median {np.median(start):.4f} (worst {start.max():.4f}), "
          f"after pem {np.median(refined):.4f}, lower in {int((refined < start).sum())}; "
          f"relative RMS error {np.median(rel_start):.4f} -> {np.median(rel_refined):.4f}, "
          f"lower in {int((rel_refined < rel_start).sum())}; with the true noise level as "
          f"weights: max error lower in {int((oracle < start).sum())}, relative RMS "
          f"{np.median(rel_oracle):.4f}; a spurious slow pole in {slow[0]} starts and "
          f"{slow[1]} pem results")


if __name__ == "__main__":
    if len(sys.argv) == 3:
        first, count = int(sys.argv[1]), int(sys.argv[2])
        noisy(count, relative=True, first_seed=first)
        noisy(count, relative=False, first_seed=first)
    else:
        noise_free()
        noisy(relative=True)
        noisy(relative=False)
        noisy(relative=True, equal_variance=True)
