"""One BLAS thread inside subid's computations unless the user chose (subid._blas)."""

import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import subid
from subid import _blas
from subid.methods.registry import METHODS


def _blas_threads():
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


@pytest.fixture
def no_choice(monkeypatch):
    """No thread variable in the environment (make test sets OPENBLAS_NUM_THREADS=1)
    and two BLAS threads before the call, set through threadpoolctl, not thread_limit."""
    for name in _blas.CHOICE_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    np.ones((2, 2)) @ np.ones((2, 2))
    with threadpool_limits(limits=2, user_api="blas"):
        assert set(_blas_threads()) == {2}
        yield


def _record_csv(tmp_path, seed):
    """A 400-sample record of the seed-001 system as a CSV (u1, u2, y1, y2)."""
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=seed)
    path = tmp_path / "r.csv"
    np.savetxt(path, np.hstack([data.u, data.y]), delimiter=",",
               header="u1,u2,y1,y2", comments="")
    return path


def _probe(seen):
    @_blas.serial_blas
    def computation(fail=False):
        seen.append(_blas_threads())
        if fail:
            raise RuntimeError("inside")
        return subid.moesp(subid.systems.simulate_data(subid.systems.seed001_system(), 300,
                                                       seed=0), 3)
    return computation


def test_one_thread_inside_and_restored_after(no_choice):
    seen = []
    _probe(seen)()
    assert set(seen[0]) == {1}
    assert set(_blas_threads()) == {2}
    with pytest.raises(RuntimeError):                # an exception restores them too
        _probe(seen)(fail=True)
    assert set(seen[1]) == {1}
    assert set(_blas_threads()) == {2}


def test_the_users_choice_holds(no_choice, monkeypatch):
    seen = []
    with subid.thread_limit(2):
        _probe(seen)()
    assert set(seen[0]) == {2}
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    _probe(seen)()
    assert set(seen[1]) == {2}
    assert set(_blas_threads()) == {2}


def test_calls_in_other_threads_leave_the_main_threads_setting(no_choice):
    # a worker thread's call (a Dask worker's) neither sets nor restores the pools: the
    # main thread's call keeps one thread after the worker's ended, and the pools end as
    # they began
    seen = {}

    @_blas.serial_blas
    def worker_call():
        seen["worker"] = _blas_threads()

    @_blas.serial_blas
    def main_call():
        worker = threading.Thread(target=worker_call)
        worker.start()
        worker.join(30)
        seen["main after the worker"] = _blas_threads()

    main_call()
    assert set(seen["worker"]) == {1}                 # the process's setting
    assert set(seen["main after the worker"]) == {1}
    assert set(_blas_threads()) == {2}
    worker = threading.Thread(target=worker_call)     # alone: the pools as they are
    worker.start()
    worker.join(30)
    assert set(seen["worker"]) == {2}
    assert set(_blas_threads()) == {2}


def test_the_public_computations_are_marked():
    names = ["identify", "pem", "fit_percent", "predict", "residuals", "spa", "etfe",
             "impulseest", "estimate_delay", "freqresp_bounds", "step_bounds",
             "simulation_bounds", "parameter_covariance", "identify_file",
             "identify_stream", "ct_subspace_paper"]
    names += [spec.attribute for spec in METHODS.values() if spec.kind == "batch"]
    unmarked = [n for n in names if not getattr(getattr(subid, n), "serial_blas", False)]
    assert not unmarked


def test_the_command_line_restores_the_pools(no_choice, tmp_path):
    from subid.cli import main
    path = _record_csv(tmp_path, seed=1)
    assert main(["--quiet", "identify", str(path), "--inputs", "u1,u2", "--outputs",
                 "y1,y2", "--order", "3", "--no-report", "--out",
                 str(tmp_path / "out")]) == 0
    assert set(_blas_threads()) == {2}


def test_a_library_that_refuses_does_not_stop_the_computation(no_choice, monkeypatch):
    class Refusing:
        num_threads = 4

        def set_num_threads(self, n):
            raise RuntimeError("not settable")

    monkeypatch.setattr(_blas, "_controllers", [Refusing()])
    seen = []
    model = _probe(seen)()
    assert model.order == 3
    assert set(_blas_threads()) == {2}


def test_the_online_updates_of_track_run_with_one_thread(no_choice, tmp_path, monkeypatch):
    from subid.cli import main
    from subid.methods.online.base import Tracker
    seen = []
    run = Tracker.run

    def recorded(self, *args, **kwargs):
        seen.append(_blas_threads())
        return run(self, *args, **kwargs)

    monkeypatch.setattr(Tracker, "run", recorded)
    path = _record_csv(tmp_path, seed=2)
    assert main(["--quiet", "track", str(path), "--inputs", "u1,u2", "--outputs", "y1,y2",
                 "--method", "recursive", "--order", "3", "--no-report", "--out",
                 str(tmp_path / "out")]) == 0
    assert seen and set(seen[0]) == {1}
    assert set(_blas_threads()) == {2}
