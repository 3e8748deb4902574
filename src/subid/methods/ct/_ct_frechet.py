"""Frechet derivatives of one matrix exponential along many directions.

The analytic Jacobian of the output-error refinement
(:mod:`subid.methods.ct._ct_jacobian`) needs ``L(M, E_d)``, the Frechet derivative of
``expm`` at one matrix ``M`` along every direction ``E_d`` of the local coordinates.
:func:`frechet_many` runs the scaling-and-squaring Pade algorithm of Al-Mohy and
Higham ("Computing the Frechet derivative of the matrix exponential, with an
application to condition number estimation", SIAM J. Matrix Anal. Appl. 30, 2009,
Algorithm 6.4), exactly as ``scipy.linalg.expm_frechet`` does (the same operations in
the same order, so the same values to the last bit), with the parts that depend on ``M``
alone (its powers, the Pade numerator and denominator and their LU factors, the
squarings of ``expm(M)``) computed once instead of once per direction.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

__all__ = ["frechet_many"]

#: Largest 1-norms ``ell_m`` for the Pade degrees m = 3, 5, 7, 9, 13 (Al-Mohy and
#: Higham 2009, Table 6.1; the values of ``scipy.linalg.expm_frechet``).
_ELL = {3: 1.08e-2, 5: 2.00e-1, 7: 7.83e-1, 9: 1.78e0, 13: 4.74e0}
_PADE = {
    3: (120., 60., 12., 1.),
    5: (30240., 15120., 3360., 420., 30., 1.),
    7: (17297280., 8648640., 1995840., 277200., 25200., 1512., 56., 1.),
    9: (17643225600., 8821612800., 2075673600., 302702400., 30270240., 2162160., 110880.,
        3960., 90., 1.),
    13: (64764752532480000., 32382376266240000., 7771770303897600., 1187353796428800.,
         129060195264000., 10559470521600., 670442572800., 33522128640., 1323241920.,
         40840800., 960960., 16380., 182., 1.),
}


def _sum(b, X, degrees, last=None):
    """``b[k0] X[k0] + b[k1] X[k1] + ... (+ last)`` over ``degrees``, summed left to right."""
    out = None
    for k, j in degrees:
        term = b[k] * X[j]
        out = term if out is None else out + term
    return out if last is None else out + last


def frechet_many(A, Es):
    """``expm(A)`` and its Frechet derivatives along each of ``Es``.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    Es : sequence of ndarray, shape (n, n)

    Returns
    -------
    expm_A : ndarray, shape (n, n)
    derivatives : list of ndarray, shape (n, n)
        ``scipy.linalg.expm_frechet(A, E, compute_expm=False)`` for every ``E``.

    Raises
    ------
    ValueError
        ``A`` or a direction is not finite (as ``scipy.linalg.expm_frechet``).
    """
    A = np.asarray_chkfinite(A)
    Es = [np.asarray_chkfinite(E) for E in Es]
    ident = np.identity(A.shape[0])
    norm = scipy.linalg.norm(A, 1)
    m = next((k for k in (3, 5, 7, 9) if norm <= _ELL[k]), None)
    s = 0
    if m is not None:
        # the Pade approximant of degree m (scipy's _diff_pade3 .. _diff_pade9)
        b = _PADE[m]
        odd = [(k, k - 1) for k in range(m, 2, -2)]      # b[k] * (power k - 1)
        even = [(k, k) for k in range(m - 1, 1, -2)]     # b[k] * (power k)
        P = {2: A.dot(A)}
        if m >= 5:
            P[4] = np.dot(P[2], P[2])
        if m >= 7:
            P[6] = np.dot(P[2], P[4])
        if m >= 9:
            P[8] = np.dot(P[4], P[4])
        inner = _sum(b, P, odd, b[1] * ident)
        U = A.dot(inner)
        V = _sum(b, P, even, b[0] * ident)

        def parts(E):
            M = {2: np.dot(A, E) + np.dot(E, A)}
            if m >= 5:
                M[4] = np.dot(P[2], M[2]) + np.dot(M[2], P[2])
            if m >= 7:
                M[6] = np.dot(P[4], M[2]) + np.dot(M[4], P[2])
            if m >= 9:
                M[8] = np.dot(P[4], M[4]) + np.dot(M[4], P[4])
            return A.dot(_sum(b, M, odd)) + E.dot(inner), _sum(b, M, even)
    else:
        s = max(0, int(np.ceil(np.log2(norm / _ELL[13]))))
        b = _PADE[13]
        A = A * 2.0**-s
        A2 = np.dot(A, A)
        A4 = np.dot(A2, A2)
        A6 = np.dot(A2, A4)
        W1 = b[13]*A6 + b[11]*A4 + b[9]*A2
        W2 = b[7]*A6 + b[5]*A4 + b[3]*A2 + b[1]*ident
        Z1 = b[12]*A6 + b[10]*A4 + b[8]*A2
        Z2 = b[6]*A6 + b[4]*A4 + b[2]*A2 + b[0]*ident
        W = np.dot(A6, W1) + W2
        U = np.dot(A, W)
        V = np.dot(A6, Z1) + Z2

        def parts(E):
            E = E * 2.0**-s
            M2 = np.dot(A, E) + np.dot(E, A)
            M4 = np.dot(A2, M2) + np.dot(M2, A2)
            M6 = np.dot(A4, M2) + np.dot(M4, A2)
            Lw1 = b[13]*M6 + b[11]*M4 + b[9]*M2
            Lw2 = b[7]*M6 + b[5]*M4 + b[3]*M2
            Lz1 = b[12]*M6 + b[10]*M4 + b[8]*M2
            Lz2 = b[6]*M6 + b[4]*M4 + b[2]*M2
            Lw = np.dot(A6, Lw1) + np.dot(M6, W1) + Lw2
            Lu = np.dot(A, Lw) + np.dot(E, W)
            Lv = np.dot(A6, Lz1) + np.dot(M6, Z1) + Lz2
            return Lu, Lv
    lu_piv = scipy.linalg.lu_factor(-U + V)
    R = scipy.linalg.lu_solve(lu_piv, U + V)
    squares = [R]
    for _ in range(s):
        squares.append(np.dot(squares[-1], squares[-1]))
    out = []
    for E in Es:
        Lu, Lv = parts(E)
        L = scipy.linalg.lu_solve(lu_piv, Lu + Lv + np.dot((Lu - Lv), R))
        for k in range(s):
            L = np.dot(squares[k], L) + np.dot(L, squares[k])
        out.append(L)
    return squares[-1], out
