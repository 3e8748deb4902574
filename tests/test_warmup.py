"""subid.warmup: fills numba's cache for the common calls (issue 14 item 5)."""

import pytest

from subid.errors import SubidError
from subid.warmup import main, warmup


def test_warmup_runs_the_adaptive_group_and_reports_seconds():
    out = warmup(["adaptive"])
    assert list(out) == ["adaptive"]
    assert out["adaptive"] >= 0.0


def test_warmup_rejects_unknown_groups():
    with pytest.raises(SubidError, match="unknown warm-up group"):
        warmup(["adaptive", "gpu"])


def test_warmup_command_line(capsys):
    assert main(["--only", "adaptive"]) == 0
    assert capsys.readouterr().out.startswith("adaptive")
    with pytest.raises(SystemExit):
        main(["--only", "nonsense"])


@pytest.mark.slow
def test_warmup_compiles_every_kernel_of_the_default_calls():
    """After ``warmup(['batch'])`` the default calls on a noisy record (the order search,
    its scored solves, identify's PEM refinement) compile nothing more: a fresh process,
    so that no other test has compiled them."""
    import subprocess
    import sys
    code = """
import sys, warnings
import numba
from subid.warmup import kernels_cached, warmup
warmup(['batch'])
assert kernels_cached()              # what warm-up filled, the command line finds

def compiled():
    out = {}
    for name, mod in list(sys.modules.items()):
        if name.startswith('subid'):
            for key, value in list(vars(mod).items()):
                if isinstance(value, numba.core.registry.CPUDispatcher):
                    out[value.__module__ + '.' + key] = len(value.signatures)
    return out

before = compiled()
import subid
from subid.systems import seed001_system, simulate_data
data = simulate_data(seed001_system(), 3000, seed=1, output_snr_db=20)
with warnings.catch_warnings():
    warnings.simplefilter('ignore')
    subid.identify(data); subid.moesp(data); subid.n4sid(data); subid.ls_subspace(data)
after = compiled()
print(sorted(k for k, v in after.items() if v > before.get(k, 0)))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=600)
    assert out.stdout.strip() == "[]", out.stdout


def test_kernels_cached_is_false_on_an_empty_cache(tmp_path):
    """A fresh process whose numba cache is empty: the default calls' kernels would
    compile on first use, which the command line announces."""
    import os
    import subprocess
    import sys
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c",
                          "from subid.warmup import kernels_cached; print(kernels_cached())"],
                         capture_output=True, text=True, check=True, timeout=300, env=env)
    assert out.stdout.strip() == "False"


def test_the_command_line_announces_a_first_run(tmp_path, monkeypatch, capsys):
    import numpy as np

    import subid
    import subid.cli._shared as shared
    import subid.warmup as warm
    from subid.cli import main
    data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=1)
    path = tmp_path / "r.csv"
    np.savetxt(path, np.hstack([data.u, data.y]), delimiter=",", header="u1,u2,y1,y2",
               comments="")
    args = ["identify", str(path), "--inputs", "u1,u2", "--outputs", "y1,y2", "--order",
            "3", "--no-report", "--out", str(tmp_path / "out")]
    monkeypatch.setattr(shared, "on_terminal", lambda quiet=False: not quiet)  # a terminal
    monkeypatch.setattr(warm, "kernels_cached", lambda: False)
    assert main(args) == 0
    assert "first run: compiling the numerical kernels" in capsys.readouterr().err
    monkeypatch.setattr(warm, "kernels_cached", lambda: True)
    assert main(args) == 0
    assert "first run" not in capsys.readouterr().err
    monkeypatch.setattr(warm, "kernels_cached", lambda: False)
    assert main(["--quiet", *args]) == 0                     # --quiet: nothing
    assert "first run" not in capsys.readouterr().err
