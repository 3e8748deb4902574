"""Order selection: singular values or rank profile and the chosen order
(:func:`order_selection`), the validation scores of the candidates (:func:`order_scores`)."""

from __future__ import annotations

import math

import numpy as np

from subid.errors import DataError, ModelError
from subid.evaluation.figures._common import (
    _layout,
    _legend_beside,
    _legend_room,
    _model_groups,
    _plain_log_labels,
    _pyplot,
    _styled,
    colors_for,
)
from subid.evaluation.figures._light_axes import subplot_kw

_PROFILE_KEYS = (("singular_values", "singular value"),
                 ("rank_profile", "rank profile (Cholesky pivot)"))


@_styled
def order_selection(models, *, labels=None, title=None):
    """The order-selection chart: the values whose largest gap picks the order.

    ``info['singular_values']`` (MOESP, N4SID, ct_subspace) or
    ``info['rank_profile']`` (ls_subspace, SVD-free, seed 001 Remark 2) of each
    model, normalised by the first value, on a log scale against their index;
    the order of each model is marked (a ring on its last kept value and a
    vertical line), with the ratio across the gap in the legend.

    Parameters
    ----------
    models : StateSpace, list or dict label -> StateSpace
        Models from the batch methods (their ``info`` holds the profile).
    labels : list of str, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ModelError
        No model carries a profile (e.g. only online models, or models built
        by hand).
    """
    plt = _pyplot()
    groups = _model_groups(models, labels)
    profiles = {}
    for label, m in groups.items():
        for key, what in _PROFILE_KEYS:
            values = m.info.get(key)
            if values is not None and np.size(values) > 0:
                profiles[label] = (np.abs(np.asarray(values, dtype=float).reshape(-1)), what, m)
                break
    if not profiles:
        raise ModelError("no model has info['singular_values'] or info['rank_profile']: the "
                         "order-selection chart needs models from the batch methods")
    texts = []
    for label, (v, _, m) in profiles.items():
        n = m.order
        gap = v[n - 1] / v[n] if n < v.size and v[n] > 0 else math.inf
        texts.append(f"{label}: order {n} (gap ×{gap:.3g})" if math.isfinite(gap)
                     else f"{label}: order {n}")
    room = _legend_room(texts)
    fig, ax = plt.subplots(figsize=(6.5 + room, 3.6), subplot_kw=subplot_kw())
    colors = colors_for((label, m) for label, (_, _, m) in profiles.items())
    kinds = set()
    for (_label, (v, what, m)), color, text in zip(profiles.items(), colors, texts):
        kinds.add(what)
        scaled = v / v[0] if v[0] > 0 else v
        idx = np.arange(1, v.size + 1)
        with np.errstate(divide="ignore"):
            ax.semilogy(idx, np.where(scaled > 0, scaled, np.nan), "o-", color=color, lw=1.0,
                        ms=4, label=text)
        n = m.order
        if n <= v.size:
            ax.plot([n], [scaled[n - 1]], "o", ms=11, mfc="none", mec=color, mew=1.5)
        ax.axvline(n + 0.5, color=color, ls=":", lw=1.0)
    ax.set_xlabel("index (order)")
    ax.set_ylabel(" / ".join(sorted(kinds)) + "\n(relative to the first)")
    from matplotlib.ticker import MaxNLocator, NullLocator
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.yaxis.set_minor_locator(NullLocator())    # decades labelled; minor ticks: 40 % of the cost
    _plain_log_labels(ax.yaxis)
    ax.grid(True, lw=0.3)
    _legend_beside(ax)
    if title:
        ax.set_title(title)
    _layout(fig, np.array([[ax]]), left=1.0, right=room + 0.1, top=0.35 if title else 0.2)
    return fig


@_styled
def order_scores(models, *, labels=None, title=None):
    """The score of every candidate order (and horizon) a model was chosen from.

    For ``selection='cv'`` (the default of the DT batch methods): the
    cross-validated simulation fit % of each candidate order, one line per
    horizon, the chosen candidate ringed; for ``selection='gap'``: the gap
    (log10) after each candidate order. One panel per model; see
    :func:`order_selection` for the singular values / rank profile.

    Parameters
    ----------
    models : StateSpace, list or dict label -> StateSpace
        Models with ``info['order_selection']`` (rule ``'cv'`` or ``'gap'``).
    labels : list of str, optional
        Labels replacing the dict keys (default: the keys or ``model.info['method']``).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    DataError
        No model carries a selection record (their orders were given).
    """
    plt = _pyplot()
    groups = _model_groups(models, labels)
    rows = [(label, m) for label, m in groups.items()
            if isinstance(m.info.get("order_selection"), dict)
            and m.info["order_selection"].get("rule") in ("cv", "gap")]
    if not rows:
        raise DataError("none of the models carries an order selection record "
                        "(info['order_selection'] with rule 'cv' or 'gap'): their order was "
                        "given")
    fig, axes = plt.subplots(len(rows), 1, figsize=(6.5, 2.4 * len(rows) + 0.6),
                             squeeze=False, subplot_kw=subplot_kw())
    for (label, m), ax in zip(rows, axes[:, 0]):
        record = m.info["order_selection"]
        candidates = record.get("candidates", [])
        if record["rule"] == "cv":
            # one line per horizon (and per estimator of the system matrices, when the
            # cross-validation chose that too: system_matrices='auto')
            groups = sorted({(c["horizon"], c.get("system_matrices") or "")
                             for c in candidates})
            for j, (f, how) in enumerate(groups):
                pts = sorted((c["order"], c["score"]) for c in candidates
                             if (c["horizon"], c.get("system_matrices") or "") == (f, how))
                ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, lw=0.9,
                        color=f"C{j}", label=f"horizon {f}" + (f", {how}" if how else ""))
            chosen = record["selected"]
            ax.plot([chosen["order"]], [chosen["score"]], "o", mfc="none", mec="C3", ms=11,
                    mew=1.5, label=f"chosen: n={chosen['order']}, f={chosen['horizon']}")
            ax.set_ylabel("CV fit %")
            scores = [c["score"] for c in candidates]
            ax.set_ylim(max(min(scores), max(scores) - 60) - 2, min(max(scores) + 5, 102))
        else:
            pts = sorted((c["order"], c["score"]) for c in candidates)
            ax.bar([p[0] for p in pts], [p[1] for p in pts], color="C0", width=0.6)
            ax.bar([m.order], [dict(pts).get(m.order, 0)], color="C3", width=0.6,
                   label=f"chosen: n={m.order}")
            ax.set_ylabel("gap (log10)")
        ax.set_title(f"{label}: " + ("cross-validated simulation fit (estimation data)"
                                     if record["rule"] == "cv" else "largest gap of the profile"))
        ax.legend(loc="lower right")
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.grid(True, lw=0.3)
    axes[-1, 0].set_xlabel("order")
    if title:
        fig.suptitle(title)
    _layout(fig, axes, top=0.45, hgap=0.75, left=0.95)
    return fig
