"""What the methods decided, in words, for the reports and the command line: the automatic
order rule (:data:`AUTO_ORDER_RULE`), the one-line summaries of
``info['order_selection']`` (:func:`describe_order_selection`) and of
``info['feedthrough']`` (:func:`describe_feedthrough`, written in :mod:`subid._repr`,
where the notebook summary of a model reads it too).

The evaluation and command-line layers read these here, not in the private modules of the
discrete-time pipeline (issue 24); the constants of the rule are those of
:mod:`subid.methods.crossval`.
"""

from __future__ import annotations

from subid._repr import describe_feedthrough as describe_feedthrough
from subid.methods.crossval import AUTO_ORDER_RULE as AUTO_ORDER_RULE

__all__ = ["AUTO_ORDER_RULE", "describe_feedthrough", "describe_order_selection"]


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
    if not isinstance(record, dict):
        return str(record)
    rule = record.get("rule")
    if rule == "given":
        return "given"
    chosen = record.get("selected", {})
    if rule == "cv":
        how = chosen.get("system_matrices")
        return (f"cross-validated on the estimation data: horizon {chosen.get('horizon')}"
                + (f", system matrices by {how}" if how else "")
                + f", fit {chosen.get('score', float('nan')):.1f} % over "
                f"{len(record.get('candidates', []))} candidates")
    return str(record.get("description", rule))
