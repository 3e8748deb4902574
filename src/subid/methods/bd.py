"""B, D and the initial state x0 for a given (A, C): the one entry point.

Every method that has A and C and needs B, D (and x0) calls :func:`fit_b_d_x0`:
the discrete-time batch methods (in memory, streamed, on Dask, one or several
experiments), the recursive identifier and the continuous-time subspace
method. One vocabulary names the routes, as the ``bd_method`` option of every
method (each takes the subset that applies to it) and as ``info['bd_method']``
(:data:`INFO_KEY`), the route that ran:

``'simulation'``
    Output error: B, D, x0 fitted by least squares to the raw output samples
    through the model, ``y(t) = C A^t x0 + sum_{k<t} C A^(t-1-k) B u(k) + D u(t)``
    (seed 001, eq. (1)), each output weighted (by 1 / its standard deviation in
    the subspace methods). Engines: :mod:`subid.methods.dt._regression` (the
    modal normal equations, else the QR factor of the sensitivity rows),
    :mod:`subid.methods.dt._bd_large` (one x0 per experiment, eliminated
    experiment by experiment; many channels with the D rows eliminated),
    :mod:`subid.methods.dt._bd_pass` (a record in pieces: a second pass),
    :mod:`subid.methods.ct._ct_fit` (continuous time, the hold-exact response);
    the regression accumulated over a stream (:class:`Accumulated`, the
    recursive identifier) is solved by the QR and modal solvers of
    :mod:`subid.methods.dt._regression`.
``'prediction'``
    The same regression on the one-step predictor ``(A - K C, C)`` with the
    noise gain K (Ljung 1999, eq. 4.86): well posed for an unstable A.
``'projection'``
    The SVD-free projected data equation on the statistic (seed 001, eq. (5);
    no x0, no raw samples): :func:`subid.methods.dt._regression.fit_b_d_projection`.
``'filtered'``
    Continuous time: the filtered data equation (seed 002, eq. (15)),
    :func:`subid.methods.ct._ct_estimate._fit_b_filtered`.
``'auto'``
    ``'simulation'``, and ``'projection'`` where the simulation overflows or
    leaves the regression singular, or there are no raw samples.

Two more values appear in ``info['bd_method']`` only (:data:`INFO_ONLY`), where B
and D do not come from a regression for a given (A, C): ``'states'``, the
state-sequence regression that gives A, B, C, D together (N4SID, Van Overschee
& De Moor 1996, eq. 4.29; PBSID's state equation), and ``'converted'``, the
continuous-time model converted from a discrete-time one, which keeps the
converted B and D.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from subid.data import IOData
from subid.errors import ResourceLimitError, SubidError, TooFewSamplesError
from subid.methods._stability import spectral_radius
from subid.methods.dt._regression import fit_b_d_projection
from subid.methods.dt._regression import fit_b_d_x0 as _fit_record
from subid.methods.dt._regression import regression_rows as regression_rows
from subid.statistic.hankel import HankelStatistic

__all__ = ["INFO_KEY", "BD_METHODS", "INFO_ONLY", "BATCH_OPTIONS", "CT_OPTIONS", "ONLINE_OPTIONS",
           "Projection", "Accumulated", "fit_b_d_x0", "regression_rows",
           "check_experiment_lengths", "experiment_starts"]

#: The ``model.info`` key that names the route that gave B, D, x0.
INFO_KEY = "bd_method"
#: Every route (module docstring).
BD_METHODS = ("auto", "simulation", "prediction", "projection", "filtered")
#: Values of ``info['bd_method']`` that are no option (module docstring); the
#: diagnostics of a fit skipped by ``worse_than`` say ``'bound'``.
INFO_ONLY = ("states", "converted")
#: The ``bd_method`` values of the discrete-time batch methods.
BATCH_OPTIONS = ("auto", "simulation", "projection")
#: The ``bd_method`` values of :func:`subid.ct_subspace`.
CT_OPTIONS = ("simulation", "filtered")
#: The ``bd_method`` values of :class:`subid.RecursiveSubspace`.
ONLINE_OPTIONS = ("simulation", "projection")


class Projection(NamedTuple):
    """What the ``'projection'`` route needs: the statistic's blocks in the units of
    the normalised channels and the map back to the user's units."""

    #: C in the normalised units
    C: np.ndarray
    #: extended observability matrix (horizon * ny, n)
    gamma: np.ndarray
    #: lower-triangular factor of the future inputs
    L11: np.ndarray
    #: block of the factor coupling the future outputs to the future inputs
    L_yu: np.ndarray
    #: ``unscale(B_n, C_n, D_n) -> (B, C, D)`` in the user's units
    unscale: object


class Accumulated(NamedTuple):
    """The ``'simulation'`` regression for a given (A, C) accumulated over a stream
    (:class:`subid.RecursiveSubspace`), as one of

    * ``kind='factor'``: the upper-triangular factor of the rows ``[Phi(t), y(t)]``
      of :func:`regression_rows` (reduced by Givens rotations as they arrive, with
      the forgetting), solved as the QR path of the batch regression;
    * ``kind='normal'``: the augmented normal matrix ``[Phi, y]^T W [Phi, y]`` of the
      same rows over the whole stream, from lagged statistics
      (:mod:`subid.methods.online._lagged`), solved as the modal path.

    The parameters are ``theta = [x0; vec B; vec D]``; B, D and x0 are returned in
    the basis of the (A, C) the rows were built with.
    """

    #: ``'factor'`` or ``'normal'``
    kind: str
    #: the triangular factor, or the augmented normal matrix
    matrix: np.ndarray
    #: inputs of the model
    n_inputs: int
    #: samples (an effective count under forgetting)
    n_samples: float


def fit_b_d_x0(A, C, data, *, bd_method="simulation", feedthrough=True, estimate_x0=True,
               output_weights=None, projection=None, noise_gain=None, path="auto",
               offset=False, whiten=None, filtered=None, worse_than=None):
    """B, D and x0 of the model with the given A and C on ``data``, by ``bd_method``.

    Parameters
    ----------
    A, C : ndarray
        State and output matrices (C in the user's output units).
    data : IOData, HankelStatistic, Accumulated, continuous-time record or None
        The raw samples (one or several experiments, :func:`subid.merge`); a
        statistic, with a second pass over its record attached as
        ``output_regression`` (:mod:`subid.methods.dt._bd_pass`) or without
        one; the ``'simulation'`` regression accumulated over a stream
        (:class:`Accumulated`, :class:`subid.RecursiveSubspace`); the record of
        :mod:`subid.methods.ct._ct_fit` (continuous time); None for
        ``'projection'`` on a running statistic (:class:`subid.RecursiveSubspace`).
    bd_method : {'simulation', 'prediction', 'projection', 'filtered', 'auto'}
        The route (module docstring).
    feedthrough : bool
        Estimate D (else D = 0).
    estimate_x0 : bool
        Estimate the initial state (one per experiment).
    output_weights : ndarray, optional
        Weight of each output's errors (default ones).
    projection : Projection, optional
        The statistic's blocks: needed by ``'projection'`` and ``'auto'``.
    noise_gain : ndarray, optional
        K of the ``'prediction'`` route.
    path : {'auto', 'qr', 'modal'}
        Engine of the in-memory ``'simulation'``
        (:func:`subid.methods.dt._regression.fit_b_d_x0`).
    offset : bool
        Continuous time: estimate an output offset per experiment.
    whiten : callable, optional
        Continuous time: the noise model's whitening of the regression rows.
    filtered : tuple, optional
        Continuous time, ``'filtered'``: ``(Tfun, Theta, Lf, iU)`` of eq. (15).
    worse_than : float, optional
        ``'auto'`` on one raw record: when the residual RMS of the output
        regression is proven at least this from part of the record
        (:func:`subid.methods.dt._residual_bound.loses`), no fit:
        ``(None, None, None, {'bd_method': 'bound', 'residual_at_least': bound})``
        (the unstable A of a cross-validation fold, which then cannot be kept).

    Returns
    -------
    B, D, x0, diagnostics
        ``x0`` None when not estimated (one row per experiment for several);
        ``diagnostics[INFO_KEY]`` names the route that ran. :class:`Accumulated`:
        ``diagnostics['theta']`` holds the parameter vector, and the result is None
        where the normal matrix does not determine it. Continuous time:
        ``diagnostics['y_offset']`` holds the offsets, and the result is None
        where simulating A overflows. ``'prediction'`` returns None where the
        predictor regression is not usable (the caller keeps the output-error fit).

    Raises
    ------
    SubidError
        ``'simulation'`` where it cannot run (no raw samples; the simulation
        overflows or the regression is singular).
    """
    if bd_method not in BD_METHODS:
        raise ValueError(f"bd_method must be one of {BD_METHODS}, got {bd_method!r}")
    if data is None and bd_method != "projection":
        raise ValueError(f"bd_method={bd_method!r} needs the data")
    if isinstance(data, Accumulated):
        if bd_method != "simulation":
            raise ValueError(f"an accumulated regression is solved by bd_method='simulation', "
                             f"got {bd_method!r}")
        return _accumulated(A, C, data, feedthrough=feedthrough, estimate_x0=estimate_x0)
    if data is not None and not isinstance(data, (IOData, HankelStatistic)):
        return _continuous(A, C, data, bd_method=bd_method, feedthrough=feedthrough,
                           estimate_x0=estimate_x0, offset=offset, whiten=whiten,
                           filtered=filtered)
    if bd_method == "prediction":
        return _prediction(A, C, data, noise_gain, feedthrough=feedthrough,
                           estimate_x0=estimate_x0, output_weights=output_weights, path=path)
    radius = spectral_radius(A)
    # a statistic whose record can be read again (subid.methods.dt.stream, .distributed)
    second_pass = getattr(data, "output_regression", None)
    if isinstance(data, HankelStatistic) and second_pass is None:   # the statistic only
        if bd_method == "simulation":
            raise SubidError("bd_method='simulation' fits B and D to the raw output samples; "
                             "with a statistic only, use bd_method='projection' (or 'auto')")
        bd_method = "projection"
    diag = {}
    if estimate_x0 and isinstance(data, IOData) and data.n_experiments > 1:
        check_experiment_lengths(data, A.shape[0])
    if worse_than is not None and bd_method == "auto" and isinstance(data, IOData) \
            and data.n_experiments == 1:
        from subid.methods.dt._residual_bound import loses
        bound = loses(A, C, data.u, data.y, worse_than, feedthrough=feedthrough,
                      estimate_x0=estimate_x0, output_weights=output_weights)
        if bound is not None:
            return None, None, None, {INFO_KEY: "bound", "residual_at_least": bound}
    if bd_method in ("auto", "simulation"):
        with np.errstate(over="ignore", invalid="ignore"):
            if second_pass is not None:
                B, D, x0, diag = second_pass(A, C, feedthrough=feedthrough,
                                             estimate_x0=estimate_x0)
            else:
                B, D, x0, diag = _raw_samples(A, C, data.u, data.y, experiment_starts(data),
                                              feedthrough=feedthrough,
                                              estimate_x0=estimate_x0,
                                              output_weights=output_weights, path=path)
        usable = (np.isfinite(B).all() and np.isfinite(D).all()
                  and not diag["regression_rank_deficient"])
        if usable:
            diag.update({INFO_KEY: "simulation", "spectral_radius": radius})
            return B, D, (x0 if estimate_x0 else None), diag
        if bd_method == "simulation":
            raise SubidError(f"the identified A has spectral radius {radius:.4g}: simulating it "
                             f"over {data.n_samples} samples overflows or leaves the regression "
                             "singular; use bd_method='projection' (or 'auto')")
    pj = projection
    B_n, D_n, proj = fit_b_d_projection(A, pj.C, pj.gamma, pj.L11, pj.L_yu,
                                        feedthrough=feedthrough)
    B, _, D = pj.unscale(B_n, pj.C, D_n)
    if diag:
        proj["simulation_regression_condition"] = diag["regression_condition"]
    proj.update({INFO_KEY: "projection", "spectral_radius": radius})
    return B, D, None, proj


def _accumulated(A, C, acc: Accumulated, *, feedthrough, estimate_x0):
    """The ``'simulation'`` regression accumulated over a stream (:class:`Accumulated`)."""
    from subid.methods.dt._regression import solve_factor, solve_normal_equations
    n, nu, ny = A.shape[0], acc.n_inputs, C.shape[0]
    if acc.kind == "factor":
        B, D, x0, theta, diag = solve_factor(acc.matrix, n, nu, ny, estimate_x0=estimate_x0,
                                             n_samples=acc.n_samples, feedthrough=feedthrough)
    else:
        solved = solve_normal_equations(acc.matrix, n, nu, ny, estimate_x0=estimate_x0,
                                        feedthrough=feedthrough, n_samples=acc.n_samples,
                                        max_condition=1e12)
        if solved is None:
            return None
        B, D, x0, theta, diag = solved
        diag["regression_path"] = "lagged"
    diag.update({INFO_KEY: "simulation", "theta": theta})
    return B, D, x0, diag


def _raw_samples(A, C, u, y, starts, *, feedthrough, estimate_x0, output_weights, path):
    """The in-memory output-error engines: one record, several experiments, many channels."""
    from subid.methods.dt import _bd_large
    kw = dict(feedthrough=feedthrough, estimate_x0=estimate_x0, output_weights=output_weights)
    n, nu, ny = A.shape[0], u.shape[1], y.shape[1]
    dense = _bd_large.dense_bytes(n, nu, ny, u.shape[0], estimate_x0=estimate_x0,
                                  feedthrough=feedthrough,
                                  n_experiments=1 if starts is None else len(starts))
    if path != "auto" or dense <= _bd_large.DENSE_LIMIT:
        if starts is not None and len(starts) > 1:
            return _bd_large.fit_experiments(A, C, u, y, starts, path=path, **kw)
        return _fit_record(A, C, u, y, path=path, **kw)
    several = starts is not None and len(starts) > 1
    need = _bd_large.channel_bytes(n, nu, len(starts) if several else 1,
                                   estimate_x0=estimate_x0) + _bd_large.CHUNK_BYTES
    if need > _bd_large.MEMORY_LIMIT:
        raise ResourceLimitError(
            f"the B, D, x0 regression of order {n} with {nu} inputs, {ny} outputs"
            + (f" and {len(starts)} experiments (one initial state each)" if several else "")
            + f" needs {need / 2**30:.3g} GiB even with the outputs eliminated one by one "
            f"(limit {_bd_large.MEMORY_LIMIT / 2**30:g} GiB); "
            + ("merge fewer experiments, pass estimate_x0=False, " if several else "")
            + "identify fewer channels at a time, or use n4sid (B and D from the state "
              "sequence, no regression)")
    return _bd_large.fit_channels(A, C, u, y, starts=starts if several else None, **kw)


def _prediction(A, C, data, K, *, feedthrough, estimate_x0, output_weights, path):
    """B, D, x0 by the one-step predictor (module docstring), or None.

    ``x̂(k+1) = Ā x̂(k) + (B - K D) u(k) + K y(k)``, ``ŷ(k) = C x̂(k) + D u(k)``
    with ``Ā = A - K C`` (Ljung, *System Identification*, 2nd ed., 1999, eq.
    4.86) is linear in ``B̃ = B - K D``, D and ``x̂(0) = x0``:
    ``y(k) - y_K(k) = C Ā^k x0 + sum_j C Ā^(k-1-j) B̃ u(j) + D u(k) + e(k)`` with
    ``y_K`` the output of ``(Ā, K, C, 0)`` driven by y; ``B = B̃ + K D``.

    A record of several experiments (:func:`subid.merge`) has one predictor per
    experiment: ``y_K`` restarts from zero and ``x̂(0)`` is the experiment's own
    ``x0`` at every border, as in the output-error route (a single record takes
    the same path as before, bit for bit).
    """
    from subid.model._simulate import _simulate_discrete
    if not isinstance(data, IOData) or K is None:
        return None
    A_bar = A - K @ C
    ny = C.shape[0]
    starts = experiment_starts(data)
    if starts is not None and estimate_x0:
        check_experiment_lengths(data, A.shape[0])

    def predictor_output(y):
        return _simulate_discrete(A_bar, K, C, np.zeros((ny, ny)), y, np.zeros(A.shape[0]))[0]
    if starts is None:
        y_k = predictor_output(data.y)
    else:
        y_k = np.concatenate([predictor_output(data.y[a:b]) for a, b in data.experiment_ranges])
    with np.errstate(all="ignore"):
        B_t, D_p, x0, reg = _raw_samples(A_bar, C, data.u, data.y - y_k, starts,
                                         feedthrough=feedthrough, estimate_x0=estimate_x0,
                                         output_weights=output_weights, path=path)
    B_p = B_t + K @ D_p
    if not (np.isfinite(B_p).all() and np.isfinite(D_p).all()) \
            or reg["regression_rank_deficient"]:
        return None
    reg.update({INFO_KEY: "prediction",
                "spectral_radius": spectral_radius(A),
                "prediction_residual_rms": reg.pop("residual_rms")})
    return B_p, D_p, (x0 if estimate_x0 else None), reg


def _continuous(A, C, rec, *, bd_method, feedthrough, estimate_x0, offset, whiten, filtered):
    """The continuous-time routes (``'simulation'``, ``'filtered'``)."""
    from subid.methods.ct import _ct_fit
    if bd_method == "filtered":
        from subid.methods.ct._ct_estimate import _fit_b_filtered
        Tfun, Theta, Lf, iU = filtered
        B, D, diag = _fit_b_filtered(Tfun, Theta, Lf, iU, A.shape[0], rec.n_inputs,
                                     rec.n_outputs, feedthrough)
        diag[INFO_KEY] = "filtered"
        return B, D, None, diag
    if bd_method != "simulation":
        raise ValueError(f"continuous time: bd_method must be one of {CT_OPTIONS}, got "
                         f"{bd_method!r}")
    fitted = _ct_fit.fit_linear(A, C, rec, feedthrough=feedthrough, estimate_x0=estimate_x0,
                                offset=offset, whiten=whiten)
    if fitted is None:
        return None
    B, D, x0, y0, diag = fitted
    diag.update({INFO_KEY: "simulation", "y_offset": y0})
    return B, D, x0, diag


def check_experiment_lengths(data, order: int) -> None:
    """:class:`TooFewSamplesError` naming every experiment of ``data`` too short to
    determine its own initial state (``n_samples * n_outputs < order``
    equations for ``order`` unknowns), instead of a regression that would be
    rank deficient and send B, D to another route without x0."""
    short = [(name, b - a) for name, (a, b) in zip(data.experiment_names,
                                                     data.experiment_ranges)
             if (b - a) * data.n_outputs < order]
    if short:
        need = -(-order // data.n_outputs)
        listed = ", ".join(f"{name!r} ({length} sample{'s' if length != 1 else ''})"
                           for name, length in short[:5])
        more = f" and {len(short) - 5} more" if len(short) > 5 else ""
        raise TooFewSamplesError(
            f"experiment{'s' if len(short) > 1 else ''} {listed}{more} of the merged record "
            f"{'are' if len(short) > 1 else 'is'} too short to determine an initial state of "
            f"order {order}: each experiment needs at least {need} samples. Drop "
            f"{'them' if len(short) > 1 else 'it'} from the merge, or pass estimate_x0=False")


def experiment_starts(data):
    """The first sample of every experiment of a record of several (None otherwise)."""
    if isinstance(data, IOData) and data.n_experiments > 1:
        return [a for a, _ in data.experiment_ranges]
    return None
