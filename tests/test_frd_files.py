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
from subid.errors import DataError, FileReadError

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


@pytest.mark.parametrize("unit, scale", [
    ("kHz", 1 / (2 * np.pi * 1e3)), ("MHz", 1 / (2 * np.pi * 1e6)), ("GHz", 1 / (2 * np.pi * 1e9)),
    ("Hz", 1 / (2 * np.pi)), ("cycles/s", 1 / (2 * np.pi)), ("cycles/TimeUnit", 1 / (2 * np.pi)),
    ("rpm", 60 / (2 * np.pi)), ("cycles/min", 60 / (2 * np.pi)), ("rad/s", 1.0),
    ("rad/TimeUnit", 1.0), ("rad/ms", 1e-3), ("rad/min", 60.0), ("rad/hr", 3600.0),
    ("rad/day", 86400.0), ("rad/week", 604800.0), ("cycles/millisecond", 1e-3 / (2 * np.pi)),
    ("mHz", 1 / (2 * np.pi * 1e-3)),
])
def test_mat_frequency_units(tmp_path, unit, scale):
    import scipy.io
    w = np.linspace(0.1, 3.0, 5)
    path = tmp_path / "u.mat"
    scipy.io.savemat(path, dict(ResponseData=(1 / (1j * w + 1)).reshape(1, 1, -1),
                                Frequency=w * scale, FrequencyUnit=unit, Ts=0.0))
    assert np.allclose(subid.read_frd(path).w, w, rtol=1e-12)


def test_mat_frequency_unit_unknown_and_time_unit(tmp_path):
    import scipy.io
    w = np.linspace(0.1, 3.0, 5)
    path = tmp_path / "u.mat"
    base = dict(ResponseData=(1 / (1j * w + 1)).reshape(1, 1, -1), Ts=0.0)
    for unit in ("rad/month", "cycles/year", "furlongs", "mhz"):
        scipy.io.savemat(path, dict(base, Frequency=w, FrequencyUnit=unit))
        with pytest.raises(FileReadError, match=f"unknown FrequencyUnit '{unit}'; known"):
            subid.read_frd(path)
    # TimeUnit: Ts and w are in milliseconds; Hz converts to rad per millisecond
    scipy.io.savemat(path, dict(base, Frequency=w * 1e3 / (2 * np.pi), FrequencyUnit="Hz",
                                TimeUnit="milliseconds"))
    assert np.allclose(subid.read_frd(path).w, w, rtol=1e-12)
    scipy.io.savemat(path, dict(base, Frequency=w, FrequencyUnit="rad/TimeUnit",
                                TimeUnit="milliseconds"))
    assert np.allclose(subid.read_frd(path).w, w, rtol=1e-12)
    scipy.io.savemat(path, dict(base, Frequency=w, TimeUnit="fortnights"))
    with pytest.raises(FileReadError, match="unknown TimeUnit 'fortnights'"):
        subid.read_frd(path)


@pytest.mark.parametrize("head, scale", [
    ("w [Hz]", 2 * np.pi), ("omega (Hz)", 2 * np.pi), ("Frequency [rad/sec]", 1.0),
    ("Frequency [kHz]", 2 * np.pi * 1e3), ("f [rad/s]", 1.0), ("freq [rpm]", 2 * np.pi / 60),
    ("Frequency (cycles/min)", 2 * np.pi / 60), ("f_hz [Hz]", 2 * np.pi), ("w", 1.0),
    ("f", 2 * np.pi), ("Frequency [MHz]", 2 * np.pi * 1e6), ("hz", 2 * np.pi),
    ("rad/s", 1.0), ("w [rad/TimeUnit]", 1.0),
])
def test_csv_frequency_header_unit(tmp_path, head, scale):
    path = tmp_path / "h.csv"
    path.write_text(f"{head},mag,phase\n1,1,0\n10,0.5,-45\n")
    assert np.allclose(subid.read_frd(path).w, [scale, 10 * scale], rtol=1e-12)


_TWO = "w,a/u:re,a/u:im,b/u:re,b/u:im"


@pytest.mark.parametrize("text, match", [
    ("Frequency [furlongs],mag,phase\n1,1,0\n",
     "frequency column 'Frequency \\[furlongs\\]' has the unknown unit 'furlongs'; known"),
    ("f_hz [rad/s],mag,phase\n1,1,0\n", "its name says Hz but its unit says rad/s"),
    ("w_rad (kHz),mag,phase\n1,1,0\n", "name says rad per time unit but its unit says kHz"),
    (f"{_TWO},a/u:std\n1,1,0,1,0,0.1\n",
     "':std' columns for a/u but not for b/u; give them for every output/input pair or for "
     "none"),
    (f"{_TWO},b:coherence\n1,1,0,1,0,0.9\n", "':coherence' columns for b but not for a"),
    (f"{_TWO},coherence\n1,1,0,1,0,0.9\n", "'<output>:coherence'"),
    ("w,re,im,mag,phase\n1,1,0,1,0\n",
     "y1/u1 has columns 're', 'im', 'mag', 'phase', two representations"),
    ("w,Magnitude [dB],mag,phase\n1,0,1,0\n", "'mag', 'Magnitude \\[dB\\]'"),
    ("w,mag,phase,phase_rad\n1,1,0,0\n", "'phase', 'phase_rad'"),
    ("w,a/u:re,a/u:im,a/u:weight,b/u:re,b/u:im\n1,1,0,2,1,0\n",
     "':weight' columns for a/u but not for b/u"),
    ("w,a/u:re,a/u:im,a/u:weight,weight\n1,1,0,2,3\n", "keep one kind"),
    # magnitude and phase units: an unknown one was read as linear or as degrees
    ("f,Magnitude [dB],Phase [r]\n1,0,0\n",
     "column 'Phase \\[r\\]' has the unknown unit 'r'; a phase is in deg or rad"),
    ("f,Magnitude [dB],Phase [grad]\n1,0,0\n", "unknown unit 'grad'"),
    ("f,Gain [V],Phase [deg]\n1,1,0\n",
     "unknown unit 'v'; a magnitude is linear \\(no unit, abs\\) or in dB"),
])
def test_unknown_units_and_partial_or_conflicting_columns_refused(tmp_path, text, match):
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(FileReadError, match=match):
        subid.read_frd(path)


@pytest.mark.parametrize("mag, phase, in_db, in_rad", [
    ("Gain [dBV]", "Phase [deg]", True, False), ("Magnitude [dB re 1 V/V]", "Phase [°]", True,
                                                 False),
    ("Magnitude [dB]", "Phase [rads]", True, True), ("Magnitude (abs)", "Phase (radians)",
                                                     False, True),
])
def test_magnitude_and_phase_units(tmp_path, mag, phase, in_db, in_rad):
    # a 40 dB amplifier with a pole at 2 kHz, as an analyser exports it
    f = np.geomspace(10, 1e4, 20)
    g = 100 / (1 + 1j * f / 2000)
    path = tmp_path / "amp.csv"
    np.savetxt(path, np.column_stack([f, 20 * np.log10(np.abs(g)) if in_db else np.abs(g),
                                      np.angle(g) if in_rad else np.degrees(np.angle(g))]),
               delimiter=",", header=f"Frequency [Hz],{mag},{phase}", comments="")
    np.testing.assert_allclose(subid.read_frd(path).response[:, 0, 0], g, rtol=1e-12)


def test_negative_magnitude_named_by_line_and_complete_extras_accepted(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("# a comment\nw,mag,phase\n1,1,0\n2,-0.5,0\n")
    with pytest.raises(FileReadError, match="line 4, column 'mag': magnitude -0.5 is "
                                            "negative") as err:
        subid.read_frd(path)
    assert err.value.line == 4
    path.write_text(f"{_TWO},a:coherence,b:coherence,a/u:std,b/u:std\n"
                    "1,1,0,1,0,0.9,0.8,0.1,0.2\n")
    back = subid.read_frd(path)                       # all pairs (outputs): accepted
    assert np.allclose(back.coherence, [[0.9, 0.8]]) and np.allclose(back.std.ravel(), [0.1, 0.2])


@pytest.mark.parametrize("name", ["frd.csv", "frd.tsv"])
def test_channel_names_with_delimiter_or_quotes_round_trip(tmp_path, name):
    G = np.ones((20, 2, 2)) * (1 / (1j * W + 1))[:, None, None]
    data = subid.FRData(W, G, input_names=["a,b", 'say "hi"'], output_names=["x\ty", "a;b;c;d"])
    subid.write_frd(data, tmp_path / name)
    back = subid.read_frd(tmp_path / name)
    assert back.input_names == data.input_names and back.output_names == data.output_names
    assert np.array_equal(back.response, data.response)
    siso = subid.FRData(W, G[:, 0, 0], input_names=["p;q;r;s,t"])     # ';' only inside quotes
    subid.write_frd(siso, tmp_path / name)
    assert subid.read_frd(tmp_path / name).input_names == ("p;q;r;s,t",)


@pytest.mark.parametrize("outputs, inputs, problem", [
    (["a/b"], ["u"], "output name 'a/b' holds '/'"), ([" y"], ["u"], "white space"),
    (["y"], ["u\nv"], "line break"), ([""], ["u"], "is empty")])
def test_channel_names_a_text_header_cannot_carry(tmp_path, outputs, inputs, problem):
    data = subid.FRData(W, 1 / (1j * W + 1), input_names=inputs, output_names=outputs)
    with pytest.raises(DataError, match=problem):
        subid.write_frd(data, tmp_path / "n.csv")
    subid.write_frd(data, tmp_path / "n.npz")               # arrays carry any name
    assert subid.read_frd(tmp_path / "n.npz").output_names == tuple(outputs)


def test_a_zero_std_is_refused_where_it_sets_the_weights():
    # floored, three zero-std frequencies of 100 got 1e12 times the others' weight (a
    # relative error of 0.37); all zero ended in a raw LAPACK error
    from subid.errors import DataError
    true = subid.systems.random_system(2, 1, 1, seed=3)
    w = np.linspace(0.05, 3.0, 100)
    G = true.freqresp(w)
    std = np.full(G.shape, 0.01)
    std[[0, 40, 80]] = 0.0
    data = subid.FRData(w, G, 1.0, std=std)
    for call in (lambda: subid.fd_subspace(data, 2), lambda: subid.pem(data, true)):
        with pytest.raises(DataError, match="std is zero at 3 of 100 frequencies"):
            call()
    # weights given: the std does not weight, and the fit goes on
    model = subid.fd_subspace(subid.FRData(w, G, 1.0, std=std, weights=np.ones(100)), 2)
    assert np.abs(model.freqresp(w) - G).max() < 1e-8


def test_pem_on_frequency_data_refuses_a_jacobian_past_its_limit():
    # 8 x 8 at order 16 on 10^4 frequencies: a raw numpy MemoryError mid-search before
    from subid.errors import ResourceLimitError
    rng = np.random.default_rng(0)
    w = np.linspace(0.001, 3.1, 10_000)
    response = rng.standard_normal((w.size, 8, 8)) + 1j * rng.standard_normal((w.size, 8, 8))
    start = subid.StateSpace(0.5 * np.eye(16), np.ones((16, 8)), np.ones((8, 16)),
                             np.zeros((8, 8)), 1.0)
    with pytest.raises(ResourceLimitError, match="forms a Jacobian of 2.44 GiB \\(limit 2 GiB\\)"):
        subid.pem(subid.FRData(w, response, 1.0), start)
