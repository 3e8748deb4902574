"""The registry of methods (subid.registry): well-formed entries, their declared check
parameters, lookup by name, and the consumers that read it."""

import pytest

from subid import errors
from subid.methods import registry
from subid.testing import BATCH_CHECKS, ONLINE_CHECKS


@pytest.mark.parametrize("name", list(registry.METHODS))
def test_spec_is_well_formed(name):
    spec = registry.METHODS[name]
    assert spec.name == name and spec.kind in ("batch", "online")
    assert spec.time in ("discrete", "continuous")
    assert spec.capabilities <= registry.CAPABILITIES, spec.capabilities - registry.CAPABILITIES
    assert spec.available()
    assert registry.find(name) is spec
    for alias in spec.aliases:
        assert registry.find(alias) is spec


@pytest.mark.parametrize("name", list(registry.METHODS))
def test_check_parameters_are_declared_consistently(name):
    """What the contract checks call a method with is declared in its entry, and names
    only its own options and existing sub-checks."""
    spec = registry.METHODS[name]
    params = spec.checks
    assert isinstance(params, registry.CheckParameters)
    assert params.record in registry.RECORDS and params.exact in registry.EXACTNESS
    assert isinstance(params.order, int) and params.order >= 1
    assert set(params.call_options) <= set(spec.options)
    assert set(params.unrecorded) <= set(spec.options)
    checks = BATCH_CHECKS if spec.kind == "batch" else ONLINE_CHECKS
    assert set(params.expected) <= set(checks)
    assert all(isinstance(reason, str) and reason for reason in params.expected.values())
    # a continuous-time record for the continuous-time methods, frequency-response data
    # for those that identify from it
    assert (params.record == "discrete") == (spec.time == "discrete")
    assert (params.record == "frequency") == spec.supports("frequency")


def test_check_parameters_refuse_unknown_records_and_claims():
    with pytest.raises(errors.OptionError, match="record must be one of"):
        registry.CheckParameters(record="frequency-domain")
    with pytest.raises(errors.OptionError, match="exact must be one of"):
        registry.CheckParameters(exact="bode")


def test_find_names_what_is_allowed():
    with pytest.raises(errors.OptionError, match="method must be one of 'ls', 'moesp'"):
        registry.find("svd", kind="batch", time="discrete")
    assert registry.find("ls_subspace").name == "ls"
    assert registry.find("ct_subspace").name == "ct"


def test_the_public_registry_is_the_methods_one():
    import subid
    assert subid.registry.METHODS is registry.METHODS
    assert subid.registry.CheckParameters is registry.CheckParameters
    assert set(subid.registry.__all__) == set(registry.__all__)


def test_the_consumers_read_the_registry():
    from subid.cli import commands as cli
    from subid.cli import demo
    from subid.methods.dt import stream
    assert set(cli.METHODS) == {n for n, s in registry.METHODS.items() if s.command_line}
    assert all(cli.METHODS[n] is registry.METHODS[n] for n in cli.METHODS)
    assert not hasattr(cli, "_accepts") and not hasattr(stream, "METHODS")
    assert set(demo._methods()) == set(registry.available_methods("batch")) - \
        set(demo.SLOW_METHODS)
    assert set(demo._methods(registry.available_methods("batch"))) == \
        set(registry.available_methods("batch"))
    assert stream.streaming_method("ls_subspace") is registry.METHODS["ls"]
    with pytest.raises(errors.OptionError, match="method must be one of"):
        stream.statistic_depth("ct", 3, None, 1)
