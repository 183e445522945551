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
    this drive's fix quality and its agreement with the dead reckoning."""
    g = params["gnss"]
    if epochs.rtk_fixed_share >= float(g["rtk_share"]):
        out = copy.deepcopy(params)
        _set_err_sd(out, float(g["rtk_err_sd_m"]))
        return epochs, out
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
    epochs = dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n)
    if bad.sum() >= float(g["nlos_drive_share"]) * known.sum():
        params = copy.deepcopy(params)
        params["aekf"]["gnss_err_sd_m"] = float(g["nlos_err_sd_m"])
    return epochs, params


def _set_err_sd(params: Params, sd_m: float) -> None:
    params["aekf"]["gnss_err_sd_m"] = sd_m
    params["fkf"]["gnss_err_sd_m"] = sd_m
    params["fkf"]["gnss_err_obstructed_sd_m"] = sd_m
