"""Small dense linear algebra for the compiled filter kernels (numba, nopython).

Written by hand rather than calling ``np.linalg`` inside numba: for the 2x2 to
10x10 matrices of these filters a plain Cholesky is several times faster than
a LAPACK call through numba's wrappers (which also need SciPy at run time), and
it lets us floor the pivots so a covariance that rounding pushed slightly
indefinite is repaired instead of producing NaN.

All functions work in place on preallocated arrays where they can: no per-epoch
allocation in the filter loops.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Smallest pivot accepted in a Cholesky factorisation, relative to the diagonal.
PIVOT_FLOOR = 1e-12


@njit(cache=True)
def symmetrize(P: np.ndarray) -> None:
    """P <- (P + P^T)/2 in place."""
    k = P.shape[0]
    for i in range(k):
        for j in range(i + 1, k):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@njit(cache=True)
def cholesky(A: np.ndarray, L: np.ndarray) -> bool:
    """Lower Cholesky factor of symmetric A into L.  Returns False if a pivot had to be floored."""
    k = A.shape[0]
    ok = True
    for i in range(k):
        for j in range(k):
            L[i, j] = 0.0
    for j in range(k):
        s = A[j, j]
        for m in range(j):
            s -= L[j, m] * L[j, m]
        floor = PIVOT_FLOOR * max(abs(A[j, j]), 1e-300)
        if not (s > floor):  # also catches NaN
            s = floor
            ok = False
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, k):
            s2 = A[i, j]
            for m in range(j):
                s2 -= L[i, m] * L[j, m]
            L[i, j] = s2 / d
    return ok


@njit(cache=True)
def chol_solve(L: np.ndarray, B: np.ndarray) -> None:
    """Solve (L L^T) X = B in place (B becomes X); B is (k, m)."""
    k = L.shape[0]
    m = B.shape[1]
    for c in range(m):
        for i in range(k):  # forward: L y = b
            s = B[i, c]
            for j in range(i):
                s -= L[i, j] * B[j, c]
            B[i, c] = s / L[i, i]
        for i in range(k - 1, -1, -1):  # backward: L^T x = y
            s = B[i, c]
            for j in range(i + 1, k):
                s -= L[j, i] * B[j, c]
            B[i, c] = s / L[i, i]


@njit(cache=True)
def is_spd(P: np.ndarray) -> bool:
    """True when P is symmetric (to rounding) and its Cholesky needs no floored pivot."""
    k = P.shape[0]
    for i in range(k):
        if not np.isfinite(P[i, i]) or P[i, i] <= 0.0:
            return False
        for j in range(i + 1, k):
            if abs(P[i, j] - P[j, i]) > 1e-9 * (abs(P[i, j]) + abs(P[j, i]) + 1e-300):
                return False
    L = np.empty_like(P)
    return cholesky(P, L)


@njit(cache=True)
def rts_step(x_post: np.ndarray, P_post: np.ndarray, x_prior_next: np.ndarray,
             P_prior_next: np.ndarray, Phi_next: np.ndarray, x_s_next: np.ndarray,
             P_s_next: np.ndarray, x_s: np.ndarray, P_s: np.ndarray,
             work_L: np.ndarray, work_B: np.ndarray) -> None:
    """One backward step of the Rauch-Tung-Striebel smoother (Rauch, Tung & Striebel 1965).

    Given the forward filter's posterior at k (``x_post, P_post``), its prior at
    k+1 (``x_prior_next, P_prior_next`` = Phi P_post Phi^T + Q) with ``Phi_next``,
    and the smoothed estimate at k+1, write the smoothed estimate at k:

        C   = P_post Phi^T P_prior_next^-1          (a solve, not an inverse)
        x_s = x_post + C (x_s_next - x_prior_next)
        P_s = P_post + C (P_s_next - P_prior_next) C^T

    ``work_L`` and ``work_B`` are (k, k) scratch arrays.
    """
    k = x_post.shape[0]
    # B = Phi P_post  (so that C^T = P_prior^-1 Phi P_post, P_post symmetric)
    for i in range(k):
        for j in range(k):
            s = 0.0
            for m in range(k):
                s += Phi_next[i, m] * P_post[m, j]
            work_B[i, j] = s
    cholesky(P_prior_next, work_L)
    chol_solve(work_L, work_B)  # work_B = C^T
    for i in range(k):
        s = x_post[i]
        for m in range(k):
            s += work_B[m, i] * (x_s_next[m] - x_prior_next[m])
        x_s[i] = s
    # D = (P_s_next - P_prior_next) C^T, then P_s = P_post + C D
    D = work_L  # reuse: L no longer needed
    for i in range(k):
        for j in range(k):
            s = 0.0
            for m in range(k):
                s += (P_s_next[i, m] - P_prior_next[i, m]) * work_B[m, j]
            D[i, j] = s
    for i in range(k):
        for j in range(k):
            s = P_post[i, j]
            for m in range(k):
                s += work_B[m, i] * D[m, j]
            P_s[i, j] = s
    symmetrize(P_s)
