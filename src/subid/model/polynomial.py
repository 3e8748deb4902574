"""Polynomial (transfer-function) models and their state-space realisation.

The polynomial methods (:func:`subid.arx`, :func:`subid.armax`,
:func:`subid.oe`, :func:`subid.bj`) return a :class:`subid.StateSpace` in
innovation form whose ``info['polynomials']`` holds the polynomials in
MATLAB's ``idpoly`` convention (Ljung, *System Identification*, 2nd ed.,
1999, eq. 4.33, the general family)::

    A(q) y(t) = sum_j B_j(q) / F_j(q) u_j(t - nk_j) + C(q) / D(q) e(t)

with polynomials in the delay operator ``q^-1``: ``A``, ``C``, ``D``, ``F``
monic (leading coefficient 1), ``B`` with ``nk`` leading zeros (as MATLAB
stores it). Decision (issue 25): the model *is* a StateSpace, so that it
works everywhere a StateSpace does (simulation, prediction, fit, Markov
parameters, frequency response, plots, reports, files, ``to_control``),
and keeps its polynomials in ``info``, from which :func:`polynomials_of`
rebuilds them and :func:`realise` the state-space matrices.

Stored arrays (``info['polynomials']``, a dict; every array zero-padded on
the right to a common length):

``structure``  ``'arx'``, ``'armax'``, ``'oe'`` or ``'bj'``
``A``          (ny, ny, la) matrix polynomial, ``A[:, :, 0] = I`` (diagonal for
               the single-output models, full for a multi-output ARX)
``B``          (ny, nu, lb), ``nk`` leading zeros
``C``, ``D``   (ny, lc), (ny, ld), monic, one per output
``F``          (ny, nu, lf), monic
``na``         (ny, ny) int, ``nb``, ``nk``, ``nf`` (ny, nu) int,
               ``nc``, ``nd`` (ny,) int

Realisation (:func:`realise`). ``A(q) y = B(q) u + C(q) e`` (``F = D = 1``)
in block observer form of degree ``p``: with ``y(t) = x_1(t) + B_0 u(t) +
e(t)`` and ``x_k(t+1) = x_(k+1)(t) - A_k y(t) + B_k u(t) + C_k e(t)``,

    A_ss = [[-A_1, I, 0, ...], [-A_2, 0, I, ...], ..., [-A_p, 0, ..., 0]],
    B_ss[k] = B_k - A_k B_0,   K[k] = C_k - A_k,   C_ss = [I 0 ... 0],
    D_ss = B_0,

whose predictor ``A_ss - K C_ss`` is the block companion matrix of ``C(q)``.
With ``F`` or ``D`` not 1 (OE, BJ; then ``A = 1``), each ratio
``B_ij / F_ij`` and ``C_i / D_i`` is realised in the same (single-output)
observer form and the blocks are stacked: ``y_i`` is their sum plus
``e_i``. The realisation has ``sum`` of the block degrees as order; it is
minimal for generic coefficients, not when blocks share poles (e.g. the
outputs of a multi-output ARX with a diagonal ``A``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STRUCTURES", "realise", "polynomials_of", "polynomial_record", "describe",
           "coefficient_slots", "coefficients", "with_coefficients", "realisation_jacobian"]

STRUCTURES = ("arx", "armax", "oe", "bj")


def observer_form(den: np.ndarray, num: np.ndarray):
    """``(A, B, C, D)`` of ``den(q)^-1 num(q)`` in block observer form.

    ``den`` has shape (p+1, ny, ny) with ``den[0] = I``; ``num`` shape
    (p+1, ny, m) (both padded to the same length p+1). Order ``ny * p``.
    """
    p = den.shape[0] - 1
    ny, m = num.shape[1], num.shape[2]
    n = ny * p
    A = np.zeros((n, n))
    if p:
        A[:, :ny] = -den[1:].reshape(n, ny)          # block k: -den[k] in the first column
        A[:n - ny, ny:] = np.eye(n - ny)             # identities on the block superdiagonal
    B = (num[1:] - den[1:] @ num[0]).reshape(n, m)   # block k: num[k] - den[k] num[0]
    C = np.zeros((ny, n))
    if p:
        C[:, :ny] = np.eye(ny)
    return A, B, C, np.array(num[0], dtype=float)


def _pad(coef, length):
    out = np.zeros(length)
    out[:len(coef)] = coef
    return out


def _trim(coef) -> np.ndarray:
    """Coefficients without trailing zeros (at least the leading one)."""
    coef = np.asarray(coef, dtype=float)
    nz = np.flatnonzero(coef)
    return coef[:max(int(nz[-1]) + 1 if nz.size else 1, 1)]


def _block_diag(blocks, ny, nu):
    """Stack realisations ``(i, A, B_u, K_col, C_row)`` of single-output terms."""
    n = sum(b[1].shape[0] for b in blocks)
    A = np.zeros((n, n))
    B = np.zeros((n, nu))
    K = np.zeros((n, ny))
    C = np.zeros((ny, n))
    at = 0
    for i, Ab, Bu, Ke, Cr in blocks:
        m = Ab.shape[0]
        s = slice(at, at + m)
        A[s, s] = Ab
        B[s] = Bu
        K[s, i] = Ke
        C[i, s] = Cr
        at += m
    return A, B, C, K


def _sub(poly: dict, i: int) -> dict:
    """The single-output record of output ``i`` of a per-output (MISO) model."""
    out = dict(poly)
    for key in ("B", "F", "nb", "nk", "nf", "C", "D", "nc", "nd"):
        out[key] = np.asarray(poly[key])[i:i + 1]
    out["A"] = np.asarray(poly["A"])[i:i + 1, i:i + 1]
    out["na"] = np.asarray(poly["na"])[i:i + 1, i:i + 1]
    return out


def _realise_single(poly: dict):
    """Blocks ``(A, B, K, C)`` of a single-output model (see :func:`realise`)."""
    Ap, Bp = np.asarray(poly["A"], float), np.asarray(poly["B"], float)
    Cp, Dp, Fp = (np.asarray(poly[k], float) for k in ("C", "D", "F"))
    nu = Bp.shape[1]
    nb, nk, nf = (np.asarray(poly[k]) for k in ("nb", "nk", "nf"))
    if poly["structure"] in ("arx", "armax"):
        p = max(int(np.asarray(poly["na"]).max()), int((nk + nb - 1).max(initial=0)),
                int(np.asarray(poly["nc"]).max()), 0)
        den = np.zeros((p + 1, 1, 1))
        num = np.zeros((p + 1, 1, nu + 1))
        la, lb, lc = min(Ap.shape[2], p + 1), min(Bp.shape[2], p + 1), min(Cp.shape[1], p + 1)
        den[:la, 0, 0] = Ap[0, 0, :la]
        num[:lb, 0, :nu] = Bp[0, :, :lb].T
        num[:lc, 0, nu] = Cp[0, :lc]
        A, BK, C, DD = observer_form(den, num)
        return [(A, BK[:, :nu], BK[:, nu], C[0])], DD[0, :nu]
    blocks, Dss = [], np.zeros(nu)
    for j in range(nu):
        p = max(int(nf[0, j]), int(nk[0, j] + nb[0, j] - 1), 0)
        Ab, Bb, Cb, Db = observer_form(_pad(Fp[0, j][:p + 1], p + 1)[:, None, None],
                                       _pad(Bp[0, j][:p + 1], p + 1)[:, None, None])
        Dss[j] = Db[0, 0]
        bu = np.zeros((p, nu))
        bu[:, j] = Bb[:, 0]
        blocks.append((Ab, bu, np.zeros(p), Cb[0]))
    p = max(int(np.asarray(poly["nc"])[0]), int(np.asarray(poly["nd"])[0]))
    Ab, Bb, Cb, _ = observer_form(_pad(Dp[0][:p + 1], p + 1)[:, None, None],
                                  _pad(Cp[0][:p + 1], p + 1)[:, None, None])
    blocks.append((Ab, np.zeros((p, nu)), Bb[:, 0], Cb[0]))
    return blocks, Dss


def realise(poly: dict):
    """``(A, B, C, D, K)`` of the innovation form of the polynomial model ``poly``.

    ``poly`` is a :func:`polynomial_record` dict (``info['polynomials']``).
    A multi-output ARX is realised in the block observer form of its matrix
    polynomials; the per-output models (ARMAX, OE, BJ) output by output, the
    blocks stacked in output order (see the module docstring). The state
    dimension follows from the orders alone (never from coefficient values),
    so that the realisation is a smooth function of the coefficients.
    """
    Ap, Bp = np.asarray(poly["A"], float), np.asarray(poly["B"], float)
    Cp = np.asarray(poly["C"], float)
    ny, nu = Bp.shape[0], Bp.shape[1]
    if poly["structure"] == "arx" and ny > 1:
        p = max(Ap.shape[2], Bp.shape[2], Cp.shape[1]) - 1
        den = np.zeros((p + 1, ny, ny))
        num = np.zeros((p + 1, ny, nu + ny))
        den[:Ap.shape[2]] = np.moveaxis(Ap, 2, 0)
        num[:Bp.shape[2], :, :nu] = np.moveaxis(Bp, 2, 0)
        for i in range(ny):
            num[:Cp.shape[1], i, nu + i] = Cp[i]
        A, BK, C, DD = observer_form(den, num)
        return A, BK[:, :nu], C, DD[:, :nu], BK[:, nu:]
    blocks, D = [], np.zeros((ny, nu))
    for i in range(ny):
        parts, D[i] = _realise_single(_sub(poly, i) if ny > 1 else poly)
        blocks += [(i, Ab, Bu, Ke, Cr) for Ab, Bu, Ke, Cr in parts]
    A, B, C, K = _block_diag(blocks, ny, nu)
    return A, B, C, D, K


def polynomial_record(structure: str, *, A, B, C, D, F, na, nb, nc, nd, nf, nk) -> dict:
    """The ``info['polynomials']`` dict (see the module docstring for the arrays)."""
    return {"structure": structure, "A": np.asarray(A, float), "B": np.asarray(B, float),
            "C": np.asarray(C, float), "D": np.asarray(D, float), "F": np.asarray(F, float),
            "na": np.asarray(na, dtype=np.int64), "nb": np.asarray(nb, dtype=np.int64),
            "nc": np.asarray(nc, dtype=np.int64), "nd": np.asarray(nd, dtype=np.int64),
            "nf": np.asarray(nf, dtype=np.int64), "nk": np.asarray(nk, dtype=np.int64)}


def coefficient_slots(poly: dict) -> list:
    """The free coefficients of ``poly``: a list of ``(key, index, name)``.

    Output by output ``i``: ``A[i, k]`` lags ``1..na[i, k]`` for every ``k``
    (the diagonal only for the per-output structures), ``B[i, j]`` lags
    ``nk..nk+nb-1`` for every input ``j``, ``C[i]`` lags ``1..nc``, ``D[i]``
    lags ``1..nd``, ``F[i, j]`` lags ``1..nf`` (the order of
    :mod:`subid.methods.dt.pem_poly`'s coefficient vector, output by output).
    ``name`` is ``'B[0,1][2]'``: polynomial, channel indices, lag.
    """
    na, nb, nk, nf = (np.asarray(poly[k]) for k in ("na", "nb", "nk", "nf"))
    nc, nd = np.asarray(poly["nc"]), np.asarray(poly["nd"])
    ny, nu = nb.shape
    out: list[tuple[str, tuple[int, ...], str]] = []
    for i in range(ny):
        out += [("A", (i, k, lag), f"A[{i},{k}][{lag}]") for k in range(ny)
                for lag in range(1, int(na[i, k]) + 1)]
        out += [("B", (i, j, lag), f"B[{i},{j}][{lag}]") for j in range(nu)
                for lag in range(int(nk[i, j]), int(nk[i, j] + nb[i, j]))]
        out += [("C", (i, lag), f"C[{i}][{lag}]") for lag in range(1, int(nc[i]) + 1)]
        out += [("D", (i, lag), f"D[{i}][{lag}]") for lag in range(1, int(nd[i]) + 1)]
        out += [("F", (i, j, lag), f"F[{i},{j}][{lag}]") for j in range(nu)
                for lag in range(1, int(nf[i, j]) + 1)]
    return out


def coefficients(poly: dict) -> np.ndarray:
    """The free coefficients of ``poly`` in the order of :func:`coefficient_slots`."""
    return np.array([np.asarray(poly[key], float)[index]
                     for key, index, _ in coefficient_slots(poly)], dtype=float)


def with_coefficients(poly: dict, values) -> dict:
    """``poly`` with its free coefficients (:func:`coefficient_slots`) set to ``values``."""
    slots = coefficient_slots(poly)
    out = dict(poly)
    for key in {key for key, _, _ in slots}:
        out[key] = np.array(poly[key], dtype=float)
    for (key, index, _), value in zip(slots, np.asarray(values, dtype=float)):
        out[key][index] = value
    return out


def realisation_jacobian(poly: dict) -> np.ndarray:
    """``d vec(A, B, C, D, K) / d c`` of :func:`realise` at the coefficients ``c``
    (:func:`coefficients`), each matrix row-major, shape (P, len(c)).

    The realised matrices are polynomials of degree at most two in the
    coefficients (entries ``-a_k``, ``b_k - a_k b_0``, ``c_k - a_k``: the
    observer form of :func:`observer_form`), so the central difference with
    unit step is their exact derivative.
    """
    c = coefficients(poly)

    def flat(values):
        return np.concatenate([np.asarray(m, float).ravel()
                               for m in realise(with_coefficients(poly, values))])
    cols = []
    for j in range(c.size):
        e = np.zeros(c.size)
        e[j] = 1.0
        cols.append(0.5 * (flat(c + e) - flat(c - e)))
    return np.array(cols).T if cols else np.zeros((flat(c).size, 0))


def polynomials_of(model) -> dict | None:
    """The polynomials of a model from a polynomial method (None for any other model)."""
    poly = getattr(model, "info", {}).get("polynomials")
    return poly if isinstance(poly, dict) and "structure" in poly else None


def _poly_text(coef, stds=None) -> str:
    """``coef`` as ``1 -1.5 q^-1 ...``; ``stds`` ({lag: std}) adds ``(±std)`` to a term."""
    coef = _trim(coef)
    stds = stds or {}
    terms = [f"{c:+.4g}" + (f" (±{stds[k]:.2g})" if k in stds else "")
             + ("" if k == 0 else " q^-1" if k == 1 else f" q^-{k}")
             for k, c in enumerate(coef) if c != 0]
    text = " ".join(terms) if terms else "0"
    return text[1:] if text.startswith("+") else text


#: The model equation of each structure (MATLAB's ``present``).
EQUATIONS = {"arx": "A(q) y(t) = B(q) u(t) + e(t)", "armax": "A(q) y(t) = B(q) u(t) + C(q) e(t)",
             "oe": "y(t) = B(q)/F(q) u(t) + e(t)", "bj": "y(t) = B(q)/F(q) u(t) + C(q)/D(q) e(t)"}


def describe(poly: dict, input_names=None, output_names=None, std=None) -> list[str]:
    """Lines giving every polynomial of ``poly`` (for reports), as MATLAB's ``present``;
    ``std`` (the standard deviation of every coefficient of :func:`coefficient_slots`)
    adds ``(±std)`` after each estimated coefficient."""
    spread: dict = {}
    if std is not None:
        for (key, index, _), s in zip(coefficient_slots(poly), np.asarray(std, float)):
            spread.setdefault((key,) + tuple(index[:-1]), {})[index[-1]] = float(s)
    A, B, C, D, F = (np.asarray(poly[k]) for k in ("A", "B", "C", "D", "F"))
    ny, nu = B.shape[0], B.shape[1]
    structure = str(poly["structure"])
    inputs = list(input_names or [f"u{j + 1}" for j in range(nu)])
    outputs = list(output_names or [f"y{i + 1}" for i in range(ny)])
    lines = [f"{structure.upper()} model: {EQUATIONS.get(structure, structure)}"]

    def text(key, *index):
        return _poly_text({"A": A, "B": B, "C": C, "D": D, "F": F}[key][index],
                          spread.get((key,) + index))
    for i in range(ny):
        y = outputs[i]
        if structure in ("arx", "armax"):
            for k in range(ny):
                if k == i or np.any(A[i, k]):
                    lines.append(f"A[{y},{outputs[k]}] = {text('A', i, k)}")
        for j in range(nu):
            lines.append(f"B[{y},{inputs[j]}] = {text('B', i, j)}  (nk = "
                         f"{int(np.asarray(poly['nk'])[i, j])})")
            if structure in ("oe", "bj"):
                lines.append(f"F[{y},{inputs[j]}] = {text('F', i, j)}")
        if structure in ("armax", "bj"):
            lines.append(f"C[{y}] = {text('C', i)}")
        if structure == "bj":
            lines.append(f"D[{y}] = {text('D', i)}")
    return lines


