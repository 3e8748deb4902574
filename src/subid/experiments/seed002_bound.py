"""The Cramér-Rao bound of the seed-002 experiment under white and AR(1) output noise.

Issue 22 asks for the error of ``ct_subspace`` under AR(1) output noise (pole
0.9 in sample steps, 20 dB) to be within 1.5 times the error under white
noise of the same variance. This module computes what any unbiased
estimator can reach on the same records, so that the measured ratio can be
compared with the bound instead of with 1.

Model and bound
---------------
The records of :func:`subid.experiments.seed002.simulate`: the paper's
4th-order ``G(s) = b(s) / a(s)``, the input linear between samples
(first-order hold), a non-zero initial state ``x0``, and Gaussian output
noise ``v`` of variance ``sigma^2`` (the clean output's variance divided by
``10^(snr / 10)``), white or AR(1) ``v_k = a v_{k-1} + e_k`` started
stationary. The parameters are the eight coefficients of ``b`` and ``a``
(monic ``a``) and the four entries of ``x0`` in the controllable canonical
realisation (:func:`scipy.signal.tf2ss`). With ``J = d y_hat / d theta``
(the sampled output's sensitivities, by central differences of the exact
simulation) the Fisher information is

    I = J^T Sigma_v^{-1} J,    Sigma_v^{-1} = W^T W / var(e),

where ``W`` is the exact whitening map of the stationary AR(1) noise (row 0:
``sqrt(1 - a^2)``, row k: ``e_k - a e_{k-1}``; ``W = I`` for white noise)
and ``var(e) = (1 - a^2) sigma^2`` (Ljung 1999, Sec. 7.4 and 9.3: the noise
model is known here; estimating it as well does not change the bound on the
``G`` parameters in open loop, where the Fisher information is block
diagonal). An efficient estimator's error is, to first order, Gaussian
with covariance ``I^{-1}`` (Cramér-Rao), and the error of ``G(i w)`` is
``dG/dtheta (theta_hat - theta)``, with ``dG/db_j = (i w)^j / a(i w)``,
``dG/da_j = -G (i w)^j / a(i w)``. :func:`bound_errors` draws that error
(``theta_hat - theta = R^{-1} z``, ``I = R^T R``, ``z`` standard normal) and
returns ``max_w |G - G_hat|`` per draw: the median of those is the bound on
the figure ``bench/ct_coloured.py`` measures.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.signal

from subid.experiments.seed002 import DENOMINATOR, FREQUENCIES, NUMERATOR, simulate
from subid.model.statespace import StateSpace

__all__ = ["fisher_information", "bound_errors", "median_bound"]


def _output(theta, u, t):
    """Sampled output of the model with coefficients ``theta[:8]`` (b3..b0, a3..a0) from
    the initial state ``theta[8:]``, the input linear between samples."""
    num = theta[:4]
    den = np.concatenate([[1.0], theta[4:8]])
    A, B, C, D = scipy.signal.tf2ss(num, den)
    model = StateSpace(A, B, C, D, 0.0)
    return model.simulate(u, t=t, x0=theta[8:], hold="foh")[:, 0]


def fisher_information(n_samples: int, seed: int, *, noise_pole: float = 0.0,
                       snr_db: float = 20.0):
    """Fisher information of ``(b, a, x0)`` for one record of the seed-002 experiment.

    Parameters
    ----------
    n_samples : int
        Record length L.
    seed : int
        Seed of :func:`subid.experiments.seed002.simulate` (the input and the
        initial state; the noise draw does not enter the bound).
    noise_pole : float
        AR(1) pole of the output noise in sample steps (0: white).
    snr_db : float
        Signal-to-noise ratio of the record.

    Returns
    -------
    ndarray
        The 12 x 12 information matrix.
    """
    data, y, x = simulate(n_samples, seed, return_state=True)
    # the experiment's state is in the realisation of paper_system (tf2ss): the same
    theta = np.concatenate([NUMERATOR, DENOMINATOR[1:], x[0]])
    u, t = data.u, data.t
    J = np.empty((n_samples, theta.size))
    for j in range(theta.size):
        h = 1e-6 * max(abs(theta[j]), 1.0)
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        J[:, j] = (_output(up, u, t) - _output(down, u, t)) / (2.0 * h)
    sigma2 = float(np.var(y[:, 0])) * 10.0 ** (-snr_db / 10.0)
    a = float(noise_pole)
    Jw = J.copy()
    if a:
        Jw[0] = np.sqrt(1.0 - a * a) * J[0]
        Jw[1:] = J[1:] - a * J[:-1]
    return Jw.T @ Jw / ((1.0 - a * a) * sigma2)


def _gradient(w):
    """``dG(i w)/d(b3..b0, a3..a0)`` at the true system, shape (len(w), 8)."""
    s = 1j * np.asarray(w)
    num = np.polyval(NUMERATOR, s)
    den = np.polyval(DENOMINATOR, s)
    G = num / den
    powers = np.stack([s ** 3, s ** 2, s, np.ones_like(s)], axis=1)
    return np.hstack([powers / den[:, None], -(G / den)[:, None] * powers])


def bound_errors(information, draws: int, seed: int, *, frequencies=FREQUENCIES):
    """``max_w |G - G_hat|`` of ``draws`` errors distributed as the Cramér-Rao bound.

    Parameters
    ----------
    information : ndarray
        Fisher information of :func:`fisher_information`.
    draws : int
        Number of draws.
    seed : int
        Seed of the draws.
    frequencies : ndarray
        Frequencies (rad/s) of the maximum.

    Returns
    -------
    ndarray
        One maximum error per draw.
    """
    R = scipy.linalg.cholesky(information, lower=False)
    z = np.random.default_rng(seed).standard_normal((information.shape[0], draws))
    delta = scipy.linalg.solve_triangular(R, z, lower=False)    # covariance I^{-1}
    dG = _gradient(frequencies) @ delta[:8]
    return np.abs(dG).max(axis=0)


def median_bound(n_samples: int, seeds, *, noise_pole: float = 0.0, snr_db: float = 20.0,
                 draws: int = 400) -> float:
    """Median over ``seeds`` (records) and ``draws`` (errors per record) of the
    Cramér-Rao ``max_w |G - G_hat|``.

    Parameters
    ----------
    n_samples : int
        Record length L.
    seeds : iterable of int
        Records of :func:`subid.experiments.seed002.simulate`.
    noise_pole : float
        AR(1) pole of the output noise (0: white).
    snr_db : float
        Signal-to-noise ratio.
    draws : int
        Draws per record.

    Returns
    -------
    float
    """
    out = [bound_errors(fisher_information(n_samples, s, noise_pole=noise_pole,
                                           snr_db=snr_db), draws, 1000 + s)
           for s in seeds]
    return float(np.median(np.concatenate(out)))
