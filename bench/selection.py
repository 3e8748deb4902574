"""Order selection Monte Carlo of issue 21: the default against BIC.

40 random stable 2x2 systems (``subid.systems.random_system(2 + k % 5, 2, 2,
seed=k)``, orders 2..6), white Gaussian input, 20 dB process and 20 dB output
noise (the process noise coloured by the plant), N = 2000 samples to
estimate and 2000 more to validate. For each: the order the default
``moesp(est)`` chooses, and the order of the least BIC of the innovation
models ``n4sid(est, n, horizon=10)``, n = 1..10
(``N ln det Σ + (n (nu + 2 ny) + nu ny) ln N``, Σ the one-step prediction
error covariance on the estimation data); how often each is the true order,
and the median validation simulation fit of the models.

Usage::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/selection.py [--runs 40]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import subid


def bic_order(est, orders=range(1, 11)):
    N, nu, ny = est.n_samples, est.n_inputs, est.n_outputs
    best = None
    for n in orders:
        # horizon 10 (20 where 10 cannot reveal n: one output, n = 10)
        model = subid.n4sid(est, n, horizon=10 if 9 * ny >= n else 20)
        e = est.y - subid.predict(model, est, 1)
        value = N * np.log(np.linalg.det(e.T @ e / N)) + (n * (nu + 2 * ny) + nu * ny) * np.log(N)
        if best is None or value < best[0]:
            best = (value, n, model)
    return best[1], best[2]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    args = parser.parse_args(argv)
    hits = {"default": 0, "bic": 0}
    fits = {"default": [], "bic": []}
    for k in range(args.runs):
        order = 2 + k % 5
        true = subid.systems.random_system(order, 2, 2, seed=k)
        data = subid.systems.simulate_data(true, 4000, seed=1000 + k, process_snr_db=20,
                                           output_snr_db=20)
        est, val = data[:2000], data[2000:]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = subid.moesp(est)
            n_bic, model_bic = bic_order(est)
        hits["default"] += model.order == order
        hits["bic"] += n_bic == order
        fits["default"].append(float(np.mean(subid.fit_percent(model, val))))
        fits["bic"].append(float(np.mean(subid.fit_percent(model_bic, val))))
        print(f"{k:2d} true {order} default {model.order} bic {n_bic}", flush=True)
    for key in hits:
        print(f"{key:8s} true order {hits[key]}/{args.runs}, median validation fit "
              f"{np.median(fits[key]):.2f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
