"""Command line of issue 11: identify --refine pem, compare --steps K, K in the report."""

from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("click")

import subid  # noqa: E402
from subid.cli.commands import main  # noqa: E402
from test_cli import run  # noqa: E402 (the command line in-process)


@pytest.fixture(scope="module")
def refined_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("pem")
    code = main(["--quiet", "identify", "dataset:dryer", "--method", "n4sid", "--order", "3",
                 "--refine", "pem", "--out", str(out)])
    assert code == 0
    return out


@pytest.mark.slow
def test_identify_refine_pem_writes_a_refined_model(refined_dir):
    model = subid.StateSpace.load(refined_dir / "model.json")
    assert model.info["refined_by"] == "pem" and model.K is not None
    assert model.info["final_cost"] <= model.info["start_cost"]
    html = (refined_dir / "report.html").read_text(encoding="utf-8")
    assert "Kalman gain" in html and "noise covariance" in html and "idss(" in html
    assert "one-step prediction errors" in html
    # the report says how the noise covariance was found
    assert f"e; {model.info['noise_cov_estimate']}" in html.replace("&#x27;", "'")


def test_identify_summary_shows_refinement_and_noise_covariance(capsys, tmp_path):
    code, out, _ = run(capsys, "identify", "dataset:dryer", "--method", "ls", "--order", "3",
                       "--refine", "pem", "--no-report", "--out", tmp_path)
    assert code == 0
    assert re.search(r"refined\s+pem \(prediction focus\): cost", out)
    assert re.search(r"noise cov\s+[\d.e-]+ \(innovations", out)


def test_compare_steps(capsys, refined_dir):
    model = str(refined_dir / "model.json")
    code, out1, _ = run(capsys, "compare", model, "--data", "dataset:dryer", "--steps", "1",
                        "--out", refined_dir / "c1")
    assert code == 0 and "1-step predicted" in out1
    code, out_sim, _ = run(capsys, "compare", model, "--data", "dataset:dryer",
                           "--out", refined_dir / "c2")
    assert code == 0 and "simulated" in out_sim
    fit1 = float(out1.strip().splitlines()[-2].split()[-1])
    fit_sim = float(out_sim.strip().splitlines()[-2].split()[-1])
    assert fit1 > fit_sim
    page = (refined_dir / "c1" / "compare.html").read_text(encoding="utf-8")
    assert "1-step predicted" in page


def test_compare_steps_bad_value(capsys, refined_dir):
    code, _, err = run(capsys, "compare", str(refined_dir / "model.json"), "--data",
                       "dataset:dryer", "--steps", "0")
    assert code == 2 and "--steps" in err


def test_refine_with_stream_is_refused(capsys, tmp_path):
    d = subid.datasets.load("dryer")
    path = tmp_path / "d.csv"
    np.savetxt(path, np.column_stack([d.u, d.y]), delimiter=",", header="u,y", comments="")
    code, _, err = run(capsys, "identify", path, "--inputs", "u", "--outputs", "y", "--stream",
                       "--refine", "pem", "--out", tmp_path / "o")
    assert code == 2 and "--refine" in err


def test_summary_says_when_the_noise_covariance_had_no_samples(capsys, tmp_path):
    """In memory the covariance of the model's own prediction errors; streamed (a
    statistic, no samples kept) the Riccati covariance, and the summary says so."""
    d = subid.datasets.load("dryer")
    path = tmp_path / "d.csv"
    np.savetxt(path, np.column_stack([d.u, d.y]), delimiter=",", header="u,y", comments="")
    code, streamed, _ = run(capsys, "identify", path, "--inputs", "u", "--outputs", "y",
                            "--dt", "0.08", "--stream", "--no-report", "--out", tmp_path / "s")
    assert code == 0
    assert re.search(r"noise cov\s+[\d.e-]+ \(innovations, with Kalman gain K; from the "
                     r"Riccati equation, no samples at hand\)", streamed)
    code, memory, _ = run(capsys, "identify", path, "--inputs", "u", "--outputs", "y",
                          "--dt", "0.08", "--no-report", "--out", tmp_path / "m")
    assert code == 0
    assert re.search(r"noise cov\s+[\d.e-]+ \(innovations, with Kalman gain K\)", memory)
