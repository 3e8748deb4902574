"""The Kalman gain of ``subid.identify`` on real records: state-sequence K against the
prediction-error K (``subid.methods.dt.gain.refine_gain``), and ``noise_cov`` against
the covariance of the model's own prediction errors.

For each bundled DaISy record (the split of ``bench/realdata.py``: first 2/3 to
estimate, means removed, last 1/3 to validate), ``subid.identify(est)`` is run twice in
one process: as it is, and with the gain step switched off (its model keeps the
state-sequence K of :mod:`subid.methods.dt.noise_model`). Reported: the one-step
prediction error power (mean square, per output) on the validation part for both, the
ratio of the two, and ``noise_cov`` (diagonal) over the estimation part's own one-step
error power (x0 by least squares: ``subid.predict``)::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/gain_realdata.py --out bench/gain_realdata.md
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import subid
import subid.methods.dt.gain as gain
from realdata import split


def power(model, data):
    e = data.y - subid.predict(model, data, 1)
    return np.mean(e ** 2, axis=0)


def fmt(values):
    return ", ".join(f"{v:.3g}" for v in values)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    rows = []
    refine_gain = gain.refine_gain
    for name in subid.datasets.names():
        est, val = split(name)
        gain.refine_gain = lambda data, model, **options: model       # the step off
        t = time.process_time()
        before = subid.identify(est)
        seconds_before = time.process_time() - t
        gain.refine_gain = refine_gain
        t = time.process_time()
        after = subid.identify(est)
        seconds_after = time.process_time() - t
        p0, p1 = power(before, val), power(after, val)
        white = ["yes" if subid.residuals(m, val)["whiteness_ok"] else "no"
                 for m in (before, after)]
        ratio = np.diag(after.noise_cov) / power(after, est)
        step = after.info["identify"].get("gain", {})
        rows.append(f"| {name} | {after.order} | {fmt(p0)} | {fmt(p1)} | {fmt(p1 / p0)} | "
                    f"{fmt(ratio)} | {white[0]} / {white[1]} | "
                    f"{step.get('n_evaluations', '-')} | "
                    f"{seconds_after - seconds_before:+.2f} |")
        print(rows[-1], flush=True)
    lines = [
        "# The gain of `subid.identify` on real records", "",
        "Command: `OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/gain_realdata.py "
        "--out bench/gain_realdata.md` (see its docstring). One-step prediction error power "
        "(mean square per output) on the validation third, with the state-sequence K "
        "(the gain step off) and with the prediction-error K; `noise_cov / own` is the "
        "reported innovation covariance (diagonal) over the estimation part's own one-step "
        "error power; `white` whether the validation residuals pass the whiteness test of "
        "`subid.residuals` (99 %), state-sequence K / prediction-error K; "
        "`evaluations` of the gain step; `CPU s` the extra time of the call "
        "(one run each, a shared machine: noise of a few tenths).", "",
        "| record | order | state-sequence K | prediction-error K | ratio | "
        "noise_cov / own | white | evaluations | CPU s |",
        "|---|---:|---|---|---|---|---|---:|---:|", *rows, ""]
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
