"""Readings that jump off their neighbours further than a vehicle can move: corrupt records.

A reading is compared with the median of itself and up to two readings on each side (at
most ``span_s`` away, in time order): the median of five outvotes two wrong ones, so a lone
glitch or a pair is found and the good readings next to them are not.  It is a spike when
it is further from that median than a physical rate limit over the time to its farthest
neighbour plus a tolerance for the sensor's own noise.  A longer run of wrong readings is
left to the filters' gates and the dead-reckoning health screen (:mod:`gpsdr_cli.dr_health`).

Why here and not in the filters: one receiver velocity in twenty with a random speed and
course took every filter from 0.5 m to 8-180 m on simulated 300-s drives, and one odometer
reading in two hundred with a random speed of 0-40 m/s took ekf/aekf to 8-86 m (fixes at
1.4 m), and one forward acceleration in a hundred at a random +-40 m/s^2 every filter
from 0.6 to 4.5-4.9 m through 15-s outages bridged by the accelerometer.  Units: m/s, rad/s, stamps in ns.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..conventions import NS_PER_S

#: m/s^2: no road vehicle's velocity changes faster (braking, cornering: about 1 g)
MAX_ACCEL_MPS2 = 10.0
#: rad/s^2: nor its yaw rate (a snap steer at speed)
MAX_YAW_ACCEL_RADPS2 = 3.0
#: m/s^3: nor its acceleration (an emergency stop's onset)
MAX_JERK_MPS3 = 20.0
#: m/s: what a receiver's velocity may differ from its neighbours' beyond that acceleration
#: (Doppler noise, a reflected signal's bias of about 1 m/s)
VELOCITY_TOL_MPS = 2.0
#: m/s: the same for an odometer (a CAN wheel speed is smooth to centimetres per second; an
#: odometer blip of 3-5 m/s at a stop turned aekf's held heading and the track left 400 m
#: off); raised to the stream's own step size where that is larger (:func:`step_noise`)
ODO_TOL_MPS = 2.0
#: rad/s: the same for a gyro
GYRO_TOL_RADPS = 1.0
#: m/s^2: and for a forward accelerometer (road vibration raises it through its step size)
ACCEL_TOL_MPS2 = 3.0
#: s: a receiver velocity is judged only against neighbours this close (1 Hz: two each side)
VELOCITY_SPAN_S = 2.5
#: s: a dead-reckoning reading likewise (CAN at 5 Hz: two each side)
DR_SPAN_S = 1.0
#: the tolerance is at least this many robust sigmas of the stream's sample-to-sample steps
STEP_SIGMAS = 8.0


def _time_order(t_ns: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Indices of the ``ok`` readings in time order (stable; no sort when already in order)."""
    idx = np.flatnonzero(ok)
    ti = t_ns[idx]
    return idx if np.all(ti[1:] >= ti[:-1]) else idx[np.argsort(ti, kind="stable")]


def _step_size(v: np.ndarray) -> float:
    """Robust size (median x 1.4826) of the non-zero steps of ``v`` (in time order)."""
    d = np.abs(np.diff(v))
    d = d[d > 1e-6]     # not the rounding of a speed computed from ticks over stamps
    return 1.4826 * float(np.median(d)) if len(d) else 0.0


def off_neighbours(t_ns: np.ndarray, values: np.ndarray, *, rate_limit: float, tol: float,
                   span_s: float, step_sigmas: float = 0.0) -> np.ndarray:
    """Per reading, whether it is a spike (see the module docstring).  ``values``: (n,) or
    (n, k) (a vector per reading, medians per column, distance Euclidean); NaN rows are
    neither judged nor neighbours.  ``rate_limit`` per second, ``tol`` in the values' unit,
    raised to ``step_sigmas`` x the stream's step size (:func:`step_noise`; 1-D only)."""
    v = np.asarray(values, float)
    v = v[:, None] if v.ndim == 1 else v
    bad = np.zeros(len(v), bool)
    ok = np.isfinite(v).all(axis=1)
    if ok.sum() < 3:
        return bad
    order = _time_order(t_ns, ok)
    if step_sigmas > 0.0:
        tol = max(tol, step_sigmas * _step_size(v[order, 0]))
    t = (t_ns[order] - t_ns[order[0]]) / NS_PER_S
    # windows of five as views: the neighbours -2, -1, the reading, +1, +2 (padding beyond
    # the ends); a neighbour counts when at most span_s away, and the farthest one's time
    # sets the allowance
    tp = np.concatenate(([-np.inf] * 2, t, [np.inf] * 2))
    m = len(t)
    far_s = np.zeros(m)
    n_near = np.zeros(m, np.int64)
    for c in (0, 1, 3, 4):                      # one column of the window at a time
        gap = np.abs(tp[c:c + m] - t)
        near_c = gap <= span_s
        far_s = np.where(near_c, np.maximum(far_s, gap), far_s)
        n_near += near_c
    judged = n_near >= 2
    full = n_near == 4
    part = judged & ~full
    if part.any():
        near = np.abs(sliding_window_view(tp, 5)[part] - t[part, None]) <= span_s
    dist2 = np.zeros(len(order))
    for j in range(v.shape[1]):
        col = v[order, j]
        win = sliding_window_view(np.concatenate(([np.nan] * 2, col, [np.nan] * 2)), 5)
        # five readings everywhere but at ends and gaps: a median network, not a NaN median
        med = np.where(full, _median5(*(win[:, c] for c in range(5))), col)
        if part.any():
            med[part] = np.nanmedian(np.where(near, win[part], np.nan), axis=1)
        dist2 += (col - med) ** 2
    spike = judged & (np.sqrt(dist2) > rate_limit * far_s + tol)
    bad[order[spike]] = True
    return bad


def _median5(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
             e: np.ndarray) -> np.ndarray:
    """Elementwise median of five arrays: the median of ``e`` and the middle two of the
    four others (the larger of the pairs' minima, the smaller of their maxima)."""
    lo = np.maximum(np.minimum(a, b), np.minimum(c, d))
    hi = np.minimum(np.maximum(a, b), np.maximum(c, d))
    return np.maximum(np.minimum(e, lo), np.minimum(np.maximum(e, lo), hi))


def receiver_velocity_spikes(t_ns: np.ndarray, speed_mps: np.ndarray,
                             course_deg: np.ndarray) -> np.ndarray:
    """Receiver velocities (speed along a course clockwise from north) that no vehicle could
    reach from those around them: :data:`MAX_ACCEL_MPS2`, :data:`VELOCITY_TOL_MPS`, east and
    north together."""
    c = np.deg2rad(np.asarray(course_deg, float))
    s = np.asarray(speed_mps, float)
    return off_neighbours(t_ns, np.column_stack([s * np.sin(c), s * np.cos(c)]),
                          rate_limit=MAX_ACCEL_MPS2, tol=VELOCITY_TOL_MPS, span_s=VELOCITY_SPAN_S)


def step_noise(t_ns: np.ndarray, values: np.ndarray) -> float:
    """Robust size (median x 1.4826) of a stream's non-zero steps from one reading to the
    next, in time order: a wheel speed from ticks steps by whole ticks per reading interval
    (0.05 m ticks at 100 Hz: 5 m/s) and holds still in between, so its median step is 0
    and its median non-zero step is the tick."""
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    return _step_size(v[_time_order(t_ns, ok)]) if ok.sum() >= 3 else 0.0


def _dr_spikes(rate_limit: float, tol: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """A dead-reckoning stream's check: off its neighbours beyond ``rate_limit`` over the
    span plus ``tol``, or :data:`STEP_SIGMAS` x the stream's step size if larger."""
    def spikes(t_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
        return off_neighbours(t_ns, values, rate_limit=rate_limit, tol=tol, span_s=DR_SPAN_S,
                              step_sigmas=STEP_SIGMAS)
    return spikes


#: odometer speeds (m/s) off their neighbours beyond 1 g
odometer_spikes = _dr_spikes(MAX_ACCEL_MPS2, ODO_TOL_MPS)
#: yaw rates (rad/s) off their neighbours beyond a snap steer
gyro_spikes = _dr_spikes(MAX_YAW_ACCEL_RADPS2, GYRO_TOL_RADPS)
#: forward accelerations (m/s^2) off their neighbours beyond an emergency stop's onset
accel_spikes = _dr_spikes(MAX_JERK_MPS3, ACCEL_TOL_MPS2)


__all__ = ["accel_spikes", "gyro_spikes", "odometer_spikes", "off_neighbours",
           "receiver_velocity_spikes", "step_noise"]
