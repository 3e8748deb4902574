"""subid: subspace identification of linear MIMO state-space models.

Batch methods are functions ``method(data, order, ...) -> StateSpace``:
:func:`ls_subspace` (SVD-free least squares, seed 001), the classical
baselines :func:`moesp` and :func:`n4sid`, and :func:`ct_subspace`
(continuous time with orthonormal basis filters, seed 002, uniform or
non-uniform sampling). Online identifiers are classes with ``update``:
:class:`RecursiveSubspace` (seed 001) and :class:`AdaptiveIdentifier`
(continuous time, seed 000). Data live in :class:`IOData`,
models in :class:`StateSpace`; :func:`markov_error`, :func:`fit_percent`
and :func:`pole_error` validate them. Errors are :mod:`subid.errors`
exceptions (all ``ValueError`` subclasses).
"""

from . import basis, datasets, delay, errors, interop, plot, systems
from .adaptive import AdaptiveIdentifier
from .config import thread_limit
from .ct_subspace import ct_subspace, ct_subspace_paper, dt_to_ct
from .data import IOData
from .delay import absorb_delay, delay_inputs, estimate_delay
from .io import read, read_chunks
from .ls_subspace import ls_subspace
from .metrics import fit_percent, markov_error, pole_error
from .model import StateSpace
from .moesp import moesp
from .n4sid import n4sid
from .pem import pem
from .prediction import predict, residuals
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
    "ct_subspace",
    "ct_subspace_paper",
    "dt_to_ct",
    "RecursiveSubspace",
    "AdaptiveIdentifier",
    "HankelStatistic",
    "markov_error",
    "fit_percent",
    "pole_error",
    "predict",
    "pem",
    "residuals",
    "estimate_delay",
    "delay_inputs",
    "absorb_delay",
    "errors",
    "systems",
    "basis",
    "datasets",
    "interop",
    "plot",
    "delay",
]

__version__ = "0.1.0"
