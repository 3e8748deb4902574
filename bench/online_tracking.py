"""How fast RecursiveSubspace tracks an abrupt switch, in memories ``1 / (1 - λ)``.

Noise-free data: 4,000 samples of one random 3-state 2x2 system, then 6,000 of another
(``subid.systems.random_system(3, 2, 2, seed=...)``, white inputs); after every 25
samples of the second system the Markov error of the current model against it
(``subid.markov_error``). The table gives, per switch and forgetting factor, the
memories after the switch until the error falls below 1e-2 and 1e-3, and the error 2, 5
and 10 memories after it. Run::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/online_tracking.py \
        > bench/online_tracking.md
"""

import warnings

import subid

PAIRS = ((1, 2), (2, 1), (11, 12), (12, 11), (3, 4), (5, 6))
FORGETTING = (0.99, 0.995)
STEP = 25


def recovery(before, after, forgetting, n_before=4000, n_after=6000):
    first = subid.systems.simulate_data(before, n_before, seed=10)
    second = subid.systems.simulate_data(after, n_after, seed=11)
    ident = subid.RecursiveSubspace(3, 2, 2, forgetting=forgetting).update(first.u, first.y)
    memory = 1.0 / (1.0 - forgetting)
    reached, at = {}, {}
    for k in range(STEP, n_after + 1, STEP):
        ident.update(second.u[k - STEP:k], second.y[k - STEP:k])
        error = subid.markov_error(ident.model, after)
        for m in (2, 5, 10):
            if abs(k - m * memory) < STEP / 2:
                at[m] = error
        for level in (1e-2, 1e-3):
            if level not in reached and error < level:
                reached[level] = k / memory
    return reached, at


def main():
    warnings.simplefilter("ignore")
    print(__doc__.split("Run::")[0].strip())
    print()
    print("| switch (system seeds) | λ | memories to < 1e-2 | memories to < 1e-3 | "
          "error at 2 / 5 / 10 memories |")
    print("|---|---:|---:|---:|---|")
    for a, b in PAIRS:
        before = subid.systems.random_system(3, 2, 2, seed=a)
        after = subid.systems.random_system(3, 2, 2, seed=b)
        for lam in FORGETTING:
            reached, at = recovery(before, after, lam)
            cells = [f"{reached[level]:.1f}" if level in reached else "—"
                     for level in (1e-2, 1e-3)]
            print(f"| {a} -> {b} | {lam} | {cells[0]} | {cells[1]} | "
                  + " / ".join(f"{at.get(m, float('nan')):.2g}" for m in (2, 5, 10)) + " |",
                  flush=True)


if __name__ == "__main__":
    main()
