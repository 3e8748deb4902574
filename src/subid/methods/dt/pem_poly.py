"""ARMAX, output-error and Box-Jenkins models by prediction-error minimisation.

:func:`armax`, :func:`oe` and :func:`bj` (MATLAB ``armax``, ``oe``, ``bj``)
minimise the one-step prediction-error criterion (Ljung, *System
Identification*, 2nd ed., 1999, Ch. 7, eq. 7.12) of the polynomial models

    ARMAX  A y = B u + C e           OE  y = B/F u + e
    BJ     y = B/F u + C/D e

output by output: multi-output ARMAX/OE/BJ models are not defined here
(MATLAB's multi-output ``armax``, ``oe`` and ``bj`` are also fitted as one
multi-input single-output model per output), so each output ``y_i`` gets
its own ``A_i``, ``C_i``, ``D_i`` and, for each input ``j``, ``B_ij`` and
``F_ij``; the outputs' models are stacked into one StateSpace
(:func:`subid.model.polynomial.realise`).

Start: a consistent estimate, the best (lowest criterion) of

* the ARX model of the same orders (:func:`subid.arx`; ``F = A`` for OE and
  BJ when every ``nf`` of the output is the same), which is exact on
  noise-free data;
* ARMAX: the Hannan-Rissanen estimate (Hannan & Rissanen, Biometrika 69,
  1982): a high-order ARX model gives the innovations ``ê``, then
  ``A, B, C`` by least squares with ``ê``'s lags as regressors;
* OE and BJ: each ``B_ij / F_ij`` fitted to the response ``x̂_ij`` of the
  high-order ARX model's ``B_ij / A_i`` to ``u_j`` (a model reduction of a
  consistent estimate; the high-order ARX is consistent for any noise model,
  Ljung 1999, Sec. 10.4) by Steiglitz-McBride iterations (least squares of
  the signals filtered by the last ``1/F``, :func:`_steiglitz_mcbride`; the
  first iterate is the plain least squares, whose equation error put the
  poles of oversampled plants far from the response's), and for BJ ``C/D`` by
  Hannan-Rissanen on the output-error residual.

Unstable ``C``, ``D`` and ``F`` roots of the start are reflected into the
unit circle (``1/conj(p)``), so the start's predictor is stable, and roots
are pulled within :data:`START_RADIUS`. For OE the search below runs from
every start with a stable predictor and keeps the least final criterion
(``info['starts_searched']``): the estimate is the criterion's global
minimum, and the searches from different starts end in different local
minima (DaISy dryer, ``oe(data, 4)``: 0.0042 from the start of the least
criterion, 0.0033 from the other); ARMAX and BJ search from the start of
the least criterion only (BJ's four starts each searched cost 12x on
DaISy evaporator).

Search: the coefficients are the parameters; the predictor of the
innovation form (:func:`subid.model.polynomial.realise`) is driven by
``[u, y_i]``, and its matrices are polynomials of degree at most two in the
coefficients (the observer form has the entries ``-a_k``, ``c_k - a_k``
and ``b_k - a_k b_0``), so their derivatives are the central differences
with unit step, exact to rounding. The Jacobian is then run by the compiled
sensitivity loop of :func:`subid.pem` and the same trust-region search
(:func:`subid.methods.dt._pe_search.minimise_prediction_error`), with the
predictor's initial state among the parameters. A trial with an unstable
predictor is rejected; the result never has a larger criterion than its
start (the start is kept when nothing improves).

Stop: scipy's tolerances (``tolerance``), the budget (``max_iterations``
evaluations), or a stall: once the evaluations left would, at the rate of the last
five accepted steps, decrease the criterion by less than a tenth of its statistical
scale ``d / (2N)`` (:data:`STALL_PRECISION`; ``d`` parameters, ``N`` samples, the
criterion whitened by the start's residual variance: the expected excess of the
criterion at the true parameters over its minimum, Ljung 1999, Sec. 9.2), the search
ends where it is (``info['stop_reason']`` says so). An over-parametrised noise model
(``C`` and ``D`` of a Box-Jenkins model nearly cancelling on white noise) leaves a flat
valley along which the search crawled to its budget: ``bj(data, (3, 3, 3, 3, 0))`` on
10^4 samples of a 2 x 2 system stops after 10 evaluations per output instead of 100,
0.2 s instead of 1.7, the same validation fit to 0.001 points; the DaISy defaults of
``oe``, ``armax`` and ``bj`` 104 -> 49 CPU s in all, their validation fits within 0.2
points but steamgen's ``armax`` (74.9 -> 74.3) and glassfurnace's ``oe`` (54.2 ->
54.8); the Monte Carlo medians of ``tests/test_polynomial.py`` unchanged.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.signal

from subid._blas import serial_blas
from subid._validation import check_bool, check_choice, check_optimiser_options, checked_call
from subid.errors import FeedbackWarning, SubidError
from subid.methods._info import collect_warnings
from subid.methods.dt import _pe_search
from subid.methods.dt._arx_nested import check_samples
from subid.methods.dt._pe_search import (
    _predictor,
    _radius,
    _simulate_experiments,
    _start_x0,
    kernel_pieces,
    minimise_prediction_error,
    statistical_precision,
)
from subid.methods.dt._poly_covariance import (
    attach_covariance,
    coefficient_factor_from_grams,
    sandwich_coefficient_factor,
)
from subid.methods.dt._sandwich import describe as describe_sandwich
from subid.methods.dt.feedthrough import feedback_test, feedback_warning
from subid.methods.dt.polynomial import (
    ORDER_NAMES,
    SELECTIONS,
    _check_input_columns,
    check_polynomial_data,
    polynomial_model,
    regress,
    regress_start,
    structure_orders,
)
from subid.model.polynomial import polynomial_record, realise

__all__ = ["armax", "oe", "bj"]

#: Largest order of the high-order ARX model behind the starts.
HIGH_ORDER = 50
#: A search stops once the evaluations it has left would, at the rate of its last steps,
#: decrease the criterion by less than this fraction of its statistical scale ``d / (2N)``
#: (:func:`subid.methods.dt._pe_search.statistical_precision`; the ``stall_tol`` of
#: :func:`subid.methods.dt._trust_region.trust_region_least_squares`).
STALL_PRECISION = 0.1
#: Root radius the start's C, D, F are pulled within (roots outside the unit circle are
#: reflected in first). 0.99 pulled the poles of slow or oversampled plants (0.999 and
#: 0.998: a 2nd-order plant with time constants of 1 and 0.5 s sampled at 1 kHz) to a
#: double pole at 0.99, from which every search ended on the stability boundary (a pole
#: at 1) at a criterion 10^3 times the optimum's: ``oe`` validated at 10-23 % there,
#: against 97.7-99.1 % for :func:`subid.pem` started from MOESP.
START_RADIUS = 0.9999
#: Steiglitz-McBride iterations of the reduction start of OE and BJ (module docstring).
STEIGLITZ_MCBRIDE_ITERATIONS = 10
#: Relative change of the denominator below which the Steiglitz-McBride iteration stops.
SETTLED = 1e-6
#: Samples (the last ones of a one-experiment record) the Steiglitz-McBride start reads.
START_SAMPLES = 100_000


def _stable(coef) -> np.ndarray:
    """Monic polynomial (in q^-1) with its roots outside the unit circle reflected in."""
    coef = np.asarray(coef, dtype=float)
    if coef.size <= 1:
        return coef
    roots = np.roots(coef)
    mag = np.abs(roots)
    if mag.size == 0 or mag.max() < START_RADIUS:
        return coef
    roots = np.where(mag > 1.0, 1.0 / np.conj(roots), roots)
    mag = np.abs(roots)
    roots = np.where(mag > START_RADIUS, roots / np.maximum(mag, 1e-300) * START_RADIUS, roots)
    return np.real(np.poly(roots))


class _Output:
    """The single-output sub-problem of output ``i``: orders, packing, predictor."""

    def __init__(self, structure, orders, i, nu):
        self.structure, self.nu = structure, nu
        self.na = int(orders["na"][i, i])
        self.nb = [int(v) for v in orders["nb"][i]]
        self.nk = [int(v) for v in orders["nk"][i]]
        self.nf = [int(v) for v in orders["nf"][i]]
        self.nc, self.nd = int(orders["nc"][i]), int(orders["nd"][i])
        self.lb = max(k + b for k, b in zip(self.nk, self.nb))
        self.size = self.na + sum(self.nb) + self.nc + self.nd + sum(self.nf)

    def record(self, theta):
        """The single-output polynomial record of the coefficients ``theta``."""
        nu = self.nu
        at = 0
        A = np.zeros((1, 1, self.na + 1))
        A[0, 0, 0] = 1.0
        A[0, 0, 1:] = theta[at:at + self.na]
        at += self.na
        B = np.zeros((1, nu, self.lb))
        for j in range(nu):
            B[0, j, self.nk[j]:self.nk[j] + self.nb[j]] = theta[at:at + self.nb[j]]
            at += self.nb[j]
        C = np.concatenate([[1.0], theta[at:at + self.nc]])[None]
        at += self.nc
        D = np.concatenate([[1.0], theta[at:at + self.nd]])[None]
        at += self.nd
        F = np.zeros((1, nu, max(self.nf) + 1))
        F[0, :, 0] = 1.0
        for j in range(nu):
            F[0, j, 1:self.nf[j] + 1] = theta[at:at + self.nf[j]]
            at += self.nf[j]
        return polynomial_record(self.structure, A=A, B=B, C=C, D=D, F=F, na=[[self.na]],
                                 nb=[self.nb], nc=[self.nc], nd=[self.nd], nf=[self.nf],
                                 nk=[self.nk])

    def pack(self, a, b, c, d, f):
        """``theta`` from ``a`` (1..na), ``b`` (list of nb_j), ``c``, ``d``, ``f`` (list)."""
        parts = [np.asarray(a, float)[:self.na]]
        parts += [np.asarray(bj, float)[:n] for bj, n in zip(b, self.nb)]
        parts += [np.asarray(c, float)[:self.nc], np.asarray(d, float)[:self.nd]]
        parts += [np.asarray(fj, float)[:n] for fj, n in zip(f, self.nf)]
        return np.concatenate(parts)

    def starts(self):
        """Where each polynomial's coefficients begin in ``theta`` (a, b_j, c, d, f_j):
        ``(b, c, d, f)``, ``b`` and ``f`` one index per input."""
        at, b, f = self.na, [], []
        for n in self.nb:
            b.append(at)
            at += n
        c, d = at, at + self.nc
        at = d + self.nd
        for n in self.nf:
            f.append(at)
            at += n
        return b, c, d, f

    def input_order(self, j):
        """The order of input j's block ``B_j / F_j`` in the OE and BJ realisations."""
        return max(self.nf[j], self.nk[j] + self.nb[j] - 1, 0)

    def blocks(self):
        """``(states, coordinates)`` of each input's block for an output-error model
        (whose predictor is block diagonal, :func:`block_jacobian`); None otherwise."""
        if self.structure != "oe":
            return None
        b_at, _, _, f_at = self.starts()
        out, at_state = [], 0
        for j in range(self.nu):
            p = self.input_order(j)
            coords = list(range(b_at[j], b_at[j] + self.nb[j])) + \
                list(range(f_at[j], f_at[j] + self.nf[j]))
            out.append((np.arange(at_state, at_state + p), np.array(coords, dtype=np.int64)))
            at_state += p
        return out

    def predictor(self, theta):
        A, B, C, D, K = realise(self.record(theta))
        return _predictor(A, B, C, D, K, "prediction")

    def directions(self, theta):
        """Derivatives of the predictor along every coefficient, then the x0 rows:
        ``(dAp, dBp, dC, dDp, dx0)``, each with ``size + n`` leading rows.

        The predictor's matrices are polynomials of degree <= 2 in ``theta`` (module
        docstring), so the unit-step central difference of two realisations per
        coefficient would be exact; the derivatives are written out from the observer
        form instead (equal to those differences to rounding, tests/test_polynomial.py).
        :func:`subid.model.polynomial.realise` realises ARMAX in the observer form of
        ``A^-1 [B_1 .. B_nu, C]`` (order ``p = max(na, nk_j + nb_j - 1, nc)``: first
        column of A ``-a[1..p]``, B ``b_j[1..p] - a[1..p] b_j[0]``, gain K ``c[1..p] -
        a[1..p]``, C ``e_1``, D ``b_j[0]``); OE and BJ input by input, the observer form
        of ``B_j / F_j`` (order :meth:`input_order`: first column ``-f_j[1..p_j]``, B
        ``b_j[1..p_j] - f_j[1..p_j] b_j[0]``, C ``e_1``, D ``b_j[0]``), then that of the
        noise ``C / D`` (order ``max(nc, nd)``: first column ``-d[1..]``, K ``c[1..] -
        d[1..]``). The predictor is ``(A - K C, [B - K D, K], C, [D, 0])``. Along a
        coefficient, in the rows of its block: ``b_j`` at lag ``l >= 1`` moves ``B[l - 1,
        j]``; ``b_j[0]`` moves ``D[0, j]`` and ``B[., j]`` by minus the denominator (``a``
        or ``f_j``); a denominator coefficient at lag ``l`` moves the first column's
        ``A[l - 1, 0]`` by -1 and ``B[l - 1, j]`` by ``-b_j[0]`` (ARMAX: every j, and
        ``K[l - 1]`` by -1); ``c`` at lag ``l`` moves ``K[l - 1]`` by +1; ``d`` at lag ``l``
        moves ``K[l - 1]`` by -1 and ``A[l - 1, 0]`` by -1.
        """
        A, B, C, D, K = realise(self.record(theta))
        n, nu, d = A.shape[0], self.nu, self.size
        dA, dB, dK = np.zeros((d, n, n)), np.zeros((d, n, nu)), np.zeros((d, n))
        dD = np.zeros((d, nu))
        b_at, c_at, d_at, f_at = self.starts()
        b0 = [theta[b_at[j]] if self.nk[j] == 0 and self.nb[j] > 0 else 0.0
              for j in range(nu)]

        def b_terms(j, row, p, den):
            # b_j along its coefficients: D (lag 0, with B by minus the denominator), B
            for m in range(self.nb[j]):
                lag, k = self.nk[j] + m, b_at[j] + m
                if lag == 0:
                    dD[k, j] = 1.0
                    dB[k, row:row + p, j] = -den[1:]
                else:
                    dB[k, row + lag - 1, j] = 1.0

        if self.structure == "armax":
            a = np.zeros(n + 1)
            a[0] = 1.0
            a[1:self.na + 1] = theta[:self.na]
            for m in range(self.na):
                dA[m, m, 0] = -1.0
                dB[m, m, :] = -np.asarray(b0)
                dK[m, m] = -1.0
            for j in range(nu):
                b_terms(j, 0, n, a)
            for m in range(self.nc):
                dK[c_at + m, m] = 1.0
        else:
            row = 0
            for j in range(nu):
                p = self.input_order(j)
                f = np.zeros(p + 1)
                f[0] = 1.0
                f[1:self.nf[j] + 1] = theta[f_at[j]:f_at[j] + self.nf[j]]
                b_terms(j, row, p, f)
                for m in range(self.nf[j]):
                    dA[f_at[j] + m, row + m, row] = -1.0
                    dB[f_at[j] + m, row + m, j] = -b0[j]
                row += p
            for m in range(self.nc):
                dK[c_at + m, row + m] = 1.0
            for m in range(self.nd):
                dA[d_at + m, row + m, row] = -1.0
                dK[d_at + m, row + m] = -1.0
        # the predictor (A - K C, [B - K D, K], C, [D, 0]) along each coefficient
        Kc = K[:, 0]
        dAp = dA - dK[:, :, None] * C[0][None, None, :]
        dBu = dB - dK[:, :, None] * D[0][None, None, :] - Kc[None, :, None] * dD[:, None, :]
        out_A = np.zeros((d + n, n, n))
        out_A[:d] = dAp
        out_B = np.zeros((d + n, n, nu + 1))
        out_B[:d, :, :nu] = dBu
        out_B[:d, :, nu] = dK
        out_C = np.zeros((d + n, 1, n))
        out_D = np.zeros((d + n, 1, nu + 1))
        out_D[:d, 0, :nu] = dD
        dx0 = np.zeros((d + n, n))
        dx0[d:] = np.eye(n)
        return out_A, out_B, out_C, out_D, dx0


def _cost(sub, theta, v, y, ranges):
    """``(cost, x0s)`` of the predictor of ``theta`` with least-squares initial states;
    inf for an unstable predictor."""
    Ap, Bp, Cp, Dp = sub.predictor(theta)
    n = Ap.shape[0]
    y = y[:, None]
    if not np.isfinite(theta).all() or (n and _radius(Ap) >= 1.0 - 1e-9):
        return math.inf, None
    with np.errstate(all="ignore"):
        x0 = np.stack([_start_x0(Ap, Bp, Cp, Dp, v[a:b], y[a:b]) if n else np.zeros(0)
                       for a, b in ranges])
        yhat = _simulate_experiments(Ap, Bp, Cp, Dp, v, x0, ranges)[0]
    cost = 0.5 * float(np.mean((y - yhat) ** 2))
    return (cost if math.isfinite(cost) else math.inf), x0


def _high_order(n_samples, nu, needed):
    return int(max(min(HIGH_ORDER, n_samples // (10 * (nu + 1))), needed + 2))


def _filter(b, a, x):
    with np.errstate(all="ignore"):
        return scipy.signal.lfilter(b, a, x)


def _arx_start(sub, u, y, ranges, na):
    """ARX of the output's orders with autoregression degree ``na``: ``(a, b)``."""
    blocks = [(u[:, j], range(sub.nk[j], sub.nk[j] + sub.nb[j])) for j in range(sub.nu)]
    blocks.append((y, range(1, na + 1)))
    first = max(na, sub.lb - 1)
    theta, resid, _ = regress(y, blocks, ranges, first)
    at, b = 0, []
    for j in range(sub.nu):
        b.append(theta[at:at + sub.nb[j]])
        at += sub.nb[j]
    return -theta[at:at + na], b


def _high_order_arx(sub, u, y, ranges):
    """A high-order ARX model of the output: ``(a, b_list, residual, h)``."""
    h = _high_order(y.size, sub.nu, max([sub.na, sub.nc, sub.nd] + sub.nf + [sub.lb]))
    k0 = min(sub.nk)
    blocks = [(u[:, j], range(k0, k0 + h)) for j in range(sub.nu)] + [(y, range(1, h + 1))]
    theta, resid = regress_start(y, blocks, ranges, h + k0)
    b = [np.concatenate([np.zeros(k0), theta[j * h:(j + 1) * h]]) for j in range(sub.nu)]
    a = np.concatenate([[1.0], -theta[sub.nu * h:]])
    return a, b, np.nan_to_num(resid), h


def _hannan_rissanen(target, ehat, lags_ar, nc, extra_blocks, ranges, first):
    """Least squares of ``target - ehat`` on ``lags_ar`` of ``target``, ``ehat``'s lags
    1..nc and ``extra_blocks``: ``(ar_coefficients, c, extra_theta)``."""
    blocks = list(extra_blocks) + [(target, range(1, lags_ar + 1)), (ehat, range(1, nc + 1))]
    theta, _, _ = regress(target - ehat, blocks, ranges, first)
    m = sum(len(lags) for _, lags in extra_blocks)
    return -theta[m:m + lags_ar], theta[m + lags_ar:], theta[:m]


def _steiglitz_mcbride(u, x, nb, nf, nk, ranges):
    """``(b, f)``: ``B/F`` (``nb`` coefficients from lag ``nk``, ``nf`` poles) fitted to
    the response ``x`` to ``u`` by the Steiglitz-McBride iteration (Steiglitz & McBride,
    IEEE Trans. Automatic Control 10, 1965; Stoica & Söderström, Automatica 17, 1981):
    least squares of ``x/F`` on the lags of ``u/F`` and ``x/F``, ``F`` the last
    iterate's denominator (none at first, which is the plain equation-error fit). The
    equation error weighs the fit by ``F``, i.e. towards high frequencies: on an
    oversampled plant the plain fit put the poles far from the response's; the
    iteration's fixed point has the output-error fit's stationarity condition on
    noise-free ``x``. Stopped after :data:`STEIGLITZ_MCBRIDE_ITERATIONS`, once the
    denominator changes by less than :data:`SETTLED` (relative), or when a filtered
    signal is not finite (the last finite iterate is kept)."""
    f = np.zeros(nf)
    b = np.zeros(nb)
    first = max(nf, nk + nb - 1)
    if len(ranges) == 1 and u.size > START_SAMPLES:
        # a start: the last START_SAMPLES samples of a long record suffice (the ten
        # passes over 10^6 samples were 8 of the 29 s of oe(data, 2))
        u, x, ranges = u[-START_SAMPLES:], x[-START_SAMPLES:], [(0, START_SAMPLES)]
    for _ in range(STEIGLITZ_MCBRIDE_ITERATIONS):
        den = np.concatenate([[1.0], f])
        uf, xf = _filter([1.0], den, u), _filter([1.0], den, x)
        if not (np.isfinite(uf).all() and np.isfinite(xf).all()):
            break
        blocks = [(uf, range(nk, nk + nb)), (xf, range(1, nf + 1))]
        theta, _, _ = regress(xf, blocks, ranges, first)
        b, f_new = theta[:nb], _stable(np.concatenate([[1.0], -theta[nb:]]))[1:]
        settled = f_new.size == 0 or \
            np.max(np.abs(f_new - f)) <= SETTLED * max(1.0, float(np.max(np.abs(f_new))))
        f = f_new
        if settled:                       # a fixed point: further passes change nothing
            break
    return b, f


def _starts(sub, u, y, ranges):
    """Candidate start coefficient vectors (module docstring)."""
    out = []
    structure = sub.structure
    if structure == "armax":
        a, b = _arx_start(sub, u, y, ranges, sub.na)
        out.append(sub.pack(a, b, np.zeros(sub.nc), [], [[]] * sub.nu))
        if sub.nc:
            _, _, ehat, h = _high_order_arx(sub, u, y, ranges)
            first = h + max(sub.na, sub.lb - 1, sub.nc)
            blocks = [(u[:, j], range(sub.nk[j], sub.nk[j] + sub.nb[j])) for j in range(sub.nu)]
            a2, c2, bt = _hannan_rissanen(y, ehat, sub.na, sub.nc, blocks, ranges, first)
            # HR regresses y - ê on ê's lags: the ê(t) term has coefficient one (monic C)
            b2, at = [], 0
            for j in range(sub.nu):
                b2.append(bt[at:at + sub.nb[j]])
                at += sub.nb[j]
            out.append(sub.pack(a2, b2, _stable(np.concatenate([[1.0], c2]))[1:], [],
                                [[]] * sub.nu))
        return out
    # OE and BJ: the plant's starts
    plants = []
    if len(set(sub.nf)) == 1:
        a, b = _arx_start(sub, u, y, ranges, sub.nf[0])
        f = _stable(np.concatenate([[1.0], a]))[1:]
        plants.append((b, [f] * sub.nu))
    a_h, b_h, _, _ = _high_order_arx(sub, u, y, ranges)
    b_red, f_red = [], []
    for j in range(sub.nu):
        x = _filter(b_h[j], a_h, u[:, j])
        if not np.isfinite(x).all():
            break
        b, f = _steiglitz_mcbride(u[:, j], x, sub.nb[j], sub.nf[j], sub.nk[j], ranges)
        b_red.append(b)
        f_red.append(f)
    else:
        plants.append((b_red, f_red))
    for b, f in plants:
        if structure == "oe":
            out.append(sub.pack([], b, [], [], f))
            continue
        out.append(sub.pack([], b, np.zeros(sub.nc), np.zeros(sub.nd), f))
        if sub.nc or sub.nd:
            v = y.copy()
            for j in range(sub.nu):
                bj = np.zeros(sub.nk[j] + sub.nb[j])
                bj[sub.nk[j]:] = b[j]
                v -= _filter(bj, np.concatenate([[1.0], f[j]]), u[:, j])
            if not np.isfinite(v).all():
                continue
            h = _high_order(y.size, 0, max(sub.nc, sub.nd))
            _, ehat = regress_start(v, [(v, range(1, h + 1))], ranges, h)
            ehat = np.nan_to_num(ehat)
            d, c, _ = _hannan_rissanen(v, ehat, sub.nd, sub.nc, [], ranges,
                                       h + max(sub.nc, sub.nd))
            out.append(sub.pack([], b, _stable(np.concatenate([[1.0], c]))[1:],
                                _stable(np.concatenate([[1.0], d]))[1:], f))
    return out


def _fit_output(sub, u, y, ranges, *, estimate_x0, max_iterations, tolerance):
    """The coefficients of one output: start, then prediction-error search."""
    v = np.hstack([u, y[:, None]])
    costs = []
    for theta in _starts(sub, u, y, ranges):
        cost, x0 = _cost(sub, theta, v, y, ranges)
        if not estimate_x0 and x0 is not None:
            x0 = np.zeros_like(x0)
            cost = _cost_fixed(sub, theta, v, y, ranges, x0)
        costs.append((cost, len(costs), theta, x0))
    costs.sort(key=lambda c: (c[0], c[1]))
    if not math.isfinite(costs[0][0]):
        raise SubidError(f"{sub.structure}: no start with a stable predictor was found; "
                         "try lower orders")
    # OE: a search from every start with a stable predictor, the least final criterion
    # kept: the estimate is the criterion's global minimum, which a local search from the
    # start of the least criterion missed (on DaISy dryer, oe (4, 4, 1): 0.0042 against
    # 0.0033 from the other start; Ljung 1999, Sec. 10.5). ARMAX and BJ: from the start
    # of the least criterion (BJ's four starts searched each cost 12x on DaISy evaporator)
    best, evaluations = None, 0
    for cost0, _, theta0, x00 in (costs if sub.structure == "oe" else costs[:1]):
        if not math.isfinite(cost0):
            break
        got = _search(sub, theta0, x00, cost0, v, y, ranges, estimate_x0=estimate_x0,
                      max_iterations=max_iterations, tolerance=tolerance)
        evaluations += got[2]["n_evaluations"]
        if best is None or got[2]["final_cost"] < best[2]["final_cost"]:
            best = got
        if got[2]["stop_reason"].startswith("the start fits"):
            break                         # noise-free: nothing to improve
    best[2].update(n_evaluations=evaluations, starts_searched=sum(
        math.isfinite(c[0]) for c in costs) if sub.structure == "oe" else 1)
    return best


def _search(sub, theta0, x00, cost0, v, y, ranges, *, estimate_x0, max_iterations,
            tolerance):
    """``(theta, x0, record)``: the prediction-error search of one output from one start
    (``theta0``, its initial state ``x00`` and criterion ``cost0``)."""
    record = {"start_cost": cost0, "final_cost": cost0, "n_evaluations": 0,
              "stop_reason": "start kept"}
    if cost0 <= 1e-24 * max(0.5 * float(np.mean(y ** 2)), 1e-300):
        record["stop_reason"] = "the start fits the data to rounding (noise-free): kept"
        return theta0, x00, record
    sigma = math.sqrt(2.0 * cost0)
    W = np.array([[1.0 / sigma]])
    history = []
    penalty = math.sqrt(2.0 * (10.0 * 0.5 + 1.0) / y.size)    # cost 10x the start's + 1
    d = sub.size + (x00.size if estimate_x0 else 0)
    stall = statistical_precision(d, y.size, STALL_PRECISION)
    z, res = minimise_prediction_error(lambda dz: sub.predictor(theta0 + dz),
                                       lambda dz: sub.directions(theta0 + dz), sub.size, x00, v,
                                       y[:, None], ranges, W, max_iterations, tolerance,
                                       history, penalty, fit_x0=estimate_x0,
                                       blocks=sub.blocks(), stall_tol=stall)
    record["n_evaluations"] = int(res.nfev)
    new_cost = float(res.cost) * sigma ** 2
    if new_cost < cost0:
        theta = theta0 + z[:sub.size]
        x0 = x00 + z[sub.size:].reshape(x00.shape) if estimate_x0 else x00
        record.update(final_cost=new_cost, stop_reason=str(res.message))
        return theta, x0, record
    record["stop_reason"] = f"no improvement on the start ({res.message}); start kept"
    return theta0, x00, record


def _cost_fixed(sub, theta, v, y, ranges, x0):
    Ap, Bp, Cp, Dp = sub.predictor(theta)
    y = y[:, None]
    with np.errstate(all="ignore"):
        yhat = _simulate_experiments(Ap, Bp, Cp, Dp, v, x0, ranges)[0]
    cost = 0.5 * float(np.mean((y - yhat) ** 2))
    return cost if math.isfinite(cost) else math.inf


def _stack(records, structure, orders):
    """The multi-output record from the single-output ones."""
    ny = len(records)
    nu = records[0]["B"].shape[1]

    def cat(key):                      # (1, nu, l) per output -> (ny, nu, max l)
        length = max(r[key].shape[-1] for r in records)
        out = np.zeros((ny, nu, length))
        for i, r in enumerate(records):
            out[i, :, :r[key].shape[-1]] = r[key][0]
        return out
    A = np.zeros((ny, ny, max(r["A"].shape[-1] for r in records)))
    for i, r in enumerate(records):
        A[i, i, :r["A"].shape[-1]] = r["A"][0, 0]
    C = np.zeros((ny, max(r["C"].shape[-1] for r in records)))
    D = np.zeros((ny, max(r["D"].shape[-1] for r in records)))
    for i, r in enumerate(records):
        C[i, :r["C"].shape[-1]] = r["C"][0]
        D[i, :r["D"].shape[-1]] = r["D"][0]
    return polynomial_record(structure, A=A, B=cat("B"), C=C, D=D, F=cat("F"),
                             na=orders["na"], nb=orders["nb"], nc=orders["nc"],
                             nd=orders["nd"], nf=orders["nf"], nk=orders["nk"])


def _identify(structure, data, order, selection, estimate_x0, max_iterations, tolerance):
    check_choice(selection, "selection", SELECTIONS)
    check_bool(estimate_x0, "estimate_x0")
    check_optimiser_options(max_iterations, tolerance)
    data = check_polynomial_data(data, structure)
    ny, nu = data.n_outputs, data.n_inputs
    with collect_warnings() as issued:
        orders, selection_record = structure_orders(order, structure, data)
        feedback = _output_error_feedback(structure, data, selection_record)
        ranges = data.experiment_ranges
        records, fits, fitted = [], [], []
        for i in range(ny):
            sub = _Output(structure, orders, i, nu)
            first = max(sub.na, sub.lb - 1, max(sub.nf), sub.nc, sub.nd)
            check_samples(data.experiment_ranges, data.n_samples, sub.size, first, structure)
            blocks = [(data.u[:, j], range(sub.nk[j], sub.nk[j] + sub.nb[j]))
                      for j in range(nu)]
            _, _, R = regress(data.y[:, i], blocks, ranges, first)
            _check_input_columns(R, [f"input {data.input_names[j]} at lag {lag}"
                                     for j in range(nu)
                                     for lag in range(sub.nk[j], sub.nk[j] + sub.nb[j])],
                                 structure)
            theta, x0, fit = _fit_output(sub, data.u, data.y[:, i], ranges,
                                         estimate_x0=estimate_x0,
                                         max_iterations=max_iterations, tolerance=tolerance)
            records.append(sub.record(theta))
            fits.append(fit)
            fitted.append((sub, theta, x0))
        resid, grams, widths = _covariance_pass(fitted, data, estimate_x0)
        n_nuisance = [w - sub.size for w, (sub, _, _) in zip(widths, fitted)]
        method = ("asymptotic prediction-error covariance lambda (sum psi psi^T)^-1 per "
                  "output (Ljung 1999, Theorem 9.1)")
        if structure == "oe":          # output error: the disturbance need not be white
            lag = {}
            factor, designs = sandwich_coefficient_factor(
                lambda: _design_blocks(fitted, data, estimate_x0), grams, widths, resid,
                n_nuisance, data.experiment_ranges, lag), None
            method = "asymptotic output-error covariance per output, " + \
                describe_sandwich(lag.get("lag", 0))
        else:
            factor, designs = coefficient_factor_from_grams(grams, widths, resid,
                                                            n_nuisance), None
        if factor[0] is None and structure != "oe":      # the QR route: designs whole
            designs = [_sensitivities(sub, theta, x0, np.hstack([data.u, data.y[:, i:i + 1]]),
                                      ranges, estimate_x0)[1]
                       for i, (sub, theta, x0) in enumerate(fitted)]
            factor = None
        poly = _stack(records, structure, orders)
        model = polynomial_model(
            data, poly, method=structure, order_selection=selection_record, residuals=resid,
            conditions={}, rank_profile=np.sort(np.abs(np.diag(R)))[::-1],
            orders={k: orders[k] for k in ORDER_NAMES[structure]},
            start_cost=[f["start_cost"] for f in fits],
            final_cost=[f["final_cost"] for f in fits],
            n_evaluations=[f["n_evaluations"] for f in fits],
            stop_reason=[f["stop_reason"] for f in fits],
            starts_searched=[f["starts_searched"] for f in fits],
            multi_output="one multi-input single-output model per output" if ny > 1
            else None)
        attach_covariance(model, designs, resid, n_nuisance,
                          method + ", the predictors' initial states eliminated, with the "
                          "outputs' cross-covariances; mapped to the realisation's "
                          "matrices", factor=factor)
        if not estimate_x0:
            model.info["x0"] = None
        if feedback is not None:
            model.info["feedback"] = feedback
    model.info["warnings"] = list(issued)
    return model


def _output_error_feedback(structure, data, selection_record):
    """For ``oe``: the feedback test (:func:`subid.methods.dt.feedthrough.feedback_test`,
    the structure search's where it ran), with a :class:`subid.errors.FeedbackWarning`
    when it shows feedback at :data:`~subid.methods.dt.feedthrough.WARNING_LEVEL`: the
    output-error criterion is biased in closed loop, its input being correlated with the
    noise (Ljung 1999, Sec. 13.4; on the DaISy ballbeam
    record, an unstable plant under feedback, ``oe`` validates at 30.7 % against
    ``arx``'s 89.7 %). None for the other structures, whose noise models keep the
    prediction-error estimate consistent there."""
    if structure != "oe":
        return None
    ran = (selection_record or {}).get("delays", {}).get("feedback")
    record = ran if isinstance(ran, dict) else feedback_test(data)
    if (p_value := feedback_warning(record)) is not None:
        warnings.warn(f"oe: the data show feedback from the outputs to the inputs "
                      f"{p_value}: an output-error model is biased in "
                      "closed loop, because the input is correlated with the noise (Ljung "
                      "1999, Sec. 13.4); compare it on validation data with armax or arx, "
                      "which are consistent there (bj too, but like oe it keeps its plant "
                      "B/F stable: not for an unstable plant in the loop), or with "
                      "subid.identify",
                      FeedbackWarning, stacklevel=4)
    return record


def _design_pieces(sub, theta, x0, v, ranges, estimate_x0, rows=None):
    """``(a, b, ŷ[a:b], J[a:b])`` of output ``sub`` at ``theta``, in order over the
    record, at most ``rows`` samples a piece (default: one piece per experiment): the
    one-step prediction and its derivatives, the initial states' columns first (one
    block per experiment; none when they are not estimated), then the coefficients'.
    Each piece's kernel continues from the state and sensitivities where the last one
    ended."""
    mats = [np.ascontiguousarray(a) for a in sub.predictor(theta)]
    dirs = [np.ascontiguousarray(a) for a in sub.directions(theta)]
    d = sub.size
    n = mats[0].shape[0]
    n_x0 = len(ranges) * n if estimate_x0 else 0
    x0 = np.asarray(x0, dtype=float).reshape(len(ranges), n)
    for e, s, t, ye, Je in kernel_pieces(mats, dirs, v, x0, ranges, rows, sub.blocks(), d):
        J = np.zeros((t - s, n_x0 + d))
        J[:, n_x0:] = Je[:, 0, :d]
        if estimate_x0:
            J[:, e * n:(e + 1) * n] = Je[:, 0, d:]
        yield s, t, ye[:, 0], J


def _sensitivities(sub, theta, x0, v, ranges, estimate_x0):
    """``(ŷ, J)`` of output ``sub`` at ``theta`` over the whole record
    (:func:`_design_pieces` joined)."""
    pieces = list(_design_pieces(sub, theta, x0, v, ranges, estimate_x0))
    return np.concatenate([p[2] for p in pieces]), np.concatenate([p[3] for p in pieces])


def _design_blocks(fitted, data, estimate_x0):
    """Every output's design rows (:func:`_design_pieces`), the same samples at a time
    (those of :func:`_covariance_pass`), in order over the record: a list per block."""
    widths = [sub.size + (np.size(x0) if estimate_x0 else 0) for sub, _, x0 in fitted]
    rows = max(1, int(_pe_search.JACOBIAN_PIECE_BYTES // (8 * max(widths))))
    streams = [_design_pieces(sub, theta, x0, np.hstack([data.u, data.y[:, i:i + 1]]),
                              data.experiment_ranges, estimate_x0, rows)
               for i, (sub, theta, x0) in enumerate(fitted)]
    for pieces in zip(*streams):
        yield [p[3] for p in pieces]


def _covariance_pass(fitted, data, estimate_x0):
    """The residuals (N, ny) of the outputs' fitted predictors and the Gram blocks
    ``J_i^T J_j`` of their designs (:func:`_design_pieces`), the designs formed a piece
    of at most :data:`subid.methods.dt._pe_search.JACOBIAN_PIECE_BYTES` per output at a
    time, every output at the same samples: the covariance of a long record without its
    designs whole (:func:`subid.methods.dt._poly_covariance.coefficient_factor_from_grams`;
    at 10^6 samples of a 2 x 2 ``armax`` model they were 0.5 GB). ``fitted``: ``(sub,
    theta, x0)`` per output. Returns ``(residuals, grams, widths)``."""
    ranges = data.experiment_ranges
    ny = data.n_outputs
    # the coefficients, and the initial states (one per experiment) where estimated
    widths = [sub.size + (np.size(x0) if estimate_x0 else 0) for sub, _, x0 in fitted]
    rows = max(1, int(_pe_search.JACOBIAN_PIECE_BYTES // (8 * max(widths))))
    resid = np.empty_like(data.y)
    grams = {(i, j): np.zeros((widths[i], widths[j])) for i in range(ny) for j in range(i, ny)}
    streams = [_design_pieces(sub, theta, x0, np.hstack([data.u, data.y[:, i:i + 1]]),
                              ranges, estimate_x0, rows)
               for i, (sub, theta, x0) in enumerate(fitted)]
    for pieces in zip(*streams):
        for i, (a, b, yh, J) in enumerate(pieces):
            resid[a:b, i] = data.y[a:b, i] - yh
            for j in range(i, ny):
                grams[(i, j)] += J.T @ pieces[j][3]
    return resid, grams, widths


@serial_blas
@checked_call
def armax(data, order=None, *, selection="cv", estimate_x0=True, max_iterations=100,
          tolerance=1e-8):
    """Identify an ARMAX model ``A y = B u + C e`` by prediction-error minimisation.

    MATLAB ``armax``; one multi-input single-output model per output (module
    docstring), started from the better of the ARX estimate and the
    Hannan-Rissanen estimate.

    Parameters
    ----------
    data : IOData
        Uniformly sampled record with at least one input.
    order : tuple, dict, int, 'auto' or None
        MATLAB's ``(na, nb, nc, nk)``: ``na``, ``nc`` scalars or one per
        output, ``nb``, ``nk`` scalars or (ny, nu) arrays. An integer ``n``:
        ``na = nc = n``, ``nk`` from :func:`subid.estimate_delay`, ``nb = n``
        (``n + 1`` where ``nk = 0``). None/'auto': see ``selection``. A
        dict of them by name (``model.info['orders']``) reproduces the
        structure of ``model``.
    selection : {'cv'}
        How a structure not given is chosen: the degrees of the ARX
        structure :func:`subid.arx` chooses by cross-validation.
    estimate_x0 : bool
        Estimate the initial state of each output's predictor with the
        coefficients (else it is zero).
    max_iterations : int
        Bound on the criterion evaluations of the search, per output.
    tolerance : float
        ``ftol = xtol = gtol`` of :func:`scipy.optimize.least_squares`.

    Returns
    -------
    StateSpace
        Innovation form of the model (``K``, ``noise_cov``: the covariance
        of the one-step prediction errors) with ``info['polynomials']``
        (:mod:`subid.model.polynomial`), ``start_cost``, ``final_cost``,
        ``n_evaluations`` and ``stop_reason`` (one entry per output).

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, or no input.
    OrderError
        Orders that are not non-negative integers of the right shapes.
    NotExcitingError
        An input lag of the regression is a combination of the others.
    TooFewSamplesError
        Fewer samples than the coefficients need.
    OptionError
        Bad option values.

    Examples
    --------
    >>> import subid
    >>> data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=1)
    >>> model = subid.armax(data, (3, 4, 1, 0))
    >>> model.info["polynomials"]["structure"]
    'armax'
    """
    return _identify("armax", data, order, selection, estimate_x0, max_iterations, tolerance)


@serial_blas
@checked_call
def oe(data, order=None, *, selection="cv", estimate_x0=True, max_iterations=100,
       tolerance=1e-8):
    """Identify an output-error model ``y = B/F u + e`` by prediction-error minimisation.

    MATLAB ``oe``; one multi-input single-output model per output with one
    ``F`` per input (module docstring), started from the better of the ARX
    estimate and the reduction of a high-order ARX model.

    Parameters
    ----------
    data : IOData
        Uniformly sampled record with at least one input.
    order : tuple, dict, int, 'auto' or None
        MATLAB's ``(nb, nf, nk)``, each a scalar or a (ny, nu) array. An
        integer ``n``: ``nf = n``, ``nk`` from :func:`subid.estimate_delay`,
        ``nb = n`` (``n + 1`` where ``nk = 0``). None/'auto': see
        ``selection``. A dict of them by name (``model.info['orders']``)
        reproduces the structure of ``model``.
    selection : {'cv'}
        How a structure not given is chosen: the integer order ``n`` that
        :func:`subid.moesp` chooses by cross-validation (the simulation fit
        on held-out folds, which is the output-error criterion;
        :func:`subid.methods.dt.polynomial.output_error_order`), with
        ``nk`` from :func:`subid.estimate_delay`; the degrees of the ARX
        structure :func:`subid.arx` chooses where ``moesp`` fails.
    estimate_x0 : bool
        Estimate the initial state of each output's predictor with the
        coefficients (else it is zero).
    max_iterations : int
        Bound on the criterion evaluations of the search, per output.
    tolerance : float
        ``ftol = xtol = gtol`` of :func:`scipy.optimize.least_squares`.

    Returns
    -------
    StateSpace
        Innovation form of the model (``K``, ``noise_cov``: the covariance
        of the one-step prediction errors) with ``info['polynomials']``
        (:mod:`subid.model.polynomial`), ``start_cost``, ``final_cost``,
        ``n_evaluations`` and ``stop_reason`` (one entry per output).

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, or no input.
    OrderError
        Orders that are not non-negative integers of the right shapes.
    NotExcitingError
        An input lag of the regression is a combination of the others.
    TooFewSamplesError
        Fewer samples than the coefficients need.
    OptionError
        Bad option values.

    Examples
    --------
    >>> import subid
    >>> data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=1)
    >>> model = subid.oe(data, (4, 3, 0))
    >>> round(float(subid.markov_error(model, subid.systems.seed001_system())), 6)
    0.0
    """
    return _identify("oe", data, order, selection, estimate_x0, max_iterations, tolerance)


@serial_blas
@checked_call
def bj(data, order=None, *, selection="cv", estimate_x0=True, max_iterations=100,
       tolerance=1e-8):
    """Identify a Box-Jenkins model ``y = B/F u + C/D e`` by prediction-error minimisation.

    MATLAB ``bj``; one multi-input single-output model per output (module
    docstring), the plant started as in :func:`subid.oe` and the noise model
    by Hannan-Rissanen on the output-error residual.

    Parameters
    ----------
    data : IOData
        Uniformly sampled record with at least one input.
    order : tuple, dict, int, 'auto' or None
        MATLAB's ``(nb, nc, nd, nf, nk)``: ``nc``, ``nd`` scalars or one per
        output, ``nb``, ``nf``, ``nk`` scalars or (ny, nu) arrays. An integer
        ``n``: ``nc = nd = nf = n``, ``nk`` from :func:`subid.estimate_delay`,
        ``nb = n`` (``n + 1`` where ``nk = 0``). None/'auto': see
        ``selection``. A dict of them by name (``model.info['orders']``)
        reproduces the structure of ``model``.
    selection : {'cv'}
        How a structure not given is chosen: the degrees of the ARX
        structure :func:`subid.arx` chooses by cross-validation.
    estimate_x0 : bool
        Estimate the initial state of each output's predictor with the
        coefficients (else it is zero).
    max_iterations : int
        Bound on the criterion evaluations of the search, per output.
    tolerance : float
        ``ftol = xtol = gtol`` of :func:`scipy.optimize.least_squares`.

    Returns
    -------
    StateSpace
        Innovation form of the model (``K``, ``noise_cov``: the covariance
        of the one-step prediction errors) with ``info['polynomials']``
        (:mod:`subid.model.polynomial`), ``start_cost``, ``final_cost``,
        ``n_evaluations`` and ``stop_reason`` (one entry per output).

    Raises
    ------
    DataError
        Not a uniformly sampled IOData record, or no input.
    OrderError
        Orders that are not non-negative integers of the right shapes.
    NotExcitingError
        An input lag of the regression is a combination of the others.
    TooFewSamplesError
        Fewer samples than the coefficients need.
    OptionError
        Bad option values.

    Examples
    --------
    >>> import subid
    >>> data = subid.systems.simulate_data(subid.systems.seed001_system(), 400, seed=1)
    >>> model = subid.bj(data, (4, 1, 1, 3, 0))
    >>> sorted(model.info["polynomials"])[:3]
    ['A', 'B', 'C']
    """
    return _identify("bj", data, order, selection, estimate_x0, max_iterations, tolerance)

