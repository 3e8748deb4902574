"""Long online runs: excitation coming and going, NaN bursts, kill and resume."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import subid
from subid import errors, systems


def _stream(n, seed):
    """A record whose input is white noise, then constant, then white again."""
    true = systems.seed001_system()
    r = np.random.default_rng(seed)
    u = r.standard_normal((n, 2))
    u[n // 3: 2 * n // 3] = 0.7                      # excitation stops for a third
    y = true.simulate(u) + 1e-3 * r.standard_normal((n, 2))
    return true, u, y


def _run(n, forgetting, chunk):
    true, u, y = _stream(n, seed=1)
    rs = subid.RecursiveSubspace(3, 2, 2, forgetting=forgetting)
    errors_seen = 0
    for k in range(0, n, chunk):
        rs.update(u[k:k + chunk], y[k:k + chunk])
        if k % (n // 20) < chunk:
            assert np.isfinite(rs._R).all()
            try:
                model = rs.model
                assert all(np.isfinite(getattr(model, m)).all() for m in "ABCD")
            except errors.NotExcitingError:
                errors_seen += 1
        if k == n // 2:                              # a NaN burst is rejected
            bad = y[k:k + 50].copy()
            bad[10:30] = np.nan
            before = rs._R.copy()
            with pytest.raises(errors.DataError, match="NaN"):
                rs.update(u[k:k + 50], bad)
            np.testing.assert_array_equal(rs._R, before)
    assert subid.markov_error(rs.model, true) < 0.01      # converged again
    return errors_seen


def test_excitation_gap_and_nan_burst():
    _run(60_000, forgetting=0.999, chunk=1000)


@pytest.mark.long
def test_ten_million_samples():
    seen = _run(10_000_000, forgetting=0.9999, chunk=100_000)
    assert seen >= 1          # the long constant stretch is reported, not papered over


_WORKER = textwrap.dedent("""
    import sys, numpy as np, subid
    path, ckpt = sys.argv[1], sys.argv[2]
    d = np.load(path)
    rs = subid.RecursiveSubspace(3, 2, 2, forgetting=0.999)
    for k in range(0, d.shape[0], 500):
        rs.update(d[k:k + 500, :2], d[k:k + 500, 2:])
        rs.save(ckpt)
        print(k, flush=True)
""")


@pytest.mark.slow
def test_kill_and_resume_continues_identically(tmp_path):
    _, u, y = _stream(400_000, seed=2)
    path = tmp_path / "rec.npy"
    np.save(path, np.hstack([u, y]))
    ckpt = tmp_path / "state.npz"
    proc = subprocess.Popen([sys.executable, "-c", _WORKER, str(path), str(ckpt)],
                            stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    lines = 0
    deadline = time.time() + 120
    while lines < 20 and time.time() < deadline:       # let it write a few checkpoints
        if proc.stdout.readline():
            lines += 1
    proc.send_signal(signal.SIGKILL)                     # no chance to clean up
    proc.wait()
    resumed = subid.RecursiveSubspace.load(ckpt)         # the last complete checkpoint
    done = resumed.n_samples
    assert 0 < done < 400_000
    resumed.update(u[done:], y[done:])
    straight = subid.RecursiveSubspace(3, 2, 2, forgetting=0.999).update(u, y)
    np.testing.assert_array_equal(resumed._R, straight._R)
    np.testing.assert_array_equal(resumed.model.A, straight.model.A)


_ADAPTIVE_WORKER = textwrap.dedent("""
    import sys, numpy as np, subid
    path, ckpt = sys.argv[1], sys.argv[2]
    d = np.load(path)
    ai = subid.AdaptiveIdentifier(4, 2, 2, dt=0.001)
    for k in range(0, d.shape[0], 20000):
        ai.update(d[k:k + 20000, :2], d[k:k + 20000, 2:])
        ai.save(ckpt)
        print(k, flush=True)
""")


def _adaptive_stream(n, seed):
    from subid.experiments.seed000 import multisine
    true = systems.seed000_system()
    t = np.arange(n) * 0.001
    u = multisine(t, 2, seed=seed)
    quiet = (t % 2000.0) > 1400.0                      # excitation off 30 % of every 2000 s
    u[quiet] = 0.3
    y = true.simulate(u, t=t, hold="foh")
    return true, u, y


@pytest.mark.long
def test_adaptive_ten_million_samples_with_gaps_nan_and_kill_resume(tmp_path):
    n = 10_000_000
    true, u, y = _adaptive_stream(n, seed=3)
    ai = subid.AdaptiveIdentifier(4, 2, 2, dt=0.001)
    half = n // 2
    for k in range(0, half, 500_000):
        ai.update(u[k:k + 500_000], y[k:k + 500_000])
        assert all(np.isfinite(getattr(ai.model, m)).all() for m in "ABCD")
    bad = y[half:half + 100].copy()
    bad[40:60] = np.nan
    snapshot = ai.model.A.copy()
    with pytest.raises(errors.DataError, match="NaN"):
        ai.update(u[half:half + 100], bad)
    np.testing.assert_array_equal(ai.model.A, snapshot)
    # kill and resume: a worker runs the second half, is killed, and we resume
    path = tmp_path / "rest.npy"
    np.save(path, np.hstack([u[half:], y[half:]]))
    ckpt = tmp_path / "adaptive.npz"
    ai.save(ckpt)
    proc = subprocess.Popen([sys.executable, "-c", _ADAPTIVE_WORKER.replace(
        "ai = subid.AdaptiveIdentifier(4, 2, 2, dt=0.001)",
        f"ai = subid.AdaptiveIdentifier.load({str(ckpt)!r})"), str(path), str(ckpt)],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    lines = 0
    while lines < 10 and proc.stdout.readline():
        lines += 1
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    resumed = subid.AdaptiveIdentifier.load(ckpt)
    done = resumed.n_samples
    assert half < done < n
    resumed.update(u[done:], y[done:])
    straight = subid.AdaptiveIdentifier(4, 2, 2, dt=0.001)    # never interrupted
    straight.update(u, y)
    np.testing.assert_array_equal(resumed.model.A, straight.model.A)
    assert subid.pole_error(resumed.model, true) < 1e-3
