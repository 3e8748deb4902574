"""subid.systems checks its arguments with subid errors (numpy's ValueError,
AttributeError, TypeError, LinAlgError before, or bad values accepted)."""

import numpy as np
import pytest

import subid
from subid.errors import ModelError, OptionError

S = subid.systems


@pytest.mark.parametrize("call", [
    lambda: S.random_system(2, 1, 1, seed=0, pole_radius=(0.9, 0.2)),
    lambda: S.random_system(2, 1, 1, seed=0, pole_radius="x"),
    lambda: S.random_system(2, 1, 1, seed=0, pole_radius=(0.5, 1.5)),
    lambda: S.random_system(2, 1, 1, seed=0, pole_radius=(-0.5, 0.5)),
    lambda: S.random_system(2, 1, 1, seed=0, pole_radius=(0.2, np.nan)),
    lambda: S.random_system(2, 1, 1, seed=0, feedthrough="no"),
    lambda: S.random_system(2, 1, 1, seed=0, min_hsv_ratio=-1),
    lambda: S.simulate_data(S.random_system(2, 1, 1, seed=0), 100, seed=0, output_snr_db="x"),
    lambda: S.simulate_data(S.random_system(2, 1, 1, seed=0), 100, seed=0, process_snr_db=np.inf),
    lambda: S.simulate_data(S.random_system(2, 1, 1, seed=0), 100, seed=0, input_std=-1),
    lambda: S.simulate_data(S.random_system(2, 1, 1, seed=0), 100, seed=0, input_std=0),
    lambda: S.simulate_innovation_data(S.seed001_innovation_system(), 100, seed=0,
                                       noise_cov=-np.eye(2)),
    lambda: S.simulate_innovation_data(S.seed001_innovation_system(), 100, seed=0,
                                       noise_cov=np.eye(3)),
    lambda: S.simulate_innovation_data(S.seed001_innovation_system(), 100, seed=0,
                                       noise_cov=[[1.0, 0.5], [0.0, 1.0]]),
    lambda: S.simulate_innovation_data(S.seed001_innovation_system(feedthrough=False), 100,
                                       seed=0, feedback=np.eye(3)),
    lambda: S.simulate_innovation_data(S.seed001_innovation_system(), 100, seed=0,
                                       input_std=0),
    lambda: S.seed001_innovation_system(measurement_std=np.nan),
    lambda: S.seed001_innovation_system(measurement_std=0),
    lambda: S.seed001_innovation_system(process_std=-1),
    lambda: S.seed001_innovation_system(feedthrough="no"),
])
def test_bad_options_are_option_errors(call):
    with pytest.raises(OptionError):
        call()


@pytest.mark.parametrize("call", [lambda: S.simulate_data("s", 100, seed=0),
                                  lambda: S.simulate_innovation_data("s", 100, seed=0)])
def test_a_system_that_is_not_a_model_is_a_model_error(call):
    with pytest.raises(ModelError, match="subid.StateSpace"):
        call()


def test_valid_calls_draw_what_they_drew():
    # the checks do not change the draws (the seeds of the docs and tests)
    system = S.random_system(2, 1, 1, seed=0, pole_radius=[0.5, 0.5])
    assert np.allclose(np.abs(system.poles()), 0.5)
    closed = S.simulate_innovation_data(S.seed001_innovation_system(feedthrough=False), 5,
                                        seed=0, feedback=0.1 * np.eye(2))
    assert closed.y.shape == (5, 2)
    data = S.simulate_data(S.random_system(2, 1, 1, seed=0), 3, seed=0, output_snr_db=20)
    rng = np.random.default_rng(0)
    assert np.allclose(data.u[:, 0], rng.standard_normal(3))
