"""Exceptions raised by subid.

Every exception raised on purpose by subid derives from :class:`SubidError`,
itself a :class:`ValueError`, so ``except ValueError`` keeps working for code
that does not know about subid. Messages say what is wrong and what to do.
"""

from __future__ import annotations

__all__ = [
    "SubidError",
    "DataError",
    "TooFewSamplesError",
    "NotExcitingError",
    "OrderError",
    "ModelError",
    "FileReadError",
    "DataFileNotFoundError",
    "ExcitationWarning",
    "CheckpointError",
    "UnstableModelWarning",
    "NoiseModelWarning",
    "ResolutionWarning",
    "FileWriteError",
    "ResourceLimitError",
    "NotConvergedWarning",
    "DelayWarning",
    "ConversionWarning",
    "OffsetWarning",
    "FeedbackWarning",
    "PoorFitWarning",
    "SamplingWarning",
    "OptionError",
]


#: Longest message an error keeps; beyond, its middle is cut (an echoed cell, name
#: or value of millions of characters must not become a megabyte line on stderr).
MAX_MESSAGE_CHARS = 2000


def shorten(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` itself, or its beginning and end around a note of how much was cut."""
    text = str(text)
    if len(text) <= limit:
        return text
    head, tail = (2 * limit) // 3, limit // 4
    return f"{text[:head]} ... [{len(text) - head - tail} characters cut] ... {text[-tail:]}"


class SubidError(ValueError):
    """Base class of all errors raised by subid.

    A message longer than :data:`MAX_MESSAGE_CHARS` is shortened in its middle
    (:func:`shorten`): whatever a message echoes (a cell, a name, a value), it
    stays a readable line.
    """

    def __init__(self, *args):
        if args and isinstance(args[0], str) and len(args[0]) > MAX_MESSAGE_CHARS:
            args = (shorten(args[0]),) + args[1:]
        super().__init__(*args)

    def __reduce__(self):
        # rebuilt by calling the class (its attributes set after): the default reduction
        # of an exception that is also an OSError (FileWriteError, DataFileNotFoundError)
        # is rebuilt by dask.distributed's unpickler (tblib) with ValueError.__new__,
        # which Python refuses for them, so a cluster's client got a bare Exception
        return _rebuild, (type(self), self.args, dict(self.__dict__))


def _rebuild(cls, args, state):
    """A :class:`SubidError` of class ``cls`` from its ``args`` and attributes (its
    reduction, :meth:`SubidError.__reduce__`)."""
    error = cls(*args)
    error.__dict__.update(state)
    return error


class DataError(SubidError):
    """Input/output data are unusable: NaN or inf values, mismatched lengths,
    wrong dtype or shape, time stamps that do not increase."""


class TooFewSamplesError(DataError):
    """The record is too short for the requested horizon, order or basis."""


class NotExcitingError(DataError):
    """The input is not persistently exciting of the order the method needs.

    Attributes
    ----------
    required_order : int
        Order of persistent excitation the method needs.
    achieved_order : int
        Largest order of excitation the data provide (0 for a zero input).
    """

    def __init__(self, message: str, *, required_order: int | None = None,
                 achieved_order: int | None = None):
        super().__init__(message)
        self.required_order = required_order
        self.achieved_order = achieved_order


class OrderError(SubidError):
    """The requested model order is invalid or cannot be revealed by the
    chosen horizon and number of outputs."""


class OptionError(SubidError):
    """An option of a method or function has a bad value: an unknown choice,
    the wrong type, or a value out of range. The message names the option,
    the value given and what is allowed."""


class ModelError(SubidError):
    """A state-space model is malformed: matrix shapes disagree, values are not
    finite, or a model file cannot be interpreted."""


class _LocatedError(SubidError):
    """An error that may name a file and a place in it (``path``, ``line``,
    ``column``; each None when unknown)."""

    def __init__(self, message: str, *, path=None, line=None, column=None):
        super().__init__(message)
        self.path = None if path is None else str(path)
        self.line = line
        self.column = column


class FileReadError(_LocatedError):
    """A data or model file cannot be read.

    Attributes
    ----------
    path : str or None
        The file.
    line : int or None
        1-based line number of the problem, when it is known.
    column : int or str or None
        Column (0-based index or name) of the problem, when it is known.
    """


class ResourceLimitError(_LocatedError):
    """A file or a request needs more than the caller allowed or than fits:
    a compressed archive that would expand beyond ``max_bytes``, a text line
    longer than the limit, a statistic or a regression larger than the
    memory budget. The message names the limit and how to raise it or to
    avoid it. When a file is the cause, ``path`` (and ``line``) name it, as
    for :class:`FileReadError`; otherwise they are None.
    """


class FileWriteError(SubidError, OSError):
    """A file or folder cannot be written (disk full, permissions, a name
    holding a NUL byte). Also an :class:`OSError`; ``path`` and ``filename``
    name the file the user asked for, never a temporary file. The previous
    content, if any, is unchanged."""

    def __init__(self, message: str, *, path=None):
        super().__init__(message)
        self.path = None if path is None else str(path)
        self.filename = self.path

    def __str__(self) -> str:
        return self.args[0] if self.args else ""


class DataFileNotFoundError(FileReadError, FileNotFoundError):
    """The file does not exist (also a :class:`FileNotFoundError`)."""


class ExcitationWarning(UserWarning):
    """The input excites the system only barely (ill-conditioned data matrix);
    the identified model may be unreliable."""


class CheckpointError(FileReadError):
    """A checkpoint file is truncated, corrupted, of another kind or of an
    unsupported version."""


class UnstableModelWarning(UserWarning):
    """The identified model is unstable although the measured output shows no
    growth: the order may be too high, or the data too short or too noisy."""


class NoiseModelWarning(UserWarning):
    """A noise model (Kalman gain, innovation covariance) is missing, dropped or
    could not be estimated, and a computation falls back to the deterministic
    model (e.g. prediction by simulation)."""


class NotConvergedWarning(UserWarning):
    """An online identifier's current model is not (yet) a converged estimate:
    a stage has not started, or its convergence test fails. ``model.info``
    says which (``converged``, ``convergence``)."""


class OffsetWarning(UserWarning):
    """A channel of the record sits far from zero (an operating point that was not
    removed): the discrete-time methods identify from the samples as given, and an offset
    the inputs do not explain costs fit and states. ``data.detrend()`` removes it."""


class FeedbackWarning(UserWarning):
    """The data show feedback from the outputs to the inputs (closed loop), and the
    estimate's criterion is biased there: an output-error (simulation) criterion, whose
    input is correlated with the noise (Ljung 1999, Sec. 13.4). The message names a
    consistent alternative."""


class PoorFitWarning(UserWarning):
    """The data do not support the model returned: the model an order search chose
    simulates its held-out folds worse than their means (a negative cross-validated fit:
    no candidate describes the data; the message names what usually causes it: drifts
    or offsets, feedback, nonlinearity), or a regularised impulse response whose
    parameters the data barely determine (:func:`subid.impulseest`)."""


class DelayWarning(UserWarning):
    """Input delays counted in samples (``info['input_delay']``) are dropped by an
    operation that changes the time base (:meth:`subid.StateSpace.to_continuous`: dead
    time has no finite-dimensional continuous-time state-space form); the message says
    what keeps or approximates them."""


class ConversionWarning(UserWarning):
    """A discrete-time model has no continuous-time counterpart of its order under the
    hold (a pole on the negative real axis, or at the origin), and a continuous-time
    method changed its result because of it: a mode at the Nyquist frequency was added
    (one state more per such pole), or another candidate model was used. The message
    says which (:func:`subid.ct_subspace`'s discrete-time starts). Also: a model that
    assumes a first-order hold (``hold='foh'``) is exported to a system without an input
    hold (:meth:`subid.StateSpace.to_control`, :meth:`~subid.StateSpace.to_scipy`), which
    read as a zero-order hold."""


class SamplingWarning(UserWarning):
    """A record read without its sampling period (``dt = 1``, time counted in samples)
    from a file with a column that looks like time stamps (``time``, ``t``,
    ``Time [s]``...): the message names it and how to use it; ``column`` holds its
    name."""

    def __init__(self, message: str, column: str | None = None):
        super().__init__(message)
        self.column = column


class ResolutionWarning(UserWarning):
    """A spectral estimate (:func:`subid.spa`) cannot resolve the response at some
    frequencies with its lag window: the estimated noise spectrum is not positive
    there. Use a larger window."""
