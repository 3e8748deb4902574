"""The cost of ``subid.identify(data)`` against SIPPY's own order search (issue 21).

2x2 order-4 random system (seed 1), 20 dB output noise, 100,000 samples: CPU time of
``subid.identify(data)`` (refinement included), of the subspace model it starts from
(``subid.identify(data, refine=False)``: both estimators' cross-validations), of
``subid.moesp(data)`` and of SIPPY's N4SID with its AIC search (orders 1..10,
f = p = 10), interleaved, median of three rounds. The refinement's cost is
identify's minus the subspace model's. Needs SIPPY (the benchmark venv)::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/identify_cost.py
"""

import statistics
import time
import warnings

from sippy_unipi import system_identification

import subid
from subid import systems

ROUNDS = 3

warnings.simplefilter("ignore")
true = systems.random_system(4, 2, 2, seed=1)
warm = systems.simulate_data(true, 2000, seed=3, output_snr_db=20)
data = systems.simulate_data(true, 100_000, seed=2, output_snr_db=20)


def sippy(d):
    return system_identification(d.y.T, d.u.T, "N4SID", IC="AIC", SS_orders=[1, 10],
                                 SS_f=10, SS_p=10, SS_D_required=True)


def subspace(d):
    return subid.identify(d, refine=False)


calls = {"identify": subid.identify, "subspace": subspace, "moesp": subid.moesp,
         "sippy": sippy}
for f in calls.values():
    f(warm)
t = {k: [] for k in calls}
for _ in range(ROUNDS):
    for k, f in calls.items():
        t0 = time.process_time()
        f(data)
        t[k].append(time.process_time() - t0)
med = {k: statistics.median(v) for k, v in t.items()}
refinement = statistics.median(a - b for a, b in zip(t["identify"], t["subspace"]))
print({k: [round(x, 3) for x in v] for k, v in t.items()})
print(f"identify {med['identify']:.2f} s, its subspace model {med['subspace']:.2f} s, "
      f"refinement {refinement:.2f} s, moesp {med['moesp']:.2f} s, SIPPY {med['sippy']:.2f} s")
print(f"identify/SIPPY {med['identify'] / med['sippy']:.2f}, refinement/subspace "
      f"{refinement / med['subspace']:.2f}")
