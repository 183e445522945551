"""The odometer's lag, measured against RTK-fixed fixes before any filter runs.

A wheel speed describes the past: ticks counted over a window, a CAN signal filtered or
averaged over its period.  Read at its stamp, an odometer ``L`` seconds late puts the dead
reckoning ``L x (speed change)`` metres behind along the track at every acceleration and
ahead at every braking: 1 m for a stop from 20 m/s at 0.05 s.  Between metre fixes that is
noise.  Against centimetre fixes it is not: a filter that has followed them is sure of its
position to centimetres, so after them it trusts its dead reckoning and the lag carries the
track a metre off while its sigma says decimetres (a simulated open-sky drive with 30 % of
its fixes RTK fixed: aekf 0.45 -> 0.82 m on the others, 0.10 m with the lag removed).

Centimetre fixes also measure the lag to a few milliseconds.  Over each window of about
``WINDOW_S`` between two RTK-fixed fixes (every fix between them RTK fixed too, the car
moving), the fixes' path length ``d`` against the odometer's distance ``D`` over the same
stamps is ``d - D = (k - 1) D + L (v_end - v_start)`` to first order (``k`` the
odometer's scale, ``v`` its speeds at the ends), so a Huber regression of ``d - D`` on the
speed change and ``D`` gives ``L`` (:func:`gpsdr_cli.latency.huber_fit`).  When it is late
by at least ``MIN_LAG_S`` at ``MIN_T`` standard errors, the odometer is read that much
earlier (``[time] odo_offset_s = -L``, at most ``dr_clock_min_s``), for every filter.
Hand-written: a few lines of numpy on top of the latency module's regression.  Units:
seconds, metres, m/s.
"""

from __future__ import annotations

import math

import numpy as np

from .align import base_sigma, clean_times
from .config import Params
from .conventions import NS_PER_S
from .geodesy import LocalFrame
from .io.drive import SkipReport

#: s: the window between the two fixes of a pair (the first fix at least this far on)
WINDOW_S = 1.0
#: s: no pair across a gap between fixes longer than this
MAX_GAP_S = 1.5
#: m/s: both ends of a pair at least this fast (a parked car's path length is noise)
MIN_SPEED_MPS = 2.0
#: pairs needed, and the speed change they must hold (m/s, root-sum-square)
MIN_PAIRS = 30
MIN_SIGNAL_MPS = 10.0
#: s: a lag is used from this size (rounded to 0.01 s: a 100-Hz odometer stays on its
#: gyro's stamps) ...
MIN_LAG_S = 0.01
#: ... at this many standard errors
MIN_T = 5.0


def estimate(drive, params: Params, frame: LocalFrame) -> tuple[float, float, int] | None:
    """(lag s, its standard error s, pairs used) of the odometer against the drive's
    RTK-fixed fixes, or None when they do not measure it (too few moving pairs, too little
    speed change).  A fix is RTK fixed as the filters judge it: its base sigma per axis
    (:func:`gpsdr_cli.align.base_sigma`) at most ``[gnss] rtk_cm_sd_m``; both streams in
    the order :func:`gpsdr_cli.align.clean_times` keeps (the drive is not aligned yet)."""
    g, odo = drive.gnss, drive.odo
    if g is None or odo is None or len(odo) < 2 or not len(g):
        return None
    keep = clean_times(g.t_ns, g.valid, "gnss", SkipReport())
    sd_e, sd_n = base_sigma(g.sigma_e_m[keep], g.sigma_n_m[keep], g.hdop[keep], params,
                            g.fix_quality[keep])
    cm = np.fmax(sd_e, sd_n) <= float(params["gnss"]["rtk_cm_sd_m"])
    if cm.sum() < MIN_PAIRS:
        return None
    # each fix's place among the kept ones: a pair must not skip a fix that is not RTK fixed
    pos = np.flatnonzero(cm)
    idx = keep[pos]
    t0 = int(g.t_ns[idx[0]])
    tf = (g.t_ns[idx] - t0) / NS_PER_S + float(params["time"]["gnss_offset_s"])
    e, n = frame.forward(g.lat_deg[idx], g.lon_deg[idx])
    ko = clean_times(odo.t_ns, np.isfinite(odo.speed_mps), "odo", SkipReport())
    if len(ko) < 2:
        return None
    to = (odo.t_ns[ko] - t0) / NS_PER_S
    vo = np.asarray(odo.speed_mps, float)[ko]
    dist = np.concatenate(([0.0], np.cumsum(0.5 * (vo[1:] + vo[:-1]) * np.diff(to))))
    step = np.hypot(np.diff(e), np.diff(n))
    path = np.concatenate(([0.0], np.cumsum(step)))
    a = np.arange(len(tf))
    b = np.minimum(np.searchsorted(tf, tf + WINDOW_S), len(tf) - 1)
    gaps = np.concatenate(([0], np.cumsum((np.diff(tf) > MAX_GAP_S) | (np.diff(pos) != 1))))
    inside = (tf >= to[0]) & (tf <= to[-1])
    ok = ((b > a) & (gaps[b] == gaps[a]) & inside & inside[b]
          & (tf[b] - tf[a] < WINDOW_S + MAX_GAP_S))
    a, b = a[ok], b[ok]
    va, vb = np.interp(tf[a], to, vo), np.interp(tf[b], to, vo)
    moving = (va >= MIN_SPEED_MPS) & (vb >= MIN_SPEED_MPS)
    a, b, va, vb = a[moving], b[moving], va[moving], vb[moving]
    if len(a) < MIN_PAIRS:
        return None
    dv = vb - va
    if float(np.sqrt(np.sum(dv * dv))) < MIN_SIGNAL_MPS:
        return None
    big_d = np.interp(tf[b], to, dist) - np.interp(tf[a], to, dist)
    from .latency import huber_fit

    beta, cov = huber_fit(np.column_stack([dv, big_d]), (path[b] - path[a]) - big_d)
    sd = float(np.sqrt(cov[0, 0])) if np.isfinite(cov[0, 0]) and cov[0, 0] >= 0 else math.nan
    if not (math.isfinite(beta[0]) and math.isfinite(sd)):
        return None
    return float(beta[0]), sd, len(a)


def apply(drive, params: Params, frame: LocalFrame, auto_gnss_offset: bool
          ) -> tuple[Params, str | None]:
    """``params`` with ``[time] odo_offset_s`` set to read a late odometer earlier, by the lag
    its RTK-fixed fixes measure (:func:`estimate`), and the warning line saying so; as given
    when the user set an offset, asked for ``--gnss-offset auto`` or ``odo_lag_auto = false``,
    or the lag is not clear."""
    tp = params["time"]
    if (auto_gnss_offset or not bool(tp["odo_lag_auto"])
            or any(float(tp[k]) != 0.0 for k in ("odo_offset_s", "gyro_offset_s"))):
        return params, None
    found = estimate(drive, params, frame)
    if found is None:
        return params, None
    lag, sd, used = found
    lag_r = min(round(lag, 2), float(tp["dr_clock_min_s"]))
    if lag_r < MIN_LAG_S or lag < MIN_T * sd:
        return params, None
    out = {**params, "time": {**tp, "odo_offset_s": -lag_r}}
    return out, (f"the odometer's speed reads {lag_r:.2f} s late against the RTK-fixed fixes "
                 f"(+-{sd:.3f} s from {used} pairs of them): read that much earlier "
                 "([time] odo_offset_s; odo_lag_auto = false keeps it as logged)")


__all__ = ["apply", "estimate"]
