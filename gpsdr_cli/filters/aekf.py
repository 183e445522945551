"""AEKF: Fang et al.'s adaptive EKF on the current statistical model (docs/algorithms.md#aekf).

``run(epochs, params)`` prepares arrays and calls the compiled kernel
:func:`gpsdr_cli.filters.kernels_aekf.cs_filter_kernel`; the same preparation
serves the non-adaptive baseline :mod:`gpsdr_cli.filters.ekf` (``adaptive=False``).

What is adaptive here (``[gnss]``, ``[aekf]``, ``[adaptive]`` in config.py):

- Q: per axis ``sigma_a^2`` from the current acceleration estimate
  (Fang et al. eqs. (14)-(15)) scaled by the regime's K_a;
- R and K_a from PDOP: three regimes (``pdop_mode = "regimes"``: good <
  pdop_good <= medium < pdop_poor <= poor) or ``"continuous"``: log k and log K_a
  interpolated linearly over PDOP through (pdop_good, good),
  ((pdop_good + pdop_poor)/2, medium), (pdop_poor, poor), clamped outside.  The
  base sigma per fix (GST > HDOP x UERE > covariance > default) comes in
  ``epochs.gnss_sd_e/n``; R = (k sigma)^2.  A fix without PDOP uses k_good (its
  base sigma already carries the quality).  Between fixes K_a keeps the last
  GNSS record's regime; inside a GNSS outage (``epochs.gnss_outage``) it is the
  poor regime's ("no fix: DR dominates");
- options for every filter: innovation adaptive factor, fading memory,
  Sage-Husa R, chi-square gate, standstill (ZUPT + held position).

Our choices beyond Fang et al. (``[aekf]``, ``[gnss]``; the benchmark chose the
defaults, ``turn_propagation = false`` and ``gate_mode = "reject"`` give the
earlier behaviour): the gyro turns the velocity and acceleration in the
prediction (heading driven by the gyro in mean and covariance, the drift
observed through the GNSS positions; :func:`kernels_aekf.turn_predict`); the
gate starts after ``gate_warmup_fixes`` accepted fixes and, in ``"inflate"``
mode, accepts a fix above the gate with R scaled by NIS/gate (separate count
``info["gnss_inflated"]``; ``gnss_rejected`` counts hard rejections only);
a drive without any GNSS fix starts the drift at ``gyro.bias_init_sd_dr_radps``.

GNSS error states (``aekf.gnss_err_states``, issue #4, ekf and aekf alike): the fix
error is white noise (the receiver's sigma, R) plus a first-order Gauss-Markov bias per
axis (multipath: ``gnss_err_sd_m``, correlation time ``1/tau = 1/gnss_err_tau_s +
speed/gnss_err_dist_m``), estimated as two more states (kernels_aekf GE_*; exact
10-state Kalman filter and smoother).  A white-noise model fed that error converged
within seconds to a sigma far below its error and then held the offset for minutes
(evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#aekf).  The bias is estimated only
while the velocity is known apart from the fixes (receiver velocity, or a standstill),
else it is a consider state; an estimate outside its stationary gate for
``gnss.gate_reset_s`` while moving goes into the position (the bias gate).  A receiver
that gives positions only (velocity at fewer than ``gnss_err_min_velocity_share`` of the
fixes: GGA without RMC/VTG, a ROS NavSatFix), or one whose velocity the filter is told not
to take (``gnss_velocity = false``), runs without the states
(:func:`gnss_err_states_on`, ``info["gnss_err_states_off"]`` says why): the forward pass
then keeps b as a consider state throughout, which the RTS smoother, estimating b from
both ends, does not follow -- it moved the open-sky track metres off at stops.

Initialisation (our choice, documented in :func:`initial_state`): first usable
GNSS fix; velocity from the receiver's speed/course, else from the next fix,
else unknown (zero with a large variance, odometer row deferred until the
velocity is known); DR-only drives start at e = n = 0 with
``frame.initial_heading_deg`` (NaN: heading 0 with a 180 deg sigma).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..config import Params
from ..epochs import Epochs
from ..errors import ConfigError
from ..models.cs_model import N_STATES
from ..rtk_false_fix import centimetre_fixes
from . import kernels_aekf as kn
from . import register
from .adaptive import gate_threshold
from .base import MAX_SPEED_MPS, FilterResult
from .calibration import known_gyro_bias, known_odo_scale
from .gnss_model import gnss_only_gate_reset_s, pdop_factors, rtk_bias_sd
from .smoothing import rts_checkpointed

#: Speed sigma (m/s) assigned to a velocity taken from the receiver's speed and course.
GNSS_VEL_SD_MPS = 1.0
#: Largest gap (s) between the first two fixes for a velocity by differencing.
INIT_DIFF_MAX_S = 5.0
#: Shortest chord (m) between fixes for a positions-only initial heading (chord_velocity).
CHORD_MIN_M = 5.0
#: Heading sigma (rad) for a DR-only start with a given heading / without one.
DR_HEADING_SD_RAD = math.radians(5.0)
DR_UNKNOWN_HEADING_SD_RAD = math.pi


def gnss_noise(epochs: Epochs, params: Params, adaptive: bool) -> tuple[np.ndarray, np.ndarray,
                                                                      np.ndarray, float]:
    """Per-epoch GNSS variances r_e, r_n (m^2) and K_a, and the constant sigma of the ekf.

    ``adaptive=False`` (ekf): one sigma for the whole drive, the median over the
    fixes of the base sigma ``sqrt((sd_e^2 + sd_n^2)/2)``; K_a = 1 everywhere.  On a drive
    that mixes centimetre (RTK-fixed) fixes with others, the centimetre fixes' median: the
    median of either class would weigh the other wrongly by two orders of magnitude, and
    the others (float, autonomous, centimetre fixes judged false) by their own sigmas:
    the GNSS model tells these apart, and one median of them follows a false fix.
    ``adaptive=True`` (aekf): Fang et al.'s PDOP regimes or their continuous form.
    """
    g = params["gnss"]
    n = len(epochs)
    fix = epochs.has_gnss
    sd_e = np.where(fix, epochs.gnss_sd_e, np.nan)
    sd_n = np.where(fix, epochs.gnss_sd_n, np.nan)
    base = np.sqrt(0.5 * (sd_e ** 2 + sd_n ** 2))
    if fix.any():
        sigma_const = float(np.median(base[fix]))
    else:
        sigma_const = float(g["sigma_default_m"])
    if not adaptive:
        r = np.where(fix, sigma_const ** 2, np.nan)
        cm = centimetre_fixes(epochs, params)
        if cm.any() and (fix & ~cm).any():
            r[cm] = float(np.median(base[cm])) ** 2
            r[fix & ~cm] = base[fix & ~cm] ** 2
        return r, r.copy(), np.ones(n), sigma_const
    k_fix, ka_rec = pdop_factors(epochs.pdop, g)
    r_e = np.where(fix, (k_fix * sd_e) ** 2, np.nan)
    r_n = np.where(fix, (k_fix * sd_n) ** 2, np.nan)
    # K_a: the last GNSS record's regime held forward; poor inside outages
    rec = np.isfinite(epochs.pdop) | fix
    idx = np.where(rec, np.arange(n), -1)
    np.maximum.accumulate(idx, out=idx)
    ka = np.where(idx >= 0, ka_rec[np.maximum(idx, 0)], float(g["ka_good"]))
    ka = np.where(epochs.gnss_outage, float(g["ka_poor"]), ka)
    return r_e, r_n, ka, sigma_const


def start_from_known_calibration(epochs: Epochs, params: Params, x0: np.ndarray,
                                 P0: np.ndarray) -> None:
    """Set the drift state (``x0[6]``, rad/s, ``yaw_true = yaw + eps``) and the odometer scale
    (``x0[7]``, reading = scale x true speed), with their variances in ``P0``, from the known
    calibration (:mod:`.calibration`) where there is one; else leave them."""
    gp = params["graph"]
    bias = known_gyro_bias(epochs, params)
    if bias is not None:
        x0[6] = -bias
        # the drift wanders about its drive's mean by its own stationary sigma
        P0[6, 6] = max(float(gp["gyro_bias_sd_radps"]), float(params["gyro"]["bias_sd_radps"])) ** 2
    scale = known_odo_scale(params)
    if scale is not None:
        x0[7] = 1.0 / scale
        P0[7, 7] = (float(gp["odo_scale_sd"]) / scale ** 2) ** 2


def initial_state(epochs: Epochs, params: Params) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """x0, P0 at epoch 0, the remembered heading psi0 (rad) and whether it is known.

    With GNSS: position of the first usable fix (k0), variance
    ``init_pos_sd^2 + base sigma^2 + d^2`` where d bounds the distance travelled
    before k0 (odometer integral, else MAX_SPEED_MPS x time).  Velocity: receiver
    speed/course at k0 (sigma GNSS_VEL_SD_MPS); else along the chord to a fix far
    enough away (:func:`chord_velocity`); else difference to the next fix within
    INIT_DIFF_MAX_S; else zero with variance ``init_vel_sd^2 + u^2``
    (u the first odometer speed) and the heading unknown.  Our choice: when the
    odometer reading nearest the first fix (within INIT_DIFF_MAX_S) says stopped,
    the velocity is zero (sigma of the zero-velocity update) and the heading
    unknown, whatever the fixes suggest (a first fix 5 m off differenced over
    0.2 s gave a 25 m/s "velocity" and a wrong remembered heading).
    DR-only: e = n = 0 (the frame origin, sigma 1 m), drift sigma
    ``gyro.bias_init_sd_dr_radps``, heading
    ``frame.initial_heading_deg`` with a 5 deg sigma, or 0 with a 180 deg sigma
    when NaN; velocity = first odometer speed along it.
    """
    a = params["aekf"]
    n_ep = len(epochs)
    x0 = np.zeros(N_STATES)
    x0[7] = 1.0
    P0 = np.zeros((N_STATES, N_STATES))
    P0[2, 2] = P0[5, 5] = a["init_acc_sd_mps2"] ** 2
    P0[6, 6] = params["gyro"]["bias_init_sd_radps"] ** 2
    P0[7, 7] = params["odo"]["scale_init_sd"] ** 2
    start_from_known_calibration(epochs, params, x0, P0)
    odo_idx = np.flatnonzero(sensor_masks(epochs, params)[1])
    u0 = float(epochs.odo_speed_mps[odo_idx[0]]) if len(odo_idx) else 0.0
    fixes = np.flatnonzero(epochs.has_gnss)
    if len(fixes):
        k0 = int(fixes[0])
        t_before = (epochs.t_ns[k0] - epochs.t_ns[0]) / 1e9 if n_ep else 0.0
        if len(odo_idx) and k0 > 0:
            before = slice(1, k0 + 1)
            d = float(np.nansum(np.abs(np.where(epochs.has_odo[:k0 + 1], epochs.odo_speed_mps[:k0 + 1],
                                                0.0))[before] * epochs.dt_s[before])) * 1.2
        else:
            # capped as a gap is (aekf.max_gap_s): a larger variance carries no more meaning and
            # costs the first fix its precision in float64 (negative variances, NaN sigma)
            d = MAX_SPEED_MPS * min(t_before, float(a["max_gap_s"]))
        sd = max(float(epochs.gnss_sd_e[k0]), float(epochs.gnss_sd_n[k0]))
        x0[0], x0[3] = epochs.gnss_e[k0], epochs.gnss_n[k0]
        P0[0, 0] = P0[3, 3] = a["init_pos_sd_m"] ** 2 + sd ** 2 + d ** 2
        spd, crs = float(epochs.gnss_speed_mps[k0]), float(epochs.gnss_course_rad[k0])
        omega_min = params["standstill"]["omega_min_speed_mps"]
        st = params["standstill"]
        if len(odo_idx) and st["enabled"]:
            # the odometer reading nearest the first fix: parked there, the velocity is zero
            # whatever two noisy (or one displaced) fixes suggest, and the heading unknown
            j = int(odo_idx[np.argmin(np.abs(epochs.t_ns[odo_idx] - epochs.t_ns[k0]))])
            near = abs(int(epochs.t_ns[j]) - int(epochs.t_ns[k0])) <= INIT_DIFF_MAX_S * 1e9
            if near and float(epochs.odo_speed_mps[j]) < st["speed_mps"]:
                P0[1, 1] = P0[4, 4] = st["zupt_sd_mps"] ** 2 + params["odo"]["noise_sd_mps"] ** 2
                return x0, P0, crs if math.isfinite(crs) else 0.0, False
        if math.isfinite(spd) and math.isfinite(crs):
            x0[1], x0[4] = spd * math.sin(crs), spd * math.cos(crs)
            P0[1, 1] = P0[4, 4] = GNSS_VEL_SD_MPS ** 2
            return x0, P0, crs, spd >= omega_min
        chord = chord_velocity(epochs, fixes, u0 if len(odo_idx) else math.nan, params)
        if chord is not None:
            x0[1], x0[4], P0[1, 1], P0[4, 4], P0[1, 4] = chord
            P0[4, 1] = P0[1, 4]
            return x0, P0, math.atan2(x0[1], x0[4]), math.hypot(x0[1], x0[4]) >= omega_min
        if len(fixes) > 1:
            k1 = int(fixes[1])
            dt1 = (epochs.t_ns[k1] - epochs.t_ns[k0]) / 1e9
            if 0 < dt1 <= INIT_DIFF_MAX_S:
                ve = (epochs.gnss_e[k1] - epochs.gnss_e[k0]) / dt1
                vn = (epochs.gnss_n[k1] - epochs.gnss_n[k0]) / dt1
                sd1 = max(float(epochs.gnss_sd_e[k1]), float(epochs.gnss_sd_n[k1]))
                spd = math.hypot(ve, vn)
                x0[1], x0[4] = ve, vn
                P0[1, 1] = P0[4, 4] = (sd ** 2 + sd1 ** 2) / dt1 ** 2 + GNSS_VEL_SD_MPS ** 2
                return x0, P0, math.atan2(ve, vn), spd >= omega_min and spd > 3 * math.sqrt(
                    sd ** 2 + sd1 ** 2) / dt1
        P0[1, 1] = P0[4, 4] = a["init_vel_sd_mps"] ** 2 + u0 ** 2
        return x0, P0, 0.0, False
    # DR-only: start at the frame origin with the configured heading.  Our choice: the drift
    # prior is gyro.bias_init_sd_dr_radps (no GNSS will ever tell the bias; only standstills
    # do, and a 0.1 rad/s prior made the yaw-rate row feed the gyro into eps, not the heading)
    P0[6, 6] = params["gyro"]["bias_init_sd_dr_radps"] ** 2
    psi = math.radians(params["frame"]["initial_heading_deg"])
    psi_sd = DR_HEADING_SD_RAD
    if not math.isfinite(psi):
        psi, psi_sd = 0.0, DR_UNKNOWN_HEADING_SD_RAD
    P0[0, 0] = P0[3, 3] = 1.0
    s, c = math.sin(psi), math.cos(psi)
    x0[1], x0[4] = u0 * s, u0 * c
    var_along = params["odo"]["noise_sd_mps"] ** 2 + (params["odo"]["scale_init_sd"] * u0) ** 2
    var_cross = (u0 * psi_sd) ** 2 + params["odo"]["noise_sd_mps"] ** 2
    P0[1, 1], P0[4, 4], P0[1, 4] = along_cross_cov(s, c, var_along, var_cross)
    P0[4, 1] = P0[1, 4]
    return x0, P0, psi, True


def along_cross_cov(s: float, c: float, var_along: float, var_cross: float
                    ) -> tuple[float, float, float]:
    """(var_e, var_n, cov_en) of a velocity whose variance is ``var_along`` along the unit
    direction (s, c) = (sin psi, cos psi) and ``var_cross`` across it, (c, -s)."""
    return (var_along * s * s + var_cross * c * c, var_along * c * c + var_cross * s * s,
            (var_along - var_cross) * s * c)


def chord_velocity(epochs: Epochs, fixes: np.ndarray, odo_speed: float, params: Params
                   ) -> tuple[float, float, float, float, float] | None:
    """Initial (v_e, v_n, var_e, var_n, cov_en) of a positions-only start (m/s, m^2/s^2):
    the direction of the chord from the first fix to the first one at least
    ``max(CHORD_MIN_M, 4 sigma)`` away within INIT_DIFF_MAX_S, the speed the odometer's
    (``odo_speed``; NaN: the chord's).  None when no fix is that far in time.

    Differencing the first two fixes of a 10-Hz receiver (0.1 s, 2 m sigma) gave a
    velocity sigma of 40 m/s, which the odometer row then split into the wrong speed and
    odometer scale (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#aekf).  Along the
    chord the variance is the odometer's (or the chord
    speed's), across it ``(speed x heading sigma)^2`` with the heading sigma
    ``sqrt(sd0^2 + sd1^2) / length``.
    """
    k0 = int(fixes[0])
    sd0 = max(float(epochs.gnss_sd_e[k0]), float(epochs.gnss_sd_n[k0]))
    t0 = int(epochs.t_ns[k0])
    for k1 in fixes[1:]:
        dt1 = (int(epochs.t_ns[k1]) - t0) / 1e9
        if dt1 > INIT_DIFF_MAX_S:
            return None
        de = float(epochs.gnss_e[k1] - epochs.gnss_e[k0])
        dn = float(epochs.gnss_n[k1] - epochs.gnss_n[k0])
        length = math.hypot(de, dn)
        sd01 = math.hypot(sd0, max(float(epochs.gnss_sd_e[k1]), float(epochs.gnss_sd_n[k1])))
        if dt1 > 0.0 and length >= max(CHORD_MIN_M, 4.0 * sd01):
            s, c = de / length, dn / length
            if math.isfinite(odo_speed):
                speed = abs(odo_speed)
                var_along = (params["odo"]["noise_sd_mps"] ** 2
                             + (params["odo"]["scale_init_sd"] * speed) ** 2)
            else:
                speed = length / dt1
                var_along = 2.0 * (sd01 / dt1) ** 2 + GNSS_VEL_SD_MPS ** 2
            var_cross = (speed * sd01 / length) ** 2 + GNSS_VEL_SD_MPS ** 2
            return (speed * s, speed * c, *along_cross_cov(s, c, var_along, var_cross))
    return None


def initial_heading_var(x0: np.ndarray, P0: np.ndarray, heading_known: bool,
                        params: Params) -> float:
    """Heading variance (rad^2) the heading floor (``aekf.heading_floor``) starts from.

    Moving (speed >= ``standstill.omega_min_speed_mps``): the cross-track velocity
    variance of P0 over the speed squared; a known heading at rest (a DR-only
    start): the ``frame.initial_heading_deg`` sigma (5 deg, or a uniform heading
    when it is NaN); an unknown heading: 0, no floor until a GNSS fix while
    moving sets it from P.
    """
    if not heading_known:
        return 0.0
    sp = math.hypot(x0[1], x0[4])
    if sp >= params["standstill"]["omega_min_speed_mps"]:
        ce, cn = x0[4] / sp, -x0[1] / sp
        pc = ce * ce * P0[1, 1] + 2.0 * ce * cn * P0[1, 4] + cn * cn * P0[4, 4]
        return min(pc / sp ** 2, kn.VPSI_MAX)
    if math.isfinite(params["frame"]["initial_heading_deg"]):
        return DR_HEADING_SD_RAD ** 2
    return kn.VPSI_MAX


def gnss_velocity(epochs: Epochs, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Receiver velocity (m/s, east and north) where a fix reports speed and course, else NaN."""
    spd, crs = epochs.gnss_speed_mps, epochs.gnss_course_rad
    ok = (epochs.has_gnss & np.isfinite(spd) & np.isfinite(crs)
          & (spd >= params["aekf"]["gnss_velocity_min_mps"]))
    with np.errstate(invalid="ignore"):
        return np.where(ok, spd * np.sin(crs), np.nan), np.where(ok, spd * np.cos(crs), np.nan)


def sensor_masks(epochs: Epochs, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Gyro and odometer readings the filter uses: present, finite and physically plausible.

    Our choice: ``|yaw rate| <= gyro.max_rate_radps`` and ``|speed| <=
    odo.max_speed_mps``; a reading beyond is a glitch (a 100 rad/s gyro spike
    turned the velocity by 5 rad in one 20 Hz step, a 1000 m/s odometer spike
    threw the track kilometres off) and is treated as missing.  A clipping gyro
    (``gyro.saturation_min_count`` readings or more exactly at the largest
    magnitude of the drive, and more there than within 20 % below it: a pile-up
    at the top, which a natural tail, even quantised, does not show) has
    those readings treated as missing too: the filter then turns with the GNSS
    instead of 2.9 deg/s short of a 6 deg/s turn.
    """
    yaw = epochs.yaw_rate_radps
    with np.errstate(invalid="ignore"):
        gyro = epochs.has_gyro & (np.abs(yaw) <= params["gyro"]["max_rate_radps"])
        odo = epochs.has_odo & (np.abs(epochs.odo_speed_mps) <= params["odo"]["max_speed_mps"])
    if gyro.any():
        mag = np.abs(yaw[gyro])
        top = float(mag.max())
        at_top = np.abs(yaw) >= top * (1.0 - 1e-9)
        n_top = np.count_nonzero(at_top & gyro)
        # clipping piles the readings up AT the top; a natural (even quantised) tail thins out
        n_below = np.count_nonzero((mag >= 0.8 * top) & (mag < top * (1.0 - 1e-9)))
        if top > 0.0 and n_top >= params["gyro"]["saturation_min_count"] and n_top > n_below:
            gyro &= ~at_top
    return gyro, odo


def unknown_rate_var(params: Params) -> float:
    """Yaw-rate variance (rad^2/s^2) by which the heading floor grows in a GNSS outage while no
    gyro reading turns the prediction (kernels_aekf PAR_UNKNOWN_W_VAR; 0: the floor stops).

    On a gyro drive the lateral row holds the acceleration's turn part near zero, and without
    a gyro the CS model's manoeuvre variance is sized for straight-line driving: either way a
    turn through the outage (readings clipped, dropped out, or none at all) would be
    predicted straight with a confident heading, and a smoother then moves the drive before
    the outage to meet its end.
    """
    if not params["aekf"]["heading_floor"]:
        return 0.0
    return float(params["gyro"]["unknown_rate_sd_radps"]) ** 2


def kernel_params(params: Params, adaptive: bool, store: bool) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's float parameter vector and integer flags (see kernels_aekf PAR_*/FLG_*)."""
    a, ad, st, g = params["aekf"], params["adaptive"], params["standstill"], params["gnss"]
    gy, od = params["gyro"], params["odo"]
    prm = np.zeros(kn.N_PRM)
    prm[kn.PAR_ALPHA] = 1.0 / a["tau_a_s"]
    prm[kn.PAR_AMAX] = a["a_max_mps2"]
    prm[kn.PAR_AMIN] = a["a_min_mps2"]
    prm[kn.PAR_SIGMA_A] = a["sigma_a_mps2"]
    prm[kn.PAR_TAU_EPS] = gy["bias_tau_s"]
    prm[kn.PAR_Q_EPS] = 2.0 * gy["bias_sd_radps"] ** 2 / gy["bias_tau_s"]  # docs/algorithms.md#cs-model
    prm[kn.PAR_Q_KS] = od["scale_rw_sd"] ** 2
    prm[kn.PAR_R_OMEGA] = gy["noise_sd_radps"] ** 2
    prm[kn.PAR_R_ODO] = od["noise_sd_mps"] ** 2
    prm[kn.PAR_STATIC_SPEED] = st["speed_mps"]
    prm[kn.PAR_R_ZUPT] = st["zupt_sd_mps"] ** 2
    prm[kn.PAR_OMEGA_MIN] = st["omega_min_speed_mps"]
    prm[kn.PAR_GATE_THR] = gate_threshold(g["gate_prob"])
    prm[kn.PAR_GATE_RESET] = g["gate_reset_s"]
    prm[kn.PAR_INNOV_C] = ad["innovation_c"]
    prm[kn.PAR_FADING] = ad["fading_lambda"]
    prm[kn.PAR_SH_B] = ad["sage_husa_b"]
    prm[kn.PAR_SH_RMIN] = ad["sage_husa_r_min"]
    prm[kn.PAR_SH_RMAX] = ad["sage_husa_r_max"]
    prm[kn.PAR_EPS_MEAN_DECAY] = float(a["drift_mean_decay"])
    prm[kn.PAR_GYRO_HOLD] = a["gyro_hold_s"]
    prm[kn.PAR_GATE_INFLATE_MAX] = g["gate_inflate_max"]
    prm[kn.PAR_GATE_WARMUP] = g["gate_warmup_fixes"]
    prm[kn.PAR_GATE_INFLATE_AFTER] = g["gate_inflate_after_s"]
    prm[kn.PAR_MAX_GAP] = a["max_gap_s"]
    prm[kn.PAR_GAP_SPEED] = MAX_SPEED_MPS
    prm[kn.PAR_WH_B] = a["whitening_b"]
    prm[kn.PAR_WH_MAX] = a["whitening_max"]
    prm[kn.PAR_WH_GAP] = a["whitening_gap_s"]
    prm[kn.PAR_WH_NIS] = gate_threshold(a["whitening_nis_prob"])
    prm[kn.PAR_SCALE_VAR] = gy["scale_sd"] ** 2
    prm[kn.PAR_GVEL_VAR] = a["gnss_velocity_sd_mps"] ** 2 if a["gnss_velocity"] else 0.0
    prm[kn.PAR_VGATE_VAR] = g["velocity_gate_floor_mps"] ** 2
    prm[kn.PAR_VGATE_RESET] = g["velocity_gate_reset_s"]
    prm[kn.PAR_HEADING_MIN] = max(st["heading_min_speed_mps"], st["omega_min_speed_mps"])
    prm[kn.PAR_GE_VAR] = a["gnss_err_sd_m"] ** 2
    prm[kn.PAR_GE_RATE] = 1.0 / a["gnss_err_tau_s"]
    prm[kn.PAR_GE_DIST_RATE] = 1.0 / a["gnss_err_dist_m"] if a["gnss_err_dist_m"] > 0.0 else 0.0
    flg = np.zeros(kn.N_FLG, np.int64)
    flg[kn.FLG_ADAPT_Q] = int(adaptive)
    flg[kn.FLG_STANDSTILL] = int(st["enabled"])
    flg[kn.FLG_GATE] = int(g["gate"])
    flg[kn.FLG_INNOV] = int(ad["innovation_factor"])
    flg[kn.FLG_FADING] = int(ad["fading"])
    flg[kn.FLG_SAGE_HUSA] = int(ad["sage_husa"])
    flg[kn.FLG_CHECK_SPD] = int(a["check_spd"])
    flg[kn.FLG_STORE] = int(store)
    flg[kn.FLG_GE] = int(a["gnss_err_states"])
    modes = {"never": 0, "outage": 1, "always": 2}
    if a["drift_consider"] not in modes:
        raise ConfigError(f"aekf.drift_consider = {a['drift_consider']!r}: expected one of "
                          f"{', '.join(modes)}")
    flg[kn.FLG_DRIFT_CONSIDER] = modes[a["drift_consider"]]
    if a["odo_consider"] not in modes:
        raise ConfigError(f"aekf.odo_consider = {a['odo_consider']!r}: expected one of "
                          f"{', '.join(modes)}")
    flg[kn.FLG_ODO_CONSIDER] = modes[a["odo_consider"]]
    flg[kn.FLG_HEADING_CONSIDER] = int(a["heading_consider"])
    flg[kn.FLG_TURN] = int(a["turn_propagation"])
    flg[kn.FLG_ODO_ALONG] = int(a["odo_along_track"])
    flg[kn.FLG_HEADING_FLOOR] = int(a["heading_floor"])
    if a["lateral_acc_only"] not in modes:
        raise ConfigError(f"aekf.lateral_acc_only = {a['lateral_acc_only']!r}: expected one of "
                          f"{', '.join(modes)}")
    flg[kn.FLG_LATERAL_ACC] = modes[a["lateral_acc_only"]]
    flg[kn.FLG_WHITEN] = int(adaptive and a["innovation_whitening"])  # the ekf keeps a fixed R
    if st["zupt_keeps_position"] not in modes:
        raise ConfigError(f"standstill.zupt_keeps_position = {st['zupt_keeps_position']!r}: expected "
                          f"one of {', '.join(modes)}")
    flg[kn.FLG_ZUPT_POS] = modes[st["zupt_keeps_position"]]
    rows = {"skip": kn.OMEGA_SKIP, "lateral": kn.OMEGA_LATERAL}
    if a["turn_omega_row"] not in rows:
        raise ConfigError(f"aekf.turn_omega_row = {a['turn_omega_row']!r}: expected one of "
                          f"{', '.join(rows)}")
    flg[kn.FLG_TURN_OMEGA] = rows[a["turn_omega_row"]]
    gates = {"reject": kn.GATE_REJECT, "inflate": kn.GATE_INFLATE}
    if g["gate_mode"] not in gates:
        raise ConfigError(f"gnss.gate_mode = {g['gate_mode']!r}: expected one of {', '.join(gates)}")
    flg[kn.FLG_GATE_MODE] = gates[g["gate_mode"]]
    return prm, flg


#: Epochs per checkpoint segment of the smoother (memory: one segment of packed P).
SEGMENT_EPOCHS = 4096


def gnss_err_states_on(epochs: Epochs, params: Params) -> bool:
    """Whether the GNSS error states run: ``aekf.gnss_err_states``, and the filter takes the
    receiver's velocity (``aekf.gnss_velocity``) and the receiver gives it at
    ``aekf.gnss_err_min_velocity_share`` of the fixes or more (positions only: the bias and
    the position are told apart by dead reckoning alone; see the key's note).  With the
    velocity logged but not taken, comma2k19's ekf + RTS ran 3.06 m from the reference
    against fixes at 0.54 m."""
    return bool(params["aekf"]["gnss_err_states"]) and not gnss_err_states_off_why(epochs, params)


def gnss_err_states_off_why(epochs: Epochs, params: Params) -> str:
    """Why the receiver's velocity leaves the states off, in a phrase for
    ``info["gnss_err_states_off"]`` ("" when it does not)."""
    a = params["aekf"]
    if not bool(a["gnss_velocity"]):
        return "the receiver's velocity is not used (aekf.gnss_velocity = false)"
    if epochs.velocity_share < a["gnss_err_min_velocity_share"]:
        return (f"the receiver gives its velocity at {epochs.velocity_share:.0%} of the fixes "
                f"(< aekf.gnss_err_min_velocity_share)")
    return ""


def odometer_inputs(epochs: Epochs, params: Params, use_odo: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, int]:
    """The odometer the kernel reads: (records used, speed m/s, records made from the GNSS).

    With an odometer: ``use_odo``, its plausible readings (:func:`sensor_masks`), and speeds.  Without
    one (GNSS and gyro only: a phone, a ROS bag without wheel odometry) nothing told the
    filter that the car stopped: the velocity wandered on the fixes' noise at every stop.
    There the standstill comes from the GNSS as for fkf (:func:`.standstill.standstill_from_gnss`:
    the receiver's Doppler speed under ``[fkf] gnss_standstill_speed_mps`` over
    ``gnss_standstill_window_s``, or with positions only the speed between the median
    positions of the fixes either side, :func:`.standstill.fix_speeds`): a zero-speed record at
    each standstill epoch (the kernel's zero-velocity update and position hold) and a NaN
    record at the first epoch after each (it ends the standstill; the kernel skips the
    speed row of a NaN).  With positions only the forward pass cannot beat the fixes:
    nothing measures the speed in an outage (evidence:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#aekf).
    """
    if (epochs.has_odo.any() or not params["standstill"]["enabled"]
            or epochs.n_gnss < 2):
        return use_odo, epochs.odo_speed_mps, 0
    from .standstill import standstill_from_gnss

    still = standstill_from_gnss(epochs, (epochs.t_ns - epochs.t_ns[0]) / 1e9, params)
    ends = np.zeros(len(still), bool)
    ends[1:] = still[:-1] & ~still[1:]
    return still | ends, np.where(still, 0.0, np.nan), int(np.count_nonzero(still))


def coast_psd(epochs: Epochs, params: Params) -> float:
    """``aekf.coast_acc_psd`` (m^2/s^3); the kernel coasts only while the odometer is
    silent (a drive without one, or one that dropped out, ``kernels_aekf.STALE_ODO_S``).

    Coasting: in a GNSS outage with nothing measuring the speed, the kernel takes
    zero-acceleration rows ``a_e = a_n = 0`` with ``r = q_c / T`` (kernels_aekf step 3).
    The current statistical model's mean keeps the last acceleration estimate, so without
    them a drive-off or a braking carried on through the outage.  A drive without a gyro or
    odometer holds its outages instead (:func:`no_dr_hold`).
    """
    return max(float(params["aekf"]["coast_acc_psd"]), 0.0)


def no_dr_hold(epochs: Epochs, params: Params) -> tuple[float, float]:
    """``(1, aekf.no_dr_vel_psd)`` on a GNSS-only drive (no gyro or odometer record), else
    ``(0, 0)``: the kernel's GNSS outages of such a drive are held.

    Nothing measures the motion there, and the current statistical model's mean carried the
    last acceleration on (coast_acc_psd only slowed it: a real receiver log's no-fix records
    after its last fix took the speed from 1.9 to 13.3 m/s in a minute).  Before each step
    into the outage the kernel takes rows ``a = 0`` (``core.update.NO_DR_COAST_Q``), and the
    velocity's variance grows by ``no_dr_vel_psd`` (m^2/s^3) x T per axis instead.
    """
    if epochs.has_gyro.any() or epochs.has_odo.any():
        return 0.0, 0.0
    return 1.0, max(float(params["aekf"]["no_dr_vel_psd"]), 0.0)


def drive_off_var(params: Params) -> tuple[float, float]:
    """Variances (m^2/s^2, m^2/s^4) added to v_e, v_n and a_e, a_n where a standstill ends
    (``aekf.drive_off_speed_sd_mps``, ``drive_off_acc_sd_mps2``; the kernel's step 3).

    The zero-velocity updates of a stop leave the velocity and acceleration known to mm/s
    and the current statistical model's acceleration variance regrows slowly from a = 0,
    but the record that ends the stop says the car moves off, at an acceleration nothing
    has measured yet.  Without an odometer (a standstill from the GNSS) only the receiver's
    Doppler velocity, from ``gnss_velocity_min_mps`` up, and the fixes then measured it: the
    forward speed ran behind for seconds and the fixes' displacement went into the GNSS
    error states (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#aekf).
    """
    a = params["aekf"]
    return (max(float(a["drive_off_speed_sd_mps"]), 0.0) ** 2,
            max(float(a["drive_off_acc_sd_mps2"]), 0.0) ** 2)


def bias_variance(epochs: Epochs, params: Params) -> np.ndarray:
    """Per epoch, the stationary variance (m^2) of the GNSS error states b: on an RTK drive
    its fix kind's regime (:func:`~gpsdr_cli.filters.gnss_model.rtk_bias_sd`; the kernel
    starts a new, independent b where it changes), else ``aekf.gnss_err_sd_m`` squared."""
    sd = rtk_bias_sd(epochs, params)
    if sd is None:
        return np.full(len(epochs), float(params["aekf"]["gnss_err_sd_m"]) ** 2)
    return sd ** 2


def run_cs(epochs: Epochs, params: Params, *, adaptive: bool, name: str) -> FilterResult:
    """Forward pass (and RTS when ``params["filter"]["smooth"]``) of the CS-model filter."""
    n = len(epochs)
    ge_wanted = bool(params["aekf"]["gnss_err_states"])
    ge_off_why = gnss_err_states_off_why(epochs, params) if ge_wanted else ""
    if ge_off_why:
        params = {**params, "aekf": {**params["aekf"], "gnss_err_states": False}}
    smooth = bool(params["filter"]["smooth"])
    r_e, r_n, ka, sigma_const = gnss_noise(epochs, params, adaptive)
    x0, P0, psi0, heading_known = initial_state(epochs, params)
    prm, flg = kernel_params(params, adaptive, smooth)
    prm[kn.PAR_COAST_Q] = coast_psd(epochs, params)
    prm[kn.PAR_NO_DR], prm[kn.PAR_NO_DR_VEL_Q] = no_dr_hold(epochs, params)
    if prm[kn.PAR_NO_DR] > 0.0:
        # GNSS only: the motion model alone judges the fixes, and fixes gated for seconds
        # mean the state ran off (with a gyro the turn is measured, and on simulated city
        # drives a shorter reset let reflected runs in)
        prm[kn.PAR_GATE_RESET] = gnss_only_gate_reset_s(params)  # at most gate_reset_s
    prm[kn.PAR_UNKNOWN_W_VAR] = unknown_rate_var(params)
    prm[kn.PAR_OFF_VVAR], prm[kn.PAR_OFF_AVAR] = drive_off_var(params)
    st = np.zeros(kn.N_ST)
    st[kn.ST_PSI] = psi0
    st[kn.ST_REJ_SINCE] = -1.0
    st[kn.ST_VREJ_SINCE] = -1.0
    st[kn.ST_SH_R] = 1.0
    st[kn.ST_HEADING_KNOWN] = float(heading_known)
    st[kn.ST_W] = 0.0
    st[kn.ST_W_T] = -math.inf  # no gyro rate held yet
    st[kn.ST_FIX_T] = -math.inf  # no fix used yet
    st[kn.ST_ODO_T] = -math.inf  # no odometer record yet
    st[kn.ST_VPSI] = initial_heading_var(x0, P0, heading_known, params)
    st[kn.ST_WH_T] = -math.inf  # no previous innovation yet
    st[kn.ST_WH_T2] = -math.inf
    st[kn.ST_B_SINCE] = -1.0  # the bias gate's timer: not running
    ge_var = (bias_variance(epochs, params) if params["aekf"]["gnss_err_states"]
              else np.zeros(0))
    st[kn.ST_GE_VAR] = ge_var[0] if len(ge_var) else prm[kn.PAR_GE_VAR]
    f64 = np.float64
    x_out = np.empty((N_STATES, n))  # rows: contiguous track columns, no copies
    pcov = np.empty((3, n))
    sd = np.empty((2, n))
    gnss_used = np.zeros(n, bool)
    gnss_rej = np.zeros(n, bool)
    nis = np.empty(n)
    static = np.zeros(n, bool)
    hold = np.zeros(n, bool)
    seg = min(SEGMENT_EPOCHS, max(n, 1))
    P_seg = np.empty((seg if smooth else 0, kn.N_PACKED + kn.N_GE_PACKED))
    prior_store = np.empty((n if smooth else 0, kn.N_PRIOR))
    info_v = np.zeros(kn.N_INFO)
    info_v[kn.INF_MIN_DIAG] = math.inf
    c64 = np.ascontiguousarray  # no copies of the (already contiguous) inputs: memory
    use_gyro, use_odo = sensor_masks(epochs, params)
    use_odo, odo_speed, gnss_still = odometer_inputs(epochs, params, use_odo)
    gv_e, gv_n = gnss_velocity(epochs, params)
    inputs = kn.CsInputs(
        c64(epochs.dt_s, f64), c64(epochs.has_gnss, bool), c64(epochs.gnss_e, f64),
        c64(epochs.gnss_n, f64), c64(r_e, f64), c64(r_n, f64), c64(ka, f64),
        c64(use_gyro, bool), c64(epochs.yaw_rate_radps, f64), c64(use_odo, bool),
        c64(odo_speed, f64), c64(epochs.gnss_outage, bool), gv_e, gv_n, ge_var)
    del r_e, r_n, ka

    opts = kn.kernel_options(flg)
    wk = np.zeros((5, N_STATES))
    b_out = np.zeros((2, n))  # GNSS error states (aekf.gnss_err_states), zero when off
    ge = initial_gnss_err(params, st[kn.ST_GE_VAR])
    gw = np.zeros((kn.GW_ROWS, N_STATES))  # its work rows
    outputs = kn.CsOutputs(x_out, pcov, gnss_used, gnss_rej, nis, static, hold, sd, b_out)

    def run_segment(k0: int, k1: int, x: np.ndarray, P: np.ndarray, s: np.ndarray,
                    g: np.ndarray, P_buf: np.ndarray, counters: np.ndarray | None = None) -> None:
        kn.cs_filter_kernel(inputs, kn.CsState(x, P, s, g), k0, k1, k0, prm, flg, outputs,
                            kn.CsStore(P_buf, prior_store),
                            np.zeros(kn.N_INFO) if counters is None else counters, wk, gw, **opts)

    x, P = x0.copy(), P0.copy()
    checkpoints: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    if n and not smooth:
        run_segment(0, n, x, P, st, ge, P_seg, info_v)
    elif n:
        for k0 in range(0, n, seg):
            k1 = min(k0 + seg, n)
            checkpoints.append((k0, k1, x.copy(), P.copy(), st.copy(), ge.copy()))
            run_segment(k0, k1, x, P, st, ge, P_seg, info_v)
    info = {
        "filter": name,
        "gnss_rejected": int(gnss_rej.sum()),
        "gnss_used": int(gnss_used.sum()),
        "gate_resets": int(info_v[kn.INF_GATE_RESETS]),
        "gnss_inflated": int(info_v[kn.INF_INFLATED]),
        "gnss_velocity_gated": int(info_v[kn.INF_VEL_GATED]),
        "gyro_implausible": int(np.count_nonzero(epochs.has_gyro & ~use_gyro)),  # incl. clipped
        "odo_implausible": int(np.count_nonzero(epochs.has_odo & ~use_odo)),
        "updates_skipped": int(info_v[kn.INF_SKIPPED]),
        "nonfinite_states": int(info_v[kn.INF_NONFINITE]),
        "min_p_diag": float(info_v[kn.INF_MIN_DIAG]) if n else math.nan,
        "spd_checked": bool(params["aekf"]["check_spd"]),
        "spd_failures": int(info_v[kn.INF_SPD_FAIL]),
        "smoothed": smooth,
        "ekf_gnss_sigma_m": sigma_const,
        "gnss_err_states": bool(params["aekf"]["gnss_err_states"]),
        "gnss_standstill_epochs": gnss_still,
        "coast_epochs": int(np.count_nonzero(epochs.gnss_outage & ~static & (epochs.dt_s > 0.0)))
        if prm[kn.PAR_COAST_Q] > 0.0 and not epochs.has_odo.any() else 0,
    }
    if ge_off_why:
        info["gnss_err_states_off"] = ge_off_why
    if smooth and n:
        rts_checkpointed(run_segment, checkpoints, epochs.dt_s, hold, prm, x_out, prior_store,
                         pcov, sd, P_seg, b_out, bool(flg[kn.FLG_GE]))
    del P_seg, checkpoints
    return _result(epochs, x_out, pcov, sd, gnss_used, gnss_rej, nis, static, info, b_out)


def compile_parts(params: Params, adaptive: bool) -> tuple[Callable[[], None], ...]:
    """Parts of the compile of :func:`run_cs`'s kernel that two processes can share.

    The cold start (:mod:`gpsdr_cli.warmup`): numba's compile of the kernel and its
    callees is ~7 s of CPU, and the kernel needs every callee compiled first.  Each part
    runs its functions once on placeholder values with exactly the argument types
    :func:`run_cs` gives them (the same options from ``params``), so numba compiles, or
    loads from its cache, the specialisations the kernel then uses.  In order:

    [0] ``unit_update``, which both halves call (before the fork: once);
    [1] (helper) the GNSS fix's helpers ``nis_2d``, ``ge_fix_update``, ``ge_push``;
    [2] (helper, once [3] is done) :func:`kernels_aekf.gnss_fix
    <gpsdr_cli.filters.kernels_aekf.gnss_fix>`, which loads [3]'s ``ge_epoch`` from the
    cache;
    [3] ``ge_epoch``; [4] what only the kernel's 100-Hz path calls (``predict_cov``,
    ``turn_predict``, ``ge_turn``, ``sparse_update``, ``pack``).

    The kernel, compiled after all of them where [3] and [4] ran, finds them compiled in
    its process or in the cache.  A type that drifted from the kernel's only costs time
    (tests/test_warmup.py checks that nothing is compiled twice).
    """
    prm, flg = kernel_params(params, adaptive, bool(params["filter"]["smooth"]))
    opts = kn.kernel_options(flg)
    ge0 = initial_gnss_err(params)
    ge_on = "ge_on" in opts
    no_cons = np.int64(0)

    def state() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return (np.zeros(N_STATES), np.eye(N_STATES), np.zeros((5, N_STATES)),
                np.zeros((kn.GW_ROWS, N_STATES)), ge0.copy())

    def shared() -> None:
        x, P, wk, _, _ = state()
        kn.unit_update(x, P, no_cons, 0.0, 1.0, 1.0, wk[1], wk[2], no_cons)

    def fix_helpers() -> None:
        x, P, wk, gw, ge = state()
        kn.nis_2d(0.0, 0.0, 1.0, 0.0, 1.0)
        if ge_on:
            kn.ge_fix_update(x, P, ge, 0.0, 0.0, 1.0, 1.0, wk[1], False)
            kn.ge_push(gw, no_cons, 1.0, wk[0], wk[2], 1.0, 0.0)

    def fix() -> None:
        x, P, wk, gw, ge = state()
        kn.gnss_fix(1.0, 1.0, 1.0, 1.0, math.nan, math.nan, x, P, np.zeros(kn.N_ST), prm, ge, gw,
                    wk, np.zeros(kn.N_INFO), 0.0, False, False, bool(flg[kn.FLG_GATE]), False, 0.0,
                    0.0, *(opts.get(k) for k in ("innov_on", "sage_on", "whiten_off",
                                                 "inflate_on", "ge_on")))

    def block() -> None:
        _, _, _, gw, ge = state()
        if ge_on:
            kn.ge_epoch(ge, gw, no_cons, False, prm[kn.PAR_ALPHA], prm[kn.PAR_GE_VAR])

    def dr_helpers() -> None:
        x, P, wk, gw, _ = state()
        kn.predict_cov(P, 0.01, prm[kn.PAR_ALPHA], 1.0, 1.0, 1.0, prm[kn.PAR_Q_EPS], prm[kn.PAR_Q_KS],
                       1.0, False, wk[4])
        kn.turn_predict(x, P, 0.01, 0.0, prm[kn.PAR_R_OMEGA])  # compiled with turn_off too
        if ge_on:
            kn.ge_turn(gw, x, 0.01, 0.0)
        nz = kn.NZ_ODO.copy()
        nz.flags.writeable = False  # a global array is read-only in the kernel: the same type
        kn.sparse_update(x, P, wk[0], nz, 0.0, 1.0, 1.0, wk[1], wk[2], 0, 0.0, 0.0)
        if "store_on" in opts:
            kn.pack(P, np.zeros((1, kn.N_PACKED + kn.N_GE_PACKED))[0])

    return shared, fix_helpers, fix, block, dr_helpers


def initial_gnss_err(params: Params, var: float | None = None) -> np.ndarray:
    """The GNSS error block at epoch 0 (kernels_aekf GE_*): b = 0 with its stationary variance,
    ``var`` (m^2; the first epoch's regime, :func:`bias_variance`), else ``gnss_err_sd_m``'s.

    ``aekf.gnss_err_states`` off: an empty array (the kernel does not touch it).
    """
    a = params["aekf"]
    if not a["gnss_err_states"]:
        return np.zeros(0)
    ge = np.zeros(kn.N_GE)
    ge[kn.GE_PEE] = ge[kn.GE_PNN] = a["gnss_err_sd_m"] ** 2 if var is None else var
    return ge


def _result(epochs: Epochs, x: np.ndarray, pcov: np.ndarray, sd: np.ndarray,
            gnss_used: np.ndarray, gnss_rej: np.ndarray, nis: np.ndarray, static: np.ndarray,
            info: dict, b: np.ndarray) -> FilterResult:
    """FilterResult over row views of x (8, n), pcov (3, n), sd (2, n), b (2, n): no copies."""
    extras = {
        "gnss_err_e": b[0], "gnss_err_n": b[1],
        "a_e": x[2], "a_n": x[5],
        # the drift state eps is in d(psi)/dt = -yaw_rate; report the bias of the gyro reading
        "gyro_bias_radps": -x[6], "odo_scale": x[7],
        "gyro_bias_sd_radps": sd[0], "odo_scale_sd": sd[1],
    }
    return FilterResult(t_ns=epochs.t_ns, e=x[0], n=x[3], v_e=x[1], v_n=x[4], var_e=pcov[0],
                        var_n=pcov[1], cov_en=pcov[2], gnss_used=gnss_used,
                        gnss_rejected=gnss_rej, nis=nis, static=static, extras=extras, info=info)


@register("aekf")
def run(epochs: Epochs, params: Params) -> FilterResult:
    """Fang et al. AEKF (adaptive Q from the acceleration, PDOP-driven R and K_a) with options."""
    return run_cs(epochs, params, adaptive=True, name="aekf")
