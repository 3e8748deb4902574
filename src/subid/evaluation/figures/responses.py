"""Model responses: Bode diagrams with confidence bands and measured frequency responses
(:func:`bode`, :func:`frequency_grid`) and step responses (:func:`step`)."""

from __future__ import annotations

import math

import numpy as np

from subid._validation import check_int
from subid.errors import DataError, ModelError
from subid.evaluation.figures._common import (
    _autoscale_once,
    _layout,
    _legend_beside,
    _legend_room,
    _model_groups,
    _plain_log_labels,
    _pyplot,
    _styled,
    colors_for,
    frequency_unit,
    is_unstable,
    log,
)
from subid.evaluation.figures._light_axes import subplot_kw


def frequency_grid(models, n_points: int = 400) -> np.ndarray:
    """A logarithmic grid of angular frequencies (rad/s) suited to ``models``.

    Discrete-time models: up to the Nyquist frequency ``pi / dt`` of the
    fastest-sampled model. Continuous-time models: a decade beyond their
    fastest pole. The lower end is a decade below the slowest non-zero pole
    (and at most a thousandth of the upper end).

    Parameters
    ----------
    models : StateSpace, list or dict of StateSpace
    n_points : int

    Returns
    -------
    ndarray, shape (n_points,)
    """
    groups = _model_groups(models)
    n_points = check_int(n_points, "n_points", minimum=2, maximum=10_000_000)
    hi_candidates, pole_speeds = [], []
    for m in groups.values():
        p = m.poles()
        if m.dt > 0:
            hi_candidates.append(math.pi / m.dt)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.log(p.astype(complex)) / m.dt
        else:
            s = p
        speed = np.abs(s)
        speed = speed[np.isfinite(speed) & (speed > 0)]
        pole_speeds.extend(speed.tolist())
        if m.dt == 0:
            hi_candidates.append(10 * (speed.max() if speed.size else 1.0))
    hi = max(hi_candidates)
    lo = hi * 1e-3
    if pole_speeds:
        lo = min(lo, 0.1 * min(pole_speeds))
    lo = max(lo, hi * 1e-6)
    return np.logspace(np.log10(lo), np.log10(hi), n_points)


@_styled
def bode(model_or_models=None, w=None, *, data=None, hz=False, labels=None, phase=True,
         title=None, confidence=None):
    """Bode diagram: magnitude (dB) and phase (degrees) of every input/output pair.

    Parameters
    ----------
    model_or_models : StateSpace, list of StateSpace, dict label -> StateSpace or FRData
        Models drawn on the same axes (same numbers of inputs and outputs).
        An :class:`~subid.FRData` here is drawn as ``data`` (without models).
    w : array_like, optional
        Angular frequencies in **rad/s** (default: :func:`frequency_grid`,
        or the data's frequencies when ``data`` is given).
        A discrete-time model is drawn only up to its Nyquist frequency.
    data : FRData, optional
        Measured frequency response, drawn as points under the models (with
        a band of two standard deviations on the magnitude when it has
        ``std``).
    hz : bool
        Label the frequency axis in Hz (``w / 2 pi``) instead of rad/s.
    labels : list of str, optional
        Legend labels (default: the dict keys or ``model.info['method']``).
    phase : bool
        Draw the phase panels.
    title : str, optional
    confidence : float, optional
        Draw the band of this level (e.g. 0.95) around the magnitude of every
        model that has a parameter covariance (:func:`subid.freqresp_bounds`,
        :func:`subid.pem`); a ``ModelError`` when none has one.

    Returns
    -------
    matplotlib.figure.Figure
        Rows: magnitude (and phase) per output; columns: inputs.

    Examples
    --------
    >>> fig = subid.plot.bode({"moesp": m1, "n4sid": m2}, hz=True)   # doctest: +SKIP
    >>> fig = subid.plot.bode(subid.fd_subspace(frd), data=frd)      # doctest: +SKIP
    """
    from subid.frdata import FRData
    plt = _pyplot()
    if isinstance(model_or_models, FRData):
        if data is not None:
            raise DataError("bode: give the frequency data once (as data=)")
        model_or_models, data = None, model_or_models
    if data is not None and not isinstance(data, FRData):
        raise DataError(f"bode: data must be a subid.FRData, got {type(data).__name__}")
    if model_or_models is None and data is None:
        raise ModelError("bode: nothing to draw; give models, data=FRData, or both")
    groups = {} if model_or_models is None else _model_groups(model_or_models, labels)
    first = next(iter(groups.values())) if groups else data
    ny, nu = first.n_outputs, first.n_inputs
    for label, m in groups.items():
        if (m.n_outputs, m.n_inputs) != (ny, nu):
            raise ModelError(f"model {label!r} has {m.n_inputs} inputs and {m.n_outputs} "
                             f"outputs but the first has {nu} and {ny}; a Bode diagram draws "
                             "models of the same shape")
    if data is not None and (data.n_outputs, data.n_inputs) != (ny, nu):
        raise DataError(f"the frequency data have {data.n_inputs} inputs and "
                        f"{data.n_outputs} outputs but the models have {nu} and {ny}")
    if nu == 0:
        raise ModelError("the model has no inputs: there is no frequency response to draw")
    if confidence is not None:
        _require_covariance(groups)
    if w is None:
        w = frequency_grid(groups) if data is None else _data_grid(data)
    else:
        try:
            w = np.atleast_1d(np.asarray(w, dtype=float))
        except (TypeError, ValueError):
            raise DataError(f"w must be a 1-D array of positive frequencies in rad/s, got "
                            f"{w!r}"[:300]) from None
        if w.ndim != 1 or w.size == 0 or not np.isfinite(w).all() or (w <= 0).any():
            raise DataError("w must be a non-empty 1-D array of positive, finite frequencies "
                            f"in rad/s (got shape {w.shape}); leave it out for a grid suited "
                            "to the models")
        nyquist = [math.pi / m.dt for m in groups.values() if m.dt > 0]
        if data is None and len(nyquist) == len(groups) and \
                w.min() > max(nyquist) * (1 + 1e-12):
            raise DataError(f"w: every frequency (from {w.min():.4g} rad/s) is above the "
                            f"Nyquist frequency of the models (at most {max(nyquist):.4g} "
                            "rad/s, pi/dt), where a discrete-time response is not drawn; "
                            "give frequencies below it")
    x_scale = 1 / (2 * math.pi) if hz else 1.0
    rows = 2 * ny if phase else ny
    colors = colors_for(groups.items())
    unstable = {label: is_unstable(m) for label, m in groups.items()}
    shown = [label + (" (unstable)" if unstable[label] else "") for label in groups]
    room = _legend_room(shown + (["data"] if data is not None else []))
    fig, axes = plt.subplots(rows, nu, figsize=(min(3.8 * nu + 1.2, 16) + room,
                                                1.9 * rows + 0.8),
                             sharex=True, squeeze=False, subplot_kw=subplot_kw())
    # one log scale for the shared frequency axis: semilogx on every panel would set it
    # again on all the shared axes each time (quadratic in the panels: 5 s of a 5x3 grid)
    axes[0, 0].set_xscale("log")
    _plain_log_labels(axes[0, 0].xaxis)          # shared by every panel
    reference = None                     # phase of the first model, to align the data's
    with _autoscale_once(axes):      # the limits once, after the plotting calls
        for k, (label, m) in enumerate(groups.items()):
            style = dict(color=colors[k], lw=1.2, ls="--" if unstable[label] else "-")
            wk = w if m.dt == 0 else w[w <= math.pi / m.dt * (1 + 1e-12)]
            if wk.size == 0:
                log.warning("bode: model %r has no frequency below its Nyquist frequency in w",
                            label)
                continue
            G = m.freqresp(wk)
            with np.errstate(divide="ignore"):
                mag = 20 * np.log10(np.maximum(np.abs(G), 1e-300))
            ph = np.degrees(np.unwrap(np.angle(G), axis=0))
            if reference is None:
                reference = (wk, ph)
            band = None
            if confidence is not None and _has_covariance(m):
                from subid.evaluation.uncertainty import freqresp_bounds
                band = freqresp_bounds(m, wk, confidence)
            for i in range(ny):
                for j in range(nu):
                    r = 2 * i if phase else i
                    axes[r, j].plot(wk * x_scale, mag[:, i, j], label=shown[k], **style)
                    if band is not None:
                        lo = np.maximum(band.lower[:, i, j], 1e-3 * band.value[:, i, j])
                        axes[r, j].fill_between(wk * x_scale, 20 * np.log10(lo),
                                                20 * np.log10(band.upper[:, i, j]),
                                                color=colors[k], alpha=0.2, lw=0)
                    if phase:
                        axes[r + 1, j].plot(wk * x_scale, ph[:, i, j], **style)
        if data is not None:
            _bode_data(axes, data, x_scale, phase, reference)
    for i in range(ny):
        for j in range(nu):
            r = 2 * i if phase else i
            axes[r, j].set_title(f"{first.input_names[j]} → {first.output_names[i]}")
            axes[r, j].set_ylabel("magnitude (dB)")
            axes[r, j].grid(True, lw=0.3)
            if phase:
                axes[r + 1, j].set_ylabel("phase (deg)")
                axes[r + 1, j].grid(True, lw=0.3)
    unit = frequency_unit([m.dt for m in list(groups.values()) + ([data] if data else [])],
                          hz)
    for j in range(nu):
        axes[-1, j].set_xlabel(f"frequency ({unit})")
    # after the autoscale is requested: axvline maps its x to data coordinates through
    # the view (computed then), and the Nyquist frequency, the largest drawn, sets the
    # upper limit: as when every plotting call autoscaled
    nyquists = sorted({math.pi / m.dt for m in list(groups.values()) + ([data] if data else [])
                       if m.dt > 0})
    for f_nyq in nyquists:
        _shared_vline(axes, f_nyq * x_scale, color="0.5", lw=0.6, ls=":")
    # minor log ticks are slow to draw (a Tick object each, 40 % of a 2 x 2 diagram):
    # at 2 and 5 of every decade on a single pair's diagram, none on a grid (the
    # decades are labelled and gridded)
    from matplotlib.ticker import LogLocator, NullLocator
    for ax in axes.ravel():
        ax.xaxis.set_minor_locator(NullLocator() if ny * nu > 1 else
                                   LogLocator(base=10.0, subs=(2.0, 5.0)))
    _legend_beside(axes[0, -1])
    if title:
        fig.suptitle(title)
    _layout(fig, axes, hgap=0.5, wgap=0.85, right=room + 0.1)
    return fig


def _shared_vline(axes, x, **style):
    """``ax.axvline(x, **style)`` on every panel of a grid sharing its x axis.

    What axvline does (a line from bottom to top at ``x``, which joins the data
    limits, and a new autoscale when ``x`` lies outside the current view), with the
    view computed once for the grid: each axvline reads the view, which after the
    previous one's autoscale request is recomputed over every panel sharing the
    axis (a tenth of the time to build a 4 x 2 Bode diagram)."""
    from matplotlib.lines import Line2D
    low, high = axes.flat[0].get_xbound()
    for ax in axes.ravel():
        ax.add_line(Line2D([x, x], [0.0, 1.0], transform=ax.get_xaxis_transform(which="grid"),
                           **style))
    if (x < low or x > high) and axes.flat[0].get_autoscalex_on():
        axes.flat[0].autoscale(axis="x")        # requested, for every panel sharing x


def _data_grid(data) -> np.ndarray:
    """Model frequencies for a Bode diagram over measured data: a log grid over the data's band."""
    positive = data.w[data.w > 0]
    if positive.size < 2:
        return positive if positive.size else np.array([1.0])
    return np.logspace(np.log10(positive[0]), np.log10(positive[-1]), 400)


def _bode_data(axes, data, x_scale, phase, reference=None):
    """Measured response as points (and a two-sigma magnitude band when ``std`` is known).

    The unwrapped phase of each channel is shifted by whole turns to start
    nearest the ``reference`` ``(w, phase)`` of the first model."""
    keep = data.w > 0                                  # a log axis cannot show w = 0
    w, G = data.w[keep] * x_scale, data.response[keep]
    if w.size == 0:
        return
    with np.errstate(divide="ignore"):
        mag = 20 * np.log10(np.maximum(np.abs(G), 1e-300))
    ph = np.degrees(np.unwrap(np.angle(G), axis=0))
    if reference is not None and reference[0].size:
        w_ref, ph_ref = reference
        for i in range(data.n_outputs):
            for j in range(data.n_inputs):
                target = np.interp(data.w[keep][0], w_ref, ph_ref[:, i, j])
                ph[:, i, j] += 360.0 * np.round((target - ph[0, i, j]) / 360.0)
    for i in range(data.n_outputs):
        for j in range(data.n_inputs):
            r = 2 * i if phase else i
            axes[r, j].plot(w, mag[:, i, j], ".", color="0.35", ms=3, label="data",
                                zorder=1)
            if data.std is not None:
                absG, sd = np.abs(G[:, i, j]), 2 * data.std[keep][:, i, j]
                with np.errstate(divide="ignore"):
                    # a band reaching zero is drawn to 60 dB below the point (as the
                    # models' bands): a floor of 1e-12 |G| stretched the axis to -260 dB
                    # on a noisy spa estimate and flattened the data
                    lo = 20 * np.log10(np.maximum(absG - sd, 1e-300 + 1e-3 * absG))
                    hi = 20 * np.log10(np.maximum(absG + sd, 1e-300))
                axes[r, j].fill_between(w, lo, hi, color="0.8", lw=0, zorder=0)
            if phase:
                axes[r + 1, j].plot(w, ph[:, i, j], ".", color="0.35", ms=3, zorder=1)


def _has_covariance(model) -> bool:
    return isinstance(model.info.get("parameter_covariance"), dict)


def _require_covariance(groups) -> None:
    """Refuse bands when no model has a covariance; warn naming the models drawn without
    one when only some have it (their bands were left out silently)."""
    if not any(_has_covariance(m) for m in groups.values()):
        if all(m.is_continuous for m in groups.values()):
            # pem refines a continuous-time model too, but attaches no covariance to it
            raise ModelError(
                "confidence bands need a model with a parameter covariance; continuous-time "
                f"models carry none ({list(groups)}), refined by pem or not: draw the bands "
                "of a discrete-time model (subid.identify(data), or pem on discrete-time "
                "data)")
        raise ModelError("confidence bands need a model with a parameter covariance; none of "
                         f"{list(groups)} has one: refine a model with subid.pem(data, model)")
    missing = [label for label, m in groups.items() if not _has_covariance(m)]
    if missing:
        import warnings
        warnings.warn(f"no confidence band for {', '.join(repr(v) for v in missing)}: "
                      f"{'it has' if len(missing) == 1 else 'they have'} no parameter "
                      "covariance (a subspace model); refine with subid.pem(data, model) "
                      "for one", UserWarning, stacklevel=4)


@_styled
def step(model_or_models, t=None, *, labels=None, confidence=None, title=None):
    """Step responses of every input/output pair (MATLAB ``step``).

    Parameters
    ----------
    model_or_models : StateSpace, list of StateSpace or dict label -> StateSpace
        Models of the same shape (:meth:`StateSpace.step`).
    t : float or array_like, optional
        Final time or time stamps (default: the slowest model's settling time).
    labels : list of str, optional
        Legend labels.
    confidence : float, optional
        Draw the band of this level (e.g. 0.95) around the response of every
        model that has a parameter covariance (:func:`subid.step_bounds`); a
        ``ModelError`` when none has one.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        One panel per output (rows) and input (columns).
    """
    plt = _pyplot()
    groups = _model_groups(model_or_models, labels)
    first = next(iter(groups.values()))
    ny, nu = first.n_outputs, first.n_inputs
    if nu == 0:
        raise ModelError("the model has no inputs: there is no step response to draw")
    if any((m.n_outputs, m.n_inputs) != (ny, nu) for m in groups.values()):
        raise ModelError("step: the models differ in their numbers of inputs and outputs")
    if confidence is not None:
        _require_covariance(groups)
    if t is None:
        t = max(float(m.step()[0][-1]) for m in groups.values())
    colors = colors_for(groups.items())
    room = _legend_room(list(groups))
    fig, axes = plt.subplots(ny, nu, figsize=(min(3.8 * nu + 1.2, 16) + room, 2.2 * ny + 0.8),
                             sharex=True, squeeze=False, subplot_kw=subplot_kw())
    with _autoscale_once(axes):      # the limits once, after the plotting calls
        for k, (label, m) in enumerate(groups.items()):
            if confidence is not None and _has_covariance(m):
                from subid.evaluation.uncertainty import step_bounds
                band = step_bounds(m, t, confidence)
                tk, y = band.x, band.value
            else:
                band = None
                tk, y = m.step(t)
            for i in range(ny):
                for j in range(nu):
                    draw = axes[i, j].step if m.dt > 0 else axes[i, j].plot
                    kwargs = {"where": "post"} if m.dt > 0 else {}
                    draw(tk, y[:, i, j], color=colors[k], lw=1.2, label=label, **kwargs)
                    if band is not None:
                        axes[i, j].fill_between(tk, band.lower[:, i, j], band.upper[:, i, j],
                                                color=colors[k], alpha=0.2, lw=0,
                                                step="post" if m.dt > 0 else None)
    for i in range(ny):
        for j in range(nu):
            axes[i, j].set_title(f"{first.input_names[j]} → {first.output_names[i]}")
            axes[i, j].grid(True, lw=0.3)
    for j in range(nu):
        axes[-1, j].set_xlabel("time")
    _legend_beside(axes[0, -1])
    if title:
        fig.suptitle(title)
    _layout(fig, axes, hgap=0.5, wgap=0.85, right=room + 0.1)
    return fig

