"""Step and impulse responses of a state-space model (:meth:`StateSpace.step`,
:meth:`StateSpace.impulse`).

Both are computed by the model's own simulation, so that input delays
(``info['input_delay']``) and the exact discretisation of continuous-time
models are honoured:

* step: input ``j`` held at 1 from ``t = 0`` (state zero), every other input
  zero; the output at the time stamps ``t``. In continuous time a constant
  input is exact under the zero-order hold.
* impulse, discrete time: the unit pulse ``u_j[0] = 1`` (the Markov
  parameters ``D, C B, C A B, ...``; MATLAB's ``impulse`` divides these by
  ``dt``, subid does not). Continuous time: ``C exp(A t) B``, the response
  to a Dirac impulse without the Dirac part ``D delta(t)`` of the feedthrough
  (the initial state ``x(0+) = B e_j``, zero input).
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from subid._validation import check_time_stamps
from subid.delay import input_delay_of
from subid.errors import DataError, ResourceLimitError

__all__ = ["response_times", "step_response", "impulse_response"]

# Continuous-time default grid: points between 0 and the final time.
CT_POINTS = 500
# Bounds of the automatic horizon in samples (discrete time).
MIN_SAMPLES, MAX_SAMPLES = 20, 20_000
#: Most samples of a discrete-time response asked for by its final time: beyond, a
#: :class:`~subid.errors.ResourceLimitError` names the memory (``step(1e9)`` with
#: ``dt = 1`` ran into a MemoryError of 93 GiB in ``step_bounds``).
MAX_RESPONSE_SAMPLES = 10_000_000


def _default_final_time(model) -> float:
    """About the 0.1 % settling time of the slowest stable mode (a fixed number of
    samples / time constants for unstable or integrating models).

    Discrete time: at least ``order + 1`` samples (poles at 0, e.g. an FIR model's
    shift register, settle after ``order`` samples, which no pole magnitude tells),
    plus the largest input delay (``info['input_delay']``), after which the response
    only starts."""
    poles = model.poles()
    if model.dt > 0:
        r = float(np.abs(poles).max())
        if r < 1e-12:
            k = MIN_SAMPLES
        elif r < 1.0 - 1e-9:
            k = math.ceil(math.log(1e-3) / math.log(r))
        else:
            k = 100
        k = min(max(k, MIN_SAMPLES, model.order + 1), max(MAX_SAMPLES, model.order + 1))
        delays = input_delay_of(model)
        return (k + (0 if delays is None else int(delays.max()))) * model.dt
    re = poles.real
    speed = float(np.abs(poles).max())
    slow = float(-re.max()) if re.max() < 0 else 0.0
    if slow > 0:
        return min(7.0 / slow, 1e4 * 7.0 / max(speed, slow))
    return 10.0 / speed if speed > 0 else 10.0


def response_times(model, t=None) -> np.ndarray:
    """Time stamps of a step or impulse response.

    Parameters
    ----------
    model : StateSpace
    t : None, float or array_like
        None: automatic final time; a positive number: the final time
        (discrete time: ``t = 0, dt, ..., floor(t/dt) dt``; continuous time:
        500 points from 0); an array: the time stamps themselves, starting at 0
        (discrete time: multiples of ``dt``, uniform).

    Returns
    -------
    ndarray, shape (N,)
    """
    if t is None:
        t = _default_final_time(model)
    if isinstance(t, numbers.Real) and not isinstance(t, bool):
        final = float(t)
        if not (math.isfinite(final) and final > 0):
            raise DataError(f"the final time t must be a positive number, got {t!r}")
        if model.dt > 0:
            samples = final / model.dt * (1 + 1e-12)
            if samples >= MAX_RESPONSE_SAMPLES:
                need = 8.0 * (samples + 1) * model.n_inputs * (model.n_outputs + 1)
                raise ResourceLimitError(
                    f"the final time t = {final:g} is {samples:.4g} samples of dt = "
                    f"{model.dt:g}: the response alone needs {need / 2**30:.3g} GiB (its "
                    f"bounds several times that); at most {MAX_RESPONSE_SAMPLES} samples "
                    "are computed: give a shorter final time (the default is the settling "
                    "time)")
            n = int(math.floor(samples)) + 1
            return np.arange(max(n, 2)) * model.dt
        return np.linspace(0.0, final, CT_POINTS)
    arr = np.asarray(t)
    if arr.ndim != 1 or arr.size < 2:
        raise DataError("time stamps t must be a 1-D array of at least 2 values starting at 0 "
                        "(or a final time)")
    arr = check_time_stamps(arr, arr.size)
    if arr[0] != 0:
        raise DataError(f"time stamps t must start at 0 (the step or impulse is applied at "
                        f"t = 0), got t[0] = {arr[0]!r}")
    if model.dt > 0:
        k = arr / model.dt
        if not np.allclose(k, np.arange(arr.size), rtol=0, atol=1e-9 * arr.size):
            raise DataError(f"time stamps t must be 0, dt, 2 dt, ... for a discrete-time model "
                            f"(dt = {model.dt!r}); pass a final time instead")
    return arr


def step_response(model, t=None):
    """``(t, y)``: step response, ``y[k, i, j]`` output ``i`` for a unit step on input
    ``j`` (see the module docstring)."""
    t = response_times(model, t)
    N, nu = t.size, model.n_inputs
    y = np.empty((N, model.n_outputs, nu))
    for j in range(nu):
        u = np.zeros((N, nu))
        u[:, j] = 1.0
        if model.dt > 0:
            y[:, :, j] = model.simulate(u)
        else:
            y[:, :, j] = model.simulate(u, t, hold="zoh")
    return t, y


def impulse_response(model, t=None):
    """``(t, y)``: impulse response, ``y[k, i, j]`` output ``i`` for an impulse on
    input ``j`` (see the module docstring)."""
    t = response_times(model, t)
    N, nu = t.size, model.n_inputs
    y = np.empty((N, model.n_outputs, nu))
    for j in range(nu):
        u = np.zeros((N, nu))
        if model.dt > 0:
            u[0, j] = 1.0
            y[:, :, j] = model.simulate(u)
        else:
            y[:, :, j] = model.simulate(u, t, x0=model.B[:, j], hold="zoh")
    return t, y
