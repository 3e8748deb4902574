"""The registry of identification methods: ``import subid.registry``.

The public name of :mod:`subid.methods.registry`: :data:`METHODS` maps each
method's name to its :class:`MethodSpec` (where it lives, its kind, time
base, options and capabilities), which the command line, streaming, Dask
and the tests read.
"""

from subid.methods.registry import (
    CAPABILITIES,
    METHODS,
    MethodSpec,
    MethodUnavailableError,
    available_methods,
    find,
)

__all__ = ["MethodSpec", "MethodUnavailableError", "METHODS", "CAPABILITIES", "find",
           "available_methods"]
