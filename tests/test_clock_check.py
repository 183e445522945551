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
