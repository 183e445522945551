"""The gyro's sign against the receiver's course: a yaw rate logged clockwise-positive and read
as counter-clockwise (``[gyro] sign``) turns every turn the wrong way.

Loggers differ: ROS (REP-103) and most IMUs give yaw rate counter-clockwise positive, some CAN
buses clockwise.  Read with the wrong sign, the dead reckoning mirrors each turn, and the
filters and the graph smoother, which trust it between fixes, end hundreds of metres off
(a simulated 300-s canyon drive: the graph 444 m against fixes at 7.6 m).  The receiver's
course (RMC/VTG, NAV-PVT) changes with every turn: over windows of ``WINDOW_S`` at speed,
the course change against the gyro's heading change (``-integral(yaw_rate)``, heading
clockwise from north) has slope +1 when the sign is right and -1 when it is not.  The fit is
a Huber M-estimate with a constant gyro bias (reflected Dopplers and manoeuvres at low
speed are its outliers); the sign is called wrong only when the slope is near -1, many
standard errors from 0, and the mirrored gyro explains the course changes far better than
the gyro as read.  Then the yaw rates are negated and the summary says so.  Hand-written:
a few lines of IRLS, as in :mod:`gpsdr_cli.latency`.  Units: rad, rad/s, s.
"""

from __future__ import annotations

import math

import numpy as np

from .conventions import NS_PER_S
from .epochs import Epochs
from .latency import huber_fit

#: window over which the course change is compared (s), and the speed at both ends (m/s)
WINDOW_S = 6.0
MIN_SPEED_MPS = 5.0
#: at least this many windows, this many of them turning more than TURN_RAD
MIN_WINDOWS = 30
MIN_TURNS = 5
TURN_RAD = 0.3
#: the slope called mirrored: within this of -1, and this many standard errors below 0 ...
SLOPE_TOL = 0.5
MIN_T = 10.0
#: ... with the robust residual cost of the gyro as read at least this many times that of
#: the mirrored one
COST_RATIO = 3.0


def course_slope(epochs: Epochs) -> tuple[float, float, float, int] | None:
    """(slope, its standard error, robust cost as read / mirrored, windows) of the course change
    on the gyro's heading change, or None where the drive cannot tell."""
    g = np.asarray(epochs.has_gyro, bool) & np.isfinite(epochs.yaw_rate_radps)
    if g.sum() < 10 or epochs.gnss_course_rad is None:
        return None
    t = (np.asarray(epochs.t_ns, np.int64) - int(epochs.t_ns[0])) / NS_PER_S
    tg, yg = t[g], np.asarray(epochs.yaw_rate_radps, float)[g]
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (yg[1:] + yg[:-1]) * np.diff(tg))))
    speed = np.asarray(epochs.gnss_speed_mps, float)
    course = np.asarray(epochs.gnss_course_rad, float)
    fx = (np.asarray(epochs.has_gnss, bool) & np.isfinite(course) & np.isfinite(speed)
          & (speed >= MIN_SPEED_MPS) & (t >= tg[0]) & (t <= tg[-1]))
    tf, cf = t[fx], course[fx]
    if len(tf) < MIN_WINDOWS:
        return None
    yaw_int = np.interp(tf, tg, cum)
    j = np.searchsorted(tf, tf + WINDOW_S)
    ok = (j < len(tf))
    i = np.flatnonzero(ok)
    j = j[ok]
    span = tf[j] - tf[i]
    keep = span <= WINDOW_S + 2.0
    i, j, span = i[keep], j[keep], span[keep]
    if len(i) < MIN_WINDOWS:
        return None
    dc = np.angle(np.exp(1j * (cf[j] - cf[i])))
    dg = -(yaw_int[j] - yaw_int[i])  # the gyro's heading change, clockwise
    if np.count_nonzero(np.abs(dc) > TURN_RAD) < MIN_TURNS:
        return None
    X = np.column_stack([dg, span])
    beta, cov = huber_fit(X, dc)[:2]
    se = math.sqrt(max(float(cov[0, 0]), 0.0))

    def cost(m: float) -> float:
        # the bias refitted for each sign; the residuals' sum of absolute values
        r = dc - m * dg
        b = float(np.median(r / np.maximum(span, 1e-9)))
        return float(np.sum(np.abs(r - b * span)))

    return float(beta[0]), se, cost(1.0) / max(cost(-1.0), 1e-12), len(i)


def check(epochs: Epochs) -> tuple[Epochs, str | None]:
    """``epochs`` with the yaw rates negated where their sign is wrong, and the note why."""
    fit = course_slope(epochs)
    if fit is None:
        return epochs, None
    slope, se, ratio, n = fit
    if not (abs(slope + 1.0) < SLOPE_TOL and slope < -MIN_T * se and ratio > COST_RATIO):
        return epochs, None
    import dataclasses

    flipped = dataclasses.replace(epochs, yaw_rate_radps=-np.asarray(epochs.yaw_rate_radps))
    return flipped, (f"the gyro turns against the receiver's course (slope {slope:+.2f} over {n} "
                     "windows): its yaw rates are read negated; set [gyro] sign to the other "
                     "value for this logger")
