"""The figures' arguments are checked at the boundary with subid errors (they gave
AttributeError, numpy's or matplotlib's errors, all-NaN results, or drew without
complaint), and bands missing for some models are reported."""

import warnings

import matplotlib
import numpy as np
import pytest

import subid
from subid import plot
from subid.errors import DataError, ModelError, OptionError, OrderError

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def case():
    A = np.array([[1.5, -0.7], [1.0, 0.0]])
    true = subid.StateSpace(A, [[1.0], [0.0]], [[1.0, 0.5]], [[0.0]], 1.0)
    data = subid.systems.simulate_data(true, 400, seed=2, output_snr_db=30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = subid.n4sid(data, 2)
        refined = subid.pem(data, model)
    return data, model, refined


@pytest.mark.parametrize("steps", [0, -1, 2.5, "1"])
def test_predicted_output_and_compare_refuse_steps_predict_refuses(case, steps):
    data, model, _ = case
    with pytest.raises(DataError, match="steps must be a positive integer"):
        plot.predicted_output(model, data, steps)
    with pytest.raises(DataError, match="steps must be a positive integer"):
        plot.compare(data, model, steps=steps)
    plot.compare(data, model, steps=3)


def test_compare_refuses_simulated_outputs_it_would_ignore(case):
    data, model, _ = case
    with pytest.raises(DataError, match="must be a dict"):
        plot.compare(data, model, simulated=np.ones((3, 3)))
    with pytest.raises(DataError, match="has shape"):
        plot.compare(data, {"m": model}, simulated={"m": np.ones((3, 3))})
    with pytest.raises(DataError, match="not one of the models"):
        plot.compare(data, {"m": model}, simulated={"x": np.ones(data.y.shape)})
    plot.compare(data, {"m": model}, simulated={"m": model.simulate(data.u)})


def test_bode_overlays_frequency_data_of_another_time_base(case):
    """A Bode diagram is drawn in rad/s, so a continuous-time model (or one of another
    sampling period) is overlaid on measured responses as MATLAB's bode does; the report
    draws its continuous-time models over the record's spa estimate so."""
    _, model, _ = case
    w = np.linspace(0.1, 3, 20)
    measured = subid.FRData(w, model.freqresp(w), dt=1.0)
    other = subid.StateSpace(model.A, model.B, model.C, model.D, 2.0)
    continuous = subid.StateSpace([[-1.0]], [[1.0]], [[1.0]], [[0.0]], 0.0)
    for m in (other, continuous, model):
        plot.bode(m, data=measured)


@pytest.mark.parametrize("call, error", [
    (lambda m, d: plot.bode("m"), ModelError),
    (lambda m, d: plot.step("m"), ModelError),
    (lambda m, d: plot.residuals("m", d), ModelError),
    (lambda m, d: plot.frequency_grid("m"), ModelError),
    (lambda m, d: plot.order_selection("m"), ModelError),
    (lambda m, d: plot.order_scores("m"), ModelError),
    (lambda m, d: plot.poles("m"), ModelError),
    (lambda m, d: plot.poles(None), ModelError),
    (lambda m, d: plot.poles([m], "r"), ModelError),
    (lambda m, d: plot.bode(m, w=[]), DataError),
    (lambda m, d: plot.bode(m, w="w"), DataError),
    (lambda m, d: plot.error_histograms({"a": [np.nan, 1.0]}), DataError),
    (lambda m, d: plot.error_histograms({"a": []}), DataError),
    (lambda m, d: plot.error_histograms([1, 2]), DataError),
    (lambda m, d: plot.error_histograms({"a": [1.0, 2.0]}, bins=0), OptionError),
    (lambda m, d: plot.frequency_grid([m], -5), OrderError),
    (lambda m, d: plot.frequency_grid([m], 0), OrderError),
    (lambda m, d: plot.data_overview(d, split="x"), OptionError),
    (lambda m, d: plot.data_overview(d, split=-0.5), OptionError),
    (lambda m, d: plot.data_overview(d, split=1e6), OptionError),
    (lambda m, d: plot.colors_for(3), OptionError),
    (lambda m, d: plot.colors_for([1, 2]), OptionError),
    (lambda m, d: plot.is_unstable("m"), ModelError),
])
def test_bad_arguments_raise_subid_errors(case, call, error):
    data, model, _ = case
    with pytest.raises(error):
        call(model, data)


def test_good_arguments_still_draw(case):
    data, model, _ = case
    plot.data_overview(data, split=280.0)
    assert plot.colors_for([("a", model), ("b", None)])[0]
    assert not plot.is_unstable(model)
    assert plot.frequency_grid([model], 50).shape == (50,)
    plot.error_histograms({"a": [0.1, 0.2], "b": [1.0, 3.0]}, bins=5)


def test_bode_and_step_name_the_models_drawn_without_a_band(case):
    _, model, refined = case
    for draw in (plot.bode, plot.step):
        with pytest.warns(UserWarning, match="no confidence band for 'n4sid'") as record:
            draw({"pem": refined, "n4sid": model}, confidence=0.95)
        assert "'pem'" not in str(record[0].message)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            draw({"pem": refined}, confidence=0.95)
