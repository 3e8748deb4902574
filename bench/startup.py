"""Start-up, first-call compile and single-sample update cost (issue 14 items 5, 6).

The single-sample figures are AdaptiveIdentifier's (the target) and, for
comparison, RecursiveSubspace's.

Run: OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/startup.py [--repeat 7]

Every figure is a median over fresh interpreters (subprocesses) or repeated
calls in this process; ratios are formed from figures measured in this run.
Cold numba compilation uses an empty NUMBA_CACHE_DIR (a fresh install has no
cache unless it ships one); warm uses the same directory again; "after
warm-up" runs ``python -m subid.warmup`` (what ``make test``/``make demo`` run
after installing) on an empty directory, then the first update.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

PY = sys.executable
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1")


def wall(code, env=None, repeat=5):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([PY, "-c", code], env=env or ENV, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def inner(code, env, repeat):
    """Median of the seconds a child prints (its own timing of one step)."""
    out = []
    for _ in range(repeat):
        r = subprocess.run([PY, "-c", code], env=env, check=True, capture_output=True, text=True)
        out.append(float(r.stdout.strip().splitlines()[-1]))
    return statistics.median(out)


FIRST_UPDATE = """
import time, numpy as np
from subid import AdaptiveIdentifier
rng = np.random.default_rng(0)
u = rng.standard_normal((200, 2)); y = rng.standard_normal((200, 2))
ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-3)
t0 = time.perf_counter(); ident.update(u, y); print(time.perf_counter() - t0)
"""

FIRST_CT = """
import time, numpy as np
import subid
sys_ = subid.systems.seed000_system()
rng = np.random.default_rng(0)
t = np.arange(2000) * 1e-2
u = rng.standard_normal((2000, 2))
y = sys_.simulate(u, t=t, hold="foh")
data = subid.IOData(u, y, t=t)
fn = subid.ct_subspace          # imported before the clock starts (lazy import)
t0 = time.perf_counter(); fn(data, 4); print(time.perf_counter() - t0)
"""


def single_update(repeat):
    import numpy as np

    from subid import AdaptiveIdentifier
    rng = np.random.default_rng(0)
    u = rng.standard_normal((20_000, 2))
    y = rng.standard_normal((20_000, 2))
    ident = AdaptiveIdentifier(4, 2, 2, horizon=5, dt=1e-3)
    ident.update(u[:1000], y[:1000])                       # compile, settle
    one = _one_sample_cost(ident, u, y, repeat)
    # the kernel alone on the same single samples: a chunk of 2000 samples
    per_chunk = []
    for r in range(repeat):
        a = 1000 + (repeat + r) * 2000
        t0 = time.perf_counter()
        ident.update(u[a:a + 2000], y[a:a + 2000])
        per_chunk.append((time.perf_counter() - t0) / 2000)
    return one, statistics.median(per_chunk)


def single_update_recursive(repeat, **settings):
    """Median cost of one ``RecursiveSubspace.update(u_k, y_k)`` (seconds)."""
    import numpy as np

    from subid import RecursiveSubspace
    rng = np.random.default_rng(0)
    u = rng.standard_normal((2000 * repeat + 1000, 2))
    y = rng.standard_normal((2000 * repeat + 1000, 2))
    ident = RecursiveSubspace(4, 2, 2, horizon=5, **settings)
    ident.update(u[:1000], y[:1000])                       # compile, settle
    return _one_sample_cost(ident, u, y, repeat)


def _one_sample_cost(ident, u, y, repeat):
    """Median cost (seconds) of ``ident.update(u[k], y[k])``, one sample a call, over
    ``repeat`` runs of 2000 samples from sample 1000 on."""
    per = []
    for r in range(repeat):
        a = 1000 + r * 2000
        t0 = time.perf_counter()
        for k in range(a, a + 2000):
            ident.update(u[k], y[k])
        per.append((time.perf_counter() - t0) / 2000)
    return statistics.median(per)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--skip-cold", action="store_true")
    a = ap.parse_args()
    rep = a.repeat
    print(f"python {sys.version.split()[0]}, repeat {rep} (medians)")
    base = wall("import numpy, scipy.linalg", repeat=rep)
    imp = wall("import subid", repeat=rep)
    cli_help = wall("import sys; from subid.cli.commands import main; sys.exit(main(['--help']))",
                    repeat=rep)
    module_help = wall("import runpy, sys; sys.argv = ['subid', '--help']; "
                       "runpy.run_module('subid', run_name='__main__')", repeat=rep)
    print(f"import numpy, scipy.linalg      {base:8.3f} s")
    print(f"import subid                    {imp:8.3f} s   ratio {imp / base:5.2f} (target <= 1.5)")
    print(f"subid --help (python -c main)   {cli_help:8.3f} s   (target < 1 s)")
    print(f"python -m subid --help          {module_help:8.3f} s")
    if not a.skip_cold:
        with tempfile.TemporaryDirectory() as cache:
            env = dict(ENV, NUMBA_CACHE_DIR=cache)
            cold = inner(FIRST_UPDATE, env, 1)
            warm = inner(FIRST_UPDATE, env, rep)
            print(f"first AdaptiveIdentifier.update cold cache {cold:8.2f} s, "
                  f"warm cache {warm:6.3f} s")
        with tempfile.TemporaryDirectory() as cache:
            # a fresh install that ran `python -m subid.warmup` (make test / make demo do)
            env = dict(ENV, NUMBA_CACHE_DIR=cache)
            t0 = time.perf_counter()
            subprocess.run([PY, "-m", "subid.warmup", "--quiet", "--only", "adaptive"],
                           env=env, check=True)
            pre = time.perf_counter() - t0
            after = inner(FIRST_UPDATE, env, rep)
            print(f"python -m subid.warmup --only adaptive {pre:8.2f} s; then the first "
                  f"AdaptiveIdentifier.update {after:6.3f} s")
        with tempfile.TemporaryDirectory() as cache:
            env = dict(ENV, NUMBA_CACHE_DIR=cache)
            cold = inner(FIRST_CT, env, 1)
            warm = inner(FIRST_CT, env, rep)
            print(f"first ct_subspace (L=2000)        cold cache {cold:8.2f} s, "
                  f"warm cache {warm:6.3f} s")
    one, chunk = single_update(rep)
    print(f"single-sample update            {one * 1e6:8.1f} us   (target < 15 us); "
          f"per sample in a 2000-sample chunk {chunk * 1e6:6.2f} us")
    rs = single_update_recursive(rep)
    rs_forget = single_update_recursive(rep, forgetting=0.99)
    print(f"RecursiveSubspace single-sample update {rs * 1e6:6.1f} us (forgetting 1), "
          f"{rs_forget * 1e6:6.1f} us (forgetting 0.99)")


if __name__ == "__main__":
    main()
