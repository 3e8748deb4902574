"""Plots. matplotlib is imported lazily; every function returns a Figure.

Install with ``pip install subid[plot]``. Functions never show or save the
figure: the caller decides (``fig.savefig(...)`` or display in a notebook).
"""

from __future__ import annotations

import numpy as np

__all__ = ["poles", "error_histograms"]


def _pyplot():
    try:
        import matplotlib
        if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
            import os
            if not os.environ.get("DISPLAY") and os.name != "nt":
                matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError("subid.plot needs matplotlib: pip install 'subid[plot]'") from exc
    return plt


def poles(models, reference=None, *, labels=None, ax=None, title=None, markersize=4):
    """Pole map of one or several groups of models.

    Parameters
    ----------
    models : StateSpace, list of StateSpace, or dict label -> list of StateSpace
        Models whose poles are drawn (one colour per group).
    reference : StateSpace, optional
        True system; its poles are drawn as large crosses.
    ax : matplotlib Axes, optional
    """
    plt = _pyplot()
    from .model import StateSpace
    if isinstance(models, StateSpace):
        groups = {"model": [models]}
    elif isinstance(models, dict):
        groups = {str(k): list(v) if not isinstance(v, StateSpace) else [v]
                  for k, v in models.items()}
    else:
        groups = {"models": list(models)}
    if labels is not None:
        groups = dict(zip(labels, groups.values()))
    fig = ax.figure if ax is not None else plt.figure(figsize=(5.5, 5))
    ax = ax if ax is not None else fig.add_subplot(111)
    discrete = None
    if reference is not None:      # drawn first: the estimates must stay visible
        q = reference.poles()
        discrete = reference.dt > 0
        ax.plot(q.real, q.imag, "o", ms=16, mfc="none", mec="k", mew=1.2, zorder=1,
                label="true")
    for label, group in groups.items():
        p = np.concatenate([m.poles() for m in group]) if group else np.array([])
        discrete = group[0].dt > 0 if group else discrete
        ax.plot(p.real, p.imag, ".", ms=markersize, alpha=0.4, zorder=2, label=label)
    if discrete:
        theta = np.linspace(0, 2 * np.pi, 400)
        ax.plot(np.cos(theta), np.sin(theta), "k-", lw=0.6)
        ax.set_aspect("equal")
    else:
        ax.axvline(0.0, color="k", lw=0.6)
    ax.axhline(0.0, color="k", lw=0.3)
    ax.set_xlabel("real part")
    ax.set_ylabel("imaginary part")
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title)
    return fig


def error_histograms(errors: dict, *, bins=40, xlabel="relative error", title=None):
    """One histogram panel per method of a Monte-Carlo error sample.

    Parameters
    ----------
    errors : dict label -> array of errors
    """
    plt = _pyplot()
    k = len(errors)
    fig, axes = plt.subplots(k, 1, figsize=(6, 1.9 * k + 0.6), sharex=True, squeeze=False)
    all_vals = np.concatenate([np.asarray(v, float) for v in errors.values()])
    lo, hi = all_vals.min(), all_vals.max()
    edges = np.logspace(np.log10(max(lo, 1e-300)), np.log10(max(hi, lo * 1.01)) + 1e-9, bins)
    for ax, (label, vals) in zip(axes[:, 0], errors.items()):
        ax.hist(vals, bins=edges, color="C0", alpha=0.8)
        ax.axvline(np.median(vals), color="C3", lw=1.5, label=f"median {np.median(vals):.3g}")
        ax.set_xscale("log")
        ax.set_ylabel("runs")
        ax.set_title(label, fontsize="small", loc="left")
        ax.legend(fontsize="small")
    axes[-1, 0].set_xlabel(xlabel)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
