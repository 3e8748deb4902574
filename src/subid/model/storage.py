"""Where the file methods of :class:`~subid.model.statespace.StateSpace` find their readers
and writers.

Files are the concern of :mod:`subid.io`, which sits above :mod:`subid.model` (it reads
records and writes models): the model imports nothing of it (issue 24). ``StateSpace.save``,
``load``, ``to_mat`` and ``from_mat`` look their format up here; :mod:`subid.io.models`
registers the JSON model file and the MATLAB file when it is imported, and the first
look-up of a format nobody registered yet imports it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

# format -> (reader(path, cls, **options) -> model, writer(model, path) -> None)
_FORMATS: dict[str, tuple[Callable, Callable]] = {}

# The module that registers the formats of this package's models.
PROVIDER = "subid.io.models"


def register(name: str, *, reader: Callable, writer: Callable) -> None:
    """Make ``reader`` and ``writer`` the implementation of the model file format ``name``.

    Parameters
    ----------
    name : str
        ``'json'`` (:meth:`StateSpace.save` / :meth:`StateSpace.load`) or ``'mat'``
        (:meth:`StateSpace.to_mat` / :meth:`StateSpace.from_mat`).
    reader : callable
        ``reader(path, cls, **options)`` returns a ``cls`` model read from ``path``.
    writer : callable
        ``writer(model, path)`` writes ``model`` to ``path``.
    """
    _FORMATS[name] = (reader, writer)


def _lookup(name: str) -> tuple[Callable, Callable]:
    if name not in _FORMATS:
        importlib.import_module(PROVIDER)        # registers its formats on import
    return _FORMATS[name]


def reader(name: str) -> Callable:
    """The reader registered for the model file format ``name`` (``'json'``, ``'mat'``)."""
    return _lookup(name)[0]


def writer(name: str) -> Callable:
    """The writer registered for the model file format ``name`` (``'json'``, ``'mat'``)."""
    return _lookup(name)[1]
