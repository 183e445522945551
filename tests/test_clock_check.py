"""Dead-reckoning clocks seconds off the receiver's (gpsdr_cli.clock_check).

Why: a CAN logger in GPS time beside NMEA in UTC is 18 s off; every filter then joins each
fix to the dead reckoning of another moment.  On the simulated city drive aekf went from
2.8 m to 28-43 m RMSE against fixes at 7.7 m.
"""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli import clock_check, config
from gpsdr_cli.pipeline import fuse
from gpsdr_cli.simulate import simulate_drive

COMMA = Path(__file__).resolve().parents[1] / "sample_logs" / "comma2k19"


def _shifted(drive, shift_s: float):
    d = copy.deepcopy(drive)
    ns = np.int64(round(shift_s * 1e9))
    if d.odo is not None:
        d.odo = dataclasses.replace(d.odo, t_ns=d.odo.t_ns + ns)
    if d.gyro is not None:
        d.gyro = dataclasses.replace(d.gyro, t_ns=d.gyro.t_ns + ns)
    return d


def test_offset_of_a_scaled_shifted_signal() -> None:
    """A speed profile logged 18 s late with a 3 % scale error: the offset is -18 s to 0.01 s
    (the scale is fitted, so it does not tilt the lag)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 300.0, 0.2)
    v = 10.0 + 5.0 * np.sin(t / 17.0) + 3.0 * np.sin(t / 5.3)
    ref = v + rng.normal(0.0, 0.2, len(t))
    tx = np.arange(0.0, 300.0, 0.01)
    vx = 1.03 * np.interp(tx, t, v)
    res = clock_check.find_offset(t, ref, tx + 18.0, vx, 120.0, 0.5, 1.0)
    assert res.applied and res.offset_s == pytest.approx(-18.0, abs=0.011)
    res = clock_check.find_offset(t, ref, tx + 0.05, vx, 120.0, 0.5, 1.0)
    assert not res.applied and res.offset_s == pytest.approx(-0.05, abs=0.011)


@pytest.mark.parametrize("scenario", ["urban_canyon", "urban_nlos", "rtk", "no_odometer"])
def test_no_offset_where_the_clocks_agree(scenario: str) -> None:
    sim = simulate_drive(scenario, 1)
    p, notes = clock_check.check(sim.drive, config.defaults())
    assert notes == [] and p["time"]["odo_offset_s"] == 0.0 and p["time"]["gyro_offset_s"] == 0.0


def test_an_18_s_logger_clock_is_found_and_fused_right() -> None:
    """The gyro and odometer stamped 18 s late (GPS time against NMEA's UTC)."""
    sim = simulate_drive("urban_canyon", 1)
    d = _shifted(sim.drive, 18.0)
    p, notes = clock_check.check(d, config.defaults())
    assert p["time"]["odo_offset_s"] == pytest.approx(-18.0, abs=0.1)
    assert p["time"]["gyro_offset_s"] == pytest.approx(-18.0, abs=0.1)
    assert len(notes) == 2 and "clock" in notes[0]
    truth = sim.truth[["t_ns", "lat", "lon"]]
    res = fuse(d, config.defaults(), truth)
    assert any("clock is +18" in w for w in res.drive_warnings)
    fixes = fuse(d, config.defaults() | {"time": config.defaults()["time"] | {"dr_clock_check": False}},
                 truth)
    # without the check: 28 m against the fixes' 7.7 m
    assert fixes.summary()["rmse_m"] > 15.0
    assert res.summary()["rmse_m"] < 0.5 * fixes.summary()["rmse_m"]
    assert res.summary()["rmse_m"] < 4.0


def test_a_user_offset_is_left_alone() -> None:
    sim = simulate_drive("urban_canyon", 1)
    p0 = config.defaults()
    p0["time"]["odo_offset_s"] = -0.05
    p, notes = clock_check.check(_shifted(sim.drive, 18.0), p0)
    assert notes == [] and p["time"]["gyro_offset_s"] == 0.0


def test_the_real_drive_is_not_moved() -> None:
    """comma2k19: u-blox fixes, CAN speed, a phone gyro, one clock (about 0.1 s of latency)."""
    from gpsdr_cli.io.readers import read_drive

    drive = read_drive(gps=COMMA / "gps.nmea", gyro=COMMA / "gyro.csv", odo=COMMA / "odo.csv",
                       params=config.defaults())
    p, notes = clock_check.check(drive, config.defaults())
    assert notes == [] and p["time"]["odo_offset_s"] == 0.0


def _gnss_step_back(drive, at_s: float, step_s: float):
    """The receiver's stamps from ``at_s`` on ``step_s`` seconds early (a clock step back)."""
    d = copy.deepcopy(drive)
    t = d.gnss.t_ns.copy()
    after = t >= t[0] + round(at_s * 1e9)
    t[after] -= round(step_s * 1e9)
    d.gnss = dataclasses.replace(d.gnss, t_ns=t)
    return d, after


@pytest.mark.parametrize(("with_odo", "at_s"), [(True, 200.0), (False, 200.0), (True, 450.0)])
def test_a_receiver_clock_that_steps_back_is_restamped(with_odo: bool, at_s: float) -> None:
    """The fixes' stamps step back 2 s at 200 s (or 450 s: the stretch before the step is the
    shorter one) and stay so: the stretch off the dead reckoning's clock (the odometer's speed,
    else the gyro against the course rate) is re-stamped by 2 s to 0.05 s, the other kept as
    logged.  Fused, the track is back within 1.5 x the clean drive's error; as logged (the
    check off) every fix after the step sits 2 s of travel off (about 20 m)."""
    sim = simulate_drive("urban_canyon", 2, duration_s=600.0)
    d, after = _gnss_step_back(sim.drive, at_s, 2.0)
    if not with_odo:
        d.odo = None
    out, notes = clock_check.gnss_clock_steps(d, config.defaults())
    assert len(notes) == 1 and "re-stamped" in notes[0] and "go back 1.80 s" in notes[0]
    moved = (out.gnss.t_ns - d.gnss.t_ns) / 1e9
    assert np.all(moved[~after] == 0.0)
    np.testing.assert_allclose(moved[after], 2.0, atol=0.05)
    truth = sim.truth[["t_ns", "lat", "lon"]]
    p = config.defaults()
    clean = fuse(sim.drive if with_odo else dataclasses.replace(sim.drive, odo=None), p, truth)
    res = fuse(d, p, truth)
    off = fuse(d, p | {"time": p["time"] | {"dr_clock_check": False}}, truth)
    assert any("receiver's clock steps" in w for w in res.drive_warnings)
    assert res.summary()["rmse_m"] < 1.5 * clean.summary()["rmse_m"]
    assert off.summary()["rmse_m"] > 3.0 * res.summary()["rmse_m"]


def test_no_restamping_without_a_step_or_a_judge() -> None:
    """No step: nothing moves.  A step with no gyro and no odometer: nothing to judge it by,
    the fixes stay as logged."""
    sim = simulate_drive("urban_canyon", 2, duration_s=300.0)
    out, notes = clock_check.gnss_clock_steps(sim.drive, config.defaults())
    assert notes == [] and out is sim.drive
    d, _ = _gnss_step_back(sim.drive, 150.0, 2.0)
    d.odo = d.gyro = None
    out, notes = clock_check.gnss_clock_steps(d, config.defaults())
    assert notes == [] and out is d
