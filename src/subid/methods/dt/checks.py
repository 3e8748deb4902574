"""The checks of a record every discrete-time method (and :func:`subid.pem`) makes
at its boundary: an IOData record, uniformly sampled, magnitudes whose squares do
not overflow or underflow, inputs not lost against their offsets, no constant output."""

from __future__ import annotations

import warnings

import numpy as np
import scipy.special

from subid._validation import check_magnitude, check_tiny
from subid.data import IOData, column_std, column_sums, not_a_record
from subid.errors import DataError, NotExcitingError, OffsetWarning


def check_data(data, method: str, *, warn: bool = True) -> IOData:
    """The record a discrete-time method may use, or a clear error; ``warn``: also the
    warnings about its operating point and drift (:func:`warn_offsets`,
    :func:`warn_trends`), which a cross-validation fold, whose warnings are not shown,
    skips (they cost 2.3 ms a fold at 10^5 samples)."""
    if not isinstance(data, IOData):
        raise not_a_record(data, method)
    if not data.is_uniform:
        raise DataError(f"{method} identifies a discrete-time model and needs uniformly "
                        "sampled data; these time stamps are non-uniform "
                        "(use a continuous-time method for them; if the samples are "
                        "uniform and only their stamps jitter, build the record with the "
                        "sampling period: subid.IOData(u, y, dt=...))")
    check_channels(data)
    check_offsets(data.u, data.input_names, method)
    if warn:
        warn_offsets(data)
        warn_trends(data)
    return data


def check_channels(data: IOData) -> None:
    """The checks of the samples every method makes (:func:`check_data`, and
    :func:`subid.impulseest`, :func:`subid.ct_subspace`): no magnitude whose square
    overflows or underflows (:func:`subid._validation.check_magnitude`,
    :func:`subid._validation.check_tiny`), no constant output; else :class:`DataError`."""
    check_magnitude(data.u, "input", data.input_names)
    check_magnitude(data.y, "output", data.output_names)
    check_tiny(data.u, "input", data.input_names)
    check_tiny(data.y, "output", data.output_names)
    flat = [k for k, column in enumerate(data.y.T) if column.max() == column.min()]
    if flat:
        names = ", ".join(data.output_names[k] for k in flat)
        raise DataError(f"output {names} is constant over the whole record: it carries no "
                        "information about the dynamics; drop that channel")


#: A channel whose mean exceeds this many standard deviations sits at an operating point
#: (:func:`warn_offsets`): an excitation from zero (a step, a PRBS between 0 and 1) has a
#: mean of about one standard deviation.
OFFSET_STDS = 3.0


#: Lags and samples (the last ones) of the ARX regression of :func:`_unexplained_offset`,
#: and its largest number of columns (fewer lags on records of many channels: 100
#: channels at 10 lags would factor 20,000 x 1,050).
OFFSET_LAGS, OFFSET_SAMPLES, OFFSET_COLUMNS = 10, 20_000, 200
#: Samples (the last ones) whose means and spreads :func:`warn_offsets` compares.
OFFSET_MOMENT_SAMPLES = 100_000
#: Significance level of its test of the intercept.
OFFSET_LEVEL = 1e-3


def _unexplained_offset(data: IOData, *, trend: bool = False) -> np.ndarray | None:
    """Whether the inputs leave an offset (``trend``: a linear trend) in the outputs
    unexplained: in the regression of each output on :data:`OFFSET_LAGS` lags (fewer past
    :data:`OFFSET_COLUMNS` columns) of the outputs and the inputs (a high-order ARX model,
    which approximates any linear predictor, Ljung 1999, Sec. 16.4), a constant (and the
    sample index), the last term's F-test is significant at :data:`OFFSET_LEVEL` (last
    experiment, last :data:`OFFSET_SAMPLES` samples): a boolean per output, None when the
    record is too short to tell. A record excited from rest (a staircase of steps from
    zero) has large means, or a response that builds up, that the inputs explain: no
    warning for it."""
    e = data.experiments[-1]
    u, y = e.u[-OFFSET_SAMPLES:], e.y[-OFFSET_SAMPLES:]
    N = y.shape[0]
    L = max(1, min(OFFSET_LAGS, OFFSET_COLUMNS // (u.shape[1] + y.shape[1])))
    if N <= 4 * L * (u.shape[1] + y.shape[1] + 1 + trend):
        return None
    cols = [y[L - i:N - i] for i in range(1, L + 1)] + [u[L - i:N - i] for i in range(L + 1)]
    cols.append(np.ones((N - L, 1)))
    if trend:
        cols.append(np.linspace(-1.0, 1.0, N - L)[:, None])
    X = np.hstack(cols)
    Q, R = np.linalg.qr(X)
    d = abs(R[-1, -1])
    if not d > 1e-10 * np.sqrt(N - L):      # the term lies in the span of the lags
        return None
    proj = Q.T @ y[L:]
    total = np.sum(y[L:] ** 2, axis=0)
    rss1 = total - np.sum(proj ** 2, axis=0)
    # the lags explain an output to rounding (noise-free data, an unstable plant's
    # growth included): nothing is left for the constant or the trend, whose F-ratio
    # would divide rounding by rounding
    exact = rss1 <= 1e-12 * total
    gain = proj[-1] ** 2                    # what the last term takes off the residual
    dof = N - L - X.shape[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        F = gain / (np.maximum(rss1, 0.0) / dof)
    p_values = scipy.special.fdtrc(1, dof, F)
    return (np.nan_to_num(p_values, nan=1.0) < OFFSET_LEVEL) & ~exact


def warn_offsets(data: IOData) -> None:
    """An :class:`subid.errors.OffsetWarning` when a channel's mean exceeds
    :data:`OFFSET_STDS` standard deviations (over the last :data:`OFFSET_MOMENT_SAMPLES`
    samples; naming the largest) and the inputs do not
    explain the outputs' offsets (:func:`_unexplained_offset`). Measured: a 2 x 2 order-3
    record (30 dB) with input offsets of 5 and 3 and output offsets of about 7 standard
    deviations: ``moesp`` chose order 4 and validated at 59.5 / 70.2 %, against 96.8 /
    96.9 % detrended, and the feedback test fired on this open-loop record; a staircase of
    steps from rest (means 3.3 standard deviations) validates alike raw and detrended. On
    DaISy records (``moesp``, first 2/3 to estimate; re-measured in session 21): steamgen
    warns, 72.9 % raw against 76.0 % detrended; exchanger warns, 64.6 % raw against 57.4 %
    (hence "compare", not "remove"); dryer does not warn (its offsets pass the intercept
    test), 86.8 % raw against 89.6 % (session 20)."""
    worst = None
    # the last OFFSET_MOMENT_SAMPLES samples at most (12 ms of every check of a 2 x 2
    # record of 10^6 samples otherwise, against a pinned call of 130 ms)
    tail = slice(max(data.n_samples - OFFSET_MOMENT_SAMPLES, 0), None)
    for role, signal, names in (("input", data.u[tail], data.input_names),
                                ("output", data.y[tail], data.output_names)):
        if not signal.size:
            continue
        means = column_sums(signal) / signal.shape[0]
        spread = column_std(signal, block=8192)
        ratio = np.abs(means) / np.where(spread > 0, spread, np.inf)
        k = int(np.argmax(ratio))
        if ratio[k] > OFFSET_STDS and (worst is None or ratio[k] > worst[0]):
            worst = (float(ratio[k]), role, names[k], float(means[k]))
    if worst is not None and np.any(_unexplained_offset(data)):
        ratio, role, name, mean = worst
        warnings.warn(f"{role} {name} has a mean of {mean:.4g}, {ratio:.3g} times its standard "
                      "deviation, and the inputs do not explain the outputs' offsets: the methods "
                      "identify from the samples as given, so the model's states must explain "
                      "that operating point. Compare with the means removed: data.detrend() "
                      "(on the command line --detrend constant, the default)",
                      OffsetWarning, stacklevel=2)


#: An output whose straight-line trend takes at least this share of its variance (over the
#: last :data:`TREND_SAMPLES` samples) drifts (:func:`warn_trends`).
TREND_SHARE = 0.25
#: Samples (the last ones) whose trend :func:`warn_trends` measures: a share of variance
#: needs no more, and the check runs on every fold of a default call (over 10^5 samples it
#: cost 2.3 ms a check, 13.6 ms of a 160 ms ``moesp(data)``).
TREND_SAMPLES = 20_000


def warn_trends(data: IOData) -> None:
    """An :class:`subid.errors.OffsetWarning` when an output's straight-line trend takes
    at least :data:`TREND_SHARE` of its variance (over the last :data:`TREND_SAMPLES`
    samples of the last experiment; naming the largest) and the inputs do not explain it
    (:func:`_unexplained_offset` with the trend). A drift the methods take as
    given must be a state: an unstable or integrating mode. Measured (session 24's
    exploratory test): a SISO order-3 record (20 dB, 1500 samples) with a sensor drift of
    0.01 per sample (trend share 0.66): ``identify`` validated at 52.3 and 63.5 % with
    unstable models, without a word, against 89.8 and 90.0 % after ``detrend('linear')``
    (0.002 per sample, share 0.07: 88.3 and 89.6 %, no warning). Among the DaISy records
    (2/3 to estimate, means removed) only dryer2's and powerplant's outputs reach the
    share (0.70, 0.78; 0.05-0.19 for powerplant's), with inputs that trend too."""
    last = data.experiments[-1]        # a line across experiments means nothing
    y = last.y[max(last.n_samples - TREND_SAMPLES, 0):]
    if y.shape[0] < 3:
        return
    k = np.linspace(-1.0, 1.0, y.shape[0])
    centred = y - column_sums(y)[None, :] / y.shape[0]
    slope = (k @ centred) / (k @ k)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.nan_to_num(slope ** 2 * (k @ k) / np.sum(centred ** 2, axis=0))
    if not share.max() >= TREND_SHARE:
        return
    unexplained = _unexplained_offset(data, trend=True)
    if unexplained is None or not np.any(unexplained & (share >= TREND_SHARE)):
        return
    j = int(np.argmax(np.where(unexplained, share, -1.0)))
    dt = data.dt or 0.0                   # uniform here (check_data)
    per_sample = slope[j] * 2.0 / max(y.shape[0] - 1, 1)
    per_time = per_sample / dt if dt > 0 else per_sample
    warnings.warn(f"output {data.output_names[j]} drifts: a straight-line trend "
                  f"({per_time:.4g} per time unit) takes {100 * share[j]:.0f} % of its "
                  "variance, and the inputs do not explain it: the methods identify from "
                  "the samples as given, so the model needs an unstable or integrating mode "
                  "to follow it. Compare with it removed: data.detrend('linear') (on the "
                  "command line --detrend linear)", OffsetWarning, stacklevel=2)


#: An input whose standard deviation is below this fraction of its mean is lost
#: against its offset in double precision (the Hankel rows of its lags coincide
#: to rounding): :func:`check_offsets`.
OFFSET_RATIO = 1e-8


def check_offsets(u, input_names, method: str) -> None:
    """Raise :class:`NotExcitingError` naming the offset when an input's variation
    is below :data:`OFFSET_RATIO` of its mean.

    The methods identify from the samples as given (offsets included); an
    input of 1e12 ± 1 then has lagged Hankel rows equal to rounding, and the
    excitation check would report a lagged dependence instead of the cause.
    """
    if not u.size:
        return
    mean = np.abs(column_sums(u)) / u.shape[0]
    std = column_std(u, block=8192)      # channel by channel from 8192 samples (cheaper)
    lost = np.flatnonzero((mean > 0) & (std < OFFSET_RATIO * mean) & (std > 0))
    if lost.size:
        k = int(lost[0])
        raise NotExcitingError(
            f"{method}: input {input_names[k]} varies by {std[k]:.3g} (standard deviation) "
            f"around an offset of {mean[k]:.3g}: in double precision its variation is lost "
            "against the offset in the identification's products. Remove the offsets "
            "first (data.detrend('constant'), or subtract a constant from the channel)",
            required_order=None, achieved_order=0)
