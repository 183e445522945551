"""Compiled per-epoch loop of the ekf/aekf filters (numba, nopython, ``cache=True``).

One kernel, :func:`cs_filter_kernel`, runs the whole forward pass over the epoch
arrays (no per-epoch Python objects).  Model: :mod:`gpsdr_cli.models.cs_model`
(Fang et al., docs/algorithms.md#cs-model); conventions: :mod:`gpsdr_cli.conventions`
(ENU metres, heading clockwise from north, ``omega = d(psi)/dt = -yaw_rate``).

Per epoch k (asynchronous cycle, docs/algorithms.md#cycle):

1. predict with the actual step ``T = dt[k]``: mean by the Newton matrix
   (current statistical model), covariance by the Singer blocks, exploiting
   the block structure (two 3x3 axis blocks + two scalars) instead of 8x8
   products; fading memory multiplies ``Phi P Phi^T``; in static mode
   (Zeng et al.) the axes are held (no propagation, no position noise); with
   ``aekf.turn_propagation`` (our choice) the gyro then turns the velocity and
   acceleration (:func:`turn_predict`);
2. GNSS fix (if any): chi-square gate on the 2-D NIS (none before
   ``gnss.gate_warmup_fixes`` accepted fixes; a no-lock-out reset; in
   ``gate_mode = "inflate"``, once fixes have failed the gate for
   ``gate_inflate_after_s``, a fix between the gate and ``gate_inflate_max``
   times it is accepted with R scaled by NIS/gate), innovation adaptive factor on
   P(k|k-1), Sage-Husa scale on R, then two sequential scalar updates (e, n);
3. odometer (if any): below ``standstill.speed_mps`` a zero-velocity update of
   v_e, v_n, a_e, a_n; else the speed ``u = k_s |v|`` (with
   ``aekf.odo_along_track`` its gains projected on the velocity direction);
4. gyro (if any): at standstill the rate measures the drift alone; above
   ``omega_min_speed_mps`` the Fang et al. heading-rate row (with the turn
   propagation: skipped, or reduced to "no lateral residual acceleration",
   ``aekf.turn_omega_row``); in between skipped.

Every scalar update uses the Joseph form and re-symmetrises P.  A remembered
heading (from the velocity above the direction threshold, gyro-integrated
below it) keeps the odometer row defined when the vehicle starts from rest.

GNSS outages without an odometer record coast (``aekf.coast_acc_psd``: zero-acceleration
rows in step 3).  On a drive with neither a gyro nor an odometer (``PAR_NO_DR``) an outage
is held instead: before each step into it rows ``a_e = a_n = 0`` that correct the
acceleration only (``NO_DR_COAST_Q``), and in the step's prior the velocity's variance grows
by ``aekf.no_dr_vel_psd`` x T per axis (kept with the heading floor's in ``fl_*``, so the
smoother's prior is the forward one).  The last fixes' velocity is held and the sigma grows;
the current statistical model's mean had carried the last acceleration on.

Cold start (the first run after installing, before numba's cache exists): the
options off by default are None keyword arguments whose branches numba prunes
before type inference (:func:`kernel_options`), scratch arrays come from the
caller (no ``np.zeros`` specialisations), state indices are passed as int64
values, not literals (one signature per helper), and every function uses
``error_model="numpy"`` (every division is guarded; no ZeroDivisionError paths
to lower).  The GNSS fix (section 2, 5 Hz) is its own function, :func:`gnss_fix`
(issue #5: with the GNSS error states the kernel's own compile had grown slow, numba's
type inference and SSA growing faster than linearly with a function's size); the
100-Hz sections stay in the kernel (a call with their ~15 array arguments per epoch
slowed the forward pass).  Timings: docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-aekf.
:func:`gpsdr_cli.filters.aekf.compile_parts` splits the
callees' compile over two processes (:mod:`gpsdr_cli.warmup`).

For the RTS smoother the kernel optionally stores the packed upper triangle of
P(k|k) and the seven scalars that rebuild P(k|k-1) from it exactly
(:func:`rebuild_prior`), instead of a second packed matrix: 43 instead of 72
floats per epoch.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from ..models.cs_model import (
    IAE,
    IAN,
    IE,
    IEPS,
    IKS,
    IN,
    IVE,
    IVN,
    N_STATES,
    cs_sigma_a2,
    odo_row,
    omega_row,
    singer_phi,
    singer_q,
)
from .adaptive import adaptive_factor, fading_factor, nis_2d, sage_husa_r
from .core import update as core_update
from .core.gate import GATE_FAIL, GATE_RESET, RESET_AFTER_FIRST_REJECT, chi2_gate
from .core.linalg import cholesky
from .core.packing import pack
from .core.update import NO_DR_COAST_Q

# indices into the float parameter vector ``prm`` (PAR_) and the flags ``flg`` (FLG_):
# prefixes that cannot be read as the matrices P, F, Q, K, S of the filter
PAR_ALPHA, PAR_AMAX, PAR_AMIN, PAR_SIGMA_A, PAR_TAU_EPS, PAR_Q_EPS, PAR_Q_KS = range(7)
PAR_R_OMEGA, PAR_R_ODO = 7, 8
PAR_STATIC_SPEED, PAR_R_ZUPT, PAR_OMEGA_MIN, PAR_GATE_THR, PAR_GATE_RESET, PAR_INNOV_C = range(9, 15)
PAR_FADING, PAR_SH_B, PAR_SH_RMIN, PAR_SH_RMAX, PAR_EPS_MEAN_DECAY = range(15, 20)
PAR_GYRO_HOLD, PAR_GATE_INFLATE_MAX, PAR_GATE_WARMUP, PAR_GATE_INFLATE_AFTER, PAR_HEADING_MIN = range(20, 25)
PAR_MAX_GAP, PAR_GAP_SPEED, PAR_WH_B, PAR_WH_MAX, PAR_WH_GAP, PAR_GVEL_VAR = range(25, 31)
PAR_WH_NIS, PAR_SCALE_VAR = 31, 32
PAR_GE_VAR, PAR_GE_RATE, PAR_GE_DIST_RATE, PAR_COAST_Q, PAR_OFF_VVAR, PAR_OFF_AVAR = range(33, 39)
PAR_UNKNOWN_W_VAR = 39
PAR_VGATE_VAR = 40  # (m/s)^2, the receiver velocity gate's least variance per axis
PAR_VGATE_RESET = 41  # s: receiver velocities gated this long are taken again (no lock-out)
PAR_NO_DR = 42  # 1: a GNSS-only drive (no gyro, no odometer): its GNSS outages are held
PAR_NO_DR_VEL_Q = 43  # m^2/s^3 per axis: the velocity's random walk through such an outage
N_PRM = 44
# indices into the integer flag vector ``flg``
FLG_ADAPT_Q, FLG_STANDSTILL, FLG_GATE, FLG_INNOV, FLG_FADING, FLG_SAGE_HUSA = range(6)
FLG_CHECK_SPD, FLG_STORE = 6, 7
FLG_DRIFT_CONSIDER, FLG_HEADING_CONSIDER, FLG_TURN, FLG_TURN_OMEGA = range(8, 12)
FLG_GATE_MODE, FLG_ODO_ALONG = 12, 13
FLG_HEADING_FLOOR, FLG_LATERAL_ACC, FLG_WHITEN, FLG_ZUPT_POS, FLG_GE, FLG_ODO_CONSIDER = range(14, 20)
N_FLG = 20
#: values of flg[FLG_TURN_OMEGA] (the Fang et al. yaw-rate row when aekf.turn_propagation is on)
OMEGA_SKIP, OMEGA_LATERAL = 0, 1
#: values of flg[FLG_GATE_MODE] (gnss.gate_mode)
GATE_REJECT, GATE_INFLATE = 0, 1
# internal state carried between segments (``st``)
ST_PSI, ST_STATIC, ST_T, ST_REJ_SINCE, ST_SH_R, ST_SH_M, ST_HEADING_KNOWN = range(7)
ST_W, ST_W_T, ST_N_FIX, ST_VPSI, ST_CPE = 7, 8, 9, 10, 11
ST_WH_C0, ST_WH_C1, ST_WH_UE, ST_WH_UN, ST_WH_T, ST_WH_M, ST_WH_STATIC = range(12, 19)
ST_WH_C2, ST_WH_UE2, ST_WH_UN2, ST_WH_T2, ST_B_SINCE = range(19, 24)
ST_ODO_T = 24  # time of the latest odometer record (s since the start)
ST_JUMP_E, ST_JUMP_N = 25, 26  # this epoch's bias-gate move of b into the position (m; 0: none)
ST_FIX_T = 27  # time of the latest used GNSS fix (s since the start)
ST_GE_VAR = 28  # the stationary variance of b's current regime (m^2; inp.ge_var)
ST_VREJ_SINCE = 29  # first rejection of the current run of gated receiver velocities (s; < 0: none)
N_ST = 30
#: a standstill the odometer said is forgotten after this long without an odometer record (s),
#: as fkf's STALE_ODO_S: an odometer that drops out at a stop must not hold the car for minutes
STALE_ODO_S = 1.0
#: largest heading variance (rad^2) of the heading floor: a heading uniform on (-pi, pi]
VPSI_MAX = math.pi ** 2 / 3.0
# stored prior scalars per epoch (columns of ``prior_store``: PRI_, the prior's, not Q)
PRI_QA_E, PRI_QA_N, PRI_LAM, PRI_GAIN, PRI_ADD_E, PRI_ADD_N, PRI_W = range(7)
PRI_FL_EE, PRI_FL_NN, PRI_FL_EN, PRI_FB = 7, 8, 9, 10
PRI_JUMP_E, PRI_JUMP_N = 11, 12  # the bias gate's mean move of b into the position (m)
PRI_VB = 13  # b's stationary variance at this epoch (m^2; its regime's)
PRI_ADD_VE, PRI_ADD_VN = 14, 15  # velocity variance a gate reset added (m^2/s^2)
N_PRIOR = 16
# counters (``info`` vector)
INF_SPD_FAIL, INF_MIN_DIAG, INF_SKIPPED, INF_GATE_RESETS, INF_NONFINITE, INF_INFLATED = range(6)
INF_VEL_GATED = 6  # receiver velocities the gate left out (their fix was used)
N_INFO = 7

# the kernel's arguments as records (numba takes namedtuples of arrays as they are)
#: per-epoch inputs, arrays of n: dt (s), the GNSS fix z_e, z_n (m) and its variances
#: r_e, r_n (m^2), K_a, the gyro yaw rate (rad/s, CCW+), the odometer speed (m/s), the
#: outage flag, the receiver velocity gv_e, gv_n (m/s, NaN when none) and the GNSS error
#: states' stationary variance ge_var (m^2; empty when they are off)
CsInputs = namedtuple("CsInputs", "dt has_gnss z_e z_n r_e r_n ka has_gyro yaw has_odo odo "
                                  "outage gv_e gv_n ge_var")
#: the filter state a segment starts from, updated in place: x (8), P (8, 8), the ST_* memory
#: and the GNSS error block (GE_*)
CsState = namedtuple("CsState", "x P st ge")
#: per-epoch outputs, one row per quantity
CsOutputs = namedtuple("CsOutputs", "x_out pcov_out gnss_used gnss_rej nis_out static_out "
                                    "hold_out sd_out b_out")
#: what the smoother keeps (with flg[FLG_STORE]): packed P(k|k) of the segment, prior scalars
CsStore = namedtuple("CsStore", "P_store prior_store")
N_PACKED = N_STATES * (N_STATES + 1) // 2
#: the GNSS-error block ``ge`` (aekf.gnss_err_states), one flat float64 array: P(x, b) (8 x 2)
#: row-major at [2 i + j], then P(b, b) (ee, en, nn) and the mean b (e, n)
GE_PEE, GE_PEN, GE_PNN, GE_BE, GE_BN = range(2 * N_STATES, 2 * N_STATES + 5)
N_GE = 2 * N_STATES + 5
#: floats per epoch the smoother stores for the block: its first N_GE_PACKED (the covariances)
N_GE_PACKED = 2 * N_STATES + 3
#: the block's work rows ``gw`` (GW_ROWS x 8): P H^T of up to GW_MAX pending DR rows, their
#: H, their (state index or GW_ODO / GW_OMEGA, R, y), and the prediction of the epoch
GW_MAX = 8
GW_H = GW_MAX
GW_IDX, GW_R, GW_Y = 2 * GW_MAX, 2 * GW_MAX + 1, 2 * GW_MAX + 2
GW_PRED = 2 * GW_MAX + 3
GW_ROWS = 2 * GW_MAX + 5
GW_ODO, GW_OMEGA = -1.0, -2.0
#: nonzero columns of the odometer row (v_e, v_n, k_s) and the heading-rate row
NZ_ODO = np.array([1, 4, 7], np.int64)
NZ_OMEGA = np.array([1, 2, 4, 5, 6], np.int64)
#: consider-state bit masks: the gyro drift; the velocity (for aekf.heading_consider)
CONS_EPS = 1 << 6
CONS_KS = 1 << 7
CONS_VEL = (1 << 1) | (1 << 4)
CONS_NOT_ACC = 0xFF & ~((1 << 2) | (1 << 5))
CONS_POS = (1 << 0) | (1 << 3)


def kernel_options(flg: np.ndarray) -> dict[str, int]:
    """The keyword arguments of :func:`cs_filter_kernel` for the options in ``flg``.

    Only the options that differ from the default run appear (value 1); an absent
    one is None in the kernel, and numba compiles none of its code.
    """
    opts = {}
    for name, on in (("fading_on", flg[FLG_FADING]), ("innov_on", flg[FLG_INNOV]),
                     ("sage_on", flg[FLG_SAGE_HUSA]), ("check_on", flg[FLG_CHECK_SPD]),
                     ("store_on", flg[FLG_STORE]), ("inflate_on", flg[FLG_GATE_MODE] == GATE_INFLATE),
                     ("whiten_off", not flg[FLG_WHITEN]), ("floor_off", not flg[FLG_HEADING_FLOOR]),
                     ("turn_off", not flg[FLG_TURN]), ("omega_skip_on", flg[FLG_TURN_OMEGA] == OMEGA_SKIP),
                     ("along_off", not flg[FLG_ODO_ALONG]), ("ge_on", flg[FLG_GE]),
                     ("heading_consider_on", flg[FLG_HEADING_CONSIDER])):
        if on:
            opts[name] = 1
    return opts


@njit(cache=True, inline="always", error_model="numpy")
def predict_mean(x: np.ndarray, T: float, f_eps: float, hold: bool) -> None:
    """Current statistical mean propagation (abar = a_hat): Newton per axis (Fang et al.).

    ``f_eps`` multiplies the drift: exp(-T/tau_eps) for Fang et al.'s literal
    Gauss-Markov mean, 1 for our default (``aekf.drift_mean_decay = false``): the
    drift's mean is held like a random constant (a turn-on bias does not decay
    toward zero in an outage) while its covariance stays the Gauss-Markov one.
    """
    if not hold:
        for o in range(0, 6, 3):
            x[o] += T * x[o + 1] + 0.5 * T * T * x[o + 2]
            x[o + 1] += T * x[o + 2]
    x[IEPS] *= f_eps


@njit(cache=True, error_model="numpy")
def predict_cov(P: np.ndarray, T: float, alpha: float, f_eps: float, qa_e: float, qa_n: float,
                q_eps: float, q_ks: float, lam: float, hold: bool, qbuf: np.ndarray) -> None:
    """P <- lam * Phi P Phi^T + Q in place, Phi = blockdiag(Phi_a, Phi_a, f_eps, 1) (Singer).

    Row then column operations on the two 3x3 axis blocks: ~200 flops instead
    of two dense 8x8 products.  ``hold``: static mode, axis blocks not propagated
    and no position noise (Zeng et al.).
    """
    n = N_STATES
    if not hold:
        p13, p23, p33 = singer_phi(T, alpha)
        for j in range(n):  # rows: Phi P
            for o in range(0, 6, 3):
                r0 = P[o, j]
                r1 = P[o + 1, j]
                r2 = P[o + 2, j]
                P[o, j] = r0 + T * r1 + p13 * r2
                P[o + 1, j] = r1 + p23 * r2
                P[o + 2, j] = p33 * r2
        for i in range(n):  # columns: (Phi P) Phi^T
            for o in range(0, 6, 3):
                c0 = P[i, o]
                c1 = P[i, o + 1]
                c2 = P[i, o + 2]
                P[i, o] = c0 + T * c1 + p13 * c2
                P[i, o + 1] = c1 + p23 * c2
                P[i, o + 2] = p33 * c2
    for j in range(n):
        P[6, j] *= f_eps
    for i in range(n):
        P[i, 6] *= f_eps
    if lam != 1.0:
        for i in range(n):
            for j in range(n):
                P[i, j] *= lam
    singer_q(T, alpha, qbuf)  # [q11, q12, q13, q22, q23, q33]
    for o in range(0, 6, 3):
        qa = qa_e if o == 0 else qa_n
        if not hold:  # static mode: no position noise
            P[o, o] += qa * qbuf[0]
            P[o, o + 1] += qa * qbuf[1]
            P[o + 1, o] += qa * qbuf[1]
            P[o, o + 2] += qa * qbuf[2]
            P[o + 2, o] += qa * qbuf[2]
        P[o + 1, o + 1] += qa * qbuf[3]
        P[o + 1, o + 2] += qa * qbuf[4]
        P[o + 2, o + 1] += qa * qbuf[4]
        P[o + 2, o + 2] += qa * qbuf[5]
    P[IEPS, IEPS] += q_eps * T
    P[IKS, IKS] += q_ks * T
    for i in range(n):  # symmetrize (written out: one helper less to compile)
        for j in range(i + 1, n):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@njit(cache=True, error_model="numpy")
def unit_update(x: np.ndarray, P: np.ndarray, idx: int, y: float, R: float, w: float,
                K: np.ndarray, PHt: np.ndarray, consider: int) -> bool:
    """:func:`gpsdr_cli.filters.core.update.unit_update` for the 8 states (R scaled by w)."""
    return core_update.unit_update(N_STATES, x, P, idx, y, R, w, K, PHt, consider)


@njit(cache=True, error_model="numpy")
def sparse_update(x: np.ndarray, P: np.ndarray, H: np.ndarray, nz: np.ndarray, y: float,
                  R: float, w: float, K: np.ndarray, PHt: np.ndarray, consider: int,
                  along_e: float, along_n: float) -> bool:
    """:func:`gpsdr_cli.filters.core.update.sparse_update` for the 8 states."""
    return core_update.sparse_update(N_STATES, x, P, H, nz, y, R, w, K, PHt, consider,
                                     along_e, along_n)


@njit(cache=True, error_model="numpy")
def inflate_kinematic(P: np.ndarray, g: float) -> None:
    """innovation adaptive factor, P(k|k-1) /= alpha with g = 1/alpha, on the kinematic block.

    Our choice: only the six kinematic states (position, velocity, acceleration)
    are inflated, as ``D P D`` with ``D = diag(sqrt(g) x 6, 1, 1)`` (a congruence,
    so P stays positive definite): the gyro drift and odometer scale are
    parameters, not dynamics; inflating them at every 5 Hz fix (the seed's
    c = 0.9 fires on ~44 % of fixes with chi-square innovations) let the drift
    wander and the open-sky track diverge (evidence:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-aekf).
    """
    r = math.sqrt(g)
    for i in range(N_STATES):
        si = r if i < 6 else 1.0
        for j in range(N_STATES):
            sj = r if j < 6 else 1.0
            P[i, j] *= si * sj


@njit(cache=True, error_model="numpy")
def turn_predict(x: np.ndarray, P: np.ndarray, T: float, w: float, r_w: float) -> None:
    """Rotate velocity and acceleration by the gyro heading increment (aekf.turn_propagation).

    Our choice (docs/algorithms.md#cs-model leaves the heading out of the state): after the
    current statistical prediction, ``(v_e, v_n)`` and ``(a_e, a_n)`` turn
    clockwise by ``dpsi = (w - eps) T`` where ``w = -yaw_rate`` is the gyro's
    heading rate (CCW-positive gyro, heading clockwise) and ``eps`` the drift
    state: ``v_e' = c v_e + s v_n``, ``v_n' = -s v_e + c v_n`` (c, s of dpsi).
    Covariance: ``P <- J P J^T + r_w T^2 g g^T`` with J the Jacobian of that map
    (the rotation on the velocity and acceleration pairs, and
    ``d v'/d eps = -T g`` with ``g = d v'/d dpsi = (v_n', -v_e')``, likewise for a)
    and r_w the gyro noise variance per sample.  The position moves along the
    chord: the prediction moved it by ``T v`` with the step's first velocity, and
    the turn adds ``(T/2) (v' - v)``, so the step's displacement is ``T (v + v')/2``
    (to first order, the arc the car drove) instead of lagging half a step of turn
    (docs/benchmarks.md, "Dead reckoning at CAN rate").  So the gyro drives the heading
    in the mean and the covariance, and the drift becomes observable through the
    GNSS positions (as in a strapdown INS) instead of through the heading-rate row.
    """
    n = N_STATES
    dpsi = (w - x[IEPS]) * T
    c = math.cos(dpsi)
    s = math.sin(dpsi)
    ve = x[IVE]
    vn = x[IVN]
    ae = x[IAE]
    an = x[IAN]
    h = 0.5 * T
    x[IVE] = c * ve + s * vn
    x[IVN] = -s * ve + c * vn
    x[IAE] = c * ae + s * an
    x[IAN] = -s * ae + c * an
    x[IE] += h * (x[IVE] - ve)  # the chord
    x[IN] += h * (x[IVN] - vn)
    g1 = x[IVN]
    g4 = -x[IVE]
    g2 = x[IAN]
    g5 = -x[IAE]
    for j in range(n):  # rows: J P
        p1 = P[1, j]
        p4 = P[4, j]
        p2 = P[2, j]
        p5 = P[5, j]
        p6 = P[6, j]
        P[1, j] = c * p1 + s * p4 - T * g1 * p6
        P[4, j] = -s * p1 + c * p4 - T * g4 * p6
        P[2, j] = c * p2 + s * p5 - T * g2 * p6
        P[5, j] = -s * p2 + c * p5 - T * g5 * p6
        P[0, j] += h * (P[1, j] - p1)
        P[3, j] += h * (P[4, j] - p4)
    for i in range(n):  # columns: (J P) J^T
        p1 = P[i, 1]
        p4 = P[i, 4]
        p2 = P[i, 2]
        p5 = P[i, 5]
        p6 = P[i, 6]
        P[i, 1] = c * p1 + s * p4 - T * g1 * p6
        P[i, 4] = -s * p1 + c * p4 - T * g4 * p6
        P[i, 2] = c * p2 + s * p5 - T * g2 * p6
        P[i, 5] = -s * p2 + c * p5 - T * g5 * p6
        P[i, 0] += h * (P[i, 1] - p1)
        P[i, 3] += h * (P[i, 4] - p4)
    q = r_w * T * T
    gv = (h * g1, g1, g2, h * g4, g4, g5)
    for a in range(6):
        for b in range(a, 6):
            v = q * gv[a] * gv[b]
            P[a, b] += v
            if b != a:
                P[b, a] += v
    # no symmetrize: the same row and column operations keep P symmetric to rounding, and
    # every update re-mirrors it (speed: this runs at every epoch)


@njit(cache=True, error_model="numpy")
def turn_jacobian(F: np.ndarray, x: np.ndarray, T: float, w: float) -> None:
    """F <- J F with J the Jacobian of :func:`turn_predict` at its input mean x (dense, smoother)."""
    dpsi = (w - x[IEPS]) * T
    c = math.cos(dpsi)
    s = math.sin(dpsi)
    g1 = -s * x[IVE] + c * x[IVN]  # v_n' (the rotated velocity), d v_e'/d dpsi
    g4 = -(c * x[IVE] + s * x[IVN])  # -v_e'
    g2 = -s * x[IAE] + c * x[IAN]
    g5 = -(c * x[IAE] + s * x[IAN])
    for j in range(N_STATES):
        p1 = F[1, j]
        p4 = F[4, j]
        p2 = F[2, j]
        p5 = F[5, j]
        p6 = F[6, j]
        F[1, j] = c * p1 + s * p4 - T * g1 * p6
        F[4, j] = -s * p1 + c * p4 - T * g4 * p6
        F[2, j] = c * p2 + s * p5 - T * g2 * p6
        F[5, j] = -s * p2 + c * p5 - T * g5 * p6
        F[0, j] += 0.5 * T * (F[1, j] - p1)  # the chord
        F[3, j] += 0.5 * T * (F[4, j] - p4)


# ---------------------------------------------------------------- GNSS error states
# aekf.gnss_err_states (our choice, after the fkf's Tang et al. error states; issue #4): the fix
# error is white noise plus a first-order Gauss-Markov bias b = (b_e, b_n) per axis
# (multipath), z = (e, n) + b + v.  The 10-state covariance is kept in two parts: the 8x8 P
# of the kinematic model, whose code is the same with and without b, and the block ``ge`` =
# [P(x, b) (8 x 2), P(b, b), b] (flat, GE_*).  The DR rows have no b column (H_b = 0), so
# their S and their x gains are the 8-state ones and the block needs only O(8 x 2)
# corrections.  Speed: those are not applied row by row (a call per row at 100 Hz slowed
# the filter; timing: docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-aekf)
# but once per epoch by :func:`ge_epoch`, from the rows' P H^T, H, R and y that the update
# helpers left in the work rows ``gw`` (GW_*), in order.


@njit(cache=True, error_model="numpy")
def ge_epoch(G: np.ndarray, gw: np.ndarray, n_rows: int, predict: bool, alpha: float,
             var_b: float) -> None:
    """Bring the GNSS error block up to date: the epoch's prediction, then its pending DR rows.

    ``predict``: ``gw[GW_PRED]`` = (T, f_eps, lam, hold, f_b, turned, c, s) and
    ``gw[GW_PRED + 1]`` = (g1, g4, g2, g5) of the turn: P(x, b) <- J lam Phi P(x, b) f_b
    (Phi the Singer transition, axes held when ``hold``; J the gyro turn of
    :func:`turn_predict` when ``turned``), P(b, b) <- lam f_b^2 P(b, b) + var_b (1 - f_b^2)
    (stationary Gauss-Markov), b <- f_b b.  Then for each of the ``n_rows`` rows r in order
    (``gw[r]`` = P H^T of its prior, ``gw[GW_H + r]`` = H, ``gw[GW_IDX, r]`` = the state of a
    unit row or GW_ODO / GW_OMEGA for the sparse rows): with ``hc = H P(x, b)``,
    ``S = H P H^T + R`` and the optimal bias gain ``k_b = hc / S`` the 10-state Joseph form
    reduces, for any gain of x (consider states, along-track projection), to
    ``P(x, b) <- P(x, b) - P H^T k_b``, ``P(b, b) <- P(b, b) - S k_b k_b^T``, ``b += k_b y``.
    """
    if predict:
        T = gw[GW_PRED, 0]
        f_eps = gw[GW_PRED, 1]
        lam = gw[GW_PRED, 2]
        f_b = gw[GW_PRED, 4]
        sc = lam * f_b
        if gw[GW_PRED, 3] == 0.0:  # not held: Singer rows
            p13, p23, p33 = singer_phi(T, alpha)
            for m in range(0, 12, 6):
                for j in range(2):
                    r0 = G[m + j]
                    r1 = G[m + 2 + j]
                    r2 = G[m + 4 + j]
                    G[m + j] = sc * (r0 + T * r1 + p13 * r2)
                    G[m + 2 + j] = sc * (r1 + p23 * r2)
                    G[m + 4 + j] = sc * p33 * r2
        else:
            for m in range(12):
                G[m] *= sc
        G[12] *= sc * f_eps  # the drift's row
        G[13] *= sc * f_eps
        G[14] *= sc
        G[15] *= sc
        sb = sc * f_b
        q = var_b * (1.0 - f_b * f_b)
        G[GE_PEE] = sb * G[GE_PEE] + q
        G[GE_PEN] *= sb
        G[GE_PNN] = sb * G[GE_PNN] + q
        G[GE_BE] *= f_b
        G[GE_BN] *= f_b
        if gw[GW_PRED, 5] != 0.0:  # rows: J P(x, b), as turn_predict does for P
            c = gw[GW_PRED, 6]
            s = gw[GW_PRED, 7]
            g1 = gw[GW_PRED + 1, 0]
            g4 = gw[GW_PRED + 1, 1]
            g2 = gw[GW_PRED + 1, 2]
            g5 = gw[GW_PRED + 1, 3]
            for j in range(2):
                p1 = G[2 + j]
                p4 = G[8 + j]
                p2 = G[4 + j]
                p5 = G[10 + j]
                p6 = G[12 + j]
                G[2 + j] = c * p1 + s * p4 - T * g1 * p6
                G[8 + j] = -s * p1 + c * p4 - T * g4 * p6
                G[4 + j] = c * p2 + s * p5 - T * g2 * p6
                G[10 + j] = -s * p2 + c * p5 - T * g5 * p6
                G[j] += 0.5 * T * (G[2 + j] - p1)  # the chord
                G[6 + j] += 0.5 * T * (G[8 + j] - p4)
    for r in range(n_rows):
        code = gw[GW_IDX, r]
        if code >= 0.0:
            idx = int(code)
            hc0 = G[2 * idx]
            hc1 = G[2 * idx + 1]
            hpht = gw[r, idx]
        else:
            nz = NZ_ODO if code == GW_ODO else NZ_OMEGA
            hc0 = 0.0
            hc1 = 0.0
            hpht = 0.0
            for q in range(nz.shape[0]):
                j = nz[q]
                h = gw[GW_H + r, j]
                hc0 += h * G[2 * j]
                hc1 += h * G[2 * j + 1]
                hpht += h * gw[r, j]
        S = hpht + gw[GW_R, r]
        if not (S > 0.0):
            continue
        kb0 = hc0 / S
        kb1 = hc1 / S
        for i in range(N_STATES):
            G[2 * i] -= gw[r, i] * kb0
            G[2 * i + 1] -= gw[r, i] * kb1
        G[GE_PEE] -= hc0 * kb0
        G[GE_PEN] -= hc0 * kb1
        G[GE_PNN] -= hc1 * kb1
        G[GE_BE] += kb0 * gw[GW_Y, r]
        G[GE_BN] += kb1 * gw[GW_Y, r]


@njit(cache=True, error_model="numpy")
def ge_turn(gw: np.ndarray, x: np.ndarray, T: float, w: float) -> None:
    """Record the gyro turn of this epoch's prediction for :func:`ge_epoch`: the angle
    (w - eps) T of :func:`turn_predict` and the rows (g1, g4, g2, g5) of its Jacobian."""
    dpsi = (w - x[IEPS]) * T
    gw[GW_PRED, 5] = 1.0
    gw[GW_PRED, 6] = math.cos(dpsi)
    gw[GW_PRED, 7] = math.sin(dpsi)
    gw[GW_PRED + 1, 0] = x[IVN]
    gw[GW_PRED + 1, 1] = -x[IVE]
    gw[GW_PRED + 1, 2] = x[IAN]
    gw[GW_PRED + 1, 3] = -x[IAE]


@njit(cache=True, error_model="numpy")
def ge_push(gw: np.ndarray, r: int, code: float, H: np.ndarray, PHt: np.ndarray, R: float,
            y: float) -> int:
    """Queue an applied DR row for :func:`ge_epoch` in work row ``r``: its P H^T, its H (read
    only for the sparse rows, ``code`` GW_ODO / GW_OMEGA; a state index for a unit row),
    R and innovation; returns the next free row."""
    for i in range(N_STATES):
        gw[r, i] = PHt[i]
        gw[GW_H + r, i] = H[i]
    gw[GW_IDX, r] = code
    gw[GW_R, r] = R
    gw[GW_Y, r] = y
    return r + 1


@njit(cache=True, error_model="numpy")
def ge_fix_update(x: np.ndarray, P: np.ndarray, G: np.ndarray, z_e: float, z_n: float,
                  r_e: float, r_n: float, u: np.ndarray, est_b: bool) -> bool:
    """A GNSS fix z = (e, n) + b + v, var(v) = diag(r_e, r_n): two scalar 10-state updates.

    Per coordinate (state idx, bias column jb): ``u_x = P H^T = P[:, idx] + P(x, b)[:, jb]``,
    ``u_b = P(b, x)[:, idx] + P(b, b)[:, jb]``, S = H P H^T + R; x += u_x y / S,
    b += u_b y / S, P -= u u^T / S in each block (the optimal gain, for which Joseph's
    form reduces to this), mirrored.  ``est_b`` False: b is a Schmidt consider state
    (gain zero; Joseph then leaves b and P(b, b) as they are, and P, P(x, b) as above):
    the bias still widens S (a correlated error the fix carries) but is not estimated.
    ``u`` (8) scratch.  False if a coordinate was skipped (S not positive, y not
    finite); the east update then stays applied.
    """
    ok = True
    for jb in range(2):
        idx = 3 * jb
        y = (z_e if jb == 0 else z_n) - x[idx] - G[GE_BE + jb]
        R = r_e if jb == 0 else r_n
        for i in range(N_STATES):
            u[i] = P[i, idx] + G[2 * i + jb]
        ub0 = G[2 * idx] + (G[GE_PEE] if jb == 0 else G[GE_PEN])
        ub1 = G[2 * idx + 1] + (G[GE_PEN] if jb == 0 else G[GE_PNN])
        S = u[idx] + (ub0 if jb == 0 else ub1) + R
        if not (S > 0.0) or not math.isfinite(S) or not math.isfinite(y):
            ok = False
            continue
        for i in range(N_STATES):
            x[i] += u[i] * y / S
        if est_b:
            G[GE_BE] += ub0 * y / S
            G[GE_BN] += ub1 * y / S
        for i in range(N_STATES):
            ui = u[i] / S
            for j in range(i, N_STATES):
                v = P[i, j] - ui * u[j]
                P[i, j] = v
                P[j, i] = v
            G[2 * i] -= ui * ub0
            G[2 * i + 1] -= ui * ub1
        if est_b:
            G[GE_PEE] -= ub0 * ub0 / S
            G[GE_PEN] -= ub0 * ub1 / S
            G[GE_PNN] -= ub1 * ub1 / S
    return ok


@njit(cache=True, error_model="numpy")
def rebuild_prior(P: np.ndarray, x: np.ndarray, T: float, alpha: float, tau_eps: float,
                  q_eps: float, q_ks: float, r_w: float, pr: np.ndarray, hold: bool,
                  qbuf: np.ndarray, scale_var: float) -> None:
    """P(k-1|k-1) -> the P(k|k-1) the forward pass used (predict, turn, adaptive factor, gate reset).

    ``x`` enters as the current statistical prediction of the mean and leaves
    rotated when the forward pass turned it (``pr[PRI_W]`` finite); the heading
    floor's deficit (``pr[PRI_FL_*]``) is added after the turn, as in the forward pass.
    """
    f_eps = math.exp(-T / tau_eps)
    predict_cov(P, T, alpha, f_eps, pr[PRI_QA_E], pr[PRI_QA_N], q_eps, q_ks, pr[PRI_LAM], hold, qbuf)
    if math.isfinite(pr[PRI_W]):
        turn_predict(x, P, T, pr[PRI_W], r_w + scale_var * abs(pr[PRI_W]) / T)
    if pr[PRI_FL_EE] != 0.0 or pr[PRI_FL_NN] != 0.0:  # heading floor
        P[IVE, IVE] += pr[PRI_FL_EE]
        P[IVN, IVN] += pr[PRI_FL_NN]
        P[IVE, IVN] += pr[PRI_FL_EN]
        P[IVN, IVE] = P[IVE, IVN]
    if pr[PRI_GAIN] != 1.0:
        inflate_kinematic(P, pr[PRI_GAIN])
    P[IE, IE] += pr[PRI_ADD_E]
    P[IN, IN] += pr[PRI_ADD_N]
    P[IVE, IVE] += pr[PRI_ADD_VE]
    P[IVN, IVN] += pr[PRI_ADD_VN]



@njit(cache=True, error_model="numpy")
def gnss_fix(z_e: float, z_n: float, r_e: float, r_n: float, gv_e: float, gv_n: float,
             x: np.ndarray, P: np.ndarray, st: np.ndarray, prm: np.ndarray, ge: np.ndarray,
             gw: np.ndarray, wk: np.ndarray, info: np.ndarray, t: float, is_static: bool,
             gap: bool, gate: bool, ge_pred: bool, add_e: float, add_n: float,
             innov_on: int | None = None, sage_on: int | None = None,
             whiten_off: int | None = None, inflate_on: int | None = None,
             ge_on: int | None = None
             ) -> tuple[float, float, float, float, float, int, bool, float, bool, bool]:
    """Section 2 of :func:`cs_filter_kernel`: the GNSS position fix of an epoch (5 Hz).

    Its own function for the cold start: numba's type inference and SSA
    reconstruction grow faster than linearly with a function's size, and this
    block was half of the kernel's body.  Its
    memory (gate timers, Sage-Husa, whitening, fix count: the ST_* entries) lives
    in ``st`` only, so the 100-Hz path between fixes carries none of it.  The epoch's
    fix ``z_e, z_n`` (m), variances ``r_e, r_n`` (m^2) and receiver velocity ``gv_e,
    gv_n`` (m/s, NaN when none) come as values, not arrays: a call passes every array
    as ~7 values, and 17 arrays slowed the forward pass.  ``t``
    (s since the start), ``is_static``, ``gap`` (a step not propagated), ``gate``
    and ``ge_pred`` (the GNSS error block's prediction still pending) come from the
    kernel; ``add_e, add_n`` the position variance added to P(k|k-1) so far
    (m^2).  The options are the kernel's None-or-int keyword arguments (numba
    prunes a None one before type inference).  Returns the updated ``add_e,
    add_n``, the velocity variance a gate reset added (m^2/s^2 per axis, GNSS-only
    drives), the innovation adaptive factor g applied to P(k|k-1), the number of DR rows
    queued in ``gw`` for the block, ``ge_pred``, the NIS, and whether the fix was used
    and whether the gate rejected it.
    """
    H = wk[0]
    K = wk[1]
    PHt = wk[2]
    alpha = prm[PAR_ALPHA]
    # state indices and the empty consider mask as int64 values (see cs_filter_kernel)
    i_e = np.int64(0)
    i_n = np.int64(3)
    no_cons = np.int64(0)
    g = 1.0
    used = False
    rej = False
    n_rows = np.int64(0)  # not the literal 0: one ge_push specialisation, not two
    add_ve = 0.0  # velocity variance a gate reset added on a GNSS-only drive (m^2/s^2)
    add_vn = 0.0

    rej_since = st[ST_REJ_SINCE]
    sh_r = st[ST_SH_R]
    sh_m = int(st[ST_SH_M])
    n_fix = st[ST_N_FIX]
    wh_c0 = st[ST_WH_C0]
    wh_c1 = st[ST_WH_C1]
    wh_c2 = st[ST_WH_C2]
    wh_ue = st[ST_WH_UE]
    wh_un = st[ST_WH_UN]
    wh_ue2 = st[ST_WH_UE2]
    wh_un2 = st[ST_WH_UN2]
    wh_t = st[ST_WH_T]
    wh_t2 = st[ST_WH_T2]
    wh_m = st[ST_WH_M]
    wh_static = st[ST_WH_STATIC]
    b_since = st[ST_B_SINCE]
    ye = z_e - x[IE]
    yn = z_n - x[IN]
    if ge_on is not None:  # z = position + b + v: the predicted fix includes the bias
        if ge_pred:
            ge_epoch(ge, gw, no_cons, ge_pred, alpha, st[ST_GE_VAR])  # no rows yet
            ge_pred = False
        if gate and n_fix >= prm[PAR_GATE_WARMUP]:
            # bias gate (our choice): multipath decorrelates as the car moves; an
            # estimated b outside the gate of its stationary distribution for
            # gate_reset_s while moving is not multipath but fixes that moved (a datum
            # change) or a DR error: b goes into the position, whose variance grows by
            # it (no lock-out, like the gate reset; a step in the fixes otherwise stayed
            # half in b; evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-aekf)
            if not is_static:
                b2 = ge[GE_BE] * ge[GE_BE] + ge[GE_BN] * ge[GE_BN]
                verdict, b_since = chi2_gate(b2, prm[PAR_GATE_THR] * st[ST_GE_VAR], t, b_since,
                                             prm[PAR_GATE_RESET], RESET_AFTER_FIRST_REJECT, False)
                if verdict == GATE_RESET:
                    x[IE] += ge[GE_BE]
                    x[IN] += ge[GE_BN]
                    st[ST_JUMP_E] = ge[GE_BE]  # part of the prior's mean, for the smoother
                    st[ST_JUMP_N] = ge[GE_BN]
                    add_e += ge[GE_BE] * ge[GE_BE]
                    add_n += ge[GE_BN] * ge[GE_BN]
                    P[IE, IE] += ge[GE_BE] * ge[GE_BE]
                    P[IN, IN] += ge[GE_BN] * ge[GE_BN]
                    ge[GE_BE] = 0.0
                    ge[GE_BN] = 0.0
                    info[INF_GATE_RESETS] += 1.0
        ye = z_e - x[IE] - ge[GE_BE]
        yn = z_n - x[IN] - ge[GE_BN]
    # innovation whitening (aekf.innovation_whitening, Mehra 1970): an optimal filter's
    # innovations are white; a lag-one correlation rho of the normalised innovations
    # says the fixes' errors are time-correlated (multipath) and carry less independent
    # information than R claims: R is scaled by the AR(1) variance factor of an average,
    # (1 + rho)/(1 - rho), within [1, PAR_WH_MAX]
    f_wh = 1.0
    if whiten_off is None and wh_c0 > 0.0 and wh_c1 > 0.0:
        # white + first-order Gauss-Markov innovations: lag-one and lag-two
        # autocovariances c1 = s_c r, c2 = s_c r^2 give the correlation r of the
        # coloured part and its share s_c of c0; R is scaled by the variance factor
        # of an average of such a sequence, ((c0 - s_c) + s_c (1 + r)/(1 - r)) / c0
        r_c = min(max(wh_c2 / wh_c1, 0.0), 0.999)
        s_c = min(wh_c1 / max(r_c, 1e-3), wh_c0)
        f_wh = min(((wh_c0 - s_c) + s_c * (1.0 + r_c) / (1.0 - r_c)) / wh_c0,
                   prm[PAR_WH_MAX])
    if whiten_off is None and is_static:
        # parked, the antenna does not move and its multipath does not change: the
        # m-th fix of a stop carries ~1/m of a fix's information (all m together about
        # as much as one, not m), so R x m (our choice; aekf.innovation_whitening)
        wh_static += 1.0
        f_wh = max(f_wh, wh_static)
    re = r_e * sh_r * f_wh
    rn = r_n * sh_r * f_wh
    # NIS, gate and the innovation adaptive factor with the nominal R: the whitening factor scales
    # the information of a fix, not the spread of its error (which the NIS tests)
    s00 = P[IE, IE] + r_e * sh_r
    s11 = P[IN, IN] + r_n * sh_r
    s01 = P[IE, IN]
    if ge_on is not None:  # H = [I_pos, I_b]: S gains 2 P(pos, b) + P(b, b)
        s00 += 2.0 * ge[0] + ge[GE_PEE]
        s11 += 2.0 * ge[7] + ge[GE_PNN]
        s01 += ge[1] + ge[6] + ge[GE_PEN]
    nis = nis_2d(ye, yn, s00, s01, s11)
    # the receiver (Doppler) velocity has its own gate against the predicted velocity (our
    # choice): a wrong but plausible speed or course taken at its 0.2-5 m/s sigma carried
    # the track tens of metres (docs/decisions/0031).  Judged with at least [gnss]
    # velocity_gate_floor_mps (a drive-off the state has not seen is not an outlier), the
    # fixes' threshold and no lock-out: a reset keeps its run open until a velocity is used.
    # A fix that fails its own gate too (also one the gate resets on) says the state, not
    # the velocity, is off (a turn in an outage the gyro did not see): it is taken then
    has_v = math.isfinite(gv_e) and math.isfinite(gv_n) and prm[PAR_GVEL_VAR] > 0.0
    vel = has_v
    if has_v and gate and n_fix >= prm[PAR_GATE_WARMUP]:
        rv = max(prm[PAR_GVEL_VAR], prm[PAR_VGATE_VAR])
        nis_v = nis_2d(gv_e - x[IVE], gv_n - x[IVN], P[IVE, IVE] + rv, P[IVE, IVN],
                       P[IVN, IVN] + rv)
        verdict_v, since_v = chi2_gate(nis_v, prm[PAR_GATE_THR], t, st[ST_VREJ_SINCE],
                                       prm[PAR_VGATE_RESET], RESET_AFTER_FIRST_REJECT,
                                       nis > prm[PAR_GATE_THR])
        vel = verdict_v != GATE_FAIL
        if verdict_v != GATE_RESET:
            st[ST_VREJ_SINCE] = since_v
    accept = True
    reset = False
    r_fac = 1.0
    if gate and n_fix >= prm[PAR_GATE_WARMUP]:  # no gate before the filter has converged
        thr = prm[PAR_GATE_THR]
        run_s = t - rej_since if rej_since >= 0.0 else 0.0
        verdict, rej_since = chi2_gate(nis, thr, t, rej_since, prm[PAR_GATE_RESET],
                                       RESET_AFTER_FIRST_REJECT, False)
        if verdict == GATE_RESET:
            # no lock-out: accept and inflate P by the innovation.  First, also in
            # inflate mode: fixes that have disagreed for gate_reset_s are a new
            # truth (a datum change), not an error to down-weight forever
            reset = True
            info[INF_GATE_RESETS] += 1.0
        elif verdict == GATE_FAIL:
            if (inflate_on is not None and nis <= thr * prm[PAR_GATE_INFLATE_MAX]
                    and t - rej_since >= prm[PAR_GATE_INFLATE_AFTER]):
                # robust down-weighting (docs/algorithms.md#gate) once the fixes have
                # disagreed for gate_inflate_after_s (a short multipath burst is still
                # rejected): accept with R scaled so that the NIS equals the gate
                r_fac = nis / thr
                info[INF_INFLATED] += 1.0
            else:
                accept = False
                rej = True
    if accept:
        if innov_on is not None and r_fac == 1.0 and not gap:
            # innovation adaptive factor: P(k|k-1) /= alpha (not on a fix the gate
            # down-weighted as an outlier: in reject mode it would not be used at all)
            af = adaptive_factor(ye, yn, s00 + s11, prm[PAR_INNOV_C])
            if af < 1.0:
                g = 1.0 / af
                inflate_kinematic(P, g)
                if ge_on is not None:  # the same congruence on P(x, b)'s kinematic rows
                    for i in range(12):
                        ge[i] *= math.sqrt(g)
        if reset:
            add_e += ye * ye
            add_n += yn * yn
            P[IE, IE] += ye * ye
            P[IN, IN] += yn * yn
            if prm[PAR_NO_DR] > 0.0:
                # GNSS only: the fixes alone measured the motion, so the state ran off (a
                # manoeuvre the model did not follow), its velocity by about the innovation
                # over the run's seconds.  With the position alone freed, the old velocity
                # carried the track off again (a real GNSS-only log's U-turn: 65 m from its
                # fixes even after a 1-s reset)
                tv = max(run_s, 1.0)
                add_ve = (ye / tv) ** 2
                add_vn = (yn / tv) ** 2
                P[IVE, IVE] += add_ve
                P[IVN, IVN] += add_vn
        if sage_on is not None:  # Zeng et al. Sage-Husa on a scale of R, with the divergence guard
            sample = (ye * ye - P[IE, IE] + yn * yn - P[IN, IN]) / (r_e + r_n)
            sh_r = sage_husa_r(sh_r, sh_m, prm[PAR_SH_B], sample, prm[PAR_SH_RMIN],
                               prm[PAR_SH_RMAX])
            sh_m += 1
            re = r_e * sh_r * f_wh
            rn = r_n * sh_r * f_wh
        if (whiten_off is None and not reset and r_fac == 1.0 and nis <= prm[PAR_WH_NIS]
                and not is_static  # a stop has its own rule (R x m, above)
                and P[IE, IE] + P[IN, IN] < (r_e + r_n) * sh_r):  # converged only
            # normalised innovations; their lag-one product only between fixes at most
            # PAR_WH_GAP s apart (an outage restarts the pair).  Only fixes with a NIS
            # under PAR_WH_NIS: a filter error (a drive-off with an unknown heading, the
            # end of an outage) also makes the innovations correlated, and inflating R
            # then slowed its correction
            ue = ye / math.sqrt(P[IE, IE] + r_e * sh_r)
            un = yn / math.sqrt(P[IN, IN] + r_n * sh_r)
            d_wh = (1.0 - prm[PAR_WH_B]) / (1.0 - prm[PAR_WH_B] ** (wh_m + 1.0))
            wh_c0 = (1.0 - d_wh) * wh_c0 + d_wh * 0.5 * (ue * ue + un * un)
            if t - wh_t <= prm[PAR_WH_GAP]:
                wh_c1 = (1.0 - d_wh) * wh_c1 + d_wh * 0.5 * (ue * wh_ue + un * wh_un)
            if t - wh_t2 <= 2.0 * prm[PAR_WH_GAP]:
                wh_c2 = (1.0 - d_wh) * wh_c2 + d_wh * 0.5 * (ue * wh_ue2 + un * wh_un2)
            wh_ue2 = wh_ue
            wh_un2 = wh_un
            wh_t2 = wh_t
            wh_ue = ue
            wh_un = un
            wh_t = t
            wh_m += 1.0
        re *= r_fac
        rn *= r_fac
        if ge_on is not None:
            # the bias is estimated only when the velocity is known independently of the
            # fixes, from the receiver (Doppler) or by a standstill (ZUPT): otherwise a
            # slow drift of the fixes cannot be told from a DR heading error, and the
            # states absorbed a drive-off's wrong heading; then b is a consider
            # state (it widens S only)
            est_b = is_static or vel
            ok1 = ge_fix_update(x, P, ge, z_e, z_n, re, rn, K, est_b)
            ok2 = ok1
        else:
            ok1 = unit_update(x, P, i_e, ye, re, 1.0, K, PHt, no_cons)
            ok2 = unit_update(x, P, i_n, z_n - x[IN], rn, 1.0, K, PHt, no_cons)
        if ok1 and ok2:
            used = True
            n_fix += 1.0
            if vel:
                # receiver (Doppler) velocity, aekf.gnss_velocity_sd_mps
                st[ST_VREJ_SINCE] = -1.0
                for idx in (IVE, IVN):
                    y = (gv_e if idx == IVE else gv_n) - x[idx]
                    ok_v = unit_update(x, P, idx, y, prm[PAR_GVEL_VAR], 1.0, K, PHt, no_cons)
                    if ge_on is not None:  # noqa: SIM102 (a plain test: numba prunes it when off)
                        if ok_v:
                            n_rows = ge_push(gw, n_rows, float(idx), H, PHt, prm[PAR_GVEL_VAR], y)
            elif has_v:
                info[INF_VEL_GATED] += 1.0
        else:
            info[INF_SKIPPED] += 1.0
    st[ST_REJ_SINCE] = rej_since
    st[ST_SH_R] = sh_r
    st[ST_SH_M] = sh_m
    st[ST_N_FIX] = n_fix
    st[ST_WH_C0] = wh_c0
    st[ST_WH_C1] = wh_c1
    st[ST_WH_C2] = wh_c2
    st[ST_WH_UE] = wh_ue
    st[ST_WH_UN] = wh_un
    st[ST_WH_UE2] = wh_ue2
    st[ST_WH_UN2] = wh_un2
    st[ST_WH_T] = wh_t
    st[ST_WH_T2] = wh_t2
    st[ST_WH_M] = wh_m
    st[ST_WH_STATIC] = wh_static
    st[ST_B_SINCE] = b_since
    return add_e, add_n, add_ve, add_vn, g, n_rows, ge_pred, nis, used, rej


@njit(cache=True, error_model="numpy")
def cs_filter_kernel(inp: CsInputs, state: CsState, k_start: int, k_end: int, p_off: int,
                     prm: np.ndarray, flg: np.ndarray, out: CsOutputs, store: CsStore,
                     info: np.ndarray, wk: np.ndarray, gw: np.ndarray,
                     fading_on: int | None = None, innov_on: int | None = None,
                     sage_on: int | None = None, check_on: int | None = None,
                     store_on: int | None = None, inflate_on: int | None = None,
                     whiten_off: int | None = None, floor_off: int | None = None,
                     turn_off: int | None = None, omega_skip_on: int | None = None,
                     along_off: int | None = None, heading_consider_on: int | None = None,
                     ge_on: int | None = None) -> None:
    """Forward pass of the ekf/aekf over n epochs; writes the ``out`` arrays in place.

    Inputs per epoch (``inp``, :data:`CsInputs`): ``dt`` s; GNSS ``z_e, z_n`` m with
    variances ``r_e, r_n`` m^2 (already regime-scaled); ``ka`` K_a factor; ``yaw`` gyro yaw
    rate rad/s (CCW+, so the heading rate is ``-yaw``); inputs are read only where their flag
    is set; ``odo`` speed m/s; ``outage`` epoch inside a GNSS outage.
    Runs epochs ``k_start <= k < k_end`` from ``state`` (:data:`CsState`): ``x, P`` (after epoch
    k_start - 1, or the initial state at epoch 0), updated in place, and the
    internal state ``st`` (ST_* indices: remembered heading, static flag, time,
    gate and Sage-Husa memory), read at the start and written at the end; so
    the pass can be cut into segments and a segment re-run bit for bit from a
    checkpoint (the checkpointed smoother).  ``prm``/``flg``: PAR_*/FLG_* indices.
    Outputs (``out``, :data:`CsOutputs`; one row per quantity, so every track column is a
    contiguous view): ``x_out`` (8, n) posterior states; ``pcov_out`` (3, n) var_e, var_n, cov_en;
    ``sd_out`` (2, n) sigma of eps and k_s; when ``flg[FLG_STORE]`` (``store``,
    :data:`CsStore`), ``P_store[k - p_off]`` the packed P(k|k) and ``prior_store[k]`` the prior
    scalars; ``info`` counters (INF_*), accumulated (the caller initialises them);
    ``wk`` (5, 8) scratch rows (H, K, P H^T, B H^T, the Singer q).
    ``ge`` (N_GE,): the GNSS error block (aekf.gnss_err_states; GE_* layout: P(x, b),
    P(b, b), b), read and updated in place like x, P (empty when off); ``gw``
    (GW_ROWS, 8) its work rows; ``b_out`` (2, n) the posterior b per epoch; with
    ``flg[FLG_STORE]`` the block's covariances follow the packed P in ``P_store`` and the
    bias transition f_b is ``prior_store[k, PRI_FB]``.
    The options that are off by default come as keyword arguments that are None
    when off (``*_on``; ``*_off`` for those on by default): numba prunes the branches of a None
    argument before type
    inference, so a default run compiles none of their code and helpers (cold
    start); :func:`kernel_options` builds them from ``flg``.
    """
    dt, has_gnss, z_e, z_n, r_e, r_n, ka, has_gyro, yaw, has_odo, odo, outage, gv_e, gv_n, ge_var = inp
    x, P, st, ge = state
    x_out, pcov_out, gnss_used, gnss_rej, nis_out, static_out, hold_out, sd_out, b_out = out
    P_store, prior_store = store
    n = N_STATES
    H = wk[0]
    K = wk[1]
    PHt = wk[2]
    qbuf = wk[4]
    if check_on is not None:
        L = np.empty((n, n))  # Cholesky scratch of the SPD check (tests)
    alpha = prm[PAR_ALPHA]
    tau_eps = prm[PAR_TAU_EPS]
    adapt_q = flg[FLG_ADAPT_Q] != 0
    standstill = flg[FLG_STANDSTILL] != 0
    gate = flg[FLG_GATE] != 0
    heading_known = st[ST_HEADING_KNOWN] != 0.0
    drift_consider = flg[FLG_DRIFT_CONSIDER]
    odo_consider = flg[FLG_ODO_CONSIDER]
    coast_q = prm[PAR_COAST_Q]
    no_dr = prm[PAR_NO_DR] != 0.0
    n_ep = dt.shape[0]
    cons_not_acc = np.int64(CONS_NOT_ACC)
    off_vvar = prm[PAR_OFF_VVAR]
    off_avar = prm[PAR_OFF_AVAR]
    omega_min = prm[PAR_OMEGA_MIN]
    sigma_a = prm[PAR_SIGMA_A]
    psi_mem = st[ST_PSI]
    is_static = st[ST_STATIC] != 0.0
    t = st[ST_T]
    r_w = prm[PAR_R_OMEGA]
    w_held = st[ST_W]
    w_t = st[ST_W_T]
    fix_t = st[ST_FIX_T]
    odo_t = st[ST_ODO_T]
    vpsi = st[ST_VPSI]
    cpe = st[ST_CPE]
    heading_min = prm[PAR_HEADING_MIN]
    # standstill.zupt_keeps_position: the zero-velocity update does not move the position (a stop
    # says nothing about where the car is), but P's velocity-position correlation (a heading
    # error's, which shrinks with the speed in truth and not in the linear model) made it halve
    # the position sigma at every stop in an outage
    zupt_pos = flg[FLG_ZUPT_POS]  # 0 never, 1 in GNSS outages, 2 always
    # state indices and the empty consider mask as int64 values, not integer literals: numba
    # compiles a helper once per literal argument (cold start: 4 copies of unit_update)
    i_eps = np.int64(6)
    no_cons = np.int64(0)
    for k in range(k_start, k_end):
        T = dt[k]
        qa_e = 0.0
        qa_n = 0.0
        lam = 1.0
        g = 1.0
        add_e = 0.0
        add_n = 0.0
        add_ve = 0.0
        add_vn = 0.0
        w_use = math.nan
        r_turn = r_w
        fl_ee = 0.0
        fl_nn = 0.0
        fl_en = 0.0
        f_b = 1.0
        n_rows = 0  # DR rows waiting for the GNSS error block (ge_epoch)
        ge_pred = np.bool_(False)  # a bool, not the literal False: gnss_fix's type with ge off
        # a step longer than aekf.max_gap_s (a logger pause, a far-future stamp) is not
        # propagated: held like a standstill, the position variance grown by (speed bound x T)^2
        gap = T > prm[PAR_MAX_GAP]
        st[ST_JUMP_E] = 0.0
        st[ST_JUMP_N] = 0.0
        if is_static and t + T - odo_t > STALE_ODO_S:
            is_static = False
        hold = (standstill and is_static) or gap
        # ---- 1. predict (Fang et al. CS model; Zeng et al. static hold; fading memory)
        if k > 0 and T > 0.0:
            if adapt_q:  # Fang et al. eqs. (14)-(15)
                s2e = cs_sigma_a2(x[IAE], prm[PAR_AMAX], prm[PAR_AMIN], ka[k], sigma_a)
                s2n = cs_sigma_a2(x[IAN], prm[PAR_AMAX], prm[PAR_AMIN], ka[k], sigma_a)
            else:
                s2e = sigma_a * sigma_a
                s2n = s2e
            qa_e = 2.0 * alpha * s2e
            qa_n = 2.0 * alpha * s2n
            if fading_on is not None:
                lam = fading_factor(prm[PAR_FADING], T)
            f_eps = math.exp(-T / tau_eps)
            p66 = P[IEPS, IEPS]
            predict_mean(x, T, f_eps if prm[PAR_EPS_MEAN_DECAY] != 0.0 else 1.0, hold)
            predict_cov(P, T, alpha, f_eps, qa_e, qa_n, prm[PAR_Q_EPS], prm[PAR_Q_KS], lam, hold, qbuf)
            if ge_on is not None:  # GNSS error states: 1/tau_b = 1/tau + speed/distance (multipath
                # decorrelates with the antenna's displacement; parked, only with time)
                sp_b = 0.0 if hold else math.sqrt(x[IVE] * x[IVE] + x[IVN] * x[IVN])
                f_b = math.exp(-T * (prm[PAR_GE_RATE] + sp_b * prm[PAR_GE_DIST_RATE]))
                if ge_var[k] != st[ST_GE_VAR]:
                    # the fixes' error changed kind (an RTK drive's centimetre fixes and its
                    # float / autonomous ones): b is a new variable, independent of the old
                    f_b = 0.0
                    st[ST_GE_VAR] = ge_var[k]
                gw[GW_PRED, 0] = T
                gw[GW_PRED, 1] = f_eps
                gw[GW_PRED, 2] = lam
                gw[GW_PRED, 3] = 1.0 if hold else 0.0
                gw[GW_PRED, 4] = f_b
                gw[GW_PRED, 5] = 0.0
                ge_pred = True
            t += T
            if gap:
                # capped at max_gap_s: past it the position is as good as unknown, and a
                # larger variance only costs the next fix its precision in float64 (NaN P)
                add_e = (prm[PAR_GAP_SPEED] * min(T, prm[PAR_MAX_GAP])) ** 2
                add_n = add_e
                P[IE, IE] += add_e
                P[IN, IN] += add_n
            if turn_off is None and not hold:  # our choice: the gyro turns v and a (aekf.turn_propagation)
                if has_gyro[k] and math.isfinite(yaw[k]):
                    w_use = -yaw[k]  # the rate read at the end of the step
                elif t - w_t <= prm[PAR_GYRO_HOLD]:
                    w_use = w_held  # a slower gyro: its last rate, held briefly
                if math.isfinite(w_use):
                    # gyro.scale_sd (our choice): a scale error turns the heading by s x the
                    # angle turned; as a random walk per radian turned its variance grows by
                    # scale_sd^2 |w T| (a 90 deg turn: 0.36 deg for 0.5 %, exact 0.45 deg)
                    r_turn = r_w + prm[PAR_SCALE_VAR] * abs(w_use) / T
                    turn_predict(x, P, T, w_use, r_turn)
                    if ge_on is not None:  # the turn's Jacobian, for P(x, b) in ge_epoch
                        ge_turn(gw, x, T, w_use)
            if floor_off is None:
                # ---- heading floor (aekf.heading_floor, our choice): the model has no heading
                # state, so the heading error lives in the cross-track velocity variance, which
                # a stop (ZUPT) erases and the speed and lateral rows can shrink without heading
                # information.  A consider heading variance vpsi follows the gyro-integrated
                # heading error dpsi' = dpsi - T d_eps + T n_w (drift covariance from P; reset
                # from P at GNSS fixes while moving, below) and the prior's cross-track
                # velocity variance is kept >= speed^2 vpsi: the deficit enters as process
                # noise of this step, so the smoother treats it like Q
                if math.isfinite(w_use) or (hold and has_gyro[k]):
                    r_h = r_turn if math.isfinite(w_use) else r_w
                    vpsi = min(vpsi + T * T * (p66 + r_h) - 2.0 * T * cpe, VPSI_MAX)
                    cpe = f_eps * (cpe - T * p66)
                elif (not hold and outage[k] and prm[PAR_UNKNOWN_W_VAR] > 0.0
                      and max(w_t, fix_t) > -math.inf):
                    # in an outage without a gyro reading (none on the drive, or clipped, dropped
                    # out): the turn since the heading was last known (a reading, or the fix that
                    # reset this floor) is unknown, its angle grows as that time times a typical
                    # yaw rate (gyro.unknown_rate_sd_radps); a turn through it must not be
                    # predicted straight with a confident heading
                    tg = t - max(w_t, fix_t)
                    tg0 = max(tg - T, 0.0)
                    vpsi = min(vpsi + prm[PAR_UNKNOWN_W_VAR] * (tg * tg - tg0 * tg0), VPSI_MAX)
                elif not hold:  # the gyro does not drive the heading in this step: no floor
                    vpsi = 0.0
                    cpe = 0.0
                sp = math.sqrt(x[IVE] * x[IVE] + x[IVN] * x[IVN])
                if not hold and sp >= omega_min:
                    ce = x[IVN] / sp  # cross-track unit: (d v / d psi) / speed
                    cn = -x[IVE] / sp
                    d = sp * sp * vpsi - (ce * ce * P[IVE, IVE] + 2.0 * ce * cn * P[IVE, IVN]
                                          + cn * cn * P[IVN, IVN])
                    if d > 0.0:
                        fl_ee = d * ce * ce
                        fl_nn = d * cn * cn
                        fl_en = d * ce * cn
                        P[IVE, IVE] += fl_ee
                        P[IVN, IVN] += fl_nn
                        P[IVE, IVN] += fl_en
                        P[IVN, IVE] = P[IVE, IVN]
            if no_dr and outage[k] and not hold:
                # a GNSS-only drive's outage: the acceleration is held at 0 (the rows in step 3),
                # so the velocity's variance grows as a random walk instead (the car may brake or
                # drive off); kept with the floor's deficit in fl_*, the smoother's process noise
                q_v = prm[PAR_NO_DR_VEL_Q] * T
                fl_ee += q_v
                fl_nn += q_v
                P[IVE, IVE] += q_v
                P[IVN, IVN] += q_v
        # ---- 2. GNSS position fix
        nis_out[k] = math.nan
        gnss_used[k] = False
        gnss_rej[k] = False
        if has_gnss[k]:
            add_e, add_n, add_ve, add_vn, g, n_rows, ge_pred, nis_out[k], gnss_used[k], \
                gnss_rej[k] = gnss_fix(
                z_e[k], z_n[k], r_e[k], r_n[k], gv_e[k], gv_n[k], x, P, st, prm, ge, gw, wk, info,
                t, is_static, gap, gate, ge_pred, add_e, add_n, innov_on, sage_on, whiten_off,
                inflate_on, ge_on)
            if gnss_used[k]:
                fix_t = t
        # ---- 3. odometer: ZUPT at standstill, else speed u = k_s |v|
        if has_odo[k]:
            u = odo[k]
            odo_t = t
            was_static = is_static
            is_static = standstill and u < prm[PAR_STATIC_SPEED]
            if was_static and not is_static and heading_known:
                # drive-off (aekf.drive_off_*): the stop's zero-velocity updates left v and a known
                # to mm/s, and the record that ends it says the car moves off at an acceleration
                # nothing has measured yet.  Along the remembered heading only: the car drives
                # off the way it faced, and an isotropic v lost the heading (evidence:
                # docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-aekf)
                ue = math.sin(psi_mem)
                un = math.cos(psi_mem)
                for i, j, var in ((1, 4, off_vvar), (2, 5, off_avar)):
                    P[i, i] += var * ue * ue
                    P[j, j] += var * un * un
                    P[i, j] += var * ue * un
                    P[j, i] = P[i, j]
            if whiten_off is None and not is_static:  # (a store to st at 100 Hz only if used)
                st[ST_WH_STATIC] = 0.0  # a new stop starts a new count of its fixes
            if is_static:
                zupt_cons = CONS_POS if (zupt_pos == 2 or (zupt_pos == 1 and outage[k])) else 0
                for idx in (1, 4, 2, 5):
                    y = -x[idx]
                    if not unit_update(x, P, idx, y, prm[PAR_R_ZUPT], 1.0, K, PHt, zupt_cons):
                        info[INF_SKIPPED] += 1.0
                    elif ge_on is not None:
                        n_rows = ge_push(gw, n_rows, float(idx), H, PHt, prm[PAR_R_ZUPT], y)
            else:
                sp = math.sqrt(x[IVE] * x[IVE] + x[IVN] * x[IVN])
                use = True
                if sp >= omega_min:
                    ue = x[IVE] / sp
                    un = x[IVN] / sp
                else:
                    ue = math.sin(psi_mem)
                    un = math.cos(psi_mem)
                    use = heading_known
                if use:
                    h = odo_row(x, ue, un, H)
                    cons = CONS_EPS if (drift_consider == 2 or (drift_consider == 1 and outage[k])) else 0
                    # in a GNSS outage the speed row corrects neither the odometer scale nor the
                    # position (aekf.odo_consider: consider states): nothing else measures the
                    # speed, so the innovation split between k_s and a speed the motion model lags
                    # in every acceleration walked k_s off, and P's position-velocity correlation
                    # moved the position with every speed innovation; with both as consider
                    # states the outage is plain integration of the gyro heading with the odometer
                    # speed (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-aekf)
                    if odo_consider == 2 or (odo_consider == 1 and outage[k]):
                        cons |= CONS_KS | CONS_POS
                    pe = ue if along_off is None else 0.0
                    pn = un if along_off is None else 0.0
                    if not sparse_update(x, P, H, NZ_ODO, u - h, prm[PAR_R_ODO], 1.0, K, PHt, cons, pe, pn):
                        info[INF_SKIPPED] += 1.0
                    elif ge_on is not None:
                        for i in range(n):
                            gw[GW_H + n_rows, i] = H[i]
                        n_rows = ge_push(gw, n_rows, GW_ODO, H, PHt, prm[PAR_R_ODO], u - h)
        coast = False
        r_c = 0.0
        c_cons = no_cons
        if no_dr:
            # a GNSS-only drive: nothing measures the motion in an outage; rows a = 0 before each
            # step into it (NO_DR_COAST_Q) hold the velocity from the step's start, the prior's
            # velocity variance grows instead (PAR_NO_DR_VEL_Q, step 1).  They correct the
            # acceleration only: the last fixes' velocity is what is held (as an optimal row,
            # through P's velocity-acceleration covariance, it took 1.9 -> 1.2 m/s off a real
            # log's last fix)
            if k + 1 < n_ep and outage[k + 1] and not is_static and dt[k + 1] > 0.0:
                coast = True
                r_c = NO_DR_COAST_Q / dt[k + 1]
                c_cons = cons_not_acc
        elif coast_q > 0.0 and outage[k] and not is_static and T > 0.0 and t - odo_t > STALE_ODO_S:
            # coasting (aekf.coast_acc_psd; a drive without an odometer, in a GNSS outage): nothing
            # measures the speed, and the current statistical model's mean (abar = a_hat) carries
            # the last acceleration through the outage, and the speed ran away;
            # zero-acceleration rows with r = q_c / T (information T / q_c per step, whatever the
            # rate) hold the speed instead, as fkf's kernels_fkf coasting
            coast = True
            r_c = coast_q / T
        if coast:
            for idx in (2, 5):
                y = -x[idx]
                if not unit_update(x, P, idx, y, r_c, 1.0, K, PHt, c_cons):
                    info[INF_SKIPPED] += 1.0
                elif ge_on is not None:
                    n_rows = ge_push(gw, n_rows, float(idx), H, PHt, r_c, y)
        static_out[k] = is_static
        hold_out[k] = hold
        # ---- 4. gyro: heading rate (Fang et al.), or the drift alone at standstill
        if has_gyro[k]:
            if is_static:
                y = -yaw[k] - x[IEPS]
                if not unit_update(x, P, i_eps, y, prm[PAR_R_OMEGA], 1.0, K, PHt, no_cons):
                    info[INF_SKIPPED] += 1.0
                elif ge_on is not None:
                    n_rows = ge_push(gw, n_rows, 6.0, H, PHt, prm[PAR_R_OMEGA], y)
            elif turn_off is None and omega_skip_on is not None:
                pass  # the gyro already turned the velocity in the prediction
            elif math.sqrt(x[IVE] * x[IVE] + x[IVN] * x[IVN]) >= omega_min:
                h = omega_row(x, H)
                z = -yaw[k]
                if turn_off is None:  # OMEGA_LATERAL: the turn is in the prediction; what is left of the
                    # Fang et al. row says the residual acceleration has no lateral part (it
                    # corrects v too: with v, eps or both as consider states the 10 minute
                    # outage of tests/test_faults.py ended 2-3 x farther off)
                    z = 0.0
                    h -= x[IEPS]
                    H[IEPS] = 0.0
                # drift as a consider state while moving (aekf.drift_consider): without an
                # absolute reference a sustained turn (the Singer covariance lets a decay while
                # the mean holds it) or a speed update (through P[eps, v]) must not move eps
                cons = CONS_EPS if (drift_consider == 2 or (drift_consider == 1 and outage[k])) else 0
                if heading_consider_on is not None and outage[k]:
                    cons |= CONS_VEL
                lat = flg[FLG_LATERAL_ACC]
                if turn_off is None and (lat == 2 or (lat == 1 and outage[k])):
                    cons |= CONS_NOT_ACC
                if not sparse_update(x, P, H, NZ_OMEGA, z - h, prm[PAR_R_OMEGA], 1.0, K, PHt, cons, 0.0, 0.0):
                    info[INF_SKIPPED] += 1.0
                elif ge_on is not None:
                    for i in range(n):
                        gw[GW_H + n_rows, i] = H[i]
                    n_rows = ge_push(gw, n_rows, GW_OMEGA, H, PHt, prm[PAR_R_OMEGA], z - h)
        if ge_on is not None:  # noqa: SIM102 (the block: prediction and DR rows; numba prunes a plain test)
            if ge_pred or n_rows > 0:
                ge_epoch(ge, gw, n_rows, ge_pred, alpha, st[ST_GE_VAR])
        sp = math.sqrt(x[IVE] * x[IVE] + x[IVN] * x[IVN])
        if floor_off is None and gnss_used[k] and sp >= heading_min:  # the heading floor restarts from P
            ce = x[IVN] / sp
            cn = -x[IVE] / sp
            vpsi = min((ce * ce * P[IVE, IVE] + 2.0 * ce * cn * P[IVE, IVN] + cn * cn * P[IVN, IVN])
                       / (sp * sp), VPSI_MAX)
            cpe = (ce * P[IVE, IEPS] + cn * P[IVN, IEPS]) / sp
        # ---- remembered heading for the odometer row near standstill
        if sp >= heading_min:  # slower, while braking, the Newton step can reverse v
            psi_mem = math.atan2(x[IVE], x[IVN])
            heading_known = True
        elif has_gyro[k] and k > 0:
            psi_mem += (-yaw[k] - x[IEPS]) * T
        if has_gyro[k] and math.isfinite(yaw[k]):
            w_held = -yaw[k]
            w_t = t
        # ---- outputs and health
        for i in range(n):
            x_out[i, k] = x[i]
            if not math.isfinite(x[i]):
                info[INF_NONFINITE] += 1.0
        pcov_out[0, k] = P[IE, IE]
        pcov_out[1, k] = P[IN, IN]
        pcov_out[2, k] = P[IE, IN]
        if ge_on is not None:
            b_out[0, k] = ge[GE_BE]
            b_out[1, k] = ge[GE_BN]
        sd_out[0, k] = math.sqrt(max(P[IEPS, IEPS], 0.0))
        sd_out[1, k] = math.sqrt(max(P[IKS, IKS], 0.0))
        for i in range(n):
            if P[i, i] < info[INF_MIN_DIAG] or not math.isfinite(P[i, i]):
                info[INF_MIN_DIAG] = P[i, i] if math.isfinite(P[i, i]) else -math.inf
        if check_on is not None and not cholesky(P, L):
            info[INF_SPD_FAIL] += 1.0
        if store_on is not None:
            pack(P, P_store[k - p_off])
            if ge_on is not None:
                for i in range(N_GE_PACKED):
                    P_store[k - p_off, N_PACKED + i] = ge[i]
            prior_store[k, PRI_FB] = f_b
            prior_store[k, PRI_VB] = st[ST_GE_VAR]
            prior_store[k, PRI_QA_E] = qa_e
            prior_store[k, PRI_QA_N] = qa_n
            prior_store[k, PRI_LAM] = lam
            prior_store[k, PRI_GAIN] = g
            prior_store[k, PRI_ADD_E] = add_e
            prior_store[k, PRI_ADD_N] = add_n
            prior_store[k, PRI_ADD_VE] = add_ve
            prior_store[k, PRI_ADD_VN] = add_vn
            prior_store[k, PRI_W] = w_use
            prior_store[k, PRI_FL_EE] = fl_ee
            prior_store[k, PRI_FL_NN] = fl_nn
            prior_store[k, PRI_FL_EN] = fl_en
            prior_store[k, PRI_JUMP_E] = st[ST_JUMP_E]
            prior_store[k, PRI_JUMP_N] = st[ST_JUMP_N]
    st[ST_PSI] = psi_mem
    st[ST_STATIC] = 1.0 if is_static else 0.0
    st[ST_T] = t
    st[ST_HEADING_KNOWN] = 1.0 if heading_known else 0.0
    st[ST_W] = w_held
    st[ST_W_T] = w_t
    st[ST_FIX_T] = fix_t
    st[ST_ODO_T] = odo_t
    st[ST_VPSI] = vpsi
    st[ST_CPE] = cpe
