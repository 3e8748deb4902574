"""Small dense LAPACK problems by direct calls (least squares, an orthonormal basis, the
eigenvectors of a real matrix), without the wrappers of :mod:`scipy.linalg` and
:mod:`numpy.linalg`, whose checks cost more than the factorisations on the matrices of a
candidate model: the order search fits hundreds of them (issue 21).

The same LAPACK routines with the same arguments and workspace sizes as the calls they
replace, so the same bits (``tests/test_selection_speed.py``, ``tests/test_lag_fit.py``).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

#: Optimal LAPACK workspace sizes by routine and shape (the queries of scipy.linalg).
_LWORK: dict = {}


def orthonormal_basis(gamma: np.ndarray) -> np.ndarray:
    """``Q`` of the economic QR factorisation of a finite float matrix with at least
    as many rows as columns: ``scipy.linalg.qr(gamma, mode='economic')[0]`` by the
    same LAPACK calls (``dgeqrf``, ``dorgqr``, the workspace sizes queried as it queries
    them) without its wrapper, which cost more than the factorisation on the matrices
    of a candidate order (the same bits; ``tests/test_selection_speed.py``)."""
    gamma = np.asarray(gamma, dtype=float)
    m, n = gamma.shape
    if n == 0 or m < n:
        return scipy.linalg.qr(gamma, mode="economic", check_finite=False)[0]
    lapack = scipy.linalg.lapack
    key = ("qr", m, n)
    if key not in _LWORK:
        qr, tau, work, _ = lapack.dgeqrf(gamma, lwork=-1)
        lw_qr = int(work[0].real)
        qr, tau, _, _ = lapack.dgeqrf(gamma, lwork=lw_qr)
        _LWORK[key] = (lw_qr, int(lapack.dorgqr(qr, tau, lwork=-1)[1][0].real))
    lw_qr, lw_q = _LWORK[key]
    qr, tau, _, info = lapack.dgeqrf(gamma, lwork=lw_qr)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of dgeqrf")
    Q, _, info = lapack.dorgqr(qr, tau, lwork=lw_q, overwrite_a=1)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of dorgqr")
    return Q


def least_squares_gelsy(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``scipy.linalg.lstsq(a, b, lapack_driver='gelsy')[0]`` (``cond`` the machine
    epsilon) for finite float matrices with at least as many rows as columns and a
    2-D ``b``, by the same ``dgelsy`` call without the wrapper (the same bits)."""
    m, n = a.shape
    if n == 0 or m < n or b.ndim != 2 or m != b.shape[0]:
        return scipy.linalg.lstsq(a, b, lapack_driver="gelsy", check_finite=False)[0]
    lapack = scipy.linalg.lapack
    cond = np.finfo(float).eps
    key = ("gelsy", m, n, b.shape[1])
    if key not in _LWORK:
        work, info = lapack.dgelsy_lwork(m, n, b.shape[1], cond)
        if info != 0:
            raise ValueError(f"dgelsy workspace query failed: {info}")
        _LWORK[key] = int(work.real)
    jptv = np.zeros((n, 1), dtype=np.int32)
    _, x, _, _, info = lapack.dgelsy(a, b, jptv, cond, _LWORK[key], False, False)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of dgelsy")
    return x[:n]


def eig_real(A: np.ndarray):
    """``(wr, wi, vr)``: the eigenvalues (real and imaginary parts) and right eigenvectors
    (LAPACK's real storage of conjugate pairs) of a finite real square matrix by the
    ``dgeev`` call of ``numpy.linalg.eig`` (the optimal workspace queried as it queries
    it), without its wrapper: :func:`subid.methods.dt._lag_kernel.complex_eigenvectors`
    gives numpy's ``eig(A)`` from them, the same bits (``tests/test_lag_fit.py``).
    Raises ``numpy.linalg.LinAlgError`` where numpy's ``eig`` does (no convergence)."""
    n = A.shape[0]
    lapack = scipy.linalg.lapack
    key = ("geev", n)
    if key not in _LWORK:
        work, info = lapack.dgeev_lwork(n, compute_vl=0)
        if info != 0:
            raise ValueError(f"dgeev workspace query failed: {info}")
        _LWORK[key] = max(int(work.real), 1)
    wr, wi, _, vr, info = lapack.dgeev(A, compute_vl=0, lwork=_LWORK[key])
    if info > 0:
        raise np.linalg.LinAlgError("Eigenvalues did not converge")
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of dgeev")
    return wr, wi, vr
