"""``fkf``: federated Kalman filter of GNSS and dead reckoning (Tang et al.).

Two local filters share the 10-state model of
:mod:`gpsdr_cli.filters.kernels_fkf` (which documents Phi, Q, H and the
fusion): a GNSS filter (position fixes) and a DR filter (gyro-integrated
heading ``Theta`` and odometer distance ``S``).  A master filter fuses them
every epoch by covariance weighting ``P_g = (sum P_i^-1)^-1``,
``x_g = P_g sum P_i^-1 x_i``.  ``[fkf] mode``: ``"nr"`` (no reset, the
paper's) or ``"fr"`` (fusion-reset with information-sharing factors
``beta_gnss``, ``1 - beta_gnss``, Carlson 1990; the default because in NR the
DR filter's position is pure dead reckoning from the start of the drive).

Conventions (:mod:`gpsdr_cli.conventions`): metres ENU, seconds; heading
clockwise from north; the gyro's yaw rate is CCW-positive, so the integrated
heading is ``psi(t) = psi(t_a) - int_{t_a}^t yaw_rate dt``.

This module prepares the kernel's arrays from :class:`~gpsdr_cli.epochs.Epochs`:

* ``Theta``: the trapezoid integral of ``-yaw_rate`` over the gyro records,
  aligned at ``t_a`` to the first GNSS course over ground given with speed
  >= ``[standstill] omega_min_speed_mps``; without one, to the course between
  two fixes 2 s apart that are at least max(5 m, 4 sigma) apart; without any,
  to ``[frame] initial_heading_deg`` (else 0).  Then (our choice, beyond the
  paper) slowly steered to the GNSS course by :func:`course_correction`.  Used at gyro epochs at most
  every ``[fkf] heading_interval_s`` (the integrated heading's errors are
  correlated; updating at the gyro's full rate would treat them as white).
  Without a gyro but with an odometer, Theta only inside GNSS outages that run
  straight or through a gentle curve: the course at both ends, interpolated
  (:func:`outage_headings`).
* ``S = |odo speed| x T_m`` summed over ``[fkf] distance_interval_s`` slots and
  at every heading epoch (:func:`distance_rows`), ``T_m`` the time since the
  previous distance row; sigma ``[odo] noise_sd_mps x T_m``.  The odometer
  speed is first scaled to the GNSS speed by :func:`odometer_scale` (our
  choice, beyond the paper: its q_s is an additive error in metres per
  odometer interval, which cannot hold a wheel-radius error, and the fused
  track fell behind; a scale state ``S = (1 + q_s) T_m v`` instead let (q_s, v)
  wander along their unobservable ridge in GNSS outages; evidence:
  docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf).
* positions only (the receiver's speed at fewer than ``[fkf]
  fix_course_velocity_share`` of the fixes: NMEA GGA without RMC/VTG, a ROS
  NavSatFix), the course steering and the odometer scale come instead from
  chords between fixes compared with the dead-reckoned chords over the same
  times (:func:`fix_chords`, :func:`chord_course_correction`,
  :func:`chord_odometer_scale`; ``info["course_source"] = "fix_chords"``).
  Per drive, not per fix: a drive with the receiver's velocity keeps its
  course steering bit for bit, and a chord is worth far less than a Doppler
  course beside it.  Without them the gyro bias ran into Theta and the
  odometer kept its scale error (evidence:
  docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf).  The chords never become velocity
  rows (they are made of the same fixes the GNSS filter already takes: counted twice).
* receiver velocity ``(speed sin(course), speed cos(course))`` at fixes with
  speed >= ``[fkf] gnss_velocity_min_mps`` (else NaN): the GNSS local
  filter's velocity rows (``[fkf] gnss_velocity``).
* standstill: the latest odometer speed (at most 1 s old) below
  ``[standstill] speed_mps``; without an odometer, the receiver's (Doppler)
  speed below ``[fkf] gnss_standstill_speed_mps`` over ``gnss_standstill_window_s``
  (:func:`~.standstill.gnss_standstill`), or with positions only the speed between the
  median positions of the fixes either side (:func:`~.standstill.fix_speeds`) below
  ``fix_standstill_speed_mps``.  Without it the velocity ran away at stops: no
  odometer, nothing else says the car stopped (evidence:
  docs/decisions/0015-evidence-behind-the-filter-choices.md#standstill).
* the regime of the GNSS error states eps per epoch, clear or obstructed sky
  (:func:`multipath_regime`: the share of recent fixes with a high PDOP);
  the kernel blends the two eps models by it (our choice, issue #4).
* initial state: the first usable fix (else e = n = 0), speed from the first
  odometer (else GNSS) record along the aligned heading.

Smoothing (``params["filter"]["smooth"]``), ``info["smoothing"]``:

* ``fkf``: the *fused* sequence is smoothed by a fixed-interval RTS pass
  (:func:`~gpsdr_cli.filters.core.rts.rts_step`, written out for this Phi in
  :func:`~.kernels_fkf.rts_step_fused`: the same floats) with the master's own
  prediction ``Phi x_g``, ``Phi P_g Phi^T + Q``, Phi and Q recomputed from
  ``dt``.  It needs the fused x and P_g of every epoch; the forward pass keeps
  instead a checkpoint of its whole state every ``[fkf] smooth_segment_epochs``
  (4096) epochs, and the smoother re-runs each segment from its checkpoint
  (the same floats) and smooths it (:func:`~.kernels_fkf.federated_pass`):
  65 floats x 4096 epochs in memory instead of x every epoch (a one-hour drive
  at 100 Hz: 187 MB), for one more forward pass.  In FR mode the covariance-weighted fused
  sequence is the centralised filter's (up to the EKF linearisation), so this is the usual RTS
  smoother; in NR mode it is an approximation.  Where the fused sequence is
  not a Kalman posterior (a stale local filter dropped, a heading re-aligned,
  an unmodelled gyro bias) RTS can run away; a guard restarts the backward
  recursion from the forward estimate wherever the smoothed position leaves
  it by more than chi-square(2) = 25 (``info["smoother_restarts"]``).
* ``fafkf`` with ``[fafkf] weights = "shares"`` (covariance-weighted fusion):
  the same fused RTS as fkf.
* ``fafkf`` with the paper's convex weights (``"scalar"``, ``"block"``): the
  fuzzy-weighted fused sequence is *not* a Kalman posterior
  (its P_g is Carlson's bound, and block weights change the position-velocity
  cross-covariance from epoch to epoch), and RTS over it made the track worse
  (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#fkf).  It is
  smoothed instead as forward + backward: the same filter run over the
  time-reversed drive (:func:`reverse_epochs`), the two tracks fused by their
  position covariances (:func:`combine_two_filter`).  Nothing is stored per
  epoch beyond the two tracks.  Without GNSS the backward pass has no heading
  anchor, so a DR-only drive keeps its forward track.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Params
from ..epochs import Epochs
from ..errors import NoDataError
from . import fuzzy, register
from . import kernels_fkf as kf
from .adaptive import gate_threshold
from .base import FilterResult
from .fkf_inputs import (  # the input conditioning, re-exported: fkf.prepare etc.
    COURSE_BASE_S,
    MAX_OUTAGE_TURN_RATE,
    MIN_SCALE_FIXES,
    OUTAGE_EDGE_S,
    STALE_ODO_S,
    STRAIGHT_OUTAGE_RAD,
    FixChords,
    Prepared,
    chi2_1,
    chord_course_correction,
    chord_odometer_scale,
    course_correction,
    despike,
    distance_rows,
    dr_positions,
    fix_chords,
    heading_alignment,
    multipath_regime,
    odometer_scale,
    outage_headings,
    prepare,
    windowed_ratio,
)

__all__ = [
    "gate_threshold",
    "COURSE_BASE_S",
    "FixChords",
    "MAX_OUTAGE_TURN_RATE",
    "MIN_SCALE_FIXES",
    "OUTAGE_EDGE_S",
    "Prepared",
    "STALE_ODO_S",
    "STRAIGHT_OUTAGE_RAD",
    "chi2_1",
    "chord_course_correction",
    "chord_odometer_scale",
    "course_correction",
    "despike",
    "distance_rows",
    "dr_positions",
    "fix_chords",
    "heading_alignment",
    "multipath_regime",
    "odometer_scale",
    "outage_headings",
    "prepare",
    "windowed_ratio",
    "combine_two_filter",
    "forward",
    "reverse_epochs",
    "run",
    "run_federated",
]


def reverse_epochs(epochs: Epochs) -> Epochs:
    """The same drive with time running backwards (for the backward pass of fafkf's smoother).

    Time ``t' = t_first + t_last - t``; the vehicle then drives in reverse, so
    its heading is ``psi + pi`` (GNSS course turned by pi) and ``d(psi)/dt``
    changes sign (yaw rate negated); speeds and positions are unchanged.
    """
    t = epochs.t_ns
    rev = slice(None, None, -1)
    dt = np.zeros(len(t))
    dt[1:] = epochs.dt_s[rev][:-1]
    course = epochs.gnss_course_rad[rev] + math.pi
    return Epochs(t_ns=(t[0] + t[-1]) - t[rev], dt_s=dt, has_gnss=epochs.has_gnss[rev],
                  gnss_e=epochs.gnss_e[rev], gnss_n=epochs.gnss_n[rev],
                  gnss_sd_e=epochs.gnss_sd_e[rev], gnss_sd_n=epochs.gnss_sd_n[rev],
                  pdop=epochs.pdop[rev], gnss_speed_mps=epochs.gnss_speed_mps[rev],
                  gnss_course_rad=np.angle(np.exp(1j * course)), has_gyro=epochs.has_gyro[rev],
                  yaw_rate_radps=-epochs.yaw_rate_radps[rev], has_odo=epochs.has_odo[rev],
                  odo_speed_mps=epochs.odo_speed_mps[rev], gnss_outage=epochs.gnss_outage[rev],
                  gap_s=epochs.gap_s, rtk_fixed_share=epochs.rtk_fixed_share,
                  gnss_quality=epochs.gnss_quality[rev])


#: epochs per block of :func:`combine_two_filter` (bounds its ~20 temporaries to ~10 MB)
COMBINE_BLOCK = 65536


def combine_two_filter(fwd: np.ndarray, bwd: np.ndarray) -> np.ndarray:
    """Forward and backward tracks (kernel ``out`` layout: rows ``O_*``) fused by their
    position covariances.

    Position: ``P_s = (P_f^-1 + P_b^-1)^-1``, ``x_s = P_s (P_f^-1 x_f + P_b^-1 x_b)``
    with the 2x2 blocks (closed-form inverses); velocity: the same weights
    reduced to a scalar, ``w_f = tr P_b / (tr P_f + tr P_b)``.  Both passes
    use the measurement of the epoch itself, so P_s is optimistic by up to a
    factor 2 where the passes are equally good (the Fraser-Potter form would
    exclude it from one pass).  Elementwise, in blocks of ``COMBINE_BLOCK``
    epochs: the whole-drive form's temporaries took ~50 MB on a one-hour drive.
    """
    out = np.empty(fwd.shape)
    for lo in range(0, fwd.shape[1], COMBINE_BLOCK):
        sl = slice(lo, lo + COMBINE_BLOCK)
        _combine_block(fwd[:, sl], bwd[:, sl], out[:, sl])
    return out


def _combine_block(fwd: np.ndarray, bwd: np.ndarray, out: np.ndarray) -> None:
    """:func:`combine_two_filter` over one block of epochs, into ``out``."""
    def info(o: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b, c = o[kf.O_VAR_E], o[kf.O_COV_EN], o[kf.O_VAR_N]
        det = a * c - b * b
        return c / det, -b / det, a / det               # inverse [[a, b], [b, c]]

    fa, fb, fc = info(fwd)
    ba, bb, bc = info(bwd)
    ia, ib, ic = fa + ba, fb + bb, fc + bc
    det = ia * ic - ib * ib
    pa, pb, pc = ic / det, -ib / det, ia / det
    ye = fa * fwd[kf.O_E] + fb * fwd[kf.O_N] + ba * bwd[kf.O_E] + bb * bwd[kf.O_N]
    yn = fb * fwd[kf.O_E] + fc * fwd[kf.O_N] + bb * bwd[kf.O_E] + bc * bwd[kf.O_N]
    out[kf.O_E] = pa * ye + pb * yn
    out[kf.O_N] = pb * ye + pc * yn
    tf = fwd[kf.O_VAR_E] + fwd[kf.O_VAR_N]
    tb = bwd[kf.O_VAR_E] + bwd[kf.O_VAR_N]
    wf = tb / (tf + tb)
    out[kf.O_VE] = wf * fwd[kf.O_VE] + (1.0 - wf) * bwd[kf.O_VE]
    out[kf.O_VN] = wf * fwd[kf.O_VN] + (1.0 - wf) * bwd[kf.O_VN]
    out[kf.O_VAR_E] = pa
    out[kf.O_COV_EN] = pb
    out[kf.O_VAR_N] = pc


def forward(kind: str, prep: Prepared, store: bool, segment: int = 0) -> tuple:
    """The compiled pass of ``kind`` over prepared inputs (:func:`~.kernels_fkf.federated_pass`).

    With ``store`` and ``segment > 0`` the pass is smoothed in O(segment) memory
    (its ``out`` the smoothed track); with ``store`` and ``segment <= 0`` it
    returns every epoch's fused x and P for :func:`~.kernels_fkf.smooth_fused`.
    The kernel is given ``segment`` only in the first case, else None: a run
    without the checkpointed smoother then compiles none of it (cold start).
    Returns ``(out, used, rejected, nis, beta, rfac, counters, xs, Ps, smooth_stats)``.
    """
    flags = prep.flags.copy()
    flags[kf.FLG_STORE] = store
    inp = kf.FkfInputs(prep.dt, prep.has_gnss, prep.gnss_e, prep.gnss_n, prep.gnss_var_e,
                       prep.gnss_var_n, prep.gnss_ve, prep.gnss_vn, prep.theta, prep.dist,
                       prep.t_m, prep.static, prep.eps_w)
    return kf.federated_pass(inp, kf.FkfStart(prep.x0, prep.P0, float(prep.psi0)), prep.par,
                             kf.kernel_flags(kind == "fafkf", flags), fuzzy.R_TABLE,
                             fuzzy.W_TABLE, int(segment) if store and segment > 0 else None)


def run_federated(kind: str, epochs: Epochs, params: Params) -> FilterResult:
    """Run ``fkf`` or ``fafkf`` over the epochs (forward pass, then the smoother when asked)."""
    n = len(epochs)
    if n == 0:
        raise NoDataError(None, f"{kind}: no epochs to filter; expected at least one record")
    prep = prepare(epochs, params)
    smoothed = bool(params["filter"]["smooth"])
    # RTS needs a Kalman posterior: covariance-weighted fusion (fkf, fafkf "shares")
    rts = kind == "fkf" or params["fafkf"]["weights"] == "shares"
    segment = int(params["fkf"]["smooth_segment_epochs"])
    out, used, rej, nis, beta, rfac, counters, xs, Ps, stats = forward(
        kind, prep, smoothed and rts, segment)
    smooth_not_spd, restarts = int(stats[0]), int(stats[1])
    smoothing = "none"
    if smoothed and rts:
        if segment <= 0:                            # every epoch's x and P were stored
            out, smooth_not_spd, restarts = kf.smooth_fused(xs, Ps, prep.dt, prep.static,
                                                            prep.has_gnss, prep.eps_w, prep.par)
        smoothing = "rts_fused"
    del xs, Ps
    static, info, gnss_on = prep.static, dict(prep.info), bool(prep.flags[kf.FLG_GNSS_ON])
    del prep                                        # the inputs: not needed from here on
    if smoothed and not rts and gnss_on and n > 1:
        out_b = forward(kind, prepare(reverse_epochs(epochs), params), False)[0][:, ::-1]
        out_b[kf.O_VE] *= -1.0                      # a reversed view: flipped back, no copy
        out_b[kf.O_VN] *= -1.0
        out = combine_two_filter(out, out_b)
        del out_b
        smoothing = "forward_backward"
    if smoothing == "rts_fused":
        info["smoother_restarts"] = int(restarts)
    info.update({
        "filter": kind, "mode": params["fkf"]["mode"], "smoothed": smoothing != "none",
        "smoothing": smoothing,
        "gnss_used": int(counters[kf.C_GNSS_USED]),
        "gnss_rejected": int(counters[kf.C_GNSS_REJECTED]),
        "gate_resets": int(counters[kf.C_GATE_RESETS]),
        "heading_updates": int(counters[kf.C_HEADING]),
        "heading_skipped_slow": int(counters[kf.C_HEADING_SLOW]),
        "distance_updates": int(counters[kf.C_DIST]),
        "gnss_velocity_updates": int(counters[kf.C_GVEL]),
        "gnss_velocity_gated": int(counters[kf.C_GVEL_REJECTED]),
        "coast_updates": int(counters[kf.C_COAST]),
        "zupt_epochs": int(counters[kf.C_ZUPT]),
        "r_adaptations": int(counters[kf.C_R_ADAPT]),
        "heading_rejected": int(counters[kf.C_HEAD_REJECTED]),
        "distance_rejected": int(counters[kf.C_DIST_REJECTED]),
        "heading_realigned": int(counters[kf.C_HEAD_REALIGN]),
        "stale_filter_epochs": int(counters[kf.C_STALE]),
        "spd_failures": int(counters[kf.C_NOT_SPD]) + int(smooth_not_spd),
    })
    if kind == "fafkf":
        info["weights"] = params["fafkf"]["weights"]
        info["normalisation"] = params["fafkf"]["normalisation"]
    # rows of the kernels' (k, n) outputs: contiguous views, no copies
    extras = {"beta_gnss": beta[0], "beta_gnss_vel": beta[1]}
    if kind == "fafkf":
        extras.update({"r_factor_gnss_e": rfac[0], "r_factor_gnss_n": rfac[1],
                       "r_factor_heading": rfac[2], "r_factor_distance": rfac[3]})
    return FilterResult(
        t_ns=epochs.t_ns, e=out[kf.O_E], n=out[kf.O_N], v_e=out[kf.O_VE], v_n=out[kf.O_VN],
        var_e=out[kf.O_VAR_E], var_n=out[kf.O_VAR_N], cov_en=out[kf.O_COV_EN],
        gnss_used=used, gnss_rejected=rej, nis=nis, static=static, extras=extras,
        info=info)


@register("fkf")
def run(epochs: Epochs, params: Params) -> FilterResult:
    """Federated Kalman filter (Tang et al.'s FKF baseline): covariance-weighted fusion, fixed R."""
    return run_federated("fkf", epochs, params)
