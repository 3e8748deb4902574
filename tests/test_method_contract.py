"""Every registered method honours one contract, checked by the public checks of
:mod:`subid.testing` (in the spirit of scikit-learn's ``check_estimator``): signature
``method(data, order=None, *, option=...)`` with the registry's options, exact on
noise-free data, the same call gives the same model, bad input raises a ``subid.errors``
exception, bad option values an ``OptionError``, ``info`` carries the core keys
(:data:`subid.methods._info.CORE_KEYS`) and the defaults in use; the online identifiers'
chunk invariance and checkpoints. What each method is called with is declared in its
registry entry (``MethodSpec.checks``), not here.
"""

import warnings

import pytest

import subid
from subid import errors
from subid.methods import registry
from subid.methods._info import missing_core_keys
from subid.testing import check_batch_method, check_online_identifier, noise_free_record

BATCH = [name for name, spec in registry.METHODS.items() if spec.kind == "batch"]
ONLINE = [name for name, spec in registry.METHODS.items() if spec.kind == "online"]


@pytest.fixture(scope="module")
def dt_record():
    return noise_free_record("discrete")[0]


@pytest.fixture(scope="module")
def ct_record():
    return noise_free_record("continuous")[0]


def _call(spec, **options):
    """The registered method on its declared noise-free record, order and options."""
    data, _ = noise_free_record(spec.checks.record)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", errors.UnstableModelWarning)
        return spec.load()(data, spec.checks.order, **{**spec.checks.call_options, **options})


# ---------------------------------------------------------------------------
# the contract of every method (subid.testing)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", BATCH)
def test_batch_method_keeps_the_contract(name):
    results = check_batch_method(name)
    # the declared claims were checked, not skipped
    assert results["noise_free"] == results["info"] == results["reproducible"] == "passed"
    frequency = registry.METHODS[name].supports("frequency")
    assert (results["experiments"] == "passed") != frequency
    assert results["default_call"].startswith("skipped")


@pytest.mark.slow
@pytest.mark.parametrize("name", BATCH)
def test_batch_method_default_call_keeps_the_contract(name):
    """The order chosen from the data: the same call twice gives the same model, and
    ``method(data, order=m.order, horizon=m.info['horizon'])`` reproduces it."""
    results = check_batch_method(name, checks=["default_call"], full=True)
    assert results == {"default_call": "passed"}


@pytest.mark.parametrize("name", ONLINE)
def test_online_identifier_keeps_the_contract(name):
    results = check_online_identifier(name)
    assert results["chunk_invariance"] == results["checkpoint"] == "passed"
    assert results["model"] == results["rejected_chunk"] == "passed"


def test_pre_release_option_names_are_unknown_options(ct_record):
    for old in ("input_hold", "b_method"):
        with pytest.raises(subid.errors.OptionError, match=f"no option '{old}'"):
            subid.ct_subspace(ct_record, 2, **{old: "zoh"})


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
    ad = subid.AdaptiveIdentifier(2, 1, 2)
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
    fd_module = importlib.import_module("subid.methods.fd.fd_subspace")

    def probe(original):
        def wrapped(*args, **kwargs):
            warnings.warn("probe warning", UserWarning, stacklevel=2)
            return original(*args, **kwargs)
        return wrapped
    monkeypatch.setattr(_subspace, "check_stability", probe(_subspace.check_stability))
    monkeypatch.setattr(ct_module, "_estimate_a_c", probe(ct_module._estimate_a_c))
    monkeypatch.setattr(fd_module, "_build", probe(fd_module._build))
    for name in BATCH:
        with pytest.warns(UserWarning, match="probe warning"):    # still issued to the caller
            model = _call(registry.METHODS[name])
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
