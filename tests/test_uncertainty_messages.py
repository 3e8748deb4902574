"""Messages of parameter_covariance when a model carries no usable covariance: they say
why and what to do (they contradicted themselves or named only the symptom)."""

import warnings

import numpy as np
import pytest

import subid
from subid.errors import ModelError


@pytest.fixture(scope="module")
def refined():
    A = np.array([[1.5, -0.7], [1.0, 0.0]])
    true = subid.StateSpace(A, [[1.0], [0.0]], [[1.0, 0.5]], [[0.0]], 1.0)
    data = subid.systems.simulate_data(true, 600, seed=1, output_snr_db=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return subid.pem(data, subid.n4sid(data, 2))


def test_a_model_identify_left_without_covariance_gives_identifys_reason(refined):
    reason = ("the data show feedback: the subspace estimate is biased in closed loop and "
              "bounds around it would not hold the plant; refine it with subid.pem(data, "
              "model) (consistent in closed loop) for bounds")
    info = {"method": "identify", "identify": {"covariance": {
        "at": "the subspace model", "computed": False, "reason": reason}}}
    model = subid.StateSpace(refined.A, refined.B, refined.C, refined.D, 1.0, info=info)
    with pytest.raises(ModelError) as err:
        subid.parameter_covariance(model)
    text = str(err.value)
    assert "feedback" in text and "subid.pem(data, model)" in text
    assert "identify it with subid.identify" not in text
    other = dict(info, identify={"covariance": {"computed": False,
                                                "reason": "the Jacobian is rank deficient"}})
    model = subid.StateSpace(refined.A, refined.B, refined.C, refined.D, 1.0, info=other)
    with pytest.raises(ModelError, match="rank deficient; refine it with subid.pem"):
        subid.parameter_covariance(model)


def test_a_model_whose_gain_was_removed_says_why_and_to_refit(refined):
    assert refined.K is not None
    subid.parameter_covariance(refined)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bare = refined.with_noise_model(None, None)
    with pytest.raises(ModelError,
                       match=r"with_noise_model\(\) replaced the Kalman gain.*subid\.pem"):
        subid.parameter_covariance(bare)


def test_a_model_with_absorbed_delays_keeps_its_bounds(refined):
    # absorb_delay maps the covariance to the shift-register model (it was dropped, with a
    # message saying to refit): the same bands as the delayed model's
    delayed = subid.StateSpace(refined.A, refined.B, refined.C, refined.D, 1.0,
                               K=refined.K, noise_cov=refined.noise_cov,
                               info=dict(refined.info, input_delay=[3]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        absorbed = subid.absorb_delay(delayed)
    assert absorbed.order == refined.order + 3
    w = np.linspace(0.1, 3.0, 4)
    np.testing.assert_allclose(subid.freqresp_bounds(absorbed, w).std,
                               subid.freqresp_bounds(delayed, w).std, rtol=1e-9)


def test_step_bounds_of_a_huge_final_time_name_the_memory(refined):
    from subid.errors import ResourceLimitError
    with pytest.raises(ResourceLimitError, match="GiB"):
        subid.step_bounds(refined, 1e9)
