"""Frequency-response files (read_frd, write_frd): what a round trip keeps, units, refusals.

Reproducers of the session-21 user test: a text round trip kept no sampling period,
MATLAB frequency units other than Hz and rad/s were misread, a unit in a CSV frequency
header was ignored, partial MIMO columns were filled silently, channel names holding the
delimiter made a file read_frd rejects.
"""

from __future__ import annotations

import numpy as np
import pytest

import subid
from subid.errors import FileReadError

W = np.linspace(0.1, 3.0, 20)


def _dt_data(**kw):
    return subid.FRData(W, 0.5 / (np.exp(1j * W) - 0.5), dt=1.0, **kw)


@pytest.mark.parametrize("name", ["frd.csv", "frd.tsv", "frd.txt", "frd.mat", "frd.npz"])
def test_round_trip_keeps_dt(tmp_path, name):
    path = tmp_path / name
    subid.write_frd(_dt_data(), path)
    back = subid.read_frd(path)
    assert back.dt == 1.0
    assert subid.read_frd(path, dt=1.0).dt == 1.0
    with pytest.raises(FileReadError, match=r"dt=0\.5 was passed but .* says dt = 1"):
        subid.read_frd(path, dt=0.5)


def test_text_dt_comment_line(tmp_path):
    path = tmp_path / "frd.csv"
    subid.write_frd(_dt_data(), path)
    assert path.read_text().splitlines()[0] == "# dt = 1.0"
    continuous = tmp_path / "ct.csv"
    subid.write_frd(subid.FRData(W, 1 / (1j * W + 1)), continuous)
    assert subid.read_frd(continuous).dt == 0.0
    with pytest.raises(FileReadError, match="continuous time"):
        subid.read_frd(continuous, dt=0.1)
    path.write_text("# measured 2024\n#Ts: 0.01\nw,re,im\n1,1,0\n")
    assert subid.read_frd(path).dt == 0.01
    path.write_text("# dt = 1 ms\nw,re,im\n1,1,0\n")
    with pytest.raises(FileReadError, match="line 1: '1 ms' is not a sampling period"):
        subid.read_frd(path)
    path.write_text("# dt = 0.1\n# dt = 0.2\nw,re,im\n1,1,0\n")
    with pytest.raises(FileReadError, match="keep one"):
        subid.read_frd(path)
    path.write_text("w,re,im\n1,1,0\n")                     # no dt line: dt= or 0
    assert subid.read_frd(path).dt == 0.0 and subid.read_frd(path, dt=0.5).dt == 0.5


def test_cli_frequency_response_reads_dt_line(tmp_path):
    from click.testing import CliRunner

    from subid.cli.commands import cli
    system = subid.systems.seed001_system()
    w = np.linspace(0.01, 3.0, 120)
    path = tmp_path / "frf.csv"
    subid.write_frd(subid.FRData(w, system.freqresp(w), dt=system.dt), path)
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["identify", str(path), "--frequency-response", "--order",
                                      str(system.A.shape[0]), "--no-report", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert subid.StateSpace.load(out / "model.json").dt == system.dt


def test_mat_ts_minus_one_needs_dt(tmp_path):
    import scipy.io
    path = tmp_path / "ts.mat"
    scipy.io.savemat(path, dict(ResponseData=np.ones((1, 1, 3)), Frequency=[0.1, 0.2, 0.3],
                                Ts=-1.0))
    with pytest.raises(FileReadError, match=r"Ts = -1 .* pass the sampling period as dt="):
        subid.read_frd(path)
    assert subid.read_frd(path, dt=0.5).dt == 0.5
    scipy.io.savemat(path, dict(ResponseData=np.ones((1, 1, 3)), Frequency=[0.1, 0.2, 0.3],
                                Ts=-2.0))
    with pytest.raises(FileReadError, match="Ts = -2 is not a sampling period"):
        subid.read_frd(path)


@pytest.mark.parametrize("name", ["frd.csv", "frd.tsv", "frd.mat", "frd.npz"])
@pytest.mark.parametrize("per_pair", [False, True])
def test_round_trip_keeps_weights(tmp_path, name, per_pair):
    G = np.stack([1 / (1j * W + 1), 2 / (1j * W + 3)], axis=1)[:, :, None]     # 2 x 1
    weights = np.linspace(1, 2, 20 * 2).reshape(20, 2, 1) if per_pair else np.linspace(1, 2, 20)
    data = subid.FRData(W, G, weights=weights)
    subid.write_frd(data, tmp_path / name)
    back = subid.read_frd(tmp_path / name)
    assert back.weights.shape == weights.shape and np.array_equal(back.weights, weights)


def test_partial_or_mixed_weight_columns_refused(tmp_path):
    path = tmp_path / "w.csv"
    path.write_text("w,a/u:re,a/u:im,a/u:weight,b/u:re,b/u:im\n1,1,0,2,1,0\n")
    with pytest.raises(FileReadError, match="':weight' columns for a/u but not for b/u"):
        subid.read_frd(path)
    path.write_text("w,a/u:re,a/u:im,a/u:weight,weight\n1,1,0,2,3\n")
    with pytest.raises(FileReadError, match="keep one kind"):
        subid.read_frd(path)
