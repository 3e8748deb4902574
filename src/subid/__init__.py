"""subid: subspace identification of linear MIMO state-space models.

Batch methods are functions ``method(data, order, ...) -> StateSpace``:
:func:`ls_subspace` (SVD-free least squares, seed 001), the classical
baselines :func:`moesp` and :func:`n4sid`, and :func:`ct_subspace`
(continuous time with orthonormal basis filters, seed 002, uniform or
non-uniform sampling). Online identifiers are classes with ``update``:
:class:`RecursiveSubspace` (seed 001) and :class:`AdaptiveIdentifier`
(continuous time, seed 000), both :class:`OnlineIdentifier` s (one
contract: ``update``, ``model``, ``state``, ``history``, ``save``/``load``).
Data live in :class:`IOData`,
models in :class:`StateSpace`; :func:`markov_error`, :func:`fit_percent`
and :func:`pole_error` validate them. Errors are :mod:`subid.errors`
exceptions (all ``ValueError`` subclasses).

Public names are imported on first use (PEP 562 module ``__getattr__``),
so ``import subid`` does not load numba, scipy.optimize or matplotlib;
``from subid import X``, ``subid.X`` and ``dir(subid)`` behave as if
everything had been imported eagerly.
"""

import importlib
import sys
import types

# public name -> (submodule, attribute); attribute None: the submodule itself
_LAZY = {
    "IOData": ("data", "IOData"),
    "merge": ("data", "merge"),
    "StateSpace": ("model", "StateSpace"),
    "read": ("io", "read"),
    "thread_limit": ("config", "thread_limit"),
    "read_chunks": ("io", "read_chunks"),
    "identify_file": ("stream", "identify_file"),
    "identify_stream": ("stream", "identify_stream"),
    "ls_subspace": ("ls_subspace", "ls_subspace"),
    "moesp": ("moesp", "moesp"),
    "n4sid": ("n4sid", "n4sid"),
    "ct_subspace": ("ct_subspace", "ct_subspace"),
    "ct_subspace_paper": ("ct_subspace", "ct_subspace_paper"),
    "dt_to_ct": ("ct_subspace", "dt_to_ct"),
    "RecursiveSubspace": ("recursive", "RecursiveSubspace"),
    "AdaptiveIdentifier": ("adaptive", "AdaptiveIdentifier"),
    "OnlineIdentifier": ("online", "OnlineIdentifier"),
    "HankelStatistic": ("statistic", "HankelStatistic"),
    "markov_error": ("metrics", "markov_error"),
    "fit_percent": ("metrics", "fit_percent"),
    "pole_error": ("metrics", "pole_error"),
    "predict": ("prediction", "predict"),
    "pem": ("pem", "pem"),
    "residuals": ("prediction", "residuals"),
    "estimate_delay": ("delay", "estimate_delay"),
    "delay_inputs": ("delay", "delay_inputs"),
    "absorb_delay": ("delay", "absorb_delay"),
    "errors": ("errors", None),
    "registry": ("registry", None),
    "systems": ("systems", None),
    "basis": ("basis", None),
    "datasets": ("datasets", None),
    "interop": ("interop", None),
    "plot": ("plot", None),
    "delay": ("delay", None),
}

__all__ = [
    "IOData",
    "merge",
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
    "OnlineIdentifier",
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
    "registry",
    "systems",
    "basis",
    "datasets",
    "interop",
    "plot",
    "delay",
]

from ._version import __version__ as __version__  # the one place the version is written


def __getattr__(name):
    """Import a public name on first use (PEP 562) and cache it on the package."""
    try:
        module_name, attribute = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'subid' has no attribute {name!r}") from None
    module = importlib.import_module(f".{module_name}", __name__)
    value = module if attribute is None else getattr(module, attribute)
    # A submodule import binds the submodule on the package (``subid.delay``
    # would otherwise shadow nothing); the public name wins, as it did when
    # everything was imported eagerly.
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


# Public functions that share their module's name (``subid.ls_subspace`` is
# the function, defined in the module ``subid.ls_subspace``).  Importing such a
# submodule binds the module on the package; eagerly, the function imported
# afterwards overwrote it.  Lazily the submodule may be imported later (by the
# CLI registry, a stream, a test), so the package refuses that binding and the
# public function stays what ``subid.<name>`` means.
_SHADOWED = frozenset(
    name for name, (module_name, attribute) in _LAZY.items() if attribute is not None and name == module_name
)


class _Package(types.ModuleType):
    def __setattr__(self, name, value):
        if name in _SHADOWED and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
