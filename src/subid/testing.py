"""Public contract checks of identification methods, for their authors and the project's tests.

:func:`check_batch_method` and :func:`check_online_identifier` check that a method keeps
the contract every subid method keeps, as scikit-learn's
``sklearn.utils.estimator_checks.check_estimator`` and river's ``river.checks`` do for
estimators. Each runs named sub-checks (:data:`BATCH_CHECKS`, :data:`ONLINE_CHECKS`) on
small noise-free records (a few hundred samples of a 2- or 3-state system: seconds, not
minutes), and raises :class:`ContractError`, listing every sub-check that failed with what
was expected and what happened, or returns each sub-check's result.

What a method is called with and what it claims (the test record, the order, options, the
exactness it reaches, known failures) is declared once, in its registry entry
(:class:`subid.registry.CheckParameters`, ``MethodSpec.checks``), never special-cased on a
method's name. A method that is not registered yet is checked from a
:class:`subid.registry.MethodSpec` built for it (see CONTRIBUTING.md, "Adding a method").

Examples
--------
>>> from subid.testing import check_batch_method
>>> results = check_batch_method("moesp", checks=("signature", "unknown_option"))
>>> results
{'signature': 'passed', 'unknown_option': 'passed'}
"""

from __future__ import annotations

import inspect
import json
import os
import re
import tempfile
import warnings

import numpy as np

from subid import errors
from subid.data import IOData, merge
from subid.evaluation.metrics import markov_error
from subid.frdata import FRData
from subid.methods.online.base import OnlineIdentifier
from subid.methods.registry import CORE_KEYS, METHODS, CheckParameters, MethodSpec, find
from subid.model.fit import fit_percent
from subid.model.statespace import StateSpace
from subid.systems import seed001_system, simulate_data

__all__ = ["check_batch_method", "check_online_identifier", "ContractError", "BATCH_CHECKS",
           "ONLINE_CHECKS", "SYNONYMS", "BAD_OPTION_VALUES", "INFO_KEYS", "noise_free_record",
           "scaled_record", "UNITS_TOLERANCE"]

#: The sub-checks of :func:`check_batch_method`, in the order they run.
BATCH_CHECKS = ("signature", "keyword_only", "option_names", "unknown_option",
                "bad_option_values", "bad_data", "noise_free", "finite", "info",
                "info_defaults", "reproducible", "save_load", "experiments", "units",
                "default_call")

#: The sub-checks of :func:`check_online_identifier`, in the order they run.
ONLINE_CHECKS = ("signature", "keyword_only", "option_names", "unknown_option",
                 "bad_option_values", "model_before_data", "rejected_chunk", "model", "exact",
                 "reproducible", "chunk_invariance", "read_only", "checkpoint", "save_load",
                 "units")

#: Spellings that other tools use for a concept subid names once: spelling -> subid's name.
SYNONYMS = {
    "input_hold": "hold", "intersample": "hold", "inter_sample": "hold",
    "b_method": "bd_method", "bd_engine": "bd_method",
    "nx": "order", "n_states": "order",
    "block_rows": "horizon", "i": "horizon", "f": "horizon", "past": "horizon",
    "future": "horizon", "p": "horizon",
    "x0": "estimate_x0", "initial_state": "estimate_x0", "estimate_initial_state":
    "estimate_x0",
    "estimate_d": "feedthrough", "direct_feedthrough": "feedthrough", "d_term": "feedthrough",
    "stable": "stability", "enforce_stability": "stability",
    "random_state": "seed", "rng": "seed",
    "maxiter": "max_iterations", "max_iter": "max_iterations", "n_iterations":
    "max_iterations",
    "tol": "tolerance", "ts": "dt", "sample_time": "dt", "sampling_time": "dt",
    "delay": "input_delay", "input_delays": "input_delay",
    "lambda_": "forgetting", "forgetting_factor": "forgetting",
    "weight": "weighting", "weights": "weighting",
}

#: One bad value per shared option name (an unknown choice or the wrong type): a method
#: that takes the option raises :class:`subid.errors.OptionError` naming the option and
#: the value.
BAD_OPTION_VALUES = {
    "hold": "cubic", "bd_method": "guess", "stability": "maybe", "selection": "vote",
    "weighting": "unit", "statistic": "svd", "refine": "newton", "instruments": "future",
    "feedthrough": "yes", "estimate_x0": "no", "method": "no_such_method",
}

#: The ``info`` key that records an option when it is not the option's own name.
INFO_KEYS = {"selection": "order_selection", "estimate_x0": "x0"}

_CT_SYSTEM = ([[-1.0, 2.0], [-2.0, -1.0]], [[1.0], [0.5]], [[1.0, 0.0], [0.3, 1.0]],
              [[0.0], [0.2]])
_CT_DT = 0.02


class ContractError(AssertionError):
    """Sub-checks of a contract check failed.

    Attributes
    ----------
    failures : dict of str to str
        Sub-check -> what was expected and what happened.
    results : dict of str to str
        Every sub-check that ran -> ``'passed'``, ``'failed: ...'``, ``'skipped: ...'``
        or ``'expected failure: ...'``.
    """

    def __init__(self, label, failures, results):
        self.failures, self.results = dict(failures), dict(results)
        lines = [f"{label}: {len(failures)} sub-check{'s' if len(failures) > 1 else ''} "
                 f"failed"] + [f"  {name}: {text}" for name, text in failures.items()]
        super().__init__("\n".join(lines))


class _Skip(Exception):
    """A sub-check that does not apply to the method (the reason is the message)."""


def noise_free_record(kind: str = "discrete", *, n_experiments: int = 1):
    """The noise-free test record of the checks and the system that made it.

    Parameters
    ----------
    kind : {'discrete', 'continuous', 'frequency'}
        ``'discrete'``: seed 001's system (3 states, 2 inputs, 2 outputs, D != 0), 600
        samples of white Gaussian input, dt = 1. ``'continuous'``: a 2-state, 1-input,
        2-output continuous-time system (D != 0), 300 samples of a Gaussian input held
        first-order, dt = 0.02 s, from a non-zero initial state. ``'frequency'``: that
        system's frequency response at 60 frequencies from 0.03 to 30 rad/s.
    n_experiments : int
        1, or 2 for a record of two experiments (:func:`subid.merge`) of half the
        length each (time records only).

    Returns
    -------
    data : IOData or FRData
    system : StateSpace
        The true system (the continuous-time one with ``hold='foh'``, the hold of its
        record).

    Examples
    --------
    >>> data, system = noise_free_record("continuous")
    >>> data.n_samples, system.order, system.dt
    (300, 2, 0.0)
    """
    if kind not in ("discrete", "continuous", "frequency"):
        raise errors.OptionError(f"kind must be 'discrete', 'continuous' or 'frequency'; got "
                                 f"{kind!r}"[:300])
    if n_experiments not in (1, 2) or (kind == "frequency" and n_experiments != 1):
        raise errors.OptionError(f"n_experiments must be 1 or 2 (1 for frequency-response "
                                 f"data); got {n_experiments!r}"[:300])
    if kind == "discrete":
        system = seed001_system()
        records = [simulate_data(system, 600 // n_experiments, seed=3 + k)
                   for k in range(n_experiments)]
    else:
        system = StateSpace(*_CT_SYSTEM, 0.0, hold="foh")
        if kind == "frequency":
            w = np.logspace(np.log10(0.03), np.log10(30.0), 60)
            return FRData(w, system.freqresp(w)), system
        records = []
        for k in range(n_experiments):
            rng = np.random.default_rng(k)
            warm, n = 200, 300 // n_experiments
            t = np.arange(-warm, n) * _CT_DT
            u = rng.standard_normal((t.size, system.n_inputs))
            y = system.simulate(u, t=t, hold="foh")
            records.append(IOData(u[warm:], y[warm:], dt=_CT_DT))
    return (records[0] if n_experiments == 1 else merge(records)), system


#: Largest difference (fit points, or relative frequency response) the ``units`` check of
#: :func:`check_batch_method` accepts between a record and the same record in other units.
UNITS_TOLERANCE = 1e-6


def scaled_record(data):
    """A record with noise and the same record in other units: the ``units`` checks of
    :func:`check_batch_method` and :func:`check_online_identifier`.

    Parameters
    ----------
    data : IOData or FRData
        A record (:func:`noise_free_record`).

    Returns
    -------
    noisy : IOData or FRData
        ``data`` with seeded noise added (5 % of each output's spread; for
        frequency-response data, 2 % of the mean magnitude).
    scaled : IOData or FRData
        ``noisy`` in other units: each input multiplied by 10^-3, 40, 7, ... and each
        output by 2 x 10^4, 0.05, 3, ... in turn.
    input_factors, output_factors : ndarray
        Those factors.

    Examples
    --------
    >>> data, _ = noise_free_record("discrete")
    >>> noisy, scaled, su, sy = scaled_record(data)
    >>> su.tolist(), sy.tolist()
    ([0.001, 40.0], [20000.0, 0.05])
    """
    rng = np.random.default_rng(0)
    su = np.resize([1e-3, 40.0, 7.0], data.n_inputs)
    sy = np.resize([2e4, 0.05, 3.0], data.n_outputs)
    if isinstance(data, FRData):
        H = data.response
        noisy_h = H + 0.02 * np.abs(H).mean() * (rng.standard_normal(H.shape)
                                                 + 1j * rng.standard_normal(H.shape))
        return (FRData(data.w, noisy_h, data.dt),
                FRData(data.w, noisy_h * sy[None, :, None] / su[None, None, :], data.dt),
                su, sy)
    y = data.y + 0.05 * np.std(data.y, axis=0) * rng.standard_normal(data.y.shape)
    noisy = IOData(data.u, y, dt=data.dt) if data.is_uniform else IOData(data.u, y, t=data.t)
    return noisy, noisy.scaled(inputs=su, outputs=sy), su, sy


def _same_fits(fa, fb, what: str, name: str) -> None:
    """The ``units`` checks' requirement: the ``what`` fits per output of a record and of
    the same record in other units equal to :data:`UNITS_TOLERANCE` points."""
    fa, fb = np.asarray(fa), np.asarray(fb)
    gap = float(np.max(np.abs(fa - fb)))
    _require(gap < UNITS_TOLERANCE,
             f"{name}: the {what} fit differs by {gap:.3g} points between the record and "
             f"the same record in other units ({np.round(fa, 4)} against {np.round(fb, 4)}): "
             "the model depends on the units of the channels")


def _exactness_error(model, system, exact) -> float:
    """The error ``CheckParameters.exact`` bounds: relative Markov or frequency-response error."""
    if exact == "markov":
        return markov_error(model, system)
    w = np.logspace(-1.5, 1.5, 60)
    g = system.freqresp(w)
    return float(np.max(np.abs(model.freqresp(w) - g)) / np.max(np.abs(g)))


# ---------------------------------------------------------------------------
# shared machinery
# ---------------------------------------------------------------------------
def _resolve(method, kind):
    """(spec, the function or class) of a registry name, a MethodSpec, or the object."""
    if isinstance(method, str):
        spec = find(method, kind=kind)
        return spec, spec.load()
    if isinstance(method, MethodSpec):
        if method.kind != kind:
            other = "batch_method" if method.kind == "batch" else "online_identifier"
            raise errors.OptionError(f"{method.name} is a {method.kind} method; use "
                                     f"check_{other}")
        return method, method.load()
    for spec in METHODS.values():                   # a registered function or class
        if spec.kind == kind and spec.available() and spec.load() is method:
            return spec, method
    raise errors.OptionError(
        f"method must be a registry name, a subid.registry.MethodSpec or a registered "
        f"{'function' if kind == 'batch' else 'class'}; got {method!r}: build a MethodSpec "
        f"for a method that is not registered yet"[:600])


class _Runner:
    """Runs the selected sub-checks, collecting results; raises ContractError at the end."""

    def __init__(self, label, names, checks, params: CheckParameters):
        if checks is not None:
            unknown = sorted(set(checks) - set(names))
            if unknown:
                raise errors.OptionError(f"checks: unknown sub-check {unknown[0]!r}; the "
                                         f"sub-checks are {', '.join(names)}")
        self.label, self.names = label, names
        self.selected = set(names if checks is None else checks)
        self.expected = params.expected
        self.results: dict = {}
        self.failures: dict = {}

    def run(self, name, fn):
        if name not in self.selected:
            return
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fn()
        except _Skip as why:
            self.results[name] = f"skipped: {why}"
            return
        except Exception as exc:                     # noqa: BLE001 (any failure is reported)
            text = str(exc) if isinstance(exc, AssertionError) else \
                f"raised {type(exc).__name__}: {exc}"
            if name in self.expected:
                self.results[name] = f"expected failure: {self.expected[name]}"
            else:
                self.results[name] = f"failed: {text}"
                self.failures[name] = text
            return
        if name in self.expected:
            text = (f"passed, but the registry declares it an expected failure "
                    f"({self.expected[name]}): remove it from CheckParameters.expected_failures")
            self.results[name] = f"failed: {text}"
            self.failures[name] = text
        else:
            self.results[name] = "passed"

    def finish(self) -> dict:
        if self.failures:
            raise ContractError(self.label, self.failures, self.results)
        return dict(self.results)


def _require(condition, message):
    if not condition:
        raise AssertionError(message)


def _raises(exc_type, call, what, *, names=()):
    """``call()`` raises ``exc_type`` whose message contains each of ``names``."""
    try:
        call()
    except exc_type as exc:
        text = str(exc)
        missing = [n for n in names if n not in text]
        _require(not missing, f"{what}: the {type(exc).__name__} message does not name "
                              f"{', '.join(missing)}: {text!r}"[:600])
        return
    except Exception as exc:                         # noqa: BLE001
        raise AssertionError(f"{what}: expected {exc_type.__name__}, got "
                             f"{type(exc).__name__}: {exc}"[:600]) from None
    raise AssertionError(f"{what}: expected {exc_type.__name__}, nothing was raised")


def _same_model(a, b, what, *, exact=True):
    """Two models equal bit for bit (or to rounding: rtol 1e-8, atol 1e-9)."""
    for key in ("A", "B", "C", "D", "K", "noise_cov"):
        x, y = getattr(a, key), getattr(b, key)
        _require((x is None) == (y is None), f"{what}: {key} is None in one model only")
        if x is None:
            continue
        _require(np.shape(x) == np.shape(y), f"{what}: {key} has shape {np.shape(x)} and "
                                             f"{np.shape(y)}")
        same = np.array_equal(x, y) if exact else np.allclose(x, y, rtol=1e-8, atol=1e-9)
        if not same:
            diff = float(np.max(np.abs(np.asarray(x) - np.asarray(y))))
            raise AssertionError(f"{what}: {key} differs (largest difference {diff:.3g}"
                                 f"{'' if exact else ', beyond rtol 1e-8'})")
    _require(a.dt == b.dt and a.hold == b.hold, f"{what}: dt or hold differs")


def _check_finite(model, what):
    for key in ("A", "B", "C", "D", "K", "noise_cov"):
        value = getattr(model, key)
        _require(value is None or np.all(np.isfinite(value)),
                 f"{what}: {key} has non-finite entries")
    x0 = model.info.get("x0")
    if x0 is not None:
        _require(np.all(np.isfinite(np.asarray(x0, dtype=float))),
                 f"{what}: info['x0'] has non-finite entries")


def _check_core_info(model, data, spec, what):
    info = model.info
    missing = [k for k in CORE_KEYS if k not in info]
    _require(not missing, f"{what}: info lacks the core keys {missing} (build it with "
                          f"subid.methods._info.model_info)")
    _require(list(info)[:len(CORE_KEYS)] == list(CORE_KEYS),
             f"{what}: info does not start with the core keys in order {list(CORE_KEYS)}")
    _require(isinstance(info["method"], str), f"{what}: info['method'] is not a str")
    _require(info["order"] == model.order,
             f"{what}: info['order'] is {info['order']!r}, the model's order {model.order}")
    samples = getattr(data, "n_samples", None)           # None for frequency-response data
    _require(info["n_samples"] == samples,
             f"{what}: info['n_samples'] is {info['n_samples']!r}; the record has "
             f"{samples} samples")
    _require(info["hold"] == model.hold,
             f"{what}: info['hold'] is {info['hold']!r}, model.hold {model.hold!r}")
    selection = info["order_selection"]
    _require(isinstance(selection, dict) and "rule" in selection,
             f"{what}: info['order_selection'] is not a record with a 'rule'")
    _require(isinstance(info["conditions"], dict)
             and all(isinstance(v, float) for v in info["conditions"].values()),
             f"{what}: info['conditions'] is not a dict of floats")
    _require(isinstance(info["warnings"], list)
             and all(isinstance(v, str) for v in info["warnings"]),
             f"{what}: info['warnings'] is not a list of messages")
    if spec.supports("horizon"):
        _require(isinstance(info["horizon"], int) and not isinstance(info["horizon"], bool),
                 f"{what}: the method takes a horizon; info['horizon'] is "
                 f"{info['horizon']!r}, not an int")
    if "rank_profile" in info:
        _require(np.asarray(info["rank_profile"]).ndim == 1,
                 f"{what}: info['rank_profile'] is not one-dimensional")


def _check_round_trip(model, what):
    text = json.dumps(model.to_dict(), allow_nan=False, sort_keys=True)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "model.json")
        model.save(path)
        back = StateSpace.load(path)
    _same_model(back, model, f"{what}: the model read back from its file")
    _require(tuple(back.input_names) == tuple(model.input_names)
             and tuple(back.output_names) == tuple(model.output_names),
             f"{what}: the channel names changed in the file")
    _require(json.dumps(back.to_dict(), allow_nan=False, sort_keys=True) == text,
             f"{what}: info changed through the file")


def _time_base(model, spec, what):
    _require((model.dt == 0) == (spec.time == "continuous"),
             f"{what}: the registry says the method's models are {spec.time}-time; the "
             f"model has dt = {model.dt}")


def _check_signature(params, leading, spec, what):
    """The leading positional parameters, then options that are the registry's."""
    names = [p.name for p in params]
    _require(names[:len(leading)] == list(leading),
             f"{what}: the first parameters must be {', '.join(leading)}; got "
             f"{', '.join(names[:len(leading)])}")
    rest = params[len(leading):]
    options = [p.name for p in rest if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    extra = sorted(set(options) - set(spec.options))
    _require(not extra, f"{what}: takes options {extra} that its registry entry does not "
                        f"list (MethodSpec.options)")
    if not any(p.kind is p.VAR_KEYWORD for p in rest):
        absent = sorted(set(spec.options) - set(options))
        _require(not absent, f"{what}: its registry entry lists options {absent} that it "
                             f"does not take")
    for capability, option in (("horizon", "horizon"), ("stability", "stability"),
                               ("input_delay", "input_delay"), ("weighting", "weighting"),
                               ("x0", "estimate_x0"), ("hold", "hold"), ("seeded", "seed"),
                               ("feedthrough", "feedthrough")):
        _require(option not in options or spec.supports(capability),
                 f"{what}: takes the option {option!r} but does not declare the capability "
                 f"{capability!r}")


def _check_keyword_only(params, leading, what):
    rest = params[len(leading):]
    positional = [p.name for p in rest if p.kind not in (p.KEYWORD_ONLY, p.VAR_KEYWORD)]
    _require(not positional, f"{what}: options after ({', '.join(leading)}) must be "
                             f"keyword-only; {positional} can be given by position")


def _check_unknown_option(construct, what):
    _raises(errors.OptionError, lambda: construct(no_such_option=1),
            f"{what}(..., no_such_option=1)", names=("no_such_option",))


def _check_bad_option_values(spec, construct, what):
    """Each shared option the method takes, given its bad value (BAD_OPTION_VALUES)."""
    tried = [o for o in BAD_OPTION_VALUES if spec.accepts(o)]
    if not tried:
        raise _Skip("takes none of the shared options of BAD_OPTION_VALUES")
    for option in tried:
        bad = BAD_OPTION_VALUES[option]
        _raises(errors.OptionError, lambda o=option, b=bad: construct(**{o: b}),
                f"{what}(..., {option}={bad!r})", names=(option, repr(bad)))


def _start(method, kind, names, checks):
    """(spec, function or class, its CheckParameters, runner, record, true system)."""
    spec, obj = _resolve(method, kind)
    label = (f"check_{'batch_method' if kind == 'batch' else 'online_identifier'}"
             f"({spec.name!r})")
    data, system = noise_free_record(spec.checks.record)
    return spec, obj, spec.checks, _Runner(label, names, checks, spec.checks), data, system


def _check_option_names(spec, what):
    bad = {o: SYNONYMS[o] for o in spec.options if o in SYNONYMS}
    _require(not bad, f"{what}: options named as other tools name them: " + ", ".join(
        f"{o!r} is {n!r} in subid" for o, n in bad.items()))
    odd = [o for o in spec.options if not re.fullmatch(r"[a-z][a-z0-9_]+", o)]
    _require(not odd, f"{what}: option names {odd} are not spelled-out lower-case words")


# ---------------------------------------------------------------------------
# batch methods
# ---------------------------------------------------------------------------
def check_batch_method(method, *, checks=None, full: bool = False) -> dict:
    """Check that a batch identification method keeps subid's method contract.

    The sub-checks (:data:`BATCH_CHECKS`), on the noise-free record and with the order
    and options of the method's :class:`~subid.registry.CheckParameters`:

    ``signature``          ``method(data, order=None, ...)``, its options those of its
                           registry entry, and a capability for every option that has one
    ``keyword_only``       every option keyword-only; a third positional argument raises
                           :class:`~subid.errors.OptionError`
    ``option_names``       the shared option names (:data:`SYNONYMS`), spelled out
    ``unknown_option``     an unknown option raises OptionError naming it
    ``bad_option_values``  a bad value of a shared option (:data:`BAD_OPTION_VALUES`)
                           raises OptionError naming the option and the value
    ``bad_data``           the record as an array, not an IOData, raises DataError (which
                           columns are inputs is not guessed); a negative or
                           non-integer order OrderError; five samples a subid error
    ``noise_free``         the model has the order and time base asked for, and recovers
                           the true system (``exact``: Markov parameters or frequency
                           response to ``tolerance``); its simulation fits the record
    ``finite``             finite matrices and initial state
    ``info``               ``model.info`` starts with the core keys, which hold what they
                           should (order, samples, hold, condition numbers, warnings)
    ``info_defaults``      every option's value in use is recorded in ``info`` (under its
                           name or :data:`INFO_KEYS`), except the declared ``unrecorded``
                           (which must not be: a stale declaration fails)
    ``reproducible``       the same call twice gives the same model bit for bit, and (if
                           ``reproduces``) so does ``method(data, order=m.order,
                           horizon=m.info['horizon'])``
    ``save_load``          the model survives its JSON file bit for bit, ``info`` included
    ``experiments``        a record of two experiments (:func:`subid.merge`) gives the
                           system, with one initial state per experiment; a method that
                           does not declare ``experiments`` refuses such a record
    ``units``              the record with noise added (seeded) and in other units (each
                           channel multiplied by a factor, 10^-3 to 2 x 10^4) gives the
                           same model in those units: the same order, and the same
                           simulation fit per output (and one-step prediction fit, with a
                           noise model) to :data:`UNITS_TOLERANCE` points; for
                           frequency-response data, the same response to that relative
                           tolerance (:func:`scaled_record`)
    ``default_call``       (``full=True``) ``method(data)``, order chosen: twice the same,
                           and reproduced by ``method(data, order=m.order, horizon=...)``

    Parameters
    ----------
    method : str, MethodSpec or registered function
        A registry name (``'moesp'``), a :class:`~subid.registry.MethodSpec` (a method not
        registered yet: its module and function importable), or a registered function
        (an unregistered callable is an ``OptionError``). The ``keyword_only`` and
        ``unknown_option`` sub-checks expect subid's boundary: an unknown or positional
        option raises :class:`~subid.errors.OptionError`, not Python's ``TypeError``.
    checks : iterable of str, optional
        Run only these sub-checks (default all).
    full : bool
        Also run the costlier sub-checks (``default_call``: the order chosen from the
        data, a few seconds per method).

    Returns
    -------
    dict of str to str
        Each sub-check that ran -> ``'passed'``, ``'skipped: <why>'`` or ``'expected
        failure: <reason>'``.

    Raises
    ------
    ContractError
        One or more sub-checks failed; the message lists each with what was expected and
        what happened.
    OptionError
        ``method`` is not a batch method, or ``checks`` names an unknown sub-check.

    Examples
    --------
    >>> from subid.testing import check_batch_method
    >>> check_batch_method("n4sid", checks=["noise_free"])
    {'noise_free': 'passed'}
    """
    spec, fn, params, run, data, system = _start(method, "batch", BATCH_CHECKS, checks)
    order, options = params.order, params.call_options
    cache = {}

    def call(d=data, n=order, **extra):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fn(d, n, **{**options, **extra})

    def reference():
        if "model" not in cache:
            try:
                cache["model"] = call()
            except Exception as exc:                 # noqa: BLE001
                cache["model"] = AssertionError(
                    f"{spec.name}(data, {order}, **{options}) on the noise-free "
                    f"{params.record} record raised {type(exc).__name__}: {exc}"[:600])
        if isinstance(cache["model"], AssertionError):
            raise cache["model"]
        return cache["model"]

    def signature():
        sig = list(inspect.signature(fn).parameters.values())
        _check_signature(sig, ("data", "order"), spec, spec.name)
        _require(sig[1].default is None, f"{spec.name}: order must default to None "
                                         f"(the order chosen from the data)")
        _require(all(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in sig[:2]),
                 f"{spec.name}: data and order must be positional parameters")

    def keyword_only():
        _check_keyword_only(list(inspect.signature(fn).parameters.values()),
                            ("data", "order"), spec.name)
        _raises(errors.OptionError, lambda: fn(data, order, None, **options),
                f"{spec.name}(data, {order}, None): a third positional argument")

    def option_names():
        _check_option_names(spec, spec.name)

    def unknown_option():
        _check_unknown_option(call, spec.name)

    def bad_option_values():
        _check_bad_option_values(spec, call, spec.name)

    def bad_data():
        frequency = isinstance(data, FRData)
        array = data.response if frequency else np.hstack([data.u, data.y])
        _raises(errors.DataError, lambda: call(array),
                f"{spec.name}(array, {order}): the record as one array, not an "
                f"{type(data).__name__}")
        _raises(errors.OrderError, lambda: call(n=-1), f"{spec.name}(data, -1)")
        _raises(errors.OrderError, lambda: call(n="three"), f"{spec.name}(data, 'three')")
        short, what = (data[:1], "one frequency") if frequency else (data[:5], "five samples")
        _raises(errors.SubidError, lambda: call(short),
                f"{spec.name}(data[:{len(short)}], {order}): {what}")

    def noise_free():
        model = reference()
        _require(model.order == order or spec.supports("polynomial"),
                 f"{spec.name}(data, {order}) gave a model of order {model.order}")
        _require((model.n_inputs, model.n_outputs) == (data.n_inputs, data.n_outputs),
                 f"{spec.name}: the model has {model.n_inputs} inputs and {model.n_outputs} "
                 f"outputs; the record {data.n_inputs} and {data.n_outputs}")
        _time_base(model, spec, spec.name)
        if model.dt:
            _require(model.dt == data.dt, f"{spec.name}: the model's dt {model.dt} is not "
                                          f"the record's {data.dt}")
        if isinstance(data, IOData):
            fit = float(np.min(fit_percent(model, data)))
            _require(fit > 99.99, f"{spec.name}: the model's simulation fits the noise-free "
                                  f"record {fit:.4f} % (expected > 99.99 %)")
        if params.exact is None:
            return
        error = _exactness_error(model, system, params.exact)
        _require(error < params.tolerance,
                 f"{spec.name}: relative {params.exact} error {error:.3g} on noise-free data "
                 f"(the registry claims < {params.tolerance:g})")

    def finite():
        _check_finite(reference(), spec.name)

    def info():
        _check_core_info(reference(), data, spec, spec.name)
        if spec.supports("x0"):
            x0 = reference().info["x0"]
            _require(x0 is not None and np.shape(x0) == (reference().order,),
                     f"{spec.name}: estimates x0 (capability 'x0'); info['x0'] has shape "
                     f"{np.shape(x0)}")

    def info_defaults():
        model_info = reference().info
        absent = [o for o in spec.options if o not in params.unrecorded
                  and INFO_KEYS.get(o, o) not in model_info]
        _require(not absent, f"{spec.name}: info does not record the value in use of the "
                             f"options {absent}: record it (under the option's name), or "
                             f"declare it in CheckParameters.unrecorded")
        stale = [o for o in params.unrecorded if INFO_KEYS.get(o, o) in model_info]
        _require(not stale, f"{spec.name}: info records the options {stale} that the "
                            f"registry declares unrecorded: remove them from "
                            f"CheckParameters.unrecorded")

    def reproducible():
        model = reference()
        _same_model(call(), model, f"{spec.name}: the same call twice")
        if not params.reproduces:
            return
        again = {"horizon": model.info["horizon"]} if spec.accepts("horizon") else {}
        _same_model(call(n=model.order, **again), model,
                    f"{spec.name}(data, order=m.order"
                    f"{', horizon=m.info[horizon]' if again else ''}) against m")

    def save_load():
        _check_round_trip(reference(), spec.name)

    def experiments():
        if params.record == "frequency":
            raise _Skip("frequency-response data have no experiments")
        merged, _ = noise_free_record(params.record, n_experiments=2)
        if not spec.supports("experiments"):
            _raises(errors.SubidError, lambda: call(merged),
                    f"{spec.name} on a record of two experiments, which it does not declare "
                    f"(capability 'experiments')")
            return
        model = call(merged)
        _require(model.info["n_samples"] == merged.n_samples,
                 f"{spec.name}: info['n_samples'] {model.info['n_samples']} on a merged "
                 f"record of {merged.n_samples} samples")
        if spec.supports("x0"):
            _require(np.shape(model.info["x0"]) == (2, model.order),
                     f"{spec.name}: info['x0'] has shape {np.shape(model.info['x0'])} on two "
                     f"experiments; expected one row per experiment {(2, model.order)}")
        if params.exact is not None:
            error = _exactness_error(model, system, params.exact)
            _require(error < params.tolerance,
                     f"{spec.name}: relative {params.exact} error {error:.3g} on two "
                     f"noise-free experiments (claimed < {params.tolerance:g})")

    def units():
        noisy, scaled, su, sy = scaled_record(data)
        a, b = call(noisy), call(scaled)
        _require(a.order == b.order, f"{spec.name}: order {a.order} on the noisy record, "
                                     f"{b.order} on the same record in other units")
        if isinstance(data, FRData):
            Ha = a.freqresp(data.w)
            Hb = b.freqresp(data.w) / sy[None, :, None] * su[None, None, :]
            error = float(np.abs(Ha - Hb).max() / max(np.abs(Ha).max(), 1e-300))
            _require(error < UNITS_TOLERANCE, f"{spec.name}: the model of the response in "
                                              f"other units differs by {error:.3g} (relative)")
            return
        steps = (np.inf, 1) if a.K is not None and b.K is not None else (np.inf,)
        for k in steps:
            _same_fits(fit_percent(a, noisy, steps=k), fit_percent(b, scaled, steps=k),
                       "simulation" if k == np.inf else "one-step prediction", spec.name)

    def default_call():
        if not full:
            raise _Skip("costly: run with full=True")
        if not spec.supports("order_selection"):
            raise _Skip("does not choose the order (no capability 'order_selection')")
        model = call(n=None)
        _require(model.info["order_selection"].get("rule") != "given",
                 f"{spec.name}(data): info['order_selection'] says the order was given")
        _same_model(call(n=None), model, f"{spec.name}(data) twice")
        if params.reproduces:
            again = {"horizon": model.info["horizon"]} if spec.accepts("horizon") else {}
            _same_model(call(n=model.order, **again), model,
                        f"{spec.name}(data, order=m.order"
                        f"{', horizon=m.info[horizon]' if again else ''}) against m = "
                        f"{spec.name}(data)")

    for name in BATCH_CHECKS:
        run.run(name, locals()[name])
    return run.finish()


# ---------------------------------------------------------------------------
# online identifiers
# ---------------------------------------------------------------------------
def check_online_identifier(cls, *, checks=None) -> dict:
    """Check that an online identifier keeps subid's online contract.

    The sub-checks (:data:`ONLINE_CHECKS`), on the noise-free record with the order and
    options of the identifier's :class:`~subid.registry.CheckParameters`:

    ``signature``          a :class:`subid.OnlineIdentifier`, constructed as
                           ``Cls(order, n_inputs, n_outputs, ...)`` with its registry
                           options
    ``keyword_only``       every option after ``(order, n_inputs, n_outputs)``
                           keyword-only
    ``option_names``       the shared option names (:data:`SYNONYMS`), spelled out
    ``unknown_option``     an unknown option raises OptionError naming it
    ``bad_option_values``  a bad value of a shared option raises OptionError naming it
    ``model_before_data``  ``model`` raises :class:`~subid.errors.TooFewSamplesError`
                           before any data
    ``rejected_chunk``     a chunk with a NaN, a sample of 1e200 (its square overflows),
                           unequal lengths or the wrong channels raises
                           DataError and leaves the state unchanged (the checkpoint file
                           is the same bytes)
    ``model``              after the record: finite, of the order and time base, its core
                           ``info`` keys right
    ``exact``              the true system recovered as the registry claims
    ``reproducible``       two identifiers with the same settings (one built from the
                           other's ``get_params()``) end bit for bit alike
    ``chunk_invariance``   the record in one update, and in updates of 1, 7 and 60
                           samples, end alike (bit for bit if ``chunks_exact``, else to
                           rounding)
    ``read_only``          reading ``model`` and ``state`` mid-record leaves what follows
                           unchanged, bit for bit
    ``checkpoint``         ``save`` then ``load`` (also through
                           ``OnlineIdentifier.load``) resumes exactly: the loaded and the
                           original identifiers continue bit for bit alike
    ``save_load``          the model survives its JSON file bit for bit
    ``units``              the noisy record in other units (:func:`scaled_record`): the
                           same simulation fit per output to :data:`UNITS_TOLERANCE` points

    Parameters
    ----------
    cls : str, MethodSpec or type
        A registry name (``'recursive'``), a :class:`~subid.registry.MethodSpec` of kind
        ``'online'``, or a registered class.
    checks : iterable of str, optional
        Run only these sub-checks (default all).

    Returns
    -------
    dict of str to str
        Each sub-check that ran -> ``'passed'``, ``'skipped: <why>'`` or ``'expected
        failure: <reason>'``.

    Raises
    ------
    ContractError
        One or more sub-checks failed; the message lists each.
    OptionError
        ``cls`` is not an online identifier, or ``checks`` names an unknown sub-check.

    Examples
    --------
    >>> from subid.testing import check_online_identifier
    >>> check_online_identifier("recursive", checks=["chunk_invariance"])
    {'chunk_invariance': 'passed'}
    """
    spec, klass, params, run, data, system = _start(cls, "online", ONLINE_CHECKS, checks)
    shape = (params.order, data.n_inputs, data.n_outputs)
    options = params.call_options
    name = klass.__name__

    def make(**extra):
        return klass(*shape, **{**options, **extra})

    def feed(ident, stop=None, sizes=(), start=0):
        """Update with samples ``start:stop`` of the record: chunks of ``sizes`` (pairs
        ``(chunk, samples)``, in turn), then the rest in one chunk; as arrays with the
        whole record's time stamps (a slice of an IOData recomputes its stamps from its
        own start, which differ from the record's in the last bit)."""
        stop = data.n_samples if stop is None else stop
        u, y, t = data.u, data.y, data.t
        for chunk, samples in sizes:
            for k in range(start, start + samples, chunk):
                end = min(k + chunk, start + samples)
                ident.update(u[k:end], y[k:end], t[k:end])
            start += samples
        if start < stop:
            ident.update(u[start:stop], y[start:stop], t[start:stop])
        return ident

    def quiet_model(ident):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return ident.model

    def same(a, b, what, exact=True):
        _require(a.n_samples == b.n_samples, f"{what}: n_samples {a.n_samples} and "
                                             f"{b.n_samples}")
        _same_model(quiet_model(a), quiet_model(b), what, exact=exact)
        sa, sb = np.asarray(a.state), np.asarray(b.state)
        _require(sa.shape == sb.shape and (np.array_equal(sa, sb) if exact else
                                           np.allclose(sa, sb, rtol=1e-8, atol=1e-9)),
                 f"{what}: the states differ")

    def signature():
        _require(isinstance(klass, type) and issubclass(klass, OnlineIdentifier),
                 f"{name} is not a subclass of subid.OnlineIdentifier")
        sig = list(inspect.signature(klass).parameters.values())
        _check_signature(sig, ("order", "n_inputs", "n_outputs"), spec, name)

    def keyword_only():
        _check_keyword_only(list(inspect.signature(klass).parameters.values()),
                            ("order", "n_inputs", "n_outputs"), name)

    def option_names():
        _check_option_names(spec, name)

    def unknown_option():
        _check_unknown_option(make, name)

    def bad_option_values():
        _check_bad_option_values(spec, make, name)

    def model_before_data():
        _raises(errors.TooFewSamplesError, lambda: make().model,
                f"{name}(...).model before any update")

    def rejected_chunk():
        ident = feed(make(), 200)
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "state.npz")
            ident.save(path)
            with open(path, "rb") as fh:
                before = fh.read()
            u, y, t = data.u[200:260], data.y[200:260], data.t[200:260]
            bad_u = u.copy()
            bad_u[17, 0] = np.nan
            huge_y = y.copy()
            huge_y[5, 0] = 1e200              # its square overflows (a missing-value marker)
            for what, args in (("a NaN input", (bad_u, y, t)),
                               ("an output sample of 1e200", (u, huge_y, t)),
                               ("unequal lengths", (u, y[:-1], t)),
                               ("one input channel too many",
                                (np.hstack([u, u[:, :1]]), y, t)),
                               ("time stamps that do not increase", (u, y, t[::-1]))):
                _raises(errors.DataError, lambda a=args: ident.update(*a),
                        f"{name}.update with {what}")
                ident.save(path)
                with open(path, "rb") as fh:
                    _require(fh.read() == before,
                             f"{name}.update with {what} changed the state before refusing")

    def model():
        ident = feed(make())
        fitted = quiet_model(ident)
        _require(isinstance(fitted, StateSpace), f"{name}.model is not a StateSpace")
        _require((fitted.order, fitted.n_inputs, fitted.n_outputs) == shape,
                 f"{name}.model has (order, inputs, outputs) "
                 f"{(fitted.order, fitted.n_inputs, fitted.n_outputs)}; expected {shape}")
        _require(ident.n_samples == data.n_samples,
                 f"{name}.n_samples is {ident.n_samples} after {data.n_samples} samples")
        _time_base(fitted, spec, f"{name}.model")
        _check_finite(fitted, f"{name}.model")
        _check_core_info(fitted, data, spec, f"{name}.model")

    def units():
        noisy, scaled, _, _ = scaled_record(data)
        fits = []
        for record in (noisy, scaled):
            ident = make()
            ident.update(record.u, record.y, record.t)
            fits.append(fit_percent(quiet_model(ident), record))
        _same_fits(*fits, "simulation", name)

    def exact():
        if params.exact is None:
            raise _Skip("the registry claims no exactness (CheckParameters.exact is None)")
        error = _exactness_error(quiet_model(feed(make())), system, params.exact)
        _require(error < params.tolerance,
                 f"{name}: relative {params.exact} error {error:.3g} on noise-free data "
                 f"(the registry claims < {params.tolerance:g})")

    def reproducible():
        first = make()
        twin = klass(**first.get_params())
        same(feed(make()), feed(first), f"{name}: two identifiers on the same record")
        same(feed(twin), feed(make()),
             f"{name}(**ident.get_params()) against ident on the same record")

    def chunk_invariance():
        chunked = feed(make(), sizes=((1, 20), (7, 140), (60, 120)))
        same(chunked, feed(make()), f"{name}: updates of 1, 7 and 60 samples against one "
             f"update", exact=params.chunks_exact)

    def read_only():
        half = data.n_samples // 2
        read = feed(make(), half)
        quiet_model(read)
        _ = read.state
        same(feed(read, start=half), feed(make()),
             f"{name}: reading model and state at sample {half}, then continuing, against "
             f"not reading them")

    def checkpoint():
        half = data.n_samples // 2
        first = feed(make(), half)
        with tempfile.TemporaryDirectory() as folder:
            path, again = os.path.join(folder, "state.npz"), os.path.join(folder, "again.npz")
            first.save(path)
            loaded = klass.load(path)
            generic = OnlineIdentifier.load(path)
            _require(type(loaded) is klass and type(generic) is klass,
                     f"{name}.load / OnlineIdentifier.load returned "
                     f"{type(loaded).__name__} / {type(generic).__name__}")
            for ident, how in ((loaded, f"{name}.load"), (generic, "OnlineIdentifier.load")):
                _require(ident.n_samples == first.n_samples and ident.t == first.t,
                         f"{how}: n_samples, t are {ident.n_samples}, {ident.t}; saved "
                         f"{first.n_samples}, {first.t}")
                _require(sorted(ident.get_params()) == sorted(first.get_params()),
                         f"{how}: the settings differ from the saved identifier's")
                ident.save(again)                # the whole state: the same bytes
                with open(path, "rb") as fh, open(again, "rb") as gh:
                    _require(fh.read() == gh.read(),
                             f"{how}: saved again, the checkpoint is not the same bytes")
        for ident in (first, loaded, generic):
            feed(ident, start=half)
        same(loaded, first, f"{name}: resumed from its checkpoint against the original")
        same(generic, first, f"{name}: resumed through OnlineIdentifier.load")

    def save_load():
        _check_round_trip(quiet_model(feed(make())), f"{name}.model")

    for check in ONLINE_CHECKS:
        run.run(check, locals()[check])
    return run.finish()
