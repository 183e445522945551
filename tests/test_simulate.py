"""The simulator: determinism, truth consistency, sensor error statistics, writers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gpsdr_cli.config import DEFAULTS, defaults
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.errors import UsageError
from gpsdr_cli.simulate import (
    SCENARIOS,
    oracle_drive,
    oracle_params,
    simulate_drive,
    write_drive,
)


@pytest.fixture(scope="module")
def urban():
    return simulate_drive("urban_canyon", seed=7, duration_s=300.0)


@pytest.fixture(scope="module")
def tunnels():
    return simulate_drive("tunnels", seed=3)


def test_same_seed_same_drive_other_seed_other_drive():
    a = simulate_drive("stop_and_go", seed=11, duration_s=120.0)
    b = simulate_drive("stop_and_go", seed=11, duration_s=120.0)
    c = simulate_drive("stop_and_go", seed=12, duration_s=120.0)
    assert a.truth.equals(b.truth)
    np.testing.assert_array_equal(a.drive.gnss.lat_deg, b.drive.gnss.lat_deg)
    np.testing.assert_array_equal(a.drive.gyro.yaw_rate_radps, b.drive.gyro.yaw_rate_radps)
    np.testing.assert_array_equal(a.drive.odo.speed_mps, b.drive.odo.speed_mps)
    assert a.noise == b.noise
    assert not np.allclose(a.truth["e"], c.truth["e"])


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_every_scenario_runs_and_moves(scenario):
    sim = simulate_drive(scenario, seed=1, duration_s=200.0)
    tr = sim.truth
    assert len(tr) == 200 * 100 + 1
    dist_m = float(np.sum(tr["speed"]) * 0.01)
    assert dist_m > 500.0
    assert tr["speed"].max() < 26.0  # m/s, below the 22 m/s cruise plus wobble
    assert np.all(tr["speed"] >= 0.0)
    lat_acc = np.abs(tr["speed"] * tr["yaw_rate"])
    assert lat_acc.max() < 3.0  # m/s^2, the driver respects curve speed


def test_truth_is_consistent(urban):
    tr = urban.truth
    dt = 0.01
    # position is the integral of velocity (trapezoid) to within 1 cm over the drive
    v_e, v_n = tr["v_e"].to_numpy(), tr["v_n"].to_numpy()
    e_int = np.concatenate(([0.0], np.cumsum(0.5 * (v_e[1:] + v_e[:-1]) * dt)))
    n_int = np.concatenate(([0.0], np.cumsum(0.5 * (v_n[1:] + v_n[:-1]) * dt)))
    assert np.max(np.abs(e_int - tr["e"])) < 0.01
    assert np.max(np.abs(n_int - tr["n"])) < 0.01
    # speed and heading agree with the velocity components
    np.testing.assert_allclose(np.hypot(tr["v_e"], tr["v_n"]), tr["speed"], atol=1e-9)
    moving = tr["speed"].to_numpy() > 0.5
    hd = np.degrees(np.arctan2(tr["v_e"], tr["v_n"])) % 360.0
    d = (hd - tr["heading_deg"] + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(d[moving])) < 1e-6
    # yaw rate (CCW+) = -d(heading)/dt: heading is the integral of -yaw_rate (1e-6 rad) ...
    psi = np.unwrap(np.radians(tr["heading_deg"].to_numpy()))
    w = tr["yaw_rate"].to_numpy()
    psi_int = psi[0] - np.concatenate(([0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)))
    assert np.max(np.abs(psi_int - psi)) < 1e-6
    # ... and central differences agree within 3e-3 rad/s (the driver's jerk limit)
    dpsi = np.gradient(psi, dt)
    assert np.max(np.abs(dpsi[1:-1] + w[1:-1])) < 3e-3
    assert np.sqrt(np.mean((dpsi[1:-1] + w[1:-1]) ** 2)) < 1e-4
    # lat/lon are the local frame's inverse of e/n (1 mm)
    e, n = urban.frame.forward(tr["lat"], tr["lon"])
    assert np.max(np.hypot(e - tr["e"], n - tr["n"])) < 1e-3
    assert tr["t_ns"].dtype == np.int64
    assert np.all(np.diff(tr["t_ns"]) == NS_PER_S // 100)


def test_urban_drive_turns_corners_and_stops(urban):
    tr = urban.truth
    heading_change = np.sum(np.abs(tr["yaw_rate"])) * 0.01
    assert heading_change > np.radians(360.0)  # several 90-degree corners in 5 minutes
    assert np.mean(tr["speed"] < 0.01) > 0.05  # stops at lights


def test_gnss_white_noise_matches_stated_sigma():
    sim = simulate_drive("open_sky", seed=5, duration_s=600.0)
    g = sim.drive.gnss
    ge = sim.gnss_errors
    e, n = sim.frame.forward(g.lat_deg, g.lon_deg)
    t = sim.truth["t_ns"].to_numpy()
    e_true = np.interp(g.t_ns, t, sim.truth["e"])
    n_true = np.interp(g.t_ns, t, sim.truth["n"])
    sd = sim.noise["gnss_sd_per_pdop_m"] * g.pdop
    ok = g.valid & ~ge["outlier"].to_numpy()
    # what is left after removing the recorded multipath is the white part: unit variance
    z_e = (e - e_true - ge["multipath_e"])[ok] / sd[ok]
    z_n = (n - n_true - ge["multipath_n"])[ok] / sd[ok]
    assert abs(np.std(z_e) - 1.0) < 0.10
    assert abs(np.std(z_n) - 1.0) < 0.10
    # total error sigma: white plus multipath, as stated in true_sd_m (10 %)
    tot = np.concatenate([(e - e_true)[ok] / ge["true_sd_m"][ok], (n - n_true)[ok] / ge["true_sd_m"][ok]])
    assert abs(np.std(tot) - 1.0) < 0.15
    # open sky: the receiver's sigma is honest (within 10 % of the true one)
    ratio = g.sigma_e_m[ok] / ge["true_sd_m"].to_numpy()[ok]
    assert abs(np.median(ratio) - 1.0) < 0.10


def test_urban_multipath_is_underreported(urban):
    g = urban.drive.gnss
    ge = urban.gnss_errors
    ok = g.valid
    e, n = urban.frame.forward(g.lat_deg, g.lon_deg)
    t = urban.truth["t_ns"].to_numpy()
    err = np.hypot(e - np.interp(g.t_ns, t, urban.truth["e"]), n - np.interp(g.t_ns, t, urban.truth["n"]))
    rms_err = np.sqrt(np.mean(err[ok] ** 2))
    rms_rep = np.sqrt(np.mean(2 * g.sigma_e_m[ok] ** 2))
    assert rms_err > 1.3 * rms_rep  # the receiver claims better than it is
    assert (ge["multipath_e"].std()) > 2.0  # m: urban multipath is metres


def test_outages_where_declared(tunnels):
    g = tunnels.drive.gnss
    rel = (g.t_ns - g.t_ns[0]) / NS_PER_S
    outs = tunnels.noise["outages"]
    assert [round(o["duration_s"]) for o in outs] == [30, 60, 120]
    inside = np.zeros(len(g), bool)
    for o in outs:
        m = (rel >= o["start_s"]) & (rel < o["start_s"] + o["duration_s"])
        inside |= m
        assert not g.valid[m].any()
        assert np.all(g.fix_quality[m] == 0)
        assert np.all(np.isnan(g.lat_deg[m]))
    assert g.valid[~inside].all()  # open sky elsewhere: every fix present
    # the 60 s tunnel holds a curve: heading changes by more than 30 degrees inside it
    o = outs[1]
    tr = tunnels.truth
    rel_t = (tr["t_ns"] - tr["t_ns"].iloc[0]) / NS_PER_S
    m = (rel_t >= o["start_s"]) & (rel_t < o["start_s"] + o["duration_s"])
    assert np.degrees(np.sum(np.abs(tr["yaw_rate"][m])) * 0.01) > 30.0


def test_gyro_and_odometer_error_models(urban):
    tr = urban.truth
    y = urban.drive.gyro
    nz = urban.noise
    truth_rate = tr["yaw_rate"].to_numpy()
    resid = y.yaw_rate_radps - (1 + nz["gyro_scale_error"]) * truth_rate
    # residual = bias + white; the bias moves slowly, so first differences are white
    d = np.diff(resid)
    assert abs(np.std(d) / np.sqrt(2) / nz["gyro_noise_sd_radps"] - 1.0) < 0.05
    assert abs(np.mean(resid[:500]) - nz["gyro_bias_initial_radps"]) < 3e-4  # rad/s
    o = urban.drive.odo
    moving = tr["speed"].to_numpy() > 3.0
    ratio = np.median(o.speed_mps[moving] / tr["speed"].to_numpy()[moving])
    assert abs(ratio - (1 + nz["odo_scale_error"])) < 0.01
    q = 1.0 / (nz["odo_ticks_per_m"] * nz["odo_window_s"])  # m/s per tick in the window
    assert q > 0.1


def test_gnss_rate_and_stamp_offset():
    sim = simulate_drive("open_sky", seed=2, duration_s=60.0, gnss_rate_hz=10.0,
                         gnss_stamp_offset_s=0.1)
    g = sim.drive.gnss
    assert np.all(np.diff(g.t_ns) == NS_PER_S // 10)
    assert sim.noise["gnss_stamp_offset_s"] == 0.1
    with pytest.raises(UsageError):
        simulate_drive("nowhere")
    with pytest.raises(UsageError):
        simulate_drive("open_sky", gyro_rate_hz=30.0)


def test_write_drive(tmp_path):
    sim = simulate_drive("urban_canyon", seed=4, duration_s=40.0)
    paths = write_drive(sim, tmp_path)
    assert set(paths) == {"gps.nmea", "gyro.csv", "odo.csv", "drive.mcap", "truth.csv", "noise.json"}
    lines = paths["gps.nmea"].read_text().splitlines()
    assert len(lines) == 4 * len(sim.drive.gnss) - sum(sim.drive.gnss.fix_quality == 0)
    for line in lines:
        body, cs = line[1:].split("*")
        x = 0
        for ch in body.encode():
            x ^= ch
        assert int(cs, 16) == x
    assert {ln[3:6] for ln in lines} == {"RMC", "GGA", "GSA", "GST"}
    gyro = np.loadtxt(paths["gyro.csv"], delimiter=",", skiprows=1)
    np.testing.assert_allclose(gyro[:, 1], sim.drive.gyro.yaw_rate_radps, atol=1e-7)
    truth = np.loadtxt(paths["truth.csv"], delimiter=",", skiprows=1)
    assert truth.shape[1] == 5
    assert json.loads(paths["noise.json"].read_text())["seed"] == 4

    from mcap_ros2.reader import read_ros2_messages

    topics = {}
    for m in read_ros2_messages(str(paths["drive.mcap"])):
        topics.setdefault(m.channel.topic, []).append(m.ros_msg)
    assert len(topics["/imu"]) == len(sim.drive.gyro)
    assert len(topics["/vehicle/twist"]) == len(sim.drive.odo)
    fixes = topics["/gnss/fix"]
    assert len(fixes) == len(sim.drive.gnss)
    ok = sim.drive.gnss.valid
    lat = np.array([f.latitude for f in fixes])
    np.testing.assert_allclose(lat[ok], sim.drive.gnss.lat_deg[ok], atol=1e-12)
    var_e = np.array([f.position_covariance[0] for f in fixes])
    np.testing.assert_allclose(np.sqrt(var_e[ok]), sim.drive.gnss.sigma_e_m[ok], rtol=1e-9)


def test_oracle_params_only_known_keys(urban):
    p = oracle_params(urban.noise, defaults())
    for section, values in p.items():
        assert set(values) == set(DEFAULTS[section])
    assert p["gyro"]["noise_sd_radps"] == pytest.approx(urban.noise["gyro_noise_sd_radps"])
    assert p["gyro"]["bias_tau_s"] == pytest.approx(urban.noise["gyro_bias_tau_s"])
    # fkf: both eps regimes get the one environment's multipath (the urban canyon has one)
    env = urban.noise["gnss_environments"]["urban"]
    for prefix in ("gnss_err_", "gnss_err_obstructed_"):
        assert p["fkf"][prefix + "sd_m"] == pytest.approx(env["multipath_sd_m"])
        assert p["fkf"][prefix + "tau_s"] == pytest.approx(env["multipath_tau_s"])
        assert p["fkf"][prefix + "dist_m"] == pytest.approx(env["multipath_decorrelation_m"])
    # ekf/aekf multipath states: the urban environment's time constant and distance
    assert p["aekf"]["gnss_err_sd_m"] == pytest.approx(urban.noise["multipath_sd_m"])
    assert p["aekf"]["gnss_err_tau_s"] == pytest.approx(env["multipath_tau_s"])
    assert p["aekf"]["gnss_err_dist_m"] == pytest.approx(env["multipath_decorrelation_m"])
    od = oracle_drive(urban)
    ok = od.gnss.valid
    np.testing.assert_allclose(od.gnss.sigma_e_m[ok], urban.gnss_errors["true_sd_m"][ok])
    assert np.all(od.gnss.sigma_e_m[ok] >= urban.drive.gnss.sigma_e_m[ok] - 1e-12)


def test_oracle_drive_white_only_for_multipath_states(urban):
    od = oracle_drive(urban, multipath_in_sigma=False)
    ok = od.gnss.valid
    np.testing.assert_allclose(od.gnss.sigma_e_m[ok], urban.gnss_errors["white_sd_m"][ok])
    assert np.all(np.isnan(od.gnss.sigma_e_m[~ok]))


def test_oracle_params_fkf_regimes_from_least_and_most_multipath():
    envs = {"open": {"multipath_sd_m": 0.4, "multipath_tau_s": 120.0, "multipath_decorrelation_m": 300.0},
            "urban": {"multipath_sd_m": 4.0, "multipath_tau_s": 60.0, "multipath_decorrelation_m": 50.0},
            "suburb": {"multipath_sd_m": 1.5, "multipath_tau_s": 90.0, "multipath_decorrelation_m": 100.0}}
    p = oracle_params({"gnss_environments": envs}, defaults())
    fkf = p["fkf"]
    assert (fkf["gnss_err_sd_m"], fkf["gnss_err_tau_s"], fkf["gnss_err_dist_m"]) == (0.4, 120.0, 300.0)
    assert (p["fkf"]["gnss_err_obstructed_sd_m"], p["fkf"]["gnss_err_obstructed_tau_s"],
            p["fkf"]["gnss_err_obstructed_dist_m"]) == (4.0, 60.0, 50.0)


# --------------------------------------------------------------------------- newer scenarios

#: the older scenarios' drives (seed 1, 120 s) as they were before the newer scenarios came:
#: their generators' draws must not change (the benchmark figures rest on them)
OLD_DRIVES = {
    "open_sky": (48.77604300917892, 0.0),
    "urban_canyon": (50.114025480777265, 7.754439088193602),
    "stop_and_go": (48.13567924276877, 0.0),
    "one_hour": (52.517912111013395, 8.004439088193603),
}


@pytest.mark.parametrize("scenario", sorted(OLD_DRIVES))
def test_older_scenarios_unchanged(scenario):
    sim = simulate_drive(scenario, seed=1, duration_s=120.0)
    lat_last, odo_last = OLD_DRIVES[scenario]
    assert sim.drive.gnss.lat_deg[-1] == pytest.approx(lat_last, abs=1e-12)  # deg
    assert sim.drive.odo.speed_mps[-1] == pytest.approx(odo_last, abs=1e-12)  # m/s
    assert sim.drive.gyro.yaw_rate_radps[-1] == pytest.approx(-0.0032410218687095533, abs=1e-15)
    assert sim.drive.accel is None


def _fix_errors(sim):
    """Per fix: east and north error against the truth (m)."""
    g = sim.drive.gnss
    e, n = sim.frame.forward(g.lat_deg, g.lon_deg)
    t = sim.truth["t_ns"].to_numpy()
    return e - np.interp(g.t_ns, t, sim.truth["e"]), n - np.interp(g.t_ns, t, sim.truth["n"])


@pytest.fixture(scope="module")
def nlos():
    return simulate_drive("urban_nlos", seed=2)


def test_urban_nlos_steps(nlos):
    g, ge, nz = nlos.drive.gnss, nlos.gnss_errors, nlos.noise
    steps = nz["nlos_steps"]
    assert len(steps) >= 10
    mags = np.array([s["magnitude_m"] for s in steps])
    durs = np.array([s["duration_s"] for s in steps])
    assert mags.min() >= 10.0 and mags.max() <= 80.0          # m
    assert durs.min() >= 5.0 and durs.max() <= 60.0           # s
    assert 1.5 <= nz["nlos_steps_per_canyon_min"] <= 4.0      # several per minute in canyons
    assert 0.3 <= nz["nlos_fix_share"] <= 0.8
    # the step's plateau is its magnitude: recorded bias at the step's middle fixes (1 mm)
    for sid, s in enumerate(steps):
        k = np.flatnonzero(ge["nlos_step"].to_numpy() == sid)
        mid = k[len(k) // 2]
        assert np.hypot(ge["nlos_bias_e"][mid], ge["nlos_bias_n"][mid]) == pytest.approx(
            s["magnitude_m"], abs=1e-3)
        # inside a canyon section and not beyond it
        assert ge["canyon"].to_numpy()[k].all()
    # most steps lie across the street
    assert np.mean([s["across_street"] for s in steps]) > 0.5
    # the fixes' error is the step: within 3 m of bias + drift on every NLOS fix
    de, dn = _fix_errors(nlos)
    on = ge["nlos"].to_numpy() & g.valid
    base_e = de - ge["nlos_e"].to_numpy()
    base_n = dn - ge["nlos_n"].to_numpy()
    assert np.sqrt(np.mean(base_e[on] ** 2 + base_n[on] ** 2)) < 3.0
    err = np.hypot(de, dn)
    assert np.median(err[on]) > 15.0  # m: NLOS fixes are tens of metres off
    # consistent among themselves: fix-to-fix error changes on the plateau stay small
    plateau = on & (np.hypot(ge["nlos_bias_e"], ge["nlos_bias_n"]).to_numpy()
                    >= 0.999 * np.array([0.0] + [s["magnitude_m"] for s in steps])[
                        ge["nlos_step"].to_numpy() + 1])
    both = plateau[1:] & plateau[:-1] & (np.diff(ge["nlos_step"].to_numpy()) == 0)
    jumps = np.hypot(np.diff(de), np.diff(dn))[both]
    assert np.percentile(jumps, 99) < 5.0  # m, against 10-80 m steps
    # the receiver reports nothing of it: HDOP 0.6-1.3, GST 0.5-3 m, quality 1
    ok = g.valid
    assert np.nanmin(g.hdop[ok]) >= 0.6 and np.nanmax(g.hdop[ok]) <= 1.3
    assert np.nanmin(g.sigma_e_m[ok]) >= 0.5 and np.nanmax(g.sigma_e_m[ok]) <= 3.0
    assert set(np.unique(g.fix_quality[ok])) == {1}
    # the Doppler velocity is off in a step (1 m/s bias per step and axis), honest elsewhere
    t = nlos.truth["t_ns"].to_numpy()
    moving = ok & np.isfinite(g.course_deg)
    ve = g.speed_mps * np.sin(np.radians(g.course_deg)) - np.interp(g.t_ns, t, nlos.truth["v_e"])
    vn = g.speed_mps * np.cos(np.radians(g.course_deg)) - np.interp(g.t_ns, t, nlos.truth["v_n"])
    v_err = np.hypot(ve, vn)
    assert 0.7 < np.sqrt(np.mean(v_err[moving & on] ** 2)) < 2.5   # m/s
    assert np.sqrt(np.mean(v_err[moving & ~on] ** 2)) < 0.15      # m/s
    # open sky between canyons: ordinary errors (metres at most)
    open_sky = ok & ~ge["canyon"].to_numpy()
    assert open_sky.sum() > 300
    assert np.sqrt(np.mean(err[open_sky] ** 2)) < 3.0


def test_urban_nlos_doppler_error_proportional_to_speed(monkeypatch):
    """``NLOS_VEL_MODEL = "speed"``: in a reflection the receiver's velocity error is a linear
    map of the true velocity (a wall mirrors it), so a stop inside a step reads no speed,
    while a step at speed reads a velocity error of about a tenth of it."""
    from gpsdr_cli import simulate

    monkeypatch.setattr(simulate, "NLOS_VEL_MODEL", "speed")
    sim = simulate_drive("urban_nlos", seed=2)
    g, ge = sim.drive.gnss, sim.gnss_errors
    on = ge["nlos"].to_numpy() & g.valid
    t = sim.truth["t_ns"].to_numpy()
    tve, tvn = np.interp(g.t_ns, t, sim.truth["v_e"]), np.interp(g.t_ns, t, sim.truth["v_n"])
    true_speed = np.hypot(tve, tvn)
    err = np.hypot(ge["nlos_vel_e"].to_numpy(), ge["nlos_vel_n"].to_numpy())
    stopped = on & (true_speed < 0.05)
    fast = on & (true_speed > 8.0)
    assert stopped.sum() > 20 and fast.sum() > 200
    assert np.max(err[stopped]) < 0.05                      # m/s (a step's bias: 1 m/s)
    share = np.sqrt(np.mean((err[fast] / true_speed[fast]) ** 2))
    assert 0.05 < share < 0.3
    assert sim.noise["nlos_velocity_model"] == "speed"


def test_urban_nlos_oracle_drops_nlos_fixes(nlos):
    od = oracle_drive(nlos)
    on = nlos.gnss_errors["nlos"].to_numpy()
    assert not od.gnss.valid[on].any()
    assert od.gnss.valid[~on].sum() == nlos.drive.gnss.valid[~on].sum()
    de, dn = _fix_errors(type(nlos)(**{**nlos.__dict__, "drive": od}))
    ok = od.gnss.valid
    assert np.sqrt(np.mean(de[ok] ** 2 + dn[ok] ** 2)) < 3.0  # m: what is left is honest


def test_urban_nlos_written_as_quality_1(tmp_path):
    from gpsdr_cli.io.nmea import read_nmea

    sim = simulate_drive("urban_nlos", seed=3, duration_s=120.0)
    paths = write_drive(sim, tmp_path, mcap=False)
    back = read_nmea(paths["gps.nmea"]).gnss
    ok = sim.drive.gnss.valid
    assert set(np.unique(back.fix_quality[back.valid])) == {1}
    np.testing.assert_allclose(back.hdop[back.valid], sim.drive.gnss.hdop[ok], atol=0.005)
    np.testing.assert_allclose(back.sigma_e_m[back.valid], sim.drive.gnss.sigma_e_m[ok], atol=5e-4)


@pytest.fixture(scope="module")
def rtk():
    return simulate_drive("rtk", seed=1)


def test_rtk_qualities_sigmas_and_errors(rtk):
    g, ge, nz = rtk.drive.gnss, rtk.gnss_errors, rtk.noise
    assert rtk.drive.odo is None
    assert np.all(np.diff(g.t_ns) == NS_PER_S // 4)  # 4 Hz
    assert np.all(np.diff(rtk.drive.gyro.t_ns) == NS_PER_S // 100)  # 100 Hz gyro
    ok = g.valid
    assert ok.all()
    q = g.fix_quality
    false = ge["false_fix"].to_numpy()
    fixed = (q == 4) & ~false
    flt = q == 5
    assert set(np.unique(q)) == {4, 5}
    assert 0.6 <= fixed.mean() <= 0.9 and 0.08 <= flt.mean() <= 0.35
    assert 0.01 <= false.mean() <= 0.15
    # fixed: GST 1-2.5 cm, and the error is of that size (per-axis RMS within 20 %)
    assert g.sigma_e_m[fixed].min() >= 0.01 and g.sigma_e_m[fixed].max() <= 0.025
    de, dn = _fix_errors(rtk)
    z = np.concatenate([de[fixed] / g.sigma_e_m[fixed], dn[fixed] / g.sigma_n_m[fixed]])
    assert abs(np.sqrt(np.mean(z**2)) - 1.0) < 0.2
    assert np.max(np.hypot(de[fixed], dn[fixed])) < 0.15  # m
    # float: 0.1-0.5 m, errors of that size
    assert g.sigma_e_m[flt].min() >= 0.1 - 1e-12 and g.sigma_e_m[flt].max() <= 0.5
    zf = np.concatenate([de[flt] / g.sigma_e_m[flt], dn[flt] / g.sigma_n_m[flt]])
    assert abs(np.sqrt(np.mean(zf**2)) - 1.0) < 0.3
    # false fixes: quality 4 reported at cm, the position off by 0.2-1 m for 5-30 s
    assert np.all(q[false] == 4)
    assert g.sigma_e_m[false].max() <= 0.025
    ff = nz["rtk_false_fixes"]
    assert 2 <= len(ff) <= 5
    rel = (g.t_ns - g.t_ns[0]) / NS_PER_S
    for f in ff:
        assert 0.2 <= f["jump_m"] <= 1.0 and 5.0 <= f["duration_s"] <= 30.0
        sel = (rel >= f["start_s"]) & (rel < f["start_s"] + f["duration_s"])
        off = np.hypot(de[sel], dn[sel])
        assert abs(np.median(off) - f["jump_m"]) < 0.06  # m: the jump plus cm noise
        assert np.all(q[sel] == 4)


def test_rtk_has_a_parked_stretch(rtk):
    v = rtk.truth["speed"].to_numpy()
    stopped = v < 1e-3
    d = np.diff(np.concatenate(([0], stopped.astype(np.int8), [0])))
    lengths = (np.flatnonzero(d == -1) - np.flatnonzero(d == 1)) * 0.01
    assert lengths.max() >= 119.0  # s


def test_rtk_oracle_knows_false_fixes_and_lowers_the_floor(rtk):
    od = oracle_drive(rtk)
    false = rtk.gnss_errors["false_fix"].to_numpy()
    assert od.gnss.valid.all()
    # a false fix's oracle sigma holds its jump: per axis |jump| / sqrt(2) at least
    jump = np.hypot(rtk.gnss_errors["jump_e"], rtk.gnss_errors["jump_n"]).to_numpy()
    assert np.all(od.gnss.sigma_e_m[false] >= jump[false] / np.sqrt(2) - 1e-12)
    assert np.all(od.gnss.sigma_e_m[false] >= 0.14)  # m, against 1-2.5 cm reported
    assert np.all(od.gnss.sigma_e_m[~false] <= 0.5 + 1e-12)
    p = oracle_params(rtk.noise, defaults())
    assert p["gnss"]["sigma_min_m"] <= 0.01


@pytest.fixture(scope="module")
def no_odo():
    return simulate_drive("no_odometer", seed=2)


def test_no_odometer_outages_while_braking_and_accelerating(no_odo):
    g, nz, tr = no_odo.drive.gnss, no_odo.noise, no_odo.truth
    assert no_odo.drive.odo is None
    outs = nz["brake_outages"]
    assert len(outs) >= 6
    assert {o["kind"] for o in outs} == {"braking", "accelerating"}
    rel_fix = (g.t_ns - g.t_ns[0]) / NS_PER_S
    t = (tr["t_ns"].to_numpy() - tr["t_ns"].iloc[0]) / NS_PER_S
    v = tr["speed"].to_numpy()
    acc = np.gradient(v, 0.01)
    for o in outs:
        assert o["duration_s"] == 15.0
        inside = (rel_fix >= o["start_s"]) & (rel_fix < o["start_s"] + 15.0)
        assert inside.sum() == 60 and not g.valid[inside].any()  # 15 s at 4 Hz
        m = (t >= o["start_s"]) & (t < o["start_s"] + 15.0)
        # the car brakes to a standstill / drives off from one inside the window (m/s)
        assert v[m].min() < 0.05 and v[m].max() > 5.0
        if o["kind"] == "braking":
            assert acc[m].min() < -1.0  # m/s^2
            assert v[m][0] > 5.0
        else:
            assert acc[m].max() > 1.0
            assert v[m][0] < 0.05 and v[m][-1] > 5.0
    # outside the windows: RTK fixed throughout
    out = np.zeros(len(g), bool)
    for o in outs:
        out |= (rel_fix >= o["start_s"]) & (rel_fix < o["start_s"] + 15.0)
    assert g.valid[~out].all() and np.all(g.fix_quality[~out] == 4)


def test_no_odometer_accelerometer_model(no_odo):
    a, tr, nz = no_odo.drive.accel, no_odo.truth, no_odo.noise
    np.testing.assert_array_equal(a.t_ns, no_odo.drive.gyro.t_ns)
    f = tr["accel_fwd"].to_numpy()
    pitch = np.radians(tr["pitch_deg"].to_numpy())
    assert 3.0 < np.degrees(np.max(np.abs(pitch))) < 6.0  # grades of 5-10 %
    # f = d(road speed)/dt + g sin(pitch): standing on a slope it reads g sin(pitch) ...
    v = tr["speed"].to_numpy()
    still = np.convolve(v < 1e-9, np.ones(5), "same") == 5
    assert still.sum() > 500 and np.max(np.abs(pitch[still])) > np.radians(0.5)
    np.testing.assert_allclose(f[still], 9.80665 * np.sin(pitch[still]), atol=1e-9)
    # ... and f minus gravity integrates to the road speed (horizontal speed / cos(pitch))
    v_road = v / np.cos(pitch)
    dv = np.concatenate(([0.0], np.cumsum(0.5 * np.diff(np.arange(len(v)) * 0.01)
                                          * ((f - 9.80665 * np.sin(pitch))[1:]
                                             + (f - 9.80665 * np.sin(pitch))[:-1]))))
    assert np.max(np.abs(v_road[0] + dv - v_road)) < 0.05  # m/s over the 10-min drive
    resid = a.accel_mps2 - (1 + nz["accel_scale_error"]) * f
    assert abs(np.std(np.diff(resid)) / np.sqrt(2) / nz["accel_noise_sd_mps2"] - 1.0) < 0.05
    assert abs(np.mean(resid[:500]) - nz["accel_bias_initial_mps2"]) < 0.01  # m/s^2


def test_write_drive_without_odometer_with_accel(tmp_path, no_odo):
    from gpsdr_cli.io.csv import read_gyro_csv

    paths = write_drive(no_odo, tmp_path)
    assert "odo.csv" not in paths and not (tmp_path / "odo.csv").exists()
    assert paths["gyro.csv"].read_text().splitlines()[0] == "t,yaw_rate,acc_x"
    back = read_gyro_csv(paths["gyro.csv"], defaults()["gyro"])
    np.testing.assert_array_equal(back.accel.t_ns, no_odo.drive.accel.t_ns)
    # written with 6 decimals: parsed back within 1e-6 m/s^2
    assert np.max(np.abs(back.accel.accel_mps2 - no_odo.drive.accel.accel_mps2)) <= 1e-6
    np.testing.assert_allclose(back.gyro.yaw_rate_radps, no_odo.drive.gyro.yaw_rate_radps, atol=1e-7)
    assert "accel" in back.sources[0].streams

    from mcap_ros2.reader import read_ros2_messages

    imu = [m.ros_msg for m in read_ros2_messages(str(paths["drive.mcap"]), topics=["/imu"])]
    acc = np.array([m.linear_acceleration.x for m in imu])
    np.testing.assert_allclose(acc, no_odo.drive.accel.accel_mps2, atol=1e-12)


def test_accel_onto_epochs_and_fuse_option(tmp_path, no_odo):
    """The accelerometer reaches the epochs from gyro.csv's acc_x column and from --accel."""
    from click.testing import CliRunner

    from gpsdr_cli.align import build_epochs
    from gpsdr_cli.cli.main import cli
    from gpsdr_cli.io.readers import read_drive

    sim = simulate_drive("no_odometer", seed=2, duration_s=60.0)
    paths = write_drive(sim, tmp_path, mcap=False)
    p = defaults()
    drive = read_drive(gps=paths["gps.nmea"], gyro=paths["gyro.csv"], params=p)
    ep = build_epochs(drive, sim.frame, p)
    np.testing.assert_array_equal(ep.has_accel, ep.has_gyro)  # one IMU: same stamps
    a = sim.drive.accel
    k = np.searchsorted(ep.t_ns, a.t_ns)
    assert np.max(np.abs(ep.accel_mps2[k] - a.accel_mps2)) <= 1e-6  # m/s^2
    assert np.all(np.isnan(ep.accel_mps2[~ep.has_accel]))
    # a separate t,acc_x file, shifted by 5 ms: its own epochs, NaN at the gyro's
    acc = tmp_path / "accel.csv"
    with acc.open("w") as fh:
        fh.write("t,acc_x\n")
        for t, x in zip(a.t_ns + 5_000_000, a.accel_mps2, strict=True):
            fh.write(f"{t // NS_PER_S}.{t % NS_PER_S:09d},{x:.6f}\n")
    drive2 = read_drive(gps=paths["gps.nmea"], gyro=paths["gyro.csv"], accel=acc, params=p)
    ep2 = build_epochs(drive2, sim.frame, p)
    assert ep2.has_accel.sum() == len(a) and not (ep2.has_accel & ep2.has_gyro).any()
    k2 = np.searchsorted(ep2.t_ns, a.t_ns + 5_000_000)
    assert np.max(np.abs(ep2.accel_mps2[k2] - a.accel_mps2)) <= 1e-6
    assert any("accel" in s.streams and s.path == str(acc) for s in drive2.sources)
    # epochs built without the accelerometer: False / NaN
    drive.accel = None
    ep3 = build_epochs(drive, sim.frame, p)
    assert not ep3.has_accel.any() and np.all(np.isnan(ep3.accel_mps2))
    # the CLI option
    bad = tmp_path / "bad.csv"
    bad.write_text("t,ax\n1715673600.0,0.1\n")
    r = CliRunner().invoke(cli, ["fuse", "--gps", str(paths["gps.nmea"]), "--gyro",
                                 str(paths["gyro.csv"]), "--accel", str(bad), "-o",
                                 str(tmp_path / "t.parquet")])
    assert r.exit_code != 0 and "bad.csv" in r.output and "acc_x" in r.output


def test_cli_simulate_rtk_without_odometer(tmp_path):
    from click.testing import CliRunner

    from gpsdr_cli.cli.main import cli
    from gpsdr_cli.io.nmea import read_nmea

    r = CliRunner().invoke(cli, ["simulate", "-o", str(tmp_path), "--scenario", "rtk",
                                 "--seed", "1", "--duration", "60"])
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "odo.csv").exists() and (tmp_path / "drive.mcap").exists()
    assert (tmp_path / "gyro.csv").read_text().splitlines()[0] == "t,yaw_rate"  # no accelerometer
    g = read_nmea(tmp_path / "gps.nmea").gnss
    assert set(np.unique(g.fix_quality)) <= {4, 5}
    assert np.all(np.diff(g.t_ns) == NS_PER_S // 4)
    fixed = g.fix_quality == 4
    assert np.nanmax(g.sigma_e_m[fixed]) <= 0.025 + 5e-4  # m: GST written to the millimetre


def test_gyro_phase_stamps_the_gyro_apart_from_the_odometer(monkeypatch) -> None:
    """``GYRO_PHASE_S`` = 0.1 at 5 Hz: every gyro stamp 0.1 s after an odometer stamp, each
    reading the true yaw rate at its own stamp (the scale error, bias and noise aside: within
    0.05 rad/s at the median); 0 keeps the drive bit for bit."""
    from gpsdr_cli import simulate

    base = simulate_drive("urban_canyon", seed=3, duration_s=60.0, gyro_rate_hz=5, odo_rate_hz=5)
    monkeypatch.setattr(simulate, "GYRO_PHASE_S", 0.0)
    again = simulate_drive("urban_canyon", seed=3, duration_s=60.0, gyro_rate_hz=5, odo_rate_hz=5)
    np.testing.assert_array_equal(again.drive.gyro.yaw_rate_radps, base.drive.gyro.yaw_rate_radps)
    monkeypatch.setattr(simulate, "GYRO_PHASE_S", 0.1)
    sim = simulate_drive("urban_canyon", seed=3, duration_s=60.0, gyro_rate_hz=5, odo_rate_hz=5)
    t_g, t_o = sim.drive.gyro.t_ns, sim.drive.odo.t_ns
    n = min(len(t_g), len(t_o))
    np.testing.assert_array_equal(t_g[:n] - t_o[:n], 100_000_000)
    truth = np.interp(t_g, sim.truth["t_ns"], sim.truth["yaw_rate"])
    assert np.median(np.abs(sim.drive.gyro.yaw_rate_radps - truth)) < 0.05
    early = np.interp(t_g - 100_000_000, sim.truth["t_ns"], sim.truth["yaw_rate"])
    assert np.sqrt(np.mean((sim.drive.gyro.yaw_rate_radps - truth) ** 2)) < \
        np.sqrt(np.mean((sim.drive.gyro.yaw_rate_radps - early) ** 2))
