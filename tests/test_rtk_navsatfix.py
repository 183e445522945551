"""A real ROS 2 recording of an RTK receiver whose NavSatFix cannot say RTK.

``../shared/data/mcap_samples/ublox_gps_ros2.mcap``: a u-blox F9P's ``/gps/fix`` at 10 Hz,
status GBAS (augmented; NavSatStatus has no RTK code) with hAcc 1.4-2.6 cm from 15.7 s
on, and its ENU ``/fix_velocity``; no gyro, no odometer.  At 106.6 s the fixes jump
1.8 m while still reporting centimetres: one of the two plateaus (91 s before, 233 s
after) is a wrong integer fix.  Read as DGPS, the drive was not an RTK drive and every
track wandered 1-3 m from the centimetre fixes (forward 1.04 m RMS after the jump).
"""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.io.mcap import read_mcap
from gpsdr_cli.pipeline import fuse

from .conftest import SHARED_DATA

LOG = SHARED_DATA / "mcap_samples" / "ublox_gps_ros2.mcap"
JUMP_S = 106.55  # s after the first fix


@pytest.mark.parametrize("smoother", ["none", "rts"])
def test_the_track_follows_the_centimetre_fixes(smoother: str) -> None:
    drive = read_mcap(LOG)
    params = config.defaults()
    params["filter"]["smoother"] = smoother
    res = fuse(drive, params)
    t = res.track["time"].astype("int64").to_numpy()
    g = drive.gnss
    rel_fix = (g.t_ns - g.t_ns[0]) / NS_PER_S
    e_fix, n_fix = res.frame.forward(g.lat_deg, g.lon_deg)
    i = np.searchsorted(g.t_ns, t)
    assert np.array_equal(g.t_ns[i], t)     # GNSS only: a track epoch at every fix
    dev = np.hypot(res.track["e"].to_numpy() - e_fix[i], res.track["n"].to_numpy() - n_fix[i])
    after = rel_fix[i] > JUMP_S
    rms_after = float(np.sqrt(np.mean(dev[after] ** 2)))
    assert rms_after < 0.06, rms_after        # m; was 1.04 (forward) and 1.78 (RTS) as DGPS
    sigma = np.hypot(res.track["sigma_e"], res.track["sigma_n"]).to_numpy() / np.sqrt(2.0)
    assert np.median(sigma[after]) < 0.05      # m: the reported sigma says centimetres too
    # the minority plateau is the wrong fix: caught (metres from it), not followed
    before = (rel_fix[i] > 16.0) & (rel_fix[i] < JUMP_S - 1.0)
    assert np.median(dev[before]) > 1.0
