"""Every registered method honours one contract (in the spirit of scikit-learn's
``check_estimator``): signature ``method(data, order=None, *, option=...)`` with the
registry's options, exact on noise-free data, the same call gives the same model,
bad input raises a ``subid.errors`` exception, bad option values an ``OptionError``,
and ``info`` carries the core keys (:data:`subid.methods._info.CORE_KEYS`).
"""

import inspect
import json
import warnings

import numpy as np
import pytest

import subid
from subid import errors
from subid.experiments.seed002 import simulate as seed002_record
from subid.methods import registry
from subid.methods._info import CORE_KEYS, missing_core_keys

BATCH = [name for name, spec in registry.METHODS.items() if spec.kind == "batch"]
ONLINE = [name for name, spec in registry.METHODS.items() if spec.kind == "online"]

# one bad value per option name: an unknown choice or the wrong type
BAD_OPTION_VALUES = {
    "hold": "cubic", "bd_method": "guess", "stability": "maybe", "selection": "vote",
    "weighting": "unit", "statistic": "svd", "refine": "newton", "instruments": "future",
    "feedthrough": "yes", "estimate_x0": "no", "method": "no_such_method",
}


@pytest.fixture(scope="module")
def dt_record():
    return subid.systems.simulate_data(subid.systems.seed001_system(), 600, seed=3)


@pytest.fixture(scope="module")
def ct_record():
    data, _ = seed002_record(400, 0)          # noise-free, first-order-hold input
    return data


def _record(spec, dt_record, ct_record):
    return dt_record if spec.time == "discrete" else ct_record


def _call(spec, data, order, **options):
    extra = {"hold": "foh"} if spec.name == "dt_to_ct" else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", errors.UnstableModelWarning)
        return spec.load()(data, order, **{**extra, **options})


def _order(spec):
    return 3 if spec.time == "discrete" else 4


# ---------------------------------------------------------------------------
# the registry itself
# ---------------------------------------------------------------------------
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


@pytest.mark.parametrize("name", BATCH)
def test_batch_signature_is_data_order_then_keyword_only_options(name):
    spec = registry.METHODS[name]
    params = list(inspect.signature(spec.load()).parameters.values())
    assert [p.name for p in params[:2]] == ["data", "order"]
    assert params[1].default is None
    rest = params[2:]
    assert all(p.kind in (p.KEYWORD_ONLY, p.VAR_KEYWORD) for p in rest), \
        [p.name for p in rest if p.kind not in (p.KEYWORD_ONLY, p.VAR_KEYWORD)]
    keyword = [p.name for p in rest if p.kind is p.KEYWORD_ONLY]
    assert set(keyword) <= set(spec.options)
    if not any(p.kind is p.VAR_KEYWORD for p in rest):
        assert set(keyword) == set(spec.options)
    # the capabilities that name an option agree with the options
    for capability, option in (("horizon", "horizon"), ("stability", "stability"),
                               ("input_delay", "input_delay"), ("weighting", "weighting"),
                               ("x0", "estimate_x0"), ("hold", "hold"), ("seeded", "seed")):
        if option in keyword:
            assert spec.supports(capability), (capability, option)


@pytest.mark.parametrize("name", ONLINE)
def test_online_options_are_the_constructor_keywords(name):
    spec = registry.METHODS[name]
    params = list(inspect.signature(spec.load()).parameters)
    assert params[:3] == ["order", "n_inputs", "n_outputs"]
    assert set(params[3:]) == set(spec.options)


def test_find_names_what_is_allowed():
    with pytest.raises(errors.OptionError, match="method must be one of 'ls', 'moesp'"):
        registry.find("svd", kind="batch", time="discrete")
    assert registry.find("ls_subspace").name == "ls"
    assert registry.find("ct_subspace").name == "ct"


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


# ---------------------------------------------------------------------------
# the contract of every batch method
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", BATCH)
def test_noise_free_data_give_the_system(name, dt_record, ct_record):
    spec = registry.METHODS[name]
    data = _record(spec, dt_record, ct_record)
    model = _call(spec, data, _order(spec))
    # a polynomial structure's state dimension follows from its degrees (registry capability)
    assert model.order == _order(spec) or spec.supports("polynomial")
    assert model.info["order"] == model.order
    assert (model.dt == 0) == (spec.time == "continuous")
    if spec.time == "discrete":
        assert subid.markov_error(model, subid.systems.seed001_system()) < 1e-8
    # the model is scored with the hold it assumes: exact on noise-free data
    assert subid.fit_percent(model, data).min() > 99.99


@pytest.mark.parametrize("name", BATCH)
def test_same_call_same_model(name, dt_record, ct_record):
    spec = registry.METHODS[name]
    data = _record(spec, dt_record, ct_record)
    a, b = _call(spec, data, None), _call(spec, data, None)
    for x, y in zip((a.A, a.B, a.C, a.D), (b.A, b.B, b.C, b.D)):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("name", BATCH)
def test_core_info_keys(name, dt_record, ct_record):
    spec = registry.METHODS[name]
    data = _record(spec, dt_record, ct_record)
    model = _call(spec, data, _order(spec))
    info = model.info
    assert missing_core_keys(info) == []
    assert list(info)[:len(CORE_KEYS)] == list(CORE_KEYS) or name == "dt_to_ct"
    assert info["order"] == model.order and info["n_samples"] == data.n_samples
    assert info["hold"] == model.hold
    assert isinstance(info["order_selection"], dict) and "rule" in info["order_selection"]
    assert isinstance(info["conditions"], dict)
    assert all(isinstance(v, float) for v in info["conditions"].values())
    assert isinstance(info["warnings"], list)
    if spec.supports("x0"):
        assert np.asarray(info["x0"]).shape == (model.order,)
    if spec.supports("horizon"):
        assert isinstance(info["horizon"], int)
    assert np.asarray(info["rank_profile"]).ndim == 1
    json.dumps(model.to_dict(), allow_nan=False)          # storable


@pytest.mark.parametrize("name", BATCH)
def test_bad_input_raises_subid_errors(name, dt_record, ct_record):
    spec = registry.METHODS[name]
    data = _record(spec, dt_record, ct_record)
    fn = spec.load()
    with pytest.raises(errors.DataError):
        fn(np.ones((50, 2)), 2)
    with pytest.raises(errors.OrderError):
        fn(data, -1)
    with pytest.raises(errors.OrderError):
        fn(data, "three")
    with pytest.raises(errors.OptionError, match="no option .no_such_option."):
        fn(data, 2, no_such_option=1)


@pytest.mark.parametrize("name", BATCH)
def test_bad_option_values_raise_option_error(name, dt_record, ct_record):
    spec = registry.METHODS[name]
    data = _record(spec, dt_record, ct_record)
    checked = 0
    for option, bad in BAD_OPTION_VALUES.items():
        if not spec.accepts(option):
            continue
        with pytest.raises(errors.OptionError, match=option) as exc:
            _call(spec, data, _order(spec), **{option: bad})
        assert repr(bad) in str(exc.value)                  # what was given
        checked += 1
    assert checked >= 2


@pytest.mark.parametrize("name", BATCH)
def test_options_after_order_are_keyword_only(name, dt_record, ct_record):
    """``(data, order)`` then keyword-only options: a third positional argument is an
    OptionError (no release ever took options by position), and so are the
    pre-release names of renamed options (``input_hold``, ``b_method``)."""
    spec = registry.METHODS[name]
    fn = spec.load()
    data = _record(spec, dt_record, ct_record)
    with pytest.raises(subid.errors.OptionError, match="positional"):
        fn(data, 2, None)


def test_pre_release_option_names_are_unknown_options(ct_record):
    for old in ("input_hold", "b_method"):
        with pytest.raises(subid.errors.OptionError, match=f"no option '{old}'"):
            subid.ct_subspace(ct_record, 4, **{old: "zoh"})


# ---------------------------------------------------------------------------
# the other producers of models
# ---------------------------------------------------------------------------
def test_pem_stream_and_distributed_models_have_the_core_keys(dt_record):
    start = subid.n4sid(dt_record, 3)
    assert missing_core_keys(subid.pem(dt_record, start).info) == []
    pieces = [dt_record.split(0.5)[0], dt_record.split(0.5)[1]]
    assert missing_core_keys(subid.identify_stream(pieces, "moesp", 3).info) == []
    from subid.methods.dt import distributed
    models, summary = distributed.identify_many([dt_record], "n4sid", 3)
    assert missing_core_keys(models[0].info) == []


def test_online_models_have_the_core_keys(dt_record, ct_record):
    rs = subid.RecursiveSubspace(3, 2, 2)
    rs.update(dt_record.u, dt_record.y)
    info = rs.model.info
    assert missing_core_keys(info) == [] and info["hold"] == "zoh"
    assert info["n_samples"] == dt_record.n_samples and info["order"] == 3
    ad = subid.AdaptiveIdentifier(4, 1, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", errors.NotConvergedWarning)
        ad.update(ct_record.u, ct_record.y, t=ct_record.t)
        model = ad.model
    assert missing_core_keys(model.info) == []
    assert model.hold == model.info["hold"] == "foh"
    assert set(model.info["conditions"]) == {"ac", "bd"}


def test_warnings_issued_while_identifying_are_in_info(monkeypatch, dt_record, ct_record):
    import importlib

    from subid.methods.dt import _subspace
    ct_module = importlib.import_module("subid.methods.ct.ct_subspace")

    def probe(original):
        def wrapped(*args, **kwargs):
            warnings.warn("probe warning", UserWarning, stacklevel=2)
            return original(*args, **kwargs)
        return wrapped
    monkeypatch.setattr(_subspace, "check_stability", probe(_subspace.check_stability))
    monkeypatch.setattr(ct_module, "_prepare", probe(ct_module._prepare))
    for name in BATCH:
        spec = registry.METHODS[name]
        with pytest.warns(UserWarning, match="probe warning"):    # still issued to the caller
            model = _call(spec, _record(spec, dt_record, ct_record), _order(spec),
                          **({"refine": False} if name == "ct" else {}))
        assert "probe warning" in model.info["warnings"], name
    with pytest.warns(UserWarning, match="probe warning"):
        clean = subid.moesp(dt_record, 3)
    monkeypatch.undo()
    assert "probe warning" in clean.info["warnings"]
    assert subid.moesp(dt_record, 3).info["warnings"] == []


def test_collect_warnings_lists_each_warning_once_and_reissues_it():
    from subid.methods._info import collect_warnings

    with pytest.warns(Warning) as record:
        with collect_warnings() as issued:
            for _ in range(3):
                warnings.warn("same", UserWarning, stacklevel=1)
            warnings.warn("other", RuntimeWarning, stacklevel=1)
    assert issued == ["same", "other"]
    assert [str(w.message) for w in record] == ["same", "other"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(RuntimeWarning, match="raised after the block"):
            with collect_warnings():
                warnings.warn("raised after the block", RuntimeWarning, stacklevel=1)
