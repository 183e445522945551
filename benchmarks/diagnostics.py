"""Accuracy diagnostics for issue #4's three missed targets: one table, one figure.

    .venv/bin/python benchmarks/diagnostics.py                  # ~40 s -> docs/accuracy_diagnostics.png
    .venv/bin/python benchmarks/diagnostics.py --seeds 1 --out /tmp/d.png

Issue #4 asks, where a target is missed, by how much and why, "with plots and residuals,
not guesses".  ``benchmarks/accuracy.py`` says by how much; this command shows why.  It
runs the filters through :func:`gpsdr_cli.pipeline.fuse` (the same path as ``gpsdr fuse``),
prints the figures that carry each finding and draws eight panels:

Miss 1, urban canyon (``simulate_drive("urban_canyon", seed)``, seeds 1-3, 600 s each):
"aekf >= 30 % below ekf".

(a) horizontal error (m) vs time (s) on the first seed: ekf and aekf as shipped (GNSS
    multipath carried as Gauss-Markov error states, ``[aekf] gnss_err_states = true``) and
    with the seed's plain model (``[aekf] gnss_err_states = false, gnss_velocity = false``);
    PDOP and the GNSS outages beneath, with aekf's regime thresholds (``[gnss] pdop_good``,
    ``pdop_poor``: R scaled by k = 1 / 3 / 10).
(b) RMSE (m) pooled over the seeds (root of the mean of the per-seed mean squared errors),
    forward and RTS, next to each filter's oracle (the same filter told the true noise:
    :func:`gpsdr_cli.simulate.oracle_params` / :func:`~gpsdr_cli.simulate.oracle_drive`).
(c) GNSS innovation consistency: mean NIS of the 2-dof GNSS updates (``FilterResult.nis``)
    per PDOP band, forward runs pooled over the seeds, over the updates under the gate
    (``[gnss] gate_prob``: NIS <= 18.4; the simulator's 10-40 m outlier jumps would lift
    even the oracle's plain mean to ~3.4), so ~2 when R and P are right, as aekf's oracle
    shows.  Below 2: the innovation covariance is larger than the innovations (R too big);
    above: too small.

Miss 2, the same drives: "fafkf error variance (mean squared error) >= 50 % below fkf".

(d) CDF of fafkf's covariance-matching R factors at the GNSS fixes
    (``FilterResult.extras["r_factor_gnss_e"/"_n"]``; clamped to ``[fafkf] r_min_factor`` = 1
    from below, so a factor on that floor means residuals no larger than their theory),
    as shipped and in the seed's plain configuration (``[fkf] gnss_velocity = false,
    gnss_err_pdop = inf`` (one regime), ``gnss_err_dist_m = 0, gnss_err_sd_m = 1,
    gnss_err_tau_s = 60``: one time-only 1-m error state).
(e) mean squared error (m^2) of fkf and fafkf, shipped and plain, forward and RTS, with the
    oracle of each.

Miss 3, comma2k19 (real, ``sample_logs/comma2k19``, 60 s, open-sky highway; the
reference is comma's own post-processed fusion): "fused below GNSS-only with the GNSS
latency estimated or applied".

(f) RMSE (m) vs the GNSS time offset ``[time] gnss_offset_s`` (s; ``t_true = t_logged +
    offset``) for GNSS-only and ekf, aekf, fkf, fafkf (forward solid, RTS dashed), with the
    README's 0.1 s and gpsdr's own estimate (``fuse(..., auto_gnss_offset=True)``, what
    ``gpsdr fuse --gnss-offset auto`` does) marked.
(g) the mean along-track and cross-track error (m) vs the offset: a time offset moves a
    track along its path by offset x speed; a lateral offset between the reference and the
    antenna does not depend on it.
(h) along-track and cross-track error (m) vs time (s) at 0.1 s for the GNSS fixes and
    ekf's forward track; the title splits the fixes' error into a slow part (3-s running
    mean) and the fast rest, which is all a filter can average away.

The printed table adds what the panels only summarise: per method the RMSE and oracle
RMSE forward and RTS, the NIS per PDOP regime (also for fkf/fafkf), the R-factor
quantiles, and on comma2k19 each method's best offset, along-track slope, gpsdr's auto
offsets, each track minus its own fixes (and ekf without the receiver velocity), and the
time offsets at which the receiver's speed and the CAN speed best match the reference's.

Units: metres in the local east/north frame of the first fix, seconds, PDOP unitless; along
track positive = ahead of the reference, cross track positive = right of its travel
(:func:`gpsdr_cli.evaluation.track_errors`).  Every figure is computed here from the runs;
nothing is typed in.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

# the seeds' plain models (GNSS positions only, white-noise R / one time-only error state)
# and the parameter builder: the accuracy benchmark's, so both tell of the same filters
from accuracy import AEKF_PLAIN, FKF_PLAIN, params_for

from gpsdr_cli import config
from gpsdr_cli.config import Params
from gpsdr_cli.evaluation import gnss_only_errors, reference_en, summarise, track_errors
from gpsdr_cli.pipeline import FuseResult, fuse
from gpsdr_cli.simulate import SimDrive, oracle_drive, oracle_params, simulate_drive

COMMA = ROOT / "sample_logs" / "comma2k19"
OUT_PNG = ROOT / "docs" / "accuracy_diagnostics.png"

#: method label -> (registered filter, config overrides, run the oracle too)
SIM_METHODS: dict[str, tuple[str, dict | None]] = {
    "ekf": ("ekf", None),
    "aekf": ("aekf", None),
    "ekf plain": ("ekf", AEKF_PLAIN),
    "aekf plain": ("aekf", AEKF_PLAIN),
    "fkf": ("fkf", None),
    "fafkf": ("fafkf", None),
    "fkf plain": ("fkf", FKF_PLAIN),
    "fafkf plain": ("fafkf", FKF_PLAIN),
}
NIS_METHODS = ("ekf", "aekf", "ekf plain", "aekf plain", "aekf oracle")
#: ... and the federated filters' GNSS local filter, reported in the table and panel (d)'s title
NIS_ALL = (*NIS_METHODS, "fkf", "fafkf", "fkf plain", "fafkf plain")
RFACTOR_METHODS = ("fafkf", "fafkf plain")
#: PDOP band edges for the NIS panel (the urban simulator's PDOP is 1.4-9, median ~3.7)
PDOP_EDGES = (1.0, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0, math.inf)
COMMA_FILTERS = ("ekf", "aekf", "fkf", "fafkf")
#: comma2k19 offset grid (s): 0.05-0.20 by 0.01, 5 ms steps around the minima
COMMA_OFFSETS = tuple(sorted({round(x, 3) for x in np.arange(0.05, 0.2001, 0.01)}
                             | {0.095, 0.105, 0.115, 0.125, 0.135}))
README_OFFSET_S = 0.1


def mode_label(method: str, smooth: bool) -> str:
    return method + (" + RTS" if smooth else "")


# --------------------------------------------------------------------------- miss 1 and 2

@dataclass
class SimStudy:
    """Everything the simulated panels need.

    ``runs``: one row per (seed, method, smooth, oracle) with mse_m2 and rmse_m (m);
    ``series``: the first seed's per-epoch t_s, err_m per forward method, pdop, outage;
    ``nis``: method -> (pdop, nis) at the GNSS updates of the forward runs, all seeds;
    ``r_factors``: method -> R factors (east and north pooled) at the accepted fixes;
    ``gnss_rmse_m``: GNSS-only RMSE per seed.
    """

    runs: pd.DataFrame
    series: dict[str, np.ndarray]
    nis: dict[str, tuple[np.ndarray, np.ndarray]]
    r_factors: dict[str, np.ndarray]
    gnss_rmse_m: dict[int, float] = field(default_factory=dict)


def sim_reference(sim: SimDrive, res: FuseResult) -> pd.DataFrame:
    return reference_en(sim.truth[["t_ns", "lat", "lon"]], res.frame)


def run_oracle(sim: SimDrive, name: str, p: Params) -> FuseResult:
    """The same filter told the true noise; filters that carry the multipath as states get the
    fixes' white sigma only (their states take the multipath), the others white + multipath."""
    po = oracle_params(sim.noise, p)
    states = name in ("fkf", "fafkf") or bool(po["aekf"]["gnss_err_states"])
    return fuse(oracle_drive(sim, multipath_in_sigma=not states), po)


def sim_study(seeds: list[int], scenario: str = "urban_canyon", duration_s: float | None = None,
              methods: dict[str, tuple[str, dict | None]] | None = None, oracle: bool = True,
              smooth_modes: tuple[bool, ...] = (False, True), log=print) -> SimStudy:
    """Run every method (forward and RTS, and its oracle) on each seed of ``scenario``."""
    methods = SIM_METHODS if methods is None else methods
    rows: list[dict] = []
    series: dict[str, np.ndarray] = {}
    nis: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    rfac: dict[str, list[np.ndarray]] = {}
    gnss: dict[int, float] = {}
    for seed in seeds:
        t0 = time.perf_counter()
        sim = simulate_drive(scenario, seed=seed, duration_s=duration_s)
        ref = None
        for method, (name, overrides) in methods.items():
            for smooth in smooth_modes:
                p = params_for(name, smooth, overrides)
                res = fuse(sim.drive, p)
                if ref is None:
                    ref = sim_reference(sim, res)
                    gnss[seed] = summarise(gnss_only_errors(res.epochs, ref))["rmse_m"]
                err = track_errors(res.track, ref)["err_m"].to_numpy()
                ok = np.isfinite(err)
                mse = float(np.mean(err[ok] ** 2))
                rows.append({"seed": seed, "method": method, "smooth": smooth, "oracle": False,
                             "mse_m2": mse, "rmse_m": math.sqrt(mse)})
                if not smooth:
                    _collect_forward(seed == seeds[0], method, res, err, series, nis, rfac)
                if oracle:
                    ores = run_oracle(sim, name, p)
                    if not smooth and method == "aekf":  # the NIS a right R gives, for panel (c)
                        _collect_forward(False, "aekf oracle", ores, err, series, nis, rfac)
                    oerr = track_errors(ores.track, ref)["err_m"].to_numpy()
                    omse = float(np.nanmean(oerr ** 2))
                    rows.append({"seed": seed, "method": method, "smooth": smooth, "oracle": True,
                                 "mse_m2": omse, "rmse_m": math.sqrt(omse)})
        log(f"# {scenario} seed {seed}: {len(methods) * len(smooth_modes) * (2 if oracle else 1)} "
            f"runs in {time.perf_counter() - t0:.1f} s")
    return SimStudy(
        runs=pd.DataFrame(rows), series=series,
        nis={k: (np.concatenate([a for a, _ in v]), np.concatenate([b for _, b in v]))
             for k, v in nis.items()},
        r_factors={k: np.concatenate(v) for k, v in rfac.items()}, gnss_rmse_m=gnss)


def _collect_forward(first_seed: bool, method: str, res: FuseResult, err: np.ndarray,
                     series: dict, nis: dict, rfac: dict) -> None:
    """Keep what the panels need from a forward run: the error series (first seed), the NIS
    with the PDOP of its fix, the fuzzy R factors at the accepted fixes."""
    track = res.track
    if first_seed:
        t_ns = track["time"].astype("int64").to_numpy()
        series.setdefault("t_s", (t_ns - t_ns[0]) / 1e9)
        series.setdefault("pdop", track["pdop"].to_numpy(float))
        series.setdefault("outage", track["gnss_outage"].to_numpy(bool))
        series[method] = err
    r = res.result
    if method in NIS_ALL:
        v = np.asarray(r.nis, float)
        pdop = track["pdop"].to_numpy(float)
        ok = np.isfinite(v) & np.isfinite(pdop)
        nis.setdefault(method, []).append((pdop[ok], v[ok]))
    if method in RFACTOR_METHODS and "r_factor_gnss_e" in r.extras:
        used = np.asarray(r.gnss_used, bool)
        rfac.setdefault(method, []).append(np.concatenate(
            [np.asarray(r.extras["r_factor_gnss_e"])[used], np.asarray(r.extras["r_factor_gnss_n"])[used]]))


def at_floor(r_factor: np.ndarray, floor: float) -> float:
    """Share of R factors on their lower clamp ``[fafkf] r_min_factor`` (to 1e-6): there the
    residuals were no larger than their theory and the controller could not lower R."""
    return float(np.mean(np.asarray(r_factor, float) <= floor * (1 + 1e-6)))


def pooled(runs: pd.DataFrame) -> pd.DataFrame:
    """Per (method, smooth, oracle): MSE as the mean over seeds, RMSE as its root (m)."""
    g = runs.groupby(["method", "smooth", "oracle"], sort=False)["mse_m2"].mean().reset_index()
    g["rmse_m"] = np.sqrt(g["mse_m2"])
    return g


def pooled_value(pool: pd.DataFrame, method: str, smooth: bool, oracle: bool = False,
                 col: str = "rmse_m") -> float:
    sel = pool[(pool["method"] == method) & (pool["smooth"] == smooth) & (pool["oracle"] == oracle)]
    return float(sel[col].iloc[0]) if len(sel) else math.nan


def nis_gate(params: Params) -> float:
    """The GNSS gate's chi-square(2) bound (``[gnss] gate_prob``: 18.4 at 0.9999)."""
    from gpsdr_cli.filters.adaptive import gate_threshold

    return float(gate_threshold(params["gnss"]["gate_prob"]))


def nis_by_pdop(pdop: np.ndarray, nis: np.ndarray, gate: float, edges: tuple[float, ...] = PDOP_EDGES,
                min_count: int = 20) -> pd.DataFrame:
    """NIS per PDOP band [lo, hi): columns pdop_lo, pdop_hi, pdop_mid (median PDOP in the
    band), count, mean_nis (every update), mean_nis_gated (updates with NIS <= ``gate``:
    expected ~2 when R and P are right; the simulator's 10-40 m outlier jumps lift the plain
    mean of even the oracle to ~3.4), above_gate (share of updates above it), share_in_95
    (NIS <= 5.991, expected 0.95).  Bands with fewer than ``min_count`` updates are left out."""
    pdop = np.asarray(pdop, float)
    nis = np.asarray(nis, float)
    out = []
    for lo, hi in itertools.pairwise(edges):
        m = (pdop >= lo) & (pdop < hi) & np.isfinite(nis)
        if m.sum() < min_count:
            continue
        x = nis[m]
        out.append({"pdop_lo": lo, "pdop_hi": hi, "pdop_mid": float(np.median(pdop[m])),
                    "count": int(m.sum()), "mean_nis": float(np.mean(x)),
                    "mean_nis_gated": float(np.mean(x[x <= gate])) if (x <= gate).any() else math.nan,
                    "above_gate": float(np.mean(x > gate)),
                    "share_in_95": float(np.mean(x <= 5.991464547107979))})
    return pd.DataFrame(out)


def pdop_regime_nis(pdop: np.ndarray, nis: np.ndarray, good: float, poor: float, gate: float = math.inf
                    ) -> dict[str, float]:
    """Mean NIS (of the updates with NIS <= ``gate``) in aekf's three PDOP regimes
    (good < ``good`` <= medium < ``poor`` <= poor)."""
    tab = nis_by_pdop(pdop, nis, gate, (0.0, good, poor, math.inf), min_count=1)
    got = dict(zip(tab["pdop_lo"], tab["mean_nis_gated"], strict=True))
    return {k: float(got.get(lo, math.nan)) for k, lo in (("good", 0.0), ("medium", good), ("poor", poor))}


# --------------------------------------------------------------------------- miss 3

def load_comma(folder: Path | None = None):
    """comma2k19: the Drive (fixes, gyro, CAN speed) and the reference."""
    from gpsdr_cli.io.csv import read_gyro_csv, read_odo_csv
    from gpsdr_cli.io.nmea import read_nmea
    from gpsdr_cli.io.reference import read_reference

    folder = folder or COMMA
    p0 = config.defaults()
    drive = read_nmea(folder / "gps.nmea")
    drive.merge(read_gyro_csv(folder / "gyro.csv", p0["gyro"]))
    drive.merge(read_odo_csv(folder / "odo.csv", p0["odo"]))
    return drive, read_reference(folder / "truth.csv")


def along_cross(track: pd.DataFrame, ref: pd.DataFrame, gnss: bool = False) -> pd.DataFrame:
    """Along-/cross-track errors (m) of a track, or of its GNSS fixes (``gnss``): t_ns,
    along_m, cross_m, err_m; NaN-free."""
    if gnss:
        has = np.isfinite(track["gnss_e"].to_numpy(float))
        track = track.loc[has, ["time", "gnss_e", "gnss_n"]].rename(columns={"gnss_e": "e", "gnss_n": "n"})
    te = track_errors(track, ref)
    return te.loc[np.isfinite(te["err_m"]), ["t_ns", "along_m", "cross_m", "err_m"]].reset_index(drop=True)


def _row(offset: float, method: str, ac: pd.DataFrame) -> dict:
    a, c, d = (ac[k].to_numpy() for k in ("along_m", "cross_m", "err_m"))
    return {"offset_s": offset, "method": method, "rmse_m": float(np.sqrt(np.mean(d * d))),
            "along_mean_m": float(a.mean()), "along_sd_m": float(a.std()),
            "cross_mean_m": float(c.mean()), "cross_sd_m": float(c.std())}


def offset_sweep(drive, reference, offsets: tuple[float, ...] = COMMA_OFFSETS,
                 names: tuple[str, ...] = COMMA_FILTERS, smooth_modes: tuple[bool, ...] = (False, True)
                 ) -> pd.DataFrame:
    """RMSE and mean along/cross-track error (m) of GNSS-only and each filter per GNSS offset (s).

    One row per (offset_s, method); method ``GNSS only`` are the fixes themselves at that
    offset, ``<filter>`` / ``<filter> + RTS`` the fused tracks (error over every epoch)."""
    rows = []
    for off in offsets:
        for name in names:
            for smooth in smooth_modes:
                p = params_for(name, smooth)
                p["time"]["gnss_offset_s"] = float(off)
                res = fuse(drive, p, reference)
                if not any(r["offset_s"] == off and r["method"] == "GNSS only" for r in rows):
                    rows.append(_row(off, "GNSS only", along_cross(res.track, res.reference_en, gnss=True)))
                rows.append(_row(off, mode_label(name, smooth), along_cross(res.track, res.reference_en)))
    return pd.DataFrame(rows)


def best_offset(sweep: pd.DataFrame, method: str) -> tuple[float, float]:
    """(offset s, RMSE m) at the minimum of ``method``'s RMSE curve: the vertex of the
    parabola through the grid minimum and its two neighbours (the grid point at an edge)."""
    s = sweep[sweep["method"] == method].sort_values("offset_s")
    x, y = s["offset_s"].to_numpy(float), s["rmse_m"].to_numpy(float)
    k = int(np.argmin(y))
    if k == 0 or k == len(x) - 1:
        return float(x[k]), float(y[k])
    a, b, c = np.polyfit(x[k - 1:k + 2], y[k - 1:k + 2], 2)
    if a <= 0:
        return float(x[k]), float(y[k])
    xv = -b / (2 * a)
    return float(xv), float(np.polyval([a, b, c], xv))


def along_zero(sweep: pd.DataFrame, method: str) -> float:
    """Offset (s) where ``method``'s mean along-track error crosses zero (linear between grid
    points; NaN when it does not cross)."""
    s = sweep[sweep["method"] == method].sort_values("offset_s")
    x, y = s["offset_s"].to_numpy(float), s["along_mean_m"].to_numpy(float)
    for i in range(len(x) - 1):
        if y[i] == 0.0:
            return float(x[i])
        if y[i] * y[i + 1] < 0:
            return float(x[i] + (x[i + 1] - x[i]) * y[i] / (y[i] - y[i + 1]))
    return math.nan


def along_slope(sweep: pd.DataFrame, method: str) -> float:
    """d(mean along-track error)/d(offset) (m/s) by least squares over the grid: for a pure
    time offset this is minus the mean speed."""
    s = sweep[sweep["method"] == method]
    return float(np.polyfit(s["offset_s"].to_numpy(float), s["along_mean_m"].to_numpy(float), 1)[0])


def auto_offsets(drive, reference, names: tuple[str, ...] = COMMA_FILTERS) -> pd.DataFrame:
    """gpsdr's own offset estimate per filter (``--gnss-offset auto``) and the forward RMSE at it."""
    rows = []
    for name in names:
        res = fuse(drive, params_for(name, False), reference, auto_gnss_offset=True)
        gnss = summarise(gnss_only_errors(res.epochs, res.reference_en))["rmse_m"]
        rows.append({"filter": name, "offset_s": res.gnss_offset_s, "rmse_m": res.summary()["rmse_m"],
                     "gnss_rmse_m": gnss, "note": res.gnss_offset_note})
    return pd.DataFrame(rows)


def comma_series(drive, reference, offset_s: float = README_OFFSET_S, name: str = "ekf"
                 ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Along/cross-track error series (m) at ``offset_s``: the GNSS fixes and ``name``'s forward track."""
    p = params_for(name, False)
    p["time"]["gnss_offset_s"] = offset_s
    res = fuse(drive, p, reference)
    return along_cross(res.track, res.reference_en, gnss=True), along_cross(res.track, res.reference_en)


def slow_fast(ac: pd.DataFrame, window_s: float = 3.0) -> dict[str, float]:
    """Split along- and cross-track errors (m) into a slow part (centred ``window_s`` running
    mean) and the fast rest; RMS of each, and the along-track drift (m/s, least squares
    over time).  White noise is what a filter averages away; a slow error it cannot tell
    from the truth when the fixes are the only absolute position."""
    t = pd.to_datetime(ac["t_ns"].to_numpy(np.int64), unit="ns")
    out: dict[str, float] = {}
    for col in ("along_m", "cross_m"):
        x = pd.Series(ac[col].to_numpy(float), index=t)
        slow = x.rolling(pd.Timedelta(seconds=window_s), center=True, min_periods=3).mean()
        fast = (x - slow).to_numpy()
        key = col[:-2]
        out[f"{key}_slow_rms_m"] = float(np.sqrt(np.nanmean(slow.to_numpy() ** 2)))
        out[f"{key}_fast_rms_m"] = float(np.sqrt(np.nanmean(fast ** 2)))
    ts = (ac["t_ns"].to_numpy(np.int64) - int(ac["t_ns"].iloc[0])) / 1e9
    out["along_drift_mps"] = float(np.polyfit(ts, ac["along_m"].to_numpy(float), 1)[0])
    out["span_s"] = float(ts[-1])
    return out


def fused_minus_fixes(drive, reference, offset_s: float, name: str = "ekf", smooth: bool = False,
                      overrides: dict | None = None) -> dict[str, float]:
    """Mean along-/cross-track position of ``name``'s track minus the fixes at the fix epochs
    (m; < 0 along: the track sits behind its own fixes), and the track's RMSE (m)."""
    p = params_for(name, smooth, overrides)
    p["time"]["gnss_offset_s"] = offset_s
    res = fuse(drive, p, reference)
    g = along_cross(res.track, res.reference_en, gnss=True)
    f = along_cross(res.track, res.reference_en).set_index("t_ns").reindex(g["t_ns"])
    return {"along_m": float(np.nanmean(f["along_m"].to_numpy() - g["along_m"].to_numpy())),
            "cross_m": float(np.nanmean(f["cross_m"].to_numpy() - g["cross_m"].to_numpy())),
            "corr_along": float(pd.Series(f["along_m"].to_numpy()).corr(g["along_m"].reset_index(drop=True))),
            "rmse_m": res.summary()["rmse_m"]}


def speed_offset(t_ns: np.ndarray, speed_mps: np.ndarray, ref_en: pd.DataFrame,
                 grid_s: np.ndarray | None = None) -> tuple[float, float, float]:
    """Time offset (s, ``t_true = t_logged + offset``) at which a speed log best matches the
    reference's speed (its positions differentiated), after a least-squares scale: grid
    search over ``grid_s`` (default -0.3..0.3 s by 5 ms).  Returns (offset s, scale, RMS m/s)."""
    grid_s = np.arange(-0.3, 0.3001, 0.005) if grid_s is None else grid_s
    tr = ref_en["t_ns"].to_numpy(np.int64) / 1e9
    vr = np.hypot(np.gradient(ref_en["e"].to_numpy(float), tr), np.gradient(ref_en["n"].to_numpy(float), tr))
    t = np.asarray(t_ns, np.int64) / 1e9
    v = np.asarray(speed_mps, float)
    ok = np.isfinite(v) & (t > tr[0] + 1.0) & (t < tr[-1] - 1.0)
    best = (math.inf, math.nan, math.nan)
    for lag in grid_s:
        vv = np.interp(t[ok] + lag, tr, vr)
        k = float(np.sum(vv * v[ok]) / np.sum(v[ok] ** 2))
        rms = float(np.sqrt(np.mean((k * v[ok] - vv) ** 2)))
        if rms < best[0]:
            best = (rms, float(lag), k)
    return best[1], best[2], best[0]


def speed_offsets(drive, reference) -> pd.DataFrame:
    """:func:`speed_offset` of the receiver's speed (RMC) and the odometer (CAN) against the
    reference: whether the velocity inputs share the fixes' time offset."""
    from gpsdr_cli.pipeline import choose_frame

    ref_en = reference_en(reference, choose_frame(drive, config.defaults()))
    rows = []
    for label, stream, col in (("GNSS speed (RMC)", drive.gnss, "speed_mps"),
                               ("odometer (CAN speed)", drive.odo, "speed_mps")):
        if stream is None:
            continue
        off, k, rms = speed_offset(stream.t_ns, getattr(stream, col), ref_en)
        rows.append({"source": label, "offset_s": off, "scale": k, "rms_mps": rms})
    return pd.DataFrame(rows)


def lag_checks(drive, reference, offset_s: float) -> pd.DataFrame:
    """Where the forward filters' along-track shift comes from: fused minus fixes at
    ``offset_s`` for ekf and fkf, forward and RTS, and ekf forward without the receiver velocity."""
    rows = []
    for label, name, smooth, ov in (("ekf", "ekf", False, None), ("ekf + RTS", "ekf", True, None),
                                    ("fkf", "fkf", False, None), ("fkf + RTS", "fkf", True, None),
                                    ("ekf, [aekf] gnss_velocity = false", "ekf", False,
                                     {"aekf": {"gnss_velocity": False}})):
        rows.append({"run": label, **fused_minus_fixes(drive, reference, offset_s, name, smooth, ov)})
    return pd.DataFrame(rows)


@dataclass
class CommaStudy:
    """The comma2k19 panels' data: the offset sweep, gpsdr's own estimates, the error series
    at the README's offset (fixes and ekf forward), and the lag checks at the fixes' best offset."""

    sweep: pd.DataFrame
    autos: pd.DataFrame
    gnss_series: pd.DataFrame
    fused_series: pd.DataFrame
    lags: pd.DataFrame
    lag_offset_s: float
    speeds: pd.DataFrame = field(default_factory=pd.DataFrame)
    series_filter: str = "ekf"


def comma_study(drive, reference, offsets: tuple[float, ...] = COMMA_OFFSETS,
                names: tuple[str, ...] = COMMA_FILTERS, log=print) -> CommaStudy:
    """Everything panels (f)-(h) need from comma2k19."""
    t0 = time.perf_counter()
    sweep = offset_sweep(drive, reference, offsets, names)
    autos = auto_offsets(drive, reference, names)
    gs, fs = comma_series(drive, reference)
    best = round(best_offset(sweep, "GNSS only")[0], 3)
    lags = lag_checks(drive, reference, best)
    log(f"# comma2k19: {len(sweep)} sweep rows, auto offsets, lag checks in {time.perf_counter() - t0:.1f} s")
    return CommaStudy(sweep, autos, gs, fs, lags, best, speed_offsets(drive, reference))


# --------------------------------------------------------------------------- figure

COLOURS = {"GNSS only": "0.45", "ekf": "tab:blue", "aekf": "tab:orange", "fkf": "tab:green",
           "fafkf": "tab:red"}
TITLE = {"fontsize": 8.5, "loc": "left"}


def _colour(method: str) -> str:
    return COLOURS.get(method.replace(" + RTS", "").replace(" plain", "").replace(" oracle", ""), "k")


def _bars(ax, pool: pd.DataFrame, methods: list[str], col: str, unit: str) -> None:
    """Grouped bars: per method forward and RTS, each beside its oracle (hatched)."""
    from matplotlib.patches import Patch

    x = np.arange(len(methods))
    w = 0.2
    for j, (smooth, oracle) in enumerate(((False, False), (False, True), (True, False), (True, True))):
        vals = [pooled_value(pool, m, smooth, oracle, col) for m in methods]
        bars = ax.bar(x + (j - 1.5) * w, vals, w, color=[_colour(m) for m in methods],
                      alpha=0.5 if smooth else 0.95, hatch="//" if oracle else None,
                      edgecolor="k", linewidth=0.4)
        for b, v in zip(bars, vals, strict=True):
            if np.isfinite(v):
                ax.text(b.get_x() + b.get_width() / 2, v, f" {v:.2f}", ha="center", va="bottom",
                        fontsize=6.5, rotation=90)
    ax.set_xticks(x, methods, fontsize=8)
    ax.set_ylabel(unit)
    ax.legend(handles=[Patch(facecolor="0.3", edgecolor="k", label="forward"),
                       Patch(facecolor="0.3", alpha=0.5, edgecolor="k", label="RTS"),
                       Patch(facecolor="white", edgecolor="k", hatch="//", label="its oracle")],
              fontsize=7, loc="upper left")
    ymax = np.nanmax(pool[pool["method"].isin(methods)][col].to_numpy(float))
    ax.set_ylim(0, ymax * 1.25)


def _pct(a: float, b: float) -> str:
    """a relative to b as '-4 %' / '+3 %'."""
    return f"{round(100 * (a / b - 1)):+d} %"


def make_figure(study: SimStudy, comma: CommaStudy, params: Params):
    """The eight panels (module docstring); titles state each finding with its numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pool = pooled(study.runs)
    g = params["gnss"]
    good, poor = float(g["pdop_good"]), float(g["pdop_poor"])
    gate = nis_gate(params)
    seeds = sorted(study.runs["seed"].unique().tolist())
    seed_txt = f"seeds {','.join(map(str, seeds))}"
    sweep = comma.sweep
    fig = plt.figure(figsize=(12, 14), dpi=110, layout="constrained")
    outer = fig.add_gridspec(4, 2)

    # (a) urban error vs time, PDOP beneath
    sub = outer[0, 0].subgridspec(2, 1, height_ratios=(3, 1), hspace=0.0)
    ax = fig.add_subplot(sub[0])
    axp = fig.add_subplot(sub[1], sharex=ax)
    t = study.series["t_s"]
    step = max(1, int(len(t) / 3000))
    shown = [m for m in ("ekf plain", "aekf plain", "ekf", "aekf") if m in study.series]
    for m in shown:
        rm = float(np.sqrt(np.nanmean(study.series[m] ** 2)))
        ax.plot(t[::step], study.series[m][::step], lw=0.6 if "plain" in m else 1.0, color=_colour(m),
                alpha=0.4 if "plain" in m else 0.95, label=f"{m} (RMSE {rm:.2f} m)")
    ax.set_ylabel("horizontal error (m)")
    ax.set_ylim(0, np.nanpercentile(np.concatenate([study.series[m] for m in shown]), 99.7) * 1.1)
    ax.legend(fontsize=7, ncol=2, loc="upper right")
    e_f, a_f = pooled_value(pool, "ekf", False), pooled_value(pool, "aekf", False)
    e_p, a_p = pooled_value(pool, "ekf plain", False), pooled_value(pool, "aekf plain", False)
    ax.set_title(f"(a) Urban canyon (seed {seeds[0]} shown): aekf vs ekf RMSE {_pct(a_f, e_f)} with\n"
                 f"the multipath states, {_pct(a_p, e_p)} without them ({seed_txt}, forward; "
                 "target -30 %)", **TITLE)
    plt.setp(ax.get_xticklabels(), visible=False)
    axp.plot(t[::step], study.series["pdop"][::step], color="0.3", lw=0.7)
    axp.fill_between(t, 0, 1, where=study.series["outage"], transform=axp.get_xaxis_transform(),
                     color="tab:red", alpha=0.2, lw=0, label="GNSS outage")
    for k, thr in enumerate((good, poor)):
        axp.axhline(thr, color="tab:orange", ls=":", lw=0.9,
                    label=(f"aekf regimes: R x k^2, k = 1 | 3 | 10 at PDOP {good:g} | {poor:g}"
                           if k == 0 else None))
    axp.set_ylabel("PDOP")
    axp.set_xlabel("time since start (s)")
    axp.legend(fontsize=6.5, loc="upper left", ncol=2)

    # (b) ekf/aekf RMSE with oracles
    ax = fig.add_subplot(outer[0, 1])
    _bars(ax, pool, ["ekf", "aekf", "ekf plain", "aekf plain"], "rmse_m", "RMSE (m)")
    r = {m: pooled_value(pool, m, False) / pooled_value(pool, m, False, True)
         for m in ("ekf", "aekf", "ekf plain", "aekf plain")}
    ax.set_title(f"(b) Urban canyon, {seed_txt}: every variant is within {100 * (max(r.values()) - 1):.0f} % "
                 "of its own oracle\n(forward; RMSE / oracle: "
                 + ", ".join(f"{m} {v:.2f}" for m, v in r.items())
                 + "):\nno error is left for aekf's adaptation to remove, with or without the states",
                 **TITLE)

    # (c) NIS per PDOP band
    ax = fig.add_subplot(outer[1, 0])
    regimes = {}
    for m in NIS_METHODS:
        if m not in study.nis:
            continue
        pd_, nis = study.nis[m]
        tab = nis_by_pdop(pd_, nis, gate)
        regimes[m] = pdop_regime_nis(pd_, nis, good, poor, gate)
        style = ":" if "oracle" in m else ("--" if "plain" in m else "-")
        ax.plot(tab["pdop_mid"], tab["mean_nis_gated"], style, marker="s" if "plain" in m else "o",
                color="k" if "oracle" in m else _colour(m), ms=3.5, lw=1.2, label=m)
    ax.axhline(2.0, color="k", lw=0.8, label="expected 2")
    for thr in (good, poor):
        ax.axvline(thr, color="tab:orange", ls=":", lw=0.9)
    ax.set_yscale("log")
    ax.set_xlabel("PDOP of the fix (aekf's regime bounds dotted)")
    ax.set_ylabel(f"mean NIS of the GNSS updates <= gate {gate:.1f}")
    ax.legend(fontsize=7, loc="lower left")
    fmt = {m: " / ".join(f"{v:.2f}" for v in regimes[m].values()) for m in regimes}
    ax.set_title(f"(c) GNSS innovations, {seed_txt}, forward: mean NIS (2 dof) in the good / medium /\n"
                 f"poor PDOP regimes: oracle {fmt.get('aekf oracle', '-')}, "
                 f"ekf (one R) {fmt.get('ekf', '-')}, "
                 f"aekf (R x k^2)\n{fmt.get('aekf', '-')}: the receiver sigma already grows with PDOP; "
                 "aekf's k scales it twice", **TITLE)

    # (d) fuzzy R factors
    ax = fig.add_subplot(outer[1, 1])
    for m, ls in (("fafkf", "-"), ("fafkf plain", "--")):
        if m not in study.r_factors:
            continue
        rr = np.sort(study.r_factors[m])
        ax.plot(rr, np.arange(1, len(rr) + 1) / len(rr), ls, color=_colour(m), label=m)
    ax.set_xscale("log")
    ax.set_xlabel("fafkf R factor at the accepted fixes (R / nominal R; east and north)")
    ax.set_ylabel("cumulative share of fixes")
    floor = float(params["fafkf"]["r_min_factor"])
    ax.axvline(floor, color="k", lw=0.8, label=f"floor [fafkf] r_min_factor = {floor:g}")
    ax.legend(fontsize=7, loc="lower right")

    def nis_range(m: str) -> str:
        if m not in study.nis:
            return "-"
        v = pdop_regime_nis(*study.nis[m], good, poor, gate).values()
        return f"{min(v):.1f}-{max(v):.1f}"

    shares = {m: at_floor(study.r_factors[m], floor) for m in study.r_factors}
    q = {m: np.percentile(study.r_factors[m], [50, 90]) for m in study.r_factors}
    qs = {m: f"median {v[0]:.2f}, p90 {v[1]:.2f}" for m, v in q.items()}
    ax.set_title(f"(d) fafkf's covariance matching, {seed_txt}. Shipped: fkf's GNSS NIS {nis_range('fkf')} "
                 f"(< 2),\n{shares.get('fafkf', math.nan):.0%} of the R factors on the floor "
                 f"({qs.get('fafkf', '-')}): nothing to raise.\nPlain: fkf's NIS {nis_range('fkf plain')}; "
                 f"fafkf raises R ({qs.get('fafkf plain', '-')}) and gets NIS "
                 f"{nis_range('fafkf plain')}", **TITLE)

    # (e) fkf / fafkf MSE
    ax = fig.add_subplot(outer[2, 0])
    _bars(ax, pool, ["fkf", "fafkf", "fkf plain", "fafkf plain"], "mse_m2", "mean squared error (m$^2$)")
    f_s, fa_s = (pooled_value(pool, m, False, col="mse_m2") for m in ("fkf", "fafkf"))
    f_p, fa_p = (pooled_value(pool, m, False, col="mse_m2") for m in ("fkf plain", "fafkf plain"))
    fo_s = pooled_value(pool, "fkf", False, True, "mse_m2")
    fo_p = pooled_value(pool, "fkf plain", False, True, "mse_m2")
    ax.set_title(f"(e) Urban canyon, {seed_txt}, forward: fafkf vs fkf error variance {_pct(fa_s, f_s)} "
                 f"shipped,\n{_pct(fa_p, f_p)} plain (target -50 %). fkf's own oracle: "
                 f"{_pct(fo_s, f_s)} / {_pct(fo_p, f_p)}\nagainst fkf: the most any noise adaptation "
                 "could win", **TITLE)

    # (f) comma RMSE vs offset
    ax = fig.add_subplot(outer[2, 1])
    for m in ["GNSS only"] + [mode_label(n, s) for n in COMMA_FILTERS for s in (False, True)]:
        s = sweep[sweep["method"] == m].sort_values("offset_s")
        if len(s):
            ax.plot(s["offset_s"], s["rmse_m"], "--" if "RTS" in m else "-", color=_colour(m),
                    lw=2.2 if m == "GNSS only" else 1.1, label=m)
    ax.axvline(README_OFFSET_S, color="k", lw=0.8, ls=":")
    ax.text(README_OFFSET_S, 0.02, " README 0.1 s", transform=ax.get_xaxis_transform(), fontsize=7)
    for _, row in comma.autos.iterrows():
        ax.plot(row["offset_s"], row["rmse_m"], "v", color=_colour(row["filter"]), ms=7, mec="k", mew=0.5)
    ax.plot([], [], "v", color="0.6", mec="k", label="--gnss-offset auto (fwd)")
    g_off, g_min = best_offset(sweep, "GNSS only")
    e_off, e_min = best_offset(sweep, "ekf")
    f_off, f_min = best_offset(sweep, "fkf")
    fr_off, fr_min = best_offset(sweep, "fkf + RTS")
    ax.set_xlabel("GNSS time offset [time] gnss_offset_s (s)")
    ax.set_ylabel("RMSE vs comma's reference (m)")
    ax.set_ylim(0.3, 1.45)
    ax.legend(fontsize=6.5, ncol=3, loc="upper center")
    ax.set_title(f"(f) comma2k19: RMSE minimum of GNSS-only {g_min:.3f} m at {g_off:.3f} s; forward\n"
                 f"ekf {e_min:.3f} m at {e_off:.3f} s, fkf {f_min:.3f} m at {f_off:.3f} s; fkf RTS "
                 f"{fr_min:.3f} m at {fr_off:.3f} s\n(aekf = ekf, fafkf = fkf to the mm)", **TITLE)

    # (g) along/cross mean vs offset
    ax = fig.add_subplot(outer[3, 0])
    for m in ("GNSS only", "ekf", "ekf + RTS", "fkf", "fkf + RTS"):
        s = sweep[sweep["method"] == m].sort_values("offset_s")
        ls = "--" if "RTS" in m else "-"
        ax.plot(s["offset_s"], s["along_mean_m"], ls, color=_colour(m), lw=2.2 if m == "GNSS only" else 1.1,
                label=m)
        ax.plot(s["offset_s"], s["cross_mean_m"], ls, color=_colour(m), lw=0.8, alpha=0.7)
    ax.axhline(0, color="k", lw=0.6)
    cross = sweep["cross_mean_m"].to_numpy(float)
    ax.text(0.055, float(np.mean(cross)) - 0.05, "cross track (every track, every offset)", fontsize=7,
            va="top")
    ax.text(0.055, 0.6, "along track", fontsize=7)
    ax.set_xlabel("GNSS time offset (s)")
    ax.set_ylabel("mean error (m)\nalong: + ahead, cross: + right")
    ax.legend(fontsize=7, loc="upper right")
    z = {m: along_zero(sweep, m) for m in ("GNSS only", "ekf", "ekf + RTS", "fkf", "fkf + RTS")}
    lag = comma.lags.set_index("run")
    ax.set_title(f"(g) comma2k19: mean along-track error is 0 at {z['GNSS only']:.3f} s for the fixes, "
                 f"{z['ekf']:.3f} / {z['fkf']:.3f} s\nfor ekf / fkf forward (track - fixes: "
                 f"{lag.loc['ekf', 'along_m']:+.2f} / "
                 f"{lag.loc['fkf', 'along_m']:+.2f} m), {z['ekf + RTS']:.3f} / "
                 f"{z['fkf + RTS']:.3f} s RTS;\ncross track {cross.min():+.2f} to {cross.max():+.2f} m "
                 "whatever the offset", **TITLE)

    # (h) along/cross vs time at 0.1 s
    ax = fig.add_subplot(outer[3, 1])
    gs, fs = comma.gnss_series, comma.fused_series
    t0 = min(int(gs["t_ns"].iloc[0]), int(fs["t_ns"].iloc[0]))
    sf = comma.series_filter
    ax.plot((gs["t_ns"] - t0) / 1e9, gs["along_m"], ".", ms=2.5, color="0.35", label="GNSS along")
    ax.plot((gs["t_ns"] - t0) / 1e9, gs["cross_m"], ".", ms=2.5, color="0.7", label="GNSS cross")
    ax.plot((fs["t_ns"] - t0) / 1e9, fs["along_m"], lw=1.0, color=_colour(sf), label=f"{sf} along")
    ax.plot((fs["t_ns"] - t0) / 1e9, fs["cross_m"], lw=1.0, color="tab:purple", label=f"{sf} cross")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("time since start (s)")
    ax.set_ylabel("error vs comma's reference (m)")
    ax.legend(fontsize=7, ncol=2, loc="lower right")
    q = slow_fast(gs)
    ax.set_title(f"(h) comma2k19 at {README_OFFSET_S} s: the fixes' error is slow, not noise: sub-3-s part "
                 f"{q['along_fast_rms_m']:.3f} /\n{q['cross_fast_rms_m']:.3f} m RMS along / cross, slow part "
                 f"{q['along_slow_rms_m']:.2f} / {q['cross_slow_rms_m']:.2f} m; cross mean "
                 f"{gs['cross_m'].mean():+.2f} m, along drifts\n"
                 f"{q['along_drift_mps'] * 60:+.2f} m per minute; "
                 f"{sf} forward follows it (cross {fs['cross_m'].mean():+.2f} m)", **TITLE)
    return fig


# --------------------------------------------------------------------------- table

def report(study: SimStudy, comma: CommaStudy, params: Params) -> str:
    """The figures that carry each panel's finding, as text."""
    pool = pooled(study.runs)
    g = params["gnss"]
    sweep = comma.sweep
    gnss_rms = math.sqrt(np.mean([v * v for v in study.gnss_rmse_m.values()]))
    lines = [(f"## Miss 1 and 2: urban canyon, seeds {','.join(map(str, sorted(study.gnss_rmse_m)))} "
             f"(GNSS-only RMSE {gnss_rms:.2f} m)"), "",
             ("| method | fwd RMSE m | fwd oracle m | fwd / oracle | RTS RMSE m | RTS oracle m | "
              "RTS / oracle | fwd MSE m^2 | RTS MSE m^2 |"), "|---|---|---|---|---|---|---|---|---|"]
    for m in SIM_METHODS:
        v = [pooled_value(pool, m, s, o) for s in (False, True) for o in (False, True)]
        if not np.isfinite(v[0]):
            continue
        mse = [pooled_value(pool, m, s, False, "mse_m2") for s in (False, True)]
        lines.append(f"| {m} | {v[0]:.2f} | {v[1]:.2f} | {v[0] / v[1]:.2f} | {v[2]:.2f} | {v[3]:.2f} | "
                     f"{v[2] / v[3]:.2f} | {mse[0]:.2f} | {mse[1]:.2f} |")
    lines.append("")
    for a, b, col, what in (("aekf", "ekf", "rmse_m", "RMSE"), ("aekf plain", "ekf plain", "rmse_m", "RMSE"),
                            ("fafkf", "fkf", "mse_m2", "error variance"),
                            ("fafkf plain", "fkf plain", "mse_m2", "error variance")):
        parts = []
        for s in (False, True):
            base = pooled_value(pool, b, s, col=col)
            parts.append(f"{'RTS' if s else 'fwd'} {_pct(pooled_value(pool, a, s, col=col), base)} "
                         f"(oracle of {b}: {_pct(pooled_value(pool, b, s, True, col), base)})")
        lines.append(f"- {a} vs {b} ({what}): " + ", ".join(parts))
    gate = nis_gate(params)
    lines += ["", (f"NIS per PDOP regime (good < {g['pdop_good']} <= medium < {g['pdop_poor']} <= poor), "
                   f"forward: mean of the updates with NIS <= the gate {gate:.1f} (expected ~2) | "
                   "mean of all | share above the gate | share of the updates:")]
    edges = (0.0, float(g["pdop_good"]), float(g["pdop_poor"]), math.inf)
    for m in NIS_ALL:
        if m in study.nis:
            tab = nis_by_pdop(*study.nis[m], gate, edges, min_count=1)
            n_all = tab["count"].sum()
            lines.append(f"- {m}: " + " / ".join(f"{v:.2f}" for v in tab["mean_nis_gated"]) + " | "
                         + " / ".join(f"{v:.2f}" for v in tab["mean_nis"]) + " | "
                         + " / ".join(f"{v:.1%}" for v in tab["above_gate"]) + " | "
                         + " / ".join(f"{c / n_all:.0%}" for c in tab["count"]))
    lines.append("")
    floor = float(params["fafkf"]["r_min_factor"])
    for m, r in study.r_factors.items():
        q = np.percentile(r, [10, 50, 90])
        lines.append(f"- {m} R factor at the accepted fixes: p10 {q[0]:.2f}, median {q[1]:.2f}, "
                     f"p90 {q[2]:.2f}, at the floor r_min_factor = {floor:g}: {at_floor(r, floor):.0%}, "
                     f"> 1.5: {np.mean(r > 1.5):.0%} (n = {len(r)})")
    lines += ["", "## Miss 3: comma2k19", "",
              ("| method | best offset s | RMSE there m | RMSE at 0.1 s m | along-track zero s | "
               "d(along)/d(offset) m/s | cross mean m |"), "|---|---|---|---|---|---|---|"]
    for m in ["GNSS only"] + [mode_label(n, s) for n in COMMA_FILTERS for s in (False, True)]:
        s = sweep[sweep["method"] == m]
        if not len(s):
            continue
        bo, bm = best_offset(sweep, m)
        at = s[np.isclose(s["offset_s"], README_OFFSET_S)]["rmse_m"]
        lines.append(f"| {m} | {bo:.3f} | {bm:.3f} | {float(at.iloc[0]) if len(at) else math.nan:.3f} | "
                     f"{along_zero(sweep, m):.3f} | {along_slope(sweep, m):.1f} | "
                     f"{s['cross_mean_m'].mean():+.3f} |")
    lines += ["", "gpsdr --gnss-offset auto (forward):"]
    for _, r in comma.autos.iterrows():
        lines.append(f"- {r['filter']}: {r['offset_s']:.3f} s, RMSE {r['rmse_m']:.3f} m vs GNSS-only "
                     f"{r['gnss_rmse_m']:.3f} m at it ({r['note']})")
    lines += ["", f"Track minus its own fixes at the fixes' best offset {comma.lag_offset_s:.3f} s (m):"]
    for _, r in comma.lags.iterrows():
        lines.append(f"- {r['run']}: along {r['along_m']:+.3f}, cross {r['cross_m']:+.3f}, "
                     f"corr(track, fixes) along {r['corr_along']:.2f}, RMSE {r['rmse_m']:.3f}")
    for _, r in comma.speeds.iterrows():
        lines.append(f"- {r['source']} matches the reference's speed best at {r['offset_s']:+.3f} s "
                     f"(scale {r['scale']:.4f}, RMS {r['rms_mps']:.3f} m/s); the fixes' positions at "
                     f"{best_offset(sweep, 'GNSS only')[0]:+.3f} s")
    gs, fs = comma.gnss_series, comma.fused_series
    for label, ac in (("fixes", gs), (f"{comma.series_filter} forward", fs)):
        q = slow_fast(ac)
        lines.append(f"- at {README_OFFSET_S} s, {label}: along mean {ac['along_m'].mean():+.3f} (sd "
                     f"{ac['along_m'].std():.3f}), cross mean {ac['cross_m'].mean():+.3f} (sd "
                     f"{ac['cross_m'].std():.3f}); slow (3-s mean) / fast RMS along "
                     f"{q['along_slow_rms_m']:.3f} / {q['along_fast_rms_m']:.3f}, cross "
                     f"{q['cross_slow_rms_m']:.3f} / {q['cross_fast_rms_m']:.3f}; "
                     f"along drift {q['along_drift_mps'] * 60:+.2f} m/min")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1,2,3", help="urban canyon seeds (default 1,2,3)")
    ap.add_argument("--out", default=str(OUT_PNG), help="the PNG to write")
    ap.add_argument("--no-oracle", action="store_true", help="skip the oracle runs")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    study = sim_study(seeds, oracle=not args.no_oracle, log=log)
    drive, reference = load_comma()
    comma = comma_study(drive, reference, log=log)
    params = config.defaults()
    print(report(study, comma, params))
    fig = make_figure(study, comma, params)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(f"\nwrote {args.out} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
