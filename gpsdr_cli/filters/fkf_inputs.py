"""fkf's input conditioning: the epochs turned into the federated kernels' inputs.

Heading alignment, gyro despiking and the outage headings, the course
corrections and fix chords, the odometer scale and its distance rows, the
multipath regimes, standstill and the initial state: everything
:func:`prepare` builds into a :class:`Prepared` for
:func:`gpsdr_cli.filters.kernels_fkf.federated_pass`.  The filter itself (the
forward pass, the smoothers and the registered ``run``) is
:mod:`gpsdr_cli.filters.fkf`, whose docstring describes the model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..angles import GAP_S, drive_rate, unwrap_across_gaps
from ..config import Params
from ..conventions import NS_PER_S
from ..epochs import Epochs, true_runs
from ..errors import ConfigError, NoDataError
from . import kernels_fkf as kf
from .adaptive import gate_threshold
from .gnss_model import gnss_only_gate_reset_s, rtk_bias_sd
from .standstill import standstill_from_gnss

#: seconds: an odometer reading older than this does not decide standstill
STALE_ODO_S = 1.0
#: an odometer pause longer than this (s; or 5 record intervals) is a dropout: what the car drove
#: in it is unknown, so no distance row spans it and the odometer scale is not fitted across it
ODO_DROPOUT_S = 5.0
#: fixes with a speed needed to scale the odometer to the GNSS speed
MIN_SCALE_FIXES = 20
#: seconds: fixes this far apart give the fallback course for the heading alignment
COURSE_BASE_S = 2.0
#: rad: a course this far from the course-corrected gyro heading is left out of the course
#: correction's means (noise at [fkf] course_min_speed_mps: 0.2 m/s over 3 m/s, 4 deg)
COURSE_OUTLIER_RAD = math.radians(20.0)


@dataclass
class Prepared:
    """Everything the kernels take, built from the epochs and the parameters."""

    dt: np.ndarray
    has_gnss: np.ndarray
    gnss_e: np.ndarray
    gnss_n: np.ndarray
    gnss_var_e: np.ndarray
    gnss_var_n: np.ndarray
    gnss_ve: np.ndarray
    gnss_vn: np.ndarray
    theta: np.ndarray
    dist: np.ndarray
    t_m: np.ndarray
    static: np.ndarray
    eps_w: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    psi0: float
    par: np.ndarray
    flags: np.ndarray
    info: dict


def chi2_1(prob: float) -> float:
    """chi-square(1) quantile: the square of the normal quantile at ``(1 + p)/2``.

    (Closed form: :func:`.adaptive.gate_threshold` would import SciPy for dof 1.)
    """
    return NormalDist().inv_cdf(0.5 * (1.0 + prob)) ** 2


def odometer_held(epochs: Epochs, t_s: np.ndarray, o: np.ndarray,
                  speed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per epoch: whether an odometer record at most ``STALE_ODO_S`` old exists, and that
    record's speed from ``speed`` (m/s, one per epoch of ``o``; 0 before the first)."""
    n = len(t_s)
    last = np.maximum.accumulate(np.where(epochs.has_odo, np.arange(n), -1))
    lastc = np.maximum(last, 0)
    fresh = (last >= 0) & (t_s - t_s[lastc] <= STALE_ODO_S)
    held = np.zeros(n)
    held[o] = speed
    return fresh, held[lastc]


def wheels_moving(fresh: np.ndarray, held: np.ndarray, v_min: float) -> np.ndarray:
    """Per epoch: False where a fresh odometer record (:func:`odometer_held`) reads below
    ``v_min`` m/s, else True (no odometer there: no say).

    With an odometer the wheels, not the receiver's Doppler nor the filter's predicted
    velocity, say whether the car moves.  Where they say it is slower than ``[fkf]
    course_min_speed_mps`` the receiver's speed and course are not a course or a speed for
    :func:`course_correction` and :func:`odometer_scale`: a reflected (NLOS) signal's
    Doppler is biased by metres per second, and the NLOS screen judges a fix by its
    position only (``simulate_drive("urban_nlos", 33, 283.0, gyro_rate_hz=5.0,
    odo_rate_hz=5.0)``: a 13-s stop's kept fixes read 3.0-3.8 m/s at 76-98 deg off the
    road while the odometer read 0; the course correction took them for the heading and
    interpolated it through the 76 s of screened fixes after them, fkf 194 m off, and the
    odometer scale read 1.106 for 1.020).  Where they say it is slower than ``[standstill]
    omega_min_speed_mps`` there is no heading row (:func:`prepare`)."""
    return ~fresh | (held >= v_min)


def heading_alignment(epochs: Epochs, t_s: np.ndarray, params: Params) -> tuple[float, float, str]:
    """(t_a s, heading at t_a rad, source) for aligning the integrated gyro heading."""
    v_min = params["standstill"]["omega_min_speed_mps"]
    ok = (epochs.has_gnss & np.isfinite(epochs.gnss_course_rad)
          & (epochs.gnss_speed_mps >= v_min))
    k = np.flatnonzero(ok)
    if len(k):
        return float(t_s[k[0]]), float(epochs.gnss_course_rad[k[0]]), "gnss_course"
    f = np.flatnonzero(epochs.has_gnss)
    if len(f) > 1:
        tf = t_s[f]
        j = np.searchsorted(tf, tf + COURSE_BASE_S)
        valid = j < len(f)
        i = np.flatnonzero(valid)
        jj = j[valid]
        de = epochs.gnss_e[f[jj]] - epochs.gnss_e[f[i]]
        dn = epochs.gnss_n[f[jj]] - epochs.gnss_n[f[i]]
        sd = np.maximum(epochs.gnss_sd_e[f[i]], epochs.gnss_sd_n[f[i]])
        moved = (np.hypot(de, dn) >= np.maximum(5.0, 4.0 * sd)) & (tf[jj] - tf[i] <= 2.5 * COURSE_BASE_S)
        m = np.flatnonzero(moved)
        if len(m):
            a = m[0]
            return (float(0.5 * (tf[i[a]] + tf[jj[a]])), float(math.atan2(de[a], dn[a])),
                    "gnss_fixes")
    h0 = params["frame"]["initial_heading_deg"]
    if math.isfinite(h0):
        return float(t_s[0]), math.radians(h0), "initial_heading_deg"
    return float(t_s[0]), 0.0, "none"


def despike(values: np.ndarray, threshold: float) -> tuple[np.ndarray, int]:
    """Samples further than ``threshold`` from the median of their 5-sample neighbourhood
    replaced by that median (single-sample glitches: a 100 rad/s gyro reading would
    otherwise stay in the integrated heading for good).  Returns (values, count)."""
    if len(values) < 5 or not threshold > 0:
        return values, 0
    out = np.empty(len(values))
    count = kf.despike5(np.ascontiguousarray(values, dtype=float), float(threshold), out)
    return out, int(count)


#: s: the course at each end of a GNSS outage is the mean over the fixes this close to it
OUTAGE_EDGE_S = 1.0
#: rad: a drive without a gyro gets heading rows in an outage when the course at its two
#: ends differs by at most this (the road ran straight through it)
STRAIGHT_OUTAGE_RAD = math.radians(10.0)
#: rad/s: ... or when that difference over the outage's time is a yaw rate of at most this
#: (a highway curve; a turn at a junction is sharper, and where in the outage it was is
#: unknown)
MAX_OUTAGE_TURN_RATE = math.radians(2.0)


def outage_headings(epochs: Epochs, t_s: np.ndarray, o: np.ndarray, params: Params
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(epochs, heading rad) of the heading rows for a drive with an odometer and no gyro:
    in each GNSS outage whose two ends have a course (fixes with speed >= ``[fkf]
    course_min_speed_mps`` within ``OUTAGE_EDGE_S`` of it, averaged) that differs by at
    most ``STRAIGHT_OUTAGE_RAD`` or by at most ``MAX_OUTAGE_TURN_RATE`` x its time, the
    two courses interpolated linearly in time (a constant yaw rate), at the first
    odometer record of each ``[fkf] heading_interval_s`` slot, as the gyro's rows.

    Why (our choice): with an odometer and no gyro the distance rows measure the speed
    and nothing the direction.  In an outage the white-jerk model carried the lateral
    acceleration the fixes left behind, the velocity's cross-track variance grew to metres
    per second, and each distance row, linearised along a velocity that had turned against
    P's axes, turned it further, even on a straight road.  A post-processor knows the
    course at both ends; on a straight road the heading holds between them, through a
    highway curve it turns at a roughly constant rate.  Not through a junction: the turn's
    time is unknown, and a linear heading there was worse than none.  Evidence:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf-inputs.
    """
    none = np.zeros(0, np.int64), np.zeros(0)
    out = epochs.gnss_outage
    if not (len(o) and out.any()):
        return none
    fp = params["fkf"]
    ok = (epochs.has_gnss & np.isfinite(epochs.gnss_course_rad)
          & (epochs.gnss_speed_mps >= fp["course_min_speed_mps"]))
    k = np.flatnonzero(ok)
    if not len(k):
        return none
    tk = t_s[k]
    uk = np.exp(1j * epochs.gnss_course_rad[k])
    use, value = [], []
    for a, b in zip(*true_runs(out), strict=True):      # outage epochs a..b
        before = (tk < t_s[a]) & (tk >= t_s[a] - OUTAGE_EDGE_S)
        after = (tk > t_s[b]) & (tk <= t_s[b] + OUTAGE_EDGE_S)
        if not (before.any() and after.any()):
            continue                                    # a drive's end, or stopped there
        c1 = float(np.angle(uk[before].sum()))
        c2 = float(np.angle(uk[after].sum()))
        turn = math.remainder(c2 - c1, 2.0 * math.pi)
        t1, t2 = float(tk[before].mean()), float(tk[after].mean())
        if abs(turn) > STRAIGHT_OUTAGE_RAD and abs(turn) > MAX_OUTAGE_TURN_RATE * (t2 - t1):
            continue
        oo = o[(o >= a) & (o <= b)]
        if not len(oo):
            continue
        slot = np.floor(t_s[oo] / max(fp["heading_interval_s"], 1e-9))
        oo = oo[np.concatenate(([True], slot[1:] != slot[:-1]))]
        use.append(oo)
        value.append(c1 + turn * (t_s[oo] - t1) / (t2 - t1))
    if not use:
        return none
    return np.concatenate(use), np.angle(np.exp(1j * np.concatenate(value)))


def course_correction(epochs: Epochs, t_s: np.ndarray, tg: np.ndarray, psi_g: np.ndarray,
                      params: Params, moving: np.ndarray | None = None) -> np.ndarray:
    """Slow correction (rad) of the integrated gyro heading towards the GNSS course, at ``tg``.

    ``d_k = wrap(course_k - psi_g(t_k))`` at fixes with a course and speed >=
    ``[fkf] course_min_speed_mps``, unwrapped, averaged over a centred window of
    ``[fkf] heading_course_window_s`` (0: off, the heading stays aligned once,
    as in the paper) and interpolated linearly in time -- across GNSS outages
    too, since a log post-processor knows both ends.  A complementary filter:
    the gyro keeps the short-term heading, the course removes the integrated
    gyro bias (a 4 deg/s bias otherwise outruns the random walk q_w).

    Each window's mean belongs to the mean time of the fixes in it, not to the
    fix it is centred on: next to a GNSS outage the window is one-sided, and a
    gyro bias makes ``d`` a ramp, so the mean placed at the fix lagged it and the
    track left an outage far off.  ``moving`` (per epoch, :func:`wheels_moving`): only
    the fixes it marks give a course.
    Evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf-inputs.
    """
    fp = params["fkf"]
    window = fp["heading_course_window_s"]
    ok = (epochs.has_gnss & np.isfinite(epochs.gnss_course_rad)
          & (epochs.gnss_speed_mps >= fp["course_min_speed_mps"]))
    if moving is not None:
        ok &= moving
    k = np.flatnonzero(ok)
    if window <= 0 or len(k) < 2:
        return np.zeros(len(tg))
    tk = t_s[k]
    d = unwrap_across_gaps(tk, np.angle(np.exp(1j * (epochs.gnss_course_rad[k]
                                                     - np.interp(tk, tg, psi_g)))))
    t_mean, d_mean = _window_means(tk, d, window)
    # a course further than COURSE_OUTLIER_RAD from the corrected gyro heading is a wrong
    # course, not noise (a receiver's bad epochs: four 3-s runs 45 deg off turned the
    # windows' means by up to 13 deg and fkf's track without an odometer 12-19 m off,
    # docs/decisions/0031): the means again without them
    far = np.abs(d - np.interp(tk, t_mean, d_mean)) > COURSE_OUTLIER_RAD
    if far.any() and (~far).sum() >= 2:
        t_mean, d_mean = _window_means(tk[~far], d[~far], window)
    out = np.interp(tg, t_mean, d_mean)
    # before the first course and after the last the offset keeps drifting at the gyro's
    # bias: the drive's rate, not zero (held, a drive's last two minutes of reflected
    # fixes, all left out, turned a simulated fkf heading 30 deg; decisions/0044)
    rate = drive_rate(tk, d, np.flatnonzero(np.diff(tk) > GAP_S))
    if math.isfinite(rate):
        out += rate * (np.minimum(tg - t_mean[0], 0.0) + np.maximum(tg - t_mean[-1], 0.0))
    return out


def _window_means(tk: np.ndarray, d: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray]:
    """Centred window means of ``d`` (shrinking at the ends) and their fixes' mean times,
    increasing (see :func:`course_correction`)."""
    c = np.concatenate(([0.0], np.cumsum(d)))
    half = np.minimum(0.5 * window, np.minimum(tk - tk[0], tk[-1] - tk))
    lo = np.searchsorted(tk, tk - half, side="left")
    hi = np.searchsorted(tk, tk + half, side="right")
    d_mean = (c[hi] - c[lo]) / (hi - lo)     # centred average, shrinking at the ends
    ct = np.concatenate(([0.0], np.cumsum(tk - tk[0])))
    t_mean = tk[0] + (ct[hi] - ct[lo]) / (hi - lo)  # ... at its fixes' mean time: no lag on a ramp
    # lo and hi never decrease with k, so neither does t_mean; equal times (a window
    # that did not move) keep their first mean
    keep = np.concatenate(([True], np.diff(t_mean) > 0.0))
    return t_mean[keep], d_mean[keep]


@dataclass
class FixChords:
    """Displacements between pairs of GNSS fixes and the dead-reckoned ones over the same times.

    ``g`` and ``dr``: complex ``east + 1j*north`` (m), the fixes' chord and the chord of the
    track dead-reckoned from the gyro heading and the unscaled odometer speed (see
    :func:`fix_chords`); ``t_mid`` the chord's time (s), ``var`` the modelled
    variance of ``g`` per axis (m^2: both fixes' sigmas and the GNSS error states' share
    that the two ends do not have in common).  A rotation ``g ~ k exp(-1j*delta) dr`` (heading
    clockwise from north) gives the heading correction ``delta`` and the odometer scale ``k``.
    """

    t_mid: np.ndarray
    g: np.ndarray
    dr: np.ndarray
    var: np.ndarray


def dr_positions(tg: np.ndarray, psi: np.ndarray, t_odo: np.ndarray | None,
                 speed: np.ndarray | None, at: np.ndarray) -> np.ndarray:
    """Dead-reckoned position (complex ``e + 1j n``, m, arbitrary origin) at times ``at`` (s).

    Trapezoid integral on the gyro grid ``tg`` of ``v (sin psi, cos psi)``, ``v`` the
    speed (``speed`` at ``t_odo``) interpolated to ``tg`` (1 m/s without one: then only
    the direction of a chord means anything)."""
    v = np.interp(tg, t_odo, speed) if t_odo is not None and len(t_odo) else np.ones(len(tg))
    z = v * np.exp(1j * (0.5 * np.pi - psi))            # e + 1j n = v (sin psi + 1j cos psi)
    cum = np.zeros(len(tg), complex)
    cum[1:] = np.cumsum(0.5 * (z[1:] + z[:-1]) * np.diff(tg))
    return np.interp(at, tg, cum.real) + 1j * np.interp(at, tg, cum.imag)


def fix_chords(epochs: Epochs, t_s: np.ndarray, tg: np.ndarray | None, psi_g: np.ndarray | None,
               t_odo: np.ndarray | None, speed: np.ndarray | None, eps_w: np.ndarray,
               params: Params) -> FixChords:
    """Chords between fixes, long enough that their course is known to ``[fkf]
    fix_chord_course_sd_rad`` (for a receiver that reports positions only).

    From each fix ``i`` the chord runs to the first fix ``j`` at least ``D_i`` further
    along the road (odometer distance; without an odometer, the fixes' own distance) and
    at most ``[fkf] fix_chord_max_s`` later, ``D_i = sqrt(2 (sigma_i^2 + sigma_eps,i^2)) /
    fix_chord_course_sd_rad``: the chord's error with both ends' white noise and the GNSS
    error states' stationary sigma (the multipath allowance: eps's regime at fix ``i``,
    :func:`multipath_regime`, blends the clear and obstructed sigmas) fully decorrelated.
    Open sky (sigma 1 m, eps 1 m): 40 m; urban canyon (2.6 m, 3 m): 112 m.  Without an
    odometer the dead-reckoned chord takes its speed profile from the chords themselves
    (``|g|/dt`` at their mid times); without a gyro (``tg`` None) ``dr`` is the odometer
    distance along the fixes' own chord, straight chords only (for the scale alone).  Chords of a
    fixed time fail both ways (multipath makes short chords garbage).  Each chord's
    variance ``var`` counts the eps share that the ends do not have in common,
    ``2 sigma_eps^2 (1 - exp(-dt/tau - L/dist))``; its
    time ``t_mid`` is the distance-weighted mean time of its travel (``int t ds / int ds``
    on the odometer; the midpoint without one), as the heading error it measures is
    weighted by the distance driven.  Longer chords in time lost (``fix_chord_max_s``):
    a 30-s limit let slow chords with a ramping heading error dominate the weights.
    Evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf-inputs.
    """
    fp = params["fkf"]
    f = np.flatnonzero(epochs.has_gnss)
    empty = FixChords(np.zeros(0), np.zeros(0, complex), np.zeros(0, complex), np.zeros(0))
    no_gyro = tg is None or len(tg) < 2
    if len(f) < 2 or (no_gyro and (t_odo is None or len(t_odo) < 2)):
        return empty
    tf = t_s[f]
    pf = epochs.gnss_e[f] + 1j * epochs.gnss_n[f]
    var_fix = 0.5 * (epochs.gnss_sd_e[f] ** 2 + epochs.gnss_sd_n[f] ** 2)
    w = np.mod(eps_w[f], kf.EPS_RESET)  # the regime share, without a reset mark
    var_eps = (1.0 - w) * fp["gnss_err_sd_m"] ** 2 + w * fp["gnss_err_obstructed_sd_m"] ** 2
    d_min = np.sqrt(2.0 * (var_fix + var_eps)) / fp["fix_chord_course_sd_rad"]
    with_odo = t_odo is not None and len(t_odo) > 1
    if with_odo:
        cum = np.concatenate(([0.0], np.cumsum(speed[1:] * np.diff(t_odo))))
        # int t ds: a chord's time is the distance-weighted mean time of its travel
        cum_t = np.concatenate(([0.0], np.cumsum(speed[1:] * np.diff(t_odo)
                                                 * 0.5 * (t_odo[1:] + t_odo[:-1]))))
        s_f = np.interp(tf, t_odo, cum)
        j = np.searchsorted(s_f, s_f + d_min, side="left")     # odometer distance: monotonic
    else:                               # the first fix D away within fix_chord_max_s
        j = np.full(len(f), len(f))
        last = np.searchsorted(tf, tf + fp["fix_chord_max_s"], side="right")
        for a in range(len(f)):
            far = np.flatnonzero(np.abs(pf[a + 1:last[a]] - pf[a]) >= d_min[a])
            if len(far):
                j[a] = a + 1 + far[0]
    ok = j < len(f)
    i = np.flatnonzero(ok)
    j = j[ok]
    keep = tf[j] - tf[i] <= fp["fix_chord_max_s"]
    i, j = i[keep], j[keep]
    if not len(i):
        return empty
    g = pf[j] - pf[i]
    dt = tf[j] - tf[i]
    if no_gyro:
        # odometer distance along the fixes' own chord, on straight chords only: the middle
        # fix (half the odometer distance on) within one sigma of the chord's line -- an arc
        # is longer than its chord (a sagitta of L/30 already 0.3 %)
        m = np.minimum(np.searchsorted(s_f, 0.5 * (s_f[i] + s_f[j]), side="left"), len(f) - 1)
        u = g / np.where(np.abs(g) > 0.0, np.abs(g), 1.0)
        sag = np.abs(((pf[m] - pf[i]) * np.conj(u)).imag)
        straight = sag <= np.sqrt(var_fix[m] + var_eps[m])
        i, j, g, dt, u = i[straight], j[straight], g[straight], dt[straight], u[straight]
        dr = (s_f[j] - s_f[i]) * u
    else:
        if not with_odo:    # the speed profile from the chords themselves (|g| / dt)
            t_odo = 0.5 * (tf[i] + tf[j])
            speed = np.abs(g) / dt
        p_dr = dr_positions(tg, psi_g, t_odo, speed, np.concatenate((tf[i], tf[j])))
        dr = p_dr[len(i):] - p_dr[:len(i)]
    length = np.abs(g)
    wi = w[i]

    def rho(tau: float, dist: float) -> np.ndarray:
        return np.exp(-dt / tau - (length / dist if dist > 0 else 0.0))

    corr = ((1.0 - wi) * rho(fp["gnss_err_tau_s"], fp["gnss_err_dist_m"])
            + wi * rho(fp["gnss_err_obstructed_tau_s"], fp["gnss_err_obstructed_dist_m"]))
    var = var_fix[i] + var_fix[j] + 2.0 * var_eps[i] * (1.0 - corr)
    t_mid = 0.5 * (tf[i] + tf[j])
    if with_odo:        # the heading error a chord measures is weighted by the distance driven
        ct_f = np.interp(tf, t_odo, cum_t)
        ds = s_f[j] - s_f[i]
        t_mid = np.where(ds > 0.0, (ct_f[j] - ct_f[i]) / np.where(ds > 0.0, ds, 1.0), t_mid)
    # in time order (D varies from fix to fix, so the ends need not be)
    k = np.flatnonzero(np.abs(dr) > 0.0)
    k = k[np.argsort(t_mid[k], kind="stable")]
    return FixChords(t_mid[k], g[k], dr[k], var[k])


def chord_course_correction(chords: FixChords, tg: np.ndarray, params: Params) -> np.ndarray:
    """Slow correction (rad) of the integrated gyro heading at ``tg`` from fix chords.

    The chord of the fixes and the dead-reckoned chord over the same times differ by the
    heading error the gyro heading had over them: ``delta_k = arg(dr_k conj(g_k))``
    (clockwise positive; exact for any road shape when the error is constant over the
    chord).  ``delta`` unwrapped; at each chord a straight line fitted by weighted least
    squares to the ``delta`` in a window of ``[fkf] fix_course_window_s`` centred on it (cut
    at the data's ends, at outages and stops: the line needs no symmetry), weights
    ``|dr_k|^2 / var_k`` (the inverse variance of ``delta_k``); its value there,
    interpolated in time.  A line, not :func:`course_correction`'s mean: the gyro bias
    makes the heading error a ramp (0.3 deg/s: 0.3 rad a minute), and a mean over the
    one-sided window at the edge of a tunnel lagged it.
    Evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf-inputs.
    """
    window = params["fkf"]["fix_course_window_s"]
    if window <= 0 or len(chords.t_mid) < 2:
        return np.zeros(len(tg))
    tk = chords.t_mid
    d = unwrap_across_gaps(tk, np.angle(chords.dr * np.conj(chords.g)))
    wk = np.abs(chords.dr) ** 2 / chords.var
    t0 = tk - tk[0]

    def csum(x: np.ndarray) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(x)))

    c_w, c_t, c_tt = csum(wk), csum(wk * t0), csum(wk * t0 * t0)
    c_d, c_td = csum(wk * d), csum(wk * t0 * d)
    lo = np.searchsorted(tk, tk - 0.5 * window, side="left")
    hi = np.searchsorted(tk, tk + 0.5 * window, side="right")
    sw, st, stt = c_w[hi] - c_w[lo], c_t[hi] - c_t[lo], c_tt[hi] - c_tt[lo]
    sd, std = c_d[hi] - c_d[lo], c_td[hi] - c_td[lo]
    # the line about the window's weighted mean time tm: d(t) = mean + slope (t - tm)
    tm = st / sw
    mean = sd / sw
    var_t = stt / sw - tm * tm
    cov = std / sw - tm * mean
    # a window without a spread in time (a single chord) gives its mean
    span_ok = var_t > 1e-6 * window * window
    slope = np.where(span_ok, cov / np.where(span_ok, var_t, 1.0), 0.0)
    d_fit = mean + slope * (t0 - tm)
    return np.interp(tg, tk, d_fit)


def chord_odometer_scale(chords: FixChords, t_odo: np.ndarray, params: Params
                         ) -> tuple[np.ndarray, float]:
    """:func:`odometer_scale` from fix chords: per odometer record at ``t_odo``, the
    weighted least-squares scale of ``g ~ k dr`` (``dr`` dead-reckoned with the corrected
    heading) over a centred ``[fkf] fix_odo_scale_window_s``: ``k = sum Re(g conj(dr))/var /
    sum |dr|^2/var`` -- the fixes' noise along the chord averages out (the ratio of
    chord lengths would be biased up by it).  Clamped to [0.8, 1.25]; needs
    ``MIN_SCALE_FIXES`` chords, else 1.  Returns (k per record, median k)."""
    window = params["fkf"]["fix_odo_scale_window_s"]
    ones = np.ones(len(t_odo))
    inside = (chords.t_mid >= t_odo[0]) & (chords.t_mid <= t_odo[-1]) if len(t_odo) else None
    if window <= 0 or len(t_odo) < 2 or np.count_nonzero(inside) < MIN_SCALE_FIXES:
        return ones, 1.0
    tk = chords.t_mid[inside]
    g, dr, var = chords.g[inside], chords.dr[inside], chords.var[inside]
    ratio = windowed_ratio(tk, (g * np.conj(dr)).real / var, np.abs(dr) ** 2 / var, window)
    return np.interp(t_odo, tk, ratio), float(np.median(ratio))


def windowed_ratio(tk: np.ndarray, num: np.ndarray, den: np.ndarray, window_s: float) -> np.ndarray:
    """``sum(num) / sum(den)`` over a window of ``window_s`` seconds centred on each time ``tk``
    (sorted, s), 1 where the window's ``den`` sums to zero, clamped to [0.8, 1.25]: an
    odometer scale (a ratio outside is a unit error, not a wheel)."""
    cn = np.concatenate(([0.0], np.cumsum(num)))
    cd = np.concatenate(([0.0], np.cumsum(den)))
    lo = np.searchsorted(tk, tk - 0.5 * window_s, side="left")
    hi = np.searchsorted(tk, tk + 0.5 * window_s, side="right")
    d = cd[hi] - cd[lo]
    ratio = np.where(d > 0.0, (cn[hi] - cn[lo]) / np.where(d > 0.0, d, 1.0), 1.0)
    return np.clip(ratio, 0.8, 1.25)


def odometer_scale(epochs: Epochs, t_s: np.ndarray, t_odo: np.ndarray, speed: np.ndarray,
                   params: Params, moving: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Scale factor (per odometer record at ``t_odo``) taking the odometer speed to the GNSS's.

    ``k = sum(gnss speed) / sum(odometer speed)`` over the fixes with a speed >=
    ``[fkf] course_min_speed_mps`` in a window of ``[fkf] odo_scale_window_s``
    centred on each fix (clipped at the drive's ends), the odometer speed
    interpolated to the fix times; interpolated linearly to the odometer
    records; clamped to [0.8, 1.25] (a ratio outside is a unit error, not a
    wheel).  A post-processor sees the whole drive, so an outage is bridged
    from both ends.  Needs ``MIN_SCALE_FIXES`` such fixes, else 1; with ``moving``
    (:func:`wheels_moving`) only the fixes it marks.  Returns (k per record, median k).
    """
    fp = params["fkf"]
    window = fp["odo_scale_window_s"]
    ones = np.ones(len(t_odo))
    if window <= 0 or len(t_odo) < 2:
        return ones, 1.0
    ok = (epochs.has_gnss & np.isfinite(epochs.gnss_speed_mps)
          & (epochs.gnss_speed_mps >= fp["course_min_speed_mps"])
          & (t_s >= t_odo[0]) & (t_s <= t_odo[-1]))
    if moving is not None:
        ok &= moving
    if len(t_odo) > 1:  # not fitted across an odometer dropout (its speed there is unknown)
        gap = dropouts(np.diff(t_odo))
        j = np.searchsorted(t_odo, t_s, side="right") - 1     # the record at or before each epoch
        inside = (j >= 0) & (j < len(gap))
        inside[inside] &= gap[j[inside]] & (t_s[inside] > t_odo[j[inside]])
        ok &= ~inside
    k = np.flatnonzero(ok)
    if len(k) < MIN_SCALE_FIXES:
        return ones, 1.0
    tk = t_s[k]
    ratio = windowed_ratio(tk, epochs.gnss_speed_mps[k], np.interp(tk, t_odo, speed), window)
    return np.interp(t_odo, tk, ratio), float(np.median(ratio))


def multipath_regime(epochs: Epochs, params: Params) -> np.ndarray:
    """Per epoch, the regime of the GNSS error states eps in [0, 1]: 0 clear sky, 1 obstructed.

    A fix is obstructed when its PDOP >= ``[fkf] gnss_err_pdop`` (2: the top of
    the usual "excellent" DOP class; ``inf``: every fix clear, one regime); a
    fix without PDOP (ROS NavSatFix, NMEA without GSA) when its base sigma
    (:func:`gpsdr_cli.align.base_sigma`: the receiver's, else HDOP x UERE, else
    the default) >= ``[fkf] gnss_err_sigma_m`` (2.2 m: PDOP 2 at HDOP = 0.62
    PDOP and the default UERE 2.5 m, HDOP x UERE/sqrt 2).  Without it a
    receiver with a covariance and no DOP (NavSatFix) stayed in the clear-sky
    regime.  The regime of a fix is
    the share of obstructed fixes
    in a centred window of ``[fkf] gnss_err_window_s`` (0: its own), and an
    epoch takes the latest fix's (before the first fix, the first one's; across
    an outage, the last one's).  :func:`~.kernels_fkf.select_eps` blends the
    two eps models by it.

    Why two models (issue #4): under obstruction the fix error is multipath --
    metres, and decorrelating with the antenna's displacement as the
    reflecting geometry changes, ``1/tau = 1/tau_s + speed/D``
    (``gnss_err_obstructed_*``).  With one time-only model the filter read
    the urban canyon's slow multipath as position.  In clear sky the error
    that is left drifts slowly in time, moving or not (orbit, atmosphere, the
    receiver's own smoothing and latency): a distance decorrelation there
    made the real drive worse.  Why a share over a window: PDOP wanders
    around a threshold within one environment (suburban PDOP 2.2 +- 20 %),
    and a regime that followed each fix let a few seconds of obstruction
    leave eps's variance at 9 m^2 for minutes of clear sky or, with eps
    rescaled by the ratio of the sigmas at each switch, jumped the track.
    Evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf-inputs.
    """
    n = len(epochs)
    rtk_sd = rtk_bias_sd(epochs, params)
    if rtk_sd is not None:  # an RTK drive: the regime is the fix kind (0 centimetres, 1 other)
        c2 = float(params["fkf"]["gnss_err_sd_m"]) ** 2
        o2 = float(params["fkf"]["gnss_err_obstructed_sd_m"]) ** 2
        w = np.clip((rtk_sd ** 2 - c2) / (o2 - c2), 0.0, 1.0) if o2 > c2 else np.zeros(n)
        switch = np.concatenate(([False], np.diff(rtk_sd) != 0.0))
        return np.where(switch, w + kf.EPS_RESET, w)
    thr = params["fkf"]["gnss_err_pdop"]
    f = np.flatnonzero(epochs.has_gnss)
    if not len(f) or thr == math.inf:
        return np.zeros(n)                  # one regime: the clear-sky keys
    pd_f = epochs.pdop[f]
    sd_f = np.maximum(epochs.gnss_sd_e[f], epochs.gnss_sd_n[f])
    ob = np.where(np.isfinite(pd_f), pd_f >= thr,
                  sd_f >= params["fkf"]["gnss_err_sigma_m"]).astype(float)
    window = params["fkf"]["gnss_err_window_s"]
    if window > 0:                          # share of obstructed fixes in a centred window
        tf = (epochs.t_ns[f] - epochs.t_ns[0]) / NS_PER_S
        c = np.concatenate(([0.0], np.cumsum(ob)))
        lo = np.searchsorted(tf, tf - 0.5 * window, side="left")
        hi = np.searchsorted(tf, tf + 0.5 * window, side="right")
        ob = (c[hi] - c[lo]) / (hi - lo)
    last = np.cumsum(epochs.has_gnss) - 1                         # latest fix <= k
    return ob[np.maximum(last, 0)]


def distance_rows(t_s: np.ndarray, o: np.ndarray, speed: np.ndarray, interval_s: float,
                  heading: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(epoch indices, distance m, T_m s) of the odometer distance rows S.

    ``o``: the epochs of the odometer records, ``speed`` theirs; record ``k >= 1``
    covers ``speed_k x (t_k - t_{k-1})`` (the cumulative distance is linear in
    between).  With ``interval_s > 0`` (``[fkf] distance_interval_s``) the rows
    are the first record of each ``interval_s`` slot and every epoch flagged in
    ``heading`` (an epoch with a heading row; when the gyro and the odometer
    are stamped apart, the cumulative distance is interpolated to it) inside
    the odometer's span with a record at most ``STALE_ODO_S`` before it; each
    ``S`` is the distance since the previous row (our choice, beyond the
    paper).  Why: at the record rate (100 Hz in the simulator and comma2k19)
    each row had a 1-mm sigma (``[odo] noise_sd_mps x T_m``) while successive
    wheel-tick speeds (a moving average) share most of their ticks, so their
    errors are not white; and in a GNSS outage the heading rows then moved the
    fused position by metres each (in turns the constant-acceleration
    prediction lags the heading, and the rows' gain to the position through P
    was large) and the distance rows by metres on mm of odometer noise.
    Coarser rows *and* a distance row at every heading epoch cut those gains;
    either alone did not (evidence:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf-inputs).
    ``q_s`` is metres per row, so ``[fkf] dist_err_rw_sd = 0.01`` at 0.05 s keeps the
    speed-equivalent random walk of 0.002 at 100 Hz (0.2 m/s per sqrt(s)).
    ``interval_s <= 0``: every record (Tang et al.).  An odometer dropout (:func:`dropouts`)
    ends a row and the next row starts after it: the row across it is NaN (not used).
    """
    m = len(o)
    if m < 2:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    t_odo = t_s[o]
    dt = np.diff(t_odo)
    gap = dropouts(dt)
    inc = speed[1:] * dt
    inc[gap] = 0.0                                   # a dropout: the distance in it is unknown
    cum = np.concatenate(([0.0], np.cumsum(inc)))
    if interval_s <= 0:
        use = o[1:]
        d = cum[1:] - cum[:-1]
        d[gap] = np.nan
        return use, d, t_odo[1:] - t_odo[:-1]
    slot = np.floor(t_odo / interval_s)              # t_odo in time order (epochs are)
    rows = o[np.flatnonzero(slot[1:] != slot[:-1]) + 1]
    after = o[np.flatnonzero(gap) + 1]               # the first record after each dropout
    rows = np.union1d(rows, after)
    if heading is not None:
        h = np.flatnonzero(heading)
        h = h[(t_s[h] > t_odo[0]) & (t_s[h] <= t_odo[-1])]
        last = np.searchsorted(t_odo, t_s[h], side="right") - 1     # latest record <= t
        h = h[t_s[h] - t_odo[last] <= STALE_ODO_S]
        rows = np.union1d(rows, h)
    t_row = t_s[rows]
    c_row = np.interp(t_row, t_odo, cum)
    dist = np.diff(np.concatenate(([0.0], c_row)))
    t_m = np.diff(np.concatenate(([t_odo[0]], t_row)))
    if len(after):  # the row that ends at a dropout's end spans it: no row (the next starts there)
        dist[np.isin(rows, after)] = np.nan
    return rows, dist, t_m


def dropouts(dt: np.ndarray) -> np.ndarray:
    """Which odometer record intervals (s) are dropouts (:data:`ODO_DROPOUT_S`)."""
    if len(dt) == 0:
        return np.zeros(0, bool)
    return dt > max(ODO_DROPOUT_S, 5.0 * float(np.median(dt)))


def prepare(epochs: Epochs, params: Params) -> Prepared:
    """Kernel inputs from epochs and parameters (see the module docstring)."""
    fp = params["fkf"]
    ap = params["fafkf"]
    sp = params["standstill"]
    n = len(epochs)
    t_s = (epochs.t_ns - epochs.t_ns[0]) / NS_PER_S
    gnss_on = bool(epochs.has_gnss.any())
    dr_on = bool(epochs.has_gyro.any() or epochs.has_odo.any())
    if not (gnss_on or dr_on):
        raise NoDataError(None, "fkf/fafkf: no usable GNSS fix and no gyro or odometer record; "
                                "expected at least one stream with data")
    if fp["mode"] not in ("nr", "fr"):
        raise ConfigError(f"fkf.mode = {fp['mode']!r}: expected \"nr\" or \"fr\"")
    if ap["weights"] not in ("shares", "scalar", "block"):
        raise ConfigError(f"fafkf.weights = {ap['weights']!r}: expected \"shares\", "
                          "\"scalar\" or \"block\"")
    if ap["normalisation"] not in ("share", "log"):
        raise ConfigError(f"fafkf.normalisation = {ap['normalisation']!r}: "
                          "expected \"share\" or \"log\"")
    if ap["window"] < 1:
        raise ConfigError(f"fafkf.window = {ap['window']}: expected an integer >= 1")

    # ---- heading measurement Theta from the gyro ------------------------------------
    t_a, psi_a, source = heading_alignment(epochs, t_s, params)
    theta = np.full(n, np.nan)
    g = np.flatnonzero(epochs.has_gyro)
    o = np.flatnonzero(epochs.has_odo)
    odo_spikes = 0
    if len(o):
        speed, odo_spikes = despike(np.abs(epochs.odo_speed_mps[o]), fp["odo_spike_mps"])
    eps_w = multipath_regime(epochs, params)
    # the receiver's course and speed only where the wheels do not say the car is slower
    wheels = (odometer_held(epochs, t_s, o, speed) if len(o)
              else (np.zeros(n, bool), np.zeros(n)))
    moving = wheels_moving(*wheels, fp["course_min_speed_mps"])
    # positions only (GGA without RMC/VTG, a ROS NavSatFix): course and odometer scale
    # from chords between fixes instead of the receiver's course and speed
    v_share = epochs.velocity_share
    from_fixes = bool(gnss_on and v_share < fp["fix_course_velocity_share"])
    chords = None
    if len(g):
        tg = t_s[g]
        rate, gyro_spikes = despike(-epochs.yaw_rate_radps[g], fp["gyro_spike_radps"])
        # rate: d(psi)/dt, clockwise-positive
        integral = np.zeros(len(g))
        integral[1:] = np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(tg))
        psi_g = psi_a + integral - np.interp(t_a, tg, integral)
        if from_fixes:
            t_odo, sp_odo = (t_s[o], speed) if len(o) else (None, None)
            chords = fix_chords(epochs, t_s, tg, psi_g, t_odo, sp_odo, eps_w, params)
            psi_g = psi_g + chord_course_correction(chords, tg, params)
            if len(chords.t_mid) >= 2 and fp["fix_course_window_s"] > 0:
                source = "fix_chords"       # the alignment was only the chords' reference
            if len(o):      # the chords again, dead-reckoned with the corrected heading
                chords = fix_chords(epochs, t_s, tg, psi_g, t_s[o], speed, eps_w, params)
        else:
            psi_g = psi_g + course_correction(epochs, t_s, tg, psi_g, params, moving)
        slot = np.floor(tg / max(fp["heading_interval_s"], 1e-9))
        if np.all(slot[1:] >= slot[:-1]):               # epochs are in time order: O(n)
            first = np.flatnonzero(np.concatenate(([True], slot[1:] != slot[:-1])))
        else:
            _, first = np.unique(slot, return_index=True)
        use = g[first]
        # no heading row where the wheels say the car is slower than omega_min: the kernel
        # skips the row below that *predicted* speed, but at a stop the constant-acceleration
        # model carries the velocity through zero to a direction that is noise, and a heading
        # row linearised there (d atan2 / dv ~ 1/v) threw it to metres per second, which the
        # zero-velocity rows then read, through the row's covariance, as heading error q_w
        # (urban_nlos seed 19 fafkf: q_w 2.5 -> 58 deg at a stop, the track 143 m off after it)
        slow = ~wheels_moving(*wheels, sp["omega_min_speed_mps"])
        first = first[~slow[use]]
        use = use[~slow[use]]
        theta[use] = np.angle(np.exp(1j * psi_g[first]))     # wrapped to (-pi, pi]
        if from_fixes:      # the heading at the start: the corrected gyro heading
            psi0 = float(np.interp(0.0, tg, psi_g))
        else:
            psi0 = float(psi_a - np.interp(t_a, tg, integral) + np.interp(0.0, tg, integral))
    else:
        psi0 = psi_a
        gyro_spikes = 0
        if len(o) and gnss_on and not from_fixes:
            # no gyro: the course at both ends of a straight outage (outage_headings)
            use, value = outage_headings(epochs, t_s, o, params)
            theta[use] = value

    # ---- odometer distance S and standstill -----------------------------------------
    dist = np.full(n, np.nan)
    t_m = np.zeros(n)
    odo_scale = 1.0
    speed0 = math.nan
    static = np.zeros(n, bool)
    if len(o):
        if from_fixes and chords is None:       # no gyro: straight chords for the scale
            chords = fix_chords(epochs, t_s, None, None, t_s[o], speed, eps_w, params)
        if float(fp["known_odo_scale"]) > 0:
            odo_scale = float(fp["known_odo_scale"])
            scale = np.full(len(o), odo_scale)
        elif chords is not None:
            scale, odo_scale = chord_odometer_scale(chords, t_s[o], params)
        else:
            scale, odo_scale = odometer_scale(epochs, t_s, t_s[o], speed, params, moving)
        speed = speed * scale
        rows, d_rows, tm_rows = distance_rows(t_s, o, speed, fp["distance_interval_s"],
                                              np.isfinite(theta))
        t_m[rows] = tm_rows
        dist[rows] = d_rows
        speed0 = float(speed[0])
        if sp["enabled"]:
            fresh, held = odometer_held(epochs, t_s, o, speed)   # the scaled speed
            static = fresh & (held < sp["speed_mps"])
            if gnss_on and not fresh.all():  # a silent odometer: the receiver's speed says when
                gnss_static = standstill_from_gnss(epochs, t_s, params,
                                                   (t_s[g], psi_g) if len(g) else None)
                static |= ~fresh & gnss_static
    elif sp["enabled"] and gnss_on:        # no odometer: the receiver's speed says when stopped
        static = standstill_from_gnss(epochs, t_s, params, (t_s[g], psi_g) if len(g) else None)

    # ---- initial state ---------------------------------------------------------------
    x0 = np.zeros(kf.NX)
    f = np.flatnonzero(epochs.has_gnss)
    if len(f):
        x0[kf.IE] = epochs.gnss_e[f[0]]
        x0[kf.IN] = epochs.gnss_n[f[0]]
        if not math.isfinite(speed0) and math.isfinite(epochs.gnss_speed_mps[f[0]]):
            speed0 = float(epochs.gnss_speed_mps[f[0]])
    if not math.isfinite(speed0):
        speed0 = 0.0
    x0[kf.IVE] = speed0 * math.sin(psi0)
    x0[kf.IVN] = speed0 * math.cos(psi0)

    g_p = params["gnss"]
    par = np.zeros(kf.N_PAR)
    par[kf.PAR_JERK_PSD] = fp["jerk_psd_m2ps5"]
    par[kf.PAR_QW_RW] = fp["heading_err_rw_sd"]
    par[kf.PAR_QS_RW] = fp["dist_err_rw_sd"]
    par[kf.PAR_HEAD_SD] = fp["heading_sd_rad"]
    par[kf.PAR_ODO_SD] = params["odo"]["noise_sd_mps"]
    par[kf.PAR_ZUPT_SD] = sp["zupt_sd_mps"]
    par[kf.PAR_OMEGA_MIN] = max(sp["omega_min_speed_mps"], 1e-3)
    par[kf.PAR_GATE_CHI2] = gate_threshold(g_p["gate_prob"], 2) if g_p["gate"] else 0.0
    par[kf.PAR_GATE_RESET_S] = g_p["gate_reset_s"]
    if not len(o) and not epochs.has_gyro.any():    # GNSS only: the model alone judges the fixes
        par[kf.PAR_GATE_RESET_S] = gnss_only_gate_reset_s(params)
    elif not len(o) and fp["no_odo_gate_reset_s"] > 0:   # no odometer: the state is the outlier sooner
        par[kf.PAR_GATE_RESET_S] = min(g_p["gate_reset_s"], fp["no_odo_gate_reset_s"])
    par[kf.PAR_GATE_WARMUP] = g_p["gate_warmup_fixes"]
    # the eps gate (kernels_fkf): with an odometer only, as gate_reset_s.  Without one the
    # fixes' Doppler alone carries the position, and eps is what keeps their offsets out of
    # it: 40 short city drives without an odometer 0.919 -> 0.942 of the fixes' RMSE with it
    par[kf.PAR_EPS_GATE_S] = g_p["gate_reset_s"] if fp["eps_gate"] and len(o) else 0.0
    par[kf.PAR_GVEL_VAR] = fp["gnss_velocity_sd_mps"] ** 2 if fp["gnss_velocity"] else 0.0
    par[kf.PAR_VGATE_VAR] = g_p["velocity_gate_floor_mps"] ** 2
    # not no_odo_gate_reset_s (but on NLOS drives, gnss_model.reflected_doppler): at 3 s the
    # gate took the last velocity of a 3-s run 45 deg off, and the track left (decisions/0031)
    par[kf.PAR_VGATE_RESET_S] = g_p["velocity_gate_reset_s"]
    par[kf.PAR_TAU_EPS_C] = fp["gnss_err_tau_s"]
    par[kf.PAR_EPS_SD_C] = fp["gnss_err_sd_m"]
    par[kf.PAR_EPS_DIST_C] = fp["gnss_err_dist_m"]
    par[kf.PAR_TAU_EPS_O] = fp["gnss_err_obstructed_tau_s"]
    par[kf.PAR_EPS_SD_O] = fp["gnss_err_obstructed_sd_m"]
    par[kf.PAR_EPS_DIST_O] = fp["gnss_err_obstructed_dist_m"]
    par[kf.PAR_R_MIN] = ap["r_min_factor"]
    par[kf.PAR_R_MAX] = ap["r_max_factor"]
    par[kf.PAR_DELTA_MAX] = ap["delta_max"]
    par[kf.PAR_RES_CLIP] = ap["residual_clip"]
    par[kf.PAR_RES_DEMEAN] = float(bool(ap["remove_residual_mean"]))
    par[kf.PAR_BETA_GNSS] = fp["beta_gnss"]
    par[kf.PAR_V_LIN] = max(fp["v_lin_mps"], 1e-3)
    par[kf.PAR_HEAD_CHI2] = chi2_1(g_p["gate_prob"]) if g_p["gate"] else 0.0
    par[kf.PAR_GNSS_STALE_S] = epochs.gap_s
    par[kf.PAR_DR_STALE_S] = fp["dr_stale_s"]
    # no odometer: in GNSS outages nothing measures the speed (kernels_fkf: zero-acceleration rows)
    par[kf.PAR_COAST_Q] = fp["coast_acc_psd"]  # the kernel coasts only while no distance is fresh
    # no gyro, no odometer: a no-fix record measures nothing, its epoch is held (kernels_fkf)
    par[kf.PAR_NO_DR] = 0.0 if dr_on else 1.0
    par[kf.PAR_NO_DR_VEL_Q] = max(float(fp["no_dr_vel_psd"]), 0.0)
    par[kf.PAR_NO_DR_HEAD_Q] = max(float(fp["no_dr_heading_psd"]), 0.0)
    positive = {"fkf.heading_sd_rad": fp["heading_sd_rad"], "odo.noise_sd_mps": par[kf.PAR_ODO_SD],
                "standstill.zupt_sd_mps": sp["zupt_sd_mps"], "fkf.gnss_err_sd_m": fp["gnss_err_sd_m"],
                "fkf.gnss_err_obstructed_sd_m": fp["gnss_err_obstructed_sd_m"],
                "fkf.gnss_err_tau_s": fp["gnss_err_tau_s"],
                "fkf.gnss_err_obstructed_tau_s": fp["gnss_err_obstructed_tau_s"]}
    for key, value in positive.items():
        if not value > 0:
            raise ConfigError(f"{key} = {value}: expected a value > 0 (a zero sigma makes a "
                              "measurement or state exact, a zero time constant makes the filter "
                              "divide by zero)")
    if not (par[kf.PAR_TAU_EPS_C] > 0 and 0 < par[kf.PAR_R_MIN] <= 1.0 <= par[kf.PAR_R_MAX]):
        raise ConfigError("fkf.gnss_err_tau_s must be > 0 and fafkf.r_min_factor <= 1 <= "
                          f"fafkf.r_max_factor (got {par[kf.PAR_TAU_EPS_C]}, {par[kf.PAR_R_MIN]}, "
                          f"{par[kf.PAR_R_MAX]})")
    # the eps model at the start (tau, sigma, distance of the first epoch's regime): the
    # kernel's own blend, which also gives eps's initial sigma
    kf.select_eps(par, float(eps_w[0]) if len(eps_w) else 0.0)
    P0 = np.diag(np.array([
        fp["init_pos_sd_m"], fp["init_vel_sd_mps"], fp["init_acc_sd_mps2"],
        fp["init_pos_sd_m"], fp["init_vel_sd_mps"], fp["init_acc_sd_mps2"],
        par[kf.PAR_EPS_SD], par[kf.PAR_EPS_SD],
        fp["init_heading_err_sd_rad"], fp["init_dist_err_sd_m"]]) ** 2)

    flags = np.zeros(kf.N_FLAGS, np.int64)
    flags[kf.FLG_MODE_FR] = fp["mode"] == "fr"
    flags[kf.FLG_FUSION] = {"shares": kf.FUSE_SHARES, "scalar": kf.FUSE_SCALAR,
                          "block": kf.FUSE_BLOCK}[ap["weights"]]
    flags[kf.FLG_NORM] = ap["normalisation"] == "log"
    flags[kf.FLG_WINDOW] = ap["window"]
    flags[kf.FLG_GNSS_ON] = gnss_on
    flags[kf.FLG_DR_ON] = dr_on
    flags[kf.FLG_STORE] = bool(params["filter"]["smooth"])
    flags[kf.FLG_CHECK_SPD] = bool(fp["check_spd"])

    f = np.flatnonzero(epochs.has_gnss)                # only the fix epochs are computed
    spd, crs = epochs.gnss_speed_mps[f], epochs.gnss_course_rad[f]
    mv = f[np.isfinite(spd) & np.isfinite(crs) & (spd >= fp["gnss_velocity_min_mps"])]
    gv_e = np.full(n, np.nan)
    gv_n = np.full(n, np.nan)
    gv_e[mv] = epochs.gnss_speed_mps[mv] * np.sin(epochs.gnss_course_rad[mv])
    gv_n[mv] = epochs.gnss_speed_mps[mv] * np.cos(epochs.gnss_course_rad[mv])
    var_e = np.ones(n)
    var_n = np.ones(n)
    var_e[f] = epochs.gnss_sd_e[f] ** 2
    var_n[f] = epochs.gnss_sd_n[f] ** 2
    info = {"heading_alignment": source, "heading_alignment_t_s": t_a,
            "gyro_spikes_removed": gyro_spikes, "odo_spikes_removed": odo_spikes,
            "odo_scale": odo_scale,
            "local_filters": ",".join(name for name, on in (("gnss", gnss_on), ("dr", dr_on)) if on)}
    if from_fixes:      # positions only: say so, and how many chords stood in for the course
        info["course_source"] = "fix_chords"
        info["fix_chords"] = 0 if chords is None else len(chords.t_mid)
        info["receiver_velocity_share"] = v_share
    return Prepared(dt=np.ascontiguousarray(epochs.dt_s, dtype=float),
                    has_gnss=np.ascontiguousarray(epochs.has_gnss, dtype=bool),
                    gnss_e=np.nan_to_num(epochs.gnss_e), gnss_n=np.nan_to_num(epochs.gnss_n),
                    gnss_var_e=var_e, gnss_var_n=var_n, gnss_ve=gv_e, gnss_vn=gv_n, theta=theta,
                    dist=dist, t_m=t_m,
                    static=static, eps_w=eps_w, x0=x0, P0=P0, psi0=psi0, par=par, flags=flags, info=info)
