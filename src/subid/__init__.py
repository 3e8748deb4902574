"""subid: subspace identification of linear MIMO state-space models.

Batch methods are functions ``method(data, order, ...) -> StateSpace``:
:func:`ls_subspace` (SVD-free least squares, seed 001), and the classical
baselines :func:`moesp` and :func:`n4sid`. Data live in :class:`IOData`,
models in :class:`StateSpace`; :func:`markov_error`, :func:`fit_percent`
and :func:`pole_error` validate them. Errors are :mod:`subid.errors`
exceptions (all ``ValueError`` subclasses).
"""

from . import datasets, errors, interop, plot, systems
from .adaptive import AdaptiveIdentifier
from .config import thread_limit
from .data import IOData
from .io import read, read_chunks
from .ls_subspace import ls_subspace
from .metrics import fit_percent, markov_error, pole_error
from .model import StateSpace
from .moesp import moesp
from .n4sid import n4sid
from .recursive import RecursiveSubspace
from .statistic import HankelStatistic
from .stream import identify_file, identify_stream

__all__ = [
    "IOData",
    "StateSpace",
    "read",
    "thread_limit",
    "read_chunks",
    "identify_file",
    "identify_stream",
    "ls_subspace",
    "moesp",
    "n4sid",
    "RecursiveSubspace",
    "AdaptiveIdentifier",
    "HankelStatistic",
    "markov_error",
    "fit_percent",
    "pole_error",
    "errors",
    "systems",
    "datasets",
    "interop",
    "plot",
]

__version__ = "0.1.0"
