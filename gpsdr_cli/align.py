"""Merge a drive's streams into one time-ordered epoch sequence for the filters.

An *epoch* is one distinct time stamp at which at least one stream has a
record.  Each stream is first shifted by its time offset (``[time]`` section:
``t_true = t_logged + offset``), then cleaned: non-finite values and records
whose time is not later than every earlier record of the same stream
(duplicates, steps backwards) are dropped and counted in the drive's
:class:`~gpsdr_cli.io.drive.SkipReport`.  Then all stamps are merged with
``np.unique`` and each stream's values scattered onto its epochs, NaN where the
stream has nothing.

Conventions: :mod:`gpsdr_cli.conventions` (int64 ns UTC, metres, ENU, yaw rate
CCW-positive as read; the filters convert it to ``d(psi)/dt = -yaw_rate``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import Params
from .conventions import FIX_DR, NS_PER_S
from .geodesy import LocalFrame
from .io.drive import Drive, SkipReport


@dataclass
class Epochs:
    """Arrays of equal length ``n``, one entry per epoch (the filters' input).

    GNSS (at epochs with a usable fix, NaN elsewhere):
      ``gnss_e, gnss_n`` m; ``gnss_sd_e, gnss_sd_n`` base 1-sigma in m (GST or
      covariance, else HDOP x UERE, else the default, floored); ``pdop`` at GNSS
      records (NaN elsewhere); ``gnss_speed_mps``, ``gnss_course_rad`` (clockwise
      from north) where the receiver gave them.
    DR: ``yaw_rate_radps`` (CCW-positive), ``odo_speed_mps``; NaN where absent.
    ``dt_s[k]`` = t[k] - t[k-1] in seconds (``dt_s[0] = 0``).
    ``gnss_outage``: the epoch lies in a gap between usable fixes longer than
    ``gap_s`` (also before the first / after the last fix when that stretch is).
    """

    t_ns: np.ndarray
    dt_s: np.ndarray
    has_gnss: np.ndarray
    gnss_e: np.ndarray
    gnss_n: np.ndarray
    gnss_sd_e: np.ndarray
    gnss_sd_n: np.ndarray
    pdop: np.ndarray
    gnss_speed_mps: np.ndarray
    gnss_course_rad: np.ndarray
    has_gyro: np.ndarray
    yaw_rate_radps: np.ndarray
    has_odo: np.ndarray
    odo_speed_mps: np.ndarray
    gnss_outage: np.ndarray
    gap_s: float

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def n_gnss(self) -> int:
        return int(self.has_gnss.sum())

    @property
    def velocity_share(self) -> float:
        """Share of the usable fixes that carry the receiver's speed (RMC/VTG); 0 without fixes."""
        n_fix = self.n_gnss
        if n_fix == 0:
            return 0.0
        return float(np.count_nonzero(self.has_gnss & np.isfinite(self.gnss_speed_mps))) / n_fix


def clean_times(t_ns: np.ndarray, finite: np.ndarray, name: str,
                report: SkipReport) -> np.ndarray:
    """Indices of records to keep: finite values, strictly increasing time (first wins)."""
    n = len(t_ns)
    bad = ~finite
    report.add(f"{name}: non-finite value", name, int(bad.sum()))
    idx = np.flatnonzero(~bad)
    t = t_ns[idx]
    if len(t) == 0:
        return idx
    prev_max = np.maximum.accumulate(t)
    keep = np.ones(len(t), bool)
    keep[1:] = t[1:] > prev_max[:-1]
    dup = ~keep.copy()
    dup[1:] &= t[1:] == prev_max[:-1]
    report.add(f"{name}: duplicate timestamp", name, int(dup.sum()))
    report.add(f"{name}: timestamp earlier than a previous record", name,
               int((~keep).sum() - dup.sum()))
    del n
    return idx[keep]


def base_sigma(sigma_e: np.ndarray, sigma_n: np.ndarray, hdop: np.ndarray,
               params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Base GNSS 1-sigma per axis (m): receiver sigmas, else HDOP x UERE, else the default."""
    g = params["gnss"]
    from_hdop = hdop * g["uere_m"] / np.sqrt(2.0)  # HDOP x UERE is the horizontal radius
    fallback = np.where(np.isfinite(from_hdop) & (hdop > 0), from_hdop,
                        g["sigma_default_m"] / np.sqrt(2.0))
    sd_e = np.where(np.isfinite(sigma_e) & (sigma_e > 0), sigma_e, fallback)
    sd_n = np.where(np.isfinite(sigma_n) & (sigma_n > 0), sigma_n, fallback)
    return np.maximum(sd_e, g["sigma_min_m"]), np.maximum(sd_n, g["sigma_min_m"])


def build_epochs(drive: Drive, frame: LocalFrame | None, params: Params) -> Epochs:
    """Clean, shift, project and merge the drive's streams into :class:`Epochs`."""
    tp = params["time"]
    rep = drive.skipped
    parts: list[np.ndarray] = []

    gnss_t = np.zeros(0, np.int64)
    g_rec: dict[str, np.ndarray] = {}
    if drive.gnss is not None and len(drive.gnss):
        g = drive.gnss
        keep = clean_times(g.t_ns, np.ones(len(g), bool), "gnss", rep)
        gnss_t = g.t_ns[keep] + np.int64(round(tp["gnss_offset_s"] * NS_PER_S))
        q = g.fix_quality[keep]
        usable = g.valid[keep] & (q >= params["gnss"]["min_fix_quality"])
        if not params["gnss"]["use_dr_fixes"]:
            usable &= q != FIX_DR
        if frame is not None:
            e, n = frame.forward(g.lat_deg[keep], g.lon_deg[keep])
        else:
            e = n = np.full(len(keep), np.nan)
        usable &= np.isfinite(e) & np.isfinite(n)
        sd_e, sd_n = base_sigma(g.sigma_e_m[keep], g.sigma_n_m[keep], g.hdop[keep], params)
        g_rec = {"usable": usable, "e": e, "n": n, "sd_e": sd_e, "sd_n": sd_n, "pdop": g.pdop[keep],
                     "speed": g.speed_mps[keep], "course": np.deg2rad(g.course_deg[keep])}
        parts.append(gnss_t)

    gyro_t = np.zeros(0, np.int64)
    if drive.gyro is not None and len(drive.gyro):
        y = drive.gyro
        keep = clean_times(y.t_ns, np.isfinite(y.yaw_rate_radps), "gyro", rep)
        gyro_t = y.t_ns[keep] + np.int64(round(tp["gyro_offset_s"] * NS_PER_S))
        gyro_v = y.yaw_rate_radps[keep]
        parts.append(gyro_t)

    odo_t = np.zeros(0, np.int64)
    if drive.odo is not None and len(drive.odo):
        o = drive.odo
        keep = clean_times(o.t_ns, np.isfinite(o.speed_mps), "odo", rep)
        odo_t = o.t_ns[keep] + np.int64(round(tp["odo_offset_s"] * NS_PER_S))
        odo_v = o.speed_mps[keep]
        parts.append(odo_t)

    t = sorted_unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)
    n_ep = len(t)

    def scatter(times: np.ndarray, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        out = np.full(n_ep, fill, dtype=np.result_type(values, type(fill)))
        out[np.searchsorted(t, times)] = values
        return out

    has_gnss = np.zeros(n_ep, bool)
    nan = np.full(n_ep, np.nan)
    gnss_e = gnss_n = sd_e = sd_n = pdop = gspeed = gcourse = nan
    if len(gnss_t):
        u = g_rec["usable"]
        has_gnss = scatter(gnss_t[u], np.ones(u.sum(), bool), False).astype(bool)
        gnss_e = scatter(gnss_t[u], g_rec["e"][u])
        gnss_n = scatter(gnss_t[u], g_rec["n"][u])
        sd_e = scatter(gnss_t[u], g_rec["sd_e"][u])
        sd_n = scatter(gnss_t[u], g_rec["sd_n"][u])
        gspeed = scatter(gnss_t[u], g_rec["speed"][u])
        gcourse = scatter(gnss_t[u], g_rec["course"][u])
        pdop = scatter(gnss_t, g_rec["pdop"])
    has_gyro = scatter(gyro_t, np.ones(len(gyro_t), bool), False).astype(bool)
    yaw = scatter(gyro_t, gyro_v) if len(gyro_t) else nan.copy()
    has_odo = scatter(odo_t, np.ones(len(odo_t), bool), False).astype(bool)
    odo = scatter(odo_t, odo_v) if len(odo_t) else nan.copy()

    dt = np.zeros(n_ep)
    if n_ep > 1:
        dt[1:] = np.diff(t) / NS_PER_S

    fix_t = t[has_gnss]
    gap_s = float(tp["outage_gap_s"])
    if len(fix_t) > 2:
        gap_s = max(gap_s, 2.5 * float(np.median(np.diff(fix_t))) / NS_PER_S)
    outage = outage_mask(t, fix_t, gap_s)
    return Epochs(t_ns=t, dt_s=dt, has_gnss=has_gnss, gnss_e=gnss_e, gnss_n=gnss_n,
                  gnss_sd_e=sd_e, gnss_sd_n=sd_n, pdop=pdop, gnss_speed_mps=gspeed,
                  gnss_course_rad=gcourse, has_gyro=has_gyro, yaw_rate_radps=yaw,
                  has_odo=has_odo, odo_speed_mps=odo, gnss_outage=outage, gap_s=gap_s)


def sorted_unique(t: np.ndarray) -> np.ndarray:
    """Distinct values of an int array, ascending.

    Sort plus an adjacent-difference mask: numpy 2's ``np.unique`` hashes integer
    arrays, which is about 10x slower here (0.23 s vs 0.02 s on a one-hour drive's
    720 k stamps, already sorted per stream)."""
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
