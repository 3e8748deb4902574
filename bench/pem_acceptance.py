"""Figures of issue 11's acceptance checks (the same computations as tests/test_pem.py
and tests/test_prediction.py, printed).

Run: ``OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/pem_acceptance.py``.
"""

from __future__ import annotations

import warnings

import numpy as np

import subid
from subid import systems


def kalman_and_variance():
    true = systems.seed001_innovation_system()
    est = systems.simulate_innovation_data(true, 5000, seed=1)
    fresh = systems.simulate_innovation_data(true, 5000, seed=2)
    x, ref = np.zeros(3), []
    for k in range(est.n_samples):
        yk = true.C @ x + true.D @ est.u[k]
        ref.append(yk)
        x = true.A @ x + true.B @ est.u[k] + true.K @ (est.y[k] - yk)
    print("Kalman predictor, max |predict - hand-written|:",
          np.abs(subid.predict(true, est, 1, x0=0) - np.array(ref)).max())
    e = fresh.y - subid.predict(true, fresh, 1)
    print("true model, fresh one-step variance / true:",
          np.round(np.diag(np.cov(e.T)) / np.diag(true.noise_cov), 4))
    rec = subid.RecursiveSubspace(3, 2, 2)
    rec.update(est.u, est.y)
    for name, model in (("ls_subspace", subid.ls_subspace(est, 3)),
                        ("ls_subspace instruments=None", subid.ls_subspace(est, 3,
                                                                           instruments=None)),
                        ("moesp", subid.moesp(est, 3)), ("n4sid", subid.n4sid(est, 3)),
                        ("RecursiveSubspace", rec.model)):
        e = fresh.y - subid.predict(model, fresh, 1)
        print(f"{name}: fresh one-step variance / true innovation variance",
              np.round(np.diag(np.cov(e.T)) / np.diag(true.noise_cov), 4))


def closed_loop(runs=10):
    true = systems.seed001_innovation_system(feedthrough=False)
    F = -0.3 * np.eye(2)
    a, b, c = [], [], []
    for r in range(runs):
        data = systems.simulate_innovation_data(true, 3000, seed=100 + r, feedback=F)
        start = subid.n4sid(data, 3, feedthrough=False)
        a.append(subid.markov_error(start, true))
        b.append(subid.markov_error(subid.pem(data, start), true))
        c.append(subid.markov_error(subid.moesp(data, 3, feedthrough=False), true))
    print(f"closed loop, median Markov error: n4sid {np.median(a):.4f}, moesp {np.median(c):.4f}, "
          f"pem {np.median(b):.4f} ({np.median(b) / np.median(a):.2f}x n4sid)")


def open_loop(runs=20):
    true = systems.seed001_system()
    a, b, pa, pb = [], [], [], []
    for r in range(runs):
        data = systems.simulate_data(true, 1000, seed=r, process_snr_db=25, output_snr_db=25)
        fresh = systems.simulate_data(true, 1000, seed=1000 + r, process_snr_db=25,
                                      output_snr_db=25)
        start = subid.n4sid(data, 3)
        refined = subid.pem(data, start)
        a.append(subid.markov_error(start, true))
        b.append(subid.markov_error(refined, true))
        for m, out in ((start, pa), (refined, pb)):
            e = fresh.y - subid.predict(m, fresh, 1)
            out.append(np.linalg.det(np.cov(e.T)))
    print(f"open loop 25 dB, median Markov error: n4sid {np.median(a):.5f}, pem "
          f"{np.median(b):.5f} ({np.median(b) / np.median(a):.3f}x); median det of the fresh "
          f"one-step error covariance pem/n4sid {np.median(pb) / np.median(pa):.4f}")


if __name__ == "__main__":
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kalman_and_variance()
        closed_loop()
        open_loop()
