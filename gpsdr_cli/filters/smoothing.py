"""Fixed-interval Rauch-Tung-Striebel smoother over the ekf/aekf forward pass (docs/algorithms.md#rts).

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
:func:`gpsdr_cli.filters.core.rts.rts_step` (a Cholesky solve, no inverse).

Mean transition for the smoother gain: the covariance transition Phi (Singer
blocks) is the one that produced P(k+1|k), so it is the Phi in
``C = P(k|k) Phi^T P(k+1|k)^-1``; the predicted mean is the current
statistical model's (Newton) prediction, as in the forward pass.  With
``aekf.turn_propagation`` the forward pass also turned the velocity and
acceleration by the gyro (the rate used is stored per epoch), so the
transition is ``J Phi`` with J the Jacobian of that turn at the predicted mean
(:func:`gpsdr_cli.filters.kernels_aekf.turn_jacobian`) and the predicted mean
is the turned one.

With ``aekf.gnss_err_states`` the state has two more entries, the GNSS error
states b: the forward pass stores P(x, b) and P(b, b) after the packed P, and
each step is a 10-state RTS step whose prior block is rebuilt by
:func:`ge_prior` (the kernel's ``ge_epoch``) and whose transition has
``f_b = exp(-T/tau_b)`` (stored per epoch) for b.  A time-correlated measurement
error smoothed as states, not as white noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

from ..models.cs_model import IE, IEPS, IKS, IN, N_STATES, phi_into
from .core.packing import unpack
from .core.rts import phi_times, rts_step
from .kernels_aekf import (
    GE_BE,
    GE_BN,
    GE_PEE,
    GE_PEN,
    GE_PNN,
    GW_PRED,
    GW_ROWS,
    N_GE,
    N_GE_PACKED,
    N_PACKED,
    PAR_ALPHA,
    PAR_EPS_MEAN_DECAY,
    PAR_Q_EPS,
    PAR_Q_KS,
    PAR_R_OMEGA,
    PAR_SCALE_VAR,
    PAR_TAU_EPS,
    PRI_FB,
    PRI_GAIN,
    PRI_JUMP_E,
    PRI_JUMP_N,
    PRI_LAM,
    PRI_VB,
    PRI_W,
    ge_epoch,
    ge_turn,
    predict_mean,
    rebuild_prior,
    turn_jacobian,
)


@njit(cache=True)
def ge_prior(G: np.ndarray, gw: np.ndarray, x: np.ndarray, T: float, alpha: float,
             tau_eps: float, pr: np.ndarray, hold: bool, var_b: float) -> None:
    """The GNSS error block of k-1 -> the prior of k the forward pass used (kernels_aekf.ge_epoch).

    ``x``: the predicted, turned mean (from rebuild_prior); ``pr`` the stored prior scalars
    (f_b, the gyro rate of the turn, fading, the innovation adaptive factor).
    """
    gw[GW_PRED, 0] = T
    gw[GW_PRED, 1] = math.exp(-T / tau_eps)
    gw[GW_PRED, 2] = pr[PRI_LAM]
    gw[GW_PRED, 3] = 1.0 if hold else 0.0
    gw[GW_PRED, 4] = pr[PRI_FB]
    gw[GW_PRED, 5] = 0.0
    if math.isfinite(pr[PRI_W]):
        ge_turn(gw, x, T, pr[PRI_W])
    ge_epoch(G, gw, np.int64(0), T > 0.0, alpha, var_b)  # int64 and bool: the kernel's types
    if pr[PRI_GAIN] != 1.0:  # innovation adaptive factor: the kinematic rows of P(x, b) too
        for i in range(12):
            G[i] *= math.sqrt(pr[PRI_GAIN])


@njit(cache=True)
def _join(P8: np.ndarray, G: np.ndarray, P10: np.ndarray) -> None:
    """The 10-state covariance [[P, P(x, b)], [P(b, x), P(b, b)]] from P and the block G (GE_*)."""
    for i in range(N_STATES):
        for j in range(N_STATES):
            P10[i, j] = P8[i, j]
        for j in range(2):
            P10[i, N_STATES + j] = G[2 * i + j]
            P10[N_STATES + j, i] = G[2 * i + j]
    P10[N_STATES, N_STATES] = G[GE_PEE]
    P10[N_STATES, N_STATES + 1] = G[GE_PEN]
    P10[N_STATES + 1, N_STATES] = G[GE_PEN]
    P10[N_STATES + 1, N_STATES + 1] = G[GE_PNN]


@njit(cache=True)
def rts_segment(dt: np.ndarray, hold: np.ndarray, prm: np.ndarray, x_io: np.ndarray,
                P_seg: np.ndarray, p_off: int, k_hi: int, k_lo: int, prior_store: np.ndarray,
                pcov_out: np.ndarray, sd_out: np.ndarray, x_s_next: np.ndarray,
                P_s_next: np.ndarray, b_io: np.ndarray, ge_on: bool) -> None:
    """Backward RTS steps k = k_hi, k_hi - 1, ..., k_lo, in place.

    ``ge_on`` (aekf.gnss_err_states): the state has the two GNSS error states b
    (``b_io[:, k]`` forward posterior in, smoothed out; their covariances stored
    after the packed P); the step is then a 10-state RTS step whose prior is
    rebuilt with the 8-state one (:func:`~gpsdr_cli.filters.kernels_aekf.rebuild_prior`) and whose
    transition has ``f_b = prior_store[k + 1, PRI_FB]`` for b.  ``x_s_next``,
    ``P_s_next`` are then 10-long / 10 x 10.

    ``x_io[:, k]`` holds the forward posterior and receives the smoothed state;
    ``P_seg[k - p_off]`` the packed P(k|k); ``x_s_next, P_s_next`` enter as the
    smoothed estimate at k_hi + 1 and leave as the one at k_lo.  ``pcov_out``
    (3, n) and ``sd_out`` (2, n) receive the smoothed var_e, var_n, cov_en and the
    sigmas of eps and k_s.  ``hold[k]``: the prediction into epoch k was static.
    """
    n8 = N_STATES
    n = N_STATES + 2 if ge_on else N_STATES
    alpha = prm[PAR_ALPHA]
    tau_eps = prm[PAR_TAU_EPS]
    P8 = np.zeros((n8, n8))
    G = np.zeros(N_GE if ge_on else 0)
    gw = np.zeros((GW_ROWS, N_STATES))
    P_post = np.zeros((n, n))
    P_prior = np.zeros((n, n))
    P_s = np.zeros((n, n))
    F = np.zeros((n, n))
    F8 = np.zeros((n8, n8))
    L = np.zeros((n, n))
    B = np.zeros((n, n))
    dx = np.zeros(n)
    x_post = np.zeros(n)
    x_prior = np.zeros(n)
    x8 = np.zeros(n8)
    x_s = np.zeros(n)
    qbuf = np.zeros(6)
    for k in range(k_hi, k_lo - 1, -1):
        T = dt[k + 1]
        row = P_seg[k - p_off]
        unpack(row, P8)
        for i in range(n8):
            x8[i] = x_io[i, k]
        if ge_on:
            for i in range(N_GE_PACKED):
                G[i] = row[N_PACKED + i]
            _join(P8, G, P_post)
            x_post[n8] = b_io[0, k]
            x_post[n8 + 1] = b_io[1, k]
        else:
            for i in range(n8):
                for j in range(n8):
                    P_post[i, j] = P8[i, j]
        for i in range(n8):
            x_post[i] = x8[i]
        if T > 0.0:
            pr = prior_store[k + 1]
            f_mean = math.exp(-T / tau_eps) if prm[PAR_EPS_MEAN_DECAY] != 0.0 else 1.0
            predict_mean(x8, T, f_mean, hold[k + 1])
            phi_into(T, alpha, tau_eps, hold[k + 1], F8)
            w = pr[PRI_W]
            if math.isfinite(w):  # aekf.turn_propagation: F = J Phi at the predicted mean
                turn_jacobian(F8, x8, T, w)
            if ge_on:
                G[GE_BE] = x_post[n8]
                G[GE_BN] = x_post[n8 + 1]
            # the prior as the forward pass built it, the GNSS error block with it
            rebuild_prior(P8, x8, T, alpha, tau_eps, prm[PAR_Q_EPS], prm[PAR_Q_KS],
                          prm[PAR_R_OMEGA], pr, hold[k + 1], qbuf, prm[PAR_SCALE_VAR])
            if ge_on:
                ge_prior(G, gw, x8, T, alpha, tau_eps, pr, hold[k + 1], pr[PRI_VB])
            for i in range(n8):
                x_prior[i] = x8[i]
                for j in range(n8):
                    F[i, j] = F8[i, j]
            if ge_on:
                _join(P8, G, P_prior)
                x_prior[n8] = G[GE_BE]
                x_prior[n8 + 1] = G[GE_BN]
                # the bias gate moved b into the position before this epoch's fix
                x_prior[IE] += pr[PRI_JUMP_E]
                x_prior[IN] += pr[PRI_JUMP_N]
                x_prior[n8] -= pr[PRI_JUMP_E]
                x_prior[n8 + 1] -= pr[PRI_JUMP_N]
                for i in range(n8):
                    F[i, n8] = 0.0
                    F[i, n8 + 1] = 0.0
                    F[n8, i] = 0.0
                    F[n8 + 1, i] = 0.0
                F[n8, n8] = pr[PRI_FB]
                F[n8 + 1, n8 + 1] = pr[PRI_FB]
                F[n8, n8 + 1] = 0.0
                F[n8 + 1, n8] = 0.0
            else:
                for i in range(n8):
                    for j in range(n8):
                        P_prior[i, j] = P8[i, j]
            # the size as a constant: loops of a known trip count (0.6x the time)
            if ge_on:
                phi_times(N_STATES + 2, F, P_post, B)
                rts_step(N_STATES + 2, x_post, P_post, B, x_prior, P_prior, x_s_next, P_s_next,
                         x_s, P_s, L, dx)
            else:
                phi_times(N_STATES, F, P_post, B)
                rts_step(N_STATES, x_post, P_post, B, x_prior, P_prior, x_s_next, P_s_next,
                         x_s, P_s, L, dx)
        else:  # no time step: the smoothed estimate carries over
            for i in range(n):
                x_s[i] = x_s_next[i]
                for j in range(n):
                    P_s[i, j] = P_s_next[i, j]
        for i in range(n8):
            x_io[i, k] = x_s[i]
        if ge_on:
            b_io[0, k] = x_s[n8]
            b_io[1, k] = x_s[n8 + 1]
        for i in range(n):
            x_s_next[i] = x_s[i]
            for j in range(n):
                P_s_next[i, j] = P_s[i, j]
        pcov_out[0, k] = P_s[IE, IE]
        pcov_out[1, k] = P_s[IN, IN]
        pcov_out[2, k] = P_s[IE, IN]
        sd_out[0, k] = math.sqrt(max(P_s[IEPS, IEPS], 0.0))
        sd_out[1, k] = math.sqrt(max(P_s[IKS, IKS], 0.0))


def rts_checkpointed(run_segment: Callable[[int, int, np.ndarray, np.ndarray, np.ndarray,
                                            np.ndarray, np.ndarray], None],
                     checkpoints: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray,
                                             np.ndarray]],
                     dt_s: np.ndarray, hold: np.ndarray, prm: np.ndarray, x_out: np.ndarray,
                     prior_store: np.ndarray, pcov: np.ndarray, sd: np.ndarray,
                     P_seg: np.ndarray, b_out: np.ndarray, ge_on: bool) -> None:
    """Smooth the forward pass in place, segment by segment from the end.

    ``checkpoints``: per segment ``(k0, k1, x, P, st, ge)``, the filter state before
    epoch k0 (``ge`` the GNSS error block).  ``run_segment(k0, k1, x, P, st, ge, P_seg)``
    re-runs the forward
    kernel over the segment from that state, storing P(k|k) into ``P_seg``
    (bit-identical to the first pass); then :func:`rts_segment` walks it
    backwards.  Memory: one segment of packed covariances plus the checkpoints.
    """
    n_ep = len(dt_s)
    if n_ep < 2:
        return
    dt = np.ascontiguousarray(dt_s, dtype=np.float64)
    hold = np.ascontiguousarray(hold)
    m = N_STATES + 2 if ge_on else N_STATES
    x_s_next = np.zeros(m)
    P_s_next = np.zeros((m, m))
    for j in range(len(checkpoints) - 1, -1, -1):
        k0, k1, x, P, st, ge = checkpoints[j]
        run_segment(k0, k1, x.copy(), P.copy(), st.copy(), ge.copy(), P_seg)
        k_hi = k1 - 1
        if k1 == n_ep:  # last segment: the smoothed estimate at n-1 is the filtered one
            x_s_next[:N_STATES] = x_out[:, n_ep - 1]
            P8 = np.zeros((N_STATES, N_STATES))
            unpack(P_seg[n_ep - 1 - k0], P8)
            P_s_next[:N_STATES, :N_STATES] = P8
            if ge_on:
                G = np.zeros(N_GE)
                G[:N_GE_PACKED] = P_seg[n_ep - 1 - k0, N_PACKED:N_PACKED + N_GE_PACKED]
                _join(P8, G, P_s_next)
                x_s_next[N_STATES:] = b_out[:, n_ep - 1]
            k_hi = n_ep - 2
        if k_hi >= k0:
            rts_segment(dt, hold, prm, x_out, P_seg, k0, k_hi, k0, prior_store, pcov, sd,
                        x_s_next, P_s_next, b_out, ge_on)
