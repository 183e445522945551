"""RTK false fixes: centimetre fixes that a wrong integer ambiguity put decimetres off.

An RTK receiver that resolves its carrier-phase ambiguities to the wrong integers still
reports a fixed solution (GGA quality 4) and a GST sigma of centimetres, while its
position is off by 0.2-1 m; it holds that offset for seconds and jumps back when it
fixes right.  Taken at its word, such a fix drags the track by the jump.  This check
runs once per drive, right after the streams are merged
(:func:`gpsdr_cli.align.build_epochs`), so every consumer of the fixes' sigmas -- the GNSS
error model, the four filters, both smoothers, the evaluation -- sees the same verdict.

How: the receiver's Doppler velocity predicts each centimetre fix from its neighbours to
centimetres, so a least-squares fit over a few fixes either side finds each step of the
position (:func:`step_estimates`); the steps cut the fixes into segments whose offsets
from one another are known, and the offset most fixes hold is taken as right.
Without the receiver's velocity the check is off (a quadratic in time misfits a city turn
by as much as the smallest false fix).  Units: metres, seconds.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .config import Params
from .conventions import NS_PER_S
from .epochs import Epochs


def centimetre_fixes(epochs: Epochs, params: Params) -> np.ndarray:
    """Per epoch, a usable fix whose base sigma on both axes is at most ``[gnss] rtk_cm_sd_m``
    (an RTK-fixed fix: GST or HDOP x ``uere_rtk_fixed_m``)."""
    sd = np.fmax(epochs.gnss_sd_e, epochs.gnss_sd_n)
    return epochs.has_gnss & (sd <= float(params["gnss"]["rtk_cm_sd_m"]))


def step_estimates(t_s: np.ndarray, e: np.ndarray, n: np.ndarray, sd: np.ndarray,
                   half: int, max_dt_s: float, v_e: np.ndarray | None = None,
                   v_n: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per fix i, the position step (m, east and north) between fix i-1 and fix i, and its
    1-sigma (m per axis), from a least-squares fit over ``half`` fixes either side (weighted
    by the fixes' sigmas ``sd``, m) of the motion plus a step at t_i: with the receiver's
    Doppler velocity ``v_e, v_n`` (m/s, finite at every fix) the positions less the velocity's
    integral are a line in time (a velocity bias), else the positions are a quadratic.
    A smooth motion has no step; a jump of the fixes has one.  NaN where the window has a gap
    over ``max_dt_s``, a fix without velocity (``v_e``/``v_n`` given) or leaves the series."""
    m = len(t_s)
    se = np.full(m, np.nan)
    sn = np.full(m, np.nan)
    ss = np.full(m, np.nan)
    if m < 2 * half + 1 or half < 2:
        return se, sn, ss
    doppler = v_e is not None and v_n is not None
    brk = np.diff(t_s) > max_dt_s
    if doppler:  # trapezoidal integral of the velocity; a window with a fix without one: NaN
        dt = np.diff(t_s)
        miss = ~(np.isfinite(v_e) & np.isfinite(v_n))
        v_e, v_n = np.where(miss, 0.0, v_e), np.where(miss, 0.0, v_n)
        e = e - np.concatenate(([0.0], np.cumsum(0.5 * (v_e[1:] + v_e[:-1]) * dt)))
        n = n - np.concatenate(([0.0], np.cumsum(0.5 * (v_n[1:] + v_n[:-1]) * dt)))
        brk = brk | miss[1:] | miss[:-1]
    centre = np.arange(half, m - half + 1)                       # window [c - half, c + half)
    idx = centre[:, None] + np.arange(-half, half)[None, :]
    gap = np.concatenate(([0], np.cumsum(brk)))
    ok = gap[idx[:, -1]] == gap[idx[:, 0]]
    centre, idx = centre[ok], idx[ok]
    if not len(centre):
        return se, sn, ss
    tau = t_s[idx] - t_s[centre][:, None]
    cols = [np.ones_like(tau), tau] + ([] if doppler else [tau * tau])
    A = np.stack(cols + [(tau >= 0).astype(float)], axis=2)
    wt = 1.0 / sd[idx] ** 2
    cov = np.linalg.inv(np.einsum("kij,ki,kil->kjl", A, wt, A))
    be = np.einsum("kjl,kil,ki,ki->kj", cov, A, wt, e[idx])
    bn = np.einsum("kjl,kil,ki,ki->kj", cov, A, wt, n[idx])
    se[centre], sn[centre] = be[:, -1], bn[:, -1]
    ss[centre] = np.sqrt(cov[:, -1, -1])
    return se, sn, ss


#: median of a 2-D Gaussian error's length over its per-axis sigma: sqrt(2 ln 2) (Rayleigh)
RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))
#: a step estimate's size over its stated sigma (x sqrt 2) has a median of 0.83 for fixes whose
#: errors are as stated (a Rayleigh median of 1.18 / sqrt 2); measured 0.71-0.72 on the simulated
#: RTK drives, 0.31 on a real u-blox F9P recording, 74-159 on simulated metre fixes stated to 1 cm
RAYLEIGH_MEDIAN_Z = RAYLEIGH_MEDIAN / math.sqrt(2.0)
#: judged centimetre fixes needed before their claim is judged
CLAIM_MIN_FIXES = 20


def _steps(epochs: Epochs, params: Params, f: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t s, step e, step n, its sigma per axis) at the fixes ``f`` (:func:`step_estimates`
    with the receiver's velocity)."""
    g = params["gnss"]
    t = epochs.t_ns[f] / NS_PER_S
    sd = np.fmax(epochs.gnss_sd_e[f], epochs.gnss_sd_n[f])
    # the receiver's velocity (a speed with no course: too slow to have one).  Without it
    # the check is off: a quadratic's misfit in a city turn reached 0.16 m (rtk scenario),
    # as large as the smallest false fix
    spd = epochs.gnss_speed_mps[f]
    crs = np.where(np.isfinite(epochs.gnss_course_rad[f]), epochs.gnss_course_rad[f], 0.0)
    se, sn, ss = step_estimates(t, epochs.gnss_e[f], epochs.gnss_n[f], sd,
                                int(g["rtk_step_half_fixes"]), float(g["rtk_step_max_dt_s"]),
                                spd * np.sin(crs), spd * np.cos(crs))
    return t, se, sn, ss


def centimetres_held(epochs: Epochs, params: Params, cm: np.ndarray | None = None,
                     steps: tuple[np.ndarray, ...] | None = None) -> tuple[Epochs, str | None]:
    """``epochs`` as given when its centimetre fixes scatter as little as the receiver says
    (or too few can be judged); else with their sigmas scaled up to the scatter their
    position steps show, no fix RTK (``rtk_fixed_share`` 0), and a warning line.

    A receiver or driver can state centimetres (GGA 4, GST or a covariance of 1 cm) for
    fixes with metres of error.  Taken at its word, the drive became an RTK drive and its
    track followed metre noise (simulated open sky: aekf 1.56 m against the fixes' 1.41 m).
    Each step estimate (:func:`step_estimates`) over its stated sigma has a median of 0.83
    when the fixes err as stated; the drive's median above ``[gnss] rtk_claim_max_z`` says
    they do not, and by how much: their sigmas are scaled by median / 0.83.  ``cm``,
    ``steps``: :func:`centimetre_fixes` and :func:`_steps` at them, when already made."""
    cm = centimetre_fixes(epochs, params) if cm is None else cm
    f = np.flatnonzero(cm)
    half = int(params["gnss"]["rtk_step_half_fixes"])
    if len(f) < max(2 * half + 1, CLAIM_MIN_FIXES):
        return epochs, None
    _, se, sn, ss = _steps(epochs, params, f) if steps is None else steps
    z = np.hypot(se, sn) / (ss * math.sqrt(2.0))
    z = z[np.isfinite(z)]
    if len(z) < CLAIM_MIN_FIXES:
        return epochs, None
    med = float(np.median(z))
    if not med > float(params["gnss"]["rtk_claim_max_z"]):
        return epochs, None
    ratio = med / RAYLEIGH_MEDIAN_Z
    sd_e = epochs.gnss_sd_e.copy()
    sd_n = epochs.gnss_sd_n.copy()
    sd_e[f] *= ratio
    sd_n[f] *= ratio
    stated = float(np.median(np.fmax(epochs.gnss_sd_e[f], epochs.gnss_sd_n[f])))
    return (dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n, rtk_fixed_share=0.0),
            f"the receiver states {len(f)} fixes to centimetres (RTK fixed, median sigma "
            f"{stated:.3f} m) but they step {ratio:.0f} times as far from fix to fix as that "
            f"allows: read as fixes of about {stated * ratio:.2f} m, not RTK ([gnss] "
            "rtk_claim_max_z)")


def false_fixes(epochs: Epochs, params: Params, cm: np.ndarray,
                steps: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Per epoch, the centimetre fixes judged wrong by an RTK false fix (a wrong integer
    ambiguity): the position jumps by decimetres while the receiver still reports
    centimetres, holds that offset for seconds, and jumps back when it fixes right.

    The centimetre fixes are cut into segments at every step (:func:`step_estimates` with
    the receiver's Doppler velocity, above ``[gnss] rtk_step_m`` and ``rtk_step_k`` sigmas,
    the largest within its window) and at every other fix or gap in between.  A run of
    segments joined by steps knows each segment's offset from the first; the offset held by
    the most fixes is the right one (a false fix lasts seconds, the right fix the rest), and
    the segments more than ``rtk_step_m`` off it are false.  ``steps``: :func:`_steps` at
    the centimetre fixes, when already made."""
    g = params["gnss"]
    f = np.flatnonzero(cm)
    out = np.zeros(len(epochs), bool)
    half = int(g["rtk_step_half_fixes"])
    if len(f) < 2 * half + 1:
        return out
    max_dt = float(g["rtk_step_max_dt_s"])
    t, se, sn, ss = _steps(epochs, params, f) if steps is None else steps
    size = np.hypot(se, sn)
    thr = float(g["rtk_step_m"])
    cand = np.isfinite(size) & (size > thr) & (size > float(g["rtk_step_k"]) * ss * np.sqrt(2.0))
    # the step sits where its estimate peaks: its neighbours see part of it
    sz = np.where(np.isfinite(size), size, 0.0)
    peak = np.ones(len(f), bool)
    for k in range(1, half + 1):
        peak[k:] &= sz[k:] >= sz[:-k]
        peak[:-k] &= sz[:-k] > sz[k:]
    step = cand & peak
    # a break: another epoch's fix (not centimetres) or a gap between consecutive cm fixes
    other = np.cumsum(epochs.has_gnss & ~cm)
    brk = np.zeros(len(f), bool)
    brk[1:] = (other[f[1:]] != other[f[:-1]]) | (np.diff(t) > max_dt)
    seg = np.cumsum(step | brk)                  # segment id per cm fix
    grp = np.cumsum(brk)                         # run of segments joined by steps
    off_e = np.cumsum(np.where(step, se, 0.0))   # offset since the drive's first cm fix
    off_n = np.cumsum(np.where(step, sn, 0.0))
    bad = np.zeros(len(f), bool)
    for gid in np.unique(grp):
        sel = np.flatnonzero(grp == gid)
        segs = np.unique(seg[sel])
        if len(segs) < 2:
            continue
        first = np.searchsorted(seg, segs)       # each segment's first fix
        oe, on = off_e[first], off_n[first]
        cnt = np.array([np.count_nonzero(seg == s) for s in segs])
        near = np.hypot(oe[:, None] - oe[None, :], on[:, None] - on[None, :]) <= thr
        ref = int(np.argmax(near.astype(float) @ cnt))    # the offset most fixes hold
        wrong = ~near[ref]
        bad[np.isin(seg, segs[wrong])] = True
    out[f[bad]] = True
    return out


def mark_false_fixes(epochs: Epochs, params: Params) -> tuple[Epochs, str | None]:
    """``epochs`` with the centimetre fixes' word checked, and a warning line when it fails:
    fixes that step far more than they state are no centimetre fixes
    (:func:`centimetres_held`); of those left, every one judged false (:func:`false_fixes`)
    gets a sigma of at least ``[gnss] rtk_false_sd_m``: it is no centimetre measurement,
    and every consumer of the fixes' sigmas (the filters, the graph smoother) must know it.
    The position steps are estimated once for both."""
    cm = centimetre_fixes(epochs, params)
    if not cm.any():
        return epochs, None
    steps = _steps(epochs, params, np.flatnonzero(cm))
    epochs, note = centimetres_held(epochs, params, cm, steps)
    if note:  # the sigmas grew: what is still stated to centimetres is judged afresh
        cm = centimetre_fixes(epochs, params)
        if not cm.any():
            return epochs, note
        steps = None
    wrong = false_fixes(epochs, params, cm, steps)
    if not wrong.any():
        return epochs, note
    floor = float(params["gnss"]["rtk_false_sd_m"])
    sd_e = epochs.gnss_sd_e.copy()
    sd_n = epochs.gnss_sd_n.copy()
    sd_e[wrong] = np.fmax(sd_e[wrong], floor)
    sd_n[wrong] = np.fmax(sd_n[wrong], floor)
    return dataclasses.replace(epochs, gnss_sd_e=sd_e, gnss_sd_n=sd_n), note
