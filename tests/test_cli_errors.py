"""Every kind of command-line user error exits 2 with one line and no traceback."""

import pytest

from subid.cli.commands import main


def run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _one_line_error(code, stdout, stderr):
    assert code == 2, stderr
    assert stdout == ""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("subid: error: ") and "Traceback" not in stderr
    return lines[0]


@pytest.mark.parametrize("extra, message", [
    (["--option", "nope=1"], "method ls has no option 'nope'"),
    (["--option", "seed=1", "--option", "seed=2"], "seed given twice"),
    (["--option", "order=3"], "order is set by its own command-line option (--order)"),
    (["--horizon", "6", "--option", "horizon=5"], "horizon is set by its own"),
    (["--option", "instruments"], "'instruments': use KEY=VALUE"),
    (["--option", "=3"], "KEY must be an option name"),
    (["--option", "horizon=abc"], "horizon must be an integer, got 'abc'"),
    (["--option", "instruments=maybe"], "instruments must be 'past' or None"),
    (["--option", "stability=maybe"], "stability must be one of ('auto', 'enforce', 'none')"),
    (["--option", "feedthrough=yes"], "feedthrough must be one of 'auto', True, False; got 'yes'"),
    (["--option", "estimate_x0=3"], "estimate_x0 must be True or False; got 3"),
    (["--option", "selection=[1]"], "selection must be one of"),
    (["--option", "bd_method=guess"], "bd_method must be one of"),
    (["--option", "power_iterations=-1"], "power_iterations must be an integer from 0 to 100"),
    (["--frobnicate"], "No such option '--frobnicate'"),
    (["--order", "x"], "use an integer, 'auto'"),
])
def test_identify_user_errors(capsys, tmp_path, extra, message):
    line = _one_line_error(*run(capsys, "identify", "dataset:dryer", "--method", "ls",
                                "--order", "2", "--no-report", "--out", tmp_path / "o",
                                *extra))
    assert message in line
    assert not (tmp_path / "o").exists()


def test_track_unknown_option_names_the_options(capsys, tmp_path):
    line = _one_line_error(*run(capsys, "track", "dataset:dryer", "--method", "recursive",
                                "--order", "2", "--out", tmp_path / "o", "--option",
                                "bogus=1"))
    assert "method recursive has no option 'bogus'" in line and "forgetting" in line
    line = _one_line_error(*run(capsys, "track", "dataset:dryer", "--method", "recursive",
                                "--order", "2", "--out", tmp_path / "p", "--option",
                                "n_inputs=3"))
    assert "n_inputs is set by its own" in line


def test_unknown_command_and_missing_argument(capsys):
    line = _one_line_error(*run(capsys, "frobnicate"))
    assert "No such command 'frobnicate'" in line and "subid --help" in line
    line = _one_line_error(*run(capsys, "identify"))
    assert "Missing argument 'DATA'" in line and "subid identify --help" in line


def test_option_accepted_by_the_method_still_works(capsys, tmp_path):
    code, stdout, stderr = run(capsys, "identify", "dataset:dryer", "--method", "ls",
                               "--order", "2", "--no-report", "--quiet", "--out",
                               tmp_path / "o", "--option", "instruments=null",
                               "--option", "horizon=6")
    assert code == 0, stderr


@pytest.mark.parametrize("method, option, message", [
    ("ct", "hold=cubic", "hold must be one of 'foh', 'zoh', None; got 'cubic'"),
    ("ct", "bd_method=guess", "bd_method must be one of 'simulation', 'filtered'"),
    ("ct", "refine=maybe", "refine must be one of 'auto', True, False"),
    ("moesp", "weighting=7", "weighting must be one of"),
    ("n4sid", "refine=newton", "refine must be None, 'simulation' or 'prediction'"),
])
def test_bad_option_values_exit_2_with_one_line(capsys, tmp_path, method, option, message):
    """OptionError (a bad option value) is a user error like the others."""
    line = _one_line_error(*run(capsys, "identify", "dataset:dryer", "--method", method,
                                "--order", "2", "--no-report", "--out", tmp_path / "o",
                                "--option", option))
    assert message in line
    assert not (tmp_path / "o").exists()


def test_bad_online_option_value_exits_2(capsys, tmp_path):
    line = _one_line_error(*run(capsys, "track", "dataset:dryer", "--method", "recursive",
                                "--order", "2", "--out", tmp_path / "o", "--option",
                                "bd_method=guess"))
    assert "bd_method" in line


def test_channels_given_space_separated_are_named_as_such(capsys, tmp_path):
    """``--inputs u1 u2`` makes click read ``u2`` as a second DATA file: the error says
    that it is not a file and shows the comma-separated form, before anything is read."""
    import numpy as np
    path = tmp_path / "plant.csv"
    rng = np.random.default_rng(0)
    np.savetxt(path, rng.standard_normal((50, 4)), delimiter=",", header="u1,u2,y1,y2",
               comments="")
    line = _one_line_error(*run(capsys, "identify", path, "--inputs", "u1", "u2",
                                "--outputs", "y1", "y2", "--out", tmp_path / "o"))
    assert "'u2', 'y2' are not files" in line and "--inputs u1,u2" in line
    assert "read here: --inputs u1 --outputs y1" in line
    assert not (tmp_path / "o").exists()
    # a missing file with an extension keeps the reader's own message
    line = _one_line_error(*run(capsys, "identify", tmp_path / "none.csv", "--inputs", "u1",
                                "--outputs", "y1", "--out", tmp_path / "p"))
    assert "no such file" in line


def test_decimal_commas_on_the_command_line(capsys, tmp_path):
    """A ';'-delimited export with decimal commas: the error names --decimal, and with
    it the record is identified; --decimal with --stream is refused in one line."""
    import numpy as np
    rng = np.random.default_rng(1)
    u = rng.standard_normal(300)
    y = np.convolve(u, [0.0, 0.5, 0.3])[:300] + 0.01 * rng.standard_normal(300)
    path = tmp_path / "export.csv"
    path.write_text("u;y\n" + "".join(f"{a:.6f};{b:.6f}\n".replace(".", ",")
                                      for a, b in zip(u, y)))
    line = _one_line_error(*run(capsys, "identify", path, "--inputs", "u", "--outputs", "y",
                                "--method", "arx", "--out", tmp_path / "o"))
    assert "--decimal ," in line
    code, out, err = run(capsys, "identify", path, "--inputs", "u", "--outputs", "y",
                         "--decimal", ",", "--method", "arx", "--no-report",
                         "--out", tmp_path / "p")
    assert code == 0, err
    assert "300 samples" in out
    line = _one_line_error(*run(capsys, "identify", path, "--inputs", "u", "--outputs", "y",
                                "--decimal", ",", "--stream", "--dt", "1",
                                "--out", tmp_path / "q"))
    assert "--decimal , reads records in memory" in line
