"""The public contract checks (subid.testing) catch what they claim to: each deliberately
broken method below fails its sub-check with a message that says what is wrong, and a
method that keeps the contract passes (tests/test_method_contract.py runs them over the
registry)."""

import dataclasses
import re

import numpy as np
import pytest

import subid
from subid import errors
from subid.methods import registry
from subid.testing import (
    BATCH_CHECKS,
    ONLINE_CHECKS,
    ContractError,
    check_batch_method,
    check_online_identifier,
    noise_free_record,
)

MOESP = registry.METHODS["moesp"]
ADAPTIVE = registry.METHODS["adaptive"]


def _like_moesp(attribute, **changes):
    """A MethodSpec of this module's function ``attribute``, registered as moesp is."""
    return dataclasses.replace(MOESP, name=attribute, module=__name__, attribute=attribute,
                               **changes)


def _like_adaptive(attribute, **changes):
    """The same for this module's class ``attribute``, without adaptive's known failures."""
    return dataclasses.replace(ADAPTIVE, name=attribute, module=__name__, attribute=attribute,
                               checks=dataclasses.replace(ADAPTIVE.checks, expected_failures=()),
                               **changes)


def _failures(spec, checks, check=check_batch_method):
    with pytest.raises(ContractError) as info:
        check(spec, checks=checks)
    return info.value


def _rebuild(model, **changes):
    """``model`` with some of its matrices or info changed."""
    mats = {k: getattr(model, k) for k in ("A", "B", "C", "D")}
    info = dict(model.info)
    info.update(changes.pop("info", {}))
    for key in changes.pop("drop", ()):
        del info[key]
    mats.update(changes)
    return subid.StateSpace(mats["A"], mats["B"], mats["C"], mats["D"], model.dt, info=info,
                            hold=model.hold)


# ---------------------------------------------------------------------------
# deliberately broken batch methods (each wraps moesp)
# ---------------------------------------------------------------------------
def positional(data, order=None, horizon=None, **options):
    """Takes its horizon by position."""
    return subid.moesp(data, order, horizon=horizon, **options)


def lenient(data, order=None, **options):
    """Ignores the options it does not know."""
    return subid.moesp(data, order, **{k: v for k, v in options.items()
                                       if k in MOESP.options})


def inexact(data, order=None, **options):
    """Off the true system by a relative 1e-6."""
    model = subid.moesp(data, order, **options)
    return _rebuild(model, A=model.A * (1 + 1e-6))


_CALLS = [0]


def drifting(data, order=None, **options):
    """A different model on every call (a state kept between calls)."""
    _CALLS[0] += 1
    model = subid.moesp(data, order, **options)
    return _rebuild(model, B=model.B + 1e-13 * _CALLS[0])


def forgetful(data, order=None, **options):
    """Drops a core key and the record of its weighting."""
    return _rebuild(subid.moesp(data, order, **options), drop=("horizon", "weighting"))


def nan_state(data, order=None, **options):
    """Returns a NaN initial state."""
    model = subid.moesp(data, order, **options)
    return _rebuild(model, info={"x0": np.full(model.order, np.nan)})


def guessing(data, order=None, **options):
    """Guesses which columns of an array are inputs."""
    if not isinstance(data, subid.IOData):
        data = subid.IOData(data[:, :2], data[:, 2:])
    return subid.moesp(data, order, **options)


def joining(data, order=None, **options):
    """Joins the experiments of a merged record as if they were one."""
    return subid.moesp(subid.IOData(data.u, data.y, dt=data.dt), order, **options)


def unstorable(data, order=None, **options):
    """Puts an object no file can hold into info."""
    return _rebuild(subid.moesp(data, order, **options), info={"callback": object()})


def unit_bound(data, order=None, **options):
    """Fits the outputs in their own units: the first output's samples are shrunk toward
    zero by a fixed amount in its units before the fit (a threshold that does not scale
    with the channel)."""
    y = data.y.copy()
    y[:, 0] = np.sign(y[:, 0]) * np.maximum(np.abs(y[:, 0]) - 0.01, 0.0)
    return subid.moesp(subid.IOData(data.u, y, dt=data.dt), order, **options)


def other_names(data, order=None, *, input_hold="zoh", tol=1e-8):
    """Names two options as other tools do."""
    return subid.moesp(data, order)


@pytest.mark.parametrize("attribute, checks, broken, message", [
    ("positional", ["signature", "keyword_only"], "keyword_only",
     r"\['horizon'\] can be given by position"),
    ("lenient", ["unknown_option"], "unknown_option",
     "no_such_option=1.*expected OptionError, nothing was raised"),
    ("inexact", ["noise_free", "finite"], "noise_free",
     r"relative markov error .* on noise-free data \(the registry claims < 1e-08\)"),
    ("drifting", ["reproducible"], "reproducible", "the same call twice: B differs"),
    ("forgetful", ["info", "signature"], "info", r"lacks the core keys \['horizon'\]"),
    ("forgetful", ["info_defaults"], "info_defaults",
     r"does not record the value in use of the options \['horizon', 'weighting'\]"),
    ("nan_state", ["finite"], "finite", r"info\['x0'\] has non-finite entries"),
    ("guessing", ["bad_data"], "bad_data",
     "the record as one array, not an IOData: expected DataError, nothing was raised"),
    ("joining", ["experiments"], "experiments",
     r"info\['x0'\] has shape \(3,\) on two experiments; expected one row per experiment"),
    ("unstorable", ["save_load"], "save_load", "raised ModelError"),
    ("unit_bound", ["units"], "units",
     "the simulation fit differs by .* points between the record and the same record in "
     "other units"),
])
def test_a_broken_batch_method_fails_its_sub_check(attribute, checks, broken, message):
    failed = _failures(_like_moesp(attribute), checks)
    assert list(failed.failures) == [broken]
    assert f"  {broken}: " in str(failed)
    assert failed.results[broken].startswith("failed: ")
    assert re.search(message, failed.failures[broken]), failed.failures[broken]
    for other in set(checks) - {broken}:
        assert failed.results[other] == "passed"


def test_option_names_of_other_tools_are_refused():
    spec = _like_moesp("other_names", options=("input_hold", "tol"))
    failed = _failures(spec, ["signature", "option_names"])
    assert failed.results["signature"] == "passed"
    assert failed.failures["option_names"] == (
        "other_names: options named as other tools name them: 'input_hold' is 'hold' in "
        "subid, 'tol' is 'tolerance' in subid")


def test_the_registry_options_must_be_the_signature():
    failed = _failures(_like_moesp("other_names"), ["signature"])   # moesp's options
    assert failed.failures["signature"] == (
        "other_names: takes options ['input_hold', 'tol'] that its registry entry does not "
        "list (MethodSpec.options)")
    failed = _failures(_like_moesp("other_names", options=("input_hold", "tol", "horizon")),
                       ["signature"])
    assert failed.failures["signature"] == (
        "other_names: its registry entry lists options ['horizon'] that it does not take")
    # a function with **options takes any of the registry's options
    assert check_batch_method(_like_moesp("lenient"), checks=["signature"]) == \
        {"signature": "passed"}


def test_expected_failures_are_reported_and_must_stay_true():
    declared = registry.CheckParameters(
        unrecorded=registry.METHODS["moesp"].checks.unrecorded,
        expected_failures=(("keyword_only", "horizon is positional"),))
    results = check_batch_method(_like_moesp("positional", checks=declared),
                                 checks=["keyword_only"])
    assert results == {"keyword_only": "expected failure: horizon is positional"}
    # a declared failure that passes fails: the declaration must go
    failed = _failures(dataclasses.replace(MOESP, checks=declared), ["keyword_only"])
    assert "passed, but the registry declares it an expected failure (horizon is " \
           "positional): remove it" in failed.failures["keyword_only"]


def test_a_stale_unrecorded_declaration_fails():
    declared = dataclasses.replace(MOESP.checks, unrecorded=MOESP.checks.unrecorded
                                   + ("weighting",))
    failed = _failures(dataclasses.replace(MOESP, checks=declared), ["info_defaults"])
    assert failed.failures["info_defaults"] == (
        "moesp: info records the options ['weighting'] that the registry declares "
        "unrecorded: remove them from CheckParameters.unrecorded")


def test_all_failures_are_listed_in_one_error():
    failed = _failures(_like_moesp("forgetful"), ["info", "info_defaults", "signature"])
    assert list(failed.failures) == ["info", "info_defaults"]
    text = str(failed)
    assert text.splitlines()[0] == "check_batch_method('forgetful'): 2 sub-checks failed"
    assert failed.results["signature"] == "passed"


def test_arguments_of_the_checks_are_validated():
    with pytest.raises(errors.OptionError, match="unknown sub-check 'exactness'"):
        check_batch_method("moesp", checks=["exactness"])
    with pytest.raises(errors.OptionError, match="method must be one of"):
        check_batch_method("no_such_method")
    with pytest.raises(errors.OptionError, match="method must be one of"):
        check_batch_method("recursive")                 # an online identifier
    with pytest.raises(errors.OptionError, match="use check_online_identifier"):
        check_batch_method(registry.METHODS["adaptive"])
    with pytest.raises(errors.OptionError, match="build a MethodSpec"):
        check_batch_method(positional)                   # not registered
    assert check_batch_method(subid.n4sid, checks=["signature"]) == {"signature": "passed"}
    assert set(BATCH_CHECKS) >= {"signature", "noise_free", "experiments", "default_call"}


def test_noise_free_records():
    data, system = noise_free_record("discrete")
    assert (data.n_samples, data.n_inputs, data.n_outputs, system.order) == (600, 2, 2, 3)
    merged, _ = noise_free_record("continuous", n_experiments=2)
    assert merged.n_experiments == 2 and merged.n_samples == 300 and merged.dt == 0.02
    ct, system = noise_free_record("continuous")
    # the record is the system's foh response from the record's own initial state
    np.testing.assert_allclose(subid.fit_percent(system, ct), 100.0, atol=1e-6)
    frd, system = noise_free_record("frequency")
    assert frd.n_frequencies == 60 and frd.dt == 0.0
    np.testing.assert_array_equal(frd.response, system.freqresp(frd.w))
    with pytest.raises(errors.OptionError, match="1 for frequency-response data"):
        noise_free_record("frequency", n_experiments=2)
    with pytest.raises(errors.OptionError, match="kind must be"):
        noise_free_record("bode")


# ---------------------------------------------------------------------------
# deliberately broken online identifiers (each an AdaptiveIdentifier)
# ---------------------------------------------------------------------------
class Positional(subid.AdaptiveIdentifier):
    """Takes its horizon by position."""

    def __init__(self, order, n_inputs, n_outputs, horizon=None, **options):
        super().__init__(order, n_inputs, n_outputs, horizon=horizon, **options)


class Windowed(subid.AdaptiveIdentifier):
    """Uses only the last 50 samples of each chunk."""

    def update(self, u, y=None, t=None):
        return super().update(u[-50:], y[-50:], None if t is None else t[-50:])


class Amnesic(subid.AdaptiveIdentifier):
    """Loads a checkpoint as a fresh identifier."""

    @classmethod
    def load(cls, path):
        return cls(**super().load(path).get_params())


class Unchecked(subid.AdaptiveIdentifier):
    """Updates the state before validating the chunk."""

    def update(self, u, y=None, t=None):
        if t is not None and np.all(np.isfinite(u)) and len(u) == len(y) and \
                np.any(np.diff(t) <= 0):
            super().update(u[:1], y[:1], t[:1] + 1e3)
        return super().update(u, y, t)


@pytest.mark.parametrize("attribute, checks, broken, message", [
    ("Positional", ["signature", "keyword_only"], "keyword_only",
     r"after \(order, n_inputs, n_outputs\) must be keyword-only; \['horizon'\]"),
    ("Windowed", ["chunk_invariance"], "chunk_invariance",
     "updates of 1, 7 and 60 samples against one update: n_samples"),
    ("Amnesic", ["checkpoint"], "checkpoint", r"Amnesic.load: n_samples, t are 0, None"),
    ("Unchecked", ["rejected_chunk"], "rejected_chunk",
     "time stamps that do not increase changed the state before refusing"),
])
def test_a_broken_online_identifier_fails_its_sub_check(attribute, checks, broken, message):
    failed = _failures(_like_adaptive(attribute), checks, check_online_identifier)
    assert list(failed.failures) == [broken]
    assert re.search(message, failed.failures[broken]), failed.failures[broken]
    assert set(ONLINE_CHECKS) >= set(checks)


def test_an_online_identifier_that_is_not_one():
    spec = _like_adaptive("joining")                       # a function, not a class
    failed = _failures(spec, ["signature"], check_online_identifier)
    assert failed.failures["signature"] == "joining is not a subclass of " \
                                           "subid.OnlineIdentifier"
