"""Accuracy benchmark: every registered filter, forward and RTS-smoothed, on every
simulated scenario (fixed seeds 1, 2, 3, figures pooled) and on the real comma2k19 drive, next to GNSS alone
and the oracle (the same filter told the true noise: ``simulate.oracle_params`` and
``simulate.oracle_drive``), checked against issue #4's accuracy targets.

    # everything -> benchmarks/accuracy.md (~2.5 min, 2 vCPUs)
    .venv/bin/python benchmarks/accuracy.py
    .venv/bin/python benchmarks/accuracy.py --seeds 1       # one seed per scenario
    .venv/bin/python benchmarks/accuracy.py --quick         # 3-minute drives, no one_hour, no oracle
    .venv/bin/python benchmarks/accuracy.py --scenarios tunnels --filters ekf,aekf
    .venv/bin/python benchmarks/accuracy.py --no-paper      # without the seeds' plain baselines
    .venv/bin/python benchmarks/accuracy.py --scenarios urban_nlos,rtk,no_odometer --no-comma \
        --out /tmp/lying.md                                 # the receivers that lie (~15 min)

Smoothing modes: forward, ``+ RTS`` and ``+ graph`` (the robust batch smoother,
``[filter] smoother = "graph"``; ``--no-graph`` skips it; no oracle for it).  Scenario
``urban_nlos``: ``gpsdr simulate``'s canyon drive whose fixes carry NLOS steps of 10-80 m
lasting 5-60 s while HDOP and GST look good.

Figures per run: RMSE, CEP95, max horizontal error against the truth (m), and the
60-s-outage drift: the error at the end of each GNSS outage of 50-70 s as % of the
distance driven in it (mean over such outages; "-" when the drive has none).

Paper baselines (``--no-paper`` skips them).  Our ``ekf`` and ``fkf`` carry model
extensions the seeds' baselines do not have, so four more methods are run on
urban_canyon and one_hour (forward and RTS, no oracle), through config overrides only:

* ``ekf (seed 000 plain)``, ``aekf (seed 000 plain)``: filter ekf / aekf with
  ``[aekf] gnss_err_states = false, gnss_velocity = false`` (GNSS positions only,
  white-noise R; no multipath states);
* ``fkf (seed 002 plain)``, ``fafkf (seed 002 plain)``: filter fkf / fafkf with
  ``[fkf] gnss_velocity = false, gnss_err_pdop = inf`` (one regime), ``gnss_err_dist_m = 0,
  gnss_err_sd_m = 1, gnss_err_tau_s = 60, eps_gate = false`` (the seed's one time-only
  error state, never moved into the position) and
  ``[fafkf] remove_residual_mean = false`` (the paper's covariance matching).

comma2k19: the u-blox fixes sit ~0.1 s ahead of the reference.  Four runs of every
filter: ``[time] gnss_offset_s = 0.1`` (the README's calibration: the latency applied),
``auto`` (estimated by gpsdr itself: ``pipeline.fuse(..., auto_gnss_offset=True)``, what
``gpsdr fuse --gnss-offset auto`` does; each filter estimates its own offset), 0.135 s
(``latency.estimate_gnss_offset`` of the raw fixes against the reference, a cheat the
tool cannot do) and 0 (as logged).  Every comma2k19 row's GNSS-only figure is taken
from the fixes at the time shift that run applied (the ``gnss_e/gnss_n`` of its own track).

Targets (issue #4), two tables.  Issue scope, counted in the header ("N of M issue
targets pass", then one line per miss):

* every shipped filter's RMSE within 15 % of its oracle, on every simulated scenario;
* urban canyon: every shipped filter >= 40 % below GNSS-only RMSE;
* urban canyon: aekf >= 30 % below ekf (RMSE) and fafkf's error variance (mean squared
  error) >= 50 % below fkf's, each checked three ways with its own verdict (no combined
  one): (a) literal, shipped against shipped; (b) adaptation alone, as the seed measured
  it: plain adaptive against plain baseline; (c) the shipped adaptive filter against the
  seed's plain baseline;
* every shipped filter's 60-s outage ends within 2 % (forward) / 1 % (RTS) of the distance;
* comma2k19, per shipped filter and mode: fused RMSE below GNSS-only RMSE with the
  latency applied (0.1 s) OR estimated by gpsdr (auto); both figures in the row.

Real-data targets, on the scenarios whose receivers lie as real ones do (counted with the
others; ``real_data_targets``):

* urban_nlos (NLOS steps of 10-80 m in canyons, HDOP and GST looking good): every shipped
  filter, forward and RTS, <= 1.0 x the fixes' RMSE, the best <= 0.75 x.  Its oracle has the
  NLOS fixes taken out (it knows which they are) and the rest's true sigmas: a fair bound,
  not a reachable one, since it coasts through the steps on the dead reckoning.
* rtk (GGA 4 at 1-2.5 cm, float stretches, false fixes; no odometer): the track within
  0.05 m RMS of the RTK-fixed fixes linearly interpolated at its epochs (fixes <= 0.3 s apart;
  the false fixes left out, and shown with them), and the RMS reported sigma within 2 x of
  that deviation.  Its oracle keeps the false fixes with their jump in the true sigma.
* no_odometer (RTK-fixed fixes, gyro and forward accelerometer, 15-s outages while braking
  and accelerating): the end error of the 15-s outages (13-17 s from the last fix), median
  over the seeds' outages, <= 25 m forward, <= 10 m with the accelerometer (the forward track
  reads it, ``gpsdr_cli.filters.accel_speed``), <= 0.5 m smoothed.  Two dead-reckoning
  baselines run beside the filters (informational rows, ``hold_baselines``): the last fix's
  speed held with the gyro's heading, and that speed plus the integrated accelerometer less
  its bias and gravity as measured over the last 5 s of fixes (no slope model).

Positions only (``--no-positions-only`` skips them): the shipped filters on open_sky,
urban_canyon, tunnels and stop_and_go with the fixes' speed and course removed, as a
receiver that logs GGA without RMC/VTG or a ROS ``NavSatFix`` gives them (forward and RTS,
no oracle; ``<filter> (positions only)``).

Beyond the issue's scope (informational, not counted): the comparisons (a)-(c) on other
drives, comma2k19 at 0.135 s and 0 s, the paper baselines' own GNSS/drift figures, and
the positions-only runs against GNSS alone.

Conventions: gpsdr_cli.conventions (metres, local frame of the first fix).
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gpsdr_cli import config, filters
from gpsdr_cli.errors import GpsdrError
from gpsdr_cli.evaluation import (
    error_statistics,
    gnss_only_errors,
    reference_en,
    summarise,
)
from gpsdr_cli.simulate import SCENARIOS, oracle_drive, oracle_params, simulate_drive

#: the real drive, as bundled with the repository (the same files as the dataset's export)
COMMA = ROOT / "sample_logs" / "comma2k19"

#: Fang et al.'s baseline: GNSS positions only, white-noise R (no multipath states, no velocity)
AEKF_PLAIN = {"aekf": {"gnss_err_states": False, "gnss_velocity": False}}
#: Tang et al.'s baseline: GNSS positions only, one time-only error state (1 m, 60 s)
FKF_PLAIN = {"fkf": {"gnss_velocity": False, "gnss_err_pdop": math.inf, "gnss_err_dist_m": 0.0,
                     "gnss_err_sd_m": 1.0, "gnss_err_tau_s": 60.0, "eps_gate": False},
             "fafkf": {"remove_residual_mean": False}}
#: method -> (registered filter, config overrides)
PAPER = {
    "ekf (seed 000 plain)": ("ekf", AEKF_PLAIN),
    "aekf (seed 000 plain)": ("aekf", AEKF_PLAIN),
    "fkf (seed 002 plain)": ("fkf", FKF_PLAIN),
    "fafkf (seed 002 plain)": ("fafkf", FKF_PLAIN),
}
PAPER_SCENARIOS = ("urban_canyon", "one_hour")
#: a receiver that reports positions only (GGA without RMC/VTG, a ROS NavSatFix): the shipped
#: filters on the same drives with the fixes' speed and course removed (informational)
POSITIONS_ONLY = " (positions only)"
POSITIONS_ONLY_SCENARIOS = ("open_sky", "urban_canyon", "tunnels", "stop_and_go")
#: the scenario the issue sets the comparative and the GNSS-reduction targets for
URBAN = "urban_canyon"
#: the comparative targets: (check, what it measures, adaptive method, baseline method,
#: figure compared (RMSE or the mean squared error), reduction needed)
COMPARISONS = [
    ("a", "literal, shipped vs shipped", "aekf", "ekf", "rmse", 0.30),
    ("b", "adaptation alone, plain vs plain (Fang et al.)", "aekf (seed 000 plain)",
     "ekf (seed 000 plain)", "rmse", 0.30),
    ("c", "shipped aekf vs Fang et al.'s plain ekf", "aekf", "ekf (seed 000 plain)", "rmse", 0.30),
    ("a", "literal, shipped vs shipped", "fafkf", "fkf", "mse", 0.50),
    ("b", "adaptation alone, plain vs plain (Tang et al.)", "fafkf (seed 002 plain)",
     "fkf (seed 002 plain)", "mse", 0.50),
    ("c", "shipped fafkf vs Tang et al.'s plain fkf", "fafkf", "fkf (seed 002 plain)", "mse", 0.50),
]
#: comma2k19: the offset keys of the target's OR-rule (latency applied, estimated by gpsdr)
COMMA_APPLIED = "0.1"
COMMA_AUTO = "auto"
#: the scenarios whose receivers lie as real ones do, and their real-data targets:
#: urban_nlos: every filter (forward and RTS) <= 1.0 x the fixes' RMSE, the best <= 0.75 x
NLOS = "urban_nlos"
NLOS_EVERY, NLOS_BEST = 1.0, 0.75
#: rtk: the track within 0.05 m RMS of the RTK-fixed fixes interpolated at its epochs (fixes
#: at most RTK_PAIR_S apart around the epoch), its reported sigma within 2 x of that
RTK = "rtk"
RTK_DEV_M, RTK_SIGMA_X, RTK_PAIR_S = 0.05, 2.0, 0.3
#: no_odometer: the end error of its 15-s outages (13-17 s from the last fix), median
NO_ODO = "no_odometer"
NO_ODO_FWD_M, NO_ODO_ACCEL_M, NO_ODO_RTS_M = 25.0, 10.0, 0.5
NO_ODO_OUTAGE_S = (13.0, 17.0)


@dataclass
class Row:
    drive: str
    method: str
    rmse_m: float = math.nan
    cep95_m: float = math.nan
    max_m: float = math.nan
    mse_m2: float = math.nan
    drift60_pct: float = math.nan
    oracle_rmse_m: float = math.nan
    oracle_drift60_pct: float = math.nan
    seconds: float = math.nan
    note: str = ""
    #: comma2k19: RMSE of the GNSS fixes alone at the time shift this run applied (m)
    gnss_rmse_m: float = math.nan
    #: comma2k19: which offset ("0.1", "auto", "0.135", "0"); "" for simulated drives
    offset: str = ""
    #: comma2k19: the GNSS time offset the run applied (s)
    offset_s: float = math.nan
    extra: dict = field(default_factory=dict)


@dataclass
class Target:
    """One checked target: what, where, the measured figure, PASS/MISS, and its scope."""

    target: str
    drive: str
    measured: str
    verdict: str            # "PASS" | "MISS"
    issue: bool             # True: one of issue #4's targets (counted); False: informational
    shortfall: str = ""     # for a MISS: by how much


def available_filters(wanted: list[str] | None) -> list[str]:
    names = []
    for name in wanted or list(filters.NAMES):
        try:
            filters.get(name)
        except (ImportError, GpsdrError) as err:
            print(f"# filter {name} not available: {err}", file=sys.stderr)
            continue
        names.append(name)
    return names


def scenario_of(row: Row) -> str:
    """``urban_canyon`` of ``urban_canyon (seeds 1,2,3)``, ``comma2k19`` of ``comma2k19 (...)``."""
    return row.drive.split(" ")[0]


def params_for(name: str, smooth: bool | str, overrides: dict | None = None) -> dict:
    """Default parameters for filter ``name`` (+ RTS when ``smooth`` is True, + the graph smoother
    when it is ``"graph"``), with config overrides {section: {key: value}}."""
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = bool(smooth)
    p["filter"]["smoother"] = "graph" if smooth == "graph" else ("rts" if smooth else "none")
    for section, values in (overrides or {}).items():
        for key, value in values.items():
            if key not in p[section]:
                raise KeyError(f"config has no [{section}] {key} (gpsdr_cli/defaults.toml)")
            p[section][key] = value
    return p


def run_filter(drive, params: dict, auto_offset: bool = False
               ) -> tuple[pd.DataFrame, object, float, float, str]:
    """Fuse with the pipeline (``auto_offset``: gpsdr estimates the GNSS time offset itself,
    as ``gpsdr fuse --gnss-offset auto``), else build_epochs + filter + a small track.
    Returns the track, the frame, seconds, the GNSS offset applied (s) and how it was found."""
    t0 = time.perf_counter()
    try:
        from gpsdr_cli.pipeline import fuse
    except ImportError:
        fuse = None
    if fuse is not None:
        res = fuse(drive, params, auto_gnss_offset=auto_offset)
        return (res.track, res.frame, time.perf_counter() - t0, res.gnss_offset_s,
                res.gnss_offset_note)
    if auto_offset:
        raise GpsdrError("the GNSS offset estimate needs gpsdr_cli.pipeline")
    from gpsdr_cli.align import build_epochs
    from gpsdr_cli.geodesy import LocalFrame

    frame = LocalFrame.for_fixes(drive.gnss.lat_deg, drive.gnss.lon_deg)
    ep = build_epochs(drive, frame, params)
    r = filters.get(params["filter"]["name"])(ep, params)
    track = pd.DataFrame({
        "t_ns": ep.t_ns, "e": r.e, "n": r.n, "v_e": r.v_e, "v_n": r.v_n,
        "sigma_e": np.sqrt(np.maximum(r.var_e, 0)), "sigma_n": np.sqrt(np.maximum(r.var_n, 0)),
        "pdop": pd.Series(ep.pdop).ffill().to_numpy(), "gnss_e": ep.gnss_e, "gnss_n": ep.gnss_n,
        "gnss_outage": ep.gnss_outage, "static": r.static, "nis": r.nis,
        "gnss_rejected": r.gnss_rejected, "gnss_used": r.gnss_used,
    })
    return (track, frame, time.perf_counter() - t0, float(params["time"]["gnss_offset_s"]), "")


def drift60(stats: pd.DataFrame) -> float:
    rows = stats[stats["segment"].str.startswith("outage_")]
    rows = rows[(rows["duration_s"] >= 50.0) & (rows["duration_s"] <= 70.0)]
    vals = rows["end_error_pct_distance"].dropna().to_numpy(float)
    return float(np.mean(vals)) if len(vals) else math.nan


def figures(track: pd.DataFrame, ref: pd.DataFrame, name: str, params: dict) -> dict:
    st = error_statistics(track, ref, name, params)
    a = st[st["segment"] == "all"].iloc[0]
    f = {k: float(a[k]) if not pd.isna(a[k]) else math.nan for k in ("rmse_m", "cep95_m", "max_m")}
    f["mse_m2"] = f["rmse_m"] ** 2
    f["drift60_pct"] = drift60(st)
    f["stats"] = st
    return f


def mode_label(smooth: bool | str) -> str:
    """The method suffix of a smoothing mode."""
    return " + graph" if smooth == "graph" else (" + RTS" if smooth else "")


def bench_sim(scenario: str, names: list[str], duration_s: float | None,
              smooth_modes: list[bool | str], oracle: bool, keep: dict, seed: int,
              paper: bool = True, positions: bool = True) -> list[Row]:
    sim = simulate_drive(scenario, seed=seed, duration_s=duration_s)
    label = f"{scenario} (seed {seed}, {sim.truth['t_ns'].size / 100 / 60:.0f} min)"
    rows: list[Row] = []
    truth_ll = sim.truth[["t_ns", "lat", "lon"]]
    odrive = oracle_drive(sim)
    odrive_gm = oracle_drive(sim, multipath_in_sigma=False)  # filters with multipath states
    ref = None
    # (method, filter, overrides, with oracle): the shipped filters, then the paper baselines
    runs: list[tuple[str, str, dict | None, bool]] = [(n, n, None, oracle) for n in names]
    if paper and scenario in PAPER_SCENARIOS:
        runs += [(m, n, o, False) for m, (n, o) in PAPER.items() if n in names]
    if positions and scenario in POSITIONS_ONLY_SCENARIOS:
        runs += [(n + POSITIONS_ONLY, n, None, False) for n in names]
    pos_drive = positions_only(sim.drive) if positions else None
    if scenario == NO_ODO:
        rows += [Row(label, name, extra={"outage_end_m": ends})
                 for name, ends in hold_baselines(sim).items() if ends]
    for base, name, overrides, with_oracle in runs:
        for smooth in smooth_modes:
            method = base + mode_label(smooth)
            row = Row(label, method)
            try:
                p = params_for(name, smooth, overrides)
                drive = pos_drive if POSITIONS_ONLY in base else sim.drive
                track, frame, secs, _, _ = run_filter(drive, p)
                if ref is None:
                    ref = reference_en(truth_ll, frame)
                    g = gnss_only_errors(track, ref)
                    s = summarise(g)
                    rows.insert(0, Row(label, "GNSS only", s["rmse_m"], s["cep95_m"], s["max_m"],
                                       s["rmse_m"] ** 2))
                f = figures(track, ref, method, p)
                row.extra = scenario_extras(scenario, sim, track, frame, f["stats"])
                keep[(scenario, method)] = (track, ref)
                row.rmse_m, row.cep95_m, row.max_m = f["rmse_m"], f["cep95_m"], f["max_m"]
                row.mse_m2, row.drift60_pct, row.seconds = f["mse_m2"], f["drift60_pct"], secs
                if with_oracle and smooth != "graph":
                    po = oracle_params(sim.noise, p)
                    states = name in ("fkf", "fafkf") or bool(p["aekf"]["gnss_err_states"])
                    otrack, _, _, _, _ = run_filter(odrive_gm if states else odrive, po)
                    fo = figures(otrack, ref, method + " oracle", po)
                    row.oracle_rmse_m, row.oracle_drift60_pct = fo["rmse_m"], fo["drift60_pct"]
            except Exception as err:  # a broken filter must not stop the table  # noqa: BLE001
                row.note = f"failed: {type(err).__name__}: {str(err)[:80]}"
                traceback.print_exc(file=sys.stderr)
            rows.append(row)
    return rows


def rtk_fixed_deviation(sim, track: pd.DataFrame, frame, *, include_false: bool = False
                        ) -> tuple[float, float, int]:
    """The track against the RTK-fixed fixes (GGA 4) linearly interpolated at its epochs:
    (sum of squared horizontal deviations m^2, sum of the track's reported horizontal
    variance sigma_e^2 + sigma_n^2 m^2, epochs).  Only epochs between two consecutive fixed
    fixes at most ``RTK_PAIR_S`` apart count; the false fixes (GGA 4 too) are left out unless
    ``include_false`` (what a user comparing against the receiver's quality 4 would see)."""
    g = sim.drive.gnss
    fixed = g.valid & (g.fix_quality == 4)
    if not include_false and "false_fix" in sim.gnss_errors:
        fixed &= ~sim.gnss_errors["false_fix"].to_numpy(bool)
    tf = g.t_ns[fixed]
    if len(tf) < 2:
        return math.nan, math.nan, 0
    fe, fn = frame.forward(g.lat_deg[fixed], g.lon_deg[fixed])
    t = (track["t_ns"].to_numpy(np.int64) if "t_ns" in track
         else track["time"].to_numpy("datetime64[ns]").astype(np.int64))
    i = np.searchsorted(tf, t, side="right")  # tf[i-1] <= t < tf[i]
    ok = (i > 0) & (i < len(tf))
    i = np.clip(i, 1, len(tf) - 1)
    ok &= (tf[i] - tf[i - 1]) <= RTK_PAIR_S * 1e9
    w = (t - tf[i - 1]) / np.maximum(tf[i] - tf[i - 1], 1)
    ie = fe[i - 1] + w * (fe[i] - fe[i - 1])
    in_ = fn[i - 1] + w * (fn[i] - fn[i - 1])
    d2 = (track["e"].to_numpy() - ie) ** 2 + (track["n"].to_numpy() - in_) ** 2
    var = track["sigma_e"].to_numpy() ** 2 + track["sigma_n"].to_numpy() ** 2
    ok &= np.isfinite(d2) & np.isfinite(var)
    return float(d2[ok].sum()), float(var[ok].sum()), int(ok.sum())


#: no_odometer's dead-reckoning baselines (rows of the table, not filters)
HOLD = "hold: last fix's speed, gyro heading (baseline)"
HOLD_ACCEL = "hold + accelerometer speed (baseline)"
#: the accelerometer baseline's bias-plus-gravity estimate: the last seconds of fixes
ACCEL_FIT_S = 5.0


def hold_baselines(sim) -> dict[str, list[float]]:
    """End errors (m, against the truth) of no_odometer's 15-s outages dead-reckoned from the
    last fix: its position and course, the gyro's yaw rate as measured (d(psi)/dt =
    -yaw_rate; standing, the last course before the stop), and either the last fix's speed held
    (``HOLD``) or that speed plus the
    integral of the forward accelerometer less its mean bias-plus-gravity over the last
    ``ACCEL_FIT_S`` of fixes (reading minus the fixes' speed slope; ``HOLD_ACCEL``; speed
    floored at 0).  Each outage ends at the last gyro sample before the next fix."""
    g, y, a, tr = sim.drive.gnss, sim.drive.gyro, sim.drive.accel, sim.truth
    ok = g.valid & np.isfinite(g.speed_mps)
    tf = g.t_ns[ok]
    fe, fn = sim.frame.forward(g.lat_deg[ok], g.lon_deg[ok])
    spd, crs = g.speed_mps[ok], np.radians(g.course_deg[ok])
    out: dict[str, list[float]] = {HOLD: [], HOLD_ACCEL: []}
    t0 = int(tr["t_ns"].iloc[0])
    for o in sim.noise.get("brake_outages", []):
        start = t0 + int(o["start_s"] * 1e9)
        k = int(np.searchsorted(tf, start)) - 1
        known = np.flatnonzero(np.isfinite(crs[:k + 1]))  # standing: the course before the stop
        if k < 0 or k + 1 >= len(tf) or not len(known):
            continue
        crs_k = crs[known[-1]]
        t_end = tf[k + 1]
        sel = (y.t_ns > tf[k]) & (y.t_ns < t_end)
        t = np.concatenate(([tf[k]], y.t_ns[sel])).astype(np.int64)
        dt = np.diff(t) / 1e9
        w = y.yaw_rate_radps[sel]
        psi = crs_k - np.cumsum(w * dt)
        fit = (tf > tf[k] - ACCEL_FIT_S * 1e9) & (tf <= tf[k])
        speeds = {HOLD: np.full(len(dt), spd[k])}
        if a is not None and fit.sum() >= 3:
            slope = np.polyfit((tf[fit] - tf[k]) / 1e9, spd[fit], 1)[0]
            am = (a.t_ns > tf[k] - ACCEL_FIT_S * 1e9) & (a.t_ns <= tf[k])
            b = float(np.mean(a.accel_mps2[am])) - slope
            acc = np.interp(t[1:], a.t_ns, a.accel_mps2) - b
            v = np.empty(len(dt))
            vk = spd[k]
            for i in range(len(dt)):  # floored at 0: a braking car stops, it does not reverse
                vk = max(vk + acc[i] * dt[i], 0.0)
                v[i] = vk
            speeds[HOLD_ACCEL] = v
        te = np.interp(t[-1], tr["t_ns"], tr["e"])
        tn = np.interp(t[-1], tr["t_ns"], tr["n"])
        for name, v in speeds.items():
            e = fe[k] + np.sum(v * np.sin(psi) * dt)
            n = fn[k] + np.sum(v * np.cos(psi) * dt)
            out[name].append(float(np.hypot(e - te, n - tn)))
    return out


def scenario_extras(scenario: str, sim, track: pd.DataFrame, frame, stats: pd.DataFrame) -> dict:
    """What the real-data targets of ``scenario`` need from one run (pooled over seeds by
    :func:`pool_extras`): rtk's deviation from the fixed fixes, no_odometer's outage ends."""
    if scenario == RTK:
        return {"rtk": rtk_fixed_deviation(sim, track, frame),
                "rtk_all4": rtk_fixed_deviation(sim, track, frame, include_false=True)}
    if scenario == NO_ODO:
        rows = stats[stats["segment"].str.startswith("outage_")]
        lo, hi = NO_ODO_OUTAGE_S
        rows = rows[(rows["duration_s"] >= lo) & (rows["duration_s"] <= hi)]
        ends = rows["end_error_m"].dropna().to_numpy(float) if "end_error_m" in rows else []
        return {"outage_end_m": [float(x) for x in ends]}
    return {}


def pool_extras(extras: list[dict]) -> dict:
    """Lists concatenated, tuples of sums added element by element."""
    out: dict = {}
    for ex in extras:
        for k, v in ex.items():
            if isinstance(v, list):
                out.setdefault(k, []).extend(v)
            elif isinstance(v, tuple):
                prev = out.get(k)
                out[k] = v if prev is None else tuple(a + b for a, b in zip(prev, v, strict=True))
    return out


def bench_comma(names: list[str], smooth_modes: list[bool], keep: dict) -> list[Row]:
    from gpsdr_cli.io.csv import read_gyro_csv, read_odo_csv
    from gpsdr_cli.io.nmea import read_nmea
    from gpsdr_cli.io.reference import read_reference
    from gpsdr_cli.latency import estimate_gnss_offset

    p0 = config.defaults()
    drive = read_nmea(COMMA / "gps.nmea")
    drive.merge(read_gyro_csv(COMMA / "gyro.csv", p0["gyro"]))
    drive.merge(read_odo_csv(COMMA / "odo.csv", p0["odo"]))
    refobj = read_reference(COMMA / "truth.csv")
    rows: list[Row] = []
    # the offset the fixes themselves show against the reference (no filter involved)
    from gpsdr_cli.align import build_epochs
    from gpsdr_cli.geodesy import LocalFrame

    frame0 = LocalFrame.for_fixes(drive.gnss.lat_deg, drive.gnss.lon_deg)
    ep0 = build_epochs(copy.deepcopy(drive), frame0, p0)
    fixes = pd.DataFrame({"t_ns": ep0.t_ns, "gnss_e": ep0.gnss_e, "gnss_n": ep0.gnss_n,
                          "e": np.nan, "n": np.nan, "v_e": np.nan, "v_n": np.nan})
    est0 = estimate_gnss_offset(fixes, reference_en(refobj, frame0))
    est0_s = round(est0.offset_s, 3)
    offsets: list[tuple[str, float | None, str]] = [
        (COMMA_APPLIED, 0.1, "README calibration"),
        (COMMA_AUTO, None, "estimated by gpsdr"),
        (f"{est0_s:g}", est0_s, "estimated vs reference"),
        ("0", 0.0, "as logged"),
    ]
    for key, offset, why in offsets:
        label = f"comma2k19 (gnss_offset_s = {key}, {why})"
        auto = offset is None
        ref = None
        block: list[Row] = []
        gnss_rows: dict[float, Row] = {}  # GNSS-only row per time shift applied (to 1 ms)
        for name in names:
            for smooth in smooth_modes:
                p = params_for(name, smooth)
                p["time"]["gnss_offset_s"] = 0.0 if auto else offset
                method = name + mode_label(smooth)
                row = Row(label, method, offset=key)
                try:
                    track, frame, secs, used_s, how = run_filter(copy.deepcopy(drive), p, auto)
                    if ref is None:
                        ref = reference_en(refobj, frame)
                    # the fixes at the time shift this very run applied (auto: its own estimate)
                    s = summarise(gnss_only_errors(track, ref))
                    shift_ms = round(used_s, 3)
                    if shift_ms not in gnss_rows:
                        est_ref = estimate_gnss_offset(track, ref)
                        gname = f"GNSS only (at {used_s:+.3f} s)" if auto else "GNSS only"
                        gnss_rows[shift_ms] = Row(
                            label, gname, s["rmse_m"], s["cep95_m"], s["max_m"], s["rmse_m"] ** 2,
                            note=f"offset vs reference: {est_ref.offset_s:+.3f} s more",
                            gnss_rmse_m=s["rmse_m"], offset=key, offset_s=used_s)
                    f = figures(track, ref, method, p)
                    keep[("comma2k19", key, method)] = (track, ref)
                    row.rmse_m, row.cep95_m, row.max_m = f["rmse_m"], f["cep95_m"], f["max_m"]
                    row.mse_m2, row.seconds = f["mse_m2"], secs
                    row.gnss_rmse_m, row.offset_s = s["rmse_m"], used_s
                    if auto:
                        row.note = (f"gpsdr's offset {used_s:+.3f} s ({how}); GNSS only at it: "
                                    f"{s['rmse_m']:.2f} m")
                    else:
                        est = estimate_gnss_offset(track)
                        row.note = (f"offset from track: {est.offset_s:+.3f} s more"
                                    if est.identified else f"offset: {est.reason}")
                except Exception as err:  # noqa: BLE001
                    row.note = f"failed: {type(err).__name__}: {str(err)[:80]}"
                    traceback.print_exc(file=sys.stderr)
                block.append(row)
        rows += list(gnss_rows.values()) + block
    return rows


def pool(per_seed: list[list[Row]], scenario: str, seeds: list[int]) -> list[Row]:
    """One row per method over several seeds: RMSE and oracle RMSE as root mean squares,
    CEP95 and drifts as means, max as the max."""
    out: list[Row] = []
    label = f"{scenario} (seeds {','.join(map(str, seeds))})"
    for i, first in enumerate(per_seed[0]):
        rs = [rows[i] for rows in per_seed if i < len(rows) and rows[i].method == first.method]

        def mean(attr: str, rs=rs) -> float:
            v = np.array([getattr(r, attr) for r in rs], float)
            return float(np.nanmean(v)) if np.isfinite(v).any() else math.nan

        def rms(attr: str, rs=rs) -> float:
            v = np.array([getattr(r, attr) for r in rs], float)
            return float(np.sqrt(np.nanmean(v * v))) if np.isfinite(v).any() else math.nan

        mx = np.array([r.max_m for r in rs], float)
        out.append(Row(label, first.method, rms("rmse_m"), mean("cep95_m"),
                       float(np.nanmax(mx)) if np.isfinite(mx).any() else math.nan,
                       mean("mse_m2"), mean("drift60_pct"), rms("oracle_rmse_m"),
                       mean("oracle_drift60_pct"), mean("seconds"),
                       "; ".join(sorted({r.note for r in rs if r.note})),
                       extra=pool_extras([r.extra for r in rs])))
    return out


def fmt(x: float, nd: int = 2) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def table(rows: list[Row]) -> str:
    head = ("| drive | method | RMSE m | CEP95 m | max m | 60-s drift % | oracle RMSE m | "
            "RMSE/oracle | oracle 60-s drift % | s | note |")
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        has_oracle = np.isfinite(r.oracle_rmse_m) and r.oracle_rmse_m > 0
        ratio = r.rmse_m / r.oracle_rmse_m if has_oracle else math.nan
        lines.append(f"| {r.drive} | {r.method} | {fmt(r.rmse_m)} | {fmt(r.cep95_m)} | {fmt(r.max_m)} | "
                     f"{fmt(r.drift60_pct)} | {fmt(r.oracle_rmse_m)} | {fmt(ratio)} | "
                     f"{fmt(r.oracle_drift60_pct)} | {fmt(r.seconds, 1)} | {row_note(r)} |")
    return "\n".join(lines)


def row_note(r: Row) -> str:
    """The row's note, with no_odometer's 15-s outage end errors (median and max over the
    seeds' outages) for the filters and the dead-reckoning baselines alike."""
    ends = np.asarray(r.extra.get("outage_end_m", []), float)
    if not len(ends):
        return r.note
    what = (f"15-s outage end error median {np.median(ends):.2f} m, max {np.max(ends):.1f} m "
            f"({len(ends)} outages)")
    return f"{r.note}; {what}" if r.note else what


def _finite(*xs: float) -> bool:
    return all(x is not None and np.isfinite(x) for x in xs)


def _is_paper(method: str) -> bool:
    """A method outside the issue's scope: the seeds' plain baselines, the positions-only runs."""
    return "plain)" in method or POSITIONS_ONLY in method


def positions_only(drive):
    """``drive`` without the receiver's speed and course over ground (a copy)."""
    d = copy.deepcopy(drive)
    d.gnss.speed_mps[:] = np.nan
    d.gnss.course_deg[:] = np.nan
    return d


def _below(red: float) -> str:
    """A reduction as '53 % below' or, when negative, '40 % above'."""
    pct = round(100 * red)
    return f"{pct} % below" if pct >= 0 else f"{-pct} % above"


def _gnss_of(row: Row, by: dict[tuple[str, str], Row]) -> float:
    """GNSS-only RMSE at this run's time shift: its own figure, else its drive's GNSS row."""
    if _finite(row.gnss_rmse_m):
        return row.gnss_rmse_m
    g = by.get((row.drive, "GNSS only"))
    return g.rmse_m if g is not None else math.nan


def targets(rows: list[Row]) -> list[Target]:
    """Issue #4's accuracy targets (``issue=True``) and the comparisons beyond its scope
    (``issue=False``), each with the measured figure, PASS/MISS and, for a miss, by how much."""
    by = {(r.drive, r.method): r for r in rows}
    out: list[Target] = []

    def add(target: str, drive: str, measured: str, ok: bool, issue: bool, short: str) -> None:
        out.append(Target(target, drive, measured, "PASS" if ok else "MISS", issue,
                          "" if ok else short))

    # 1. within 15 % of the oracle, every scenario, every shipped filter
    for r in rows:
        if _finite(r.oracle_rmse_m, r.rmse_m) and r.oracle_rmse_m > 0:
            ratio = r.rmse_m / r.oracle_rmse_m
            add(f"{r.method}: RMSE within 15 % of the oracle", r.drive, f"{ratio:.2f} x oracle",
                ratio <= 1.15, True, f"{ratio:.2f} x oracle, limit 1.15 x")
    # 2. urban canyon: >= 40 % below GNSS-only (the paper baselines: informational)
    for r in rows:
        if scenario_of(r) != URBAN or r.method.startswith("GNSS only") or not _finite(r.rmse_m):
            continue
        gnss = _gnss_of(r, by)
        if _finite(gnss) and gnss > 0:
            red = 1 - r.rmse_m / gnss
            add(f"{r.method}: >= 40 % below GNSS-only", r.drive, _below(red),
                red >= 0.40, not _is_paper(r.method),
                f"{_below(red)}, needs 40 % below ({100 * (0.40 - red):.0f} points short)")
    # 2b. positions only (informational): below GNSS-only on every drive
    for r in rows:
        if (POSITIONS_ONLY not in r.method or not _finite(r.rmse_m)
                or scenario_of(r) in (URBAN, "tunnels")):
            continue  # the urban canyon's are in 2. above; in tunnels GNSS alone has no outage epochs
        gnss = _gnss_of(r, by)
        if _finite(gnss) and gnss > 0:
            red = 1 - r.rmse_m / gnss
            add(f"{r.method}: below GNSS-only", r.drive, f"{r.rmse_m:.2f} vs {gnss:.2f} m",
                red > 0.0, False, f"{_below(red)}")
    # 3. the comparative targets, a/b/c; issue scope in the urban canyon only
    drives = list(dict.fromkeys(r.drive for r in rows))
    for drive in drives:
        for suffix in ("", " + RTS"):
            for check, what, adaptive, baseline, figure, need in COMPARISONS:
                ra, rb = by.get((drive, adaptive + suffix)), by.get((drive, baseline + suffix))
                if ra is None or rb is None:
                    continue
                xa, xb = (ra.rmse_m, rb.rmse_m) if figure == "rmse" else (ra.mse_m2, rb.mse_m2)
                if not _finite(xa, xb) or xb <= 0:
                    continue
                red = 1 - xa / xb
                quantity = "RMSE" if figure == "rmse" else "error variance"
                unit = "m" if figure == "rmse" else "m^2"
                add(f"({check}) {adaptive + suffix}: {quantity} >= {100 * need:.0f} % below "
                    f"{baseline + suffix} [{what}]", drive,
                    f"{xa:.2f} vs {xb:.2f} {unit}: {_below(red)}", red >= need,
                    scenario_of(ra) == URBAN,
                    f"{_below(red)}, needs {100 * need:.0f} % below "
                    f"({100 * (need - red):.0f} points short)")
    # 4. a 60-s outage ends within 2 % (forward) / 1 % (RTS) of the distance
    for r in rows:
        if _finite(r.drift60_pct):
            lim = 1.0 if "RTS" in r.method else 2.0
            add(f"{r.method}: 60 s outage ends within {lim:g} % of distance", r.drive,
                f"{r.drift60_pct:.2f} %", r.drift60_pct <= lim, not _is_paper(r.method),
                f"{r.drift60_pct:.2f} %, limit {lim:g} %")
    # 5. comma2k19: below GNSS-only with the latency applied (0.1 s) OR estimated by gpsdr
    comma = [r for r in rows if scenario_of(r) == "comma2k19" and not r.method.startswith("GNSS only")]
    methods = list(dict.fromkeys(r.method for r in comma))
    for method in methods:
        parts, oks, shorts, where = [], [], [], []
        for key, name in ((COMMA_APPLIED, "applied 0.1 s"), (COMMA_AUTO, "auto")):
            r = next((x for x in comma if x.method == method and x.offset == key), None)
            if r is None or not _finite(r.rmse_m):
                continue
            gnss = _gnss_of(r, by)
            if not _finite(gnss):
                continue
            if key == COMMA_AUTO and _finite(r.offset_s):
                name = f"auto {r.offset_s:+.3f} s"
            parts.append(f"{name}: {r.rmse_m:.3f} vs {gnss:.3f} m")
            oks.append(r.rmse_m < gnss)
            shorts.append(f"{r.rmse_m - gnss:+.3f} m at {name}")
            where.append(key)
        if parts:
            add(f"{method}: below GNSS-only, latency applied or estimated",
                f"comma2k19 (gnss_offset_s = {' / '.join(where)})", "; ".join(parts),
                any(oks), True, "fused - GNSS-only: " + ", ".join(shorts))
    for r in comma:
        if r.offset in (COMMA_APPLIED, COMMA_AUTO) or not _finite(r.rmse_m):
            continue
        gnss = _gnss_of(r, by)
        if _finite(gnss):
            add(f"{r.method}: below GNSS-only", r.drive, f"{r.rmse_m:.3f} vs {gnss:.3f} m",
                r.rmse_m < gnss, False, f"{r.rmse_m - gnss:+.3f} m")
    return out


def real_data_targets(rows: list[Row]) -> list[Target]:
    """The targets set on real drives, checked on the scenarios that lie like them:
    urban_nlos (every filter <= 1.0 x the fixes' RMSE, the best <= 0.75 x), rtk (within
    0.05 m RMS of the RTK-fixed fixes, reported sigma within 2 x) and no_odometer (15-s
    outage end error median <= 25 m forward, <= 10 m with the accelerometer, <= 0.5 m RTS)."""
    by = {(r.drive, r.method): r for r in rows}
    out: list[Target] = []

    def add(target: str, drive: str, measured: str, ok: bool, short: str) -> None:
        out.append(Target(target, drive, measured, "PASS" if ok else "MISS", True,
                          "" if ok else short))

    for r in rows:  # the dead-reckoning baselines: informational
        if scenario_of(r) == NO_ODO and "(baseline)" in r.method and r.extra.get("outage_end_m"):
            ends = np.array(r.extra["outage_end_m"], float)
            out.append(Target(f"{r.method}: 15-s outage end error", r.drive,
                              f"median {np.median(ends):.2f} m over {len(ends)} outages", "-",
                              False))
    shipped = [r for r in rows if not r.method.startswith("GNSS only") and not _is_paper(r.method)
               and _finite(r.rmse_m) and "(baseline)" not in r.method]
    for drive in dict.fromkeys(r.drive for r in shipped if scenario_of(r) == NLOS):
        gnss = _gnss_of(Row(drive, ""), by)
        runs = [r for r in shipped if r.drive == drive]
        if not (_finite(gnss) and gnss > 0):
            continue
        for r in runs:
            x = r.rmse_m / gnss
            add(f"{r.method}: <= {NLOS_EVERY:.2f} x the fixes' RMSE (NLOS)", drive,
                f"{r.rmse_m:.2f} vs {gnss:.2f} m: {x:.2f} x", x <= NLOS_EVERY,
                f"{x:.2f} x, limit {NLOS_EVERY:.2f} x")
        best = min(runs, key=lambda r: r.rmse_m)
        x = best.rmse_m / gnss
        add(f"best filter <= {NLOS_BEST:.2f} x the fixes' RMSE (NLOS)", drive,
            f"{best.method}: {best.rmse_m:.2f} vs {gnss:.2f} m: {x:.2f} x", x <= NLOS_BEST,
            f"{x:.2f} x, limit {NLOS_BEST:.2f} x")
    for r in shipped:
        if scenario_of(r) == RTK and "rtk" in r.extra:
            d2, var, n = r.extra["rtk"]
            if not n:
                continue
            dev, sig = math.sqrt(d2 / n), math.sqrt(var / n)
            d2a, _, na = r.extra.get("rtk_all4", (math.nan, math.nan, 0))
            lit = f"; {math.sqrt(d2a / na):.3f} m against every GGA-4 fix" if na else ""
            add(f"{r.method}: within {RTK_DEV_M:.2f} m RMS of the RTK-fixed fixes", r.drive,
                f"{dev:.3f} m{lit}", dev <= RTK_DEV_M, f"{dev:.3f} m, limit {RTK_DEV_M:.2f} m")
            ratio = sig / dev if dev > 0 else math.inf
            add(f"{r.method}: reported sigma within {RTK_SIGMA_X:g} x of that deviation", r.drive,
                f"sigma {sig:.3f} m vs {dev:.3f} m: {ratio:.2f} x",
                1 / RTK_SIGMA_X <= ratio <= RTK_SIGMA_X, f"{ratio:.2f} x, limit 0.5-2 x")
        if scenario_of(r) == NO_ODO and r.extra.get("outage_end_m"):
            ends = np.array(r.extra["outage_end_m"], float)
            med = float(np.median(ends))
            what = f"median {med:.2f} m over {len(ends)} outages"
            if "RTS" in r.method:
                add(f"{r.method}: 15-s outage end error median <= {NO_ODO_RTS_M:g} m", r.drive,
                    what, med <= NO_ODO_RTS_M, f"{med:.2f} m, limit {NO_ODO_RTS_M:g} m")
                continue
            add(f"{r.method}: 15-s outage end error median <= {NO_ODO_FWD_M:g} m", r.drive,
                what, med <= NO_ODO_FWD_M, f"{med:.2f} m, limit {NO_ODO_FWD_M:g} m")
            add(f"{r.method}: 15-s outage end error median <= {NO_ODO_ACCEL_M:g} m with the "
                "forward accelerometer (in the log)", r.drive, what, med <= NO_ODO_ACCEL_M,
                f"{med:.2f} m, limit {NO_ODO_ACCEL_M:g} m")
    return out


def _target_table(tgts: list[Target]) -> str:
    lines = ["| target | drive | measured | verdict |", "|---|---|---|---|"]
    lines += [f"| {t.target} | {t.drive} | {t.measured} | {t.verdict} |" for t in tgts]
    return "\n".join(lines)


def verdict_summary(tgts: list[Target]) -> str:
    """'N of M issue targets pass', then one line per miss: target, drive, by how much."""
    issue = [t for t in tgts if t.issue]
    misses = [t for t in issue if t.verdict == "MISS"]
    lines = [f"**{len(issue) - len(misses)} of {len(issue)} issue targets pass.**"]
    if misses:
        lines += ["", "Misses:", ""]
        lines += [f"- {t.target} -- {t.drive} -- {t.shortfall}" for t in misses]
    return "\n".join(lines)


COMPARISON_NOTE = (
    "The comparative targets come from Fang et al. (aekf >= 30 % below ekf) and Tang et al. (fafkf's "
    "error variance >= 50 % below fkf), which measured their adaptive filter against a plain "
    "baseline: GNSS positions only, fixed white-noise R. Our shipped ekf and fkf are not that "
    "baseline: they carry model extensions (ekf: Gauss-Markov multipath states and the GNSS "
    "velocity; fkf: two-regime multipath error states and the GNSS velocity) that already put "
    "them within a few % of their oracle, so (a), shipped against shipped, leaves no room for "
    "30 % or 50 %; (b) measures the adaptation alone as the seeds did (plain against plain, "
    "config overrides only, see the module docstring), and (c) the shipped adaptive filter "
    "against the seed's plain baseline. Each check keeps its own verdict; there is no combined "
    "one, and the figures are what they are.")


def targets_markdown(tgts: list[Target]) -> str:
    """The Targets section: the note on a/b/c, the issue-scope table, the informational one."""
    issue = [t for t in tgts if t.issue]
    beyond = [t for t in tgts if not t.issue]
    text = COMPARISON_NOTE + "\n\n### Issue #4's targets\n\n" + _target_table(issue) + "\n"
    if beyond:
        text += ("\n### Beyond the issue's scope (informational, not counted)\n\n"
                 "The comparisons (a)-(c) on drives other than the urban canyon, comma2k19 at "
                 "the offset estimated against the reference and as logged, and the paper "
                 "baselines' own GNSS-reduction and drift figures.\n\n" + _target_table(beyond) + "\n")
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--filters", default="")
    ap.add_argument("--quick", action="store_true", help="3-minute drives, no one_hour, no oracle")
    ap.add_argument("--no-comma", action="store_true")
    ap.add_argument("--no-smooth", action="store_true")
    ap.add_argument("--no-graph", action="store_true", help="skip the graph smoother's column")
    ap.add_argument("--no-oracle", action="store_true")
    ap.add_argument("--no-paper", action="store_true",
                    help="skip the seeds' plain baselines (ekf/aekf Fang et al., fkf/fafkf Tang et al.)")
    ap.add_argument("--no-positions-only", action="store_true",
                    help="skip the runs without the receiver's speed/course (positions only)")
    ap.add_argument("--seeds", default="1,2,3", help="simulation seeds, comma-separated (default 1,2,3); "
                    "with several, each figure is pooled over the seeds (RMSE as the root of "
                    "the mean square, CEP95 and drift as means, max as the max)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "accuracy.md"))
    args = ap.parse_args(argv)
    seeds = [int(x) for x in args.seeds.split(",") if x.strip()]
    names = available_filters([s for s in args.filters.split(",") if s] or None)
    scen = list(dict.fromkeys(s for s in args.scenarios.split(",") if s))  # each once
    if args.quick:
        scen = [s for s in scen if s != "one_hour"]
    smooth_modes: list[bool | str] = [False] if args.no_smooth else [False, True]
    if not args.no_graph:
        smooth_modes.append("graph")
    keep: dict = {}
    rows: list[Row] = []
    t0 = time.perf_counter()
    for sc in scen:
        print(f"# {sc} ...", file=sys.stderr)
        per_seed = [bench_sim(sc, names, 180.0 if args.quick and sc != "tunnels" else None,
                              smooth_modes, not (args.no_oracle or args.quick), keep, seed,
                              paper=not args.no_paper, positions=not args.no_positions_only)
                    for seed in seeds]
        rows += per_seed[0] if len(seeds) == 1 else pool(per_seed, sc, seeds)
    if not args.no_comma and COMMA.exists():
        print("# comma2k19 ...", file=sys.stderr)
        rows += bench_comma(names, smooth_modes, keep)
    tab = table(rows)
    tgts = targets(rows) + real_data_targets(rows)
    text = (f"# gpsdr accuracy benchmark\n\n`.venv/bin/python benchmarks/accuracy.py"
            f"{' ' + ' '.join(argv or sys.argv[1:]) if (argv or sys.argv[1:]) else ''}` "
            f"(seeds {args.seeds}, filters: {', '.join(names)}; {time.perf_counter() - t0:.0f} s)\n\n"
            + verdict_summary(tgts) + "\n\n"
            "Errors are horizontal, against the simulator's truth (or comma2k19's reference), over "
            "every filter epoch; GNSS only: the fixes themselves (comma2k19: at the time shift "
            "each run applied; with `auto` each filter estimates its own). 60-s drift: error at "
            "the end of each 50-70 s GNSS outage as % of the distance driven in it. Oracle: the "
            "same filter with the true noise parameters and per-fix sigmas "
            "(`simulate.oracle_params`, `simulate.oracle_drive`). `(seed 000 plain)` / "
            "`(seed 002 plain)`: the seeds' baselines, our filters with the model extensions "
            "switched off by config (module docstring). `(positions only)`: the shipped filter on "
            "the same drive without the fixes' speed and course (a receiver logging GGA without "
            "RMC/VTG, a ROS NavSatFix).\n\n" + tab
            + "\n\n## Targets\n\n" + targets_markdown(tgts))
    print(text)
    Path(args.out).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
