"""``subid.identify`` on frequency-response data: fd_subspace, then pem on the response."""

import numpy as np
import pytest
import scipy.linalg

import subid
from subid.errors import OptionError

W_CT = np.logspace(-2, 2, 200)


def _structure():
    """A lightly damped 2x2 structure: four modes at 3, 7.5, 21 and 40 Hz, damping
    0.005, 0.01, 0.002, 0.02, displacement outputs (continuous time)."""
    rng = np.random.default_rng(5)
    hz, zeta = [3.0, 7.5, 21.0, 40.0], [0.005, 0.01, 0.002, 0.02]
    blocks, B, C = [], np.zeros((8, 2)), np.zeros((2, 8))
    for i, (f, z) in enumerate(zip(hz, zeta)):
        wn = 2 * np.pi * f
        blocks.append(np.array([[0.0, 1.0], [-wn ** 2, -2 * z * wn]]))
        B[2 * i + 1] = rng.normal(size=2)
        C[:, 2 * i] = rng.normal(size=2) * wn ** 2
    return subid.StateSpace(scipy.linalg.block_diag(*blocks), B, C, np.zeros((2, 2)), 0.0)


def _true_fit(model, system, w):
    return float(np.mean(subid.fit_percent(model, subid.FRData(w, system.freqresp(w)))))


def test_identify_refines_the_frequency_domain_subspace_model():
    # 1 % noise proportional to |G| (a spectral estimate's): the noise weighting that
    # suits the likelihood leaves a poor subspace model on this structure (seed 1: 23.5 %
    # of the true response), and pem's weighted least squares repairs it (99.3 %)
    system = _structure()
    w = 2 * np.pi * np.logspace(0, 2, 400)
    G0 = system.freqresp(w)
    rng = np.random.default_rng(1)
    data = subid.FRData(w, G0 * (1 + 0.01 * (rng.standard_normal(G0.shape)
                                             + 1j * rng.standard_normal(G0.shape)) / np.sqrt(2)))
    start = subid.fd_subspace(data)
    model = subid.identify(data)
    assert _true_fit(start, system, w) < 50
    assert _true_fit(model, system, w) > 99
    assert model.dt == 0 and model.order == start.order
    record = model.info["identify"]
    assert model.info["method"] == "identify" and record["estimator"] == "fd_subspace"
    assert record["time_base"] == "continuous" and record["refinement"]["kept"]
    assert record["refinement"]["final_cost"] < record["refinement"]["start_cost"]
    # refine=False: the subspace model itself
    plain = subid.identify(data, refine=False)
    np.testing.assert_allclose(plain.freqresp(w), start.freqresp(w), rtol=0,
                               atol=1e-12 * np.abs(G0).max())
    assert plain.info["identify"]["refinement"] == {"kept": False, "reason": "refine=False"}


@pytest.mark.parametrize("dt", [0.0, 1.0])
def test_identify_on_frequency_data_is_exact_noise_free(dt):
    system = subid.systems.seed000_system() if dt == 0 else subid.systems.seed001_system()
    w = W_CT if dt == 0 else np.linspace(0, np.pi, 202)[1:-1]
    G = system.freqresp(w)
    model = subid.identify(subid.FRData(w, G, dt))
    assert model.dt == dt and model.order == system.order
    assert np.abs(model.freqresp(w) - G).max() < 1e-8 * np.abs(G).max()
    assert model.info["identify"]["time_base"] == ("continuous" if dt == 0 else "discrete")


def test_identify_refuses_options_a_frequency_response_cannot_honour():
    data = subid.FRData(W_CT, subid.systems.seed000_system().freqresp(W_CT))
    with pytest.raises(OptionError, match="no noise model"):
        subid.identify(data, focus="prediction")
    with pytest.raises(OptionError, match="no input hold"):
        subid.identify(data, hold="zoh")
    with pytest.raises(OptionError, match="continuous-time"):
        subid.identify(data, time_base="dt")
    with pytest.raises(OptionError, match="feedthrough"):
        subid.identify(data, feedthrough="yes")
    # the options it can honour reach fd_subspace
    model = subid.identify(data, 4, feedthrough=False, horizon=6, refine=False)
    assert model.info["horizon"] == 6 and not np.any(model.D)
    assert model.info["identify"]["options"] == {"horizon": 6, "feedthrough": False}
