"""The shared Kalman core (gpsdr_cli/filters/core): solve, packing, RTS step."""

from __future__ import annotations

import numpy as np

from gpsdr_cli.filters.core.linalg import chol_solve, cholesky
from gpsdr_cli.filters.core.packing import pack, packed_length, unpack
from gpsdr_cli.filters.core.rts import phi_times, rts_step


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def _solve_by_columns(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Forward and back substitution one column at a time, as a textbook writes it."""
    X = B.copy()
    k = L.shape[0]
    for c in range(X.shape[1]):
        for i in range(k):
            s = X[i, c]
            for j in range(i):
                s -= L[i, j] * X[j, c]
            X[i, c] = s / L[i, i]
        for i in range(k - 1, -1, -1):
            s = X[i, c]
            for j in range(i + 1, k):
                s -= L[j, i] * X[j, c]
            X[i, c] = s / L[i, i]
    return X


def test_solve_is_the_column_substitution_bit_for_bit_and_solves() -> None:
    rng = np.random.default_rng(1)
    for n in (2, 8, 10):
        A = _spd(rng, n)
        L = np.zeros((n, n))
        assert cholesky(A, L)
        B = rng.normal(size=(n, n))
        X = B.copy()
        chol_solve(n, L, X)
        np.testing.assert_array_equal(X, _solve_by_columns(L, B))
        np.testing.assert_allclose(A @ X, B, rtol=1e-10, atol=1e-10)


def test_pack_round_trip() -> None:
    rng = np.random.default_rng(2)
    P = _spd(rng, 8)
    v = np.zeros(packed_length(8) + 5)          # longer rows carry more after the triangle
    pack(P, v)
    assert np.all(v[packed_length(8):] == 0.0)
    Q = np.zeros((8, 8))
    unpack(v, Q)
    np.testing.assert_array_equal(Q, np.triu(P) + np.triu(P, 1).T)


def test_rts_step_against_the_textbook_gain() -> None:
    """C = P Phi^T P_prior^-1, x_s = x + C (x_sn - x_prior), P_s = P + C (P_sn - P_prior) C^T."""
    rng = np.random.default_rng(3)
    n = 8
    Phi = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    P = _spd(rng, n)
    Q = 0.2 * _spd(rng, n)
    x = rng.normal(size=n)
    x_prior, P_prior = Phi @ x, Phi @ P @ Phi.T + Q
    x_sn = x_prior + rng.normal(size=n)
    P_sn = 0.5 * P_prior
    B = np.zeros((n, n))
    phi_times(n, Phi, P, B)
    np.testing.assert_allclose(B, Phi @ P, rtol=1e-13, atol=1e-13)
    x_s, P_s = np.zeros(n), np.zeros((n, n))
    rts_step(n, x, P, B, x_prior, P_prior, x_sn, P_sn, x_s, P_s, np.zeros((n, n)), np.zeros(n))
    C = P @ Phi.T @ np.linalg.inv(P_prior)
    np.testing.assert_allclose(x_s, x + C @ (x_sn - x_prior), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P_s, P + C @ (P_sn - P_prior) @ C.T, rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(P_s, P_s.T)


def test_gate_resets_after_the_first_rejection_rule() -> None:
    """ekf/aekf: rejected from the first failing fix until gate_reset_s (>=) has passed."""
    from gpsdr_cli.filters.core.gate import (
        GATE_FAIL,
        GATE_PASS,
        GATE_RESET,
        RESET_AFTER_FIRST_REJECT,
        chi2_gate,
    )
    rule = RESET_AFTER_FIRST_REJECT
    assert chi2_gate(1.0, 9.2, 0.0, -1.0, 5.0, rule, False) == (GATE_PASS, -1.0)
    assert chi2_gate(50.0, 9.2, 10.0, -1.0, 5.0, rule, False) == (GATE_FAIL, 10.0)
    assert chi2_gate(50.0, 9.2, 14.8, 10.0, 5.0, rule, False) == (GATE_FAIL, 10.0)
    assert chi2_gate(50.0, 9.2, 15.0, 10.0, 5.0, rule, False) == (GATE_RESET, -1.0)
    assert chi2_gate(1.0, 9.2, 12.0, 10.0, 5.0, rule, False) == (GATE_PASS, -1.0)  # run ends
    assert chi2_gate(float("nan"), 9.2, 12.0, 10.0, 5.0, rule, False)[0] == GATE_PASS


def test_gate_resets_after_the_last_acceptance_rule() -> None:
    """fkf/fafkf: rejected until more than gate_reset_s after the last accepted fix."""
    from gpsdr_cli.filters.core.gate import (
        GATE_FAIL,
        GATE_PASS,
        GATE_RESET,
        RESET_AFTER_LAST_ACCEPT,
        chi2_gate,
    )
    rule = RESET_AFTER_LAST_ACCEPT
    assert chi2_gate(1.0, 9.2, 20.0, 10.0, 5.0, rule, False) == (GATE_PASS, 10.0)
    assert chi2_gate(50.0, 9.2, 15.0, 10.0, 5.0, rule, False) == (GATE_FAIL, 10.0)
    assert chi2_gate(50.0, 9.2, 15.2, 10.0, 5.0, rule, False) == (GATE_RESET, 10.0)
    assert chi2_gate(50.0, 9.2, 11.0, 10.0, 5.0, rule, True) == (GATE_RESET, 10.0)
