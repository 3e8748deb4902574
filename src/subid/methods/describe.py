"""What the methods decided, in words, for the reports and the command line: the automatic
order rule (:data:`AUTO_ORDER_RULE`) and the one-line summary of
``info['order_selection']`` (:func:`describe_order_selection`).

The evaluation and command-line layers read these here, not in the private modules of the
discrete-time pipeline (issue 24).
"""

from __future__ import annotations

from subid.methods.dt._selection import AUTO_ORDER_RULE as AUTO_ORDER_RULE
from subid.methods.dt._selection import describe as _describe

__all__ = ["AUTO_ORDER_RULE", "describe_order_selection"]


def describe_order_selection(record) -> str:
    """One line describing how a model's order was chosen.

    Parameters
    ----------
    record : dict or str
        ``model.info['order_selection']`` (a string from older methods).

    Returns
    -------
    str
        ``'given'``, the cross-validation summary (horizon, system matrices, fit,
        number of candidates) or the rule's description.
    """
    return _describe(record)
