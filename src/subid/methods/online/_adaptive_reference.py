"""Plain numpy reference of the per-sample recursion of :class:`AdaptiveIdentifier` (seed 000).

:func:`reference` takes the arguments of
:func:`subid.methods.online._adaptive_kernel.kernel` and implements the same
recursion, written for readability with numpy/scipy (the module docstring of
the kernel describes the steps); the tests compare the two (agreement to
1e-12 on well-conditioned systems, see ``docs/seed000.md``). The identifier
runs it with ``engine='numpy'``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from subid.methods.online._adaptive_kernel import (
    _EXCITATION_ITERATIONS,
    _FORGOTTEN,
    _RESCALE_BELOW,
    _STALL_FACTOR,
    _STALL_MAX,
    SHIFT_RANK_TOL,
)
from subid.model._simulate import expm_blocks

__all__ = ["reference"]


def _ref_solve(R, G, X, max_cond):
    """Reference of :func:`_solve_normal`: numpy Cholesky, scipy cho_solve."""
    Rs = np.tril(R) + np.tril(R, -1).T
    tr = np.trace(Rs)
    if not tr > 0:
        return False
    delta = tr / max_cond
    try:
        L = np.linalg.cholesky(Rs + delta * np.eye(Rs.shape[0]))
    except np.linalg.LinAlgError:
        return False
    step = scipy.linalg.cho_solve((L, True), G.T).T
    X += step
    G -= step @ Rs
    return True


def _ref_solve_iv_weighted(C, G, Z, X, max_cond):
    """Reference of :func:`_solve_iv_weighted`: numpy Cholesky of Z, scipy
    triangular solves, the normal equations of the whitened problem solved by
    :func:`_ref_solve`. Returns the excitation of the whitened normal matrix
    (:func:`_ref_weakest`), None where the kernel returns False."""
    Zs = np.tril(Z) + np.tril(Z, -1).T
    tr = np.trace(Zs)
    if not tr > 0:
        return None
    try:
        L = np.linalg.cholesky(Zs + tr / max_cond * np.eye(Zs.shape[0]))
    except np.linalg.LinAlgError:
        return None
    Ct = scipy.linalg.solve_triangular(L, C, lower=True)
    Gt = scipy.linalg.solve_triangular(L, G.T, lower=True).T
    Xold = X.copy()
    N, Gn = Ct.T @ Ct, Gt @ Ct
    scale = max_cond * max_cond
    if not _ref_solve(N, Gn, X, scale):
        scale = max_cond
        if not _ref_solve(N, Gn, X, scale):
            return None
    G -= (X - Xold) @ C.T
    return _ref_weakest(N, np.trace(N) / scale)


def _ref_weakest(X, delta):
    """Reference of :func:`_weakest`: the same inverse iteration, scipy's
    Cholesky solves."""
    Xs = np.tril(X) + np.tril(X, -1).T
    d = Xs.shape[0]
    factor = scipy.linalg.cho_factor(Xs + delta * np.eye(d), lower=True)
    v = 1.0 + 0.5 * np.sin(np.arange(1.0, d + 1.0))
    v /= np.linalg.norm(v)
    nrm = 1.0
    for _ in range(_EXCITATION_ITERATIONS):
        v = scipy.linalg.cho_solve(factor, v)
        nrm = np.linalg.norm(v)
        v /= nrm
    return (1.0 / nrm - delta) / np.trace(Xs)


def _ref_refresh(n, nu, ny, omega, alpha, max_cond, gate, settle, ode, iv, T_now, ist, fst,
                 R, G, M, Rt, gt, theta, Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, hist, Cz, Gz, Zz):
    if not ode:
        if iv:
            Zs = np.tril(Zz) + np.tril(Zz, -1).T
            Cf = np.hstack([Cz, Zs[:, :M.shape[1] - n]])
            excitation = _ref_solve_iv_weighted(Cf, Gz, Zz, M, max_cond)
            if excitation is None:
                ist[7] += 1
                excitation = 0.0
        elif not _ref_solve(R, G, M, max_cond):
            ist[7] += 1
            excitation = 0.0
        else:
            excitation = _ref_weakest(R, np.trace(R) / max_cond)
        ist[13] = 0 if excitation * max_cond >= 1.0 else 1
        if ist[9] and not _ref_solve(Rt, gt, theta, max_cond):
            ist[7] += 1
    dp = M.shape[0]
    Up, W = M[:dp - ny, :n], M[ny:, :n]
    Q, Rq = np.linalg.qr(Up)
    piv = np.abs(np.diag(Rq))
    if piv.max() > 0 and np.all(piv > SHIFT_RANK_TOL * piv.max()):
        X = scipy.linalg.solve_triangular(Rq, Q.T @ W)
        tot = np.linalg.norm(W)
        res = np.linalg.norm(W - Up @ X) / tot if tot > 0 else 0.0
        Am[:] = omega * X
        Cm[:] = M[:ny, :n]
    else:
        res = -1.0
        ist[5] += 1
    fst[2] = res
    if ist[9]:
        Bm[:] = theta[0, n:n + n * nu].reshape(nu, n).T
        Dm[:] = theta[0, n + n * nu:].reshape(nu, ny).T
    level = gate
    if res >= 0:
        if res < 0.5 * fst[5]:
            fst[5], fst[6] = res, T_now
        elif (not ist[10] and fst[5] <= _STALL_MAX
              and T_now - fst[6] >= min(1.0 / alpha, max(fst[6] - fst[8], settle))):
            ist[10] = 1
        if ist[10]:
            level = max(gate, _STALL_FACTOR * fst[5])
    if 0 <= res <= level and ist[13] == 0 and np.all(np.linalg.eigvals(Am).real < 0):
        Apsi[:] = Am
        Cpsi[:] = Cm
        ist[6] += 1
        ist[11] = 0
        if not ist[9]:
            Psi[:] = 0.0
            Psi[:, :n] = Cm
            ist[9] = 1
            fst[1] = T_now
    else:
        ist[4] += 1
        ist[11] = 1
    ist[1] += 1
    cap = hist.shape[0]
    r = ist[1]
    if cap > 0 and r % ist[3] == 0:
        if ist[2] == cap:
            kept = hist[1:cap:2].copy()
            hist[:kept.shape[0]] = kept
            ist[2] = kept.shape[0]
            ist[3] *= 2
        if r % ist[3] == 0:
            hist[ist[2]] = np.concatenate([[T_now, ist[0]], Am.ravel(), Bm.ravel(),
                                           Cm.ravel(), Dm.ravel()])
            ist[2] += 1


def reference(Tm, U, Y, idx, steps, lamM, lamT, Fphi, Fg0, Fg1, Iphi, Ig0, Ig1, Hsel, par,
              ipar, ist, fst, prev_u, prev_y, zp, zq, R, G, M, Rt, gt, theta,
              Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, zr, xi, Cz, Gz, Zz, Ev,
              PsiPhi, PsiG0, PsiG1, pstamp, hist, buf):
    """Plain numpy implementation of :func:`kernel` (same arguments).

    Differences of implementation only: the Ψ discretisation uses
    :func:`subid.model._simulate.expm_blocks` (scipy) instead of the compiled
    Taylor series, (13) numpy's QR, the normal equations numpy's Cholesky,
    the stability test eigenvalues, and the whole symmetric matrices are
    updated (the kernel updates lower triangles).
    """
    (omega, alpha, beta, max_cond, trace_bound, gate, max_gap, dcF, dcI, settle,
     startup) = (float(v) for v in par)
    K, ode, foh, iv = int(ipar[0]), bool(ipar[1]), bool(ipar[2]), bool(ipar[3])
    n = Am.shape[0]
    ny = zp.shape[1]
    nu = zq.shape[1]
    for k in range(U.shape[0]):
        u, y = U[k], Y[k]
        if ist[0] == 0:
            prev_u[:], prev_y[:], fst[0], fst[8], ist[0] = u, y, Tm[k], Tm[k], 1
            continue
        q = idx[k]
        h = steps[q]
        gap = h > max_gap
        # 1. filters (6a)-(6b); re-initialised at the steady state after a gap
        if gap:
            ist[12] += 1
            fst[7] = Tm[k] + settle
            zp[:], zq[:], zr[:] = 0.0, 0.0, 0.0
            zp[0], zq[0], zr[0] = dcF * y, dcF * u, dcI * u
        else:
            zp[:] = Fphi[q] @ zp + np.outer(Fg0[q], prev_y) + np.outer(Fg1[q], y)
            zq[:] = Fphi[q] @ zq + np.outer(Fg0[q], prev_u) + np.outer(Fg1[q], u)
            if iv:
                zr[:] = Iphi[q] @ zr + np.outer(Ig0[q], prev_u) + np.outer(Ig1[q], u)
        # 2. regression (8)
        p = zp.reshape(-1)
        phi = np.concatenate([Hsel @ p, zq.reshape(-1)])
        r2 = 1.0 + phi @ phi
        if not ode:
            c2 = fst[3] * lamM[q]
            if c2 < _RESCALE_BELOW:        # fold the factor in first (long gaps)
                c2 = c2 if c2 > _FORGOTTEN else 0.0
                if iv:
                    Cz *= c2
                    Gz *= c2
                    Zz *= c2
                else:
                    R *= c2
                    G *= c2
                fst[3] = 1.0
            else:
                fst[3] = c2
            w = 0.0 if Tm[k] <= fst[7] else h / (r2 * fst[3])
            if iv:
                zeta = np.concatenate([zq.reshape(-1), zr.reshape(-1), xi[0]])
                Cz += np.outer(w * zeta, phi[:n])
                Zz += np.outer(w * zeta, zeta)
                Gz += np.outer(w * (p - M @ phi), zeta)
            else:
                R += np.outer(w * phi, phi)
                G += np.outer(w * (p - M @ phi), phi)
        elif Tm[k] > fst[7]:
            g = R @ phi
            c = h / (r2 + h * (phi @ g))
            M += np.outer((p - M @ phi) * c, g)
            grow = h * alpha
            if np.trace(R) > trace_bound:
                grow, ist[8] = 0.0, ist[8] + 1
            R[:] = R + grow * R - c * np.outer(g, g)
        if ist[9]:
            # 3. Ξ, Ψ of (15), exact for the held input
            if pstamp[q] != ist[6]:
                Ph, G1, G2 = expm_blocks(Apsi, np.eye(n), [h], "foh" if foh else "zoh")
                PsiPhi[q] = Ph[0]
                if foh:
                    PsiG0[q] = Cpsi @ (G1[0] - G2[0])
                    PsiG1[q] = Cpsi @ G2[0]
                else:
                    PsiG0[q] = Cpsi @ G1[0]
                    PsiG1[q] = 0.0
                pstamp[q] = ist[6]
            Psi[:, :n] = Psi[:, :n] @ PsiPhi[q]
            for jj in range(nu):
                blk = slice(n + jj * n, n + (jj + 1) * n)
                Psi[:, blk] = (Psi[:, blk] @ PsiPhi[q] + prev_u[jj] * PsiG0[q]
                               + u[jj] * PsiG1[q])
            if gap:     # restart (14): Ψ = 0, Ξ = C̃, x̃(t_g) information dropped
                Psi[:] = 0.0
                Psi[:, :n] = Cpsi
                if not ode:
                    Rt[:n, :] = 0.0
                    Rt[:, :n] = 0.0
                    gt[0, :n] = 0.0
            if iv:      # auxiliary-model instrument (see the kernel)
                xi[0] = PsiPhi[q] @ xi[0] + h * (Bm @ zq[0])
            # regression (16)
            Phi = np.hstack([Psi, np.kron(u[None, :], np.eye(ny))])
            if not ode:
                lam, age = lamT[q], Tm[k] - fst[1]
                if startup > beta * age:        # start-up schedule of β
                    lam = np.exp(-startup * h / age)
                c2 = fst[4] * lam
                if c2 < _RESCALE_BELOW:
                    c2 = c2 if c2 > _FORGOTTEN else 0.0
                    Rt *= c2
                    gt *= c2
                    fst[4] = 1.0
                else:
                    fst[4] = c2
                w = 0.0 if gap else h / ((1.0 + np.sum(Phi * Phi)) * fst[4])
                res = y - Phi @ theta[0]
                Ev[0, :ny] = lam * Ev[0, :ny] + (0.0 if gap else h * (res * res))
                Ev[0, ny:2 * ny] = lam * Ev[0, ny:2 * ny] + (0.0 if gap else h * (y * y))
                Ev[0, 2 * ny] = lam * Ev[0, 2 * ny] + (0.0 if gap else h)
                Rt += w * (Phi.T @ Phi)
                gt += (Phi.T @ (w * (y - Phi @ theta[0])))[None, :]
            elif not gap:
                Gq = Rt @ Phi.T
                tq = np.trace(Phi @ Gq)
                c = h / (1.0 + tq + h * tq)
                theta += (Gq @ ((y - Phi @ theta[0]) * c))[None, :]
                grow = h * beta
                if np.trace(Rt) > trace_bound:
                    grow, ist[8] = 0.0, ist[8] + 1
                Rt[:] = Rt + grow * Rt - c * (Gq @ Gq.T)
        prev_u[:], prev_y[:], fst[0] = u, y, Tm[k]
        ist[0] += 1
        if (ist[0] - 1) % K == 0:
            _ref_refresh(n, nu, ny, omega, alpha, max_cond, gate, settle, ode, iv, Tm[k], ist,
                         fst, R, G, M, Rt, gt, theta, Am, Cm, Bm, Dm, Apsi, Cpsi, Psi, hist, Cz,
                         Gz, Zz)
    return bool(np.isfinite(buf).all())
