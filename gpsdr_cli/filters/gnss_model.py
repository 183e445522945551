"""The GNSS error model every filter shares: fix quality and the dead reckoning's word.

The filters model a fix's error as white noise (each fix's base sigma, from GST, a
covariance or HDOP x the UERE of its quality: :func:`gpsdr_cli.align.base_sigma`) plus
a Gauss-Markov bias per axis (multipath).  This module sets, per drive, what the
receiver's own figures cannot say:

* **RTK.** On a drive whose fixes are mostly RTK fixed (GGA quality 4, centimetres) a
  bias of metres lets the track wander metres from the fixes, so there the bias's sigma
  becomes ``[gnss] rtk_err_sd_m``.
* **NLOS.** Reflected signals give errors of tens of metres that persist for seconds to
  minutes under a good HDOP, consistent among themselves, so neither HDOP nor a gate on
  one fix sees them.  What does: over a few seconds (``[gnss] nlos_lag_s``) the distance
  between two fixes disagrees with the distance the odometer (else the receiver's
  Doppler speed) measured.  Each fix whose chord disagrees by more than
  ``nlos_mismatch_m``, in a run of such fixes lasting ``nlos_run_s`` or more (a step's
  ramp plus the chord; a burst of outliers is the gate's), gets its sigma scaled by ``mismatch /
  nlos_mismatch_m`` (a Huber weight on that fix).  A drive where at least
  ``nlos_drive_share`` of the fixes are so marked is an NLOS drive: ekf/aekf's bias sigma
  becomes ``nlos_err_sd_m``, so they let the dead reckoning carry the shape and average
  the fixes over the bias's correlation time instead of following each step (fkf/fafkf
  keep their two-regime bias model: a larger sigma there was worse on the NLOS scenario).
  The distance alone misses a step across the street at speed (a 20-m chord with a 20-m
  sideways ramp is only 8 m longer), and 70 % of reflected-signal offsets on a street lie
  across it; with a gyro the chord is also compared as a vector with the dead reckoning's
  own displacement (odometer, else Doppler speed) over ``nlos_vector_lag_s``, turned onto
  east/north by the local median of all chords' rotation (most chords lie inside one
  offset's plateau and are right even where most fixes are reflected).  A drive where at least
  ``nlos_vector_share`` of the fixes sit in runs of ``nlos_vector_run_s`` or more of vector
  mismatch beyond ``nlos_vector_mismatch_m`` is an NLOS drive too, when the dead
  reckoning is healthy (a step holds its offset for the whole lag; a canyon's burst of
  outliers, shorter than the run, does not).  The per-fix sigmas still come from the
  distance check.
  Without an odometer the receiver's Doppler velocity carries ekf/aekf's speed, and
  reflected signals bias it by metres per second: its sigma becomes at least
  ``nlos_velocity_sd_mps``.  fkf/fafkf's GNSS local filter takes that velocity as a
  measurement of its own: on an NLOS drive its sigma becomes at least
  ``nlos_fkf_velocity_sd_mps`` (0.5 m/s: a reflected Doppler's bias held over a step
  otherwise pulled their speed 8-15 % high for a minute; 2 m/s put them at the fixes'
  error without an odometer; decisions/0029).

* **Clamped speeds.** Some receivers report a speed of exactly 0 below a threshold
  (SiRF's static navigation) while their fixes move on at 1-2 m/s; taken as a measurement
  and as a standstill, that zero held the track metres behind the fixes.  A zero speed at
  a fix whose own displacement (the median positions either side,
  :func:`.standstill.fix_speeds` over ``[fkf] fix_standstill_window_s``) is faster than
  ``fix_standstill_speed_mps`` (the speed that ends a positions-only stop) is dropped with
  its course by :func:`clamped_speeds`, once, as the epochs are built
  (:func:`gpsdr_cli.align.build_epochs`; decisions/0051).  Only an exact zero: a Doppler
  speed measured at a stop scatters by centimetres per second, and a reflected fix's jump
  in a city must not cost the filters a real stop (a speed threshold did: 3 more of 40
  simulated city drives without an odometer above their fixes).

Applied by the filter registry (:func:`gpsdr_cli.filters.register`) to every run, so
no caller can skip it (the clamped speeds excepted: they are the input's, dropped once).
Units: metres, seconds.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..config import Params
from ..conventions import FIX_FLOAT_RTK, NS_PER_S
from ..epochs import Epochs, true_runs
from ..errors import ConfigError
from ..rtk_false_fix import centimetre_fixes

#: a speed reading older than this (s) is not trusted for the chord check
SPEED_MAX_AGE_S = 0.5


def gnss_only_gate_reset_s(params: Params) -> float:
    """s: ``[gnss] gate_reset_s`` on a GNSS-only drive (no gyro, no odometer), every filter.

    ``[gnss] gnss_only_gate_reset_s``, else ``[fkf] no_odo_gate_reset_s`` (0 in both: the
    full ``gate_reset_s``).  A white-jerk or current-statistical model cannot foresee the end
    of a turn: a simulated 1-Hz U-turn at 10 m/s^2 had the next three fixes gated, each
    farther from the prediction (18, 44, 75 m), until a 3-s reset let them in
    (docs/decisions/0054).
    """
    for sec, key in (("gnss", "gnss_only_gate_reset_s"), ("fkf", "no_odo_gate_reset_s")):
        if float(params[sec][key]) > 0.0:
            return min(float(params["gnss"]["gate_reset_s"]), float(params[sec][key]))
    return float(params["gnss"]["gate_reset_s"])


def pdop_factors(pdop: np.ndarray, g: dict) -> tuple[np.ndarray, np.ndarray]:
    """R factor k and Q factor K_a for each PDOP (Fang et al.'s table; NaN PDOP -> good)."""
    good, poor = float(g["pdop_good"]), float(g["pdop_poor"])
    ks = np.array([g["k_good"], g["k_medium"], g["k_poor"]], float)
    kas = np.array([g["ka_good"], g["ka_medium"], g["ka_poor"]], float)
    p = np.where(np.isfinite(pdop), pdop, -np.inf)
    mode = g["pdop_mode"]
    if mode == "regimes":
        reg = np.where(p < good, 0, np.where(p < poor, 1, 2))
        return ks[reg], kas[reg]
    if mode == "continuous":
        xp = np.array([good, 0.5 * (good + poor), poor])
        pc = np.clip(p, good, poor)
        return np.exp(np.interp(pc, xp, np.log(ks))), np.exp(np.interp(pc, xp, np.log(kas)))
    raise ConfigError(f"gnss.pdop_mode = {mode!r}: expected \"regimes\" or \"continuous\"")


def _held(has: np.ndarray, values: np.ndarray, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each epoch's latest reading (0 before the first), and a counter that steps at every
    epoch whose reading is older than ``SPEED_MAX_AGE_S`` (a held reading is no measurement)."""
    idx = np.maximum.accumulate(np.where(has & np.isfinite(values), np.arange(len(has)), -1))
    age = np.where(idx >= 0, (t_ns - t_ns[np.maximum(idx, 0)]) / NS_PER_S, np.inf)
    return (np.where(idx >= 0, values[np.maximum(idx, 0)], 0.0),
            np.concatenate(([0], np.cumsum(age > SPEED_MAX_AGE_S))))


def chord_mismatch_m(epochs: Epochs, lag_s: float) -> np.ndarray:
    """Per usable fix, | |p_i - p_j| - DR distance(t_j, t_i) | (m) with j the fix nearest
    ``lag_s`` before i; NaN where no earlier fix is within 1.5 lag or the drive has no
    speed (odometer, else the receiver's Doppler speed)."""
    f = np.flatnonzero(epochs.has_gnss)
    out = np.full(len(f), np.nan)
    if len(f) < 3:
        return out
    if epochs.has_odo.any():
        has, values = epochs.has_odo, epochs.odo_speed_mps
    elif np.isfinite(epochs.gnss_speed_mps).any():
        has, values = epochs.has_gnss, epochs.gnss_speed_mps
    else:
        return out
    # each epoch's latest speed reading; a chord is judged only where that reading is
    # fresh at every epoch it spans
    speed, stale = _held(has, values, epochs.t_ns)
    speed = np.abs(speed)
    dist = np.concatenate(([0.0], np.cumsum(speed[:-1] * epochs.dt_s[1:])))
    t = epochs.t_ns[f] / NS_PER_S
    j = np.clip(np.searchsorted(t, t - lag_s), 0, len(f) - 1)
    ok = (t - t[j] >= 0.5 * lag_s) & (t - t[j] <= 1.5 * lag_s)
    ok &= stale[f + 1] == stale[f[j]]   # no stale epoch in (t_j, t_i]
    chord = np.hypot(epochs.gnss_e[f] - epochs.gnss_e[f[j]], epochs.gnss_n[f] - epochs.gnss_n[f[j]])
    mis = np.abs(chord - (dist[f] - dist[f[j]]))
    out[ok] = mis[ok]
    return out


#: window (s) of the local median that turns the dead reckoning's chords onto east/north:
#: a MEMS gyro's bias of 0.3 deg/s turns them by 0.08 rad across it
VECTOR_WINDOW_S = 30.0
#: a chord shorter than this (m), GNSS or dead reckoning, has no direction to vote with
VECTOR_MIN_CHORD_M = 3.0


def chord_vector_mismatch_m(epochs: Epochs, lag_s: float) -> np.ndarray:
    """Per usable fix, | (p_i - p_j) - R (d_i - d_j) | (m): the chord to the fix nearest
    ``lag_s`` before, against the dead reckoning's displacement (odometer speed, else the
    receiver's Doppler speed, along the gyro's integrated heading, in its own frame) turned
    by R, the local median over ``VECTOR_WINDOW_S`` of every chord's rotation.  NaN where
    not judged, and everywhere on a drive without a gyro or without any speed.

    Without an odometer the Doppler speed stands in: a reflected Doppler is about 1 m/s off,
    8 m over an 8-s chord, while reflected fixes move tens of metres across the street, which
    the chord's length barely shows (7 of 40 simulated city drives went uncalled;
    decisions/0040)."""
    f = np.flatnonzero(epochs.has_gnss)
    out = np.full(len(f), np.nan)
    if epochs.has_odo.any():
        has_speed, speed_mps = epochs.has_odo, epochs.odo_speed_mps
    else:
        has_speed, speed_mps = epochs.has_gnss, epochs.gnss_speed_mps
    if len(f) < 3 or not (epochs.has_gyro.any() and np.isfinite(speed_mps[has_speed]).any()):
        return out
    import pandas as pd

    dt = epochs.dt_s[1:]
    rate, stale_gyro = _held(epochs.has_gyro, epochs.yaw_rate_radps, epochs.t_ns)
    speed, stale_speed = _held(has_speed, speed_mps, epochs.t_ns)
    psi = np.concatenate(([0.0], np.cumsum(rate[:-1] * dt)))
    speed = np.abs(speed[:-1]) * dt
    dr = np.concatenate(([0.0], np.cumsum(speed * np.exp(1j * psi[:-1]))))  # east + i north
    t = epochs.t_ns[f] / NS_PER_S
    j = np.clip(np.searchsorted(t, t - lag_s), 0, len(f) - 1)
    ok = (t - t[j] >= 0.5 * lag_s) & (t - t[j] <= 1.5 * lag_s)
    ok &= (stale_speed[f + 1] == stale_speed[f[j]]) & (stale_gyro[f + 1] == stale_gyro[f[j]])
    c = (epochs.gnss_e[f] - epochs.gnss_e[f[j]]) + 1j * (epochs.gnss_n[f] - epochs.gnss_n[f[j]])
    d = dr[f] - dr[f[j]]
    vote = ok & (np.abs(c) > VECTOR_MIN_CHORD_M) & (np.abs(d) > VECTOR_MIN_CHORD_M)
    if not vote.any():
        return out
    z = np.full(len(f), np.nan + 0j)
    z[vote] = c[vote] / d[vote]
    z[vote] /= np.abs(z[vote])
    # a window in time, not in fixes: across a GNSS outage the votes come from another
    # stretch of the gyro's drift (a tunnel drive run backwards read 25 deg against 3 deg)
    at = pd.to_timedelta(t - t[0], unit="s")
    window = pd.Timedelta(seconds=VECTOR_WINDOW_S)
    rot = (pd.Series(z.real, index=at).rolling(window, center=True, min_periods=5).median().to_numpy()
           + 1j * pd.Series(z.imag, index=at).rolling(window, center=True,
                                                      min_periods=5).median().to_numpy())
    judged = ok & np.isfinite(rot) & (np.abs(rot) > 0)
    out[judged] = np.abs(c[judged] - rot[judged] / np.abs(rot[judged]) * d[judged])
    return out


def _run_share(t_s: np.ndarray, flagged: np.ndarray, known: np.ndarray, run_s: float) -> float:
    """Share of the known fixes inside runs of ``flagged`` fixes lasting ``run_s`` or more."""
    starts, last = true_runs(flagged)
    long_run = (t_s[last] - t_s[starts]) >= run_s
    return float(np.sum((last - starts + 1)[long_run])) / max(int(known.sum()), 1)


def gnss_error_model(epochs: Epochs, params: Params, *,
                     vector: bool = True) -> tuple[Epochs, Params]:
    """``(epochs, params)`` with each fix's sigma and the GNSS error states' sigmas for
    this drive's fix quality and its agreement with the dead reckoning, the same for every
    filter; ``epochs.nlos_drive`` says whether the drive has reflected signals (NLOS).
    ``vector``: the vector chord may call the drive NLOS (not when the fixes the NLOS screen
    kept are judged again: those agree with the dead reckoning by construction)."""
    g = params["gnss"]
    if rtk_drive(epochs, params):
        return rtk_error_model(epochs, params)
    thr = float(g["nlos_mismatch_m"])
    if not thr > 0.0:
        return epochs, params
    mis = chord_mismatch_m(epochs, float(g["nlos_lag_s"]))
    known = np.isfinite(mis)
    t_fix = epochs.t_ns[epochs.has_gnss] / NS_PER_S
    bad = np.zeros(len(mis), bool)
    if known.any():
        # a step of NLOS error disagrees over every chord that spans its ramp: a run of
        # disagreeing fixes; a lone outlier (one fix, left to the gate) gives no run
        starts, last = true_runs(known & (mis > thr))
        long_run = (t_fix[last] - t_fix[starts]) >= float(g["nlos_run_s"])
        mark = np.zeros(len(mis) + 1, np.int64)
        np.add.at(mark, starts[long_run], 1)
        np.add.at(mark, last[long_run] + 1, -1)
        bad = np.cumsum(mark[:-1]) > 0
    nlos = bool(known.any() and bad.sum() >= float(g["nlos_drive_share"]) * known.sum())
    # the vector chord takes the dead reckoning's shape as the truth: not with a clipping
    # gyro or a gappy odometer
    if vector and not nlos and not epochs.dr_unhealthy and float(g["nlos_vector_share"]) > 0.0:
        vec = chord_vector_mismatch_m(epochs, float(g["nlos_vector_lag_s"]))
        vknown = np.isfinite(vec)
        nlos = bool(vknown.any()) and _run_share(
            t_fix, vknown & (vec > float(g["nlos_vector_mismatch_m"])), vknown,
            float(g["nlos_vector_run_s"])) >= float(g["nlos_vector_share"])
    # ... and where the receiver's Doppler speeds disagree with the odometer's often enough:
    # a step whose plateau the chords never see still shifts the Doppler (decisions/0070)
    if (vector and not nlos and not epochs.dr_unhealthy and float(g["nlos_doppler_share"]) > 0.0
            and epochs.doppler_off_share >= float(g["nlos_doppler_share"])):
        nlos = True
    if not (bad.any() or nlos):
        return epochs, params
    f = np.flatnonzero(epochs.has_gnss)
    scale = np.ones(len(f))
    scale[bad] = mis[bad] / thr
    sd_e = epochs.gnss_sd_e.copy()
    sd_n = epochs.gnss_sd_n.copy()
    sd_e[f] *= scale
    sd_n[f] *= scale
    epochs = dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n, nlos_drive=nlos)
    if nlos:
        params = reflected_doppler(params, bool(epochs.has_odo.any()),  # a copy
                                   not epochs.dr_unhealthy)
        params["aekf"]["gnss_err_sd_m"] = float(g["nlos_err_sd_m"])
    return epochs, params


def clamped_speeds(epochs: Epochs, params: Params) -> Epochs:
    """``epochs`` without the receiver speeds (and courses) that say stopped where the
    fixes themselves move: a speed of exactly 0 at a fix whose
    :func:`.standstill.fix_speeds` exceeds ``[fkf] fix_standstill_speed_mps`` (m/s)."""
    from .standstill import fix_speeds

    fp = params["fkf"]
    window, thr = float(fp["fix_standstill_window_s"]), float(fp["fix_standstill_speed_mps"])
    f = np.flatnonzero(epochs.has_gnss)
    if not (window > 0.0 and thr > 0.0) or len(f) < 4:
        return epochs
    # exactly zero: a clamp, not a Doppler measurement (a measured standstill scatters by
    # centimetres per second; a reflected fix's jump at a real stop must not drop it)
    low = epochs.gnss_speed_mps[f] == 0.0
    if not low.any():
        return epochs
    # (the window centred on a stop's first or last fix still holds some of the braking or
    # the drive-off: a hard stop, 5 m/s^2, loses its first and last 0.2-0.4 s of zeros;
    # windows either side of the fix kept those but held a 1.2-m/s creep 3 s too long)
    moving = fix_speeds(epochs, (epochs.t_ns - epochs.t_ns[0]) / NS_PER_S, window) > thr
    drop = f[low & moving]
    if not len(drop):
        return epochs
    speed, course = epochs.gnss_speed_mps.copy(), epochs.gnss_course_rad.copy()
    speed[drop] = np.nan
    course[drop] = np.nan
    return dataclasses.replace(epochs, gnss_speed_mps=speed, gnss_course_rad=course)


def _at_least(section: dict, key: str, floor: float) -> None:
    """``section[key]`` raised to ``floor`` where below it."""
    section[key] = max(float(section[key]), float(floor))


def reflected_doppler(params: Params, has_odo: bool, dr_healthy: bool = True) -> Params:
    """``params`` with the receiver's velocity sigmas of an NLOS drive: reflected signals
    put the Doppler velocity metres per second off too.  fkf/fafkf: at least ``[gnss]
    nlos_fkf_velocity_sd_mps``; ekf/aekf without an odometer (the Doppler speed then carries
    their speed; 0.2 m/s drove aekf up to 2x the fixes): at least ``nlos_velocity_sd_mps``;
    with one, the receiver's velocity (ekf/aekf, at least ``nlos_odo_velocity_sd_mps`` while
    the dead reckoning is healthy: where the odometer falls silent the Doppler is the speed)
    and course (fkf/fafkf's steering) only at ``nlos_velocity_min_mps`` or faster, and fkf's
    odometer scale over ``nlos_odo_scale_window_s``.
    Without an odometer the receiver velocity's gate also resets after ``[fkf]
    no_odo_gate_reset_s`` (as the fixes'), not ``[gnss] velocity_gate_reset_s``, and
    ekf/aekf's zero-velocity update never moves the position in a pass no smoother follows
    (``[gnss] nlos_no_odo_zupt_keeps_position``).
    Applied on the whole NLOS drive, also to the fixes the NLOS screen keeps (some of them
    are reflected as well)."""
    out = copy.deepcopy(params)
    g = out["gnss"]
    k = out["fkf"]
    a = out["aekf"]
    _at_least(k, "gnss_velocity_sd_mps", g["nlos_fkf_velocity_sd_mps"])
    if has_odo:
        # the odometer measures the speed; at walking pace a reflected Doppler's course is off
        # by tens of degrees and turned ekf's heading 9.5 deg just after a stop (decisions/0037)
        _at_least(a, "gnss_velocity_min_mps", g["nlos_velocity_min_mps"])
        # ... and faster, a Doppler the screen kept can still be reflected: one 20 deg off the
        # course ended a run of kept fixes and turned aekf's heading 11 deg for 90 s
        # (decisions/0073)
        if dr_healthy:
            _at_least(a, "gnss_velocity_sd_mps", g["nlos_odo_velocity_sd_mps"])
        # ... and fkf's course steering: twelve courses 14 deg off at 3-5 m/s ended a 90-s
        # gap and turned its gyro heading 15 deg across it (decisions/0038)
        _at_least(k, "course_min_speed_mps", g["nlos_velocity_min_mps"])
        # a wheel's scale holds over the drive; the kept fixes' Dopplers are partly reflected,
        # and a window of them read 1.058 for 0.999 across a 100-s gap (decisions/0038)
        if float(k["odo_scale_window_s"]) > 0:
            _at_least(k, "odo_scale_window_s", g["nlos_odo_scale_window_s"])
    else:
        if float(k["no_odo_gate_reset_s"]) > 0:
            # the fixes, not the Doppler, are the suspects: fkf's state follows a reflected
            # step and then gates the Doppler that disagrees (decisions/0031)
            g["velocity_gate_reset_s"] = min(float(g["velocity_gate_reset_s"]),
                                             float(k["no_odo_gate_reset_s"]))
        _at_least(a, "gnss_velocity_sd_mps", g["nlos_velocity_sd_mps"])
        # a stop says nothing about where the car is; without an odometer the velocity a
        # ZUPT zeroes is the filter's own guess (the Doppler at 5 m/s), and its correlation
        # with the position moved a track 24 m off good fixes at one stop (decisions/0039).
        # Forward only: a smoother's gain takes the forward pass for the optimal one, and
        # over those consider rows RTS ran 2 x its forward pass (decisions/0081)
        if g["nlos_no_odo_zupt_keeps_position"] and not out["filter"]["smooth"]:
            out["standstill"]["zupt_keeps_position"] = "always"
    return out


def doppler_misfit(epochs: Epochs, min_speed_mps: float = 4.0, *,
                   steady_only: bool = False) -> np.ndarray:
    """Per epoch: the receiver's Doppler speed minus the odometer's (m/s; linear between two
    of its records at most ``ODO_GAP_S`` apart, scaled by :func:`densest_ratio` of the two
    above ``min_speed_mps``); NaN without a fix, a Doppler speed or the odometer around it,
    with ``steady_only`` also where either speed is ``min_speed_mps`` or less or the
    odometer's changes by more than ``STEADY_MPS2`` over ``STEADY_SPAN_S``, and everywhere
    when fewer than ten fixes are both moving and measured."""
    out = np.full(len(epochs), np.nan)
    f = np.flatnonzero(epochs.has_gnss & np.isfinite(epochs.gnss_speed_mps))
    o = np.flatnonzero(epochs.has_odo & np.isfinite(epochs.odo_speed_mps))
    if len(f) < 10 or len(o) < 10:
        return out
    t = np.asarray(epochs.t_ns, np.int64)
    t_f, t_o = (t[f] - t[o[0]]).astype(float), (t[o] - t[o[0]]).astype(float)
    odo = np.interp(t_f, t_o, epochs.odo_speed_mps[o])
    inside = (t[f] >= t[o[0]]) & (t[f] <= t[o[-1]])
    # ... and not across a pause in the odometer's records (a 30-s dropout read as a line)
    inside &= between_close_records(t[o], t[f], ODO_GAP_S * NS_PER_S)
    dop = epochs.gnss_speed_mps[f]
    moving = inside & (odo > min_speed_mps) & (dop > min_speed_mps)
    if moving.sum() < 10:
        return out
    scale = densest_ratio(dop[moving], odo[moving], SCALE_AGREE_MPS)
    use = inside
    if steady_only:
        # a GNSS clock 0.5 s off puts a 2-m/s^2 braking's Doppler 1 m/s off the wheel's, and
        # `--gnss-offset auto` had run to -0.52 s on a simulated 150-s canyon drive
        h = 0.5 * STEADY_SPAN_S * NS_PER_S
        acc = (np.interp(t_f + h, t_o, epochs.odo_speed_mps[o])
               - np.interp(t_f - h, t_o, epochs.odo_speed_mps[o])) / STEADY_SPAN_S
        use = moving & (np.abs(acc) <= STEADY_MPS2)
    out[f[use]] = (dop - scale * odo)[use]
    return out


#: the odometer is read at a fix only between two of its records at most this far apart (s;
#: a 1-Hz logger with jitter passes)
ODO_GAP_S = 2.0


def between_close_records(t_rec: np.ndarray, t: np.ndarray, max_gap: float) -> np.ndarray:
    """Per time in ``t``: whether the two records of ``t_rec`` (sorted, at least two) around it
    are at most ``max_gap`` apart (the units of the times), so that a value interpolated there
    is not a line across a pause.  Times outside ``t_rec`` are judged by its first or last
    interval; the caller bounds them."""
    j = np.clip(np.searchsorted(t_rec, t), 1, len(t_rec) - 1)
    return (t_rec[j] - t_rec[j - 1]) <= max_gap
#: the Doppler and odometer speeds of clean fixes agree within this (m/s) at the right scale
SCALE_AGREE_MPS = 0.2


def densest_ratio(num: np.ndarray, den: np.ndarray, tol: float) -> float:
    """The scale s for which the most pairs agree, |num - s den| <= ``tol`` (``den`` > 0),
    refined to the median ratio of those pairs.  The Doppler speeds of a run of reflected
    fixes are off together, and on a drive that is mostly reflected the median ratio of
    all of them read a wheel 4.5 % off, where its clean fixes agree at 1.00 (decisions/0069)."""
    lo, hi = (num - tol) / den, (num + tol) / den
    # the most intervals [lo, hi] over one point: a sweep over their ends
    ends = np.concatenate((lo, hi))
    step = np.concatenate((np.ones(len(lo)), -np.ones(len(hi))))
    order = np.lexsort((-step, ends))
    depth = np.cumsum(step[order])
    at = float(ends[order][int(np.argmax(depth))])
    agree = (lo <= at) & (hi >= at)
    return float(np.median(num[agree] / den[agree]))


def doppler_against_odometer(epochs: Epochs, max_mps: float, min_speed_mps: float = 4.0,
                             misfit: np.ndarray | None = None) -> tuple[Epochs, int]:
    """``(epochs, n)``: the receiver's speed and course cleared at the ``n`` fixes whose Doppler
    speed differs from the odometer's by more than ``max_mps`` (m/s; ``[gnss]
    nlos_doppler_odo_max_mps``; :func:`doppler_misfit`).  A clean Doppler speed and a wheel's agree
    to a few tenths (the wheel's noise and its lag in a 3-m/s^2 braking: 0.1-0.2 m/s); a
    reflected signal's Doppler is off by about 1 m/s (decisions/0029), and on the drive's few
    kept fixes such a velocity at 0.2 m/s turned the screen's judge, then the filters, tens of
    metres off (decisions/0067, 0068).  The position of such a fix stays: the screen judges it.
    ``misfit``: :func:`doppler_misfit` of these epochs at ``min_speed_mps``, when the caller
    has it already."""
    if max_mps <= 0:
        return epochs, 0
    if misfit is None:
        misfit = doppler_misfit(epochs, min_speed_mps)
    with np.errstate(invalid="ignore"):
        bad = np.abs(misfit) > max_mps
    if not bad.any():
        return epochs, 0
    speed, course = epochs.gnss_speed_mps.copy(), epochs.gnss_course_rad.copy()
    speed[bad] = np.nan
    course[bad] = np.nan
    return dataclasses.replace(epochs, gnss_speed_mps=speed, gnss_course_rad=course), int(bad.sum())


def doppler_off_share(epochs: Epochs, params: Params) -> float:
    """Share of the fixes measured by :func:`doppler_misfit` (``[gnss] nlos_velocity_min_mps``)
    whose Doppler speed is more than ``nlos_doppler_odo_max_mps`` off the odometer's, both
    speeds above the minimum (an odometer that reads nothing while the car drives is the
    health check's) and the speed steady (``STEADY_MPS2``); 0 with fewer than
    ``DOPPLER_SHARE_MIN_N`` measured.  On the simulator's
    clear-sky and multipath drives and on comma2k19's real highway: none; on its
    reflected-signal drives 7-27 % (decisions/0070)."""
    g = params["gnss"]
    thr = float(g["nlos_doppler_odo_max_mps"])
    m = doppler_misfit(epochs, float(g["nlos_velocity_min_mps"]), steady_only=True)
    ok = np.isfinite(m)
    if not thr > 0.0 or ok.sum() < DOPPLER_SHARE_MIN_N:
        return 0.0
    return float(np.mean(np.abs(m[ok]) > thr))


#: the Doppler share needs this many fixes measured against the odometer (10 s at 5 Hz) ...
DOPPLER_SHARE_MIN_N = 50
#: ... at a steady speed: the odometer's speed changing by at most this (m/s^2) over this (s)
STEADY_MPS2 = 0.5
STEADY_SPAN_S = 1.0


def drop_reflected_doppler(epochs: Epochs, params: Params, misfit: np.ndarray | None = None
                           ) -> tuple[Epochs, int]:
    """:func:`doppler_against_odometer` at ``[gnss] nlos_doppler_odo_max_mps``, the scale from
    speeds above ``nlos_velocity_min_mps``: the filters' registry and the graph smoother
    leave out the same velocities.  ``misfit``: :func:`doppler_misfit` at that speed, when
    the caller has it already."""
    g = params["gnss"]
    return doppler_against_odometer(epochs, float(g["nlos_doppler_odo_max_mps"]),
                                    float(g["nlos_velocity_min_mps"]), misfit)


def rtk_drive(epochs: Epochs, params: Params) -> bool:
    """At least ``[gnss] rtk_share`` of the drive's usable fixes are RTK fixed."""
    return epochs.rtk_fixed_share >= float(params["gnss"]["rtk_share"])


def rtk_bias_sd(epochs: Epochs, params: Params) -> np.ndarray | None:
    """Per epoch on an RTK drive (``[gnss] rtk_share``), the sigma (m) of the GNSS error
    states' regime, the fix kind's at or last before the epoch (the first fix's before it):
    ``rtk_err_sd_m`` at a centimetre fix (:func:`~gpsdr_cli.rtk_false_fix.centimetre_fixes`),
    ``rtk_float_err_sd_m`` at an RTK float fix (quality 5), ``rtk_free_err_sd_m`` at any
    other (autonomous, DGPS, a false RTK fix).  None on other drives (one regime).  The
    filters start a new, independent bias where it changes: the kinds of fix err apart, and
    float or autonomous fixes averaged at a stop must not pin the position their own bias
    holds (decision 0026)."""
    if not rtk_drive(epochs, params) or not epochs.has_gnss.any():
        return None
    g = params["gnss"]
    f = np.flatnonzero(epochs.has_gnss)
    sd = np.where(centimetre_fixes(epochs, params)[f], float(g["rtk_err_sd_m"]),
                  np.where(epochs.gnss_quality[f] == FIX_FLOAT_RTK, float(g["rtk_float_err_sd_m"]),
                           float(g["rtk_free_err_sd_m"])))
    last = np.searchsorted(f, np.arange(len(epochs)), side="right") - 1
    return sd[np.maximum(last, 0)]


def rtk_error_model(epochs: Epochs, params: Params) -> tuple[Epochs, Params]:
    """A drive with at least ``[gnss] rtk_share`` of its fixes RTK fixed (a fifth: long
    float or autonomous stretches under trees do not undo the centimetres where it is
    fixed, decision 0027): the centimetre fixes are taken at their word -- the GNSS error
    states pinned at ``[gnss] rtk_err_sd_m`` there (a regime per fix kind,
    :func:`rtk_bias_sd`), the standstill from the receiver's speed below
    ``rtk_standstill_speed_mps`` -- and every other fix (float, autonomous, or a
    centimetre fix judged false by :func:`gpsdr_cli.rtk_false_fix.mark_false_fixes`) gets
    its sigma x ``rtk_free_sd_factor``: its error, decimetres to metres, holds for seconds,
    which a white sigma at each fix would count as independent.  (ekf, with one sigma per
    fix class rather than per fix, takes the centimetre fixes' and the others' medians apart:
    :func:`gpsdr_cli.filters.aekf.gnss_noise`.)"""
    g = params["gnss"]
    cm = centimetre_fixes(epochs, params)
    free = epochs.has_gnss & ~cm
    k = float(g["rtk_free_sd_factor"])
    if k != 1.0 and free.any():
        sd_e = epochs.gnss_sd_e.copy()
        sd_n = epochs.gnss_sd_n.copy()
        sd_e[free] *= k
        sd_n[free] *= k
        epochs = dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n)
    out = copy.deepcopy(params)
    sd = float(g["rtk_err_sd_m"])
    out["aekf"]["gnss_err_sd_m"] = sd
    # fkf's two eps regimes become the fix kinds' (fkf_inputs.multipath_regime): centimetre
    # fixes clear, the others obstructed
    out["fkf"]["gnss_err_sd_m"] = sd
    out["fkf"]["gnss_err_obstructed_sd_m"] = float(g["rtk_free_err_sd_m"])
    # an RTK receiver's Doppler speed is good to centimetres per second: the standstill from
    # it may end sooner, before the pinned states would have to carry the first metre
    out["fkf"]["gnss_standstill_speed_mps"] = min(float(out["fkf"]["gnss_standstill_speed_mps"]),
                                                  float(g["rtk_standstill_speed_mps"]))
    return epochs, out
