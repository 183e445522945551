"""A drive partly RTK fixed, with a wheel odometer: the centimetre fixes measure the
odometer's lag, and the track follows them (decision 0027).

The simulated odometer averages its ticks over 0.1 s, so its speed reads 0.05 s late
(``noise["odo_lag_s"]``).  The drives are ``benchmarks/rtk_mixed.py``'s: a simulated
open-sky drive whose fixes in three 60-s windows (30 % of them) are RTK fixed.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from gpsdr_cli import config, rtk_odo_lag
from gpsdr_cli.pipeline import choose_frame, fuse
from gpsdr_cli.simulate import simulate_drive

from .conftest import load_benchmark

RM = load_benchmark("rtk_mixed")


@pytest.fixture(scope="module")
def mixed():
    sim = simulate_drive("open_sky", seed=1, duration_s=600.0)
    drive, sel = RM.with_rtk_windows(sim, RM.LAYOUTS["30 %"], 1)
    return sim, drive, sel


def test_the_rtk_fixed_fixes_measure_the_odometer_lag(mixed):
    sim, drive, _ = mixed
    p = config.defaults()
    lag, sd, used = rtk_odo_lag.estimate(drive, p, choose_frame(drive, p))
    assert abs(lag - sim.noise["odo_lag_s"]) < 0.005, lag     # s
    assert 0.0 < sd < 0.003 and used > 300
    # metre fixes measure nothing here: no estimate, no change
    assert rtk_odo_lag.estimate(sim.drive, p, choose_frame(sim.drive, p)) is None


def test_the_lag_is_applied_unless_the_user_said_otherwise(mixed):
    _, drive, _ = mixed
    p = config.defaults()
    frame = choose_frame(drive, p)
    out, note = rtk_odo_lag.apply(drive, p, frame, False)
    assert out["time"]["odo_offset_s"] == pytest.approx(-0.05)
    assert "0.05 s late against the RTK-fixed fixes" in note
    assert p["time"]["odo_offset_s"] == 0.0                  # the caller's params untouched
    for key, value in (("odo_offset_s", -0.1), ("gyro_offset_s", 0.02), ("odo_lag_auto", False)):
        q = copy.deepcopy(p)
        q["time"][key] = value
        assert rtk_odo_lag.apply(drive, q, frame, False) == (q, None)
    assert rtk_odo_lag.apply(drive, p, frame, True) == (p, None)  # --gnss-offset auto


@pytest.mark.parametrize("name", ["aekf", "fkf"])
def test_a_drive_30_percent_rtk_fixed_follows_its_centimetre_fixes(mixed, name):
    """Before: the drive was no RTK drive (rtk_share 0.5), so the track stayed 0.3-0.5 m from
    the centimetre fixes; an RTK drive without the lag read, aekf's track went 0.82 m off
    the truth on the other fixes (sure of its dead reckoning after the centimetre ones)."""
    sim, drive, sel = mixed
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smoother"] = "none"
    res = fuse(copy.deepcopy(drive), p)
    inside, outside, fixes = RM.errors(sim, res, drive.gnss, sel)
    assert inside < 0.03, inside          # m; 0.45 (aekf) / 0.36 (fkf) before
    assert outside < 0.35, outside        # m; aekf 0.82 without the lag; fixes 1.45 m
    assert any("0.05 s late against the RTK-fixed" in w for w in res.drive_warnings)
    assert np.all(np.isfinite(res.track["sigma_e"]))
