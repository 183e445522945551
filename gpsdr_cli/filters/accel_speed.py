"""The speed through the GNSS outages of drives without an odometer: the forward
accelerometer's, else the last fixes'.

A drive with a gyro and no odometer has nothing that measures the speed while the fixes are
out.  The filters' current statistical model carried the last acceleration estimate on
(its mean is ``abar = a_hat``; the coasting rows, ``coast_acc_psd``, only slow it), and
through a 15-s outage that turned a passing acceleration into metres per second of speed,
the wrong way while the car braked; a car that brakes to a stop or drives off inside the
outage ends it far off whatever holds the speed (evidence:
docs/decisions/0015-evidence-behind-the-filter-choices.md#accel-speed).  A
forward accelerometer (``acc_x``, or ``sensor_msgs/Imu`` linear_acceleration.x) measures the
speed change.

:func:`speed_track` runs a small Kalman filter forward in time over the epochs, state
``[s, v, b, c]``: the distance driven since the last used fix (m), the horizontal speed (m/s),
the reading's offset (m/s^2) and the offset's rate of change along the road (m/s^2 per m).
The reading drives the prediction, ``dv/dt = a_meas - b``, and the receiver's Doppler speed
updates it at every fix, so ``b`` and ``c`` are estimated against the GNSS speed up to the
last fix before an outage.

Gravity: on a slope of pitch theta the accelerometer also reads ``g sin(theta)`` (0.98 m/s^2
at 10 %).  Nothing on a car with a yaw gyro and a forward accelerometer measures the pitch, so
``b`` is the sensor's bias *plus* ``g sin(theta)`` of the road under the car.  The grade
changes along the road, not in time (and not while parked): roads are built as straight
grades joined by parabolic vertical curves, along which the grade changes at a constant rate
per metre, so ``db/ds = c`` with ``c`` a random walk in the distance driven
(``grade_rate_rw_var_per_m``), beside a random walk of ``b`` itself per metre
(``grade_rw_var_m2ps4_per_m``) and the bias's slow wander in time (``bias_rw_var_m2ps5``).
At each fix the Doppler speed pins ``b`` down; through an outage the grade rate learnt before
it is extrapolated and the variances grow with the distance driven: the reported
along-track sigma is that of the distance (conservative: the random walks are sized for
vertical curves of ~100 m).

:func:`bridge_outages` replaces the forward filter's track inside each GNSS outage of a drive
with a gyro and no odometer: from the filter's position at the last used fix, the distance
driven along the gyro's heading (the filter's velocity heading where it last moved at >=
``heading_min_speed_mps``, then the yaw rate less the filter's gyro-bias estimate, or the
mean rate at the standstills so far).  The distance is :func:`speed_track`'s where the
accelerometer covers the outage, else :func:`held_speed`'s: the last fix's Doppler speed
plus the acceleration the last second of fixes showed, decaying over a few seconds (a
manoeuvre is short; what the current statistical model should predict with nothing
measuring the speed).  The across-track variance stays the filter's, the along-track one is
the fix's plus the distance's.  A smoothed track is bridged too (``smoothed``): the same
[s, v, b, c] model is smoothed over the outage (Rauch-Tung-Striebel, :func:`_outage_rts`)
with the distance to the outage's first fix along the track and that fix's Doppler speed
as its last measurements, so an offset error shows in the speed profile it belongs to (a
speed error growing in time), and what misclosure is left (across the track: the gyro's
heading) is spread back over the outage.  The speed stays >= 0 (a braking car stops, it
does not reverse).  The filters' own state is not touched: each resumes at the outage's
first fix as before, so the bridge changes the track's outage epochs and nothing else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..angles import unwrap_across_gaps
from ..config import Params
from ..conventions import NS_PER_S
from ..epochs import Epochs
from .base import FilterResult

#: a fix's Doppler speed below this (m/s) is a standstill (the gyro's rest rate is its bias)
STANDSTILL_MPS = 0.1
#: the accelerometer's last reading older than this (s) leaves an epoch uncovered
MAX_ACCEL_AGE_S = 0.5
#: the gyro bias against the fixes' course (:func:`course_gyro_bias`): courses at this speed
#: or more (m/s) over the last COURSE_WINDOW_S, at least COURSE_MIN_FIXES spanning
#: COURSE_MIN_SPAN_S
COURSE_MIN_MPS = 3.0
COURSE_WINDOW_S = 60.0
COURSE_MIN_FIXES = 8
COURSE_MIN_SPAN_S = 10.0


@dataclass
class SpeedTrack:
    """Per epoch (after the epoch's update): ``v_mps`` speed, ``v_var`` its variance (m^2/s^2),
    ``s_m`` distance since the last used fix, ``s_var`` its variance (m^2), ``b_mps2`` the
    offset (bias + g sin(pitch)) and ``covered`` (an accelerometer reading within
    MAX_ACCEL_AGE_S); ``acc_mps2``: the reading held at each epoch (NaN where none is that
    recent); ``x_keep``, ``P_keep``: the whole state [s, v, b, c] and its covariance after
    each epoch :func:`speed_track` was asked to keep, in order."""

    v_mps: np.ndarray
    v_var: np.ndarray
    s_m: np.ndarray
    s_var: np.ndarray
    b_mps2: np.ndarray
    covered: np.ndarray
    acc_mps2: np.ndarray
    x_keep: np.ndarray
    P_keep: np.ndarray


@njit(cache=True, error_model="numpy")
def _predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, T: float, acc: float,
             prm: np.ndarray, stop_jacobian: bool = False) -> np.ndarray:
    """One step of T seconds of the [s, v, b, c] model in place (``acc`` the held reading, NaN:
    none); ``F`` is set to the step's Jacobian.  Returns the new P (module docstring).
    ``stop_jacobian``: where the speed stops at 0, F says so (the speed then depends on
    neither the last speed nor the offset; the smoother's pass back must not move a stopped
    car); the forward filter keeps the unclamped one."""
    q_a, q_bt, q_bs, q_c = prm[3], prm[4], prm[5], prm[6]
    a = acc if math.isfinite(acc) else x[2]  # no reading: no speed change
    v0 = x[1]
    v_free = v0 + (a - x[2]) * T
    v1 = max(v_free, 0.0)
    ds = 0.5 * (v0 + v1) * T
    x[0] += ds
    x[1] = v1
    x[2] += x[3] * ds        # the grade changes along the road (a vertical curve)
    if stop_jacobian and v_free < 0.0:
        F[0, 1] = 0.5 * T
        F[0, 2] = 0.0
        F[1, 1] = 0.0
        F[1, 2] = 0.0
    else:
        F[0, 1] = T
        F[0, 2] = -0.5 * T * T
        F[1, 2] = -T
    F[2, 3] = ds
    P = F @ P @ F.T
    P[0, 0] += q_a * T * T * T / 3.0
    P[0, 1] += q_a * T * T / 2.0
    P[1, 0] += q_a * T * T / 2.0
    P[1, 1] += q_a * T
    P[2, 2] += q_bt * T + q_bs * ds
    P[3, 3] += q_c * ds
    return P


@njit(cache=True, error_model="numpy")
def _speed_kf(dt: np.ndarray, acc: np.ndarray, z: np.ndarray, anchor: np.ndarray,
              prm: np.ndarray, v_out: np.ndarray, vv_out: np.ndarray, s_out: np.ndarray,
              ss_out: np.ndarray, b_out: np.ndarray, keep: np.ndarray, x_keep: np.ndarray,
              P_keep: np.ndarray) -> None:
    """The [s, v, b, c] filter (module docstring): ``acc`` the held reading (NaN: none yet),
    ``z`` the Doppler speed (NaN: none), ``anchor`` where s restarts from 0 (used fixes).
    ``prm``: initial sds of the speed, the offset and the grade rate; the white-acceleration
    PSD (m^2/s^3); the offset's random walk per s and per m; the grade rate's per m; the
    Doppler speed's variance (m^2/s^2).  The whole state and covariance after the epochs
    marked ``keep`` go to ``x_keep`` and ``P_keep`` in order (the smoothed outages start there)."""
    r_v = prm[7]
    x = np.zeros(4)          # s, v, b, c
    P = np.zeros((4, 4))
    P[1, 1] = prm[0] * prm[0]
    P[2, 2] = prm[1] * prm[1]
    P[3, 3] = prm[2] * prm[2]
    F = np.eye(4)
    started = False
    i_keep = 0
    for k in range(len(dt)):
        T = dt[k]
        if started and T > 0.0:
            P = _predict(x, P, F, T, acc[k], prm)
        if math.isfinite(z[k]):
            if not started:  # the first Doppler speed starts the filter
                x[1] = z[k]
                P[1, 1] = r_v
                started = True
            else:
                S = P[1, 1] + r_v
                y = z[k] - x[1]
                K = P[:, 1] / S
                x += K * y
                x[1] = max(x[1], 0.0)
                P = P - np.outer(K, P[1, :])
                P = 0.5 * (P + P.T)
        if anchor[k]:
            x[0] = 0.0
            P[0, :] = 0.0
            P[:, 0] = 0.0
        v_out[k] = x[1]
        vv_out[k] = P[1, 1]
        s_out[k] = x[0]
        ss_out[k] = P[0, 0]
        b_out[k] = x[2]
        if keep[k]:
            x_keep[i_keep] = x
            P_keep[i_keep] = P
            i_keep += 1


@njit(cache=True, error_model="numpy")
def _measure(x: np.ndarray, P: np.ndarray, row: int, z: float, r: float) -> np.ndarray:
    """State ``row`` measured as ``z`` with variance ``r`` (x in place; returns the new P)."""
    if not (math.isfinite(z) and r > 0.0):
        return P
    K = P[:, row] / (P[row, row] + r)
    x += K * (z - x[row])
    P = P - np.outer(K, P[row, :])
    return 0.5 * (P + P.T)


#: the outage smoother relinearises about its own answer this many times at most, until its
#: start moves less than OUTAGE_RTS_TOL (m, m/s, m/s^2): where the car stops inside the
#: outage, the stop moves with the offset the end measurements reveal
OUTAGE_RTS_ITERATIONS = 5
OUTAGE_RTS_TOL = 1e-4


@njit(cache=True, error_model="numpy")
def _outage_rts(dt: np.ndarray, acc: np.ndarray, x0: np.ndarray, P0: np.ndarray,
                prm: np.ndarray, z_s: float, r_s: float, z_v: float, r_v: float,
                s_out: np.ndarray, v_out: np.ndarray) -> None:
    """The [s, v, b, c] model smoothed over one outage: from ``x0``, ``P0`` (the forward filter
    at the outage's last used fix, s = 0 there) through ``dt``/``acc`` of the epochs after it up
    to the outage's first fix (the last entry), where the distance ``z_s`` (m, variance ``r_s``)
    and the Doppler speed ``z_v`` (m/s, variance ``r_v``; NaN: none) are measured; then the
    Rauch-Tung-Striebel pass back, about a nominal trajectory from the smoothed start of the
    last pass (Gauss-Newton; the first pass's nominal starts at ``x0``).  ``s_out``, ``v_out``:
    the smoothed distance and speed (>= 0) at every entry."""
    n = len(dt)
    xp = np.empty((n, 4))        # predicted = filtered: nothing is measured inside the outage
    Pp = np.empty((n, 4, 4))
    Fs = np.empty((n, 4, 4))
    start = x0.copy()            # where the nominal trajectory starts
    for _ in range(OUTAGE_RTS_ITERATIONS):
        nom = start.copy()
        x = x0.copy()
        P = P0.copy()
        for i in range(n):
            F = np.eye(4)
            before = nom.copy()
            if dt[i] > 0.0:
                P = _predict(nom, P, F, dt[i], acc[i], prm, True)
            x = nom + F @ (x - before)
            Fs[i] = F
            Pp[i] = P
            xp[i] = x
        P = _measure(x, P, 0, z_s, r_s)
        P = _measure(x, P, 1, z_v, r_v)
        s_out[n - 1] = x[0]
        v_out[n - 1] = max(x[1], 0.0)
        for i in range(n - 2, -1, -1):
            # pinv: a step of 0 s leaves P(i+1|i) = P(i), singular where s was just anchored
            C = Pp[i] @ Fs[i + 1].T @ np.linalg.pinv(Pp[i + 1])
            x = xp[i] + C @ (x - xp[i + 1])
            s_out[i] = x[0]
            v_out[i] = max(x[1], 0.0)
        new_start = x0 + P0 @ Fs[0].T @ np.linalg.pinv(Pp[0]) @ (x - xp[0])
        moved = np.max(np.abs(new_start - start))
        start = new_start
        if moved < OUTAGE_RTS_TOL:
            break


def speed_track(epochs: Epochs, params: Params, anchor: np.ndarray | None = None,
                keep: np.ndarray | None = None) -> SpeedTrack:
    """The accelerometer's speed and distance per epoch (module docstring); ``anchor`` marks
    the epochs where the distance restarts (default: every epoch with a fix), ``keep`` those
    whose whole state and covariance are kept (default: none)."""
    n = len(epochs)
    covered = accel_covered(epochs)
    acc = np.where(covered, _ffill(np.where(epochs.has_accel, epochs.accel_mps2, np.nan)), np.nan)
    z = np.where(epochs.has_gnss, epochs.gnss_speed_mps, np.nan)
    if anchor is None:
        anchor = epochs.has_gnss
    keep = np.zeros(n, np.bool_) if keep is None else np.ascontiguousarray(keep, np.bool_)
    n_keep = int(np.count_nonzero(keep))
    x_keep, P_keep = np.empty((n_keep, 4)), np.empty((n_keep, 4, 4))
    out = [np.empty(n) for _ in range(5)]
    _speed_kf(np.ascontiguousarray(epochs.dt_s, np.float64), acc, z,
              np.ascontiguousarray(anchor, np.bool_), _kf_params(params), *out, keep, x_keep,
              P_keep)
    return SpeedTrack(*out, covered=covered, acc_mps2=acc, x_keep=x_keep, P_keep=P_keep)


def _kf_params(params: Params) -> np.ndarray:
    """``prm`` of :func:`_speed_kf` from ``[accel]``."""
    p = params["accel"]
    return np.array([float(p["init_speed_sd_mps"]), float(p["bias_init_sd_mps2"]),
                     float(p["grade_rate_init_sd_mps2_per_m"]), float(p["noise_psd_m2ps3"]),
                     float(p["bias_rw_var_m2ps5"]), float(p["grade_rw_var_m2ps4_per_m"]),
                     float(p["grade_rate_rw_var_per_m"]), float(p["gnss_speed_sd_mps"]) ** 2])


def _gyro_bias(epochs: Epochs, result: FilterResult) -> np.ndarray:
    """The gyro bias per epoch (rad/s, in the yaw rate's sign: true rate = reading - bias):
    the filter's estimate when it has one, else the mean reading at the standstills so far
    (a fix's Doppler speed under STANDSTILL_MPS at most MAX_ACCEL_AGE_S old; 0 before the
    first)."""
    est = result.extras.get("gyro_bias_radps")
    if est is not None and np.all(np.isfinite(est)):
        return np.asarray(est, float)
    n = len(epochs)
    t_s = (epochs.t_ns - epochs.t_ns[0]) / NS_PER_S
    fix = epochs.has_gnss & np.isfinite(epochs.gnss_speed_mps)
    last = np.maximum.accumulate(np.where(fix, np.arange(n), -1))
    j = np.maximum(last, 0)
    fresh = (last >= 0) & (t_s - t_s[j] <= MAX_ACCEL_AGE_S)
    yaw = epochs.yaw_rate_radps
    still = fresh & (epochs.gnss_speed_mps[j] < STANDSTILL_MPS) & epochs.has_gyro & np.isfinite(yaw)
    total = np.cumsum(np.where(still, yaw, 0.0))
    count = np.cumsum(still)
    return np.where(count > 0, total / np.maximum(count, 1), 0.0)


def course_gyro_bias(epochs: Epochs, k: int, psi_gyro: np.ndarray) -> float | None:
    """The gyro bias (rad/s, in the yaw rate's sign) from the fixes' course over the
    COURSE_WINDOW_S before epoch ``k``: the slope of course minus the raw gyro heading
    ``psi_gyro`` (the integral of -yaw rate, rad), unwrapped; None with too few courses.
    A 60-s fit at 0.05 m/s Doppler noise pins the bias to ~1e-4 rad/s, where a highway
    without a stop gives the standstill mean nothing to average."""
    t_s = (epochs.t_ns - epochs.t_ns[k]) / NS_PER_S
    lo = int(np.searchsorted(t_s, -COURSE_WINDOW_S))
    sel = lo + np.flatnonzero(epochs.has_gnss[lo:k + 1]
                              & np.isfinite(epochs.gnss_course_rad[lo:k + 1])
                              & (epochs.gnss_speed_mps[lo:k + 1] >= COURSE_MIN_MPS))
    if len(sel) < COURSE_MIN_FIXES or np.ptp(t_s[sel]) < COURSE_MIN_SPAN_S:
        return None
    r = unwrap_across_gaps(t_s[sel], epochs.gnss_course_rad[sel] - psi_gyro[sel])
    return float(np.polyfit(t_s[sel], r, 1)[0])


def _ffill(x: np.ndarray) -> np.ndarray:
    """``x`` with each NaN replaced by the latest finite value before it (NaN before the first)."""
    idx = np.maximum.accumulate(np.where(np.isfinite(x), np.arange(len(x)), -1))
    return np.where(idx >= 0, x[np.maximum(idx, 0)], np.nan)


def outage_spans(epochs: Epochs, result: FilterResult, params: Params
                 ) -> list[tuple[int, int, bool]]:
    """(k, m, accel): a fix the filter used, the next fix (exclusive end) more than
    ``accel.min_outage_s`` later, and whether the accelerometer covers every epoch in
    between; none on a drive with an odometer (it measures the speed) or without a gyro.
    Only GNSS outages: a stretch of fixes the filter rejected is the filter's to judge."""
    if epochs.has_odo.any() or not epochs.has_gyro.any():
        return []
    fixes = np.flatnonzero(epochs.has_gnss)
    if len(fixes) < 2:
        return []
    gap = np.diff(epochs.t_ns[fixes]) / NS_PER_S
    used = np.asarray(result.gnss_used, bool)
    cov = accel_covered(epochs)
    bad = np.concatenate(([0], np.cumsum(~cov)))
    out = []
    for i in np.flatnonzero(gap > float(params["accel"]["min_outage_s"])):
        k, m = int(fixes[i]), int(fixes[i + 1])
        if used[k]:
            out.append((k, m, bool(bad[m] == bad[k + 1])))
    return out


def held_speed(epochs: Epochs, result: FilterResult, params: Params, k: int, m: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Speed (m/s) and distance variance (m^2) at epochs k+1 .. m-1 of a gyro-only outage:
    the last fix's Doppler speed (else the filter's) plus the acceleration the fixes' speed
    showed over the last ``gyro_only_fit_s`` (a straight-line slope over >= 3 fixes, else 0),
    decaying with ``gyro_only_tau_s`` (a manoeuvre lasts seconds: v = v_k + a_k tau (1 -
    exp(-t / tau)), >= 0); the distance variance that of an unseen manoeuvre acceleration of
    sigma ``gyro_only_acc_sd_mps2`` and the same correlation time (2/3 sigma^2 tau t^3) on top
    of the speed's (``accel.gnss_speed_sd_mps``) t^2."""
    p = params["accel"]
    t_s = (epochs.t_ns - epochs.t_ns[k]) / NS_PER_S
    v_k = float(epochs.gnss_speed_mps[k])
    if not math.isfinite(v_k):
        v_k = math.hypot(result.v_e[k], result.v_n[k])
    fit_s = float(p["gyro_only_fit_s"])
    lo = int(np.searchsorted(t_s, -fit_s, side="right"))
    near = lo + np.flatnonzero(epochs.has_gnss[lo:k + 1] & np.isfinite(epochs.gnss_speed_mps[lo:k + 1]))
    a_k = 0.0
    if len(near) >= 3 and np.ptp(t_s[near]) > 0:
        a_k = float(np.polyfit(t_s[near], epochs.gnss_speed_mps[near], 1)[0])
    tau = max(float(p["gyro_only_tau_s"]), 1e-9)
    t = t_s[k + 1:m]
    v = np.maximum(v_k + a_k * tau * -np.expm1(-t / tau), 0.0)
    s_var = (float(p["gnss_speed_sd_mps"]) ** 2 * t * t
             + 2.0 / 3.0 * float(p["gyro_only_acc_sd_mps2"]) ** 2 * tau * t ** 3)
    return v, s_var


def accel_covered(epochs: Epochs) -> np.ndarray:
    """Epochs with an accelerometer reading at most MAX_ACCEL_AGE_S old."""
    return _covered(epochs, epochs.has_accel & np.isfinite(epochs.accel_mps2))


def _covered(epochs: Epochs, has: np.ndarray) -> np.ndarray:
    """Epochs with a reading (``has``) at most MAX_ACCEL_AGE_S old."""
    n = len(epochs)
    t_s = (epochs.t_ns - epochs.t_ns[0]) / NS_PER_S
    last = np.maximum.accumulate(np.where(has, np.arange(n), -1))
    return (last >= 0) & (t_s - t_s[np.maximum(last, 0)] <= MAX_ACCEL_AGE_S)


def bridge_outages(epochs: Epochs, result: FilterResult, params: Params, *,
                   smoothed: bool = False) -> FilterResult:
    """The forward track through each outage of :func:`outage_spans` dead-reckoned along the
    gyro's heading with the accelerometer's speed (``accel.enabled``) or, without readings,
    the last fixes' speed (:func:`held_speed`, ``accel.gyro_only``); ``result`` is changed in
    place and returned.  ``result.info["accel_bridged_outages"]`` and
    ``["gyro_only_bridged_outages"]`` count them; an outage the gyro does not cover (from
    where the filter last moved to its end) is left to the filter.

    ``smoothed``: ``result`` is a smoothed track, which has the fix at the outage's end too;
    only the accelerometer's outages are bridged (a held speed did worse than the smoother's
    own model between the two ends; evidence:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#accel-speed).
    The dead reckoning's misclosure there is spread back over the outage in proportion to
    the distance's variance (the mean of a random walk pinned at both ends: a Brownian
    bridge), and the along-track variance shrinks with it."""
    p = params["accel"]
    # the accelerometer's speed is the Doppler speed's, carried on: without the receiver's speed
    # at the outage's last fix (a positions-only receiver) it has no start: the held speed
    spans = [(k, m, acc and math.isfinite(epochs.gnss_speed_mps[k]))
             for k, m, acc in outage_spans(epochs, result, params)]
    # smoothed, only a measured speed beats the smoother's own model between the two ends
    spans = [(k, m, acc) for k, m, acc in spans
             if (p["enabled"] if acc else p["gyro_only"] and not smoothed)]
    result.info["accel_bridged_outages"] = 0
    result.info["gyro_only_bridged_outages"] = 0
    if not spans:
        return result
    anchor = np.asarray(result.gnss_used, bool)
    # smoothed: each accelerometer outage is smoothed from the forward filter at its start
    starts = np.zeros(len(epochs), bool)
    if smoothed:
        starts[[k for k, _, acc in spans if acc]] = True
    sp = speed_track(epochs, params, anchor, starts) if any(acc for _, _, acc in spans) else None
    start_row = np.cumsum(starts) - 1
    bias = _gyro_bias(epochs, result)
    yaw = np.where(epochs.has_gyro & np.isfinite(epochs.yaw_rate_radps), epochs.yaw_rate_radps,
                   np.nan)
    yaw = np.where(np.isfinite(_ffill(yaw)), _ffill(yaw), 0.0)
    dt = epochs.dt_s
    psi_gyro = np.cumsum(-yaw * dt)
    own = "gyro_bias_radps" in result.extras
    # a span the gyro does not cover (a dropout, clipped samples left out) stays the filter's
    gyro_gap = np.concatenate(([0], np.cumsum(~_covered(epochs, epochs.has_gyro
                                                         & np.isfinite(epochs.yaw_rate_radps)))))
    fspeed = np.hypot(result.v_e, result.v_n)
    moving = np.flatnonzero(fspeed >= float(p["heading_min_speed_mps"]))
    for k, m, acc in spans:
        i = np.searchsorted(moving, k, side="right") - 1
        if i < 0:
            continue  # never moved before: no heading to drive along
        j0 = int(moving[i])
        if gyro_gap[m] != gyro_gap[j0 + 1]:
            continue
        psi_ref = math.atan2(result.v_e[j0], result.v_n[j0])
        # the filter's own bias estimate, else the fixes' course, else the standstills'
        b = None if own else course_gyro_bias(epochs, k, psi_gyro)
        b_sp = bias[j0 + 1:m] if b is None else b
        cum = np.cumsum(-(yaw[j0 + 1:m] - b_sp) * dt[j0 + 1:m])
        psi = psi_ref + cum[k - j0:]                # epochs k+1 .. m-1
        sl = slice(k + 1, m)
        if acc:
            v, v_k, s_var = sp.v_mps[sl], sp.v_mps[k], sp.s_var[sl]
        else:
            v, s_var = held_speed(epochs, result, params, k, m)
            v_k = v[0] if len(v) else 0.0
        v_prev = np.concatenate(([v_k], v[:-1]))
        step = 0.5 * (v + v_prev) * dt[sl]
        ue, un = np.sin(psi), np.cos(psi)
        e = result.e[k] + np.cumsum(step * ue)
        n = result.n[k] + np.cumsum(step * un)
        if acc and smoothed and m < len(result.e) and len(e):
            v, step = _smoothed_outage(epochs, result, params, sp, int(start_row[k]), k, m,
                                       e[-1] + v[-1] * dt[m] * ue[-1],
                                       n[-1] + v[-1] * dt[m] * un[-1], ue[-1], un[-1])
            psi = _closed_heading(epochs, result, psi, step, v[-1] * dt[m], k, m,
                                  float(p["heading_min_speed_mps"]))
            ue, un = np.sin(psi), np.cos(psi)
            e = result.e[k] + np.cumsum(step * ue)
            n = result.n[k] + np.cumsum(step * un)
        # along-track: the fix's variance plus the distance's; across: the filter's
        pe, pn, pen = result.var_e[k], result.var_n[k], result.cov_en[k]
        along0 = ue * ue * pe + 2 * ue * un * pen + un * un * pn
        ce, cn = un, -ue
        qe, qn, qen = result.var_e[sl], result.var_n[sl], result.cov_en[sl]
        cross = ce * ce * qe + 2 * ce * cn * qen + cn * cn * qn
        along = along0 + s_var
        if smoothed and m < len(result.e) and len(e) and s_var[-1] > 0.0:
            # where the dead reckoning would reach the outage's first fix, against the track
            end_step = v[-1] * dt[m]
            de = result.e[m] - (e[-1] + end_step * ue[-1])
            dn = result.n[m] - (n[-1] + end_step * un[-1])
            w = s_var / s_var[-1]
            e = e + w * de
            n = n + w * dn
            along = along0 + s_var * (1.0 - w)
        result.e[sl], result.n[sl] = e, n
        result.v_e[sl], result.v_n[sl] = v * ue, v * un
        result.var_e[sl] = along * ue * ue + cross * ce * ce
        result.var_n[sl] = along * un * un + cross * cn * cn
        result.cov_en[sl] = along * ue * un + cross * ce * cn
        result.info["accel_bridged_outages" if acc else "gyro_only_bridged_outages"] += 1
    return result


def _smoothed_outage(epochs: Epochs, result: FilterResult, params: Params, sp: SpeedTrack,
                     row: int, k: int, m: int, e_end: float, n_end: float,
                     ue: float, un: float) -> tuple[np.ndarray, np.ndarray]:
    """(speed m/s, distance step m) at epochs k+1 .. m-1 of an accelerometer outage of a
    smoothed track: :func:`_outage_rts` from the forward filter's state at ``k`` (``sp``'s
    kept ``row``), measured at ``m`` by the smoothed track's fix there (the forward dead
    reckoning reaches (``e_end``, ``n_end``) heading (``ue``, ``un``); the misclosure along
    that heading is the distance's, with the track's own variance along it) and the fix's
    Doppler speed."""
    p = params["accel"]
    sl = slice(k + 1, m + 1)
    s_fwd_end = float(sp.s_m[m - 1]) + float(sp.v_mps[m - 1]) * float(epochs.dt_s[m])
    along = (result.e[m] - e_end) * ue + (result.n[m] - n_end) * un
    r_s = max(ue * ue * result.var_e[m] + 2.0 * ue * un * result.cov_en[m]
              + un * un * result.var_n[m], 1e-6)
    z_v = float(epochs.gnss_speed_mps[m]) if epochs.has_gnss[m] else math.nan
    s_sm, v_sm = np.empty(m - k), np.empty(m - k)
    _outage_rts(np.ascontiguousarray(epochs.dt_s[sl], np.float64),
                np.ascontiguousarray(sp.acc_mps2[sl]), sp.x_keep[row].copy(),
                sp.P_keep[row].copy(), _kf_params(params), s_fwd_end + float(along), r_s, z_v,
                float(p["gnss_speed_sd_mps"]) ** 2, s_sm, v_sm)
    step = np.diff(np.concatenate(([0.0], s_sm[:-1])))
    return v_sm[:-1], step


#: rad: a heading correction larger than this at either end of an outage is not the gyro's
#: drift (a reversal, a heading learnt at walking pace): the misclosure is spread instead
MAX_HEADING_FIX_RAD = 0.35


def _closed_heading(epochs: Epochs, result: FilterResult, psi: np.ndarray, step: np.ndarray,
                    end_step: float, k: int, m: int, min_speed: float) -> np.ndarray:
    """The gyro's heading ``psi`` (rad, clockwise from north) at epochs k+1 .. m-1 of a
    smoothed track's outage, corrected by ``a + b t`` (t: s since epoch ``k``; a start heading
    error and a gyro bias error) so that it meets the track's velocity heading at ``m`` and
    the dead reckoning along it (distance steps ``step`` m, then ``end_step`` to ``m``) meets
    the fix there across the track.  Unchanged where the track is slower than ``min_speed``
    (m/s) at ``m`` (no heading to meet) or the correction exceeds MAX_HEADING_FIX_RAD."""
    if len(psi) == 0 or math.hypot(result.v_e[m], result.v_n[m]) < min_speed:
        return psi
    t = (epochs.t_ns[k + 1:m + 1] - epochs.t_ns[k]) / NS_PER_S
    psi_m = psi[-1]
    d_end = math.remainder(math.atan2(result.v_e[m], result.v_n[m]) - psi_m, math.tau)
    e_end = result.e[k] + float(np.sum(step * np.sin(psi))) + end_step * math.sin(psi_m)
    n_end = result.n[k] + float(np.sum(step * np.cos(psi))) + end_step * math.cos(psi_m)
    # right of the travel at m: a heading turned clockwise by d moves a step ds by d ds there
    cross = (result.e[m] - e_end) * math.cos(psi_m) - (result.n[m] - n_end) * math.sin(psi_m)
    ds = np.append(step, end_step)
    A = np.array([[1.0, t[-1]], [float(np.sum(ds)), float(np.sum(ds * t))]])
    if abs(np.linalg.det(A)) < 1e-9:
        return psi
    a, b = np.linalg.solve(A, np.array([d_end, cross]))
    if max(abs(a), abs(a + b * t[-1])) > MAX_HEADING_FIX_RAD:
        return psi
    return psi + a + b * t[:-1]
