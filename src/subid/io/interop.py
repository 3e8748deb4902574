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

pandas
------
:func:`iodata_from_pandas` and :func:`iodata_to_pandas` convert between
:class:`~subid.IOData` and a :class:`pandas.DataFrame` (one column per
channel, time in the index or in a column). pandas is optional and imported
only when they are called.
"""

from __future__ import annotations

# The MAT reader and writer live in subid.io.mat, the pandas converters with IOData: the
# methods StateSpace.from_mat/to_mat and IOData.from_pandas/to_pandas use them, and this
# module, above data, io and model, re-exports them.
from subid.data import iodata_from_pandas, iodata_to_pandas
from subid.errors import ModelError
from subid.io.mat import write_mat_model
from subid.model.statespace import StateSpace

__all__ = ["save_mat", "load_mat", "iodata_from_pandas", "iodata_to_pandas"]


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
