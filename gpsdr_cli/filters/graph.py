"""Robust batch smoother: the whole drive solved at once (maximum a posteriori), with a
robust kernel on the GNSS factors so that the dead reckoning outvotes a run of consistent
but wrong (non-line-of-sight) fixes.  ``[filter] smoother = "graph"``, ``--smooth graph``.

Model (units SI, local ENU frame, heading psi clockwise from north, yaw rate CCW-positive:
``d(psi)/dt = -(yaw_rate - b)``):

* States at keyframes (every fix epoch, and at least every ``[graph] keyframe_s`` between):
  e, n (m), psi (rad), speed v (m/s), gyro bias b (rad/s), gyro scale correction g
  (``d(psi)/dt = -((1 + g) yaw_rate - b)``), odometer scale s, GNSS error eps_e, eps_n
  (m), and in the NLOS segment fit's last solve a course bias per segment (rad; pinned at
  zero elsewhere); b, g and s are random walks from keyframe to keyframe (``[gyro]
  bias_sd_radps`` over its correlation time, ``[graph] gyro_scale_rw_sd``, ``[odo]
  scale_rw_sd``), so every factor links neighbours only.  g starts at 0 within ``[graph]
  gyro_scale_prior_sd`` (or, the readings multiplied by a known scale ``--gyro-scale``,
  within ``gyro_scale_cal_sd``): a gyro that reads 3 % too much turn put every turn's
  heading 2.7 deg off, which the per-radian heading noise below let the fixes bend back
  only where they were clean.
* Dead reckoning between keyframes: preintegrated from the raw epochs once per interval
  (exact in psi and s; in b through moments of the gyro time, in g to first order through
  moments of the raw heading, taken again when b or g moves far:
  :func:`.graph_kernels._preintegrate`; Jacobians alongside), with the
  covariance of the displacement from the sensors' declared noise (``[gyro]``, ``[odo]``;
  the gyro's scale error is ``[graph] gyro_scale_sd`` per radian turned, or the filters'
  ``[gyro] scale_sd`` on an NLOS drive: docs/decisions/0056)
  plus a per-metre random walk ``[graph] dr_dist_sd``.  Without an odometer the speed
  state carries the position: driven by the forward accelerometer where there is one
  (``dv = (a - s) dt``, the S slot then holding the reading's offset, bias + g sin(pitch),
  m/s^2, a random walk in time and in the distance driven, ``[accel]``), else a random
  walk in acceleration; without a gyro the heading walks freely.  The speed state is tied
  to s x odometer speed where there is one.
* GNSS: position factors with the receiver's sigma after the filters' GNSS quality model
  (:func:`.gnss_model.gnss_error_model`: NLOS-suspect fixes' sigmas scaled) and,
  with the error states, times the PDOP regime's factor; speed and course factors (the
  receiver's Doppler velocity); both under a robust kernel.  A fix is position + GNSS
  error + white noise: the GNSS error is a first-order Gauss-Markov state per axis
  (multipath, two more unknowns per keyframe), with fkf's two sky regimes
  (:func:`.fkf.multipath_regime`): clear sky decorrelates in time, obstructed
  sky with the distance driven as well.
  Drives where the quality model marks NLOS fixes (``[graph] nlos_share``) and RTK
  drives keep white fixes instead, their variance inflated by the number of fixes per
  decorrelation span, under a tighter kernel.
* Each step between two epochs is integrated with the gyro's rate and the odometer's
  speed at the step's middle, linear between readings: held from the step's start, a
  5 Hz CAN gyro turned the track half a reading late (docs/benchmarks.md, "Dead
  reckoning at CAN rate").
* The odometer's speed is read ``[graph] odo_lag_s`` later than its stamp (a speed from
  ticks over a window describes the window's middle); by default that lag is fitted to
  the receiver's speed (:func:`odo_lag_s`), and never negative.
* Standstill (odometer below ``[standstill] speed_mps`` over a whole interval): no heading
  change (the gyro's reading is then its bias).  Priors: keyframe 0 loosely at the forward
  filter's smoothed solution (also the initial guess of every keyframe), b and s at the
  user's calibration (``--gyro-bias``, ``--odo-scale``) or loosely at 0 and 1.

Engine: Levenberg-Marquardt over iteratively reweighted least squares on the banded normal
equations (11 sub-diagonals), solved by a banded Cholesky factorisation compiled with the
factors (:func:`.graph_kernels.band_cholesky`; LAPACK's ``dpbsv`` took twice as long on a
band this narrow): O(keyframes) per iteration; an accepted step is doubled
while the robust cost keeps falling (:data:`EXTRAPOLATE_MAX`), which halves the iterations
where reweighting lets a reflected run go slowly.  Chosen over GTSAM (its
Python-side custom factors cost milliseconds each, and a pose chain with a per-sample
between-factor needs 360 k of them an hour) and over ``scipy.optimize.least_squares``
(its robust losses re-scale the whole Jacobian and its sparse trust-region solver is an
iterative LSQR, far slower than a direct banded solve on this structure).  The kernel is
graduated (graduated non-convexity, Yang et al. 2020): the Cauchy scale starts at
2^(``gnc_stages`` - 1) x ``kernel_scale`` and halves stage by stage to ``kernel_scale``,
so the start -- the forward filter's track, already pulled towards the biased fixes --
does not lock the solution into accepting them (on an NLOS drive without an odometer over
``nlos_no_odo_gnc_stages`` only).  On an NLOS drive with a gyro and an odometer a last
stage follows under the bounded Geman-McClure kernel (``[graph] nlos_last_kernel``), as
GNC's own last stage would be: Cauchy's cost keeps growing with the residual, so a long
reflected run still pulls.  A stage before the last only leads into the next, and ends at
the looser ``gnc_stage_tolerance``; the last converges to ``tolerance``.
Kernel and scale by benchmark: docs/decisions/0002-graph-smoother.md and 0035.

Marginal sigmas: the entries of H^-1 inside the band by the Takahashi recursion on the
banded Cholesky factor (:func:`.graph_kernels.banded_inverse_band`), interpolated linearly
between keyframes.  A solve that does not converge (or goes non-finite) returns None and
the caller keeps the RTS track with a warning.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.linalg import LinAlgError

from ..angles import unwrap_across_gaps
from ..config import Params
from ..conventions import NS_PER_S
from ..epochs import Epochs
from .base import FilterResult
from .calibration import known_gyro_scale
from .gnss_model import rtk_drive

KERNELS = {"gauss": 0, "huber": 1, "cauchy": 2, "geman": 3}
#: an accepted step is doubled up to this factor while the cost keeps falling (8: the same
#: minima as plain steps on 80 simulated city drives at half the iterations; 64 jumped one
#: drive into another basin, decisions/0034)
EXTRAPOLATE_MAX = 8.0


@dataclass
class GraphOutcome:
    """The smoothed result (None when the solve failed) and what happened."""

    result: FilterResult | None
    converged: bool
    iterations: int
    message: str
    #: per epoch: robust weight of the fix (NaN where none)
    gnss_weight: np.ndarray = field(default_factory=lambda: np.zeros(0))
    odo_scale: float = math.nan
    odo_scale_sd: float = math.nan
    gyro_bias_radps: float = math.nan
    gyro_bias_sd_radps: float = math.nan
    #: the gyro's scale correction: true rate = (1 + this) x reading - bias
    gyro_scale: float = math.nan


def kernel_id(params: Params, key: str) -> int:
    """The kernel ``[graph] key`` names, or a usage error that lists the choices."""
    from ..errors import UsageError

    name = str(params["graph"][key])
    if name not in KERNELS:
        raise UsageError(f"[graph] {key} = {name!r}: expected one of {', '.join(KERNELS)}")
    return KERNELS[name]


def parse_prior(text: str, default_sd: float, what: str) -> tuple[float, float]:
    """``"1.02"`` or ``"1.02+-0.005"`` -> (value, sd); the sd defaults to ``default_sd``."""
    from ..errors import UsageError

    s = text.strip().replace("±", "+-")
    val, sep, sd = s.partition("+-")
    try:
        v = float(val)
        d = float(sd) if sep else float(default_sd)
    except ValueError as err:
        raise UsageError(f"{what} {text!r}: expected VALUE or VALUE+-SD, e.g. 1.02+-0.005") from err
    if not (math.isfinite(v) and math.isfinite(d) and d > 0):
        raise UsageError(f"{what} {text!r}: expected a finite value and a positive SD")
    return v, d


def _ffill_ok(t_s: np.ndarray, has: np.ndarray, val: np.ndarray, max_age_s: float,
              bad: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The latest good reading at every epoch and whether it is at most ``max_age_s`` old."""
    good = has & np.isfinite(val)
    if bad is not None:
        good &= ~bad
    n = len(t_s)
    if not good.any():
        return np.zeros(n), np.zeros(n, bool)
    idx = np.where(good, np.arange(n), -1)
    last = np.maximum.accumulate(idx)
    ok = last >= 0
    out = np.where(ok, val[np.maximum(last, 0)], 0.0)
    age = np.where(ok, t_s - t_s[np.maximum(last, 0)], np.inf)
    return np.nan_to_num(out), ok & (age <= max_age_s)


def odo_lag_s(t_s: np.ndarray, odo_good: np.ndarray, odo: np.ndarray, has_fix: np.ndarray,
              gnss_speed: np.ndarray, max_lag_s: float, step_s: float = 0.005) -> float:
    """How long (s) the odometer's speed lags the receiver's Doppler speed: the shift that
    best fits one to the other (least squares, one scale fitted, both above 1 m/s), on a
    ``step_s`` grid within 0..``max_lag_s``; 0 without enough of both.

    Never negative: an odometer's speed describes the past (a tick count over a window
    describes the window's middle), never a time after its stamp.  A fit that says
    otherwise says that the receiver's Doppler speed is late against its own positions,
    as u-blox's velocity is (comma2k19: 0.06-0.085 s), and reading the odometer that much
    earlier shifts the whole track back in time (docs/decisions/0020)."""
    f = has_fix & np.isfinite(gnss_speed)
    if odo_good.sum() < 10 or f.sum() < 10 or not max_lag_s > 0:
        return 0.0
    to, vo = t_s[odo_good], odo[odo_good]
    tf, vf = t_s[f], gnss_speed[f]
    inside = (tf >= to[0] + max_lag_s) & (tf <= to[-1] - max_lag_s)
    # ... and not across a pause in the odometer's good samples: a 36-s stretch the health
    # check left out, read as a line between its ends, fitted a lag of 0.275 s for 0.05 s
    from .gnss_model import ODO_GAP_S, between_close_records

    for shift in (0.0, max_lag_s):
        inside &= between_close_records(to, tf + shift, ODO_GAP_S)
    tf, vf = tf[inside], vf[inside]
    best, best_lag = math.inf, 0.0
    for lag in np.arange(0.0, max_lag_s + 0.5 * step_s, step_s):
        vi = np.interp(tf + lag, to, vo)
        m = (vf > 1.0) & (vi > 1.0)
        if m.sum() < 10:
            return 0.0
        s = float(np.dot(vf[m], vi[m]) / np.dot(vi[m], vi[m]))
        cost = float(np.mean((vf[m] - s * vi[m]) ** 2))
        if cost < best:
            best, best_lag = cost, float(lag)
    return best_lag


#: sd of a GNSS error state where a segment of fixes starts (m): free
SEGMENT_FREE_SD_M = 1e3
#: ... and of a segment's course bias there (rad): free
SEGMENT_FREE_SD_RAD = 10.0
#: the kept-fix solve's distance from the segment fit: the largest median over windows this
#: long (s), as the NLOS screen measures a track's distance from the fixes
KEPT_APART_WINDOW_S = 30.0


def _segment_states(seg: np.ndarray, run: np.ndarray, fix: np.ndarray, tk_s: np.ndarray,
                    gp: Params, trust: np.ndarray | None = None,
                    course_drift: float | None = None):
    """Per keyframe: segment id (keyframes between two fixes of one segment belong to it,
    others -1), the error states' chain (phi, sd of w per interval: held in a segment,
    free at its start, pinned at zero outside), and each segment's zero prior (sd, vote)
    at its middle fix: its run's vote shared among the run's segments by length, each share
    times the segment's ``trust`` (per keyframe: :func:`.nlos_segments.segment_trust`) where
    given; then the course bias's chain (phi, sd of w), held in a segment as the error
    states are with a walk of ``course_drift`` rad per sqrt(s), or pinned at zero
    throughout when None."""
    n = len(seg)
    seg_k = np.where(fix, seg, -1)
    fix_i = np.flatnonzero(fix & (seg >= 0))
    if len(fix_i):
        # each keyframe's last fix at or before it and first fix at or after it
        pos = np.arange(n)
        prev = np.maximum.accumulate(np.where(seg_k >= 0, pos, -1))
        nxt = np.minimum.accumulate(np.where(seg_k >= 0, pos, n)[::-1])[::-1]
        inside = (prev >= 0) & (nxt < n)
        both = np.where(inside, seg_k[np.clip(prev, 0, n - 1)], -1)
        seg_k = np.where(inside & (both == seg_k[np.clip(nxt, 0, n - 1)]), both, -1)
    same = (seg_k[:-1] == seg_k[1:]) & (seg_k[1:] >= 0)
    start = (seg_k[1:] >= 0) & ~same
    dt = np.maximum(np.diff(tk_s), 0.0)
    phi = np.where(same, 1.0, 0.0)
    wsd = np.where(same, np.maximum(float(gp["nlos_segment_drift_sd"]) * np.sqrt(dt), 1e-4),
                   np.where(start, SEGMENT_FREE_SD_M, 1e-5))
    crs_phi, crs_wsd = np.zeros(max(n - 1, 1)), np.full(max(n - 1, 1), 1e-5)
    if course_drift is not None and n > 1:
        crs_phi = phi.copy()
        crs_wsd = np.where(same, np.maximum(course_drift * np.sqrt(dt), 1e-6),
                           np.where(start, SEGMENT_FREE_SD_RAD, 1e-5))
    if n < 2:
        phi, wsd = np.ones(1), np.ones(1)
    seg_sd = np.full(n, np.nan)
    vote = np.zeros(n)
    if len(fix_i):
        step = float(np.median(np.diff(tk_s[fix_i]))) if len(fix_i) > 1 else 0.0
        vote_s = max(float(gp["nlos_segment_vote_s"]), 1e-3)
        for run_i in np.split(fix_i, np.flatnonzero(np.diff(run[fix_i])) + 1):
            run_dur = tk_s[run_i[-1]] - tk_s[run_i[0]] + step
            for grp in np.split(run_i, np.flatnonzero(np.diff(seg_k[run_i])) + 1):
                mid = grp[len(grp) // 2]
                seg_sd[mid] = max(float(gp["nlos_segment_sd_m"]), 1e-3)
                dur = tk_s[grp[-1]] - tk_s[grp[0]] + step
                vote[mid] = math.sqrt(run_dur / vote_s) * dur / max(run_dur, 1e-9)
                if trust is not None:
                    vote[mid] *= float(trust[mid])
    return seg_k, phi, wsd, seg_sd, vote, crs_phi, crs_wsd


def _segment_weights(x: np.ndarray, seg_k: np.ndarray, fe: np.ndarray, fn: np.ndarray,
                     sd_m: float, kernel: int, c: float) -> np.ndarray:
    """Each fix keyframe's weight: the robust weight of its segment's median offset from
    the track (in ``sd_m``), NaN without a fix.  From the offsets, not the error states:
    a short segment's error state sits near its zero prior whatever its fixes say."""
    from . import graph_kernels as gk
    from .nlos_segments import segment_offsets

    out = np.full(len(seg_k), np.nan)
    fix = np.flatnonzero(np.isfinite(fe) & (seg_k >= 0))
    off = segment_offsets(seg_k[fix], fe[fix] - x[gk.N_X * fix + gk.E],
                          fn[fix] - x[gk.N_X * fix + gk.N])
    out[fix] = gk.robust_weights(off * off / (sd_m * sd_m), kernel, c)
    return out


def keyframes(t_s: np.ndarray, has_fix: np.ndarray, step_s: float) -> np.ndarray:
    """Epoch indices of the keyframes: every fix, the first and the last epoch, and enough
    epochs between so that no two keyframes are more than ``step_s`` apart where epochs allow."""
    from .graph_kernels import keyframe_epochs

    if len(t_s) == 0:
        return np.zeros(0, np.int64)
    mark = np.asarray(has_fix, bool).copy()
    mark[0] = mark[-1] = True
    return keyframe_epochs(np.asarray(t_s, float), mark, float(step_s))


def _initial_heading(t_s: np.ndarray, yaw: np.ndarray, gyro_ok: np.ndarray,
                     ve: np.ndarray, vn: np.ndarray) -> np.ndarray:
    """Heading at every epoch: the gyro's integrated heading turned onto the forward track's
    course where that moves at >= 2 m/s (the offset interpolated in time between); on a
    drive never that fast (a walking-speed robot), where it moves at >= 0.5 m/s.  Without a
    gyro the heading is that course itself, held across the stops: at a constant north,
    every stretch driven south started with its speed the wrong way round."""
    dt = np.diff(t_s, prepend=t_s[0])
    rate = np.where(np.roll(gyro_ok, 1), -np.roll(yaw, 1), 0.0)
    rate[0] = 0.0
    psi_g = np.cumsum(rate * dt)
    course = np.arctan2(ve, vn)
    speed = np.hypot(ve, vn)
    fast = speed >= 2.0
    if not fast.any():
        fast = speed >= 0.5
    if not fast.any():
        return psi_g
    off = unwrap_across_gaps(t_s[fast], course[fast] - psi_g[fast])
    return psi_g + np.interp(t_s, t_s[fast], off)


def smooth_graph(epochs: Epochs, init: FilterResult, params: Params,
                 segments: np.ndarray | None = None, *, sigmas: bool = True) -> GraphOutcome:
    """Solve the drive as one robust least-squares problem, started from ``init`` (the
    forward filter's RTS result on the same epochs).

    ``segments`` (rows: per epoch, the fix's segment id and run id from
    :func:`.nlos_segments.fix_segments`, -1: none): each segment's fixes share one GNSS
    error (a reflected-signal bias, constant but for ``[graph] nlos_segment_drift_sd``,
    free at the segment's start), the fixes are Gaussian about it, and each run (its
    segments sharing it by length) has one robust vote that its error is zero (sigma
    ``nlos_segment_sd_m`` under the bounded ``nlos_segment_kernel`` at ``nlos_segment_c``
    sigmas, so that many far segments cannot add up to a pull; the vote
    sqrt(length / ``nlos_segment_vote_s``): a run's fixes are correlated, a longer run
    is more, not proportionally more, evidence).  The fixes' weights returned are their
    segment's.

    Started from a filter whose NLOS screen applied (:mod:`.nlos_screen`) and without
    ``segments``, the drive is solved as the screen judges it: segments cut where the
    fixes jump off ``init``'s track and solved as above, each fix at its own sigma (the
    segment's bias replaces the quality model's scaled sigmas); then the segments within
    ``[graph] nlos_segment_keep_m`` of that solution are solved again fix by fix (white
    fixes, robust kernel, ``nlos_kept_gnc_stages`` graduated stages: the start is that
    solution), the others left out.  A segment's single vote decides which
    fixes are clean; the clean fixes then weigh one by one, as in the filters.

    ``sigmas`` False: the track's variances (and the calibration's sds) are left NaN, for a
    caller that only weighs the fixes against the track (:mod:`.nlos_screen`): the band of
    H^-1 costs a factorisation and a recursion over the whole drive."""
    if init.info.get("gyro_steady"):  # the gyro model the filter took (gyro_stops)
        from ..gyro_stops import steady_walk

        params = steady_walk(params)
    doppler = None
    if "nlos_screened" in init.info and epochs.has_odo.any():
        from .gnss_model import doppler_misfit

        doppler = doppler_misfit(epochs, float(params["gnss"]["nlos_velocity_min_mps"]))
    if init.info.get("nlos_doppler_dropped"):  # the receiver velocities the filter left out
        from .gnss_model import drop_reflected_doppler

        epochs, _ = drop_reflected_doppler(epochs, params, doppler)
    if (segments is None and len(epochs) and "nlos_screened" in init.info
            and bool(params["graph"]["nlos_segments"])):
        return _by_segments(epochs, init, params, doppler)
    return _solve(epochs, init, params, segments, sigmas)


def solve_by_segments(epochs: Epochs, init: FilterResult, params: Params, *,
                      sigmas: bool = True, doppler: np.ndarray | None = None,
                      basin_only: bool = False
                      ) -> tuple[GraphOutcome, np.ndarray, np.ndarray]:
    """The NLOS judgement the screen and the graph smoother share: the fixes cut into
    segments and runs against ``init``'s track (:mod:`.nlos_segments`), the drive solved
    with one bias per segment and one vote per run, each fix at its own sigma (the
    segment's bias replaces the quality model's scaled sigmas), then again from that solution
    with a course bias per segment too (``[graph] nlos_segment_course_sd_rad``; 0: not).
    Returns the outcome, the segments (:func:`.nlos_segments.fix_segments`) and, per epoch,
    whether its fix's segment lies within ``[graph] nlos_segment_keep_m`` of the solution
    (all False if it failed).
    ``sigmas``: as :func:`smooth_graph`'s.  ``doppler``: per epoch, the receiver's Doppler
    speed minus the odometer's (m/s, :func:`.gnss_model.doppler_misfit`): each segment's vote
    times its agreement (:func:`.nlos_segments.segment_trust`, ``[gnss] nlos_doppler_trust_mps``).
    ``basin_only``: the last solve ends at ``[graph] gnc_stage_tolerance``, for a caller that
    only starts another solve from it (without ``sigmas`` it always does)."""
    from .nlos_segments import fix_segments, segments_near

    own = own_sigmas(params)
    seg = fix_segments(epochs, init, params["graph"])
    course = float(params["graph"]["nlos_segment_course_sd_rad"]) > 0.0
    out = _solve(epochs, init, own, seg, sigmas, doppler, basin_only=course)
    if out.result is not None and course:
        # ... then again from there with a course bias per segment: a reflected Doppler's
        # course is off for as long as its position is, and a minute of them turned the
        # heading onto a reflected plateau (decisions/0079).  From the solution anchored by
        # every course, not from the start: with the courses free from the first step the
        # fit stayed in a wrong basin it had left before (one drive 23 m, not 2.6 m).  The
        # screen (no sigmas) only weighs the fixes against the track: the basin will do
        freed = _solve(epochs, out.result, own, seg, sigmas, doppler, course_bias=True,
                       basin_only=not sigmas or basin_only)
        if freed.result is not None:
            out = freed
    if out.result is None:
        return out, seg, np.zeros(len(epochs), bool)
    return out, seg, segments_near(epochs, out.result, seg,
                                   float(params["graph"]["nlos_segment_keep_m"]))


def own_sigmas(params: Params) -> Params:
    """``params`` with each fix at its own sigma and white (no chord scaling, no error
    states) and the gyro's scale error at ``[gyro] scale_sd``: the NLOS fit's."""
    own = copy.deepcopy(params)
    own["gnss"]["nlos_mismatch_m"] = 0.0
    own["graph"]["gnss_err_states"] = False
    own["graph"]["gyro_scale_sd"] = math.nan    # the filters' tighter heading (see _solve)
    return own


def _by_segments(epochs: Epochs, init: FilterResult, params: Params,
                 doppler: np.ndarray | None = None) -> GraphOutcome:
    """:func:`smooth_graph` of a screened NLOS drive: segment votes (each segment's weighed by
    its ``doppler`` agreement, as :func:`solve_by_segments`), then the kept fixes."""
    # the segment fit only starts the solve of the kept fixes and says which are kept: it
    # ends in its basin, without the track's sigmas (an NLOS hour: 21 -> 11 iterations,
    # the graph on simulated drives as close to the truth; decisions/0082), and is finished
    # only where it is the answer
    by_seg, seg, near = solve_by_segments(epochs, init, params, doppler=doppler, sigmas=False,
                                          basin_only=True)
    if by_seg.result is None:
        return _solve(epochs, init, params, None)

    def finished() -> GraphOutcome:
        # solved again to the end from the same start: restarted from the basin instead,
        # the segments' biases started again from their medians and the fit went elsewhere
        done = solve_by_segments(epochs, init, params, doppler=doppler)[0]
        return done if done.result is not None else by_seg
    fix = np.asarray(epochs.has_gnss, bool)
    kept = replace(epochs, has_gnss=fix & near)
    own = own_sigmas(params)
    # started from the segment fit's solution, a wide first stage only walks back to it
    own["graph"]["gnc_stages"] = int(params["graph"]["nlos_kept_gnc_stages"])
    out = _solve(kept, by_seg.result, own, None)
    if out.result is None:
        return finished()
    # ... a refinement: the kept fixes lie within keep_m of the segment fit's track, so a
    # solution of them that leaves it by twice that has walked off where none is kept (174
    # fixes kept of 1400, the gyro scale run to -8 %, a track 97 m from the segment fit's
    # and 53 m from the truth against fixes at 29 m; decisions/0079)
    from .nlos_segments import largest_window_median

    apart = largest_window_median(
        (np.asarray(epochs.t_ns, np.int64) - int(epochs.t_ns[0])) / NS_PER_S,
        np.hypot(out.result.e - by_seg.result.e, out.result.n - by_seg.result.n),
        KEPT_APART_WINDOW_S)[0]
    if apart > 2.0 * float(params["graph"]["nlos_segment_keep_m"]):
        by_seg = finished()
        by_seg.result.info["graph_kept_solve"] = (
            f"not taken: {apart:.0f} m from the segment fit's track")
        return by_seg
    # the left-out fixes: their segment's weight, rejected
    gone = fix & ~near
    out.gnss_weight = np.where(gone, by_seg.gnss_weight, out.gnss_weight)
    res = out.result
    res.extras["gnss_weight"] = out.gnss_weight
    res.gnss_rejected = res.gnss_rejected | gone
    res.gnss_used = res.gnss_used & ~gone
    res.nis = np.where(gone, by_seg.result.nis, res.nis)
    res.info["gnss_rejected"] = int(res.gnss_rejected.sum())
    res.info["graph_fixes_downweighted"] = int(np.count_nonzero(
        fix & (np.nan_to_num(out.gnss_weight, nan=1.0) < 0.5)))
    res.info["graph_nlos_segments"] = int(seg[0].max() + 1) if seg.size else 0
    res.info["graph_nlos_left_out"] = int(gone.sum())
    res.info["graph_iterations"] = int(res.info.get("graph_iterations", 0)) + by_seg.iterations
    out.iterations += by_seg.iterations
    return out


def _banded_solve(ab: np.ndarray, rhs: np.ndarray, lam: float, work: np.ndarray) -> np.ndarray:
    """(H + lam diag(H))^-1 rhs for the banded H in ``ab`` (lower form, :mod:`.graph_kernels`),
    factored in ``work``: ``ab`` stays as it is for a retry at another damping."""
    from . import graph_kernels as gk

    info = gk.band_cholesky_damped(ab, lam, work)
    if info:
        raise LinAlgError(f"{info}-th leading minor not positive definite")
    return gk.band_solve(work, rhs)


def _marginals(ab: np.ndarray, n_x: int) -> tuple[np.ndarray, ...]:
    """Per keyframe, from H's lower band ``ab`` (factored in place): var(e), var(n), cov(e, n)
    (m^2), var(s), var(b) and var(g), read from the band of H^-1."""
    from . import graph_kernels as gk

    info = gk.band_cholesky_damped(ab, 0.0, ab)  # the solve's 1e-12 on the diagonal
    if info:
        raise LinAlgError(f"{info}-th leading minor not positive definite")
    sb = gk.banded_inverse_band(gk.upper_of_lower(ab), n_x)
    return (sb[gk.BAND, gk.E::gk.N_X].copy(), sb[gk.BAND, gk.N::gk.N_X].copy(),
            sb[gk.BAND + gk.E - gk.N, gk.N::gk.N_X].copy(),   # H^-1[E_i, N_i]
            sb[gk.BAND, gk.S::gk.N_X].copy(), sb[gk.BAND, gk.B::gk.N_X].copy(),
            sb[gk.BAND, gk.G::gk.N_X].copy())


#: the last :func:`_dr_inputs`: (its inputs, its outputs).  The five solves of an NLOS drive
#: (the screen's three, the smoother's two) share the dead reckoning, and all but the last
#: the fixes: the odometer lag fit alone took 0.05 s a solve an hour
_DR_LAST: list[tuple[tuple, tuple]] = []


def _dr_inputs(epochs: Epochs, params: Params) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                          np.ndarray, np.ndarray, float]:
    """``(t_s, yaw, gyro_ok, odo, odo_ok, lag)``: seconds from the first epoch; per epoch step
    the gyro's rate (rad/s) and the odometer's speed (m/s) at the step's middle, linear
    between good readings, and whether each is fresh (``[graph] sensor_max_age_s``); the
    odometer's lag (s, :func:`odo_lag_s` unless ``[graph] odo_lag_s`` is given).  The last
    answer is kept and given again for the same arrays and parameters."""
    gp = params["graph"]
    key = (np.asarray(epochs.t_ns), np.asarray(epochs.has_gyro), np.asarray(epochs.yaw_rate_radps),
           np.asarray(epochs.has_odo), np.asarray(epochs.odo_speed_mps),
           np.asarray(epochs.has_gnss), np.asarray(epochs.gnss_speed_mps),
           repr([float(params["gyro"]["max_rate_radps"]),
                 int(params["gyro"]["saturation_min_count"]),
                 float(params["odo"]["max_speed_mps"])]
                + [float(gp[k]) for k in ("sensor_max_age_s", "odo_lag_s", "odo_lag_max_s")]))
    if _DR_LAST and all(
            x == y if isinstance(x, str) else x is y or x.shape == y.shape and np.array_equal(
                x, y, equal_nan=x.dtype.kind == "f")
            for x, y in zip(_DR_LAST[0][0], key, strict=True)):
        return _DR_LAST[0][1]
    t_s = (np.asarray(epochs.t_ns, np.int64) - int(epochs.t_ns[0])) / NS_PER_S
    max_rate = float(params["gyro"]["max_rate_radps"])
    max_spd = float(params["odo"]["max_speed_mps"])
    yaw_raw = np.asarray(epochs.yaw_rate_radps, float)
    odo_raw = np.asarray(epochs.odo_speed_mps, float)
    yaw_bad = ~(np.abs(np.nan_to_num(yaw_raw)) <= max_rate)
    # a clipping gyro: many readings exactly at the drive's largest magnitude are not rates
    mag = np.abs(np.where(np.isfinite(yaw_raw) & ~yaw_bad, yaw_raw, 0.0))
    if len(mag) and mag.max() > 0:
        at_max = mag >= mag.max()
        if at_max.sum() >= int(params["gyro"]["saturation_min_count"]):
            yaw_bad |= at_max
        del at_max
    del mag
    yaw, gyro_ok = _ffill_ok(t_s, np.asarray(epochs.has_gyro, bool), yaw_raw,
                             float(gp["sensor_max_age_s"]), bad=yaw_bad)
    odo_bad = ~((np.nan_to_num(odo_raw, nan=-1.0) >= 0) & (odo_raw <= max_spd))
    odo, odo_ok = _ffill_ok(t_s, np.asarray(epochs.has_odo, bool), odo_raw,
                            float(gp["sensor_max_age_s"]), bad=odo_bad)
    # the step from epoch k to k+1 is integrated with one rate and one speed: those at its
    # middle, linear between readings (held from the step's start, a 5 Hz gyro turns
    # the track half a reading late and every turn leaves a cross-track error)
    mid = t_s.copy()
    mid[:-1] = 0.5 * (t_s[:-1] + t_s[1:])
    yaw_good = np.asarray(epochs.has_gyro, bool) & np.isfinite(yaw_raw) & ~yaw_bad
    if yaw_good.sum() > 1:
        yaw = np.where(gyro_ok, np.interp(mid, t_s[yaw_good], yaw_raw[yaw_good]), yaw)
    # a speed from wheel ticks over a window describes the window's middle: read it that
    # much later (linear between readings), else every speed change leaves a distance error
    odo_good = np.asarray(epochs.has_odo, bool) & ~odo_bad
    lag = float(gp["odo_lag_s"])
    if not math.isfinite(lag):
        lag = odo_lag_s(t_s, odo_good, odo_raw, np.asarray(epochs.has_gnss, bool),
                        np.asarray(epochs.gnss_speed_mps, float), float(gp["odo_lag_max_s"]))
    if odo_good.sum() > 1:
        odo = np.where(odo_ok, np.interp(mid + lag, t_s[odo_good], odo_raw[odo_good]), odo)
    out = (t_s, yaw, gyro_ok, odo, odo_ok, lag)
    # the epochs' arrays are never changed in place (a new drive, or a new mask, is a new
    # Epochs): kept by reference
    _DR_LAST[:] = [(key, out)]
    return out


def _solve(epochs: Epochs, init: FilterResult, params: Params,
           segments: np.ndarray | None, sigmas: bool = True,
           doppler: np.ndarray | None = None, *, course_bias: bool = False,
           basin_only: bool = False) -> GraphOutcome:
    """:func:`smooth_graph` proper.  ``course_bias`` (with ``segments``): each segment's
    receiver courses share one bias, voted zero with its position error
    (``[graph] nlos_segment_course_sd_rad``).  ``basin_only``: for a solve that only starts
    another, its last stage ends at ``[graph] gnc_stage_tolerance`` as the earlier ones do."""
    from . import graph_kernels as gk

    gp = params["graph"]
    n_ep = len(epochs)
    if n_ep == 0:
        return GraphOutcome(None, False, 0, "no epochs")
    t_s, yaw, gyro_ok, odo, odo_ok, lag = _dr_inputs(epochs, params)
    # the filters' GNSS quality model: NLOS-suspect fixes' sigmas scaled, the error
    # states' sigma for this drive (RTK, NLOS)
    from .gnss_model import gnss_error_model

    sd_before = np.asarray(epochs.gnss_sd_e, float)
    epochs, qparams = gnss_error_model(epochs, params)
    f_all = np.asarray(epochs.has_gnss, bool)
    nlos_share = float(np.mean(np.asarray(epochs.gnss_sd_e, float)[f_all]
                               > 1.0001 * sd_before[f_all])) if f_all.any() else 0.0
    has_fix = (np.asarray(epochs.has_gnss, bool) & np.isfinite(epochs.gnss_e)
               & np.isfinite(epochs.gnss_n))
    key_ep = keyframes(t_s, has_fix, float(gp["keyframe_s"]))
    n_key = len(key_ep)
    n_x = gk.N_X * n_key

    # An NLOS drive (by the quality model) keeps white fixes under the tight kernel: with
    # error states the NLOS steps trade between the error state and the track, and the
    # solve crawls (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#graph-smoother).
    # (a share of NLOS-marked fixes: a lower bar than the filters' NLOS drive, or the
    # filters' NLOS drive itself, which the vector chord may call with few fixes marked)
    nlos_drive = nlos_share >= float(gp["nlos_share"]) or epochs.nlos_drive
    # An RTK drive too: centimetre fixes against a 0.3-m error state did not converge.
    err_on = (bool(gp["gnss_err_states"]) and not nlos_drive and segments is None
              and not rtk_drive(epochs, params))

    # ---- fixes per keyframe
    sd_min = float(params["gnss"]["sigma_min_m"])
    fe = np.where(has_fix, epochs.gnss_e, np.nan)[key_ep]
    fn = np.where(has_fix, epochs.gnss_n, np.nan)[key_ep]
    sde = np.nan_to_num(np.asarray(epochs.gnss_sd_e, float)[key_ep],
                        nan=float(params["gnss"]["sigma_default_m"]))
    sdn = np.nan_to_num(np.asarray(epochs.gnss_sd_n, float)[key_ep],
                        nan=float(params["gnss"]["sigma_default_m"]))
    sde = np.maximum(sde, sd_min)
    sdn = np.maximum(sdn, sd_min)
    if err_on and bool(gp["pdop_factors"]):
        # the filters' PDOP regimes (Fang et al.'s R factor k: sigma x k at medium / poor PDOP)
        from .gnss_model import pdop_factors

        k_fix = pdop_factors(np.asarray(epochs.pdop, float)[key_ep], params["gnss"])[0]
        sde = sde * k_fix
        sdn = sdn * k_fix
    # Fixes' errors are correlated (multipath, NLOS): fixes within one decorrelation span
    # (1/span = 1/tau + speed/distance) count as one, their variance times their number --
    # with white fixes a 2-minute stop's 600 fixes outvoted the rest of the drive.
    tau = float(gp["gnss_corr_tau_s"]) if not err_on else 0.0
    if tau > 0 and has_fix.sum() > 1:
        tf = t_s[has_fix]
        rate = (len(tf) - 1) / max(tf[-1] - tf[0], 1e-9)
        spd_k = np.hypot(np.nan_to_num(init.v_e), np.nan_to_num(init.v_n))[key_ep]
        span = 1.0 / (1.0 / tau + spd_k / max(float(gp["gnss_corr_dist_m"]), 1e-9))
        infl = np.sqrt(np.maximum(1.0, rate * span))
        # carrier-phase fixes (centimetres) are white at the fix rate: no inflation
        infl = np.where(np.hypot(sde, sdn) / math.sqrt(2.0) < float(gp["gnss_corr_min_sd_m"]),
                        1.0, infl)
        sde = sde * infl
        sdn = sdn * infl
    gspd = np.asarray(epochs.gnss_speed_mps, float)[key_ep].copy()
    gcrs = np.asarray(epochs.gnss_course_rad, float)[key_ep].copy()
    use_vel = bool(gp["gnss_velocity"])
    gspd[~(has_fix[key_ep] & np.isfinite(gspd) & (gspd >= 0)) | (not use_vel)] = np.nan
    gcrs[~np.isfinite(gcrs)] = np.nan

    # ---- GNSS error states: first-order Gauss-Markov per axis, 1/tau = 1/tau_s + speed/dist
    # (the ekf/aekf model, its sigma from the quality model); off: pinned at zero
    tk_s = t_s[key_ep]
    # Two regimes, fkf's (:func:`.fkf.multipath_regime`): under obstruction the
    # error decorrelates with the distance driven, in clear sky with time only
    spd_all = np.hypot(np.nan_to_num(init.v_e), np.nan_to_num(init.v_n))
    cdist = np.concatenate(([0.0], np.cumsum(0.5 * (spd_all[1:] + spd_all[:-1]) * np.diff(t_s))))
    dt_k = np.diff(tk_s)
    dd_k = np.diff(cdist[key_ep])
    del spd_all, cdist
    if err_on:
        from .fkf_inputs import multipath_regime

        w_all = multipath_regime(epochs, params)[key_ep]
        err_sd = np.sqrt(w_all * float(gp["gnss_err_sd_m"]) ** 2
                         + (1.0 - w_all) * float(gp["gnss_err_clear_sd_m"]) ** 2)
        w_ob = w_all[:-1]
        dist_o = float(gp["gnss_err_dist_m"])
        dist_c = float(gp["gnss_err_clear_dist_m"])
        expo = (w_ob * (dt_k / float(gp["gnss_err_tau_s"])
                        + (dd_k / dist_o if dist_o > 0 else 0.0))
                + (1.0 - w_ob) * (dt_k / float(gp["gnss_err_clear_tau_s"])
                                  + (dd_k / dist_c if dist_c > 0 else 0.0)))
    else:  # each pinned at zero on its own (a tight chain would ruin the conditioning)
        err_sd = np.full(n_key, 1e-5)
        expo = np.full(len(dt_k), np.inf)
    err_sd = np.maximum(err_sd, 1e-5)
    err_phi = np.exp(-expo) if len(dt_k) else np.ones(1)
    # eps[i+1] = phi eps[i] + w: var(w) = sd[i+1]^2 - phi^2 sd[i]^2 keeps each keyframe's
    # variance at its regime's (floored at the stationary increment of the smaller sigma)
    if len(dt_k):
        v1 = err_sd[1:] ** 2 - err_phi ** 2 * err_sd[:-1] ** 2
        v0 = np.minimum(err_sd[1:], err_sd[:-1]) ** 2 * -np.expm1(-2.0 * expo)
        err_wsd = np.sqrt(np.maximum(np.maximum(v1, v0), 1e-12))
    else:
        err_wsd = np.ones(1)
    seg_sd = np.full(n_key, np.nan)
    seg_vote = np.zeros(n_key)
    seg_k = None
    # each receiver velocity's information, as a multiple of [graph] gnss_speed_sd_mps's
    gvel_w = np.ones(n_key)
    # ... and with ``course_bias``, each segment's course bias (rad): held in a segment as
    # its position error is, free at its start, pinned at zero elsewhere (and everywhere
    # without), voted zero with the position error
    crs_phi = np.zeros(max(n_key - 1, 1))
    crs_wsd = np.full(max(n_key - 1, 1), 1e-5)
    seg_crs_sd = 0.0
    if segments is not None:
        seg_rows = np.asarray(segments, np.int64)
        trust = None
        if doppler is not None:
            from .nlos_segments import segment_trust

            trust = segment_trust(np.where(has_fix[key_ep], seg_rows[0][key_ep], -1),
                                  np.asarray(doppler, float)[key_ep],
                                  float(params["gnss"]["nlos_doppler_trust_mps"]))
            # ... and its velocities too: a reflected Doppler's course is off as its speed
            # is, and a minute of them bent the heading towards a reflected plateau under
            # Cauchy's ever-growing cost (decisions/0078)
            gvel_w = np.maximum(trust, 1e-6)
        freed = course_bias and n_key > 1
        seg_k, err_phi, err_wsd, seg_sd, seg_vote, crs_phi, crs_wsd = _segment_states(
            seg_rows[0][key_ep], seg_rows[1][key_ep], has_fix[key_ep], tk_s, gp, trust,
            float(gp["nlos_segment_course_drift"]) if freed else None)
        if freed:
            seg_crs_sd = max(float(gp["nlos_segment_course_sd_rad"]), 1e-6)

    # ---- standstill intervals: the odometer below the threshold over the whole interval;
    # without an odometer the receiver's speed, as the filters take it
    # (:func:`.standstill.gnss_standstill`: epochs (t_k, t_k+1] of still fixes)
    stop_v = float(params["standstill"]["speed_mps"])
    stopped = np.zeros(max(n_key - 1, 0), bool)
    if bool(params["standstill"]["enabled"]) and n_key > 1:
        if odo_ok.any():
            still_ep = odo_ok & (odo < stop_v)
            cs = np.concatenate(([0], np.cumsum(~still_ep)))
            # epochs key_ep[i] .. key_ep[i+1] all still
            stopped = (cs[key_ep[1:] + 1] - cs[key_ep[:-1]]) == 0
            del cs, still_ep
        elif (epochs.velocity_share >= float(params["fkf"]["fix_course_velocity_share"])
              or not np.asarray(epochs.has_accel, bool).any()):
            # Without the receiver's speed the filters' stand-in from the fixes' positions
            # calls a car creeping at up to 1 m/s stopped: against an accelerometer that
            # measures the speed, a zero speed held there walks the track metres from
            # centimetre fixes after each stop, so with one it is left out
            from .standstill import standstill_from_gnss

            still_ep = standstill_from_gnss(epochs, t_s, qparams)
            cs = np.concatenate(([0], np.cumsum(~still_ep)))
            # epochs key_ep[i] + 1 .. key_ep[i+1] all still
            stopped = (cs[key_ep[1:] + 1] - cs[key_ep[:-1] + 1]) == 0
            del cs, still_ep

    # ---- parameters of the kernels
    gyro_dt = 0.01
    if epochs.has_gyro.sum() > 2:
        tg = t_s[np.asarray(epochs.has_gyro, bool)]
        gyro_dt = float(np.median(np.diff(tg))) or 0.01
    prm = np.zeros(gk.N_P)
    prm[gk.P_SD_ODO] = float(params["odo"]["noise_sd_mps"])
    prm[gk.P_Q_DIST] = float(gp["dr_dist_sd"])
    prm[gk.P_POS_FLOOR] = float(gp["dr_floor_m"])
    prm[gk.P_HEAD_RW] = float(gp["heading_rw_sd"])
    # the gyro's scale error: the graph's own, but on an NLOS drive the filters' tighter one
    # (a looser heading let a reflected run bend a simulated city drive: 1.60 -> 11.2 m)
    scale_sd = float(gp["gyro_scale_sd"])
    if nlos_drive or not math.isfinite(scale_sd):
        scale_sd = float(params["gyro"]["scale_sd"])
    prm[gk.P_GYRO_SCALE] = scale_sd
    prm[gk.P_NOGYRO_RW] = float(gp["no_gyro_heading_rw_sd"])
    prm[gk.P_ACC_SD] = float(gp["accel_sd"])
    tau_b = float(params["gyro"]["bias_tau_s"])
    prm[gk.P_BIAS_RW] = max(float(params["gyro"]["bias_sd_radps"]) * math.sqrt(2.0 / tau_b), 1e-9)
    prm[gk.P_SCALE_RW] = max(float(params["odo"]["scale_rw_sd"]), 1e-9)
    prm[gk.P_ZARU_SD] = float(gp["zaru_sd_rad"])
    prm[gk.P_VTIE_SD] = float(params["odo"]["noise_sd_mps"])
    prm[gk.P_GSPEED_SD] = float(gp["gnss_speed_sd_mps"])
    prm[gk.P_GCOURSE_MIN] = float(gp["gnss_course_min_mps"])
    prm[gk.P_MAX_STEP] = float(gp["max_step_s"])
    prm[gk.P_GYRO_SD] = float(params["gyro"]["noise_sd_radps"]) * math.sqrt(gyro_dt)
    prm[gk.P_STOP_SPEED] = stop_v
    prm[gk.P_ZUPT_SD] = float(params["standstill"]["zupt_sd_mps"])
    prm[gk.P_GSCALE_RW] = max(float(gp["gyro_scale_rw_sd"]), 1e-9)

    # ---- the speed state: a random walk, or on a drive without an odometer the forward
    # accelerometer's integral (its offset, bias + g sin(pitch), in the S slot the odometer
    # scale would use): through a GNSS outage nothing else measures how the car brakes
    have_gyro = bool(gyro_ok.any())
    have_odo = bool(odo_ok.any())
    n_int = max(n_key - 1, 1)
    dt_i = np.maximum(dt_k, 1e-6) if len(dt_k) else np.ones(1)
    acc_sd2 = float(gp["accel_sd"]) ** 2
    acc_dv = np.zeros(n_int)
    acc_t = np.zeros(n_int)
    v_psd = np.full(n_int, acc_sd2)
    s_rw = prm[gk.P_SCALE_RW] * np.sqrt(dt_i)
    acc_on = (not have_odo and bool(params["accel"]["enabled"]) and n_key > 1
              and bool(np.asarray(epochs.has_accel, bool).any()))
    b_acc0 = None
    if acc_on:
        from .accel_speed import accel_covered, speed_track

        pa = params["accel"]
        cov = accel_covered(epochs)
        a_raw = np.where(np.asarray(epochs.has_accel, bool), epochs.accel_mps2, np.nan)
        a_held, _ = _ffill_ok(t_s, np.isfinite(a_raw), a_raw, math.inf)
        dt_ep = np.diff(t_s)
        step_ok = (dt_ep > 0) & (dt_ep <= float(gp["max_step_s"])) & cov[:-1]
        c_dv = np.concatenate(([0.0], np.cumsum(np.where(step_ok, a_held[:-1] * dt_ep, 0.0))))
        c_t = np.concatenate(([0.0], np.cumsum(np.where(step_ok, dt_ep, 0.0))))
        acc_dv = np.diff(c_dv[key_ep])
        acc_t = np.diff(c_t[key_ep])
        # the reading's white noise where it covers the interval, the free walk elsewhere
        v_psd = (acc_sd2 * np.maximum(dt_i - acc_t, 0.0)
                 + float(pa["noise_psd_m2ps3"]) * acc_t) / dt_i
        # the offset: the sensor bias wanders in time, g sin(pitch) along the road
        s_rw = np.sqrt(float(pa["bias_rw_var_m2ps5"]) * dt_i
                       + float(pa["grade_rw_var_m2ps4_per_m"]) * np.abs(dd_k) + 1e-12)
        b_acc0 = np.nan_to_num(speed_track(epochs, params).b_mps2)[key_ep]
    if not have_odo and len(stopped):
        # stopped without an odometer: the speed state held at zero, nothing to integrate
        v_psd = np.where(stopped, 0.0, v_psd)
    v_sd = np.sqrt(np.maximum(v_psd * dt_i, 1e-12))

    # ---- priors and the initial guess
    b_mean = float(gp["gyro_bias_radps"])
    b_sd = float(gp["gyro_bias_sd_radps"])
    b_given = math.isfinite(b_mean)
    if not b_given:
        b_mean, b_sd = 0.0, float(params["gyro"]["bias_init_sd_radps"])
    s_mean = float(gp["odo_scale"])
    s_sd = float(gp["odo_scale_sd"])
    s_given = math.isfinite(s_mean)
    if not s_given:
        s_mean, s_sd = 1.0, float(params["odo"]["scale_init_sd"])
    # a known gyro scale (--gyro-scale) already multiplies the readings: g corrects what is left
    g_sd = max(float(gp["gyro_scale_cal_sd"] if known_gyro_scale(params) is not None
                     else gp["gyro_scale_prior_sd"]), 1e-6)
    if not have_gyro:
        b_mean, b_sd = 0.0, 1e-6
        g_sd = 1e-6
    if not have_odo:
        s_mean, s_sd = 1.0, 1e-6
    if acc_on:
        s_mean, s_sd = float(b_acc0[0]), float(params["accel"]["bias_init_sd_mps2"])
    e0 = np.nan_to_num(np.asarray(init.e, float))
    n0 = np.nan_to_num(np.asarray(init.n, float))
    ve0 = np.nan_to_num(np.asarray(init.v_e, float))
    vn0 = np.nan_to_num(np.asarray(init.v_n, float))
    psi0 = _initial_heading(t_s, yaw, gyro_ok, ve0, vn0)
    x = np.zeros(n_x)
    x[gk.E::gk.N_X] = e0[key_ep]
    x[gk.N::gk.N_X] = n0[key_ep]
    x[gk.PSI::gk.N_X] = psi0[key_ep]
    x[gk.V::gk.N_X] = np.hypot(ve0, vn0)[key_ep]
    # per-epoch copies freed before the solve (a 4-hour drive: 11.5 MB each)
    del e0, n0, ve0, vn0, psi0
    x[gk.B::gk.N_X] = b_mean
    x[gk.S::gk.N_X] = s_mean if b_acc0 is None else b_acc0
    if seg_k is not None:
        # started from a batch fit: its gyro bias and odometer scale too (at the priors'
        # means the first step's dead reckoning disagreed with the start track by metres)
        for slot, name in ((gk.B, "gyro_bias_radps"), (gk.S, "odo_scale"),
                           (gk.G, "gyro_scale")):
            val = np.asarray(init.extras.get(name, np.zeros(0)), float)
            if len(val) == n_ep and np.all(np.isfinite(val[key_ep])) and (
                    slot in (gk.B, gk.G) and have_gyro
                    or slot == gk.S and have_odo and not acc_on):
                x[slot::gk.N_X] = val[key_ep]
        # each segment's error starts at its fixes' median offset from the start track
        # (at zero, the first step pulled the track to the mean of every segment's fixes)
        from .nlos_segments import segment_medians

        me, mn = segment_medians(seg_k, fe - x[gk.E::gk.N_X], fn - x[gk.N::gk.N_X],
                                 np.isfinite(fe))
        ks = np.flatnonzero(np.isfinite(me))
        x[gk.N_X * ks + gk.GE] = me[ks]
        x[gk.N_X * ks + gk.GN] = mn[ks]
        del me, mn, ks
        if seg_crs_sd > 0.0:  # ... and its course bias at its courses' median offset
            crs_res = np.where(np.isfinite(gspd) & (gspd >= float(gp["gnss_course_min_mps"]))
                               & np.isfinite(gcrs),
                               (gcrs - x[gk.PSI::gk.N_X] + np.pi) % (2 * np.pi) - np.pi, np.nan)
            mc, _ = segment_medians(seg_k, crs_res, crs_res, np.isfinite(crs_res))
            kc = np.flatnonzero(np.isfinite(mc))
            x[gk.N_X * kc + gk.GC] = mc[kc]
            del crs_res, mc, kc
    prior_mean = x[:gk.N_X].copy()
    prior_mean[[gk.B, gk.S, gk.G, gk.GE, gk.GN, gk.GC]] = b_mean, s_mean, 0.0, 0.0, 0.0, 0.0
    prior_sd = np.zeros(gk.N_X)
    prior_sd[[gk.E, gk.N]] = float(gp["init_pos_sd_m"])
    prior_sd[gk.PSI] = float(gp["init_heading_sd_rad"])
    prior_sd[gk.V] = float(gp["init_speed_sd_mps"])
    prior_sd[[gk.B, gk.S, gk.GE, gk.GN]] = b_sd, s_sd, err_sd[0], err_sd[0]
    prior_sd[gk.G] = g_sd
    prior_sd[gk.GC] = SEGMENT_FREE_SD_RAD if seg_crs_sd > 0.0 and seg_k[0] >= 0 else 1e-5
    if seg_k is not None and seg_k[0] >= 0:
        prior_sd[[gk.GE, gk.GN]] = SEGMENT_FREE_SD_M

    kernel = kernel_id(params, "kernel")
    c_final = float(gp["kernel_scale_err_states"] if err_on else gp["kernel_scale"])
    n_stages = int(gp["gnc_stages"])
    if nlos_drive and not have_odo:
        # nothing holds the distance: a wide first stage let reflected steps bend the speed,
        # heading and gyro bias, and the narrower stages then kept the bend and rejected
        # the good fixes (a 600-s drive 63 m off against fixes at 35 m; decisions/0041)
        n_stages = int(gp["nlos_no_odo_gnc_stages"])
    if seg_k is not None:
        # started from a robust fit: a wide first stage averages the segments' biases
        n_stages = int(gp["nlos_segment_gnc_stages"])
    n_stages = max(n_stages, 1) if kernel != KERNELS["gauss"] else 1
    stages = [(kernel, c_final * 2.0 ** (n_stages - 1 - k)) for k in range(n_stages)]
    kernel_names = str(gp["kernel"])
    # An NLOS drive whose dead reckoning holds the shape on its own: a last stage under a
    # bounded kernel, where a reflected fix costs at most c^2 however far off it is; under
    # Cauchy a run of them 20-80 m off still pulled the track (decisions/0035)
    if (str(gp["nlos_last_kernel"]) and nlos_drive and not err_on and have_odo and have_gyro
            and seg_k is None):
        stages.append((kernel_id(params, "nlos_last_kernel"), c_final))
        kernel_names += "+" + str(gp["nlos_last_kernel"])
    ab = np.zeros((gk.BAND + 1, n_x), order="F")  # H's lower band, column by column
    g = np.zeros(n_x)
    q = np.zeros((max(n_key - 1, 1), gk.N_Q))
    pre = np.full((max(n_key - 1, 1), gk.N_PRE), np.nan)
    work = np.empty_like(ab, order="F")
    max_it = int(gp["max_iterations"])
    tol = float(gp["tolerance"])
    stage_tol = float(gp["gnc_stage_tolerance"])
    its = 0
    converged = False
    message = ""
    args_fix = (fe, fn, sde, sdn, gspd, gcrs, gvel_w, err_phi, err_wsd, crs_phi, crs_wsd,
                acc_dv, acc_t, v_sd, s_rw, prior_mean, prior_sd)

    seg_mult = float(gp["nlos_segment_c"]) / c_final
    seg_kern = kernel_id(params, "nlos_segment_kernel")

    def cost_at(xx: np.ndarray, kern: int, c: float, want: bool) -> float:
        # with segments the fixes are Gaussian about their segment's error
        fix_kern = KERNELS["gauss"] if seg_k is not None else kern
        return gk.linearise(xx, key_ep, t_s, yaw, odo, gyro_ok, odo_ok, stopped, q, prm,
                            *args_fix, kern, c, ab, g, want, fix_kern, seg_sd, seg_crs_sd,
                            seg_vote, seg_kern, c * seg_mult, pre)

    try:
        for n_stage, (kern, c) in enumerate(stages):
            gk.interval_noise(x, key_ep, t_s, yaw, odo, gyro_ok, odo_ok, prm, v_psd, q)
            # a graduated stage before the last only guides the next one (it needs the basin,
            # not the minimum): 43 -> 29 iterations of the screen's fit of an NLOS hour
            tol_k = tol if n_stage == len(stages) - 1 and not basin_only else max(tol, stage_tol)
            lam = 1e-6
            stage_done = False
            cost = cost_at(x, kern, c, True)
            while its < max_it:
                its += 1
                step = None
                while lam < 1e10:
                    try:
                        step = _banded_solve(ab, -g, lam, work)
                    except LinAlgError:
                        step = None
                    if step is not None and np.all(np.isfinite(step)):
                        x_new = x + step
                        new_cost = cost_at(x_new, kern, c, False)
                        if math.isfinite(new_cost) and new_cost <= cost:
                            break
                    lam *= 10.0
                    step = None
                if step is None:
                    stage_done = True  # no descent left at any damping: a minimum
                    break
                # the step doubled while the cost still falls: as the robust weights change,
                # a reflected run's fixes are let go a few at a time and the solution slides
                # along a valley in steps of decimetres, for hundreds of iterations without
                # an odometer (decisions/0034)
                alpha = 1.0
                while alpha < EXTRAPOLATE_MAX:
                    x_try = x + (2.0 * alpha) * step
                    c_try = cost_at(x_try, kern, c, False)
                    if not (math.isfinite(c_try) and c_try < new_cost):
                        break
                    alpha *= 2.0
                    x_new, new_cost = x_try, c_try
                step = alpha * step
                rel = (cost - new_cost) / max(cost, 1e-12)
                x = x_new
                lam = max(lam / 10.0, 1e-9)
                cost = cost_at(x, kern, c, True)
                if rel < tol_k or float(np.max(np.abs(step))) < 1e-5:
                    stage_done = True
                    break
            if not stage_done:
                message = f"no convergence in {max_it} iterations"
                break
        else:
            converged = True
    except (LinAlgError, ValueError, FloatingPointError) as err:
        message = f"solver failed: {err}"
    if converged and not np.all(np.isfinite(x)):
        converged, message = False, "solution not finite"
    if not converged:
        return GraphOutcome(None, False, its, message or "not converged")

    # ---- marginal covariance inside the band (H at the solution, final weights)
    var_e_k = var_n_k = cov_en_k = s_var = b_var = g_var = np.full(n_key, np.nan)
    if sigmas:
        cost_at(x, stages[-1][0], c_final, True)
        try:
            var_e_k, var_n_k, cov_en_k, s_var, b_var, g_var = _marginals(ab, n_x)
        except LinAlgError as err:
            return GraphOutcome(None, False, its,
                                f"information matrix not positive definite: {err}")
        if not (np.all(np.isfinite(var_e_k)) and np.all(np.isfinite(var_n_k))):
            return GraphOutcome(None, False, its, "marginal covariance not finite")
    ab = g = q = None

    # ---- to every epoch
    e = np.zeros(n_ep)
    nn = np.zeros(n_ep)
    ve = np.zeros(n_ep)
    vn = np.zeros(n_ep)
    psi = np.zeros(n_ep)
    gk.to_epochs(x, key_ep, t_s, yaw, odo, gyro_ok, odo_ok, prm, n_ep, e, nn, ve, vn, psi)
    tk = t_s[key_ep]
    var_e = np.interp(t_s, tk, np.maximum(var_e_k, 0.0))
    var_n = np.interp(t_s, tk, np.maximum(var_n_k, 0.0))
    cov_en = np.interp(t_s, tk, cov_en_k)
    w_k = np.full(n_key, np.nan)
    r2_k = np.full(n_key, np.nan)
    gk.fix_weights(x, fe, fn, sde, sdn, stages[-1][0], c_final, w_k, r2_k)
    if seg_k is not None:
        w_k = _segment_weights(x, seg_k, fe, fn, max(float(gp["nlos_segment_sd_m"]), 1e-3), seg_kern,
                               c_final * seg_mult)
        r2_k = np.where(np.isfinite(w_k), r2_k, np.nan)
    weight = np.full(n_ep, np.nan)
    weight[key_ep] = w_k
    nis = np.full(n_ep, np.nan)
    nis[key_ep] = r2_k
    rejected = has_fix & (np.nan_to_num(weight, nan=1.0) < float(gp["weight_rejected"]))
    static = np.zeros(n_ep, bool)
    for i in np.flatnonzero(stopped):
        static[key_ep[i]:key_ep[i + 1] + 1] = True
    s_k = x[gk.S::gk.N_X]
    b_k = x[gk.B::gk.N_X]
    g_k = x[gk.G::gk.N_X]
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(nn)) and np.all(np.isfinite(ve))
            and np.all(np.isfinite(vn))):
        return GraphOutcome(None, False, its, "track not finite")
    extras = {"gyro_bias_radps": np.interp(t_s, tk, b_k), "odo_scale": np.interp(t_s, tk, s_k),
              "gyro_scale": np.interp(t_s, tk, g_k), "gnss_weight": weight}
    n_down = int(np.count_nonzero(has_fix & (np.nan_to_num(weight, nan=1.0) < 0.5)))
    odo_fit, odo_fit_sd = _pooled(s_k, s_var, have_odo)
    bias_fit, bias_fit_sd = _pooled(b_k, b_var, have_gyro)
    gsc_fit, gsc_fit_sd = _pooled(g_k, g_var, have_gyro)
    info = dict(init.info)
    info.update({"smoothing": "graph", "smoothed": True, "graph_iterations": its,
                 "graph_keyframes": n_key, "graph_kernel": kernel_names,
                 "graph_odo_lag_s": lag, "graph_gnss_err_states": err_on,
                 "graph_accel": acc_on,
                 "graph_fixes_downweighted": n_down,
                 "graph_odo_scale": odo_fit, "graph_gyro_bias_radps": bias_fit,
                 "graph_gyro_scale": gsc_fit, "graph_odo_scale_sd": odo_fit_sd,
                 "graph_gyro_bias_sd_radps": bias_fit_sd, "graph_gyro_scale_sd": gsc_fit_sd,
                 "gnss_rejected": int(rejected.sum())})
    res = FilterResult(t_ns=np.asarray(epochs.t_ns, np.int64), e=e, n=nn, v_e=ve, v_n=vn,
                       var_e=var_e, var_n=var_n, cov_en=cov_en,
                       gnss_used=has_fix & ~rejected, gnss_rejected=rejected, nis=nis,
                       static=static, extras=extras, info=info)
    return GraphOutcome(res, True, its, "converged", gnss_weight=weight, odo_scale=odo_fit,
                        odo_scale_sd=odo_fit_sd, gyro_bias_radps=bias_fit,
                        gyro_bias_sd_radps=bias_fit_sd, gyro_scale=gsc_fit)


def _pooled(per_key: np.ndarray, var: np.ndarray, have: bool) -> tuple[float, float]:
    """A drive's calibration from the keyframes' values: their mean and the last keyframe's
    sigma (the marginal variances ``var``; NaN where not computed), NaN for a sensor the
    drive lacks."""
    if not have:
        return math.nan, math.nan
    return float(np.mean(per_key)), float(math.sqrt(max(var[-1], 0.0)))
