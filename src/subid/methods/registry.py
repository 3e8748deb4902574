"""The registry of identification methods: one contract for every method.

Every batch method is a function ``method(data, order=None, *, option=...)
-> StateSpace``: the data, the order, then keyword-only options with one
vocabulary across methods (``horizon``, ``hold``, ``bd_method``,
``estimate_x0``, ``feedthrough``, ``stability``, ``selection``,
``weighting``, ``refine``, ``input_delay``, ...). Every online identifier is
a class ``Cls(order, n_inputs, n_outputs, *, option=...)`` with ``update``,
``model``, ``save`` and ``load``. Every model's ``info`` has the core keys
of :data:`subid.methods._info.CORE_KEYS`.

:data:`METHODS` maps a method's name to its :class:`MethodSpec`: where it
lives (imported on first use), its kind, its time base, the keyword options
it takes and its capabilities. The command line (``--method``, ``--option``),
:func:`subid.identify_stream`, :mod:`subid.methods.dt.distributed`,
:func:`subid.dt_to_ct`, :mod:`subid.cli.demo` and the conformance tests all read
this one table; adding a method means adding one entry here (see
CONTRIBUTING.md).

Examples
--------
>>> from subid.methods.registry import METHODS, find
>>> find("moesp").time
'discrete'
>>> "statistic" in find("n4sid").capabilities
True
>>> sorted(name for name, spec in METHODS.items() if spec.kind == "online")
['adaptive', 'recursive']
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util

from subid.errors import OptionError, SubidError
from subid.methods._info import CORE_KEYS

__all__ = ["MethodSpec", "CheckParameters", "MethodUnavailableError", "METHODS",
           "CAPABILITIES", "CORE_KEYS", "RECORDS", "EXACTNESS", "find", "available_methods"]

#: Capabilities a method may declare (``MethodSpec.capabilities``):
#:
#: ``statistic``        identifies from a :class:`subid.HankelStatistic` too
#: ``streaming``        usable by :func:`subid.identify_stream` / :mod:`subid.methods.dt.distributed`
#: ``order_selection``  chooses the order when ``order`` is None
#: ``horizon``          takes a ``horizon`` option
#: ``stability``        takes a ``stability`` option
#: ``input_delay``      takes an ``input_delay`` option
#: ``weighting``        takes a ``weighting`` option
#: ``x0``               estimates the initial state (``estimate_x0``)
#: ``refine``           takes ``refine='simulation'`` or ``'prediction'`` (PEM)
#: ``hold``             takes a ``hold`` option (the input between samples)
#: ``nonuniform``       accepts non-uniformly sampled records
#: ``seeded``           has a ``seed`` option (a random draw)
#: ``polynomial``       ``order`` is a polynomial structure (MATLAB's ``(na, nb, nk)``, ...;
#:                      an integer n sets every degree to n), and the model's state dimension
#:                      follows from it: ``method(data, n).order`` need not be n
#: ``feedthrough``      takes a ``feedthrough`` option (estimate D or not)
#: ``experiments``      identifies from a record of several experiments (:func:`subid.merge`),
#:                      with one initial state per experiment in ``info['x0']``
#: ``frequency``        identifies from frequency-response data (:class:`subid.FRData`), not
#:                      from time records; the model's time base is the data's
CAPABILITIES = frozenset({"statistic", "streaming", "order_selection", "horizon", "stability",
                          "input_delay", "weighting", "x0", "refine", "hold", "nonuniform",
                          "seeded", "polynomial", "feedthrough", "experiments", "frequency"})

#: The noise-free test records :mod:`subid.testing` builds (``CheckParameters.record``):
#: ``discrete``    seed 001's system (3 states, 2 inputs, 2 outputs, D != 0), 600 samples of
#:                 white Gaussian input, dt = 1;
#: ``continuous``  a 2-state, 1-input, 2-output continuous-time system (D != 0), 300 samples
#:                 of a Gaussian input held first-order (``hold='foh'``), dt = 0.02 s,
#:                 starting from a non-zero state;
#: ``frequency``   that continuous-time system's frequency response at 60 frequencies from
#:                 0.03 to 30 rad/s (:class:`subid.FRData`, dt = 0).
RECORDS = ("discrete", "continuous", "frequency")

#: What a method claims on a noise-free record (``CheckParameters.exact``):
#: ``markov``     the first Markov parameters of the true system to ``tolerance``;
#: ``frequency``  its frequency response to ``tolerance`` (relative to its largest gain);
#: None          no exactness claimed (an adaptive estimate that converges).
EXACTNESS = ("markov", "frequency", None)


@dataclasses.dataclass(frozen=True)
class CheckParameters:
    """What the contract checks of :mod:`subid.testing` call a method with, and what it claims.

    Every registered method declares these in its :class:`MethodSpec` (``checks``), so that
    the checks hold no case keyed on a method's name.

    Attributes
    ----------
    record : {'discrete', 'continuous', 'frequency'}
        The noise-free test record (see :data:`RECORDS`).
    order : int
        The order every check passes (a polynomial method: every degree).
    options : tuple of (str, object) pairs
        Options passed on every call (e.g. ``(('hold', 'foh'),)``: the record's hold).
    exact : {'markov', 'frequency'} or None
        What the method recovers exactly from the noise-free record (see
        :data:`EXACTNESS`).
    tolerance : float
        Largest error allowed by ``exact``.
    reproduces : bool
        ``method(data, order=m.order, horizon=m.info['horizon'])`` gives ``m`` bit for
        bit (False for a polynomial method, whose ``order`` is a structure, not the state
        dimension).
    unrecorded : tuple of str
        Options whose value ``model.info`` does not record (a given input such as a
        statistic, or a known gap); every other option is recorded under its own name
        (``selection`` as ``order_selection``, ``estimate_x0`` as ``x0``). The check
        fails when an option declared here is recorded (delete it from here).
    chunks_exact : bool
        Online identifiers: updates in several chunks end bit for bit where one chunk
        ends (False: to rounding, ``rtol=1e-8``).
    expected_failures : tuple of (str, str) pairs
        ``(sub-check, reason)``: sub-checks known to fail on this version (as
        scikit-learn's ``expected_failed_checks``). The check reports them as expected
        failures, and fails when one of them passes (then delete the declaration).
    """

    record: str = "discrete"
    order: int = 3
    options: tuple = ()
    exact: str | None = "markov"
    tolerance: float = 1e-8
    reproduces: bool = True
    unrecorded: tuple = ()
    chunks_exact: bool = True
    expected_failures: tuple = ()

    def __post_init__(self):
        if self.record not in RECORDS:
            raise OptionError(f"CheckParameters: record must be one of {RECORDS}, got "
                              f"{self.record!r}")
        if self.exact not in EXACTNESS:
            raise OptionError(f"CheckParameters: exact must be one of {EXACTNESS}, got "
                              f"{self.exact!r}")

    @property
    def call_options(self) -> dict:
        """``options`` as a dict (the keyword arguments of every call)."""
        return dict(self.options)

    @property
    def expected(self) -> dict:
        """``expected_failures`` as a dict, sub-check -> reason."""
        return dict(self.expected_failures)


class MethodUnavailableError(SubidError):
    """The method's module is not part of this version of subid."""


@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """One identification method.

    Attributes
    ----------
    name : str
        Registry name (``--method NAME`` on the command line).
    kind : {'batch', 'online'}
        ``batch``: a function ``fn(data, order=None, *, **options) ->
        StateSpace``. ``online``: a class ``Cls(order, n_inputs, n_outputs,
        *, **options)`` with ``update``, ``model``, ``save`` and ``load``.
    module, attribute : str
        Where the function or class lives; imported on first use.
    time : {'discrete', 'continuous'}
        Time base of the models it produces (a ``frequency`` method: that of the
        data, here the time base of its test record).
    description : str
        One line for ``subid methods``.
    options : tuple of str
        The keyword options it takes (after ``data, order`` for a batch
        method, after ``order, n_inputs, n_outputs`` for an online one).
    capabilities : frozenset of str
        Subset of :data:`CAPABILITIES`.
    aliases : tuple of str
        Other names :func:`find` accepts (e.g. the function's name).
    command_line : bool
        Offered by ``subid identify``/``subid track`` and the demo.
    checks : CheckParameters
        What :func:`subid.testing.check_batch_method` and
        :func:`subid.testing.check_online_identifier` call it with and what it claims.
    """

    name: str
    kind: str
    module: str
    attribute: str
    time: str
    description: str
    options: tuple = ()
    capabilities: frozenset = frozenset()
    aliases: tuple = ()
    command_line: bool = True
    checks: CheckParameters = dataclasses.field(default_factory=CheckParameters)

    def available(self) -> bool:
        """Whether the method's module is installed (without importing it)."""
        try:
            return importlib.util.find_spec(self.module) is not None
        except (ImportError, ValueError):
            return False

    def load(self):
        """The function or class; :class:`MethodUnavailableError` when its module is absent."""
        try:
            module = importlib.import_module(self.module)
        except ModuleNotFoundError as exc:
            if exc.name == self.module:
                raise MethodUnavailableError(
                    f"method {self.name} is not available in this version of subid (module "
                    f"{self.module} is missing); available methods: "
                    f"{', '.join(available_methods(self.kind if self.kind == 'online' else None))}"
                ) from None
            raise
        try:
            return getattr(module, self.attribute)
        except AttributeError:
            raise MethodUnavailableError(
                f"method {self.name} is not available in this version of subid "
                f"({self.module} has no {self.attribute})") from None

    @property
    def function(self):
        """Alias of :meth:`load` as a property (the function or class)."""
        return self.load()

    def accepts(self, option: str) -> bool:
        """Whether ``option`` is one of the method's keyword options."""
        return option in self.options

    def supports(self, capability: str) -> bool:
        """Whether the method declares ``capability`` (see :data:`CAPABILITIES`)."""
        return capability in self.capabilities


_DT_COMMON = ("horizon", "selection", "stability", "feedthrough", "estimate_x0", "bd_method",
              "statistic", "refine", "input_delay")
_DT_CAPS = frozenset({"statistic", "streaming", "order_selection", "horizon", "stability",
                      "input_delay", "x0", "refine", "feedthrough", "experiments"})
_POLY_COMMON = ("selection", "estimate_x0")
_POLY_PEM = ("max_iterations", "tolerance")
_POLY_CAPS = frozenset({"polynomial", "order_selection", "x0", "experiments"})

# What the contract checks (subid.testing) call each method with and what it claims.
_DT_CHECKS = CheckParameters()
_POLY_CHECKS = CheckParameters(reproduces=False)          # order is a structure
_PEM_CHECKS = CheckParameters(reproduces=False, unrecorded=_POLY_PEM)

#: Every registered method, by name.
METHODS: dict[str, MethodSpec] = {
    "ls": MethodSpec(
        "ls", "batch", "subid.methods.dt.ls_subspace", "ls_subspace", "discrete",
        "SVD-free least-squares subspace identification (seed 001)",
        options=_DT_COMMON + ("instruments", "selector", "seed", "instrument_weighting",
                              "power_iterations", "normalize_outputs", "system_matrices"),
        capabilities=_DT_CAPS | {"seeded"}, aliases=("ls_subspace",),
        checks=CheckParameters(unrecorded=("seed", "normalize_outputs"))),
    "moesp": MethodSpec(
        "moesp", "batch", "subid.methods.dt.moesp", "moesp", "discrete", "PO-MOESP (Verhaegen)",
        options=_DT_COMMON + ("weighting", "system_matrices"),
        capabilities=_DT_CAPS | {"weighting"}, checks=_DT_CHECKS),
    "n4sid": MethodSpec(
        "n4sid", "batch", "subid.methods.dt.n4sid", "n4sid", "discrete",
        "N4SID (Van Overschee & De Moor)",
        options=tuple(o for o in _DT_COMMON if o != "bd_method") + ("weighting",),
        capabilities=_DT_CAPS | {"weighting"}, checks=_DT_CHECKS),
    "pbsid": MethodSpec(
        "pbsid", "batch", "subid.methods.dt.pbsid", "pbsid", "discrete",
        "predictor-based subspace identification, PBSID-opt (Chiuso 2007; closed loop)",
        options=tuple(o for o in _DT_COMMON if o != "bd_method"),
        capabilities=_DT_CAPS, checks=_DT_CHECKS),
    "arx": MethodSpec(
        "arx", "batch", "subid.methods.dt.polynomial", "arx", "discrete",
        "ARX polynomial model by least squares (MATLAB arx; structure by cross-validation)",
        options=_POLY_COMMON, capabilities=_POLY_CAPS, checks=_POLY_CHECKS),
    "armax": MethodSpec(
        "armax", "batch", "subid.methods.dt.pem_poly", "armax", "discrete",
        "ARMAX polynomial model by prediction-error minimisation (MATLAB armax)",
        options=_POLY_COMMON + _POLY_PEM, capabilities=_POLY_CAPS, checks=_PEM_CHECKS),
    "oe": MethodSpec(
        "oe", "batch", "subid.methods.dt.pem_poly", "oe", "discrete",
        "output-error polynomial model by prediction-error minimisation (MATLAB oe)",
        options=_POLY_COMMON + _POLY_PEM, capabilities=_POLY_CAPS, checks=_PEM_CHECKS),
    "bj": MethodSpec(
        "bj", "batch", "subid.methods.dt.pem_poly", "bj", "discrete",
        "Box-Jenkins polynomial model by prediction-error minimisation (MATLAB bj)",
        options=_POLY_COMMON + _POLY_PEM, capabilities=_POLY_CAPS, checks=_PEM_CHECKS),
    "ct": MethodSpec(
        "ct", "batch", "subid.methods.ct.ct_subspace", "ct_subspace", "continuous",
        "continuous-time subspace identification (uniform or non-uniform samples)",
        options=("basis", "poly_order", "estimate_x0", "feedthrough", "hold", "selection",
                 "start", "offset", "stability", "noise_model", "instruments",
                 "iterations", "tolerance", "refine", "refine_iterations", "startup",
                 "correction", "ac_method", "bd_method", "filtering", "data_equation",
                 "filtered"),
        capabilities=frozenset({"order_selection", "x0", "hold", "nonuniform", "stability",
                                "feedthrough", "experiments"}),
        aliases=("ct_subspace",),
        # the horizon is the number of basis functions, not an option; refine is
        # recorded as 'refined' and 'refine_selection'; filtered is a given input
        checks=CheckParameters(
            record="continuous", order=2, exact="frequency",
            unrecorded=("noise_model", "tolerance", "refine", "refine_iterations",
                        "correction", "filtered"))),
    "dt_to_ct": MethodSpec(
        "dt_to_ct", "batch", "subid.methods.ct.ct_subspace", "dt_to_ct", "continuous",
        "discrete-time subspace identification converted to continuous time (baseline)",
        options=("method", "hold") + tuple(o for o in _DT_COMMON
                                           if o not in ("feedthrough", "bd_method")),
        capabilities=frozenset({"order_selection", "horizon", "hold", "x0", "experiments"}),
        command_line=False,
        # its default hold is 'zoh'; the continuous test record is held first-order
        checks=CheckParameters(record="continuous", order=2, options=(("hold", "foh"),),
                               exact="frequency")),
    "fd": MethodSpec(
        "fd", "batch", "subid.methods.fd.fd_subspace", "fd_subspace", "continuous",
        "subspace identification from a frequency response (McKelvey et al. 1996); the "
        "model's time base is the data's",
        options=("horizon", "feedthrough", "stability", "selection"),
        capabilities=frozenset({"frequency", "order_selection", "horizon", "stability",
                                "feedthrough"}),
        aliases=("fd_subspace",), command_line=False,
        checks=CheckParameters(record="frequency", order=2, exact="frequency")),
    "recursive": MethodSpec(
        "recursive", "online", "subid.methods.online.recursive", "RecursiveSubspace", "discrete",
        "online SVD-free subspace identification (seed 001 made recursive), fixed state "
        "basis",
        options=("horizon", "forgetting", "instruments", "selector", "seed",
                 "instrument_weighting", "power_iterations", "feedthrough", "dt",
                 "history_size", "history_stride", "input_names", "output_names",
                 "bd_method", "refresh_every", "restart_tolerance", "lags"),
        capabilities=frozenset({"horizon", "seeded", "feedthrough"}),
        aliases=("RecursiveSubspace",),
        checks=CheckParameters(chunks_exact=False)),
    "adaptive": MethodSpec(
        "adaptive", "online", "subid.methods.online.adaptive", "AdaptiveIdentifier", "continuous",
        "online continuous-time identification",
        options=("horizon", "filter_poles", "forgetting", "bd_forgetting", "selector", "seed",
                 "dt", "hold", "method", "scale_filters", "refresh_every", "bd_gate",
                 "max_condition", "initial_covariance", "bd_initial_covariance",
                 "ode_trace_bound", "history_size", "engine", "input_names", "output_names",
                 "instrument_poles", "max_gap", "bd_startup", "refine"),
        capabilities=frozenset({"horizon", "hold", "nonuniform", "seeded"}),
        aliases=("AdaptiveIdentifier",),
        # an adaptive estimate converges; it is not exact on a finite record
        checks=CheckParameters(record="continuous", order=2, exact=None, expected_failures=(
            ("units", "the paper's normalisation 1 + |phi|^2 fixes a signal size "
                      "(docs/seed000.md, Units)"),))),
}


def find(name: str, *, kind: str | None = None, time: str | None = None,
         capability: str | None = None) -> MethodSpec:
    """The :class:`MethodSpec` registered as ``name`` (or one of its aliases).

    Parameters
    ----------
    name : str
    kind : {'batch', 'online'}, optional
        Required kind.
    time : {'discrete', 'continuous'}, optional
        Required time base.
    capability : str, optional
        Required capability.

    Raises
    ------
    OptionError
        No method of that name (and kind, time base, capability); the
        message lists those that qualify.
    """
    def qualifies(spec):
        return ((kind is None or spec.kind == kind) and (time is None or spec.time == time)
                and (capability is None or capability in spec.capabilities))

    for spec in METHODS.values():
        if (name == spec.name or name in spec.aliases) and qualifies(spec):
            return spec
    names = [s.name for s in METHODS.values() if qualifies(s)]
    raise OptionError(f"method must be one of {', '.join(repr(n) for n in names)}; "
                      f"got {name!r}"[:300])


def available_methods(kind: str | None = None, time_base: str | None = None, *,
                      command_line: bool = True) -> list[str]:
    """Names of the registered methods whose module is present.

    Parameters
    ----------
    kind : {'batch', 'online'}, optional
    time_base : {'discrete', 'continuous'}, optional
    command_line : bool
        Only those offered by the command line (default).
    """
    return [name for name, spec in METHODS.items()
            if (kind is None or spec.kind == kind)
            and (time_base is None or spec.time == time_base)
            and (spec.command_line or not command_line) and spec.available()]
