"""Tests of subid.datasets: every bundled DaISy set loads with the documented layout."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

from subid import datasets
from subid.errors import DataError

# name: (n_samples, n_inputs, n_outputs, dt, dt_known), from docs/daisy-datasets.md
EXPECTED = {
    "dryer": (1000, 1, 1, 0.08, False),
    "ballbeam": (1000, 1, 1, 0.1, True),
    "robot_arm": (1024, 1, 1, 1.0, False),
    "exchanger": (4000, 1, 1, 1.0, True),
    "CD_player_arm": (2048, 2, 2, 1.0, False),
    "glassfurnace": (1247, 3, 6, 1.0, False),
    "dryer2": (867, 3, 3, 10.0, True),
    "powerplant": (200, 5, 3, 1228.8, True),
    "winding": (2500, 5, 2, 0.1, True),
    "evaporator": (6305, 3, 3, 1.0, False),
    "steamgen": (9600, 4, 4, 3.0, True),
}


def _raw(name):
    ref = resources.files("subid.datasets").joinpath("data", datasets.info(name)["file"])
    with resources.as_file(ref) as path:
        return np.loadtxt(path)


def test_names():
    assert sorted(datasets.names()) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_load_shape_dt_finite(name):
    n, n_in, n_out, dt, known = EXPECTED[name]
    data = datasets.load(name)
    assert data.u.shape == (n, n_in)
    assert data.y.shape == (n, n_out)
    assert data.dt == pytest.approx(dt)
    assert np.isfinite(data.u).all() and np.isfinite(data.y).all()
    assert len(set(data.input_names + data.output_names)) == n_in + n_out
    meta = datasets.info(name)
    assert meta["n_samples"] == n
    assert (meta["n_inputs"], meta["n_outputs"]) == (n_in, n_out)
    assert meta["dt"] == pytest.approx(dt) and meta["dt_known"] is known
    assert tuple(meta["input_names"]) == data.input_names
    assert tuple(meta["output_names"]) == data.output_names
    assert meta["description"] and "DaISy" in meta["source"] and meta["dt_note"]
    # the record equals the documented columns of the file
    raw = _raw(name)
    np.testing.assert_array_equal(data.u, raw[:, np.array(meta["input_columns"]) - 1])
    np.testing.assert_array_equal(data.y, raw[:, np.array(meta["output_columns"]) - 1])


def test_dryer_input_is_binary_and_dt_caveat():
    data = datasets.load("dryer")
    assert set(np.unique(data.u[:, 0])) == {3.41, 6.41}
    meta = datasets.info("dryer")
    assert meta["dt_known"] is False and "0.08" in meta["dt_note"]
    assert data.input_names == ("voltage",) and data.output_names == ("temperature",)


def test_exchanger_index_column_not_an_input():
    data = datasets.load("exchanger")
    assert data.n_inputs == 1
    assert not np.array_equal(data.u[:, 0], np.arange(1, 4001))
    raw = _raw("exchanger")
    np.testing.assert_array_equal(raw[:, 0], np.arange(1, 4001))
    np.testing.assert_array_equal(data.u[:, 0], raw[:, 1])


def test_powerplant_layout_ignores_yr():
    data = datasets.load("powerplant")
    assert (data.n_inputs, data.n_outputs) == (5, 3)
    raw = _raw("powerplant")
    assert raw.shape == (200, 12)
    np.testing.assert_array_equal(data.u, raw[:, 1:6])
    np.testing.assert_array_equal(data.y, raw[:, 6:9])
    assert data.output_names[0] == "steam_pressure"


def test_index_columns_dropped():
    for name in ("glassfurnace", "dryer2", "steamgen"):
        data = datasets.load(name)
        n = data.n_samples
        for arr in (data.u, data.y):
            for col in arr.T:
                assert not np.array_equal(col, np.arange(1, n + 1))
                assert not np.array_equal(col, 3.0 * np.arange(n))


def test_case_insensitive_and_unknown():
    assert datasets.load("cd_player_arm").n_inputs == 2
    with pytest.raises(DataError, match=r"unknown data set 'dryerr'.*ballbeam.*winding"):
        datasets.load("dryerr")
    with pytest.raises(DataError, match="available"):
        datasets.info("nope")


def test_info_is_a_copy():
    meta = datasets.info("ballbeam")
    meta["input_names"].append("x")
    meta["dt"] = 99
    assert datasets.info("ballbeam")["input_names"] == ["beam_angle"]
    assert datasets.load("ballbeam").dt == pytest.approx(0.1)
