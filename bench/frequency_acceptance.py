"""Figures of issue 27's acceptance checks (the same computations as
tests/test_frequency.py, printed): fd_subspace and pem on frequency-response data.

Run: ``OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/frequency_acceptance.py``.
"""

from __future__ import annotations

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


def noisy(runs: int = 20, level: float = 0.05):
    system = subid.systems.seed000_system()
    w = np.logspace(-2, 2, 200)
    G = system.freqresp(w)
    start, refined = [], []
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        noise = level * np.abs(G) * (rng.standard_normal(G.shape)
                                     + 1j * rng.standard_normal(G.shape)) / np.sqrt(2)
        data = subid.FRData(w, G + noise)
        model = subid.fd_subspace(data, 4)
        start.append(max_relative_error(model, system, w))
        refined.append(max_relative_error(subid.pem(data, model), system, w))
    start, refined = np.array(start), np.array(refined)
    print(f"{100 * level:g} % complex noise, {runs} runs, order 4: fd_subspace median "
          f"{np.median(start):.4f} (worst {start.max():.4f}); after pem median "
          f"{np.median(refined):.4f}; pem lower in {int((refined < start).sum())} of {runs}")


if __name__ == "__main__":
    noise_free()
    noisy()
