"""Identification of records larger than memory, from their statistic.

A record is read piece by piece (:func:`subid.read_chunks`, or any iterable
of :class:`IOData` pieces), reduced to its :class:`HankelStatistic` and
identified from the statistic: memory stays bounded by one piece plus
a matrix of ``(2 * horizon * (nu + ny))^2`` numbers, however long the record.
When the pieces can be read again (a file, a list of pieces, or ``reread``),
B, D and x0 come from the output regression of the in-memory default, done as
a second pass over the pieces (:mod:`subid.methods.dt._bd_pass`), so the model is the
in-memory one; a one-shot iterator leaves the statistic-only projection.

Several experiments: the pieces are consecutive pieces of one record unless
the caller says otherwise, in one of two ways: a piece that holds several
experiments (made by :func:`subid.merge`) contributes its own borders (its
first experiment continues the previous piece, the others are new), and the
marker :data:`NEW_EXPERIMENT` between two pieces starts a new experiment.
:func:`identify_file` with a list of files takes every file as one experiment.
No Hankel column and no simulated trajectory then crosses a border, and x0 is
estimated once per experiment, exactly as for the merged record in memory.
"""

from __future__ import annotations

import itertools
import logging
import os
import sys
import tempfile
import warnings

import numpy as np

from subid._blas import serial_blas
from subid._validation import check_int, same_period
from subid.data import IOData, minus_columns
from subid.errors import DataError, OptionError
from subid.io.formats import read_chunks
from subid.methods.dt._bd_pass import OutputRegression, sequential, threaded
from subid.methods.dt._subspace import default_horizon
from subid.methods.registry import find
from subid.statistic.hankel import HankelStatistic

__all__ = ["identify_stream", "identify_file", "streaming_method", "NEW_EXPERIMENT"]

log = logging.getLogger(__name__)

#: Consecutive stretches a spooled record is cut into for the passes after the
#: parse, reduced on subid's threads: fixed, so the model does not depend on
#: the number of threads.
SPOOL_GROUPS = 4


def streaming_method(method: str):
    """The :class:`~subid.registry.MethodSpec` of a method that identifies from a
    statistic (capability ``streaming``); :class:`~subid.errors.OptionError` otherwise."""
    return find(method, kind="batch", capability="streaming")


class _NewExperiment:
    """The marker type of :data:`NEW_EXPERIMENT`."""

    def __repr__(self) -> str:
        return "subid.methods.dt.stream.NEW_EXPERIMENT"

    def __reduce__(self):
        return "NEW_EXPERIMENT"


#: Put between two pieces given to :func:`identify_stream`: the next piece
#: starts a new experiment instead of continuing the record.
NEW_EXPERIMENT = _NewExperiment()


def _segments(pieces):
    """``(experiment index, single-experiment IOData)`` for every piece in order.

    :data:`NEW_EXPERIMENT` and the borders inside a merged piece start a new
    experiment (markers before any sample, or repeated, change nothing)."""
    experiment, started = 0, False
    for k, piece in enumerate(pieces):
        if piece is NEW_EXPERIMENT:
            if started:
                experiment += 1
                started = False
            continue
        if not isinstance(piece, IOData):
            raise DataError(f"piece {k} is a {type(piece).__name__}, not an IOData record "
                            "(or subid.methods.dt.stream.NEW_EXPERIMENT)")
        for j, part in enumerate(piece.experiments):
            if j:
                experiment += 1
            yield experiment, part
            started = True


def statistic_depth(method: str, order, horizon, n_outputs: int, instruments="past") -> tuple:
    """``(horizon, depth)`` of the statistic ``method`` needs."""
    spec = streaming_method(method)
    blocks = 1 if spec.name == "ls" and instruments is None else 2
    if horizon is None:
        fixed = order if isinstance(order, int) else None
        horizon = default_horizon(fixed, n_outputs, 1, 10**18, blocks)
    else:
        horizon = check_int(horizon, "horizon", minimum=2)
    return horizon, blocks * horizon


@serial_blas
def identify_stream(pieces, method: str = "moesp", order=None, horizon=None, *,
                    statistic: str = "gram", progress=None, reread=None, **options):
    """Identify a model from consecutive pieces of one record.

    Parameters
    ----------
    pieces : iterable of IOData
        Consecutive, uniformly sampled pieces (e.g. :func:`subid.read_chunks`)
        of one record. To give several experiments, put
        :data:`NEW_EXPERIMENT` between the pieces of two experiments, or pass
        pieces made by :func:`subid.merge` (their internal borders are kept;
        the first experiment of a piece continues the previous piece). Two
        pieces are never taken for different experiments otherwise: they are
        joined as one record.
    method : {'moesp', 'n4sid', 'ls'}
        Batch method applied to the statistic: a method of
        :data:`subid.registry.METHODS` with the ``streaming`` capability.
    order, horizon
        As for the method. The horizon must be known before the data are
        read (default: 10 with an estimated order, as the batch methods).
    statistic : {'gram', 'qr'}
        Kind of :class:`HankelStatistic` (``'gram'``: fast lagged products;
        ``'qr'``: accurate to rounding, ~25x slower).
    progress : callable, optional
        Wraps the iterator of pieces of the first pass (e.g. ``tqdm.tqdm``).
    reread : callable, optional
        Returns a fresh iterable of the same pieces, for the second pass (the
        B, D, x0 regression). Default: iterate ``pieces`` again when it is a
        re-iterable collection (a list, ...). For a one-shot iterator without
        ``reread``, B and D come from the statistic only (the projection),
        with a warning.
    **options
        Passed to the method. ``bd_method='projection'`` skips the second
        pass (B and D from the statistic only, no x0).

    Returns
    -------
    StateSpace
        ``info['n_samples']`` is the length of the whole record; with several
        experiments ``info['x0']`` has one row per experiment.
    """
    try:
        iter(pieces)
    except TypeError:
        raise DataError(f"identify_stream expects an iterable of IOData pieces (a list, a "
                        f"generator, subid.read_chunks(...)), got {type(pieces).__name__}"
                        ) from None
    for name, value in (("progress", progress), ("reread", reread)):
        if value is not None and not callable(value):
            raise OptionError(f"{name} must be a function (progress: wraps the iterator of "
                              "pieces, e.g. tqdm.tqdm; reread: returns the pieces again) or "
                              f"None, got {value!r}"[:300])
    stat, first, experiment = None, None, 0
    for k, (e, piece) in enumerate(_segments(pieces if progress is None else progress(pieces))):
        if first is None:
            _check_uniform(piece, k)
            first = piece
            horizon, depth = statistic_depth(method, order, horizon, first.n_outputs,
                                             options.get("instruments", "past"))
            stat = HankelStatistic(first.n_inputs, first.n_outputs, depth, kind=statistic,
                                   dt=first.dt, input_names=first.input_names,
                                   output_names=first.output_names)
        else:
            _check_piece(piece, first, k)
        if e != experiment:
            stat.new_experiment()  # type: ignore[union-attr]  # made with the first piece
            experiment = e
        stat.update(piece.u, piece.y)  # type: ignore[union-attr]
    if stat is None:
        raise DataError("the record is empty: no pieces to identify from")
    if options.get("bd_method", "auto") != "projection":
        if reread is None and iter(pieces) is not pieces:
            reread = lambda: pieces       # noqa: E731 - a collection iterates again
        if reread is None:
            warnings.warn("identify_stream: the pieces come from a one-shot iterator, so B and "
                          "D come from the statistic only (bd_method='projection'), not from "
                          "the output regression of the in-memory default; pass a list of "
                          "pieces or reread= (a function returning them again)", stacklevel=2)
        elif stat.n_experiments == 1 and isinstance(pieces, ParsedOnce):
            attach_second_pass(stat, groups=pieces.groups(SPOOL_GROUPS))
        elif stat.n_experiments == 1:
            attach_second_pass(stat, lambda: ((p.u, p.y) for _, p in _segments(reread())))
        else:
            def map_pieces(function, arguments):
                groups = itertools.groupby(_segments(reread()), key=lambda item: item[0])
                return [function(((p.u, p.y) for _, p in group), *arguments[e])
                        for e, group in groups]
            stat.output_regression = OutputRegression(
                map_pieces, stat.n_experiments, stat.n_inputs, stat.n_outputs,
                experiments=list(range(stat.n_experiments)))
    log.info("identifying from the statistic of %d samples", stat.n_samples)
    fit = streaming_method(method).load()
    selection = None
    if order is None and reread is not None and stat.n_experiments == 1:
        if isinstance(pieces, ParsedOnce):    # a spooled file: read its last samples only
            read, count = _spooled_tail(pieces, stat.n_samples)
        else:
            read, count = (lambda: ((p.u, p.y) for _, p in _segments(reread()))), \
                stat.n_samples
        order, selection = _order_on_tail(fit, read, first, count, horizon, options)
    model = fit(stat, order, horizon=horizon, **options)
    if selection is not None:
        model.info["order_selection"] = selection
    return model


def _spooled_tail(pieces, stop: int, offsets=None):
    """``(read, count)``: the reader (:meth:`ParsedOnce.ranges`) of the last
    :data:`MAX_SELECTION_SAMPLES` samples before ``stop`` of a spooled record, and their
    count (what :func:`_order_on_tail` reads)."""
    from subid.methods.crossval import MAX_SELECTION_SAMPLES
    start = max(0, stop - MAX_SELECTION_SAMPLES)
    return pieces.ranges([(start, stop)], offsets=offsets)[0], stop - start


def _order_on_tail(fit, read_pairs, first, n_samples: int, horizon: int, options: dict,
                   call=None):
    """``(order, record)``: the order ``fit`` (the method's function) chooses by its
    in-memory default, cross-validation, on the last :data:`MAX_SELECTION_SAMPLES`
    samples of a streamed record (what the in-memory order search reads too,
    :func:`subid.methods.crossval.selection_part`), at the statistic's ``horizon``.
    ``read_pairs()`` gives the ``(u, y)`` arrays of those samples or of the whole record
    (the samples before the last ones are skipped); ``call`` as in
    :func:`identify_spooled` (the command line logs the warnings). A statistic alone only has the
    largest singular-value gap, which chose order 2 for 4th-order 2 x 2 systems at 20 dB
    on four of six seeds (validation fit 84-89 % against 90 % in memory)."""
    from subid.methods.crossval import MAX_SELECTION_SAMPLES
    start = max(0, n_samples - MAX_SELECTION_SAMPLES)
    us, ys, pos = [], [], 0
    for u, y in read_pairs():
        a, pos = pos, pos + u.shape[0]
        if pos > start:
            us.append(u[max(start - a, 0):])
            ys.append(y[max(start - a, 0):])
    tail = IOData(np.vstack(us)[-(n_samples - start):], np.vstack(ys)[-(n_samples - start):],
                  dt=first.dt, input_names=first.input_names,
                  output_names=first.output_names)
    chosen = fit(tail, None, horizon=horizon, **options) if call is None else \
        call(fit, tail, None, horizon, options)
    record = dict(chosen.info["order_selection"])
    record["streamed"] = (f"chosen on the last {tail.n_samples} samples of the record (as in "
                          f"memory), at the statistic's horizon {horizon}")
    return chosen.order, record


def _check_uniform(piece, k: int) -> None:
    """The first piece must be uniformly sampled (the statistic needs one period)."""
    if piece.dt is None:
        raise DataError(f"piece {k} is sampled with dt = None (non-uniform time stamps): the "
                        "pieces of one record must share one uniform sampling period "
                        "(resample them first)")


def _check_piece(piece, first, k: int) -> None:
    """Every piece must continue the first one: same channels, same sampling."""
    if not isinstance(piece, IOData):
        raise DataError(f"piece {k} is a {type(piece).__name__}, not an IOData record")
    if (piece.n_inputs, piece.n_outputs) != (first.n_inputs, first.n_outputs):
        raise DataError(f"piece {k} has {piece.n_inputs} inputs and {piece.n_outputs} outputs "
                        f"but the first piece has {first.n_inputs} and {first.n_outputs}")
    if first.dt is None or piece.dt is None or not same_period(piece.dt, first.dt):
        raise DataError(f"piece {k} is sampled with dt = {piece.dt} but the first piece with "
                        f"dt = {first.dt}: the pieces of one record must share one uniform "
                        "sampling period (resample them first)")


def attach_second_pass(stat: HankelStatistic, make_chunks=None, *, groups=None
                       ) -> HankelStatistic:
    """Let the methods fit B, D, x0 on the record behind ``stat`` by a second pass.

    ``make_chunks()`` returns a fresh iterable of the record's consecutive
    ``(u, y)`` arrays (as fed to the statistic). Or ``groups``: such callables
    for consecutive stretches of the record (e.g. :meth:`ParsedOnce.groups`),
    reduced on subid's threads and merged exactly.
    """
    if groups is not None:
        regression = OutputRegression(threaded(groups), len(groups), stat.n_inputs,
                                      stat.n_outputs)
    else:
        regression = OutputRegression(sequential(make_chunks), 1, stat.n_inputs,
                                      stat.n_outputs)
    stat.output_regression = regression  # type: ignore[attr-defined]  # read by the B/D pass
    return stat


@serial_blas
def identify_file(path, inputs, outputs, *, dt=None, method: str = "moesp", order=None,
                  horizon=None, chunk_size: int = 100_000, statistic: str = "gram",
                  delimiter=None, progress=None, **options):
    """Identify a model from a file of any size, with bounded memory.

    The file is parsed once with :func:`subid.read_chunks` (on subid's
    threads) and reduced to its statistic on the way; the B, D, x0 regression
    (unless ``bd_method='projection'``) reads the parsed values back from a
    temporary file of doubles (:class:`ParsedOnce`) instead of parsing the
    file again, in :data:`SPOOL_GROUPS` consecutive stretches reduced on
    subid's threads and merged exactly (the model does not depend on the
    number of threads).
    ``path`` may be a list of files: each is one experiment (no Hankel column
    crosses from one file to the next; one x0 per file), as
    ``subid.merge([subid.read(p, ...) for p in paths])`` in memory. See
    :func:`identify_stream` for the parameters.
    """
    paths = [path] if isinstance(path, (str, os.PathLike)) else list(path)
    if not paths:
        raise DataError("identify_file needs a file (or a list of files, one per experiment)")
    files = [ParsedOnce(lambda p=p: read_chunks(p, inputs, outputs, dt=dt,
                                                chunk_size=chunk_size, delimiter=delimiter))
             for p in paths]
    pieces = files[0] if len(files) == 1 else _Experiments(files)
    try:
        return identify_stream(pieces, method, order, horizon, statistic=statistic,
                               progress=progress, reread=lambda: pieces, **options)
    finally:
        for f in files:
            f.close()


class SpooledFit:
    """What :func:`identify_spooled` returns: the model, the first samples of the
    estimation and validation parts (``est``, ``val``: IOData or None), the record's
    length ``n_samples``, its first piece ``first`` (channel names, dt), the samples
    of the statistic ``n_estimation``, the offsets removed ``u_mean``, ``y_mean`` and
    the ``seconds`` the statistic and the method took."""

    def __init__(self, **fields):
        self.__dict__.update(fields)


def identify_spooled(pieces, fit, method: str, order, horizon, *, detrend: str,
                     validate: float, report_samples: int, options: dict, on_step=None,
                     call=None):
    """A streamed identification with its estimation/validation cut, in three passes
    over a :class:`ParsedOnce` record (what ``subid identify --stream`` runs).

    Pass 1 counts the samples and sums the channels (for the means and the cut at
    ``1 - validate`` of the record); pass 2 feeds the estimation part, means removed
    (``detrend='constant'``) or not (``'none'``), to a :class:`HankelStatistic`, in
    :data:`SPOOL_GROUPS` consecutive stretches reduced on subid's threads and merged
    exactly; ``fit(stat, order, horizon=..., **options)`` then identifies from it, with
    the B, D, x0 regression as a third pass (:func:`attach_second_pass`; not with
    ``bd_method='projection'``), so the model is the in-memory one. Only the first
    ``report_samples`` samples of each part are read once more (``est``, ``val``).

    Parameters
    ----------
    pieces : ParsedOnce
        The record, parsed once.
    fit : callable
        The method's function (``spec.load()`` of a streaming method).
    method : str
        Its registry name (for the statistic's depth).
    order, horizon
        As given to the method (``horizon`` None: chosen as the statistic allows).
    detrend : {'constant', 'none'}
        Whether the means of the record are removed.
    validate : float
        Share of the record, at its end, kept for validation.
    report_samples : int
        Samples of each part read back for the fit and the report.
    options : dict
        Keyword arguments of the method.
    on_step : callable, optional
        ``on_step(name)`` when the 'identify' and 'evaluate' steps begin.
    call : callable, optional
        ``call(fit, stat, order, horizon, options)`` runs the method (default: the
        plain call); the command line passes one that logs its warnings.

    Returns
    -------
    SpooledFit

    Raises
    ------
    DataError
        The record holds no samples.
    """
    import functools
    import time

    from subid._threads import ordered_map
    from subid.data import column_sums
    step = on_step or (lambda name: None)
    n, first = 0, None
    total_u: float | np.ndarray = 0.0         # the column sums, from the first piece on
    total_y: float | np.ndarray = 0.0
    for piece in pieces:
        if first is None:
            first = piece
        n += piece.n_samples
        total_u = total_u + column_sums(piece.u)
        total_y = total_y + column_sums(piece.y)
    if first is None:
        raise DataError("the record holds no samples")
    u_mean = total_u / n if detrend == "constant" else np.zeros(first.n_inputs)
    y_mean = total_y / n if detrend == "constant" else np.zeros(first.n_outputs)
    cut = n - int(round(validate * n)) if validate > 0 else n
    hor, depth = statistic_depth(method, order if isinstance(order, int) else None,
                                 horizon, first.n_outputs, options.get("instruments", "past"))

    def statistic(read):
        part = HankelStatistic(first.n_inputs, first.n_outputs, depth, kind="gram",
                               dt=first.dt, input_names=first.input_names,
                               output_names=first.output_names)
        for u, y in read():
            part.update(u, y)
        return part

    step("identify")
    t0 = time.perf_counter()
    # pass 2: the statistic of the estimation part, means removed, from the spooled
    # doubles in consecutive stretches on subid's threads (merged exactly)
    stretches = pieces.groups(SPOOL_GROUPS, stop=cut, offsets=(u_mean, y_mean))
    stat = functools.reduce(HankelStatistic.merge, ordered_map(statistic, stretches))
    if options.get("bd_method", "auto") != "projection":
        # pass 3 (issue 14): B, D, x0 by the output regression of the in-memory default
        attach_second_pass(stat, groups=stretches)
    selection = None
    if order is None:             # the in-memory rule on the last samples of the part
        read, count = _spooled_tail(pieces, cut, offsets=(u_mean, y_mean))
        order, selection = _order_on_tail(fit, read, first, count, hor, options, call)
    if call is None:
        model = fit(stat, order, horizon=hor, **options)
    else:
        model = call(fit, stat, order, hor, options)
    if selection is not None:
        model.info["order_selection"] = selection
    seconds = time.perf_counter() - t0

    def sample(start, stop):
        """The first ``report_samples`` samples of a part, for the fit and the report."""
        stop = min(stop, start + report_samples)
        if stop <= start:
            return None
        chunks = list(pieces.ranges([(start, stop)], offsets=(u_mean, y_mean))[0]())
        return IOData(np.vstack([u for u, _ in chunks]), np.vstack([y for _, y in chunks]),
                      dt=first.dt, input_names=first.input_names,
                      output_names=first.output_names)
    step("evaluate")
    return SpooledFit(model=model, est=sample(0, cut), val=sample(cut, n), n_samples=n,
                      first=first, n_estimation=stat.n_samples, u_mean=u_mean,
                      y_mean=y_mean, seconds=seconds)


class _Experiments:
    """The pieces of several re-iterable records, :data:`NEW_EXPERIMENT` between them."""

    def __init__(self, records):
        self.records = records

    def __iter__(self):
        from subid.data import check_same_channels
        first = None
        for k, record in enumerate(self.records):
            if k:
                yield NEW_EXPERIMENT
            for i, piece in enumerate(record):
                if i == 0 and piece is not NEW_EXPERIMENT:
                    if first is None:
                        first = piece
                    elif k:               # columns by position: the same names, as merge
                        check_same_channels(piece, first, f"file {k + 1}", "file 1")
                yield piece


class ParsedOnce:
    """The pieces of a file, parsed once: iterable any number of times.

    The first complete iteration parses the file (``make()``, e.g.
    :func:`subid.read_chunks`) and spools the values of each piece, as
    float64, to a temporary file; later iterations read them back piece by
    piece, without parsing, and :meth:`ranges` reads any stretch of samples
    directly. Memory stays bounded by one piece; the disk holds the selected
    columns in doubles (8 bytes a value) until :meth:`close`. When the
    temporary file cannot be written (no space), later iterations parse the
    file again.
    """

    def __init__(self, make):
        self.make = make
        self.spool = None
        self.sizes = None              # rows of each piece, once spooled whole
        self.layout = None

    def __iter__(self):
        return self._replay() if self.sizes is not None else self._first()

    def _first(self):
        self.close()
        try:
            fd, name = tempfile.mkstemp(prefix="subid-stream-", suffix=".f8")
            fh = os.fdopen(fd, "wb")
            self.spool = name
        except OSError:
            fh = None
        sizes = []
        try:
            for piece in self.make():
                if self.layout is None:
                    self.layout = (piece.n_inputs, piece.n_outputs, piece.dt,
                                   piece.input_names, piece.output_names)
                if fh is not None:
                    try:
                        fh.write(piece.u.data)     # u then y: no copy, no bytes
                        fh.write(piece.y.data)
                    except OSError:
                        fh.close()
                        fh = None
                        self.close()
                sizes.append(piece.n_samples)
                yield piece
            if fh is not None:
                fh.close()
                fh = None
                self.sizes = sizes
        finally:
            if fh is not None:         # abandoned or failed midway: parse again next time
                fh.close()
                self.close()

    def _replay(self):
        n_in, n_out, dt, in_names, out_names = self.layout
        first = None
        start = 0
        with open(self.spool, "rb") as fh:
            for rows in self.sizes:
                u = np.fromfile(fh, dtype=np.float64, count=rows * n_in).reshape(rows, n_in)
                y = np.fromfile(fh, dtype=np.float64, count=rows * n_out).reshape(rows, n_out)
                if first is None:
                    piece = first = IOData(u, y, dt=dt, input_names=in_names,
                                           output_names=out_names, copy=False)
                else:                      # values checked when spooled: no second check
                    piece = first._derive(u, y, dt=dt, t0=start * dt)
                start += rows
                yield piece

    @property
    def n_samples(self):
        """Samples of the record, once parsed whole (None before)."""
        return None if self.sizes is None else sum(self.sizes)

    def ranges(self, bounds, offsets=None):
        """Readers of stretches of the record: one callable per ``(start, stop)``
        of ``bounds`` (sample indices), returning a fresh iterable of the
        consecutive ``(u, y)`` arrays of samples ``start .. stop - 1``, minus
        ``offsets = (u offset, y offset)`` (one value per channel) if given.

        They read the spooled doubles directly (each its own file handle, so
        they may run in threads at once); without a spool they parse the file
        again.
        """
        return [lambda a=int(a), b=int(b): self._stretch(a, b, offsets) for a, b in bounds]

    def groups(self, count: int, stop=None, offsets=None):
        """:meth:`ranges` of ``count`` consecutive stretches of about equal
        length covering samples ``0 .. stop - 1`` (default: all), cut at piece
        borders; a single stretch when the record is not spooled."""
        if self.sizes is None:
            return self.ranges([(0, sys.maxsize if stop is None else stop)], offsets)
        total = self.n_samples if stop is None else stop
        borders = np.cumsum([0] + self.sizes)
        cuts = [0]
        for k in range(1, count):
            at = int(borders[np.searchsorted(borders, k * total / count)])
            if cuts[-1] < at < total:
                cuts.append(at)
        cuts.append(total)
        return self.ranges(zip(cuts[:-1], cuts[1:]), offsets)

    def _stretch(self, start: int, stop: int, offsets):
        if self.sizes is None:          # no spool: parse again, keep the stretch
            begin = 0
            for piece in self:
                end = begin + piece.n_samples
                a, b = max(start - begin, 0), min(stop, end) - begin
                if b > a and offsets is not None:
                    yield (minus_columns(piece.u[a:b], offsets[0]),
                           minus_columns(piece.y[a:b], offsets[1]))
                elif b > a:
                    yield piece.u[a:b], piece.y[a:b]
                begin = end
                if begin >= stop:
                    return
            return
        n_in, n_out = self.layout[:2]
        offset = begin = 0                # bytes and samples before the piece
        with open(self.spool, "rb") as fh:
            for rows in self.sizes:
                end = begin + rows
                a, b = max(start - begin, 0), min(stop, end) - begin
                if b > a:
                    fh.seek(offset + 8 * n_in * a)
                    u = np.fromfile(fh, dtype=np.float64, count=(b - a) * n_in)
                    fh.seek(offset + 8 * (n_in * rows + n_out * a))
                    y = np.fromfile(fh, dtype=np.float64, count=(b - a) * n_out)
                    u, y = u.reshape(b - a, n_in), y.reshape(b - a, n_out)
                    if offsets is not None:           # fresh arrays: in place
                        minus_columns(u, offsets[0], out=u)
                        minus_columns(y, offsets[1], out=y)
                    yield u, y
                offset += 8 * (n_in + n_out) * rows
                begin = end
                if begin >= stop:
                    return

    def close(self):
        """Delete the temporary file."""
        if self.spool is not None:
            try:
                os.unlink(self.spool)
            except OSError:
                pass
        self.spool, self.sizes = None, None
