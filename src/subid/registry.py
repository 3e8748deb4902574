"""The registry of identification methods: ``import subid.registry``.

The public name of :mod:`subid.methods.registry`: :data:`METHODS` maps each
method's name to its :class:`MethodSpec` (where it lives, its kind, time
base, options, capabilities and the :class:`CheckParameters` of the contract
checks of :mod:`subid.testing`), which the command line, streaming, Dask
and the tests read.
"""

from subid.methods.registry import (
    CAPABILITIES,
    CORE_KEYS,
    EXACTNESS,
    METHODS,
    RECORDS,
    CheckParameters,
    MethodSpec,
    MethodUnavailableError,
    available_methods,
    find,
)

__all__ = ["MethodSpec", "CheckParameters", "MethodUnavailableError", "METHODS",
           "CAPABILITIES", "CORE_KEYS", "RECORDS", "EXACTNESS", "find", "available_methods"]
