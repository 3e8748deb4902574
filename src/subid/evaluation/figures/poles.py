"""Pole maps (:func:`poles`) and Monte-Carlo error histograms (:func:`error_histograms`)."""

from __future__ import annotations

import numbers

import numpy as np

from subid.errors import DataError, ModelError, OptionError
from subid.evaluation.figures._common import (
    _legend_beside,
    _legend_room,
    _pyplot,
    _styled,
    colors_for,
)
from subid.evaluation.figures._light_axes import subplot_kw


@_styled
def poles(models, reference=None, *, labels=None, ax=None, title=None, markersize=4,
          marker=".", alpha=0.4):
    """Pole map of one or several groups of models.

    Discrete-time poles are drawn with the unit circle, continuous-time
    poles with the imaginary axis; a mixture of both gets two panels.

    Parameters
    ----------
    models : StateSpace, list of StateSpace, or dict label -> list of StateSpace
        Models whose poles are drawn (one colour per group; a dict value may
        also be a single model).
    reference : StateSpace, optional
        True system; its poles are drawn as large circles.
    labels : list of str, optional
        Group labels replacing the dict keys.
    ax : matplotlib Axes, optional
        Draw into this axes (all groups must then share a time base).
    title : str, optional
    markersize : float
    marker : str
        Matplotlib marker of the estimates (``'x'`` reads well for a few
        models, ``'.'`` for Monte-Carlo clouds).
    alpha : float
        Opacity of the estimates.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    from subid.model.statespace import StateSpace
    if isinstance(models, StateSpace):
        groups = {"model": [models]}
    elif isinstance(models, dict):
        groups = {str(k): list(v) if not isinstance(v, StateSpace) else [v]
                  for k, v in models.items()}
    else:
        try:
            if isinstance(models, str):
                raise TypeError
            groups = {"models": list(models)}
        except TypeError:
            raise ModelError(f"poles: expected a StateSpace, a list or a dict of them, got "
                             f"{type(models).__name__}") from None
    if labels is not None:
        groups = dict(zip(labels, groups.values()))
    for label, group in groups.items():
        for m in group:
            if not isinstance(m, StateSpace):
                raise ModelError(f"poles: {label!r} holds a {type(m).__name__}, not a "
                                 "subid.StateSpace")
    if reference is not None and not isinstance(reference, StateSpace):
        raise ModelError(f"poles: reference must be a subid.StateSpace, got "
                         f"{type(reference).__name__}")
    kinds = {m.dt > 0 for group in groups.values() for m in group}
    if reference is not None:
        kinds.add(reference.dt > 0)
    colors = dict(zip(groups, colors_for((k, g[0] if g else None)
                                         for k, g in groups.items())))
    legend_labels = list(groups) + (["true"] if reference is not None else [])
    room = _legend_room(legend_labels)
    if ax is None and len(kinds) == 2:
        fig, axes = plt.subplots(1, 2, figsize=(10.5 + room, 5), subplot_kw=subplot_kw())
        for sub, discrete in zip(axes, (True, False)):
            part = {k: [m for m in g if (m.dt > 0) == discrete] for k, g in groups.items()}
            ref = reference if reference is not None and (reference.dt > 0) == discrete \
                else None
            _pole_axes(sub, {k: g for k, g in part.items() if g}, ref, discrete, markersize,
                       marker, alpha, colors, legend=False)
            sub.set_title("discrete time (z plane)" if discrete else
                          "continuous time (s plane)")
        handles = [h for a in axes for h in a.get_legend_handles_labels()[0]]
        names = [n for a in axes for n in a.get_legend_handles_labels()[1]]
        seen = {}
        for h, n in zip(handles, names):
            seen.setdefault(n, h)
        _legend_beside(axes[-1], list(seen.values()), list(seen))
        if title:
            fig.suptitle(title)
        width = fig.get_figwidth()     # fixed margins: tight_layout draws the figure twice
        fig.subplots_adjust(left=0.85 / width, right=1 - (room + 0.1) / width,
                            bottom=0.6 / 5, top=1 - (0.75 if title else 0.45) / 5,
                            wspace=0.9 / ((width - room - 1.85) / 2))
        return fig
    own = ax is None
    fig = ax.figure if ax is not None else plt.figure(figsize=(5.0 + room, 5))
    ax = ax if ax is not None else fig.add_subplot(111, **subplot_kw())
    discrete = True if not kinds else kinds.pop()
    _pole_axes(ax, groups, reference, discrete, markersize, marker, alpha, colors,
               legend=not own)
    if own and (groups or reference is not None):
        _legend_beside(ax)
        fig.subplots_adjust(left=0.85 / fig.get_figwidth(),
                            right=1 - (room + 0.1) / fig.get_figwidth(),
                            bottom=0.6 / 5, top=1 - (0.5 if title else 0.25) / 5)
    if title:
        ax.set_title(title)
    return fig


def _pole_axes(ax, groups, reference, discrete, markersize, marker, alpha, colors=None,
               legend=True):
    colors = colors or {}
    if reference is not None:      # drawn first: the estimates must stay visible
        q = reference.poles()
        ax.plot(q.real, q.imag, "o", ms=16, mfc="none", mec="k", mew=1.2, zorder=1,
                label="true")
    for label, group in groups.items():
        p = np.concatenate([m.poles() for m in group]) if group else np.array([])
        ax.plot(p.real, p.imag, marker, ms=markersize, alpha=alpha, zorder=2, label=label,
                color=colors.get(label), mew=1.5 if marker in ("x", "+") else None)
    if discrete:
        theta = np.linspace(0, 2 * np.pi, 400)
        ax.plot(np.cos(theta), np.sin(theta), "k-", lw=0.6)
        ax.set_aspect("equal")
    else:
        ax.axvline(0.0, color="k", lw=0.6)
    ax.axhline(0.0, color="k", lw=0.3)
    ax.set_xlabel("real part")
    ax.set_ylabel("imaginary part")
    if legend and (groups or reference is not None):
        ax.legend(loc="best")


@_styled
def error_histograms(errors: dict, *, bins=40, xlabel="relative error", title=None):
    """One histogram panel per method of a Monte-Carlo error sample.

    Parameters
    ----------
    errors : dict label -> array of errors
    bins : int
    xlabel, title : str

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    errors = _check_errors(errors)
    if isinstance(bins, (bool, np.bool_)) or not isinstance(bins, numbers.Integral) \
            or not 2 <= int(bins) <= 100_000:
        raise OptionError(f"bins must be an integer from 2 to 100000, got {bins!r}"[:300])
    k = len(errors)
    fig, axes = plt.subplots(k, 1, figsize=(8, 1.9 * k + 0.6), sharex=True, squeeze=False,
                             subplot_kw=subplot_kw())
    all_vals = np.concatenate([np.asarray(v, float) for v in errors.values()])
    lo, hi = all_vals.min(), all_vals.max()
    edges = np.logspace(np.log10(max(lo, 1e-300)), np.log10(max(hi, lo * 1.01)) + 1e-9, bins)
    colors = colors_for((label, None) for label in errors)
    for ax, (label, vals), color in zip(axes[:, 0], errors.items(), colors):
        ax.hist(vals, bins=edges, color=color, alpha=0.8)
        ax.axvline(np.median(vals), color="k", lw=1.5, ls="--",
                   label=f"median {np.median(vals):.3g}")
        ax.set_xscale("log")
        ax.set_ylabel("runs")
        ax.set_title(label, loc="left")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  frameon=False)
    axes[-1, 0].set_xlabel(xlabel)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def _check_errors(errors) -> dict:
    """The errors of :func:`error_histograms` as ``{label: float array}``; else
    :class:`DataError` (drawn on a log axis: each must be positive and finite)."""
    if not isinstance(errors, dict) or not errors:
        raise DataError("error_histograms takes a non-empty dict label -> array of errors, "
                        f"got {type(errors).__name__}"
                        + (" (empty)" if isinstance(errors, dict) else ""))
    out = {}
    for label, values in errors.items():
        try:
            arr = np.asarray(values, dtype=float).ravel()
        except (TypeError, ValueError):
            raise DataError(f"errors[{label!r}] is not an array of numbers") from None
        if arr.size == 0:
            raise DataError(f"errors[{label!r}] is empty")
        bad = ~np.isfinite(arr) | (arr <= 0)
        if bad.any():
            raise DataError(f"errors[{label!r}] has {int(bad.sum())} value(s) that are not "
                            f"finite and positive (e.g. {float(arr[bad][0])!r}); the histogram has "
                            "a logarithmic axis: pass magnitudes of errors, without NaN")
        out[label] = arr
    return out
