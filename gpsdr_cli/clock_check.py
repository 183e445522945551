"""Dead-reckoning clocks that disagree with the receiver's by seconds.

The fixes carry the receiver's own time (NMEA UTC, UBX iTOW); the gyro and odometer carry a
logger's.  When the two differ by seconds -- a CAN logger in GPS time beside NMEA in UTC
(18 s), a PC clock that was not synchronised, a bag's header stamps against its receive
stamps -- every filter joins each fix to the dead reckoning of another moment: on a
simulated city drive an 18-s offset took aekf from 2.8 m to 28-43 m against fixes at 7.7 m.

The receiver's Doppler speed and the odometer's speed are the same signal, so their time
offset is where they agree best: the mean squared difference over every lag within
``[time] dr_clock_max_s`` (all lags at once, by FFT correlation on a 0.1-s grid), refined to
0.01 s around the best.  The gyro's yaw rate is matched the same way to the rate of the
receiver's course.  A stream's stamps are moved only when the match is clear: the best lag
at least ``dr_clock_min_s`` from zero (smaller offsets are latency, ``[time] odo_offset_s``
and ``gyro_offset_s``), its misfit under 0.8 of the misfit at zero, and the drive's speed (or
turn rate) varying enough to tell lags apart.  A warning line says what was moved.  Not run
when the user set either offset.  Units: seconds, m/s, rad/s; stamps in ns.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import Params
from .conventions import NS_PER_S

#: the grid of the coarse search (s)
GRID_S = 0.1
#: the fine search: +- this around the coarse lag (s), in steps of FINE_STEP_S
FINE_HALF_S = 0.3
FINE_STEP_S = 0.01
#: a lag is judged on at least this share of the samples that overlap at zero lag
MIN_OVERLAP_SHARE = 0.5
#: the best lag's misfit must be below this share of the misfit at zero
CLEAR_RATIO = 0.8
#: a reference signal must vary by at least this (its SD, m/s or rad/s) to time anything
MIN_SD = {"odo": 1.0, "gyro": 0.03}
#: a gyro whose own match is not clear takes the odometer's offset unless its misfit there
#: exceeds this many times its misfit at zero
SHARED_CLOCK_TOL = 1.05
#: per stream: its [time] offset key, its name in a warning, the GNSS signal it is timed by
STREAMS = {"odo": ("odo_offset_s", "odometer", "Doppler speed"),
           "gyro": ("gyro_offset_s", "gyro", "course rate")}
#: the course is a rate only above this speed (m/s)
COURSE_MIN_SPEED_MPS = 3.0


@dataclass
class ClockOffset:
    """The offset found for one stream (s, added to its stamps) and why."""

    offset_s: float
    applied: bool
    reason: str


def _misfit(t_ref: np.ndarray, v_ref: np.ndarray, t_x: np.ndarray, v_x: np.ndarray,
            lag_s: float, also_s: float | None = None) -> tuple[float, int]:
    """RMS of ref(t) - k x(t - lag) over the reference samples inside x's span (at ``also_s``
    too, when given: two lags compared on the same samples), with the scale k fitted (an
    odometer's scale error would otherwise tilt the lag); and how many samples."""
    tq = t_ref - lag_s
    inside = (tq >= t_x[0]) & (tq <= t_x[-1])
    if also_s is not None:
        inside &= (t_ref - also_s >= t_x[0]) & (t_ref - also_s <= t_x[-1])
    if inside.sum() < 2:
        return math.inf, 0
    r = v_ref[inside]
    x = np.interp(tq[inside], t_x, v_x)
    xx = float(np.dot(x, x))
    k = float(np.dot(r, x)) / xx if xx > 0 else 1.0
    d = r - k * x
    return float(np.sqrt(np.mean(d * d))), int(inside.sum())


def _misfits(t_ref: np.ndarray, v_ref: np.ndarray, t_x: np.ndarray, v_x: np.ndarray,
             lags_s: np.ndarray, chunk: int = 16) -> np.ndarray:
    """:func:`_misfit` at every lag of ``lags_s`` (s), a few lags per numpy call."""
    out = np.empty(len(lags_s))
    for a in range(0, len(lags_s), chunk):
        tq = t_ref[None, :] - lags_s[a:a + chunk, None]
        m = (tq >= t_x[0]) & (tq <= t_x[-1])
        x = np.where(m, np.interp(tq, t_x, v_x), 0.0)
        r = np.where(m, v_ref[None, :], 0.0)
        cnt = m.sum(axis=1)
        xx = np.einsum("ij,ij->i", x, x)
        k = np.where(xx > 0, np.einsum("ij,ij->i", r, x) / np.where(xx > 0, xx, 1.0), 1.0)
        d = r - k[:, None] * x
        ms = np.einsum("ij,ij->i", d, d) / np.maximum(cnt, 1)
        out[a:a + chunk] = np.where(cnt >= 2, np.sqrt(ms), np.inf)
    return out


def _coarse(t_ref: np.ndarray, v_ref: np.ndarray, t_x: np.ndarray, v_x: np.ndarray,
            max_s: float) -> float:
    """The lag (s) within +-max_s minimising the mean squared difference of ref(t) and
    x(t - lag) on a GRID_S grid (masked correlation by FFT); NaN without enough overlap."""
    t0 = min(t_ref[0], t_x[0]) - max_s
    t1 = max(t_ref[-1], t_x[-1]) + max_s
    n = int(math.ceil((t1 - t0) / GRID_S)) + 1
    if n > 2_000_000:  # a drive of days: thin the reference
        return math.nan
    grid = t0 + GRID_S * np.arange(n)

    def on_grid(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.clip(np.round((t - t0) / GRID_S).astype(np.int64), 0, n - 1)
        s = np.bincount(idx, weights=v, minlength=n)
        c = np.bincount(idx, minlength=n).astype(float)
        m = c > 0
        out = np.zeros(n)
        out[m] = s[m] / c[m]
        return out, m.astype(float)

    a, ma = on_grid(t_ref, v_ref)
    # the dead reckoning is dense: interpolate it onto the grid inside its span
    inside = (grid >= t_x[0]) & (grid <= t_x[-1])
    b = np.where(inside, np.interp(grid, t_x, v_x), 0.0)
    mb = inside.astype(float)
    size = 1 << int(math.ceil(math.log2(2 * n)))

    def xcorr(p: np.ndarray, q: np.ndarray) -> np.ndarray:
        # r[k] = sum_t p[t] q[t - k]: ref at t against x at t - lag, lag = k GRID_S
        return np.fft.irfft(np.fft.rfft(p, size) * np.conj(np.fft.rfft(q, size)), size)

    cnt = xcorr(ma, mb)
    s_aa = xcorr(ma * a * a, mb)
    s_bb = xcorr(ma, mb * b * b)
    s_ab = xcorr(ma * a, mb * b)
    k_max = int(round(max_s / GRID_S))
    ks = np.arange(-k_max, k_max + 1)
    cnt_k = np.round(cnt[ks % size])
    msd = (s_aa[ks % size] + s_bb[ks % size] - 2.0 * s_ab[ks % size]) / np.maximum(cnt_k, 1.0)
    zero = cnt_k[k_max]
    ok = cnt_k >= max(MIN_OVERLAP_SHARE * zero, 20.0)
    if not ok.any():
        return math.nan
    msd = np.where(ok, msd, np.inf)
    return float(ks[int(np.argmin(msd))] * GRID_S)


def find_offset(t_ref: np.ndarray, v_ref: np.ndarray, t_x: np.ndarray, v_x: np.ndarray,
                max_s: float, min_s: float, min_sd: float) -> ClockOffset:
    """The offset (s) to add to stream x's stamps so that x matches the reference signal
    (both in seconds on one axis), and whether it is clear enough to apply."""
    ok_r = np.isfinite(t_ref) & np.isfinite(v_ref)
    ok_x = np.isfinite(t_x) & np.isfinite(v_x)
    t_ref, v_ref, t_x, v_x = t_ref[ok_r], v_ref[ok_r], t_x[ok_x], v_x[ok_x]
    if len(t_ref) < 50 or len(t_x) < 50:
        return ClockOffset(0.0, False, "too few samples")
    if float(np.std(v_ref)) < min_sd:
        return ClockOffset(0.0, False, "the reference signal hardly varies")
    lag = _coarse(t_ref, v_ref, t_x, v_x, max_s)
    if not math.isfinite(lag):
        return ClockOffset(0.0, False, "no overlap")
    fine = lag + np.arange(-FINE_HALF_S, FINE_HALF_S + 0.5 * FINE_STEP_S, FINE_STEP_S)
    fits = _misfits(t_ref, v_ref, t_x, v_x, fine)
    lag = float(fine[int(np.argmin(fits))])
    best, n_common = _misfit(t_ref, v_ref, t_x, v_x, lag, 0.0)   # both on the same samples
    at_zero, _ = _misfit(t_ref, v_ref, t_x, v_x, 0.0, lag)
    if n_common < 50:  # the clocks barely overlap at zero: compare on each lag's own samples
        best, at_zero = float(np.min(fits)), _misfit(t_ref, v_ref, t_x, v_x, 0.0)[0]
    if abs(lag) < min_s:
        return ClockOffset(lag, False, "within the latency range")
    if not (best < CLEAR_RATIO * at_zero):
        return ClockOffset(lag, False, f"not clear (misfit {best:.3g} against {at_zero:.3g} at 0)")
    return ClockOffset(lag, True, f"misfit {best:.3g} against {at_zero:.3g} at 0")


def _course_rate(t_s: np.ndarray, course_deg: np.ndarray, speed: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The receiver's course rate (rad/s, counter-clockwise positive like a yaw rate) at the
    midpoints of consecutive fixes both above COURSE_MIN_SPEED_MPS."""
    ok = np.isfinite(course_deg) & np.isfinite(speed) & (speed > COURSE_MIN_SPEED_MPS)
    t, c = t_s[ok], np.radians(course_deg[ok])
    if len(t) < 3:
        return np.zeros(0), np.zeros(0)
    dt = np.diff(t)
    dc = np.angle(np.exp(1j * np.diff(c)))
    use = (dt > 0) & (dt <= 1.5)
    # course is clockwise from north; a yaw rate is counter-clockwise
    return 0.5 * (t[1:] + t[:-1])[use], -(dc[use] / dt[use])


#: a receiver clock step: the fixes' stamps go back by more than ``[time] dr_clock_min_s`` from
#: one fix to the next (in the log's order); at most this many are judged (more: a log whose
#: stamps are scrambled, which the alignment's ordering handles record by record)
MAX_GNSS_STEPS = 4
#: a stretch of fixes between two steps is timed only when it has this many fixes
MIN_STRETCH_FIXES = 50


def _stretch_misfit(t_fix: np.ndarray, speed: np.ndarray, course: np.ndarray, drive,
                    t_base: int) -> Callable[[float], float] | None:
    """For one stretch of fixes: the misfit of the dead reckoning against it (odometer speed
    to Doppler speed, else yaw rate to course rate; :func:`_misfit`) at its best lag within
    ``FINE_HALF_S`` of a given lag (s); None when the stretch cannot be timed."""
    if drive.odo is not None and len(drive.odo) >= 50:
        t_r, v_r = t_fix, speed
        t_x = (drive.odo.t_ns - t_base) / NS_PER_S
        v_x = np.asarray(drive.odo.speed_mps, float)
        min_sd = MIN_SD["odo"]
    elif drive.gyro is not None and len(drive.gyro) >= 50:
        t_r, v_r = _course_rate(t_fix, course, speed)
        t_x = (drive.gyro.t_ns - t_base) / NS_PER_S
        v_x = np.asarray(drive.gyro.yaw_rate_radps, float)
        min_sd = MIN_SD["gyro"]
    else:
        return None
    ok = np.isfinite(t_x) & np.isfinite(v_x)
    t_x, v_x = t_x[ok], v_x[ok]
    fine = np.isfinite(t_r) & np.isfinite(v_r)
    t_r, v_r = t_r[fine], v_r[fine]
    if len(t_r) < MIN_STRETCH_FIXES or len(t_x) < 50 or float(np.std(v_r)) < min_sd:
        return None
    near = np.arange(-FINE_HALF_S, FINE_HALF_S + 0.5 * FINE_STEP_S, FINE_STEP_S)
    return lambda lag: float(np.min(_misfits(t_r, v_r, t_x, v_x, lag + near)))


def gnss_clock_steps(drive, params: Params):
    """``(drive, notes)``: the drive with the fixes after a receiver clock step re-stamped
    onto the dead reckoning's clock, where the dead reckoning says so.

    A receiver (or the logger stamping its sentences) whose clock steps back by seconds in
    mid-drive leaves the fixes after the step seconds early: ordering the stamps drops the
    overlap, and every later fix then met the dead reckoning of another moment (a 2-s step
    took every filter from 0.4 m to 10 m on a simulated drive).  The log itself says by how
    much: the stamps go back by the step less one fix period.  So the hypotheses are few: the
    dead reckoning runs on the clock of one stretch between steps, and the others are off it by
    the steps between.  Each hypothesis is scored by the misfit of the odometer's speed to the
    Doppler speed (else the gyro's rate to the course rate; :func:`_misfit`) over every
    stretch, each within ``FINE_HALF_S`` of its hypothesised lag, and the best is taken when its
    misfit is under :data:`CLEAR_RATIO` of the stamps' as logged.  (Searched freely, a
    city's repeating turns matched a 200-s stretch of course rates 108 s off.)  A dead
    reckoning seconds off every stretch is :func:`check`'s to find.  Not run with ``[time]
    dr_clock_check = false``."""
    tp = params["time"]
    g = drive.gnss
    if not tp["dr_clock_check"] or g is None or len(g) < 2 * MIN_STRETCH_FIXES:
        return drive, []
    min_s = float(tp["dr_clock_min_s"])
    t = np.asarray(g.t_ns, np.int64)
    dt = np.diff(t)
    steps = np.flatnonzero(dt < -round(min_s * NS_PER_S)) + 1
    if not 0 < len(steps) <= MAX_GNSS_STEPS or not (dt > 0).any():
        return drive, []
    period = int(np.median(dt[dt > 0]))
    bounds = np.concatenate(([0], steps, [len(t)]))
    # clock of stretch k relative to stretch 0 (s; the stamps after a step back are early)
    clock = np.concatenate(([0.0], -np.cumsum((t[steps - 1] - t[steps] + period) / NS_PER_S)))
    usable = g.valid & (g.fix_quality >= 1)
    t_base = int(t[usable][0]) if usable.any() else int(t[0])
    speed = np.asarray(g.speed_mps, float)
    course = np.asarray(g.course_deg, float)
    fits, sizes = [], []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        u = np.flatnonzero(usable[a:b]) + a
        fits.append(_stretch_misfit((t[u] - t_base) / NS_PER_S, speed[u], course[u], drive, t_base)
                    if len(u) >= MIN_STRETCH_FIXES else None)
        sizes.append(len(u))
    timed = [k for k, f in enumerate(fits) if f is not None]
    if len(timed) < 2:
        return drive, []

    def score(shifts: np.ndarray) -> float:
        """Fix-weighted mean square misfit with stretch k moved by shifts[k] (s)."""
        return sum(sizes[k] * fits[k](-shifts[k]) ** 2 for k in timed) / sum(sizes[k] for k in timed)

    as_logged = score(np.zeros(len(fits)))
    best = min((score(clock[r] - clock), r) for r in timed)
    if not (best[0] < CLEAR_RATIO ** 2 * as_logged):
        return drive, []
    shifts = clock[best[1]] - clock
    new_t, notes = t.copy(), []
    for k, shift in enumerate(shifts):
        if shift == 0.0:
            continue
        a, b = int(bounds[k]), int(bounds[k + 1])
        new_t[a:b] += round(shift * NS_PER_S)
        where = (f"from fix {a + 1}, where their time stamps go back "
                 f"{(t[a - 1] - t[a]) / NS_PER_S:.2f} s," if a > 0 else "from the first")
        upto = "the end" if b == len(t) else f"fix {b}, where they go back " \
            f"{(t[b - 1] - t[b]) / NS_PER_S:.2f} s"
        notes.append(f"GNSS: the receiver's clock steps: the {b - a} fixes {where} to {upto} "
                     f"match the dead reckoning {shift:+.2f} s later and were re-stamped so "
                     f"(misfit {math.sqrt(best[0]):.3g} against {math.sqrt(as_logged):.3g} as "
                     "logged; [time] dr_clock_check = false keeps them)")
    return dataclasses.replace(drive, gnss=dataclasses.replace(g, t_ns=new_t)), notes


def check(drive, params: Params) -> tuple[Params, list[str]]:
    """``params`` with ``[time] odo_offset_s`` / ``gyro_offset_s`` set where the stream's
    clock is clearly seconds off the receiver's, and the warning lines saying so."""
    tp = params["time"]
    if (not tp["dr_clock_check"] or drive.gnss is None or not len(drive.gnss)
            or float(tp["odo_offset_s"]) != 0.0 or float(tp["gyro_offset_s"]) != 0.0):
        return params, []
    g = drive.gnss
    usable = g.valid & (g.fix_quality >= 1)
    if usable.sum() < 50:
        return params, []
    t_base = g.t_ns[usable][0]
    t_fix = (g.t_ns[usable] - t_base) / NS_PER_S + float(tp["gnss_offset_s"])
    speed = np.asarray(g.speed_mps, float)[usable]
    max_s, min_s = float(tp["dr_clock_max_s"]), float(tp["dr_clock_min_s"])
    out, notes = params, []
    found: dict[str, ClockOffset] = {}
    if drive.odo is not None and len(drive.odo) >= 50:
        t_o = (drive.odo.t_ns - t_base) / NS_PER_S
        found["odo"] = find_offset(t_fix, speed, t_o, np.asarray(drive.odo.speed_mps, float),
                                   max_s, min_s, MIN_SD["odo"])
    if drive.gyro is not None and len(drive.gyro) >= 50:
        t_c, rate = _course_rate(t_fix, np.asarray(g.course_deg, float)[usable], speed)
        t_y = (drive.gyro.t_ns - t_base) / NS_PER_S
        yaw = np.asarray(drive.gyro.yaw_rate_radps, float)
        res = find_offset(t_c, rate, t_y, yaw, max_s, min_s, MIN_SD["gyro"])
        odo = found.get("odo")
        if not res.applied and odo is not None and odo.applied:
            # one logger's clock, usually: the course rate (noisy under reflections, flat on
            # straight roads) need only not speak against the odometer's offset
            fin = np.isfinite(yaw)
            at_odo, _ = _misfit(t_c, rate, t_y[fin], yaw[fin], odo.offset_s, 0.0)
            at_zero, _ = _misfit(t_c, rate, t_y[fin], yaw[fin], 0.0, odo.offset_s)
            if len(t_c) < 50 or not at_odo > SHARED_CLOCK_TOL * at_zero:
                res = ClockOffset(odo.offset_s, True, "the odometer's offset: one logger's "
                                  f"clock (course-rate misfit {at_odo:.3g} against {at_zero:.3g} "
                                  "at 0)")
        found["gyro"] = res
    applied = {name: res for name, res in found.items() if res.applied}
    if applied:
        out = copy.deepcopy(params)
    for name, res in applied.items():
        key, what, ref = STREAMS[name]
        out["time"][key] = res.offset_s
        notes.append(f"{what}: its clock is {-res.offset_s:+.2f} s off the receiver's (it "
                     f"matches the GNSS {ref} only so shifted; {res.reason}); its stamps were "
                     f"moved by {res.offset_s:+.2f} s ([time] {key} sets it, "
                     "dr_clock_check = false turns the check off)")
    return out, notes


__all__ = ["ClockOffset", "check", "find_offset", "gnss_clock_steps"]
