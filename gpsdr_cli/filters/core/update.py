"""One guarded scalar measurement update in Joseph form, for every filter.

docs/algorithms.md#cycle.  A measurement row ``z = h(x) + v``, ``var(v) = R w`` with the
innovation ``y = z - h(x)`` and ``s = P H^T`` (the caller forms it: a unit row reads P's
column, a sparse or dense row sums over its nonzeros):

    S = H P H^T + R w,   K = s / S,   x += K y,
    P <- (I - K H) P (I - K H)^T + R w K K^T      (Joseph form)

``w`` is the robust-weight hook: a scale on R the caller passes in (1 for a plain row).
The Joseph form is exact for any gain, so the gain may be edited before it is applied:
``consider`` is a bit mask of Schmidt consider states (gain zero: not corrected by this
row, their uncertainty still in S and the cross-covariances), and ``(along_e, along_n)``,
a unit vector, projects the gains of the (e, n) pairs of the kinematic states, indices
(i, i + 3) for i < 3 in both state layouts, on that direction.  The update is skipped
(False) when S is not positive and finite or y is not finite: P and x stay as they were.

Scratch: ``K`` and ``PHt`` (n,), no allocation.  Every function takes the state size ``n``
first and is inlined into its caller: each family wraps them in its own compiled row
updates with its size as a constant (``N_STATES``, ``NX``), so the loops have a known
trip count and compile as if written for that size (as calls with ``x.shape[0]`` the
federated filter ran 40 % slower).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: m^2/s^3: both families' zero-acceleration rows before a GNSS-only drive's step into a
#: no-fix epoch (``R = this / T``, so the rate does not matter): the acceleration is ~0 when
#: the step starts, and the last fixes' velocity is held.  As coasting rows at
#: coast_acc_psd = 1 they let in about a second of the last acceleration: after a real log's
#: last fix the speed ran 1.9 -> 13.3 m/s in a minute (aekf), 2.7 -> 5.9 m/s (fkf)
NO_DR_COAST_Q = 1e-3


@njit(cache=True, error_model="numpy", inline="always")
def joseph_apply(n: int, P: np.ndarray, K: np.ndarray, PHt: np.ndarray, HPHt: float, R: float) -> None:
    """P <- (I - K H) P (I - K H)^T + R K K^T in place, for a scalar row with P H^T = PHt.

    With ``B = (I - K H) P = P - K PHt^T`` and ``B H^T = PHt - K (H P H^T)`` (valid for
    any gain) the result is ``B - (B H^T) K^T + R K K^T``; evaluated on the upper
    triangle and mirrored, so P stays exactly symmetric (one O(n^2) pass).
    """
    for i in range(n):
        ki = K[i]
        bi = PHt[i] - ki * HPHt
        for j in range(i, n):
            v = P[i, j] - ki * PHt[j] - bi * K[j] + R * ki * K[j]
            P[i, j] = v
            P[j, i] = v


@njit(cache=True, error_model="numpy", inline="always")
def gain_update(n: int, x: np.ndarray, P: np.ndarray, PHt: np.ndarray, HPHt: float, y: float,
                R: float, K: np.ndarray, consider: int, along_e: float,
                along_n: float) -> bool:
    """The update from ``PHt = P H^T`` and ``HPHt = H P H^T`` (R already scaled by w)."""
    S = HPHt + R
    if not (S > 0.0) or not math.isfinite(S) or not math.isfinite(y):
        return False
    for i in range(n):
        K[i] = PHt[i] / S
    if consider > 0:
        for i in range(n):
            if (consider >> i) & 1:
                K[i] = 0.0
    if along_e != 0.0 or along_n != 0.0:
        for o in range(3):
            dot = K[o] * along_e + K[o + 3] * along_n
            K[o] = dot * along_e
            K[o + 3] = dot * along_n
    for i in range(n):
        x[i] += K[i] * y
    joseph_apply(n, P, K, PHt, HPHt, R)
    return True


@njit(cache=True, error_model="numpy", inline="always")
def unit_update(n: int, x: np.ndarray, P: np.ndarray, idx: int, y: float, R: float, w: float,
                K: np.ndarray, PHt: np.ndarray, consider: int) -> bool:
    """The update for ``H = e_idx`` (one state measured directly)."""
    for i in range(n):
        PHt[i] = P[i, idx]
    return gain_update(n, x, P, PHt, P[idx, idx], y, R * w, K, consider, 0.0, 0.0)


@njit(cache=True, error_model="numpy", inline="always")
def sparse_update(n: int, x: np.ndarray, P: np.ndarray, H: np.ndarray, nz: np.ndarray, y: float,
                  R: float, w: float, K: np.ndarray, PHt: np.ndarray, consider: int,
                  along_e: float, along_n: float) -> bool:
    """The update for a row H whose nonzeros are at the indices ``nz`` (ascending)."""
    nnz = nz.shape[0]
    for i in range(n):
        s = 0.0
        for q in range(nnz):
            s += P[i, nz[q]] * H[nz[q]]
        PHt[i] = s
    HPHt = 0.0
    for q in range(nnz):
        HPHt += H[nz[q]] * PHt[nz[q]]
    return gain_update(n, x, P, PHt, HPHt, y, R * w, K, consider, along_e, along_n)


@njit(cache=True, error_model="numpy", inline="always")
def dense_update(n: int, x: np.ndarray, P: np.ndarray, h: np.ndarray, y: float, R: float, w: float,
                 K: np.ndarray, PHt: np.ndarray, consider: int = 0) -> bool:
    """The update for a dense row h (its zeros skipped)."""
    for i in range(n):
        PHt[i] = 0.0
    for j in range(n):
        hj = h[j]
        if hj != 0.0:
            for i in range(n):
                PHt[i] += P[i, j] * hj
    HPHt = 0.0
    for j in range(n):
        if h[j] != 0.0:
            HPHt += h[j] * PHt[j]
    return gain_update(n, x, P, PHt, HPHt, y, R * w, K, consider, 0.0, 0.0)
