"""Online runs: poles and parameters of the estimates over time (:func:`convergence`)."""

from __future__ import annotations

import numpy as np

from subid.errors import DataError
from subid.evaluation.figures._common import _layout, _legend_beside, _legend_room, _pyplot, _styled
from subid.evaluation.figures._light_axes import subplot_kw


@_styled
def convergence(history, *, reference=None, title=None, max_parameters: int = 12):
    """Poles and parameters of an online identifier against the samples seen.

    Parameters
    ----------
    history : dict
        ``sample`` (k,) and ``poles`` (k, n) complex, as
        :attr:`subid.RecursiveSubspace.history`; optionally ``parameters``
        (k, p) real (e.g. Markov parameters) and ``parameter_names`` (p,).
    reference : StateSpace, optional
        True system: its poles are drawn as dashed lines.
    title : str, optional
    max_parameters : int
        At most this many parameter trajectories are drawn.

    Returns
    -------
    matplotlib.figure.Figure
        Real and imaginary parts of the poles; with parameters, their
        trajectories and their relative distance to the final estimate.
    """
    plt = _pyplot()
    if not isinstance(history, dict) or "sample" not in history or "poles" not in history:
        raise DataError("history must be a dict with the keys 'sample' and 'poles'")
    sample = np.asarray(history["sample"], dtype=float).reshape(-1)
    pol = np.asarray(history["poles"], dtype=complex)
    if pol.ndim != 2 or pol.shape[0] != sample.size:
        raise DataError(f"history['poles'] must have shape ({sample.size}, order), got "
                        f"{pol.shape}")
    params = history.get("parameters")
    if params is not None:
        params = np.asarray(params, dtype=float)
        if params.ndim != 2 or params.shape[0] != sample.size or params.shape[1] == 0:
            params = None
    rows = 2 + (2 if params is not None else 0)
    names: list | None = None
    shown = 0
    if params is not None:
        names = list(history.get("parameter_names", [])) or \
            [f"θ{k + 1}" for k in range(params.shape[1])]
        shown = min(params.shape[1], max_parameters)
    legend_texts = [f"pole {k + 1}" for k in range(pol.shape[1])] + ["true poles"] + \
        [str(n) for n in (names or [])[:shown]]
    room = _legend_room(legend_texts)
    fig, axes = plt.subplots(rows, 1, figsize=(9 + room, 2.2 * rows + 0.6), sharex=True,
                             squeeze=False, subplot_kw=subplot_kw())
    axes = axes[:, 0]
    if sample.size == 0:
        axes[0].text(0.5, 0.5, "no snapshot recorded", ha="center", va="center",
                     transform=axes[0].transAxes)
    for k in range(pol.shape[1]):
        axes[0].plot(sample, pol[:, k].real, ".-", color=f"C{k % 10}", lw=0.8, ms=3,
                     label=f"pole {k + 1}")
        axes[1].plot(sample, pol[:, k].imag, ".-", color=f"C{k % 10}", lw=0.8, ms=3)
    if reference is not None:
        for r, q in enumerate(reference.poles()):
            axes[0].axhline(q.real, color="k", ls="--", lw=0.6,
                            label="true poles" if r == 0 else None)
            axes[1].axhline(q.imag, color="k", ls="--", lw=0.6)
    if pol.shape[1] or reference is not None:
        _legend_beside(axes[0])
    axes[0].set_ylabel("pole real part")
    axes[1].set_ylabel("pole imag. part")
    if params is not None:
        for k in range(shown):
            axes[2].plot(sample, params[:, k], lw=0.9, label=names[k] if names and k < len(names) else None)
        _legend_beside(axes[2], ncol=1 if shown <= 8 else 2)
        axes[2].set_ylabel("parameters")
        final = params[-1]
        scale = np.linalg.norm(final)
        with np.errstate(all="ignore"):
            rel = np.linalg.norm(params - final, axis=1) / (scale if scale > 0 else 1.0)
        rel[rel <= 0] = np.nan
        axes[3].semilogy(sample, rel, "k.-", lw=0.8, ms=3)
        axes[3].set_ylabel("‖θ − θ_final‖ / ‖θ_final‖")
    for ax in axes:
        ax.grid(True, lw=0.3)
    axes[-1].set_xlabel("samples processed")
    fig.suptitle(title or "convergence of the online estimate")
    _layout(fig, axes[:, None], top=0.25, hgap=0.2, left=1.0, right=room + 0.1)
    return fig
