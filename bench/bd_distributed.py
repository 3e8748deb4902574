"""Distributed and streamed identification against the in-memory default (issue 14.2).

A random stable 4th-order 2x2 system, 2e5 samples at 30 dB output SNR, on a
2-worker Dask LocalCluster (chunks of 25,013 samples): the largest relative
difference of A, B, C, D between ``subid.methods.dt.distributed.identify`` and the
in-memory default with the same statistic, and the Markov errors of both and
of the statistic-only projection; then robot_arm (DaISy) streamed in pieces
through ``identify_stream`` against in memory, with validation fits.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python bench/bd_distributed.py
"""
from __future__ import annotations

import numpy as np


def _largest_difference(model, reference):
    return max(float(np.abs(getattr(model, k) - getattr(reference, k)).max()
                     / np.abs(getattr(reference, k)).max()) for k in "ABCD")


def main() -> int:
    import dask.array as da
    from dask.distributed import Client, LocalCluster

    import subid
    from subid import datasets, systems
    from subid.methods.dt import distributed as sd

    true = systems.random_system(4, 2, 2, seed=1)
    data = systems.simulate_data(true, 200_000, seed=2, output_snr_db=30)
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    client = Client(cluster)
    u = da.from_array(data.u, chunks=(25_013, 2))
    y = da.from_array(data.y, chunks=(25_013, 2))
    for method, fn in (("moesp", subid.moesp), ("ls", subid.ls_subspace),
                       ("n4sid", subid.n4sid)):
        single = fn(data, 4, horizon=10, statistic="gram")
        dist = sd.identify(u, y, method, order=4, horizon=10, client=client)
        proj = sd.identify(u, y, method, order=4, horizon=10, client=client,
                           **({} if method == "n4sid" else {"bd_method": "projection"}))
        print(f"{method}: distributed vs in-memory default, largest relative difference of "
              f"A, B, C, D {_largest_difference(dist, single):.1e}; Markov error in memory "
              f"{subid.markov_error(single, true):.4e}, distributed "
              f"{subid.markov_error(dist, true):.4e}, statistic-only projection "
              f"{subid.markov_error(proj, true):.4e}")
    client.close()
    cluster.close()

    record = datasets.load("robot_arm")
    cut = 2 * record.n_samples // 3
    est = record[:cut].detrend()
    mean_u, mean_y = record[:cut].u.mean(axis=0), record[:cut].y.mean(axis=0)
    val = subid.IOData(record[cut:].u - mean_u, record[cut:].y - mean_y, dt=record.dt)
    for order in (4, 6):
        memory = subid.moesp(est, order, horizon=10, statistic="gram")
        for size in (97, 100_000):
            pieces = [est[a:a + size] for a in range(0, cut, size)]
            streamed = subid.identify_stream(pieces, "moesp", order, 10)
            projection = subid.identify_stream(pieces, "moesp", order, 10,
                                               bd_method="projection")
            print(f"robot_arm moesp order {order}, pieces of {size}: streamed vs in memory "
                  f"{_largest_difference(streamed, memory):.1e}; validation fit in memory "
                  f"{np.mean(subid.fit_percent(memory, val)):.2f} %, streamed "
                  f"{np.mean(subid.fit_percent(streamed, val)):.2f} %, projection "
                  f"{np.mean(subid.fit_percent(projection, val)):.2f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
