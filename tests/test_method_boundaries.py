"""The boundary checks of the identification methods, the Hankel statistic and the
online identifiers (session 22): magnitudes whose squares underflow, option types,
resource limits, and errors that name the function and option the user gave."""

import time

import numpy as np
import pytest

import subid
from subid import errors
from subid.methods.online.adaptive import AdaptiveIdentifier
from subid.methods.online.recursive import RecursiveSubspace

IO = subid.IOData


@pytest.fixture(scope="module")
def d():
    return subid.systems.simulate_data(subid.systems.random_system(2, 1, 1, seed=1), 400,
                                       seed=2, output_snr_db=30)


@pytest.fixture(scope="module")
def dryer():
    return subid.datasets.load("dryer").detrend()


# -- 1. channels whose squares underflow ----------------------------------------------

TINY_CALLS = {
    "moesp y*1e-300": lambda d: subid.moesp(IO(d.u, d.y * 1e-300), 2),
    "ls_subspace 1e-160": lambda d: subid.ls_subspace(IO(d.u * 1e-160, d.y * 1e-160), 2),
    "n4sid u*1e-160": lambda d: subid.n4sid(IO(d.u * 1e-160, d.y), 2),
    "pbsid y*1e-200": lambda d: subid.pbsid(IO(d.u, d.y * 1e-200), 2),
    "identify 1e-160": lambda d: subid.identify(IO(d.u * 1e-160, d.y * 1e-160), 2),
    "pem 1e-160": lambda d: subid.pem(IO(d.u * 1e-160, d.y * 1e-160), subid.n4sid(d, 2)),
    "arx y*1e-200": lambda d: subid.arx(IO(d.u, d.y * 1e-200), (2, 2, 1)),
    "oe u*1e-200": lambda d: subid.oe(IO(d.u * 1e-200, d.y), (2, 2, 1)),
    "ct_subspace y*1e-200": lambda d: subid.ct_subspace(IO(d.u, d.y * 1e-200), 2),
    "impulseest 1e-160": lambda d: subid.impulseest(IO(d.u * 1e-160, d.y * 1e-160), 20),
    "HankelStatistic 1e-160": lambda d: subid.HankelStatistic.from_data(
        IO(d.u * 1e-160, d.y), 10),
}


@pytest.mark.parametrize("call", TINY_CALLS, ids=list(TINY_CALLS))
def test_channels_below_the_tiny_magnitude_are_refused(d, call):
    """moesp on outputs of 1e-300 returned C = 0 (fit 36.7 % against 96.8 %) silently;
    ls_subspace on 1e-160 raised LinAlgError, pem blamed the model's noise_cov."""
    with pytest.raises(errors.DataError, match="underflow double precision.*other units"):
        TINY_CALLS[call](d)


def test_the_tiny_check_names_the_channel_and_leaves_zero_channels(d):
    with pytest.raises(errors.DataError, match=r"^output y1 never exceeds \d\.\d+e-300"):
        subid.moesp(IO(d.u, d.y * 1e-300), 2)
    # an all-zero input is the excitation check's, as before
    with pytest.raises(errors.NotExcitingError):
        subid.moesp(IO(np.zeros_like(d.u), d.y), 2)
    # small but representable channels are identified as in their own units
    small = subid.moesp(IO(d.u * 1e-100, d.y * 1e-100), 2)
    assert subid.fit_percent(small, IO(d.u * 1e-100, d.y * 1e-100))[0] > 90


# -- 2. impulseest has the methods' checks ----------------------------------------------

@pytest.mark.parametrize("make, match", [
    (lambda d: IO(d.u * 1e200, d.y * 1e200), "overflow"),
    (lambda d: IO(d.u, np.ones((400, 1))), "constant"),
    (lambda d: IO(d.u, np.zeros((400, 1))), "constant"),
])
def test_impulseest_refuses_what_the_methods_refuse(d, make, match):
    """1e200 gave all-zero coefficients and a constant output an estimate, silently."""
    with pytest.raises(errors.DataError, match=match):
        subid.impulseest(make(d), 20)


# -- 3. pem's feedthrough ---------------------------------------------------------------

@pytest.mark.parametrize("value", ["no", "False", 2])
def test_pem_feedthrough_must_be_a_bool_or_none(d, value):
    start = subid.n4sid(d, 2, feedthrough=False)
    with pytest.raises(errors.OptionError, match="feedthrough must be one of"):
        subid.pem(d, start, feedthrough=value)


# -- 4. HankelStatistic ---------------------------------------------------------------

def test_statistics_of_different_sampling_periods_do_not_merge(d):
    one = subid.HankelStatistic.from_data(d, 10)
    two = subid.HankelStatistic.from_data(IO(d.u, d.y, dt=2.0), 10)
    with pytest.raises(errors.DataError, match=r"dt=1 and dt=2 cannot be merged"):
        one.merge(two)
    with pytest.raises(errors.DataError, match="cannot be merged"):
        one.merge(two, new_experiment=True)


def test_statistic_update_checks_the_magnitude(d):
    """A chunk of 1e200 was absorbed and later blamed as "a combination of inputs"."""
    with pytest.raises(errors.DataError, match=r"input u1 reaches .*overflow"):
        subid.HankelStatistic(1, 1, 10).update(d.u * 1e200, d.y)


# -- 5. ct_subspace and ct_subspace_paper --------------------------------------------

def test_ct_subspace_does_not_depend_on_the_input_units(dryer):
    """Inputs of 1e100 met a matmul ValueError deep inside (their simulated responses
    beyond the regressors' bound): the inputs are now scaled as the outputs."""
    base = subid.ct_subspace(dryer, 2, selection="gap", refine=False)
    big = subid.ct_subspace(IO(dryer.u * 1e100, dryer.y, dt=dryer.dt), 2, selection="gap",
                            refine=False)
    np.testing.assert_allclose(np.sort_complex(big.poles()), np.sort_complex(base.poles()),
                               rtol=1e-6)
    np.testing.assert_allclose(big.B * 1e100, base.B, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("function", [subid.ct_subspace, subid.ct_subspace_paper])
@pytest.mark.parametrize("make, error, match", [
    (lambda r: IO(r.u * 1e200, r.y * 1e200, dt=r.dt), errors.DataError, "overflow"),
    (lambda r: IO(r.u, r.y, dt=1e-300), errors.DataError, "time units apart"),
    (lambda r: IO(r.u, r.y, dt=1e300), errors.DataError, "time units apart"),
    (lambda r: IO(np.ones((1000, 1)), r.y, dt=r.dt), errors.NotExcitingError,
     "linearly dependent"),
    (lambda r: r[:10], errors.OrderError, "cannot be revealed"),
])
def test_ct_methods_check_their_data(dryer, function, make, error, match):
    """LAPACK 'illegal value' (and DLASCL lines on stderr), LinAlgError, "SVD did not
    converge"; ct_subspace_paper returned an unstable model of a constant input and a
    model of 10 samples."""
    with pytest.raises(error, match=match) as info:
        function(make(dryer), 2)
    if function is subid.ct_subspace_paper and "ct_subspace" in str(info.value):
        assert "ct_subspace_paper:" in str(info.value)


@pytest.mark.parametrize("function", [subid.ct_subspace, subid.ct_subspace_paper])
def test_ct_poly_order_must_be_an_integer(dryer, function):
    with pytest.raises(errors.OrderError, match="poly_order must be an integer"):
        function(dryer, 2, poly_order="3")


# -- 6. resource limits -----------------------------------------------------------------

def test_power_iterations_are_bounded(d):
    with pytest.raises(errors.OptionError, match="power_iterations must be an integer from 0 "
                                                 "to 100"):
        subid.ls_subspace(d, 2, power_iterations=10**6)


@pytest.mark.parametrize("make, match", [
    (lambda: AdaptiveIdentifier(10**4, 1, 1, dt=0.1), r"AdaptiveIdentifier: .* need 2\d\.\d GiB"),
    (lambda: RecursiveSubspace(10**4, 1, 1), r"RecursiveSubspace: .* need 1\d\.\d GiB"),
    (lambda: RecursiveSubspace(3, 10**4, 1), r"RecursiveSubspace: .* need 8\d\.\d GiB"),
])
def test_online_identifiers_refuse_states_beyond_the_memory_limit(make, match):
    """21.6, 11.9 and 74.5 GiB were asked for (and the selector of order 10^4 computed
    for 28 s first)."""
    start = time.perf_counter()
    with pytest.raises(errors.ResourceLimitError, match=match):
        make()
    assert time.perf_counter() - start < 5.0


# -- 7. errors that name the right function or option -----------------------------------

def test_identify_names_itself(d):
    with pytest.raises(errors.OrderError, match=r"^identify: order 50 cannot be revealed"):
        subid.identify(d, 50)


def test_order_of_the_wrong_kind_is_named(d):
    with pytest.raises(errors.OrderError, match=r"^order must be an integer, 'auto'"):
        subid.ls_subspace(d, {})
    with pytest.raises(errors.OrderError, match=r"^order is an empty list"):
        subid.ls_subspace(d, [])


def test_dt_to_ct_names_its_options(dryer):
    with pytest.raises(errors.OptionError, match=r"^dt_to_ct\(\) has no option 'nx'"):
        subid.dt_to_ct(dryer, 2, nx=3)


def test_polynomial_orders_without_dynamics(d):
    """armax (0, 0, 0, 0) raised IndexError; arx (0, 0, 0) "A is 0x0"."""
    for fn, orders in ((subid.armax, (0, 0, 0, 0)), (subid.arx, (0, 0, 0)),
                       (subid.armax, (0, 1, 0, 0))):
        with pytest.raises(errors.OrderError, match="without dynamics"):
            fn(d, orders)
    # no input term at lag 0 (nb = 0, nk = 0) indexed a missing coefficient
    assert subid.armax(d, (1, 0, 1, 0)).order == 1


def test_identify_stream_checks_its_arguments(d):
    pieces = [d[:200], d[200:]]
    with pytest.raises(errors.OrderError, match="^horizon must be at least 2"):
        subid.identify_stream(pieces, horizon=0)
    with pytest.raises(errors.DataError, match="iterable of IOData pieces"):
        subid.identify_stream(None)
    for name in ("reread", "progress"):
        with pytest.raises(errors.OptionError, match=f"^{name} must be a function"):
            subid.identify_stream(pieces, **{name: 3})


def test_distributed_client_must_be_a_client(d):
    import subid.distributed
    with pytest.raises(errors.OptionError, match=r"client must be a dask.distributed.Client"):
        subid.distributed.identify(d.u, d.y, client="tcp://nohost:1")


# -- 8. online identifiers' options -----------------------------------------------------

def test_adaptive_identifier_options(tmp_path):
    ident = AdaptiveIdentifier(2, 1, 1, dt=0.1)
    u = np.random.default_rng(0).standard_normal((50, 1))
    with pytest.raises(errors.DataError, match="time stamps t must be numbers"):
        ident.update(u, u, t="t")
    with pytest.raises(errors.OptionError, match="scale_filters must be True or False"):
        AdaptiveIdentifier(2, 1, 1, scale_filters="no")
    with pytest.raises(errors.OptionError, match="instrument_weighting must be True or False"):
        RecursiveSubspace(2, 1, 1, instrument_weighting="no")


@pytest.mark.parametrize("cls", [AdaptiveIdentifier, RecursiveSubspace])
def test_checkpoint_path_must_be_a_file_name(cls):
    with pytest.raises(errors.OptionError, match="checkpoint to save must be a file name"):
        cls(2, 1, 1).save(None)
    with pytest.raises(errors.OptionError, match="checkpoint to load must be a file name"):
        cls.load(None)
    with pytest.raises(errors.OptionError, match="checkpoint to load must be a file name"):
        subid.OnlineIdentifier.load(3)
