"""One contract for the online identifiers (subid.OnlineIdentifier), checked on both classes.

Chunk invariance, checkpoint round trip, a rejected chunk leaves the state
unchanged, kill/resume (a checkpoint continued in a new process equals the
uninterrupted run), model before data, IOData and time stamps, the settings
stored unchanged, and one history format that plot.convergence reads.
"""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import subid
from subid import errors, systems
from subid.methods.online.base import OnlineIdentifier, Tracker


def _adaptive_record(n=3000, dt=0.01):
    from subid.experiments.seed000 import multisine
    true = subid.StateSpace([[-1.0, 0.5], [-0.5, -1.5]], [[1.0, 0.4], [-0.3, 1.0]],
                            [[1.0, 0.4], [-0.3, 1.0]], [[0.2, 0.0], [0.1, -0.3]], 0.0)
    t = np.arange(n) * dt
    u = multisine(t, 2, w_min=0.3, w_max=10.0)
    y = true.simulate(u, t=t, hold="foh")
    return subid.IOData(u, y, t=t)


def _recursive_record(n=1500):
    return systems.simulate_data(systems.seed001_system(), n, seed=5, process_snr_db=30,
                                 output_snr_db=30)


# name -> (factory of a fresh identifier, record, whether chunking is bit-exact)
CASES = {
    "recursive": (lambda **kw: subid.RecursiveSubspace(3, 2, 2, horizon=5, history_size=16,
                                                       history_stride=100, **kw),
                  _recursive_record, False),
    "recursive_forgetting": (lambda **kw: subid.RecursiveSubspace(
        3, 2, 2, horizon=5, forgetting=0.999, history_size=16, history_stride=100, **kw),
        _recursive_record, False),
    "adaptive": (lambda **kw: subid.AdaptiveIdentifier(2, 2, 2, horizon=3, filter_poles=-2.0,
                                                       refresh_every=7, history_size=16,
                                                       dt=0.01, **kw),
                 _adaptive_record, True),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    make, record, exact = CASES[request.param]
    return request.param, make, record(), exact


def _quiet_model(ident):
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", errors.NotConvergedWarning)
        return ident.model


def _assert_same(a, b, exact):
    ma, mb = _quiet_model(a), _quiet_model(b)
    for name in "ABCD":
        if exact:
            np.testing.assert_array_equal(getattr(ma, name), getattr(mb, name), err_msg=name)
        else:
            # to rounding, amplified by AdaptiveIdentifier's refit of (8) (an
            # iterative fit of the state; the states themselves agree to 1e-10)
            np.testing.assert_allclose(getattr(ma, name), getattr(mb, name), rtol=1e-6,
                                       atol=1e-8, err_msg=name)
    if exact:
        np.testing.assert_array_equal(a.state, b.state)
    else:
        np.testing.assert_allclose(a.state, b.state, rtol=1e-8, atol=1e-9)


def test_is_an_online_identifier(case):
    _, make, data, _ = case
    ident = make()
    assert isinstance(ident, OnlineIdentifier)
    assert (ident.order, ident.n_inputs, ident.n_outputs) in ((3, 2, 2), (2, 2, 2))
    assert ident.n_samples == 0 and ident.t is None
    with pytest.raises(errors.TooFewSamplesError):
        _ = ident.model
    # settings stored unchanged: a fresh identifier with the same settings
    params = ident.get_params()
    assert params["history_size"] == 16 and params["horizon"] in (3, 5)
    twin = type(ident)(**params)
    # only (order, n_inputs, n_outputs) by position (issue 24, item 6)
    with pytest.raises(errors.OptionError, match="horizon"):
        type(ident)(params["order"], params["n_inputs"], params["n_outputs"], params["horizon"])
    a = ident.update(data.u[:600], data.y[:600])
    b = twin.update(data.u[:600], data.y[:600])
    assert a is ident and ident.n_samples == 600
    _assert_same(a, b, exact=True)
    assert ident.checkpoint_kind() == f"subid.{type(ident).__name__}"


def test_chunk_invariance(case):
    _, make, data, exact = case
    whole = make().update(data.u, data.y)
    for size in (1, 7, 250):
        ident = make()
        for k in range(0, 700, size):
            stop = min(k + size, 700)
            ident.update(data.u[k:stop], data.y[k:stop])
        ident.update(data.u[700:], data.y[700:])
        assert ident.n_samples == data.n_samples
        _assert_same(ident, whole, exact)
        assert ident.t == pytest.approx(whole.t, rel=1e-12)


def test_iodata_and_time_stamps(case):
    """update accepts an IOData record, and arrays with their time stamps t."""
    name, make, data, _ = case
    plain = make().update(data.u, data.y)
    from_record = make().update(data)            # (the adaptive record has time stamps)
    _assert_same(from_record, plain, exact=False)
    dt = 0.01 if name == "adaptive" else 1.0
    t = np.arange(data.n_samples) * dt
    stamped = make()
    stamped.update(data.u[:500], data.y[:500], t[:500])
    stamped.update(data.u[500:], data.y[500:], t=t[500:])
    _assert_same(stamped, plain, exact=False)
    assert stamped.t == pytest.approx(t[-1])
    with pytest.raises(errors.DataError):
        make().update(data, data.y)              # a record and arrays: ambiguous
    with pytest.raises(errors.DataError):
        make().update(data.u)                    # no outputs


def test_rejected_chunk_leaves_state_unchanged(case, tmp_path):
    _, make, data, _ = case
    ident = make().update(data.u[:800], data.y[:800])
    ident.save(tmp_path / "before.npz")
    before = (tmp_path / "before.npz").read_bytes()
    bad_u = data.u[800:900].copy()
    bad_u[17, 0] = np.nan
    bad_calls = [(bad_u, data.y[800:900], None),
                 (data.u[800:900], data.y[800:899], None),           # lengths differ
                 (data.u[800:900, :1], data.y[800:900], None),        # channels
                 (data.u[800:900], data.y[800:900], np.zeros(100))]   # time not increasing
    for u, y, t in bad_calls:
        with pytest.raises(errors.DataError):
            ident.update(u, y, t)
        ident.save(tmp_path / "after.npz")
        assert (tmp_path / "after.npz").read_bytes() == before
    reference = make().update(data.u, data.y)
    ident.update(data.u[800:], data.y[800:])
    _assert_same(ident, reference, exact=False)


def test_checkpoint_round_trip(case, tmp_path):
    """A loaded identifier is the saved one, and continuing it gives exactly
    the estimates of a run that never stopped."""
    _, make, data, _ = case
    straight = make().update(data.u, data.y)
    first = make().update(data.u[:900], data.y[:900])
    first.save(tmp_path / "ckpt.npz")
    loaded = type(first).load(tmp_path / "ckpt.npz")
    assert loaded.n_samples == 900 and loaded.t == first.t
    assert loaded.get_params().keys() == first.get_params().keys()
    first.update(data.u[900:], data.y[900:])
    loaded.update(data.u[900:], data.y[900:])
    _assert_same(loaded, first, exact=True)
    _assert_same(loaded, straight, exact=False)
    for key in ("sample", "t", "poles", "A"):
        np.testing.assert_array_equal(loaded.history[key], first.history[key])


def test_kill_and_resume(case, tmp_path):
    """A process killed after writing a checkpoint: a new process resumes from
    it and ends where an uninterrupted run ends."""
    name, make, data, _ = case
    np.savez(tmp_path / "data.npz", u=data.u, y=data.y)
    kw = {"recursive": "subid.RecursiveSubspace(3, 2, 2, horizon=5, history_size=16, "
                       "history_stride=100)",
          "recursive_forgetting": "subid.RecursiveSubspace(3, 2, 2, horizon=5, "
                                  "forgetting=0.999, history_size=16, history_stride=100)",
          "adaptive": "subid.AdaptiveIdentifier(2, 2, 2, horizon=3, filter_poles=-2.0, "
                      "refresh_every=7, history_size=16, dt=0.01)"}[name]
    script = textwrap.dedent(f"""
        import os, signal, sys
        import numpy as np
        import subid
        d = np.load({str(tmp_path / 'data.npz')!r})
        ident = {kw}
        ident.update(d["u"][:1000], d["y"][:1000])
        ident.save({str(tmp_path / 'ckpt.npz')!r})
        sys.stdout.flush()
        os.kill(os.getpid(), signal.SIGKILL)      # killed mid-stream
    """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [os.path.join(os.path.dirname(os.path.dirname(__file__)), "src"),
         os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          timeout=300)
    assert proc.returncode != 0                       # it did not exit normally
    resumed = type(make()).load(tmp_path / "ckpt.npz")
    assert resumed.n_samples == 1000
    resumed.update(data.u[1000:], data.y[1000:])
    straight = make().update(data.u, data.y)
    _assert_same(resumed, straight, exact=False)


def test_history_format_and_convergence_plot(case):
    _, make, data, _ = case
    ident = make().update(data.u, data.y)
    hist = ident.history
    k = hist["sample"].size
    assert 2 <= k <= 16
    n, nu, ny = ident.order, ident.n_inputs, ident.n_outputs
    assert hist["t"].shape == (k,) and hist["poles"].shape == (k, n)
    assert hist["A"].shape == (k, n, n) and hist["B"].shape == (k, n, nu)
    assert hist["C"].shape == (k, ny, n) and hist["D"].shape == (k, ny, nu)
    assert np.all(np.diff(hist["sample"]) > 0)
    np.testing.assert_allclose(np.sort_complex(hist["poles"][-1]),
                               np.sort_complex(np.linalg.eigvals(hist["A"][-1])), rtol=1e-8)
    pytest.importorskip("matplotlib")
    from subid.evaluation import plot
    fig = plot.convergence(hist)
    assert len(fig.axes) >= 2
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_tracker_runs_any_online_identifier(case, tmp_path):
    """The library's tracker (what `subid track` runs): snapshots, periodic
    checkpoints with their traces, and a resumed run that continues them."""
    _, make, data, _ = case
    tracker = Tracker(make(), data, trace_every=300, checkpoint_every=1000,
                      checkpoint_dir=str(tmp_path / "ck"), keep=1)
    tracker.run(0, chunk=128)
    hist = tracker.history()
    assert hist["sample"][-1] == data.n_samples and hist["parameters"].shape[0] == \
        hist["sample"].size
    files = sorted(os.listdir(tmp_path / "ck"))
    assert len([f for f in files if not f.endswith(".trace.npz")]) == 1       # keep=1
    ckpt = str(tmp_path / "ck" / [f for f in files if not f.endswith(".trace.npz")][0])
    ident = type(tracker.ident).load(ckpt)
    again = Tracker(ident, data, trace_every=300)
    again.load_trace(ckpt[:-4] + ".trace.npz", ident.n_samples)
    again.run(ident.n_samples, chunk=128)
    np.testing.assert_array_equal(again.history()["sample"], hist["sample"])
    np.testing.assert_allclose(again.history()["poles"], hist["poles"], rtol=1e-8, atol=1e-10)


OLD = os.path.join(os.path.dirname(__file__), "data", "old_checkpoints")


@pytest.mark.parametrize("name", ["recursive_v2", "recursive_v2_forgetting",
                                  "adaptive_kind_AdaptiveIdentifier"])
def test_checkpoints_of_the_previous_format_still_load(name):
    """Checkpoints written before the common contract (RecursiveSubspace format
    2, AdaptiveIdentifier kind 'AdaptiveIdentifier'; files made with the
    previous release's code) load, and continuing them gives what that code
    gave (continued.json, written by it)."""
    import json
    import warnings
    data = systems.simulate_data(systems.seed001_system(), 1200, seed=5, process_snr_db=30,
                                 output_snr_db=30)
    cls = subid.AdaptiveIdentifier if name.startswith("adaptive") else subid.RecursiveSubspace
    ident = cls.load(os.path.join(OLD, name + ".npz"))
    assert ident.n_samples == 600
    ident.update(data.u[600:], data.y[600:])
    with open(os.path.join(OLD, "continued.json")) as fh:
        want = json.load(fh)[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", errors.NotConvergedWarning)
        model = ident.model
    for key in "ABCD":
        np.testing.assert_allclose(getattr(model, key), want[key], rtol=1e-9, atol=1e-10,
                                   err_msg=key)


def test_a_plain_subclass_of_an_identifier_restores_through_the_base_class(tmp_path):
    """OnlineIdentifier.load found only classes defining load themselves: a plain
    subclass of RecursiveSubspace (inheriting load) saved a checkpoint that
    OnlineIdentifier.load (and so check_online_identifier's checkpoint sub-check)
    refused as 'no online identifier of this version of subid'."""
    import numpy as np

    import subid

    class Plain(subid.RecursiveSubspace):
        pass

    data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=1)
    ident = Plain(3, 2, 2, horizon=5).update(data.u, data.y)
    ident.save(tmp_path / "plain.npz")
    back = subid.OnlineIdentifier.load(tmp_path / "plain.npz")
    assert type(back) is Plain
    np.testing.assert_array_equal(back.model.A, ident.model.A)
