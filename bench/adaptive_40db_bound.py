"""Issue 23 at 40 dB: the default ``AdaptiveIdentifier`` against the output-error (ML) estimate.

Paper's system, 1 ms, the paper's white-noise input (input seed 0), 400 s, white
output noise at 40 dB per channel (noise seeds as given): the same records as
``python -m subid.experiments.seed000 --startup-study``. For each record:

* ε_r of the default identifier after 400 s;
* ε_r of the output-error estimate on the same record: ``subid.pem(...,
  focus='simulation')`` started from the true system (its exact discrete-time
  equivalent for the first-order hold), converted back with the same hold. With
  white output noise the output-error minimiser is the maximum-likelihood
  estimate, so its error is what an efficient estimator reaches on the record
  (about its Cramér-Rao spread); no online estimator with the same data can be
  expected to do much better.

Slow (a few minutes per record on a loaded core: PEM on 400,000 samples); rows
are appended to the output as they come.

Run: ``OPENBLAS_NUM_THREADS=1 python bench/adaptive_40db_bound.py --seeds 1 2 3``.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

import numpy as np

import subid
from subid.experiments.seed000 import DT, INPUTS, _noisy, paper_system, relative_error
from subid.io._files import write_bytes


def row(seed: int, duration: float = 400.0, snr: float = 40.0) -> tuple[float, float, str]:
    """(ε_r default, ε_r output-error, its poles) for noise seed ``seed``."""
    true = paper_system()
    t = np.arange(int(round(duration / DT)) + 1) * DT
    u = INPUTS["white"](t, 2, seed=0)
    y = _noisy(true.simulate(u, t=t, hold="foh"), snr, seed)
    ident = subid.AdaptiveIdentifier(4, 2, 2, horizon=5, dt=DT)
    ident.update(u, y)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = relative_error(ident.model, true)
        oe = subid.pem(subid.IOData(u=u, y=y, dt=DT), true.to_discrete(DT, method="foh"),
                       focus="simulation").to_continuous(method="foh")
    poles = ", ".join(f"{p:.3f}" for p in np.sort(np.linalg.eigvals(oe.A).real))
    return default, relative_error(oe, true), poles


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 11)))
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "adaptive_40db_bound.md"))
    args = parser.parse_args(argv)
    lines = ["# AdaptiveIdentifier at 40 dB against the output-error (ML) estimate", "",
             "Paper's system, 1 ms, white input (seed 0), 400 s, 40 dB; the true poles are "
             "-3.620, -1.677, -1.243, -0.160.", "",
             "| noise seed | default ε_r | output-error ε_r | output-error poles |",
             "|---:|---:|---:|---|"]
    results = []
    for seed in args.seeds:
        d, o, poles = row(seed)
        results.append((d, o))
        lines.append(f"| {seed} | {d:.3f} | {o:.3f} | {poles} |")
        write_bytes(args.out, "\n".join(lines) + "\n")
        print(lines[-1], flush=True)
    d, o = np.array(results).T
    lines += ["", f"Median (worst): default {np.median(d):.3f} ({d.max():.3f}), output error "
              f"{np.median(o):.3f} ({o.max():.3f}); median ratio default / output error "
              f"{np.median(d / o):.2f}.", ""]
    write_bytes(args.out, "\n".join(lines))
    print(lines[-2])
    return 0


if __name__ == "__main__":
    sys.exit(main())
