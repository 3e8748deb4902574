"""A record whose channels are the model's in another order is refused (it passed
fit_percent, predict and residuals silently: fit -16 % instead of 97 %)."""

import warnings

import matplotlib
import numpy as np
import pytest

import subid
from subid.errors import DataError

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def case():
    true = subid.systems.random_system(3, 2, 2, seed=0)
    data = subid.systems.simulate_data(true, 400, seed=1, output_snr_db=30)
    model = subid.StateSpace(true.A, true.B, true.C, true.D, 1.0, K=np.zeros((3, 2)),
                             noise_cov=np.eye(2))
    return model, data


@pytest.mark.parametrize("swap", ["inputs", "outputs", "both"])
def test_channels_in_another_order_are_refused(case, swap):
    model, data = case
    u, y = data.u, data.y
    names_u, names_y = ["u1", "u2"], ["y1", "y2"]
    if swap in ("inputs", "both"):
        u, names_u = u[:, ::-1], names_u[::-1]
    if swap in ("outputs", "both"):
        y, names_y = y[:, ::-1], names_y[::-1]
    record = subid.IOData(u, y, dt=1.0, input_names=names_u, output_names=names_y)
    calls = [lambda: subid.fit_percent(model, record),
             lambda: subid.fit_percent(model, record, steps=1),
             lambda: subid.predict(model, record, steps=1),
             lambda: subid.residuals(model, record),
             lambda: subid.plot.compare(record, model)]
    for call in calls:
        with pytest.raises(DataError, match="in a different order.*matched by position"):
            call()


def test_the_model_order_and_other_names_pass(case):
    model, data = case
    assert np.all(subid.fit_percent(model, data) > 90)
    other = subid.IOData(data.u, data.y, dt=1.0, input_names=["a", "b"],
                         output_names=["c", "d"])
    assert np.all(subid.fit_percent(model, other) > 90)
    named = subid.StateSpace(model.A, model.B, model.C, model.D, 1.0,
                             input_names=["a", "b"], output_names=["c", "d"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert np.all(subid.fit_percent(named, other) > 90)
        with pytest.raises(DataError, match="outputs d, c are the model's"):
            subid.fit_percent(named, subid.IOData(data.u, data.y[:, ::-1], dt=1.0,
                                                  input_names=["a", "b"],
                                                  output_names=["d", "c"]))
