"""Runs of fixes that share one reflected-signal (NLOS) bias.

A reflected signal moves a fix by tens of metres and keeps it there for seconds to
minutes; between two fixes a fifth of a second apart the dead reckoning moves by
centimetres of error.  So the offset of each fix from a dead-reckoned track (fix minus
track, east and north) is nearly constant inside one run of reflection and jumps where
the reflection starts, ends or changes.  Cutting the fixes where that offset jumps gives
runs; inside one, the fixes share one bias (zero where the sky is clear).  A run whose
offset drifts (a reflection whose path changes as the car moves, or the track's own
drift) is cut again into segments that each hold one bias.  The batch fit
(:func:`gpsdr_cli.filters.graph.smooth_graph` with ``segments``) then gives each segment
one bias and each run one vote for "this bias is zero", so a minute of consistent
reflected fixes counts as one witness, not three hundred (docs/decisions/0044).

The track only has to hold its shape over a fix interval: a drifting track moves the
offsets slowly, and only a jump makes a new run.  Units: metres, seconds.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ..conventions import NS_PER_S

#: a segment's Doppler agreement needs this many measured fixes (a second at 5 Hz)
TRUST_MIN_N = 5

if TYPE_CHECKING:
    from ..epochs import Epochs
    from .base import FilterResult


def segments(t_s: np.ndarray, off_e: np.ndarray, off_n: np.ndarray, jump_m: float,
             gap_s: float, ref_n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """``(segment, run)`` ids (0, 1, ...) per fix, in order.  A new run, and segment, where
    the fix's offset (``off_e``, ``off_n``: fix minus track, m) lies more than ``jump_m``
    from the median offset of the segment's last ``ref_n`` fixes (a jump), or more than
    ``gap_s`` after the previous fix; a new segment only where it lies that far from the
    median of the segment's first ``ref_n`` (a slow drift: a reflection whose path changes
    as the car moves, or the track's own drift).  A run is the evidence that votes once;
    its segments each carry their own bias.  ``t_s`` increasing (s)."""
    return _segments(np.ascontiguousarray(t_s, np.float64), np.ascontiguousarray(off_e, np.float64),
                     np.ascontiguousarray(off_n, np.float64), float(jump_m), float(gap_s),
                     int(ref_n))


@njit(cache=True)
def _median(a):  # pragma: no cover - compiled
    # NaN as numpy gives it (numba's median does not check)
    for v in a:
        if math.isnan(v):
            return math.nan
    return np.median(a)


@njit(cache=True)
def _segments(t_s, off_e, off_n, jump_m, gap_s, ref_n):  # pragma: no cover - compiled
    # compiled: a median of the last few offsets per fix is 50 us in numpy, 17 k fixes an hour
    n = len(t_s)
    seg = np.zeros(n, np.int64)
    run = np.zeros(n, np.int64)
    cur = 0
    cur_run = 0
    start = 0
    for i in range(1, n):
        jump = t_s[i] - t_s[i - 1] > gap_s
        drift = False
        if not jump:
            lo = max(start, i - ref_n)
            jump = math.hypot(off_e[i] - _median(off_e[lo:i]),
                              off_n[i] - _median(off_n[lo:i])) > jump_m
        if not jump:
            hi = min(i, start + ref_n)
            drift = math.hypot(off_e[i] - _median(off_e[start:hi]),
                               off_n[i] - _median(off_n[start:hi])) > jump_m
        if jump or drift:
            cur += 1
            start = i
        if jump:
            cur_run += 1
        seg[i] = cur
        run[i] = cur_run
    return seg, run


def segment_offsets(ids: np.ndarray, de: np.ndarray, dn: np.ndarray) -> np.ndarray:
    """Per fix: the length (m) of its segment's median offset (``de``, ``dn``: east, north),
    the fixes in time order (``ids`` never decreasing and >= 0, as :func:`segments` gives
    them; :func:`segment_medians` over every fix)."""
    return _segment_offsets(np.ascontiguousarray(ids, np.int64),
                            np.ascontiguousarray(de, np.float64),
                            np.ascontiguousarray(dn, np.float64))


@njit(cache=True)
def _segment_offsets(ids, de, dn):  # pragma: no cover - compiled
    # compiled: thousands of segments an hour, a numpy median call each cost 0.15 s a pass
    me, mn = _segment_medians(ids, de, dn, np.ones(len(ids), np.bool_))
    out = np.empty(len(ids))
    for i in range(len(ids)):
        out[i] = math.hypot(me[i], mn[i])
    return out


def segment_medians(ids: np.ndarray, de: np.ndarray, dn: np.ndarray,
                    use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per element: the median east and north (``de``, ``dn``) over the ``use``d elements of
    its segment (``ids``: contiguous groups, each id in one stretch; -1: none), NaN where its
    segment has none or it has no segment."""
    return _segment_medians(np.ascontiguousarray(ids, np.int64),
                            np.ascontiguousarray(de, np.float64),
                            np.ascontiguousarray(dn, np.float64),
                            np.ascontiguousarray(use, np.bool_))


@njit(cache=True)
def _segment_medians(ids, de, dn, use):  # pragma: no cover - compiled
    # compiled: a numpy median per segment (thousands an hour) cost 0.1 s a solve
    n = len(ids)
    me = np.full(n, np.nan)
    mn = np.full(n, np.nan)
    lo = 0
    for i in range(1, n + 1):
        if i == n or ids[i] != ids[lo]:
            if ids[lo] >= 0:
                sel = np.flatnonzero(use[lo:i]) + lo
                if len(sel):
                    vm_e = _median(de[sel])
                    vm_n = _median(dn[sel])
                    me[lo:i] = vm_e
                    mn[lo:i] = vm_n
            lo = i
    return me, mn


def segments_near(epochs: Epochs, track: FilterResult, seg: np.ndarray,
                  keep_m: float) -> np.ndarray:
    """Per epoch: its fix belongs to a segment (``seg``: :func:`fix_segments`) whose median
    offset (east, north) from ``track`` is within ``keep_m`` (m)."""
    ids = np.asarray(seg)[0]
    ok = np.zeros(len(epochs), bool)
    idx = np.flatnonzero(ids >= 0)
    ok[idx] = segment_offsets(ids[idx], epochs.gnss_e[idx] - track.e[idx],
                              epochs.gnss_n[idx] - track.n[idx]) <= keep_m
    return ok


def segment_trust(ids: np.ndarray, misfit: np.ndarray, scale_mps: float,
                  min_n: int = TRUST_MIN_N) -> np.ndarray:
    """Per element, how far its segment's receiver velocities agree with the dead reckoning:
    1 / (1 + (r / ``scale_mps``)^2), r the RMS of the segment's Doppler-minus-odometer speeds
    (``misfit``, m/s: :func:`gpsdr_cli.filters.gnss_model.doppler_misfit`, NaN where not
    measured).  1 where the segment (``ids``: id per element, -1 none) has fewer than
    ``min_n`` measured, or ``scale_mps`` <= 0.  Per segment, not per run: a run that ramps
    from clean into a reflection holds both.  A clean Doppler speed and a wheel's agree to
    0.1 m/s RMS (comma2k19's highway drive: 0.09); a reflected signal moves the Doppler too,
    and a segment of reflected fixes disagrees by 0.3-1.8 m/s (decisions/0069)."""
    ids = np.asarray(ids, np.int64)
    out = np.ones(len(ids))
    ok = (ids >= 0) & np.isfinite(misfit)
    if not scale_mps > 0.0 or not ok.any():
        return out
    n_ids = int(ids.max()) + 1
    cnt = np.bincount(ids[ok], minlength=n_ids)
    ss = np.bincount(ids[ok], weights=np.asarray(misfit)[ok] ** 2, minlength=n_ids)
    per = np.where(cnt >= min_n, 1.0 / (1.0 + ss / np.maximum(cnt, 1) / scale_mps ** 2), 1.0)
    has = ids >= 0
    out[has] = per[ids[has]]
    return out


def largest_window_median(t_s: np.ndarray, d: np.ndarray, window_s: float,
                          min_n: int = 1) -> tuple[float, float]:
    """``(value, time s)``: the largest median of ``d`` over windows of ``window_s`` seconds
    of ``t_s`` (increasing, s), stepped by half a window from ``t_s[0]``, each with at least
    ``min_n`` values, and the middle of that window; (0, NaN) with none."""
    best, at = 0.0, math.nan
    if not len(t_s):
        return best, at
    for t0 in np.arange(t_s[0], t_s[-1] + 0.5 * window_s, 0.5 * window_s):
        lo, hi = np.searchsorted(t_s, [t0, t0 + window_s])
        if hi - lo >= min_n:
            m = float(np.median(d[lo:hi]))
            if m > best:
                best, at = m, t0 + 0.5 * window_s
    return best, at


def fix_segments(epochs: Epochs, track: FilterResult, gp: dict) -> np.ndarray:
    """Per epoch, rows (segment id, run id) of its fix (:func:`segments` on the offsets of
    the fixes from ``track``), -1 where there is none: shape (2, epochs)."""
    fix = np.flatnonzero(np.asarray(epochs.has_gnss, bool) & np.isfinite(epochs.gnss_e)
                         & np.isfinite(epochs.gnss_n))
    out = np.full((2, len(epochs)), -1, np.int64)
    if len(fix):
        t_s = (np.asarray(epochs.t_ns, np.int64)[fix] - int(epochs.t_ns[0])) / NS_PER_S
        out[0, fix], out[1, fix] = segments(
            t_s, epochs.gnss_e[fix] - track.e[fix], epochs.gnss_n[fix] - track.n[fix],
            float(gp["nlos_segment_jump_m"]), float(gp["nlos_segment_gap_s"]))
    return out


__all__ = ["fix_segments", "largest_window_median", "segment_trust", "segment_offsets",
           "segments", "segments_near"]
