"""CPU of the ``armax``, ``oe`` and ``bj`` default calls with the derivatives written out
against the unit-step central differences they replaced, interleaved in one process.

``pem_poly._Output.directions`` took the derivatives of the predictor along every
coefficient from ``2 d`` realisations (exact: the realisation is of degree <= 2 in the
coefficients); ARMAX, OE and BJ now write them out from the observer form
(``_Output.directions``, equal to rounding, tests/test_polynomial.py). The
reference path (the central differences, written here) is put in place by
monkeypatching ``_Output.directions``. Each record: means of
the first 2/3 removed, that part estimated, the last 1/3 validated (simulation fit %,
x0 by least squares, mean over outputs, as bench/realdata.py); CPU seconds
(``time.process_time``), the two paths alternated ``--repeat`` times, medians; the
largest entry-wise difference of the two models' A relative to its largest entry.

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/poly_directions.py [RECORD ...]
     [--methods armax,oe,bj] [--repeat 2] [--out bench/poly_directions.md]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings

RECORDS = ["dryer", "exchanger", "robot_arm", "evaporator", "glassfurnace", "steamgen"]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", nargs="*", default=RECORDS)
    parser.add_argument("--methods", default="armax,oe,bj")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__),
                                                      "poly_directions.md"))
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    import numpy as np

    import subid
    from subid.methods.dt import pem_poly

    written = pem_poly._Output.directions

    def reference(self, theta):
        """The unit-step central differences of two realisations per coefficient (the
        library's computation before the change)."""
        base = self.predictor(theta)
        n, d = base[0].shape[0], self.size
        out = [np.zeros((d + n,) + m.shape) for m in base]
        for j in range(d):
            e = np.zeros(d)
            e[j] = 1.0
            plus, minus = self.predictor(theta + e), self.predictor(theta - e)
            for k in range(4):
                out[k][j] = 0.5 * (plus[k] - minus[k])
        dx0 = np.zeros((d + n, n))
        dx0[d:] = np.eye(n)
        return (*out, dx0)

    rows = []
    for name in args.records:
        d = subid.datasets.load(name)
        cut = 2 * d.n_samples // 3
        mu, my = d.u[:cut].mean(axis=0), d.y[:cut].mean(axis=0)
        est = subid.IOData(d.u[:cut] - mu, d.y[:cut] - my, dt=d.dt)
        val = subid.IOData(d.u[cut:] - mu, d.y[cut:] - my, dt=d.dt)
        for method in args.methods.split(","):
            fn = getattr(subid, method)
            times, models = {"reference": [], "written": []}, {}
            for _ in range(args.repeat):
                for path, directions in (("reference", reference), ("written", written)):
                    pem_poly._Output.directions = directions
                    t0 = time.process_time()
                    models[path] = fn(est)
                    times[path].append(time.process_time() - t0)
            pem_poly._Output.directions = written
            ref, now = (statistics.median(times[p]) for p in ("reference", "written"))
            fits = [float(np.mean(subid.fit_percent(models[p], val, x0="estimate")))
                    for p in ("reference", "written")]
            A0, A1 = models["reference"].A, models["written"].A
            diff = float(np.abs(A0 - A1).max() / max(np.abs(A0).max(), 1e-300)) \
                if A0.shape == A1.shape else float("inf")
            rows.append(f"| {name} | {method} | {models['written'].order} | {ref:.2f} | "
                        f"{now:.2f} | {now / ref:.2f} | {fits[0]:.3f} | {fits[1]:.3f} | "
                        f"{diff:.1e} |")
            print(rows[-1], flush=True)
    text = "\n".join([
        "# The predictor's derivatives of ARMAX, OE and BJ written out "
        "(bench/poly_directions.py)", "",
        f"Median CPU seconds of {args.repeat} calls per path, alternated in one process, "
        f"OPENBLAS_NUM_THREADS=1, load average {os.getloadavg()[1]:.1f} at the end. "
        "Reference: the unit-step central differences (module docstring).", "",
        "| record | method | order | reference s | now s | ratio | validation fit, "
        "reference | now | A difference |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|", *rows, ""])
    with open(args.out, "w") as f:   # noqa: SIM115 - the benchmark's table
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
