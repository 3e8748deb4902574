"""The figures shown in the README and the documentation, from bundled data.

* ``fig_compare.png``, ``fig_bode.png``, ``fig_poles.png``, ``fig_residuals.png``,
  ``fig_order_selection.png``: the DaISy dryer record, means removed, identified on the
  first 2/3 by ``ls_subspace``, ``moesp`` and ``n4sid`` (orders chosen automatically),
  checked on the last 1/3;
* ``fig_convergence.png``: :class:`subid.RecursiveSubspace` on seed 001's system
  (3000 samples, 30 dB output noise), against the true poles.

Run ``python -m subid.experiments.figures --out docs/img`` (a few seconds).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings


def make(out: str) -> list[str]:
    """Draw the figures into folder ``out``; returns the paths written."""
    import subid
    from subid.evaluation import plot
    from subid.io._files import save_figure
    os.makedirs(out, exist_ok=True)
    data = subid.datasets.load("dryer").detrend()
    est, val = data.split(2 / 3)
    with warnings.catch_warnings():     # an unstable or poorly excited fit is drawn as is
        warnings.simplefilter("ignore", subid.errors.UnstableModelWarning)
        models = {"ls_subspace": subid.ls_subspace(est), "moesp": subid.moesp(est),
                  "n4sid": subid.n4sid(est)}
    true = subid.systems.seed001_system()
    record = subid.systems.simulate_data(true, 3000, seed=1, output_snr_db=30)
    online = subid.RecursiveSubspace(3, 2, 2, history_size=64, history_stride=50)
    online.update(record.u, record.y)
    figures = {
        "fig_compare.png": plot.compare(val, models, title="dryer: validation (last 1/3)"),
        "fig_bode.png": plot.bode(models, title="dryer: frequency response"),
        "fig_poles.png": plot.poles({k: [m] for k, m in models.items()}, marker="x",
                                    markersize=8, alpha=0.9, title="dryer: poles"),
        "fig_residuals.png": plot.residuals(models, val),
        "fig_order_selection.png": plot.order_selection(models,
                                                        title="dryer: order selection"),
        "fig_order_scores.png": plot.order_scores(models, title="dryer: candidate scores"),
        "fig_convergence.png": plot.convergence(online.history, reference=true,
                                                title="RecursiveSubspace on seed 001's "
                                                      "system, 30 dB noise"),
    }
    paths = []
    for name, fig in figures.items():
        path = os.path.join(out, name)
        save_figure(fig, path)
        paths.append(path)
    import matplotlib.pyplot as plt
    plt.close("all")
    return paths


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Draw the README figures.")
    parser.add_argument("--out", default="docs/img", help="output folder (default docs/img)")
    args = parser.parse_args(argv)
    for path in make(args.out):
        sys.stdout.write(path + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
