"""Defects a user test of the command line found: the order of the polynomial methods
(a structure, no range of candidates), what the summary says was chosen, the report's
frequency units, the documentation of the options, hints written in the command line's
own options, the channel names of ``compare``/``simulate`` and MATLAB's ``Ts``."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("click")

from subid.methods.describe import describe_order_selection, describe_structure  # noqa: E402
from test_cli import run  # noqa: E402 (the command line in-process)


def _order_line(out: str) -> str:
    return next(line for line in out.splitlines() if line.startswith("order"))


# -- 1. the order of a polynomial method is a structure, not a range of candidates ------
@pytest.mark.parametrize("method, names", [("arx", "na,nb,nk"), ("armax", "na,nb,nc,nk"),
                                           ("oe", "nb,nf,nk"), ("bj", "nb,nc,nd,nf,nk")])
def test_a_range_of_orders_for_a_polynomial_method_is_an_error_naming_the_structure(
        method, names, tmp_path, capsys):
    code, out, err = run(capsys, "identify", "dataset:dryer", "--method", method,
                         "--order", "2:4", "--out", tmp_path / "o")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1
    assert "no range" in err and f"'{names}'" in err and "'auto'" in err
    assert not (tmp_path / "o").exists()


def test_a_range_still_gives_candidate_orders_to_a_subspace_method(tmp_path, capsys):
    code, out, err = run(capsys, "identify", "dataset:dryer", "--method", "moesp", "--order",
                         "3:4", "--no-report", "--out", tmp_path / "o")
    assert code == 0, err
    assert _order_line(out).split()[1] in ("3", "4")
    assert "over" in _order_line(out) and "given" not in _order_line(out)


def test_the_summary_of_a_polynomial_model_names_its_structure(tmp_path, capsys):
    code, out, err = run(capsys, "identify", "dataset:dryer", "--method", "arx", "--order",
                         "3", "--no-report", "--out", tmp_path / "o")
    assert code == 0, err
    line = _order_line(out)
    assert re.fullmatch(r"order +5 \(na 3, nb 3, nk \d+; given\)", line), line
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert list(summary["structure"]) == ["na", "nb", "nk"]
    assert summary["structure"]["na"] == [[3]] and summary["structure"]["nb"] == [[3]]
    # a MATLAB structure is echoed as given
    code, out, err = run(capsys, "identify", "dataset:dryer", "--method", "oe", "--order",
                         "2,2,1", "--no-report", "--out", tmp_path / "oe")
    assert code == 0, err
    assert "(nb 2, nf 2, nk 1; given)" in _order_line(out)


def test_a_chosen_polynomial_structure_shows_no_horizon_anywhere(tmp_path, capsys):
    code, out, err = run(capsys, "identify", "dataset:dryer", "--method", "arx",
                         "--out", tmp_path / "o")
    assert code == 0, err
    line = _order_line(out)
    assert "None" not in out and "horizon" not in line
    assert "cross-validated on the estimation data: na " in line
    html = (tmp_path / "o" / "report.html").read_text(encoding="utf-8")
    assert ">None<" not in html and "horizon None" not in html
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert describe_structure(summary["structure"]) in line


# -- 2. a given order is said to be given --------------------------------------------
def test_a_given_order_is_given_and_the_summary_says_what_was_cross_validated(tmp_path,
                                                                              capsys):
    code, out, err = run(capsys, "identify", "dataset:dryer", "--method", "moesp", "--order",
                         "4", "--no-report", "--out", tmp_path / "o")
    assert code == 0, err
    line = _order_line(out)
    assert line.startswith("order       4 (given; horizon cross-validated on the "
                           "estimation data: horizon "), line
    record = json.loads((tmp_path / "o" / "model.json").read_text())["info"]["order_selection"]
    assert record["given"] == ["order"]


def test_order_selection_text_omits_what_does_not_apply():
    polynomial = {"rule": "cv", "candidates": [{}, {}],
                  "selected": {"na": 2, "nb": 3, "nk": [1], "score": 80.0}}
    text = describe_order_selection(polynomial)
    assert text == ("cross-validated on the estimation data: na 2, nb 3, nk 1, fit 80.0 % "
                    "over 2 candidates")
    state_space = {"rule": "cv", "given": ["order"],
                   "candidates": [{"order": 4, "horizon": 10}, {"order": 4, "horizon": 20}],
                   "selected": {"order": 4, "horizon": 20, "score": 89.0}}
    assert describe_order_selection(state_space) == (
        "given; horizon cross-validated on the estimation data: horizon 20, fit 89.0 % "
        "over 2 candidates")


# -- 3. the report names one frequency unit: per sample when time is in samples --------
@pytest.mark.parametrize("extra, unit", [((), "rad/sample"),
                                         (("--frequency-unit", "Hz"), "cycles/sample"),
                                         (("--dt", "0.1", "--frequency-unit", "Hz"), "Hz")])
def test_bode_caption_axis_and_pole_table_name_the_same_unit(extra, unit, tmp_path, capsys):
    import subid
    from subid.evaluation.figures._common import frequency_unit
    code, out, err = run(capsys, "identify", "dataset:CD_player_arm", "--method", "moesp",
                         "--order", "4", *extra, "--out", tmp_path / "o")
    assert code == 0, err
    html = (tmp_path / "o" / "report.html").read_text(encoding="utf-8")
    captions = set(re.findall(r"frequency in ([a-zA-Z/]+)", html))
    assert captions == {unit}, captions
    assert f"natural frequency ({unit})" in html
    model = subid.StateSpace.load(tmp_path / "o" / "model.json")
    hz = "Hz" in extra
    assert frequency_unit([model.dt], hz) == unit
    figure = subid.plot.bode(model, hz=hz)
    assert figure.axes[-1].get_xlabel() == f"frequency ({unit})"


# -- 4. docs/cli.md says what the command line does ----------------------------------
def _cli_doc() -> str:
    from pathlib import Path
    return (Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text(encoding="utf-8")


def test_cli_docs_list_every_method_in_the_table_and_in_the_identify_synopsis():
    from subid.cli._shared import METHODS
    from subid.cli.identify import identify
    doc = _cli_doc()
    table = re.findall(r"^\| `(\w+)` \| (?:batch|online) \|", doc, re.M)
    assert table == list(METHODS)
    section = doc.split("## `subid identify DATA`")[1].split("\n## ")[0]
    synopsis = re.search(r"\[--method ([\w|]+)\]", section).group(1).split("|")
    choices = next(p for p in identify.params if p.name == "method_name").type.choices
    assert synopsis == list(choices)


def _named_in(text: str) -> set:
    return set(re.findall(r"`(\w+)`", text))


def test_cli_docs_state_the_detrend_defaults_and_the_methods_taking_several_files():
    from subid.cli._shared import METHODS, _default_detrend
    doc = " ".join(_cli_doc().split())
    defaults = doc.split("The default depends on the method: ")[1].split(";")[0]
    assert defaults.startswith("`none` for ")
    assert _named_in(defaults) - {"none"} == \
        {name for name, spec in METHODS.items() if _default_detrend(spec) == "none"}
    several = doc.split("Every batch method takes several files (")[1].split(")")[0]
    assert _named_in(several) == {name for name, spec in METHODS.items()
                                  if spec.supports("experiments")}
    refusing = doc.split("the online methods (")[1].split(")")[0]
    assert _named_in(refusing) == {name for name, spec in METHODS.items()
                                   if not spec.supports("experiments")}


@pytest.mark.parametrize("method", ["arx", "ct"])
def test_batch_methods_take_several_files_as_experiments(method, tmp_path, capsys):
    import subid
    rng = np.random.default_rng(11)
    paths = []
    for k in range(2):
        u = rng.standard_normal((300, 1))
        y = np.convolve(u[:, 0], [0.0, 0.5, 0.25, 0.125])[:300, None] \
            + 0.01 * rng.standard_normal((300, 1))
        paths.append(tmp_path / f"run{k}.csv")
        np.savetxt(paths[-1], np.hstack([u, y]), delimiter=",", header="u,y", comments="")
    code, out, err = run(capsys, "identify", *paths, "--inputs", "u", "--outputs", "y",
                         "--dt", "0.1", "--method", method, "--order", "2", "--no-report",
                         "--out", tmp_path / "o")
    assert code == 0, err
    model = subid.StateSpace.load(tmp_path / "o" / "model.json")
    assert np.shape(model.info["x0"])[0] == 2          # one initial state per file
    assert model.info["data"]["detrend"] == "constant"


# -- 5. the command line's hints name its own options --------------------------------
def test_convert_names_its_method_option_where_the_library_says_method_bilinear(tmp_path,
                                                                                capsys):
    import subid
    from subid.errors import ModelError
    model = subid.StateSpace([[-0.5]], [[1.0]], [[1.0]], [[0.0]], dt=0.1)
    with pytest.raises(ModelError, match="use method='bilinear' instead"):   # the API's words
        model.to_continuous()
    path = tmp_path / "neg.json"
    model.save(path)
    code, out, err = run(capsys, "convert", path, "--to", "ct")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "use --method bilinear instead" in err and "method='bilinear'" not in err
    code, out, err = run(capsys, "convert", path, "--to", "ct", "--method", "bilinear")
    assert code == 0, err


def test_track_names_detrend_where_the_library_says_data_scaled(tmp_path, capsys):
    import subid
    code, out, err = run(capsys, "track", "dataset:dryer", "--method", "adaptive", "--order",
                         "3", "--no-report", "--out", tmp_path / "t")
    assert code == 0, err
    model = subid.StateSpace.load(tmp_path / "t" / "model.json")
    assert "data.scaled(...)" in model.info["convergence"]          # the API's words
    assert "data.scaled" not in out + err
    assert "remove their offsets with --detrend constant" in err     # the warning
    assert "remove their offsets with --detrend constant" in out     # the converged line


def test_cli_hint_translates_keyword_hints_to_the_commands_flags_and_options():
    from subid.cli._shared import _State, cli_hint
    state = _State()
    state.hint_flags = frozenset({"--horizon", "--method", "--dt", "--time"})
    state.hint_options = ("horizon", "method", "feedthrough")
    assert cli_hint("use method='iv' (the default)", state) == \
        "use --option method=iv (the default)"
    assert cli_hint("give horizon=20 or more", state) == "give --horizon 20 or more"
    assert cli_hint("use feedthrough=True", state) == "use --option feedthrough=true"
    assert cli_hint("pass time='Time [s]'", state) == "pass --time 'Time [s]'"
    assert cli_hint("use stability='none'", state) == "use stability='none'"   # no such
    convert = _State()
    convert.hint_flags = frozenset({"--method", "--to"})
    assert cli_hint("use method='bilinear' instead", convert) == \
        "use --method bilinear instead"


# -- 6. channels named as the model's in another order are refused ----------------------
@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """A 2 x 2 record (stable 4th-order system, 1500 samples, dt 0.05, header t,u1,u2,y1,y2)
    and a moesp model of it with inputs [u1, u2]."""
    import subid
    rng = np.random.default_rng(2)
    poles = [0.95, 0.9, 0.8, 0.6]
    true = subid.StateSpace(np.diag(poles), rng.standard_normal((4, 2)),
                            rng.standard_normal((2, 4)), np.zeros((2, 2)), dt=0.05)
    u = rng.standard_normal((1500, 2))
    y = true.simulate(u) + 0.01 * rng.standard_normal((1500, 2))
    folder = tmp_path_factory.mktemp("plain")
    path = folder / "plain.csv"
    t = 0.05 * np.arange(1500)
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u1,u2,y1,y2",
               comments="", fmt="%.12g")
    np.savetxt(folder / "u.csv", np.column_stack([t, u]), delimiter=",", header="t,u1,u2",
               comments="", fmt="%.12g")
    model = subid.moesp(subid.read(path, inputs=["u1", "u2"], outputs=["y1", "y2"],
                                   time="t"), 4)
    model.save(folder / "model.json")
    return folder


@pytest.mark.parametrize("inputs, outputs, role, fix", [("u2,u1", "y1,y2", "inputs", "u1,u2"),
                                                        ("u1,u2", "y2,y1", "outputs", "y1,y2")])
def test_compare_refuses_the_models_channels_in_another_order(plain, inputs, outputs, role,
                                                              fix, tmp_path, capsys):
    code, out, err = run(capsys, "compare", plain / "model.json", "--data", plain / "plain.csv",
                         "--inputs", inputs, "--outputs", outputs, "--out", tmp_path / "c")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"--{role} {fix}" in err and "another order" in err
    code, out, err = run(capsys, "compare", plain / "model.json", "--data", plain / "plain.csv",
                         "--inputs", "u1,u2", "--outputs", "y1,y2", "--out", tmp_path / "c")
    assert code == 0, err
    assert min(float(v) for v in out.splitlines()[2].split()[1:]) > 90


def test_simulate_refuses_the_models_inputs_in_another_order(plain, tmp_path, capsys):
    code, out, err = run(capsys, "simulate", plain / "model.json", "--input", plain / "u.csv",
                         "--inputs", "u2,u1", "--out", tmp_path / "y.csv")
    assert code == 2 and "give --inputs u1,u2" in err
    assert not (tmp_path / "y.csv").exists()
    code, out, err = run(capsys, "simulate", plain / "model.json", "--input", plain / "u.csv",
                         "--out", tmp_path / "y.csv")
    assert code == 0, err


# -- 7. MATLAB's Ts is the sampling period of a .mat/.npz record -----------------------
def _record(n=400, seed=4):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 1))
    y = np.convolve(u[:, 0], [0.0, 0.6, 0.3, 0.1])[:n, None] + 0.01 * rng.standard_normal((n, 1))
    return u, y


@pytest.mark.parametrize("ext", [".mat", ".npz"])
def test_read_takes_matlabs_ts_as_the_sampling_period(ext, tmp_path):
    import scipy.io

    import subid
    from subid.errors import FileReadError
    u, y = _record()

    def save(name, **extra):
        path = tmp_path / f"{name}{ext}"
        if ext == ".mat":
            scipy.io.savemat(path, {"u": u, "y": y, **extra})
        else:
            np.savez(path, u=u, y=y, **extra)
        return path
    assert subid.read(save("ts", Ts=0.05)).dt == 0.05
    assert subid.read(save("same", Ts=0.05, dt=0.05)).dt == 0.05
    assert subid.read(save("unspecified", Ts=-1.0)).dt == 1.0        # MATLAB's Ts = -1
    assert subid.read(save("ts", Ts=0.05), dt=0.2).dt == 0.2         # the caller's wins
    with pytest.raises(FileReadError, match=r"'dt' = 0.1 and MATLAB's 'Ts' = 0.05"):
        subid.read(save("both", Ts=0.05, dt=0.1))
    t = 0.1 * np.arange(u.shape[0])
    with pytest.raises(FileReadError, match="both 't' and 'Ts'"):
        subid.read(save("stamps", Ts=0.05, t=t))


def test_identify_a_mat_file_with_ts_uses_it(tmp_path, capsys):
    import scipy.io
    u, y = _record()
    scipy.io.savemat(tmp_path / "d.mat", {"u": u, "y": y, "Ts": 0.05})
    code, out, err = run(capsys, "identify", tmp_path / "d.mat", "--method", "moesp", "--order",
                         "3", "--no-report", "--out", tmp_path / "o")
    assert code == 0, err
    assert "dt = 0.05" in out and "No sampling period" not in err
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["dt"] == 0.05
    scipy.io.savemat(tmp_path / "both.mat", {"u": u, "y": y, "Ts": 0.05, "dt": 0.1})
    code, out, err = run(capsys, "identify", tmp_path / "both.mat", "--method", "moesp",
                         "--out", tmp_path / "o2")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "'Ts'" in err


def test_a_pole_on_the_boundary_to_rounding_is_called_marginal():
    """Two files detrended each on its own: the per-file offsets left over made the
    default model absorb them with a pole at 1 - 2e-9, which the summary printed as
    'poles 1, ...' beside 'stable yes'. The stable line now says it is marginal."""
    from subid.cli._shared import _fmt_stable
    assert _fmt_stable({"stable": True, "poles": [1 - 1.9e-9, 0.5]}, False).startswith(
        "yes (marginally: a pole at |z| = 1 - 1.9e-09")
    assert _fmt_stable({"stable": True, "poles": [0.999, 0.5]}, False) == "yes"
    assert _fmt_stable({"stable": False, "poles": [1.01]}, False) == "NO"
    assert _fmt_stable({"stable": True, "poles": [-1e-12, -3.0]}, True).startswith(
        "yes (marginally")
    assert _fmt_stable({"stable": True, "poles": [-0.1 + 2j, -0.1 - 2j]}, True) == "yes"


def test_a_diverging_fit_prints_short_and_draws_without_numpy_warnings():
    """An unstable online model on a record: its fit of -3.6e147 % was printed with 150
    digits, and drawing its simulated trace overflowed a float32 cast (numpy's warning,
    twice, on the command line)."""
    import warnings

    import matplotlib
    matplotlib.use("Agg")
    import subid
    from subid.cli._shared import _fmt_fit
    assert _fmt_fit([-3.649e147, 89.456]) == "-3.65e+147 / 89.46"
    from subid.evaluation.report import identification_report
    unstable = subid.StateSpace([[1.05]], [[1.0]], [[1.0]], [[0.0]], 1.0)
    rng = np.random.default_rng(0)
    data = subid.IOData(rng.standard_normal(3000), rng.standard_normal(3000), dt=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        identification_report({"online": unstable}, data)
