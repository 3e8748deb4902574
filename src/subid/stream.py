"""Identification of records larger than memory, from their statistic.

A record is read piece by piece (:func:`subid.read_chunks`, or any iterable
of :class:`IOData` pieces), reduced to its :class:`HankelStatistic` and
identified from the statistic: memory stays bounded by one piece plus
a matrix of ``(2 * horizon * (nu + ny))^2`` numbers, however long the record.
When the pieces can be read again (a file, a list of pieces, or ``reread``),
B, D and x0 come from the output regression of the in-memory default, done as
a second pass over the pieces (:mod:`subid._bd_pass`), so the model is the
in-memory one; a one-shot iterator leaves the statistic-only projection.
"""

from __future__ import annotations

import logging
import os
import tempfile
import warnings

import numpy as np

from ._bd_pass import OutputRegression, sequential
from ._subspace import default_horizon
from .data import IOData
from .errors import DataError, SubidError
from .io import read_chunks
from .ls_subspace import ls_subspace
from .moesp import moesp
from .n4sid import n4sid
from .statistic import HankelStatistic

__all__ = ["identify_stream", "identify_file", "METHODS"]

log = logging.getLogger(__name__)

#: Batch methods that can identify from a statistic.
METHODS = {"ls": ls_subspace, "ls_subspace": ls_subspace, "moesp": moesp, "n4sid": n4sid}


def statistic_depth(method: str, order, horizon, n_outputs: int, instruments="past") -> tuple:
    """``(horizon, depth)`` of the statistic ``method`` needs."""
    if method not in METHODS:
        raise SubidError(f"method must be one of {sorted(METHODS)}, got {method!r}")
    blocks = 1 if METHODS[method] is ls_subspace and instruments is None else 2
    if horizon is None:
        fixed = order if isinstance(order, int) else None
        horizon = default_horizon(fixed, n_outputs, 1, 10**18, blocks)
    return horizon, blocks * horizon


def identify_stream(pieces, method: str = "moesp", order=None, horizon=None, *,
                    statistic: str = "gram", progress=None, reread=None, **options):
    """Identify a model from consecutive pieces of one record.

    Parameters
    ----------
    pieces : iterable of IOData
        Consecutive, uniformly sampled pieces (e.g. :func:`subid.read_chunks`).
    method : {'moesp', 'n4sid', 'ls'}
        Batch method applied to the statistic.
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
        ``info['n_samples']`` is the length of the whole record.
    """
    iterator = iter(pieces if progress is None else progress(pieces))
    first = next(iterator, None)
    if first is None:
        raise DataError("the record is empty: no pieces to identify from")
    if not isinstance(first, IOData):
        raise DataError(f"pieces must be IOData records, got {type(first).__name__}")
    horizon, depth = statistic_depth(method, order, horizon, first.n_outputs,
                                     options.get("instruments", "past"))
    stat = HankelStatistic(first.n_inputs, first.n_outputs, depth, kind=statistic,
                           dt=first.dt, input_names=first.input_names,
                           output_names=first.output_names)
    stat.update(first.u, first.y)
    for k, piece in enumerate(iterator, start=1):
        _check_piece(piece, first, k)
        stat.update(piece.u, piece.y)
    if options.get("bd_method", "auto") != "projection":
        if reread is None and iter(pieces) is not pieces:
            reread = lambda: pieces       # noqa: E731 - a collection iterates again
        if reread is None:
            warnings.warn("identify_stream: the pieces come from a one-shot iterator, so B and "
                          "D come from the statistic only (bd_method='projection'), not from "
                          "the output regression of the in-memory default; pass a list of "
                          "pieces or reread= (a function returning them again)", stacklevel=2)
        else:
            attach_second_pass(stat, lambda: ((p.u, p.y) for p in reread()))
    log.info("identifying from the statistic of %d samples", stat.n_samples)
    return METHODS[method](stat, order, horizon, **options)


def _check_piece(piece, first, k: int) -> None:
    """Every piece must continue the first one: same channels, same sampling."""
    if not isinstance(piece, IOData):
        raise DataError(f"piece {k} is a {type(piece).__name__}, not an IOData record")
    if (piece.n_inputs, piece.n_outputs) != (first.n_inputs, first.n_outputs):
        raise DataError(f"piece {k} has {piece.n_inputs} inputs and {piece.n_outputs} outputs "
                        f"but the first piece has {first.n_inputs} and {first.n_outputs}")
    if first.dt is None or piece.dt is None or not np.isclose(piece.dt, first.dt, rtol=1e-9,
                                                              atol=0):
        raise DataError(f"piece {k} is sampled with dt = {piece.dt} but the first piece with "
                        f"dt = {first.dt}: the pieces of one record must share one uniform "
                        "sampling period (resample them first)")


def attach_second_pass(stat: HankelStatistic, make_chunks) -> HankelStatistic:
    """Let the methods fit B, D, x0 on the record behind ``stat`` by a second pass.

    ``make_chunks()`` returns a fresh iterable of the record's consecutive
    ``(u, y)`` arrays (as fed to the statistic).
    """
    stat.output_regression = OutputRegression(sequential(make_chunks), 1, stat.n_inputs,
                                              stat.n_outputs)
    return stat


def identify_file(path, inputs, outputs, *, dt=None, method: str = "moesp", order=None,
                  horizon=None, chunk_size: int = 100_000, statistic: str = "gram",
                  delimiter=None, progress=None, **options):
    """Identify a model from a file of any size, with bounded memory.

    The file is parsed once with :func:`subid.read_chunks` and reduced to its
    statistic on the way; the B, D, x0 regression (unless
    ``bd_method='projection'``) reads the parsed values back from a temporary
    file of doubles (:class:`ParsedOnce`) instead of parsing the file again.
    See :func:`identify_stream` for the parameters.
    """
    pieces = ParsedOnce(lambda: read_chunks(path, inputs, outputs, dt=dt,
                                            chunk_size=chunk_size, delimiter=delimiter))
    try:
        return identify_stream(pieces, method, order, horizon, statistic=statistic,
                               progress=progress, reread=lambda: pieces, **options)
    finally:
        pieces.close()


class ParsedOnce:
    """The pieces of a file, parsed once: iterable any number of times.

    The first complete iteration parses the file (``make()``, e.g.
    :func:`subid.read_chunks`) and spools the values of each piece, as
    float64, to a temporary file; later iterations read them back piece by
    piece, without parsing. Memory stays bounded by one piece; the disk
    holds the selected columns in doubles (8 bytes a value) until
    :meth:`close`. When the temporary file cannot be written (no space),
    later iterations parse the file again.
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
                    self.layout = (piece.n_inputs, piece.dt, piece.input_names,
                                   piece.output_names)
                if fh is not None:
                    try:
                        fh.write(np.hstack([piece.u, piece.y]).data)   # no bytes copy
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
        n_in, dt, in_names, out_names = self.layout
        width = None
        start = 0
        with open(self.spool, "rb") as fh:
            for rows in self.sizes:
                if width is None:
                    width = os.path.getsize(self.spool) // (8 * sum(self.sizes))
                block = np.fromfile(fh, dtype=np.float64, count=rows * width)
                block = block.reshape(rows, width)
                piece = IOData(block[:, :n_in], block[:, n_in:], dt=dt,
                               input_names=in_names, output_names=out_names, copy=False)
                if start:
                    piece = piece._derive(piece.u, piece.y, dt=dt, t0=start * dt)
                start += rows
                yield piece

    def close(self):
        """Delete the temporary file."""
        if self.spool is not None:
            try:
                os.unlink(self.spool)
            except OSError:
                pass
        self.spool, self.sizes = None, None
