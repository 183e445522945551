"""Dead-reckoning health: gyro and odometer samples the filters must not believe.

Two sensor faults make a fused track worse than the GNSS fixes alone, because every
filter (and the smoother) trusts the dead reckoning more than a single fix:

* **An odometer that drops out to 0 m/s (or reads far off) while the car moves.**  The
  filter integrates a stopped car, the standstill detector fires zero-velocity updates,
  and the track parks while the fixes drive on: hundreds of metres of error in a
  simulated city drive where the fixes are at 8 m.  The GNSS Doppler speed sees it: a
  wheel odometer is within a few per cent of it, never metres per second off for a
  second on end.  Without Doppler speed, a car that turns cannot be standing still.
  But reflected signals (NLOS) bias the Doppler speed by metres per second too, so a
  disagreement alone does not say which one is wrong: the fixes' own chord over the same
  seconds (``CHORD_S``) decides.  The odometer is blamed only where the distance between
  the fixes sides with the Doppler speed; where no chord can be formed, the Doppler speed
  is believed.
* **A gyro clipping at its range.**  Every rate beyond the limit reads as the limit, so
  each sharp turn is under-rotated by the same sign and the smoother bends the whole
  drive to match.  Clipping shows as a pile-up of readings at exactly the extreme value,
  many times more than at the values just below it (a natural peak tapers).

Flagged samples are left out, as if the sensor had not reported: the filter follows the
fixes and its motion model there, and a warning line says which stream, how much and
where.  Units: m/s, rad/s, nanoseconds for stamps.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .conventions import NS_PER_S
from .epochs import true_runs

#: a fix's Doppler speed is compared with odometer samples at most this far from it (s)
NEAREST_FIX_S = 0.6
#: below this speed (m/s) the odometer counts as "stopped" for the turning check
STOPPED_MPS = 0.2
#: a GNSS Doppler speed below this (m/s) confirms a stop the odometer reports
STOPPED_BY_GNSS_MPS = 0.5
#: a drop of the odometer's speed faster than this (m/s^2, beyond tyre grip) is a dropout,
#: judged over this long (s: longer than the quantisation steps of a slow wheel's ticks)
MAX_DECEL_MPS2 = 10.0
DROP_LOOKBACK_S = 0.5
#: a run of zeros that began as a stop is a dropout only on this much motion seen in it (s)
ZERO_EVIDENCE_S = 3.0
#: the fixes' chord that arbitrates an odometer-Doppler disagreement spans this long (s) ...
CHORD_S = 3.0
#: ... and must side with the Doppler speed by this much (m): two fixes' own scatter, which
#: at a stop makes any chord longer than the odometer's zero
CHORD_MARGIN_M = 2.0


@dataclass
class Health:
    """Per-sample masks (True: usable) and the warning lines that explain them."""

    gyro_ok: np.ndarray | None = None
    odo_ok: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    #: how long the left-out odometer samples span (s)
    odo_bad_s: float = 0.0


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) indices of the True runs of ``mask``."""
    starts, last = true_runs(mask)
    return starts, last + 1


def _persistent(t_ns: np.ndarray, bad: np.ndarray, min_run_s: float, pad_s: float) -> np.ndarray:
    """``bad`` kept only in runs lasting ``min_run_s`` or more, each widened by ``pad_s``."""
    out = np.zeros(len(bad), bool)
    starts, ends = _runs(bad)
    for a, b in zip(starts, ends, strict=True):
        if (t_ns[b - 1] - t_ns[a]) / NS_PER_S + 1e-9 < min_run_s:
            continue
        lo = np.searchsorted(t_ns, t_ns[a] - int(pad_s * NS_PER_S), "left")
        hi = np.searchsorted(t_ns, t_ns[b - 1] + int(pad_s * NS_PER_S), "right")
        out[lo:hi] = True
    return out


def _longest_run_s(t_ns: np.ndarray, flag: np.ndarray) -> float:
    """The longest stretch of ``flag`` (s, first to last flagged stamp of a run)."""
    starts, ends = _runs(flag)
    return max(((t_ns[b - 1] - t_ns[a]) / NS_PER_S for a, b in zip(starts, ends, strict=True)),
               default=0.0)


def flagged_seconds(t_ns: np.ndarray, flag: np.ndarray) -> float:
    """Time the ``flag``ged readings cover (s): each stretch from its first stamp to one
    reporting interval (the median spacing of ``t_ns``) past its last, so that a stretch of
    n readings counts n intervals, not n - 1."""
    starts, ends = _runs(flag)
    if not len(starts):
        return 0.0
    period = float(np.median(np.diff(t_ns))) if len(t_ns) > 1 else 0.0
    return float(sum(int(t_ns[b - 1] - t_ns[a]) + period
                     for a, b in zip(starts, ends, strict=True))) / NS_PER_S


def clipped_gyro(rate_radps: np.ndarray, min_rate_radps: float, min_samples: int,
                 pile_up: float) -> tuple[np.ndarray, list[float]]:
    """Samples at a clipping limit, and the limits found (rad/s, signed).

    A limit is the extreme reading of one sign, at least ``min_rate_radps`` from zero, held
    by ``min_samples`` samples or more and by ``pile_up`` times more samples than the mean
    count of the ten distinct readings just inside it."""
    bad = np.zeros(len(rate_radps), bool)
    limits: list[float] = []
    finite = np.isfinite(rate_radps)
    for sign in (1.0, -1.0):
        v = sign * rate_radps
        if not finite.any():
            break
        top = float(np.max(v[finite]))
        if top < min_rate_radps:
            continue
        at = finite & (v >= top - 1e-9 * max(1.0, top))
        n_at = int(at.sum())
        if n_at < min_samples:
            continue
        below = np.unique(v[finite & ~at])[::-1][:10]
        n_below = np.array([np.count_nonzero(v == x) for x in below]) if len(below) else np.zeros(1)
        if n_at >= pile_up * max(float(n_below.mean()), 1.0):
            bad |= at
            limits.append(sign * top)
    return bad, limits


def chord_sides_with_doppler(odo_t: np.ndarray, odo_v: np.ndarray, fix_t: np.ndarray,
                             fix_speed: np.ndarray, fix_e: np.ndarray, fix_n: np.ndarray,
                             at: np.ndarray) -> np.ndarray:
    """Per odometer sample index in ``at``: True where the fixes' chord over ``CHORD_S``
    around it (m, from ``fix_e``/``fix_n``) is closer to the Doppler speed's distance than
    to the odometer's by ``CHORD_MARGIN_M``, or where no such chord exists (nothing
    contradicts the Doppler speed); False where the positions do not side with the Doppler
    speed (it may be the one that is off, as under reflected signals).  Stamps in ns,
    speeds m/s."""
    out = np.ones(len(at), bool)
    if len(at) == 0 or len(fix_t) < 2 or len(odo_t) < 2:
        return out
    half = np.int64(round(0.5 * CHORD_S * NS_PER_S))
    tol = NEAREST_FIX_S * NS_PER_S
    ta = odo_t[at]
    i0 = np.clip(np.searchsorted(fix_t, ta - half), 0, len(fix_t) - 1)
    i1 = np.clip(np.searchsorted(fix_t, ta + half, side="right") - 1, 0, len(fix_t) - 1)
    ok = (i1 > i0) & (np.abs(fix_t[i0] - (ta - half)) <= tol) & (np.abs(fix_t[i1] - (ta + half)) <= tol)
    # no gap between two fixes inside the chord longer than 2 x tol
    holes = np.concatenate(([0], np.cumsum(np.diff(fix_t) > 2 * tol)))
    ok &= holes[i1] == holes[i0]
    if not ok.any():
        return out
    chord = np.hypot(fix_e[i1] - fix_e[i0], fix_n[i1] - fix_n[i0])
    # both distances over [fix_t[i0], fix_t[i1]]: the odometer's from its samples (each held
    # to the next), the Doppler speed's by the trapezoid over the fixes between
    odo_dist = np.concatenate(([0.0], np.cumsum(odo_v[:-1] * np.diff(odo_t) / NS_PER_S)))
    d_odo = np.interp(fix_t[i1], odo_t, odo_dist) - np.interp(fix_t[i0], odo_t, odo_dist)
    dop = np.concatenate(([0.0], np.cumsum(0.5 * (fix_speed[1:] + fix_speed[:-1])
                                           * np.diff(fix_t) / NS_PER_S)))
    d_dop = dop[i1] - dop[i0]
    out[ok] = (np.abs(chord - d_odo) - np.abs(chord - d_dop))[ok] >= CHORD_MARGIN_M
    return out


def odometer_mismatch(odo_t: np.ndarray, odo_v: np.ndarray, fix_t: np.ndarray,
                      fix_speed: np.ndarray, gyro_t: np.ndarray | None,
                      gyro_v: np.ndarray | None, p: dict, fix_e: np.ndarray | None = None,
                      fix_n: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Odometer samples that disagree with the GNSS Doppler speed (or stand still while the
    gyro turns) for ``min_run_s`` or longer; and what was seen, for the warning.  With the
    fixes' positions (``fix_e``/``fix_n``, m, at ``fix_t``) a Doppler disagreement counts
    only where the fixes' chord sides with the Doppler speed
    (:func:`chord_sides_with_doppler`)."""
    n = len(odo_t)
    bad = np.zeros(n, bool)
    why = ""
    confirmed_stop = None
    ok = np.isfinite(fix_speed)
    ft, fv = fix_t[ok], fix_speed[ok]
    if len(ft):
        j = np.clip(np.searchsorted(ft, odo_t), 1, max(len(ft) - 1, 1))
        j0 = np.clip(j - 1, 0, len(ft) - 1)
        j1 = np.clip(j, 0, len(ft) - 1)
        near = np.where(np.abs(ft[j0] - odo_t) <= np.abs(ft[j1] - odo_t), j0, j1)
        close = np.abs(ft[near] - odo_t) <= NEAREST_FIX_S * NS_PER_S
        vg = fv[near]
        gap = np.abs(odo_v - vg)
        limit = np.maximum(p["odo_mismatch_mps"], p["odo_mismatch_share"] * np.maximum(odo_v, vg))
        # a reading of 0 is held to a tighter limit: it fires zero-velocity updates
        stopped = np.abs(odo_v) < STOPPED_MPS
        limit = np.where(stopped, np.minimum(limit, p["odo_zero_moving_mps"]), limit)
        doppler_bad = close & (gap > limit)
        if fix_e is not None and fix_n is not None and doppler_bad.any():
            at = np.flatnonzero(doppler_bad)
            fin = np.isfinite(fv) & np.isfinite(fix_e[ok]) & np.isfinite(fix_n[ok])
            doppler_bad[at] = chord_sides_with_doppler(
                odo_t, np.nan_to_num(odo_v), ft[fin], fv[fin], fix_e[ok][fin], fix_n[ok][fin], at)
        confirmed_stop = close & (vg < STOPPED_BY_GNSS_MPS)
        if doppler_bad.any():
            why = "its speed disagrees with the GNSS Doppler speed"
        bad |= doppler_bad
    if gyro_t is not None and gyro_v is not None and len(gyro_t):
        g = np.interp(odo_t, gyro_t, np.abs(gyro_v))
        turning = (np.abs(odo_v) < STOPPED_MPS) & (g > p["turning_radps"])
        if turning.any() and not why:
            why = "it reads 0 m/s while the gyro turns"
        bad |= turning
    caught = _persistent(odo_t, bad, p["min_run_s"], 0.0)
    bad = _persistent(odo_t, bad, p["min_run_s"], 0.5)
    # an odometer caught reading 0 while the car moved is not believed for the rest of that
    # run of zeros (through GNSS gaps, where nothing can check it) unless the GNSS says stopped.
    # A run that began with a drop no brake gives is a dropout; one that began as a stop is
    # blamed only on ZERO_EVIDENCE_S of motion without a break: a car that drove off keeps
    # moving, while reflected signals fake bursts of a few m/s at a stop (Doppler and
    # positions alike), and a real stop left out leaves the heading to them
    starts, ends = _runs(np.abs(odo_v) < STOPPED_MPS)
    for a, b in zip(starts, ends, strict=True):
        if not bad[a:b].any():
            continue
        before = np.interp(odo_t[a] - DROP_LOOKBACK_S * NS_PER_S, odo_t[:a + 1], odo_v[:a + 1])
        abrupt = a > 0 and before > MAX_DECEL_MPS2 * DROP_LOOKBACK_S
        bad[a:b] = abrupt or _longest_run_s(odo_t[a:b], caught[a:b]) >= ZERO_EVIDENCE_S
        if confirmed_stop is not None:
            bad[a:b] &= ~confirmed_stop[a:b]
    return bad, why


def _when(t_ns: int, t0_ns: int) -> str:
    return f"{(t_ns - t0_ns) / NS_PER_S:.1f} s"


def screen(drive, params: dict, fix_en: tuple[np.ndarray, np.ndarray] | None = None) -> Health:
    """The drive's unusable gyro and odometer samples (see the module docstring).
    ``fix_en``: every GNSS row's local east/north (m), as the caller projected them; without
    it they are projected here, in a frame centred on the first fix."""
    p = params["health"]
    out = Health()
    if not p["enabled"]:
        return out
    tp = params["time"]
    starts = [s.t_ns[0] for s in (drive.gnss, drive.gyro, drive.odo) if s is not None and len(s)]
    if not starts:
        return out
    t0 = int(min(starts))
    gyro_t = gyro_v = None
    if drive.gyro is not None and len(drive.gyro) >= 50:
        gyro_v = np.asarray(drive.gyro.yaw_rate_radps, float)
        gyro_t = drive.gyro.t_ns + np.int64(round(tp["gyro_offset_s"] * NS_PER_S))
        bad, limits = clipped_gyro(gyro_v, p["gyro_clip_min_radps"], p["gyro_clip_min_samples"],
                                   p["gyro_clip_pile_up"])
        if bad.any():
            out.gyro_ok = ~bad
            lim = " and ".join(f"{x:+.3f}" for x in limits)
            k = int(np.flatnonzero(bad)[0])
            out.notes.append(
                f"gyro: {int(bad.sum())} of {len(bad)} readings sit at its clipping limit "
                f"({lim} rad/s), first at {_when(int(gyro_t[k]), t0)}; they are not used and "
                "the track follows the fixes through those turns (a gyro with a wider range, "
                "or a smaller scale setting, avoids it)")
    if drive.odo is not None and len(drive.odo) and drive.gnss is not None:
        g = drive.gnss
        odo_t = drive.odo.t_ns + np.int64(round(tp["odo_offset_s"] * NS_PER_S))
        odo_v = np.asarray(drive.odo.speed_mps, float)
        usable = g.valid & (g.fix_quality >= 1)
        fix_t = g.t_ns[usable] + np.int64(round(tp["gnss_offset_s"] * NS_PER_S))
        if fix_en is None and np.any(np.isfinite(g.lat_deg[usable]) & np.isfinite(g.lon_deg[usable])):
            from .geodesy import LocalFrame

            fix_en = LocalFrame.for_fixes(g.lat_deg[usable], g.lon_deg[usable]).forward(
                g.lat_deg, g.lon_deg)
        fix_e, fix_n = (fix_en[0][usable], fix_en[1][usable]) if fix_en is not None else (None, None)
        bad, why = odometer_mismatch(odo_t, odo_v, fix_t, np.asarray(g.speed_mps, float)[usable],
                                     gyro_t, gyro_v, p, fix_e, fix_n)
        bad &= np.isfinite(odo_v)
        if bad.any():
            out.odo_ok = ~bad
            starts_i, _ = _runs(bad)
            secs = flagged_seconds(odo_t, bad)
            out.odo_bad_s = secs
            out.notes.append(
                f"odometer: {int(bad.sum())} of {len(bad)} readings "
                f"({secs:.{0 if secs >= 10 else 1}f} s in "
                f"{len(starts_i)} stretch{'es' if len(starts_i) > 1 else ''}, first at "
                f"{_when(int(odo_t[starts_i[0]]), t0)}) are not used: {why}; the track "
                "follows the fixes there")
    return out


__all__ = ["Health", "chord_sides_with_doppler", "clipped_gyro", "flagged_seconds",
           "odometer_mismatch", "screen"]
