"""GNSS time offset (latency) estimation from a fused track's GNSS residuals.

Sign convention, the same as ``[time] gnss_offset_s`` (:mod:`gpsdr_cli.align`):
``t_true = t_logged + offset``.  A fix whose position belongs to a *later*
instant than its stamp (it sits ahead of the vehicle along track, as the
u-blox fixes of ../shared/data/comma2k19 do by about 0.1 s) has offset > 0;
a receiver whose fixes are late (classic latency) has offset < 0.

Model: ``gnss(t) = p(t + offset) + noise ~= p(t) + offset * v(t) + noise``, so the
along-track GNSS-minus-track residual grows linearly with speed and the slope
is the offset.  Two ways to use it:

* against an independent reference (``reference_en`` given): regress the
  along-track residual ``(gnss - ref) . u`` on speed (plus an intercept), robustly;
* on a fused track alone (the default): the track has already been pulled
  onto the GNSS positions, so a constant along-track shift is invisible in its
  level.  What survives is the *differenced* form: over a window of ``W``
  seconds the GNSS displacement is the true displacement over the shifted
  window, ``g(t+W) - g(t) = D(t, t+W) + offset * (v(t+W) - v(t))``, while the
  track's own velocity (dominated by the odometer and gyro, which carry their
  own time stamps) integrates to ``D``.  So the residual displacement is
  regressed on the velocity change (vectors, so turns count as well as
  accelerations), with a second nuisance coefficient on ``D`` itself that
  absorbs a residual odometer scale error.

Both regressions are Huber M-estimates (IRLS, scale from the MAD): multipath
jumps and gated outliers do not drag them.  When the drive does not identify
the offset (too few fixes, too little speed change or speed), the estimate is
0 with the reason stated.  Hand-written because it is a few lines of IRLS on
top of numpy; statsmodels is not a dependency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .conventions import NS_PER_S

#: Huber tuning constant (95 % efficiency under Gaussian noise)
HUBER_K = 1.345
#: window of the differenced estimator, s
WINDOW_S = 3.0
#: largest offset believed, s (beyond: a clock error, not a latency)
MAX_OFFSET_S = 2.0
#: ``gpsdr fuse`` without ``--gnss-offset auto`` suggests it when its own track shows an
#: offset at least this large (s: 1 m at 20 m/s) ...
HINT_OFFSET_S = 0.06
#: ... estimated to this many standard errors.  The forward track's own lag and a wheel
#: odometer's window (half its period) read as a few hundredths of a second on simulated
#: drives without latency (+0.00..+0.06 s at 1-3 standard errors); comma2k19 as logged,
#: whose fixes are ~0.1 s ahead, reads +0.076 s at 38 standard errors.
HINT_MIN_T = 10.0


@dataclass
class OffsetEstimate:
    """The estimated GNSS time offset (s, ``t_true = t_logged + offset_s``) and how."""

    offset_s: float
    stderr_s: float
    n_used: int
    method: str      # "reference" | "differenced" | "none"
    reason: str      # why it is 0, or "ok"

    @property
    def identified(self) -> bool:
        return self.method != "none"

    def describe(self) -> str:
        """How it was found, for a summary line."""
        if not math.isfinite(self.stderr_s):
            return self.method
        return f"{self.method}, +-{self.stderr_s:.3f} s from {self.n_used} fixes"


def huber_fit(X: np.ndarray, y: np.ndarray, k: float = HUBER_K, iters: int = 50
              ) -> tuple[np.ndarray, np.ndarray]:
    """Huber M-estimate of ``y ~ X beta`` by iteratively reweighted least squares.

    Returns (beta, covariance of beta).  The scale is the residuals' MAD/0.6745.
    """
    w = np.ones(len(y))
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    scale = 1.0
    for _ in range(iters):
        r = y - X @ beta
        scale = float(np.median(np.abs(r - np.median(r)))) / 0.6745 or 1e-9
        u = np.abs(r) / (k * scale)
        w = np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-12))
        sw = np.sqrt(w)
        new = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)[0]
        if np.allclose(new, beta, atol=1e-9, rtol=1e-7):
            beta = new
            break
        beta = new
    r = y - X @ beta
    xtwx = (X * w[:, None]).T @ X
    dof = max(len(y) - X.shape[1], 1)
    sigma2 = float(np.sum(w * r * r) / dof)
    try:
        cov = np.linalg.inv(xtwx) * sigma2
    except np.linalg.LinAlgError:
        cov = np.full((X.shape[1], X.shape[1]), np.nan)
    return beta, cov


def _t_ns(track: pd.DataFrame) -> np.ndarray:
    if "t_ns" in track:
        return track["t_ns"].to_numpy(np.int64)
    col = track["time"]
    if pd.api.types.is_datetime64_any_dtype(col):
        if getattr(col.dt, "tz", None) is not None:
            col = col.dt.tz_convert("UTC").dt.tz_localize(None)
        return col.astype("datetime64[ns]").to_numpy().view(np.int64)
    return col.to_numpy(np.int64)


def _fix_mask(track: pd.DataFrame) -> np.ndarray:
    ge = track["gnss_e"].to_numpy(float)
    gn = track["gnss_n"].to_numpy(float)
    ok = np.isfinite(ge) & np.isfinite(gn)
    if "gnss_rejected" in track:
        ok &= ~track["gnss_rejected"].fillna(False).to_numpy(bool)
    return ok


def estimate_gnss_offset(track: pd.DataFrame, reference_en: pd.DataFrame | None = None, *,
                         window_s: float = WINDOW_S, min_fixes: int = 30,
                         along: bool = False) -> OffsetEstimate:
    """Estimate the GNSS time offset of a track (see the module docstring).  ``along``: from
    the along-track components alone (speed changes: the fixes against the odometer), not
    the vectors, whose turns read an antenna ahead of the reference point, ``L`` metres, as
    an offset of ``L / speed`` (an along-track unit vector ``u`` of the window's chord sees
    neither that nor a turn's velocity change, both perpendicular to it)."""
    for col in ("gnss_e", "gnss_n", "e", "n", "v_e", "v_n"):
        if col not in track:
            return OffsetEstimate(0.0, np.nan, 0, "none", f"the track has no {col} column")
    fixes = _fix_mask(track)
    if fixes.sum() < min_fixes:
        return OffsetEstimate(0.0, np.nan, int(fixes.sum()), "none",
                              f"too few GNSS fixes ({int(fixes.sum())} < {min_fixes})")
    if reference_en is not None:
        return _by_reference(track, reference_en, fixes, window_s, min_fixes)
    return _differenced(track, fixes, window_s, min_fixes, along=along)


def significant_offset(track: pd.DataFrame, *, along: bool = False) -> OffsetEstimate | None:
    """The offset of ``track``'s fixes against its dead reckoning when it is clear: at least
    :data:`HINT_OFFSET_S` and :data:`HINT_MIN_T` standard errors.  None otherwise.  About
    0.05 s on a one-hour track; ``along`` as in :func:`estimate_gnss_offset`."""
    est = estimate_gnss_offset(track, along=along)
    if not (est.identified and math.isfinite(est.offset_s) and math.isfinite(est.stderr_s)):
        return None
    if abs(est.offset_s) < HINT_OFFSET_S or abs(est.offset_s) < HINT_MIN_T * est.stderr_s:
        return None
    return est


def offset_hint(track: pd.DataFrame, *, odometer: bool = True) -> str | None:
    """A warning line when ``track`` (fused with the offsets the user gave) shows the fixes
    stamped off the dead reckoning's clock (:func:`significant_offset`).  None otherwise.
    ``odometer``: the drive has one, whose own lag reads the same way as fixes stamped
    early (decisions/0022)."""
    est = significant_offset(track)
    if est is None:
        return None
    way = "ahead of" if est.offset_s > 0 else "behind"
    return (f"the GNSS fixes sit {way} the dead reckoning along the track by about "
            f"{abs(est.offset_s):.2f} s of travel (their error grows with the speed): their time "
            "stamps look late or early; --gnss-offset auto estimates the offset "
            "(or give it in seconds)" + (
                ".  auto moves the fixes onto the odometer's clock: if the wheel speed is "
                "the late one (a CAN signal averaged over its period), give a negative "
                "[time] odo_offset_s in a --config file instead"
                if odometer and est.offset_s > 0 else ""))


def estimate_gnss_offset_s(track: pd.DataFrame, reference_en: pd.DataFrame | None = None) -> float:
    """The GNSS time offset in s (``t_true = t_logged + offset``); 0.0 when not identifiable
    (:func:`estimate_gnss_offset` says why)."""
    return float(estimate_gnss_offset(track, reference_en).offset_s)


def _finish(beta0: float, var0: float, n: int, method: str, signal: float, need: float,
            what: str) -> OffsetEstimate:
    if signal < need:
        return OffsetEstimate(0.0, np.nan, n, "none",
                              f"not identifiable: {what} {signal:.1f} < {need:.1f}")
    sd = float(np.sqrt(var0)) if np.isfinite(var0) and var0 >= 0 else np.nan
    if not np.isfinite(beta0) or abs(beta0) > MAX_OFFSET_S:
        return OffsetEstimate(0.0, sd, n, "none",
                              f"estimate {beta0:.3f} s is beyond +-{MAX_OFFSET_S} s: not a latency")
    return OffsetEstimate(float(beta0), sd, n, method, "ok")


def _by_reference(track: pd.DataFrame, ref: pd.DataFrame, fixes: np.ndarray, window_s: float,
                  min_fixes: int) -> OffsetEstimate:
    """The differenced estimator with the reference's own kinematics in place of the track's:
    the fixes are compared with the reference's displacement and velocity (central
    differences over +-0.1 s).  Differencing keeps slow multipath, which a level
    regression on speed would confound with the offset, out of the estimate."""
    from .evaluation import interpolate_reference

    t = _t_ns(track)
    re, rn, _, _, valid = interpolate_reference(ref, t)
    tr = ref["t_ns"].to_numpy(np.int64)
    x = (t - tr[0]).astype(float)
    xr = (tr - tr[0]).astype(float)
    h = 0.1 * NS_PER_S
    er = ref["e"].to_numpy(float)
    nr = ref["n"].to_numpy(float)
    ve = (np.interp(x + h, xr, er) - np.interp(x - h, xr, er)) / 0.2
    vn = (np.interp(x + h, xr, nr) - np.interp(x - h, xr, nr)) / 0.2
    ok = valid & np.isfinite(re) & np.isfinite(rn)
    kin = pd.DataFrame({"t_ns": t, "e": re, "n": rn, "v_e": np.where(ok, ve, np.nan),
                        "v_n": np.where(ok, vn, np.nan),
                        "gnss_e": track["gnss_e"].to_numpy(float),
                        "gnss_n": track["gnss_n"].to_numpy(float)})
    est = _differenced(kin, fixes & ok, window_s, min_fixes, positions=True)
    if est.method == "differenced":
        est.method = "reference"
    return est


#: m: ``along``: windows whose chord is shorter than this give no along-track direction
ALONG_MIN_CHORD_M = 1.0


def _differenced(track: pd.DataFrame, fixes: np.ndarray, window_s: float,
                 min_fixes: int, positions: bool = False, along: bool = False) -> OffsetEstimate:
    """Differenced regression; ``positions``: take displacements from e/n (a reference)
    instead of integrating v_e/v_n (a fused track, whose positions follow the GNSS).
    Every per-epoch series is reduced to the fix epochs as soon as it is made: on an
    hour at 100 Hz the full-length copies would add tens of MB to ``gpsdr fuse``."""
    idx = np.flatnonzero(fixes)
    t_all = _t_ns(track)
    ts = (t_all - t_all[0]) / NS_PER_S
    del t_all
    dt = np.diff(ts)
    tf = ts[idx]
    del ts
    good_v = np.isfinite(track["v_e"].to_numpy(float)) & np.isfinite(track["v_n"].to_numpy(float))
    vel, disp = [], []
    for axis, pos in (("v_e", "e"), ("v_n", "n")):
        v = np.where(good_v, track[axis].to_numpy(float), 0.0)
        vel.append(v[idx])
        if positions:
            disp.append(np.nan_to_num(track[pos].to_numpy(float))[idx])
        else:  # the velocity's integral
            disp.append(np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)))[idx])
        del v
    del dt
    bad_cum = np.cumsum(~good_v)[idx]
    del good_v
    out_cum = (np.cumsum(track["gnss_outage"].fillna(False).to_numpy(bool))[idx]
               if "gnss_outage" in track else np.zeros(len(idx), np.int64))

    j = np.searchsorted(tf, tf + window_s)
    j = np.minimum(j, len(idx) - 1)
    a, b = np.arange(len(idx)), j               # positions among the fixes
    ok = (np.abs(tf[b] - tf[a] - window_s) < 0.35 * window_s) & (b > a)
    ok &= (bad_cum[b] - bad_cum[a]) == 0
    ok &= (out_cum[b] - out_cum[a]) == 0
    a, b = a[ok], b[ok]
    n = len(a)
    if n < min_fixes:
        return OffsetEstimate(0.0, np.nan, n, "none",
                              f"too few fix pairs {window_s:g} s apart ({n} < {min_fixes})")
    ge = track["gnss_e"].to_numpy(float)[idx]
    gn = track["gnss_n"].to_numpy(float)[idx]
    (ve, vn), (pe, pn) = vel, disp
    if along:
        de, dn = pe[b] - pe[a], pn[b] - pn[a]
        chord = np.hypot(de, dn)
        keep = chord >= ALONG_MIN_CHORD_M
        if keep.sum() < min_fixes:
            return OffsetEstimate(0.0, np.nan, int(keep.sum()), "none",
                                  f"too few moving fix pairs ({int(keep.sum())} < {min_fixes})")
        a, b, de, dn, chord = a[keep], b[keep], de[keep], dn[keep], chord[keep]
        ue, un = de / chord, dn / chord
        r = ((ge[b] - ge[a]) - de) * ue + ((gn[b] - gn[a]) - dn) * un
        dv = (ve[b] - ve[a]) * ue + (vn[b] - vn[a]) * un
        d = chord
    else:
        r = np.concatenate([(ge[b] - ge[a]) - (pe[b] - pe[a]), (gn[b] - gn[a]) - (pn[b] - pn[a])])
        dv = np.concatenate([ve[b] - ve[a], vn[b] - vn[a]])
        d = np.concatenate([pe[b] - pe[a], pn[b] - pn[a]])
    X = np.column_stack([dv, d])
    beta, cov = huber_fit(X, r)
    signal = float(np.sqrt(np.sum(dv * dv)))
    return _finish(beta[0], cov[0, 0], len(r) if along else n,
                   "differenced along track" if along else "differenced", signal, 30.0,
                   "velocity change (m/s, root-sum-square over pairs)")


__all__ = ["OffsetEstimate", "estimate_gnss_offset", "estimate_gnss_offset_s", "huber_fit"]
