"""Reliability, round three (issue 28): one property test per class of failure.

Each class was fixed at its root; these tests draw their cases instead of
listing them:

1. everything derived from a model honours its input delays
   (:func:`subid.delay.effective_input`);
2. memory bounded or refused before allocating (:func:`subid.absorb_delay`);
3. reads detect a file truncated while it is read (``io._files.open_regular``);
4. every bad option value is a ``subid.errors`` exception (seeds, confidence
   levels, tolerances, magnitudes);
5. consistent results (``OnlineIdentifier.load``, experiments too short for their
   initial state, one output-path policy, no empty folder after a failed write);
6. messages that cap what they echo and name the actual cause (time-stamp
   rounding, offsets, the Kalman predictor, Dask rows).
"""

from __future__ import annotations

import os
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import subid
from subid import errors
from subid.delay import record_delay

FAST = settings(max_examples=6, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def _delayed_innovation_model(seed, delays):
    true = subid.systems.random_system(3, len(delays), 2, seed=seed)
    K = 0.2 * np.random.default_rng(seed).standard_normal((3, 2))
    while np.abs(np.linalg.eigvals(true.A - K @ true.C)).max() >= 0.95:
        K *= 0.5
    model = true.with_noise_model(K, np.eye(2), info={})
    return record_delay(model, delays)


# -- 1. silent garbage: delays --------------------------------------------------------

@FAST
@given(seed=st.integers(0, 10_000), delays=st.lists(st.integers(0, 4), min_size=1, max_size=2),
       steps=st.sampled_from([1, 3, np.inf]))
def test_everything_derived_from_a_delayed_model_honours_its_delays(seed, delays, steps):
    model = _delayed_innovation_model(seed, delays)
    u = np.random.default_rng(seed + 1).standard_normal((300, len(delays)))
    data = subid.IOData(u, model.simulate(u), dt=1.0)           # exact, noise-free
    assert np.all(subid.fit_percent(model, data, steps=steps) > 99.999)
    res = subid.residuals(model, data)
    assert np.abs(res["residual"]).max() < 1e-8 * np.abs(data.y).max()


def test_pem_refines_a_delayed_model_with_its_delays():
    model = _delayed_innovation_model(3, [2, 0])
    rng = np.random.default_rng(4)
    u = rng.standard_normal((1500, 2))
    y = model.simulate(u) + 0.05 * rng.standard_normal((1500, 2))
    data = subid.IOData(u, y, dt=1.0)
    start = model.with_noise_model(model.K, model.noise_cov, info=dict(model.info))
    start = start.transform(np.eye(3))
    refined = subid.pem(data, start)
    assert refined.info["input_delay"] == [2, 0]
    assert refined.info["final_cost"] <= refined.info["start_cost"]
    assert subid.fit_percent(refined, data).min() > 95


# -- 2. memory -----------------------------------------------------------------------

@pytest.mark.parametrize("delay", [20_000, 100_000])
def test_absorbing_a_huge_delay_is_refused_before_allocating(delay):
    model = record_delay(subid.systems.seed001_system(), [delay, 0])
    tracemalloc.start()
    try:
        with pytest.raises(errors.ResourceLimitError, match="GiB"):
            subid.absorb_delay(model)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20
    assert subid.absorb_delay(record_delay(subid.systems.seed001_system(), [3, 1])).order == 7


# -- 3. data loss: truncation --------------------------------------------------------

@FAST
@given(keep=st.floats(0.0, 0.95), first=st.integers(1, 4000))
def test_a_file_truncated_while_read_is_an_error(tmp_path, keep, first):
    from subid.io._files import open_regular
    path = tmp_path / "x.bin"
    path.write_bytes(bytes(range(256)) * 40)
    fh, size = open_regular(path)
    with fh:
        head = fh.read(min(first, size))
        os.truncate(path, int(keep * size))
        with pytest.raises(errors.FileReadError, match="truncated while it was read"):
            while fh.read(1000):
                pass
    assert head


def test_read_chunks_of_a_truncated_file_is_an_error(tmp_path):
    path = tmp_path / "x.csv"
    rng = np.random.default_rng(0)
    np.savetxt(path, rng.standard_normal((80_000, 2)), delimiter=",", header="u1,y1",
               comments="")
    pieces = subid.read_chunks(path, inputs=["u1"], outputs=["y1"], dt=1.0, chunk_size=2000)
    seen = 0
    with pytest.raises(errors.FileReadError, match="truncated"):
        for k, piece in enumerate(pieces):
            seen += piece.n_samples
            if k == 0:
                os.truncate(path, os.path.getsize(path) // 5)
    assert seen < 80_000


# -- 4. only subid errors ------------------------------------------------------------

BAD_SEEDS = st.one_of(st.text(max_size=5), st.integers(max_value=-1), st.floats(),
                      st.booleans(), st.none(), st.lists(st.integers(0, 3), max_size=2))


@FAST
@given(seed=BAD_SEEDS)
def test_every_seed_option_rejects_bad_seeds_with_an_option_error(seed):
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 300, seed=1)
    calls = [lambda: subid.ls_subspace(data, 3, horizon=5, seed=seed),
             lambda: subid.RecursiveSubspace(3, 2, 2, seed=seed, dt=1.0),
             lambda: subid.AdaptiveIdentifier(2, 1, 1, seed=seed, dt=0.01),
             lambda: subid.systems.random_system(2, 1, 1, seed=seed),
             lambda: subid.systems.simulate_data(subid.systems.seed001_system(), 10,
                                                 seed=seed)]
    for call in calls:
        with pytest.raises(errors.OptionError, match="seed"):
            call()


@FAST
@given(level=st.one_of(st.text(max_size=4), st.floats().filter(lambda v: not 0 < v < 1),
                       st.booleans(), st.none()))
def test_confidence_levels_are_validated(level):
    true = subid.systems.seed001_innovation_system()
    data = subid.systems.simulate_innovation_data(true, 300, seed=2)
    with pytest.raises(errors.OptionError, match="confidence"):
        subid.residuals(true, data, confidence=level)


def test_pem_tolerance_and_magnitudes_are_subid_errors():
    true = subid.systems.seed001_innovation_system()
    data = subid.systems.simulate_innovation_data(true, 400, seed=2)
    for tolerance in (1e-300, 0.0, 1.0, "1e-8", True):
        with pytest.raises(errors.OptionError, match="tolerance"):
            subid.pem(data, true, tolerance=tolerance)
    huge = subid.IOData(data.u, data.y * 1e299, dt=1.0)
    with pytest.raises(errors.DataError, match="overflow"):
        subid.pem(huge, true)
    # the same check for every prediction-error search (frequency data, polynomial models)
    w = np.linspace(0.1, 3.0, 40)
    frd = subid.FRData(w, true.freqresp(w), 1.0)
    with pytest.raises(errors.OptionError, match="tolerance"):
        subid.pem(frd, true, tolerance=1e-300)
    with pytest.raises(errors.OptionError, match="tolerance"):
        subid.oe(data, (2, 2, 1), tolerance=1e-300)


# -- 5. consistent results -----------------------------------------------------------

def test_online_identifier_load_restores_the_class_the_checkpoint_names(tmp_path):
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=1)
    for ident in (subid.RecursiveSubspace(3, 2, 2, dt=1.0),
                  subid.AdaptiveIdentifier(3, 2, 2, dt=1.0)):
        ident.update(data)
        path = tmp_path / f"{type(ident).__name__}.npz"
        ident.save(path)
        back = subid.OnlineIdentifier.load(path)
        assert type(back) is type(ident) and back.n_samples == ident.n_samples
    (tmp_path / "other.npz").write_bytes(b"not a checkpoint")
    with pytest.raises(errors.CheckpointError):
        subid.OnlineIdentifier.load(tmp_path / "other.npz")


@pytest.mark.parametrize("method", ["moesp", "ls_subspace", "n4sid"])
def test_an_experiment_too_short_for_its_initial_state_is_named(method):
    true = subid.systems.random_system(4, 1, 1, seed=3)
    a = subid.systems.simulate_data(true, 400, seed=1)
    b = subid.systems.simulate_data(true, 400, seed=2)
    merged = subid.merge([a, b[:2], b[2:]])
    with pytest.raises(errors.TooFewSamplesError, match="'exp2' \\(2 samples\\)"):
        getattr(subid, method)(merged, 4)
    model = getattr(subid, method)(merged, 4, estimate_x0=False)
    assert model.info["x0"] is None


def test_one_output_path_policy_no_writes_through_links(tmp_path):
    from subid.io._files import atomic_directory
    model = subid.systems.seed001_system()
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "model.json").write_text("keep")
    for name, target in (("file.json", outside / "model.json"), ("folder", outside)):
        link = tmp_path / name
        os.symlink(target, link)
        with pytest.raises(errors.FileWriteError, match="symbolic link"):
            if name == "folder":
                with atomic_directory(link) as stage:
                    model.save(os.path.join(stage, "model.json"))
            else:
                model.save(link)
    assert (outside / "model.json").read_text() == "keep"


def test_a_failed_checkpoint_leaves_no_empty_folder(tmp_path, monkeypatch):
    from subid.methods.online.base import Tracker
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 300, seed=1)
    ident = subid.RecursiveSubspace(3, 2, 2, dt=1.0)
    folder = tmp_path / "run" / "checkpoints"
    tracker = Tracker(ident, data, checkpoint_every=100, checkpoint_dir=str(folder))

    def full_disk(path):
        raise errors.FileWriteError("No space left on device", path=str(path))
    monkeypatch.setattr(ident, "save", full_disk)
    with pytest.raises(errors.FileWriteError):
        tracker.checkpoint(0)
    assert not folder.exists() and not folder.parent.exists()


# -- 6. messages ---------------------------------------------------------------------

@FAST
@given(length=st.integers(0, 3_000_000))
def test_error_messages_cap_what_they_echo(length):
    message = "cell " + "x" * length + " is not a number"
    text = str(errors.DataError(message))
    assert len(text) <= errors.MAX_MESSAGE_CHARS + 80
    assert text.startswith("cell ") and text.endswith("is not a number")


@FAST
@given(start=st.sampled_from([0.0, 1.7e9, 1.7e9 + 0.5, 3.1e7, 1e5]),
       rate=st.sampled_from([1.0, 100.0, 1000.0, 8000.0]))
def test_time_stamps_are_uniform_up_to_their_own_rounding(tmp_path, start, rate):
    n = 2000
    text = "\n".join(f"{start + k / rate:.6f},{np.sin(k)},{np.cos(k)}" for k in range(n))
    path = tmp_path / "t.csv"
    path.write_text("t,u1,y1\n" + text + "\n")
    data = subid.read(path, inputs=["u1"], outputs=["y1"], time="t")
    assert data.is_uniform
    assert abs(data.dt - 1 / rate) < 1e-6 / rate + 4 * np.spacing(start + n / rate)


def test_an_input_lost_against_its_offset_is_named():
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 600, seed=1)
    u = data.u.copy()
    u[:, 1] += 1e12
    for method in (subid.moesp, subid.n4sid, subid.ls_subspace):
        with pytest.raises(errors.NotExcitingError, match="u2 varies by .* offset of 1e\\+12"):
            method(subid.IOData(u, data.y, dt=1.0), 3)


def test_a_diverging_prediction_names_the_kalman_predictor():
    true = subid.systems.seed001_system()
    K = np.full((3, 2), 5.0)                       # A stable, A - K C not
    model = true.with_noise_model(K, np.eye(2))
    data = subid.systems.simulate_data(true, 3000, seed=1)
    with pytest.raises(errors.DataError, match="Kalman predictor A - K C is unstable .* "
                                               "A itself is stable"):
        subid.predict(model, data, steps=1)


def test_dask_names_rows_of_the_record_and_unknown_chunks():
    da = pytest.importorskip("dask.array")
    from subid.methods.dt import distributed
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 5000, seed=1)
    y = data.y.copy()
    y[2500, 1] = np.nan
    with pytest.raises(errors.DataError, match="row 2500 of the record"):
        distributed.identify(da.from_array(data.u, chunks=(1000, 2)),
                             da.from_array(y, chunks=(1000, 2)), order=3, horizon=5)
    u = da.from_array(data.u, chunks=(1000, 2))
    u = u[u[:, 0] > -100]
    with pytest.raises(errors.DataError, match="chunk sizes of u along time are unknown"):
        distributed.identify(u, da.from_array(data.y, chunks=(1000, 2)), order=3, horizon=5)


def test_every_public_callable_refuses_an_unknown_option_with_an_option_error():
    """An unknown keyword (a typo of an option) is an OptionError naming the options,
    with the closest one suggested, for every public function and class of subid
    (``_validation.checked_call``), not Python's TypeError."""
    import inspect
    import types
    varkw = {"identify_file", "identify_stream", "dt_to_ct", "OnlineIdentifier"}
    checked = 0
    for name in subid.__all__:
        obj = getattr(subid, name)
        if isinstance(obj, types.ModuleType) or name in varkw or (
                inspect.isclass(obj) and issubclass(obj, BaseException)) or not callable(obj):
            continue
        with pytest.raises(errors.OptionError, match="has no option 'horizn'"):
            obj(horizn=3)
        checked += 1
    assert checked >= 40
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 300, seed=1)
    with pytest.raises(errors.OptionError, match="did you mean 'horizon'"):
        subid.moesp(data, 3, horizn=5)


def test_every_error_class_survives_pickling_and_a_dask_cluster():
    """Every subid.errors exception comes back from pickle, and from dask.distributed's
    unpickler (tblib), as its own class with its message and attributes: the two that
    are also OSErrors (FileWriteError, DataFileNotFoundError) came back from a cluster
    as a bare Exception, which `except FileReadError` did not catch."""
    import inspect
    import pickle

    from subid import errors
    loaders = [pickle]
    try:
        from distributed.protocol import pickle as dask_pickle
        loaders.append(dask_pickle)
    except ImportError:          # the distributed extra is optional
        pass
    classes = [c for _, c in inspect.getmembers(errors, inspect.isclass)
               if issubclass(c, errors.SubidError)]
    assert errors.DataFileNotFoundError in classes and errors.FileWriteError in classes
    for cls in classes:
        try:
            error = cls("no such file: x.csv", path="x.csv")
        except TypeError:
            error = cls("no such file: x.csv")
        for loader in loaders:
            back = loader.loads(loader.dumps(error))
            assert type(back) is cls and str(back) == str(error)
            assert back.__dict__ == error.__dict__
