"""The checks of a record every discrete-time method (and :func:`subid.pem`) makes
at its boundary: an IOData record, uniformly sampled, magnitudes whose squares do
not overflow, inputs not lost against their offsets, no constant output."""

from __future__ import annotations

import warnings

import numpy as np

from subid.data import IOData, column_std, column_sums, not_a_record
from subid.errors import DataError, NotExcitingError, OffsetWarning

#: Largest magnitude of a channel the methods accept: its square must not overflow.
HUGE_VALUE = 1e150


def check_data(data, method: str) -> IOData:
    """The record a discrete-time method may use, or a clear error."""
    if not isinstance(data, IOData):
        raise not_a_record(data, method)
    if not data.is_uniform:
        raise DataError(f"{method} identifies a discrete-time model and needs uniformly "
                        "sampled data; these time stamps are non-uniform "
                        "(use a continuous-time method for them)")
    for name, signal, names in (("input", data.u, data.input_names),
                                ("output", data.y, data.output_names)):
        if not signal.size or max(abs(float(signal.max())), abs(float(signal.min()))) \
                <= HUGE_VALUE:       # whole-array reductions: cheap on long records
            continue
        peak = np.abs(signal).max(axis=0)
        huge = np.flatnonzero(peak > HUGE_VALUE)
        if huge.size:
            k = int(huge[0])
            raise DataError(f"{name} {names[k]} reaches {peak[k]:.3g}: squares and products "
                            "of such values overflow double precision in the identification; "
                            "express the channel in other units (divide it by a constant) "
                            "and scale the model back")
    check_offsets(data.u, data.input_names, method)
    warn_offsets(data)
    flat = [k for k, column in enumerate(data.y.T) if column.max() == column.min()]
    if flat:
        names = ", ".join(data.output_names[k] for k in flat)
        raise DataError(f"output {names} is constant over the whole record: it carries no "
                        "information about the dynamics; drop that channel")
    return data


#: A channel whose mean exceeds this many standard deviations sits at an operating point
#: (:func:`warn_offsets`): an excitation from zero (a step, a PRBS between 0 and 1) has a
#: mean of about one standard deviation.
OFFSET_STDS = 3.0


def warn_offsets(data: IOData) -> None:
    """An :class:`subid.errors.OffsetWarning` when a channel's mean exceeds
    :data:`OFFSET_STDS` standard deviations, naming the largest. Measured: a 2 x 2
    order-3 record (30 dB) with input offsets of 5 and 3 and output offsets of about 7
    standard deviations: ``moesp`` chose order 4 and validated at 59.5 / 70.2 %, against
    96.8 / 96.9 % detrended, and the feedback test fired on this open-loop record."""
    worst = None
    for role, signal, names in (("input", data.u, data.input_names),
                                ("output", data.y, data.output_names)):
        if not signal.size:
            continue
        means = column_sums(signal) / signal.shape[0]
        spread = column_std(signal, block=8192)
        ratio = np.abs(means) / np.where(spread > 0, spread, np.inf)
        k = int(np.argmax(ratio))
        if ratio[k] > OFFSET_STDS and (worst is None or ratio[k] > worst[0]):
            worst = (float(ratio[k]), role, names[k], float(means[k]))
    if worst is not None:
        ratio, role, name, mean = worst
        warnings.warn(f"{role} {name} has a mean of {mean:.4g}, {ratio:.3g} times its standard "
                      "deviation: the methods identify from the samples as given, and an "
                      "operating point that the inputs do not explain costs fit and states. "
                      "Remove the means first (data.detrend(), as subid identify on the "
                      "command line does)", OffsetWarning, stacklevel=2)


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
