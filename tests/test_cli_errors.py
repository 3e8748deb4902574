"""Every kind of command-line user error exits 2 with one line and no traceback."""

import pytest

from subid.cli import main


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
