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

import numpy as np

from subid._repr import describe_feedthrough as describe_feedthrough
from subid.methods.crossval import AUTO_ORDER_RULE as AUTO_ORDER_RULE

__all__ = ["AUTO_ORDER_RULE", "describe_feedthrough", "describe_order_selection",
           "describe_structure", "structure_orders"]

#: The degrees of each polynomial structure, in MATLAB's order (those of
#: :data:`subid.methods.dt.polynomial.ORDER_NAMES`, repeated here so that the command line
#: reads them without importing the methods).
_STRUCTURE_NAMES = {"arx": ("na", "nb", "nk"), "armax": ("na", "nb", "nc", "nk"),
                    "oe": ("nb", "nf", "nk"), "bj": ("nb", "nc", "nd", "nf", "nk")}
_DEGREES = ("na", "nb", "nc", "nd", "nf", "nk")


def _degree_text(name: str, value) -> str:
    """``'na 3'``, or ``'nk [[1, 2]]'`` when the degrees differ between channels (``na``:
    its diagonal when only that is set, as the single-output structures store it)."""
    a = np.asarray(value)
    if name == "na" and a.ndim == 2 and a.shape[0] == a.shape[1] \
            and not np.any(a - np.diag(np.diag(a))):
        a = np.diag(a)
    flat = a.ravel()
    if flat.size and np.all(flat == flat[0]):
        return f"{name} {int(flat[0])}"
    return f"{name} {a.tolist()}"


def structure_orders(info) -> dict | None:
    """The polynomial structure of a model, ``{'na': [[3]], 'nb': [[3]], 'nk': [[3]]}``.

    Parameters
    ----------
    info : dict
        ``model.info``.

    Returns
    -------
    dict or None
        The degrees of ``info['orders']`` in MATLAB's order (nested lists, as
        :func:`subid.arx` and the other polynomial methods take them back as ``order``),
        or None for a model that is not a polynomial one.
    """
    orders, poly = info.get("orders"), info.get("polynomials")
    if not isinstance(orders, dict) or not isinstance(poly, dict):
        return None
    names = _STRUCTURE_NAMES.get(str(poly.get("structure")), tuple(orders))
    return {k: np.asarray(orders[k]).tolist() for k in names if k in orders}


def describe_structure(orders) -> str:
    """``'na 3, nb 3, nk 3'``: the degrees of a polynomial structure in words.

    Parameters
    ----------
    orders : dict or None
        Degrees by name (:func:`structure_orders`, or the ``selected`` entry of a
        polynomial method's ``order_selection``); other keys are ignored.

    Returns
    -------
    str
        Empty for None or a dict without degrees.

    Examples
    --------
    >>> describe_structure({"na": [[2, 0], [0, 2]], "nb": [[3], [1]], "nk": [[1], [1]]})
    'na 2, nb [[3], [1]], nk 1'
    """
    if not orders:
        return ""
    return ", ".join(_degree_text(k, orders[k]) for k in _DEGREES if k in orders)


def describe_order_selection(record) -> str:
    """One line describing how a model's order was chosen.

    Parameters
    ----------
    record : dict or str
        ``model.info['order_selection']`` (a string from older methods).

    Returns
    -------
    str
        ``'given'``, the cross-validation summary (the structure of a polynomial
        method, horizon, system matrices, fit, number of candidates; what was not
        chosen is not named) or the rule's description. A record of a given order whose
        horizon or estimator was cross-validated (``record['given']`` names ``'order'``)
        says so: ``'given; horizon cross-validated on the estimation data: ...'``.
    """
    if not isinstance(record, dict):
        return str(record)
    rule = record.get("rule")
    if rule == "given":
        return "given"
    chosen = record.get("selected", {})
    if rule == "cv":
        how = chosen.get("system_matrices")
        details = [text for text in (describe_structure(chosen),
                                     *([f"horizon {chosen['horizon']}"]
                                       if chosen.get("horizon") is not None else []),
                                     *([f"system matrices by {how}"] if how else []),
                                     f"fit {chosen.get('score', float('nan')):.1f} % over "
                                     f"{len(record.get('candidates', []))} candidates")
                   if text]
        if "order" in record.get("given", ()):
            # the order was the caller's: say what the folds chose instead
            candidates = record.get("candidates", [])
            chose = [what for what, key in (("horizon", "horizon"),
                                            ("estimator", "system_matrices"))
                     if len({c.get(key) for c in candidates}) > 1]
            return (f"given; {' and '.join(chose) or 'the candidates'} cross-validated on "
                    f"the estimation data: {', '.join(details)}")
        return f"cross-validated on the estimation data: {', '.join(details)}"
    return str(record.get("description", rule))
