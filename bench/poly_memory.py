"""Time and peak memory of a polynomial method on a long record.

``oe(data, 2)`` (``--call oe``, the default) or the default call ``arx(data)``,
``armax(data)`` or ``bj(data)`` (``--call arx|armax|bj``: the structure chosen) on 10^6
samples of the 2x2 order-4 system of the other benchmarks
(20 dB output noise), in a fresh process (peak resident memory, ``ru_maxrss``), after
a call on 3,000 samples that compiles the kernels. Run:
``OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/poly_memory.py [--samples N]
[--call oe|arx|armax|bj] [--system-seed S]``; prints one line (bench/poly_cost.md holds
the figures). ``--system-seed`` draws another random system (the cost depends on it: the
structure chosen and the iterations of the search).
"""

from __future__ import annotations

import argparse
import resource
import time
import warnings


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--call", choices=("oe", "arx", "armax", "bj"), default="oe")
    parser.add_argument("--system-seed", type=int, default=29,
                        help="seed of the random 2x2 order-4 system (default 29)")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    import subid
    true = subid.systems.random_system(4, 2, 2, seed=args.system_seed)
    data = subid.systems.simulate_data(true, args.samples, seed=30, output_snr_db=20)
    def call(record):
        return subid.oe(record, 2) if args.call == "oe" else getattr(subid, args.call)(record)
    call(data[:3000])
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t, c = time.perf_counter(), time.process_time()
    call(data)
    label = "oe(data, 2)" if args.call == "oe" else f"{args.call}(data)"
    label += f", system seed {args.system_seed}"
    print(f"{label}, {args.samples} samples: {time.perf_counter() - t:.1f} s wall, "
          f"{time.process_time() - c:.1f} CPU s, peak resident memory "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB "
          f"({before / 1e6:.2f} GB before the call)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
