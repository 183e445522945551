"""Merge a drive's streams into one time-ordered epoch sequence for the filters.

An *epoch* is one distinct time stamp at which at least one stream has a
record.  Each stream is first cleaned (:func:`clean_times`): non-finite values
are dropped, and of the rest the longest subsequence whose stamps strictly
increase is kept -- a lone stamp out of line with both neighbours (one corrupt
record, however far off), backward jitter and repeated stamps cost only
themselves, and after a clock step back only the records overlapping the kept
ones in time are dropped.  (Keeping only records later than the running maximum,
as before, let one stamp 480 s late throw away the next 480 s of the stream.)
Every drop is counted in the drive's :class:`~gpsdr_cli.io.drive.SkipReport` by
stream, file, record and reason, and a stream that loses more than
:data:`LOSS_WARN_SHARE` of its records gets a line in ``drive.meta["warnings"]``
(``gpsdr fuse`` prints those).  Then each stream is shifted by its time offset
(``[time]`` section: ``t_true = t_logged + offset``), all stamps are merged and
each stream's values scattered onto its epochs, NaN where the stream has nothing.

Why a hand-written longest increasing subsequence (a Fenwick-tree dynamic
programme, O(n log n), numba) and not a library: numpy and scipy have none, and
ours needs a tie-break (records close to their neighbours win).  It runs only on
a stream that is not already in order (recognised with one ``np.diff``).

Conventions: :mod:`gpsdr_cli.conventions` (int64 ns UTC, metres, ENU, yaw rate
CCW-positive as read; the filters convert it to ``d(psi)/dt = -yaw_rate``).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np
import pandas as pd

from . import dr_health
from .config import Params
from .conventions import FIX_DR, FIX_FLOAT_RTK, FIX_RTK, NS_PER_S
from .epochs import Epochs, true_runs
from .geodesy import LocalFrame
from .io.drive import Drive, SkipReport, stream_source
from .rtk_false_fix import mark_false_fixes

#: A stream losing more than this share of its records in cleaning gets a warning.
LOSS_WARN_SHARE = 0.01
#: Out-of-order records in a row up to this count are a spike or jitter; a longer
#: run of them is reported as a clock step (the drop is the same: fewest records).
SPIKE_MAX_RECORDS = 10
#: SkipReport reasons (after ``"<stream>: "``) of :func:`clean_times`
REASON_DUPLICATE = "duplicate timestamp"
REASON_SPIKE = "time stamp out of line with its neighbours (a lone spike or jitter; dropped by itself)"
REASON_STEP = (f"time stamps out of order for more than {SPIKE_MAX_RECORDS} records in a row (clock "
               "stepped back; the records overlapping the kept ones in time dropped)")


def _heaviest_increasing_py(rank: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Mask of the strictly increasing (in ``rank``) subsequence of largest total ``weight``.

    Dynamic programme over a Fenwick tree of prefix maxima: ``best[i]`` = weight[i] +
    the best chain ending at a smaller rank, found in O(log n).  A later record replaces
    a node only with a strictly larger chain weight, so of equal chains the earlier one
    stays (the first of equal stamps wins).  Compiled with numba by :func:`_kernel`.
    """
    n = len(rank)
    m = int(rank.max()) + 1 if n else 0
    tree_val = np.full(m + 1, -1.0)
    tree_idx = np.full(m + 1, -1, np.int64)
    best = np.zeros(n)
    prev = np.full(n, -1, np.int64)
    for i in range(n):
        # prefix maximum over ranks < rank[i] (tree positions 1 .. rank[i])
        v, j, pos = 0.0, -1, rank[i]
        while pos > 0:
            if tree_val[pos] > v:
                v, j = tree_val[pos], tree_idx[pos]
            pos -= pos & -pos
        best[i] = v + weight[i]
        prev[i] = j
        pos = rank[i] + 1
        while pos <= m:
            if best[i] > tree_val[pos]:
                tree_val[pos] = best[i]
                tree_idx[pos] = i
            pos += pos & -pos
    keep = np.zeros(n, np.bool_)
    if n == 0:
        return keep
    i = int(np.argmax(best))
    while i >= 0:
        keep[i] = True
        i = prev[i]
    return keep


@lru_cache(maxsize=1)
def _kernel() -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The numba-compiled :func:`_heaviest_increasing_py` (imported only when a stream is out
    of order: numba costs nothing to a drive whose stamps are in order)."""
    from numba import njit

    return njit(cache=True)(_heaviest_increasing_py)


def increasing_subsequence(t: np.ndarray) -> np.ndarray:
    """Mask of a longest strictly increasing subsequence of ``t`` (the fewest records dropped).

    Among the longest, the one whose records lie closest to their neighbours: each record
    weighs 1 plus a tie-break below 1/n that shrinks with its distance from the median
    stamp of the five records around it (in read order), in units of the stream's median
    step.  Without it a lone stamp 480 s early at the start ``[t0, t0 - 480 s, t1, ...]``
    could be kept in place of ``t0`` (both give the same count).  Of equal stamps the
    first stays.
    """
    t = np.asarray(t, np.int64)
    n = len(t)
    if n < 2:
        return np.ones(n, bool)
    rel = (t - t.min()).astype(float)
    med = pd.Series(rel).rolling(5, center=True, min_periods=1).median().to_numpy()
    steps = np.diff(np.sort(rel))
    steps = steps[steps > 0]
    step = float(np.median(steps)) if len(steps) else 1.0
    in_line = 1.0 / (1.0 + np.abs(rel - med) / step)          # 1 on the line, -> 0 far off it
    weight = 1.0 + in_line / (n + 1.0)                         # the count always dominates
    rank = np.unique(t, return_inverse=True)[1].astype(np.int64)
    return np.asarray(_kernel()(rank, weight), bool)


def _iso(t_ns: int) -> str:
    return pd.Timestamp(int(t_ns), unit="ns", tz="UTC").isoformat()


def clean_times(t_ns: np.ndarray, finite: np.ndarray, name: str,
                report: SkipReport, source: str = "") -> np.ndarray:
    """Indices of the records to keep, ascending: finite values whose stamps form a longest
    strictly increasing subsequence of the stream (first of equal stamps wins).

    Drops are counted in ``report`` by reason -- ``non-finite value``; of runs of at
    most :data:`SPIKE_MAX_RECORDS` dropped records in a row, ``duplicate timestamp``
    (equal to a kept record's) and ``time stamp out of line with its neighbours`` (a
    corrupt stamp, jitter); longer runs ``time stamps out of order`` (the clock stepped
    back; the records overlapping the kept ones in time go) -- each with the first place:
    ``source`` (the file), the stream's record number (1-based, in read order), its
    stamp and how far it lies from the kept record before it.
    """
    t_ns = np.asarray(t_ns, np.int64)
    bad = ~np.asarray(finite, bool)
    where = f"{source}: " if source else ""

    def place(i: int, ref: int | None = None) -> str:
        off = "" if ref is None else f", {(int(t_ns[i]) - int(t_ns[ref])) / NS_PER_S:+.3f} s " \
            "from the kept record before it"
        return f"{where}{name} record {i + 1} ({_iso(t_ns[i])}{off})"

    if bad.any():
        report.add(f"{name}: non-finite value", place(int(np.flatnonzero(bad)[0])), int(bad.sum()))
    idx = np.flatnonzero(~bad)
    t = t_ns[idx]
    if len(t) < 2 or bool(np.all(np.diff(t) > 0)):
        return idx
    # a stamp repeating the record just before it is a duplicate whatever the rest does:
    # the first stays (the subsequence's tie-break could otherwise pick either)
    keep = np.ones(len(t), bool)
    keep[1:] = t[1:] != t[:-1]
    rest = np.flatnonzero(keep)
    keep[rest] = increasing_subsequence(t[rest])
    dropped = np.flatnonzero(~keep)
    kept_t = t[keep]
    pos = np.searchsorted(kept_t, t[dropped])
    dup = (pos < len(kept_t)) & (kept_t[np.minimum(pos, len(kept_t) - 1)] == t[dropped])
    # the kept record before each dropped one (in read order), for the report
    last_kept = np.maximum.accumulate(np.where(keep, np.arange(len(t)), -1))
    # runs of consecutive dropped records (read order), duplicates included
    run_id = np.cumsum(np.concatenate(([1], np.diff(dropped) != 1)))
    run_len = np.bincount(run_id)[run_id]
    step = run_len > SPIKE_MAX_RECORDS  # a clock step back: even stamps equal to kept ones
    dup &= ~step
    spike = ~dup & ~step
    for mask, reason in ((dup, REASON_DUPLICATE), (spike, REASON_SPIKE)):
        if mask.any():
            j = int(dropped[np.flatnonzero(mask)[0]])
            ref = int(last_kept[j]) if last_kept[j] >= 0 else None
            report.add(f"{name}: {reason}", place(int(idx[j]), None if ref is None else int(idx[ref])),
                       int(mask.sum()))
    if step.any():
        # the first clock step: its largest step back among the dropped run and its edges
        run = dropped[run_id == run_id[np.flatnonzero(step)[0]]]
        lo, hi = max(int(run[0]), 1), min(int(run[-1]) + 1, len(t) - 1)
        k = lo + int(np.argmin(np.diff(t[lo - 1:hi + 1])))
        report.add(f"{name}: {REASON_STEP}",
                   f"{where}{name} record {idx[k] + 1} ({_iso(t[k])}, "
                   f"{(int(t[k]) - int(t[k - 1])) / NS_PER_S:+.3f} s after the record before it)",
                   int(step.sum()))
    return idx[keep]


def _clean_stream(drive: Drive, name: str, t_ns: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """:func:`clean_times` on one of the drive's streams, counted in ``drive.skipped``; a
    line in ``drive.meta["warnings"]`` when it loses more than :data:`LOSS_WARN_SHARE` of
    its records (added once, however often the drive is aligned)."""
    source = stream_source(drive, name)
    report = SkipReport()
    keep = clean_times(t_ns, finite, name, report, source)
    drive.skipped.merge(report)
    n, lost = len(t_ns), len(t_ns) - len(keep)
    if n and lost > LOSS_WARN_SHARE * n:
        lead = f"{source}: "
        why = "; ".join(f"{c} {r.split(': ', 1)[1]}, first {report.first[r].removeprefix(lead)}"
                        for r, c in report.counts.items())
        msg = (f"{source or '<input>'}: {name}: {lost} of {n} records ({100.0 * lost / n:.1f} %) "
               f"dropped while ordering the time stamps: {why}")
        warnings = drive.meta.setdefault("warnings", [])
        if msg not in warnings:
            warnings.append(msg)
    return keep


def base_sigma(sigma_e: np.ndarray, sigma_n: np.ndarray, hdop: np.ndarray,
               params: Params, quality: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Base GNSS 1-sigma per axis (m): receiver sigmas (GST, covariance, hAcc), else HDOP x
    the UERE of the fix's quality, else that UERE alone.

    The fix quality decides the UERE: RTK fixed (GGA 4) is a centimetre measurement, RTK
    float (5) a decimetre one, every other fix metres (``[gnss] uere_rtk_fixed_m``,
    ``uere_rtk_float_m``, ``uere_m``)."""
    g = params["gnss"]
    uere = np.full(len(hdop), float(g["uere_m"]))
    if quality is not None:
        q = np.asarray(quality)
        uere = np.where(q == FIX_RTK, float(g["uere_rtk_fixed_m"]),
                        np.where(q == FIX_FLOAT_RTK, float(g["uere_rtk_float_m"]), uere))
    from_hdop = hdop * uere / np.sqrt(2.0)  # HDOP x UERE is the horizontal radius
    default = np.where(uere < g["uere_m"], uere, g["sigma_default_m"])
    fallback = np.where(np.isfinite(from_hdop) & (hdop > 0), from_hdop, default / np.sqrt(2.0))
    sd_e = np.where(np.isfinite(sigma_e) & (sigma_e > 0), sigma_e, fallback)
    sd_n = np.where(np.isfinite(sigma_n) & (sigma_n > 0), sigma_n, fallback)
    return np.maximum(sd_e, g["sigma_min_m"]), np.maximum(sd_n, g["sigma_min_m"])


def flicker_zeros(t_ns: np.ndarray, speed_mps: np.ndarray, stop_mps: float, min_stop_s: float
                  ) -> np.ndarray:
    """Odometer records to drop: runs of readings below ``stop_mps`` (m/s) that last less than
    ``min_stop_s`` (s, from the run's first record to the next moving one).

    A wheel-tick odometer at walking pace, or one whose speed is a tick count over a short
    window, reads 1, 0, 0, 1 m/s while the car creeps; each zero said "stopped" and fired a
    zero-velocity update (evidence: docs/decisions/0001-defaults-evidence.md,
    ``standstill.min_stop_s``).  A real stop lasts longer; the dropped readings are ambiguous, not
    wrong, so they are not counted as skipped.  A run at either end of the stream is kept.
    """
    n = len(t_ns)
    if n < 3 or not min_stop_s > 0.0:
        return np.zeros(n, bool)
    starts, last = true_runs(np.abs(speed_mps) < stop_mps)
    ends = last + 1                                  # first record after each run (n: none)
    inner = (starts > 0) & (ends < n)                # runs at either end are kept
    starts, ends = starts[inner], ends[inner]
    short = (t_ns[ends] - t_ns[starts]) / NS_PER_S < min_stop_s
    mark = np.zeros(n + 1, np.int64)
    np.add.at(mark, starts[short], 1)
    np.add.at(mark, ends[short], -1)
    return np.cumsum(mark[:n]) > 0


def build_epochs(drive: Drive, frame: LocalFrame | None, params: Params) -> Epochs:
    """Clean, shift, project and merge the drive's streams into :class:`Epochs`."""
    tp = params["time"]
    parts: list[np.ndarray] = []

    g_en = None  # every GNSS row projected once: the health screen's chords and the epochs
    if drive.gnss is not None and len(drive.gnss) and frame is not None:
        g_en = frame.forward(drive.gnss.lat_deg, drive.gnss.lon_deg)
    health = dr_health.screen(drive, params, g_en)
    if health.notes:
        warnings = drive.meta.setdefault("warnings", [])
        warnings.extend(n for n in health.notes if n not in warnings)

    gnss_t = np.zeros(0, np.int64)
    g_rec: dict[str, np.ndarray] = {}
    rtk_share = 0.0
    if drive.gnss is not None and len(drive.gnss):
        g = drive.gnss
        keep = _clean_stream(drive, "gnss", g.t_ns, np.ones(len(g), bool))
        gnss_t = g.t_ns[keep] + np.int64(round(tp["gnss_offset_s"] * NS_PER_S))
        q = g.fix_quality[keep]
        usable = g.valid[keep] & (q >= params["gnss"]["min_fix_quality"])
        if not params["gnss"]["use_dr_fixes"]:
            usable &= q != FIX_DR
        if g_en is not None:
            e, n = g_en[0][keep], g_en[1][keep]
        else:
            e = n = np.full(len(keep), np.nan)
        usable &= np.isfinite(e) & np.isfinite(n)
        sd_e, sd_n = base_sigma(g.sigma_e_m[keep], g.sigma_n_m[keep], g.hdop[keep], params,
                                q)
        rtk_share = float(np.count_nonzero(usable & (q == FIX_RTK))) / max(int(usable.sum()), 1)
        g_rec = {"usable": usable, "e": e, "n": n, "sd_e": sd_e, "sd_n": sd_n, "pdop": g.pdop[keep],
                 "quality": q, "speed": g.speed_mps[keep], "course": np.deg2rad(g.course_deg[keep])}
        parts.append(gnss_t)

    gyro_t = np.zeros(0, np.int64)
    if drive.gyro is not None and len(drive.gyro):
        y = drive.gyro
        keep = _clean_stream(drive, "gyro", y.t_ns, np.isfinite(y.yaw_rate_radps))
        if health.gyro_ok is not None:  # unhealthy samples: a warning line, not a skip count
            keep = keep[health.gyro_ok[keep]]
        gyro_t = y.t_ns[keep] + np.int64(round(tp["gyro_offset_s"] * NS_PER_S))
        gyro_v = y.yaw_rate_radps[keep]
        parts.append(gyro_t)

    odo_t = np.zeros(0, np.int64)
    if drive.odo is not None and len(drive.odo):
        o = drive.odo
        keep = _clean_stream(drive, "odo", o.t_ns, np.isfinite(o.speed_mps))
        if health.odo_ok is not None:  # unhealthy samples: a warning line, not a skip count
            keep = keep[health.odo_ok[keep]]
        odo_t = o.t_ns[keep] + np.int64(round(tp["odo_offset_s"] * NS_PER_S))
        odo_v = o.speed_mps[keep]
        sp = params["standstill"]
        flicker = flicker_zeros(odo_t, odo_v, sp["speed_mps"], sp["min_stop_s"])
        odo_t, odo_v = odo_t[~flicker], odo_v[~flicker]
        parts.append(odo_t)

    accel_t = np.zeros(0, np.int64)
    if drive.accel is not None and len(drive.accel):
        a = drive.accel
        keep = _clean_stream(drive, "accel", a.t_ns, np.isfinite(a.accel_mps2))
        accel_t = a.t_ns[keep] + np.int64(round(tp["gyro_offset_s"] * NS_PER_S))
        accel_v = a.accel_mps2[keep]
        parts.append(accel_t)

    t = sorted_unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)
    n_ep = len(t)

    def scatter(times: np.ndarray, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        out = np.full(n_ep, fill, dtype=np.result_type(values, type(fill)))
        out[np.searchsorted(t, times)] = values
        return out

    has_gnss = np.zeros(n_ep, bool)
    nan = np.full(n_ep, np.nan)
    gnss_e = gnss_n = sd_e = sd_n = pdop = gspeed = gcourse = nan
    quality = np.zeros(n_ep, np.int8)
    if len(gnss_t):
        u = g_rec["usable"]
        has_gnss = scatter(gnss_t[u], np.ones(u.sum(), bool), False).astype(bool)
        gnss_e = scatter(gnss_t[u], g_rec["e"][u])
        gnss_n = scatter(gnss_t[u], g_rec["n"][u])
        sd_e = scatter(gnss_t[u], g_rec["sd_e"][u])
        sd_n = scatter(gnss_t[u], g_rec["sd_n"][u])
        gspeed = scatter(gnss_t[u], g_rec["speed"][u])
        quality = scatter(gnss_t[u], g_rec["quality"][u], 0).astype(np.int8)
        gcourse = scatter(gnss_t[u], g_rec["course"][u])
        pdop = scatter(gnss_t, g_rec["pdop"])
    has_gyro = scatter(gyro_t, np.ones(len(gyro_t), bool), False).astype(bool)
    yaw = scatter(gyro_t, gyro_v) if len(gyro_t) else nan.copy()
    has_odo = scatter(odo_t, np.ones(len(odo_t), bool), False).astype(bool)
    odo = scatter(odo_t, odo_v) if len(odo_t) else nan.copy()
    has_accel = scatter(accel_t, np.ones(len(accel_t), bool), False).astype(bool)
    accel = scatter(accel_t, accel_v) if len(accel_t) else nan.copy()

    dt = np.zeros(n_ep)
    if n_ep > 1:
        dt[1:] = np.diff(t) / NS_PER_S

    fix_t = t[has_gnss]
    gap_s = float(tp["outage_gap_s"])
    if len(fix_t) > 2:
        gap_s = max(gap_s, 2.5 * float(np.median(np.diff(fix_t))) / NS_PER_S)
    outage = outage_mask(t, fix_t, gap_s)
    epochs = Epochs(t_ns=t, dt_s=dt, has_gnss=has_gnss, gnss_e=gnss_e, gnss_n=gnss_n,
                    gnss_sd_e=sd_e, gnss_sd_n=sd_n, pdop=pdop, gnss_speed_mps=gspeed,
                    gnss_course_rad=gcourse, has_gyro=has_gyro, yaw_rate_radps=yaw,
                    has_odo=has_odo, odo_speed_mps=odo, gnss_outage=outage, gap_s=gap_s,
                    has_accel=has_accel, accel_mps2=accel, rtk_fixed_share=rtk_share,
                    gnss_quality=quality,
                    dr_unhealthy=(health.gyro_ok is not None
                                  or health.odo_bad_s >= float(params["health"]["odo_silent_s"])
                                  or _silent(odo_t, float(params["health"]["odo_silent_s"]),
                                             t[has_gnss], gspeed[has_gnss])))
    from .filters.gnss_model import clamped_speeds, doppler_off_share

    epochs = clamped_speeds(epochs, params)  # once, before any filter or check reads them
    epochs.doppler_off_share = doppler_off_share(epochs, params)
    epochs, claim = mark_false_fixes(epochs, params)
    if claim:
        warnings = drive.meta.setdefault("warnings", [])
        if claim not in warnings:
            warnings.append(claim)
    return epochs


def _silent(t_ns: np.ndarray, gap_s: float, fix_t: np.ndarray, fix_speed: np.ndarray) -> bool:
    """Whether a stream's records (ns, sorted) pause longer than ``gap_s`` inside its span while
    the car moves: the receiver's median speed in the pause above 1 m/s, or unknown (a logger
    that writes the odometer only when it changes is silent at every stop)."""
    if len(t_ns) < 2:
        return False
    for i in np.flatnonzero(np.diff(t_ns) > gap_s * NS_PER_S):
        lo, hi = np.searchsorted(fix_t, [t_ns[i], t_ns[i + 1]])
        v = fix_speed[lo:hi]
        v = v[np.isfinite(v)]
        if len(v) == 0 or float(np.median(v)) > 1.0:
            return True
    return False


def sorted_unique(t: np.ndarray) -> np.ndarray:
    """Distinct values of an int array, ascending.

    Sort plus an adjacent-difference mask: numpy 2's ``np.unique`` hashes integer
    arrays, which is about 10x slower here on already sorted stamps (timing:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#align)."""
    t = np.sort(t, kind="stable")
    if len(t) < 2:
        return t
    keep = np.empty(len(t), bool)
    keep[0] = True
    np.not_equal(t[1:], t[:-1], out=keep[1:])
    return t[keep]


def sorted_member(a: np.ndarray, sorted_b: np.ndarray) -> np.ndarray:
    """``np.isin(a, sorted_b)`` for an ascending ``sorted_b``, by binary search."""
    if len(sorted_b) == 0:
        return np.zeros(len(a), bool)
    i = np.minimum(np.searchsorted(sorted_b, a), len(sorted_b) - 1)
    return sorted_b[i] == a


def outage_mask(t_ns: np.ndarray, fix_t_ns: np.ndarray, gap_s: float) -> np.ndarray:
    """True for epochs inside a stretch without fixes longer than ``gap_s`` seconds.

    The stretch before the first fix and after the last are measured from the
    first/last epoch.  With no fix at all, every epoch is in an outage.
    """
    if len(t_ns) == 0:
        return np.zeros(0, bool)
    if len(fix_t_ns) == 0:
        return np.ones(len(t_ns), bool)
    gap_ns = gap_s * NS_PER_S
    bounds = np.concatenate(([min(t_ns[0], fix_t_ns[0]) - 1], fix_t_ns,
                             [max(t_ns[-1], fix_t_ns[-1]) + 1]))
    i = np.searchsorted(bounds, t_ns, side="right")  # bounds[i-1] <= t < bounds[i]
    prev_b = bounds[i - 1]
    next_b = bounds[np.minimum(i, len(bounds) - 1)]
    at_fix = sorted_member(t_ns, fix_t_ns)
    length = (next_b - prev_b).astype(float)
    return (length > gap_ns) & ~at_fix
