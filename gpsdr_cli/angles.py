"""Unwrapping a heading offset (course minus the integrated gyro heading) across gaps.

The offset between the receiver's course and the gyro's integrated heading drifts at the
gyro's bias: 1 deg/s is a plausible MEMS turn-on bias, so across a 3-minute gap without
courses (a tunnel, a run of reflected fixes left out) it moves by about 180 deg, and
``numpy.unwrap``, which takes the shortest way round, can take the wrong way: the offset
interpolated across the gap then turns the heading a whole turn the wrong way over the gap
(2 deg/s across 175 s), and a simulated city drive's fkf track went 600 m off (urban_nlos
seed 25; docs/decisions/0036).  Across a gap the branch is chosen by the drift rate the
offsets show on either side of it.  A rate seen on one side only must agree with the
drift the whole drive shows (a gyro bias changes slowly), else the drive's is taken:
thirty seconds of reflected courses after a 100-s gap read 1.8 deg/s against the drive's
0.05 and turned an fkf heading a whole turn across the gap (decisions/0042).  Units:
seconds, radians.
"""

from __future__ import annotations

import math

import numpy as np

#: a step between offsets longer than this (s) is a gap: its branch comes from the drift rate
GAP_S = 10.0
#: the drift rate is fitted over the offsets up to this long (s) before and after a gap ...
RATE_SPAN_S = 30.0
#: ... from at least this many offsets spanning at least RATE_MIN_SPAN_S (s)
RATE_MIN_POINTS = 3
RATE_MIN_SPAN_S = 5.0


def _rate(t: np.ndarray, a: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of ``a`` over ``t`` and its standard error (rad/s), or NaNs where
    too short to tell."""
    if len(t) < RATE_MIN_POINTS or t[-1] - t[0] < RATE_MIN_SPAN_S:
        return math.nan, math.nan
    tc = t - t.mean()
    stt = float(np.dot(tc, tc))
    slope = float(np.dot(tc, a - a.mean()) / stt)
    resid = a - a.mean() - slope * tc
    return slope, math.sqrt(float(np.dot(resid, resid)) / max(len(t) - 2, 1) / stt)


def unwrap_across_gaps(t_s: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """``angle_rad`` (at increasing times ``t_s``) unwrapped: as ``numpy.unwrap`` between
    neighbours less than :data:`GAP_S` apart; across a longer gap, the branch nearest the
    value the drift rate predicts, where the rate is clear: fitted on either side of the
    gap, the two agreeing to a quarter turn over the gap and known to an eighth
    (``numpy.unwrap``'s choice otherwise: near a stop a track's course can turn fast)."""
    t = np.asarray(t_s, float)
    out = np.unwrap(np.asarray(angle_rad, float))
    if len(out) < 2:
        return out
    gaps = np.flatnonzero(np.diff(t) > GAP_S)
    drive = drive_rate(t, out, gaps) if len(gaps) else math.nan
    for g in gaps:
        lo = int(np.searchsorted(t, t[g] - RATE_SPAN_S, side="left"))
        hi = int(np.searchsorted(t, t[g + 1] + RATE_SPAN_S, side="right"))
        nxt = g + 1 + np.flatnonzero(np.diff(t[g + 1:hi]) > GAP_S)[:1]
        hi = int(nxt[0]) + 1 if len(nxt) else hi     # the right side ends at the next gap
        prv = np.flatnonzero(np.diff(t[lo:g + 1]) > GAP_S)
        lo = lo + int(prv[-1]) + 1 if len(prv) else lo  # the left side starts after the last one
        sides = [r for r in (_rate(t[lo:g + 1], out[lo:g + 1]), _rate(t[g + 1:hi], out[g + 1:hi]))
                 if math.isfinite(r[0])]
        if not sides:
            continue
        gap = t[g + 1] - t[g]
        if len(sides) == 1 and math.isfinite(drive) and abs(sides[0][0] - drive) * gap > 0.25 * math.pi:
            sides = [(drive, 0.0)]  # the drive's rate, taken as known (it is the fallback)
        w = [1.0 / max(se * se, 1e-18) for _, se in sides]
        rate = sum(wi * r for wi, (r, _) in zip(w, sides, strict=True)) / sum(w)
        se = 1.0 / math.sqrt(sum(w))
        if se * gap > 0.25 * math.pi or (
                len(sides) == 2 and abs(sides[0][0] - sides[1][0]) * gap > 0.5 * math.pi):
            continue
        pred = out[g] + rate * gap
        out[g + 1:] += 2.0 * math.pi * round((pred - out[g + 1]) / (2.0 * math.pi))
    return out


def drive_rate(t: np.ndarray, a: np.ndarray, gaps: np.ndarray) -> float:
    """The drift rate of the whole drive (rad/s): the median of the slopes fitted over each
    run of offsets between gaps, weighted by the run's duration (not by its standard error:
    a run of identical offsets would outvote the drive); NaN without one."""
    bounds = np.concatenate(([0], gaps + 1, [len(t)]))
    runs = [(_rate(t[i:j], a[i:j])[0], float(t[j - 1] - t[i]))
            for i, j in zip(bounds[:-1], bounds[1:], strict=True)]
    fits = sorted((r, w) for r, w in runs if math.isfinite(r))
    if not fits:
        return math.nan
    w = np.cumsum([wi for _, wi in fits])
    return fits[int(np.searchsorted(w, 0.5 * w[-1]))][0]


__all__ = ["GAP_S", "drive_rate", "unwrap_across_gaps"]
