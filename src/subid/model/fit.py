"""The fit of a model to data, NRMSE in percent (:func:`fit_percent`), for records (by
simulation or k-step prediction, :mod:`subid.model.prediction`) and frequency responses
(:func:`frequency_fit`). Below the methods, whose order and structure selection score the
held-out folds with it; :mod:`subid.evaluation.metrics` exports it as :func:`subid.fit_percent`.
"""

from __future__ import annotations

import numpy as np

from subid._blas import serial_blas
from subid._validation import checked_call, same_period
from subid.errors import DataError, OptionError
from subid.model.prediction import _SIM_BLOCK, check_model, predict, simulate_fit

__all__ = ["fit_percent", "frequency_fit", "output_fit"]


@serial_blas
@checked_call
def fit_percent(model, data, x0="estimate", hold=None, steps=np.inf, *,
                per_experiment: bool = False) -> np.ndarray:
    """NRMSE fit in percent, per output: ``100 (1 - ||y - ŷ|| / ||y - mean(y)||)``.

    ``ŷ`` is the simulated output (default, ``steps=inf``) or the
    ``steps``-ahead prediction (:func:`subid.predict`, the Kalman predictor
    of a model with ``K``), from an initial state estimated by least squares
    unless ``x0`` says otherwise. 100 is a perfect fit; 0 is no better than
    the mean; it can be negative.

    Parameters
    ----------
    model : StateSpace
    data : IOData
        Same channels; for a discrete model, the same sampling period.
    x0 : 'estimate', None, 'zero', 0 or array_like of shape (n,)
        Initial state: 'estimate' or None (default) fits it by least
        squares, 'zero' or 0 is the zero state, an array gives it (shape
        (n_experiments, n) for a record of several experiments). Anything
        else raises a :class:`~subid.errors.DataError` (as in
        :func:`subid.predict`; one validator,
        :func:`subid.model.prediction.check_x0`).
    hold : {'zoh', 'foh'}, optional
        Inter-sample behaviour of the input for a continuous-time model.
        Default: the model's :attr:`~subid.StateSpace.hold` (``'foh'`` for a
        ``ct_subspace`` model).
    steps : int or numpy.inf
        Prediction horizon (MATLAB ``compare(data, model, k)``).
    per_experiment : bool
        For a record of several experiments (:func:`subid.merge`; each is
        simulated from its own initial state): ``False`` (default) gives one
        pooled fit per output, ``100 (1 - ||y - ŷ|| / ||y - ȳ_e||)`` over all
        samples with each experiment's own mean ``ȳ_e`` as the reference;
        ``True`` gives one fit per experiment and output (as MATLAB's
        ``compare``).

    Returns
    -------
    ndarray, shape (n_outputs,), or (n_experiments, n_outputs) with
    ``per_experiment=True``

    Notes
    -----
    For frequency-response data (``data`` an :class:`subid.FRData`) the fit
    is the frequency-domain analogue, per output i:
    ``100 (1 - ||W (G_i - Ĝ_i)|| / ||W (G_i - Ḡ_i)||)``, the norms over all
    frequencies and inputs, ``W`` the data's weights (ones when none),
    ``Ĝ`` the model's response at the data's frequencies and ``Ḡ_i`` the
    weighted mean over frequencies of each channel pair (the best constant
    response). ``x0``, ``hold``, ``steps`` and ``per_experiment`` do not apply.
    """
    from subid.frdata import FRData
    if isinstance(data, FRData):
        return frequency_fit(model, data)
    if steps is not None and not (isinstance(steps, float) and np.isinf(steps) and steps > 0):
        y_hat = predict(check_model(model, "model"), data, steps, x0, hold=hold)
    else:
        y_hat, _ = simulate_fit(model, data, x0=x0, hold=hold)
    return output_fit(data, y_hat, per_experiment=per_experiment)


def output_fit(data, y_hat, *, per_experiment: bool = False, constant: str = "raise") -> np.ndarray:
    """The fit % of :func:`fit_percent` for outputs ``y_hat`` already simulated or
    predicted on ``data`` (its last step: the report's comparison figure draws the
    simulation that gave the fit, see :func:`subid.evaluation.report.evaluate`).

    Parameters
    ----------
    data : IOData
        The record ``y_hat`` was computed on.
    y_hat : ndarray, shape (n_samples, n_outputs)
    per_experiment : bool
        As in :func:`fit_percent`.
    constant : {'raise', 'nan'}
        An output that is constant (in an experiment, with ``per_experiment``)
        has no fit: ``'raise'`` (default) a :class:`~subid.errors.DataError`,
        ``'nan'`` NaN for it (a figure's legend).

    Returns
    -------
    ndarray, shape (n_outputs,), or (n_experiments, n_outputs) with
    ``per_experiment=True``
    """
    if constant not in ("raise", "nan"):
        raise OptionError(f"constant must be 'raise' or 'nan', got {constant!r}")
    # Each output is divided by its largest magnitude first: the ratio is
    # scale-invariant, and squaring values near 1e300 would overflow to inf
    # (inf / inf = NaN) where the fit is perfectly defined.
    # In blocks of rows, so that no N x outputs temporary is allocated.
    N, block = data.n_samples, _SIM_BLOCK
    scale = np.zeros(data.n_outputs)
    for a in range(0, N, block):
        scale = np.maximum(scale, np.abs(data.y[a:a + block]).max(axis=0))
    scale[scale == 0] = 1.0
    ranges = data.experiment_ranges
    dev2 = np.zeros((len(ranges), data.n_outputs))
    err2 = np.zeros((len(ranges), data.n_outputs))
    for e, (a0, b0) in enumerate(ranges):       # each experiment against its own mean
        mean = sum(np.sum(data.y[a:min(a + block, b0)] / scale, axis=0)
                   for a in range(a0, b0, block)) / (b0 - a0)
        for a in range(a0, b0, block):
            b = min(a + block, b0)
            y = data.y[a:b] / scale
            dev2[e] += np.sum((y - mean) ** 2, axis=0)
            err2[e] += np.sum((y - y_hat[a:b] / scale) ** 2, axis=0)
    if per_experiment:
        dev2_used, err2_used = dev2, err2
    else:
        dev2_used, err2_used = dev2.sum(axis=0), err2.sum(axis=0)
    flat = np.flatnonzero(np.atleast_2d(dev2_used).min(axis=0) == 0)
    if flat.size and constant == "nan":
        with np.errstate(divide="ignore", invalid="ignore"):
            return 100.0 * (1.0 - np.sqrt(err2_used) / np.where(dev2_used > 0,
                                                                np.sqrt(dev2_used), np.nan))
    if flat.size:
        names = ", ".join(data.output_names[k] for k in flat)
        where = " in an experiment" if per_experiment and data.n_experiments > 1 else ""
        raise DataError(f"output {names} is constant{where}; the fit percentage is undefined "
                        "for it")
    return 100.0 * (1.0 - np.sqrt(err2_used) / np.sqrt(dev2_used))


def frequency_fit(model, data) -> np.ndarray:
    """Frequency-domain fit (%) per output of ``model`` on :class:`subid.FRData`
    ``data`` (see :func:`fit_percent`, Notes)."""
    check_model(model, "model")
    if (model.n_inputs, model.n_outputs) != (data.n_inputs, data.n_outputs):
        raise DataError(f"the data have {data.n_inputs} inputs and {data.n_outputs} outputs "
                        f"but the model has {model.n_inputs} and {model.n_outputs}")
    if model.dt != data.dt and not same_period(model.dt, data.dt):
        raise DataError(f"the model has dt={model.dt} but the frequency data have "
                        f"dt={data.dt} (0 = continuous time); convert the model "
                        "(to_discrete / to_continuous)")
    G = data.response
    W2 = data.fit_weights() ** 2
    G_hat = model.freqresp(data.w)
    mean = (W2 * G).sum(axis=0) / W2.sum(axis=0)
    err = np.sqrt((W2 * np.abs(G - G_hat) ** 2).sum(axis=(0, 2)))
    dev = np.sqrt((W2 * np.abs(G - mean) ** 2).sum(axis=(0, 2)))
    flat = np.flatnonzero(dev == 0)
    if flat.size:
        names = ", ".join(data.output_names[k] for k in flat)
        raise DataError(f"the response of output {names} does not vary with frequency; the "
                        "fit percentage is undefined for it")
    return 100.0 * (1.0 - err / dev)
