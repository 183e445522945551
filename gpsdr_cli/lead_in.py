"""The lead-in: epochs before the first GNSS fix, dead-reckoned backwards from the filter.

A logger usually starts its gyro and odometer before the receiver has a fix (a cold
start takes 30 s or more).  Every filter starts its state at the first usable fix's
position, so the epochs before it began from that position at the wrong time and the
error went into the states (the odometer scale among them), which smoothing did not
recover (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#lead-in).

So :func:`split` cuts the drive at the first usable fix, the filter runs from there, and
:func:`backfill` dead-reckons the epochs before it *backwards* from the filter's first
state, with the gyro (heading, ``d(psi)/dt = -yaw_rate``, less its bias
taken from the track after the fix, :func:`calibration`) and the odometer (speed, divided
by its scale against the track; without an odometer the first state's speed, held along
the gyro's heading when it is fast enough for a course, else the first position held: a
GNSS-only log's no-fix records measured no motion).  A track that never moves after the
fix tells no heading: the first fix is then held, the odometer's distance back to each
epoch as its sigma.  Units: metres ENU, seconds, radians, heading clockwise from north.

The lead-in's sigma is a plain bound, not a covariance (nothing measured the position
there): the first state's position variance plus ``(LEAD_IN_DIST_SD * distance)^2``
plus, without an odometer, ``(LEAD_IN_SPEED_SD_MPS * time)^2`` (without any sensor, the
filters' 60 m/s bound on an unmeasured step instead), with distance and time counted back
from the first fix (time at most ``NO_DR_MAX_S``).  Written by hand: it is a cumulative
sum over the lead-in; no library does a backward dead reckoning on our epoch layout.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from .config import Params
from .conventions import NS_PER_S
from .epochs import Epochs
from .filters.base import MAX_SPEED_MPS, FilterResult

#: a lead-in shorter than this (s) is left to the filter (one GNSS interval or less: the
#: filter's own initial position sigma covers it)
MIN_LEAD_IN_S = 0.25
#: sigma of the backward dead reckoning per metre driven (heading and odometer scale errors)
LEAD_IN_DIST_SD = 0.03
#: sigma (m/s) of the speed held backwards without an odometer
LEAD_IN_SPEED_SD_MPS = 1.0
#: s: the lead-in's sigma stops growing this far back (the filters' default ``[aekf]
#: max_gap_s``: a larger bound means nothing more)
NO_DR_MAX_S = 600.0
#: heading from the filter's velocity only at or above this speed (m/s)
HEADING_MIN_SPEED_MPS = 1.0
#: s after the first fix over which the gyro bias and odometer scale are taken from the track
CALIBRATION_S = 60.0
#: least moving time (s) and track distance (m) in that window for an estimate
MIN_CALIBRATION_S = 10.0
MIN_CALIBRATION_M = 100.0


def split(epochs: Epochs) -> tuple[int, Epochs]:
    """``(k, epochs[k:])`` where k is the first usable fix when the epochs before it span
    ``MIN_LEAD_IN_S`` or more; else ``(0, epochs)``.  Also without a gyro or odometer record
    before it (a GNSS-only log's no-fix records): the filter run from epoch 0 had carried
    its first velocity through them, 830 m in 165 s of a simulated cold start."""
    if not epochs.has_gnss.any():
        return 0, epochs
    k = int(np.argmax(epochs.has_gnss))                 # the first usable fix
    if k == 0:
        return 0, epochs
    span_s = (int(epochs.t_ns[k]) - int(epochs.t_ns[0])) / NS_PER_S
    if span_s < MIN_LEAD_IN_S:
        return 0, epochs
    fields = {}
    for f in dataclasses.fields(Epochs):
        value = getattr(epochs, f.name)
        fields[f.name] = value[k:].copy() if isinstance(value, np.ndarray) else value
    fields["dt_s"][0] = 0.0
    return k, Epochs(**fields)


def run_from_first_fix(epochs: Epochs, run: Callable[[Epochs, Params], FilterResult],
                       params: Params, *, gyro_bias: float | None = None,
                       true_scale: float | None = None) -> FilterResult:
    """``run`` from the first usable fix (:func:`split`), the epochs before it dead-reckoned
    back from there (:func:`backfill`).  ``gyro_bias`` (rad/s) and ``true_scale`` (true speed
    over the odometer's), fitted over the whole drive, stand for the lead-in's own
    calibration when given."""
    k, tail = split(epochs)
    result = run(tail, params)
    if not k:
        return result
    return backfill(epochs, k, result, gyro_bias=gyro_bias,
                    odo_scale=1.0 / true_scale if true_scale else None)


def _held(has: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Each epoch's latest record (``values`` where ``has``), the first record before any;
    NaN when there is none."""
    ok = has & np.isfinite(values)
    if not ok.any():
        return np.full(len(has), np.nan)
    last = np.maximum.accumulate(np.where(ok, np.arange(len(has)), -1))
    return values[np.where(last >= 0, last, np.argmax(ok))]


def calibration(epochs: Epochs, k: int, result: FilterResult) -> tuple[float, float]:
    """The gyro bias (rad/s, ``yaw_measured = yaw_true + bias``) and odometer scale
    (``odometer = scale x true speed``) over the first ``CALIBRATION_S`` after the first fix,
    from the filter's own track: the mean of ``yaw dt + d(psi)`` over steps where the track
    moves at ``HEADING_MIN_SPEED_MPS`` or more, and the ratio of the odometer's distance to the
    track's.  The same for every filter (fkf holds neither as a per-epoch state); 0 and 1
    where the window does not tell."""
    t = (epochs.t_ns[k:] - epochs.t_ns[k]) / NS_PER_S
    w = t <= CALIBRATION_S
    v_e, v_n = np.asarray(result.v_e)[w], np.asarray(result.v_n)[w]
    speed = np.hypot(v_e, v_n)
    dt = np.diff(t[w])
    moving = (speed[1:] >= HEADING_MIN_SPEED_MPS) & (speed[:-1] >= HEADING_MIN_SPEED_MPS)
    yaw = epochs.yaw_rate_radps[k:][w]
    has = epochs.has_gyro[k:][w] & np.isfinite(yaw)
    bias = 0.0
    if has.any() and moving.any():
        y = _held(has, yaw)
        dpsi = np.angle(np.exp(1j * np.diff(np.arctan2(v_e, v_n))))
        use = moving & np.isfinite(y[1:])
        if dt[use].sum() >= MIN_CALIBRATION_S:
            bias = float(np.sum(y[1:][use] * dt[use] + dpsi[use]) / dt[use].sum())
    scale = 1.0
    odo = epochs.odo_speed_mps[k:][w]
    has_o = epochs.has_odo[k:][w] & np.isfinite(odo)
    if has_o.any():
        o = np.abs(_held(has_o, odo))
        d_track = float(np.sum(0.5 * (speed[1:] + speed[:-1]) * dt))
        d_odo = float(np.sum(0.5 * (o[1:] + o[:-1]) * dt))
        if d_track >= MIN_CALIBRATION_M and d_odo > 0.0:
            scale = min(max(d_odo / d_track, 0.5), 2.0)
    return bias, scale


def backfill(epochs: Epochs, k: int, result: FilterResult, *, gyro_bias: float | None = None,
             odo_scale: float | None = None) -> FilterResult:
    """The full-length result: the lead-in ``epochs[:k]`` dead-reckoned backwards from
    ``result`` (which starts at epoch k), then ``result``.  ``info["lead_in_epochs"]`` and
    ``info["lead_in_s"]`` say how much.  ``gyro_bias`` (rad/s) and ``odo_scale`` (as
    :func:`calibration` gives them), fitted over the whole drive, stand for
    :func:`calibration`'s when given; with that gyro bias the heading is taken where the
    track is fastest within ``CALIBRATION_S`` of the fix (a course is surest there) and
    carried back by the gyro."""
    t_s = (epochs.t_ns[: k + 1] - epochs.t_ns[k]) / NS_PER_S      # <= 0, 0 at the first fix
    speed0 = math.hypot(float(result.v_e[0]), float(result.v_n[0]))
    # heading at the first fix: the filter's course, from the first epoch it moves at
    # HEADING_MIN_SPEED_MPS, carried back to the first fix by the gyro
    speed_r = np.hypot(result.v_e, result.v_n)
    moving = np.flatnonzero(speed_r >= HEADING_MIN_SPEED_MPS)
    j = int(moving[0]) if len(moving) else 0
    if gyro_bias is not None and len(moving):
        # a filter that has just met its first fix after a stop reads its course poorly at
        # walking pace (114 deg off at 1.1 m/s on a simulated city drive), well at speed
        t_r = (result.t_ns - result.t_ns[0]) / NS_PER_S
        j = int(np.argmax(np.where(t_r <= CALIBRATION_S, speed_r, -1.0)))
    psi_j = math.atan2(float(result.v_e[j]), float(result.v_n[j])) if len(moving) else 0.0

    if gyro_bias is None or odo_scale is None:
        own_bias, own_scale = calibration(epochs, k, result)
        gyro_bias = own_bias if gyro_bias is None else gyro_bias
        odo_scale = own_scale if odo_scale is None else odo_scale
    n_all = len(epochs)
    has_gyro = epochs.has_gyro & np.isfinite(epochs.yaw_rate_radps)
    yaw = _held(has_gyro, epochs.yaw_rate_radps) - gyro_bias if has_gyro.any() else np.zeros(n_all)
    yaw = np.nan_to_num(yaw)
    t_all = (epochs.t_ns - epochs.t_ns[k]) / NS_PER_S
    # psi(t) = psi(t_j) + int_t^{t_j} yaw dt  (d(psi)/dt = -yaw_rate), trapezoid over epochs
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (yaw[1:] + yaw[:-1]) * np.diff(t_all))))
    psi = psi_j + (cum[min(k + j, n_all - 1)] - cum[: k + 1])
    has_odo = epochs.has_odo & np.isfinite(epochs.odo_speed_mps)
    # the track never moves after the fix (a log that ends parked): the odometer says how
    # far the car went before it, nothing says which way (heading 0 put a simulated lead-in
    # 535 m off, its sigma 9 m); the first fix held, the distance as its sigma
    odo_lead = bool(has_odo[: k + 1].any())
    lost = odo_lead and not len(moving)
    if odo_lead:
        speed = np.abs(_held(has_odo, epochs.odo_speed_mps)[: k + 1]) / odo_scale
        time_sd = 0.0
    else:
        # the first speed held along the gyro's heading; without a gyro before the fix, or
        # slower than a course can be told, nothing says where it went: the position held
        held = has_gyro[:k].any() and speed0 >= HEADING_MIN_SPEED_MPS
        speed = np.full(k + 1, speed0 if held else 0.0)
        time_sd = LEAD_IN_SPEED_SD_MPS
        if not (has_gyro[:k].any() or has_odo[:k].any()):
            # no sensor at all: the bound the filters give an unmeasured step
            time_sd = MAX_SPEED_MPS
    v_e = speed * np.sin(psi) * (not lost)
    v_n = speed * np.cos(psi) * (not lost)
    # position at epoch i < k: the first fix's minus the displacement from t_i to t_k
    dt = np.diff(t_s)                                             # > 0
    de = np.concatenate((np.cumsum((0.5 * (v_e[1:] + v_e[:-1]) * dt)[::-1])[::-1], [0.0]))
    dn = np.concatenate((np.cumsum((0.5 * (v_n[1:] + v_n[:-1]) * dt)[::-1])[::-1], [0.0]))
    dist = np.concatenate((np.cumsum((0.5 * (speed[1:] + speed[:-1]) * dt)[::-1])[::-1], [0.0]))
    add = ((1.0 if lost else LEAD_IN_DIST_SD) * dist) ** 2 \
        + (time_sd * np.maximum(t_s, -NO_DR_MAX_S)) ** 2
    pre = slice(0, k)

    def cat(lead: np.ndarray, rest: np.ndarray) -> np.ndarray:
        return np.concatenate((np.asarray(lead, dtype=np.asarray(rest).dtype), rest))

    extras = {}
    for name, arr in result.extras.items():
        arr = np.asarray(arr)
        if arr.ndim == 1 and len(arr) == len(result):
            fill = np.zeros(k, bool) if arr.dtype == bool else np.full(k, arr[0])
            extras[name] = cat(fill, arr)
        else:
            extras[name] = arr
    info = dict(result.info)
    info["lead_in_epochs"] = k
    info["lead_in_s"] = float(-t_s[0])
    return dataclasses.replace(
        result,
        t_ns=cat(epochs.t_ns[pre], result.t_ns),
        e=cat(float(result.e[0]) - de[pre], result.e),
        n=cat(float(result.n[0]) - dn[pre], result.n),
        v_e=cat(v_e[pre], result.v_e),
        v_n=cat(v_n[pre], result.v_n),
        var_e=cat(float(result.var_e[0]) + add[pre], result.var_e),
        var_n=cat(float(result.var_n[0]) + add[pre], result.var_n),
        cov_en=cat(np.zeros(k), result.cov_en),
        gnss_used=cat(np.zeros(k, bool), result.gnss_used),
        gnss_rejected=cat(np.zeros(k, bool), result.gnss_rejected),
        nis=cat(np.full(k, np.nan), result.nis),
        static=cat(speed[pre] < 0.05, result.static),
        extras=extras,
        info=info,
    )
