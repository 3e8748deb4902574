"""Continuous-time subspace identification with orthonormal basis filters (seed 002).

Yu, Chen, Ljung, Verhaegen, "Subspace identification of continuous-time
models using generalized orthonormal bases", CDC 2017. Numbers in
parentheses are the paper's equations; docs/seed002.md lists every
correction made to them.

Data equation
-------------
Filter the output and the input by the same bank of ``N`` orthonormal basis
filters ``xi' = F xi + g v`` (:mod:`subid.basis`), all at rest at ``t_0``.
Stack the filtered samples function-major: ``y_f(t)`` has ``N p`` rows,
block ``k`` being basis function ``k`` applied to every output (the paper's
``y_k``), and likewise ``u_f(t)`` (``N m`` rows). For ``x' = A x + B u``,
``y = C x + D u`` the filtered state ``Xi_x`` (n x N) obeys both
``Xi_x' = Xi_x F^T + x g^T`` and ``Xi_x' = A Xi_x + B Xi_u`` (filtering
commutes with the system), hence the Sylvester equation
``A Xi_x - Xi_x F^T = x g^T - B Xi_u`` and

    y_f(t) = O x(t) + T u_f(t) + Psi phi(t - t_0),                     (6')

    O = (I_N kron C) S^{-1} (g kron I_n),
    T = -(I_N kron C) S^{-1} (I_N kron B) + I_N kron D,
    S = I_N kron A - F kron I_n,

with ``phi(t) = e^{F t} g`` the basis functions: the start-up transients of
the filters and the response to a non-zero ``x(t_0)`` are free responses of
the bank (``x(t_0) phi(t - t_0)^T`` enters the Sylvester equation), so they
lie in the span of ``phi(t - t_0)``, which are therefore used as regressors
(``startup=True``). For real poles ``O`` is exactly the paper's extended
observability matrix (10). The paper's (6) stacks instead the
``N (N + 1) / 2`` signals ``psi_{l,j+1} M_j u``; they all lie in the span of
the ``N`` filtered inputs, so that stacked input has rank ``N m`` only. Its
convolution matrix is printed wrong (:func:`tm_convolution_matrix` gives the
corrected one). Both forms are available (``data_equation``).

Estimation
----------
1. LQ factorisation of the signals ``[phi; u_f; r; z; y_f]`` (``r``
   interpolation-correction regressors, ``z`` instruments) and SVD of the
   block of ``y_f`` on the instruments, or on its own rows without them:
   range(O) (Lemma 3, eq. (8)).
2. ``A`` and ``C``. The blocks ``K_k`` of ``S^{-1} (g kron I)`` are
   rational functions of ``A``, so they commute with it and block row ``k`` of
   ``O`` obeys ``O_k A = sum_j F_kj O_j + g_k C``. ``ac_method='joint'``
   solves these ``N p`` block equations for ``[A; C]`` by least squares;
   ``'paper'`` eliminates ``C`` between consecutive equations normalised by
   ``g_k``, which for real poles is exactly the paper's ``M A = R`` (11)-(12)
   solved as ``A = M^+ R`` ((13) as printed reads ``L_A^+ R_A``), and takes
   ``C = O_0 (A + sigma_0 I) / sqrt(2 sigma_0)`` ((14) prints ``2 sigma_0``).
3. ``B`` (and ``D``, ``x0``): ``bd_method='simulation'`` fits them to the raw
   output samples through the exactly discretised model (the output is
   linear in them); ``'filtered'`` solves (15) on the filtered data equation.

Beyond the paper
----------------
* Interpolation-correction regressors (``correction=True``). The output
  inherits the non-smoothness of the input: with ``G(s) = D + CB/s + CAB/s^2
  + ...``, ``y - D u - sum_i c_i H_i u`` is smooth to the order the
  degree-p interpolation needs once ``i`` runs to ``p - 1`` (input continuous
  between samples) or ``p`` (held input), ``H_i(s) = (a/(s + a))^i``. The
  filtered interpolation errors of ``H_i u`` are computable from the input
  alone; entering them as regressors with free coefficients removes the
  dominant filtering error of ``y`` (4th-order system, L = 400: from O(1) to
  1e-9 in max |G - G_hat|).
* Instruments (``instruments='model'``): after a first estimate, the states
  of the model simulated from the input alone replace ``y_f``'s own rows in
  the SVD (iterated). They are functions of the input only, uncorrelated with
  output noise of any colour, so range(O) is consistent.
* Output-error refinement (``refine=True``): Levenberg-Marquardt on the raw
  output samples over (A, C) in local coordinates transversal to the state
  basis, with B, D, x0 eliminated by linear least squares (variable
  projection). It turns the consistent subspace estimate into the
  least-squares (maximum-likelihood for white Gaussian output noise)
  estimate. ``info['subspace_model']`` keeps the subspace estimate.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import scipy.linalg
import scipy.optimize

from subid._validation import check_bool, check_choice, check_int, legacy_arguments
from subid.data import IOData, require_single_experiment
from subid.errors import (
    DataError,
    ModelError,
    NotExcitingError,
    OptionError,
    OrderError,
    TooFewSamplesError,
)
from subid.methods._info import model_info, records_warnings
from subid.methods.ct import _ct_kernels
from subid.methods.ct.basis import MAX_POLY_ORDER, FilterBank, default_basis
from subid.methods.dt._subspace import choose_order
from subid.model.statespace import StateSpace
from subid.statistic._hankel import lq_lower

__all__ = [
    "ct_subspace",
    "ct_subspace_paper",
    "dt_to_ct",
    "data_equation_matrices",
    "observability_matrix",
    "tm_convolution_matrix",
]

DEFAULT_MAX_ORDER = 10
HOLD_ORDERS = {"zoh": 0, "foh": 1}
# Relative size of a diagonal entry of the filtered-input factor below which
# the filtered inputs count as linearly dependent.
_RANK_TOL = 1e-10


# ---------------------------------------------------------------------------
# data-equation matrices of a known model
# ---------------------------------------------------------------------------
def data_equation_matrices(bank: FilterBank, A, B, C, D=None):
    """``O`` and ``T`` of the compact data equation (6') for a known model.

    Parameters
    ----------
    bank : FilterBank
    A, B, C : array_like
    D : array_like, optional

    Returns
    -------
    O : ndarray, shape (N p, n)
    T : ndarray, shape (N p, N m)
        ``y_f(t) = O x(t) + T u_f(t)`` for filters at rest and ``x(t_0) = 0``.
    """
    A, B, C = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, C))
    N = bank.n_functions
    n = A.shape[0]
    _, g = bank.realization()
    S = bank.sylvester_matrix(A)
    IC = np.kron(np.eye(N), C)
    O = IC @ np.linalg.solve(S, np.kron(g[:, None], np.eye(n)))
    T = -IC @ np.linalg.solve(S, np.kron(np.eye(N), B))
    if D is not None:
        T = T + np.kron(np.eye(N), np.atleast_2d(np.asarray(D, dtype=float)))
    return O, T


def observability_matrix(bank: FilterBank, A, C):
    """Extended observability matrix ``O`` of (6'); eq. (10) for real poles."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    return data_equation_matrices(bank, A, np.zeros((A.shape[0], 1)), C)[0]


def tm_convolution_matrix(A, B, C, poles):
    """Convolution matrix ``T`` of the paper's data equation (6), corrected.

    From ``y_i = C (x_i - x_{i+1}) / sqrt(2 sigma_i)`` (proof of Lemma 2) and
    the expansion (5) of ``x_i``, the coefficient of ``[psi_{l,j+1} M_j u]``
    in ``y_i`` is, for ``i >= j``,

        Gamma_j / sqrt(2 sigma_i) * ([l = i - 1] - [l = i]),
        Gamma_j = C Phi(j-1, 0) B_j = sqrt(2 sigma_j) C Phi(j-1, 0) (A + sigma_j I)^{-1} B,

    and zero for ``i < j``. So block column ``T_j`` has ``j`` leading zero
    block rows (the printed ``T_i`` has one), every block row ``i`` carries
    ``1/sqrt(2 sigma_i)`` (missing in print), and the diagonal blocks are
    ``-Gamma_j/sqrt(2 sigma_j)``; for ``j = 0`` that is
    ``C (A + sigma_0 I)^{-1} B = -D_0``, so the printed ``T_0`` (``-D_0`` on
    the diagonal, ``+D_0`` below) has the wrong sign.

    Parameters
    ----------
    A, B, C : array_like
    poles : sequence of float
        Real TM poles ``sigma_0 .. sigma_{N-1}``.

    Returns
    -------
    ndarray, shape (N p, m N (N + 1) / 2)
        Columns in the order of :meth:`FilterBank.paper_input_stack`.
    """
    A, B, C = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, C))
    sig = np.asarray(poles, dtype=float).reshape(-1)
    N, n, p, m = sig.size, A.shape[0], C.shape[0], B.shape[1]
    eye = np.eye(n)
    Phi = eye
    gam = []
    for j in range(N):
        gam.append(np.sqrt(2 * sig[j]) * C @ Phi @ np.linalg.solve(A + sig[j] * eye, B))
        Phi = Phi @ np.linalg.solve(A + sig[j] * eye, A - sig[j] * eye)
    blocks = []
    for j in range(N):
        Tj = np.zeros((N * p, (N - j) * m))
        for i in range(j, N):
            rows = slice(i * p, (i + 1) * p)
            col = i - j
            Tj[rows, col * m:(col + 1) * m] -= gam[j] / np.sqrt(2 * sig[i])
            if i > j:
                Tj[rows, (col - 1) * m:col * m] += gam[j] / np.sqrt(2 * sig[i])
        blocks.append(Tj)
    return np.hstack(blocks)


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------
def _check_data(data, method: str) -> IOData:
    if not isinstance(data, IOData):
        raise DataError(f"{method} expects an IOData record, got {type(data).__name__}; "
                        "wrap arrays as subid.IOData(u, y, t=...) or IOData(u, y, dt=...)")
    require_single_experiment(data, method)
    std = data.y.std(axis=0)
    flat = np.flatnonzero(std <= 1e-14 * np.maximum(np.abs(data.y).max(axis=0), 1e-300))
    if flat.size:
        names = ", ".join(data.output_names[k] for k in flat)
        raise DataError(f"output {names} is constant over the whole record: it carries no "
                        "information about the dynamics; drop that channel")
    if data.n_samples > 1:
        # a spacing near the rounding of the time stamps themselves is known to few digits,
        # and every exact discretisation over it is wrong: say so instead of fitting noise
        h = np.diff(data.t)
        resolution = 1e-9 * float(np.abs(data.t).max())
        k = int(np.argmin(h))
        if h[k] <= resolution:
            raise DataError(f"{method}: the time stamps {data.t[k]!r} and {data.t[k + 1]!r} "
                            f"(rows {k}, {k + 1}) are {h[k]:.3g} apart, below the resolution "
                            f"of time stamps of magnitude {np.abs(data.t).max():.3g} (about "
                            "1e-9 of it): the interval is known to few digits. Subtract the "
                            "start time, merge the two samples, or resample")
    return data


def _parse_order(order, max_order):
    """(fixed order or None, candidate orders)."""
    if order is None or (isinstance(order, str) and order == "auto"):
        return None, list(range(1, max_order + 1))
    if isinstance(order, (str, bytes)) or not hasattr(order, "__iter__"):
        n = check_int(order, "order", minimum=1)
        if n > max_order:
            raise OrderError(f"order {n} cannot be revealed with this basis: the filtered "
                             f"outputs reveal at most {max_order} states (N p - p, at most "
                             f"{DEFAULT_MAX_ORDER}); use more basis functions")
        return n, [n]
    cands = sorted({check_int(k, "candidate order", minimum=1) for k in order})
    if not cands:
        raise OrderError("the list of candidate orders is empty")
    cands = [k for k in cands if k <= max_order]
    if not cands:
        raise OrderError(f"every candidate order exceeds {max_order}, the largest this basis "
                         "reveals; use more basis functions")
    return None, cands


def _check_filtered(filtered, L, N, m, p):
    try:
        uf, yf = filtered
    except (TypeError, ValueError):
        raise DataError("filtered must be a pair (u_f, y_f) of arrays") from None
    uf = np.asarray(uf, dtype=float)
    yf = np.asarray(yf, dtype=float)
    if uf.shape != (L, N, m) or yf.shape != (L, N, p):
        raise DataError(f"filtered signals must have shapes {(L, N, m)} and {(L, N, p)} "
                        f"(samples, basis functions, channels), got {uf.shape} and "
                        f"{yf.shape}")
    if not (np.isfinite(uf).all() and np.isfinite(yf).all()):
        raise DataError("filtered signals contain NaN or infinite values")
    return uf, yf


def _lag_for(bank: FilterBank, t: np.ndarray) -> int:
    """Lag of the 'past' instruments: about two time constants of the slowest filter."""
    slow = min(abs(z.real) for z in bank.poles)
    h = (t[-1] - t[0]) / (t.size - 1)
    return max(1, int(math.ceil(2.0 / (slow * h))))


# ---------------------------------------------------------------------------
# regressors
# ---------------------------------------------------------------------------
def _correction_count(poly_order: int, input_order: int, feedthrough: bool):
    """Orders ``i`` of the correction filters ``H_i``: ``range(i0, j + 1)``."""
    j = poly_order - (1 if input_order >= 1 else 0)
    i0 = 0 if (feedthrough and input_order != poly_order) else 1
    return i0, j


def _correction_regressors(bank: FilterBank, t, u, poly_order, input_order, feedthrough,
                           filtering, uniform):
    """Filtered interpolation errors of ``H_i u`` (beyond the paper).

    ``y = G u`` with ``G(s) = D + CB/s + CAB/s^2 + ...``. An input
    interpolated continuously between samples (``input_order >= 1``) has jumps
    in its first derivative, so ``H_i u`` with ``H_i(s) = (a/(s + a))^i`` has
    jumps in derivative ``i + 1``; a held input (order 0) has jumps in value,
    giving derivative ``i``. A degree-p interpolating polynomial is accurate to
    ``O(h^{p+1})`` only for signals whose first p derivatives are continuous,
    and ``y - D u - sum_{i<=j} c_i H_i u`` (suitable ``c_i``, matching the
    Markov parameters) is such a signal for ``j = p - [input_order >= 1]``.
    The filtered interpolation error of ``y`` is therefore
    ``sum_i c_i e_i + O(h^{p+1})`` with the known signals
    ``e_i = F[H_i u] - F[P_p H_i u]`` (exact filtering minus filtering of the
    interpolated samples), and the ``O(h^{p+1})`` part, proportional to a
    derivative of ``y``, only perturbs ``O`` and ``T``. The ``e_i`` (``N m``
    columns each) are regressors with free coefficients. ``i = 0`` (the
    input's own interpolation error) is included with a feedthrough when the
    input is not interpolated like the output.

    ``a`` is the slowest basis pole: the remainder must be smooth on the
    scale of the sampling step (``a h << 1``), else its own interpolation
    error is not small (with ``a h = 0.1`` jittered records fail). The price:
    the regressors then carry slow, state-like components, and projecting
    them out costs variance under noise (docs/seed002.md, ablation).

    Returns
    -------
    ndarray, shape (L, k)
    """
    L, m = u.shape
    i0, j = _correction_count(poly_order, input_order, feedthrough)
    if j < i0:
        return np.zeros((L, 0))
    F, g = bank.realization()
    N = F.shape[0]
    cols = []
    if i0 == 0:
        exact = _ct_kernels.run_bank(F, g, t, u, input_order, uniform=uniform)
        approx = bank.filter(u, t, poly_order=poly_order, chain=filtering)
        cols.append((exact - approx).reshape(L, -1))
    k = j
    if k >= 1:
        Fa, Ga = _poisson_chain_bank(bank, k)
        Z = _ct_kernels.run_bank(Fa, Ga, t, u, input_order, uniform=uniform)   # (L, size, m)
        for i in range(k):
            exact = Z[:, k + i * N:k + (i + 1) * N, :]
            approx = bank.filter(Z[:, i, :], t, poly_order=poly_order, chain=filtering)
            cols.append((exact - approx).reshape(L, -1))
    return np.hstack(cols)


def _poisson_chain_bank(bank, k: int):
    """``(Fa, Ga)``: the system of the correction regressors of
    :func:`_correction_regressors`, a Poisson chain ``h_1 .. h_k`` of the
    slowest basis pole ``a``, each stage feeding a copy of the bank.

    State ``[h_1 .. h_k, bank_1 .. bank_k]``; its matrix is defective (a
    Jordan chain at ``a``) with every bank pole repeated ``k`` times.
    """
    F, g = bank.realization()
    N = F.shape[0]
    a = min(abs(z.real) for z in bank.poles)
    size = k + k * N
    Fa = np.zeros((size, size))
    Ga = np.zeros(size)
    Ga[0] = a
    for i in range(k):
        Fa[i, i] = -a
        if i:
            Fa[i, i - 1] = a
        blk = slice(k + i * N, k + (i + 1) * N)
        Fa[blk, i] = g
        Fa[blk, blk] = F
    return Fa, Ga


def _subspace_factor(R, Z, Y):
    """LQ factor of the signals ``[R, Z, Y]`` (columns) and the block revealing range(O).

    Returns the factor ``Lf`` (``[R Z Y]^T = Lf Q``) and ``W``: the block of
    ``Y`` on the instrument directions (``Y Pi_R^perp Z^T`` up to a right
    factor) when ``Z`` is given, else on its own directions (``Y Pi_R^perp``).
    """
    M = np.hstack([R, Y] if Z is None else [R, Z, Y])
    scale = np.sqrt(np.mean(M ** 2, axis=0))
    scale[scale == 0] = 1.0
    Lf = lq_lower((M / scale).T) * scale[:, None]
    nR = R.shape[1]
    nZ = 0 if Z is None else Z.shape[1]
    iY = slice(nR + nZ, M.shape[1])
    W = Lf[iY, nR:nR + nZ] if nZ else Lf[iY, iY]
    return Lf, W


# ---------------------------------------------------------------------------
# A, C
# ---------------------------------------------------------------------------
def _estimate_a_c(bank: FilterBank, Theta, p, ac_method):
    """A and C from ``O_k A = sum_j F_kj O_j + g_k C`` (k = 0..N-1)."""
    F, g = bank.realization()
    N = F.shape[0]
    n = Theta.shape[1]
    blocks = Theta.reshape(N, p, n)
    rhs = np.einsum("kj,jpn->kpn", F, blocks)
    if ac_method == "joint":
        reg = np.zeros((N, p, n + p))
        reg[:, :, :n] = blocks
        reg[:, :, n:] = -g[:, None, None] * np.eye(p)[None]
        reg = reg.reshape(N * p, n + p)
        sol = scipy.linalg.lstsq(reg, rhs.reshape(N * p, n), lapack_driver="gelsy",
                                 check_finite=False)[0]
        resid = reg @ sol - rhs.reshape(N * p, n)
        return sol[:n], sol[n:], float(np.linalg.norm(resid)
                                       / max(np.linalg.norm(rhs), 1e-300))
    # the paper: C eliminated between consecutive equations with g_k != 0 (for real
    # poles these rows are exactly M and R of (12)); the equations with g_k = 0
    # (second state of a complex pair) contain no C and are kept as they are
    live = np.flatnonzero(np.abs(g) > 0)
    lhs_rows = [blocks[a] / g[a] - blocks[b] / g[b] for a, b in zip(live[:-1], live[1:])]
    rhs_rows = [rhs[a] / g[a] - rhs[b] / g[b] for a, b in zip(live[:-1], live[1:])]
    for k in np.flatnonzero(g == 0):
        lhs_rows.append(blocks[k])
        rhs_rows.append(rhs[k])
    Mm = np.vstack(lhs_rows)
    Rm = np.vstack(rhs_rows)
    A = scipy.linalg.lstsq(Mm, Rm, lapack_driver="gelsy", check_finite=False)[0]  # (13)
    k0 = live[0]
    C = (blocks[k0] @ A - rhs[k0]) / g[k0]        # (14): O_0 (A + sigma_0 I) / sqrt(2 sigma_0)
    resid = np.linalg.norm(Mm @ A - Rm) / max(np.linalg.norm(Rm), 1e-300)
    return A, C, float(resid)


# ---------------------------------------------------------------------------
# B, D, x0
# ---------------------------------------------------------------------------
def _raw_regressors(A, C, t, u, input_order, feedthrough, estimate_x0, uniform):
    """Regressor of the raw output samples on ``[vec B, x0, vec D]``, or None.

    Row ``k p + i`` is output ``i`` at sample ``k``; column ``a m + j``
    multiplies ``B[a, j]``, then come ``x0`` and ``D[i, j]`` (column
    ``i m + j``). None when simulating ``A`` over the record overflows.
    """
    L, m = u.shape
    p, n = C.shape
    with np.errstate(over="ignore", invalid="ignore"):
        rows_b, rows_x = _ct_kernels.run_sensitivity(A, C, t, u, input_order, uniform=uniform)
    cols = [rows_b.reshape(L, p, n * m)]
    if estimate_x0:
        cols.append(rows_x)
    if feedthrough:
        Dreg = np.zeros((L, p, p * m))
        for i in range(p):
            Dreg[:, i, i * m:(i + 1) * m] = u
        cols.append(Dreg)
    R = np.concatenate(cols, axis=2).reshape(L * p, -1)
    # beyond 1e100 the squares in the least-squares solve overflow: treat as divergent
    return R if np.isfinite(R).all() and np.abs(R).max() < 1e100 else None


def _solve_raw(R, y):
    """Column-equilibrated least squares: (theta, residual, condition)."""
    scale = np.linalg.norm(R, axis=0)
    scale[scale == 0] = 1.0
    theta, _, _, sing = scipy.linalg.lstsq(R / scale, y.reshape(-1), lapack_driver="gelsd",
                                           check_finite=False)
    theta = theta / scale
    cond = float(sing[0] / sing[-1]) if sing.size and sing[-1] > 0 else float("inf")
    return theta, y.reshape(-1) - R @ theta, cond


def _fit_b_raw(A, C, t, u, y, input_order, feedthrough, estimate_x0, uniform):
    """B (D, x0) by least squares on the raw output samples; raises ModelError on overflow."""
    m = u.shape[1]
    p, n = C.shape
    R = _raw_regressors(A, C, t, u, input_order, feedthrough, estimate_x0, uniform)
    if R is None:
        raise ModelError("the identified A is unstable enough that simulating it over the "
                         "record overflows; use bd_method='filtered'")
    theta, resid, cond = _solve_raw(R, y)
    B = theta[:n * m].reshape(n, m)
    pos = n * m
    x0 = None
    if estimate_x0:
        x0 = theta[pos:pos + n]
        pos += n
    D = theta[pos:pos + p * m].reshape(p, m) if feedthrough else np.zeros((p, m))
    return B, D, x0, {"b_residual_rms": float(np.sqrt(np.mean(resid ** 2))),
                      "b_regression_condition": cond}


def _fit_x0(A, B, C, D, t, u, y, input_order, uniform):
    """Least-squares x0 for a complete model (None when the simulation overflows)."""
    L = u.shape[0]
    p, n = C.shape
    with np.errstate(over="ignore", invalid="ignore"):
        rows_b, rows_x = _ct_kernels.run_sensitivity(A, C, t, u, input_order, uniform=uniform)
        forced = np.einsum("lpnm,nm->lp", rows_b, B) + u @ D.T
    if not (np.isfinite(rows_x).all() and np.isfinite(forced).all()) \
            or max(np.abs(rows_x).max(), np.abs(forced).max()) > 1e100:
        return None
    return scipy.linalg.lstsq(rows_x.reshape(L * p, n), (y - forced).reshape(-1),
                              lapack_driver="gelsy", check_finite=False)[0]


def _fit_b_filtered(Tfun, Theta, Lf, iU, n, m, p, feedthrough):
    """Eq. (15): ``min ||Y - Theta X - T(B) U - (other regressors)||`` over X, B (, D).

    With the factor ``[phi; U; ...; Y]^T = L Q`` the regressors before ``U``
    only touch the columns before ``U``'s own, those after it the columns
    after; so only the block ``L_YU`` (``Y`` on ``U``'s own directions) depends
    on B, and ``Theta^perp`` (an orthonormal basis of range(Theta)'s
    complement) removes the free state sequence: minimise
    ``||Theta^perp^T (L_YU - T(B) L_UU)||_F``, linear in B (and D).
    """
    nY = Theta.shape[0]
    Qp = scipy.linalg.qr(Theta, mode="full", check_finite=False)[0][:, n:]
    LUU = Lf[iU, iU]
    LYU = Lf[Lf.shape[0] - nY:, iU]
    target = (Qp.T @ LYU).reshape(-1)
    T0 = Tfun(np.zeros((n, m)), None)
    cols = []
    for a in range(n):
        for j in range(m):
            Bm = np.zeros((n, m))
            Bm[a, j] = 1.0
            cols.append((Qp.T @ (Tfun(Bm, None) - T0) @ LUU).reshape(-1))
    if feedthrough:
        for i in range(p):
            for j in range(m):
                Dm = np.zeros((p, m))
                Dm[i, j] = 1.0
                cols.append((Qp.T @ (Tfun(np.zeros((n, m)), Dm) - T0) @ LUU).reshape(-1))
    R = np.column_stack(cols)
    theta, _, _, sing = scipy.linalg.lstsq(R, target, lapack_driver="gelsd",
                                           check_finite=False)
    B = theta[:n * m].reshape(n, m)
    D = theta[n * m:].reshape(p, m) if feedthrough else np.zeros((p, m))
    cond = float(sing[0] / sing[-1]) if sing[-1] > 0 else float("inf")
    resid = np.linalg.norm(R @ theta - target) / max(np.linalg.norm(target), 1e-300)
    return B, D, {"b_residual_relative": float(resid), "b_regression_condition": cond}


# ---------------------------------------------------------------------------
# instruments and refinement
# ---------------------------------------------------------------------------
def _stabilized(A):
    """``A`` with eigenvalues in the closed right half-plane mirrored."""
    lam, V = np.linalg.eig(A)
    if np.all(lam.real < 0):
        return A
    if np.linalg.cond(V) > 1e8:         # (nearly) defective: shift instead of mirroring
        return A - (lam.real.max() + 1e-3 * max(float(np.abs(lam).max()), 1.0)) * np.eye(len(lam))
    lam = -np.abs(lam.real) + 1j * lam.imag
    lam[lam.real == 0] -= 1e-6 * max(float(np.abs(lam).max()), 1.0)
    return np.real(V @ np.diag(lam) @ np.linalg.solve(V, np.eye(len(lam))))


def _simulated_states(A, B, x0, t, u, input_order, uniform):
    """States of the (stabilised) model along the record, or None on overflow."""
    n = A.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        X = _ct_kernels.run_bank(_stabilized(A), B, t, u, input_order, uniform=uniform,
                                 x0=np.zeros(n) if x0 is None else x0)[:, :, 0]
    return X if np.isfinite(X).all() else None


def _markov_change(old, new):
    """Relative change of ``C A^k B`` (k = 0..n): invariant to the state basis."""
    (Ao, Bo, Co), (An, Bn, Cn) = old, new
    worst = 0.0
    Po, Pn = Bo, Bn
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(Ao.shape[0] + 1):
            mo, mn = Co @ Po, Cn @ Pn
            change = np.linalg.norm(mo - mn) / max(np.linalg.norm(mo), 1e-300)
            worst = max(worst, float(change) if np.isfinite(change) else math.inf)
            Po, Pn = Ao @ Po, An @ Pn
    return worst


def _similarity_complement(A, C):
    """Orthonormal directions in (A, C) space transversal to similarity.

    The tangent of ``(T^{-1} A T, C T)`` at ``T = I`` is ``(A X - X A, C X)``;
    for an observable pair it has rank ``n^2``, and the remaining ``n p``
    left singular vectors span local coordinates of (A, C) modulo the state
    basis (data-driven local coordinates).
    """
    n = A.shape[0]
    cols = []
    for i in range(n):
        for j in range(n):
            X = np.zeros((n, n))
            X[i, j] = 1.0
            cols.append(np.concatenate([(A @ X - X @ A).ravel(), (C @ X).ravel()]))
    Uf = np.linalg.svd(np.column_stack(cols), full_matrices=True)[0]
    return Uf[:, n * n:]


def _refine_output_error(A, C, t, u, y, input_order, feedthrough, estimate_x0, uniform,
                         max_iterations):
    """Output-error refinement of (A, C) by variable projection.

    Minimises ``sum_k |y(t_k) - y_hat(t_k)|^2`` over (A, C) in local
    coordinates, B, D and x0 being eliminated by linear least squares for
    every (A, C). Levenberg-Marquardt with a finite-difference Jacobian;
    trial points with an unstable A get a large constant residual.
    """
    n, p = A.shape[0], C.shape[0]
    Q = _similarity_complement(A, C)
    base = np.concatenate([A.ravel(), C.ravel()])
    yv = y.reshape(-1)
    penalty = 1e3 * max(float(np.sqrt(np.mean(yv ** 2))), 1e-300)

    def unpack(theta):
        v = base + Q @ theta
        return v[:n * n].reshape(n, n), v[n * n:].reshape(p, n)

    def residual(theta):
        Ai, Ci = unpack(theta)
        if np.linalg.eigvals(Ai).real.max() >= 0:
            return np.full(yv.size, penalty)
        R = _raw_regressors(Ai, Ci, t, u, input_order, feedthrough, estimate_x0, uniform)
        if R is None:
            return np.full(yv.size, penalty)
        return _solve_raw(R, y)[1]

    zero = np.zeros(Q.shape[1])
    rms0 = float(np.sqrt(np.mean(residual(zero) ** 2)))
    sol = scipy.optimize.least_squares(residual, zero, method="lm", x_scale="jac",
                                       xtol=1e-12, ftol=1e-12, gtol=1e-12,
                                       max_nfev=max_iterations * (Q.shape[1] + 1))
    rms1 = float(np.sqrt(np.mean(sol.fun ** 2)))
    diag = {"refine_rms_before": rms0, "refine_evaluations": int(sol.nfev)}
    if not rms1 < rms0:
        diag.update(refined=False, refine_rms_after=rms0)
        return A, C, diag
    Ar, Cr = unpack(sol.x)
    diag.update(refined=True, refine_rms_after=rms1)
    return Ar, Cr, diag


# ---------------------------------------------------------------------------
# the method
# ---------------------------------------------------------------------------
@legacy_arguments(positional=("basis", "poly_order", "estimate_x0", "feedthrough"),
                  renamed={"input_hold": "hold", "b_method": "bd_method"})
@records_warnings
def ct_subspace(data, order=None, *, basis=None, poly_order: int = 3, estimate_x0: bool = True,
                feedthrough: bool = False, hold="foh", instruments="model",
                iterations: int = 10, tolerance: float = 1e-4, refine: bool = True,
                refine_iterations: int = 50, startup: bool = True, correction: bool = True,
                ac_method: str = "joint", bd_method: str = "simulation",
                filtering: str = "exact", data_equation: str = "compact",
                filtered=None) -> StateSpace:
    """Identify a continuous-time state-space model from sampled data (seed 002).

    Parameters
    ----------
    data : IOData
        Input/output samples on a uniform or non-uniform time grid.
    order : int, None, 'auto' or iterable of int
        Model order n. ``None`` picks it at the largest gap of the singular
        values (``info['singular_values']``) among 1..min(10, N p - p), or
        among the candidates given.
    basis : FilterBank, optional
        Basis filter bank (:func:`subid.basis.takenaka_malmquist`,
        :func:`~subid.basis.laguerre`, :func:`~subid.basis.legendre`).
        Default :func:`subid.basis.default_basis` of the time stamps.
    poly_order : int
        Degree p of the local polynomials interpolating the output samples
        (eq. (21); 3 in the paper).
    estimate_x0 : bool
        Estimate the initial state ``x(t_0)`` with B (``info['x0']``).
    feedthrough : bool
        Estimate D (else D = 0, as in the paper's model (1)).
    hold : {'foh', 'zoh', None}
        The input between samples: linear (first-order hold, the paper's
        Section V), constant (zero-order hold), or None when unknown: then it
        is interpolated like the output (degree ``poly_order``). The input is
        filtered and simulated exactly under this assumption, and the model
        records it (:attr:`StateSpace.hold`; ``'foh'`` for None), so that
        ``simulate``, ``fit_percent`` and the reports use it by default.
        (Formerly ``input_hold``, still accepted with a DeprecationWarning.)
    instruments : {'model', 'past', None}
        ``'model'``: after a first estimate, the SVD uses the correlation of
        the filtered outputs with the states of the model simulated from the
        input alone (re-estimated ``iterations`` times); consistent under output
        noise of any colour. ``'past'``: filtered inputs about two time
        constants of the slowest filter earlier (seed 001 style). None: the
        paper's projection, Lemma 3.
    iterations : int
        Maximum number of instrument iterations (``'model'``).
    tolerance : float
        The instrument iterations stop when the Markov parameters change by
        less than this (relative).
    refine : bool
        Refine (A, C) by output-error least squares on the raw samples (B, D,
        x0 eliminated by variable projection). ``info['subspace_model']``
        keeps the subspace estimate.
    refine_iterations : int
        Bound on Levenberg-Marquardt iterations (Jacobian evaluations).
    startup : bool
        Use the basis functions ``phi(t - t_0)`` as regressors: they absorb
        the filters' start-up transients and the initial-state response.
    correction : bool
        Use the interpolation-correction regressors (see the module notes).
    ac_method : {'joint', 'paper'}
        A and C by least squares on all block equations jointly, or as in the
        paper, (12)-(14) corrected.
    bd_method : {'simulation', 'filtered'}
        B (D, x0) by least squares on the raw output samples through the
        exactly discretised model, or from the filtered data equation (15).
        'simulation' falls back to 'filtered' if simulating A overflows
        (``info['bd_method_used']``). (Formerly ``b_method``, still accepted
        with a DeprecationWarning.)
    filtering : {'exact', 'sections'}
        Interpolate each signal once and propagate the whole filter chain
        exactly, or re-interpolate after every section (the paper's S1-S4).
    data_equation : {'compact', 'paper'}
        The N filtered inputs of (6'), or the paper's N (N + 1) / 2 stacked
        signals per input with the corrected T (real poles, no D).
    filtered : tuple of arrays, optional
        ``(u_f, y_f)``, shapes (L, N, m) and (L, N, p): filtered signals
        computed by the caller (e.g. exactly, for tests). They replace the
        filtering step; no correction regressors are used then.

    Returns
    -------
    StateSpace
        Continuous-time model (``dt = 0``) with the data's channel names.
        ``info`` holds the singular values, the chosen order, the basis, the
        options, residuals and condition numbers of the A/C and B steps,
        ``x0``, the instrument iterations and the refinement diagnostics.

    Raises
    ------
    DataError
        ``data`` is not an IOData, an output is constant, ``filtered`` is
        malformed.
    TooFewSamplesError
        Fewer samples than the data matrix has rows.
    NotExcitingError
        The filtered inputs are linearly dependent.
    OrderError
        ``order``, ``poly_order``, ``iterations`` invalid.
    ModelError
        ``basis`` is not a FilterBank, or the options need real poles.

    Examples
    --------
    >>> import numpy as np, subid
    >>> from subid.methods.ct.ct_subspace import ct_subspace
    >>> true = subid.StateSpace([[-1.0]], [[1.0]], [[2.0]], 0, dt=0.0)
    >>> t = np.arange(300) * 0.01
    >>> u = np.random.default_rng(0).standard_normal(300)
    >>> y = true.simulate(u, t=t, hold="foh")
    >>> model = ct_subspace(subid.IOData(u, y, t=t), 1)
    >>> float(np.round(model.poles()[0].real, 6))
    -1.0
    """
    method = "ct_subspace"
    data = _check_data(data, method)
    if basis is None:
        basis = default_basis(data.t)
    elif not isinstance(basis, FilterBank):
        raise ModelError(f"basis must be a subid.basis.FilterBank (takenaka_malmquist, "
                         f"laguerre, legendre), got {type(basis).__name__}")
    poly_order = check_int(poly_order, "poly_order", minimum=0)
    if poly_order > MAX_POLY_ORDER:
        raise OrderError(f"poly_order must be at most {MAX_POLY_ORDER}, got {poly_order}")
    for name, flag in (("estimate_x0", estimate_x0), ("feedthrough", feedthrough),
                       ("refine", refine), ("startup", startup), ("correction", correction)):
        check_bool(flag, name)
    check_choice(hold, "hold", ("foh", "zoh", None))
    check_choice(instruments, "instruments", ("model", "past", None))
    check_choice(ac_method, "ac_method", ("joint", "paper"))
    check_choice(bd_method, "bd_method", ("simulation", "filtered"))
    check_choice(filtering, "filtering", ("exact", "sections"))
    check_choice(data_equation, "data_equation", ("compact", "paper"))
    iterations = check_int(iterations, "iterations", minimum=0)
    refine_iterations = check_int(refine_iterations, "refine_iterations", minimum=1)
    if isinstance(tolerance, bool) or not isinstance(tolerance, numbers.Real) \
            or not tolerance > 0:
        raise OptionError(f"tolerance must be a positive number, got {tolerance!r}")
    if data_equation == "paper":
        if not basis.is_real:
            raise ModelError("data_equation='paper' needs real basis poles (the paper's "
                             "stacked input); use data_equation='compact' for complex poles")
        if feedthrough:
            raise ModelError("the paper's data equation (6) has no feedthrough term; use "
                             "data_equation='compact' with feedthrough=True")
        if filtered is not None:
            raise DataError("filtered signals can only be given with data_equation='compact'")

    t, u, y = data.t, data.u, data.y
    L, m = u.shape
    p = y.shape[1]
    N = basis.n_functions
    input_order = poly_order if hold is None else HOLD_ORDERS[hold]
    max_order = min(DEFAULT_MAX_ORDER, N * p - p)
    if max_order < 1:
        raise OrderError(f"a basis of {N} function(s) with {p} output(s) reveals no state: "
                         "use at least 2 basis functions")
    fixed, candidates = _parse_order(order, max_order)
    lag = _lag_for(basis, t) if instruments == "past" else 0

    # -- 1. filtered signals and regressors --------------------------------------
    n_u_rows = (N * (N + 1) // 2 if data_equation == "paper" else N) * m
    n_corr = 0
    if correction and filtered is None:
        i0, j = _correction_count(poly_order, input_order, feedthrough)
        n_corr = max(0, j - i0 + 1) * N * m
    rows = (N if startup else 0) + n_u_rows + n_corr + N * p \
        + (N * m if instruments == "past" else 0)
    need = max(rows + 1, poly_order + 1) + lag
    if L < need:
        raise TooFewSamplesError(
            f"{method}: {L} samples are too few for a basis of {N} functions with {m} "
            f"input(s) and {p} output(s): the data matrix has {rows} rows and needs at "
            f"least {need} samples; supply more data or use fewer basis functions")
    uniform = data.is_uniform
    if filtered is not None:
        uf, yf = _check_filtered(filtered, L, N, m, p)
    else:
        yf = basis.filter(y, t, poly_order=poly_order, chain=filtering)
        uf = basis.filter(u, t, poly_order=input_order, chain=filtering)
    if data_equation == "paper":
        U = basis.paper_input_stack(u, t, poly_order=input_order, chain=filtering)
        U = U.reshape(L, -1)
    else:
        U = uf.reshape(L, -1)
    Y = yf.reshape(L, -1)
    regs = []
    if startup:
        regs.append(basis.functions(t - t[0]))
    n_e = N if startup else 0
    regs.append(U)
    if n_corr:
        regs.append(_correction_regressors(basis, t, u, poly_order, input_order, feedthrough,
                                           filtering, uniform))
    R = np.hstack(regs)
    iU = slice(n_e, n_e + U.shape[1])

    # -- 2. range(O) ---------------------------------------------------------------
    Z = None
    if instruments == "past":
        Z = np.zeros_like(uf.reshape(L, -1))
        Z[lag:] = uf.reshape(L, -1)[:-lag]
    Lf, W = _subspace_factor(R, Z, Y)
    dU = np.abs(np.diag(Lf)[iU])
    if dU.max(initial=0.0) == 0 or (data_equation == "compact"
                                    and dU.min() <= _RANK_TOL * dU.max()):
        raise NotExcitingError(f"{method}: the filtered inputs are linearly dependent: the "
                               "input does not excite every basis function (is it zero, "
                               "constant, or are two inputs proportional?); use a richer "
                               "input (white noise, multisine)")
    Uo, sv, _ = np.linalg.svd(W, full_matrices=False)
    if fixed is None:
        n, order_selection = choose_order(
            None, [k for k in candidates if k < sv.size] or [candidates[0]], sv,
            "singular values")
    else:
        n, order_selection = fixed, None
    if n > sv.size:
        raise OrderError(f"order {n} exceeds the {sv.size} directions the instruments reveal")
    Theta = Uo[:, :n] * sv[:n]

    def complete(Theta, Lf):
        """A, C from Theta; then B, D, x0."""
        A, C, ac_resid = _estimate_a_c(basis, Theta, p, ac_method)
        diag = {"ac_residual": ac_resid}
        if bd_method == "simulation":
            try:
                B, D, x0, bd = _fit_b_raw(A, C, t, u, y, input_order, feedthrough,
                                          estimate_x0, uniform)
                diag.update(bd, bd_method_used="simulation")
                return A, B, C, D, x0, diag
            except ModelError:          # A too unstable to simulate over the record
                pass
        if data_equation == "paper":
            def Tfun(Bm, Dm):
                return tm_convolution_matrix(A, Bm, C, basis.poles)
        else:
            def Tfun(Bm, Dm):
                return data_equation_matrices(basis, A, Bm, C, Dm)[1]
        B, D, bd = _fit_b_filtered(Tfun, Theta, Lf, iU, n, m, p, feedthrough)
        x0 = _fit_x0(A, B, C, D, t, u, y, input_order, uniform) if estimate_x0 else None
        diag.update(bd, bd_method_used="filtered")
        return A, B, C, D, x0, diag

    A, B, C, D, x0, diag = complete(Theta, Lf)

    # -- 3. instruments from the model, iterated ---------------------------------------
    changes = []
    if instruments == "model":
        for _ in range(iterations):
            Xs = _simulated_states(A, B, x0, t, u, input_order, uniform)
            if Xs is None:
                break
            Lf, W = _subspace_factor(R, Xs, Y)
            Uo, s2, _ = np.linalg.svd(W, full_matrices=False)
            previous = (A, B, C)
            A, B, C, D, x0, diag = complete(Uo[:, :n] * s2[:n], Lf)
            changes.append(_markov_change(previous, (A, B, C)))
            if changes[-1] < tolerance:
                break
    subspace_model = {"A": A, "B": B, "C": C, "D": D}

    # -- 4. output-error refinement ---------------------------------------------------
    refine_diag = {"refined": False}
    if refine:
        Ar, Cr, refine_diag = _refine_output_error(_stabilized(A), C, t, u, y, input_order,
                                                   feedthrough, estimate_x0, uniform,
                                                   refine_iterations)
        if refine_diag["refined"]:
            A, C = Ar, Cr
            B, D, x0, bd = _fit_b_raw(A, C, t, u, y, input_order, feedthrough, estimate_x0,
                                      uniform)
            diag.update(bd, bd_method_used="simulation")

    conditions = {"bd": diag.get("b_regression_condition")}
    info = model_info(
        method, order=n, order_selection=order_selection, horizon=N, n_samples=L, x0=x0,
        hold="foh" if hold is None else hold,      # None: interpolated, closest to 'foh'
        conditions=conditions,
        rank_profile=sv,
        singular_values=sv,
        basis=basis.name,
        basis_poles=list(basis.poles),
        n_basis_functions=N,
        poly_order=poly_order,
        input_order=input_order,
        interpolated_input=hold is None,
        startup=startup,
        n_correction_regressors=n_corr,
        instruments=instruments,
        instrument_lag=lag if instruments == "past" else None,
        iterations=len(changes),
        iteration_changes=changes,
        ac_method=ac_method,
        bd_method=bd_method,
        filtering=filtering if filtered is None else "given",
        data_equation=data_equation,
        subspace_model=subspace_model,
        **diag,
        **refine_diag,
    )
    return StateSpace(A, B, C, D, 0.0, input_names=data.input_names,
                      output_names=data.output_names, info=info, hold=info["hold"])


@legacy_arguments(positional=("basis", "poly_order"))
def ct_subspace_paper(data, order=None, *, basis=None, poly_order: int = 3) -> StateSpace:
    """The paper's printed algorithm, with its typos corrected (seed 002).

    Data equation (6) with the stacked input and the corrected ``T``
    (:func:`tm_convolution_matrix`), both signals interpolated by degree-p
    polynomials and filtered section by section (S1-S4), no start-up or
    correction regressors, no instruments, A and C by (12)-(14), B by (15),
    no refinement. For comparison with :func:`ct_subspace`; real poles only.
    """
    return ct_subspace(data, order, basis=basis, poly_order=poly_order, estimate_x0=False,
                       feedthrough=False, hold=None, instruments=None, startup=False,
                       correction=False, refine=False, ac_method="paper", bd_method="filtered",
                       filtering="sections", data_equation="paper")


@legacy_arguments(positional=("method", "hold"))
@records_warnings
def dt_to_ct(data, order=None, *, method: str = "n4sid", hold: str = "zoh", **options):
    """Baseline: discrete-time subspace identification, then conversion to continuous time.

    Only possible on a uniform grid. The discrete-time model is identified
    with a feedthrough term (a first-order hold makes one appear even when
    the continuous system has none) and converted by
    :meth:`StateSpace.to_continuous` with the input's hold.

    Parameters
    ----------
    data : IOData
        Uniformly sampled record.
    order : int or None
    method : {'n4sid', 'moesp', 'ls'}
        A discrete-time batch method of :data:`subid.registry.METHODS`
        (``'ls_subspace'`` is accepted for ``'ls'``).
    hold : {'zoh', 'foh'}
        Inter-sample behaviour of the input; the model records it
        (:attr:`StateSpace.hold`).
    **options
        Passed to the discrete-time method (e.g. ``horizon``).

    Returns
    -------
    StateSpace
        Continuous-time model; ``info`` is the discrete method's, plus
        ``method`` and ``discrete_model_dt``.
    """
    from subid.methods.registry import find
    spec = find(method, kind="batch", time="discrete")
    check_choice(hold, "hold", ("zoh", "foh"))
    if not isinstance(data, IOData):
        raise DataError(f"dt_to_ct expects an IOData record, got {type(data).__name__}")
    if not data.is_uniform:
        raise DataError("dt_to_ct needs uniformly sampled data (a discrete-time model has "
                        "one sampling period); use ct_subspace for non-uniform time stamps")
    dmodel = spec.load()(data, order, feedthrough=True, **options)
    cmodel = dmodel.with_noise_model(None, None).to_continuous(hold)   # K has no CT form
    info = dict(cmodel.info)
    info.update(method=f"dt_to_ct({spec.attribute}, {hold})", discrete_model_dt=data.dt,
                hold=hold)
    return StateSpace(cmodel.A, cmodel.B, cmodel.C, cmodel.D, 0.0,
                      input_names=data.input_names, output_names=data.output_names, info=info,
                      hold=hold)
