"""Compiled kernels of the federated filters ``fkf`` and ``fafkf`` (Tang et al.).

One forward pass for both filters (:func:`federated_pass`, the filter chosen
by :func:`kernel_flags`), which with smoothing also runs the backward RTS
pass in O(segment) memory by re-running the loop per segment from a
checkpoint of its state; :func:`smooth_fused` is the same smoother over every
epoch's stored x and P.  All over plain arrays: no Python object per epoch.

Conventions (:mod:`gpsdr_cli.conventions`): metres in the local ENU frame,
seconds, radians; heading ``psi = atan2(v_e, v_n)`` clockwise from north.

Model (docs/algorithms.md#fkf), shared by both local filters::

    x = [e, v_e, a_e, n, v_n, a_n, eps_e, eps_n, q_w, q_s]          (indices 0..9)
    Phi = diag(Phi_e(T), Phi_n(T), exp(-T/tau_eps), exp(-T/tau_eps), I2)   # Tang et al. eq. (2)
    Phi_e = Phi_n = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]]    # eq. (3), erratum: T^2/2

``eps_e, eps_n`` GNSS position error (Gauss-Markov, ``tau_eps``; our choice
beyond the paper: its factor is ``exp(-T/tau - |v| T/D)``, the error also
decorrelating over the distance ``D`` driven, since multipath follows the
antenna's displacement -- :func:`eps_decay`; and tau, D and its sigma per
step from two regimes, clear and obstructed sky, by the share of recent fixes
with a high PDOP -- :func:`select_eps`, ``fkf.multipath_regime``), ``q_w`` the
heading-sensor error and ``q_s`` the odometer distance error (random walks).
Q (our choice, the paper gives none): per axis the white-jerk discretisation
``q_j * [[T^5/20, T^4/8, T^3/6], [T^4/8, T^3/3, T^2/2], [T^3/6, T^2/2, T]]``
(exact for the Newton Phi above, ``q_j = jerk_psd``, m^2/s^5); for eps
``sd^2 (1 - f^2)``, f that factor (keeps its variance stationary at ``sd^2``); for
q_w, q_s ``rw_sd^2 T``.  Phi is applied in place using its block structure
(row and column operations), never as a dense 10x10 product.

Standstill (Zeng et al. static mode): at epochs flagged static the kinematic
blocks are held (Phi = I, no kinematic Q: "x(k|k-1) = x(k-1)") and both local
filters apply a zero-velocity update ``v_e = v_n = a_e = a_n = 0``.
Coasting (our choice): while nothing measures the speed -- no odometer row or
zero-velocity update for ``[fkf] dr_stale_s`` and no accepted fix for the
outage gap; ``PAR_COAST_Q`` > 0 only on drives without an odometer -- the DR
filter takes zero-acceleration rows ``a_e = a_n = 0`` with ``r = q_c / T``
(information ``T / q_c`` per step, so the rate does not matter): the
white-jerk model otherwise carries a drive-off's acceleration through a GNSS
outage (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-fkf).
Held steps (our choice): on a drive without a gyro or odometer (only the GNSS filter
exists) the step into a no-fix epoch (a receiver's record without a position, e.g. the
quality-0 GGA/RMC it keeps writing after losing the fix) is held: before it the GNSS filter
takes rows ``a_e = a_n = 0`` that correct the acceleration only (``NO_DR_COAST_Q``,
``HOLD_ACC_ONLY``), and the step's prior gets a velocity random walk instead
(:func:`held_noise`, ``[fkf] no_dr_vel_psd`` per axis and ``no_dr_heading_psd`` x speed^2
across the track), which the smoother adds as well (:func:`held_step` reads the inputs
only).  The velocity of the last fixes is held and its sigma grows; the white-jerk model had
carried the last acceleration on (a real log's speed 2.7 -> 239 m/s in a minute of no-fix
records).

GNSS local filter (Tang et al. eqs. (4)-(6), erratum: row 2 selects n)::

    z1 = [e + eps_e, n + eps_n],  R1 = diag(f_e sd_e^2, f_n sd_n^2)

plus (our choice, beyond the paper) the receiver's velocity ``z = [v_e, v_n]``
(RMC/VTG speed and course: Doppler, barely touched by multipath), sigma
``[fkf] gnss_velocity_sd_mps``, with each accepted fix while moving (the
paper's GNSS filter sees positions only; evidence:
docs/decisions/0015-evidence-behind-the-filter-choices.md#kernels-fkf), with a chi-square gate on the
2-dof NIS.  The gate is off until ``[gnss] gate_warmup_fixes`` fixes were accepted (the
initial state is one fix: when that one was an outlier, e.g. the 11 m-off copy of a duplicated NMEA
record, the gate otherwise rejected every good fix and kept only the copies, fault
case ``duplicates``).  No lock-out: a gated fix is accepted
anyway when every fix was gated for ``gate_reset_s`` or when most recent
fixes were -- an exponentially weighted share of gated fixes (time constant
``gate_reset_s / ln 2``, so an unbroken run reaches 1/2 after
``gate_reset_s``) above 1/2: the state, not the fixes, is then the outlier
(a minority of bad fixes that keep passing would otherwise hold the
all-gated timer off for ever).  DR local filter (eqs. (7)-(14), erratum: h3, h4 divide by
``v``)::

    Theta = atan2(v_e, v_n) + q_w     H: d/dv_e = v_n/v2, d/dv_n = -v_e/v2, d/dq_w = 1
    S     = T_m sqrt(v2) + q_s        H: d/dv_e = T_m v_e/v, d/dv_n = T_m v_n/v, d/dq_s = 1

The heading row is skipped below ``omega_min_speed`` (of the predicted state:
the Jacobian divides by v2) and while the predicted speed is under
``sqrt(HEAD_SPEED_SNR2)`` sigmas of the speed when no odometer row or
zero-velocity update was applied for ``[fkf] dr_stale_s`` (with a fresh
odometer the speed is measured; fafkf's Carlson-bound P_g would otherwise
inflate the speed variance in a 10-min outage and lock the heading out) (the variance of the velocity
along itself, which the heading rows do not reduce: no lock-out; below it the
direction is noise: a
stop without an odometer left a GNSS-noise velocity pointing backwards, and the
heading residual near pi threw v off, fault case no_odo); below ``v_lin`` the
distance row is linearised
along the latest heading instead of ``v/|v|``: no division by a speed that
can be zero; so it is where the velocity points against the gyro's heading (the
constant-acceleration model carried it through a stop into reverse, which |v| cannot
see: decisions/0064).  fkf/fafkf's eps gate: an eps outside the fix gate's bound on its
stationary distribution for ``[gnss] gate_reset_s`` while moving goes into the position
(:func:`shift_prior`; decisions/0062).  Heading residuals are wrapped to (-pi, pi] and gated
(chi-square(1) at ``[gnss] gate_prob``); after ``gate_reset_s`` of rejected
headings q_w is re-aligned (``q_w += y``, its variance raised by ``y^2``), so
a heading that outran the q_w random walk cannot lock the DR filter out.

Stale local filters (NR mode): a filter without an accepted measurement for
longer than the epochs' outage gap (GNSS) or ``[fkf] dr_stale_s`` (DR) is
left out of the fusion while the other is fresh; in FR mode it needs no such
rule (it is reset to x_g each epoch and carries only its share of the prior).

Updates are sequential scalar rows with the Joseph form
``P = (I - K h) P (I - K h)^T + K r K^T`` (computed in O(n^2) for a row) and
P symmetrised after each.

Master fusion (each epoch):

* covariance weighting (fkf): ``P_g = (sum_i P_i^-1)^-1``,
  ``x_g = P_g sum_i P_i^-1 x_i`` (Tang et al. section 4 / Carlson 1990), every
  inverse through a Cholesky factor and solves.  In NR mode a filter's
  information is taken only over the states it can observe (the marginal of
  its P over them): the GNSS filter never contributes q_w, q_s, the DR filter
  never eps_e, eps_n -- their copies there are the never-updated prior, and
  fusing them would count that prior twice and pull the other filter's
  estimate towards zero.  In FR mode every state is fused (the reset gives
  each filter a consistent share of all of them), with a single factorisation
  (:func:`fuse_two`).  In FR mode with one share per filter the local filters
  start each epoch as ``x_g, P_g/c_i`` (``c_1 + c_2 = 1``), so in information
  form ``P_g'^-1 = P_g^-1 + sum_rows h^T h / r``: the fusion equals every
  local row applied to the fused state, with the innovation
  ``y + h (x_i - x_g)`` of the row's linearisation point
  (:func:`local_and_central_row`) -- one O(n^2) row instead of a 10x10
  fusion per epoch.  The two are the same up to rounding; :func:`fuse_two`
  still serves epochs where a P_i was capped or q_w re-aligned (not rows).
* fuzzy weights (fafkf, Tang et al. eq. (19)-(20)): ``x_g = W1 x1 + W2 x2`` with
  diagonal weight matrices ``W1 + W2 = I``; ``P_g = W1 P1 W1 + W2 P2 W2``
  (the covariance of that combination when the local errors are bounded by
  blockdiag(P1, P2), Carlson's invariant).  Shared states (position, velocity,
  acceleration) get the controller's beta (one scalar, or one per block:
  position block [e, n] and velocity block [v, a]); each sensor-error state
  comes from the filter that observes it.
* fuzzy shares (fafkf, ``weights = "shares"``): covariance weighting as for
  fkf, the controller's beta the FR information share ``c_1``.

Modes: NR (no reset, Tang et al.'s choice) keeps the local filters apart; FR
(fusion-reset, Carlson 1990) sets ``x_i = x_g``, ``P_i = P_g / c_i`` after
each fusion and predicts with ``Q_i = Q / c_i`` (shares ``c_1 + c_2 = 1``),
which keeps the fused covariance consistent.  fkf uses ``c_1 = beta_gnss``;
fafkf the position-block (or scalar) beta of the epoch.

Adaptive R (fafkf, Tang et al. section 3): see :mod:`gpsdr_cli.filters.fuzzy`;
the controller's table is interpolated here, once per measurement row.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from .adaptive import nis_2d
from .core.gate import (
    GATE_FAIL,
    GATE_PASS,
    GATE_RESET,
    RESET_AFTER_FIRST_REJECT,
    RESET_AFTER_LAST_ACCEPT,
    chi2_gate,
)
from .core.linalg import cholesky, is_spd
from .core.packing import pack, unpack
from .core.rts import rts_step
from .core.update import NO_DR_COAST_Q, dense_update, unit_update

NX = 10
IE, IVE, IAE, IN, IVN, IAN, IEPS_E, IEPS_N, IQW, IQS = range(NX)
#: a stop without a fresh fix corrects the velocity only: there the velocity's innovation is the
#: moment's deceleration transient (an odometer at 0 m/s has no scale error to integrate), and
#: read through a position-velocity covariance built over the seconds without fixes it moved
#: a city track 75 m at a stop (decisions/0015, fkf)
ZUPT_CONSIDER = (1 << IE) | (1 << IN) | (1 << IEPS_E) | (1 << IEPS_N)
#: a stop says nothing about the gyro heading's alignment error: read through the velocity's
#: covariance, the braking transient moved it 1.3 -> 10.7 deg at one city stop (decisions/0023)
ZUPT_KEEP_HEADING = 1 << IQW
#: the zero-acceleration rows before a held step correct the acceleration only: the last fixes'
#: velocity is what is held (an optimal row, through P's velocity-acceleration covariance,
#: took 2.70 -> 2.35 m/s off a real log's last fix)
HOLD_ACC_ONLY = ((1 << NX) - 1) & ~((1 << IAE) | (1 << IAN))
#: consider mask of a gate reset's fix: it does not correct the velocity and acceleration
#: (a wrong heading, e.g. a gyro bias, is one reason for a run of rejected fixes: it stays in)
RESET_CONSIDER = (1 << IVE) | (1 << IVN) | (1 << IAE) | (1 << IAN)

# ---- float parameter vector (built by fkf.kernel_parameters) ---------------------------
PAR_TAU_EPS = 0      # s, correlation time of eps_e, eps_n
PAR_EPS_SD = 1       # m, steady-state sigma of eps_e, eps_n
PAR_JERK_PSD = 2     # m^2/s^5, white-jerk spectral density of each axis
PAR_QW_RW = 3        # rad/sqrt(s), random walk of q_w
PAR_QS_RW = 4        # m/sqrt(s), random walk of q_s
PAR_HEAD_SD = 5      # rad, sigma of the heading measurement Theta
PAR_ODO_SD = 6       # m/s, odometer speed sigma (distance sigma = this x T_m)
PAR_ZUPT_SD = 7      # m/s (and m/s^2), sigma of the zero-velocity pseudo-measurements
PAR_OMEGA_MIN = 8    # m/s, heading row skipped below this predicted speed
PAR_GATE_CHI2 = 9    # chi-square(2) gate threshold; <= 0 disables the gate
PAR_GATE_RESET_S = 10  # s, accept again after this long with every fix rejected
PAR_R_MIN = 11       # lower clamp of the R adaptation factor
PAR_R_MAX = 12       # upper clamp
PAR_DELTA_MAX = 13   # largest |Delta| of one R adaptation step
PAR_RES_CLIP = 14    # r^2 clipped to this x Te before entering the window
PAR_BETA_GNSS = 15   # fkf FR: information share of the GNSS filter
PAR_V_LIN = 16       # m/s, below this the distance row is linearised along the heading
PAR_HEAD_CHI2 = 17   # chi-square(1) gate on the heading innovation; <= 0 disables it
PAR_GNSS_STALE_S = 18  # s, GNSS filter without an accepted fix for longer: left out of the fusion
PAR_DR_STALE_S = 19  # s, DR filter without any update for longer: left out of the fusion
PAR_GATE_WARMUP = 20  # no GNSS gate before this many fixes were accepted
PAR_EPS_DIST = 21    # m, eps_e, eps_n also decorrelate over this distance driven; <= 0: off
PAR_GVEL_VAR = 22    # (m/s)^2, variance of the receiver velocity rows; <= 0: not used
# eps regimes (select_eps writes PAR_TAU_EPS, PAR_EPS_SD, PAR_EPS_DIST from these each epoch):
PAR_TAU_EPS_C = 23   # s, clear sky (the latest fix's PDOP < [fkf] gnss_err_pdop)
PAR_EPS_SD_C = 24    # m
PAR_EPS_DIST_C = 25  # m; <= 0: time only
PAR_TAU_EPS_O = 26   # s, obstructed sky (PDOP >= gnss_err_pdop): multipath
PAR_EPS_SD_O = 27    # m
PAR_EPS_DIST_O = 28  # m; <= 0: time only
PAR_COAST_Q = 29     # m^2/s^3: zero-acceleration rows r = this / T while nothing measures the speed; 0: off
PAR_EPS_RESET = 30   # 1: the step into this epoch starts a new, independent eps (select_eps)
PAR_VGATE_VAR = 31   # (m/s)^2, the receiver velocity gate's least variance per axis
PAR_VGATE_RESET_S = 32  # s: receiver velocities gated this long are taken again (no lock-out)
PAR_RES_DEMEAN = 33  # 1: covariance matching on the residuals' scatter about their window mean
PAR_NO_DR = 34       # 1: a GNSS-only drive (no gyro, no odometer): its no-fix epochs are held
PAR_NO_DR_VEL_Q = 35  # m^2/s^3, per axis: velocity random walk of a step into a held epoch
PAR_NO_DR_HEAD_Q = 36  # rad^2/s: heading random walk of that step (cross-track, x speed^2)
PAR_EPS_GATE_S = 37  # s: an eps outside its gate this long goes into the position (0: off)
N_PAR = 38
#: added to a regime share w in ``eps_w``: the step into that epoch starts a new eps
#: (an RTK drive's fix kind changed: fkf_inputs.multipath_regime)
EPS_RESET = 10.0

#: heading row only while v^2 >= this x var(speed), var(speed) = u^T P_vv u, u = v/|v|:
#: a speed of 3 sigmas or more
HEAD_SPEED_SNR2 = 9.0

#: RTS guard: smoothed-minus-forward position NEES above this restarts the recursion
#: (chi-square(2) at 1 - 4e-6)
SMOOTH_RESTART_NEES = 25.0



# ---- integer flags --------------------------------------------------------------------
FLG_MODE_FR = 0      # 1: fusion-reset, 0: no reset
FLG_ADAPT_R = 1      # 1: fuzzy adaptive R
FLG_FUSION = 2       # 0: covariance weighting, 1: fuzzy scalar weight, 2: fuzzy block weights,
                   # 3: covariance weighting with fuzzy information shares
FLG_NORM = 3         # 0: share, 1: log
FLG_WINDOW = 4       # M, residual window length
FLG_GNSS_ON = 5      # the GNSS local filter exists (the drive has fixes)
FLG_DR_ON = 6        # the DR local filter exists (the drive has gyro or odometer)
FLG_STORE = 7        # store the fused x, P per epoch for the smoother
FLG_CHECK_SPD = 8    # count epochs where a P fails the SPD test (tests)
N_FLAGS = 9

FUSE_COV = 0
FUSE_SCALAR = 1
FUSE_BLOCK = 2
FUSE_SHARES = 3    # covariance weighting, the fuzzy reliability as the FR information share

# ---- counters -------------------------------------------------------------------------
C_GNSS_USED = 0
C_GNSS_REJECTED = 1
C_GATE_RESETS = 2
C_HEADING = 3
C_HEADING_SLOW = 4
C_DIST = 5
C_ZUPT = 6
C_NOT_SPD = 7
C_R_ADAPT = 8
C_HEAD_REJECTED = 9
C_HEAD_REALIGN = 10
C_STALE = 11
C_DIST_REJECTED = 12
C_GVEL = 13
C_COAST = 14
C_GVEL_REJECTED = 15
N_COUNTERS = 16

# Output columns of the fused track.
O_E, O_N, O_VE, O_VN, O_VAR_E, O_VAR_N, O_COV_EN = range(7)
N_OUT = 7

# the pass's arguments as records (numba takes namedtuples as they are)
#: per-epoch inputs, arrays of n (fkf_inputs.Prepared): dt (s), the fix (m) and its variances
#: (m^2), the receiver velocity (m/s), the DR heading theta (rad) and distance (m), the odometer
#: time t_m, the standstill flag and the epoch's eps weight
FkfInputs = namedtuple("FkfInputs", "dt has_gnss gnss_e gnss_n gnss_var_e gnss_var_n gnss_ve "
                                    "gnss_vn theta dist t_m static eps_w")
#: where the pass starts: x0 (NX), P0 (NX, NX) and the initial heading psi0 (rad)
FkfStart = namedtuple("FkfStart", "x0 P0 psi0")

NPACK = NX * (NX + 1) // 2
#: stored per epoch for the smoother: the fused x, then the eps the eps gate moved into the
#: position at the step into the epoch (m, e and n; :func:`shift_prior`)
JUMP_E, JUMP_N = NX, NX + 1
NXS = NX + 2

# ---- the filter state (init_state): rows of vec, mats, aux; scalars of sc --------------
V_X1, V_X2, V_XG, V_D1, V_D2 = range(5)         # local states, fused state, reset scalings
M_P1, M_P2, M_PG = range(3)                      # local and fused covariances
A_RFAC, A_ULAST = range(2)                       # R factors, last u per component
ST_T_NOW = 0        # s since the first epoch (the sum of dt, as the pass accumulates it)
ST_T_LAST_ACC = 1   # s, last accepted GNSS fix
ST_T_LAST_DR = 2    # s, last DR update of any kind
ST_T_LAST_DIST = 3  # s, last odometer distance or ZUPT update
ST_T_HEAD_ACC = 4   # s, last accepted heading
ST_PSI_HINT = 5     # rad, latest heading measurement minus q_w (distance-row linearisation)
ST_N_ACC = 6        # GNSS fixes accepted so far
ST_REJ_SHARE = 7    # recent share of gated fixes (EWMA)
ST_T_LAST_FIX = 8   # s, last fix seen
ST_T_LAST_VACC = 9  # s, last accepted receiver velocity
ST_EPS_SINCE = 10   # s, first epoch of the current run of eps outside its gate (< 0: none)
N_SCALARS = 11

#: Ceiling on each state's sigma after a prediction (m, m/s, m/s^2, m, m/s, m/s^2, m, m,
#: rad, m): a logger pause of 50 min grows the white-jerk position variance to ~1e16 m^2,
#: and the next fix's update cancelled it to rounding noise (a variance of -1, then a
#: ZeroDivisionError; found by the fault tests).  The position's 1e5 m (1e10 m^2, beyond a
#: car's reach in a gap of 27 min at 60 m/s) keeps the update of the next fix accurate to
#: 2e-6 m^2: at 1e7 m an RTK fix (GST 1.5 cm) after a 10-min gap of a GNSS-only log left the
#: fused P indefinite (eigenvalue -1e-4 m^2) and the smoother's variances negative.
#: Applied by :func:`cap_variance` (P stays positive semi-definite).
SD_CEILING = np.array([1e5, 3e4, 100.0, 1e5, 3e4, 100.0, 100.0, 100.0, math.pi, 10.0])


@njit(cache=True)
def despike5(values: np.ndarray, threshold: float, out: np.ndarray) -> int:
    """Median-of-5 despiking (the pre-pass of :func:`gpsdr_cli.filters.fkf.despike`).

    ``out[i]`` = the median of ``values[i-2 .. i+2]`` (the ends padded with the
    first/last value) where ``values[i]`` is further than ``threshold`` from it,
    else ``values[i]``; a window holding a NaN leaves the sample as it is (as
    ``np.median``'s NaN would).  Returns the count replaced.  Compiled: the
    numpy form (a sliding-window view and ``np.median``, a partition per row)
    took 60 % of fafkf's pre-pass on a one-hour drive.
    """
    n = values.shape[0]
    count = 0
    for i in range(n):
        a = values[max(i - 2, 0)]
        b = values[max(i - 1, 0)]
        v = values[i]
        c = values[min(i + 1, n - 1)]
        d = values[min(i + 2, n - 1)]
        if math.isnan(a) or math.isnan(b) or math.isnan(v) or math.isnan(c) or math.isnan(d):
            out[i] = v
            continue
        # median of five with min/max exchanges: drop the smaller of the two pairs' minima
        # and the larger of their maxima, then the median of the remaining three
        lo1 = min(a, b)
        hi1 = max(a, b)
        lo2 = min(c, d)
        hi2 = max(c, d)
        lo = max(lo1, lo2)                          # the two smallest minus the smallest
        hi = min(hi1, hi2)                          # the two largest minus the largest
        med = max(min(lo, hi), min(max(lo, hi), v))
        if abs(v - med) > threshold:
            out[i] = med
            count += 1
        else:
            out[i] = v
    return count


@njit(cache=True)
def copy_state(x: np.ndarray, P: np.ndarray, x_to: np.ndarray, P_to: np.ndarray) -> None:
    """x_to, P_to <- x, P element by element.  Not ``x_to[:] = x``: numba compiles a slice
    assignment with its shape-mismatch error path (string formatting), which took ~5 s of
    the kernels' cold compile."""
    for i in range(NX):
        x_to[i] = x[i]
        for j in range(NX):
            P_to[i, j] = P[i, j]


@njit(cache=True)
def wrap_pi(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return a - 2.0 * math.pi * math.ceil((a - math.pi) / (2.0 * math.pi))


@njit(cache=True)
def interp1_uniform(table: np.ndarray, lo: float, hi: float, x: float) -> float:
    """Linear interpolation of ``table`` sampled evenly over [lo, hi]; clamped outside."""
    n = table.shape[0]
    if not x > lo:
        return table[0]
    if x >= hi:
        return table[n - 1]
    f = (x - lo) / (hi - lo) * (n - 1)
    i = min(int(f), n - 2)
    w = f - i
    return table[i] + w * (table[i + 1] - table[i])


@njit(cache=True)
def interp2_unit(table: np.ndarray, a: float, b: float) -> float:
    """Bilinear interpolation of ``table`` sampled evenly over [0, 1]^2 (rows a, columns b)."""
    n = table.shape[0]
    a = min(max(a, 0.0), 1.0)
    b = min(max(b, 0.0), 1.0)
    fa = a * (n - 1)
    fb = b * (n - 1)
    ia = min(int(fa), n - 2)
    ib = min(int(fb), n - 2)
    wa = fa - ia
    wb = fb - ib
    t0 = table[ia, ib] + wb * (table[ia, ib + 1] - table[ia, ib])
    t1 = table[ia + 1, ib] + wb * (table[ia + 1, ib + 1] - table[ia + 1, ib])
    return t0 + wa * (t1 - t0)


@njit(cache=True)
def predict(x: np.ndarray, P: np.ndarray, T: float, static: bool, par: np.ndarray,
            d: np.ndarray) -> None:
    """x <- Phi x, P <- Phi P Phi^T + D Q D over a step of T s (Tang et al. eqs. (1)-(3)).

    ``d`` (length 10) scales Q per state: ``(D Q D)_ij = d_i Q_ij d_j``; all ones
    for the master, ``1/sqrt(c_i)`` for a local filter after a fusion-reset.
    The sigmas are then capped (:func:`cap_variance`).
    """
    if not T > 0.0:
        return
    predict_uncapped(x, P, T, static, par, d)
    cap_variance(P)


@njit(cache=True)
def predict_uncapped(x: np.ndarray, P: np.ndarray, T: float, static: bool, par: np.ndarray,
                     d: np.ndarray) -> None:
    """:func:`predict` without the sigma ceiling (the caller applies it)."""
    if not T > 0.0:
        return
    f = eps_decay(x, T, par)
    if not static:
        h2 = 0.5 * T * T
        for b in range(0, 6, 3):                    # axes e (0..2) and n (3..5)
            x[b] += T * x[b + 1] + h2 * x[b + 2]
            x[b + 1] += T * x[b + 2]
            for j in range(NX):                     # rows: Phi P
                P[b, j] += T * P[b + 1, j] + h2 * P[b + 2, j]
                P[b + 1, j] += T * P[b + 2, j]
            for i in range(NX):                     # columns: (Phi P) Phi^T
                P[i, b] += T * P[i, b + 1] + h2 * P[i, b + 2]
                P[i, b + 1] += T * P[i, b + 2]
        q = par[PAR_JERK_PSD]
        T2 = T * T
        T3 = T2 * T
        for b in range(0, 6, 3):                    # white-jerk Q per axis
            d0 = d[b]
            d1 = d[b + 1]
            d2 = d[b + 2]
            P[b, b] += q * T3 * T2 / 20.0 * d0 * d0
            P[b, b + 1] += q * T2 * T2 / 8.0 * d0 * d1
            P[b + 1, b] += q * T2 * T2 / 8.0 * d0 * d1
            P[b, b + 2] += q * T3 / 6.0 * d0 * d2
            P[b + 2, b] += q * T3 / 6.0 * d0 * d2
            P[b + 1, b + 1] += q * T3 / 3.0 * d1 * d1
            P[b + 1, b + 2] += q * T2 / 2.0 * d1 * d2
            P[b + 2, b + 1] += q * T2 / 2.0 * d1 * d2
            P[b + 2, b + 2] += q * T * d2 * d2
    for s in range(IEPS_E, IEPS_N + 1):
        x[s] *= f
        for j in range(NX):
            P[s, j] *= f
        for i in range(NX):
            P[i, s] *= f
    qe = par[PAR_EPS_SD] ** 2 * (1.0 - f * f)
    P[IEPS_E, IEPS_E] += qe * d[IEPS_E] ** 2
    P[IEPS_N, IEPS_N] += qe * d[IEPS_N] ** 2
    P[IQW, IQW] += par[PAR_QW_RW] ** 2 * T * d[IQW] ** 2   # random walks q_w, q_s
    P[IQS, IQS] += par[PAR_QS_RW] ** 2 * T * d[IQS] ** 2


@njit(cache=True)
def shift_prior(x: np.ndarray, P: np.ndarray, jump_e: float, jump_n: float) -> None:
    """Move ``jump_e, jump_n`` (m) from the GNSS error states eps into the position, whose
    variance grows by its square: a known input of the step (ekf/aekf's bias gate does the
    same), so the RTS pass, which rebuilds the prior with it (:func:`smooth_range`), does not
    spread the correction back over the drive before it.  The forward eps gate calls it too."""
    x[IE] += jump_e
    x[IN] += jump_n
    x[IEPS_E] -= jump_e
    x[IEPS_N] -= jump_n
    P[IE, IE] += jump_e * jump_e
    P[IN, IN] += jump_n * jump_n


@njit(cache=True)
def held_step(k: int, dt: np.ndarray, static: np.ndarray, has_gnss: np.ndarray,
              par: np.ndarray) -> bool:
    """Whether the step into epoch ``k`` is held: a GNSS-only drive (``PAR_NO_DR``), a
    no-fix epoch (a receiver's record without a position), moving, ``dt[k] > 0``.

    From the inputs alone, so the smoother's prior (:func:`smooth_range`) is the forward one.
    """
    return (par[PAR_NO_DR] != 0.0 and k < dt.shape[0] and dt[k] > 0.0 and not static[k]
            and not has_gnss[k])


@njit(cache=True)
def held_noise(x: np.ndarray, P: np.ndarray, T: float, par: np.ndarray) -> None:
    """Velocity variance of a held step of T s (:func:`held_step`), added to the prior P.

    With nothing measuring the motion the velocity is held (the zero-acceleration rows before
    the step, ``NO_DR_COAST_Q``) and its variance grows instead: per axis a random walk of
    ``PAR_NO_DR_VEL_Q`` (m^2/s^3: the speed may change), and across the track one of
    ``PAR_NO_DR_HEAD_Q`` (rad^2/s) x speed^2 (the heading may change; ``c c^T speed^2`` with
    ``c = (v_n, -v_e)/speed`` needs no division).  ``x``: the predicted state.
    """
    qv = par[PAR_NO_DR_VEL_Q] * T
    qh = par[PAR_NO_DR_HEAD_Q] * T
    ve = x[IVE]
    vn = x[IVN]
    P[IVE, IVE] += qv + qh * vn * vn
    P[IVN, IVN] += qv + qh * ve * ve
    P[IVE, IVN] -= qh * ve * vn
    P[IVN, IVE] = P[IVE, IVN]


@njit(cache=True)
def eps_decay(x: np.ndarray, T: float, par: np.ndarray) -> float:
    """Gauss-Markov factor of eps_e, eps_n over T s: ``exp(-T/tau - |v| T/D)``.

    Multipath decorrelates with the antenna's displacement (the reflecting
    geometry changes), not with time alone: ``1/tau_eff = 1/tau + |v|/D``,
    ``|v|`` the speed of the state being predicted, ``D = [fkf]
    gnss_err_dist_m`` (<= 0: time only, Tang et al.).
    """
    if par[PAR_EPS_RESET] != 0.0:
        return 0.0
    rate = 1.0 / par[PAR_TAU_EPS]
    if par[PAR_EPS_DIST] > 0.0:
        rate += math.sqrt(x[IVE] * x[IVE] + x[IVN] * x[IVN]) / par[PAR_EPS_DIST]
    return math.exp(-T * rate)


@njit(cache=True)
def select_eps(par: np.ndarray, w: float) -> None:
    """The eps model of a step into an epoch of regime ``w``
    (:func:`gpsdr_cli.filters.fkf.multipath_regime`): ``par[PAR_TAU_EPS, PAR_EPS_SD,
    PAR_EPS_DIST]`` from the clear-sky (``w <= 0``) or obstructed-sky (``w >= 1``)
    regime, in between blended in rate and variance (``1/tau``, ``1/D``, ``sd^2``
    linear in w).  Copied, so a regime's floats are the parameter's own.  The
    variance of eps relaxes to a new regime's at the process's own rate (Q =
    ``sd^2 (1 - f^2)``); the regime itself changes gradually (a share over a window).
    ``w >= EPS_RESET``: regime ``w - EPS_RESET``, and the step starts a new, independent
    eps (:func:`eps_decay` 0: Q is then the regime's whole variance).
    """
    par[PAR_EPS_RESET] = 1.0 if w >= EPS_RESET else 0.0
    if w >= EPS_RESET:
        w -= EPS_RESET
    if w <= 0.0:
        par[PAR_TAU_EPS] = par[PAR_TAU_EPS_C]
        par[PAR_EPS_SD] = par[PAR_EPS_SD_C]
        par[PAR_EPS_DIST] = par[PAR_EPS_DIST_C]
    elif w >= 1.0:
        par[PAR_TAU_EPS] = par[PAR_TAU_EPS_O]
        par[PAR_EPS_SD] = par[PAR_EPS_SD_O]
        par[PAR_EPS_DIST] = par[PAR_EPS_DIST_O]
    else:
        par[PAR_TAU_EPS] = 1.0 / ((1.0 - w) / par[PAR_TAU_EPS_C] + w / par[PAR_TAU_EPS_O])
        par[PAR_EPS_SD] = math.sqrt((1.0 - w) * par[PAR_EPS_SD_C] ** 2 + w * par[PAR_EPS_SD_O] ** 2)
        inv = 0.0
        if par[PAR_EPS_DIST_C] > 0.0:
            inv += (1.0 - w) / par[PAR_EPS_DIST_C]
        if par[PAR_EPS_DIST_O] > 0.0:
            inv += w / par[PAR_EPS_DIST_O]
        par[PAR_EPS_DIST] = 1.0 / inv if inv > 0.0 else 0.0


@njit(cache=True)
def cap_variance(P: np.ndarray) -> bool:
    """Sigmas at most SD_CEILING: for each state i above it, with ``f_i = (SD_CEILING_i /
    sigma_i)^2``, its variance and its covariances are multiplied by ``f_i`` (so a pair of
    capped states' covariance by ``f_i f_j``).

    Not the congruence D P D: that keeps the correlations, so it multiplies the regression of
    every other state on a capped one by 1/d (at 1e5 m after a 10-min gap, d = 1/22: the next
    fix would move the velocity 22 times as far as the uncapped model does).  Scaling the covariances by the
    variance's own factor keeps those regressions, the gain a fix gives the other states, as
    they were, and P stays positive semi-definite (each step takes ``C - f b b^T / a`` for
    the Schur complement ``C - b b^T / a``, f <= 1).  Returns True when P was scaled."""
    scaled = False
    for i in range(NX):
        if P[i, i] > SD_CEILING[i] ** 2:
            scaled = True
    if not scaled:
        return False
    f = np.ones(NX)
    for i in range(NX):
        if P[i, i] > SD_CEILING[i] ** 2:
            f[i] = SD_CEILING[i] ** 2 / P[i, i]
    for i in range(NX):
        for j in range(NX):
            P[i, j] *= f[i] if i == j else f[i] * f[j]
    return True


@njit(cache=True)
def phi_matrix(T: float, static: bool, par: np.ndarray, Phi: np.ndarray, x: np.ndarray) -> None:
    """The dense Phi of a step from state x (for the smoother; the filters apply it in place)."""
    for i in range(NX):
        for j in range(NX):
            Phi[i, j] = 1.0 if i == j else 0.0
    if not static:
        for b in range(0, 6, 3):
            Phi[b, b + 1] = T
            Phi[b, b + 2] = 0.5 * T * T
            Phi[b + 1, b + 2] = T
    f = eps_decay(x, T, par)
    Phi[IEPS_E, IEPS_E] = f
    Phi[IEPS_N, IEPS_N] = f


@njit(cache=True)
def update_row(x: np.ndarray, P: np.ndarray, h: np.ndarray, y: float, r: float,
               s: np.ndarray, k: np.ndarray, consider: int = 0) -> None:
    """Scalar measurement update of a dense row h with the innovation y = z - h(x) and
    variance r (:func:`~gpsdr_cli.filters.core.update.dense_update`, Joseph form);
    ``s``, ``k`` are length-10 scratch (P h^T, the gain); ``consider``: a bit mask of
    states the row does not correct."""
    dense_update(NX, x, P, h, y, r, 1.0, k, s, consider)


@njit(cache=True)
def unit_row(x: np.ndarray, P: np.ndarray, idx: int, y: float, r: float, s: np.ndarray,
             k: np.ndarray, consider: int = 0) -> None:
    """:func:`update_row` for ``h = e_idx`` (one state measured directly); ``consider``: a
    bit mask of states the row does not correct."""
    unit_update(NX, x, P, idx, y, r, 1.0, k, s, consider)


@njit(cache=True)
def local_and_central_unit(x: np.ndarray, P: np.ndarray, xc: np.ndarray, Pc: np.ndarray,
                           central: bool, idx: int, y: float, r: float, s: np.ndarray,
                           k: np.ndarray, consider: int = 0) -> None:
    """:func:`local_and_central_row` for ``h = e_idx`` (``consider``: see :func:`unit_row`)."""
    if central:
        unit_row(xc, Pc, idx, y + (x[idx] - xc[idx]), r, s, k, consider)
    unit_row(x, P, idx, y, r, s, k, consider)


@njit(cache=True)
def local_and_central_row(x: np.ndarray, P: np.ndarray, xc: np.ndarray, Pc: np.ndarray,
                          central: bool, h: np.ndarray, y: float, r: float,
                          s: np.ndarray, k: np.ndarray, consider: int = 0) -> None:
    """One local row (innovation y at the local x), and, when ``central``, the same row on
    the running fused state (xc, Pc) first (``consider``: see :func:`update_row`).

    Information form of a row: ``P^-1 += h^T h / r``, ``P^-1 x += h^T z~ / r`` with the
    linearised measurement ``z~ = y + h x`` at the local state; on the fused state the
    innovation is therefore ``z~ - h xc = y + h (x - xc)``.
    """
    if central:
        yc = y
        for i in range(NX):
            if h[i] != 0.0:
                yc += h[i] * (x[i] - xc[i])
        update_row(xc, Pc, h, yc, r, s, k, consider)
    update_row(x, P, h, y, r, s, k, consider)


@njit(cache=True)
def zupt_central(x: np.ndarray, P: np.ndarray, xc: np.ndarray, Pc: np.ndarray, central: bool,
                 sd: float, h: np.ndarray, s: np.ndarray, k: np.ndarray, consider: int) -> None:
    """:func:`zupt` on a local filter, its rows also on the fused state when ``central``;
    ``consider``: a bit mask of states the rows do not correct."""
    for idx in (IVE, IVN, IAE, IAN):
        local_and_central_unit(x, P, xc, Pc, central, idx, -x[idx], sd * sd, s, k, consider)


@njit(cache=True)
def hph(P: np.ndarray, h: np.ndarray) -> float:
    """h P h^T for a row h."""
    acc = 0.0
    for i in range(NX):
        if h[i] != 0.0:
            for j in range(NX):
                if h[j] != 0.0:
                    acc += h[i] * P[i, j] * h[j]
    return acc


@njit(cache=True)
def zupt(x: np.ndarray, P: np.ndarray, sd: float, h: np.ndarray, s: np.ndarray,
         k: np.ndarray) -> None:
    """Zero-velocity update: v_e = v_n = a_e = a_n = 0 with sigma ``sd`` (Zeng et al. static mode)."""
    for idx in (IVE, IVN, IAE, IAN):
        h[:] = 0.0
        h[idx] = 1.0
        update_row(x, P, h, -x[idx], sd * sd, s, k)


@njit(cache=True)
def heading_row(x: np.ndarray, h: np.ndarray) -> float:
    """Fill h with the heading row at x; return the prediction atan2(v_e, v_n) + q_w (rad).

    Caller guarantees v_e^2 + v_n^2 >= omega_min_speed^2 > 0.  Tang et al. eqs. (11)-(12).
    """
    ve = x[IVE]
    vn = x[IVN]
    v2 = ve * ve + vn * vn
    h[:] = 0.0
    h[IVE] = vn / v2
    h[IVN] = -ve / v2
    h[IQW] = 1.0
    return math.atan2(ve, vn) + x[IQW]


@njit(cache=True)
def distance_row(x: np.ndarray, h: np.ndarray, t_m: float, v_lin: float, psi_hint: float,
                 heading: bool) -> float:
    """Fill h with the odometer-distance row; return the prediction T_m |v| + q_s (m).

    Tang et al. eqs. (13)-(14) with the erratum (divide by v, not v2).  Below
    ``v_lin`` the speed is linearised along the heading ``psi_hint`` instead, and so it is
    where the velocity points away from that heading (``heading``: the gyro gave it this
    epoch): the odometer measures travel along the vehicle's heading, and |v| cannot tell a
    velocity that the constant-acceleration model carried through a stop into reverse
    (which then grew backwards, and the heading rows near pi threw the track 70 m off after
    a stop without fixes; docs/decisions/0064).
    """
    ve = x[IVE]
    vn = x[IVN]
    v = math.sqrt(ve * ve + vn * vn)
    h[:] = 0.0
    h[IQS] = 1.0
    ue = math.sin(psi_hint)
    un = math.cos(psi_hint)
    if v >= v_lin and not (heading and ue * ve + un * vn < 0.0):
        h[IVE] = t_m * ve / v
        h[IVN] = t_m * vn / v
        return t_m * v + x[IQS]
    h[IVE] = t_m * ue
    h[IVN] = t_m * un
    return t_m * (ue * ve + un * vn) + x[IQS]


@njit(cache=True)
def adapt_r(j: int, y: float, te: float, ring: np.ndarray, pos: np.ndarray, cnt: np.ndarray,
            par: np.ndarray, r_table: np.ndarray, rfac: np.ndarray, u_last: np.ndarray) -> bool:
    """Covariance matching for component j (Tang et al. eqs. (15)-(18)) + the fuzzy R controller.

    Pushes the prior residual ``y`` (clipped to +-sqrt(``res_clip x Te``)) into the
    window; once it holds M values: ``Ra`` = the mean of ``y^2`` (Tang et al.), less the
    square of the window's mean when ``PAR_RES_DEMEAN`` (our choice: a residual that stays
    off for the whole window is the state's error, which the position and the GNSS error
    states are there to take; read as fix noise it raised R to its clamp and locked good
    fixes out of a track left tens of metres off, decisions/0033), ``u = (Te - Ra)/Te``,
    ``Delta = delta_max * table(u)``, ``f_j *= 1 + Delta`` clamped.  Returns True when R
    was adapted.  The window (M is tens) is summed afresh at each push.
    """
    m = ring.shape[1]
    lim = math.sqrt(par[PAR_RES_CLIP] * te)
    ring[j, pos[j]] = min(max(y, -lim), lim)
    pos[j] = (pos[j] + 1) % m
    cnt[j] += 1
    if cnt[j] < m:
        return False
    s1 = 0.0
    s2 = 0.0
    for i in range(m):
        s1 += ring[j, i]
        s2 += ring[j, i] * ring[j, i]
    ra = s2 / m                                     # Tang et al. eq. (16)
    if par[PAR_RES_DEMEAN] != 0.0:
        ra -= (s1 / m) ** 2
    u = (te - ra) / te                              # Dis_jj / Te_jj, eqs. (17)-(18)
    u = min(max(u, -1.0), 1.0)
    u_last[j] = u
    f = rfac[j] * (1.0 + par[PAR_DELTA_MAX] * interp1_uniform(r_table, -1.0, 1.0, u))
    rfac[j] = min(max(f, par[PAR_R_MIN]), par[PAR_R_MAX])
    return True


@njit(cache=True)
def chol_inverse(L: np.ndarray, Linv: np.ndarray, out: np.ndarray) -> None:
    """``out = (L L^T)^-1`` from a Cholesky factor L (of :func:`~.core.linalg.cholesky`).

    ``Linv = L^-1`` by forward substitution with one reciprocal per pivot, then
    ``out = Linv^T Linv`` on the upper triangle, mirrored.  Written here
    because :func:`~.core.linalg.chol_solve` against the identity divides at every
    element of every column: on these 8x8 to 10x10 blocks it was 4x slower.
    """
    k = L.shape[0]
    for i in range(k):
        d = 1.0 / L[i, i]
        Linv[i, i] = d
        for j in range(i):
            acc = 0.0
            for m in range(j, i):
                acc += L[i, m] * Linv[m, j]
            Linv[i, j] = -acc * d
        for j in range(i + 1, k):
            Linv[i, j] = 0.0
    for i in range(k):
        for j in range(i, k):
            acc = 0.0
            for m in range(j, k):
                acc += Linv[m, i] * Linv[m, j]
            out[i, j] = acc
            out[j, i] = acc


@njit(cache=True)
def fuse_information(x1: np.ndarray, P1: np.ndarray, idx1: np.ndarray,
                     x2: np.ndarray, P2: np.ndarray, idx2: np.ndarray,
                     xg: np.ndarray, Pg: np.ndarray, Y: np.ndarray, yv: np.ndarray,
                     A1: np.ndarray, L1: np.ndarray, B1: np.ndarray,
                     A2: np.ndarray, L2: np.ndarray, B2: np.ndarray,
                     L: np.ndarray, W: np.ndarray) -> None:
    """Covariance-weighted fusion over the states ``idx_i`` each filter contributes.

    ``Y = sum_i E_i (P_i[idx_i, idx_i])^-1 E_i^T``, ``P_g = Y^-1``,
    ``x_g = P_g sum_i E_i P_i[idx_i, idx_i]^-1 x_i[idx_i]`` -- every inverse from
    a Cholesky factor (:func:`chol_inverse`), never a general-purpose inverse.
    ``yv`` (10,) and ``L``, ``W`` (10, 10) are scratch; A/L/B the sub-block sizes.
    """
    for i in range(NX):
        yv[i] = 0.0
        for j in range(NX):
            Y[i, j] = 0.0
    for f in range(2):
        if f == 0:
            x, P, idx, A, Lk, B = x1, P1, idx1, A1, L1, B1
        else:
            x, P, idx, A, Lk, B = x2, P2, idx2, A2, L2, B2
        k = idx.shape[0]
        for a in range(k):
            for c in range(k):
                A[a, c] = P[idx[a], idx[c]]
        cholesky(A, Lk)
        chol_inverse(Lk, A, B)                      # B = P_i^-1 (marginal); A reused as scratch
        for a in range(k):
            acc = 0.0
            for c in range(k):
                Y[idx[a], idx[c]] += B[a, c]
                acc += B[a, c] * x[idx[c]]
            yv[idx[a]] += acc                       # P_i^-1 x_i
    cholesky(Y, L)
    chol_inverse(L, W, Pg)                          # P_g = Y^-1
    for i in range(NX):
        acc = 0.0
        for j in range(NX):
            acc += Pg[i, j] * yv[j]
        xg[i] = acc                                 # x_g = P_g sum P_i^-1 x_i


@njit(cache=True)
def fuse_two(x1: np.ndarray, P1: np.ndarray, x2: np.ndarray, P2: np.ndarray,
             xg: np.ndarray, Pg: np.ndarray, S: np.ndarray, L: np.ndarray,
             Y: np.ndarray, u: np.ndarray) -> None:
    """:func:`fuse_information` for two filters over all states, with one factorisation.

    ``(P1^-1 + P2^-1)^-1 = Pa - Pa (P1 + P2)^-1 Pa`` and
    ``x_g = xa + Pa (P1 + P2)^-1 (xb - xa)`` for either labelling (a, b) of
    the two filters; with ``P1 + P2 = L L^T`` and ``Y = L^-1 Pa`` (forward
    substitution): ``P_g = Pa - Y^T Y`` (symmetric by construction) and
    ``x_g = xa + Y^T L^-1 (xb - xa)``.  One Cholesky and triangular solves, no
    explicit inverse (half the work of ``P1 (P1 + P2)^-1 P2`` through
    ``(P1 + P2)^-1``).  ``a`` is the filter with the smaller trace: the
    difference then starts from the smaller covariance, so its cancellation
    stays at rounding level.  ``S``, ``L``, ``Y`` (10, 10) and ``u`` (10,) are scratch.
    """
    ta = 0.0
    tb = 0.0
    for i in range(NX):
        ta += P1[i, i]
        tb += P2[i, i]
    if ta <= tb:
        xa, Pa, xb = x1, P1, x2
    else:
        xa, Pa, xb = x2, P2, x1
    for i in range(NX):
        for j in range(NX):
            S[i, j] = P1[i, j] + P2[i, j]
    cholesky(S, L)
    for i in range(NX):
        S[i, 0] = 1.0 / L[i, i]                     # reciprocal pivots (column 0 of S)
    for c in range(NX):                             # Y = L^-1 Pa
        for i in range(NX):
            acc = Pa[i, c]
            for m in range(i):
                acc -= L[i, m] * Y[m, c]
            Y[i, c] = acc * S[i, 0]
    for i in range(NX):                             # u = L^-1 (xb - xa)
        acc = xb[i] - xa[i]
        for m in range(i):
            acc -= L[i, m] * u[m]
        u[i] = acc * S[i, 0]
    for i in range(NX):
        acc = xa[i]
        for m in range(NX):
            acc += Y[m, i] * u[m]
        xg[i] = acc
        for j in range(i, NX):
            v = Pa[i, j]
            for m in range(NX):
                v -= Y[m, i] * Y[m, j]
            Pg[i, j] = v
            Pg[j, i] = v


@njit(cache=True)
def normalise_pair(a: float, b: float, log_scale: bool) -> tuple[float, float]:
    """Normalise two non-negative evaluation factors to [0, 1] (docs/algorithms.md#fafkf, our choice).

    share: ``a/(a+b)`` (both 0 when both are 0: equally perfect);
    log: ``0.5 + 0.25 log10(a/b)`` clipped to [0, 1] (two decades either side saturate).
    """
    if log_scale:
        tiny = 1e-300
        la = 0.5 + 0.25 * math.log10((a + tiny) / (b + tiny))
        la = min(max(la, 0.0), 1.0)
        return la, 1.0 - la
    tot = a + b
    if not tot > 0.0:
        return 0.0, 0.0
    return a / tot, b / tot


@njit(cache=True)
def in_block(i: int, block: int) -> bool:
    """State i belongs to block 0 (all), 1 (position e, n) or 2 (velocity and acceleration)."""
    if block == 1:
        return i == IE or i == IN
    if block == 2:
        return i == IVE or i == IAE or i == IVN or i == IAN
    return True


@njit(cache=True)
def block_pe(P: np.ndarray, d: np.ndarray, block: int) -> float:
    """PE = tr(M M^T), M = D^-1 P D^-1, over a state block (Tang et al. section 4).

    ``d`` is the filter's reset scaling (ones in NR mode), so M is its
    covariance before the reset's inflation; blocks: see :func:`in_block`.
    P is symmetric: the upper triangle counted twice (half the products, and
    one reciprocal per state instead of a division per element).
    """
    inv = np.zeros(NX)
    for i in range(NX):
        inv[i] = 1.0 / d[i] if in_block(i, block) else 0.0
    diag = 0.0
    off = 0.0
    for i in range(NX):
        a = inv[i]
        if a == 0.0:
            continue
        v = P[i, i] * a * a
        diag += v * v
        for j in range(i + 1, NX):
            v = P[i, j] * a * inv[j]
            off += v * v
    return diag + 2.0 * off


@njit(cache=True)
def pe_scalar(P: np.ndarray, d: float) -> float:
    """:func:`block_pe` over all states when D = d I: ``tr(P P^T) / d^4``."""
    diag = 0.0
    off = 0.0
    for i in range(NX):
        diag += P[i, i] * P[i, i]
        for j in range(i + 1, NX):
            off += P[i, j] * P[i, j]
    d2 = d * d
    return (diag + 2.0 * off) / (d2 * d2)


@njit(cache=True)
def fuzzy_beta(pe1: float, pe2: float, de1n: float, de2n: float, log_scale: bool,
               w_table: np.ndarray) -> float:
    """beta_1 = W_1/(W_1 + W_2) from the fusion controller (Tang et al. eq. (20))."""
    p1, p2 = normalise_pair(pe1, pe2, log_scale)
    w1 = interp2_unit(w_table, p1, de1n)
    w2 = interp2_unit(w_table, p2, de2n)
    return w1 / (w1 + w2)


@njit(cache=True)
def fuse_convex(x1: np.ndarray, P1: np.ndarray, x2: np.ndarray, P2: np.ndarray,
                w: np.ndarray, xg: np.ndarray, Pg: np.ndarray) -> None:
    """x_g = W x1 + (I - W) x2, P_g = W P1 W + (I - W) P2 (I - W), W = diag(w) (Tang et al. eq. (19))."""
    for i in range(NX):
        wi = w[i]
        ui = 1.0 - wi
        xg[i] = wi * x1[i] + ui * x2[i]
        for j in range(i, NX):                      # symmetric: upper triangle, mirrored
            v = wi * w[j] * P1[i, j] + ui * (1.0 - w[j]) * P2[i, j]
            Pg[i, j] = v
            Pg[j, i] = v


@njit(cache=True)
def init_state(x0: np.ndarray, P0: np.ndarray, psi0: float, par: np.ndarray,
               flags: np.ndarray):
    """The filter state before the first epoch: ``(vec, mats, aux, ring, pc, sc)``.

    ``vec`` (5, 10): x1, x2, x_g, d1, d2; ``mats`` (3, 10, 10): P1, P2, P_g;
    ``aux`` (2, 4): R factors, last normalised discrepancies; ``ring`` (4, M): the
    residual windows; ``pc`` (2, 4) int: window positions and counts; ``sc``: the scalars
    ``ST_*``.  Everything that carries from one epoch to the next lives here, so a run can
    stop after any epoch and resume bit-identically (:func:`save_state`, :func:`load_state`).
    """
    mode_fr = flags[FLG_MODE_FR] != 0
    fusion = flags[FLG_FUSION]
    both = flags[FLG_GNSS_ON] != 0 and flags[FLG_DR_ON] != 0
    m_window = max(flags[FLG_WINDOW], 1)
    vec = np.zeros((5, NX))
    mats = np.zeros((3, NX, NX))
    # local filters; per-state shares c_i, d_i = 1/sqrt(c_i): FR keeps
    # P_i = D_i P_g D_i and predicts with Q_i = D_i Q D_i (c_1 + c_2 = 1 per state)
    c0 = 1.0
    if mode_fr and both:
        c0 = min(max(par[PAR_BETA_GNSS], 0.05), 0.95) if fusion == FUSE_COV else 0.5
    for i in range(NX):
        vec[V_X1, i] = x0[i]
        vec[V_X2, i] = x0[i]
        vec[V_XG, i] = x0[i]
        if mode_fr and both:
            vec[V_D1, i] = 1.0 / math.sqrt(c0)
            vec[V_D2, i] = 1.0 / math.sqrt(1.0 - c0)
        else:
            vec[V_D1, i] = 1.0
            vec[V_D2, i] = 1.0
    for i in range(NX):
        for j in range(NX):
            mats[M_P1, i, j] = P0[i, j] * (vec[V_D1, i] * vec[V_D1, j])
            mats[M_P2, i, j] = P0[i, j] * (vec[V_D2, i] * vec[V_D2, j])
            mats[M_PG, i, j] = P0[i, j]
    aux = np.zeros((2, 4))
    aux[A_RFAC, :] = 1.0
    ring = np.zeros((4, m_window))
    pc = np.zeros((2, 4), np.int64)
    sc = np.zeros(N_SCALARS)
    sc[ST_PSI_HINT] = psi0
    sc[ST_EPS_SINCE] = -1.0
    return vec, mats, aux, ring, pc, sc


@njit(cache=True)
def checkpoint_length(m_window: int) -> int:
    """Floats in one checkpoint row (:func:`save_state`) for a residual window of M."""
    return 5 * NX + 3 * NX * NX + 8 + 8 + N_SCALARS + 4 * m_window


def save_state(segment, row, vec, mats, aux, ring, pc, sc):  # hints: _save_checkpoint
    """The state into one float row (the integers of ``pc`` are exact as floats).

    Compiled inside :func:`federated_pass` only, through :func:`_save_checkpoint` (not
    jitted on its own: ``segment``, unused here, selects it at compile time)."""
    m = 0
    for a in range(vec.shape[0]):
        for i in range(NX):
            row[m] = vec[a, i]
            m += 1
    for a in range(mats.shape[0]):
        for i in range(NX):
            for j in range(NX):
                row[m] = mats[a, i, j]
                m += 1
    for a in range(aux.shape[0]):
        for i in range(aux.shape[1]):
            row[m] = aux[a, i]
            m += 1
    for a in range(pc.shape[0]):
        for i in range(pc.shape[1]):
            row[m] = pc[a, i]
            m += 1
    for i in range(sc.shape[0]):
        row[m] = sc[i]
        m += 1
    for a in range(ring.shape[0]):
        for i in range(ring.shape[1]):
            row[m] = ring[a, i]
            m += 1


def load_state(segment, row, vec, mats, aux, ring, pc, sc):  # hints: _load_checkpoint
    """Inverse of :func:`save_state` (compiled the same way, through :func:`_load_checkpoint`)."""
    m = 0
    for a in range(vec.shape[0]):
        for i in range(NX):
            vec[a, i] = row[m]
            m += 1
    for a in range(mats.shape[0]):
        for i in range(NX):
            for j in range(NX):
                mats[a, i, j] = row[m]
                m += 1
    for a in range(aux.shape[0]):
        for i in range(aux.shape[1]):
            aux[a, i] = row[m]
            m += 1
    for a in range(pc.shape[0]):
        for i in range(pc.shape[1]):
            pc[a, i] = np.int64(row[m])
            m += 1
    for i in range(sc.shape[0]):
        sc[i] = row[m]
        m += 1
    for a in range(ring.shape[0]):
        for i in range(ring.shape[1]):
            ring[a, i] = row[m]
            m += 1


# ---- the checkpointed smoother's calls in the pass, typed away without it ----------------
# federated_pass's ``segment`` is an int (checkpointed smoothing) or None (forward only, or
# full storage for smooth_fused).  With None these calls compile to nothing, so a run
# without --smooth does not compile the smoother (smooth_range, rts_step_fused,
# save_state, load_state): numba compiles every call in a function, taken or not.  The
# overloads return the bodies themselves (no wrapper compiled around them); numba matches
# an overload's implementation by its bare argument names, hence no hints on the bodies.


def _segment_length(segment: int | None) -> int:  # pragma: no cover - compiled: the overload
    """Epochs per checkpointed segment; 0 for None."""
    return 0 if segment is None else segment


def _save_checkpoint(segment: int | None, row: np.ndarray, vec: np.ndarray, mats: np.ndarray,
                     aux: np.ndarray, ring: np.ndarray, pc: np.ndarray,
                     sc: np.ndarray) -> None:  # pragma: no cover
    """:func:`save_state`, or nothing when ``segment`` is None."""


def _load_checkpoint(segment: int | None, row: np.ndarray, vec: np.ndarray, mats: np.ndarray,
                     aux: np.ndarray, ring: np.ndarray, pc: np.ndarray,
                     sc: np.ndarray) -> None:  # pragma: no cover
    """:func:`load_state`, or nothing when ``segment`` is None."""


def _smooth_segment(segment: int | None, xs: np.ndarray, Ps: np.ndarray, off: int, k_hi: int,
                    k_lo: int, n: int, dt: np.ndarray, static: np.ndarray, has_gnss: np.ndarray,
                    eps_w: np.ndarray, par: np.ndarray,
                    x_sn: np.ndarray, P_sn: np.ndarray, u_next: np.ndarray, out: np.ndarray,
                    stats: np.ndarray) -> None:  # pragma: no cover
    """:func:`smooth_range`, or nothing when ``segment`` is None."""


@overload(_segment_length)
def _ol_segment_length(segment):
    if isinstance(segment, types.NoneType):
        return lambda segment: 0
    return lambda segment: segment


@overload(_save_checkpoint)
def _ol_save_checkpoint(segment, row, vec, mats, aux, ring, pc, sc):
    if isinstance(segment, types.NoneType):
        return lambda segment, row, vec, mats, aux, ring, pc, sc: None
    return save_state


@overload(_load_checkpoint)
def _ol_load_checkpoint(segment, row, vec, mats, aux, ring, pc, sc):
    if isinstance(segment, types.NoneType):
        return lambda segment, row, vec, mats, aux, ring, pc, sc: None
    return load_state


@overload(_smooth_segment)
def _ol_smooth_segment(segment, xs, Ps, off, k_hi, k_lo, n, dt, static, has_gnss, eps_w, par,
                       x_sn, P_sn, u_next, out, stats):
    if isinstance(segment, types.NoneType):
        return (lambda segment, xs, Ps, off, k_hi, k_lo, n, dt, static, has_gnss, eps_w, par,
                x_sn, P_sn, u_next, out, stats: None)
    return smooth_range


@njit(cache=True)
def store_track(out: np.ndarray, k: int, x: np.ndarray, P: np.ndarray) -> None:
    """Epoch ``k``'s track columns (O_* rows of ``out``) from a state and its covariance."""
    out[O_E, k] = x[IE]
    out[O_N, k] = x[IN]
    out[O_VE, k] = x[IVE]
    out[O_VN, k] = x[IVN]
    out[O_VAR_E, k] = P[IE, IE]
    out[O_VAR_N, k] = P[IN, IN]
    out[O_COV_EN, k] = P[IE, IN]


@njit(cache=True)
def federated_pass(inp: FkfInputs, start: FkfStart, par: np.ndarray, flags: np.ndarray,
                   r_table: np.ndarray, w_table: np.ndarray, segment: int | None):
    """The forward pass of fkf or fafkf (``flags`` from :func:`kernel_flags`) over all epochs.

    Returns ``(out, gnss_used, gnss_rej, nis, beta, rfac, counters, xs, Ps,
    smooth_stats)``; ``out`` (N_OUT, n) holds the track by rows ``O_*``,
    ``beta`` (2, n) the GNSS filter's position and velocity weights, ``rfac``
    (4, n) the R factors (fafkf; (4, 0) without adaptive R).

    With ``flags[FLG_STORE]`` the pass is smoothed:

    * ``segment`` an int > 0: the forward pass keeps a checkpoint of its whole
      state (:func:`save_state`) before every ``segment`` epochs; then, from the last
      segment to the first, it re-runs the segment from its checkpoint -- the
      same code on the same state, so the same floats -- storing the fused x
      and packed P_g of those epochs only, and the backward RTS recursion walks
      them (:func:`smooth_range`), its smoothed state carried from segment to
      segment.  ``out`` then holds the smoothed track and ``smooth_stats`` =
      (epochs whose smoothed P failed the SPD test, restarts).  Cost: one more
      forward pass; memory: ``segment x 65`` floats instead of ``n x 65`` (a
      one-hour drive at 100 Hz: 187 MB -> 2 MB at 4096), as the ekf/aekf
      smoother does (:func:`gpsdr_cli.filters.smoothing.rts_checkpointed`).
    * ``segment`` None: ``xs`` (n, 10), ``Ps`` (n, 55) hold the fused x and
      packed P_g of every epoch, for :func:`smooth_fused`; ``out`` is forward.

    Without ``flags[FLG_STORE]`` pass ``segment = None``: the checkpointed
    smoother's calls then compile to nothing (:func:`_save_checkpoint` ..), so
    a forward-only cold start does not compile the smoother; numba compiles
    one specialisation per type of ``segment`` (None, int64).

    Cold-start compile time, the reasons for the shape of this function:

    * one epoch loop, here: numba links every jitted callee's compiled module
      into each caller and optimises and emits the whole again, so the loop
      in a function of its own (called for the forward segments and again
      for the re-runs) was compiled on its own and once more inside this one.
      The loop runs over jobs instead (the forward segments, then the
      re-runs), each choosing its output arrays.
    * integer arguments of callees as ``np.int64(...)``, not literals (numba
      specialises a callee per literal value); allocations as ``np.zeros``
      with few distinct argument types (each np.full/ones/empty/zeros
      signature is compiled on its own); no slice assignment between arrays
      (:func:`copy_state`).
    """
    dt, has_gnss, gnss_e, gnss_n, gnss_var_e, gnss_var_n, gnss_ve, gnss_vn, theta, dist, t_m, \
        static, eps_w = inp
    x0, P0, psi0 = start
    n = dt.shape[0]
    par = par.copy()                                # its eps slots change per epoch (select_eps)
    store = flags[FLG_STORE] != 0
    adaptive = flags[FLG_ADAPT_R] != 0
    m_window = max(flags[FLG_WINDOW], 1)
    out = np.zeros((N_OUT, n))
    gnss_used = np.zeros(n, np.bool_)
    gnss_rej = np.zeros(n, np.bool_)
    # allocations as np.zeros with few distinct argument types, then filled: numba compiles
    # each np.full/ones/empty/zeros signature on its own (~0.1 s each at a cold start)
    nis_out = np.zeros(n)
    beta_out = np.zeros((2, n))                     # GNSS weight: position, velocity
    rfac_out = np.zeros((4, n if adaptive else 0))  # R factors: gnss e, gnss n, heading, distance
    for k in range(n):
        nis_out[k] = np.nan
        beta_out[0, k] = np.nan
        beta_out[1, k] = np.nan
    for j in range(rfac_out.shape[0]):
        for k in range(rfac_out.shape[1]):
            rfac_out[j, k] = 1.0
    counters = np.zeros(N_COUNTERS, np.int64)
    stats = np.zeros(2, np.int64)
    seg_len = _segment_length(segment)
    full = store and seg_len <= 0
    ns = n if full else 1
    xs = np.zeros((ns, NXS))
    Ps = np.zeros((ns, NPACK))
    checkpoints = store and seg_len > 0
    seg = seg_len if checkpoints else max(n, 1)
    n_ck = (n + seg - 1) // seg if checkpoints else 0
    ck = np.zeros((n_ck, checkpoint_length(m_window)))
    vec, mats, aux, ring, pc, sc = init_state(x0, P0, psi0, par, flags)
    # the scratch of the backward re-runs (empty without checkpoints)
    sg = seg if checkpoints else 0
    o_out = np.zeros((N_OUT, sg))
    o_used = np.zeros(sg, np.bool_)
    o_rej = np.zeros(sg, np.bool_)
    o_nis = np.zeros(sg)
    o_beta = np.zeros((2, sg))
    o_rfac = np.zeros((4, sg if adaptive else 0))   # scratch: the re-runs write it first
    o_counters = np.zeros(N_COUNTERS, np.int64)
    xs_seg = np.zeros((sg, NXS))
    u_next = np.zeros(2)                            # the smoother's jump into a segment's end + 1
    Ps_seg = np.zeros((sg, NPACK))
    x_sn = np.zeros(NX)
    P_sn = np.zeros((NX, NX))

    mode_fr = flags[FLG_MODE_FR] != 0
    fusion = flags[FLG_FUSION]
    log_scale = flags[FLG_NORM] != 0
    gnss_on = flags[FLG_GNSS_ON] != 0
    dr_on = flags[FLG_DR_ON] != 0
    check = flags[FLG_CHECK_SPD] != 0
    both = gnss_on and dr_on
    # FR with one share per filter (all of w equal): see the prediction in the loop
    shared = mode_fr and both and fusion != FUSE_BLOCK
    cov_fusion = shared and (fusion == FUSE_COV or fusion == FUSE_SHARES)
    central = False                                 # set at each epoch before its use
    # integer arguments of callees (components, blocks, state indices) as np.int64(...),
    # not literals: numba compiles a jitted callee once per literal value it is passed
    # (adapt_r four times, block_pe three ...), ~0.5 s each at a cold start
    ones = np.zeros(NX)
    for i in range(NX):
        ones[i] = 1.0

    x1 = vec[V_X1]
    x2 = vec[V_X2]
    xg = vec[V_XG]
    d1 = vec[V_D1]
    d2 = vec[V_D2]
    P1 = mats[M_P1]
    P2 = mats[M_P2]
    Pg = mats[M_PG]
    rfac = aux[A_RFAC]
    u_last = aux[A_ULAST]
    pos = pc[0]
    cnt = pc[1]

    # states each filter contributes to the NR fusion (see the module docstring)
    if mode_fr:
        idx1 = np.array([IE, IVE, IAE, IN, IVN, IAN, IEPS_E, IEPS_N, IQW, IQS])
        idx2 = np.array([IE, IVE, IAE, IN, IVN, IAN, IEPS_E, IEPS_N, IQW, IQS])
    else:
        idx1 = np.array([IE, IVE, IAE, IN, IVN, IAN, IEPS_E, IEPS_N])
        idx2 = np.array([IE, IVE, IAE, IN, IVN, IAN, IQW, IQS])
    k1_ = idx1.shape[0]
    k2_ = idx2.shape[0]
    A1 = np.zeros((k1_, k1_))
    L1 = np.zeros((k1_, k1_))
    B1 = np.zeros((k1_, k1_))
    A2 = np.zeros((k2_, k2_))
    L2 = np.zeros((k2_, k2_))
    B2 = np.zeros((k2_, k2_))
    Y = np.zeros((NX, NX))
    yv = np.zeros(NX)
    L = np.zeros((NX, NX))
    Wk = np.zeros((NX, NX))

    h = np.zeros(NX)
    s = np.zeros(NX)
    kk = np.zeros(NX)
    w = np.zeros(NX)
    y_dist = 0.0
    hph_dist = 0.0

    n_fwd = (n + seg - 1) // seg
    for job in range(n_fwd + n_ck):
        # jobs 0 .. n_fwd - 1: the forward pass, segment by segment; then the
        # backward re-runs, from the last segment to the first
        if job < n_fwd:
            k0 = job * seg
            if checkpoints:
                _save_checkpoint(segment, ck[job], vec, mats, aux, ring, pc, sc)
            p_out, p_used, p_rej, p_nis = out, gnss_used, gnss_rej, nis_out
            p_beta, p_rfac, p_counters = beta_out, rfac_out, counters
            p_off = 0
            p_store = full
            p_xs, p_Ps = xs, Ps
        else:
            k0 = (n_ck - 1 - (job - n_fwd)) * seg
            _load_checkpoint(segment, ck[k0 // seg], vec, mats, aux, ring, pc, sc)
            p_out, p_used, p_rej, p_nis = o_out, o_used, o_rej, o_nis
            p_beta, p_rfac, p_counters = o_beta, o_rfac, o_counters
            p_off = k0
            p_store = True
            p_xs, p_Ps = xs_seg, Ps_seg
        k1 = min(k0 + seg, n)
        t_now = sc[ST_T_NOW]
        t_last_acc = sc[ST_T_LAST_ACC]                   # last accepted GNSS fix
        t_last_dr = sc[ST_T_LAST_DR]                     # last DR update of any kind
        t_last_dist = sc[ST_T_LAST_DIST]                 # last odometer distance or ZUPT update
        t_head_acc = sc[ST_T_HEAD_ACC]                   # last accepted heading
        psi_hint = sc[ST_PSI_HINT]
        n_acc = np.int64(sc[ST_N_ACC])                   # GNSS fixes accepted so far
        rej_share = sc[ST_REJ_SHARE]                     # recent share of gated fixes (EWMA)
        t_last_fix = sc[ST_T_LAST_FIX]
        t_last_vacc = sc[ST_T_LAST_VACC]
        eps_since = sc[ST_EPS_SINCE]
        zupt_sd = par[PAR_ZUPT_SD]
        omin2 = par[PAR_OMEGA_MIN] ** 2
        chi2 = par[PAR_GATE_CHI2]
        tau_rej = par[PAR_GATE_RESET_S] / math.log(2.0)   # all gated for gate_reset_s: share 1/2
        w_eps = -1.0                                    # eps regime in par: none yet (select_eps)

        for kx in range(k0, k1):
            ko = kx - p_off
            T = dt[kx] if kx > 0 else 0.0
            jump_e = 0.0
            jump_n = 0.0
            t_now += T
            st = static[kx]
            if eps_w[kx] != w_eps:                      # the eps model of the step into kx
                w_eps = eps_w[kx]
                select_eps(par, w_eps)
            if shared:
                # FR with one share per filter (fkf, fafkf scalar weights): the local
                # filters are x_g, P_g/c_i after the last reset and D_i = I/sqrt(c_i)
                # commutes with Phi, so Phi (P_g/c_i) Phi^T + Q/c_i = (Phi P_g Phi^T + Q)/c_i:
                # one prediction of the fused state serves both (then each capped)
                if T > 0.0:
                    predict_uncapped(xg, Pg, T, st, par, ones)
                if (has_gnss[kx] and not st and chi2 > 0.0 and n_acc >= par[PAR_GATE_WARMUP]
                        and par[PAR_EPS_GATE_S] > 0.0):
                    # eps gate (as ekf/aekf's bias gate; shared FR only, where the fused
                    # state is the local filters' start): multipath decorrelates as the car
                    # moves; an eps outside the gate of its stationary distribution for
                    # gate_reset_s is not multipath but a position the fixes left (a
                    # reflection that ended): it goes into the position.  Without it a 160-s
                    # reflection left 22 m in eps and the track 22 m from clean fixes for
                    # 80 s (docs/decisions/0062)
                    b2 = xg[IEPS_E] * xg[IEPS_E] + xg[IEPS_N] * xg[IEPS_N]
                    verdict, eps_since = chi2_gate(b2, chi2 * par[PAR_EPS_SD] ** 2, t_now,
                                                   eps_since, par[PAR_EPS_GATE_S],
                                                   RESET_AFTER_FIRST_REJECT, False)
                    if verdict == GATE_RESET:
                        jump_e = xg[IEPS_E]
                        jump_n = xg[IEPS_N]
                        shift_prior(xg, Pg, jump_e, jump_n)
                        p_counters[C_GATE_RESETS] += 1
                s1 = d1[0] * d1[0]
                s2 = d2[0] * d2[0]
                for i in range(NX):
                    x1[i] = xg[i]
                    x2[i] = xg[i]
                    for j in range(NX):
                        P1[i, j] = Pg[i, j] * s1
                        P2[i, j] = Pg[i, j] * s2
                capped1 = cap_variance(P1)
                capped2 = cap_variance(P2)
                # covariance fusion of the two (FR, one share) = the rows of both applied to the
                # predicted fused state: exact in the information form as long as P_i = P_g/c_i
                # held at the prediction (no cap) and every local change was a Kalman row
                central = cov_fusion and not (capped1 or capped2)
            else:
                if gnss_on:
                    predict(x1, P1, T, st, par, d1)
                    if held_step(kx, dt, static, has_gnss, par):
                        held_noise(x1, P1, T, par)
                if dr_on:
                    predict(x2, P2, T, st, par, d2)
            zupt_consider = ZUPT_KEEP_HEADING
            if st:
                p_counters[C_ZUPT] += 1
                if t_now - t_last_acc > par[PAR_GNSS_STALE_S]:
                    zupt_consider = ZUPT_CONSIDER | ZUPT_KEEP_HEADING
                central = False                         # consider rows are no Kalman rows: fuse

            # ---- GNSS local filter -------------------------------------------------------
            if gnss_on:
                if st:
                    zupt_central(x1, P1, xg, Pg, central, zupt_sd, h, s, kk, zupt_consider)
                if has_gnss[kx]:
                    ye = gnss_e[kx] - (x1[IE] + x1[IEPS_E])
                    yn = gnss_n[kx] - (x1[IN] + x1[IEPS_N])
                    s00 = P1[IE, IE] + 2.0 * P1[IE, IEPS_E] + P1[IEPS_E, IEPS_E]
                    s11 = P1[IN, IN] + 2.0 * P1[IN, IEPS_N] + P1[IEPS_N, IEPS_N]
                    s01 = P1[IE, IN] + P1[IE, IEPS_N] + P1[IEPS_E, IN] + P1[IEPS_E, IEPS_N]
                    if adaptive:
                        if adapt_r(np.int64(0), ye, s00 + rfac[0] * gnss_var_e[kx], ring, pos, cnt,
                                   par, r_table, rfac, u_last):
                            p_counters[C_R_ADAPT] += 1
                        if adapt_r(np.int64(1), yn, s11 + rfac[1] * gnss_var_n[kx], ring, pos, cnt,
                                   par, r_table, rfac, u_last):
                            p_counters[C_R_ADAPT] += 1
                    re = rfac[0] * gnss_var_e[kx]
                    rn = rfac[1] * gnss_var_n[kx]
                    nis = nis_2d(ye, yn, s00 + re, s01, s11 + rn)
                    p_nis[ko] = nis
                    # the receiver (Doppler) velocity has its own gate against the predicted
                    # velocity (our choice; docs/decisions/0031): a wrong but plausible speed
                    # or course at 0.2 m/s carried the track away.  Judged with at least
                    # [gnss] velocity_gate_floor_mps; no lock-out either, and taken when the
                    # fix fails its gate too (the state, not the velocity, is off)
                    has_v = par[PAR_GVEL_VAR] > 0.0 and not (math.isnan(gnss_ve[kx])
                                                            or math.isnan(gnss_vn[kx]))
                    vel = has_v
                    if has_v and chi2 > 0.0 and n_acc >= par[PAR_GATE_WARMUP]:
                        rv = max(par[PAR_GVEL_VAR], par[PAR_VGATE_VAR])
                        nis_v = nis_2d(gnss_ve[kx] - x1[IVE], gnss_vn[kx] - x1[IVN],
                                       P1[IVE, IVE] + rv, P1[IVE, IVN], P1[IVN, IVN] + rv)
                        verdict, _ = chi2_gate(nis_v, chi2, t_now, t_last_vacc,
                                               par[PAR_VGATE_RESET_S], RESET_AFTER_LAST_ACCEPT,
                                               nis > chi2)
                        vel = verdict != GATE_FAIL
                    accept = True
                    fix_consider = 0
                    a_rej = math.exp(-(t_now - t_last_fix) / tau_rej) if tau_rej > 0.0 else 0.0
                    t_last_fix = t_now
                    if chi2 > 0.0 and n_acc >= par[PAR_GATE_WARMUP]:
                        # no lock-out: every fix rejected for gate_reset_s, or most of the
                        # recent ones -- the state, not the fixes, is then the outlier
                        verdict, _ = chi2_gate(nis, chi2, t_now, t_last_acc, par[PAR_GATE_RESET_S],
                                               RESET_AFTER_LAST_ACCEPT,
                                               a_rej * rej_share + (1.0 - a_rej) > 0.5)
                        if verdict == GATE_RESET:
                            p_counters[C_GATE_RESETS] += 1
                            # the state, not the fix, is off, but where: the fix says its
                            # position, not its velocity.  As a plain row a 75-m reflection
                            # read after 3 s of gated fixes set 38 m/s on a car standing still
                            # and fkf ran 300 m off (decisions/0080)
                            fix_consider = RESET_CONSIDER
                        elif verdict == GATE_FAIL:
                            accept = False
                    rej_share = a_rej * rej_share + (0.0 if accept else 1.0 - a_rej)
                    if accept:
                        h[:] = 0.0
                        h[IE] = 1.0
                        h[IEPS_E] = 1.0
                        local_and_central_row(x1, P1, xg, Pg, central, h,
                                              gnss_e[kx] - (x1[IE] + x1[IEPS_E]), re, s, kk,
                                              fix_consider)
                        h[:] = 0.0
                        h[IN] = 1.0
                        h[IEPS_N] = 1.0
                        local_and_central_row(x1, P1, xg, Pg, central, h,
                                              gnss_n[kx] - (x1[IN] + x1[IEPS_N]), rn, s, kk,
                                              fix_consider)
                        if vel:
                            # receiver (Doppler) velocity with the accepted fix (our choice)
                            local_and_central_unit(x1, P1, xg, Pg, central, np.int64(IVE),
                                                   gnss_ve[kx] - x1[IVE], par[PAR_GVEL_VAR], s, kk)
                            local_and_central_unit(x1, P1, xg, Pg, central, np.int64(IVN),
                                                   gnss_vn[kx] - x1[IVN], par[PAR_GVEL_VAR], s, kk)
                            p_counters[C_GVEL] += 1
                            t_last_vacc = t_now
                        elif has_v:
                            p_counters[C_GVEL_REJECTED] += 1
                        p_used[ko] = True
                        p_counters[C_GNSS_USED] += 1
                        n_acc += 1
                        t_last_acc = t_now
                    else:
                        p_rej[ko] = True
                        p_counters[C_GNSS_REJECTED] += 1
                if held_step(kx + 1, dt, static, has_gnss, par):
                    # the next step is held (no fix, no gyro or odometer): the white-jerk model
                    # carried the last acceleration on (+3.75 m/s every second after a real
                    # log's last fix); rows a = 0 here, before the step, hold the speed
                    rc = NO_DR_COAST_Q / dt[kx + 1]
                    local_and_central_unit(x1, P1, xg, Pg, central, np.int64(IAE), -x1[IAE],
                                           rc, s, kk, np.int64(HOLD_ACC_ONLY))
                    local_and_central_unit(x1, P1, xg, Pg, central, np.int64(IAN), -x1[IAN],
                                           rc, s, kk, np.int64(HOLD_ACC_ONLY))
                    p_counters[C_COAST] += 1
            else:
                t_last_acc = t_now

            # ---- DR local filter ---------------------------------------------------------
            if dr_on:
                if st:
                    zupt_central(x2, P2, xg, Pg, central, zupt_sd, h, s, kk, zupt_consider)
                    t_last_dr = t_now
                    t_last_dist = t_now
                else:
                    if (par[PAR_COAST_Q] > 0.0 and T > 0.0 and t_now - t_last_dist > par[PAR_DR_STALE_S]
                            and t_now - t_last_acc > par[PAR_GNSS_STALE_S]):
                        # nothing measures the speed (no odometer, GNSS outage): zero-acceleration
                        # rows, information T / q_c per step, keep the constant-acceleration model
                        # from extrapolating the last acceleration through the outage
                        rc = par[PAR_COAST_Q] / T
                        local_and_central_unit(x2, P2, xg, Pg, central, np.int64(IAE), -x2[IAE],
                                               rc, s, kk)
                        local_and_central_unit(x2, P2, xg, Pg, central, np.int64(IAN), -x2[IAN],
                                               rc, s, kk)
                        p_counters[C_COAST] += 1
                    do_head = False
                    do_dist = False
                    if not math.isnan(theta[kx]):
                        psi_hint = theta[kx] - x2[IQW]
                        v2 = x2[IVE] ** 2 + x2[IVN] ** 2
                        var_v2 = (x2[IVE] ** 2 * P2[IVE, IVE] + 2.0 * x2[IVE] * x2[IVN] * P2[IVE, IVN]
                                  + x2[IVN] ** 2 * P2[IVN, IVN])      # v^2 x var(speed)
                        speed_known = t_now - t_last_dist <= par[PAR_DR_STALE_S]
                        if v2 >= omin2 and (speed_known or v2 * v2 >= HEAD_SPEED_SNR2 * var_v2):
                            do_head = True
                        else:
                            p_counters[C_HEADING_SLOW] += 1
                    if not math.isnan(dist[kx]) and t_m[kx] > 0.0:
                        do_dist = True
                    r_head = par[PAR_HEAD_SD] ** 2
                    r_dist = (par[PAR_ODO_SD] * t_m[kx]) ** 2
                    if adaptive:                        # prior residuals, Tang et al. eq. (15)
                        if do_head:
                            pred = heading_row(x2, h)
                            y = wrap_pi(theta[kx] - pred)
                            if adapt_r(np.int64(2), y, hph(P2, h) + rfac[2] * r_head, ring, pos, cnt,
                                       par, r_table, rfac, u_last):
                                p_counters[C_R_ADAPT] += 1
                        if do_dist:
                            pred = distance_row(x2, h, t_m[kx], par[PAR_V_LIN], psi_hint,
                                                not math.isnan(theta[kx]))
                            y_dist = dist[kx] - pred
                            hph_dist = hph(P2, h)
                            y = y_dist
                            if adapt_r(np.int64(3), y, hph_dist + rfac[3] * r_dist, ring, pos, cnt,
                                       par, r_table, rfac, u_last):
                                p_counters[C_R_ADAPT] += 1
                    if do_head:
                        pred = heading_row(x2, h)
                        y = wrap_pi(theta[kx] - pred)
                        rh = rfac[2] * r_head
                        verdict = np.int64(GATE_PASS)
                        if par[PAR_HEAD_CHI2] > 0.0:
                            verdict, _ = chi2_gate(y * y, par[PAR_HEAD_CHI2] * (hph(P2, h) + rh), t_now,
                                                   t_head_acc, par[PAR_GATE_RESET_S],
                                                   RESET_AFTER_LAST_ACCEPT, False)
                        if verdict == GATE_RESET:
                            # every heading rejected for gate_reset_s (e.g. a large gyro
                            # bias outran q_w): re-align, q_w absorbs the discrepancy
                            x2[IQW] += y
                            central = False         # not a Kalman row: fuse the two
                            P2[IQW, IQW] += y * y
                            t_head_acc = t_now
                            p_counters[C_HEAD_REALIGN] += 1
                        elif verdict == GATE_FAIL:
                            p_counters[C_HEAD_REJECTED] += 1
                        else:
                            local_and_central_row(x2, P2, xg, Pg, central, h, y, rh, s, kk)
                            t_head_acc = t_now
                            t_last_dr = t_now
                            p_counters[C_HEADING] += 1
                    if do_dist:
                        if not (adaptive and not do_head):  # else h, y, hPh of the window's row
                            pred = distance_row(x2, h, t_m[kx], par[PAR_V_LIN], psi_hint,
                                                not math.isnan(theta[kx]))
                            y_dist = dist[kx] - pred
                            hph_dist = hph(P2, h)
                        y = y_dist
                        rd = rfac[3] * r_dist
                        if par[PAR_HEAD_CHI2] > 0.0 and y * y > par[PAR_HEAD_CHI2] * (hph_dist + rd):
                            p_counters[C_DIST_REJECTED] += 1      # odometer glitch: gated
                        else:
                            local_and_central_row(x2, P2, xg, Pg, central, h, y, rd, s, kk)
                            t_last_dr = t_now
                            t_last_dist = t_now
                            p_counters[C_DIST] += 1

            # ---- master fusion -----------------------------------------------------------
            g_fresh = t_now - t_last_acc <= par[PAR_GNSS_STALE_S]
            d_fresh = t_now - t_last_dr <= par[PAR_DR_STALE_S]
            if both and not mode_fr and g_fresh != d_fresh:
                # NR: a local filter that has had no measurement for a while (GNSS
                # outage, DR stream gap) contributes nothing -- the GNSS filter's lone
                # extrapolation would otherwise drag the fused track with the weight the
                # fuzzy controller never lets reach 0 (a 10-min gap: 19 km).  FR needs no
                # such rule: a stale filter is reset to x_g every epoch and carries only
                # its share of the common prior.
                p_counters[C_STALE] += 1
                if g_fresh:
                    copy_state(x1, P1, xg, Pg)
                    p_beta[0, ko] = 1.0
                    p_beta[1, ko] = 1.0
                else:
                    copy_state(x2, P2, xg, Pg)
                    p_beta[0, ko] = 0.0
                    p_beta[1, ko] = 0.0
            elif both:
                if fusion == FUSE_COV or fusion == FUSE_SHARES:
                    if fusion == FUSE_SHARES:           # fuzzy reliability -> information share
                        de1n, de2n = normalise_pair(u_last[0] ** 2 + u_last[1] ** 2,
                                                    u_last[2] ** 2 + u_last[3] ** 2, log_scale)
                        bp = fuzzy_beta(pe_scalar(P1, d1[0]), pe_scalar(P2, d2[0]),
                                        de1n, de2n, log_scale, w_table)
                    else:
                        bp = par[PAR_BETA_GNSS]
                    if central:
                        pass                            # xg, Pg: the rows applied centrally
                    elif mode_fr:
                        fuse_two(x1, P1, x2, P2, xg, Pg, Y, L, Wk, yv)
                    else:
                        fuse_information(x1, P1, idx1, x2, P2, idx2, xg, Pg, Y, yv,
                                         A1, L1, B1, A2, L2, B2, L, Wk)
                    if fusion == FUSE_SHARES:
                        p_beta[0, ko] = bp
                        p_beta[1, ko] = bp
                    else:
                        p_beta[0, ko] = 0.5 * (Pg[IE, IE] / max(P1[IE, IE], 1e-300)
                                                 + Pg[IN, IN] / max(P1[IN, IN], 1e-300))
                        p_beta[1, ko] = 0.5 * (Pg[IVE, IVE] / max(P1[IVE, IVE], 1e-300)
                                                 + Pg[IVN, IVN] / max(P1[IVN, IVN], 1e-300))
                    for i in range(NX):
                        w[i] = bp
                else:
                    de1n, de2n = normalise_pair(u_last[0] ** 2 + u_last[1] ** 2,
                                                u_last[2] ** 2 + u_last[3] ** 2, log_scale)
                    if fusion == FUSE_BLOCK:
                        bp = fuzzy_beta(block_pe(P1, d1, np.int64(1)), block_pe(P2, d2, np.int64(1)),
                                        de1n, de2n, log_scale, w_table)
                        bv = fuzzy_beta(block_pe(P1, d1, np.int64(2)), block_pe(P2, d2, np.int64(2)),
                                        de1n, de2n, log_scale, w_table)
                    else:
                        bp = fuzzy_beta(block_pe(P1, d1, np.int64(0)), block_pe(P2, d2, np.int64(0)),
                                        de1n, de2n, log_scale, w_table)
                        bv = bp
                    w[IE] = bp
                    w[IN] = bp
                    w[IVE] = bv
                    w[IAE] = bv
                    w[IVN] = bv
                    w[IAN] = bv
                    if mode_fr:                         # sensor-error states: the block's weight
                        w[IEPS_E] = bp
                        w[IEPS_N] = bp
                        w[IQW] = bv
                        w[IQS] = bv
                    else:                               # NR: from the filter that observes them
                        w[IEPS_E] = 1.0
                        w[IEPS_N] = 1.0
                        w[IQW] = 0.0
                        w[IQS] = 0.0
                    fuse_convex(x1, P1, x2, P2, w, xg, Pg)
                    p_beta[0, ko] = bp
                    p_beta[1, ko] = bv
                if shared:                              # Carlson 1990 fusion-reset, one share:
                    ci = min(max(w[0], 0.05), 0.95)     # x_i, P_i made at the next prediction
                    for i in range(NX):
                        d1[i] = 1.0 / math.sqrt(ci)
                        d2[i] = 1.0 / math.sqrt(1.0 - ci)
                elif mode_fr:                           # Carlson 1990 fusion-reset
                    for i in range(NX):
                        ci = min(max(w[i], 0.05), 0.95)
                        d1[i] = 1.0 / math.sqrt(ci)
                        d2[i] = 1.0 / math.sqrt(1.0 - ci)
                    for i in range(NX):
                        x1[i] = xg[i]
                        x2[i] = xg[i]
                        for j in range(NX):
                            P1[i, j] = Pg[i, j] * d1[i] * d1[j]
                            P2[i, j] = Pg[i, j] * d2[i] * d2[j]
            elif gnss_on:
                copy_state(x1, P1, xg, Pg)
                p_beta[0, ko] = 1.0
                p_beta[1, ko] = 1.0
            elif dr_on:
                copy_state(x2, P2, xg, Pg)
                p_beta[0, ko] = 0.0
                p_beta[1, ko] = 0.0

            if check and ((gnss_on and not is_spd(P1)) or (dr_on and not is_spd(P2))
                          or not is_spd(Pg)):
                p_counters[C_NOT_SPD] += 1
            store_track(p_out, ko, xg, Pg)
            if adaptive:
                for j in range(4):
                    p_rfac[j, ko] = rfac[j]
            if p_store:
                for i in range(NX):
                    p_xs[kx - k0, i] = xg[i]
                p_xs[kx - k0, JUMP_E] = jump_e
                p_xs[kx - k0, JUMP_N] = jump_n
                pack(Pg, p_Ps[kx - k0])
        sc[ST_T_NOW] = t_now
        sc[ST_T_LAST_ACC] = t_last_acc
        sc[ST_T_LAST_DR] = t_last_dr
        sc[ST_T_LAST_DIST] = t_last_dist
        sc[ST_T_HEAD_ACC] = t_head_acc
        sc[ST_PSI_HINT] = psi_hint
        sc[ST_N_ACC] = n_acc
        sc[ST_REJ_SHARE] = rej_share
        sc[ST_T_LAST_FIX] = t_last_fix
        sc[ST_T_LAST_VACC] = t_last_vacc
        sc[ST_EPS_SINCE] = eps_since
        if job >= n_fwd:                            # RTS backward over the segment
            _smooth_segment(segment, xs_seg, Ps_seg, k0, k1 - 1, k0, n, dt, static, has_gnss,
                            eps_w, par, x_sn, P_sn, u_next, out, stats)
    return out, gnss_used, gnss_rej, nis_out, beta_out, rfac_out, counters, xs, Ps, stats


@njit(cache=True)
def kernel_flags(fafkf: bool, flags: np.ndarray) -> np.ndarray:
    """The flags the pass runs with: fkf fuses by covariance with fixed R; fafkf adapts R
    and, unless ``flags[FLG_FUSION]`` names another fusion, weights by fuzzy blocks."""
    flags = flags.copy()
    if fafkf:
        if flags[FLG_FUSION] == FUSE_COV:
            flags[FLG_FUSION] = FUSE_BLOCK
        flags[FLG_ADAPT_R] = 1
    else:
        flags[FLG_FUSION] = FUSE_COV
        flags[FLG_ADAPT_R] = 0
    return flags


@njit(cache=True)
def smooth_fused(xs: np.ndarray, Ps: np.ndarray, dt: np.ndarray, static: np.ndarray,
                 has_gnss: np.ndarray, eps_w: np.ndarray,
                 par: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Fixed-interval RTS smoother over the fused sequence with the master's prediction,
    from the fused x and packed P_g of every epoch (``segment <= 0``: O(n) storage).

    The prior of epoch k+1 is recomputed from the fused posterior of k
    (``Phi(dt[k+1]) x_g``, ``Phi P_g Phi^T + Q``, Q unscaled, plus a held step's velocity
    variance, :func:`held_step` from ``has_gnss``): nothing but the fused x and packed P are
    stored per epoch.  Returns the smoothed outputs
    (rows as the forward ``out``), the count of epochs whose smoothed P
    failed the SPD test and the count of restarts (see :func:`smooth_range`).
    """
    n = xs.shape[0]
    out = np.zeros((N_OUT, n))
    x_sn = np.zeros(NX)
    P_sn = np.zeros((NX, NX))
    stats = np.zeros(2, np.int64)
    _smooth_segment(n, xs, Ps, 0, n - 1, 0, n, dt, static, has_gnss, eps_w, par, x_sn, P_sn,
                    np.zeros(2), out, stats)
    return out, stats[0], stats[1]


def smooth_range(segment, xs, Ps, off, k_hi, k_lo, n, dt, static, has_gnss, eps_w, par, x_sn,
                 P_sn, u_next, out, stats):  # hints: _smooth_segment
    """Backward RTS steps k = k_hi, k_hi - 1, .., k_lo over the fused posteriors
    ``xs[k - off]``, ``Ps[k - off]`` (packed) of an n-epoch pass.

    ``x_sn, P_sn`` enter as the smoothed estimate at k_hi + 1 (ignored when
    k_hi = n - 1: the smoothed estimate there is the filtered one) and leave as
    the one at k_lo; ``u_next`` (2,) likewise: the eps gate's jump at the step into
    k_hi + 1 (columns ``JUMP_E, JUMP_N`` of ``xs``, :func:`shift_prior`), left as the
    one into k_lo; ``out[:, k]`` receives it (rows as the forward ``out``);
    ``stats[0]`` counts epochs whose smoothed position block is not SPD,
    ``stats[1]`` the restarts of the guard below.  Compiled through
    :func:`_smooth_segment` (``segment``, unused here, selects it at compile time).
    """
    par = par.copy()                                # eps slots per step (select_eps)
    x_post = np.zeros(NX)
    P_post = np.zeros((NX, NX))
    x_prior = np.zeros(NX)
    P_prior = np.zeros((NX, NX))
    ones = np.zeros(NX)
    for i in range(NX):
        ones[i] = 1.0
    x_s = np.zeros(NX)
    P_s = np.zeros((NX, NX))
    wL = np.zeros((NX, NX))
    wB = np.zeros((NX, NX))
    dx = np.zeros(NX)
    for k in range(k_hi, k_lo - 1, -1):
        if k == n - 1:
            for i in range(NX):
                x_sn[i] = xs[k - off, i]
            unpack(Ps[k - off], P_sn)
        else:
            for i in range(NX):
                x_post[i] = xs[k - off, i]
            unpack(Ps[k - off], P_post)
            copy_state(x_post, P_post, x_prior, P_prior)
            select_eps(par, eps_w[k + 1])           # the forward pass's model of this step
            predict(x_prior, P_prior, dt[k + 1], static[k + 1], par, ones)
            if held_step(k + 1, dt, static, has_gnss, par):
                held_noise(x_prior, P_prior, dt[k + 1], par)
            if k == k_hi:
                shift_prior(x_prior, P_prior, u_next[0], u_next[1])
            else:
                shift_prior(x_prior, P_prior, xs[k + 1 - off, JUMP_E], xs[k + 1 - off, JUMP_N])
            rts_step_fused(x_post, P_post, x_prior, P_prior, dt[k + 1], static[k + 1],
                           eps_decay(x_post, dt[k + 1], par), x_sn, P_sn, x_s, P_s, wL, wB,
                           dx)
            # guard: the fused sequence is not always a Kalman posterior (stale-filter
            # switches, heading re-alignments, an unmodelled gyro bias); where the
            # smoothed position leaves the forward one by more than the chi-square(2)
            # bound, restart the backward recursion from the forward estimate
            a = P_post[IE, IE]
            b = P_post[IE, IN]
            c = P_post[IN, IN]
            de = x_s[IE] - x_post[IE]
            dn = x_s[IN] - x_post[IN]
            nees = (c * de * de - 2.0 * b * de * dn + a * dn * dn) / (a * c - b * b)
            if nees > SMOOTH_RESTART_NEES or not math.isfinite(nees):
                copy_state(x_post, P_post, x_sn, P_sn)
                stats[1] += 1
            else:
                copy_state(x_s, P_s, x_sn, P_sn)
        store_track(out, k, x_sn, P_sn)
        if not (P_sn[IE, IE] > 0.0 and P_sn[IN, IN] > 0.0
                and P_sn[IE, IN] ** 2 < P_sn[IE, IE] * P_sn[IN, IN]):
            stats[0] += 1
    u_next[0] = xs[k_lo - off, JUMP_E]
    u_next[1] = xs[k_lo - off, JUMP_N]


@njit(cache=True)
def rts_step_fused(x_post: np.ndarray, P_post: np.ndarray, x_prior: np.ndarray,
                   P_prior: np.ndarray, T: float, static: bool, f: float, x_sn: np.ndarray,
                   P_sn: np.ndarray, x_s: np.ndarray, P_s: np.ndarray, L: np.ndarray,
                   B: np.ndarray, dx: np.ndarray) -> None:
    """The RTS step (:func:`~gpsdr_cli.filters.core.rts.rts_step`) with this model's Phi.

    ``B = Phi P_post`` is taken by Phi's rows (:func:`phi_matrix`: ``1, T, T^2/2`` per
    axis, ``f`` for eps): the dense product's other terms are exact zeros, so each
    element is the float :func:`~gpsdr_cli.filters.core.rts.phi_times` gives, in a
    fraction of its time.  ``f``: the eps factor of the step (:func:`eps_decay` at
    ``x_post``); ``L``, ``B`` (10, 10) and ``dx`` (10,) are scratch.
    """
    for i in range(NX):
        for j in range(NX):
            B[i, j] = P_post[i, j]
    if not static:
        h2 = 0.5 * T * T                            # phi_matrix's corner
        for b in range(0, 6, 3):
            for j in range(NX):
                B[b, j] = (P_post[b, j] + T * P_post[b + 1, j]) + h2 * P_post[b + 2, j]
                B[b + 1, j] = P_post[b + 1, j] + T * P_post[b + 2, j]
    for j in range(NX):
        B[IEPS_E, j] = f * P_post[IEPS_E, j]
        B[IEPS_N, j] = f * P_post[IEPS_N, j]
    rts_step(NX, x_post, P_post, B, x_prior, P_prior, x_sn, P_sn, x_s, P_s, L, dx)
