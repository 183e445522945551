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


@njit(cache=True, inline="always")
def chol_solve(n: int, L: np.ndarray, B: np.ndarray) -> None:
    """Solve (L L^T) X = B in place (B becomes X); L is (n, n), B (n, n).

    Row by row, the independent column index innermost (the compiler vectorises
    it); every element sees the same operations in the same order as a column-by-
    column substitution.  Inlined, with the size ``n`` first: a caller that passes
    its size as a constant gets loops of a known trip count.
    """
    for i in range(n):  # forward: L y = b
        for j in range(i):
            lij = L[i, j]
            for c in range(n):
                B[i, c] -= lij * B[j, c]
        for c in range(n):
            B[i, c] = B[i, c] / L[i, i]
    for i in range(n - 1, -1, -1):  # backward: L^T x = y
        for j in range(i + 1, n):
            lji = L[j, i]
            for c in range(n):
                B[i, c] -= lji * B[j, c]
        for c in range(n):
            B[i, c] = B[i, c] / L[i, i]


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
