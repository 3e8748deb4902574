"""Exchange with MATLAB (``.mat`` files) and pandas.

MATLAB
------
:func:`save_mat` writes the fields of MATLAB's ``ss(A, B, C, D, Ts)`` as
top-level variables of a MAT-file (version 5, readable by MATLAB and GNU
Octave): ``A``, ``B``, ``C``, ``D``, ``Ts`` (0 for continuous time, the
sampling period otherwise), ``InputName`` and ``OutputName`` (cell arrays of
strings). In MATLAB::

    S = load('model.mat');
    sys = ss(S.A, S.B, S.C, S.D, S.Ts, 'InputName', S.InputName, 'OutputName', S.OutputName);

and back, from a MATLAB model ``sys``::

    A = sys.A; B = sys.B; C = sys.C; D = sys.D; Ts = sys.Ts;
    InputName = sys.InputName; OutputName = sys.OutputName;
    save('model.mat', 'A', 'B', 'C', 'D', 'Ts', 'InputName', 'OutputName');

(or ``S = struct('A', sys.A, ...); save('model.mat', '-struct', 'S')``;
a file holding one struct variable with these fields, such as
``save('model.mat', 'S')``, is read too). MATLAB's ``Ts = -1`` (discrete
time, unspecified period) needs the ``dt`` argument of :func:`load_mat`.

Converted models and Python scripts
-----------------------------------
:func:`convert_model` writes a model converted to another time base
(MATLAB's ``c2d``/``d2c``/``d2d``), as MATLAB ``ss`` fields, as a subid model
file, or as a Python script that builds the python-control or scipy.signal
system (:func:`python_source`), with the operating point
(:func:`operating_point`) a detrended model relates deviations from: the
library side of ``subid convert``.

pandas
------
:func:`iodata_from_pandas` and :func:`iodata_to_pandas` convert between
:class:`~subid.IOData` and a :class:`pandas.DataFrame` (one column per
channel, time in the index or in a column). pandas is optional and imported
only when they are called.
"""

from __future__ import annotations

import textwrap

import numpy as np

from subid._validation import check_choice, same_period

# The MAT reader and writer live in subid.io.mat, the pandas converters with IOData: the
# methods StateSpace.from_mat/to_mat and IOData.from_pandas/to_pandas use them, and this
# module, above data, io and model, re-exports them.
from subid.data import iodata_from_pandas, iodata_to_pandas, offset_kind
from subid.errors import DataError, ModelError, OptionError
from subid.io._files import write_bytes
from subid.io.mat import write_mat_model
from subid.model.statespace import StateSpace

__all__ = ["save_mat", "load_mat", "iodata_from_pandas", "iodata_to_pandas", "convert_model",
           "python_source", "operating_point", "CONVERT_TARGETS"]

#: What :func:`convert_model` writes (``'discrete'`` with a sampling period).
CONVERT_TARGETS = ("discrete", "continuous", "mat", "json", "control", "scipy")


# ---------------------------------------------------------------------------
# MATLAB
# ---------------------------------------------------------------------------
def save_mat(model, path) -> None:
    """Write a model as the fields of MATLAB's ``ss(A, B, C, D, Ts)``.

    Parameters
    ----------
    model : StateSpace
    path : str or os.PathLike
        The ``.mat`` file (written atomically: a temporary file renamed over
        ``path``).

    Notes
    -----
    Variables: ``A``, ``B``, ``C``, ``D`` (double matrices), ``Ts`` (0 for
    continuous time), ``InputName``, ``OutputName`` (1-by-m cell arrays of
    char), and ``subid_format`` (the string ``'subid.StateSpace'``, ignored
    by MATLAB), ``subid_hold`` for a model that assumes a first-order hold
    (:attr:`StateSpace.hold`; ignored by MATLAB). A model in innovation form adds ``K`` and ``NoiseVariance``,
    the names of the fields of MATLAB's ``idss`` (build it there with
    ``idss(A, B, C, D, K, zeros(n,1), Ts, 'NoiseVariance', NoiseVariance)``). Values are stored as IEEE doubles, so a round trip is exact.

    Raises
    ------
    ModelError
        ``model`` is not a StateSpace.
    OSError
        The file cannot be written.
    """
    if not isinstance(model, StateSpace):
        raise ModelError(f"save_mat expects a subid.StateSpace, got {type(model).__name__}")
    write_mat_model(model, path)


def load_mat(path, *, dt=None) -> StateSpace:
    """Read a model written by :func:`save_mat` or saved from MATLAB's ``ss`` fields.

    Parameters
    ----------
    path : str or os.PathLike
        MAT-file up to version 7 with the variables ``A``, ``B``, ``C``,
        ``D`` and ``Ts`` (optional: ``InputName``, ``OutputName``, and the
        ``idss`` fields ``K`` and ``NoiseVariance``), or a single
        struct variable with these fields.
    dt : float, optional
        Sampling period to use when ``Ts`` is -1 (MATLAB's "unspecified") or
        missing.

    Returns
    -------
    StateSpace
        ``dt = Ts`` (0: continuous time).

    Raises
    ------
    DataFileNotFoundError
        The file does not exist.
    FileReadError
        The file is not a readable MAT-file (or is a v7.3 HDF5 file).
    ModelError
        A variable is missing or malformed, or ``Ts`` is -1 and ``dt`` is not
        given.
    """
    return StateSpace.from_mat(path, dt=dt)


# ---------------------------------------------------------------------------
# converted models and Python scripts (subid convert)
# ---------------------------------------------------------------------------
_PY_TEMPLATE = '''"""{what} written by subid convert from {source}."""
import numpy as np
{import_line}

A = np.array({A!r})
B = np.array({B!r})
C = np.array({C!r})
D = np.array({D!r})
{build}
'''


def _check_model(model, where: str) -> None:
    """Raise :class:`ModelError` unless ``model`` is a :class:`StateSpace`."""
    from subid.model.statespace import StateSpace
    if not isinstance(model, StateSpace):
        raise ModelError(f"{where}: model must be a subid.StateSpace, got "
                         f"{type(model).__name__}" + (" (load a model file with subid.load)"
                                                      if isinstance(model, str) else ""))


def operating_point(model, estimation=None):
    """The operating point a detrended model relates deviations from.

    Parameters
    ----------
    model : StateSpace
    estimation : IOData, optional
        The estimation record, whose ``u_offset``/``y_offset`` are used when
        ``model.info`` does not record the means.

    Returns
    -------
    tuple of ndarray or None
        ``(u0, y0)``: the channel means removed before identification, from
        ``model.info['data']`` (the command line records them) or the estimation
        record; None when no constant was removed (no detrending, or a linear
        trend, which is no fixed operating point).
    """
    _check_model(model, "operating_point")
    from subid.data import IOData
    if estimation is not None and not isinstance(estimation, IOData):
        raise DataError(f"operating_point: estimation must be the estimation record (a "
                        f"subid.IOData) or None, got {type(estimation).__name__}")
    info = model.info.get("data") if isinstance(model.info, dict) else None
    if isinstance(info, dict) and info.get("u_offset") is not None:
        if info.get("detrend", "constant") != "constant":
            return None
        u0, y0 = info.get("u_offset"), info.get("y_offset")
    elif estimation is not None and getattr(estimation, "u_offset", None) is not None:
        u0, y0 = estimation.u_offset, estimation.y_offset
    else:
        return None
    u0 = np.asarray(u0, dtype=float)
    y0 = np.asarray(y0, dtype=float)
    if u0.ndim != 1 or y0.ndim != 1 or u0.size != model.n_inputs or y0.size != model.n_outputs:
        return None                      # linear trends: (intercept, slope) rows
    return u0, y0


#: What :func:`removed_lines` says of a model identified from linearly detrended data.
LINES_NOTE = ("the model relates deviations from the straight lines removed from every "
              "channel before identification (--detrend linear): those lines are functions "
              "of the identification record's time, recorded in the model file "
              "(info['data']), and are not part of this model; with another record, "
              "detrend it the same way and compare deviations")


def removed_lines(model, estimation=None) -> str | None:
    """:data:`LINES_NOTE` when ``model`` was identified from data whose straight lines
    were removed (``--detrend linear``, recorded in ``model.info['data']``; or the
    estimation record's own ``detrend('linear')``), else None: no operating point to add
    back (:func:`operating_point` is None for them), which every export says."""
    info = model.info.get("data") if isinstance(model.info, dict) else None
    if isinstance(info, dict) and info.get("detrend") == "linear":
        return LINES_NOTE
    if estimation is not None and offset_kind(estimation) == "linear":
        return LINES_NOTE
    return None


def _operating_point_source(model) -> str:
    """Python lines stating the operating point (the means removed by --detrend), or a
    comment saying that linear trends were removed (:func:`removed_lines`)."""
    point = operating_point(model)
    if point is None:
        lines = removed_lines(model)
        return "" if lines is None else \
            "".join(f"# {line}\n" for line in textwrap.wrap(lines[0].upper() + lines[1:] + ".", 86))
    u0, y0 = point
    return ("# The model relates deviations from the operating point, the channel means\n"
            "# removed before identification: in the data's units y = G(u - u0) + y0.\n"
            f"u0 = np.array({u0.tolist()!r})  # {', '.join(model.input_names)}\n"
            f"y0 = np.array({y0.tolist()!r})  # {', '.join(model.output_names)}\n")


def python_source(model, target: str = "control", *, source: str = "a subid model") -> str:
    """A Python script that builds ``model`` as a python-control or scipy.signal system.

    Parameters
    ----------
    model : StateSpace
    target : {'control', 'scipy'}
        ``control.ss(A, B, C, D, dt, inputs=..., outputs=...)`` or
        ``scipy.signal.StateSpace(A, B, C, D[, dt=...])``, assigned to ``sys``.
    source : str
        Where the model came from (the script's docstring names it).

    Returns
    -------
    str
        The script: the matrices as literal arrays (exact: ``repr`` of the
        floats), ``sys``, and ``u0``, ``y0`` when the model relates deviations from
        an operating point (:func:`operating_point`).
    """
    _check_model(model, "python_source")
    check_choice(target, "target", ("control", "scipy"))
    mats = {k: getattr(model, k).tolist() for k in "ABCD"}
    if target == "control":
        dt = model.dt
        build = (f"sys = control.ss(A, B, C, D, {dt!r}, inputs={list(model.input_names)!r}, "
                 f"outputs={list(model.output_names)!r})")
        return _PY_TEMPLATE.format(what="python-control model", source=source,
                                   import_line="import control", build=build, **mats) \
            + _operating_point_source(model)
    build = "sys = signal.StateSpace(A, B, C, D)" if model.dt == 0 else \
        f"sys = signal.StateSpace(A, B, C, D, dt={model.dt!r})"
    return _PY_TEMPLATE.format(what="scipy.signal model", source=source,
                               import_line="from scipy import signal", build=build, **mats) \
        + _operating_point_source(model)


def convert_model(model, path, to: str, *, dt=None, method: str | None = None,
                  source: str = "a subid model") -> str:
    """Write ``model`` converted to another time base or format (``subid convert``).

    Parameters
    ----------
    model : StateSpace
    path : str or os.PathLike
        The file written (atomically).
    to : {'discrete', 'continuous', 'mat', 'json', 'control', 'scipy'}
        ``'discrete'``: a model file of the model sampled with period ``dt`` (a
        continuous model discretised; a discrete one resampled through continuous
        time, or kept when ``dt`` is its own period); ``'continuous'``: a model
        file of the continuous-time model; ``'mat'``: MATLAB ``ss`` fields
        (:func:`save_mat`); ``'json'``: the subid model file; ``'control'``,
        ``'scipy'``: the Python script of :func:`python_source`.
    dt : float, optional
        The sampling period of ``to='discrete'`` (positive, finite).
    method : {None, 'zoh', 'foh', 'bilinear'}
        The discretisation method (MATLAB's ``c2d``/``d2c``); None: the model's
        :attr:`~subid.StateSpace.hold`.
    source : str
        Where the model came from (named by the Python scripts).

    Returns
    -------
    str
        What was written, in a few words (with the operating point of a ``.mat``
        file, which the file does not store).

    Raises
    ------
    OptionError
        ``to``, ``method`` or ``dt`` is not allowed.
    ImportError
        ``to='control'`` without python-control (the message names the extra).
    """
    if not isinstance(model, StateSpace):
        raise ModelError(f"convert_model expects a subid.StateSpace, got {type(model).__name__}")
    check_choice(to, "to", CONVERT_TARGETS)
    method = model.hold if method is None else method
    check_choice(method, "method", ("zoh", "foh", "bilinear"))
    if to == "discrete":
        try:
            period = float(dt)
        except (TypeError, ValueError):
            period = float("nan")
        if isinstance(dt, bool) or not (period > 0 and np.isfinite(period)):
            raise OptionError(f"to='discrete' needs a positive, finite sampling period dt, "
                              f"got {dt!r}")
        dt = period
        if model.dt == 0:
            result = model.to_discrete(dt, method)
        elif same_period(dt, model.dt):
            result = model
        else:
            result = model.to_continuous(method).to_discrete(dt, method)
        result.save(path)
        return f"discrete-time model, dt = {dt:g} ({method})"
    if to == "continuous":
        model.to_continuous(method).save(path)
        return f"continuous-time model ({method})"
    if to == "mat":
        save_mat(model, path)
        what = "MATLAB ss fields A, B, C, D, Ts, InputName, OutputName"
        if (point := operating_point(model)) is not None:
            what += ("; the model is around the operating point u0 = "
                     f"{np.round(point[0], 6).tolist()}, y0 = "
                     f"{np.round(point[1], 6).tolist()} (not stored in the .mat file)")
        elif (lines := removed_lines(model)) is not None:
            what += f"; {lines}"
        return what
    if to == "json":
        model.save(path)
        return "subid model file"
    if to == "control":
        model.to_control()          # ImportError with an install hint if missing
    write_bytes(path, python_source(model, to, source=source), what="script")
    return "python-control script" if to == "control" else "scipy.signal script"
