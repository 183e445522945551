"""fkf/fafkf on a receiver that reports positions only (NMEA GGA without RMC/VTG, a ROS
NavSatFix): the course steering and the odometer scale come from chords between fixes
(:func:`gpsdr_cli.filters.fkf.fix_chords`), never from velocity rows."""

from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.filters import fkf
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.sim import run_filter


def _synthetic(seed: int = 7):
    """A 300-s curving drive at 10 m/s: fixes at 5 Hz with 1-m white noise per axis, a gyro
    heading off by 0.2 rad + 0.004 rad/s (misalignment and bias ramp), an odometer reading
    3 % high.  Returns (epochs-like fixes, t_s, tg, psi_gyro, true heading error, speed)."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(0.0, 300.0, dt)
    psi = 0.8 * np.sin(t / 25.0) + t / 60.0            # rad, clockwise from north
    v = np.full(len(t), 10.0)
    e = np.concatenate(([0.0], np.cumsum(v[1:] * np.sin(psi[1:]) * dt)))
    n = np.concatenate(([0.0], np.cumsum(v[1:] * np.cos(psi[1:]) * dt)))
    has = np.zeros(len(t), bool)
    has[::20] = True
    sd = 1.0
    ge = np.where(has, e + rng.normal(0.0, sd, len(t)), np.nan)
    gn = np.where(has, n + rng.normal(0.0, sd, len(t)), np.nan)
    ep = SimpleNamespace(has_gnss=has, gnss_e=ge, gnss_n=gn,
                         gnss_sd_e=np.full(len(t), sd), gnss_sd_n=np.full(len(t), sd))
    err = 0.2 + 0.004 * t
    return ep, t, t, psi + err, err, 1.03 * v


def test_chords_recover_the_heading_error_and_the_odometer_scale() -> None:
    ep, t_s, tg, psi_g, err, speed = _synthetic()
    p = config.defaults()
    eps_w = np.zeros(len(t_s))
    chords = fkf.fix_chords(ep, t_s, tg, psi_g, t_s, speed, eps_w, p)
    # chords long enough for 0.05 rad: sqrt(2 (1 + 1)) / 0.05 = 40 m, i.e. 4 s at 10 m/s
    assert len(chords.t_mid) > 1000
    assert np.all(np.abs(chords.dr) >= 40.0 * 1.03 - 1.0)   # m, dead-reckoned: 3 % long
    corr = fkf.chord_course_correction(chords, tg, p)
    resid = np.angle(np.exp(1j * (corr + err)))          # the correction should be -err
    assert np.sqrt(np.mean(resid ** 2)) < 0.004           # rad
    assert np.max(np.abs(resid)) < 0.02                   # rad, the ends included
    chords2 = fkf.fix_chords(ep, t_s, tg, psi_g + corr, t_s, speed, eps_w, p)
    k, k_med = fkf.chord_odometer_scale(chords2, t_s, p)
    assert abs(k_med * 1.03 - 1.0) < 0.003               # relative: 3 % scale found to 0.3 %
    assert np.all(np.abs(k * 1.03 - 1.0) < 0.005)


def test_chords_without_odometer_or_gyro() -> None:
    ep, t_s, tg, psi_g, err, speed = _synthetic()
    p = config.defaults()
    eps_w = np.zeros(len(t_s))
    # no odometer: the dead-reckoned chords take their speed from the chords (|g| / dt)
    chords = fkf.fix_chords(ep, t_s, tg, psi_g, None, None, eps_w, p)
    resid = np.angle(np.exp(1j * (fkf.chord_course_correction(chords, tg, p) + err)))
    assert np.sqrt(np.mean(resid ** 2)) < 0.004           # rad
    # no gyro: odometer distance along the straight chords gives the scale
    chords = fkf.fix_chords(ep, t_s, None, None, t_s, speed, eps_w, p)
    assert len(chords.t_mid) > 100
    _, k_med = fkf.chord_odometer_scale(chords, t_s, p)
    assert abs(k_med * 1.03 - 1.0) < 0.003               # relative


@pytest.fixture(scope="module")
def drives():
    return {s: simulate_drive(s, seed=1, duration_s=300.0) for s in ("open_sky", "urban_canyon")}


def _run(sim, name: str, smooth: bool, positions_only: bool) -> tuple[float, dict]:
    d = copy.deepcopy(sim.drive)
    if positions_only:
        d.gnss.speed_mps[:] = np.nan
        d.gnss.course_deg[:] = np.nan
    run = run_filter(sim, d, name, smooth)
    return run.rmse_m, run.result.info


# RMSE bounds in metres (positions only, seed 1, 300 s; GNSS alone: open sky 1.41 m, urban
# canyon 7.63 m).  The old code (course and odometer scale from the receiver only, so no
# heading steering and a 4.5 % odometer scale error left in) gave fkf / fafkf forward, RTS:
# open sky 9.24, 8.14 / 14.93, 12.51; urban 15.71, 13.97 / 11.90, 9.54.  With fix chords:
# open sky 0.77, 0.75 / 0.77, 0.75; urban 3.58, 2.57 / 3.60, 2.59.
BOUNDS_M = {(s, name, smooth): bound
            for s, bounds in (("open_sky", (0.95, 0.9)), ("urban_canyon", (4.3, 3.2)))
            for name in ("fkf", "fafkf") for smooth, bound in zip((False, True), bounds, strict=True)}


@pytest.mark.parametrize("scenario", ["open_sky", "urban_canyon"])
@pytest.mark.parametrize("name", ["fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
def test_positions_only_beats_gnss_alone(drives, scenario: str, name: str, smooth: bool) -> None:
    sim = drives[scenario]
    rmse, info = _run(sim, name, smooth, positions_only=True)
    assert info["course_source"] == "fix_chords"
    assert info["fix_chords"] > 500
    assert info["gnss_velocity_updates"] == 0       # the chords never become velocity rows
    assert rmse < BOUNDS_M[(scenario, name, smooth)]


def test_with_receiver_velocity_the_chords_stay_out(drives) -> None:
    _, info = _run(drives["open_sky"], "fkf", False, positions_only=False)
    assert "course_source" not in info
    assert info["heading_alignment"] == "gnss_course"
    assert info["gnss_velocity_updates"] > 0
