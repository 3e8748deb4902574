"""Orthonormal basis filter banks of :func:`subid.ct_subspace`: ``import subid.basis``.

The public name of :mod:`subid.methods.ct.basis`, where the filter banks are
implemented and documented (Yu, Chen, Ljung & Verhaegen, seed 002, eq. (2)).
"""

from subid.methods.ct.basis import (
    FilterBank,
    default_basis,
    laguerre,
    legendre,
    takenaka_malmquist,
)

__all__ = ["FilterBank", "takenaka_malmquist", "laguerre", "legendre", "default_basis"]
