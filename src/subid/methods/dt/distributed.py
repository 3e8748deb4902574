"""Identification beyond one machine, with Dask.

Why Dask: the work splits into independent pieces whose results combine
exactly (the :class:`~subid.HankelStatistic` of consecutive partitions merge
with the rows that straddle their borders), which is the task-graph model
Dask schedules well; Dask arrays already give users time-chunked data from
Zarr/HDF5/Parquet/CSV; and the same code runs on threads, on a
``LocalCluster`` or on a cluster of machines, without a separate service
to run. Dask is optional (``pip install "dask[distributed]"``).

Point the functions at an existing cluster by connecting a client first;
Dask then uses it by default, or pass it explicitly::

    from dask.distributed import Client
    client = Client("tcp://scheduler-host:8786")      # the scheduler's address
    model = subid.methods.dt.distributed.identify(u, y, method="moesp", dt=0.01, order=4)

Without a client, Dask's default scheduler of the current process is used
(threads for dask arrays).

* :func:`identify` — one record held as dask arrays chunked along time:
  per-chunk statistics on the workers, merged in time order on the workers
  (a tree of merges), then the identification on the small statistic; B, D
  and x0 by the output regression of the in-memory default, as a second
  pass whose per-chunk normal equations merge exactly (:mod:`subid.methods.dt._bd_pass`).
* :func:`identify_files` — one record stored as consecutive files (say one
  file per day of a plant historian); each worker reads its files in pieces.
* :func:`fan_out` / :func:`identify_many` — many independent records (a
  fleet of units, a Monte-Carlo study): one task per record, models and a
  summary table back.
"""

from __future__ import annotations

import math
import time

import numpy as np

from subid.errors import DataError, OptionError, SubidError
from subid.io.formats import read_chunks
from subid.methods.dt._bd_pass import OutputRegression
from subid.methods.dt.stream import statistic_depth, streaming_method
from subid.methods.registry import find
from subid.statistic.hankel import HankelStatistic

__all__ = ["identify", "identify_files", "fan_out", "identify_many", "summary_markdown"]


def _check_client(client) -> None:
    """``client`` is None or a Dask client (anything with ``compute``, ``gather`` and
    ``map``); else :class:`OptionError` (an address string met an AttributeError deep
    inside)."""
    if client is None or all(callable(getattr(client, name, None))
                             for name in ("compute", "gather", "map")):
        return
    hint = f" (connect to it first: dask.distributed.Client({client!r}))" \
        if isinstance(client, str) else ""
    raise OptionError(f"client must be a dask.distributed.Client or None, got "
                      f"{type(client).__name__} {client!r}{hint}"[:400])


def _dask():
    try:
        import dask
        import dask.array  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the install
        from subid._extras import install_hint
        raise ImportError("subid.distributed needs Dask: "
                          + install_hint("distributed", '"dask[distributed]"')) from exc
    return dask


def _block_statistic(u_block, y_block, depth, kind, start=0):
    for name, block in (("input u", u_block), ("output y", y_block)):
        block = np.asarray(block)
        finite = np.isfinite(block).all(axis=1) if block.ndim == 2 else np.isfinite(block)
        if not finite.all():                 # rows of the whole record, not of the block
            bad = np.flatnonzero(~finite)
            rows = ", ".join(str(start + int(r)) for r in bad[:5])
            raise DataError(f"{name} has {bad.size} row{'s' if bad.size != 1 else ''} with "
                            f"NaN or infinite values in the partition starting at sample "
                            f"{start} (row{'s' if bad.size != 1 else ''} {rows}"
                            f"{', ...' if bad.size > 5 else ''} of the "
                            "record); remove or interpolate them before identification")
    stat = HankelStatistic(u_block.shape[1], y_block.shape[1], depth, kind=kind)
    return stat.update(u_block, y_block)


def _file_statistic(path, inputs, outputs, depth, kind, chunk_size, delimiter):
    stat = None
    # dt: set on the merged statistic (_finish); 1.0 here, without read_chunks' hint
    for piece in read_chunks(path, inputs, outputs, dt=1.0, chunk_size=chunk_size,
                             delimiter=delimiter):
        if stat is None:
            stat = HankelStatistic(piece.n_inputs, piece.n_outputs, depth, kind=kind,
                                   input_names=piece.input_names,
                                   output_names=piece.output_names)
        stat.update(piece.u, piece.y)
    if stat is None:
        raise DataError(f"{path} holds no samples")
    return stat


def _merge(first, second, new_experiment=False):
    return first.merge(second, new_experiment=new_experiment)


def _tree_merge(dask, parts, new_experiment=False):
    """Merge delayed statistics pairwise, keeping time order (``new_experiment``:
    every part is an experiment of its own, :func:`subid.merge`)."""
    while len(parts) > 1:
        parts = [dask.delayed(_merge)(parts[k], parts[k + 1], new_experiment)
                 if k + 1 < len(parts) else parts[k] for k in range(0, len(parts), 2)]
    return parts[0]


def _apply_block(function, u_block, y_block, *arguments):
    return function([(u_block, y_block)], *arguments)


def _apply_file(function, path, inputs, outputs, chunk_size, delimiter, *arguments):
    chunks = ((p.u, p.y) for p in read_chunks(path, inputs, outputs, dt=1.0,
                                               chunk_size=chunk_size, delimiter=delimiter))
    return function(chunks, *arguments)


def _compute_all(dask, tasks, client):
    if client is not None:
        return client.gather(client.compute(tasks))
    return list(dask.compute(*tasks))


def _second_pass(stat, dask, client, make_task, n_pieces, options, experiments=None):
    """Attach the distributed B, D, x0 regression to ``stat`` (unless projection);
    ``experiments``: the experiment of every piece."""
    if options.get("bd_method", "auto") == "projection":
        return

    def map_pieces(function, arguments):
        return _compute_all(dask, [make_task(k, function, arguments[k])
                                   for k in range(n_pieces)], client)
    stat.output_regression = OutputRegression(map_pieces, n_pieces, stat.n_inputs,
                                              stat.n_outputs, experiments=experiments)


def _compute(dask, value, client):
    if client is not None:
        return client.compute(value).result()
    return dask.compute(value)[0]


def _as_dask_pair(u, y):
    import dask.array as da
    u = u if isinstance(u, da.Array) else da.asarray(u)
    y = y if isinstance(y, da.Array) else da.asarray(y)
    if u.ndim == 1:
        u = u[:, None]
    if y.ndim == 1:
        y = y[:, None]
    if u.ndim != 2 or y.ndim != 2:
        raise DataError(f"u and y must be 1-D or 2-D with time on axis 0, got shapes "
                        f"{u.shape} and {y.shape}")
    for name, arr in (("u", u), ("y", y)):
        if any(math.isnan(c) for c in arr.chunks[0]):
            raise DataError(f"the chunk sizes of {name} along time are unknown (a Dask array "
                            "made from a dataframe's .values, or after boolean indexing); "
                            f"call {name}.compute_chunk_sizes() first, or build it with "
                            "dataframe.to_dask_array(lengths=True)")
    if u.shape[0] != y.shape[0]:
        raise DataError(f"input u has {u.shape[0]} samples but output y has {y.shape[0]}")
    u = u.rechunk({1: -1})
    y = y.rechunk({0: u.chunks[0], 1: -1})
    return u, y


def identify(u, y, method: str = "moesp", *, dt: float = 1.0, order=None, horizon=None,
             statistic: str = "gram", input_names=None, output_names=None, client=None,
             **method_options):
    """Identify one record held as Dask arrays chunked along time.

    Parameters
    ----------
    u, y : dask.array.Array (or array_like)
        Inputs (N, nu) and outputs (N, ny), time on axis 0, chunked along
        time (any chunk sizes; chunk borders lose nothing: the Hankel
        columns that straddle them are added when partitions merge).
    method : {'moesp', 'n4sid', 'ls'}
    dt : float
        Sampling period.
    order, horizon
        As for the method (the horizon must be fixed before the data are
        reduced).
    statistic : {'gram', 'qr'}
        Kind of per-partition statistic (see :mod:`subid.statistic.hankel`).
    input_names, output_names : sequence of str, optional
        Channel names of the model.
    client : dask.distributed.Client, optional
        Default: Dask's current default scheduler (a connected client, or
        threads).
    **method_options
        Passed to the method.

    Returns
    -------
    StateSpace
        Equal to the in-memory identification with the same statistic
        (``method(data, ..., statistic=statistic)``): B, D and x0 by the output
        regression, as a second pass over the chunks (``bd_method='projection'``
        keeps the statistic-only B and D and one pass).
    """
    _check_client(client)
    dask = _dask()
    u, y = _as_dask_pair(u, y)
    horizon, depth = statistic_depth(method, order, horizon, y.shape[1],
                                     method_options.get("instruments", "past"))
    u_blocks = u.to_delayed().ravel()
    y_blocks = y.to_delayed().ravel()
    starts = np.concatenate([[0], np.cumsum(u.chunks[0])[:-1]]).astype(int)
    parts = [dask.delayed(_block_statistic)(ub, yb, depth, statistic, int(a))
             for ub, yb, a in zip(u_blocks, y_blocks, starts)]
    stat = _compute(dask, _tree_merge(dask, parts), client)
    _second_pass(stat, dask, client,
                 lambda k, function, args: dask.delayed(_apply_block)(function, u_blocks[k],
                                                                      y_blocks[k], *args),
                 len(u_blocks), method_options)
    return _finish(stat, method, order, horizon, dt, input_names, output_names,
                   method_options)


def identify_files(paths, inputs, outputs, method: str = "moesp", *, dt: float = 1.0,
                   order=None, horizon=None, statistic: str = "gram", chunk_size=100_000,
                   delimiter=None, client=None, experiments: bool = False,
                   **method_options):
    """Identify one record stored as consecutive files, read on the workers.

    Parameters
    ----------
    paths : sequence of str
        Files in time order (each any format :func:`subid.read_chunks`
        reads). The record continues from one file to the next: samples at
        the borders form Hankel columns with the neighbouring file.
    inputs, outputs
        Columns, as in :func:`subid.read_chunks`.
    method, dt, order, horizon, statistic
        As in :func:`identify`.
    chunk_size : int
        Samples per piece read from a file (:func:`subid.read_chunks`).
    delimiter : str, optional
        Column separator of text files, as in :func:`subid.read_chunks`.
    client
        As in :func:`identify`.
    experiments : bool
        ``True``: every file is an experiment of its own (:func:`subid.merge`):
        no Hankel column crosses from one file to the next, and x0 is
        estimated once per file (``info['x0']`` one row per file).
    **method_options
        As in :func:`identify`.
    """
    _check_client(client)
    dask = _dask()
    paths = [str(p) for p in paths]
    if not paths:
        raise DataError("identify_files needs at least one file")
    first = next(iter(read_chunks(paths[0], inputs, outputs, dt=1.0, chunk_size=16)), None)
    if first is None:
        raise DataError(f"{paths[0]} holds no samples")
    from subid.data import check_same_channels
    for k, p in enumerate(paths[1:], start=2):    # columns by position: the same names
        head = next(iter(read_chunks(p, inputs, outputs, dt=1.0, chunk_size=16)), None)
        if head is not None:
            check_same_channels(head, first, f"{p} (file {k})", f"{paths[0]} (file 1)")
    horizon, depth = statistic_depth(method, order, horizon, first.n_outputs,
                                     method_options.get("instruments", "past"))
    parts = [dask.delayed(_file_statistic)(p, inputs, outputs, depth, statistic, chunk_size,
                                           delimiter) for p in paths]
    stat = _compute(dask, _tree_merge(dask, parts, bool(experiments)), client)
    _second_pass(stat, dask, client,
                 lambda k, function, args: dask.delayed(_apply_file)(
                     function, paths[k], inputs, outputs, chunk_size, delimiter, *args),
                 len(paths), method_options,
                 experiments=list(range(len(paths))) if experiments else None)
    return _finish(stat, method, order, horizon, dt, first.input_names, first.output_names,
                   method_options)


def _finish(stat, method, order, horizon, dt, input_names, output_names, options):
    from subid._validation import check_dt
    stat.dt = check_dt(dt)
    if input_names is not None:
        stat.input_names = tuple(input_names)
    if output_names is not None:
        stat.output_names = tuple(output_names)
    return streaming_method(method).load()(stat, order, horizon=horizon, **options)


def fan_out(function, items, *, client=None, progress=None):
    """Run ``function(item)`` for every item as independent Dask tasks.

    Parameters
    ----------
    function : callable
        Must be importable by the workers (a module-level function).
    items : sequence
        One task per item (records, seeds, file names, ...).
    client : dask.distributed.Client, optional
        Default: Dask's current default scheduler.
    progress : callable, optional
        Wraps the iterator of completed results when a client is given
        (e.g. ``tqdm.tqdm``).

    Returns
    -------
    list
        ``function(item)`` in the order of ``items``.
    """
    _check_client(client)
    dask = _dask()
    items = list(items)
    if client is None:
        return list(dask.compute(*[dask.delayed(function)(item) for item in items]))
    from dask.distributed import as_completed
    futures = client.map(function, items, pure=False)
    index = {f.key: k for k, f in enumerate(futures)}
    results = [None] * len(items)
    completed = as_completed(futures, with_results=True)
    for future, result in (completed if progress is None else progress(completed,
                                                                        total=len(items))):
        results[index[future.key]] = result
    return results


def _identify_one(job):
    record, method, order, options = job
    start = time.perf_counter()
    try:
        model = find(method, kind="batch").load()(record, order, **options)
        error = None
    except SubidError as exc:
        model, error = None, str(exc)
    return model, error, time.perf_counter() - start


def identify_many(records, method: str = "moesp", order=None, *, names=None, client=None,
                  progress=None, **method_options):
    """Identify many independent records (a fleet, a Monte-Carlo study).

    Parameters
    ----------
    records : sequence of IOData (or HankelStatistic)
    method : str
        A batch method of :data:`subid.registry.METHODS` (``'moesp'``,
        ``'n4sid'``, ``'ls'``, ``'ct'``, ...); a statistic needs one with the
        ``streaming`` capability.
    order : int, None or candidates
    names : sequence of str, optional
        Labels of the records in the summary (default ``record0``, ...).
    client, progress
        As in :func:`fan_out`.
    **method_options
        Passed to the method.

    Returns
    -------
    models : list of StateSpace or None
        None where the identification failed (its error is in the summary).
    summary : list of dict
        Per record: ``name``, ``order``, ``stable``, ``seconds``, ``error``.
    """
    find(method, kind="batch")                 # OptionError naming the methods
    records = list(records)
    names = [f"record{k}" for k in range(len(records))] if names is None else list(names)
    if len(names) != len(records):
        raise DataError(f"{len(names)} names for {len(records)} records")
    jobs = [(r, method, order, method_options) for r in records]
    results = fan_out(_identify_one, jobs, client=client, progress=progress)
    models, summary = [], []
    for name, (model, error, seconds) in zip(names, results):
        models.append(model)
        summary.append({"name": name, "order": None if model is None else model.order,
                        "stable": None if model is None else bool(model.is_stable()),
                        "seconds": seconds, "error": error})
    return models, summary


def summary_markdown(summary) -> str:
    """The summary of :func:`identify_many` as a Markdown table."""
    lines = ["| record | order | stable | time (s) | error |", "|---|---:|---|---:|---|"]
    for row in summary:
        lines.append(f"| {row['name']} | {row['order'] if row['order'] is not None else '—'} | "
                     f"{'' if row['stable'] is None else ('yes' if row['stable'] else 'NO')} | "
                     f"{row['seconds']:.3f} | {row['error'] or ''} |")
    return "\n".join(lines)
