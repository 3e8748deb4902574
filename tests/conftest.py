import numpy as np
import pytest

import subid
from subid import systems
from subid.methods import registry


@pytest.fixture(scope="session")
def paper_system():
    return systems.seed001_system()


@pytest.fixture(scope="session")
def paper_data(paper_system):
    return systems.simulate_data(paper_system, 1000, seed=1)


def _registered(spec):
    return lambda d, n=None, **kw: spec.load()(d, n, **kw)


# The discrete-time batch state-space methods of the registry (subid.registry.METHODS;
# the polynomial ones take structures, not state orders: tests/test_polynomial.py),
# under the names of the functions, plus two configurations of ls_subspace
# (without instruments; the paper's one-shot estimate).
METHODS = {spec.attribute if spec.name != "ls" else "ls_iv": _registered(spec)
           for spec in registry.METHODS.values() if spec.kind == "batch"
           and spec.time == "discrete" and not spec.supports("polynomial")}
METHODS.update({
    "ls_noiv": lambda d, n=None, **kw: subid.ls_subspace(d, n, instruments=None, **kw),
    "ls_paper": lambda d, n=None, **kw: subid.ls_subspace(d, n, instrument_weighting=False,
                                                          power_iterations=0, **kw),
})


@pytest.fixture(params=sorted(METHODS))
def method(request):
    return METHODS[request.param]


def rng(seed):
    return np.random.default_rng(seed)


# Hypothesis budgets: a small one for `make test`, a long one for `make test-long`
# (SUBID_HYPOTHESIS_PROFILE=long).
import os  # noqa: E402

from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("default", max_examples=12, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=300, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("SUBID_HYPOTHESIS_PROFILE", "default"))
