"""Models: :class:`StateSpace` and its simulation kernels."""

from subid.model.statespace import StateSpace

__all__ = ['StateSpace']
