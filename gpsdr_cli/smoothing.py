"""Fixed-interval Rauch-Tung-Striebel smoother over the ekf/aekf forward pass (ALGORITHMS.md 5).

Checkpointed: the forward kernel (:mod:`gpsdr_cli.filters.kernels_aekf`) keeps,
per epoch, only the posterior state (8 floats) and the seven scalars from which
P(k+1|k) is rebuilt exactly from P(k|k) (process-noise scales, fading and
adaptive-factor multipliers, gate-reset inflation, gyro rate of the turn), plus a checkpoint of the
filter state every segment (4096 epochs).  The backward pass re-runs each
segment forward from its checkpoint (bit-identical), storing the packed upper
triangle of P(k|k) for that segment only, then walks it backwards; Phi is
recomputed from dt.  Cost: one extra forward pass.  Memory: about
(8 + 7) x 8 = 120 B per epoch (43 MB for a one-hour drive at 100 Hz) instead
of 2 x 64 x 8 for two full covariance stacks (368 MB).  Each backward step is
:func:`gpsdr_cli.filters.linalg.rts_step` (a Cholesky solve, no inverse).

Mean transition for the smoother gain: the covariance transition Phi (Singer
blocks) is the one that produced P(k+1|k), so it is the Phi in
``C = P(k|k) Phi^T P(k+1|k)^-1``; the predicted mean is the current
statistical model's (Newton) prediction, as in the forward pass.  With
``aekf.turn_propagation`` the forward pass also turned the velocity and
acceleration by the gyro (the rate used is stored per epoch), so the
transition is ``J Phi`` with J the Jacobian of that turn at the predicted mean
(:func:`gpsdr_cli.filters.kernels_aekf.turn_jacobian`) and the predicted mean
is the turned one.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

from .filters.kernels_aekf import (
    P_ALPHA,
    P_EPS_MEAN_DECAY,
    P_Q_EPS,
    P_Q_KS,
    P_R_OMEGA,
    P_SCALE_VAR,
    P_TAU_EPS,
    Q_W,
    predict_mean,
    rebuild_prior,
    turn_jacobian,
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
def rts_segment(dt: np.ndarray, hold: np.ndarray, prm: np.ndarray, x_io: np.ndarray,
                P_seg: np.ndarray, p_off: int, k_hi: int, k_lo: int, prior_store: np.ndarray,
                pcov_out: np.ndarray, sd_out: np.ndarray, x_s_next: np.ndarray,
                P_s_next: np.ndarray) -> None:
    """Backward RTS steps k = k_hi, k_hi - 1, ..., k_lo, in place.

    ``x_io[:, k]`` holds the forward posterior and receives the smoothed state;
    ``P_seg[k - p_off]`` the packed P(k|k); ``x_s_next, P_s_next`` enter as the
    smoothed estimate at k_hi + 1 and leave as the one at k_lo.  ``pcov_out``
    (3, n) and ``sd_out`` (2, n) receive the smoothed var_e, var_n, cov_en and the
    sigmas of eps and k_s.  ``hold[k]``: the prediction into epoch k was static.
    """
    n = N_STATES
    alpha = prm[P_ALPHA]
    tau_eps = prm[P_TAU_EPS]
    P_post = np.zeros((n, n))
    P_prior = np.zeros((n, n))
    P_s = np.zeros((n, n))
    F = np.zeros((n, n))
    L = np.zeros((n, n))
    B = np.zeros((n, n))
    x_post = np.zeros(n)
    x_prior = np.zeros(n)
    x_s = np.zeros(n)
    qbuf = np.zeros(6)
    for k in range(k_hi, k_lo - 1, -1):
        T = dt[k + 1]
        unpack(P_seg[k - p_off], P_post)
        for i in range(n):
            x_post[i] = x_io[i, k]
        if T > 0.0:
            for i in range(n):
                x_prior[i] = x_post[i]
                for j in range(n):
                    P_prior[i, j] = P_post[i, j]
            f_mean = math.exp(-T / tau_eps) if prm[P_EPS_MEAN_DECAY] != 0.0 else 1.0
            predict_mean(x_prior, T, f_mean, hold[k + 1])
            _phi_dense(T, alpha, tau_eps, hold[k + 1], F)
            w = prior_store[k + 1, Q_W]
            if math.isfinite(w):  # aekf.turn_propagation: F = J Phi at the predicted mean
                turn_jacobian(F, x_prior, T, w)
            rebuild_prior(P_prior, x_prior, T, alpha, tau_eps, prm[P_Q_EPS], prm[P_Q_KS],
                          prm[P_R_OMEGA], prior_store[k + 1], hold[k + 1], qbuf,
                          prm[P_SCALE_VAR])
            rts_step(x_post, P_post, x_prior, P_prior, F, x_s_next, P_s_next, x_s, P_s, L, B)
        else:  # no time step: the smoothed estimate carries over
            for i in range(n):
                x_s[i] = x_s_next[i]
                for j in range(n):
                    P_s[i, j] = P_s_next[i, j]
        for i in range(n):
            x_io[i, k] = x_s[i]
            x_s_next[i] = x_s[i]
            for j in range(n):
                P_s_next[i, j] = P_s[i, j]
        pcov_out[0, k] = P_s[0, 0]
        pcov_out[1, k] = P_s[3, 3]
        pcov_out[2, k] = P_s[0, 3]
        sd_out[0, k] = math.sqrt(max(P_s[6, 6], 0.0))
        sd_out[1, k] = math.sqrt(max(P_s[7, 7], 0.0))


def rts_checkpointed(run_segment: Callable[[int, int, np.ndarray, np.ndarray, np.ndarray,
                                            np.ndarray], None],
                     checkpoints: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray]],
                     dt_s: np.ndarray, hold: np.ndarray, prm: np.ndarray, x_out: np.ndarray,
                     prior_store: np.ndarray, pcov: np.ndarray, sd: np.ndarray,
                     P_seg: np.ndarray) -> None:
    """Smooth the forward pass in place, segment by segment from the end.

    ``checkpoints``: per segment ``(k0, k1, x, P, st)``, the filter state before
    epoch k0.  ``run_segment(k0, k1, x, P, st, P_seg)`` re-runs the forward
    kernel over the segment from that state, storing P(k|k) into ``P_seg``
    (bit-identical to the first pass); then :func:`rts_segment` walks it
    backwards.  Memory: one segment of packed covariances plus the checkpoints.
    """
    n_ep = len(dt_s)
    if n_ep < 2:
        return
    dt = np.ascontiguousarray(dt_s, dtype=np.float64)
    hold = np.ascontiguousarray(hold)
    x_s_next = np.zeros(N_STATES)
    P_s_next = np.zeros((N_STATES, N_STATES))
    for j in range(len(checkpoints) - 1, -1, -1):
        k0, k1, x, P, st = checkpoints[j]
        run_segment(k0, k1, x.copy(), P.copy(), st.copy(), P_seg)
        k_hi = k1 - 1
        if k1 == n_ep:  # last segment: the smoothed estimate at n-1 is the filtered one
            x_s_next[:] = x_out[:, n_ep - 1]
            unpack(P_seg[n_ep - 1 - k0], P_s_next)
            k_hi = n_ep - 2
        if k_hi >= k0:
            rts_segment(dt, hold, prm, x_out, P_seg, k0, k_hi, k0, prior_store, pcov, sd,
                        x_s_next, P_s_next)
