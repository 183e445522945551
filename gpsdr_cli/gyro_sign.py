"""The gyro's sign and units against the receiver's course: a yaw rate logged clockwise-positive
and read as counter-clockwise (``[gyro] sign``) turns every turn the wrong way, and one logged
in deg/s and read as rad/s (``[gyro] units``), or the other way round, 57 times too far or too
little.

Loggers differ: ROS (REP-103) and most IMUs give yaw rate counter-clockwise positive in rad/s,
some CAN buses clockwise or in deg/s.  Misread, the dead reckoning mirrors or scales each turn,
and the filters and the graph smoother, which trust it between fixes, end hundreds of metres
off (a simulated 300-s canyon drive: the graph 444 m against fixes at 7.6 m with the sign
wrong, 104 m with rad/s read as deg/s).  The receiver's course (RMC/VTG, NAV-PVT) changes with
every turn: over windows of ``WINDOW_S`` at speed, the course change against the gyro's
heading change (``-integral(yaw_rate)``, heading clockwise from north) has slope +1 when sign
and units are right, -1 when the sign is not, 180/pi or pi/180 (either sign) when the units
are not.  The fit is a Huber M-estimate with a constant gyro bias (reflected Dopplers and
manoeuvres at low speed are its outliers); the gyro is called misread only when the slope is
within a factor ``SLOPE_FACTOR`` of one of those (:data:`MISREADINGS`), many standard errors
from 0, and the gyro read that way explains the course changes far better than as read.
Then the yaw rates are multiplied by that factor and the summary says so.  Hand-written: a
few lines of IRLS, as in :mod:`gpsdr_cli.latency`.  Units: rad, rad/s, s.
"""

from __future__ import annotations

import math

import numpy as np

from .conventions import NS_PER_S
from .epochs import Epochs
from .filters.calibration import scaled_yaw
from .latency import huber_fit

#: window over which the course change is compared (s), and the speed at both ends (m/s)
WINDOW_S = 6.0
MIN_SPEED_MPS = 5.0
#: at least this many windows, this many of them turning more than TURN_RAD
MIN_WINDOWS = 30
MIN_TURNS = 5
TURN_RAD = 0.3
#: the slope called a misreading: within this factor of one of MISREADINGS, and this many
#: standard errors from 0 ...
SLOPE_FACTOR = 1.5
MIN_T = 10.0
#: ... with the robust residual cost of the gyro as read at least this many times that of
#: the gyro read that way
COST_RATIO = 3.0
DEG = math.pi / 180.0
#: true rate / reading, and what the user's configuration then has wrong
MISREADINGS = ((-1.0, "its yaw rates have the other sign; set [gyro] sign to the other value"),
               (DEG, 'its yaw rates are deg/s, read as rad/s; set [gyro] units = "deg/s"'),
               (1.0 / DEG, 'its yaw rates are rad/s, read as deg/s; set [gyro] units = "rad/s"'),
               (-DEG, "its yaw rates have the other sign and are deg/s; set [gyro] sign to the "
                      'other value and units = "deg/s"'),
               (-1.0 / DEG, "its yaw rates have the other sign and are rad/s; set [gyro] sign to "
                            'the other value and units = "rad/s"'))


def course_slope(epochs: Epochs) -> tuple[float, float, float, int] | None:
    """(slope, its standard error, robust cost as read / read as the nearest misreading,
    windows) of the course change on the gyro's heading change, or None where the drive
    cannot tell."""
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
        # the bias refitted for each factor; the residuals' sum of absolute values
        r = dc - m * dg
        b = float(np.median(r / np.maximum(span, 1e-9)))
        return float(np.sum(np.abs(r - b * span)))

    slope = float(beta[0])
    return slope, se, cost(1.0) / max(cost(_nearest(slope)[0]), 1e-12), len(i)


def _nearest(slope: float) -> tuple[float, str]:
    """The misreading (factor, what the configuration has wrong) nearest to ``slope``."""
    return min(MISREADINGS, key=lambda m: _log_gap(slope, m[0]))


def _log_gap(slope: float, factor: float) -> float:
    """How far ``slope`` is from ``factor`` as a ratio (inf: opposite signs)."""
    if slope * factor <= 0.0:
        return math.inf
    return abs(math.log(slope / factor))


def check(epochs: Epochs) -> tuple[Epochs, str | None]:
    """``epochs`` with the yaw rates corrected where their sign or units are misread, and the
    note why."""
    fit = course_slope(epochs)
    if fit is None:
        return epochs, None
    slope, se, ratio, n = fit
    factor, what = _nearest(slope)
    if not (_log_gap(slope, factor) < math.log(SLOPE_FACTOR) and abs(slope) > MIN_T * se
            and ratio > COST_RATIO):
        return epochs, None
    return scaled_yaw(epochs, factor), (
        f"the gyro turns {slope:+.3g} times as the receiver's course does (over {n} windows): "
        f"{what} for this logger; the track uses them corrected")
