"""The 8-state "current statistical" GNSS/DR model of Fang et al. (docs/algorithms.md#cs-model).

State ``x = [e, v_e, a_e, n, v_n, a_n, eps, k_s]`` (m, m/s, m/s^2 per axis in the
local ENU frame; ``eps`` gyro drift of d(psi)/dt in rad/s, first-order
Gauss-Markov; ``k_s`` odometer scale factor, ~1, random walk).
Heading ``psi = atan2(v_e, v_n)`` clockwise from north, so the measured heading
rate is ``omega = d(psi)/dt = -yaw_rate`` (gyro CCW-positive, see
:mod:`gpsdr_cli.conventions`).

Mean propagation (current statistical model, abar = a_hat): Newton matrix per
axis.  Covariance propagation: Singer discretisation per axis with alpha = 1/tau_a
(Fang et al.; Singer 1970).  Phi is block diagonal: two identical 3x3 axis blocks,
``exp(-T/tau_eps)`` and 1; the kernels exploit that, these helpers also build
the dense matrices for the reference implementation and the FilterPy benchmark.

Every function is numba-compiled (``cache=True``, ``error_model="numpy"``: the
divisions are guarded) and callable from Python too; the small ones are inlined
into the filter kernel (``inline="always"``: fewer compilations at cold start).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

N_STATES = 8
IE, IVE, IAE, IN, IVN, IAN, IEPS, IKS = 0, 1, 2, 3, 4, 5, 6, 7

#: Below this alpha*T the Singer Q uses its small-T series (Fang et al.'s q(T));
#: above it, the exact expressions (their cancellation error is < 1e-8 relative there).
SINGER_SERIES_MAX_AT = 0.05

#: (4 - pi)/pi of the current statistical model's Rayleigh-type variance (Fang et al. eq. (14)).
CS_VAR_FACTOR = (4.0 - math.pi) / math.pi


@njit(cache=True, inline="always", error_model="numpy")
def singer_phi(T: float, alpha: float) -> tuple[float, float, float]:
    """Singer transition corner terms (phi13, phi23, phi33) for step T (s), alpha = 1/tau_a (1/s).

    Phi_a = [[1, T, phi13], [0, 1, phi23], [0, 0, phi33]] (docs/algorithms.md#cs-model).
    """
    aT = alpha * T
    if aT < 1e-6:
        # series: avoids (aT - 1 + exp(-aT))/alpha^2 cancellation
        return 0.5 * T * T * (1.0 - aT / 3.0), T * (1.0 - 0.5 * aT), 1.0 - aT + 0.5 * aT * aT
    ex = math.exp(-aT)
    return (aT - 1.0 + ex) / (alpha * alpha), (1.0 - ex) / alpha, ex


@njit(cache=True, error_model="numpy")
def singer_q(T: float, alpha: float, q: np.ndarray) -> None:
    """Per-axis Singer q(T) into q = [q11, q12, q13, q22, q23, q33]; Q_axis = 2 alpha sigma_a^2 q.

    alpha*T < SINGER_SERIES_MAX_AT: Fang et al.'s small-T form
    [[T^5/20, T^4/8, T^3/6], [T^4/8, T^3/3, T^2/2], [T^3/6, T^2/2, T]];
    above it the exact Singer (1970) expressions, which stay bounded for long
    steps (a gap of minutes between epochs) where the series would explode.
    """
    aT = alpha * T
    if aT < SINGER_SERIES_MAX_AT:
        T2 = T * T
        T3 = T2 * T
        q[0] = T3 * T2 / 20.0
        q[1] = T2 * T2 / 8.0
        q[2] = T3 / 6.0
        q[3] = T3 / 3.0
        q[4] = T2 / 2.0
        q[5] = T
        return
    a = alpha
    a2 = a * a  # powers as products: ``**`` made this function 0.4 s of the cold compile
    a3 = a2 * a
    aT2 = aT * aT
    e1 = math.exp(-aT)
    e2 = e1 * e1
    q[0] = (1.0 - e2 + 2.0 * aT + 2.0 * aT2 * aT / 3.0 - 2.0 * aT2 - 4.0 * aT * e1) / (2.0 * a3 * a2)
    q[1] = (e2 + 1.0 - 2.0 * e1 + 2.0 * aT * e1 - 2.0 * aT + aT2) / (2.0 * a2 * a2)
    q[2] = (1.0 - e2 - 2.0 * aT * e1) / (2.0 * a3)
    q[3] = (4.0 * e1 - 3.0 - e2 + 2.0 * aT) / (2.0 * a3)
    q[4] = (e2 + 1.0 - 2.0 * e1) / (2.0 * a2)
    q[5] = (1.0 - e2) / (2.0 * a)


@njit(cache=True, inline="always", error_model="numpy")
def cs_sigma_a2(a_hat: float, a_max: float, a_min_mag: float, ka: float,
                sigma_floor: float) -> float:
    """Adaptive acceleration variance (m^2/s^4) of the current statistical model.

    Fang et al. eqs. (14)-(15) with the regime factor K_a:
    ``K_a^2 (4-pi)/pi (a_max - a_hat)^2`` for a_hat > 0,
    ``K_a^2 (4-pi)/pi (a_min_mag + a_hat)^2`` for a_hat < 0; a_hat is clipped
    to the bounds so the bracket never goes negative.  Floor (our choice):
    ``sigma_floor^2`` (m^2/s^4), NOT scaled by K_a, which also covers a_hat at
    a bound.  Why: with the paper's K_a = 0.003 (poor GNSS / no fix) the
    acceleration cannot follow a turn in the ENU frame, the gyro residual
    leaks into the drift state and an outage ended far off with a claimed
    sigma of metres (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#models);
    with the floor the aekf is never less agile than the fixed-Q ekf.
    """
    if a_hat > 0.0:
        d = a_max - min(a_hat, a_max)
    else:
        d = a_min_mag + max(a_hat, -a_min_mag)
    s2 = ka * ka * CS_VAR_FACTOR * d * d
    f2 = sigma_floor * sigma_floor
    return max(f2, s2)


@njit(cache=True, inline="always", error_model="numpy")
def omega_row(x: np.ndarray, H: np.ndarray) -> float:
    """Heading-rate measurement h(x) (rad/s, clockwise+) and its Jacobian row into H (Fang et al.).

    ``omega = (v_n a_e - v_e a_n)/(v_e^2 + v_n^2) + eps``.  The caller must
    ensure the speed is above the standstill threshold (the row is singular at v = 0).
    """
    ve, ae, vn, an = x[IVE], x[IAE], x[IVN], x[IAN]
    v2 = ve * ve + vn * vn
    c = vn * ae - ve * an
    for i in range(N_STATES):
        H[i] = 0.0
    H[IVE] = (-an * v2 - 2.0 * ve * c) / (v2 * v2)
    H[IVN] = (ae * v2 - 2.0 * vn * c) / (v2 * v2)
    H[IAE] = vn / v2
    H[IAN] = -ve / v2
    H[IEPS] = 1.0
    return c / v2 + x[IEPS]


@njit(cache=True, inline="always", error_model="numpy")
def odo_row(x: np.ndarray, ue: float, un: float, H: np.ndarray) -> float:
    """Odometer speed measurement u = k_s * v along the unit direction (ue, un), and its row.

    Fang et al. measures the distance ``s = k_s T sqrt(v_e^2+v_n^2)``; we use the
    speed ``u = s/T`` (the same information, with sigma_s/T = noise_sd_mps), so
    the row does not depend on the sampling interval.  With (ue, un) the current
    velocity direction this is exactly ``k_s |v|`` and the Jacobian of Fang et al.
    divided by T; below the direction threshold the caller passes the remembered
    heading (sin psi, cos psi) so the row stays defined at v ~ 0.
    """
    along = x[IVE] * ue + x[IVN] * un
    for i in range(N_STATES):
        H[i] = 0.0
    H[IVE] = x[IKS] * ue
    H[IVN] = x[IKS] * un
    H[IKS] = along
    return x[IKS] * along


@njit(cache=True)
def phi_into(T: float, alpha: float, tau_eps_s: float, hold: bool, F: np.ndarray) -> None:
    """The dense 8x8 covariance transition (Singer blocks) into ``F``; ``hold``: static mode,
    axes not propagated."""
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
    F[IEPS, IEPS] = math.exp(-T / tau_eps_s)


def phi_matrix(T: float, alpha: float, tau_eps_s: float, hold: bool = False) -> np.ndarray:
    """Dense 8x8 covariance transition (Singer blocks); ``hold``: static mode, axes not propagated."""
    F = np.empty((N_STATES, N_STATES))
    phi_into(T, alpha, tau_eps_s, bool(hold), F)
    return F


def newton_matrix(T: float, tau_eps_s: float, hold: bool = False,
                  drift_decay: bool = True) -> np.ndarray:
    """Dense 8x8 mean transition of the current statistical model (abar = a_hat): Newton per axis.

    ``drift_decay=False``: the drift's mean is held (see ``aekf.drift_mean_decay``).
    """
    F = np.eye(N_STATES)
    if not hold:
        for o in (0, 3):
            F[o, o + 1] = T
            F[o, o + 2] = 0.5 * T * T
            F[o + 1, o + 2] = T
    F[IEPS, IEPS] = math.exp(-T / tau_eps_s) if drift_decay else 1.0
    return F


def q_matrix(T: float, alpha: float, qa_e: float, qa_n: float, q_eps: float, q_ks: float,
             hold: bool = False) -> np.ndarray:
    """Dense 8x8 process noise: per axis ``qa * q(T)`` with qa = 2 alpha sigma_a^2; eps, k_s white.

    ``hold`` (static mode, Zeng et al.): position rows/columns get no noise.
    """
    q = np.empty(6)
    singer_q(T, alpha, q)
    Q = np.zeros((N_STATES, N_STATES))
    block = np.array([[q[0], q[1], q[2]], [q[1], q[3], q[4]], [q[2], q[4], q[5]]])
    if hold:
        block[0, :] = 0.0
        block[:, 0] = 0.0
    Q[0:3, 0:3] = qa_e * block
    Q[3:6, 3:6] = qa_n * block
    Q[IEPS, IEPS] = q_eps * T
    Q[IKS, IKS] = q_ks * T
    return Q
