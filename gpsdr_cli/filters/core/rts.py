"""One backward step of the Rauch-Tung-Striebel smoother (Rauch, Tung & Striebel 1965).

docs/algorithms.md#rts.  Both families call :func:`rts_step`; each forms ``B = Phi
P(k|k)`` its own way (the federated model by Phi's three nonzero bands, the current
statistical model with a dense Phi: :func:`phi_times`), since only that product
depends on the model.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .linalg import chol_solve, cholesky, symmetrize


@njit(cache=True, inline="always")
def phi_times(k: int, Phi: np.ndarray, P: np.ndarray, B: np.ndarray) -> None:
    """B <- Phi P (dense, k x k; inlined, as :func:`rts_step`)."""
    for i in range(k):
        for j in range(k):
            s = 0.0
            for m in range(k):
                s += Phi[i, m] * P[m, j]
            B[i, j] = s


@njit(cache=True, inline="always")
def rts_step(n: int, x_post: np.ndarray, P_post: np.ndarray, B: np.ndarray, x_prior: np.ndarray,
             P_prior: np.ndarray, x_sn: np.ndarray, P_sn: np.ndarray, x_s: np.ndarray,
             P_s: np.ndarray, L: np.ndarray, dx: np.ndarray) -> None:
    """The smoothed estimate at k from the filter's posterior at k and prior at k+1.

    ``x_post, P_post``: the forward posterior at k; ``B`` enters as ``Phi P_post``
    (``Phi`` the transition k -> k+1) and is overwritten; ``x_prior, P_prior`` the
    forward prior at k+1 (``Phi P_post Phi^T + Q``); ``x_sn, P_sn`` the smoothed
    estimate at k+1.  Writes::

        C   = P_post Phi^T P_prior^-1          (a Cholesky solve, no inverse)
        x_s = x_post + C (x_sn - x_prior)
        P_s = P_post + C (P_sn - P_prior) C^T  (symmetrised)

    ``n`` the state size; ``L`` (n, n) and ``dx`` (n,) are scratch.  Every sum runs
    over the same index in the same order whatever the caller, with the independent
    index innermost.  Inlined: a caller passing its size as a constant gets loops of
    a known trip count (the federated smoother's backward pass ran at half the speed
    as a call with the size read from the arrays).
    """
    k = n
    cholesky(P_prior, L)
    chol_solve(k, L, B)                               # B = P_prior^-1 Phi P_post = C^T
    for m in range(k):
        dx[m] = x_sn[m] - x_prior[m]
    for i in range(k):
        x_s[i] = x_post[i]
    for m in range(k):
        for i in range(k):
            x_s[i] += B[m, i] * dx[m]
    D = L                                           # D = (P_sn - P_prior) C^T (L is spent)
    for i in range(k):
        for j in range(k):
            D[i, j] = 0.0
        for m in range(k):
            dif = P_sn[i, m] - P_prior[i, m]
            for j in range(k):
                D[i, j] += dif * B[m, j]
    for i in range(k):                              # P_s = P_post + C D
        for j in range(k):
            P_s[i, j] = P_post[i, j]
        for m in range(k):
            bmi = B[m, i]
            for j in range(k):
                P_s[i, j] += bmi * D[m, j]
    symmetrize(P_s)
