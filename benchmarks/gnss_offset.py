"""Whose clock is late?  `--gnss-offset auto` on drives whose fixes or dead reckoning are late.

    python benchmarks/gnss_offset.py [--scenarios open_sky,urban_canyon] [--seeds 1,2]
                                     [--filters aekf,fkf] [--duration 300]

For each simulated drive the fixes are stamped 0.12 s late (``late``) or early (``early``),
or the gyro and odometer are block-averaged to 5 Hz and stamped at the end of each block
(``can5hz``: 0.1 s of dead-reckoning lag, a CAN bus's averaged signals); ``clean`` is the
drive as simulated (whose odometer already lags 0.05 s: a filtered wheel speed).  Each
filter runs forward and with RTS with the streams as logged (offset 0, ``[time] odo_lag_auto =
false``), at the defaults (ekf/aekf read an odometer that is clearly late against the fixes
earlier: ``odo lag``, decisions/0024) and with ``auto``; RMSE in metres against the truth,
next to the fixes' own.  ``hint`` is the offset the track as logged shows (what ``gpsdr fuse``
warns about at 0.06 s and 10 standard errors).

Then the same drives, and comma2k19, split the disagreement two ways from the RTS track at
offset 0, without trusting the fused velocity: the residual displacement of the fixes over
3 s against the dead reckoning (odometer speed, gyro heading) is regressed on the velocity
change along the track (which reads GNSS-vs-odometer) and across it (turns:
GNSS-vs-gyro).  Shows which clock ``auto`` aligns the fixes to.  The standard errors are
the regression's over windows that overlap about 15-fold: the real scatter is 2-4x larger.

Last, comma2k19's streams each against its reference, no filter involved (``--comma-only``
prints this table alone, in seconds): the odometer's and the receiver's speed shifted until
they fit the reference's speed best (central differences over +-0.1 s, one scale fitted), and
the fixes' positions by the reference regression of :func:`gpsdr_cli.latency.estimate_gnss_offset`
and by the shift at which their RMSE against the reference is least.  A positive lag: the
stream at stamp t describes the reference at t + lag (decisions/0083).
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli import config  # noqa: E402
from gpsdr_cli.align import build_epochs  # noqa: E402
from gpsdr_cli.evaluation import reference_en  # noqa: E402
from gpsdr_cli.geodesy import LocalFrame  # noqa: E402
from gpsdr_cli.io.readers import read_drive  # noqa: E402
from gpsdr_cli.io.reference import read_reference  # noqa: E402
from gpsdr_cli.latency import _fix_mask, _t_ns, estimate_gnss_offset, huber_fit  # noqa: E402
from gpsdr_cli.pipeline import fuse  # noqa: E402
from gpsdr_cli.simulate import simulate_drive  # noqa: E402
from gpsdr_cli.testing import faults as F  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CASES = ("clean", "late", "early", "can5hz")
STAMP = {"late": -0.12, "early": +0.12}
WINDOW_S = 3.0
SMOOTH_S = 15.0


def _interp(x: np.ndarray, has: np.ndarray, t: np.ndarray) -> np.ndarray:
    i = np.flatnonzero(has)
    return np.interp(t, t[i], x[i]) if len(i) else np.zeros(len(t))


def split(track, epochs) -> tuple[float, float, float, float]:
    """(along, its sd, across, its sd) in s: the fixes' offset read from speed changes
    (against the odometer's clock) and from turns (against the gyro's)."""
    t = (np.asarray(epochs.t_ns) - epochs.t_ns[0]) / 1e9
    s = _interp(np.asarray(epochs.odo_speed_mps, float), np.asarray(epochs.has_odo, bool), t)
    w = _interp(np.asarray(epochs.yaw_rate_radps, float), np.asarray(epochs.has_gyro, bool), t)
    dt = np.diff(t)
    phi = np.concatenate(([0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)))  # CCW, rad
    z = s * np.exp(1j * phi)
    k = np.concatenate(([0.0], np.cumsum(0.5 * (z[1:] + z[:-1]) * dt)))
    psi = np.radians(track.heading_deg.to_numpy(float))  # clockwise from north
    # heading = c - phi; c (the gyro's heading offset, which drifts with its bias) averaged
    # over +-SMOOTH_S, so that the fused heading, pulled toward the fixes' course on their
    # clock, does not carry that clock into the turns
    moving = s > 1.0
    c = np.unwrap(np.where(moving, psi + phi, np.nan)[moving])
    cs = np.concatenate(([0.0], np.cumsum(c)))
    tm = t[moving]
    lo = np.searchsorted(tm, t - SMOOTH_S)
    hi = np.searchsorted(tm, t + SMOOTH_S)
    c_all = (cs[hi] - cs[lo]) / np.maximum(hi - lo, 1)
    idx = np.flatnonzero(_fix_mask(track))
    tf = t[idx]
    j = np.minimum(np.searchsorted(tf, tf + WINDOW_S), len(idx) - 1)
    a, b = idx, idx[j]
    ok = (np.abs(t[b] - t[a] - WINDOW_S) < 0.35 * WINDOW_S) & (b > a) & (s[a] > 1.0)
    a, b = a[ok], b[ok]
    # east + i north of a unit vector at heading psi is i exp(-i psi)
    rot = 1j * np.exp(-1j * c_all[a])
    disp = rot * (k[b] - k[a])
    va = rot * s[a] * np.exp(1j * phi[a])
    vb = rot * s[b] * np.exp(1j * phi[b])
    g = track.gnss_e.to_numpy(float) + 1j * track.gnss_n.to_numpy(float)
    u = disp / np.maximum(np.abs(disp), 1e-9)
    r = ((g[b] - g[a]) - disp) / u            # real: along the track, imaginary: across
    dv = (vb - va) / u
    d = np.abs(disp)                           # nuisances: speed scale, heading rotation
    ba, ca = huber_fit(np.column_stack([dv.real, d]), r.real)
    bc, cc = huber_fit(np.column_stack([dv.imag, d]), r.imag)
    return float(ba[0]), float(np.sqrt(ca[0, 0])), float(bc[0]), float(np.sqrt(cc[0, 0]))


def _params(name: str, smooth: bool, offset: float = 0.0, odo_lag_auto: bool = True):
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = smooth
    p["filter"]["smoother"] = "rts" if smooth else "none"
    p["time"]["gnss_offset_s"] = offset
    p["time"]["odo_lag_auto"] = odo_lag_auto
    return p


def _drive(scenario: str, seed: int, case: str, duration: float):
    sim = simulate_drive(scenario, seed, duration, gnss_stamp_offset_s=STAMP.get(case, 0.0))
    drive = sim.drive
    if case == "can5hz":
        drive = F.decimate(F.decimate(drive, "gyro", 5.0), "odo", 5.0)
    return sim, drive


#: shifts tried against the reference (s), and the reference's speed: central differences (s)
SHIFTS_S = np.arange(-0.10, 0.2501, 0.005)
REF_DIFF_S = 0.1


def _best_speed_shift(t: np.ndarray, speed: np.ndarray, tr: np.ndarray, er: np.ndarray,
                      nr: np.ndarray) -> float:
    """The shift (s) at which ``speed`` at ``t`` (s) fits the reference's speed at t + shift
    best (least RMS, one scale fitted), inside the reference's span less 1 s at each end."""
    m = np.isfinite(speed) & (t > tr[0] + 1.0) & (t < tr[-1] - 1.0)
    t, speed = t[m], speed[m]
    h = REF_DIFF_S
    cost = []
    for d in SHIFTS_S:
        ve = (np.interp(t + d + h, tr, er) - np.interp(t + d - h, tr, er)) / (2 * h)
        vn = (np.interp(t + d + h, tr, nr) - np.interp(t + d - h, tr, nr)) / (2 * h)
        rs = np.hypot(ve, vn)
        k = float(np.sum(speed * rs) / np.sum(speed * speed))
        cost.append(float(np.sqrt(np.mean((k * speed - rs) ** 2))))
    return float(SHIFTS_S[int(np.argmin(cost))])


def comma_stream_lags(comma, refobj) -> list[tuple[str, float]]:
    """comma2k19's streams against its reference, each on its own (s): see the docstring."""
    p = config.defaults()
    frame = LocalFrame.for_fixes(comma.gnss.lat_deg, comma.gnss.lon_deg)
    ref = reference_en(refobj, frame)
    tr = (ref["t_ns"].to_numpy(np.int64) - ref["t_ns"].iloc[0]) / 1e9
    er, nr = ref["e"].to_numpy(float), ref["n"].to_numpy(float)
    t0 = int(ref["t_ns"].iloc[0])
    rows = []
    for label, t_ns, speed in (("odometer speed", comma.odo.t_ns, comma.odo.speed_mps),
                               ("receiver speed", comma.gnss.t_ns, comma.gnss.speed_mps)):
        t = (np.asarray(t_ns, np.int64) - t0) / 1e9
        rows.append((label, _best_speed_shift(t, np.asarray(speed, float), tr, er, nr)))
    ep = build_epochs(copy.deepcopy(comma), frame, p)
    fixes = {"t_ns": ep.t_ns, "gnss_e": ep.gnss_e, "gnss_n": ep.gnss_n}
    est = estimate_gnss_offset(pd.DataFrame({**fixes, "e": np.nan, "n": np.nan, "v_e": np.nan,
                                             "v_n": np.nan}), ref)
    rows.append(("fixes' positions (reference regression)", est.offset_s))
    f = np.flatnonzero(np.isfinite(ep.gnss_e))
    tf = (np.asarray(ep.t_ns, np.int64)[f] - t0) / 1e9
    rmse = []
    for d in SHIFTS_S:
        tt = tf + d
        ok = (tt > tr[0]) & (tt < tr[-1])
        de = ep.gnss_e[f][ok] - np.interp(tt[ok], tr, er)
        dn = ep.gnss_n[f][ok] - np.interp(tt[ok], tr, nr)
        rmse.append(float(np.sqrt(np.mean(de * de + dn * dn))))
    best = float(SHIFTS_S[int(np.argmin(rmse))])
    rows.append(("fixes' positions (least RMSE)", best))
    # the tracks' speed, the fixes moved by that shift: whose clock does each filter follow?
    for name in ("ekf", "fkf"):
        for smooth in (False, True):
            tr_ = fuse(copy.deepcopy(comma), _params(name, smooth, offset=round(best, 3),
                                                     odo_lag_auto=False)).track
            t = (_t_ns(tr_) - t0) / 1e9
            speed = np.hypot(tr_["v_e"].to_numpy(float), tr_["v_n"].to_numpy(float))
            rows.append((f"{name}{' + RTS' if smooth else ''} track speed, fixes at "
                         f"{best:+.3f} s", _best_speed_shift(t, speed, tr, er, nr)))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="open_sky,urban_canyon")
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--filters", default="aekf,fkf")
    ap.add_argument("--duration", type=float, default=300.0, help="s")
    ap.add_argument("--comma-only", action="store_true",
                    help="only comma2k19's streams against its reference")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    t0 = time.perf_counter()
    c = ROOT / "sample_logs" / "comma2k19"
    comma = read_drive(params=config.defaults(), gps=c / "gps.nmea", gyro=c / "gyro.csv",
                       odo=c / "odo.csv")
    comma_ref = read_reference(c / "truth.csv")
    if args.comma_only:
        _print_stream_lags(comma, comma_ref)
        return 0
    scenarios = args.scenarios.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    print("| drive | case | filter | fixes | as logged | hint s | default | odo lag s | auto "
          "| auto offset s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for sc in scenarios:
        for case in CASES:
            for seed in seeds:
                sim, drive = _drive(sc, seed, case, args.duration)
                ref = sim.reference()
                for name in args.filters.split(","):
                    for smooth in (False, True):
                        p = _params(name, smooth)
                        r0 = fuse(copy.deepcopy(drive), _params(name, smooth, odo_lag_auto=False),
                                  ref)
                        hint = estimate_gnss_offset(r0.track)
                        rd = fuse(copy.deepcopy(drive), p, ref)
                        r1 = fuse(copy.deepcopy(drive), p, ref, auto_gnss_offset=True)
                        label = name + (" + RTS" if smooth else "")
                        fixes = r0.gnss_only_summary()["rmse_m"]
                        print(f"| {sc} s{seed} | {case} | {label} | {fixes:.2f} | "
                              f"{r0.summary()['rmse_m']:.2f} | "
                              f"{hint.offset_s:+.3f} +-{hint.stderr_s:.3f} | "
                              f"{rd.summary()['rmse_m']:.2f} | "
                              f"{max(0.0, -rd.params['time']['odo_offset_s']):.3f} | "
                              f"{r1.summary()['rmse_m']:.2f} | {r1.gnss_offset_s:+.3f} |", flush=True)
    print()
    print("| drive | case | along: fixes vs odometer, s | across: fixes vs gyro, s |")
    print("|---|---|---|---|")
    runs = [("comma2k19", "as logged", comma, comma_ref)]
    for sc in scenarios:
        for case in CASES:
            sim, drive = _drive(sc, seeds[0], case, args.duration)
            runs.append((f"{sc} s{seeds[0]}", case, drive, None))
    for label, case, drive, ref in runs:
        res = fuse(copy.deepcopy(drive), _params("aekf", True, odo_lag_auto=False), ref)
        al, sal, ac, sac = split(res.track, res.epochs)
        print(f"| {label} | {case} | {al:+.3f} +-{sal:.3f} | {ac:+.3f} +-{sac:.3f} |", flush=True)
    print()
    _print_stream_lags(comma, comma_ref)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


def _print_stream_lags(comma, refobj) -> None:
    print("| comma2k19 stream | lag against the reference, s |")
    print("|---|---|")
    for label, lag in comma_stream_lags(comma, refobj):
        print(f"| {label} | {lag:+.3f} |")


if __name__ == "__main__":
    sys.exit(main())
