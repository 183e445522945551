"""Standstill from the GNSS, for drives without an odometer (every filter).

Nothing but the receiver then says when the car stopped; without it the velocity
wandered on GNSS noise at every stop (fkf: a gated multipath burst then ran the track
far off; evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#standstill).
:func:`standstill_from_gnss` is what the filters call: the receiver's (Doppler) speed,
or with positions only (fewer than ``[fkf] fix_course_velocity_share`` of the fixes
with a speed) the speed between the median positions of the fixes either side
(:func:`fix_speeds`), into :func:`gnss_standstill`.  The keys live in ``[fkf]``, where they were introduced.

Plain numpy (once per drive, vectorised): no compiled kernel is needed.
Conventions (:mod:`gpsdr_cli.conventions`): seconds, metres ENU, radians.
"""

from __future__ import annotations

import numpy as np

from ..config import Params
from ..epochs import Epochs

#: seconds: two fixes further apart do not make a standstill from the receiver's speed
MAX_STILL_GAP_S = 2.0
#: seconds: a longer GNSS outage is never taken for a standstill
MAX_BRIDGE_S = 30.0
#: rad: ... nor one across which the gyro heading turned this much
BRIDGE_TURN_RAD = 0.35


def standstill_from_gnss(epochs: Epochs, t_s: np.ndarray, params: Params,
                         heading: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Per epoch, stopped (bool): :func:`gnss_standstill` on the receiver's speed, or on
    :func:`fix_speeds` when the receiver reports positions only.  ``t_s``: epoch times
    (s); ``heading``: the gyro heading (t s, psi rad unwrapped) for the outage bridge."""
    fp = params["fkf"]
    speeds = None
    if epochs.velocity_share < fp["fix_course_velocity_share"] and fp["fix_standstill_window_s"] > 0:
        speeds = fix_speeds(epochs, t_s, fp["fix_standstill_window_s"])
    return gnss_standstill(epochs, t_s, params, speeds, heading)


def gnss_standstill(epochs: Epochs, t_s: np.ndarray, params: Params,
                    speeds: np.ndarray | None = None,
                    heading: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Standstill from the receiver's (Doppler) speed, for drives without an odometer.

    The epochs in ``(t_k, t_k+1]`` between consecutive fixes are static when both fixes,
    at most ``MAX_STILL_GAP_S`` apart, and every fix in ``[t_k+1 - W, t_k+1]``
    (``W = [fkf] gnss_standstill_window_s``) report a speed below ``[fkf]
    gnss_standstill_speed_mps``; a fix without a speed is never still.  The fix
    ``k+1`` closes the interval before it: a look-ahead of one fix interval, so
    the zero-velocity update ends when the car drives off, not one fix later.

    Why (our choice, beyond Tang et al.): without an odometer nothing else tells
    the filters that the car stopped.  The constant-acceleration model then let
    the velocity wander on GNSS noise (~1 m/s at a stop), its variance grew
    while a multipath burst was gated, a late fix of the burst passed the
    gate, threw the velocity off, and every good fix after it was gated
    until the reset.
    ``speeds`` (m/s, one per fix) stands in for the receiver's speed when given
    (positions only: :func:`fix_speeds`).

    A GNSS outage of at most ``MAX_BRIDGE_S`` is static too when the fix before it
    was still, every fix in the window after it is still, the two fixes lie within 3
    sigma of each other and the gyro heading ``heading = (t s, psi rad unwrapped)``
    turned less than ``BRIDGE_TURN_RAD`` across it: the car braked into the outage
    and waited (without the bridge the decelerating velocity was extrapolated through
    the stop).  Evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#standstill.
    """
    fp = params["fkf"]
    n = len(t_s)
    static = np.zeros(n, bool)
    f = np.flatnonzero(epochs.has_gnss)
    thr, window = fp["gnss_standstill_speed_mps"], fp["gnss_standstill_window_s"]
    if speeds is not None:
        thr = fp["fix_standstill_speed_mps"]
    if len(f) < 2 or not thr > 0:
        return static
    tf = t_s[f]
    spd = epochs.gnss_speed_mps[f] if speeds is None else speeds
    still = np.isfinite(spd) & (spd < thr)
    bad = np.concatenate(([0], np.cumsum(~still)))       # fixes not still before index j
    j0 = np.minimum(np.searchsorted(tf, tf[1:] - max(window, 0.0), "left"), np.arange(len(f) - 1))
    gap = np.diff(tf)
    ok = (bad[np.arange(2, len(f) + 1)] - bad[j0] == 0) & (gap <= MAX_STILL_GAP_S)
    if heading is not None and len(heading[0]) > 1:
        # an outage (MAX_STILL_GAP_S < gap <= MAX_BRIDGE_S) entered slowly, left stopped
        # (every fix in the window after it still), at the same place (within 3 sigma of the
        # two fixes) and with the same heading (gyro): the car waited there
        j1 = np.searchsorted(tf, tf[1:] + max(window, 0.0), "right")     # window after
        after = (bad[j1] - bad[np.arange(1, len(f))] == 0) & (j1 - np.arange(1, len(f)) >= 2)
        tg, psi = heading
        turn = np.abs(np.interp(tf[1:], tg, psi) - np.interp(tf[:-1], tg, psi))
        e, nn = epochs.gnss_e[f], epochs.gnss_n[f]
        var = epochs.gnss_sd_e[f] ** 2 + epochs.gnss_sd_n[f] ** 2
        moved = np.hypot(np.diff(e), np.diff(nn))
        ok |= ((gap > MAX_STILL_GAP_S) & (gap <= MAX_BRIDGE_S) & still[:-1] & after
               & (turn < BRIDGE_TURN_RAD) & (moved <= 3.0 * np.sqrt(var[:-1] + var[1:])))
    mark = np.zeros(n + 1, np.int64)                     # epochs f[i] + 1 .. f[i + 1]
    i = np.flatnonzero(ok)
    np.add.at(mark, f[i] + 1, 1)
    np.add.at(mark, f[i + 1] + 1, -1)
    return np.cumsum(mark[:n]) > 0


def fix_speeds(epochs: Epochs, t_s: np.ndarray, window_s: float) -> np.ndarray:
    """Speed (m/s) at each fix from the positions alone: the distance between the median
    position of the fixes in ``[t - W/2, t]`` and in ``[t, t + W/2]`` over the time between
    their median times (``W = window_s``; NaN with fewer than two fixes on a side).

    Medians, not a fitted line: a multipath jump inside the window moves a line's slope by
    metres per second, a median not while under half of a side's fixes jumped.  The
    windows are gathered into NaN-padded rows (:func:`window_medians`): no loop per fix
    (timing: docs/decisions/0015-evidence-behind-the-filter-choices.md#standstill).
    """
    f = np.flatnonzero(epochs.has_gnss)
    tf, e, nn = t_s[f], epochs.gnss_e[f], epochs.gnss_n[f]
    half = 0.5 * window_s
    i = np.arange(len(f))
    lo = np.searchsorted(tf, tf - half, "left")
    hi = np.searchsorted(tf, tf + half, "right")
    n_before, n_after = i + 1 - lo, hi - i          # fixes in [t - W/2, t] and [t, t + W/2]
    out = np.full(len(f), np.nan)
    k = i[(n_before >= 2) & (n_after >= 2)]
    if not len(k):
        return out
    before = [window_medians(v, lo[k], n_before[k]) for v in (tf, e, nn)]
    after = [window_medians(v, k, n_after[k]) for v in (tf, e, nn)]
    dt = after[0] - before[0]
    dist = np.hypot(after[1] - before[1], after[2] - before[2])
    out[k] = np.where(dt > 0.0, dist / np.where(dt > 0.0, dt, 1.0), np.nan)
    return out


def window_medians(values: np.ndarray, start: np.ndarray, count: np.ndarray,
                   rows: int = 2048) -> np.ndarray:
    """``median(values[start[i]:start[i] + count[i]])`` for each i (every count >= 1), from
    NaN-padded rows of the longest window, ``rows`` at a time (memory: rows x longest)."""
    out = np.empty(len(start))
    cols = np.arange(int(count.max()))
    for r0 in range(0, len(start), rows):
        s, c = start[r0:r0 + rows], count[r0:r0 + rows]
        idx = np.minimum(s[:, None] + cols[None, :], len(values) - 1)
        out[r0:r0 + rows] = np.nanmedian(np.where(cols[None, :] < c[:, None], values[idx], np.nan),
                                         axis=1)
    return out
