"""A symmetric covariance as its packed upper triangle (n (n + 1) / 2 floats, row by row).

The smoothers store P(k|k) packed per epoch or per segment: 36 instead of 64 floats
for the 8-state model, 55 instead of 100 for the 10-state one.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def packed_length(n: int) -> int:
    """Floats in the packed upper triangle of an n x n matrix."""
    return n * (n + 1) // 2


@njit(cache=True, error_model="numpy")
def pack(P: np.ndarray, out: np.ndarray) -> None:
    """Upper triangle of symmetric P, row by row, into ``out[:n (n + 1) / 2]``."""
    n = P.shape[0]
    m = 0
    for i in range(n):
        for j in range(i, n):
            out[m] = P[i, j]
            m += 1


@njit(cache=True, error_model="numpy")
def unpack(v: np.ndarray, P: np.ndarray) -> None:
    """Inverse of :func:`pack`: P (n x n, allocated) from ``v[:n (n + 1) / 2]``, mirrored."""
    n = P.shape[0]
    m = 0
    for i in range(n):
        for j in range(i, n):
            P[i, j] = v[m]
            P[j, i] = v[m]
            m += 1
