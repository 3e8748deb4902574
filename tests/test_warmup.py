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
from subid.warmup import warmup
warmup(['batch'])

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
