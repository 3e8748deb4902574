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

import importlib as _importlib

# public name -> (submodule, attribute); attribute None: the submodule itself. Every
# public namespace is a module of the package itself (subid/plot.py re-exports
# subid.evaluation.plot, ...), so that ``import subid.plot`` works as ``subid.plot`` does.
_LAZY = {
    "IOData": ("data", "IOData"),
    "merge": ("data", "merge"),
    "FRData": ("frdata", "FRData"),
    "StateSpace": ("model.statespace", "StateSpace"),
    "read": ("io.formats", "read"),
    "read_frd": ("io.frequency", "read_frd"),
    "write_frd": ("io.frequency", "write_frd"),
    "thread_limit": ("config", "thread_limit"),
    "read_chunks": ("io.formats", "read_chunks"),
    "identify_file": ("methods.dt.stream", "identify_file"),
    "identify_stream": ("methods.dt.stream", "identify_stream"),
    "ls_subspace": ("methods.dt.ls_subspace", "ls_subspace"),
    "moesp": ("methods.dt.moesp", "moesp"),
    "n4sid": ("methods.dt.n4sid", "n4sid"),
    "pbsid": ("methods.dt.pbsid", "pbsid"),
    "arx": ("methods.dt.polynomial", "arx"),
    "armax": ("methods.dt.pem_poly", "armax"),
    "oe": ("methods.dt.pem_poly", "oe"),
    "bj": ("methods.dt.pem_poly", "bj"),
    "ct_subspace": ("methods.ct.ct_subspace", "ct_subspace"),
    "fd_subspace": ("methods.fd.fd_subspace", "fd_subspace"),
    "ct_subspace_paper": ("methods.ct.ct_subspace", "ct_subspace_paper"),
    "dt_to_ct": ("methods.ct.ct_subspace", "dt_to_ct"),
    "RecursiveSubspace": ("methods.online.recursive", "RecursiveSubspace"),
    "AdaptiveIdentifier": ("methods.online.adaptive", "AdaptiveIdentifier"),
    "OnlineIdentifier": ("methods.online.base", "OnlineIdentifier"),
    "HankelStatistic": ("statistic.hankel", "HankelStatistic"),
    "markov_error": ("evaluation.metrics", "markov_error"),
    "fit_percent": ("model.fit", "fit_percent"),
    "pole_error": ("evaluation.metrics", "pole_error"),
    "predict": ("model.prediction", "predict"),
    "pem": ("methods.dt.pem", "pem"),
    "identify": ("methods.identify", "identify"),
    "residuals": ("evaluation.residuals", "residuals"),
    "estimate_delay": ("delay", "estimate_delay"),
    "delay_inputs": ("delay", "delay_inputs"),
    "absorb_delay": ("delay", "absorb_delay"),
    "freqresp_bounds": ("evaluation.uncertainty", "freqresp_bounds"),
    "step_bounds": ("evaluation.uncertainty", "step_bounds"),
    "simulation_bounds": ("evaluation.uncertainty", "simulation_bounds"),
    "parameter_covariance": ("evaluation.uncertainty", "parameter_covariance"),
    "impulseest": ("methods.dt.impulse", "impulseest"),
    "spa": ("evaluation.nonparametric", "spa"),
    "etfe": ("evaluation.nonparametric", "etfe"),
    "errors": ("errors", None),
    "registry": ("registry", None),
    "testing": ("testing", None),
    "systems": ("systems", None),
    "basis": ("basis", None),
    "datasets": ("datasets", None),
    "interop": ("interop", None),
    "plot": ("plot", None),
    "delay": ("delay", None),
    "distributed": ("distributed", None),
}

__all__ = [
    "IOData",
    "merge",
    "FRData",
    "StateSpace",
    "read",
    "read_frd",
    "write_frd",
    "thread_limit",
    "read_chunks",
    "identify_file",
    "identify_stream",
    "ls_subspace",
    "moesp",
    "n4sid",
    "pbsid",
    "arx",
    "armax",
    "oe",
    "bj",
    "ct_subspace",
    "fd_subspace",
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
    "identify",
    "residuals",
    "estimate_delay",
    "delay_inputs",
    "absorb_delay",
    "freqresp_bounds",
    "step_bounds",
    "simulation_bounds",
    "parameter_covariance",
    "impulseest",
    "spa",
    "etfe",
    "errors",
    "registry",
    "testing",
    "systems",
    "basis",
    "datasets",
    "interop",
    "plot",
    "delay",
]

from subid._version import __version__ as __version__  # the one place the version is written


def __getattr__(name):
    """Import a public name on first use (PEP 562) and cache it on the package."""
    try:
        module_name, attribute = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'subid' has no attribute {name!r}") from None
    module = _importlib.import_module(f".{module_name}", __name__)
    value = module if attribute is None else getattr(module, attribute)
    # A submodule import binds the submodule on the package (``subid.delay``
    # would otherwise shadow nothing); the public name wins, as it did when
    # everything was imported eagerly.
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
