"""Fixed-interval Rauch-Tung-Striebel smoother over the ekf/aekf forward pass (ALGORITHMS.md 5).

The forward kernel (:mod:`gpsdr_cli.filters.kernels_aekf`) stores, per epoch,
the posterior state, the packed upper triangle of P(k|k) (36 floats) and the
six scalars from which P(k+1|k) is rebuilt exactly (process-noise scales,
fading and adaptive-factor multipliers, gate-reset inflation).  The backward
pass recomputes Phi from dt and the prior from P(k|k), so peak memory is about
(8 + 36 + 6) x 8 bytes = 400 B per epoch (144 MB for a one-hour drive at
100 Hz) instead of 2 x 64 x 8 for two full covariance stacks.  Each backward
step is :func:`gpsdr_cli.filters.linalg.rts_step` (a Cholesky solve, no inverse).

Mean transition for the smoother gain: the covariance transition Phi (Singer
blocks) is the one that produced P(k+1|k), so it is the Phi in
``C = P(k|k) Phi^T P(k+1|k)^-1``; the predicted mean is the current
statistical model's (Newton) prediction, as in the forward pass.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .filters.kernels_aekf import (
    P_ALPHA,
    P_EPS_MEAN_DECAY,
    P_Q_EPS,
    P_Q_KS,
    P_TAU_EPS,
    predict_mean,
    rebuild_prior,
    unpack,
)
from .filters.linalg import rts_step
from .models.cs_model import N_STATES, singer_phi


@njit(cache=True)
def _phi_dense(T: float, alpha: float, tau_eps: float, hold: bool, F: np.ndarray) -> None:
    for i in range(N_STATES):
        for j in range(N_STATES):
            F[i, j] = 0.0
        F[i, i] = 1.0
    if not hold:
        p13, p23, p33 = singer_phi(T, alpha)
        for o in (0, 3):
            F[o, o + 1] = T
            F[o, o + 2] = p13
            F[o + 1, o + 2] = p23
            F[o + 2, o + 2] = p33
    F[6, 6] = math.exp(-T / tau_eps)


@njit(cache=True)
def rts_kernel(dt: np.ndarray, hold: np.ndarray, prm: np.ndarray, x_io: np.ndarray,
               P_store: np.ndarray, prior_store: np.ndarray, pcov_out: np.ndarray,
               sd_out: np.ndarray) -> None:
    """Backward RTS pass in place: ``x_io`` (n, 8) posterior states become smoothed states;
    ``pcov_out`` (n, 3) and ``sd_out`` (n, 2) receive the smoothed var_e, var_n, cov_en and
    the sigmas of eps and k_s.  ``hold[k]``: the prediction into epoch k was static (seed 004).
    """
    n_ep = dt.shape[0]
    if n_ep == 0:
        return
    n = N_STATES
    alpha = prm[P_ALPHA]
    tau_eps = prm[P_TAU_EPS]
    P_post = np.zeros((n, n))
    P_prior = np.zeros((n, n))
    P_s_next = np.zeros((n, n))
    P_s = np.zeros((n, n))
    F = np.zeros((n, n))
    L = np.zeros((n, n))
    B = np.zeros((n, n))
    x_post = np.zeros(n)
    x_prior = np.zeros(n)
    x_s_next = x_io[n_ep - 1].copy()
    x_s = np.zeros(n)
    qbuf = np.zeros(6)
    unpack(P_store[n_ep - 1], P_s_next)
    for k in range(n_ep - 2, -1, -1):
        T = dt[k + 1]
        unpack(P_store[k], P_post)
        for i in range(n):
            x_post[i] = x_io[k, i]
        if T > 0.0:
            for i in range(n):
                x_prior[i] = x_post[i]
                for j in range(n):
                    P_prior[i, j] = P_post[i, j]
            f_mean = math.exp(-T / tau_eps) if prm[P_EPS_MEAN_DECAY] != 0.0 else 1.0
            predict_mean(x_prior, T, f_mean, hold[k + 1])
            rebuild_prior(P_prior, T, alpha, tau_eps, prm[P_Q_EPS], prm[P_Q_KS],
                          prior_store[k + 1], hold[k + 1], qbuf)
            _phi_dense(T, alpha, tau_eps, hold[k + 1], F)
            rts_step(x_post, P_post, x_prior, P_prior, F, x_s_next, P_s_next, x_s, P_s, L, B)
        else:  # no time step (only possible at k = 0): the smoothed estimate carries over
            for i in range(n):
                x_s[i] = x_s_next[i]
                for j in range(n):
                    P_s[i, j] = P_s_next[i, j]
        for i in range(n):
            x_io[k, i] = x_s[i]
            x_s_next[i] = x_s[i]
            for j in range(n):
                P_s_next[i, j] = P_s[i, j]
        pcov_out[k, 0] = P_s[0, 0]
        pcov_out[k, 1] = P_s[3, 3]
        pcov_out[k, 2] = P_s[0, 3]
        sd_out[k, 0] = math.sqrt(max(P_s[6, 6], 0.0))
        sd_out[k, 1] = math.sqrt(max(P_s[7, 7], 0.0))


def rts_smooth(dt_s: np.ndarray, hold: np.ndarray, prm: np.ndarray, x_post: np.ndarray,
               P_store: np.ndarray, prior_store: np.ndarray, pcov: np.ndarray,
               sd: np.ndarray) -> None:
    """Smooth the forward pass in place (see :func:`rts_kernel`)."""
    rts_kernel(np.ascontiguousarray(dt_s, dtype=np.float64), np.ascontiguousarray(hold),
               prm, x_post, P_store, prior_store, pcov, sd)
