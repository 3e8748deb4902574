"""Which refinements ``subid.identify`` keeps, on random systems, for two trees.

12 random 2x2 systems of orders 2..6 (seeds 100..111), 15 dB output noise, 2,000
samples to estimate and 1,000 to validate: the chosen order, whether the refinement
was kept and the validation fit (simulation, %, mean over outputs). Run it once per
tree, then compare::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=<old tree>/src python bench/identify_keep.py run old.json
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/identify_keep.py run new.json
    python bench/identify_keep.py compare old.json new.json
"""

import json
import sys
import warnings


def run(path):
    import numpy as np

    import subid
    from subid import systems
    warnings.simplefilter("ignore")
    out = []
    for seed in range(12):
        true = systems.random_system(2 + seed % 5, 2, 2, seed=100 + seed)
        data = systems.simulate_data(true, 3000, seed=200 + seed, output_snr_db=15)
        est, val = data[:2000], data[2000:]
        model = subid.identify(est)
        kept = bool(model.info["identify"]["refinement"].get("kept"))
        out.append([seed, model.order, kept, float(np.mean(subid.fit_percent(model, val)))])
    with open(path, "w") as fh:
        json.dump(out, fh)


def compare(old_path, new_path):
    with open(old_path) as fh:
        old = json.load(fh)
    with open(new_path) as fh:
        new = json.load(fh)
    print("| seed | order (old, new) | kept (old, new) | validation fit old | new - old |")
    print("|---:|---|---|---:|---:|")
    for a, b in zip(old, new):
        print(f"| {a[0]} | {a[1]}, {b[1]} | {a[2]}, {b[2]} | {a[3]:.3f} | {b[3] - a[3]:+.4f} |")
    changed = sum(a[2] != b[2] for a, b in zip(old, new))
    print(f"\nkept: {sum(a[2] for a in old)} -> {sum(b[2] for b in new)} of {len(old)}; "
          f"{changed} decisions changed; largest fit change "
          f"{max(abs(b[3] - a[3]) for a, b in zip(old, new)):.4f} points")


if __name__ == "__main__":
    if sys.argv[1:2] == ["run"]:
        run(sys.argv[2])
    elif sys.argv[1:2] == ["compare"]:
        compare(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
