"""Closed-loop acceptance of issue 21: the default feedthrough and identify().

Seed-001 plant (D = 0) in innovation form, u = r - F y with F = -0.5 I,
N = 3000, 10 runs: median Markov error (first 10 Markov parameters) of
``pem(data, n4sid(data, 3))`` (the default ``feedthrough='auto'``), of
``identify(data, 3)`` and of the reference ``pem`` started from
``n4sid(data, 3, feedthrough=False)``.

Usage::

    OPENBLAS_NUM_THREADS=1 python bench/closed_loop.py
"""

from __future__ import annotations

import warnings

import numpy as np

import subid


def main(runs: int = 10) -> dict:
    true = subid.systems.seed001_innovation_system(feedthrough=False)
    F = -0.5 * np.eye(2)
    errors = {"pem(n4sid(data, 3))": [], "identify(data, 3)": [],
              "pem(n4sid(data, 3, feedthrough=False))": []}
    detected = 0
    for r in range(runs):
        data = subid.systems.simulate_innovation_data(true, 3000, seed=100 + r, feedback=F)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = subid.n4sid(data, 3)
            detected += not start.info["feedthrough"]["estimated"]
            errors["pem(n4sid(data, 3))"].append(
                subid.markov_error(subid.pem(data, start), true))
            errors["identify(data, 3)"].append(
                subid.markov_error(subid.identify(data, 3), true))
            errors["pem(n4sid(data, 3, feedthrough=False))"].append(
                subid.markov_error(subid.pem(data, subid.n4sid(data, 3, feedthrough=False)),
                                   true))
    ref = np.median(errors["pem(n4sid(data, 3, feedthrough=False))"])
    print(f"feedback detected (D = 0) in {detected} of {runs} runs")
    for name, values in errors.items():
        med = float(np.median(values))
        print(f"{name:42s} median Markov error {med:.4f} ({med / ref:.2f}x the reference)")
    return errors


if __name__ == "__main__":
    main()
