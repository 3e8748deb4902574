"""spa and etfe are scale invariant: at 1e200 they returned NaN responses (refused as
"FRData: response has 128 NaN values"), at 1e-300 "input spectrum singular"."""

import numpy as np
import pytest

import subid


@pytest.fixture(scope="module")
def record():
    system = subid.systems.random_system(2, 1, 1, seed=1)
    return subid.systems.simulate_data(system, 400, seed=2, output_snr_db=30)


@pytest.mark.parametrize("scale", [1e200, 1e-300, (1e3, 1e-2)])
@pytest.mark.parametrize("estimate", [lambda d: subid.spa(d), lambda d: subid.etfe(d, 4),
                                      lambda d: subid.etfe(d)], ids=["spa", "etfe4", "etfe"])
def test_responses_in_other_units_are_the_same_scaled(record, scale, estimate):
    su, sy = scale if isinstance(scale, tuple) else (scale, scale)
    reference = estimate(record)
    other = estimate(subid.IOData(record.u * su, record.y * sy, dt=1.0))
    assert np.allclose(other.response * su / sy, reference.response, rtol=1e-10, atol=0)
    if reference.std is not None:
        assert np.allclose(other.std * su / sy, reference.std, rtol=1e-9, atol=0)
        assert np.allclose(other.coherence, reference.coherence, rtol=1e-9, atol=1e-12)
