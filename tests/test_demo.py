"""The demo's work sharing (issue 29): one identification per (dataset, method), its fit %
shown in the report as computed, and the pool's schedule."""

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from subid.cli import demo  # noqa: E402


def test_identify_one_is_the_row_of_evaluate_and_the_report_shows_its_fits(tmp_path):
    row, model = demo.identify_one("dryer", "arx")
    rows, models, est, val = demo.evaluate("dryer", ["arx"])
    assert rows[0]["order"] == row["order"] == model.order
    np.testing.assert_allclose(rows[0]["fit_val"], row["fit_val"], rtol=0, atol=1e-12)
    assert row["cpu_seconds"] >= 0 and row["error"] is None
    # the report shows the fit % of the rows it is given (not computed again): a
    # distinctive value appears in the summary table
    shown = dict(row, fit_val=np.array([12.345]), fit_est=np.array([67.891]))
    result = demo.write_report("dryer", str(tmp_path), [shown], {"arx": model})
    html = open(result["path"], encoding="utf-8").read()
    assert "12.3" in html and "67.9" in html
    assert result["entry"]["arx"].startswith("12.3")


def test_a_failed_method_gives_a_row_with_its_error_and_no_model(monkeypatch):
    from subid.errors import DataError
    from subid.methods.registry import METHODS

    def failing(data, order=None):
        raise DataError("no luck here")
    monkeypatch.setattr(type(METHODS["arx"]), "load", lambda spec: failing)
    row, model = demo.identify_one("dryer", "arx")
    assert model is None and row["error"] == "no luck here" and row["fit_val"] is None


def test_the_pool_starts_the_longest_tasks_first():
    # ct on the largest record before any discrete-time method on the smallest
    assert demo._expected_cost("steamgen", "ct") > demo._expected_cost("steamgen", "ls") \
        > demo._expected_cost("powerplant", "ls")
    assert demo.default_jobs(1) == 1 and demo.default_jobs(1000) >= 1


def test_worker_environment_is_restored():
    import os
    before = os.environ.get("SUBID_TEST_VARIABLE")
    with demo._Environment(SUBID_TEST_VARIABLE="1"):
        assert os.environ["SUBID_TEST_VARIABLE"] == "1"
    assert os.environ.get("SUBID_TEST_VARIABLE") == before


def test_the_pool_counts_every_task_on_the_progress_bar(tmp_path, monkeypatch):
    """With jobs > 1 the bar has one step per identification and per report, and
    every one is counted (here a pool of two threads on one small record, two methods:
    the schedule of the process pool without its start-up)."""
    counted = []

    class Recorder:
        def __init__(self, names, desc, *, enabled):
            self.names = list(names)

        def finished(self, name):
            counted.append(name)

        def close(self):
            assert sorted(counted) == sorted(self.names)

    monkeypatch.setattr(demo, "Steps", Recorder)
    import concurrent.futures
    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor",        # no spawning here
                        lambda jobs, **_: concurrent.futures.ThreadPoolExecutor(jobs))
    result = demo.run(str(tmp_path), datasets=["dryer"], methods=["arx", "n4sid"], jobs=2,
                      progress=True)
    assert sorted(counted) == ["dryer: arx", "dryer: n4sid", "dryer: report"]
    assert len(result["reports"]) == 1
