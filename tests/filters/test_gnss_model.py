"""The shared GNSS error model (gpsdr_cli.filters.gnss_model and align.base_sigma):
fix quality decides the noise, and fixes whose chords disagree with the dead reckoning
(NLOS) are down-weighted.  Errors against the simulator's truth, in metres."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gpsdr_cli import config, qc, simulate
from gpsdr_cli.align import base_sigma, build_epochs
from gpsdr_cli.filters.gnss_model import (
    chord_mismatch_m,
    chord_vector_mismatch_m,
    densest_ratio,
    doppler_against_odometer,
    doppler_off_share,
    gnss_error_model,
)
from gpsdr_cli.testing.faults import drop_streams, with_drive
from gpsdr_cli.testing.sim import run_filter


def test_base_sigma_follows_fix_quality():
    p = config.defaults()
    hdop = np.array([0.8, 0.8, 0.8, 0.8])
    nan = np.full(4, np.nan)
    q = np.array([4, 5, 1, 4])
    gst = np.array([np.nan, np.nan, np.nan, 0.015])
    sd_e, _ = base_sigma(gst, gst, hdop, p, q)
    assert sd_e[0] == pytest.approx(0.8 * 0.03 / np.sqrt(2.0), rel=1e-12)   # RTK fixed
    assert sd_e[1] == pytest.approx(0.8 * 0.4 / np.sqrt(2.0), rel=1e-12)    # RTK float
    assert sd_e[2] == pytest.approx(0.8 * 2.5 / np.sqrt(2.0), rel=1e-12)    # autonomous
    assert sd_e[3] == pytest.approx(0.015, rel=1e-12)                       # GST honoured
    # without HDOP an RTK-fixed fix is still centimetres, an autonomous one the default
    sd_e, _ = base_sigma(nan, nan, nan, p, np.array([4, 4, 1, 1]))
    assert sd_e[0] == pytest.approx(0.03 / np.sqrt(2.0))
    assert sd_e[2] == pytest.approx(5.0 / np.sqrt(2.0))


@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
def test_rtk_drive_follows_centimetre_fixes(name, smooth):
    """rtk scenario (GGA 4 at 1-2.5 cm, float stretches, false fixes, no odometer, a
    2-minute stop), seed 1: the track stays within 5 cm RMS of the right RTK-fixed fixes
    (0.11-0.13 m with the error states of one sigma per drive; ekf 0.11-0.13 m with one
    fix sigma for the float and the fixed fixes alike) with its sigma within 2 x of that,
    within 5 cm of the truth while parked on such fixes, and does not follow the false
    fixes."""
    sim = simulate.simulate_drive("rtk", seed=1)
    assert sim.drive.odo is None
    ep = build_epochs(sim.drive, sim.frame, config.defaults())
    assert ep.rtk_fixed_share > 0.5
    run = run_filter(sim, sim.drive, name, smooth=smooth)
    dev, sig, parked, on_false, false_fix = _rtk_figures(run, sim)
    assert dev < 0.05
    assert 0.5 * dev < sig < 2.0 * dev
    assert parked < 0.05
    assert on_false < 0.5 * false_fix  # followed, it would be ~1 x
    assert run.rmse_m < 0.6 * run.gnss_rmse_m


def test_rtk_drive_bias_regime_per_fix_kind():
    """aekf.bias_variance on the rtk scenario: 2 cm at the centimetre fixes, 0.2 m at the
    float ones (quality 5), 2 m at the false ones; between fixes the last fix's; one
    regime (aekf.gnss_err_sd_m) on a drive that is not RTK."""
    from gpsdr_cli.filters.aekf import bias_variance
    from gpsdr_cli.filters.gnss_model import gnss_error_model as apply
    from gpsdr_cli.rtk_false_fix import centimetre_fixes

    sim = simulate.simulate_drive("rtk", seed=1, duration_s=300)
    p = config.defaults()
    ep, pp = apply(build_epochs(sim.drive, sim.frame, p), p)
    var = bias_variance(ep, pp)
    f = ep.has_gnss
    cm = centimetre_fixes(ep, pp)
    g = pp["gnss"]
    assert np.all(var[cm] == g["rtk_err_sd_m"] ** 2)
    assert np.all(var[f & ~cm & (ep.gnss_quality == 5)] == g["rtk_float_err_sd_m"] ** 2)
    assert np.all(var[f & ~cm & (ep.gnss_quality != 5)] == g["rtk_free_err_sd_m"] ** 2)
    assert (f & ~cm & (ep.gnss_quality == 5)).any() and (f & ~cm & (ep.gnss_quality == 4)).any()
    k = np.flatnonzero(f)
    between = np.arange(k[0] + 1, k[1])
    assert np.all(var[between] == var[k[0]])
    # fkf: the same kinds as its two eps regimes (0 clear = centimetres, 1 the others,
    # float in between at its sigma), a new eps where the kind changes
    from gpsdr_cli.filters import kernels_fkf as kf
    from gpsdr_cli.filters.fkf_inputs import multipath_regime

    w = multipath_regime(ep, pp)
    reset = w >= kf.EPS_RESET
    w = np.mod(w, kf.EPS_RESET)
    assert np.all(w[cm] == 0.0) and np.all(w[f & ~cm & (ep.gnss_quality != 5)] == 1.0)
    sd2 = (1 - w) * g["rtk_err_sd_m"] ** 2 + w * g["rtk_free_err_sd_m"] ** 2
    np.testing.assert_allclose(sd2, var, rtol=1e-12)
    np.testing.assert_array_equal(reset[1:], np.diff(var) != 0.0)
    assert 4 <= reset.sum() < f.sum() // 20
    city = simulate.simulate_drive("urban_canyon", seed=1, duration_s=60)
    ep2, pp2 = apply(build_epochs(city.drive, city.frame, p), p)
    assert np.all(bias_variance(ep2, pp2) == pp2["aekf"]["gnss_err_sd_m"] ** 2)


def test_nlos_steps_are_down_weighted_for_ekf():
    """urban_nlos (steps of 10-80 m for 5-60 s under a good HDOP): the chords betray the
    steps, and ekf ends well below the fixes' error; without the check it is at or above
    the fixes'."""
    sim = simulate.simulate_drive("urban_nlos", seed=2)
    run = run_filter(sim, sim.drive, "ekf")
    off = run_filter(sim, sim.drive, "ekf", overrides={"gnss": {"nlos_mismatch_m": 0.0}})
    rms = lambda a: float(np.sqrt(np.mean(a ** 2)))  # noqa: E731
    gnss = rms(run.gnss_err_m)
    assert rms(run.err_m) < 0.75 * gnss
    assert rms(off.err_m) > 0.95 * gnss


@pytest.mark.parametrize("scenario", ["open_sky", "tunnels"])
def test_clean_drives_untouched(scenario):
    """Open-sky fixes agree with the odometer: no fix is re-weighted, the parameters stay."""
    sim = simulate.simulate_drive(scenario, seed=1)
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    mis = chord_mismatch_m(ep, 2.0)
    assert np.nanmax(mis) < 8.0
    ep2, p2 = gnss_error_model(ep, p)
    assert ep2 is ep and p2 is p


def _nlos_by_default_not_with(sim, key: str, value: float) -> None:
    """The drive is an NLOS drive with the defaults, and not with ``[gnss] key = value``
    (and the Doppler speeds' own call, ``nlos_doppler_share``, off: the chords are tested)."""
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    assert gnss_error_model(ep, p)[0].nlos_drive
    other = config.defaults()
    other["gnss"][key] = value
    other["gnss"]["nlos_doppler_share"] = 0.0
    assert not gnss_error_model(ep, other)[0].nlos_drive


def test_vector_chord_calls_a_drive_with_sideways_reflections_nlos():
    """A 283-s city drive (urban_nlos seed 17, gyro and odometer at 5 Hz) whose fixes are
    36.8 m RMS off, most of it across the street: the distance check marked no run of 3 s,
    the drive was not an NLOS drive, nothing screened the fixes, and aekf ended at 35.8 m
    and the graph smoother at 18.5 m.  The chords compared as vectors call it NLOS."""
    sim = simulate.simulate_drive("urban_nlos", 17, 283.0, gyro_rate_hz=5.0, odo_rate_hz=5.0)
    _nlos_by_default_not_with(sim, "nlos_vector_share", 0.0)
    run = run_filter(sim, sim.drive, "aekf", pipeline=True)
    assert run.result.info.get("nlos_screened", 0) > 500
    assert run.rmse_m < 0.2 * run.gnss_rmse_m


def test_vector_chord_sees_reflections_that_ramp_in_slowly(monkeypatch):
    """A 283-s city drive (urban_nlos seed 38, gyro and odometer at 5 Hz) whose reflections
    ramp in and out over 10-30 s, as a receiver that blends them in slowly gives them (fixes
    16.1 m RMS off): over 5 s a ramp moves the fixes off the dead reckoning by less than
    12 m, 7.7 % of the fixes were in such runs against the 8 % of an NLOS drive, and aekf +
    RTS followed the fixes to 16.4 m.  Over 8 s, 21 %: the screen runs, 0.9 m."""
    monkeypatch.setattr(simulate, "NLOS_RAMP_S", (10.0, 30.0))
    sim = simulate.simulate_drive("urban_nlos", 38, 283.0, gyro_rate_hz=5.0, odo_rate_hz=5.0)
    _nlos_by_default_not_with(sim, "nlos_vector_lag_s", 5.0)
    run = run_filter(sim, sim.drive, "aekf", smooth=True, pipeline=True)
    assert run.rmse_m < 0.2 * run.gnss_rmse_m


@pytest.mark.parametrize("odometer", [True, False])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_vector_chord_leaves_urban_canyons_alone(seed, odometer):
    """Canyon multipath (2 m, outliers, no steps): chords agree with the dead reckoning as
    vectors too, and the drive is not called NLOS (8-s chords: shares at most 0.05 on canyon
    drives of 150-600 s, forwards or backwards as the quality check runs them, against 0.08;
    decisions/0058); without an odometer, with the receiver's Doppler speed along the gyro
    heading."""
    sim = simulate.simulate_drive("urban_canyon", seed)
    if not odometer:
        sim = with_drive(sim, drop_streams(sim.drive, "odo"))
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    mis = chord_vector_mismatch_m(ep, 5.0)
    assert np.isfinite(mis).mean() > 0.9 and np.nanmedian(mis) < 10.0  # a wrong turn: ~the chord
    assert not gnss_error_model(ep, p)[0].nlos_drive
    assert not gnss_error_model(qc.reverse_epochs(ep), p)[0].nlos_drive


def test_vector_chord_without_an_odometer_rides_on_the_doppler_speed():
    """urban_nlos seed 35, 283 s, 5-Hz gyro, no odometer: fixes 31.7 m RMS off, mostly
    across the street, and the distance check alone did not call the drive NLOS (7 of 40
    such drives); fkf followed the fixes' steps with its clear-sky model to 39.7 m.  The
    vector chord with the Doppler speed calls it NLOS."""
    sim = simulate.simulate_drive("urban_nlos", 35, 283.0, gyro_rate_hz=5.0, odo_rate_hz=5.0)
    sim = with_drive(sim, drop_streams(sim.drive, "odo"))
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    assert np.isfinite(chord_vector_mismatch_m(ep, 5.0)).mean() > 0.8
    assert gnss_error_model(ep, p)[0].nlos_drive
    run = run_filter(sim, sim.drive, "fkf", pipeline=True)
    assert run.rmse_m < 1.1 * run.gnss_rmse_m  # was 1.25 x


def test_vector_chord_turns_by_the_votes_of_its_own_stretch():
    """A tunnel drive (150 s, seed 3) run backwards, as the quality check runs it: the turn
    between the dead reckoning's frame and east/north was taken as the median of the 150
    fixes around each one, so before a 30-s tunnel it mixed the votes of both sides (25 deg
    and 3 deg), and the 115-m chords at 23 m/s missed by 12-25 m: 8.7 % of the fixes, an NLOS
    drive.  The median is now over 30 s of time."""
    sim = simulate.simulate_drive("tunnels", 3, duration_s=150.0)
    p = config.defaults()
    p["time"]["gnss_offset_s"] = 0.0415  # what --gnss-offset auto estimates on this drive
    ep = qc.reverse_epochs(build_epochs(sim.drive, sim.frame, p))
    mis = chord_vector_mismatch_m(ep, 5.0)
    assert np.nanmax(mis) < 12.0


@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf"])
def test_outlier_burst_is_down_weighted(name):
    """Fixes 40 m off for 2 s: the chord check scales their sigma up, and the track stays
    within 3.5 m of the truth without a gate (4.5 m with neither the gate nor the check)."""
    from tests.filters import horizontal_error, tiny_drive

    ep, tr = tiny_drive(120.0, seed=11, dr_hz=20.0, outliers=((60.0, 62.0, 40.0),))
    p = config.defaults()
    p["gnss"]["gate"] = False
    ep2, _ = gnss_error_model(ep, p)
    window = (tr.t_s >= 60.0) & (tr.t_s < 62.0) & ep.has_gnss
    assert (ep2.gnss_sd_e[window] > 2.0 * ep.gnss_sd_e[window]).all()
    from gpsdr_cli.filters import get

    res = get(name)(ep, p)
    assert horizontal_error(res, tr)[tr.t_s > 10.0].max() < 3.5


def test_step_estimate_sees_a_jump_on_a_curve():
    """A car on a 30-m circle at 12 m/s, fixes at 4 Hz with 1.5 cm noise, and a 0.3 m jump
    from the 40th fix on: the step fit (Doppler velocity integrated) finds the jump to 3 cm
    at that fix and nothing above 0.1 m elsewhere, where a plain difference of fixes sees
    3 m per fix."""
    from gpsdr_cli.rtk_false_fix import step_estimates

    rng = np.random.default_rng(3)
    t = np.arange(80) * 0.25
    w = 12.0 / 30.0
    e, n = 30.0 * np.sin(w * t), 30.0 * np.cos(w * t)
    v_e, v_n = 12.0 * np.cos(w * t), -12.0 * np.sin(w * t)
    e = e + rng.normal(0, 0.015, 80) + np.where(np.arange(80) >= 40, 0.3, 0.0)
    n = n + rng.normal(0, 0.015, 80)
    v_e = v_e + rng.normal(0, 0.04, 80)
    v_n = v_n + rng.normal(0, 0.04, 80)
    se, sn, ss = step_estimates(t, e, n, np.full(80, 0.015), 4, 1.0, v_e, v_n)
    size = np.hypot(se, sn)
    assert abs(se[40] - 0.3) < 0.03 and abs(sn[40]) < 0.03
    others = np.isfinite(size) & (np.abs(np.arange(80) - 40) > 4)
    assert others.sum() > 50 and size[others].max() < 0.1
    assert np.all(ss[np.isfinite(ss)] < 0.03)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_false_rtk_fixes_found(seed):
    """rtk scenario: every false fix (a 0.2-1 m jump reported at 1-2.5 cm for 5-30 s) is
    found, and no right one is taken for false; build_epochs gives them the false fixes'
    sigma, so no filter or smoother weighs them at centimetres."""
    from gpsdr_cli.rtk_false_fix import centimetre_fixes, false_fixes

    sim = simulate.simulate_drive("rtk", seed=seed)
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    g = sim.drive.gnss
    truth = np.isin(ep.t_ns, g.t_ns[sim.gnss_errors["false_fix"].to_numpy(bool) & g.valid])
    assert truth.sum() > 100
    flagged = ep.has_gnss & (ep.gnss_sd_e >= p["gnss"]["rtk_false_sd_m"])
    assert np.array_equal(flagged, truth)
    # the raw sigmas (no check) are centimetres there, and the check on them agrees
    p_off = config.defaults()
    p_off["gnss"]["rtk_step_m"] = np.inf
    raw = build_epochs(sim.drive, sim.frame, p_off)
    assert raw.gnss_sd_e[truth].max() < 0.05
    assert np.array_equal(false_fixes(raw, p, centimetre_fixes(raw, p)), truth)


def _rtk_figures(run, sim):
    """At every epoch between two right RTK-fixed fixes at most 0.3 s apart: the RMS
    distance (m) of the track from the fixes interpolated there and the RMS reported sigma
    (m); the track's RMS error there while parked; and its RMS error during the false fixes
    against the fixes' own error there (m)."""
    ep, r = run.epochs, run.result
    g = sim.drive.gnss
    false = np.isin(ep.t_ns, g.t_ns[sim.gnss_errors["false_fix"].to_numpy(bool) & g.valid])
    f = np.flatnonzero(ep.has_gnss & (ep.gnss_sd_e < 0.05) & ~false)
    tf = ep.t_ns[f]
    i = np.clip(np.searchsorted(tf, ep.t_ns, side="right"), 1, len(f) - 1)
    ok = (ep.t_ns >= tf[0]) & (ep.t_ns < tf[-1]) & (tf[i] - tf[i - 1] <= 0.3e9)
    w = (ep.t_ns - tf[i - 1]) / (tf[i] - tf[i - 1])
    ie = ep.gnss_e[f[i - 1]] + w * (ep.gnss_e[f[i]] - ep.gnss_e[f[i - 1]])
    in_ = ep.gnss_n[f[i - 1]] + w * (ep.gnss_n[f[i]] - ep.gnss_n[f[i - 1]])
    rms = lambda a: float(np.sqrt(np.mean(a ** 2)))  # noqa: E731
    dev = rms(np.hypot(r.e - ie, r.n - in_)[ok])
    sig = rms(np.sqrt(r.var_e + r.var_n)[ok])
    parked = ok & (run.true_speed_mps < 0.01)
    fix_err = np.full(len(ep), np.nan)
    fix_err[ep.has_gnss] = run.gnss_err_m
    return dev, sig, rms(run.err_m[parked]), rms(run.err_m[false]), rms(fix_err[false])


def test_false_fix_check_needs_the_receivers_velocity():
    """Positions only (GGA without RMC): no step fit, so no fix is judged false -- a
    quadratic in time misfits city turns by as much as the smallest false fix."""
    import dataclasses

    from gpsdr_cli.rtk_false_fix import centimetre_fixes, false_fixes

    sim = simulate.simulate_drive("rtk", seed=1)
    p = config.defaults()
    p_off = config.defaults()
    p_off["gnss"]["rtk_step_m"] = np.inf
    ep = build_epochs(sim.drive, sim.frame, p_off)
    cm = centimetre_fixes(ep, p)
    assert false_fixes(ep, p, cm).sum() > 100
    nan = np.full(len(ep), np.nan)
    blind = dataclasses.replace(ep, gnss_speed_mps=nan, gnss_course_rad=nan)
    assert not false_fixes(blind, p, cm).any()


def test_doppler_off_the_odometer_is_left_out():
    """An open-sky drive (100-Hz odometer, its scale a few % off) with 40 fixes' Doppler
    speeds 1.5 m/s high and 40 more 1.5 m/s low, as reflected signals put them: exactly those
    lose their speed and course; the clean ones (within a few tenths of the scaled odometer,
    braking included) keep theirs, and their positions stay."""
    sim = simulate.simulate_drive("open_sky", seed=2, duration_s=300.0)
    ep = build_epochs(sim.drive, sim.frame, config.defaults())
    f = np.flatnonzero(ep.has_gnss & np.isfinite(ep.gnss_speed_mps) & (ep.gnss_speed_mps > 3.0))
    rng = np.random.default_rng(5)
    hit = rng.choice(f, 80, replace=False)
    speed = ep.gnss_speed_mps.copy()
    speed[hit[:40]] += 1.5
    speed[hit[40:]] -= 1.5
    biased = dataclasses.replace(ep, gnss_speed_mps=speed)
    out, n = doppler_against_odometer(biased, 1.0)
    assert n == 80
    gone = np.flatnonzero(ep.has_gnss & np.isfinite(ep.gnss_speed_mps) & ~np.isfinite(out.gnss_speed_mps))
    np.testing.assert_array_equal(np.sort(gone), np.sort(hit))
    assert np.all(np.isnan(out.gnss_course_rad[hit]))
    np.testing.assert_array_equal(out.has_gnss, ep.has_gnss)
    np.testing.assert_array_equal(out.gnss_e, ep.gnss_e)
    assert doppler_against_odometer(ep, 1.0)[1] == 0
    assert doppler_against_odometer(biased, 0.0)[1] == 0


def test_the_odometer_scale_from_the_speeds_that_agree():
    """Most of a city drive's Doppler speeds reflected, together high: the median ratio to the
    odometer reads the wheel 6 % off; the scale at which the most speeds agree within 0.2 m/s
    reads the clean ones' 1.02, and their misfits are the wheel's noise."""
    rng = np.random.default_rng(11)
    odo = rng.uniform(5.0, 15.0, 1000)
    dop = 1.02 * odo + rng.normal(0.0, 0.08, 1000)
    dop[:600] += rng.uniform(0.3, 1.5, 600)
    assert abs(float(np.median(dop / odo)) - 1.02) > 0.03
    assert abs(densest_ratio(dop, odo, 0.2) - 1.02) < 0.002


def test_the_share_of_doppler_speeds_off_the_odometer():
    """An open-sky drive (100-Hz odometer): no Doppler speed is 1 m/s off the wheel's, and
    the drive is not called NLOS.  With a tenth of them 1.5 m/s high (reflected) the share
    reads a tenth and the drive is an NLOS drive; a 30-s odometer dropout is not read as a
    line across it (no share), and without an odometer there is none."""
    sim = simulate.simulate_drive("open_sky", seed=2, duration_s=300.0)
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    assert ep.doppler_off_share == 0.0
    assert not gnss_error_model(ep, p)[0].nlos_drive
    f = np.flatnonzero(ep.has_gnss & (np.nan_to_num(ep.gnss_speed_mps) > 5.0))
    hit = np.random.default_rng(3).choice(f, len(f) // 10, replace=False)
    speed = ep.gnss_speed_mps.copy()
    speed[hit] += 1.5
    biased = dataclasses.replace(ep, gnss_speed_mps=speed)
    share = doppler_off_share(biased, p)
    assert 0.08 < share < 0.12
    assert gnss_error_model(dataclasses.replace(biased, doppler_off_share=share), p)[0].nlos_drive
    t_s = (ep.t_ns - ep.t_ns[0]) / 1e9
    gap = ep.has_odo & (t_s > 100.0) & (t_s < 130.0)
    dropout = dataclasses.replace(ep, has_odo=ep.has_odo & ~gap,
                                  odo_speed_mps=np.where(gap, np.nan, ep.odo_speed_mps))
    assert doppler_off_share(dropout, p) == 0.0
    no_odo = dataclasses.replace(ep, has_odo=np.zeros(len(ep), bool))
    assert doppler_off_share(no_odo, p) == 0.0
