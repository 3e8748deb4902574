"""The ``info`` dictionary of every identified model, built by one function.

Every producer of a model (the batch methods, ``dt_to_ct``, ``pem``, the
online identifiers' ``model``, streamed and distributed identification)
builds ``info`` with :func:`model_info`, so that these core keys are always
present (None where a method has no such quantity):

``method``           name of the producer (``'ls_subspace'``, ``'moesp'``, ...)
``order``            model order n
``order_selection``  how n was chosen: a record ``{'rule': 'given'}``,
                     ``{'rule': 'gap', ...}`` or ``{'rule': 'cv', ...}``
                     (:func:`subid.methods.describe.describe_order_selection` prints it)
``horizon``          block rows of the data matrices (number of basis
                     functions for ``ct_subspace``), None when there is none
``n_samples``        samples the model was identified from
``x0``               estimated initial state (None when not estimated)
``hold``             the input between samples the model assumes
                     (``'zoh'``/``'foh'``; also :attr:`StateSpace.hold`)
``conditions``       dict of the condition numbers the method computed, by
                     stage: ``input`` (excitation), ``selector``,
                     ``regression`` (the A/C or B/D least squares), ...
``warnings``         list of the messages of the warnings issued while the
                     model was identified (empty when none)

``rank_profile`` (the singular values, or the SVD-free profile of seed 001,
whose largest gap reveals the order) is present wherever the method computes
one. Method-specific keys follow the core keys.
"""

from __future__ import annotations

import contextlib
import warnings as _warnings

__all__ = ["CORE_KEYS", "model_info", "collect_warnings", "selection_record",
           "missing_core_keys", "continuous_x0", "delayed_x0"]

CORE_KEYS = ("method", "order", "order_selection", "horizon", "n_samples", "x0", "hold",
             "conditions", "warnings")


def selection_record(value) -> dict:
    """An ``order_selection`` record from a record, a rule string or None (given)."""
    if value is None:
        return {"rule": "given"}
    if isinstance(value, dict):
        return value
    text = str(value)
    if text == "given":
        return {"rule": "given"}
    return {"rule": "gap", "description": text}


def model_info(method: str, *, order: int, order_selection=None, horizon=None,
               n_samples=None, x0=None, hold: str = "zoh", conditions=None, warnings=None,
               **extra) -> dict:
    """The ``info`` dict of a model: the core keys, then ``extra``.

    Parameters
    ----------
    method : str
    order : int
    order_selection : dict, str or None
        See :func:`selection_record`.
    horizon, n_samples : int or None
    x0 : ndarray or None
    hold : {'zoh', 'foh'}
    conditions : dict of str to float, optional
        Condition numbers by stage; None values are dropped.
    warnings : list of str, optional
    **extra
        Method-specific keys (a key named like a core key is refused).

    Returns
    -------
    dict
    """
    clash = sorted(set(extra) & set(CORE_KEYS))
    if clash:
        raise TypeError(f"model_info: {clash} are core keys; pass them as such")
    info = {
        "method": method,
        "order": None if order is None else int(order),
        "order_selection": selection_record(order_selection),
        "horizon": None if horizon is None else int(horizon),
        "n_samples": None if n_samples is None else int(n_samples),
        "x0": x0,
        "hold": hold,
        "conditions": {k: float(v) for k, v in (conditions or {}).items() if v is not None},
        "warnings": list(warnings or []),
    }
    info.update(extra)
    return info


def missing_core_keys(info) -> list:
    """The core keys ``info`` lacks (empty for a conforming model)."""
    return [k for k in CORE_KEYS if k not in info]


def _module_of(filename: str):
    """The name of the imported module defined in ``filename`` (for warning filters)."""
    import sys
    for name, module in list(sys.modules.items()):
        if getattr(module, "__file__", None) == filename:
            return name
    return None


@contextlib.contextmanager
def collect_warnings():
    """Record the warnings issued inside, then issue them again unchanged.

    Yields a list that holds, after the block, the messages (str) of the
    warnings issued inside it, for ``info['warnings']``. The warnings are
    re-issued with their category, module, file and line (also when the block
    raises), so callers (``pytest.warns``, ``warnings.simplefilter('error')``,
    module filters) see them as before.
    """
    messages: list = []
    recorder = _warnings.catch_warnings(record=True)
    caught = recorder.__enter__()
    _warnings.simplefilter("always")
    try:
        yield messages
    finally:
        recorder.__exit__(None, None, None)
        # one record per distinct warning (message, category, place), as the default
        # filter shows them, so a warning repeated in a loop is neither listed nor
        # re-issued once per repetition
        seen = set()
        for w in caught:
            key = (str(w.message), w.category, w.filename, w.lineno)
            if key in seen:
                continue
            seen.add(key)
            if str(w.message) not in messages:
                messages.append(str(w.message))
            _warnings.warn_explicit(w.message, w.category, w.filename, w.lineno,
                                    module=_module_of(w.filename), source=w.source)


def records_warnings(fn):
    """Decorator of a model producer: ``info['warnings']`` lists the warnings it issued."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with collect_warnings() as issued:
            model = fn(*args, **kwargs)
        model.info["warnings"] = list(issued)
        return model
    return wrapper


def continuous_x0(info: dict, cmodel, xi0, data) -> dict:
    """``info`` of ``cmodel`` (converted to continuous time by ``to_continuous``) with
    its initial state(s) ``x0`` again: ``to_continuous('foh')`` drops the discrete-time
    model's ``xi0``, whose state is ``x - Gamma2 u`` (:func:`subid.model._simulate.foh_state`),
    and only ``data`` give ``u`` at each experiment's first sample. Unchanged when
    ``cmodel`` assumes a zero-order hold (its ``x0`` is kept) or ``xi0`` is None."""
    if cmodel.hold != "foh" or xi0 is None:
        return info
    import numpy as np

    from subid.model._simulate import foh_state
    xi0 = np.asarray(xi0, dtype=float)
    firsts = data.u[[a for a, _ in data.experiment_ranges]]
    x0 = foh_state(cmodel.A, cmodel.B, data.dt, xi0, firsts if xi0.ndim == 2 else firsts[0])
    out = {}                       # x0 back in its place among the core keys
    for key, value in info.items():
        out[key] = value
        if key == "n_samples":
            out["x0"] = x0
    out["x0"] = x0
    dropped = {k: v for k, v in (out.get("dropped") or {}).items() if k != "x0"}
    if dropped:
        out["dropped"] = dropped
    else:
        out.pop("dropped", None)
    return out


def delayed_x0(model, data, *, prediction: bool):
    """``model`` (input delays recorded, :func:`subid.delay.record_delay`) with
    ``info['x0']`` the initial state at the first sample of ``data``, the record the
    caller gave before :func:`subid.delay.delay_inputs` shifted it.

    A method given ``input_delay=`` fits the shifted record, whose first sample is sample
    ``max(d)`` of ``data``: its ``x0`` was the state there, while every function that
    takes an ``x0`` (simulation, prediction, ``fit_percent``) starts at sample 0 (a user's
    ``fit_percent(m, data, x0=m.info['x0'])`` fitted 85.5 % against 99.6 %). It is
    estimated again on ``data`` as ``x0='estimate'`` does, with the delay line's inputs
    before the record (:func:`subid.model.prediction.simulate_fit`; the one-step
    predictor's, :func:`subid.predict`, for a ``prediction`` fit). Unchanged when the
    model has no ``x0`` (None) or no delays."""
    from subid.delay import input_delay_of
    from subid.model.prediction import predict, simulate_fit
    if model.info.get("x0") is None or input_delay_of(model) is None or model.is_continuous:
        return model
    if prediction and model.K is not None:
        x0 = predict(model, data, 1, "estimate", return_x0=True)[1]
    else:
        x0 = simulate_fit(model, data, "estimate")[1]
    model.info["x0"] = x0
    return model
