"""What the methods decided, in words, for the reports and the command line: the automatic
order rule (:data:`AUTO_ORDER_RULE`), the one-line summaries of
``info['order_selection']`` (:func:`describe_order_selection`) and of
``info['feedthrough']`` (:func:`describe_feedthrough`).

The evaluation and command-line layers read these here, not in the private modules of the
discrete-time pipeline (issue 24); the constants of the rule are those of
:mod:`subid.methods.crossval`.
"""

from __future__ import annotations

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


def describe_feedthrough(record, *, option: str = "feedthrough=True", input_names=None,
                         output_names=None) -> str | None:
    """One line saying whether the model has a direct term D, and why.

    Under ``feedthrough='auto'`` (:mod:`subid.methods.dt.feedthrough`) D is fixed at
    zero when the data show feedback from the outputs to the inputs, because a direct
    term and a feedback without delay give the same lag-0 correlation; the line then
    names the inputs the feedback test flagged and what a free D would take from each
    output's one-step prediction error (``lag0_share``), and how to ask for D: the
    decision stays the data's, and the user who knows the plant has the last word.

    Parameters
    ----------
    record : dict or None
        ``model.info['feedthrough']``.
    option : str
        How the reader asks for D (``'--option feedthrough=true'`` on the command line).
    input_names, output_names : list of str, optional
        Channel names for the line (default ``u1..``, ``y1..``).

    Returns
    -------
    str or None
        None without a record.
    """
    if not isinstance(record, dict) or "estimated" not in record:
        return None
    estimated = bool(record["estimated"])
    if record.get("requested") != "auto":
        return "D estimated (asked)" if estimated else "D = 0 (asked)"
    direct = record.get("direct_term")
    feedback = record.get("feedback")
    if estimated:
        if isinstance(direct, dict) and direct.get("significant"):
            p = min((v for v in direct.get("p_values", []) if v is not None), default=None)
            return "D estimated: the data show a direct term" + (
                f" (F-test, p = {p:.2g})" if p is not None else "")
        return "D estimated: " + (str(direct) if isinstance(direct, str)
                                   else "the past explains the outputs exactly")
    if isinstance(feedback, dict) and feedback.get("detected"):
        level = float(record.get("level", 0.01))
        p_values = feedback.get("p_values", [])
        names = list(input_names) if input_names is not None else \
            [f"u{j + 1}" for j in range(len(p_values))]
        flagged = [names[j] for j, v in enumerate(p_values)
                   if v is not None and v < level / max(len(p_values), 1)]
        shares = record.get("lag0_share") or []
        outs = list(output_names) if output_names is not None else \
            [f"y{i + 1}" for i in range(len(shares))]
        share = ", ".join(f"{100 * v:.0f} % ({name})" for name, v in zip(outs, shares))
        return (f"D = 0: the data show feedback to {', '.join(flagged) or 'the inputs'}, "
                "under which a direct term cannot be told apart"
                + (f"; a free D would take {share} of the one-step prediction error"
                   if share else "")
                + f"; pass {option} if the plant has a direct term and the feedback a delay")
    if isinstance(direct, dict):
        p = min((v for v in direct.get("p_values", []) if v is not None), default=None)
        return "D = 0: no direct term in the data" + (
            f" (F-test, p = {p:.2g})" if p is not None else "")
    return "D = 0" + (f": {direct}" if isinstance(direct, str) else "")
