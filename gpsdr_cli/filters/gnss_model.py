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

Applied by the filter registry (:func:`gpsdr_cli.filters.register`) to every run, so
no caller can skip it.  Units: metres, seconds.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..align import Epochs, true_runs
from ..config import Params
from ..conventions import NS_PER_S

#: a speed reading older than this (s) is not trusted for the chord check
SPEED_MAX_AGE_S = 0.5


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
    # each epoch's latest speed reading (0 before the first); a chord is judged only where
    # that reading is fresh at every epoch it spans: a held reading is no measurement
    idx = np.maximum.accumulate(np.where(has & np.isfinite(values), np.arange(len(has)), -1))
    speed = np.where(idx >= 0, np.abs(values[np.maximum(idx, 0)]), 0.0)
    age = np.where(idx >= 0, (epochs.t_ns - epochs.t_ns[np.maximum(idx, 0)]) / NS_PER_S, np.inf)
    stale = np.concatenate(([0], np.cumsum(age > SPEED_MAX_AGE_S)))
    dist = np.concatenate(([0.0], np.cumsum(speed[:-1] * epochs.dt_s[1:])))
    t = epochs.t_ns[f] / NS_PER_S
    j = np.clip(np.searchsorted(t, t - lag_s), 0, len(f) - 1)
    ok = (t - t[j] >= 0.5 * lag_s) & (t - t[j] <= 1.5 * lag_s)
    ok &= stale[f + 1] == stale[f[j]]   # no stale epoch in (t_j, t_i]
    chord = np.hypot(epochs.gnss_e[f] - epochs.gnss_e[f[j]], epochs.gnss_n[f] - epochs.gnss_n[f[j]])
    mis = np.abs(chord - (dist[f] - dist[f[j]]))
    out[ok] = mis[ok]
    return out


def gnss_error_model(epochs: Epochs, params: Params) -> tuple[Epochs, Params]:
    """``(epochs, params)`` with each fix's sigma and the GNSS error states' sigmas for
    this drive's fix quality and its agreement with the dead reckoning, the same for every
    filter; ``epochs.nlos_drive`` says whether the drive has reflected signals (NLOS)."""
    g = params["gnss"]
    if epochs.rtk_fixed_share >= float(g["rtk_share"]):
        return rtk_error_model(epochs, params)
    thr = float(g["nlos_mismatch_m"])
    if not thr > 0.0:
        return epochs, params
    mis = chord_mismatch_m(epochs, float(g["nlos_lag_s"]))
    known = np.isfinite(mis)
    if not known.any():
        return epochs, params
    # a step of NLOS error disagrees over every chord that spans its ramp: a run of
    # disagreeing fixes; a lone outlier (one fix, left to the gate) gives no run
    starts, last = true_runs(known & (mis > thr))
    t_fix = epochs.t_ns[epochs.has_gnss] / NS_PER_S
    long_run = (t_fix[last] - t_fix[starts]) >= float(g["nlos_run_s"])
    if not long_run.any():
        return epochs, params
    bad = np.zeros(len(mis), bool)
    mark = np.zeros(len(mis) + 1, np.int64)
    np.add.at(mark, starts[long_run], 1)
    np.add.at(mark, last[long_run] + 1, -1)
    bad = np.cumsum(mark[:-1]) > 0
    f = np.flatnonzero(epochs.has_gnss)
    scale = np.ones(len(f))
    scale[bad] = mis[bad] / thr
    sd_e = epochs.gnss_sd_e.copy()
    sd_n = epochs.gnss_sd_n.copy()
    sd_e[f] *= scale
    sd_n[f] *= scale
    nlos = bool(bad.sum() >= float(g["nlos_drive_share"]) * known.sum())
    epochs = dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n, nlos_drive=nlos)
    if nlos:
        params = copy.deepcopy(params)
        params["aekf"]["gnss_err_sd_m"] = float(g["nlos_err_sd_m"])
    return epochs, params


def centimetre_fixes(epochs: Epochs, params: Params) -> np.ndarray:
    """Per epoch, a usable fix whose base sigma on both axes is at most ``[gnss] rtk_cm_sd_m``
    (an RTK-fixed fix: GST or HDOP x ``uere_rtk_fixed_m``)."""
    sd = np.fmax(epochs.gnss_sd_e, epochs.gnss_sd_n)
    return epochs.has_gnss & (sd <= float(params["gnss"]["rtk_cm_sd_m"]))


def step_estimates(t_s: np.ndarray, e: np.ndarray, n: np.ndarray, sd: np.ndarray,
                   half: int, max_dt_s: float, v_e: np.ndarray | None = None,
                   v_n: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per fix i, the position step (m, east and north) between fix i-1 and fix i, and its
    1-sigma (m per axis), from a least-squares fit over ``half`` fixes either side (weighted
    by the fixes' sigmas ``sd``, m) of the motion plus a step at t_i: with the receiver's
    Doppler velocity ``v_e, v_n`` (m/s, finite at every fix) the positions less the velocity's
    integral are a line in time (a velocity bias), else the positions are a quadratic.
    A smooth motion has no step; a jump of the fixes has one.  NaN where the window has a gap
    over ``max_dt_s``, a fix without velocity (``v_e``/``v_n`` given) or leaves the series."""
    m = len(t_s)
    se = np.full(m, np.nan)
    sn = np.full(m, np.nan)
    ss = np.full(m, np.nan)
    if m < 2 * half + 1 or half < 2:
        return se, sn, ss
    doppler = v_e is not None and v_n is not None
    brk = np.diff(t_s) > max_dt_s
    if doppler:  # trapezoidal integral of the velocity; a window with a fix without one: NaN
        dt = np.diff(t_s)
        miss = ~(np.isfinite(v_e) & np.isfinite(v_n))
        v_e, v_n = np.where(miss, 0.0, v_e), np.where(miss, 0.0, v_n)
        e = e - np.concatenate(([0.0], np.cumsum(0.5 * (v_e[1:] + v_e[:-1]) * dt)))
        n = n - np.concatenate(([0.0], np.cumsum(0.5 * (v_n[1:] + v_n[:-1]) * dt)))
        brk = brk | miss[1:] | miss[:-1]
    centre = np.arange(half, m - half + 1)                       # window [c - half, c + half)
    idx = centre[:, None] + np.arange(-half, half)[None, :]
    gap = np.concatenate(([0], np.cumsum(brk)))
    ok = gap[idx[:, -1]] == gap[idx[:, 0]]
    centre, idx = centre[ok], idx[ok]
    if not len(centre):
        return se, sn, ss
    tau = t_s[idx] - t_s[centre][:, None]
    cols = [np.ones_like(tau), tau] + ([] if doppler else [tau * tau])
    A = np.stack(cols + [(tau >= 0).astype(float)], axis=2)
    wt = 1.0 / sd[idx] ** 2
    cov = np.linalg.inv(np.einsum("kij,ki,kil->kjl", A, wt, A))
    be = np.einsum("kjl,kil,ki,ki->kj", cov, A, wt, e[idx])
    bn = np.einsum("kjl,kil,ki,ki->kj", cov, A, wt, n[idx])
    se[centre], sn[centre] = be[:, -1], bn[:, -1]
    ss[centre] = np.sqrt(cov[:, -1, -1])
    return se, sn, ss


def false_fixes(epochs: Epochs, params: Params, cm: np.ndarray) -> np.ndarray:
    """Per epoch, the centimetre fixes judged wrong by an RTK false fix (a wrong integer
    ambiguity): the position jumps by decimetres while the receiver still reports
    centimetres, holds that offset for seconds, and jumps back when it fixes right.

    The centimetre fixes are cut into segments at every step (:func:`step_estimates` with
    the receiver's Doppler velocity, above ``[gnss] rtk_step_m`` and ``rtk_step_k`` sigmas,
    the largest within its window) and at every other fix or gap in between.  A run of
    segments joined by steps knows each segment's offset from the first; the offset held by
    the most fixes is the right one (a false fix lasts seconds, the right fix the rest), and
    the segments more than ``rtk_step_m`` off it are false."""
    g = params["gnss"]
    f = np.flatnonzero(cm)
    out = np.zeros(len(epochs), bool)
    half = int(g["rtk_step_half_fixes"])
    if len(f) < 2 * half + 1:
        return out
    t = epochs.t_ns[f] / NS_PER_S
    e, n = epochs.gnss_e[f], epochs.gnss_n[f]
    sd = np.fmax(epochs.gnss_sd_e[f], epochs.gnss_sd_n[f])
    max_dt = float(g["rtk_step_max_dt_s"])
    # the receiver's velocity (a speed with no course: too slow to have one).  Without it
    # the check is off: a quadratic's misfit in a city turn reached 0.16 m (rtk scenario),
    # as large as the smallest false fix
    spd = epochs.gnss_speed_mps[f]
    crs = np.where(np.isfinite(epochs.gnss_course_rad[f]), epochs.gnss_course_rad[f], 0.0)
    se, sn, ss = step_estimates(t, e, n, sd, half, max_dt, spd * np.sin(crs), spd * np.cos(crs))
    size = np.hypot(se, sn)
    thr = float(g["rtk_step_m"])
    cand = np.isfinite(size) & (size > thr) & (size > float(g["rtk_step_k"]) * ss * np.sqrt(2.0))
    # the step sits where its estimate peaks: its neighbours see part of it
    sz = np.where(np.isfinite(size), size, 0.0)
    peak = np.ones(len(f), bool)
    for k in range(1, half + 1):
        peak[k:] &= sz[k:] >= sz[:-k]
        peak[:-k] &= sz[:-k] > sz[k:]
    step = cand & peak
    # a break: another epoch's fix (not centimetres) or a gap between consecutive cm fixes
    other = np.cumsum(epochs.has_gnss & ~cm)
    brk = np.zeros(len(f), bool)
    brk[1:] = (other[f[1:]] != other[f[:-1]]) | (np.diff(t) > max_dt)
    seg = np.cumsum(step | brk)                  # segment id per cm fix
    grp = np.cumsum(brk)                         # run of segments joined by steps
    off_e = np.cumsum(np.where(step, se, 0.0))   # offset since the drive's first cm fix
    off_n = np.cumsum(np.where(step, sn, 0.0))
    bad = np.zeros(len(f), bool)
    for gid in np.unique(grp):
        sel = np.flatnonzero(grp == gid)
        segs = np.unique(seg[sel])
        if len(segs) < 2:
            continue
        first = np.searchsorted(seg, segs)       # each segment's first fix
        oe, on = off_e[first], off_n[first]
        cnt = np.array([np.count_nonzero(seg == s) for s in segs])
        near = np.hypot(oe[:, None] - oe[None, :], on[:, None] - on[None, :]) <= thr
        ref = int(np.argmax(near.astype(float) @ cnt))    # the offset most fixes hold
        wrong = ~near[ref]
        bad[np.isin(seg, segs[wrong])] = True
    out[f[bad]] = True
    return out


def mark_false_fixes(epochs: Epochs, params: Params) -> Epochs:
    """``epochs`` with the sigma of every centimetre fix judged false (:func:`false_fixes`)
    raised to at least ``[gnss] rtk_false_sd_m``: it is no centimetre measurement, and every
    consumer of the fixes' sigmas (the filters, the graph smoother) must know it."""
    cm = centimetre_fixes(epochs, params)
    if not cm.any():
        return epochs
    wrong = false_fixes(epochs, params, cm)
    if not wrong.any():
        return epochs
    floor = float(params["gnss"]["rtk_false_sd_m"])
    sd_e = epochs.gnss_sd_e.copy()
    sd_n = epochs.gnss_sd_n.copy()
    sd_e[wrong] = np.fmax(sd_e[wrong], floor)
    sd_n[wrong] = np.fmax(sd_n[wrong], floor)
    return dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n)


def rtk_error_model(epochs: Epochs, params: Params) -> tuple[Epochs, Params]:
    """A drive whose fixes are mostly RTK fixed: the centimetre fixes are taken at their
    word -- the GNSS error states pinned at ``[gnss] rtk_err_sd_m``, the standstill from
    the receiver's speed below ``rtk_standstill_speed_mps`` -- and every other fix (float, autonomous, or a
    centimetre fix judged false by :func:`mark_false_fixes`) gets its sigma x
    ``rtk_free_sd_factor``: its error, decimetres to metres, holds for seconds, which a
    white sigma at each fix would count as independent.  (ekf, with one sigma per fix class
    rather than per fix, takes the centimetre fixes' and the others' medians apart:
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
    out["fkf"]["gnss_err_sd_m"] = out["fkf"]["gnss_err_obstructed_sd_m"] = sd
    # an RTK receiver's Doppler speed is good to centimetres per second: the standstill from
    # it may end sooner, before the pinned states would have to carry the first metre
    out["fkf"]["gnss_standstill_speed_mps"] = min(float(out["fkf"]["gnss_standstill_speed_mps"]),
                                                  float(g["rtk_standstill_speed_mps"]))
    return epochs, out
