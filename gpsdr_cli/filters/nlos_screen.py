"""Fixes the whole drive's dead reckoning outvotes are left out of the filters.

On a drive the chord check (:mod:`gpsdr_cli.filters.gnss_model`) marks as NLOS, reflected
signals give most fixes errors of tens of metres that stay consistent among themselves
for seconds to minutes.  A forward filter cannot tell a slow NLOS bias from a slow drift
of its own dead reckoning, and an inflated sigma only slows its pull: on the simulated
``urban_nlos`` drive every filter still ended at 20-40 m against the fixes' 32-40 m.
A post-processor has the whole drive: the robust batch fit of the dead reckoning to
every fix (:func:`gpsdr_cli.filters.graph.smooth_graph`, Cauchy kernel) gives each fix a
weight, and a fix whose weight is below ``[gnss] nlos_screen_min_weight`` (its residual
beyond the kernel's scale) is not given to the filter at all.  With those fixes left out
the same filters reach 1.5 m on that drive.

Fix by fix, a 40-s run of 200 reflected fixes outvotes 70 clean ones.  So by default
(``[graph] nlos_segments``) the fixes are then cut into runs that share one bias
(:mod:`.nlos_segments`, against that fit's track), the fit is solved again with one vote per
run, and the fixes kept are those of the runs within ``[graph] nlos_segment_keep_m`` of
its track (docs/decisions/0044), less any of their fixes farther from that track than
``[gnss] nlos_screen_fix_sigmas`` of its own sigmas (:func:`far_fixes`: the edges of
reflections, which the receiver ramps in and out; docs/decisions/0045), and less the
fixes next to a left-out run that lie ``nlos_screen_edge_sigmas`` its way (:func:`edge_fixes`:
the start of that ramp, nearer than far; docs/decisions/0049).

The runs are cut against a track the reflections still pull where no clean fix anchors it
(a reflected run at the end of a drive was kept whole).  So ``[gnss] nlos_screen_passes``
= 2 judges them a second time, against the ekf's smoothed track of the fixes the first
pass kept: its gate and the dead reckoning hold that track off a reflected run which the
fit over every fix had followed (docs/decisions/0046); before the first fix kept, that track
is dead-reckoned back from it with the fit's calibration (:func:`judge_kept`,
docs/decisions/0059).  Not where that track lies farther from the fixes than
``nlos_screen_max_offset_m`` (the last check below): its ekf crossed minutes without a kept
fix on a drift learnt from a few, and the first judgement stands (decisions/0072).  The
screen's judge is the ekf whatever filter runs after it, so every filter is given the same
fixes.  No clean fix follows the drive's last run to hold a track off a reflection that
ramps in there, so the later segments of that run are judged once more, against the ekf's
track of the fixes before them (:func:`last_run_drift`, ``[gnss] nlos_screen_last_sigmas``;
decisions/0048).
The screen is a judgement over the whole drive: the quality check's backward pass, over the
time-reversed drive, is given the forward judgement read backwards.

Only on NLOS drives with a gyro and an odometer (the batch fit needs a dead reckoning
that holds the shape on its own), and only when the fit converges, keeps at least
``nlos_screen_min_kept`` of the fixes, and the judge's track of the fixes it keeps stays
within ``nlos_screen_max_offset_m`` of all the fixes (its forward pass, median over any
``OFFSET_WINDOW_S``): reflections put fixes tens of metres off, so a track farther from all
of them is the dead reckoning's own error (a gyro whose scale is 3 % off had the fit keep a
few fixes in 200 s, and the track of those ran 1.9 km away; decisions/0061).  Otherwise the
epochs pass unchanged, and ekf/aekf take their clear-sky error states, which follow the
fixes (:func:`gpsdr_cli.filters.register`).  Units: metres, seconds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from ..config import Params
from ..conventions import NS_PER_S
from ..epochs import Epochs, true_runs
from ..rtk_false_fix import RAYLEIGH_MEDIAN
from .base import FilterResult

#: the last screen: (its drive's :func:`_fingerprint`, which of the fixes were left out, info).
#: A smoothed run's quality check runs the forward filter again, and every filter of a
#: comparison is given the same screen
_LAST: list[tuple[tuple, np.ndarray, dict]] = []
#: the track of the fixes kept is compared with every fix over windows this long (s), each
#: with at least this many fixes (a median over a few seconds of fixes, not one outlier)
OFFSET_WINDOW_S = 30.0
OFFSET_MIN_FIXES = 10


def _fingerprint(epochs: Epochs, params: Params) -> tuple:
    """What the screen weighs: the parameters (the filter and smoothing aside: the judges are
    the ekf whatever runs after it), the fixes (east, north, time steps) and the
    dead reckoning from the first fix to the last (counts, sums of readings; a backward
    pass starts at the last fix, so its lead-in is the forward pass's tail)."""
    f = np.flatnonzero(epochs.has_gnss)
    s = slice(int(f[0]), int(f[-1]) + 1) if len(f) else slice(0, 0)
    gyro, odo = epochs.has_gyro[s], epochs.has_odo[s]
    return (repr({k: v for k, v in params.items() if k != "filter"}), s.stop - s.start,
            int(np.count_nonzero(gyro)), int(np.count_nonzero(odo)),
            float(np.nansum(epochs.odo_speed_mps[s][odo])),
            float(np.nansum(epochs.yaw_rate_radps[s][gyro])),
            epochs.gnss_e[f], epochs.gnss_n[f], np.diff(np.asarray(epochs.t_ns, np.int64)[f]))


#: float arrays of two fingerprints agree within this (m, m/s): the receiver-minus-odometer
#: speeds of a drive read backwards and turned round again differ from the forward ones by
#: a few 1e-17 m/s (interpolated on the reversed clock), and a four-hour NLOS drive was
#: screened twice, 2.3 x the time of one
FINGERPRINT_ATOL = 1e-9


def _agree(x: object, y: object) -> bool:
    """Two fingerprint entries agree: arrays element by element (NaN equal to NaN, float
    arrays within :data:`FINGERPRINT_ATOL`), anything else by ``==``."""
    if not (isinstance(x, np.ndarray) or isinstance(y, np.ndarray)):
        return x == y
    x, y = np.asarray(x), np.asarray(y)
    if x.shape != y.shape:
        return False
    if x.dtype.kind == "f" and y.dtype.kind == "f":
        return bool(np.allclose(x, y, rtol=0.0, atol=FINGERPRINT_ATOL, equal_nan=True))
    return bool(np.array_equal(x, y))


def _same(a: tuple, b: tuple) -> bool:
    """Two fingerprints agree, entry by entry (:func:`_agree`)."""
    return len(a) == len(b) and all(_agree(x, y) for x, y in zip(a, b, strict=True))


def _cached(epochs: Epochs, fp: tuple) -> tuple[Epochs, dict] | None:
    """The last screen's answer if ``fp`` (:func:`_fingerprint`) is its drive's."""
    if not _LAST or not _same(_LAST[0][0], fp):
        return None
    _, out_fix, info = _LAST[0]
    has_gnss = epochs.has_gnss.copy()
    has_gnss[np.flatnonzero(has_gnss)[out_fix]] = False
    return dataclasses.replace(epochs, has_gnss=has_gnss), dict(info)


def screen(epochs: Epochs, params: Params, nlos_drive: bool,
           judge: Callable[[Epochs, Params], FilterResult],
           doppler: np.ndarray | None = None) -> tuple[Epochs, dict]:
    """``(epochs, info)``: the epochs with the outvoted fixes' ``has_gnss`` cleared, and
    what was done (``info["nlos_screened"]``: fixes left out; absent when not applied, where
    ``info["nlos_screen_not_applied"]`` says why (and ``info["nlos_screen"]`` "not applied: why");
    ``info["nlos_screen_skipped"]``: "no odometer" or "no gyro" on an NLOS drive that
    lacks one; ``info["nlos_screen_odo_scale"]``: the fit's odometer scale, true speed over
    the odometer's; ``info["nlos_screen_gyro_bias_radps"]``: its gyro bias, in the readings
    corrected by ``info["nlos_screen_gyro_scale"]``, g: true rate = (1 + g) x reading - bias).
    ``judge``: the bare ekf (:func:`gpsdr_cli.filters.bare`), whichever filter runs after the
    screen.
    ``doppler``: per epoch, the receiver's Doppler speed minus the odometer's before any was
    left out (m/s, :func:`.gnss_model.doppler_misfit`; NaN where not measured): a segment
    of fixes whose velocities disagree weighs less (:func:`.nlos_segments.segment_trust`)."""
    if not nlos_drive:
        return epochs, {}
    if not (epochs.has_gyro.any() and epochs.has_odo.any()):
        return epochs, {"nlos_screen_skipped": "no odometer" if epochs.has_gyro.any()
                        else "no gyro"}
    if not params["gnss"]["nlos_screen"]:
        return epochs, {}
    if epochs.time_reversed:
        # the quality check's backward pass: the drive judged forward, read backwards (the
        # judgement is over the whole drive; judged backwards, the main track would depend
        # on whether the check ran first)
        from ..qc import reverse_epochs

        fwd, info = screen(reverse_epochs(epochs), params, nlos_drive, judge,
                           None if doppler is None else np.asarray(doppler)[::-1])
        return dataclasses.replace(epochs, has_gnss=fwd.has_gnss[::-1].copy()), info
    fp = _fingerprint(epochs, params) + (None if doppler is None else np.asarray(doppler, float),)
    hit = _cached(epochs, fp)
    if hit is not None:
        return hit
    out, info = _screen(epochs, params, judge, doppler)
    _LAST[:] = [(fp, ~out.has_gnss[epochs.has_gnss], dict(info))]
    return out, info


def _screen(epochs: Epochs, params: Params, run: Callable[[Epochs, Params], FilterResult],
            doppler: np.ndarray | None = None) -> tuple[Epochs, dict]:
    g = params["gnss"]
    max_offset_m = float(g["nlos_screen_max_offset_m"])
    from .gnss_model import reflected_doppler
    from .graph import own_sigmas, smooth_graph, solve_by_segments

    # the start: the ekf, with an NLOS drive's receiver velocity sigmas (forward only: the fit
    # reached the same fixes from it as from the smoothed track, one RTS pass sooner)
    probe = reflected_doppler(params, bool(epochs.has_odo.any()))
    probe["filter"]["smooth"] = False
    init = run(epochs, probe)
    probe["filter"]["smooth"] = True
    # each fix weighed by its own sigma: the chord check's scaled sigmas would shrink the
    # very residuals the weights are for; white fixes, as the graph takes an NLOS drive
    fit = own_sigmas(probe)
    # Cauchy only: with the bounded last stage the screen left seed 14 of the 283-s city
    # drives a forward track of 46 m against fixes at 35 m (decisions/0035)
    fit["graph"]["nlos_last_kernel"] = ""
    # ... and a segment of fixes whose receiver velocities disagree with the odometer weighs
    # less (its fixes' information times its trust): a reflected plateau of minutes had the
    # most fixes, and the fit kept it (decisions/0059, 0069)
    fit_epochs = epochs
    if doppler is not None:
        from .nlos_segments import fix_segments, segment_trust

        trust = segment_trust(fix_segments(epochs, init, fit["graph"])[0], doppler,
                              float(g["nlos_doppler_trust_mps"]))
        if (trust < 1.0).any():
            fit_epochs = dataclasses.replace(epochs, gnss_sd_e=epochs.gnss_sd_e / np.sqrt(trust),
                                             gnss_sd_n=epochs.gnss_sd_n / np.sqrt(trust))
    outcome = smooth_graph(fit_epochs, init, fit, sigmas=False)  # the fixes weighed, not the track
    if outcome.result is None or len(outcome.gnss_weight) != len(epochs):
        return epochs, not_applied(outcome.message)
    w = outcome.gnss_weight
    fix = epochs.has_gnss
    out = fix & np.isfinite(w) & (w < float(g["nlos_screen_min_weight"]))
    if bool(fit["graph"]["nlos_segments"]):
        # each run of fixes with one reflection bias votes once (a long run of reflected
        # fixes outvoted the clean ones around it fix by fix); the runs are cut against the
        # fit, then against the ekf's track of the fixes kept (decisions/0046)
        track = outcome.result
        seg = None
        for n_pass in range(max(int(g["nlos_screen_passes"]), 1)):
            if n_pass:
                track = judge_kept(epochs, fix & ~out, run, probe, outcome)
                # a judge farther from every fix than a reflection reaches has dead-reckoned
                # across a long gap in the fixes kept: runs cut against it would be noise
                if farthest_window(epochs, track, fix)[0] > max_offset_m:
                    break
            seg_out, seg_pass, near = solve_by_segments(epochs, track, fit, sigmas=False,
                                                        doppler=doppler)
            if seg_out.result is None:
                break
            outcome, out, seg = seg_out, fix & ~near, seg_pass
        # ... the last run of the drive once more, against the fixes before it (decisions/0048)
        if seg is not None:
            out |= last_run_drift(epochs, fix & ~out, seg,
                                  lambda ep, p: judge_kept(ep, ep.has_gnss, run, p, outcome),
                                  probe, float(g["nlos_screen_last_sigmas"]),
                                  float(fit["graph"]["nlos_segment_keep_m"]))
    # ... and so is a fix of a kept run that lies far from the fit's track: the edge of a
    # reflection the receiver's own filter ramps in and out (decisions/0045)
    out |= far_fixes(epochs, outcome.result, fix & ~out, float(g["nlos_screen_fix_sigmas"]))
    out |= edge_fixes(epochs, outcome.result, fix & ~out, fix & out,
                      float(g["nlos_screen_edge_sigmas"]), float(g["nlos_screen_edge_s"]),
                      float(fit["graph"]["nlos_segment_keep_m"]))
    kept = int(np.count_nonzero(fix & ~out))
    if kept < float(g["nlos_screen_min_kept"]) * max(int(fix.sum()), 1):
        return epochs, not_applied(f"only {kept} of {int(fix.sum())} fixes agree")
    if not out.any():
        return epochs, {"nlos_screened": 0}
    # ... and only if the forward track of the fixes kept (the default output) stays within a
    # reflection's reach of the fixes: a gyro whose scale is 3 % off left a few fixes in
    # 200 s, and the ekf's track of them ran 1.9 km from every fix (decisions/0061)
    forward = {**probe, "filter": {**probe["filter"], "smooth": False}}
    far_m, at_s = farthest_window(epochs, judge_kept(epochs, fix & ~out, run, forward, outcome),
                                  fix)
    if far_m > max_offset_m:
        return epochs, not_applied(f"the track of the {kept} fixes it would keep lies {far_m:.0f} m "
                                    f"from the fixes around {at_s:.0f} s")
    info = {"nlos_screened": int(out.sum())}
    if math.isfinite(outcome.odo_scale):
        info["nlos_screen_odo_scale"] = outcome.odo_scale
    if math.isfinite(outcome.gyro_bias_radps):
        info["nlos_screen_gyro_bias_radps"] = outcome.gyro_bias_radps
    if math.isfinite(outcome.gyro_scale):
        info["nlos_screen_gyro_scale"] = outcome.gyro_scale
    return dataclasses.replace(epochs, has_gnss=fix & ~out), info


def not_applied(why: str) -> dict:
    """The screen's info when it could not judge the fixes (the filters then follow them):
    ``nlos_screen_not_applied`` is ``why``, ``nlos_screen`` "not applied: ``why``"."""
    return {"nlos_screen": f"not applied: {why}", "nlos_screen_not_applied": why}


def judge_kept(epochs: Epochs, kept: np.ndarray, run: Callable[[Epochs, Params], FilterResult],
               probe: Params, fit) -> FilterResult:
    """The judge's track of the ``kept`` fixes (a mask over the epochs), its gyro read with the
    batch ``fit``'s scale correction and the epochs before the first of them dead-reckoned back
    from it with the fit's gyro bias and odometer scale
    (:func:`gpsdr_cli.lead_in.run_from_first_fix`), as the filters are after the screen.
    Started at epoch 0, the judge began at that fix's position with no heading: with the
    first 100 s of a simulated city drive left out, its track lay 800 m off there and the
    runs cut against it held no fix that agreed."""
    from ..lead_in import run_from_first_fix
    from .calibration import scaled_yaw

    judged = dataclasses.replace(epochs, has_gnss=kept)
    if math.isfinite(fit.gyro_scale):
        judged = scaled_yaw(judged, 1.0 + fit.gyro_scale)
    return run_from_first_fix(
        judged, run, probe,
        gyro_bias=fit.gyro_bias_radps if math.isfinite(fit.gyro_bias_radps) else None,
        true_scale=fit.odo_scale if math.isfinite(fit.odo_scale) and fit.odo_scale > 0 else None)


def farthest_window(epochs: Epochs, track: FilterResult, fixes: np.ndarray,
                    window_s: float = OFFSET_WINDOW_S) -> tuple[float, float]:
    """``(distance m, time s)``: the largest median distance from ``track`` to the ``fixes``
    (a mask over the epochs) over windows of ``window_s`` seconds (stepped by half a
    window), and the middle of that window in seconds since the first epoch; (0, NaN) with
    no window of ``OFFSET_MIN_FIXES`` fixes."""
    f = np.flatnonzero(fixes)
    t_s = (np.asarray(epochs.t_ns, np.int64)[f] - int(epochs.t_ns[0])) / NS_PER_S
    d = np.hypot(epochs.gnss_e[f] - track.e[f], epochs.gnss_n[f] - track.n[f])
    ok = np.isfinite(d)
    from .nlos_segments import largest_window_median

    return largest_window_median(t_s[ok], d[ok], window_s, OFFSET_MIN_FIXES)


def last_run_drift(epochs: Epochs, kept: np.ndarray, seg: np.ndarray,
                   run: Callable[[Epochs, Params], FilterResult], probe: Params, k: float,
                   keep_m: float) -> np.ndarray:
    """Of the ``kept`` fixes (a mask over the epochs), the later segments of the drive's last
    run that lie farther than max(``keep_m``, ``k`` sigmas) from the ekf's smoothed track of
    the kept fixes without them (``seg``: rows segment id and run id per epoch,
    :func:`.nlos_segments.fix_segments`; sigma: that track's, m; ``probe``: the judge's
    parameters, smoothed).  No clean fix follows the last run to hold the track off a
    reflection that ramps in (no jump, so no new run), and the judge's track follows it
    there; the dead reckoning from the run's first segment does not.  ``k`` <= 0: none."""
    drop = np.zeros(len(kept), bool)
    idx = np.flatnonzero(kept)
    if not k > 0.0 or not len(idx):
        return drop
    last = kept & (seg[1] == seg[1][idx[-1]])
    ids = np.unique(seg[0][last])
    if len(ids) < 2 or last.sum() == kept.sum():
        return drop
    later = last & (seg[0] != ids[0])
    track = run(dataclasses.replace(epochs, has_gnss=kept & ~later), probe)
    for sid in ids[1:]:
        f = np.flatnonzero(last & (seg[0] == sid))
        off = math.hypot(float(np.median(epochs.gnss_e[f] - track.e[f])),
                         float(np.median(epochs.gnss_n[f] - track.n[f])))
        sd = float(np.median(np.sqrt(track.var_e[f] + track.var_n[f])))
        if off > max(keep_m, k * sd):
            drop[f] = True
    return drop


def far_fixes(epochs: Epochs, track: FilterResult, fixes: np.ndarray, k: float) -> np.ndarray:
    """Of ``fixes`` (a mask over the epochs), those farther from ``track`` than ``k`` times
    their own sigma (per axis, m), each sigma first scaled by how far the fixes' residuals
    run beyond their sigmas (their median over the Rayleigh median sqrt(2 ln 2), never below
    1): a receiver that states its sigma too small does not lose its clean fixes.
    ``k`` <= 0: none."""
    far = np.zeros(len(fixes), bool)
    i = np.flatnonzero(fixes)
    if not k > 0.0 or not len(i):
        return far
    res = np.hypot(epochs.gnss_e[i] - track.e[i], epochs.gnss_n[i] - track.n[i])
    sd = np.sqrt(0.5 * (epochs.gnss_sd_e[i] ** 2 + epochs.gnss_sd_n[i] ** 2))
    scale = _sigma_scale(res, sd)
    if math.isfinite(scale):
        with np.errstate(invalid="ignore"):
            far[i] = res > k * scale * sd
    return far


def _sigma_scale(res: np.ndarray, sd: np.ndarray) -> float:
    """How far the fixes' residuals ``res`` (m, horizontal) run beyond their sigmas ``sd``
    (m, per axis): their median ratio over the Rayleigh median sqrt(2 ln 2), never below 1;
    NaN without a finite ratio."""
    with np.errstate(invalid="ignore", divide="ignore"):
        z = res / sd
    ok = np.isfinite(z)
    if not ok.any():
        return math.nan
    return max(1.0, float(np.median(z[ok])) / RAYLEIGH_MEDIAN)


def edge_fixes(epochs: Epochs, track: FilterResult, kept: np.ndarray, out: np.ndarray,
               k: float, edge_s: float, far_m: float) -> np.ndarray:
    """Of the ``kept`` fixes (a mask over the epochs), those next to a run of left-out ones
    (``out``) whose offset from ``track`` (fix minus track, m) points the way the run's
    median offset does by more than ``k`` of their sigmas (scaled as :func:`far_fixes`
    scales them): the ramp of a reflection that the receiver's own filter blends in and
    out over a second or more, too small yet to be far (:func:`far_fixes`).  Only runs of
    two or more fixes whose median offset is beyond ``far_m`` (m): next to a run left out
    for the track's own error, the neighbours point the same way because that error is
    smooth in time, not because they are reflected.  At most (L - 1) / 2 of the L kept
    fixes between two left-out runs (or a run and the drive's end) go from each side: a
    lone clean fix after a reflection is what holds the track there.  Walked outwards from
    each run, fix by fix, within ``edge_s`` seconds of it, and stopped at the first fix
    that does not point that way.  ``k`` <= 0 or ``edge_s`` <= 0: none."""
    drop = np.zeros(len(kept), bool)
    f = np.flatnonzero(kept | out)
    if not (k > 0.0 and edge_s > 0.0) or not out.any() or not kept.any():
        return drop
    t_s = (np.asarray(epochs.t_ns, np.int64)[f] - int(epochs.t_ns[0])) / NS_PER_S
    de = epochs.gnss_e[f] - track.e[f]
    dn = epochs.gnss_n[f] - track.n[f]
    sd = np.sqrt(0.5 * (epochs.gnss_sd_e[f] ** 2 + epochs.gnss_sd_n[f] ** 2))
    is_out = out[f]
    ok = kept[f] & np.isfinite(de) & np.isfinite(dn) & np.isfinite(sd) & (sd > 0)
    scale = _sigma_scale(np.hypot(de[ok], dn[ok]), sd[ok])
    if not math.isfinite(scale):
        return drop
    sd = sd * scale
    for a, b in zip(*true_runs(is_out), strict=True):
        ue, un = float(np.nanmedian(de[a:b + 1])), float(np.nanmedian(dn[a:b + 1]))
        size = math.hypot(ue, un)
        if b == a or not size > far_m:
            continue
        ue, un = ue / size, un / size
        for j, stop, t_edge in ((a - 1, -1, t_s[a]), (b + 1, len(f), t_s[b])):
            step = -1 if stop < 0 else 1
            stretch = 0  # the kept fixes between this run and the next left-out one
            while j + step * stretch != stop and not is_out[j + step * stretch]:
                stretch += 1
            room = (stretch - 1) // 2
            while room > 0 and ok[j] and abs(t_s[j] - t_edge) <= edge_s:
                room -= 1
                if not de[j] * ue + dn[j] * un > k * sd[j]:
                    break
                drop[f[j]] = True
                j += step
    return drop


__all__ = ["edge_fixes", "far_fixes", "farthest_window", "judge_kept", "last_run_drift",
           "not_applied", "screen"]
